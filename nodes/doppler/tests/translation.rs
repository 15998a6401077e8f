//! Uniform translation of a scatterer cloud at a known velocity, RF from SIMUS, PRF 10 kHz:
//! the Doppler velocity per receive angle is the projection of v on the bisector, and the
//! vector solve recovers (vx, vz), for a 0° and a 10° steered transmit.
#![allow(clippy::unwrap_used)]

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sonoflow_beamform::testkit::{paper_das, RfSim};
use sonoflow_beamform::{DasPlan, Grid, TxWave, C32};
use sonoflow_doppler::{
    flags, nominal_projection, solve_vector, DopplerEstimator, DopplerParams, Estimator, Packet, Projection,
    VectorField, VectorInput,
};
use sonoflow_simus::{Scatterers, Transmit};

const PRF: f64 = 10e3;
const N_FRAMES: usize = 16;

fn cloud(seed: u64) -> (Vec<f64>, Vec<f64>, Vec<f32>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = 4000;
    let x = (0..n).map(|_| rng.gen_range(-8e-3..8e-3)).collect();
    let z = (0..n).map(|_| rng.gen_range(12e-3..28e-3)).collect();
    let a = (0..n).map(|_| rng.gen_range(-1.0f32..1.0)).collect();
    (x, z, a)
}

struct Result1 {
    /// ROI mean of v_D per receive angle: (autocorrelation, Loupas), and the nominal expectation.
    per_angle: Vec<(f64, f64, f64, f64)>,
    vec_nominal: (f64, f64),
    vec_plan: (f64, f64),
}

fn run(tilt_deg: f64, v: [f64; 2]) -> Result1 {
    let tilt = tilt_deg.to_radians();
    let mut sim = RfSim::new(0.045, 5e-6);
    let tx = Transmit::plane_wave(&sim.probe, 1540.0, tilt).unwrap();
    let (x0, z0, a) = cloud(7);
    let frames: Vec<Vec<C32>> = (0..N_FRAMES)
        .map(|n| {
            let t = n as f64 / PRF;
            let x: Vec<f32> = x0.iter().map(|x| (x + v[0] * t) as f32).collect();
            let z: Vec<f32> = z0.iter().map(|z| (z + v[1] * t) as f32).collect();
            sim.iq(&Scatterers::new(x, z, a.clone()).unwrap(), &tx)
        })
        .collect();
    let grid = Grid::spanning(-3e-3, 3e-3, 61, 17e-3, 23e-3, 61).unwrap();
    let wave = TxWave::PlaneWave { tilt };
    let mut per_angle = Vec::new();
    let mut maps = Vec::new();
    let mut plans = Vec::new();
    for rx_deg in [-15.0f64, 0.0, 15.0] {
        let rx = rx_deg.to_radians();
        let plan = DasPlan::new(&paper_das(3.0, rx, sim.plan.fs), &wave, &grid, sim.plan.n_samples).unwrap();
        let imgs: Vec<Vec<C32>> = frames.iter().map(|f| plan.apply_to_vec(f).unwrap()).collect();
        let refs: Vec<&[C32]> = imgs.iter().map(|v| v.as_slice()).collect();
        let mut p = DopplerParams::new(5e6, 1540.0, PRF);
        let ac = DopplerEstimator::for_plan(p.clone(), &plan).unwrap().estimate_to_map(Packet::Frames(&refs)).unwrap();
        p.estimator = Estimator::Loupas;
        let lo = DopplerEstimator::for_plan(p, &plan).unwrap().estimate_to_map(Packet::Frames(&refs)).unwrap();
        let mean = |v: &[f32]| v.iter().map(|x| f64::from(*x)).sum::<f64>() / v.len() as f64;
        let a = nominal_projection(tilt, rx);
        let want = a[0] * v[0] + a[1] * v[1];
        assert!(ac.flags.iter().all(|f| *f == 0), "unexpected flags");
        per_angle.push((mean(&ac.velocity), mean(&lo.velocity), want, mean(&lo.mean_frequency)));
        if rx_deg != 0.0 {
            maps.push((lo, rx));
            plans.push(plan);
        }
    }
    let proj: Vec<Vec<[f32; 2]>> = plans.iter().map(|p| p.projection()).collect();
    let mean2 = |f: &VectorField| {
        let n = f.vx.len() as f64;
        (f.vx.iter().map(|x| f64::from(*x)).sum::<f64>() / n, f.vz.iter().map(|x| f64::from(*x)).sum::<f64>() / n)
    };
    let inputs: Vec<VectorInput> = maps
        .iter()
        .map(|(m, rx)| VectorInput {
            velocity: &m.velocity,
            flags: &m.flags,
            projection: Projection::Nominal { tx_tilt: tilt, rx_angle: *rx },
        })
        .collect();
    let mut f = VectorField::default();
    solve_vector(&inputs, &mut f).unwrap();
    assert!(f.flags.iter().all(|x| *x & flags::NO_ESTIMATE == 0));
    let vec_nominal = mean2(&f);
    let inputs: Vec<VectorInput> = maps
        .iter()
        .zip(&proj)
        .map(|((m, _), a)| VectorInput { velocity: &m.velocity, flags: &m.flags, projection: Projection::PerPixel(a) })
        .collect();
    solve_vector(&inputs, &mut f).unwrap();
    let vec_plan = mean2(&f);
    Result1 { per_angle, vec_nominal, vec_plan }
}

