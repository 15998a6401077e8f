//! Delay-and-sum of I/Q onto a rectangular grid, with receive sub-aperture steering
//! (MUST/PyMUST `dasmtx`, pymust-notes §7; Shahriari & Garcia 2018 §2.4; Madiena et al. 2018).
//!
//! For pixel p = (x, z) and element e at (x_e, z_e) (z_e = 0 on a linear array):
//!
//! * round-trip delay `τ = (d_TX(p) + |p − e|)/c`, fractional sample `i = (τ − t0)·fs`;
//! * receive aperture (`fnumber` F > 0, receive angle θ): element e is used iff
//!   `|x − x_e − z·tan θ| ≤ z/(2F·cos θ)` — the aperture is centred where the line through p at
//!   angle θ from the z axis meets the array (θ > 0 centres it at smaller x: the receive beam runs
//!   from the aperture down towards +x), and its width keeps the f-number F along that line. F = 0 (MUST's default) uses every element (θ must then be 0).
//!   Rectangular weights, plain sum (MUST: no normalisation by the number of elements);
//! * convex array (`radius` R finite, [`crate::convex`]): elements on an arc whose chord lies on
//!   z = 0 (MUST `getElementPositions`), element normals at θ_e from the z axis; element e is used
//!   iff `|φ_e − θ_e − θ| ≤ atan(1/(2F))`, φ_e = atan2(x − x_e, z − z_e) the direction from e
//!   to p (PyMUST: `asin(dx/d)`, θ = 0); Hann weights by `u = −(φ_e − θ_e − θ)/(2·atan(1/(2F)))`;
//!   pixels behind the face (inside the arc's circle) are an error;
//! * linear interpolation on samples `⌊i⌋, ⌊i⌋+1` (valid for `0 ≤ i ≤ n_samples − 2`), or nearest;
//! * I/Q phase rotation: each weight is multiplied by `exp(i·2π fc·τ)` (the demodulated signal is
//!   re-modulated at its delay), so the beamformed value is the analytic RF signal at p.
//!
//! Transmit distance `d_TX` (a [`TxWave`]):
//! * plane wave of tilt θt (delays `x_e sin θt/c − min`): MUST's rule `min_i (c·delay_i + |p − e_i|)`
//!   over the transmitting aperture, evaluated in closed form (continuous minimum): `x sin θt +
//!   z cos θt − min_e x_e sin θt` inside the insonified region, the distance through the nearest
//!   array end outside it. PyMUST takes the minimum over 4·N discrete points instead
//!   (nRMS ≈ 3e-4 difference on an image); [`TxWave::Delays`] reproduces that exactly.
//! * diverging wave from (x0, z0 < 0): the same rule in closed form (`|p − s| − min_e |e − s|`
//!   where the ray from the source through p crosses the aperture);
//! * focused wave at (x0, z0 > 0): virtual-source model `max_e|e − f| ∓ |p − f|` (− above the
//!   focus, + below it), the physical arrival time (MUST's minimum rule is wrong below the focus);
//! * arbitrary delays ([`TxWave::Delays`], NaN = element off): PyMUST's rule literally, minimum
//!   over 4·n_tx points along the transmitting elements, positions linear in the element index
//!   and delays by PyMUST's not-a-knot cubic spline (linear below 4 elements).
//! * convex array: a focused wave by the virtual-source model above, every other wave by its
//!   MUST delays ([`TxWave::delays`]) and PyMUST's rule, the minimum over 4·n_tx points whose
//!   positions (x, z) and delays follow the cubic spline through the transmitting elements.
//!
//! The set-up (delays, aperture, weights, phase factors) is done once into a [`DasPlan`]: a
//! per-pixel list of taps (sample index, two complex weights) in CSR form, applied to each frame
//! in O(taps). Pixels are processed in parallel (rayon over grid rows); every pixel's sum is
//! computed by the same sequential code, so results are bit-identical for any thread count.
//!
//! The plan also records, per pixel, the mean over the active elements of the gradient of the
//! round-trip delay `∇τ = (∇d_TX + (p − e)/|p − e|)/c` (s/m). A displacement δ of the scatterers
//! changes the slow-time phase by `2π f ∇τ·δ`, so the Doppler velocity (positive toward the
//! probe) is `v_D = −(c/2) ∇τ·v`: [`DasPlan::projection`] gives this per-pixel projection vector
//! (`−(sin θt + sin θr, cos θt + cos θr)/2` for an ideal plane wave and narrow aperture) for
//! vector Doppler and for the Loupas estimator.

