//! The shipped networks (`nodes/platelet/weights`, trained by `sonoflow platelet train` on
//! `nodes/platelet/data/stokes-data.jsonl`) on the five test particles of paper 2's Table 2:
//! against our resolved Stokes solver (an independent computation) and the paper's qualitative
//! description of figs 9–12 (§5.1.1–5.1.4).
use std::f64::consts::PI;

use sonoflow_platelet::nn::model::{translational_from_si, NetworkModel};
use sonoflow_platelet::testkit::shipped_model;
use sonoflow_platelet::{solve_shape, CoefficientModel, Rotational, Shape, StokesOptions, Translational};

/// Table 2 (µm): Lx, Ly, Lz, α_top, α_bot.
const TABLE2: [[f64; 5]; 5] = [
    [3.0, 0.5, 3.0, 1.0, 1.0],
    [3.1, 0.8, 2.5, 1.7, 1.7],
    [2.7, 0.2, 3.2, 0.3, 0.3],
    [3.1, 0.7, 2.8, 0.3, 1.7],
    [2.8, 0.3, 3.1, 1.7, 0.3],
];

/// RMS of eq 18's t_p over the test shapes of the shipped data (training report).
const T_P_RMS: f64 = 0.334;

/// (ψ grid, D, L, T per particle) in paper units from the networks.
fn curves(m: &NetworkModel, n: usize) -> (Vec<f64>, Vec<[Vec<f64>; 3]>) {
    let psi: Vec<f64> = (0..n).map(|k| 2.0 * PI * k as f64 / n as f64).collect();
    let mut out = Vec::new();
    for p in TABLE2 {
        let s = Shape::from_um(p[0], p[1], p[2], p[3], p[4]);
        let shapes = vec![s; n];
        let mut c = vec![Translational::default(); n];
        m.translational(&shapes, &psi, &mut c);
        let raw: Vec<[f64; 3]> = c.iter().map(translational_from_si).collect();
        out.push([0, 1, 2].map(|k| raw.iter().map(|r| r[k]).collect::<Vec<_>>()));
    }
    (psi, out)
}

fn argmax(v: &[f64]) -> usize {
    (0..v.len()).max_by(|&a, &b| v[a].total_cmp(&v[b])).unwrap_or(0)
}

#[test]
fn networks_match_the_stokes_solver_on_the_five_test_particles() {
    let m = shipped_model();
    let psi = [0.3, 1.0, 2.0, 4.0];
    for p in TABLE2 {
        let s = Shape::from_um(p[0], p[1], p[2], p[3], p[4]);
        let r = solve_shape(&s, &StokesOptions::default()).expect("solve");
        let mut c = vec![Translational::default(); psi.len()];
        m.translational(&vec![s; psi.len()], &psi, &mut c);
        for (k, &a) in psi.iter().enumerate() {
            let net = translational_from_si(&c[k]);
            let (d, l) = (r.paper_drag(a), r.paper_lift(a));
            // test-set accuracy is 0.1 % on average, 0.5–0.8 % at worst: 1.5 % of the drag
            assert!((net[0] - d).abs() < 0.015 * d, "{p:?} ψ {a}: drag {} vs {d}", net[0]);
            assert!((net[1] - l).abs() < 0.015 * d, "{p:?} ψ {a}: lift {} vs {l}", net[1]);
            // pitching torque: eq 18's t_p = T / (2 cos ψ) against the RMS of t_p over the data
            // (T_P_RMS): test-set error 0.4 % on average; here 0.01–0.9 %
            let (tp_net, tp) = (net[2] / (2.0 * a.cos()), r.paper_torque(a) / (2.0 * a.cos()));
            assert!((tp_net - tp).abs() < 0.03 * T_P_RMS, "{p:?} ψ {a}: t_p {tp_net} vs {tp}");
        }
        let mut rot = [Rotational::default()];
        m.rotational(&[s], &mut rot);
        let exact = r.rotational();
        assert!((rot[0].c_r - exact.c_r).abs() < 0.015 * exact.c_r, "{p:?}: c_r {} vs {}", rot[0].c_r, exact.c_r);
        assert!((rot[0].c_s - exact.c_s).abs() < 0.015 * exact.c_r, "{p:?}: c_s {} vs {}", rot[0].c_s, exact.c_s);
    }
}

