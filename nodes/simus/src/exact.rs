//! Exact reference kernel ([`crate::Accuracy::Exact`]): the same sums as [`crate::kernel`] but
//! every phasor `amp·exp((−β + 2πi/c) f r)` is evaluated directly in f64 at every bin and all
//! sums are f64. No recursion, no f32: the yardstick for the fast modes and for PyMUST.

use std::ops::Range;

use crate::math::sinc_eps;
use crate::pfield::{ArrayGeom, BlockGeom};

/// f64 transmit table `D_e(k)`, `[bin][e_pad]`.
#[derive(Clone, Debug, Default)]
pub(crate) struct Tables64 {
    pub d_re: Vec<f64>,
    pub d_im: Vec<f64>,
}

/// One scatterer's echo at one bin into the spectra row `row` (`[re, im][e_pad]`):
/// `T = rc Σ_e D_e R_e` (transmit), then `U_e += T R_e` (receive, by reciprocity).
#[inline(always)]
fn add_echo(d: (&[f64], &[f64]), r: (&[f64], &[f64]), rc: f64, row: &mut [f64]) {
    let ((d_re, d_im), (r_re, r_im)) = (d, r);
    let ep = r_re.len();
    let (mut tr, mut ti) = (0.0, 0.0);
    for e in 0..ep {
        tr += d_re[e] * r_re[e] - d_im[e] * r_im[e];
        ti += d_re[e] * r_im[e] + d_im[e] * r_re[e];
    }
    let (tr, ti) = (tr * rc, ti * rc);
    let (u_re, u_im) = row.split_at_mut(ep);
    for e in 0..ep {
        u_re[e] += tr * r_re[e] - ti * r_im[e];
        u_im[e] += tr * r_im[e] + ti * r_re[e];
    }
}

/// MUST's elevation model for one block of scatterers off the imaging plane
/// ([`crate::Simus::simulate_3d_into`]): each element's pattern times the MGBM factor of the
/// scatterer, recomputed at the band bins `mgbm_bins` (MUST: `max(3, round(n/20))` of them) and
/// held in between.
#[derive(Clone, Debug, Default)]
pub(crate) struct ElevationBlock {
    /// Elevation of each scatterer of the block (m), padding 0.
    pub y: Vec<f64>,
    /// Mean distance over the sub-elements, `[scatterer][e_pad]`.
    pub rm: Vec<f64>,
    /// Element height, elevation focus (∞: unset), speed of sound.
    pub h: f64,
    pub rf: f64,
    pub c: f64,
    /// MUST's branch when every |y| is below f32's ε.
    pub planar: bool,
    /// Band-relative bins where MUST recomputes the factor (ascending, starts at 0).
    pub mgbm_bins: Vec<usize>,
}

/// Adds block `blk` into `u` (`[bin - bins.start][re, im][e_pad]`) for the band bins `bins`.
pub(crate) fn accumulate_exact(
    geom: &ArrayGeom,
    blk: &BlockGeom,
    tab: &Tables64,
    freqs: &[f64],
    bins: Range<usize>,
    u: &mut [f64],
    rbuf: &mut Vec<f64>,
) {
    let ep = geom.e_pad;
    rbuf.resize(2 * ep, 0.0);
    for (kl, k) in bins.enumerate() {
        let f = freqs[k];
        let (d_re, d_im) = (&tab.d_re[k * ep..(k + 1) * ep], &tab.d_im[k * ep..(k + 1) * ep]);
        for s in 0..blk.n_s {
            let rc = blk.rc[s];
            if rc == 0.0 {
                continue;
            }
            let (r_re, r_im) = rbuf.split_at_mut(ep);
            r_re.fill(0.0);
            r_im.fill(0.0);
            let nc = ep / crate::kernel::L;
            for c in 0..nc {
                for m in 0..geom.m {
                    let base = ((s * nc + c) * geom.m + m) * crate::kernel::L;
                    for l in 0..crate::kernel::L {
                        let (i, e) = (base + l, c * crate::kernel::L + l);
                        let (mut pr, mut pi) = geom.phasor(blk.amp[i], blk.r[i], f);
                        if geom.ffd {
                            let d = sinc_eps(blk.dirb[i] * f);
                            pr *= d;
                            pi *= d;
                        }
                        r_re[e] += pr;
                        r_im[e] += pi;
                    }
                }
            }
            add_echo((d_re, d_im), (&*r_re, &*r_im), rc, &mut u[kl * 2 * ep..(kl + 1) * 2 * ep]);
        }
    }
}

