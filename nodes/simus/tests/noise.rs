//! Receive noise at a set SNR: measured on a SIMUS frame as the module defines it (echo power
//! over the calibration frame against the noise power inside the probe band, from the FFT of the
//! added noise), it equals the set value within 0.5 dB; the noise is reproducible per frame key.

#![allow(clippy::unwrap_used)]

use sonoflow_simus::testkit::{band_power, forty_scatterer_frame, noisy_frame};
use sonoflow_simus::{NoiseModel, NoiseParams, Probe};

/// The testkit's 40-scatterer frame: (data element-major, n_samples, fs, probe).
fn frame() -> (Vec<f32>, usize, f64, Probe) {
    let (rf, probe) = forty_scatterer_frame();
    (rf.data, rf.n_samples, rf.fs, probe)
}

#[test]
fn measured_snr_equals_the_set_value() {
    let (clean, n, fs, probe) = frame();
    let ps = clean.iter().map(|&v| f64::from(v).powi(2)).sum::<f64>() / clean.len() as f64;
    let (lo, hi) = (probe.fc * (1.0 - probe.bandwidth / 2.0), probe.fc * (1.0 + probe.bandwidth / 2.0));
    for snr_db in [-10.0, 0.0, 20.0, 40.0] {
        let mut model = NoiseModel::new(NoiseParams { snr_db, seed: 5 }, probe.fc, probe.bandwidth, fs).unwrap();
        for key in [0u64, 17] {
            // the first frame calibrates; the second (another key) gets the same level
            let mut noisy = clean.clone();
            model.add(&mut noisy, key).unwrap();
            let noise: Vec<f32> = noisy.iter().zip(&clean).map(|(a, b)| a - b).collect();
            let measured = 10.0 * (ps / band_power(&noise, n, fs, lo, hi)).log10();
            eprintln!("set {snr_db} dB, key {key}: measured {measured:.3} dB");
            assert!((measured - snr_db).abs() < 0.5, "set {snr_db} dB, key {key}: measured {measured:.3} dB");
        }
    }
}

#[test]
fn noise_is_reproducible_per_frame_key_and_checked() {
    let (clean, _, fs, probe) = frame();
    let p = NoiseParams { snr_db: 10.0, seed: 3 };
    let add = |key: u64, seed: u64| {
        let mut m = NoiseModel::new(NoiseParams { seed, ..p.clone() }, probe.fc, probe.bandwidth, fs).unwrap();
        let mut x = clean.clone();
        m.add(&mut x, key).unwrap();
        x
    };
    assert_eq!(add(4, 3), add(4, 3), "same seed and key: same bits");
    assert_ne!(add(4, 3), add(5, 3), "another frame key: other noise");
    assert_ne!(add(4, 3), add(4, 9), "another seed: other noise");
    let mut m = NoiseModel::new(p.clone(), probe.fc, probe.bandwidth, fs).unwrap();
    let e = m.add(&mut vec![0.0f32; 100], 0).unwrap_err();
    assert!(e.contains("no signal") && e.contains("snr_db"), "{e}");
    let e = NoiseModel::new(NoiseParams { snr_db: 500.0, seed: 0 }, probe.fc, probe.bandwidth, fs).unwrap_err();
    assert!(e.contains("noise.snr_db") && e.contains("-40 ..= 120"), "{e}");
    let e = NoiseModel::new(p, 5e6, 0.5, 4e6).unwrap_err();
    assert!(e.contains("probe band") && e.contains("empty"), "{e}");
}

/// The testkit's noisy frame (used by the stability matrix) measures what the test above does.
#[test]
fn testkit_noisy_frame_measures_the_set_snr() {
    for snr_db in [0.0, -10.0] {
        let (noisy, measured) = noisy_frame(snr_db, 1);
        assert!(noisy.iter().all(|v| v.is_finite()));
        assert!((measured - snr_db).abs() < 0.5, "{snr_db}: {measured}");
    }
}

/// `calibrate` sets the level on the blood frame it is given: a frame with 40 dB louder echoes
/// (tissue) later gets the same σ, and the noise is the set SNR below the blood.
#[test]
fn calibration_on_the_blood_frame_sets_the_level() {
    let (clean, n, fs, probe) = frame();
    let ps = clean.iter().map(|&v| f64::from(v).powi(2)).sum::<f64>() / clean.len() as f64;
    let mut m = NoiseModel::new(NoiseParams { snr_db: 10.0, seed: 1 }, probe.fc, probe.bandwidth, fs).unwrap();
    let sigma = m.calibrate(&clean).unwrap();
    let loud: Vec<f32> = clean.iter().map(|v| v * 100.0).collect();
    let mut noisy = loud.clone();
    m.add(&mut noisy, 3).unwrap();
    assert_eq!(m.sigma(), Some(sigma), "not re-calibrated on the loud frame");
    let noise: Vec<f32> = noisy.iter().zip(&loud).map(|(a, b)| a - b).collect();
    let (lo, hi) = (probe.fc * (1.0 - probe.bandwidth / 2.0), probe.fc * (1.0 + probe.bandwidth / 2.0));
    let measured = 10.0 * (ps / band_power(&noise, n, fs, lo, hi)).log10();
    assert!((measured - 10.0).abs() < 0.5, "{measured}");
}
