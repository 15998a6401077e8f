//! Digital Butterworth low-pass design and zero-phase forward–backward filtering, identical in
//! method to `scipy.signal.butter(N, Wn)` and `scipy.signal.filtfilt(b, a, x)` with its
//! defaults (`padtype = "odd"`, `padlen = 3·max(len(a), len(b))`, steady-state initial
//! conditions from `lfilter_zi`), which PyMUST's `rf2iq` uses (pymust-notes §6).
//!
//! Design: analog prototype poles `p_k = −exp(iπ m/(2N))`, `m = −N+1, −N+3, …, N−1`, frequency
//! pre-warping `ω = 4·tan(π Wn/2)` (scipy's `fs = 2` convention), bilinear transform
//! `z = (4 + p)/(4 − p)` with N zeros at −1, gain `k = ω^N / Π(4 − p)`, then polynomial expansion.
//! All arithmetic is f64.

use num_complex::Complex;

/// Numerator `b` and denominator `a` (a\[0\] = 1) of an order-`order` digital Butterworth
/// low-pass with normalised cut-off `wn` (1 = Nyquist), as `scipy.signal.butter(order, wn)`.
/// The caller validates `0 < wn < 1` and `order ≥ 1`.
pub fn butter_lowpass(order: usize, wn: f64) -> (Vec<f64>, Vec<f64>) {
    let n = order as f64;
    let warped = 4.0 * (std::f64::consts::PI * wn / 2.0).tan();
    let mut poles = Vec::with_capacity(order);
    let mut m = -(order as i64) + 1;
    while m < order as i64 {
        let ang = std::f64::consts::PI * m as f64 / (2.0 * n);
        poles.push(-Complex::new(ang.cos(), ang.sin()) * warped);
        m += 2;
    }
    let fs2 = Complex::new(4.0, 0.0);
    let mut k = Complex::new(warped.powi(order as i32), 0.0);
    let mut zpoles = Vec::with_capacity(order);
    for p in &poles {
        k /= fs2 - p;
        zpoles.push((fs2 + p) / (fs2 - p));
    }
    let zeros = vec![Complex::new(-1.0, 0.0); order];
    let b: Vec<f64> = poly(&zeros).iter().map(|c| (c * k.re).re).collect();
    let a: Vec<f64> = poly(&zpoles).iter().map(|c| c.re).collect();
    (b, a)
}

/// Coefficients of Π (x − r_i), highest power first (numpy `poly`).
fn poly(roots: &[Complex<f64>]) -> Vec<Complex<f64>> {
    let mut c = vec![Complex::new(1.0, 0.0)];
    for r in roots {
        let mut next = vec![Complex::new(0.0, 0.0); c.len() + 1];
        for (i, ci) in c.iter().enumerate() {
            next[i] += ci;
            next[i + 1] -= ci * r;
        }
        c = next;
    }
    c
}

/// Steady-state initial state of the transposed direct form II filter for a unit step input
/// (`scipy.signal.lfilter_zi`): solves `(I − Aᵀ) zi = b[1:] − a[1:]·b[0]` with `A` the
/// companion matrix of `a`. `a[0]` must be 1 and `b.len() == a.len()`.
pub fn lfilter_zi(b: &[f64], a: &[f64]) -> Vec<f64> {
    let n = a.len() - 1;
    if n == 0 {
        return Vec::new();
    }
    // I − companion(a)ᵀ: column 0 gets +a[i+1]; the super-diagonal gets −1.
    let mut m = vec![vec![0.0f64; n]; n];
    for (i, row) in m.iter_mut().enumerate() {
        row[i] += 1.0;
        row[0] += a[i + 1];
        if i + 1 < n {
            row[i + 1] -= 1.0;
        }
    }
    let mut rhs: Vec<f64> = (0..n).map(|i| b[i + 1] - a[i + 1] * b[0]).collect();
    // Gaussian elimination with partial pivoting (n ≤ 11).
    for col in 0..n {
        let piv = (col..n).fold(col, |best, r| if m[r][col].abs() > m[best][col].abs() { r } else { best });
        m.swap(col, piv);
        rhs.swap(col, piv);
        let d = m[col][col];
        for r in col + 1..n {
            let f = m[r][col] / d;
            if f != 0.0 {
                let pivot_row = m[col].clone();
                for (x, p) in m[r][col..].iter_mut().zip(&pivot_row[col..]) {
                    *x -= f * p;
                }
                rhs[r] -= f * rhs[col];
            }
        }
    }
    let mut x = vec![0.0; n];
    for r in (0..n).rev() {
        let s: f64 = (r + 1..n).map(|c| m[r][c] * x[c]).sum();
        x[r] = (rhs[r] - s) / m[r][r];
    }
    x
}

