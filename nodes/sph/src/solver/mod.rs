//! Time integration: second-order predictor–corrector (Monaghan 1989 form) with an adaptive time
//! step and outputs exactly at requested times (paper §2.2).
//!
//! One step from t to t + Δt, with F the acceleration and D = Dρ/Dt:
//! * F⁰, D⁰ at state n; Δt = min(C_cfl h/(c + |u|max), C_ν h²/ν, C_f √(h/|a|max), dt_max, time left);
//! * predictor: u* = uⁿ + Δt/2 F⁰, ρ* = ρⁿ + Δt/2 D⁰, r* = rⁿ + Δt/2 uⁿ;
//! * corrector at the half state: u½ = uⁿ + Δt/2 F*, ρ½ = ρⁿ + Δt/2 D*, r½ = rⁿ + Δt/2 u½;
//! * uⁿ⁺¹ = 2u½ − uⁿ, ρⁿ⁺¹ = 2ρ½ − ρⁿ, rⁿ⁺¹ = 2r½ − rⁿ.
//!
//! Time-dependent data are evaluated at the time of each stage (tⁿ, tⁿ + Δt/2, tⁿ⁺¹): the body
//! force, the walls' prescribed motion and the reservoirs' imposed velocity. Reservoir particles
//! move with the imposed velocity (rⁿ⁺¹ = rⁿ + Δt u(tⁿ⁺½)); their density is extrapolated from the
//! fluid at every stage. After the step, particles are exchanged between the fluid and the reservoirs
//! ([`crate::boundary::exchange`]) and, with a [`Domain`], the anti-penetration guard runs.

use std::sync::Arc;

use crate::boundary::{self, BoundaryFlux, BoundaryState, OpenBoundary};
use crate::checkpoint::{Checkpoint, CheckpointHeader};
use crate::fast::{self, FastWorkspace};
use crate::kernel::Kernel;
use crate::neighbours::CellList;
use crate::params::{Integrator, ParamError, SphParams};
use crate::particles::{ParticleKind, Particles};
pub use crate::step::{DtCriterion, StepReport};
use crate::walls::{BuiltMotion, Domain, WallMotion};
use crate::waveform::Waveform;
use crate::wcsph::{compute_rates, Rate, Workspace};
use crate::Real;

mod chunks;
mod corrections;

/// Steps between two reorderings of the particle arrays by cell ([`Solver::reorder_by_cell`]).
const REORDER_INTERVAL: u64 = 25;

/// What went wrong in a blow-up.
#[derive(Clone, Debug, PartialEq)]
pub enum BlowUpCriterion {
    /// A position, velocity, density or rate is NaN or infinite.
    NonFinite {
        /// Name of the quantity.
        quantity: &'static str,
    },
    /// |ρ/ρ₀ − 1| exceeded `density_error_limit`.
    DensityError {
        /// The offending |ρ/ρ₀ − 1|.
        value: Real,
        /// The limit.
        limit: Real,
    },
    /// The adaptive dt fell below `dt_collapse_ratio` × the first step's dt.
    DtCollapse {
        /// The dt \[s\].
        dt: Real,
        /// The threshold \[s\].
        threshold: Real,
        /// Which criterion produced it.
        binding: DtCriterion,
    },
}

impl std::fmt::Display for BlowUpCriterion {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            BlowUpCriterion::NonFinite { quantity } => write!(f, "non-finite {quantity}"),
            BlowUpCriterion::DensityError { value, limit } => {
                write!(f, "density error |rho/rho0 - 1| = {value:.4} above the limit {limit}")
            }
            BlowUpCriterion::DtCollapse { dt, threshold, binding } => {
                write!(f, "time step collapsed to {dt:.3e} s (< {threshold:.3e} s, binding criterion {binding:?})")
            }
        }
    }
}

/// Errors of the solver.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SphError {
    /// Invalid parameters.
    #[error(transparent)]
    Params(#[from] ParamError),
    /// Particle arrays of different lengths, or no fluid particle.
    #[error("invalid particle state: {0}")]
    State(String),
    /// A requested output time lies before the current time.
    #[error("requested time {requested} s is before the current time {now} s")]
    TimeInPast {
        /// Requested \[s\].
        requested: Real,
        /// Current \[s\].
        now: Real,
    },
    /// The run blew up; the state is that of the failing step.
    #[error("blow-up at t = {time} s, particle id {particle_id}: {criterion}")]
    BlowUp {
        /// Time at the start of the failing step \[s\].
        time: Real,
        /// Stable id of the particle.
        particle_id: u64,
        /// What was detected.
        criterion: BlowUpCriterion,
    },
}

