//! With a given S and no robust weights the smoother is a linear operator defined exactly:
//! `(W + S L^m) z = W y`, `L` the N-D Neumann Laplacian scaled by the normalised spacing. These tests
//! build that system densely (independently of the DCT) and compare.
#![allow(clippy::unwrap_used, clippy::needless_range_loop)] // test helpers; dense linear algebra by index
use sonoflow_regularise::testkit::*;
use sonoflow_regularise::{smoothn, SmoothnParams};

/// Dense N-D Neumann Laplacian `Σ_a L_a / dI_a²` (row-major grid), `L_a = tridiag(−1, 2, −1)` with
/// 1 in the first and last diagonal entries (its eigenvectors are the DCT-II basis).
fn laplacian(shape: &[usize], spacing: &[f64]) -> Vec<Vec<f64>> {
    let n: usize = shape.iter().product();
    let mx = spacing.iter().copied().fold(0.0, f64::max);
    let mut l = vec![vec![0.0; n]; n];
    let mut stride = 1;
    for a in (0..shape.len()).rev() {
        let inv = 1.0 / (spacing[a] / mx).powi(2);
        for p in 0..n {
            let i = (p / stride) % shape[a];
            for q in [i.checked_sub(1), (i + 1 < shape[a]).then_some(i + 1)].into_iter().flatten() {
                let pq = p - i * stride + q * stride;
                l[p][p] += inv;
                l[p][pq] -= inv;
            }
        }
        stride *= shape[a];
    }
    l
}

fn matmul(a: &[Vec<f64>], b: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let n = a.len();
    (0..n).map(|i| (0..n).map(|j| (0..n).map(|k| a[i][k] * b[k][j]).sum()).collect()).collect()
}

/// Solves `a x = b` by Gaussian elimination with partial pivoting.
fn solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Vec<f64> {
    let n = b.len();
    for col in 0..n {
        let piv = (col..n).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs())).unwrap();
        a.swap(col, piv);
        b.swap(col, piv);
        for row in col + 1..n {
            let f = a[row][col] / a[col][col];
            for k in col..n {
                a[row][k] -= f * a[col][k];
            }
            b[row] -= f * b[col];
        }
    }
    let mut x = vec![0.0; n];
    for row in (0..n).rev() {
        let s: f64 = (row + 1..n).map(|k| a[row][k] * x[k]).sum();
        x[row] = (b[row] - s) / a[row][row];
    }
    x
}

/// Dense solution of `(W + S L^m) z = W y` for each component (W = 1 where weights are None).
fn dense_smooth(y: &[f64], shape: &[usize], spacing: &[f64], w: &[f64], s: f64, m: u32) -> Vec<f64> {
    let n = w.len();
    let l = laplacian(shape, spacing);
    let mut p = l.clone();
    for _ in 1..m {
        p = matmul(&p, &l);
    }
    let a: Vec<Vec<f64>> =
        (0..n).map(|i| (0..n).map(|j| s * p[i][j] + if i == j { w[i] } else { 0.0 }).collect()).collect();
    y.chunks(n)
        .flat_map(|yc| {
            let b: Vec<f64> = yc.iter().zip(w).map(|(v, w)| if *w > 0.0 { v * w } else { 0.0 }).collect();
            solve(a.clone(), b)
        })
        .collect()
}

fn noisy(len: usize, seed: u64) -> Vec<f64> {
    random_mask(len, 0.5, seed)
        .iter()
        .enumerate()
        .map(|(i, b)| (i as f64 * 0.37).sin() + if *b { 0.2 } else { -0.1 })
        .collect()
}

#[test]
fn fixed_s_unweighted_equals_a_dense_solve_in_1d_2d_3d_for_orders_1_2_3() {
    for (shape, spacing, comps) in [
        (vec![23], vec![1.0], 1),
        (vec![7, 9], vec![1.0, 1.0], 2),
        (vec![6, 8], vec![2.0, 0.7], 1),
        (vec![4, 3, 5], vec![1.0, 1.0, 1.5], 2),
        (vec![1, 12], vec![1.0, 1.0], 1),
    ] {
        let n: usize = shape.iter().product();
        let y = noisy(n * comps, n as u64);
        for m in 1..=3 {
            for s in [0.05, 3.0, 200.0] {
                let p =
                    SmoothnParams { s: Some(s), order: m, spacing: Some(spacing.clone()), ..SmoothnParams::default() };
                let (z, _) = smoothn(&y, &shape, comps, None, &p).unwrap();
                let want = dense_smooth(&y, &shape, &spacing, &vec![1.0; n], s, m);
                // Rounding of the dense LU grows with cond(I + S L^m) ≤ 1 + S·max Λ^m (up to ~1e7 here):
                // measured ≤ 1e-15 for well-conditioned cases, worst 3e-11 (order 3, S = 200,
                // spacing 2 : 0.7); a wrong operator (boundary, spacing, order) gives O(0.1).
                let err = max_abs_diff(&z, &want);
                assert!(err < 1e-9, "shape {shape:?} spacing {spacing:?} m={m} S={s}: max diff {err:e}");
            }
        }
    }
}

