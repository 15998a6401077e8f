//! A pixel's slow-time sums R0 = Σ|x_k|² and R_L = Σ x_k·conj(x_{k+L}) (eq. 19's autocorrelation
//! at lag L) in a fixed summation order ([`LagAcc`]'s lanes): frame by frame for frame-major
//! packets (a row at a time, the lanes as arrays over the row) and four frames at a time over
//! contiguous frames for pixel-major ones (portable, AVX-512 and AVX2 kernels). Every path gives
//! the same bits.

use num_complex::Complex;
use sonoflow_beamform::C32;

type C64 = Complex<f64>;

/// (s0 + s1) + (s2 + s3) of four partial sums.
#[inline]
fn combine<T: Copy + std::ops::Add<Output = T>>(q: [T; 4]) -> T {
    (q[0] + q[1]) + (q[2] + q[3])
}

/// Partial sums of one pixel's slow-time autocorrelation, in 8 lanes: lane `2·(k mod 4) + c`
/// holds frame k's real (c = 0) or imaginary (c = 1) part of re², ar·br / ai·bi and ar·bi /
/// ai·br (a = x_k, b = x_{k+L}). Both packet layouts accumulate the same lanes in the same
/// frame order, so they give the same bits; with complex samples interleaved in memory the
/// lanes are vector lanes.
#[derive(Clone, Copy, Default)]
pub(crate) struct LagAcc {
    p0: [f64; 8],
    p1: [f64; 8],
    q1: [f64; 8],
}

impl LagAcc {
    /// Frame k's power into lane `k mod 4` (the reference order of the tests).
    #[cfg(test)]
    fn add_power(&mut self, lane: usize, x: &C32) {
        let (r, i) = (f64::from(x.re), f64::from(x.im));
        self.p0[2 * lane] += r * r;
        self.p0[2 * lane + 1] += i * i;
    }

    /// Frame k's lag products into lane `k mod 4` (the reference order of the tests).
    #[cfg(test)]
    fn add_lag(&mut self, lane: usize, a: &C32, b: &C32) {
        let (ar, ai, br, bi) = (f64::from(a.re), f64::from(a.im), f64::from(b.re), f64::from(b.im));
        self.p1[2 * lane] += ar * br;
        self.p1[2 * lane + 1] += ai * bi;
        self.q1[2 * lane] += ar * bi;
        self.q1[2 * lane + 1] += ai * br;
    }

    /// R0 = Σ|x_k|², R_L = Σ x_k·conj(x_{k+L}): per lane (re² + im², (ar·br + ai·bi) + i(ai·br −
    /// ar·bi)), then (s0 + s1) + (s2 + s3).
    #[inline(always)]
    pub(crate) fn finish(&self) -> (f64, C64) {
        let (p0, p1, q1) = (&self.p0, &self.p1, &self.q1);
        let r0 = |j: usize| p0[2 * j] + p0[2 * j + 1];
        let r1 = |j: usize| C64::new(p1[2 * j] + p1[2 * j + 1], q1[2 * j + 1] - q1[2 * j]);
        (combine([r0(0), r0(1), r0(2), r0(3)]), combine([r1(0), r1(1), r1(2), r1(3)]))
    }
}

