//! `sonoflow bench …`: measurements that print a Markdown table (see BENCHMARKS.md).
//!
//! * `bench transport`: cost of moving one RF frame (128 × 8192 f32 = 4 MiB) between two
//!   processes — `memcpy` (cache / DRAM) as the physical reference, iceoryx2 through the node
//!   kit (payload written in place, the way the real nodes publish) and a Unix stream socket.
//!   The receiving side is a child process (`sonoflow bench-peer`, hidden).
//! * `bench recorder`: `test-source → recorder` through the real launcher, once per codec.

use anyhow::{anyhow, bail, Context};
use serde::{Deserialize, Serialize};
use sonoflow_messages::types::RfFrame;
use sonoflow_messages::{RfFrameHeaderV3, FLAG_END_OF_STREAM};
use sonoflow_node_kit::{is_eos, unix_ns, KindSpec, Kit, KitError, NodeConfig, TopicQos, NODE_CONFIG_ENV};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::{Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Channels per frame (fixed; `--mib` changes the samples per channel).
const N_CHANNELS: usize = 128;
/// Frames at the start of every transport run excluded from rates and latencies.
const WARMUP: u64 = 10;
/// Buffer pairs of the DRAM memcpy case (32 × 2 × 4 MiB = 256 MiB ≫ L3).
const DRAM_PAIRS: usize = 32;
/// How long either side waits for the other before giving up.
const PEER_TIMEOUT: Duration = Duration::from_secs(30);

#[derive(clap::Subcommand, Debug)]
pub enum BenchCmd {
    /// Transport cost per frame: iceoryx2 in place vs memcpy vs Unix socket (two processes).
    Transport {
        /// Frames per variant.
        #[arg(long, default_value_t = 2000)]
        frames: u64,
        /// Frame size in MiB (128 channels × mib·2048 f32 samples).
        #[arg(long, default_value_t = 4)]
        mib: usize,
        /// Also write the table to this file.
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Recorder throughput per codec (none / zstd / lz4) through the graph test-source → recorder.
    Recorder {
        /// Frames (4 MiB each) per codec.
        #[arg(long, default_value_t = 200)]
        frames: u64,
        /// Also write the table to this file.
        #[arg(long)]
        out: Option<PathBuf>,
    },
}

/// Transport of the peer process.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum PeerTransport {
    /// iceoryx2 subscriber through the node kit (config in SONOFLOW_NODE_CONFIG).
    Iox,
    /// Unix stream socket client.
    Unix,
}

/// Arguments of the hidden `sonoflow bench-peer` (the receiving process of `bench transport`).
#[derive(clap::Args, Debug)]
pub struct PeerArgs {
    #[arg(long, value_enum)]
    pub transport: PeerTransport,
    /// Read (sum) the whole payload of every frame, not only the header.
    #[arg(long)]
    pub read_all: bool,
    /// Socket file to connect to (`unix`).
    #[arg(long)]
    pub socket: Option<PathBuf>,
    /// Where to write the result (JSON).
    #[arg(long)]
    pub result: PathBuf,
}

/// What the peer reports back.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct PeerResult {
    /// Frames received (end of stream not counted).
    pub received: u64,
    /// Sequence gaps.
    pub gaps: u64,
    /// End of stream seen.
    pub eos: bool,
    /// Payload bytes of the last frame.
    pub frame_bytes: u64,
    /// Frames per second at the receiver, warm-up frames excluded.
    pub frames_per_s: f64,
    /// One-way latencies (ns) of the frames after the warm-up.
    pub latency_ns: Vec<u64>,
    /// Sum of the payload words (keeps the reads from being optimised away).
    pub checksum: u64,
}

/// `sonoflow bench …`; `registry`: the node kinds the recorder benchmark's graph uses.
pub fn run_bench(c: BenchCmd, registry: &'static [KindSpec]) -> anyhow::Result<i32> {
    let command = std::env::args().collect::<Vec<_>>().join(" ");
    let (table, out) = match c {
        BenchCmd::Transport { frames, mib, out } => (transport(frames, mib, &command)?, out),
        BenchCmd::Recorder { frames, out } => (recorder(frames, &command, registry)?, out),
    };
    print!("{table}");
    if let Some(p) = out {
        std::fs::write(&p, &table).with_context(|| format!("writing {}", p.display()))?;
        eprintln!("bench: table written to {}", p.display());
    }
    Ok(0)
}

