//! Fast evaluation of the WCSPH right-hand sides: the same equations as
//! [`crate::wcsph::compute_rates`] (Shahriari & Garcia 2018, eq 7, 8, 10, 12 or Morris et al. 1997,
//! the wall particles of §2.2, δ-SPH diffusion and the shifting sums), the reference being kept as
//! the twin this module is tested against (`tests/fast_rhs.rs`).
//!
//! Design (see `PERF.md`):
//! * particles are sorted by cell once per evaluation into scratch arrays (the solver's order is
//!   untouched; results are scattered back), with the per-particle quantities of the pair terms
//!   precomputed in f32: velocities, m p/ρ², m, m/ρ, ρ − ρ₀;
//! * per cell, the neighbour cells (3 contiguous runs of the sorted order, more where a periodic
//!   axis wraps) are copied into one buffer with positions relative to the cell centre, in units
//!   of h, as f32 (exact minimum image: the periodic shift is applied per run, in f64);
//! * each particle of the cell runs over the buffer 8 candidates at a time with no branch
//!   ([`kernels`]), in f32 with fused multiply-adds; the 8 lanes of every sum are added in f64 and
//!   the constants (σ/h³, C μ/ρ_a, …) applied in f64;
//! * the lanes are AVX2 + FMA registers where the CPU has them (runtime detection), else a portable
//!   array type with the same IEEE operations: both give the same bits (tested);
//! * cells are processed in blocks on rayon threads (`params.parallel`); every particle's result
//!   depends only on the data, never on the blocks or threads: bit-identical for any thread count.
//!
//! Precision: positions relative to the cell centre are ≤ 1.5 cells ≈ 4 h, so their f32 rounding
//! is ≤ 2.4e-7 h; every pair term is then correct to a few 1e-7 of itself, and a rate to about
//! 1e-6 of Σ|terms| (f32 lane sums of ≤ ~12 terms, f64 across lanes). Rates that are a small
//! difference of large terms (a large background pressure) lose that relative accuracy; see
//! `PERF.md`.

mod grid;
mod kernels;
mod lanes;

use grid::Grid;
use kernels::{Cubic, Frames, Pos, Quartic, RateConsts, RatesIn, Scratch, Shape, WallIn, Wendland, PAD};
use lanes::{Lanes, Portable};

use crate::kernel::{Kernel, KernelKind};
use crate::neighbours::CellList;
use crate::params::{SphParams, ViscousTerm};
use crate::particles::{ParticleKind, Particles};
use crate::wcsph::{self, mean_value_constant, pressure, Rate, Workspace};
use crate::Real;

/// Which lanes the fast evaluator runs on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Backend {
    /// AVX2 + FMA where the CPU has them, else portable.
    #[default]
    Auto,
    /// The portable lanes (same bits as AVX2; for tests and comparisons).
    Portable,
}

/// Default cells per support radius of the fast grid (cells of side ≥ support / reach, neighbours
/// reach cells on each side): 2 runs ~30 % fewer candidate lanes than 1 (measured, `PERF.md`);
/// 3 has fewer lanes still but one particle per cell, and the per-cell work then dominates.
const REACH: usize = 2;
/// Blocks of cells handed to the threads hold at least this many particles.
const BLOCK_PARTICLES: usize = 384;

/// f32 channels of the sorted particles.
const UX: usize = 0;
const UZ: usize = 1;
const MP: usize = 2;
const M: usize = 3;
const V: usize = 4;
const DEV: usize = 5;
const VD: usize = 6;
const P: usize = 7;
const RHO: usize = 8;
const FL: usize = 9;
const NCH: usize = 10;

/// Caller-owned scratch of the fast evaluator (no allocation once warmed up, except one small
/// vector of block slices per pass).
#[derive(Clone, Debug, Default)]
pub struct FastWorkspace {
    grid: Grid,
    blocks: Vec<(usize, usize)>,
    /// x/h (f64) and its f32 hi and lo parts, z relative to the cell row centre / h.
    xoh: Vec<Real>,
    xh: Vec<f32>,
    xl: Vec<f32>,
    zr: Vec<f32>,
    kind: Vec<ParticleKind>,
    wall: Vec<bool>,
    rho: Vec<Real>,
    mass: Vec<Real>,
    /// ux, uz, m p/ρ², m, m/ρ, ρ − ρ₀, m/ρ of non-walls (0 for walls), p, ρ, non-wall flag.
    ch: [Vec<f32>; NCH],
    /// p/ρ².
    pr: Vec<f32>,
    wall_out: Vec<[Real; 4]>,
    rates: Vec<Rate>,
    frames: Frames,
    any_wall: bool,
    cells: CellList,
    /// Cells per support radius; 0 = [`REACH`].
    reach: usize,
}

