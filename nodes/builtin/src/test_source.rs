//! `test-source` node: deterministic RF test frames (a pattern from the seed and the sequence
//! number), to exercise the transport with real frame sizes (e.g. 128 × 8192 f32 = 4 MiB).

use serde::{Deserialize, Serialize};
use sonoflow_messages::types::RfFrame;
use sonoflow_messages::MessageType::*;
use sonoflow_messages::RfFrameHeaderV3;
use sonoflow_node_kit::PortDir::*;
use sonoflow_node_kit::{in_range, parse_params, thread_cpu_ns, Kit};
use sonoflow_node_kit::{port, KindSpec};

/// The `test-source` node kind.
pub const SPEC: KindSpec = KindSpec::new(
    "test-source",
    "deterministic RF test frames (pattern from seed and sequence number)",
    &[port("rf", Out, RfFrameV3, true)],
    validate_source,
    run_source,
);

/// Deterministic test value of sample `i` of frame `frame` (uniform in [-0.5, 0.5)).
pub fn pattern(seed: u64, frame: u64, i: u64) -> f32 {
    let mut x = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ frame.wrapping_mul(0xD1B5_4A32_D192_ED03)
        ^ i.wrapping_mul(0x94D0_49BB_1331_11EB);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^= x >> 31;
    ((x >> 40) as f32) / 16_777_216.0 - 0.5
}

/// `test-source` parameters.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct SourceParams {
    /// Frames to send.
    pub n_frames: u64,
    /// Channels per frame.
    pub n_channels: u32,
    /// Samples per channel.
    pub n_samples: u32,
    /// Pattern seed.
    pub seed: u64,
    /// Frame rate used for `t_valid` (Hz).
    pub prf: f64,
    /// Send frames in real time at `prf` instead of as fast as possible.
    pub paced: bool,
}

impl Default for SourceParams {
    fn default() -> Self {
        Self { n_frames: 20, n_channels: 128, n_samples: 8192, seed: 1, prf: 1000.0, paced: false }
    }
}

impl SourceParams {
    fn validate(&self) -> Result<(), String> {
        in_range("n_frames", self.n_frames, 1, 10_000_000)?;
        in_range("n_channels", self.n_channels, 1, 1024)?;
        in_range("n_samples", self.n_samples, 1, 1 << 20)?;
        if !(self.prf.is_finite() && self.prf > 0.0 && self.prf <= 1e7) {
            return Err(format!("prf = {} is out of range: (0, 1e7] Hz", self.prf));
        }
        Ok(())
    }
}

pub fn validate_source(v: &serde_json::Value) -> Result<(), String> {
    parse_params::<SourceParams>(v)?.validate()
}

pub fn run_source(mut kit: Kit) -> anyhow::Result<()> {
    let p: SourceParams = parse_params(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    p.validate().map_err(anyhow::Error::msg)?;
    let mut out = kit.output::<RfFrame>("rf")?;
    kit.handshake(&mut [&mut out])?;
    let n = p.n_channels as usize * p.n_samples as usize;
    let step = (p.n_frames / 10).max(1);
    let start = std::time::Instant::now();
    let mut last_progress = start;
    for frame in 0..p.n_frames {
        if kit.check_termination().is_err() {
            break;
        }
        if p.paced {
            let due = std::time::Duration::from_secs_f64(frame as f64 / p.prf);
            if let Some(wait) = due.checked_sub(start.elapsed()) {
                std::thread::sleep(wait);
            }
        }
        let t0 = thread_cpu_ns();
        let mut h = RfFrameHeaderV3 {
            fs: 20e6,
            fc: 5e6,
            c: 1540.0,
            pitch: 0.3e-3,
            prf: p.prf,
            n_channels: p.n_channels,
            n_samples: p.n_samples,
            ..Default::default()
        };
        h.common.frame_id = frame;
        h.common.t_valid = frame as f64 / p.prf;
        let compute = thread_cpu_ns() - t0;
        h.common.compute_ns = compute;
        out.publish_in_place(n, h, |dst| {
            for (i, d) in dst.iter_mut().enumerate() {
                d.write(pattern(p.seed, frame, i as u64));
            }
        })?;
        let compute = thread_cpu_ns() - t0;
        kit.published((n * 4) as u64, frame, frame as f64 / p.prf, compute)?;
        if (frame + 1) % step == 0 || frame + 1 == p.n_frames || last_progress.elapsed().as_secs_f64() > 1.0 {
            last_progress = std::time::Instant::now();
            kit.progress(frame + 1, p.n_frames);
        }
    }
    out.publish_eos(p.n_frames as f64 / p.prf)?;
    kit.finish()?;
    Ok(())
}