/// State summary for monitoring (paper-independent acceptance signals, sph-validation.md §e).
#[derive(Clone, Debug, PartialEq)]
pub struct Diagnostics {
    /// Simulation time \[s\].
    pub time: Real,
    /// Steps taken.
    pub steps: u64,
    /// Last step's report (None before the first step).
    pub last_step: Option<StepReport>,
    /// Free fluid particles.
    pub n_fluid: usize,
    /// Reservoir particles.
    pub n_buffer: usize,
    /// Wall particles.
    pub n_wall: usize,
    /// max |ρ/ρ₀ − 1| over free fluid particles now.
    pub max_density_error: Real,
    /// Kinetic energy of the free fluid ½ Σ m |u|² \[J/m\] (2D: per unit depth).
    pub kinetic_energy: Real,
    /// Mass of the free fluid \[kg/m\].
    pub fluid_mass: Real,
    /// Largest fluid speed \[m/s\].
    pub max_speed: Real,
    /// Smallest distance between a fluid particle and any other particle at the last step's
    /// half-step evaluation \[m\] (∞ before the first step).
    pub min_pair_distance: Real,
    /// Id of the fluid particle of that closest pair.
    pub min_pair_id: u64,
    /// With shifting: RMS shifting displacement over RMS advection displacement u Δt, over all fluid
    /// particles and steps so far (0 without shifting). How far the particles — the acoustic
    /// scatterers — leave their material paths, relative to how far they move.
    pub shift_ratio: Real,
    /// Per open boundary: name and mass bookkeeping.
    pub boundaries: Vec<(String, BoundaryFlux)>,
    /// Times the anti-penetration guard had to put a fluid particle back inside the domain.
    pub guard_corrections: u64,
}

/// Weakly compressible SPH solver owning its particles and buffers.
#[derive(Debug)]
pub struct Solver {
    params: SphParams,
    kernel: Kernel,
    /// Particle state (read it between steps; positions of walls must not change).
    pub particles: Particles,
    time: Real,
    cells: CellList,
    ws: Workspace,
    fast: FastWorkspace,
    x0: Vec<Real>,
    z0: Vec<Real>,
    vx0: Vec<Real>,
    vz0: Vec<Real>,
    rho0: Vec<Real>,
    first_dt: Option<Real>,
    last: Option<StepReport>,
    steps: u64,
    pulsatile: Option<([Real; 2], Waveform)>,
    boundaries: Vec<BoundaryState>,
    motions: Vec<BuiltMotion>,
    motion_time: Real,
    domain: Option<Arc<dyn Domain>>,
    guard_corrections: u64,
    next_id: u64,
    keep: Vec<bool>,
    sums: Vec<(Real, u32)>,
    checked: bool,
    /// Smallest fluid–any pair distance at the last half-step evaluation, and the fluid particle's id.
    min_pair: (Real, u64),
    /// Σ |δr_shift|² and Σ |u Δt|² over fluid particles and steps (shifting diagnostics).
    shift_sums: (Real, Real),
    /// Rates used by the predictor and the time step (state n, or carried over from the last
    /// half-step evaluation with [`Integrator::SingleEvaluation`]).
    rates0: Vec<Rate>,
    /// `rates0` is aligned with the particles and may be reused.
    carried: bool,
    /// The next evaluation also fills the workspace's velocities, pressures and densities (walls
    /// interpolated), not only the rates.
    want_state: bool,
}

