//! [`recover`]: rewrite a possibly unfinished file into a finished, indexed one.

use std::{
    fs::OpenOptions,
    io::{self, BufWriter},
    path::Path,
};

use mcap::records::Metadata;

use crate::{
    reader::ReadOptions,
    writer::{mcap_error, sync_file_and_dir},
    Compression, McapIoError, McapReader, WriterOptions,
};

/// What [`recover`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RecoverStats {
    /// Messages written to the output.
    pub messages: u64,
    /// Bytes at the end of the input that could not be used (truncated or corrupt records and
    /// any partial summary); 0 for a complete input.
    pub truncated_bytes: u64,
    /// Whether the input was already complete (had a valid footer and summary).
    pub was_complete: bool,
}

/// Rewrites every readable message of `input` (with its schemas, channels, metadata and
/// attachments, keeping schema and channel ids) into `output`, a new finished MCAP file with
/// summary and indexes. `input` may be unfinished (e.g. the recorder was killed): everything up
/// to the last complete chunk is kept. Messages are written in log-time order, zstd-compressed
/// with the [`WriterOptions`] defaults. `output` must not exist; it is fsynced when done.
pub fn recover(input: &Path, output: &Path) -> Result<RecoverStats, McapIoError> {
    let reader = McapReader::open(input)?;
    let file = OpenOptions::new().write(true).create_new(true).open(output).map_err(|e| {
        if e.kind() == io::ErrorKind::AlreadyExists {
            McapIoError::AlreadyExists { path: output.to_path_buf() }
        } else {
            McapIoError::io(output, e)
        }
    })?;
    let defaults = WriterOptions::default();
    let profile = if reader.profile().is_empty() { defaults.profile.clone() } else { reader.profile().to_string() };
    let merr = |e| mcap_error(output, e);
    let mut writer = mcap::WriteOptions::new()
        .profile(profile)
        .library(format!("sonoflow-mcap-io/{} recover ({})", env!("CARGO_PKG_VERSION"), mcap::LIBRARY_IDENTIFIER))
        .compression(Compression::Zstd.to_mcap())
        .compression_level(defaults.compression_level)
        .compression_threads(0)
        .chunk_size(Some(defaults.chunk_size))
        .create(BufWriter::with_capacity(1 << 20, file))
        .map_err(merr)?;

    for schema in reader.schemas() {
        writer.add_schema_with_id(schema.id, &schema.name, &schema.encoding, &schema.data).map_err(merr)?;
    }
    for channel in reader.channels() {
        let schema_id = channel.schema.as_ref().map(|s| s.id).unwrap_or(0);
        writer
            .add_channel_with_id(channel.id, schema_id, &channel.topic, &channel.message_encoding, &channel.metadata)
            .map_err(merr)?;
    }
    let mut messages = 0u64;
    for item in reader.raw_messages(&ReadOptions::default())? {
        let (header, data) = item?;
        writer.write_to_known_channel(&header, &data).map_err(merr)?;
        messages += 1;
    }
    for (name, metadata) in reader.metadata() {
        writer.write_metadata(&Metadata { name, metadata }).map_err(merr)?;
    }
    for a in reader.full_attachments() {
        writer
            .attach(&mcap::Attachment {
                log_time: a.log_time,
                create_time: a.create_time,
                name: a.name,
                media_type: a.media_type,
                data: a.data.into(),
            })
            .map_err(merr)?;
    }
    writer.finish().map_err(merr)?;
    let file = writer.into_inner().into_inner().map_err(|e| McapIoError::io(output, e.into_error()))?;
    sync_file_and_dir(&file, output)?;
    Ok(RecoverStats { messages, truncated_bytes: reader.truncated_bytes(), was_complete: reader.is_complete() })
}
