//! Delay-and-sum of I/Q onto a rectangular grid, with receive sub-aperture steering
//! (MUST/PyMUST `dasmtx`, pymust-notes §7; Shahriari & Garcia 2018 §2.4; Madiena et al. 2018).
//!
//! For pixel p = (x, z) and element e at (x_e, 0):
//!
//! * round-trip delay `τ = (d_TX(p) + |p − e|)/c`, fractional sample `i = (τ − t0)·fs`;
//! * receive aperture (`fnumber` F > 0, receive angle θ): element e is used iff
//!   `|x − x_e − z·tan θ| ≤ z/(2F·cos θ)` — the aperture is centred where the line through p at
//!   angle θ from the z axis meets the array (θ > 0 centres it at smaller x: the receive beam runs
//!   from the aperture down towards +x), and its width keeps the f-number F along that line. F = 0 (MUST's default) uses every element (θ must then be 0).
//!   Rectangular weights, plain sum (MUST: no normalisation by the number of elements);
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
//!   over 4·n_tx points linearly interpolated along the transmitting elements (PyMUST: cubic
//!   spline for the delays; identical for linear delay laws).
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
use serde::{Deserialize, Serialize};

use crate::error::{check_len, invalid, positive, BeamformError, Result};
use crate::grid::Grid;
use crate::C32;

fn default_c() -> f64 {
    1540.0
}

/// Receive apodisation across the aperture a pixel uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Apodization {
    /// Equal weights (MUST's rectangular 0/1 aperture, default): the narrowest main lobe, first
    /// side lobes at −13 dB.
    #[default]
    Boxcar,
    /// Hann window over the aperture, `cos²(π u)` with `u ∈ [−½, ½]` the element's position
    /// across it: side lobes below −31 dB for a main lobe about 1.6 times wider.
    Hann,
}

impl Apodization {
    /// Weight of an element at relative position `u ∈ [−½, ½]` across the aperture.
    pub fn weight(self, u: f64) -> f64 {
        match self {
            Apodization::Boxcar => 1.0,
            Apodization::Hann => {
                let c = (std::f64::consts::PI * u.clamp(-0.5, 0.5)).cos();
                c * c
            }
        }
    }
}

/// Interpolation of the I/Q traces at the fractional delay.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Interpolation {
    /// Nearest sample (MUST `'nearest'`).
    Nearest,
    /// Linear between the two neighbouring samples (MUST `'linear'`, default).
    #[default]
    Linear,
}

/// Delay-and-sum parameters (MUST names, SI units).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DasParams {
    /// Centre (demodulation) frequency (Hz), > 0. MUST `fc`.
    pub fc: f64,
    /// Speed of sound (m/s), > 0, default 1540. MUST `c`.
    #[serde(default = "default_c")]
    pub c: f64,
    /// Sampling frequency of the I/Q traces (Hz), > 0. MUST `fs`.
    pub fs: f64,
    /// Time of sample 0 (s), finite, default 0. MUST `t0`.
    #[serde(default)]
    pub t0: f64,
    /// Element pitch (m), > 0. MUST `pitch`. Elements at `x_e = (e − (N−1)/2)·pitch`, z = 0.
    pub pitch: f64,
    /// Number of elements in [1, 65536]. MUST `Nelements`.
    #[serde(alias = "Nelements", alias = "nelements")]
    pub n_elements: usize,
    /// Receive f-number, ≥ 0 and ≤ 1000; 0 = full aperture (MUST's default). MUST `fnumber`.
    #[serde(default)]
    pub fnumber: f64,
    /// Receive steering angle (rad), |θ| < 80°; needs `fnumber > 0` when ≠ 0. MUST `RXangle`.
    #[serde(default, alias = "RXangle", alias = "rxangle")]
    pub rx_angle: f64,
    /// Interpolation method, default linear.
    #[serde(default)]
    pub interpolation: Interpolation,
    /// Receive apodisation, default boxcar (MUST).
    #[serde(default)]
    pub apodization: Apodization,
}

impl DasParams {
    /// Lateral position of element `e` (m), as MUST: `(e − (N−1)/2)·pitch`.
    pub fn element_x(&self, e: usize) -> f64 {
        (e as f64 - (self.n_elements as f64 - 1.0) / 2.0) * self.pitch
    }

