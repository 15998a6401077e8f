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
//!   over 4·n_tx points linearly interpolated along the transmitting elements (PyMUST: cubic
//!   spline for the delays; identical for linear delay laws).
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
use serde::{Deserialize, Serialize};

pub mod convex;

use crate::error::{check_len, invalid, positive, BeamformError, Result};
use crate::grid::Grid;
use crate::C32;
use convex::Convex;

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
    /// Element pitch (m), > 0. MUST `pitch`. Linear array: elements at `x_e = (e − (N−1)/2)·pitch`,
    /// z = 0; convex array: one pitch apart along the arc ([`DasParams::element_positions`]).
    pub pitch: f64,
    /// Number of elements in [1, 65536] (on a convex array, few enough that the arc spans less
    /// than half a circle). MUST `Nelements`.
    #[serde(alias = "Nelements", alias = "nelements")]
    pub n_elements: usize,
    /// Radius of curvature of a convex array (m), > 0; None or +∞ = linear array (default).
    /// MUST `radius`. The arc's chord lies on z = 0, centred on x = 0; its circle's centre is at
    /// (0, −h), h the apothem ([`crate::convex`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius: Option<f64>,
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
    /// Lateral position of element `e` (m), as MUST: `(e − (N−1)/2)·pitch` for a linear array,
    /// `R sin θ_e` for a convex one (the x of [`DasParams::element_positions`]).
    pub fn element_x(&self, e: usize) -> f64 {
        match self.convex_radius() {
            None => (e as f64 - (self.n_elements as f64 - 1.0) / 2.0) * self.pitch,
            Some(r) => convex::convex_element(self.pitch, self.n_elements, r, e).0,
        }
    }

    /// The radius of a convex array (`radius` finite), None for a linear one.
    pub fn convex_radius(&self) -> Option<f64> {
        self.radius.filter(|r| r.is_finite())
    }

    /// `(x_e, z_e, θ_e)` of every element (m, m, rad): MUST `getElementPositions`. Linear array:
    /// x_e as [`DasParams::element_x`], z_e = 0, θ_e = 0; convex array:
    /// [`convex::convex_element_positions`] (θ_e is the angle of element e's normal from the z
    /// axis, positive towards +x).
    pub fn element_positions(&self) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let n = self.n_elements;
        match self.convex_radius() {
            None => ((0..n).map(|e| self.element_x(e)).collect(), vec![0.0; n], vec![0.0; n]),
            Some(r) => convex::convex_element_positions(self.pitch, n, r),
        }
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
        convex::validate_radius(self)
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

    /// The transmit delays (s) of this wave on the array of `params` ([`DasParams::element_positions`]),
    /// minimum 0, as MUST `txdelay` (txdelay.py):
    ///
    /// * plane wave of tilt θ: linear array `x_e sin θ/c − min`; convex array `−d_e/c − min`, d_e
    ///   the distance from element e to the line tangent to the arc's circle at angle θ
    ///   (`xn = R sin θ, zn = R cos θ − h`, `d = |z_e + xn/(zn + h)·x_e − xn²/(zn + h) − zn| /
    ///   √(1 + xn²/(zn + h)²)`);
    /// * focused at f: `−|e − f|/c − min`; diverging from s: `|e − s|/c − min` (MUST picks the
    ///   sign of a convex array's law by whether the point lies in the circle of radius R about
    ///   (0, R); here the kind chooses it);
    /// * `Delays`: as given (NaN = element off).
    ///
    /// Errors: invalid parameters or wave.
    pub fn delays(&self, params: &DasParams) -> Result<Vec<f64>> {
        params.validate()?;
        self.validate(params.n_elements)?;
        Ok(convex::tx_delays(params, self))
    }
}

