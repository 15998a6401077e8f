//! The SPH flow as a scatterer producer (what the `sph-flow` node runs, without IPC): builds the
//! vessel scene from [`ProducerParams`], starts the solver (or resumes it from a checkpoint), and
//! advances it through the acquisition schedule, yielding [`Event`]s in time order:
//!
//! * [`Event::Advanced`] after every piece of time stepping; pieces end on the schedule's times
//!   and on the diagnostics instants (every `stats_interval` of simulated time from the start),
//!   where `stats` carries the progress;
//! * [`Event::Snapshot`] at every frame time: the fluid particles (the acoustic scatterers) with
//!   their amplitudes ([`amplitude`]), and the tissue around the lumen (with `tissue`);
//! * [`Event::Truth`] at every packet's mid time (when asked for and a `truth_grid` is given): the
//!   SPH-interpolated velocity on the grid, zero outside the lumen.
//!
//! After the last frame the producer keeps advancing to `run_until` (if later), then ends (`None`).

mod params;

pub use params::{GeometrySpec, InvalidParams, Prepared, ProducerParams, SolverTable};

use std::path::{Path, PathBuf};

pub use sonoflow_analytic_flow::{AcquisitionTime, GridSpec, Particles as Scatterers, Schedule, Truth};

use sonoflow_analytic_flow::{LumenShape, Tissue};

use crate::geometry::{Lumen, SdfGrid, VesselGeometry, VesselScene};
use crate::{Checkpoint, CheckpointError, Diagnostics, ParticleKind, Real, Solver, SphError};

