//! Motion of the scene around the blood: wall pulsation (tissue only) and bulk motion (the whole
//! scene), both smooth and known exactly, so that clutter filters meet tissue that moves.
//!
//! - **Wall pulsation** (`tissue.pulsation`): a tissue scatterer at rest position p₀, a distance
//!   d ≥ 0 outside the lumen boundary with outward normal n, is at
//!   p₀ + A·w(t)·e^(−d/λ)·n with the cardiac waveform w(t) = ½(1 − cos 2π(t − t₀)/T) (0 at t₀,
//!   1 at mid-cycle), or, with `waveform = "inflow"` (SPH scenes), the scene's own inflow
//!   waveform u(t) scaled to [0, 1] over its cycle: w(t) = (u(t − t₀) − u_min)/(u_max − u_min)
//!   (the wall distends with the pulse). The lumen and the blood stay rigid: the wall only moves outward from its
//!   rest position, so no tissue enters the lumen (documented in docs/nodes.md).
//! - **Bulk motion** (`bulk`, top level): the whole scene (blood, lumen, tissue and the truth
//!   field) turns by θ(t) = θ̂·s(t) about `center` and translates by a·s(t), with
//!   s(t) = sin 2π(t − t₀)/T, as from a probe held by hand or breathing. Blood velocities on
//!   the wire and in the truth are the lab-frame ones (flow plus bulk motion).
//!
//! Velocities are the exact time derivatives of these displacements.

use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

use crate::{require, ParamError};

/// Wall pulsation of the tissue (see the module doc).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct Pulsation {
    /// Peak outward displacement at the lumen boundary (m), in [0, 2e-3]. Default 0.3 mm (the
    /// common carotid's diameter changes by ≈ 0.5–0.7 mm over a cycle).
    pub amplitude: f64,
    /// Cardiac period T (s), in [0.2, 10]. Default 1 s (60 beats per minute).
    pub period: f64,
    /// Decay length λ of the displacement away from the wall (m), in (0, 0.05]. Default 5 mm.
    pub decay_length: f64,
    /// Time t₀ (s) of the rest position (start of the cycle), finite. Default 0. With
    /// `waveform = "inflow"`: the delay of the wall's motion behind the inflow.
    pub t0: f64,
    /// `raised-cosine` (default: w(t) above, with `period`) or `inflow` (the scene's inflow
    /// waveform scaled to [0, 1]; its period, not `period`; SPH scenes only).
    pub waveform: PulsationWaveform,
}

/// Time course of the wall pulsation (module doc).
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum PulsationWaveform {
    /// ½(1 − cos 2π(t − t₀)/T).
    #[default]
    RaisedCosine,
    /// The scene's inflow waveform scaled to [0, 1] (SPH scenes).
    Inflow,
}

impl Default for Pulsation {
    fn default() -> Self {
        Self { amplitude: 0.3e-3, period: 1.0, decay_length: 5e-3, t0: 0.0, waveform: PulsationWaveform::RaisedCosine }
    }
}

impl Pulsation {
    /// Checks every field; the error names it (`tissue.pulsation.…`).
    pub fn validate(&self) -> Result<(), ParamError> {
        require(
            "tissue.pulsation.amplitude",
            self.amplitude,
            self.amplitude.is_finite() && (0.0..=2e-3).contains(&self.amplitude),
            "0 ..= 0.002 m",
        )?;
        require(
            "tissue.pulsation.period",
            self.period,
            self.period.is_finite() && (0.2..=10.0).contains(&self.period),
            "0.2 ..= 10 s",
        )?;
        require(
            "tissue.pulsation.decay_length",
            self.decay_length,
            self.decay_length.is_finite() && self.decay_length > 0.0 && self.decay_length <= 0.05,
            "0 < value <= 0.05 m",
        )?;
        require("tissue.pulsation.t0", self.t0, self.t0.is_finite(), "finite (s)")
    }

    /// The raised-cosine waveform w(t) = ½(1 − cos 2π(t − t₀)/T) and its derivative (for
    /// `waveform = "inflow"` the caller supplies w and dw/dt: [`crate::tissue::Tissue::place`]).
    pub fn waveform(&self, t: f64) -> (f64, f64) {
        let (sin, cos) = (TAU * (t - self.t0) / self.period).sin_cos();
        (0.5 * (1.0 - cos), 0.5 * TAU / self.period * sin)
    }

