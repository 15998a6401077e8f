//! Colour Doppler estimators on packets of beamformed I/Q (Shahriari & Garcia 2018 eq. 19;
//! MUST/PyMUST `iq2doppler`, pymust-notes §8; Loupas, McDicken & Allan 1995, IEEE UFFC 42:672).
//!
//! With `x_n` the I/Q of a pixel in frame n of an N-frame packet and lag L:
//!
//! * `R1 = Σ_{n=0}^{N−1−L} x_n · conj(x_{n+L})` (MUST's definition: the conjugate is on the
//!   *later* frame), `R0 = Σ_{n=0}^{N−1} |x_n|²`;
//! * optional spatial window of `window = [M_z, M_x]` pixels (MUST `M`): `R1` and `R0` are
//!   convolved with `w(M_z) ⊗ w(M_x)`, `w` = symmetric Hamming (MUST) or boxcar, 'same' size,
//!   symmetric (mirror) boundary as `scipy.signal.convolve2d(…, 'same', boundary='symmetric')`;
//! * **autocorrelation** (eq. 19): `v = −V_N·arg(R1)/π`, `V_N = c·PRF/(4 fc L)` (Nyquist
//!   velocity). **Sign: positive = toward the probe** (the echo path shortens). Proof: an echo
//!   delayed by τ_n demodulates to `exp(−i 2π f τ_n)`; toward the probe τ_{n+1} < τ_n, so
//!   `arg(x_n conj(x_{n+1})) = 2π f (τ_{n+1} − τ_n) < 0` and v > 0;
//! * **Loupas 2-D autocorrelator**: the mean RF frequency f̄ of the echoes is estimated from the
//!   axial (depth) lag-1 correlation `R_ax = Σ_n Σ x_n(z) conj(x_n(z + dz))` (same window). The
//!   beamformed I/Q of a DAS plan is the analytic RF signal at each pixel, whose phase advances by
//!   `2π f̄ Δτ` per row, `Δτ = (∂τ/∂z)·dz` from the plan (≈ 2 dz/c); removing the known carrier
//!   term gives `f̄ = fc − arg(R_ax·exp(i 2π fc Δτ))/(2π Δτ)` (unaliased while |f̄ − fc| Δτ < ½),
//!   then `v = −c·PRF·arg(R1)/(4π f̄ L)`. This removes the bias of assuming `fc` (the paper
//!   probe's pulse-echo spectrum is centred at 4.97 MHz, not 5, ⇒ −0.6 % with the plain
//!   estimator). f̄ is clamped to [fc/2, 3fc/2];
//! * power = R0; variance (MUST) `2 (V_N/π)² (1 − |R1|/R0)` (m²/s²; note R1 sums N − L pairs);
//!   the normalised variance of the wire format is `1 − |R1|/R0`.
//!
//! Flags per pixel ([`flags`]): **no estimate** when R0 = 0, R1 = 0 or either is not finite
//! (velocity and variance are then 0, never NaN/inf); **aliasing suspected** when
//! `|arg R1| > alias_fraction·π` (default 0.9, i.e. |v| > 0.9 V_N): a lag-1 estimator wraps
//! silently beyond ±V_N, so values this close to the limit are flagged rather than trusted.
//!
//! Arithmetic is f64 (per-pixel sums in frame order, windows in fixed order); pixels run in
//! parallel over rows and the results do not depend on the thread count.

use num_complex::Complex;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use sonoflow_beamform::error::{check_len, invalid, positive, BeamformError, Result};
use sonoflow_beamform::DasPlan;
use sonoflow_beamform::C32;

use crate::lag_sums::{lag_sums_frames_row, lag_sums_row};

thread_local! {
    /// Scratch of [`lag_sums_frames_row`] per worker thread (12 × 2nx f64; reused across packets).
    static ROW_ACC: std::cell::RefCell<Vec<f64>> = const { std::cell::RefCell::new(Vec::new()) };
}

