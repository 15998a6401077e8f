//! Orthonormal DCT-II and its inverse (DCT-III) in one and N dimensions, computed with an FFT.
//!
//! One line of length `n` uses Makhoul's even/odd reordering (J. Makhoul 1980, "A fast cosine
//! transform in one and two dimensions", IEEE Trans. ASSP 28:27-34): `v = [x0, x2, x4, …, x5, x3, x1]`,
//! `V = FFT(v)`, `X_k = Re(e^{-iπk/2n} V_k)`, O(n log n) for every length, not only powers of two
//! (`rustfft`). Both transforms are real-linear, so two real lines travel as the real and imaginary
//! parts of one complex line through one complex FFT of length n, with
//! `X_k = (e^{-iπk/2n} V_k + e^{iπk/2n} V_(n−k)) / 2` separating them again; lines are transformed in
//! blocks of [`BLOCK`] (one batched FFT call). Scaling is orthonormal (MATLAB `dct`,
//! `scipy.fft.dct(norm="ortho")`): `X_0 = sqrt(1/n) Σ x_j`,
//! `X_k = sqrt(2/n) Σ_j x_j cos(πk(2j+1)/2n)`, so the inverse is the transpose.
//!
//! The N-D transform applies the 1-D transform along every non-singleton axis. Lines along the
//! last (contiguous) axis are transformed and written transposed, which rotates the axes; after the
//! forward transform the coefficients are therefore stored in the *spectral layout*
//! `(a1, a2, …, a(K-1), a0)` of the K non-singleton axes `a0 … a(K-1)` (see [`DctN::spectral_axes`]).
//! The inverse transform takes that layout and returns the spatial (row-major) one. Element-wise
//! work in the DCT domain is layout-agnostic; [`DctN::spectral_indices`] maps each coefficient to
//! its per-axis frequency indices.
//! A full block of [`BLOCK`] lines is written transposed straight from the FFT output, its four
//! pairs as the lanes of AVX2 vectors (one 64-byte row segment per coefficient). Two axes (the
//! smoother's case) take a fused path: the first pass pairs the lines so that each pair's FFT
//! output holds what the second pass's FFT input needs, which is written directly (see
//! `Dct1d::inverse_rows_into_next` and `Dct1d::forward_rows_into_next`); on that path the
//! weighted residual sum is taken in the same pass that unpacks the inverse's samples, and
//! [`DctN::forward_pseudo`] forms smoothn's pseudo-data row by row as the transform reads them.
//!
//! The FFTs are RustFFT's, except where the CPU has AVX-512F and a line's length is a power of two
//! in 16 ..= 512: there a full block's four complex lines go through a Stockham FFT that keeps
//! element j of all four lines in one 512-bit register (`lanes.rs`; a 2-D transform of 128² 22 %
//! faster on a Zen 5 host; tested against RustFFT to rounding). Results then differ from
//! the RustFFT path in the last bits (another summation order), as RustFFT's AVX and scalar paths
//! differ from each other; on one machine they are the same for any thread count.
//!
//! A plan ([`DctN`]) is immutable and shareable across threads; each thread brings its own
//! [`DctNScratch`], so repeated transforms of the same shape allocate nothing.

mod fused;
#[cfg(target_arch = "x86_64")]
mod lanes;
mod nd;
#[cfg(target_arch = "x86_64")]
mod simd;

use std::sync::Arc;

use num_complex::Complex;
use rustfft::{Fft, FftPlanner};

pub use nd::{DctN, DctNScratch};

type C64 = Complex<f64>;

/// Lines transformed together (in pairs, through one batched FFT call).
pub const BLOCK: usize = 8;

