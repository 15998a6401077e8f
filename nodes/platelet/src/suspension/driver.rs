//! A suspension run as the `platelets` node runs it, without any IPC: the node's parameters
//! ([`PlateletsParams`]: the suspension's plus the output schedule and the mapping into imaging
//! coordinates of [`OutputParams`]), the seeding, the per-macro-step bookkeeping (fluid snapshots
//! paired with macro steps, timings, diagnostics) and the platelet states to publish
//! ([`Driver`]). The caller (the node adapter) supplies the fluid snapshots through a
//! [`FluidSource`] and publishes what [`Driver::states`] gives.
//!
//! **Schedule**: the initial (relaxed) state at t = t₀ if `publish_initial`, then a snapshot after
//! every `publish_every`-th of the `n_macro_steps` macro steps (t = t₀ + k · sub_step · sub_steps),
//! with frame ids 0, 1, …. t₀ = 0 for an analytic carrier. Following an acquisition schedule (PRF
//! times inside a macro step) is future work.
//!
//! **SPH carrier** (`carrier = { type = "particles", … }`, [`ParticleCarrier`](super::ParticleCarrier);
//! the node's input `particles` must be wired, and that input needs this carrier:
//! [`check_fluid_input`]): each fluid snapshot's particles (positions and velocities in imaging
//! coordinates, as the source gives them) are mapped into channel coordinates with the inverse of
//! the output mapping below (any `angle_deg`), then interpolated onto the lattice (SPH kernel fit,
//! first order by default, fluid-fraction mask, eq 12 per cell: `dynamics::sph_interp`). The first
//! snapshot fixes t₀ (its time), seeds the platelets and relaxes them. As in Algorithm 2
//! (Navier–Stokes t_{n−1} → t_n, transfer, particles t_{n−1} → t_n), the macro step [t, t + k]
//! uses the latest snapshot with time ≤ t + k (to within 1e-6 k): the driver reads the source
//! until it holds a later snapshot or the end of the stream, so the pairing depends only on the
//! snapshot times, never on process timing; the lattice is refilled only when that snapshot
//! changes. Snapshots finer than k are skipped; coarser ones carry several macro steps (frozen
//! flow). After the fluid stream ends the last snapshot carries the remaining macro steps (logged).
//! Once the platelets are done, [`Driver::drain`] reads the source to its end, so that a fluid
//! producer waiting for its subscribers can finish.
//!
//! **Mapping** ([`FrameMap`]): channel point (x, y) → imaging (x0, z0) + R(angle) (x, y), with R
//! the rotation by `angle_deg` from the imaging x axis towards +z (depth); velocities rotate the
//! same way; fluid particles come back with Rᵀ. Amplitudes: N(0, amplitude_sigma²) per particle
//! id, drawn once from `seed` (like the analytic-flow node), so the platelets can be scatterers too.
//!
//! **Timing**: per published snapshot the thread CPU time of the macro steps and lattice fills
//! since the last one ([`Frame::compute_ns`], from [`Hooks::cpu_ns`]); the split advection /
//! collisions (+ walls, sort) / coefficients (wall clock, from the dynamics) and, with an SPH
//! carrier, the lattice fills go to [`Hooks::log`] per snapshot and in a summary line, and into
//! the [`TimingReport`] of [`Driver::finish`].

use super::{CarrierParams, Suspension, SuspensionError, SuspensionParams};
use crate::dynamics::{DynamicsError, FillReport, Timings};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use std::time::Instant;

/// Node-only parameters (module doc).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OutputParams {
    /// Macro steps to run (each `dynamics.sub_steps` × `dynamics.sub_step`). Default 10.
    pub n_macro_steps: u64,
    /// Publish a snapshot every this many macro steps (1 ..= n_macro_steps). Default 1.
    pub publish_every: u64,
    /// Publish the initial state at t = 0 as well. Default true.
    pub publish_initial: bool,
    /// Imaging coordinates (x, z) \[m\] of the channel's (0, 0). Default (−6 mm, 19 mm): the
    /// 12 mm × 2 mm channel centred at 20 mm depth.
    pub origin: [f64; 2],
    /// Rotation of the channel's x axis from the imaging x axis towards +z \[deg\]. Default 0.
    pub angle_deg: f64,
    /// Standard deviation of the scattering amplitudes (> 0). Default 1.
    pub amplitude_sigma: f64,
}