type C64 = Complex<f64>;

/// Per-pixel flag bits (same values as the wire format's `FLAGS` plane).
pub mod flags {
    /// No estimate: zero or non-finite power/autocorrelation. Velocity is 0.
    pub const NO_ESTIMATE: u8 = 1;
    /// Aliasing suspected: |arg R1| above `alias_fraction·π`.
    pub const ALIASING: u8 = 2;
}

/// Spatial averaging window shape.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WindowShape {
    /// Symmetric Hamming (MUST `iq2doppler`).
    #[default]
    Hamming,
    /// Uniform weights.
    Boxcar,
}

/// Velocity estimator.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Estimator {
    /// Lag-L slow-time autocorrelation with the nominal fc (eq. 19, MUST `iq2doppler`).
    #[default]
    Autocorrelation,
    /// Loupas 2-D autocorrelator (mean RF frequency estimated along depth).
    Loupas,
}

fn default_c() -> f64 {
    1540.0
}
fn default_lag() -> usize {
    1
}
fn default_window() -> [usize; 2] {
    [1, 1]
}
fn default_alias() -> f64 {
    0.9
}

/// Doppler parameters (MUST names, SI units).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DopplerParams {
    /// Centre frequency (Hz), > 0. MUST `fc`.
    pub fc: f64,
    /// Speed of sound (m/s), > 0, default 1540. MUST `c`.
    #[serde(default = "default_c")]
    pub c: f64,
    /// Pulse repetition frequency (Hz), > 0 (slow-time sampling). MUST `PRF`.
    #[serde(alias = "PRF")]
    pub prf: f64,
    /// Slow-time lag in [1, 64], default 1. The packet needs more than `lag` frames.
    #[serde(default = "default_lag")]
    pub lag: usize,
    /// Spatial window `[rows (z), columns (x)]`, each in [1, 64], default [1, 1] (none). MUST `M`.
    #[serde(default = "default_window")]
    pub window: [usize; 2],
    /// Window shape, default Hamming (MUST).
    #[serde(default)]
    pub window_shape: WindowShape,
    /// Estimator, default autocorrelation.
    #[serde(default)]
    pub estimator: Estimator,
    /// Aliasing flag threshold as a fraction of the Nyquist velocity, in ]0, 1], default 0.9.
    #[serde(default = "default_alias")]
    pub alias_fraction: f64,
}

impl DopplerParams {
    /// Autocorrelation estimator with MUST's defaults (lag 1, no window).
    pub fn new(fc: f64, c: f64, prf: f64) -> Self {
        Self {
            fc,
            c,
            prf,
            lag: 1,
            window: [1, 1],
            window_shape: WindowShape::Hamming,
            estimator: Estimator::Autocorrelation,
            alias_fraction: 0.9,
        }
    }

    /// Nyquist velocity `c·PRF/(4 fc lag)` (m/s).
    pub fn nyquist_velocity(&self) -> f64 {
        self.c * self.prf / (4.0 * self.fc * self.lag as f64)
    }

    /// Checks every field; the error names the field and the allowed range.
    pub fn validate(&self) -> Result<()> {
        positive("doppler.fc", self.fc)?;
        positive("doppler.c", self.c)?;
        positive("doppler.prf", self.prf)?;
        if !(1..=64).contains(&self.lag) {
            return Err(invalid("doppler.lag", self.lag, "in [1, 64]"));
        }
        for m in self.window {
            if !(1..=64).contains(&m) {
                return Err(invalid(
                    "doppler.window",
                    format!("{:?}", self.window),
                    "two sizes in [1, 64] (rows, columns)",
                ));
            }
        }
        if !(self.alias_fraction > 0.0 && self.alias_fraction <= 1.0) {
            return Err(invalid("doppler.alias_fraction", self.alias_fraction, "in ]0, 1]"));
        }
        Ok(())
    }
}

