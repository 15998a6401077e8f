//! MUST's PFIELD: the RMS acoustic pressure field of one transmit of a linear or convex array over a set
//! of points in the x–z plane (2-D, the model SIMUS uses for its transmit path).
//!
//! For points p, elements e (split into M sub-elements m, [`crate::pfield`] geometry: clamped
//! distance r, obliquity, directivity, 1/√r, attenuation) and frequencies f_k of MUST's grid,
//!
//! `P_k(p) = i·P(ω_k)·H(ω_k) · Σ_e apod_e e^{iω_k τ_e} · (1/M) Σ_m a_pem e^{(−β + 2πi/c) f_k r_pem}`,
//!
//! `RP(p) = sqrt(df·W · Σ_k |P_k(p)|²)` (W = element width), 0 at z < 0. MUST's frequency grid
//! for PFIELD alone: `df = FrequencyStep / (max r/c + max τ)`, `Nf = 2⌈fc/df⌉ + 1` samples on
//! [0, 2fc] (df then `2fc/(Nf − 1)`), kept where `|P H|` is above `dBThresh` (−60 dB) of its
//! maximum. The points are rounded to f32 as PyMUST does; the phasors are stepped across the band
//! in f64 from an exact start (PyMUST steps them in complex64) and the sums are f64; PyMUST's
//! result is within its own float32 error of this one (tests against PyMUST 0.1.9:
//! `nodes/python/tests/test_pfield.py`). [`pfield_3d`] adds MUST's elevation model for points off
//! the plane (y ≠ 0: element `height`, elevation `focus`, MGBM); convex arrays and chirps are not
//! modelled, as in SIMUS.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{invalid, Result, SimusError};
use crate::math::sinc_eps;
use crate::pfield::{ArrayGeom, BlockGeom, ScattererGeom};
use crate::pulse::PulseModel;
use crate::{Medium, Probe, Transmit};

/// One point's index and its geometry buffers (r, amplitude, directivity factor).
type PointBufs<'a> = (usize, (&'a mut [f64], (&'a mut [f64], &'a mut [f64])));

/// Most points one call may take.
pub const MAX_POINTS: usize = 100_000_000;

/// MUST's PFIELD `options`.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct PfieldOptions {
    /// Band kept: where |P H| is above this (dB, < 0) of its maximum. MUST's default −60.
    #[serde(alias = "dBThresh")]
    pub db_thresh: f64,
    /// Multiplies MUST's frequency step (> 0; MUST's default 1).
    #[serde(alias = "FrequencyStep")]
    pub frequency_step: f64,
    /// Directivity at every frequency (MUST's default: at fc only).
    #[serde(alias = "FullFrequencyDirectivity")]
    pub full_frequency_directivity: bool,
    /// Sub-elements per element (default: MUST's `ceil(W/λmin)`), in [1, 64].
    #[serde(alias = "ElementSplitting")]
    pub element_splitting: Option<u32>,
}

impl Default for PfieldOptions {
    fn default() -> Self {
        Self { db_thresh: -60.0, frequency_step: 1.0, full_frequency_directivity: false, element_splitting: None }
    }
}

impl PfieldOptions {
    /// Checks every field; errors name it and its allowed range.
    pub fn validate(&self) -> Result<()> {
        if !(self.db_thresh.is_finite() && self.db_thresh < 0.0) {
            return Err(invalid("options.dBThresh", self.db_thresh, "finite and < 0 (dB)"));
        }
        if !(self.frequency_step.is_finite() && self.frequency_step > 0.0 && self.frequency_step <= 100.0) {
            return Err(invalid("options.FrequencyStep", self.frequency_step, "in (0, 100]"));
        }
        if let Some(m) = self.element_splitting {
            if !(1..=64).contains(&m) {
                return Err(invalid("options.ElementSplitting", m, "in [1, 64]"));
            }
        }
        Ok(())
    }
}

/// A computed pressure field.
#[derive(Clone, Debug, PartialEq)]
pub struct PressureField {
    /// RMS pressure per point (MUST's `RP`), in the points' order.
    pub rms: Vec<f64>,
    /// Frequency step (Hz) and the band's first and last frequency (Hz).
    pub df: f64,
    pub band_hz: (f64, f64),
    /// Frequencies in the band.
    pub n_freq: usize,
    /// MUST's `IDX`: for each of the Nf grid frequencies on [0, 2fc], whether it is in the band.
    pub idx: Vec<bool>,
}

