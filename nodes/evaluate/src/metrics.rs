//! Error of an estimated vector field against ground truth, as paper 1 reports it: per pixel
//! inside the vessel, `e_x = (vx − vx_true)/v_max` and `e_z = (vz − vz_true)/v_max` with `v_max`
//! the largest true speed in the field; then the distribution of each (bias, RMS, median,
//! quartiles, the half-width holding 75 % of the pixels, 95th percentile of |e|, fraction within
//! ±2 % and ±10 %). Beside them, where the error is: the gain of each component (the slope of
//! the estimate against the truth) and the errors by distance to the vessel wall, the signature of
//! a velocity blurred over a resolution cell (over-estimated near the walls, a flattened centre).
//! No IPC: the evaluator node and the tests call it.

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
    /// Gain of vx and vz: the least-squares slope of the estimate against the truth through the
    /// origin, Σ v·v_true / Σ v_true² over the evaluated pixels (1: no scale error; below 1: the
    /// speeds are under-estimated). `None` where the true component is zero throughout.
    #[serde(default)]
    pub gain_x: Option<f64>,
    #[serde(default)]
    pub gain_z: Option<f64>,
    /// The errors by distance to the wall (bands of [`WALL_BANDS_M`]; empty bands left out).
    #[serde(default)]
    pub by_wall_distance: Vec<BandError>,
}

/// Edges of the wall-distance bands (m): 0–1, 1–2, 2–3 mm and beyond 3 mm.
pub const WALL_BANDS_M: [f64; 4] = [0.0, 1e-3, 2e-3, 3e-3];

/// One component's error in one band (fractions of `v_max`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BandStats {
    /// Mean error.
    pub bias: f64,
    /// 75th percentile of |e|.
    pub abs_p75: f64,
    /// Gain (see [`FieldError::gain_x`]).
    pub gain: Option<f64>,
}

/// Errors of the pixels whose distance to the wall is in `[from_m, to_m)`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BandError {
    /// Distance to the wall (m): from the pixel's centre to the centre of the nearest pixel
    /// outside the vessel.
    pub from_m: f64,
    /// Upper edge (m); `None`: no upper edge.
    pub to_m: Option<f64>,
    /// Evaluated pixels (with an estimate) in the band.
    pub pixels: usize,
    pub x: BandStats,
    pub z: BandStats,
}

/// The pixel grid of the fields: columns, rows and spacing (m).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelGrid {
    pub nx: usize,
    pub nz: usize,
    pub dx: f64,
    pub dz: f64,
}

/// Per evaluated pixel: errors and true velocity (fractions of `v_max`) and the distance to the
/// wall (m, infinite when no pixel of the field is outside the vessel). Pooled over packets for the
/// overall figures.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Samples {
    pub ex: Vec<f64>,
    pub ez: Vec<f64>,
    pub tx: Vec<f64>,
    pub tz: Vec<f64>,
    pub wall_m: Vec<f64>,
}

impl Samples {
    /// Appends `other`'s pixels.
    pub fn append(&mut self, other: &Samples) {
        self.ex.extend_from_slice(&other.ex);
        self.ez.extend_from_slice(&other.ez);
        self.tx.extend_from_slice(&other.tx);
        self.tz.extend_from_slice(&other.tz);
        self.wall_m.extend_from_slice(&other.wall_m);
    }

    /// The statistics of these pixels, with the counts of the [`FieldError`] they belong to.
    pub fn field_error(&self, pixels: usize, no_estimate: usize, v_max: f64) -> FieldError {
        let bands = WALL_BANDS_M
            .iter()
            .enumerate()
            .filter_map(|(k, &from_m)| {
                let to_m = WALL_BANDS_M.get(k + 1).copied();
                let idx: Vec<usize> = (0..self.wall_m.len())
                    .filter(|&i| self.wall_m[i] >= from_m && to_m.is_none_or(|t| self.wall_m[i] < t))
                    .collect();
                if idx.is_empty() {
                    return None;
                }
                let band = |e: &[f64], t: &[f64]| {
                    let (be, bt): (Vec<f64>, Vec<f64>) = idx.iter().map(|&i| (e[i], t[i])).unzip();
                    let s = error_stats(&be);
                    BandStats { bias: s.bias, abs_p75: s.abs_p75, gain: gain(&be, &bt) }
                };
                Some(BandError {
                    from_m,
                    to_m,
                    pixels: idx.len(),
                    x: band(&self.ex, &self.tx),
                    z: band(&self.ez, &self.tz),
                })
            })
            .collect();
        FieldError {
            pixels,
            no_estimate,
            v_max,
            x: error_stats(&self.ex),
            z: error_stats(&self.ez),
            gain_x: gain(&self.ex, &self.tx),
            gain_z: gain(&self.ez, &self.tz),
            by_wall_distance: bands,
        }
    }
}

