//! Fast evaluation of the WCSPH right-hand sides: the same equations as
//! [`crate::wcsph::compute_rates`] (Shahriari & Garcia 2018, eq 7, 8, 10, 12 or Morris et al. 1997,
//! the wall particles of §2.2, δ-SPH diffusion and the shifting sums), the reference being kept as
//! the twin this module is tested against (`tests/fast_rhs.rs`). Selected by
//! [`SphParams::fast_rhs`] (default) in [`crate::Solver`].
//!
//! Design (measurements in `PERF.md`):
//! * a grid of cells of side ≥ support / 2 (`grid.rs`); once per evaluation the particles are
//!   copied in cell order (row-major, stable: deterministic) into scratch arrays, the solver's order
//!   untouched, with the per-particle quantities of the pair terms precomputed in f32: x/h as an
//!   f32 pair hi + lo, (z − cell row centre)/h, velocities, m p/ρ², m, m/ρ, ρ − ρ₀;
//! * the neighbour cells of a cell are 5 rows of 5 cells, each row a contiguous run of the sorted
//!   arrays (2 where a periodic axis wraps), cut into chunks of ≤ 8 candidates once per cell;
//! * every particle of the cell runs over its cell's chunks 8 lanes at a time, without branches, in
//!   two passes — geometry and kernel, then the sums (`kernels.rs`) — in f32 with fused
//!   multiply-adds; the 8 lanes of every sum are added in f64 and the constants (σ/h³, C μ/ρ_a, …)
//!   applied in f64;
//! * the lanes are AVX2 + FMA registers where the CPU has them (runtime detection), else a portable
//!   array type with the same IEEE operations: both give the same bits (tested);
//! * wall particles first get their Shepard values in a pass of the same form (over chunk lists
//!   without wall-only runs), then the rates;
//! * cells are processed in blocks on rayon threads (`params.parallel`), every particle written by
//!   exactly one block; a particle's result depends only on the data, never on the blocks or the
//!   threads: bit-identical for any thread count. Results are scattered back to the solver's order.
//!
//! Precision: dx is exact to one f32 rounding of itself (hi/lo pair), dz to ~2e-7 h; every pair
//! term is then correct to a few 1e-7 of itself, and a rate to ~1e-6 of the sum of the magnitudes
//! of its terms (f32 lane sums of ≤ ~10 terms, f64 across lanes). Measured against the reference:
//! ≤ 1.8e-6 of the largest rate (`tests/fast_rhs.rs`, `PERF.md`).

mod grid;
mod kernels;
mod lanes;
mod symmetric;

use grid::Grid;
use kernels::{Cubic, Frames, Pos, Quartic, RateConsts, RatesIn, Scratch, Shape, Sums, WallIn, Wendland, PAD};
use lanes::{Lanes, Portable};
use symmetric::{SymIn, SymOut, NR, NR_BASIC};

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
    /// AVX2 + FMA with the 16 registers of AVX2 even where AVX-512VL would give 32 (same bits; for
    /// tests and comparisons).
    Avx2,
}

/// The lanes an evaluation runs on: `Avx` registers compiled for AVX2 + FMA, or for AVX-512F/VL as
/// well (the same 256-bit operations, but 32 vector registers instead of 16: fewer spills in the
/// pair loops, ~10 % faster, measured in `PERF.md`), or the portable twin. All give the same bits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Simd {
    Portable,
    Avx2,
    Avx512,
}

