//! [`McapReader::verify`]: decode every record of a file, check every CRC, and compare what was
//! decoded with the file's summary.
//!
//! [`McapReader::open`] trusts the summary of a complete file: it reads the footer, the summary
//! and the indexes, and decompresses a chunk only when a message of it is asked for. Damaged
//! chunk data therefore goes unnoticed until a reader gets to it. `verify` walks the whole file
//! instead, record by record, like `mcap doctor`.

use std::collections::{BTreeMap, BTreeSet};

use mcap::{
    read::{parse_record, ChannelAccumulator},
    records::{op, Record},
    MAGIC,
};

use crate::{
    error::error_chain,
    reader::{chunk_records, record_at},
    McapReader,
};

/// A message as [`McapReader::verify`] hands it to its checker.
#[derive(Debug, Clone, Copy)]
pub struct MessageView<'a> {
    pub topic: &'a str,
    /// Empty if the channel has no schema.
    pub schema_name: &'a str,
    pub message_encoding: &'a str,
    pub sequence: u32,
    pub log_time: u64,
    pub data: &'a [u8],
}

/// Messages of one channel: decoded by [`McapReader::verify`], and according to the summary.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct VerifiedTopic {
    pub topic: String,
    /// Messages in intact records (before the first damaged one).
    pub decoded: u64,
    /// The count in the file's statistics record; `None` for an unfinished file or a summary
    /// without per-channel counts.
    pub summary: Option<u64>,
}

/// What [`McapReader::verify`] found.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Verification {
    /// Records read (top level, chunks counted once).
    pub records: u64,
    /// Chunks decompressed and CRC-checked without error.
    pub chunks: u64,
    /// One entry per channel, by channel id.
    pub topics: Vec<VerifiedTopic>,
    /// Everything found wrong, each naming where; empty if the file is intact. A damaged or
    /// truncated record ends the walk, so it comes first and later records are not looked at.
    pub problems: Vec<String>,
}

impl Verification {
    /// `true` if nothing is wrong.
    pub fn is_ok(&self) -> bool {
        self.problems.is_empty()
    }

    /// Messages decoded, all channels.
    pub fn messages(&self) -> u64 {
        self.topics.iter().map(|t| t.decoded).sum()
    }
}

fn record_name(opcode: u8) -> String {
    match opcode {
        op::HEADER => "header".into(),
        op::FOOTER => "footer".into(),
        op::SCHEMA => "schema".into(),
        op::CHANNEL => "channel".into(),
        op::MESSAGE => "message".into(),
        op::CHUNK => "chunk".into(),
        op::MESSAGE_INDEX => "message index".into(),
        op::CHUNK_INDEX => "chunk index".into(),
        op::ATTACHMENT => "attachment".into(),
        op::ATTACHMENT_INDEX => "attachment index".into(),
        op::STATISTICS => "statistics".into(),
        op::METADATA => "metadata".into(),
        op::METADATA_INDEX => "metadata index".into(),
        op::SUMMARY_OFFSET => "summary offset".into(),
        op::DATA_END => "data end".into(),
        other => format!("opcode 0x{other:02X}"),
    }
}

/// The channel bookkeeping and counters of one walk.
struct Walk<'c> {
    channels: ChannelAccumulator<'static>,
    /// Messages per channel id in intact records.
    decoded: BTreeMap<u16, u64>,
    check: &'c mut dyn FnMut(&MessageView<'_>) -> Result<(), String>,
    bad_messages: u64,
    first_bad_message: Option<String>,
}