/// Σ v·t / Σ t² with v = t + e; `None` when Σ t² is zero (or the sums are not finite).
fn gain(e: &[f64], t: &[f64]) -> Option<f64> {
    let (num, den) = e.iter().zip(t).fold((0.0, 0.0), |(n, d), (e, t)| (n + (t + e) * t, d + t * t));
    (den > 0.0 && num.is_finite() && den.is_finite()).then(|| num / den)
}

/// Distance (m) from every pixel to the centre of the nearest pixel with `mask` ≤ 0.5 (0 for
/// those pixels themselves; infinite when there is none). Only the outside pixels touching the
/// vessel can be nearest, so the search runs over those.
pub fn wall_distance(mask: &[f32], g: PixelGrid) -> Vec<f64> {
    let inside = |ix: usize, iz: usize| mask[iz * g.nx + ix] > 0.5;
    let mut border = Vec::new();
    for iz in 0..g.nz {
        for ix in 0..g.nx {
            if inside(ix, iz) {
                continue;
            }
            let touches = (iz.saturating_sub(1)..=(iz + 1).min(g.nz - 1))
                .any(|z| (ix.saturating_sub(1)..=(ix + 1).min(g.nx - 1)).any(|x| inside(x, z)));
            if touches {
                border.push((ix as f64 * g.dx, iz as f64 * g.dz));
            }
        }
    }
    let mut out = vec![0.0; g.nx * g.nz];
    for iz in 0..g.nz {
        for ix in 0..g.nx {
            if inside(ix, iz) {
                let (x, z) = (ix as f64 * g.dx, iz as f64 * g.dz);
                out[iz * g.nx + ix] =
                    border.iter().map(|(bx, bz)| (bx - x).hypot(bz - z)).fold(f64::INFINITY, f64::min);
            }
        }
    }
    out
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
/// truth (`vx`, `vz`, `mask`), both `nz × nx` row-major on `grid`. Pixels count when the truth
/// mask is set on the whole `(2·margin+1)²` neighbourhood (a wall pixel's Doppler mixes both
/// sides).
pub fn field_error(
    truth: (&[f32], &[f32], &[f32]),
    est: (&[f32], &[f32], Option<&[f32]>),
    grid: PixelGrid,
    margin: usize,
) -> FieldError {
    field_error_samples(truth, est, grid, margin).0
}

/// [`field_error`] and the per-pixel samples it summarises (one per counted pixel with an
/// estimate, row-major order): the report's histograms and the pooled overall figures.
pub fn field_error_samples(
    truth: (&[f32], &[f32], &[f32]),
    est: (&[f32], &[f32], Option<&[f32]>),
    grid: PixelGrid,
    margin: usize,
) -> (FieldError, Samples) {
    let PixelGrid { nx, nz, .. } = grid;
    let (tvx, tvz, mask) = truth;
    let (vx, vz, flags) = est;
    let v_max = max_speed(tvx, tvz, mask);
    if v_max <= 0.0 || nx <= 2 * margin || nz <= 2 * margin {
        return (FieldError { v_max, ..Default::default() }, Samples::default());
    }
    let wall = wall_distance(mask, grid);
    let mut smp = Samples::default();
    let counted = counted_pixels(mask, grid, margin);
    let mut no_estimate = 0;
    for &i in &counted {
        if flags.is_some_and(|f| (f[i] as u32) & 1 != 0) || !(vx[i].is_finite() && vz[i].is_finite()) {
            no_estimate += 1;
            continue;
        }
        smp.ex.push((vx[i] as f64 - tvx[i] as f64) / v_max);
        smp.ez.push((vz[i] as f64 - tvz[i] as f64) / v_max);
        smp.tx.push(tvx[i] as f64 / v_max);
        smp.tz.push(tvz[i] as f64 / v_max);
        smp.wall_m.push(wall[i]);
    }
    (smp.field_error(counted.len(), no_estimate, v_max), smp)
}

/// Error of one look's colour-Doppler map against the truth projected on the look's direction:
/// per counted pixel `e = (v − a·v_true)/v_max`, `a` the map's projection vector (planes
/// `projection_x`, `projection_z`), `v_max` the largest true speed — where a look reads a scale
/// error (e.g. its band's mean frequency differs from the demodulation frequency) or a bias of
/// its own before the vector solve mixes the looks.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LookError {
    /// Transmit tilt and receive angle (degrees), demodulation frequency (Hz).
    pub tx_angle_deg: f64,
    pub rx_angle_deg: f64,
    pub fc: f64,
    /// Pixels inside the vessel (as for the fields) and, of those, without an estimate.
    pub pixels: usize,
    pub no_estimate: usize,
    /// Distribution of e (fractions of v_max).
    pub error: ErrorStats,
    /// Σ v·(a·v_true) / Σ (a·v_true)²: 1 without scale error. `None` where a·v_true is zero.
    pub gain: Option<f64>,
}