/// PFIELD of `transmit` (delays s, NaN = element off; apodisation) from `probe` in `medium`
/// at the points (`x`, `z`) (m; z < 0 is behind the array: 0 there).
pub fn pfield(
    probe: &Probe,
    medium: &Medium,
    transmit: &Transmit,
    x: &[f64],
    z: &[f64],
    options: &PfieldOptions,
) -> Result<PressureField> {
    pfield_impl(probe, medium, transmit, x, None, z, options)
}

/// [`pfield`] at points (`x`, `y`, `z`) off the imaging plane, with MUST's elevation model when
/// any |y| ≥ 1e-9 m (PyMUST's rule; otherwise exactly [`pfield`]): distances in 3-D, spreading
/// 1/r instead of 1/√r, no element-width factor, and each element's radiation pattern multiplied
/// by the multi-Gaussian beam model (MGBM, 4 Gaussians, Wen & Breazeale) of an element of
/// height `probe.height` focused at `probe.focus` (unset: infinite) in elevation, evaluated as
/// MUST does at `max(3, round(n/20))` of the n band frequencies and held in between. The in-plane
/// angle (obliquity, directivity) is that of (x, z).
pub fn pfield_3d(
    probe: &Probe,
    medium: &Medium,
    transmit: &Transmit,
    x: &[f64],
    y: &[f64],
    z: &[f64],
    options: &PfieldOptions,
) -> Result<PressureField> {
    if y.len() != x.len() {
        return Err(SimusError::LengthMismatch { field: "pfield.y", got: y.len(), expected: x.len() });
    }
    if let Some(i) = (0..y.len()).find(|&i| !(y[i].is_finite() && y[i].abs() <= 100.0)) {
        return Err(invalid("pfield.y", format!("{} at point {i}", y[i]), "finite, |y| ≤ 100 m"));
    }
    let elevation = y.iter().any(|v| v.abs() >= 1e-9);
    pfield_impl(probe, medium, transmit, x, elevation.then_some(y), z, options)
}

/// MUST's elevation parameters: (element height, elevation focus), ∞ when unset.
pub(crate) fn elevation_params(probe: &Probe) -> Result<(f64, f64)> {
    let h = probe.height.unwrap_or(f64::INFINITY);
    let rf = probe.focus.unwrap_or(f64::INFINITY);
    if h.is_nan() || h <= 0.0 {
        return Err(invalid("param.height", h, "> 0 m (∞: unset)"));
    }
    if rf.is_nan() || rf <= 0.0 {
        return Err(invalid("param.focus", rf, "> 0 m (∞: no elevation focus)"));
    }
    Ok((h, rf))
}

/// The band bins (0-based, of `n_bins`) where MUST recomputes the MGBM factor:
/// `round(linspace(1, n, max(3, round(n/20)))) − 1` (numpy's round: half to even).
pub(crate) fn mgbm_bins(n_bins: usize) -> Vec<usize> {
    let nm = ((n_bins as f64 / 20.0).round_ties_even() as usize).max(3);
    (0..nm)
        .map(|j| {
            let v = 1.0 + (n_bins as f64 - 1.0) * j as f64 / (nm - 1) as f64;
            (v.round_ties_even() as usize).saturating_sub(1)
        })
        .collect()
}

/// MUST's `MGBMcoeff(4)`: A_n, B_n of `rect(y) ≈ Σ A_n exp(−B_n y²)`.
const MGBM_A: [(f64, f64); 4] = [(0.187, 0.275), (0.288, -1.954), (0.187, -0.275), (0.288, 1.954)];
const MGBM_B: [(f64, f64); 4] = [(4.558, -25.59), (8.598, -7.924), (4.558, 25.59), (8.598, 7.924)];

type C64 = num_complex::Complex<f64>;

