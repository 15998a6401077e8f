//! Particle set-ups for validation cases: plane channels (periodic, open), the Taylor–Green vortex,
//! the lid-driven cavity (a closed box with its wall-domain guard).

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

/// Plane channel between plates z = 0 and z = `width` from x = 0 to x = `length`, with an inflow
/// reservoir at x < 0 (opening at x = 0, normal −x) and an outflow reservoir at x > `length`
/// (normal +x), both `depth` deep; the plates (type I on them, type II layers outside) run over the
/// reservoirs too. The inlet imposes the mean velocity `inflow(t)` (into the domain, +x), the outlet
/// the same flow rate leaving (mean inward velocity −inflow). Lattice rows at z = j dx, columns at
/// x = (i − ½) dx, so the reservoirs continue the lattice without a seam.
#[derive(Clone, Debug, PartialEq)]
pub struct OpenChannelConfig {
    /// Plate separation L \[m\].
    pub width: Real,
    /// dx = L / `n_across`.
    pub n_across: usize,
    /// Number of lattice columns between the openings (length = `n_along` · dx).
    pub n_along: usize,
    /// Layers of type II particles outside each plate.
    pub wall_layers: usize,
    /// Reservoir depth in lattice spacings.
    pub reservoir_columns: usize,
    /// Reference density ρ₀ \[kg/m³\]; mass = ρ₀ dx².
    pub rho0: Real,
    /// Kinematic viscosity ν \[m²/s\] (for the imposed Womersley profile).
    pub nu: Real,
    /// Cross-section mean velocity through the inlet \[m/s\].
    pub inflow: crate::waveform::Waveform,
    /// Profile across the openings.
    pub profile: crate::boundary::ProfileKind,
    /// Start the fluid with the fully developed profile at t = 0 (else at rest).
    pub developed: bool,
}

impl OpenChannelConfig {
    /// Lattice spacing \[m\].
    pub fn dx(&self) -> Real {
        self.width / self.n_across as Real
    }

    /// Distance between the openings \[m\].
    pub fn length(&self) -> Real {
        self.n_along as Real * self.dx()
    }

    /// The two open boundaries (inlet first).
    pub fn boundaries(&self) -> Vec<crate::boundary::OpenBoundary> {
        let (dx, a) = (self.dx(), 0.5 * self.width);
        let depth = self.reservoir_columns as Real * dx;
        let mk = |name: &str, x: Real, nx: Real, inflow: crate::waveform::Waveform| crate::boundary::OpenBoundary {
            name: name.into(),
            origin: [x, a],
            normal: [nx, 0.0],
            half_width: a,
            depth,
            dx,
            inflow,
            profile: self.profile,
            ramp_time: 0.0,
        };
        vec![mk("inlet", 0.0, -1.0, self.inflow.clone()), mk("outlet", self.length(), 1.0, self.inflow.scaled(-1.0))]
    }

    /// The validation channel of the tests and the stability matrix: L = 2 mm, 20 spacings across
    /// (dx = 0.1 mm), 4 mm between the openings, 3 wall layers, reservoirs 4 dx deep (support 3 dx
    /// at h = 1.2 dx), ρ₀ = 1000 kg/m³, ν = 4e-6 m²/s (blood), Womersley profiles.
    pub fn validation(inflow: crate::waveform::Waveform, developed: bool) -> Self {
        OpenChannelConfig {
            width: 2e-3,
            n_across: 20,
            n_along: 40,
            wall_layers: 3,
            reservoir_columns: 4,
            rho0: 1000.0,
            nu: 4e-6,
            inflow,
            profile: crate::boundary::ProfileKind::Womersley,
            developed,
        }
    }

    /// Solver parameters for this channel: h = 1.2 dx, its ρ₀ and μ = ρ₀ν, sound speed `c`, no
    /// dt cap; the rest default.
    pub fn solver_params(&self, c: Real) -> crate::params::SphParams {
        crate::params::SphParams {
            h: 1.2 * self.dx(),
            rho0: self.rho0,
            c,
            mu: self.nu * self.rho0,
            dt_max: 1.0,
            ..Default::default()
        }
    }

