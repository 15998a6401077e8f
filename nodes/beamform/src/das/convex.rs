//! Convex arrays (MUST `param.radius`) for delay-and-sum: element geometry, transmit delays,
//! receive angles and the checks that go with them (MUST/PyMUST 0.1.9 `getElementPositions`,
//! `txdelay`, `dasmtx`).
//!
//! Axes as MUST's: x parallel to the chord (0 at its middle), z = 0 at the chord, depth > 0.
//! The N elements sit on an arc of radius R whose circle has its centre at (0, −h), h the
//! apothem; the arc bulges to z = R − h > 0 in the middle, its ends are at z = 0. Element e's
//! normal makes the angle θ_e with the z axis (positive towards +x). A pixel is in front of the
//! array iff it lies outside the circle: `x² + (z + h)² > R²`.

use std::f64::consts::PI;

use super::transmit::{lane_argmin, spline_at, spline_second_derivatives};
use super::{DasParams, TxWave};
use crate::error::{invalid, BeamformError, Result};
use crate::grid::Grid;

/// The largest finite radius of curvature accepted (m); beyond it the arc's sagitta is lost in
/// rounding (`R cos θ − h` cancels), use a linear array.
pub const MAX_RADIUS: f64 = 1e6;

/// Chord and apothem of the arc of `n` elements of pitch `pitch` on a circle of radius `r`
/// (MUST: `chord = 2R·sin(asin(pitch/2/R)·(N−1))`, `h = √(R² − chord²/4)`).
fn chord_apothem(pitch: f64, n: usize, r: f64) -> (f64, f64) {
    let chord = 2.0 * r * ((pitch / 2.0 / r).asin() * (n as f64 - 1.0)).sin();
    (chord, (r * r - chord * chord / 4.0).sqrt())
}

/// Apothem h (m) of a convex array: the distance from the circle's centre to the chord (the
/// centre is at (0, −h)). MUST `getElementPositions`' fourth output.
pub fn apothem(pitch: f64, n_elements: usize, radius: f64) -> f64 {
    chord_apothem(pitch, n_elements, radius).1
}

/// Position `(x_e, z_e)` (m) and normal angle `θ_e` (rad from the z axis, positive towards +x)
/// of element `e` of a convex array, exactly as MUST/PyMUST `getElementPositions` (utils.py):
///
/// ```text
/// chord = 2R·sin(asin(pitch/2/R)·(N−1));  h = √(R² − chord²/4)        (apothem)
/// θ_e = linspace(atan2(−chord/2, h), atan2(chord/2, h), N)[e]
/// x_e = R·sin θ_e;  z_e = R·cos θ_e − h
/// ```
///
/// (numpy's linspace: `θ_0 + e·step`, the last angle exactly `atan2(chord/2, h)`.) Neighbours
/// are one pitch apart (chord of the angle `2·asin(pitch/2R)`), the end elements at z = 0. For
/// valid parameters ([`DasParams::validate`]); NaN where `pitch > 2R`.
pub fn convex_element(pitch: f64, n_elements: usize, radius: f64, e: usize) -> (f64, f64, f64) {
    let (chord, h) = chord_apothem(pitch, n_elements, radius);
    element_on_arc(radius, h, chord, n_elements, e)
}

/// [`convex_element`] for every element: `(x_e, z_e, θ_e)`.
pub fn convex_element_positions(pitch: f64, n_elements: usize, radius: f64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let (chord, h) = chord_apothem(pitch, n_elements, radius);
    let mut out = (Vec::with_capacity(n_elements), Vec::with_capacity(n_elements), Vec::with_capacity(n_elements));
    for e in 0..n_elements {
        let (x, z, t) = element_on_arc(radius, h, chord, n_elements, e);
        out.0.push(x);
        out.1.push(z);
        out.2.push(t);
    }
    out
}

/// The one formula of [`convex_element`], given the chord and apothem.
#[inline]
fn element_on_arc(r: f64, h: f64, chord: f64, n: usize, e: usize) -> (f64, f64, f64) {
    let (a, b) = ((-chord / 2.0).atan2(h), (chord / 2.0).atan2(h));
    let t = if n <= 1 {
        a
    } else if e == n - 1 {
        b
    } else {
        a + e as f64 * ((b - a) / (n - 1) as f64)
    };
    (r * t.sin(), r * t.cos() - h, t)
}

