#![allow(clippy::unwrap_used)]
#![allow(clippy::field_reassign_with_default)]
//! Pins the wire layout: a change here is a protocol change (bump the type name to `…V2`).
use sonoflow_messages::types::*;
use sonoflow_messages::*;
use std::mem::{align_of, offset_of, size_of};

#[test]
fn sizes_are_pinned() {
    assert_eq!(size_of::<MsgHeaderV1>(), 64);
    assert_eq!(size_of::<GridV1>(), 40);
    assert_eq!(size_of::<ParticleSnapshotHeaderV1>(), 112);
    assert_eq!(size_of::<ParticleV1>(), 32);
    assert_eq!(size_of::<RfFrameHeaderV3>(), 1184);
    assert_eq!(size_of::<Complex32>(), 8);
    assert_eq!(size_of::<IqFrameHeaderV3>(), 200);
    assert_eq!(size_of::<DopplerMapHeaderV2>(), 224);
    assert_eq!(size_of::<VectorFieldHeaderV2>(), 200);
    assert_eq!(size_of::<StageStatsHeaderV1>(), 128);
    assert_eq!(size_of::<FlowStatsHeaderV1>(), 160);
    assert_eq!(size_of::<BoundaryFluxV1>(), 32);
    for k in MessageType::ALL {
        // CDR needs every header to be a multiple of 8 so the u32 count is 4-aligned and
        // the payload starts on its natural alignment.
        assert_eq!(k.header_size() % 8, 0, "{k}");
    }
    assert!(align_of::<RfFrameHeaderV3>() <= 8);
}

#[test]
fn offsets_are_pinned() {
    assert_eq!(offset_of!(MsgHeaderV1, seq), 0);
    assert_eq!(offset_of!(MsgHeaderV1, frame_id), 8);
    assert_eq!(offset_of!(MsgHeaderV1, t_valid), 16);
    assert_eq!(offset_of!(MsgHeaderV1, t_pub_ns), 24);
    assert_eq!(offset_of!(MsgHeaderV1, compute_ns), 32);
    assert_eq!(offset_of!(MsgHeaderV1, incarnation), 40);
    assert_eq!(offset_of!(MsgHeaderV1, flags), 44);
    assert_eq!(offset_of!(MsgHeaderV1, source_id), 48);
    assert_eq!(offset_of!(MsgHeaderV1, schema_minor), 52);
    assert_eq!(offset_of!(RfFrameHeaderV3, fs), 64);
    assert_eq!(offset_of!(RfFrameHeaderV3, t0), 72);
    assert_eq!(offset_of!(RfFrameHeaderV3, fc), 80);
    assert_eq!(offset_of!(RfFrameHeaderV3, element_width), 120);
    assert_eq!(offset_of!(RfFrameHeaderV3, radius), 128);
    assert_eq!(offset_of!(RfFrameHeaderV3, n_channels), 136);
    assert_eq!(offset_of!(RfFrameHeaderV3, n_samples), 140);
    assert_eq!(offset_of!(RfFrameHeaderV3, tx_delays), 160);
    assert_eq!(offset_of!(ParticleSnapshotHeaderV1, n_particles), 64);
    assert_eq!(offset_of!(ParticleSnapshotHeaderV1, packet), 96);
    assert_eq!(offset_of!(ParticleSnapshotHeaderV1, packet_size), 104);
    assert_eq!(offset_of!(ParticleV1, x), 8);
    assert_eq!(offset_of!(ParticleV1, amplitude), 24);
    assert_eq!(offset_of!(IqFrameHeaderV3, grid), 64);
    assert_eq!(offset_of!(IqFrameHeaderV3, rx_angle), 128);
    assert_eq!(offset_of!(IqFrameHeaderV3, pitch), 144);
    assert_eq!(offset_of!(IqFrameHeaderV3, radius), 168);
    assert_eq!(offset_of!(IqFrameHeaderV3, n_elements), 188);
    assert_eq!(offset_of!(DopplerMapHeaderV2, plane_ids), 192);
    assert_eq!(offset_of!(VectorFieldHeaderV2, plane_ids), 168);
    assert_eq!(offset_of!(StageStatsHeaderV1, messages_in), 72);
    assert_eq!(offset_of!(FlowStatsHeaderV1, dt), 64);
    assert_eq!(offset_of!(FlowStatsHeaderV1, guard_corrections), 120);
    assert_eq!(offset_of!(FlowStatsHeaderV1, n_fluid), 136);
    assert_eq!(offset_of!(FlowStatsHeaderV1, n_boundaries), 152);
}