/// A packet of beamformed frames of one grid.
#[derive(Clone, Copy, Debug)]
pub enum Packet<'a> {
    /// One slice per frame (slow time), each `nz·nx` row-major: what a node accumulates.
    Frames(&'a [&'a [C32]]),
    /// MUST's `(nz, nx, n_frames)` C-order array: `data[(iz·nx + ix)·n_frames + n]`.
    PixelMajor {
        /// The samples.
        data: &'a [C32],
        /// Frames per pixel.
        n_frames: usize,
    },
}

impl Packet<'_> {
    fn n_frames(&self) -> usize {
        match self {
            Packet::Frames(f) => f.len(),
            Packet::PixelMajor { n_frames, .. } => *n_frames,
        }
    }

    #[inline]
    fn get(&self, pix: usize, n: usize) -> C64 {
        let v = match self {
            Packet::Frames(f) => f[n][pix],
            Packet::PixelMajor { data, n_frames } => data[pix * n_frames + n],
        };
        C64::new(f64::from(v.re), f64::from(v.im))
    }

    fn check(&self, n_pixels: usize) -> Result<()> {
        match self {
            Packet::Frames(f) => {
                for fr in f.iter() {
                    check_len("packet frame", fr.len(), n_pixels)?;
                }
            }
            Packet::PixelMajor { data, n_frames } => check_len("packet", data.len(), n_pixels * n_frames)?,
        }
        Ok(())
    }
}

/// Output maps of one packet (row-major `nz·nx`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DopplerMap {
    /// Doppler velocity (m/s), positive toward the probe; 0 where flagged "no estimate".
    pub velocity: Vec<f32>,
    /// Slow-time power R0 (windowed like R1).
    pub power: Vec<f32>,
    /// MUST's Doppler variance `2 (V_N/π)² (1 − |R1|/R0)` (m²/s²); 0 where no estimate.
    pub variance: Vec<f32>,
    /// [`flags`] bits.
    pub flags: Vec<u8>,
    /// Mean RF frequency (Hz) used per pixel (fc for the autocorrelation estimator).
    pub mean_frequency: Vec<f32>,
    /// Nyquist velocity of the nominal fc (m/s).
    pub nyquist: f64,
}

impl DopplerMap {
    fn resize(&mut self, n: usize) {
        self.velocity.resize(n, 0.0);
        self.power.resize(n, 0.0);
        self.variance.resize(n, 0.0);
        self.flags.resize(n, 0);
        self.mean_frequency.resize(n, 0.0);
    }
}

/// Reusable Doppler estimator for one grid size: window kernels and f64 correlation maps.
/// After the first packet it does not allocate (the output map is reused too).
#[derive(Clone, Debug)]
pub struct DopplerEstimator {
    params: DopplerParams,
    nx: usize,
    nz: usize,
    wz: Vec<f64>,
    wx: Vec<f64>,
    /// Per-pixel axial delay step Δτ (s) for Loupas.
    axial_step: Vec<f64>,
    r0: Vec<f64>,
    r1: Vec<C64>,
    rax: Vec<C64>,
    tmp_r: Vec<f64>,
    tmp_c: Vec<C64>,
}

fn window(shape: WindowShape, m: usize) -> Vec<f64> {
    match shape {
        WindowShape::Boxcar => vec![1.0; m],
        WindowShape::Hamming if m == 1 => vec![1.0],
        WindowShape::Hamming => {
            (0..m).map(|n| 0.54 - 0.46 * (2.0 * std::f64::consts::PI * n as f64 / (m - 1) as f64).cos()).collect()
        }
    }
}

/// Index of a mirror-extended (half-sample symmetric) signal of length n.
#[inline]
fn mirror(i: isize, n: usize) -> usize {
    let n2 = 2 * n as isize;
    let mut j = i.rem_euclid(n2);
    if j >= n as isize {
        j = n2 - 1 - j;
    }
    j as usize
}

