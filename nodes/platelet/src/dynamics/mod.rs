//! Platelet dynamics in 2-D (paper 2: section 3.2 eq 5–6, section 4.1 "2d Simplification",
//! eq 11, eq 12, Algorithm 2, Remarks 1–2, section 5.2).
//!
//! Each platelet is a point particle with shape ([`Particles`], structure of arrays) moved by
//! Newton–Euler, m V' = F, I Ω' = T, X' = V, φ' = Ω, with F and T from the coefficient law of
//! [`crate::coefficients`] (eq 6 plus the strain torque c_s E'_xy), δv = v − V at the centre of
//! mass and ψ from eq 11, ψ = ∠(e_x, δv) − φ. When |δv| ≤ [`DynamicsParams::psi_min_speed`]
//! ∠(e_x, δv) is undefined and the last known direction of δv ([`Particles::dv_dir`]) is used, so
//! ψ still follows the body's rotation (at creation the direction of the flow, or e_x in still
//! fluid). A relaxed platelet in a steady flow has δv ≈ 0 (the exact relaxation leaves only
//! rounding), so this is the common case, not an exception.
//!
//! **Stiffness.** For a platelet m/C_d and I/C_r are tens of nanoseconds while the paper's particle
//! sub-step is 0.25 ms. The default [`Integrator::Exponential`] integrates the linear relaxation
//! exactly with the coefficients and the fluid sample frozen over the step (see [`integrate`]);
//! [`Integrator::ExplicitEuler`] is there to show why: it diverges unless the step is below
//! [`integrate::explicit_limit`], and a diverged state is reported as [`DynamicsError::State`].
//!
//! **Rotation–translation coupling** ([`DynamicsParams::coupling`]). Lorentz reciprocity makes the
//! 3 × 3 resistance matrix relating (F, T) to (δv, ω − Ω) symmetric, so a pitching torque C_p
//! (centre of pressure ≠ centre of mass) implies a force c (ω − Ω) from relative rotation, with
//! c the coupling vector; eq 6 omits it. The platelet is mirror-symmetric in its x → −x plane,
//! so c has no component along the body's y axis: c = c_x (cos φ, sin φ) with c_x = C_p(ψ = 0),
//! evaluated once per particle ([`Particles::coupling`]), and T_p = c · δv = c_x |δv| cos ψ, which
//! is eq 6's pitching torque for the networks' C_p(ψ) ∝ cos ψ. The resistance matrix must then be
//! positive definite, c_x² < C_d C_r, or the step is refused. **Default: off**, so that the
//! default model is eq 6 as the paper writes it; turn it on to study the oscillatory y-motion of
//! asymmetric particles (section 5.1.5).
//!
//! **Sub-cycling** (Algorithm 2): [`Dynamics::macro_step`] runs M sub-steps of length k/M; the
//! translational coefficients are refreshed for all particles in one batch call of the
//! [`CoefficientModel`] on every `coeff_every`-th sub-step (counted over the whole run), the
//! rotational ones once per particle when it is first stepped. After every sub-step collisions
//! (Remark 1, [`collide`]) and walls are applied.
//!
//! **Speed** (Remark 2): the particles are a structure of arrays, the workspaces are reused, the
//! advection can run on `threads` rayon workers (same bits for any count), and
//! [`DynamicsParams::spatial_sort`] reorders the particles by position every macro step for
//! memory locality (halves the advection time with a lattice-sampled flow; off by default because
//! it changes particle indices — [`Particles::id`] keeps the identity). See
//! `examples/platelet_bench.rs` for the section 5.2 test.

pub mod collide;
pub mod flow;
pub mod integrate;
pub mod particles;
pub mod sph_interp;
pub mod standin;
pub mod stenosis;

pub use collide::CellGrid;
pub use flow::{CarrierFlow, Channel, FlowError, FlowSample, LatticeField, LocalWalls, SimpleShear};
pub use particles::{ParticleState, Particles, DEFAULT_DENSITY};
pub use sph_interp::{FillReport, InterpOrder, InterpParams, ParticleInterpolator, SphKernel};
pub use standin::DiscStandIn;
pub use stenosis::Stenosis;

use crate::coefficients::CoefficientModel;
use crate::shape::ShapeError;
use integrate::{Body, CoupledPropagator, Kin, Propagator};
use std::time::{Duration, Instant};

