//! Analytic velocity fields ([`FlowKind`]) and their exact geometry.
//!
//! The public description is [`FlowKind`]; [`Geometry`] is the pre-computed
//! form used on hot paths (axis cosines computed once).

use serde::{Deserialize, Serialize};

use crate::{require, ParamError};

/// Largest accepted |centre coordinate|, vessel length/diameter or disk
/// radius, in metres. Imaging scenes are centimetres; a value above 1 m is
/// almost certainly a unit mistake (millimetres passed as metres).
const MAX_EXTENT_M: f64 = 1.0;
/// Largest accepted |v_max| in m/s (blood is < 10 m/s even in jets).
const MAX_SPEED: f64 = 100.0;
/// Largest accepted |omega| in rad/s.
const MAX_OMEGA: f64 = 1.0e5;

/// An analytic, steady 2-D velocity field in the (x, z) imaging plane.
///
/// Conventions (see also the crate docs): x lateral, z depth (positive into
/// the body, probe at z = 0), SI units.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
pub enum FlowKind {
    /// Straight vessel segment with a parabolic (Poiseuille) profile.
    ///
    /// The axis passes through (`center_x`, `center_z`) with unit direction
    /// `a = (cos θ, sin θ)` in (x, z), θ = `angle_deg` in degrees: a positive
    /// angle tilts the axis towards +z, i.e. the vessel is deeper at +x.
    /// With `s` the coordinate along the axis and `r` the distance from it,
    /// the fluid is `|s| <= length/2`, `r <= diameter/2`, and the velocity is
    /// `u(r) a` with `u(r) = v_max (1 - (2r/D)^2)`. `v_max` is signed:
    /// positive flows along `a`. Particles leaving one end re-enter at the
    /// other (periodic along the axis).
    Poiseuille {
        /// Axis point, lateral (m).
        center_x: f64,
        /// Axis point, depth (m).
        center_z: f64,
        /// Axis angle from +x towards +z (degrees).
        angle_deg: f64,
        /// Lumen diameter D (m).
        diameter: f64,
        /// Signed centre-line speed (m/s).
        v_max: f64,
        /// Segment length along the axis (m).
        length: f64,
    },
    /// A band of fluid translating rigidly (plug flow): every particle moves with the same velocity
    /// `v a`, `a = (cos θ, sin θ)` as for [`FlowKind::Poiseuille`], inside `|s| <= length/2`,
    /// `r <= width/2` (periodic along the axis). No velocity gradient anywhere: the phantom that
    /// isolates the imaging chain's Doppler gain from the flow (speckle translation).
    Plug {
        /// Axis point, lateral (m).
        center_x: f64,
        /// Axis point, depth (m).
        center_z: f64,
        /// Axis angle from +x towards +z (degrees).
        angle_deg: f64,
        /// Band width across the axis (m).
        width: f64,
        /// Signed speed along the axis (m/s).
        v: f64,
        /// Band length along the axis (m).
        length: f64,
    },
    /// Rigid rotation of a disk of fluid.
    ///
    /// `v = omega * (-(z - center_z), x - center_x)` for points with
    /// `|(x, z) - centre| <= radius`; no fluid outside. A positive `omega`
    /// turns +x towards +z: on an image drawn with x to the right and z
    /// downwards this appears **clockwise** (counter-clockwise in a plot with
    /// z upwards).
    RotatingDisk {
        /// Centre, lateral (m).
        center_x: f64,
        /// Centre, depth (m).
        center_z: f64,
        /// Disk radius (m).
        radius: f64,
        /// Angular velocity (rad/s).
        omega: f64,
    },
}

impl Default for FlowKind {
    fn default() -> Self {
        FlowKind::Poiseuille {
            center_x: 0.0,
            center_z: 0.02,
            angle_deg: 20.0,
            diameter: 6.0e-3,
            v_max: 0.5,
            length: 0.04,
        }
    }
}

