//! Speckle tracking (MUST/PyMUST `sptrack`; Garcia, Lantelme & Saloux 2018; Perrot & Garcia,
//! IUS 2018): the motion of the speckle between frames `t` and `t + lag` of a packet, by
//! FFT cross-correlation of interrogation windows, as a vector velocity on the image grid — the
//! same product as the vector-Doppler estimators, so the regulariser, the evaluator and the
//! sweeps take it unchanged.
//!
//! Per packet ([`SpeckleAssembler`], what the `speckle-tracking` node does):
//! 1. each image's envelope `|IQ|` (after the optional clutter filter of the I/Q over slow time);
//! 2. for each pass (window sizes decreasing, MUST's multi-grid scheme), windows of `m × n`
//!    pixels on a grid of centres (`overlap`), the second window offset by the previous pass's
//!    displacement rounded to whole pixels (half of it on each window, so that the estimate
//!    belongs to the window centre); an **ensemble correlation**: the cross-spectra of every pair
//!    (`t`, `t + lag`) of every look are summed (mean removed, Hann-weighted windows);
//! 3. the integer peak of the correlation within ± half a window, refined to sub-pixel either by
//!    MUST's three-point parabolic fit (`subpixel = "parabolic"`) or, by default, by Newton's
//!    method on the correlation's own trigonometric (Fourier) interpolant, which has no
//!    pixel-locking bias for a translation (`subpixel = "fourier"`, the parabola's estimate is the
//!    start);
//! 4. validation: a correlation coefficient below `min_correlation` or the normalised median
//!    test (Westerweel & Scarano 2005, 3 × 3 neighbours, ε = 0.1 px) above `median_threshold`
//!    marks a window invalid; invalid windows take the median of their valid neighbours for the
//!    next pass's offsets (MUST smooths with `smoothn` between passes instead: here the
//!    regulariser node does that on the output);
//! 5. the last pass's centres are interpolated bilinearly onto the image grid (constant beyond
//!    the outermost centres); a pixel whose nearest centre is invalid is flagged
//!    [`crate::flags::NO_ESTIMATE`]. `v = d · (dx, dz) · prf / lag`.
//!
//! The weight plane is `√ρ` (ρ the correlation coefficient of the nearest centre), MUST's
//! smoothn weights.

use std::collections::BTreeMap;
use std::sync::Arc;

use rayon::prelude::*;
use rustfft::{Fft, FftPlanner};
use serde::{Deserialize, Serialize};
use sonoflow_beamform::error::{invalid, Result};
use sonoflow_beamform::{BeamformError, Grid, C32};

use crate::clutter::{ClutterParams, ClutterReport};
use crate::estimator::flags;
use crate::packet::{LookCollector, LookHeader, LookKey, Stream};

type C64 = rustfft::num_complex::Complex<f64>;

/// Sub-pixel refinement of the correlation peak.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Subpixel {
    /// Maximum of the correlation's trigonometric interpolant (Newton from the parabola's
    /// estimate): unbiased for a translation.
    #[default]
    Fourier,
    /// Three-point parabola per axis (MUST `sptrack`, `subpix = 'PF'`).
    Parabolic,
}

/// What is correlated.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TrackedImage {
    /// The envelope `|IQ|` (MUST tracks B-mode images): one real correlation over all looks.
    #[default]
    Envelope,
    /// The complex I/Q: per look a complex correlation (its Doppler phase is the look's), the
    /// peak of `Σ_looks |c|²`. Measured worse than the envelope on the shipped scenes
    /// (docs/nodes.md, "Speckle tracking").
    Iq,
}

/// Parameters of the speckle tracker (the `speckle-tracking` node's params).
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct SpeckleParams {
    /// Interrogation windows per pass, `[rows (z), columns (x)]` in pixels, each 4 ..= 256,
    /// non-increasing from pass to pass (MUST `winsize`), 1 to 6 passes.
    pub windows: Vec<[usize; 2]>,
    /// Overlap of neighbouring windows, in [0, 0.95] (MUST `overlap` / 100).
    pub overlap: f64,
    /// Frames between the two images of a pair (MUST `iminc`), 1 ..= 64; default 10 (the shortest
    /// lag with a rigid-translation bias below 2 % on the 0.1 mm plug: docs/nodes.md).
    pub lag: usize,
    /// `fourier` (default) or `parabolic` (MUST).
    pub subpixel: Subpixel,
    /// Windows whose correlation coefficient is below this are invalid, in [0, 1).
    pub min_correlation: f64,
    /// Normalised-median-test threshold (Westerweel & Scarano 2005); 0 = off, else in (0, 100].
    pub median_threshold: f64,
    /// `envelope` (default) or `iq` ([`TrackedImage`]).
    pub image: TrackedImage,
    /// Clutter (wall) filter of the I/Q over slow time before the envelope (as the `doppler`
    /// node's `clutter`); absent: none.
    pub clutter: Option<ClutterParams>,
}

