//! Convex arrays (MUST `param.radius`, the C5-2v preset): element geometry, echo timing along
//! the arc, transmit delay laws, the field behind the face, symmetry, clear errors. Agreement
//! with PyMUST 0.1.9 (nRMS ≤ 1e-4 on two probes) is checked by the Python suite
//! (`nodes/python/tests/test_convex.py`), which runs PyMUST itself.
#![allow(clippy::unwrap_used)] // test helpers outside #[test] functions

use sonoflow_simus::testkit::{envelope_centroid, linear_engine, one, single_element_transmit};
use sonoflow_simus::{nrms, Medium, Probe, SimusError, SimusOptions, Transmit};

/// Half-width of the window for echo centroids (s): C5-2v's two-way pulse lasts ≈ 3.5 µs.
const W: f64 = 2.5e-6;

fn c5() -> Probe {
    Probe::preset("C5-2v").unwrap()
}

/// The elements lie on the circle of radius R centred at (0, −h), the end elements on the
/// chord (z = 0), neighbours one pitch apart along the chord of their angle step (MUST keeps
/// the pitch as the chord: 2R·sin(asin(pitch/2R)) = pitch), normals radial.
#[test]
fn elements_lie_on_the_arc() {
    for (p, n) in
        [(c5(), 128usize), (Probe { radius: Some(0.02), n_elements: 96, ..Probe::preset("L11-5v").unwrap() }, 96)]
    {
        let pos = p.element_positions();
        let (r, h) = (p.radius.unwrap(), p.apothem());
        assert_eq!(pos.len(), n);
        assert!(pos[0].z.abs() < 1e-15 && pos[n - 1].z.abs() < 1e-15, "ends {} {}", pos[0].z, pos[n - 1].z);
        assert!((pos[0].x + pos[n - 1].x).abs() < 1e-15, "chord centred");
        for (e, q) in pos.iter().enumerate() {
            assert!((q.x.hypot(q.z + h) - r).abs() < 1e-14, "element {e} off the circle");
            let (s, c) = q.theta.sin_cos();
            assert!((q.x / r - s).abs() < 1e-14 && ((q.z + h) / r - c).abs() < 1e-14, "element {e} normal not radial");
            assert!((p.element_x(e) - q.x).abs() == 0.0);
        }
        for w in pos.windows(2) {
            assert!(((w[1].x - w[0].x).hypot(w[1].z - w[0].z) - p.pitch).abs() < 1e-15);
        }
        // the apex of the arc, behind-the-face test
        assert!(p.is_behind(0.0, r - h - 1e-6) && !p.is_behind(0.0, r - h + 1e-6));
        assert!(!p.is_behind(pos[n - 1].x + 1e-3, 0.0) && p.is_behind(0.0, -1e-9));
    }
}

/// One element transmits, another receives: the echo's envelope centroid is at
/// `(|p − e_tx| + |p − e_rx|)/c` with the elements on the arc — the same argument and tolerance
/// as the linear test in physics.rs (0.05 sample), and here the sub-elements are tilted along
/// each element.
#[test]
fn echo_arrival_time_on_the_arc() {
    let probe = c5();
    let medium = Medium::default();
    let mut simus = linear_engine(&probe, &medium, SimusOptions::default());
    let pos = probe.element_positions();
    for &(x, z, tx) in &[(0.0f32, 0.04f32, 64usize), (0.012, 0.05, 90), (-0.018, 0.06, 20)] {
        let rf = simus.simulate(&one(x, z), &single_element_transmit(probe.n_elements, tx)).unwrap();
        let d = |e: usize| (f64::from(x) - pos[e].x).hypot(f64::from(z) - pos[e].z);
        for rx in [tx, 10, 64, 120] {
            let want = (d(tx) + d(rx)) / medium.c;
            let err = (envelope_centroid(rf.element(rx), rf.fs, rf.t0, want, W) - want) * rf.fs;
            assert!(err.abs() < 0.05, "scatterer ({x}, {z}) tx {tx} rx {rx}: {err:.4} samples");
        }
    }
}

