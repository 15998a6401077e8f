//! [`RecorderWriter`]: a queue in front of an `mcap::Writer` owned by a background thread.

use std::{
    collections::{BTreeMap, HashMap},
    fs::{File, OpenOptions},
    io::{self, Seek, SeekFrom, Write},
    path::{Path, PathBuf},
    sync::{
        atomic::{AtomicU64, Ordering},
        Arc, Condvar, Mutex, MutexGuard, PoisonError,
    },
    thread::JoinHandle,
    time::{Duration, Instant, SystemTime, UNIX_EPOCH},
};

use crossbeam_channel::{Receiver, RecvTimeoutError, Sender};
use mcap::records::{MessageHeader, Metadata};

use crate::{error::error_chain, Compression, McapIoError};

/// Bytes of a message record besides its payload: opcode (1) + length (8) + channel id (2) +
/// sequence (4) + log time (8) + publish time (8).
const MESSAGE_RECORD_OVERHEAD: usize = 31;
/// How many commands the channel between caller and writer thread holds at most (the byte
/// bound, [`WriterOptions::queue_bytes`], is usually the one that bites).
const QUEUE_CAPACITY: usize = 16 * 1024;
/// How often a blocked [`RecorderWriter::write`] re-checks that the writer thread is alive.
const LIVENESS_POLL: Duration = Duration::from_millis(100);

/// Options of a [`RecorderWriter`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WriterOptions {
    /// Chunk compression. Default: zstd.
    pub compression: Compression,
    /// Compression level (zstd: 1..=22, lz4: 0..=12; ignored without compression). Default: 1.
    pub compression_level: u32,
    /// Target uncompressed size of a chunk in bytes. A chunk is closed before a message would
    /// make it larger; a single larger message gets a chunk of its own. Default: 4 MiB.
    pub chunk_size: u64,
    /// The open chunk is closed and written at the latest this long after it received its first
    /// record, so a `kill -9` loses at most about this much data. Default: 1 s.
    pub flush_interval: Duration,
    /// Bound of the in-RAM queue between caller and writer thread, in payload bytes; `write`
    /// blocks while it is full. Default: 256 MiB.
    pub queue_bytes: usize,
    /// The MCAP header's profile. Default: "sonoflow".
    pub profile: String,
}

impl Default for WriterOptions {
    fn default() -> Self {
        Self {
            compression: Compression::Zstd,
            compression_level: 1,
            chunk_size: 4 * 1024 * 1024,
            flush_interval: Duration::from_secs(1),
            queue_bytes: 256 * 1024 * 1024,
            profile: "sonoflow".to_string(),
        }
    }
}

/// A channel (topic) to record.
///
/// A channel whose `schema_name`, `schema_encoding` and `schema_data` are all empty is written
/// without a schema (schema id 0). Schemas are deduplicated by (name, encoding, data); adding an
/// identical spec twice returns the same [`ChannelId`].
#[derive(Debug, Clone, Default, PartialEq, Eq, Hash)]
pub struct ChannelSpec {
    pub topic: String,
    pub message_encoding: String,
    pub schema_name: String,
    pub schema_encoding: String,
    pub schema_data: Vec<u8>,
    pub metadata: BTreeMap<String, String>,
}

impl ChannelSpec {
    fn has_schema(&self) -> bool {
        !(self.schema_name.is_empty() && self.schema_encoding.is_empty() && self.schema_data.is_empty())
    }

    /// Rough uncompressed size of the schema + channel records (for chunk-size accounting).
    fn record_bytes(&self) -> usize {
        let meta: usize = self.metadata.iter().map(|(k, v)| 8 + k.len() + v.len()).sum();
        let channel = 9 + 2 + 2 + 4 + self.topic.len() + 4 + self.message_encoding.len() + 4 + meta;
        let schema = if self.has_schema() {
            9 + 2 + 4 + self.schema_name.len() + 4 + self.schema_encoding.len() + 4 + self.schema_data.len()
        } else {
            0
        };
        channel + schema
    }
}

