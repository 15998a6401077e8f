//! Test fixtures (feature `testkit`), shared by this crate's tests and the stability matrix
//! (`sonoflow stability`): the reference data reader, error norms, the smooth test field and its
//! corruption (noise, gross outliers, missing values), the N-D Neumann Laplacian, and the
//! extreme smoothn runs of `tests/extremes.rs` and `tests/robustness.rs` (the callers state the
//! bounds). Test code: it panics on a missing data file or a failed run.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::{Path, PathBuf};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use crate::{smoothn, SmoothnParams, SmoothnReport};

/// Directory of the PyMUST reference cases.
pub fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests").join("data")
}

/// Reads a little-endian real `.npy` file (through `sonoflow_fileio::npy`): (shape, data).
pub fn read_npy(path: &Path) -> (Vec<usize>, Vec<f64>) {
    let a = sonoflow_fileio::npy::read(path).unwrap_or_else(|e| panic!("{e}"));
    (a.shape, a.data)
}

/// Root-mean-square of `a − b`.
pub fn rms_diff(a: &[f64], b: &[f64]) -> f64 {
    (a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>() / a.len() as f64).sqrt()
}

/// ‖a − b‖ / ‖b‖.
pub fn nrms(a: &[f64], b: &[f64]) -> f64 {
    let d: f64 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
    let n: f64 = b.iter().map(|y| y * y).sum();
    (d / n).sqrt()
}

/// max |a − b|.
pub fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

/// The smooth 2-component test field `(cos 2πx sin πy, sin 2πx cos 1.5πy + 0.3)` on an ny × nx grid
/// (x, y in [0, 1)), component-major.
pub fn smooth_field(ny: usize, nx: usize) -> Vec<f64> {
    let mut f = vec![0.0; 2 * ny * nx];
    for i in 0..ny {
        for j in 0..nx {
            let (y, x) = (i as f64 / ny as f64, j as f64 / nx as f64);
            let tau = std::f64::consts::TAU;
            f[i * nx + j] = (tau * x).cos() * (std::f64::consts::PI * y).sin();
            f[ny * nx + i * nx + j] = (tau * x).sin() * (1.5 * std::f64::consts::PI * y).cos() + 0.3;
        }
    }
    f
}

/// `truth` + N(0, σ²) noise; then a fraction `outliers` of the grid points get uniform values in
/// ±2.5 in every component (fixed seed). Returns the noisy field and the outlier mask.
pub fn corrupt(truth: &[f64], components: usize, sigma: f64, outliers: f64, seed: u64) -> (Vec<f64>, Vec<bool>) {
    let n = truth.len() / components;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let normal = Normal::new(0.0, sigma).unwrap();
    let mut y: Vec<f64> = truth.iter().map(|t| t + normal.sample(&mut rng)).collect();
    let mask: Vec<bool> = (0..n).map(|_| rng.gen_bool(outliers)).collect();
    for p in (0..n).filter(|&p| mask[p]) {
        for c in 0..components {
            y[c * n + p] = rng.gen_range(-2.5..2.5);
        }
    }
    (y, mask)
}

/// Fixed-seed random mask with probability `p`.
pub fn random_mask(n: usize, p: f64, seed: u64) -> Vec<bool> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n).map(|_| rng.gen_bool(p)).collect()
}

/// Applies the N-D Neumann Laplacian (unit spacing, row-major grid) `m` times, matrix-free.
pub fn neumann_laplacian_pow(z: &[f64], shape: &[usize], m: u32) -> Vec<f64> {
    let mut cur = z.to_vec();
    for _ in 0..m {
        let mut next = vec![0.0; cur.len()];
        let mut stride = 1;
        for a in (0..shape.len()).rev() {
            for (p, out) in next.iter_mut().enumerate() {
                let i = (p / stride) % shape[a];
                if i > 0 {
                    *out += cur[p] - cur[p - stride];
                }
                if i + 1 < shape[a] {
                    *out += cur[p] - cur[p + stride];
                }
            }
            stride *= shape[a];
        }
        cur = next;
    }
    cur
}

/// Robust smoothing (bisquare weights), automatic S: the defaults otherwise.
pub fn robust_auto() -> SmoothnParams {
    SmoothnParams { robust: true, ..SmoothnParams::default() }
}

/// The 16 × 20 smooth field with σ = 0.05 noise (seed 1), once with NaN and once with ±inf at
/// the same 5 points, each smoothed robustly with automatic S: [NaN run, inf run].
pub fn nan_and_infinity_runs() -> [(Vec<f64>, SmoothnReport); 2] {
    let (mut y_nan, _) = corrupt(&smooth_field(16, 20), 2, 0.05, 0.0, 1);
    let mut y_inf = y_nan.clone();
    for (k, p) in [3usize, 77, 150, 151, 300].iter().enumerate() {
        y_nan[*p] = f64::NAN;
        y_inf[*p] = if k % 2 == 0 { f64::INFINITY } else { f64::NEG_INFINITY };
    }
    [y_nan, y_inf].map(|y| smoothn(&y, &[16, 20], 2, None, &robust_auto()).unwrap())
}

/// The 64 × 64 smooth field with σ = 0.1 noise plus 10 % of the points replaced by uniform values
/// in ±2.5 (seed `seed`), with the references a robust fit is measured against.
pub struct OutlierScene {
    pub truth: Vec<f64>,
    /// The corrupted field and its outlier mask.
    pub y: Vec<f64>,
    pub mask: Vec<bool>,
    /// RMS error of the non-robust smoothing of the same noise without outliers (the best one can
    /// hope for).
    pub e_clean: f64,
    /// RMS error of the non-robust smoothing of `y`, and its report.
    pub e_plain: f64,
    pub plain: SmoothnReport,
}

/// Grid of [`OutlierScene`].
pub const OUTLIER_GRID: [usize; 2] = [64, 64];

/// Builds [`OutlierScene`].
pub fn outlier_scene(seed: u64) -> OutlierScene {
    let [ny, nx] = OUTLIER_GRID;
    let truth = smooth_field(ny, nx);
    let (y, mask) = corrupt(&truth, 2, 0.1, 0.1, seed);
    let (clean, _) = corrupt(&truth, 2, 0.1, 0.0, seed);
    let (zc, _) = smoothn(&clean, &OUTLIER_GRID, 2, None, &SmoothnParams::default()).unwrap();
    let (z0, plain) = smoothn(&y, &OUTLIER_GRID, 2, None, &SmoothnParams::default()).unwrap();
    OutlierScene { e_clean: rms_diff(&zc, &truth), e_plain: rms_diff(&z0, &truth), truth, y, mask, plain }
}