/// All elements fire together: the arc launches a cylindrical wave from the circle's centre
/// O = (0, −h), which reaches p at `(|p − O| − R)/c`; it equals `Transmit::diverging` from O
/// (delays 0). A convex "plane wave" of tilt θ (MUST's delays) makes the line tangent to the arc
/// at θ the wavefront: it reaches p at `(d_max + dist(p, tangent))/c`, d_max the largest
/// element–tangent distance. Echo centroids within ±2.5 µs, tolerance 0.1 sample as the linear
/// plane-wave test (edge waves).
#[test]
fn transmit_wavefronts_on_the_arc() {
    let probe = c5();
    let medium = Medium::default();
    let c = medium.c;
    let (r, h) = (probe.radius.unwrap(), probe.apothem());
    let pos = probe.element_positions();
    let div = Transmit::diverging(&probe, c, 0.0, -h).unwrap();
    assert!(div.delays.iter().all(|d| d.abs() < 1e-15), "diverging from the centre: {:?}", &div.delays[..3]);
    let mut simus = linear_engine(&probe, &medium, SimusOptions::default());
    let zero = Transmit::zero(probe.n_elements);
    for &(x, z) in &[(0.0f64, 0.05f64), (0.015, 0.06)] {
        let rf = simus.simulate(&one(x as f32, z as f32), &zero).unwrap();
        for rx in [30, 64, 100] {
            let want = (x.hypot(z + h) - r + (x - pos[rx].x).hypot(z - pos[rx].z)) / c;
            let err = (envelope_centroid(rf.element(rx), rf.fs, rf.t0, want, W) - want) * rf.fs;
            assert!(err.abs() < 0.1, "zero delays ({x}, {z}) rx {rx}: {err:.3} samples");
        }
    }
    for tilt in [0.15f64, -0.25] {
        let tx = Transmit::plane_wave(&probe, c, tilt).unwrap();
        let (s, co) = tilt.sin_cos();
        // tangent line at angle tilt: points q with (q − t)·n = 0, n = (sin, cos), t = O + R n
        let dist = |x: f64, z: f64| x * s + (z + h) * co - r;
        let d_max = pos.iter().map(|p| -dist(p.x, p.z)).fold(0.0, f64::max);
        for (e, p) in pos.iter().enumerate() {
            let want = (d_max + dist(p.x, p.z)) / c;
            assert!((tx.delays[e] - want).abs() < 1e-15, "tilt {tilt} element {e}: {} vs {want}", tx.delays[e]);
        }
        let (x, z) = (0.01 * s.signum(), 0.05);
        let rf = simus.simulate(&one(x as f32, z as f32), &tx).unwrap();
        for rx in [40, 64, 90] {
            let want = (d_max + dist(x, z) + (x - pos[rx].x).hypot(z - pos[rx].z)) / c;
            let err = (envelope_centroid(rf.element(rx), rf.fs, rf.t0, want, W) - want) * rf.fs;
            assert!(err.abs() < 0.1, "tilt {tilt} rx {rx}: {err:.3} samples");
        }
    }
}

/// A scatterer between the chord and the arc (inside the circle: behind the face) is not
/// insonified (MUST's isOUT): silent, while the same point 1 mm in front of the apex echoes.
#[test]
fn behind_the_face_is_silent() {
    let probe = c5();
    let medium = Medium::default();
    let mut simus = linear_engine(&probe, &medium, SimusOptions::default());
    let apex = (probe.radius.unwrap() - probe.apothem()) as f32;
    let tx = Transmit::zero(probe.n_elements);
    let behind = simus.simulate(&one(0.0, apex - 1e-3), &tx).unwrap();
    assert!(behind.data.iter().all(|v| *v == 0.0));
    let front = simus.simulate(&one(0.0, apex + 1e-3), &tx).unwrap();
    assert!(front.data.iter().any(|v| v.abs() > 0.0));
}