impl Simd {
    fn detect(backend: Backend) -> Simd {
        #[cfg(target_arch = "x86_64")]
        {
            let avx2 = lanes::Avx::available();
            let wide = avx2
                && std::arch::is_x86_feature_detected!("avx512f")
                && std::arch::is_x86_feature_detected!("avx512vl");
            match backend {
                Backend::Auto if wide => Simd::Avx512,
                Backend::Auto | Backend::Avx2 if avx2 => Simd::Avx2,
                _ => Simd::Portable,
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let _ = backend;
            Simd::Portable
        }
    }
}

/// Default cells per support radius of the fast grid (cells of side ≥ support / reach, neighbours
/// reach cells on each side): 2 runs ~30 % fewer candidate lanes than 1 (measured, `PERF.md`);
/// 3 has fewer lanes still but one particle per cell, and the per-cell work then dominates.
const REACH: usize = 2;
/// Blocks of cells handed to the threads hold at least this many particles.
const BLOCK_PARTICLES: usize = 384;

/// `$f!(Shape, MV, EX)` for the kernel `$kind` and the flags `$mv` (mean-value viscous term) and
/// `$ex` (δ-SPH or shifting sums) as a type and two constants.
macro_rules! shapes_and_flags {
    ($kind:expr, $mv:expr, $ex:expr, $f:ident) => {
        match ($kind, $mv, $ex) {
            (KernelKind::QuarticSpline, true, false) => $f!(Quartic, true, false),
            (KernelKind::QuarticSpline, true, true) => $f!(Quartic, true, true),
            (KernelKind::QuarticSpline, false, false) => $f!(Quartic, false, false),
            (KernelKind::QuarticSpline, false, true) => $f!(Quartic, false, true),
            (KernelKind::WendlandC2, true, false) => $f!(Wendland, true, false),
            (KernelKind::WendlandC2, true, true) => $f!(Wendland, true, true),
            (KernelKind::WendlandC2, false, false) => $f!(Wendland, false, false),
            (KernelKind::WendlandC2, false, true) => $f!(Wendland, false, true),
            (KernelKind::CubicSpline, true, false) => $f!(Cubic, true, false),
            (KernelKind::CubicSpline, true, true) => $f!(Cubic, true, true),
            (KernelKind::CubicSpline, false, false) => $f!(Cubic, false, false),
            (KernelKind::CubicSpline, false, true) => $f!(Cubic, false, true),
        }
    };
}

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
/// x/h hi and lo parts, (z − row centre)/h, p/ρ².
const XH: usize = 10;
const XL: usize = 11;
const ZR: usize = 12;
const PR: usize = 13;
const NCH: usize = 14;

/// Caller-owned scratch of the fast evaluator (no allocation once warmed up, except one small
/// vector of block slices per pass).
#[derive(Clone, Debug, Default)]
pub struct FastWorkspace {
    grid: Grid,
    blocks: Vec<(usize, usize)>,
    /// x/h (f64).
    xoh: Vec<Real>,
    kind: Vec<ParticleKind>,
    wall: Vec<bool>,
    rho: Vec<Real>,
    mass: Vec<Real>,
    /// f32 channels (padded with [`PAD`] zeros): ux, uz, m p/ρ², m, m/ρ, ρ − ρ₀, m/ρ of non-walls
    /// (0 for walls), p, ρ, non-wall flag, x/h hi, x/h lo, (z − row centre)/h, p/ρ².
    ch: [Vec<f32>; NCH],
    /// Constant C of eq 12 and the (kernel, h, choice) it was computed for.
    c_visc: Option<(KernelKind, Real, crate::params::ViscousConstant, Real, Real)>,
    wall_out: Vec<[Real; 4]>,
    /// Number of non-wall particles before each sorted index.
    fluid: Vec<u32>,
    rates: Vec<Rate>,
    frames: Frames,
    any_wall: bool,
    cells: CellList,
    /// Cells per support radius; 0 = [`REACH`].
    reach: usize,
    phases: [Real; 5],
    /// Stripes of cell rows of the symmetric pass.
    stripes: Vec<(usize, usize)>,
    /// Received accumulators of the symmetric pass (f32, sorted order, padded).
    acc: [Vec<f32>; NR],
    /// The particles' own sums of the symmetric pass (sorted order).
    own: Vec<Sums>,
    /// 1/f_s(Δp/h) per sorted particle (f32, padded).
    ifdp: Vec<f32>,
    /// Fill only `ws.rates` (the solver's steps); `ws.ux`, `uz`, `p`, `rho` are left as they are.
    pub(crate) rates_only: bool,
}

thread_local! {
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::new(Scratch::default());
}

/// [`crate::wcsph::compute_rates`] computed by the fast evaluator: same outputs (`ws.ux`, `uz`, `p`,
/// `rho`, `rates`) to f32 accuracy (see the module doc), with its own cell grid at the kernel support
/// (no [`CellList`] needed). Falls back to the reference where the fast grid does not apply (a
/// periodic axis shorter than 2 reach + 1 cells, impossible with validated parameters) and when two
/// particles share a position (the reference's 0/0 then gives NaN rates, which the solver reports).
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
    let t0 = std::time::Instant::now();
    let reach = fws.reach();
    if particles.is_empty() || !fws.grid.build(&particles.x, &particles.z, support, reach, px, pz) {
        fws.phases = [0.0; 5];
        fws.cells.build(&particles.x, &particles.z, support, px, pz);
        wcsph::compute_rates(params, kernel, particles, &fws.cells, g, ws);
        return;
    }
    let simd = Simd::detect(backend);
    let t1 = std::time::Instant::now();
    if fws.sort(params, kernel, particles, wcsph::hydrostatic_density_gradient(params, g)) {
        // coincident particles: the reference's 0/0 (NaN rates, reported by the solver)
        fws.cells.build(&particles.x, &particles.z, support, px, pz);
        wcsph::compute_rates(params, kernel, particles, &fws.cells, g, ws);
        fws.phases = [0.0; 5];
        return;
    }
    let t2 = std::time::Instant::now();
    if fws.any_wall {
        fws.wall_pass(params, kernel, particles, g, simd);
    }
    let t3 = std::time::Instant::now();
    let spacing = wcsph::particle_spacing(params, kernel, particles);
    fws.rate_pass(params, kernel, g, simd, spacing);
    let t4 = std::time::Instant::now();
    fws.scatter(params, particles, ws);
    let t5 = std::time::Instant::now();
    let s = |a: std::time::Instant, b: std::time::Instant| (b - a).as_secs_f64();
    fws.phases = [s(t0, t1), s(t1, t2), s(t2, t3), s(t3, t4), s(t4, t5)];
}

