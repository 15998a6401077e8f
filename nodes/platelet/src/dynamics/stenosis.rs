//! Stenosed channel (paper 2, section 5.2: a 2 mm × 12 mm channel with a 25 % narrowing) as a
//! [`CarrierFlow`], from the lubrication (slowly varying channel) approximation.
//!
//! **Geometry.** Walls y_lo(x) = δ(x) and y_hi(x) = H − δ(x), a symmetric cosine bump
//! (Young's cosine stenosis) on both walls centred at x_c with length L_s:
//!
//! δ(x) = δ_m (1 + cos(2π (x − x_c)/L_s)) / 2 for |x − x_c| < L_s/2, else 0,
//!
//! with δ_m = f H / 2 for a narrowing f of the height (f = 0.25: the throat gap is 0.75 H). The
//! local gap is h(x) = H − 2δ(x); outside the bump the channel is straight and the flow is
//! [`Channel`]'s. δ and δ' are continuous; δ'' jumps by δ_m (2π/L_s)²/2 at the ends of the bump, so ω
//! and the strain jump there (by a few per cent of the wall shear rate for the defaults).
//!
//! **Flow.** A stream function ψ(x, y) = Q F(η), with η = (y − δ(x))/h(x) ∈ [0, 1] and
//! F(η) = 3η² − 2η³, Q = v_in H / 3 (per unit depth) the flow rate of the paper's inflow profile
//! v_x = 2 v_in s (1 − s). Then, with G(η) = F'(η) = 6η(1 − η):
//!
//! - u = ∂ψ/∂y = (Q/h) G(η): at every x a parabola in the local gap carrying the flow rate Q
//!   (the paper's profile where h = H);
//! - v = −∂ψ/∂x = (Q/h) δ' K(η) with K(η) = G(η)(1 − 2η) (using h' = −2δ', ∂η/∂x = −δ'(1 − 2η)/h);
//!
//! so ∂u/∂x + ∂v/∂y = 0 exactly (up to rounding), u = v = 0 on both walls (no slip; the velocity
//! is tangent to the walls everywhere), and the derivatives are exact:
//!
//! - ∂u/∂x = (Q δ'/h²) (2G − G'(1 − 2η)) = −∂v/∂y, ∂u/∂y = Q G'/h² with G' = 6(1 − 2η),
//! - ∂v/∂x = Q [δ'' K / h + 2δ'² K / h² − δ'² (1 − 2η) K' / h²], K' = G'(1 − 2η) − 2G,
//!
//! giving ω = ½(∂v/∂x − ∂u/∂y) and E = (∂u/∂x, ½(∂u/∂y + ∂v/∂x), ∂v/∂y).
//!
//! **Validity.** This is the leading order of lubrication theory, not a Stokes or Navier–Stokes
//! solution: its relative error is O(ε²) + O(ε Re) with ε = H/L_s the aspect ratio of the narrowing
//! and Re = ρ v_in H / μ the channel Reynolds number. For the paper's blood (ρ = 1060 kg/m³,
//! μ = 3 mPa·s) and v_in = 5 mm/s, Re ≈ 3.5 (≈ 1.8 on the axis speed), so it needs L_s ≫ H; the
//! default L_s = 6 mm = 3 H (ε ≈ 0.33, largest wall slope π δ_m / L_s ≈ 0.13) is a compromise
//! between the paper's 12 mm channel and the approximation. No separation or recirculation is
//! represented (none is expected at this Re and slope). Kinematically the field is exact:
//! divergence-free, no-slip, constant flow rate, which is what the particle dynamics relies on.
//!
//! **Walls.** [`CarrierFlow::local_walls`] reports y_lo(x), y_hi(x) and their slopes; the dynamics
//! reflects a centre that crossed a wall about it (see `collide::walls_local`).

use super::flow::{check, CarrierFlow, Channel, FlowError, FlowSample, LocalWalls};
use std::f64::consts::PI;

