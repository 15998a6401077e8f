//! The training data generator: seeded per-index shapes, resumable file, eq 18 targets.
use std::io::Write;

use sonoflow_platelet::dataset::{
    draw_shape, generate, load, network_datasets, strain_dataset, GenerateOptions, Refinement, Set,
    GENERALISATION_LIMITS,
};
use sonoflow_platelet::nn::model::StrainTarget;
use sonoflow_platelet::nn::model::{eq18_factors, rotational_from_si, translational_from_si};
use sonoflow_platelet::shape::BOUNDS;
use sonoflow_platelet::{Outer, StokesOptions};

fn quick() -> GenerateOptions {
    // coarse and in free space: this tests the bookkeeping, not the solver
    GenerateOptions {
        n_shapes: 4,
        n_generalisation: 2,
        seed: 7,
        threads: 2,
        stokes: StokesOptions { n_beta: 6, outer: Outer::FreeSpace, ..StokesOptions::default() },
        refine: Vec::new(),
    }
}

#[test]
fn shapes_are_seeded_per_index_and_sets_respect_their_bounds() {
    assert_eq!(draw_shape(1, Set::InBounds, 5), draw_shape(1, Set::InBounds, 5));
    assert_ne!(draw_shape(1, Set::InBounds, 5), draw_shape(1, Set::InBounds, 6));
    assert_ne!(draw_shape(1, Set::InBounds, 5), draw_shape(2, Set::InBounds, 5));
    for i in 0..200 {
        let s = draw_shape(3, Set::InBounds, i);
        assert!(s.check_bounds().is_ok(), "{s:?}");
        let g = draw_shape(3, Set::Generalisation, i);
        assert!(g.check_bounds().is_err(), "generalisation shape inside eq 7: {g:?}");
        let v = [g.lx, g.ly, g.lz, g.alpha_top, g.alpha_bot];
        for (x, (name, lo, hi)) in v.iter().zip(GENERALISATION_LIMITS) {
            assert!((lo..=hi).contains(x), "{name} = {x} outside [{lo}, {hi}]");
        }
    }
    assert_eq!(BOUNDS.len(), 5);
}

#[test]
fn generation_resumes_after_a_torn_line_and_rejects_other_options() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("d.jsonl");
    let opts = quick();
    let noop = |_: u64, _: u64| {};
    let first = generate(&path, &opts, &noop).expect("generate");
    assert_eq!(first.len(), 6);
    // Simulate an interrupted run: keep the header and two records, then half a line.
    let text = std::fs::read_to_string(&path).expect("read");
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 7);
    let mut f = std::fs::File::create(&path).expect("rewrite");
    for l in &lines[..3] {
        writeln!(f, "{l}").expect("write");
    }
    write!(f, "{}", &lines[3][..lines[3].len() / 2]).expect("write torn");
    drop(f);
    let solved = std::sync::atomic::AtomicU64::new(0);
    let count = |_: u64, total: u64| {
        solved.store(total, std::sync::atomic::Ordering::Relaxed);
    };
    let second = generate(&path, &opts, &count).expect("resume");
    assert_eq!(solved.load(std::sync::atomic::Ordering::Relaxed), 4, "only the 4 missing shapes are solved");
    assert_eq!(second.len(), 6);
    for (a, b) in first.iter().zip(&second) {
        assert_eq!((a.set, a.index, a.shape), (b.set, b.index, b.shape));
        assert_eq!(a.resistance.force_per_flow, b.resistance.force_per_flow, "solves are deterministic");
    }
    assert_eq!(load(&path).expect("load").len(), 6);
    // Another seed on the same file is refused, not mixed in.
    let e = generate(&path, &GenerateOptions { seed: 8, ..opts.clone() }, &noop).unwrap_err();
    assert!(e.to_string().contains("generated with"), "{e}");
    let e = generate(&path, &GenerateOptions { threads: 0, ..opts }, &noop).unwrap_err();
    assert!(e.to_string().contains("threads"), "{e}");
}

