//! AVX2 versions of the hottest per-line kernels of the DCT. Each runs exactly the IEEE operations of
//! its scalar twin in [`super`] (same operands, same order, no FMA), lane by lane, so results are
//! bit-identical with and without AVX2.

use std::arch::x86_64::*;

use super::C64;

#[cfg(test)]
thread_local! {
    /// Test switch: run the scalar twins on this thread even where AVX2 is available.
    pub(super) static FORCE_SCALAR: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// AVX2 available (cached by the standard library).
#[inline]
pub(super) fn available() -> bool {
    #[cfg(test)]
    if FORCE_SCALAR.with(std::cell::Cell::get) {
        return false;
    }
    std::arch::is_x86_feature_detected!("avx2")
}

/// Reverses the four lanes.
///
/// # Safety
/// The CPU must support AVX2.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn rev(v: __m256d) -> __m256d {
    _mm256_permute4x64_pd::<0x1B>(v)
}

/// Starts of the blocks of four that cover `0..m` (m ≥ 4): 0, 4, …, and a last partial block done
/// as the block ending at m, overlapping the one before it (its overlapped elements get the same
/// values again).
fn overlapping_blocks(m: usize) -> impl Iterator<Item = usize> {
    (0..m.div_ceil(4)).map(move |b| (4 * b).min(m - 4))
}

/// `vperm2f128` (halves of `a` and `b` chosen by `IMM`) in inline assembly: LLVM would otherwise
/// turn some of these moves into `vpermpd` (two micro-ops and a lower throughput on Zen 2) or
/// combine them with neighbouring shuffles into more `vpermpd`s. Moves only.
///
/// # Safety
/// The CPU must support AVX2.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn perm2f128<const IMM: i32>(a: __m256d, b: __m256d) -> __m256d {
    let r: __m256d;
    // SAFETY: a register-only AVX instruction (the caller guarantees AVX2).
    unsafe {
        std::arch::asm!(
            "vperm2f128 {r}, {a}, {b}, {imm}",
            a = in(ymm_reg) a, b = in(ymm_reg) b, r = lateout(ymm_reg) r, imm = const IMM,
            options(pure, nomem, nostack, preserves_flags),
        );
    }
    r
}

/// Swaps the two 128-bit halves (`vperm2f128`, see [`perm2f128`]).
///
/// # Safety
/// The CPU must support AVX2.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn swap_halves(v: __m256d) -> __m256d {
    // SAFETY: the caller guarantees AVX2.
    unsafe { perm2f128::<0x01>(v, v) }
}

/// Stores `(re[l], im[l])`, l = 0…3, as four consecutive complex numbers at `p`; `REVERSED`
/// stores them in reverse order, `(re[3], im[3]), …, (re[0], im[0])` (moves only).
///
/// # Safety
/// The CPU must support AVX2; `p` must point to 8 writable f64.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn store_complex<const REVERSED: bool>(p: *mut f64, re: __m256d, im: __m256d) {
    // a = (re0 im0 re2 im2), b = (re1 im1 re3 im3).
    let (a, b) = (_mm256_unpacklo_pd(re, im), _mm256_unpackhi_pd(re, im));
    // SAFETY: the caller guarantees AVX2 and 8 writable f64 at p.
    unsafe {
        let (first, second) = if REVERSED {
            (perm2f128::<0x31>(b, a), perm2f128::<0x20>(b, a))
        } else {
            (perm2f128::<0x20>(a, b), perm2f128::<0x31>(a, b))
        };
        _mm256_storeu_pd(p, first);
        _mm256_storeu_pd(p.add(4), second);
    }
}

