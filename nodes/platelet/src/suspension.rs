//! A platelet suspension ready to run (paper 2, Algorithm 2 with an analytic or SPH carrier): a carrier
//! flow, the particles, the dynamics and the coefficient model, built from plain serde parameters
//! ([`SuspensionParams`]; the `[params]` of the `platelets` node deserialise into
//! [`PlateletsParams`], which adds the output schedule, and the node's run is [`Driver`]).
//!
//! Seeding: `particles = { count = N }` draws N shapes from [`ShapeSampler`] (eq 7's means and
//! spreads), positions uniform in the fluid (rejection against the local walls for the stenosis)
//! and orientations uniform in [0, 2π), all from one ChaCha8 stream seeded by `seed` (same
//! suspension on every machine). An explicit list gives each particle's shape (µm) and position.
//! Every particle starts relaxed: V = v(X), Ω = ω(X) of the carrier at t = 0.
//!
//! **Carrier from fluid particles** (`carrier = { type = "particles", … }`, [`ParticleCarrier`];
//! Algorithm 2 step 2 with an SPH fluid): the carrier is a [`LatticeField`] filled from scattered
//! fluid particles by [`ParticleInterpolator`] (module `dynamics::sph_interp`: SPH kernel
//! interpolation, first-order by default, fluid-fraction mask, eq 12 per cell). There is no flow before the first fluid snapshot, so such
//! a suspension is built by [`Suspension::with_fluid`] (seeding, `{ count }` in the lattice cells
//! whose four nodes have fluid, and the relaxed start use that snapshot) and each later snapshot
//! replaces the lattice velocities through [`Suspension::set_fluid`]; [`Suspension::new`]
//! refuses it. Its time starts at the first snapshot's.

use crate::coefficients::CoefficientModel;
use crate::dynamics::{
    CarrierFlow, Channel, DiscStandIn, Dynamics, DynamicsError, DynamicsParams, FillReport, FlowError, LatticeField,
    ParticleInterpolator, ParticleState, Particles, SimpleShear, Stenosis, Timings, DEFAULT_DENSITY,
};
use crate::nn::model::NetworkModel;
use crate::nn::NnError;
use crate::shape::{Shape, ShapeSampler};
use rand::{Rng, SeedableRng};
use std::path::{Path, PathBuf};

pub mod driver;
mod particle_carrier;
pub use driver::{
    check_fluid_input, Driver, DriverError, FluidReport, FluidSnapshot, FluidSource, Frame, FrameMap, Hooks,
    OutputParams, PlateletState, PlateletsParams, Received, TimingReport,
};
pub use particle_carrier::{LatticeSpec, ParticleCarrier, MAX_LATTICE_NODES, MAX_SUPPORT_SPACINGS};

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
    /// Fluid particles (e.g. SPH) interpolated onto a lattice ([`ParticleCarrier`]; module doc),
    /// seeded in the lattice cells with fluid (within the walls, if any).
    Particles(ParticleCarrier),
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
    /// A parameter of the node's output schedule or mapping ([`OutputParams`]) outside its range.
    #[error("{field} = {value} is out of range: {allowed}")]
    OutOfRange { field: String, value: String, allowed: String },
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
    /// The lattice (no fluid until the first [`ParticleInterpolator::fill`]) and its interpolator.
    Particles(Box<(ParticleCarrier, LatticeField, ParticleInterpolator)>),
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
            CarrierParams::Particles(pc) => {
                pc.validate()?;
                let l = &pc.lattice;
                let field =
                    LatticeField::new(l.origin, l.h, l.nx, l.ny, vec![[0.0; 2]; l.nx * l.ny])?.with_walls(pc.walls);
                Carrier::Particles(Box::new((pc, field, ParticleInterpolator::new(pc.interp())?)))
            }
        })
    }
    fn flow(&self) -> &dyn CarrierFlow {
        match self {
            Carrier::Channel(c, _) => c,
            Carrier::Stenosis(s) => s,
            Carrier::Shear(s, _, _) => s,
            Carrier::Particles(b) => &b.1,
        }
    }
    /// x range and y range of the seeding box.
    fn bbox(&self) -> [f64; 4] {
        match self {
            Carrier::Channel(c, l) => [0.0, *l, 0.0, c.height],
            Carrier::Stenosis(s) => [0.0, s.length, 0.0, s.height],
            Carrier::Shear(_, l, h) => [0.0, *l, 0.0, *h],
            Carrier::Particles(b) => b.0.bbox(),
        }
    }
    /// Inside the seeding box (and between the local walls): what can be checked without fluid.
    fn in_box(&self, x: [f64; 2]) -> bool {
        let b = self.bbox();
        match self {
            Carrier::Stenosis(s) => x[0] >= b[0] && x[0] <= b[1] && s.contains(x),
            _ => x[0] >= b[0] && x[0] <= b[1] && x[1] >= b[2] && x[1] <= b[3],
        }
    }
    /// In the fluid: in the box and, for a `particles` carrier, in a lattice cell with fluid on
    /// all four nodes.
    fn contains(&self, x: [f64; 2]) -> bool {
        match self {
            Carrier::Particles(b) => self.in_box(x) && b.1.cell_valid_at(x),
            _ => self.in_box(x),
        }
    }
    /// Lattice cells (of a `particles` carrier) in the seeding box with fluid on all four nodes.
    fn fluid_cells(&self) -> usize {
        let Carrier::Particles(b) = self else { return 0 };
        let f = &b.1;
        let (nx, ny) = f.dims();
        let mut n = 0;
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                let p = f.node_position(i, j);
                let c = [p[0] + 0.5 * f.spacing(), p[1] + 0.5 * f.spacing()];
                n += (self.in_box(c) && f.cell_valid_at(c)) as usize;
            }
        }
        n
    }
}

