//! Linear and convex arrays (MUST `param` transducer fields) and MUST probe presets.
//!
//! Linear array: element centres `x_e = (e − (N−1)/2)·pitch`, `z_e = 0` (MUST
//! `getElementPositions`, pymust-notes §0): x lateral from the first (left) element to the last,
//! z depth. Convex array of radius R (MUST `param.radius`): the elements lie on an arc whose
//! chord is the x axis (z = 0 at the chord, the arc bulges to z > 0 in the middle, centre of
//! the circle at (0, −h)); see [`Probe::element_positions`].

use serde::{Deserialize, Serialize};

use crate::error::{invalid, Result, SimusError};

/// Property of the baffle around each element (MUST `param.baffle`).
///
/// Obliquity factor applied to each sub-element's field at angle θ from its normal:
/// `Soft` → `cos θ` (default), `Rigid` → 1, `Impedance(α)` → `cos θ / (cos θ + α)` (α > 0).
/// Where `|θ| ≥ π/2` the factor is 1.1921e-7 (MUST).
/// Serialised as `"soft"`, `"rigid"` or a number.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "BaffleRepr", into = "BaffleRepr")]
pub enum Baffle {
    /// Soft baffle, obliquity `cos θ`.
    #[default]
    Soft,
    /// Rigid baffle, obliquity 1.
    Rigid,
    /// Intermediate baffle: obliquity `cos θ / (cos θ + α)`, α > 0.
    Impedance(f64),
}

#[derive(Serialize, Deserialize)]
#[serde(untagged)]
enum BaffleRepr {
    Name(String),
    Number(f64),
}

impl TryFrom<BaffleRepr> for Baffle {
    type Error = String;
    fn try_from(r: BaffleRepr) -> std::result::Result<Self, String> {
        match r {
            BaffleRepr::Number(a) => Ok(Baffle::Impedance(a)),
            BaffleRepr::Name(s) => match s.to_ascii_lowercase().as_str() {
                "soft" => Ok(Baffle::Soft),
                "rigid" => Ok(Baffle::Rigid),
                _ => Err(format!("baffle must be \"soft\", \"rigid\" or a positive number, got \"{s}\"")),
            },
        }
    }
}

impl From<Baffle> for BaffleRepr {
    fn from(b: Baffle) -> Self {
        match b {
            Baffle::Soft => BaffleRepr::Name("soft".into()),
            Baffle::Rigid => BaffleRepr::Name("rigid".into()),
            Baffle::Impedance(a) => BaffleRepr::Number(a),
        }
    }
}

fn default_bandwidth() -> f64 {
    75.0
}
fn default_tx_now() -> f64 {
    1.0
}

/// Uniform linear or convex array. Field names follow MUST's `param` (aliases accept MUST's
/// spelling).
///
/// In files, `fc`, `pitch`, `n_elements` and one of `width`/`kerf` are required; the other
/// fields take MUST's defaults (bandwidth 75 %, soft baffle, `TXnow` 1, linear).
/// [`Probe::default`] is the paper probe ([`Probe::paper_5mhz`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Probe {
    /// Centre frequency (Hz), > 0. MUST `fc`.
    pub fc: f64,
    /// Element pitch (m), > 0. MUST `pitch`.
    pub pitch: f64,
    /// Element width (m), in ]0, pitch]. MUST `width`; derived as `pitch − kerf` if absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub width: Option<f64>,
    /// Kerf (m), in [0, pitch[. MUST `kerf`; if both are given, `width + kerf = pitch` (±1.19e-7 m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kerf: Option<f64>,
    /// Number of elements, ≥ 1. MUST `Nelements`.
    #[serde(alias = "Nelements", alias = "nelements")]
    pub n_elements: usize,
    /// Pulse-echo −6 dB fractional bandwidth (%), in ]0, 200[. MUST `bandwidth`, default 75.
    #[serde(default = "default_bandwidth")]
    pub bandwidth: f64,
    /// Baffle: `"soft"` (default), `"rigid"` or a number > 0. MUST `baffle`.
    #[serde(default)]
    pub baffle: Baffle,
    /// Number of cycles of the transmitted windowed sine, > 0. MUST `TXnow`, default 1
    /// (the paper uses 6).
    #[serde(default = "default_tx_now", alias = "TXnow", alias = "txnow")]
    pub tx_now: f64,
    /// Radius of curvature (m). MUST `radius`; absent or infinite = linear array, finite and
    /// > 0 = convex array (elements on the arc, [`Probe::element_positions`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius: Option<f64>,
    /// Elevation focus (m), MUST `focus`: used by [`crate::pfield_3d`] off the imaging plane,
    /// ignored by SIMUS (2-D).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub focus: Option<f64>,
    /// Element height (m), MUST `height`: used by [`crate::pfield_3d`] off the imaging plane,
    /// ignored by SIMUS (2-D).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height: Option<f64>,
}

