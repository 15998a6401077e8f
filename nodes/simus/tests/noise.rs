//! Receive noise at a set SNR: measured on a SIMUS frame as the module defines it (echo power
//! over the calibration frame against the noise power inside the probe band, from the FFT of the
//! added noise), it equals the set value within 0.5 dB; the noise is reproducible per frame key.

#![allow(clippy::unwrap_used)]

use sonoflow_simus::{Medium, NoiseModel, NoiseParams, Probe, Scatterers, Simus, SimusOptions, Transmit};

/// One RF frame of 40 scatterers (paper probe, plane wave at 0°): (data element-major, n_samples, fs).
fn frame() -> (Vec<f32>, usize, f64, Probe) {
    let probe = Probe::paper_5mhz();
    let n = 40;
    let x: Vec<f32> = (0..n).map(|i| -8e-3 + 16e-3 * i as f32 / n as f32).collect();
    let z: Vec<f32> = (0..n).map(|i| 15e-3 + 10e-3 * ((i * 7) % n) as f32 / n as f32).collect();
    let rc: Vec<f32> = (0..n).map(|i| if i % 2 == 0 { 1.0 } else { -0.7 }).collect();
    let mut simus = Simus::new(probe.clone(), Medium::default(), SimusOptions::default()).unwrap();
    let tx = Transmit::plane_wave(&probe, 1540.0, 0.0).unwrap();
    let rf = simus.simulate(&Scatterers::new(x, z, rc).unwrap(), &tx).unwrap();
    (rf.data, rf.n_samples, rf.fs, probe)
}

/// Mean power per sample of `x` (channels of `n` samples) inside [lo, hi] Hz, by Parseval.
fn band_power(x: &[f32], n: usize, fs: f64, lo: f64, hi: f64) -> f64 {
    let mut planner = realfft::RealFftPlanner::<f64>::new();
    let fft = planner.plan_fft_forward(n);
    let mut total = 0.0;
    for ch in x.chunks(n) {
        let mut buf: Vec<f64> = ch.iter().map(|&v| f64::from(v)).collect();
        let mut spec = fft.make_output_vec();
        fft.process(&mut buf, &mut spec).unwrap();
        for (k, s) in spec.iter().enumerate().skip(1) {
            let f = k as f64 * fs / n as f64;
            if f >= lo && f <= hi && 2 * k != n {
                total += 2.0 * s.norm_sqr();
            }
        }
    }
    total / (n as f64 * n as f64) / (x.len() / n) as f64
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