    /// Mean vx of the fluid particles of each lattice row j = 1 … n_across − 1 (|z − j dx| < dx/2)
    /// in the middle half of the channel (0 for an empty row).
    pub fn mid_profile(&self, p: &Particles) -> Vec<Real> {
        let dx = self.dx();
        let (lo, hi) = (0.25 * self.length(), 0.75 * self.length());
        let mut sum = vec![0.0; self.n_across + 1];
        let mut n = vec![0usize; self.n_across + 1];
        for i in 0..p.len() {
            if p.kind[i] == ParticleKind::Fluid && p.x[i] > lo && p.x[i] < hi {
                let row = (p.z[i] / dx).round();
                if row >= 1.0 && (row as usize) < self.n_across && (p.z[i] - row * dx).abs() < 0.5 * dx {
                    sum[row as usize] += p.vx[i];
                    n[row as usize] += 1;
                }
            }
        }
        (1..self.n_across).map(|r| sum[r] / n[r].max(1) as Real).collect()
    }

    /// Builds fluid, walls and filled reservoirs; returns the particles and the boundaries.
    pub fn build(&self) -> (Particles, Vec<crate::boundary::OpenBoundary>) {
        let dx = self.dx();
        let a = 0.5 * self.width;
        let m = self.rho0 * dx * dx;
        let mut p = Particles::default();
        let mut id = 0u64;
        let n = self.n_across as i64;
        let lay = self.wall_layers as i64;
        let res = self.reservoir_columns as i64;
        // walls over the whole length including the reservoirs
        for j in (-lay..=0).chain(n..=n + lay) {
            let kind = if j == 0 || j == n { ParticleKind::WallOn } else { ParticleKind::WallOutside };
            for i in -res..self.n_along as i64 + res {
                p.push((i as Real + 0.5) * dx, j as Real * dx, 0.0, 0.0, self.rho0, m, kind, id);
                id += 1;
            }
        }
        let mut table = crate::womersley::ProfileTable::new(&self.inflow, a, self.nu, 257, false);
        table.set_time(0.0);
        for j in 1..n {
            for i in 0..self.n_along {
                let z = j as Real * dx;
                let u = if self.developed { table.at(z - a) } else { 0.0 };
                p.push((i as Real + 0.5) * dx, z, u, 0.0, self.rho0, m, ParticleKind::Fluid, id);
                id += 1;
            }
        }
        let bs = self.boundaries();
        for (k, b) in bs.iter().enumerate() {
            let r = b.fill(k as u16, self.rho0, self.nu, 0.0, &mut id);
            p.append(&r);
        }
        (p, bs)
    }
}

/// Lid-driven square cavity: a closed box [0, L]² (x, z) of fluid at rest, driven by its lid
/// z = L sliding along +x at U (a wall velocity: the wall particles stay put), Reynolds number
/// Re = U L / ν. The benchmark of Ghia, Ghia & Shin (1982) with y = z.
///
/// Particles on the square lattice of spacing dx = L/n through the corner (0, 0): fluid at the
/// (n − 1)² interior nodes (i dx, j dx), i, j = 1 … n − 1 (one spacing from every wall, where a
/// wall row gives the full kernel sum); type I wall particles on the four sides (i or j = 0 or n),
/// `wall_layers` rows of type II outside them, corners filled. The lid is every wall particle with
/// z ≥ L (over the side walls' layers too), velocity (U, 0); the other walls are at rest. ρ = ρ₀,
/// m = ρ₀ dx². Build it with [`CavityConfig::build`], run it with [`CavityConfig::solver`] (the
/// anti-penetration guard on [`CavityConfig::domain`]: a fluid particle that crosses a wall is
/// put back and counted in [`crate::Diagnostics::guard_corrections`], and
/// [`CavityConfig::fluid_outside`] counts the ones outside the box now).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CavityConfig {
    /// Side L \[m\], > 0.
    pub side: Real,
    /// Lid velocity U along +x \[m/s\], > 0.
    pub lid_velocity: Real,
    /// Reynolds number U L / ν, > 0.
    pub reynolds: Real,
    /// Lattice spacings per side (dx = L / n), ≥ 4.
    pub n: usize,
    /// Type II layers outside each wall, ≥ 1 (they must cover the kernel support minus one spacing).
    pub wall_layers: usize,
    /// Reference density ρ₀ \[kg/m³\], > 0.
    pub rho0: Real,
    /// Sound speed c \[m/s\], > 0.
    pub sound_speed: Real,
    /// Smoothing length h in lattice spacings.
    pub h_over_dx: Real,
}

