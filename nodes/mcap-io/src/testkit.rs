//! Test fixtures (feature `testkit`), shared by this crate's tests and the stability matrix
//! (`sonoflow stability`): deterministic payloads, a byte-message channel, writing and reading
//! back numbered messages, and the finished two-channel recording that the damaged-file tests
//! and cases cut, zero and corrupt. Test code: it panics where a fixture cannot be written or
//! read.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

use crate::{
    recover, ChannelId, ChannelSpec, InMessage, McapReader, OutMessage, ReadOptions, RecorderWriter, RecoverStats,
    WriterOptions,
};

/// Deterministic pseudo-random bytes (xorshift64*), different for every (seed, len).
pub fn payload(seed: u64, len: usize) -> Vec<u8> {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ (len as u64) ^ 0xD1B5_4A32_D192_ED03;
    if s == 0 {
        s = 1;
    }
    let mut out = Vec::with_capacity(len + 8);
    while out.len() < len {
        s ^= s >> 12;
        s ^= s << 25;
        s ^= s >> 27;
        out.extend_from_slice(&s.wrapping_mul(0x2545_F491_4F6C_DD1D).to_le_bytes());
    }
    out.truncate(len);
    out
}

/// What a test wrote, for comparison with what is read back.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Expected {
    pub topic: String,
    pub sequence: u32,
    pub log_time: u64,
    pub publish_time: u64,
    pub data: Vec<u8>,
}

impl Expected {
    pub fn matches(&self, m: &InMessage) -> bool {
        self.topic == m.topic
            && self.sequence == m.sequence
            && self.log_time == m.log_time
            && self.publish_time == m.publish_time
            && self.data == m.data
    }
}

pub fn simple_spec(topic: &str) -> ChannelSpec {
    ChannelSpec {
        topic: topic.to_string(),
        message_encoding: "application/octet-stream".to_string(),
        schema_name: "bytes".to_string(),
        schema_encoding: "jsonschema".to_string(),
        schema_data: br#"{"type":"string","contentEncoding":"base64"}"#.to_vec(),
        metadata: BTreeMap::new(),
    }
}

/// A writer creating `path` with `opts`, and its one byte-message channel `topic`.
pub fn writer_with_channel(path: &Path, opts: WriterOptions, topic: &str) -> (RecorderWriter, ChannelId) {
    let mut w = RecorderWriter::create(path, opts).expect("create");
    let ch = w.add_channel(simple_spec(topic)).expect("channel");
    (w, ch)
}

/// Writes `n` messages of `len` bytes on `channel` (topic `topic`), sequence 0.., log time
/// 1000 * (seq + 1).
pub fn write_n(w: &RecorderWriter, channel: ChannelId, topic: &str, n: u32, len: usize) -> Vec<Expected> {
    let mut expected = Vec::new();
    for seq in 0..n {
        let data = payload(u64::from(seq) + 7, len);
        let log_time = 1000 * (u64::from(seq) + 1);
        expected.push(Expected {
            topic: topic.to_string(),
            sequence: seq,
            log_time,
            publish_time: log_time + 1,
            data: data.clone(),
        });
        w.write(OutMessage { channel, sequence: seq, log_time, publish_time: log_time + 1, data }).expect("write");
    }
    expected
}

pub fn read_all(path: &Path) -> (McapReader, Vec<InMessage>) {
    let r = McapReader::open(path).expect("open");
    let msgs =
        r.messages(&ReadOptions::default()).expect("messages").collect::<Result<Vec<_>, _>>().expect("read messages");
    (r, msgs)
}

/// The index of the first message of `got` that is not the message of `expected` at its place,
/// or of the first message beyond `expected`; None if `got` is a prefix of `expected`.
pub fn first_mismatch(got: &[InMessage], expected: &[Expected]) -> Option<usize> {
    if let Some(i) = got.iter().zip(expected).position(|(g, e)| !e.matches(g)) {
        return Some(i);
    }
    (got.len() > expected.len()).then_some(expected.len())
}

/// Asserts that `got` is exactly a prefix of `expected` and returns its length.
pub fn assert_prefix(got: &[InMessage], expected: &[Expected]) -> usize {
    assert!(got.len() <= expected.len(), "read {} messages, wrote {}", got.len(), expected.len());
    if let Some(i) = first_mismatch(got, expected) {
        let (g, e) = (&got[i], &expected[i]);
        panic!(
            "message {i} differs: got topic {} seq {} t {}, expected topic {} seq {} t {}",
            g.topic, g.sequence, g.log_time, e.topic, e.sequence, e.log_time
        );
    }
    got.len()
}

/// A finished recording `full.mcap`: 60 messages of 20 KiB alternating on `/a` and `/b` in
/// 64 KiB chunks (log time 1000 + 10 seq), with metadata `run` and an attachment `config`
/// written after message 3.
pub struct FinishedRecording {
    pub path: PathBuf,
    pub expected: Vec<Expected>,
    pub bytes: Vec<u8>,
    pub summary: mcap::Summary,
    pub run_meta: BTreeMap<String, String>,
    pub config: Vec<u8>,
}