/// The largest number of elements of pitch `pitch` that fit on an arc of radius `r` spanning
/// less than half a circle, `(N − 1)·asin(pitch/2R) < π/2` (1 when `pitch ≥ 2R`).
pub fn max_elements(pitch: f64, r: f64) -> usize {
    let fits = |n: usize| n <= 1 || (n as f64 - 1.0) * (pitch / 2.0 / r).asin() < PI / 2.0;
    let a = (pitch / 2.0 / r).asin();
    if !(a.is_finite() && a > 0.0 && fits(2)) {
        return 1;
    }
    let mut n = ((PI / 2.0 / a).ceil() as usize).clamp(1, usize::MAX / 2);
    while n > 1 && !fits(n) {
        n -= 1;
    }
    while fits(n + 1) {
        n += 1;
    }
    n
}

/// Checks `radius` (None or +∞: linear array) against the other fields; the error names the
/// field and the allowed range.
pub(crate) fn validate_radius(p: &DasParams) -> Result<()> {
    let Some(r) = p.radius else { return Ok(()) };
    if r.is_nan() || r <= 0.0 {
        return Err(invalid("das.radius", r, "> 0 (infinite = linear array)"));
    }
    if r == f64::INFINITY {
        return Ok(());
    }
    if r > MAX_RADIUS {
        return Err(invalid("das.radius", r, "<= 1e6 m when finite (an infinite radius, or none, is a linear array)"));
    }
    if p.pitch > 2.0 * r {
        return Err(invalid("das.pitch", p.pitch, "<= 2·radius on a convex array (the pitch is a chord of the arc)"));
    }
    let n_max = max_elements(p.pitch, r);
    if p.n_elements > n_max {
        return Err(invalid(
            "das.n_elements",
            format!("{} (at most {n_max} elements of pitch {} m fit on radius {} m)", p.n_elements, p.pitch, r),
            "such that the arc spans less than half a circle: (N − 1)·asin(pitch/(2·radius)) < π/2",
        ));
    }
    Ok(())
}

/// What the DAS of a convex array needs beside the element x positions: the element depths and
/// normal angles, the circle, and the f-number's half-angle `atan(1/(2F))`.
#[derive(Clone, Debug)]
pub(crate) struct Convex {
    /// Radius of curvature (m).
    pub radius: f64,
    /// Apothem (m); the circle's centre is (0, −h).
    pub h: f64,
    /// Element x (m).
    pub xe: Vec<f64>,
    /// Element z (m).
    pub ze: Vec<f64>,
    /// Element normal angles (rad).
    pub the: Vec<f64>,
    /// Half-angle of the receive aperture, `atan(1/(2F))` (0 without an f-number).
    pub alpha: f64,
}

impl Convex {
    /// The geometry of `p`, None for a linear array.
    pub fn of(p: &DasParams) -> Option<Self> {
        let r = p.convex_radius()?;
        let (xe, ze, the) = convex_element_positions(p.pitch, p.n_elements, r);
        let alpha = if p.fnumber > 0.0 { (1.0 / (2.0 * p.fnumber)).atan() } else { 0.0 };
        Some(Self { radius: r, h: apothem(p.pitch, p.n_elements, r), xe, ze, the, alpha })
    }

    /// Errors if a grid pixel lies behind the face (MUST's isOUT: inside or on the circle of the
    /// arc; z < 0 is refused for every array by [`Grid::validate`]).
    pub fn check_grid(&self, grid: &Grid) -> Result<()> {
        let (r, h) = (self.radius, self.h);
        // x² is convex in the column index: its minimum over a row is at one of these columns
        let near0 = if grid.dx > 0.0 { (-grid.x0 / grid.dx).round() } else { 0.0 };
        let c = near0.clamp(0.0, (grid.nx - 1) as f64) as usize;
        let cols = [c.saturating_sub(1), c, (c + 1).min(grid.nx - 1), 0, grid.nx - 1];
        for iz in 0..grid.nz {
            let z = grid.z(iz);
            if z + h > r {
                continue;
            }
            for &ix in &cols {
                let x = grid.x(ix);
                if x * x + (z + h) * (z + h) <= r * r {
                    return Err(BeamformError::InvalidParameter {
                        field: "grid",
                        value: format!(
                            "pixel (ix {ix}, iz {iz}) at (x, z) = ({x:e}, {z:e}) m, behind the convex array's face \
                             (face depth at that x: {:e} m)",
                            face_depth(r, h, x)
                        ),
                        allowed: "pixels in front of the array, below its face: x² + (z + h)² > radius² \
                                  (z > radius·cos(asin(x/radius)) − h where |x| < radius)",
                    });
                }
            }
        }
        Ok(())
    }
}

