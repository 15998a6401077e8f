//! # sonoflow-analytic-flow
//!
//! Analytic fluid producer for scenes that do not need SPH, after the
//! analytic flow phantoms used for vector-Doppler validation (Jensen; Kerr &
//! Hunt): point scatterers are seeded uniformly in the fluid region at a
//! given areal density with Gaussian amplitudes, moved **exactly** by a
//! steady analytic 2-D velocity field ([`FlowKind`]) and sampled at the
//! acquisition times of a plane-wave Doppler [`Schedule`]. The exact field on
//! a grid ([`AnalyticFlow::sample_truth`]) serves as ground truth.
//!
//! ## Conventions
//!
//! - **Plane and axes**: 2-D imaging plane (x, z). x is lateral, z is depth,
//!   positive into the body; the probe face lies at z = 0. On an image, x
//!   points right and z points down.
//! - **Units**: SI throughout (m, s, m/s, rad/s, Hz) unless a name says
//!   otherwise (`angle_deg` in degrees, `density_per_mm2` per mm²).
//! - **Vessel angle**: [`FlowKind::Poiseuille`] has axis direction
//!   `(cos θ, sin θ)` in (x, z) with θ = `angle_deg`; a positive angle tilts
//!   the axis towards +z (the vessel is deeper at +x). `v_max` is signed,
//!   positive along that direction. Profile `u(r) = v_max (1 - (2r/D)^2)`.
//! - **Plug band**: [`FlowKind::Plug`] has the vessel's axis convention and a
//!   uniform velocity `v` across its `width`: a rigid translation, the phantom
//!   that measures the imaging chain's Doppler gain without flow gradients.
//! - **Rotation sign**: [`FlowKind::RotatingDisk`] has
//!   `v = omega * (-(z - zc), x - xc)`: positive `omega` turns +x towards +z,
//!   which looks **clockwise** on an image (z down).
//! - **Time**: scatterers are seeded at `schedule.t_start`;
//!   [`AnalyticFlow::advance_to`] moves them to any later time in closed form
//!   from their seeding state (no time-stepping, no accumulated error).
//!   Vessel scatterers are periodic along the axis: leaving one end they
//!   re-enter at the other with the same id, radius and amplitude, so the
//!   count is constant.
//! - **Reproducibility**: all randomness comes from one `ChaCha8Rng` seeded
//!   with `seed`, drawn per particle in id order (two uniforms for the
//!   position, then one normal amplitude), so results are identical on every
//!   platform.
//! - Positions and velocities of scatterers are stored as `f32` (rounded from
//!   exact `f64` values); the field queries return `f64`.

mod flow;
mod grid;
pub mod motion;
mod schedule;
pub mod tissue;

pub use flow::FlowKind;
pub use grid::{GridSpec, Truth};
pub use motion::{BulkMotion, Pulsation, PulsationWaveform, Rigid};
pub use schedule::{AcquisitionTime, Schedule};
pub use tissue::{LumenShape, Tissue, TissueParams, WallLayer};

use flow::Geometry;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Scatterers in structure-of-arrays layout; all vectors have the same
/// length. Positions in m, velocities in m/s, amplitude dimensionless.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Particles {
    /// Stable identifier, `0..n`, equal to the index.
    pub id: Vec<u32>,
    /// Lateral position (m).
    pub x: Vec<f32>,
    /// Depth (m).
    pub z: Vec<f32>,
    /// Lateral velocity (m/s) (field at the current position).
    pub vx: Vec<f32>,
    /// Depth velocity (m/s) (field at the current position).
    pub vz: Vec<f32>,
    /// Scattering amplitude, N(0, amplitude_sigma²), fixed for life.
    pub amplitude: Vec<f32>,
}

impl Particles {
    /// Number of particles.
    pub fn len(&self) -> usize {
        self.id.len()
    }

    /// True when there are no particles.
    pub fn is_empty(&self) -> bool {
        self.id.is_empty()
    }

