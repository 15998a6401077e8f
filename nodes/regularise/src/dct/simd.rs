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

/// Stores `(re[l], im[l])`, l = 0…3, as four consecutive complex numbers at `p`.
///
/// # Safety
/// The CPU must support AVX2; `p` must point to 8 writable f64.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn store_complex(p: *mut f64, re: __m256d, im: __m256d) {
    let a = _mm256_unpacklo_pd(re, im); // re0 im0 re2 im2
    let b = _mm256_unpackhi_pd(re, im); // re1 im1 re3 im3
                                        // SAFETY: the caller guarantees 8 writable f64 at p.
    unsafe {
        _mm256_storeu_pd(p, _mm256_permute2f128_pd::<0x20>(a, b));
        _mm256_storeu_pd(p.add(4), _mm256_permute2f128_pd::<0x31>(a, b));
    }
}

/// Body of `Dct1d::pack_inverse` over the pairs (k, n − k) in blocks of four: for block j0 and
/// `r0 = m − 4 − j0`, `lo[j] = b (U − iR)`, `hi[m − 1 − j] = conj(b) (U + iR)` with
/// `U = (xal gal, xbl gbl)[j]`, `R = (xah gah, xbh gbh)[m − 1 − j]` (no `g` without `WEIGHTED`).
/// Every slice has length m = `lo.len()`; returns the number of pairs done (a multiple of 4).
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
    let body = m / 4 * 4;
    let mut j0 = 0;
    while j0 < body {
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
            store_complex(lo.as_mut_ptr().add(j0).cast::<f64>(), lre, lim);
            store_complex(hi.as_mut_ptr().add(r0).cast::<f64>(), rev(hre), rev(him));
        }
        j0 += 4;
    }
    body
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
            let o = _mm256_permute2f128_pd::<0x01>(o, o);
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