/// Depth (m) of the circle of the arc at lateral position x, `R·cos(asin(x/R)) − h` (−h beyond
/// |x| ≥ R).
pub fn face_depth(r: f64, h: f64, x: f64) -> f64 {
    r * (x / r).clamp(-1.0, 1.0).asin().cos() - h
}

/// Direction (rad from the z axis, positive towards +x) of the vector (dx, dz) from an element to
/// a pixel: `atan2(dx, dz)`, PyMUST's `asin(dx/d)` where dz ≥ 0 (better conditioned near ±90°),
/// continued beyond ±π/2 where the pixel is shallower than the element (dz < 0). (PyMUST keeps
/// `asin(dx/d)` there, a mirror image of the direction that can pick elements facing away from
/// the pixel and make the aperture non-contiguous.)
#[inline(always)]
pub(crate) fn direction(dx: f64, dz: f64) -> f64 {
    dx.atan2(dz)
}

/// Angle (rad) between the receive direction of element e (its normal turned by `rx`) and the
/// direction from it to pixel (x, z): `direction − θ_e − θ_RX`, strictly decreasing in e for a
/// pixel outside the circle of the arc.
#[inline(always)]
pub(crate) fn rx_offset(cv: &Convex, e: usize, x: f64, z: f64, rx: f64) -> f64 {
    direction(x - cv.xe[e], z - cv.ze[e]) - cv.the[e] - rx
}

/// The elements `lo..hi` a pixel (x, z) in front of the array uses with an f-number: those with
/// `|direction − θ_e − θ_RX| ≤ atan(1/(2F))` (PyMUST's `|asin(dx/d) − θ_e| ≤ atan(1/2F)` for
/// θ_RX = 0). The offset decreases along the arc for a pixel outside its circle (the direction
/// from a point moving along a circle to a point outside it turns slower than the normal), so
/// the set is a contiguous run, found by bisection on the same expression as the per-element test.
#[inline(always)]
pub(crate) fn aperture(cv: &Convex, x: f64, z: f64, rx: f64) -> (usize, usize) {
    let n = cv.xe.len();
    let off = |e: usize| rx_offset(cv, e, x, z, rx);
    let lo = partition(0, n, |e| off(e) > cv.alpha);
    let hi = partition(lo, n, |e| off(e) >= -cv.alpha);
    (lo, hi)
}

/// The first index in `lo..hi` where `pred` is false, `pred` being true on a prefix.
#[inline(always)]
fn partition(mut lo: usize, mut hi: usize, pred: impl Fn(usize) -> bool) -> usize {
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if pred(mid) {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    lo
}

/// [`TxWave::delays`] without the checks (MUST `txdelay`, txdelay.py).
pub(crate) fn tx_delays(p: &DasParams, tx: &TxWave) -> Vec<f64> {
    let (xe, ze, _) = p.element_positions();
    let c = p.c;
    let mut d: Vec<f64> = match tx {
        TxWave::Delays { delays } => return delays.clone(),
        TxWave::PlaneWave { tilt } => match p.convex_radius() {
            None => xe.iter().map(|x| x * tilt.sin() / c).collect(),
            Some(r) => {
                let h = apothem(p.pitch, p.n_elements, r);
                let (xn, zn) = (r * tilt.sin(), r * tilt.cos() - h);
                let s = xn / (zn + h);
                let norm = (1.0 + s * s).sqrt();
                xe.iter().zip(&ze).map(|(x, z)| -((z + s * x - xn * xn / (zn + h) - zn).abs() / norm) / c).collect()
            }
        },
        TxWave::Focused { x0, z0 } => xe.iter().zip(&ze).map(|(x, z)| -((x - x0).hypot(z - z0) / c)).collect(),
        TxWave::Diverging { x0, z0 } => xe.iter().zip(&ze).map(|(x, z)| (x - x0).hypot(z - z0) / c).collect(),
    };
    let m = d.iter().copied().fold(f64::INFINITY, f64::min);
    for v in &mut d {
        *v -= m;
    }
    d
}

/// PyMUST's transmit points of a convex array for `tx` (any kind; focused waves use
/// [`tx_delays`] too): `(x_i, z_i, c·delay_i)` at `idxi = linspace(0, n_tx − 1, 4·n_tx)` along
/// the transmitting elements, positions and delays interpolated by the not-a-knot cubic spline
/// (scipy interp1d 'cubic', as PyMUST's dasmtx does for xe, ze and the delays; linear below 4
/// elements); the one element itself when only one transmits.
pub(crate) fn tx_points(p: &DasParams, tx: &TxWave) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let (xe, ze, _) = p.element_positions();
    let delays = tx_delays(p, tx);
    let on: Vec<usize> = (0..p.n_elements).filter(|&e| !delays[e].is_nan()).collect();
    let n_tx = on.len();
    if n_tx <= 1 {
        return (
            on.iter().map(|&e| xe[e]).collect(),
            on.iter().map(|&e| ze[e]).collect(),
            on.iter().map(|&e| delays[e] * p.c).collect(),
        );
    }
    let pick = |v: &[f64]| -> Vec<f64> { on.iter().map(|&e| v[e]).collect() };
    let (yx, yz, yd) = (pick(&xe), pick(&ze), pick(&delays));
    let (mx, mz, md) = (spline_second_derivatives(&yx), spline_second_derivatives(&yz), spline_second_derivatives(&yd));
    let m = 4 * n_tx;
    let mut out = (Vec::with_capacity(m), Vec::with_capacity(m), Vec::with_capacity(m));
    for i in 0..m {
        let t = (n_tx - 1) as f64 * i as f64 / (m - 1) as f64;
        let k = (t.floor() as usize).min(n_tx - 2);
        let u = t - k as f64;
        out.0.push(spline_at(&yx, &mx, k, u));
        out.1.push(spline_at(&yz, &mz, k, u));
        out.2.push(spline_at(&yd, &md, k, u) * p.c);
    }
    out
}

