//! Test fixtures (feature `testkit`), shared by this crate's tests (`tests/stiff.rs`,
//! `channel.rs`, `operators.rs`, `fast_rhs.rs`), its examples and the stability matrix
//! (`sonoflow stability`): the stiff and extreme scenes of sph-validation.md §e, each run to its
//! measurement, and the error measures. The callers state the bounds. The scenes run the library
//! defaults ([`Scheme::Stabilised`]) but three, which run the paper's scheme their bars were set
//! for: the Taylor–Green vortex (with a given shifting coefficient), the flow reversal and the
//! hydrostatic tank (their `…_with` variants take the scheme). Test code: it panics where a scene
//! cannot be built as written.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::f64::consts::PI;
use std::sync::Arc;

use crate::setup::{ChannelConfig, OpenChannelConfig};
use crate::{
    BlowUpCriterion, BoxDomain, ParticleKind, Particles, Period, Real, Scheme, Solver, SphError, SphParams, StepReport,
    Waveform, WaveformSpec,
};

/// Reference density of every scene \[kg/m³\].
pub const RHO0: Real = 1000.0;
/// Kinematic viscosity of the validation channel \[m²/s\] (blood).
pub const NU: Real = 4e-6;

/// Deterministic uniform numbers in [-1, 1) (splitmix64): lattice jitter and disorder.
pub fn splitmix(seed: &mut u64) -> Real {
    *seed = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *seed;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    2.0 * ((z >> 11) as Real / (1u64 << 53) as Real) - 1.0
}

/// The validation open channel ([`OpenChannelConfig::validation`]) at sound speed `c` with
/// background pressure `background_pressure`, inflow `inflow`, started developed or at rest, with
/// `scheme`.
pub fn open_channel(
    inflow: Waveform,
    c: Real,
    background_pressure: Real,
    developed: bool,
    scheme: Scheme,
) -> Result<(OpenChannelConfig, Solver), SphError> {
    let cfg = OpenChannelConfig::validation(inflow, developed);
    let params = scheme.apply(SphParams { background_pressure, ..cfg.solver_params(c) });
    let (p, bs) = cfg.build();
    let s = Solver::new(params, p, 0.0)?.with_open_boundaries(bs)?;
    Ok((cfg, s))
}

/// max over rows k of |prof\[k\] − exact(z)| / scale, z = (k + 1) dx; NaN if any row is NaN.
pub fn profile_error(prof: &[Real], dx: Real, scale: Real, exact: impl Fn(Real) -> Real) -> Real {
    prof.iter().enumerate().map(|(k, u)| (u - exact((k + 1) as Real * dx)).abs() / scale).fold(0.0, |a, b| {
        if a.is_nan() || b.is_nan() {
            Real::NAN
        } else {
            a.max(b)
        }
    })
}

/// Mean vx of the fluid particles within dx/2 of depth `z` (and with x0 < x < x1 if `x_range` is
/// given); None if there are none.
pub fn row_mean_vx(p: &Particles, z: Real, dx: Real, x_range: Option<(Real, Real)>) -> Option<Real> {
    let (mut sum, mut n) = (0.0, 0usize);
    for i in 0..p.len() {
        let in_x = x_range.is_none_or(|(x0, x1)| p.x[i] > x0 && p.x[i] < x1);
        if p.kind[i] == ParticleKind::Fluid && (p.z[i] - z).abs() < 0.5 * dx && in_x {
            sum += p.vx[i];
            n += 1;
        }
    }
    (n > 0).then(|| sum / n as Real)
}

/// A steady validation channel (ū = 0.02 m/s, u_max = 0.03 m/s) at sound speed `c`, run
/// developed to `t_end` and one step more.
pub struct SteadyChannel {
    pub cfg: OpenChannelConfig,
    pub solver: Solver,
    /// The step after `t_end`.
    pub report: StepReport,
    /// The mid-channel profile ([`OpenChannelConfig::mid_profile`]).
    pub profile: Vec<Real>,
    /// Its largest deviation from Poiseuille, relative to u_max ([`profile_error`]).
    pub error: Real,
    /// The acoustic CFL step C_cfl h / (c + |u|max) after the step.
    pub cfl_dt: Real,
}

