//! Flags, errors, determinism (DAS + Doppler over thread counts), vector geometry (eq. 20) and the
//! clutter filter on synthetic data.
#![allow(clippy::unwrap_used)]

use sonoflow_beamform::testkit::{field_of, paper_das};
use sonoflow_beamform::{BeamformError, DasPlan, Grid, Rf2Iq, Rf2IqParams, RfView, TxWave, C32};
use sonoflow_doppler::testkit::{approaching_packet, degenerate_vector_solves, frame_refs, map_finite, phase_packet};
use sonoflow_doppler::{
    flags, nominal_projection, outlier_looks, solve_vector, solve_vector_weighted, ClutterFilter, DopplerEstimator,
    DopplerParams, Estimator, Packet, PacketParams, Projection, VectorField, VectorInput,
};

/// Zero signal gives "no estimate" with velocity 0 (never NaN); a phase step of ±0.95π per frame
/// (|v| = 0.95 V_N) is flagged as aliasing; 0.5π is not; NaN input gives "no estimate".
/// A phase that *decreases* per frame (x_n conj(x_{n+1}) has positive phase) is motion away
/// from the probe: negative velocity.
#[test]
fn doppler_flags_zero_signal_aliasing_and_sign() {
    let pi = std::f64::consts::PI;
    let steps = [None, Some(0.95 * pi), Some(-0.95 * pi), Some(0.5 * pi), Some(-0.5 * pi), Some(0.0)];
    let mut frames = phase_packet(&steps, 8);
    frames[3][5] = C32::new(f32::NAN, 0.0);
    let refs = frame_refs(&frames);
    for est in [Estimator::Autocorrelation, Estimator::Loupas] {
        let mut p = DopplerParams::new(5e6, 1540.0, 10e3);
        p.estimator = est;
        let vn = p.nyquist_velocity();
        let mut e = DopplerEstimator::new(p, steps.len(), 1, 1e-4).unwrap();
        let m = e.estimate_to_map(Packet::Frames(&refs)).unwrap();
        assert!(map_finite(&m));
        assert_eq!(m.flags, vec![flags::NO_ESTIMATE, flags::ALIASING, flags::ALIASING, 0, 0, flags::NO_ESTIMATE]);
        assert_eq!(m.velocity[0], 0.0);
        assert_eq!(m.velocity[5], 0.0);
        // phase +0.5π per frame: arg R1 = −0.5π ⇒ v = +V_N/2 (toward the probe)
        if est == Estimator::Autocorrelation {
            assert!((f64::from(m.velocity[3]) - 0.5 * vn).abs() < 1e-6 * vn, "{}", m.velocity[3]);
            assert!((f64::from(m.velocity[4]) + 0.5 * vn).abs() < 1e-6 * vn);
            assert!((f64::from(m.velocity[1]) - 0.95 * vn).abs() < 1e-5 * vn);
        }
    }
}

/// A scatterer moving toward the probe (echo delay decreasing by δ per frame) gives v > 0:
/// the I/Q phase is −2π fc τ, and v = c·δ·PRF/2.
#[test]
fn doppler_sign_toward_probe_from_delays() {
    let (fc, prf, c) = (5e6, 10e3, 1540.0);
    let v_true = 0.2; // toward the probe
    let frames = approaching_packet(fc, prf, c, v_true, 16);
    let refs = frame_refs(&frames);
    let mut e = DopplerEstimator::new(DopplerParams::new(fc, c, prf), 1, 1, 1e-4).unwrap();
    let m = e.estimate_to_map(Packet::Frames(&refs)).unwrap();
    assert!((f64::from(m.velocity[0]) - v_true).abs() < 1e-4, "{}", m.velocity[0]);
}