impl FlowKind {
    /// Checks every field for finiteness and range; the error names the
    /// field as `flow.<name>`.
    pub fn validate(&self) -> Result<(), ParamError> {
        let coord = format!("finite, |value| <= {MAX_EXTENT_M} m");
        let extent = format!("finite, 0 < value <= {MAX_EXTENT_M} m");
        match *self {
            FlowKind::Poiseuille { center_x, center_z, angle_deg, diameter, v_max, length } => {
                require_abs("flow.center_x", center_x, MAX_EXTENT_M, &coord)?;
                require_abs("flow.center_z", center_z, MAX_EXTENT_M, &coord)?;
                require_abs("flow.angle_deg", angle_deg, 360.0, "finite, -360 <= value <= 360 degrees")?;
                require_pos("flow.diameter", diameter, MAX_EXTENT_M, &extent)?;
                require_abs("flow.v_max", v_max, MAX_SPEED, &format!("finite, |value| <= {MAX_SPEED} m/s"))?;
                require_pos("flow.length", length, MAX_EXTENT_M, &extent)?;
            }
            FlowKind::Plug { center_x, center_z, angle_deg, width, v, length } => {
                require_abs("flow.center_x", center_x, MAX_EXTENT_M, &coord)?;
                require_abs("flow.center_z", center_z, MAX_EXTENT_M, &coord)?;
                require_abs("flow.angle_deg", angle_deg, 360.0, "finite, -360 <= value <= 360 degrees")?;
                require_pos("flow.width", width, MAX_EXTENT_M, &extent)?;
                require_abs("flow.v", v, MAX_SPEED, &format!("finite, |value| <= {MAX_SPEED} m/s"))?;
                require_pos("flow.length", length, MAX_EXTENT_M, &extent)?;
            }
            FlowKind::RotatingDisk { center_x, center_z, radius, omega } => {
                require_abs("flow.center_x", center_x, MAX_EXTENT_M, &coord)?;
                require_abs("flow.center_z", center_z, MAX_EXTENT_M, &coord)?;
                require_pos("flow.radius", radius, MAX_EXTENT_M, &extent)?;
                require_abs("flow.omega", omega, MAX_OMEGA, &format!("finite, |value| <= {MAX_OMEGA} rad/s"))?;
            }
        }
        Ok(())
    }

    /// Area of the fluid region in m² (vessel: length × diameter; disk: π r²).
    pub fn area_m2(&self) -> f64 {
        Geometry::from_kind(self).area_m2()
    }

    /// Exact velocity (vx, vz) in m/s at (x, z), or `None` outside the fluid
    /// (the boundary itself counts as inside) or for non-finite input.
    pub fn velocity(&self, x: f64, z: f64) -> Option<(f64, f64)> {
        Geometry::from_kind(self).velocity(x, z)
    }
}

fn require_abs(field: &'static str, v: f64, max: f64, allowed: &str) -> Result<(), ParamError> {
    require(field, v, v.is_finite() && v.abs() <= max, allowed)
}

fn require_pos(field: &'static str, v: f64, max: f64, allowed: &str) -> Result<(), ParamError> {
    require(field, v, v.is_finite() && v > 0.0 && v <= max, allowed)
}

/// Pre-computed geometry of a [`FlowKind`].
///
/// Each particle is described by two "local" numbers `(a, b)` fixed at
/// seeding time, from which its exact state at any later time follows:
/// vessel: `a` = axial coordinate `s0` at seeding, `b` = signed transverse
/// coordinate `q` (r = |q|); disk: `a` = radius `rho`, `b` = angle `phi0`.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Geometry {
    Pipe {
        cx: f64,
        cz: f64,
        /// Unit axis (cos θ, sin θ).
        ax: f64,
        az: f64,
        half_d: f64,
        length: f64,
        v_max: f64,
        /// Uniform speed across the band (plug flow) instead of the parabola.
        plug: bool,
    },
    Disk {
        cx: f64,
        cz: f64,
        radius: f64,
        omega: f64,
    },
}

/// Exact state of one particle: position and velocity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct State {
    pub x: f64,
    pub z: f64,
    pub vx: f64,
    pub vz: f64,
}

