//! Average leverage, the bounds on S that it implies, and the bounded 1-D minimiser used for the
//! generalised cross-validation (GCV) search (Garcia 2010 CSDA, §3.2 and eq. 12).

use num_complex::Complex;

/// Average leverage bounds (MATLAB `hMin`, `hMax`): very weak smoothing has h → 1, very strong
/// smoothing h → 0.
pub const H_MIN: f64 = 1e-6;
/// See [`H_MIN`].
pub const H_MAX: f64 = 0.99;

/// Average leverage `h(s) = (1/π) ∫₀^π dθ / (1 + s (2 − 2cos θ)^m)` of the unweighted 1-D smoother
/// of order `m` on a long grid (the continuum limit of `(1/n) Σ_k Γ_k`).
///
/// Closed forms (Garcia 2010, eq. 12 for m = 2): `1/sqrt(1+4s)` (m = 1),
/// `sqrt(1+sqrt(1+16s)) / (sqrt2 · sqrt(1+16s))` (m = 2); any other order uses
/// [`leverage_1d_any_order`].
pub fn leverage_1d(s: f64, m: u32) -> f64 {
    match m {
        1 => 1.0 / (1.0 + 4.0 * s).sqrt(),
        2 => {
            let t = (1.0 + 16.0 * s).sqrt();
            (1.0 + t).sqrt() / std::f64::consts::SQRT_2 / t
        }
        _ => leverage_1d_any_order(s, m),
    }
}

/// The integral of [`leverage_1d`] for any order `m ≥ 1`: with `2 − 2cos θ = 4 sin² φ` and the
/// partial fractions `1/(1+x^m) = (1/m) Σ_j 1/(1 − x/r_j)` over the roots `r_j = e^{iπ(2j+1)/m}` of
/// `x^m = −1`, each term integrates to `(1 − 4 s^{1/m}/r_j)^{-1/2}` (principal branch; the argument
/// never crosses the negative real axis), so `h = (1/m) Σ_j Re (1 − 4 s^{1/m}/r_j)^{-1/2}`.
pub fn leverage_1d_any_order(s: f64, m: u32) -> f64 {
    let b = 4.0 * s.powf(1.0 / f64::from(m));
    let sum: f64 = (0..m)
        .map(|j| {
            let r = Complex::from_polar(1.0, std::f64::consts::PI * f64::from(2 * j + 1) / f64::from(m));
            (Complex::new(1.0, 0.0) - b / r).sqrt().inv().re
        })
        .sum();
    sum / f64::from(m)
}

/// Average leverage of the N-D smoother: the product of the 1-D leverages along the non-singleton
/// axes, with S scaled by each axis' normalised spacing `dI` (`S/dI^(2m)`, as Λ ∝ dI⁻² is raised to m).
/// This is MATLAB's `h` in the robust step.
pub fn leverage(s: f64, m: u32, spacing_of_non_singleton_axes: &[f64]) -> f64 {
    spacing_of_non_singleton_axes.iter().map(|d| leverage_1d(s / d.powi(2 * m as i32), m)).product()
}