#[test]
fn five_particle_curves_have_the_papers_features() {
    let m = shipped_model();
    let n = 360;
    let (psi, c) = curves(&m, n);
    let near = |k: usize, target: f64| {
        let d = (psi[k] - target).rem_euclid(2.0 * PI);
        d.min(2.0 * PI - d) < 0.06
    };
    for (i, [d, l, t]) in c.iter().enumerate() {
        // §5.1.1: drag largest broadside (ψ = π/2 or 3π/2), smallest edgewise (0 or π)
        let kmax = argmax(d);
        assert!(near(kmax, PI / 2.0) || near(kmax, 1.5 * PI), "particle {}: drag peaks at {}", i + 1, psi[kmax]);
        let neg: Vec<f64> = d.iter().map(|x| -x).collect();
        let kmin = argmax(&neg);
        assert!(near(kmin, 0.0) || near(kmin, PI), "particle {}: drag smallest at {}", i + 1, psi[kmin]);
        // §5.1.2: lift zero at multiples of π/2, extremal at odd multiples of π/4
        let lmax = l.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        for q in 0..4 {
            let k = q * n / 4;
            assert!(l[k].abs() < 0.02 * lmax, "particle {}: lift {} at ψ = {}", i + 1, l[k], psi[k]);
        }
        let kl = argmax(&l.iter().map(|x| x.abs()).collect::<Vec<_>>());
        assert!(
            [1.0, 3.0, 5.0, 7.0].iter().any(|o| near(kl, o * PI / 4.0)),
            "particle {}: |lift| peaks at {}",
            i + 1,
            psi[kl]
        );
        // lift has the sign pattern of sin 2ψ: the same sign at π/4 and 5π/4, opposite at 3π/4
        let (a, b, e) = (l[n / 8], l[5 * n / 8], l[3 * n / 8]);
        assert!(a * b > 0.0 && a * e < 0.0, "particle {}: lift {a}, {b}, {e}", i + 1);
        // §5.1.4: pitching torque zero at π/2 and 3π/2 for all
        let tmax = t.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        assert!(t[n / 4].abs() <= 0.02 * tmax.max(1e-9) && t[3 * n / 4].abs() <= 0.02 * tmax.max(1e-9));
    }
    // §5.1.1 and §5.1.3: particle 3 (the thinnest) has the lowest drag (edgewise, ψ = 0) and the
    // lowest rotational torque. The paper also ranks particle 2 highest in drag, lift and rotational
    // torque by its size; in Stokes flow it is not (it is the thickest, with the smallest planform,
    // Lz = 2.5 µm): its broadside drag and its lift are the lowest of the five. Resistance theory
    // instead ties the lift of a mirror-symmetric body to its anisotropy, |L|max = (D(π/2) − D(0))/2,
    // which is asserted for particles 1–3.
    let peak = |k: usize, q: usize| c[k][q].iter().fold(0.0f64, |a, x| a.max(x.abs()));
    let d0: Vec<f64> = (0..5).map(|k| -c[k][0][0]).collect();
    assert_eq!(argmax(&d0), 2, "edgewise drag: {d0:?}");
    for (k, ck) in c.iter().enumerate().take(3) {
        let aniso = 0.5 * (ck[0][n / 4] - ck[0][0]);
        assert!((peak(k, 1) - aniso).abs() < 0.02 * aniso, "particle {}: |L|max {} vs {aniso}", k + 1, peak(k, 1));
    }
    let shapes: Vec<Shape> = TABLE2.iter().map(|p| Shape::from_um(p[0], p[1], p[2], p[3], p[4])).collect();
    let mut rot = vec![Rotational::default(); 5];
    m.rotational(&shapes, &mut rot);
    let cr: Vec<f64> = rot.iter().map(|r| -r.c_r).collect();
    assert_eq!(argmax(&cr), 2, "{cr:?}");
    // §5.1.4: pitching torque (near) zero for the symmetric particles 1–3, clearly non-zero and
    // of opposite signs for the mirror-image pair 4 (convex below) and 5 (convex above)
    let p4 = peak(3, 2);
    for k in 0..3 {
        assert!(peak(k, 2) < 0.1 * p4, "particle {}: |T| {} vs particle 4 {p4}", k + 1, peak(k, 2));
    }
    assert!(c[3][2][0] * c[4][2][0] < 0.0, "T(0): {} and {}", c[3][2][0], c[4][2][0]);
}

/// The shipped networks against the shipped solver data on the shipped test split (the split the
/// trainer uses: 80/20 by shape, seed 1, 4 angles): paper 2's Table 1 targets, recomputed here
/// from the data, not read from the training report. Drag, lift and rotational torque must beat
/// the table's average and maximum relative errors; the pitching torque (zero for symmetric
/// platelets, so relative to its RMS) must beat the table's 0.95 % average.
#[test]
fn shipped_networks_beat_table_1_on_the_test_shapes() {
    use sonoflow_platelet::dataset::{load, network_datasets, split_by_shape};
    use sonoflow_platelet::nn::{evaluate, Mlp};
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let records = load(&root.join("data/stokes-data.jsonl")).expect("the shipped data load");
    let (_, test) = split_by_shape(&records, 0.2, 1).expect("split");
    assert_eq!(test.len(), 800, "20 % of the 4 000 in-bounds shapes");
    let d = network_datasets(&test, 4, 1).expect("network data");
    let (n, _) = Mlp::load(&root.join("weights/n.safetensors")).expect("N loads");
    let (n_r, _) = Mlp::load(&root.join("weights/n_r.safetensors")).expect("N_r loads");
    let e = evaluate(&n, &d.n).expect("evaluate N");
    let er = evaluate(&n_r, &d.n_r).expect("evaluate N_r");
    // Table 1 (test data, avg / max %)
    for (name, got, avg, max) in [("drag", e[0], 0.40, 1.43), ("lift", e[1], 0.34, 1.33), ("t_r", er[0], 0.45, 1.50)] {
        assert!(got.mean_rel_pct < avg && got.max_rel_pct < max, "{name}: {got:?} vs Table 1 {avg} / {max}");
    }
    assert!(e[2].mean_rms_pct < 0.95, "pitching torque: {:?} vs Table 1 0.95 %", e[2]);
    // and the mirror the shipped N is built with (README: ŷ(M x) = S ŷ(x), M: α_top ↔ α_bot,
    // ψ → 2π − ψ; S flips t_p), exact up to rounding, on an asymmetric platelet
    let (x, xm) = ([3.1, 0.7, 2.8, 0.3, 1.7, 0.7], [3.1, 0.7, 2.8, 1.7, 0.3, 2.0 * PI - 0.7]);
    let (mut y, mut ym) = ([0.0; 3], [0.0; 3]);
    n.predict(&x, &mut y).expect("predict");
    n.predict(&xm, &mut ym).expect("predict");
    assert!(y[2].abs() > 0.01, "particle 4 has a pitching torque: {y:?}");
    for (k, s) in [1.0, 1.0, -1.0].into_iter().enumerate() {
        assert!((ym[k] - s * y[k]).abs() < 1e-12 * y[0].abs(), "mirror, output {k}: {y:?} vs {ym:?}");
    }
}
