//! The clutter (wall) filters against independent references: the IIR high-pass against the
//! Butterworth magnitude formula (and its own coefficients), the polynomial regression against
//! the closed-form energy it removes from a complex exponential, the SVD filter on a synthetic
//! packet whose tissue is 60 dB above the blood.

#![allow(clippy::unwrap_used)]

use num_complex::Complex;
use sonoflow_doppler::testkit::{frames_of, frequency_and_power, pixels_of, tissue_and_blood};
use sonoflow_doppler::{ClutterParams, IirHighPass, IirInit, PacketParams, SvdFilter, SvdRank, C32};
use std::f64::consts::{PI, TAU};

fn tone(f: f64, n: usize) -> Vec<Complex<f64>> {
    (0..n).map(|k| Complex::from_polar(1.0, TAU * f * k as f64)).collect()
}

fn filter(c: &ClutterParams, frames: &mut [Vec<C32>]) -> sonoflow_doppler::ClutterReport {
    let mut refs: Vec<&mut [C32]> = frames.iter_mut().map(|f| f.as_mut_slice()).collect();
    c.apply_frames(&mut refs).unwrap()
}

/// Steady-state gain of the IIR filter on long tones equals the Butterworth formula
/// |H|² = 1/(1 + (tan πf_c / tan πf)^(2N)) to 1e-9, which also equals |B/A| of its coefficients.
#[test]
fn iir_high_pass_follows_the_butterworth_response() {
    for (order, cutoff) in [(2, 0.1), (4, 0.1), (3, 0.03)] {
        let h = IirHighPass::new(order, cutoff, IirInit::Zero).unwrap();
        let (b, a) = h.coefficients();
        for f in [0.01, 0.05, 0.1, 0.2, 0.3, 0.45, -0.2] {
            let formula = h.response(f);
            let z = Complex::from_polar(1.0, -TAU * f);
            let eval = |c: &[f64]| c.iter().enumerate().map(|(k, ck)| z.powi(k as i32) * *ck).sum::<Complex<f64>>();
            let from_coeffs = (eval(b) / eval(a)).norm();
            assert!(
                (from_coeffs - formula).abs() < 1e-9,
                "order {order} fc {cutoff} f {f}: {from_coeffs} vs {formula}"
            );
            let mut x = tone(f, 6000);
            h.filter(&mut x);
            let gain = x[3000..].iter().map(|v| v.norm()).sum::<f64>() / 3000.0;
            assert!((gain - formula).abs() < 1e-9, "order {order} fc {cutoff} f {f}: measured {gain} vs {formula}");
        }
        assert!((h.response(cutoff) - 0.5f64.sqrt()).abs() < 1e-12, "−3 dB at the cut-off");
    }
}

/// `step` initialisation removes a still echo from the first frame on; `zero` rings.
#[test]
fn iir_step_initialisation_removes_a_still_echo_at_once() {
    let still = vec![Complex::new(3.0, -2.0); 16];
    for (init, quiet) in [(IirInit::Step, true), (IirInit::Zero, false)] {
        let mut x = still.clone();
        IirHighPass::new(4, 0.1, init).unwrap().filter(&mut x);
        let peak = x.iter().map(|v| v.norm()).fold(0.0, f64::max);
        assert_eq!(peak < 1e-9, quiet, "{init:?}: peak residual {peak}");
    }
}

/// Order 0 removes the mean: the energy left of a tone is 1 − |D_N(f)|² (Dirichlet kernel);
/// order 1 also removes the projection on the centred ramp (closed form).
#[test]
fn polynomial_regression_removes_the_closed_form_energy() {
    let n = 16;
    for f in [0.0, 0.01, 0.03, 0.08, 0.2, 0.5] {
        let x = tone(f, n);
        let mean: Complex<f64> = x.iter().sum::<Complex<f64>>() / n as f64;
        let c = (n - 1) as f64 / 2.0;
        let ramp: Complex<f64> = x.iter().enumerate().map(|(k, v)| v * (k as f64 - c)).sum();
        let ramp_norm2: f64 = (0..n).map(|k| (k as f64 - c).powi(2)).sum();
        let expect = [1.0 - mean.norm_sqr(), 1.0 - mean.norm_sqr() - ramp.norm_sqr() / ramp_norm2 / n as f64];
        if f > 0.0 {
            let dirichlet = (n as f64 * PI * f).sin() / (n as f64 * (PI * f).sin());
            assert!((expect[0] - (1.0 - dirichlet * dirichlet)).abs() < 1e-12);
        }
        for (order, want) in expect.iter().enumerate() {
            let mut frames = frames_of(std::slice::from_ref(&x));
            filter(&ClutterParams::Polynomial { order }, &mut frames);
            let left = frames.iter().map(|f| f[0].norm_sqr() as f64).sum::<f64>() / n as f64;
            assert!((left - want).abs() < 1e-6, "order {order}, f {f}: {left} vs {want}");
        }
    }
}

