//! Where the lumen ends: the no-slip wall of the divergence-free fit, from the Doppler power.
//!
//! The blood's echo power is blurred by the point-spread function: across a wall it falls from
//! the blood's level to the level of whatever is outside (nothing, or clutter-filtered tissue) over
//! a resolution cell, and the wall itself sits near the half-power point. Pixels whose power,
//! smoothed by a Gaussian of σ = `smoothing` (speckle removed), lies more than `threshold_db`
//! below the median smoothed power of the blood pixels are outside the lumen. Only the pixels
//! adjacent to the blood need to be right: far outside the data the prior only keeps the fit at
//! rest.
//!
//! After a clutter filter the blood's power is no longer even across the lumen: where the flow
//! runs nearly across the beams its Doppler frequencies are low and the filter removes part of
//! its echo (10 dB and more on the clutter carotid), so a threshold a few dB below the blood's
//! median puts the wall inside the lumen. `rule = "two-class"` then places the threshold halfway
//! (in dB) between the blood's median and the median of the other pixels (residual tissue and
//! noise), or at `threshold_db`, whichever is lower.

use serde::{Deserialize, Serialize};

use super::DivFreeError;

/// Parameters of the no-slip wall ([`wall_from_power`]); every field has a default.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NoSlipParams {
    /// Pixels whose smoothed power is more than this far below the blood's median are outside the
    /// lumen (dB, in [−30, −1]; default −5: 2 dB beyond the half-power point, so that speckle
    /// and a depth-dependent level do not put the wall inside the lumen).
    pub threshold_db: f64,
    /// Weight of the zero-velocity prior on those pixels, relative to the largest data weight
    /// (0 < weight ≤ 100; default 3: on carotid packets 3 beat 1 and 10).
    pub weight: f64,
    /// σ of the Gaussian that smooths the power first (m, > 0; default 0.4 mm, about a speckle
    /// grain).
    pub smoothing: f64,
    /// How the threshold is set (module doc): `blood-median` (default) or `two-class`.
    pub rule: WallRule,
}

/// Where the no-slip wall's power threshold lies (module doc).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum WallRule {
    /// `threshold_db` below the blood's median.
    #[default]
    BloodMedian,
    /// Halfway (dB) between the blood's median and the other pixels' median, at most `threshold_db`.
    TwoClass,
}

impl Default for NoSlipParams {
    fn default() -> Self {
        Self { threshold_db: -5.0, weight: 3.0, smoothing: 0.4e-3, rule: WallRule::BloodMedian }
    }
}

impl NoSlipParams {
    /// Checks every field.
    pub fn validate(&self) -> Result<(), DivFreeError> {
        let bad = |field, value: f64, allowed| {
            Err(DivFreeError::InvalidParameter { field, value: format!("{value}"), allowed })
        };
        if !(self.threshold_db.is_finite() && (-30.0..=-1.0).contains(&self.threshold_db)) {
            return bad("no_slip.threshold_db", self.threshold_db, "−30 ..= −1 dB");
        }
        if !(self.weight.is_finite() && self.weight > 0.0 && self.weight <= 100.0) {
            return bad("no_slip.weight", self.weight, "0 < weight ≤ 100");
        }
        if !(self.smoothing.is_finite() && self.smoothing > 0.0 && self.smoothing <= 0.1) {
            return bad("no_slip.smoothing", self.smoothing, "0 < smoothing ≤ 0.1 m");
        }
        Ok(())
    }
}

/// 1-D Gaussian smoothing along one axis of a row-major `nz × nx` image, truncated at 3σ and
/// normalised by the kernel weight inside the image (no padding: the edges keep their level).
fn smooth_axis(img: &[f64], nz: usize, nx: usize, sigma_px: f64, along_x: bool) -> Vec<f64> {
    let r = (3.0 * sigma_px).ceil() as isize;
    let k: Vec<f64> = (-r..=r).map(|d| (-0.5 * (d as f64 / sigma_px).powi(2)).exp()).collect();
    let mut out = vec![0.0; img.len()];
    for i in 0..nz {
        for j in 0..nx {
            let (mut acc, mut norm) = (0.0, 0.0);
            for (t, kv) in k.iter().enumerate() {
                let d = t as isize - r;
                let (ii, jj) = if along_x { (i as isize, j as isize + d) } else { (i as isize + d, j as isize) };
                if ii >= 0 && jj >= 0 && (ii as usize) < nz && (jj as usize) < nx {
                    acc += kv * img[ii as usize * nx + jj as usize];
                    norm += kv;
                }
            }
            out[i * nx + j] = acc / norm;
        }
    }
    out
}

/// The no-slip wall of a `[nz, nx]` grid with spacing `[dz, dx]` (m): `true` where the pixel is
/// outside the lumen (module doc). `power`: the Doppler power per pixel (non-finite or negative =
/// 0); `blood`: the pixels with data (their median smoothed power is the blood's level). Returns
/// all `false` when no pixel is blood.
pub fn wall_from_power(
    power: &[f64],
    blood: &[bool],
    shape: [usize; 2],
    spacing: [f64; 2],
    p: &NoSlipParams,
) -> Result<Vec<bool>, DivFreeError> {
    p.validate()?;
    let [nz, nx] = shape;
    let n = nz * nx;
    for (what, got) in [("power", power.len()), ("blood", blood.len())] {
        if got != n {
            return Err(DivFreeError::LengthMismatch { what, got, expected: n, nz, nx });
        }
    }
    let [dz, dx] = spacing;
    if !(dz.is_finite() && dz > 0.0 && dx.is_finite() && dx > 0.0) {
        return Err(DivFreeError::InvalidParameter {
            field: "spacing",
            value: format!("[{dz}, {dx}]"),
            allowed: "> 0",
        });
    }
    let clean: Vec<f64> = power.iter().map(|v| if v.is_finite() && *v > 0.0 { *v } else { 0.0 }).collect();
    let sm = smooth_axis(&smooth_axis(&clean, nz, nx, p.smoothing / dx, true), nz, nx, p.smoothing / dz, false);
    let mut level: Vec<f64> = (0..n).filter(|&i| blood[i]).map(|i| sm[i]).collect();
    if level.is_empty() {
        return Ok(vec![false; n]);
    }
    let ref_level = super::median(&mut level);
    let mut threshold_db = p.threshold_db;
    if p.rule == WallRule::TwoClass {
        let mut rest: Vec<f64> = (0..n).filter(|&i| !blood[i]).map(|i| sm[i]).collect();
        if !rest.is_empty() && ref_level > 0.0 {
            let bg = super::median(&mut rest).max(ref_level * 1e-10);
            threshold_db = threshold_db.min(0.5 * 10.0 * (bg / ref_level).log10());
        }
    }
    let floor = ref_level * 10f64.powf(threshold_db / 10.0);
    Ok(sm.iter().map(|v| *v < floor).collect())
}

/// The power mask of the regulariser: pixels whose power is at least `power_mask_db` (≤ 0) relative
/// to the frame's 99th percentile (finite values only) count as blood; NaN and below: not.
pub fn blood_from_power(power: &[f32], power_mask_db: f64) -> Vec<bool> {
    let mut sorted: Vec<f32> = power.iter().copied().filter(|v| v.is_finite()).collect();
    sorted.sort_by(f32::total_cmp);
    let p99 = sorted.get(((sorted.len() as f64 - 1.0) * 0.99).round() as usize).copied().unwrap_or(0.0);
    let floor = f64::from(p99) * 10f64.powf(power_mask_db / 10.0);
    power.iter().map(|p| p.is_finite() && f64::from(*p) >= floor).collect()
}