/// Vector-solve inputs of Doppler maps `vd` (one per receive angle) with nominal projections.
fn nominal_inputs<'a>(vd: &'a [Vec<f32>], flags: &'a [u8], tilt: f64, angles: &[f64]) -> Vec<VectorInput<'a>> {
    vd.iter()
        .zip(angles)
        .map(|(d, r)| VectorInput {
            velocity: d,
            flags,
            projection: Projection::Nominal { tx_tilt: tilt, rx_angle: *r },
        })
        .collect()
}

/// Paper eq. 20 (θt = 0, θr = ∓15°) equals our least squares with the paper's Doppler values
/// being the negatives of ours; the LS also recovers v for a steered transmit and 3 angles.
#[test]
fn vector_solve_matches_eq20_and_steered_geometry() {
    let phi = 15f64.to_radians();
    let v = [0.3, -0.2];
    for (tilt, angles) in [(0.0, vec![-phi, phi]), (10f64.to_radians(), vec![-phi, 0.0, phi]), (-0.2, vec![-0.3, 0.25])]
    {
        let vd: Vec<Vec<f32>> = angles
            .iter()
            .map(|r| {
                let a = nominal_projection(tilt, *r);
                vec![(a[0] * v[0] + a[1] * v[1]) as f32]
            })
            .collect();
        let fl = vec![0u8];
        let inputs = nominal_inputs(&vd, &fl, tilt, &angles);
        let mut f = VectorField::default();
        solve_vector(&inputs, &mut f).unwrap();
        assert!((f64::from(f.vx[0]) - v[0]).abs() < 1e-6 && (f64::from(f.vz[0]) - v[1]).abs() < 1e-6, "{f:?}");
        if tilt == 0.0 {
            // eq. 20 with v_D{1} at −15°, v_D{2} at +15°, paper sign = −ours
            let (d1, d2) = (-f64::from(vd[0][0]), -f64::from(vd[1][0]));
            let vx = (d2 - d1) / phi.sin();
            let vz = (d2 + d1) / (1.0 + phi.cos());
            assert!((vx - v[0]).abs() < 1e-6 && (vz - v[1]).abs() < 1e-6, "eq20 gives ({vx}, {vz})");
        }
    }
    // degenerate geometry (same angle twice) and flagged inputs → no estimate
    let [same, one_bad] = degenerate_vector_solves();
    assert_eq!(same, (flags::NO_ESTIMATE, 0.0, 0.0));
    assert_eq!(one_bad.0, flags::NO_ESTIMATE);
}

/// Weighted vector solve: equal weights reproduce `solve_vector` bit for bit; unequal weights
/// give the weighted least-squares solution of three inconsistent maps (here, with the third map
/// at 0° carrying a thousand times the weight, vz follows it: vz → −v_D(0°), to O(1/w));
/// weights that are not finite and positive are a clear error.
#[test]
fn weighted_vector_solve() {
    let phi = 15f64.to_radians();
    let angles = [-phi, phi, 0.0];
    let vd = [vec![0.05f32, -0.1], vec![-0.02f32, 0.3], vec![0.04f32, 0.2]];
    let fl = vec![0u8; 2];
    let inputs = nominal_inputs(&vd, &fl, 0.0, &angles);
    let (mut a, mut b) = (VectorField::default(), VectorField::default());
    solve_vector(&inputs, &mut a).unwrap();
    solve_vector_weighted(&inputs, &[1.0; 3], &mut b).unwrap();
    assert_eq!(a, b);
    solve_vector_weighted(&inputs, &[1.0, 1.0, 1e3], &mut b).unwrap();
    for (p, d0) in vd[2].iter().enumerate() {
        // the 0° map's projection is (0, −1): v_D = −vz; the ±15° maps pull by ~2/1000 of
        // their disagreement (< 0.4 m/s)
        assert!((f64::from(b.vz[p]) + f64::from(*d0)).abs() < 1e-3, "{b:?}");
        assert!((b.vz[p] - a.vz[p]).abs() > 1e-3, "weights change the solution: {a:?} {b:?}");
    }
    for w in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let e = solve_vector_weighted(&inputs, &[1.0, w, 1.0], &mut b).unwrap_err().to_string();
        assert!(e.contains("vector weights"), "{e}");
    }
    let e = solve_vector_weighted(&inputs, &[1.0, 1.0], &mut b).unwrap_err().to_string();
    assert!(e.contains("vector weights"), "{e}");
}