impl CavityConfig {
    /// A cavity of side L with lid velocity U at Reynolds number `reynolds`, n spacings per side,
    /// with ρ₀ = 1000 kg/m³, c = 10 U (Mach 0.1: ~1 % density variation), h = 1.2 dx and wall layers
    /// covering the default kernel's support (3 at h = 1.2 dx).
    pub fn new(side: Real, lid_velocity: Real, reynolds: Real, n: usize) -> Self {
        let h_over_dx = 1.2;
        let support = crate::kernel::KernelKind::default().support_factor() * h_over_dx;
        CavityConfig {
            side,
            lid_velocity,
            reynolds,
            n,
            wall_layers: support.ceil() as usize,
            rho0: 1000.0,
            sound_speed: 10.0 * lid_velocity,
            h_over_dx,
        }
    }

    /// Lattice spacing dx = L / n \[m\].
    pub fn dx(&self) -> Real {
        self.side / self.n as Real
    }

    /// Kinematic viscosity ν = U L / Re \[m²/s\].
    pub fn nu(&self) -> Real {
        self.lid_velocity * self.side / self.reynolds
    }

    /// The convective time unit L / U \[s\].
    pub fn time_unit(&self) -> Real {
        self.side / self.lid_velocity
    }

    /// Checks the fields; the error names the first bad one.
    pub fn validate(&self) -> Result<(), crate::params::ParamError> {
        let bad = |field: &'static str, value: String, allowed: &str| {
            Err(crate::params::ParamError { field, value, allowed: allowed.into() })
        };
        let positive = [
            ("side", self.side),
            ("lid_velocity", self.lid_velocity),
            ("reynolds", self.reynolds),
            ("rho0", self.rho0),
            ("sound_speed", self.sound_speed),
            ("h_over_dx", self.h_over_dx),
        ];
        for (field, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return bad(field, v.to_string(), "finite and > 0");
            }
        }
        if self.n < 4 {
            return bad("n", self.n.to_string(), "n >= 4");
        }
        if self.wall_layers < 1 {
            return bad("wall_layers", self.wall_layers.to_string(), "wall_layers >= 1");
        }
        Ok(())
    }

    /// Solver parameters: the library defaults ([`crate::SphParams::default`]) with h = `h_over_dx`
    /// dx, ρ₀, c and μ = ρ₀ U L / Re, dt cap L / U (none in effect).
    pub fn solver_params(&self) -> crate::params::SphParams {
        crate::params::SphParams {
            h: self.h_over_dx * self.dx(),
            rho0: self.rho0,
            c: self.sound_speed,
            mu: self.rho0 * self.nu(),
            dt_max: self.time_unit(),
            ..Default::default()
        }
    }

    /// The particles (see [`CavityConfig`]); ids: row by row from the bottom layer.
    pub fn build(&self) -> Particles {
        let (dx, n, lay) = (self.dx(), self.n as i64, self.wall_layers as i64);
        let m = self.rho0 * dx * dx;
        let mut p = Particles::default();
        let mut id = 0u64;
        for j in -lay..=n + lay {
            for i in -lay..=n + lay {
                let fluid = (1..n).contains(&i) && (1..n).contains(&j);
                let on_wall = (0..=n).contains(&i) && (0..=n).contains(&j);
                let (kind, vx) = match (fluid, on_wall) {
                    (true, _) => (ParticleKind::Fluid, 0.0),
                    (false, on) => (
                        if on { ParticleKind::WallOn } else { ParticleKind::WallOutside },
                        if j >= n { self.lid_velocity } else { 0.0 },
                    ),
                };
                p.push(i as Real * dx, j as Real * dx, vx, 0.0, self.rho0, m, kind, id);
                id += 1;
            }
        }
        p
    }

    /// The fluid region [0, L]² for the anti-penetration guard.
    pub fn domain(&self) -> crate::walls::BoxDomain {
        crate::walls::BoxDomain { min: [0.0, 0.0], max: [self.side, self.side] }
    }

    /// A solver on [`CavityConfig::build`] at t = 0 with `params` (normally
    /// [`CavityConfig::solver_params`], possibly changed) and the guard on [`CavityConfig::domain`].
    /// Errors: a bad field of the cavity (as [`crate::SphError::Params`]), bad `params`, or wall
    /// layers that do not cover the kernel support of `params` (one spacing short is allowed: the
    /// first fluid row is one spacing inside).
    pub fn solver(&self, params: crate::params::SphParams) -> Result<crate::Solver, crate::SphError> {
        self.validate()?;
        let support = params.kernel.support_factor() * params.h;
        if (self.wall_layers + 1) as Real * self.dx() < support * (1.0 - 1e-9) {
            return Err(crate::SphError::State(format!(
                "cavity: {} wall layers of {} m do not cover the kernel support {} m (one spacing short is allowed)",
                self.wall_layers,
                self.dx(),
                support
            )));
        }
        Ok(crate::Solver::new(params, self.build(), 0.0)?.with_domain(std::sync::Arc::new(self.domain())))
    }

    /// Fluid particles outside [0, L]² now (0 while the walls hold; the guard puts leaks back
    /// every 4th step, so this counts the ones of the last few steps).
    pub fn fluid_outside(&self, p: &Particles) -> usize {
        (0..p.len())
            .filter(|&i| {
                p.kind[i].is_fluid() && !(p.x[i] >= 0.0 && p.x[i] <= self.side && p.z[i] >= 0.0 && p.z[i] <= self.side)
            })
            .count()
    }
}