/// Tissue 60 dB above the blood (a still and a slowly moving component, 0 and 0.01 PRF) and blood
/// at 0.15 … 0.25 PRF: the adaptive SVD filter removes the two tissue components and leaves the
/// blood's mean Doppler frequency within 1 % and its power within 1 dB of the blood alone.
#[test]
fn svd_filter_removes_tissue_60_db_above_blood() {
    let (n_pix, n) = (3000, 32);
    for seed in [1u64, 2, 3] {
        let (mixed, blood) = tissue_and_blood(n_pix, n, 60.0, &[0.0, 0.01], (0.15, 0.25), seed);
        let (f_blood, p_blood) = frequency_and_power(&blood);
        let mut frames = frames_of(&mixed);
        let mut refs: Vec<&mut [C32]> = frames.iter_mut().map(|f| f.as_mut_slice()).collect();
        let svd = SvdFilter::new(SvdRank::Adaptive { tissue_cutoff: 0.05, max_rank: None, gap_db: None }).unwrap();
        let out = svd.apply_frames(&mut refs).unwrap();
        assert_eq!(out.rank, 2, "seed {seed}: frequencies {:?}", &out.frequencies[..4]);
        assert!(out.removed_energy > 0.999, "{}", out.removed_energy);
        let (f, p) = frequency_and_power(&pixels_of(&frames));
        assert!(((f - f_blood) / f_blood).abs() < 0.01, "seed {seed}: {f} vs blood alone {f_blood}");
        let db = 10.0 * (p / p_blood).log10();
        eprintln!("seed {seed}: rank {}, frequency {f:.5} vs {f_blood:.5}, power {db:+.3} dB", out.rank);
        assert!(db.abs() < 1.0, "seed {seed}: power {db:+.2} dB from the blood alone");
    }
}

/// Per-pixel slow-time signals.
type Pixels = Vec<Vec<Complex<f64>>>;

/// A deterministic uniform generator in [0, 1) (splitmix64).
fn uniform(state: &mut u64) -> f64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
}

/// Slow blood as real blood echoes are: per pixel six scatterers crossing the beam (Gaussian
/// transit envelope, 1/e half-width 8 frames, centres anywhere from before to after the packet)
/// at one Doppler frequency in `band` (flow nearly across the beam), unit mean power, plus white
/// noise 20 dB below it; and tissue 60 dB above the blood, a still component and one at 0.002 PRF
/// (a pulsating wall). Returns (tissue + blood + noise, blood + noise).
fn slow_blood_under_tissue(n_pix: usize, n: usize, band: (f64, f64), seed: u64) -> (Pixels, Pixels) {
    let mut s = seed;
    let phasor = |s: &mut u64| Complex::from_polar(1.0, TAU * uniform(s));
    let gauss = |s: &mut u64| {
        let (u, v) = (uniform(s).max(1e-300), uniform(s));
        Complex::from_polar((-u.ln()).sqrt(), TAU * v)
    };
    let mut blood: Vec<Vec<Complex<f64>>> = (0..n_pix)
        .map(|_| {
            let f = band.0 + (band.1 - band.0) * uniform(&mut s);
            let mut x = vec![Complex::new(0.0, 0.0); n];
            for _ in 0..6 {
                let (centre, ph) = (-10.0 + 52.0 * uniform(&mut s), phasor(&mut s));
                for (t, v) in x.iter_mut().enumerate() {
                    let env = (-((t as f64 - centre) / 8.0).powi(2)).exp();
                    *v += ph * env * Complex::from_polar(1.0, TAU * f * t as f64);
                }
            }
            x
        })
        .collect();
    let power = blood.iter().flatten().map(|v| v.norm_sqr()).sum::<f64>() / (n_pix * n) as f64;
    for x in blood.iter_mut() {
        for v in x.iter_mut() {
            *v = *v / power.sqrt() + gauss(&mut s) * 0.1;
        }
    }
    let mixed = blood
        .iter()
        .map(|b| {
            let (a0, a1) = (gauss(&mut s) * 1000.0, gauss(&mut s) * 1000.0);
            b.iter().enumerate().map(|(t, v)| v + a0 + a1 * Complex::from_polar(1.0, TAU * 0.002 * t as f64)).collect()
        })
        .collect();
    (mixed, blood)
}

