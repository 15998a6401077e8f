//! The fused two-axis path of the DCT (the smoother's case): the first pass pairs the lines so
//! that each pair's FFT output holds what the second pass's FFT input needs, which is written
//! directly, with no transposed real intermediate (see the module docs of [`super`]).

#[cfg(target_arch = "x86_64")]
use super::simd;
use super::{Dct1d, LineScratch, RowSource, BLOCK, C64};

impl Dct1d {
    /// First pass of a two-axis inverse, fused with the second pass's preparation. `self` inverts
    /// along the rows of `src` (`next.len()` rows of length `self.len()`, times `weight`, laid out as
    /// `src`); row k is paired with row n1 − k (row 0 with row n1/2, or with zeros for odd n1) in
    /// one complex FFT, so that each pair's output holds, for every pair of sample rows (2q, 2q + 1),
    /// both `U_k` and `U_(n1−k)` of `next`'s inverse: `V_k = b_k (U_k − i U_(n1−k))` and
    /// `V_(n1−k) = conj(b_k) (U_k + i U_(n1−k))` (`next.b`), written to `out[q·n1 + k]` — the input
    /// of `next`'s FFT ([`Self::finish_pair_rows`]), with no transposed real intermediate and no
    /// second preparation pass. `out` holds ⌈n0/2⌉ rows of n1.
    pub(super) fn inverse_rows_into_next(
        &self,
        src: &[f64],
        weight: Option<&[f64]>,
        next: &Dct1d,
        out: &mut [C64],
        s: &mut LineScratch,
    ) {
        let (n0, n1) = (self.n, next.n);
        let m = (n1 - 1) / 2;
        let LineScratch { c1, c2, fft, zeros, lanes, .. } = s;
        let zeros = &zeros[..n0];
        // Pack the pair (ka, kb) (kb = None: zeros) into complex line p of c1.
        let pack = |c1: &mut [C64], p: usize, ka: usize, kb: Option<usize>| {
            let v = &mut c1[p * n0..(p + 1) * n0];
            let xa = &src[ka * n0..][..n0];
            let xb = kb.map_or(zeros, |k| &src[k * n0..][..n0]);
            match weight {
                None => self.pack_inverse::<false>(v, xa, xb, xa, xb),
                Some(w) => {
                    let ga = &w[ka * n0..][..n0];
                    let gb = kb.map_or(zeros, |k| &w[k * n0..][..n0]);
                    self.pack_inverse::<true>(v, xa, xb, ga, gb);
                }
            }
        };
        // Row 0 with row n1/2 (even n1) or zeros.
        pack(c1, 0, 0, (n1 & 1 == 0).then_some(n1 / 2));
        self.inv.process(&mut c1[..n0], &mut c2[..n0], fft, lanes);
        next.fuse_ends(&c2[..n0], n0, out);
        // Rows (k, n1 − k), k = 1 … m, four pairs per FFT call.
        let mut k0 = 1;
        while k0 <= m {
            let mut np = (m + 1 - k0).min(BLOCK / 2);
            #[cfg(target_arch = "x86_64")]
            if np < BLOCK / 2 && m >= BLOCK / 2 && simd::available() {
                // The last pairs as a full block ending at m (its first pairs are done again, to
                // the same values), so that the vector kernel covers them.
                (k0, np) = (m + 1 - BLOCK / 2, BLOCK / 2);
            }
            for p in 0..np {
                pack(c1, p, k0 + p, Some(n1 - k0 - p));
            }
            self.inv.process(&mut c1[..np * n0], &mut c2[..np * n0], fft, lanes);
            #[allow(unused_mut)]
            let mut q_done = 0;
            #[cfg(target_arch = "x86_64")]
            if np == BLOCK / 2 && simd::available() {
                let [re, im, nim] = &next.b_dup;
                // SAFETY: AVX2 is available.
                unsafe { simd::fuse_pairs(&c2[..np * n0], n0, k0, [re, im, nim], out, n1) };
                q_done = n0 / 2;
            }
            next.fuse_pairs(&c2[..np * n0], np, n0, k0, out, q_done);
            k0 += np;
        }
    }