impl Default for OutputParams {
    fn default() -> Self {
        OutputParams {
            n_macro_steps: 10,
            publish_every: 1,
            publish_initial: true,
            origin: [-6e-3, 19e-3],
            angle_deg: 0.0,
            amplitude_sigma: 1.0,
        }
    }
}

fn out_of_range(field: impl Into<String>, value: impl std::fmt::Display, allowed: String) -> SuspensionError {
    SuspensionError::OutOfRange { field: field.into(), value: value.to_string(), allowed }
}

fn in_range<T: PartialOrd + std::fmt::Display>(field: &str, v: T, lo: T, hi: T) -> Result<(), SuspensionError> {
    if v >= lo && v <= hi {
        Ok(())
    } else {
        Err(out_of_range(field, v, format!("{lo} ..= {hi}")))
    }
}

impl OutputParams {
    /// The keys of these parameters among the node's.
    pub const KEYS: [&'static str; 6] =
        ["n_macro_steps", "publish_every", "publish_initial", "origin", "angle_deg", "amplitude_sigma"];

    /// Every field in its range (the error names it).
    pub fn validate(&self) -> Result<(), SuspensionError> {
        in_range("n_macro_steps", self.n_macro_steps, 1, 1_000_000)?;
        in_range("publish_every", self.publish_every, 1, self.n_macro_steps)?;
        for (i, o) in self.origin.iter().enumerate() {
            if !(o.is_finite() && o.abs() <= 1.0) {
                return Err(out_of_range(format!("origin[{i}]"), o, "-1 ..= 1 m".into()));
            }
        }
        in_range("angle_deg", self.angle_deg, -360.0, 360.0)?;
        if !(self.amplitude_sigma.is_finite() && self.amplitude_sigma > 0.0 && self.amplitude_sigma <= 1e6) {
            return Err(out_of_range("amplitude_sigma", self.amplitude_sigma, "0 < amplitude_sigma <= 1e6".into()));
        }
        Ok(())
    }

    /// Snapshots published in all.
    pub fn n_snapshots(&self) -> u64 {
        self.publish_initial as u64 + self.n_macro_steps / self.publish_every
    }
}

/// The `[params]` of the `platelets` node: the keys of [`OutputParams`] and those of
/// [`SuspensionParams`] side by side in one table (unknown keys are refused, naming them).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct PlateletsParams {
    /// The suspension.
    #[serde(flatten)]
    pub suspension: SuspensionParams,
    /// Output schedule and mapping.
    #[serde(flatten)]
    pub output: OutputParams,
}

/// Deserialises with the path of the offending field in the message (`carrier: unknown field …`).
fn from_value<T: serde::de::DeserializeOwned>(v: serde_json::Value) -> Result<T, String> {
    serde_path_to_error::deserialize(v).map_err(|e| {
        let path = e.path().to_string();
        if path == "." {
            e.inner().to_string()
        } else {
            format!("{path}: {}", e.inner())
        }
    })
}

impl<'de> serde::Deserialize<'de> for PlateletsParams {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        let mut v = serde_json::Value::deserialize(d)?;
        if v.is_null() {
            v = serde_json::json!({});
        }
        let mut out = serde_json::Map::new();
        if let Some(o) = v.as_object_mut() {
            for k in OutputParams::KEYS {
                if let Some(x) = o.remove(k) {
                    out.insert(k.to_string(), x);
                }
            }
        }
        let output = from_value(serde_json::Value::Object(out)).map_err(D::Error::custom)?;
        let suspension = from_value(v).map_err(D::Error::custom)?;
        Ok(PlateletsParams { suspension, output })
    }
}

impl PlateletsParams {
    /// Every field in its range, and the weights exist (without loading them).
    pub fn validate(&self) -> Result<(), SuspensionError> {
        self.output.validate()?;
        self.suspension.validate()?;
        self.suspension.check_weights()
    }
}

