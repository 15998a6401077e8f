//! Element-wise kernels of the smoother with a fixed summation order: 4-lane partial sums and
//! fixed-size chunks (independent of the thread count), run on rayon threads when the `parallel`
//! feature is on. Same inputs give the same bits for any number of threads.

/// Runs `f` on every component, on rayon threads when the `parallel` feature is on. Each
/// component's arithmetic is sequential, so the result does not depend on the thread count.
pub(crate) fn for_each_component<T: Send, F: Fn(&mut T) + Sync + Send>(comps: &mut [T], f: F) {
    #[cfg(feature = "parallel")]
    if comps.len() > 1 && rayon::current_num_threads() > 1 {
        use rayon::prelude::*;
        comps.par_iter_mut().for_each(f);
        return;
    }
    comps.iter_mut().for_each(f);
}

/// Runs `f(i, chunk)` on the [`CHUNK`]-sized chunks of `out` (chunk `i` starts at `i·CHUNK`), on
/// rayon threads when enabled. Chunks are independent, so the result does not depend on the thread
/// count.
pub(crate) fn for_each_chunk<F: Fn(usize, &mut [f64]) + Sync + Send>(out: &mut [f64], f: F) {
    #[cfg(feature = "parallel")]
    if out.len() > CHUNK && rayon::current_num_threads() > 1 {
        use rayon::prelude::*;
        out.par_chunks_mut(CHUNK).enumerate().for_each(|(i, c)| f(i, c));
        return;
    }
    out.chunks_mut(CHUNK).enumerate().for_each(|(i, c)| f(i, c));
}

/// `Σ_i f(a_i, b_i)` accumulated in 4 interleaved lanes: a fixed order (deterministic) that the
/// compiler can vectorise.
#[inline(always)]
pub(crate) fn lane_sum(a: &[f64], b: &[f64], f: impl Fn(f64, f64) -> f64) -> f64 {
    let mut acc = [0.0f64; 4];
    let body = a.len() / 4 * 4;
    for (a4, b4) in a[..body].chunks_exact(4).zip(b[..body].chunks_exact(4)) {
        for l in 0..4 {
            acc[l] += f(a4[l], b4[l]);
        }
    }
    let tail: f64 = a[body..].iter().zip(&b[body..]).map(|(x, y)| f(*x, *y)).sum();
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// `Σ v` in 16 interleaved lanes (four independent vector chains, so the additions run at the
/// adders' throughput instead of their latency), combined in a fixed order.
#[inline(always)]
fn sum16(v: &[f64]) -> f64 {
    let mut acc = [0.0f64; 16];
    let body = v.len() / 16 * 16;
    for c in v[..body].chunks_exact(16) {
        for l in 0..16 {
            acc[l] += c[l];
        }
    }
    let tail: f64 = v[body..].iter().sum();
    let mut quads = [0.0f64; 4];
    for (q, quad) in quads.iter_mut().enumerate() {
        *quad = (acc[q] + acc[q + 4]) + (acc[q + 8] + acc[q + 12]);
    }
    (quads[0] + quads[1]) + (quads[2] + quads[3]) + tail
}

/// Elements per chunk of [`gamma_sums`] (fixed, so partial sums do not depend on the thread count).
pub(crate) const CHUNK: usize = 4096;

/// `Γ = 1/(1 + S Λ^m)` into `gamma`; returns `[Σ Γ, Σ power·(Γ − 1)²]` (the second 0 without
/// `power`). `square = Some(n)`: `lm` is an n × n array equal to its transpose (bit for bit), so
/// only the upper triangle is divided and mirrored (the same values). Chunks of [`CHUNK`] run on
/// rayon threads when enabled; their partial sums are added in chunk order, so the result is the
/// same for any thread count.
pub(crate) fn gamma_sums(
    gamma: &mut [f64],
    lm: &[f64],
    power: Option<&[f64]>,
    s: f64,
    square: Option<usize>,
    partials: &mut Vec<[f64; 2]>,
) -> [f64; 2] {
    #[allow(unused_mut)]
    let mut divided = None;
    #[cfg(target_arch = "x86_64")]
    if let Some(n) = square {
        if n.is_multiple_of(8) && n * n == gamma.len() && avx512() {
            // SAFETY: the CPU supports AVX-512F; the lengths are checked inside.
            divided = Some(unsafe { gamma_symmetric_avx512(gamma, lm, n, s) });
        } else if n.is_multiple_of(4) && n * n == gamma.len() && avx2() {
            // SAFETY: the CPU supports AVX2; the lengths are checked inside.
            divided = Some(unsafe { gamma_symmetric_avx2(gamma, lm, n, s) });
        }
    }
    if let (Some(trace), None) = (divided, power) {
        // The trace came with the divisions, and no other sum is asked for.
        partials.clear();
        return [trace, 0.0];
    }
    let (trace, divided) = (divided, divided.is_some());
    let work = |i: usize, g: &mut [f64]| -> [f64; 2] {
        let range = i * CHUNK..i * CHUNK + g.len();
        let (lm, pw) = (&lm[range.clone()], power.map(|pw| &pw[range]));
        #[cfg(target_arch = "x86_64")]
        if avx2() {
            // SAFETY: the CPU supports AVX2.
            return unsafe { gamma_chunk_avx2(g, lm, pw, s, !divided) };
        }
        gamma_chunk(g, lm, pw, s, !divided)
    };
    partials.clear();
    #[cfg(feature = "parallel")]
    if gamma.len() > CHUNK && rayon::current_num_threads() > 1 {
        use rayon::prelude::*;
        gamma.par_chunks_mut(CHUNK).enumerate().map(|(i, g)| work(i, g)).collect_into_vec(partials);
    }
    if partials.is_empty() {
        partials.extend(gamma.chunks_mut(CHUNK).enumerate().map(|(i, g)| work(i, g)));
    }
    let [tr, rss] = partials.iter().fold([0.0, 0.0], |acc, p| [acc[0] + p[0], acc[1] + p[1]]);
    // The symmetric path's trace in either case, so that both kinds of GCV evaluation agree.
    [trace.unwrap_or(tr), rss]
}

/// One chunk of [`gamma_sums`] (`divide`: compute Γ first; otherwise it is already there).
#[inline(always)]
fn gamma_chunk(g: &mut [f64], lm: &[f64], power: Option<&[f64]>, s: f64, divide: bool) -> [f64; 2] {
    if divide {
        for (g, l) in g.iter_mut().zip(lm) {
            *g = 1.0 / (1.0 + s * l);
        }
    }
    let tr = sum16(g);
    let rss = power.map_or(0.0, |pw| lane_sum(g, pw, |g, p| p * (g - 1.0) * (g - 1.0)));
    [tr, rss]
}

/// [`gamma_chunk`] compiled for AVX2 (the same operations in the same order, so the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn gamma_chunk_avx2(g: &mut [f64], lm: &[f64], power: Option<&[f64]>, s: f64, divide: bool) -> [f64; 2] {
    gamma_chunk(g, lm, power, s, divide)
}