/// Errors of the dynamics.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum DynamicsError {
    /// A parameter outside its allowed range.
    #[error("platelet dynamics: `{field}` = {value} is invalid: allowed {allowed}")]
    Invalid { field: &'static str, value: f64, allowed: &'static str },
    /// A particle's kinematic state is NaN or infinite (input, or an unstable explicit step).
    #[error("platelet dynamics: particle {index}: `{field}` = {value}; allowed finite (an explicit step above the stability limit diverges)")]
    State { field: &'static str, index: usize, value: f64 },
    /// A coefficient from the model outside its allowed range.
    #[error("platelet dynamics: model `{model}` gave particle {index} `{field}` = {value}: allowed {allowed}")]
    Coefficient { model: String, index: usize, field: &'static str, value: f64, allowed: &'static str },
    /// The shape of a new particle.
    #[error(transparent)]
    Shape(#[from] ShapeError),
}

/// Time integrator (module doc).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Integrator {
    /// Exact relaxation with frozen coefficients and flow, exponential midpoint (default).
    #[default]
    Exponential,
    /// Forward Euler (for comparison; unstable at the paper's sub-step).
    ExplicitEuler,
}

/// Parameters of the dynamics.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DynamicsParams {
    /// Particle sub-step k_P \[s\]. Default 2.5e-4 (section 5.2).
    pub sub_step: f64,
    /// Sub-steps per macro step M_p. Default 20 (section 5.2).
    pub sub_steps: usize,
    /// Refresh the translational coefficients every this many sub-steps. Default 10.
    pub coeff_every: usize,
    /// Integrator. Default exponential.
    pub integrator: Integrator,
    /// Rotation–translation coupling (module doc). Default false.
    pub coupling: bool,
    /// Apply collisions. Default true.
    pub collisions: bool,
    /// Coefficient of restitution e ∈ [0, 1]. Default 1 (elastic).
    pub restitution: f64,
    /// Worker threads for the advection (collisions and coefficient calls stay serial). 1
    /// (default) runs serially; results are identical bit for bit for any count.
    pub threads: usize,
    /// Sort the particles spatially (rows of cells of `sort_cell` \[m\]) at the start of every
    /// macro step, for memory locality of the flow lookups and the collision search. Changes
    /// particle indices ([`Particles::id`] keeps the identity). Default false.
    pub spatial_sort: bool,
    /// Cell size of the spatial sort \[m\]. Default 2e-5.
    pub sort_cell: f64,
    /// Below this |δv| \[m/s\] ψ is kept from the last refresh. Default 1e-12 (the rounding of a
    /// relaxed V is ~1e-19 m/s at 5 mm/s).
    pub psi_min_speed: f64,
}

impl Default for DynamicsParams {
    fn default() -> Self {
        DynamicsParams {
            sub_step: 2.5e-4,
            sub_steps: 20,
            coeff_every: 10,
            integrator: Integrator::Exponential,
            coupling: false,
            collisions: true,
            restitution: 1.0,
            threads: 1,
            spatial_sort: false,
            sort_cell: 2e-5,
            psi_min_speed: 1e-12,
        }
    }
}

impl DynamicsParams {
    /// Every field in its range.
    pub fn validate(&self) -> Result<(), DynamicsError> {
        let inv = |field, value, allowed| Err(DynamicsError::Invalid { field, value, allowed });
        if !(self.sub_step.is_finite() && self.sub_step > 0.0 && self.sub_step <= 1.0) {
            return inv("sub_step", self.sub_step, "0 < sub_step <= 1 s");
        }
        if self.sub_steps == 0 {
            return inv("sub_steps", 0.0, "sub_steps >= 1");
        }
        if self.coeff_every == 0 {
            return inv("coeff_every", 0.0, "coeff_every >= 1");
        }
        if self.threads == 0 || self.threads > 1024 {
            return inv("threads", self.threads as f64, "1 <= threads <= 1024");
        }
        if !(self.sort_cell.is_finite() && self.sort_cell > 0.0) {
            return inv("sort_cell", self.sort_cell, "finite and > 0 m");
        }
        if !(0.0..=1.0).contains(&self.restitution) {
            return inv("restitution", self.restitution, "0 <= restitution <= 1");
        }
        if !(self.psi_min_speed.is_finite() && self.psi_min_speed >= 0.0) {
            return inv("psi_min_speed", self.psi_min_speed, "finite and >= 0 m/s");
        }
        Ok(())
    }
}

