//! Live view of a running graph: the Foxglove pictures of its topics (particles → `PointCloud`,
//! Doppler maps and vector fields → `Grid`, beamformed I/Q → B-mode `RawImage`; the same pictures
//! a recording carries under `viz/<topic>`) served over Foxglove's WebSocket protocol by the
//! `foxglove` crate's server, so Foxglove (or any client of that protocol) shows the flow and the
//! estimates while the graph runs.
//!
//! No IPC here: the `live-view` node receives the topics and hands each message to
//! [`LiveView::offer`]. The design rule is that a viewer never slows the graph:
//!
//! - `offer` only copies the message into the topic's one-message mailbox (replacing one not yet
//!   shown, which is counted as skipped) and wakes the picture thread; it never waits for the
//!   picture thread, the network or a viewer.
//! - The picture thread makes pictures at most `max_rate_hz` per topic (the newest message wins)
//!   and logs them to the server, whose per-viewer queue holds `backlog` messages and drops the
//!   oldest when a viewer reads too slowly (the `foxglove` crate's behaviour).
//! - A viewer that subscribes gets the newest picture of that topic at once (a late viewer, or
//!   one that connects after a short run, still sees every topic).
//!
//! Nothing of the recording depends on this: the recorder is a separate node with its own
//! lossless subscription.

use foxglove::websocket::{ChannelView, Client, ServerListener};
use foxglove::{Context, RawChannel, WebSocketServer, WebSocketServerHandle};
use sonoflow_messages::viz;
use sonoflow_messages::MessageType;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Errors of the live view.
#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    /// A parameter out of range; the message names it.
    #[error("{0}")]
    Param(String),
    /// A topic type without a picture.
    #[error(
        "topic `{topic}` carries {kind}, which has no picture (pictures: particles, I/Q, Doppler maps, vector fields)"
    )]
    NoPicture { topic: String, kind: String },
    /// The server could not start (address in use, …).
    #[error("live view: cannot serve on {addr}: {detail}")]
    Server { addr: String, detail: String },
}

/// Where and how to serve.
#[derive(Clone, Debug)]
pub struct LiveOptions {
    /// Host to bind (`127.0.0.1`: this machine only; `0.0.0.0`: every interface).
    pub host: String,
    /// TCP port (0: any free port; see [`LiveView::url`]).
    pub port: u16,
    /// Pictures per viewer the server queues before it drops the oldest (1–100000).
    pub backlog: usize,
    /// Pictures per second and topic at most (0.1–1000); the newest message wins.
    pub max_rate_hz: f64,
    /// Server name shown by Foxglove.
    pub name: String,
}

impl Default for LiveOptions {
    fn default() -> Self {
        Self { host: "127.0.0.1".into(), port: DEFAULT_PORT, backlog: 256, max_rate_hz: 30.0, name: "sonoflow".into() }
    }
}

/// Foxglove's default WebSocket port.
pub const DEFAULT_PORT: u16 = 8765;

/// Parses `HOST:PORT`, `:PORT`, `PORT` or `HOST` (port 8765) into host and port.
pub fn parse_addr(s: &str) -> Result<(String, u16), String> {
    let s = s.trim();
    let bad = || format!("`{s}` is not an address: expected HOST:PORT (e.g. 127.0.0.1:8765, 0.0.0.0:8765 or :0)");
    if s.is_empty() {
        return Err(bad());
    }
    let (host, port) = match s.rsplit_once(':') {
        Some((h, p)) if !h.contains(':') || h.starts_with('[') => (h, Some(p)),
        Some(_) => return Err(bad()),
        None if s.chars().all(|c| c.is_ascii_digit()) => ("", Some(s)),
        None => (s, None),
    };
    let port = match port {
        Some(p) => p.parse::<u16>().map_err(|_| format!("{}: the port must be 0–65535", bad()))?,
        None => DEFAULT_PORT,
    };
    let host = host.trim_start_matches('[').trim_end_matches(']');
    let host = if host.is_empty() { "127.0.0.1" } else { host };
    if !host.chars().all(|c| c.is_ascii_alphanumeric() || ".-:".contains(c)) {
        return Err(bad());
    }
    Ok((host.to_string(), port))
}