/// `atan2(y, x)` (the argument of x + iy) to ~1e-13 rad, branch-free so that a loop over it
/// vectorises: a = min/max of |x|, |y| in [0, 1]; above tan(π/8) reduced by atan a = π/4 +
/// atan((a − 1)/(a + 1)) to |t| ≤ tan(π/8) ≈ 0.414, whose Taylor series t − t³/3 + … is cut
/// after t^33 (next term < 0.4143^35/35 ≈ 1e-15); then the octant. 0 at the origin.
#[inline(always)]
fn atan2_fast(y: f64, x: f64) -> f64 {
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};
    const TAN_PI_8: f64 = 0.414_213_562_373_095_03;
    let (ax, ay) = (x.abs(), y.abs());
    let (mn, mx) = (ax.min(ay), ax.max(ay));
    let a = if mx > 0.0 { mn / mx } else { 0.0 };
    let big = a > TAN_PI_8;
    let t = if big { (a - 1.0) / (a + 1.0) } else { a };
    let t2 = t * t;
    // poly = 1 − t²/3 + t⁴/5 − … − t³²/33 … by Horner, the signs alternating by the subtraction
    let mut poly = 1.0 / 33.0;
    for k in (0..16).rev() {
        poly = 1.0 / (2 * k + 1) as f64 - t2 * poly;
    }
    let mut r = t * poly + if big { FRAC_PI_4 } else { 0.0 };
    r = if ay > ax { FRAC_PI_2 - r } else { r };
    r = if x < 0.0 { PI - r } else { r };
    if y < 0.0 {
        -r
    } else {
        r
    }
}

/// What turns a pixel's (R0, R_L) into its estimate (the lag-L autocorrelation estimator at the
/// nominal fc; Loupas' per-pixel mean frequency stays in `estimate`).
struct Finish {
    fc: f64,
    c: f64,
    prf: f64,
    lag: f64,
    var_scale: f64,
    alias: f64,
}

impl Finish {
    /// One row of the map, branch-free so that it vectorises: velocity, power, variance, flags
    /// and mean frequency from R0 and R_L.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn row(
        &self,
        r0: &[f64],
        r1: &[C64],
        v: &mut [f32],
        pw: &mut [f32],
        var: &mut [f32],
        fl: &mut [u8],
        fm: &mut [f32],
    ) {
        let two_pi = 2.0 * std::f64::consts::PI;
        let n = r0.len().min(r1.len()).min(v.len()).min(pw.len()).min(var.len()).min(fl.len()).min(fm.len());
        for i in 0..n {
            let (q0, q1) = (r0[i], r1[i]);
            // |R1| without hypot's scaling: R1 sums products of f32 samples, far from overflow
            let mag = q1.norm_sqr().sqrt();
            let ok = q0.is_finite() && q0 > 0.0 && mag.is_finite() && mag > 0.0;
            let phi = atan2_fast(q1.im, q1.re);
            pw[i] = if q0.is_finite() { q0 as f32 } else { 0.0 };
            fm[i] = self.fc as f32;
            v[i] = if ok { (-self.c * self.prf * phi / (2.0 * two_pi * self.fc * self.lag)) as f32 } else { 0.0 };
            var[i] = if ok { (self.var_scale * (1.0 - mag / q0)) as f32 } else { 0.0 };
            fl[i] = if !ok {
                flags::NO_ESTIMATE
            } else if phi.abs() > self.alias {
                flags::ALIASING
            } else {
                0
            };
        }
    }

    /// [`Finish::row`] with the widest vector instructions the CPU has (the same operations,
    /// so the same bits).
    #[allow(clippy::too_many_arguments)]
    fn row_simd(
        &self,
        r0: &[f64],
        r1: &[C64],
        v: &mut [f32],
        pw: &mut [f32],
        var: &mut [f32],
        fl: &mut [u8],
        fm: &mut [f32],
    ) {
        #[cfg(target_arch = "x86_64")]
        {
            #[target_feature(enable = "avx512f")]
            #[allow(clippy::too_many_arguments)]
            unsafe fn avx512(
                f: &Finish,
                r0: &[f64],
                r1: &[C64],
                v: &mut [f32],
                pw: &mut [f32],
                var: &mut [f32],
                fl: &mut [u8],
                fm: &mut [f32],
            ) {
                f.row(r0, r1, v, pw, var, fl, fm)
            }
            #[target_feature(enable = "avx2")]
            #[allow(clippy::too_many_arguments)]
            unsafe fn avx2(
                f: &Finish,
                r0: &[f64],
                r1: &[C64],
                v: &mut [f32],
                pw: &mut [f32],
                var: &mut [f32],
                fl: &mut [u8],
                fm: &mut [f32],
            ) {
                f.row(r0, r1, v, pw, var, fl, fm)
            }
            if std::arch::is_x86_feature_detected!("avx512f") {
                // SAFETY: the CPU has AVX-512F (checked above).
                return unsafe { avx512(self, r0, r1, v, pw, var, fl, fm) };
            }
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU has AVX2 (checked above).
                return unsafe { avx2(self, r0, r1, v, pw, var, fl, fm) };
            }
        }
        self.row(r0, r1, v, pw, var, fl, fm)
    }
}

