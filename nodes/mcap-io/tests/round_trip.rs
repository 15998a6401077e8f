//! Write → read round trips, ordering, filters, chunking and options.

use std::{collections::BTreeMap, fs, time::Duration};

use sonoflow_mcap_io::testkit::{payload, read_all, simple_spec, writer_with_channel, Expected};
use sonoflow_mcap_io::{ChannelSpec, Compression, McapReader, OutMessage, ReadOptions, RecorderWriter, WriterOptions};

const RF_LEN: usize = 4 * 1024 * 1024;
const ROUNDS: u64 = 6;

fn round_trip(compression: Compression) {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join(format!("rt-{compression}.mcap"));
    let opts = WriterOptions { compression, ..WriterOptions::default() };
    let mut w = RecorderWriter::create(&path, opts).expect("create");
    let rf = w
        .add_channel(ChannelSpec {
            topic: "/rf".into(),
            message_encoding: "raw-f32le".into(),
            schema_name: "sonoflow.RfFrame".into(),
            schema_encoding: "raw".into(),
            schema_data: b"f32 samples[1048576]".to_vec(),
            metadata: BTreeMap::from([("fs_hz".to_string(), "40000000".to_string())]),
        })
        .expect("rf channel");
    let status = w.add_channel(simple_spec("/status")).expect("status");
    let mut pose_spec = simple_spec("/pose");
    pose_spec.metadata.insert("frame".to_string(), "probe".to_string());
    let pose = w.add_channel(pose_spec.clone()).expect("pose");
    // Same spec again: same id, no new channel.
    assert_eq!(w.add_channel(pose_spec).expect("pose again"), pose);
    assert_ne!(rf, status);
    assert_ne!(status, pose);

    let mut expected = Vec::new();
    let mut push = |w: &RecorderWriter, ch, topic: &str, seq: u32, t: u64, data: Vec<u8>| {
        expected.push(Expected {
            topic: topic.to_string(),
            sequence: seq,
            log_time: t,
            publish_time: t + 5,
            data: data.clone(),
        });
        w.write(OutMessage { channel: ch, sequence: seq, log_time: t, publish_time: t + 5, data }).expect("write");
    };
    for round in 0..ROUNDS {
        let t = round * 1_000_000;
        let seq = round as u32;
        push(&w, rf, "/rf", seq, t, payload(round, RF_LEN));
        // Same log time as the rf message: must come back after it (file order).
        push(&w, status, "/status", seq, t, payload(100 + round, 100));
        push(&w, pose, "/pose", seq, t + 10, payload(200 + round, 48));
    }
    let config = b"[run]\nseed = 42\n".to_vec();
    w.attach("config.toml", "application/toml", config.clone()).expect("attach");
    let run_meta = BTreeMap::from([("seed".to_string(), "42".to_string()), ("git".to_string(), "abc123".to_string())]);
    w.metadata("run", run_meta.clone()).expect("metadata");

    let stats = w.finish().expect("finish");
    assert_eq!(stats.messages_written.get("/rf"), Some(&ROUNDS));
    assert_eq!(stats.messages_written.get("/status"), Some(&ROUNDS));
    assert_eq!(stats.messages_written.get("/pose"), Some(&ROUNDS));
    let payload_bytes: u64 = expected.iter().map(|e| e.data.len() as u64).sum();
    assert_eq!(stats.bytes_written, payload_bytes);
    assert_eq!(stats.bytes_queued, 0);
    let file_len = fs::metadata(&path).expect("stat").len();
    assert_eq!(stats.file_bytes, file_len);

    let (reader, got) = read_all(&path);
    assert!(reader.is_complete());
    assert_eq!(reader.profile(), "sonoflow");
    assert_eq!(got.len(), expected.len());
    for (i, (g, e)) in got.iter().zip(&expected).enumerate() {
        assert!(e.matches(g), "{compression}: message {i} differs ({} {})", g.topic, g.sequence);
    }
    let rf_msg = got.iter().find(|m| m.topic == "/rf").expect("rf message");
    assert_eq!(rf_msg.schema_name, "sonoflow.RfFrame");
    assert_eq!(rf_msg.message_encoding, "raw-f32le");
    assert_eq!(rf_msg.channel_metadata["fs_hz"], "40000000");
    let pose_msg = got.iter().find(|m| m.topic == "/pose").expect("pose message");
    assert_eq!(pose_msg.channel_metadata["frame"], "probe");

    let topics = reader.topics();
    assert_eq!(topics.len(), 3);
    for t in &topics {
        assert_eq!(t.message_count, Some(ROUNDS), "{t:?}");
    }
    assert_eq!(topics[0].topic, "/rf");
    assert_eq!(topics[1].schema_name, "bytes");
    assert_eq!(reader.metadata(), vec![("run".to_string(), run_meta)]);
    assert_eq!(reader.attachments(), vec![("config.toml".to_string(), "application/toml".to_string(), config)]);

    // Filters.
    let only_status: Vec<_> = reader
        .messages(&ReadOptions { topics: Some(vec!["/status".into()]), ..Default::default() })
        .expect("filtered")
        .collect::<Result<_, _>>()
        .expect("read");
    assert_eq!(only_status.len(), ROUNDS as usize);
    assert!(only_status.iter().all(|m| m.topic == "/status"));
    let window: Vec<_> = reader
        .messages(&ReadOptions { topics: None, start_time: Some(2_000_000), end_time: Some(4_000_000) })
        .expect("window")
        .collect::<Result<_, _>>()
        .expect("read");
    assert_eq!(window.len(), 6);
    assert!(window.iter().all(|m| (2_000_000..4_000_000).contains(&m.log_time)));
    let none = reader
        .messages(&ReadOptions { topics: Some(vec!["/does-not-exist".into()]), ..Default::default() })
        .expect("no topic")
        .count();
    assert_eq!(none, 0);

    // Cross-check with the mcap crate's own strict readers.
    let bytes = fs::read(&path).expect("read file");
    let summary = mcap::Summary::read(&bytes).expect("summary").expect("has summary");
    assert_eq!(summary.schemas.len(), 2, "/status and /pose share a schema");
    assert_eq!(summary.channels.len(), 3);
    let want = match compression {
        Compression::None => "",
        Compression::Zstd => "zstd",
        Compression::Lz4 => "lz4",
    };
    assert!(summary.chunk_indexes.len() >= ROUNDS as usize);
    assert!(summary.chunk_indexes.iter().all(|c| c.compression == want));
    let strict = mcap::MessageStream::new(&bytes).expect("stream").collect::<Result<Vec<_>, _>>().expect("strict read");
    assert_eq!(strict.len(), expected.len());
}

