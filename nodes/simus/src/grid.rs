//! Frequency plan: the grid, the computed band and the RF length (MUST `simus.m` + `pfield.m`,
//! pymust-notes §5.2 and §5.9).
//!
//! Exactly as PyMUST 0.1.9:
//!
//! 1. `maxD = max_{s,e} |scatterer_s − element_e| + c·tp`, with `tp` the duration of MUST's
//!    two-way pulse ([`crate::pulse::PulseModel::two_way_pulse_duration`], 2.921 µs for the paper
//!    probe);
//! 2. `df0 = FrequencyStep / (2 (2 maxD/c + max delay))`: the time window 1/df0 holds **twice**
//!    the longest round trip, so the circular convolution of the inverse FFT never wraps;
//! 3. `Nf = 2 ceil(fc/df0) + 1` bins on `f = linspace(0, 2 fc, Nf)`, i.e. `df = 2 fc/(Nf − 1) ≤ df0`;
//! 4. the band: the contiguous bins from the first to the last where
//!    `20 log10(|P(f) H(f)| / max) > dB_thresh` (pulse × **one-way** probe, default −100 dB);
//!    only these bins are computed, the others are zero;
//! 5. RF: `nf = ceil(fs/(2 fc)·(Nf − 1))`-point inverse real FFT of the conjugated spectrum,
//!    keeping the first `(nf + 1)/2` samples; sample k is at `t0 + k/fs`, `t0 = 0` (the instant the
//!    centre of the pulse leaves an element with zero delay).
//!
//! With [`RfWindow::Compact`] (not MUST's) step 2 drops the factor 2 — the window `1/df0` holds the
//! longest round trip (with the pulse margins of step 1) once, or MUST's kept samples if
//! `FrequencyStep` < 1 makes them longer, plus one pulse duration so that the leading half of a
//! pulse that starts before t = 0 wraps past the samples kept — and step 5 keeps as many samples as
//! MUST's plan for the same scene (`FrequencyStep` > 1 shortens them, as in MUST, but never makes
//! echoes wrap onto them): about half the bins, the same samples. The spectrum is scaled with
//! MUST's step for the same scene ([`FrequencyPlan::gain_df`]), so the RF has MUST's gain.
//!
//! MUST re-plans on every call, so the length and the gain (∝ df) of the RF change with the
//! scene. [`crate::Simus::plan_for_max_distance`] (or [`crate::PlanMode::MaxDistance`]) fixes the
//! grid for a whole packet instead.

use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

use crate::error::{invalid, Result};
use crate::params::RfWindow;
use crate::pulse::PulseModel;

/// The frequency grid and RF geometry used for one or more frames.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrequencyPlan {
    /// Frequency step (Hz): bin k is at `k·df`, `df = 2 fc / (n_freq − 1)`.
    pub df: f64,
    /// Number of bins of the grid on [0, 2 fc] (MUST `Nf`).
    pub n_freq: usize,
    /// First computed bin (inclusive).
    pub band_first: usize,
    /// Last computed bin (inclusive).
    pub band_last: usize,
    /// Length of the inverse real FFT (MUST `nf`).
    pub n_fft: usize,
    /// RF samples per element: `(n_fft + 1) / 2` (MUST's window); MUST's count for the same scene,
    /// at most `n_fft` (compact window).
    pub n_samples: usize,
    /// The RF window the plan was made with.
    #[serde(default)]
    pub window: RfWindow,
    /// Frequency step (Hz) that sets the RF's gain: `df` for MUST's window, MUST's `df` for the
    /// same scene for the compact one (MUST's RF scales with its step, pymust-notes §5.9).
    pub gain_df: f64,
    /// Sampling frequency (Hz).
    pub fs: f64,
    /// Time of sample 0 (s): 0.
    pub t0: f64,
    /// Distance the plan was made for (m): largest element–scatterer distance + c·(pulse duration).
    pub max_distance: f64,
    /// Largest transmit delay the plan was made for (s).
    pub max_delay: f64,
    /// Centre frequency (Hz) and speed of sound (m/s) of the plan, to detect misuse.
    pub fc: f64,
    /// Speed of sound (m/s).
    pub c: f64,
}

/// What the grid depends on besides the scene.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PlanInputs {
    pub fc: f64,
    pub c: f64,
    pub fs: f64,
    pub db_thresh: f64,
    pub frequency_step: f64,
    pub window: RfWindow,
    pub pulse: PulseModel,
    pub pulse_duration: f64,
}