/// Identifies a channel of one [`RecorderWriter`] (it is the MCAP channel id).
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash)]
pub struct ChannelId(pub u16);

/// A message to record.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OutMessage {
    pub channel: ChannelId,
    pub sequence: u32,
    /// Nanoseconds; messages are read back ordered by this.
    pub log_time: u64,
    pub publish_time: u64,
    pub data: Vec<u8>,
}

/// Progress counters of a [`RecorderWriter`].
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct WriterStats {
    /// Messages handed to the MCAP writer so far, per topic (channels sharing a topic are
    /// summed). After [`RecorderWriter::finish`] this is what the file contains.
    pub messages_written: BTreeMap<String, u64>,
    /// Payload bytes of those messages.
    pub bytes_written: u64,
    /// Bytes in the file so far (chunks still being assembled in memory not included).
    pub file_bytes: u64,
    /// Payload bytes accepted by `write`/`attach` and not yet handed to the MCAP writer.
    pub bytes_queued: u64,
}

enum Command {
    AddChannel { id: u16, spec: ChannelSpec, cost: usize },
    Message { msg: OutMessage, cost: usize },
    Attach { name: String, media_type: String, data: Vec<u8>, time: u64, cost: usize },
    Metadata { name: String, map: BTreeMap<String, String> },
    Finish,
    Abandon,
}

/// State shared by the caller side and the writer thread.
struct Shared {
    /// Payload bytes queued (admitted by `write` and not yet written by the thread).
    queued: Mutex<usize>,
    /// Signalled whenever `queued` shrinks or the thread stops.
    space: Condvar,
    /// Set (with the error and its causes) when the writer thread failed.
    failure: Mutex<Option<String>>,
    /// Messages written per channel id (index = id).
    counts: Mutex<Vec<u64>>,
    bytes_written: AtomicU64,
    file_bytes: AtomicU64,
    /// Message buffers handed back by the writer thread for reuse (see [`RecorderWriter::buffer`]).
    pool: Mutex<Vec<Vec<u8>>>,
}

/// At most this many buffers are kept for reuse.
const POOL_BUFFERS: usize = 16;

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

impl Shared {
    fn release(&self, cost: usize) {
        if cost == 0 {
            return;
        }
        let mut q = lock(&self.queued);
        *q = q.saturating_sub(cost);
        drop(q);
        self.space.notify_all();
    }

    fn failure(&self) -> Option<String> {
        lock(&self.failure).clone()
    }
}

/// Records messages into an MCAP file from a background writer thread. See the crate docs.
///
/// `write`, `attach`, `metadata` and `stats` take `&self`, so one writer can be shared by several
/// producer threads (e.g. with `std::thread::scope` or an `Arc`).
pub struct RecorderWriter {
    path: PathBuf,
    queue_bytes: usize,
    tx: Option<Sender<Command>>,
    thread: Option<JoinHandle<Result<(), McapIoError>>>,
    shared: Arc<Shared>,
    /// Topic of channel id `i + 1`.
    topics: Vec<String>,
    known_specs: HashMap<ChannelSpec, ChannelId>,
}

impl RecorderWriter {
    /// Creates `path` (which must not exist yet), writes the MCAP header and starts the writer
    /// thread.
    pub fn create(path: &Path, opts: WriterOptions) -> Result<Self, McapIoError> {
        Self::create_impl(path, opts, u64::MAX)
    }