    /// Checks every field; the error names the field and the allowed range.
    pub fn validate(&self) -> Result<()> {
        positive("das.fc", self.fc)?;
        positive("das.c", self.c)?;
        positive("das.fs", self.fs)?;
        positive("das.pitch", self.pitch)?;
        if !self.t0.is_finite() {
            return Err(invalid("das.t0", self.t0, "finite (s)"));
        }
        if !(1..=65536).contains(&self.n_elements) {
            return Err(invalid("das.n_elements", self.n_elements, "in [1, 65536]"));
        }
        if !(self.fnumber.is_finite() && (0.0..=1000.0).contains(&self.fnumber)) {
            return Err(invalid("das.fnumber", self.fnumber, "in [0, 1000] (0 = full aperture)"));
        }
        if !(self.rx_angle.is_finite() && self.rx_angle.abs() < 80f64.to_radians()) {
            return Err(invalid("das.rx_angle", self.rx_angle, "finite with |rx_angle| < 80° (1.396 rad)"));
        }
        if self.rx_angle != 0.0 && self.fnumber == 0.0 {
            return Err(invalid(
                "das.fnumber",
                self.fnumber,
                "> 0 when rx_angle != 0 (a steered sub-aperture needs a finite width)",
            ));
        }
        Ok(())
    }
}

/// The transmitted wave, which sets the transmit distance `d_TX` of every pixel.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum TxWave {
    /// Plane wave tilted by `tilt` (rad, |tilt| < 80°); tilt > 0 travels towards +x
    /// (MUST `txdelay(param, tilt)`, SIMUS `Transmit::plane_wave`).
    PlaneWave {
        /// Tilt (rad).
        tilt: f64,
    },
    /// Wave focused at (x0, z0), z0 > 0 (MUST `txdelay(x0, z0, param)`).
    Focused {
        /// Focus x (m).
        x0: f64,
        /// Focus depth (m), > 0.
        z0: f64,
    },
    /// Diverging wave from the virtual source (x0, z0), z0 < 0.
    Diverging {
        /// Source x (m).
        x0: f64,
        /// Source z (m), < 0.
        z0: f64,
    },
    /// Arbitrary transmit delays (s) per element (NaN = element off; the transmitting elements
    /// must be contiguous). MUST `TXdelay`.
    Delays {
        /// One delay per element (s).
        delays: Vec<f64>,
    },
}

impl TxWave {
    /// Checks the wave against `n_elements`; the error names the field.
    pub fn validate(&self, n_elements: usize) -> Result<()> {
        let lim = 80f64.to_radians();
        match self {
            TxWave::PlaneWave { tilt } => {
                if !(tilt.is_finite() && tilt.abs() < lim) {
                    return Err(invalid("tx.tilt", tilt, "finite with |tilt| < 80° (1.396 rad)"));
                }
            }
            TxWave::Focused { x0, z0 } => {
                if !x0.is_finite() {
                    return Err(invalid("tx.x0", x0, "finite (m)"));
                }
                if !(z0.is_finite() && *z0 > 0.0) {
                    return Err(invalid("tx.z0", z0, "finite and > 0 for a focused wave (m)"));
                }
            }
            TxWave::Diverging { x0, z0 } => {
                if !x0.is_finite() {
                    return Err(invalid("tx.x0", x0, "finite (m)"));
                }
                if !(z0.is_finite() && *z0 < 0.0) {
                    return Err(invalid("tx.z0", z0, "finite and < 0 for a diverging wave (m)"));
                }
            }
            TxWave::Delays { delays } => {
                check_len("tx.delays", delays.len(), n_elements)?;
                if let Some(d) = delays.iter().find(|d| !(d.is_nan() || d.is_finite() && d.abs() < 1.0)) {
                    return Err(invalid("tx.delays", d, "NaN (element off) or finite with |delay| < 1 s"));
                }
                let on: Vec<usize> = (0..n_elements).filter(|&e| !delays[e].is_nan()).collect();
                match (on.first(), on.last()) {
                    (Some(a), Some(b)) if b - a + 1 == on.len() => {}
                    (None, _) => return Err(invalid("tx.delays", "all NaN", "at least one finite delay")),
                    _ => {
                        return Err(invalid(
                            "tx.delays",
                            "gaps",
                            "a contiguous run of transmitting (non-NaN) elements",
                        ));
                    }
                }
            }
        }
        Ok(())
    }

