//! Pair kernels of the fast evaluator, written once over [`Lanes`] and instantiated for the portable
//! lanes and (x86-64) the AVX2 + FMA lanes.
//!
//! Every particle runs over the chunks ([`Chunk`]: ≤ 8 consecutive sorted particles of one row run)
//! of its cell's neighbour cells, 8 candidates at a time and without branches:
//! * positions: x/h is stored as an f32 pair hi + lo (exact to ~1e-14 h at any domain size) and the
//!   pair difference taken as (hi_a − hi_b) + (lo_a − lo_b), so dx is correct to one rounding of
//!   itself; a periodic x image uses the running particle's x/h shifted by the period in f64 and
//!   split again (its "frame"); z is stored relative to the centre of the particle's cell row
//!   (|z̃| ≤ cell/2h), a run being one row, and the running particle's z̃ is moved into the run's
//!   row frame by −d·cell/h (d the row offset, periodic images included);
//! * the kernels are written with `max(0, ·)`, so candidates outside the support give exact zeros;
//! * the lanes past a run's end get dx = 10⁶ h (one blend): their kernel terms are exact zeros and
//!   their r² is never the smallest;
//! * r² carries a tiny offset (1e-30 h²): the particle's own lane has r = 1e-15 h, f' = 0, hence
//!   zero gradient terms, and W(0) in the Shepard denominator of eq 12 — the self term of
//!   [`crate::wcsph::compute_rates`]; r² ≤ the offset is left out of the nearest distance.

use super::grid::Grid;
use super::lanes::{sum_f64, Lanes};
use crate::particles::ParticleKind;
use crate::wcsph::Rate;
use crate::Real;

/// dx of the lanes past a run's end \[h\].
const FAR: f32 = 1.0e6;
/// Offset added to r² \[h²\] (see the module doc).
const TINY2: f32 = 1.0e-30;
/// `bits(r²) − R2_BIAS` maps r² ≤ TINY2 (the own lane) above every other r² as u32.
pub(super) const R2_BIAS: u32 = TINY2.to_bits() + 1;
/// Lane masks: 8 loads from `MASK[8 − k..]` give k ones then zeros.
static MASK: [u32; 16] = [!0, !0, !0, !0, !0, !0, !0, !0, 0, 0, 0, 0, 0, 0, 0, 0];
/// Zero entries after the sorted arrays (a masked tail may read up to 7 past the end).
pub(super) const PAD: usize = 8;

/// Mask of the first `k` (≤ 8) lanes.
///
/// # Safety
/// `L::available()`.
#[inline(always)]
unsafe fn mask<L: Lanes>(k: usize) -> L {
    // SAFETY: 8 − k ≥ 0 and 16 − (8 − k) ≥ 8 entries follow; u32 and f32 have one layout.
    unsafe { L::load(MASK.as_ptr().add(8 - k).cast::<f32>()) }
}

/// A kernel shape in the lane form: f(q) = `FS` · f_s(q), f'(q) = `DS` · d_s(q), q = r/h.
pub(super) trait Shape {
    /// Support radius / h.
    const CUT: Real;
    /// Scale of f_s.
    const FS: Real;
    /// Scale of d_s.
    const DS: Real;
    /// (f_s(q), d_s(q)); zero for q ≥ `CUT`.
    fn f_d<L: Lanes>(q: L) -> (L, L);
    /// f_s(q).
    fn f<L: Lanes>(q: L) -> L;
}

/// Quartic M5 spline: f = (2.5−q)₊⁴ − 5(1.5−q)₊⁴ + 10(0.5−q)₊⁴, f' = −4[(2.5−q)₊³ − 5(1.5−q)₊³ + 10(0.5−q)₊³].
pub(super) struct Quartic;
/// Wendland C2: f = (1−q/2)₊⁴ (2q+1), f' = −5 q (1−q/2)₊³.
pub(super) struct Wendland;
/// Cubic M4 spline: f = ¼[(2−q)₊³ − 4(1−q)₊³], f' = −¾[(2−q)₊² − 4(1−q)₊²].
pub(super) struct Cubic;