/// Errors of [`Producer::new`] and [`Producer::next_event`].
#[derive(Debug, thiserror::Error)]
pub enum ProducerError {
    /// An invalid parameter.
    #[error(transparent)]
    Params(#[from] InvalidParams),
    /// The scene could not be built.
    #[error(transparent)]
    Geometry(#[from] crate::geometry::GeometryError),
    /// The solver refused its state or blew up.
    #[error(transparent)]
    Solver(#[from] SphError),
    /// The checkpoint could not be read or written.
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    /// The schedule starts before the (resumed) solver's time.
    #[error("schedule: the first frame (t = {first} s) is before the solver's start time {start} s (checkpoint): raise schedule.t_start")]
    ScheduleBeforeStart {
        /// The first frame time \[s\].
        first: Real,
        /// The solver's start time \[s\].
        start: Real,
    },
}

/// Progress in units of 0.1 ms of simulated time from the start: `done` of `total`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Progress {
    /// Simulated time done.
    pub done: u64,
    /// Simulated time to do (≥ 1).
    pub total: u64,
}

/// The fluid particles at one frame time.
#[derive(Clone, Debug, PartialEq)]
pub struct Snapshot {
    /// The frame.
    pub at: AcquisitionTime,
    /// Frames per packet of the schedule.
    pub packet_size: u32,
    /// The solver's last time step \[s\] (0 before the first step).
    pub dt: Real,
    /// Bounding box of the fluid particles \[xmin, xmax, zmin, zmax\] (m, f32).
    pub bbox: [f32; 4],
    /// The fluid particles in solver order: id (the solver's stable id, truncated to u32),
    /// position and velocity (f32), amplitude ([`amplitude`]).
    pub particles: Scatterers,
    /// The tissue scatterers (empty without `tissue`; ids from [`TISSUE_FIRST_ID`]).
    pub tissue: Scatterers,
    /// True when the tissue moves (a wall pulsation).
    pub tissue_moves: bool,
    /// Progress after the frame.
    pub progress: Progress,
}

/// The SPH-interpolated velocity on the truth grid at a packet's mid time.
#[derive(Clone, Debug, PartialEq)]
pub struct TruthField {
    /// The packet.
    pub packet: u32,
    /// Its mid time \[s\].
    pub t: Real,
    /// The id of the packet's middle frame (`packet · packet_size + packet_size / 2`).
    pub frame_id: u64,
    /// The grid.
    pub grid: GridSpec,
    /// Velocity (0 outside the lumen) and mask (1 inside the lumen), row-major `iz · nx + ix`.
    pub truth: Truth,
}

/// What [`Producer::next_event`] did.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// The solver advanced by one piece, to `time`; `stats` is set when the piece reached a
    /// diagnostics instant (read [`Producer::diagnostics`] then).
    Advanced {
        /// Simulated time now \[s\].
        time: Real,
        /// Progress, at a diagnostics instant only.
        stats: Option<Progress>,
    },
    /// A frame's particles.
    Snapshot(Box<Snapshot>),
    /// A packet's ground truth.
    Truth(TruthField),
}

/// A scheduled output.
#[derive(Clone, Copy, Debug)]
enum Scheduled {
    Frame(AcquisitionTime),
    Truth { packet: u32, t: Real, frame_id: u64 },
}

/// The truth grid's nodes and whether each lies in the lumen.
#[derive(Clone, Debug)]
struct TruthGrid {
    spec: GridSpec,
    xs: Vec<Real>,
    zs: Vec<Real>,
    inside: Vec<bool>,
    /// The lumen's signed distance (for the mask in the vessel's frame under bulk motion).
    sdf: SdfGrid,
}

/// The SPH flow through an acquisition schedule (see the module documentation).
pub struct Producer {
    params: ProducerParams,
    solver: Solver,
    events: Vec<(Real, Scheduled)>,
    next: usize,
    grid: Option<TruthGrid>,
    t_start: Real,
    t_end: Real,
    total: u64,
    next_stats: Real,
    frames_done: usize,
    last_frame_t: Real,
    log: Vec<String>,
    tissue: Tissue,
    /// With `tissue.pulsation.waveform = "inflow"`: the inflow waveform, the wall's delay t₀ and
    /// the waveform's (min, max) over its cycle.
    wall_waveform: Option<(crate::waveform::Waveform, Real, (Real, Real))>,
}

/// Offset \[m\] of particle `id`'s scatterer from the particle for position seed `seed`: uniform
/// in [−dx/2, dx/2)², fixed for the particle's life (SplitMix64 of (seed, id); platform-independent).
/// The scatterer moves with its particle, so its velocity is the particle's: the error against
/// the fluid's velocity at the scatterer's own position is at most |∇u|·dx/√2 (the SPH
/// interpolation error is of the same order).
pub fn scatterer_offset(seed: u64, id: u64, dx: Real) -> [Real; 2] {
    let unit = |lane: u64| {
        let mut z = seed ^ id.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ lane.wrapping_mul(0xD1B5_4A32_D192_ED03);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as Real / (1u64 << 53) as Real
    };
    [(unit(1) - 0.5) * dx, (unit(2) - 0.5) * dx]
}

/// First id of the tissue scatterers of an SPH scene (2³¹: above the solver's particle ids).
pub const TISSUE_FIRST_ID: u32 = 1 << 31;

/// The lumen of an SPH vessel for tissue seeding: the signed distance to the wall of the lumen
/// with its open ends extended straight by 1 m (so that the tissue continues beside a vessel
/// that leaves the domain, instead of closing over its opening); the outward normal is the
/// distance's gradient (central differences, 1 µm).
pub struct SphLumen(Lumen);

impl SphLumen {
    /// The lumen of `geometry`.
    pub fn new(geometry: &VesselGeometry) -> Self {
        SphLumen(Lumen::new(geometry, &geometry.openings(), 1.0))
    }
}

impl LumenShape for SphLumen {
    fn outside_distance(&self, x: f64, z: f64) -> f64 {
        self.0.signed_distance_with_reservoirs(x, z)
    }
    fn outward_normal(&self, x: f64, z: f64) -> (f64, f64) {
        let h = 1e-6;
        let gx = self.outside_distance(x + h, z) - self.outside_distance(x - h, z);
        let gz = self.outside_distance(x, z + h) - self.outside_distance(x, z - h);
        let n = gx.hypot(gz);
        if n > 0.0 && n.is_finite() {
            (gx / n, gz / n)
        } else {
            (0.0, 0.0)
        }
    }
}

impl Producer {
    /// Builds the scene of `prep` and the solver: from the checkpoint `checkpoint_in` if given
    /// (its open boundaries must be this scene's), else from the scene's initial state. `truth`:
    /// produce [`Event::Truth`] (with a `truth_grid`). Log lines for the caller:
    /// [`Producer::take_log`].
    pub fn new(prep: &Prepared, truth: bool) -> Result<Self, ProducerError> {
        let p = &prep.params;
        let mut log = Vec::new();
        let t_build = std::time::Instant::now();
        let scene: VesselScene = prep.geometry.build(&prep.build)?;
        let names: Vec<String> = scene.boundaries.iter().map(|b| b.name.clone()).collect();
        log.push(format!(
            "{} particles ({} fluid, {} wall, {} reservoir), boundaries {:?}, built in {:.2} s; h = {:.3} mm, c = {} m/s",
            scene.particles.len(),
            scene.count(ParticleKind::Fluid),
            scene.count(ParticleKind::WallOn) + scene.count(ParticleKind::WallOutside),
            scene.count(ParticleKind::Buffer),
            names,
            t_build.elapsed().as_secs_f64(),
            prep.solver.h * 1e3,
            prep.solver.c
        ));
        let domain = scene.guard_domain();
        let solver = match &p.checkpoint_in {
            Some(path) => {
                let ck = Checkpoint::read(path)?;
                let t = ck.header.time;
                if ck.header.params != prep.solver {
                    log.push(
                        "note: the checkpoint was written with other solver parameters; continuing with this run's"
                            .into(),
                    );
                }
                if p.position_seed.is_some() {
                    log.push(
                        "note: position_seed is ignored when resuming from a checkpoint (its particles are used)"
                            .into(),
                    );
                }
                let s = Solver::from_checkpoint(prep.solver.clone(), ck, scene.boundaries.clone(), &[])?;
                log.push(format!("resumed from {} at t = {t} s", path.display()));
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
                return Err(ProducerError::ScheduleBeforeStart { first: first.t, start: t_start });
            }
        }
        // events in time order: frames and (with a truth grid) packet mid times
        let mut events: Vec<(Real, Scheduled)> = frames.iter().map(|a| (a.t, Scheduled::Frame(*a))).collect();
        let grid = match (&p.truth_grid, truth) {
            (Some(g), true) => Some(truth_grid(g, &scene)),
            _ => None,
        };
        if grid.is_some() {
            for k in 0..p.schedule.n_packets {
                let frame_id = k as u64 * p.schedule.packet_size as u64 + (p.schedule.packet_size / 2) as u64;
                let t = p.schedule.packet_mid_time(k);
                events.push((t, Scheduled::Truth { packet: k, t, frame_id }));
            }
        }
        events.sort_by(|a, b| a.0.total_cmp(&b.0));
        let t_end = p.run_until.unwrap_or(p.schedule.end_time()).max(t_start);
        let tissue = match &p.tissue {
            Some(t) => {
                let blood_density = 1e-6 / (p.dx * p.dx);
                let lumen = SphLumen::new(&prep.geometry);
                let tissue = Tissue::new(t, &lumen, blood_density, f64::from(p.amplitude_sigma), TISSUE_FIRST_ID)
                    .map_err(|e| InvalidParams::new(e.field(), e.to_string()))?;
                log.push(format!(
                    "tissue: {} scatterers outside the lumen, {} dB above the blood{}",
                    tissue.particles().len(),
                    t.tissue_to_blood_db,
                    if tissue.pulsates() { ", pulsating wall" } else { ", static" }
                ));
                tissue
            }
            None => Tissue::default(),
        };
        let wall_waveform = match p.tissue.as_ref().and_then(|t| t.pulsation.as_ref()) {
            Some(pu) if pu.waveform == sonoflow_analytic_flow::PulsationWaveform::Inflow => {
                let (lo, hi) = prep.build.inflow.range();
                if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
                    return Err(InvalidParams::new(
                        "tissue.pulsation.waveform",
                        "tissue.pulsation.waveform = \"inflow\" needs a pulsatile inflow (this one is constant): use \"raised-cosine\"",
                    )
                    .into());
                }
                Some((prep.build.inflow.clone(), pu.t0, (lo, hi)))
            }
            _ => None,
        };
        // progress in units of 0.1 ms of simulated time
        let total = (((t_end - t_start) * 1e4).ceil() as u64).max(1);
        Ok(Producer {
            params: p.clone(),
            solver,
            events,
            next: 0,
            grid,
            t_start,
            t_end,
            total,
            next_stats: t_start,
            frames_done: 0,
            last_frame_t: t_start,
            log,
            tissue,
            wall_waveform,
        })
    }