/// Stenosed channel (module doc). Defaults: paper 2 section 5.2 — H = 2 mm, 12 mm long, 25 %
/// narrowing centred at 6 mm over 6 mm, v_in = 5 mm/s, no ramp.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Stenosis {
    /// Channel height H \[m\] outside the narrowing (walls at y = 0 and y = H). Default 2e-3.
    pub height: f64,
    /// Channel length \[m\]: the fluid domain x ∈ [0, length] used for seeding (the flow itself is
    /// defined for every x, straight outside the bump). Default 12e-3.
    pub length: f64,
    /// Inflow speed v_in \[m/s\] of the paper's profile (flow rate v_in H / 3). Default 5e-3.
    pub v_in: f64,
    /// Ramp time \[s\]: v_in scaled by min(t / ramp, 1); `None` (default) for a steady flow.
    pub ramp: Option<f64>,
    /// Narrowing f: fraction of the height closed at the throat (both walls together), in
    /// [0, 0.9]. Default 0.25.
    pub narrowing: f64,
    /// Centre x_c of the narrowing \[m\]. Default 6e-3.
    pub centre: f64,
    /// Length L_s of the narrowing \[m\] (validity needs L_s ≫ H). Default 6e-3.
    pub bump_length: f64,
}

impl Default for Stenosis {
    fn default() -> Self {
        Stenosis {
            height: 2e-3,
            length: 12e-3,
            v_in: 5e-3,
            ramp: None,
            narrowing: 0.25,
            centre: 6e-3,
            bump_length: 6e-3,
        }
    }
}

impl Stenosis {
    /// Height and length in (0, 1 m], v_in finite, ramp > 0, narrowing in [0, 0.9], the centre
    /// finite, bump length in (0, 1 m].
    pub fn validate(&self) -> Result<(), FlowError> {
        self.as_channel().validate()?;
        check("length", self.length, self.length > 0.0 && self.length <= 1.0, "0 < length <= 1 m")?;
        check("narrowing", self.narrowing, (0.0..=0.9).contains(&self.narrowing), "0 <= narrowing <= 0.9")?;
        check("centre", self.centre, true, "finite")?;
        check(
            "bump_length",
            self.bump_length,
            self.bump_length > 0.0 && self.bump_length <= 1.0,
            "0 < bump_length <= 1 m",
        )?;
        Ok(())
    }

    /// The straight channel with the same height, inflow and ramp.
    pub fn as_channel(&self) -> Channel {
        Channel { height: self.height, v_in: self.v_in, ramp: self.ramp }
    }

    /// δ(x), δ'(x), δ''(x) of the lower wall \[m, 1, 1/m\].
    pub fn bump(&self, x: f64) -> [f64; 3] {
        let d = x - self.centre;
        if d.abs() >= 0.5 * self.bump_length || self.narrowing == 0.0 {
            return [0.0; 3];
        }
        let dm = 0.5 * self.narrowing * self.height;
        let k = 2.0 * PI / self.bump_length;
        let (s, c) = (k * d).sin_cos();
        [0.5 * dm * (1.0 + c), -0.5 * dm * k * s, -0.5 * dm * k * k * c]
    }

    /// Local gap h(x) = H − 2δ(x) \[m\].
    pub fn gap(&self, x: f64) -> f64 {
        self.height - 2.0 * self.bump(x)[0]
    }

    /// Flow rate per unit depth at time t \[m²/s\]: v_in H / 3 × ramp factor.
    pub fn flow_rate(&self, t: f64) -> f64 {
        self.v_in * self.as_channel().ramp_factor(t) * self.height / 3.0
    }

    /// Whether (x, y) is in the fluid: δ(x) ≤ y ≤ H − δ(x) (any x).
    pub fn contains(&self, x: [f64; 2]) -> bool {
        let d = self.bump(x[0])[0];
        x[1] >= d && x[1] <= self.height - d
    }
}