impl Geometry {
    pub(crate) fn from_kind(kind: &FlowKind) -> Self {
        match *kind {
            FlowKind::Poiseuille { center_x, center_z, angle_deg, diameter, v_max, length } => {
                let (az, ax) = angle_deg.to_radians().sin_cos();
                Geometry::Pipe {
                    cx: center_x,
                    cz: center_z,
                    ax,
                    az,
                    half_d: 0.5 * diameter,
                    length,
                    v_max,
                    plug: false,
                }
            }
            FlowKind::Plug { center_x, center_z, angle_deg, width, v, length } => {
                let (az, ax) = angle_deg.to_radians().sin_cos();
                Geometry::Pipe { cx: center_x, cz: center_z, ax, az, half_d: 0.5 * width, length, v_max: v, plug: true }
            }
            FlowKind::RotatingDisk { center_x, center_z, radius, omega } => {
                Geometry::Disk { cx: center_x, cz: center_z, radius, omega }
            }
        }
    }

    pub(crate) fn area_m2(&self) -> f64 {
        match *self {
            Geometry::Pipe { half_d, length, .. } => 2.0 * half_d * length,
            Geometry::Disk { radius, .. } => std::f64::consts::PI * radius * radius,
        }
    }

    pub(crate) fn velocity(&self, x: f64, z: f64) -> Option<(f64, f64)> {
        match *self {
            Geometry::Pipe { cx, cz, ax, az, half_d, length, v_max, plug } => {
                let (dx, dz) = (x - cx, z - cz);
                let s = dx * ax + dz * az;
                let q = -dx * az + dz * ax;
                // NaN fails both comparisons and lands in `None`.
                if s.abs() <= 0.5 * length && q.abs() <= half_d {
                    let u = pipe_speed(v_max, half_d, q, plug);
                    Some((u * ax, u * az))
                } else {
                    None
                }
            }
            Geometry::Disk { cx, cz, radius, omega } => {
                let (dx, dz) = (x - cx, z - cz);
                if dx * dx + dz * dz <= radius * radius {
                    Some((-omega * dz, omega * dx))
                } else {
                    None
                }
            }
        }
    }

    /// Distance (m) of a point outside the lumen to its boundary across the flow: a pipe's wall
    /// (`|q| − D/2`, within the segment's length; +∞ beyond its ends), a disk's rim (`r − R`).
    /// ≤ 0 inside.
    pub(crate) fn outside_distance(&self, x: f64, z: f64) -> f64 {
        match *self {
            Geometry::Pipe { cx, cz, ax, az, half_d, length, .. } => {
                let (dx, dz) = (x - cx, z - cz);
                if (dx * ax + dz * az).abs() > 0.5 * length {
                    return f64::INFINITY;
                }
                (-dx * az + dz * ax).abs() - half_d
            }
            Geometry::Disk { cx, cz, radius, .. } => (x - cx).hypot(z - cz) - radius,
        }
    }

    /// Unit normal pointing away from the lumen at a point outside it: across a pipe's axis, radial
    /// from a disk's centre ((0, 0) on the axis or at the centre).
    pub(crate) fn outward_normal(&self, x: f64, z: f64) -> (f64, f64) {
        match *self {
            Geometry::Pipe { cx, cz, ax, az, .. } => {
                let q = -(x - cx) * az + (z - cz) * ax;
                let s = if q > 0.0 {
                    1.0
                } else if q < 0.0 {
                    -1.0
                } else {
                    0.0
                };
                (-az * s, ax * s)
            }
            Geometry::Disk { cx, cz, .. } => {
                let (dx, dz) = (x - cx, z - cz);
                let r = dx.hypot(dz);
                if r > 0.0 {
                    (dx / r, dz / r)
                } else {
                    (0.0, 0.0)
                }
            }
        }
    }

    /// Maps two independent U[0, 1) draws to local coordinates that are
    /// uniformly distributed over the fluid area.
    pub(crate) fn local_from_unit(&self, u1: f64, u2: f64) -> (f64, f64) {
        match *self {
            Geometry::Pipe { half_d, length, .. } => ((u1 - 0.5) * length, (2.0 * u2 - 1.0) * half_d),
            // rho = R sqrt(U) gives a density proportional to rho: uniform in area.
            Geometry::Disk { radius, .. } => (radius * u1.sqrt(), std::f64::consts::TAU * u2),
        }
    }

