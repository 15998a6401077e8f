//! A platelet suspension ready to run (paper 2, Algorithm 2 with an analytic carrier): a carrier
//! flow, the particles, the dynamics and the coefficient model, built from plain serde parameters
//! (the `[params]` of the `platelets` node deserialise into [`SuspensionParams`]).
//!
//! Seeding: `particles = { count = N }` draws N shapes from [`ShapeSampler`] (eq 7's means and
//! spreads), positions uniform in the fluid (rejection against the local walls for the stenosis)
//! and orientations uniform in [0, 2π), all from one ChaCha8 stream seeded by `seed` (same
//! suspension on every machine). An explicit list gives each particle's shape (µm) and position.
//! Every particle starts relaxed: V = v(X), Ω = ω(X) of the carrier at t = 0.

use crate::coefficients::CoefficientModel;
use crate::dynamics::{
    CarrierFlow, Channel, DiscStandIn, Dynamics, DynamicsError, DynamicsParams, FlowError, ParticleState, Particles,
    SimpleShear, Stenosis, Timings, DEFAULT_DENSITY,
};
use crate::nn::model::NetworkModel;
use crate::nn::NnError;
use crate::shape::{Shape, ShapeSampler};
use rand::{Rng, SeedableRng};
use std::path::{Path, PathBuf};

/// The folder of the trained networks shipped with this crate (`nodes/platelet/weights`).
pub fn shipped_weights_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("weights")
}

/// Largest number of particles accepted.
pub const MAX_PARTICLES: usize = 10_000_000;

fn d_height() -> f64 {
    2e-3
}
fn d_length() -> f64 {
    12e-3
}
fn d_v_in() -> f64 {
    5e-3
}
fn d_shear_extent() -> f64 {
    1e-3
}

/// The carrier flow (tagged by `type`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
pub enum CarrierParams {
    /// Paper 2's straight channel ([`Channel`]), seeded over x ∈ [0, length].
    Channel {
        /// Height H \[m\]. Default 2e-3.
        #[serde(default = "d_height")]
        height: f64,
        /// Inflow speed v_in \[m/s\] (axis speed v_in/2). Default 5e-3.
        #[serde(default = "d_v_in")]
        v_in: f64,
        /// Linear ramp time \[s\] (v_in × min(t/ramp, 1)); absent: steady.
        #[serde(default)]
        ramp: Option<f64>,
        /// Length \[m\] of the seeded part. Default 12e-3.
        #[serde(default = "d_length")]
        length: f64,
    },
    /// The stenosed channel ([`Stenosis`], all its fields with their defaults).
    Stenosis(Stenosis),
    /// Simple shear v = (rate y, 0) ([`SimpleShear`]), seeded in [0, length] × [0, height], no walls.
    Shear {
        /// Shear rate γ̇ \[1/s\].
        rate: f64,
        /// Seeded length \[m\]. Default 1e-3.
        #[serde(default = "d_shear_extent")]
        length: f64,
        /// Seeded height \[m\]. Default 1e-3.
        #[serde(default = "d_shear_extent")]
        height: f64,
    },
}

impl Default for CarrierParams {
    fn default() -> Self {
        CarrierParams::Stenosis(Stenosis::default())
    }
}

/// One explicitly placed particle (e.g. the paper's five test particles).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExplicitParticle {
    /// L_x \[µm\].
    pub lx_um: f64,
    /// L_y \[µm\].
    pub ly_um: f64,
    /// L_z \[µm\].
    pub lz_um: f64,
    /// α_top.
    pub alpha_top: f64,
    /// α_bot.
    pub alpha_bot: f64,
    /// Centre x \[m\] in channel coordinates.
    pub x: f64,
    /// Centre y \[m\] in channel coordinates.
    pub y: f64,
    /// Orientation φ \[rad\] from the channel's x axis.
    #[serde(default)]
    pub phi: f64,
}