/// 'same'-size convolution with mirror boundary along x then z (separable kernel). Interior
/// samples index directly, the mirror rule applies only within a kernel half-width of an edge;
/// every output is summed over the kernel taps in the same order either way.
fn smooth<T>(data: &mut Vec<T>, tmp: &mut Vec<T>, nx: usize, nz: usize, wz: &[f64], wx: &[f64])
where
    T: Copy + Default + Send + Sync + std::ops::Add<Output = T> + std::ops::Mul<f64, Output = T>,
{
    let (sx, sz) = ((wx.len() - 1) / 2, (wz.len() - 1) / 2);
    if wx.len() > 1 {
        let (lo, hi) = (wx.len() - 1 - sx, nx.saturating_sub(sx)); // i in [lo, hi): no mirroring
        tmp.par_chunks_mut(nx).zip(data.par_chunks(nx)).for_each(|(t, d)| {
            // Tap by tap over the whole row (a loop that vectorises); each output still sums
            // its taps from zero in ascending k, the same order as a per-sample loop.
            t.fill(T::default());
            for (k, w) in wx.iter().enumerate() {
                if lo < hi {
                    let shift = lo + sx - k; // d index of output lo for tap k
                    for (o, x) in t[lo..hi].iter_mut().zip(&d[shift..shift + (hi - lo)]) {
                        *o = *o + *x * *w;
                    }
                }
                for i in (0..lo.min(nx)).chain(hi.max(lo)..nx) {
                    t[i] = t[i] + d[mirror(i as isize + sx as isize - k as isize, nx)] * *w;
                }
            }
        });
        std::mem::swap(data, tmp);
    }
    if wz.len() > 1 {
        // Row by row: output row iz = Σ_k w_k · row(mirror(iz + sz − k)), k ascending.
        let src: &[T] = data.as_slice();
        tmp.par_chunks_mut(nx).enumerate().for_each(|(iz, t)| {
            t.fill(T::default());
            for (k, w) in wz.iter().enumerate() {
                let r = mirror(iz as isize + sz as isize - k as isize, nz);
                for (o, x) in t.iter_mut().zip(&src[r * nx..(r + 1) * nx]) {
                    *o = *o + *x * *w;
                }
            }
        });
        std::mem::swap(data, tmp);
    }
}