    /// [`Self::inverse_rows_into_next`] for the pair (0, n1/2) (or (0, zeros)): `V_0 = b_0 U_0`,
    /// and for even n1 `V_(n1/2) = b (1 − i) U_(n1/2)` (real factor), `self` being the second axis.
    fn fuse_ends(&self, c: &[C64], n0: usize, out: &mut [C64]) {
        let n1 = self.n;
        let b0 = self.b[0].re;
        let bh = self.b[n1 / 2];
        let fac = bh.re + bh.im;
        for q in 0..n0.div_ceil(2) {
            let (a, b) = (c[q], if 2 * q + 1 < n0 { c[n0 - 1 - q] } else { C64::new(0.0, 0.0) });
            out[q * n1] = C64::new(a.re * b0, b.re * b0);
            if n1 & 1 == 0 {
                out[q * n1 + n1 / 2] = C64::new(a.im * fac, b.im * fac);
            }
        }
    }

    /// [`Self::inverse_rows_into_next`] for `pairs` pairs (k0 + p, n1 − k0 − p) from sample-row pair
    /// `q_start` on (`self` the second axis; scalar twin of `simd::fuse_pairs`). With `A` the pair's
    /// FFT output at bin q (samples 2q of rows k, n1 − k) and `B` at bin n0 − 1 − q (samples 2q + 1;
    /// zero for the last row of an odd n0): `U_k = (A.re, B.re)`, `U_(n1−k) = (A.im, B.im)`.
    fn fuse_pairs(&self, c: &[C64], pairs: usize, n0: usize, k0: usize, out: &mut [C64], q_start: usize) {
        let n1 = self.n;
        for p in 0..pairs {
            let k = k0 + p;
            let (br, bi, nbi) = (self.b_re[k], self.b_im[k], -self.b_im[k]);
            let c = &c[p * n0..(p + 1) * n0];
            for q in q_start..n0.div_ceil(2) {
                let (a, b) = (c[q], if 2 * q + 1 < n0 { c[n0 - 1 - q] } else { C64::new(0.0, 0.0) });
                let (s1, s2) = (a.re + b.im, b.re - a.im);
                let (d1, d2) = (a.re - b.im, a.im + b.re);
                out[q * n1 + k] = C64::new(br * s1 - bi * s2, br * s2 + bi * s1);
                out[q * n1 + n1 - k] = C64::new(br * d1 - nbi * d2, br * d2 + nbi * d1);
            }
        }
    }

    /// Second pass of a two-axis inverse: the FFT of the rows of `c` (from
    /// [`Self::inverse_rows_into_next`], ⌈n0/2⌉ rows of `self.len()`; used as scratch), whose row q
    /// holds sample rows 2q and 2q + 1 of the result; writes them to `keep` (n0 rows) and/or
    /// returns `Σ w (y − x)²` against `rss = (y, w)` (n0 rows each), summed pair by pair.
    pub(super) fn finish_pair_rows(
        &self,
        c: &mut [C64],
        n0: usize,
        rss: Option<(&[f64], &[f64])>,
        mut keep: Option<&mut [f64]>,
        s: &mut LineScratch,
    ) -> f64 {
        let n = self.n;
        let rows = n0.div_ceil(2);
        let mut total = 0.0;
        for q0 in (0..rows).step_by(BLOCK / 2) {
            let nq = (rows - q0).min(BLOCK / 2);
            let LineScratch { c2, fft, sink, block, lanes, .. } = s;
            self.inv.process(&mut c[q0 * n..(q0 + nq) * n], &mut c2[..nq * n], fft, lanes);
            for (i, v) in c2.chunks_exact(n).take(nq).enumerate() {
                let ra = 2 * (q0 + i);
                let both = ra + 1 < n0;
                let rb = if both { ra + 1 } else { ra };
                // The pair's two sample rows: into `keep`, or into scratch when only the RSS is asked.
                let (a, b): (&mut [f64], &mut [f64]) = match keep.as_deref_mut() {
                    Some(out) if both => {
                        let (a, b) = out[ra * n..].split_at_mut(n);
                        (a, &mut b[..n])
                    }
                    Some(out) => (&mut out[ra * n..][..n], &mut sink[..n]),
                    None => {
                        let (a, b) = block.split_at_mut(n);
                        (&mut a[..n], &mut b[..n])
                    }
                };
                match rss {
                    Some((y, w)) => {
                        let (ya, yb, wa, wb) =
                            (&y[ra * n..][..n], &y[rb * n..][..n], &w[ra * n..][..n], &w[rb * n..][..n]);
                        total += self.unpack_rss_pair(v, a, b, [ya, yb], [wa, wb], both);
                    }
                    None => self.unpack_inverse_rows(v, a, b),
                }
            }
        }
        total
    }

