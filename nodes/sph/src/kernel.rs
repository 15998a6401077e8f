//! 2D smoothing kernels W(r, h) with compact support, normalised so that ∫ W dA = 1 (paper eq 2).
//!
//! * [`KernelKind::QuarticSpline`]: the M5 quartic B-spline that Shahriari & Garcia (2018, §2.1,
//!   after eq 3) use, support 2.5 h, σ₂D = 96 / (1199 π).
//! * [`KernelKind::WendlandC2`]: Wendland (1995) C² kernel, support 2 h, σ₂D = 7 / (4 π).
//! * [`KernelKind::CubicSpline`]: Monaghan's M4 cubic B-spline, support 2 h, σ₂D = 10 / (7 π).
//!
//! `W(r, h) = σ₂D / h² · f(r / h)`, `∂W/∂r = σ₂D / h³ · f'(r / h)`.

use serde::{Deserialize, Serialize};

use crate::Real;

/// Which kernel function to use.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum KernelKind {
    /// M5 quartic B-spline, support 2.5 h (the paper's choice).
    #[default]
    QuarticSpline,
    /// Wendland C2, support 2 h.
    WendlandC2,
    /// M4 cubic B-spline, support 2 h.
    CubicSpline,
}

impl KernelKind {
    /// Support radius in units of h (κ if κh is read as the support radius).
    pub fn support_factor(self) -> Real {
        match self {
            KernelKind::QuarticSpline => 2.5,
            KernelKind::WendlandC2 | KernelKind::CubicSpline => 2.0,
        }
    }

    /// 2D normalisation constant σ₂D.
    pub fn sigma_2d(self) -> Real {
        use std::f64::consts::PI;
        match self {
            KernelKind::QuarticSpline => 96.0 / (1199.0 * PI),
            KernelKind::WendlandC2 => 7.0 / (4.0 * PI),
            KernelKind::CubicSpline => 10.0 / (7.0 * PI),
        }
    }

    /// Dimensionless shape f(q) and its derivative f'(q).
    #[inline(always)]
    pub fn shape(self, q: Real) -> (Real, Real) {
        match self {
            KernelKind::QuarticSpline => {
                let (mut f, mut df) = (0.0, 0.0);
                let a = 2.5 - q;
                if a > 0.0 {
                    f += a * a * a * a;
                    df -= 4.0 * a * a * a;
                    let b = 1.5 - q;
                    if b > 0.0 {
                        f -= 5.0 * b * b * b * b;
                        df += 20.0 * b * b * b;
                        let c = 0.5 - q;
                        if c > 0.0 {
                            f += 10.0 * c * c * c * c;
                            df -= 40.0 * c * c * c;
                        }
                    }
                }
                (f, df)
            }
            KernelKind::WendlandC2 => {
                if q < 2.0 {
                    let a = 1.0 - 0.5 * q;
                    let a3 = a * a * a;
                    (a3 * a * (2.0 * q + 1.0), -5.0 * q * a3)
                } else {
                    (0.0, 0.0)
                }
            }
            KernelKind::CubicSpline => {
                if q < 1.0 {
                    (1.0 - 1.5 * q * q + 0.75 * q * q * q, -3.0 * q + 2.25 * q * q)
                } else if q < 2.0 {
                    let a = 2.0 - q;
                    (0.25 * a * a * a, -0.75 * a * a)
                } else {
                    (0.0, 0.0)
                }
            }
        }
    }
}

/// A kernel with its smoothing length fixed: evaluates W and ∂W/∂r in SI units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Kernel {
    /// Kernel function.
    pub kind: KernelKind,
    /// Smoothing length h \[m\].
    pub h: Real,
    inv_h: Real,
    norm_w: Real,
    norm_dw: Real,
    support: Real,
}

impl Kernel {
    /// Kernel `kind` with smoothing length `h` \[m\] (h > 0, finite).
    pub fn new(kind: KernelKind, h: Real) -> Self {
        let sigma = kind.sigma_2d();
        Kernel {
            kind,
            h,
            inv_h: 1.0 / h,
            norm_w: sigma / (h * h),
            norm_dw: sigma / (h * h * h),
            support: kind.support_factor() * h,
        }
    }