    /// Bounding box of the positions, `[xmin, xmax, zmin, zmax]` (m); `[MAX, MIN, MAX, MIN]` of
    /// f32 when there are no particles.
    pub fn bbox(&self) -> [f32; 4] {
        let (mut xmin, mut xmax, mut zmin, mut zmax) = (f32::MAX, f32::MIN, f32::MAX, f32::MIN);
        for (&x, &z) in self.x.iter().zip(&self.z) {
            xmin = xmin.min(x);
            xmax = xmax.max(x);
            zmin = zmin.min(z);
            zmax = zmax.max(z);
        }
        [xmin, xmax, zmin, zmax]
    }
}

/// Parameters of an [`AnalyticFlow`].
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct AnalyticFlowParams {
    /// Velocity field and fluid region.
    pub flow: FlowKind,
    /// Scatterers per mm² of fluid, in (0, 1e4]. Default 10.
    pub density_per_mm2: f64,
    /// Standard deviation of the Gaussian scattering amplitude (> 0). Default 1.
    pub amplitude_sigma: f64,
    /// RNG seed. Default 1.
    pub seed: u64,
    /// Acquisition timing; scatterers are seeded at `schedule.t_start`.
    pub schedule: Schedule,
    /// Upper bound on the scatterer count (error if exceeded). Default 2 000 000.
    pub max_particles: u32,
    /// Tissue around the lumen (absent: blood only), see [`tissue`].
    pub tissue: Option<TissueParams>,
    /// Rigid bulk motion of the whole scene (absent: none), see [`motion`].
    pub bulk: Option<BulkMotion>,
}

impl Default for AnalyticFlowParams {
    fn default() -> Self {
        Self {
            flow: FlowKind::default(),
            density_per_mm2: 10.0,
            amplitude_sigma: 1.0,
            seed: 1,
            schedule: Schedule::default(),
            max_particles: 2_000_000,
            tissue: None,
            bulk: None,
        }
    }
}

/// Largest accepted `density_per_mm2`.
pub const MAX_DENSITY_PER_MM2: f64 = 1.0e4;
/// Largest accepted `amplitude_sigma`.
pub const MAX_AMPLITUDE_SIGMA: f64 = 1.0e6;

impl AnalyticFlowParams {
    /// Checks every field (see [`FlowKind::validate`],
    /// [`Schedule::validate`]) and that the scatterer count is between 1 and
    /// `max_particles`.
    pub fn validate(&self) -> Result<(), ParamError> {
        self.particle_count().map(|_| ())
    }

    /// Validates and returns the scatterer count
    /// `round(density_per_mm2 * area_mm2)`.
    pub fn particle_count(&self) -> Result<u32, ParamError> {
        self.flow.validate()?;
        require(
            "density_per_mm2",
            self.density_per_mm2,
            self.density_per_mm2.is_finite()
                && self.density_per_mm2 > 0.0
                && self.density_per_mm2 <= MAX_DENSITY_PER_MM2,
            format!("finite, 0 < value <= {MAX_DENSITY_PER_MM2} per mm^2"),
        )?;
        require(
            "amplitude_sigma",
            self.amplitude_sigma,
            self.amplitude_sigma.is_finite()
                && self.amplitude_sigma > 0.0
                && self.amplitude_sigma <= MAX_AMPLITUDE_SIGMA,
            format!("finite, 0 < value <= {MAX_AMPLITUDE_SIGMA}"),
        )?;
        self.schedule.validate()?;
        if let Some(t) = &self.tissue {
            t.validate()?;
            if t.pulsation.as_ref().is_some_and(|p| p.waveform == PulsationWaveform::Inflow) {
                return Err(ParamError::OutOfRange {
                    field: "tissue.pulsation.waveform",
                    value: "\"inflow\"".into(),
                    allowed:
                        "\"raised-cosine\" (an analytic flow has no inflow waveform; \"inflow\" is for sph-flow scenes)"
                            .into(),
                });
            }
        }
        if let Some(b) = &self.bulk {
            b.validate()?;
        }
        let area_mm2 = self.flow.area_m2() * 1.0e6;
        let expected = (self.density_per_mm2 * area_mm2).round();
        require(
            "density_per_mm2",
            self.density_per_mm2,
            expected >= 1.0,
            format!("density_per_mm2 * fluid area ({area_mm2} mm^2) must give at least 1 scatterer"),
        )?;
        if expected > f64::from(self.max_particles) {
            return Err(ParamError::TooManyParticles {
                // Finite and >= 1 here; `as` saturates beyond u64::MAX.
                expected: expected as u64,
                max_particles: self.max_particles,
            });
        }
        // In [1, max_particles] (an integer-valued f64), so the cast is exact.
        Ok(expected as u32)
    }
}