/// Wall-clock split of the work (for reports; never asserted).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Timings {
    /// Advection (flow samples and integration).
    pub advection: Duration,
    /// Collision detection and resolution, walls.
    pub collisions: Duration,
    /// Coefficient evaluation (model calls, validation, propagators).
    pub coefficients: Duration,
    /// Collision impulses applied.
    pub impulses: usize,
    /// Overlapping pairs found.
    pub pairs: usize,
    /// Wall reflections.
    pub wall_hits: usize,
}

impl std::ops::AddAssign for Timings {
    fn add_assign(&mut self, o: Self) {
        self.advection += o.advection;
        self.collisions += o.collisions;
        self.coefficients += o.coefficients;
        self.impulses += o.impulses;
        self.pairs += o.pairs;
        self.wall_hits += o.wall_hits;
    }
}

/// The particle integrator with its workspaces (no allocation per step once grown).
#[derive(Clone, Debug)]
pub struct Dynamics {
    params: DynamicsParams,
    sub_step_count: u64,
    /// Propagators for τ/2 and τ, per particle.
    half: Vec<Propagator>,
    full: Vec<Propagator>,
    /// Coupled propagators for τ/2 and τ, per particle (only with the coupling on).
    coupled_half: Vec<CoupledPropagator>,
    coupled_full: Vec<CoupledPropagator>,
    grid: CellGrid,
    /// Worker pool for the advection when `threads > 1`.
    pool: Option<std::sync::Arc<rayon::ThreadPool>>,
}

/// Mean particles per collision cell the lattice aims at (module `collide`).
const CELL_OCCUPANCY: f64 = 2.0;

impl Dynamics {
    /// Checks the parameters.
    pub fn new(params: DynamicsParams) -> Result<Self, DynamicsError> {
        params.validate()?;
        let mut grid = CellGrid::default();
        grid.occupancy = CELL_OCCUPANCY;
        let pool = if params.threads > 1 {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(params.threads).build().map_err(|_| {
                DynamicsError::Invalid {
                    field: "threads",
                    value: params.threads as f64,
                    allowed: "a thread count the system can start",
                }
            })?;
            Some(std::sync::Arc::new(pool))
        } else {
            None
        };
        Ok(Dynamics {
            params,
            sub_step_count: 0,
            half: Vec::new(),
            full: Vec::new(),
            coupled_half: Vec::new(),
            coupled_full: Vec::new(),
            grid,
            pool,
        })
    }

    /// The parameters.
    pub fn params(&self) -> &DynamicsParams {
        &self.params
    }

    /// Sub-steps done so far.
    pub fn sub_step_count(&self) -> u64 {
        self.sub_step_count
    }