    /// `create`, with writes past `fail_at` bytes failing (fault injection for tests).
    fn create_impl(path: &Path, opts: WriterOptions, fail_at: u64) -> Result<Self, McapIoError> {
        let file = OpenOptions::new().write(true).create_new(true).open(path).map_err(|e| {
            if e.kind() == io::ErrorKind::AlreadyExists {
                McapIoError::AlreadyExists { path: path.to_path_buf() }
            } else {
                McapIoError::io(path, e)
            }
        })?;
        let shared = Arc::new(Shared {
            queued: Mutex::new(0),
            space: Condvar::new(),
            failure: Mutex::new(None),
            counts: Mutex::new(Vec::new()),
            bytes_written: AtomicU64::new(0),
            file_bytes: AtomicU64::new(0),
            pool: Mutex::new(Vec::new()),
        });
        let sink = FileSink { file, pos: 0, fail_at, shared: shared.clone() };
        let writer = mcap_write_options(&opts).create(sink).map_err(|e| mcap_error(path, e))?;

        let (tx, rx) = crossbeam_channel::bounded(QUEUE_CAPACITY);
        let thread_state = WriterThread {
            path: path.to_path_buf(),
            writer: Some(writer),
            rx,
            shared: shared.clone(),
            chunk_size: opts.chunk_size,
            flush_interval: opts.flush_interval,
            chunk_bytes: 0,
            chunk_opened: None,
        };
        let thread = std::thread::Builder::new()
            .name("mcap-writer".into())
            .spawn(move || thread_state.run())
            .map_err(|e| McapIoError::io(path, e))?;
        Ok(Self {
            path: path.to_path_buf(),
            queue_bytes: opts.queue_bytes,
            tx: Some(tx),
            thread: Some(thread),
            shared,
            topics: Vec::new(),
            known_specs: HashMap::new(),
        })
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Registers a channel (and its schema, deduplicated by name, encoding and data). Adding an
    /// identical spec again returns the same id.
    pub fn add_channel(&mut self, spec: ChannelSpec) -> Result<ChannelId, McapIoError> {
        if let Some(id) = self.known_specs.get(&spec) {
            return Ok(*id);
        }
        let id = u16::try_from(self.topics.len() + 1).map_err(|_| McapIoError::TooManyChannels)?;
        let cost = spec.record_bytes();
        self.reserve(cost)?;
        self.topics.push(spec.topic.clone());
        self.known_specs.insert(spec.clone(), ChannelId(id));
        self.send(Command::AddChannel { id, spec, cost })?;
        Ok(ChannelId(id))
    }

    /// Queues a message. Blocks while the queue is full (see [`WriterOptions::queue_bytes`]);
    /// never drops. Fails if the channel is unknown or the writer thread has failed.
    pub fn write(&self, msg: OutMessage) -> Result<(), McapIoError> {
        let id = msg.channel.0;
        if id == 0 || usize::from(id) > self.topics.len() {
            return Err(McapIoError::UnknownChannel(id));
        }
        let cost = msg.data.len() + MESSAGE_RECORD_OVERHEAD;
        self.reserve(cost)?;
        self.send(Command::Message { msg, cost })
    }

    /// Queues an attachment (a file embedded in the recording, e.g. the run configuration).
    /// Its log and create times are the current wall-clock time.
    pub fn attach(&self, name: &str, media_type: &str, data: Vec<u8>) -> Result<(), McapIoError> {
        let cost = data.len() + 64 + name.len() + media_type.len();
        self.reserve(cost)?;
        self.send(Command::Attach {
            name: name.to_string(),
            media_type: media_type.to_string(),
            data,
            time: now_ns(),
            cost,
        })
    }

    /// An empty buffer with at least `capacity` bytes reserved, reused from messages already
    /// written when possible (fill it and pass it as [`OutMessage::data`]).
    pub fn buffer(&self, capacity: usize) -> Vec<u8> {
        let mut pool = lock(&self.shared.pool);
        let mut buf = match pool.iter().position(|b| b.capacity() >= capacity) {
            Some(i) => pool.swap_remove(i),
            None => pool.pop().unwrap_or_default(),
        };
        drop(pool);
        buf.clear();
        buf.reserve(capacity);
        buf
    }

    /// Queues a metadata record (a named string map).
    pub fn metadata(&self, name: &str, map: BTreeMap<String, String>) -> Result<(), McapIoError> {
        self.check_alive()?;
        self.send(Command::Metadata { name: name.to_string(), map })
    }

    /// Current counters (cheap: a few atomics and a short mutex).
    pub fn stats(&self) -> WriterStats {
        let mut messages_written = BTreeMap::new();
        {
            let counts = lock(&self.shared.counts);
            for (i, topic) in self.topics.iter().enumerate() {
                let n = counts.get(i + 1).copied().unwrap_or(0);
                *messages_written.entry(topic.clone()).or_insert(0) += n;
            }
        }
        WriterStats {
            messages_written,
            bytes_written: self.shared.bytes_written.load(Ordering::Relaxed),
            file_bytes: self.shared.file_bytes.load(Ordering::Relaxed),
            bytes_queued: *lock(&self.shared.queued) as u64,
        }
    }

    /// Drains the queue, writes the summary section and footer, fsyncs the file and its
    /// directory, and returns the final counters.
    pub fn finish(mut self) -> Result<WriterStats, McapIoError> {
        self.stop(Command::Finish)?;
        Ok(self.stats())
    }

    /// Simulates a crash (`kill -9`) for tests: the writer thread writes everything queued
    /// before this call, then stops *without* closing the open chunk and without writing the
    /// summary and footer. The file is left unfinished, ending after the last closed chunk.
    #[doc(hidden)]
    pub fn abandon(mut self) -> Result<(), McapIoError> {
        self.stop(Command::Abandon)
    }

    fn stop(&mut self, cmd: Command) -> Result<(), McapIoError> {
        let Some(thread) = self.thread.take() else {
            return Err(McapIoError::Closed);
        };
        if let Some(tx) = self.tx.take() {
            // A send error means the thread is gone already; join() tells why.
            let _ = tx.send(cmd);
        }
        match thread.join() {
            Ok(result) => result,
            Err(_) => Err(McapIoError::WriterThread("the writer thread panicked".to_string())),
        }
    }

    fn send(&self, cmd: Command) -> Result<(), McapIoError> {
        let tx = self.tx.as_ref().ok_or(McapIoError::Closed)?;
        tx.send(cmd).map_err(|_| self.thread_gone())
    }

    fn thread_gone(&self) -> McapIoError {
        match self.shared.failure() {
            Some(cause) => McapIoError::WriterThread(cause),
            None => McapIoError::WriterThread("the writer thread has stopped".to_string()),
        }
    }

    fn check_alive(&self) -> Result<(), McapIoError> {
        if let Some(cause) = self.shared.failure() {
            return Err(McapIoError::WriterThread(cause));
        }
        match &self.thread {
            Some(t) if !t.is_finished() => Ok(()),
            Some(_) => Err(self.thread_gone()),
            None => Err(McapIoError::Closed),
        }
    }

    /// Admits `cost` bytes into the queue, blocking while it is full.
    fn reserve(&self, cost: usize) -> Result<(), McapIoError> {
        let mut queued = lock(&self.shared.queued);
        loop {
            self.check_alive()?;
            if *queued == 0 || queued.saturating_add(cost) <= self.queue_bytes {
                *queued += cost;
                return Ok(());
            }
            queued = self.shared.space.wait_timeout(queued, LIVENESS_POLL).unwrap_or_else(PoisonError::into_inner).0;
        }
    }
}

impl Drop for RecorderWriter {
    /// Finishes the file if neither `finish` nor `abandon` was called (errors are ignored).
    fn drop(&mut self) {
        if self.thread.is_some() {
            let _ = self.stop(Command::Finish);
        }
    }
}

fn mcap_write_options(opts: &WriterOptions) -> mcap::WriteOptions {
    let mut w = mcap::WriteOptions::new()
        .profile(opts.profile.clone())
        .library(format!("sonoflow-mcap-io/{} ({})", env!("CARGO_PKG_VERSION"), mcap::LIBRARY_IDENTIFIER))
        .compression(opts.compression.to_mcap())
        // Chunks are closed by the writer thread (size, flush interval), never by mcap itself.
        .chunk_size(None)
        // Buffered chunk mode: a chunk is assembled in memory and written in one piece when it
        // is closed, so the file never holds a half-written chunk with a placeholder header.
        .disable_seeking(true)
        // Compress on the writer thread only; no zstd worker pool.
        .compression_threads(0);
    if opts.compression != Compression::None {
        w = w.compression_level(opts.compression_level);
    }
    w
}

pub(crate) fn mcap_error(path: &Path, e: mcap::McapError) -> McapIoError {
    match e {
        mcap::McapError::Io(source) => McapIoError::io(path, source),
        other => McapIoError::Mcap(other),
    }
}

fn now_ns() -> u64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map(|d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)).unwrap_or(0)
}

