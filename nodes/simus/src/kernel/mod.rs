//! Fast f32 kernel: incremental phase stepping with exact re-anchoring (pymust-notes §5.6–5.7,
//! ultrasound-anchors §4.1).
//!
//! For one block of scatterers and a contiguous range of frequency bins it accumulates
//! `U_e(k) = Σ_s RC_s T_s(k) R_se(k)`, `T_s(k) = Σ_e' D_e'(k) R_se'(k)`, where
//! `R_se(k) = Σ_m P_sem(k)` and `D_e(k) = apod_e exp(2πi f_k τ_e)`. The phasors are set exactly
//! at the first bin of the range (phase reduced in f64, then an f32 sin/cos accurate to ~1e-7),
//! then stepped `P ← P·E`, `E = exp((−β + 2πi/c) df r)`, in complex f32 as MUST does — but only
//! across one range of at most `reanchor_every` bins (MUST steps across the whole band and
//! drifts by up to 3.3e-5 rad; here the drift stays below ~1e-5 rad).
//!
//! Layout: lanes = elements (16 per vector), so the transmit sum is a vertical sum plus one
//! horizontal reduction per (scatterer, bin); the receive accumulation reads and writes one row
//! `U[k][·]` per group of [`G`] scatterers. Each phasor is loaded once per `NB` = 2 bins, and
//! with 32 vector registers two chunks are processed together (4 independent recursion chains
//! for M = 2, as the complex multiply's 7-cycle latency needs ≥ 4 chains in flight). With 16
//! registers (AVX2, a 16-lane vector in two of them) the phasor pass runs on each 8-lane half in
//! turn, so that a chunk's state stays in registers ([`simd::Lanes::SPLIT`]). The generic code
//! is instantiated for the vector types of [`simd`].

// Lane loops index several arrays in lockstep: plain index loops keep them vectorisable.
#![allow(clippy::needless_range_loop)]

use std::ops::Range;

pub(crate) use crate::lanes::{L, V};
use crate::pfield::{ArrayGeom, BlockGeom};
use simd::Lanes;

pub(crate) mod simd;

/// Scatterers per receive group.
pub(crate) const G: usize = 4;
/// Bins per pass over the phasors.
const NB: usize = 2;
/// Chunks of 16 elements processed together in pass 1 (builds with 32 vector registers).
const CW: usize = 2;

/// General delays: `D_e(k)` complex, per bin.
pub(crate) const TX_COMPLEX: u8 = 0;
/// No delays: `D_e(k) = apod_e` real and constant.
pub(crate) const TX_REAL: u8 = 1;
/// No delays and unit weights (padding lanes still 0: their phasors are 0).
pub(crate) const TX_UNIT: u8 = 2;

/// Per-bin transmit tables of one call: `D_e(k)` in f32, `[bin][chunk]`, and the frequencies.
#[derive(Clone, Debug, Default)]
pub(crate) struct Tables {
    pub d_re: Vec<V>,
    pub d_im: Vec<V>,
    pub freqs: Vec<f64>,
    /// Transmit kind: [`TX_COMPLEX`], [`TX_REAL`] (all delays 0: `D_e(k) = apod_e`, the same
    /// for every bin) or [`TX_UNIT`] (all delays 0 and all weights 1).
    pub tx: u8,
}

/// Working memory of one bin range (one parallel task).
#[derive(Clone, Debug, Default)]
pub(crate) struct Scratch {
    p_re: Vec<V>,
    p_im: Vec<V>,
    r_re: Vec<V>,
    r_im: Vec<V>,
    turn: Vec<V>,
    aamp: Vec<V>,
    dir: Vec<V>,
    /// f32 partial sums of the current scatterer block, `[k][chunk]`.
    pub s_re: Vec<V>,
    pub s_im: Vec<V>,
}

impl Scratch {
    pub fn prepare(&mut self, geom: &ArrayGeom, n_bins: usize) {
        let nc = geom.e_pad / L;
        let np = G * geom.m * nc;
        for v in [&mut self.p_re, &mut self.p_im, &mut self.turn, &mut self.aamp] {
            v.resize(np, V::default());
        }
        self.dir.resize(if geom.ffd { np } else { 0 }, V::default());
        self.r_re.resize(NB * G * nc, V::default());
        self.r_im.resize(NB * G * nc, V::default());
        for v in [&mut self.s_re, &mut self.s_im] {
            v.clear();
            v.resize(n_bins * nc, V::default());
        }
    }
}

