use std::{io, path::PathBuf};

/// Errors of this crate.
#[derive(Debug, thiserror::Error)]
pub enum McapIoError {
    /// An I/O operation on `path` failed.
    #[error("I/O error on {}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    /// The mcap library reported an error (malformed record, bad CRC, bad index, ...).
    #[error("MCAP error: {}", error_chain(.0))]
    Mcap(#[from] mcap::McapError),
    /// The background writer thread failed earlier; the string is its error (with causes).
    #[error("MCAP writer thread failed: {0}")]
    WriterThread(String),
    /// The writer was already finished or abandoned.
    #[error("MCAP writer is closed")]
    Closed,
    /// The file does not start with the MCAP magic bytes.
    #[error("{} is not an MCAP file", path.display())]
    NotMcap { path: PathBuf },
    /// [`crate::RecorderWriter::create`] / [`crate::recover`] refuse to overwrite a file.
    #[error("refusing to overwrite existing file {}", path.display())]
    AlreadyExists { path: PathBuf },
    /// A message named a channel id that `add_channel` never returned.
    #[error("unknown channel id {0}")]
    UnknownChannel(u16),
    /// More than 65535 channels were added to one writer.
    #[error("too many channels (at most 65535 per file)")]
    TooManyChannels,
    /// A compression name other than "none", "zstd" or "lz4".
    #[error("unknown compression {0:?} (expected none, zstd or lz4)")]
    UnknownCompression(String),
}

impl McapIoError {
    pub(crate) fn io(path: impl Into<PathBuf>, source: io::Error) -> Self {
        McapIoError::Io { path: path.into(), source }
    }
}

/// `err` and all its sources, joined with ": " (mcap's own messages hide the I/O cause in
/// `source()`).
pub(crate) fn error_chain(err: &dyn std::error::Error) -> String {
    let mut out = err.to_string();
    let mut cur = err.source();
    while let Some(e) = cur {
        let s = e.to_string();
        if !out.ends_with(&s) {
            out.push_str(": ");
            out.push_str(&s);
        }
        cur = e.source();
    }
    out
}