impl Default for SpeckleParams {
    fn default() -> Self {
        Self {
            windows: vec![[32, 32], [16, 16]],
            overlap: 0.75,
            lag: 10,
            subpixel: Subpixel::Fourier,
            min_correlation: 0.2,
            median_threshold: 2.0,
            image: TrackedImage::Envelope,
            clutter: None,
        }
    }
}

impl SpeckleParams {
    /// Checks every field (errors name it).
    pub fn validate(&self) -> Result<()> {
        if self.windows.is_empty() || self.windows.len() > 6 {
            return Err(invalid("windows", self.windows.len(), "1 to 6 passes of [rows, columns]"));
        }
        for (k, w) in self.windows.iter().enumerate() {
            if w.iter().any(|&s| !(4..=256).contains(&s)) {
                return Err(invalid("windows", format!("{w:?}"), "each size in 4 ..= 256 pixels"));
            }
            if k > 0 {
                let p = self.windows[k - 1];
                if w[0] > p[0] || w[1] > p[1] {
                    return Err(invalid("windows", format!("{w:?} after {p:?}"), "non-increasing from pass to pass"));
                }
            }
        }
        if !(self.overlap.is_finite() && (0.0..=0.95).contains(&self.overlap)) {
            return Err(invalid("overlap", self.overlap, "in [0, 0.95]"));
        }
        if !(1..=64).contains(&self.lag) {
            return Err(invalid("lag", self.lag, "1 ..= 64"));
        }
        if !(self.min_correlation.is_finite() && (0.0..1.0).contains(&self.min_correlation)) {
            return Err(invalid("min_correlation", self.min_correlation, "in [0, 1)"));
        }
        let t = self.median_threshold;
        if !(t == 0.0 || (t.is_finite() && t > 0.0 && t <= 100.0)) {
            return Err(invalid("median_threshold", t, "0 (off) or in (0, 100]"));
        }
        if let Some(c) = &self.clutter {
            c.validate()?;
        }
        Ok(())
    }
}

/// Displacements of one pass at its window centres (pixels; `i` rows/z, `j` columns/x).
#[derive(Clone, Debug, PartialEq)]
pub struct Tracked {
    /// Row of the first centre and the step between centres (pixels).
    pub i_first: f64,
    /// See `i_first`.
    pub i_step: f64,
    /// Column of the first centre and the step between centres (pixels).
    pub j_first: f64,
    /// See `j_first`.
    pub j_step: f64,
    /// Centres per column and per row.
    pub ni: usize,
    /// See `ni`.
    pub nj: usize,
    /// Row displacement (pixels, +i = deeper), `ni × nj` row-major; invalid ones replaced by
    /// their neighbours' median.
    pub di: Vec<f64>,
    /// Column displacement (pixels, +j = +x).
    pub dj: Vec<f64>,
    /// Correlation coefficient at the peak (0 where no estimate).
    pub rho: Vec<f64>,
    /// Valid estimate (correlation and median test passed).
    pub valid: Vec<bool>,
}

impl Tracked {
    /// Fractional centre indices of pixel row `i`, column `j` (clamped to the centre grid).
    fn coords(&self, i: f64, j: f64) -> (f64, f64) {
        let u = ((i - self.i_first) / self.i_step).clamp(0.0, (self.ni - 1) as f64);
        let v = ((j - self.j_first) / self.j_step).clamp(0.0, (self.nj - 1) as f64);
        (u, v)
    }

    /// Bilinear interpolation of a centre plane at pixel (`i`, `j`).
    fn sample(&self, plane: &[f64], i: f64, j: f64) -> f64 {
        let (u, v) = self.coords(i, j);
        let (u0, v0) = (u.floor() as usize, v.floor() as usize);
        let (u1, v1) = ((u0 + 1).min(self.ni - 1), (v0 + 1).min(self.nj - 1));
        let (fu, fv) = (u - u0 as f64, v - v0 as f64);
        let at = |a: usize, b: usize| plane[a * self.nj + b];
        (1.0 - fu) * ((1.0 - fv) * at(u0, v0) + fv * at(u0, v1)) + fu * ((1.0 - fv) * at(u1, v0) + fv * at(u1, v1))
    }

    /// Index of the centre nearest pixel (`i`, `j`).
    fn nearest(&self, i: f64, j: f64) -> usize {
        let (u, v) = self.coords(i, j);
        u.round() as usize * self.nj + v.round() as usize
    }

