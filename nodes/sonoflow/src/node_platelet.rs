//! `platelets` node: thin wiring of `sonoflow_platelet::suspension` — a platelet suspension
//! (paper 2, Algorithm 2) advanced by macro steps in an analytic carrier (straight channel,
//! stenosed channel, simple shear), published as `ParticleSnapshotV1` with
//! `kind = PARTICLE_PLATELET`.
//!
//! **Parameters**: those of [`SuspensionParams`] (`carrier`, `particles`, `seed`, `dynamics`,
//! `model`, `weights`, `density`, `radius_factor`), plus the output schedule and the mapping into
//! imaging coordinates of [`OutputParams`] (`n_macro_steps`, `publish_every`, `publish_initial`,
//! `origin`, `angle_deg`, `amplitude_sigma`).
//!
//! **Schedule**: the initial (relaxed) state at t = 0 if `publish_initial`, then a snapshot after
//! every `publish_every`-th of the `n_macro_steps` macro steps (t = k · sub_step · sub_steps), with
//! frame ids 0, 1, …; `packet_size` = 0 (no acquisition schedule). Following an acquisition schedule
//! (PRF times inside a 5 ms macro step) and taking the carrier from an input of fluid snapshots
//! (SPH) sampled onto a `LatticeField` are future work.
//!
//! **Mapping**: channel point (x, y) → imaging (x0, z0) + R(angle) (x, y), with R the rotation by
//! `angle_deg` from the imaging x axis towards +z (depth); velocities rotate the same way.
//! Amplitudes: N(0, amplitude_sigma²) per particle id, drawn once from `seed` (like the
//! analytic-flow node), so the platelets can be scatterers too.
//!
//! **Timing**: per published snapshot `compute_ns` (thread CPU of the macro steps since the last
//! one) goes to the stage statistics; the split advection / collisions (+ walls, sort) /
//! coefficients (wall clock, from the dynamics) is logged per snapshot and in a summary line,
//! and written to `<node>.json` in the run folder.

use crate::kinds::{in_range, parse};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use sonoflow_messages::kinds::ParticleSnapshot;
use sonoflow_messages::*;
use sonoflow_node_kit::{thread_cpu_ns, Kit};
use sonoflow_platelet::dynamics::Timings;
use sonoflow_platelet::suspension::{Suspension, SuspensionParams};

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
    let o: OutputParams = parse(&serde_json::Value::Object(out))?;
    let s: SuspensionParams = parse(&v)?;
    o.validate()?;
    s.validate().map_err(|e| e.to_string())?;
    s.check_weights().map_err(|e| e.to_string())?;
    Ok((s, o))
}

pub fn validate(v: &serde_json::Value) -> Result<(), String> {
    split_params(v).map(|_| ())
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
}

pub fn run(mut kit: Kit) -> anyhow::Result<()> {
    let (sp, op) = split_params(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    let mut out = kit.output::<ParticleSnapshot>("particles")?;
    let n = sp.count();
    if n > out.max_elements() {
        anyhow::bail!(
            "the suspension has {n} platelets but topic `{}` allows max_elements = {}: raise it in the launch file or lower particles.count",
            out.topic(),
            out.max_elements()
        );
    }
    let t_setup = std::time::Instant::now();
    let mut s = Suspension::new(&sp)?;
    eprintln!(
        "platelets: {n} platelets, model `{}`, seeded in {:.2} s",
        s.model_name(),
        t_setup.elapsed().as_secs_f64()
    );
    let normal = Normal::new(0.0, op.amplitude_sigma)?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(sp.seed ^ 0x9e37_79b9_7f4a_7c15);
    let amplitude: Vec<f32> = (0..n).map(|_| normal.sample(&mut rng) as f32).collect();
    kit.handshake(&mut [&mut out])?;

    let (sa, ca) = op.angle_deg.to_radians().sin_cos();
    let [x0, z0] = op.origin;
    let total_snaps = op.n_snapshots();
    let mut frame = 0u64;
    let mut publish = |kit: &mut Kit,
                       out: &mut sonoflow_node_kit::Output<ParticleSnapshot>,
                       s: &Suspension,
                       compute: u64|
     -> anyhow::Result<()> {
        let p = &s.particles;
        let (mut xmin, mut xmax, mut zmin, mut zmax) = (f32::MAX, f32::MIN, f32::MAX, f32::MIN);
        let map = |i: usize| {
            let (x, y) = (p.x[i], p.y[i]);
            let (vx, vy) = (p.vx[i], p.vy[i]);
            (
                (x0 + ca * x - sa * y) as f32,
                (z0 + sa * x + ca * y) as f32,
                (ca * vx - sa * vy) as f32,
                (sa * vx + ca * vy) as f32,
            )
        };
        for i in 0..p.len() {
            let (x, z, _, _) = map(i);
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
                let (x, z, vx, vz) = map(i);
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
    for k in 1..=op.n_macro_steps {
        if kit.check_termination().is_err() {
            break;
        }
        let c0 = thread_cpu_ns();
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
            publish(&mut kit, &mut out, &s, cpu_since)?;
            since = Timings::default();
            cpu_since = 0;
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
    out.publish_eos(s.time())?;
    kit.finish()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

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
