//! A point scatterer simulated with SIMUS focuses at its true position for receive angles 0°
//! and ±15° and for tilted, focused and diverging transmits.
//!
//! Tolerance: SIMUS's time zero is the centre of the transmitted pulse to within +9…+18 ns
//! (pymust-notes §3; ≤ 14 µm of depth at c/2), the DAS uses exact geometry, and the envelope The residual lateral
//! bias of a steered, asymmetric PSF is a small fraction of the lateral resolution. The position
//! estimate is the −3 dB main-lobe centroid of |image|² on a 10 µm grid. We require it within
//! λ/10 = 31 µm of the scatterer in each direction.
#![allow(clippy::unwrap_used)]

use sonoflow_beamform::testkit::{centroid, one_scatterer, paper_das, RfSim};
use sonoflow_beamform::{DasPlan, Grid, TxWave};
use sonoflow_simus::Transmit;

#[test]
fn point_scatterer_focuses_at_true_position() {
    let lambda = 1540.0 / 5e6;
    let (xs, zs) = (2.0e-3, 20.0e-3);
    let scat = one_scatterer(xs, zs);
    let mut sim = RfSim::new(0.045, 2e-6);
    let grid = Grid::spanning(xs - 0.5e-3, xs + 0.5e-3, 101, zs - 1.5e-3, zs + 1.5e-3, 301).unwrap();
    let probe = sim.probe.clone();
    let cases: Vec<(&str, Transmit, TxWave)> = vec![
        ("pw 0°", Transmit::plane_wave(&probe, 1540.0, 0.0).unwrap(), TxWave::PlaneWave { tilt: 0.0 }),
        (
            "pw +10°",
            Transmit::plane_wave(&probe, 1540.0, 10f64.to_radians()).unwrap(),
            TxWave::PlaneWave { tilt: 10f64.to_radians() },
        ),
        (
            "focused (0, 25 mm)",
            Transmit::focused(&probe, 1540.0, 0.0, 25e-3).unwrap(),
            TxWave::Focused { x0: 0.0, z0: 25e-3 },
        ),
        (
            "diverging (0, -10 mm)",
            Transmit::diverging(&probe, 1540.0, 0.0, -10e-3).unwrap(),
            TxWave::Diverging { x0: 0.0, z0: -10e-3 },
        ),
    ];
    for (name, tx, wave) in &cases {
        let iq = sim.iq(&scat, tx);
        for rx_deg in [0.0f64, -15.0, 15.0] {
            if *name != "pw 0°" && rx_deg != 0.0 {
                continue;
            }
            let p = paper_das(3.0, rx_deg.to_radians(), sim.plan.fs);
            let plan = DasPlan::new(&p, wave, &grid, sim.plan.n_samples).unwrap();
            let img = plan.apply_to_vec(&iq).unwrap();
            let (x, z) = centroid(&img, &grid).expect("main lobe inside the grid");
            let (ex, ez) = ((x - xs) / lambda, (z - zs) / lambda);
            println!("{name}, rx {rx_deg:+}°: peak error x {ex:+.4} λ, z {ez:+.4} λ");
            assert!(ex.abs() < 0.1 && ez.abs() < 0.1, "{name} rx {rx_deg}°: ({ex:.3}, {ez:.3}) λ");
        }
    }
}
