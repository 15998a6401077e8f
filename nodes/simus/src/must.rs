//! A flat MUST-style `param` structure, for files written the MUST way
//! (`{"fc": 5e6, "pitch": 3e-4, "kerf": 3.5e-5, "Nelements": 128, "TXnow": 6, "TXdelay": [...]}`).

use serde::{Deserialize, Serialize};

use crate::error::Result;
use crate::params::Medium;
use crate::probe::{Baffle, Probe};
use crate::transmit::Transmit;

fn default_bandwidth() -> f64 {
    75.0
}
fn default_tx_now() -> f64 {
    1.0
}
fn default_c() -> f64 {
    1540.0
}

/// MUST's `param` fields in one flat structure (snake_case names, MUST spellings as aliases).
/// Defaults are MUST's. Split it with [`MustParam::into_parts`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MustParam {
    /// Centre frequency (Hz).
    pub fc: f64,
    /// Pitch (m).
    pub pitch: f64,
    /// Element width (m) (or give `kerf`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub width: Option<f64>,
    /// Kerf (m) (or give `width`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kerf: Option<f64>,
    /// Number of elements (MUST `Nelements`).
    #[serde(alias = "Nelements", alias = "nelements")]
    pub n_elements: usize,
    /// Pulse-echo −6 dB fractional bandwidth (%), default 75.
    #[serde(default = "default_bandwidth")]
    pub bandwidth: f64,
    /// `"soft"` (default), `"rigid"` or a number > 0.
    #[serde(default)]
    pub baffle: Baffle,
    /// Speed of sound (m/s), default 1540.
    #[serde(default = "default_c")]
    pub c: f64,
    /// Attenuation (dB/cm/MHz), default 0.
    #[serde(default)]
    pub attenuation: f64,
    /// Sampling frequency (Hz), default 4 fc.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fs: Option<f64>,
    /// Pulse cycles (MUST `TXnow`), default 1.
    #[serde(default = "default_tx_now", alias = "TXnow", alias = "txnow")]
    pub tx_now: f64,
    /// Transmit delays (s), `null` = element off (MUST `TXdelay`).
    #[serde(default, alias = "TXdelay", skip_serializing_if = "Option::is_none")]
    pub tx_delay: Option<Vec<Option<f64>>>,
    /// Transmit apodisation (MUST `TXapodization`).
    #[serde(default, alias = "TXapodization", skip_serializing_if = "Option::is_none")]
    pub tx_apodization: Option<Vec<f64>>,
    /// Radius of curvature (m): absent/infinite = linear (convex is rejected).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius: Option<f64>,
    /// Elevation focus (m): ignored in 2-D.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub focus: Option<f64>,
    /// Element height (m): ignored in 2-D.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height: Option<f64>,
    /// Receive f-number (MUST `fnumber`, used by `dasmtx`): not used by SIMUS, accepted so that
    /// one MUST param file serves `sonoflow simus`, `das` and `doppler`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fnumber: Option<f64>,
    /// Pulse repetition frequency (Hz) (MUST `PRF`, used by `iq2doppler`): not used by SIMUS.
    #[serde(default, alias = "PRF", skip_serializing_if = "Option::is_none")]
    pub prf: Option<f64>,
    /// Receive steering angle (rad) (MUST `RXangle`, used by `dasmtx`): not used by SIMUS.
    #[serde(default, alias = "RXangle", skip_serializing_if = "Option::is_none")]
    pub rx_angle: Option<f64>,
}

/// The pieces of a [`MustParam`].
#[derive(Clone, Debug, PartialEq)]
pub struct MustParts {
    /// Transducer.
    pub probe: Probe,
    /// Medium.
    pub medium: Medium,
    /// The transmit if `TXdelay` was given (apodisation applied).
    pub transmit: Option<Transmit>,
    /// `fs` if given (put it in [`crate::SimusOptions::fs`]).
    pub fs: Option<f64>,
}

impl MustParam {
    /// Splits into probe, medium, transmit and fs, validating each.
    pub fn into_parts(self) -> Result<MustParts> {
        let probe = Probe {
            fc: self.fc,
            pitch: self.pitch,
            width: self.width,
            kerf: self.kerf,
            n_elements: self.n_elements,
            bandwidth: self.bandwidth,
            baffle: self.baffle,
            tx_now: self.tx_now,
            radius: self.radius,
            focus: self.focus,
            height: self.height,
        };
        probe.validate()?;
        let medium = Medium { c: self.c, attenuation: self.attenuation };
        medium.validate()?;
        let transmit = match self.tx_delay {
            Some(d) => {
                let t = Transmit {
                    delays: d.into_iter().map(|v| v.unwrap_or(f64::NAN)).collect(),
                    apodization: self.tx_apodization.unwrap_or_default(),
                };
                t.validate(probe.n_elements)?;
                Some(t)
            }
            None => None,
        };
        Ok(MustParts { probe, medium, transmit, fs: self.fs })
    }
}