// ---------------------------------------------------------------------------------------------
// Shared helpers

/// "2 logical CPUs, AMD EPYC …, kernel …".
fn machine() -> String {
    let cpus = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(0);
    let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let model = cpuinfo
        .lines()
        .find_map(|l| l.strip_prefix("model name").and_then(|r| r.split_once(':')).map(|(_, m)| m.trim().to_string()))
        .unwrap_or_else(|| "unknown CPU".into());
    let kernel = std::fs::read_to_string("/proc/sys/kernel/osrelease").unwrap_or_default();
    let mem_gib = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|m| {
            m.lines()
                .find_map(|l| l.strip_prefix("MemTotal:"))
                .and_then(|r| r.trim().trim_end_matches("kB").trim().parse::<f64>().ok())
        })
        .map(|kb| kb / 1048576.0)
        .unwrap_or(0.0);
    format!("{cpus} logical CPU(s) (nproc), {model}, {mem_gib:.0} GiB RAM, kernel {}", kernel.trim())
}

/// A private temporary folder, removed on drop.
struct TempDir(PathBuf);

impl TempDir {
    fn new(tag: &str) -> anyhow::Result<Self> {
        let p = std::env::temp_dir().join(format!("sonoflow-bench-{tag}-{}-{}", std::process::id(), unix_ns()));
        std::fs::create_dir_all(&p).with_context(|| format!("creating {}", p.display()))?;
        Ok(Self(p))
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Nearest-rank percentile of sorted values.
fn percentile(sorted: &[u64], q: f64) -> Option<u64> {
    if sorted.is_empty() {
        return None;
    }
    let rank = (q * sorted.len() as f64).ceil() as usize;
    Some(sorted[rank.clamp(1, sorted.len()) - 1])
}

/// Wrapping sum of the payload's bit patterns (integer adds vectorise; an f32 sum would not).
fn sum_words(data: &[f32]) -> u64 {
    data.iter().fold(0u64, |a, x| a.wrapping_add(x.to_bits() as u64))
}

/// The cheap fill pattern both senders write: element index + frame number, as f32 (through
/// i32: signed int → f32 vectorises on baseline x86-64, a u64 → f32 conversion does not).
#[inline]
fn fill_value(i: usize, frame: u64) -> f32 {
    (i as i32).wrapping_add(frame as i32) as f32
}

fn frame_header(frame: u64, n_samples: usize) -> RfFrameHeaderV3 {
    let mut h = RfFrameHeaderV3 {
        fs: 20e6,
        fc: 5e6,
        c: 1540.0,
        pitch: 0.3e-3,
        prf: 1000.0,
        n_channels: N_CHANNELS as u32,
        n_samples: n_samples as u32,
        ..Default::default()
    };
    h.common.frame_id = frame;
    h.common.t_valid = frame as f64 / 1000.0;
    h
}

fn fmt_rate(x: f64) -> String {
    if x >= 100.0 {
        format!("{x:.0}")
    } else {
        format!("{x:.1}")
    }
}

// ---------------------------------------------------------------------------------------------
// bench transport

/// One row of the transport table.
struct Row {
    path: String,
    frames_per_s: f64,
    frame_bytes: f64,
    /// (p50, p99) in ns.
    latency: Option<(u64, u64)>,
    received: String,
}

fn transport(frames: u64, mib: usize, command: &str) -> anyhow::Result<String> {
    if !(1..=256).contains(&mib) {
        bail!("--mib {mib} is out of range: 1 ..= 256");
    }
    if frames < WARMUP + 10 {
        bail!("--frames {frames}: need at least {}", WARMUP + 10);
    }
    let dead = sonoflow_node_kit::cleanup_dead_nodes()?;
    if dead > 0 {
        eprintln!("bench: removed shared-memory resources of {dead} dead node(s)");
    }
    let n = mib * 1024 * 1024 / 4;
    let n_samples = n / N_CHANNELS;
    let bytes = (n * 4) as f64;
    let exe = std::env::current_exe().context("locating the sonoflow executable")?;
    let tmp = TempDir::new("transport")?;
    let mut rows = Vec::new();

    eprintln!("bench: memcpy …");
    for (pairs, label) in [
        (1usize, "memcpy, cache-resident (1 buffer pair)"),
        (DRAM_PAIRS, "memcpy, DRAM (rotating over 32 buffer pairs)"),
    ] {
        let per_s = memcpy_rate(n * 4, pairs, frames);
        rows.push(Row {
            path: label.to_string(),
            frames_per_s: per_s,
            frame_bytes: bytes,
            latency: None,
            received: "–".into(),
        });
    }
    let variants: [(PeerTransport, bool, &str); 4] = [
        (PeerTransport::Iox, false, "iceoryx2 (node kit), written in place; subscriber reads the header"),
        (PeerTransport::Iox, true, "iceoryx2 (node kit), written in place; subscriber sums all 4 MiB"),
        (PeerTransport::Unix, false, "Unix stream socket, fill Vec + write_all; receiver read_exact"),
        (PeerTransport::Unix, true, "Unix stream socket, fill Vec + write_all; receiver read_exact + sums"),
    ];
    for (t, read_all, label) in variants {
        eprintln!("bench: {label} …");
        let r = match t {
            PeerTransport::Iox => run_iox(&exe, &tmp.0, frames, n_samples, read_all)?,
            PeerTransport::Unix => run_unix(&exe, &tmp.0, frames, n_samples, read_all)?,
        };
        if r.received != frames || r.gaps != 0 || !r.eos {
            bail!("{label}: peer received {} of {frames} frames, {} gaps, end of stream {}", r.received, r.gaps, r.eos);
        }
        let mut lat = r.latency_ns.clone();
        lat.sort_unstable();
        let latency = match (percentile(&lat, 0.5), percentile(&lat, 0.99)) {
            (Some(a), Some(b)) => Some((a, b)),
            _ => None,
        };
        rows.push(Row {
            path: label.replace("4 MiB", &format!("{mib} MiB")),
            frames_per_s: r.frames_per_s,
            frame_bytes: r.frame_bytes as f64,
            latency,
            received: format!("{} ({} gaps)", r.received, r.gaps),
        });
    }

    let mut s = String::new();
    let _ = writeln!(
        s,
        "### Transport: one frame of {N_CHANNELS} × {n_samples} f32 = {mib} MiB ({:.2} MB) between two processes\n",
        bytes / 1e6
    );
    let _ = writeln!(s, "- machine: {}", machine());
    let _ = writeln!(s, "- command: `{command}`");
    let _ = writeln!(s, "- {frames} frames per variant; the first {WARMUP} are excluded from rates and latencies\n");
    let _ = writeln!(s, "| path | frames/s | GB/s | ms / frame | latency p50 (µs) | latency p99 (µs) | received |");
    let _ = writeln!(s, "|---|---:|---:|---:|---:|---:|---:|");
    for r in &rows {
        let (p50, p99) = match r.latency {
            Some((a, b)) => (format!("{:.1}", a as f64 / 1e3), format!("{:.1}", b as f64 / 1e3)),
            None => ("–".into(), "–".into()),
        };
        let _ = writeln!(
            s,
            "| {} | {} | {:.1} | {:.3} | {p50} | {p99} | {} |",
            r.path,
            fmt_rate(r.frames_per_s),
            r.frames_per_s * r.frame_bytes / 1e9,
            1e3 / r.frames_per_s.max(1e-9),
            r.received
        );
    }
    let _ = writeln!(
        s,
        "\nGB/s = payload bytes delivered per second (1 GB = 10⁹ B); memcpy: bytes copied (`copy_from_slice`). \
         Both senders write every element of every frame (`(index + frame) as f32`): iceoryx2 directly into the \
         loaned shared-memory slot (`Output::publish_in_place`, lossless, queue depth 4), the socket sender into \
         a reused `Vec` before `write_all` (header + payload); that fill is part of the per-frame cost. frames/s is \
         measured at the receiver from frame {WARMUP} to the last one. Latency = `t_pub_ns` (wall clock just before \
         send / write, after the fill) → frame in the receiver's hands (iceoryx2: after `receive()`, before \
         reading the payload; socket: after the last payload byte was read), same host clock, free-running sender, \
         so it includes queueing whenever the receiver is the slower side.\n"
    );
    Ok(s)
}

/// Copies of `bytes` per second with `pairs` (src, dst) buffer pairs used round robin.
fn memcpy_rate(bytes: usize, pairs: usize, iters: u64) -> f64 {
    let src: Vec<Vec<u8>> = (0..pairs).map(|k| vec![(k as u8).wrapping_add(1); bytes]).collect();
    let mut dst: Vec<Vec<u8>> = (0..pairs).map(|_| vec![7u8; bytes]).collect();
    // Warm-up: one pass over every pair (page faults, TLB).
    for (d, s) in dst.iter_mut().zip(&src) {
        d.copy_from_slice(s);
    }
    let t = Instant::now();
    for i in 0..iters as usize {
        let k = i % pairs;
        dst[k].copy_from_slice(std::hint::black_box(&src[k]));
        std::hint::black_box(&mut dst[k]);
    }
    iters as f64 / t.elapsed().as_secs_f64()
}

fn peer_command(exe: &Path, t: &str, read_all: bool, result: &Path) -> Command {
    let mut c = Command::new(exe);
    c.arg("bench-peer").arg("--transport").arg(t).arg("--result").arg(result).stdin(Stdio::null());
    if read_all {
        c.arg("--read-all");
    }
    c
}

fn finish_peer(mut child: Child, sent: anyhow::Result<()>, result: &Path) -> anyhow::Result<PeerResult> {
    if let Err(e) = sent {
        let _ = child.kill();
        let _ = child.wait();
        return Err(e);
    }
    let st = child.wait().context("waiting for the bench peer")?;
    if !st.success() {
        bail!("bench peer failed: {st}");
    }
    let text = std::fs::read_to_string(result).with_context(|| format!("reading {}", result.display()))?;
    serde_json::from_str(&text).with_context(|| format!("parsing {}", result.display()))
}

/// Publisher here, subscriber in a child process; both through the node kit.
fn run_iox(exe: &Path, tmp: &Path, frames: u64, n_samples: usize, read_all: bool) -> anyhow::Result<PeerResult> {
    let n = N_CHANNELS * n_samples;
    let run_id = format!("bench-{}-{}", std::process::id(), unix_ns());
    let qos = TopicQos {
        topic: "frames".into(),
        message_type: "RfFrameV3".into(),
        max_elements: n,
        depth: 4,
        max_subscribers: 1,
        max_publishers: 1,
        expected_subscribers: 1,
    };
    let pub_cfg = NodeConfig {
        run_id,
        node_name: "bench-pub".into(),
        node_index: 0,
        kind: "bench".into(),
        params: serde_json::Value::Null,
        inputs: BTreeMap::new(),
        outputs: BTreeMap::from([("rf".to_string(), qos.clone())]),
        stats: None,
        handshake_timeout_s: PEER_TIMEOUT.as_secs_f64(),
        out_dir: None,
    };
    let peer_cfg = NodeConfig {
        node_name: "bench-sub".into(),
        node_index: 1,
        inputs: BTreeMap::from([("rf".to_string(), qos)]),
        outputs: BTreeMap::new(),
        ..pub_cfg.clone()
    };
    let result = tmp.join(format!("iox-{read_all}.json"));
    let mut kit = Kit::new(pub_cfg)?;
    let mut out = kit.output::<RfFrame>("rf")?;
    let child = peer_command(exe, "iox", read_all, &result)
        .env(NODE_CONFIG_ENV, serde_json::to_string(&peer_cfg)?)
        .spawn()
        .context("starting the bench peer")?;
    let sent = (|| -> anyhow::Result<()> {
        kit.handshake(&mut [&mut out])?;
        for f in 0..frames {
            out.publish_in_place(n, frame_header(f, n_samples), |dst| {
                for (i, d) in dst.iter_mut().enumerate() {
                    d.write(fill_value(i, f));
                }
            })?;
        }
        out.publish_eos(frames as f64 / 1000.0)?;
        Ok(())
    })();
    let r = finish_peer(child, sent, &result);
    drop(out);
    drop(kit);
    r
}

/// Sender here (socket file in `tmp`), receiver in a child process.
fn run_unix(exe: &Path, tmp: &Path, frames: u64, n_samples: usize, read_all: bool) -> anyhow::Result<PeerResult> {
    let n = N_CHANNELS * n_samples;
    let sock = tmp.join(format!("unix-{read_all}.sock"));
    let result = tmp.join(format!("unix-{read_all}.json"));
    let listener = UnixListener::bind(&sock).with_context(|| format!("binding {}", sock.display()))?;
    listener.set_nonblocking(true)?;
    let mut child = peer_command(exe, "unix", read_all, &result)
        .arg("--socket")
        .arg(&sock)
        .spawn()
        .context("starting the bench peer")?;
    let sent = (|| -> anyhow::Result<()> {
        let deadline = Instant::now() + PEER_TIMEOUT;
        let mut stream = loop {
            match listener.accept() {
                Ok((s, _)) => break s,
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                    if let Some(st) = child.try_wait()? {
                        bail!("bench peer exited before connecting: {st}");
                    }
                    if Instant::now() > deadline {
                        bail!("bench peer did not connect within {} s", PEER_TIMEOUT.as_secs());
                    }
                    std::thread::sleep(Duration::from_millis(1));
                }
                Err(e) => return Err(e).context("accepting the bench peer"),
            }
        };
        stream.set_nonblocking(false)?;
        let mut payload = vec![0f32; n];
        for f in 0..frames {
            for (i, d) in payload.iter_mut().enumerate() {
                *d = fill_value(i, f);
            }
            let mut h = frame_header(f, n_samples);
            h.common.seq = f;
            h.common.t_pub_ns = unix_ns();
            stream.write_all(bytemuck::bytes_of(&h))?;
            stream.write_all(bytemuck::cast_slice(&payload))?;
        }
        let mut h = RfFrameHeaderV3::default();
        h.common.flags = FLAG_END_OF_STREAM;
        h.common.seq = frames;
        stream.write_all(bytemuck::bytes_of(&h))?;
        stream.flush()?;
        Ok(())
    })();
    finish_peer(child, sent, &result)
}

/// Receiver-side bookkeeping shared by both peers.
struct Tally {
    n: u64,
    first: Option<Instant>,
    last: Option<Instant>,
    latency_ns: Vec<u64>,
    checksum: u64,
    frame_bytes: u64,
}

impl Tally {
    fn new() -> Self {
        Self { n: 0, first: None, last: None, latency_ns: Vec::new(), checksum: 0, frame_bytes: 0 }
    }