    /// Displacement magnitude per unit of w at distance `d` (m) outside the lumen: A·e^(−d/λ)
    /// (0 for an infinite distance, e.g. beyond a vessel's ends).
    pub fn reach(&self, d: f64) -> f64 {
        if d.is_finite() {
            self.amplitude * (-d.max(0.0) / self.decay_length).exp()
        } else {
            0.0
        }
    }
}

/// Rigid bulk motion of the whole scene (see the module doc).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct BulkMotion {
    /// Peak translation `[a_x, a_z]` (m), each in [−5e-3, 5e-3]. Default [1 mm, 0.5 mm].
    pub amplitude: [f64; 2],
    /// Peak rotation θ̂ (degrees), in [−10, 10]; positive turns +x towards +z. Default 0.
    pub rotation_deg: f64,
    /// Centre of rotation `[x, z]` (m), finite. Default [0, 20 mm].
    pub center: [f64; 2],
    /// Period T (s), in [0.2, 100]. Default 4 s (15 breaths per minute).
    pub period: f64,
    /// Time t₀ (s) of the rest position, finite. Default 0.
    pub t0: f64,
}

impl Default for BulkMotion {
    fn default() -> Self {
        Self { amplitude: [1e-3, 0.5e-3], rotation_deg: 0.0, center: [0.0, 0.02], period: 4.0, t0: 0.0 }
    }
}

/// A rigid transform at one time: lab = c + R(θ)(p − c) + d, with its rates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rigid {
    /// cos θ, sin θ.
    pub cos: f64,
    pub sin: f64,
    /// dθ/dt (rad/s).
    pub omega: f64,
    /// Centre of rotation (m).
    pub center: [f64; 2],
    /// Translation d (m) and its rate (m/s).
    pub shift: [f64; 2],
    pub shift_rate: [f64; 2],
}

impl Rigid {
    /// The identity (no bulk motion).
    pub const IDENTITY: Rigid =
        Rigid { cos: 1.0, sin: 0.0, omega: 0.0, center: [0.0; 2], shift: [0.0; 2], shift_rate: [0.0; 2] };

    /// Lab-frame position and velocity of a point at scene-frame position (x, z) moving with
    /// scene-frame velocity (vx, vz).
    pub fn apply(&self, x: f64, z: f64, vx: f64, vz: f64) -> [f64; 4] {
        let [cx, cz] = self.center;
        let (rx, rz) = (self.cos * (x - cx) - self.sin * (z - cz), self.sin * (x - cx) + self.cos * (z - cz));
        let (ux, uz) = (self.cos * vx - self.sin * vz, self.sin * vx + self.cos * vz);
        [
            cx + rx + self.shift[0],
            cz + rz + self.shift[1],
            ux - self.omega * rz + self.shift_rate[0],
            uz + self.omega * rx + self.shift_rate[1],
        ]
    }

    /// The scene-frame position of lab point (x, z) (inverse of [`apply`](Self::apply)'s position).
    pub fn invert(&self, x: f64, z: f64) -> (f64, f64) {
        let [cx, cz] = self.center;
        let (rx, rz) = (x - cx - self.shift[0], z - cz - self.shift[1]);
        (cx + self.cos * rx + self.sin * rz, cz - self.sin * rx + self.cos * rz)
    }
}

impl BulkMotion {
    /// Checks every field; the error names it (`bulk.…`).
    pub fn validate(&self) -> Result<(), ParamError> {
        require(
            "bulk.amplitude",
            format!("{:?}", self.amplitude),
            self.amplitude.iter().all(|a| a.is_finite() && a.abs() <= 5e-3),
            "[a_x, a_z] in m, each in -0.005 ..= 0.005",
        )?;
        require(
            "bulk.rotation_deg",
            self.rotation_deg,
            self.rotation_deg.is_finite() && self.rotation_deg.abs() <= 10.0,
            "-10 ..= 10 degrees",
        )?;
        require(
            "bulk.center",
            format!("{:?}", self.center),
            self.center.iter().all(|c| c.is_finite() && c.abs() <= 1.0),
            "[x, z] in m, finite, each within 1 m",
        )?;
        require(
            "bulk.period",
            self.period,
            self.period.is_finite() && (0.2..=100.0).contains(&self.period),
            "0.2 ..= 100 s",
        )?;
        require("bulk.t0", self.t0, self.t0.is_finite(), "finite (s)")
    }

