//! `platelets` node: thin wiring of `sonoflow_platelet::suspension` — a platelet suspension
//! (paper 2, Algorithm 2) advanced by macro steps in an analytic carrier (straight channel,
//! stenosed channel, simple shear) or in a fluid given as particles (SPH snapshots on the optional
//! input `particles`), published as `ParticleSnapshotV1` with `kind = PARTICLE_PLATELET`.
//!
//! **Parameters**: those of [`SuspensionParams`] (`carrier`, `particles`, `seed`, `dynamics`,
//! `model`, `weights`, `density`, `radius_factor`), plus the output schedule and the mapping into
//! imaging coordinates of [`OutputParams`] (`n_macro_steps`, `publish_every`, `publish_initial`,
//! `origin`, `angle_deg`, `amplitude_sigma`).
//!
//! **Schedule**: the initial (relaxed) state at t = t₀ if `publish_initial`, then a snapshot after
//! every `publish_every`-th of the `n_macro_steps` macro steps (t = t₀ + k · sub_step · sub_steps),
//! with frame ids 0, 1, …; `packet_size` = 0 (no acquisition schedule). t₀ = 0 for an analytic
//! carrier. Following an acquisition schedule (PRF times inside a macro step) is future work.
//!
//! **SPH carrier** (`carrier = { type = "particles", lattice = { origin, h, nx, ny }, kernel_h,
//! kernel, min_fraction, interpolation, walls }`, [`ParticleCarrier`]; needs the input `particles` wired, and
//! that input needs this carrier — `sonoflow check` says so): each fluid snapshot's particles of
//! kind `PARTICLE_FLUID` (positions and velocities, both on the wire) are mapped from imaging into
//! channel coordinates with the inverse of the output mapping below (any `angle_deg`), then
//! interpolated onto the lattice (SPH kernel fit, first order by default, fluid-fraction mask,
//! eq 12 per cell: `sonoflow_platelet::dynamics::sph_interp`). The first snapshot fixes t₀ (its `t_valid`), seeds the
//! platelets and relaxes them. As in Algorithm 2 (Navier–Stokes t_{n−1} → t_n, transfer, particles
//! t_{n−1} → t_n), the macro step [t, t + k] uses the latest snapshot with t_valid ≤ t + k (to
//! within 1e-6 k): the node reads the input until it holds a later snapshot or the end of the
//! stream, so the pairing depends only on the snapshot times, never on process timing; the lattice
//! is refilled only when that snapshot changes. Snapshots finer than k are skipped; coarser ones
//! carry several macro steps (frozen flow). After the fluid stream ends the last snapshot carries
//! the remaining macro steps (logged). Once the platelets are done the input is drained to its end
//! of stream, so the fluid producer (which waits for its subscribers) can finish.
//!
//! **Mapping**: channel point (x, y) → imaging (x0, z0) + R(angle) (x, y), with R the rotation by
//! `angle_deg` from the imaging x axis towards +z (depth); velocities rotate the same way; fluid
//! particles come back with Rᵀ. Amplitudes: N(0, amplitude_sigma²) per particle id, drawn once
//! from `seed` (like the analytic-flow node), so the platelets can be scatterers too.
//!
//! **Timing**: per published snapshot `compute_ns` (thread CPU of the macro steps and lattice
//! fills since the last one) goes to the stage statistics; the split advection / collisions
//! (+ walls, sort) / coefficients (wall clock, from the dynamics) and, with an SPH carrier, the
//! lattice fills are logged per snapshot and in a summary line, and written to `<node>.json` in the
//! run folder.

use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use sonoflow_messages::types::ParticleSnapshot;
use sonoflow_messages::MessageType::*;
use sonoflow_messages::*;
use sonoflow_node_kit::PortDir::*;
use sonoflow_node_kit::{in_range, parse_params};
use sonoflow_node_kit::{is_eos, Input};
use sonoflow_node_kit::{port, KindSpec};
use sonoflow_node_kit::{thread_cpu_ns, Kit};
use sonoflow_platelet::dynamics::{FillReport, Timings};
#[cfg(doc)]
use sonoflow_platelet::suspension::ParticleCarrier;
use sonoflow_platelet::suspension::{CarrierParams, Suspension, SuspensionParams};
use std::time::Duration;

