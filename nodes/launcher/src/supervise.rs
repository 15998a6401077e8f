//! Running a graph (`sonoflow run`): starts a checked graph as separate processes, streams their logs, shows
//! progress, supervises, stops everything cleanly and writes the run report.
//!
//! Shutdown order (normal end, Ctrl-C, or a node dying): stop the non-recorder nodes (they send
//! end-of-stream downstream and exit), then the recorders (they finish their MCAP files), and
//! only after `graph.stop_grace_s` escalate to SIGKILL — reported as a failure.

use crate::launch::{Program, ResolvedGraph};
use crate::report::{NodeOutcome, RunReport};
use crossbeam_channel::{unbounded, Receiver, RecvTimeoutError};
use sonoflow_node_kit::{NodeConfig, NodeStats, NODE_CONFIG_ENV, PROGRESS_LINE_PREFIX, STATS_LINE_PREFIX};
use std::io::{BufRead, BufReader, Write};
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::PathBuf;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

static INTERRUPTED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    INTERRUPTED.store(true, Ordering::SeqCst);
}

/// Whether SIGINT/SIGTERM reached this process since its first run started (a caller running
/// several graphs in a row, such as a sweep, stops there).
pub fn interrupted() -> bool {
    INTERRUPTED.load(Ordering::SeqCst)
}

fn install_signal_handlers() {
    // SAFETY: the handler only stores to an atomic (async-signal-safe).
    unsafe {
        libc::signal(libc::SIGINT, on_signal as *const () as libc::sighandler_t);
        libc::signal(libc::SIGTERM, on_signal as *const () as libc::sighandler_t);
    }
}

/// Options of one run.
pub struct RunOptions {
    pub out_dir: PathBuf,
    pub run_id: String,
    pub quiet: bool,
}

struct Running {
    name: String,
    program: String,
    child: Child,
    is_recorder: bool,
    status: Option<ExitStatus>,
    stopping: bool,
    log: std::fs::File,
    log_path: PathBuf,
    stats: Option<NodeStats>,
    progress: Option<(u64, u64)>,
    last_err: Vec<String>,
}

fn describe_status(s: &ExitStatus) -> String {
    if let Some(code) = s.code() {
        format!("exited with code {code}")
    } else if let Some(sig) = s.signal() {
        let name = match sig {
            libc::SIGKILL => "SIGKILL",
            libc::SIGTERM => "SIGTERM",
            libc::SIGINT => "SIGINT",
            libc::SIGSEGV => "SIGSEGV",
            libc::SIGBUS => "SIGBUS",
            libc::SIGABRT => "SIGABRT",
            _ => "signal",
        };
        format!("killed by signal {sig} ({name})")
    } else {
        "ended".into()
    }
}

enum Line {
    Out(usize, String),
    Err(usize, String),
}

fn spawn_reader<R: std::io::Read + Send + 'static>(idx: usize, r: R, err: bool, tx: crossbeam_channel::Sender<Line>) {
    std::thread::spawn(move || {
        for line in BufReader::new(r).lines() {
            let Ok(line) = line else { break };
            let msg = if err { Line::Err(idx, line) } else { Line::Out(idx, line) };
            if tx.send(msg).is_err() {
                break;
            }
        }
    });
}

