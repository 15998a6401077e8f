//! `sph-flow` node: thin wiring of `sonoflow-sph` — builds a vessel scene (geometry preset or
//! table), runs the weakly compressible SPH solver, publishes the fluid particles (the acoustic
//! scatterers) at every acquisition time, the SPH-interpolated velocity on the truth grid at every
//! packet's mid time, and the solver diagnostics; optionally starts from and ends with a checkpoint.

use std::path::PathBuf;

use serde::Deserialize;
use sonoflow_analytic_flow::{GridSpec, Schedule};
use sonoflow_messages::types::{FlowStats, ParticleSnapshot, VectorField};
use sonoflow_messages::*;
// The solver runs on rayon threads: its cost is the process CPU time (the node does nothing else).
use sonoflow_messages::MessageType::*;
use sonoflow_node_kit::PortDir::*;
use sonoflow_node_kit::{port, KindSpec};
use sonoflow_node_kit::{process_cpu_ns as thread_cpu_ns, Kit, Output};
use sonoflow_sph::geometry::{
    carotid_bifurcation, stenosis, straight_tube, BuildOptions, InitialVelocity, VesselGeometry, VesselScene,
};
use sonoflow_sph::{Checkpoint, DtCriterion, ParticleKind, ProfileKind, Real, Solver, SphParams, WaveformSpec};

/// The `sph-flow` node kind.
pub const SPEC: KindSpec = KindSpec {
        name: "sph-flow",
        about: "weakly compressible SPH blood flow (paper 1 §2.1–2.2) in a vessel geometry (carotid bifurcation preset): fluid particles = scatterers at the acquisition times, SPH-interpolated ground truth, solver diagnostics",
        ports: &[
            port("particles", Out, ParticleSnapshotV1, true),
            port("truth", Out, VectorFieldV1, false),
            port("stats", Out, FlowStatsV1, false),
        ],
        dynamic_inputs: false,
        dynamic_outputs: false,
        validate,
        check_wiring: None,
        input_files: &["checkpoint_in"],
        run,
};

/// The vessel geometry: a preset name or a full description.
#[derive(Clone, Debug, Deserialize)]
#[serde(untagged)]
pub enum GeometrySpec {
    /// `"carotid"` (the paper's bifurcation), `"straight-tube"` (8 mm × 40 mm along x at 20 mm
    /// depth) or `"stenosis"` (the same tube with a 50 % cosine narrowing over 8 mm).
    Preset(String),
    /// `{ branches = [...], fillet = … }` (see `sonoflow_sph::geometry`).
    Custom(VesselGeometry),
}

