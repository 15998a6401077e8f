//! Receive noise: additive white Gaussian noise per channel at a set signal-to-noise ratio,
//! seeded and reproducible frame by frame.
//!
//! **Definition.** SNR = P_s / P_n,band in dB, where P_s is the mean power of the blood echoes —
//! the mean of rf² over every channel and sample of a calibration frame simulated from the blood
//! scatterers alone ([`NoiseModel::calibrate`]; the `simus` node uses the first frame's fluid
//! scatterers, leaving tissue out; without it, the first frame the model sees; SIMUS's RF is
//! already limited to the probe band by its pulse and probe response) — and P_n,band the noise power inside the probe band [fc (1 − B/2), fc (1 + B/2)]
//! (B the probe's fractional bandwidth, clipped to [0, fs/2]). The noise is white over
//! [0, fs/2], so its total variance is σ² = P_s / 10^(SNR/10) / ((f_hi − f_lo) / (fs/2)).
//! σ is fixed at calibration: later frames get the same noise level whatever their echo power.
//!
//! **Reproducibility.** The noise of a frame depends only on (`seed`, the frame's key): ChaCha8
//! seeded with `seed`, stream = key (e.g. frame id × transmits + transmit), so frames can be
//! simulated in any order, and a re-run gives the same bits.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

/// Noise parameters (`noise = { snr_db = …, seed = … }` of the `simus` node).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct NoiseParams {
    /// SNR in the probe band (dB, see the module doc), −40 ..= 120.
    pub snr_db: f64,
    /// Seed of the noise (default 0).
    #[serde(default)]
    pub seed: u64,
}

impl NoiseParams {
    /// Checks every field; the error names it and the allowed range.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.snr_db.is_finite() && (-40.0..=120.0).contains(&self.snr_db)) {
            return Err(format!("noise.snr_db = {} is out of range: -40 ..= 120 dB", self.snr_db));
        }
        Ok(())
    }
}

/// Adds noise to RF frames at the set SNR (see the module doc).
#[derive(Clone, Debug)]
pub struct NoiseModel {
    params: NoiseParams,
    /// Fraction of [0, fs/2] the probe band covers.
    band_fraction: f64,
    sigma: Option<f64>,
}

impl NoiseModel {
    /// A model for RF sampled at `fs` from a probe with centre `fc` and fractional bandwidth
    /// `bandwidth`.
    pub fn new(params: NoiseParams, fc: f64, bandwidth: f64, fs: f64) -> Result<Self, String> {
        params.validate()?;
        let nyquist = fs / 2.0;
        let (lo, hi) =
            ((fc * (1.0 - bandwidth / 2.0)).clamp(0.0, nyquist), (fc * (1.0 + bandwidth / 2.0)).clamp(0.0, nyquist));
        if (hi - lo).is_nan() || hi <= lo {
            return Err(format!(
                "noise: the probe band [{lo:.3e}, {hi:.3e}] Hz is empty at fs = {fs:.3e} Hz (fc {fc:.3e}, bandwidth {bandwidth})"
            ));
        }
        Ok(Self { params, band_fraction: (hi - lo) / nyquist, sigma: None })
    }

    /// The probe band's share of [0, fs/2].
    pub fn band_fraction(&self) -> f64 {
        self.band_fraction
    }

    /// Noise standard deviation per sample, once calibrated.
    pub fn sigma(&self) -> Option<f64> {
        self.sigma
    }

    /// Sets σ from the RF of the blood echoes alone (`blood_rf`, a frame simulated from the
    /// blood scatterers only: the SNR is against the blood, not the tissue). An RF without echo
    /// power gives an error (the SNR would be undefined).
    pub fn calibrate(&mut self, blood_rf: &[f32]) -> Result<f64, String> {
        let ps = blood_rf.iter().map(|&v| f64::from(v) * f64::from(v)).sum::<f64>() / blood_rf.len().max(1) as f64;
        if !(ps.is_finite() && ps > 0.0) {
            return Err(format!(
                "noise: the calibration frame has echo power {ps:e}: no signal to set snr_db = {} against",
                self.params.snr_db
            ));
        }
        let s = (ps / 10f64.powf(self.params.snr_db / 10.0) / self.band_fraction).sqrt();
        self.sigma = Some(s);
        Ok(s)
    }

    /// Adds noise to `rf` (any layout), frame `key`; without a [`Self::calibrate`] before, the
    /// first call calibrates σ on `rf` itself (all of its echoes count as signal).
    pub fn add(&mut self, rf: &mut [f32], key: u64) -> Result<(), String> {
        let sigma = match self.sigma {
            Some(s) => s,
            None => self.calibrate(rf)?,
        };
        let mut rng = ChaCha8Rng::seed_from_u64(self.params.seed);
        rng.set_stream(key);
        for v in rf.iter_mut() {
            let n: f64 = rng.sample(StandardNormal);
            *v += (sigma * n) as f32;
        }
        Ok(())
    }
}
