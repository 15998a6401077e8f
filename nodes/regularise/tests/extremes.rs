//! Extreme inputs, errors, parameters, workspace reuse and thread-count determinism.
#![allow(clippy::unwrap_used)] // test helpers outside #[test] functions
use sonoflow_regularise::testkit::*;
use sonoflow_regularise::{smoothn, Smoothn, SmoothnError, SmoothnParams, WeightFunction};

#[test]
fn all_nan_input_is_a_clear_error() {
    let y = vec![f64::NAN; 2 * 30];
    let err = smoothn(&y, &[5, 6], 2, None, &SmoothnParams::default()).unwrap_err();
    assert_eq!(err, SmoothnError::NoValidData { points: 30 });
    assert!(err.to_string().contains("no valid data"), "{err}");
    // Also when every point is missing in at least one component, or every weight is 0.
    let mut y = vec![1.0; 60];
    y[..30].fill(f64::INFINITY);
    assert!(matches!(smoothn(&y, &[5, 6], 2, None, &SmoothnParams::default()), Err(SmoothnError::NoValidData { .. })));
    let w = vec![0.0; 30];
    let y = vec![1.0; 60];
    assert!(matches!(
        smoothn(&y, &[5, 6], 2, Some(&w), &SmoothnParams::default()),
        Err(SmoothnError::NoValidData { .. })
    ));
    assert!(matches!(
        smoothn(&[f64::NAN], &[1, 1], 1, None, &SmoothnParams::default()),
        Err(SmoothnError::NoValidData { .. })
    ));
}

#[test]
fn infinities_are_treated_exactly_like_nan() {
    let [(a, ra), (b, rb)] = nan_and_infinity_runs();
    assert_eq!(a, b);
    assert_eq!(ra, rb);
    assert!(a.iter().all(|v| v.is_finite()));
}

#[test]
fn single_row_and_single_column_equal_the_1d_smoother() {
    let y: Vec<f64> = (0..50).map(|i| (i as f64 * 0.3).sin() + if i % 5 == 0 { 0.4 } else { 0.0 }).collect();
    for params in [SmoothnParams::default(), robust_auto(), SmoothnParams { s: Some(4.0), ..SmoothnParams::default() }]
    {
        let (z1, r1) = smoothn(&y, &[50], 1, None, &params).unwrap();
        let (zr, rr) = smoothn(&y, &[1, 50], 1, None, &params).unwrap();
        let (zc, rc) = smoothn(&y, &[50, 1], 1, None, &params).unwrap();
        assert_eq!(z1, zr);
        assert_eq!(z1, zc);
        assert_eq!((r1.s, r1.s_bounds), (rr.s, rr.s_bounds));
        assert_eq!((r1.s, r1.s_bounds), (rc.s, rc.s_bounds));
        assert!(rms_diff(&z1, &y) > 0.01, "something was smoothed");
    }
}

#[test]
fn constant_field_is_returned_unchanged() {
    for (shape, comps) in [(vec![12, 17], 2), (vec![40], 1), (vec![3, 4, 5], 1)] {
        let n: usize = shape.iter().product();
        let y: Vec<f64> = (0..n * comps).map(|i| if i < n { 2.5 } else { -1.25 }).collect();
        for params in
            [SmoothnParams::default(), robust_auto(), SmoothnParams { s: Some(1e3), ..SmoothnParams::default() }]
        {
            let (z, r) = smoothn(&y, &shape, comps, None, &params).unwrap();
            // The constant is the k = 0 DCT coefficient, which Γ keeps exactly; rounding only.
            assert!(max_abs_diff(&z, &y) < 1e-13, "shape {shape:?} {params:?}: {}", max_abs_diff(&z, &y));
            assert!(r.s.is_finite() && r.s > 0.0);
        }
    }
}

#[test]
fn one_by_one_grid_returns_the_value() {
    let (z, r) = smoothn(&[3.0, -2.0], &[1, 1], 2, None, &robust_auto()).unwrap();
    assert_eq!(z, vec![3.0, -2.0]);
    assert!(r.converged);
    let (z, r) = smoothn(&[7.0], &[1], 1, None, &SmoothnParams { s: Some(2.0), ..SmoothnParams::default() }).unwrap();
    assert_eq!((z[0], r.s), (7.0, 2.0));
}