/// The MGBM elevation factor of one (point, element) at wavenumber `kw`: MUST's
/// `Σ A_n √(π t) exp(kw² β²/4 t + kw γ)`, `t = 1/(kw α + B_n/h²)`, `α = i/2 (1/R_f − 1/r_m)`,
/// `γ = i y²/(2 r_m)`, `β² = −(y/r_m)²` (`planar`: all |y| below f32's ε, MUST's branch without
/// the y terms).
pub(crate) fn mgbm(kw: f64, y: f64, rm: f64, h: f64, rf: f64, planar: bool) -> C64 {
    let alpha = C64::new(0.0, 0.5 * (1.0 / rf - 1.0 / rm));
    let gamma = C64::new(0.0, y * y / (2.0 * rm));
    let beta2 = -(y / rm) * (y / rm);
    let mut g = C64::new(0.0, 0.0);
    for n in 0..4 {
        let (a, b) = (C64::new(MGBM_A[n].0, MGBM_A[n].1), C64::new(MGBM_B[n].0, MGBM_B[n].1));
        let t = (kw * alpha + b / (h * h)).inv();
        g += if planar {
            a * csqrt(std::f64::consts::PI * t)
        } else {
            a * csqrt(std::f64::consts::PI * t) * (kw * kw * beta2 / 4.0 * t + kw * gamma).exp()
        };
    }
    g
}

/// Principal complex square root by the algebraic formula (no polar form: several times faster
/// than `Complex::sqrt`, the same branch cut as numpy's).
#[inline]
fn csqrt(z: C64) -> C64 {
    let m = (z.re * z.re + z.im * z.im).sqrt();
    let re = (0.5 * (m + z.re)).max(0.0).sqrt();
    let im = (0.5 * (m - z.re)).max(0.0).sqrt();
    C64::new(re, if z.im < 0.0 { -im } else { im })
}