impl LiveOptions {
    /// Checks the ranges; the error names the field.
    pub fn validate(&self) -> Result<(), LiveError> {
        if !(1..=100_000).contains(&self.backlog) {
            return Err(LiveError::Param(format!("backlog = {} is out of range 1–100000", self.backlog)));
        }
        if !(self.max_rate_hz.is_finite() && (0.1..=1000.0).contains(&self.max_rate_hz)) {
            return Err(LiveError::Param(format!("max_rate_hz = {} is out of range 0.1–1000", self.max_rate_hz)));
        }
        Ok(())
    }
}

/// What happened to one topic's messages.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LiveCount {
    pub topic: String,
    /// Messages handed to [`LiveView::offer`].
    pub offered: u64,
    /// Pictures sent to the server (to every subscribed viewer).
    pub shown: u64,
    /// Messages replaced by a newer one before their picture was made (rate limit or a busy
    /// picture thread; the graph never waits for either).
    pub skipped: u64,
}

/// One topic: its channel, mailbox and newest picture.
struct Topic {
    name: String,
    kind: MessageType,
    channel: Arc<RawChannel>,
    /// Newest picture sent (for viewers that subscribe later).
    latest: Mutex<Option<Arc<Vec<u8>>>>,
    offered: AtomicU64,
    shown: AtomicU64,
    skipped: AtomicU64,
}

/// A message waiting for its picture.
#[derive(Default)]
struct Pending {
    header: Vec<u8>,
    payload: Vec<u8>,
    full: bool,
}

struct Shared {
    topics: Vec<Topic>,
    mailbox: Mutex<Vec<Pending>>,
    wake: Condvar,
    closing: AtomicBool,
    viewers_seen: AtomicUsize,
    subscriptions_seen: AtomicUsize,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // A panic while holding these locks cannot leave them inconsistent (plain buffers).
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// Sends the newest picture of a channel to a viewer that has just subscribed to it.
struct Latch(Arc<Shared>);

impl ServerListener for Latch {
    fn on_subscribe(&self, client: Client, channel: ChannelView) {
        self.0.subscriptions_seen.fetch_add(1, Ordering::SeqCst);
        let Some(t) = self.0.topics.iter().find(|t| t.channel.id() == channel.id()) else { return };
        let latest = lock(&t.latest).clone();
        if let (Some(pic), Some(sink)) = (latest, client.sink_id()) {
            t.channel.log_to_sink(&pic, Some(sink));
        }
    }
    fn on_client_connect(&self) {
        self.0.viewers_seen.fetch_add(1, Ordering::SeqCst);
    }
}

/// The running live view: a WebSocket server and the picture thread.
pub struct LiveView {
    /// The server and the channels hold only weak references to their context.
    _context: Arc<Context>,
    shared: Arc<Shared>,
    server: Option<WebSocketServerHandle>,
    worker: Option<JoinHandle<()>>,
    url: String,
}

impl LiveView {
    /// Starts the server on `opts.host:opts.port` with one channel `viz/<topic>` per topic
    /// (advertised at once, before any message) and the picture thread.
    pub fn start(opts: &LiveOptions, topics: &[(String, MessageType)]) -> Result<Self, LiveError> {
        opts.validate()?;
        let ctx = Context::new();
        let mut list = Vec::with_capacity(topics.len());
        for (name, kind) in topics {
            let no_picture = || LiveError::NoPicture { topic: name.clone(), kind: kind.name().to_string() };
            let schema = viz::viz_schema(*kind).ok_or_else(no_picture)?;
            let channel = ctx
                .channel_builder(viz::viz_topic(name))
                .schema(schema)
                .message_encoding(viz::viz_message_encoding())
                .build_raw()
                .map_err(|e| LiveError::Param(format!("topic `{name}`: {e}")))?;
            list.push(Topic {
                name: name.clone(),
                kind: *kind,
                channel,
                latest: Mutex::new(None),
                offered: AtomicU64::new(0),
                shown: AtomicU64::new(0),
                skipped: AtomicU64::new(0),
            });
        }
        let shared = Arc::new(Shared {
            mailbox: Mutex::new((0..list.len()).map(|_| Pending::default()).collect()),
            topics: list,
            wake: Condvar::new(),
            closing: AtomicBool::new(false),
            viewers_seen: AtomicUsize::new(0),
            subscriptions_seen: AtomicUsize::new(0),
        });
        let addr = format!("{}:{}", opts.host, opts.port);
        let server = WebSocketServer::new()
            .name(opts.name.clone())
            .bind(opts.host.clone(), opts.port)
            .message_backlog_size(opts.backlog)
            .listener(Arc::new(Latch(shared.clone())))
            .context(&ctx)
            .start_blocking()
            .map_err(|e| LiveError::Server { addr: addr.clone(), detail: e.to_string() })?;
        let host = if opts.host.contains(':') { format!("[{}]", opts.host) } else { opts.host.clone() };
        let url = format!("ws://{host}:{}", server.port());
        let period = Duration::from_secs_f64(1.0 / opts.max_rate_hz);
        let s = shared.clone();
        let worker = std::thread::Builder::new()
            .name("live-pictures".into())
            .spawn(move || picture_loop(&s, period))
            .map_err(|e| LiveError::Server { addr, detail: format!("picture thread: {e}") })?;
        Ok(Self { _context: ctx, shared, server: Some(server), worker: Some(worker), url })
    }