use rayon::prelude::*;

pub mod convex;
mod params;
mod transmit;

use crate::error::{check_len, invalid, BeamformError, Result};
use crate::grid::Grid;
use crate::C32;
use convex::Convex;
pub use params::{Apodization, DasParams, Interpolation, TxWave};
pub(crate) use transmit::TxModel;

/// `(sin φ, cos φ)` for |φ| < 2^51, to ~1e-9 absolute (the DAS phase factors are stored in
/// f32): φ reduced to r ∈ [−π, π] by the nearest multiple of 2π (round-to-nearest through the
/// 1.5·2^52 constant, no rounding instruction needed), then Taylor series to r^19 (sin) and r^20
/// (cos), whose first omitted terms are below π^21/21! ≈ 5e-10. Branch-free, so a loop over it
/// vectorises.
#[inline(always)]
fn sincos_fast(phi: f64) -> (f64, f64) {
    const MAGIC: f64 = 6_755_399_441_055_744.0;
    const TAU: f64 = 2.0 * std::f64::consts::PI;
    const INV_TAU: f64 = 1.0 / TAU;
    // 1/n! with alternating signs
    const S: [f64; 9] = [
        -1.0 / 6.0,
        1.0 / 120.0,
        -1.0 / 5040.0,
        1.0 / 362_880.0,
        -1.0 / 39_916_800.0,
        1.0 / 6_227_020_800.0,
        -1.0 / 1_307_674_368_000.0,
        1.0 / 355_687_428_096_000.0,
        -1.0 / 121_645_100_408_832_000.0,
    ];
    const C: [f64; 10] = [
        -1.0 / 2.0,
        1.0 / 24.0,
        -1.0 / 720.0,
        1.0 / 40_320.0,
        -1.0 / 3_628_800.0,
        1.0 / 479_001_600.0,
        -1.0 / 87_178_291_200.0,
        1.0 / 20_922_789_888_000.0,
        -1.0 / 6_402_373_705_728_000.0,
        1.0 / 2_432_902_008_176_640_000.0,
    ];
    let k = (phi * INV_TAU + MAGIC) - MAGIC;
    let r = phi - k * TAU;
    let r2 = r * r;
    let mut ps = S[8];
    for c in S[..8].iter().rev() {
        ps = c + r2 * ps;
    }
    let mut pc = C[9];
    for c in C[..9].iter().rev() {
        pc = c + r2 * pc;
    }
    (r * (1.0 + r2 * ps), 1.0 + r2 * pc)
}

/// A precomputed delay-and-sum operator for one configuration (probe, transmit, receive
/// angle, f-number, grid, trace length): a sparse matrix from the element-major I/Q frame
/// (`n_elements × n_samples`) to the grid (`nz × nx`, row-major), plus per-pixel geometry.
#[derive(Clone, Debug)]
pub struct DasPlan {
    params: DasParams,
    tx: TxWave,
    grid: Grid,
    n_samples: usize,
    /// CSR row pointers, one row per pixel.
    offsets: Vec<u32>,
    /// First I/Q index of each tap (`e·n_samples + ⌊i⌋`).
    index: Vec<u32>,
    /// Weight of sample `index`, phase factor included.
    w0: Vec<C32>,
    /// Weight of sample `index + 1`.
    w1: Vec<C32>,
    /// Mean round-trip delay gradient (s/m) over the active elements, per pixel.
    gradient: Vec<[f32; 2]>,
}

/// One grid row of a plan under construction.
struct Row {
    counts: Vec<u32>,
    index: Vec<u32>,
    w0: Vec<C32>,
    w1: Vec<C32>,
    grad: Vec<[f32; 2]>,
}

/// One pixel's candidate taps, structure of arrays (reused across pixels): I/Q index, weights,
/// whether the sample lies on the trace, and (valid, weight, weighted x and z gradient terms).
struct Taps {
    geo: Vec<[f64; 6]>,
    index: Vec<u32>,
    w0: Vec<C32>,
    w1: Vec<C32>,
    valid: Vec<bool>,
    sums: Vec<[f64; 4]>,
}

impl Taps {
    fn with_capacity(n: usize) -> Self {
        let mut t = Taps {
            geo: Vec::new(),
            index: Vec::new(),
            w0: Vec::new(),
            w1: Vec::new(),
            valid: Vec::new(),
            sums: Vec::new(),
        };
        t.resize(n);
        t
    }