impl FrequencyPlan {
    /// Number of computed bins.
    pub fn n_bins(&self) -> usize {
        self.band_last + 1 - self.band_first
    }

    /// Frequency (Hz) of grid bin `k`.
    pub fn frequency(&self, k: usize) -> f64 {
        k as f64 * self.df
    }

    /// Frequencies (Hz) of the computed band.
    pub fn band_frequencies(&self) -> (f64, f64) {
        (self.frequency(self.band_first), self.frequency(self.band_last))
    }

    /// Longest round trip (s) this plan holds without circular aliasing: `1/df` (the RF keeps the
    /// first half of it with MUST's window, all but about one pulse duration with the compact one).
    pub fn window(&self) -> f64 {
        1.0 / self.df
    }

    /// A plan fixed for scatterers up to `max_element_distance` (m) from any element and delays
    /// up to `max_delay` (s); see the module docs. Identical to MUST's per-call plan for a scene
    /// whose largest distance is `max_element_distance`.
    pub(crate) fn for_max_distance(inp: &PlanInputs, max_element_distance: f64, max_delay: f64) -> Result<Self> {
        if !(max_element_distance.is_finite() && max_element_distance >= 0.0) {
            return Err(invalid("plan.max_distance", max_element_distance, "finite and >= 0 (m)"));
        }
        let max_d = max_element_distance + inp.pulse_duration * inp.c;
        // MUST: the window 1/df0 holds twice the longest round trip; compact: once
        let round_trip = 2.0 * max_d / inp.c + max_delay;
        let grid = |df0: f64| -> Result<(usize, f64)> {
            let nf_half = (inp.fc / df0).ceil();
            if !(nf_half.is_finite() && nf_half <= 5.0e7) {
                return Err(invalid(
                    "plan.max_distance",
                    max_element_distance,
                    "small enough that the grid has <= 1e8 bins (fc / df)",
                ));
            }
            let n_freq = 2 * nf_half as usize + 1;
            Ok((n_freq, 2.0 * inp.fc / (n_freq - 1) as f64))
        };
        let (must_n_freq, must_df) = grid(1.0 / 2.0 / round_trip * inp.frequency_step)?;
        // MUST's sample count for this scene (the compact window keeps as many)
        let must_n_fft = (inp.fs / 2.0 / inp.fc * (must_n_freq - 1) as f64).ceil() as usize;
        let must_n_samples = must_n_fft.div_ceil(2);
        let (n_freq, df) = match inp.window {
            RfWindow::Must => (must_n_freq, must_df),
            // the echoes (≤ the round trip) and the kept samples (shorter than the round trip when
            // FrequencyStep > 1, longer when < 1), plus one pulse duration: a pulse's leading half
            // that starts before t = 0 (scatterers within ~c·tp/4 of an element) wraps to the
            // window's end, past the samples kept
            RfWindow::Compact => {
                let kept = must_n_samples as f64 / inp.fs;
                grid(1.0 / (round_trip.max(kept) + inp.pulse_duration))?
            }
        };
        // band: |P H| above db_thresh relative to its maximum over the grid
        let mag: Vec<f64> = (0..n_freq)
            .map(|k| {
                let w = 2.0 * PI * (k as f64 * df);
                (inp.pulse.pulse_im(w) * inp.pulse.probe(w)).abs()
            })
            .collect();
        let peak = mag.iter().fold(0.0f64, |m, v| m.max(*v));
        let keep = |v: &f64| 20.0 * (1e-200 + v / peak).log10() > inp.db_thresh;
        let band_first = mag.iter().position(keep).unwrap_or(0);
        let band_last = mag.iter().rposition(keep).unwrap_or(0);
        let n_fft = (inp.fs / 2.0 / inp.fc * (n_freq - 1) as f64).ceil() as usize;
        let n_samples = must_n_samples.min(n_fft);
        Ok(Self {
            df,
            n_freq,
            band_first,
            band_last,
            n_fft,
            n_samples,
            window: inp.window,
            gain_df: must_df,
            fs: inp.fs,
            t0: 0.0,
            max_distance: max_d,
            max_delay,
            fc: inp.fc,
            c: inp.c,
        })
    }
}