    /// The transform at time `t`.
    pub fn at(&self, t: f64) -> Rigid {
        let k = TAU / self.period;
        let (s, ds) = {
            let (sin, cos) = (k * (t - self.t0)).sin_cos();
            (sin, k * cos)
        };
        let theta_hat = self.rotation_deg.to_radians();
        let (sin, cos) = (theta_hat * s).sin_cos();
        Rigid {
            cos,
            sin,
            omega: theta_hat * ds,
            center: self.center,
            shift: [self.amplitude[0] * s, self.amplitude[1] * s],
            shift_rate: [self.amplitude[0] * ds, self.amplitude[1] * ds],
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// Central difference of a function of time.
    fn rate(f: impl Fn(f64) -> f64, t: f64) -> f64 {
        let h = 1e-6;
        (f(t + h) - f(t - h)) / (2.0 * h)
    }

    #[test]
    fn pulsation_waveform_is_a_raised_cosine_with_its_exact_derivative() {
        let p = Pulsation { amplitude: 0.4e-3, period: 0.8, decay_length: 3e-3, t0: 0.1, ..Pulsation::default() };
        p.validate().unwrap();
        assert_eq!(p.waveform(0.1).0, 0.0);
        assert!((p.waveform(0.5).0 - 1.0).abs() < 1e-15);
        assert!((p.waveform(0.9).0).abs() < 1e-15);
        for t in [0.13, 0.37, 0.61, 1.7] {
            let (_, dw) = p.waveform(t);
            assert!((dw - rate(|t| p.waveform(t).0, t)).abs() < 1e-7, "t = {t}");
        }
        assert_eq!(p.reach(0.0), 0.4e-3);
        assert!((p.reach(3e-3) - 0.4e-3 / std::f64::consts::E).abs() < 1e-18);
        assert_eq!(p.reach(f64::INFINITY), 0.0);
    }

    #[test]
    fn bulk_motion_is_rigid_invertible_and_its_velocity_is_the_derivative() {
        let b =
            BulkMotion { amplitude: [1e-3, -0.5e-3], rotation_deg: 3.0, center: [1e-3, 0.02], period: 2.0, t0: 0.2 };
        b.validate().unwrap();
        let r0 = b.at(0.2);
        assert_eq!(r0.apply(0.004, 0.03, 0.0, 0.0)[..2], [0.004, 0.03]);
        let (x, z, vx, vz) = (0.003, 0.025, 0.2, -0.1);
        for t in [0.35, 0.9, 1.6] {
            let r = b.at(t);
            let [lx, lz, lvx, lvz] = r.apply(x, z, vx, vz);
            let (bx, bz) = r.invert(lx, lz);
            assert!((bx - x).abs() < 1e-15 && (bz - z).abs() < 1e-15);
            // A point moving with velocity (vx, vz) in the scene frame: its lab position's rate.
            let pos = |s: f64| b.at(s).apply(x + vx * (s - t), z + vz * (s - t), 0.0, 0.0);
            assert!((lvx - rate(|s| pos(s)[0], t)).abs() < 1e-8, "t = {t}");
            assert!((lvz - rate(|s| pos(s)[1], t)).abs() < 1e-8, "t = {t}");
            // Distances are kept.
            let [mx, mz, ..] = r.apply(x + 1e-3, z, 0.0, 0.0);
            assert!(((mx - lx).hypot(mz - lz) - 1e-3).abs() < 1e-15);
        }
        let mut bad = b.clone();
        bad.rotation_deg = 11.0;
        assert_eq!(bad.validate().unwrap_err().field(), "bulk.rotation_deg");
        bad = b.clone();
        bad.amplitude = [f64::NAN, 0.0];
        assert_eq!(bad.validate().unwrap_err().field(), "bulk.amplitude");
    }
}