    /// Exact state `dt` seconds after seeding of the particle with local
    /// coordinates `(a, b)`.
    pub(crate) fn state(&self, a: f64, b: f64, dt: f64) -> State {
        match *self {
            Geometry::Pipe { cx, cz, ax, az, half_d, length, v_max, plug } => {
                let q = b;
                let u = pipe_speed(v_max, half_d, q, plug);
                let half_l = 0.5 * length;
                // Periodic along the axis: s in [-L/2, L/2] (rem_euclid may
                // round up to exactly L, which is still on the closed segment).
                let s = (a + half_l + u * dt).rem_euclid(length) - half_l;
                State { x: cx + s * ax - q * az, z: cz + s * az + q * ax, vx: u * ax, vz: u * az }
            }
            Geometry::Disk { cx, cz, omega, .. } => {
                let rho = a;
                let (sin, cos) = (b + omega * dt).sin_cos();
                let (dx, dz) = (rho * cos, rho * sin);
                State { x: cx + dx, z: cz + dz, vx: -omega * dz, vz: omega * dx }
            }
        }
    }
}

/// u(q) = v_max (1 - (q / (D/2))^2), clamped to 0 at and beyond the wall; `v_max` everywhere
/// for a plug.
fn pipe_speed(v_max: f64, half_d: f64, q: f64, plug: bool) -> f64 {
    if plug {
        return v_max;
    }
    let xi = q / half_d;
    v_max * (1.0 - xi * xi).max(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pipe(angle_deg: f64, v_max: f64) -> FlowKind {
        FlowKind::Poiseuille { center_x: 0.001, center_z: 0.02, angle_deg, diameter: 6.0e-3, v_max, length: 0.04 }
    }

    /// Profile values are exact algebra on O(1e-2) coordinates; a relative
    /// tolerance of 1e-12 leaves room for the ~1e-16 rounding of the
    /// rotation into local coordinates.
    #[test]
    fn poiseuille_profile_centre_half_radius_outside_and_direction() {
        let tol = 1e-12;
        for &angle in &[-45.0, 0.0, 20.0, 90.0, 135.0] {
            for &v_max in &[0.5, -0.3] {
                let f = pipe(angle, v_max);
                let th = f64::to_radians(angle);
                let (ax, az) = (th.cos(), th.sin());
                let (nx, nz) = (-az, ax);
                let (cx, cz) = (0.001, 0.02);
                let r_half = 0.5 * 3.0e-3; // r = (D/2) * 0.5

                // Centre (and a point along the axis) -> v_max along the axis.
                for &s in &[0.0, 0.015, -0.019] {
                    let (vx, vz) = f.velocity(cx + s * ax, cz + s * az).expect("axis point inside");
                    assert!((vx - v_max * ax).abs() <= tol * v_max.abs(), "{angle} {s}");
                    assert!((vz - v_max * az).abs() <= tol * v_max.abs(), "{angle} {s}");
                }
                // r = D/4 on both sides -> 0.75 v_max, still along the axis.
                for &sign in &[1.0, -1.0] {
                    let (x, z) = (cx + sign * r_half * nx, cz + sign * r_half * nz);
                    let (vx, vz) = f.velocity(x, z).expect("inside");
                    let along = vx * ax + vz * az;
                    let across = -vx * az + vz * ax;
                    assert!((along - 0.75 * v_max).abs() <= tol * v_max.abs());
                    assert!(across.abs() <= tol * v_max.abs());
                }
                // Outside: beyond the wall, beyond the ends.
                let out = [
                    (cx + 3.1e-3 * nx, cz + 3.1e-3 * nz),
                    (cx - 3.1e-3 * nx, cz - 3.1e-3 * nz),
                    (cx + 0.0201 * ax, cz + 0.0201 * az),
                    (cx - 0.0201 * ax, cz - 0.0201 * az),
                ];
                for (x, z) in out {
                    assert_eq!(f.velocity(x, z), None, "angle {angle}: ({x}, {z})");
                }
            }
        }
    }

    #[test]
    fn positive_angle_goes_deeper_at_positive_x() {
        let f = pipe(20.0, 1.0);
        let (vx, vz) = f.velocity(0.001, 0.02).expect("centre inside");
        assert!(vx > 0.0 && vz > 0.0, "({vx}, {vz})");
    }

    /// Disk: v = omega (-(z - zc), x - xc) exactly (products of exact
    /// differences), zero-size tolerance apart from one rounding.
    #[test]
    fn disk_field_sign_and_extent() {
        let f = FlowKind::RotatingDisk { center_x: 0.0, center_z: 0.03, radius: 0.01, omega: 2.0 };
        // Point to the right of the centre moves towards +z (deeper).
        let (vx, vz) = f.velocity(0.005, 0.03).expect("inside");
        assert!(vx.abs() < 1e-15 && (vz - 0.01).abs() < 1e-15);
        // Point below (deeper than) the centre moves towards -x.
        let (vx, vz) = f.velocity(0.0, 0.035).expect("inside");
        assert!((vx + 0.01).abs() < 1e-15 && vz.abs() < 1e-15);
        assert_eq!(f.velocity(0.0101, 0.03), None);
        assert_eq!(f.velocity(f64::NAN, 0.03), None);
        assert!((f.area_m2() - std::f64::consts::PI * 1e-4).abs() < 1e-18);
    }

    /// The plug band translates rigidly: the same velocity everywhere inside (walls included),
    /// none outside, every particle displaced by v·t (modulo the period along the axis), and
    /// bad values rejected with the field's name.
    #[test]
    fn plug_band_translates_rigidly() {
        let f = FlowKind::Plug { center_x: 0.0, center_z: 0.02, angle_deg: 30.0, width: 0.01, v: 0.3, length: 0.04 };
        let (s, c) = 30f64.to_radians().sin_cos();
        for (along, across) in [(0.0, 0.0), (0.01, 0.0049), (-0.019, -0.005), (0.0, 0.004)] {
            let (x, z) = (along * c - across * s, 0.02 + along * s + across * c);
            let (vx, vz) = f.velocity(x, z).expect("inside");
            assert!((vx - 0.3 * c).abs() < 1e-15 && (vz - 0.3 * s).abs() < 1e-15, "({along}, {across})");
        }
        assert!(f.velocity(-0.0051 * s, 0.02 + 0.0051 * c).is_none(), "just outside the band");
        let g = Geometry::from_kind(&f);
        for (a, b) in [(0.0, 0.0), (-0.015, 0.004), (0.019, -0.0049)] {
            let (s0, s1) = (g.state(a, b, 0.0), g.state(a, b, 0.01));
            let d = ((s1.x - s0.x).powi(2) + (s1.z - s0.z).powi(2)).sqrt();
            // 3 mm along the axis unless the particle wrapped around the 40 mm period
            assert!((d - 0.003).abs() < 1e-12 || (d - 0.037).abs() < 1e-12, "displacement {d}");
            assert_eq!((s1.vx, s1.vz), (s0.vx, s0.vz));
        }
        let bad = FlowKind::Plug { center_x: 0.0, center_z: 0.02, angle_deg: 0.0, width: 0.0, v: 0.3, length: 0.04 };
        assert!(bad.validate().unwrap_err().to_string().contains("flow.width"));
        let bad = FlowKind::Plug { center_x: 0.0, center_z: 0.02, angle_deg: 0.0, width: 0.01, v: 1e3, length: 0.04 };
        assert!(bad.validate().unwrap_err().to_string().contains("flow.v"));
        let json = serde_json::to_string(&f).expect("serialize");
        assert!(json.contains("\"type\":\"plug\""), "{json}");
    }

    #[test]
    fn serde_round_trip_and_tags() {
        let disk = FlowKind::RotatingDisk { center_x: 0.0, center_z: 0.03, radius: 0.01, omega: 6.0 };
        let json = serde_json::to_string(&disk).expect("serialize");
        assert!(json.contains("\"type\":\"rotating-disk\""), "{json}");
        let back: FlowKind = serde_json::from_str(&json).expect("deserialize");
        assert_eq!(back, disk);
        let bad = r#"{"type":"rotating-disk","center_x":0,"center_z":0.03,"radius":0.01,"omega":1,"extra":2}"#;
        assert!(serde_json::from_str::<FlowKind>(bad).is_err());
        let json = serde_json::to_string(&FlowKind::default()).expect("serialize");
        assert!(json.contains("\"type\":\"poiseuille\""), "{json}");
    }
}
