//! `gain` node: multiplies RF frames by a constant — a minimal processing stage, and the model
//! for external nodes (`sonoflow-external-nodes`).

use serde::{Deserialize, Serialize};
use sonoflow_messages::types::RfFrame;
use sonoflow_messages::MessageType::*;
use sonoflow_node_kit::transform;
use sonoflow_node_kit::PortDir::*;
use sonoflow_node_kit::{parse_params, thread_cpu_ns, Kit};
use sonoflow_node_kit::{port, KindSpec};

/// The `gain` node kind.
pub const SPEC: KindSpec = KindSpec::new(
    "gain",
    "multiplies RF frames by a constant (a minimal processing stage)",
    &[port("rf_in", In, RfFrameV3, true), port("rf_out", Out, RfFrameV3, true)],
    validate_gain,
    run_gain,
);

/// `gain` parameters.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct GainParams {
    /// Multiplier (finite).
    pub gain: f32,
}

impl Default for GainParams {
    fn default() -> Self {
        Self { gain: 2.0 }
    }
}

pub fn validate_gain(v: &serde_json::Value) -> Result<(), String> {
    let p = parse_params::<GainParams>(v)?;
    if !p.gain.is_finite() || p.gain.abs() > 1e30 {
        return Err(format!("gain = {} is out of range: finite, |gain| <= 1e30", p.gain));
    }
    Ok(())
}

pub fn run_gain(mut kit: Kit) -> anyhow::Result<()> {
    validate_gain(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    let p: GainParams = parse_params(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    let mut input = kit.input::<RfFrame>("rf_in")?;
    let mut out = kit.output::<RfFrame>("rf_out")?;
    kit.handshake(&mut [&mut input, &mut out])?;
    transform(kit, &mut input, &mut out, |kit, out, sample| {
        let t0 = thread_cpu_ns();
        let src = sample.payload();
        let mut h = *sample.user_header();
        // Fresh common header: keep the frame id and time of validity only.
        h.common = sonoflow_messages::MsgHeaderV1 {
            frame_id: h.common.frame_id,
            t_valid: h.common.t_valid,
            ..Default::default()
        };
        out.publish_in_place(src.len(), h, |dst| {
            for (d, s) in dst.iter_mut().zip(src) {
                d.write(s * p.gain);
            }
        })?;
        let compute = thread_cpu_ns() - t0;
        kit.published((src.len() * 4) as u64, h.common.frame_id, h.common.t_valid, compute)?;
        Ok(())
    })
}
