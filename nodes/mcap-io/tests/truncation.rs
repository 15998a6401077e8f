//! Unfinished and damaged files: linear reading, `recover`, and a real `kill -9`.

use std::{
    fs,
    path::{Path, PathBuf},
    process::{Child, Command, Stdio},
    thread::sleep,
    time::{Duration, Instant},
};

use sonoflow_mcap_io::testkit::{
    assert_prefix, finished_recording, payload, read_all, read_and_recover, write_n, writer_with_channel, Damaged,
    Expected, FinishedRecording,
};
use sonoflow_mcap_io::{recover, McapIoError, McapReader, OutMessage, ReadOptions, WriterOptions};

/// Checks that `recovered` is a finished file holding exactly `expected` (which it must read
/// back in order), also by the mcap crate's strict readers.
fn assert_recovered(recovered: &Path, expected: &[Expected]) {
    let (r, got) = read_all(recovered);
    assert!(r.is_complete(), "recovered file must be complete");
    assert_eq!(assert_prefix(&got, expected), expected.len());
    let bytes = fs::read(recovered).expect("read recovered");
    let summary = mcap::Summary::read(&bytes).expect("summary").expect("recovered file has a summary");
    assert_eq!(summary.stats.as_ref().map(|s| s.message_count), Some(expected.len() as u64));
    let strict = mcap::MessageStream::new(&bytes)
        .expect("stream")
        .collect::<Result<Vec<_>, _>>()
        .expect("strict reader accepts the recovered file");
    assert_eq!(strict.len(), expected.len());
}

#[test]
fn abandoned_writer_leaves_a_readable_prefix() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("abandoned.mcap");
    let opts =
        WriterOptions { chunk_size: 64 * 1024, flush_interval: Duration::from_secs(3600), ..WriterOptions::default() };
    let (w, ch) = writer_with_channel(&path, opts, "/a");
    let expected = write_n(&w, ch, "/a", 100, 10 * 1024);
    w.abandon().expect("abandon");

    let (r, got) = read_all(&path);
    assert!(!r.is_complete());
    let n = assert_prefix(&got, &expected);
    // 6 messages per 64 KiB chunk: 16 closed chunks (96 messages); the open one is lost.
    assert!((90..100).contains(&n), "read {n} messages");
    assert_eq!(r.topics()[0].message_count, Some(n as u64));
    assert_eq!(r.truncated_bytes(), 0, "abandon stops at a chunk boundary");

    let out = dir.path().join("recovered.mcap");
    let stats = recover(&path, &out).expect("recover");
    assert_eq!(stats.messages, n as u64);
    assert!(!stats.was_complete);
    assert_eq!(stats.truncated_bytes, 0);
    assert_recovered(&out, &expected[..n]);
}

/// The testkit's finished recording in a folder of its own.
struct Finished {
    _dir: tempfile::TempDir,
    rec: FinishedRecording,
}

impl std::ops::Deref for Finished {
    type Target = FinishedRecording;
    fn deref(&self) -> &FinishedRecording {
        &self.rec
    }
}

/// A finished file with two channels, many small chunks, and metadata + an attachment near the
/// start.
fn finished_file() -> Finished {
    let dir = tempfile::tempdir().expect("tempdir");
    let rec = finished_recording(dir.path());
    assert!(rec.summary.chunk_indexes.len() >= 10);
    Finished { _dir: dir, rec }
}

/// Writes `bytes` to a new file, opens it, and checks the linear read and `recover`.
fn check_damaged(f: &Finished, name: &str, bytes: &[u8], want: usize, want_extras: bool) {
    let Damaged { reader: r, read: got, stats, recovered: out } = read_and_recover(f, name, bytes);
    assert!(!r.is_complete(), "{name}: must not be complete");
    assert_eq!(assert_prefix(&got, &f.expected), want, "{name}: wrong number of messages");
    if want_extras {
        assert_eq!(r.metadata(), vec![("run".to_string(), f.run_meta.clone())]);
        assert_eq!(r.attachments().len(), 1, "{name}");
    }
    assert_eq!(stats.messages, want as u64, "{name}");
    assert!(!stats.was_complete);
    assert_eq!(stats.truncated_bytes, r.truncated_bytes());
    assert_recovered(&out, &f.expected[..want]);
    if want_extras {
        let rr = McapReader::open(&out).expect("open recovered");
        assert_eq!(rr.metadata(), vec![("run".to_string(), f.run_meta.clone())]);
        assert_eq!(rr.attachments(), vec![("config".to_string(), "text/plain".to_string(), f.config.clone())]);
    }
}

#[test]
fn truncated_in_the_middle_of_the_last_chunk() {
    let f = finished_file();
    let (bytes, want) = f.cut_in_last_chunk();
    assert!(want > 0 && want < f.expected.len());
    check_damaged(&f, "cut-last-chunk", &bytes, want, true);
}

#[test]
fn truncated_in_the_middle_of_an_earlier_chunk() {
    let f = finished_file();
    let c = &f.summary.chunk_indexes[f.summary.chunk_indexes.len() / 2];
    let cut = c.chunk_start_offset + 20;
    let want = f.messages_before(cut);
    assert!(want > 0 && want < f.expected.len());
    check_damaged(&f, "cut-mid-chunk", &f.bytes[..cut as usize], want, true);
}

#[test]
fn truncated_in_the_summary_or_footer() {
    let f = finished_file();
    let all = f.expected.len();
    let data_end = f.summary.chunk_indexes.iter().map(|c| c.chunk_start_offset + c.chunk_length).max().expect("chunks");
    let len = f.bytes.len();
    // Somewhere in the summary section, and inside the footer / end magic.
    let summary_cut = (data_end as usize + len) / 2;
    check_damaged(&f, "cut-summary", &f.bytes[..summary_cut], all, true);
    check_damaged(&f, "cut-magic", &f.bytes[..len - 3], all, true);
}

