//! `recorder` node: subscribes to topics of the graph and writes MCAP.
//!
//! Lossless by construction: inputs are lossless iceoryx2 subscribers, the receive loop copies
//! each sample out of shared memory into the writer's bounded queue and blocks when the queue is
//! full (back-pressure up the graph), the writer thread closes a chunk at least every
//! `flush_interval_s` so a `kill -9` loses at most that much. Per-topic received / written /
//! sequence-gap counters and `complete = true|false` go into the file's `recording_stats`
//! metadata and are printed at the end.

use serde::{Deserialize, Serialize};
use sonoflow_mcap_io::{ChannelId, ChannelSpec, Compression, OutMessage, RecorderWriter, WriterOptions};
use sonoflow_messages::{cdr, viz, MessageType};
use sonoflow_node_kit::KindSpec;
use sonoflow_node_kit::{in_range, parse_params};
use sonoflow_node_kit::{select_loop, unix_ns, DynInput, Kit, SelectEnd, Step};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Duration;

/// The `recorder` node kind.
pub const SPEC: KindSpec = KindSpec {
    name: "recorder",
    about: "records topics to MCAP (lossless, chunk-compressed, Foxglove pictures)",
    ports: &[],
    dynamic_inputs: true,
    dynamic_outputs: false,
    validate,
    check_wiring: None,
    input_files: &[],
    run,
};

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

/// Per-topic counters written into the file.
#[derive(Clone, Debug, Default, Serialize)]
struct TopicCount {
    received: u64,
    written: u64,
    gaps: u64,
    end_of_stream: bool,
}

struct Recorded {
    input: Box<dyn DynInput>,
    raw: ChannelId,
    viz: Option<ChannelId>,
    is_stats: bool,
    count: TopicCount,
}