/// Runs `f(c0, c1, item)` for every block of cells with its item.
fn run_blocks<T: Send>(parallel: bool, blocks: &[(usize, usize)], items: Vec<T>, f: impl Fn(usize, usize, T) + Sync) {
    #[cfg(feature = "parallel")]
    if parallel {
        use rayon::prelude::*;
        blocks.par_iter().zip(items).for_each(|(&(c0, c1), it)| f(c0, c1, it));
        return;
    }
    let _ = parallel;
    for (&(c0, c1), it) in blocks.iter().zip(items) {
        f(c0, c1, it);
    }
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
    run_blocks(parallel, blocks, slices, f);
}

impl FastWorkspace {
    /// A workspace whose grid has `reach` (clamped to 1..=4) cells per kernel support radius
    /// (default 2). The results differ between reaches only by rounding (the lanes are summed in
    /// another order); for a given reach they are bit-identical for any thread count.
    pub fn with_reach(reach: usize) -> Self {
        FastWorkspace { reach: reach.clamp(1, 4), ..Default::default() }
    }

    /// Wall-clock seconds of the phases of the last evaluation: grid build, sorted copies, wall
    /// particles, rates, scatter back (zeros after a fallback to the reference).
    pub fn phase_seconds(&self) -> [Real; 5] {
        self.phases
    }

    /// Cells per kernel support radius of the grid.
    pub(crate) fn reach(&self) -> usize {
        if self.reach == 0 {
            REACH
        } else {
            self.reach
        }
    }

