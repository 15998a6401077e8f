//! The DCT against a naive O(n²) DCT-II (test reference only), round trips, layouts.
#![allow(clippy::unwrap_used)]
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sonoflow_regularise::dct::{Dct1d, DctN};

/// Naive O(n²) orthonormal DCT-II (test reference only).
fn naive_dct2(x: &[f64]) -> Vec<f64> {
    let n = x.len() as f64;
    (0..x.len())
        .map(|k| {
            let s: f64 = x
                .iter()
                .enumerate()
                .map(|(j, v)| v * (std::f64::consts::PI * k as f64 * (2.0 * j as f64 + 1.0) / (2.0 * n)).cos())
                .sum();
            s * if k == 0 { (1.0 / n).sqrt() } else { (2.0 / n).sqrt() }
        })
        .collect()
}

fn random(n: usize, seed: u64) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n).map(|_| rng.gen_range(-1.0..1.0)).collect()
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

// Tolerances: inputs are O(1); an FFT of length n has error ~ ε log2 n per coefficient
// (ε = 2.2e-16), the naive sum ~ ε n. 1e-13 leaves a margin of > 10 for n ≤ 101.
#[test]
fn dct1d_matches_naive_for_odd_and_even_lengths() {
    for n in [1, 2, 3, 4, 5, 7, 8, 12, 16, 17, 30, 99, 100, 101] {
        let x = random(n, n as u64);
        let plan = Dct1d::new(n);
        let mut s = plan.make_scratch();
        let mut y = vec![0.0; n];
        plan.forward(&x, &mut y, &mut s);
        let err = max_abs_diff(&y, &naive_dct2(&x));
        assert!(err < 1e-13, "n = {n}: max |fast - naive| = {err:e}");
        let mut back = vec![0.0; n];
        plan.inverse(&y, &mut back, &mut s);
        let err = max_abs_diff(&back, &x);
        assert!(err < 1e-14, "n = {n}: round trip error {err:e}");
        let mut inplace = x.clone();
        plan.forward_in_place(&mut inplace, &mut s);
        assert_eq!(inplace, y, "in-place forward differs from out-of-place (n = {n})");
        plan.inverse_in_place(&mut inplace, &mut s);
        assert_eq!(inplace, back, "in-place inverse differs from out-of-place (n = {n})");
    }
}

#[test]
fn dct1d_is_orthonormal_on_basis_vectors() {
    // Columns of the inverse are the DCT basis: forward(inverse(e_k)) = e_k and Σ x² is preserved.
    let n = 9;
    let plan = Dct1d::new(n);
    let mut s = plan.make_scratch();
    for k in 0..n {
        let mut e = vec![0.0; n];
        e[k] = 1.0;
        let mut x = vec![0.0; n];
        plan.inverse(&e, &mut x, &mut s);
        let norm2: f64 = x.iter().map(|v| v * v).sum();
        assert!((norm2 - 1.0).abs() < 1e-14, "basis vector {k} has norm² {norm2}");
    }
}

/// Naive N-D DCT by separable application of the naive 1-D transform in spatial layout.
fn naive_dctn(x: &[f64], shape: &[usize]) -> Vec<f64> {
    let mut y = x.to_vec();
    let mut stride = 1;
    for a in (0..shape.len()).rev() {
        let n = shape[a];
        let outer = y.len() / (n * stride);
        for o in 0..outer {
            for i in 0..stride {
                let idx: Vec<usize> = (0..n).map(|j| o * n * stride + j * stride + i).collect();
                let line: Vec<f64> = idx.iter().map(|&p| y[p]).collect();
                for (p, v) in idx.iter().zip(naive_dct2(&line)) {
                    y[*p] = v;
                }
            }
        }
        stride *= n;
    }
    y
}