impl Walk<'_> {
    /// Links one record of the data section (top level or inside a chunk, at `where_`) to the
    /// channels seen so far; messages go to the checker and into `counts`.
    fn record(&mut self, record: Record<'_>, where_: &str, counts: &mut BTreeMap<u16, u64>) -> Result<(), String> {
        match record {
            Record::Schema { header, data } => {
                self.channels.add_schema(header, data.into_owned().into()).map_err(|e| error_chain(&e))
            }
            Record::Channel(c) => self.channels.add_channel(c).map_err(|e| error_chain(&e)),
            Record::Message { header, data } => {
                let Some(channel) = self.channels.get(header.channel_id) else {
                    return Err(format!(
                        "message {} names channel {}, which no earlier channel record defines",
                        header.sequence, header.channel_id
                    ));
                };
                *counts.entry(header.channel_id).or_insert(0) += 1;
                let view = MessageView {
                    topic: &channel.topic,
                    schema_name: channel.schema.as_ref().map(|s| s.name.as_str()).unwrap_or(""),
                    message_encoding: &channel.message_encoding,
                    sequence: header.sequence,
                    log_time: header.log_time,
                    data: &data,
                };
                if let Err(e) = (self.check)(&view) {
                    self.bad_messages += 1;
                    if self.first_bad_message.is_none() {
                        self.first_bad_message = Some(format!(
                            "message {} on `{}` (log time {}, in the {where_}) does not decode: {e}",
                            header.sequence, channel.topic, header.log_time
                        ));
                    }
                }
                Ok(())
            }
            _ => Ok(()),
        }
    }
}

