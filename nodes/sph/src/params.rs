//! Solver parameters (SI units, the paper's symbols) and their validation.

use serde::{Deserialize, Serialize};

use crate::kernel::KernelKind;
use crate::neighbours::Period;
use crate::waveform::WaveformSpec;
use crate::Real;

/// Viscous term of the momentum equation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum ViscousTerm {
    /// Paper eq 12: `C μ/ρ_a Σ (u_b − u_a) m_b/ρ_b W_ab / Σ m_b/ρ_b W_ab` (the self term is in the
    /// denominator, as in eq 3), with the constant C chosen by [`ViscousConstant`].
    #[default]
    MeanValue,
    /// Morris, Fox & Zhu (1997) eq 8: `Σ m_b (μ_a+μ_b)/(ρ_a ρ_b) (r_ab·∇_a W_ab)/(r_ab² + 0.01 h²) (u_a − u_b)`.
    Morris,
}

/// Constant C of the mean-value viscous term (eq 12).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum ViscousConstant {
    /// C = 4 / M₂ with M₂ = ∫ r² W dA of the kernel in use: the kernel-weighted mean satisfies
    /// ⟨u⟩ − u_a = M₂/4 ∇²u + O(h⁴), so the term equals ν∇²u (i.e. κ² = 2 M₂ / h² in eq 12;
    /// κ = 1.264 for the quartic spline).
    SecondMoment,
    /// C = 8 / (κ² h²) with κh the kernel support radius (literal reading of eq 11–12, which holds for
    /// an unweighted disk mean). For the quartic spline this is 3.9× too weak; kept for comparison.
    SupportRadius,
    /// C = 4 / M₂,lattice with M₂,lattice = Σ V r² W / Σ V W the second moment of the kernel sampled
    /// on the square lattice of the particle spacing Δp = √(m/ρ₀) (of the first fluid particle): the
    /// discrete operator is then exact for quadratic fields on that lattice. At h = 1.2 Δp it differs
    /// from `second-moment` by 0.2 %, the resolution-independent floor of the Poiseuille error at
    /// fixed h/Δp (with it Poiseuille converges at second order: E₂ 0.17/0.046/0.012/0.003 % at
    /// 10/20/40/80 across). Default.
    #[default]
    LatticeMoment,
}

/// A time-dependent body force g(t) = `direction` · f(t) per unit mass, added to `body_force`
/// (pulsatile channel flow: the forcing −∂p/∂x / ρ of Womersley's problem).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PulsatileForce {
    /// Direction (not normalised: the components multiply f) \[1\].
    pub direction: [Real; 2],
    /// f(t) \[m/s²\].
    pub waveform: WaveformSpec,
}

/// Time integrator.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Integrator {
    /// The paper's second-order predictor–corrector (Monaghan 1989) with rates evaluated at state n
    /// and at the half step: 2 evaluations per step. Default.
    #[default]
    PredictorCorrector,
    /// The same predictor–corrector with the predictor's rates taken from the previous step's
    /// half-step evaluation (as in SPHysics): 1 evaluation per step, still second order (the
    /// predicted half state is off by O(Δt²) only, so the corrector's rates are off by O(Δt²) and
    /// the update by O(Δt³)). Reservoir particles created by the last step start from zero rates
    /// (their velocity and density are imposed anyway). After a checkpoint resume the first step
    /// evaluates twice, so a resumed run is not bit-identical to an uninterrupted one.
    SingleEvaluation,
}

/// A named scheme: which of the stabilising options beyond the paper are on (the other parameters
/// are independent of it). The sph-flow node's `scheme`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Scheme {
    /// The library defaults: particle shifting A = 2 and δ-SPH δ = 0.1 ([`SphParams::default`]).
    #[default]
    Stabilised,
    /// The paper's scheme as published: no shifting, no δ-SPH ([`SphParams::paper_scheme`]).
    Paper,
}

impl Scheme {
    /// The default parameters with this scheme's options.
    pub fn params(self) -> SphParams {
        match self {
            Scheme::Stabilised => SphParams::default(),
            Scheme::Paper => SphParams::paper_scheme(),
        }
    }

    /// `p` with this scheme's options (`shifting`, `density_diffusion`); the rest unchanged.
    pub fn apply(self, p: SphParams) -> SphParams {
        let s = self.params();
        SphParams { shifting: s.shifting, density_diffusion: s.density_diffusion, ..p }
    }
}