/// The carrier `particles` and the node's input `particles` (the fluid snapshots) go together:
/// checks the raw node params (`carrier.type`) against whether that input is wired.
pub fn check_fluid_input(params: &serde_json::Value, input_wired: bool) -> Result<(), String> {
    let carrier = params.get("carrier").and_then(|c| c.get("type")).and_then(|t| t.as_str());
    match (carrier == Some("particles"), input_wired) {
        (true, false) => Err(
            "carrier type \"particles\" needs the input `particles` wired to a fluid producer (e.g. `inputs = { particles = \"fluid\" }` with an sph-flow node's output)"
                .into(),
        ),
        (false, true) => Err(format!(
            "input `particles` is wired but carrier type {} does not read it: use carrier = {{ type = \"particles\", … }} or remove the input",
            carrier.map_or("\"stenosis\" (the default)".to_string(), |c| format!("{c:?}"))
        )),
        _ => Ok(()),
    }
}

/// Imaging ↔ channel coordinates (module doc).
#[derive(Clone, Copy, Debug)]
pub struct FrameMap {
    origin: [f64; 2],
    sin: f64,
    cos: f64,
}

impl FrameMap {
    /// The mapping of `origin` and `angle_deg`.
    pub fn new(op: &OutputParams) -> Self {
        let (sin, cos) = op.angle_deg.to_radians().sin_cos();
        FrameMap { origin: op.origin, sin, cos }
    }
    /// Channel (x, y) → imaging (x, z).
    pub fn to_imaging(self, p: [f64; 2]) -> [f64; 2] {
        [self.origin[0] + self.cos * p[0] - self.sin * p[1], self.origin[1] + self.sin * p[0] + self.cos * p[1]]
    }
    /// A velocity in channel axes → imaging axes.
    pub fn vel_to_imaging(self, v: [f64; 2]) -> [f64; 2] {
        [self.cos * v[0] - self.sin * v[1], self.sin * v[0] + self.cos * v[1]]
    }
    /// Imaging (x, z) → channel (x, y).
    pub fn to_channel(self, q: [f64; 2]) -> [f64; 2] {
        self.vel_to_channel([q[0] - self.origin[0], q[1] - self.origin[1]])
    }
    /// A velocity in imaging axes → channel axes.
    pub fn vel_to_channel(self, v: [f64; 2]) -> [f64; 2] {
        [self.cos * v[0] + self.sin * v[1], -self.sin * v[0] + self.cos * v[1]]
    }
}

/// One fluid snapshot: filled by a [`FluidSource`] in imaging coordinates, kept by the driver in
/// channel coordinates.
#[derive(Clone, Debug, Default)]
pub struct FluidSnapshot {
    /// Time \[s\].
    pub t: f64,
    /// Frame id (for messages).
    pub frame_id: u64,
    /// Fluid particle positions \[m\].
    pub pos: Vec<[f64; 2]>,
    /// Fluid particle velocities \[m/s\].
    pub vel: Vec<[f64; 2]>,
}

/// What [`FluidSource::next`] got.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Received {
    /// A snapshot (in the buffer given).
    Snapshot,
    /// The end of the stream.
    Ended,
    /// The caller was asked to stop (e.g. SIGTERM) while waiting.
    Stopped,
}

/// Where the fluid snapshots of a `particles` carrier come from (the node's input). Never read
/// for an analytic carrier.
pub trait FluidSource {
    /// The caller's error type (driver errors convert into it).
    type Error: From<DriverError>;
    /// Waits for the next message. On [`Received::Snapshot`], `into` (positions and velocities
    /// cleared) holds the snapshot's time and frame id and its fluid particles' positions (x, z)
    /// and velocities (vx, vz) in imaging coordinates.
    fn next(&mut self, into: &mut FluidSnapshot) -> Result<Received, Self::Error>;
    /// The stream's name for messages (e.g. the topic).
    fn name(&self) -> String;
}