impl Solver {
    /// Validates `params` and the particle arrays.
    pub fn new(params: SphParams, particles: Particles, time: Real) -> Result<Self, SphError> {
        params.validate()?;
        if particles.consistent_len().is_none() {
            return Err(SphError::State("particle arrays have different lengths".into()));
        }
        if particles.fluid_count() == 0 {
            return Err(SphError::State("no fluid particle".into()));
        }
        if !time.is_finite() {
            return Err(SphError::State(format!("start time {time} is not finite")));
        }
        for i in 0..particles.len() {
            let vals =
                [particles.x[i], particles.z[i], particles.vx[i], particles.vz[i], particles.rho[i], particles.mass[i]];
            if vals.iter().any(|v| !v.is_finite()) || particles.rho[i] <= 0.0 || particles.mass[i] <= 0.0 {
                return Err(SphError::State(format!(
                    "particle id {} has a non-finite value or non-positive density/mass",
                    particles.id[i]
                )));
            }
        }
        let mut seen = std::collections::HashSet::with_capacity(particles.len());
        if let Some(i) = particles.id.iter().position(|id| !seen.insert(*id)) {
            return Err(SphError::State(format!("particle id {} appears twice: ids must be unique", particles.id[i])));
        }
        let pulsatile = match &params.body_force_pulsatile {
            Some(f) => Some((f.direction, f.waveform.build().map_err(|e| SphError::State(e.to_string()))?)),
            None => None,
        };
        let kernel = Kernel::new(params.kernel, params.h);
        let next_id = particles.next_free_id();
        let mut s = Solver {
            params,
            kernel,
            particles,
            time,
            cells: CellList::default(),
            ws: Workspace::default(),
            fast: FastWorkspace::default(),
            x0: Vec::new(),
            z0: Vec::new(),
            vx0: Vec::new(),
            vz0: Vec::new(),
            rho0: Vec::new(),
            first_dt: None,
            last: None,
            steps: 0,
            pulsatile,
            boundaries: Vec::new(),
            motions: Vec::new(),
            motion_time: time,
            domain: None,
            guard_corrections: 0,
            next_id,
            keep: Vec::new(),
            sums: Vec::new(),
            checked: false,
            min_pair: (Real::INFINITY, 0),
            shift_sums: (0.0, 0.0),
            rates0: Vec::new(),
            carried: false,
            want_state: false,
        };
        s.wrap_positions();
        Ok(s)
    }

    /// Adds the open boundaries (reservoirs); reservoir particles' `group` indexes this list.
    pub fn with_open_boundaries(mut self, boundaries: Vec<OpenBoundary>) -> Result<Self, SphError> {
        let support = self.kernel.support_radius();
        for b in &boundaries {
            b.validate(support).map_err(SphError::State)?;
        }
        let nu = self.params.nu();
        self.boundaries = boundaries.into_iter().map(|b| BoundaryState::new(b, nu)).collect();
        self.checked = false;
        boundary::impose(&mut self.boundaries, &mut self.particles, self.time);
        Ok(self)
    }

    /// Adds prescribed wall motions; wall particles with `group` = k ≥ 1 follow motion k − 1.
    pub fn with_wall_motions(mut self, motions: &[WallMotion]) -> Result<Self, SphError> {
        self.motions = motions
            .iter()
            .enumerate()
            .map(|(i, m)| BuiltMotion::new(m, i))
            .collect::<Result<_, _>>()
            .map_err(SphError::State)?;
        self.checked = false;
        self.motion_time = self.time;
        self.move_walls(self.time);
        Ok(self)
    }

    /// SPH interpolation of the velocity at the points (xs\[k\], zs\[k\]) at the current time:
    /// Shepard-normalised kernel sums u(r) = Σ V_b u_b W / Σ V_b W over fluid, reservoir and wall
    /// particles (walls with the velocities of the no-slip condition, so the interpolant vanishes at
    /// a fixed wall), and the fluid fraction Σ_{fluid, reservoir} V_b W (≈ 1 inside the fluid, 0 far
    /// outside; ≈ 1/4 on a flat wall whose first fluid row is one spacing away, 1/2 half a spacing
    /// inside). Returns (vx, vz, fluid fraction) per point; (0, 0, 0) where no
    /// particle is within the kernel support. Costs one right-hand-side evaluation plus the sums.
    pub fn sample_velocity(&mut self, xs: &[Real], zs: &[Real]) -> Vec<[Real; 3]> {
        let t = self.time;
        self.set_boundary_time(t);
        self.want_state = true;
        self.evaluate(t);
        self.want_state = false;
        let r = self.kernel.support_radius();
        self.cells.build(&self.particles.x, &self.particles.z, r, self.params.periodic_x, self.params.periodic_z);
        let (p, ws, k) = (&self.particles, &self.ws, &self.kernel);
        let (px, pz) = (&p.x[..], &p.z[..]);
        xs.iter()
            .zip(zs)
            .map(|(&x, &z)| {
                let (mut sw, mut su, mut sv, mut sf) = (0.0, 0.0, 0.0, 0.0);
                self.cells.for_each_neighbour(x, z, px, pz, |b, _, _, r2| {
                    let wv = p.mass[b] / ws.rho[b] * k.w(r2.sqrt());
                    sw += wv;
                    su += wv * ws.ux[b];
                    sv += wv * ws.uz[b];
                    if !p.kind[b].is_wall() {
                        sf += wv;
                    }
                });
                if sw > 0.0 {
                    [su / sw, sv / sw, sf]
                } else {
                    [0.0, 0.0, 0.0]
                }
            })
            .collect()
    }

