#![allow(clippy::unwrap_used)]
//! Crashes and bad input: kill -9 of a producer and of the recorder mid-run, and malformed
//! launch files.

mod common;
use common::*;
use sonoflow_launcher::testkit::{
    dangling_input_and_type_mismatch, out_of_range_params, two_producers, unknown_key, MINIMAL_GRAPH, TOML_SYNTAX_ERROR,
};
use sonoflow_mcap_io::{McapReader, ReadOptions};
use std::process::Command;

fn count(path: &std::path::Path, topic: &str) -> usize {
    let r = McapReader::open(path).unwrap();
    let mut n = 0;
    for m in r.messages(&ReadOptions { topics: Some(vec![topic.into()]), start_time: None, end_time: None }).unwrap() {
        m.unwrap();
        n += 1;
    }
    n
}

/// A clean small run: proves no stale resource from a killed run gets in the way.
fn next_run_is_clean() {
    let dir = tempfile::tempdir().unwrap();
    run_graph_ok("tests/launch/record.toml", dir.path(), &[]);
    assert_eq!(count(&dir.path().join("recording.mcap"), "rf_gain"), 40);
}

#[test]
fn kill9_of_a_producer_is_reported_and_the_recording_is_finished() {
    let dir = tempfile::tempdir().unwrap();
    let mut l = Launcher::start("tests/launch/kill.toml", dir.path(), &[]);
    let pid = l.node_pid("source");
    l.wait_line("progress");
    kill9(pid);
    let (code, log) = l.finish();
    assert_eq!(code, 1, "{log}");
    assert!(log.contains("node `source` (sonoflow node test-source) killed by signal 9 (SIGKILL)"), "{log}");
    // The recorder was stopped cleanly after the others: a complete file, marked incomplete.
    let rec = dir.path().join("recording.mcap");
    let r = McapReader::open(&rec).unwrap();
    assert!(r.is_complete());
    let n = count(&rec, "rf");
    assert!(n > 0, "frames recorded before the kill");
    let stats = r.metadata().into_iter().find(|(n, _)| n == "recording_stats").unwrap().1;
    assert_eq!(stats["complete"], "false");
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("report.json")).unwrap()).unwrap();
    assert_eq!(report["status"], "failed");
    next_run_is_clean();
}

#[test]
fn kill9_of_the_recorder_leaves_a_readable_and_recoverable_file() {
    let dir = tempfile::tempdir().unwrap();
    let mut l = Launcher::start("tests/launch/kill.toml", dir.path(), &[]);
    let pid = l.node_pid("recorder");
    l.wait_line("progress");
    std::thread::sleep(std::time::Duration::from_millis(500));
    kill9(pid);
    let (code, log) = l.finish();
    assert_eq!(code, 1, "{log}");
    assert!(log.contains("node `recorder` (sonoflow node recorder) killed by signal 9 (SIGKILL)"), "{log}");
    let rec = dir.path().join("recording.mcap");
    let r = McapReader::open(&rec).unwrap();
    assert!(!r.is_complete(), "no summary after kill -9");
    let n = count(&rec, "rf");
    assert!(n > 0, "the chunks closed before the kill are readable");
    // `sonoflow recover` turns it into a complete file with the same messages.
    let fixed = dir.path().join("fixed.mcap");
    let out = Command::new(bin()).arg("recover").arg(&rec).arg(&fixed).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(McapReader::open(&fixed).unwrap().is_complete());
    assert_eq!(count(&fixed, "rf"), n);
    next_run_is_clean();
}

fn check(text: &str, extra: &[&str]) -> (i32, String) {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("bad.toml");
    std::fs::write(&f, text).unwrap();
    let out = Command::new(bin()).arg("check").arg(&f).args(extra).output().unwrap();
    (out.status.code().unwrap_or(-1), String::from_utf8_lossy(&out.stderr).to_string())
}

#[test]
fn malformed_launch_files_give_one_clear_error_per_problem() {
    assert_eq!(check(MINIMAL_GRAPH, &[]).0, 0, "{}", check(MINIMAL_GRAPH, &[]).1);
    let cases: &[(&str, &[&str], &[&str])] = &[
        // unknown key
        (&unknown_key(), &[], &["unknown field `colour`"]),
        // dangling input + type mismatch + unknown topic
        (
            &dangling_input_and_type_mismatch(),
            &[],
            &[
                "carries RfFrameV3 but topic `iq` is IqFrameV3",
                "topic `iq` is consumed by checker but no node produces it",
            ],
        ),
        // out-of-range params, several at once
        (
            &out_of_range_params(),
            &[],
            &["n_channels = 0 is out of range: 1 ..= 1024", "topics.rf.max_elements = 0 is out of range"],
        ),
        // unknown kind, unknown port
        (&MINIMAL_GRAPH.replace("kind = \"checker\"", "kind = \"chekcer\""), &[], &["kind `chekcer` is unknown"]),
        (
            &MINIMAL_GRAPH.replace("outputs = { rf = \"rf\" }", "outputs = { rf = \"rf\", iq = \"rf\" }"),
            &[],
            &["no output port `iq`"],
        ),
        // two producers
        (&two_producers(), &[], &["topic `rf` has 2 producers"]),
        // bad --set and --swap
        (MINIMAL_GRAPH, &["--set", "source.n_frames=-3"], &["n_frames"]),
        (MINIMAL_GRAPH, &["--set", "nosuch.x=1"], &["no node `nosuch`"]),
        (MINIMAL_GRAPH, &["--swap", "source=fast"], &["node `source` has no variant `fast`"]),
        // exec that does not exist, TOML syntax error
        (
            &MINIMAL_GRAPH.replace("kind = \"checker\"", "exec = \"./no-such-binary\""),
            &[],
            &["exec `./no-such-binary` not found"],
        ),
        (TOML_SYNTAX_ERROR, &[], &["TOML parse error"]),
    ];
    for (text, extra, needles) in cases {
        let (code, err) = check(text, extra);
        assert_eq!(code, 2, "expected a check failure for {extra:?}:\n{text}\n{err}");
        for n in *needles {
            assert!(err.contains(n), "missing {n:?} in:\n{err}");
        }
        assert!(err.contains("nothing was started"), "{err}");
    }
}

