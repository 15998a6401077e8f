//! Extreme cases: each has a clear outcome, a finite RF or a clear error.
#![allow(clippy::unwrap_used)] // test helpers outside #[test] functions

use sonoflow_simus::testkit::{
    all_finite, grazing_angles, linear_engine, many_scatterers, one, paper_engine as engine, peak, pw0,
    random_scatterers, scatterer_on_array_face, very_deep_scatterer, zero_scatterers,
};
use sonoflow_simus::{nrms, Accuracy, Medium, Probe, Scatterers, Simus, SimusError, SimusOptions, Transmit};

/// On the array face (z = 0) at an element centre and at a sub-element centre (d = 0): r is
/// clamped to λ/2 and |θ| = 90° gives MUST's obliquity floor, so the echo is finite and weaker
/// than that of the same scatterer λ/2 in front of the element.
#[test]
fn scatterer_on_the_array_face() {
    let face = scatterer_on_array_face();
    assert!(face.finite);
    for p in face.face_peaks {
        assert!(p <= face.front_peak, "{p} > {}", face.front_peak);
    }
}

/// Exactly on an element axis (θ = 0 for both sub-elements' mean, dx = 0 for the centre): the
/// limit is continuous — a 1 µm lateral shift changes the RF by ≪ 1e-2.
#[test]
fn scatterer_exactly_on_an_element_axis() {
    let p = Probe::paper_5mhz();
    let mut simus = linear_engine(&p, &Medium::default(), SimusOptions::default());
    let plan = simus.plan_for_max_distance(0.03, 0.0).unwrap();
    let xe = p.element_x(64) as f32;
    let mut a = vec![0f32; p.n_elements * plan.n_samples];
    let mut b = a.clone();
    simus.simulate_into(&one(xe, 0.01), &pw0(&p), &plan, &mut a).unwrap();
    simus.simulate_into(&one(xe + 1e-6, 0.01), &pw0(&p), &plan, &mut b).unwrap();
    assert!(all_finite(&a) && peak(&a) > 0.0);
    // a 1 µm shift moves the echoes by < 1e-6 m of path: relative change ~ k·1e-6·(x/r) < 1e-2
    let e = nrms(&b, &a);
    assert!(e < 1e-2, "{e:e}");
}

/// Grazing angles (|θ| → 90°): scatterers just below the face, inside and far outside the
/// aperture. Finite, and far weaker than a scatterer in front of the array at the same range.
#[test]
fn grazing_angles_are_finite_and_weak() {
    let (finite, ratio) = grazing_angles();
    assert!(finite);
    assert!(ratio < 0.1, "{ratio}");
}

/// Very deep (30 cm, 8-element probe to keep it fast): the grid grows (Nf ∝ depth) and the
/// echo still arrives at (z + d)/c; windowed centroid, within 0.1 sample.
#[test]
fn very_deep_scatterer_arrives_on_time() {
    let deep = very_deep_scatterer();
    assert!(deep.finite);
    assert!(deep.n_freq > 3000, "{}", deep.n_freq);
    assert!(deep.arrival_error.abs() < 0.1, "{}", deep.arrival_error);
}

/// No scatterers: an all-zero RF of the planned length (the plan covers the pulse only), not
/// an error.
#[test]
fn zero_scatterers_give_zero_rf_of_planned_length() {
    let z = zero_scatterers();
    assert_eq!(z.rf.plan, z.plan);
    assert_eq!(z.rf.data.len(), z.n_elements * z.plan.n_samples);
    assert!(z.rf.n_samples > 0 && z.rf.data.iter().all(|v| *v == 0.0));
    // with a fixed plan too
    assert!(z.fixed_plan_out.iter().all(|v| *v == 0.0));
}

