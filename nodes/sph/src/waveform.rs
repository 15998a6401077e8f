//! Periodic waveforms (inlet velocity, body-force forcing) as truncated Fourier series.
//!
//! `f(t) = mean + Σ_{k=1..N} [a_k cos(kωt) + b_k sin(kωt)]`, ω = 2π/period. A waveform is given in a
//! launch file as a [`WaveformSpec`] (constant, Fourier coefficients, equally spaced samples, or the
//! built-in carotid preset) and turned into a [`Waveform`] once.
//!
//! **Carotid preset** ([`carotid_shape`]). Shahriari & Garcia (2018, §2.2) impose at the common
//! carotid inlet a fully developed waveform "with a peak at 0.39 m/s, a mean Reynolds number of 375,
//! and a period of 830 ms", inspired by Zhao et al. (2003, *Ann. Biomed. Eng.* 31:962) whose data we
//! do not have. We therefore use a *synthetic* common-carotid mean-velocity shape with the features
//! of the archetypal CCA waveform of Holdsworth et al. (1999, *Physiol. Meas.* 20:219): a steep
//! systolic upstroke to a peak at 0.15 T, a dicrotic notch near 0.30 T followed by a dicrotic wave
//! peaking near 0.40 T, and a slowly decaying diastolic flow that stays forward. It is built from
//! periodic Gaussian pulses over a smooth diastolic baseline (the parameters are in
//! [`carotid_shape`]), projected onto 24 harmonics, then scaled affinely so that its time mean and
//! peak are the requested values. Defaults: peak 0.39 m/s, mean 0.1875 m/s (Re = ū D / ν = 375 with
//! D = 8 mm and ν = μ/ρ₀ = 4·10⁻³/1000 m²/s), period 0.83 s. The peak and the mean refer to the
//! **cross-section mean velocity** (the centreline velocity of the fully developed profile is larger).
//! These are not digitised measurements; the shape only has to be physiological, and its harmonics
//! are what the Womersley inlet profile and the validation use.

use serde::{Deserialize, Serialize};

use crate::Real;
use std::f64::consts::PI;

/// A periodic waveform in Fourier form.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Waveform {
    /// Period T \[s\] (> 0). A constant waveform has any period.
    pub period: Real,
    /// Time mean (the zeroth harmonic).
    pub mean: Real,
    /// a_k, k = 1..N (cosine coefficients).
    pub cos: Vec<Real>,
    /// b_k, k = 1..N (sine coefficients); same length as `cos`.
    pub sin: Vec<Real>,
}

/// How a waveform is written in a parameter file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
pub enum WaveformSpec {
    /// f(t) = value.
    Constant {
        /// The value.
        value: Real,
    },
    /// f(t) = value · cos(2π t / period + phase).
    Cosine {
        /// Amplitude.
        amplitude: Real,
        /// Period \[s\].
        period: Real,
        /// Phase \[rad\]. Default 0.
        #[serde(default)]
        phase: Real,
        /// Added constant. Default 0.
        #[serde(default)]
        offset: Real,
    },
    /// Explicit Fourier coefficients.
    Fourier {
        /// Period \[s\].
        period: Real,
        /// Time mean.
        mean: Real,
        /// Cosine coefficients a_1..a_N.
        cos: Vec<Real>,
        /// Sine coefficients b_1..b_N.
        sin: Vec<Real>,
    },
    /// Equally spaced samples over one period, starting at t = 0 (trigonometric interpolation).
    Samples {
        /// Period \[s\].
        period: Real,
        /// f(k T / n), k = 0..n−1 (n ≥ 3).
        values: Vec<Real>,
    },
    /// The synthetic common-carotid mean-velocity waveform (see the module documentation).
    Carotid {
        /// Peak of the cross-section mean velocity \[m/s\]. Default 0.39 (the paper).
        #[serde(default = "default_carotid_peak")]
        peak: Real,
        /// Time mean of the cross-section mean velocity \[m/s\]. Default 0.1875 (Re 375 at D = 8 mm, ν = 4e-6).
        #[serde(default = "default_carotid_mean")]
        mean: Real,
        /// Period \[s\]. Default 0.83 (the paper).
        #[serde(default = "default_carotid_period")]
        period: Real,
    },
}