#[test]
fn network_targets_are_eq_18_of_the_solved_resistance() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("d.jsonl");
    let records = generate(&path, &GenerateOptions { n_generalisation: 0, ..quick() }, &|_, _| {}).expect("generate");
    let refs: Vec<_> = records.iter().collect();
    let d = network_datasets(&refs, 3, 1).expect("datasets");
    assert_eq!((d.n.len(), d.n_r.len(), d.n_s.len()), (12, 4, 4));
    for (k, r) in records.iter().enumerate() {
        for a in 0..3 {
            let row = 3 * k + a;
            let x = &d.n.inputs()[6 * row..6 * row + 6];
            assert!((x[0] - r.shape.lx * 1e6).abs() < 1e-12 && (x[3] - r.shape.alpha_top).abs() < 1e-15);
            let psi = x[5];
            // independent: D, L, T from the resistance tensor by hand, divided by eq 18's factors
            let k2 = r.resistance.force_per_flow;
            let (s, c) = psi.sin_cos();
            let f = [k2[0][0] * c + k2[0][1] * s, k2[1][0] * c + k2[1][1] * s];
            let drag = (f[0] * c + f[1] * s) * 1e-6 / 1e-15;
            let lift = (-f[0] * s + f[1] * c) * 1e-6 / 1e-15;
            let y = &d.n.targets()[3 * row..3 * row + 3];
            let fac = eq18_factors(psi);
            assert!((y[0] * fac[0] - drag).abs() < 1e-9 * drag.abs(), "{} vs {drag}", y[0] * fac[0]);
            assert!((y[1] * fac[1] - lift).abs() < 1e-9 * drag.abs());
            // the angle is away from the zeros of sin 2ψ and cos ψ
            assert!(fac[1].abs() > 1e-2 * 1e-1 && fac[2].abs() > 1e-3);
            let raw = translational_from_si(&r.resistance.translational(psi));
            assert!((raw[0] - drag).abs() < 1e-9 * drag.abs());
        }
        let [t_r, t_s] = rotational_from_si(&r.resistance.rotational());
        assert!((d.n_r.targets()[k] * 800.0 - t_r).abs() < 1e-9 * t_r.abs());
        assert!((d.n_s.targets()[k] * 800.0 - t_s).abs() < 1e-9 * t_s.abs().max(1e-30));
    }
    assert!(network_datasets(&refs, 0, 1).is_err());
}

/// The mirrors the trainer averages over ([`Mirror::platelet_n`], [`Mirror::platelet_shape`]) are
/// exact symmetries of the solver's targets: for a shape and its mirror image (α_top ↔ α_bot),
/// solved independently, the eq 18 targets at the mirrored input M x are S times those at x.
#[test]
fn platelet_mirrors_are_symmetries_of_the_solved_targets() {
    use sonoflow_platelet::nn::mlp::Mirror;
    use sonoflow_platelet::nn::model::{network_inputs, scale_translational, shape_inputs};
    use sonoflow_platelet::{solve_shape, Shape};
    let opts = StokesOptions { n_beta: 8, ..StokesOptions::default() }; // the paper's ball, coarse
    let targets = |r: &sonoflow_platelet::ShapeResistance, psi: f64| {
        scale_translational(psi, translational_from_si(&r.translational(psi))).expect("away from the zeros")
    };
    let shapes = [Shape::from_um(3.1, 0.7, 2.8, 0.3, 1.7), Shape::from_um(2.7, 0.35, 3.3, 1.4, 0.6)];
    for s in shapes {
        let m = Shape { alpha_top: s.alpha_bot, alpha_bot: s.alpha_top, ..s };
        let (rs, rm) = (solve_shape(&s, &opts).expect("solve"), solve_shape(&m, &opts).expect("solve"));
        // N: (d, l, t_p) at M x = S (d, l, t_p) at x
        let n = Mirror::platelet_n();
        for psi in [0.3, 1.2, 2.0, 3.5, 5.9] {
            let x = network_inputs(&s, psi);
            let mut mx = [0.0; 6];
            n.input(&x, &mut mx);
            assert_eq!(mx, network_inputs(&m, 2.0 * std::f64::consts::PI - psi), "M x is the mirror image at −ψ");
            let mut want = targets(&rs, psi);
            n.output(&mut want);
            let got = targets(&rm, mx[5]);
            for k in 0..3 {
                assert!(
                    (got[k] - want[k]).abs() < 1e-12 * (1.0 + want[k].abs()),
                    "{s:?} ψ {psi} output {k}: {got:?} vs {want:?}"
                );
            }
            // and t_p does not change sign trivially: the shape is asymmetric
            assert!(want[2].abs() > 1e-3, "{want:?}");
        }
        // N_r, N_s: the same t_r and t_s
        let sh = Mirror::platelet_shape();
        let mut mx = [0.0; 5];
        sh.input(&shape_inputs(&s), &mut mx);
        assert_eq!(mx, shape_inputs(&m));
        let (a, b) = (rotational_from_si(&rs.rotational()), rotational_from_si(&rm.rotational()));
        for k in 0..2 {
            assert!((a[k] - b[k]).abs() < 1e-12 * a[k].abs(), "{s:?}: {a:?} vs {b:?}");
        }
    }
}