impl Default for Probe {
    fn default() -> Self {
        Self::paper_5mhz()
    }
}

/// Names accepted by [`Probe::preset`] (case-insensitive).
pub const PRESET_NAMES: &str =
    "paper-5mhz, L11-5v, L12-3v, P4-2v, C5-2v (convex), PA4-2/20, L9-4/38, LA530, L14-5/38, L14-5W/60, P6-3";

impl Probe {
    /// The probe of Shahriari & Garcia (2018), section 2.4: 5 MHz, 128 elements, pitch 0.30 mm,
    /// kerf 35 µm, 6-cycle pulse. The paper does not state the bandwidth; we use MUST's default
    /// 75 % (the paper's simulations ran MUST with its defaults). Soft baffle.
    pub fn paper_5mhz() -> Self {
        Self::linear(5e6, 0.30e-3, Some(0.30e-3 - 35e-6), Some(35e-6), 128, 75.0, 6.0)
    }

    fn linear(
        fc: f64,
        pitch: f64,
        width: Option<f64>,
        kerf: Option<f64>,
        n: usize,
        bandwidth: f64,
        tx_now: f64,
    ) -> Self {
        Self {
            fc,
            pitch,
            width,
            kerf,
            n_elements: n,
            bandwidth,
            baffle: Baffle::Soft,
            tx_now,
            radius: None,
            focus: None,
            height: None,
        }
    }

    /// MUST/PyMUST `getparam` presets (values of PyMUST 0.1.9 `getparam.py`; `TXnow` = 1, MUST's
    /// default, as getparam sets none) plus `paper-5mhz`. Elevation fields (`height`, `focus`)
    /// are used off the imaging plane only. `C5-2v` is convex (radius 49.57 mm).
    pub fn preset(name: &str) -> Result<Self> {
        let key = name.trim().to_ascii_uppercase();
        let mut p = match key.as_str() {
            "PAPER-5MHZ" | "PAPER" => return Ok(Self::paper_5mhz()),
            "L11-5V" => Self::linear(7.6e6, 0.3e-3, Some(0.27e-3), Some(0.03e-3), 128, 77.0, 1.0),
            "L12-3V" => Self::linear(7.54e6, 0.2e-3, Some(0.17e-3), Some(0.03e-3), 192, 93.0, 1.0),
            "P4-2V" => Self::linear(2.72e6, 0.3e-3, Some(0.25e-3), Some(0.05e-3), 64, 74.0, 1.0),
            "C5-2V" => Self::linear(3.57e6, 0.508e-3, Some(0.46e-3), Some(0.048e-3), 128, 79.0, 1.0),
            "PA4-2/20" => Self::linear(2.5e6, 0.3e-3, None, Some(0.05e-3), 64, 60.0, 1.0),
            "L9-4/38" => Self::linear(5e6, 0.3048e-3, None, Some(0.035e-3), 128, 65.0, 1.0),
            "LA530" => Self::linear(3e6, 0.215e-3 + 0.03e-3, Some(0.215e-3), Some(0.03e-3), 192, 75.0, 1.0),
            "L14-5/38" => Self::linear(7.2e6, 0.3048e-3, None, Some(0.025e-3), 128, 70.0, 1.0),
            "L14-5W/60" => Self::linear(7.5e6, 0.472e-3, None, Some(0.025e-3), 128, 65.0, 1.0),
            "P6-3" => Self::linear(4.5e6, 0.218e-3, None, Some(0.025e-3), 64, 2.0 / 3.0 * 100.0, 1.0),
            _ => return Err(SimusError::UnknownProbe { name: name.to_string(), known: PRESET_NAMES }),
        };
        match key.as_str() {
            "L11-5V" => (p.height, p.focus) = (Some(5e-3), Some(18e-3)),
            "L12-3V" => (p.height, p.focus) = (Some(5e-3), Some(20e-3)),
            "P4-2V" => (p.height, p.focus) = (Some(14e-3), Some(60e-3)),
            "C5-2V" => (p.radius, p.height, p.focus) = (Some(0.04957), Some(13.5e-3), Some(60e-3)),
            "PA4-2/20" => p.height = Some(14e-3),
            "L9-4/38" => p.height = Some(6e-3),
            _ => {}
        }
        Ok(p)
    }