/// `Γ = 1/(1 + S Λ^m)` of a symmetric n × n `lm` (n a multiple of 4): each 4 × 4 tile on or above
/// the diagonal is divided (the scalar formula's operations, lane by lane) and stored, and the
/// tiles above it also transposed into their mirror tile — half the divisions, the same values.
/// Returns `Σ Γ` summed tile by tile (4 lanes; a tile above the diagonal counts twice).
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn gamma_symmetric_avx2(g: &mut [f64], lm: &[f64], n: usize, s: f64) -> f64 {
    use std::arch::x86_64::*;
    assert!(n.is_multiple_of(4) && g.len() == n * n && lm.len() == n * n);
    let (one, sv) = (_mm256_set1_pd(1.0), _mm256_set1_pd(s));
    let (mut diagonal, mut above) = (_mm256_setzero_pd(), _mm256_setzero_pd());
    for bi in (0..n).step_by(4) {
        for bj in (bi..n).step_by(4) {
            // SAFETY: bi + 3, bj + 3 < n, so every row offset (bi + i)·n + bj … + 3 and the mirror
            // offsets (bj + k)·n + bi … + 3 lie inside the n² elements (asserted above).
            unsafe {
                let row = |i: usize| {
                    let l = _mm256_loadu_pd(lm.as_ptr().add((bi + i) * n + bj));
                    _mm256_div_pd(one, _mm256_add_pd(one, _mm256_mul_pd(sv, l)))
                };
                let r = [row(0), row(1), row(2), row(3)];
                for (i, v) in r.iter().enumerate() {
                    _mm256_storeu_pd(g.as_mut_ptr().add((bi + i) * n + bj), *v);
                }
                let tile = _mm256_add_pd(_mm256_add_pd(r[0], r[1]), _mm256_add_pd(r[2], r[3]));
                if bj == bi {
                    diagonal = _mm256_add_pd(diagonal, tile);
                } else {
                    above = _mm256_add_pd(above, tile);
                }
                if bj != bi {
                    let (t0, t1) = (_mm256_unpacklo_pd(r[0], r[1]), _mm256_unpackhi_pd(r[0], r[1]));
                    let (t2, t3) = (_mm256_unpacklo_pd(r[2], r[3]), _mm256_unpackhi_pd(r[2], r[3]));
                    let cols = [
                        _mm256_permute2f128_pd::<0x20>(t0, t2),
                        _mm256_permute2f128_pd::<0x20>(t1, t3),
                        _mm256_permute2f128_pd::<0x31>(t0, t2),
                        _mm256_permute2f128_pd::<0x31>(t1, t3),
                    ];
                    for (k, c) in cols.iter().enumerate() {
                        _mm256_storeu_pd(g.as_mut_ptr().add((bj + k) * n + bi), *c);
                    }
                }
            }
        }
    }
    let (mut d, mut a) = ([0.0f64; 4], [0.0f64; 4]);
    // SAFETY: 4 writable f64 each.
    unsafe {
        _mm256_storeu_pd(d.as_mut_ptr(), diagonal);
        _mm256_storeu_pd(a.as_mut_ptr(), above);
    }
    let sum = |v: [f64; 4]| (v[0] + v[1]) + (v[2] + v[3]);
    sum(d) + 2.0 * sum(a)
}