    /// The log lines written since the last call (scene summary, checkpoint notes).
    pub fn take_log(&mut self) -> Vec<String> {
        std::mem::take(&mut self.log)
    }

    /// Advances to the next output or by one piece of time stepping; `None` once the schedule
    /// and `run_until` are done.
    pub fn next_event(&mut self) -> Result<Option<Event>, ProducerError> {
        let to = self.events.get(self.next).map_or(self.t_end, |e| e.0);
        let s = &mut self.solver;
        // advance in pieces no longer than the stats interval (progress and diagnostics on long gaps)
        if s.time() < to {
            let target = to.min(self.next_stats).max(s.time());
            s.advance_to(if target > s.time() { target } else { to })?;
            let mut stats = None;
            if s.time() >= self.next_stats {
                self.next_stats += self.params.stats_interval;
                stats = Some(self.progress());
            }
            return Ok(Some(Event::Advanced { time: self.solver.time(), stats }));
        }
        let Some(&(_, ev)) = self.events.get(self.next) else { return Ok(None) };
        self.next += 1;
        Ok(Some(match ev {
            Scheduled::Frame(at) => {
                let snapshot = self.snapshot(at);
                self.last_frame_t = at.t;
                self.frames_done += 1;
                Event::Snapshot(Box::new(snapshot))
            }
            Scheduled::Truth { packet, t, frame_id } => {
                let Some(g) = self.grid.as_ref() else { return self.next_event() };
                let rigid = self.params.bulk.as_ref().map(|b| b.at(t));
                // under bulk motion: each lab node's point in the vessel's frame, and its mask there
                let moved: Option<(Vec<Real>, Vec<Real>, Vec<bool>)> = rigid.map(|r| {
                    let pts: Vec<(Real, Real)> = g.xs.iter().zip(&g.zs).map(|(&x, &z)| r.invert(x, z)).collect();
                    let inside = pts.iter().map(|&(x, z)| g.sdf.is_inside(x, z)).collect();
                    (pts.iter().map(|p| p.0).collect(), pts.iter().map(|p| p.1).collect(), inside)
                });
                let (xs, zs, inside) = match &moved {
                    Some((xs, zs, inside)) => (xs, zs, inside),
                    None => (&g.xs, &g.zs, &g.inside),
                };
                let field = self.solver.sample_velocity(xs, zs);
                let nn = field.len();
                let mut truth =
                    Truth { vx: Vec::with_capacity(nn), vz: Vec::with_capacity(nn), mask: Vec::with_capacity(nn) };
                for (i, (f, &m)) in field.iter().zip(inside).enumerate() {
                    let v = match &rigid {
                        Some(r) => {
                            let a = r.apply(xs[i], zs[i], f[0], f[1]);
                            [a[2], a[3]]
                        }
                        None => [f[0], f[1]],
                    };
                    truth.vx.push(if m { v[0] as f32 } else { 0.0 });
                    truth.vz.push(if m { v[1] as f32 } else { 0.0 });
                    truth.mask.push(m as u8);
                }
                Event::Truth(TruthField { packet, t, frame_id, grid: g.spec.clone(), truth })
            }
        }))
    }