/// Body of `Dct1d::pack_inverse` over the pairs (k, n − k) in blocks of four: for block j0 and
/// `r0 = m − 4 − j0`, `lo[j] = b (U − iR)`, `hi[m − 1 − j] = conj(b) (U + iR)` with
/// `U = (xal gal, xbl gbl)[j]`, `R = (xah gah, xbh gbh)[m − 1 − j]` (no `g` without `WEIGHTED`).
/// Every slice has length m = `lo.len()`; returns the number of pairs done (m, or 0 for m < 4).
///
/// # Safety
/// The CPU must support AVX2.
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
pub(super) unsafe fn pack_inverse<const WEIGHTED: bool>(
    lo: &mut [C64],
    hi: &mut [C64],
    b: [&[f64]; 2],
    x: [&[f64]; 4],
    g: [&[f64]; 4],
) -> usize {
    let m = lo.len();
    assert!(hi.len() == m && b.iter().chain(&x).all(|s| s.len() == m));
    assert!(!WEIGHTED || g.iter().all(|s| s.len() == m));
    if m < 4 {
        return 0;
    }
    for j0 in overlapping_blocks(m) {
        let r0 = m - 4 - j0;
        // SAFETY: j0 + 4 ≤ m and r0 + 4 ≤ m, so every access is in bounds (lengths asserted above);
        // lo and hi hold m complex numbers (2m f64, repr(C)).
        unsafe {
            let ld = |s: &[f64], o: usize| _mm256_loadu_pd(s.as_ptr().add(o));
            let (mut ur, mut ui, mut rr, mut ri) = (ld(x[0], j0), ld(x[1], j0), rev(ld(x[2], r0)), rev(ld(x[3], r0)));
            if WEIGHTED {
                ur = _mm256_mul_pd(ur, ld(g[0], j0));
                ui = _mm256_mul_pd(ui, ld(g[1], j0));
                rr = _mm256_mul_pd(rr, rev(ld(g[2], r0)));
                ri = _mm256_mul_pd(ri, rev(ld(g[3], r0)));
            }
            let (br, bi) = (ld(b[0], j0), ld(b[1], j0));
            let (s1, s2) = (_mm256_add_pd(ur, ri), _mm256_sub_pd(ui, rr));
            let (d1, d2) = (_mm256_sub_pd(ur, ri), _mm256_add_pd(ui, rr));
            let lre = _mm256_sub_pd(_mm256_mul_pd(br, s1), _mm256_mul_pd(bi, s2));
            let lim = _mm256_add_pd(_mm256_mul_pd(br, s2), _mm256_mul_pd(bi, s1));
            let hre = _mm256_add_pd(_mm256_mul_pd(br, d1), _mm256_mul_pd(bi, d2));
            let him = _mm256_sub_pd(_mm256_mul_pd(br, d2), _mm256_mul_pd(bi, d1));
            store_complex::<false>(lo.as_mut_ptr().add(j0).cast::<f64>(), lre, lim);
            store_complex::<true>(hi.as_mut_ptr().add(r0).cast::<f64>(), hre, him);
        }
    }
    m
}

/// Body of `Dct1d::rss_pair` (both lines): over blocks of two q, accumulates
/// `w (y − x) (y − x)` (as `(w·d)·d`) into the lanes `[a, b, a', b']` of the even (`x_2q = v_q`)
/// and odd (`x_2q+1 = v_(n−1−q)`) positions. `lo = v[..h]`, `hi = v[n − h..]`; `y`, `w` hold lines
/// a and b (length ≥ 2h). Returns the q done (a multiple of 2) and the two accumulators.
///
/// # Safety
/// The CPU must support AVX2.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn rss_pair(lo: &[C64], hi: &[C64], y: [&[f64]; 2], w: [&[f64]; 2]) -> (usize, [[f64; 4]; 2]) {
    let h = hi.len();
    assert!(lo.len() >= h && y.iter().chain(&w).all(|s| s.len() >= 2 * h));
    let body = h / 2 * 2;
    let mut q0 = 0;
    let (mut acc_e, mut acc_o) = (_mm256_setzero_pd(), _mm256_setzero_pd());
    while q0 < body {
        // SAFETY: q0 + 2 ≤ h ≤ lo.len(), h − 2 − q0 ≥ 0, 2q0 + 4 ≤ 2h (lengths asserted above).
        unsafe {
            let e = _mm256_loadu_pd(lo.as_ptr().add(q0).cast::<f64>());
            let o = _mm256_loadu_pd(hi.as_ptr().add(h - 2 - q0).cast::<f64>());
            let o = swap_halves(o);
            let ld = |s: &[f64]| _mm256_loadu_pd(s.as_ptr().add(2 * q0));
            let (ya, yb, wa, wb) = (ld(y[0]), ld(y[1]), ld(w[0]), ld(w[1]));
            let de = _mm256_sub_pd(_mm256_unpacklo_pd(ya, yb), e);
            let dod = _mm256_sub_pd(_mm256_unpackhi_pd(ya, yb), o);
            let we = _mm256_unpacklo_pd(wa, wb);
            let wo = _mm256_unpackhi_pd(wa, wb);
            acc_e = _mm256_add_pd(acc_e, _mm256_mul_pd(_mm256_mul_pd(we, de), de));
            acc_o = _mm256_add_pd(acc_o, _mm256_mul_pd(_mm256_mul_pd(wo, dod), dod));
        }
        q0 += 2;
    }
    let (mut e, mut o) = ([0.0; 4], [0.0; 4]);
    // SAFETY: 4 writable f64 each.
    unsafe {
        _mm256_storeu_pd(e.as_mut_ptr(), acc_e);
        _mm256_storeu_pd(o.as_mut_ptr(), acc_o);
    }
    (body, [e, o])
}