/// [`LagAcc`] of one pixel's contiguous frames, four frames (8 interleaved f32 parts, one
/// vector) at a time; the last incomplete group is zero-padded, which adds nothing (x + 0 = x
/// for every partial sum, none of which can be −0 since they start at +0).
#[inline(always)]
fn lag_sums(s: &[C32], lag: usize) -> (f64, C64) {
    // SAFETY: `Complex<f32>` is `#[repr(C)] { re, im }`, so n samples are 2n contiguous f32.
    let f: &[f32] = unsafe { std::slice::from_raw_parts(s.as_ptr().cast::<f32>(), 2 * s.len()) };
    let n = s.len();
    let (mut p0, mut p1, mut q1) = ([0.0f64; 8], [0.0f64; 8], [0.0f64; 8]);
    let widen = |c: &[f32]| -> [f64; 8] { std::array::from_fn(|l| f64::from(c[l])) };
    let full = n - n % 4;
    let mut pad = [0.0f32; 8];
    let tail = |pad: &mut [f32; 8], src: &[f32]| {
        *pad = [0.0; 8];
        pad[..src.len()].copy_from_slice(src);
        *pad
    };
    let last = (full < n).then(|| tail(&mut pad, &f[2 * full..]));
    for c in f[..2 * full].chunks_exact(8).chain(last.as_ref().map(|p| &p[..])) {
        let v = widen(c);
        for l in 0..8 {
            p0[l] += v[l] * v[l];
        }
    }
    let m = n - lag;
    let mfull = m - m % 4;
    let mut pad_b = [0.0f32; 8];
    let last_a = (mfull < m).then(|| tail(&mut pad, &f[2 * mfull..2 * m]));
    let last_b = (mfull < m).then(|| tail(&mut pad_b, &f[2 * (mfull + lag)..2 * n]));
    let a_chunks = f[..2 * mfull].chunks_exact(8).chain(last_a.as_ref().map(|p| &p[..]));
    let b_chunks = f[2 * lag..2 * (lag + mfull)].chunks_exact(8).chain(last_b.as_ref().map(|p| &p[..]));
    for (ca, cb) in a_chunks.zip(b_chunks) {
        let (x, y) = (widen(ca), widen(cb));
        for l in 0..8 {
            p1[l] += x[l] * y[l];
            q1[l] += x[l] * y[l ^ 1];
        }
    }
    LagAcc { p0, p1, q1 }.finish()
}

/// [`lag_sums`] with AVX-512 vectors: the same lanes, products and additions (multiply, then
/// add: no FMA), so the same bits.
///
/// # Safety
/// The CPU must support AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512vl")]
unsafe fn lag_sums_avx512(s: &[C32], lag: usize) -> (f64, C64) {
    use std::arch::x86_64::{
        __m512d, _mm256_maskz_loadu_ps, _mm512_add_pd, _mm512_cvtps_pd, _mm512_mul_pd, _mm512_permute_pd,
        _mm512_setzero_pd, _mm512_storeu_pd,
    };
    // SAFETY: `Complex<f32>` is `#[repr(C)] { re, im }`, so n samples are 2n contiguous f32.
    let f: &[f32] = unsafe { std::slice::from_raw_parts(s.as_ptr().cast::<f32>(), 2 * s.len()) };
    let n = s.len();
    // The raw loads below stay inside `f` only for lag ≤ n (the estimator checks frames > lag).
    assert!(lag <= n, "lag_sums_avx512: lag {lag} > {n} frames");
    // The `k` f32 from `at` (k ≤ 8) widened to f64, zeros after them; a masked load reads
    // only those k (the zero padding of `lag_sums`, without a store and a reload).
    let widen = |at: usize, k: usize| -> __m512d {
        debug_assert!(k <= 8 && at + k <= f.len());
        let mask = ((1u32 << k) - 1) as u8;
        // SAFETY: the mask limits the load to f[at..at + k], inside the slice.
        unsafe { _mm512_cvtps_pd(_mm256_maskz_loadu_ps(mask, f.as_ptr().add(at))) }
    };
    let (mut p0, mut p1, mut q1) = (_mm512_setzero_pd(), _mm512_setzero_pd(), _mm512_setzero_pd());
    for k0 in (0..n).step_by(4) {
        let v = widen(2 * k0, 2 * (n - k0).min(4));
        p0 = _mm512_add_pd(p0, _mm512_mul_pd(v, v));
    }
    let m = n - lag;
    for k0 in (0..m).step_by(4) {
        let k = 2 * (m - k0).min(4);
        let (x, y) = (widen(2 * k0, k), widen(2 * (k0 + lag), k));
        p1 = _mm512_add_pd(p1, _mm512_mul_pd(x, y));
        q1 = _mm512_add_pd(q1, _mm512_mul_pd(x, _mm512_permute_pd::<0x55>(y)));
    }
    let mut acc = LagAcc::default();
    // SAFETY: each destination holds 8 f64.
    unsafe {
        _mm512_storeu_pd(acc.p0.as_mut_ptr(), p0);
        _mm512_storeu_pd(acc.p1.as_mut_ptr(), p1);
        _mm512_storeu_pd(acc.q1.as_mut_ptr(), q1);
    }
    acc.finish()
}

