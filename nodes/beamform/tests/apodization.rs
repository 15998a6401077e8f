//! Receive apodisation: a point scatterer imaged with SIMUS RF (paper probe, 0° plane wave,
//! receive F# 3 at 0°), its lateral profile at the scatterer's depth.
//!
//! With a plane-wave transmit there is no transmit focusing, so the lateral point-spread
//! function is the receive aperture's beam pattern: a uniform (boxcar) aperture has its first
//! side lobes at −13.3 dB (sinc²), a Hann-weighted one at −31.5 dB for a main lobe 1.6 times
//! wider (both for a continuous wave; the 6-cycle pulse fills the nulls a little and spreads the
//! lobes). We require the boxcar side lobes above −18 dB, the Hann ones below −25 dB, and the
//! Hann main lobe (−6 dB width) 1.3–2.0 times the boxcar one.
#![allow(clippy::unwrap_used)]

use sonoflow_beamform::testkit::{paper_das, RfSim};
use sonoflow_beamform::{Apodization, DasPlan, Grid, TxWave};
use sonoflow_simus::{Scatterers, Transmit};

#[test]
fn hann_apodisation_lowers_the_side_lobes_and_widens_the_main_lobe() {
    let (xs, zs) = (0.0, 20.0e-3);
    let scat = Scatterers::new(vec![xs as f32], vec![zs as f32], vec![1.0]).unwrap();
    let mut sim = RfSim::new(0.045, 2e-6);
    let probe = sim.probe.clone();
    let iq = sim.iq(&scat, &Transmit::plane_wave(&probe, 1540.0, 0.0).unwrap());
    let n = sim.plan.n_samples;
    // a lateral line through the scatterer, over a few axial samples around it (the envelope's peak)
    let grid = Grid::spanning(xs - 6e-3, xs + 6e-3, 601, zs - 0.3e-3, zs + 0.3e-3, 13).unwrap();
    let profile = |apodization: Apodization| -> Vec<f64> {
        let mut p = paper_das(3.0, 0.0, sim.plan.fs);
        p.t0 = sim.plan.t0;
        p.apodization = apodization;
        let plan = DasPlan::new(&p, &TxWave::PlaneWave { tilt: 0.0 }, &grid, n).unwrap();
        let img = plan.apply_to_vec(&iq).unwrap();
        // lateral profile: the largest intensity over the depths of each column
        (0..grid.nx)
            .map(|ix| (0..grid.nz).map(|iz| f64::from(img[iz * grid.nx + ix].norm_sqr())).fold(0.0, f64::max))
            .collect()
    };
    // −6 dB main-lobe width and the highest side lobe beyond the first minima (dB)
    let lobes = |prof: &[f64]| -> (f64, f64) {
        let (ipk, pk) = prof.iter().enumerate().fold((0, 0.0), |a, (i, &v)| if v > a.1 { (i, v) } else { a });
        let half = prof.iter().filter(|&&v| v >= 0.25 * pk).count() as f64 * grid.dx;
        // from the peak past the −6 dB point, then down to the first minimum
        let mut r = ipk;
        while r + 1 < prof.len() && (prof[r] >= 0.25 * pk || prof[r + 1] < prof[r]) {
            r += 1;
        }
        let mut l = ipk;
        while l > 0 && (prof[l] >= 0.25 * pk || prof[l - 1] < prof[l]) {
            l -= 1;
        }
        let side = prof[..l].iter().chain(&prof[r + 1..]).copied().fold(0.0, f64::max);
        (half, 10.0 * (side / pk).log10())
    };
    let (w_box, sl_box) = lobes(&profile(Apodization::Boxcar));
    let (w_hann, sl_hann) = lobes(&profile(Apodization::Hann));
    println!(
        "boxcar: −6 dB width {:.3} mm, side lobes {sl_box:.1} dB; hann: {:.3} mm, {sl_hann:.1} dB",
        w_box * 1e3,
        w_hann * 1e3
    );
    assert!(sl_box > -18.0 && sl_box < -10.0, "boxcar side lobes {sl_box} dB");
    assert!(sl_hann < -25.0, "hann side lobes {sl_hann} dB");
    let ratio = w_hann / w_box;
    assert!((1.3..2.0).contains(&ratio), "main-lobe width ratio {ratio}");
}