    /// The field on an `nz × nx` pixel grid: (di, dj, ρ, valid) per pixel, row-major.
    pub fn to_pixels(&self, nz: usize, nx: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<bool>) {
        let n = nz * nx;
        let (mut di, mut dj, mut rho, mut valid) =
            (Vec::with_capacity(n), Vec::with_capacity(n), vec![0.0; n], vec![false; n]);
        for i in 0..nz {
            for j in 0..nx {
                let (fi, fj) = (i as f64, j as f64);
                di.push(self.sample(&self.di, fi, fj));
                dj.push(self.sample(&self.dj, fi, fj));
                let k = self.nearest(fi, fj);
                rho[i * nx + j] = self.rho[k];
                valid[i * nx + j] = self.valid[k];
            }
        }
        (di, dj, rho, valid)
    }
}

/// One window's estimate.
#[derive(Clone, Copy, Debug)]
struct Estimate {
    di: f64,
    dj: f64,
    rho: f64,
    ok: bool,
}

const NONE: Estimate = Estimate { di: 0.0, dj: 0.0, rho: 0.0, ok: false };

/// 2-D FFT of an `m × n` window (row-major) with rustfft, forward or inverse.
struct Fft2 {
    rows: Arc<dyn Fft<f64>>,
    cols: Arc<dyn Fft<f64>>,
    m: usize,
    n: usize,
}

impl Fft2 {
    fn new(planner: &mut FftPlanner<f64>, m: usize, n: usize, inverse: bool) -> Self {
        let (rows, cols) = match inverse {
            false => (planner.plan_fft_forward(n), planner.plan_fft_forward(m)),
            true => (planner.plan_fft_inverse(n), planner.plan_fft_inverse(m)),
        };
        Self { rows, cols, m, n }
    }

    /// In place; `col` is scratch of length `m`.
    fn run(&self, a: &mut [C64], col: &mut [C64]) {
        self.rows.process(a);
        for j in 0..self.n {
            for i in 0..self.m {
                col[i] = a[i * self.n + j];
            }
            self.cols.process(col);
            for i in 0..self.m {
                a[i * self.n + j] = col[i];
            }
        }
    }
}

/// Symmetric Hann window of `m` points without its zero end points (MUST: `hann(m+2)(2:end-1)`).
fn hann(m: usize) -> Vec<f64> {
    (1..=m).map(|k| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * k as f64 / (m + 1) as f64).cos()).collect()
}

/// `W(τ) = Σ_x h(x) h((x + τ) mod m) / Σ_x h²` for τ = 0 … m − 1.
fn circular_autocorrelation(h: &[f64]) -> Vec<f64> {
    let m = h.len();
    let e: f64 = h.iter().map(|v| v * v).sum();
    (0..m).map(|t| (0..m).map(|x| h[x] * h[(x + t) % m]).sum::<f64>() / e).collect()
}

/// Signed frequency/lag of DFT index `k` of `m` points, and whether it is the Nyquist bin.
fn signed(k: usize, m: usize) -> (f64, bool) {
    if 2 * k == m {
        (k as f64, true)
    } else if 2 * k > m {
        (k as f64 - m as f64, false)
    } else {
        (k as f64, false)
    }
}

/// Per-axis factor of the trigonometric interpolant at lag `tau` and its first two derivatives:
/// `exp(2πi k τ / m)`, or `cos(π τ)` for the Nyquist bin (the mean of ±m/2).
fn axis_factor(k: usize, m: usize, tau: f64) -> [C64; 3] {
    let (ks, nyq) = signed(k, m);
    if nyq {
        let w = std::f64::consts::PI;
        let (s, c) = (w * tau).sin_cos();
        return [C64::new(c, 0.0), C64::new(-w * s, 0.0), C64::new(-w * w * c, 0.0)];
    }
    let w = 2.0 * std::f64::consts::PI * ks / m as f64;
    let e = C64::from_polar(1.0, w * tau);
    let iw = C64::new(0.0, w);
    [e, e * iw, e * iw * iw]
}

/// The interpolant of each spectrum at `τ` and its derivatives `[c, ∂i, ∂j, ∂ii, ∂jj, ∂ij]`.
fn interpolant(s: &[C64], m: usize, n: usize, ti: f64, tj: f64) -> [C64; 6] {
    let fi: Vec<[C64; 3]> = (0..m).map(|k| axis_factor(k, m, ti)).collect();
    let fj: Vec<[C64; 3]> = (0..n).map(|k| axis_factor(k, n, tj)).collect();
    let zero = C64::new(0.0, 0.0);
    let mut out = [zero; 6];
    for a in 0..m {
        let row = &s[a * n..(a + 1) * n];
        let (mut r0, mut r1, mut r2) = (zero, zero, zero);
        for (b, v) in row.iter().enumerate() {
            r0 += v * fj[b][0];
            r1 += v * fj[b][1];
            r2 += v * fj[b][2];
        }
        out[0] += r0 * fi[a][0];
        out[1] += r0 * fi[a][1];
        out[2] += r1 * fi[a][0];
        out[3] += r0 * fi[a][2];
        out[4] += r2 * fi[a][0];
        out[5] += r1 * fi[a][1];
    }
    out
}