#[test]
fn round_trip_zstd() {
    round_trip(Compression::Zstd);
}

#[test]
fn round_trip_lz4() {
    round_trip(Compression::Lz4);
}

#[test]
fn round_trip_uncompressed() {
    round_trip(Compression::None);
}

#[test]
fn out_of_order_log_times_come_back_sorted_with_ties_in_file_order() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("order.mcap");
    let opts = WriterOptions {
        chunk_size: 4096, // many chunks with overlapping time ranges
        ..WriterOptions::default()
    };
    let (mut w, a) = writer_with_channel(&path, opts, "/a");
    let b = w.add_channel(simple_spec("/b")).expect("b");
    // log time = pseudo-random in 0..50 (lots of ties); sequence = write index.
    let n = 400u32;
    let mut written = Vec::new();
    for i in 0..n {
        let t = u64::from(payload(u64::from(i), 1)[0] % 50);
        let ch = if i % 3 == 0 { a } else { b };
        w.write(OutMessage {
            channel: ch,
            sequence: i,
            log_time: t,
            publish_time: 0,
            data: payload(u64::from(i), 200),
        })
        .expect("write");
        written.push((t, i));
    }
    w.finish().expect("finish");
    let mut expected = written.clone();
    expected.sort(); // (log_time, write index): ties in file order
    let (r, got) = read_all(&path);
    assert!(r.is_complete());
    let got: Vec<(u64, u32)> = got.iter().map(|m| (m.log_time, m.sequence)).collect();
    assert_eq!(got, expected);
}

#[test]
fn message_larger_than_chunk_size_gets_its_own_chunk() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("big.mcap");
    let opts = WriterOptions {
        chunk_size: 1024 * 1024,
        flush_interval: Duration::from_secs(3600),
        ..WriterOptions::default()
    };
    let (w, ch) = writer_with_channel(&path, opts, "/x");
    for (t, len) in [(1u64, 1024usize), (2, 3 * 1024 * 1024), (3, 1024), (4, 1024)] {
        w.write(OutMessage { channel: ch, sequence: t as u32, log_time: t, publish_time: t, data: payload(t, len) })
            .expect("write");
    }
    w.finish().expect("finish");
    let bytes = fs::read(&path).expect("read");
    let summary = mcap::Summary::read(&bytes).expect("summary").expect("some");
    let ranges: Vec<(u64, u64)> =
        summary.chunk_indexes.iter().map(|c| (c.message_start_time, c.message_end_time)).collect();
    assert_eq!(ranges, vec![(1, 1), (2, 2), (3, 4)]);
    let big = &summary.chunk_indexes[1];
    assert!(big.uncompressed_size > 3 * 1024 * 1024);
    assert!(summary.chunk_indexes[2].uncompressed_size < 1024 * 1024);
    assert_eq!(read_all(&path).1.len(), 4);
}