/// Errors of a [`Driver`].
#[derive(Debug, thiserror::Error)]
pub enum DriverError {
    /// Building the suspension or filling its lattice.
    #[error(transparent)]
    Suspension(#[from] SuspensionError),
    /// A macro step.
    #[error(transparent)]
    Dynamics(#[from] DynamicsError),
    /// The amplitude distribution.
    #[error(transparent)]
    Amplitude(#[from] rand_distr::NormalError),
    /// A fluid stream the carrier cannot use.
    #[error("{0}")]
    Fluid(String),
}

/// What the driver needs from its caller besides the fluid.
#[derive(Clone, Copy, Debug)]
pub struct Hooks {
    /// CPU clock of the calling thread \[ns\], read around each macro step ([`Frame::compute_ns`]).
    pub cpu_ns: fn() -> u64,
    /// Takes one line of diagnostics (no prefix, no newline).
    pub log: fn(&str),
}

impl Default for Hooks {
    /// No clock (0), no log.
    fn default() -> Self {
        Hooks { cpu_ns: || 0, log: |_| {} }
    }
}

/// A snapshot to publish: the driver's current state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// 0, 1, … in publishing order.
    pub frame_id: u64,
    /// Time of the state \[s\].
    pub t: f64,
    /// Thread CPU time of the macro steps (and lattice fills) since the last snapshot \[ns\].
    pub compute_ns: u64,
}

/// One platelet as published: imaging coordinates, single precision.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlateletState {
    /// Particle id (seeding order).
    pub id: u32,
    /// Position x \[m\].
    pub x: f32,
    /// Position z (depth) \[m\].
    pub z: f32,
    /// Velocity x \[m/s\].
    pub vx: f32,
    /// Velocity z \[m/s\].
    pub vz: f32,
    /// Scattering amplitude.
    pub amplitude: f32,
}

/// Time split of a run (written to `<node>.json` by the node).
#[derive(Clone, Debug, serde::Serialize)]
pub struct TimingReport {
    pub particles: usize,
    pub macro_steps: u64,
    pub sub_steps: u64,
    pub model: String,
    pub advection_s: f64,
    pub collisions_s: f64,
    pub coefficients_s: f64,
    pub compute_cpu_s: f64,
    pub pairs: usize,
    pub impulses: usize,
    pub wall_hits: usize,
    /// SPH carrier only: fluid snapshots received, lattice fills, their wall-clock time.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fluid: Option<FluidReport>,
}

/// The fluid part of a [`TimingReport`].
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct FluidReport {
    pub snapshots_received: u64,
    pub lattice_fills: u64,
    pub lattice_s: f64,
    pub first_t: f64,
    pub last_used_t: f64,
    /// Valid lattice nodes / all nodes at the last fill.
    pub valid_nodes: usize,
    pub nodes: usize,
    pub particle_volume_m2: f64,
}

/// The fluid stream: the snapshot in use and the next one, paired with macro steps by time.
#[derive(Default)]
struct Fluid {
    current: Option<FluidSnapshot>,
    pending: Option<FluidSnapshot>,
    spare: FluidSnapshot,
    /// End of stream seen.
    ended: bool,
    /// Stop request while waiting.
    terminated: bool,
    report: FluidReport,
}

impl Fluid {
    /// Takes one message into `pending` (which must be empty).
    fn receive<S: FluidSource>(&mut self, src: &mut S, map: FrameMap) -> Result<(), S::Error> {
        let mut snap = std::mem::take(&mut self.spare);
        snap.pos.clear();
        snap.vel.clear();
        match src.next(&mut snap)? {
            Received::Ended => self.ended = true,
            Received::Stopped => self.terminated = true,
            Received::Snapshot => {
                for p in &mut snap.pos {
                    *p = map.to_channel(*p);
                }
                for v in &mut snap.vel {
                    *v = map.vel_to_channel(*v);
                }
                if !snap.t.is_finite() {
                    let e = format!("fluid snapshot {} on `{}` has t_valid = {}", snap.frame_id, src.name(), snap.t);
                    return Err(DriverError::Fluid(e).into());
                }
                if snap.pos.is_empty() {
                    return Err(DriverError::Fluid(format!(
                        "fluid snapshot {} (t = {} s) on `{}` has no particles of kind PARTICLE_FLUID: wire the input to a fluid producer (sph-flow, analytic-flow)",
                        snap.frame_id,
                        snap.t,
                        src.name()
                    ))
                    .into());
                }
                self.pending = Some(snap);
                return Ok(());
            }
        }
        self.spare = snap;
        Ok(())
    }

