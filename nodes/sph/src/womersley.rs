//! Womersley's pulsatile flow in a 2D plane channel |y| ≤ a (sph-validation.md §b), the "fully
//! developed" profile the reservoirs impose (paper §2.2) and the analytic reference of the
//! pulsatile validation case.
//!
//! With λ_k = √(i k ω / ν) = (1 + i) √(k ω / (2ν)) and the Womersley number α = a √(ω/ν):
//! * forcing per unit mass g(t) = K₀ + Σ Re{K_k e^{ikωt}} (a body force, or −∂p/∂x / ρ):
//!   u(y, t) = K₀ (a² − y²)/(2ν) + Σ Re{ K_k/(ikω) [1 − cosh(λ_k y)/cosh(λ_k a)] e^{ikωt} };
//! * prescribed cross-section mean velocity ū(t) = U₀ + Σ Re{U_k e^{ikωt}}:
//!   u(y, t) = 3/2 U₀ (1 − y²/a²) + Σ Re{ U_k [1 − cosh(λ_k y)/cosh(λ_k a)] / [1 − tanh(λ_k a)/(λ_k a)] e^{ikωt} }.
//!
//! The ratio cosh(λy)/cosh(λa) is evaluated as e^{λ(|y|−a)} (1 + e^{−2λ|y|}) / (1 + e^{−2λa}), which
//! does not overflow for any harmonic.

use num_complex::Complex64;

use crate::waveform::Waveform;
use crate::Real;

fn lambda(omega: Real, nu: Real) -> Complex64 {
    let s = (omega / (2.0 * nu)).sqrt();
    Complex64::new(s, s)
}

/// 1 − cosh(λy)/cosh(λa), overflow-free.
fn shape(lam: Complex64, y: Real, a: Real) -> Complex64 {
    let ya = y.abs().min(a);
    let num = (lam * (ya - a)).exp() * (1.0 + (-2.0 * lam * ya).exp());
    let den = 1.0 + (-2.0 * lam * a).exp();
    1.0 - num / den
}

/// 1 − tanh(λa)/(λa): the cross-section mean of [`shape`].
fn mean_shape(lam: Complex64, a: Real) -> Complex64 {
    let e = (-2.0 * lam * a).exp();
    let tanh = (1.0 - e) / (1.0 + e);
    1.0 - tanh / (lam * a)
}

/// Womersley number α = a √(ω/ν).
pub fn womersley_number(a: Real, omega: Real, nu: Real) -> Real {
    a * (omega / nu).sqrt()
}

/// Periodic velocity u(y, t) of the channel |y| ≤ a driven by the forcing per unit mass `forcing`
/// \[m/s²\] (body force along the channel).
pub fn forced_velocity(forcing: &Waveform, y: Real, t: Real, a: Real, nu: Real) -> Real {
    let mut u = forcing.mean * (a * a - y * y) / (2.0 * nu);
    let w = forcing.omega();
    for k in 1..=forcing.harmonics() {
        let kw = k as Real * w;
        let (re, im) = forcing.complex_amplitude(k);
        let amp = Complex64::new(re, im) / Complex64::new(0.0, kw);
        let v = amp * shape(lambda(kw, nu), y, a) * Complex64::from_polar(1.0, kw * t);
        u += v.re;
    }
    u
}

/// Cross-section mean velocity of [`forced_velocity`] at time t.
pub fn forced_mean_velocity(forcing: &Waveform, t: Real, a: Real, nu: Real) -> Real {
    let mut u = forcing.mean * a * a / (3.0 * nu);
    let w = forcing.omega();
    for k in 1..=forcing.harmonics() {
        let kw = k as Real * w;
        let (re, im) = forcing.complex_amplitude(k);
        let amp = Complex64::new(re, im) / Complex64::new(0.0, kw);
        u += (amp * mean_shape(lambda(kw, nu), a) * Complex64::from_polar(1.0, kw * t)).re;
    }
    u
}