/// [`lag_sums`] with AVX2 vectors: the 8 lanes as two halves of four f64, the same products and
/// additions (multiply, then add: no FMA), so the same bits. Full four-sample groups are plain
/// loads; a tail is a masked load (zeros after it, as `lag_sums`' padding; masked loads are slow
/// on some CPUs, so only there). The lag products' full groups also feed R0 (one load of x for
/// both); every lane still sums its frames in ascending order.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn lag_sums_avx2(s: &[C32], lag: usize) -> (f64, C64) {
    use std::arch::x86_64::{
        __m256d, _mm256_add_pd, _mm256_castps256_ps128, _mm256_cmpgt_epi32, _mm256_cvtps_pd, _mm256_extractf128_ps,
        _mm256_loadu_ps, _mm256_maskload_ps, _mm256_mul_pd, _mm256_permute_pd, _mm256_set1_epi32, _mm256_setr_epi32,
        _mm256_setzero_pd, _mm256_storeu_pd,
    };
    // SAFETY: `Complex<f32>` is `#[repr(C)] { re, im }`, so n samples are 2n contiguous f32.
    let f: &[f32] = unsafe { std::slice::from_raw_parts(s.as_ptr().cast::<f32>(), 2 * s.len()) };
    let n = s.len();
    // The raw loads below stay inside `f` only for lag ≤ n (the estimator checks frames > lag).
    assert!(lag <= n, "lag_sums_avx2: lag {lag} > {n} frames");
    let lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    // The `k` f32 from `at` (k ≤ 8) widened to f64 in two halves, zeros after them.
    let widen = |at: usize, k: usize| -> [__m256d; 2] {
        debug_assert!(k <= 8 && at + k <= f.len());
        // SAFETY: a full load reads f[at..at + 8]; otherwise the mask limits it to f[at..at + k].
        let v = unsafe {
            if k == 8 {
                _mm256_loadu_ps(f.as_ptr().add(at))
            } else {
                _mm256_maskload_ps(f.as_ptr().add(at), _mm256_cmpgt_epi32(_mm256_set1_epi32(k as i32), lane))
            }
        };
        [_mm256_cvtps_pd(_mm256_castps256_ps128(v)), _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(v))]
    };
    let z = _mm256_setzero_pd();
    let (mut p0, mut p1, mut q1) = ([z; 2], [z; 2], [z; 2]);
    let m = n - lag;
    // The full groups of the lag products also feed R0 (x is the same sample group), then the
    // rest of R0 and the lag products' tail: every lane still sums in ascending frame order.
    let mfull = m - m % 4;
    for k0 in (0..mfull).step_by(4) {
        let (x, y) = (widen(2 * k0, 8), widen(2 * (k0 + lag), 8));
        for h in 0..2 {
            p0[h] = _mm256_add_pd(p0[h], _mm256_mul_pd(x[h], x[h]));
            p1[h] = _mm256_add_pd(p1[h], _mm256_mul_pd(x[h], y[h]));
            q1[h] = _mm256_add_pd(q1[h], _mm256_mul_pd(x[h], _mm256_permute_pd::<0b0101>(y[h])));
        }
    }
    for k0 in (mfull..n).step_by(4) {
        let v = widen(2 * k0, 2 * (n - k0).min(4));
        for h in 0..2 {
            p0[h] = _mm256_add_pd(p0[h], _mm256_mul_pd(v[h], v[h]));
        }
    }
    if mfull < m {
        let k = 2 * (m - mfull);
        let (x, y) = (widen(2 * mfull, k), widen(2 * (mfull + lag), k));
        for h in 0..2 {
            p1[h] = _mm256_add_pd(p1[h], _mm256_mul_pd(x[h], y[h]));
            q1[h] = _mm256_add_pd(q1[h], _mm256_mul_pd(x[h], _mm256_permute_pd::<0b0101>(y[h])));
        }
    }
    let mut acc = LagAcc::default();
    // SAFETY: each destination holds 8 f64, written as two halves of 4.
    unsafe {
        for (dst, v) in [(&mut acc.p0, p0), (&mut acc.p1, p1), (&mut acc.q1, q1)] {
            _mm256_storeu_pd(dst.as_mut_ptr(), v[0]);
            _mm256_storeu_pd(dst.as_mut_ptr().add(4), v[1]);
        }
    }
    acc.finish()
}