/// Flushes and fsyncs `file`, then fsyncs the directory holding `path` so the new directory
/// entry survives a power loss too.
pub(crate) fn sync_file_and_dir(file: &File, path: &Path) -> Result<(), McapIoError> {
    file.sync_all().map_err(|e| McapIoError::io(path, e))?;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    File::open(dir).and_then(|d| d.sync_all()).map_err(|e| McapIoError::io(dir, e))
}

/// The writer's output: an unbuffered file that tracks its own position (so `stream_position`
/// costs no syscall) and publishes the byte count for [`WriterStats::file_bytes`].
struct FileSink {
    file: File,
    pos: u64,
    /// Writes reaching past this offset fail (`u64::MAX` except in fault-injection tests).
    fail_at: u64,
    shared: Arc<Shared>,
}

impl Write for FileSink {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        if self.pos.saturating_add(buf.len() as u64) > self.fail_at {
            return Err(io::Error::other("injected write failure"));
        }
        let n = self.file.write(buf)?;
        self.pos += n as u64;
        self.shared.file_bytes.store(self.pos, Ordering::Relaxed);
        Ok(n)
    }

    fn flush(&mut self) -> io::Result<()> {
        // Nothing is buffered here: every write went to the kernel already.
        Ok(())
    }
}

impl Seek for FileSink {
    fn seek(&mut self, pos: SeekFrom) -> io::Result<u64> {
        self.pos = self.file.seek(pos)?;
        Ok(self.pos)
    }