/// Fully developed velocity u(y, t) of the channel |y| ≤ a whose cross-section mean velocity is
/// `mean_velocity(t)` \[m/s\].
pub fn profile_velocity(mean_velocity: &Waveform, y: Real, t: Real, a: Real, nu: Real) -> Real {
    let ya = y.abs().min(a);
    let mut u = 1.5 * mean_velocity.mean * (1.0 - (ya / a) * (ya / a));
    let w = mean_velocity.omega();
    for k in 1..=mean_velocity.harmonics() {
        let kw = k as Real * w;
        let lam = lambda(kw, nu);
        let (re, im) = mean_velocity.complex_amplitude(k);
        let c = Complex64::new(re, im) * shape(lam, ya, a) / mean_shape(lam, a);
        u += (c * Complex64::from_polar(1.0, kw * t)).re;
    }
    u
}

/// The profile of [`profile_velocity`] tabulated on `n` points across the channel, for fast
/// evaluation at many lateral positions and times: per harmonic the complex shape is stored once,
/// so one time costs N·n complex products.
#[derive(Clone, Debug)]
pub struct ProfileTable {
    half_width: Real,
    omega: Real,
    steady: Vec<Real>,
    modes: Vec<Vec<Complex64>>,
    values: Vec<Real>,
    time: Real,
}

impl ProfileTable {
    /// Tabulates the Womersley profile of `mean_velocity` for half-width `a` and viscosity ν on
    /// `n ≥ 3` equally spaced points y_j = −a + 2a j/(n−1). With `quasi_steady`, every harmonic uses
    /// the parabola (the α → 0 limit).
    pub fn new(mean_velocity: &Waveform, a: Real, nu: Real, n: usize, quasi_steady: bool) -> Self {
        let n = n.max(3);
        let ys: Vec<Real> = (0..n).map(|j| -a + 2.0 * a * j as Real / (n - 1) as Real).collect();
        let para: Vec<Real> = ys.iter().map(|y| 1.5 * (1.0 - (y / a) * (y / a))).collect();
        let steady: Vec<Real> = para.iter().map(|p| p * mean_velocity.mean).collect();
        let w = mean_velocity.omega();
        let modes = (1..=mean_velocity.harmonics())
            .map(|k| {
                let kw = k as Real * w;
                let (re, im) = mean_velocity.complex_amplitude(k);
                let amp = Complex64::new(re, im);
                ys.iter()
                    .zip(&para)
                    .map(|(&y, &p)| {
                        if quasi_steady || nu <= 0.0 {
                            amp * p
                        } else {
                            let lam = lambda(kw, nu);
                            amp * shape(lam, y, a) / mean_shape(lam, a)
                        }
                    })
                    .collect()
            })
            .collect();
        let mut t = ProfileTable { half_width: a, omega: w, steady, modes, values: vec![0.0; n], time: Real::NAN };
        t.set_time(0.0);
        t
    }

    /// Evaluates the table at time t (cached: repeated calls at the same t are free).
    pub fn set_time(&mut self, t: Real) {
        if t == self.time {
            return;
        }
        self.values.copy_from_slice(&self.steady);
        for (k, mode) in self.modes.iter().enumerate() {
            let e = Complex64::from_polar(1.0, (k + 1) as Real * self.omega * t);
            for (v, c) in self.values.iter_mut().zip(mode) {
                *v += c.re * e.re - c.im * e.im;
            }
        }
        self.time = t;
    }