    /// Nominal tilt of the wave at pixel (x, z) (rad from the z axis, positive towards +x),
    /// used for the ideal Doppler projection; plane waves return their tilt.
    pub fn direction_at(&self, x: f64, z: f64) -> f64 {
        match self {
            TxWave::PlaneWave { tilt } => *tilt,
            TxWave::Focused { x0, z0 } | TxWave::Diverging { x0, z0 } => {
                let s = if z >= *z0 { 1.0 } else { -1.0 };
                (s * (x - x0)).atan2(s * (z - z0))
            }
            TxWave::Delays { .. } => 0.0,
        }
    }
}

/// Second derivatives of the not-a-knot cubic spline through `y` at the integer knots 0..n−1
/// (all zero, i.e. linear interpolation, when n < 4).
fn spline_second_derivatives(y: &[f64]) -> Vec<f64> {
    let n = y.len();
    let mut m = vec![0.0; n];
    if n < 4 {
        return m;
    }
    let r = |i: usize| 6.0 * (y[i + 1] - 2.0 * y[i] + y[i - 1]);
    // not-a-knot (M0 − 2M1 + M2 = 0, likewise at the end) turns rows 1 and n−2 into 6·M = r
    m[1] = r(1) / 6.0;
    m[n - 2] = r(n - 2) / 6.0;
    if n > 4 {
        // M_{i−1} + 4 M_i + M_{i+1} = r_i for i = 2..n−3 (Thomas algorithm)
        let k = n - 4;
        let (mut cp, mut dp) = (vec![0.0; k], vec![0.0; k]);
        for j in 0..k {
            let i = j + 2;
            let mut rhs = r(i);
            if i == 2 {
                rhs -= m[1];
            }
            if i == n - 3 {
                rhs -= m[n - 2];
            }
            let denom = if j == 0 { 4.0 } else { 4.0 - cp[j - 1] };
            cp[j] = 1.0 / denom;
            dp[j] = if j == 0 { rhs / denom } else { (rhs - dp[j - 1]) / denom };
        }
        for j in (0..k).rev() {
            m[j + 2] = if j + 1 < k { dp[j] - cp[j] * m[j + 3] } else { dp[j] };
        }
    }
    m[0] = 2.0 * m[1] - m[2];
    m[n - 1] = 2.0 * m[n - 2] - m[n - 3];
    m
}

/// `min_i (d_i + √((x_i − x)² + z²))` and the first index attaining it, as a plain scan would
/// find them; the values are reduced in 8 independent lanes first (vectorisable), then the index
/// is the first whose value equals the minimum (the same expression, so the same bits).
#[inline(always)]
fn points_min(xs: &[f64], d: &[f64], x: f64, z: f64) -> (f64, usize) {
    const L: usize = 8;
    let value = |i: usize| d[i] + ((xs[i] - x) * (xs[i] - x) + z * z).sqrt();
    let n = xs.len().min(d.len());
    let main = n - n % L;
    let mut lanes = [f64::INFINITY; L];
    for c in (0..main).step_by(L) {
        for (j, lane) in lanes.iter_mut().enumerate() {
            let v = value(c + j);
            *lane = if v < *lane { v } else { *lane };
        }
    }
    let mut best = lanes.iter().fold(f64::INFINITY, |a, &b| if b < a { b } else { a });
    for i in main..n {
        let v = value(i);
        best = if v < best { v } else { best };
    }
    let first = (0..n).find(|&i| value(i) == best).unwrap_or(0);
    (best, first)
}

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

/// Transmit distance and its gradient, per pixel.
struct TxModel {
    kind: TxKind,
}

enum TxKind {
    Plane { sin: f64, cos: f64, tan: f64, xa: f64, xb: f64, xref: f64 },
    Diverging { x0: f64, z0: f64, xa: f64, xb: f64, m: f64 },
    Focused { x0: f64, z0: f64, m: f64 },
    Points { x: Vec<f64>, d: Vec<f64> },
}