/// Second derivatives of the not-a-knot cubic spline through `y` at the integer knots 0..n−1
/// (all zero, i.e. linear interpolation, when n < 4).
pub(crate) fn spline_second_derivatives(y: &[f64]) -> Vec<f64> {
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

/// The spline of [`spline_second_derivatives`] (second derivatives `m2`) between knots k and
/// k + 1, at fraction u.
#[inline]
pub(crate) fn spline_at(y: &[f64], m2: &[f64], k: usize, u: f64) -> f64 {
    (1.0 - u) * y[k] + u * y[k + 1] + (((1.0 - u).powi(3) - (1.0 - u)) * m2[k] + (u.powi(3) - u) * m2[k + 1]) / 6.0
}

/// `min_i (d_i + √((x_i − x)² + z²))` and the first index attaining it, as a plain scan would
/// find them: 8 independent lanes each keep their smallest value and its first index (the same
/// expression, branch-free, so it vectorises), then the lanes are merged by value and, on ties,
/// by index; the tail is scanned after them.
#[inline(always)]
fn points_min(xs: &[f64], d: &[f64], x: f64, z: f64) -> (f64, usize) {
    const L: usize = 8;
    let n = xs.len().min(d.len());
    let (xs, d) = (&xs[..n], &d[..n]);
    let z2 = z * z;
    let mut lv = [f64::INFINITY; L];
    // the chunk index as f64 (exact below 2^53), so the select is a vector blend
    let mut li = [0.0f64; L];
    for (c, (xc, dc)) in xs.chunks_exact(L).zip(d.chunks_exact(L)).enumerate() {
        let cf = c as f64;
        for j in 0..L {
            let dx = xc[j] - x;
            let v = dc[j] + (dx * dx + z2).sqrt();
            let better = v < lv[j];
            lv[j] = if better { v } else { lv[j] };
            li[j] = if better { cf } else { li[j] };
        }
    }
    let mut best = (f64::INFINITY, usize::MAX);
    for j in 0..L {
        let i = li[j] as usize * L + j;
        if lv[j] < best.0 || (lv[j] == best.0 && lv[j] < f64::INFINITY && i < best.1) {
            best = (lv[j], i);
        }
    }
    for i in n - n % L..n {
        let dx = xs[i] - x;
        let v = d[i] + (dx * dx + z2).sqrt();
        if v < best.0 {
            best = (v, i);
        }
    }
    (best.0, if best.1 == usize::MAX { 0 } else { best.1 })
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
pub(crate) struct TxModel {
    kind: TxKind,
}

/// How d_TX is evaluated: closed forms (linear arrays; focused waves on convex ones), PyMUST's
/// transmit points on z = 0 (linear arrays) or off it (`PointsXz`, convex arrays).
enum TxKind {
    Plane { sin: f64, cos: f64, tan: f64, xa: f64, xb: f64, xref: f64 },
    Diverging { x0: f64, z0: f64, xa: f64, xb: f64, m: f64 },
    Focused { x0: f64, z0: f64, m: f64 },
    Points { x: Vec<f64>, d: Vec<f64> },
    PointsXz { x: Vec<f64>, z: Vec<f64>, d: Vec<f64> },
}

impl TxModel {
    pub(crate) fn new(tx: &TxWave, p: &DasParams) -> Self {
        if p.convex_radius().is_some() {
            return Self::convex(tx, p);
        }
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

    /// A convex array: a focused wave by its virtual source (`max_e |e − f|` over the elements on
    /// the arc), every other wave by its delays ([`TxWave::delays`]) and PyMUST's rule, the
    /// minimum over 4·n_tx points along the transmitting elements, positions and delays
    /// interpolated by the not-a-knot cubic spline (scipy interp1d 'cubic', as PyMUST does for
    /// xe, ze and the delays).
    fn convex(tx: &TxWave, p: &DasParams) -> Self {
        if let TxWave::Focused { x0, z0 } = tx {
            let (xe, ze, _) = p.element_positions();
            let m = xe.iter().zip(&ze).map(|(x, z)| (x - x0).hypot(z - z0)).fold(0.0, f64::max);
            return Self { kind: TxKind::Focused { x0: *x0, z0: *z0, m } };
        }
        let (x, z, d) = convex::tx_points(p, tx);
        Self { kind: TxKind::PointsXz { x, z, d } }
    }

    /// `(d_TX, ∂d_TX/∂x, ∂d_TX/∂z)` at (x, z).
    #[inline(always)]
    pub(crate) fn eval(&self, x: f64, z: f64) -> (f64, f64, f64) {
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
            TxKind::Points { x: xs, d } => Self::through_point(xs, points_min(xs, d, x, z), x, z),
            TxKind::PointsXz { x: xs, z: zs, d } => convex::points_eval(xs, zs, d, x, z),
        }
    }

    /// `(d_TX, ∂d_TX/∂x, ∂d_TX/∂z)` from the nearest transmit point `best` (value, index).
    #[inline(always)]
    fn through_point(xs: &[f64], best: (f64, usize), x: f64, z: f64) -> (f64, f64, f64) {
        let xi = xs[best.1];
        let r = (x - xi).hypot(z);
        let (gx, gz) = if r > 0.0 { ((x - xi) / r, z / r) } else { (0.0, 1.0) };
        (best.0, gx, gz)
    }

    /// [`Self::eval`] at `(x_i, z)` for every `x_i` of `xq` (ascending), into `out`. For
    /// PyMUST's transmit points (sorted by x) the nearest point moves monotonically with x —
    /// the matrix `d_j + √((x_i − x_j)² + z²)` is Monge, since √(t² + z²) is convex — so the
    /// minima of a row are found by divide and conquer over the columns, O((points + columns)
    /// · log columns) evaluations instead of points × columns, each search a [`points_min`]
    /// over the range its neighbours leave.
    fn eval_row(&self, xq: &[f64], z: f64, out: &mut Vec<(f64, f64, f64)>) {
        out.clear();
        match &self.kind {
            TxKind::Points { x: xs, d }
                if xs.windows(2).all(|w| w[0] <= w[1]) && xq.windows(2).all(|w| w[0] < w[1]) =>
            {
                let mut best = vec![(0.0, 0usize); xq.len()];
                monotone_minima(xs, d, xq, z, 0..xq.len(), 0, xs.len().min(d.len()).saturating_sub(1), &mut best);
                out.extend(xq.iter().zip(&best).map(|(&x, &b)| Self::through_point(xs, b, x, z)));
            }
            _ => out.extend(xq.iter().map(|&x| self.eval(x, z))),
        }
    }
}

/// The minima of [`points_min`] for the queries `q` (ascending x), searching only the points
/// `lo..=hi` (the leftmost minimum of a Monge matrix moves right with the query).
#[allow(clippy::too_many_arguments)]
fn monotone_minima(
    xs: &[f64],
    d: &[f64],
    xq: &[f64],
    z: f64,
    q: std::ops::Range<usize>,
    lo: usize,
    hi: usize,
    out: &mut [(f64, usize)],
) {
    if q.is_empty() {
        return;
    }
    let mid = q.start + (q.end - q.start) / 2;
    let (v, i) = points_min(&xs[lo..=hi], &d[lo..=hi], xq[mid], z);
    out[mid] = (v, lo + i);
    monotone_minima(xs, d, xq, z, q.start..mid, lo, lo + i, out);
    monotone_minima(xs, d, xq, z, mid + 1..q.end, lo + i, hi, out);
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

    /// The divide-and-conquer row of transmit distances equals the per-pixel scan: PyMUST-like
    /// transmit points (4 per element, uneven delays) and a row crossing the aperture and beyond.
    #[test]
    fn row_minima_equal_the_per_pixel_scan() {
        let p = DasParams {
            fc: 5e6,
            c: 1540.0,
            fs: 20e6,
            t0: 0.0,
            pitch: 0.3e-3,
            n_elements: 32,
            radius: None,
            fnumber: 1.5,
            rx_angle: 0.0,
            interpolation: Interpolation::Linear,
            apodization: Apodization::Hann,
        };
        let delays: Vec<f64> = (0..32).map(|e| 1e-6 * ((e * 13 % 7) as f64 / 7.0 + (e as f64 / 9.0).sin())).collect();
        let model = TxModel::new(&TxWave::Delays { delays }, &p);
        let xq: Vec<f64> = (0..301).map(|i| -0.02 + 0.04 * i as f64 / 300.0).collect();
        let mut row = Vec::new();
        for z in [0.0, 1e-4, 3e-3, 0.02, 0.06] {
            model.eval_row(&xq, z, &mut row);
            for (&x, &got) in xq.iter().zip(&row) {
                let want = model.eval(x, z);
                assert!(
                    (got.0 - want.0).abs() <= 1e-15 * want.0.abs().max(1e-3),
                    "d_TX at ({x}, {z}): {got:?} vs {want:?}"
                );
                assert!((got.1 - want.1).abs() < 1e-9 && (got.2 - want.2).abs() < 1e-9, "gradient at ({x}, {z})");
            }
        }
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
