//! `platelets` node: thin wiring of `sonoflow_platelet::suspension::Driver` — a platelet
//! suspension (paper 2, Algorithm 2) advanced by macro steps in an analytic carrier (straight
//! channel, stenosed channel, simple shear) or in a fluid given as particles (SPH snapshots on the
//! optional input `particles`), published as `ParticleSnapshotV1` with `kind = PARTICLE_PLATELET`.
//!
//! **Parameters**: [`PlateletsParams`] (those of `SuspensionParams` and `OutputParams`: `carrier`,
//! `particles`, `seed`, `dynamics`, `model`, `weights`, `density`, `radius_factor`,
//! `n_macro_steps`, `publish_every`, `publish_initial`, `origin`, `angle_deg`, `amplitude_sigma`).
//! Schedule, pairing of fluid snapshots with macro steps, coordinate mapping and timings: the
//! module doc of `sonoflow_platelet::suspension::driver`.
//!
//! **Wire**: the input's particles of kind `PARTICLE_FLUID` are the fluid (positions and
//! velocities, imaging coordinates); the header's `t_valid` is the snapshot time. Out: one message
//! per snapshot, `frame_id` 0, 1, …, `t_valid` the suspension time, `dt` the sub-step,
//! `packet_size` = 0 (no acquisition schedule), `n_fluid` = 0. `compute_ns` (thread CPU of the
//! macro steps and lattice fills since the last snapshot) goes to the stage statistics; the
//! driver's diagnostics go to stderr, its time split to `<node>.json` in the run folder. Once the
//! platelets are done the input is drained to its end of stream, so the fluid producer (which
//! waits for its subscribers) can finish.

use sonoflow_messages::types::ParticleSnapshot;
use sonoflow_messages::MessageType::*;
use sonoflow_messages::*;
use sonoflow_node_kit::PortDir::*;
use sonoflow_node_kit::{is_eos, parse_params, port, thread_cpu_ns, Input, KindSpec, Kit, Output};
use sonoflow_platelet::suspension::{
    check_fluid_input, CarrierParams, Driver, FluidSnapshot, FluidSource, Frame, Hooks, PlateletsParams, Received,
};
use std::time::Duration;

/// The `platelets` node kind.
pub const SPEC: KindSpec = KindSpec::new(
    "platelets",
    "platelet suspension (paper 2, Algorithm 2: point particles with shape, trained coefficient networks) in an analytic carrier (straight or stenosed channel, shear) or in fluid snapshots on the input `particles` (SPH, interpolated onto a lattice; carrier type \"particles\"): platelet snapshots every few macro steps, with the time split advection / collisions / coefficients",
    &[port("particles", In, ParticleSnapshotV1, false), port("particles", Out, ParticleSnapshotV1, true)],
    validate,
    run,
)
.with_wiring_check(check_wiring)
.with_input_files(&["weights"]);

/// The node params, validated (without loading the weights, but checking that they exist).
pub fn params(v: &serde_json::Value) -> Result<PlateletsParams, String> {
    let p: PlateletsParams = parse_params(v)?;
    p.validate().map_err(|e| e.to_string())?;
    Ok(p)
}

pub fn validate(v: &serde_json::Value) -> Result<(), String> {
    params(v).map(|_| ())
}

/// The carrier `particles` and the input `particles` go together (called by `sonoflow check` with
/// whether the input is wired, and by the node itself).
pub fn check_wiring(v: &serde_json::Value, inputs: &[&str]) -> Result<(), String> {
    check_fluid_input(v, inputs.contains(&"particles"))
}

/// The input `particles` as the driver's fluid source (none for an analytic carrier).
struct Wire<'a> {
    input: Option<&'a mut Input<ParticleSnapshot>>,
    kit: &'a Kit,
}

impl FluidSource for Wire<'_> {
    type Error = anyhow::Error;
    fn next(&mut self, into: &mut FluidSnapshot) -> anyhow::Result<Received> {
        let Some(input) = self.input.as_deref_mut() else { return Ok(Received::Ended) };
        loop {
            let Some(sample) = input.try_receive()? else {
                if self.kit.check_termination().is_err() {
                    return Ok(Received::Stopped);
                }
                input.wait(Duration::from_millis(200))?;
                continue;
            };
            let h = *sample.user_header();
            if is_eos::<ParticleSnapshot>(&h) {
                return Ok(Received::Ended);
            }
            into.t = h.common.t_valid;
            into.frame_id = h.common.frame_id;
            for q in sample.payload().iter().filter(|q| q.kind == PARTICLE_FLUID) {
                into.pos.push([q.x as f64, q.z as f64]);
                into.vel.push([q.vx as f64, q.vz as f64]);
            }
            return Ok(Received::Snapshot);
        }
    }
    fn name(&self) -> String {
        self.input.as_ref().map_or(String::new(), |i| i.topic().to_string())
    }
}

fn log(line: &str) {
    eprintln!("platelets: {line}");
}

