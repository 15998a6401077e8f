//! `field-noise` node: corrupts vector fields the way a vector Doppler estimator does (speckle
//! noise, gross outliers, missing pixels), deterministically, to exercise the regulariser.

use serde::{Deserialize, Serialize};
use sonoflow_messages::MessageType::*;
use sonoflow_node_kit::PortDir::*;
use sonoflow_node_kit::{in_range, parse_params, thread_cpu_ns, transform, Kit};
use sonoflow_node_kit::{port, KindSpec};

/// The `field-noise` node kind.
pub const SPEC: KindSpec = KindSpec::new(
    "field-noise",
    "adds Gaussian noise, gross outliers and missing pixels to vector fields (deterministic; exercises the regulariser)",
    &[port("clean", In, VectorFieldV2, true), port("noisy", Out, VectorFieldV2, true)],
    validate_field_noise,
    run_field_noise,
);

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
    let p = parse_params::<FieldNoiseParams>(v)?;
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
    h: &sonoflow_messages::VectorFieldHeaderV2,
    src: &[f32],
    dst: &mut Vec<f32>,
) -> anyhow::Result<sonoflow_messages::VectorFieldHeaderV2> {
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
    let p: FieldNoiseParams = parse_params(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    let mut input = kit.input::<sonoflow_messages::types::VectorField>("clean")?;
    let mut out = kit.output::<sonoflow_messages::types::VectorField>("noisy")?;
    kit.handshake(&mut [&mut input, &mut out])?;
    let mut buf = Vec::new();
    transform(kit, &mut input, &mut out, |kit, out, sample| {
        let t0 = thread_cpu_ns();
        let mut oh = corrupt_field(&p, sample.user_header(), sample.payload(), &mut buf)?;
        oh.common.compute_ns = thread_cpu_ns() - t0;
        Ok(kit.publish_copy(out, oh, &buf)?)
    })
}