fn default_carotid_peak() -> Real {
    0.39
}
fn default_carotid_mean() -> Real {
    0.1875
}
fn default_carotid_period() -> Real {
    0.83
}

/// A waveform specification outside its allowed range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("waveform `{field}` is invalid: {reason}")]
pub struct WaveformError {
    /// Field name.
    pub field: &'static str,
    /// What is wrong, with the allowed range.
    pub reason: String,
}

fn werr(field: &'static str, reason: impl Into<String>) -> WaveformError {
    WaveformError { field, reason: reason.into() }
}

/// Harmonics kept for sampled and preset waveforms.
pub const PRESET_HARMONICS: usize = 24;

impl WaveformSpec {
    /// Checks the fields and builds the Fourier form.
    pub fn build(&self) -> Result<Waveform, WaveformError> {
        let finite = |field: &'static str, v: Real| {
            if v.is_finite() {
                Ok(())
            } else {
                Err(werr(field, format!("{v} is not finite")))
            }
        };
        let period_ok = |v: Real| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(werr("period", format!("{v}: allowed period > 0 [s]")))
            }
        };
        match self {
            WaveformSpec::Constant { value } => {
                finite("value", *value)?;
                Ok(Waveform::constant(*value))
            }
            WaveformSpec::Cosine { amplitude, period, phase, offset } => {
                finite("amplitude", *amplitude)?;
                finite("phase", *phase)?;
                finite("offset", *offset)?;
                period_ok(*period)?;
                Ok(Waveform {
                    period: *period,
                    mean: *offset,
                    cos: vec![amplitude * phase.cos()],
                    sin: vec![-amplitude * phase.sin()],
                })
            }
            WaveformSpec::Fourier { period, mean, cos, sin } => {
                period_ok(*period)?;
                finite("mean", *mean)?;
                if cos.len() != sin.len() {
                    return Err(werr(
                        "sin",
                        format!("has {} terms, `cos` has {}: they must match", sin.len(), cos.len()),
                    ));
                }
                if let Some(v) = cos.iter().find(|v| !v.is_finite()) {
                    return Err(werr("cos", format!("{v} is not finite")));
                }
                if let Some(v) = sin.iter().find(|v| !v.is_finite()) {
                    return Err(werr("sin", format!("{v} is not finite")));
                }
                Ok(Waveform { period: *period, mean: *mean, cos: cos.clone(), sin: sin.clone() })
            }
            WaveformSpec::Samples { period, values } => {
                period_ok(*period)?;
                if values.len() < 3 {
                    return Err(werr("values", format!("{} samples: allowed at least 3", values.len())));
                }
                if let Some(v) = values.iter().find(|v| !v.is_finite()) {
                    return Err(werr("values", format!("{v} is not finite")));
                }
                Ok(Waveform::from_samples(*period, values, (values.len() - 1) / 2))
            }
            WaveformSpec::Carotid { peak, mean, period } => {
                period_ok(*period)?;
                finite("mean", *mean)?;
                if !(peak.is_finite() && *peak > *mean) {
                    return Err(werr("peak", format!("{peak}: allowed peak > mean ({mean})")));
                }
                let n = 512;
                let shape: Vec<Real> = (0..n).map(|k| carotid_shape(k as Real / n as Real)).collect();
                let w = Waveform::from_samples(*period, &shape, PRESET_HARMONICS);
                Ok(w.rescaled_to(*mean, *peak))
            }
        }
    }
}

/// Synthetic common-carotid mean-velocity shape over one period, τ = t/T ∈ [0, 1), arbitrary units
/// (scaled by [`WaveformSpec::Carotid`]): periodic Gaussian pulses — systole (centre 0.15, width
/// 0.045, height 1), dicrotic wave (0.40, 0.04, 0.28), late diastolic wave (0.62, 0.09, 0.10) — over a
/// smooth periodic diastolic baseline 0.24 + 0.02 (1 + cos 2π(τ − 0.45)). The notch between the
/// systolic and dicrotic pulses falls at ≈ 0.30 T.
pub fn carotid_shape(tau: Real) -> Real {
    let pulses = [(0.15, 0.045, 1.0), (0.40, 0.04, 0.28), (0.62, 0.09, 0.10)];
    let mut f = 0.0;
    for (c, w, a) in pulses {
        for image in [-1.0, 0.0, 1.0] {
            let d = tau - c - image;
            f += a * (-0.5 * (d / w) * (d / w)).exp();
        }
    }
    let base = 0.24 + 0.02 * (1.0 + (2.0 * PI * (tau - 0.45)).cos());
    f + base
}