    fn frame(&mut self, now_ns: u64, t_pub_ns: u64, frame_bytes: u64) {
        let now = Instant::now();
        if self.n >= WARMUP {
            self.latency_ns.push(now_ns.saturating_sub(t_pub_ns));
        }
        if self.n == WARMUP {
            self.first = Some(now);
        }
        self.last = Some(now);
        self.frame_bytes = frame_bytes;
        self.n += 1;
    }

    fn result(self, gaps: u64, eos: bool) -> PeerResult {
        let frames_per_s = match (self.first, self.last) {
            (Some(a), Some(b)) if self.n > WARMUP + 1 && b > a => {
                (self.n - 1 - WARMUP) as f64 / b.duration_since(a).as_secs_f64()
            }
            _ => 0.0,
        };
        PeerResult {
            received: self.n,
            gaps,
            eos,
            frame_bytes: self.frame_bytes,
            frames_per_s,
            latency_ns: self.latency_ns,
            checksum: self.checksum,
        }
    }
}

/// `sonoflow bench-peer`: the receiving process of `bench transport`.
pub fn run_peer(a: PeerArgs) -> anyhow::Result<i32> {
    let r = match a.transport {
        PeerTransport::Iox => peer_iox(a.read_all)?,
        PeerTransport::Unix => {
            let sock = a.socket.as_deref().ok_or_else(|| anyhow!("--socket is required with --transport unix"))?;
            peer_unix(sock, a.read_all)?
        }
    };
    std::fs::write(&a.result, serde_json::to_vec(&r)?).with_context(|| format!("writing {}", a.result.display()))?;
    Ok(0)
}

fn peer_iox(read_all: bool) -> anyhow::Result<PeerResult> {
    let mut kit = Kit::from_env()?;
    let mut input = kit.input::<RfFrame>("rf")?;
    kit.handshake(&mut [&mut input])?;
    let mut tally = Tally::new();
    let mut idle_since = Instant::now();
    'outer: loop {
        while let Some(s) = input.try_receive()? {
            if is_eos::<RfFrame>(s.user_header()) {
                break 'outer;
            }
            let now_ns = unix_ns();
            let data = s.payload();
            tally.frame(now_ns, s.user_header().common.t_pub_ns, std::mem::size_of_val(data) as u64);
            if read_all {
                tally.checksum = tally.checksum.wrapping_add(sum_words(data));
            }
            idle_since = Instant::now();
        }
        match kit.check_termination() {
            Ok(()) => {}
            Err(KitError::Terminated) => break,
            Err(e) => return Err(e.into()),
        }
        if idle_since.elapsed() > PEER_TIMEOUT {
            bail!("no frame for {} s", PEER_TIMEOUT.as_secs());
        }
        input.wait(Duration::from_millis(100))?;
    }
    Ok(tally.result(input.gaps, input.eos))
}