    /// The full state, to write with [`Checkpoint::write`].
    pub fn checkpoint(&self) -> Checkpoint {
        Checkpoint {
            header: CheckpointHeader {
                time: self.time,
                steps: self.steps,
                next_id: self.next_id,
                n_particles: self.particles.len() as u64,
                first_dt: self.first_dt,
                last_step: self.last,
                fluxes: self.boundaries.iter().map(|b| b.flux).collect(),
                shift_sums: self.shift_sums,
                guard_corrections: self.guard_corrections,
                params: self.params.clone(),
                boundaries: self.boundaries.iter().map(|b| b.spec.clone()).collect(),
            },
            particles: self.particles.clone(),
        }
    }

    /// Continues a run from `ckpt` with `params`, `boundaries` and `motions`. The open boundaries
    /// must be those the checkpoint was written with (same names, in order): the reservoir particles
    /// refer to them. Parameters may differ (e.g. a finer output schedule or another thread
    /// setting); [`Checkpoint`] users can list the differences with [`CheckpointHeader::params`].
    pub fn from_checkpoint(
        params: SphParams,
        ckpt: Checkpoint,
        boundaries: Vec<OpenBoundary>,
        motions: &[WallMotion],
    ) -> Result<Self, SphError> {
        let names: Vec<&str> = boundaries.iter().map(|b| b.name.as_str()).collect();
        let saved: Vec<&str> = ckpt.header.boundaries.iter().map(|b| b.name.as_str()).collect();
        if names != saved {
            return Err(SphError::State(format!(
                "the checkpoint was written with open boundaries {saved:?}, this run has {names:?}"
            )));
        }
        let h = ckpt.header;
        let mut s = Solver::new(params, ckpt.particles, h.time)?
            .with_open_boundaries(boundaries)?
            .with_wall_motions(motions)?;
        for (b, f) in s.boundaries.iter_mut().zip(&h.fluxes) {
            b.flux = *f;
        }
        s.steps = h.steps;
        s.shift_sums = h.shift_sums;
        s.guard_corrections = h.guard_corrections;
        s.first_dt = h.first_dt;
        s.last = h.last_step;
        s.next_id = s.next_id.max(h.next_id);
        Ok(s)
    }

    /// Adds the anti-penetration guard: after every step a fluid particle found outside `domain`
    /// (signed distance > 0) is put back half a particle spacing inside along the distance gradient
    /// and its outward normal velocity is removed; every correction is counted in
    /// [`Diagnostics::guard_corrections`]. Not used with moving walls.
    pub fn with_domain(mut self, domain: Arc<dyn Domain>) -> Self {
        self.domain = Some(domain);
        self
    }

    /// Every reservoir particle names an existing boundary and every moving wall an existing motion
    /// (checked once, before the first step after a change).
    fn check_ready(&mut self) -> Result<(), SphError> {
        if self.checked {
            return Ok(());
        }
        let p = &self.particles;
        for i in 0..p.len() {
            let g = p.group[i] as usize;
            let bad = match p.kind[i] {
                ParticleKind::Buffer => g >= self.boundaries.len(),
                ParticleKind::WallOn | ParticleKind::WallOutside => g > self.motions.len(),
                ParticleKind::Fluid => false,
            };
            if bad {
                return Err(SphError::State(format!(
                    "particle id {} ({:?}) has group {g}, but there are {} open boundaries and {} wall motions",
                    p.id[i],
                    p.kind[i],
                    self.boundaries.len(),
                    self.motions.len()
                )));
            }
        }
        self.checked = true;
        Ok(())
    }

    /// Current time \[s\].
    pub fn time(&self) -> Real {
        self.time
    }

    /// Parameters.
    pub fn params(&self) -> &SphParams {
        &self.params
    }

    /// Kernel in use.
    pub fn kernel(&self) -> &Kernel {
        &self.kernel
    }

    /// Open boundaries and their bookkeeping.
    pub fn boundaries(&self) -> &[BoundaryState] {
        &self.boundaries
    }

    /// Diagnostics of the last step, if any.
    pub fn last_step(&self) -> Option<StepReport> {
        self.last
    }

    /// Steps taken since the start.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Next particle id the solver will give to a created particle.
    pub fn next_id(&self) -> u64 {
        self.next_id
    }

