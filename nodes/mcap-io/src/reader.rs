//! [`McapReader`]: memory-mapped reading of complete (indexed) and unfinished (linear) files.

use std::{
    collections::{BTreeMap, HashMap},
    fs::File,
    io::Read,
    ops::Deref,
    path::{Path, PathBuf},
    sync::Arc,
};

use mcap::{
    read::parse_record,
    records::{op, ChunkIndex, MessageHeader, Record},
    sans_io::{
        IndexedReadEvent, IndexedReader, IndexedReaderOptions, LinearReadEvent, LinearReader, LinearReaderOptions,
    },
    Channel, McapError, Schema, Summary, MAGIC,
};
use memmap2::Mmap;

use crate::McapIoError;

/// A message read back from a file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InMessage {
    pub topic: String,
    /// Empty if the channel has no schema.
    pub schema_name: String,
    pub message_encoding: String,
    pub channel_metadata: BTreeMap<String, String>,
    pub sequence: u32,
    pub log_time: u64,
    pub publish_time: u64,
    pub data: Vec<u8>,
}

/// Which messages [`McapReader::messages`] returns.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ReadOptions {
    /// Only these topics; `None` = all.
    pub topics: Option<Vec<String>>,
    /// Only messages with `log_time >= start_time`.
    pub start_time: Option<u64>,
    /// Only messages with `log_time < end_time` (exclusive, like the mcap CLI and Python
    /// library).
    pub end_time: Option<u64>,
}

/// One channel of a file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicInfo {
    pub topic: String,
    /// Empty if the channel has no schema.
    pub schema_name: String,
    pub message_encoding: String,
    /// Number of messages, if known (from the statistics of a complete file, or counted while
    /// scanning an unfinished one).
    pub message_count: Option<u64>,
}

/// Where a record lies in the file: `[offset, offset + len)`, opcode and length prefix included.
#[derive(Debug, Clone, Copy)]
struct Span {
    offset: u64,
    len: u64,
}

#[derive(Debug, Clone)]
struct AttachmentInfo {
    span: Span,
    log_time: u64,
    create_time: u64,
    name: String,
    media_type: String,
}

/// An attachment with its timestamps (for [`crate::recover`]).
pub(crate) struct FullAttachment {
    pub log_time: u64,
    pub create_time: u64,
    pub name: String,
    pub media_type: String,
    pub data: Vec<u8>,
}

/// Reads an MCAP file through a memory map.
///
/// The file must not be truncated by another process while it is open (that would fault the
/// mapping); a file that is still growing is fine, the reader sees it as it was at `open`.
pub struct McapReader {
    path: PathBuf,
    pub(crate) mmap: Mmap,
    pub(crate) complete: bool,
    profile: String,
    /// Channels, schemas and the chunk index: the file's own summary, or (linear mode) one
    /// rebuilt by scanning the file; chunk start times adjusted by [`tie_safe`].
    pub(crate) summary: Summary,
    message_counts: Option<BTreeMap<u16, u64>>,
    metadata: Vec<(String, BTreeMap<String, String>)>,
    attachments: Vec<AttachmentInfo>,
    /// Linear mode: synthetic chunks made of runs of top-level (unchunked) message records, by
    /// the data offset the indexed reader asks for -> where the records really are.
    virtual_chunks: HashMap<u64, Span>,
    /// End of the last intact record (the file length for complete files).
    valid_end: u64,
}

impl std::fmt::Debug for McapReader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapReader")
            .field("path", &self.path)
            .field("len", &self.mmap.len())
            .field("complete", &self.complete)
            .field("channels", &self.summary.channels.len())
            .field("chunks", &self.summary.chunk_indexes.len())
            .finish_non_exhaustive()
    }
}