    fn resize(&mut self, n: usize) {
        if self.index.len() < n {
            self.geo.resize(n, [0.0; 6]);
            self.index.resize(n, 0);
            self.w0.resize(n, C32::new(0.0, 0.0));
            self.w1.resize(n, C32::new(0.0, 0.0));
            self.valid.resize(n, false);
            self.sums.resize(n, [0.0; 4]);
        }
    }
}

/// Column sums of `v` in 8 independent lanes (vectorisable), then the lanes and the tail.
#[inline(always)]
fn lane_sums(v: &[[f64; 4]]) -> [f64; 4] {
    const L: usize = 8;
    let mut lanes = [[0.0f64; 4]; L];
    let chunks = v.chunks_exact(L);
    let tail = chunks.remainder();
    for c in chunks {
        for (lane, x) in lanes.iter_mut().zip(c) {
            for (a, b) in lane.iter_mut().zip(x) {
                *a += b;
            }
        }
    }
    let mut out = [0.0f64; 4];
    for x in lanes.iter().chain(tail) {
        for (a, b) in out.iter_mut().zip(x) {
            *a += b;
        }
    }
    out
}

/// What building a row of a [`DasPlan`] needs.
struct RowCtx<'a> {
    model: &'a TxModel,
    p: &'a DasParams,
    xe: &'a [f64],
    /// Element depths, normals and aperture half-angle of a convex array (None: linear).
    convex: Option<&'a Convex>,
    tan_rx: f64,
    cos_rx: f64,
    wc: f64,
    last: f64,
    grid: &'a Grid,
    n_samples: usize,
}