#[test]
fn several_producer_threads_share_one_writer() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("mt.mcap");
    let opts = WriterOptions { queue_bytes: 256 * 1024, chunk_size: 64 * 1024, ..WriterOptions::default() };
    let mut w = RecorderWriter::create(&path, opts).expect("create");
    let channels: Vec<_> = (0..4).map(|i| w.add_channel(simple_spec(&format!("/t{i}"))).expect("channel")).collect();
    std::thread::scope(|s| {
        for (i, ch) in channels.iter().enumerate() {
            let w = &w;
            let ch = *ch;
            s.spawn(move || {
                for seq in 0..500u32 {
                    w.write(OutMessage {
                        channel: ch,
                        sequence: seq,
                        log_time: u64::from(seq),
                        publish_time: 0,
                        data: payload((i as u64) << 32 | u64::from(seq), 3000),
                    })
                    .expect("write");
                }
            });
        }
    });
    let stats = w.finish().expect("finish");
    for i in 0..4 {
        assert_eq!(stats.messages_written[&format!("/t{i}")], 500);
    }
    let (_, got) = read_all(&path);
    assert_eq!(got.len(), 2000);
    for i in 0..4u64 {
        let topic = format!("/t{i}");
        let seqs: Vec<u32> = got.iter().filter(|m| m.topic == topic).map(|m| m.sequence).collect();
        assert_eq!(seqs, (0..500).collect::<Vec<_>>(), "{topic}");
        for m in got.iter().filter(|m| m.topic == topic) {
            assert_eq!(m.data, payload(i << 32 | u64::from(m.sequence), 3000));
        }
    }
}

#[test]
fn dropping_the_writer_finishes_the_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("drop.mcap");
    {
        let (w, ch) = writer_with_channel(&path, WriterOptions::default(), "/d");
        sonoflow_mcap_io::testkit::write_n(&w, ch, "/d", 10, 100);
    }
    let (r, got) = read_all(&path);
    assert!(r.is_complete());
    assert_eq!(got.len(), 10);
}

#[test]
fn channel_without_schema() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("noschema.mcap");
    let mut w = RecorderWriter::create(&path, WriterOptions::default()).expect("create");
    let ch = w
        .add_channel(ChannelSpec { topic: "/log".into(), message_encoding: "text".into(), ..Default::default() })
        .expect("channel");
    let expected = sonoflow_mcap_io::testkit::write_n(&w, ch, "/log", 3, 10);
    w.finish().expect("finish");
    let (r, got) = read_all(&path);
    assert_eq!(sonoflow_mcap_io::testkit::assert_prefix(&got, &expected), 3);
    assert_eq!(got[0].schema_name, "");
    assert_eq!(r.topics()[0].schema_name, "");
    let bytes = fs::read(&path).expect("read");
    let summary = mcap::Summary::read(&bytes).expect("summary").expect("some");
    assert!(summary.schemas.is_empty());
}

#[test]
fn compression_names_and_option_defaults() {
    for (c, s) in [(Compression::None, "none"), (Compression::Zstd, "zstd"), (Compression::Lz4, "lz4")] {
        assert_eq!(c.to_string(), s);
        assert_eq!(s.parse::<Compression>().expect("parse"), c);
        assert_eq!(serde_json::to_string(&c).expect("ser"), format!("\"{s}\""));
        assert_eq!(serde_json::from_str::<Compression>(&format!("\"{s}\"")).expect("de"), c);
    }
    assert!("gzip".parse::<Compression>().is_err());
    assert!(serde_json::from_str::<Compression>("\"Zstd\"").is_err());
    let d = WriterOptions::default();
    assert_eq!(d.compression, Compression::Zstd);
    assert_eq!(d.compression_level, 1);
    assert_eq!(d.chunk_size, 4 * 1024 * 1024);
    assert_eq!(d.flush_interval, Duration::from_secs(1));
    assert_eq!(d.queue_bytes, 256 * 1024 * 1024);
    assert_eq!(d.profile, "sonoflow");
}

#[test]
fn reading_a_file_with_messages_outside_chunks() {
    // Files from other writers may not use chunks; linear mode serves them too.
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("unchunked.mcap");
    let file = fs::File::create(&path).expect("create");
    let mut w = mcap::WriteOptions::new()
        .use_chunks(false)
        .emit_summary_records(false)
        .create(std::io::BufWriter::new(file))
        .expect("writer");
    let ch = w.add_channel(0, "/u", "raw", &BTreeMap::new()).expect("channel");
    for (i, t) in [5u64, 3, 9, 3, 1].into_iter().enumerate() {
        w.write_to_known_channel(
            &mcap::records::MessageHeader { channel_id: ch, sequence: i as u32, log_time: t, publish_time: t },
            &payload(i as u64, 10),
        )
        .expect("write");
    }
    w.finish().expect("finish");
    drop(w);
    let r = McapReader::open(&path).expect("open");
    assert!(!r.is_complete());
    let got: Vec<(u64, u32)> = r
        .messages(&ReadOptions::default())
        .expect("messages")
        .map(|m| m.map(|m| (m.log_time, m.sequence)))
        .collect::<Result<_, _>>()
        .expect("read");
    assert_eq!(got, vec![(1, 4), (3, 1), (3, 3), (5, 0), (9, 2)]);
    assert_eq!(r.topics()[0].message_count, Some(5));
}