thread_local! {
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::new(Scratch::default());
}

/// [`crate::wcsph::compute_rates`] computed by the fast evaluator: same outputs (`ws.ux`, `uz`, `p`,
/// `rho`, `rates`) to f32 accuracy (see the module doc), with its own cell grid at the kernel support
/// (no [`CellList`] needed). Falls back to the reference where the fast grid does not apply (a
/// periodic axis shorter than 2 `REACH` + 1 cells, impossible with validated parameters).
pub fn compute_rates(
    params: &SphParams,
    kernel: &Kernel,
    particles: &Particles,
    g: [Real; 2],
    ws: &mut Workspace,
    fws: &mut FastWorkspace,
) {
    compute_rates_with(params, kernel, particles, g, ws, fws, Backend::Auto);
}

/// [`compute_rates`] on the chosen lanes.
pub fn compute_rates_with(
    params: &SphParams,
    kernel: &Kernel,
    particles: &Particles,
    g: [Real; 2],
    ws: &mut Workspace,
    fws: &mut FastWorkspace,
    backend: Backend,
) {
    let support = kernel.support_radius();
    let (px, pz) = (params.periodic_x, params.periodic_z);
    let reach = fws.reach();
    if particles.is_empty() || !fws.grid.build(&particles.x, &particles.z, support, reach, px, pz) {
        fws.cells.build(&particles.x, &particles.z, support, px, pz);
        wcsph::compute_rates(params, kernel, particles, &fws.cells, g, ws);
        return;
    }
    let avx = backend == Backend::Auto && avx_available();
    fws.sort(params, kernel, particles);
    if fws.any_wall {
        fws.wall_pass(params, kernel, particles, g, avx);
    }
    fws.rate_pass(params, kernel, g, avx);
    fws.scatter(params, particles, ws);
}

#[cfg(target_arch = "x86_64")]
fn avx_available() -> bool {
    lanes::Avx::available()
}

#[cfg(not(target_arch = "x86_64"))]
fn avx_available() -> bool {
    false
}

/// Runs `f(c0, c1, out)` on every block of cells with its slice of `out` (sorted order).
fn for_blocks<T: Send>(
    parallel: bool,
    grid: &Grid,
    blocks: &[(usize, usize)],
    out: &mut [T],
    f: impl Fn(usize, usize, &mut [T]) + Sync,
) {
    let mut slices = Vec::with_capacity(blocks.len());
    let mut rest = out;
    for &(c0, c1) in blocks {
        let len = grid.range(c1 - 1).1 - grid.range(c0).0;
        let (a, b) = std::mem::take(&mut rest).split_at_mut(len);
        slices.push(a);
        rest = b;
    }
    #[cfg(feature = "parallel")]
    if parallel {
        use rayon::prelude::*;
        blocks.par_iter().zip(slices).for_each(|(&(c0, c1), s)| f(c0, c1, s));
        return;
    }
    let _ = parallel;
    for (&(c0, c1), s) in blocks.iter().zip(slices) {
        f(c0, c1, s);
    }
}

impl FastWorkspace {
    /// A workspace whose grid has `reach` (clamped to 1..=4) cells per kernel support radius
    /// (default 2). The results differ between reaches only by rounding (the lanes are summed in
    /// another order); for a given reach they are bit-identical for any thread count.
    pub fn with_reach(reach: usize) -> Self {
        FastWorkspace { reach: reach.clamp(1, 4), ..Default::default() }
    }

    fn reach(&self) -> usize {
        if self.reach == 0 {
            REACH
        } else {
            self.reach
        }
    }