/// One look's map planes: velocity, optional flags, projection_x, projection_z.
pub type LookPlanes<'a> = (&'a [f32], Option<&'a [f32]>, &'a [f32], &'a [f32]);

/// One look's samples (see [`LookError`]): errors e, projected truths t (both fractions of the
/// packet's v_max), pixels counted and pixels without estimate. The truth is (`vx`, `vz`,
/// `mask`); the map (`velocity`, optional `flags`, `projection_x`, `projection_z`), all on `grid`.
pub fn look_error_samples(
    truth: (&[f32], &[f32], &[f32]),
    map: LookPlanes<'_>,
    grid: PixelGrid,
    margin: usize,
) -> (Vec<f64>, Vec<f64>, usize, usize) {
    let (tvx, tvz, mask) = truth;
    let (vel, flags, px, pz) = map;
    let v_max = max_speed(tvx, tvz, mask);
    let (mut e, mut t, mut no_estimate) = (Vec::new(), Vec::new(), 0);
    let counted = counted_pixels(mask, grid, margin);
    if v_max <= 0.0 {
        return (e, t, counted.len(), 0);
    }
    for &i in &counted {
        if flags.is_some_and(|f| (f[i] as u32) & 1 != 0) || !vel[i].is_finite() {
            no_estimate += 1;
            continue;
        }
        let truth = f64::from(px[i]) * f64::from(tvx[i]) + f64::from(pz[i]) * f64::from(tvz[i]);
        e.push((f64::from(vel[i]) - truth) / v_max);
        t.push(truth / v_max);
    }
    (e, t, counted.len(), no_estimate)
}

/// [`LookError`] from pooled samples.
pub fn look_error(look: (f64, f64, f64), e: &[f64], t: &[f64], pixels: usize, no_estimate: usize) -> LookError {
    LookError {
        tx_angle_deg: look.0.to_degrees(),
        rx_angle_deg: look.1.to_degrees(),
        fc: look.2,
        pixels,
        no_estimate,
        error: error_stats(e),
        gain: gain(e, t),
    }
}

/// Largest true speed inside the mask.
fn max_speed(tvx: &[f32], tvz: &[f32], mask: &[f32]) -> f64 {
    tvx.iter()
        .zip(tvz)
        .zip(mask)
        .filter(|(_, m)| **m > 0.5)
        .map(|((a, b), _)| (*a as f64).hypot(*b as f64))
        .fold(0.0, f64::max)
}