#[test]
fn fixed_s_with_weights_and_missing_values_converges_to_the_dense_weighted_solution() {
    let shape = [8, 7];
    let n = 56;
    let mut y = noisy(2 * n, 5);
    let mut w: Vec<f64> = noisy(n, 6).iter().map(|v| 0.2 + v.abs()).collect();
    let missing = random_mask(n, 0.1, 7);
    for p in (0..n).filter(|&p| missing[p]) {
        y[p] = f64::NAN; // missing in one component ⇒ the point is missing in both
    }
    let mx = w.iter().copied().fold(0.0, f64::max);
    w.iter_mut().for_each(|v| *v /= mx); // MATLAB normalises the weights by their maximum
    let w_eff: Vec<f64> = w.iter().zip(&missing).map(|(w, m)| if *m { 0.0 } else { *w }).collect();
    for m in 1..=3 {
        let p = SmoothnParams { s: Some(2.0), order: m, tol_z: 1e-13, max_iter: 20_000, ..SmoothnParams::default() };
        let (z, r) = smoothn(&y, &shape, 2, Some(&w), &p).unwrap();
        assert!(r.converged, "m = {m}: {} iterations", r.iterations);
        let want = dense_smooth(&y, &shape, &[1.0, 1.0], &w_eff, 2.0, m);
        // Stopped at a relative step of 1e-13; the fixed-point iteration contracts geometrically, so
        // the remaining error is ≤ step·ρ/(1−ρ); measured 3e-14 to 5e-14 after 93 to 99 iterations.
        let err = max_abs_diff(&z, &want);
        assert!(err < 1e-9, "m = {m}: max diff {err:e} after {} iterations", r.iterations);
    }
}

#[test]
fn s_to_zero_returns_the_data() {
    let shape = [9, 11];
    let y = noisy(2 * 99, 8);
    for m in 1..=3 {
        let p = SmoothnParams { s: Some(1e-12), order: m, ..SmoothnParams::default() };
        let (z, _) = smoothn(&y, &shape, 2, None, &p).unwrap();
        // 1 − Γ ≤ S·max Λ^m = 1e-12·8³ ⇒ |z − y| ≤ 5e-10·max|y|.
        assert!(max_abs_diff(&z, &y) < 1e-9, "m = {m}");
    }
}

#[test]
fn s_to_infinity_returns_the_weighted_mean_for_every_order_not_the_plane() {
    let (ny, nx) = (10, 13);
    let n = ny * nx;
    // A plane: the least-squares plane fit of a plane is itself, yet the DCT smoother's penalty
    // (reflective boundaries) has only constants in its null space, so S → ∞ gives the mean.
    let plane: Vec<f64> = (0..n).map(|p| 0.5 + 0.1 * (p / nx) as f64 - 0.07 * (p % nx) as f64).collect();
    let w: Vec<f64> = noisy(n, 9).iter().map(|v| 0.1 + v.abs()).collect();
    let wmean = plane.iter().zip(&w).map(|(y, w)| y * w).sum::<f64>() / w.iter().sum::<f64>();
    let mean = plane.iter().sum::<f64>() / n as f64;
    for m in 1..=3 {
        // Smallest nonzero Λ^m = (2 − 2cos(π/13))³ ≈ 1.6e-5; S = 1e16 makes every Γ_k≠0 < 1e-10.
        let p = SmoothnParams { s: Some(1e16), order: m, tol_z: 1e-12, max_iter: 1000, ..SmoothnParams::default() };
        let (z, _) = smoothn(&plane, &[ny, nx], 1, None, &p).unwrap();
        assert!(z.iter().all(|v| (v - mean).abs() < 1e-9), "m = {m}: unweighted limit is the mean {mean}");
        let (zw, r) = smoothn(&plane, &[ny, nx], 1, Some(&w), &p).unwrap();
        assert!(r.converged);
        // Geometric convergence at tol 1e-12 ⇒ error ≲ 1e-11 (measured 3e-13).
        assert!(zw.iter().all(|v| (v - wmean).abs() < 1e-9), "m = {m}: weighted limit {} vs Σwy/Σw = {wmean}", zw[0]);
        assert!(max_abs_diff(&zw, &plane) > 0.3, "the limit is not the plane");
    }
}
