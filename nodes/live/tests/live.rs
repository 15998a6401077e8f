//! The live view against a real WebSocket client speaking Foxglove's protocol
//! (`sonoflow_live::testkit::Viewer`): every picture topic arrives and decodes as its Foxglove
//! schema, a late viewer still sees every topic, and a viewer that never reads cannot hold up
//! the sender.

use foxglove::Decode;
use sonoflow_live::testkit::{Received, Viewer};
use sonoflow_live::{LiveOptions, LiveView};
use sonoflow_messages::wire::*;
use sonoflow_messages::MessageType;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

const TOPICS: [(&str, MessageType); 4] = [
    ("particles", MessageType::ParticleSnapshotV1),
    ("iq", MessageType::IqFrameV3),
    ("maps", MessageType::DopplerMapV2),
    ("vector", MessageType::VectorFieldV2),
];

fn options() -> LiveOptions {
    LiveOptions { port: 0, ..LiveOptions::default() }
}

fn topics() -> Vec<(String, MessageType)> {
    TOPICS.iter().map(|(t, k)| (t.to_string(), *k)).collect()
}

fn grid(nx: u32, nz: u32) -> GridV1 {
    GridV1 { x0: -0.01, z0: 0.01, dx: 2.5e-4, dz: 2.5e-4, nx, nz }
}

/// A snapshot of `n` particles at x = i µm.
fn particles(n: usize) -> (Vec<u8>, Vec<u8>) {
    let h = ParticleSnapshotHeaderV1 { n_particles: n as u32, ..Default::default() };
    let p: Vec<ParticleV1> = (0..n)
        .map(|i| ParticleV1 { id: i as u32, x: i as f32 * 1e-6, z: 0.02, amplitude: 1.0, ..Default::default() })
        .collect();
    (bytemuck::bytes_of(&h).to_vec(), bytemuck::cast_slice(&p).to_vec())
}

/// One message of each picture topic, in `TOPICS` order.
fn one_of_each() -> Vec<(Vec<u8>, Vec<u8>)> {
    let iq = IqFrameHeaderV3 { grid: grid(7, 5), ..Default::default() };
    let iq_payload: Vec<f32> = (0..70).map(|i| (i % 7) as f32 + 0.5).collect();
    let mut maps = DopplerMapHeaderV2 { grid: grid(6, 4), n_planes: 2, ..Default::default() };
    maps.plane_ids[0] = plane::VELOCITY;
    maps.plane_ids[1] = plane::POWER;
    let mut vec = VectorFieldHeaderV2 { grid: grid(5, 3), n_planes: 2, ..Default::default() };
    vec.plane_ids[0] = plane::VX;
    vec.plane_ids[1] = plane::VZ;
    let f = |n: usize| -> Vec<u8> { bytemuck::cast_slice(&(0..n).map(|i| i as f32).collect::<Vec<f32>>()).to_vec() };
    vec![
        particles(9),
        (bytemuck::bytes_of(&iq).to_vec(), bytemuck::cast_slice(&iq_payload).to_vec()),
        (bytemuck::bytes_of(&maps).to_vec(), f(6 * 4 * 2)),
        (bytemuck::bytes_of(&vec).to_vec(), f(5 * 3 * 2)),
    ]
}

/// Reads until one message of every topic has arrived (or the deadline).
fn collect_each(v: &mut Viewer, deadline: Duration) -> BTreeMap<String, Received> {
    let t0 = Instant::now();
    let mut got = BTreeMap::new();
    while got.len() < TOPICS.len() && t0.elapsed() < deadline {
        if let Some(m) = v.read(Duration::from_millis(100)).expect("viewer read") {
            got.entry(m.topic.clone()).or_insert(m);
        }
    }
    got
}

/// Each picture decodes as its Foxglove schema with the geometry of the message it came from.
fn check_pictures(got: &BTreeMap<String, Received>) {
    let names: Vec<&str> = got.keys().map(String::as_str).collect();
    assert_eq!(names, ["viz/iq", "viz/maps", "viz/particles", "viz/vector"]);
    let pc = foxglove::schemas::PointCloud::decode(&got["viz/particles"].data[..]).expect("PointCloud");
    assert_eq!(got["viz/particles"].schema_name, "foxglove.PointCloud");
    assert_eq!(pc.data.len(), 9 * pc.point_stride as usize);
    // x of the third point = 2 µm.
    let x2 = f32::from_le_bytes(pc.data[40..44].try_into().expect("4 bytes"));
    assert!((x2 - 2e-6).abs() < 1e-12, "x of point 2: {x2}");
    let img = foxglove::schemas::RawImage::decode(&got["viz/iq"].data[..]).expect("RawImage");
    assert_eq!((img.width, img.height, img.encoding.as_str()), (7, 5, "mono8"));
    // Brightest column (re = im = 6.5) at full scale.
    assert_eq!(img.data[6], 255);
    let g = foxglove::schemas::Grid::decode(&got["viz/maps"].data[..]).expect("Grid");
    assert_eq!((g.column_count, g.fields.len()), (6, 2));
    let g = foxglove::schemas::Grid::decode(&got["viz/vector"].data[..]).expect("Grid");
    assert_eq!((g.column_count, g.fields[1].name.as_str()), (5, "vz"));
}

