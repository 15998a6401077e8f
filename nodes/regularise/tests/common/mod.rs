//! Helpers shared by the integration tests: a minimal `.npy` reader, norms, test fields.
#![allow(dead_code, clippy::unwrap_used)]

use std::path::Path;

/// Reads a little-endian float64 C-order `.npy` file (format 1.0-3.0): (shape, data).
pub fn read_npy(path: &Path) -> (Vec<usize>, Vec<f64>) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(&bytes[..6], b"\x93NUMPY", "{}: not an .npy file", path.display());
    let (header_len, start) = if bytes[6] == 1 {
        (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10)
    } else {
        (u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize, 12)
    };
    let header = std::str::from_utf8(&bytes[start..start + header_len]).unwrap();
    assert!(header.contains("'descr': '<f8'"), "{}: need float64, header {header}", path.display());
    assert!(header.contains("'fortran_order': False"), "{}: need C order", path.display());
    let shape_str = header.split("'shape': (").nth(1).unwrap().split(')').next().unwrap();
    let shape: Vec<usize> =
        shape_str.split(',').filter(|s| !s.trim().is_empty()).map(|s| s.trim().parse().unwrap()).collect();
    let data: Vec<f64> =
        bytes[start + header_len..].chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().unwrap())).collect();
    assert_eq!(data.len(), shape.iter().product::<usize>(), "{}: size mismatch", path.display());
    (shape, data)
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

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

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
