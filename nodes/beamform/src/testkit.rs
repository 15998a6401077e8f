//! Test fixtures (feature `testkit`), shared by this crate's tests, `sonoflow-doppler`'s tests and
//! the stability matrix and the cross-process tests: the PyMUST reference data (`tests/data`,
//! complex128 values kept), nRMS, the paper probe's DAS parameters, SIMUS scenes, the −3 dB
//! main-lobe centroid and the field an error names. Test code: it panics on a missing data file
//! or a failed simulation.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::{Path, PathBuf};

use crate::{BeamformError, Complex, Grid, C32};

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

/// Reads `name` from the reference data folder (real or complex, any order; through
/// `sonoflow_fileio::npy`).
pub fn read_npy(name: &str) -> Npy {
    use sonoflow_fileio::npy;
    let path = data_dir().join(name);
    match npy::read_complex(&path) {
        Ok(a) => Npy {
            shape: a.shape,
            re: a.data.iter().map(|c| c.re).collect(),
            im: Some(a.data.iter().map(|c| c.im).collect()),
        },
        Err(npy::NpyError::NotComplex { .. }) => {
            let a = npy::read(&path).unwrap_or_else(|e| panic!("{e}"));
            Npy { shape: a.shape, re: a.data, im: None }
        }
        Err(e) => panic!("{e}"),
    }
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
        radius: None,
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
        Self::with_probe(Probe::paper_5mhz(), max_distance, max_delay)
    }

    /// As [`Self::new`] for any probe (a convex one included).
    pub fn with_probe(probe: Probe, max_distance: f64, max_delay: f64) -> Self {
        let simus = Simus::new(probe.clone(), Medium::default(), SimusOptions::default()).unwrap();
        let plan = simus.plan_for_max_distance(max_distance, max_delay).unwrap();
        let rf2iq = Rf2Iq::new(Rf2IqParams::new(probe.fc, plan.fs, Some(probe.bandwidth))).unwrap();
        Self { simus, probe, plan, rf2iq }
    }

    /// Element-major RF of `scat` for `tx` on the fixed plan.
    pub fn rf(&mut self, scat: &Scatterers, tx: &Transmit) -> Vec<f32> {
        let mut rf = vec![0f32; self.probe.n_elements * self.plan.n_samples];
        self.simus.simulate_into(scat, tx, &self.plan, &mut rf).unwrap();
        rf
    }

    /// Demodulated element-major RF.
    pub fn iq_of(&mut self, rf: &[f32]) -> Vec<C32> {
        self.rf2iq.process_to_vec(RfView::element_major(rf, self.plan.n_samples, self.probe.n_elements)).unwrap()
    }

    /// Demodulated RF of `scat` for `tx`.
    pub fn iq(&mut self, scat: &Scatterers, tx: &Transmit) -> Vec<C32> {
        let rf = self.rf(scat, tx);
        self.iq_of(&rf)
    }
}

/// One point scatterer of reflection coefficient 1 at (x, z).
pub fn one_scatterer(x: f64, z: f64) -> Scatterers {
    Scatterers::new(vec![x as f32], vec![z as f32], vec![1.0]).unwrap()
}

/// Centroid (x, z) of |img|² over the pixels above half the peak intensity (−3 dB); None if that
/// main lobe touches the grid border or the image is zero. The envelope of the 6-cycle pulse is
/// flat-topped (pymust-notes §3), so its arg-max is not a position estimate; the centroid of the
/// main lobe is, for a PSF symmetric about the scatterer.
pub fn centroid(img: &[C32], g: &Grid) -> Option<(f64, f64)> {
    let int: Vec<f64> = img.iter().map(|c| f64::from(c.norm_sqr())).collect();
    let max = int.iter().copied().fold(0.0, f64::max);
    let (mut sx, mut sz, mut sw) = (0.0, 0.0, 0.0);
    for (i, v) in int.iter().enumerate() {
        if *v >= 0.5 * max {
            let (iz, ix) = (i / g.nx, i % g.nx);
            if ix == 0 || ix + 1 == g.nx || iz == 0 || iz + 1 == g.nz {
                return None;
            }
            sx += v * g.x(ix);
            sz += v * g.z(iz);
            sw += v;
        }
    }
    (sw > 0.0).then(|| (sx / sw, sz / sw))
}

/// Every value finite.
pub fn finite_c(v: &[C32]) -> bool {
    v.iter().all(|c| c.re.is_finite() && c.im.is_finite())
}

/// The parameter field or buffer a beamforming error names.
pub fn field_of(e: BeamformError) -> String {
    match e {
        BeamformError::InvalidParameter { field, .. }
        | BeamformError::LengthMismatch { field, .. }
        | BeamformError::BadDimension { field, .. } => field.to_string(),
        BeamformError::ConfigMismatch { what } => what,
    }
}
