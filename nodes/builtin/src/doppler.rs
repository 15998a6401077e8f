//! `doppler` node: thin wrapper of `sonoflow_doppler::PacketAssembler` in the shared per-packet
//! loop ([`crate::packet_node`]).
//!
//! Collects the I/Q images of a packet per look and, per finished packet, publishes `vector`
//! (vx, vz, flags, power) and, if connected, `maps` (per look: velocity, power, normalised
//! variance, flags and the projection vector `projection_x`, `projection_z` the velocity
//! measures). The estimator is the param `estimator` (`autocorrelation`, `loupas`); the receive
//! aperture of each look comes in the I/Q header (`projection = "nominal"` ignores it).

use sonoflow_beamform::C32;
use sonoflow_doppler::{Estimator, LookHeader, PacketAssembler, PacketParams, PacketProducts};
use sonoflow_messages::MessageType::*;
use sonoflow_messages::{
    plane, DopplerMapHeaderV2, MsgHeaderV1, VectorFieldHeaderV2, ESTIMATOR_AUTOCORRELATION, ESTIMATOR_LOUPAS,
    VECTOR_RAW,
};
use sonoflow_node_kit::PortDir::*;
use sonoflow_node_kit::{parse_params, port, KindSpec, Kit};

use crate::packet_node::{run_packet_node, wire_clutter_kind, PacketEstimator, PacketMessages};

/// The `doppler` node kind.
pub const SPEC: KindSpec = KindSpec::new(
    "doppler",
    "colour + vector Doppler per packet: lag-L slow-time autocorrelation (eq. 19) or Loupas per look, fc²-weighted least-squares (vx, vz) through each look's receive aperture",
    &[
        port("iq", In, IqFrameV3, true),
        port("vector", Out, VectorFieldV2, true),
        port("maps", Out, DopplerMapV2, false),
    ],
    validate,
    run,
);

pub fn validate(v: &serde_json::Value) -> Result<(), String> {
    parse_params::<PacketParams>(v)?.validate().map_err(|e| e.to_string())
}

