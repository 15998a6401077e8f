//! `recorder` node: subscribes to topics of the graph and writes MCAP
//! (`sonoflow_mcap_io::TopicRecorder`: channels, CDR, pictures, counters).
//!
//! Lossless by construction: inputs are lossless iceoryx2 subscribers, the receive loop copies
//! each sample out of shared memory into the writer's bounded queue and blocks when the queue is
//! full (back-pressure up the graph), the writer thread closes a chunk at least every
//! `flush_interval_s` so a `kill -9` loses at most that much. Per-topic received / written /
//! sequence-gap counters and `complete = true|false` go into the file's `recording_stats`
//! metadata and are printed at the end.

use serde::{Deserialize, Serialize};
use sonoflow_mcap_io::{Compression, TopicCount, TopicRecorder, WriterOptions};
use sonoflow_messages::MessageType;
use sonoflow_node_kit::KindSpec;
use sonoflow_node_kit::{in_range, parse_params};
use sonoflow_node_kit::{select_loop, unix_ns, DynInput, Kit, SelectEnd, Step};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The `recorder` node kind.
pub const SPEC: KindSpec = KindSpec::new(
    "recorder",
    "records topics to MCAP (lossless, chunk-compressed, Foxglove pictures)",
    &[],
    validate,
    run,
)
.with_dynamic_ports(true, false)
.recording();

/// Recorder parameters.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct RecorderParams {
    /// Output file, relative to the run folder (`--out`).
    pub path: String,
    /// Topics to record; `"*"` = every topic of the graph.
    pub topics: Vec<String>,
    /// Chunk compression: `zstd`, `lz4` or `none`.
    pub compression: Compression,
    /// Compression level (zstd 1–19, lz4 0–12).
    pub compression_level: u32,
    /// Chunk size (MiB): about one large message.
    pub chunk_size_mb: f64,
    /// A chunk is written at least this often (s): bounds the loss on `kill -9`.
    pub flush_interval_s: f64,
    /// RAM queue between the receive loop and the writer thread (MiB).
    pub queue_mb: f64,
    /// Also write Foxglove pictures (`viz/<topic>`) of particles, maps and I/Q.
    pub viz: bool,
    /// Record per-message stage statistics (`_stats`).
    pub stats: bool,
    /// Resolved launch file to attach (set by the launcher).
    pub launch_file: Option<String>,
}

impl Default for RecorderParams {
    fn default() -> Self {
        Self {
            path: "recording.mcap".into(),
            topics: vec!["*".into()],
            compression: Compression::Zstd,
            compression_level: 1,
            chunk_size_mb: 4.0,
            flush_interval_s: 1.0,
            queue_mb: 512.0,
            viz: true,
            stats: true,
            launch_file: None,
        }
    }
}

impl RecorderParams {
    pub fn validate(&self) -> Result<(), String> {
        if self.path.is_empty() {
            return Err("path is empty".into());
        }
        match self.compression {
            Compression::Zstd => in_range("compression_level", self.compression_level, 1, 19)?,
            Compression::Lz4 => in_range("compression_level", self.compression_level, 0, 12)?,
            Compression::None => {}
        }
        in_range("chunk_size_mb", self.chunk_size_mb, 0.0625, 256.0)?;
        in_range("flush_interval_s", self.flush_interval_s, 0.01, 600.0)?;
        in_range("queue_mb", self.queue_mb, 16.0, 65536.0)?;
        Ok(())
    }
}

pub fn validate(v: &serde_json::Value) -> Result<(), String> {
    parse_params::<RecorderParams>(v)?.validate()
}

/// A recorded input and its counters.
struct Recorded {
    input: Box<dyn DynInput>,
    index: usize,
    is_stats: bool,
    count: TopicCount,
}