/// Runs the graph; returns the process exit code (0 ok, 1 failure, 130 interrupted).
pub fn run_graph(graph: &ResolvedGraph, opts: &RunOptions) -> anyhow::Result<i32> {
    let started = Instant::now();
    std::fs::create_dir_all(&opts.out_dir)
        .map_err(|e| anyhow::anyhow!("creating output folder {}: {e}", opts.out_dir.display()))?;
    let out_dir = opts.out_dir.canonicalize()?;
    let logs = out_dir.join("logs");
    std::fs::create_dir_all(&logs)?;
    let launch_path = out_dir.join("launch.resolved.toml");
    sonoflow_fileio::write_atomic(&launch_path, graph.resolved_toml.as_bytes())?;

    // Recordings must not overwrite earlier ones.
    let mut recordings = Vec::new();
    for n in graph.nodes.iter().filter(|n| n.is_recorder) {
        let p = n.params.get("path").and_then(|v| v.as_str()).unwrap_or("recording.mcap");
        let full = out_dir.join(p);
        if full.exists() {
            anyhow::bail!(
                "{} already exists: choose another --out folder (recordings are never overwritten)",
                full.display()
            );
        }
        recordings.push(full);
    }

    install_signal_handlers();
    let dead = sonoflow_node_kit::cleanup_dead_nodes()?;
    if dead > 0 {
        eprintln!("sonoflow: removed shared-memory resources of {dead} dead node(s) from an earlier run");
    }
    let launcher = sonoflow_node_kit::create_node_with("sonoflow-launcher", false)?;
    let mut held = Vec::new();
    for q in graph.topics.values().chain(graph.stats.iter()) {
        held.push(sonoflow_node_kit::open_topic_services(&launcher, &opts.run_id, q)?);
    }

    let exe = std::env::current_exe()?;
    let (tx, rx) = unbounded::<Line>();
    let mut procs: Vec<Running> = Vec::new();
    // Consumers first (recorders, then the rest in reverse declaration order).
    let mut order: Vec<usize> = (0..graph.nodes.len()).collect();
    order.sort_by_key(|&i| (!graph.nodes[i].is_recorder, std::cmp::Reverse(i)));
    for i in order {
        let n = &graph.nodes[i];
        let mut params = n.params.clone();
        let mut inputs = n.inputs.clone();
        if n.is_recorder {
            if let Some(obj) = params.as_object_mut() {
                obj.insert("launch_file".into(), launch_path.display().to_string().into());
            } else {
                params = serde_json::json!({ "launch_file": launch_path.display().to_string() });
            }
            if let Some(s) = &graph.stats {
                inputs.insert(crate::launch::STATS_TOPIC.into(), s.clone());
            }
        }
        let cfg = NodeConfig {
            run_id: opts.run_id.clone(),
            node_name: n.name.clone(),
            node_index: n.index,
            kind: match &n.program {
                Program::Builtin(k) => k.clone(),
                Program::Exec(p, _) => p.display().to_string(),
            },
            params,
            inputs,
            outputs: n.outputs.clone(),
            stats: if n.is_recorder { None } else { graph.stats.clone() },
            handshake_timeout_s: graph.graph.handshake_timeout_s,
            out_dir: Some(out_dir.display().to_string()),
        };
        let (mut cmd, program) = match &n.program {
            Program::Builtin(k) => {
                let mut c = Command::new(&exe);
                c.arg("node").arg(k);
                (c, format!("sonoflow node {k}"))
            }
            Program::Exec(p, args) => {
                let mut c = Command::new(p);
                c.args(args);
                (c, p.display().to_string())
            }
        };
        if let Some(c) = n.cpus {
            cmd.env("RAYON_NUM_THREADS", c.to_string()).env("SONOFLOW_THREADS", c.to_string());
        }
        cmd.env(NODE_CONFIG_ENV, serde_json::to_string(&cfg)?)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .current_dir(&out_dir);
        // SAFETY: only async-signal-safe calls between fork and exec.
        unsafe {
            cmd.pre_exec(|| {
                // Own process group: a terminal Ctrl-C reaches the launcher only, which stops
                // the graph in order. Parent death → SIGTERM, so nothing is orphaned.
                libc::setpgid(0, 0);
                libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM);
                Ok(())
            });
        }
        let mut child = cmd.spawn().map_err(|e| anyhow::anyhow!("starting node `{}` ({program}): {e}", n.name))?;
        let idx = procs.len();
        if !opts.quiet {
            eprintln!("sonoflow: started node `{}` ({program}) pid {}", n.name, child.id());
        }
        if let Some(o) = child.stdout.take() {
            spawn_reader(idx, o, false, tx.clone());
        }
        if let Some(e) = child.stderr.take() {
            spawn_reader(idx, e, true, tx.clone());
        }
        let log_path = logs.join(format!("{}.log", n.name));
        let log = std::fs::File::create(&log_path)?;
        procs.push(Running {
            name: n.name.clone(),
            program,
            child,
            is_recorder: n.is_recorder,
            status: None,
            stopping: false,
            log,
            log_path,
            stats: None,
            progress: None,
            last_err: Vec::new(),
        });
    }
    drop(tx);
    if !opts.quiet {
        eprintln!(
            "sonoflow: graph `{}` started: {} node(s), run id {}, output {}",
            graph.graph.name,
            procs.len(),
            opts.run_id,
            out_dir.display()
        );
    }

    let grace = Duration::from_secs_f64(graph.graph.stop_grace_s);
    let mut failures: Vec<String> = Vec::new();
    let mut shutdown: Option<(Instant, u8)> = None; // (phase start, phase: 1 = others, 2 = recorders, 3 = kill)
    let mut interrupted = false;
    let mut last_progress = Instant::now();
    loop {
        drain_lines(&rx, &mut procs, opts.quiet, Duration::from_millis(50));
        // Exits.
        for p in procs.iter_mut() {
            if p.status.is_none() {
                if let Ok(Some(st)) = p.child.try_wait() {
                    p.status = Some(st);
                    // A node that exits with an error code after we asked it to stop is not a
                    // failure (e.g. a checker that saw fewer frames); a signal death always is.
                    let tolerated = st.success() || (p.stopping && st.code().is_some());
                    if !tolerated {
                        let tail = if p.last_err.is_empty() {
                            String::new()
                        } else {
                            format!("; last output: {}", p.last_err.join(" | "))
                        };
                        let msg = format!("node `{}` ({}) {}{tail}", p.name, p.program, describe_status(&st));
                        eprintln!("sonoflow: ERROR {msg}");
                        failures.push(msg);
                    }
                }
            }
        }
        if INTERRUPTED.load(Ordering::SeqCst) && !interrupted {
            interrupted = true;
            eprintln!("sonoflow: interrupted, stopping the graph (recordings are finished cleanly)");
        }
        let all_done = procs.iter().all(|p| p.status.is_some());
        if all_done {
            break;
        }
        let others_done = procs.iter().filter(|p| !p.is_recorder).all(|p| p.status.is_some());
        if shutdown.is_none() && (interrupted || !failures.is_empty()) {
            shutdown = Some((Instant::now(), 1));
            for p in procs.iter_mut().filter(|p| !p.is_recorder && p.status.is_none()) {
                terminate(p, libc::SIGTERM);
            }
        }
        if shutdown.is_none() && others_done {
            // Normal end: recorders finish on end-of-stream; give them the grace period.
            shutdown = Some((Instant::now(), 1));
        }
        if let Some((t, phase)) = shutdown {
            if phase == 1 && (others_done || t.elapsed() > grace) {
                if others_done {
                    // Recorders normally finish by themselves once every stream ended.
                    let recorder_grace = if interrupted || !failures.is_empty() { Duration::ZERO } else { grace };
                    if t.elapsed() >= recorder_grace {
                        shutdown = Some((Instant::now(), 2));
                        for p in procs.iter_mut().filter(|p| p.status.is_none()) {
                            terminate(p, libc::SIGTERM);
                        }
                    }
                } else {
                    shutdown = Some((Instant::now(), 2));
                    for p in procs.iter_mut().filter(|p| p.status.is_none()) {
                        terminate(p, libc::SIGTERM);
                    }
                }
            } else if phase == 2 && t.elapsed() > grace {
                shutdown = Some((Instant::now(), 3));
                for p in procs.iter_mut().filter(|p| p.status.is_none()) {
                    let msg =
                        format!("node `{}` did not stop within {:.1} s and was killed", p.name, grace.as_secs_f64());
                    eprintln!("sonoflow: ERROR {msg}");
                    failures.push(msg);
                    terminate(p, libc::SIGKILL);
                }
            }
        }
        if !opts.quiet && last_progress.elapsed() > Duration::from_secs(2) {
            last_progress = Instant::now();
            let parts: Vec<String> = procs
                .iter()
                .filter_map(|p| {
                    p.progress.map(|(d, t)| format!("{} {d}/{t} ({:.0} %)", p.name, 100.0 * d as f64 / t.max(1) as f64))
                })
                .collect();
            if !parts.is_empty() {
                eprintln!("sonoflow: progress {} — {:.1} s", parts.join(", "), started.elapsed().as_secs_f64());
            }
        }
    }
    drain_lines(&rx, &mut procs, opts.quiet, Duration::from_millis(100));
    drop(held);
    let _ = sonoflow_node_kit::cleanup_dead_nodes();

    let status = if !failures.is_empty() {
        "failed"
    } else if interrupted {
        "interrupted"
    } else {
        "ok"
    };
    let mut report = RunReport {
        graph: graph.graph.name.clone(),
        run_id: opts.run_id.clone(),
        out_dir: out_dir.display().to_string(),
        status: status.into(),
        wall_s: started.elapsed().as_secs_f64(),
        failures: failures.clone(),
        warnings: graph.warnings.clone(),
        recordings: recordings.iter().filter(|p| p.exists()).map(|p| p.display().to_string()).collect(),
        shm_bytes: graph.shm_bytes,
        nodes: procs
            .iter()
            .map(|p| NodeOutcome {
                name: p.name.clone(),
                program: p.program.clone(),
                exit: p.status.as_ref().map(describe_status).unwrap_or_else(|| "unknown".into()),
                ok: p.status.map(|s| s.success()).unwrap_or(false),
                stats: p.stats.clone(),
                log: p.log_path.display().to_string(),
            })
            .collect(),
        figures: Vec::new(),
        critical_path: None,
    };
    report.critical_path = crate::report::critical_stage(&report).map(|n| n.name.clone());
    crate::report::add_figures(&out_dir, &mut report);
    crate::report::write(&out_dir, &report)?;
    for r in &report.recordings {
        println!("recording: {r}");
    }
    println!("report: {}", out_dir.join("report.md").display());
    if !failures.is_empty() {
        eprintln!("sonoflow: run FAILED ({} problem(s)); logs in {}", failures.len(), logs.display());
        return Ok(1);
    }
    if interrupted {
        return Ok(130);
    }
    eprintln!("sonoflow: run finished in {:.2} s", report.wall_s);
    Ok(0)
}

