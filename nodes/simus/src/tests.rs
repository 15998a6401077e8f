//! Unit tests: parameters (serde, MUST aliases, validation), presets, plan, helpers.

use crate::simus::ZERO_BELOW;
use crate::*;

#[test]
fn probe_loads_from_toml_and_json_with_must_aliases() {
    let toml_txt = r#"
        fc = 5e6
        pitch = 3e-4
        kerf = 3.5e-5
        Nelements = 128
        TXnow = 6
        baffle = "rigid"
    "#;
    let p: Probe = toml::from_str(toml_txt).unwrap();
    assert_eq!(p.n_elements, 128);
    assert_eq!(p.tx_now, 6.0);
    assert_eq!(p.baffle, Baffle::Rigid);
    assert_eq!(p.bandwidth, 75.0); // MUST default
    assert!((p.element_width() - 2.65e-4).abs() < 1e-15);
    p.validate().unwrap();
    let j: Probe =
        serde_json::from_str(r#"{"fc": 7.6e6, "pitch": 3e-4, "width": 2.7e-4, "n_elements": 4, "baffle": 1.5}"#)
            .unwrap();
    assert_eq!(j.baffle, Baffle::Impedance(1.5));
    assert_eq!(j.tx_now, 1.0); // MUST default
                               // round trip
    let back: Probe = serde_json::from_str(&serde_json::to_string(&j).unwrap()).unwrap();
    assert_eq!(back, j);
}

#[test]
fn unknown_fields_are_rejected() {
    let e = toml::from_str::<Probe>("fc = 5e6\npitch = 3e-4\nkerf = 0\nn_elements = 8\nfoo = 1").unwrap_err();
    assert!(e.to_string().contains("foo"), "{e}");
    assert!(toml::from_str::<SimusOptions>("dbthresh = -60\nbar = 2").is_err());
    assert!(serde_json::from_str::<Medium>(r#"{"c": 1500, "attenuatoin": 0.5}"#).is_err());
}

#[test]
fn options_and_medium_load_with_must_names() {
    let o: SimusOptions = toml::from_str(
        r#"
        dBThresh = -60
        FrequencyStep = 0.5
        FullFrequencyDirectivity = true
        ElementSplitting = 3
        fs = 2.4e7
        plan = { mode = "max_distance", max_distance = 0.06 }
        accuracy = { mode = "fast", reanchor_every = 32 }
        "#,
    )
    .unwrap();
    assert_eq!(o.db_thresh, -60.0);
    assert_eq!(o.frequency_step, 0.5);
    assert!(o.full_frequency_directivity);
    assert_eq!(o.element_splitting, Some(3));
    assert_eq!(o.plan, PlanMode::MaxDistance { max_distance: 0.06, max_delay: 0.0 });
    assert_eq!(o.accuracy, Accuracy::Fast { reanchor_every: 32, scatterer_block: 256 });
    o.validate(5e6).unwrap();
    let exact: SimusOptions = toml::from_str("accuracy = { mode = \"exact\" }").unwrap();
    assert_eq!(exact.accuracy, Accuracy::Exact);
    let m: Medium = serde_json::from_str(r#"{"attenuation": 0.5}"#).unwrap();
    assert_eq!(m, Medium { c: 1540.0, attenuation: 0.5 });
}

#[test]
fn must_param_splits_into_parts() {
    let j = r#"{"fc": 5e6, "pitch": 3e-4, "kerf": 3.5e-5, "Nelements": 3, "TXnow": 6, "c": 1500,
                "attenuation": 0.5, "fs": 2e7, "TXdelay": [0, null, 1e-7], "TXapodization": [1, 1, 0.5],
                "height": 5e-3, "focus": 2e-2}"#;
    let parts = serde_json::from_str::<MustParam>(j).unwrap().into_parts().unwrap();
    assert_eq!(parts.probe.n_elements, 3);
    assert_eq!(parts.medium.c, 1500.0);
    assert_eq!(parts.fs, Some(2e7));
    let tx = parts.transmit.unwrap();
    assert!(tx.delays[1].is_nan());
    assert_eq!(tx.weight(1), 0.0);
    assert_eq!(tx.weight(2), 0.5);
    // One MUST param file for SIMUS, DAS and Doppler: fnumber, PRF, RXangle are accepted (unused
    // by SIMUS); anything else unknown is still an error.
    let j =
        r#"{"fc": 5e6, "pitch": 3e-4, "kerf": 3.5e-5, "Nelements": 3, "fnumber": 1.5, "PRF": 1e4, "RXangle": 0.26}"#;
    let p = serde_json::from_str::<MustParam>(j).unwrap();
    assert_eq!((p.fnumber, p.prf, p.rx_angle), (Some(1.5), Some(1e4), Some(0.26)));
    assert!(p.into_parts().is_ok());
    let bad = r#"{"fc": 5e6, "pitch": 3e-4, "kerf": 3.5e-5, "Nelements": 3, "fnumbr": 1.5}"#;
    let e = serde_json::from_str::<MustParam>(bad).unwrap_err().to_string();
    assert!(e.contains("fnumbr"), "{e}");
}

#[test]
fn validation_errors_name_the_field_and_range() {
    let mut p = Probe::paper_5mhz();
    p.bandwidth = 0.0;
    let e = p.validate().unwrap_err();
    assert!(matches!(e, SimusError::InvalidParameter { field: "probe.bandwidth", .. }), "{e}");
    assert!(e.to_string().contains("]0, 200["), "{e}");
    p.bandwidth = 200.0;
    assert!(p.validate().is_err());
    let mut p = Probe::paper_5mhz();
    p.kerf = Some(1e-4); // width + kerf != pitch
    assert!(matches!(p.validate().unwrap_err(), SimusError::InvalidParameter { field: "probe.kerf", .. }));
    let mut p = Probe::paper_5mhz();
    p.n_elements = 0;
    assert!(matches!(p.validate().unwrap_err(), SimusError::InvalidParameter { field: "probe.n_elements", .. }));
    let o = SimusOptions { fs: Some(19.9e6), ..SimusOptions::default() };
    let e = o.validate(5e6).unwrap_err();
    assert!(matches!(e, SimusError::InvalidParameter { field: "options.fs", .. }), "{e}");
    assert!(e.to_string().contains(">= 4 * probe.fc"), "{e}");
    let o = SimusOptions { db_thresh: 0.0, ..SimusOptions::default() };
    assert!(o.validate(5e6).is_err());
    let m = Medium { c: -1.0, attenuation: 0.0 };
    assert!(matches!(m.validate().unwrap_err(), SimusError::InvalidParameter { field: "medium.c", .. }));
}

#[test]
fn presets_match_pymust_getparam() {
    // values of PyMUST 0.1.9 getparam.py
    let l11 = Probe::preset("L11-5v").unwrap();
    assert_eq!((l11.fc, l11.pitch, l11.n_elements, l11.bandwidth), (7.6e6, 3e-4, 128, 77.0));
    assert!((l11.element_width() - 2.7e-4).abs() < 1e-12);
    let l12 = Probe::preset("l12-3V").unwrap();
    assert_eq!((l12.fc, l12.pitch, l12.n_elements, l12.bandwidth), (7.54e6, 2e-4, 192, 93.0));
    let p4 = Probe::preset("P4-2v").unwrap();
    assert_eq!((p4.fc, p4.pitch, p4.n_elements, p4.bandwidth), (2.72e6, 3e-4, 64, 74.0));
    assert!((p4.element_width() - 2.5e-4).abs() < 1e-12);
    let paper = Probe::preset("paper-5mhz").unwrap();
    assert_eq!((paper.fc, paper.n_elements, paper.tx_now, paper.bandwidth), (5e6, 128, 6.0, 75.0));
    assert!((paper.element_width() - 2.65e-4).abs() < 1e-12);
    for name in ["PA4-2/20", "L9-4/38", "LA530", "L14-5/38", "L14-5W/60", "P6-3"] {
        Probe::preset(name).unwrap().validate().unwrap();
    }
    let c5 = Probe::preset("C5-2v").unwrap();
    assert_eq!((c5.fc, c5.pitch, c5.n_elements, c5.bandwidth, c5.radius), (3.57e6, 5.08e-4, 128, 79.0, Some(0.04957)));
    assert!((c5.element_width() - 4.6e-4).abs() < 1e-12);
    assert!(matches!(Probe::preset("X1").unwrap_err(), SimusError::UnknownProbe { .. }));
}

#[test]
fn sub_elements_follow_must_rule() {
    // M = ceil(width / lambda_min), lambda_min = c / (fc (1 + bw/200)): paper 265/224 um -> 2
    let s = Simus::new(Probe::paper_5mhz(), Medium::default(), SimusOptions::default()).unwrap();
    assert_eq!(s.sub_elements(), 2);
    let s = Simus::new(Probe::preset("P4-2v").unwrap(), Medium::default(), SimusOptions::default()).unwrap();
    assert_eq!(s.sub_elements(), 1);
    let o = SimusOptions { element_splitting: Some(5), ..SimusOptions::default() };
    assert_eq!(Simus::new(Probe::paper_5mhz(), Medium::default(), o).unwrap().sub_elements(), 5);
}

#[test]
fn plan_follows_must_grid_rule() {
    let s = Simus::new(Probe::paper_5mhz(), Medium::default(), SimusOptions::default()).unwrap();
    let plan = s.plan_for_max_distance(0.04, 0.0).unwrap();
    // df0 = 1/(2 (2 maxD/c)), maxD = 0.04 + c tp
    let max_d: f64 = 0.04 + 1540.0 * 2.921e-6;
    let df0: f64 = 1.0 / (2.0 * (2.0 * max_d / 1540.0));
    let nf = 2 * (5e6 / df0).ceil() as usize + 1;
    assert_eq!(plan.n_freq, nf);
    assert!((plan.df - 1e7 / (nf - 1) as f64).abs() < 1e-9);
    assert!(plan.df <= df0);
    assert_eq!(plan.n_fft, 2 * (nf - 1)); // fs = 4 fc
    assert_eq!(plan.n_samples, nf - 1);
    assert_eq!(plan.t0, 0.0);
    // -100 dB band of the paper pulse: about 1.35 - 8.6 MHz (pymust-notes §5.2)
    let (f0, f1) = plan.band_frequencies();
    assert!((1.2e6..1.5e6).contains(&f0) && (8.4e6..8.8e6).contains(&f1), "{f0} {f1}");
    // a longer round trip never gives a coarser grid
    assert!(s.plan_for_max_distance(0.08, 0.0).unwrap().df < plan.df);
    assert!(s.plan_for_max_distance(0.04, 1e-6).unwrap().df <= plan.df);
}

#[test]
fn zero_small_values_matches_pymust_step() {
    let mut rf = vec![1.0f32, -0.5, 1e-6, -2e-6, 5e-5, 0.0];
    zero_small_values(&mut rf);
    assert_eq!(&rf[..2], &[1.0, -0.5]);
    assert_eq!(rf[2], 0.0); // rho = 1e-6 < 1e-5: zeroed
    assert_eq!(rf[3], 0.0);
    assert_eq!(rf[4], 5e-5); // rho = 5e-5: kept
    let mut zeros = vec![0.0f32; 4];
    zero_small_values(&mut zeros);
    assert!(zeros.iter().all(|v| *v == 0.0));
    // at the threshold the factor is the quantised tanh step (1/2 at rho = 1e-5)
    let mut at = vec![1.0f32, 1e-5];
    zero_small_values(&mut at);
    assert!((at[1] - 0.5e-5).abs() < 1e-11, "{}", at[1]);
}

#[test]
fn zero_small_values_shortcut_keeps_the_bits() {
    // the shortcut below ρ = 2.4e-6 against the formula it skips, on a fine sweep of ρ (both signs)
    let peak = 1.0f32;
    let formula = |v: f32| -> f32 {
        let (thr, rho) = (1e-5f64, f64::from(v.abs()) / f64::from(peak));
        if rho > thr + 2e-5 {
            return v;
        }
        let step = 0.5 * (1.0 + ((rho - thr) / (thr / 10.0)).tanh());
        ((f64::from(v)) * ((step / (thr / 10.0)).round() * (thr / 10.0))) as f32
    };
    let mut vals: Vec<f32> = (0..=40_000).map(|i| i as f32 * 1e-9).collect(); // ρ 0 … 4e-5
    vals.extend(vals.clone().iter().map(|v| -v));
    let mut rf = vec![peak];
    rf.extend(&vals);
    zero_small_values(&mut rf);
    for (got, v) in rf[1..].iter().zip(&vals) {
        assert_eq!(got.to_bits(), formula(*v).to_bits(), "v = {v:e}");
    }
    // the cut-off is below the first non-zero factor (ρ = 2.746e-6), with a margin
    let first_nonzero = vals.iter().find(|v| **v > 0.0 && formula(**v) != 0.0).copied().unwrap_or(0.0);
    assert!(f64::from(first_nonzero) > 1.1 * ZERO_BELOW, "first non-zero factor at {first_nonzero:e}");
}

#[test]
fn nrms_definition() {
    assert_eq!(nrms(&[1.0, 2.0], &[1.0, 2.0]), 0.0);
    assert!((nrms(&[1.1, 0.0], &[1.0, 0.0]) - 0.1).abs() < 1e-6);
    assert_eq!(nrms(&[0.0], &[0.0]), 0.0);
    assert!(nrms(&[1.0], &[0.0]).is_infinite());
    assert!(nrms(&[1.0], &[1.0, 2.0]).is_nan());
}

#[test]
fn transmit_helpers_follow_must_txdelay() {
    let p = Probe::paper_5mhz();
    let c = 1540.0;
    let tilt = 10f64.to_radians();
    let t = Transmit::plane_wave(&p, c, tilt).unwrap();
    assert_eq!(t.delays[0], 0.0); // tilt > 0: element 0 fires first
    for e in 1..p.n_elements {
        let want = (p.element_x(e) - p.element_x(0)) * tilt.sin() / c;
        assert!((t.delays[e] - want).abs() < 1e-18, "{e}");
    }
    let neg = Transmit::plane_wave(&p, c, -tilt).unwrap();
    assert_eq!(neg.delays[p.n_elements - 1], 0.0);
    // focused: the element nearest the focus fires last; delays >= 0 with min 0
    let f = Transmit::focused(&p, c, 0.0, 0.02).unwrap();
    let (imax, _) = f.delays.iter().enumerate().fold((0, 0.0), |a, (i, &d)| if d > a.1 { (i, d) } else { a });
    assert!(imax == 63 || imax == 64);
    assert_eq!(f.delays.iter().copied().fold(f64::INFINITY, f64::min), 0.0);
    // diverging: the element nearest the virtual source fires first
    let d = Transmit::diverging(&p, c, 0.0, -0.01).unwrap();
    assert!(d.delays[64] < 1e-20 && d.delays[0] > 0.0);
    assert!(Transmit::focused(&p, c, 0.0, -0.01).is_err());
    assert!(Transmit::plane_wave(&p, c, 2.0).is_err());
}

#[test]
fn simulate_3d_in_the_plane_is_simulate_and_is_symmetric_in_y() {
    let probe = Probe::preset("L11-5v").unwrap();
    let medium = Medium::default();
    let tx = Transmit::plane_wave(&probe, medium.c, 0.05).unwrap();
    let scat = Scatterers::new(vec![1e-3, -2e-3, 0.5e-3], vec![15e-3, 22e-3, 30e-3], vec![1.0, 0.7, 1.2]).unwrap();
    let mut sim = Simus::new(probe.clone(), medium.clone(), SimusOptions::default()).unwrap();
    let flat = sim.simulate(&scat, &tx).unwrap();
    assert_eq!(sim.simulate_3d(&scat, &[0.0; 3], &tx).unwrap().data, flat.data);
    let up = sim.simulate_3d(&scat, &[1e-3, -0.5e-3, 2e-3], &tx).unwrap();
    let down = sim.simulate_3d(&scat, &[-1e-3, 0.5e-3, -2e-3], &tx).unwrap();
    assert_eq!(up.data, down.data);
    assert_eq!(up.n_samples, flat.n_samples, "the plan is the 2-D one");
    // the elevation model is evaluated in f64 whatever the accuracy option: Exact (shorter
    // ranges of bins between exact anchors) agrees to f32 rounding
    let mut exact =
        Simus::new(probe.clone(), medium.clone(), SimusOptions { accuracy: Accuracy::Exact, ..Default::default() })
            .unwrap();
    let e = exact.simulate_3d(&scat, &[1e-3, -0.5e-3, 2e-3], &tx).unwrap();
    assert!(nrms(&e.data, &up.data) < 1e-6, "{}", nrms(&e.data, &up.data));
    let err = |r: Result<RfFrame>| r.unwrap_err().to_string();
    assert!(err(sim.simulate_3d(&scat, &[0.0; 2], &tx)).contains("scatterers.y"));
    assert!(err(sim.simulate_3d(&scat, &[f32::NAN; 3], &tx)).contains("scatterers.y"));
    let mut flat_el = probe;
    flat_el.height = Some(-1.0);
    match Simus::new(flat_el, medium, SimusOptions::default()) {
        Err(e) => assert!(e.to_string().contains("height"), "{e}"),
        Ok(mut b) => assert!(err(b.simulate_3d(&scat, &[1e-3; 3], &tx)).contains("param.height")),
    }
}
