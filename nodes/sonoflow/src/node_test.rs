//! Test-pattern nodes: `test-source` (deterministic RF frames), `gain` (a minimal processing
//! stage, also the model for external nodes) and `checker` (verifies every sample bit for bit).
//! They exercise the transport with real frame sizes (e.g. 128 × 8192 f32 = 4 MiB).

use crate::kinds::{in_range, parse};
use crate::nodeutil::{for_each, Flow};
use serde::{Deserialize, Serialize};
use sonoflow_messages::kinds::RfFrame;
use sonoflow_messages::RfFrameHeaderV1;
use sonoflow_node_kit::{thread_cpu_ns, Kit};

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
    parse::<SourceParams>(v)?.validate()
}

pub fn run_source(mut kit: Kit) -> anyhow::Result<()> {
    let p: SourceParams = parse(&kit.cfg.params).map_err(anyhow::Error::msg)?;
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
        let mut h = RfFrameHeaderV1 {
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
        kit.stats.messages_out += 1;
        kit.stats.bytes_out += (n * 4) as u64;
        kit.record(frame, frame as f64 / p.prf, compute)?;
        if (frame + 1) % step == 0 || frame + 1 == p.n_frames || last_progress.elapsed().as_secs_f64() > 1.0 {
            last_progress = std::time::Instant::now();
            kit.progress(frame + 1, p.n_frames);
        }
    }
    out.publish_eos(p.n_frames as f64 / p.prf)?;
    kit.finish()?;
    Ok(())
}

/// `gain` parameters.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct GainParams {
    /// Multiplier (finite).
    pub gain: f32,
}

impl Default for GainParams {
    fn default() -> Self {
        Self { gain: 2.0 }
    }
}

pub fn validate_gain(v: &serde_json::Value) -> Result<(), String> {
    let p = parse::<GainParams>(v)?;
    if !p.gain.is_finite() || p.gain.abs() > 1e30 {
        return Err(format!("gain = {} is out of range: finite, |gain| <= 1e30", p.gain));
    }
    Ok(())
}