    /// Support radius κh \[m\]: W = 0 for r ≥ support.
    #[inline]
    pub fn support_radius(&self) -> Real {
        self.support
    }

    /// W(r) \[1/m²\].
    #[inline(always)]
    pub fn w(&self, r: Real) -> Real {
        self.kind.shape(r * self.inv_h).0 * self.norm_w
    }

    /// (W(r), ∂W/∂r(r)) \[1/m², 1/m³\].
    #[inline(always)]
    pub fn w_dw(&self, r: Real) -> (Real, Real) {
        let (f, df) = self.kind.shape(r * self.inv_h);
        (f * self.norm_w, df * self.norm_dw)
    }

    /// Second moment M₂ = ∫ r² W dA \[m²\] of the normalised kernel (composite Simpson, 4096
    /// panels per unit of q; the kernels are piecewise polynomials with breaks on that grid, so the
    /// result is exact to rounding).
    pub fn second_moment(&self) -> Real {
        dimensionless_moment(self.kind, 3) * self.kind.sigma_2d() * 2.0 * std::f64::consts::PI * self.h * self.h
    }
}

/// ∫₀^{support} q^p f(q) dq by composite Simpson with breakpoints at multiples of 1/2.
fn dimensionless_moment(kind: KernelKind, p: i32) -> Real {
    let panels_per_unit = 4096usize;
    let n = (kind.support_factor() * panels_per_unit as Real).round() as usize; // even for 2.0 and 2.5
    let dq = kind.support_factor() / n as Real;
    let g = |q: Real| q.powi(p) * kind.shape(q).0;
    let mut s = g(0.0) + g(kind.support_factor());
    for i in 1..n {
        let q = i as Real * dq;
        s += if i % 2 == 1 { 4.0 * g(q) } else { 2.0 * g(q) };
    }
    s * dq / 3.0
}

#[cfg(test)]
mod tests {
    use super::*;

    const KINDS: [KernelKind; 3] = [KernelKind::QuarticSpline, KernelKind::WendlandC2, KernelKind::CubicSpline];

    #[test]
    fn continuous_normalisation_is_one() {
        for kind in KINDS {
            let m0 = dimensionless_moment(kind, 1) * kind.sigma_2d() * 2.0 * std::f64::consts::PI;
            assert!((m0 - 1.0).abs() < 1e-12, "{kind:?}: {m0}");
        }
    }

    #[test]
    fn second_moments_match_research_table() {
        // sph-validation.md V0.2 (scipy quad): M2/h^2 = 0.79939, 0.55556 (= 5/9), 0.63265.
        for (kind, m2) in [
            (KernelKind::QuarticSpline, 0.79939),
            (KernelKind::WendlandC2, 5.0 / 9.0),
            (KernelKind::CubicSpline, 0.63265),
        ] {
            let got = Kernel::new(kind, 1.0).second_moment();
            assert!((got - m2).abs() < 1e-5, "{kind:?}: {got}");
        }
    }

    #[test]
    fn derivative_matches_finite_difference_and_vanishes_at_support() {
        for kind in KINDS {
            let k = Kernel::new(kind, 1.3e-4);
            for i in 1..60 {
                let r = i as Real / 60.0 * k.support_radius();
                let e = 1e-9 * k.h;
                let fd = (k.w(r + e) - k.w(r - e)) / (2.0 * e);
                let (_, dw) = k.w_dw(r);
                assert!((fd - dw).abs() <= 1e-5 * k.w_dw(0.4 * k.h).1.abs(), "{kind:?} r={r}: {fd} vs {dw}");
            }
            assert_eq!(k.w(k.support_radius()), 0.0);
            assert_eq!(k.w_dw(k.support_radius()).1, 0.0);
            assert_eq!(k.w_dw(0.0).1, 0.0);
        }
    }
}