/// Look rejection: six looks (−15° … 15°) of one field (vx 0.3, vz 0.05 m/s) with ±2 mm/s noise;
/// one look garbage (uniform ±0.3 m/s, as a look whose blood the clutter filter removed): it is
/// the only one flagged, and solving without it recovers the field to the noise, while with it the
/// error is tens of mm/s. Consistent looks: none flagged; three looks: none (too few to judge); a factor
/// ≤ 1: an error naming `look_rejection`, as in the Doppler stage's parameters.
#[test]
fn look_rejection_leaves_out_a_failed_look() {
    let n = 2000;
    let angles: Vec<f64> = [-15.0f64, -9.0, -3.0, 3.0, 9.0, 15.0].iter().map(|a| a.to_radians()).collect();
    let (vx, vz) = (0.3, 0.05);
    let mut state = 11u64;
    let mut uniform = move || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let mut vd: Vec<Vec<f32>> = angles
        .iter()
        .map(|&r| {
            let a = nominal_projection(0.0, r);
            (0..n).map(|_| (a[0] * vx + a[1] * vz + 0.004 * uniform()) as f32).collect()
        })
        .collect();
    let clean = vd.clone();
    vd[2] = (0..n).map(|_| (0.6 * uniform()) as f32).collect();
    let fl = vec![0u8; n];
    let all = vec![true; n];
    let rms = |f: &VectorField| {
        let s: f64 = (0..n).map(|p| (f64::from(f.vx[p]) - vx).powi(2) + (f64::from(f.vz[p]) - vz).powi(2)).sum();
        (s / n as f64).sqrt()
    };
    let inputs = nominal_inputs(&vd, &fl, 0.0, &angles);
    let mut solved = VectorField::default();
    solve_vector(&inputs, &mut solved).unwrap();
    let (reject, medians) = outlier_looks(&inputs, &[1.0; 6], &all, 4.0).unwrap();
    assert_eq!(reject, [false, false, true, false, false, false], "medians {medians:?}");
    let kept: Vec<VectorInput> = (0..6).filter(|&i| !reject[i]).map(|i| inputs[i]).collect();
    let mut again = VectorField::default();
    solve_vector(&kept, &mut again).unwrap();
    let (before, after) = (rms(&solved), rms(&again));
    assert!(before > 0.05 && after < 0.01, "RMS error {before} with the failed look, {after} without");

    let consistent = nominal_inputs(&clean, &fl, 0.0, &angles);
    solve_vector(&consistent, &mut solved).unwrap();
    assert!(outlier_looks(&consistent, &[1.0; 6], &all, 4.0).unwrap().0.iter().all(|r| !r));
    let three = nominal_inputs(&vd[1..4], &fl, 0.0, &angles[1..4]);
    assert_eq!(outlier_looks(&three, &[1.0; 3], &all, 4.0).unwrap().0, [false, false, false]);
    for bad in [1.0, 0.5, f64::NAN] {
        let e = outlier_looks(&consistent, &[1.0; 6], &all, bad).unwrap_err().to_string();
        assert!(e.contains("look_rejection"), "{e}");
    }
    let p: PacketParams = serde_json::from_value(serde_json::json!({ "look_rejection": 0.5 })).unwrap();
    assert!(p.validate().unwrap_err().to_string().contains("look_rejection"));
    let p: PacketParams = serde_json::from_value(serde_json::json!({ "look_rejection": 0.0 })).unwrap();
    p.validate().unwrap();
    assert_eq!(PacketParams::default().look_rejection, 4.0);
}