/// [`gamma_symmetric_avx2`] in 8 × 8 tiles of 512-bit rows (n a multiple of 8): the same
/// division per element, so the same Γ; the trace is summed tile by tile in 8 lanes (another order
/// than the 4 × 4 tiles, equal to rounding). AVX-512 divides twice as many f64 per cycle as AVX2
/// on Zen 5 (8256 divisions: 1.0 µs against 2.0 µs).
///
/// # Safety
/// The CPU must support AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn gamma_symmetric_avx512(g: &mut [f64], lm: &[f64], n: usize, s: f64) -> f64 {
    use std::arch::x86_64::*;
    assert!(n.is_multiple_of(8) && g.len() == n * n && lm.len() == n * n);
    let (one, sv) = (_mm512_set1_pd(1.0), _mm512_set1_pd(s));
    let (mut diagonal, mut above) = (_mm512_setzero_pd(), _mm512_setzero_pd());
    for bi in (0..n).step_by(8) {
        for bj in (bi..n).step_by(8) {
            // SAFETY: bi + 7, bj + 7 < n, so every row offset (bi + i)·n + bj … + 7 and the mirror
            // offsets (bj + k)·n + bi … + 7 lie inside the n² elements (asserted above).
            unsafe {
                let mut r = [_mm512_setzero_pd(); 8];
                for (i, r) in r.iter_mut().enumerate() {
                    let l = _mm512_loadu_pd(lm.as_ptr().add((bi + i) * n + bj));
                    *r = _mm512_div_pd(one, _mm512_add_pd(one, _mm512_mul_pd(sv, l)));
                    _mm512_storeu_pd(g.as_mut_ptr().add((bi + i) * n + bj), *r);
                }
                let q = |a: usize| _mm512_add_pd(_mm512_add_pd(r[a], r[a + 1]), _mm512_add_pd(r[a + 2], r[a + 3]));
                let tile = _mm512_add_pd(q(0), q(4));
                if bj == bi {
                    diagonal = _mm512_add_pd(diagonal, tile);
                    continue;
                }
                above = _mm512_add_pd(above, tile);
                // 8 × 8 transpose: pairs, then 128-bit blocks, then 256-bit halves.
                let mut t = [_mm512_setzero_pd(); 8];
                for k in 0..4 {
                    t[2 * k] = _mm512_unpacklo_pd(r[2 * k], r[2 * k + 1]);
                    t[2 * k + 1] = _mm512_unpackhi_pd(r[2 * k], r[2 * k + 1]);
                }
                let mut u = [_mm512_setzero_pd(); 8];
                for k in 0..2 {
                    let (a, b) = (4 * k, 4 * k + 2);
                    u[a] = _mm512_shuffle_f64x2::<0x88>(t[a], t[b]);
                    u[a + 1] = _mm512_shuffle_f64x2::<0x88>(t[a + 1], t[b + 1]);
                    u[a + 2] = _mm512_shuffle_f64x2::<0xDD>(t[a], t[b]);
                    u[a + 3] = _mm512_shuffle_f64x2::<0xDD>(t[a + 1], t[b + 1]);
                }
                for k in 0..4 {
                    let lo = _mm512_shuffle_f64x2::<0x88>(u[k], u[k + 4]);
                    let hi = _mm512_shuffle_f64x2::<0xDD>(u[k], u[k + 4]);
                    _mm512_storeu_pd(g.as_mut_ptr().add((bj + k) * n + bi), lo);
                    _mm512_storeu_pd(g.as_mut_ptr().add((bj + k + 4) * n + bi), hi);
                }
            }
        }
    }
    let (mut d, mut a) = ([0.0f64; 8], [0.0f64; 8]);
    // SAFETY: 8 writable f64 each.
    unsafe {
        _mm512_storeu_pd(d.as_mut_ptr(), diagonal);
        _mm512_storeu_pd(a.as_mut_ptr(), above);
    }
    let sum = |v: [f64; 8]| ((v[0] + v[1]) + (v[2] + v[3])) + ((v[4] + v[5]) + (v[6] + v[7]));
    sum(d) + 2.0 * sum(a)
}