/// Body of `Dct1d::unpack_rss_pair`: over blocks of two q, the samples `x[2q] = v_q`,
/// `x[2q + 1] = v_(n−1−q)` of lines a (real parts) and b (imaginary parts) are written to `x` and
/// `w (y − x) (y − x)` (as `(w·d)·d`) is added to the lanes (sample index mod 4) of each line's
/// sum. `lo = v[..h]`, `hi = v[n − h..]`; `x`, `y`, `w` hold lines a and b (length ≥ 2h). Returns
/// the q done (a multiple of 2) and the two lines' lanes.
///
/// # Safety
/// The CPU must support AVX2.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn unpack_rss(
    lo: &[C64],
    hi: &[C64],
    x: [&mut [f64]; 2],
    y: [&[f64]; 2],
    w: [&[f64]; 2],
) -> (usize, [[f64; 4]; 2]) {
    let h = hi.len();
    let [xa, xb] = x;
    assert!(lo.len() >= h && xa.len() >= 2 * h && xb.len() >= 2 * h);
    assert!(y.iter().chain(&w).all(|s| s.len() >= 2 * h));
    let body = h / 2 * 2;
    let mut q0 = 0;
    let (mut acc_a, mut acc_b) = (_mm256_setzero_pd(), _mm256_setzero_pd());
    while q0 < body {
        // SAFETY: q0 + 2 ≤ h ≤ lo.len(), h − 2 − q0 ≥ 0, 2q0 + 4 ≤ 2h (lengths asserted above).
        unsafe {
            let e = _mm256_loadu_pd(lo.as_ptr().add(q0).cast::<f64>());
            let o = swap_halves(_mm256_loadu_pd(hi.as_ptr().add(h - 2 - q0).cast::<f64>()));
            let (a, b) = (_mm256_unpacklo_pd(e, o), _mm256_unpackhi_pd(e, o));
            _mm256_storeu_pd(xa.as_mut_ptr().add(2 * q0), a);
            _mm256_storeu_pd(xb.as_mut_ptr().add(2 * q0), b);
            let ld = |s: &[f64]| _mm256_loadu_pd(s.as_ptr().add(2 * q0));
            let (da, db) = (_mm256_sub_pd(ld(y[0]), a), _mm256_sub_pd(ld(y[1]), b));
            acc_a = _mm256_add_pd(acc_a, _mm256_mul_pd(_mm256_mul_pd(ld(w[0]), da), da));
            acc_b = _mm256_add_pd(acc_b, _mm256_mul_pd(_mm256_mul_pd(ld(w[1]), db), db));
        }
        q0 += 2;
    }
    let (mut a, mut b) = ([0.0; 4], [0.0; 4]);
    // SAFETY: 4 writable f64 each.
    unsafe {
        _mm256_storeu_pd(a.as_mut_ptr(), acc_a);
        _mm256_storeu_pd(b.as_mut_ptr(), acc_b);
    }
    (body, [a, b])
}

