//! `sonoflow inspect` and `sonoflow recover`.

use sonoflow_mcap_io::{McapReader, MessageView};
use sonoflow_messages::{cdr, MessageType};
use std::path::Path;

/// Prints a summary of a recording. By default only the summary is read (for a complete file)
/// and the output says so; with `verify`, every record is read and checked as well
/// ([`McapReader::verify`], plus the structure of every sonoflow wire message), the decoded
/// message counts are printed next to the summary's, and any problem makes this an error.
pub fn inspect(file: &Path, verify: bool) -> anyhow::Result<i32> {
    let r = McapReader::open(file)?;
    let what = match (r.is_complete(), verify) {
        (true, false) => "complete MCAP (summary only; run with --verify to decode every chunk and check CRCs)",
        (true, true) => "complete MCAP",
        (false, _) => "UNFINISHED MCAP (no summary; counts from a scan of its complete chunks; run `sonoflow recover`)",
    };
    println!("{}: {what} ({} bytes)", file.display(), r.file_len());
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
    if !verify {
        return Ok(0);
    }
    let v = r.verify(&mut check_wire_message);
    println!(
        "verify: {} records, {} chunks decoded and CRC-checked, {} messages decoded",
        v.records,
        v.chunks,
        v.messages()
    );
    for t in &v.topics {
        let summary = t.summary.map(|n| n.to_string()).unwrap_or_else(|| "-".into());
        let mark = match t.summary {
            Some(n) if n != t.decoded => "  MISMATCH",
            _ => "",
        };
        println!("  {:<24} {:>8} decoded {:>8} in the summary{mark}", t.topic, t.decoded, summary);
    }
    if v.is_ok() {
        println!("verify: ok");
        return Ok(0);
    }
    anyhow::bail!("{} failed verification: {}", file.display(), v.problems.join("; "))
}

/// Messages of a sonoflow wire type (CDR encoding, `sonoflow_msgs/msg/<Type>` schema) must have
/// the structure of that type: encapsulation, header, element count matching the payload.
/// Other channels are opaque here.
fn check_wire_message(m: &MessageView<'_>) -> Result<(), String> {
    let Some(kind) = m.schema_name.strip_prefix("sonoflow_msgs/msg/").and_then(MessageType::from_name) else {
        return Ok(());
    };
    if m.message_encoding != "cdr" {
        return Ok(());
    }
    cdr::split(kind, m.data).map(|_| ()).map_err(|e| e.to_string())
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