impl DopplerEstimator {
    /// Estimator for `nx × nz` maps. For [`Estimator::Loupas`] the axial delay step defaults to
    /// the nominal `2·dz/c` of a 0° transmit and receive; use [`DopplerEstimator::for_plan`] (or
    /// [`DopplerEstimator::set_axial_step`]) to take it from the DAS geometry.
    pub fn new(params: DopplerParams, nx: usize, nz: usize, dz: f64) -> Result<Self> {
        params.validate()?;
        if nx == 0 || nz == 0 || nx.saturating_mul(nz) > 1 << 26 {
            return Err(BeamformError::BadDimension {
                field: "grid nx·nz",
                got: nx * nz,
                allowed: "in [1, 2^26] pixels with nx, nz >= 1",
            });
        }
        positive("grid.dz", dz)?;
        let n = nx * nz;
        Ok(Self {
            wz: window(params.window_shape, params.window[0]),
            wx: window(params.window_shape, params.window[1]),
            axial_step: vec![2.0 * dz / params.c; n],
            params,
            nx,
            nz,
            r0: vec![0.0; n],
            r1: vec![C64::default(); n],
            rax: Vec::new(),
            tmp_r: vec![0.0; n],
            tmp_c: vec![C64::default(); n],
        })
    }

    /// Estimator for the images of `plan`; the Loupas axial step is `(∂τ/∂z)·dz` per pixel from
    /// the plan's delay gradient (nominal 2 dz/c where the plan has no active element).
    pub fn for_plan(params: DopplerParams, plan: &DasPlan) -> Result<Self> {
        let g = plan.grid();
        let mut est = Self::new(params, g.nx, g.nz, g.dz)?;
        let nominal = 2.0 * g.dz / est.params.c;
        let steps: Vec<f64> =
            plan.delay_gradient().iter().map(|d| if d[1] > 0.0 { f64::from(d[1]) * g.dz } else { nominal }).collect();
        est.axial_step = steps;
        Ok(est)
    }

    /// Sets the per-pixel axial delay step Δτ (s) between consecutive rows (Loupas).
    pub fn set_axial_step(&mut self, step: &[f64]) -> Result<()> {
        check_len("axial_step", step.len(), self.nx * self.nz)?;
        if let Some(s) = step.iter().find(|s| !(s.is_finite() && **s > 0.0)) {
            return Err(invalid("axial_step", s, "finite and > 0 (s)"));
        }
        self.axial_step.copy_from_slice(step);
        Ok(())
    }

    /// The parameters.
    pub fn params(&self) -> &DopplerParams {
        &self.params
    }