    /// Sorted, padded copies of the particle data with the per-particle quantities of the pair
    /// terms; blocks of cells.
    fn sort(&mut self, params: &SphParams, kernel: &Kernel, p: &Particles) {
        let n = p.len();
        let inv_h = 1.0 / kernel.h;
        for v in [&mut self.xh, &mut self.xl, &mut self.zr, &mut self.pr].into_iter().chain(&mut self.ch) {
            v.clear();
            v.resize(n + PAD, 0.0);
        }
        self.xoh.resize(n, 0.0);
        self.rho.resize(n, 0.0);
        self.mass.resize(n, 0.0);
        self.kind.resize(n, ParticleKind::Fluid);
        self.wall.resize(n, false);
        let grid = &self.grid;
        let nx = grid.ax.n;
        let [ux, uz, mp, m, v, dev, vd, pc, rc, fl] = &mut self.ch;
        for c in 0..grid.cells() {
            let (s, e) = grid.range(c);
            let zc = grid.az_centre(c / nx);
            for k in s..e {
                let i = grid.order[k] as usize;
                let (r, mk, kd) = (p.rho[i], p.mass[i], p.kind[i]);
                let xo = p.x[i] * inv_h;
                let hi = xo as f32;
                self.xoh[k] = xo;
                self.xh[k] = hi;
                self.xl[k] = (xo - hi as Real) as f32;
                self.zr[k] = ((p.z[i] - zc) * inv_h) as f32;
                self.rho[k] = r;
                self.mass[k] = mk;
                self.kind[k] = kd;
                let w = kd.is_wall();
                self.wall[k] = w;
                let pk = pressure(params, r);
                let prk = pk / (r * r);
                ux[k] = p.vx[i] as f32;
                uz[k] = p.vz[i] as f32;
                mp[k] = (mk * prk) as f32;
                m[k] = mk as f32;
                v[k] = (mk / r) as f32;
                dev[k] = (r - params.rho0) as f32;
                vd[k] = if w { 0.0 } else { v[k] };
                pc[k] = pk as f32;
                rc[k] = r as f32;
                fl[k] = if w { 0.0 } else { 1.0 };
                self.pr[k] = prk as f32;
            }
        }
        self.any_wall = self.wall.iter().any(|&w| w);
        self.frames = Frames::new(&self.grid, inv_h);
        self.blocks.clear();
        let (mut c0, mut count) = (0, 0);
        for c in 0..self.grid.cells() {
            let (s, e) = self.grid.range(c);
            count += e - s;
            if count >= BLOCK_PARTICLES {
                self.blocks.push((c0, c + 1));
                (c0, count) = (c + 1, 0);
            }
        }
        if c0 < self.grid.cells() {
            self.blocks.push((c0, self.grid.cells()));
        }
    }

    /// Wall particles' velocity, pressure and density, then their rate-pass channels.
    fn wall_pass(&mut self, params: &SphParams, kernel: &Kernel, p: &Particles, g: [Real; 2], avx: bool) {
        let n = self.xoh.len();
        self.wall_out.resize(n, [0.0; 4]);
        let inp = WallIn {
            pos: Pos { grid: &self.grid, xoh: &self.xoh, xh: &self.xh, xl: &self.xl, zr: &self.zr },
            frames: &self.frames,
            kind: &self.kind,
            ch: [&self.ch[UX], &self.ch[UZ], &self.ch[P], &self.ch[RHO], &self.ch[FL]],
            order: &self.grid.order,
            vx: &p.vx,
            vz: &p.vz,
            h: kernel.h,
            g,
            rho0: params.rho0,
            c2: params.c * params.c,
            pb: params.background_pressure,
        };
        let (par, b, out) = (params.parallel, &self.blocks[..], &mut self.wall_out[..]);
        match kernel.kind {
            KernelKind::QuarticSpline => wall_run::<Quartic>(&inp, par, avx, b, out),
            KernelKind::WendlandC2 => wall_run::<Wendland>(&inp, par, avx, b, out),
            KernelKind::CubicSpline => wall_run::<Cubic>(&inp, par, avx, b, out),
        }
        let [ux, uz, mp, _, v, dev, ..] = &mut self.ch;
        for k in 0..n {
            if self.wall[k] {
                let [u, w, pw, rw] = self.wall_out[k];
                let prk = pw / (rw * rw);
                ux[k] = u as f32;
                uz[k] = w as f32;
                mp[k] = (self.mass[k] * prk) as f32;
                v[k] = (self.mass[k] / rw) as f32;
                dev[k] = (rw - params.rho0) as f32;
                self.pr[k] = prk as f32;
                self.rho[k] = rw;
            }
        }
    }