/// Rows of a two-axis forward transform's input: stored, or the pseudo-data `w (y − z) + z`
/// formed row by row as the transform reads them (`y`, `z` row-major like the input, `w` too).
#[derive(Clone, Copy)]
pub(super) enum RowSource<'a> {
    Data(&'a [f64]),
    Pseudo { y: &'a [f64], z: &'a [f64], w: &'a [f64] },
}

/// Scratch buffers of a block of 1-D transforms (sized for the longest line of a plan).
pub struct LineScratch {
    c1: Vec<C64>,
    c2: Vec<C64>,
    fft: Vec<C64>,
    /// A line of zeros (partner of an odd last line) and a line to discard its output into.
    zeros: Vec<f64>,
    sink: Vec<f64>,
    /// The real lines of a block, row-major, before they are written transposed.
    block: Vec<f64>,
    /// Work space of the AVX-512 four-line FFT (empty where no plan uses it).
    lanes: Vec<f64>,
}

impl LineScratch {
    fn new(max_len: usize, fft_len: usize, lanes_len: usize) -> Self {
        let c = BLOCK / 2 * max_len;
        Self {
            c1: vec![C64::default(); c],
            c2: vec![C64::default(); c],
            fft: vec![C64::default(); fft_len],
            zeros: vec![0.0; max_len],
            sink: vec![0.0; max_len],
            block: vec![0.0; BLOCK * max_len],
            lanes: vec![0.0; lanes_len],
        }
    }

    fn bytes(&self) -> usize {
        (self.c1.capacity() + self.c2.capacity() + self.fft.capacity()) * std::mem::size_of::<C64>()
            + (self.zeros.capacity() + self.sink.capacity() + self.block.capacity() + self.lanes.capacity())
                * std::mem::size_of::<f64>()
    }
}

/// The FFTs of one length and direction: RustFFT, and where the CPU has AVX-512F and the length
/// is a power of two in 16 ..= 512, the four-line kernel of `lanes` for full blocks.
struct LineFft {
    rust: Arc<dyn Fft<f64>>,
    #[cfg(target_arch = "x86_64")]
    lanes: Option<lanes::LanesFft>,
}

impl LineFft {
    fn new(n: usize, inverse: bool, planner: &mut FftPlanner<f64>) -> Self {
        Self {
            rust: if inverse { planner.plan_fft_inverse(n) } else { planner.plan_fft_forward(n) },
            #[cfg(target_arch = "x86_64")]
            lanes: lanes::LanesFft::new(n, inverse),
        }
    }

    /// f64 of [`LineScratch::lanes`] this transform needs.
    fn lanes_len(&self) -> usize {
        #[cfg(target_arch = "x86_64")]
        if self.lanes.is_some() {
            return lanes::work_len(self.rust.len());
        }
        0
    }

    /// The FFT of each line of `input` (whole lines of this length) into `output`; `input` may be
    /// overwritten (RustFFT uses it as scratch).
    #[inline(always)]
    fn process(&self, input: &mut [C64], output: &mut [C64], fft: &mut [C64], lanes_work: &mut [f64]) {
        #[cfg(target_arch = "x86_64")]
        if let Some(l) = &self.lanes {
            if input.len() == BLOCK / 2 * self.rust.len() {
                l.process4(input, output, lanes_work);
                return;
            }
        }
        let _ = lanes_work;
        self.rust.process_outofplace_with_scratch(input, output, fft);
    }
}

/// Orthonormal DCT-II / DCT-III of one length. Two real lines travel as the real and imaginary parts
/// of one complex line (both transforms are real-linear) through one complex FFT of length n.
pub struct Dct1d {
    n: usize,
    fwd: LineFft,
    inv: LineFft,
    /// `a_k = σ_k e^{-iθ_k} / 2`, θ_k = πk/2n: `X_k = a_k V_k + conj(a_k) V_(n−k)` (V_n = V_0).
    a: Vec<C64>,
    /// Real and imaginary parts of `a`.
    a_re: Vec<f64>,
    a_im: Vec<f64>,
    /// `b_k = e^{iθ_k} / (σ_k n)`: `V_k = b_k (X_k − i X_(n−k))` (X_n = 0), 1/n of the inverse FFT included.
    b: Vec<C64>,
    /// Real and imaginary parts of `b`.
    b_re: Vec<f64>,
    b_im: Vec<f64>,
    /// `b` per complex lane: `[b_k.re, b_k.re]`, `[b_k.im, b_k.im]`, `[−b_k.im, −b_k.im]` (length 2n).
    b_dup: [Vec<f64>; 3],
}

impl Dct1d {
    /// Plans a transform of length `n ≥ 1`, sharing FFT plans through `planner`.
    pub fn with_planner(n: usize, planner: &mut FftPlanner<f64>) -> Self {
        let n = n.max(1);
        let nf = n as f64;
        let sigma = |k: usize| if k == 0 { (1.0 / nf).sqrt() } else { (2.0 / nf).sqrt() };
        let theta = |k: usize| std::f64::consts::PI * k as f64 / (2.0 * nf);
        let a: Vec<C64> = (0..n).map(|k| C64::from_polar(0.5 * sigma(k), -theta(k))).collect();
        let (a_re, a_im) = (a.iter().map(|c| c.re).collect(), a.iter().map(|c| c.im).collect());
        let b: Vec<C64> = (0..n).map(|k| C64::from_polar(1.0 / (sigma(k) * nf), theta(k))).collect();
        let (b_re, b_im) = (b.iter().map(|c| c.re).collect(), b.iter().map(|c| c.im).collect());
        let dup = |f: &dyn Fn(&C64) -> f64| b.iter().flat_map(|c| [f(c), f(c)]).collect::<Vec<f64>>();
        let b_dup = [dup(&|c| c.re), dup(&|c| c.im), dup(&|c| -c.im)];
        Self {
            n,
            fwd: LineFft::new(n, false, planner),
            inv: LineFft::new(n, true, planner),
            a,
            a_re,
            a_im,
            b,
            b_re,
            b_im,
            b_dup,
        }
    }

    /// Plans a transform of length `n ≥ 1` with a private FFT planner.
    pub fn new(n: usize) -> Self {
        Self::with_planner(n, &mut FftPlanner::new())
    }

    /// Transform length.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Always false (a plan has length ≥ 1).
    pub fn is_empty(&self) -> bool {
        false
    }

    fn fft_scratch_len(&self) -> usize {
        self.fwd.rust.get_outofplace_scratch_len().max(self.inv.rust.get_outofplace_scratch_len())
    }

    fn lanes_scratch_len(&self) -> usize {
        self.fwd.lanes_len().max(self.inv.lanes_len())
    }

    /// Scratch buffers for this length.
    pub fn make_scratch(&self) -> LineScratch {
        LineScratch::new(self.n, self.fft_scratch_len(), self.lanes_scratch_len())
    }

    /// Orthonormal DCT-II of `x` into `y` (both of length [`Self::len`]).
    pub fn forward(&self, x: &[f64], y: &mut [f64], s: &mut LineScratch) {
        self.load(&x[..self.n], self.n, 1, None, false, s);
        self.store_block(&mut y[..self.n], self.n, 1, false, &s.c2, &mut s.sink);
    }

    /// Orthonormal DCT-III (inverse of [`Self::forward`]) of `y` into `x`.
    pub fn inverse(&self, y: &[f64], x: &mut [f64], s: &mut LineScratch) {
        self.load(&y[..self.n], self.n, 1, None, true, s);
        self.store_block(&mut x[..self.n], self.n, 1, true, &s.c2, &mut s.sink);
    }

    /// In-place orthonormal DCT-II.
    pub fn forward_in_place(&self, xy: &mut [f64], s: &mut LineScratch) {
        self.load(&xy[..self.n], self.n, 1, None, false, s);
        self.store_block(&mut xy[..self.n], self.n, 1, false, &s.c2, &mut s.sink);
    }

    /// In-place orthonormal DCT-III.
    pub fn inverse_in_place(&self, xy: &mut [f64], s: &mut LineScratch) {
        self.load(&xy[..self.n], self.n, 1, None, true, s);
        self.store_block(&mut xy[..self.n], self.n, 1, true, &s.c2, &mut s.sink);
    }

    /// Packs the `lines ≤ BLOCK` lines of `src` (line l at `l·stride`) in pairs (line 2p real,
    /// 2p+1 imaginary part of complex line p; an odd last line pairs with zeros; `weight`, laid out
    /// as `src`, multiplies element-wise), prepares them and runs the batched FFT. Forward: Makhoul
    /// reordering `v = [x0, x2, …, x3, x1]`. Inverse: `V_k = b_k (X_k − i X_(n−k))`.
    #[inline(always)]
    fn load(
        &self,
        src: &[f64],
        stride: usize,
        lines: usize,
        weight: Option<&[f64]>,
        inverse: bool,
        s: &mut LineScratch,
    ) {
        let n = self.n;
        let pairs = lines.div_ceil(2);
        let LineScratch { c1, c2, fft, zeros, lanes, .. } = s;
        let zeros = &zeros[..n];
        fn pick<'a>(buf: &'a [f64], l: usize, (lines, stride): (usize, usize), zeros: &'a [f64]) -> &'a [f64] {
            if l < lines {
                &buf[l * stride..][..zeros.len()]
            } else {
                zeros
            }
        }
        let line = |buf, l| pick(buf, l, (lines, stride), zeros);
        for (p, v) in c1.chunks_exact_mut(n).take(pairs).enumerate() {
            let (xa, xb) = (line(src, 2 * p), line(src, 2 * p + 1));
            match (inverse, weight) {
                (false, _) => self.pack_forward(v, xa, xb),
                (true, None) => self.pack_inverse::<false>(v, xa, xb, xa, xb),
                (true, Some(w)) => self.pack_inverse::<true>(v, xa, xb, line(w, 2 * p), line(w, 2 * p + 1)),
            }
        }
        let plan = if inverse { &self.inv } else { &self.fwd };
        plan.process(&mut c1[..pairs * n], &mut c2[..pairs * n], fft, lanes);
    }

    /// `v_q = x_2q` (q < ⌈n/2⌉), `v_(n−1−q) = x_2q+1`, lines a and b as real and imaginary parts.
    #[inline(always)]
    fn pack_forward(&self, v: &mut [C64], xa: &[f64], xb: &[f64]) {
        let n = self.n;
        let (v, xa, xb) = (&mut v[..n], &xa[..n], &xb[..n]);
        #[allow(unused_mut)]
        let mut done = 0;
        #[cfg(target_arch = "x86_64")]
        if simd::available() {
            // SAFETY: AVX2 is available.
            done = unsafe { simd::pack_forward(v, xa, xb) };
        }
        for q in done..n / 2 {
            v[q] = C64::new(xa[2 * q], xb[2 * q]);
            v[n - 1 - q] = C64::new(xa[2 * q + 1], xb[2 * q + 1]);
        }
        if n & 1 == 1 {
            v[n / 2] = C64::new(xa[n - 1], xb[n - 1]);
        }
    }

    /// `U = X^(a) g^(a) + i X^(b) g^(b)`; `V_k = b_k (U_k − i U_(n−k))`,
    /// `V_(n−k) = conj(b_k) (U_k + i U_(n−k))`, `V_0 = b_0 U_0`, and for even n
    /// `V_(n/2) = b (1 − i) U_(n/2)` with `b (1 − i) = √2/(σ n)` real.
    #[inline(always)]
    fn pack_inverse<const WEIGHTED: bool>(&self, v: &mut [C64], xa: &[f64], xb: &[f64], ga: &[f64], gb: &[f64]) {
        let n = self.n;
        let (v, xa, xb, ga, gb) = (&mut v[..n], &xa[..n], &xb[..n], &ga[..n], &gb[..n]);
        let u = |k: usize| {
            if WEIGHTED {
                C64::new(xa[k] * ga[k], xb[k] * gb[k])
            } else {
                C64::new(xa[k], xb[k])
            }
        };
        let (b0, bh) = (self.b[0].re, self.b[n / 2]);
        v[0] = u(0) * b0;
        if n & 1 == 0 {
            v[n / 2] = u(n / 2) * (bh.re + bh.im);
        }
        // Pairs (k, n − k), k = 1 … m, over equal-length sub-slices (no bounds checks; SoA twiddles).
        let m = (n - 1) / 2;
        let (lo, hi) = v[1..].split_at_mut(n - 1 - m);
        let (lo, hi) = (&mut lo[..m], &mut hi[..m]);
        let (br, bi) = (&self.b_re[1..=m], &self.b_im[1..=m]);
        let (xal, xah, xbl, xbh) = (&xa[1..=m], &xa[n - m..], &xb[1..=m], &xb[n - m..]);
        let (gal, gah, gbl, gbh) = (&ga[1..=m], &ga[n - m..], &gb[1..=m], &gb[n - m..]);
        // One pass over k = j + 1 (forward) and its partner n − k (reversed), in blocks of four
        // (the partner block is loaded and reversed as an array), which vectorises.
        let step = |j: usize, (ur, ui, rr, ri): (f64, f64, f64, f64)| {
            // V_k = b (U − iR), V_(n−k) = conj(b) (U + iR).
            let (br, bi) = (br[j], bi[j]);
            let (s1, s2) = (ur + ri, ui - rr);
            let (d1, d2) = (ur - ri, ui + rr);
            (C64::new(br * s1 - bi * s2, br * s2 + bi * s1), C64::new(br * d1 + bi * d2, br * d2 - bi * d1))
        };
        let load = |j: usize, r: usize| {
            if WEIGHTED {
                (xal[j] * gal[j], xbl[j] * gbl[j], xah[r] * gah[r], xbh[r] * gbh[r])
            } else {
                (xal[j], xbl[j], xah[r], xbh[r])
            }
        };
        #[allow(unused_mut)]
        let mut done = 0;
        #[cfg(target_arch = "x86_64")]
        if simd::available() {
            // SAFETY: AVX2 is available.
            done =
                unsafe { simd::pack_inverse::<WEIGHTED>(lo, hi, [br, bi], [xal, xbl, xah, xbh], [gal, gbl, gah, gbh]) };
        }
        // Scalar twin of the AVX2 body (same operations), and the tail.
        #[allow(clippy::needless_range_loop)]
        for j in done..m {
            let r = m - 1 - j;
            (lo[j], hi[r]) = step(j, load(j, r));
        }
    }

    /// Transforms the `lines` rows (length n, row stride `src_stride`; `weight` laid out as `src`)
    /// of `src` into `dst`, with row stride `dst_stride`: row-major, or transposed (n rows, line l
    /// in column l).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn rows(
        &self,
        (src, src_stride, lines): (&[f64], usize, usize),
        weight: Option<&[f64]>,
        (dst, dst_stride): (&mut [f64], usize),
        inverse: bool,
        transpose: bool,
        s: &mut LineScratch,
    ) {
        let n = self.n;
        for r0 in (0..lines).step_by(BLOCK) {
            let nb = (lines - r0).min(BLOCK);
            self.load(&src[r0 * src_stride..], src_stride, nb, weight.map(|w| &w[r0 * src_stride..]), inverse, s);
            let LineScratch { c2, sink, block, .. } = s;
            if !transpose {
                self.store_block(&mut dst[r0 * dst_stride..], dst_stride, nb, inverse, c2, sink);
                continue;
            }
            #[cfg(target_arch = "x86_64")]
            if nb == BLOCK && simd::available() {
                // A full block straight into its 8 columns, the 4 pairs as lanes.
                let c = &c2[..BLOCK / 2 * n];
                // SAFETY: AVX2 is available.
                unsafe {
                    if inverse {
                        simd::unpack_inverse_columns(c, n, dst, (r0, dst_stride));
                    } else {
                        simd::unpack_forward_columns(c, n, (&self.a_re, &self.a_im), dst, (r0, dst_stride));
                    }
                }
                continue;
            }
            // Unpack into an L1-resident row-major block, then write it as columns r0 … r0 + nb.
            let block = &mut block[..nb * n];
            self.store_block(block, n, nb, inverse, c2, sink);
            transpose_block(block, nb, n, dst, r0, dst_stride);
        }
    }

    /// Writes the `lines` lines of the last load into `out` (line l at `l·stride`); the partner of
    /// an odd last line goes to scratch.
    #[inline(always)]
    fn store_block(&self, out: &mut [f64], stride: usize, lines: usize, inverse: bool, c2: &[C64], sink: &mut [f64]) {
        let n = self.n;
        for (p, v) in c2.chunks_exact(n).take(lines.div_ceil(2)).enumerate() {
            let (a, b) = if 2 * p + 1 < lines {
                let (a, b) = out[2 * p * stride..].split_at_mut(stride);
                (&mut a[..n], &mut b[..n])
            } else {
                (&mut out[2 * p * stride..][..n], &mut sink[..n])
            };
            if inverse {
                self.unpack_inverse_rows(v, a, b);
            } else {
                self.unpack_forward_rows(v, a, b);
            }
        }
    }

    /// DCT-II coefficients of the pair spectrum `v` into lines `ya` (real part) and `yb`:
    /// `X_k = P + Q`, `X_(n−k) = i (P − Q)` with `P = a_k V_k`, `Q = conj(a_k) V_(n−k)`, and
    /// `X_0 = 2 Re(a_0) V_0`, `X_(n/2) = 2 Re(a_(n/2)) V_(n/2)` (AVX2 body in blocks of four k).
    #[inline(always)]
    fn unpack_forward_rows(&self, v: &[C64], ya: &mut [f64], yb: &mut [f64]) {
        let n = self.n;
        let (v, ya, yb) = (&v[..n], &mut ya[..n], &mut yb[..n]);
        let (a0, ah) = (self.a[0].re, self.a[n / 2].re);
        let x0 = v[0] * (2.0 * a0);
        (ya[0], yb[0]) = (x0.re, x0.im);
        if n & 1 == 0 {
            let xh = v[n / 2] * (2.0 * ah);
            (ya[n / 2], yb[n / 2]) = (xh.re, xh.im);
        }
        let m = (n - 1) / 2;
        let (vl, vh) = (&v[1..=m], &v[n - m..]);
        let (al, ar) = (&self.a_re[1..=m], &self.a_im[1..=m]);
        let (yal, yah) = ya[1..].split_at_mut(n - 1 - m);
        let (ybl, ybh) = yb[1..].split_at_mut(n - 1 - m);
        let (yal, yah, ybl, ybh) = (&mut yal[..m], &mut yah[..m], &mut ybl[..m], &mut ybh[..m]);
        #[allow(unused_mut)]
        let mut done = 0;
        #[cfg(target_arch = "x86_64")]
        if simd::available() {
            // SAFETY: AVX2 is available.
            done = unsafe { simd::unpack_forward(vl, vh, [al, ar], [&mut *yal, &mut *ybl], [&mut *yah, &mut *ybh]) };
        }
        for j in done..m {
            let r = m - 1 - j;
            let (p, q) = (vl[j], vh[r]);
            // P = a V_k, Q = conj(a) V_(n−k); X_k = P + Q, X_(n−k) = i (P − Q).
            let (pr, pi) = (al[j] * p.re - ar[j] * p.im, al[j] * p.im + ar[j] * p.re);
            let (qr, qi) = (al[j] * q.re + ar[j] * q.im, al[j] * q.im - ar[j] * q.re);
            (yal[j], ybl[j]) = (pr + qr, pi + qi);
            (yah[r], ybh[r]) = (-(pi - qi), pr - qr);
        }
    }

    /// Samples of the pair from the inverse FFT output `v` into two row-major lines:
    /// `x_2q = v_q`, `x_2q+1 = v_(n−1−q)`.
    #[inline(always)]
    fn unpack_inverse_rows(&self, v: &[C64], xa: &mut [f64], xb: &mut [f64]) {
        let n = self.n;
        let h = n / 2;
        let (lo, hi) = v[..n].split_at(n - h);
        let hi = &hi[..h];
        let (xa, xb) = (&mut xa[..n], &mut xb[..n]);
        #[allow(unused_mut)]
        let mut done = 0;
        #[cfg(target_arch = "x86_64")]
        if simd::available() {
            // SAFETY: AVX2 is available.
            done = unsafe { simd::unpack_inverse_rows(lo, hi, xa, xb) };
        }
        unpack_rows_from(lo, hi, xa, xb, done);
    }

    /// [`Self::unpack_inverse_rows`] that also returns `Σ w (y − x)²` (as `(w·d)·d`) of line a,
    /// plus line b when `both`, against the data rows `y` and weights `w`: one running sum per line
    /// and sample index mod 4 (the AVX2 kernel's lanes), added in a fixed order.
    #[inline(always)]
    fn unpack_rss_pair(
        &self,
        v: &[C64],
        xa: &mut [f64],
        xb: &mut [f64],
        y: [&[f64]; 2],
        w: [&[f64]; 2],
        both: bool,
    ) -> f64 {
        let n = self.n;
        let h = n / 2;
        let (lo, hi) = v[..n].split_at(n - h);
        let hi = &hi[..h];
        let (xa, xb) = (&mut xa[..n], &mut xb[..n]);
        let (ya, yb, wa, wb) = (&y[0][..n], &y[1][..n], &w[0][..n], &w[1][..n]);
        #[allow(unused_mut)]
        let (mut done, mut acc) = (0, [[0.0f64; 4]; 2]);
        #[cfg(target_arch = "x86_64")]
        if simd::available() {
            // SAFETY: AVX2 is available.
            (done, acc) = unsafe { simd::unpack_rss(lo, hi, [&mut *xa, &mut *xb], [ya, yb], [wa, wb]) };
        }
        unpack_rows_from(lo, hi, xa, xb, done);
        for i in 2 * done..n {
            let (da, db) = (ya[i] - xa[i], yb[i] - xb[i]);
            acc[0][i % 4] += wa[i] * da * da;
            acc[1][i % 4] += wb[i] * db * db;
        }
        let line = |a: [f64; 4]| (a[0] + a[1]) + (a[2] + a[3]);
        if both {
            line(acc[0]) + line(acc[1])
        } else {
            line(acc[0])
        }
    }

    /// Inverse-transforms the `lines` rows of `src` (row stride `stride`; times `weight`, laid out
    /// as `src`) and returns `Σ w (y − x)²` against the rows of `y` with weights `w` (row-major,
    /// length n); the samples are also written to `keep` (row-major) when given.
    #[inline(always)]
    fn rows_rss(
        &self,
        (src, stride, lines): (&[f64], usize, usize),
        weight: Option<&[f64]>,
        (y, w): (&[f64], &[f64]),
        mut keep: Option<&mut [f64]>,
        s: &mut LineScratch,
    ) -> f64 {
        let n = self.n;
        let mut total = 0.0;
        for r0 in (0..lines).step_by(BLOCK) {
            let nb = (lines - r0).min(BLOCK);
            self.load(&src[r0 * stride..], stride, nb, weight.map(|w| &w[r0 * stride..]), true, s);
            if let Some(out) = keep.as_deref_mut() {
                self.store_block(&mut out[r0 * n..], n, nb, true, &s.c2, &mut s.sink);
            }
            for (p, v) in s.c2.chunks_exact(n).take(nb.div_ceil(2)).enumerate() {
                let (ra, pair) = (r0 + 2 * p, (nb - 2 * p).min(2));
                let rb = if pair == 2 { ra + 1 } else { ra };
                let (ya, yb, wa, wb) = (&y[ra * n..][..n], &y[rb * n..][..n], &w[ra * n..][..n], &w[rb * n..][..n]);
                total += if pair == 2 {
                    self.rss_pair::<true>(v, [ya, yb], [wa, wb])
                } else {
                    self.rss_pair::<false>(v, [ya, yb], [wa, wb])
                };
            }
        }
        total
    }

    /// `Σ w (y − x)²` of the inverse samples `x` of a pair (`BOTH`: line b too) against data rows
    /// `y` and weights `w`; positions 2q and 2q+1 come from `v_q` and `v_(n−1−q)`. Running sums per
    /// line × even/odd position (both lines: also per parity of q, as the AVX2 kernel), added in a
    /// fixed order.
    #[inline(always)]
    fn rss_pair<const BOTH: bool>(&self, v: &[C64], y: [&[f64]; 2], w: [&[f64]; 2]) -> f64 {
        let n = self.n;
        let h = n / 2;
        let (lo, hi) = v[..n].split_at(n - h);
        let hi = &hi[..h];
        let (ya, yb, wa, wb) = (&y[0][..n], &y[1][..n], &w[0][..n], &w[1][..n]);
        if BOTH {
            // Lanes [a, b, a', b'] over blocks of two q, even and odd positions (as `simd::rss_pair`).
            #[allow(unused_mut)]
            let (mut done, mut acc) = (0, [[0.0f64; 4]; 2]);
            #[cfg(target_arch = "x86_64")]
            if simd::available() {
                // SAFETY: AVX2 is available.
                (done, acc) = unsafe { simd::rss_pair(lo, hi, [ya, yb], [wa, wb]) };
            }
            let body = h / 2 * 2;
            for q in done..body {
                let (e, o) = (lo[q], hi[h - 1 - q]);
                let l = 2 * (q & 1);
                let (d0, d1) = (ya[2 * q] - e.re, yb[2 * q] - e.im);
                let (d2, d3) = (ya[2 * q + 1] - o.re, yb[2 * q + 1] - o.im);
                acc[0][l] += wa[2 * q] * d0 * d0;
                acc[0][l + 1] += wb[2 * q] * d1 * d1;
                acc[1][l] += wa[2 * q + 1] * d2 * d2;
                acc[1][l + 1] += wb[2 * q + 1] * d3 * d3;
            }
            let mut tail = 0.0;
            let mut add = |w: f64, y: f64, x: f64| tail += w * (y - x) * (y - x);
            if h & 1 == 1 {
                let q = h - 1;
                let (e, o) = (lo[q], hi[0]);
                add(wa[2 * q], ya[2 * q], e.re);
                add(wb[2 * q], yb[2 * q], e.im);
                add(wa[2 * q + 1], ya[2 * q + 1], o.re);
                add(wb[2 * q + 1], yb[2 * q + 1], o.im);
            }
            if n & 1 == 1 {
                let e = lo[h];
                add(wa[n - 1], ya[n - 1], e.re);
                add(wb[n - 1], yb[n - 1], e.im);
            }
            let [e, o] = acc;
            return (((e[0] + e[1]) + (e[2] + e[3])) + ((o[0] + o[1]) + (o[2] + o[3]))) + tail;
        }
        let mut acc = [0.0f64; 4];
        for q in 0..h {
            let (e, o) = (lo[q], hi[h - 1 - q]);
            let (d0, d1) = (ya[2 * q] - e.re, ya[2 * q + 1] - o.re);
            acc[0] += wa[2 * q] * d0 * d0;
            acc[1] += wa[2 * q + 1] * d1 * d1;
            if BOTH {
                let (d2, d3) = (yb[2 * q] - e.im, yb[2 * q + 1] - o.im);
                acc[2] += wb[2 * q] * d2 * d2;
                acc[3] += wb[2 * q + 1] * d3 * d3;
            }
        }
        if n & 1 == 1 {
            let e = lo[h];
            let d = ya[n - 1] - e.re;
            acc[0] += wa[n - 1] * d * d;
            if BOTH {
                let d = yb[n - 1] - e.im;
                acc[2] += wb[n - 1] * d * d;
            }
        }
        (acc[0] + acc[1]) + (acc[2] + acc[3])
    }

    /// Transforms the rows of `data` in place.
    #[inline(always)]
    fn rows_in_place(&self, data: &mut [f64], inverse: bool, s: &mut LineScratch) {
        let n = self.n;
        for lines in data.chunks_mut(BLOCK * n) {
            let nb = lines.len() / n;
            self.load(lines, n, nb, None, inverse, s);
            self.store_block(lines, n, nb, inverse, &s.c2, &mut s.sink);
        }
    }
}