#[test]
fn out_of_range_parameters_stop_the_run_before_any_process_starts() {
    let dir = tempfile::tempdir().unwrap();
    let out = run_graph("launch/quickstart.toml", dir.path(), &["--set", "flow.flow.diameter=-1"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("flow.diameter"), "{err}");
    assert!(!dir.path().join("logs").exists(), "nothing was started");
    for (set, needle) in [
        ("regulariser.order=5", "1, 2 or 3"),
        ("regulariser.s=0", "`s` = 0"),
        ("regulariser.weights=\"quality\"", "weights"),
        ("noise.outlier_fraction=1.5", "outlier_fraction"),
    ] {
        let out = run_graph("launch/regularise-demo.toml", dir.path(), &["--set", set]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{set}: {err}");
        assert!(err.contains(needle), "{set}: {err}");
        assert!(!dir.path().join("logs").exists(), "nothing was started");
    }
}

/// Ctrl-C (SIGINT to the launcher): the graph stops in order, the recording is a complete,
/// finished file, the report says `interrupted`, exit code 130.
#[test]
fn ctrl_c_stops_the_graph_and_finishes_the_recording() {
    let dir = tempfile::tempdir().unwrap();
    let mut l = Launcher::start("tests/launch/kill.toml", dir.path(), &[]);
    l.wait_line("progress");
    // SAFETY: kill(2) on our own child.
    unsafe {
        libc::kill(l.child.id() as i32, libc::SIGINT);
    }
    let (code, log) = l.finish();
    assert_eq!(code, 130, "{log}");
    let rec = dir.path().join("recording.mcap");
    let r = McapReader::open(&rec).unwrap();
    assert!(r.is_complete(), "{log}");
    assert!(count(&rec, "rf") > 0);
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("report.json")).unwrap()).unwrap();
    assert_eq!(report["status"], "interrupted");
    assert!(report["failures"].as_array().unwrap().is_empty(), "{report}");
}

/// A recording of a retired wire version (here an `rf` channel of schema RfFrameV1, as an older
/// sonoflow wrote it) is refused by `replay` with an error naming the version and its
/// replacement, not replayed as garbage.
#[test]
fn replay_refuses_a_retired_wire_version_naming_it() {
    use sonoflow_mcap_io::{ChannelSpec, OutMessage, RecorderWriter, WriterOptions};
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("old.mcap");
    let w = RecorderWriter::create(&rec, WriterOptions::default()).unwrap();
    let mut w = w;
    let ch = w
        .add_channel(ChannelSpec {
            topic: "rf".into(),
            message_encoding: "cdr".into(),
            schema_name: "sonoflow_msgs/msg/RfFrameV1".into(),
            schema_encoding: "ros2msg".into(),
            schema_data: b"sonoflow_msgs/RfFrameHeaderV1 header\nfloat32[] data\n".to_vec(),
            metadata: Default::default(),
        })
        .unwrap();
    w.write(OutMessage { channel: ch, sequence: 0, log_time: 1, publish_time: 1, data: vec![0, 1, 0, 0] }).unwrap();
    w.finish().unwrap();
    let out_dir = dir.path().join("run");
    let set = format!("replay.path={:?}", rec.display().to_string());
    let out = run_graph("tests/launch/replay.toml", &out_dir, &["--set", &set]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_ne!(out.status.code(), Some(0), "{err}");
    assert!(err.contains("RfFrameV1") && err.contains("retired") && err.contains("RfFrameV3"), "{err}");
}

/// A node's thread budget (`--set NODE.cpus=N`) reaches its process as `RAYON_NUM_THREADS` (and
/// `SONOFLOW_THREADS`); a node without one gets neither (its rayon pool takes every CPU).
#[test]
fn a_thread_budget_reaches_the_node_process() {
    let dir = tempfile::tempdir().unwrap();
    let mut l = Launcher::start("tests/launch/kill.toml", dir.path(), &["--set", "checker.cpus=3"]);
    let checker = l.node_pid("checker");
    let source = l.node_pid("source");
    let env = |pid: i32| -> Vec<String> {
        std::fs::read(format!("/proc/{pid}/environ"))
            .unwrap()
            .split(|b| *b == 0)
            .map(|v| String::from_utf8_lossy(v).to_string())
            .collect()
    };
    let (c, s) = (env(checker), env(source));
    assert!(c.iter().any(|v| v == "RAYON_NUM_THREADS=3") && c.iter().any(|v| v == "SONOFLOW_THREADS=3"), "{c:?}");
    assert!(!s.iter().any(|v| v.starts_with("SONOFLOW_THREADS=")), "{s:?}");
    kill9(source);
    let _ = l.finish();
}
