//! Error of an estimated vector field against ground truth, as paper 1 reports it: per pixel
//! inside the vessel, `e_x = (vx − vx_true)/v_max` and `e_z = (vz − vz_true)/v_max` with `v_max`
//! the largest true speed in the field; then the distribution of each (bias, RMS, median,
//! quartiles, the half-width holding 75 % of the pixels, 95th percentile of |e|, fraction within
//! ±2 % and ±10 %). No IPC: the evaluator node and the tests call it.

use serde::{Deserialize, Serialize};

/// Distribution of one error component (fractions of `v_max`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ErrorStats {
    /// Mean error (bias).
    pub bias: f64,
    /// Root mean square error.
    pub rms: f64,
    /// Median error.
    pub median: f64,
    /// First and third quartile of the error.
    pub q25: f64,
    pub q75: f64,
    /// 75th percentile of |e|: 75 % of the pixels are within ±this (the paper's "75 % of data").
    pub abs_p75: f64,
    /// 95th percentile of |e|.
    pub abs_p95: f64,
    /// Fraction of pixels with |e| ≤ 0.02 and ≤ 0.10.
    pub within_2pct: f64,
    pub within_10pct: f64,
}

/// Errors of one estimated field against the truth.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FieldError {
    /// Pixels inside the vessel (truth mask, eroded by `margin`).
    pub pixels: usize,
    /// Of those, pixels the estimator flagged "no estimate" (left out of the statistics).
    pub no_estimate: usize,
    /// Largest true speed (m/s), the normaliser.
    pub v_max: f64,
    /// Lateral (x) and axial (z) errors.
    pub x: ErrorStats,
    pub z: ErrorStats,
}

/// Percentile (0..=1) of sorted data, linear interpolation (NumPy's default).
fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let pos = p * (sorted.len() - 1) as f64;
    let (i, f) = (pos.floor() as usize, pos - pos.floor());
    match sorted.get(i + 1) {
        Some(next) => sorted[i] * (1.0 - f) + next * f,
        None => sorted[i],
    }
}

/// Statistics of a set of errors.
pub fn error_stats(e: &[f64]) -> ErrorStats {
    if e.is_empty() {
        return ErrorStats::default();
    }
    let n = e.len() as f64;
    let mut s = e.to_vec();
    s.sort_by(f64::total_cmp);
    let mut a: Vec<f64> = e.iter().map(|v| v.abs()).collect();
    a.sort_by(f64::total_cmp);
    ErrorStats {
        bias: e.iter().sum::<f64>() / n,
        rms: (e.iter().map(|v| v * v).sum::<f64>() / n).sqrt(),
        median: percentile(&s, 0.5),
        q25: percentile(&s, 0.25),
        q75: percentile(&s, 0.75),
        abs_p75: percentile(&a, 0.75),
        abs_p95: percentile(&a, 0.95),
        within_2pct: a.iter().filter(|v| **v <= 0.02).count() as f64 / n,
        within_10pct: a.iter().filter(|v| **v <= 0.10).count() as f64 / n,
    }
}

/// Compares `est` (planes `vx`, `vz` and optional `flags` at the given plane indices) with the
/// truth (`vx`, `vz`, `mask`), both `nz × nx` row-major. Pixels count when the truth mask is set
/// on the whole `(2·margin+1)²` neighbourhood (a wall pixel's Doppler mixes both sides).
pub fn field_error(
    truth: (&[f32], &[f32], &[f32]),
    est: (&[f32], &[f32], Option<&[f32]>),
    nx: usize,
    nz: usize,
    margin: usize,
) -> FieldError {
    field_error_samples(truth, est, nx, nz, margin).0
}

