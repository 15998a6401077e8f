//! Parameters of a [`super::Producer`] (the `sph-flow` node's `[params]` table) and their checks.

use std::path::PathBuf;

use serde::{Deserialize, Deserializer};
use sonoflow_analytic_flow::{BulkMotion, GridSpec, Schedule, TissueParams};

use crate::geometry::{carotid_bifurcation, stenosis, straight_tube, BuildOptions, InitialVelocity, VesselGeometry};
use crate::{ProfileKind, Real, Scheme, SphParams, WaveformSpec};

/// The vessel geometry: a preset name or a full description.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum GeometrySpec {
    /// `"carotid"` (the paper's bifurcation), `"straight-tube"` (8 mm × 40 mm along x at 20 mm
    /// depth) or `"stenosis"` (the same tube with a 50 % cosine narrowing over 8 mm).
    Preset(String),
    /// `{ branches = [...], fillet = … }` (see [`crate::geometry`]).
    Custom(VesselGeometry),
}

impl GeometrySpec {
    /// The geometry (a preset built, a description cloned); an unknown preset name is an error.
    pub fn build(&self) -> Result<VesselGeometry, InvalidParams> {
        match self {
            GeometrySpec::Preset(name) => match name.as_str() {
                "carotid" => Ok(carotid_bifurcation()),
                "straight-tube" => Ok(straight_tube(0.04, 8e-3, [0.0, 0.02], 0.0)),
                "stenosis" => Ok(stenosis(0.04, 8e-3, 0.5, 8e-3, [0.0, 0.02], 0.0)),
                other => Err(InvalidParams::new(
                    "geometry",
                    format!(
                        "geometry = \"{other}\" is not a preset: allowed \"carotid\", \"straight-tube\", \"stenosis\" or a table with `branches`"
                    ),
                )),
            },
            GeometrySpec::Custom(g) => Ok(g.clone()),
        }
    }
}

/// The `solver` table: [`SphParams`] as given (missing fields at their defaults), and which of
/// the fields [`ProducerParams::prepare`] may set it gave: `h` (if not, h = `h_over_dx` · `dx`),
/// `shifting` and `density_diffusion` (if not, those of [`ProducerParams::scheme`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SolverTable {
    /// The solver parameters as written.
    pub params: SphParams,
    /// True when the table sets `h`.
    pub h_given: bool,
    /// True when the table sets `shifting`.
    pub shifting_given: bool,
    /// True when the table sets `density_diffusion`.
    pub density_diffusion_given: bool,
}

impl<'de> Deserialize<'de> for SolverTable {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let v = serde_json::Value::deserialize(d)?;
        let h_given = v.get("h").is_some();
        let shifting_given = v.get("shifting").is_some();
        let density_diffusion_given = v.get("density_diffusion").is_some();
        let v = if v.is_null() { serde_json::json!({}) } else { v };
        let params = serde_path_to_error::deserialize(v).map_err(|e| {
            let path = e.path().to_string();
            match path.as_str() {
                "." => serde::de::Error::custom(e.into_inner()),
                _ => serde::de::Error::custom(format!("{path}: {}", e.into_inner())),
            }
        })?;
        Ok(SolverTable { params, h_given, shifting_given, density_diffusion_given })
    }
}

fn default_geometry() -> GeometrySpec {
    GeometrySpec::Preset("carotid".into())
}
fn default_dx() -> Real {
    0.15e-3
}
fn default_h_over_dx() -> Real {
    1.2
}
fn default_inflow() -> WaveformSpec {
    WaveformSpec::Carotid { peak: 0.39, mean: 0.1875, period: 0.83 }
}
fn default_initial() -> InitialVelocity {
    InitialVelocity::FullyDeveloped
}
fn default_relax() -> usize {
    200
}
fn default_sigma() -> f32 {
    1.0
}
fn default_stats_interval() -> Real {
    0.01
}