impl McapReader {
    /// Opens and maps `path`. Fails with [`McapIoError::NotMcap`] if it does not start with the
    /// MCAP magic. A file without a valid footer and summary opens in linear mode (see the crate
    /// docs); [`Self::is_complete`] tells which.
    pub fn open(path: &Path) -> Result<Self, McapIoError> {
        let mut file = File::open(path).map_err(|e| McapIoError::io(path, e))?;
        let mut magic = [0u8; 8];
        let mut got = 0;
        while got < magic.len() {
            match file.read(&mut magic[got..]) {
                Ok(0) => break,
                Ok(n) => got += n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(McapIoError::io(path, e)),
            }
        }
        if got < MAGIC.len() || magic[..] != *MAGIC {
            return Err(McapIoError::NotMcap { path: path.to_path_buf() });
        }
        // SAFETY: the map is read-only and private to this reader. Like every reader of a
        // memory-mapped file we rely on no other process truncating the file while it is mapped
        // (documented on `McapReader`); appending to it is harmless.
        let mmap = unsafe { Mmap::map(&file) }.map_err(|e| McapIoError::io(path, e))?;
        let data: &[u8] = &mmap;
        let profile = read_profile(data);

        if let Some(indexed) = try_indexed(data) {
            let message_counts = indexed.summary.stats.as_ref().map(|s| s.channel_message_counts.clone());
            return Ok(Self {
                path: path.to_path_buf(),
                complete: true,
                profile,
                summary: tie_safe(indexed.summary),
                message_counts,
                metadata: indexed.metadata,
                attachments: indexed.attachments,
                virtual_chunks: HashMap::new(),
                valid_end: data.len() as u64,
                mmap,
            });
        }

        let scan = scan_linear(data);
        let summary = Summary {
            stats: None,
            channels: scan.channels,
            schemas: scan.schemas,
            chunk_indexes: scan.chunk_indexes,
            attachment_indexes: Vec::new(),
            metadata_indexes: Vec::new(),
        };
        Ok(Self {
            path: path.to_path_buf(),
            complete: false,
            profile,
            summary: tie_safe(summary),
            message_counts: Some(scan.message_counts),
            metadata: scan.metadata,
            attachments: scan.attachments,
            virtual_chunks: scan.virtual_chunks,
            valid_end: scan.valid_end,
            mmap,
        })
    }

    /// The file this reader was opened on.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// `true` if the file had a valid footer and summary (it was finished).
    pub fn is_complete(&self) -> bool {
        self.complete
    }

    /// The profile of the MCAP header record ("sonoflow" for our recordings).
    pub fn profile(&self) -> &str {
        &self.profile
    }

    /// File size in bytes.
    pub fn file_len(&self) -> u64 {
        self.mmap.len() as u64
    }

    /// Bytes after the last intact record, which linear mode ignores (0 for complete files).
    pub fn truncated_bytes(&self) -> u64 {
        self.file_len().saturating_sub(self.valid_end)
    }

    /// For an unfinished file, one sentence on what could be read, for a warning: "PATH is
    /// unfinished (no summary: ...): N message(s) read from K complete chunk(s); the last B
    /// byte(s) are unreadable". `None` for a complete file.
    pub fn unfinished_note(&self) -> Option<String> {
        if self.complete {
            return None;
        }
        let messages: u64 = self.message_counts.iter().flat_map(|m| m.values()).sum();
        Some(format!(
            "{} is unfinished (no summary: its writer was killed or the copy was cut short): {messages} message(s) \
             read from {} complete chunk(s); the last {} byte(s) are unreadable",
            self.path.display(),
            self.summary.chunk_indexes.len(),
            self.truncated_bytes()
        ))
    }

    /// The channels, ordered by channel id.
    pub fn topics(&self) -> Vec<TopicInfo> {
        let mut ids: Vec<u16> = self.summary.channels.keys().copied().collect();
        ids.sort_unstable();
        ids.into_iter()
            .filter_map(|id| self.summary.channels.get(&id).map(|c| (id, c)))
            .map(|(id, c)| TopicInfo {
                topic: c.topic.clone(),
                schema_name: c.schema.as_ref().map(|s| s.name.clone()).unwrap_or_default(),
                message_encoding: c.message_encoding.clone(),
                message_count: self.message_counts.as_ref().map(|m| m.get(&id).copied().unwrap_or(0)),
            })
            .collect()
    }