/// The `platelets` node kind.
pub const SPEC: KindSpec = KindSpec {
        name: "platelets",
        about: "platelet suspension (paper 2, Algorithm 2: point particles with shape, trained coefficient networks) in an analytic carrier (straight or stenosed channel, shear) or in fluid snapshots on the input `particles` (SPH, interpolated onto a lattice; carrier type \"particles\"): platelet snapshots every few macro steps, with the time split advection / collisions / coefficients",
        ports: &[port("particles", In, ParticleSnapshotV1, false), port("particles", Out, ParticleSnapshotV1, true)],
        dynamic_inputs: false,
        dynamic_outputs: false,
        validate,
        check_wiring: Some(check_wiring),
        input_files: &["weights"],
        run,
};

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

const OUTPUT_KEYS: [&str; 6] =
    ["n_macro_steps", "publish_every", "publish_initial", "origin", "angle_deg", "amplitude_sigma"];

impl OutputParams {
    pub fn validate(&self) -> Result<(), String> {
        in_range("n_macro_steps", self.n_macro_steps, 1, 1_000_000)?;
        in_range("publish_every", self.publish_every, 1, self.n_macro_steps)?;
        for (i, o) in self.origin.iter().enumerate() {
            if !(o.is_finite() && o.abs() <= 1.0) {
                return Err(format!("origin[{i}] = {o} is out of range: -1 ..= 1 m"));
            }
        }
        in_range("angle_deg", self.angle_deg, -360.0, 360.0)?;
        if !(self.amplitude_sigma.is_finite() && self.amplitude_sigma > 0.0 && self.amplitude_sigma <= 1e6) {
            return Err(format!(
                "amplitude_sigma = {} is out of range: 0 < amplitude_sigma <= 1e6",
                self.amplitude_sigma
            ));
        }
        Ok(())
    }

    /// Snapshots published in all.
    pub fn n_snapshots(&self) -> u64 {
        self.publish_initial as u64 + self.n_macro_steps / self.publish_every
    }
}

/// Splits the node params into the suspension's and the node's, and validates both (without
/// loading the weights, but checking that they exist).
pub fn split_params(v: &serde_json::Value) -> Result<(SuspensionParams, OutputParams), String> {
    let mut v = if v.is_null() { serde_json::json!({}) } else { v.clone() };
    let mut out = serde_json::Map::new();
    if let Some(o) = v.as_object_mut() {
        for k in OUTPUT_KEYS {
            if let Some(x) = o.remove(k) {
                out.insert(k.to_string(), x);
            }
        }
    }
    let o: OutputParams = parse_params(&serde_json::Value::Object(out))?;
    let s: SuspensionParams = parse_params(&v)?;
    o.validate()?;
    s.validate().map_err(|e| e.to_string())?;
    s.check_weights().map_err(|e| e.to_string())?;
    Ok((s, o))
}

pub fn validate(v: &serde_json::Value) -> Result<(), String> {
    split_params(v).map(|_| ())
}