/// Newton's method for the maximum of the correlation's trigonometric interpolant
/// `c(τ) = Σ_k S(k) e^{2πi(k_i τ_i/m + k_j τ_j/n)}` from `start`: of `Re c` for one real
/// correlation (envelope), of `Σ_l |c_l|²` for the complex correlations of the looks (I/Q).
/// None if it leaves the integer peak's pixel by more than one pixel or does not reach a maximum.
fn fourier_peak(
    spectra: &[Vec<C64>],
    power: bool,
    m: usize,
    n: usize,
    start: (f64, f64),
    peak: (f64, f64),
) -> Option<(f64, f64)> {
    let (mut ti, mut tj) = start;
    for _ in 0..20 {
        let (mut gi, mut gj, mut hii, mut hjj, mut hij) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for s in spectra {
            let [c, ci, cj, cii, cjj, cij] = interpolant(s, m, n, ti, tj);
            if power {
                // ∂|c|² = 2 Re(c̄ ∂c); ∂²|c|² = 2 Re(∂c̄ ∂c + c̄ ∂²c).
                gi += 2.0 * (c.conj() * ci).re;
                gj += 2.0 * (c.conj() * cj).re;
                hii += 2.0 * (ci.conj() * ci + c.conj() * cii).re;
                hjj += 2.0 * (cj.conj() * cj + c.conj() * cjj).re;
                hij += 2.0 * (ci.conj() * cj + c.conj() * cij).re;
            } else {
                (gi, gj, hii, hjj, hij) = (gi + ci.re, gj + cj.re, hii + cii.re, hjj + cjj.re, hij + cij.re);
            }
        }
        let det = hii * hjj - hij * hij;
        if !(det > 0.0 && hii < 0.0) {
            return None;
        }
        let si = -(hjj * gi - hij * gj) / det;
        let sj = -(hii * gj - hij * gi) / det;
        ti += si;
        tj += sj;
        if (ti - peak.0).abs() > 1.0 || (tj - peak.1).abs() > 1.0 {
            return None;
        }
        if si.abs() < 1e-6 && sj.abs() < 1e-6 {
            return Some((ti, tj));
        }
    }
    Some((ti, tj))
}

/// The images of one look: `frames × (nz·nx)` I/Q samples (or real images with zero
/// imaginary part).
pub type LookImages = Vec<Vec<C32>>;

/// Speckle tracking on envelope images ([`SpeckleParams`]).
pub struct SpeckleTracker {
    params: SpeckleParams,
}

impl SpeckleTracker {
    /// Validates `params`.
    pub fn new(params: SpeckleParams) -> Result<Self> {
        params.validate()?;
        Ok(Self { params })
    }

    /// The parameters.
    pub fn params(&self) -> &SpeckleParams {
        &self.params
    }

