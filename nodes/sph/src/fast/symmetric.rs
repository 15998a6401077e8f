//! Symmetric rate pass of the fast evaluator: every pair once (Newton's third law).
//!
//! Particle a visits only the forward half of its neighbourhood — the rest of its own cell row from
//! the next sorted particle on (its cell and the `reach` cells to its right) and the `reach` rows
//! above (all 2 reach + 1 columns) — computes each pair's geometry and kernel once (pass 1 of the
//! gather, [`geometry`]) and adds the pair's terms to its own lane sums and, with the signs of the
//! antisymmetric gradient, to the neighbours' f32 accumulators (8 consecutive sorted particles: one
//! vector load, one fused multiply-add, one store per channel).
//!
//! Conflict-free and deterministic: the cell rows are cut into *stripes* of whole rows, each with
//! more than `reach` rows and at least [`PAD`] particles past its first `reach` rows. A stripe
//! writes only its own rows, the first `reach` rows of the next stripe and, through the lanes past
//! a run's end (whose terms are exact zeros), at most 7 particles further: never a particle of the
//! stripe after next. The even stripes run (in parallel) first, then the odd ones; a particle
//! receives from at most two stripes, one per phase, each in its fixed serial order — the same
//! sums, bit for bit, with any number of threads or none. (A periodic z axis with an odd number of
//! stripes merges the last two so that the wrap joins stripes of different phases.)
//!
//! A particle's rate is then its own lane sums (f64) plus its received accumulators (f32 sums of
//! single lane terms, converted to f64) and, for the Shepard denominator of eq 12, the self term
//! V_a f_s(0) in f64.

use super::grid::Grid;
use super::kernels::{finish, geometry, Chunk, Frames, RateConsts, RatesIn, Scratch, Shape, Sums, PAD, R2_BIAS};
use super::lanes::{sum_f64, Lanes};
use crate::wcsph::Rate;
use crate::Real;

/// Received channels: Dρ/Dt, pressure x and z, viscous sums 1–3, r² minimum (u32 bits), diffusion,
/// ∇C x and z, ∇u (4).
pub(super) const NR: usize = 14;
const DRHO: usize = 0;
const APX: usize = 1;
const APZ: usize = 2;
const S1: usize = 3;
const S2: usize = 4;
const S3: usize = 5;
/// min(bits(r²) − [`R2_BIAS`]) as u32 bit patterns (u32::MAX: none).
pub(super) const R2: usize = 6;
const DSUM: usize = 7;
const GCX: usize = 8;
const GCZ: usize = 9;
const GU: usize = 10;
/// Channels in use without the extra terms (δ-SPH, shifting).
pub(super) const NR_BASIC: usize = 7;

/// Where the stripes write: the received accumulators (f32, sorted order, n + [`PAD`] each) and the
/// particles' own sums (sorted order).
#[derive(Clone, Copy)]
pub(super) struct SymOut {
    pub(super) acc: [*mut f32; NR],
    pub(super) own: *mut Sums,
}

// SAFETY: the stripes that run at the same time write disjoint index sets (module doc); the phases
// run one after the other.
unsafe impl Send for SymOut {}
// SAFETY: as above.
unsafe impl Sync for SymOut {}

/// Inputs of the symmetric pass.
pub(super) struct SymIn<'a> {
    pub(super) r: RatesIn<'a>,
    /// 1/f_s(Δp/h) of every particle (the shifting term's w(Δp)), f32, padded.
    pub(super) ifdp: &'a [f32],
    /// Number of non-wall particles before each sorted index (n + 1), empty without walls.
    pub(super) fluid: &'a [u32],
}

/// Stripes of whole cell rows (module doc), as cell ranges.
pub(super) fn stripes(grid: &Grid, periodic_z: bool, min_particles: usize, out: &mut Vec<(usize, usize)>) {
    let (nx, nz, reach) = (grid.ax.n, grid.az.n, grid.reach());
    let row = |j: usize| (grid.cell_start[(j + 1) * nx] - grid.cell_start[j * nx]) as usize;
    out.clear();
    let (mut r0, mut rows, mut total, mut beyond) = (0, 0, 0, 0);
    for j in 0..nz {
        let c = row(j);
        rows += 1;
        total += c;
        if rows > reach {
            beyond += c;
        }
        if rows > reach && beyond >= PAD && total >= min_particles {
            out.push((r0 * nx, (j + 1) * nx));
            (r0, rows, total, beyond) = (j + 1, 0, 0, 0);
        }
    }
    if r0 < nz {
        match out.last_mut() {
            Some(last) => last.1 = nz * nx,
            None => out.push((0, nz * nx)),
        }
    }
    if periodic_z && out.len() > 1 && out.len() % 2 == 1 {
        if let Some((_, end)) = out.pop() {
            if let Some(last) = out.last_mut() {
                last.1 = end;
            }
        }
    }
}