/// Accumulates block `blk` (its size a multiple of [`G`]) into `sc.s_re/s_im` (rows indexed
/// from `bins.start`) for the band bins `bins` (indices into `tab.freqs`).
#[inline(always)]
pub(crate) fn accumulate<S: Lanes>(
    geom: &ArrayGeom,
    blk: &BlockGeom,
    tab: &Tables,
    bins: Range<usize>,
    sc: &mut Scratch,
) {
    match (geom.ffd, tab.tx, geom.m) {
        (true, _, _) => run::<S, 0, true, TX_COMPLEX>(geom, blk, tab, bins, sc),
        (false, TX_UNIT, 1) => run::<S, 1, false, TX_UNIT>(geom, blk, tab, bins, sc),
        (false, TX_UNIT, 2) => run::<S, 2, false, TX_UNIT>(geom, blk, tab, bins, sc),
        (false, TX_UNIT, _) => run::<S, 0, false, TX_UNIT>(geom, blk, tab, bins, sc),
        (false, TX_REAL, 1) => run::<S, 1, false, TX_REAL>(geom, blk, tab, bins, sc),
        (false, TX_REAL, 2) => run::<S, 2, false, TX_REAL>(geom, blk, tab, bins, sc),
        (false, TX_REAL, _) => run::<S, 0, false, TX_REAL>(geom, blk, tab, bins, sc),
        (false, _, 1) => run::<S, 1, false, TX_COMPLEX>(geom, blk, tab, bins, sc),
        (false, _, 2) => run::<S, 2, false, TX_COMPLEX>(geom, blk, tab, bins, sc),
        (false, _, _) => run::<S, 0, false, TX_COMPLEX>(geom, blk, tab, bins, sc),
    }
}

/// `M` = sub-elements per element when known at compile time, 0 = `geom.m` at run time.
#[inline(always)]
fn run<S: Lanes, const M: usize, const FFD: bool, const TX: u8>(
    geom: &ArrayGeom,
    blk: &BlockGeom,
    tab: &Tables,
    bins: Range<usize>,
    sc: &mut Scratch,
) {
    let Some(&f_a) = tab.freqs.get(bins.start) else { return };
    let mm = if M == 0 { geom.m } else { M };
    let mut g0 = 0;
    while g0 + G <= blk.n_s {
        anchor::<S>(geom, blk, g0, mm, f_a, sc);
        let mut k = bins.start;
        while k < bins.end {
            if FFD {
                directivity::<S>(geom, blk, g0, tab.freqs[k], sc);
                step::<S, 1, M, FFD, TX, 1>(geom, blk, tab, g0, k, k - bins.start, sc);
                k += 1;
            } else if k + NB <= bins.end {
                if S::WIDE {
                    step::<S, NB, M, FFD, TX, CW>(geom, blk, tab, g0, k, k - bins.start, sc);
                } else {
                    step::<S, NB, M, FFD, TX, 1>(geom, blk, tab, g0, k, k - bins.start, sc);
                }
                k += NB;
            } else {
                step::<S, 1, M, FFD, TX, 1>(geom, blk, tab, g0, k, k - bins.start, sc);
                k += 1;
            }
        }
        g0 += G;
    }
}

/// `exp(x)` for `x <= 0` in f32 (relative error ~2e-7; 0 below −87).
#[inline(always)]
fn exp_nonpos<S: Lanes>(x: S) -> S {
    const MAGIC32: f32 = 12_582_912.0;
    let x = x.max(S::splat(-87.0));
    let n = x.mul(S::splat(std::f32::consts::LOG2_E)).add(S::splat(MAGIC32)).sub(S::splat(MAGIC32));
    let r = n.neg_mul_add(S::splat(0.693_145_75), x);
    let r = n.neg_mul_add(S::splat(1.428_606_8e-6), r);
    let p = r.mul_add(S::splat(1.0 / 5040.0), S::splat(1.0 / 720.0));
    let p = r.mul_add(p, S::splat(1.0 / 120.0));
    let p = r.mul_add(p, S::splat(1.0 / 24.0));
    let p = r.mul_add(p, S::splat(1.0 / 6.0));
    let p = r.mul_add(p, S::splat(0.5));
    let p = r.mul_add(p, S::splat(1.0));
    let p = r.mul_add(p, S::splat(1.0));
    p.scalef(n)
}