/// Polynomial clutter filter: polynomials up to the order vanish, a Doppler tone far from DC
/// keeps > 90 % of its energy (order 1, 32 frames, 0.4π rad/frame).
#[test]
fn clutter_filter_removes_polynomials_keeps_flow() {
    let nf = 32;
    for order in 0..=3 {
        let f = ClutterFilter::new(order, nf).unwrap();
        let mut data: Vec<C32> = (0..nf)
            .map(|n| {
                let t = n as f32 / 10.0;
                C32::new(1.0 + 0.5 * t.powi(order as i32), -2.0 + t)
            })
            .collect();
        if order == 0 {
            for d in &mut data {
                d.im = -2.0;
            }
        }
        f.apply_pixel_major(&mut data).unwrap();
        let e: f32 = data.iter().map(|c| c.norm_sqr()).sum();
        assert!(e < 1e-8, "order {order}: residual energy {e}");
    }
    let f = ClutterFilter::new(1, nf).unwrap();
    let mut tone: Vec<C32> = (0..nf).map(|n| C32::from_polar(1.0, 0.4 * std::f32::consts::PI * n as f32)).collect();
    let mut frames: Vec<&mut [C32]> = tone.chunks_mut(1).collect();
    f.apply_frames(&mut frames).unwrap();
    let e: f32 = tone.iter().map(|c| c.norm_sqr()).sum::<f32>() / nf as f32;
    assert!(e > 0.9 && e <= 1.0, "{e}");
    assert!(matches!(ClutterFilter::new(31, 32), Err(BeamformError::InvalidParameter { field: "clutter.order", .. })));
}

/// DAS and Doppler outputs are bit-identical for 1, 2 and 3 threads.
#[test]
fn results_do_not_depend_on_thread_count() {
    let ns = 600;
    let iq: Vec<C32> = (0..128 * ns)
        .map(|i| C32::new(((i * 7919) % 1013) as f32 / 1013.0 - 0.5, ((i * 104_729) % 997) as f32 / 997.0 - 0.5))
        .collect();
    let grid = Grid::spanning(-5e-3, 5e-3, 50, 5e-3, 20e-3, 40).unwrap();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let plan = DasPlan::new(&paper_das(3.0, 0.2, 20e6), &TxWave::PlaneWave { tilt: 0.1 }, &grid, ns).unwrap();
            let imgs: Vec<Vec<C32>> = (0..6)
                .map(|k| {
                    plan.apply_to_vec(&iq.iter().cycle().skip(k * 10).take(iq.len()).copied().collect::<Vec<_>>())
                        .unwrap()
                })
                .collect();
            let refs: Vec<&[C32]> = imgs.iter().map(|v| v.as_slice()).collect();
            let mut p = DopplerParams::new(5e6, 1540.0, 5e3);
            p.window = [3, 5];
            p.estimator = Estimator::Loupas;
            let m = DopplerEstimator::for_plan(p, &plan).unwrap().estimate_to_map(Packet::Frames(&refs)).unwrap();
            let mut rf2iq = Rf2Iq::new(Rf2IqParams::new(5e6, 20e6, Some(75.0))).unwrap();
            let rf: Vec<f32> = iq.iter().map(|c| c.re).collect();
            let q = rf2iq.process_to_vec(RfView::element_major(&rf, ns, 128)).unwrap();
            (imgs, m, q)
        })
    };
    let a = run(1);
    for t in [2, 3] {
        let b = run(t);
        assert!(a.0 == b.0 && a.1 == b.1 && a.2 == b.2, "{t} threads differ");
    }
}