    /// Algorithm 2 steps 3(a)–(c) for all particles: ψ from eq 11 at time t, one batch call of the
    /// model, validation, propagators. Rotational coefficients for particles that have none.
    pub fn refresh_coefficients(
        &mut self,
        p: &mut Particles,
        flow: &dyn CarrierFlow,
        model: &dyn CoefficientModel,
        t: f64,
    ) -> Result<(), DynamicsError> {
        let n = p.len();
        let model_err = |index, field, value, allowed| DynamicsError::Coefficient {
            model: model.name().to_string(),
            index,
            field,
            value,
            allowed,
        };
        if p.n_rot < n {
            let from = p.n_rot;
            model.rotational(&p.shape[from..], &mut p.rot[from..]);
            for i in from..n {
                let r = p.rot[i];
                if !(r.c_r.is_finite() && r.c_r > 0.0) {
                    return Err(model_err(i, "c_r", r.c_r, "finite and > 0"));
                }
                if !r.c_s.is_finite() {
                    return Err(model_err(i, "c_s", r.c_s, "finite"));
                }
            }
            // the coupling along the body x axis: C_p at ψ = 0 (see `Particles::coupling`)
            let zeros = vec![0.0; n - from];
            let mut at0 = vec![crate::coefficients::Translational::default(); n - from];
            model.translational(&p.shape[from..], &zeros, &mut at0);
            for (k, c) in at0.iter().enumerate() {
                if !c.c_p.is_finite() {
                    return Err(model_err(from + k, "c_p", c.c_p, "finite"));
                }
                p.coupling[from + k] = c.c_p;
            }
            p.n_rot = n;
        }
        for i in 0..n {
            let f = flow.velocity([p.x[i], p.y[i]], t);
            let d = [f[0] - p.vx[i], f[1] - p.vy[i]];
            if d[0].hypot(d[1]) > self.params.psi_min_speed {
                p.dv_dir[i] = d[1].atan2(d[0]);
            } else if !p.dv_dir[i].is_finite() {
                // new particle in a relaxed state: the flow direction, or e_x in still fluid
                p.dv_dir[i] = if f[0].hypot(f[1]) > 0.0 { f[1].atan2(f[0]) } else { 0.0 };
            }
            // eq 11 with the last known direction of δv; within (−π, π] for the models
            p.psi[i] = wrap_angle(p.dv_dir[i] - p.phi[i]);
        }
        model.translational(&p.shape, &p.psi, &mut p.trans);
        for i in 0..n {
            let c = p.trans[i];
            if !(c.c_d.is_finite() && c.c_d > 0.0) {
                return Err(model_err(i, "c_d", c.c_d, "finite and > 0"));
            }
            if !c.c_l.is_finite() {
                return Err(model_err(i, "c_l", c.c_l, "finite"));
            }
            if !c.c_p.is_finite() {
                return Err(model_err(i, "c_p", c.c_p, "finite"));
            }
            if self.params.coupling && p.coupling[i] * p.coupling[i] >= c.c_d * p.rot[i].c_r {
                return Err(model_err(
                    i,
                    "c_p",
                    p.coupling[i],
                    "c_x^2 < c_d c_r with the coupling on (positive definite resistance matrix)",
                ));
            }
        }
        p.n_trans = n;
        let tau = self.params.sub_step;
        self.half.resize(n, Propagator::default());
        self.full.resize(n, Propagator::default());
        for i in 0..n {
            let (a, l, b) = (p.trans[i].c_d / p.mass[i], p.trans[i].c_l / p.mass[i], p.rot[i].c_r / p.inertia[i]);
            self.half[i] = Propagator::new(a, l, b, 0.5 * tau);
            self.full[i] = Propagator::new(a, l, b, tau);
        }
        if self.params.coupling {
            self.coupled_half.resize(n, CoupledPropagator::default());
            self.coupled_full.resize(n, CoupledPropagator::default());
            for i in 0..n {
                let body = Body {
                    m: p.mass[i],
                    i: p.inertia[i],
                    tr: p.trans[i],
                    rot: p.rot[i],
                    psi: p.psi[i],
                    c_x: p.coupling[i],
                };
                let singular = || model_err(i, "c_p", p.trans[i].c_p, "a nonsingular coupled resistance matrix");
                self.coupled_half[i] = CoupledPropagator::new(&body, 0.5 * tau).ok_or_else(singular)?;
                self.coupled_full[i] = self.coupled_half[i].doubled();
            }
        }
        Ok(())
    }

    /// One sub-step from time t (Algorithm 2 step 3): refresh if due, advect, collide.
    pub fn sub_step(
        &mut self,
        p: &mut Particles,
        flow: &dyn CarrierFlow,
        model: &dyn CoefficientModel,
        t: f64,
    ) -> Result<Timings, DynamicsError> {
        let mut tm = Timings::default();
        if !t.is_finite() {
            return Err(DynamicsError::Invalid { field: "t", value: t, allowed: "finite" });
        }
        p.check_lengths()?;
        let t0 = Instant::now();
        if self.sub_step_count.is_multiple_of(self.params.coeff_every as u64)
            || p.n_trans < p.len()
            || p.n_rot < p.len()
        {
            self.refresh_coefficients(p, flow, model, t)?;
        }
        let t1 = Instant::now();
        tm.coefficients = t1 - t0;
        let vmax = self.advect(p, flow, t)?;
        let t2 = Instant::now();
        tm.advection = t2 - t1;
        if self.params.collisions {
            let pairs = self.grid.find_pairs(&p.x, &p.y, &p.radius, vmax * self.params.sub_step);
            tm.pairs = pairs.len();
            let mut s = collide::CollisionState {
                x: &mut p.x,
                y: &mut p.y,
                vx: &mut p.vx,
                vy: &mut p.vy,
                m: &p.mass,
                r: &p.radius,
            };
            tm.impulses = collide::resolve(&mut s, &self.grid.pairs, self.params.restitution);
        }
        if flow.walls().is_some() {
            tm.wall_hits = collide::walls_local(&mut p.x, &mut p.y, &mut p.vx, &mut p.vy, |x| flow.local_walls(x));
        }
        tm.collisions = t2.elapsed();
        self.sub_step_count += 1;
        Ok(tm)
    }