fn pfield_impl(
    probe: &Probe,
    medium: &Medium,
    transmit: &Transmit,
    x: &[f64],
    y: Option<&[f64]>,
    z: &[f64],
    options: &PfieldOptions,
) -> Result<PressureField> {
    probe.validate()?;
    medium.validate()?;
    options.validate()?;
    transmit.validate(probe.n_elements)?;
    if x.len() != z.len() {
        return Err(SimusError::LengthMismatch { field: "pfield.z", got: z.len(), expected: x.len() });
    }
    if x.len() > MAX_POINTS {
        return Err(invalid("pfield.x", x.len(), "at most 1e8 points"));
    }
    if let Some(i) =
        (0..x.len()).find(|&i| !(x[i].is_finite() && z[i].is_finite() && x[i].abs() <= 100.0 && z[i].abs() <= 100.0))
    {
        return Err(invalid("pfield.x/z", format!("({}, {}) at point {i}", x[i], z[i]), "finite, |x|, |z| ≤ 100 m"));
    }
    if let Some(d) = transmit.delays.iter().find(|d| **d < 0.0) {
        return Err(invalid("pfield.delaysTX", d, "≥ 0 s (NaN: element off)"));
    }
    let geom = ArrayGeom::new(probe, medium, options.element_splitting, options.full_frequency_directivity);
    let (fc, c) = (probe.fc, medium.c);
    // geometry per point: r, amplitude (and |(2π/c)(W/M)/2 sin θ| with ffd), [e_pad·M]
    let per = geom.e_pad * geom.m;
    let n = x.len();
    let mut r = vec![0.0f64; n * per];
    let mut amp = vec![0.0f64; n * per];
    let mut dirb = vec![0.0f64; if geom.ffd { n * per } else { 0 }];
    {
        let work = |(p, (r, (amp, dirb))): PointBufs<'_>| {
            let mut blk = BlockGeom::default();
            blk.resize(1, &geom);
            let out = ScattererGeom {
                r: &mut blk.r,
                amp: &mut blk.amp,
                dirb: &mut blk.dirb,
                e_re: &mut blk.e_re,
                e_im: &mut blk.e_im,
            };
            geom.scatterer(x[p] as f32, z[p] as f32, 1.0, false, out);
            r.copy_from_slice(&blk.r);
            // not insonified behind the array (MUST: isOUT)
            let on = if geom.is_behind(x[p], z[p]) { 0.0 } else { 1.0 };
            amp.iter_mut().zip(&blk.amp).for_each(|(a, b)| *a = on * b);
            if geom.ffd {
                dirb.copy_from_slice(&blk.dirb);
            }
        };
        let dirb_chunks: Vec<&mut [f64]> =
            if geom.ffd { dirb.chunks_mut(per).collect() } else { (0..n).map(|_| &mut [][..]).collect() };
        r.par_chunks_mut(per).zip(amp.par_chunks_mut(per).zip(dirb_chunks.into_par_iter())).enumerate().for_each(work);
    }
    // Elevation: 3-D distances (clamped as MUST: ≥ λ/2), 1/r spreading, and each element's mean
    // distance over its sub-elements for the MGBM.
    let elev = match y {
        Some(_) => Some(elevation_params(probe)?),
        None => None,
    };
    let mut r_mean = Vec::new();
    if let Some(y) = y {
        let yf: Vec<f64> = y.iter().map(|v| f64::from(*v as f32)).collect();
        r_mean = vec![0.0f64; n * geom.n_el];
        r.par_chunks_mut(per).zip(amp.par_chunks_mut(per)).zip(r_mean.par_chunks_mut(geom.n_el)).enumerate().for_each(
            |(p, ((rp, ap), rm))| {
                let (xp, zp, yp) = (f64::from(x[p] as f32), f64::from(z[p] as f32), yf[p]);
                for (e, rme) in rm.iter_mut().enumerate() {
                    for m in 0..geom.m {
                        let i = layout(e, m, geom.m);
                        let (dx, dz) = geom.delta(e, m, xp, zp);
                        let r3 = (dx * dx + dz * dz + yp * yp).sqrt().max(geom.r_min);
                        ap[i] *= rp[i].sqrt() / r3;
                        rp[i] = r3;
                        *rme += r3 / geom.m as f64;
                    }
                }
            },
        );
    }
    // MUST's frequency grid and band
    let mut r_max = 0.0f64;
    for rp in r.chunks_exact(per) {
        for e in 0..geom.n_el {
            for m in 0..geom.m {
                r_max = r_max.max(rp[layout(e, m, geom.m)]);
            }
        }
    }
    let tau_max = transmit.delays.iter().filter(|d| !d.is_nan()).copied().fold(0.0, f64::max);
    let df0 = options.frequency_step / (r_max / c + tau_max);
    if !(df0.is_finite() && df0 > 0.0) {
        return Err(invalid("pfield.x/z", "no point at a distance from the array", "at least one point"));
    }
    let nf = 2 * (fc / df0).ceil() as usize + 1;
    if nf > 2_000_001 {
        return Err(invalid(
            "pfield.x/z",
            format!("{nf} frequencies (points {r_max:.3} m away)"),
            "a grid needing at most 2e6 frequencies",
        ));
    }
    let df = 2.0 * fc / (nf - 1) as f64;
    let pulse = PulseModel::new(fc, probe.tx_now, probe.bandwidth);
    let w = |k: usize| 2.0 * std::f64::consts::PI * k as f64 * df;
    let s: Vec<f64> = (0..nf).map(|k| (pulse.pulse_im(w(k)) * pulse.probe(w(k))).abs()).collect();
    let peak = s.iter().copied().fold(0.0, f64::max);
    let keep = |v: f64| 20.0 * (1e-200 + v / peak).log10() > options.db_thresh;
    let first = s.iter().position(|v| keep(*v)).unwrap_or(0);
    let last = s.iter().rposition(|v| keep(*v)).unwrap_or(0);
    let idx: Vec<bool> = (0..nf).map(|k| (first..=last).contains(&k)).collect();
    let bins: Vec<(f64, f64)> =
        (first..=last).map(|k| (k as f64 * df, pulse.pulse_im(w(k)) * pulse.probe(w(k)))).collect();
    // transmit weights and delays per (element, sub-element) in the point layout (0 on padding):
    // D_e(f) = apod_e e^{2πi f τ_e} is itself a phasor in f, so each (e, m) term of the sum is
    // one phasor, stepped across the band by e^{2πi df τ_e} · e^{(−β + 2πi/c) df r}
    let (mut w_em, mut tau_em) = (vec![0.0f64; per], vec![0.0f64; per]);
    for e in 0..geom.n_el {
        let tau = if transmit.delays[e].is_nan() { 0.0 } else { transmit.delays[e] };
        for m in 0..geom.m {
            let i = layout(e, m, geom.m);
            (w_em[i], tau_em[i]) = (transmit.weight(e), tau);
        }
    }
    let cor = if y.is_some() { df } else { df * geom.width };
    // MUST recomputes the MGBM at these band bins only (0-based), holding it in between.
    let n_bins = bins.len();
    let mgbm_bins: Vec<usize> = if y.is_some() { mgbm_bins(n_bins) } else { Vec::new() };
    let planar = y.is_some_and(|y| y.iter().all(|v| (v.abs() as f32) < f32::EPSILON));
    let e_of: Vec<usize> = {
        let mut e_of = vec![usize::MAX; per];
        for e in 0..geom.n_el {
            for m in 0..geom.m {
                e_of[layout(e, m, geom.m)] = e;
            }
        }
        e_of
    };
    let rms: Vec<f64> = (0..n)
        .into_par_iter()
        .map_init(
            || vec![0.0f64; 4 * per],
            |buf, p| {
                let (rp, ap) = (&r[p * per..(p + 1) * per], &amp[p * per..(p + 1) * per]);
                if ap.iter().all(|a| *a == 0.0) {
                    return 0.0;
                }
                let db = if geom.ffd { &dirb[p * per..(p + 1) * per] } else { &[][..] };
                // phasor of every (e, m) at the first bin and its step per bin, in f64
                let (ph, st) = buf.split_at_mut(2 * per);
                let (ph_re, ph_im) = ph.split_at_mut(per);
                let (st_re, st_im) = st.split_at_mut(per);
                let f0 = bins[0].0;
                for i in 0..per {
                    let (pr, pi) = geom.phasor(ap[i] * w_em[i], rp[i], f0);
                    let (ds, dc) = crate::math::sincos_turns(f0 * tau_em[i]);
                    (ph_re[i], ph_im[i]) = (pr * dc - pi * ds, pr * ds + pi * dc);
                    let (sr, si) = geom.phasor(1.0, rp[i], df);
                    let (ds, dc) = crate::math::sincos_turns(df * tau_em[i]);
                    (st_re[i], st_im[i]) = (sr * dc - si * ds, sr * ds + si * dc);
                }
                let tables = Tables { bins: &bins, db, ffd: geom.ffd };
                let sum = match (y, elev) {
                    (Some(y), Some((h, rf))) => {
                        // Per MGBM segment (the factor held constant, as MUST): the phasors,
                        // stepped across the whole band as in the 2-D field, carry each element's
                        // factor, swapped at the segment's first bin (× new/old factor).
                        let rm = &r_mean[p * geom.n_el..(p + 1) * geom.n_el];
                        let yp = f64::from(y[p] as f32);
                        let mut g_old = vec![C64::new(1.0, 0.0); geom.n_el];
                        let mut sum = 0.0;
                        for (j, &start) in mgbm_bins.iter().enumerate() {
                            let end = mgbm_bins.get(j + 1).copied().unwrap_or(bins.len());
                            if start >= end {
                                continue;
                            }
                            if start > 0 {
                                step(ph_re, ph_im, st_re, st_im);
                            }
                            let kw = 2.0 * std::f64::consts::PI * bins[start].0 / c;
                            let ratio: Vec<C64> = (0..geom.n_el)
                                .map(|e| {
                                    let g = mgbm(kw, yp, rm[e], h, rf, planar);
                                    let r = if g_old[e].norm_sqr() > 0.0 { g / g_old[e] } else { C64::new(0.0, 0.0) };
                                    g_old[e] = g;
                                    r
                                })
                                .collect();
                            for i in 0..per {
                                if e_of[i] != usize::MAX {
                                    let v = ratio[e_of[i]] * C64::new(ph_re[i], ph_im[i]);
                                    (ph_re[i], ph_im[i]) = (v.re, v.im);
                                }
                            }
                            let seg = Tables { bins: &bins[start..end], db, ffd: geom.ffd };
                            sum += band_power(&seg, ph_re, ph_im, st_re, st_im);
                        }
                        sum
                    }
                    _ => band_power(&tables, ph_re, ph_im, st_re, st_im),
                };
                (sum * cor).sqrt()
            },
        )
        .collect();
    Ok(PressureField { rms, df, band_hz: (bins[0].0, bins[bins.len() - 1].0), n_freq: bins.len(), idx })
}

