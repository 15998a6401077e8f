//! RF → I/Q demodulation (MUST/PyMUST `rf2iq`, pymust-notes §6; Madiena et al. 2018).
//!
//! For every element: `IQ(t_k) = 2 · filtfilt_LP( RF(t_k) · exp(−i 2π fc t_k) )`, `t_k = t0 + k/fs`.
//!
//! * Low-pass: digital Butterworth of order 5 (MUST), normalised cut-off (1 = Nyquist)
//!   `Wn = (bandwidth/100 · fc)/fs` when `bandwidth` is given (PyMUST `rf2iq(RF, param)`), else
//!   `Wn = min(2 fc/fs, 0.5)` (PyMUST `rf2iq(RF, fs, fc)`). The two call forms of PyMUST give
//!   different filters; pick the one you compare with.
//! * Zero phase: forward–backward filtering exactly as `scipy.signal.filtfilt` with its defaults:
//!   **edges** are handled by an odd extension of `padlen = 3·(order + 1) = 18` samples at each end
//!   (`2·x[0] − x[padlen..1]`, `2·x[n−1] − x[n−2..n−1−padlen]`) and steady-state initial
//!   conditions (`lfilter_zi` scaled by the first sample of each pass); the pads are dropped.
//!   MATLAB's `filtfilt` pads differently, so MUST-MATLAB and PyMUST differ in the first/last
//!   ~50 samples; this module reproduces PyMUST. Frames need more than `padlen` samples.
//! * The factor 2 preserves the envelope amplitude.
//! * fc must be given (PyMUST's automatic estimate uses an unseeded random subset of columns).
//!
//! Arithmetic is f64 (as PyMUST's complex128); the output is complex f32, element-major
//! (`iq[e·n_samples + k]`, the layout the DAS plan reads).

use num_complex::Complex;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::butterworth::{butter_lowpass, filtfilt_in_place, lfilter_zi};
use crate::error::{check_len, invalid, positive, BeamformError, Result};
use crate::C32;

/// Memory layout of an RF (or I/Q) frame of `n_samples × n_elements`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Layout {
    /// `data[e·n_samples + k]`: each element's trace contiguous. This is the SIMUS crate's
    /// `RfFrame` layout, `RfFrameV3`'s `[channel][sample]`, and column-major samples × elements.
    #[default]
    ElementMajor,
    /// `data[k·n_elements + e]`: a C-order `(n_samples, n_elements)` array (PyMUST/numpy `.npy`).
    SampleMajor,
}

/// A borrowed frame of real RF samples (f32 or f64).
#[derive(Clone, Copy, Debug)]
pub struct RfView<'a, T> {
    /// The samples, `n_samples · n_elements` of them in `layout` order.
    pub data: &'a [T],
    /// Time samples per element.
    pub n_samples: usize,
    /// Elements (channels).
    pub n_elements: usize,
    /// Memory layout of `data`.
    pub layout: Layout,
}

impl<'a, T> RfView<'a, T> {
    /// Element-major view (SIMUS `RfFrame::data`).
    pub fn element_major(data: &'a [T], n_samples: usize, n_elements: usize) -> Self {
        Self { data, n_samples, n_elements, layout: Layout::ElementMajor }
    }
    /// Sample-major view (numpy `(n_samples, n_elements)`).
    pub fn sample_major(data: &'a [T], n_samples: usize, n_elements: usize) -> Self {
        Self { data, n_samples, n_elements, layout: Layout::SampleMajor }
    }
    fn index(&self, e: usize, k: usize) -> usize {
        match self.layout {
            Layout::ElementMajor => e * self.n_samples + k,
            Layout::SampleMajor => k * self.n_elements + e,
        }
    }
}

/// A real RF sample type accepted by [`Rf2Iq::process`].
pub trait RfSample: Copy + Send + Sync {
    /// The value as f64.
    fn to_f64(self) -> f64;
}
impl RfSample for f32 {
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
}
impl RfSample for f64 {
    fn to_f64(self) -> f64 {
        self
    }
}

