//! `checker` node: verifies `test-source` frames (× gain) bit for bit and writes `<node>.json`
//! into the run folder.

use crate::test_source::pattern;
use serde::{Deserialize, Serialize};
use sonoflow_messages::types::RfFrame;
use sonoflow_messages::MessageType::*;
use sonoflow_node_kit::PortDir::*;
use sonoflow_node_kit::{for_each, Flow};
use sonoflow_node_kit::{parse_params, thread_cpu_ns, Kit};
use sonoflow_node_kit::{port, KindSpec};

/// The `checker` node kind.
pub const SPEC: KindSpec = KindSpec::new(
    "checker",
    "verifies test-source frames (× gain) bit for bit and writes <node>.json in the run folder",
    &[port("rf", In, RfFrameV3, true)],
    validate_checker,
    run_checker,
);

/// `checker` parameters.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct CheckerParams {
    /// Seed of the test source.
    pub seed: u64,
    /// Gain applied upstream (1 = none).
    pub gain: f32,
    /// Frames expected (0 = do not check the count).
    pub n_frames: u64,
}

impl Default for CheckerParams {
    fn default() -> Self {
        Self { seed: 1, gain: 1.0, n_frames: 0 }
    }
}

pub fn validate_checker(v: &serde_json::Value) -> Result<(), String> {
    let p = parse_params::<CheckerParams>(v)?;
    if !p.gain.is_finite() {
        return Err(format!("gain = {} is out of range: finite", p.gain));
    }
    Ok(())
}

/// What the checker writes to `<out_dir>/<node>.json`.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct CheckReport {
    pub frames_ok: u64,
    pub frames_bad: u64,
    pub samples_checked: u64,
    pub bytes_checked: u64,
    pub gaps: u64,
    pub end_of_stream: bool,
    pub first_error: Option<String>,
}

pub fn run_checker(mut kit: Kit) -> anyhow::Result<()> {
    validate_checker(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    let p: CheckerParams = parse_params(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    let mut input = kit.input::<RfFrame>("rf")?;
    kit.handshake(&mut [&mut input])?;
    let mut rep = CheckReport::default();
    for_each(&mut kit, &mut input, |kit, sample| {
        let t0 = thread_cpu_ns();
        let h = sample.user_header();
        let data = sample.payload();
        let frame = h.common.frame_id;
        let n = h.n_channels as usize * h.n_samples as usize;
        let mut bad = None;
        if data.len() != n {
            bad = Some(format!("frame {frame}: {} samples, header says {n}", data.len()));
        } else if let Some((i, v)) =
            data.iter().enumerate().find(|(i, v)| v.to_bits() != (pattern(p.seed, frame, *i as u64) * p.gain).to_bits())
        {
            bad = Some(format!(
                "frame {frame} sample {i}: got {v}, expected {}",
                pattern(p.seed, frame, i as u64) * p.gain
            ));
        }
        match bad {
            Some(e) => {
                rep.frames_bad += 1;
                rep.first_error.get_or_insert(e);
            }
            None => rep.frames_ok += 1,
        }
        rep.samples_checked += data.len() as u64;
        rep.bytes_checked += (data.len() * 4) as u64;
        kit.stats.messages_in += 1;
        kit.record(frame, h.common.t_valid, thread_cpu_ns() - t0)?;
        Ok(Flow::Continue)
    })?;
    rep.gaps = input.gaps;
    rep.end_of_stream = input.eos;
    kit.stats.gaps = input.gaps;
    if let Some(dir) = &kit.cfg.out_dir {
        let path = std::path::Path::new(dir).join(format!("{}.json", kit.cfg.node_name));
        sonoflow_fileio::write_atomic(&path, serde_json::to_string_pretty(&rep)?.as_bytes())?;
    }
    let expected_ok = p.n_frames == 0 || rep.frames_ok == p.n_frames;
    kit.finish()?;
    if rep.frames_bad > 0 || !expected_ok || rep.gaps > 0 {
        anyhow::bail!(
            "checker: {} good, {} bad frames (expected {}), {} gaps; first error: {}",
            rep.frames_ok,
            rep.frames_bad,
            p.n_frames,
            rep.gaps,
            rep.first_error.as_deref().unwrap_or("none")
        );
    }
    println!("checker: {} frames, {} MB verified bit for bit", rep.frames_ok, rep.bytes_checked as f64 / 1e6);
    Ok(())
}
