//! Foxglove well-known-schema pictures of wire messages, so a recording opens in Foxglove with
//! images: particles → `foxglove.PointCloud`, Doppler maps and vector fields → `foxglove.Grid`
//! (real geometry, one FLOAT32 field per plane), beamformed I/Q → `foxglove.RawImage` (B-mode,
//! mono8, 60 dB dynamic range). RF frames have no picture (raw record only).

use crate::types::{MessageType, WireMessage};
use crate::wire::*;
use foxglove::schemas::{packed_element_field::NumericType, PackedElementField, Pose, Quaternion, Vector2, Vector3};
use foxglove::Encode;

/// An encoded Foxglove message with its schema.
pub struct VizMessage {
    pub schema_name: String,
    pub schema_encoding: String,
    pub schema_data: Vec<u8>,
    pub message_encoding: String,
    pub data: Vec<u8>,
}

fn encode<T: Encode>(msg: &T) -> Option<VizMessage> {
    let schema = T::get_schema()?;
    let mut data = Vec::with_capacity(msg.encoded_len().unwrap_or(1024));
    msg.encode(&mut data).ok()?;
    Some(VizMessage {
        schema_name: schema.name,
        schema_encoding: schema.encoding,
        schema_data: schema.data.into_owned(),
        message_encoding: T::get_message_encoding(),
        data,
    })
}

fn timestamp(t: f64) -> Option<foxglove::schemas::Timestamp> {
    Some(foxglove::schemas::Timestamp::saturating_from_epoch_secs_f64(t.max(0.0)))
}

fn identity_pose(x: f64, y: f64) -> Option<Pose> {
    Some(Pose {
        position: Some(Vector3 { x, y, z: 0.0 }),
        orientation: Some(Quaternion { x: 0.0, y: 0.0, z: 0.0, w: 1.0 }),
    })
}

