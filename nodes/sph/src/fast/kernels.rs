//! Pair kernels of the fast evaluator, written once over [`Lanes`] and instantiated for the portable
//! lanes and (x86-64) the AVX2 + FMA lanes.
//!
//! Per cell, the particles of the neighbour cells are copied into one contiguous scratch buffer
//! ([`Buf`]) with positions in units of h relative to the cell centre (f32), then every particle of
//! the cell runs over the whole buffer 8 candidates at a time, without branches: the kernels are
//! written with `max(0, ·)` so candidates outside the support contribute exact zeros, the buffer is
//! padded to a multiple of 8 with far-away dummies of zero mass, and the particle's own entry is
//! moved far away while it runs (its self term, in the Shepard denominator of eq 12 only, is added
//! in f64 as in [`crate::wcsph::compute_rates`]).

use super::grid::{Grid, Run};
use super::lanes::{min_lane, sum_f64, Lanes};
use crate::particles::ParticleKind;
use crate::wcsph::Rate;
use crate::Real;

/// Position of padding entries and of the running particle's own entry \[h\]: its kernel terms are
/// exact zeros (q ≫ support) and every product stays finite in f32.
const FAR: f32 = 1.0e6;

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
        let f = a2.mul_add(a2, c2.mul(c2).mul_add(ten, b2.mul(b2).mul(m5)));
        let d = c2.mul(c).mul_add(ten, b2.mul(b).mul_add(m5, a2.mul(a)));
        (f, d)
    }
    #[inline(always)]
    fn f<L: Lanes>(q: L) -> L {
        let (z, m5, ten) = (L::splat(0.0), L::splat(-5.0), L::splat(10.0));
        let a = L::splat(2.5).sub(q).max(z);
        let b = L::splat(1.5).sub(q).max(z);
        let c = L::splat(0.5).sub(q).max(z);
        let (a2, b2, c2) = (a.mul(a), b.mul(b), c.mul(c));
        a2.mul_add(a2, c2.mul(c2).mul_add(ten, b2.mul(b2).mul(m5)))
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

/// Channels of the candidate buffer.
pub(super) const NCH: usize = 7;

/// Candidate buffer of one cell: positions relative to the cell centre in units of h, and up to
/// [`NCH`] per-particle channels, padded to a multiple of 8.
#[derive(Clone, Debug, Default)]
pub(super) struct Buf {
    x: Vec<f32>,
    z: Vec<f32>,
    ch: [Vec<f32>; NCH],
    runs: Vec<Run>,
}

impl Buf {
    /// Copies the neighbour runs of cell `c` with the first `src.len()` channels; returns
    /// (padded length, offset of cell c's own particles).
    fn gather(
        &mut self,
        grid: &Grid,
        c: usize,
        xs: &[Real],
        zs: &[Real],
        src: &[&[f32]],
        inv_h: Real,
    ) -> (usize, usize) {
        let own = grid.runs(c, &mut self.runs);
        let (cx, cz) = grid.centre(c);
        let total: usize = self.runs.iter().map(|r| r.end - r.start).sum();
        let n8 = total.div_ceil(8) * 8;
        self.x.resize(n8, FAR);
        self.z.resize(n8, FAR);
        for ch in &mut self.ch[..src.len()] {
            ch.resize(n8, 0.0);
        }
        let mut o = 0;
        for r in &self.runs {
            let (s, e) = (r.start, r.end);
            let (ox, oz) = (r.sx - cx, r.sz - cz);
            for (d, &v) in self.x[o..o + e - s].iter_mut().zip(&xs[s..e]) {
                *d = ((v + ox) * inv_h) as f32;
            }
            for (d, &v) in self.z[o..o + e - s].iter_mut().zip(&zs[s..e]) {
                *d = ((v + oz) * inv_h) as f32;
            }
            for (ch, sc) in self.ch.iter_mut().zip(src) {
                ch[o..o + e - s].copy_from_slice(&sc[s..e]);
            }
            o += e - s;
        }
        self.x[total..].fill(FAR);
        self.z[total..].fill(FAR);
        for ch in &mut self.ch[..src.len()] {
            ch[total..].fill(0.0);
        }
        (n8, own)
    }
}

/// Sorted particle data and constants of the rate pass.
pub(super) struct RatesIn<'a> {
    pub(super) grid: &'a Grid,
    pub(super) xs: &'a [Real],
    pub(super) zs: &'a [Real],
    pub(super) wall: &'a [bool],
    /// ux, uz, m p/ρ², m, m/ρ, ρ − ρ₀, (m/ρ for non-walls, 0 for walls) — f32.
    pub(super) ch: [&'a [f32]; NCH],
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
    /// f_s(0) (self term of the Shepard denominator).
    pub(super) f0: Real,
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
struct Sums {
    drho: Real,
    apx: Real,
    apz: Real,
    s1: Real,
    s2: Real,
    s3: Real,
    r2min: f32,
    dsum: Real,
    gc: [Real; 2],
    gu: [Real; 4],
}

/// Lane sums of one particle against the buffer (its own entry already moved away).
///
/// # Safety
/// `L::available()`; the buffer's x, z and first 5 (7 with `EX`) channels hold ≥ n8 values.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
unsafe fn pair_sums<L: Lanes, S: Shape, const MV: bool, const EX: bool>(
    buf: &Buf,
    n8: usize,
    xa: f32,
    za: f32,
    uax: f32,
    uaz: f32,
    pa: f32,
    deva: f32,
    inv_fdp: f32,
) -> Sums {
    let (xa, za, uax, uaz, pa) = (L::splat(xa), L::splat(za), L::splat(uax), L::splat(uaz), L::splat(pa));
    let (deva, inv_fdp) = (L::splat(deva), L::splat(inv_fdp));
    let (zero, eps, one, c02) = (L::splat(0.0), L::splat(0.01), L::splat(1.0), L::splat(0.2));
    let (mut drho, mut apx, mut apz, mut s1, mut s2, mut s3) = (zero, zero, zero, zero, zero, zero);
    let mut r2min = L::splat(f32::INFINITY);
    let (mut dsum, mut gcx, mut gcz) = (zero, zero, zero);
    let (mut gu0, mut gu1, mut gu2, mut gu3) = (zero, zero, zero, zero);
    let (px, pz) = (buf.x.as_ptr(), buf.z.as_ptr());
    let [pux, puz, pmp, pm, pv, pdev, pvd] = [0, 1, 2, 3, 4, 5, 6].map(|c| buf.ch[c].as_ptr());
    let mut i = 0;
    while i < n8 {
        // SAFETY: i + 8 ≤ n8 ≤ every used slice's length (caller).
        let ld = |p: *const f32| unsafe { L::load(p.add(i)) };
        let dx = xa.sub(ld(px));
        let dz = za.sub(ld(pz));
        let r2 = dz.mul_add(dz, dx.mul(dx));
        r2min = r2min.min(r2);
        let r = r2.sqrt();
        let (f, d) = S::f_d(r);
        let fr = d.div(r);
        let (gx, gz) = (dx.mul(fr), dz.mul(fr));
        let dux = uax.sub(ld(pux));
        let duz = uaz.sub(ld(puz));
        let m = ld(pm);
        drho = m.mul_add(duz.mul_add(gz, dux.mul(gx)), drho);
        let pt = m.mul_add(pa, ld(pmp));
        apx = pt.mul_add(gx, apx);
        apz = pt.mul_add(gz, apz);
        let v = ld(pv);
        let kk = if MV && !EX { zero } else { d.mul(r).div(r2.add(eps)) };
        if MV {
            let vw = v.mul(f);
            s1 = dux.mul_add(vw, s1);
            s2 = duz.mul_add(vw, s2);
            s3 = s3.add(vw);
        } else {
            let vk = v.mul(kk);
            s1 = vk.mul_add(dux, s1);
            s2 = vk.mul_add(duz, s2);
        }
        if EX {
            dsum = ld(pvd).mul(ld(pdev).sub(deva)).mul_add(kk, dsum);
            let q = f.mul(inv_fdp);
            let q2 = q.mul(q);
            let corr = v.mul(q2.mul(q2).mul_add(c02, one));
            gcx = corr.mul_add(gx, gcx);
            gcz = corr.mul_add(gz, gcz);
            let (vgx, vgz) = (v.mul(gx), v.mul(gz));
            gu0 = dux.mul_add(vgx, gu0);
            gu1 = dux.mul_add(vgz, gu1);
            gu2 = duz.mul_add(vgx, gu2);
            gu3 = duz.mul_add(vgz, gu3);
        }
        i += 8;
    }
    let mut s = Sums {
        drho: sum_f64(drho),
        apx: sum_f64(apx),
        apz: sum_f64(apz),
        s1: sum_f64(s1),
        s2: sum_f64(s2),
        s3: sum_f64(s3),
        r2min: min_lane(r2min),
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
/// `L::available()`.
#[inline(always)]
pub(super) unsafe fn rates_cells<L: Lanes, S: Shape, const MV: bool, const EX: bool>(
    inp: &RatesIn,
    c0: usize,
    c1: usize,
    out: &mut [Rate],
    buf: &mut Buf,
) {
    let k = &inp.k;
    let base = inp.grid.range(c0).0;
    let nch = if EX { NCH } else { 5 };
    for c in c0..c1 {
        let (s, e) = inp.grid.range(c);
        if inp.wall[s..e].iter().all(|&w| w) {
            out[s - base..e - base].fill(Rate::default());
            continue;
        }
        let (n8, own) = buf.gather(inp.grid, c, inp.xs, inp.zs, &inp.ch[..nch], k.inv_h);
        for a in s..e {
            if inp.wall[a] {
                out[a - base] = Rate::default();
                continue;
            }
            let j = own + a - s;
            let (xa, za) = (buf.x[j], buf.z[j]);
            buf.x[j] = FAR;
            buf.z[j] = FAR;
            let (ra, ma) = (inp.rho[a], inp.mass[a]);
            let inv_fdp =
                if EX && k.shifting { (1.0 / (k.f_scalar)((ma / k.rho0).sqrt() * k.inv_h)) as f32 } else { 1.0 };
            let deva = if EX { inp.ch[5][a] } else { 0.0 };
            // SAFETY: L::available() (caller); gather sized x, z and the nch channels to n8.
            let sm = unsafe {
                pair_sums::<L, S, MV, EX>(buf, n8, xa, za, inp.ch[0][a], inp.ch[1][a], inp.pr[a], deva, inv_fdp)
            };
            buf.x[j] = xa;
            buf.z[j] = za;
            out[a - base] = finish::<S, MV, EX>(k, &sm, ra, ma / ra);
        }
    }
}

/// Rate of one particle from its lane sums (f64).
#[inline(always)]
fn finish<S: Shape, const MV: bool, const EX: bool>(k: &RateConsts, s: &Sums, ra: Real, va: Real) -> Rate {
    let mut drho = k.grad * s.drho;
    let (avx, avz) = if MV {
        let sc = -k.c_mu / ra / (va * k.f0 + s.s3);
        (sc * s.s1, sc * s.s2)
    } else {
        let sc = 2.0 * k.mu / ra * (k.grad * k.inv_h);
        (sc * s.s1, sc * s.s2)
    };
    let mut rate = Rate {
        drho,
        acc: [avx - k.grad * s.apx + k.g[0], avz - k.grad * s.apz + k.g[1]],
        r2min: if (s.r2min as Real) < S::CUT * S::CUT { s.r2min as Real * k.h * k.h } else { Real::INFINITY },
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
    pub(super) grid: &'a Grid,
    pub(super) xs: &'a [Real],
    pub(super) zs: &'a [Real],
    pub(super) kind: &'a [ParticleKind],
    /// ux, uz, p, ρ, (1 non-wall, 0 wall) — f32.
    pub(super) ch: [&'a [f32]; 5],
    /// Prescribed wall velocity (f64).
    pub(super) vx: &'a [Real],
    pub(super) vz: &'a [Real],
    pub(super) h: Real,
    pub(super) inv_h: Real,
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
/// `L::available()`.
#[inline(always)]
pub(super) unsafe fn wall_cells<L: Lanes, S: Shape>(
    inp: &WallIn,
    c0: usize,
    c1: usize,
    out: &mut [[Real; 4]],
    buf: &mut Buf,
) {
    let base = inp.grid.range(c0).0;
    for c in c0..c1 {
        let (s, e) = inp.grid.range(c);
        out[s - base..e - base].fill([0.0; 4]);
        if !inp.kind[s..e].iter().any(|k| k.is_wall()) {
            continue;
        }
        let (n8, own) = buf.gather(inp.grid, c, inp.xs, inp.zs, &inp.ch, inp.inv_h);
        let (px, pz) = (buf.x.as_ptr(), buf.z.as_ptr());
        let [pux, puz, pp, prho, pfl] = [0, 1, 2, 3, 4].map(|c| buf.ch[c].as_ptr());
        for w in s..e {
            if !inp.kind[w].is_wall() {
                continue;
            }
            let j = own + w - s;
            let (xa, za) = (L::splat(buf.x[j]), L::splat(buf.z[j]));
            let zero = L::splat(0.0);
            let (mut sw, mut sux, mut suz, mut sp, mut srx, mut srz) = (zero, zero, zero, zero, zero, zero);
            let mut i = 0;
            while i < n8 {
                // SAFETY: i + 8 ≤ n8 ≤ the buffer's lengths (gather); L::available() (caller).
                let ld = |p: *const f32| unsafe { L::load(p.add(i)) };
                let dx = xa.sub(ld(px));
                let dz = za.sub(ld(pz));
                let r = dz.mul_add(dz, dx.mul(dx)).sqrt();
                let wf = S::f(r).mul(ld(pfl));
                sw = sw.add(wf);
                sux = ld(pux).mul_add(wf, sux);
                suz = ld(puz).mul_add(wf, suz);
                sp = ld(pp).mul_add(wf, sp);
                let rho = ld(prho);
                srx = rho.mul(dx).mul_add(wf, srx);
                srz = rho.mul(dz).mul_add(wf, srz);
                i += 8;
            }
            let sw = sum_f64(sw);
            let (vwx, vwz) = (inp.vx[w], inp.vz[w]);
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