/// Runs [`SteadyChannel`].
pub fn steady_channel(c: Real, t_end: Real) -> Result<SteadyChannel, SphError> {
    let w = WaveformSpec::Constant { value: 0.02 }.build().expect("a constant waveform");
    let (cfg, mut solver) = open_channel(w, c, 0.0, true, Scheme::Stabilised)?;
    solver.advance_to(t_end)?;
    let report = solver.step(None)?;
    let profile = cfg.mid_profile(&solver.particles);
    let a = 0.5 * cfg.width;
    let error = profile_error(&profile, cfg.dx(), 0.03, |z| 0.03 * (1.0 - ((z - a) / a).powi(2)));
    let cfl_dt = solver.params().cfl * solver.params().h / (c + solver.diagnostics().max_speed);
    Ok(SteadyChannel { cfg, solver, report, profile, error, cfl_dt })
}

/// Taylor–Green vortex on an n × n lattice at Reynolds number `re`, c = 10 U, the paper's scheme
/// with shifting coefficient `shifting` (no δ-SPH; [`crate::setup::taylor_green`]).
pub fn taylor_green(n: usize, re: Real, shifting: Real) -> Result<Solver, SphError> {
    let (p, params) = crate::setup::taylor_green(n, re, 10.0, shifting);
    Solver::new(params, p, 0.0)
}

/// Advances `s` to 0.05, 0.10, … 0.05 `segments` s, stopping at the first error; returns the
/// smallest pair distance over the completed segments in units of `dx`, and the error.
pub fn advance_in_segments(s: &mut Solver, dx: Real, segments: usize) -> (Real, Option<SphError>) {
    let mut min_pair = Real::INFINITY;
    for j in 1..=segments {
        if let Err(e) = s.advance_to(0.05 * j as Real) {
            return (min_pair, Some(e));
        }
        min_pair = min_pair.min(s.diagnostics().min_pair_distance / dx);
    }
    (min_pair, None)
}

/// Kinetic energy decay of a Taylor–Green vortex: (E(t)/E₀, the exact e^{−16π² t/Re}).
pub fn taylor_green_decay(s: &Solver, e0: Real, t: Real, re: Real) -> (Real, Real) {
    (s.diagnostics().kinetic_energy / e0, (-16.0 * PI * PI * t / re).exp())
}

/// Mean velocity +0.02 → −0.02 m/s over 20 ms centred on `t0` (back up at t0 + 0.1 s), period
/// 0.2 s, as trigonometric interpolation of 400 samples.
pub fn reversing(t0: Real) -> Waveform {
    let (period, n) = (0.2, 400);
    let edge = |t: Real, c: Real| -> Real {
        let q = ((t - c) / 0.02 + 0.5).clamp(0.0, 1.0);
        0.5 - 0.5 * (PI * q).cos()
    };
    let v: Vec<Real> = (0..n)
        .map(|j| j as Real * period / n as Real)
        .map(|t| 0.02 - 0.04 * (edge(t, t0) - edge(t, t0 + 0.1)))
        .collect();
    WaveformSpec::Samples { period, values: v }.build().expect("a valid sampled waveform")
}

/// What a flow-reversal run measured across the reversal.
#[derive(Clone, Debug, PartialEq)]
pub struct Reversal {
    /// Worst profile error against the Womersley solution, relative to 0.03 m/s (NaN if any is).
    pub worst: Real,
    /// Smallest gauge pressure c² (ρ − ρ₀) of a fluid particle \[Pa\].
    pub min_gauge_pressure: Real,
    /// Smallest pair distance in units of dx.
    pub min_pair: Real,
    /// The last time checked \[s\].
    pub t_last: Real,
}

