//! Transmit delay laws and apodisation (MUST `txdelay`, `param.TXdelay`,
//! `param.TXapodization`; pymust-notes §2).

use serde::{Deserialize, Serialize};

use crate::error::{invalid, Result, SimusError};
use crate::probe::Probe;

/// One transmit: a delay (s) and an apodisation weight per element.
///
/// A NaN delay switches the element off (MUST: its apodisation becomes 0). Delays must
/// otherwise be finite and ≥ 0 (MUST's `txdelay` subtracts the minimum).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Transmit {
    /// Delay of each element (s), ≥ 0 or NaN (element off). MUST `TXdelay`.
    #[serde(alias = "TXdelay", alias = "txdelay", with = "nan_as_null")]
    pub delays: Vec<f64>,
    /// Apodisation weight of each element (finite); empty = all ones. MUST `TXapodization`.
    #[serde(default, alias = "TXapodization", skip_serializing_if = "Vec::is_empty")]
    pub apodization: Vec<f64>,
}

/// JSON has no NaN: delays are written with `null` for switched-off elements.
mod nan_as_null {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    pub fn serialize<S: Serializer>(v: &[f64], s: S) -> Result<S::Ok, S::Error> {
        let o: Vec<Option<f64>> = v.iter().map(|x| if x.is_nan() { None } else { Some(*x) }).collect();
        o.serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
        let o: Vec<Option<f64>> = Vec::deserialize(d)?;
        Ok(o.into_iter().map(|x| x.unwrap_or(f64::NAN)).collect())
    }
}

impl Transmit {
    /// All elements fire at t = 0 with unit weight (0° plane wave).
    pub fn zero(n_elements: usize) -> Self {
        Self { delays: vec![0.0; n_elements], apodization: Vec::new() }
    }

    fn from_raw(mut delays: Vec<f64>) -> Self {
        let min = delays.iter().copied().fold(f64::INFINITY, f64::min);
        if min.is_finite() {
            for d in &mut delays {
                // |.| removes the -0.0 of MUST's 0° law
                *d = (*d - min).abs();
            }
        }
        Self { delays, apodization: Vec::new() }
    }

    /// Plane wave tilted by `tilt` (rad, |tilt| < π/2): `delay_e = x_e sin(tilt)/c − min`.
    /// A positive tilt fires elements at larger x later: the wave travels towards +x. On a
    /// convex array (MUST `txdelay`): each element fires so that the wavefront is the line
    /// tangent to the arc at the angle `tilt`, `delay_e = −dist(e, tangent)/c − min`.
    pub fn plane_wave(probe: &Probe, c: f64, tilt: f64) -> Result<Self> {
        if !(tilt.is_finite() && tilt.abs() < std::f64::consts::FRAC_PI_2) {
            return Err(invalid("tilt", tilt, "finite with |tilt| < pi/2 (rad)"));
        }
        let Some(r) = probe.convex_radius() else {
            let d = (0..probe.n_elements).map(|e| probe.element_x(e) * tilt.sin() / c).collect();
            return Ok(Self::from_raw(d));
        };
        let h = probe.apothem();
        // the tangent point (xn, zn) and MUST's distance from each element to the tangent
        let (xn, zn) = (r * tilt.sin(), r * tilt.cos() - h);
        let s = xn / (zn + h);
        let d = probe
            .element_positions()
            .iter()
            .map(|p| -(p.z + s * p.x - xn * xn / (zn + h) - zn).abs() / (1.0 + s * s).sqrt() / c)
            .collect();
        Ok(Self::from_raw(d))
    }

    /// Wave focused at `(x0, z0)`, `z0 > 0`: `delay_e = −|e − focus|/c − min` (outer elements first).
    /// On a convex array the focus must lie in front of the arc.
    pub fn focused(probe: &Probe, c: f64, x0: f64, z0: f64) -> Result<Self> {
        if !(x0.is_finite() && z0.is_finite() && z0 > 0.0) {
            return Err(invalid("focus z0", z0, "finite and > 0 (m); use diverging() for z0 < 0"));
        }
        if probe.convex_radius().is_some() && probe.is_behind(x0, z0) {
            return Err(invalid(
                "focus z0",
                format!("{z0} at x0 = {x0}"),
                "in front of the convex array's face (outside the circle of its arc)",
            ));
        }
        Ok(Self::point(probe, c, x0, z0))
    }

    /// Diverging wave from the virtual source `(x0, z0)` behind the array, `z0 < 0`:
    /// `delay_e = |e − source|/c − min`. On a convex array, the centre of its circle
    /// `(0, −h)` gives all delays 0 (the arc's own diverging wave).
    pub fn diverging(probe: &Probe, c: f64, x0: f64, z0: f64) -> Result<Self> {
        if !(x0.is_finite() && z0.is_finite() && z0 < 0.0) {
            return Err(invalid("virtual source z0", z0, "finite and < 0 (m); use focused() for z0 > 0"));
        }
        Ok(Self::point(probe, c, x0, z0))
    }

    /// MUST `txdelay(x0, z0, param)`: `−sign(z0)·|e − (x0, z0)|/c − min` (elements at (x_e, z_e)).
    /// MUST decides focused/diverging on a convex array by `hypot(x0, R − z0) < R`, which calls a
    /// focus deeper than 2R diverging; here the sign of z0 decides, as on a linear array.
    fn point(probe: &Probe, c: f64, x0: f64, z0: f64) -> Self {
        let d = probe.element_positions().iter().map(|p| -z0.signum() * (p.x - x0).hypot(p.z - z0) / c).collect();
        Self::from_raw(d)
    }

    /// Effective apodisation of element `e`: 0 for a NaN delay, else the weight (1 if none given).
    pub fn weight(&self, e: usize) -> f64 {
        if self.delays.get(e).is_none_or(|d| d.is_nan()) {
            0.0
        } else {
            self.apodization.get(e).copied().unwrap_or(1.0)
        }
    }

    /// Largest non-NaN delay (0 if none): enters the time window of the frequency plan.
    pub fn max_delay(&self) -> f64 {
        self.delays.iter().filter(|d| !d.is_nan()).fold(0.0f64, |m, d| m.max(*d))
    }

    /// Checks lengths and values against `n_elements`; the error names the field, and the
    /// element index for a bad value.
    pub fn validate(&self, n_elements: usize) -> Result<()> {
        if self.delays.len() != n_elements {
            return Err(SimusError::LengthMismatch {
                field: "transmit.delays",
                got: self.delays.len(),
                expected: n_elements,
            });
        }
        if !self.apodization.is_empty() && self.apodization.len() != n_elements {
            return Err(SimusError::LengthMismatch {
                field: "transmit.apodization",
                got: self.apodization.len(),
                expected: n_elements,
            });
        }
        if let Some(d) = self.delays.iter().find(|d| !d.is_nan() && !(0.0..1.0).contains(*d)) {
            return Err(invalid("transmit.delays", d, "NaN (element off) or finite in [0, 1) s"));
        }
        if let Some(a) = self.apodization.iter().find(|a| !a.is_finite()) {
            return Err(invalid("transmit.apodization", a, "finite"));
        }
        Ok(())
    }
}