    /// The metadata records, in file order.
    pub fn metadata(&self) -> Vec<(String, BTreeMap<String, String>)> {
        self.metadata.clone()
    }

    /// The attachments as (name, media type, data), in file order.
    pub fn attachments(&self) -> Vec<(String, String, Vec<u8>)> {
        self.full_attachments().into_iter().map(|a| (a.name, a.media_type, a.data)).collect()
    }

    pub(crate) fn full_attachments(&self) -> Vec<FullAttachment> {
        self.attachments
            .iter()
            .filter_map(|a| {
                let data = attachment_data(&self.mmap, a.span)?;
                Some(FullAttachment {
                    log_time: a.log_time,
                    create_time: a.create_time,
                    name: a.name.clone(),
                    media_type: a.media_type.clone(),
                    data,
                })
            })
            .collect()
    }

    pub(crate) fn schemas(&self) -> Vec<Arc<Schema<'static>>> {
        let mut v: Vec<_> = self.summary.schemas.values().cloned().collect();
        v.sort_by_key(|s| s.id);
        v
    }

    pub(crate) fn channels(&self) -> Vec<Arc<Channel<'static>>> {
        let mut v: Vec<_> = self.summary.channels.values().cloned().collect();
        v.sort_by_key(|c| c.id);
        v
    }

    /// The selected messages in `log_time` order (ties in file order). On an unfinished file
    /// these are the messages of all complete chunks; the cut-off tail is no error.
    pub fn messages(&self, opts: &ReadOptions) -> Result<MessageIter<'_>, McapIoError> {
        Ok(MessageIter { raw: raw_iter(self, opts)? })
    }

    /// [`Self::messages`] from a shared reader: the iterator owns a clone of the `Arc` instead
    /// of a borrow (for callers that cannot hold one, such as the Python bindings).
    pub fn shared_messages(self: &Arc<Self>, opts: &ReadOptions) -> Result<SharedMessageIter, McapIoError> {
        Ok(SharedMessageIter { raw: raw_iter(Arc::clone(self), opts)? })
    }

    /// Like [`Self::messages`], but yields headers and payloads only (for [`crate::recover`]).
    pub(crate) fn raw_messages(&self, opts: &ReadOptions) -> Result<RawIter<&Self>, McapIoError> {
        raw_iter(self, opts)
    }

    fn chunk_data(&self, offset: u64, length: usize) -> Result<&[u8], McapIoError> {
        let start = match self.virtual_chunks.get(&offset) {
            Some(span) => span.offset,
            None => offset,
        };
        usize::try_from(start)
            .ok()
            .and_then(|s| self.mmap.get(s..s.checked_add(length)?))
            .ok_or(McapIoError::Mcap(McapError::BadIndex))
    }

    fn in_message(&self, header: &MessageHeader, data: Vec<u8>) -> Result<InMessage, McapIoError> {
        let channel = self
            .summary
            .channels
            .get(&header.channel_id)
            .ok_or(McapIoError::Mcap(McapError::UnknownChannel(header.sequence, header.channel_id)))?;
        Ok(InMessage {
            topic: channel.topic.clone(),
            schema_name: channel.schema.as_ref().map(|s| s.name.clone()).unwrap_or_default(),
            message_encoding: channel.message_encoding.clone(),
            channel_metadata: channel.metadata.clone(),
            sequence: header.sequence,
            log_time: header.log_time,
            publish_time: header.publish_time,
            data,
        })
    }
}

/// The raw iterator over `reader` (a borrow or an `Arc`) for `opts`.
fn raw_iter<R: Deref<Target = McapReader>>(reader: R, opts: &ReadOptions) -> Result<RawIter<R>, McapIoError> {
    let mut iopts = IndexedReaderOptions::new();
    if let Some(topics) = &opts.topics {
        // The indexed reader treats "no matching channel" as "no filter": short-circuit.
        if !reader.summary.channels.values().any(|c| topics.contains(&c.topic)) {
            return Ok(RawIter { reader, inner: None });
        }
        iopts = iopts.include_topics(topics.iter().cloned());
    }
    if let Some(start) = opts.start_time {
        iopts = iopts.starting_at(start);
    }
    if let Some(end) = opts.end_time {
        iopts = iopts.ending_before(end);
    }
    let inner = IndexedReader::new_with_options(&reader.summary, iopts)?;
    Ok(RawIter { reader, inner: Some(inner) })
}