/// Four consecutive complex numbers at `p` as (real parts, imaginary parts), lanes in order.
///
/// # Safety
/// The CPU must support AVX2; `p` must point to 8 readable f64.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn load_complex(p: *const f64) -> (__m256d, __m256d) {
    // SAFETY: the caller guarantees AVX2 and 8 readable f64 at p.
    unsafe {
        let (a, b) = (_mm256_loadu_pd(p), _mm256_loadu_pd(p.add(4)));
        // (c0, c2) and (c1, c3); unpacking them gives the parts in order.
        let (t0, t1) = (perm2f128::<0x20>(a, b), perm2f128::<0x31>(a, b));
        (_mm256_unpacklo_pd(t0, t1), _mm256_unpackhi_pd(t0, t1))
    }
}

/// Body of `Dct1d::pack_forward` in blocks of two q: `v[q] = (xa[2q], xb[2q])`,
/// `v[n − 1 − q] = (xa[2q + 1], xb[2q + 1])` (moves only). `v` has length n ≤ `xa.len()`,
/// `xb.len()`; returns the q done (a multiple of 2, at most n/2).
///
/// # Safety
/// The CPU must support AVX2.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn pack_forward(v: &mut [C64], xa: &[f64], xb: &[f64]) -> usize {
    let n = v.len();
    assert!(xa.len() >= n && xb.len() >= n);
    let body = n / 2 / 2 * 2;
    let mut q0 = 0;
    while q0 < body {
        // SAFETY: 2q0 + 4 ≤ 2·body ≤ n; q0 + 2 ≤ n/2 and n − 2 − q0 + 2 ≤ n (lengths asserted above).
        unsafe {
            let a = _mm256_loadu_pd(xa.as_ptr().add(2 * q0));
            let b = _mm256_loadu_pd(xb.as_ptr().add(2 * q0));
            let even = _mm256_unpacklo_pd(a, b); // a0 b0 a2 b2: v[q0], v[q0 + 1]
            let odd = _mm256_unpackhi_pd(a, b); // a1 b1 a3 b3: v[n − 1 − q0], v[n − 2 − q0]
            _mm256_storeu_pd(v.as_mut_ptr().add(q0).cast::<f64>(), even);
            _mm256_storeu_pd(v.as_mut_ptr().add(n - 2 - q0).cast::<f64>(), swap_halves(odd));
        }
        q0 += 2;
    }
    body
}

/// Body of `Dct1d::unpack_inverse_rows` in blocks of two q: `xa[2q] = lo[q].re`,
/// `xb[2q] = lo[q].im`, `xa[2q + 1] = hi[h − 1 − q].re`, `xb[2q + 1] = hi[h − 1 − q].im` with
/// h = `hi.len()` ≤ `lo.len()` (moves only). Returns the q done (a multiple of 2).
///
/// # Safety
/// The CPU must support AVX2.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn unpack_inverse_rows(lo: &[C64], hi: &[C64], xa: &mut [f64], xb: &mut [f64]) -> usize {
    let h = hi.len();
    assert!(lo.len() >= h && xa.len() >= 2 * h && xb.len() >= 2 * h);
    let body = h / 2 * 2;
    let mut q0 = 0;
    while q0 < body {
        // SAFETY: q0 + 2 ≤ h ≤ lo.len(), h − 2 − q0 ≥ 0, 2q0 + 4 ≤ 2h (lengths asserted above).
        unsafe {
            let e = _mm256_loadu_pd(lo.as_ptr().add(q0).cast::<f64>());
            let o = _mm256_loadu_pd(hi.as_ptr().add(h - 2 - q0).cast::<f64>());
            let o = swap_halves(o);
            _mm256_storeu_pd(xa.as_mut_ptr().add(2 * q0), _mm256_unpacklo_pd(e, o));
            _mm256_storeu_pd(xb.as_mut_ptr().add(2 * q0), _mm256_unpackhi_pd(e, o));
        }
        q0 += 2;
    }
    body
}