    /// Waits for the first snapshot and makes it current (none if stopped).
    fn first<S: FluidSource>(&mut self, src: &mut S, map: FrameMap) -> Result<(), S::Error> {
        while self.pending.is_none() && !self.terminated {
            if self.ended {
                let e = format!("the fluid stream on `{}` ended before its first snapshot", src.name());
                return Err(DriverError::Fluid(e).into());
            }
            self.receive(src, map)?;
        }
        self.current = self.pending.take();
        Ok(())
    }

    /// Makes the latest snapshot with t ≤ t_end + eps current, reading until a later one or the end
    /// of the stream is seen; true if the current snapshot changed.
    fn advance_to<S: FluidSource>(
        &mut self,
        src: &mut S,
        map: FrameMap,
        t_end: f64,
        eps: f64,
    ) -> Result<bool, S::Error> {
        let mut changed = false;
        loop {
            if let Some(p) = &self.pending {
                if p.t > t_end + eps {
                    return Ok(changed);
                }
                if let Some(old) = self.current.take() {
                    self.spare = old;
                }
                self.current = self.pending.take();
                changed = true;
                continue;
            }
            if self.ended || self.terminated {
                return Ok(changed);
            }
            self.receive(src, map)?;
        }
    }
}

fn log_fill(log: fn(&str), what: &str, snap: &FluidSnapshot, r: &FillReport) {
    log(&format!(
        "{what} fluid snapshot {} (t = {:.6} s): {} fluid particles, {} near the lattice, {} of {} nodes with fluid ({} by the Shepard fallback), particle volume {:.3e} m²",
        snap.frame_id, snap.t, r.particles, r.used, r.valid_nodes, r.nodes, r.shepard_fallback, r.volume
    ));
}

/// Seconds of a duration.
fn secs(d: std::time::Duration) -> f64 {
    d.as_secs_f64()
}

/// The `platelets` node's run without IPC (module doc): [`Driver::new`] seeds, [`Driver::initial`]
/// and [`Driver::step`] say what to publish ([`Driver::states`]), [`Driver::finish`] reports.
pub struct Driver {
    params: PlateletsParams,
    s: Suspension,
    map: FrameMap,
    amplitude: Vec<f32>,
    hooks: Hooks,
    fluid: Option<Fluid>,
    /// Macro steps done.
    k: u64,
    /// The next frame id.
    frame: u64,
    stopped: bool,
    total: Timings,
    since: Timings,
    cpu_since: u64,
    cpu_total: u64,
    lattice_since: f64,
    warned_end: bool,
}

impl Driver {
    /// Seeds the suspension (validated params): for a `particles` carrier after waiting for the
    /// first fluid snapshot (`None` if stopped meanwhile); draws the amplitudes.
    pub fn new<S: FluidSource>(params: PlateletsParams, hooks: Hooks, src: &mut S) -> Result<Option<Self>, S::Error> {
        let sp = &params.suspension;
        let n = sp.count();
        let map = FrameMap::new(&params.output);
        let t_setup = Instant::now();
        let (s, fluid) = match sp.carrier {
            CarrierParams::Particles(_) => {
                let mut fl = Fluid::default();
                fl.first(src, map)?;
                let Some(snap) = &fl.current else {
                    (hooks.log)("stopped while waiting for the first fluid snapshot");
                    return Ok(None);
                };
                let (s, rep) = Suspension::with_fluid(sp, snap.t, &snap.pos, &snap.vel).map_err(DriverError::from)?;
                log_fill(hooks.log, "seeded in", snap, &rep);
                fl.report = FluidReport {
                    lattice_fills: 1,
                    first_t: snap.t,
                    last_used_t: snap.t,
                    valid_nodes: rep.valid_nodes,
                    nodes: rep.nodes,
                    particle_volume_m2: rep.volume,
                    ..Default::default()
                };
                (s, Some(fl))
            }
            _ => (Suspension::new(sp).map_err(DriverError::from)?, None),
        };
        (hooks.log)(&format!(
            "{n} platelets, model `{}`, seeded in {:.2} s",
            s.model_name(),
            t_setup.elapsed().as_secs_f64()
        ));
        let normal = Normal::new(0.0, params.output.amplitude_sigma).map_err(DriverError::from)?;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(sp.seed ^ 0x9e37_79b9_7f4a_7c15);
        let amplitude: Vec<f32> = (0..n).map(|_| normal.sample(&mut rng) as f32).collect();
        Ok(Some(Driver {
            params,
            s,
            map,
            amplitude,
            hooks,
            fluid,
            k: 0,
            frame: 0,
            stopped: false,
            total: Timings::default(),
            since: Timings::default(),
            cpu_since: 0,
            cpu_total: 0,
            lattice_since: 0.0,
            warned_end: false,
        }))
    }