/// Bytes ahead of the pixel being summed that [`prefetch_ahead`] asks the cache for.
#[cfg(target_arch = "x86_64")]
const PREFETCH_BYTES: usize = 2048;

/// Software prefetch of the samples [`PREFETCH_BYTES`] past those of the pixel starting at sample
/// `at` (`len` samples): a packet is read once, straight from memory, and the hardware prefetcher
/// alone left the first load of each pixel waiting. A hint only: no effect on the results, and
/// addresses past the end of `data` are never dereferenced (prefetches do not fault).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn prefetch_ahead(data: &[C32], at: usize, len: usize) {
    prefetch_ahead_by(data, at, len, PREFETCH_BYTES);
}

/// Prefetches the cache lines of `data[at..at + len]` shifted by `ahead` bytes (a hint: addresses
/// past the end of `data` are never dereferenced).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn prefetch_ahead_by(data: &[C32], at: usize, len: usize, ahead: usize) {
    use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
    let bytes = std::mem::size_of::<C32>();
    let base = data.as_ptr().cast::<i8>().wrapping_add(at * bytes + ahead);
    for off in (0..len * bytes).step_by(64) {
        // SAFETY: a prefetch is a hint; it does not read memory architecturally nor fault.
        unsafe { _mm_prefetch::<_MM_HINT_T0>(base.wrapping_add(off)) };
    }
}

/// [`lag_sums`] of each pixel of a pixel-major row (`n_frames` contiguous frames per pixel),
/// with the widest vector instructions the CPU has (the same operations, so the same bits).
pub(crate) fn lag_sums_row(data: &[C32], n_frames: usize, lag: usize, r0: &mut [f64], r1: &mut [C64]) {
    #[inline(always)]
    fn row(data: &[C32], n_frames: usize, lag: usize, r0: &mut [f64], r1: &mut [C64]) {
        for ((s, a), b) in data.chunks_exact(n_frames).zip(r0).zip(r1) {
            (*a, *b) = lag_sums(s, lag);
        }
    }
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx512f,avx512vl")]
        unsafe fn avx512(data: &[C32], n_frames: usize, lag: usize, r0: &mut [f64], r1: &mut [C64]) {
            for (p, ((s, a), b)) in data.chunks_exact(n_frames).zip(r0).zip(r1).enumerate() {
                prefetch_ahead(data, p * n_frames, n_frames);
                // SAFETY: the CPU has AVX-512F and VL (this function's target features).
                (*a, *b) = unsafe { lag_sums_avx512(s, lag) };
            }
        }
        #[target_feature(enable = "avx2")]
        unsafe fn avx2(data: &[C32], n_frames: usize, lag: usize, r0: &mut [f64], r1: &mut [C64]) {
            for (p, ((s, a), b)) in data.chunks_exact(n_frames).zip(r0).zip(r1).enumerate() {
                prefetch_ahead(data, p * n_frames, n_frames);
                // SAFETY: the CPU has AVX2 (this function's target feature).
                (*a, *b) = unsafe { lag_sums_avx2(s, lag) };
            }
        }
        if std::arch::is_x86_feature_detected!("avx512f") && std::arch::is_x86_feature_detected!("avx512vl") {
            // SAFETY: the CPU has AVX-512F and VL (checked above).
            return unsafe { avx512(data, n_frames, lag, r0, r1) };
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked above).
            return unsafe { avx2(data, n_frames, lag, r0, r1) };
        }
    }
    row(data, n_frames, lag, r0, r1)
}

