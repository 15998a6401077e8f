//! Helpers for the cross-process tests: every run gets its own service prefix (run id) and
//! output folder, and a guard kills the launcher (whose children get SIGTERM through their
//! parent-death signal) if a test fails midway.
#![allow(dead_code, clippy::unwrap_used)]

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::mpsc::{channel, Receiver};
use std::time::{Duration, Instant};

/// The `sonoflow` binary of this build (target/<profile>/sonoflow), built on first use together
/// with the external example nodes: cargo builds a workspace's binaries for the integration
/// tests of their own package only, and these tests live in a package of their own.
pub fn bin() -> &'static Path {
    static BIN: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    BIN.get_or_init(|| {
        // target/<profile>/deps/<test> → target/<profile>
        let exe = std::env::current_exe().expect("test executable path");
        let dir = exe.parent().and_then(Path::parent).expect("target/<profile>").to_path_buf();
        let mut cmd = Command::new(env!("CARGO"));
        cmd.args(["build", "--quiet", "--bins", "-p", "sonoflow", "-p", "sonoflow-external-nodes"]).current_dir(root());
        if dir.file_name().is_some_and(|n| n == "release") {
            cmd.arg("--release");
        }
        let status = cmd.status().expect("run cargo build");
        assert!(status.success(), "cargo build of the sonoflow binaries failed");
        let bin = dir.join("sonoflow");
        assert!(bin.is_file(), "{} was not built", bin.display());
        bin
    })
}

pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").canonicalize().expect("workspace root")
}

pub fn run_id(name: &str) -> String {
    let n = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap().subsec_nanos();
    format!("test-{name}-{}-{n}", std::process::id())
}

/// Runs `sonoflow run FILE --out OUT --run-id … EXTRA…` to completion.
pub fn run_graph(file: &str, out: &Path, extra: &[&str]) -> Output {
    let name = Path::new(file).file_stem().unwrap().to_string_lossy().to_string();
    let mut cmd = Command::new(bin());
    cmd.arg("run").arg(root().join(file)).arg("--out").arg(out).arg("--run-id").arg(run_id(&name)).args(extra);
    let out = cmd.output().expect("start sonoflow");
    if std::env::var_os("SONOFLOW_TEST_VERBOSE").is_some() {
        eprintln!("{}", String::from_utf8_lossy(&out.stderr));
    }
    out
}

/// [`run_graph`], asserting that the run succeeded (exit code 0; its log otherwise).
pub fn run_graph_ok(file: &str, out: &Path, extra: &[&str]) -> Output {
    let o = run_graph(file, out, extra);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    o
}

/// A launcher running in the background, with its stderr lines collected.
pub struct Launcher {
    pub child: Child,
    pub lines: Receiver<String>,
    pub seen: Vec<String>,
}

impl Launcher {
    pub fn start(file: &str, out: &Path, extra: &[&str]) -> Self {
        let name = Path::new(file).file_stem().unwrap().to_string_lossy().to_string();
        let mut child = Command::new(bin())
            .arg("run")
            .arg(root().join(file))
            .arg("--out")
            .arg(out)
            .arg("--run-id")
            .arg(run_id(&name))
            .args(extra)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start sonoflow");
        let (tx, rx) = channel();
        let err = child.stderr.take().unwrap();
        let tx2 = tx.clone();
        std::thread::spawn(move || {
            for l in BufReader::new(err).lines().map_while(Result::ok) {
                let _ = tx.send(l);
            }
        });
        let outp = child.stdout.take().unwrap();
        std::thread::spawn(move || {
            for l in BufReader::new(outp).lines().map_while(Result::ok) {
                let _ = tx2.send(l);
            }
        });
        Self { child, lines: rx, seen: Vec::new() }
    }

    /// Waits (bounded, 60 s) for a line containing `needle`; returns it.
    pub fn wait_line(&mut self, needle: &str) -> String {
        let deadline = Instant::now() + Duration::from_secs(60);
        while Instant::now() < deadline {
            if let Ok(l) = self.lines.recv_timeout(Duration::from_millis(100)) {
                self.seen.push(l.clone());
                if l.contains(needle) {
                    return l;
                }
            }
        }
        panic!("no line containing {needle:?}; seen:\n{}", self.seen.join("\n"));
    }