/// The next message of `raw` as an [`InMessage`]; ends the iteration after an error.
fn next_message<R: Deref<Target = McapReader>>(raw: &mut RawIter<R>) -> Option<Result<InMessage, McapIoError>> {
    let (header, data) = match raw.next()? {
        Ok(m) => m,
        Err(e) => return Some(Err(e)),
    };
    let msg = raw.reader.in_message(&header, data);
    if msg.is_err() {
        raw.inner = None;
    }
    Some(msg)
}

/// Iterator returned by [`McapReader::messages`]. Ends after the first error.
pub struct MessageIter<'a> {
    raw: RawIter<&'a McapReader>,
}

impl Iterator for MessageIter<'_> {
    type Item = Result<InMessage, McapIoError>;

    fn next(&mut self) -> Option<Self::Item> {
        next_message(&mut self.raw)
    }
}

/// Iterator returned by [`McapReader::shared_messages`]: [`MessageIter`] owning its reader.
pub struct SharedMessageIter {
    raw: RawIter<Arc<McapReader>>,
}

impl Iterator for SharedMessageIter {
    type Item = Result<InMessage, McapIoError>;

    fn next(&mut self) -> Option<Self::Item> {
        next_message(&mut self.raw)
    }
}

/// Messages as (header, payload), in log-time order. Ends after the first error.
pub(crate) struct RawIter<R: Deref<Target = McapReader>> {
    reader: R,
    inner: Option<IndexedReader>,
}

impl<R: Deref<Target = McapReader>> Iterator for RawIter<R> {
    type Item = Result<(MessageHeader, Vec<u8>), McapIoError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            let inner = self.inner.as_mut()?;
            let event = match inner.next_event() {
                None => {
                    self.inner = None;
                    return None;
                }
                Some(Err(e)) => Err(McapIoError::Mcap(e)),
                Some(Ok(IndexedReadEvent::Message { header, data })) => {
                    return Some(Ok((header, data.to_vec())));
                }
                Some(Ok(IndexedReadEvent::ReadChunkRequest { offset, length })) => {
                    match self.reader.chunk_data(offset, length) {
                        Ok(chunk) => inner.insert_chunk_record_data(offset, chunk).map_err(McapIoError::Mcap),
                        Err(e) => Err(e),
                    }
                }
            };
            if let Err(e) = event {
                self.inner = None;
                return Some(Err(e));
            }
        }
    }
}

/// `summary` with its chunk indexes starting one nanosecond early.
///
/// mcap's `IndexedReader` yields a message at log time `t` once the next chunk to load (chunks
/// are loaded in (start time, file offset) order) starts at or after `t`. A chunk starting
/// exactly at `t` but placed earlier in the file than the chunk being read is then loaded too
/// late, and its messages at `t` come out after later ones: ties would not be in file order.
/// Starting every chunk at `start - 1` makes the reader load all chunks that can hold a message
/// at `t` before yielding it. (At `t == 0` the order of chunks starting at 0 is file order, so
/// the saturation is harmless.) Time filtering still happens per message, so at most one extra
/// chunk is decompressed.
fn tie_safe(mut summary: Summary) -> Summary {
    for ci in &mut summary.chunk_indexes {
        ci.message_start_time = ci.message_start_time.saturating_sub(1);
    }
    summary
}

/// The profile from the header record, which must directly follow the magic.
fn read_profile(data: &[u8]) -> String {
    let Some((opcode, body, _)) = record_at(data, MAGIC.len()) else {
        return String::new();
    };
    match parse_record(opcode, body) {
        Ok(Record::Header(h)) => h.profile,
        _ => String::new(),
    }
}