/// The generated ROS 2 schema lists the fields in struct order with the right types; the sum
/// of the primitive sizes equals the struct size (so CDR = the raw bytes, see `cdr`).
#[test]
fn ros_schema_matches_struct() {
    let text = MessageType::RfFrameV3.schema_text();
    assert!(text.starts_with("sonoflow_msgs/RfFrameHeaderV3 header\nfloat32[] data\n"), "{text}");
    assert!(text.contains("MSG: sonoflow_msgs/MsgHeaderV1\nuint64 seq\nuint64 frame_id\nfloat64 t_valid\n"));
    assert!(text.contains("float32[256] tx_delays\n"));
    fn prim_size(t: &str) -> usize {
        match t {
            "uint8" => 1,
            "uint16" => 2,
            "uint32" | "int32" | "float32" => 4,
            "uint64" | "int64" | "float64" => 8,
            _ => 0,
        }
    }
    // Size of every nested message computed from its schema text alone.
    for kind in MessageType::ALL {
        let text = kind.schema_text();
        let mut sizes = std::collections::HashMap::<String, usize>::new();
        let sections: Vec<&str> = text.split(&"=".repeat(80)).collect();
        // Dependencies are listed before their users, so one pass resolves them.
        for sec in sections.iter().skip(1) {
            let mut lines = sec.trim().lines();
            let name = lines.next().unwrap().trim_start_matches("MSG: ").to_string();
            let mut size = 0;
            for l in lines {
                let (ty, _) = l.split_once(' ').unwrap();
                let (base, count) = match ty.split_once('[') {
                    Some((b, n)) => (b, n.trim_end_matches(']').parse::<usize>().unwrap()),
                    None => (ty, 1),
                };
                let s = match prim_size(base) {
                    0 => sizes[base],
                    s => s,
                };
                size += s * count;
            }
            sizes.insert(name, size);
        }
        let header_type = text.lines().next().unwrap().split(' ').next().unwrap();
        assert_eq!(sizes[header_type], kind.header_size(), "{kind}");
    }
}

#[test]
fn cdr_round_trip_and_errors() {
    let mut h = RfFrameHeaderV3::default();
    h.common.seq = 7;
    h.common.t_valid = 0.125;
    h.n_channels = 3;
    h.n_samples = 5;
    h.fs = 20e6;
    h.tx_delays[2] = 1.5e-6;
    let payload: Vec<f32> = (0..15).map(|i| i as f32 * 0.5 - 3.0).collect();
    let mut buf = Vec::new();
    cdr::encode_into::<RfFrame>(&h, &payload, &mut buf);
    assert_eq!(buf.len(), cdr::encoded_len::<RfFrame>(15));
    assert_eq!(&buf[..4], &[0, 1, 0, 0]);
    assert_eq!(u32::from_le_bytes(buf[4 + 1184..8 + 1184].try_into().unwrap()), 15);
    let (h2, p2) = cdr::decode::<RfFrame>(&buf).unwrap();
    assert_eq!(h2, h);
    assert_eq!(p2, payload);
    // Truncated record, wrong count, wrong dimensions.
    assert!(matches!(cdr::decode::<RfFrame>(&buf[..100]), Err(cdr::DecodeError::TooShort { .. })));
    assert!(matches!(cdr::decode::<RfFrame>(&buf[..buf.len() - 4]), Err(cdr::DecodeError::Length { .. })));
    let mut bad = Vec::new();
    cdr::encode_into::<RfFrame>(&h, &payload[..14], &mut bad);
    assert!(matches!(cdr::decode::<RfFrame>(&bad), Err(cdr::DecodeError::Dimensions { .. })));
    bad[1] = 0;
    assert!(matches!(cdr::split(MessageType::RfFrameV3, &bad), Err(cdr::DecodeError::Encapsulation { .. })));
}

#[test]
fn viz_pictures_have_the_grid_geometry() {
    use foxglove::Decode;
    let mut h = VectorFieldHeaderV2::default();
    h.grid = GridV1 { x0: -0.01, z0: 0.005, dx: 1e-3, dz: 2e-3, nx: 3, nz: 2 };
    h.n_planes = 2;
    h.plane_ids[0] = plane::VX;
    h.plane_ids[1] = plane::VZ;
    let payload: Vec<f32> = (0..12).map(|i| i as f32).collect();
    let v = viz::viz(MessageType::VectorFieldV2, bytemuck::bytes_of(&h), bytemuck::cast_slice(&payload)).unwrap();
    assert_eq!(v.schema_name, "foxglove.Grid");
    let g = foxglove::schemas::Grid::decode(&v.data[..]).unwrap();
    assert_eq!(g.column_count, 3);
    assert_eq!(g.fields[1].name, "vz");
    // First stored row is the deepest depth row (iz = 1): vx of (ix=0, iz=1) = plane0[3] = 3.
    let first = f32::from_le_bytes(g.data[0..4].try_into().unwrap());
    assert_eq!(first, 3.0);
    // vz of that cell = plane1[3] = 6 + 3 = 9.
    assert_eq!(f32::from_le_bytes(g.data[4..8].try_into().unwrap()), 9.0);
}