    /// Tracks the displacement from frame `t` to `t + lag` (pixels) over every look of `looks`
    /// (each `frames × nz·nx`, row-major, z rows); returns the last pass at its window centres.
    pub fn track(&self, looks: &[LookImages], nz: usize, nx: usize) -> Result<Tracked> {
        let p = &self.params;
        let n_img = nz * nx;
        if looks.is_empty() || looks.iter().any(|l| l.len() <= p.lag) {
            return Err(BeamformError::ConfigMismatch {
                what: format!(
                    "speckle tracking: every look needs more than lag = {} frames, got {:?}",
                    p.lag,
                    looks.iter().map(Vec::len).collect::<Vec<_>>()
                ),
            });
        }
        if looks.iter().flatten().any(|f| f.len() != n_img) {
            return Err(BeamformError::ConfigMismatch { what: format!("speckle tracking: images are not {nz}×{nx}") });
        }
        let mut planner = FftPlanner::new();
        let mut prev: Option<Tracked> = None;
        for &[m, n] in &p.windows {
            if m > nz || n > nx {
                return Err(BeamformError::ConfigMismatch {
                    what: format!("speckle tracking: window {m}×{n} larger than the {nz}×{nx} image (param `windows`)"),
                });
            }
            let si = ((m as f64 * (1.0 - p.overlap)).ceil() as usize).max(1);
            let sj = ((n as f64 * (1.0 - p.overlap)).ceil() as usize).max(1);
            let i0s: Vec<usize> = (0..=nz - m).step_by(si).collect();
            let j0s: Vec<usize> = (0..=nx - n).step_by(sj).collect();
            let (ci, cj) = ((m - 1) as f64 / 2.0, (n - 1) as f64 / 2.0);
            let fwd = Fft2::new(&mut planner, m, n, false);
            let inv = Fft2::new(&mut planner, m, n, true);
            let (hi, hj) = (hann(m), hann(n));
            let (wi, wj) = (circular_autocorrelation(&hi), circular_autocorrelation(&hj));
            let ctx = WindowCtx {
                looks,
                nz,
                nx,
                m,
                n,
                lag: p.lag,
                hi: &hi,
                hj: &hj,
                wi: &wi,
                wj: &wj,
                fwd: &fwd,
                inv: &inv,
                subpixel: p.subpixel,
                image: p.image,
            };
            let cells: Vec<(usize, usize)> = i0s.iter().flat_map(|&i| j0s.iter().map(move |&j| (i, j))).collect();
            let est: Vec<Estimate> = cells
                .par_iter()
                .map(|&(i0, j0)| {
                    let (oi, oj) = match &prev {
                        Some(t) => {
                            let (ic, jc) = (i0 as f64 + ci, j0 as f64 + cj);
                            (t.sample(&t.di, ic, jc).round() as i64, t.sample(&t.dj, ic, jc).round() as i64)
                        }
                        None => (0, 0),
                    };
                    ctx.estimate(i0, j0, oi, oj)
                })
                .collect();
            let mut t = Tracked {
                i_first: ci,
                i_step: si as f64,
                j_first: cj,
                j_step: sj as f64,
                ni: i0s.len(),
                nj: j0s.len(),
                di: est.iter().map(|e| e.di).collect(),
                dj: est.iter().map(|e| e.dj).collect(),
                rho: est.iter().map(|e| e.rho).collect(),
                valid: est.iter().map(|e| e.ok && e.rho >= p.min_correlation).collect(),
            };
            if p.median_threshold > 0.0 {
                median_test(&mut t, p.median_threshold);
            }
            fill_invalid(&mut t);
            prev = Some(t);
        }
        prev.ok_or_else(|| BeamformError::ConfigMismatch { what: "speckle tracking: no pass".into() })
    }
}

/// What every window of a pass shares.
struct WindowCtx<'a> {
    looks: &'a [LookImages],
    nz: usize,
    nx: usize,
    m: usize,
    n: usize,
    lag: usize,
    hi: &'a [f64],
    hj: &'a [f64],
    wi: &'a [f64],
    wj: &'a [f64],
    fwd: &'a Fft2,
    inv: &'a Fft2,
    subpixel: Subpixel,
    image: TrackedImage,
}

