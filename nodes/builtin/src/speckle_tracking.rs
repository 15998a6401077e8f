//! `speckle-tracking` node: thin wrapper of `sonoflow_doppler::SpeckleAssembler` (MUST
//! `sptrack`), the alternative to the `doppler` node with the same ports.
//!
//! Collects the I/Q images of a packet per look and, per finished packet, publishes `vector`
//! (vx, vz, flags, power, weight = √correlation) on the images' grid and, if connected, `maps`:
//! one map of the tracked field's axial component (velocity toward the probe, power,
//! 1 − correlation as variance, flags, projection (0, −1)), so that a launch file swaps it in for
//! `doppler` unchanged and the evaluator scores it the same way.

use sonoflow_beamform::C32;
use sonoflow_doppler::{LookHeader, SpeckleAssembler, SpeckleParams, SpeckleProducts};
use sonoflow_messages::MessageType::*;
use sonoflow_messages::{
    plane, DopplerMapHeaderV2, GridV1, MsgHeaderV1, VectorFieldHeaderV2, ESTIMATOR_SPECKLE_TRACKING, VECTOR_RAW,
};
use sonoflow_node_kit::PortDir::*;
use sonoflow_node_kit::{parse_params, port, KindSpec, Kit};

use crate::packet_node::{run_packet_node, wire_clutter_kind, Message, PacketEstimator, PacketMessages};

/// The `speckle-tracking` node kind.
pub const SPEC: KindSpec = KindSpec::new(
    "speckle-tracking",
    "speckle tracking per packet (MUST sptrack): ensemble FFT cross-correlation of the envelope between frames t and t + lag, multi-pass windows, sub-pixel peak, median test; the vector field on the image grid",
    &[
        port("iq", In, IqFrameV3, true),
        port("vector", Out, VectorFieldV2, true),
        port("maps", Out, DopplerMapV2, false),
    ],
    validate,
    run,
);

pub fn validate(v: &serde_json::Value) -> Result<(), String> {
    parse_params::<SpeckleParams>(v)?.validate().map_err(|e| e.to_string())
}

/// The messages of one packet: the axial map, then the vector field.
pub fn packet_messages(
    r: &SpeckleProducts,
    p: &SpeckleParams,
) -> (Message<DopplerMapHeaderV2>, Message<VectorFieldHeaderV2>) {
    let n = r.grid.nx * r.grid.nz;
    let grid = GridV1 {
        x0: r.grid.x0,
        z0: r.grid.z0,
        dx: r.grid.dx,
        dz: r.grid.dz,
        nx: r.grid.nx as u32,
        nz: r.grid.nz as u32,
    };
    let h = &r.header;
    let flags: Vec<f32> = r.flags.iter().map(|f| f32::from(*f)).collect();
    let mut mp = Vec::with_capacity(6 * n);
    mp.extend(r.vz.iter().map(|v| -v));
    mp.extend_from_slice(&r.power);
    mp.extend(r.weight.iter().map(|w| 1.0 - w * w));
    mp.extend_from_slice(&flags);
    mp.extend(std::iter::repeat_n(0.0f32, n));
    mp.extend(std::iter::repeat_n(-1.0f32, n));
    // The largest axial displacement the last window can see: half of it per lag.
    let last = p.windows.last().copied().unwrap_or([2, 2]);
    let mut mh = DopplerMapHeaderV2 {
        grid,
        fc: h.fc,
        c: h.c,
        prf: h.prf,
        rx_angle: 0.0,
        tx_angle: 0.0,
        nyquist_velocity: (last[0] / 2) as f64 * r.grid.dz * h.prf / p.lag as f64,
        packet: r.packet,
        packet_size: r.frames as u32,
        n_planes: 6,
        estimator: ESTIMATOR_SPECKLE_TRACKING,
        clutter_filter: wire_clutter_kind(r.clutter.kind),
        clutter_order: r.clutter.order_or_rank as u32,
        clutter_cutoff: r.clutter.cutoff,
        clutter_removed_energy: r.clutter.removed_energy,
        ..Default::default()
    };
    mh.plane_ids[..6].copy_from_slice(&[
        plane::VELOCITY,
        plane::POWER,
        plane::VARIANCE,
        plane::FLAGS,
        plane::PROJECTION_X,
        plane::PROJECTION_Z,
    ]);
    mh.common = MsgHeaderV1 { frame_id: r.frame_id, t_valid: r.t_valid, ..Default::default() };
    let mut vp = Vec::with_capacity(5 * n);
    vp.extend_from_slice(&r.vx);
    vp.extend_from_slice(&r.vz);
    vp.extend_from_slice(&flags);
    vp.extend_from_slice(&r.power);
    vp.extend_from_slice(&r.weight);
    let mut vh = VectorFieldHeaderV2 {
        grid,
        n_planes: 5,
        source: VECTOR_RAW,
        packet: r.packet,
        converged: 1,
        clutter_filter: wire_clutter_kind(r.clutter.kind),
        clutter_order: r.clutter.order_or_rank as u32,
        clutter_cutoff: r.clutter.cutoff,
        clutter_removed_energy: r.clutter.removed_energy,
        n_looks: r.n_looks as u32,
        ..Default::default()
    };
    vh.plane_ids[..5].copy_from_slice(&[plane::VX, plane::VZ, plane::FLAGS, plane::POWER, plane::WEIGHT]);
    vh.common = MsgHeaderV1 { frame_id: r.frame_id, t_valid: r.t_valid, ..Default::default() };
    ((mh, mp), (vh, vp))
}

/// The `speckle-tracking` node's estimator: the assembler and its parameters.
struct Speckle {
    assembler: SpeckleAssembler,
    params: SpeckleParams,
}

impl PacketEstimator for Speckle {
    type Products = SpeckleProducts;
    fn push(&mut self, h: &LookHeader, frame: Vec<C32>) -> anyhow::Result<Option<SpeckleProducts>> {
        Ok(self.assembler.push(h, frame)?)
    }
    fn finish(&mut self) -> anyhow::Result<Option<SpeckleProducts>> {
        Ok(self.assembler.finish()?)
    }
    fn messages(&mut self, r: SpeckleProducts) -> PacketMessages {
        let (map, vector) = packet_messages(&r, &self.params);
        (vec![map], vector)
    }
}

pub fn run(kit: Kit) -> anyhow::Result<()> {
    let params: SpeckleParams = parse_params(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    run_packet_node(kit, Speckle { assembler: SpeckleAssembler::new(params.clone())?, params })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn speckle_params_errors_name_the_field() {
        let bad = |v: serde_json::Value, needle: &str| {
            let e = validate(&v).unwrap_err();
            assert!(e.contains(needle), "{e}");
        };
        bad(serde_json::json!({"lag": 0}), "lag");
        bad(serde_json::json!({"windows": [[16, 16], [32, 32]]}), "windows");
        bad(serde_json::json!({"windows": [[2, 16]]}), "windows");
        bad(serde_json::json!({"windows": []}), "windows");
        bad(serde_json::json!({"overlap": 1.0}), "overlap");
        bad(serde_json::json!({"min_correlation": 1.5}), "min_correlation");
        bad(serde_json::json!({"median_threshold": -1}), "median_threshold");
        bad(serde_json::json!({"subpixel": "gaussian"}), "subpixel");
        bad(serde_json::json!({"window": [3, 3]}), "window");
        assert!(validate(&serde_json::json!({"windows": [[32, 24], [16, 16]], "lag": 6})).is_ok());
    }
}