impl Shape for Quartic {
    const CUT: Real = 2.5;
    const FS: Real = 1.0;
    const DS: Real = -4.0;
    #[inline(always)]
    fn f_d<L: Lanes>(q: L) -> (L, L) {
        let (z, m5, ten) = (L::splat(0.0), L::splat(-5.0), L::splat(10.0));
        let a = L::splat(2.5).sub(q).max(z);
        let b = L::splat(1.5).sub(q).max(z);
        let c = L::splat(0.5).sub(q).max(z);
        let (a2, b2, c2) = (a.mul(a), b.mul(b), c.mul(c));
        let (b5, c10) = (b2.mul(m5), c2.mul(ten)); // −5 b², 10 c²
        let f = a2.mul_add(a2, b5.mul_add(b2, c10.mul(c2)));
        let d = c10.mul_add(c, b5.mul_add(b, a2.mul(a)));
        (f, d)
    }
    #[inline(always)]
    fn f<L: Lanes>(q: L) -> L {
        let (z, m5, ten) = (L::splat(0.0), L::splat(-5.0), L::splat(10.0));
        let a = L::splat(2.5).sub(q).max(z);
        let b = L::splat(1.5).sub(q).max(z);
        let c = L::splat(0.5).sub(q).max(z);
        let (a2, b2, c2) = (a.mul(a), b.mul(b), c.mul(c));
        let (b5, c10) = (b2.mul(m5), c2.mul(ten));
        a2.mul_add(a2, b5.mul_add(b2, c10.mul(c2)))
    }
}

impl Shape for Wendland {
    const CUT: Real = 2.0;
    const FS: Real = 1.0;
    const DS: Real = -5.0;
    #[inline(always)]
    fn f_d<L: Lanes>(q: L) -> (L, L) {
        let one = L::splat(1.0);
        let a = q.mul_add(L::splat(-0.5), one).max(L::splat(0.0));
        let a2 = a.mul(a);
        let f = a2.mul(a2).mul(q.mul_add(L::splat(2.0), one));
        (f, q.mul(a2.mul(a)))
    }
    #[inline(always)]
    fn f<L: Lanes>(q: L) -> L {
        let one = L::splat(1.0);
        let a = q.mul_add(L::splat(-0.5), one).max(L::splat(0.0));
        let a2 = a.mul(a);
        a2.mul(a2).mul(q.mul_add(L::splat(2.0), one))
    }
}

impl Shape for Cubic {
    const CUT: Real = 2.0;
    const FS: Real = 0.25;
    const DS: Real = -0.75;
    #[inline(always)]
    fn f_d<L: Lanes>(q: L) -> (L, L) {
        let (z, m4) = (L::splat(0.0), L::splat(-4.0));
        let a = L::splat(2.0).sub(q).max(z);
        let b = L::splat(1.0).sub(q).max(z);
        let (a2, b2) = (a.mul(a), b.mul(b));
        (b2.mul(b).mul_add(m4, a2.mul(a)), b2.mul_add(m4, a2))
    }
    #[inline(always)]
    fn f<L: Lanes>(q: L) -> L {
        let (z, m4) = (L::splat(0.0), L::splat(-4.0));
        let a = L::splat(2.0).sub(q).max(z);
        let b = L::splat(1.0).sub(q).max(z);
        let (a2, b2) = (a.mul(a), b.mul(b));
        b2.mul(b).mul_add(m4, a2.mul(a))
    }
}

/// One chunk of ≤ 8 consecutive candidates of one run: first sorted index, lane count, x frame of
/// the running particle (0: no shift, else a periodic image), z offset / h of the running particle
/// into the run's row frame.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Chunk {
    pub(super) i: u32,
    pub(super) k: u8,
    pub(super) frame: u8,
    /// 1: the lanes up to the running particle's own sorted index are left out (the own-row chunks
    /// of the symmetric pass).
    pub(super) own: u8,
    pub(super) dz: f32,
}

/// Chunks of the neighbour runs of one cell, and per-lane pair values of one particle (pass 1 of
/// [`pair_sums`]).
#[derive(Clone, Debug, Default)]
pub(super) struct Scratch {
    /// `chunks[..n]` are the cell's chunks.
    pub(super) chunks: Vec<Chunk>,
    pub(super) n: usize,
    /// dx, dz, f_s, d_s/r, d_s r/(r² + 0.01), r² per lane.
    pub(super) lane: [Vec<f32>; 6],
}

/// Per-evaluation constants of the chunk lists.
#[derive(Clone, Debug, Default)]
pub(super) struct Frames {
    /// x shift / h of frames 0 (none), 1 (−period), 2 (+period).
    pub(super) shifts: [Real; 3],
    /// z offset / h of the running particle into the frame of the row `d` cells away, at index
    /// d + reach: −d · cell / h (a periodic image row is d cells away as well).
    pub(super) dz: Vec<f32>,
}

impl Frames {
    pub(super) fn new(grid: &Grid, inv_h: Real) -> Self {
        let l = grid.period_x().unwrap_or(0.0) * inv_h;
        let r = grid.reach() as isize;
        let dz = (-r..=r).map(|d| (-(d as Real) * grid.cell_z() * inv_h) as f32).collect();
        Frames { shifts: [0.0, -l, l], dz }
    }
}