/// Body of `Dct1d::unpack_forward_rows` over the pairs (k, n − k) in blocks of four: for block
/// j0 and `r0 = m − 4 − j0`, with `P = a V_k`, `Q = conj(a) V_(n−k)` (`V_k = vl[j]`,
/// `V_(n−k) = vh[m − 1 − j]`, `a = (ar[j], ai[j])`): `yl = (P + Q)` (lines a, b as real and
/// imaginary parts) and `yh[m − 1 − j] = (−(P.im − Q.im), P.re − Q.re)`. The same IEEE operations
/// in the same order as the scalar loop. Every slice has length m = `vl.len()`; returns the pairs
/// done (m, or 0 for m < 4).
///
/// # Safety
/// The CPU must support AVX2.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn unpack_forward(
    vl: &[C64],
    vh: &[C64],
    a: [&[f64]; 2],
    yl: [&mut [f64]; 2],
    yh: [&mut [f64]; 2],
) -> usize {
    let m = vl.len();
    assert!(vh.len() == m && a.iter().all(|s| s.len() == m));
    assert!(yl.iter().chain(&yh).all(|s| s.len() == m));
    let [yal, ybl] = yl;
    let [yah, ybh] = yh;
    if m < 4 {
        return 0;
    }
    let sign = _mm256_set1_pd(-0.0);
    for j0 in overlapping_blocks(m) {
        let r0 = m - 4 - j0;
        // SAFETY: j0 + 4 ≤ m and r0 + 4 ≤ m, so every access is in bounds (lengths asserted above);
        // vl and vh hold m complex numbers (2m f64, repr(C)).
        unsafe {
            let (p_re, p_im) = load_complex(vl.as_ptr().add(j0).cast::<f64>());
            let (q_re, q_im) = load_complex(vh.as_ptr().add(r0).cast::<f64>());
            let (q_re, q_im) = (rev(q_re), rev(q_im));
            let (al, ar) = (_mm256_loadu_pd(a[0].as_ptr().add(j0)), _mm256_loadu_pd(a[1].as_ptr().add(j0)));
            let pr = _mm256_sub_pd(_mm256_mul_pd(al, p_re), _mm256_mul_pd(ar, p_im));
            let pi = _mm256_add_pd(_mm256_mul_pd(al, p_im), _mm256_mul_pd(ar, p_re));
            let qr = _mm256_add_pd(_mm256_mul_pd(al, q_re), _mm256_mul_pd(ar, q_im));
            let qi = _mm256_sub_pd(_mm256_mul_pd(al, q_im), _mm256_mul_pd(ar, q_re));
            _mm256_storeu_pd(yal.as_mut_ptr().add(j0), _mm256_add_pd(pr, qr));
            _mm256_storeu_pd(ybl.as_mut_ptr().add(j0), _mm256_add_pd(pi, qi));
            let neg = _mm256_xor_pd(_mm256_sub_pd(pi, qi), sign);
            _mm256_storeu_pd(yah.as_mut_ptr().add(r0), rev(neg));
            _mm256_storeu_pd(ybh.as_mut_ptr().add(r0), rev(_mm256_sub_pd(pr, qr)));
        }
    }
    m
}

/// Writes the `lines` rows of `block` (row-major, length n each) as columns `c0 … c0 + lines` of
/// `dst` (row stride `stride`): `dst[k·stride + c0 + l] = block[l·n + k]`, in 4 × 4 tiles
/// (moves only). Returns the rows of `dst` done (a multiple of 4; the caller finishes the rest)
/// and the lines covered (a multiple of 4).
///
/// # Safety
/// The CPU must support AVX2.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn transpose_block(
    block: &[f64],
    lines: usize,
    n: usize,
    dst: &mut [f64],
    c0: usize,
    stride: usize,
) -> (usize, usize) {
    assert!(block.len() >= lines * n);
    let (kb, lb) = (n / 4 * 4, lines / 4 * 4);
    if kb > 0 && lb > 0 {
        assert!(c0 + lb <= stride && (kb - 1) * stride + c0 + lb <= dst.len());
    }
    // Line-tiles inner: a row of dst (one cache line for 8 lines) is finished before the next.
    let mut k0 = 0;
    while k0 < kb {
        for l0 in (0..lb).step_by(4) {
            // SAFETY: rows l0 … l0 + 3 < lines and columns k0 … k0 + 3 < n of block; rows
            // k0 … k0 + 3 < kb and columns c0 + l0 … + 3 < c0 + lb ≤ stride of dst (asserted above).
            unsafe {
                let r = |i: usize| _mm256_loadu_pd(block.as_ptr().add((l0 + i) * n + k0));
                let (r0, r1, r2, r3) = (r(0), r(1), r(2), r(3));
                let (t0, t1) = (_mm256_unpacklo_pd(r0, r1), _mm256_unpackhi_pd(r0, r1));
                let (t2, t3) = (_mm256_unpacklo_pd(r2, r3), _mm256_unpackhi_pd(r2, r3));
                let d = dst.as_mut_ptr().add(k0 * stride + c0 + l0);
                _mm256_storeu_pd(d, perm2f128::<0x20>(t0, t2));
                _mm256_storeu_pd(d.add(stride), perm2f128::<0x20>(t1, t3));
                _mm256_storeu_pd(d.add(2 * stride), perm2f128::<0x31>(t0, t2));
                _mm256_storeu_pd(d.add(3 * stride), perm2f128::<0x31>(t1, t3));
            }
        }
        k0 += 4;
    }
    (kb, lb)
}