    fn frame(&mut self, compute_ns: u64) -> Frame {
        let f = Frame { frame_id: self.frame, t: self.s.time(), compute_ns };
        self.frame += 1;
        f
    }

    /// The initial state to publish, if `publish_initial` (call once, before the steps).
    pub fn initial(&mut self) -> Option<Frame> {
        self.params.output.publish_initial.then(|| self.frame(0))
    }

    /// All macro steps done, or stopped while waiting for fluid.
    pub fn done(&self) -> bool {
        self.stopped || self.k >= self.params.output.n_macro_steps
    }

    /// One macro step (with a `particles` carrier, first the fluid snapshot for it); the snapshot
    /// to publish after every `publish_every`-th.
    pub fn step<S: FluidSource>(&mut self, src: &mut S) -> Result<Option<Frame>, S::Error> {
        let k = self.k + 1;
        let every = self.params.output.publish_every;
        let log = self.hooks.log;
        let c0 = (self.hooks.cpu_ns)();
        if let Some(fl) = self.fluid.as_mut() {
            let s = &mut self.s;
            let k_len = s.macro_step_length();
            let t_end = s.time() + k_len;
            if fl.advance_to(src, self.map, t_end, 1e-6 * k_len)? {
                if let Some(snap) = &fl.current {
                    let w0 = Instant::now();
                    let rep = s.set_fluid(&snap.pos, &snap.vel).map_err(DriverError::from)?;
                    let w = w0.elapsed().as_secs_f64();
                    self.lattice_since += w;
                    let fr = &mut fl.report;
                    fr.lattice_s += w;
                    fr.lattice_fills += 1;
                    fr.last_used_t = snap.t;
                    fr.valid_nodes = rep.valid_nodes;
                    fr.nodes = rep.nodes;
                    fr.particle_volume_m2 = rep.volume;
                    if k.is_multiple_of(every) {
                        log_fill(log, "macro step to", snap, &rep);
                    }
                }
            }
            if fl.terminated {
                self.stopped = true;
                return Ok(None);
            }
            if fl.ended && fl.pending.is_none() && !self.warned_end {
                if let Some(snap) = &fl.current {
                    if snap.t + 1e-6 * k_len < t_end {
                        log(&format!(
                            "the fluid stream ended; its last snapshot (t = {:.6} s) carries the macro steps from t = {:.6} s on",
                            snap.t,
                            s.time()
                        ));
                        self.warned_end = true;
                    }
                }
            }
        }
        let tm = self.s.macro_step().map_err(DriverError::from)?;
        let c = (self.hooks.cpu_ns)().saturating_sub(c0);
        self.k = k;
        self.cpu_since += c;
        self.cpu_total += c;
        self.since += tm;
        self.total += tm;
        if !k.is_multiple_of(every) {
            return Ok(None);
        }
        let since = self.since;
        log(&format!(
            "t = {:.4} s (macro step {k}/{}): advection {:.3} s, collisions {:.3} s, coefficients {:.3} s, {} pairs, {} wall hits",
            self.s.time(),
            self.params.output.n_macro_steps,
            secs(since.advection),
            secs(since.collisions),
            secs(since.coefficients),
            since.pairs,
            since.wall_hits
        ));
        if self.fluid.is_some() {
            log(&format!("lattice fills {:.3} s", self.lattice_since));
            self.lattice_since = 0.0;
        }
        let f = self.frame(self.cpu_since);
        self.since = Timings::default();
        self.cpu_since = 0;
        Ok(Some(f))
    }