/// Streaming over scatterer blocks: 20 000 scatterers in blocks of 7 (not a multiple of the
/// receive group: padding path) give the same RF as the default blocks of 256 and as one block
/// of 65 536 — only the f32 partial sums (folded into f64 after each block) are cut at other
/// places. Rounding of an f32 sum of n random-phase terms grows ~ε√n: ≲ 1e-6 for 256,
/// ~ε√20000 ≈ 8e-6 for one block of 20 000: tolerances 2e-6 and 2e-5. Memory is per block,
/// never scatterers × elements × bins (see the 10⁶-scatterer test).
#[test]
fn streaming_blocks_give_the_same_rf() {
    let p = Probe { n_elements: 16, ..Probe::paper_5mhz() };
    let s = random_scatterers(20_000, 99);
    let run = |block: u32| {
        let o = SimusOptions {
            db_thresh: -20.0,
            accuracy: Accuracy::Fast { reanchor_every: 64, scatterer_block: block },
            ..SimusOptions::default()
        };
        let mut simus = linear_engine(&p, &Medium::default(), o);
        simus.simulate(&s, &pw0(&p)).unwrap().data
    };
    let (a, b, c) = (run(7), run(256), run(65_536));
    let (e1, e2) = (nrms(&b, &a), nrms(&c, &a));
    assert!(e1 < 2e-6, "{e1:e}");
    assert!(e2 < 2e-5, "{e2:e}");
}

/// 10⁶ scatterers (8 elements, −20 dB band: ~1 s in release): finite RF and a peak-memory
/// increase far below one (scatterers × elements × bins) array (10⁶ × 8 × 200 × 8 B = 12.8 GB);
/// the engine streams blocks of 256 scatterers.
#[test]
fn one_million_scatterers_memory_bounded() {
    let m = many_scatterers(1_000_000);
    assert!(m.finite && m.peak > 0.0);
    if let Some(grew) = m.memory_growth_mib {
        assert!(grew < 200, "peak memory grew by {grew} MiB");
    }
}

#[test]
fn non_finite_scatterer_is_an_error_naming_the_row() {
    let p = Probe::paper_5mhz();
    let mut simus = engine();
    let mut s = random_scatterers(10, 99);
    s.x[3] = f32::NAN;
    match simus.simulate(&s, &pw0(&p)) {
        Err(SimusError::InvalidScatterer { row: 3, field: "x", .. }) => {}
        other => panic!("{other:?}"),
    }
    let mut s = random_scatterers(10, 99);
    s.rc[7] = f32::INFINITY;
    let e = simus.simulate(&s, &pw0(&p)).unwrap_err();
    assert!(matches!(e, SimusError::InvalidScatterer { row: 7, field: "rc", .. }), "{e}");
    assert!(e.to_string().contains("row 7"), "{e}");
    let mut s = random_scatterers(10, 99);
    s.z[0] = f32::NEG_INFINITY;
    let plan = simus.plan_for_max_distance(0.05, 0.0).unwrap();
    let mut out = vec![0f32; p.n_elements * plan.n_samples];
    let e = simus.simulate_into(&s, &pw0(&p), &plan, &mut out).unwrap_err();
    assert!(matches!(e, SimusError::InvalidScatterer { row: 0, field: "z", .. }), "{e}");
    let mut s = random_scatterers(10, 99);
    s.z[2] = 1e4; // finite but absurd: 10 km
    assert!(matches!(simus.simulate(&s, &pw0(&p)), Err(SimusError::InvalidScatterer { row: 2, .. })));
}

#[test]
fn bad_sampling_or_bandwidth_is_an_error_naming_the_field() {
    let e = Simus::new(Probe::paper_5mhz(), Medium::default(), SimusOptions { fs: Some(19e6), ..Default::default() })
        .unwrap_err();
    assert!(matches!(e, SimusError::InvalidParameter { field: "options.fs", .. }), "{e}");
    for bw in [0.0, -10.0, f64::NAN] {
        let p = Probe { bandwidth: bw, ..Probe::paper_5mhz() };
        let e = Simus::new(p, Medium::default(), SimusOptions::default()).unwrap_err();
        assert!(matches!(e, SimusError::InvalidParameter { field: "probe.bandwidth", .. }), "{e}");
        assert!(e.to_string().contains("probe.bandwidth"), "{e}");
    }
}

