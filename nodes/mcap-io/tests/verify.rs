//! `McapReader::verify` (behind `sonoflow inspect --verify`) and `unfinished_note` (the replay
//! node's warning).

use std::{collections::BTreeMap, fs, path::Path, time::Duration};

use sonoflow_mcap_io::testkit::{simple_spec, write_n};
use sonoflow_mcap_io::{Compression, McapReader, MessageView, RecorderWriter, Verification, WriterOptions};

fn opts(compression: Compression) -> WriterOptions {
    WriterOptions {
        compression,
        chunk_size: 64 * 1024,
        flush_interval: Duration::from_secs(3600),
        ..Default::default()
    }
}

/// A finished file: 40 messages of 10 KiB on `/a`, 20 on `/b`, many chunks.
fn finished(path: &Path, compression: Compression) -> mcap::Summary {
    let mut w = RecorderWriter::create(path, opts(compression)).expect("create");
    let a = w.add_channel(simple_spec("/a")).expect("a");
    let b = w.add_channel(simple_spec("/b")).expect("b");
    write_n(&w, a, "/a", 40, 10 * 1024);
    write_n(&w, b, "/b", 20, 10 * 1024);
    w.metadata("run", BTreeMap::from([("seed".to_string(), "1".to_string())])).expect("metadata");
    w.finish().expect("finish");
    let bytes = fs::read(path).expect("read");
    let summary = mcap::Summary::read(&bytes).expect("summary").expect("some summary");
    assert!(summary.chunk_indexes.len() >= 5, "{} chunks", summary.chunk_indexes.len());
    summary
}

fn verify_all(path: &Path) -> Verification {
    McapReader::open(path).expect("open").verify(&mut |_: &MessageView<'_>| Ok(()))
}

fn counts(v: &Verification) -> Vec<(String, u64, Option<u64>)> {
    v.topics.iter().map(|t| (t.topic.clone(), t.decoded, t.summary)).collect()
}

#[test]
fn an_intact_file_passes_and_every_message_is_checked() {
    for compression in [Compression::Zstd, Compression::Lz4, Compression::None] {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("ok.mcap");
        let summary = finished(&path, compression);
        let mut seen = 0u64;
        let v = McapReader::open(&path).expect("open").verify(&mut |m: &MessageView<'_>| {
            seen += 1;
            assert!(m.topic == "/a" || m.topic == "/b");
            assert_eq!(m.schema_name, "bytes");
            assert_eq!(m.data.len(), 10 * 1024);
            Ok(())
        });
        assert!(v.is_ok(), "{compression}: {:?}", v.problems);
        assert_eq!(seen, 60);
        assert_eq!(v.messages(), 60);
        assert_eq!(v.chunks, summary.chunk_indexes.len() as u64);
        assert_eq!(counts(&v), [("/a".to_string(), 40, Some(40)), ("/b".to_string(), 20, Some(20))]);
    }
}

#[test]
fn flipped_bytes_inside_a_chunk_fail_and_name_the_chunk() {
    for compression in [Compression::Zstd, Compression::None] {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("flipped.mcap");
        let summary = finished(&path, compression);
        let chunk = &summary.chunk_indexes[2];
        let mut bytes = fs::read(&path).expect("read");
        let mid = (chunk.chunk_start_offset + chunk.chunk_length / 2) as usize;
        for b in &mut bytes[mid..mid + 200] {
            *b ^= 0xFF;
        }
        fs::write(&path, &bytes).expect("write");

        // The summary is intact: the file still opens as complete.
        let r = McapReader::open(&path).expect("open");
        assert!(r.is_complete());
        let v = verify_all(&path);
        assert!(!v.is_ok());
        let first = &v.problems[0];
        assert!(
            first.starts_with(&format!("chunk record at byte offset {}: ", chunk.chunk_start_offset)),
            "{compression}: {first}"
        );
        if compression == Compression::None {
            // Nothing to fail in decompression: the CRC must catch it.
            assert!(first.contains("Chunk CRC failed"), "{first}");
        }
        assert_eq!(v.chunks, 2, "the two chunks before the damaged one are intact");
    }
}

#[test]
fn a_changed_byte_outside_the_chunks_fails_the_data_section_crc() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("index.mcap");
    let summary = finished(&path, Compression::Zstd);
    // The message index records follow each chunk; change the last byte of the first one (the
    // high byte of an offset): it still parses, only the data section CRC can tell.
    let chunk = &summary.chunk_indexes[0];
    let index_start = chunk.chunk_start_offset + chunk.chunk_length;
    let index_end = index_start + chunk.message_index_length;
    let mut bytes = fs::read(&path).expect("read");
    assert_eq!(bytes[index_start as usize], 0x07, "a message index record follows the chunk");
    let i = (chunk.chunk_start_offset + chunk.chunk_length + 9 + 2 + 4 + 16 - 1) as usize;
    assert!((i as u64) < index_end);
    bytes[i] ^= 0x01;
    fs::write(&path, &bytes).expect("write");
    let v = verify_all(&path);
    assert_eq!(v.problems.len(), 1, "{:?}", v.problems);
    assert!(v.problems[0].starts_with("data end record at byte offset "), "{}", v.problems[0]);
    assert!(v.problems[0].contains("data section CRC failed"), "{}", v.problems[0]);
    assert_eq!(v.messages(), 60, "every message still decodes");
}