/// Parameters of a [`super::Producer`]: the scene, the solver, the acquisition schedule, the
/// scatterer amplitudes, the truth grid, checkpoints. Every field has a default.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProducerParams {
    /// Vessel geometry. Default "carotid".
    #[serde(default = "default_geometry")]
    pub geometry: GeometrySpec,
    /// Lattice spacing of the initial particles \[m\], in \[1e-6, 1e-2\]. Default 0.15e-3 (the paper).
    #[serde(default = "default_dx")]
    pub dx: Real,
    /// Smoothing length in lattice spacings, h = h_over_dx · dx, unless `solver.h` is given; in
    /// \[0.8, 3\]. Default 1.2.
    #[serde(default = "default_h_over_dx")]
    pub h_over_dx: Real,
    /// The stabilising options of the solver by name: `"stabilised"` (default: particle shifting
    /// A = 2 and δ-SPH δ = 0.1, stable on every validation case) or `"paper"` (the paper's scheme
    /// as published: neither; unstable where the flow compresses the particles, see the sph crate's
    /// README, "Defaults and the paper's scheme"). `solver.shifting` and
    /// `solver.density_diffusion`, where given, override it.
    #[serde(default)]
    pub scheme: Scheme,
    /// Solver parameters ([`SphParams`]: c, mu, rho0, kernel, viscous term, cfl, …).
    #[serde(default)]
    pub solver: SolverTable,
    /// Cross-section mean velocity at the inlet \[m/s\]. Default: the carotid waveform (peak 0.39,
    /// mean 0.1875, period 0.83 s).
    #[serde(default = "default_inflow")]
    pub inflow: WaveformSpec,
    /// Profile imposed across the openings. Default "womersley".
    #[serde(default)]
    pub profile: ProfileKind,
    /// Initial fluid velocity ("rest" or "fully-developed"). Default fully developed.
    #[serde(default = "default_initial")]
    pub initial_velocity: InitialVelocity,
    /// Ramp of the imposed velocity from 0 over this time \[s\]. Default 0.
    #[serde(default)]
    pub ramp_time: Real,
    /// Type II wall layers (default: one kernel support).
    #[serde(default)]
    pub wall_layers: Option<usize>,
    /// Reservoir depth \[m\] (default: support + 2 dx).
    #[serde(default)]
    pub reservoir_depth: Option<Real>,
    /// Iterations of the geometric relaxation of the initial particles against the walls (evens
    /// out the kernel sums next to curved walls; 0 = the lattice as is). Default 200.
    #[serde(default = "default_relax")]
    pub relax_iterations: usize,
    /// Acquisition schedule: particle snapshots at these times (seconds of simulated time).
    #[serde(default)]
    pub schedule: Schedule,
    /// Standard deviation σ of the scatterers' amplitudes N(0, σ²), ≥ 0. Default 1.
    #[serde(default = "default_sigma")]
    pub amplitude_sigma: f32,
    /// Seed of the amplitudes (with the particle id). Default 0.
    #[serde(default)]
    pub seed: u64,
    /// Seed of the scatterer positions (absent: each scatterer sits on its fluid particle, as in
    /// the paper). With a seed, each fluid particle's scatterer sits at a fixed offset from it,
    /// uniform in [−dx/2, dx/2)² and drawn from (seed, particle id), carried with the particle
    /// (its velocity): the speckle is a new realisation while the SPH solution is untouched (the
    /// amplitude `seed` alone keeps the scatterers where the lattice puts them). See
    /// [`super::scatterer_offset`].
    #[serde(default)]
    pub position_seed: Option<u64>,
    /// Ground-truth grid (SPH-interpolated velocity at each packet's mid time). Default none.
    #[serde(default)]
    pub truth_grid: Option<GridSpec>,
    /// Tissue around the lumen (absent: blood only): seeded outside the vessel's lumen (its open
    /// ends extended straight), optionally with a wall pulsation; the SPH lumen itself stays
    /// rigid. See [`sonoflow_analytic_flow::tissue`] and [`super::SphLumen`].
    #[serde(default)]
    pub tissue: Option<TissueParams>,
    /// Rigid bulk motion of the whole scene (absent: none), as for the analytic scenes
    /// ([`sonoflow_analytic_flow::BulkMotion`]): the SPH solution is computed in the vessel's own
    /// frame and the blood scatterers, the tissue, the lumen and the truth field are moved to the
    /// lab frame (velocities: the flow's, turned, plus the rigid motion's).
    #[serde(default)]
    pub bulk: Option<BulkMotion>,
    /// Start from this checkpoint (the node resolves it relative to the launch file's folder).
    #[serde(default)]
    pub checkpoint_in: Option<PathBuf>,
    /// Write a checkpoint here at the end (relative to the run folder or absolute).
    #[serde(default)]
    pub checkpoint_out: Option<PathBuf>,
    /// Simulate until this time even after the last frame (e.g. warm-up runs ending in a
    /// checkpoint) \[s\], ≥ the last frame time. Default: the last frame.
    #[serde(default)]
    pub run_until: Option<Real>,
    /// Simulated time between diagnostics outside the packets \[s\], in \[1e-6, 1e3\]. Default 0.01.
    #[serde(default = "default_stats_interval")]
    pub stats_interval: Real,
}

impl Default for ProducerParams {
    fn default() -> Self {
        ProducerParams {
            geometry: default_geometry(),
            dx: default_dx(),
            h_over_dx: default_h_over_dx(),
            scheme: Scheme::default(),
            solver: SolverTable::default(),
            inflow: default_inflow(),
            profile: ProfileKind::default(),
            initial_velocity: default_initial(),
            ramp_time: 0.0,
            wall_layers: None,
            reservoir_depth: None,
            relax_iterations: default_relax(),
            schedule: Schedule::default(),
            amplitude_sigma: default_sigma(),
            seed: 0,
            position_seed: None,
            truth_grid: None,
            tissue: None,
            bulk: None,
            checkpoint_in: None,
            checkpoint_out: None,
            run_until: None,
            stats_interval: default_stats_interval(),
        }
    }
}