    /// Estimates one packet into `out` (resized to nz·nx). Errors: fewer than `lag + 1` frames,
    /// frame lengths. Non-finite samples give "no estimate" pixels, not errors.
    pub fn estimate(&mut self, packet: Packet<'_>, out: &mut DopplerMap) -> Result<()> {
        let (nx, nz) = (self.nx, self.nz);
        let n = nx * nz;
        let nf = packet.n_frames();
        let lag = self.params.lag;
        if nf <= lag {
            return Err(BeamformError::BadDimension {
                field: "packet frames",
                got: nf,
                allowed: "> lag (at least lag + 1 frames)",
            });
        }
        packet.check(n)?;
        let loupas = self.params.estimator == Estimator::Loupas;
        if loupas && self.rax.len() != n {
            self.rax = vec![C64::default(); n];
        }
        let pk = &packet;
        // Sums over the frames in four interleaved partial sums (frame index mod 4, combined as
        // (s0 + s1) + (s2 + s3)): four independent dependency chains instead of one. Both packet
        // layouts use this order, so they give bit-identical maps.
        self.r0.par_chunks_mut(nx).zip(self.r1.par_chunks_mut(nx)).enumerate().for_each(|(iz, (r0, r1))| {
            if let Packet::Frames(fr) = pk {
                // Stream each frame's row into the partial sums of its lane (arrays over the row).
                ROW_ACC.with_borrow_mut(|acc| lag_sums_frames_row(fr, iz * nx, lag, (r0, r1), acc));
                return;
            }
            if let Packet::PixelMajor { data, n_frames } = pk {
                lag_sums_row(&data[iz * nx * n_frames..(iz + 1) * nx * n_frames], *n_frames, lag, r0, r1);
            }
        });
        if loupas {
            self.rax.par_chunks_mut(nx).enumerate().for_each(|(iz, ra)| {
                let (a, b) = if nz == 1 {
                    (iz, iz)
                } else if iz + 1 < nz {
                    (iz, iz + 1)
                } else {
                    (iz - 1, iz)
                };
                for (ix, r) in ra.iter_mut().enumerate() {
                    let mut c = C64::default();
                    for k in 0..nf {
                        c += pk.get(a * nx + ix, k) * pk.get(b * nx + ix, k).conj();
                    }
                    *r = c;
                }
            });
        }
        if self.wz.len() > 1 || self.wx.len() > 1 {
            smooth(&mut self.r0, &mut self.tmp_r, nx, nz, &self.wz, &self.wx);
            smooth(&mut self.r1, &mut self.tmp_c, nx, nz, &self.wz, &self.wx);
            if loupas {
                smooth(&mut self.rax, &mut self.tmp_c, nx, nz, &self.wz, &self.wx);
            }
        }
        out.resize(n);
        let p = &self.params;
        let vn = p.nyquist_velocity();
        out.nyquist = vn;
        let var_scale = 2.0 * (vn / std::f64::consts::PI).powi(2);
        let alias = p.alias_fraction * std::f64::consts::PI;
        let (r0, r1, rax, steps) = (&self.r0, &self.r1, &self.rax, &self.axial_step);
        if !loupas {
            let fin = Finish { fc: p.fc, c: p.c, prf: p.prf, lag: lag as f64, var_scale, alias };
            out.velocity
                .par_chunks_mut(nx)
                .zip(out.power.par_chunks_mut(nx))
                .zip(out.variance.par_chunks_mut(nx))
                .zip(out.flags.par_chunks_mut(nx))
                .zip(out.mean_frequency.par_chunks_mut(nx))
                .enumerate()
                .for_each(|(iz, ((((v, pw), var), fl), fm))| {
                    let row = iz * nx..(iz + 1) * nx;
                    fin.row_simd(&r0[row.clone()], &r1[row], v, pw, var, fl, fm);
                });
            return Ok(());
        }
        let two_pi = 2.0 * std::f64::consts::PI;
        out.velocity
            .par_iter_mut()
            .zip(out.power.par_iter_mut())
            .zip(out.variance.par_iter_mut())
            .zip(out.flags.par_iter_mut())
            .zip(out.mean_frequency.par_iter_mut())
            .enumerate()
            .for_each(|(i, ((((v, pw), var), fl), fm))| {
                let (q0, q1) = (r0[i], r1[i]);
                // |R1| without hypot's scaling: R1 sums products of f32 samples, far from overflow
                let mag = q1.norm_sqr().sqrt();
                *pw = if q0.is_finite() { q0 as f32 } else { 0.0 };
                if !(q0.is_finite() && q0 > 0.0 && mag.is_finite() && mag > 0.0) {
                    *v = 0.0;
                    *var = 0.0;
                    *fl = flags::NO_ESTIMATE;
                    *fm = p.fc as f32;
                    return;
                }
                let phi = atan2_fast(q1.im, q1.re);
                let mut f = p.fc;
                if loupas {
                    let dt = steps[i];
                    let ph = two_pi * p.fc * dt;
                    let d = rax[i] * C64::new(ph.cos(), ph.sin());
                    if d.norm() > 0.0 && d.norm().is_finite() {
                        f = (p.fc - d.arg() / (two_pi * dt)).clamp(0.5 * p.fc, 1.5 * p.fc);
                    }
                }
                *fm = f as f32;
                *v = (-p.c * p.prf * phi / (2.0 * two_pi * f * lag as f64)) as f32;
                *var = (var_scale * (1.0 - mag / q0)) as f32;
                *fl = if phi.abs() > alias { flags::ALIASING } else { 0 };
            });
        Ok(())
    }

