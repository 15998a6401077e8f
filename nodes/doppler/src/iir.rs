//! IIR clutter (wall) filter: a digital Butterworth high-pass over slow time, designed by the
//! bilinear transform (the low-pass of `sonoflow_beamform::butterworth` at cut-off 1 − w,
//! mirrored by z → −z), run forward over each pixel's packet in transposed direct form II.
//!
//! Magnitude response at slow-time frequency f (cycles per frame, i.e. a fraction of the PRF):
//! |H(f)|² = 1 / (1 + (tan(π f_c) / tan(π |f|))^(2N)) — zero at DC, 1/√2 at the cut-off f_c,
//! → 1 at the Nyquist frequency ±PRF/2 ([`IirHighPass::response`]).
//!
//! A packet is short (8 … 64 frames), so the filter's start matters. Initialisation
//! ([`IirInit`]): `zero` starts from rest (the first frames carry the full step response of the
//! tissue echo); `step` (the default) starts in the steady state for a constant input equal to
//! the first frame (`lfilter_zi` · x₀), so a still echo is removed from the first frame on and
//! only its change during the packet rings.

use crate::slowtime::for_each_pixel;
use num_complex::Complex;
use serde::{Deserialize, Serialize};
use sonoflow_beamform::butterworth::{butter_lowpass, lfilter_in_place, lfilter_zi};
use sonoflow_beamform::error::{invalid, Result};
use sonoflow_beamform::C32;

/// How the filter state starts at each packet.
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum IirInit {
    /// At rest (zero state).
    Zero,
    /// Steady state for a constant input equal to the first frame (the default).
    #[default]
    Step,
}

/// Butterworth high-pass over slow time (see the module doc).
#[derive(Clone, Debug)]
pub struct IirHighPass {
    order: usize,
    cutoff: f64,
    init: IirInit,
    b: Vec<f64>,
    a: Vec<f64>,
    zi: Vec<f64>,
}

impl IirHighPass {
    /// Order `order` (1 ..= 8), cut-off `cutoff` as a fraction of the PRF (0 < f_c < 0.5).
    pub fn new(order: usize, cutoff: f64, init: IirInit) -> Result<Self> {
        if !(1..=8).contains(&order) {
            return Err(invalid("clutter.order", order, "in 1 ..= 8 for the IIR filter"));
        }
        if !(cutoff.is_finite() && cutoff > 0.0 && cutoff < 0.5) {
            return Err(invalid("clutter.cutoff", cutoff, "a fraction of the PRF in (0, 0.5)"));
        }
        // Low-pass at 1 − 2 f_c of Nyquist, then z → −z: b_k, a_k times (−1)^k.
        let (mut b, mut a) = butter_lowpass(order, 1.0 - 2.0 * cutoff);
        for (k, (bk, ak)) in b.iter_mut().zip(a.iter_mut()).enumerate() {
            if k % 2 == 1 {
                *bk = -*bk;
                *ak = -*ak;
            }
        }
        let zi = lfilter_zi(&b, &a);
        Ok(Self { order, cutoff, init, b, a, zi })
    }

    /// Filter order.
    pub fn order(&self) -> usize {
        self.order
    }

    /// Cut-off as a fraction of the PRF.
    pub fn cutoff(&self) -> f64 {
        self.cutoff
    }

    /// The designed magnitude response |H(f)| at `f` cycles per frame (|f| ≤ 0.5).
    pub fn response(&self, f: f64) -> f64 {
        let r = (std::f64::consts::PI * self.cutoff).tan() / (std::f64::consts::PI * f.abs()).tan();
        1.0 / (1.0 + r.powi(2 * self.order as i32)).sqrt()
    }

    /// Numerator and denominator (a\[0\] = 1).
    pub fn coefficients(&self) -> (&[f64], &[f64]) {
        (&self.b, &self.a)
    }

    /// Filters one slow-time signal in place.
    pub fn filter(&self, x: &mut [Complex<f64>]) {
        let Some(&x0) = x.first() else { return };
        let mut z: Vec<Complex<f64>> = match self.init {
            IirInit::Zero => vec![Complex::new(0.0, 0.0); self.zi.len()],
            IirInit::Step => self.zi.iter().map(|&s| x0 * s).collect(),
        };
        lfilter_in_place(&self.b, &self.a, x, &mut z, 0..x.len());
    }

    /// Filters a packet given as one mutable slice per frame (all of the same length).
    pub fn apply_frames(&self, frames: &mut [&mut [C32]]) -> Result<()> {
        for_each_pixel(frames, |x| self.filter(x))
    }
}
