//! Closed-form resistance of spheroids in unbounded Stokes flow (Oberbeck 1876 for translation,
//! Edwardes 1892 / Jeffery 1922 for rotation; collected by Perrin 1934, Happel & Brenner 1965
//! §5.11, and in the form used here by Kim & Karrila 1991, *Microhydrodynamics*, Table 3.4), and
//! Jeffery's shape factor.
//!
//! Notation: `a` the semi-axis along the symmetry axis, `b` the equatorial semi-axis, μ the
//! viscosity. Resistances are per unit velocity \[kg/s\] or per unit angular velocity \[N·m·s\].
//! With the major semi-axis A = max(a, b) and the eccentricity e = √(1 − min²/max²),
//! Kim & Karrila write F = 6πμA X_A U (axial), 6πμA Y_A U (transverse), T = 8πμA³ Y_C Ω (about an
//! equatorial axis):
//!
//! - prolate (a > b), L = ln((1 + e)/(1 − e)): X_A = (8/3) e³ / (−2e + (1 + e²) L),
//!   Y_A = (16/3) e³ / (2e + (3e² − 1) L), Y_C = (4/3) e³ (2 − e²) / (−2e + (1 + e²) L);
//! - oblate (a < b), C = arcsin e, S = e √(1 − e²): X_A = (4/3) e³ / ((2e² − 1) C + S),
//!   Y_A = (8/3) e³ / ((2e² + 1) C − S), Y_C = (2/3) e³ (2 − e²) / (S − (1 − 2e²) C).
//!
//! Limits (tested): the sphere, 6πμaU and 8πμa³Ω; the disc (e → 1), 16μbU broadside,
//! 32/3 μbU edgewise, 32/3 μb³Ω edgewise rotation. Near e = 0 the formulas cancel
//! catastrophically, so below e = 1e-3 the sphere values (exact to O(e²) ≈ 1e-6) are returned.

use std::f64::consts::PI;

/// Below this eccentricity the sphere value is returned (module doc).
const E_SPHERE: f64 = 1e-3;

/// Resistances of a spheroid (module doc).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpheroidResistance {
    /// Force per unit velocity along the symmetry axis \[kg/s\].
    pub axial: f64,
    /// Force per unit velocity across the symmetry axis \[kg/s\].
    pub transverse: f64,
    /// Torque per unit angular velocity about an equatorial axis \[N·m·s\].
    pub rotation_equatorial: f64,
}

/// Resistance of the spheroid with semi-axis `a` along its symmetry axis and equatorial semi-axis
/// `b` (both > 0) in fluid of viscosity `mu` (module doc for the formulas and their source).
pub fn spheroid_resistance(mu: f64, a: f64, b: f64) -> SpheroidResistance {
    let big = a.max(b);
    // ratio = √(1 − e²) directly, so that thin bodies keep their precision
    let ratio = a.min(b) / big;
    let e = (1.0 - ratio * ratio).max(0.0).sqrt();
    let (xa, ya, yc) = if e < E_SPHERE {
        (1.0, 1.0, 1.0)
    } else if a > b {
        // (1 + e)/(1 − e) = (1 + e)²/(1 − e²)
        let l = 2.0 * ((1.0 + e) / ratio).ln();
        let e3 = e * e * e;
        let d = -2.0 * e + (1.0 + e * e) * l;
        (8.0 / 3.0 * e3 / d, 16.0 / 3.0 * e3 / (2.0 * e + (3.0 * e * e - 1.0) * l), 4.0 / 3.0 * e3 * (2.0 - e * e) / d)
    } else {
        let c = e.asin();
        let s = e * ratio;
        let e3 = e * e * e;
        (
            4.0 / 3.0 * e3 / ((2.0 * e * e - 1.0) * c + s),
            8.0 / 3.0 * e3 / ((2.0 * e * e + 1.0) * c - s),
            2.0 / 3.0 * e3 * (2.0 - e * e) / (s - (1.0 - 2.0 * e * e) * c),
        )
    };
    SpheroidResistance {
        axial: 6.0 * PI * mu * big * xa,
        transverse: 6.0 * PI * mu * big * ya,
        rotation_equatorial: 8.0 * PI * mu * big.powi(3) * yc,
    }
}

/// Jeffery's (1922) shape factor B = (a² − b²)/(a² + b²) of an ellipsoid with semi-axes a (along
/// the body's x axis) and b (along y) in the plane of rotation: Ω = ω + B E'_xy, the ratio c_s/c_r
/// of [`crate::coefficients`].
pub fn jeffery_factor(a: f64, b: f64) -> f64 {
    (a * a - b * b) / (a * a + b * b)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rel(a: f64, b: f64) -> f64 {
        (a - b).abs() / b.abs()
    }

    #[test]
    fn sphere_limits() {
        // just above the cut-off the formulas themselves must approach the sphere (O(e²) = 1e-4
        // plus the cancellation error of ~1e-16/e³ = 1e-10)
        for (a, b) in [(1.0, (1.0f64 - 1e-4).sqrt()), ((1.0f64 - 1e-4).sqrt(), 1.0)] {
            let r = spheroid_resistance(1.0, a, b);
            let big = a.max(b);
            assert!(rel(r.axial, 6.0 * PI * big) < 2e-4, "{r:?}");
            assert!(rel(r.transverse, 6.0 * PI * big) < 2e-4, "{r:?}");
            assert!(rel(r.rotation_equatorial, 8.0 * PI * big.powi(3)) < 3e-4, "{r:?}");
        }
        let r = spheroid_resistance(2.0, 1.5, 1.5);
        assert_eq!(r.axial, 6.0 * PI * 2.0 * 1.5);
        assert_eq!(r.rotation_equatorial, 8.0 * PI * 2.0 * 1.5f64.powi(3));
    }

    #[test]
    fn disc_limits() {
        // a/b = 1e-6: corrections O(a/b) from the finite thickness
        let r = spheroid_resistance(1.0, 1e-6, 1.0);
        assert!(rel(r.axial, 16.0) < 1e-5, "{r:?}");
        assert!(rel(r.transverse, 32.0 / 3.0) < 1e-5, "{r:?}");
        assert!(rel(r.rotation_equatorial, 32.0 / 3.0) < 1e-5, "{r:?}");
    }

    #[test]
    fn slender_prolate_matches_slender_body_theory() {
        // slender-body theory, exact for the spheroid up to O((b/a)² ln): 4πμa/(ln(2a/b) − ½)
        // axial, 8πμa/(ln(2a/b) + ½) transverse, 8πμa³/(3(ln(2a/b) − ½)) rotation (Batchelor 1970)
        let (a, b): (f64, f64) = (1.0, 1e-8);
        let l = (2.0 * a / b).ln();
        let r = spheroid_resistance(1.0, a, b);
        assert!(rel(r.axial, 4.0 * PI / (l - 0.5)) < 1e-9, "{r:?}");
        assert!(rel(r.transverse, 8.0 * PI / (l + 0.5)) < 1e-9, "{r:?}");
        assert!(rel(r.rotation_equatorial, 8.0 * PI / (3.0 * (l - 0.5))) < 1e-9, "{r:?}");
    }

    #[test]
    fn jeffery_limits() {
        assert_eq!(jeffery_factor(1.0, 1.0), 0.0);
        assert!((jeffery_factor(3.0, 1.0) - 0.8).abs() < 1e-15);
        assert!((jeffery_factor(1.0, 3.0) + 0.8).abs() < 1e-15);
    }
}