impl CarrierFlow for Stenosis {
    fn sample(&self, x: [f64; 2], t: f64) -> FlowSample {
        let [d, d1, d2] = self.bump(x[0]);
        let h = self.height - 2.0 * d;
        let eta = (x[1] - d) / h;
        if !(0.0..=1.0).contains(&eta) {
            return FlowSample::default();
        }
        let q = self.flow_rate(t);
        let a = 1.0 - 2.0 * eta;
        let g = 6.0 * eta * (1.0 - eta);
        let g1 = 6.0 * a;
        let k = g * a;
        let k1 = g1 * a - 2.0 * g;
        let h2 = h * h;
        let u = q / h * g;
        let v = q / h * d1 * k;
        let dudx = q * d1 / h2 * (2.0 * g - g1 * a);
        let dudy = q * g1 / h2;
        let dvdx = q * (d2 * k / h + 2.0 * d1 * d1 * k / h2 - d1 * d1 * a * k1 / h2);
        let dvdy = q * d1 / h2 * k1;
        FlowSample { v: [u, v], omega: 0.5 * (dvdx - dudy), strain: [dudx, 0.5 * (dudy + dvdx), dvdy] }
    }
    fn walls(&self) -> Option<[f64; 2]> {
        Some([0.0, self.height])
    }
    fn local_walls(&self, x: f64) -> Option<LocalWalls> {
        let [d, d1, _] = self.bump(x);
        Some(LocalWalls { lo: d, hi: self.height - d, slope_lo: d1, slope_hi: -d1 })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn random_points(s: &Stenosis, n: usize, seed: u64) -> Vec<[f64; 2]> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                // concentrated on the bump, where everything varies
                let x = rng.gen_range(s.centre - 0.6 * s.bump_length..s.centre + 0.6 * s.bump_length);
                let w = s.local_walls(x).unwrap_or_default();
                [x, rng.gen_range(w.lo..w.hi)]
            })
            .collect()
    }

    /// Central differences of the velocity with step e; truncation O(e² |∇³v|), rounding
    /// O(ε_mach |v| / e).
    fn fd(s: &Stenosis, p: [f64; 2], e: f64) -> [[f64; 2]; 2] {
        let v = |dx: f64, dy: f64| s.velocity([p[0] + dx, p[1] + dy], 0.0);
        let (xp, xm, yp, ym) = (v(e, 0.0), v(-e, 0.0), v(0.0, e), v(0.0, -e));
        [
            [(xp[0] - xm[0]) / (2.0 * e), (yp[0] - ym[0]) / (2.0 * e)],
            [(xp[1] - xm[1]) / (2.0 * e), (yp[1] - ym[1]) / (2.0 * e)],
        ]
    }

    #[test]
    fn divergence_free_to_rounding_on_random_points() {
        let s = Stenosis::default();
        // scale of the velocity gradients: wall shear rate at the throat, 6 Q / h² ≈ 13 1/s
        let scale = 6.0 * s.flow_rate(0.0) / (0.75 * s.height).powi(2);
        for p in random_points(&s, 2000, 7) {
            let f = s.sample(p, 0.0);
            // exact derivatives: to rounding
            assert!((f.strain[0] + f.strain[2]).abs() <= 1e-13 * scale, "div {} at {p:?}", f.strain[0] + f.strain[2]);
        }
    }

    #[test]
    fn derivatives_match_finite_differences() {
        let s = Stenosis::default();
        let scale = 6.0 * s.flow_rate(0.0) / (0.75 * s.height).powi(2);
        let e = 1e-7; // 0.1 µm: truncation ~1e-14 · scale relative, rounding ~1e-9 · scale
        for p in random_points(&s, 500, 11) {
            // keep the stencil inside the fluid and off the ends of the bump (δ'' jumps there)
            let w = s.local_walls(p[0]).unwrap_or_default();
            if p[1] - w.lo < 2.0 * e
                || w.hi - p[1] < 2.0 * e
                || ((p[0] - s.centre).abs() - 0.5 * s.bump_length).abs() < 2.0 * e
            {
                continue;
            }
            let g = fd(&s, p, e);
            let f = s.sample(p, 0.0);
            let exact = [[f.strain[0], f.strain[1] - f.omega], [f.strain[1] + f.omega, f.strain[2]]];
            for i in 0..2 {
                for j in 0..2 {
                    assert!(
                        (g[i][j] - exact[i][j]).abs() < 1e-6 * scale,
                        "∂v{i}/∂x{j}: fd {} exact {} at {p:?}",
                        g[i][j],
                        exact[i][j]
                    );
                }
            }
            // and the finite-difference divergence vanishes to its own error
            assert!((g[0][0] + g[1][1]).abs() < 1e-6 * scale);
        }
    }

    #[test]
    fn flow_rate_is_constant_along_the_channel() {
        let s = Stenosis::default();
        let q = s.flow_rate(0.0);
        // Gauss–Legendre, 3 points per panel on 8 panels: exact for the cubic-in-y profile
        let gl = [(-0.774_596_669_241_483_4, 5.0 / 9.0), (0.0, 8.0 / 9.0), (0.774_596_669_241_483_4, 5.0 / 9.0)];
        for k in 0..=120 {
            let x = k as f64 * s.length / 120.0;
            let w = s.local_walls(x).unwrap_or_default();
            let (n, hw) = (8, (w.hi - w.lo) / 16.0);
            let mut sum = 0.0;
            for j in 0..n {
                let c = w.lo + (2 * j + 1) as f64 * hw;
                for (z, wt) in gl {
                    sum += wt * hw * s.velocity([x, c + z * hw], 0.0)[0];
                }
            }
            assert!((sum - q).abs() < 1e-13 * q, "Q({x}) = {sum}, expected {q}");
        }
        // the throat gap is 75 % of H
        assert!((s.gap(s.centre) - 0.75 * s.height).abs() < 1e-18);
    }

    #[test]
    fn no_slip_on_the_walls_and_velocity_tangent_near_them() {
        let s = Stenosis::default();
        for k in 0..=100 {
            let x = 3e-3 + k as f64 * 6e-5;
            let w = s.local_walls(x).unwrap_or_default();
            for (y, slope) in [(w.lo, w.slope_lo), (w.hi, w.slope_hi)] {
                let v = s.velocity([x, y], 0.0);
                // (η = 1 on the upper wall up to rounding: |v| ~ ε_mach v_in)
                let tol = 1e-13 * s.v_in;
                assert!(v[0].abs() < tol && v[1].abs() < tol, "v = {v:?} on the wall at x = {x}");
                // 1 µm inside: the velocity follows the wall, v/u → slope
                let yi = if y == w.lo { y + 1e-6 } else { y - 1e-6 };
                let vi = s.velocity([x, yi], 0.0);
                assert!((vi[1] / vi[0] - slope).abs() < 2e-3 * slope.abs().max(1e-3), "{vi:?} slope {slope}");
            }
        }
    }

    #[test]
    fn reduces_to_the_straight_channel_without_narrowing() {
        let s = Stenosis { narrowing: 0.0, ramp: Some(0.01), ..Default::default() };
        let c = s.as_channel();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for _ in 0..500 {
            let p = [rng.gen_range(0.0..s.length), rng.gen_range(0.0..s.height)];
            let t = rng.gen_range(0.0..0.02);
            let (a, b) = (s.sample(p, t), c.sample(p, t));
            let close = |x: f64, y: f64| (x - y).abs() <= 1e-15 * (1.0 + y.abs());
            assert!(close(a.v[0], b.v[0]) && a.v[1] == 0.0, "{a:?} {b:?}");
            assert!(close(a.omega, b.omega) && close(a.strain[1], b.strain[1]), "{a:?} {b:?}");
            assert!(a.strain[0] == 0.0 && a.strain[2] == 0.0);
        }
        // with the narrowing, far from the bump it is the channel too
        let s = Stenosis::default();
        let f = s.sample([1e-3, 0.7e-3], 0.0);
        let g = s.as_channel().sample([1e-3, 0.7e-3], 0.0);
        assert!((f.v[0] - g.v[0]).abs() < 1e-18 && f.v[1] == 0.0);
    }

    #[test]
    fn faster_and_steeper_at_the_throat() {
        let s = Stenosis::default();
        let axis = |x: f64| s.velocity([x, 0.5 * s.height], 0.0)[0];
        // peak speed scales as 1/h: 3 Q / (2 h)
        assert!((axis(s.centre) / axis(1e-3) - 1.0 / 0.75).abs() < 1e-12);
        // symmetric about the axis: v_y antisymmetric, v_x symmetric
        let (a, b) = (s.velocity([5e-3, 0.6e-3], 0.0), s.velocity([5e-3, s.height - 0.6e-3], 0.0));
        assert!((a[0] - b[0]).abs() < 1e-18 && (a[1] + b[1]).abs() < 1e-18);
        assert!(a[1] > 0.0, "converging part: the lower half moves up");
    }

    #[test]
    fn validation_names_the_field() {
        let bad = Stenosis { narrowing: 0.95, ..Default::default() };
        let e = bad.validate().unwrap_err().to_string();
        assert!(e.contains("`narrowing`") && e.contains("0.9"), "{e}");
        let bad = Stenosis { bump_length: 0.0, ..Default::default() };
        assert!(bad.validate().unwrap_err().to_string().contains("`bump_length`"));
        assert!(Stenosis::default().validate().is_ok());
    }
}