fn field(name: &str, offset: u32) -> PackedElementField {
    PackedElementField { name: name.into(), offset, r#type: NumericType::Float32 as i32 }
}

/// The schema of the picture [`viz`] makes of a message type (`None`: the type has no picture),
/// known before any message arrives, so a live viewer can advertise its channels up front.
pub fn viz_schema(kind: MessageType) -> Option<foxglove::Schema> {
    match kind {
        MessageType::ParticleSnapshotV1 => foxglove::schemas::PointCloud::get_schema(),
        MessageType::DopplerMapV2 | MessageType::VectorFieldV2 => foxglove::schemas::Grid::get_schema(),
        MessageType::IqFrameV3 => foxglove::schemas::RawImage::get_schema(),
        MessageType::RfFrameV3 | MessageType::StageStatsV1 | MessageType::FlowStatsV1 => None,
    }
}

/// Whether messages of this type have a picture.
pub fn has_picture(kind: MessageType) -> bool {
    viz_schema(kind).is_some()
}

/// Message encoding of every picture (`protobuf`).
pub fn viz_message_encoding() -> String {
    foxglove::schemas::Grid::get_message_encoding()
}

/// Picture of a message, if its kind has one. `header`/`payload` are the raw wire bytes.
pub fn viz(kind: MessageType, header: &[u8], payload: &[u8]) -> Option<VizMessage> {
    match kind {
        MessageType::ParticleSnapshotV1 => {
            let h: ParticleSnapshotHeaderV1 = bytemuck::try_pod_read_unaligned(header).ok()?;
            // Particle layout: id u32, kind u32, x, z, vx, vz, amplitude (f32). Depth z is drawn
            // as -y so the image reads top-down like an ultrasound image.
            let n = payload.len() / 32;
            let mut data = Vec::with_capacity(n * 20);
            for p in bytemuck::pod_collect_to_vec::<u8, ParticleV1>(payload) {
                for v in [p.x, -p.z, p.vx, p.vz, p.amplitude] {
                    data.extend_from_slice(&v.to_le_bytes());
                }
            }
            encode(&foxglove::schemas::PointCloud {
                timestamp: timestamp(h.common.t_valid),
                frame_id: "probe".into(),
                pose: identity_pose(0.0, 0.0),
                point_stride: 20,
                fields: vec![field("x", 0), field("y", 4), field("vx", 8), field("vz", 12), field("amplitude", 16)],
                data: data.into(),
            })
        }
        MessageType::DopplerMapV2 => {
            let h: DopplerMapHeaderV2 = bytemuck::try_pod_read_unaligned(header).ok()?;
            grid(h.common.t_valid, &h.grid, h.n_planes, &h.plane_ids, payload)
        }
        MessageType::VectorFieldV2 => {
            let h: VectorFieldHeaderV2 = bytemuck::try_pod_read_unaligned(header).ok()?;
            grid(h.common.t_valid, &h.grid, h.n_planes, &h.plane_ids, payload)
        }
        MessageType::IqFrameV3 => {
            let h: IqFrameHeaderV3 = bytemuck::try_pod_read_unaligned(header).ok()?;
            let iq: Vec<Complex32> = bytemuck::pod_collect_to_vec(payload);
            let (nx, nz) = (h.grid.nx as usize, h.grid.nz as usize);
            if iq.len() != nx * nz || iq.is_empty() {
                return None;
            }
            let mag: Vec<f32> = iq.iter().map(|c| (c.re * c.re + c.im * c.im).sqrt()).collect();
            let max = mag.iter().cloned().fold(0.0f32, f32::max);
            let data: Vec<u8> = mag
                .iter()
                .map(|&m| {
                    let db = if max > 0.0 && m > 0.0 { 20.0 * (m / max).log10() } else { -60.0 };
                    (((db + 60.0) / 60.0).clamp(0.0, 1.0) * 255.0).round() as u8
                })
                .collect();
            encode(&foxglove::schemas::RawImage {
                timestamp: timestamp(h.common.t_valid),
                frame_id: "probe".into(),
                width: nx as u32,
                height: nz as u32,
                encoding: "mono8".into(),
                step: nx as u32,
                data: data.into(),
            })
        }
        MessageType::RfFrameV3 | MessageType::StageStatsV1 | MessageType::FlowStatsV1 => None,
    }
}

fn grid(t: f64, g: &GridV1, n_planes: u32, ids: &[u32; 8], payload: &[u8]) -> Option<VizMessage> {
    let (nx, nz, np) = (g.nx as usize, g.nz as usize, (n_planes as usize).min(MAX_PLANES));
    let planes: Vec<f32> = bytemuck::pod_collect_to_vec(payload);
    if np == 0 || planes.len() != nx * nz * np {
        return None;
    }
    // Interleave planes into cells; rows go up in +y, so row r is depth row nz-1-r (y = -z).
    let mut data = Vec::with_capacity(planes.len() * 4);
    for r in 0..nz {
        let iz = nz - 1 - r;
        for ix in 0..nx {
            for p in 0..np {
                data.extend_from_slice(&planes[p * nx * nz + iz * nx + ix].to_le_bytes());
            }
        }
    }
    let fields = (0..np).map(|p| field(crate::wire::plane::name(ids[p]), (4 * p) as u32)).collect();
    encode(&foxglove::schemas::Grid {
        timestamp: timestamp(t),
        frame_id: "probe".into(),
        pose: identity_pose(g.x0 - 0.5 * g.dx, -(g.z0 + (nz as f64 - 0.5) * g.dz)),
        column_count: nx as u32,
        cell_size: Some(Vector2 { x: g.dx, y: g.dz }),
        row_stride: (nx * np * 4) as u32,
        cell_stride: (np * 4) as u32,
        fields,
        data: data.into(),
    })
}

/// Topic of the picture channel for a raw topic (`particles` → `viz/particles`).
pub fn viz_topic(topic: &str) -> String {
    format!("viz/{topic}")
}

#[allow(dead_code)]
fn _assert_marker<M: WireMessage>() {}