/// An invalid parameter: `field` is its path (`dx`, `schedule.prf`, `solver.c`, `geometry`,
/// `inflow.period`, …), the message starts with it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{message}")]
pub struct InvalidParams {
    /// Field path.
    pub field: String,
    /// The whole message (field, value, allowed range).
    pub message: String,
}

impl InvalidParams {
    pub(crate) fn new(field: impl Into<String>, message: impl Into<String>) -> Self {
        InvalidParams { field: field.into(), message: message.into() }
    }
}

/// `field = v is out of range: lo ..= hi` unless lo ≤ v ≤ hi.
fn in_range(field: &str, v: Real, lo: Real, hi: Real) -> Result<(), InvalidParams> {
    if v >= lo && v <= hi {
        Ok(())
    } else {
        Err(InvalidParams::new(field, format!("{field} = {v} is out of range: {lo} ..= {hi}")))
    }
}

/// Checked parameters and what the scene and the solver are built from.
#[derive(Clone, Debug)]
pub struct Prepared {
    /// The parameters.
    pub params: ProducerParams,
    /// The solver's parameters (h from `h_over_dx` and the options of `scheme` unless given).
    pub solver: SphParams,
    /// The vessel geometry.
    pub geometry: VesselGeometry,
    /// The options of [`VesselGeometry::build`].
    pub build: BuildOptions,
}

impl ProducerParams {
    /// Checks every field and returns what the run is built from (without building the
    /// particles); the error names the first bad field.
    pub fn prepare(&self) -> Result<Prepared, InvalidParams> {
        let p = self;
        in_range("dx", p.dx, 1e-6, 1e-2)?;
        in_range("h_over_dx", p.h_over_dx, 0.8, 3.0)?;
        in_range("stats_interval", p.stats_interval, 1e-6, 1e3)?;
        if !(p.amplitude_sigma.is_finite() && p.amplitude_sigma >= 0.0) {
            return Err(InvalidParams::new(
                "amplitude_sigma",
                format!("amplitude_sigma = {}: allowed >= 0", p.amplitude_sigma),
            ));
        }
        p.schedule.validate().map_err(|e| InvalidParams::new(e.field(), e.to_string()))?;
        if let Some(t) = &p.tissue {
            t.validate().map_err(|e| InvalidParams::new(e.field(), e.to_string()))?;
        }
        if let Some(b) = &p.bulk {
            b.validate().map_err(|e| InvalidParams::new(e.field(), e.to_string()))?;
        }
        if let Some(g) = &p.truth_grid {
            g.validate().map_err(|e| {
                InvalidParams::new(e.field().replacen("grid.", "truth_grid.", 1), format!("truth_grid: {e}"))
            })?;
        }
        let mut solver = p.solver.params.clone();
        if !p.solver.h_given {
            solver.h = p.h_over_dx * p.dx;
        }
        let scheme = p.scheme.params();
        if !p.solver.shifting_given {
            solver.shifting = scheme.shifting;
        }
        if !p.solver.density_diffusion_given {
            solver.density_diffusion = scheme.density_diffusion;
        }
        solver.validate().map_err(|e| InvalidParams::new(format!("solver.{}", e.field), format!("solver.{e}")))?;
        let geometry = p.geometry.build()?;
        geometry
            .validate()
            .map_err(|e| InvalidParams::new(format!("geometry.{}", e.field()), format!("geometry: {e}")))?;
        let inflow = p.inflow.build().map_err(|e| {
            InvalidParams::new(format!("inflow.{}", e.field), format!("inflow.{}: {}", e.field, e.reason))
        })?;
        let build = BuildOptions {
            inflow,
            profile: p.profile,
            ramp_time: p.ramp_time,
            initial_velocity: p.initial_velocity,
            wall_layers: p.wall_layers,
            reservoir_depth: p.reservoir_depth,
            relax_iterations: p.relax_iterations,
            parallel: solver.parallel,
            ..BuildOptions::for_solver(&solver, p.dx)
        };
        build.validate().map_err(|e| InvalidParams::new(e.field(), e.to_string()))?;
        if let Some(t) = p.run_until {
            if !(t.is_finite() && t >= p.schedule.end_time()) {
                return Err(InvalidParams::new(
                    "run_until",
                    format!("run_until = {t}: allowed >= the last frame time {} s", p.schedule.end_time()),
                ));
            }
        }
        Ok(Prepared { params: p.clone(), solver, geometry, build })
    }

    /// [`Self::prepare`] without the result.
    pub fn validate(&self) -> Result<(), InvalidParams> {
        self.prepare().map(|_| ())
    }
}
