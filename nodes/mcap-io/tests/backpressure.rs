//! The queue between caller and writer thread is bounded in bytes and never drops.

use sonoflow_mcap_io::testkit::{payload, read_all, writer_with_channel};
use sonoflow_mcap_io::{OutMessage, WriterOptions};

const MIB: usize = 1024 * 1024;

#[test]
fn tiny_queue_blocks_the_caller_and_loses_nothing() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("bp.mcap");
    let opts = WriterOptions { queue_bytes: MIB, ..WriterOptions::default() };
    let (w, ch) = writer_with_channel(&path, opts, "/big");
    let n = 50u32;
    for seq in 0..n {
        w.write(OutMessage {
            channel: ch,
            sequence: seq,
            log_time: u64::from(seq),
            publish_time: u64::from(seq),
            data: payload(u64::from(seq), MIB),
        })
        .expect("write");
        let stats = w.stats();
        // A 1 MiB message (plus record overhead) never fits next to another one in a 1 MiB
        // queue, so `write` may only return once everything before it has been written.
        assert!(
            stats.messages_written["/big"] >= u64::from(seq),
            "write #{seq} returned with only {} messages written: no back-pressure",
            stats.messages_written["/big"]
        );
        assert!(stats.bytes_queued <= (MIB + 64) as u64, "queue holds {} bytes", stats.bytes_queued);
    }
    let stats = w.finish().expect("finish");
    assert_eq!(stats.messages_written["/big"], u64::from(n));
    assert_eq!(stats.bytes_written, u64::from(n) * MIB as u64);
    let (r, got) = read_all(&path);
    assert!(r.is_complete());
    assert_eq!(got.len(), n as usize);
    for (seq, m) in got.iter().enumerate() {
        assert_eq!(m.sequence, seq as u32);
        assert!(m.data == payload(seq as u64, MIB), "payload {seq} differs");
    }
}

#[test]
fn queue_holds_several_small_messages_but_not_more_than_the_bound() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("bp-small.mcap");
    let queue_bytes = 256 * 1024;
    let opts = WriterOptions { queue_bytes, chunk_size: 256 * 1024, ..WriterOptions::default() };
    let (w, ch) = writer_with_channel(&path, opts, "/s");
    let n = 3000u32;
    for seq in 0..n {
        w.write(OutMessage {
            channel: ch,
            sequence: seq,
            log_time: u64::from(seq),
            publish_time: 0,
            data: payload(u64::from(seq), 4000),
        })
        .expect("write");
        assert!(w.stats().bytes_queued <= queue_bytes as u64);
    }
    w.finish().expect("finish");
    let (_, got) = read_all(&path);
    assert_eq!(got.len(), n as usize);
    assert!(got.iter().enumerate().all(|(i, m)| m.sequence == i as u32 && m.data == payload(i as u64, 4000)));
}

/// Buffers come back from the writer thread and are reused, with their capacity.
#[test]
fn written_buffers_are_reused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("pool.mcap");
    let mut w = sonoflow_mcap_io::RecorderWriter::create(&path, sonoflow_mcap_io::WriterOptions::default()).unwrap();
    let ch = w
        .add_channel(sonoflow_mcap_io::ChannelSpec {
            topic: "t".into(),
            message_encoding: "raw".into(),
            schema_name: String::new(),
            schema_encoding: String::new(),
            schema_data: Vec::new(),
            metadata: Default::default(),
        })
        .unwrap();
    let mut data = w.buffer(1 << 20);
    data.resize(1 << 20, 7);
    let ptr = data.as_ptr();
    w.write(sonoflow_mcap_io::OutMessage { channel: ch, sequence: 0, log_time: 0, publish_time: 0, data }).unwrap();
    // Wait until the writer thread has handed it back.
    let mut again = Vec::new();
    for _ in 0..200 {
        again = w.buffer(1 << 20);
        if again.as_ptr() == ptr {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    assert_eq!(again.as_ptr(), ptr, "the same allocation comes back");
    assert!(again.is_empty() && again.capacity() >= 1 << 20);
    w.finish().unwrap();
}