#[test]
fn inconsistent_inputs_are_errors() {
    let p = Probe::paper_5mhz();
    let mut simus = engine();
    let s = random_scatterers(5, 99);
    // transmit of the wrong length, negative delay
    let e = simus.simulate(&s, &Transmit::zero(3)).unwrap_err();
    assert!(matches!(e, SimusError::LengthMismatch { field: "transmit.delays", got: 3, expected: 128 }), "{e}");
    let mut t = pw0(&p);
    t.delays[5] = -1e-6;
    assert!(matches!(simus.simulate(&s, &t), Err(SimusError::InvalidParameter { field: "transmit.delays", .. })));
    // scatterer arrays of different lengths
    let bad = Scatterers { x: vec![0.0; 3], z: vec![0.01; 2], rc: vec![1.0; 3] };
    assert!(matches!(simus.simulate(&bad, &t), Err(SimusError::LengthMismatch { field: "scatterers.z", .. })));
    // output of the wrong size, plan too short for the scene, plan of another engine
    let plan = simus.plan_for_max_distance(0.01, 0.0).unwrap();
    let mut out = vec![0f32; 10];
    assert!(matches!(simus.simulate_into(&s, &pw0(&p), &plan, &mut out), Err(SimusError::OutputLength { .. })));
    let mut out = vec![0f32; p.n_elements * plan.n_samples];
    let deep = one(0.0, 0.1);
    let e = simus.simulate_into(&deep, &pw0(&p), &plan, &mut out).unwrap_err();
    assert!(matches!(e, SimusError::PlanTooShort { .. }), "{e}");
    let other = Simus::new(Probe::preset("L11-5v").unwrap(), Medium::default(), SimusOptions::default()).unwrap();
    let foreign = other.plan_for_max_distance(0.05, 0.0).unwrap();
    let mut out = vec![0f32; p.n_elements * foreign.n_samples];
    assert!(matches!(simus.simulate_into(&s, &pw0(&p), &foreign, &mut out), Err(SimusError::PlanMismatch(_))));
}

/// A fixed plan keeps the frame length and gain for a packet while the scene moves, where
/// MUST's per-call plan changes both (gain ∝ df).
#[test]
fn fixed_plan_keeps_length_and_gain_across_frames() {
    let p = Probe::paper_5mhz();
    let o = SimusOptions {
        plan: sonoflow_simus::PlanMode::MaxDistance { max_distance: 0.05, max_delay: 0.0 },
        ..SimusOptions::default()
    };
    let mut fixed = Simus::new(p.clone(), Medium::default(), o).unwrap();
    let mut per_call = engine();
    let near = Scatterers::new(vec![0.0, 0.0], vec![0.02, 0.025], vec![1.0, 0.0]).unwrap();
    let far = Scatterers::new(vec![0.0, 0.0], vec![0.02, 0.035], vec![1.0, 0.0]).unwrap(); // silent one deeper
    let (a, b) = (fixed.simulate(&near, &pw0(&p)).unwrap(), fixed.simulate(&far, &pw0(&p)).unwrap());
    assert_eq!(a.plan, b.plan);
    assert!(nrms(&b.data, &a.data) < 1e-6);
    let (c, d) = (per_call.simulate(&near, &pw0(&p)).unwrap(), per_call.simulate(&far, &pw0(&p)).unwrap());
    assert!(d.plan.df < c.plan.df && d.n_samples > c.n_samples);
    // MUST's gain ∝ df: the deeper silent scatterer lowers the echo of the first one
    let ratio = peak(&d.data) / peak(&c.data);
    assert!((f64::from(ratio) / (d.plan.df / c.plan.df) - 1.0).abs() < 1e-3, "{ratio}");
}