    /// Element width (m): `width`, or `pitch − kerf`.
    pub fn element_width(&self) -> f64 {
        match (self.width, self.kerf) {
            (Some(w), _) => w,
            (None, Some(k)) => self.pitch - k,
            (None, None) => f64::NAN,
        }
    }

    /// Lateral position (m) of the centre of element `e` (on a convex array: of its centre on
    /// the arc, [`Probe::element_positions`]).
    pub fn element_x(&self, e: usize) -> f64 {
        match self.convex_radius() {
            None => (e as f64 - (self.n_elements as f64 - 1.0) / 2.0) * self.pitch,
            Some(_) => self.element_positions().get(e).map_or(f64::NAN, |p| p.x),
        }
    }

    /// The radius of curvature of a convex array (`radius` finite), None for a linear one.
    pub fn convex_radius(&self) -> Option<f64> {
        self.radius.filter(|r| r.is_finite())
    }

    /// Centre and normal of every element: MUST `getElementPositions`. Linear array: `x_e` as
    /// [`Probe::element_x`], `z_e = 0`, `θ_e = 0`. Convex array of radius R and N elements:
    /// `chord = 2R·sin((N−1)·asin(pitch/2R))`, apothem `h = √(R² − chord²/4)`, normal angles
    /// `θ_e = linspace(atan2(−chord/2, h), atan2(chord/2, h), N)` from the z axis (positive
    /// towards +x), `x_e = R sin θ_e`, `z_e = R cos θ_e − h`.
    pub fn element_positions(&self) -> Vec<ElementPosition> {
        let n = self.n_elements;
        match self.convex_radius() {
            None => (0..n)
                .map(|e| ElementPosition { x: (e as f64 - (n as f64 - 1.0) / 2.0) * self.pitch, z: 0.0, theta: 0.0 })
                .collect(),
            Some(r) => {
                let (chord, h) = arc_chord_apothem(r, self.pitch, n);
                let (a, b) = ((-chord / 2.0).atan2(h), (chord / 2.0).atan2(h));
                (0..n)
                    .map(|e| {
                        // numpy linspace: start + e·step, the last point exactly `b`
                        let t = if n == 1 {
                            a
                        } else if e == n - 1 {
                            b
                        } else {
                            a + e as f64 * ((b - a) / (n - 1) as f64)
                        };
                        ElementPosition { x: r * t.sin(), z: r * t.cos() - h, theta: t }
                    })
                    .collect()
            }
        }
    }

    /// Apothem h of a convex array (distance from the circle's centre to the chord; the centre
    /// is at (0, −h)); 0 for a linear array.
    pub fn apothem(&self) -> f64 {
        self.convex_radius().map_or(0.0, |r| arc_chord_apothem(r, self.pitch, self.n_elements).1)
    }

