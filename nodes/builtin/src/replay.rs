//! `replay` node: publishes recorded topics from an MCAP file into the graph. It becomes the
//! producer of the topics it replays; downstream nodes cannot tell the difference, except for
//! the `REPLAYED` flag. Headers keep their recorded sequence numbers, frame ids and times.
//!
//! Outputs map a recorded topic to a graph topic: `outputs = { rf = "rf" }`.
//! `rate = 0` publishes as fast as the graph accepts (lossless, deterministic); `rate = 1`
//! reproduces the recorded timing (recorder receive times), `2` twice as fast.

use serde::{Deserialize, Serialize};
use sonoflow_mcap_io::{McapReader, ReadOptions};
use sonoflow_messages::{cdr, MessageType, MsgHeaderV1, FLAG_REPLAYED, FLAG_RESET};
use sonoflow_node_kit::parse_params;
use sonoflow_node_kit::KindSpec;
use sonoflow_node_kit::{thread_cpu_ns, DynOutput, Handshake, Kit};
use std::collections::BTreeMap;
use std::path::Path;
use std::time::{Duration, Instant};

/// The `replay` node kind.
pub const SPEC: KindSpec = KindSpec::new(
    "replay",
    "publishes the topics of an MCAP recording into the graph (outputs: recorded topic = graph topic)",
    &[],
    validate,
    run,
)
.with_input_files(&["path"])
.with_dynamic_ports(false, true);

/// Replay parameters.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReplayParams {
    /// MCAP file (relative paths: to the launch file's folder, then the working directory).
    pub path: String,
    /// Speed factor of the recorded timing; 0 = as fast as possible (lossless).
    pub rate: f64,
    /// How many times to play the file; 0 = until stopped.
    pub loops: u32,
    /// Skip this many seconds from the first recorded message.
    pub start_offset_s: f64,
}

impl Default for ReplayParams {
    fn default() -> Self {
        Self { path: String::new(), rate: 0.0, loops: 1, start_offset_s: 0.0 }
    }
}

impl ReplayParams {
    pub fn validate(&self) -> Result<(), String> {
        if self.path.is_empty() {
            return Err("path is required (the MCAP file to replay)".into());
        }
        if !(self.rate.is_finite() && (0.0..=1000.0).contains(&self.rate)) {
            return Err(format!("rate = {} is out of range: 0 (as fast as possible) ..= 1000", self.rate));
        }
        if !(self.start_offset_s.is_finite() && self.start_offset_s >= 0.0) {
            return Err(format!("start_offset_s = {} is out of range: >= 0", self.start_offset_s));
        }
        Ok(())
    }
}

pub fn validate(v: &serde_json::Value) -> Result<(), String> {
    parse_params::<ReplayParams>(v)?.validate()
}