/// Complex element `k` of pairs 0, 1 and of pairs 2, 3 of a block (`c`: 4 pairs × n).
///
/// # Safety
/// The CPU must support AVX2; `3n + k < c.len()`.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn pairs_at(c: &[C64], n: usize, k: usize) -> (__m256d, __m256d) {
    // SAFETY: the caller guarantees 3n + k < c.len(); each read is one complex (2 f64).
    unsafe {
        let p = |i: usize| c.as_ptr().add(i * n + k).cast::<f64>();
        (_mm256_loadu2_m128d(p(1), p(0)), _mm256_loadu2_m128d(p(3), p(2)))
    }
}

/// A full block (4 pairs, 8 lines) of `Dct1d::unpack_forward_rows` written transposed, the pairs
/// as lanes: row k of `dst` (stride `stride`) receives `X_k` of lines `c0 … c0 + 8` (line a, b of
/// pair p as the real and imaginary part of `P + Q`), row n − k receives `(−(P − Q).im, (P − Q).re)`,
/// with `P = a_k V_k`, `Q = conj(a_k) V_(n−k)`; rows 0 and n/2 (even n) are `V · 2 Re a`. The
/// same IEEE operations as the scalar formulas (`vaddsubpd` computes `x − y` in even and `x + y`
/// in odd lanes; `−ar·im` is exact).
///
/// # Safety
/// The CPU must support AVX2.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn unpack_forward_columns(
    c: &[C64],
    n: usize,
    (a_re, a_im): (&[f64], &[f64]),
    dst: &mut [f64],
    (c0, stride): (usize, usize),
) {
    assert!(c.len() >= 4 * n && a_re.len() >= n && a_im.len() >= n && n >= 1);
    assert!(c0 + 8 <= stride && (n - 1) * stride + c0 + 8 <= dst.len());
    let sign_even = _mm256_set_pd(0.0, -0.0, 0.0, -0.0);
    // SAFETY (all blocks below): k < n, so pairs_at reads inside c (4n complex) and every row
    // k·stride + c0 … + 8 lies inside dst (asserted above).
    let put = |dst: &mut [f64], k: usize, lo: __m256d, hi: __m256d| unsafe {
        let d = dst.as_mut_ptr().add(k * stride + c0);
        _mm256_storeu_pd(d, lo);
        _mm256_storeu_pd(d.add(4), hi);
    };
    let ends = |dst: &mut [f64], k: usize| unsafe {
        let f = _mm256_set1_pd(2.0 * a_re[k]);
        let (v01, v23) = pairs_at(c, n, k);
        put(dst, k, _mm256_mul_pd(v01, f), _mm256_mul_pd(v23, f));
    };
    ends(dst, 0);
    if n & 1 == 0 {
        ends(dst, n / 2);
    }
    for k in 1..n.div_ceil(2) {
        unsafe {
            let (al, ar) = (_mm256_set1_pd(a_re[k]), _mm256_set1_pd(a_im[k]));
            let nar = _mm256_set1_pd(-a_im[k]);
            let (v01, v23) = pairs_at(c, n, k);
            let (w01, w23) = pairs_at(c, n, n - k);
            let swap = |v: __m256d| _mm256_permute_pd::<0b0101>(v);
            // P = (al re − ar im, al im + ar re); Q = (al re + ar im, al im − ar re).
            let p = |v: __m256d| _mm256_addsub_pd(_mm256_mul_pd(al, v), _mm256_mul_pd(ar, swap(v)));
            let q = |w: __m256d| _mm256_addsub_pd(_mm256_mul_pd(al, w), _mm256_mul_pd(nar, swap(w)));
            let (p01, p23, q01, q23) = (p(v01), p(v23), q(w01), q(w23));
            put(dst, k, _mm256_add_pd(p01, q01), _mm256_add_pd(p23, q23));
            let mirror = |d: __m256d| _mm256_xor_pd(swap(d), sign_even);
            put(dst, n - k, mirror(_mm256_sub_pd(p01, q01)), mirror(_mm256_sub_pd(p23, q23)));
        }
    }
}