/// Bad Doppler parameters and packets give errors naming the field; no panics.
#[test]
fn bad_doppler_input_gives_named_errors() {
    // doppler
    let d = |f: &dyn Fn(&mut DopplerParams)| {
        let mut p = DopplerParams::new(5e6, 1540.0, 1e4);
        f(&mut p);
        field_of(DopplerEstimator::new(p, 4, 4, 1e-4).unwrap_err())
    };
    assert_eq!(d(&|p| p.prf = 0.0), "doppler.prf");
    assert_eq!(d(&|p| p.lag = 0), "doppler.lag");
    assert_eq!(d(&|p| p.window = [0, 3]), "doppler.window");
    assert_eq!(d(&|p| p.alias_fraction = 1.5), "doppler.alias_fraction");
    let mut est = DopplerEstimator::new(DopplerParams::new(5e6, 1540.0, 1e4), 2, 2, 1e-4).unwrap();
    let f = [C32::new(1.0, 0.0); 4];
    let one: [&[C32]; 1] = [&f];
    assert_eq!(field_of(est.estimate_to_map(Packet::Frames(&one)).unwrap_err()), "packet frames");
    let short = [C32::new(1.0, 0.0); 3];
    let two: [&[C32]; 2] = [&f, &short];
    assert_eq!(field_of(est.estimate_to_map(Packet::Frames(&two)).unwrap_err()), "packet frame");
    let d: DopplerParams = serde_json::from_str(r#"{"fc":5e6,"PRF":1e4,"window":[3,3],"estimator":"loupas"}"#).unwrap();
    assert_eq!((d.prf, d.estimator), (1e4, Estimator::Loupas));
}

/// The two packet layouts (frame-major as the node streams it, pixel-major as the batch tool and
/// the Python package pass it) give bit-identical maps — both sum each pixel's frames in the
/// same four interleaved partial sums — and R0, R_L agree with a plain sequential sum to 1e-12
/// (an independent computation; frame counts that are and are not multiples of 4).
#[test]
fn frame_and_pixel_major_packets_give_identical_maps() {
    let (nx, nz) = (7, 5);
    for (nf, lag) in [(13usize, 2usize), (16, 1), (5, 4)] {
        let frames: Vec<Vec<C32>> = (0..nf)
            .map(|k| {
                (0..nx * nz)
                    .map(|p| {
                        let ph = 0.37 * (k * (p % 5 + 1)) as f32 + 0.11 * p as f32;
                        C32::new(ph.cos() * (1.0 + p as f32 * 0.01), ph.sin() + 0.05 * (k as f32).sin())
                    })
                    .collect()
            })
            .collect();
        let pixel: Vec<C32> = (0..nx * nz).flat_map(|p| frames.iter().map(move |f| f[p])).collect();
        let mut p = DopplerParams::new(5e6, 1540.0, 10e3);
        p.lag = lag;
        p.window = [3, 2];
        let refs = frame_refs(&frames);
        let a = DopplerEstimator::new(p.clone(), nx, nz, 1e-4).unwrap().estimate_to_map(Packet::Frames(&refs)).unwrap();
        let b = DopplerEstimator::new(p.clone(), nx, nz, 1e-4)
            .unwrap()
            .estimate_to_map(Packet::PixelMajor { data: &pixel, n_frames: nf })
            .unwrap();
        assert!(a.velocity == b.velocity && a.variance == b.variance && a.power == b.power, "nf {nf}");
        p.window = [1, 1];
        let mut e = DopplerEstimator::new(p, nx, nz, 1e-4).unwrap();
        e.estimate_to_map(Packet::Frames(&refs)).unwrap();
        let (r0, rl) = e.autocorrelation();
        for pix in 0..nx * nz {
            let c = |x: C32| num_complex::Complex64::new(f64::from(x.re), f64::from(x.im));
            let s0: f64 = (0..nf).map(|k| c(frames[k][pix]).norm_sqr()).sum();
            let sl: num_complex::Complex64 =
                (0..nf - lag).map(|k| c(frames[k][pix]) * c(frames[k + lag][pix]).conj()).sum();
            assert!((r0[pix] - s0).abs() <= 1e-12 * s0, "R0 pixel {pix}");
            assert!((rl[pix] - sl).norm() <= 1e-12 * s0, "R_L pixel {pix}");
        }
    }
}