    /// Body force per unit mass at time t \[m/s²\].
    pub fn body_force_at(&self, t: Real) -> [Real; 2] {
        let mut g = self.params.body_force;
        if let Some((d, w)) = &self.pulsatile {
            let f = w.value(t);
            g[0] += d[0] * f;
            g[1] += d[1] * f;
        }
        g
    }

    /// State summary now.
    pub fn diagnostics(&self) -> Diagnostics {
        let p = &self.particles;
        let (mut nf, mut nb, mut nw) = (0, 0, 0);
        let (mut ke, mut mass, mut emax, mut vmax) = (0.0, 0.0, 0.0 as Real, 0.0 as Real);
        for i in 0..p.len() {
            match p.kind[i] {
                ParticleKind::Fluid => {
                    nf += 1;
                    let v2 = p.vx[i] * p.vx[i] + p.vz[i] * p.vz[i];
                    ke += 0.5 * p.mass[i] * v2;
                    mass += p.mass[i];
                    emax = emax.max((p.rho[i] / self.params.rho0 - 1.0).abs());
                    vmax = vmax.max(v2.sqrt());
                }
                ParticleKind::Buffer => nb += 1,
                _ => nw += 1,
            }
        }
        Diagnostics {
            time: self.time,
            steps: self.steps,
            last_step: self.last,
            n_fluid: nf,
            n_buffer: nb,
            n_wall: nw,
            max_density_error: emax,
            kinetic_energy: ke,
            fluid_mass: mass,
            max_speed: vmax,
            min_pair_distance: self.min_pair.0,
            min_pair_id: self.min_pair.1,
            shift_ratio: if self.shift_sums.1 > 0.0 { (self.shift_sums.0 / self.shift_sums.1).sqrt() } else { 0.0 },
            boundaries: self.boundaries.iter().map(|b| (b.spec.name.clone(), b.flux)).collect(),
            guard_corrections: self.guard_corrections,
        }
    }

    fn wrap_positions(&mut self) {
        let (px, pz) = (self.params.periodic_x, self.params.periodic_z);
        if px.is_none() && pz.is_none() {
            return;
        }
        let p = &mut self.particles;
        for i in 0..p.len() {
            if p.kind[i].is_wall() {
                continue;
            }
            if let Some(q) = px {
                p.x[i] = q.wrap(p.x[i]);
            }
            if let Some(q) = pz {
                p.z[i] = q.wrap(p.z[i]);
            }
        }
    }

    /// Moves the walls with a prescribed motion to time t (incremental: r += d(t) − d(t_prev)).
    fn move_walls(&mut self, t: Real) {
        if self.motions.is_empty() {
            return;
        }
        let t_prev = self.motion_time;
        let d: Vec<([Real; 2], [Real; 2])> = self
            .motions
            .iter()
            .map(|m| {
                let (a, b) = (m.displacement(t_prev), m.displacement(t));
                ([b[0] - a[0], b[1] - a[1]], m.velocity(t))
            })
            .collect();
        let p = &mut self.particles;
        for i in 0..p.len() {
            let g = p.group[i] as usize;
            if p.kind[i].is_wall() && g > 0 {
                let (dd, v) = d[g - 1];
                p.x[i] += dd[0];
                p.z[i] += dd[1];
                p.vx[i] = v[0];
                p.vz[i] = v[1];
            }
        }
        self.motion_time = t;
    }

    /// Sets the time-dependent boundary data (moving walls, reservoir velocities and densities) to
    /// time t.
    fn set_boundary_time(&mut self, t: Real) {
        self.set_boundary_time_with(t, true);
    }

    /// [`Solver::set_boundary_time`], the reservoir densities only when `densities`.
    fn set_boundary_time_with(&mut self, t: Real, densities: bool) {
        self.move_walls(t);
        boundary::impose(&mut self.boundaries, &mut self.particles, t);
        if densities && !self.boundaries.is_empty() {
            let support = self.kernel.support_radius();
            boundary::extrapolate_density(
                &self.boundaries,
                &mut self.particles,
                support,
                self.params.rho0,
                &mut self.sums,
            );
        }
    }

    fn evaluate(&mut self, t: Real) {
        let g = self.body_force_at(t);
        // the fast evaluator has no tensile correction: the reference computes that case
        if self.params.fast_rhs && self.params.tensile_correction == 0.0 {
            // the steps need the rates only; `sample_velocity` asks for the state as well
            self.fast.rates_only = !self.want_state;
            fast::compute_rates(&self.params, &self.kernel, &self.particles, g, &mut self.ws, &mut self.fast);
            return;
        }
        let r = self.kernel.support_radius();
        self.cells.build(&self.particles.x, &self.particles.z, r, self.params.periodic_x, self.params.periodic_z);
        compute_rates(&self.params, &self.kernel, &self.particles, &self.cells, g, &mut self.ws);
    }

