//! The transmit distance `d_TX` of every pixel and its gradient ([`TxModel`]): closed forms, and
//! PyMUST's minimum over the transmit points (lane-wise scan, divide and conquer along a row).

use super::{convex, DasParams, TxWave};

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

/// The smallest of `value(0) … value(n − 1)` and the first index attaining it, as a plain scan
/// would find them: 8 independent lanes each keep their smallest value and its first index (the
/// same expression, branch-free, so it vectorises when `value` reads slices of length ≥ `n` at
/// index `i`), then the lanes are merged by value and, on ties, by index; the tail is scanned
/// after them. Index 0 if every value is +∞ or NaN.
#[inline(always)]
pub(crate) fn lane_argmin(n: usize, value: impl Fn(usize) -> f64) -> (f64, usize) {
    const L: usize = 8;
    let mut lv = [f64::INFINITY; L];
    // the chunk index as f64 (exact below 2^53), so the select is a vector blend
    let mut li = [0.0f64; L];
    for c in 0..n / L {
        let cf = c as f64;
        for j in 0..L {
            let v = value(c * L + j);
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
        let v = value(i);
        if v < best.0 {
            best = (v, i);
        }
    }
    (best.0, if best.1 == usize::MAX { 0 } else { best.1 })
}

/// `min_i (d_i + √((x_i − x)² + z²))` and the first index attaining it ([`lane_argmin`]).
#[inline(always)]
fn points_min(xs: &[f64], d: &[f64], x: f64, z: f64) -> (f64, usize) {
    let n = xs.len().min(d.len());
    let (xs, d) = (&xs[..n], &d[..n]);
    let z2 = z * z;
    lane_argmin(n, |i| {
        let dx = xs[i] - x;
        d[i] + (dx * dx + z2).sqrt()
    })
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
                        d.push(spline_at(&yd, &m2, k, u) * p.c);
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
    pub(crate) fn eval_row(&self, xq: &[f64], z: f64, out: &mut Vec<(f64, f64, f64)>) {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::das::{Apodization, Interpolation};

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

    /// The generic scan equals a plain first-strictly-smaller scan on every length 0 … 17 and a
    /// long one: ties within and across lanes, NaN values (never smaller), all +∞ (index 0).
    #[test]
    fn lane_argmin_equals_a_plain_scan() {
        let plain = |v: &[f64]| {
            let mut best = (f64::INFINITY, 0usize);
            for (i, &x) in v.iter().enumerate() {
                if x < best.0 {
                    best = (x, i);
                }
            }
            best
        };
        let patterns: [fn(usize) -> f64; 4] = [
            |i| ((i * 7) % 5) as f64,                                      // ties in several lanes
            |i| if i % 3 == 0 { f64::NAN } else { 10.0 - (i % 4) as f64 }, // NaN among values
            |_| f64::INFINITY,
            |i| if i == 13 || i == 21 { -1.0 } else { f64::NAN }, // tie across lanes
        ];
        for n in (0..=17).chain([64, 203]) {
            for f in patterns {
                let v: Vec<f64> = (0..n).map(f).collect();
                let got = lane_argmin(n, |i| v[i]);
                let want = plain(&v);
                assert_eq!((got.0.to_bits(), got.1), (want.0.to_bits(), want.1), "n {n}: {v:?}");
            }
        }
    }
}