    fn stream_position(&mut self) -> io::Result<u64> {
        Ok(self.pos)
    }
}

struct WriterThread {
    path: PathBuf,
    writer: Option<mcap::Writer<FileSink>>,
    rx: Receiver<Command>,
    shared: Arc<Shared>,
    chunk_size: u64,
    flush_interval: Duration,
    /// Uncompressed bytes in the open chunk (0: no chunk open).
    chunk_bytes: u64,
    /// When the open chunk received its first record.
    chunk_opened: Option<Instant>,
}

enum Exit {
    Finish,
    Abandon,
}

impl WriterThread {
    fn run(mut self) -> Result<(), McapIoError> {
        let result = self.run_inner();
        if let Err(e) = &result {
            *lock(&self.shared.failure) = Some(error_chain(e));
            // Let the caller fail fast instead of filling a queue nobody drains.
            drop(std::mem::replace(&mut self.rx, crossbeam_channel::never()));
        }
        self.shared.space.notify_all();
        result
    }

    fn run_inner(&mut self) -> Result<(), McapIoError> {
        let exit = loop {
            let deadline = self.chunk_opened.and_then(|t| t.checked_add(self.flush_interval));
            let cmd = match deadline {
                Some(deadline) => match self.rx.recv_deadline(deadline) {
                    Ok(cmd) => cmd,
                    Err(RecvTimeoutError::Timeout) => {
                        self.close_chunk()?;
                        continue;
                    }
                    // All senders gone without a Finish/Abandon: finish, like mcap's Drop.
                    Err(RecvTimeoutError::Disconnected) => break Exit::Finish,
                },
                None => match self.rx.recv() {
                    Ok(cmd) => cmd,
                    Err(_) => break Exit::Finish,
                },
            };
            match cmd {
                Command::Finish => break Exit::Finish,
                Command::Abandon => break Exit::Abandon,
                cmd => self.handle(cmd)?,
            }
            if self.chunk_opened.is_some_and(|t| t.elapsed() >= self.flush_interval) {
                self.close_chunk()?;
            }
        };
        let mut writer = self.writer.take().ok_or(McapIoError::Closed)?;
        match exit {
            Exit::Finish => {
                writer.finish().map_err(|e| mcap_error(&self.path, e))?;
                let sink = writer.into_inner();
                sync_file_and_dir(&sink.file, &self.path)?;
                let len = sink.file.metadata().map_err(|e| McapIoError::io(&self.path, e))?.len();
                self.shared.file_bytes.store(len, Ordering::Relaxed);
            }
            Exit::Abandon => {
                // into_inner() hands the file back without finishing the open chunk (which only
                // lives in memory) and without writing the summary: the on-disk state a
                // `kill -9` would leave.
                drop(writer.into_inner());
            }
        }
        Ok(())
    }