/// The carrier `particles` and the input `particles` go together (called by `sonoflow check` with
/// whether the input is wired, and by the node itself).
pub fn check_wiring(v: &serde_json::Value, inputs: &[&str]) -> Result<(), String> {
    let input_wired = inputs.contains(&"particles");
    let carrier = v.get("carrier").and_then(|c| c.get("type")).and_then(|t| t.as_str());
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
struct FrameMap {
    origin: [f64; 2],
    sin: f64,
    cos: f64,
}

impl FrameMap {
    fn new(op: &OutputParams) -> Self {
        let (sin, cos) = op.angle_deg.to_radians().sin_cos();
        FrameMap { origin: op.origin, sin, cos }
    }
    /// Channel (x, y) → imaging (x, z).
    fn to_imaging(self, p: [f64; 2]) -> [f64; 2] {
        [self.origin[0] + self.cos * p[0] - self.sin * p[1], self.origin[1] + self.sin * p[0] + self.cos * p[1]]
    }
    /// A velocity in channel axes → imaging axes.
    fn vel_to_imaging(self, v: [f64; 2]) -> [f64; 2] {
        [self.cos * v[0] - self.sin * v[1], self.sin * v[0] + self.cos * v[1]]
    }
    /// Imaging (x, z) → channel (x, y).
    fn to_channel(self, q: [f64; 2]) -> [f64; 2] {
        self.vel_to_channel([q[0] - self.origin[0], q[1] - self.origin[1]])
    }
    /// A velocity in imaging axes → channel axes.
    fn vel_to_channel(self, v: [f64; 2]) -> [f64; 2] {
        [self.cos * v[0] + self.sin * v[1], -self.sin * v[0] + self.cos * v[1]]
    }
}

/// One fluid snapshot in channel coordinates.
#[derive(Default)]
struct FluidSnapshot {
    t: f64,
    frame_id: u64,
    pos: Vec<[f64; 2]>,
    vel: Vec<[f64; 2]>,
}

/// The fluid input: the snapshot in use and the next one, paired with macro steps by time (module doc).
struct FluidFeed {
    input: Input<ParticleSnapshot>,
    map: FrameMap,
    current: Option<FluidSnapshot>,
    pending: Option<FluidSnapshot>,
    spare: FluidSnapshot,
    /// End of stream seen.
    ended: bool,
    /// SIGINT/SIGTERM while waiting.
    terminated: bool,
}

impl FluidFeed {
    fn new(input: Input<ParticleSnapshot>, map: FrameMap) -> Self {
        FluidFeed {
            input,
            map,
            current: None,
            pending: None,
            spare: FluidSnapshot::default(),
            ended: false,
            terminated: false,
        }
    }

    /// Takes one message into `pending` (which must be empty), or waits up to 200 ms.
    fn receive(&mut self, kit: &Kit) -> anyhow::Result<()> {
        match self.input.try_receive()? {
            Some(sample) => {
                let h = *sample.user_header();
                if is_eos::<ParticleSnapshot>(&h) {
                    self.ended = true;
                    return Ok(());
                }
                let mut snap = std::mem::take(&mut self.spare);
                snap.t = h.common.t_valid;
                snap.frame_id = h.common.frame_id;
                snap.pos.clear();
                snap.vel.clear();
                for q in sample.payload().iter().filter(|q| q.kind == PARTICLE_FLUID) {
                    snap.pos.push(self.map.to_channel([q.x as f64, q.z as f64]));
                    snap.vel.push(self.map.vel_to_channel([q.vx as f64, q.vz as f64]));
                }
                if !snap.t.is_finite() {
                    anyhow::bail!(
                        "fluid snapshot {} on `{}` has t_valid = {}",
                        snap.frame_id,
                        self.input.topic(),
                        snap.t
                    );
                }
                if snap.pos.is_empty() {
                    anyhow::bail!(
                        "fluid snapshot {} (t = {} s) on `{}` has no particles of kind PARTICLE_FLUID: wire the input to a fluid producer (sph-flow, analytic-flow)",
                        snap.frame_id,
                        snap.t,
                        self.input.topic()
                    );
                }
                self.pending = Some(snap);
            }
            None => {
                if kit.check_termination().is_err() {
                    self.terminated = true;
                } else {
                    self.input.wait(Duration::from_millis(200))?;
                }
            }
        }
        Ok(())
    }

    /// Waits for the first snapshot and makes it current (None if the node was stopped).
    fn first(&mut self, kit: &Kit) -> anyhow::Result<Option<&FluidSnapshot>> {
        while self.pending.is_none() && !self.terminated {
            if self.ended {
                anyhow::bail!("the fluid stream on `{}` ended before its first snapshot", self.input.topic());
            }
            self.receive(kit)?;
        }
        self.current = self.pending.take();
        Ok(self.current.as_ref())
    }

    /// Makes the latest snapshot with t ≤ t_end + eps current, reading until a later one or the end
    /// of the stream is seen; true if the current snapshot changed.
    fn advance_to(&mut self, kit: &Kit, t_end: f64, eps: f64) -> anyhow::Result<bool> {
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
            self.receive(kit)?;
        }
    }

    /// Reads and drops everything up to the end of the stream (module doc).
    fn drain(&mut self, kit: &Kit) -> anyhow::Result<()> {
        while !self.ended && !self.terminated {
            self.pending = None;
            self.receive(kit)?;
        }
        Ok(())
    }
}

/// Seconds of a duration.
fn secs(d: std::time::Duration) -> f64 {
    d.as_secs_f64()
}