pub fn run(mut kit: Kit) -> anyhow::Result<()> {
    let p: ReplayParams = parse_params(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    p.validate().map_err(anyhow::Error::msg)?;
    let reader = McapReader::open(Path::new(&p.path))?;
    let mut outs = open_outputs(&mut kit, &p, &reader)?;
    {
        let mut hs: Vec<&mut dyn Handshake> =
            outs.values_mut().map(|(_, o)| o.as_mut() as &mut dyn Handshake).collect();
        kit.handshake(&mut hs)?;
    }
    let topics: Vec<String> = outs.keys().cloned().collect();
    // First log time, for the start offset and pacing.
    let first = reader
        .messages(&ReadOptions { topics: Some(topics.clone()), start_time: None, end_time: None })?
        .next()
        .transpose()?
        .map(|m| m.log_time)
        .unwrap_or(0);
    let total =
        reader.topics().iter().filter(|t| topics.contains(&t.topic)).filter_map(|t| t.message_count).sum::<u64>();
    if let Some(w) = unfinished_warning(&reader, total) {
        eprintln!("{w}");
    }
    let mut play =
        Playback { start_time: first + (p.start_offset_s * 1e9) as u64, total, sent: 0, last_t: 0.0, lap: 0 };
    while play.lap(&mut kit, &p, &reader, &topics, &mut outs)? {
        play.lap += 1;
        if p.loops != 0 && play.lap >= p.loops {
            break;
        }
    }
    for (_, o) in outs.values_mut() {
        o.eos(play.last_t)?;
    }
    println!("replay: {} messages from {}", play.sent, p.path);
    kit.finish()?;
    Ok(())
}

/// The node's outputs by recorded topic; an error names a topic that is not in the recording or
/// whose recorded schema differs from the graph topic's type (or is a retired wire version).
fn open_outputs(kit: &mut Kit, p: &ReplayParams, reader: &McapReader) -> anyhow::Result<Outputs> {
    let recorded: BTreeMap<String, String> = reader.topics().into_iter().map(|t| (t.topic, t.schema_name)).collect();
    let mut outs = Outputs::new();
    for (rec_topic, qos) in &kit.cfg.outputs.clone() {
        let kind = MessageType::from_name(&qos.message_type)
            .ok_or_else(|| anyhow::anyhow!("unknown message type {}", qos.message_type))?;
        match recorded.get(rec_topic) {
            None => anyhow::bail!(
                "replay: topic `{rec_topic}` is not in {} (recorded: {})",
                p.path,
                recorded.keys().cloned().collect::<Vec<_>>().join(", ")
            ),
            Some(schema) if *schema != kind.schema_name() => {
                MessageType::from_schema_name(schema)
                    .map_err(|e| anyhow::anyhow!("replay: {}, topic `{rec_topic}`: {e}", p.path))?;
                anyhow::bail!(
                    "replay: recorded topic `{rec_topic}` has schema {schema} but graph topic `{}` is {kind}",
                    qos.topic
                )
            }
            Some(_) => {}
        }
        outs.insert(rec_topic.clone(), (kind, kit.dyn_output(qos)?));
    }
    Ok(outs)
}

/// Recorded topic → (its type, the graph output it is published on).
type Outputs = BTreeMap<String, (MessageType, Box<dyn DynOutput>)>;

/// Where a replay stands.
struct Playback {
    /// Log time of the first message played \[ns\].
    start_time: u64,
    /// Messages per lap on the replayed topics.
    total: u64,
    sent: u64,
    last_t: f64,
    lap: u32,
}

impl Playback {
    /// Plays the file once (paced by `rate`); false if a termination request stopped it.
    fn lap(
        &mut self,
        kit: &mut Kit,
        p: &ReplayParams,
        reader: &McapReader,
        topics: &[String],
        outs: &mut Outputs,
    ) -> anyhow::Result<bool> {
        let t_start = Instant::now();
        let mut first_of_lap = true;
        let opts = ReadOptions { topics: Some(topics.to_vec()), start_time: Some(self.start_time), end_time: None };
        for m in reader.messages(&opts)? {
            let m = m?;
            if kit.check_termination().is_err() {
                return Ok(false);
            }
            let Some((kind, out)) = outs.get_mut(&m.topic) else { continue };
            if p.rate > 0.0 {
                let due = Duration::from_secs_f64((m.log_time.saturating_sub(self.start_time)) as f64 / 1e9 / p.rate);
                let el = t_start.elapsed();
                if due > el {
                    std::thread::sleep(due - el);
                }
            }
            let t0 = thread_cpu_ns();
            let (header, payload) = cdr::split(*kind, &m.data)?;
            let c: MsgHeaderV1 = bytemuck::pod_read_unaligned(&header[..std::mem::size_of::<MsgHeaderV1>()]);
            let mut flags = FLAG_REPLAYED;
            if first_of_lap && self.lap > 0 {
                flags |= FLAG_RESET;
            }
            first_of_lap = false;
            out.publish_bytes(header, payload, flags)?;
            self.last_t = c.t_valid;
            self.sent += 1;
            kit.published(payload.len() as u64, c.frame_id, c.t_valid, thread_cpu_ns() - t0)?;
            if self.total > 0 && self.sent.is_multiple_of((self.total / 20).max(1)) {
                kit.progress(self.sent, self.total * p.loops.max(1) as u64);
            }
        }
        Ok(true)
    }
}

/// The warning for a recording without a summary (its recorder was killed, or the copy was cut
/// short): replay then plays the messages of its complete chunks only, and says how many.
/// `replayed_topics_messages` is how many of those are on the replayed topics. `None` for a
/// complete recording.
pub fn unfinished_warning(reader: &McapReader, replayed_topics_messages: u64) -> Option<String> {
    let note = reader.unfinished_note()?;
    Some(format!(
        "replay: warning: {note}; {replayed_topics_messages} of them are on the replayed topics \
         (`sonoflow recover` rewrites the file as a complete recording)"
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use sonoflow_mcap_io::{ChannelSpec, OutMessage, RecorderWriter, WriterOptions};

    #[test]
    fn an_unfinished_recording_gets_a_warning_with_the_recovered_counts() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("killed.mcap");
        let opts = WriterOptions {
            chunk_size: 8 * 1024,
            flush_interval: Duration::from_secs(3600),
            ..WriterOptions::default()
        };
        let mut w = RecorderWriter::create(&path, opts).expect("create");
        let spec =
            |topic: &str| ChannelSpec { topic: topic.into(), message_encoding: "cdr".into(), ..Default::default() };
        let rf = w.add_channel(spec("rf")).expect("rf");
        let other = w.add_channel(spec("other")).expect("other");
        for seq in 0..30u32 {
            for ch in [rf, other] {
                let t = 1000 * u64::from(seq + 1);
                w.write(OutMessage { channel: ch, sequence: seq, log_time: t, publish_time: t, data: vec![7; 1000] })
                    .expect("write");
            }
        }
        // Like a kill -9: the open chunk, the summary and the footer are never written.
        w.abandon().expect("abandon");
        let reader = McapReader::open(&path).expect("open");
        let counts: BTreeMap<String, u64> =
            reader.topics().into_iter().map(|t| (t.topic, t.message_count.expect("counted"))).collect();
        let all = counts.values().sum::<u64>();
        assert!(all > 0 && all < 60, "some messages were lost with the open chunk: {counts:?}");
        let w = unfinished_warning(&reader, counts["rf"]).expect("a warning");
        assert!(w.starts_with(&format!("replay: warning: {} is unfinished", path.display())), "{w}");
        assert!(w.contains(&format!(": {all} message(s) read from ")), "{w}");
        assert!(w.contains(&format!("; {} of them are on the replayed topics", counts["rf"])), "{w}");
        assert!(w.contains("sonoflow recover"), "{w}");

        // A finished recording: no warning.
        let done = dir.path().join("done.mcap");
        let mut w = RecorderWriter::create(&done, WriterOptions::default()).expect("create");
        let rf = w.add_channel(spec("rf")).expect("rf");
        w.write(OutMessage { channel: rf, sequence: 0, log_time: 1, publish_time: 1, data: vec![1] }).expect("write");
        w.finish().expect("finish");
        assert_eq!(unfinished_warning(&McapReader::open(&done).expect("open"), 1), None);
    }
}