#[test]
fn large_grid_runs_with_memory_linear_in_the_grid() {
    // 2 × 1000 × 1000 with a given S, one iteration, and a missing value (so the nearest-fill
    // buffers are allocated too).
    let bytes_per_point = |ny: usize, nx: usize| {
        let n = ny * nx;
        let mut y: Vec<f64> =
            (0..2 * n).map(|i| ((i % nx) as f64 * 0.01).sin() + ((i / nx) as f64 * 0.003).cos()).collect();
        y[n / 3] = f64::NAN;
        let mut ws = Smoothn::new(&[ny, nx], 2).unwrap();
        let mut z = vec![0.0; 2 * n];
        let p = SmoothnParams { s: Some(10.0), max_iter: 1, ..SmoothnParams::default() };
        ws.smooth(&y, None, &p, &mut z).unwrap();
        assert!(z.iter().all(|v| v.is_finite()));
        ws.workspace_bytes() as f64 / n as f64
    };
    let small = bytes_per_point(100, 100);
    let large = bytes_per_point(1000, 1000);
    // 2 components × 5 buffers + 6 shared f64 buffers + masks + nearest-fill (f64 + usize) ≈ 150 B
    // per point; a dense operator would need ≥ 8·n bytes per point (8 MB here).
    assert!(large < 200.0, "{large} bytes per grid point");
    assert!((large / small - 1.0).abs() < 0.05, "{small} vs {large} bytes per point: not linear");
}

#[test]
fn errors_name_the_problem() {
    let y = vec![0.0; 12];
    let p = SmoothnParams::default();
    assert!(matches!(Smoothn::new(&[3, 0], 1), Err(SmoothnError::InvalidGrid { .. })));
    assert!(matches!(Smoothn::new(&[], 1), Err(SmoothnError::InvalidGrid { .. })));
    assert!(matches!(Smoothn::new(&[3, 4], 0), Err(SmoothnError::InvalidGrid { .. })));
    assert_eq!(
        smoothn(&y, &[3, 5], 1, None, &p).unwrap_err(),
        SmoothnError::LengthMismatch { what: "data", got: 12, expected: 15 }
    );
    assert_eq!(
        smoothn(&y, &[3, 4], 1, Some(&[1.0; 11]), &p).unwrap_err(),
        SmoothnError::LengthMismatch { what: "weights", got: 11, expected: 12 }
    );
    let mut w = vec![1.0; 12];
    w[4] = -0.5;
    assert_eq!(
        smoothn(&y, &[3, 4], 1, Some(&w), &p).unwrap_err(),
        SmoothnError::InvalidWeight { index: 4, value: -0.5 }
    );
    w[4] = f64::NAN;
    assert!(matches!(smoothn(&y, &[3, 4], 1, Some(&w), &p), Err(SmoothnError::InvalidWeight { index: 4, .. })));
    let sp = SmoothnParams { spacing: Some(vec![1.0]), ..SmoothnParams::default() };
    assert_eq!(smoothn(&y, &[3, 4], 1, None, &sp).unwrap_err(), SmoothnError::SpacingLength { got: 1, expected: 2 });
    let mut out = vec![0.0; 5];
    let e = Smoothn::new(&[3, 4], 1).unwrap().smooth(&y, None, &p, &mut out).unwrap_err();
    assert_eq!(e, SmoothnError::LengthMismatch { what: "out", got: 5, expected: 12 });
}

#[test]
fn validate_names_the_field_and_the_allowed_range() {
    let field_of = |p: SmoothnParams| match p.validate() {
        Err(SmoothnError::InvalidParameter { field, allowed, .. }) => (field, allowed),
        other => panic!("expected an error, got {other:?}"),
    };
    let d = SmoothnParams::default;
    assert_eq!(field_of(SmoothnParams { s: Some(0.0), ..d() }).0, "s");
    assert_eq!(field_of(SmoothnParams { s: Some(-1.0), ..d() }).0, "s");
    assert_eq!(field_of(SmoothnParams { s: Some(f64::NAN), ..d() }).0, "s");
    assert_eq!(field_of(SmoothnParams { s: Some(f64::INFINITY), ..d() }).0, "s");
    assert_eq!(field_of(SmoothnParams { order: 0, ..d() }), ("order", "1, 2 or 3"));
    assert_eq!(field_of(SmoothnParams { order: 4, ..d() }).0, "order");
    assert_eq!(field_of(SmoothnParams { tol_z: 1.0, ..d() }).0, "tol_z");
    assert_eq!(field_of(SmoothnParams { tol_z: 0.0, ..d() }).0, "tol_z");
    assert_eq!(field_of(SmoothnParams { max_iter: 0, ..d() }).0, "max_iter");
    assert_eq!(field_of(SmoothnParams { spacing: Some(vec![1.0, -2.0]), ..d() }).0, "spacing");
    assert!(d().validate().is_ok());
    let e = smoothn(&[1.0, 2.0], &[2], 1, None, &SmoothnParams { order: 7, ..d() }).unwrap_err();
    assert!(e.to_string().contains("`order` = 7"), "{e}");
}