pub fn run(mut kit: Kit) -> anyhow::Result<()> {
    let p = params(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    check_wiring(&kit.cfg.params, &kit.cfg.inputs.keys().map(String::as_str).collect::<Vec<_>>())
        .map_err(anyhow::Error::msg)?;
    let mut out = kit.output::<ParticleSnapshot>("particles")?;
    let n = p.suspension.count();
    if n > out.max_elements() {
        anyhow::bail!(
            "the suspension has {n} platelets but topic `{}` allows max_elements = {}: raise it in the launch file or lower particles.count",
            out.topic(),
            out.max_elements()
        );
    }
    let mut input = match p.suspension.carrier {
        CarrierParams::Particles(_) => Some(kit.input::<ParticleSnapshot>("particles")?),
        _ => None,
    };
    match input.as_mut() {
        Some(i) => kit.handshake(&mut [&mut out, i])?,
        None => kit.handshake(&mut [&mut out])?,
    }
    let hooks = Hooks { cpu_ns: thread_cpu_ns, log };
    let Some(mut d) = Driver::new(p, hooks, &mut Wire { input: input.as_mut(), kit: &kit })? else {
        kit.finish()?;
        return Ok(());
    };
    if let Some(f) = d.initial() {
        publish(&mut kit, &mut out, &d, f)?;
    }
    while !d.done() && kit.check_termination().is_ok() {
        if let Some(f) = d.step(&mut Wire { input: input.as_mut(), kit: &kit })? {
            publish(&mut kit, &mut out, &d, f)?;
        }
    }
    out.publish_eos(d.time())?;
    // let the fluid producer finish (it waits for its subscribers)
    d.drain(&mut Wire { input: input.as_mut(), kit: &kit })?;
    let received = input.as_ref().map_or(0, |i| i.received);
    if let Some(i) = &input {
        kit.stats.messages_in = i.received;
        kit.stats.gaps = i.gaps;
    }
    let report = d.finish(received);
    if let Some(dir) = &kit.cfg.out_dir {
        let path = std::path::Path::new(dir).join(format!("{}.json", kit.cfg.node_name));
        sonoflow_fileio::write_atomic(&path, serde_json::to_string_pretty(&report)?.as_bytes())?;
    }
    kit.finish()?;
    Ok(())
}

/// One snapshot of the driver's platelets on the wire.
fn publish(kit: &mut Kit, out: &mut Output<ParticleSnapshot>, d: &Driver, f: Frame) -> anyhow::Result<()> {
    let n = d.len();
    let mut h = ParticleSnapshotHeaderV1 {
        n_particles: n as u32,
        n_fluid: 0,
        dt: d.sub_step(),
        bbox: d.bbox(),
        ..Default::default()
    };
    h.common.frame_id = f.frame_id;
    h.common.t_valid = f.t;
    out.publish_in_place(n, h, |dst| {
        for (w, p) in dst.iter_mut().zip(d.states()) {
            let (x, z, vx, vz, amplitude) = (p.x, p.z, p.vx, p.vz, p.amplitude);
            w.write(ParticleV1 { id: p.id, kind: PARTICLE_PLATELET, x, z, vx, vz, amplitude, reserved: 0.0 });
        }
    })?;
    kit.stats.messages_out += 1;
    kit.stats.bytes_out += (n * 32) as u64;
    kit.record(f.frame_id, f.t, f.compute_ns)?;
    kit.progress(f.frame_id + 1, d.params().output.n_snapshots());
    Ok(())
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn the_particles_carrier_needs_the_input_and_vice_versa() {
        let sph = serde_json::json!({ "carrier": { "type": "particles", "lattice": { "origin": [0.0, 0.0], "h": 1e-4, "nx": 3, "ny": 3 }, "kernel_h": 2e-4 } });
        params(&sph).unwrap();
        check_wiring(&sph, &["particles"]).unwrap();
        assert!(check_wiring(&sph, &[]).unwrap_err().contains("needs the input `particles`"));
        let an = serde_json::json!({ "carrier": { "type": "channel" } });
        check_wiring(&an, &[]).unwrap();
        assert!(check_wiring(&an, &["particles"]).unwrap_err().contains("carrier type \"channel\" does not read it"));
        let e = check_wiring(&serde_json::json!({}), &["particles"]).unwrap_err();
        assert!(e.contains("\"stenosis\" (the default)"), "{e}");
    }

    #[test]
    fn validate_names_the_field_through_the_node_kit() {
        validate(&serde_json::Value::Null).unwrap();
        let e = validate(&serde_json::json!({ "publish_every": 3, "n_macro_steps": 2 })).unwrap_err();
        assert!(e.contains("publish_every") && e.contains("1 ..= 2"), "{e}");
        let e = validate(&serde_json::json!({ "carrier": { "type": "stenosis", "narowing": 0.3 } })).unwrap_err();
        assert!(e.starts_with("carrier: unknown field `narowing`"), "{e}");
    }
}
