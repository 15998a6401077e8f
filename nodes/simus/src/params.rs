//! Medium and simulation options (MUST `param.c`, `param.attenuation`, `param.fs` and the
//! `options` structure of `simus`/`pfield`).

use serde::{Deserialize, Serialize};

use crate::error::{invalid, Result};

fn default_c() -> f64 {
    1540.0
}

/// Propagation medium (uniform).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Medium {
    /// Speed of sound (m/s), finite > 0. MUST `c`, default 1540.
    #[serde(default = "default_c")]
    pub c: f64,
    /// Attenuation (dB/cm/MHz), ≥ 0, linear in frequency, no dispersion. MUST `attenuation`,
    /// default 0. Amplitude factor per path `exp(−α/8.69 · f[MHz] · r[cm])` (MUST's constant 8.69).
    #[serde(default)]
    pub attenuation: f64,
}

impl Default for Medium {
    fn default() -> Self {
        Self { c: 1540.0, attenuation: 0.0 }
    }
}

impl Medium {
    /// Checks every field; the error names the field and the allowed range.
    pub fn validate(&self) -> Result<()> {
        if !(self.c.is_finite() && self.c > 0.0) {
            return Err(invalid("medium.c", self.c, "finite and > 0 (m/s)"));
        }
        if !(self.attenuation.is_finite() && self.attenuation >= 0.0) {
            return Err(invalid("medium.attenuation", self.attenuation, "finite and >= 0 (dB/cm/MHz)"));
        }
        Ok(())
    }
}

/// How the frequency grid is chosen (see [`crate::FrequencyPlan`]).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(tag = "mode", rename_all = "snake_case", deny_unknown_fields)]
pub enum PlanMode {
    /// MUST/PyMUST behaviour: a new grid for every call, from the scene's largest
    /// element–scatterer distance. Consecutive frames of a moving scene may then differ in
    /// length and gain (gain ∝ df, pymust-notes §5.9).
    #[default]
    PerCall,
    /// One grid for every call, planned for scatterers up to `max_distance` (m) from any element
    /// and transmit delays up to `max_delay` (s): same length and gain for a whole packet.
    /// A scene that would alias circularly with this grid is an error.
    MaxDistance {
        /// Largest element–scatterer distance to plan for (m), > 0.
        max_distance: f64,
        /// Largest transmit delay to plan for (s), ≥ 0.
        #[serde(default)]
        max_delay: f64,
    },
}

/// How long the RF time window is, which sets the frequency step (see [`crate::FrequencyPlan`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RfWindow {
    /// MUST/PyMUST: the window holds **twice** the longest round trip (plus the pulse margins)
    /// and the RF keeps its first half.
    #[default]
    Must,
    /// The window holds the longest round trip once (with MUST's margins, plus one pulse
    /// duration) and the RF keeps MUST's samples of it: about half the frequency bins, so about
    /// half the work, for the same RF up to the pulse's tails (the continuous spectrum is the
    /// same, sampled more coarsely but still finely enough for echoes of that duration). The RF
    /// has MUST's length and gain (the spectrum is scaled with MUST's step).
    Compact,
}

fn default_reanchor() -> u32 {
    128
}
fn default_block() -> u32 {
    256
}

/// Numerical method; the error of any mode against [`Accuracy::Exact`] can be measured with
/// [`crate::nrms`] on two runs of the same scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "mode", rename_all = "snake_case", deny_unknown_fields)]
pub enum Accuracy {
    /// Reference: every phasor `exp((−α + ik) r)` evaluated directly in f64 at every frequency
    /// bin, all sums in f64 (no SIMD). Slow (~100× [`Accuracy::Fast`]); for tests and error studies.
    Exact,
    /// f32 SIMD kernel with incremental phase stepping (`EXP ← EXP·EXPdf`, as MUST) and exact
    /// (f64 phase) re-anchoring at least every `reanchor_every` bins; partial sums in f32 over
    /// blocks of `scatterer_block` scatterers, then accumulated in f64. Default.
    /// Typical error vs `Exact`: nRMS ≈ 2e-6 with the defaults (tests/accuracy.rs prints the
    /// table against `reanchor_every`).
    Fast {
        /// Maximum number of bins between exact re-anchorings, in [1, 4096]. Default 128.
        /// The band is split into `ceil(n_bins / reanchor_every)` fixed ranges of equal size
        /// (±1 bin), which are also the parallel tasks (8 to 10 for the paper scenes).
        #[serde(default = "default_reanchor")]
        reanchor_every: u32,
        /// Scatterers per f32 partial sum (and per geometry block), in [1, 65536]. Default 256.
        #[serde(default = "default_block")]
        scatterer_block: u32,
    },
}

impl Default for Accuracy {
    fn default() -> Self {
        Accuracy::Fast { reanchor_every: default_reanchor(), scatterer_block: default_block() }
    }
}

/// Which build of the fast kernel runs (chosen at run time from the CPU's features; the
/// output differs between builds only by rounding, nRMS ~3e-7).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum KernelChoice {
    /// AVX-512 + FMA, else AVX2 + FMA, else portable.
    #[default]
    Auto,
    /// AVX2 + FMA if available, else portable (never AVX-512).
    Avx2,
    /// Portable build without FMA.
    Portable,
}