/// What [`band_power`] reads: the band (frequency, |P H|) and, with full-frequency
/// directivity, the point's directivity factors.
struct Tables<'a> {
    bins: &'a [(f64, f64)],
    db: &'a [f64],
    ffd: bool,
}

/// `Σ_k |P H|² |Σ_(e,m) phasor|²` over the band for one point (the phasors include the transmit
/// weights and delays), stepping them
/// (AVX2 build chosen at run time: the same operations, no FMA contraction).
fn band_power(t: &Tables<'_>, ph_re: &mut [f64], ph_im: &mut [f64], st_re: &[f64], st_im: &[f64]) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked at run time).
        return unsafe { band_power_avx2(t, ph_re, ph_im, st_re, st_im) };
    }
    band_power_body(t, ph_re, ph_im, st_re, st_im)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn band_power_avx2(t: &Tables<'_>, ph_re: &mut [f64], ph_im: &mut [f64], st_re: &[f64], st_im: &[f64]) -> f64 {
    band_power_body(t, ph_re, ph_im, st_re, st_im)
}

#[inline(always)]
fn band_power_body(t: &Tables<'_>, ph_re: &mut [f64], ph_im: &mut [f64], st_re: &[f64], st_im: &[f64]) -> f64 {
    let (bins, db) = (t.bins, t.db);
    let mut sum = 0.0;
    for (kb, (f, spec)) in bins.iter().enumerate() {
        if kb > 0 {
            step(ph_re, ph_im, st_re, st_im);
        }
        let (tr, ti) = if t.ffd {
            let (mut tr, mut ti) = (0.0, 0.0);
            for i in 0..ph_re.len() {
                let dir = sinc_eps(db[i] * f);
                tr += dir * ph_re[i];
                ti += dir * ph_im[i];
            }
            (tr, ti)
        } else {
            (lane_sum(ph_re), lane_sum(ph_im))
        };
        sum += spec * spec * (tr * tr + ti * ti);
    }
    sum
}