/// Chunks of ≤ 8 of the run `s..e` at `chunks[*n..]`.
#[inline]
fn push_run(chunks: &mut Vec<Chunk>, n: &mut usize, s: usize, e: usize, frame: u8, own: u8, dz: f32) {
    let mut i = s;
    while i < e {
        let k = (e - i).min(8);
        if chunks.len() <= *n {
            chunks.resize(*n + 16, Chunk::default());
        }
        chunks[*n] = Chunk { i: i as u32, k: k as u8, frame, own, dz };
        *n += 1;
        i += k;
    }
}

fn frame_of(shift: Real) -> u8 {
    if shift < 0.0 {
        1
    } else if shift > 0.0 {
        2
    } else {
        0
    }
}

/// The forward half of the neighbourhood of cell `c` as chunks: first the own row from the cell's
/// first particle to the end of the cell `reach` to the right (`own` chunks: each particle leaves
/// out the lanes up to itself), then its wrapped part on a periodic x axis, then the `reach` rows
/// above (all 2 reach + 1 columns). Sets `sc.n`; returns whether a shifted x frame is used and
/// whether the chunks past the own-row run hold a non-wall particle, and the own-row run's end.
fn half(sc: &mut Scratch, grid: &Grid, fr: &Frames, c: usize, fluid: &[u32]) -> (bool, bool, usize) {
    let (nx, reach) = (grid.ax.n, grid.reach());
    let (cx, cz) = (c % nx, c / nx);
    let starts = &grid.cell_start;
    let st = |jz: usize, x0: usize, x1: usize| (starts[jz * nx + x0] as usize, starts[jz * nx + x1 + 1] as usize);
    let fluid_in = |s: usize, e: usize| fluid.is_empty() || fluid[s] != fluid[e];
    let mut n = 0;
    let (row, nrow) = grid.ax.forward(cx, 0, reach);
    let dz0 = fr.dz[reach];
    let (s0, e0) = st(cz, row[0].0, row[0].1);
    push_run(&mut sc.chunks, &mut n, s0, e0, 0, 1, dz0);
    let mut any = false;
    if nrow == 2 {
        let (s1, e1) = st(cz, row[1].0, row[1].1);
        any |= s1 < e1 && fluid_in(s1, e1);
        push_run(&mut sc.chunks, &mut n, s1, e1, frame_of(row[1].2), 0, dz0);
    }
    let (cols, nc) = grid.ax.segments(cx, reach);
    let (rows, nr) = grid.az.forward(cz, 1, reach);
    let nz = grid.az.n as isize;
    for &(z0, z1, sz) in &rows[..nr] {
        let wrap = if sz > 0.0 { nz } else { 0 };
        for jz in z0..=z1 {
            let d = jz as isize + wrap - cz as isize + reach as isize;
            let dz = fr.dz[d as usize];
            for &(x0, x1, sx) in &cols[..nc] {
                let (s, e) = st(jz, x0, x1);
                any |= s < e && fluid_in(s, e);
                push_run(&mut sc.chunks, &mut n, s, e, frame_of(sx), 0, dz);
            }
        }
    }
    sc.n = n;
    for l in &mut sc.lane {
        if l.len() < 8 * n {
            l.resize(8 * n, 0.0);
        }
    }
    (nc > 1 || nrow == 2, any, e0)
}