/// Parameters of the weakly compressible SPH solver.
///
/// The defaults are the paper's scheme plus two stabilising options, particle shifting A = 2 and
/// δ-SPH δ = 0.1: the settings that run every validation case (Poiseuille, Couette, Womersley,
/// open channels, Taylor–Green, the lid-driven cavity, the carotid). The paper's plain scheme is
/// [`SphParams::paper_scheme`]. Why, and what was measured: the crate README, "Defaults and the
/// paper's scheme".
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SphParams {
    /// Kernel function. Default: the paper's quartic spline.
    pub kernel: KernelKind,
    /// Smoothing length h \[m\]. Default 0.18e-3 (1.2 × the paper's 0.15 mm lattice).
    pub h: Real,
    /// Reference density ρ₀ \[kg/m³\] (eq 8). Default 1000 (the paper).
    pub rho0: Real,
    /// Numerical sound speed c \[m/s\] (eq 8). Default 4.
    pub c: Real,
    /// Background pressure p_b \[Pa\] added to eq 8: p = c²(ρ − ρ₀) + p_b. Default 0 (the paper).
    pub background_pressure: Real,
    /// Dynamic viscosity μ \[Pa·s\]. Default 4e-3 (blood).
    pub mu: Real,
    /// Viscous term. Default: the paper's mean-value term (eq 12).
    pub viscous_term: ViscousTerm,
    /// Constant of eq 12. Default: the kernel's second moment on the particle lattice (see
    /// [`ViscousConstant`]).
    pub viscous_constant: ViscousConstant,
    /// δ of the δ-SPH density diffusion term (Molteni & Colagrossi 2009) added to eq 7,
    /// δ h c Σ 2(ρ_b − ρ_a) (r_ba·∇_a W_ab)/r² V_b over fluid and reservoir neighbours, in \[0, 1\].
    /// Default 0.1 (the usual value; damps the density noise). The paper has none: 0 in
    /// [`SphParams::paper_scheme`]. Under a body force the density difference is taken relative to
    /// hydrostatic balance ([`crate::wcsph::hydrostatic_density_gradient`]).
    pub density_diffusion: Real,
    /// Coefficient A of particle shifting (Lind et al. 2012, with the diffusion coefficient of Xu et al. 2009 /
    /// Skillen et al. 2013 written D = A h |u|max Δt, |u|max the largest speed in the domain): after every step a fluid particle moves by δr = −D ∇C (capped at 0.1 h), and
    /// its velocity is corrected to first order, u += (δr·∇)u. In \[0, 10\]; default 2 (0 = off: the
    /// paper, [`SphParams::paper_scheme`]). Shifting keeps the particle distribution regular where
    /// the flow compresses or stretches it (stagnation points, vortices, recirculation, the corners
    /// of a lid-driven cavity), at the price of moving particles — the acoustic scatterers — slightly
    /// off their material paths (3–4 % RMS of their displacement in the carotid).
    pub shifting: Real,
    /// ε of Monaghan's (2000) artificial pressure against the tensile instability: in eq 10 the term
    /// (p_a/ρ_a² + p_b/ρ_b²) gets + (R_a + R_b)(W_ab/W(Δp))⁴ with R = ε|p|/ρ² for negative p (0 for
    /// positive), Δp = √(m/ρ₀) the particle spacing. In \[0, 1\]; default 0 (the paper; 0.2 is
    /// Monaghan's value). A force, so particles keep moving with the fluid velocity (unlike shifting).
    pub tensile_correction: Real,
    /// Body force per unit mass (g_x, g_z) \[m/s²\]. Default (0, 0).
    pub body_force: [Real; 2],
    /// Time-dependent body force added to `body_force`. Default none.
    pub body_force_pulsatile: Option<PulsatileForce>,
    /// Periodic boundary along x. Default none.
    pub periodic_x: Option<Period>,
    /// Periodic boundary along z. Default none.
    pub periodic_z: Option<Period>,
    /// Time integrator. Default: the paper's predictor–corrector.
    pub integrator: Integrator,
    /// Courant number C_cfl of dt ≤ C_cfl h / (c + |u|max), in (0, 1\]. Default 0.25.
    pub cfl: Real,
    /// Viscous criterion factor C_ν of dt ≤ C_ν h² / ν, in (0, 0.5\]. Default 0.125.
    pub viscous_dt_factor: Real,
    /// Force criterion factor C_f of dt ≤ C_f √(h / |a|max), in (0, 1\]. Default 0.25.
    pub force_dt_factor: Real,
    /// Upper bound on dt \[s\], > 0. Default 1e-3.
    pub dt_max: Real,
    /// Blow-up if max |ρ/ρ₀ − 1| over fluid particles exceeds this, in (0, 1\]. Default 0.1.
    pub density_error_limit: Real,
    /// Blow-up if the adaptive dt falls below this fraction of the first step's dt, in \[0, 1). Default 1e-3.
    pub dt_collapse_ratio: Real,
    /// Run the per-particle loops on rayon threads (bit-identical results either way). Default true.
    pub parallel: bool,
    /// Evaluate the right-hand sides with the fast evaluator ([`crate::fast`]: cell-sorted scratch
    /// arrays, f32 pair terms in 8 lanes, AVX2 + FMA where available, f64 lane sums; the same
    /// equations as [`crate::wcsph::compute_rates`] to ~1e-6 of the largest rate, bit-identical for
    /// any thread count; ~8× faster, see `PERF.md`). `false` runs the f64 reference
    /// `compute_rates`. Default true.
    pub fast_rhs: bool,
    /// Fast evaluator: visit every pair once and add its terms to both particles (Newton's third
    /// law; conflict-free stripes of cell rows, bit-identical for any thread count) instead of
    /// gathering every particle's neighbours (each pair twice). The two differ by rounding only. The
    /// symmetric loop halves the kernel evaluations but adds a read-modify-write of 7 (14 with the
    /// δ-SPH and shifting sums) accumulators per neighbour; on the machines measured it is not
    /// faster (`PERF.md`), so the default is false.
    pub symmetric_pairs: bool,
}