/// AVX2 available (cached by the standard library).
#[cfg(target_arch = "x86_64")]
#[inline]
fn avx2() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
}

/// AVX-512F available (cached by the standard library).
#[cfg(target_arch = "x86_64")]
#[inline]
fn avx512() -> bool {
    std::arch::is_x86_feature_detected!("avx512f")
}

/// `z ← rf·ẑ + (1 − rf)·z`; returns `[‖z_old − z‖², ‖z‖², ‖z_old‖²]`, summed in 4 lanes.
pub(crate) fn relax(z: &mut [f64], zhat: &[f64], rf: f64) -> [f64; 3] {
    #[cfg(target_arch = "x86_64")]
    if avx2() {
        // SAFETY: the CPU supports AVX2.
        return unsafe { relax_avx2(z, zhat, rf) };
    }
    relax_body(z, zhat, rf)
}

/// [`relax`] compiled for AVX2 (the same operations in the same order, so the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn relax_avx2(z: &mut [f64], zhat: &[f64], rf: f64) -> [f64; 3] {
    relax_body(z, zhat, rf)
}

#[inline(always)]
fn relax_body(z: &mut [f64], zhat: &[f64], rf: f64) -> [f64; 3] {
    // 16 lanes per sum (four vector chains each, so the additions run at the adders' throughput),
    // combined in a fixed order.
    let mut acc = [[0.0f64; 16]; 3];
    let step = |zold: f64, zhat: f64, acc: &mut [[f64; 16]; 3], l: usize| {
        let znew = rf * zhat + (1.0 - rf) * zold;
        acc[0][l] += (zold - znew) * (zold - znew);
        acc[1][l] += znew * znew;
        acc[2][l] += zold * zold;
        znew
    };
    let body = z.len() / 16 * 16;
    for (z16, h16) in z[..body].chunks_exact_mut(16).zip(zhat[..body].chunks_exact(16)) {
        for l in 0..16 {
            z16[l] = step(z16[l], h16[l], &mut acc, l);
        }
    }
    for i in body..z.len() {
        z[i] = step(z[i], zhat[i], &mut acc, i % 16);
    }
    acc.map(|a| {
        let q = |k: usize| (a[k] + a[k + 4]) + (a[k + 8] + a[k + 12]);
        (q(0) + q(1)) + (q(2) + q(3))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The mirrored Γ of a symmetric square Λ^m gives the bits of the element-by-element formula
    /// and the same power-weighted sum; its trace (summed tile by tile) agrees to rounding.
    #[test]
    fn symmetric_gamma_gives_the_plain_kernels_values() {
        // 8, 16, 128: the AVX-512 8 × 8 tiles where the CPU has them; 4, 12: the AVX2 4 × 4 ones.
        for n in [4usize, 8, 12, 16, 128] {
            let lam: Vec<f64> =
                (0..n).map(|k| 2.0 - 2.0 * (std::f64::consts::PI * k as f64 / n as f64).cos()).collect();
            let lm: Vec<f64> = (0..n * n).map(|p| (lam[p / n] + lam[p % n]).powi(2)).collect();
            let power: Vec<f64> = (0..n * n).map(|p| ((p * 7919) % 1013) as f64 * 0.01).collect();
            for s in [1e-3, 0.37, 18.85, 4.2e4] {
                let (mut g0, mut g1) = (vec![0.0; n * n], vec![-1.0; n * n]);
                let mut partials = Vec::new();
                let a = gamma_sums(&mut g0, &lm, Some(&power), s, None, &mut partials);
                let b = gamma_sums(&mut g1, &lm, Some(&power), s, Some(n), &mut partials);
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&g0), bits(&g1), "n = {n}, s = {s}");
                // The trace is summed tile by tile on the symmetric path (another order).
                assert!((a[0] - b[0]).abs() <= 1e-13 * a[0], "trace, n = {n}, s = {s}: {} vs {}", a[0], b[0]);
                assert_eq!(a[1].to_bits(), b[1].to_bits(), "power sum, n = {n}, s = {s}");
                let c = gamma_sums(&mut g1, &lm, None, s, Some(n), &mut partials);
                assert_eq!(c[0].to_bits(), b[0].to_bits(), "trace without power, n = {n}, s = {s}");
                assert!(g0.iter().zip(&lm).all(|(g, l)| g.to_bits() == (1.0 / (1.0 + s * l)).to_bits()));
            }
        }
    }
}