/// The record at `pos`: (opcode, body, end offset), or `None` if it runs past the end of `data`.
pub(crate) fn record_at(data: &[u8], pos: usize) -> Option<(u8, &[u8], usize)> {
    let head = data.get(pos..pos.checked_add(9)?)?;
    let opcode = head[0];
    let mut len_bytes = [0u8; 8];
    len_bytes.copy_from_slice(&head[1..9]);
    let len = usize::try_from(u64::from_le_bytes(len_bytes)).ok()?;
    let body_start = pos + 9;
    let end = body_start.checked_add(len)?;
    let body = data.get(body_start..end)?;
    Some((opcode, body, end))
}

fn span_slice(data: &[u8], span: Span) -> Option<&[u8]> {
    let start = usize::try_from(span.offset).ok()?;
    let end = start.checked_add(usize::try_from(span.len).ok()?)?;
    data.get(start..end)
}

fn parse_span(data: &[u8], span: Span) -> Option<Record<'_>> {
    let rec = span_slice(data, span)?;
    let (opcode, body, end) = record_at(rec, 0)?;
    if end != rec.len() {
        return None;
    }
    parse_record(opcode, body).ok()
}

fn attachment_data(data: &[u8], span: Span) -> Option<Vec<u8>> {
    match parse_span(data, span)? {
        Record::Attachment { data, .. } => Some(data.into_owned()),
        _ => None,
    }
}

struct Indexed {
    summary: Summary,
    metadata: Vec<(String, BTreeMap<String, String>)>,
    attachments: Vec<AttachmentInfo>,
}

/// The summary of a complete file, or `None` if the file has no usable footer + summary (then it
/// is read linearly).
fn try_indexed(data: &[u8]) -> Option<Indexed> {
    let summary = Summary::read(data).ok()??;
    let stats = summary.stats.as_ref()?;
    // Without chunk indexes the indexed reader would see no messages at all.
    if summary.chunk_indexes.is_empty() && stats.message_count > 0 {
        return None;
    }
    let len = data.len() as u64;
    for ci in &summary.chunk_indexes {
        let end = ci.chunk_start_offset.checked_add(ci.chunk_length)?;
        if end > len {
            return None;
        }
    }
    if summary.metadata_indexes.len() != stats.metadata_count as usize
        || summary.attachment_indexes.len() != stats.attachment_count as usize
    {
        return None;
    }
    let mut metadata = Vec::new();
    for mi in &summary.metadata_indexes {
        match parse_span(data, Span { offset: mi.offset, len: mi.length })? {
            Record::Metadata(m) => metadata.push((m.name, m.metadata)),
            _ => return None,
        }
    }
    let mut attachments = Vec::new();
    for ai in &summary.attachment_indexes {
        let span = Span { offset: ai.offset, len: ai.length };
        match parse_span(data, span)? {
            Record::Attachment { header, .. } => attachments.push(AttachmentInfo {
                span,
                log_time: header.log_time,
                create_time: header.create_time,
                name: header.name,
                media_type: header.media_type,
            }),
            _ => return None,
        }
    }
    Some(Indexed { summary, metadata, attachments })
}

#[derive(Default)]
struct LinearScan {
    schemas: HashMap<u16, Arc<Schema<'static>>>,
    channels: HashMap<u16, Arc<Channel<'static>>>,
    chunk_indexes: Vec<ChunkIndex>,
    message_counts: BTreeMap<u16, u64>,
    metadata: Vec<(String, BTreeMap<String, String>)>,
    attachments: Vec<AttachmentInfo>,
    virtual_chunks: HashMap<u64, Span>,
    valid_end: u64,
}

/// A run of consecutive top-level message records (files written without chunking).
struct MessageRun {
    start: u64,
    end: u64,
    min_time: u64,
    max_time: u64,
}

/// Schema and channel records met inside one chunk, committed only if the whole chunk is valid.
#[derive(Default)]
struct Pending {
    schemas: Vec<(u16, String, String, Vec<u8>)>,
    channels: Vec<mcap::records::Channel>,
    counts: BTreeMap<u16, u64>,
    bounds: Option<(u64, u64)>,
}

