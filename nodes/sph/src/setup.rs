//! Particle set-ups for validation cases.

use crate::particles::{ParticleKind, Particles};
use crate::Real;

/// Plane channel between plates z = 0 and z = `width`, periodic in x over `n_along` · dx.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChannelConfig {
    /// Plate separation L \[m\].
    pub width: Real,
    /// Lattice spacing dx = L / `n_across` (so the fluid has `n_across − 1` rows strictly inside).
    pub n_across: usize,
    /// Number of lattice columns along x (period = `n_along` · dx).
    pub n_along: usize,
    /// Layers of type II particles outside each plate (cover one kernel support).
    pub wall_layers: usize,
    /// Reference density ρ₀ \[kg/m³\]; mass = ρ₀ dx².
    pub rho0: Real,
    /// Velocity of the upper plate along x (Couette) \[m/s\].
    pub top_wall_velocity: Real,
}

impl ChannelConfig {
    /// Lattice spacing \[m\].
    pub fn dx(&self) -> Real {
        self.width / self.n_across as Real
    }

    /// Period along x \[m\].
    pub fn length(&self) -> Real {
        self.n_along as Real * self.dx()
    }

    /// Builds the particles: fluid rows at z = j dx (j = 1 … n_across − 1), type I rows on the plates,
    /// type II rows at z = −k dx and L + k dx. Fluid at rest with ρ = ρ₀.
    pub fn build(&self) -> Particles {
        let dx = self.dx();
        let m = self.rho0 * dx * dx;
        let mut p = Particles::default();
        let mut id = 0u64;
        let n = self.n_across as i64;
        let lay = self.wall_layers as i64;
        for j in -lay..=n + lay {
            let z = j as Real * dx;
            let (kind, vx) = if j <= 0 || j >= n {
                let on = j == 0 || j == n;
                let kind = if on { ParticleKind::WallOn } else { ParticleKind::WallOutside };
                (kind, if j >= n { self.top_wall_velocity } else { 0.0 })
            } else {
                (ParticleKind::Fluid, 0.0)
            };
            for i in 0..self.n_along {
                p.push((i as Real + 0.5) * dx, z, vx, 0.0, self.rho0, m, kind, id);
                id += 1;
            }
        }
        p
    }
}