impl TxModel {
    fn new(tx: &TxWave, p: &DasParams) -> Self {
        let n = p.n_elements;
        let (xa, xb) = (p.element_x(0), p.element_x(n - 1));
        let kind = match tx {
            TxWave::PlaneWave { tilt } => {
                let (sin, cos) = tilt.sin_cos();
                TxKind::Plane { sin, cos, tan: tilt.tan(), xa, xb, xref: if sin >= 0.0 { xa } else { xb } }
            }
            TxWave::Diverging { x0, z0 } => {
                let m = (0..n).map(|e| (p.element_x(e) - x0).hypot(*z0)).fold(f64::INFINITY, f64::min);
                TxKind::Diverging { x0: *x0, z0: *z0, xa, xb, m }
            }
            TxWave::Focused { x0, z0 } => {
                let m = (0..n).map(|e| (p.element_x(e) - x0).hypot(*z0)).fold(0.0, f64::max);
                TxKind::Focused { x0: *x0, z0: *z0, m }
            }
            TxWave::Delays { delays } => {
                let on: Vec<usize> = (0..n).filter(|&e| !delays[e].is_nan()).collect();
                let n_tx = on.len();
                let (mut x, mut d) = (Vec::new(), Vec::new());
                if n_tx == 1 {
                    x.push(p.element_x(on[0]));
                    d.push(delays[on[0]] * p.c);
                } else {
                    // PyMUST: idxi = linspace(0, nTX−1, 4·nTX); positions (linear in the index,
                    // so the cubic interpolation is exact) and delays by a not-a-knot cubic
                    // spline (scipy interp1d 'cubic'; linear below 4 elements).
                    let yd: Vec<f64> = on.iter().map(|&e| delays[e]).collect();
                    let m2 = spline_second_derivatives(&yd);
                    let m = 4 * n_tx;
                    for i in 0..m {
                        let t = (n_tx - 1) as f64 * i as f64 / (m - 1) as f64;
                        let k = (t.floor() as usize).min(n_tx - 2);
                        let u = t - k as f64;
                        let (e0, e1) = (on[k], on[k + 1]);
                        x.push(p.element_x(e0) * (1.0 - u) + p.element_x(e1) * u);
                        let v = (1.0 - u) * yd[k]
                            + u * yd[k + 1]
                            + (((1.0 - u).powi(3) - (1.0 - u)) * m2[k] + (u.powi(3) - u) * m2[k + 1]) / 6.0;
                        d.push(v * p.c);
                    }
                }
                TxKind::Points { x, d }
            }
        };
        Self { kind }
    }

    /// `(d_TX, ∂d_TX/∂x, ∂d_TX/∂z)` at (x, z).
    #[inline(always)]
    fn eval(&self, x: f64, z: f64) -> (f64, f64, f64) {
        let through = |xs: f64, base: f64| {
            let r = (x - xs).hypot(z);
            let (gx, gz) = if r > 0.0 { ((x - xs) / r, z / r) } else { (0.0, 1.0) };
            (base + r, gx, gz)
        };
        match &self.kind {
            TxKind::Plane { sin, cos, tan, xa, xb, xref } => {
                let xs = x - z * tan;
                if xs >= *xa && xs <= *xb {
                    ((x - xref) * sin + z * cos, *sin, *cos)
                } else {
                    let xs = xs.clamp(*xa, *xb);
                    through(xs, (xs - xref) * sin)
                }
            }
            TxKind::Diverging { x0, z0, xa, xb, m } => {
                // crossing of the ray source → pixel with z = 0 (z > 0 > z0 ⇒ 0 < t < 1)
                let xc = if z > *z0 { x0 + (x - x0) * (-z0) / (z - z0) } else { *x0 };
                if z > 0.0 && xc >= *xa && xc <= *xb {
                    let r = (x - x0).hypot(z - z0);
                    (r - m, (x - x0) / r, (z - z0) / r)
                } else {
                    let xs = xc.clamp(*xa, *xb);
                    through(xs, (xs - x0).hypot(*z0) - m)
                }
            }
            TxKind::Focused { x0, z0, m } => {
                let r = (x - x0).hypot(z - z0);
                let s = if z < *z0 { -1.0 } else { 1.0 };
                if r > 0.0 {
                    (m + s * r, s * (x - x0) / r, s * (z - z0) / r)
                } else {
                    (*m, 0.0, 1.0)
                }
            }
            TxKind::Points { x: xs, d } => {
                let best = points_min(xs, d, x, z);
                let xi = xs[best.1];
                let r = (x - xi).hypot(z);
                let (gx, gz) = if r > 0.0 { ((x - xi) / r, z / r) } else { (0.0, 1.0) };
                (best.0, gx, gz)
            }
        }
    }
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

/// What building a row of a [`DasPlan`] needs.
struct RowCtx<'a> {
    model: &'a TxModel,
    p: &'a DasParams,
    xe: &'a [f64],
    tan_rx: f64,
    cos_rx: f64,
    wc: f64,
    last: f64,
    grid: &'a Grid,
    n_samples: usize,
}