impl Default for SphParams {
    fn default() -> Self {
        SphParams {
            kernel: KernelKind::QuarticSpline,
            h: 0.18e-3,
            rho0: 1000.0,
            c: 4.0,
            background_pressure: 0.0,
            mu: 4e-3,
            viscous_term: ViscousTerm::MeanValue,
            viscous_constant: ViscousConstant::LatticeMoment,
            density_diffusion: 0.1,
            shifting: 2.0,
            tensile_correction: 0.0,
            body_force: [0.0, 0.0],
            body_force_pulsatile: None,
            periodic_x: None,
            periodic_z: None,
            integrator: Integrator::PredictorCorrector,
            cfl: 0.25,
            viscous_dt_factor: 0.125,
            force_dt_factor: 0.25,
            dt_max: 1e-3,
            density_error_limit: 0.1,
            dt_collapse_ratio: 1e-3,
            parallel: true,
            fast_rhs: true,
            symmetric_pairs: false,
        }
    }
}

/// A parameter outside its allowed range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("parameter `{field}` = {value} is invalid: allowed {allowed}")]
pub struct ParamError {
    /// Field name.
    pub field: &'static str,
    /// Offending value, printed.
    pub value: String,
    /// Allowed range, in words.
    pub allowed: String,
}

fn check(field: &'static str, v: Real, ok: bool, allowed: &'static str) -> Result<(), ParamError> {
    if ok && v.is_finite() {
        Ok(())
    } else {
        Err(ParamError { field, value: v.to_string(), allowed: allowed.to_string() })
    }
}

impl SphParams {
    /// The paper's scheme (Shahriari & Garcia 2018, eq 1–13) as published: the defaults without
    /// the stabilising options, `shifting` = 0 and `density_diffusion` = 0. Stable in the plane
    /// channels (Poiseuille, Couette, Womersley) but not where the flow compresses the particle
    /// lattice: the Taylor–Green vortex decays 3.7× too fast at Re 100 and blows up at Re 1000, the
    /// lid-driven cavity at Re 100 blows up at t ≈ 2 L/U, the carotid clumps at the flow divider
    /// (see the crate README, "Defaults and the paper's scheme").
    pub fn paper_scheme() -> Self {
        SphParams { shifting: 0.0, density_diffusion: 0.0, ..Default::default() }
    }

