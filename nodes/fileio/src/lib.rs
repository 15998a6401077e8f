//! Files that other programs read: atomic writes and `.npy` arrays.
//!
//! * [`write_atomic`] / [`write_atomic_with`]: a reader sees the old file or the new one, never
//!   half of it, even after a crash or power loss.
//! * [`npy`]: NumPy `.npy` arrays (the batch tools' input and output format).

pub mod npy;

use std::io::{self, BufWriter, Write};
use std::path::Path;

/// Writes a file atomically, so no reader ever sees half of it. See [`write_atomic_with`].
pub fn write_atomic(path: &Path, data: &[u8]) -> io::Result<()> {
    write_atomic_with(path, |w| w.write_all(data))
}

/// Writes a file atomically from a writer closure (for large files that need not be assembled
/// in memory first).
///
/// `write` fills a uniquely named temporary file (`.<name>.<random>.tmp`) in the folder of
/// `path`, so concurrent writers of one path, or of paths that differ only in their extension,
/// never share a temporary file. The file is then fsynced, renamed over `path` and the folder is
/// fsynced (Unix), so after a crash `path` holds either the old or the complete new content.
/// The new file gets the usual permissions of a new file (`0o666` less the umask), not those of
/// the file it replaces.
///
/// If `write` (or anything after it) fails, the temporary file is removed and `path` is left as
/// it was. Errors carry the path in their message.
pub fn write_atomic_with<F>(path: &Path, write: F) -> io::Result<()>
where
    F: FnOnce(&mut dyn Write) -> io::Result<()>,
{
    let named = |what: &str, e: io::Error| io::Error::new(e.kind(), format!("{what} {}: {e}", path.display()));
    let name = path
        .file_name()
        .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, format!("{} has no file name", path.display())))?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let mut prefix = std::ffi::OsString::from(".");
    prefix.push(name);
    prefix.push(".");
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix).suffix(".tmp");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        // tempfile's default is 0o600; a replaced file should be as readable as a created one
        // (the mode is still reduced by the umask).
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    // Dropping `tmp` before `persist` (any early return) deletes the temporary file.
    let mut tmp = builder.tempfile_in(dir).map_err(|e| named("creating a temporary file for", e))?;
    {
        let mut w = BufWriter::new(tmp.as_file_mut());
        write(&mut w).map_err(|e| named("writing", e))?;
        w.flush().map_err(|e| named("writing", e))?;
    }
    tmp.as_file().sync_all().map_err(|e| named("syncing", e))?;
    tmp.persist(path).map_err(|e| named("renaming the temporary file to", e.error))?;
    sync_dir(dir).map_err(|e| named("syncing the folder of", e))
}

/// Makes a rename in `dir` durable (Unix: fsync of the directory; elsewhere nothing to do).
fn sync_dir(dir: &Path) -> io::Result<()> {
    #[cfg(unix)]
    {
        std::fs::File::open(dir)?.sync_all()
    }
    #[cfg(not(unix))]
    {
        let _ = dir;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    /// Names in `dir` other than `keep`.
    fn leftovers(dir: &Path, keep: &[&str]) -> Vec<PathBuf> {
        std::fs::read_dir(dir)
            .expect("read dir")
            .map(|e| e.expect("dir entry").path())
            .filter(|p| !keep.iter().any(|k| p.file_name().is_some_and(|n| n == *k)))
            .collect()
    }

    #[test]
    fn same_stem_and_same_path_writers_do_not_share_a_temporary_file() {
        let dir = tempfile::tempdir().expect("tempdir");
        let npy = dir.path().join("a.npy");
        let json = dir.path().join("a.json");
        // Large enough that the writes overlap in time.
        let content = |tag: u8, i: usize| -> Vec<u8> {
            let mut v = vec![tag; 200_000];
            v[..8].copy_from_slice(&(i as u64).to_le_bytes());
            v
        };
        let writers: Vec<_> = [(npy.clone(), b'n'), (json.clone(), b'j'), (npy.clone(), b'N'), (json.clone(), b'J')]
            .into_iter()
            .map(|(path, tag)| {
                std::thread::spawn(move || {
                    for i in 0..50 {
                        write_atomic(&path, &content(tag, i)).expect("write_atomic");
                    }
                })
            })
            .collect();
        for w in writers {
            w.join().expect("writer thread");
        }
        for (path, tags) in [(&npy, [b'n', b'N']), (&json, [b'j', b'J'])] {
            let got = std::fs::read(path).expect("read back");
            assert_eq!(got.len(), 200_000, "{} is incomplete", path.display());
            assert_eq!(u64::from_le_bytes(got[..8].try_into().expect("8 bytes")), 49, "{}", path.display());
            // One writer's content, whole: never the other file's bytes nor a mix.
            assert!(tags.contains(&got[8]), "{} holds another file's data", path.display());
            assert!(got[8..].iter().all(|&b| b == got[8]), "{} mixes two writers", path.display());
        }
        assert_eq!(leftovers(dir.path(), &["a.npy", "a.json"]), Vec::<PathBuf>::new(), "temporary files left");
    }

    #[test]
    fn a_failing_writer_leaves_the_old_file_and_no_temporary_file() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("report.json");
        write_atomic(&path, b"old").expect("first write");
        let err = write_atomic_with(&path, |w| {
            w.write_all(&[b'x'; 100_000])?;
            Err(io::Error::other("serialiser failed"))
        })
        .expect_err("the closure's error is returned");
        assert!(err.to_string().contains("serialiser failed"), "{err}");
        assert!(err.to_string().contains("report.json"), "error names the file: {err}");
        assert_eq!(std::fs::read(&path).expect("read"), b"old");
        assert_eq!(leftovers(dir.path(), &["report.json"]), Vec::<PathBuf>::new(), "temporary file left");
    }

    #[test]
    fn streams_large_content_and_keeps_normal_permissions() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("big.bin");
        write_atomic_with(&path, |w| {
            for i in 0..1000u32 {
                w.write_all(&i.to_le_bytes().repeat(256))?;
            }
            Ok(())
        })
        .expect("write");
        let got = std::fs::read(&path).expect("read");
        assert_eq!(got.len(), 1000 * 1024);
        assert_eq!(&got[1024 * 999..1024 * 999 + 4], &999u32.to_le_bytes());
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            // Same mode as a file created the ordinary way (tempfile alone would give 0o600).
            let plain = dir.path().join("plain.bin");
            std::fs::File::create(&plain).expect("create");
            let mode = |p: &Path| std::fs::metadata(p).expect("metadata").permissions().mode() & 0o777;
            assert_eq!(mode(&path), mode(&plain), "mode {:o}", mode(&path));
        }
    }

    #[test]
    fn a_path_without_a_file_name_is_an_error() {
        let err = write_atomic(Path::new("/"), b"x").expect_err("no file name");
        assert_eq!(err.kind(), io::ErrorKind::InvalidInput);
        assert!(err.to_string().contains("has no file name"), "{err}");
    }
}