#[derive(serde::Serialize)]
struct TimingReport {
    particles: usize,
    macro_steps: u64,
    sub_steps: u64,
    model: String,
    advection_s: f64,
    collisions_s: f64,
    coefficients_s: f64,
    compute_cpu_s: f64,
    pairs: usize,
    impulses: usize,
    wall_hits: usize,
    /// SPH carrier only: fluid snapshots received, lattice fills, their wall-clock time.
    #[serde(skip_serializing_if = "Option::is_none")]
    fluid: Option<FluidReport>,
}

#[derive(serde::Serialize, Default)]
struct FluidReport {
    snapshots_received: u64,
    lattice_fills: u64,
    lattice_s: f64,
    first_t: f64,
    last_used_t: f64,
    /// Valid lattice nodes / all nodes at the last fill.
    valid_nodes: usize,
    nodes: usize,
    particle_volume_m2: f64,
}

fn log_fill(what: &str, snap: &FluidSnapshot, r: &FillReport) {
    eprintln!(
        "platelets: {what} fluid snapshot {} (t = {:.6} s): {} fluid particles, {} near the lattice, {} of {} nodes with fluid ({} by the Shepard fallback), particle volume {:.3e} m²",
        snap.frame_id, snap.t, r.particles, r.used, r.valid_nodes, r.nodes, r.shepard_fallback, r.volume
    );
}