/// Exact phasors of scatterers `g0..g0+G` at frequency `f`: the phase `f r / c` (turns) is
/// reduced to [−½, ½] in f64, then `amp·exp(−β f r)·(cos, sin)(2π u)` is evaluated in f32
/// (error ~1e-7).
#[inline(always)]
fn anchor<S: Lanes>(geom: &ArrayGeom, blk: &BlockGeom, g0: usize, mm: usize, f: f64, sc: &mut Scratch) {
    let nc = geom.e_pad / L;
    let np = G * nc * mm;
    let src0 = g0 * nc * mm;
    let turns = f * geom.inv_c;
    let att = -geom.beta * f;
    for i in 0..np {
        let src = (src0 + i) * L;
        let (r, a) = (&blk.r[src..src + L], &blk.amp[src..src + L]);
        let u = S::frac_turns(r, turns);
        let mut a = S::scaled(a, 1.0);
        if geom.beta > 0.0 {
            a = a.mul(exp_nonpos(S::scaled(r, att)));
        }
        let (sin, cos) = sincos_turns::<S>(u);
        a.mul(cos).store(&mut sc.p_re[i]);
        a.mul(sin).store(&mut sc.p_im[i]);
    }
}

/// `(sin 2πu, cos 2πu)` in f32 for |u| ≤ ½ (absolute error ~1e-7): octant reduction, Taylor
/// polynomials on |x| ≤ π/4, then an exact rotation by the quarter turns.
#[inline(always)]
fn sincos_turns<S: Lanes>(u: S) -> (S, S) {
    const MAGIC32: f32 = 12_582_912.0;
    let q = u.mul(S::splat(4.0)).add(S::splat(MAGIC32)).sub(S::splat(MAGIC32)); // round(4u)
    let x = q.neg_mul_add(S::splat(0.25), u).mul(S::splat(std::f32::consts::TAU)); // |x| <= pi/4
    let x2 = x.mul(x);
    let sp = x2.mul_add(S::splat(1.0 / 362_880.0), S::splat(-1.0 / 5040.0));
    let sp = x2.mul_add(sp, S::splat(1.0 / 120.0));
    let sp = x2.mul_add(sp, S::splat(-1.0 / 6.0));
    let sp = x2.mul_add(sp, S::splat(1.0));
    let s = x.mul(sp);
    let cp = x2.mul_add(S::splat(1.0 / 40_320.0), S::splat(-1.0 / 720.0));
    let cp = x2.mul_add(cp, S::splat(1.0 / 24.0));
    let cp = x2.mul_add(cp, S::splat(-0.5));
    let c = x2.mul_add(cp, S::splat(1.0));
    // rotate by q quarter turns, q in {-2..2}: cos(q pi/2) = 1 - y + y (y - 1)/6,
    // sin(q pi/2) = q (4 - y)/3, y = q^2 (exact in f32 for these q)
    let y = q.mul(q);
    let cq = y.mul(y.sub(S::splat(1.0))).mul(S::splat(1.0 / 6.0)).add(S::splat(1.0).sub(y));
    let sq = q.mul(S::splat(4.0).sub(y)).mul(S::splat(1.0 / 3.0));
    (s.mul_add(cq, c.mul(sq)), s.neg_mul_add(sq, c.mul(cq)))
}