    fn check_rates(&self) -> Result<(), SphError> {
        for (i, r) in self.ws.rates.iter().enumerate() {
            if let Some(k) = [r.drho, r.acc[0], r.acc[1]].iter().position(|v| !v.is_finite()) {
                let quantity = ["density rate", "acceleration x", "acceleration z"][k];
                return Err(self.blow_up(i, BlowUpCriterion::NonFinite { quantity }));
            }
        }
        Ok(())
    }

    fn blow_up(&self, i: usize, criterion: BlowUpCriterion) -> SphError {
        SphError::BlowUp { time: self.time, particle_id: self.particles.id[i], criterion }
    }

    /// Adaptive dt from the rates at the current state, and the binding criterion.
    fn adaptive_dt(&self) -> (Real, DtCriterion, usize) {
        let p = &self.params;
        let h = self.kernel.h;
        let (pt, rates0) = (&self.particles, &self.rates0);
        // per chunk, combined in order: the first largest acceleration, as a serial pass finds it
        let partial = chunks::map_ranges(p.parallel, pt.len(), |range| {
            let (mut vmax2, mut amax2, mut amax_i) = (0.0 as Real, 0.0 as Real, 0usize);
            for i in range {
                match pt.kind[i] {
                    ParticleKind::Fluid => {
                        let a = rates0[i].acc;
                        let a2 = a[0] * a[0] + a[1] * a[1];
                        if a2 > amax2 {
                            amax2 = a2;
                            amax_i = i;
                        }
                    }
                    ParticleKind::Buffer => {}
                    _ => continue,
                }
                vmax2 = vmax2.max(pt.vx[i].powi(2) + pt.vz[i].powi(2));
            }
            (vmax2, amax2, amax_i)
        });
        let (mut vmax2, mut amax2, mut amax_i) = (0.0 as Real, 0.0 as Real, 0usize);
        for (v, a, i) in partial {
            vmax2 = vmax2.max(v);
            if a > amax2 {
                (amax2, amax_i) = (a, i);
            }
        }
        let mut best = (p.dt_max, DtCriterion::Maximum);
        let mut consider = |dt: Real, c: DtCriterion| {
            if dt < best.0 {
                best = (dt, c);
            }
        };
        consider(p.cfl * h / (p.c + vmax2.sqrt()), DtCriterion::Cfl);
        if p.mu > 0.0 {
            consider(p.viscous_dt_factor * h * h / p.nu(), DtCriterion::Viscous);
        }
        if amax2 > 0.0 {
            consider(p.force_dt_factor * (h / amax2.sqrt()).sqrt(), DtCriterion::Force);
        }
        (best.0, best.1, amax_i)
    }