impl WindowCtx<'_> {
    /// The window at (`i0`, `j0`) with the second image offset by (`oi`, `oj`) pixels.
    fn estimate(&self, i0: usize, j0: usize, oi: i64, oj: i64) -> Estimate {
        let (m, n) = (self.m, self.n);
        // Half the offset on each window (the estimate belongs to the centre).
        // Near the image border the pair moves inward, keeping its offset (the estimate then
        // belongs to a centre up to half the offset away); offsets wider than the image: none.
        let place = |start: i64, off: i64, size: usize, len: usize| -> Option<i64> {
            let (lo, hi) = (start.min(start + off), start.max(start + off));
            if (hi - lo) as usize + size > len {
                return None;
            }
            let shift = (-lo).max(0) - (hi + size as i64 - len as i64).max(0);
            Some(start + shift)
        };
        let (Some(a_i), Some(a_j)) =
            (place(i0 as i64 - oi.div_euclid(2), oi, m, self.nz), place(j0 as i64 - oj.div_euclid(2), oj, n, self.nx))
        else {
            return NONE;
        };
        let (b_i, b_j) = (a_i + oi, a_j + oj);
        let (a, b) = ((a_i as usize, a_j as usize), (b_i as usize, b_j as usize));
        let Some((mut corr, power)) = (match self.image {
            TrackedImage::Envelope => self.envelope_correlation(a, b).map(|c| (vec![c], false)),
            TrackedImage::Iq => self.iq_correlations(a, b).map(|c| (c, true)),
        }) else {
            return NONE;
        };
        // The product of the two Hann windows pulls the peak toward τ = 0 (E c(τ) = W(τ)·R(τ − d),
        // W the windows' circular autocorrelation): dividing by W removes that bias.
        for c in &mut corr {
            for ki in 0..m {
                for kj in 0..n {
                    c[ki * n + kj] /= self.wi[ki] * self.wj[kj];
                }
            }
        }
        let at = |c: &[C64], i: i64, j: i64| c[(i.rem_euclid(m as i64) as usize) * n + j.rem_euclid(n as i64) as usize];
        let objective = |i: i64, j: i64| match power {
            false => at(&corr[0], i, j).re,
            true => corr.iter().map(|c| at(c, i, j).norm_sqr()).sum::<f64>(),
        };
        // Integer peak within ± half a window (Nyquist lag excluded).
        let (hm, hn) = (((m - 1) / 2) as i64, ((n - 1) / 2) as i64);
        let (mut best, mut pi, mut pj) = (f64::NEG_INFINITY, 0i64, 0i64);
        for i in -hm..=hm {
            for j in -hn..=hn {
                let v = objective(i, j);
                if v > best {
                    (best, pi, pj) = (v, i, j);
                }
            }
        }
        if !best.is_finite() {
            return NONE;
        }
        let rho = match power {
            false => best,
            true => corr.iter().map(|c| at(c, pi, pj).norm()).sum::<f64>(),
        };
        let parab = |l: f64, c0: f64, r: f64| {
            let den = 2.0 * l - 4.0 * c0 + 2.0 * r;
            if den < 0.0 {
                ((l - r) / den).clamp(-0.5, 0.5)
            } else {
                0.0
            }
        };
        let ti = pi as f64 + parab(objective(pi - 1, pj), best, objective(pi + 1, pj));
        let tj = pj as f64 + parab(objective(pi, pj - 1), best, objective(pi, pj + 1));
        let (ti, tj) = match self.subpixel {
            Subpixel::Parabolic => (ti, tj),
            Subpixel::Fourier => {
                let mut col = vec![C64::new(0.0, 0.0); m];
                for c in &mut corr {
                    self.fwd.run(c, &mut col);
                }
                fourier_peak(&corr, power, m, n, (ti, tj), (pi as f64, pj as f64)).unwrap_or((ti, tj))
            }
        };
        Estimate { di: oi as f64 + ti, dj: oj as f64 + tj, rho: rho.clamp(0.0, 1.0), ok: true }
    }

    /// Mean-removed, Hann-weighted window of `img` at `at`, scaled by `w` into `out`.
    fn window(&self, img: &[C32], at: (usize, usize), out: &mut [C64], envelope: bool) {
        let (m, n, nx) = (self.m, self.n, self.nx);
        let px = |v: &C32| match envelope {
            true => C64::new(f64::from(v.norm()), 0.0),
            false => C64::new(f64::from(v.re), f64::from(v.im)),
        };
        let mut mean = C64::new(0.0, 0.0);
        for r in 0..m {
            for v in &img[(at.0 + r) * nx + at.1..(at.0 + r) * nx + at.1 + n] {
                mean += px(v);
            }
        }
        mean /= (m * n) as f64;
        for r in 0..m {
            let row = &img[(at.0 + r) * nx + at.1..];
            for c in 0..n {
                out[r * n + c] = (px(&row[c]) - mean) * (self.hi[r] * self.hj[c]);
            }
        }
    }

    /// The normalised circular cross-correlation of the envelope windows at `a` (frame t) and
    /// `b` (frame t + lag), summed over every pair of every look: one real correlation.
    fn envelope_correlation(&self, a: (usize, usize), b: (usize, usize)) -> Option<Vec<C64>> {
        let (m, n, nn) = (self.m, self.n, self.m * self.n);
        let (mut z, mut w2) = (vec![C64::new(0.0, 0.0); nn], vec![C64::new(0.0, 0.0); nn]);
        let mut col = vec![C64::new(0.0, 0.0); m];
        let mut s = vec![C64::new(0.0, 0.0); nn];
        let (mut e1, mut e2) = (0.0, 0.0);
        for look in self.looks {
            for t in 0..look.len() - self.lag {
                // Two real windows in one complex FFT: z = a + i b.
                self.window(&look[t], a, &mut z, true);
                self.window(&look[t + self.lag], b, &mut w2, true);
                for (zv, bv) in z.iter_mut().zip(&w2) {
                    zv.im = bv.re;
                }
                self.fwd.run(&mut z, &mut col);
                for ki in 0..m {
                    let mi = (m - ki) % m;
                    for kj in 0..n {
                        let zk = z[ki * n + kj];
                        let zc = z[mi * n + (n - kj) % n].conj();
                        let fa = (zk + zc) * 0.5;
                        let fb = (zk - zc) * C64::new(0.0, -0.5);
                        s[ki * n + kj] += fb * fa.conj();
                        e1 += fa.norm_sqr();
                        e2 += fb.norm_sqr();
                    }
                }
            }
        }
        if !(e1 > 0.0 && e2 > 0.0) {
            return None;
        }
        // Σ_x a(x) b(x + τ) = ifft(S)/N and Σ a² = Σ|A|²/N: normalised, c(0) ≤ 1.
        self.inv.run(&mut s, &mut col);
        let norm = 1.0 / (e1 * e2).sqrt();
        Some(s.iter().map(|v| C64::new(v.re * norm, 0.0)).collect())
    }

    /// The normalised complex cross-correlations of the I/Q windows, one per look (summed over
    /// the look's pairs: the Doppler phase of a pair is the look's), normalised by the energies
    /// of all looks.
    fn iq_correlations(&self, a: (usize, usize), b: (usize, usize)) -> Option<Vec<Vec<C64>>> {
        let (m, nn) = (self.m, self.m * self.n);
        let (mut fa, mut fb) = (vec![C64::new(0.0, 0.0); nn], vec![C64::new(0.0, 0.0); nn]);
        let mut col = vec![C64::new(0.0, 0.0); m];
        let (mut e1, mut e2) = (0.0, 0.0);
        let mut out = Vec::with_capacity(self.looks.len());
        for look in self.looks {
            let mut s = vec![C64::new(0.0, 0.0); nn];
            for t in 0..look.len() - self.lag {
                self.window(&look[t], a, &mut fa, false);
                self.window(&look[t + self.lag], b, &mut fb, false);
                self.fwd.run(&mut fa, &mut col);
                self.fwd.run(&mut fb, &mut col);
                for ((sv, x), y) in s.iter_mut().zip(&fa).zip(&fb) {
                    *sv += y * x.conj();
                    e1 += x.norm_sqr();
                    e2 += y.norm_sqr();
                }
            }
            self.inv.run(&mut s, &mut col);
            out.push(s);
        }
        if !(e1 > 0.0 && e2 > 0.0) {
            return None;
        }
        let norm = 1.0 / (e1 * e2).sqrt();
        for s in &mut out {
            for v in s.iter_mut() {
                *v *= norm;
            }
        }
        Some(out)
    }
}