/// Which particles (module doc).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(untagged)]
pub enum ParticlesSpec {
    /// `{ count = N }`: N random platelets in the fluid.
    Count {
        /// Number of platelets, 1 ..= [`MAX_PARTICLES`].
        count: usize,
    },
    /// An explicit list.
    List(Vec<ExplicitParticle>),
}

/// The coefficient model.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ModelKind {
    /// The trained networks N, N_r, N_s (default; `weights` or the shipped ones).
    #[default]
    Network,
    /// The closed-form disc stand-in ([`DiscStandIn`]).
    Standin,
}

/// Parameters of a suspension.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SuspensionParams {
    /// Carrier flow. Default: the section 5.2 stenosis.
    pub carrier: CarrierParams,
    /// Particles. Default `{ count = 1000 }`.
    pub particles: ParticlesSpec,
    /// Seed of shapes, positions and orientations. Default 1.
    pub seed: u64,
    /// Dynamics (sub-step, sub-steps, coefficient refresh, integrator, coupling, collisions, …).
    pub dynamics: DynamicsParams,
    /// Coefficient model. Default `network`.
    pub model: ModelKind,
    /// Folder with n.safetensors, n_r.safetensors, n_s.safetensors (model `network`). Default: the
    /// shipped [`shipped_weights_dir`].
    pub weights: Option<PathBuf>,
    /// Platelet density ρ_p \[kg/m³\]. Default 1060.
    pub density: f64,
    /// Collision radius / L_x (Remark 1). Default 1.
    pub radius_factor: f64,
}

impl Default for SuspensionParams {
    fn default() -> Self {
        SuspensionParams {
            carrier: CarrierParams::default(),
            particles: ParticlesSpec::Count { count: 1000 },
            seed: 1,
            dynamics: DynamicsParams::default(),
            model: ModelKind::Network,
            weights: None,
            density: DEFAULT_DENSITY,
            radius_factor: 1.0,
        }
    }
}

