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

/// Adds block `blk` into `u` (`[bin - bins.start][re, im][e_pad]`) for the band bins `bins`;
/// with `elev`, each element's pattern is multiplied by the scatterer's MGBM factor.
#[allow(clippy::too_many_arguments)]
pub(crate) fn accumulate_exact(
    geom: &ArrayGeom,
    blk: &BlockGeom,
    tab: &Tables64,
    freqs: &[f64],
    bins: Range<usize>,
    u: &mut [f64],
    rbuf: &mut Vec<f64>,
    elev: Option<&ElevationBlock>,
) {
    let ep = geom.e_pad;
    rbuf.resize(2 * ep, 0.0);
    let mut g: Vec<num_complex::Complex<f64>> = Vec::new();
    let mut g_bin = usize::MAX;
    for (kl, k) in bins.enumerate() {
        let f = freqs[k];
        if let Some(el) = elev {
            let at = el.mgbm_bins.iter().copied().filter(|b| *b <= k).max().unwrap_or(0);
            if at != g_bin {
                g_bin = at;
                let kw = 2.0 * std::f64::consts::PI * freqs[at] / el.c;
                g.clear();
                for s in 0..blk.n_s {
                    for e in 0..ep {
                        let rm = el.rm[s * ep + e];
                        g.push(if rm > 0.0 {
                            crate::pressure::mgbm(kw, el.y[s], rm, el.h, el.rf, el.planar)
                        } else {
                            num_complex::Complex::new(0.0, 0.0)
                        });
                    }
                }
            }
        }
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
            if elev.is_some() {
                for e in 0..ep {
                    let v = g[s * ep + e] * num_complex::Complex::new(r_re[e], r_im[e]);
                    (r_re[e], r_im[e]) = (v.re, v.im);
                }
            }
            let (mut tr, mut ti) = (0.0, 0.0);
            for e in 0..ep {
                tr += d_re[e] * r_re[e] - d_im[e] * r_im[e];
                ti += d_re[e] * r_im[e] + d_im[e] * r_re[e];
            }
            let (tr, ti) = (tr * rc, ti * rc);
            let row = &mut u[kl * 2 * ep..(kl + 1) * 2 * ep];
            let (u_re, u_im) = row.split_at_mut(ep);
            for e in 0..ep {
                u_re[e] += tr * r_re[e] - ti * r_im[e];
                u_im[e] += tr * r_im[e] + ti * r_re[e];
            }
        }
    }
}
