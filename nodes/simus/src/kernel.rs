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
//! `U[k][·]` per group of [`G`] scatterers. Each phasor is loaded once per `NB` = 4 bins. The
//! generic code is instantiated for the vector types of [`crate::simd`].

use std::ops::Range;

use crate::math::sinc_eps;
use crate::pfield::{ArrayGeom, BlockGeom};
use crate::simd::Lanes;

/// SIMD lanes (elements per vector).
pub(crate) const L: usize = 16;
/// Scatterers per receive group.
pub(crate) const G: usize = 4;
/// Bins per pass over the phasors.
const NB: usize = 4;

/// One vector of 16 lanes, 64-byte aligned.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C, align(64))]
pub(crate) struct V(pub [f32; L]);

/// Per-bin transmit tables of one call: `D_e(k)` in f32, `[bin][chunk]`, and the frequencies.
#[derive(Clone, Debug, Default)]
pub(crate) struct Tables {
    pub d_re: Vec<V>,
    pub d_im: Vec<V>,
    pub freqs: Vec<f64>,
    /// All delays zero: `D_e(k) = apod_e` is real and the same for every bin.
    pub real_tx: bool,
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
    match (geom.ffd, tab.real_tx, geom.m) {
        (true, _, _) => run::<S, 0, true, false>(geom, blk, tab, bins, sc),
        (false, true, 1) => run::<S, 1, false, true>(geom, blk, tab, bins, sc),
        (false, true, 2) => run::<S, 2, false, true>(geom, blk, tab, bins, sc),
        (false, true, _) => run::<S, 0, false, true>(geom, blk, tab, bins, sc),
        (false, false, 1) => run::<S, 1, false, false>(geom, blk, tab, bins, sc),
        (false, false, 2) => run::<S, 2, false, false>(geom, blk, tab, bins, sc),
        (false, false, _) => run::<S, 0, false, false>(geom, blk, tab, bins, sc),
    }
}

/// `M` = sub-elements per element when known at compile time, 0 = `geom.m` at run time.
#[inline(always)]
fn run<S: Lanes, const M: usize, const FFD: bool, const REAL: bool>(
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
                directivity(geom, blk, g0, tab.freqs[k], sc);
                step::<S, 1, M, FFD, REAL>(geom, blk, tab, g0, k, k - bins.start, sc);
                k += 1;
            } else if k + NB <= bins.end {
                step::<S, NB, M, FFD, REAL>(geom, blk, tab, g0, k, k - bins.start, sc);
                k += NB;
            } else {
                step::<S, 1, M, FFD, REAL>(geom, blk, tab, g0, k, k - bins.start, sc);
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
    const MAGIC32: f32 = 12_582_912.0;
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
        let sin = s.mul_add(cq, c.mul(sq));
        let cos = s.neg_mul_add(sq, c.mul(cq));
        a.mul(cos).store(&mut sc.p_re[i]);
        a.mul(sin).store(&mut sc.p_im[i]);
    }
}

/// Full-frequency directivity `sinc(k W/(2M) sin θ)` of every phasor at frequency `f`.
fn directivity(geom: &ArrayGeom, blk: &BlockGeom, g0: usize, f: f64, sc: &mut Scratch) {
    let n = G * geom.e_pad / L * geom.m;
    let src0 = g0 * geom.e_pad * geom.m;
    for i in 0..n {
        let d = &mut sc.dir[i];
        for l in 0..L {
            d.0[l] = sinc_eps(blk.dirb[src0 + i * L + l] * f) as f32;
        }
    }
}

/// `N` consecutive bins from band bin `k` (row `kl` of `sc.s_*`) for scatterers `g0..g0+G`.
#[inline(always)]
fn step<S: Lanes, const N: usize, const M: usize, const FFD: bool, const REAL: bool>(
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
        for c in 0..nc {
            let mut rr = [S::zero(); N];
            let mut ri = [S::zero(); N];
            let (pr_c, pi_c) = (&mut p_re[c * mm..(c + 1) * mm], &mut p_im[c * mm..(c + 1) * mm]);
            let (er_c, ei_c) = (&e_re[c * mm..(c + 1) * mm], &e_im[c * mm..(c + 1) * mm]);
            for m in 0..mm {
                let er = S::load(&er_c[m]);
                let ei = S::load(&ei_c[m]);
                let mut pr = S::load(&pr_c[m]);
                let mut pi = S::load(&pi_c[m]);
                for b in 0..N {
                    if FFD {
                        let d = S::load(&dir[c * mm + m]);
                        rr[b] = d.mul_add(pr, rr[b]);
                        ri[b] = d.mul_add(pi, ri[b]);
                    } else {
                        rr[b] = rr[b].add(pr);
                        ri[b] = ri[b].add(pi);
                    }
                    let nr = pi.neg_mul_add(ei, pr.mul(er));
                    let ni = pr.mul_add(ei, pi.mul(er));
                    pr = nr;
                    pi = ni;
                }
                pr.store(&mut pr_c[m]);
                pi.store(&mut pi_c[m]);
            }
            for b in 0..N {
                rr[b].store(&mut sc.r_re[(b * G + gi) * nc + c]);
                ri[b].store(&mut sc.r_im[(b * G + gi) * nc + c]);
                if REAL {
                    let w = S::load(&tab.d_re[c]);
                    tr[b] = w.mul_add(rr[b], tr[b]);
                    ti[b] = w.mul_add(ri[b], ti[b]);
                } else {
                    let dr = S::load(&tab.d_re[(k + b) * nc + c]);
                    let di = S::load(&tab.d_im[(k + b) * nc + c]);
                    tr[b] = dr.mul_add(rr[b], tr[b]);
                    tr[b] = di.neg_mul_add(ri[b], tr[b]);
                    ti[b] = dr.mul_add(ri[b], ti[b]);
                    ti[b] = di.mul_add(rr[b], ti[b]);
                }
            }
        }
        for b in 0..N {
            tg[b] = (tr[b].hsum() * rc, ti[b].hsum() * rc);
        }
    }
    // receive: U_e += T_s R_se for the G scatterers, one row load/store per bin and chunk
    for b in 0..N {
        let mut tv = [(S::zero(), S::zero()); G];
        for gi in 0..G {
            tv[gi] = (S::splat(t[gi][b].0), S::splat(t[gi][b].1));
        }
        let row = (kl + b) * nc;
        let (s_re, s_im) = (&mut sc.s_re[row..row + nc], &mut sc.s_im[row..row + nc]);
        for c in 0..nc {
            let mut sr = S::load(&s_re[c]);
            let mut si = S::load(&s_im[c]);
            for (gi, &(tre, tim)) in tv.iter().enumerate() {
                let rr = S::load(&sc.r_re[(b * G + gi) * nc + c]);
                let ri = S::load(&sc.r_im[(b * G + gi) * nc + c]);
                sr = tre.mul_add(rr, sr);
                sr = tim.neg_mul_add(ri, sr);
                si = tre.mul_add(ri, si);
                si = tim.mul_add(rr, si);
            }
            sr.store(&mut s_re[c]);
            si.store(&mut s_im[c]);
        }
    }
}