    /// True when (x, z) lies behind the face of the array (MUST's `isOUT`): z < 0, or for a
    /// convex array inside or on the circle of the arc, `x² + (z + h)² ≤ R²`.
    pub fn is_behind(&self, x: f64, z: f64) -> bool {
        behind_face(x, z, self.convex_radius().map(|r| (r, self.apothem())))
    }

    /// Checks every field; the error names the field and the allowed range.
    pub fn validate(&self) -> Result<()> {
        let pos = |field: &'static str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(invalid(field, v, "finite and > 0"))
            }
        };
        pos("probe.fc", self.fc)?;
        pos("probe.pitch", self.pitch)?;
        if self.n_elements == 0 || self.n_elements > 65_536 {
            return Err(invalid("probe.n_elements", self.n_elements, "in [1, 65536]"));
        }
        if let Some(w) = self.width {
            if !(w.is_finite() && w > 0.0 && w <= self.pitch) {
                return Err(invalid("probe.width", w, "finite, > 0 and <= pitch"));
            }
        }
        if let Some(k) = self.kerf {
            if !(k.is_finite() && k >= 0.0 && k < self.pitch) {
                return Err(invalid("probe.kerf", k, "finite, >= 0 and < pitch"));
            }
        }
        match (self.width, self.kerf) {
            (None, None) => return Err(invalid("probe.width", "none", "given (or probe.kerf given)")),
            (Some(w), Some(k)) if (self.pitch - w - k).abs() >= 1.1921e-7 => {
                return Err(invalid("probe.kerf", k, "such that width + kerf = pitch (within 1.19e-7 m)"));
            }
            _ => {}
        }
        if !(self.bandwidth > 0.0 && self.bandwidth < 200.0) {
            return Err(invalid("probe.bandwidth", self.bandwidth, "in ]0, 200[ (%)"));
        }
        pos("probe.tx_now", self.tx_now)?;
        if let Baffle::Impedance(a) = self.baffle {
            if !(a.is_finite() && a > 0.0) {
                return Err(invalid("probe.baffle", a, "\"soft\", \"rigid\" or a finite number > 0"));
            }
        }
        if let Some(r) = self.radius {
            if r.is_nan() || r <= 0.0 {
                return Err(invalid("probe.radius", r, "> 0 (infinite = linear array)"));
            }
            if r.is_finite() {
                if r > 1e6 {
                    return Err(invalid("probe.radius", r, "<= 1e6 m when finite (inf or none: a linear array)"));
                }
                if self.pitch > 2.0 * r {
                    return Err(invalid("probe.pitch", self.pitch, "<= 2·radius on a convex array"));
                }
                let half_angle = (self.pitch / 2.0 / r).asin();
                if (self.n_elements as f64 - 1.0) * half_angle >= std::f64::consts::FRAC_PI_2 {
                    let max = (std::f64::consts::FRAC_PI_2 / half_angle).ceil() as usize;
                    return Err(SimusError::ArcTooShort { n_elements: self.n_elements, radius: r, max });
                }
            }
        }
        Ok(())
    }
}

/// Centre and normal of one element (MUST `getElementPositions`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ElementPosition {
    /// Lateral position (m).
    pub x: f64,
    /// Depth (m); 0 on a linear array.
    pub z: f64,
    /// Angle of the element's normal from the z axis (rad, positive towards +x).
    pub theta: f64,
}

/// MUST's `isOUT`: z < 0, or inside or on the circle (radius R, centre (0, −h)) of a convex
/// array's arc (`arc` = (R, h); None for a linear array).
#[inline(always)]
pub(crate) fn behind_face(x: f64, z: f64, arc: Option<(f64, f64)>) -> bool {
    z < 0.0 || arc.is_some_and(|(r, h)| x * x + (z + h) * (z + h) <= r * r)
}

/// Chord and apothem of the arc of N elements at `pitch` on a circle of radius `r` (MUST).
fn arc_chord_apothem(r: f64, pitch: f64, n: usize) -> (f64, f64) {
    let chord = 2.0 * r * ((pitch / 2.0 / r).asin() * (n as f64 - 1.0)).sin();
    (chord, (r * r - chord * chord / 4.0).sqrt())
}
