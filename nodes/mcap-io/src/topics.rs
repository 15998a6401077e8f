//! Recording sonoflow topics: one raw CDR channel per topic (schema and sizes from
//! `sonoflow-messages`), optional Foxglove pictures (`viz/<topic>`, channel created on the first
//! picture), run metadata, and at the end per-topic counters and `complete = true|false` in the
//! file's `recording_stats` metadata. What the `recorder` node does, without IPC.

use std::collections::BTreeMap;
use std::path::Path;

use serde::Serialize;
use sonoflow_messages::{cdr, viz, MessageType, MsgHeaderV1};

use crate::{ChannelId, ChannelSpec, McapIoError, OutMessage, RecorderWriter, WriterOptions, WriterStats};

/// Per-topic counters written into the file.
#[derive(Clone, Debug, Default, Serialize)]
pub struct TopicCount {
    /// Messages the subscriber received.
    pub received: u64,
    /// Data messages written (end-of-stream markers not counted).
    pub written: u64,
    /// Sequence gaps seen (lost messages).
    pub gaps: u64,
    /// Whether the topic's end of stream arrived.
    pub end_of_stream: bool,
}

struct Topic {
    name: String,
    kind: MessageType,
    raw: ChannelId,
    viz: Option<ChannelId>,
    want_viz: bool,
}

/// How a recording ended.
pub struct RecordingSummary {
    /// Every topic ended with its end of stream, no gaps, everything received written.
    pub complete: bool,
    /// Writer statistics (file size …).
    pub stats: WriterStats,
    /// One `topic written/received` entry per topic, for the log.
    pub topics: Vec<String>,
}

/// An MCAP file of sonoflow topics being written.
pub struct TopicRecorder {
    writer: RecorderWriter,
    topics: Vec<Topic>,
}

impl TopicRecorder {
    /// Creates the file (refuses to overwrite one).
    pub fn create(path: &Path, opts: WriterOptions) -> Result<Self, McapIoError> {
        Ok(Self { writer: RecorderWriter::create(path, opts)?, topics: Vec::new() })
    }

    /// Adds a topic of message type `kind`; with `viz`, its Foxglove pictures too. Returns the
    /// topic's index for [`TopicRecorder::write`].
    pub fn add_topic(&mut self, name: &str, kind: MessageType, viz: bool) -> Result<usize, McapIoError> {
        let mut md = BTreeMap::new();
        md.insert("sonoflow.kind".to_string(), kind.name().to_string());
        md.insert("sonoflow.header_size".to_string(), kind.header_size().to_string());
        md.insert("sonoflow.elem_size".to_string(), kind.elem_size().to_string());
        let raw = self.writer.add_channel(ChannelSpec {
            topic: name.to_string(),
            message_encoding: "cdr".into(),
            schema_name: kind.schema_name(),
            schema_encoding: "ros2msg".into(),
            schema_data: kind.schema_text().into_bytes(),
            metadata: md,
        })?;
        self.topics.push(Topic { name: name.to_string(), kind, raw, viz: None, want_viz: viz });
        Ok(self.topics.len() - 1)
    }

    /// Attaches a file (e.g. the resolved launch file).
    pub fn attach(&self, name: &str, media_type: &str, data: Vec<u8>) -> Result<(), McapIoError> {
        self.writer.attach(name, media_type, data)
    }

    /// Writes a `name` metadata record.
    pub fn metadata(&self, name: &str, map: BTreeMap<String, String>) -> Result<(), McapIoError> {
        self.writer.metadata(name, map)
    }

    /// Writes one message (raw header and payload bytes of the wire type) of topic `index`,
    /// logged at `log_time` (UNIX ns), and its picture if the topic has pictures.
    pub fn write(&mut self, index: usize, header: &[u8], payload: &[u8], log_time: u64) -> Result<(), McapIoError> {
        let t = self.topics.get_mut(index).ok_or(McapIoError::UnknownChannel(index as u16))?;
        let common_len = std::mem::size_of::<MsgHeaderV1>();
        let c: MsgHeaderV1 = match header.get(..common_len) {
            Some(h) => bytemuck::pod_read_unaligned(h),
            None => return Err(McapIoError::WriterThread(format!("{}: header of {} bytes", t.name, header.len()))),
        };
        let mut data = self.writer.buffer(8 + header.len() + payload.len());
        cdr::encode_bytes_into(header, payload.len() / t.kind.elem_size().max(1), payload, &mut data);
        self.writer.write(OutMessage {
            channel: t.raw,
            sequence: c.seq as u32,
            log_time,
            publish_time: c.t_pub_ns,
            data,
        })?;
        if !t.want_viz {
            return Ok(());
        }
        let Some(v) = viz::viz(t.kind, header, payload) else { return Ok(()) };
        let channel = match t.viz {
            Some(ch) => ch,
            None => {
                let ch = self.writer.add_channel(ChannelSpec {
                    topic: viz::viz_topic(&t.name),
                    message_encoding: v.message_encoding.clone(),
                    schema_name: v.schema_name.clone(),
                    schema_encoding: v.schema_encoding.clone(),
                    schema_data: v.schema_data.clone(),
                    metadata: BTreeMap::new(),
                })?;
                t.viz = Some(ch);
                ch
            }
        };
        self.writer.write(OutMessage {
            channel,
            sequence: c.seq as u32,
            log_time,
            publish_time: c.t_pub_ns,
            data: v.data,
        })
    }

    /// Writes the counters (one per topic, in the order added) and closes the file.
    pub fn finish(self, counts: &[TopicCount], terminated_early: bool) -> Result<RecordingSummary, McapIoError> {
        let mut complete = true;
        let mut md = BTreeMap::new();
        let mut topics = Vec::new();
        for (t, n) in self.topics.iter().zip(counts) {
            if !n.end_of_stream || n.gaps > 0 || n.written != n.received {
                complete = false;
            }
            md.insert(t.name.clone(), serde_json::to_string(n).unwrap_or_default());
            topics.push(format!(
                "{} {}/{}{}{}",
                t.name,
                n.written,
                n.received,
                if n.gaps > 0 { format!(" ({} gaps)", n.gaps) } else { String::new() },
                if n.end_of_stream { "" } else { " (no end of stream)" }
            ));
        }
        md.insert("complete".into(), complete.to_string());
        md.insert("dropped".into(), "0".into());
        md.insert("terminated_early".into(), terminated_early.to_string());
        self.writer.metadata("recording_stats", md)?;
        let stats = self.writer.finish()?;
        Ok(RecordingSummary { complete, stats, topics })
    }
}