    /// First pass of a two-axis forward transform, fused with the second pass's preparation.
    /// `self` transforms the `next.len()` rows of `src` (length `self.len()`), paired (2p, 2p + 1);
    /// from each pair's coefficients `X_k`, `X_(n1−k)` the second pass's Makhoul-reordered input
    /// of the line pair (k, n1 − k) follows: `w_p = (X_k[2p], X_(n1−k)[2p])`,
    /// `w_(n0−1−p) = (X_k[2p+1], X_(n1−k)[2p+1])` (row 0: the pair (0, n1/2), or (0, zeros) for odd
    /// n1), written to `out[P·n0 + …]` for line pair P = k ([`Self::finish_forward_pairs`]). `out`
    /// holds ⌊(n1 − 1)/2⌋ + 1 rows of n0.
    #[inline(always)]
    pub(super) fn forward_rows_into_next(&self, src: RowSource, next: &Dct1d, out: &mut [C64], s: &mut LineScratch) {
        let n0 = next.n;
        let full = n0 / 2;
        let mut p0 = 0;
        while p0 < full {
            let mut np = (full - p0).min(BLOCK / 2);
            #[cfg(target_arch = "x86_64")]
            if np < BLOCK / 2 && full >= BLOCK / 2 && simd::available() {
                // The last pairs as a full block (its first pairs again, to the same values).
                (p0, np) = (full - BLOCK / 2, BLOCK / 2);
            }
            self.forward_pair_block(src, n0, (p0, np, false), out, s);
            p0 += np;
        }
        if n0 & 1 == 1 {
            // The last row alone (paired with zeros): only w_p.
            self.forward_pair_block(src, n0, (full, 1, true), out, s);
        }
    }