/// Errors of a suspension.
#[derive(Debug, thiserror::Error)]
pub enum SuspensionError {
    /// A parameter outside its allowed range.
    #[error("platelet suspension: `{field}` = {value} is invalid: allowed {allowed}")]
    Invalid { field: String, value: String, allowed: String },
    /// Carrier parameters.
    #[error("carrier: {0}")]
    Flow(#[from] FlowError),
    /// Dynamics parameters or a diverged state.
    #[error(transparent)]
    Dynamics(#[from] DynamicsError),
    /// The network weights.
    #[error("model `network`, weights {dir}: {source}")]
    Weights { dir: String, source: NnError },
}

fn invalid(field: impl Into<String>, value: impl std::fmt::Display, allowed: impl Into<String>) -> SuspensionError {
    SuspensionError::Invalid { field: field.into(), value: value.to_string(), allowed: allowed.into() }
}

/// The carrier as a [`CarrierFlow`] plus its seeding box and fluid test.
enum Carrier {
    Channel(Channel, f64),
    Stenosis(Stenosis),
    Shear(SimpleShear, f64, f64),
}

impl Carrier {
    fn new(p: &CarrierParams) -> Result<Self, SuspensionError> {
        let extent = |field: &str, v: f64| -> Result<(), SuspensionError> {
            if v.is_finite() && v > 0.0 && v <= 1.0 {
                Ok(())
            } else {
                Err(invalid(format!("carrier.{field}"), v, "0 < value <= 1 m"))
            }
        };
        Ok(match *p {
            CarrierParams::Channel { height, v_in, ramp, length } => {
                let c = Channel { height, v_in, ramp };
                c.validate()?;
                extent("length", length)?;
                Carrier::Channel(c, length)
            }
            CarrierParams::Stenosis(s) => {
                s.validate()?;
                Carrier::Stenosis(s)
            }
            CarrierParams::Shear { rate, length, height } => {
                extent("length", length)?;
                extent("height", height)?;
                Carrier::Shear(SimpleShear::new(rate)?, length, height)
            }
        })
    }
    fn flow(&self) -> &dyn CarrierFlow {
        match self {
            Carrier::Channel(c, _) => c,
            Carrier::Stenosis(s) => s,
            Carrier::Shear(s, _, _) => s,
        }
    }
    /// x range and y range of the seeding box.
    fn bbox(&self) -> [f64; 4] {
        match self {
            Carrier::Channel(c, l) => [0.0, *l, 0.0, c.height],
            Carrier::Stenosis(s) => [0.0, s.length, 0.0, s.height],
            Carrier::Shear(_, l, h) => [0.0, *l, 0.0, *h],
        }
    }
    fn contains(&self, x: [f64; 2]) -> bool {
        let b = self.bbox();
        match self {
            Carrier::Stenosis(s) => x[0] >= b[0] && x[0] <= b[1] && s.contains(x),
            _ => x[0] >= b[0] && x[0] <= b[1] && x[1] >= b[2] && x[1] <= b[3],
        }
    }
}

impl SuspensionParams {
    /// Every field in its range, without reading the weights (see [`SuspensionParams::check_weights`]).
    pub fn validate(&self) -> Result<(), SuspensionError> {
        let carrier = Carrier::new(&self.carrier)?;
        self.dynamics.validate()?;
        Particles::new(self.density, self.radius_factor)?;
        match &self.particles {
            ParticlesSpec::Count { count } => {
                if *count == 0 || *count > MAX_PARTICLES {
                    return Err(invalid("particles.count", count, format!("1 ..= {MAX_PARTICLES}")));
                }
            }
            ParticlesSpec::List(list) => {
                if list.is_empty() || list.len() > MAX_PARTICLES {
                    return Err(invalid("particles", list.len(), format!("a list of 1 ..= {MAX_PARTICLES} particles")));
                }
                for (i, e) in list.iter().enumerate() {
                    Shape::from_um(e.lx_um, e.ly_um, e.lz_um, e.alpha_top, e.alpha_bot)
                        .validate()
                        .map_err(|err| invalid(format!("particles[{i}]"), "shape", err.to_string()))?;
                    if !e.phi.is_finite() {
                        return Err(invalid(format!("particles[{i}].phi"), e.phi, "finite (rad)"));
                    }
                    if !carrier.contains([e.x, e.y]) {
                        let b = carrier.bbox();
                        return Err(invalid(
                            format!("particles[{i}].(x, y)"),
                            format!("({}, {})", e.x, e.y),
                            format!(
                                "inside the fluid: {} <= x <= {} m, between the walls (within {} <= y <= {} m)",
                                b[0], b[1], b[2], b[3]
                            ),
                        ));
                    }
                }
            }
        }
        Ok(())
    }

    /// The weights folder used (model `network`).
    pub fn weights_dir(&self) -> PathBuf {
        self.weights.clone().unwrap_or_else(shipped_weights_dir)
    }

    /// For model `network`: the three weight files exist (cheap; loading happens in
    /// [`Suspension::new`]).
    pub fn check_weights(&self) -> Result<(), SuspensionError> {
        if self.model != ModelKind::Network {
            return Ok(());
        }
        let dir = self.weights_dir();
        for f in ["n.safetensors", "n_r.safetensors", "n_s.safetensors"] {
            if !dir.join(f).is_file() {
                return Err(invalid(
                    "weights",
                    dir.display(),
                    format!("a folder with n.safetensors, n_r.safetensors and n_s.safetensors (no {f})"),
                ));
            }
        }
        Ok(())
    }

    /// Number of particles.
    pub fn count(&self) -> usize {
        match &self.particles {
            ParticlesSpec::Count { count } => *count,
            ParticlesSpec::List(l) => l.len(),
        }
    }
}

/// A running suspension: particles advanced by macro steps of Algorithm 2 in the carrier.
pub struct Suspension {
    /// The particles (structure of arrays; indices change with the spatial sort, ids stay).
    pub particles: Particles,
    dynamics: Dynamics,
    carrier: Carrier,
    model: Box<dyn CoefficientModel>,
    t: f64,
    steps: u64,
}

impl Suspension {
    /// Validates, loads the model and seeds the particles (module doc).
    pub fn new(p: &SuspensionParams) -> Result<Self, SuspensionError> {
        p.validate()?;
        let carrier = Carrier::new(&p.carrier)?;
        let model: Box<dyn CoefficientModel> = match p.model {
            ModelKind::Standin => Box::new(DiscStandIn::default()),
            ModelKind::Network => {
                let dir = p.weights_dir();
                let m = NetworkModel::load_dir(&dir)
                    .map_err(|source| SuspensionError::Weights { dir: dir.display().to_string(), source })?;
                Box::new(m)
            }
        };
        let mut particles = Particles::new(p.density, p.radius_factor)?;
        particles.reserve(p.count());
        let flow = carrier.flow();
        let push = |ps: &mut Particles, shape: Shape, x: [f64; 2], phi: f64| -> Result<(), SuspensionError> {
            let f = flow.sample(x, 0.0);
            ps.push(shape, ParticleState { x, phi, v: f.v, omega: f.omega })?;
            Ok(())
        };
        match &p.particles {
            ParticlesSpec::Count { count } => {
                let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(p.seed);
                let sampler = ShapeSampler::default();
                let b = carrier.bbox();
                for _ in 0..*count {
                    let shape = sampler.sample(&mut rng);
                    let x = loop {
                        let x = [rng.gen_range(b[0]..b[1]), rng.gen_range(b[2]..b[3])];
                        if carrier.contains(x) {
                            break x;
                        }
                    };
                    let phi = rng.gen_range(0.0..std::f64::consts::TAU);
                    push(&mut particles, shape, x, phi)?;
                }
            }
            ParticlesSpec::List(list) => {
                for e in list {
                    let shape = Shape::from_um(e.lx_um, e.ly_um, e.lz_um, e.alpha_top, e.alpha_bot);
                    push(&mut particles, shape, [e.x, e.y], e.phi)?;
                }
            }
        }
        Ok(Suspension { particles, dynamics: Dynamics::new(p.dynamics)?, carrier, model, t: 0.0, steps: 0 })
    }

    /// One macro step (M sub-steps); returns the time split.
    pub fn macro_step(&mut self) -> Result<Timings, DynamicsError> {
        let tm = self.dynamics.macro_step(&mut self.particles, self.carrier.flow(), self.model.as_ref(), self.t)?;
        self.steps += 1;
        let k = self.dynamics.params().sub_step * self.dynamics.params().sub_steps as f64;
        self.t = self.steps as f64 * k;
        Ok(tm)
    }

    /// Time of the current state \[s\].
    pub fn time(&self) -> f64 {
        self.t
    }

    /// Macro steps done.
    pub fn macro_steps(&self) -> u64 {
        self.steps
    }

    /// The carrier flow.
    pub fn flow(&self) -> &dyn CarrierFlow {
        self.carrier.flow()
    }

    /// Name of the coefficient model.
    pub fn model_name(&self) -> &str {
        self.model.name()
    }

    /// Whether a point is in the fluid (inside the seeding box and between the walls).
    pub fn contains(&self, x: [f64; 2]) -> bool {
        self.carrier.contains(x)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn parse(s: &str) -> Result<SuspensionParams, String> {
        serde_json::from_str(s).map_err(|e| e.to_string())
    }

    #[test]
    fn parses_each_carrier_and_particle_spec() {
        let p = parse(r#"{"carrier": {"type": "channel", "ramp": 0.01}, "particles": {"count": 5}}"#).unwrap();
        assert_eq!(p.carrier, CarrierParams::Channel { height: 2e-3, v_in: 5e-3, ramp: Some(0.01), length: 12e-3 });
        assert_eq!(p.count(), 5);
        let p = parse(r#"{"carrier": {"type": "stenosis", "narrowing": 0.3}}"#).unwrap();
        assert_eq!(p.carrier, CarrierParams::Stenosis(Stenosis { narrowing: 0.3, ..Default::default() }));
        let p = parse(
            r#"{"carrier": {"type": "shear", "rate": 10.0}, "particles": [{"lx_um": 3, "ly_um": 0.5, "lz_um": 3, "alpha_top": 1, "alpha_bot": 1, "x": 1e-4, "y": 2e-4}]}"#,
        )
        .unwrap();
        assert_eq!(p.count(), 1);
        p.validate().unwrap();
        // unknown fields are named
        let e = parse(r#"{"carrier": {"type": "stenosis", "narowing": 0.3}}"#).unwrap_err();
        assert!(e.contains("narowing"), "{e}");
    }

    #[test]
    fn validation_names_fields_and_ranges() {
        let e = parse(r#"{"particles": {"count": 0}}"#).unwrap().validate().unwrap_err().to_string();
        assert!(e.contains("particles.count") && e.contains("1 ..="), "{e}");
        let e = parse(r#"{"carrier": {"type": "stenosis", "narrowing": 1.5}}"#).unwrap().validate().unwrap_err();
        assert!(e.to_string().contains("`narrowing`"), "{e}");
        // a particle inside the narrowed wall is outside the fluid
        let e = parse(
            r#"{"particles": [{"lx_um": 3, "ly_um": 0.5, "lz_um": 3, "alpha_top": 1, "alpha_bot": 1, "x": 6e-3, "y": 1e-4}]}"#,
        )
        .unwrap()
        .validate()
        .unwrap_err()
        .to_string();
        assert!(e.contains("particles[0].(x, y)") && e.contains("inside the fluid"), "{e}");
        let e = parse(r#"{"dynamics": {"sub_steps": 0}}"#).unwrap().validate().unwrap_err().to_string();
        assert!(e.contains("`sub_steps`"), "{e}");
        let e = parse(r#"{"weights": "/nonexistent"}"#).unwrap().check_weights().unwrap_err().to_string();
        assert!(e.contains("`weights`") && e.contains("n.safetensors"), "{e}");
        SuspensionParams::default().check_weights().unwrap();
    }

    #[test]
    fn seeds_uniformly_in_the_fluid_and_relaxed() {
        let p = SuspensionParams {
            particles: ParticlesSpec::Count { count: 4000 },
            model: ModelKind::Standin,
            ..Default::default()
        };
        let s = Suspension::new(&p).unwrap();
        let st = Stenosis::default();
        let ps = &s.particles;
        assert_eq!(ps.len(), 4000);
        // fraction in the bump region x ∈ [3, 9] mm: its fluid area / the total fluid area
        let bump_area = 6e-3 * 2e-3 * (1.0 - 0.25 / 2.0); // mean of δ is δ_m / 2 on each wall
        let total = bump_area + 6e-3 * 2e-3;
        let frac = ps.x.iter().filter(|&&x| (3e-3..9e-3).contains(&x)).count() as f64 / 4000.0;
        // binomial standard error √(p(1−p)/n) ≈ 0.008
        assert!((frac - bump_area / total).abs() < 0.03, "fraction {frac} vs {}", bump_area / total);
        for i in 0..ps.len() {
            assert!(st.contains([ps.x[i], ps.y[i]]));
            let v = st.velocity([ps.x[i], ps.y[i]], 0.0);
            assert_eq!([ps.vx[i], ps.vy[i]], v);
        }
        // same seed, same suspension
        let s2 = Suspension::new(&p).unwrap();
        assert_eq!(s2.particles.x, ps.x);
    }
}