    /// Pid of a node from the launcher's "started node `NAME` … pid N" line.
    pub fn node_pid(&mut self, node: &str) -> i32 {
        let needle = format!("started node `{node}`");
        let l = match self.seen.iter().find(|l| l.contains(&needle)) {
            Some(l) => l.clone(),
            None => self.wait_line(&needle),
        };
        l.rsplit(' ').next().unwrap().parse().unwrap()
    }

    /// Waits (bounded, 60 s) for the launcher to exit; returns its exit code and all lines.
    pub fn finish(mut self) -> (i32, String) {
        let deadline = Instant::now() + Duration::from_secs(60);
        let code = loop {
            if let Some(st) = self.child.try_wait().unwrap() {
                break st.code().unwrap_or(-1);
            }
            assert!(Instant::now() < deadline, "launcher did not exit; seen:\n{}", self.seen.join("\n"));
            std::thread::sleep(Duration::from_millis(50));
        };
        std::thread::sleep(Duration::from_millis(100));
        while let Ok(l) = self.lines.try_recv() {
            self.seen.push(l);
        }
        (code, self.seen.join("\n"))
    }
}

impl Drop for Launcher {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

pub fn kill9(pid: i32) {
    // SAFETY: kill(2) on a pid we were told about.
    unsafe {
        libc::kill(pid, libc::SIGKILL);
    }
}

/// The figures `report.json` lists: each file exists under the run folder, decodes as a PNG of
/// the stated size, and report.md links it with its caption. Returns the file names.
pub fn checked_figures(run: &Path) -> Vec<String> {
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(run.join("report.json")).unwrap()).unwrap();
    let md = std::fs::read_to_string(run.join("report.md")).unwrap();
    let mut names = Vec::new();
    for f in report["figures"].as_array().expect("report.json lists figures") {
        let path = f["path"].as_str().unwrap();
        let dec = png::Decoder::new(std::fs::File::open(run.join(path)).unwrap_or_else(|e| panic!("{path}: {e}")));
        let mut rd = dec.read_info().unwrap();
        let mut buf = vec![0; rd.output_buffer_size()];
        let info = rd.next_frame(&mut buf).unwrap();
        assert_eq!(
            (u64::from(info.width), u64::from(info.height)),
            (f["width"].as_u64().unwrap(), f["height"].as_u64().unwrap()),
            "{path}"
        );
        assert!(info.width >= 300 && info.height >= 200, "{path}: {}×{}", info.width, info.height);
        // Not a blank canvas: the figure has drawn pixels.
        assert!(buf[..info.buffer_size()].iter().any(|b| *b < 128), "{path} is blank");
        assert!(md.contains(&format!("]({path})")), "report.md links {path}");
        assert!(md.contains(f["caption"].as_str().unwrap()), "report.md has the caption of {path}");
        names.push(path.trim_start_matches("figures/").to_string());
    }
    names
}

/// The raw payloads of every message on `topic` of a recording, in log order.
pub fn read_topic(path: &Path, topic: &str) -> Vec<Vec<u8>> {
    let r = sonoflow_mcap_io::McapReader::open(path).unwrap();
    r.messages(&sonoflow_mcap_io::ReadOptions { topics: Some(vec![topic.into()]), start_time: None, end_time: None })
        .unwrap()
        .map(|m| m.unwrap().data)
        .collect()
}

/// Runs `sonoflow TOOL ARGS…` (a batch tool) to the end: (exit code, stdout, stderr).
pub fn run_tool(tool: &str, args: &[&str]) -> (i32, String, String) {
    let out = Command::new(bin()).arg(tool).args(args).output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A path as a command-line argument.
pub fn arg(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Deterministic uniform numbers in [-1, 1) (a 64-bit LCG: test data, not statistics).
pub fn lcg_noise(seed: u64, n: usize) -> Vec<f64> {
    let mut state = seed;
    (0..n)
        .map(|_| {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            2.0 * ((state >> 11) as f64 / (1u64 << 53) as f64) - 1.0
        })
        .collect()
}