    /// The last packet's per-pixel slow-time power R0 and lag-L autocorrelation R_L, after the
    /// spatial window (what the velocity and variance came from).
    pub fn autocorrelation(&self) -> (&[f64], &[C64]) {
        (&self.r0, &self.r1)
    }

    /// [`DopplerEstimator::estimate`] into a new map.
    pub fn estimate_to_map(&mut self, packet: Packet<'_>) -> Result<DopplerMap> {
        let mut m = DopplerMap::default();
        self.estimate(packet, &mut m)?;
        Ok(m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The separable window gives the same bits as a per-sample loop (each output sums its taps
    /// from zero in ascending order, mirrored at the edges) for rows shorter than, as long as
    /// and longer than the window, odd and even windows.
    #[test]
    fn smooth_matches_a_per_sample_loop_bit_for_bit() {
        let per_sample = |d: &[f64], nx: usize, nz: usize, wz: &[f64], wx: &[f64]| {
            let (sx, sz) = ((wx.len() - 1) / 2, (wz.len() - 1) / 2);
            let mut t = vec![0.0; nx * nz];
            for iz in 0..nz {
                for i in 0..nx {
                    let mut acc = 0.0;
                    for (k, w) in wx.iter().enumerate() {
                        acc += d[iz * nx + mirror(i as isize + sx as isize - k as isize, nx)] * w;
                    }
                    t[iz * nx + i] = acc;
                }
            }
            let mut o = vec![0.0; nx * nz];
            for iz in 0..nz {
                for i in 0..nx {
                    let mut acc = 0.0;
                    for (k, w) in wz.iter().enumerate() {
                        acc += t[mirror(iz as isize + sz as isize - k as isize, nz) * nx + i] * w;
                    }
                    o[iz * nx + i] = acc;
                }
            }
            o
        };
        for nx in 1..=9 {
            for (mx, mz) in [(2usize, 3usize), (3, 1), (4, 4), (5, 2), (7, 5), (12, 3)] {
                let nz = 6;
                let (wx, wz) = (window(WindowShape::Hamming, mx), window(WindowShape::Hamming, mz));
                let d: Vec<f64> = (0..nx * nz).map(|i| ((i * 37 % 11) as f64 - 4.3) * 0.71).collect();
                let (mut data, mut tmp) = (d.clone(), vec![0.0; nx * nz]);
                smooth(&mut data, &mut tmp, nx, nz, &wz, &wx);
                let want = per_sample(&d, nx, nz, &wz, &wx);
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&data), bits(&want), "nx {nx}, window {mz} x {mx}");
            }
        }
    }

    /// The polynomial argument against libm's atan2 on every octant, the axes, the octant
    /// boundaries, tiny and huge magnitudes: within 1e-13 rad (the velocity is stored in f32).
    #[test]
    fn atan2_fast_matches_libm() {
        let mut worst = 0.0f64;
        let mut pts: Vec<(f64, f64)> = vec![(0.0, 1.0), (1.0, 0.0), (0.0, -1.0), (-1.0, 0.0), (1.0, 1.0), (-1.0, 1.0)];
        for i in 0..100_000 {
            let a = i as f64 * 0.000_062_83;
            let r = 10f64.powi((i % 13) * 4 - 24);
            pts.push((r * a.sin(), r * a.cos()));
        }
        let t8 = (std::f64::consts::PI / 8.0).tan();
        pts.extend([(t8, 1.0), (1.0, t8), (-t8, -1.0), (t8 * (1.0 + 1e-15), 1.0)]);
        for (y, x) in pts {
            worst = worst.max((atan2_fast(y, x) - y.atan2(x)).abs());
        }
        assert!(worst < 1e-13, "worst error {worst:e}");
        assert_eq!(atan2_fast(0.0, 0.0), 0.0);
    }
}
