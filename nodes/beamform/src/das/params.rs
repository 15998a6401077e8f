//! The delay-and-sum parameters: receive apodisation, interpolation, probe and receive settings
//! ([`DasParams`]) and the transmitted wave ([`TxWave`]).

use serde::{Deserialize, Serialize};

use super::convex;
use crate::error::{check_len, invalid, positive, Result};

fn default_c() -> f64 {
    1540.0
}

/// Receive apodisation across the aperture a pixel uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Apodization {
    /// Equal weights (MUST's rectangular 0/1 aperture, default): the narrowest main lobe, first
    /// side lobes at −13 dB.
    #[default]
    Boxcar,
    /// Hann window over the aperture, `cos²(π u)` with `u ∈ [−½, ½]` the element's position
    /// across it: side lobes below −31 dB for a main lobe about 1.6 times wider.
    Hann,
}

impl Apodization {
    /// Weight of an element at relative position `u ∈ [−½, ½]` across the aperture.
    pub fn weight(self, u: f64) -> f64 {
        match self {
            Apodization::Boxcar => 1.0,
            Apodization::Hann => {
                let c = (std::f64::consts::PI * u.clamp(-0.5, 0.5)).cos();
                c * c
            }
        }
    }
}

/// Interpolation of the I/Q traces at the fractional delay.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Interpolation {
    /// Nearest sample (MUST `'nearest'`).
    Nearest,
    /// Linear between the two neighbouring samples (MUST `'linear'`, default).
    #[default]
    Linear,
}

/// Delay-and-sum parameters (MUST names, SI units).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DasParams {
    /// Centre (demodulation) frequency (Hz), > 0. MUST `fc`.
    pub fc: f64,
    /// Speed of sound (m/s), > 0, default 1540. MUST `c`.
    #[serde(default = "default_c")]
    pub c: f64,
    /// Sampling frequency of the I/Q traces (Hz), > 0. MUST `fs`.
    pub fs: f64,
    /// Time of sample 0 (s), finite, default 0. MUST `t0`.
    #[serde(default)]
    pub t0: f64,
    /// Element pitch (m), > 0. MUST `pitch`. Linear array: elements at `x_e = (e − (N−1)/2)·pitch`,
    /// z = 0; convex array: one pitch apart along the arc ([`DasParams::element_positions`]).
    pub pitch: f64,
    /// Number of elements in [1, 65536] (on a convex array, few enough that the arc spans less
    /// than half a circle). MUST `Nelements`.
    #[serde(alias = "Nelements", alias = "nelements")]
    pub n_elements: usize,
    /// Radius of curvature of a convex array (m), > 0; None or +∞ = linear array (default).
    /// MUST `radius`. The arc's chord lies on z = 0, centred on x = 0; its circle's centre is at
    /// (0, −h), h the apothem ([`crate::convex`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius: Option<f64>,
    /// Receive f-number, ≥ 0 and ≤ 1000; 0 = full aperture (MUST's default). MUST `fnumber`.
    #[serde(default)]
    pub fnumber: f64,
    /// Receive steering angle (rad), |θ| < 80°; needs `fnumber > 0` when ≠ 0. MUST `RXangle`.
    #[serde(default, alias = "RXangle", alias = "rxangle")]
    pub rx_angle: f64,
    /// Interpolation method, default linear.
    #[serde(default)]
    pub interpolation: Interpolation,
    /// Receive apodisation, default boxcar (MUST).
    #[serde(default)]
    pub apodization: Apodization,
}

impl DasParams {
    /// Lateral position of element `e` (m), as MUST: `(e − (N−1)/2)·pitch` for a linear array,
    /// `R sin θ_e` for a convex one (the x of [`DasParams::element_positions`]).
    pub fn element_x(&self, e: usize) -> f64 {
        match self.convex_radius() {
            None => (e as f64 - (self.n_elements as f64 - 1.0) / 2.0) * self.pitch,
            Some(r) => convex::convex_element(self.pitch, self.n_elements, r, e).0,
        }
    }

    /// The radius of a convex array (`radius` finite), None for a linear one.
    pub fn convex_radius(&self) -> Option<f64> {
        self.radius.filter(|r| r.is_finite())
    }

    /// `(x_e, z_e, θ_e)` of every element (m, m, rad): MUST `getElementPositions`. Linear array:
    /// x_e as [`DasParams::element_x`], z_e = 0, θ_e = 0; convex array:
    /// [`convex::convex_element_positions`] (θ_e is the angle of element e's normal from the z
    /// axis, positive towards +x).
    pub fn element_positions(&self) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let n = self.n_elements;
        match self.convex_radius() {
            None => ((0..n).map(|e| self.element_x(e)).collect(), vec![0.0; n], vec![0.0; n]),
            Some(r) => convex::convex_element_positions(self.pitch, n, r),
        }
    }

    /// Checks every field; the error names the field and the allowed range.
    pub fn validate(&self) -> Result<()> {
        positive("das.fc", self.fc)?;
        positive("das.c", self.c)?;
        positive("das.fs", self.fs)?;
        positive("das.pitch", self.pitch)?;
        if !self.t0.is_finite() {
            return Err(invalid("das.t0", self.t0, "finite (s)"));
        }
        if !(1..=65536).contains(&self.n_elements) {
            return Err(invalid("das.n_elements", self.n_elements, "in [1, 65536]"));
        }
        if !(self.fnumber.is_finite() && (0.0..=1000.0).contains(&self.fnumber)) {
            return Err(invalid("das.fnumber", self.fnumber, "in [0, 1000] (0 = full aperture)"));
        }
        if !(self.rx_angle.is_finite() && self.rx_angle.abs() < 80f64.to_radians()) {
            return Err(invalid("das.rx_angle", self.rx_angle, "finite with |rx_angle| < 80° (1.396 rad)"));
        }
        if self.rx_angle != 0.0 && self.fnumber == 0.0 {
            return Err(invalid(
                "das.fnumber",
                self.fnumber,
                "> 0 when rx_angle != 0 (a steered sub-aperture needs a finite width)",
            ));
        }
        convex::validate_radius(self)
    }
}