impl LinearScan {
    fn add_schema(&mut self, id: u16, name: String, encoding: String, data: Vec<u8>) -> bool {
        if id == 0 {
            return false;
        }
        match self.schemas.get(&id) {
            Some(s) => s.name == name && s.encoding == encoding && *s.data == *data,
            None => {
                self.schemas.insert(id, Arc::new(Schema { id, name, encoding, data: data.into() }));
                true
            }
        }
    }

    fn add_channel(&mut self, c: mcap::records::Channel) -> bool {
        let schema = if c.schema_id == 0 {
            None
        } else {
            match self.schemas.get(&c.schema_id) {
                Some(s) => Some(s.clone()),
                None => return false,
            }
        };
        match self.channels.get(&c.id) {
            Some(existing) => {
                existing.topic == c.topic
                    && existing.message_encoding == c.message_encoding
                    && existing.metadata == c.metadata
                    && existing.schema.as_ref().map(|s| s.id).unwrap_or(0) == c.schema_id
            }
            None => {
                self.channels.insert(
                    c.id,
                    Arc::new(Channel {
                        id: c.id,
                        topic: c.topic,
                        schema,
                        message_encoding: c.message_encoding,
                        metadata: c.metadata,
                    }),
                );
                true
            }
        }
    }

    fn close_run(&mut self, run: Option<MessageRun>) {
        let Some(run) = run else { return };
        // A synthetic uncompressed chunk whose "records" are the run. Its chunk_start_offset is
        // the run's file offset (unique, and ordered like the file for log-time ties); the
        // indexed reader will ask for the data at chunk_start_offset + header size.
        let index = ChunkIndex {
            message_start_time: run.min_time,
            message_end_time: run.max_time,
            chunk_start_offset: run.start,
            chunk_length: run.end - run.start,
            message_index_offsets: BTreeMap::new(),
            message_index_length: 0,
            compression: String::new(),
            compressed_size: run.end - run.start,
            uncompressed_size: run.end - run.start,
        };
        if let Ok(data_offset) = index.compressed_data_offset() {
            self.virtual_chunks.insert(data_offset, Span { offset: run.start, len: run.end - run.start });
            self.chunk_indexes.push(index);
        }
    }
}

/// The largest uncompressed chunk [`chunk_records`] decodes: a bound on what a corrupt size field
/// can make it allocate.
pub(crate) const MAX_CHUNK_BYTES: usize = 2 << 30;

/// The records inside one chunk; `record` is the whole chunk record (opcode, length, body).
///
/// The chunk is decompressed and its CRC checked before any record is parsed, and sizes are
/// bounded by [`MAX_CHUNK_BYTES`] and by `record` itself, so corrupt data gives an error, never a
/// panic or a huge allocation (`mcap::read::ChunkReader` sets no such bound: a damaged length
/// field inside a chunk makes it attempt the allocation and panic).
pub(crate) fn chunk_records(record: &[u8]) -> Result<Vec<Record<'static>>, McapError> {
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_skip_start_magic(true)
            .with_skip_end_magic(true)
            .with_emit_chunks(false)
            .with_prevalidate_chunk_crcs(true)
            .with_record_length_limit(MAX_CHUNK_BYTES),
    );
    let mut rest = record;
    let mut records = Vec::new();
    while let Some(event) = reader.next_event() {
        match event? {
            LinearReadEvent::ReadRequest(need) => {
                let n = need.min(rest.len());
                reader.insert(n).copy_from_slice(&rest[..n]);
                reader.notify_read(n);
                rest = &rest[n..];
            }
            LinearReadEvent::Record { data, opcode } => records.push(parse_record(opcode, data)?.into_owned()),
        }
    }
    Ok(records)
}

/// Decompresses and CRC-checks one chunk (`record`: the whole chunk record), collecting its
/// schemas, channels and message stats.
fn scan_chunk(record: &[u8]) -> Option<Pending> {
    let mut pending = Pending::default();
    for record in chunk_records(record).ok()? {
        match record {
            Record::Schema { header, data } => {
                pending.schemas.push((header.id, header.name, header.encoding, data.into_owned()));
            }
            Record::Channel(c) => pending.channels.push(c),
            Record::Message { header, .. } => {
                *pending.counts.entry(header.channel_id).or_insert(0) += 1;
                let t = header.log_time;
                pending.bounds = Some(match pending.bounds {
                    None => (t, t),
                    Some((lo, hi)) => (lo.min(t), hi.max(t)),
                });
            }
            _ => {}
        }
    }
    Some(pending)
}