impl Scratch {
    /// Chunks of cell `c` into `self.chunks[..self.n]`; returns true when some use a shifted x
    /// frame. Runs of ≤ 16 particles (nearly all) take no data-dependent branch: two chunk slots
    /// are written and ⌈len/8⌉ of them kept. With `FLUID_ONLY`, runs of wall particles only are left
    /// out (`fluid`: number of non-wall particles before each sorted index).
    #[inline]
    fn cell<const FLUID_ONLY: bool>(&mut self, grid: &Grid, fr: &Frames, c: usize, fluid: &[u32]) -> bool {
        let nx = grid.ax.n;
        let reach = grid.reach();
        let (cx, cz) = (c % nx, c / nx);
        let (cols, nc) = grid.ax.segments(cx, reach);
        let (rows, nr) = grid.az.segments(cz, reach);
        let starts = &grid.cell_start;
        let nz = grid.az.n as isize;
        let mut n = 0;
        for &(z0, z1, sz) in &rows[..nr] {
            // row offset of the image of row jz: jz − cz (± nz for a periodic image)
            let wrap = if sz < 0.0 {
                -nz
            } else if sz > 0.0 {
                nz
            } else {
                0
            };
            for jz in z0..=z1 {
                let d = jz as isize + wrap - cz as isize + reach as isize;
                let dz = fr.dz[d as usize];
                let base = jz * nx;
                for &(x0, x1, sx) in &cols[..nc] {
                    let frame = if sx == 0.0 {
                        0
                    } else if sx < 0.0 {
                        1
                    } else {
                        2
                    };
                    let (s, e) = (starts[base + x0] as usize, starts[base + x1 + 1] as usize);
                    if FLUID_ONLY && fluid[s] == fluid[e] {
                        continue;
                    }
                    let len = e - s;
                    if self.chunks.len() < n + len.div_ceil(8) + 2 {
                        self.chunks.resize(n + len.div_ceil(8) + 16, Chunk::default());
                    }
                    if len <= 16 {
                        let k1 = len.min(8);
                        self.chunks[n] = Chunk { i: s as u32, k: k1 as u8, frame, own: 0, dz };
                        self.chunks[n + 1] = Chunk { i: (s + 8) as u32, k: (len - k1) as u8, frame, own: 0, dz };
                        n += len.div_ceil(8);
                    } else {
                        let mut i = s;
                        while i < e {
                            let k = (e - i).min(8);
                            self.chunks[n] = Chunk { i: i as u32, k: k as u8, frame, own: 0, dz };
                            n += 1;
                            i += k;
                        }
                    }
                }
            }
        }
        self.n = n;
        let n8 = 8 * n;
        for l in &mut self.lane {
            if l.len() < n8 {
                l.resize(n8, 0.0);
            }
        }
        nc > 1
    }
}

/// x/h of particle a in frame 0, or in the three frames, as f32 (hi, lo) pairs.
#[inline(always)]
pub(super) fn frames_of(xoh: Real, shifts: &[Real; 3], all: bool) -> [f32; 6] {
    let mut f = [0.0f32; 6];
    for (j, &s) in shifts.iter().enumerate().take(if all { 3 } else { 1 }) {
        let x = xoh - s;
        let hi = x as f32;
        f[2 * j] = hi;
        f[2 * j + 1] = (x - hi as Real) as f32;
    }
    f
}

/// Positions of the sorted particles (each slice padded with [`PAD`] zeros).
#[derive(Clone, Copy)]
pub(super) struct Pos<'a> {
    pub(super) grid: &'a Grid,
    /// x/h (f64), hi and lo f32 parts.
    pub(super) xoh: &'a [Real],
    pub(super) xh: &'a [f32],
    pub(super) xl: &'a [f32],
    /// (z − row centre)/h.
    pub(super) zr: &'a [f32],
}

/// Sorted particle data and constants of the rate pass.
pub(super) struct RatesIn<'a> {
    pub(super) pos: Pos<'a>,
    pub(super) frames: &'a Frames,
    pub(super) wall: &'a [bool],
    /// ux, uz, m p/ρ², m, m/ρ, ρ − ρ₀, (m/ρ for non-walls, 0 for walls) — f32, padded.
    pub(super) ch: [&'a [f32]; 7],
    /// p/ρ² (f32) of every particle.
    pub(super) pr: &'a [f32],
    pub(super) rho: &'a [Real],
    pub(super) mass: &'a [Real],
    pub(super) k: RateConsts,
}

