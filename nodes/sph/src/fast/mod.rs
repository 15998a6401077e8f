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
use kernels::{Buf, Cubic, Quartic, RateConsts, RatesIn, Shape, WallIn, Wendland, NCH};
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

/// Cells per support radius of the fast grid (cells of side ≥ support / `REACH`).
const REACH: usize = 1;
/// Blocks of cells handed to the threads hold at least this many particles.
const BLOCK_PARTICLES: usize = 384;

/// Caller-owned scratch of the fast evaluator (no allocation once warmed up, except one small
/// vector of block slices per pass).
#[derive(Clone, Debug, Default)]
pub struct FastWorkspace {
    grid: Grid,
    blocks: Vec<(usize, usize)>,
    xs: Vec<Real>,
    zs: Vec<Real>,
    kind: Vec<ParticleKind>,
    wall: Vec<bool>,
    vx: Vec<Real>,
    vz: Vec<Real>,
    rho: Vec<Real>,
    p: Vec<Real>,
    mass: Vec<Real>,
    /// f32 channels: wall pass (ux, uz, p, ρ, non-wall flag), then rate pass (ux, uz, m p/ρ², m,
    /// m/ρ, ρ − ρ₀, non-wall m/ρ).
    ch: [Vec<f32>; NCH],
    pr: Vec<f32>,
    wall_out: Vec<[Real; 4]>,
    rates: Vec<Rate>,
    any_wall: bool,
    cells: CellList,
}

thread_local! {
    static BUF: std::cell::RefCell<Buf> = std::cell::RefCell::new(Buf::default());
}