    fn writer(&mut self) -> Result<&mut mcap::Writer<FileSink>, McapIoError> {
        self.writer.as_mut().ok_or(McapIoError::Closed)
    }

    fn handle(&mut self, cmd: Command) -> Result<(), McapIoError> {
        let path = self.path.clone();
        let err = |e| mcap_error(&path, e);
        match cmd {
            Command::AddChannel { id, spec, cost } => {
                let w = self.writer()?;
                let schema_id = if spec.has_schema() {
                    w.add_schema(&spec.schema_name, &spec.schema_encoding, &spec.schema_data).map_err(err)?
                } else {
                    0
                };
                w.add_channel_with_id(id, schema_id, &spec.topic, &spec.message_encoding, &spec.metadata)
                    .map_err(err)?;
                self.note_chunk_bytes(cost as u64);
                {
                    let mut counts = lock(&self.shared.counts);
                    let id = usize::from(id);
                    if counts.len() <= id {
                        counts.resize(id + 1, 0);
                    }
                }
                self.shared.release(cost);
            }
            Command::Message { msg, cost } => {
                let record = cost as u64;
                // Close the open chunk first if this message would overflow it; a message
                // larger than chunk_size thereby gets a chunk of its own.
                if self.chunk_bytes > 0 && self.chunk_bytes + record > self.chunk_size {
                    self.close_chunk()?;
                }
                let header = MessageHeader {
                    channel_id: msg.channel.0,
                    sequence: msg.sequence,
                    log_time: msg.log_time,
                    publish_time: msg.publish_time,
                };
                self.writer()?.write_to_known_channel(&header, &msg.data).map_err(err)?;
                self.note_chunk_bytes(record);
                if self.chunk_bytes >= self.chunk_size {
                    self.close_chunk()?;
                }
                {
                    let mut counts = lock(&self.shared.counts);
                    let id = usize::from(msg.channel.0);
                    if counts.len() <= id {
                        counts.resize(id + 1, 0);
                    }
                    counts[id] += 1;
                }
                self.shared.bytes_written.fetch_add(msg.data.len() as u64, Ordering::Relaxed);
                // Hand the buffer back for reuse: re-faulting fresh pages for every large message
                // is what limits a recorder on a VM that returns freed memory to the host.
                let mut buf = msg.data;
                buf.clear();
                {
                    let mut pool = lock(&self.shared.pool);
                    if pool.len() < POOL_BUFFERS {
                        pool.push(buf);
                    }
                }
                self.shared.release(cost);
            }
            Command::Attach { name, media_type, data, time, cost } => {
                // mcap closes the open chunk before an attachment.
                self.writer()?
                    .attach(&mcap::Attachment {
                        log_time: time,
                        create_time: time,
                        name,
                        media_type,
                        data: data.into(),
                    })
                    .map_err(err)?;
                self.chunk_closed();
                self.shared.release(cost);
            }
            Command::Metadata { name, map } => {
                // mcap closes the open chunk before a metadata record.
                self.writer()?.write_metadata(&Metadata { name, metadata: map }).map_err(err)?;
                self.chunk_closed();
            }
            Command::Finish | Command::Abandon => {}
        }
        Ok(())
    }

