//! The node loop shared by the per-packet estimator kinds (`doppler`, `speckle-tracking`): I/Q
//! frames in on `iq`, per finished packet the Doppler maps on `maps` (when connected) and the
//! vector field on `vector`; and the wire ↔ library conversions they share.

use sonoflow_beamform::{Apodization, Grid, C32};
use sonoflow_doppler::clutter::kind as clutter_kind;
use sonoflow_doppler::{Aperture, LookHeader};
use sonoflow_messages::types::{DopplerMap as DopplerMapMsg, IqFrame, VectorField};
use sonoflow_messages::{
    Complex32, DopplerMapHeaderV2, IqFrameHeaderV3, VectorFieldHeaderV2, APODIZATION_HANN, CLUTTER_IIR, CLUTTER_NONE,
    CLUTTER_POLYNOMIAL, CLUTTER_SVD,
};
use sonoflow_node_kit::{for_each, process_cpu_ns, Flow, Kit};

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
pub type Message<H> = (H, Vec<f32>);

/// Wire I/Q samples as the library's complex type.
pub fn to_c32(iq: &[Complex32]) -> Vec<C32> {
    iq.iter().map(|c| C32::new(c.re, c.im)).collect()
}

/// The messages of one packet: its Doppler maps (one per look, or one for the speckle tracker),
/// then the vector field.
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