impl RowCtx<'_> {
    /// Row `iz`, with the widest vector instructions the CPU has (the same operations, so the
    /// same bits, on every path: Rust does not contract a·b + c into an FMA).
    fn build(&self, iz: usize) -> Row {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx512f") {
                // SAFETY: the CPU has AVX-512F (checked above).
                return unsafe { self.build_avx512(iz) };
            }
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU has AVX2 (checked above).
                return unsafe { self.build_avx2(iz) };
            }
        }
        self.build_row(iz)
    }

    /// # Safety
    /// The CPU must support AVX-512F.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn build_avx512(&self, iz: usize) -> Row {
        self.build_row(iz)
    }

    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn build_avx2(&self, iz: usize) -> Row {
        self.build_row(iz)
    }

    /// Per pixel: the distance and delay to every element (vectorisable), the elements the
    /// pixel uses (aperture, apodisation, trace range), their phase factors (vectorisable), then
    /// the taps and the mean delay gradient.
    #[inline(always)]
    fn build_row(&self, iz: usize) -> Row {
        let (p, grid, xe) = (self.p, self.grid, self.xe);
        let (ne, n_samples) = (xe.len(), self.n_samples);
        let z = grid.z(iz);
        let mut row = Row {
            counts: Vec::with_capacity(grid.nx),
            index: Vec::new(),
            w0: Vec::new(),
            w1: Vec::new(),
            grad: Vec::with_capacity(grid.nx),
        };
        let (mut drx, mut tau) = (vec![0.0f64; ne], vec![0.0f64; ne]);
        let (mut act, mut act_aw, mut act_idx) =
            (Vec::with_capacity(ne), Vec::with_capacity(ne), Vec::with_capacity(ne));
        let (mut act_phase, mut rot) = (Vec::with_capacity(ne), Vec::with_capacity(ne));
        for ix in 0..grid.nx {
            let x = grid.x(ix);
            let (dtx, gtx_x, gtx_z) = self.model.eval(x, z);
            for ((d, t), &xe) in drx.iter_mut().zip(tau.iter_mut()).zip(xe) {
                let dx = x - xe;
                *d = (dx * dx + z * z).sqrt();
                *t = (dtx + *d) / p.c;
            }
            act.clear();
            act_aw.clear();
            act_idx.clear();
            act_phase.clear();
            for (e, &xe) in xe.iter().enumerate() {
                let dx = x - xe;
                // position across the aperture, −½ … ½ (for the apodisation)
                let u = if p.fnumber > 0.0 {
                    let (off, half) = if p.rx_angle == 0.0 {
                        (dx, z / 2.0 / p.fnumber)
                    } else {
                        (dx - z * self.tan_rx, z / self.cos_rx / 2.0 / p.fnumber)
                    };
                    if off.abs() > half {
                        continue;
                    }
                    -off / (2.0 * half)
                } else if ne > 1 {
                    e as f64 / (ne - 1) as f64 - 0.5
                } else {
                    0.0
                };
                let aw = p.apodization.weight(u);
                if aw <= 0.0 {
                    continue;
                }
                let idx = (tau[e] - p.t0) * p.fs;
                if !(idx >= 0.0 && idx <= self.last) {
                    continue;
                }
                act.push(e);
                act_aw.push(aw);
                act_idx.push(idx);
                act_phase.push(self.wc * tau[e]);
            }
            rot.clear();
            rot.extend(act_phase.iter().map(|&ph| sincos_fast(ph)));
            let (mut gx, mut gz, mut gw) = (0.0f64, 0.0f64, 0.0f64);
            for (k, &e) in act.iter().enumerate() {
                let (aw, idx) = (act_aw[k], act_idx[k]);
                let r = C32::new(rot[k].1 as f32, rot[k].0 as f32);
                let base = e * n_samples;
                match p.interpolation {
                    Interpolation::Linear => {
                        let kf = idx.floor();
                        let f = idx - kf;
                        row.index.push((base + kf as usize) as u32);
                        row.w0.push(r * ((1.0 - f) * aw) as f32);
                        row.w1.push(r * (f * aw) as f32);
                    }
                    Interpolation::Nearest => {
                        let ks = idx.round() as usize;
                        let r = r * aw as f32;
                        if ks + 1 < n_samples {
                            row.index.push((base + ks) as u32);
                            row.w0.push(r);
                            row.w1.push(C32::new(0.0, 0.0));
                        } else {
                            row.index.push((base + ks - 1) as u32);
                            row.w0.push(C32::new(0.0, 0.0));
                            row.w1.push(r);
                        }
                    }
                }
                gw += aw;
                let (dx, d) = (x - xe[e], drx[e]);
                if d > 0.0 {
                    gx += aw * (gtx_x + dx / d);
                    gz += aw * (gtx_z + z / d);
                } else {
                    gx += aw * gtx_x;
                    gz += aw * gtx_z;
                }
            }
            let count = act.len() as u32;
            row.counts.push(count);
            row.grad.push(if count > 0 && gw > 0.0 {
                let s = 1.0 / (gw * p.c);
                [(gx * s) as f32, (gz * s) as f32]
            } else {
                [0.0, 0.0]
            });
        }
        row
    }
}