    /// Takes one step of at most `dt_limit` seconds (if given).
    pub fn step(&mut self, dt_limit: Option<Real>) -> Result<StepReport, SphError> {
        self.check_ready()?;
        let t_n = self.time;
        let single = self.params.integrator == Integrator::SingleEvaluation;
        let reuse = single && self.carried && self.rates0.len() == self.particles.len();
        // with carried rates nothing is evaluated at t_n: the reservoir densities are not needed
        self.set_boundary_time_with(t_n, !reuse);
        if !reuse {
            self.evaluate(t_n);
            self.check_rates()?;
            self.rates0.clone_from(&self.ws.rates);
        }
        self.carried = false;
        let (mut dt, mut binding, amax_i) = self.adaptive_dt();
        if let Some(first) = self.first_dt {
            let threshold = first * self.params.dt_collapse_ratio;
            if dt < threshold {
                return Err(self.blow_up(amax_i, BlowUpCriterion::DtCollapse { dt, threshold, binding }));
            }
        } else {
            self.first_dt = Some(dt);
        }
        if let Some(l) = dt_limit {
            if l < dt {
                dt = l;
                binding = DtCriterion::Output;
            }
        }
        let half = 0.5 * dt;
        // Save state n.
        self.x0.clone_from(&self.particles.x);
        self.z0.clone_from(&self.particles.z);
        self.vx0.clone_from(&self.particles.vx);
        self.vz0.clone_from(&self.particles.vz);
        self.rho0.clone_from(&self.particles.rho);
        // Predictor. Reservoir particles move with their imposed velocity; it is re-imposed at the
        // half time below.
        {
            let pt = &mut self.particles;
            let (kind, rates0, vx0, vz0) = (&pt.kind, &self.rates0, &self.vx0, &self.vz0);
            let parts = chunks::state_chunks(&mut pt.x, &mut pt.z, &mut pt.vx, &mut pt.vz, &mut pt.rho);
            chunks::map_chunks(self.params.parallel, parts, |c| {
                for j in 0..c.x.len() {
                    let i = c.start + j;
                    let r = rates0[i];
                    match kind[i] {
                        ParticleKind::Fluid => {
                            c.vx[j] += half * r.acc[0];
                            c.vz[j] += half * r.acc[1];
                        }
                        ParticleKind::Buffer => {
                            // velocity and density are imposed/extrapolated at every stage
                            c.x[j] += half * vx0[i];
                            c.z[j] += half * vz0[i];
                            continue;
                        }
                        _ => continue,
                    }
                    c.x[j] += half * vx0[i];
                    c.z[j] += half * vz0[i];
                    c.rho[j] += half * r.drho;
                }
            });
        }
        self.wrap_positions();
        let t_half = t_n + half;
        self.set_boundary_time(t_half);
        self.evaluate(t_half);
        // Corrector and final update, in one pass over the rates with their finiteness check
        // (`check_rates`, reported before anything else) and the nearest pair; chunk by chunk,
        // the chunks' results combined in order (the serial pass's first/last-index rules).
        let (mut max_err, mut worst) = (0.0 as Real, 0usize);
        let mut first_bad: Option<usize> = None;
        let mut bad_rate: Option<usize> = None;
        let mut min_pair = (Real::INFINITY, 0usize);
        {
            let pt = &mut self.particles;
            let rho_ref = self.params.rho0;
            let (kind, rates, x0, z0, vx0, vz0, rho0) =
                (&pt.kind, &self.ws.rates, &self.x0, &self.z0, &self.vx0, &self.vz0, &self.rho0);
            let parts = chunks::state_chunks(&mut pt.x, &mut pt.z, &mut pt.vx, &mut pt.vz, &mut pt.rho);
            let partial = chunks::map_chunks(self.params.parallel, parts, |c| {
                let mut max_err = 0.0 as Real;
                let mut worst = 0usize;
                let mut first_bad: Option<usize> = None;
                let mut bad_rate: Option<usize> = None;
                let mut min_pair = (Real::INFINITY, 0usize);
                for j in 0..c.x.len() {
                    let i = c.start + j;
                    let r = rates[i];
                    // a sum is finite only if every term is
                    if bad_rate.is_none() && !(r.drho + r.acc[0] + r.acc[1]).is_finite() {
                        bad_rate = Some(i);
                    }
                    let (vxh, vzh) = match kind[i] {
                        ParticleKind::Fluid => (vx0[i] + half * r.acc[0], vz0[i] + half * r.acc[1]),
                        ParticleKind::Buffer => {
                            c.x[j] = x0[i] + dt * c.vx[j];
                            c.z[j] = z0[i] + dt * c.vz[j];
                            continue;
                        }
                        _ => continue,
                    };
                    let rhoh = rho0[i] + half * r.drho;
                    let xh = x0[i] + half * vxh;
                    let zh = z0[i] + half * vzh;
                    c.vx[j] = 2.0 * vxh - vx0[i];
                    c.vz[j] = 2.0 * vzh - vz0[i];
                    c.rho[j] = 2.0 * rhoh - rho0[i];
                    c.x[j] = 2.0 * xh - x0[i];
                    c.z[j] = 2.0 * zh - z0[i];
                    if kind[i].is_fluid() {
                        if r.r2min < min_pair.0 {
                            min_pair = (r.r2min, i);
                        }
                        let e = (c.rho[j] / rho_ref - 1.0).abs();
                        if e > max_err || e.is_nan() {
                            max_err = e;
                            worst = i;
                        }
                    }
                    // a sum is finite only if every term is (inf − inf is NaN)
                    if first_bad.is_none() && !(c.x[j] + c.z[j] + c.vx[j] + c.vz[j] + c.rho[j]).is_finite() {
                        first_bad = Some(i);
                    }
                }
                (max_err, worst, first_bad, bad_rate, min_pair)
            });
            for (e, w, fb, br, mp) in partial {
                if e > max_err || e.is_nan() {
                    (max_err, worst) = (e, w);
                }
                first_bad = first_bad.or(fb);
                bad_rate = bad_rate.or(br);
                if mp.0 < min_pair.0 {
                    min_pair = mp;
                }
            }
        }
        if bad_rate.is_some() {
            // the first particle with a non-finite rate, named as `check_rates` names it
            self.check_rates()?;
        }
        self.min_pair = (min_pair.0.sqrt(), if min_pair.0.is_finite() { self.particles.id[min_pair.1] } else { 0 });
        if let Some(i) = first_bad {
            let pt = &self.particles;
            let vals = [
                ("position", pt.x[i]),
                ("position", pt.z[i]),
                ("velocity", pt.vx[i]),
                ("velocity", pt.vz[i]),
                ("density", pt.rho[i]),
            ];
            let q = vals.iter().find(|(_, v)| !v.is_finite()).map_or("value", |(q, _)| q);
            return Err(self.blow_up(i, BlowUpCriterion::NonFinite { quantity: q }));
        }
        if max_err > self.params.density_error_limit {
            let limit = self.params.density_error_limit;
            return Err(self.blow_up(worst, BlowUpCriterion::DensityError { value: max_err, limit }));
        }
        self.shift(dt);
        self.wrap_positions();
        let t_new = t_n + dt;
        // the guard every 4th step: a fluid particle moves ≤ 4 · cfl · h · |u|/(c + |u|) ≲ 0.1 h in
        // that time, far less than the wall layers' thickness
        if (self.steps + 1).is_multiple_of(4) {
            self.guard(t_new);
        }
        if single {
            // the half-step rates become the next predictor's (swap: no copy; the next evaluation
            // refills the workspace)
            std::mem::swap(&mut self.rates0, &mut self.ws.rates);
        }
        // profiles at t_new for the particles the exchange creates or converts; the next step's
        // first stage imposes velocities and extrapolates densities at the same time
        for b in &mut self.boundaries {
            b.set_time(t_new);
        }
        boundary::exchange(
            &mut self.boundaries,
            &mut self.particles,
            self.params.rho0,
            &mut self.next_id,
            &mut self.keep,
        );
        if single {
            // keep the carried rates aligned with the particles the exchange removed and created
            if !self.boundaries.is_empty() && self.keep.len() == self.rates0.len() {
                let first = crate::particles::first_removed(&self.keep);
                crate::particles::retain_from(&mut self.rates0, &self.keep, first);
            }
            self.rates0.resize(self.particles.len(), Rate::default());
            self.carried = true;
        }
        self.time = t_new;
        self.steps += 1;
        if self.steps.is_multiple_of(REORDER_INTERVAL) {
            self.reorder_by_cell();
        }
        let rep = StepReport { dt, binding, max_density_error: max_err, steps: self.steps };
        self.last = Some(rep);
        Ok(rep)
    }

