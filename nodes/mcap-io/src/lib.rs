//! Moves opaque byte messages to and from [MCAP](https://mcap.dev) files.
//!
//! This crate knows nothing about IPC or about sonoflow's wire types: a channel is a topic plus
//! encoding/schema strings, a message is a `Vec<u8>` with a sequence number and two timestamps.
//!
//! # Writing: [`RecorderWriter`]
//!
//! [`RecorderWriter::create`] opens the file (it never overwrites one) and starts a background
//! *writer thread* that owns the [`mcap::Writer`]. [`RecorderWriter::write`],
//! [`attach`](RecorderWriter::attach) and [`metadata`](RecorderWriter::metadata) only enqueue:
//! compression and disk I/O happen on the writer thread, so the caller's hot loop does neither.
//!
//! **Back-pressure.** The queue between caller and writer thread is a bounded crossbeam channel
//! plus a byte counter. A write is admitted when the bytes already queued plus its own payload fit
//! in [`WriterOptions::queue_bytes`] (or when the queue is empty, so a single message larger than
//! the bound still goes through). Otherwise `write` *blocks* until the writer thread has written
//! enough: a slow disk slows the producer down instead of growing RAM without bound, and nothing
//! is ever dropped. If the writer thread fails (disk full, I/O error), every later call returns
//! [`McapIoError::WriterThread`] with the cause, and [`RecorderWriter::finish`] returns the
//! original error.
//!
//! **Chunks and crash safety.** Messages are written into compressed MCAP chunks
//! ([`WriterOptions::compression`], [`chunk_size`](WriterOptions::chunk_size)). An open chunk is
//! assembled in memory (mcap's buffered chunk mode) and reaches the file in one piece when it is
//! closed, so the file on disk always ends at a record boundary or inside the one record being
//! written. Chunks are closed
//! * when adding the next message would exceed `chunk_size` (a single message larger than
//!   `chunk_size` gets a chunk of its own),
//! * at the latest [`WriterOptions::flush_interval`] after the chunk received its first record,
//!   even if nothing else arrives (the writer thread waits on the queue with a deadline),
//! * before attachments and metadata records.
//!
//! The file is a plain unbuffered [`std::fs::File`], so a closed chunk is in the kernel's page
//! cache as soon as it is written: after a `kill -9` of the recording process, the file holds
//! every message up to the last closed chunk, i.e. everything except roughly the last
//! `flush_interval` of data (plus whatever was still queued). Surviving a power loss additionally
//! needs the data to be fsynced, which [`RecorderWriter::finish`] does for the file and its
//! directory.
//!
//! [`RecorderWriter::finish`] drains the queue, writes the summary section (schemas, channels,
//! statistics, chunk/metadata/attachment indexes) and the footer, and fsyncs. Dropping a
//! `RecorderWriter` without calling `finish` also finishes the file (ignoring errors).
//!
//! # Reading: [`McapReader`]
//!
//! [`McapReader::open`] memory-maps the file. A file with a valid footer and summary is read
//! through the summary's chunk index ([`McapReader::is_complete`] is `true`). A file without one
//! (the writer was killed, the disk filled up, the copy was cut short) is opened in *linear* mode:
//! the records are scanned from the start, every chunk is decompressed and CRC-checked once, and
//! the scan stops cleanly at the first truncated or corrupt record. The messages of all complete
//! chunks before that point are then served exactly like those of a complete file: in `log_time`
//! order (ties in file order), filtered by topic and time range, without any error for the cut-off
//! tail.
//!
//! Opening a complete file trusts its summary: chunks are decompressed (and their data checked)
//! only when their messages are read. [`McapReader::verify`] reads the whole file instead, record
//! by record: every chunk decompressed and CRC-checked, the data and summary section CRCs, every
//! message linked to its channel and handed to a caller's check, and the message counts per
//! channel compared with the summary's statistics; each problem names the byte offset of its
//! record. [`McapReader::unfinished_note`] describes what could be read of an unfinished file.
//!
//! [`recover`] rewrites every readable message, schema, channel, metadata record and attachment of
//! a possibly unfinished file into a new, finished (indexed) file, like `mcap recover`.
//!
//! ```no_run
//! use std::{collections::BTreeMap, path::Path};
//! use sonoflow_mcap_io::*;
//!
//! # fn main() -> Result<(), McapIoError> {
//! let mut w = RecorderWriter::create(Path::new("run.mcap"), WriterOptions::default())?;
//! let ch = w.add_channel(ChannelSpec {
//!     topic: "/rf".into(),
//!     message_encoding: "raw-f32".into(),
//!     ..Default::default()
//! })?;
//! w.write(OutMessage { channel: ch, sequence: 0, log_time: 1, publish_time: 1, data: vec![0; 16] })?;
//! w.metadata("run", BTreeMap::from([("seed".to_string(), "42".to_string())]))?;
//! let stats = w.finish()?;
//! assert_eq!(stats.messages_written["/rf"], 1);
//!
//! let r = McapReader::open(Path::new("run.mcap"))?;
//! for m in r.messages(&ReadOptions::default())? {
//!     let m = m?;
//!     println!("{} {} {}", m.topic, m.log_time, m.data.len());
//! }
//! # Ok(())
//! # }
//! ```

mod error;
mod reader;
mod recover;
#[cfg(feature = "testkit")]
pub mod testkit;
pub mod topics;
mod verify;
mod writer;

use std::{fmt, str::FromStr};

use serde::{Deserialize, Serialize};

pub use error::McapIoError;
pub use reader::{InMessage, McapReader, MessageIter, ReadOptions, SharedMessageIter, TopicInfo};
pub use recover::{recover, RecoverStats};
pub use topics::{RecordingSummary, TopicCount, TopicRecorder};
pub use verify::{MessageView, Verification, VerifiedTopic};
pub use writer::{ChannelId, ChannelSpec, OutMessage, RecorderWriter, WriterOptions, WriterStats};

/// Chunk compression of a recording.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Compression {
    /// Chunks are stored uncompressed.
    None,
    /// Zstandard (the default).
    #[default]
    Zstd,
    /// LZ4 frame.
    Lz4,
}

impl Compression {
    /// The name used by [`FromStr`], [`fmt::Display`] and serde.
    pub fn as_str(self) -> &'static str {
        match self {
            Compression::None => "none",
            Compression::Zstd => "zstd",
            Compression::Lz4 => "lz4",
        }
    }

    pub(crate) fn to_mcap(self) -> Option<mcap::Compression> {
        match self {
            Compression::None => None,
            Compression::Zstd => Some(mcap::Compression::Zstd),
            Compression::Lz4 => Some(mcap::Compression::Lz4),
        }
    }
}

impl fmt::Display for Compression {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for Compression {
    type Err = McapIoError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "none" => Ok(Compression::None),
            "zstd" => Ok(Compression::Zstd),
            "lz4" => Ok(Compression::Lz4),
            other => Err(McapIoError::UnknownCompression(other.to_string())),
        }
    }
}