#[test]
fn thin_shapes_are_solved_finer_and_a_finer_rule_resolves_only_them() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("d.jsonl");
    let base = quick();
    let noop = |_: u64, _: u64| {};
    let coarse = generate(&path, &base, &noop).expect("generate");
    assert!(coarse.iter().all(|r| r.n_beta == Some(6)), "every record says its resolution");
    // a rule between the shapes' aspects: the thinner ones are solved again at 8, once
    let aspect = |r: &sonoflow_platelet::dataset::Record| r.shape.lx.max(r.shape.lz) / r.shape.ly;
    let mut aspects: Vec<f64> = coarse.iter().map(aspect).collect();
    aspects.sort_by(f64::total_cmp);
    let cut = 0.5 * (aspects[2] + aspects[3]);
    let rule = GenerateOptions { refine: vec![Refinement { min_aspect: cut, n_beta: 8 }], ..base.clone() };
    let solved = std::sync::atomic::AtomicU64::new(0);
    let count = |_: u64, total: u64| solved.store(total, std::sync::atomic::Ordering::Relaxed);
    let fine = generate(&path, &rule, &count).expect("refine");
    assert_eq!(solved.load(std::sync::atomic::Ordering::Relaxed), 3, "the three shapes above the cut");
    for (c, f) in coarse.iter().zip(&fine) {
        assert_eq!((c.set, c.index), (f.set, f.index));
        let want = if aspect(c) >= cut { 8 } else { 6 };
        assert_eq!(f.n_beta, Some(want), "aspect {}", aspect(c));
        if want == 8 {
            assert_ne!(c.resistance.rotation_torque, f.resistance.rotation_torque, "solved again");
        } else {
            assert_eq!(c, f, "kept as it was");
        }
    }
    // nothing lost: the coarse lines stay in the file, the finest counts on loading
    let text = std::fs::read_to_string(&path).expect("read");
    assert_eq!(text.lines().count(), 1 + 6 + 3);
    assert_eq!(load(&path).expect("load"), fine);
    // and a rerun with the same rule solves nothing
    solved.store(99, std::sync::atomic::Ordering::Relaxed);
    generate(&path, &rule, &count).expect("rerun");
    assert_eq!(solved.load(std::sync::atomic::Ordering::Relaxed), 99, "no progress call: nothing to solve");
    // bad rules are named
    let bad = GenerateOptions { refine: vec![Refinement { min_aspect: 0.5, n_beta: 8 }], ..base.clone() };
    let e = generate(&path, &bad, &noop).unwrap_err();
    assert!(e.to_string().contains("refine.min_aspect"), "{e}");
    let bad = GenerateOptions { refine: vec![Refinement { min_aspect: 2.0, n_beta: 7 }], ..base };
    let e = generate(&path, &bad, &noop).unwrap_err();
    assert!(e.to_string().contains("n_beta"), "{e}");
}

#[test]
fn shape_factor_targets_invert_to_the_strain_torque() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("d.jsonl");
    let records = generate(&path, &quick(), &|_, _| {}).expect("generate");
    let refs: Vec<&_> = records.iter().collect();
    for target in StrainTarget::ALL {
        let d = strain_dataset(&refs, target).expect("targets");
        assert_eq!(d.len(), records.len());
        for (k, r) in records.iter().enumerate() {
            let [t_r, t_s] = rotational_from_si(&r.resistance.rotational());
            let (t_r, t_s) = (t_r / 800.0, t_s / 800.0);
            let back = target.strain_torque(&r.shape, t_r, d.targets()[k]);
            assert!((back - t_s).abs() < 1e-12 * t_r, "{target:?}: {back} vs {t_s}");
            if target == StrainTarget::ShapeFactor {
                // ln((1 − B)/(1 − B_e)) with B_e = (Lx² − Ly²)/(Lx² + Ly²)
                let (x2, y2) = (r.shape.lx.powi(2), r.shape.ly.powi(2));
                let want = (1.0 - t_s / t_r).ln() - (2.0 * y2 / (x2 + y2)).ln();
                assert!((d.targets()[k] - want).abs() < 1e-12, "{} vs {want}", d.targets()[k]);
            }
        }
    }
    // B ≥ 1 has no log target
    let s = records[0].shape;
    assert!(StrainTarget::ShapeFactor.target(&s, 1.0, 1.0).is_err());
    assert!(StrainTarget::LogOneMinusB.target(&s, -1.0, -2.0).is_err());
    assert_eq!(StrainTarget::StrainTorque.target(&s, 1.0, 1.5).expect("t_s itself"), 1.5);
}