impl RowCtx<'_> {
    /// Walks row `iz` ([`Self::walk_row`]) with the widest vector instructions the CPU has
    /// (the same operations, so the same bits, on every path: Rust does not contract a·b + c
    /// into an FMA).
    fn walk<F: FnMut(usize, PixelTaps<'_>)>(&self, iz: usize, sink: F) {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx512f") {
                // SAFETY: the CPU has AVX-512F (checked above).
                return unsafe { self.walk_avx512(iz, sink) };
            }
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU has AVX2 (checked above).
                return unsafe { self.walk_avx2(iz, sink) };
            }
        }
        self.walk_row(iz, sink)
    }

    /// # Safety
    /// The CPU must support AVX-512F.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn walk_avx512<F: FnMut(usize, PixelTaps<'_>)>(&self, iz: usize, sink: F) {
        self.walk_row(iz, sink)
    }

    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn walk_avx2<F: FnMut(usize, PixelTaps<'_>)>(&self, iz: usize, sink: F) {
        self.walk_row(iz, sink)
    }

    /// Row `iz` of a plan.
    fn build(&self, iz: usize) -> Row {
        let nx = self.grid.nx;
        let mut row = Row {
            counts: Vec::with_capacity(nx),
            index: Vec::new(),
            w0: Vec::new(),
            w1: Vec::new(),
            grad: Vec::with_capacity(nx),
        };
        self.walk(iz, |_, t| {
            row.counts.push(t.index.len() as u32);
            row.index.extend_from_slice(t.index);
            row.w0.extend_from_slice(t.w0);
            row.w1.extend_from_slice(t.w1);
            row.grad.push(t.gradient);
        });
        row
    }

    /// The elements pixel (x, z) uses: all of them without an f-number, else those with
    /// |x − x_e − z·tan θ_RX| ≤ z / cos θ_RX / (2 F#), a contiguous range because the elements are
    /// sorted by x (pitch > 0); found by bisection on the same expression, so the same elements
    /// as testing each one. Convex array: [`convex::aperture`] (the half-width returned is then
    /// the half-angle `atan(1/(2F))`).
    #[inline(always)]
    fn aperture(&self, x: f64, z: f64) -> (usize, usize, f64) {
        let (p, xe) = (self.p, self.xe);
        if p.fnumber <= 0.0 {
            return (0, xe.len(), 0.0);
        }
        if let Some(cv) = self.convex {
            let (lo, hi) = convex::aperture(cv, x, z, p.rx_angle);
            return (lo, hi, cv.alpha);
        }
        let half = z / self.cos_rx / 2.0 / p.fnumber;
        let off = |e: &f64| (x - e) - z * self.tan_rx;
        let lo = xe.partition_point(|e| off(e) > half);
        let hi = lo + xe[lo..].partition_point(|e| off(e) >= -half);
        (lo, hi, half)
    }

    /// Hands `sink` each pixel's taps, left to right. Per pixel: the elements in its aperture
    /// ([`Self::aperture`]); for each, in a branch-free pass that vectorises, the distance,
    /// delay, fractional sample, apodisation, phase factor (polynomial, [`sincos_fast`]) and
    /// receive direction; then the I/Q index and f32 weights; then the sums for the mean delay
    /// gradient; the taps whose sample falls off the trace are dropped last. The transmit
    /// distances of the whole row come first ([`TxModel::eval_row`]). Hann and boxcar weights
    /// are positive inside the aperture, so no element is dropped for its weight.
    #[inline(always)]
    fn walk_row<F: FnMut(usize, PixelTaps<'_>)>(&self, iz: usize, mut sink: F) {
        let (p, grid, xe) = (self.p, self.grid, self.xe);
        let (ne, n_samples) = (xe.len(), self.n_samples);
        let z = grid.z(iz);
        let hann = p.apodization == Apodization::Hann;
        let (inv_c, wc, t0, fs) = (1.0 / p.c, self.wc, p.t0, p.fs);
        let u_step = if ne > 1 { 1.0 / (ne - 1) as f64 } else { 0.0 };
        let nearest = p.interpolation == Interpolation::Nearest;
        let (last, ns_f) = (self.last, n_samples as f64);
        let mut taps = Taps::with_capacity(ne);
        let xq: Vec<f64> = (0..grid.nx).map(|ix| grid.x(ix)).collect();
        let mut tx = Vec::with_capacity(grid.nx);
        self.model.eval_row(&xq, z, &mut tx);
        for (ix, &(dtx, gtx_x, gtx_z)) in tx.iter().enumerate() {
            let x = xq[ix];
            let (lo, hi, half) = self.aperture(x, z);
            let m = hi - lo;
            taps.resize(m);
            let with_f = p.fnumber > 0.0;
            let inv_width = if with_f { 1.0 / (2.0 * half) } else { 0.0 };
            let Taps { geo, index, w0, w1, valid, sums } = &mut taps;
            if let Some(cv) = self.convex {
                // convex array: elements off z = 0, aperture position by angle from the normal
                let rx = p.rx_angle;
                for (k, g) in geo[..m].iter_mut().enumerate() {
                    let e = lo + k;
                    let (dx, dz) = (x - xe[e], z - cv.ze[e]);
                    let d = (dx * dx + dz * dz).sqrt();
                    let tau = (dtx + d) * inv_c;
                    let u = if with_f {
                        -(convex::direction(dx, dz) - cv.the[e] - rx) * inv_width
                    } else if ne > 1 {
                        e as f64 * u_step - 0.5
                    } else {
                        0.0
                    };
                    *g = tap_geometry(tau, u, hann, wc, (t0, fs), (dx, dz, d));
                }
            } else {
                // geometry, apodisation and phase (f64, branch-free)
                for (k, (g, &xk)) in geo[..m].iter_mut().zip(&xe[lo..hi]).enumerate() {
                    let dx = x - xk;
                    let d = (dx * dx + z * z).sqrt();
                    let tau = (dtx + d) * inv_c;
                    let u = if with_f {
                        -(dx - z * self.tan_rx) * inv_width
                    } else if ne > 1 {
                        (lo + k) as f64 * u_step - 0.5
                    } else {
                        0.0
                    };
                    *g = tap_geometry(tau, u, hann, wc, (t0, fs), (dx, z, d));
                }
            }
            // the taps: I/Q index and f32 weights (linear or nearest), on the trace or not
            let it = geo[..m].iter().zip(&mut index[..m]).zip(&mut w0[..m]).zip(&mut w1[..m]).zip(&mut valid[..m]);
            if nearest {
                for (k, ((((g, index), w0), w1), valid)) in it.enumerate() {
                    let [idx, aw, c, s, ..] = *g;
                    let rw = C32::new(c as f32, s as f32) * aw as f32;
                    let ks = idx.round().clamp(0.0, last);
                    let at_end = ks + 1.0 >= ns_f;
                    *index = ((lo + k) * n_samples) as u32 + (if at_end { ks - 1.0 } else { ks }) as u32;
                    *w0 = if at_end { C32::new(0.0, 0.0) } else { rw };
                    *w1 = if at_end { rw } else { C32::new(0.0, 0.0) };
                    *valid = idx >= 0.0 && idx <= last;
                }
            } else {
                for (k, ((((g, index), w0), w1), valid)) in it.enumerate() {
                    let [idx, aw, c, s, ..] = *g;
                    let r = C32::new(c as f32, s as f32);
                    let kf = idx.floor();
                    let f = idx - kf;
                    *index = ((lo + k) * n_samples) as u32 + kf.clamp(0.0, last) as u32;
                    *w0 = r * ((1.0 - f) * aw) as f32;
                    *w1 = r * (f * aw) as f32;
                    *valid = idx >= 0.0 && idx <= last;
                }
            }
            // (taps, weight, weighted x and z gradient terms) over the taps on the trace
            for ((g, &ok), sum) in geo[..m].iter().zip(&valid[..m]).zip(&mut sums[..m]) {
                let [_, aw, _, _, ux, uz] = *g;
                let a = if ok { aw } else { 0.0 };
                *sum = [if ok { 1.0 } else { 0.0 }, a, a * (gtx_x + ux), a * (gtx_z + uz)];
            }
            let [count, gw, gx, gz] = lane_sums(&sums[..m]);
            let n = count as usize;
            if n < m {
                // keep the taps on the trace, in element order
                let mut j = 0;
                for k in 0..m {
                    if valid[k] {
                        index[j] = index[k];
                        w0[j] = w0[k];
                        w1[j] = w1[k];
                        j += 1;
                    }
                }
            }
            let gradient = if count > 0.0 && gw > 0.0 {
                let s = 1.0 / (gw * p.c);
                [(gx * s) as f32, (gz * s) as f32]
            } else {
                [0.0, 0.0]
            };
            sink(ix, PixelTaps { index: &index[..n], w0: &w0[..n], w1: &w1[..n], gradient });
        }
    }
}