fn peer_unix(sock: &Path, read_all: bool) -> anyhow::Result<PeerResult> {
    let mut stream = UnixStream::connect(sock).with_context(|| format!("connecting to {}", sock.display()))?;
    stream.set_read_timeout(Some(PEER_TIMEOUT))?;
    let mut tally = Tally::new();
    let mut buf: Vec<f32> = Vec::new();
    let mut h = RfFrameHeaderV3::default();
    let (mut gaps, mut eos, mut expected) = (0u64, false, 0u64);
    loop {
        match stream.read_exact(bytemuck::bytes_of_mut(&mut h)) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => break,
            Err(e) => return Err(e).context("reading a frame header"),
        }
        if h.common.flags & FLAG_END_OF_STREAM != 0 {
            eos = true;
            break;
        }
        let n = h.n_channels as usize * h.n_samples as usize;
        if n > 1 << 28 {
            bail!("frame {} announces {n} samples", h.common.seq);
        }
        buf.resize(n, 0.0);
        stream.read_exact(bytemuck::cast_slice_mut(&mut buf[..n])).context("reading a frame payload")?;
        let now_ns = unix_ns();
        if h.common.seq != expected {
            gaps += 1;
        }
        expected = h.common.seq + 1;
        tally.frame(now_ns, h.common.t_pub_ns, (n * 4) as u64);
        if read_all {
            tally.checksum = tally.checksum.wrapping_add(sum_words(&buf[..n]));
        }
    }
    Ok(tally.result(gaps, eos))
}