/// [`field_error`] and the per-pixel errors it summarises, `(e_x, e_z)` (fractions of `v_max`,
/// one per counted pixel with an estimate, row-major order): the report's histograms.
pub fn field_error_samples(
    truth: (&[f32], &[f32], &[f32]),
    est: (&[f32], &[f32], Option<&[f32]>),
    nx: usize,
    nz: usize,
    margin: usize,
) -> (FieldError, Vec<f64>, Vec<f64>) {
    let (tvx, tvz, mask) = truth;
    let (vx, vz, flags) = est;
    let inside = |ix: usize, iz: usize| mask[iz * nx + ix] > 0.5;
    let v_max = tvx
        .iter()
        .zip(tvz)
        .zip(mask)
        .filter(|(_, m)| **m > 0.5)
        .map(|((a, b), _)| (*a as f64).hypot(*b as f64))
        .fold(0.0, f64::max);
    let mut out = FieldError { v_max, ..Default::default() };
    if v_max <= 0.0 || nx <= 2 * margin || nz <= 2 * margin {
        return (out, Vec::new(), Vec::new());
    }
    let (mut ex, mut ez) = (Vec::new(), Vec::new());
    for iz in margin..nz - margin {
        for ix in margin..nx - margin {
            if !(iz - margin..=iz + margin).all(|z| (ix - margin..=ix + margin).all(|x| inside(x, z))) {
                continue;
            }
            out.pixels += 1;
            let i = iz * nx + ix;
            if flags.is_some_and(|f| (f[i] as u32) & 1 != 0) || !(vx[i].is_finite() && vz[i].is_finite()) {
                out.no_estimate += 1;
                continue;
            }
            ex.push((vx[i] as f64 - tvx[i] as f64) / v_max);
            ez.push((vz[i] as f64 - tvz[i] as f64) / v_max);
        }
    }
    out.x = error_stats(&ex);
    out.z = error_stats(&ez);
    (out, ex, ez)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn stats_of_a_known_sample() {
        // Errors −0.04, −0.01, 0, 0.01, 0.03 (fractions of v_max).
        let s = error_stats(&[0.01, -0.04, 0.0, 0.03, -0.01]);
        assert!((s.bias - (-0.002)).abs() < 1e-12);
        assert!((s.rms - (0.0027f64 / 5.0).sqrt()).abs() < 1e-12);
        assert_eq!((s.median, s.q25, s.q75), (0.0, -0.01, 0.01));
        // |e| sorted: 0, .01, .01, .03, .04 → p75 = .03, p95 = .03 + .8·.01
        assert!((s.abs_p75 - 0.03).abs() < 1e-12 && (s.abs_p95 - 0.038).abs() < 1e-12);
        assert_eq!((s.within_2pct, s.within_10pct), (0.6, 1.0));
    }

    #[test]
    fn field_error_uses_the_eroded_mask_and_skips_flagged_pixels() {
        let (nx, nz) = (6, 5);
        let n = nx * nz;
        let mask: Vec<f32> = (0..n).map(|i| if i % nx >= 1 && i / nx >= 1 { 1.0 } else { 0.0 }).collect();
        let tvx: Vec<f32> = (0..n).map(|i| if mask[i] > 0.0 { 0.5 } else { 0.0 }).collect();
        let tvz = vec![0.0f32; n];
        let mut vx = tvx.clone();
        let vz: Vec<f32> = vec![0.01; n];
        vx[2 * nx + 2] = 0.46; // −8 % in x
        let mut flags = vec![0.0f32; n];
        flags[3 * nx + 3] = 1.0;
        let e = field_error((&tvx, &tvz, &mask), (&vx, &vz, Some(&flags)), nx, nz, 1);
        // Interior of the mask eroded by 1: ix 2..=4, iz 2..=3 → 6 pixels, one flagged.
        assert_eq!((e.pixels, e.no_estimate), (6, 1));
        assert_eq!(e.v_max, 0.5);
        assert!((e.z.bias - 0.02).abs() < 1e-7 && e.z.within_2pct == 1.0);
        assert!((e.x.within_10pct - 1.0).abs() < 1e-12 && (e.x.within_2pct - 0.8).abs() < 1e-12);
    }
}