/// Constants of the rate pass (SI).
#[derive(Clone, Copy, Debug)]
pub(super) struct RateConsts {
    pub(super) h: Real,
    pub(super) inv_h: Real,
    /// σ/h³ · DS: ∇_a W = G (dx̃, dz̃) d_s/r̃ with positions in units of h.
    pub(super) grad: Real,
    /// C μ of eq 12.
    pub(super) c_mu: Real,
    /// μ.
    pub(super) mu: Real,
    /// 2 δ h c of the density diffusion (0 = off).
    pub(super) delta_hc2: Real,
    /// Shifting sums wanted.
    pub(super) shifting: bool,
    pub(super) rho0: Real,
    pub(super) g: [Real; 2],
    /// f_s(q) as a function, for w(Δp) of the shifting term.
    pub(super) f_scalar: fn(Real) -> Real,
}

/// Per-particle lane sums, reduced in f64.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Sums {
    pub(super) drho: Real,
    pub(super) apx: Real,
    pub(super) apz: Real,
    pub(super) s1: Real,
    pub(super) s2: Real,
    pub(super) s3: Real,
    pub(super) r2min: Real,
    pub(super) dsum: Real,
    pub(super) gc: [Real; 2],
    pub(super) gu: [Real; 4],
}

/// Smallest r² > TINY2 of the lanes \[h²\] (∞ if none).
#[inline(always)]
pub(super) fn r2min_of<L: Lanes>(acc: L) -> Real {
    let m = acc.min_bits();
    if m == u32::MAX {
        Real::INFINITY
    } else {
        f32::from_bits(m + R2_BIAS) as Real
    }
}

/// Pass 1 of the pair loops: for every lane of `chunks`, dx, dz (units of h), f_s, d_s/r and, with
/// `kk`, d_s r/(r² + 0.01), with `keep_r2` r² (the symmetric pass, whose own-row chunks leave out
/// the lanes up to `a`), into the scratch lanes (8 per chunk); returns the lane
/// minima of r² (as [`Lanes::min_bits_sub`] with [`R2_BIAS`]).
///
/// # Safety
/// `L::available()`; the position slices are padded with [`PAD`] entries; every chunk index < n.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) unsafe fn geometry<L: Lanes, S: Shape>(
    pos: &Pos,
    frames: &Frames,
    chunks: &[Chunk],
    lane: &mut [Vec<f32>; 6],
    shifted: bool,
    a: usize,
    kk: bool,
    keep_r2: bool,
) -> L {
    let (eps, one, tiny) = (L::splat(0.01), L::splat(1.0), L::splat(TINY2));
    let (pxh, pxl, pz) = (pos.xh.as_ptr(), pos.xl.as_ptr(), pos.zr.as_ptr());
    assert!(lane.iter().all(|l| l.len() >= 8 * chunks.len()));
    let [ldx, ldz, lf, lfr, lkk, lr2] = lane;
    let (ldx, ldz, lf, lfr, lkk, lr2) =
        (ldx.as_mut_ptr(), ldz.as_mut_ptr(), lf.as_mut_ptr(), lfr.as_mut_ptr(), lkk.as_mut_ptr(), lr2.as_mut_ptr());
    let fr = frames_of(pos.xoh[a], &frames.shifts, shifted);
    let zra = L::splat(pos.zr[a]);
    let far = L::splat(FAR);
    let mut r2min = L::splat(f32::from_bits(u32::MAX));
    for (j, ck) in chunks.iter().enumerate() {
        let i = ck.i as usize;
        // SAFETY: i < n and the slices hold n + PAD ≥ i + 8 values (caller).
        let ld = |p: *const f32| unsafe { L::load(p.add(i)) };
        // SAFETY: L::available() (caller); k ≤ 8.
        let mk = unsafe { mask::<L>(ck.k as usize) };
        let fj = 2 * ck.frame as usize;
        let dx = L::splat(fr[fj]).sub(ld(pxh)).add(L::splat(fr[fj + 1]).sub(ld(pxl)));
        let dx = far.blend(dx, mk);
        let dx = if keep_r2 {
            // the symmetric pass: own-row lanes up to a are left out
            let lo = if ck.own != 0 { (a + 1).saturating_sub(i).min(8) } else { 0 };
            // SAFETY: L::available() (caller); lo ≤ 8.
            dx.blend(far, unsafe { mask::<L>(lo) })
        } else {
            dx
        };
        let dz = zra.add(L::splat(ck.dz)).sub(ld(pz));
        let r2 = dz.mul_add(dz, dx.mul_add(dx, tiny));
        r2min = r2min.min_bits_sub(r2, R2_BIAS);
        let rr = r2.sqrt();
        let inv = one.div(rr);
        let (f, d) = S::f_d(rr);
        // SAFETY: the scratch lanes hold 8 per chunk (asserted).
        unsafe {
            L::store(ldx.add(8 * j), dx);
            L::store(ldz.add(8 * j), dz);
            L::store(lf.add(8 * j), f);
            L::store(lfr.add(8 * j), d.mul(inv));
            if kk {
                L::store(lkk.add(8 * j), d.mul(rr).div(r2.add(eps)));
            }
            if keep_r2 {
                L::store(lr2.add(8 * j), r2);
            }
        }
    }
    r2min
}

