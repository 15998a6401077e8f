//! Time integration: second-order predictor–corrector (Monaghan 1989 form) with an adaptive time
//! step and outputs exactly at requested times (paper §2.2).
//!
//! One step from t to t + Δt, with F the acceleration and D = Dρ/Dt:
//! * F⁰, D⁰ at state n; Δt = min(C_cfl h/(c + |u|max), C_ν h²/ν, C_f √(h/|a|max), dt_max, time left);
//! * predictor: u* = uⁿ + Δt/2 F⁰, ρ* = ρⁿ + Δt/2 D⁰, r* = rⁿ + Δt/2 uⁿ;
//! * corrector at the half state: u½ = uⁿ + Δt/2 F*, ρ½ = ρⁿ + Δt/2 D*, r½ = rⁿ + Δt/2 u½;
//! * uⁿ⁺¹ = 2u½ − uⁿ, ρⁿ⁺¹ = 2ρ½ − ρⁿ, rⁿ⁺¹ = 2r½ − rⁿ.

use crate::kernel::Kernel;
use crate::neighbours::CellList;
use crate::params::{ParamError, SphParams};
use crate::particles::Particles;
use crate::wcsph::{compute_rates, Workspace};
use crate::Real;

/// Which criterion set the time step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DtCriterion {
    /// Acoustic CFL: C_cfl h / (c + |u|max).
    Cfl,
    /// Viscous diffusion: C_ν h² / ν.
    Viscous,
    /// Force: C_f √(h / |a|max).
    Force,
    /// `dt_max`.
    Maximum,
    /// Shortened to land exactly on a requested output time.
    Output,
}

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