#[test]
fn params_deserialise_with_defaults_and_reject_unknown_fields() {
    let p: SmoothnParams = toml::from_str("robust = true\nweight_function = \"cauchy\"\nspacing = [1.0, 2.0]").unwrap();
    assert_eq!(
        p,
        SmoothnParams {
            robust: true,
            weight_function: WeightFunction::Cauchy,
            spacing: Some(vec![1.0, 2.0]),
            ..SmoothnParams::default()
        }
    );
    assert!(toml::from_str::<SmoothnParams>("smoothness = 3.0").is_err());
    let json = serde_json::to_string(&SmoothnParams { s: Some(3.0), ..SmoothnParams::default() }).unwrap();
    assert_eq!(serde_json::from_str::<SmoothnParams>(&json).unwrap().s, Some(3.0));
}

#[test]
fn a_reused_workspace_gives_the_same_result_as_a_fresh_one() {
    let truth = smooth_field(24, 18);
    let (mut y1, _) = corrupt(&truth, 2, 0.1, 0.1, 3);
    y1[10] = f64::NAN;
    let (y2, _) = corrupt(&truth, 2, 0.05, 0.0, 4);
    let p2 = SmoothnParams { order: 3, spacing: Some(vec![1.0, 2.0]), ..SmoothnParams::default() };
    let mut ws = Smoothn::new(&[24, 18], 2).unwrap();
    let mut z = vec![0.0; y1.len()];
    ws.smooth(&y1, None, &robust_auto(), &mut z).unwrap();
    let r2 = ws.smooth(&y2, None, &p2, &mut z).unwrap();
    let (fresh, rf) = smoothn(&y2, &[24, 18], 2, None, &p2).unwrap();
    assert_eq!(z, fresh);
    assert_eq!(r2, rf);
    assert!(ws.robust_weights().iter().all(|w| *w == 1.0), "no robust weights left over");
}

#[test]
fn results_are_bit_identical_for_any_thread_count() {
    // Three components (rayon splits them over threads), missing values, robust, automatic S, and a
    // grid larger than one chunk of the element-wise kernels (4096 points) so those split too.
    let (ny, nx) = (72, 64);
    let n = ny * nx;
    let truth: Vec<f64> = smooth_field(ny, nx).into_iter().chain((0..n).map(|p| (p as f64 * 0.01).cos())).collect();
    let (mut y, _) = corrupt(&truth, 3, 0.1, 0.1, 5);
    for p in [5, 99, 400, 401, 402] {
        y[2 * n + p] = f64::NAN;
    }
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| smoothn(&y, &[ny, nx], 3, None, &robust_auto()).unwrap())
    };
    let (z1, r1) = run(1);
    for threads in [2, 3, 4] {
        let (z, r) = run(threads);
        assert!(z.iter().zip(&z1).all(|(a, b)| a.to_bits() == b.to_bits()), "{threads} threads differ");
        assert_eq!(r, r1);
    }
}

#[test]
fn automatic_s_stays_within_the_leverage_bounds_for_every_order() {
    let truth = smooth_field(32, 28);
    let (y, _) = corrupt(&truth, 2, 0.1, 0.0, 8);
    for order in 1..=3 {
        let (z, r) = smoothn(&y, &[32, 28], 2, None, &SmoothnParams { order, ..SmoothnParams::default() }).unwrap();
        assert!(r.s_bounds[0] <= r.s && r.s <= r.s_bounds[1], "order {order}: {r:?}");
        assert!(!r.s_at_bound, "order {order}: {r:?}");
        // GCV must pick a useful S: error well below the noise σ = 0.1 (measured 0.054, 0.029,
        // 0.027 for m = 1, 2, 3; the first-order penalty is the weaker prior for this field).
        let e = rms_diff(&z, &truth);
        assert!(e < if order == 1 { 0.07 } else { 0.04 }, "order {order}: error {e} vs noise 0.1");
    }
}