/// Invalid parameters. The message starts with the offending field's name.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum ParamError {
    /// A field is non-finite or outside its allowed range.
    #[error("{field} = {value} is out of range: {allowed}")]
    OutOfRange {
        /// Dotted field name, e.g. `flow.diameter`, `schedule.prf`.
        field: &'static str,
        /// The rejected value, formatted.
        value: String,
        /// Human-readable allowed range.
        allowed: String,
    },
    /// The scatterer count `round(density_per_mm2 * area_mm2)` exceeds the limit.
    #[error("max_particles = {max_particles} is exceeded: density_per_mm2 * fluid area gives {expected} scatterers (lower density_per_mm2 or raise max_particles)")]
    TooManyParticles {
        /// Expected scatterer count (saturated at `u64::MAX`).
        expected: u64,
        /// The configured limit.
        max_particles: u32,
    },
}

impl ParamError {
    /// Name of the offending field (`max_particles` for
    /// [`ParamError::TooManyParticles`]).
    pub fn field(&self) -> &'static str {
        match self {
            ParamError::OutOfRange { field, .. } => field,
            ParamError::TooManyParticles { .. } => "max_particles",
        }
    }
}

/// Builds an [`ParamError::OutOfRange`] unless `ok`.
pub(crate) fn require(
    field: &'static str,
    value: impl std::fmt::Display,
    ok: bool,
    allowed: impl Into<String>,
) -> Result<(), ParamError> {
    if ok {
        Ok(())
    } else {
        Err(ParamError::OutOfRange { field, value: value.to_string(), allowed: allowed.into() })
    }
}

/// Errors of [`AnalyticFlow::advance_to`].
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum FlowError {
    /// The requested time is earlier than the current time.
    #[error("advance_to({requested}) goes backwards: current time is {current} s")]
    TimeWentBackwards {
        /// Requested time (s).
        requested: f64,
        /// Current time (s).
        current: f64,
    },
    /// The requested time is NaN or infinite.
    #[error("advance_to({0}): time must be finite")]
    NonFiniteTime(f64),
}

/// Scatterers per rayon work item.
const CHUNK: usize = 4096;

/// Analytic flow phantom: scatterers plus the exact field that moves them.
#[derive(Clone, Debug)]
pub struct AnalyticFlow {
    params: AnalyticFlowParams,
    geometry: Geometry,
    /// Seeding time (s) (`schedule.t_start`).
    t_seed: f64,
    /// Current time (s).
    t: f64,
    /// Per-particle local coordinates at seeding (see [`Geometry`]).
    local_a: Vec<f64>,
    local_b: Vec<f64>,
    particles: Particles,
    /// Tissue scatterers (empty without `tissue`).
    tissue: Tissue,
}