/// The S giving an N-D average leverage `h` on a grid with `n_dims` non-singleton axes (equal
/// spacing): solves `leverage_1d(s, m) = h^(1/N)`. Closed forms for m = 1, 2 are MATLAB's
/// expressions; m = 3 is solved by bisection on log10 s (to full precision).
pub fn s_for_leverage(h: f64, m: u32, n_dims: u32) -> f64 {
    let e = 2.0 / f64::from(n_dims.max(1));
    match m {
        1 => (1.0 / h.powf(e) - 1.0) / 4.0,
        2 => {
            let q = h.powf(e);
            let t = (1.0 + (1.0 + 8.0 * q).sqrt()) / 4.0 / q;
            (t * t - 1.0) / 16.0
        }
        _ => {
            let target = h.powf(e / 2.0);
            let (mut lo, mut hi) = (-30.0_f64, 60.0_f64);
            for _ in 0..200 {
                let mid = 0.5 * (lo + hi);
                if leverage_1d(10f64.powf(mid), m) > target {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            10f64.powf(0.5 * (lo + hi))
        }
    }
}

/// Result of [`fminbnd`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Minimum {
    /// Best abscissa found.
    pub x: f64,
    /// Function value there.
    pub f: f64,
    /// Number of function evaluations.
    pub evaluations: u32,
}

/// Minimises `f` on `[a, b]` by Brent's golden-section search with parabolic interpolation
/// (Forsythe, Malcolm & Moler 1977 `fmin`), stopping when the bracket is within `tol_x` (absolute)
/// of the best point. This is the algorithm of MATLAB `fminbnd` and, line for line, of SciPy's
/// `optimize.fminbound` (`_minimize_scalar_bounded`, 500 evaluations at most), which PyMUST calls.
pub fn fminbnd(mut f: impl FnMut(f64) -> f64, a: f64, b: f64, tol_x: f64) -> Minimum {
    const MAX_FUN: u32 = 500;
    let sqrt_eps = 2.2e-16_f64.sqrt();
    let golden_mean = 0.5 * (3.0 - 5.0_f64.sqrt());
    let sign = |v: f64| -> f64 {
        if v > 0.0 {
            1.0
        } else if v < 0.0 {
            -1.0
        } else {
            0.0
        }
    };
    let (mut a, mut b) = (a, b);
    let mut fulc = a + golden_mean * (b - a);
    let (mut nfc, mut xf) = (fulc, fulc);
    let (mut rat, mut e) = (0.0_f64, 0.0_f64);
    let mut fx = f(xf);
    let mut num = 1;
    let (mut ffulc, mut fnfc) = (fx, fx);
    let mut xm = 0.5 * (a + b);
    let mut tol1 = sqrt_eps * xf.abs() + tol_x / 3.0;
    let mut tol2 = 2.0 * tol1;
    while (xf - xm).abs() > tol2 - 0.5 * (b - a) {
        let mut golden = true;
        if e.abs() > tol1 {
            golden = false;
            let mut r = (xf - nfc) * (fx - ffulc);
            let mut q = (xf - fulc) * (fx - fnfc);
            let mut p = (xf - fulc) * q - (xf - nfc) * r;
            q = 2.0 * (q - r);
            if q > 0.0 {
                p = -p;
            }
            q = q.abs();
            r = e;
            e = rat;
            if p.abs() < (0.5 * q * r).abs() && p > q * (a - xf) && p < q * (b - xf) {
                rat = p / q;
                let x = xf + rat;
                if (x - a) < tol2 || (b - x) < tol2 {
                    let si = sign(xm - xf) + if xm - xf == 0.0 { 1.0 } else { 0.0 };
                    rat = tol1 * si;
                }
            } else {
                golden = true;
            }
        }
        if golden {
            e = if xf >= xm { a - xf } else { b - xf };
            rat = golden_mean * e;
        }
        let si = sign(rat) + if rat == 0.0 { 1.0 } else { 0.0 };
        let x = xf + si * rat.abs().max(tol1);
        let fu = f(x);
        num += 1;
        if fu <= fx {
            if x >= xf {
                a = xf;
            } else {
                b = xf;
            }
            (fulc, ffulc) = (nfc, fnfc);
            (nfc, fnfc) = (xf, fx);
            (xf, fx) = (x, fu);
        } else {
            if x < xf {
                a = x;
            } else {
                b = x;
            }
            if fu <= fnfc || nfc == xf {
                (fulc, ffulc) = (nfc, fnfc);
                (nfc, fnfc) = (x, fu);
            } else if fu <= ffulc || fulc == xf || fulc == nfc {
                (fulc, ffulc) = (x, fu);
            }
        }
        xm = 0.5 * (a + b);
        tol1 = sqrt_eps * xf.abs() + tol_x / 3.0;
        tol2 = 2.0 * tol1;
        if num >= MAX_FUN {
            break;
        }
    }
    Minimum { x: xf, f: fx, evaluations: num }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// (1/n) Σ_k 1/(1 + s (2 − 2cos(πk/n))^m) for a long grid: converges to the integral as O(1/n).
    fn discrete_leverage(s: f64, m: u32, n: usize) -> f64 {
        (0..n)
            .map(|k| {
                let l = 2.0 - 2.0 * (std::f64::consts::PI * (k as f64 + 0.5) / n as f64).cos();
                1.0 / (1.0 + s * l.powi(m as i32))
            })
            .sum::<f64>()
            / n as f64
    }

    #[test]
    fn leverage_closed_forms_match_quadrature_and_general_formula() {
        for m in 1..=3 {
            for s in [1e-3, 0.1, 1.0, 10.0, 1e3, 1e6] {
                let h = leverage_1d(s, m);
                // Midpoint rule with 200 000 nodes: error < 1e-8 for these smooth integrands.
                let q = discrete_leverage(s, m, 200_000);
                assert!((h - q).abs() < 1e-8 * q.max(1e-3), "m={m} s={s}: closed {h} vs quadrature {q}");
                let g = leverage_1d_any_order(s, m);
                assert!((h - g).abs() < 1e-13, "m={m} s={s}: closed {h} vs general {g}");
            }
        }
    }

    #[test]
    fn s_bounds_invert_the_leverage() {
        for m in 1..=3 {
            for n_dims in 1..=3 {
                for h in [H_MIN, 1e-3, 0.5, H_MAX] {
                    let s = s_for_leverage(h, m, n_dims);
                    let back = leverage_1d(s, m).powi(n_dims as i32);
                    assert!((back / h - 1.0).abs() < 1e-9, "m={m} N={n_dims} h={h}: s={s} gives h={back}");
                }
            }
        }
        // MATLAB's m = 2 expression evaluated independently (Python, float64) for a 2-D grid.
        assert_eq!(s_for_leverage(H_MAX, 2, 2), 0.0008436392381327013);
        assert_eq!(s_for_leverage(H_MIN, 2, 2), 15625062499.874998);
    }

    #[test]
    fn fminbnd_finds_a_parabola_minimum_within_tolerance() {
        let mut calls = 0;
        let m = fminbnd(
            |x| {
                calls += 1;
                (x - 1.234).powi(2) + 3.0
            },
            -3.0,
            10.0,
            0.1,
        );
        assert!((m.x - 1.234).abs() < 0.1, "x = {}", m.x);
        assert_eq!(m.evaluations, calls);
        // A monotone function ends at the bound side within the tolerance.
        let m = fminbnd(|x| x, -3.0, 10.0, 0.1);
        assert!(m.x < -3.0 + 0.1, "x = {}", m.x);
    }
}