#[test]
fn every_picture_topic_reaches_a_subscribed_viewer_and_decodes() {
    let live = LiveView::start(&options(), &topics()).expect("start");
    let mut v = Viewer::connect(live.url(), None).expect("connect");
    let adv = v.subscribe_all(TOPICS.len(), Duration::from_secs(10)).expect("subscribe");
    assert!(adv.iter().all(|a| a.encoding == "protobuf"), "{adv:?}");
    // Subscriptions are processed by the server asynchronously: offer until everything came.
    let msgs = one_of_each();
    let t0 = Instant::now();
    let mut got = BTreeMap::new();
    while got.len() < TOPICS.len() && t0.elapsed() < Duration::from_secs(20) {
        for (i, (h, p)) in msgs.iter().enumerate() {
            live.offer(i, h, p);
        }
        for (k, m) in collect_each(&mut v, Duration::from_millis(300)) {
            got.entry(k).or_insert(m);
        }
    }
    check_pictures(&got);
    v.close();
    let counts = live.finish(Duration::ZERO);
    assert!(counts.iter().all(|c| c.offered >= 1 && c.shown >= 1), "{counts:?}");
}

#[test]
fn a_viewer_that_comes_late_gets_the_newest_picture_of_every_topic() {
    let live = LiveView::start(&options(), &topics()).expect("start");
    for (i, (h, p)) in one_of_each().iter().enumerate() {
        live.offer(i, h, p);
    }
    // Wait until the pictures are made (nobody is connected yet).
    let t0 = Instant::now();
    while live.counts().iter().any(|c| c.shown == 0) && t0.elapsed() < Duration::from_secs(10) {
        std::thread::sleep(Duration::from_millis(10));
    }
    let mut v = Viewer::connect(live.url(), None).expect("connect");
    v.subscribe_all(TOPICS.len(), Duration::from_secs(10)).expect("subscribe");
    check_pictures(&collect_each(&mut v, Duration::from_secs(10)));
    v.close();
    drop(live);
}

#[test]
fn a_viewer_that_never_reads_does_not_hold_up_the_pictures_or_other_viewers() {
    // 400 pictures of 20 000+ points (400 kB each, 160 MB in all) to a viewer with a 4 kB
    // receive buffer that never reads: far more than any socket buffer and the server's backlog
    // of 8 can hold, so the sender must drop for it rather than wait.
    let opts = LiveOptions { backlog: 8, max_rate_hz: 1000.0, ..options() };
    let live = LiveView::start(&opts, &topics()).expect("start");
    let mut stuck = Viewer::connect(live.url(), Some(4096)).expect("connect");
    stuck.subscribe_all(TOPICS.len(), Duration::from_secs(10)).expect("subscribe");
    let mut reader = Viewer::connect(live.url(), None).expect("connect");
    reader.subscribe_all(TOPICS.len(), Duration::from_secs(10)).expect("subscribe");
    std::thread::sleep(Duration::from_millis(300)); // let the server register both subscriptions
    let n = 400usize;
    let mut largest_seen = 0usize;
    for i in 0..n {
        let (h, p) = particles(20_000 + i);
        live.offer(0, &h, &p);
        // Each picture is made before the next message (nothing skipped): the picture thread
        // would stop here if logging to the stuck viewer blocked.
        let t0 = Instant::now();
        while live.counts()[0].shown < (i + 1) as u64 {
            assert!(
                t0.elapsed() < Duration::from_secs(20),
                "picture {i} not made within 20 s: the viewer that never reads holds up the sender"
            );
            std::thread::sleep(Duration::from_micros(200));
        }
        // The reading viewer keeps up (it reads what has arrived).
        while let Some(m) = reader.read(Duration::from_millis(1)).expect("read") {
            if let Ok(pc) = foxglove::schemas::PointCloud::decode(&m.data[..]) {
                largest_seen = largest_seen.max(pc.data.len() / pc.point_stride as usize);
            }
        }
    }
    let t0 = Instant::now();
    while largest_seen < 20_000 + n - 1 && t0.elapsed() < Duration::from_secs(20) {
        if let Some(m) = reader.read(Duration::from_millis(100)).expect("read") {
            if let Ok(pc) = foxglove::schemas::PointCloud::decode(&m.data[..]) {
                largest_seen = largest_seen.max(pc.data.len() / pc.point_stride as usize);
            }
        }
    }
    assert_eq!(largest_seen, 20_000 + n - 1, "the reading viewer did not get the last picture");
    let counts = live.finish(Duration::ZERO);
    assert_eq!((counts[0].offered, counts[0].shown, counts[0].skipped), (n as u64, n as u64, 0));
    drop(stuck);
}