    fn rate_pass(&mut self, params: &SphParams, kernel: &Kernel, g: [Real; 2], avx: bool) {
        let n = self.xoh.len();
        self.rates.resize(n, Rate::default());
        let h = kernel.h;
        let kind = kernel.kind;
        let ds = match kind {
            KernelKind::QuarticSpline => Quartic::DS,
            KernelKind::WendlandC2 => Wendland::DS,
            KernelKind::CubicSpline => Cubic::DS,
        };
        let f_scalar: fn(Real) -> Real = match kind {
            KernelKind::QuarticSpline => |q| KernelKind::QuarticSpline.shape(q).0 / Quartic::FS,
            KernelKind::WendlandC2 => |q| KernelKind::WendlandC2.shape(q).0 / Wendland::FS,
            KernelKind::CubicSpline => |q| KernelKind::CubicSpline.shape(q).0 / Cubic::FS,
        };
        let k = RateConsts {
            h,
            inv_h: 1.0 / h,
            grad: kind.sigma_2d() / (h * h * h) * ds,
            c_mu: mean_value_constant(kernel, params.viscous_constant) * params.mu,
            mu: params.mu,
            delta_hc2: 2.0 * params.density_diffusion * h * params.c,
            shifting: params.shifting > 0.0,
            rho0: params.rho0,
            g,
            f_scalar,
        };
        let c = &self.ch;
        let inp = RatesIn {
            pos: Pos { grid: &self.grid, xoh: &self.xoh, xh: &self.xh, xl: &self.xl, zr: &self.zr },
            frames: &self.frames,
            wall: &self.wall,
            ch: [&c[UX], &c[UZ], &c[MP], &c[M], &c[V], &c[DEV], &c[VD]],
            pr: &self.pr,
            rho: &self.rho,
            mass: &self.mass,
            k,
        };
        let mv = params.viscous_term == ViscousTerm::MeanValue;
        let ex = params.density_diffusion > 0.0 || params.shifting > 0.0;
        let (par, b, out) = (params.parallel, &self.blocks[..], &mut self.rates[..]);
        macro_rules! go {
            ($s:ty) => {
                match (mv, ex) {
                    (true, false) => rate_run::<$s, true, false>(&inp, par, avx, b, out),
                    (true, true) => rate_run::<$s, true, true>(&inp, par, avx, b, out),
                    (false, false) => rate_run::<$s, false, false>(&inp, par, avx, b, out),
                    (false, true) => rate_run::<$s, false, true>(&inp, par, avx, b, out),
                }
            };
        }
        match kind {
            KernelKind::QuarticSpline => go!(Quartic),
            KernelKind::WendlandC2 => go!(Wendland),
            KernelKind::CubicSpline => go!(Cubic),
        }
    }

    /// Results in the particles' order: the particles' own state, the walls' interpolated one, the
    /// rates.
    fn scatter(&self, params: &SphParams, p: &Particles, ws: &mut Workspace) {
        ws.ux.clone_from(&p.vx);
        ws.uz.clone_from(&p.vz);
        ws.rho.clone_from(&p.rho);
        ws.p.clear();
        ws.p.extend(p.rho.iter().map(|&r| pressure(params, r)));
        let rank = &self.grid.rank;
        if self.any_wall {
            for (i, &k) in rank.iter().enumerate() {
                if p.kind[i].is_wall() {
                    let [u, w, pw, rw] = self.wall_out[k as usize];
                    (ws.ux[i], ws.uz[i], ws.p[i], ws.rho[i]) = (u, w, pw, rw);
                }
            }
        }
        ws.rates.clear();
        ws.rates.extend(rank.iter().map(|&k| self.rates[k as usize]));
    }
}

fn wall_run<S: Shape>(inp: &WallIn, parallel: bool, avx: bool, blocks: &[(usize, usize)], out: &mut [[Real; 4]]) {
    for_blocks(parallel, inp.pos.grid, blocks, out, |c0, c1, o| {
        SCRATCH.with(|b| {
            let buf = &mut b.borrow_mut();
            #[cfg(target_arch = "x86_64")]
            if avx {
                // SAFETY: avx is true only when AVX2 and FMA were detected.
                unsafe { wall_avx::<S>(inp, c0, c1, o, buf) };
                return;
            }
            let _ = avx;
            // SAFETY: the portable lanes run everywhere.
            unsafe { kernels::wall_cells::<Portable, S>(inp, c0, c1, o, buf) };
        });
    });
}

fn rate_run<S: Shape, const MV: bool, const EX: bool>(
    inp: &RatesIn,
    parallel: bool,
    avx: bool,
    blocks: &[(usize, usize)],
    out: &mut [Rate],
) {
    for_blocks(parallel, inp.pos.grid, blocks, out, |c0, c1, o| {
        SCRATCH.with(|b| {
            let buf = &mut b.borrow_mut();
            #[cfg(target_arch = "x86_64")]
            if avx {
                // SAFETY: avx is true only when AVX2 and FMA were detected.
                unsafe { rates_avx::<S, MV, EX>(inp, c0, c1, o, buf) };
                return;
            }
            let _ = avx;
            // SAFETY: the portable lanes run everywhere.
            unsafe { kernels::rates_cells::<Portable, S, MV, EX>(inp, c0, c1, o, buf) };
        });
    });
}

/// # Safety
/// The CPU supports AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn rates_avx<S: Shape, const MV: bool, const EX: bool>(
    inp: &RatesIn,
    c0: usize,
    c1: usize,
    out: &mut [Rate],
    buf: &mut Scratch,
) {
    // SAFETY: AVX2 and FMA (caller).
    unsafe { kernels::rates_cells::<lanes::Avx, S, MV, EX>(inp, c0, c1, out, buf) }
}

/// # Safety
/// The CPU supports AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn wall_avx<S: Shape>(inp: &WallIn, c0: usize, c1: usize, out: &mut [[Real; 4]], buf: &mut Scratch) {
    // SAFETY: AVX2 and FMA (caller).
    unsafe { kernels::wall_cells::<lanes::Avx, S>(inp, c0, c1, out, buf) }
}