/// Writes the `lines` rows of `block` (row-major, length n) as columns `c0 …` of `dst` (row
/// stride `stride`): `dst[k·stride + c0 + l] = block[l·n + k]`.
#[inline(always)]
fn transpose_block(block: &[f64], lines: usize, n: usize, dst: &mut [f64], c0: usize, stride: usize) {
    #[allow(unused_mut)]
    let (mut kb, mut lb) = (0, 0);
    #[cfg(target_arch = "x86_64")]
    if simd::available() {
        // SAFETY: AVX2 is available.
        (kb, lb) = unsafe { simd::transpose_block(block, lines, n, dst, c0, stride) };
    }
    for k in 0..n {
        // Tiles cover rows k < kb and lines l < lb; finish the rest.
        let l_start = if k < kb { lb } else { 0 };
        let d = &mut dst[k * stride + c0..][..lines];
        for (l, d) in d.iter_mut().enumerate().skip(l_start) {
            *d = block[l * n + k];
        }
    }
}

/// Scalar part of the inverse's unpacking (after `done` pairs of the vector kernel):
/// `x_2q = v_q`, `x_2q+1 = v_(n−1−q)` (line a the real parts, b the imaginary ones), and for odd
/// n `x_(n−1) = v_(n/2)`; `lo = v[..n − h]`, `hi = v[n − h..]`, h = n/2 = `hi.len()`.
#[inline(always)]
fn unpack_rows_from(lo: &[C64], hi: &[C64], xa: &mut [f64], xb: &mut [f64], done: usize) {
    let (n, h) = (xa.len(), hi.len());
    for q in done..h {
        let (e, o) = (lo[q], hi[h - 1 - q]);
        (xa[2 * q], xb[2 * q]) = (e.re, e.im);
        (xa[2 * q + 1], xb[2 * q + 1]) = (o.re, o.im);
    }
    if n & 1 == 1 {
        (xa[n - 1], xb[n - 1]) = (lo[h].re, lo[h].im);
    }
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::*;

    /// The AVX2 kernels and their scalar twins give the same bits (odd and even lengths, line
    /// counts that leave tails of every size).
    #[test]
    fn simd_kernels_match_scalar_bit_for_bit() {
        for shape in [vec![200, 200], vec![13, 18], vec![7, 9], vec![5, 3, 11], vec![31], vec![16, 1]] {
            let plan = DctN::new(&shape);
            let n = plan.len();
            let f = |i: usize, a: f64| ((i as f64 * a).sin() * 3.0 + (i % 7) as f64 * 0.1).abs();
            let (x, g, y, w): (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>) = (0..n)
                .map(|i| (f(i, 0.37) - 1.0, 1.0 / (1.0 + f(i, 0.11)), f(i, 0.71), f(i, 0.23) / 3.0))
                .fold(Default::default(), |mut acc, (a, b, c, d)| {
                    acc.0.push(a);
                    acc.1.push(b);
                    acc.2.push(c);
                    acc.3.push(d);
                    acc
                });
            let run = |scalar: bool| {
                simd::FORCE_SCALAR.with(|s| s.set(scalar));
                let mut s = plan.make_scratch();
                let (mut out, mut work, mut fwd) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
                plan.inverse_weighted(&x, Some(&g), &mut out, &mut s);
                let rss = plan.weighted_rss(&x, Some(&g), &y, &w, &mut work, &mut s);
                plan.forward(&y, &mut fwd, &mut s);
                simd::FORCE_SCALAR.with(|s| s.set(false));
                (out, rss, fwd)
            };
            let (a, b) = (run(false), run(true));
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&a.0), bits(&b.0), "inverse, shape {shape:?}");
            assert_eq!(a.1.to_bits(), b.1.to_bits(), "rss, shape {shape:?}");
            assert_eq!(bits(&a.2), bits(&b.2), "forward, shape {shape:?}");
        }
    }
}
