//! `analytic-flow` node: thin wiring of `sonoflow-analytic-flow` — particle snapshots at every
//! acquisition time, the exact velocity field on a grid once per packet (at its mid time).

use crate::flow_topics::{publish_fluid, publish_truth};
use sonoflow_analytic_flow::{AnalyticFlow, AnalyticFlowParams, GridSpec};
use sonoflow_messages::types::{ParticleSnapshot, VectorField};
use sonoflow_messages::MessageType::*;
use sonoflow_node_kit::parse_params;
use sonoflow_node_kit::PortDir::*;
use sonoflow_node_kit::{port, KindSpec};
use sonoflow_node_kit::{thread_cpu_ns, Kit};

/// The `analytic-flow` node kind.
pub const SPEC: KindSpec = KindSpec::new(
    "analytic-flow",
    "scatterers moved by an analytic flow (Poiseuille vessel, rotating disk, plug band) at the acquisition times, plus the exact field as ground truth",
    &[port("particles", Out, ParticleSnapshotV1, true), port("truth", Out, VectorFieldV2, false)],
    validate,
    run,
);

/// Default ground-truth grid: 20 mm × 20 mm from 10 mm depth, 0.25 mm spacing.
pub fn default_truth_grid() -> GridSpec {
    GridSpec { nx: 81, nz: 81, x0: -0.01, z0: 0.01, dx: 0.25e-3, dz: 0.25e-3 }
}

/// Splits the node params into the library's params and the truth grid.
pub fn split_params(v: &serde_json::Value) -> Result<(AnalyticFlowParams, GridSpec), String> {
    let mut v = if v.is_null() { serde_json::json!({}) } else { v.clone() };
    let grid = match v.as_object_mut().and_then(|o| o.remove("truth_grid")) {
        Some(g) => serde_json::from_value::<GridSpec>(g).map_err(|e| format!("truth_grid: {e}"))?,
        None => default_truth_grid(),
    };
    let p: AnalyticFlowParams = parse_params(&v)?;
    p.validate().map_err(|e| e.to_string())?;
    grid.validate().map_err(|e| format!("truth_grid: {e}"))?;
    Ok((p, grid))
}

pub fn validate(v: &serde_json::Value) -> Result<(), String> {
    split_params(v).map(|_| ())
}

pub fn run(mut kit: Kit) -> anyhow::Result<()> {
    let (params, grid) = split_params(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    let mut flow = AnalyticFlow::new(&params)?;
    let mut out = kit.output::<ParticleSnapshot>("particles")?;
    let mut truth_out = match kit.cfg.outputs.contains_key("truth") {
        true => Some(kit.output::<VectorField>("truth")?),
        false => None,
    };
    let n = flow.particles().len() + flow.tissue().len();
    if n > out.max_elements() {
        anyhow::bail!(
            "the flow has {n} scatterers but topic `{}` allows max_elements = {}: raise it in the launch file or lower density_per_mm2 (and tissue.density_per_mm2)",
            out.topic(),
            out.max_elements()
        );
    }
    match truth_out.as_mut() {
        Some(t) => kit.handshake(&mut [&mut out, t])?,
        None => kit.handshake(&mut [&mut out])?,
    }
    let times = params.schedule.times();
    let total = times.len() as u64;
    let step = (total / 20).max(1);
    let mut last_t = 0.0;
    for (k, at) in times.iter().enumerate() {
        if kit.check_termination().is_err() {
            break;
        }
        let t0 = thread_cpu_ns();
        flow.advance_to(at.t)?;
        let moves = flow.tissue_moves();
        publish_fluid(&mut out, at, params.schedule.packet_size, 0.0, flow.particles(), flow.tissue(), moves)?;
        let compute = thread_cpu_ns() - t0;
        kit.published((n * 32) as u64, at.frame_id, at.t, compute)?;
        last_t = at.t;

        let packet_done = at.frame_in_packet + 1 == params.schedule.packet_size;
        if let (true, Some(tout)) = (packet_done, truth_out.as_mut()) {
            let t0 = thread_cpu_ns();
            let t_mid = params.schedule.packet_mid_time(at.packet);
            let truth = flow.sample_truth_at(&grid, t_mid)?;
            publish_truth(tout, &grid, &truth, at.packet, at.frame_id, t_mid)?;
            kit.stats.messages_out += 1;
            kit.record(at.frame_id, t_mid, thread_cpu_ns() - t0)?;
        }
        if (k as u64 + 1).is_multiple_of(step) || k as u64 + 1 == total {
            kit.progress(k as u64 + 1, total);
        }
    }
    out.publish_eos(last_t)?;
    if let Some(t) = truth_out.as_mut() {
        t.publish_eos(last_t)?;
    }
    kit.finish()?;
    Ok(())
}