impl AnalyticFlow {
    /// Validates `params` and seeds the scatterers at `schedule.t_start`.
    pub fn new(params: &AnalyticFlowParams) -> Result<Self, ParamError> {
        let n = params.particle_count()?;
        let geometry = Geometry::from_kind(&params.flow);
        let normal = Normal::new(0.0, params.amplitude_sigma).map_err(|e| ParamError::OutOfRange {
            field: "amplitude_sigma",
            value: params.amplitude_sigma.to_string(),
            allowed: e.to_string(),
        })?;
        let mut rng = ChaCha8Rng::seed_from_u64(params.seed);
        let len = n as usize;
        let mut local_a = Vec::with_capacity(len);
        let mut local_b = Vec::with_capacity(len);
        let mut amplitude = Vec::with_capacity(len);
        for _ in 0..n {
            let u1: f64 = rng.gen();
            let u2: f64 = rng.gen();
            let (a, b) = geometry.local_from_unit(u1, u2);
            local_a.push(a);
            local_b.push(b);
            amplitude.push(normal.sample(&mut rng) as f32);
        }
        let t0 = params.schedule.t_start;
        let tissue = match &params.tissue {
            Some(t) => Tissue::new(t, &geometry, params.density_per_mm2, params.amplitude_sigma, n)?,
            None => Tissue::default(),
        };
        let n_tissue = tissue.particles().len() as u64;
        if u64::from(n) + n_tissue > u64::from(params.max_particles) {
            return Err(ParamError::TooManyParticles {
                expected: u64::from(n) + n_tissue,
                max_particles: params.max_particles,
            });
        }
        let mut flow = Self {
            params: params.clone(),
            geometry,
            t_seed: t0,
            t: t0,
            local_a,
            local_b,
            particles: Particles {
                id: (0..n).collect(),
                x: vec![0.0; len],
                z: vec![0.0; len],
                vx: vec![0.0; len],
                vz: vec![0.0; len],
                amplitude,
            },
            tissue,
        };
        flow.update_particles();
        Ok(flow)
    }

    /// The tissue scatterers at the current time (ids after the blood's; empty without `tissue`).
    pub fn tissue(&self) -> &Particles {
        self.tissue.particles()
    }

    /// True when the tissue moves (a wall pulsation of non-zero amplitude, or bulk motion);
    /// false when it is static and its echoes can be computed once.
    pub fn tissue_moves(&self) -> bool {
        self.tissue.pulsates() || (self.params.bulk.is_some() && !self.tissue.particles().is_empty())
    }

    /// The bulk motion's transform at time `t` (the identity without `bulk`).
    pub fn rigid_at(&self, t: f64) -> Rigid {
        self.params.bulk.as_ref().map_or(Rigid::IDENTITY, |b| b.at(t))
    }

    /// Moves every scatterer exactly to time `t` (closed form from its
    /// seeding state) and sets its velocity to the field at the new
    /// position. `t` equal to the current time is a no-op; an earlier or
    /// non-finite `t` is an error and leaves the state unchanged.
    pub fn advance_to(&mut self, t: f64) -> Result<(), FlowError> {
        if !t.is_finite() {
            return Err(FlowError::NonFiniteTime(t));
        }
        if t < self.t {
            return Err(FlowError::TimeWentBackwards { requested: t, current: self.t });
        }
        if t > self.t {
            self.t = t;
            self.update_particles();
        }
        Ok(())
    }

    /// Recomputes positions and velocities for the current time.
    fn update_particles(&mut self) {
        let geom = self.geometry;
        let dt = self.t - self.t_seed;
        let rigid = self.params.bulk.as_ref().map(|b| b.at(self.t));
        let p = &mut self.particles;
        (
            p.x.par_chunks_mut(CHUNK),
            p.z.par_chunks_mut(CHUNK),
            p.vx.par_chunks_mut(CHUNK),
            p.vz.par_chunks_mut(CHUNK),
            self.local_a.par_chunks(CHUNK),
            self.local_b.par_chunks(CHUNK),
        )
            .into_par_iter()
            .for_each(|(x, z, vx, vz, a, b)| {
                let outs = x.iter_mut().zip(z.iter_mut()).zip(vx.iter_mut().zip(vz));
                for (((x, z), (vx, vz)), (&a, &b)) in outs.zip(a.iter().zip(b)) {
                    let s = geom.state(a, b, dt);
                    let [sx, sz, svx, svz] = match &rigid {
                        Some(r) => r.apply(s.x, s.z, s.vx, s.vz),
                        None => [s.x, s.z, s.vx, s.vz],
                    };
                    *x = sx as f32;
                    *z = sz as f32;
                    *vx = svx as f32;
                    *vz = svz as f32;
                }
            });
        self.tissue.update(self.t, rigid.as_ref());
    }