/// Slow blood (0.004 … 0.03 PRF, flow nearly across the beam) under slow tissue 60 dB above it:
/// the frequency rule alone (cut-off 0.05 PRF) counts the blood's slow components as tissue and
/// removes them; with the energy gap (`gap_db` = 10) the rank stops at the tissue's two
/// components and most of the blood's echo stays. Blood alone: the gap rule removes nothing.
#[test]
fn svd_energy_gap_keeps_slow_blood() {
    let (n_pix, n) = (2000, 32);
    let rule = |gap_db| SvdFilter::new(SvdRank::Adaptive { tissue_cutoff: 0.05, max_rank: None, gap_db }).unwrap();
    for seed in [1u64, 2, 3] {
        let (mixed, blood) = slow_blood_under_tissue(n_pix, n, (0.004, 0.03), seed);
        let (_, p_blood) = frequency_and_power(&blood);
        let mut kept = Vec::new();
        for gap in [None, Some(10.0)] {
            let mut frames = frames_of(&mixed);
            let mut refs: Vec<&mut [C32]> = frames.iter_mut().map(|f| f.as_mut_slice()).collect();
            let out = rule(gap).apply_frames(&mut refs).unwrap();
            let (_, p) = frequency_and_power(&pixels_of(&frames));
            let db = 10.0 * (p / p_blood).log10();
            eprintln!("seed {seed}, gap {gap:?}: rank {}, blood power {db:+.2} dB", out.rank);
            kept.push((out.rank, db));
        }
        assert!(kept[0].0 > 4, "seed {seed}: the frequency rule removes blood too: {kept:?}");
        assert_eq!(kept[1].0, 2, "seed {seed}: the gap ends the tissue subspace: {kept:?}");
        assert!(kept[1].1 > kept[0].1 + 6.0, "seed {seed}: the gap keeps ≥ 6 dB more blood: {kept:?}");
        let mut frames = frames_of(&blood);
        let mut refs: Vec<&mut [C32]> = frames.iter_mut().map(|f| f.as_mut_slice()).collect();
        assert_eq!(rule(Some(10.0)).apply_frames(&mut refs).unwrap().rank, 0, "seed {seed}: blood alone");
    }
    for bad in [0.0, -3.0, f64::NAN, 200.0] {
        let e = SvdFilter::new(SvdRank::Adaptive { tissue_cutoff: 0.05, max_rank: None, gap_db: Some(bad) })
            .unwrap_err()
            .to_string();
        assert!(e.contains("clutter.gap_db"), "{e}");
    }
}