impl McapReader {
    /// Reads the whole file record by record: parses every record, decompresses every chunk and
    /// checks its CRC (and those of attachments, the data section and the summary section),
    /// links every message to its channel, passes it to `check` (which may decode the payload;
    /// an `Err` is reported as a problem, the walk goes on), and finally compares the messages
    /// per channel and the chunks with the summary's statistics and chunk indexes.
    ///
    /// Problems name the byte offset of the record concerned. An unfinished file (no footer) is
    /// always a problem, even when every record before the cut is intact.
    pub fn verify(&self, check: &mut dyn FnMut(&MessageView<'_>) -> Result<(), String>) -> Verification {
        let data: &[u8] = &self.mmap;
        let mut walk = Walk {
            channels: ChannelAccumulator::default(),
            decoded: BTreeMap::new(),
            check,
            bad_messages: 0,
            first_bad_message: None,
        };
        let mut out = Verification::default();
        let mut chunk_spans: BTreeMap<u64, u64> = BTreeMap::new();
        let mut structural: Option<String> = None;
        let mut pos = MAGIC.len();
        let mut finished = false;
        while structural.is_none() && !finished {
            if pos == data.len() {
                structural = Some(format!(
                    "the file ends at byte {pos} without a footer: it is unfinished (run `sonoflow recover`)"
                ));
                break;
            }
            let Some((opcode, body, end)) = record_at(data, pos) else {
                structural = Some(format!(
                    "the record at byte offset {pos} runs past the end of the file ({} bytes): the file is truncated",
                    data.len()
                ));
                break;
            };
            let name = record_name(opcode);
            let at = |e: String| format!("{name} record at byte offset {pos}: {e}");
            if opcode == 0 {
                structural = Some(at("opcode 0 is not a valid record (zeroed or overwritten data?)".into()));
                break;
            }
            out.records += 1;
            let parsed = match parse_record(opcode, body) {
                Ok(r) => r,
                Err(e) => {
                    structural = Some(at(error_chain(&e)));
                    break;
                }
            };
            let result: Result<(), String> = match parsed {
                Record::Chunk { .. } => {
                    let where_ = format!("chunk at byte offset {pos}");
                    let mut counts = BTreeMap::new();
                    let mut result = Ok(());
                    match chunk_records(&data[pos..end]) {
                        Err(e) => result = Err(error_chain(&e)),
                        Ok(records) => {
                            for r in records {
                                if let Err(e) = walk.record(r, &where_, &mut counts) {
                                    result = Err(e);
                                    break;
                                }
                            }
                        }
                    }
                    if result.is_ok() {
                        out.chunks += 1;
                        chunk_spans.insert(pos as u64, (end - pos) as u64);
                        for (id, n) in counts {
                            *walk.decoded.entry(id).or_insert(0) += n;
                        }
                    }
                    result
                }
                Record::DataEnd(d) => {
                    // CRC-32 of everything before the data end record (0: not computed).
                    let calculated = crc32fast::hash(&data[..pos]);
                    if d.data_section_crc != 0 && d.data_section_crc != calculated {
                        Err(format!(
                            "data section CRC failed (expected {:08X}, got {calculated:08X})",
                            d.data_section_crc
                        ))
                    } else {
                        Ok(())
                    }
                }
                Record::Footer(f) => {
                    finished = true;
                    // CRC-32 from the summary start (or this footer if there is no summary)
                    // through the footer's summary_offset_start field (0: not computed).
                    let start = if f.summary_start == 0 { pos as u64 } else { f.summary_start };
                    let crc_end = pos + 1 + 8 + 8 + 8;
                    match usize::try_from(start).ok().filter(|&s| s <= pos) {
                        None => Err(format!("summary start {start} lies after the footer")),
                        Some(s) => {
                            let calculated = crc32fast::hash(&data[s..crc_end]);
                            if f.summary_crc != 0 && f.summary_crc != calculated {
                                Err(format!(
                                    "summary section CRC failed (expected {:08X}, got {calculated:08X})",
                                    f.summary_crc
                                ))
                            } else if data.get(end..) != Some(MAGIC) {
                                Err(format!(
                                    "the footer is not followed by the closing magic bytes and the end of the file \
                                     ({} bytes follow it)",
                                    data.len() - end
                                ))
                            } else {
                                Ok(())
                            }
                        }
                    }
                }
                r @ (Record::Schema { .. } | Record::Channel(_) | Record::Message { .. }) => {
                    let where_ = format!("record at byte offset {pos}");
                    let mut counts = BTreeMap::new();
                    let result = walk.record(r, &where_, &mut counts);
                    for (id, n) in counts {
                        *walk.decoded.entry(id).or_insert(0) += n;
                    }
                    result
                }
                // Parsing checked the attachment CRC and the layout of everything else.
                _ => Ok(()),
            };
            if let Err(e) = result {
                structural = Some(at(e));
                break;
            }
            pos = end;
        }
        let walked_to_the_end = structural.is_none();
        out.problems.extend(structural);
        if let Some(first) = walk.first_bad_message.take() {
            let more = walk.bad_messages - 1;
            out.problems.push(if more > 0 { format!("{first} ({more} more do not decode either)") } else { first });
        }

        // Per-channel counts against the statistics of a complete file.
        let stats = if self.complete { self.summary.stats.as_ref() } else { None };
        let per_channel = stats.filter(|s| !s.channel_message_counts.is_empty() || s.message_count == 0);
        let mut ids: BTreeSet<u16> = self.summary.channels.keys().copied().collect();
        ids.extend(walk.decoded.keys().copied());
        for id in ids {
            let topic = match (walk.channels.get(id), self.summary.channels.get(&id)) {
                (Some(c), _) => c.topic.clone(),
                (None, Some(c)) => c.topic.clone(),
                (None, None) => format!("channel {id}"),
            };
            out.topics.push(VerifiedTopic {
                topic,
                decoded: walk.decoded.get(&id).copied().unwrap_or(0),
                summary: per_channel.map(|s| s.channel_message_counts.get(&id).copied().unwrap_or(0)),
            });
        }
        if walked_to_the_end {
            for t in &out.topics {
                if let Some(expected) = t.summary.filter(|&n| n != t.decoded) {
                    out.problems.push(format!(
                        "topic `{}`: {} message(s) decoded, the summary's statistics say {expected}",
                        t.topic, t.decoded
                    ));
                }
            }
            if let Some(s) = stats {
                if per_channel.is_none() && s.message_count != out.messages() {
                    out.problems.push(format!(
                        "{} message(s) decoded, the summary's statistics say {}",
                        out.messages(),
                        s.message_count
                    ));
                }
            }
            if self.complete {
                for ci in &self.summary.chunk_indexes {
                    if chunk_spans.get(&ci.chunk_start_offset) != Some(&ci.chunk_length) {
                        out.problems.push(format!(
                            "the summary indexes a chunk of {} bytes at byte offset {}, which is not a chunk record \
                             of that length",
                            ci.chunk_length, ci.chunk_start_offset
                        ));
                    }
                }
                if self.summary.chunk_indexes.len() != chunk_spans.len() {
                    out.problems.push(format!(
                        "the file has {} chunk(s), the summary indexes {}",
                        chunk_spans.len(),
                        self.summary.chunk_indexes.len()
                    ));
                }
            }
        }
        out
    }
}