    fn note_chunk_bytes(&mut self, bytes: u64) {
        self.chunk_bytes += bytes;
        if self.chunk_opened.is_none() {
            self.chunk_opened = Some(Instant::now());
        }
    }

    fn chunk_closed(&mut self) {
        self.chunk_bytes = 0;
        self.chunk_opened = None;
    }

    /// Closes the open chunk: `mcap::Writer::flush` finishes the chunk (compresses it, writes the
    /// chunk record and its message indexes) and flushes the sink.
    fn close_chunk(&mut self) -> Result<(), McapIoError> {
        if self.chunk_opened.is_some() || self.chunk_bytes > 0 {
            let path = self.path.clone();
            self.writer()?.flush().map_err(|e| mcap_error(&path, e))?;
        }
        self.chunk_closed();
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec() -> ChannelSpec {
        ChannelSpec { topic: "/t".into(), message_encoding: "raw".into(), ..Default::default() }
    }

    #[test]
    fn writer_thread_failure_is_reported_with_its_cause() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("fail.mcap");
        let opts = WriterOptions {
            compression: Compression::None,
            chunk_size: 64 * 1024,
            queue_bytes: 100 * 1024,
            ..WriterOptions::default()
        };
        let mut w = RecorderWriter::create_impl(&path, opts, 200_000).expect("create");
        let ch = w.add_channel(spec()).expect("channel");
        let mut failed = None;
        for seq in 0..1000u32 {
            let msg = OutMessage {
                channel: ch,
                sequence: seq,
                log_time: u64::from(seq),
                publish_time: 0,
                data: vec![seq as u8; 10 * 1024],
            };
            if let Err(e) = w.write(msg) {
                failed = Some((seq, e));
                break;
            }
        }
        let (seq, err) = failed.expect("writes past the injected limit must fail");
        assert!(seq > 5, "failed too early, at message {seq}");
        match &err {
            McapIoError::WriterThread(cause) => {
                assert!(cause.contains("injected write failure"), "{cause}")
            }
            other => panic!("expected WriterThread, got {other:?}"),
        }
        // Every later call fails as well, promptly.
        assert!(matches!(w.metadata("m", BTreeMap::new()), Err(McapIoError::WriterThread(_))));
        assert!(matches!(w.attach("a", "text/plain", vec![1; 10]), Err(McapIoError::WriterThread(_))));
        assert!(matches!(
            w.add_channel(ChannelSpec { topic: "/other".into(), ..spec() }),
            Err(McapIoError::WriterThread(_))
        ));
        // finish() returns the original error, naming the file.
        match w.finish() {
            Err(McapIoError::Io { path: p, source }) => {
                assert_eq!(p, path);
                assert!(source.to_string().contains("injected"), "{source}");
            }
            other => panic!("expected Io, got {other:?}"),
        }
    }

    #[test]
    fn blocked_writer_wakes_up_when_the_thread_fails() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("fail-blocked.mcap");
        let opts = WriterOptions {
            compression: Compression::None,
            queue_bytes: 1,
            chunk_size: 1024,
            ..WriterOptions::default()
        };
        let mut w = RecorderWriter::create_impl(&path, opts, 50_000).expect("create");
        let ch = w.add_channel(spec()).expect("channel");
        let w = &w;
        // Several producers, all blocking on the 1-byte queue, must all get the error.
        let results: Vec<_> = std::thread::scope(|s| {
            let handles: Vec<_> = (0..4)
                .map(|_| {
                    s.spawn(move || {
                        for seq in 0..10_000u32 {
                            w.write(OutMessage {
                                channel: ch,
                                sequence: seq,
                                log_time: 0,
                                publish_time: 0,
                                data: vec![0; 1000],
                            })?;
                        }
                        Ok(())
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().expect("producer panicked")).collect()
        });
        for r in results {
            assert!(matches!(r, Err(McapIoError::WriterThread(_))), "{r:?}");
        }
    }
}