impl Waveform {
    /// f(t) = value.
    pub fn constant(value: Real) -> Self {
        Waveform { period: 1.0, mean: value, cos: Vec::new(), sin: Vec::new() }
    }

    /// Trigonometric least-squares fit (for N < n/2 the DFT truncation) of `n` equally spaced samples
    /// over one period, keeping `harmonics` harmonics (≤ (n−1)/2).
    pub fn from_samples(period: Real, values: &[Real], harmonics: usize) -> Self {
        let n = values.len();
        let nh = harmonics.min((n - 1) / 2);
        let mean = values.iter().sum::<Real>() / n as Real;
        let mut cos = vec![0.0; nh];
        let mut sin = vec![0.0; nh];
        for k in 1..=nh {
            let (mut a, mut b) = (0.0, 0.0);
            for (j, &v) in values.iter().enumerate() {
                let ph = 2.0 * PI * (k * j) as Real / n as Real;
                a += v * ph.cos();
                b += v * ph.sin();
            }
            cos[k - 1] = 2.0 * a / n as Real;
            sin[k - 1] = 2.0 * b / n as Real;
        }
        Waveform { period, mean, cos, sin }
    }

    /// Number of harmonics N.
    pub fn harmonics(&self) -> usize {
        self.cos.len()
    }

    /// Angular frequency of harmonic 1, ω = 2π/T \[rad/s\].
    pub fn omega(&self) -> Real {
        2.0 * PI / self.period
    }

    /// f(t).
    pub fn value(&self, t: Real) -> Real {
        let w = self.omega();
        let mut f = self.mean;
        for (k, (a, b)) in self.cos.iter().zip(&self.sin).enumerate() {
            let ph = (k + 1) as Real * w * t;
            f += a * ph.cos() + b * ph.sin();
        }
        f
    }

    /// ∫₀ᵗ f(τ) dτ.
    pub fn integral(&self, t: Real) -> Real {
        let w = self.omega();
        let mut f = self.mean * t;
        for (k, (a, b)) in self.cos.iter().zip(&self.sin).enumerate() {
            let kw = (k + 1) as Real * w;
            let ph = kw * t;
            f += (a * ph.sin() + b * (1.0 - ph.cos())) / kw;
        }
        f
    }

    /// df/dt (t).
    pub fn derivative(&self, t: Real) -> Real {
        let w = self.omega();
        let mut f = 0.0;
        for (k, (a, b)) in self.cos.iter().zip(&self.sin).enumerate() {
            let kw = (k + 1) as Real * w;
            let ph = kw * t;
            f += kw * (-a * ph.sin() + b * ph.cos());
        }
        f
    }

    /// Complex amplitude of harmonic k ≥ 1 in the convention f = mean + Σ Re{c_k e^{i k ω t}}:
    /// c_k = a_k − i b_k, returned as (re, im).
    pub fn complex_amplitude(&self, k: usize) -> (Real, Real) {
        (self.cos[k - 1], -self.sin[k - 1])
    }

