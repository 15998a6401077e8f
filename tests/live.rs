//! `sonoflow run --live`: a real WebSocket client speaking Foxglove's protocol
//! (`sonoflow_live::testkit::Viewer`) watches whole graphs. The quickstart's every picture topic
//! arrives and decodes with the geometry of the scene; a viewer that subscribes and then never
//! reads neither stalls the graph nor costs the recording a message.
#![allow(clippy::unwrap_used)]

mod common;

use common::*;
use foxglove::Decode;
use sonoflow_live::testkit::{Received, Viewer};
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

/// The viewer URL from the live node's start line.
fn live_url(l: &mut Launcher) -> String {
    let line = l.wait_line("live view: ws://");
    let url = line.split_whitespace().find(|w| w.starts_with("ws://")).unwrap().to_string();
    url
}

#[test]
fn quickstart_live_view_shows_every_picture_topic() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let out_s = out.to_string_lossy().to_string();
    let mut l = Launcher::start(
        "launch/quickstart.toml",
        &out,
        &[
            "--live",
            ":0",
            "--set",
            "flow.schedule.n_packets=1",
            "--set",
            "live.wait_for_viewer_s=10",
            "--set",
            "live.linger_s=60",
        ],
    );
    let url = live_url(&mut l);
    let mut v = Viewer::connect(&url, None).unwrap();
    // The quickstart's picture topics: particles, truth, iq, vector, maps, regularised (rf has none).
    let adv = v.subscribe_all(6, Duration::from_secs(30)).unwrap();
    let topics: Vec<&str> =
        adv.iter().map(|a| a.topic.as_str()).collect::<std::collections::BTreeSet<_>>().into_iter().collect();
    assert_eq!(topics, ["viz/iq", "viz/maps", "viz/particles", "viz/regularised", "viz/truth", "viz/vector"]);
    let mut got: BTreeMap<String, Received> = BTreeMap::new();
    let t0 = Instant::now();
    while got.len() < 6 && t0.elapsed() < Duration::from_secs(120) {
        if let Some(m) = v.read(Duration::from_millis(200)).unwrap() {
            got.entry(m.topic.clone()).or_insert(m);
        }
    }
    assert_eq!(got.len(), 6, "pictures received: {:?}", got.keys().collect::<Vec<_>>());
    // Each decodes as its Foxglove schema with the scene's geometry (81 × 81 grids, 0.25 mm).
    let pc = foxglove::schemas::PointCloud::decode(&got["viz/particles"].data[..]).unwrap();
    let n_points = pc.data.len() / pc.point_stride as usize;
    assert!(n_points > 1000, "{n_points} particles (10 per mm² in a 6 mm × 30 mm vessel: ~1800)");
    let img = foxglove::schemas::RawImage::decode(&got["viz/iq"].data[..]).unwrap();
    assert_eq!((img.width, img.height, img.encoding.as_str()), (81, 81, "mono8"));
    assert!(img.data.contains(&255), "B-mode has its maximum at full scale");
    for t in ["viz/truth", "viz/vector", "viz/regularised", "viz/maps"] {
        assert_eq!(got[t].schema_name, "foxglove.Grid", "{t}");
        let g = foxglove::schemas::Grid::decode(&got[t].data[..]).unwrap();
        assert_eq!(g.column_count, 81, "{t}");
        assert!((g.cell_size.unwrap().x - 0.25e-3).abs() < 1e-12, "{t}");
    }
    let g = foxglove::schemas::Grid::decode(&got["viz/vector"].data[..]).unwrap();
    let names: Vec<&str> = g.fields.iter().map(|f| f.name.as_str()).collect();
    assert!(names.contains(&"vx") && names.contains(&"vz"), "{names:?}");
    // Leaving ends the linger: the run finishes cleanly with its recording.
    v.close();
    let (code, log) = l.finish();
    assert_eq!(code, 0, "{log}");
    assert!(log.contains("live view: "), "{log}");
    assert!(std::path::Path::new(&out_s).join("recording.mcap").is_file());
}

#[test]
fn a_viewer_that_never_reads_neither_stalls_the_graph_nor_costs_the_recording_a_message() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    // Every message gets its picture attempt (1000 Hz), the server queues 4 per viewer; the
    // viewer's receive buffer is 4 kB and it never reads: ~40 MB of pictures cannot reach it.
    let mut l = Launcher::start(
        "tests/launch/live-flood.toml",
        &out,
        &[
            "--live",
            "127.0.0.1:0",
            "--set",
            "live.wait_for_viewer_s=10",
            "--set",
            "live.max_rate_hz=1000",
            "--set",
            "live.backlog=4",
        ],
    );
    let url = live_url(&mut l);
    let stuck = Viewer::connect(&url, Some(4096));
    let mut stuck = stuck.unwrap();
    stuck.subscribe_all(2, Duration::from_secs(30)).unwrap();
    // The graph runs to its end while the viewer is still connected and has read nothing.
    let (code, log) = l.finish();
    assert_eq!(code, 0, "{log}");
    let shown = log.lines().find(|x| x.contains("live view: particles")).unwrap_or_else(|| panic!("{log}"));
    // "particles S/128 shown (K skipped)": every message was offered, none waited.
    let frac = shown.split("particles ").nth(1).unwrap().split(' ').next().unwrap();
    let (s, offered) = frac.split_once('/').unwrap();
    assert_eq!(offered, "128", "{shown}");
    // At least 32 pictures of ~16 000 points (20 B each: ≥ 10 MB) were logged for the viewer
    // that reads nothing: more than its 4 kB receive buffer, the server's send buffer (Linux
    // caps it at 4 MB by default) and the backlog of 4 can hold — so the server dropped for it
    // instead of waiting (the graph ends here ~100 pictures in on this 2-core machine).
    assert!(s.parse::<u32>().unwrap() >= 32, "{shown}");
    // The recording has every message (4 packets × 32 frames; one truth field per packet).
    let rec = out.join("recording.mcap");
    assert_eq!(read_topic(&rec, "particles").len(), 128);
    assert_eq!(read_topic(&rec, "truth").len(), 4);
    let r = sonoflow_mcap_io::McapReader::open(&rec).unwrap();
    assert!(r.is_complete());
    drop(stuck);
}