/// Row-major indices of the pixels whose whole `(2·margin+1)²` neighbourhood is inside the mask.
fn counted_pixels(mask: &[f32], grid: PixelGrid, margin: usize) -> Vec<usize> {
    let PixelGrid { nx, nz, .. } = grid;
    if nx <= 2 * margin || nz <= 2 * margin {
        return Vec::new();
    }
    let inside = |ix: usize, iz: usize| mask[iz * nx + ix] > 0.5;
    let mut out = Vec::new();
    for iz in margin..nz - margin {
        for ix in margin..nx - margin {
            if (iz - margin..=iz + margin).all(|z| (ix - margin..=ix + margin).all(|x| inside(x, z))) {
                out.push(iz * nx + ix);
            }
        }
    }
    out
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
        let e = field_error((&tvx, &tvz, &mask), (&vx, &vz, Some(&flags)), PixelGrid { nx, nz, dx: 1e-3, dz: 1e-3 }, 1);
        // Interior of the mask eroded by 1: ix 2..=4, iz 2..=3 → 6 pixels, one flagged.
        assert_eq!((e.pixels, e.no_estimate), (6, 1));
        assert_eq!(e.v_max, 0.5);
        assert!((e.z.bias - 0.02).abs() < 1e-7 && e.z.within_2pct == 1.0);
        assert!((e.x.within_10pct - 1.0).abs() < 1e-12 && (e.x.within_2pct - 0.8).abs() < 1e-12);
    }

    #[test]
    fn wall_distance_of_a_channel() {
        // rows 3 ..= 12 of 16 inside, full width: the nearest outside pixel is straight above or
        // below (rows 2 and 13), at dz per row
        let g = PixelGrid { nx: 9, nz: 16, dx: 0.25e-3, dz: 0.5e-3 };
        let mask: Vec<f32> = (0..g.nx * g.nz).map(|i| if (3..=12).contains(&(i / g.nx)) { 1.0 } else { 0.0 }).collect();
        let d = wall_distance(&mask, g);
        for iz in 0..g.nz {
            let want = if (3..=12).contains(&iz) { (iz - 2).min(13 - iz) as f64 * g.dz } else { 0.0 };
            assert!((d[iz * g.nx + 4] - want).abs() < 1e-15, "row {iz}: {} vs {want}", d[iz * g.nx + 4]);
        }
        // a vessel filling the field has no wall
        assert!(wall_distance(&[1.0; 4], PixelGrid { nx: 2, nz: 2, dx: 1e-3, dz: 1e-3 })
            .iter()
            .all(|d| d.is_infinite()));
    }

    #[test]
    fn gains_and_wall_bands_locate_a_blurred_profile() {
        // Poiseuille flow along x in a channel 8.2 mm wide (0.2 mm pixels); the estimate reads
        // 20 % high within 1 mm of the wall and 10 % low beyond 2 mm, exact in between: the
        // signature of blur. The bands must return exactly those gains, the true vz (zero) none.
        let g = PixelGrid { nx: 20, nz: 45, dx: 0.2e-3, dz: 0.2e-3 };
        let n = g.nx * g.nz;
        let inside = |iz: usize| (2..=42).contains(&iz);
        let mask: Vec<f32> = (0..n).map(|i| if inside(i / g.nx) { 1.0 } else { 0.0 }).collect();
        let wall = wall_distance(&mask, g);
        let tvx: Vec<f32> = (0..n)
            .map(|i| {
                let y = (i / g.nx) as f64 - 22.0; // −20 ..= 20 inside, wall at ±21
                if inside(i / g.nx) {
                    (0.5 * (1.0 - (y / 21.0).powi(2))) as f32
                } else {
                    0.0
                }
            })
            .collect();
        let tvz = vec![0.0f32; n];
        let vx: Vec<f32> = (0..n)
            .map(|i| {
                let k = if wall[i] < 1e-3 {
                    1.2
                } else if wall[i] >= 2e-3 {
                    0.9
                } else {
                    1.0
                };
                (f64::from(tvx[i]) * k) as f32
            })
            .collect();
        let e = field_error((&tvx, &tvz, &mask), (&vx, &tvz, None), g, 1);
        let bands: Vec<(f64, Option<f64>)> = e.by_wall_distance.iter().map(|b| (b.from_m, b.to_m)).collect();
        assert_eq!(bands, vec![(0.0, Some(1e-3)), (1e-3, Some(2e-3)), (2e-3, Some(3e-3)), (3e-3, None)]);
        let gx: Vec<f64> = e.by_wall_distance.iter().map(|b| b.x.gain.unwrap()).collect();
        for (got, want) in gx.iter().zip([1.2, 1.0, 0.9, 0.9]) {
            assert!((got - want).abs() < 1e-6, "{gx:?}");
        }
        assert!(e.by_wall_distance[0].x.bias > 0.0 && e.by_wall_distance[3].x.bias < 0.0);
        assert!(e.by_wall_distance.iter().all(|b| b.z.gain.is_none() && b.z.bias == 0.0) && e.gain_z.is_none());
        // every evaluated pixel is in exactly one band; the overall gain lies between the bands'
        assert_eq!(e.by_wall_distance.iter().map(|b| b.pixels).sum::<usize>(), e.pixels);
        let gx_all = e.gain_x.unwrap();
        assert!(gx_all > 0.9 && gx_all < 1.2, "{gx_all}");
        // margin 1 (one row from the wall): the first band starts at 2 rows, 0.4 mm
        assert_eq!(e.pixels, 18 * 39);
        // the table says where the error is
        let md = crate::evaluation::markdown(&crate::evaluation::Evaluation {
            packets: vec![crate::evaluation::PacketEval {
                packet: 0,
                t_valid: 0.0,
                fields: [("raw".to_string(), e)].into(),
            }],
            ..Default::default()
        });
        assert!(md.contains("| raw | 0–1 mm |") && md.contains("| 1.200 |") && md.contains("| raw | ≥ 3 mm |"), "{md}");
    }
}