/// Valid values of the 3 × 3 neighbourhood of centre (`a`, `b`), itself excluded.
fn neighbours(t: &Tracked, plane: &[f64], valid: &[bool], a: usize, b: usize) -> Vec<f64> {
    let mut v = Vec::with_capacity(8);
    for u in a.saturating_sub(1)..=(a + 1).min(t.ni - 1) {
        for w in b.saturating_sub(1)..=(b + 1).min(t.nj - 1) {
            let k = u * t.nj + w;
            if (u, w) != (a, b) && valid[k] {
                v.push(plane[k]);
            }
        }
    }
    v
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Normalised median test (Westerweel & Scarano 2005) on both components, ε = 0.1 px, at
/// centres with at least three valid neighbours.
fn median_test(t: &mut Tracked, threshold: f64) {
    let valid = t.valid.clone();
    for a in 0..t.ni {
        for b in 0..t.nj {
            let k = a * t.nj + b;
            if !valid[k] {
                continue;
            }
            let mut bad = false;
            for plane in [&t.di, &t.dj] {
                let mut nb = neighbours(t, plane, &valid, a, b);
                if nb.len() < 3 {
                    continue;
                }
                let med = median(&mut nb);
                let mut res: Vec<f64> = nb.iter().map(|v| (v - med).abs()).collect();
                let rm = median(&mut res);
                bad |= (plane[k] - med).abs() / (rm + 0.1) > threshold;
            }
            if bad {
                t.valid[k] = false;
            }
        }
    }
}

/// Replaces invalid centres by the median of their valid (or already filled) neighbours,
/// growing inward from the valid ones; 0 where the whole field is invalid.
fn fill_invalid(t: &mut Tracked) {
    let mut known = t.valid.clone();
    loop {
        let mut changed = false;
        let before = known.clone();
        for a in 0..t.ni {
            for b in 0..t.nj {
                let k = a * t.nj + b;
                if before[k] {
                    continue;
                }
                let mut ni = neighbours(t, &t.di, &before, a, b);
                if ni.is_empty() {
                    continue;
                }
                let mut nj = neighbours(t, &t.dj, &before, a, b);
                t.di[k] = median(&mut ni);
                t.dj[k] = median(&mut nj);
                known[k] = true;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    for (k, ok) in known.iter().enumerate() {
        if !ok {
            t.di[k] = 0.0;
            t.dj[k] = 0.0;
        }
    }
}

/// One packet's speckle-tracking products.
pub struct SpeckleProducts {
    /// Lateral velocity (m/s, +x), per pixel.
    pub vx: Vec<f32>,
    /// Axial velocity (m/s, +z = deeper).
    pub vz: Vec<f32>,
    /// [`flags`] per pixel (NO_ESTIMATE where the nearest window is invalid).
    pub flags: Vec<u8>,
    /// `√ρ` of the nearest window (0 where invalid): smoothn weights (MUST).
    pub weight: Vec<f32>,
    /// Mean envelope power over the packet's frames and looks.
    pub power: Vec<f32>,
    /// The tracked centres of the last pass.
    pub tracked: Tracked,
    /// Grid of the images.
    pub grid: Grid,
    /// First look's header (fc, c, prf, angles).
    pub header: LookHeader,
    /// Looks and frames per look used.
    pub n_looks: usize,
    /// See `n_looks`.
    pub frames: usize,
    /// Packet index.
    pub packet: u32,
    /// Largest frame counter among the looks.
    pub frame_id: u64,
    /// Time of validity of the last look.
    pub t_valid: f64,
    /// What the clutter filter did (first look; default without one).
    pub clutter: ClutterReport,
}

/// Collects a packet's images per look and tracks the speckle of each finished packet: what the
/// `speckle-tracking` node does, without IPC.
pub struct SpeckleAssembler {
    tracker: SpeckleTracker,
    collector: LookCollector,
}

impl SpeckleAssembler {
    /// Validates `params`.
    pub fn new(params: SpeckleParams) -> Result<Self> {
        Ok(Self { tracker: SpeckleTracker::new(params)?, collector: LookCollector::default() })
    }

    /// Adds one image; returns the finished previous packet if this image starts a new one.
    pub fn push(&mut self, h: &LookHeader, frame: Vec<C32>) -> Result<Option<SpeckleProducts>> {
        match self.collector.push(h, frame)? {
            Some(s) => self.process(s),
            None => Ok(None),
        }
    }

    /// Finishes the current packet (end of stream); None if nothing is pending.
    pub fn finish(&mut self) -> Result<Option<SpeckleProducts>> {
        let s = self.collector.take();
        self.process(s)
    }

    fn process(&mut self, streams: BTreeMap<LookKey, Stream>) -> Result<Option<SpeckleProducts>> {
        let Some(first) = streams.values().next().map(|s| s.header.clone()) else {
            return Ok(None);
        };
        let (nx, nz) = (first.grid.nx, first.grid.nz);
        let n = nx * nz;
        let p = self.tracker.params().clone();
        let mut looks = Vec::with_capacity(streams.len());
        let mut power = vec![0.0f64; n];
        let (mut frame_id, mut t_valid, mut frames_min) = (0, 0.0, usize::MAX);
        let mut clutter = ClutterReport::default();
        for (k, s) in streams.into_values().enumerate() {
            let h = s.header;
            if h.grid != first.grid || s.frames.iter().any(|f| f.len() != n) {
                return Err(BeamformError::ConfigMismatch {
                    what: format!("packet {}: the looks do not share one grid", h.packet),
                });
            }
            if h.prf.to_bits() != first.prf.to_bits() {
                return Err(BeamformError::ConfigMismatch {
                    what: format!(
                        "packet {}: the looks have different PRFs ({} and {} Hz)",
                        h.packet, first.prf, h.prf
                    ),
                });
            }
            let mut frames = s.frames;
            if let Some(c) = &p.clutter {
                let mut refs: Vec<&mut [C32]> = frames.iter_mut().map(|f| f.as_mut_slice()).collect();
                let r = c.apply_frames(&mut refs)?;
                if k == 0 {
                    clutter = r;
                }
            }
            for f in &frames {
                for (acc, v) in power.iter_mut().zip(f) {
                    *acc += f64::from(v.norm_sqr());
                }
            }
            frames_min = frames_min.min(frames.len());
            frame_id = frame_id.max(h.frame_id);
            t_valid = h.t_valid;
            looks.push(frames);
        }
        let total: usize = looks.iter().map(Vec::len).sum();
        let tracked = self.tracker.track(&looks, nz, nx)?;
        let (di, dj, rho, valid) = tracked.to_pixels(nz, nx);
        let scale = first.prf / p.lag as f64;
        let g = &first.grid;
        Ok(Some(SpeckleProducts {
            vx: dj.iter().map(|d| (d * g.dx * scale) as f32).collect(),
            vz: di.iter().map(|d| (d * g.dz * scale) as f32).collect(),
            flags: valid.iter().map(|&ok| if ok { 0 } else { flags::NO_ESTIMATE }).collect(),
            weight: rho.iter().zip(&valid).map(|(r, &ok)| if ok { r.sqrt() as f32 } else { 0.0 }).collect(),
            power: power.iter().map(|v| (v / total as f64) as f32).collect(),
            tracked,
            grid: first.grid.clone(),
            n_looks: looks.len(),
            frames: frames_min,
            packet: first.packet,
            frame_id,
            t_valid,
            clutter,
            header: first,
        }))
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests;