/// The validation channel driven by `w` (developed start) at sound speed `c` with background
/// pressure `pb`, checked at t = first, first + 5 ms, … (`n` times); the paper's scheme (the bars
/// of `tests/stiff.rs` and the stability matrix were set for it; [`reversal_with`] takes the scheme).
pub fn reversal(w: &Waveform, c: Real, pb: Real, first: Real, n: usize) -> Result<Reversal, SphError> {
    reversal_with(w, c, pb, first, n, Scheme::Paper)
}

/// [`reversal`] with `scheme`.
pub fn reversal_with(
    w: &Waveform,
    c: Real,
    pb: Real,
    first: Real,
    n: usize,
    scheme: Scheme,
) -> Result<Reversal, SphError> {
    let (cfg, mut s) = open_channel(w.clone(), c, pb, true, scheme)?;
    let a = 0.5 * cfg.width;
    let (mut worst, mut pmin, mut min_pair): (Real, Real, Real) = (0.0, Real::INFINITY, Real::INFINITY);
    for j in 0..n {
        let t = first + 0.005 * j as Real;
        s.advance_to(t)?;
        let prof = cfg.mid_profile(&s.particles);
        let e = profile_error(&prof, cfg.dx(), 0.03, |z| crate::womersley::profile_velocity(w, z - a, t, a, NU));
        worst = if e.is_nan() || worst.is_nan() { Real::NAN } else { worst.max(e) };
        min_pair = min_pair.min(s.diagnostics().min_pair_distance / cfg.dx());
        let p = &s.particles;
        for i in 0..p.len() {
            if p.kind[i] == ParticleKind::Fluid {
                pmin = pmin.min(c * c * (p.rho[i] - RHO0));
            }
        }
    }
    Ok(Reversal { worst, min_gauge_pressure: pmin, min_pair, t_last: first + 0.005 * (n - 1) as Real })
}

/// What the hydrostatic tank measured.
#[derive(Clone, Debug, PartialEq)]
pub struct Hydrostatic {
    /// √(gH) \[m/s\].
    pub u_ref: Real,
    /// Largest speed after each tenth of the run \[m/s\].
    pub peak_speed: Real,
    /// Largest speed at the end \[m/s\].
    pub final_speed: Real,
    /// Largest kinetic energy after each tenth of the run, and at the end.
    pub peak_ke: Real,
    pub final_ke: Real,
    /// Mean gauge pressure of the deepest fluid row, and ρ₀ g z there \[Pa\].
    pub p_bottom: Real,
    pub p_expected: Real,
    /// The same for the shallowest fluid row (one spacing below the lid).
    pub p_top: Real,
    pub p_top_expected: Real,
    /// Fluid particles outside the box at the end.
    pub outside: usize,
    /// Times the anti-penetration guard fired.
    pub guard_corrections: u64,
}

/// Closed 2 × 2 mm box full of fluid under gravity g = 9.81 m/s² (+z is down), 20 × 20 lattice,
/// c = 10 √(gH), hydrostatic initial density (free level at z = 0, the lid), run to
/// `units` √(H/g) in ten segments; the paper's scheme (the bars of `tests/stiff.rs` and the
/// stability matrix were set for it; [`hydrostatic_tank_with`] takes the scheme).
pub fn hydrostatic_tank(units: Real) -> Result<Hydrostatic, SphError> {
    hydrostatic_tank_with(units, Scheme::Paper)
}

impl Hydrostatic {
    /// The pressure difference between the deepest and the shallowest fluid row over its
    /// hydrostatic value ρ₀ g Δz: 1 when the pressure balances gravity, whatever the level.
    pub fn gradient_ratio(&self) -> Real {
        (self.p_bottom - self.p_top) / (self.p_expected - self.p_top_expected)
    }
}

/// [`hydrostatic_tank`] with `scheme`.
pub fn hydrostatic_tank_with(units: Real, scheme: Scheme) -> Result<Hydrostatic, SphError> {
    hydrostatic_tank_tuned(units, |p| scheme.apply(p))
}