fn terminate(p: &mut Running, sig: libc::c_int) {
    p.stopping = true;
    let pid = p.child.id() as libc::pid_t;
    // SAFETY: plain kill(2) on our own child's process group.
    unsafe {
        libc::kill(-pid, sig);
        libc::kill(pid, sig);
    }
}

fn drain_lines(rx: &Receiver<Line>, procs: &mut [Running], quiet: bool, first_wait: Duration) {
    let mut wait = first_wait;
    loop {
        let line = match rx.recv_timeout(wait) {
            Ok(l) => l,
            Err(RecvTimeoutError::Timeout) | Err(RecvTimeoutError::Disconnected) => return,
        };
        wait = Duration::ZERO;
        let (idx, text, is_err) = match line {
            Line::Out(i, t) => (i, t, false),
            Line::Err(i, t) => (i, t, true),
        };
        let Some(p) = procs.get_mut(idx) else { continue };
        let _ = writeln!(p.log, "{text}");
        if let Some(js) = text.strip_prefix(STATS_LINE_PREFIX) {
            p.stats = serde_json::from_str(js).ok();
            continue;
        }
        if let Some(pr) = text.strip_prefix(PROGRESS_LINE_PREFIX) {
            if let Some((d, t)) = pr.split_once('/') {
                if let (Ok(d), Ok(t)) = (d.trim().parse(), t.trim().parse()) {
                    p.progress = Some((d, t));
                }
            }
            continue;
        }
        if is_err {
            p.last_err.push(text.clone());
            if p.last_err.len() > 3 {
                p.last_err.remove(0);
            }
        }
        if !quiet || is_err {
            eprintln!("[{}] {text}", p.name);
        }
    }
}