    /// Blocks of consecutive cells of ≥ [`BLOCK_PARTICLES`] particles (the units of parallel work).
    fn make_blocks(&mut self) {
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

    /// Sorted, padded copies of the particle data with the per-particle quantities of the pair
    /// terms (block by block, on threads when `params.parallel`). Returns true when two particles
    /// share a position (they share a cell; the fast kernels would treat the pair as a self pair).
    /// Sorts the particles into the grid's order and fills the channels; `hk`: the hydrostatic
    /// density gradient that the δ-SPH density (`DEV`) is taken relative to.
    fn sort(&mut self, params: &SphParams, kernel: &Kernel, p: &Particles, hk: [Real; 2]) -> bool {
        let n = p.len();
        let inv_h = 1.0 / kernel.h;
        self.make_blocks();
        for v in &mut self.ch {
            v.resize(n + PAD, 0.0);
            v[n..].fill(0.0);
        }
        self.xoh.resize(n, 0.0);
        self.rho.resize(n, 0.0);
        self.mass.resize(n, 0.0);
        self.kind.resize(n, ParticleKind::Fluid);
        self.wall.resize(n, false);
        let grid = &self.grid;
        fn take<'a, T>(s: &mut &'a mut [T], len: usize) -> &'a mut [T] {
            let (a, b) = std::mem::take(s).split_at_mut(len);
            *s = b;
            a
        }
        let mut f64s = [&mut self.xoh[..], &mut self.rho[..], &mut self.mass[..]];
        let (mut kind, mut wall) = (&mut self.kind[..], &mut self.wall[..]);
        let mut ch: [&mut [f32]; NCH] = self.ch.each_mut().map(|v| &mut v[..n]);
        let mut outs = Vec::with_capacity(self.blocks.len());
        for &(c0, c1) in &self.blocks {
            let len = grid.range(c1 - 1).1 - grid.range(c0).0;
            let f = f64s.each_mut().map(|v| take(v, len));
            let c = ch.each_mut().map(|v| take(v, len));
            outs.push((f, take(&mut kind, len), take(&mut wall, len), c));
        }
        let hydro = hk != [0.0, 0.0];
        let coincident = std::sync::atomic::AtomicBool::new(false);
        run_blocks(params.parallel, &self.blocks, outs, |c0, c1, (f, kind, wall, ch)| {
            let [xoh, rho, mass] = f;
            let [ux, uz, mp, m, v, dev, vd, pc, rc, fl, xh, xl, zr, pr] = ch;
            let base = grid.range(c0).0;
            for c in c0..c1 {
                let (s, e) = grid.range(c);
                let zc = grid.az_centre(c / grid.ax.n);
                for k in s..e {
                    let i = grid.order[k] as usize;
                    let j = k - base;
                    let (r, mk, kd) = (p.rho[i], p.mass[i], p.kind[i]);
                    let xo = p.x[i] * inv_h;
                    let hi = xo as f32;
                    xoh[j] = xo;
                    xh[j] = hi;
                    xl[j] = (xo - hi as Real) as f32;
                    zr[j] = ((p.z[i] - zc) * inv_h) as f32;
                    rho[j] = r;
                    mass[j] = mk;
                    kind[j] = kd;
                    let w = kd.is_wall();
                    wall[j] = w;
                    let pk = pressure(params, r);
                    let inv_r = 1.0 / r;
                    let prk = pk * inv_r * inv_r;
                    ux[j] = p.vx[i] as f32;
                    uz[j] = p.vz[i] as f32;
                    mp[j] = (mk * prk) as f32;
                    m[j] = mk as f32;
                    v[j] = (mk * inv_r) as f32;
                    // δ-SPH's density: relative to hydrostatic balance (wcsph::hydrostatic_density_gradient)
                    dev[j] = if hydro { r - params.rho0 - (hk[0] * p.x[i] + hk[1] * p.z[i]) } else { r - params.rho0 }
                        as f32;
                    vd[j] = if w { 0.0 } else { v[j] };
                    pc[j] = pk as f32;
                    rc[j] = r as f32;
                    fl[j] = if w { 0.0 } else { 1.0 };
                    pr[j] = prk as f32;
                }
                // same position ⇒ same x/h and z̃ (the converse within ~1e-7 h only costs a
                // reference evaluation)
                let (xs, zs) = (&xoh[s - base..e - base], &zr[s - base..e - base]);
                for q in 0..xs.len() {
                    if (q + 1..xs.len()).any(|b| xs[b] == xs[q] && zs[b] == zs[q]) {
                        coincident.store(true, std::sync::atomic::Ordering::Relaxed);
                    }
                }
            }
        });
        self.any_wall = self.wall.iter().any(|&w| w);
        if self.any_wall {
            self.fluid.resize(n + 1, 0);
            let mut count = 0;
            for (f, &w) in self.fluid[1..].iter_mut().zip(&self.wall) {
                count += u32::from(!w);
                *f = count;
            }
        }
        self.frames = Frames::new(&self.grid, inv_h);
        coincident.into_inner()
    }

    /// Wall particles' velocity, pressure and density, then their rate-pass channels.
    fn wall_pass(&mut self, params: &SphParams, kernel: &Kernel, p: &Particles, g: [Real; 2], simd: Simd) {
        let n = self.xoh.len();
        self.wall_out.resize(n, [0.0; 4]);
        let inp = WallIn {
            pos: Pos { grid: &self.grid, xoh: &self.xoh, xh: &self.ch[XH], xl: &self.ch[XL], zr: &self.ch[ZR] },
            frames: &self.frames,
            kind: &self.kind,
            ch: [&self.ch[UX], &self.ch[UZ], &self.ch[P], &self.ch[RHO], &self.ch[FL]],
            fluid: &self.fluid,
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
            KernelKind::QuarticSpline => wall_run::<Quartic>(&inp, par, simd, b, out),
            KernelKind::WendlandC2 => wall_run::<Wendland>(&inp, par, simd, b, out),
            KernelKind::CubicSpline => wall_run::<Cubic>(&inp, par, simd, b, out),
        }
        let [ux, uz, mp, _, v, dev, _, _, _, _, _, _, _, pr] = &mut self.ch;
        for k in 0..n {
            if self.wall[k] {
                let [u, w, pw, rw] = self.wall_out[k];
                let prk = pw / (rw * rw);
                ux[k] = u as f32;
                uz[k] = w as f32;
                mp[k] = (self.mass[k] * prk) as f32;
                v[k] = (self.mass[k] / rw) as f32;
                dev[k] = (rw - params.rho0) as f32;
                pr[k] = prk as f32;
                self.rho[k] = rw;
            }
        }
    }

    fn rate_pass(&mut self, params: &SphParams, kernel: &Kernel, g: [Real; 2], simd: Simd, spacing: Real) {
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
        let key = (kind, h, params.viscous_constant, spacing);
        let c_visc = match self.c_visc {
            Some((k, hh, vc, sp, c)) if (k, hh, vc, sp) == key => c,
            _ => {
                let c = mean_value_constant(kernel, params.viscous_constant, spacing);
                self.c_visc = Some((kind, h, params.viscous_constant, spacing, c));
                c
            }
        };
        let k = RateConsts {
            h,
            inv_h: 1.0 / h,
            grad: kind.sigma_2d() / (h * h * h) * ds,
            c_mu: c_visc * params.mu,
            mu: params.mu,
            delta_hc2: 2.0 * params.density_diffusion * h * params.c,
            shifting: params.shifting > 0.0,
            rho0: params.rho0,
            g,
            f_scalar,
        };
        let c = &self.ch;
        let inp = RatesIn {
            pos: Pos { grid: &self.grid, xoh: &self.xoh, xh: &self.ch[XH], xl: &self.ch[XL], zr: &self.ch[ZR] },
            frames: &self.frames,
            wall: &self.wall,
            ch: [&c[UX], &c[UZ], &c[MP], &c[M], &c[V], &c[DEV], &c[VD]],
            pr: &c[PR],
            rho: &self.rho,
            mass: &self.mass,
            k,
        };
        let mv = params.viscous_term == ViscousTerm::MeanValue;
        let ex = params.density_diffusion > 0.0 || params.shifting > 0.0;
        if params.symmetric_pairs {
            let nr = if ex { NR } else { NR_BASIC };
            for (c, v) in self.acc.iter_mut().enumerate().take(nr) {
                v.clear();
                v.resize(n + PAD, if c == symmetric::R2 { f32::from_bits(u32::MAX) } else { 0.0 });
            }
            for v in self.acc.iter_mut().skip(nr) {
                v.resize(n + PAD, 0.0);
            }
            self.own.resize(n, Sums::default());
            self.ifdp.clear();
            if ex && params.shifting > 0.0 {
                let f0 = |m: Real| (1.0 / f_scalar((m / params.rho0).sqrt() / h)) as f32;
                self.ifdp.extend(self.mass.iter().map(|&m| f0(m)));
            } else {
                self.ifdp.resize(n, 1.0);
            }
            self.ifdp.resize(n + PAD, 1.0);
            symmetric::stripes(&self.grid, params.periodic_z.is_some(), BLOCK_PARTICLES, &mut self.stripes);
            let out = SymOut { acc: self.acc.each_mut().map(|v| v.as_mut_ptr()), own: self.own.as_mut_ptr() };
            let fluid: &[u32] = if self.any_wall { &self.fluid } else { &[] };
            let si = SymIn { r: inp, ifdp: &self.ifdp, fluid };
            let (par, st) = (params.parallel, &self.stripes[..]);
            macro_rules! sym {
                ($s:ty, $mv:literal, $ex:literal) => {
                    sym_run::<$s, $mv, $ex>(&si, par, simd, st, out)
                };
            }
            shapes_and_flags!(kind, mv, ex, sym);
            let acc: [&[f32]; NR] = self.acc.each_ref().map(|v| &v[..]);
            let (own, wall, rho, mass) = (&self.own[..], &self.wall[..], &self.rho[..], &self.mass[..]);
            let f0 = f_scalar(0.0);
            let kc = &si.r.k;
            macro_rules! fin {
                ($s:ty, $mv:literal, $ex:literal) => {
                    for_blocks(par, &self.grid, &self.blocks, &mut self.rates, |c0, c1, o| {
                        let (s0, s1) = (self.grid.range(c0).0, self.grid.range(c1 - 1).1);
                        for i in s0..s1 {
                            o[i - s0] = if wall[i] {
                                Rate::default()
                            } else {
                                symmetric::combine::<$s, $mv, $ex>(kc, &own[i], &acc, i, rho[i], mass[i] / rho[i] * f0)
                            };
                        }
                    })
                };
            }
            shapes_and_flags!(kind, mv, ex, fin);
            return;
        }
        let (par, b, out) = (params.parallel, &self.blocks[..], &mut self.rates[..]);
        macro_rules! gather {
            ($s:ty, $mv:literal, $ex:literal) => {
                rate_run::<$s, $mv, $ex>(&inp, par, simd, b, out)
            };
        }
        shapes_and_flags!(kind, mv, ex, gather);
    }

    /// Results in the particles' order: the particles' own state, the walls' interpolated one, the
    /// rates.
    fn scatter(&self, params: &SphParams, p: &Particles, ws: &mut Workspace) {
        let rank = &self.grid.rank;
        if !self.rates_only {
            self.scatter_state(params, p, ws);
        }
        let rates = &self.rates;
        #[cfg(feature = "parallel")]
        if params.parallel {
            use rayon::prelude::*;
            rank.par_iter().map(|&k| rates[k as usize]).collect_into_vec(&mut ws.rates);
            return;
        }
        ws.rates.clear();
        ws.rates.extend(rank.iter().map(|&k| rates[k as usize]));
    }

    /// The particles' own state and the walls' interpolated one, in the particles' order.
    fn scatter_state(&self, params: &SphParams, p: &Particles, ws: &mut Workspace) {
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
    }
}