/// Full-frequency directivity of every phasor of the group at frequency `f`: MUST's
/// `sin(|x| + 1e-16)/(|x| + 1e-16)`, `x = k(f) W/(2M) sin θ = dirb·f`, in f32 (error ~1e-7).
#[inline(always)]
fn directivity<S: Lanes>(geom: &ArrayGeom, blk: &BlockGeom, g0: usize, f: f64, sc: &mut Scratch) {
    const MAGIC32: f32 = 12_582_912.0;
    let n = G * geom.e_pad / L * geom.m;
    let src0 = g0 * geom.e_pad * geom.m;
    for i in 0..n {
        let src = src0 + i * L;
        let x = S::scaled(&blk.dirb[src..src + L], f).add(S::splat(1e-16));
        let t = x.mul(S::splat(1.0 / std::f32::consts::TAU));
        let u = t.sub(t.add(S::splat(MAGIC32)).sub(S::splat(MAGIC32)));
        let (sin, _) = sincos_turns::<S>(u);
        sin.div(x).store(&mut sc.dir[i]);
    }
}

/// The phasor state and steppers of one scatterer, `[chunk][m]`.
struct Phasors<'a> {
    p_re: &'a mut [V],
    p_im: &'a mut [V],
    e_re: &'a [V],
    e_im: &'a [V],
    dir: &'a [V],
}

/// Pass 1 for `CW` consecutive chunks from `c` of one scatterer (`gi`): sums the sub-element
/// phasors into R (stored for pass 2), accumulates the transmit sums `tr`, `ti` and advances
/// the phasors by `N` bins. Several chunks at once give the out-of-order core independent
/// recursion chains to overlap.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn chunks<S: simd::Ops, const N: usize, const M: usize, const FFD: bool, const TX: u8, const CW: usize>(
    ph: Phasors<'_>,
    tab: &Tables,
    mm: usize,
    nc: usize,
    c: usize,
    k: usize,
    gi: usize,
    r_re_all: &mut [V],
    r_im_all: &mut [V],
    tr: &mut [S; N],
    ti: &mut [S; N],
) {
    let span = c * mm..(c + CW) * mm;
    let (pr_c, pi_c) = (&mut ph.p_re[span.clone()], &mut ph.p_im[span.clone()]);
    let (er_c, ei_c) = (&ph.e_re[span.clone()], &ph.e_im[span]);
    let mut rr = [[S::zero(); N]; CW];
    let mut ri = [[S::zero(); N]; CW];
    if M > 0 && !FFD {
        // all CW·M recursion chains advance together, one bin at a time (independent chains
        // interleaved for the out-of-order core)
        let mut pr = [[S::zero(); M]; CW];
        let mut pi = [[S::zero(); M]; CW];
        let mut er = [[S::zero(); M]; CW];
        let mut ei = [[S::zero(); M]; CW];
        for w in 0..CW {
            for m in 0..M {
                let i = w * M + m;
                er[w][m] = S::load(&er_c[i]);
                ei[w][m] = S::load(&ei_c[i]);
                pr[w][m] = S::load(&pr_c[i]);
                pi[w][m] = S::load(&pi_c[i]);
            }
        }
        for b in 0..N {
            for w in 0..CW {
                rr[w][b] = pr[w][0];
                ri[w][b] = pi[w][0];
                for m in 1..M {
                    rr[w][b] = rr[w][b].add(pr[w][m]);
                    ri[w][b] = ri[w][b].add(pi[w][m]);
                }
            }
            for w in 0..CW {
                for m in 0..M {
                    let (a, bb) = (pr[w][m], pi[w][m]);
                    pr[w][m] = bb.neg_mul_add(ei[w][m], a.mul(er[w][m]));
                    pi[w][m] = a.mul_add(ei[w][m], bb.mul(er[w][m]));
                }
            }
        }
        for w in 0..CW {
            for m in 0..M {
                let i = w * M + m;
                pr[w][m].store(&mut pr_c[i]);
                pi[w][m].store(&mut pi_c[i]);
            }
        }
    } else {
        for m in 0..mm {
            for w in 0..CW {
                let i = w * mm + m;
                let er = S::load(&er_c[i]);
                let ei = S::load(&ei_c[i]);
                let mut pr = S::load(&pr_c[i]);
                let mut pi = S::load(&pi_c[i]);
                for b in 0..N {
                    if FFD {
                        let d = S::load(&ph.dir[c * mm + i]);
                        rr[w][b] = d.mul_add(pr, rr[w][b]);
                        ri[w][b] = d.mul_add(pi, ri[w][b]);
                    } else if m == 0 {
                        rr[w][b] = pr;
                        ri[w][b] = pi;
                    } else {
                        rr[w][b] = rr[w][b].add(pr);
                        ri[w][b] = ri[w][b].add(pi);
                    }
                    let nr = pi.neg_mul_add(ei, pr.mul(er));
                    let ni = pr.mul_add(ei, pi.mul(er));
                    pr = nr;
                    pi = ni;
                }
                pr.store(&mut pr_c[i]);
                pi.store(&mut pi_c[i]);
            }
        }
    }
    let rows = c * N * G..(c + CW) * N * G;
    let (rr_c, ri_c) = (&mut r_re_all[rows.clone()], &mut r_im_all[rows]);
    for w in 0..CW {
        for b in 0..N {
            rr[w][b].store(&mut rr_c[(w * N + b) * G + gi]);
            ri[w][b].store(&mut ri_c[(w * N + b) * G + gi]);
            if TX == TX_UNIT {
                tr[b] = tr[b].add(rr[w][b]);
                ti[b] = ti[b].add(ri[w][b]);
            } else if TX == TX_REAL {
                let wv = S::load(&tab.d_re[c + w]);
                tr[b] = wv.mul_add(rr[w][b], tr[b]);
                ti[b] = wv.mul_add(ri[w][b], ti[b]);
            } else {
                let dr = S::load(&tab.d_re[(k + b) * nc + c + w]);
                let di = S::load(&tab.d_im[(k + b) * nc + c + w]);
                tr[b] = dr.mul_add(rr[w][b], tr[b]);
                tr[b] = di.neg_mul_add(ri[w][b], tr[b]);
                ti[b] = dr.mul_add(ri[w][b], ti[b]);
                ti[b] = di.mul_add(rr[w][b], ti[b]);
            }
        }
    }
}