/// Diagnostics of the last step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepReport {
    /// Time step taken \[s\].
    pub dt: Real,
    /// What limited it.
    pub binding: DtCriterion,
    /// max |ρ/ρ₀ − 1| over fluid particles after the step.
    pub max_density_error: Real,
    /// Steps taken since the start.
    pub steps: u64,
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
    x0: Vec<Real>,
    z0: Vec<Real>,
    vx0: Vec<Real>,
    vz0: Vec<Real>,
    rho0: Vec<Real>,
    first_dt: Option<Real>,
    last: Option<StepReport>,
    steps: u64,
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
        let kernel = Kernel::new(params.kernel, params.h);
        let mut s = Solver {
            params,
            kernel,
            particles,
            time,
            cells: CellList::default(),
            ws: Workspace::default(),
            x0: Vec::new(),
            z0: Vec::new(),
            vx0: Vec::new(),
            vz0: Vec::new(),
            rho0: Vec::new(),
            first_dt: None,
            last: None,
            steps: 0,
        };
        s.wrap_positions();
        Ok(s)
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

    /// Diagnostics of the last step, if any.
    pub fn last_step(&self) -> Option<StepReport> {
        self.last
    }

    /// Pressure of every particle at the last evaluation (walls: interpolated) \[Pa\].
    pub fn pressure(&self) -> &[Real] {
        &self.ws.p
    }

    fn wrap_positions(&mut self) {
        if let Some(p) = self.params.periodic_x {
            for (x, k) in self.particles.x.iter_mut().zip(&self.particles.kind) {
                if !k.is_wall() {
                    *x = p.wrap(*x);
                }
            }
        }
    }

    fn evaluate(&mut self) {
        let r = self.kernel.support_radius();
        self.cells.build(&self.particles.x, &self.particles.z, r, self.params.periodic_x);
        compute_rates(&self.params, &self.kernel, &self.particles, &self.cells, &mut self.ws);
    }

    fn check_rates(&self) -> Result<(), SphError> {
        for (i, r) in self.ws.rates.iter().enumerate() {
            if let Some(k) = r.iter().position(|v| !v.is_finite()) {
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
        let (mut vmax2, mut amax2, mut amax_i) = (0.0 as Real, 0.0 as Real, 0usize);
        for i in 0..self.particles.len() {
            if self.particles.kind[i].is_wall() {
                continue;
            }
            vmax2 = vmax2.max(self.particles.vx[i].powi(2) + self.particles.vz[i].powi(2));
            let r = self.ws.rates[i];
            let a2 = r[1] * r[1] + r[2] * r[2];
            if a2 > amax2 {
                amax2 = a2;
                amax_i = i;
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
        self.evaluate();
        self.check_rates()?;
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
        let n = self.particles.len();
        // Save state n.
        self.x0.clone_from(&self.particles.x);
        self.z0.clone_from(&self.particles.z);
        self.vx0.clone_from(&self.particles.vx);
        self.vz0.clone_from(&self.particles.vz);
        self.rho0.clone_from(&self.particles.rho);
        // Predictor.
        {
            let pt = &mut self.particles;
            for i in 0..n {
                if pt.kind[i].is_wall() {
                    continue;
                }
                let r = self.ws.rates[i];
                pt.x[i] += half * pt.vx[i];
                pt.z[i] += half * pt.vz[i];
                pt.vx[i] += half * r[1];
                pt.vz[i] += half * r[2];
                pt.rho[i] += half * r[0];
            }
        }
        self.wrap_positions();
        self.evaluate();
        self.check_rates()?;
        // Corrector and final update.
        let mut max_err = 0.0 as Real;
        let mut worst = 0usize;
        {
            let pt = &mut self.particles;
            let rho_ref = self.params.rho0;
            for i in 0..n {
                if pt.kind[i].is_wall() {
                    continue;
                }
                let r = self.ws.rates[i];
                let vxh = self.vx0[i] + half * r[1];
                let vzh = self.vz0[i] + half * r[2];
                let rhoh = self.rho0[i] + half * r[0];
                let xh = self.x0[i] + half * vxh;
                let zh = self.z0[i] + half * vzh;
                pt.vx[i] = 2.0 * vxh - self.vx0[i];
                pt.vz[i] = 2.0 * vzh - self.vz0[i];
                pt.rho[i] = 2.0 * rhoh - self.rho0[i];
                pt.x[i] = 2.0 * xh - self.x0[i];
                pt.z[i] = 2.0 * zh - self.z0[i];
                let e = (pt.rho[i] / rho_ref - 1.0).abs();
                if e > max_err || e.is_nan() {
                    max_err = e;
                    worst = i;
                }
            }
        }
        for i in 0..n {
            let pt = &self.particles;
            let vals = [
                ("position", pt.x[i]),
                ("position", pt.z[i]),
                ("velocity", pt.vx[i]),
                ("velocity", pt.vz[i]),
                ("density", pt.rho[i]),
            ];
            if let Some((q, _)) = vals.iter().find(|(_, v)| !v.is_finite()) {
                return Err(self.blow_up(i, BlowUpCriterion::NonFinite { quantity: q }));
            }
        }
        if max_err > self.params.density_error_limit {
            let limit = self.params.density_error_limit;
            return Err(self.blow_up(worst, BlowUpCriterion::DensityError { value: max_err, limit }));
        }
        self.wrap_positions();
        self.time += dt;
        self.steps += 1;
        let rep = StepReport { dt, binding, max_density_error: max_err, steps: self.steps };
        self.last = Some(rep);
        Ok(rep)
    }

    /// Steps until exactly `t_target` (the last step is shortened; when less than two steps remain,
    /// they are split evenly so no tiny step is taken). Returns the report of the last step.
    pub fn advance_to(&mut self, t_target: Real) -> Result<Option<StepReport>, SphError> {
        if t_target.is_nan() || t_target < self.time {
            return Err(SphError::TimeInPast { requested: t_target, now: self.time });
        }
        let mut last = None;
        while self.time < t_target {
            let left = t_target - self.time;
            // Peek at the adaptive step by evaluating once inside `step`; limit it to `left`, or to
            // half of `left` when `left` is between one and two steps (known from the last step).
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
