//! `sonoflow inspect` and `sonoflow recover`.

use sonoflow_mcap_io::McapReader;
use std::path::Path;

/// Prints a summary of a recording.
pub fn inspect(file: &Path) -> anyhow::Result<i32> {
    let r = McapReader::open(file)?;
    println!(
        "{}: {} ({} bytes)",
        file.display(),
        if r.is_complete() { "complete MCAP" } else { "UNFINISHED MCAP (run `sonoflow recover`)" },
        r.file_len()
    );
    println!("topics:");
    for t in r.topics() {
        println!(
            "  {:<24} {:<40} {:>8} messages",
            t.topic,
            t.schema_name,
            t.message_count.map(|c| c.to_string()).unwrap_or_else(|| "?".into())
        );
    }
    for (name, md) in r.metadata() {
        println!("metadata `{name}`:");
        for (k, v) in md {
            println!("  {k} = {v}");
        }
    }
    for (name, media, data) in r.attachments() {
        println!("attachment `{name}` ({media}, {} bytes)", data.len());
    }
    Ok(0)
}

/// Rewrites a truncated recording into a complete file.
pub fn recover(input: &Path, output: &Path) -> anyhow::Result<i32> {
    let s = sonoflow_mcap_io::recover(input, output)?;
    println!(
        "{} → {}: {} messages recovered, {} trailing bytes dropped (input was {})",
        input.display(),
        output.display(),
        s.messages,
        s.truncated_bytes,
        if s.was_complete { "complete" } else { "unfinished" }
    );
    Ok(0)
}