/// Default output folder: `runs/<graph>-<UTC date-time>`.
pub fn default_out_dir(graph: &str) -> PathBuf {
    let secs = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_secs()).unwrap_or(0);
    let days = (secs / 86400) as i64;
    let tod = secs % 86400;
    // Civil date from days since 1970-01-01 (H. Hinnant's algorithm).
    let z = days + 719468;
    let era = z.div_euclid(146097);
    let doe = z - era * 146097;
    let yoe = (doe - doe / 1460 + doe / 36524 - doe / 146096) / 365;
    let y = yoe + era * 400;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = if m <= 2 { y + 1 } else { y };
    let base = format!("runs/{graph}-{y:04}{m:02}{d:02}-{:02}{:02}{:02}", tod / 3600, (tod / 60) % 60, tod % 60);
    let mut p = PathBuf::from(&base);
    let mut k = 1;
    while p.exists() {
        k += 1;
        p = PathBuf::from(format!("{base}-{k}"));
    }
    p
}

/// A run id unique on this machine (iceoryx2 names are machine-global).
pub fn new_run_id(graph: &str) -> String {
    let nanos =
        std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.subsec_nanos()).unwrap_or(0);
    let g: String = graph.chars().filter(|c| c.is_ascii_alphanumeric() || *c == '-').take(24).collect();
    format!("{g}-{}-{:06}", std::process::id(), nanos / 1000)
}