/// [`accumulate_exact`] for a block off the imaging plane, the phasors stepped in f64 from an
/// exact anchor at the first bin of `bins` (as PFIELD does; MUST steps them in complex64), each
/// element's pattern carrying the scatterer's MGBM factor, swapped (× new/old) at the bins
/// where MUST recomputes it. `buf` is scratch.
#[allow(clippy::too_many_arguments)]
pub(crate) fn accumulate_elevation(
    geom: &ArrayGeom,
    blk: &BlockGeom,
    tab: &Tables64,
    freqs: &[f64],
    df: f64,
    bins: Range<usize>,
    u: &mut [f64],
    buf: &mut Vec<f64>,
    el: &ElevationBlock,
) {
    type C = num_complex::Complex<f64>;
    let (ep, m, l_) = (geom.e_pad, geom.m, crate::kernel::L);
    let per = ep * m;
    let Some(b0) = bins.clone().next() else { return };
    buf.resize(4 * per + 2 * ep, 0.0);
    let (ph, rest) = buf.split_at_mut(2 * per);
    let (ph_re, ph_im) = ph.split_at_mut(per);
    let (st, r) = rest.split_at_mut(2 * per);
    let (st_re, st_im) = st.split_at_mut(per);
    let (r_re, r_im) = r.split_at_mut(ep);
    let elem = |i: usize| (i / (m * l_)) * l_ + i % l_;
    let factors = |s: usize, k: usize| -> Vec<C> {
        let kw = 2.0 * std::f64::consts::PI * freqs[k] / el.c;
        (0..ep)
            .map(|e| {
                let rm = el.rm[s * ep + e];
                if rm > 0.0 {
                    crate::pressure::mgbm(kw, el.y[s], rm, el.h, el.rf, el.planar)
                } else {
                    C::new(0.0, 0.0)
                }
            })
            .collect()
    };
    for s in 0..blk.n_s {
        let rc = blk.rc[s];
        if rc == 0.0 {
            continue;
        }
        let at = s * per;
        let first = el.mgbm_bins.iter().copied().filter(|b| *b <= b0).max().unwrap_or(0);
        let mut g = factors(s, first);
        for i in 0..per {
            let (pr, pi) = geom.phasor(blk.amp[at + i], blk.r[at + i], freqs[b0]);
            let v = g[elem(i)] * C::new(pr, pi);
            (ph_re[i], ph_im[i]) = (v.re, v.im);
            (st_re[i], st_im[i]) = geom.phasor(1.0, blk.r[at + i], df);
        }
        for (kl, k) in bins.clone().enumerate() {
            if kl > 0 {
                for i in 0..per {
                    let (a, b) = (ph_re[i], ph_im[i]);
                    ph_re[i] = a * st_re[i] - b * st_im[i];
                    ph_im[i] = a * st_im[i] + b * st_re[i];
                }
                if el.mgbm_bins.contains(&k) {
                    let g_new = factors(s, k);
                    for i in 0..per {
                        let e = elem(i);
                        let ratio = if g[e].norm_sqr() > 0.0 { g_new[e] / g[e] } else { C::new(0.0, 0.0) };
                        let v = ratio * C::new(ph_re[i], ph_im[i]);
                        (ph_re[i], ph_im[i]) = (v.re, v.im);
                    }
                    g = g_new;
                }
            }
            let f = freqs[k];
            r_re.fill(0.0);
            r_im.fill(0.0);
            // Σ over the sub-elements, lane by lane (contiguous: vectorises)
            for c in 0..ep / l_ {
                let (rr, ri) = (&mut r_re[c * l_..(c + 1) * l_], &mut r_im[c * l_..(c + 1) * l_]);
                for mm in 0..m {
                    let base = (c * m + mm) * l_;
                    let (pr, pi) = (&ph_re[base..base + l_], &ph_im[base..base + l_]);
                    if geom.ffd {
                        for l in 0..l_ {
                            let d = sinc_eps(blk.dirb[at + base + l] * f);
                            rr[l] += d * pr[l];
                            ri[l] += d * pi[l];
                        }
                    } else {
                        for l in 0..l_ {
                            rr[l] += pr[l];
                            ri[l] += pi[l];
                        }
                    }
                }
            }
            let (d_re, d_im) = (&tab.d_re[k * ep..(k + 1) * ep], &tab.d_im[k * ep..(k + 1) * ep]);
            add_echo((d_re, d_im), (&*r_re, &*r_im), rc, &mut u[kl * 2 * ep..(kl + 1) * 2 * ep]);
        }
    }
}