pub fn run(mut kit: Kit) -> anyhow::Result<()> {
    let p: RecorderParams = parse_params(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    p.validate().map_err(anyhow::Error::msg)?;
    let path = PathBuf::from(kit.cfg.out_dir.clone().unwrap_or_else(|| ".".into())).join(&p.path);
    let (mut file, mut rec, stats_publishers) = open(&mut kit, &p, &path)?;
    {
        let mut hs: Vec<&mut dyn sonoflow_node_kit::Handshake> =
            rec.iter_mut().map(|r| r.input.as_mut() as &mut dyn sonoflow_node_kit::Handshake).collect();
        kit.handshake(&mut hs)?;
    }
    println!("recorder: recording {} topic(s) to {}", rec.len(), path.display());
    let wakeups: Vec<_> = rec.iter().map(|r| r.input.wakeup()).collect();
    let mut stats_eos = 0usize;
    let end = select_loop(&mut kit, &wakeups, Duration::from_millis(500), |_| {
        while drain_once(&mut rec, &mut file, &mut stats_eos)? {}
        let data_done = rec.iter().filter(|r| !r.is_stats).all(|r| r.input.counters().2);
        Ok(if data_done && stats_eos >= stats_publishers { Step::Done } else { Step::Continue })
    })?;
    for r in rec.iter_mut() {
        let (received, gaps, eos) = r.input.counters();
        r.count = TopicCount {
            received,
            gaps,
            end_of_stream: eos || (r.is_stats && stats_eos >= stats_publishers),
            ..r.count
        };
    }
    let counts: Vec<TopicCount> = rec.iter().map(|r| r.count.clone()).collect();
    let s = file.finish(&counts, end == SelectEnd::Terminated)?;
    println!(
        "recorder: {} — {} MB written, complete = {}, dropped = 0; topics written/received: {}",
        path.display(),
        s.stats.file_bytes as f64 / 1e6,
        s.complete,
        s.topics.join(", ")
    );
    kit.stats.messages_in = counts.iter().map(|c| c.received).sum();
    kit.stats.bytes_out = s.stats.file_bytes;
    kit.finish()?;
    Ok(())
}

/// The recording file with its channels (one per input; the stage statistics unless
/// `stats = false`), the launch file attached and the run's metadata; the inputs; how many
/// publishers the statistics topic has.
fn open(kit: &mut Kit, p: &RecorderParams, path: &Path) -> anyhow::Result<(TopicRecorder, Vec<Recorded>, usize)> {
    let opts = WriterOptions {
        compression: p.compression,
        compression_level: p.compression_level,
        chunk_size: (p.chunk_size_mb * 1048576.0) as u64,
        flush_interval: Duration::from_secs_f64(p.flush_interval_s),
        queue_bytes: (p.queue_mb * 1048576.0) as usize,
        ..WriterOptions::default()
    };
    let mut file = TopicRecorder::create(path, opts)?;
    let (mut rec, mut stats_publishers) = (Vec::<Recorded>::new(), 0usize);
    for (port, qos) in &kit.cfg.inputs.clone() {
        let is_stats = port == sonoflow_node_kit::STATS_TOPIC;
        if is_stats && !p.stats {
            continue;
        }
        if is_stats {
            stats_publishers = qos.max_publishers;
        }
        let kind = MessageType::parse(&qos.message_type).map_err(anyhow::Error::msg)?;
        let index = file.add_topic(&qos.topic, kind, p.viz && !is_stats)?;
        rec.push(Recorded { input: kit.dyn_input(qos)?, index, is_stats, count: TopicCount::default() });
    }
    if let Some(lf) = &p.launch_file {
        match std::fs::read(lf) {
            Ok(data) => file.attach("launch.toml", "application/toml", data)?,
            Err(e) => eprintln!("recorder: cannot attach launch file {lf}: {e}"),
        }
    }
    let run_md = [
        ("run_id", kit.cfg.run_id.clone()),
        ("sonoflow_version", env!("CARGO_PKG_VERSION").to_string()),
        ("started_unix_ns", unix_ns().to_string()),
    ];
    file.metadata("run", run_md.into_iter().map(|(k, v)| (k.to_string(), v)).collect())?;
    Ok((file, rec, stats_publishers))
}

/// Receives at most one message from every input into the file; false when none had one.
fn drain_once(rec: &mut [Recorded], file: &mut TopicRecorder, stats_eos: &mut usize) -> anyhow::Result<bool> {
    let mut any = false;
    for r in rec.iter_mut() {
        let (index, topic) = (r.index, r.input.topic_name().to_string());
        let got = r.input.receive_with(&mut |header, payload| {
            file.write(index, header, payload, unix_ns())
                .map_err(|e| sonoflow_node_kit::KitError::Port { port: topic.clone(), detail: e.to_string() })
        })?;
        match got {
            None => {}
            Some(true) => {
                any = true;
                if r.is_stats {
                    *stats_eos += 1;
                }
            }
            Some(false) => {
                any = true;
                r.count.written += 1;
            }
        }
    }
    Ok(any)
}
