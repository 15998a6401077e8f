//! Write throughput of `RecorderWriter` with 4 MiB noise-like f32 messages.
//!
//! ```text
//! cargo run --release -p sonoflow-mcap-io --example write_throughput -- [N] [DIR]
//! ```
//! Writes N (default 64) messages of 4 MiB (1 Mi f32 samples of band-limited Gaussian noise, like
//! raw RF) once per compression (none, zstd, lz4; default level and chunk size) into a temporary
//! directory under DIR (default: the system temp dir), and prints MB/s measured from `create` to
//! the end of `finish` (summary written, file and directory fsynced), plus the compression
//! ratio. Files are deleted afterwards.

use std::{path::PathBuf, time::Instant};

use sonoflow_mcap_io::{ChannelSpec, Compression, OutMessage, RecorderWriter, WriterOptions};

const SAMPLES: usize = 1 << 20; // 4 MiB of f32

/// Gaussian-ish noise (sum of 4 uniforms) through a short moving average, scaled to an
/// ADC-like range: every mantissa bit is busy, as in real RF frames.
fn noise_frame(seed: u64) -> Vec<u8> {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut next = move || {
        s ^= s >> 12;
        s ^= s << 25;
        s ^= s >> 27;
        (s.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut out = Vec::with_capacity(SAMPLES * 4);
    let mut prev = [0f32; 3];
    for _ in 0..SAMPLES {
        let g = next() + next() + next() + next() - 2.0;
        let v = (g + prev[0] + prev[1] + prev[2]) * 0.25 * 800.0;
        prev = [g, prev[0], prev[1]];
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let n: usize = match args.next() {
        Some(a) => a.parse()?,
        None => 64,
    };
    let base: PathBuf = args.next().map(PathBuf::from).unwrap_or_else(std::env::temp_dir);
    let dir = tempfile::tempdir_in(&base)?;
    let pool: Vec<Vec<u8>> = (0..8).map(noise_frame).collect();
    let payload_bytes = (n * SAMPLES * 4) as f64;
    println!("{n} messages x 4 MiB noise-like f32 ({:.0} MB) into {}", payload_bytes / 1e6, base.display());
    println!("{:<6} {:>10} {:>12} {:>8}", "codec", "seconds", "MB/s", "ratio");
    for compression in [Compression::None, Compression::Zstd, Compression::Lz4] {
        let path = dir.path().join(format!("bench-{compression}.mcap"));
        let opts = WriterOptions { compression, ..WriterOptions::default() };
        let start = Instant::now();
        let mut w = RecorderWriter::create(&path, opts)?;
        let ch = w.add_channel(ChannelSpec {
            topic: "/rf".into(),
            message_encoding: "raw-f32le".into(),
            ..Default::default()
        })?;
        for i in 0..n {
            w.write(OutMessage {
                channel: ch,
                sequence: i as u32,
                log_time: i as u64 * 1_000_000,
                publish_time: i as u64 * 1_000_000,
                data: pool[i % pool.len()].clone(),
            })?;
        }
        let stats = w.finish()?;
        let secs = start.elapsed().as_secs_f64();
        println!(
            "{:<6} {:>10.3} {:>12.1} {:>8.3}",
            compression.to_string(),
            secs,
            payload_bytes / secs / 1e6,
            stats.file_bytes as f64 / payload_bytes
        );
        std::fs::remove_file(&path)?;
    }
    Ok(())
}