/// The transmitted wave, which sets the transmit distance `d_TX` of every pixel.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum TxWave {
    /// Plane wave tilted by `tilt` (rad, |tilt| < 80°); tilt > 0 travels towards +x
    /// (MUST `txdelay(param, tilt)`, SIMUS `Transmit::plane_wave`).
    PlaneWave {
        /// Tilt (rad).
        tilt: f64,
    },
    /// Wave focused at (x0, z0), z0 > 0 (MUST `txdelay(x0, z0, param)`).
    Focused {
        /// Focus x (m).
        x0: f64,
        /// Focus depth (m), > 0.
        z0: f64,
    },
    /// Diverging wave from the virtual source (x0, z0), z0 < 0.
    Diverging {
        /// Source x (m).
        x0: f64,
        /// Source z (m), < 0.
        z0: f64,
    },
    /// Arbitrary transmit delays (s) per element (NaN = element off; the transmitting elements
    /// must be contiguous). MUST `TXdelay`.
    Delays {
        /// One delay per element (s).
        delays: Vec<f64>,
    },
}

impl TxWave {
    /// Checks the wave against `n_elements`; the error names the field.
    pub fn validate(&self, n_elements: usize) -> Result<()> {
        let lim = 80f64.to_radians();
        match self {
            TxWave::PlaneWave { tilt } => {
                if !(tilt.is_finite() && tilt.abs() < lim) {
                    return Err(invalid("tx.tilt", tilt, "finite with |tilt| < 80° (1.396 rad)"));
                }
            }
            TxWave::Focused { x0, z0 } => {
                if !x0.is_finite() {
                    return Err(invalid("tx.x0", x0, "finite (m)"));
                }
                if !(z0.is_finite() && *z0 > 0.0) {
                    return Err(invalid("tx.z0", z0, "finite and > 0 for a focused wave (m)"));
                }
            }
            TxWave::Diverging { x0, z0 } => {
                if !x0.is_finite() {
                    return Err(invalid("tx.x0", x0, "finite (m)"));
                }
                if !(z0.is_finite() && *z0 < 0.0) {
                    return Err(invalid("tx.z0", z0, "finite and < 0 for a diverging wave (m)"));
                }
            }
            TxWave::Delays { delays } => {
                check_len("tx.delays", delays.len(), n_elements)?;
                if let Some(d) = delays.iter().find(|d| !(d.is_nan() || d.is_finite() && d.abs() < 1.0)) {
                    return Err(invalid("tx.delays", d, "NaN (element off) or finite with |delay| < 1 s"));
                }
                let on: Vec<usize> = (0..n_elements).filter(|&e| !delays[e].is_nan()).collect();
                match (on.first(), on.last()) {
                    (Some(a), Some(b)) if b - a + 1 == on.len() => {}
                    (None, _) => return Err(invalid("tx.delays", "all NaN", "at least one finite delay")),
                    _ => {
                        return Err(invalid(
                            "tx.delays",
                            "gaps",
                            "a contiguous run of transmitting (non-NaN) elements",
                        ));
                    }
                }
            }
        }
        Ok(())
    }

    /// Nominal tilt of the wave at pixel (x, z) (rad from the z axis, positive towards +x),
    /// used for the ideal Doppler projection; plane waves return their tilt.
    pub fn direction_at(&self, x: f64, z: f64) -> f64 {
        match self {
            TxWave::PlaneWave { tilt } => *tilt,
            TxWave::Focused { x0, z0 } | TxWave::Diverging { x0, z0 } => {
                let s = if z >= *z0 { 1.0 } else { -1.0 };
                (s * (x - x0)).atan2(s * (z - z0))
            }
            TxWave::Delays { .. } => 0.0,
        }
    }

    /// The transmit delays (s) of this wave on the array of `params` ([`DasParams::element_positions`]),
    /// minimum 0, as MUST `txdelay` (txdelay.py):
    ///
    /// * plane wave of tilt θ: linear array `x_e sin θ/c − min`; convex array `−d_e/c − min`, d_e
    ///   the distance from element e to the line tangent to the arc's circle at angle θ
    ///   (`xn = R sin θ, zn = R cos θ − h`, `d = |z_e + xn/(zn + h)·x_e − xn²/(zn + h) − zn| /
    ///   √(1 + xn²/(zn + h)²)`);
    /// * focused at f: `−|e − f|/c − min`; diverging from s: `|e − s|/c − min` (MUST picks the
    ///   sign of a convex array's law by whether the point lies in the circle of radius R about
    ///   (0, R); here the kind chooses it);
    /// * `Delays`: as given (NaN = element off).
    ///
    /// Errors: invalid parameters or wave.
    pub fn delays(&self, params: &DasParams) -> Result<Vec<f64>> {
        params.validate()?;
        self.validate(params.n_elements)?;
        Ok(convex::tx_delays(params, self))
    }
}