// ---------------------------------------------------------------------------------------------
// bench recorder

/// Sends this process's stdout to stderr while alive (the launcher prints `recording: …` and
/// `report: …` lines; the bench's stdout is the table only).
struct StdoutToStderr {
    saved: libc::c_int,
}

impl StdoutToStderr {
    fn new() -> Option<Self> {
        let _ = std::io::stdout().flush();
        // SAFETY: plain dup/dup2/close on the process's own standard descriptors.
        unsafe {
            let saved = libc::dup(1);
            if saved < 0 {
                return None;
            }
            if libc::dup2(2, 1) < 0 {
                libc::close(saved);
                return None;
            }
            Some(Self { saved })
        }
    }
}

impl Drop for StdoutToStderr {
    fn drop(&mut self) {
        let _ = std::io::stdout().flush();
        // SAFETY: restores the descriptor saved in `new`.
        unsafe {
            libc::dup2(self.saved, 1);
            libc::close(self.saved);
        }
    }
}

struct RecRow {
    payload_bytes: u64,
    file_bytes: u64,
    recorder_wall_s: f64,
    run_wall_s: f64,
    recorder_cpu_s: f64,
    source_cpu_s: f64,
}

fn node_stats<'a>(report: &'a serde_json::Value, node: &str) -> Option<&'a serde_json::Value> {
    report.get("nodes")?.as_array()?.iter().find(|n| n.get("name").and_then(|v| v.as_str()) == Some(node))?.get("stats")
}

