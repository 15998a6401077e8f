//! `sph-flow` node: thin wiring of [`sonoflow_sph::producer`] (scene, SPH solver, schedule):
//! publishes its events — fluid particles (the scatterers) per frame, SPH-interpolated truth per
//! packet, solver diagnostics; `checkpoint_in` is an input file, `checkpoint_out` goes to the run folder.

use sonoflow_messages::types::{FlowStats, ParticleSnapshot, VectorField};
use sonoflow_messages::MessageType::*;
use sonoflow_messages::*;
use sonoflow_node_kit::PortDir::*;
use sonoflow_node_kit::{parse_params, port, Handshake, KindSpec};
// The solver runs on rayon threads: its cost is the process CPU time (the node does nothing else).
use crate::flow_topics::{publish_fluid, publish_truth};
use sonoflow_node_kit::{process_cpu_ns as thread_cpu_ns, Kit, Output};
use sonoflow_sph::producer::{Event, Prepared, Producer, ProducerParams};
use sonoflow_sph::{Diagnostics, DtCriterion};

/// The `sph-flow` node kind.
pub const SPEC: KindSpec = KindSpec::new(
    "sph-flow",
    "weakly compressible SPH blood flow (paper 1 §2.1–2.2) in a vessel geometry (carotid bifurcation preset): fluid particles = scatterers at the acquisition times, SPH-interpolated ground truth, solver diagnostics",
    &[
            port("particles", Out, ParticleSnapshotV1, true),
            port("truth", Out, VectorFieldV2, false),
            port("stats", Out, FlowStatsV1, false),
        ],
    validate,
    run,
)
.with_input_files(&["checkpoint_in"]);

/// Parses and checks the node parameters (without building the particles).
pub fn prepare(v: &serde_json::Value) -> Result<Prepared, String> {
    parse_params::<ProducerParams>(v)?.prepare().map_err(|e| e.to_string())
}

pub fn validate(v: &serde_json::Value) -> Result<(), String> {
    prepare(v).map(|_| ())
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

/// The diagnostics as `FlowStatsV1` (one `BoundaryFluxV1` per open boundary).
fn publish_stats(out: &mut Output<FlowStats>, d: &Diagnostics, frame_id: u64, cpu_ns: u64) -> anyhow::Result<()> {
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
    out.publish_in_place(d.boundaries.len(), h, |dst| {
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

/// The node's outputs (`truth` and `stats` where wired).
struct Ports {
    particles: Output<ParticleSnapshot>,
    truth: Option<Output<VectorField>>,
    stats: Option<Output<FlowStats>>,
}

impl Ports {
    fn open(kit: &mut Kit) -> anyhow::Result<Self> {
        let particles = kit.output::<ParticleSnapshot>("particles")?;
        let truth = kit.cfg.outputs.contains_key("truth").then(|| kit.output::<VectorField>("truth")).transpose()?;
        let stats = kit.cfg.outputs.contains_key("stats").then(|| kit.output::<FlowStats>("stats")).transpose()?;
        let mut p = Ports { particles, truth, stats };
        let mut ports: Vec<&mut dyn Handshake> = vec![&mut p.particles];
        ports.extend(p.truth.iter_mut().map(|t| t as &mut dyn Handshake));
        ports.extend(p.stats.iter_mut().map(|s| s as &mut dyn Handshake));
        kit.handshake(&mut ports)?;
        Ok(p)
    }

    /// Publishes the producer's diagnostics on `stats` if wired.
    fn stats(&mut self, producer: &Producer, frame_id: u64, cpu_ns: u64) -> anyhow::Result<()> {
        match self.stats.as_mut() {
            Some(so) => publish_stats(so, &producer.diagnostics(), frame_id, cpu_ns),
            None => Ok(()),
        }
    }
}

pub fn run(mut kit: Kit) -> anyhow::Result<()> {
    let prep = prepare(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    let mut producer = Producer::new(&prep, kit.cfg.outputs.contains_key("truth"))?;
    producer.take_log().iter().for_each(|l| eprintln!("sph-flow: {l}"));
    let mut ports = Ports::open(&mut kit)?;
    // solver CPU time since the last frame; a termination request while stepping is an error
    let (mut solver_cpu, mut stepping) = (0u64, false);
    loop {
        if kit.check_termination().is_err() {
            anyhow::ensure!(!stepping, "terminated at t = {} s", producer.time());
            break;
        }
        let t0 = thread_cpu_ns();
        let Some(event) = producer.next_event()? else { break };
        stepping = matches!(event, Event::Advanced { .. });
        match event {
            Event::Advanced { stats, .. } => {
                solver_cpu += thread_cpu_ns() - t0;
                if let Some(pr) = stats {
                    ports.stats(&producer, 0, solver_cpu)?;
                    kit.progress(pr.done, pr.total);
                }
            }
            Event::Snapshot(s) => {
                publish_fluid(
                    &mut ports.particles,
                    &s.at,
                    s.packet_size,
                    s.dt,
                    &s.particles,
                    &s.tissue,
                    s.tissue_moves,
                )?;
                kit.stats.messages_out += 1;
                kit.stats.bytes_out += ((s.particles.len() + s.tissue.len()) * 32) as u64;
                kit.record(s.at.frame_id, s.at.t, solver_cpu + (thread_cpu_ns() - t0))?;
                solver_cpu = 0;
                ports.stats(&producer, s.at.frame_id, 0)?;
                kit.progress(s.progress.done, s.progress.total);
            }
            Event::Truth(f) => {
                if let Some(tout) = ports.truth.as_mut() {
                    publish_truth(tout, &f.grid, &f.truth, f.packet, f.frame_id, f.t)?;
                    kit.stats.messages_out += 1;
                    kit.record(f.frame_id, f.t, thread_cpu_ns() - t0)?;
                }
            }
        }
    }
    ports.stats(&producer, 0, solver_cpu)?;
    eprintln!("sph-flow: {}", producer.summary());
    if let Some(path) = producer.write_checkpoint(kit.cfg.out_dir.as_deref().map(std::path::Path::new))? {
        eprintln!("sph-flow: checkpoint at t = {} s written to {}", producer.time(), path.display());
    }
    ports.particles.publish_eos(producer.last_frame_time())?;
    if let Some(t) = ports.truth.as_mut() {
        t.publish_eos(producer.last_frame_time())?;
    }
    if let Some(s) = ports.stats.as_mut() {
        s.publish_eos(producer.time())?;
    }
    kit.finish()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dt_criteria_map_to_their_wire_codes() {
        let all = [
            (None, DT_CFL),
            (Some(DtCriterion::Cfl), DT_CFL),
            (Some(DtCriterion::Viscous), DT_VISCOUS),
            (Some(DtCriterion::Force), DT_FORCE),
            (Some(DtCriterion::Maximum), DT_MAXIMUM),
            (Some(DtCriterion::Output), DT_OUTPUT),
        ];
        for (criterion, code) in all {
            assert_eq!(binding_code(criterion), code, "{criterion:?}");
        }
    }

    #[test]
    fn the_node_params_are_the_producers_with_named_errors() {
        validate(&serde_json::Value::Null).expect("all defaults");
        let e = validate(&serde_json::json!({ "solver": { "speed_of_sound": 3.0 } })).expect_err("unknown");
        assert!(e.starts_with("solver") && e.contains("speed_of_sound"), "{e}");
        let e = validate(&serde_json::json!({ "schedule": { "prf": -1.0 } })).expect_err("prf");
        assert!(e.starts_with("schedule.prf"), "{e}");
    }
}
