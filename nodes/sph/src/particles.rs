//! Struct-of-arrays particle state.

use serde::{Deserialize, Serialize};

use crate::Real;

/// Role of a particle (paper §2.2; Liu & Liu 2010 §5.1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ParticleKind {
    /// Moving fluid particle (an acoustic scatterer).
    Fluid,
    /// Fixed virtual particle on the wall (type I): prescribed wall velocity; pressure and density
    /// interpolated from the surrounding fluid.
    WallOn,
    /// Fixed virtual particle outside the wall (type II): velocity extrapolated for no-slip
    /// (u = 2 u_wall − ũ, ũ the Shepard mean of the fluid velocity at the particle); pressure as type I
    /// (zero normal gradient, plus the body-force hydrostatic term).
    WallOutside,
}

impl ParticleKind {
    /// True for fixed virtual (wall) particles.
    #[inline]
    pub fn is_wall(self) -> bool {
        !matches!(self, ParticleKind::Fluid)
    }
}

/// All particles, struct of arrays. For wall particles `vx`, `vz` hold the prescribed wall velocity
/// (moving walls keep their positions: they model walls that slide along themselves).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Particles {
    /// Lateral position x \[m\].
    pub x: Vec<Real>,
    /// Depth position z \[m\].
    pub z: Vec<Real>,
    /// Velocity along x \[m/s\].
    pub vx: Vec<Real>,
    /// Velocity along z \[m/s\].
    pub vz: Vec<Real>,
    /// Density ρ \[kg/m³\].
    pub rho: Vec<Real>,
    /// Mass m \[kg/m\] (2D: per unit out-of-plane length).
    pub mass: Vec<Real>,
    /// Particle role.
    pub kind: Vec<ParticleKind>,
    /// Stable identifier (kept for the particle's life).
    pub id: Vec<u64>,
}

impl Particles {
    /// Number of particles.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// True when there are no particles.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// Appends one particle.
    #[allow(clippy::too_many_arguments)]
    pub fn push(&mut self, x: Real, z: Real, vx: Real, vz: Real, rho: Real, mass: Real, kind: ParticleKind, id: u64) {
        self.x.push(x);
        self.z.push(z);
        self.vx.push(vx);
        self.vz.push(vz);
        self.rho.push(rho);
        self.mass.push(mass);
        self.kind.push(kind);
        self.id.push(id);
    }

    /// Length of each array if they all agree, `None` otherwise.
    pub fn consistent_len(&self) -> Option<usize> {
        let n = self.x.len();
        let all = [
            self.z.len(),
            self.vx.len(),
            self.vz.len(),
            self.rho.len(),
            self.mass.len(),
            self.kind.len(),
            self.id.len(),
        ];
        all.iter().all(|&l| l == n).then_some(n)
    }

    /// Number of fluid particles.
    pub fn fluid_count(&self) -> usize {
        self.kind.iter().filter(|k| !k.is_wall()).count()
    }
}
