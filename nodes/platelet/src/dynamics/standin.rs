//! A cheap closed-form stand-in for the trained networks (for benchmarks and tests until the
//! networks are plugged in through [`CoefficientModel`]). Not a validated hydrodynamic model.
//!
//! The body is treated as a thin disc of radius a = (Lx + Lz)/4 with Stokes resistances
//! k_⊥ = 16 μ a (broadside, along the body y axis), k_∥ = 32/3 μ a (edgewise) and rotation about a
//! diameter c_r = 32/3 μ a³. For a symmetric body F = diag(k_∥, k_⊥) δv in the body frame, hence
//! C_d = (k_∥ + k_⊥)/2 − (k_⊥ − k_∥)/2 cos 2ψ and C_l = (k_⊥ − k_∥)/2 sin 2ψ (the form of the
//! paper's rescaling in Algorithm 2 (c)). Pitching C_p = ½ μ a² (α_top − α_bot) cos ψ (zero for a
//! symmetric body; |C_p| < √(C_d C_r) so the coupled resistance matrix stays positive definite).
//! c_s = B c_r with Jeffery's B = (A² − b²)/(A² + b²), A = Lx/2, b = Ly/2.

use crate::coefficients::{CoefficientModel, Rotational, Translational};
use crate::shape::Shape;

/// The stand-in model (module doc).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DiscStandIn {
    /// Dynamic viscosity μ \[Pa s\] (paper 2: 3 mg/(mm s) = 3e-3 Pa s).
    pub viscosity: f64,
}

impl Default for DiscStandIn {
    fn default() -> Self {
        DiscStandIn { viscosity: 3e-3 }
    }
}

impl CoefficientModel for DiscStandIn {
    fn translational(&self, shapes: &[Shape], psi: &[f64], out: &mut [Translational]) {
        let mu = self.viscosity;
        for ((s, &p), o) in shapes.iter().zip(psi).zip(out.iter_mut()) {
            let a = 0.25 * (s.lx + s.lz);
            let (kpar, kperp) = (32.0 / 3.0 * mu * a, 16.0 * mu * a);
            let (s2, c2) = (2.0 * p).sin_cos();
            *o = Translational {
                c_d: 0.5 * (kpar + kperp) - 0.5 * (kperp - kpar) * c2,
                c_l: 0.5 * (kperp - kpar) * s2,
                c_p: 0.5 * mu * a * a * (s.alpha_top - s.alpha_bot) * p.cos(),
            };
        }
    }

    fn rotational(&self, shapes: &[Shape], out: &mut [Rotational]) {
        let mu = self.viscosity;
        for (s, o) in shapes.iter().zip(out.iter_mut()) {
            let a = 0.25 * (s.lx + s.lz);
            let c_r = 32.0 / 3.0 * mu * a * a * a;
            let (aa, bb) = ((0.5 * s.lx).powi(2), (0.5 * s.ly).powi(2));
            *o = Rotational { c_r, c_s: (aa - bb) / (aa + bb) * c_r };
        }
    }

    fn name(&self) -> &str {
        "disc-standin"
    }
}