    /// The address viewers connect to (`ws://127.0.0.1:8765`).
    pub fn url(&self) -> &str {
        &self.url
    }

    /// The port the server listens on (the one chosen when the options said 0).
    pub fn port(&self) -> u16 {
        self.server.as_ref().map(|s| s.port()).unwrap_or(0)
    }

    /// Viewers connected now.
    pub fn viewers(&self) -> usize {
        self.server.as_ref().map(|s| s.client_count()).unwrap_or(0)
    }

    /// Waits up to `timeout` until a viewer has subscribed to a topic; true if one has.
    pub fn wait_for_viewer(&self, timeout: Duration) -> bool {
        let t0 = Instant::now();
        loop {
            if self.shared.subscriptions_seen.load(Ordering::SeqCst) > 0 {
                return true;
            }
            if t0.elapsed() >= timeout {
                return false;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// Hands over a message of topic `index` (raw wire header and payload). Returns at once: the
    /// message is copied into the topic's mailbox, replacing one whose picture was not made yet.
    pub fn offer(&self, index: usize, header: &[u8], payload: &[u8]) {
        let Some(t) = self.shared.topics.get(index) else { return };
        t.offered.fetch_add(1, Ordering::Relaxed);
        {
            let mut mb = lock(&self.shared.mailbox);
            let slot = &mut mb[index];
            if slot.full {
                t.skipped.fetch_add(1, Ordering::Relaxed);
            }
            slot.header.clear();
            slot.header.extend_from_slice(header);
            slot.payload.clear();
            slot.payload.extend_from_slice(payload);
            slot.full = true;
        }
        self.shared.wake.notify_one();
    }

    /// Counts per topic so far.
    pub fn counts(&self) -> Vec<LiveCount> {
        self.shared
            .topics
            .iter()
            .map(|t| LiveCount {
                topic: t.name.clone(),
                offered: t.offered.load(Ordering::Relaxed),
                shown: t.shown.load(Ordering::Relaxed),
                skipped: t.skipped.load(Ordering::Relaxed),
            })
            .collect()
    }

    /// Ends the live view: the pictures still waiting are made and sent, then the server keeps
    /// serving the newest pictures for `linger` (so a viewer can still connect and look), or
    /// until every viewer that connected has gone, and stops without waiting for slow viewers.
    pub fn finish(mut self, linger: Duration) -> Vec<LiveCount> {
        self.shared.closing.store(true, Ordering::SeqCst);
        self.shared.wake.notify_all();
        if let Some(w) = self.worker.take() {
            let _ = w.join();
        }
        let t0 = Instant::now();
        while t0.elapsed() < linger {
            let gone = self.shared.viewers_seen.load(Ordering::SeqCst) > 0 && self.viewers() == 0;
            if gone {
                break;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let counts = self.counts();
        self.stop_server();
        counts
    }

    fn stop_server(&mut self) {
        if let Some(s) = self.server.take() {
            // Dropping the shutdown handle aborts the client tasks at once: a viewer that stopped
            // reading cannot hold the node up.
            drop(s.stop());
        }
    }
}

impl Drop for LiveView {
    fn drop(&mut self) {
        self.shared.closing.store(true, Ordering::SeqCst);
        self.shared.wake.notify_all();
        if let Some(w) = self.worker.take() {
            let _ = w.join();
        }
        self.stop_server();
    }
}

/// The picture thread: takes full mailboxes (each topic at most once per `period`, all of them
/// when closing), makes the picture outside the lock and logs it.
fn picture_loop(s: &Shared, period: Duration) {
    let n = s.topics.len();
    let mut last: Vec<Option<Instant>> = vec![None; n];
    let mut work = Pending::default();
    loop {
        let closing = s.closing.load(Ordering::SeqCst);
        let now = Instant::now();
        let due = |i: usize| closing || last[i].map(|t| now.duration_since(t) >= period).unwrap_or(true);
        let mut next: Option<usize> = None;
        let mut wait = Duration::from_millis(200);
        {
            let mut mb = lock(&s.mailbox);
            for (i, slot) in mb.iter().enumerate() {
                if !slot.full {
                    continue;
                }
                if due(i) {
                    next = Some(i);
                    break;
                }
                if let Some(t) = last[i] {
                    wait = wait.min(period.saturating_sub(now.duration_since(t)));
                }
            }
            match next {
                Some(i) => {
                    std::mem::swap(&mut mb[i], &mut work);
                    mb[i].full = false;
                }
                None if closing => return,
                None => {
                    let (guard, _) =
                        s.wake.wait_timeout(mb, wait.max(Duration::from_millis(1))).unwrap_or_else(|p| p.into_inner());
                    drop(guard);
                    continue;
                }
            }
        }
        if let Some(i) = next {
            last[i] = Some(now);
            let t = &s.topics[i];
            if let Some(pic) = viz::viz(t.kind, &work.header, &work.payload) {
                let data = Arc::new(pic.data);
                *lock(&t.latest) = Some(data.clone());
                t.channel.log(&data);
                t.shown.fetch_add(1, Ordering::Relaxed);
            }
            work.full = false;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn addresses_parse_with_defaults_and_clear_errors() {
        assert_eq!(parse_addr("127.0.0.1:9000").unwrap(), ("127.0.0.1".into(), 9000));
        assert_eq!(parse_addr(":0").unwrap(), ("127.0.0.1".into(), 0));
        assert_eq!(parse_addr("8766").unwrap(), ("127.0.0.1".into(), 8766));
        assert_eq!(parse_addr("0.0.0.0").unwrap(), ("0.0.0.0".into(), DEFAULT_PORT));
        assert_eq!(parse_addr("[::1]:9000").unwrap(), ("::1".into(), 9000));
        assert!(parse_addr("host:99999").unwrap_err().contains("0–65535"));
        assert!(parse_addr("launch/quickstart.toml").unwrap_err().contains("HOST:PORT"));
        assert!(parse_addr("").is_err());
    }

    #[test]
    fn options_out_of_range_name_the_field() {
        let o = LiveOptions { backlog: 0, ..LiveOptions::default() };
        assert!(o.validate().unwrap_err().to_string().contains("backlog"));
        let o = LiveOptions { max_rate_hz: f64::NAN, ..LiveOptions::default() };
        assert!(o.validate().unwrap_err().to_string().contains("max_rate_hz"));
    }

    #[test]
    fn a_topic_without_a_picture_is_refused_by_name() {
        let o = LiveOptions { port: 0, ..LiveOptions::default() };
        let e = LiveView::start(&o, &[("rf".into(), MessageType::RfFrameV3)]).err().map(|e| e.to_string());
        assert!(e.unwrap_or_default().contains("topic `rf` carries RfFrameV3"));
    }
}

#[cfg(feature = "testkit")]
pub mod testkit;