    /// Steps until exactly `t_target` (the last step is shortened; when less than two steps remain,
    /// they are split evenly so no tiny step is taken). Returns the report of the last step.
    ///
    /// With `parallel` and more than one rayon thread, called from outside a rayon pool, the steps
    /// run on a worker of the global pool (the same bits; carotid on 2 threads +14 %, PERF.md).
    /// Prefer it to calling [`Self::step`] in a loop from outside a pool.
    pub fn advance_to(&mut self, t_target: Real) -> Result<Option<StepReport>, SphError> {
        if t_target.is_nan() || t_target < self.time {
            return Err(SphError::TimeInPast { requested: t_target, now: self.time });
        }
        // With threads, the steps run on a worker of the pool: each parallel pass is then a fork
        // within the pool (the stepping worker takes part and waits only for stolen work) instead
        // of a job injected from outside that puts this thread to sleep and wakes it at the end.
        // The same passes in the same order: the same bits.
        #[cfg(feature = "parallel")]
        if self.params.parallel && rayon::current_thread_index().is_none() && rayon::current_num_threads() > 1 {
            return rayon::scope(|_| self.advance_steps(t_target));
        }
        self.advance_steps(t_target)
    }

    /// The steps of [`Self::advance_to`] (arguments checked).
    fn advance_steps(&mut self, t_target: Real) -> Result<Option<StepReport>, SphError> {
        let mut last = None;
        while self.time < t_target {
            let left = t_target - self.time;
            let limit = match self.last {
                Some(r) if left > r.dt && left < 2.0 * r.dt => 0.5 * left,
                _ => left,
            };
            let rep = self.step(Some(limit))?;
            if (t_target - self.time) <= 1e-12 * t_target.abs().max(1e-30) {
                self.time = t_target;
            }
            last = Some(rep);
        }
        Ok(last)
    }
}