    /// Algorithm 2 step 3 for one macro step from t0: M sub-steps. Checks the state first.
    pub fn macro_step(
        &mut self,
        p: &mut Particles,
        flow: &dyn CarrierFlow,
        model: &dyn CoefficientModel,
        t0: f64,
    ) -> Result<Timings, DynamicsError> {
        p.check_finite()?;
        let mut tm = Timings::default();
        if self.params.spatial_sort {
            let t0 = Instant::now();
            self.sort_spatially(p)?;
            tm.collisions += t0.elapsed();
        }
        for m in 0..self.params.sub_steps {
            tm += self.sub_step(p, flow, model, t0 + m as f64 * self.params.sub_step)?;
        }
        Ok(tm)
    }

    /// Reorders the particles by rows of cells of [`DynamicsParams::sort_cell`] (the cached
    /// propagators move along).
    pub fn sort_spatially(&mut self, p: &mut Particles) -> Result<(), DynamicsError> {
        let n = p.len();
        if n < 2 {
            return Ok(());
        }
        let cs = self.params.sort_cell;
        let x0 = p.x.iter().copied().fold(f64::MAX, f64::min);
        let y0 = p.y.iter().copied().fold(f64::MAX, f64::min);
        let mut keyed: Vec<(u64, u32)> = (0..n)
            .map(|i| {
                let cx = ((p.x[i] - x0) / cs).min(u32::MAX as f64) as u64;
                let cy = ((p.y[i] - y0) / cs).min(u32::MAX as f64) as u64;
                ((cy << 32) | cx, i as u32)
            })
            .collect();
        keyed.sort_unstable();
        let order: Vec<u32> = keyed.into_iter().map(|(_, i)| i).collect();
        p.permute(&order)?;
        fn apply<T: Copy>(v: &mut Vec<T>, order: &[u32]) {
            if v.len() == order.len() {
                let new: Vec<T> = order.iter().map(|&k| v[k as usize]).collect();
                *v = new;
            } else {
                v.clear();
            }
        }
        apply(&mut self.half, &order);
        apply(&mut self.full, &order);
        apply(&mut self.coupled_half, &order);
        apply(&mut self.coupled_full, &order);
        if self.half.len() != n || (self.params.coupling && self.coupled_half.len() != n) {
            // caches incomplete: refresh at the next sub-step
            p.n_trans = 0;
        }
        Ok(())
    }

    /// Integrates all particles over one sub-step; returns the largest speed (× √2).
    fn advect(&mut self, p: &mut Particles, flow: &dyn CarrierFlow, t: f64) -> Result<f64, DynamicsError> {
        let ro = ReadOnly {
            mass: &p.mass,
            inertia: &p.inertia,
            trans: &p.trans,
            rot: &p.rot,
            psi: &p.psi,
            coupling: &p.coupling,
            half: &self.half,
            full: &self.full,
            coupled_half: &self.coupled_half,
            coupled_full: &self.coupled_full,
        };
        let params = &self.params;
        let (vmax, ok) = match &self.pool {
            None => advect_chunk(
                params,
                flow,
                t,
                0,
                &ro,
                [&mut p.x, &mut p.y, &mut p.phi, &mut p.vx, &mut p.vy, &mut p.omega],
            )?,
            Some(pool) => {
                use rayon::prelude::*;
                let n = p.x.len();
                let cs = n.div_ceil(4 * pool.current_num_threads()).max(256);
                let results: Vec<Result<(f64, bool), DynamicsError>> = pool.install(|| {
                    p.x.par_chunks_mut(cs)
                        .zip(p.y.par_chunks_mut(cs))
                        .zip(p.phi.par_chunks_mut(cs))
                        .zip(p.vx.par_chunks_mut(cs))
                        .zip(p.vy.par_chunks_mut(cs))
                        .zip(p.omega.par_chunks_mut(cs))
                        .enumerate()
                        .map(|(k, (((((x, y), phi), vx), vy), om))| {
                            advect_chunk(params, flow, t, k * cs, &ro, [x, y, phi, vx, vy, om])
                        })
                        .collect()
                });
                let mut acc = (0.0f64, true);
                for r in results {
                    let (v, ok) = r?;
                    acc = (acc.0.max(v), acc.1 & ok);
                }
                acc
            }
        };
        if !ok {
            p.check_finite()?;
        }
        Ok(vmax * std::f64::consts::SQRT_2)
    }
}

