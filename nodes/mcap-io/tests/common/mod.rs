//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::{collections::BTreeMap, path::Path};

use sonoflow_mcap_io::{ChannelId, ChannelSpec, InMessage, McapReader, OutMessage, ReadOptions, RecorderWriter};

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

/// Asserts that `got` is exactly a prefix of `expected` and returns its length.
pub fn assert_prefix(got: &[InMessage], expected: &[Expected]) -> usize {
    assert!(got.len() <= expected.len(), "read {} messages, wrote {}", got.len(), expected.len());
    for (i, (g, e)) in got.iter().zip(expected).enumerate() {
        assert!(
            e.matches(g),
            "message {i} differs: got topic {} seq {} t {}, expected topic {} seq {} t {}",
            g.topic,
            g.sequence,
            g.log_time,
            e.topic,
            e.sequence,
            e.log_time
        );
    }
    got.len()
}