fn default_db_thresh() -> f64 {
    -100.0
}
fn default_one() -> f64 {
    1.0
}
fn default_true() -> bool {
    true
}

/// Options of a SIMUS run (MUST `options` plus `param.fs`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimusOptions {
    /// RF sampling frequency (Hz); absent = 4·fc (MUST `param.fs`). Must be ≥ 4·fc.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fs: Option<f64>,
    /// Band threshold (dB, < 0): only bins where |pulse × one-way probe| is above this level
    /// relative to its maximum are computed. MUST `dBThresh`, default −100.
    #[serde(default = "default_db_thresh", alias = "dBThresh", alias = "dbthresh")]
    pub db_thresh: f64,
    /// Scale factor on the anti-aliasing frequency step (> 0; > 1 may alias, < 1 is finer).
    /// MUST `FrequencyStep`, default 1.
    #[serde(default = "default_one", alias = "FrequencyStep", alias = "frequencystep")]
    pub frequency_step: f64,
    /// RF time window: MUST's (twice the longest round trip, the default) or `compact` (once:
    /// about half the work, the same samples up to the pulse's tails; see [`RfWindow`]).
    #[serde(default)]
    pub window: RfWindow,
    /// Element directivity evaluated at every frequency (`true`) or at fc only (`false`, MUST's
    /// default). MUST `FullFrequencyDirectivity`. Costs ~2.5× in the fast mode (one f32 sinc per
    /// sub-element and bin); changes the paper scene's RF by nRMS ~1e-2.
    #[serde(default, alias = "FullFrequencyDirectivity", alias = "fullfrequencydirectivity")]
    pub full_frequency_directivity: bool,
    /// Sub-elements per element; absent = MUST's automatic `ceil(width / λmin)`,
    /// `λmin = c / (fc (1 + bandwidth/200))`. MUST `ElementSplitting`. In [1, 64].
    #[serde(default, alias = "ElementSplitting", alias = "elementsplitting", skip_serializing_if = "Option::is_none")]
    pub element_splitting: Option<u32>,
    /// Apply PyMUST's final "small-value zeroing" (simus.py: samples below about −100 dB of the
    /// frame maximum are set to zero through a quantised tanh step). Default true, as PyMUST.
    #[serde(default = "default_true")]
    pub zero_small_values: bool,
    /// Frequency grid per call (MUST) or fixed for a packet.
    #[serde(default)]
    pub plan: PlanMode,
    /// Numerical method.
    #[serde(default)]
    pub accuracy: Accuracy,
    /// Build of the fast kernel: the best the CPU supports (default), at most AVX2, or the
    /// portable build (same algorithm without FMA: the scalar twin the tests compare against).
    #[serde(default)]
    pub kernel: KernelChoice,
    /// Worker threads: absent = rayon's global pool; `n` = a dedicated pool of n threads.
    /// The output bits do not depend on the thread count.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub threads: Option<usize>,
}

impl Default for SimusOptions {
    fn default() -> Self {
        Self {
            fs: None,
            db_thresh: -100.0,
            frequency_step: 1.0,
            window: RfWindow::Must,
            full_frequency_directivity: false,
            element_splitting: None,
            zero_small_values: true,
            plan: PlanMode::PerCall,
            accuracy: Accuracy::default(),
            kernel: KernelChoice::Auto,
            threads: None,
        }
    }
}

impl SimusOptions {
    /// Checks every field (`fc` is needed for the `fs ≥ 4 fc` rule); the error names the field
    /// and the allowed range.
    pub fn validate(&self, fc: f64) -> Result<()> {
        if let Some(fs) = self.fs {
            if !(fs.is_finite() && fs >= 4.0 * fc) {
                return Err(invalid("options.fs", fs, ">= 4 * probe.fc (Hz) and finite"));
            }
        }
        if !(self.db_thresh.is_finite() && self.db_thresh < 0.0) {
            return Err(invalid("options.db_thresh", self.db_thresh, "finite and < 0 (dB)"));
        }
        if !(self.frequency_step.is_finite() && self.frequency_step > 0.0) {
            return Err(invalid("options.frequency_step", self.frequency_step, "finite and > 0"));
        }
        if let Some(m) = self.element_splitting {
            if !(1..=64).contains(&m) {
                return Err(invalid("options.element_splitting", m, "in [1, 64]"));
            }
        }
        if let PlanMode::MaxDistance { max_distance, max_delay } = self.plan {
            if !(max_distance.is_finite() && max_distance > 0.0) {
                return Err(invalid("options.plan.max_distance", max_distance, "finite and > 0 (m)"));
            }
            if !(max_delay.is_finite() && max_delay >= 0.0) {
                return Err(invalid("options.plan.max_delay", max_delay, "finite and >= 0 (s)"));
            }
        }
        if let Accuracy::Fast { reanchor_every, scatterer_block } = self.accuracy {
            if !(1..=4096).contains(&reanchor_every) {
                return Err(invalid("options.accuracy.reanchor_every", reanchor_every, "in [1, 4096]"));
            }
            if !(1..=65_536).contains(&scatterer_block) {
                return Err(invalid("options.accuracy.scatterer_block", scatterer_block, "in [1, 65536]"));
            }
        }
        if let Some(t) = self.threads {
            if t == 0 || t > 1024 {
                return Err(invalid("options.threads", t, "in [1, 1024]"));
            }
        }
        Ok(())
    }
}