/// The arrays advection reads.
struct ReadOnly<'a> {
    mass: &'a [f64],
    inertia: &'a [f64],
    trans: &'a [crate::coefficients::Translational],
    rot: &'a [crate::coefficients::Rotational],
    psi: &'a [f64],
    coupling: &'a [f64],
    half: &'a [Propagator],
    full: &'a [Propagator],
    coupled_half: &'a [CoupledPropagator],
    coupled_full: &'a [CoupledPropagator],
}

/// Advects particles `off..off + len` (the mutable slices: x, y, φ, V_x, V_y, Ω); returns the
/// largest velocity component and whether everything stayed finite. The serial and the parallel
/// runs call this same kernel per particle: same bits for any thread count.
fn advect_chunk(
    params: &DynamicsParams,
    flow: &dyn CarrierFlow,
    t: f64,
    off: usize,
    ro: &ReadOnly<'_>,
    rw: [&mut [f64]; 6],
) -> Result<(f64, bool), DynamicsError> {
    // (a Result for kernels that can fail; none does at present)
    let tau = params.sub_step;
    let coupled = params.coupling;
    let [xs, ys, phis, vxs, vys, oms] = rw;
    let mut vmax = 0.0f64;
    let mut ok = true;
    for l in 0..xs.len() {
        let i = off + l;
        let k = Kin { x: [xs[l], ys[l]], phi: phis[l], v: [vxs[l], vys[l]], omega: oms[l] };
        let b = Body {
            m: ro.mass[i],
            i: ro.inertia[i],
            tr: ro.trans[i],
            rot: ro.rot[i],
            psi: ro.psi[i],
            c_x: ro.coupling[i],
        };
        let f1 = flow.sample(k.x, t);
        let (s1, c1) = (2.0 * k.phi).sin_cos();
        let e1 = f1.body_strain_xy_sc(s1, c1);
        let new = match params.integrator {
            Integrator::ExplicitEuler => integrate::euler(&k, &b, tau, &f1, e1, coupled),
            Integrator::Exponential if !coupled => {
                let mid = integrate::relax_decoupled(&k, &b, &ro.half[i], 0.5 * tau, &f1, e1);
                let f2 = flow.sample(mid.x, t + 0.5 * tau);
                let (s2, c2) = sin_cos_near(2.0 * k.phi, s1, c1, 2.0 * (mid.phi - k.phi));
                let e2 = f2.body_strain_xy_sc(s2, c2);
                integrate::relax_decoupled(&k, &b, &ro.full[i], tau, &f2, e2)
            }
            Integrator::Exponential => {
                let mid = integrate::relax_coupled_cached(&k, &b, &ro.coupled_half[i], 0.5 * tau, &f1, e1, k.phi);
                let f2 = flow.sample(mid.x, t + 0.5 * tau);
                let (s2, c2) = sin_cos_near(2.0 * k.phi, s1, c1, 2.0 * (mid.phi - k.phi));
                let e2 = f2.body_strain_xy_sc(s2, c2);
                integrate::relax_coupled_cached(&k, &b, &ro.coupled_full[i], tau, &f2, e2, mid.phi)
            }
        };
        ok &= new.x[0].is_finite()
            & new.x[1].is_finite()
            & new.phi.is_finite()
            & new.v[0].is_finite()
            & new.v[1].is_finite()
            & new.omega.is_finite();
        vmax = vmax.max(new.v[0].abs().max(new.v[1].abs()));
        xs[l] = new.x[0];
        ys[l] = new.x[1];
        phis[l] = new.phi;
        vxs[l] = new.v[0];
        vys[l] = new.v[1];
        oms[l] = new.omega;
    }
    Ok((vmax, ok))
}

/// sin and cos of a + d from those of a, with a short series for small d (error below 2e-16
/// for |d| < 0.05), else directly.
#[inline]
fn sin_cos_near(a: f64, sa: f64, ca: f64, d: f64) -> (f64, f64) {
    if d.abs() < 0.05 {
        let d2 = d * d;
        let sd = d * (1.0 - d2 / 6.0 * (1.0 - d2 / 20.0 * (1.0 - d2 / 42.0)));
        let cd = 1.0 - d2 / 2.0 * (1.0 - d2 / 12.0 * (1.0 - d2 / 30.0 * (1.0 - d2 / 56.0)));
        (sa * cd + ca * sd, ca * cd - sa * sd)
    } else {
        (a + d).sin_cos()
    }
}

/// Angle in (−π, π].
pub fn wrap_angle(a: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    let w = a - TAU * (a / TAU).round();
    if w <= -PI {
        w + TAU
    } else {
        w
    }
}