    fn snapshot(&mut self, at: AcquisitionTime) -> Snapshot {
        let rigid = self.params.bulk.as_ref().map(|b| b.at(at.t));
        match &self.wall_waveform {
            Some((u, t0, (lo, hi))) => {
                let s = at.t - t0;
                self.tissue.place(((u.value(s) - lo) / (hi - lo), u.derivative(s) / (hi - lo)), rigid.as_ref());
            }
            None => self.tissue.update(at.t, rigid.as_ref()),
        }
        let ps = &self.solver.particles;
        let idx: Vec<usize> = (0..ps.len()).filter(|&i| ps.kind[i] == ParticleKind::Fluid).collect();
        let (seed, sigma) = (self.params.seed, self.params.amplitude_sigma);
        let offset = |i: usize| match self.params.position_seed {
            Some(s) => scatterer_offset(s, ps.id[i], self.params.dx),
            None => [0.0, 0.0],
        };
        let offsets: Vec<[Real; 2]> = idx.iter().map(|&i| offset(i)).collect();
        // position and velocity in the lab frame (the vessel's own without bulk motion)
        let lab: Vec<[Real; 4]> = idx
            .iter()
            .zip(&offsets)
            .map(|(&i, o)| {
                let (x, z, vx, vz) = (ps.x[i] + o[0], ps.z[i] + o[1], ps.vx[i], ps.vz[i]);
                match &rigid {
                    Some(r) => r.apply(x, z, vx, vz),
                    None => [x, z, vx, vz],
                }
            })
            .collect();
        let particles = Scatterers {
            id: idx.iter().map(|&i| ps.id[i] as u32).collect(),
            x: lab.iter().map(|l| l[0] as f32).collect(),
            z: lab.iter().map(|l| l[1] as f32).collect(),
            vx: lab.iter().map(|l| l[2] as f32).collect(),
            vz: lab.iter().map(|l| l[3] as f32).collect(),
            amplitude: idx.iter().map(|&i| amplitude(seed, ps.id[i], sigma)).collect(),
        };
        Snapshot {
            at,
            packet_size: self.params.schedule.packet_size,
            dt: self.solver.last_step().map_or(0.0, |r| r.dt),
            bbox: particles.bbox(),
            particles,
            tissue: self.tissue.particles().clone(),
            tissue_moves: self.tissue.pulsates() || (rigid.is_some() && !self.tissue.particles().is_empty()),
            progress: self.progress(),
        }
    }

