//! `doppler` node: thin wrapper of `sonoflow_doppler::PacketAssembler`.
//!
//! Collects the I/Q images of a packet per look and, per finished packet, publishes `vector`
//! (vx, vz, flags, power) and, if connected, `maps` (per look: velocity, power, normalised
//! variance, flags and the projection vector `projection_x`, `projection_z` the velocity
//! measures). The estimator is the param `estimator` (`autocorrelation`, `loupas`); the receive
//! aperture of each look comes in the I/Q header (`projection = "nominal"` ignores it).

use sonoflow_beamform::{Apodization, Grid, C32};
use sonoflow_doppler::clutter::kind as clutter_kind;
use sonoflow_doppler::{Aperture, Estimator, LookHeader, PacketAssembler, PacketParams, PacketProducts};
use sonoflow_messages::types::{DopplerMap as DopplerMapMsg, IqFrame, VectorField};
use sonoflow_messages::MessageType::*;
use sonoflow_messages::{
    plane, Complex32, DopplerMapHeaderV2, IqFrameHeaderV3, MsgHeaderV1, VectorFieldHeaderV2, APODIZATION_HANN,
    CLUTTER_IIR, CLUTTER_NONE, CLUTTER_POLYNOMIAL, CLUTTER_SVD, ESTIMATOR_AUTOCORRELATION, ESTIMATOR_LOUPAS,
    VECTOR_RAW,
};
use sonoflow_node_kit::PortDir::*;
use sonoflow_node_kit::{for_each, parse_params, port, process_cpu_ns, Flow, KindSpec, Kit};

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

/// The library's view of an I/Q header: grid, look and receive aperture (none if
/// `n_elements` = 0).
pub fn look_header(h: &IqFrameHeaderV3) -> LookHeader {
    let g = h.grid;
    LookHeader {
        grid: Grid { x0: g.x0, z0: g.z0, dx: g.dx, dz: g.dz, nx: g.nx as usize, nz: g.nz as usize },
        fc: h.fc,
        c: h.c,
        prf: h.prf,
        tx_angle: h.tx_angle,
        rx_angle: h.rx_angle,
        packet: h.packet,
        frame_id: h.common.frame_id,
        t_valid: h.common.t_valid,
        aperture: (h.n_elements > 0).then(|| Aperture {
            pitch: h.pitch,
            n_elements: h.n_elements as usize,
            fnumber: h.fnumber,
            width: (h.element_width > 0.0).then_some(h.element_width),
            radius: (h.radius.is_finite() && h.radius > 0.0).then_some(h.radius),
            apodization: if h.apodization == APODIZATION_HANN { Apodization::Hann } else { Apodization::Boxcar },
        }),
    }
}

/// The wire's `CLUTTER_*` for the library's clutter filter kind.
pub fn wire_clutter_kind(kind: u32) -> u32 {
    match kind {
        clutter_kind::POLYNOMIAL => CLUTTER_POLYNOMIAL,
        clutter_kind::IIR => CLUTTER_IIR,
        clutter_kind::SVD => CLUTTER_SVD,
        _ => CLUTTER_NONE,
    }
}

/// A header and its payload planes.
type Message<H> = (H, Vec<f32>);

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

/// Wire I/Q samples as the library's complex type.
pub fn to_c32(iq: &[Complex32]) -> Vec<C32> {
    iq.iter().map(|c| C32::new(c.re, c.im)).collect()
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

/// The messages of one packet: the Doppler maps (one per look, or none), then the vector field.
pub type PacketMessages = (Vec<Message<DopplerMapHeaderV2>>, Message<VectorFieldHeaderV2>);

/// A per-packet estimator behind the `iq` → `vector` (+ optional `maps`) ports: the library's
/// assembler and how its products become messages. [`run_packet_node`] does the rest.
pub trait PacketEstimator {
    /// What the assembler returns per finished packet.
    type Products;
    /// Adds one image; the finished previous packet if this image starts a new one.
    fn push(&mut self, h: &LookHeader, frame: Vec<C32>) -> anyhow::Result<Option<Self::Products>>;
    /// Finishes the pending packet at the end of the stream.
    fn finish(&mut self) -> anyhow::Result<Option<Self::Products>>;
    /// The packet's messages (the estimator may log about the packet here).
    fn messages(&mut self, r: Self::Products) -> PacketMessages;
}

/// The node loop shared by the per-packet estimators: reads I/Q frames, publishes each finished
/// packet's maps (if `maps` is connected) and vector field with the process CPU time the packet
/// cost, then end-of-stream on every output.
pub fn run_packet_node<E: PacketEstimator>(mut kit: Kit, mut est: E) -> anyhow::Result<()> {
    let mut input = kit.input::<IqFrame>("iq")?;
    let mut vout = kit.output::<VectorField>("vector")?;
    let mut mout = match kit.cfg.outputs.contains_key("maps") {
        true => Some(kit.output::<DopplerMapMsg>("maps")?),
        false => None,
    };
    match mout.as_mut() {
        Some(m) => kit.handshake(&mut [&mut input, &mut vout, m])?,
        None => kit.handshake(&mut [&mut input, &mut vout])?,
    }
    let mut publish = |kit: &mut Kit, (maps, (mut vh, planes)): PacketMessages, compute: u64| -> anyhow::Result<()> {
        if let Some(m) = mout.as_mut() {
            for (mut h, planes) in maps {
                h.common.compute_ns = compute;
                m.publish_copy(h, &planes)?;
                kit.stats.messages_out += 1;
            }
        }
        vh.common.compute_ns = compute;
        vout.publish_copy(vh, &planes)?;
        kit.stats.messages_out += 1;
        kit.stats.bytes_out += (planes.len() * 4) as u64;
        Ok(kit.record(vh.common.frame_id, vh.common.t_valid, compute)?)
    };
    let (mut last_t, mut acc_ns) = (0.0, 0u64);
    for_each(&mut kit, &mut input, |kit, sample| {
        let t0 = process_cpu_ns();
        let h = *sample.user_header();
        let done = est.push(&look_header(&h), to_c32(sample.payload()))?;
        kit.stats.messages_in += 1;
        acc_ns += process_cpu_ns() - t0;
        if let Some(r) = done {
            publish(kit, est.messages(r), acc_ns)?;
            acc_ns = 0;
        }
        last_t = h.common.t_valid;
        Ok(Flow::Continue)
    })?;
    let t0 = process_cpu_ns();
    if let Some(r) = est.finish()? {
        let compute = acc_ns + process_cpu_ns() - t0;
        publish(&mut kit, est.messages(r), compute)?;
    }
    vout.publish_eos(last_t)?;
    if let Some(m) = mout.as_mut() {
        m.publish_eos(last_t)?;
    }
    kit.finish_after(&input)?;
    Ok(())
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