fn stat_s(stats: Option<&serde_json::Value>, field: &str) -> f64 {
    stats.and_then(|s| s.get(field)).and_then(|v| v.as_u64()).map(|ns| ns as f64 / 1e9).unwrap_or(f64::NAN)
}

/// Memory touched and freed before a codec run (page cache of the recording + recorder queue).
const PREFAULT: usize = 1536 << 20;

fn recorder_once(
    codec: &'static str,
    frames: u64,
    tmp: &Path,
    prefault: bool,
    registry: &'static [KindSpec],
) -> anyhow::Result<RecRow> {
    let text = format!(
        r#"
[graph]
name = "bench-recorder"

[topics]
rf = {{ type = "RfFrameV3", max_elements = 1048576, depth = 4 }}

[nodes.source]
kind = "test-source"
outputs = {{ rf = "rf" }}
params = {{ n_frames = {frames}, n_channels = 128, n_samples = 8192 }}

[nodes.recorder]
kind = "recorder"
params = {{ compression = "{codec}" }}
"#
    );
    let file: sonoflow_launcher::launch::LaunchFile = toml::from_str(&text).context("bench launch file")?;
    let graph =
        sonoflow_launcher::launch::resolve(file, tmp, &sonoflow_launcher::launch::Overrides::default(), registry)
            .map_err(|e| anyhow!("bench launch file: {}", e.join("; ")))?;
    let out_dir = tmp.join(format!("run-{codec}"));
    let opts = sonoflow_launcher::supervise::RunOptions {
        out_dir: out_dir.clone(),
        run_id: sonoflow_launcher::supervise::new_run_id(&format!("bench-rec-{codec}")),
        quiet: true,
    };
    if prefault {
        drop(std::hint::black_box(vec![1u8; PREFAULT]));
    }
    let t = Instant::now();
    let rc = {
        let _redirect = StdoutToStderr::new();
        sonoflow_launcher::run_graph(&graph, &opts)?
    };
    let run_wall_s = t.elapsed().as_secs_f64();
    if rc != 0 {
        bail!("codec {codec}: the graph failed (exit {rc}); see {}", out_dir.display());
    }
    let report: serde_json::Value = serde_json::from_slice(
        &std::fs::read(out_dir.join("report.json"))
            .with_context(|| format!("reading {}/report.json", out_dir.display()))?,
    )?;
    let rec = node_stats(&report, "recorder");
    let src = node_stats(&report, "source");
    let file_bytes = std::fs::metadata(out_dir.join("recording.mcap")).map(|m| m.len()).context("recording.mcap")?;
    let row = RecRow {
        payload_bytes: frames * 128 * 8192 * 4,
        file_bytes,
        recorder_wall_s: stat_s(rec, "wall_ns"),
        run_wall_s,
        recorder_cpu_s: stat_s(rec, "cpu_ns"),
        source_cpu_s: stat_s(src, "cpu_ns"),
    };
    let _ = std::fs::remove_dir_all(&out_dir);
    Ok(row)
}

