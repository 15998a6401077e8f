//! Static echoes by linearity: the RF of moving scatterers plus the cached RF of the stationary
//! ones equals the RF of all of them (to f32 rounding), and the static part is simulated once per
//! (plan, transmit) until the stationary scatterers change.

#![allow(clippy::unwrap_used)]

use sonoflow_simus::{Medium, Probe, Scatterers, Simus, SimusOptions, StaticEchoes, Transmit};

#[test]
fn moving_plus_cached_static_rf_equals_the_whole_scene() {
    let probe = Probe::paper_5mhz();
    let mut simus = Simus::new(probe.clone(), Medium::default(), SimusOptions::default()).unwrap();
    let txs = [Transmit::plane_wave(&probe, 1540.0, 0.0).unwrap(), Transmit::plane_wave(&probe, 1540.0, 0.1).unwrap()];
    // 40 scatterers: the first 15 "move", the other 25 are tissue (100× brighter: 40 dB).
    let (x, z): (Vec<f32>, Vec<f32>) =
        (0..40).map(|i| (-8e-3 + 4e-4 * i as f32, 15e-3 + 2.5e-4 * ((i * 7) % 40) as f32)).unzip();
    let rc: Vec<f32> =
        (0..40).map(|i| if i < 15 { 1.0 } else { 100.0 * if i % 2 == 0 { 1.0 } else { -0.7 } }).collect();
    let plan = simus.plan_for_max_distance(0.045, 2e-6).unwrap();
    let n = probe.n_elements * plan.n_samples;
    let mut statics = StaticEchoes::default();
    statics.set(&x[15..], &z[15..], &rc[15..]);
    for frame in 0..3 {
        for (k, tx) in txs.iter().enumerate() {
            let mut whole = vec![0f32; n];
            simus
                .simulate_into(&Scatterers::new(x.clone(), z.clone(), rc.clone()).unwrap(), tx, &plan, &mut whole)
                .unwrap();
            let mut parts = vec![0f32; n];
            let moving = Scatterers::new(x[..15].to_vec(), z[..15].to_vec(), rc[..15].to_vec()).unwrap();
            simus.simulate_into(&moving, tx, &plan, &mut parts).unwrap();
            statics.add_into(&mut simus, tx, k, &plan, &mut parts).unwrap();
            let num: f64 = whole.iter().zip(&parts).map(|(a, b)| f64::from(a - b).powi(2)).sum();
            let den: f64 = whole.iter().map(|a| f64::from(*a).powi(2)).sum();
            assert!((num / den).sqrt() < 1e-5, "frame {frame}, transmit {k}: nRMS {:.2e}", (num / den).sqrt());
        }
    }
    assert_eq!(statics.simulated(), 2, "once per transmit over three frames");
    statics.set(&x[15..], &z[15..], &rc[15..]);
    let mut buf = vec![0f32; n];
    statics.add_into(&mut simus, &txs[0], 0, &plan, &mut buf).unwrap();
    assert_eq!(statics.simulated(), 2, "the same scatterers keep the cache");
    let mut moved = x[15..].to_vec();
    moved[3] += 1e-4;
    statics.set(&moved, &z[15..], &rc[15..]);
    statics.add_into(&mut simus, &txs[0], 0, &plan, &mut buf).unwrap();
    assert_eq!(statics.simulated(), 3, "a moved scatterer clears the cache");
}