/// Own sums and received accumulators of the pairs whose first particle lies in cells `c0..c1`.
///
/// # Safety
/// `L::available()`; the slices of `inp` and the accumulators of `out` hold n + [`PAD`] values, `own`
/// n; no other thread writes the indices this call writes (the stripes of one phase).
#[inline(always)]
pub(super) unsafe fn sym_cells<L: Lanes, S: Shape, const MV: bool, const EX: bool>(
    inp: &SymIn,
    c0: usize,
    c1: usize,
    out: SymOut,
    sc: &mut Scratch,
) {
    let r = &inp.r;
    let grid = r.pos.grid;
    let walls = !inp.fluid.is_empty();
    let fluid_in = |s: usize, e: usize| !walls || (s < e && inp.fluid[s] != inp.fluid[e]);
    let (zero, one, c02) = (L::splat(0.0), L::splat(1.0), L::splat(0.2));
    let [pux, puz, _, pm, pv, pdev, pvd] = r.ch.map(|c| c.as_ptr());
    let (ppr, pifd) = (r.pr.as_ptr(), inp.ifdp.as_ptr());
    // acc[ch][i..i + 8] = f(acc[ch][i..i + 8]): the neighbours' side of a chunk
    macro_rules! upd {
        ($i:expr, $ch:expr, |$b:ident| $e:expr) => {
            // SAFETY: the accumulators hold n + PAD ≥ i + 8 values; this stripe alone writes them
            // in this phase (caller).
            unsafe {
                let ptr = out.acc[$ch].add($i);
                let $b = L::load(ptr);
                L::store(ptr, $e);
            }
        };
    }
    for c in c0..c1 {
        let (s, e) = grid.range(c);
        if s == e {
            continue;
        }
        let (shifted, fluid_beyond, e0) = half(sc, grid, r.frames, c, inp.fluid);
        for a in s..e {
            if r.wall[a] && !(fluid_beyond || fluid_in(a + 1, e0)) {
                // SAFETY: a < n (caller).
                unsafe { *out.own.add(a) = Sums::default() };
                continue;
            }
            // own-row chunks wholly at or before a are skipped
            let chunks = &sc.chunks[(a + 1 - s) / 8..sc.n];
            // pass 1: geometry and kernel of every lane
            // SAFETY: L::available() and padding (caller).
            let r2min =
                unsafe { geometry::<L, S>(&r.pos, r.frames, chunks, &mut sc.lane, shifted, a, !MV || EX, true) };
            let [ldx, ldz, lf, lfr, lkk, lr2] = sc.lane.each_ref().map(|l| l.as_ptr());
            // pass 2: the particle's own sums and its neighbours' accumulators
            let (uax, uaz, pa) = (L::splat(r.ch[0][a]), L::splat(r.ch[1][a]), L::splat(r.pr[a]));
            let (ma, nma) = (L::splat(r.ch[3][a]), L::splat(-r.ch[3][a]));
            let (va, nva) = (L::splat(r.ch[4][a]), L::splat(-r.ch[4][a]));
            let (deva, nvda, ifa) = (L::splat(r.ch[5][a]), L::splat(-r.ch[6][a]), L::splat(inp.ifdp[a]));
            let (mut drho, mut apx, mut apz, mut s1s, mut s2s, mut s3s) = (zero, zero, zero, zero, zero, zero);
            let (mut dsum, mut gcx, mut gcz) = (zero, zero, zero);
            let (mut gu0, mut gu1, mut gu2, mut gu3) = (zero, zero, zero, zero);
            for (j, ck) in chunks.iter().enumerate() {
                let i = ck.i as usize;
                // SAFETY: i < n and the slices hold n + PAD ≥ i + 8 values (caller).
                let ld = |p: *const f32| unsafe { L::load(p.add(i)) };
                // SAFETY: the scratch lanes hold 8 per chunk, written by pass 1.
                let lds = |p: *const f32| unsafe { L::load(p.add(8 * j)) };
                let (dx, dz, f, fr) = (lds(ldx), lds(ldz), lds(lf), lds(lfr));
                let (gx, gz) = (dx.mul(fr), dz.mul(fr));
                let dux = uax.sub(ld(pux));
                let duz = uaz.sub(ld(puz));
                let m = ld(pm);
                // continuity: m_b (u_a − u_b)·∇_a W for a, m_a (u_a − u_b)·∇_a W for b
                let dg = duz.mul_add(gz, dux.mul(gx));
                drho = m.mul_add(dg, drho);
                upd!(i, DRHO, |b| ma.mul_add(dg, b));
                // pressure: (p_a/ρ_a² + p_b/ρ_b²) ∇_a W, times m_b for a and −m_a for b
                let pt = pa.add(ld(ppr));
                let (ptx, ptz) = (pt.mul(gx), pt.mul(gz));
                apx = m.mul_add(ptx, apx);
                apz = m.mul_add(ptz, apz);
                upd!(i, APX, |b| nma.mul_add(ptx, b));
                upd!(i, APZ, |b| nma.mul_add(ptz, b));
                let v = ld(pv);
                let kk = if !MV || EX { lds(lkk) } else { zero };
                if MV {
                    let vw = v.mul(f);
                    s1s = dux.mul_add(vw, s1s);
                    s2s = duz.mul_add(vw, s2s);
                    s3s = s3s.add(vw);
                    let nvw = nva.mul(f);
                    upd!(i, S1, |b| dux.mul_add(nvw, b));
                    upd!(i, S2, |b| duz.mul_add(nvw, b));
                    upd!(i, S3, |b| b.sub(nvw));
                } else {
                    let vk = v.mul(kk);
                    s1s = vk.mul_add(dux, s1s);
                    s2s = vk.mul_add(duz, s2s);
                    let nvk = nva.mul(kk);
                    upd!(i, S1, |b| nvk.mul_add(dux, b));
                    upd!(i, S2, |b| nvk.mul_add(duz, b));
                }
                upd!(i, R2, |b| b.min_bits_sub(lds(lr2), R2_BIAS));
            }
            // the extra terms in a second sweep (fewer live registers than one sweep with all 14)
            if EX {
                for (j, ck) in chunks.iter().enumerate() {
                    let i = ck.i as usize;
                    // SAFETY: i < n and the slices hold n + PAD ≥ i + 8 values (caller).
                    let ld = |p: *const f32| unsafe { L::load(p.add(i)) };
                    // SAFETY: the scratch lanes hold 8 per chunk, written by pass 1.
                    let lds = |p: *const f32| unsafe { L::load(p.add(8 * j)) };
                    let (dx, dz, f, fr, kk) = (lds(ldx), lds(ldz), lds(lf), lds(lfr), lds(lkk));
                    let (gx, gz) = (dx.mul(fr), dz.mul(fr));
                    let dux = uax.sub(ld(pux));
                    let duz = uaz.sub(ld(puz));
                    let v = ld(pv);
                    let ddk = ld(pdev).sub(deva).mul(kk);
                    dsum = ld(pvd).mul_add(ddk, dsum);
                    upd!(i, DSUM, |b| nvda.mul_add(ddk, b));
                    let q = f.mul(ifa);
                    let q2 = q.mul(q);
                    let corr = v.mul(q2.mul(q2).mul_add(c02, one));
                    gcx = corr.mul_add(gx, gcx);
                    gcz = corr.mul_add(gz, gcz);
                    let qb = f.mul(ld(pifd));
                    let qb2 = qb.mul(qb);
                    let ncorr = nva.mul(qb2.mul(qb2).mul_add(c02, one));
                    upd!(i, GCX, |b| ncorr.mul_add(gx, b));
                    upd!(i, GCZ, |b| ncorr.mul_add(gz, b));
                    let (vgx, vgz) = (v.mul(gx), v.mul(gz));
                    gu0 = dux.mul_add(vgx, gu0);
                    gu1 = dux.mul_add(vgz, gu1);
                    gu2 = duz.mul_add(vgx, gu2);
                    gu3 = duz.mul_add(vgz, gu3);
                    let (wgx, wgz) = (va.mul(gx), va.mul(gz));
                    upd!(i, GU, |b| dux.mul_add(wgx, b));
                    upd!(i, GU + 1, |b| dux.mul_add(wgz, b));
                    upd!(i, GU + 2, |b| duz.mul_add(wgx, b));
                    upd!(i, GU + 3, |b| duz.mul_add(wgz, b));
                }
            }
            let mut sm = Sums {
                drho: sum_f64(drho),
                apx: sum_f64(apx),
                apz: sum_f64(apz),
                s1: sum_f64(s1s),
                s2: sum_f64(s2s),
                s3: sum_f64(s3s),
                r2min: super::kernels::r2min_of(r2min),
                ..Default::default()
            };
            if EX {
                sm.dsum = sum_f64(dsum);
                sm.gc = [sum_f64(gcx), sum_f64(gcz)];
                sm.gu = [sum_f64(gu0), sum_f64(gu1), sum_f64(gu2), sum_f64(gu3)];
            }
            // SAFETY: a < n (caller).
            unsafe { *out.own.add(a) = sm };
        }
    }
}