impl SuspensionParams {
    /// Every field in its range, without reading the weights (see [`SuspensionParams::check_weights`]).
    pub fn validate(&self) -> Result<(), SuspensionError> {
        // (a `particles` carrier is checked without allocating its lattice)
        let carrier = match &self.carrier {
            CarrierParams::Particles(pc) => {
                pc.validate()?;
                None
            }
            other => Some(Carrier::new(other)?),
        };
        let bbox = match (&carrier, &self.carrier) {
            (Some(c), _) => c.bbox(),
            (None, CarrierParams::Particles(pc)) => pc.bbox(),
            (None, _) => [f64::NAN; 4],
        };
        let in_box = |x: [f64; 2]| match &carrier {
            Some(c) => c.in_box(x),
            None => x[0] >= bbox[0] && x[0] <= bbox[1] && x[1] >= bbox[2] && x[1] <= bbox[3],
        };
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
                    if !in_box([e.x, e.y]) {
                        let b = bbox;
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
    t0: f64,
    t: f64,
    steps: u64,
}

impl Suspension {
    /// Validates, loads the model and seeds the particles (module doc). For an analytic carrier;
    /// a `particles` carrier needs [`Suspension::with_fluid`].
    pub fn new(p: &SuspensionParams) -> Result<Self, SuspensionError> {
        p.validate()?;
        if let CarrierParams::Particles(_) = p.carrier {
            return Err(invalid(
                "carrier.type",
                "particles",
                "an analytic carrier for Suspension::new (a `particles` carrier is built by Suspension::with_fluid from the first fluid snapshot)",
            ));
        }
        Self::build(p, Carrier::new(&p.carrier)?, 0.0)
    }

    /// A suspension in a `particles` carrier (module doc): the lattice is filled from the fluid
    /// particles at `pos` \[m\] with velocities `vel` \[m/s\] (channel coordinates) of the
    /// snapshot at time `t0` \[s\], which becomes the suspension's start time; then the platelets
    /// are seeded in the lattice cells with fluid and relaxed to that flow. An explicit particle
    /// outside those cells is refused.
    pub fn with_fluid(
        p: &SuspensionParams,
        t0: f64,
        pos: &[[f64; 2]],
        vel: &[[f64; 2]],
    ) -> Result<(Self, FillReport), SuspensionError> {
        p.validate()?;
        if !t0.is_finite() {
            return Err(invalid("t0", t0, "finite (s)"));
        }
        let mut carrier = Carrier::new(&p.carrier)?;
        let Carrier::Particles(b) = &mut carrier else {
            return Err(invalid("carrier.type", "an analytic carrier", "`particles` for Suspension::with_fluid"));
        };
        let (_, field, interp) = &mut **b;
        let report = interp.fill(field, pos, vel)?;
        if carrier.fluid_cells() == 0 {
            return Err(invalid(
                "carrier.lattice",
                format!(
                    "{} of {} nodes with fluid ({} of {} particles within reach)",
                    report.valid_nodes, report.nodes, report.used, report.particles
                ),
                "a lattice (within the walls) with at least one cell whose four nodes have a fluid fraction >= min_fraction: place it over the fluid",
            ));
        }
        if let ParticlesSpec::List(list) = &p.particles {
            for (i, e) in list.iter().enumerate() {
                if !carrier.contains([e.x, e.y]) {
                    return Err(invalid(
                        format!("particles[{i}].(x, y)"),
                        format!("({}, {})", e.x, e.y),
                        "in a lattice cell whose four nodes have fluid (fraction >= carrier.min_fraction) in the first fluid snapshot",
                    ));
                }
            }
        }
        Ok((Self::build(p, carrier, t0)?, report))
    }

    /// Replaces the fluid of a `particles` carrier with a new snapshot (same frame and units as
    /// in [`Suspension::with_fluid`]); the next macro step uses it.
    pub fn set_fluid(&mut self, pos: &[[f64; 2]], vel: &[[f64; 2]]) -> Result<FillReport, SuspensionError> {
        let Carrier::Particles(b) = &mut self.carrier else {
            return Err(invalid("carrier.type", "an analytic carrier", "`particles` for set_fluid"));
        };
        let (_, field, interp) = &mut **b;
        Ok(interp.fill(field, pos, vel)?)
    }

    /// The lattice of a `particles` carrier.
    pub fn lattice(&self) -> Option<&LatticeField> {
        match &self.carrier {
            Carrier::Particles(b) => Some(&b.1),
            _ => None,
        }
    }

    fn build(p: &SuspensionParams, carrier: Carrier, t0: f64) -> Result<Self, SuspensionError> {
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
            let f = flow.sample(x, t0);
            ps.push(shape, ParticleState { x, phi, v: f.v, omega: f.omega })?;
            Ok(())
        };
        match &p.particles {
            ParticlesSpec::Count { count } => {
                let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(p.seed);
                let sampler = ShapeSampler::default();
                let b = carrier.bbox();
                // a `particles` carrier may have fluid in few cells of its box: bounded rejection
                let max_tries = match carrier {
                    Carrier::Particles(_) => 1000 * (*count as u64) + 1_000_000,
                    _ => u64::MAX,
                };
                let mut tries = 0u64;
                for _ in 0..*count {
                    let shape = sampler.sample(&mut rng);
                    let x = loop {
                        let x = [rng.gen_range(b[0]..b[1]), rng.gen_range(b[2]..b[3])];
                        if carrier.contains(x) {
                            break x;
                        }
                        tries += 1;
                        if tries > max_tries {
                            return Err(invalid(
                                "carrier.lattice",
                                format!("{} fluid cells", carrier.fluid_cells()),
                                "fluid over more of the lattice (no seeding position found in 1000 tries per particle)",
                            ));
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
        Ok(Suspension { particles, dynamics: Dynamics::new(p.dynamics)?, carrier, model, t0, t: t0, steps: 0 })
    }

    /// One macro step (M sub-steps); returns the time split.
    pub fn macro_step(&mut self) -> Result<Timings, DynamicsError> {
        let tm = self.dynamics.macro_step(&mut self.particles, self.carrier.flow(), self.model.as_ref(), self.t)?;
        self.steps += 1;
        self.t = self.t0 + self.steps as f64 * self.macro_step_length();
        Ok(tm)
    }

    /// Length of a macro step k = sub_step · sub_steps \[s\].
    pub fn macro_step_length(&self) -> f64 {
        self.dynamics.params().sub_step * self.dynamics.params().sub_steps as f64
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
    use crate::dynamics::SphKernel;

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

    /// Plane Poiseuille flow between y = 0 and y = 2a (peak u_max on y = a) as SPH-like particles
    /// on a jittered lattice of spacing dx, x ∈ [0, 12 mm].
    fn poiseuille_cloud(u_max: f64, a: f64, dx: f64, scale: f64) -> (Vec<[f64; 2]>, Vec<[f64; 2]>) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let (mut pos, mut vel) = (Vec::new(), Vec::new());
        for j in 0..(2.0 * a / dx).round() as usize {
            for i in 0..(12e-3 / dx).round() as usize {
                let x = (i as f64 + 0.5 + 0.2 * rng.gen_range(-1.0..1.0)) * dx;
                let y = ((j as f64 + 0.5 + 0.2 * rng.gen_range(-1.0..1.0)) * dx).clamp(0.0, 2.0 * a);
                pos.push([x, y]);
                vel.push([scale * u_max * (1.0 - ((y - a) / a).powi(2)), 0.0]);
            }
        }
        (pos, vel)
    }

    fn particle_carrier_params(count: usize) -> SuspensionParams {
        parse(&format!(
            r#"{{"carrier": {{"type": "particles", "lattice": {{"origin": [2e-3, -0.5e-3], "h": 1e-4, "nx": 61, "ny": 91}},
                "kernel_h": 4.8e-4, "walls": [0.0, 8e-3]}},
              "particles": {{"count": {count}}}, "model": "standin",
              "dynamics": {{"sub_step": 2.5e-5, "sub_steps": 20}}}}"#
        ))
        .unwrap()
    }

    #[test]
    fn particle_carrier_parses_and_names_bad_fields() {
        let p = particle_carrier_params(10);
        let CarrierParams::Particles(pc) = p.carrier else { panic!("{:?}", p.carrier) };
        assert_eq!((pc.kernel, pc.min_fraction, pc.walls), (SphKernel::QuarticSpline, 0.4, Some([0.0, 8e-3])));
        p.validate().unwrap();
        let with = |patch: &str| {
            let base = r#""type": "particles", "lattice": {"origin": [0, 0], "h": 1e-4, "nx": 11, "ny": 11}"#;
            parse(&format!(r#"{{"carrier": {{{base}, {patch}}}}}"#))
                .and_then(|p| p.validate().map_err(|e| e.to_string()))
        };
        with(r#""kernel_h": 2e-4"#).unwrap();
        for (patch, want) in [
            (r#""kernel_h": 0.0"#, "`carrier.kernel_h` = 0 is invalid: allowed 0 < kernel_h <= 0.1 m"),
            (r#""kernel_h": 1.0"#, "`carrier.kernel_h`"),
            (r#""kernel_h": 2e-4, "min_fraction": 2"#, "`carrier.min_fraction` = 2"),
            (r#""kernel_h": 2e-4, "walls": [3e-3, 1e-3]"#, "`carrier.walls`"),
            (r#""kernel_h": 2e-4, "walls": [3e-3, 4e-3]"#, "overlapping the lattice's y range"),
            (r#""kernel_h": 2e-4, "kernel": "gauss""#, "gauss"),
            (r#""kernel_h": 2e-4, "kernal": "wendland-c2""#, "kernal"),
            (r#""walls": [0, 1e-3]"#, "missing field `kernel_h`"),
        ] {
            let e = with(patch).unwrap_err();
            assert!(e.contains(want), "{patch}: {e}");
        }
        // support 2.5 × 0.03 m > 64 lattice spacings of 0.1 mm
        let e = with(r#""kernel_h": 0.03"#).unwrap_err();
        assert!(e.contains("`carrier.kernel_h`") && e.contains("64 lattice spacings"), "{e}");
        let e = parse(r#"{"carrier": {"type": "particles", "lattice": {"origin": [0, 0], "h": 1e-4, "nx": 1, "ny": 11}, "kernel_h": 2e-4}}"#)
            .unwrap()
            .validate()
            .unwrap_err()
            .to_string();
        assert!(e.contains("carrier.lattice.(nx, ny)") && e.contains("nx >= 2"), "{e}");
        // no fluid yet: only with_fluid builds it
        let e = Suspension::new(&particle_carrier_params(10)).err().unwrap().to_string();
        assert!(e.contains("with_fluid"), "{e}");
    }

    /// The suspension in a `particles` carrier: seeded in the lattice cells with fluid, relaxed to
    /// the interpolated flow, carried at the Poiseuille speed (minus the kernel's smoothing bias
    /// u_max M₂/(2a²) = 0.6 % with h = 0.48 mm, a = 4 mm; module `dynamics::sph_interp`), and a new
    /// snapshot takes effect at the next macro step.
    #[test]
    fn platelets_ride_a_fluid_given_as_particles() {
        let (u_max, a) = (0.075, 4e-3);
        let p = particle_carrier_params(300);
        let (pos, vel) = poiseuille_cloud(u_max, a, 0.4e-3, 1.0);
        let (mut s, rep) = Suspension::with_fluid(&p, 0.25, &pos, &vel).unwrap();
        assert_eq!(s.time(), 0.25);
        // the lattice reaches 0.5 mm outside each wall: those nodes (φ < ½) are masked
        assert!(rep.valid_nodes < rep.nodes && rep.valid_nodes > rep.nodes * 3 / 4, "{rep:?}");
        let lat = s.lattice().unwrap();
        let ps = &s.particles;
        assert_eq!(ps.len(), 300);
        for i in 0..ps.len() {
            let x = [ps.x[i], ps.y[i]];
            assert!(lat.cell_valid_at(x) && (0.0..=8e-3).contains(&x[1]), "seeded at {x:?}");
            assert_eq!([ps.vx[i], ps.vy[i]], lat.velocity(x, 0.25), "relaxed");
        }
        let x0: Vec<[f64; 2]> = (0..300).map(|i| [ps.x[i], ps.y[i]]).collect();
        s.macro_step().unwrap();
        assert!((s.time() - 0.2505).abs() < 1e-15, "{}", s.time());
        let k = s.macro_step_length();
        let bias = u_max * 0.79939 * 0.48e-3f64.powi(2) / (2.0 * a * a);
        let (mut worst, mut n_axis) = (0.0f64, 0);
        for i in 0..300 {
            let id = s.particles.id[i] as usize;
            let (x, y) = (s.particles.x[i], s.particles.y[i]);
            assert!((0.0..=8e-3).contains(&y), "left the channel: y = {y}");
            // away from the walls (a kernel support): speed = profile − bias, within the jitter term
            let yc = 0.5 * (y + x0[id][1]);
            if (yc - a).abs() < a - 1.2e-3 {
                let u = u_max * (1.0 - ((yc - a) / a).powi(2)) - bias;
                worst = worst.max(((x - x0[id][0]) / k - u).abs() / u_max);
                assert!((y - x0[id][1]).abs() < 0.005 * u_max * k, "id {id}: dy = {}", y - x0[id][1]);
                n_axis += 1;
            }
        }
        eprintln!(
            "particles carrier: {n_axis} platelets away from the walls, worst |dx/k − (u − bias)| = {:.3} % of u_max",
            100.0 * worst
        );
        assert!(n_axis > 100 && worst < 0.005, "{n_axis}, {worst}");
        // a new snapshot with twice the speed takes effect in the next step
        let (pos2, vel2) = poiseuille_cloud(u_max, a, 0.4e-3, 2.0);
        s.set_fluid(&pos2, &vel2).unwrap();
        let before: Vec<f64> = s.particles.x.clone();
        let yb: Vec<f64> = s.particles.y.clone();
        s.macro_step().unwrap();
        for i in 0..300 {
            if (yb[i] - a).abs() < a - 1.2e-3 {
                let u = 2.0 * (u_max * (1.0 - ((yb[i] - a) / a).powi(2)) - bias);
                assert!(((s.particles.x[i] - before[i]) / k - u).abs() < 0.01 * u_max, "id {}", s.particles.id[i]);
            }
        }
        // an analytic suspension has no fluid to set
        let mut an = Suspension::new(&SuspensionParams {
            model: ModelKind::Standin,
            particles: ParticlesSpec::Count { count: 2 },
            ..Default::default()
        })
        .unwrap();
        assert!(an.set_fluid(&pos, &vel).is_err());
        // a lattice beside the fluid has nothing to seed into
        let mut far = particle_carrier_params(3);
        if let CarrierParams::Particles(pc) = &mut far.carrier {
            pc.lattice.origin = [0.5, 0.5];
            pc.walls = None;
        }
        let e = Suspension::with_fluid(&far, 0.0, &pos, &vel).err().unwrap().to_string();
        assert!(e.contains("carrier.lattice") && e.contains("place it over the fluid"), "{e}");
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
