//! The open chunk is closed every `flush_interval`: what is on disk while the writer is still
//! running is readable.

use std::{fs, thread::sleep, time::Duration};

use sonoflow_mcap_io::testkit::{assert_prefix, read_all, write_n, writer_with_channel};
use sonoflow_mcap_io::WriterOptions;

fn snapshot(src: &std::path::Path, dst: &std::path::Path) {
    // Copy the bytes as they are on disk right now, while the writer is still open.
    fs::copy(src, dst).expect("copy");
}

#[test]
fn flush_interval_puts_small_messages_on_disk() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("live.mcap");
    let opts = WriterOptions {
        flush_interval: Duration::from_millis(100),
        ..WriterOptions::default() // 4 MiB chunks: only the timer can close them here
    };
    let (w, ch) = writer_with_channel(&path, opts, "/slow");
    let expected = write_n(&w, ch, "/slow", 5, 200);
    sleep(Duration::from_millis(600));
    assert!(w.stats().file_bytes > 0);

    let snap1 = dir.path().join("snap1.mcap");
    snapshot(&path, &snap1);
    let (r, got) = read_all(&snap1);
    assert!(!r.is_complete());
    assert_eq!(assert_prefix(&got, &expected), 5);
    assert_eq!(r.topics().len(), 1);
    assert_eq!(r.topics()[0].message_count, Some(5));

    // More messages later, while the writer is still open.
    let more: Vec<_> = (5..8u32)
        .map(|seq| {
            let data = sonoflow_mcap_io::testkit::payload(u64::from(seq) + 7, 200);
            let t = 1000 * (u64::from(seq) + 1);
            w.write(sonoflow_mcap_io::OutMessage {
                channel: ch,
                sequence: seq,
                log_time: t,
                publish_time: t + 1,
                data: data.clone(),
            })
            .expect("write");
            sonoflow_mcap_io::testkit::Expected {
                topic: "/slow".into(),
                sequence: seq,
                log_time: t,
                publish_time: t + 1,
                data,
            }
        })
        .collect();
    sleep(Duration::from_millis(600));
    let snap2 = dir.path().join("snap2.mcap");
    snapshot(&path, &snap2);
    let all: Vec<_> = expected.into_iter().chain(more).collect();
    let (r2, got2) = read_all(&snap2);
    assert!(!r2.is_complete());
    assert_eq!(assert_prefix(&got2, &all), 8);

    w.finish().expect("finish");
    let (r3, got3) = read_all(&path);
    assert!(r3.is_complete());
    assert_eq!(got3.len(), 8);
}

#[test]
fn without_a_timer_flush_the_open_chunk_stays_in_memory() {
    // Control for the test above: the snapshot only has the messages because of the timer.
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("no-timer.mcap");
    let opts = WriterOptions { flush_interval: Duration::from_secs(3600), ..WriterOptions::default() };
    let (w, ch) = writer_with_channel(&path, opts, "/slow");
    write_n(&w, ch, "/slow", 5, 200);
    sleep(Duration::from_millis(300));
    let snap = dir.path().join("snap.mcap");
    snapshot(&path, &snap);
    let (r, got) = read_all(&snap);
    assert!(!r.is_complete());
    assert!(got.is_empty());
    w.finish().expect("finish");
    assert_eq!(read_all(&path).1.len(), 5);
}