/// A full block (4 pairs) of `Dct1d::unpack_inverse_rows` written transposed (moves only): row
/// 2q of `dst` receives `V_q` of the 4 pairs (lines a, b as real, imaginary parts), row 2q + 1
/// receives `V_(n−1−q)`, and for odd n row n − 1 receives `V_(n/2)`.
///
/// # Safety
/// The CPU must support AVX2.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn unpack_inverse_columns(c: &[C64], n: usize, dst: &mut [f64], (c0, stride): (usize, usize)) {
    assert!(c.len() >= 4 * n && n >= 1);
    assert!(c0 + 8 <= stride && (n - 1) * stride + c0 + 8 <= dst.len());
    // SAFETY (both uses): j < n and k < n (reads inside c, writes inside dst, asserted above).
    let put = |dst: &mut [f64], j: usize, k: usize| unsafe {
        let (v01, v23) = pairs_at(c, n, k);
        let d = dst.as_mut_ptr().add(j * stride + c0);
        _mm256_storeu_pd(d, v01);
        _mm256_storeu_pd(d.add(4), v23);
    };
    for q in 0..n / 2 {
        put(dst, 2 * q, q);
        put(dst, 2 * q + 1, n - 1 - q);
    }
    if n & 1 == 1 {
        put(dst, n - 1, n / 2);
    }
}

/// Body of `Dct1d::fuse_pairs` for four pairs (k0 + p, n1 − k0 − p) as lanes, sample-row pairs
/// q < n0/2: with `A` the pairs' FFT output at bin q, `B` at bin n0 − 1 − q and `B'` = B with real
/// and imaginary parts swapped, `A + B'`, `A − B'` and `B' − A` give `s1 = A.re + B.im`,
/// `s2 = B.re − A.im`, `d1 = A.re − B.im`, `d2 = A.im + B.re`; `V_k = (br s1 − bi s2, br s2 + bi s1)`
/// and `V_(n1−k) = (br d1 − (−bi) d2, br d2 + (−bi) d1)` by `vaddsubpd` — the scalar twin's
/// operations. `b = [re, im, −im]` per complex lane (length 2·n1).
///
/// # Safety
/// The CPU must support AVX2.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn fuse_pairs(c: &[C64], n0: usize, k0: usize, b: [&[f64]; 3], out: &mut [C64], n1: usize) {
    assert!(c.len() >= 4 * n0 && k0 >= 1 && k0 + 3 <= (n1 - 1) / 2);
    assert!(b.iter().all(|s| s.len() >= 2 * n1) && out.len() >= n0 / 2 * n1);
    // SAFETY: 2(k0 + 2) + 4 ≤ 2·n1 (asserted above).
    let ld = |s: &[f64], k: usize| unsafe { _mm256_loadu_pd(s.as_ptr().add(2 * k)) };
    let lanes = [(ld(b[0], k0), ld(b[1], k0), ld(b[2], k0)), (ld(b[0], k0 + 2), ld(b[1], k0 + 2), ld(b[2], k0 + 2))];
    let swap = |v: __m256d| _mm256_permute_pd::<0b0101>(v);
    for q in 0..n0 / 2 {
        // SAFETY: q, n0 − 1 − q < n0 (pairs_at reads inside c); row q of out has n1 complex and
        // k0 + 3 < n1 − k0 − 3, so the stores at k0 … k0 + 3 and n1 − k0 − 3 … n1 − k0 are inside it.
        unsafe {
            let (a01, a23) = pairs_at(c, n0, q);
            let (b01, b23) = pairs_at(c, n0, n0 - 1 - q);
            let row = out.as_mut_ptr().add(q * n1).cast::<f64>();
            for (i, (a, bb)) in [(a01, b01), (a23, b23)].into_iter().enumerate() {
                let (re, im, nim) = lanes[i];
                let sb = swap(bb);
                let (p, m, nn) = (_mm256_add_pd(a, sb), _mm256_sub_pd(a, sb), _mm256_sub_pd(sb, a));
                let sv = _mm256_blend_pd::<0b1010>(p, nn);
                let dv = _mm256_blend_pd::<0b1010>(m, p);
                let vk = _mm256_addsub_pd(_mm256_mul_pd(re, sv), _mm256_mul_pd(im, swap(sv)));
                let vnk = _mm256_addsub_pd(_mm256_mul_pd(re, dv), _mm256_mul_pd(nim, swap(dv)));
                let k = k0 + 2 * i;
                _mm256_storeu_pd(row.add(2 * k), vk);
                _mm256_storeu_pd(row.add(2 * (n1 - k - 1)), swap_halves(vnk));
            }
        }
    }
}