/// `min_i (d_i + √((x_i − x)² + (z_i − z)²))` and the first index attaining it: the linear
/// array's `points_min` for transmit points off z = 0 ([`lane_argmin`]).
#[inline(always)]
fn points_min_xz(xs: &[f64], zs: &[f64], d: &[f64], x: f64, z: f64) -> (f64, usize) {
    let n = xs.len().min(zs.len()).min(d.len());
    let (xs, zs, d) = (&xs[..n], &zs[..n], &d[..n]);
    lane_argmin(n, |i| {
        let (dx, dz) = (xs[i] - x, zs[i] - z);
        d[i] + (dx * dx + dz * dz).sqrt()
    })
}

/// `(d_TX, ∂d_TX/∂x, ∂d_TX/∂z)` at (x, z) from transmit points off z = 0: d_TX is PyMUST's
/// discrete minimum; its gradient is the unit vector from the minimising point of the continuous
/// curve (envelope theorem), located by a parabola through the values at the best point and its
/// neighbours — so it does not jump from point to point (on the axis of a symmetric array, where
/// two points tie, it is exactly along z).
pub(crate) fn points_eval(xs: &[f64], zs: &[f64], d: &[f64], x: f64, z: f64) -> (f64, f64, f64) {
    let (v, i) = points_min_xz(xs, zs, d, x, z);
    let n = xs.len().min(zs.len()).min(d.len());
    let val = |j: usize| {
        let (dx, dz) = (xs[j] - x, zs[j] - z);
        d[j] + (dx * dx + dz * dz).sqrt()
    };
    let (mut px, mut pz) = (xs[i], zs[i]);
    if i > 0 && i + 1 < n {
        let (a, b, c) = (val(i - 1), val(i), val(i + 1));
        let curv = a - 2.0 * b + c;
        if curv > 0.0 {
            let t = (0.5 * (a - c) / curv).clamp(-0.5, 0.5);
            let j = if t >= 0.0 { i + 1 } else { i - 1 };
            px += t.abs() * (xs[j] - xs[i]);
            pz += t.abs() * (zs[j] - zs[i]);
        }
    }
    let (dx, dz) = (x - px, z - pz);
    let r = dx.hypot(dz);
    if r > 0.0 {
        (v, dx / r, dz / r)
    } else {
        (v, 0.0, 1.0)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::das::{Apodization, Interpolation};

    fn c5(fnumber: f64, rx_angle: f64) -> DasParams {
        DasParams {
            fc: 3.57e6,
            c: 1540.0,
            fs: 4.0 * 3.57e6,
            t0: 0.0,
            pitch: 0.508e-3,
            n_elements: 128,
            radius: Some(49.57e-3),
            fnumber,
            rx_angle,
            interpolation: Interpolation::Linear,
            apodization: Apodization::Boxcar,
        }
    }

    /// The bisection picks exactly the elements the per-element test picks, on a grid of pixels
    /// in front of a C5-2v-like array (including pixels shallower than the arc's middle, beside
    /// it, where some elements look at them from below the chord level), for several f-numbers
    /// and receive angles; the selected run is never empty in front of the middle elements.
    #[test]
    fn aperture_bisection_equals_brute_force() {
        let mut checked = 0;
        for (f, rx) in [(1.5, 0.0), (0.3, 0.0), (1.0, 0.3), (1.5, -0.3), (4.0, 0.0), (0.5, 1.2), (0.8, -1.2)] {
            let p = c5(f, rx);
            let cv = Convex::of(&p).unwrap();
            for ix in 0..121 {
                for iz in 0..61 {
                    let (x, z) = (-0.06 + 1e-3 * ix as f64, 0.1e-3 + 1.5e-3 * iz as f64);
                    if x * x + (z + cv.h) * (z + cv.h) <= cv.radius * cv.radius {
                        continue;
                    }
                    let (lo, hi) = aperture(&cv, x, z, rx);
                    let brute: Vec<usize> = (0..p.n_elements)
                        .filter(|&e| {
                            let o = rx_offset(&cv, e, x, z, rx);
                            o <= cv.alpha && o >= -cv.alpha
                        })
                        .collect();
                    let want = match (brute.first(), brute.last()) {
                        (Some(&a), Some(&b)) => {
                            assert_eq!(b - a + 1, brute.len(), "non-contiguous at ({x}, {z}), F {f}, rx {rx}");
                            (a, b + 1)
                        }
                        _ => (lo, lo),
                    };
                    assert_eq!((lo, hi), want, "pixel ({x}, {z}), F {f}, rx {rx}");
                    checked += 1;
                }
            }
        }
        assert!(checked > 40_000, "{checked}");
    }

    /// `direction` is PyMUST's asin(dx/d) in front of the element (dz ≥ 0), and continues it
    /// beyond ±90° behind.
    #[test]
    fn direction_continues_asin() {
        for (dx, dz) in [(1.0, 2.0), (-1.0, 2.0), (0.0, 1.0), (3.0, 0.0), (-3.0, 0.0), (0.3, 0.4)] {
            let d = f64::hypot(dx, dz);
            assert!((direction(dx, dz) - (dx / d).asin()).abs() < 1e-12, "({dx}, {dz})");
        }
        for (dx, dz) in [(1.0, -2.0), (-1.0, -2.0), (0.5, -1e-9)] {
            let d = f64::hypot(dx, dz);
            let want = std::f64::consts::PI.copysign(dx) - (dx / d).asin();
            assert!((direction(dx, dz) - want).abs() < 1e-7, "({dx}, {dz})");
        }
    }

    #[test]
    fn max_elements_is_the_largest_that_fits() {
        for (pitch, r) in [(0.508e-3, 49.57e-3), (0.3e-3, 5e-3), (1e-3, 0.6e-3), (2e-3, 0.9e-3)] {
            let n = max_elements(pitch, r);
            let a = (pitch / 2.0 / r).asin();
            if pitch <= 2.0 * r {
                assert!((n as f64 - 1.0) * a < PI / 2.0 && n as f64 * a >= PI / 2.0, "{pitch} {r}: {n}");
            } else {
                assert_eq!(n, 1);
            }
        }
    }

    /// All elements firing together (zero delays): d_TX is the distance to the arc. Computed
    /// here independently: `|p − C| − R` where the direction of p from the centre C = (0, −h)
    /// lies within the arc's span, else the distance to the nearer end element; cross-checked by
    /// 200 001 samples of the arc. PyMUST's rule takes the minimum over 4·N points along the arc
    /// (spacing s ≈ arc length/(4N − 1) ≈ pitch/4), so it exceeds the true distance r by at most
    /// `ρ·(s/2)²/(2·R·r)` (ρ = |p − C|: a point t along the arc from the foot of p is
    /// `√(r² + ρ t²/R) ≈ r + ρ t²/(2 R r)` away): 0.1–0.3 µm, below 1e-3·λ (0.43 µm), for pixels
    /// 15 mm or more from the face; we require the measured excess within that bound and ≥ −1e-10 m
    /// (the spline through the elements lies on the arc to ~1e-11 m).
    #[test]
    fn zero_delay_transmit_distance_is_the_distance_to_the_arc() {
        use crate::das::TxModel;
        let p = c5(1.5, 0.0);
        let lambda = p.c / p.fc;
        let cv = Convex::of(&p).unwrap();
        let (r, h, n) = (cv.radius, cv.h, p.n_elements);
        let (t0, t1) = (cv.the[0], cv.the[n - 1]);
        let arc_len = r * (t1 - t0);
        let s = arc_len / (4 * n - 1) as f64;
        let dense: Vec<(f64, f64)> = (0..=200_000)
            .map(|i| {
                let t = t0 + (t1 - t0) * i as f64 / 200_000.0;
                (r * t.sin(), r * t.cos() - h)
            })
            .collect();
        for (name, tx) in [
            ("zero delays", TxWave::Delays { delays: vec![0.0; n] }),
            ("diverging from C", TxWave::Diverging { x0: 0.0, z0: -h }),
        ] {
            let model = TxModel::new(&tx, &p);
            let (mut worst, mut checked): (f64, usize) = (0.0, 0);
            for ix in 0..41 {
                for iz in 0..31 {
                    let (x, z) = (-0.06 + 3e-3 * ix as f64, 1e-3 + 3e-3 * iz as f64);
                    let rho = x.hypot(z + h);
                    let beta = x.atan2(z + h);
                    let want = if beta >= t0 && beta <= t1 {
                        rho - r
                    } else {
                        let end = |e: usize| (x - cv.xe[e]).hypot(z - cv.ze[e]);
                        end(0).min(end(n - 1))
                    };
                    if want < 15e-3 {
                        continue;
                    }
                    let sampled = dense.iter().map(|(a, b)| (x - a).hypot(z - b)).fold(f64::INFINITY, f64::min);
                    assert!((sampled - want).abs() < 1e-9, "independent distances at ({x}, {z}): {sampled} vs {want}");
                    let (got, gx, gz) = model.eval(x, z);
                    let bound = rho * (s / 2.0).powi(2) / (2.0 * r * want);
                    let err = got - want;
                    assert!(err >= -1e-10 && err <= bound + 1e-10, "({x}, {z}): excess {err:e} m, bound {bound:e} m");
                    assert!(bound < 1e-3 * lambda);
                    // gradient: the unit vector from the nearest arc point
                    assert!((gx.hypot(gz) - 1.0).abs() < 1e-12);
                    if beta >= t0 && beta <= t1 {
                        assert!((gx - beta.sin()).abs() < 2e-3 && (gz - beta.cos()).abs() < 2e-3, "({x}, {z})");
                    }
                    worst = worst.max(err.abs());
                    checked += 1;
                }
            }
            assert!(checked > 500, "{checked}");
            println!("{name}: worst |d_TX − distance to the arc| = {worst:.3e} m = {:.2e} λ", worst / lambda);
        }
    }

    /// MUST's convex plane-wave delays: c·delay_e = max_k d_k − d_e, d_e = R − R cos(θ_e − tilt)
    /// the distance from element e to the line tangent to the circle at angle tilt; the linear
    /// law `x_e sin θ/c − min` without a radius.
    #[test]
    fn plane_wave_delays_follow_the_tangent_line() {
        let p = c5(0.0, 0.0);
        let (r, n) = (p.radius.unwrap(), p.n_elements);
        let (_, _, the) = p.element_positions();
        for tilt in [0.0, 0.2, -0.35] {
            let got = TxWave::PlaneWave { tilt }.delays(&p).unwrap();
            let d: Vec<f64> = the.iter().map(|t| r - r * (t - tilt).cos()).collect();
            let dmax = d.iter().copied().fold(0.0, f64::max);
            for e in 0..n {
                assert!((got[e] * p.c - (dmax - d[e])).abs() < 1e-12, "tilt {tilt}, element {e}");
            }
        }
        let lin = DasParams { radius: None, ..c5(0.0, 0.0) };
        let got = TxWave::PlaneWave { tilt: 0.1 }.delays(&lin).unwrap();
        let m = (0..n).map(|e| lin.element_x(e) * 0.1f64.sin() / lin.c).fold(f64::INFINITY, f64::min);
        assert!((0..n).all(|e| got[e] == lin.element_x(e) * 0.1f64.sin() / lin.c - m));
    }
}
