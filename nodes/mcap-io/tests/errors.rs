//! Error cases: no overwrite, not-an-MCAP, missing files, unknown channels.

use std::{fs, io::ErrorKind};

use sonoflow_mcap_io::testkit::writer_with_channel;
use sonoflow_mcap_io::{recover, ChannelId, McapIoError, McapReader, OutMessage, RecorderWriter, WriterOptions};

#[test]
fn create_refuses_to_overwrite() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("exists.mcap");
    fs::write(&path, b"precious").expect("write");
    let err = match RecorderWriter::create(&path, WriterOptions::default()) {
        Ok(_) => panic!("create overwrote an existing file"),
        Err(e) => e,
    };
    assert!(matches!(&err, McapIoError::AlreadyExists { path: p } if *p == path), "{err:?}");
    assert!(err.to_string().contains(&path.display().to_string()), "{err}");
    assert_eq!(fs::read(&path).expect("read"), b"precious");
}

#[test]
fn create_in_a_missing_directory_names_the_path() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("no/such/dir/x.mcap");
    match RecorderWriter::create(&path, WriterOptions::default()) {
        Err(McapIoError::Io { path: p, source }) => {
            assert_eq!(p, path);
            assert_eq!(source.kind(), ErrorKind::NotFound);
        }
        Err(e) => panic!("unexpected error {e:?}"),
        Ok(_) => panic!("created a file in a missing directory"),
    }
}

#[test]
fn not_an_mcap_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    for (name, content) in [
        ("text.mcap", &b"this is plainly not an MCAP file\n"[..]),
        ("empty.mcap", &b""[..]),
        ("short.mcap", &b"\x89MCA"[..]),
    ] {
        let path = dir.path().join(name);
        fs::write(&path, content).expect("write");
        match McapReader::open(&path) {
            Err(McapIoError::NotMcap { path: p }) => assert_eq!(p, path),
            other => panic!("{name}: expected NotMcap, got {other:?}"),
        }
        let out = dir.path().join(format!("{name}.recovered"));
        assert!(matches!(recover(&path, &out), Err(McapIoError::NotMcap { .. })));
        assert!(!out.exists(), "recover must not create output for bad input");
    }
}

#[test]
fn opening_a_missing_file_names_the_path() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("missing.mcap");
    let err = McapReader::open(&path).expect_err("missing file opened");
    match &err {
        McapIoError::Io { path: p, source } => {
            assert_eq!(*p, path);
            assert_eq!(source.kind(), ErrorKind::NotFound);
        }
        other => panic!("expected Io, got {other:?}"),
    }
    assert!(err.to_string().contains("missing.mcap"), "{err}");
}

#[test]
fn writing_to_an_unknown_channel_fails() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("unknown.mcap");
    let (w, ch) = writer_with_channel(&path, WriterOptions::default(), "/a");
    for bad in [ChannelId(0), ChannelId(ch.0 + 1), ChannelId(u16::MAX)] {
        let r = w.write(OutMessage { channel: bad, sequence: 0, log_time: 0, publish_time: 0, data: vec![1] });
        assert!(matches!(r, Err(McapIoError::UnknownChannel(id)) if id == bad.0), "{r:?}");
    }
    let stats = w.finish().expect("finish");
    assert_eq!(stats.messages_written["/a"], 0);
}