/// [`LagAcc`] of every pixel of one row of frame-major frames (`frames[k][start..start + r0.len()]`),
/// with the lanes laid out as arrays over the row so that the frame-by-frame updates are
/// element-wise and vectorise: for lane l = k mod 4, `p0_l[j] += x_j²`, `p1_l[j] += a_j b_j`,
/// `q1_l[j] += a_j b_(j xor 1)` over the row's interleaved f32 parts j (a = frame k, b = frame
/// k + lag). Each pixel's lanes receive the same products in the same frame order as
/// [`LagAcc::add_power`] / [`LagAcc::add_lag`], so the same bits. `acc` is scratch (resized).
pub(crate) fn lag_sums_frames_row(
    frames: &[&[C32]],
    start: usize,
    lag: usize,
    (r0, r1): (&mut [f64], &mut [C64]),
    acc: &mut Vec<f64>,
) {
    #[inline(always)]
    fn body(frames: &[&[C32]], start: usize, lag: usize, (r0, r1): (&mut [f64], &mut [C64]), acc: &mut Vec<f64>) {
        let nx = r0.len();
        let w = 2 * nx;
        acc.clear();
        acc.resize(12 * w, 0.0);
        let parts = |f: &[C32]| -> &[f32] {
            let row = &f[start..start + nx];
            // SAFETY: `Complex<f32>` is `#[repr(C)] { re, im }`, so nx samples are 2nx contiguous f32.
            unsafe { std::slice::from_raw_parts(row.as_ptr().cast::<f32>(), w) }
        };
        // Lane l's arrays: p0 at 3lw, p1 at (3l + 1)w, q1 at (3l + 2)w.
        for (k, f) in frames.iter().enumerate() {
            // The next row of this frame (the next task's, on one thread) on its way from memory.
            #[cfg(target_arch = "x86_64")]
            prefetch_ahead_by(f, start + nx, nx, 0);
            let p0 = &mut acc[3 * (k & 3) * w..][..w];
            for (p, x) in p0.iter_mut().zip(parts(f)) {
                let x = f64::from(*x);
                *p += x * x;
            }
        }
        for k in 0..frames.len() - lag {
            let (a, b) = (parts(frames[k]), parts(frames[k + lag]));
            let (p1, q1) = acc[(3 * (k & 3) + 1) * w..][..2 * w].split_at_mut(w);
            for (((p1, q1), a), b) in
                p1.chunks_exact_mut(2).zip(q1.chunks_exact_mut(2)).zip(a.chunks_exact(2)).zip(b.chunks_exact(2))
            {
                let (ar, ai, br, bi) = (f64::from(a[0]), f64::from(a[1]), f64::from(b[0]), f64::from(b[1]));
                p1[0] += ar * br;
                p1[1] += ai * bi;
                q1[0] += ar * bi;
                q1[1] += ai * br;
            }
        }
        for (ix, (r0, r1)) in r0.iter_mut().zip(r1.iter_mut()).enumerate() {
            let mut one = LagAcc::default();
            for l in 0..4 {
                for c in 0..2 {
                    let j = 2 * ix + c;
                    one.p0[2 * l + c] = acc[3 * l * w + j];
                    one.p1[2 * l + c] = acc[(3 * l + 1) * w + j];
                    one.q1[2 * l + c] = acc[(3 * l + 2) * w + j];
                }
            }
            (*r0, *r1) = one.finish();
        }
    }
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx512f,avx512vl")]
        unsafe fn avx512(f: &[&[C32]], start: usize, lag: usize, r: (&mut [f64], &mut [C64]), acc: &mut Vec<f64>) {
            body(f, start, lag, r, acc);
        }
        #[target_feature(enable = "avx2")]
        unsafe fn avx2(f: &[&[C32]], start: usize, lag: usize, r: (&mut [f64], &mut [C64]), acc: &mut Vec<f64>) {
            body(f, start, lag, r, acc);
        }
        if std::arch::is_x86_feature_detected!("avx512f") && std::arch::is_x86_feature_detected!("avx512vl") {
            // SAFETY: the CPU has AVX-512F and VL (checked above).
            return unsafe { avx512(frames, start, lag, (r0, r1), acc) };
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked above).
            return unsafe { avx2(frames, start, lag, (r0, r1), acc) };
        }
    }
    body(frames, start, lag, (r0, r1), acc)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every way of summing a pixel's frames gives the same bits: frame by frame into
    /// [`LagAcc`] (the frame-major path), the portable four-frame groups and, where the CPU has
    /// it, the AVX-512 and AVX2 kernels; lengths with and without a tail, several lags.
    #[test]
    fn lag_sum_kernels_agree_bit_for_bit() {
        for (n, lag) in [(2usize, 1usize), (5, 1), (8, 1), (13, 2), (32, 1), (33, 4), (7, 6), (12, 4), (9, 8)] {
            let s: Vec<C32> =
                (0..n).map(|k| C32::new((k as f32 * 0.7).sin() * 3.0, (k as f32 * 1.3).cos() - 0.2)).collect();
            let mut acc = LagAcc::default();
            for (k, x) in s.iter().enumerate() {
                acc.add_power(k & 3, x);
            }
            for k in 0..n - lag {
                acc.add_lag(k & 3, &s[k], &s[k + lag]);
            }
            let want = acc.finish();
            let bits = |r: (f64, C64)| (r.0.to_bits(), r.1.re.to_bits(), r.1.im.to_bits());
            assert_eq!(bits(lag_sums(&s, lag)), bits(want), "portable, n {n} lag {lag}");
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx512f") && std::arch::is_x86_feature_detected!("avx512vl") {
                // SAFETY: the CPU has AVX-512F and VL (checked above).
                assert_eq!(bits(unsafe { lag_sums_avx512(&s, lag) }), bits(want), "AVX-512, n {n} lag {lag}");
            }
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU has AVX2 (checked above).
                assert_eq!(bits(unsafe { lag_sums_avx2(&s, lag) }), bits(want), "AVX2, n {n} lag {lag}");
            }
            let r0: f64 = s.iter().map(|x| f64::from(x.norm_sqr())).sum();
            assert!((want.0 - r0).abs() < 1e-5 * r0, "R0 against a plain sum");
        }
    }

    /// The frame-major row kernel gives, pixel by pixel, the bits of [`LagAcc`] fed frame by
    /// frame (row offsets, row lengths with and without a vector tail, several lags, and a second
    /// call reusing the scratch).
    #[test]
    fn frame_major_rows_match_lag_acc_bit_for_bit() {
        let mut scratch = Vec::new();
        for (nf, lag, nx) in [(2usize, 1usize, 1usize), (5, 1, 7), (32, 1, 13), (33, 4, 16), (9, 8, 3)] {
            let rows = 3;
            let frames: Vec<Vec<C32>> = (0..nf)
                .map(|k| {
                    (0..rows * nx)
                        .map(|p| {
                            C32::new(((k * 31 + p) as f32 * 0.7).sin() * 3.0, ((k + 7 * p) as f32 * 1.3).cos() - 0.2)
                        })
                        .collect()
                })
                .collect();
            let refs: Vec<&[C32]> = frames.iter().map(|f| &f[..]).collect();
            for row in 0..rows {
                let (mut r0, mut r1) = (vec![f64::NAN; nx], vec![C64::new(f64::NAN, 0.0); nx]);
                lag_sums_frames_row(&refs, row * nx, lag, (&mut r0, &mut r1), &mut scratch);
                for ix in 0..nx {
                    let p = row * nx + ix;
                    let mut acc = LagAcc::default();
                    for (k, f) in frames.iter().enumerate() {
                        acc.add_power(k & 3, &f[p]);
                    }
                    for k in 0..nf - lag {
                        acc.add_lag(k & 3, &frames[k][p], &frames[k + lag][p]);
                    }
                    let (w0, w1) = acc.finish();
                    let what = format!("nf {nf} lag {lag} nx {nx} row {row} ix {ix}");
                    assert_eq!(r0[ix].to_bits(), w0.to_bits(), "R0, {what}");
                    assert_eq!(
                        (r1[ix].re.to_bits(), r1[ix].im.to_bits()),
                        (w1.re.to_bits(), w1.im.to_bits()),
                        "R1, {what}"
                    );
                }
            }
        }
    }
}
