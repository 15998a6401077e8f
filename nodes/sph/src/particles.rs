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
    /// Particle in an open-boundary reservoir ([`crate::boundary`]): prescribed velocity, density
    /// from the continuity equation; `group` is the index of its boundary.
    Buffer,
}

impl ParticleKind {
    /// True for fixed virtual (wall) particles.
    #[inline]
    pub fn is_wall(self) -> bool {
        matches!(self, ParticleKind::WallOn | ParticleKind::WallOutside)
    }

    /// True for free fluid particles (not walls, not reservoir particles).
    #[inline]
    pub fn is_fluid(self) -> bool {
        matches!(self, ParticleKind::Fluid)
    }
}

/// All particles, struct of arrays. For wall particles `vx`, `vz` hold the prescribed wall velocity
/// (walls without a wall motion keep their positions: a velocity then models a wall
/// that slides along itself).
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
    /// Stable identifier (kept for the particle's life, never reused).
    pub id: Vec<u64>,
    /// Group: for [`ParticleKind::Buffer`] the index of its open boundary; for walls the index of
    /// its wall motion + 1 (0 = fixed wall); 0 for fluid.
    pub group: Vec<u16>,
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
        self.push_grouped(x, z, vx, vz, rho, mass, kind, id, 0);
    }

    /// Appends one particle with its group (see [`Particles::group`]).
    #[allow(clippy::too_many_arguments)]
    pub fn push_grouped(
        &mut self,
        x: Real,
        z: Real,
        vx: Real,
        vz: Real,
        rho: Real,
        mass: Real,
        kind: ParticleKind,
        id: u64,
        group: u16,
    ) {
        self.x.push(x);
        self.z.push(z);
        self.vx.push(vx);
        self.vz.push(vz);
        self.rho.push(rho);
        self.mass.push(mass);
        self.kind.push(kind);
        self.id.push(id);
        self.group.push(group);
    }

    /// Appends all particles of `other`.
    pub fn append(&mut self, other: &Particles) {
        self.x.extend_from_slice(&other.x);
        self.z.extend_from_slice(&other.z);
        self.vx.extend_from_slice(&other.vx);
        self.vz.extend_from_slice(&other.vz);
        self.rho.extend_from_slice(&other.rho);
        self.mass.extend_from_slice(&other.mass);
        self.kind.extend_from_slice(&other.kind);
        self.id.extend_from_slice(&other.id);
        self.group.extend_from_slice(&other.group);
    }

    /// Keeps the particles for which `keep(i)` is true, in their order.
    pub fn retain_indices(&mut self, keep: &[bool]) {
        let first = first_removed(keep);
        retain_from(&mut self.x, keep, first);
        retain_from(&mut self.z, keep, first);
        retain_from(&mut self.vx, keep, first);
        retain_from(&mut self.vz, keep, first);
        retain_from(&mut self.rho, keep, first);
        retain_from(&mut self.mass, keep, first);
        retain_from(&mut self.kind, keep, first);
        retain_from(&mut self.id, keep, first);
        retain_from(&mut self.group, keep, first);
    }

    /// Reorders all arrays so that particle `order[k]` becomes particle k (`order` a permutation).
    pub fn permute(&mut self, order: &[u32]) {
        fn perm<T: Copy>(v: &mut Vec<T>, order: &[u32], tmp: &mut Vec<T>) {
            tmp.clear();
            tmp.extend(order.iter().map(|&i| v[i as usize]));
            std::mem::swap(v, tmp);
        }
        let mut f = Vec::with_capacity(order.len());
        perm(&mut self.x, order, &mut f);
        perm(&mut self.z, order, &mut f);
        perm(&mut self.vx, order, &mut f);
        perm(&mut self.vz, order, &mut f);
        perm(&mut self.rho, order, &mut f);
        perm(&mut self.mass, order, &mut f);
        perm(&mut self.kind, order, &mut Vec::with_capacity(order.len()));
        perm(&mut self.id, order, &mut Vec::with_capacity(order.len()));
        perm(&mut self.group, order, &mut Vec::with_capacity(order.len()));
    }

    /// Largest id + 1 (0 when empty): the next id that is certainly unused.
    pub fn next_free_id(&self) -> u64 {
        self.id.iter().max().map_or(0, |m| m + 1)
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
            self.group.len(),
        ];
        all.iter().all(|&l| l == n).then_some(n)
    }

    /// Number of free fluid particles.
    pub fn fluid_count(&self) -> usize {
        self.kind.iter().filter(|k| k.is_fluid()).count()
    }
}

/// Index of the first `false` in `keep` (its length if none): the prefix before it stays in place
/// when compacting with [`retain_from`].
pub(crate) fn first_removed(keep: &[bool]) -> usize {
    keep.iter().position(|&k| !k).unwrap_or(keep.len())
}

/// Keeps the entries of `v` whose `keep` flag is true, in order, moving only those from `first`
/// ([`first_removed`]) on.
pub(crate) fn retain_from<T: Copy>(v: &mut Vec<T>, keep: &[bool], first: usize) {
    let start = first.min(v.len());
    let mut j = start;
    for i in start..v.len() {
        if keep[i] {
            v[j] = v[i];
            j += 1;
        }
    }
    v.truncate(j);
}