pub fn run(mut kit: Kit) -> anyhow::Result<()> {
    let p: RecorderParams = parse_params(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    p.validate().map_err(anyhow::Error::msg)?;
    let out_dir = PathBuf::from(kit.cfg.out_dir.clone().unwrap_or_else(|| ".".into()));
    let path = out_dir.join(&p.path);
    let opts = WriterOptions {
        compression: p.compression,
        compression_level: p.compression_level,
        chunk_size: (p.chunk_size_mb * 1048576.0) as u64,
        flush_interval: Duration::from_secs_f64(p.flush_interval_s),
        queue_bytes: (p.queue_mb * 1048576.0) as usize,
        ..WriterOptions::default()
    };
    let mut writer = RecorderWriter::create(&path, opts)?;

    let inputs_cfg = kit.cfg.inputs.clone();
    let mut rec: Vec<Recorded> = Vec::new();
    let mut stats_publishers = 0usize;
    for (port, qos) in &inputs_cfg {
        let is_stats = port == sonoflow_node_kit::STATS_TOPIC;
        if is_stats && !p.stats {
            continue;
        }
        if is_stats {
            stats_publishers = qos.max_publishers;
        }
        let kind = MessageType::from_name(&qos.message_type)
            .ok_or_else(|| anyhow::anyhow!("unknown message type {}", qos.message_type))?;
        let mut md = BTreeMap::new();
        md.insert("sonoflow.kind".to_string(), kind.name().to_string());
        md.insert("sonoflow.header_size".to_string(), kind.header_size().to_string());
        md.insert("sonoflow.elem_size".to_string(), kind.elem_size().to_string());
        let raw = writer.add_channel(ChannelSpec {
            topic: qos.topic.clone(),
            message_encoding: "cdr".into(),
            schema_name: kind.schema_name(),
            schema_encoding: "ros2msg".into(),
            schema_data: kind.schema_text().into_bytes(),
            metadata: md,
        })?;
        rec.push(Recorded { input: kit.dyn_input(qos)?, raw, viz: None, is_stats, count: TopicCount::default() });
    }
    if let Some(lf) = &p.launch_file {
        match std::fs::read(lf) {
            Ok(data) => writer.attach("launch.toml", "application/toml", data)?,
            Err(e) => eprintln!("recorder: cannot attach launch file {lf}: {e}"),
        }
    }
    let mut run_md = BTreeMap::new();
    run_md.insert("run_id".to_string(), kit.cfg.run_id.clone());
    run_md.insert("sonoflow_version".to_string(), env!("CARGO_PKG_VERSION").to_string());
    run_md.insert("started_unix_ns".to_string(), unix_ns().to_string());
    writer.metadata("run", run_md)?;

    {
        let mut hs: Vec<&mut dyn sonoflow_node_kit::Handshake> =
            rec.iter_mut().map(|r| r.input.as_mut() as &mut dyn sonoflow_node_kit::Handshake).collect();
        kit.handshake(&mut hs)?;
    }
    println!("recorder: recording {} topic(s) to {}", rec.len(), path.display());

    let wakeups: Vec<_> = rec.iter().map(|r| r.input.wakeup()).collect();
    let mut stats_eos = 0usize;
    let mut buf_viz_channels: BTreeMap<String, ChannelId> = BTreeMap::new();
    let end = select_loop(&mut kit, &wakeups, Duration::from_millis(500), |_| {
        // Drain every input.
        loop {
            let mut any = false;
            for r in rec.iter_mut() {
                let kind = r.input.kind();
                let topic = r.input.topic_name().to_string();
                let raw = r.raw;
                let want_viz = p.viz && !r.is_stats;
                let mut viz_ch = r.viz;
                let w = &mut writer;
                let vc = &mut buf_viz_channels;
                let got = r.input.receive_with(&mut |header, payload| {
                    let log_time = unix_ns();
                    let c: sonoflow_messages::MsgHeaderV1 =
                        bytemuck::pod_read_unaligned(&header[..std::mem::size_of::<sonoflow_messages::MsgHeaderV1>()]);
                    let mut data = w.buffer(8 + header.len() + payload.len());
                    cdr::encode_bytes_into(header, payload.len() / kind.elem_size().max(1), payload, &mut data);
                    w.write(OutMessage {
                        channel: raw,
                        sequence: c.seq as u32,
                        log_time,
                        publish_time: c.t_pub_ns,
                        data,
                    })
                    .map_err(|e| sonoflow_node_kit::KitError::Port { port: topic.clone(), detail: e.to_string() })?;
                    if want_viz {
                        if let Some(v) = viz::viz(kind, header, payload) {
                            let ch = match viz_ch {
                                Some(ch) => ch,
                                None => {
                                    let t = viz::viz_topic(&topic);
                                    let ch =
                                        w.add_channel(ChannelSpec {
                                            topic: t.clone(),
                                            message_encoding: v.message_encoding.clone(),
                                            schema_name: v.schema_name.clone(),
                                            schema_encoding: v.schema_encoding.clone(),
                                            schema_data: v.schema_data.clone(),
                                            metadata: BTreeMap::new(),
                                        })
                                        .map_err(|e| {
                                            sonoflow_node_kit::KitError::Port { port: t.clone(), detail: e.to_string() }
                                        })?;
                                    vc.insert(t, ch);
                                    viz_ch = Some(ch);
                                    ch
                                }
                            };
                            w.write(OutMessage {
                                channel: ch,
                                sequence: c.seq as u32,
                                log_time,
                                publish_time: c.t_pub_ns,
                                data: v.data,
                            })
                            .map_err(|e| sonoflow_node_kit::KitError::Port {
                                port: topic.clone(),
                                detail: e.to_string(),
                            })?;
                        }
                    }
                    Ok(())
                })?;
                r.viz = viz_ch;
                match got {
                    None => {}
                    Some(true) => {
                        any = true;
                        if r.is_stats {
                            stats_eos += 1;
                        }
                    }
                    Some(false) => {
                        any = true;
                        r.count.written += 1;
                    }
                }
            }
            if !any {
                break;
            }
        }
        let data_done = rec.iter().filter(|r| !r.is_stats).all(|r| r.input.counters().2);
        Ok(if data_done && stats_eos >= stats_publishers { Step::Done } else { Step::Continue })
    })?;
    let terminated = end == SelectEnd::Terminated;

    // Counters into the file.
    let mut complete = true;
    let mut md = BTreeMap::new();
    let mut summary = Vec::new();
    for r in rec.iter_mut() {
        let (received, gaps, eos) = r.input.counters();
        r.count.received = received;
        r.count.gaps = gaps;
        r.count.end_of_stream = eos || (r.is_stats && stats_eos >= stats_publishers);
        if !r.count.end_of_stream || gaps > 0 || r.count.written != received {
            complete = false;
        }
        md.insert(r.input.topic_name().to_string(), serde_json::to_string(&r.count).unwrap_or_default());
        summary.push(format!(
            "{} {}/{}{}{}",
            r.input.topic_name(),
            r.count.written,
            received,
            if gaps > 0 { format!(" ({gaps} gaps)") } else { String::new() },
            if r.count.end_of_stream { "" } else { " (no end of stream)" }
        ));
    }
    md.insert("complete".into(), complete.to_string());
    md.insert("dropped".into(), "0".into());
    md.insert("terminated_early".into(), terminated.to_string());
    writer.metadata("recording_stats", md)?;
    let ws = writer.finish()?;
    println!(
        "recorder: {} — {} MB written, complete = {complete}, dropped = 0; topics written/received: {}",
        path.display(),
        ws.file_bytes as f64 / 1e6,
        summary.join(", ")
    );
    kit.stats.messages_in = rec.iter().map(|r| r.count.received).sum();
    kit.stats.bytes_out = ws.file_bytes;
    kit.finish()?;
    Ok(())
}