fn print(tilt: f64, v: [f64; 2], r: &Result1) {
    for ((ac, lo, want, fm), rx) in r.per_angle.iter().zip([-15, 0, 15]) {
        println!(
            "tilt {tilt}° rx {rx:+}°: v_D expected {want:+.4}, autocorr {ac:+.4} ({:+.2} %), Loupas {lo:+.4} ({:+.2} %), mean f {:.3} MHz",
            100.0 * (ac - want) / want.abs(),
            100.0 * (lo - want) / want.abs(),
            fm / 1e6
        );
    }
    println!(
        "tilt {tilt}°: vector (Loupas maps) nominal geometry ({:+.4}, {:+.4}), plan geometry ({:+.4}, {:+.4}); true ({}, {})",
        r.vec_nominal.0, r.vec_nominal.1, r.vec_plan.0, r.vec_plan.1, v[0], v[1]
    );
}

/// Pure axial motion (no lateral decorrelation): the only error left is the frequency used to
/// convert phase to velocity. The echoes' mean frequency is below fc (pulse-echo spectrum
/// centroid 4.97 MHz, lowered further by the receive directivity; Loupas measures 4.87–4.99
/// MHz), so eq. 19 with fc underestimates |v_D| by 0.5–3 %, and Loupas' estimator, which
/// measures the mean frequency, must be within 0.6 % (ROI of 61×61 px, 16 frames; the residual
/// is the aperture-averaged geometry, ≲ 0.3 %) and at least twice as accurate at 0°.
#[test]
fn axial_translation_autocorrelation_bias_and_loupas() {
    let v = [0.0, 0.15];
    let r = run(0.0, v);
    print(0.0, v, &r);
    for (i, (ac, lo, want, _)) in r.per_angle.iter().enumerate() {
        let (e_ac, e_lo) = ((ac - want) / want.abs(), (lo - want) / want.abs());
        assert!(e_ac > 0.002 && e_ac < 0.035, "angle {i}: autocorrelation error {e_ac}");
        assert!(e_lo.abs() < 0.006, "angle {i}: Loupas error {e_lo}");
    }
    let (ac, lo, want, _) = r.per_angle[1];
    assert!((lo - want).abs() < 0.5 * (ac - want).abs());
    assert!((r.vec_plan.0 - v[0]).abs() < 0.01 * 0.15 / 0.259 * 4.0 && (r.vec_plan.1 - v[1]).abs() < 0.006 * 0.15);
}

/// Oblique translation |v| = 0.29 m/s (V_N = 0.77 m/s) with a 0° and a 10° transmit. Lateral
/// motion decorrelates the speckle, so each ROI mean fluctuates: measured ±2 % of |v| between
/// two scatterer seeds, on top of the ≤ 3 % frequency bias of eq. 19. Tolerances: Doppler per
/// angle within 6 % of |v| (autocorrelation) and 4 % (Loupas); vector (from the Loupas maps,
/// ±15°) within 4 % of |v| for vz and 12 % of |v| for vx, whose errors are the difference of
/// the two Doppler errors amplified by 1/sin 15° = 3.9 (the paper reports vx errors within
/// ±10 % for 75 % of its pixels).
#[test]
fn oblique_translation_doppler_per_angle_and_vector() {
    let v = [0.25f64, 0.15];
    let speed = v[0].hypot(v[1]);
    for tilt in [0.0, 10.0] {
        let r = run(tilt, v);
        print(tilt, v, &r);
        for (ac, lo, want, _) in &r.per_angle {
            assert!((ac - want).abs() < 0.06 * speed, "tilt {tilt}: autocorrelation {ac} vs {want}");
            assert!((lo - want).abs() < 0.04 * speed, "tilt {tilt}: Loupas {lo} vs {want}");
        }
        for (vx, vz) in [r.vec_nominal, r.vec_plan] {
            assert!((vz - v[1]).abs() < 0.04 * speed, "tilt {tilt}: vz {vz}");
            assert!((vx - v[0]).abs() < 0.12 * speed, "tilt {tilt}: vx {vx}");
        }
    }
}