#[test]
fn message_check_failures_are_reported_and_the_walk_goes_on() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("check.mcap");
    finished(&path, Compression::Zstd);
    let v = McapReader::open(&path).expect("open").verify(&mut |m: &MessageView<'_>| {
        if m.topic == "/b" && m.sequence >= 3 {
            Err(format!("payload of {} bytes is not what I want", m.data.len()))
        } else {
            Ok(())
        }
    });
    assert_eq!(v.messages(), 60);
    assert_eq!(v.problems.len(), 1, "{:?}", v.problems);
    let p = &v.problems[0];
    assert!(p.starts_with("message 3 on `/b` (log time 4000, in the chunk at byte offset "), "{p}");
    assert!(
        p.contains("does not decode: payload of 10240 bytes is not what I want (16 more do not decode either)"),
        "{p}"
    );
}

#[test]
fn an_unfinished_file_fails_verification_but_its_messages_are_counted() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("abandoned.mcap");
    let mut w = RecorderWriter::create(&path, opts(Compression::Zstd)).expect("create");
    let a = w.add_channel(simple_spec("/a")).expect("a");
    write_n(&w, a, "/a", 50, 10 * 1024);
    w.abandon().expect("abandon");
    let r = McapReader::open(&path).expect("open");
    assert!(!r.is_complete());
    let readable = r.topics()[0].message_count.expect("count");
    assert!((40..50).contains(&readable), "{readable}");

    let v = verify_all(&path);
    assert_eq!(counts(&v), [("/a".to_string(), readable, None)]);
    assert_eq!(v.problems.len(), 1, "{:?}", v.problems);
    assert!(v.problems[0].contains("without a footer: it is unfinished"), "{}", v.problems[0]);

    // Cut inside the last chunk: a truncated record.
    let bytes = fs::read(&path).expect("read");
    let cut = dir.path().join("cut.mcap");
    fs::write(&cut, &bytes[..bytes.len() - 100]).expect("write");
    let v = verify_all(&cut);
    assert!(v.problems[0].contains("runs past the end of the file"), "{}", v.problems[0]);
}

#[test]
fn the_unfinished_note_says_how_much_was_read() {
    let dir = tempfile::tempdir().expect("tempdir");
    let done = dir.path().join("done.mcap");
    finished(&done, Compression::Lz4);
    assert_eq!(McapReader::open(&done).expect("open").unfinished_note(), None);

    let path = dir.path().join("abandoned.mcap");
    let mut w = RecorderWriter::create(&path, opts(Compression::Lz4)).expect("create");
    let a = w.add_channel(simple_spec("/a")).expect("a");
    let b = w.add_channel(simple_spec("/b")).expect("b");
    write_n(&w, a, "/a", 30, 10 * 1024);
    write_n(&w, b, "/b", 30, 10 * 1024);
    w.abandon().expect("abandon");
    let bytes = fs::read(&path).expect("read");
    fs::write(&path, &bytes[..bytes.len() - 10]).expect("cut");
    let r = McapReader::open(&path).expect("open");
    let n: u64 = r.topics().iter().filter_map(|t| t.message_count).sum();
    assert!(n > 0, "{n}");
    let note = r.unfinished_note().expect("a note for an unfinished file");
    assert!(note.starts_with(&format!("{} is unfinished (no summary", path.display())), "{note}");
    assert!(note.contains(&format!(": {n} message(s) read from ")), "{note}");
    assert!(note.contains(&format!("the last {} byte(s) are unreadable", r.truncated_bytes())), "{note}");
    assert!(r.truncated_bytes() > 0);
}

/// Damage inside a chunk is an error for every reader, never a panic (the mcap crate's own
/// chunk reader would try to allocate a garbage record length).
#[test]
fn damaged_chunks_are_errors_not_panics_for_every_reader() {
    for compression in [Compression::Zstd, Compression::Lz4, Compression::None] {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("full.mcap");
        let summary = finished(&path, compression);
        let bytes = fs::read(&path).expect("read");
        for (k, chunk) in summary.chunk_indexes.iter().enumerate().take(4) {
            for (shift, pattern) in [(0u64, 0xFFu8), (17, 0x5A), (chunk.chunk_length / 3, 0x01)] {
                let mut damaged = bytes.clone();
                let start = (chunk.chunk_start_offset + chunk.chunk_length / 2 + shift) as usize;
                let end = (start + 200).min((chunk.chunk_start_offset + chunk.chunk_length) as usize);
                for b in &mut damaged[start..end] {
                    *b ^= pattern;
                }
                // Complete file (indexed read) and the same cut before its summary (linear read).
                let cut = (chunk.chunk_start_offset + chunk.chunk_length) as usize + 5;
                for (name, content) in [("complete", &damaged[..]), ("unfinished", &damaged[..cut])] {
                    let p = dir.path().join(format!("{name}-{k}-{shift}.mcap"));
                    fs::write(&p, content).expect("write");
                    let r = McapReader::open(&p).expect("open");
                    let read: Vec<_> =
                        r.messages(&sonoflow_mcap_io::ReadOptions::default()).expect("messages").collect();
                    if name == "complete" {
                        assert!(read.iter().any(|m| m.is_err()), "{compression} {name} chunk {k}: damage unnoticed");
                    } else {
                        // The damaged chunk and what follows are the cut-off tail.
                        assert!(read.iter().all(|m| m.is_ok()));
                    }
                    let v = r.verify(&mut |_: &MessageView<'_>| Ok(()));
                    assert!(
                        v.problems[0]
                            .starts_with(&format!("chunk record at byte offset {}: ", chunk.chunk_start_offset)),
                        "{compression} {name} chunk {k}: {:?}",
                        v.problems
                    );
                }
            }
        }
    }
}