/// [`crate::wcsph::compute_rates`] computed by the fast evaluator: same outputs (`ws.ux`, `uz`, `p`,
/// `rho`, `rates`) to f32 accuracy (see the module doc), with its own cell grid at the kernel support
/// (no [`CellList`] needed). Falls back to the reference where the fast grid does not apply (a
/// periodic axis shorter than 3 cells).
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
    if particles.is_empty() || !fws.grid.build(&particles.x, &particles.z, support, REACH, px, pz) {
        fws.cells.build(&particles.x, &particles.z, support, px, pz);
        wcsph::compute_rates(params, kernel, particles, &fws.cells, g, ws);
        return;
    }
    let avx = backend == Backend::Auto && avx_available();
    fws.sort(params, particles);
    if fws.any_wall {
        fws.wall_pass(params, kernel, g, avx);
    }
    fws.derive(params);
    fws.rate_pass(params, kernel, g, avx);
    fws.scatter(ws);
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
    /// Sorted copies of the particle data, wall-pass channels, blocks.
    fn sort(&mut self, params: &SphParams, p: &Particles) {
        let order = &self.grid.order;
        macro_rules! gather {
            ($dst:expr, $src:expr) => {{
                $dst.clear();
                $dst.extend(order.iter().map(|&i| $src[i as usize]));
            }};
        }
        gather!(self.xs, p.x);
        gather!(self.zs, p.z);
        gather!(self.kind, p.kind);
        gather!(self.vx, p.vx);
        gather!(self.vz, p.vz);
        gather!(self.rho, p.rho);
        gather!(self.mass, p.mass);
        self.wall.clear();
        self.wall.extend(self.kind.iter().map(|k| k.is_wall()));
        self.any_wall = self.wall.iter().any(|&w| w);
        self.p.clear();
        self.p.extend(self.rho.iter().map(|&r| pressure(params, r)));
        let n = self.xs.len();
        for ch in &mut self.ch {
            ch.resize(n, 0.0);
        }
        if self.any_wall {
            let [ux, uz, pc, rc, fl, ..] = &mut self.ch;
            for k in 0..n {
                ux[k] = self.vx[k] as f32;
                uz[k] = self.vz[k] as f32;
                pc[k] = self.p[k] as f32;
                rc[k] = self.rho[k] as f32;
                fl[k] = if self.wall[k] { 0.0 } else { 1.0 };
            }
        }
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

    /// Wall particles' velocity, pressure and density (sorted `vx`, `vz`, `p`, `rho` updated).
    fn wall_pass(&mut self, params: &SphParams, kernel: &Kernel, g: [Real; 2], avx: bool) {
        let n = self.xs.len();
        self.wall_out.resize(n, [0.0; 4]);
        let [ux, uz, pc, rc, fl, ..] = &self.ch;
        let inp = WallIn {
            grid: &self.grid,
            xs: &self.xs,
            zs: &self.zs,
            kind: &self.kind,
            ch: [ux, uz, pc, rc, fl],
            vx: &self.vx,
            vz: &self.vz,
            h: kernel.h,
            inv_h: 1.0 / kernel.h,
            g,
            rho0: params.rho0,
            c2: params.c * params.c,
            pb: params.background_pressure,
        };
        match kernel.kind {
            KernelKind::QuarticSpline => {
                wall_run::<Quartic>(&inp, params.parallel, avx, &self.blocks, &mut self.wall_out)
            }
            KernelKind::WendlandC2 => {
                wall_run::<Wendland>(&inp, params.parallel, avx, &self.blocks, &mut self.wall_out)
            }
            KernelKind::CubicSpline => wall_run::<Cubic>(&inp, params.parallel, avx, &self.blocks, &mut self.wall_out),
        }
        for k in 0..n {
            if self.wall[k] {
                let [u, v, p, r] = self.wall_out[k];
                self.vx[k] = u;
                self.vz[k] = v;
                self.p[k] = p;
                self.rho[k] = r;
            }
        }
    }

    /// Rate-pass channels from the (wall-updated) sorted data.
    fn derive(&mut self, params: &SphParams) {
        let n = self.xs.len();
        self.pr.resize(n, 0.0);
        let [ux, uz, mp, m, v, dev, vd] = &mut self.ch;
        for k in 0..n {
            let (r, mk) = (self.rho[k], self.mass[k]);
            let pr = self.p[k] / (r * r);
            ux[k] = self.vx[k] as f32;
            uz[k] = self.vz[k] as f32;
            mp[k] = (mk * pr) as f32;
            m[k] = mk as f32;
            v[k] = (mk / r) as f32;
            dev[k] = (r - params.rho0) as f32;
            vd[k] = if self.wall[k] { 0.0 } else { v[k] };
            self.pr[k] = pr as f32;
        }
    }

    fn rate_pass(&mut self, params: &SphParams, kernel: &Kernel, g: [Real; 2], avx: bool) {
        let n = self.xs.len();
        self.rates.resize(n, Rate::default());
        let h = kernel.h;
        let kind = kernel.kind;
        let (fs, ds) = match kind {
            KernelKind::QuarticSpline => (Quartic::FS, Quartic::DS),
            KernelKind::WendlandC2 => (Wendland::FS, Wendland::DS),
            KernelKind::CubicSpline => (Cubic::FS, Cubic::DS),
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
            f0: kind.shape(0.0).0 / fs,
            c_mu: mean_value_constant(kernel, params.viscous_constant) * params.mu,
            mu: params.mu,
            delta_hc2: 2.0 * params.density_diffusion * h * params.c,
            shifting: params.shifting > 0.0,
            rho0: params.rho0,
            g,
            f_scalar,
        };
        let [ux, uz, mp, m, v, dev, vd] = &self.ch;
        let inp = RatesIn {
            grid: &self.grid,
            xs: &self.xs,
            zs: &self.zs,
            wall: &self.wall,
            ch: [ux, uz, mp, m, v, dev, vd],
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

    /// Results back in the particles' order.
    fn scatter(&self, ws: &mut Workspace) {
        let rank = &self.grid.rank;
        macro_rules! put {
            ($dst:expr, $src:expr) => {{
                $dst.clear();
                $dst.extend(rank.iter().map(|&k| $src[k as usize]));
            }};
        }
        put!(ws.rates, self.rates);
        put!(ws.ux, self.vx);
        put!(ws.uz, self.vz);
        put!(ws.p, self.p);
        put!(ws.rho, self.rho);
    }
}

fn wall_run<S: Shape>(inp: &WallIn, parallel: bool, avx: bool, blocks: &[(usize, usize)], out: &mut [[Real; 4]]) {
    for_blocks(parallel, inp.grid, blocks, out, |c0, c1, o| {
        BUF.with(|b| {
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
    for_blocks(parallel, inp.grid, blocks, out, |c0, c1, o| {
        BUF.with(|b| {
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
    buf: &mut Buf,
) {
    // SAFETY: AVX2 and FMA (caller).
    unsafe { kernels::rates_cells::<lanes::Avx, S, MV, EX>(inp, c0, c1, out, buf) }
}

/// # Safety
/// The CPU supports AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn wall_avx<S: Shape>(inp: &WallIn, c0: usize, c1: usize, out: &mut [[Real; 4]], buf: &mut Buf) {
    // SAFETY: AVX2 and FMA (caller).
    unsafe { kernels::wall_cells::<lanes::Avx, S>(inp, c0, c1, out, buf) }
}