/// The messages of one packet: one Doppler map per look, then the vector field.
pub fn packet_messages(r: PacketProducts) -> PacketMessages {
    let n = r.grid.nx * r.grid.nz;
    let grid = sonoflow_messages::GridV1 {
        x0: r.grid.x0,
        z0: r.grid.z0,
        dx: r.grid.dx,
        dz: r.grid.dz,
        nx: r.grid.nx as u32,
        nz: r.grid.nz as u32,
    };
    let maps = r
        .looks
        .iter()
        .map(|l| {
            let h = &l.header;
            let (px, pz) = l.projection_planes();
            let mut planes = Vec::with_capacity(6 * n);
            planes.extend_from_slice(&l.velocity);
            planes.extend_from_slice(&l.power);
            planes.extend_from_slice(&l.variance);
            planes.extend(l.flags.iter().map(|f| *f as f32));
            planes.extend(px);
            planes.extend(pz);
            let mut mh = DopplerMapHeaderV2 {
                grid,
                fc: h.fc,
                c: h.c,
                prf: h.prf,
                rx_angle: h.rx_angle,
                tx_angle: h.tx_angle,
                nyquist_velocity: l.nyquist,
                packet: h.packet,
                packet_size: l.packet_size as u32,
                n_planes: 6,
                estimator: match l.estimator {
                    Estimator::Autocorrelation => ESTIMATOR_AUTOCORRELATION,
                    Estimator::Loupas => ESTIMATOR_LOUPAS,
                },
                clutter_filter: wire_clutter_kind(l.clutter.kind),
                clutter_order: l.clutter.order_or_rank as u32,
                clutter_cutoff: l.clutter.cutoff,
                clutter_removed_energy: l.clutter.removed_energy,
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
            mh.common = MsgHeaderV1 { frame_id: h.frame_id, t_valid: h.t_valid, ..Default::default() };
            (mh, planes)
        })
        .collect();
    let mut planes = Vec::with_capacity(4 * n);
    planes.extend_from_slice(&r.vector.vx);
    planes.extend_from_slice(&r.vector.vz);
    planes.extend(r.vector.flags.iter().map(|f| *f as f32));
    planes.extend_from_slice(&r.power);
    let clutter = r.clutter_summary().unwrap_or_default();
    let mut vh = VectorFieldHeaderV2 {
        grid,
        n_planes: 4,
        source: VECTOR_RAW,
        packet: r.packet,
        converged: 1,
        clutter_filter: wire_clutter_kind(clutter.kind),
        clutter_order: clutter.order_or_rank as u32,
        clutter_cutoff: clutter.cutoff,
        clutter_removed_energy: clutter.removed_energy,
        n_looks: r.looks.len() as u32,
        rejected_looks: r.rejected_looks.len() as u32,
        ..Default::default()
    };
    vh.plane_ids[..4].copy_from_slice(&[plane::VX, plane::VZ, plane::FLAGS, plane::POWER]);
    vh.common = MsgHeaderV1 { frame_id: r.frame_id, t_valid: r.t_valid, ..Default::default() };
    (maps, (vh, planes))
}

/// The node's log lines for one packet: the looks left out of the vector solve, the share of
/// estimates the filter compensation corrected, and once (`warned_short`) a note when it runs on
/// packets shorter than 64 frames.
fn packet_notes(r: &PacketProducts, warned_short: &mut bool) -> Vec<String> {
    let mut notes = Vec::new();
    if !r.rejected_looks.is_empty() {
        let mut m: Vec<f64> = r.look_residuals.iter().copied().filter(|v| v.is_finite()).collect();
        m.sort_by(f64::total_cmp);
        let typical = m.get(m.len() / 2).copied().unwrap_or(f64::NAN);
        let which: Vec<String> = r
            .rejected_looks
            .iter()
            .map(|&i| {
                let h = &r.looks[i].header;
                let (deg, mhz) = (h.rx_angle.to_degrees(), h.fc / 1e6);
                format!("rx {deg:+.2}° at {mhz:.2} MHz (median residual {:.3} m/s)", r.look_residuals[i])
            })
            .collect();
        notes.push(format!(
            "doppler: packet {}: left out of the vector solve (look_rejection): {}; the looks' median {typical:.3} m/s",
            r.packet,
            which.join(", ")
        ));
    }
    let (corrected, kept) =
        r.looks.iter().fold((0, 0), |(c, k), l| (c + l.compensation.corrected, k + l.compensation.kept));
    if corrected + kept == 0 {
        return notes;
    }
    let frames = r.looks.first().map_or(0, |l| l.packet_size);
    if frames < 64 && !*warned_short {
        *warned_short = true;
        notes.push(format!(
            "doppler: note: compensate_filter with {frames}-frame packets: measured to help from 64 frames on and to hurt at 32 (docs/nodes.md, \"Filter compensation\")"
        ));
    }
    let share = 100.0 * corrected as f64 / (corrected + kept) as f64;
    notes.push(format!(
        "doppler: packet {}: compensate_filter corrected {share:.1} % of the estimates ({kept} kept the plain value)",
        r.packet
    ));
    notes
}

/// The `doppler` node's estimator: the packet assembler, and whether the short-packet note was
/// printed.
struct Doppler {
    assembler: PacketAssembler,
    warned_short: bool,
}

impl PacketEstimator for Doppler {
    type Products = PacketProducts;
    fn push(&mut self, h: &LookHeader, frame: Vec<C32>) -> anyhow::Result<Option<PacketProducts>> {
        Ok(self.assembler.push(h, frame)?)
    }
    fn finish(&mut self) -> anyhow::Result<Option<PacketProducts>> {
        Ok(self.assembler.finish()?)
    }
    fn messages(&mut self, r: PacketProducts) -> PacketMessages {
        for line in packet_notes(&r, &mut self.warned_short) {
            eprintln!("{line}");
        }
        packet_messages(r)
    }
}

pub fn run(kit: Kit) -> anyhow::Result<()> {
    let p: PacketParams = parse_params(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    run_packet_node(kit, Doppler { assembler: PacketAssembler::new(p)?, warned_short: false })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn doppler_params_errors_name_the_field() {
        let bad = |v: serde_json::Value, needle: &str| {
            let e = validate(&v).unwrap_err();
            assert!(e.contains(needle), "{e}");
        };
        bad(serde_json::json!({"lag": 0}), "lag");
        bad(serde_json::json!({"window": [0, 3]}), "window");
        bad(serde_json::json!({"clutter_order": 20}), "clutter_order");
        bad(serde_json::json!({"estimator": "music"}), "estimator");
        bad(serde_json::json!({"projection": "exact"}), "projection");
        // the retired per-node copy of the aperture is refused, not ignored
        bad(serde_json::json!({"aperture": {"pitch": 3e-4, "n_elements": 128, "fnumber": 1.5}}), "aperture");
    }
}