    /// Checks every field; the error names the first bad field and its allowed range.
    pub fn validate(&self) -> Result<(), ParamError> {
        check("h", self.h, self.h > 0.0, "h > 0 [m]")?;
        check("rho0", self.rho0, self.rho0 > 0.0, "rho0 > 0 [kg/m^3]")?;
        check("c", self.c, self.c > 0.0, "c > 0 [m/s]")?;
        check("background_pressure", self.background_pressure, true, "finite [Pa]")?;
        check("mu", self.mu, self.mu >= 0.0, "mu >= 0 [Pa s]")?;
        let d = self.density_diffusion;
        check("density_diffusion", d, (0.0..=1.0).contains(&d), "0 <= density_diffusion <= 1")?;
        let e = self.tensile_correction;
        check("tensile_correction", e, (0.0..=1.0).contains(&e), "0 <= tensile_correction <= 1")?;
        check("shifting", self.shifting, (0.0..=10.0).contains(&self.shifting), "0 <= shifting <= 10")?;
        check("body_force[0]", self.body_force[0], true, "finite [m/s^2]")?;
        check("body_force[1]", self.body_force[1], true, "finite [m/s^2]")?;
        check("cfl", self.cfl, self.cfl > 0.0 && self.cfl <= 1.0, "0 < cfl <= 1")?;
        let v = self.viscous_dt_factor;
        check("viscous_dt_factor", v, v > 0.0 && v <= 0.5, "0 < viscous_dt_factor <= 0.5")?;
        let f = self.force_dt_factor;
        check("force_dt_factor", f, f > 0.0 && f <= 1.0, "0 < force_dt_factor <= 1")?;
        check("dt_max", self.dt_max, self.dt_max > 0.0, "dt_max > 0 [s]")?;
        let d = self.density_error_limit;
        check("density_error_limit", d, d > 0.0 && d <= 1.0, "0 < density_error_limit <= 1")?;
        let r = self.dt_collapse_ratio;
        check("dt_collapse_ratio", r, (0.0..1.0).contains(&r), "0 <= dt_collapse_ratio < 1")?;
        let min = 3.0 * self.kernel.support_factor() * self.h;
        if let Some(p) = self.periodic_x {
            check("periodic_x.min", p.min, true, "finite [m]")?;
            check("periodic_x.length", p.length, p.length >= min, "length >= 3 kernel support radii [m]")?;
        }
        if let Some(p) = self.periodic_z {
            check("periodic_z.min", p.min, true, "finite [m]")?;
            check("periodic_z.length", p.length, p.length >= min, "length >= 3 kernel support radii [m]")?;
        }
        if let Some(f) = &self.body_force_pulsatile {
            check("body_force_pulsatile.direction[0]", f.direction[0], true, "finite")?;
            check("body_force_pulsatile.direction[1]", f.direction[1], true, "finite")?;
            if let Err(e) = f.waveform.build() {
                return Err(ParamError {
                    field: "body_force_pulsatile.waveform",
                    value: format!("(field `{}`)", e.field),
                    allowed: e.reason,
                });
            }
        }
        Ok(())
    }

    /// Kinematic viscosity ν = μ/ρ₀ \[m²/s\].
    pub fn nu(&self) -> Real {
        self.mu / self.rho0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_validate_and_round_trip_through_toml() {
        let p = SphParams::default();
        p.validate().expect("defaults are valid");
        let s = toml::to_string(&p).expect("serialise");
        let q: SphParams = toml::from_str(&s).expect("parse");
        assert_eq!(p, q);
    }

    #[test]
    fn defaults_are_the_stabilised_scheme_and_the_paper_scheme_differs_only_in_its_options() {
        let d = SphParams::default();
        assert_eq!((d.shifting, d.density_diffusion), (2.0, 0.1));
        let p = SphParams::paper_scheme();
        assert_eq!((p.shifting, p.density_diffusion), (0.0, 0.0));
        assert_eq!(SphParams { shifting: d.shifting, density_diffusion: d.density_diffusion, ..p.clone() }, d);
        assert_eq!(Scheme::Paper.params(), p);
        assert_eq!(Scheme::default().params(), d);
        let c = SphParams { c: 7.0, ..Default::default() };
        assert_eq!(Scheme::Paper.apply(c.clone()), SphParams { c: 7.0, ..SphParams::paper_scheme() });
        assert_eq!(Scheme::Stabilised.apply(Scheme::Paper.apply(c.clone())), c);
        let e = serde_json::from_str::<Scheme>("\"plain\"").expect_err("unknown scheme");
        assert!(e.to_string().contains("expected `stabilised` or `paper`"), "{e}");
    }

    #[test]
    fn unknown_field_is_rejected() {
        let e = toml::from_str::<SphParams>("cfl = 0.2\nsound_speed = 3.0\n").expect_err("unknown field");
        assert!(e.to_string().contains("sound_speed"), "{e}");
    }

    #[test]
    fn errors_name_field_and_range() {
        let p = SphParams { cfl: 1.5, ..Default::default() };
        let e = p.validate().expect_err("cfl out of range");
        assert_eq!(e.field, "cfl");
        assert!(e.to_string().contains("0 < cfl <= 1"), "{e}");
        let p = SphParams { h: Real::NAN, ..Default::default() };
        assert_eq!(p.validate().expect_err("nan h").field, "h");
        let p = SphParams { periodic_x: Some(Period { min: 0.0, length: 1e-4 }), ..Default::default() };
        assert_eq!(p.validate().expect_err("short period").field, "periodic_x.length");
    }
}
