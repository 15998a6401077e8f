//! Platelets as point particles with shape (paper 2, section 4.1 "2d Simplification"):
//! P = (Lx, Ly, Lz, α_top, α_bot; X, φ, V, Ω), stored as a structure of arrays.

use super::DynamicsError;
use crate::coefficients::{Rotational, Translational};
use crate::shape::Shape;

/// Default platelet density ρ_p \[kg/m³\] (paper 2, section 5: 1.06 mg/mm³).
pub const DEFAULT_DENSITY: f64 = 1060.0;

/// Initial kinematic state of one particle (SI).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ParticleState {
    /// Centre of mass X \[m\].
    pub x: [f64; 2],
    /// Orientation φ of the body x axis from the lab x axis \[rad\].
    pub phi: f64,
    /// Velocity V \[m/s\].
    pub v: [f64; 2],
    /// Angular velocity Ω about z \[rad/s\].
    pub omega: f64,
}

/// All particles, one array per quantity (structure of arrays). Index i is particle i in every
/// array. The kinematic arrays are public for reading and for setting up a state; the dynamics
/// checks them (finite) at the start of every macro step.
#[derive(Clone, Debug, Default)]
pub struct Particles {
    /// Identity: the order of [`Particles::push`] (0, 1, …); kept through [`Particles::permute`].
    pub id: Vec<u64>,
    /// Shape parameters.
    pub shape: Vec<Shape>,
    /// Mass m \[kg\] (cached from the shape and density).
    pub mass: Vec<f64>,
    /// Moment of inertia about the z axis through the centre of mass \[kg m²\] (cached).
    pub inertia: Vec<f64>,
    /// Collision sphere radius \[m\] (cached: factor × Lx, see `collide`).
    pub radius: Vec<f64>,
    /// Position of the centre of mass, x \[m\].
    pub x: Vec<f64>,
    /// Position of the centre of mass, y \[m\].
    pub y: Vec<f64>,
    /// Orientation φ \[rad\].
    pub phi: Vec<f64>,
    /// Velocity, x \[m/s\].
    pub vx: Vec<f64>,
    /// Velocity, y \[m/s\].
    pub vy: Vec<f64>,
    /// Angular velocity Ω \[rad/s\].
    pub omega: Vec<f64>,
    /// Effective angle of attack ψ (eq 11) at the last coefficient refresh \[rad\].
    pub psi: Vec<f64>,
    /// Lab-frame angle of δv at the last refresh where |δv| was above the threshold \[rad\]
    /// (ψ = dv_dir − φ when δv vanishes); NaN before the particle's first refresh.
    pub dv_dir: Vec<f64>,
    /// Translational coefficients at ψ (cached; refreshed every k-th sub-step).
    pub trans: Vec<Translational>,
    /// Rotational coefficients (cached once per particle).
    pub rot: Vec<Rotational>,
    /// Coupling c_x \[kg·m/s\]: the pitching torque per unit relative velocity along the body's x
    /// axis, C_p at ψ = 0 (cached with `rot`; by the x → −x mirror symmetry of the shape the
    /// coupling vector has no body-y component, so T_p = c_x |δv| cos ψ).
    pub coupling: Vec<f64>,
    /// Density ρ_p \[kg/m³\] used for mass and inertia.
    density: f64,
    /// Collision radius / Lx.
    radius_factor: f64,
    /// Next identity.
    next_id: u64,
    /// Particles [0, n_rot) have rotational coefficients.
    pub(crate) n_rot: usize,
    /// Particles [0, n_trans) have translational coefficients.
    pub(crate) n_trans: usize,
}

impl Particles {
    /// An empty set with density ρ_p \[kg/m³\] in (0, 1e5] and collision radius factor
    /// (radius = factor × Lx) in (0, 10].
    pub fn new(density: f64, radius_factor: f64) -> Result<Self, DynamicsError> {
        if !(density.is_finite() && density > 0.0 && density <= 1e5) {
            return Err(DynamicsError::Invalid {
                field: "density",
                value: density,
                allowed: "0 < density <= 1e5 kg/m^3",
            });
        }
        if !(radius_factor.is_finite() && radius_factor > 0.0 && radius_factor <= 10.0) {
            return Err(DynamicsError::Invalid {
                field: "radius_factor",
                value: radius_factor,
                allowed: "0 < radius_factor <= 10",
            });
        }
        Ok(Particles { density, radius_factor, ..Default::default() })
    }

    /// Number of particles.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// No particles.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// Density ρ_p \[kg/m³\].
    pub fn density(&self) -> f64 {
        self.density
    }

    /// Every per-particle `f64` array (one place to list them, so none is forgotten when the
    /// arrays are resized or reordered).
    fn f64_arrays_mut(&mut self) -> [&mut Vec<f64>; 12] {
        [
            &mut self.mass,
            &mut self.inertia,
            &mut self.radius,
            &mut self.x,
            &mut self.y,
            &mut self.phi,
            &mut self.vx,
            &mut self.vy,
            &mut self.omega,
            &mut self.psi,
            &mut self.dv_dir,
            &mut self.coupling,
        ]
    }