/// Lane sums of particle `a` over the chunks of its cell, in two passes: pass 1 computes the pair
/// geometry and kernel values of every lane into the scratch (√r² and 1/r run beside the kernel
/// polynomial, so its dependency chains are short), pass 2 accumulates. One pass would stall: the
/// ~70-cycle chain √ → kernel → ÷ of each chunk, with ~50 operations waiting on it, fills the
/// out-of-order window after two chunks.
///
/// # Safety
/// `L::available()`; the slices of `inp` are padded with [`PAD`] entries; the scratch lanes hold
/// 8 values per chunk.
#[inline(always)]
unsafe fn pair_sums<L: Lanes, S: Shape, const MV: bool, const EX: bool, const SPLIT: bool>(
    inp: &RatesIn,
    sc: &mut Scratch,
    shifted: bool,
    a: usize,
    inv_fdp: f32,
) -> Sums {
    let (zero, one, c02) = (L::splat(0.0), L::splat(1.0), L::splat(0.2));
    let chunks = &sc.chunks[..sc.n];
    // SAFETY: L::available() and padding (caller).
    let r2min = unsafe { geometry::<L, S>(&inp.pos, inp.frames, chunks, &mut sc.lane, shifted, a, !MV || EX, false) };
    let [ldx, ldz, lf, lfr, lkk, _] = &mut sc.lane;
    let (ldx, ldz, lf, lfr, lkk) =
        (ldx.as_mut_ptr(), ldz.as_mut_ptr(), lf.as_mut_ptr(), lfr.as_mut_ptr(), lkk.as_mut_ptr());
    // pass 2: sums
    let (uax, uaz, pa) = (L::splat(inp.ch[0][a]), L::splat(inp.ch[1][a]), L::splat(inp.pr[a]));
    let (deva, inv_fdp) = (L::splat(inp.ch[5][a]), L::splat(inv_fdp));
    let (mut drho, mut apx, mut apz, mut s1, mut s2, mut s3) = (zero, zero, zero, zero, zero, zero);
    let (mut dsum, mut gcx, mut gcz) = (zero, zero, zero);
    let (mut gu0, mut gu1, mut gu2, mut gu3) = (zero, zero, zero, zero);
    let [pux, puz, pmp, pm, pv, pdev, pvd] = inp.ch.map(|c| c.as_ptr());
    // With 16 vector registers (`SPLIT`: the AVX2 build) the 13 sums of the extra terms, their
    // constants and temporaries do not fit in one loop, which then spills to the stack every chunk.
    // Two loops over the chunks — the pressure, viscous and ∇u sums (parts 1 and 4), then δ-SPH
    // and the shifting gradient (part 2) — re-load the chunk's lanes instead: rate phase 4–5 %
    // faster on a Zen 2 (nodes/sph/PERF.md; other groupings were no faster or slower). Every sum
    // sees the same operations in the same order either way (same bits:
    // `avx_and_portable_lanes_give_the_same_bits`).
    let parts: &[u8] = if EX && SPLIT { &[5, 2] } else { &[7] };
    for &part in parts {
        for (j, ck) in chunks.iter().enumerate() {
            let i = ck.i as usize;
            // SAFETY: i < n and the slices hold n + PAD ≥ i + 8 values (caller).
            let ld = |p: *const f32| unsafe { L::load(p.add(i)) };
            // SAFETY: the scratch lanes hold 8 per chunk, written by pass 1.
            let lds = |p: *const f32| unsafe { L::load(p.add(8 * j)) };
            let (dx, dz, fr) = (lds(ldx), lds(ldz), lds(lfr));
            let (gx, gz) = (dx.mul(fr), dz.mul(fr));
            let dux = uax.sub(ld(pux));
            let duz = uaz.sub(ld(puz));
            let v = ld(pv);
            if part & 1 != 0 {
                let f = lds(lf);
                let m = ld(pm);
                drho = m.mul_add(duz.mul_add(gz, dux.mul(gx)), drho);
                let pt = m.mul_add(pa, ld(pmp));
                apx = pt.mul_add(gx, apx);
                apz = pt.mul_add(gz, apz);
                if MV {
                    let vw = v.mul(f);
                    s1 = dux.mul_add(vw, s1);
                    s2 = duz.mul_add(vw, s2);
                    s3 = s3.add(vw);
                } else {
                    let vk = v.mul(lds(lkk));
                    s1 = vk.mul_add(dux, s1);
                    s2 = vk.mul_add(duz, s2);
                }
            }
            if EX && part & 2 != 0 {
                let kk = lds(lkk);
                dsum = ld(pvd).mul(ld(pdev).sub(deva)).mul_add(kk, dsum);
                let q = lds(lf).mul(inv_fdp);
                let q2 = q.mul(q);
                let corr = v.mul(q2.mul(q2).mul_add(c02, one));
                gcx = corr.mul_add(gx, gcx);
                gcz = corr.mul_add(gz, gcz);
            }
            if EX && part & 4 != 0 {
                let (vgx, vgz) = (v.mul(gx), v.mul(gz));
                gu0 = dux.mul_add(vgx, gu0);
                gu1 = dux.mul_add(vgz, gu1);
                gu2 = duz.mul_add(vgx, gu2);
                gu3 = duz.mul_add(vgz, gu3);
            }
        }
    }
    let mut s = Sums {
        drho: sum_f64(drho),
        apx: sum_f64(apx),
        apz: sum_f64(apz),
        s1: sum_f64(s1),
        s2: sum_f64(s2),
        s3: sum_f64(s3),
        r2min: r2min_of(r2min),
        ..Default::default()
    };
    if EX {
        s.dsum = sum_f64(dsum);
        s.gc = [sum_f64(gcx), sum_f64(gcz)];
        s.gu = [sum_f64(gu0), sum_f64(gu1), sum_f64(gu2), sum_f64(gu3)];
    }
    s
}