/// [`hydrostatic_tank`] with the parameters (the paper's scheme's) changed by `tune`.
pub fn hydrostatic_tank_tuned(units: Real, tune: impl FnOnce(SphParams) -> SphParams) -> Result<Hydrostatic, SphError> {
    let (hgt, n, g) = (2e-3, 20i64, 9.81);
    let dx = hgt / n as Real;
    let c = 10.0 * (g * hgt).sqrt();
    let mut p = Particles::default();
    let mut id = 0u64;
    let lay = 3i64;
    for j in -lay..=n + lay {
        for i in -lay..=n + lay {
            let (x, z) = (i as Real * dx, j as Real * dx);
            let inside = (1..n).contains(&i) && (1..n).contains(&j);
            let on = !inside && (0..=n).contains(&i) && (0..=n).contains(&j);
            let kind = if inside {
                ParticleKind::Fluid
            } else if on {
                ParticleKind::WallOn
            } else {
                ParticleKind::WallOutside
            };
            // hydrostatic: p = ρ₀ g z, ρ = ρ₀ + p/c²
            let rho = RHO0 + RHO0 * g * z.clamp(0.0, hgt) / (c * c);
            p.push(x, z, 0.0, 0.0, rho, RHO0 * dx * dx, kind, id);
            id += 1;
        }
    }
    let params = tune(SphParams {
        h: 1.2 * dx,
        rho0: RHO0,
        c,
        mu: 1e-3,
        body_force: [0.0, g],
        dt_max: 1.0,
        ..Scheme::Paper.params()
    });
    let mut s = Solver::new(params, p, 0.0)?.with_domain(Arc::new(BoxDomain { min: [0.0, 0.0], max: [hgt, hgt] }));
    let t_end = units * (hgt / g).sqrt();
    let (mut vmax, mut ke_peak): (Real, Real) = (0.0, 0.0);
    for j in 1..=10 {
        s.advance_to(t_end * j as Real / 10.0)?;
        let d = s.diagnostics();
        vmax = vmax.max(d.max_speed);
        ke_peak = ke_peak.max(d.kinetic_energy);
    }
    let d = s.diagnostics();
    let pt = &s.particles;
    let zb = (n - 1) as Real * dx;
    let (mut sum, mut cnt, mut outside) = (0.0, 0usize, 0usize);
    let (mut sum_top, mut cnt_top) = (0.0, 0usize);
    for i in 0..pt.len() {
        if pt.kind[i] == ParticleKind::Fluid {
            if (pt.z[i] - zb).abs() < 0.5 * dx {
                sum += c * c * (pt.rho[i] - RHO0);
                cnt += 1;
            }
            if (pt.z[i] - dx).abs() < 0.5 * dx {
                sum_top += c * c * (pt.rho[i] - RHO0);
                cnt_top += 1;
            }
            if !(pt.x[i] > 0.0 && pt.x[i] < hgt && pt.z[i] > 0.0 && pt.z[i] < hgt) {
                outside += 1;
            }
        }
    }
    Ok(Hydrostatic {
        u_ref: (g * hgt).sqrt(),
        peak_speed: vmax,
        final_speed: d.max_speed,
        peak_ke: ke_peak,
        final_ke: d.kinetic_energy,
        p_bottom: sum / cnt as Real,
        p_expected: RHO0 * g * zb,
        p_top: sum_top / cnt_top as Real,
        p_top_expected: RHO0 * g * dx,
        outside,
        guard_corrections: d.guard_corrections,
    })
}

/// Plane channel between plates: 1 mm wide, `n_across` spacings across, 12 along, 3 wall layers,
/// top plate moving at `top` m/s; ρ₀ = 1000 kg/m³, μ = 1e-3 Pa s (ν = 1e-6 m²/s), h = 1.2 dx,
/// c = 1e-2 m/s, periodic in x, no dt cap, no body force.
pub fn plate_channel(n_across: usize, top: Real) -> (ChannelConfig, SphParams) {
    let cfg = ChannelConfig { width: 1e-3, n_across, n_along: 12, wall_layers: 3, rho0: RHO0, top_wall_velocity: top };
    let params = SphParams {
        h: 1.2 * cfg.dx(),
        rho0: RHO0,
        // Morris' criterion c² ≥ F L / δ with F = 2e-4, δ = 0.01 gives 4.5e-3 m/s (Ma = 2.5e-3).
        c: 1e-2,
        mu: 1e-3,
        periodic_x: Some(Period { min: 0.0, length: cfg.length() }),
        dt_max: 1.0,
        ..Default::default()
    };
    (cfg, params)
}