    /// Progress now.
    pub fn progress(&self) -> Progress {
        let done = (((self.solver.time() - self.t_start) * 1e4) as u64).min(self.total);
        Progress { done, total: self.total }
    }

    /// The solver's diagnostics now.
    pub fn diagnostics(&self) -> Diagnostics {
        self.solver.diagnostics()
    }

    /// The solver.
    pub fn solver(&self) -> &Solver {
        &self.solver
    }

    /// Simulated time now \[s\].
    pub fn time(&self) -> Real {
        self.solver.time()
    }

    /// Time of the last frame produced \[s\] (the start time before the first).
    pub fn last_frame_time(&self) -> Real {
        self.last_frame_t
    }

    /// One line on the run so far: time, steps, frames, density error, guard corrections and the
    /// mass split of the outflow over the outlets, e.g. `outflow split internal 54.03 %, external
    /// 45.97 %`.
    pub fn summary(&self) -> String {
        let d = self.solver.diagnostics();
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
        format!(
            "t = {:.4} s, {} steps, {} frames, max |rho/rho0-1| {:.2e}, guard {}, outflow split {}",
            d.time,
            d.steps,
            self.frames_done,
            d.max_density_error,
            d.guard_corrections,
            split.join(", ")
        )
    }

    /// Writes the state to `checkpoint_out` (a relative path under `run_dir` when given) and
    /// returns the path; `None` without `checkpoint_out`.
    pub fn write_checkpoint(&self, run_dir: Option<&Path>) -> Result<Option<PathBuf>, CheckpointError> {
        let Some(path) = &self.params.checkpoint_out else { return Ok(None) };
        let path = match (run_dir, path.is_relative()) {
            (Some(dir), true) => dir.join(path),
            _ => path.clone(),
        };
        self.solver.checkpoint().write(&path)?;
        Ok(Some(path))
    }
}

/// The nodes of `g` and whether each lies in the lumen of `scene`.
fn truth_grid(g: &GridSpec, scene: &VesselScene) -> TruthGrid {
    let (mut xs, mut zs, mut inside) = (Vec::new(), Vec::new(), Vec::new());
    for iz in 0..g.nz {
        for ix in 0..g.nx {
            let (x, z) = (g.x0 + ix as f64 * g.dx, g.z0 + iz as f64 * g.dz);
            xs.push(x);
            zs.push(z);
            inside.push(scene.is_inside(x, z));
        }
    }
    TruthGrid { spec: g.clone(), xs, zs, inside, sdf: scene.sdf.clone() }
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

#[cfg(test)]
mod tests;