fn wall_run<S: Shape>(inp: &WallIn, parallel: bool, simd: Simd, blocks: &[(usize, usize)], out: &mut [[Real; 4]]) {
    for_blocks(parallel, inp.pos.grid, blocks, out, |c0, c1, o| {
        SCRATCH.with(|b| {
            let buf = &mut b.borrow_mut();
            #[cfg(target_arch = "x86_64")]
            match simd {
                // SAFETY: Avx512 / Avx2 only when detected (`Simd::detect`).
                Simd::Avx512 => return unsafe { wall_avx512::<S>(inp, c0, c1, o, buf) },
                // SAFETY: as above.
                Simd::Avx2 => return unsafe { wall_avx::<S>(inp, c0, c1, o, buf) },
                Simd::Portable => {}
            }
            let _ = simd;
            // SAFETY: the portable lanes run everywhere.
            unsafe { kernels::wall_cells::<Portable, S>(inp, c0, c1, o, buf) };
        });
    });
}

fn rate_run<S: Shape, const MV: bool, const EX: bool>(
    inp: &RatesIn,
    parallel: bool,
    simd: Simd,
    blocks: &[(usize, usize)],
    out: &mut [Rate],
) {
    for_blocks(parallel, inp.pos.grid, blocks, out, |c0, c1, o| {
        SCRATCH.with(|b| {
            let buf = &mut b.borrow_mut();
            #[cfg(target_arch = "x86_64")]
            match simd {
                // SAFETY: Avx512 / Avx2 only when detected (`Simd::detect`).
                Simd::Avx512 => return unsafe { rates_avx512::<S, MV, EX>(inp, c0, c1, o, buf) },
                // SAFETY: as above.
                Simd::Avx2 => return unsafe { rates_avx::<S, MV, EX>(inp, c0, c1, o, buf) },
                Simd::Portable => {}
            }
            let _ = simd;
            // SAFETY: the portable lanes run everywhere.
            unsafe { kernels::rates_cells::<Portable, S, MV, EX, false>(inp, c0, c1, o, buf) };
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
    unsafe { kernels::rates_cells::<lanes::Avx, S, MV, EX, true>(inp, c0, c1, out, buf) }
}

/// # Safety
/// The CPU supports AVX2, FMA, AVX-512F and AVX-512VL.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,avx512f,avx512vl")]
unsafe fn rates_avx512<S: Shape, const MV: bool, const EX: bool>(
    inp: &RatesIn,
    c0: usize,
    c1: usize,
    out: &mut [Rate],
    buf: &mut Scratch,
) {
    // SAFETY: AVX2 and FMA (caller).
    unsafe { kernels::rates_cells::<lanes::Avx, S, MV, EX, false>(inp, c0, c1, out, buf) }
}

/// # Safety
/// The CPU supports AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn wall_avx<S: Shape>(inp: &WallIn, c0: usize, c1: usize, out: &mut [[Real; 4]], buf: &mut Scratch) {
    // SAFETY: AVX2 and FMA (caller).
    unsafe { kernels::wall_cells::<lanes::Avx, S>(inp, c0, c1, out, buf) }
}

/// # Safety
/// The CPU supports AVX2, FMA, AVX-512F and AVX-512VL.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,avx512f,avx512vl")]
unsafe fn wall_avx512<S: Shape>(inp: &WallIn, c0: usize, c1: usize, out: &mut [[Real; 4]], buf: &mut Scratch) {
    // SAFETY: AVX2 and FMA (caller).
    unsafe { kernels::wall_cells::<lanes::Avx, S>(inp, c0, c1, out, buf) }
}

/// The symmetric pass: the even stripes, then the odd ones (on rayon threads when `parallel`).
fn sym_run<S: Shape, const MV: bool, const EX: bool>(
    inp: &SymIn,
    parallel: bool,
    simd: Simd,
    stripes: &[(usize, usize)],
    out: SymOut,
) {
    let one = |&(c0, c1): &(usize, usize)| {
        SCRATCH.with(|b| {
            let buf = &mut b.borrow_mut();
            #[cfg(target_arch = "x86_64")]
            match simd {
                // SAFETY: Avx512 / Avx2 only when detected (`Simd::detect`); the stripes of one phase
                // write disjoint indices (`symmetric`).
                Simd::Avx512 => return unsafe { sym_avx512::<S, MV, EX>(inp, c0, c1, out, buf) },
                // SAFETY: as above.
                Simd::Avx2 => return unsafe { sym_avx::<S, MV, EX>(inp, c0, c1, out, buf) },
                Simd::Portable => {}
            }
            let _ = simd;
            // SAFETY: the portable lanes run everywhere; disjoint writes as above.
            unsafe { symmetric::sym_cells::<Portable, S, MV, EX>(inp, c0, c1, out, buf) };
        });
    };
    for phase in 0..2 {
        #[cfg(feature = "parallel")]
        if parallel {
            use rayon::prelude::*;
            stripes.par_iter().skip(phase).step_by(2).for_each(one);
            continue;
        }
        let _ = parallel;
        stripes.iter().skip(phase).step_by(2).for_each(one);
    }
}

/// # Safety
/// The CPU supports AVX2 and FMA; as [`symmetric::sym_cells`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn sym_avx<S: Shape, const MV: bool, const EX: bool>(
    inp: &SymIn,
    c0: usize,
    c1: usize,
    out: SymOut,
    buf: &mut Scratch,
) {
    // SAFETY: AVX2 and FMA (caller); disjoint writes (caller).
    unsafe { symmetric::sym_cells::<lanes::Avx, S, MV, EX>(inp, c0, c1, out, buf) }
}

/// # Safety
/// The CPU supports AVX2, FMA, AVX-512F and AVX-512VL; as [`symmetric::sym_cells`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,avx512f,avx512vl")]
unsafe fn sym_avx512<S: Shape, const MV: bool, const EX: bool>(
    inp: &SymIn,
    c0: usize,
    c1: usize,
    out: SymOut,
    buf: &mut Scratch,
) {
    // SAFETY: AVX2 and FMA (caller); disjoint writes (caller).
    unsafe { symmetric::sym_cells::<lanes::Avx, S, MV, EX>(inp, c0, c1, out, buf) }
}