/// One tap's geometry `[fractional sample, apodisation weight, cos, sin of the phase, receive
/// direction x, z]` from its delay `tau`, its position `u` across the aperture, the Hann switch,
/// ω_c, (t0, fs) and the element → pixel vector `(dx, dz)` of length `d` (branch-free; the same
/// operations for linear and convex arrays).
#[inline(always)]
fn tap_geometry(tau: f64, u: f64, hann: bool, wc: f64, (t0, fs): (f64, f64), (dx, dz, d): (f64, f64, f64)) -> [f64; 6] {
    let aw = if hann {
        let c = sincos_fast(std::f64::consts::PI * u.clamp(-0.5, 0.5)).1;
        c * c
    } else {
        1.0
    };
    let (s, c) = sincos_fast(wc * tau);
    let inv_d = if d > 0.0 { 1.0 / d } else { 0.0 };
    [(tau - t0) * fs, aw, c, s, dx * inv_d, dz * inv_d]
}

/// One pixel's taps as [`RowCtx::walk`] hands them over.
struct PixelTaps<'a> {
    index: &'a [u32],
    w0: &'a [C32],
    w1: &'a [C32],
    gradient: [f32; 2],
}

/// `Σ w0·iq[j] + w1·iq[j + 1]` over the taps, in order (the one sum of a plan's pixel and of
/// [`das_frames`]).
#[inline(always)]
fn tap_sum(index: &[u32], w0: &[C32], w1: &[C32], iq: &[C32]) -> C32 {
    let mut acc = C32::new(0.0, 0.0);
    for ((j, w0), w1) in index.iter().zip(w0).zip(w1) {
        let j = *j as usize;
        if let [s0, s1] = iq[j..j + 2] {
            acc += w0 * s0 + w1 * s1;
        }
    }
    acc
}