impl DasPlan {
    /// Builds the plan. Errors: invalid parameters, wave, grid, or `n_samples < 2`.
    pub fn new(params: &DasParams, tx: &TxWave, grid: &Grid, n_samples: usize) -> Result<Self> {
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
        let model = TxModel::new(tx, params);
        let p = params;
        let ne = p.n_elements;
        let xe: Vec<f64> = (0..ne).map(|e| p.element_x(e)).collect();
        let (tan_rx, cos_rx) = (p.rx_angle.tan(), p.rx_angle.cos());
        let wc = 2.0 * std::f64::consts::PI * p.fc;
        let last = match p.interpolation {
            Interpolation::Linear => (n_samples - 2) as f64,
            Interpolation::Nearest => (n_samples - 1) as f64,
        };
        let ctx = RowCtx { model: &model, p, xe: &xe, tan_rx, cos_rx, wc, last, grid, n_samples };
        let rows: Vec<Row> = (0..grid.nz).into_par_iter().map(|iz| ctx.build(iz)).collect();
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
        let mut acc = C32::new(0.0, 0.0);
        for ((j, w0), w1) in self.index[a..b].iter().zip(&self.w0[a..b]).zip(&self.w1[a..b]) {
            let j = *j as usize;
            if let [s0, s1] = iq[j..j + 2] {
                acc += w0 * s0 + w1 * s1;
            }
        }
        acc
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

    /// The lane-wise minimum equals a plain first-strictly-smaller scan, value and index, also
    /// with ties and lengths that are not multiples of 8.
    #[test]
    fn points_min_equals_a_plain_scan() {
        for n in [1usize, 7, 8, 9, 33, 512] {
            let xs: Vec<f64> = (0..n).map(|i| -0.02 + 0.04 * i as f64 / n as f64).collect();
            let d: Vec<f64> =
                (0..n).map(|i| if i % 5 == 0 { 1e-3 } else { 1e-3 * ((i * 7) % 11) as f64 / 11.0 }).collect();
            for (x, z) in [(0.0, 0.02), (-0.019, 0.005), (0.013, 0.04), (0.0, 0.0)] {
                let mut best = (f64::INFINITY, 0usize);
                for i in 0..n {
                    let v = d[i] + ((xs[i] - x).powi(2) + z * z).sqrt();
                    if v < best.0 {
                        best = (v, i);
                    }
                }
                let got = points_min(&xs, &d, x, z);
                assert_eq!((got.0.to_bits(), got.1), (best.0.to_bits(), best.1), "n {n} at ({x}, {z})");
            }
        }
    }
}