fn recorder(frames: u64, command: &str, registry: &'static [KindSpec]) -> anyhow::Result<String> {
    if frames == 0 {
        bail!("--frames must be at least 1");
    }
    let tmp = TempDir::new("recorder")?;
    // VMs with free page reporting (the dev VM) hand freed guest memory back to the host within
    // seconds; the next first touch of such a page is a host page fault (dd of 800 MiB there:
    // ~0.35-0.5 GB/s instead of ~2.2 GB/s). The recorder allocates a fresh buffer per message
    // and queues up to 512 MiB of them, so its rate depends on that. The first run goes in cold
    // and is shown as the last row; before each codec run the bench touches and frees PREFAULT
    // bytes, which the kernel hands out again first (recently freed pages are still backed).
    eprintln!("bench: recorder, first run (compression none, cold memory) …");
    let cold = recorder_once("none", frames, &tmp.0, false, registry)?;
    let mut rows = Vec::new();
    for codec in ["none", "zstd", "lz4"] {
        eprintln!("bench: recorder, compression {codec} …");
        rows.push((codec.to_string(), recorder_once(codec, frames, &tmp.0, true, registry)?));
    }
    rows.push(("none, first run, no pre-faulting (cold VM memory)".to_string(), cold));
    let mut s = String::new();
    let _ = writeln!(s, "### Recorder: graph `test-source → recorder`, {frames} frames of 128 × 8192 f32 (4 MiB)\n");
    let _ = writeln!(s, "- machine: {}", machine());
    let _ = writeln!(s, "- command: `{command}`");
    let _ = writeln!(s, "- recording folder: `{}` (removed afterwards)\n", tmp.0.display());
    let _ = writeln!(
        s,
        "| codec | payload MB | file MB | file / raw | recorder wall (s) | MB/s (recorder wall) | run wall (s) | MB/s (run wall) | CPU s recorder / source |"
    );
    let _ = writeln!(s, "|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    for (label, r) in &rows {
        let mb = r.payload_bytes as f64 / 1e6;
        let _ = writeln!(
            s,
            "| {label} | {mb:.0} | {:.0} | {:.3} | {:.2} | {:.0} | {:.2} | {:.0} | {:.2} / {:.2} |",
            r.file_bytes as f64 / 1e6,
            r.file_bytes as f64 / r.payload_bytes as f64,
            r.recorder_wall_s,
            mb / r.recorder_wall_s,
            r.run_wall_s,
            mb / r.run_wall_s,
            r.recorder_cpu_s,
            r.source_cpu_s
        );
    }
    let _ = writeln!(
        s,
        "\nMB/s = raw payload bytes ({frames} × 4 MiB, 1 MB = 10⁶ B) / time. *Recorder wall* = the recorder \
         node's own `wall_ns` from `report.json` (node start → MCAP finished and fsynced; includes its start-up and \
         the handshake); *run wall* = `sonoflow::run::run` timed by the bench (process start-up of both nodes \
         included). File / raw = MCAP file size / raw payload (headers, the `_stats` topic and the summary make \
         `none` slightly > 1). The test pattern is noise-like (uniform hash values), so the ratios are those of \
         noise — like real beamformed I/Q, unlike ADC-quantised RF or noise-free simulator output. Only 2 cores: \
         the source computes and writes every frame on one core while the recorder (receive thread + writer \
         thread, single-threaded compression) runs on the other, so these are rates with the producer competing \
         for the CPU. Default recorder settings (zstd/lz4 level 1, 4 MiB chunks, 512 MiB queue). The codec rows run \
         right after the bench touched and freed 1.5 GiB of memory; the last row is the first run, without that. \
         The difference matters on VMs with free page reporting (the 2-core dev VM): memory freed by a process or a \
         deleted file goes back to the host within seconds, and touching it again costs a host page fault per page \
         (`dd` of 800 MiB there: ~0.35–0.5 GB/s cold vs ~2.2 GB/s warm), so a first run — and a long recording \
         that keeps growing the page cache — sees the cold rate.\n"
    );
    Ok(s)
}