    /// Velocity at lateral position y (linear interpolation; 0 outside |y| ≤ a) at the last time set.
    pub fn at(&self, y: Real) -> Real {
        let n = self.values.len();
        let q = (y + self.half_width) / (2.0 * self.half_width) * (n - 1) as Real;
        if !(0.0..=(n - 1) as Real).contains(&q) {
            return 0.0;
        }
        let j = (q.floor() as usize).min(n - 2);
        let f = q - j as Real;
        self.values[j] * (1.0 - f) + self.values[j + 1] * f
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::waveform::WaveformSpec;
    use std::f64::consts::PI;

    /// sph-validation.md §b: α = 5.6 ⇒ centreline amplitude 1.026 K/ω, lag 91.6° behind the forcing.
    #[test]
    fn centreline_amplitude_and_lag_match_the_research_table() {
        let (a, nu) = (4e-3, 3.77e-6);
        let omega = (5.6 / a) * (5.6 / a) * nu;
        let k = 1.0;
        let f = WaveformSpec::Cosine { amplitude: k, period: 2.0 * PI / omega, phase: 0.0, offset: 0.0 }
            .build()
            .expect("ok");
        // u(0, t) = A cos(ωt − φ): sample one period and project.
        let n = 720;
        let (mut c, mut s) = (0.0, 0.0);
        for j in 0..n {
            let t = j as Real / n as Real * f.period;
            let u = forced_velocity(&f, 0.0, t, a, nu);
            c += u * (omega * t).cos();
            s += u * (omega * t).sin();
        }
        let (c, s) = (2.0 * c / n as Real, 2.0 * s / n as Real);
        let amp = (c * c + s * s).sqrt() / (k / omega);
        let lag = s.atan2(c).to_degrees();
        assert!((amp - 1.026).abs() < 1.5e-3, "{amp}");
        assert!((lag - 91.6).abs() < 0.1, "{lag}");
    }

    #[test]
    fn limits_and_no_slip() {
        let (a, nu) = (4e-3, 4e-6);
        // α → 0: quasi-steady Poiseuille in phase with the forcing.
        let slow = WaveformSpec::Cosine { amplitude: 1e-3, period: 1e4, phase: 0.0, offset: 0.0 }.build().expect("ok");
        let u = forced_velocity(&slow, 0.0, 0.0, a, nu);
        assert!((u / (1e-3 * a * a / (2.0 * nu)) - 1.0).abs() < 1e-4, "{u}");
        // mean-velocity profile: zero at the wall, cross-section mean equals the waveform.
        let w = WaveformSpec::Carotid { peak: 0.39, mean: 0.1875, period: 0.83 }.build().expect("ok");
        for t in [0.0, 0.1, 0.3, 0.6] {
            assert!(profile_velocity(&w, a, t, a, nu).abs() < 1e-12);
            let n = 4000;
            let m: Real = (0..n)
                .map(|j| profile_velocity(&w, -a + 2.0 * a * (j as Real + 0.5) / n as Real, t, a, nu))
                .sum::<Real>()
                / n as Real;
            assert!((m - w.value(t)).abs() < 2e-6 * 0.39, "t {t}: {m} vs {}", w.value(t));
        }
        // forced mean velocity equals the integral of the forced profile
        let f = WaveformSpec::Cosine { amplitude: 3.0, period: 0.83, phase: 0.2, offset: 0.5 }.build().expect("ok");
        let n = 4000;
        let m: Real = (0..n)
            .map(|j| forced_velocity(&f, -a + 2.0 * a * (j as Real + 0.5) / n as Real, 0.37, a, nu))
            .sum::<Real>()
            / n as Real;
        let exact = forced_mean_velocity(&f, 0.37, a, nu);
        assert!((m - exact).abs() < 1e-5 * exact.abs().max(1.0), "{m} vs {exact}");
    }

    #[test]
    fn table_matches_direct_evaluation() {
        let (a, nu) = (2.775e-3, 4e-6);
        let w = WaveformSpec::Carotid { peak: 0.39, mean: 0.1875, period: 0.83 }.build().expect("ok").scaled(0.78);
        let mut tab = ProfileTable::new(&w, a, nu, 257, false);
        for t in [0.05, 0.13, 0.5] {
            tab.set_time(t);
            for j in 0..41 {
                let y = -a + 2.0 * a * j as Real / 40.0;
                let d = profile_velocity(&w, y, t, a, nu);
                assert!((tab.at(y) - d).abs() < 2e-3 * 0.39, "t {t} y {y}: {} vs {d}", tab.at(y));
            }
        }
        assert_eq!(tab.at(2.0 * a), 0.0);
    }
}