/// Taylor–Green vortex on [0, L]², periodic in x and z (sph-validation.md §d), L = 1, U = 1, ρ₀ = 1:
/// u = −U cos kx sin kz, w = U sin kx cos kz, p = −ρU²/4 (cos 2kx + cos 2kz), density ρ₀ + p/c²,
/// on an n × n lattice. Returns the particles and the parameters: the paper's scheme
/// ([`crate::SphParams::paper_scheme`]: no δ-SPH) with shifting coefficient `shifting`, h = 1.2 dx,
/// μ = ρ₀UL/Re, sound speed `c`; the exact |u| decays as e^{−8π² t/Re}.
pub fn taylor_green(n: usize, re: Real, c: Real, shifting: Real) -> (Particles, crate::params::SphParams) {
    use crate::neighbours::Period;
    let (l, u0, rho0) = (1.0, 1.0, 1.0);
    let dx = l / n as Real;
    let k = 2.0 * std::f64::consts::PI / l;
    let mut p = Particles::default();
    for j in 0..n {
        for i in 0..n {
            let (x, z) = ((i as Real + 0.5) * dx, (j as Real + 0.5) * dx);
            let pr = -rho0 * u0 * u0 / 4.0 * ((2.0 * k * x).cos() + (2.0 * k * z).cos());
            let (ux, uz) = (-u0 * (k * x).cos() * (k * z).sin(), u0 * (k * x).sin() * (k * z).cos());
            p.push(x, z, ux, uz, rho0 + pr / (c * c), rho0 * dx * dx, ParticleKind::Fluid, (j * n + i) as u64);
        }
    }
    let params = crate::params::SphParams {
        h: 1.2 * dx,
        rho0,
        c,
        mu: rho0 * u0 * l / re,
        shifting,
        periodic_x: Some(Period { min: 0.0, length: l }),
        periodic_z: Some(Period { min: 0.0, length: l }),
        dt_max: 1.0,
        ..crate::params::SphParams::paper_scheme()
    };
    (p, params)
}