pub fn run(mut kit: Kit) -> anyhow::Result<()> {
    let (sp, op) = split_params(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    check_wiring(&kit.cfg.params, &kit.cfg.inputs.keys().map(String::as_str).collect::<Vec<_>>())
        .map_err(anyhow::Error::msg)?;
    let mut out = kit.output::<ParticleSnapshot>("particles")?;
    let n = sp.count();
    if n > out.max_elements() {
        anyhow::bail!(
            "the suspension has {n} platelets but topic `{}` allows max_elements = {}: raise it in the launch file or lower particles.count",
            out.topic(),
            out.max_elements()
        );
    }
    let map = FrameMap::new(&op);
    let mut feed = match sp.carrier {
        CarrierParams::Particles(_) => Some(FluidFeed::new(kit.input::<ParticleSnapshot>("particles")?, map)),
        _ => None,
    };
    match feed.as_mut() {
        Some(f) => kit.handshake(&mut [&mut out, &mut f.input])?,
        None => kit.handshake(&mut [&mut out])?,
    }
    let t_setup = std::time::Instant::now();
    let mut fluid_report: Option<FluidReport> = None;
    let mut s = match feed.as_mut() {
        None => Suspension::new(&sp)?,
        Some(f) => {
            let Some(snap) = f.first(&kit)? else {
                eprintln!("platelets: stopped while waiting for the first fluid snapshot");
                kit.finish()?;
                return Ok(());
            };
            let (s, rep) = Suspension::with_fluid(&sp, snap.t, &snap.pos, &snap.vel)?;
            log_fill("seeded in", snap, &rep);
            fluid_report = Some(FluidReport {
                lattice_fills: 1,
                first_t: snap.t,
                last_used_t: snap.t,
                valid_nodes: rep.valid_nodes,
                nodes: rep.nodes,
                particle_volume_m2: rep.volume,
                ..Default::default()
            });
            s
        }
    };
    eprintln!(
        "platelets: {n} platelets, model `{}`, seeded in {:.2} s",
        s.model_name(),
        t_setup.elapsed().as_secs_f64()
    );
    let normal = Normal::new(0.0, op.amplitude_sigma)?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(sp.seed ^ 0x9e37_79b9_7f4a_7c15);
    let amplitude: Vec<f32> = (0..n).map(|_| normal.sample(&mut rng) as f32).collect();

    let total_snaps = op.n_snapshots();
    let mut frame = 0u64;
    let mut publish = |kit: &mut Kit,
                       out: &mut sonoflow_node_kit::Output<ParticleSnapshot>,
                       s: &Suspension,
                       compute: u64|
     -> anyhow::Result<()> {
        let p = &s.particles;
        let (mut xmin, mut xmax, mut zmin, mut zmax) = (f32::MAX, f32::MIN, f32::MAX, f32::MIN);
        let mapped = |i: usize| {
            let [x, z] = map.to_imaging([p.x[i], p.y[i]]);
            let [vx, vz] = map.vel_to_imaging([p.vx[i], p.vy[i]]);
            (x as f32, z as f32, vx as f32, vz as f32)
        };
        for i in 0..p.len() {
            let (x, z, _, _) = mapped(i);
            xmin = xmin.min(x);
            xmax = xmax.max(x);
            zmin = zmin.min(z);
            zmax = zmax.max(z);
        }
        let mut h = ParticleSnapshotHeaderV1 {
            n_particles: p.len() as u32,
            n_fluid: 0,
            dt: sp.dynamics.sub_step,
            bbox: [xmin, xmax, zmin, zmax],
            ..Default::default()
        };
        h.common.frame_id = frame;
        h.common.t_valid = s.time();
        out.publish_in_place(p.len(), h, |dst| {
            for (i, d) in dst.iter_mut().enumerate() {
                let (x, z, vx, vz) = mapped(i);
                let id = p.id[i];
                d.write(ParticleV1 {
                    id: id as u32,
                    kind: PARTICLE_PLATELET,
                    x,
                    z,
                    vx,
                    vz,
                    amplitude: amplitude.get(id as usize).copied().unwrap_or(0.0),
                    reserved: 0.0,
                });
            }
        })?;
        kit.stats.messages_out += 1;
        kit.stats.bytes_out += (p.len() * 32) as u64;
        kit.record(frame, s.time(), compute)?;
        frame += 1;
        kit.progress(frame, total_snaps);
        Ok(())
    };

    if op.publish_initial {
        publish(&mut kit, &mut out, &s, 0)?;
    }
    let mut total = Timings::default();
    let mut since = Timings::default();
    let mut cpu_since = 0u64;
    let mut cpu_total = 0u64;
    let mut lattice_since = 0.0;
    let mut warned_end = false;
    for k in 1..=op.n_macro_steps {
        if kit.check_termination().is_err() {
            break;
        }
        let c0 = thread_cpu_ns();
        if let (Some(f), Some(fr)) = (feed.as_mut(), fluid_report.as_mut()) {
            let k_len = s.macro_step_length();
            let t_end = s.time() + k_len;
            if f.advance_to(&kit, t_end, 1e-6 * k_len)? {
                if let Some(snap) = &f.current {
                    let w0 = std::time::Instant::now();
                    let rep = s.set_fluid(&snap.pos, &snap.vel)?;
                    let w = w0.elapsed().as_secs_f64();
                    lattice_since += w;
                    fr.lattice_s += w;
                    fr.lattice_fills += 1;
                    fr.last_used_t = snap.t;
                    fr.valid_nodes = rep.valid_nodes;
                    fr.nodes = rep.nodes;
                    fr.particle_volume_m2 = rep.volume;
                    if k.is_multiple_of(op.publish_every) {
                        log_fill("macro step to", snap, &rep);
                    }
                }
            }
            if f.terminated {
                break;
            }
            if f.ended && f.pending.is_none() && !warned_end {
                if let Some(snap) = &f.current {
                    if snap.t + 1e-6 * k_len < t_end {
                        eprintln!(
                            "platelets: the fluid stream ended; its last snapshot (t = {:.6} s) carries the macro steps from t = {:.6} s on",
                            snap.t,
                            s.time()
                        );
                        warned_end = true;
                    }
                }
            }
        }
        let tm = s.macro_step()?;
        let c = thread_cpu_ns() - c0;
        cpu_since += c;
        cpu_total += c;
        since += tm;
        total += tm;
        if k.is_multiple_of(op.publish_every) {
            eprintln!(
                "platelets: t = {:.4} s (macro step {k}/{}): advection {:.3} s, collisions {:.3} s, coefficients {:.3} s, {} pairs, {} wall hits",
                s.time(),
                op.n_macro_steps,
                secs(since.advection),
                secs(since.collisions),
                secs(since.coefficients),
                since.pairs,
                since.wall_hits
            );
            if feed.is_some() {
                eprintln!("platelets: lattice fills {lattice_since:.3} s");
                lattice_since = 0.0;
            }
            publish(&mut kit, &mut out, &s, cpu_since)?;
            since = Timings::default();
            cpu_since = 0;
        }
    }
    out.publish_eos(s.time())?;
    if let Some(f) = feed.as_mut() {
        // let the fluid producer finish (it waits for its subscribers)
        f.drain(&kit)?;
        kit.stats.messages_in = f.input.received;
        kit.stats.gaps = f.input.gaps;
        if let Some(fr) = fluid_report.as_mut() {
            fr.snapshots_received = f.input.received;
        }
    }
    let report = TimingReport {
        particles: n,
        macro_steps: s.macro_steps(),
        sub_steps: s.macro_steps() * sp.dynamics.sub_steps as u64,
        model: s.model_name().to_string(),
        advection_s: secs(total.advection),
        collisions_s: secs(total.collisions),
        coefficients_s: secs(total.coefficients),
        compute_cpu_s: cpu_total as f64 * 1e-9,
        pairs: total.pairs,
        impulses: total.impulses,
        wall_hits: total.wall_hits,
        fluid: fluid_report,
    };
    eprintln!(
        "platelets: {} macro steps of {n} platelets: advection {:.3} s, collisions + walls {:.3} s, coefficients ({}) {:.3} s; {:.1} ns per particle and sub-step",
        report.macro_steps,
        report.advection_s,
        report.collisions_s,
        report.model,
        report.coefficients_s,
        1e9 * report.compute_cpu_s / (n as f64 * report.sub_steps.max(1) as f64)
    );
    if let Some(dir) = &kit.cfg.out_dir {
        let path = std::path::Path::new(dir).join(format!("{}.json", kit.cfg.node_name));
        std::fs::write(&path, serde_json::to_string_pretty(&report)?)?;
    }
    kit.finish()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn fluid_particles_come_back_into_the_channel_frame_with_the_inverse_mapping() {
        let op = OutputParams { origin: [-6e-3, 19e-3], angle_deg: 25.0, ..Default::default() };
        let m = FrameMap::new(&op);
        let (p, v) = ([3e-3, 0.7e-3], [0.02, -0.004]);
        let q = m.to_imaging(p);
        let w = m.vel_to_imaging(v);
        // rotated by +25° towards +z: the channel x axis points down-right in the image
        let a = 25f64.to_radians();
        assert!((q[0] - (-6e-3 + a.cos() * 3e-3 - a.sin() * 0.7e-3)).abs() < 1e-18);
        assert!((q[1] - (19e-3 + a.sin() * 3e-3 + a.cos() * 0.7e-3)).abs() < 1e-18);
        let (pb, vb) = (m.to_channel(q), m.vel_to_channel(w));
        for k in 0..2 {
            assert!((pb[k] - p[k]).abs() < 1e-17 && (vb[k] - v[k]).abs() < 1e-17, "{pb:?} {vb:?}");
        }
    }

    #[test]
    fn the_particles_carrier_needs_the_input_and_vice_versa() {
        let sph = serde_json::json!({ "carrier": { "type": "particles", "lattice": { "origin": [0.0, 0.0], "h": 1e-4, "nx": 3, "ny": 3 }, "kernel_h": 2e-4 } });
        split_params(&sph).unwrap();
        check_wiring(&sph, &["particles"]).unwrap();
        assert!(check_wiring(&sph, &[]).unwrap_err().contains("needs the input `particles`"));
        let an = serde_json::json!({ "carrier": { "type": "channel" } });
        check_wiring(&an, &[]).unwrap();
        assert!(check_wiring(&an, &["particles"]).unwrap_err().contains("carrier type \"channel\" does not read it"));
        let e = check_wiring(&serde_json::json!({}), &["particles"]).unwrap_err();
        assert!(e.contains("\"stenosis\" (the default)"), "{e}");
    }

    #[test]
    fn params_split_validate_and_name_the_field() {
        let v = serde_json::json!({ "carrier": { "type": "stenosis" }, "particles": { "count": 10 }, "n_macro_steps": 2, "origin": [0.0, 0.02] });
        let (s, o) = split_params(&v).unwrap();
        assert_eq!(s.count(), 10);
        assert_eq!((o.n_macro_steps, o.n_snapshots()), (2, 3));
        let bad = serde_json::json!({ "publish_every": 3, "n_macro_steps": 2 });
        let e = split_params(&bad).unwrap_err();
        assert!(e.contains("publish_every") && e.contains("1 ..= 2"), "{e}");
        let bad = serde_json::json!({ "carrier": { "type": "stenosis", "narrowing": 2.0 } });
        assert!(split_params(&bad).unwrap_err().contains("`narrowing`"));
        let bad = serde_json::json!({ "particles": { "count": 10 }, "bogus": 1 });
        assert!(split_params(&bad).unwrap_err().contains("bogus"));
        let bad = serde_json::json!({ "carrier": { "type": "pipe" } });
        assert!(split_params(&bad).unwrap_err().contains("pipe"));
    }
}