    /// Reserve room for `n` more particles.
    pub fn reserve(&mut self, n: usize) {
        for v in self.f64_arrays_mut() {
            v.reserve(n);
        }
        self.shape.reserve(n);
        self.id.reserve(n);
        self.trans.reserve(n);
        self.rot.reserve(n);
    }

    /// Adds a particle; returns its index. The shape must be a body ([`Shape::validate`]); the state
    /// must be finite. Its coefficients are evaluated at the next sub-step (rotational once).
    pub fn push(&mut self, shape: Shape, s: ParticleState) -> Result<usize, DynamicsError> {
        shape.validate()?;
        let i = self.len();
        for (field, v) in
            [("x", s.x[0]), ("y", s.x[1]), ("phi", s.phi), ("vx", s.v[0]), ("vy", s.v[1]), ("omega", s.omega)]
        {
            if !v.is_finite() {
                return Err(DynamicsError::State { field, index: i, value: v });
            }
        }
        self.id.push(self.next_id);
        self.next_id += 1;
        self.shape.push(shape);
        self.mass.push(shape.mass(self.density));
        self.inertia.push(shape.inertia_z_centre(self.density));
        self.radius.push(self.radius_factor * shape.lx);
        self.x.push(s.x[0]);
        self.y.push(s.x[1]);
        self.phi.push(s.phi);
        self.vx.push(s.v[0]);
        self.vy.push(s.v[1]);
        self.omega.push(s.omega);
        self.psi.push(-s.phi);
        self.dv_dir.push(f64::NAN); // unknown until the first refresh
        self.trans.push(Translational::default());
        self.rot.push(Rotational::default());
        self.coupling.push(f64::NAN);
        Ok(i)
    }

    /// The state of particle i.
    pub fn state(&self, i: usize) -> Option<ParticleState> {
        (i < self.len()).then(|| ParticleState {
            x: [self.x[i], self.y[i]],
            phi: self.phi[i],
            v: [self.vx[i], self.vy[i]],
            omega: self.omega[i],
        })
    }

    /// Total linear momentum Σ m V \[kg m/s\].
    pub fn momentum(&self) -> [f64; 2] {
        let mut p = [0.0; 2];
        for i in 0..self.len() {
            p[0] += self.mass[i] * self.vx[i];
            p[1] += self.mass[i] * self.vy[i];
        }
        p
    }

    /// Every kinematic quantity finite; the first offender otherwise.
    pub fn check_finite(&self) -> Result<(), DynamicsError> {
        for (field, arr) in [
            ("x", &self.x),
            ("y", &self.y),
            ("phi", &self.phi),
            ("vx", &self.vx),
            ("vy", &self.vy),
            ("omega", &self.omega),
        ] {
            if let Some((index, &value)) = arr.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Err(DynamicsError::State { field, index, value });
            }
        }
        self.check_lengths()
    }

    /// Reorders the particles: new index i holds old particle `order[i]`. `order` must be a
    /// permutation of 0..len. Cached coefficients move along; if some particle had none yet, all
    /// are re-evaluated at the next sub-step.
    pub fn permute(&mut self, order: &[u32]) -> Result<(), DynamicsError> {
        let n = self.len();
        let mut seen = vec![false; n];
        let bad =
            DynamicsError::Invalid { field: "order", value: order.len() as f64, allowed: "a permutation of 0..len" };
        if order.len() != n {
            return Err(bad);
        }
        for &k in order {
            let k = k as usize;
            if k >= n || seen[k] {
                return Err(bad);
            }
            seen[k] = true;
        }
        fn apply<T: Copy>(v: &mut Vec<T>, order: &[u32]) {
            let new: Vec<T> = order.iter().map(|&k| v[k as usize]).collect();
            *v = new;
        }
        apply(&mut self.id, order);
        apply(&mut self.shape, order);
        for v in self.f64_arrays_mut() {
            apply(v, order);
        }
        apply(&mut self.trans, order);
        apply(&mut self.rot, order);
        if self.n_rot < n || self.n_trans < n {
            self.n_rot = 0;
            self.n_trans = 0;
        }
        Ok(())
    }

    /// All arrays of the same length (O(1)).
    pub fn check_lengths(&self) -> Result<(), DynamicsError> {
        let n = self.len();
        let lens = [
            self.shape.len(),
            self.id.len(),
            self.mass.len(),
            self.inertia.len(),
            self.radius.len(),
            self.y.len(),
            self.phi.len(),
            self.vx.len(),
            self.vy.len(),
            self.omega.len(),
            self.psi.len(),
            self.dv_dir.len(),
            self.trans.len(),
            self.rot.len(),
            self.coupling.len(),
        ];
        if lens.iter().any(|&l| l != n) {
            return Err(DynamicsError::Invalid {
                field: "particles",
                value: self.len() as f64,
                allowed: "all arrays of the same length (use Particles::push)",
            });
        }
        Ok(())
    }
}