    /// Reads the fluid stream to its end (or a stop request); nothing for an analytic carrier.
    pub fn drain<S: FluidSource>(&mut self, src: &mut S) -> Result<(), S::Error> {
        if let Some(fl) = self.fluid.as_mut() {
            while !fl.ended && !fl.terminated {
                fl.pending = None;
                fl.receive(src, self.map)?;
            }
        }
        Ok(())
    }

    /// The time split of the run (`snapshots_received`: fluid messages read, for the report) and
    /// its summary line.
    pub fn finish(self, snapshots_received: u64) -> TimingReport {
        let n = self.s.particles.len();
        let (s, total) = (&self.s, self.total);
        let report = TimingReport {
            particles: self.params.suspension.count(),
            macro_steps: s.macro_steps(),
            sub_steps: s.macro_steps() * self.params.suspension.dynamics.sub_steps as u64,
            model: s.model_name().to_string(),
            advection_s: secs(total.advection),
            collisions_s: secs(total.collisions),
            coefficients_s: secs(total.coefficients),
            compute_cpu_s: self.cpu_total as f64 * 1e-9,
            pairs: total.pairs,
            impulses: total.impulses,
            wall_hits: total.wall_hits,
            fluid: self.fluid.map(|fl| FluidReport { snapshots_received, ..fl.report }),
        };
        (self.hooks.log)(&format!(
            "{} macro steps of {n} platelets: advection {:.3} s, collisions + walls {:.3} s, coefficients ({}) {:.3} s; {:.1} ns per particle and sub-step",
            report.macro_steps,
            report.advection_s,
            report.collisions_s,
            report.model,
            report.coefficients_s,
            1e9 * report.compute_cpu_s / (n as f64 * report.sub_steps.max(1) as f64)
        ));
        report
    }

    /// The parameters.
    pub fn params(&self) -> &PlateletsParams {
        &self.params
    }

    /// The suspension.
    pub fn suspension(&self) -> &Suspension {
        &self.s
    }

    /// Time of the current state \[s\].
    pub fn time(&self) -> f64 {
        self.s.time()
    }

    /// Number of platelets.
    pub fn len(&self) -> usize {
        self.s.particles.len()
    }

    /// No platelets (never, once seeded).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The sub-step \[s\].
    pub fn sub_step(&self) -> f64 {
        self.params.suspension.dynamics.sub_step
    }

    fn mapped(&self, i: usize) -> (f32, f32, f32, f32) {
        let p = &self.s.particles;
        let [x, z] = self.map.to_imaging([p.x[i], p.y[i]]);
        let [vx, vz] = self.map.vel_to_imaging([p.vx[i], p.vy[i]]);
        (x as f32, z as f32, vx as f32, vz as f32)
    }

    /// The platelets' bounding box in imaging coordinates: \[x_min, x_max, z_min, z_max\].
    pub fn bbox(&self) -> [f32; 4] {
        let (mut xmin, mut xmax, mut zmin, mut zmax) = (f32::MAX, f32::MIN, f32::MAX, f32::MIN);
        for i in 0..self.len() {
            let (x, z, _, _) = self.mapped(i);
            xmin = xmin.min(x);
            xmax = xmax.max(x);
            zmin = zmin.min(z);
            zmax = zmax.max(z);
        }
        [xmin, xmax, zmin, zmax]
    }

    /// The platelets to publish, in storage order (ids change places with the spatial sort).
    pub fn states(&self) -> impl ExactSizeIterator<Item = PlateletState> + '_ {
        (0..self.len()).map(|i| {
            let (x, z, vx, vz) = self.mapped(i);
            let id = self.s.particles.id[i];
            PlateletState {
                id: id as u32,
                x,
                z,
                vx,
                vz,
                amplitude: self.amplitude.get(id as usize).copied().unwrap_or(0.0),
            }
        })
    }
}

#[cfg(test)]
mod tests;