fn default_order() -> usize {
    5
}

/// Parameters of [`Rf2Iq`] (MUST names; SI units).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rf2IqParams {
    /// Demodulation (centre) frequency (Hz), > 0 and < fs/2. MUST `fc`. Required.
    pub fc: f64,
    /// RF sampling frequency (Hz), > 0. MUST `fs`. Required.
    pub fs: f64,
    /// Signal bandwidth (% of fc) in ]0, 200[ setting the low-pass cut-off `Wn =
    /// bandwidth/100·fc/fs`; absent = `Wn = min(2 fc/fs, 0.5)`. MUST `bandwidth`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bandwidth: Option<f64>,
    /// Time of RF sample 0 (s), finite; default 0 (SIMUS frames start at 0). MUST `t0`.
    #[serde(default)]
    pub t0: f64,
    /// Butterworth order in [1, 10]; default 5 (MUST).
    #[serde(default = "default_order")]
    pub order: usize,
}

impl Rf2IqParams {
    /// MUST's `rf2iq(RF, param)` form: cut-off from the bandwidth.
    pub fn new(fc: f64, fs: f64, bandwidth: Option<f64>) -> Self {
        Self { fc, fs, bandwidth, t0: 0.0, order: 5 }
    }

    /// Normalised cut-off `Wn` (1 = Nyquist) of the low-pass filter.
    pub fn cutoff(&self) -> f64 {
        match self.bandwidth {
            Some(b) => b / 100.0 * self.fc / self.fs,
            None => (2.0 * self.fc / self.fs).min(0.5),
        }
    }

    /// Checks every field; the error names the field and the allowed range.
    pub fn validate(&self) -> Result<()> {
        positive("rf2iq.fs", self.fs)?;
        if !(self.fc.is_finite() && self.fc > 0.0 && self.fc < self.fs / 2.0) {
            return Err(invalid("rf2iq.fc", self.fc, "finite, > 0 and < fs/2 (Hz)"));
        }
        if let Some(b) = self.bandwidth {
            if !(b.is_finite() && b > 0.0 && b < 200.0) {
                return Err(invalid("rf2iq.bandwidth", b, "in ]0, 200[ (% of fc)"));
            }
            let wn = self.cutoff();
            if !(wn > 0.0 && wn < 1.0) {
                return Err(invalid("rf2iq.bandwidth", b, "such that bandwidth/100·fc/fs < 1 (cut-off below Nyquist)"));
            }
        }
        if !self.t0.is_finite() {
            return Err(invalid("rf2iq.t0", self.t0, "finite (s)"));
        }
        if !(1..=10).contains(&self.order) {
            return Err(invalid("rf2iq.order", self.order, "in [1, 10]"));
        }
        Ok(())
    }
}

/// Reusable RF → I/Q demodulator: filter coefficients, the mixing phasors of the last frame
/// length, and per-element scratch. After the first frame of a given size it does not allocate.
#[derive(Debug, Clone)]
pub struct Rf2Iq {
    params: Rf2IqParams,
    b: Vec<f64>,
    a: Vec<f64>,
    zi: Vec<f64>,
    padlen: usize,
    mixer: Vec<Complex<f64>>,
    scratch: Vec<Complex<f64>>,
}

impl Rf2Iq {
    /// Validates the parameters and designs the filter.
    pub fn new(params: Rf2IqParams) -> Result<Self> {
        params.validate()?;
        let (b, a) = butter_lowpass(params.order, params.cutoff());
        let zi = lfilter_zi(&b, &a);
        let padlen = 3 * b.len().max(a.len());
        Ok(Self { params, b, a, zi, padlen, mixer: Vec::new(), scratch: Vec::new() })
    }

    /// The parameters.
    pub fn params(&self) -> &Rf2IqParams {
        &self.params
    }

    /// Filter numerator and denominator (as `scipy.signal.butter`).
    pub fn coefficients(&self) -> (&[f64], &[f64]) {
        (&self.b, &self.a)
    }

