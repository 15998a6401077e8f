//! Series solutions of Morris, Fox & Zhu (1997) for start-up flows between plates z = 0 and z = L
//! (sph-validation.md §a).

use crate::Real;

/// Body-force-driven Poiseuille flow from rest:
/// u(z,t) = F/(2ν) z (L − z) − Σₙ 4 F L²/(ν π³ (2n+1)³) sin(π z (2n+1)/L) exp(−(2n+1)² π² ν t / L²).
pub fn poiseuille(z: Real, t: Real, f: Real, nu: Real, l: Real, terms: usize) -> Real {
    use std::f64::consts::PI;
    let mut u = f / (2.0 * nu) * z * (l - z);
    for n in 0..terms {
        let k = (2 * n + 1) as Real;
        u -= 4.0 * f * l * l / (nu * PI.powi(3) * k.powi(3))
            * (PI * z * k / l).sin()
            * (-k * k * PI * PI * nu * t / (l * l)).exp();
    }
    u
}

/// Couette flow, upper plate moved impulsively at v₀:
/// u(z,t) = v₀ z/L + Σₙ≥1 2v₀/(nπ) (−1)ⁿ sin(nπz/L) exp(−ν n² π² t / L²).
pub fn couette(z: Real, t: Real, v0: Real, nu: Real, l: Real, terms: usize) -> Real {
    use std::f64::consts::PI;
    let mut u = v0 * z / l;
    for n in 1..=terms {
        let k = n as Real;
        let sign = if n % 2 == 0 { 1.0 } else { -1.0 };
        u += 2.0 * v0 / (k * PI) * sign * (k * PI * z / l).sin() * (-nu * k * k * PI * PI * t / (l * l)).exp();
    }
    u
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn series_start_at_rest_and_reach_the_steady_profiles() {
        let (f, nu, l) = (2e-4, 1e-6, 1e-3);
        let umax = f * l * l / (8.0 * nu);
        for i in 1..20 {
            let z = i as Real / 20.0 * l;
            assert!(poiseuille(z, 0.0, f, nu, l, 2000).abs() < 1e-6 * umax);
            assert!((poiseuille(z, 50.0, f, nu, l, 200) - f / (2.0 * nu) * z * (l - z)).abs() < 1e-12);
            assert!((couette(z, 50.0, 2.5e-5, nu, l, 200) - 2.5e-5 * z / l).abs() < 1e-15);
        }
        // Morris table value: Poiseuille centreline u/u_max at t = 0.0225 s (ref/poiseuille_morris1997.csv).
        let r = poiseuille(0.5 * l, 0.0225, f, nu, l, 200) / umax;
        assert!(r > 0.0 && r < 1.0);
    }
}