#[test]
fn dctn_matches_naive_and_round_trips_in_1d_2d_3d_4d() {
    for shape in [
        vec![7],
        vec![1, 6],
        vec![5, 1],
        vec![6, 9],
        vec![13, 8],
        vec![3, 4, 5],
        vec![4, 1, 7, 3],
        vec![2, 3, 2, 5],
        vec![1, 1],
        vec![17, 7],
        vec![3, 9, 11],
        // full blocks of 8 lines (the vectorised column writes), even and odd line lengths
        vec![24, 16],
        vec![16, 33],
        vec![8, 9, 16],
        // two-axis inverse: the pairing of rows (k, n1 − k) and (0, n1/2) at the smallest sizes
        vec![2, 2],
        vec![3, 2],
        vec![2, 3],
        vec![9, 10],
        // powers of two 16 … 512 in full blocks: the AVX-512 four-line FFT where the CPU has it
        // (naive error ~ ε n ≤ 3e-14 at n = 128)
        vec![64, 128],
        vec![32, 16],
        vec![16, 8, 32],
    ] {
        let plan = DctN::new(&shape);
        let len = plan.len();
        let x = random(len, 7 + len as u64);
        let mut s = plan.make_scratch();
        let mut y = vec![0.0; len];
        plan.forward(&x, &mut y, &mut s);
        // Map the spatial-layout naive result into the spectral layout.
        let naive = naive_dctn(&x, &shape);
        let mut strides = vec![1usize; shape.len()];
        for a in (0..shape.len().saturating_sub(1)).rev() {
            strides[a] = strides[a + 1] * shape[a + 1];
        }
        let mut expected = vec![0.0; len];
        plan.spectral_indices(|flat, k| {
            expected[flat] = naive[k.iter().zip(&strides).map(|(k, s)| k * s).sum::<usize>()];
        });
        let err = max_abs_diff(&y, &expected);
        assert!(err < 1e-13, "shape {shape:?}: max |fast - naive| = {err:e}");
        let mut back = vec![0.0; len];
        plan.inverse(&y, &mut back, &mut s);
        let err = max_abs_diff(&back, &x);
        assert!(err < 1e-14, "shape {shape:?}: round trip error {err:e}");
        // The fused weight equals pre-multiplying, bit for bit.
        let w = random(len, 99);
        let wy: Vec<f64> = w.iter().zip(&y).map(|(a, b)| a * b).collect();
        let (mut fused, mut plain) = (vec![0.0; len], vec![0.0; len]);
        plan.inverse_weighted(&y, Some(&w), &mut fused, &mut s);
        plan.inverse(&wy, &mut plain, &mut s);
        assert_eq!(fused, plain, "shape {shape:?}: weighted inverse");
    }
}

/// The residual sum that also keeps the inverse writes exactly what `inverse_weighted` returns and
/// sums exactly what `weighted_rss` sums (the smoother reuses the kept inverse after a GCV search).
#[test]
fn weighted_rss_keep_writes_the_inverse_bit_for_bit() {
    for shape in [vec![37], vec![24, 16], vec![13, 18], vec![16, 33], vec![5, 3, 11], vec![6, 1]] {
        let plan = DctN::new(&shape);
        let len = plan.len();
        let (x, g, y) = (random(len, 1), random(len, 2), random(len, 3));
        let w: Vec<f64> = random(len, 4).iter().map(|v| v.abs()).collect();
        let mut s = plan.make_scratch();
        let (mut inv, mut kept, mut work) = (vec![0.0; len], vec![0.0; len], vec![0.0; len]);
        plan.inverse_weighted(&x, Some(&g), &mut inv, &mut s);
        let rss = plan.weighted_rss(&x, Some(&g), &y, &w, &mut work, &mut s);
        let rss_kept = plan.weighted_rss_keep(&x, Some(&g), (&y, &w), &mut work, Some(&mut kept), &mut s);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&kept), bits(&inv), "shape {shape:?}: kept inverse");
        assert_eq!(rss_kept.to_bits(), rss.to_bits(), "shape {shape:?}: rss");
        let direct: f64 = (0..len).map(|i| w[i] * (y[i] - inv[i]) * (y[i] - inv[i])).sum();
        assert!((rss - direct).abs() <= 1e-12 * direct, "shape {shape:?}: rss {rss} vs {direct}");
    }
}

#[test]
fn spectral_axes_rotate_the_non_singleton_axes() {
    assert_eq!(DctN::new(&[4, 5]).spectral_axes(), vec![1, 0]);
    assert_eq!(DctN::new(&[2, 1, 3, 4]).spectral_axes(), vec![2, 3, 0]);
    assert_eq!(DctN::new(&[1, 6]).spectral_axes(), vec![1]);
    assert!(DctN::new(&[1, 1]).spectral_axes().is_empty());
}

#[test]
fn forward_pseudo_equals_forming_the_pseudo_data_first() {
    // Two-axis grids (fused: rows formed as read; even, odd and a 1-row-pair case), 1-D and 3-D.
    for shape in [vec![128, 128], vec![13, 18], vec![9, 7], vec![2, 5], vec![31], vec![5, 3, 11]] {
        let plan = DctN::new(&shape);
        let n = plan.len();
        let (y, z) = (random(n, 11), random(n, 12));
        let w: Vec<f64> = random(n, 13).iter().map(|v| v.abs()).collect();
        let pseudo: Vec<f64> = (0..n).map(|i| w[i] * (y[i] - z[i]) + z[i]).collect();
        let mut s = plan.make_scratch();
        let (mut a, mut b, mut work) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        plan.forward(&pseudo, &mut a, &mut s);
        plan.forward_pseudo((&y, &z, &w), &mut work, &mut b, &mut s);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&a), bits(&b), "shape {shape:?}");
    }
}