    /// (min, max) of f over one period, sampled at 2048 points.
    pub fn range(&self) -> (Real, Real) {
        if self.cos.is_empty() {
            return (self.mean, self.mean);
        }
        let n = 2048;
        (0..n)
            .map(|j| self.value(j as Real / n as Real * self.period))
            .fold((Real::INFINITY, Real::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)))
    }

    /// Maximum of |df/dt| over one period (2048 samples).
    pub fn max_rate(&self) -> Real {
        let n = 2048;
        (0..n).map(|j| self.derivative(j as Real / n as Real * self.period).abs()).fold(0.0, Real::max)
    }

    /// The same waveform times `s`.
    pub fn scaled(&self, s: Real) -> Self {
        Waveform {
            period: self.period,
            mean: self.mean * s,
            cos: self.cos.iter().map(|a| a * s).collect(),
            sin: self.sin.iter().map(|b| b * s).collect(),
        }
    }

    /// Affine rescaling α f + β with time mean `mean` and maximum `peak` (requires a non-constant f).
    pub fn rescaled_to(&self, mean: Real, peak: Real) -> Self {
        let (_, hi) = self.range();
        let alpha = (peak - mean) / (hi - self.mean);
        let mut w = self.scaled(alpha);
        w.mean = mean;
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn carotid_preset_has_the_requested_mean_peak_and_period_and_stays_forward() {
        let w = WaveformSpec::Carotid { peak: 0.39, mean: 0.1875, period: 0.83 }.build().expect("valid");
        let n = 4096;
        let vals: Vec<Real> = (0..n).map(|j| w.value(j as Real / n as Real * 0.83)).collect();
        let mean = vals.iter().sum::<Real>() / n as Real;
        let (lo, hi) = w.range();
        assert!((mean - 0.1875).abs() < 1e-12, "{mean}");
        assert!((hi - 0.39).abs() < 1e-9, "{hi}");
        assert!(lo > 0.0, "forward flow throughout: min {lo}");
        // systolic peak early in the cycle (0.1 T .. 0.2 T)
        let imax = vals.iter().enumerate().fold(0, |b, (i, v)| if *v > vals[b] { i } else { b });
        let tau = imax as Real / n as Real;
        assert!((0.1..0.2).contains(&tau), "peak at {tau} T");
        assert!((w.value(0.2) - w.value(0.2 + 0.83)).abs() < 1e-12, "periodic");
    }

    #[test]
    fn samples_of_a_trigonometric_polynomial_are_reproduced_exactly() {
        let f = |t: Real| 0.3 + 0.2 * (2.0 * PI * t / 0.5).cos() - 0.1 * (4.0 * PI * t / 0.5).sin();
        let v: Vec<Real> = (0..16).map(|j| f(j as Real * 0.5 / 16.0)).collect();
        let w = WaveformSpec::Samples { period: 0.5, values: v }.build().expect("valid");
        for j in 0..50 {
            let t = j as Real * 0.0173;
            assert!((w.value(t) - f(t)).abs() < 1e-12);
        }
        let e = 1e-6;
        assert!((w.derivative(0.1) - (w.value(0.1 + e) - w.value(0.1 - e)) / (2.0 * e)).abs() < 1e-6);
        // integral: Simpson over [0, 0.37]
        let n = 2000;
        let hq = 0.37 / n as Real;
        let mut q = w.value(0.0) + w.value(0.37);
        for j in 1..n {
            q += w.value(j as Real * hq) * if j % 2 == 1 { 4.0 } else { 2.0 };
        }
        assert!((w.integral(0.37) - q * hq / 3.0).abs() < 1e-12, "{} vs {}", w.integral(0.37), q * hq / 3.0);
    }

    #[test]
    fn cosine_spec_and_errors() {
        let w = WaveformSpec::Cosine { amplitude: 2.0, period: 0.2, phase: 0.3, offset: 1.0 }.build().expect("ok");
        assert!((w.value(0.05) - (1.0 + 2.0 * (2.0 * PI * 0.05 / 0.2 + 0.3).cos())).abs() < 1e-12);
        let e = WaveformSpec::Cosine { amplitude: 1.0, period: 0.0, phase: 0.0, offset: 0.0 }.build().expect_err("bad");
        assert_eq!(e.field, "period");
        let e = WaveformSpec::Fourier { period: 1.0, mean: 0.0, cos: vec![1.0], sin: vec![] }.build().expect_err("bad");
        assert_eq!(e.field, "sin");
        let e = WaveformSpec::Carotid { peak: 0.1, mean: 0.2, period: 1.0 }.build().expect_err("bad");
        assert_eq!(e.field, "peak");
        let s: WaveformSpec = toml::from_str("type = \"carotid\"").expect("defaults");
        assert_eq!(s, WaveformSpec::Carotid { peak: 0.39, mean: 0.1875, period: 0.83 });
    }
}