/// `z ← z·s` element-wise for complex vectors in split re/im form (vectorises).
#[inline(always)]
fn step(z_re: &mut [f64], z_im: &mut [f64], s_re: &[f64], s_im: &[f64]) {
    for (((zr, zi), sr), si) in z_re.iter_mut().zip(z_im.iter_mut()).zip(s_re).zip(s_im) {
        let (a, b) = (*zr, *zi);
        *zr = a * sr - b * si;
        *zi = a * si + b * sr;
    }
}

/// `Σ v` in 8 interleaved lanes (a fixed order; vectorises).
#[inline(always)]
fn lane_sum(v: &[f64]) -> f64 {
    const W: usize = 8;
    let mut acc = [0.0f64; W];
    let n = v.len() / W * W;
    for c in v[..n].chunks_exact(W) {
        for l in 0..W {
            acc[l] += c[l];
        }
    }
    acc.iter().sum::<f64>() + v[n..].iter().sum::<f64>()
}

/// Index of (element e, sub-element m) in a point's geometry (`[chunk][m][lane]`).
fn layout(e: usize, m: usize, n_m: usize) -> usize {
    use crate::lanes::L;
    ((e / L) * n_m + m) * L + e % L
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn probe8() -> Probe {
        let mut p = Probe::paper_5mhz();
        p.n_elements = 8;
        p
    }

    #[allow(clippy::too_many_arguments)]
    /// PFIELD written out independently: every phasor evaluated at every frequency, the sums in
    /// the formula's order (the points rounded to f32 as in the library and PyMUST).
    fn direct(
        probe: &Probe,
        medium: &Medium,
        tx: &Transmit,
        x: f64,
        z: f64,
        m: usize,
        df: f64,
        band: (f64, f64),
    ) -> f64 {
        let (fc, c) = (probe.fc, medium.c);
        let (x, z) = (f64::from(x as f32), f64::from(z as f32));
        let w = probe.element_width();
        let seg = w / m as f64;
        let pulse = PulseModel::new(fc, probe.tx_now, probe.bandwidth);
        let mut sum = 0.0;
        let mut f = band.0;
        while f <= band.1 * (1.0 + 1e-12) {
            let k = 2.0 * PI * f / c;
            let (mut tr, mut ti) = (0.0, 0.0);
            for e in 0..probe.n_elements {
                let (mut er, mut ei) = (0.0, 0.0);
                for j in 0..m {
                    let xs = probe.element_x(e) - w / 2.0 + seg / 2.0 + j as f64 * seg;
                    let dx = x - xs;
                    let d = dx.hypot(z);
                    let r = d.max(c / fc / 2.0);
                    let eps = f64::from(f32::EPSILON);
                    let sin_t = ((dx + eps) / (d + eps)).clamp(-1.0, 1.0);
                    let obli = (1.0 - sin_t * sin_t).sqrt();
                    let arg = 2.0 * PI * fc / c * seg / 2.0 * sin_t;
                    let dir = if arg == 0.0 { 1.0 } else { arg.sin() / arg };
                    let a = obli * dir / r.sqrt() / m as f64;
                    er += a * (k * r).cos();
                    ei += a * (k * r).sin();
                }
                let g = tx.weight(e);
                let tau = if tx.delays[e].is_nan() { 0.0 } else { tx.delays[e] };
                let (dr, di) = (g * (2.0 * PI * f * tau).cos(), g * (2.0 * PI * f * tau).sin());
                tr += dr * er - di * ei;
                ti += dr * ei + di * er;
            }
            let s = pulse.pulse_im(2.0 * PI * f) * pulse.probe(2.0 * PI * f);
            sum += s * s * (tr * tr + ti * ti);
            f += df;
        }
        (sum * df * w).sqrt()
    }

    #[test]
    fn pfield_equals_an_independent_direct_evaluation() {
        let (probe, medium) = (probe8(), Medium::default());
        let tx = Transmit::focused(&probe, medium.c, 0.5e-3, 8e-3).unwrap();
        let xs = [-3e-3, 0.0, 0.7e-3, 2.2e-3, 4e-3];
        let zs = [2e-3, 5e-3, 8e-3, 11e-3, 0.1e-3];
        let opts = PfieldOptions { element_splitting: Some(2), ..Default::default() };
        let f = pfield(&probe, &medium, &tx, &xs, &zs, &opts).unwrap();
        assert_eq!(f.idx.iter().filter(|b| **b).count(), f.n_freq);
        for i in 0..xs.len() {
            let want = direct(&probe, &medium, &tx, xs[i], zs[i], 2, f.df, f.band_hz);
            assert!((f.rms[i] / want - 1.0).abs() < 1e-9, "point {i}: {} vs {want}", f.rms[i]);
        }
    }

    #[test]
    fn symmetry_off_elements_and_the_half_space_behind() {
        let (probe, medium) = (probe8(), Medium::default());
        let tx = Transmit::plane_wave(&probe, medium.c, 0.0).unwrap();
        // a 0° plane wave of a symmetric array: mirror points in x have the same field
        let (xs, zs) = ([-2.5e-3, 2.5e-3, -0.9e-3, 0.9e-3, 1e-3], [6e-3, 6e-3, 3e-3, 3e-3, -1e-3]);
        let f = pfield(&probe, &medium, &tx, &xs, &zs, &PfieldOptions::default()).unwrap();
        // (to MUST's ε = 2^−23 m offset in sin θ = (dx + ε)/(d + ε), which is not symmetric in dx)
        let (r1, r2) = (f.rms[0] / f.rms[1] - 1.0, f.rms[2] / f.rms[3] - 1.0);
        assert!(r1.abs() < 1e-4 && r2.abs() < 1e-4, "{r1:e} {r2:e}");
        assert_eq!(f.rms[4], 0.0, "behind the array");
        assert!(f.rms[0] > 0.0);
        // an element off (NaN delay) is the same as apodisation 0
        let mut off = tx.clone();
        off.delays[3] = f64::NAN;
        let mut apod = tx.clone();
        apod.apodization = (0..8).map(|e| if e == 3 { 0.0 } else { 1.0 }).collect();
        let (a, b) = (
            pfield(&probe, &medium, &off, &xs, &zs, &PfieldOptions::default()).unwrap(),
            pfield(&probe, &medium, &apod, &xs, &zs, &PfieldOptions::default()).unwrap(),
        );
        assert_eq!(a.rms, b.rms);
        assert!((a.rms[2] / f.rms[2] - 1.0).abs() > 1e-3, "the element off changes the field");
    }

    #[test]
    fn bad_inputs_name_the_field() {
        let (probe, medium) = (probe8(), Medium::default());
        let tx = Transmit::plane_wave(&probe, medium.c, 0.0).unwrap();
        let o = PfieldOptions::default();
        let err = |r: Result<PressureField>| r.unwrap_err().to_string();
        assert!(err(pfield(&probe, &medium, &tx, &[0.0, 1.0], &[0.01], &o)).contains("pfield.z"));
        assert!(err(pfield(&probe, &medium, &tx, &[f64::NAN], &[0.01], &o)).contains("pfield.x/z"));
        let mut neg = tx.clone();
        neg.delays[0] = -1e-6;
        let e = err(pfield(&probe, &medium, &neg, &[0.0], &[0.01], &o));
        assert!(e.contains("delays"), "{e}");
        let bad = PfieldOptions { db_thresh: 0.0, ..Default::default() };
        assert!(err(pfield(&probe, &medium, &tx, &[0.0], &[0.01], &bad)).contains("options.dBThresh"));
        let bad = PfieldOptions { element_splitting: Some(0), ..Default::default() };
        assert!(err(pfield(&probe, &medium, &tx, &[0.0], &[0.01], &bad)).contains("options.ElementSplitting"));
        let mut convex = probe.clone();
        convex.radius = Some(-0.04);
        assert!(err(pfield(&convex, &medium, &tx, &[0.0], &[0.01], &o)).contains("probe.radius"));
        convex.radius = Some(0.4e-3); // 8 × 0.3 mm do not fit on half a circle of 0.4 mm
        assert!(err(pfield(&convex, &medium, &tx, &[0.0], &[0.01], &o)).contains("probe.n_elements"));
    }

    #[test]
    fn mgbm_is_the_fresnel_integral_over_the_element_height() {
        // The MGBM factor approximates ∫_{−h/2}^{h/2} exp(ik (y − y')²/(2r) − ik y'²/(2R_f)) dy'
        // (paraxial propagation across a lens-focused element of height h) with four Gaussians:
        // within 3 % on the main lobe (MUST's accuracy), checked by a direct quadrature.
        let (k, h, rf) = (2.0 * PI * 7.6e6 / 1540.0, 5e-3, 18e-3);
        let quad = |y: f64, r: f64| {
            let n = 20_000;
            let mut acc = C64::new(0.0, 0.0);
            for i in 0..=n {
                let yp = -h / 2.0 + h * i as f64 / n as f64;
                let w = if i == 0 || i == n { 0.5 } else { 1.0 };
                let ph = k * (y - yp) * (y - yp) / (2.0 * r) - k * yp * yp / (2.0 * rf);
                acc += w * C64::from_polar(1.0, ph);
            }
            acc * (h / n as f64)
        };
        for (r, y) in [(10e-3, 0.0), (18e-3, 0.0), (18e-3, 0.3e-3), (30e-3, 1e-3), (40e-3, 0.5e-3), (25e-3, -0.4e-3)] {
            let (m, q) = (mgbm(k, y, r, h, rf, false), quad(y, r));
            assert!((m - q).norm() < 0.03 * q.norm(), "r {r} y {y}: {m} vs {q}");
            if y == 0.0 {
                assert!((mgbm(k, 0.0, r, h, rf, true) - m).norm() < 1e-12 * m.norm());
            }
        }
    }

    #[test]
    fn pfield_3d_in_the_plane_is_pfield_and_is_symmetric_in_y() {
        let (probe, medium) = (Probe::preset("L11-5v").unwrap(), Medium::default());
        let tx = Transmit::plane_wave(&probe, medium.c, 0.1).unwrap();
        let o = PfieldOptions::default();
        let xs = [-3e-3, 0.0, 2e-3, 4e-3];
        let zs = [10e-3, 15e-3, 20e-3, 30e-3];
        let flat = pfield(&probe, &medium, &tx, &xs, &zs, &o).unwrap();
        let zero = pfield_3d(&probe, &medium, &tx, &xs, &[0.0; 4], &zs, &o).unwrap();
        assert_eq!(flat.rms, zero.rms);
        let up = pfield_3d(&probe, &medium, &tx, &xs, &[1e-3; 4], &zs, &o).unwrap();
        let down = pfield_3d(&probe, &medium, &tx, &xs, &[-1e-3; 4], &zs, &o).unwrap();
        assert_eq!(up.rms, down.rms);
        // Off the plane the element height's beam is weaker than on it (y = 1e-8: the plane with
        // the elevation model on).
        let on = pfield_3d(&probe, &medium, &tx, &xs, &[1e-8; 4], &zs, &o).unwrap();
        assert!(up.rms.iter().zip(&on.rms).all(|(u, c)| u < c), "{:?} {:?}", up.rms, on.rms);
        let err = |r: Result<PressureField>| r.unwrap_err().to_string();
        assert!(err(pfield_3d(&probe, &medium, &tx, &xs, &[0.0; 3], &zs, &o)).contains("pfield.y"));
        assert!(err(pfield_3d(&probe, &medium, &tx, &xs, &[f64::NAN; 4], &zs, &o)).contains("pfield.y"));
        let mut flat_el = probe.clone();
        flat_el.height = Some(0.0);
        assert!(err(pfield_3d(&flat_el, &medium, &tx, &xs, &[1e-3; 4], &zs, &o)).contains("param.height"));
    }
}