/// Rates of the particles of cells `c0..c1` into `out` (their sorted range).
///
/// # Safety
/// `L::available()`; the slices of `inp` are padded with [`PAD`] entries.
#[inline(always)]
pub(super) unsafe fn rates_cells<L: Lanes, S: Shape, const MV: bool, const EX: bool, const SPLIT: bool>(
    inp: &RatesIn,
    c0: usize,
    c1: usize,
    out: &mut [Rate],
    sc: &mut Scratch,
) {
    let k = &inp.k;
    let grid = inp.pos.grid;
    let base = grid.range(c0).0;
    for c in c0..c1 {
        let (s, e) = grid.range(c);
        if inp.wall[s..e].iter().all(|&w| w) {
            out[s - base..e - base].fill(Rate::default());
            continue;
        }
        let shifted = sc.cell::<false>(grid, inp.frames, c, &[]);
        for a in s..e {
            if inp.wall[a] {
                out[a - base] = Rate::default();
                continue;
            }
            let (ra, ma) = (inp.rho[a], inp.mass[a]);
            let inv_fdp =
                if EX && k.shifting { (1.0 / (k.f_scalar)((ma / k.rho0).sqrt() * k.inv_h)) as f32 } else { 1.0 };
            // SAFETY: L::available() and padding (caller).
            let sm = unsafe { pair_sums::<L, S, MV, EX, SPLIT>(inp, sc, shifted, a, inv_fdp) };
            out[a - base] = finish::<S, MV, EX>(k, &sm, ra);
        }
    }
}

/// Rate of one particle from its lane sums (f64).
#[inline(always)]
pub(super) fn finish<S: Shape, const MV: bool, const EX: bool>(k: &RateConsts, s: &Sums, ra: Real) -> Rate {
    let mut drho = k.grad * s.drho;
    let (avx, avz) = if MV {
        // the own lane put V_a f_s(0) into s3: the self term of the Shepard denominator
        let sc = -k.c_mu / ra / s.s3;
        (sc * s.s1, sc * s.s2)
    } else {
        let sc = 2.0 * k.mu / ra * (k.grad * k.inv_h);
        (sc * s.s1, sc * s.s2)
    };
    let mut rate = Rate {
        drho,
        acc: [avx - k.grad * s.apx + k.g[0], avz - k.grad * s.apz + k.g[1]],
        r2min: if s.r2min < S::CUT * S::CUT { s.r2min * k.h * k.h } else { Real::INFINITY },
        ..Default::default()
    };
    if EX {
        if k.delta_hc2 > 0.0 {
            drho -= k.delta_hc2 * (k.grad * k.inv_h) * s.dsum;
            rate.drho = drho;
        }
        if k.shifting {
            rate.grad_c = [k.grad * s.gc[0], k.grad * s.gc[1]];
            rate.grad_u = s.gu.map(|v| -k.grad * v);
        }
    }
    rate
}