/// Body of `Dct1d::forward_pair_block` for four row pairs p0 … p0 + 3 as lanes and k = 1 … m1:
/// `P = a V_k`, `Q = conj(a) V_(n1−k)` (as `unpack_forward_columns`), `S = P + Q`, `D = P − Q`;
/// `w_p = (S.re, −D.im)` at `out[k·n0 + p]`, `w_(n0−1−p) = (S.im, D.re)` at `out[k·n0 + n0 − 1 − p]`.
///
/// # Safety
/// The CPU must support AVX2.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn fuse_forward_pairs(
    c: &[C64],
    n1: usize,
    (a_re, a_im): (&[f64], &[f64]),
    out: &mut [C64],
    (p0, n0): (usize, usize),
) {
    let m1 = (n1 - 1) / 2;
    assert!(c.len() >= 4 * n1 && a_re.len() >= n1 && a_im.len() >= n1);
    assert!(p0 + 4 <= n0 / 2 && out.len() >= (m1 + 1) * n0);
    let sign = _mm256_set1_pd(-0.0);
    let swap = |v: __m256d| _mm256_permute_pd::<0b0101>(v);
    for k in 1..=m1 {
        // SAFETY: k, n1 − k < n1 (pairs_at reads inside c); row k of out has n0 complex, and
        // p0 + 3 < n0/2 ≤ n0 − 4 − p0, so the stores at p0 … p0 + 3 and n0 − 4 − p0 … n0 − 1 − p0
        // are inside it (asserted above).
        unsafe {
            let (al, ar, nar) = (_mm256_set1_pd(a_re[k]), _mm256_set1_pd(a_im[k]), _mm256_set1_pd(-a_im[k]));
            let (v01, v23) = pairs_at(c, n1, k);
            let (w01, w23) = pairs_at(c, n1, n1 - k);
            let p = |v: __m256d| _mm256_addsub_pd(_mm256_mul_pd(al, v), _mm256_mul_pd(ar, swap(v)));
            let q = |w: __m256d| _mm256_addsub_pd(_mm256_mul_pd(al, w), _mm256_mul_pd(nar, swap(w)));
            let row = out.as_mut_ptr().add(k * n0).cast::<f64>();
            for (i, (v, w)) in [(v01, w01), (v23, w23)].into_iter().enumerate() {
                let (pv, qw) = (p(v), q(w));
                let (s, d) = (_mm256_add_pd(pv, qw), _mm256_sub_pd(pv, qw));
                let wp = _mm256_shuffle_pd::<0b1010>(s, _mm256_xor_pd(d, sign));
                let wq = _mm256_shuffle_pd::<0b0101>(s, d);
                let pp = p0 + 2 * i;
                _mm256_storeu_pd(row.add(2 * pp), wp);
                _mm256_storeu_pd(row.add(2 * (n0 - 2 - pp)), swap_halves(wq));
            }
        }
    }
}