/// Rate of sorted particle `i` from its own sums, its received accumulators and (mean-value term)
/// the self term `self_w` = V_a f_s(0) of the Shepard denominator.
#[inline(always)]
pub(super) fn combine<S: Shape, const MV: bool, const EX: bool>(
    k: &RateConsts,
    own: &Sums,
    acc: &[&[f32]; NR],
    i: usize,
    ra: Real,
    self_w: Real,
) -> Rate {
    let g = |c: usize| acc[c][i] as Real;
    let mut s = *own;
    s.drho += g(DRHO);
    s.apx += g(APX);
    s.apz += g(APZ);
    s.s1 += g(S1);
    s.s2 += g(S2);
    if MV {
        s.s3 += g(S3) + self_w;
    }
    let bits = acc[R2][i].to_bits();
    if bits != u32::MAX {
        s.r2min = s.r2min.min(f32::from_bits(bits.wrapping_add(R2_BIAS)) as Real);
    }
    if EX {
        s.dsum += g(DSUM);
        s.gc = [s.gc[0] + g(GCX), s.gc[1] + g(GCZ)];
        s.gu = [s.gu[0] + g(GU), s.gu[1] + g(GU + 1), s.gu[2] + g(GU + 2), s.gu[3] + g(GU + 3)];
    }
    finish::<S, MV, EX>(k, &s, ra)
}