impl GeometrySpec {
    fn build(&self) -> Result<VesselGeometry, String> {
        match self {
            GeometrySpec::Preset(name) => match name.as_str() {
                "carotid" => Ok(carotid_bifurcation()),
                "straight-tube" => Ok(straight_tube(0.04, 8e-3, [0.0, 0.02], 0.0)),
                "stenosis" => Ok(stenosis(0.04, 8e-3, 0.5, 8e-3, [0.0, 0.02], 0.0)),
                other => Err(format!(
                    "geometry = \"{other}\" is not a preset: allowed \"carotid\", \"straight-tube\", \"stenosis\" or a table with `branches`"
                )),
            },
            GeometrySpec::Custom(g) => Ok(g.clone()),
        }
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
fn default_sigma() -> f32 {
    1.0
}
fn default_stats_interval() -> Real {
    0.01
}

/// Parameters of the `sph-flow` node.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SphNodeParams {
    /// Vessel geometry. Default "carotid".
    #[serde(default = "default_geometry")]
    pub geometry: GeometrySpec,
    /// Lattice spacing of the initial particles \[m\]. Default 0.15e-3 (the paper).
    #[serde(default = "default_dx")]
    pub dx: Real,
    /// Smoothing length in lattice spacings, h = h_over_dx · dx, unless `solver.h` is given. Default 1.2.
    #[serde(default = "default_h_over_dx")]
    pub h_over_dx: Real,
    /// Solver parameters (`sonoflow_sph::SphParams`: c, mu, rho0, kernel, viscous term, cfl, …).
    #[serde(default)]
    pub solver: serde_json::Value,
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
    /// Standard deviation σ of the scatterers' amplitudes N(0, σ²). Default 1.
    #[serde(default = "default_sigma")]
    pub amplitude_sigma: f32,
    /// Seed of the amplitudes (with the particle id). Default 0.
    #[serde(default)]
    pub seed: u64,
    /// Ground-truth grid (SPH-interpolated velocity at each packet's mid time).
    #[serde(default)]
    pub truth_grid: Option<GridSpec>,
    /// Start from this checkpoint (relative to the launch file's folder or absolute).
    #[serde(default)]
    pub checkpoint_in: Option<PathBuf>,
    /// Write a checkpoint here at the end (relative to the run folder or absolute).
    #[serde(default)]
    pub checkpoint_out: Option<PathBuf>,
    /// Simulate until this time even after the last frame (e.g. warm-up runs ending in a
    /// checkpoint) \[s\]. Default: the last frame.
    #[serde(default)]
    pub run_until: Option<Real>,
    /// Simulated time between diagnostics messages outside the packets \[s\]. Default 0.01.
    #[serde(default = "default_stats_interval")]
    pub stats_interval: Real,
}

fn default_relax() -> usize {
    200
}

fn default_initial() -> InitialVelocity {
    InitialVelocity::FullyDeveloped
}

/// Everything the node needs, checked.
pub struct Prepared {
    pub params: SphNodeParams,
    pub solver: SphParams,
    pub geometry: VesselGeometry,
    pub build: BuildOptions,
}

/// Parses and checks the node parameters (without building the particles).
pub fn prepare(v: &serde_json::Value) -> Result<Prepared, String> {
    let params: SphNodeParams = sonoflow_node_kit::parse_params(v)?;
    let p = &params;
    sonoflow_node_kit::in_range("dx", p.dx, 1e-6, 1e-2)?;
    sonoflow_node_kit::in_range("h_over_dx", p.h_over_dx, 0.8, 3.0)?;
    sonoflow_node_kit::in_range("stats_interval", p.stats_interval, 1e-6, 1e3)?;
    if !(p.amplitude_sigma.is_finite() && p.amplitude_sigma >= 0.0) {
        return Err(format!("amplitude_sigma = {}: allowed >= 0", p.amplitude_sigma));
    }
    p.schedule.validate().map_err(|e| e.to_string())?;
    if let Some(g) = &p.truth_grid {
        g.validate().map_err(|e| format!("truth_grid: {e}"))?;
    }
    let has_h = p.solver.get("h").is_some();
    let mut solver: SphParams = sonoflow_node_kit::parse_params(&p.solver).map_err(|e| format!("solver.{e}"))?;
    if !has_h {
        solver.h = p.h_over_dx * p.dx;
    }
    solver.validate().map_err(|e| format!("solver.{e}"))?;
    let geometry = p.geometry.build()?;
    geometry.validate().map_err(|e| format!("geometry: {e}"))?;
    let inflow = p.inflow.build().map_err(|e| format!("inflow.{}: {}", e.field, e.reason))?;
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
    build.validate().map_err(|e| format!("{e}"))?;
    if let Some(t) = p.run_until {
        if !(t.is_finite() && t >= p.schedule.end_time()) {
            return Err(format!("run_until = {t}: allowed >= the last frame time {} s", p.schedule.end_time()));
        }
    }
    Ok(Prepared { params, solver, geometry, build })
}

pub fn validate(v: &serde_json::Value) -> Result<(), String> {
    prepare(v).map(|_| ())
}

/// Amplitude of the scatterer with stable id `id`: N(0, σ²), a pure function of (seed, id) (Box–
/// Muller over two SplitMix64 draws), so it is kept for the particle's life and across checkpoints.
pub fn amplitude(seed: u64, id: u64, sigma: f32) -> f32 {
    fn mix(mut z: u64) -> u64 {
        z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    let a = mix(seed ^ mix(id));
    let b = mix(a);
    let u1 = ((a >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
    let u2 = (b >> 11) as f64 / (1u64 << 53) as f64;
    ((-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()) as f32 * sigma
}

fn binding_code(b: Option<DtCriterion>) -> u32 {
    match b {
        Some(DtCriterion::Cfl) | None => DT_CFL,
        Some(DtCriterion::Viscous) => DT_VISCOUS,
        Some(DtCriterion::Force) => DT_FORCE,
        Some(DtCriterion::Maximum) => DT_MAXIMUM,
        Some(DtCriterion::Output) => DT_OUTPUT,
    }
}

fn publish_stats(out: &mut Output<FlowStats>, s: &Solver, frame_id: u64, cpu_ns: u64) -> anyhow::Result<()> {
    let d = s.diagnostics();
    let mut h = FlowStatsHeaderV1 {
        dt: d.last_step.map_or(0.0, |r| r.dt),
        steps: d.steps,
        max_density_error: d.max_density_error,
        kinetic_energy: d.kinetic_energy,
        fluid_mass: d.fluid_mass,
        max_speed: d.max_speed,
        min_pair_distance: if d.min_pair_distance.is_finite() { d.min_pair_distance } else { 0.0 },
        guard_corrections: d.guard_corrections,
        solver_cpu_ns: cpu_ns,
        n_fluid: d.n_fluid as u32,
        n_buffer: d.n_buffer as u32,
        n_wall: d.n_wall as u32,
        binding: binding_code(d.last_step.map(|r| r.binding)),
        n_boundaries: d.boundaries.len() as u32,
        ..Default::default()
    };
    h.common.frame_id = frame_id;
    h.common.t_valid = d.time;
    let n = d.boundaries.len();
    out.publish_in_place(n, h, |dst| {
        for (slot, (_, f)) in dst.iter_mut().zip(&d.boundaries) {
            slot.write(BoundaryFluxV1 {
                mass_in: f.mass_in,
                mass_out: f.mass_out,
                created: f.created,
                removed: f.removed,
            });
        }
    })?;
    Ok(())
}

/// One event of the run: a frame (snapshot) or a packet's mid time (truth).
enum Event {
    Frame(sonoflow_analytic_flow::AcquisitionTime),
    Truth { packet: u32, t: Real, frame_id: u64 },
}

pub fn run(mut kit: Kit) -> anyhow::Result<()> {
    let prep = prepare(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    let p = &prep.params;
    let t_build = std::time::Instant::now();
    let scene: VesselScene = prep.geometry.build(&prep.build)?;
    let names: Vec<String> = scene.boundaries.iter().map(|b| b.name.clone()).collect();
    eprintln!(
        "sph-flow: {} particles ({} fluid, {} wall, {} reservoir), boundaries {:?}, built in {:.2} s; h = {:.3} mm, c = {} m/s",
        scene.particles.len(),
        scene.count(ParticleKind::Fluid),
        scene.count(ParticleKind::WallOn) + scene.count(ParticleKind::WallOutside),
        scene.count(ParticleKind::Buffer),
        names,
        t_build.elapsed().as_secs_f64(),
        prep.solver.h * 1e3,
        prep.solver.c
    );
    let domain = scene.guard_domain();
    let mut solver = match &p.checkpoint_in {
        Some(path) => {
            let ck = Checkpoint::read(path)?;
            let t = ck.header.time;
            if ck.header.params != prep.solver {
                eprintln!("sph-flow: note: the checkpoint was written with other solver parameters; continuing with this run's");
            }
            let s = Solver::from_checkpoint(prep.solver.clone(), ck, scene.boundaries.clone(), &[])?;
            eprintln!("sph-flow: resumed from {} at t = {t} s", path.display());
            s
        }
        None => Solver::new(prep.solver.clone(), scene.particles.clone(), prep.build.t0)?
            .with_open_boundaries(scene.boundaries.clone())?,
    }
    .with_domain(domain);
    let t_start = solver.time();
    let frames = p.schedule.times();
    if let Some(first) = frames.first() {
        if first.t < t_start {
            anyhow::bail!(
                "schedule: the first frame (t = {} s) is before the solver's start time {t_start} s (checkpoint): raise schedule.t_start",
                first.t
            );
        }
    }
    let mut out = kit.output::<ParticleSnapshot>("particles")?;
    let mut truth_out = match kit.cfg.outputs.contains_key("truth") {
        true => Some(kit.output::<VectorField>("truth")?),
        false => None,
    };
    let mut stats_out = match kit.cfg.outputs.contains_key("stats") {
        true => Some(kit.output::<FlowStats>("stats")?),
        false => None,
    };
    {
        let mut ports: Vec<&mut dyn sonoflow_node_kit::Handshake> = vec![&mut out];
        if let Some(t) = truth_out.as_mut() {
            ports.push(t);
        }
        if let Some(s) = stats_out.as_mut() {
            ports.push(s);
        }
        kit.handshake(&mut ports)?;
    }
    // events in time order: frames and (with a truth grid) packet mid times
    let mut events: Vec<(Real, Event)> = frames.iter().map(|a| (a.t, Event::Frame(*a))).collect();
    if truth_out.is_some() && p.truth_grid.is_some() {
        for k in 0..p.schedule.n_packets {
            let frame_id = k as u64 * p.schedule.packet_size as u64 + (p.schedule.packet_size / 2) as u64;
            let t = p.schedule.packet_mid_time(k);
            events.push((t, Event::Truth { packet: k, t, frame_id }));
        }
    }
    events.sort_by(|a, b| a.0.total_cmp(&b.0));
    let t_end = p.run_until.unwrap_or(p.schedule.end_time()).max(t_start);
    // progress in units of 0.1 ms of simulated time
    let total_ms = (((t_end - t_start) * 1e4).ceil() as u64).max(1);
    let mut solver_cpu = 0u64;
    let mut last_t = t_start;
    let mut next_stats = t_start;
    let mut frame_done = 0usize;
    let grid = p.truth_grid.clone();
    let (gx, gz, inside): (Vec<Real>, Vec<Real>, Vec<bool>) = match &grid {
        Some(g) => {
            let mut xs = Vec::new();
            let mut zs = Vec::new();
            let mut ins = Vec::new();
            for iz in 0..g.nz {
                for ix in 0..g.nx {
                    let (x, z) = (g.x0 + ix as f64 * g.dx, g.z0 + iz as f64 * g.dz);
                    xs.push(x);
                    zs.push(z);
                    ins.push(scene.is_inside(x, z));
                }
            }
            (xs, zs, ins)
        }
        None => (vec![], vec![], vec![]),
    };
    // advance in pieces no longer than the stats interval (progress and diagnostics on long gaps)
    let advance = |solver: &mut Solver,
                   to: Real,
                   kit: &mut Kit,
                   stats_out: &mut Option<Output<FlowStats>>,
                   solver_cpu: &mut u64,
                   next_stats: &mut Real|
     -> anyhow::Result<()> {
        while solver.time() < to {
            let target = to.min(*next_stats).max(solver.time());
            let t0 = thread_cpu_ns();
            solver.advance_to(if target > solver.time() { target } else { to })?;
            *solver_cpu += thread_cpu_ns() - t0;
            if solver.time() >= *next_stats {
                if let Some(so) = stats_out.as_mut() {
                    publish_stats(so, solver, 0, *solver_cpu)?;
                }
                *next_stats += p.stats_interval;
                let done = (((solver.time() - t_start) * 1e4) as u64).min(total_ms);
                kit.progress(done, total_ms);
            }
            if kit.check_termination().is_err() {
                anyhow::bail!("terminated at t = {} s", solver.time());
            }
        }
        Ok(())
    };
    for (t, ev) in &events {
        if kit.check_termination().is_err() {
            break;
        }
        advance(&mut solver, *t, &mut kit, &mut stats_out, &mut solver_cpu, &mut next_stats)?;
        match ev {
            Event::Frame(at) => {
                let t0 = thread_cpu_ns();
                let ps = &solver.particles;
                let idx: Vec<usize> = (0..ps.len()).filter(|&i| ps.kind[i] == ParticleKind::Fluid).collect();
                let n = idx.len();
                if n > out.max_elements() {
                    anyhow::bail!(
                        "the flow has {n} fluid particles but topic `{}` allows max_elements = {}: raise it in the launch file",
                        out.topic(),
                        out.max_elements()
                    );
                }
                let (mut xmin, mut xmax, mut zmin, mut zmax) = (f32::MAX, f32::MIN, f32::MAX, f32::MIN);
                for &i in &idx {
                    xmin = xmin.min(ps.x[i] as f32);
                    xmax = xmax.max(ps.x[i] as f32);
                    zmin = zmin.min(ps.z[i] as f32);
                    zmax = zmax.max(ps.z[i] as f32);
                }
                let mut h = ParticleSnapshotHeaderV1 {
                    n_particles: n as u32,
                    n_fluid: n as u32,
                    dt: solver.last_step().map_or(0.0, |r| r.dt),
                    bbox: [xmin, xmax, zmin, zmax],
                    packet: at.packet,
                    frame_in_packet: at.frame_in_packet,
                    packet_size: p.schedule.packet_size,
                    ..Default::default()
                };
                h.common.frame_id = at.frame_id;
                h.common.t_valid = at.t;
                let (seed, sigma) = (p.seed, p.amplitude_sigma);
                out.publish_in_place(n, h, |dst| {
                    for (d, &i) in dst.iter_mut().zip(&idx) {
                        d.write(ParticleV1 {
                            id: ps.id[i] as u32,
                            kind: PARTICLE_FLUID,
                            x: ps.x[i] as f32,
                            z: ps.z[i] as f32,
                            vx: ps.vx[i] as f32,
                            vz: ps.vz[i] as f32,
                            amplitude: amplitude(seed, ps.id[i], sigma),
                            reserved: 0.0,
                        });
                    }
                })?;
                kit.stats.messages_out += 1;
                kit.stats.bytes_out += (n * 32) as u64;
                kit.record(at.frame_id, at.t, solver_cpu + (thread_cpu_ns() - t0))?;
                solver_cpu = 0;
                if let Some(so) = stats_out.as_mut() {
                    publish_stats(so, &solver, at.frame_id, 0)?;
                }
                last_t = at.t;
                frame_done += 1;
                kit.progress((((solver.time() - t_start) * 1e4) as u64).min(total_ms), total_ms);
            }
            Event::Truth { packet, t, frame_id } => {
                let (Some(g), Some(tout)) = (grid.as_ref(), truth_out.as_mut()) else { continue };
                let t0 = thread_cpu_ns();
                let field = solver.sample_velocity(&gx, &gz);
                let nn = field.len();
                let mut vh = VectorFieldHeaderV1 {
                    grid: GridV1 { x0: g.x0, z0: g.z0, dx: g.dx, dz: g.dz, nx: g.nx, nz: g.nz },
                    n_planes: 3,
                    source: VECTOR_TRUTH,
                    packet: *packet,
                    converged: 1,
                    ..Default::default()
                };
                vh.plane_ids[..3].copy_from_slice(&[plane::VX, plane::VZ, plane::MASK]);
                vh.common.frame_id = *frame_id;
                vh.common.t_valid = *t;
                tout.publish_in_place(3 * nn, vh, |dst| {
                    for i in 0..nn {
                        let m = inside[i];
                        dst[i].write(if m { field[i][0] as f32 } else { 0.0 });
                        dst[nn + i].write(if m { field[i][1] as f32 } else { 0.0 });
                        dst[2 * nn + i].write(if m { 1.0 } else { 0.0 });
                    }
                })?;
                kit.stats.messages_out += 1;
                kit.record(*frame_id, *t, thread_cpu_ns() - t0)?;
            }
        }
    }
    if t_end > solver.time() && kit.check_termination().is_ok() {
        advance(&mut solver, t_end, &mut kit, &mut stats_out, &mut solver_cpu, &mut next_stats)?;
    }
    if let Some(so) = stats_out.as_mut() {
        publish_stats(so, &solver, 0, solver_cpu)?;
    }
    let d = solver.diagnostics();
    let out_total: Real = d.boundaries.iter().skip(1).map(|(_, f)| f.mass_out - f.mass_in).sum();
    let split: Vec<String> = d
        .boundaries
        .iter()
        .skip(1)
        .map(|(n, f)| match out_total > 0.0 {
            true => format!("{n} {:.2} %", 100.0 * (f.mass_out - f.mass_in) / out_total),
            false => format!("{n} (no outflow yet)"),
        })
        .collect();
    eprintln!(
        "sph-flow: t = {:.4} s, {} steps, {frame_done} frames, max |rho/rho0-1| {:.2e}, guard {}, outflow split {}",
        d.time,
        d.steps,
        d.max_density_error,
        d.guard_corrections,
        split.join(", ")
    );
    if let Some(path) = &p.checkpoint_out {
        let path = match (&kit.cfg.out_dir, path.is_relative()) {
            (Some(dir), true) => std::path::Path::new(dir).join(path),
            _ => path.clone(),
        };
        solver.checkpoint().write(&path)?;
        eprintln!("sph-flow: checkpoint at t = {} s written to {}", solver.time(), path.display());
    }
    out.publish_eos(last_t)?;
    if let Some(t) = truth_out.as_mut() {
        t.publish_eos(last_t)?;
    }
    if let Some(s) = stats_out.as_mut() {
        s.publish_eos(solver.time())?;
    }
    kit.finish()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn amplitudes_are_a_function_of_seed_and_id_with_the_requested_spread() {
        assert_eq!(amplitude(3, 17, 1.0), amplitude(3, 17, 1.0));
        assert_ne!(amplitude(3, 17, 1.0), amplitude(4, 17, 1.0));
        let n = 200_000u64;
        let v: Vec<f64> = (0..n).map(|id| amplitude(1, id, 2.0) as f64).collect();
        let mean = v.iter().sum::<f64>() / n as f64;
        let var = v.iter().map(|a| (a - mean).powi(2)).sum::<f64>() / n as f64;
        // standard errors: mean 2/√n = 0.0045, variance 4·√(2/n) = 0.0126
        assert!(mean.abs() < 0.02, "{mean}");
        assert!((var - 4.0).abs() < 0.06, "{var}");
        let kurt = v.iter().map(|a| (a - mean).powi(4)).sum::<f64>() / n as f64 / (var * var);
        assert!((kurt - 3.0).abs() < 0.1, "Gaussian kurtosis {kurt}");
    }

    #[test]
    fn parameters_are_checked_with_named_fields() {
        let ok = serde_json::json!({ "dx": 0.3e-3, "schedule": { "n_packets": 1 } });
        let p = prepare(&ok).expect("valid");
        assert!((p.solver.h - 0.36e-3).abs() < 1e-15, "h from h_over_dx");
        let e = prepare(&serde_json::json!({ "geometry": "aorta" })).err().expect("bad preset");
        assert!(e.contains("not a preset"), "{e}");
        let e = prepare(&serde_json::json!({ "solver": { "c": -1.0 } })).err().expect("bad c");
        assert!(e.contains("solver.") && e.contains("`c`"), "{e}");
        let e = prepare(&serde_json::json!({ "solver": { "speed_of_sound": 3.0 } })).err().expect("unknown");
        assert!(e.contains("speed_of_sound"), "{e}");
        let e = prepare(&serde_json::json!({ "dx": 0.0 })).err().expect("dx");
        assert!(e.contains("dx"), "{e}");
        let e = prepare(&serde_json::json!({ "inflow": { "type": "cosine", "amplitude": 1.0, "period": -1.0 } }))
            .err()
            .expect("period");
        assert!(e.contains("inflow.period"), "{e}");
        let e =
            prepare(&serde_json::json!({ "run_until": 0.0, "schedule": { "t_start": 0.5 } })).err().expect("run_until");
        assert!(e.contains("run_until"), "{e}");
    }
}
