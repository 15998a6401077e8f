//! The hydrodynamic coefficients of a platelet, as paper 2's eq 6 uses them, and the interface
//! every source of them implements (resolved Stokes solver, trained networks, closed forms of a
//! spheroid).
//!
//! **Definitions** (SI, body frame: the platelet's own x axis is at angle φ from the lab x axis;
//! δv = v − V the relative velocity at the centre of mass; ψ = ∠(e_x, δv) − φ, eq 11; ω the local
//! fluid angular velocity = ½ (∂v_y/∂x − ∂v_x/∂y); Ω the particle's):
//!
//! F = C_d(ψ) δv + C_l(ψ) δv^⊥,  T = C_p(ψ) |δv| + C_r (ω − Ω) + C_s E'_xy
//!
//! with δv^⊥ the counter-clockwise rotation of δv by 90°, all torques about the centre of mass and
//! E'_xy the off-diagonal strain rate ½ (∂v_x/∂y + ∂v_y/∂x) expressed in the body frame.
//!
//! - `c_d` \[kg/s\]: drag, the force along δv per unit |δv| (paper's D for |δv| = 1).
//! - `c_l` \[kg/s\]: lift, the force along δv^⊥ per unit |δv| (paper's L).
//! - `c_p` \[kg·m/s\]: pitching torque per unit |δv| (paper's T).
//! - `c_r` \[N·m·s\]: rotational torque per unit relative angular velocity (paper's T_r / 2π).
//! - `c_s` \[N·m·s\]: torque per unit body-frame strain rate E'_xy (the flow (y, x, 0)·ε on the
//!   fixed body). **Not in paper 2**: eq 6 has no strain torque, so it cannot produce Jeffery
//!   orbits. Without inertia the torque balance gives Ω = ω + (c_s / c_r) E'_xy, Jeffery's
//!   equation, so c_s / c_r is Bretherton's shape factor B; for any ellipsoid with semi-axes
//!   a = Lx/2, b = Ly/2 (Jeffery 1922) B = (a² − b²) / (a² + b²), positive for a body long along
//!   its x axis. The period in simple shear is then 2π/γ̇ (r + 1/r), r = a/b.
pub use crate::shape::Shape;

/// Drag, lift and pitching torque coefficients at one effective angle of attack (module doc).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Translational {
    /// Drag \[kg/s\].
    pub c_d: f64,
    /// Lift \[kg/s\].
    pub c_l: f64,
    /// Pitching torque per unit relative speed \[kg·m/s\].
    pub c_p: f64,
}

/// Orientation-independent coefficients (module doc).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Rotational {
    /// Rotational torque per unit relative angular velocity \[N·m·s\].
    pub c_r: f64,
    /// Strain torque per unit body-frame strain rate \[N·m·s\] (an extension of eq 6).
    pub c_s: f64,
}

/// A source of coefficients, evaluated for many particles at once (networks batch well).
pub trait CoefficientModel: Send + Sync {
    /// `out[i]` = coefficients of `shapes[i]` at effective angle of attack `psi[i]` \[rad\].
    /// All three slices have the same length.
    fn translational(&self, shapes: &[Shape], psi: &[f64], out: &mut [Translational]);
    /// `out[i]` = orientation-independent coefficients of `shapes[i]`.
    fn rotational(&self, shapes: &[Shape], out: &mut [Rotational]);
    /// A short name for reports ("network", "stokes", "spheroid").
    fn name(&self) -> &str;
}