/// `N` consecutive bins from band bin `k` (row `kl` of `sc.s_*`) for scatterers `g0..g0+G`.
#[inline(always)]
fn step<S: Lanes, const N: usize, const M: usize, const FFD: bool, const TX: u8, const CW: usize>(
    geom: &ArrayGeom,
    blk: &BlockGeom,
    tab: &Tables,
    g0: usize,
    k: usize,
    kl: usize,
    sc: &mut Scratch,
) {
    let nc = geom.e_pad / L;
    let mm = if M == 0 { geom.m } else { M };
    let per_s = nc * mm;
    let mut t = [[(0f32, 0f32); N]; G];
    // R layout [chunk][bin][scatterer]: pass 1 writes one column, pass 2 reads one block per chunk
    let (r_re_all, r_im_all) = (&mut sc.r_re[..nc * N * G], &mut sc.r_im[..nc * N * G]);
    let (r_re_all, r_im_all) = (&mut *r_re_all, &mut *r_im_all);
    // transmit: R_se = sum_m P, T_s = sum_e D_e R_se; the phasors advance by N bins
    for (gi, tg) in t.iter_mut().enumerate() {
        let rc = blk.rc[g0 + gi] as f32;
        let p_re = &mut sc.p_re[gi * per_s..(gi + 1) * per_s];
        let p_im = &mut sc.p_im[gi * per_s..(gi + 1) * per_s];
        let e_re = &blk.e_re[(g0 + gi) * per_s..(g0 + gi + 1) * per_s];
        let e_im = &blk.e_im[(g0 + gi) * per_s..(g0 + gi + 1) * per_s];
        let dir = if FFD { &sc.dir[gi * per_s..(gi + 1) * per_s] } else { &sc.dir[..0] };
        let mut tr = [S::zero(); N];
        let mut ti = [S::zero(); N];
        if S::SPLIT {
            // Each half of every chunk in turn, one chunk per call: per lane the same operations
            // in the same chunk order as the whole vectors (these builds are not WIDE, so the
            // whole-vector path would also take one chunk per call).
            let (mut trl, mut til) = ([<S::Lo as simd::Ops>::zero(); N], [<S::Lo as simd::Ops>::zero(); N]);
            let (mut trh, mut tih) = ([<S::Hi as simd::Ops>::zero(); N], [<S::Hi as simd::Ops>::zero(); N]);
            for c in 0..nc {
                let ph = Phasors { p_re: &mut *p_re, p_im: &mut *p_im, e_re, e_im, dir };
                chunks::<S::Lo, N, M, FFD, TX, 1>(ph, tab, mm, nc, c, k, gi, r_re_all, r_im_all, &mut trl, &mut til);
                let ph = Phasors { p_re: &mut *p_re, p_im: &mut *p_im, e_re, e_im, dir };
                chunks::<S::Hi, N, M, FFD, TX, 1>(ph, tab, mm, nc, c, k, gi, r_re_all, r_im_all, &mut trh, &mut tih);
            }
            for b in 0..N {
                tr[b] = S::join(trl[b], trh[b]);
                ti[b] = S::join(til[b], tih[b]);
            }
        }
        let mut c = if S::SPLIT { nc } else { 0 };
        while c + CW <= nc {
            let ph = Phasors { p_re: &mut *p_re, p_im: &mut *p_im, e_re, e_im, dir };
            chunks::<S, N, M, FFD, TX, CW>(ph, tab, mm, nc, c, k, gi, r_re_all, r_im_all, &mut tr, &mut ti);
            c += CW;
        }
        while c < nc {
            let ph = Phasors { p_re: &mut *p_re, p_im: &mut *p_im, e_re, e_im, dir };
            chunks::<S, N, M, FFD, TX, 1>(ph, tab, mm, nc, c, k, gi, r_re_all, r_im_all, &mut tr, &mut ti);
            c += 1;
        }
        if N == 4 {
            let sums = S::hsum8([tr[0], tr[1], tr[2], tr[3], ti[0], ti[1], ti[2], ti[3]], rc);
            for b in 0..N {
                tg[b] = (sums[b], sums[4 + b]);
            }
        } else {
            for b in 0..N {
                tg[b] = (tr[b].hsum() * rc, ti[b].hsum() * rc);
            }
        }
    }
    // receive: U_e += T_s R_se for the G scatterers, one row load/store per bin and chunk
    let (s_re, s_im) = (&mut sc.s_re[kl * nc..(kl + N) * nc], &mut sc.s_im[kl * nc..(kl + N) * nc]);
    // (Whole vectors also where pass 1 is split: splitting this pass was slower on a Zen 2, as
    // the rows of R and U would be read twice.)
    receive::<S, N>(&t, nc, r_re_all, r_im_all, s_re, s_im);
}