#[test]
fn truncated_right_after_the_header() {
    let f = finished_file();
    // Magic (8) + the header record: no chunk survives.
    check_damaged(&f, "cut-header", &f.bytes[..f.header_end() + 5], 0, false);
}

#[test]
fn zeroed_or_corrupt_tail_stops_the_linear_read_cleanly() {
    let f = finished_file();

    // A power loss can leave zeros where the last data should be.
    let (zeroed, want) = f.zeroed_tail();
    check_damaged(&f, "zeroed-tail", &zeroed, want, true);

    // Damaged compressed bytes in the last chunk of an unfinished file: the chunk's CRC fails.
    let (corrupt, want) = f.corrupt_last_chunk();
    check_damaged(&f, "corrupt-last-chunk", &corrupt, want, true);
}

#[test]
fn recovering_a_complete_file_copies_everything() {
    let f = finished_file();
    let out = f.path.with_file_name("copy.mcap");
    let stats = recover(&f.path, &out).expect("recover");
    assert!(stats.was_complete);
    assert_eq!(stats.truncated_bytes, 0);
    assert_eq!(stats.messages, f.expected.len() as u64);
    assert_recovered(&out, &f.expected);
    let r = McapReader::open(&out).expect("open");
    assert_eq!(r.profile(), "sonoflow");
    assert_eq!(r.metadata(), vec![("run".to_string(), f.run_meta.clone())]);
    assert_eq!(r.attachments().len(), 1);
    let topics: Vec<_> = r.topics().into_iter().map(|t| t.topic).collect();
    assert_eq!(topics, vec!["/a".to_string(), "/b".to_string()]);

    // recover never overwrites.
    let before = fs::read(&out).expect("read");
    match recover(&f.path, &out) {
        Err(McapIoError::AlreadyExists { path }) => assert_eq!(path, out),
        other => panic!("expected AlreadyExists, got {other:?}"),
    }
    assert_eq!(fs::read(&out).expect("read"), before);
}

// ---- a real kill -9 ------------------------------------------------------------------------

const CHILD_ENV: &str = "SONOFLOW_MCAP_IO_KILL9_DIR";
const KILL9_FLUSH: Duration = Duration::from_millis(100);

/// Not a test on its own: the body of the child process of
/// `kill_minus_9_loses_at_most_the_flush_interval` (does nothing unless started by it).
#[test]
fn kill9_child_writer() {
    let Some(dir) = std::env::var_os(CHILD_ENV) else {
        return;
    };
    let dir = PathBuf::from(dir);
    let opts = WriterOptions {
        flush_interval: KILL9_FLUSH,
        ..WriterOptions::default() // 4 MiB chunks: only the timer closes them
    };
    let (w, ch) = writer_with_channel(&dir.join("rec.mcap"), opts, "/k");
    for seq in 0u32.. {
        let t = 1000 * (u64::from(seq) + 1);
        w.write(OutMessage {
            channel: ch,
            sequence: seq,
            log_time: t,
            publish_time: t + 1,
            data: payload(u64::from(seq) + 7, 2000),
        })
        .expect("write");
        if seq % 20 == 0 {
            // "messages 0..=seq have been handed to write()"
            let tmp = dir.join("progress.tmp");
            fs::write(&tmp, seq.to_string()).expect("progress");
            fs::rename(&tmp, dir.join("progress")).expect("rename");
        }
        sleep(Duration::from_millis(1));
    }
}

struct KillOnDrop(Child);

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
fn kill_minus_9_loses_at_most_the_flush_interval() {
    let dir = tempfile::tempdir().expect("tempdir");
    let exe = std::env::current_exe().expect("test binary");
    let child = Command::new(exe)
        .args(["kill9_child_writer", "--exact", "--test-threads=1"])
        .env(CHILD_ENV, dir.path())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn child");
    let mut child = KillOnDrop(child);

    let progress = dir.path().join("progress");
    let start = Instant::now();
    let handed_over: u32 = loop {
        assert!(start.elapsed() < Duration::from_secs(60), "child made no progress");
        if let Some(n) = fs::read_to_string(&progress).ok().and_then(|s| s.trim().parse::<u32>().ok()) {
            if n >= 200 {
                break n;
            }
        }
        assert!(child.0.try_wait().expect("try_wait").is_none(), "child exited early");
        sleep(Duration::from_millis(20));
    };
    // Everything handed over now must be on disk after 10 flush intervals, kill -9 or not.
    sleep(KILL9_FLUSH * 10);
    child.0.kill().expect("SIGKILL");
    child.0.wait().expect("wait");

    let path = dir.path().join("rec.mcap");
    let r = McapReader::open(&path).expect("open");
    assert!(!r.is_complete());
    let got = r
        .messages(&ReadOptions::default())
        .expect("messages")
        .collect::<Result<Vec<_>, _>>()
        .expect("linear read of a killed recording");
    assert!(
        got.len() > handed_over as usize,
        "only {} messages survived, {} were handed over a second before the kill",
        got.len(),
        handed_over + 1
    );
    for (i, m) in got.iter().enumerate() {
        assert_eq!(m.sequence, i as u32);
        assert_eq!(m.data, payload(i as u64 + 7, 2000));
    }
    let out = dir.path().join("rec-recovered.mcap");
    let stats = recover(&path, &out).expect("recover");
    assert_eq!(stats.messages, got.len() as u64);
    let (rr, again) = read_all(&out);
    assert!(rr.is_complete());
    assert_eq!(again, got);
}
