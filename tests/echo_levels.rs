//! Echo levels defined on the beamformed data: an analytic vessel with tissue set
//! `tissue_to_blood_db` above the blood, simulated (SIMUS, paper probe, plane wave 0°) and
//! beamformed (rf2iq → DAS, f-number 1.5) for the blood and the tissue separately (the chain is
//! linear, so each region's power is its own echo, without the other's side lobes), powers
//! averaged over four realisations: the mean I/Q power of the tissue region over the lumen's is
//! the set value within 1 dB, and the wall layer sits its `level_db` above the tissue within
//! 1.5 dB.

#![allow(clippy::unwrap_used)]

use sonoflow_analytic_flow::{AnalyticFlow, AnalyticFlowParams, FlowKind, Particles, TissueParams, WallLayer};
use sonoflow_beamform::testkit::{paper_das, RfSim};
use sonoflow_beamform::{DasPlan, Grid, TxWave, C32};
use sonoflow_simus::{Scatterers, Transmit};

fn scatterers(p: &Particles) -> Scatterers {
    Scatterers::new(p.x.clone(), p.z.clone(), p.amplitude.clone()).unwrap()
}

/// Mean |I/Q|² over the pixels where `keep(x, z)`.
fn mean_power(img: &[C32], grid: &Grid, keep: impl Fn(f64, f64) -> bool) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for iz in 0..grid.nz {
        for ix in 0..grid.nx {
            let (x, z) = (grid.x0 + ix as f64 * grid.dx, grid.z0 + iz as f64 * grid.dz);
            if keep(x, z) {
                sum += f64::from(img[iz * grid.nx + ix].norm_sqr());
                n += 1;
            }
        }
    }
    sum / n as f64
}

#[test]
fn tissue_and_wall_levels_hold_on_beamformed_data() {
    let (zc, r) = (20e-3, 4e-3);
    let mut sim = RfSim::new(0.045, 2e-6);
    let tx = Transmit::plane_wave(&sim.probe, 1540.0, 0.0).unwrap();
    let grid = Grid::spanning(-6e-3, 6e-3, 97, 13e-3, 27e-3, 113).unwrap();
    let plan =
        DasPlan::new(&paper_das(1.5, 0.0, sim.plan.fs), &TxWave::PlaneWave { tilt: 0.0 }, &grid, sim.plan.n_samples)
            .unwrap();
    // Powers averaged over four realisations (seeds move the scatterers): the expected power is
    // exact (incoherent sum), what is left is speckle noise, ~0.2 dB here.
    for set_db in [20.0, 40.0] {
        let (mut p_blood, mut p_tissue, mut p_wall) = (0.0, 0.0, 0.0);
        for seed in 1..=4u64 {
            let tissue = TissueParams {
                region: [-9e-3, 9e-3, 11e-3, 29e-3],
                density_per_mm2: 8.0,
                tissue_to_blood_db: set_db,
                wall: Some(WallLayer { thickness: 1.5e-3, level_db: 10.0 }),
                seed: 100 + seed,
                pulsation: None,
            };
            let params = AnalyticFlowParams {
                flow: FlowKind::Poiseuille {
                    center_x: 0.0,
                    center_z: zc,
                    angle_deg: 0.0,
                    diameter: 2.0 * r,
                    v_max: 0.3,
                    length: 0.04,
                },
                density_per_mm2: 12.0,
                seed,
                tissue: Some(tissue),
                ..AnalyticFlowParams::default()
            };
            let flow = AnalyticFlow::new(&params).unwrap();
            let blood = plan.apply_to_vec(&sim.iq(&scatterers(flow.particles()), &tx)).unwrap();
            let tissue = plan.apply_to_vec(&sim.iq(&scatterers(flow.tissue()), &tx)).unwrap();
            // Regions a resolution cell (~0.5 mm) away from the boundaries they must not cross.
            let d = |z: f64| (z - zc).abs() - r; // distance outside the lumen (negative inside)
            p_blood += mean_power(&blood, &grid, |_, z| d(z) < -0.5e-3);
            p_tissue += mean_power(&tissue, &grid, |_, z| d(z) > 1.5e-3 + 0.5e-3);
            p_wall += mean_power(&tissue, &grid, |_, z| d(z) > 0.5e-3 && d(z) < 1.0e-3);
        }
        let measured = 10.0 * (p_tissue / p_blood).log10();
        let wall = 10.0 * (p_wall / p_tissue).log10();
        eprintln!("set {set_db} dB: tissue/blood {measured:.2} dB, wall/tissue {wall:.2} dB");
        assert!((measured - set_db).abs() < 1.0, "set {set_db} dB, measured {measured:.2} dB");
        assert!((wall - 10.0).abs() < 1.5, "wall layer {wall:.2} dB above the tissue, set 10");
    }
}