/// The row context shared by [`DasPlan::new`] and [`das_frames`], after checking the inputs.
fn with_ctx<T>(
    params: &DasParams,
    tx: &TxWave,
    grid: &Grid,
    n_samples: usize,
    f: impl FnOnce(&RowCtx<'_>) -> Result<T>,
) -> Result<T> {
    params.validate()?;
    tx.validate(params.n_elements)?;
    grid.validate()?;
    if n_samples < 2 || n_samples.saturating_mul(params.n_elements) > u32::MAX as usize - 2 {
        return Err(BeamformError::BadDimension {
            field: "iq.n_samples",
            got: n_samples,
            allowed: ">= 2 and n_samples·n_elements < 2^32",
        });
    }
    let p = params;
    let convex = Convex::of(p);
    if let Some(cv) = &convex {
        cv.check_grid(grid)?;
    }
    let model = TxModel::new(tx, params);
    let xe: Vec<f64> = match &convex {
        Some(cv) => cv.xe.clone(),
        None => (0..p.n_elements).map(|e| p.element_x(e)).collect(),
    };
    let (tan_rx, cos_rx) = (p.rx_angle.tan(), p.rx_angle.cos());
    let wc = 2.0 * std::f64::consts::PI * p.fc;
    let last = match p.interpolation {
        Interpolation::Linear => (n_samples - 2) as f64,
        Interpolation::Nearest => (n_samples - 1) as f64,
    };
    let convex = convex.as_ref();
    f(&RowCtx { model: &model, p, xe: &xe, convex, tan_rx, cos_rx, wc, last, grid, n_samples })
}

/// The images of `n_frames` element-major I/Q frames (`frames`: `n_frames × n_elements ×
/// n_samples`) without storing a plan: each pixel's taps are built and applied to every frame
/// at once — the same taps and the same sums as [`DasPlan::new`] + [`DasPlan::apply`], so the
/// same bits, without writing and reading the plan's tens of megabytes (the faster way when the
/// taps are used for a few frames only). Returns the images (`n_frames × nz × nx`) and the
/// number of taps. Errors: as [`DasPlan::new`], `frames` not `n_frames` frames.
pub fn das_frames(
    params: &DasParams,
    tx: &TxWave,
    grid: &Grid,
    n_samples: usize,
    frames: &[C32],
    n_frames: usize,
) -> Result<(Vec<C32>, usize)> {
    let frame = params.n_elements.saturating_mul(n_samples);
    check_len("iq", frames.len(), frame.saturating_mul(n_frames))?;
    with_ctx(params, tx, grid, n_samples, |ctx| {
        let (nx, npx) = (grid.nx, grid.n_pixels());
        let rows: Vec<(Vec<C32>, usize)> = (0..grid.nz)
            .into_par_iter()
            .map(|iz| {
                let mut vals = vec![C32::new(0.0, 0.0); n_frames * nx];
                let mut taps = 0;
                ctx.walk(iz, |ix, t| {
                    taps += t.index.len();
                    for (f, iq) in frames.chunks_exact(frame.max(1)).enumerate() {
                        vals[f * nx + ix] = tap_sum(t.index, t.w0, t.w1, iq);
                    }
                });
                (vals, taps)
            })
            .collect();
        let mut out = vec![C32::new(0.0, 0.0); n_frames * npx];
        let mut taps = 0;
        for (iz, (vals, t)) in rows.iter().enumerate() {
            taps += t;
            for f in 0..n_frames {
                out[f * npx + iz * nx..][..nx].copy_from_slice(&vals[f * nx..][..nx]);
            }
        }
        Ok((out, taps))
    })
}

impl DasPlan {
    /// Builds the plan. Errors: invalid parameters, wave, grid, or `n_samples < 2`.
    pub fn new(params: &DasParams, tx: &TxWave, grid: &Grid, n_samples: usize) -> Result<Self> {
        let rows: Vec<Row> = with_ctx(params, tx, grid, n_samples, |ctx| {
            Ok((0..grid.nz).into_par_iter().map(|iz| ctx.build(iz)).collect())
        })?;
        let p = params;
        let nnz: usize = rows.iter().map(|r| r.index.len()).sum();
        if nnz > u32::MAX as usize {
            return Err(invalid("grid", nnz, "fewer than 2^32 taps in total (use a smaller grid)"));
        }
        let mut plan = DasPlan {
            params: p.clone(),
            tx: tx.clone(),
            grid: grid.clone(),
            n_samples,
            offsets: Vec::with_capacity(grid.n_pixels() + 1),
            index: Vec::with_capacity(nnz),
            w0: Vec::with_capacity(nnz),
            w1: Vec::with_capacity(nnz),
            gradient: Vec::with_capacity(grid.n_pixels()),
        };
        plan.offsets.push(0);
        let mut acc = 0u32;
        for r in rows {
            for c in r.counts {
                acc += c;
                plan.offsets.push(acc);
            }
            plan.index.extend_from_slice(&r.index);
            plan.w0.extend_from_slice(&r.w0);
            plan.w1.extend_from_slice(&r.w1);
            plan.gradient.extend_from_slice(&r.grad);
        }
        Ok(plan)
    }

    /// The grid.
    pub fn grid(&self) -> &Grid {
        &self.grid
    }

    /// The parameters the plan was built with.
    pub fn params(&self) -> &DasParams {
        &self.params
    }

    /// The transmit wave.
    pub fn tx(&self) -> &TxWave {
        &self.tx
    }

    /// Samples per element expected in the I/Q frames.
    pub fn n_samples(&self) -> usize {
        self.n_samples
    }

    /// Number of (pixel, element) taps.
    pub fn n_taps(&self) -> usize {
        self.index.len()
    }

    /// The plan as a sparse matrix in CSR form, one row per pixel (`iz·nx + ix`): row `p`'s
    /// taps are `offsets[p] .. offsets[p + 1]`; tap `t` weighs I/Q sample `index[t]` (element
    /// `index[t] / n_samples`, sample `index[t] % n_samples`) by `w0[t]` and the next sample by
    /// `w1[t]` (zero for nearest-sample interpolation). MUST's `dasmtx` matrix, with columns in
    /// the same order (sample + element · n_samples).
    pub fn taps(&self) -> (&[u32], &[u32], &[C32], &[C32]) {
        (&self.offsets, &self.index, &self.w0, &self.w1)
    }

    /// Elements summed at pixel `p` (`iz·nx + ix`); 0 if `p` is out of range.
    pub fn active_elements(&self, p: usize) -> usize {
        match (self.offsets.get(p), self.offsets.get(p + 1)) {
            (Some(a), Some(b)) => (b - a) as usize,
            _ => 0,
        }
    }

    /// Mean gradient `(∂τ/∂x, ∂τ/∂z)` (s/m) of the round-trip delay over the active elements,
    /// per pixel (0 where no element is active).
    pub fn delay_gradient(&self) -> &[[f32; 2]] {
        &self.gradient
    }

    /// Doppler projection vector per pixel: `a = −(c/2)·∇τ`, so that the Doppler velocity
    /// (positive toward the probe) of a uniform motion v is `v_D = a·v`. For an ideal plane wave
    /// of tilt θt and receive angle θr: `a = −(sin θt + sin θr, cos θt + cos θr)/2`.
    pub fn projection(&self) -> Vec<[f32; 2]> {
        let h = (self.params.c / 2.0) as f32;
        self.gradient.iter().map(|g| [-h * g[0], -h * g[1]]).collect()
    }

    /// Beamforms one element-major I/Q frame (`iq[e·n_samples + k]`) into `out` (`nz·nx`,
    /// row-major). Pixels without active elements get 0.
    pub fn apply(&self, iq: &[C32], out: &mut [C32]) -> Result<()> {
        check_len("iq", iq.len(), self.params.n_elements * self.n_samples)?;
        check_len("das output", out.len(), self.grid.n_pixels())?;
        let nx = self.grid.nx;
        out.par_chunks_mut(nx).enumerate().for_each(|(iz, row)| {
            for (ix, o) in row.iter_mut().enumerate() {
                let pix = iz * nx + ix;
                *o = self.pixel(iq, pix);
            }
        });
        Ok(())
    }

    #[inline]
    fn pixel(&self, iq: &[C32], pix: usize) -> C32 {
        let (a, b) = (self.offsets[pix] as usize, self.offsets[pix + 1] as usize);
        tap_sum(&self.index[a..b], &self.w0[a..b], &self.w1[a..b], iq)
    }

    /// [`DasPlan::apply`] into a new vector.
    pub fn apply_to_vec(&self, iq: &[C32]) -> Result<Vec<C32>> {
        let mut out = vec![C32::new(0.0, 0.0); self.grid.n_pixels()];
        self.apply(iq, &mut out)?;
        Ok(out)
    }
}

/// Coherent compounding: the sum of the images of several transmits (one I/Q frame each),
/// computed per pixel in plan order (deterministic).
#[derive(Clone, Debug)]
pub struct CompoundPlan {
    plans: Vec<DasPlan>,
}

impl CompoundPlan {
    /// Plans must share the grid. Errors: no plan, different grids.
    pub fn new(plans: Vec<DasPlan>) -> Result<Self> {
        let first = plans.first().ok_or_else(|| invalid("compound.plans", 0, "at least one plan"))?;
        if let Some(p) = plans.iter().find(|p| p.grid != first.grid) {
            return Err(BeamformError::ConfigMismatch {
                what: format!("compound plans on different grids: {:?} vs {:?}", p.grid, first.grid),
            });
        }
        Ok(Self { plans })
    }

    /// The plans, in transmit order.
    pub fn plans(&self) -> &[DasPlan] {
        &self.plans
    }

    /// Sums the beamformed frames: `frames[i]` is the I/Q frame of transmit `i`.
    pub fn apply(&self, frames: &[&[C32]], out: &mut [C32]) -> Result<()> {
        check_len("compound frames", frames.len(), self.plans.len())?;
        for (p, f) in self.plans.iter().zip(frames) {
            check_len("iq", f.len(), p.params.n_elements * p.n_samples)?;
        }
        let grid = &self.plans[0].grid;
        check_len("das output", out.len(), grid.n_pixels())?;
        let nx = grid.nx;
        out.par_chunks_mut(nx).enumerate().for_each(|(iz, row)| {
            for (ix, o) in row.iter_mut().enumerate() {
                let pix = iz * nx + ix;
                let mut acc = C32::new(0.0, 0.0);
                for (p, f) in self.plans.iter().zip(frames) {
                    acc += p.pixel(f, pix);
                }
                *o = acc;
            }
        });
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The polynomial phase factors against libm over the phases DAS meets (up to ~2π·15 MHz ·
    /// 200 µs ≈ 2e4 rad) and beyond: within 2e-9 (the weights are stored in f32, eps 6e-8).
    #[test]
    fn sincos_fast_matches_libm() {
        let mut worst = 0.0f64;
        for i in 0..200_000 {
            let phi = (i as f64 * 0.7791) * if i % 2 == 0 { 1.0 } else { -0.013 } + (i as f64).sqrt();
            let (s, c) = sincos_fast(phi);
            worst = worst.max((s - phi.sin()).abs()).max((c - phi.cos()).abs());
        }
        assert!(worst < 2e-9, "worst error {worst:e}");
    }

    /// The plan-free images equal the plan's, bit for bit, for several frames, both
    /// interpolations, with and without f-number, and traces short enough that some taps fall
    /// off them (the compaction path).
    #[test]
    fn das_frames_equals_the_plan() {
        let (ne, ns, nf) = (24usize, 300usize, 3usize);
        let iq: Vec<C32> =
            (0..nf * ne * ns).map(|i| C32::new(((i * 37 % 101) as f32).sin(), ((i * 11 % 53) as f32).cos())).collect();
        let grid = Grid { x0: -4e-3, z0: 2e-3, dx: 0.1e-3, dz: 0.15e-3, nx: 81, nz: 90 };
        let delays: Vec<f64> = (0..ne).map(|e| 2e-7 * (e as f64 / 5.0).sin().abs()).collect();
        for (interpolation, fnumber, tx) in [
            (Interpolation::Linear, 1.5, TxWave::Delays { delays: delays.clone() }),
            (Interpolation::Nearest, 0.0, TxWave::PlaneWave { tilt: 0.1 }),
            (Interpolation::Linear, 0.0, TxWave::Delays { delays: delays.clone() }),
        ] {
            let p = DasParams {
                fc: 5e6,
                c: 1540.0,
                fs: 20e6,
                t0: 1e-6,
                pitch: 0.3e-3,
                n_elements: ne,
                radius: None,
                fnumber,
                rx_angle: if fnumber > 0.0 { 0.05 } else { 0.0 },
                interpolation,
                apodization: Apodization::Hann,
            };
            let plan = DasPlan::new(&p, &tx, &grid, ns).unwrap();
            let (got, taps) = das_frames(&p, &tx, &grid, ns, &iq, nf).unwrap();
            assert_eq!(taps, plan.n_taps());
            assert!(taps < grid.n_pixels() * ne, "some taps must fall off the traces");
            for f in 0..nf {
                let want = plan.apply_to_vec(&iq[f * ne * ns..(f + 1) * ne * ns]).unwrap();
                let g = &got[f * grid.n_pixels()..(f + 1) * grid.n_pixels()];
                assert!(g
                    .iter()
                    .zip(&want)
                    .all(|(a, b)| a.re.to_bits() == b.re.to_bits() && a.im.to_bits() == b.im.to_bits()));
            }
        }
        let p = DasParams {
            fc: 5e6,
            c: 1540.0,
            fs: 20e6,
            t0: 0.0,
            pitch: 0.3e-3,
            n_elements: ne,
            radius: None,
            fnumber: 1.0,
            rx_angle: 0.0,
            interpolation: Interpolation::Linear,
            apodization: Apodization::Hann,
        };
        assert!(das_frames(&p, &TxWave::PlaneWave { tilt: 0.0 }, &grid, ns, &iq[1..], nf).is_err());
    }
}