/// The plate channel (10 across, plates at rest) with a far too small sound speed for its body
/// force (c = 1e-5 m/s against 2e-4 m/s² along x and 5 m/s² across; density error limit 5 %).
pub fn far_too_small_c() -> Result<Solver, SphError> {
    let (cfg, params) = plate_channel(10, 0.0);
    let params = SphParams { c: 1e-5, body_force: [2e-4, -5.0], density_error_limit: 0.05, ..params };
    Solver::new(params, cfg.build(), 0.0)
}

/// What the anti-penetration guard did to a particle pushed through a wall.
#[derive(Clone, Debug, PartialEq)]
pub struct GuardRun {
    /// The particle's id, and the lattice spacing \[m\].
    pub id: u64,
    pub dx: Real,
    /// Its z and vz after four steps (the guard runs every 4th step).
    pub z: Real,
    pub vz: Real,
    /// Guard corrections counted.
    pub corrections: u64,
}

/// A fluid particle of the plate channel placed 0.3 dx outside the bottom wall moving outwards
/// (what a too-large step does), then four steps.
pub fn guard_run() -> Result<GuardRun, SphError> {
    let (cfg, params) = plate_channel(10, 0.0);
    let dx = cfg.dx();
    let mut p = cfg.build();
    let i = (0..p.len()).find(|&i| p.kind[i] == ParticleKind::Fluid).expect("the channel has fluid");
    p.z[i] = -0.3 * dx;
    p.vz[i] = -1e-4;
    let id = p.id[i];
    let mut s = Solver::new(params, p, 0.0)?.with_domain(Arc::new(BoxDomain { min: [0.0, 0.0], max: [1.0, 1e-3] }));
    for _ in 0..4 {
        s.step(None)?;
    }
    let j = s.particles.id.iter().position(|&k| k == id).expect("the particle is still there");
    Ok(GuardRun { id, dx, z: s.particles.z[j], vz: s.particles.vz[j], corrections: s.diagnostics().guard_corrections })
}

/// The validation channel started at rest with reservoirs imposing 0.02 m/s at 20 Hz from t = 0
/// (|dū/dt| = 2.5 m/s²; Morris' criterion asks c ≥ 1 m/s) at sound speed `c`.
pub fn impulsive_start(c: Real) -> Result<Solver, SphError> {
    let w = WaveformSpec::Cosine { amplitude: 0.02, period: 0.05, phase: 0.0, offset: 0.0 }.build().expect("valid");
    Ok(open_channel(w, c, 0.0, false, Scheme::Stabilised)?.1)
}

/// Whether `e` is a density-error blow-up before `t`.
pub fn is_density_blow_up_before(e: &SphError, t: Real) -> bool {
    matches!(e, SphError::BlowUp { criterion: BlowUpCriterion::DensityError { .. }, time, .. } if *time < t)
}

/// The plate channel (10 across, plates at rest) run to 1 ms, then a NaN velocity written into
/// its first fluid particle; returns the solver and that particle's index.
pub fn injected_nan() -> Result<(Solver, usize), SphError> {
    let (cfg, params) = plate_channel(10, 0.0);
    let mut s = Solver::new(params, cfg.build(), 0.0)?;
    s.advance_to(1e-3)?;
    let i = (0..s.particles.len()).find(|&i| s.particles.kind[i] == ParticleKind::Fluid).expect("fluid");
    s.particles.vx[i] = Real::NAN;
    Ok((s, i))
}

/// Distance from particle index `i` to the particle with id `id` (None if there is none).
pub fn distance_to_id(s: &Solver, i: usize, id: u64) -> Option<Real> {
    let p = &s.particles;
    let k = p.id.iter().position(|&q| q == id)?;
    Some((p.x[k] - p.x[i]).hypot(p.z[k] - p.z[i]))
}
