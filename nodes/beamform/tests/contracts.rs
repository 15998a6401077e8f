//! Errors of the beamforming stages on bad input (named fields, no panics).
#![allow(clippy::unwrap_used)]

use sonoflow_beamform::testkit::{field_of, paper_das};
use sonoflow_beamform::{DasParams, DasPlan, Grid, Rf2Iq, Rf2IqParams, RfView, TxWave, C32};

/// Bad parameters and buffers give errors naming the field; no panics.
#[test]
fn bad_input_gives_named_errors() {
    let g = Grid::spanning(-1e-3, 1e-3, 4, 5e-3, 6e-3, 4).unwrap();
    let tx = TxWave::PlaneWave { tilt: 0.0 };
    let das = |f: &dyn Fn(&mut DasParams)| {
        let mut p = paper_das(3.0, 0.0, 20e6);
        f(&mut p);
        field_of(DasPlan::new(&p, &tx, &g, 100).unwrap_err())
    };
    assert_eq!(das(&|p| p.fnumber = -1.0), "das.fnumber");
    assert_eq!(das(&|p| p.fc = f64::NAN), "das.fc");
    assert_eq!(das(&|p| p.n_elements = 0), "das.n_elements");
    assert_eq!(das(&|p| p.rx_angle = 1.5), "das.rx_angle");
    assert_eq!(das(&|p| (p.fnumber, p.rx_angle) = (0.0, 0.2)), "das.fnumber");
    let p = paper_das(3.0, 0.0, 20e6);
    let e = |tx: TxWave| field_of(DasPlan::new(&p, &tx, &g, 100).unwrap_err());
    assert_eq!(e(TxWave::PlaneWave { tilt: 2.0 }), "tx.tilt");
    assert_eq!(e(TxWave::Focused { x0: 0.0, z0: -1.0 }), "tx.z0");
    assert_eq!(e(TxWave::Diverging { x0: 0.0, z0: 1.0 }), "tx.z0");
    assert_eq!(e(TxWave::Delays { delays: vec![0.0; 3] }), "tx.delays");
    let mut gaps = vec![0.0; 128];
    gaps[5] = f64::NAN;
    assert_eq!(e(TxWave::Delays { delays: gaps }), "tx.delays");
    let mut bad_grid = g.clone();
    bad_grid.dx = 0.0;
    assert_eq!(field_of(DasPlan::new(&p, &tx, &bad_grid, 100).unwrap_err()), "grid.dx");
    assert_eq!(field_of(DasPlan::new(&p, &tx, &g, 1).unwrap_err()), "iq.n_samples");
    let plan = DasPlan::new(&p, &tx, &g, 100).unwrap();
    assert_eq!(field_of(plan.apply_to_vec(&[C32::new(0.0, 0.0); 10]).unwrap_err()), "iq");
    // rf2iq
    let r = |p: Rf2IqParams| field_of(Rf2Iq::new(p).unwrap_err());
    assert_eq!(r(Rf2IqParams::new(5e6, 8e6, None)), "rf2iq.fc");
    assert_eq!(r(Rf2IqParams::new(5e6, 20e6, Some(250.0))), "rf2iq.bandwidth");
    assert_eq!(r(Rf2IqParams::new(5e6, -1.0, None)), "rf2iq.fs");
    let mut q = Rf2Iq::new(Rf2IqParams::new(5e6, 20e6, Some(75.0))).unwrap();
    assert_eq!(field_of(q.process_to_vec(RfView::element_major(&[0.0f32; 10], 10, 1)).unwrap_err()), "rf.n_samples");
    assert_eq!(field_of(q.process_to_vec(RfView::element_major(&[0.0f64; 100], 50, 3)).unwrap_err()), "rf.data");
    // serde: unknown fields are rejected, MUST aliases accepted
    let p: DasParams =
        serde_json::from_str(r#"{"fc":5e6,"fs":2e7,"pitch":3e-4,"Nelements":128,"fnumber":3,"RXangle":0.26}"#).unwrap();
    assert_eq!((p.n_elements, p.rx_angle, p.c), (128, 0.26, 1540.0));
    assert!(serde_json::from_str::<DasParams>(r#"{"fc":5e6,"fs":2e7,"pitch":3e-4,"Nelements":128,"fnum":3}"#).is_err());
    let t: TxWave = serde_json::from_str(r#"{"kind":"plane_wave","tilt":0.1}"#).unwrap();
    assert_eq!(t, TxWave::PlaneWave { tilt: 0.1 });
}