    /// Length of the odd extension at each end (scipy `padlen`); frames need more samples.
    pub fn padlen(&self) -> usize {
        self.padlen
    }

    /// Demodulates one frame into `out` (element-major, `n_elements · n_samples`).
    /// Errors: too few samples (≤ padlen), zero elements, `data`/`out` lengths.
    /// Non-finite RF samples propagate into the I/Q of their element (not checked per sample).
    pub fn process<T: RfSample>(&mut self, rf: RfView<'_, T>, out: &mut [C32]) -> Result<()> {
        let (ns, ne) = (rf.n_samples, rf.n_elements);
        if ns <= self.padlen {
            return Err(BeamformError::BadDimension {
                field: "rf.n_samples",
                got: ns,
                allowed: "> 18 (the filtfilt edge extension of an order-5 filter: 3·(order+1))",
            });
        }
        if ne == 0 {
            return Err(BeamformError::BadDimension { field: "rf.n_elements", got: 0, allowed: ">= 1" });
        }
        check_len("rf.data", rf.data.len(), ns * ne)?;
        check_len("iq output", out.len(), ns * ne)?;
        if self.mixer.len() != ns {
            let (fc, fs, t0) = (self.params.fc, self.params.fs, self.params.t0);
            self.mixer = (0..ns)
                .map(|k| {
                    let t = k as f64 / fs + t0;
                    let ph = -2.0 * std::f64::consts::PI * fc * t;
                    Complex::new(ph.cos(), ph.sin())
                })
                .collect();
        }
        let ext_len = ns + 2 * self.padlen;
        if self.scratch.len() != ext_len * ne {
            self.scratch = vec![Complex::new(0.0, 0.0); ext_len * ne];
        }
        let (b, a, zi, pad, mixer) = (&self.b, &self.a, &self.zi, self.padlen, &self.mixer);
        out.par_chunks_mut(ns).zip(self.scratch.par_chunks_mut(ext_len)).enumerate().for_each(|(e, (o, ext))| {
            for (k, (x, m)) in ext[pad..pad + ns].iter_mut().zip(mixer).enumerate() {
                *x = m * rf.data[rf.index(e, k)].to_f64();
            }
            filtfilt_in_place(b, a, zi, pad, ext);
            for (o, x) in o.iter_mut().zip(&ext[pad..pad + ns]) {
                *o = Complex::new((2.0 * x.re) as f32, (2.0 * x.im) as f32);
            }
        });
        Ok(())
    }

    /// [`Rf2Iq::process`] into a new vector.
    pub fn process_to_vec<T: RfSample>(&mut self, rf: RfView<'_, T>) -> Result<Vec<C32>> {
        let mut out = vec![C32::new(0.0, 0.0); rf.n_samples * rf.n_elements];
        self.process(rf, &mut out)?;
        Ok(out)
    }
}

/// Transposes an element-major `n_elements × n_samples` I/Q frame to sample-major (numpy
/// `(n_samples, n_elements)`), e.g. to write an `.npy`.
pub fn to_sample_major(iq: &[C32], n_samples: usize, n_elements: usize) -> Result<Vec<C32>> {
    check_len("iq", iq.len(), n_samples * n_elements)?;
    let mut out = vec![C32::new(0.0, 0.0); iq.len()];
    for e in 0..n_elements {
        for k in 0..n_samples {
            out[k * n_elements + e] = iq[e * n_samples + k];
        }
    }
    Ok(out)
}

/// Transposes a sample-major `(n_samples, n_elements)` I/Q frame to element-major.
pub fn to_element_major(iq: &[C32], n_samples: usize, n_elements: usize) -> Result<Vec<C32>> {
    check_len("iq", iq.len(), n_samples * n_elements)?;
    let mut out = vec![C32::new(0.0, 0.0); iq.len()];
    for k in 0..n_samples {
        for e in 0..n_elements {
            out[e * n_samples + k] = iq[k * n_elements + e];
        }
    }
    Ok(out)
}