/// Pass 2 of [`step`]: `U_e += T_s R_se` over the G scatterers of the group (`t`: their transmit
/// sums per bin) for the `N` bins' rows of `s_re`/`s_im`, one row load/store per bin and chunk.
#[inline(always)]
fn receive<S: simd::Ops, const N: usize>(
    t: &[[(f32, f32); N]; G],
    nc: usize,
    r_re_all: &[V],
    r_im_all: &[V],
    s_re: &mut [V],
    s_im: &mut [V],
) {
    let mut tv = [[(S::zero(), S::zero()); G]; N];
    for b in 0..N {
        for gi in 0..G {
            tv[b][gi] = (S::splat(t[gi][b].0), S::splat(t[gi][b].1));
        }
    }
    for c in 0..nc {
        let rows = c * N * G..(c + 1) * N * G;
        let (rr_c, ri_c) = (&r_re_all[rows.clone()], &r_im_all[rows]);
        for b in 0..N {
            let mut sr = S::load(&s_re[b * nc + c]);
            let mut si = S::load(&s_im[b * nc + c]);
            for gi in 0..G {
                let (tre, tim) = tv[b][gi];
                let rr = S::load(&rr_c[b * G + gi]);
                let ri = S::load(&ri_c[b * G + gi]);
                sr = tre.mul_add(rr, sr);
                sr = tim.neg_mul_add(ri, sr);
                si = tre.mul_add(ri, si);
                si = tim.mul_add(rr, si);
            }
            sr.store(&mut s_re[b * nc + c]);
            si.store(&mut s_im[b * nc + c]);
        }
    }
}
