//! Test fixtures (feature `testkit`), shared by this crate's tests, `sonoflow-doppler`'s tests and
//! the stability matrix: the PyMUST reference data (`tests/data`, with a small .npy reader that
//! keeps complex128 values), nRMS, the paper probe's DAS parameters and SIMUS scenes. Test code:
//! it panics on a missing data file or a failed simulation.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::{Path, PathBuf};

use crate::{Complex, C32};

/// Directory of the PyMUST reference data.
pub fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests").join("data")
}

/// A little-endian C-order .npy array as f64 (real) or complex f64 values.
pub struct Npy {
    pub shape: Vec<usize>,
    pub re: Vec<f64>,
    pub im: Option<Vec<f64>>,
}

impl Npy {
    pub fn complex(&self) -> Vec<Complex<f64>> {
        let im = self.im.as_ref().expect("complex array");
        self.re.iter().zip(im).map(|(a, b)| Complex::new(*a, *b)).collect()
    }
    pub fn complex32(&self) -> Vec<C32> {
        self.complex().iter().map(|c| C32::new(c.re as f32, c.im as f32)).collect()
    }
}

pub fn read_npy(name: &str) -> Npy {
    let path = data_dir().join(name);
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(&bytes[..6], b"\x93NUMPY", "not an npy file");
    let (hlen, hstart) = if bytes[6] == 1 {
        (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10)
    } else {
        (u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize, 12)
    };
    let header = std::str::from_utf8(&bytes[hstart..hstart + hlen]).unwrap();
    assert!(header.contains("'fortran_order': False"), "{header}");
    let descr = header.split("'descr':").nth(1).unwrap().split('\'').nth(1).unwrap();
    let shape_txt = header.split("'shape':").nth(1).unwrap();
    let shape_txt = &shape_txt[shape_txt.find('(').unwrap() + 1..shape_txt.find(')').unwrap()];
    let shape: Vec<usize> =
        shape_txt.split(',').map(str::trim).filter(|s| !s.is_empty()).map(|s| s.parse().unwrap()).collect();
    let body = &bytes[hstart + hlen..];
    let f4 = |c: &[u8]| f64::from(f32::from_le_bytes([c[0], c[1], c[2], c[3]]));
    let f8 = |c: &[u8]| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]);
    let (re, im) = match descr {
        "<f4" => (body.chunks_exact(4).map(f4).collect(), None),
        "<f8" => (body.chunks_exact(8).map(f8).collect(), None),
        "<c8" => (
            body.chunks_exact(8).map(|c| f4(&c[..4])).collect(),
            Some(body.chunks_exact(8).map(|c| f4(&c[4..])).collect()),
        ),
        "<c16" => (
            body.chunks_exact(16).map(|c| f8(&c[..8])).collect(),
            Some(body.chunks_exact(16).map(|c| f8(&c[8..])).collect()),
        ),
        d => panic!("unsupported dtype {d}"),
    };
    let n: usize = shape.iter().product();
    let re: Vec<f64> = re;
    assert_eq!(re.len(), n);
    Npy { shape, re, im }
}

pub fn reference_json() -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(data_dir().join("reference.json")).unwrap()).unwrap()
}

/// ‖a − b‖ / ‖b‖ over complex values.
pub fn nrms_c(a: &[C32], b: &[Complex<f64>]) -> f64 {
    assert_eq!(a.len(), b.len());
    let (mut num, mut den) = (0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        num += (Complex::new(f64::from(x.re), f64::from(x.im)) - y).norm_sqr();
        den += y.norm_sqr();
    }
    (num / den).sqrt()
}

use crate::{DasParams, Interpolation, Rf2Iq, Rf2IqParams, RfView};
use sonoflow_simus::{Medium, Probe, Scatterers, Simus, SimusOptions, Transmit};

/// Paper probe DAS parameters (5 MHz, 128 elements, pitch 0.3 mm, fs 20 MHz).
pub fn paper_das(fnumber: f64, rx_angle: f64, fs: f64) -> DasParams {
    DasParams {
        fc: 5e6,
        c: 1540.0,
        fs,
        t0: 0.0,
        pitch: 0.30e-3,
        n_elements: 128,
        fnumber,
        rx_angle,
        interpolation: Interpolation::Linear,
        apodization: Default::default(),
    }
}

/// SIMUS RF of `scat` for `tx` with the paper probe and a fixed plan (same length and gain for
/// every frame), demodulated: returns element-major I/Q, n_samples, fs.
pub struct RfSim {
    pub simus: Simus,
    pub probe: Probe,
    pub plan: sonoflow_simus::FrequencyPlan,
    pub rf2iq: Rf2Iq,
}

impl RfSim {
    pub fn new(max_distance: f64, max_delay: f64) -> Self {
        let probe = Probe::paper_5mhz();
        let simus = Simus::new(probe.clone(), Medium::default(), SimusOptions::default()).unwrap();
        let plan = simus.plan_for_max_distance(max_distance, max_delay).unwrap();
        let rf2iq = Rf2Iq::new(Rf2IqParams::new(probe.fc, plan.fs, Some(probe.bandwidth))).unwrap();
        Self { simus, probe, plan, rf2iq }
    }

    pub fn iq(&mut self, scat: &Scatterers, tx: &Transmit) -> Vec<C32> {
        let n = self.plan.n_samples;
        let mut rf = vec![0f32; self.probe.n_elements * n];
        self.simus.simulate_into(scat, tx, &self.plan, &mut rf).unwrap();
        self.rf2iq.process_to_vec(RfView::element_major(&rf, n, self.probe.n_elements)).unwrap()
    }
}