/// Writes [`FinishedRecording`] into the folder `dir` (which exists).
pub fn finished_recording(dir: &Path) -> FinishedRecording {
    let path = dir.join("full.mcap");
    let opts =
        WriterOptions { chunk_size: 64 * 1024, flush_interval: Duration::from_secs(3600), ..WriterOptions::default() };
    let mut w = RecorderWriter::create(&path, opts).expect("create");
    let a = w.add_channel(simple_spec("/a")).expect("a");
    let b = w.add_channel(simple_spec("/b")).expect("b");
    let run_meta = BTreeMap::from([("seed".to_string(), "7".to_string())]);
    let config = b"config bytes".to_vec();
    let mut expected = Vec::new();
    for seq in 0..60u32 {
        if seq == 3 {
            w.metadata("run", run_meta.clone()).expect("metadata");
            w.attach("config", "text/plain", config.clone()).expect("attach");
        }
        let (ch, topic) = if seq % 2 == 0 { (a, "/a") } else { (b, "/b") };
        let t = 1000 + u64::from(seq) * 10;
        let data = payload(u64::from(seq), 20 * 1024);
        expected.push(Expected {
            topic: topic.into(),
            sequence: seq,
            log_time: t,
            publish_time: t,
            data: data.clone(),
        });
        w.write(OutMessage { channel: ch, sequence: seq, log_time: t, publish_time: t, data }).expect("write");
    }
    w.finish().expect("finish");
    let bytes = std::fs::read(&path).expect("read");
    let summary = mcap::Summary::read(&bytes).expect("summary").expect("a finished file has a summary");
    FinishedRecording { path, expected, bytes, summary, run_meta, config }
}

impl FinishedRecording {
    /// Number of messages in the chunks that end at or before `cut`.
    pub fn messages_before(&self, cut: u64) -> usize {
        self.summary
            .chunk_indexes
            .iter()
            .filter(|c| c.chunk_start_offset + c.chunk_length <= cut)
            .map(|c| self.summary.stream_chunk(&self.bytes, c).expect("chunk").count())
            .sum()
    }

    /// (start offset, length) of the last chunk.
    pub fn last_chunk(&self) -> (u64, u64) {
        let c = self.summary.chunk_indexes.last().expect("chunks");
        (c.chunk_start_offset, c.chunk_length)
    }

    /// Offset of the end of the header record (magic 8 + opcode 1 + length 8 + the record).
    pub fn header_end(&self) -> usize {
        8 + 9 + u64::from_le_bytes(self.bytes[9..17].try_into().expect("len")) as usize
    }

    /// Cut in the middle of the last chunk.
    pub fn cut_in_last_chunk(&self) -> (Vec<u8>, usize) {
        let (start, len) = self.last_chunk();
        let cut = start + len / 2;
        (self.bytes[..cut as usize].to_vec(), self.messages_before(cut))
    }

    /// The last chunk and everything after it overwritten with zeros.
    pub fn zeroed_tail(&self) -> (Vec<u8>, usize) {
        let (start, _) = self.last_chunk();
        let mut b = self.bytes.clone();
        b[start as usize..].fill(0);
        (b, self.messages_before(start))
    }

    /// Unfinished (cut 10 bytes after the last chunk) with 64 flipped bytes in the middle of the
    /// last chunk (its CRC fails).
    pub fn corrupt_last_chunk(&self) -> (Vec<u8>, usize) {
        let (start, len) = self.last_chunk();
        let end = (start + len) as usize;
        let mut b = self.bytes[..end + 10].to_vec();
        let mid = start as usize + len as usize / 2;
        for x in &mut b[mid..mid + 64] {
            *x ^= 0x5A;
        }
        (b, self.messages_before(start))
    }
}

/// A damaged copy, read linearly and recovered.
pub struct Damaged {
    /// The damaged copy opened.
    pub reader: McapReader,
    /// Its messages, read linearly.
    pub read: Vec<InMessage>,
    /// What `recover` did, and the file it wrote.
    pub stats: RecoverStats,
    pub recovered: PathBuf,
}

/// Writes `bytes` as `<name>.mcap` next to `f`, reads it linearly and recovers it into
/// `<name>-recovered.mcap`.
pub fn read_and_recover(f: &FinishedRecording, name: &str, bytes: &[u8]) -> Damaged {
    let dir = f.path.parent().expect("dir");
    let damaged = dir.join(format!("{name}.mcap"));
    std::fs::write(&damaged, bytes).expect("write damaged");
    let reader = McapReader::open(&damaged).expect("open damaged");
    let read = reader
        .messages(&ReadOptions::default())
        .expect("messages")
        .collect::<Result<Vec<_>, _>>()
        .unwrap_or_else(|e| panic!("{name}: linear read failed: {e}"));
    let recovered = dir.join(format!("{name}-recovered.mcap"));
    let stats = recover(&damaged, &recovered).unwrap_or_else(|e| panic!("{name}: recover: {e}"));
    Damaged { reader, read, stats, recovered }
}