pub fn run_gain(mut kit: Kit) -> anyhow::Result<()> {
    validate_gain(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    let p: GainParams = parse(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    let mut input = kit.input::<RfFrame>("rf_in")?;
    let mut out = kit.output::<RfFrame>("rf_out")?;
    kit.handshake(&mut [&mut input, &mut out])?;
    let mut last_t = 0.0;
    for_each(&mut kit, &mut input, |kit, sample| {
        let t0 = thread_cpu_ns();
        let src = sample.payload();
        let mut h = *sample.user_header();
        // Fresh common header: keep the frame id and time of validity only.
        h.common = sonoflow_messages::MsgHeaderV1 {
            frame_id: h.common.frame_id,
            t_valid: h.common.t_valid,
            ..Default::default()
        };
        last_t = h.common.t_valid;
        out.publish_in_place(src.len(), h, |dst| {
            for (d, s) in dst.iter_mut().zip(src) {
                d.write(s * p.gain);
            }
        })?;
        let compute = thread_cpu_ns() - t0;
        kit.stats.messages_in += 1;
        kit.stats.messages_out += 1;
        kit.stats.bytes_out += (src.len() * 4) as u64;
        kit.record(h.common.frame_id, h.common.t_valid, compute)?;
        Ok(Flow::Continue)
    })?;
    out.publish_eos(last_t)?;
    kit.stats.gaps = input.gaps;
    kit.finish()?;
    Ok(())
}

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
    let p = parse::<CheckerParams>(v)?;
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
    let p: CheckerParams = parse(&kit.cfg.params).map_err(anyhow::Error::msg)?;
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
        crate::nodeutil::write_atomic(&path, serde_json::to_string_pretty(&rep)?.as_bytes())?;
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

/// `field-noise` parameters: corrupts vector fields the way a vector Doppler estimator does
/// (speckle noise, gross outliers, missing pixels), to exercise the regulariser.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct FieldNoiseParams {
    /// Standard deviation of the Gaussian noise added to vx and vz (m/s, ≥ 0).
    pub sigma: f64,
    /// Fraction of pixels (inside the mask, if any) replaced by gross outliers, in [0, 1).
    pub outlier_fraction: f64,
    /// Outliers are uniform in ±outlier_amplitude (m/s, ≥ 0).
    pub outlier_amplitude: f64,
    /// Fraction of pixels flagged "no estimate" (velocity 0, `flags` plane bit 1), in [0, 1).
    pub missing_fraction: f64,
    /// Random seed (the noise of a frame depends on the seed and its frame id only).
    pub seed: u64,
}

impl Default for FieldNoiseParams {
    fn default() -> Self {
        Self { sigma: 0.05, outlier_fraction: 0.1, outlier_amplitude: 1.0, missing_fraction: 0.0, seed: 1 }
    }
}

pub fn validate_field_noise(v: &serde_json::Value) -> Result<(), String> {
    let p = parse::<FieldNoiseParams>(v)?;
    in_range("sigma", p.sigma, 0.0, 1e3)?;
    in_range("outlier_amplitude", p.outlier_amplitude, 0.0, 1e3)?;
    for (name, f) in [("outlier_fraction", p.outlier_fraction), ("missing_fraction", p.missing_fraction)] {
        if !(f.is_finite() && (0.0..1.0).contains(&f)) {
            return Err(format!("{name} = {f} is out of range: 0 <= {name} < 1"));
        }
    }
    Ok(())
}

/// Corrupts one vector field (planes `vx`, `vz`, optional `mask`) deterministically; appends a
/// `flags` plane when `missing_fraction > 0` and the field has none. Returns the new header.
pub fn corrupt_field(
    p: &FieldNoiseParams,
    h: &sonoflow_messages::VectorFieldHeaderV1,
    src: &[f32],
    dst: &mut Vec<f32>,
) -> anyhow::Result<sonoflow_messages::VectorFieldHeaderV1> {
    use rand::{Rng, SeedableRng};
    use rand_distr::{Distribution, StandardNormal};
    use sonoflow_messages::{plane, VECTOR_RAW};
    let n = h.grid.nx as usize * h.grid.nz as usize;
    let np = h.n_planes as usize;
    if np == 0 || np > sonoflow_messages::MAX_PLANES || src.len() != n * np {
        anyhow::bail!("vector field frame {}: {} values for {np} planes of {n}", h.common.frame_id, src.len());
    }
    let ids = &h.plane_ids[..np];
    let find = |id| ids.iter().position(|&p| p == id);
    let (Some(ivx), Some(ivz)) = (find(plane::VX), find(plane::VZ)) else {
        anyhow::bail!("vector field frame {} has no vx/vz planes", h.common.frame_id);
    };
    let mask = find(plane::MASK);
    let mut oh = *h;
    oh.common =
        sonoflow_messages::MsgHeaderV1 { frame_id: h.common.frame_id, t_valid: h.common.t_valid, ..Default::default() };
    oh.source = VECTOR_RAW;
    dst.clear();
    dst.extend_from_slice(src);
    let iflags = match (p.missing_fraction > 0.0, find(plane::FLAGS)) {
        (false, f) => f,
        (true, Some(f)) => Some(f),
        (true, None) if np < sonoflow_messages::MAX_PLANES => {
            oh.plane_ids[np] = plane::FLAGS;
            oh.n_planes += 1;
            dst.resize(dst.len() + n, 0.0);
            Some(np)
        }
        (true, None) => anyhow::bail!("vector field frame {} has no free plane for flags", h.common.frame_id),
    };
    let mut rng =
        rand_chacha::ChaCha8Rng::seed_from_u64(p.seed ^ h.common.frame_id.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    for i in 0..n {
        let inside = mask.is_none_or(|m| src[m * n + i] > 0.5);
        let (nx, nz): (f64, f64) = (StandardNormal.sample(&mut rng), StandardNormal.sample(&mut rng));
        let u: f64 = rng.gen();
        let (ox, oz): (f64, f64) = (rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0));
        let miss: f64 = rng.gen();
        if !inside {
            continue;
        }
        let (vx, vz) = if u < p.outlier_fraction {
            (ox * p.outlier_amplitude, oz * p.outlier_amplitude)
        } else {
            (src[ivx * n + i] as f64 + p.sigma * nx, src[ivz * n + i] as f64 + p.sigma * nz)
        };
        dst[ivx * n + i] = vx as f32;
        dst[ivz * n + i] = vz as f32;
        if let (Some(f), true) = (iflags, miss < p.missing_fraction) {
            dst[ivx * n + i] = 0.0;
            dst[ivz * n + i] = 0.0;
            dst[f * n + i] = ((dst[f * n + i] as u32) | 1) as f32;
        }
    }
    Ok(oh)
}

pub fn run_field_noise(mut kit: Kit) -> anyhow::Result<()> {
    validate_field_noise(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    let p: FieldNoiseParams = parse(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    let mut input = kit.input::<sonoflow_messages::kinds::VectorField>("clean")?;
    let mut out = kit.output::<sonoflow_messages::kinds::VectorField>("noisy")?;
    kit.handshake(&mut [&mut input, &mut out])?;
    let mut last_t = 0.0;
    let mut buf = Vec::new();
    for_each(&mut kit, &mut input, |kit, sample| {
        let t0 = thread_cpu_ns();
        let mut oh = corrupt_field(&p, sample.user_header(), sample.payload(), &mut buf)?;
        let compute = thread_cpu_ns() - t0;
        oh.common.compute_ns = compute;
        out.publish_copy(oh, &buf)?;
        kit.stats.messages_in += 1;
        kit.stats.messages_out += 1;
        kit.stats.bytes_out += (buf.len() * 4) as u64;
        kit.record(oh.common.frame_id, oh.common.t_valid, compute)?;
        last_t = oh.common.t_valid;
        Ok(Flow::Continue)
    })?;
    out.publish_eos(last_t)?;
    kit.stats.gaps = input.gaps;
    kit.finish()?;
    Ok(())
}