/// In-place transposed direct form II filtering of complex data with real coefficients
/// (`scipy.signal.lfilter(b, a, x, zi = zi·x0)`), `a[0] = 1`, in the sample order `order` gives
/// (e.g. `0..x.len()`). `z` is the state (len = order).
pub fn lfilter_in_place<I: Iterator<Item = usize>>(
    b: &[f64],
    a: &[f64],
    x: &mut [Complex<f64>],
    z: &mut [Complex<f64>],
    order: I,
) {
    let n = z.len();
    for idx in order {
        let xn = x[idx];
        let yn = z[0] + xn * b[0];
        for k in 0..n - 1 {
            z[k] = z[k + 1] + xn * b[k + 1] - yn * a[k + 1];
        }
        z[n - 1] = xn * b[n] - yn * a[n];
        x[idx] = yn;
    }
}

/// Zero-phase filter (`scipy.signal.filtfilt(b, a, x)` defaults) of the `len − 2·padlen`
/// central samples of `ext`, which the caller filled with the signal at
/// `ext[padlen..len − padlen]`. On return the filtered signal is at the same place.
/// The caller guarantees `signal length > padlen` and `b.len() == a.len() == zi.len() + 1`.
pub fn filtfilt_in_place(b: &[f64], a: &[f64], zi: &[f64], padlen: usize, ext: &mut [Complex<f64>]) {
    let len = ext.len();
    let n = len - 2 * padlen;
    // odd extension: 2·x[0] − x[padlen..0], 2·x[n−1] − x[n−2 ..= n−1−padlen]
    let (x0, xl) = (ext[padlen], ext[padlen + n - 1]);
    for i in 0..padlen {
        ext[padlen - 1 - i] = x0 * 2.0 - ext[padlen + 1 + i];
        ext[padlen + n + i] = xl * 2.0 - ext[padlen + n - 2 - i];
    }
    let order = zi.len();
    let mut z = [Complex::new(0.0, 0.0); 16];
    let z = &mut z[..order];
    let e0 = ext[0];
    for (s, zi) in z.iter_mut().zip(zi) {
        *s = e0 * *zi;
    }
    lfilter_in_place(b, a, ext, z, 0..len);
    let y0 = ext[len - 1];
    for (s, zi) in z.iter_mut().zip(zi) {
        *s = y0 * *zi;
    }
    lfilter_in_place(b, a, ext, z, (0..len).rev());
}

#[cfg(test)]
mod tests {
    use super::*;

    /// scipy.signal.butter(5, 0.1875) (scipy 1.17.1), printed with repr().
    #[test]
    fn butter5_matches_scipy() {
        let (b, a) = butter_lowpass(5, 0.1875);
        let b_ref = [
            0.000973102374817448,
            0.00486551187408724,
            0.00973102374817448,
            0.00973102374817448,
            0.00486551187408724,
            0.000973102374817448,
        ];
        let a_ref = [
            1.0,
            -3.1010653378832784,
            4.086924478138159,
            -2.8013719587413277,
            0.9901751548991403,
            -0.14352306041853485,
        ];
        for (x, y) in b.iter().zip(b_ref).chain(a.iter().zip(a_ref)) {
            assert!((x - y).abs() <= 1e-13 * y.abs().max(1.0), "{x} vs {y}");
        }
        // DC gain 1
        let g = b.iter().sum::<f64>() / a.iter().sum::<f64>();
        assert!((g - 1.0).abs() < 1e-12, "{g}");
    }

    /// The zi of lfilter_zi makes a constant input produce a constant output from sample 0.
    #[test]
    fn lfilter_zi_is_steady_state() {
        let (b, a) = butter_lowpass(5, 0.3);
        let zi = lfilter_zi(&b, &a);
        let mut x = vec![Complex::new(2.5, -1.0); 50];
        let mut z: Vec<Complex<f64>> = zi.iter().map(|v| Complex::new(2.5, -1.0) * v).collect();
        lfilter_in_place(&b, &a, &mut x, &mut z, 0..50);
        for v in &x {
            assert!((v - Complex::new(2.5, -1.0)).norm() < 1e-12, "{v}");
        }
    }
}