/// Mirror symmetry about the axis: an on-axis scatterer under zero delays gives
/// `RF_e = RF_{N−1−e}` up to MUST's asymmetric ε in the angle formula (as the linear test:
/// tolerance 2e-5).
#[test]
fn convex_left_right_symmetry() {
    let probe = c5();
    let medium = Medium::default();
    let mut simus = linear_engine(&probe, &medium, SimusOptions::default());
    let n = probe.n_elements;
    let rf = simus.simulate(&one(0.0, 0.05), &Transmit::zero(n)).unwrap();
    let mirrored: Vec<f32> = (0..n).rev().flat_map(|e| rf.element(e).to_vec()).collect();
    let err = nrms(&mirrored, &rf.data);
    assert!(err < 2e-5, "on-axis asymmetry {err:e}");
}

/// `radius = inf` is the linear array, bit for bit.
#[test]
fn infinite_radius_is_linear() {
    let medium = Medium::default();
    let lin = Probe::preset("L11-5v").unwrap();
    let inf = Probe { radius: Some(f64::INFINITY), ..lin.clone() };
    let tx = Transmit::plane_wave(&lin, medium.c, 0.1).unwrap();
    assert_eq!(Transmit::plane_wave(&inf, medium.c, 0.1).unwrap(), tx);
    let scat = sonoflow_simus::testkit::random_scatterers(50, 4);
    let a = linear_engine(&lin, &medium, SimusOptions::default()).simulate(&scat, &tx).unwrap();
    let b = linear_engine(&inf, &medium, SimusOptions::default()).simulate(&scat, &tx).unwrap();
    assert_eq!(a.data, b.data);
}

/// Impossible geometry gets an error naming the field: a radius ≤ 0 or NaN, more elements than
/// fit on half the circle (the largest count that fits is given), a pitch wider than the
/// diameter, a focus behind the face.
#[test]
fn impossible_geometry_is_named() {
    for r in [0.0, -0.01, f64::NAN] {
        let p = Probe { radius: Some(r), ..c5() };
        let e = p.validate().unwrap_err().to_string();
        assert!(e.contains("probe.radius"), "{e}");
    }
    // asin(0.508e-3 / 2 / 0.02) = 0.0127 rad: at most ceil(π/2 / 0.0127) = 124 elements
    let p = Probe { radius: Some(0.02), ..c5() };
    let e = p.validate().unwrap_err();
    assert!(matches!(e, SimusError::ArcTooShort { max: 124, .. }), "{e}");
    assert!(e.to_string().contains("probe.n_elements"), "{e}");
    Probe { radius: Some(0.02), n_elements: 124, ..c5() }.validate().unwrap();
    let p = Probe { radius: Some(0.2e-3), n_elements: 2, ..c5() };
    assert!(p.validate().unwrap_err().to_string().contains("probe.pitch"));
    let e = Transmit::focused(&c5(), 1540.0, 0.0, 0.005).unwrap_err().to_string();
    assert!(e.contains("focus z0") && e.contains("in front of the convex"), "{e}");
    assert!(Transmit::focused(&c5(), 1540.0, 0.0, 0.03).is_ok());
}

/// MUST's maximum element distance (the frequency step) over every element equals the
/// shortcut through the end elements for points above the circle's centre, and is found for
/// points below it too (scatterers far behind the probe are legal, silent input).
#[test]
fn max_distance_over_the_arc() {
    use sonoflow_simus::Scatterers;
    let probe = c5();
    let pos = probe.element_positions();
    let h = probe.apothem();
    let pts: Vec<(f32, f32)> = vec![
        (0.0, 0.05),
        (0.03, 0.001),
        (-0.08, 0.02),
        (0.01, -0.02),
        (0.0, (-h - 0.03) as f32),
        (0.02, (-h - 0.1) as f32),
    ];
    for &(x, z) in &pts {
        let s = Scatterers::new(vec![x], vec![z], vec![1.0]).unwrap();
        let brute = pos.iter().map(|p| (f64::from(x) - p.x).hypot(f64::from(z) - p.z)).fold(0.0, f64::max);
        let got = s.as_slices().max_probe_distance(&probe);
        assert!((got - brute).abs() <= 1e-15 * brute, "({x}, {z}): {got} vs {brute}");
    }
}