/// Sorted particle data and constants of the wall pass.
pub(super) struct WallIn<'a> {
    pub(super) pos: Pos<'a>,
    pub(super) frames: &'a Frames,
    pub(super) kind: &'a [ParticleKind],
    /// ux, uz, p, ρ, (1 non-wall, 0 wall) — f32, padded.
    pub(super) ch: [&'a [f32]; 5],
    /// Sorted position → particle index.
    pub(super) order: &'a [u32],
    /// Number of non-wall particles before each sorted index (n + 1 values).
    pub(super) fluid: &'a [u32],
    /// Prescribed wall velocity (f64, particle order).
    pub(super) vx: &'a [Real],
    pub(super) vz: &'a [Real],
    pub(super) h: Real,
    pub(super) g: [Real; 2],
    pub(super) rho0: Real,
    pub(super) c2: Real,
    pub(super) pb: Real,
}

/// Wall values (ux, uz, p, ρ) of the wall particles of cells `c0..c1` into `out` (their sorted
/// range; zeros for non-walls): Shepard means over the non-wall neighbours as in
/// [`crate::wcsph::compute_rates`].
///
/// # Safety
/// `L::available()`; the slices of `inp` are padded with [`PAD`] entries.
#[inline(always)]
pub(super) unsafe fn wall_cells<L: Lanes, S: Shape>(
    inp: &WallIn,
    c0: usize,
    c1: usize,
    out: &mut [[Real; 4]],
    sc: &mut Scratch,
) {
    let grid = inp.pos.grid;
    let base = grid.range(c0).0;
    let (pxh, pxl, pz) = (inp.pos.xh.as_ptr(), inp.pos.xl.as_ptr(), inp.pos.zr.as_ptr());
    let [pux, puz, pp, prho, pfl] = inp.ch.map(|c| c.as_ptr());
    for c in c0..c1 {
        let (s, e) = grid.range(c);
        out[s - base..e - base].fill([0.0; 4]);
        if !inp.kind[s..e].iter().any(|k| k.is_wall()) {
            continue;
        }
        let shifted = sc.cell::<true>(grid, inp.frames, c, inp.fluid);
        let chunks = &sc.chunks[..sc.n];
        assert!(sc.lane.iter().all(|l| l.len() >= 8 * chunks.len()));
        let [ldx, ldz, lf, ..] = &mut sc.lane;
        let (ldx, ldz, lf) = (ldx.as_mut_ptr(), ldz.as_mut_ptr(), lf.as_mut_ptr());
        for w in s..e {
            if !inp.kind[w].is_wall() {
                continue;
            }
            let (zero, tiny, far) = (L::splat(0.0), L::splat(TINY2), L::splat(FAR));
            // pass 1: geometry and kernel (as in the rate pass)
            let fr = frames_of(inp.pos.xoh[w], &inp.frames.shifts, shifted);
            let zra = L::splat(inp.pos.zr[w]);
            for (j, ck) in chunks.iter().enumerate() {
                let i = ck.i as usize;
                // SAFETY: i < n and the slices hold n + PAD ≥ i + 8 values (caller).
                let ld = |p: *const f32| unsafe { L::load(p.add(i)) };
                // SAFETY: L::available() (caller); k ≤ 8.
                let mk = unsafe { mask::<L>(ck.k as usize) };
                let fj = 2 * ck.frame as usize;
                let dx = L::splat(fr[fj]).sub(ld(pxh)).add(L::splat(fr[fj + 1]).sub(ld(pxl)));
                let dx = far.blend(dx, mk);
                let dz = zra.add(L::splat(ck.dz)).sub(ld(pz));
                let rr = dz.mul_add(dz, dx.mul_add(dx, tiny)).sqrt();
                // SAFETY: the scratch lanes hold 8 per chunk (asserted).
                unsafe {
                    L::store(ldx.add(8 * j), dx);
                    L::store(ldz.add(8 * j), dz);
                    L::store(lf.add(8 * j), S::f(rr));
                }
            }
            // pass 2: Shepard sums over the non-wall lanes
            let (mut sw, mut sux, mut suz, mut sp, mut srx, mut srz) = (zero, zero, zero, zero, zero, zero);
            for (j, ck) in chunks.iter().enumerate() {
                let i = ck.i as usize;
                // SAFETY: i < n and the slices hold n + PAD ≥ i + 8 values (caller).
                let ld = |p: *const f32| unsafe { L::load(p.add(i)) };
                // SAFETY: the scratch lanes hold 8 per chunk, written by pass 1.
                let lds = |p: *const f32| unsafe { L::load(p.add(8 * j)) };
                let (dx, dz) = (lds(ldx), lds(ldz));
                let wf = lds(lf).mul(ld(pfl));
                sw = sw.add(wf);
                sux = ld(pux).mul_add(wf, sux);
                suz = ld(puz).mul_add(wf, suz);
                sp = ld(pp).mul_add(wf, sp);
                let rho = ld(prho);
                srx = rho.mul(dx).mul_add(wf, srx);
                srz = rho.mul(dz).mul_add(wf, srz);
            }
            let sw = sum_f64(sw);
            let i = inp.order[w] as usize;
            let (vwx, vwz) = (inp.vx[i], inp.vz[i]);
            out[w - base] = if sw > 0.0 {
                let (sux, suz) = (sum_f64(sux), sum_f64(suz));
                let sg = inp.h * (inp.g[0] * sum_f64(srx) + inp.g[1] * sum_f64(srz));
                let pw = (sum_f64(sp) + sg) / sw;
                let rw = inp.rho0 + (pw - inp.pb) / inp.c2;
                match inp.kind[w] {
                    ParticleKind::WallOutside => [2.0 * vwx - sux / sw, 2.0 * vwz - suz / sw, pw, rw],
                    _ => [vwx, vwz, pw, rw],
                }
            } else {
                [vwx, vwz, inp.pb, inp.rho0]
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::neighbours::Period;

    /// The chunk lists and frames of every cell give each particle exactly its neighbours within
    /// the support (minimum image), each once, with (dx, dz) equal to the f64 minimum-image
    /// difference to f32 accuracy — reach 1, 2, 3, every periodic combination.
    #[test]
    fn chunks_cover_every_neighbour_once_with_exact_images() {
        let mut s = 0x9E37_79B9_7F4A_7C15u64;
        let mut rnd = || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 11) as Real / (1u64 << 53) as Real
        };
        let n = 700;
        let x: Vec<Real> = (0..n).map(|_| 3.0 + rnd()).collect();
        let z: Vec<Real> = (0..n).map(|_| rnd() * 0.7 - 0.2).collect();
        let px = Some(Period { min: 3.0, length: 1.0 });
        let pz = Some(Period { min: -0.2, length: 0.7 });
        let (r, h) = (0.13, 0.05);
        let inv_h = 1.0 / h;
        for reach in [1, 2, 3] {
            for (p, q) in [(None, None), (px, None), (None, pz), (px, pz)] {
                let mut g = Grid::default();
                assert!(g.build(&x, &z, r, reach, p, q));
                let fr = Frames::new(&g, inv_h);
                let order: Vec<usize> = g.order.iter().map(|&i| i as usize).collect();
                let xoh: Vec<Real> = order.iter().map(|&i| x[i] * inv_h).collect();
                let xh: Vec<f32> = xoh.iter().map(|&v| v as f32).collect();
                let xl: Vec<f32> = xoh.iter().zip(&xh).map(|(&v, &hi)| (v - hi as Real) as f32).collect();
                let mut zr = vec![0.0f32; n];
                for c in 0..g.cells() {
                    let (s, e) = g.range(c);
                    for k in s..e {
                        zr[k] = ((z[order[k]] - g.az_centre(c / g.ax.n)) * inv_h) as f32;
                    }
                }
                let mut sc = Scratch::default();
                for c in 0..g.cells() {
                    let shifted = sc.cell::<false>(&g, &fr, c, &[]);
                    let (s, e) = g.range(c);
                    for ka in s..e {
                        let a = order[ka];
                        let f = frames_of(xoh[ka], &fr.shifts, shifted);
                        let mut seen = Vec::new();
                        for ck in &sc.chunks[..sc.n] {
                            for l in 0..ck.k as usize {
                                let kb = ck.i as usize + l;
                                let j = 2 * ck.frame as usize;
                                let dx = (f[j] - xh[kb]) + (f[j + 1] - xl[kb]);
                                let dz = (zr[ka] + ck.dz) - zr[kb];
                                let b = order[kb];
                                let ex = p.map_or(x[a] - x[b], |p| p.image(x[a] - x[b])) * inv_h;
                                let ez = q.map_or(z[a] - z[b], |q| q.image(z[a] - z[b])) * inv_h;
                                if ex * ex + ez * ez < (r * inv_h).powi(2) {
                                    assert!((dx as Real - ex).abs() < 1e-6 && (dz as Real - ez).abs() < 1e-6);
                                    seen.push(b);
                                }
                            }
                        }
                        seen.sort_unstable();
                        let mut want: Vec<usize> = (0..n)
                            .filter(|&b| {
                                let dx = p.map_or(x[a] - x[b], |p| p.image(x[a] - x[b]));
                                let dz = q.map_or(z[a] - z[b], |q| q.image(z[a] - z[b]));
                                dx * dx + dz * dz < r * r
                            })
                            .collect();
                        want.sort_unstable();
                        assert_eq!(seen, want, "particle {a} reach {reach} periodic {p:?} {q:?}");
                    }
                }
            }
        }
    }
}