    /// One FFT call of [`Self::forward_rows_into_next`]: row pairs p0 … p0 + np (`half`: the last
    /// row of an odd n0, alone).
    #[inline(always)]
    fn forward_pair_block(
        &self,
        src: RowSource,
        n0: usize,
        (p0, np, half): (usize, usize, bool),
        out: &mut [C64],
        s: &mut LineScratch,
    ) {
        let n1 = self.n;
        let m1 = (n1 - 1) / 2;
        let LineScratch { c1, c2, fft, zeros, block, lanes, .. } = s;
        let zeros = &zeros[..n1];
        for i in 0..np {
            let p = p0 + i;
            match src {
                RowSource::Data(src) => {
                    let xa = &src[2 * p * n1..][..n1];
                    let xb = if half { zeros } else { &src[(2 * p + 1) * n1..][..n1] };
                    self.pack_forward(&mut c1[i * n1..(i + 1) * n1], xa, xb);
                }
                RowSource::Pseudo { y, z, w } => {
                    let (xa, xb) = block[..2 * n1].split_at_mut(n1);
                    let rows = if half { 1 } else { 2 };
                    for (r, x) in [&mut *xa, &mut *xb].into_iter().take(rows).enumerate() {
                        let o = (2 * p + r) * n1;
                        for (((x, y), z), w) in x.iter_mut().zip(&y[o..o + n1]).zip(&z[o..o + n1]).zip(&w[o..o + n1]) {
                            *x = w * (y - z) + z;
                        }
                    }
                    let xb: &[f64] = if half { zeros } else { xb };
                    self.pack_forward(&mut c1[i * n1..(i + 1) * n1], xa, xb);
                }
            }
        }
        self.fwd.process(&mut c1[..np * n1], &mut c2[..np * n1], fft, lanes);
        let c = &c2[..np * n1];
        // Line pair 0: X_0 and X_(n1/2) = 2 Re(a) V (zeros for odd n1).
        let (a0, ah) = (2.0 * self.a[0].re, 2.0 * self.a[n1 / 2].re);
        for i in 0..np {
            let p = p0 + i;
            let x0 = c[i * n1] * a0;
            let xh = if n1 & 1 == 0 { c[i * n1 + n1 / 2] * ah } else { C64::new(0.0, 0.0) };
            out[p] = C64::new(x0.re, xh.re);
            if !half {
                out[n0 - 1 - p] = C64::new(x0.im, xh.im);
            }
        }
        #[allow(unused_mut)]
        let mut k_done = 0;
        #[cfg(target_arch = "x86_64")]
        if np == BLOCK / 2 && !half && simd::available() {
            // SAFETY: AVX2 is available.
            unsafe { simd::fuse_forward_pairs(c, n1, (&self.a_re, &self.a_im), out, (p0, n0)) };
            k_done = m1;
        }
        for k in k_done + 1..=m1 {
            let (al, ar) = (self.a_re[k], self.a_im[k]);
            for i in 0..np {
                let p = p0 + i;
                let (v, w) = (c[i * n1 + k], c[i * n1 + n1 - k]);
                // P = a V_k, Q = conj(a) V_(n1−k); X_k = P + Q, X_(n1−k) = i (P − Q).
                let (pr, pi) = (al * v.re - ar * v.im, al * v.im + ar * v.re);
                let (qr, qi) = (al * w.re + ar * w.im, al * w.im - ar * w.re);
                let (sum, d) = (C64::new(pr + qr, pi + qi), C64::new(pr - qr, pi - qi));
                out[k * n0 + p] = C64::new(sum.re, -d.im);
                if !half {
                    out[k * n0 + n0 - 1 - p] = C64::new(sum.im, d.re);
                }
            }
        }
    }

    /// Second pass of a two-axis forward transform: the FFT of the line pairs of `w` (from
    /// [`Self::forward_rows_into_next`]; used as scratch) and their coefficients into rows
    /// (0, n1/2) and (k, n1 − k) of `out` (n1 rows of `self.len()`).
    pub(super) fn finish_forward_pairs(&self, w: &mut [C64], n1: usize, out: &mut [f64], s: &mut LineScratch) {
        let n = self.n;
        let rows = (n1 - 1) / 2 + 1;
        for r0 in (0..rows).step_by(BLOCK / 2) {
            let nr = (rows - r0).min(BLOCK / 2);
            let LineScratch { c2, fft, sink, lanes, .. } = s;
            self.fwd.process(&mut w[r0 * n..(r0 + nr) * n], &mut c2[..nr * n], fft, lanes);
            for (i, v) in c2.chunks_exact(n).take(nr).enumerate() {
                let k = r0 + i;
                let kb = if k == 0 { (n1 & 1 == 0).then_some(n1 / 2) } else { Some(n1 - k) };
                match kb {
                    Some(kb) => {
                        let (lo, hi) = out.split_at_mut(kb * n);
                        self.unpack_forward_rows(v, &mut lo[k * n..(k + 1) * n], &mut hi[..n]);
                    }
                    None => self.unpack_forward_rows(v, &mut out[k * n..(k + 1) * n], &mut sink[..n]),
                }
            }
        }
    }
}