/// Walks the records of an unfinished file from the start and stops at the first truncated or
/// corrupt one (or at the data end record).
fn scan_linear(data: &[u8]) -> LinearScan {
    let mut scan = LinearScan::default();
    let mut pos = MAGIC.len();
    let mut run: Option<MessageRun> = None;
    while let Some((opcode, body, end)) = record_at(data, pos) {
        let mut ok = true;
        let mut done = false;
        if opcode != op::MESSAGE {
            scan.close_run(run.take());
        }
        match opcode {
            0 => ok = false,
            op::CHUNK => match parse_record(opcode, body) {
                Ok(Record::Chunk { header, .. }) => {
                    let compression = header.compression.clone();
                    let compressed_size = header.compressed_size;
                    let uncompressed_size = header.uncompressed_size;
                    match scan_chunk(&data[pos..end]) {
                        Some(p) => {
                            for (id, name, encoding, bytes) in p.schemas {
                                ok &= scan.add_schema(id, name, encoding, bytes);
                            }
                            for c in p.channels {
                                ok &= scan.add_channel(c);
                            }
                            if ok {
                                for (id, n) in p.counts {
                                    *scan.message_counts.entry(id).or_insert(0) += n;
                                }
                                let (lo, hi) = p.bounds.unwrap_or((0, 0));
                                scan.chunk_indexes.push(ChunkIndex {
                                    message_start_time: lo,
                                    message_end_time: hi,
                                    chunk_start_offset: pos as u64,
                                    chunk_length: (end - pos) as u64,
                                    message_index_offsets: BTreeMap::new(),
                                    message_index_length: 0,
                                    compression,
                                    compressed_size,
                                    uncompressed_size,
                                });
                            }
                        }
                        None => ok = false,
                    }
                }
                _ => ok = false,
            },
            op::MESSAGE => match parse_record(opcode, body) {
                Ok(Record::Message { header, .. }) => {
                    *scan.message_counts.entry(header.channel_id).or_insert(0) += 1;
                    let t = header.log_time;
                    match &mut run {
                        Some(r) if r.end == pos as u64 => {
                            r.end = end as u64;
                            r.min_time = r.min_time.min(t);
                            r.max_time = r.max_time.max(t);
                        }
                        _ => {
                            scan.close_run(run.take());
                            run = Some(MessageRun { start: pos as u64, end: end as u64, min_time: t, max_time: t });
                        }
                    }
                }
                _ => ok = false,
            },
            op::SCHEMA => match parse_record(opcode, body) {
                Ok(Record::Schema { header, data }) => {
                    ok = scan.add_schema(header.id, header.name, header.encoding, data.into_owned())
                }
                _ => ok = false,
            },
            op::CHANNEL => match parse_record(opcode, body) {
                Ok(Record::Channel(c)) => ok = scan.add_channel(c),
                _ => ok = false,
            },
            op::METADATA => match parse_record(opcode, body) {
                Ok(Record::Metadata(m)) => scan.metadata.push((m.name, m.metadata)),
                _ => ok = false,
            },
            op::ATTACHMENT => match parse_record(opcode, body) {
                Ok(Record::Attachment { header, .. }) => scan.attachments.push(AttachmentInfo {
                    span: Span { offset: pos as u64, len: (end - pos) as u64 },
                    log_time: header.log_time,
                    create_time: header.create_time,
                    name: header.name,
                    media_type: header.media_type,
                }),
                _ => ok = false,
            },
            // The data section ends here; what follows is the summary.
            op::DATA_END | op::FOOTER => done = true,
            // Message indexes, the header, summary records and private records carry nothing we
            // need in linear mode.
            _ => {}
        }
        if !ok {
            break;
        }
        pos = end;
        if done {
            break;
        }
    }
    scan.close_run(run.take());
    scan.valid_end = pos as u64;
    scan
}