    /// Current scatterers.
    pub fn particles(&self) -> &Particles {
        &self.particles
    }

    /// Current time (s).
    pub fn time(&self) -> f64 {
        self.t
    }

    /// The (validated) parameters this flow was built from.
    pub fn params(&self) -> &AnalyticFlowParams {
        &self.params
    }

    /// Exact velocity (vx, vz) (m/s) at (x, z), `None` outside the fluid, in the scene's own
    /// frame (without `bulk` motion; [`sample_truth_at`](Self::sample_truth_at) includes it).
    /// The field is steady, so this does not depend on the current time.
    /// Points on the boundary count as inside; a scatterer lying on the
    /// boundary may round (f32) to just outside it.
    pub fn velocity(&self, x: f64, z: f64) -> Option<(f64, f64)> {
        self.geometry.velocity(x, z)
    }

    /// Exact lab-frame field at the nodes of `grid` at time `t` (bulk motion moves the lumen and
    /// adds its velocity; without `bulk` the field is the same at every time). An error for an
    /// invalid grid.
    pub fn sample_truth_at(&self, grid: &GridSpec, t: f64) -> Result<Truth, ParamError> {
        self.truth_with(grid, self.params.bulk.as_ref().map(|b| b.at(t)))
    }

    /// Exact field at the nodes of `grid` at the current time. The grid must satisfy
    /// [`GridSpec::validate`]; for an invalid grid this returns an empty
    /// [`Truth`] (use [`try_sample_truth`](Self::try_sample_truth) to get the
    /// error instead).
    pub fn sample_truth(&self, grid: &GridSpec) -> Truth {
        self.try_sample_truth(grid).unwrap_or_default()
    }

    /// Like [`sample_truth`](Self::sample_truth) but reports an invalid grid.
    pub fn try_sample_truth(&self, grid: &GridSpec) -> Result<Truth, ParamError> {
        self.sample_truth_at(grid, self.t)
    }

    fn truth_with(&self, grid: &GridSpec, rigid: Option<Rigid>) -> Result<Truth, ParamError> {
        grid.validate()?;
        let nx = grid.nx as usize;
        let n = nx * grid.nz as usize;
        let mut truth = Truth { vx: vec![0.0; n], vz: vec![0.0; n], mask: vec![0; n] };
        let geom = self.geometry;
        (truth.vx.par_chunks_mut(nx), truth.vz.par_chunks_mut(nx), truth.mask.par_chunks_mut(nx))
            .into_par_iter()
            .enumerate()
            .for_each(|(iz, (vx, vz, mask))| {
                // iz < nz <= u32::MAX.
                let iz = iz as u32;
                for (ix, ((vx, vz), m)) in vx.iter_mut().zip(vz).zip(mask).enumerate() {
                    let (x, z) = grid.node(ix as u32, iz);
                    let (sx, sz) = rigid.map_or((x, z), |r| r.invert(x, z));
                    if let Some((u, w)) = geom.velocity(sx, sz) {
                        let (u, w) = match &rigid {
                            Some(r) => {
                                let [_, _, u, w] = r.apply(sx, sz, u, w);
                                (u, w)
                            }
                            None => (u, w),
                        };
                        *vx = u as f32;
                        *vz = w as f32;
                        *m = 1;
                    }
                }
            });
        Ok(truth)
    }
}

#[cfg(test)]
mod tests;