/// Degenerate packets get clear outcomes: two frames work (rank ≤ 1), a fixed rank that would
/// remove the whole packet and non-finite samples are errors naming the field, an adaptive rank
/// never removes everything, a packet of tissue only is left near zero, not NaN.
#[test]
fn svd_filter_degenerate_packets() {
    let still: Vec<Vec<Complex<f64>>> = (0..50).map(|p| vec![Complex::new(1.0 + p as f64, 0.5); 2]).collect();
    let mut frames = frames_of(&still);
    let mut refs: Vec<&mut [C32]> = frames.iter_mut().map(|f| f.as_mut_slice()).collect();
    let adaptive = SvdFilter::new(SvdRank::Adaptive { tissue_cutoff: 0.05, max_rank: Some(10), gap_db: None }).unwrap();
    let out = adaptive.apply_frames(&mut refs).unwrap();
    assert_eq!(out.rank, 1, "capped below the packet size");
    assert!(frames.iter().flatten().all(|v| v.re.is_finite() && v.norm() < 1e-3), "tissue only: ~0 left");

    let mut frames = frames_of(&still);
    let mut refs: Vec<&mut [C32]> = frames.iter_mut().map(|f| f.as_mut_slice()).collect();
    let e = SvdFilter::new(SvdRank::Fixed(2)).unwrap().apply_frames(&mut refs).unwrap_err().to_string();
    assert!(e.contains("clutter.rank = 2") && e.contains("2 frames"), "{e}");
    frames[1][7].re = f32::NAN;
    let mut refs: Vec<&mut [C32]> = frames.iter_mut().map(|f| f.as_mut_slice()).collect();
    let e = adaptive.apply_frames(&mut refs).unwrap_err().to_string();
    assert!(e.contains("non-finite"), "{e}");
    let mut one = [vec![C32::new(1.0, 0.0); 4]];
    let mut refs: Vec<&mut [C32]> = one.iter_mut().map(|f| f.as_mut_slice()).collect();
    assert!(adaptive.apply_frames(&mut refs).unwrap_err().to_string().contains("≥ 2 frames"));
    assert!(SvdFilter::new(SvdRank::Fixed(0)).is_err());
    let e =
        SvdFilter::new(SvdRank::Adaptive { tissue_cutoff: 0.7, max_rank: None, gap_db: None }).unwrap_err().to_string();
    assert!(e.contains("clutter.tissue_cutoff"), "{e}");
}

/// The Doppler stage's `clutter` table: the three types with defaults (SVD: adaptive with the
/// 10 dB energy gap; `gap_db = 0` turns the gap off), errors naming the field, one filter only.
#[test]
fn clutter_table_of_the_doppler_stage() {
    let p: PacketParams = serde_json::from_value(serde_json::json!({ "clutter": { "type": "svd" } })).unwrap();
    assert_eq!(p.clutter, Some(ClutterParams::Svd { rank: None, tissue_cutoff: 0.05, max_rank: None, gap_db: 10.0 }));
    p.validate().unwrap();
    let p: PacketParams =
        serde_json::from_value(serde_json::json!({ "clutter": { "type": "iir", "order": 4, "cutoff": 0.1 } })).unwrap();
    assert_eq!(p.clutter, Some(ClutterParams::Iir { order: 4, cutoff: 0.1, init: IirInit::Step }));
    let bad =
        |v: serde_json::Value| serde_json::from_value::<PacketParams>(v).unwrap().validate().unwrap_err().to_string();
    assert!(
        bad(serde_json::json!({ "clutter": { "type": "iir", "order": 4, "cutoff": 0.6 } })).contains("clutter.cutoff")
    );
    assert!(bad(serde_json::json!({ "clutter": { "type": "polynomial", "order": 9 } })).contains("clutter.order"));
    for g in [-1.0, 101.0] {
        assert!(bad(serde_json::json!({ "clutter": { "type": "svd", "gap_db": g } })).contains("clutter.gap_db"));
    }
    // gap_db = 0: the frequency rule alone (the slow blood of svd_energy_gap_keeps_slow_blood goes).
    let (mixed, _) = slow_blood_under_tissue(500, 32, (0.004, 0.03), 9);
    for (gap_db, want) in [(0.0, false), (10.0, true)] {
        let c = ClutterParams::Svd { rank: None, tissue_cutoff: 0.05, max_rank: None, gap_db };
        c.validate().unwrap();
        let rank = filter(&c, &mut frames_of(&mixed)).order_or_rank;
        assert_eq!(rank == 2, want, "gap_db {gap_db}: rank {rank}");
    }
    assert!(bad(serde_json::json!({ "clutter_order": 1, "clutter": { "type": "svd" } })).contains("one clutter filter"));
    let e = serde_json::from_value::<PacketParams>(serde_json::json!({ "clutter": { "type": "svd", "rnak": 2 } }))
        .unwrap_err()
        .to_string();
    assert!(e.contains("rnak"), "{e}");
}
