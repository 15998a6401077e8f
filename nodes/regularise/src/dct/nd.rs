//! The N-D plan: 1-D transforms along every non-singleton axis with axis rotation (see the
//! parent module for the layouts).

use std::sync::{Mutex, OnceLock};

use rustfft::FftPlanner;

use super::{Dct1d, LineScratch, C64};

/// Tile edge of the cache-blocked transpose.
const TILE: usize = 16;

/// Plan of an orthonormal N-D DCT-II / DCT-III for one row-major shape.
pub struct DctN {
    shape: Vec<usize>,
    /// Original indices of the non-singleton axes.
    axes: Vec<usize>,
    /// One 1-D plan per non-singleton axis.
    plans: Vec<Dct1d>,
    len: usize,
}

/// Per-thread scratch of a [`DctN`] plan.
pub struct DctNScratch {
    line: LineScratch,
    tmp: Vec<f64>,
    /// Two axes: the second pass's FFT input (⌈n0/2⌉ × n1), written by the first inverse pass.
    pairs: Vec<C64>,
}

impl DctNScratch {
    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.line.bytes() + self.tmp.capacity() * 8 + self.pairs.capacity() * std::mem::size_of::<C64>()
    }
}

impl DctN {
    /// Plans the transform of a row-major array of `shape` (last axis contiguous). Axes of
    /// length 1 are skipped (the DCT of one sample is the identity). Zero-length axes give an
    /// empty plan.
    pub fn new(shape: &[usize]) -> Self {
        // One FFT planner per process: it keeps the plans of every length it has made, so a new
        // plan for a shape seen before (a Python call, a new workspace) re-plans nothing.
        static PLANNER: OnceLock<Mutex<FftPlanner<f64>>> = OnceLock::new();
        let mut planner = PLANNER
            .get_or_init(|| Mutex::new(FftPlanner::new()))
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let len = shape.iter().product();
        let axes: Vec<usize> = if len == 0 { Vec::new() } else { (0..shape.len()).filter(|&a| shape[a] > 1).collect() };
        let plans = axes.iter().map(|&a| Dct1d::with_planner(shape[a], &mut planner)).collect();
        Self { shape: shape.to_vec(), axes, plans, len }
    }

    /// The spatial shape.
    pub fn shape(&self) -> &[usize] {
        &self.shape
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True for a shape with a zero-length axis.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Original axis indices in the order in which the coefficients are stored (row-major over
    /// these axes; singleton axes are omitted): `(a1, …, a(K-1), a0)`.
    pub fn spectral_axes(&self) -> Vec<usize> {
        let mut v = self.axes.clone();
        if !v.is_empty() {
            v.rotate_left(1);
        }
        v
    }

    /// Calls `f(flat_index, k)` for every coefficient, `k[a]` being its frequency index along
    /// original axis `a` (0 along singleton axes), in storage order.
    pub fn spectral_indices(&self, mut f: impl FnMut(usize, &[usize])) {
        let order = self.spectral_axes();
        let mut k = vec![0usize; self.shape.len()];
        for flat in 0..self.len {
            f(flat, &k);
            for &a in order.iter().rev() {
                k[a] += 1;
                if k[a] < self.shape[a] {
                    break;
                }
                k[a] = 0;
            }
        }
    }

    /// Scratch buffers for this plan.
    pub fn make_scratch(&self) -> DctNScratch {
        let max_n = self.plans.iter().map(Dct1d::len).max().unwrap_or(1);
        let fft = self.plans.iter().map(Dct1d::fft_scratch_len).max().unwrap_or(0);
        let lanes = self.plans.iter().map(Dct1d::lanes_scratch_len).max().unwrap_or(0);
        let tmp_len = if self.plans.len() >= 3 { self.len } else { 0 };
        let pairs_len = match self.plans.len() {
            2 => {
                let (n0, n1) = (self.plans[0].len(), self.plans[1].len());
                // inverse: ⌈n0/2⌉ rows of n1; forward: ⌊(n1 − 1)/2⌋ + 1 rows of n0
                (n0.div_ceil(2) * n1).max(((n1 - 1) / 2 + 1) * n0)
            }
            _ => 0,
        };
        DctNScratch {
            line: LineScratch::new(max_n, fft, lanes),
            tmp: vec![0.0; tmp_len],
            pairs: vec![C64::default(); pairs_len],
        }
    }

    /// Forward orthonormal DCT-II of the spatial array `input` into `output` (spectral layout).
    ///
    /// # Panics
    /// If a slice length differs from [`Self::len`] or the scratch belongs to another plan.
    pub fn forward(&self, input: &[f64], output: &mut [f64], s: &mut DctNScratch) {
        assert!(input.len() == self.len && output.len() == self.len, "DctN::forward: wrong slice length");
        #[cfg(target_arch = "x86_64")]
        if avx2() {
            // SAFETY: the CPU supports AVX2 (checked at run time).
            return unsafe { self.forward_avx2(input, output, s) };
        }
        self.forward_body(input, output, s);
    }

    /// [`Self::forward`] of the pseudo-data `w (y − z) + z` (smoothn's iteration; `w` laid out as
    /// the grid): on a two-axis grid the rows are formed as the transform reads them, otherwise in
    /// `work` first. The same values as forming the array and calling [`Self::forward`].
    ///
    /// # Panics
    /// If a slice length differs from [`Self::len`] or the scratch belongs to another plan.
    pub fn forward_pseudo(
        &self,
        (y, z, w): (&[f64], &[f64], &[f64]),
        work: &mut [f64],
        output: &mut [f64],
        s: &mut DctNScratch,
    ) {
        assert!(
            [y.len(), z.len(), w.len(), work.len(), output.len()].iter().all(|l| *l == self.len),
            "DctN::forward_pseudo: wrong slice length"
        );
        #[cfg(target_arch = "x86_64")]
        if avx2() {
            // SAFETY: the CPU supports AVX2 (checked at run time).
            return unsafe { self.forward_pseudo_avx2((y, z, w), work, output, s) };
        }
        self.forward_pseudo_body((y, z, w), work, output, s);
    }

    /// [`Self::forward_pseudo`] compiled for AVX2 (same operations, so the same bits).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn forward_pseudo_avx2(
        &self,
        yzw: (&[f64], &[f64], &[f64]),
        work: &mut [f64],
        output: &mut [f64],
        s: &mut DctNScratch,
    ) {
        self.forward_pseudo_body(yzw, work, output, s);
    }

    #[inline(always)]
    fn forward_pseudo_body(
        &self,
        (y, z, w): (&[f64], &[f64], &[f64]),
        work: &mut [f64],
        output: &mut [f64],
        s: &mut DctNScratch,
    ) {
        if self.plans.len() == 2 {
            let (p0, p1) = (&self.plans[0], &self.plans[1]);
            let DctNScratch { line, pairs, .. } = s;
            p1.forward_rows_into_next(super::RowSource::Pseudo { y, z, w }, p0, pairs, line);
            p0.finish_forward_pairs(pairs, p1.len(), output, line);
            return;
        }
        for (((b, w), y), z) in work.iter_mut().zip(w).zip(y).zip(z) {
            *b = w * (y - z) + z;
        }
        self.forward_body(work, output, s);
    }

    /// [`Self::forward`] compiled for AVX2 (same operations, so the same bits).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn forward_avx2(&self, input: &[f64], output: &mut [f64], s: &mut DctNScratch) {
        self.forward_body(input, output, s);
    }

    #[inline(always)]
    fn forward_body(&self, input: &[f64], output: &mut [f64], s: &mut DctNScratch) {
        let k = self.plans.len();
        let DctNScratch { line, tmp, pairs } = s;
        if k == 0 {
            output.copy_from_slice(input);
            return;
        }
        let len = self.len;
        if k == 1 {
            let n = self.plans[0].len();
            self.plans[0].rows((input, n, len / n), None, (output, n), false, false, line);
            return;
        }
        if k == 2 {
            // Along a1, fused with the preparation of the pass along a0 (see `Dct1d::forward_rows_into_next`).
            let (p0, p1) = (&self.plans[0], &self.plans[1]);
            p1.forward_rows_into_next(super::RowSource::Data(input), p0, pairs, line);
            p0.finish_forward_pairs(pairs, p1.len(), output, line);
            return;
        }
        // Step t transforms axis K-1-t (the current last axis) and rotates it to the front.
        for t in 0..k - 1 {
            let plan = &self.plans[k - 1 - t];
            let (n, to_output) = (plan.len(), (k - 2 - t) & 1 == 0);
            let lines = len / n;
            match (t, to_output) {
                (0, true) => plan.rows((input, n, lines), None, (output, lines), false, true, line),
                (0, false) => plan.rows((input, n, lines), None, (tmp, lines), false, true, line),
                (_, true) => plan.rows((tmp, n, lines), None, (output, lines), false, true, line),
                (_, false) => plan.rows((output, n, lines), None, (tmp, lines), false, true, line),
            }
        }
        self.plans[0].rows_in_place(output, false, line);
    }

    /// Inverse (orthonormal DCT-III) of the spectral-layout array `input` into the spatial `output`.
    ///
    /// # Panics
    /// If a slice length differs from [`Self::len`] or the scratch belongs to another plan.
    pub fn inverse(&self, input: &[f64], output: &mut [f64], s: &mut DctNScratch) {
        self.inverse_weighted(input, None, output, s);
    }

    /// Inverse of `weight ∘ input` (element-wise product, fused into the first pass).
    ///
    /// # Panics
    /// If a slice length differs from [`Self::len`] or the scratch belongs to another plan.
    pub fn inverse_weighted(&self, input: &[f64], weight: Option<&[f64]>, output: &mut [f64], s: &mut DctNScratch) {
        assert!(input.len() == self.len && output.len() == self.len, "DctN::inverse: wrong slice length");
        assert!(weight.is_none_or(|w| w.len() == self.len), "DctN::inverse: wrong weight length");
        #[cfg(target_arch = "x86_64")]
        if avx2() {
            // SAFETY: the CPU supports AVX2 (checked at run time).
            return unsafe { self.inverse_avx2(input, weight, output, s) };
        }
        self.inverse_body(input, weight, output, s);
    }

    /// [`Self::inverse_weighted`] compiled for AVX2 (same operations, so the same bits).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn inverse_avx2(&self, input: &[f64], weight: Option<&[f64]>, output: &mut [f64], s: &mut DctNScratch) {
        self.inverse_body(input, weight, output, s);
    }

    #[inline(always)]
    fn inverse_body(&self, input: &[f64], weight: Option<&[f64]>, output: &mut [f64], s: &mut DctNScratch) {
        match self.plans.len() {
            0 => {
                for (i, (o, x)) in output.iter_mut().zip(input).enumerate() {
                    *o = weight.map_or(*x, |w| w[i] * x);
                }
            }
            1 => {
                let n = self.plans[0].len();
                self.plans[0].rows((input, n, self.len / n), weight, (output, n), true, false, &mut s.line);
            }
            2 => {
                let (p0, p1) = (&self.plans[0], &self.plans[1]);
                p0.inverse_rows_into_next(input, weight, p1, &mut s.pairs, &mut s.line);
                p1.finish_pair_rows(&mut s.pairs, p0.len(), None, Some(output), &mut s.line);
            }
            k => {
                self.inverse_all_but_last(input, weight, output, s);
                self.plans[k - 1].rows_in_place(output, true, &mut s.line);
            }
        }
    }

    /// `Σ_i w_i (y_i − x_i)²` with `x` the inverse of `weight ∘ input`, without storing `x` (the last
    /// pass accumulates instead of writing); `work` is a grid-sized buffer.
    ///
    /// # Panics
    /// If a slice length differs from [`Self::len`] or the scratch belongs to another plan.
    pub fn weighted_rss(
        &self,
        input: &[f64],
        weight: Option<&[f64]>,
        y: &[f64],
        w: &[f64],
        work: &mut [f64],
        s: &mut DctNScratch,
    ) -> f64 {
        self.weighted_rss_keep(input, weight, (y, w), work, None, s)
    }

    /// [`Self::weighted_rss`] that also writes the inverse `x` to `keep` (the same bits as
    /// [`Self::inverse_weighted`]) when given; `keep` and `work` are distinct grid-sized buffers.
    ///
    /// # Panics
    /// If a slice length differs from [`Self::len`] or the scratch belongs to another plan.
    pub fn weighted_rss_keep(
        &self,
        input: &[f64],
        weight: Option<&[f64]>,
        (y, w): (&[f64], &[f64]),
        work: &mut [f64],
        keep: Option<&mut [f64]>,
        s: &mut DctNScratch,
    ) -> f64 {
        assert!(
            [input.len(), y.len(), w.len(), work.len()].iter().all(|l| *l == self.len),
            "DctN::weighted_rss: length"
        );
        assert!(weight.is_none_or(|g| g.len() == self.len), "DctN::weighted_rss: wrong weight length");
        assert!(keep.as_ref().is_none_or(|k| k.len() == self.len), "DctN::weighted_rss: wrong keep length");
        #[cfg(target_arch = "x86_64")]
        if avx2() {
            // SAFETY: the CPU supports AVX2 (checked at run time).
            return unsafe { self.rss_avx2(input, weight, (y, w), work, keep, s) };
        }
        self.rss_body(input, weight, (y, w), work, keep, s)
    }

    /// [`Self::weighted_rss`] compiled for AVX2 (same operations, so the same bits).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn rss_avx2(
        &self,
        input: &[f64],
        weight: Option<&[f64]>,
        yw: (&[f64], &[f64]),
        work: &mut [f64],
        keep: Option<&mut [f64]>,
        s: &mut DctNScratch,
    ) -> f64 {
        self.rss_body(input, weight, yw, work, keep, s)
    }

    #[inline(always)]
    fn rss_body(
        &self,
        input: &[f64],
        weight: Option<&[f64]>,
        (y, w): (&[f64], &[f64]),
        work: &mut [f64],
        keep: Option<&mut [f64]>,
        s: &mut DctNScratch,
    ) -> f64 {
        match self.plans.len() {
            0 => {
                let x = |i: usize| weight.map_or(input[i], |g| g[i] * input[i]);
                if let Some(keep) = keep {
                    keep.iter_mut().enumerate().for_each(|(i, k)| *k = x(i));
                }
                (0..self.len).map(|i| w[i] * (y[i] - x(i)).powi(2)).sum()
            }
            1 => {
                let n = self.plans[0].len();
                self.plans[0].rows_rss((input, n, self.len / n), weight, (y, w), keep, &mut s.line)
            }
            2 => {
                let (p0, p1) = (&self.plans[0], &self.plans[1]);
                p0.inverse_rows_into_next(input, weight, p1, &mut s.pairs, &mut s.line);
                p1.finish_pair_rows(&mut s.pairs, p0.len(), Some((y, w)), keep, &mut s.line)
            }
            k => {
                self.inverse_all_but_last(input, weight, work, s);
                let n = self.plans[k - 1].len();
                self.plans[k - 1].rows_rss((work, n, self.len / n), None, (y, w), keep, &mut s.line)
            }
        }
    }

    /// Every inverse pass but the last (K ≥ 2 axes); the result, with only the last axis still to
    /// invert along its rows, is left in `output`.
    #[inline(always)]
    fn inverse_all_but_last(&self, input: &[f64], weight: Option<&[f64]>, output: &mut [f64], s: &mut DctNScratch) {
        let k = self.plans.len();
        let DctNScratch { line, tmp, .. } = s;
        // Layout rotL^(t+1)(a): invert the last axis a_t, then move the first axis to the end (K ≥ 3;
        // two axes take the padded path of the callers).
        for t in 0..k - 1 {
            let plan = &self.plans[t];
            let (n, lines) = (plan.len(), self.len / plan.len());
            if t == 0 {
                plan.rows((input, n, lines), weight, (tmp, n), true, false, line);
            } else {
                plan.rows((output, n, lines), None, (tmp, n), true, false, line);
            }
            let first = self.plans[t + 1].len();
            transpose(tmp, output, first, self.len / first);
        }
    }
}

/// AVX2 available (cached by the standard library). The AVX2 builds run the same IEEE operations in
/// the same order (no FMA contraction), so results do not depend on the CPU.
#[cfg(target_arch = "x86_64")]
#[inline]
fn avx2() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
}

/// Cache-blocked transpose of `src` (rows × cols, row-major) into `dst` (cols × rows).
#[inline(always)]
fn transpose(src: &[f64], dst: &mut [f64], rows: usize, cols: usize) {
    for r0 in (0..rows).step_by(TILE) {
        let r1 = (r0 + TILE).min(rows);
        for c0 in (0..cols).step_by(TILE) {
            let c1 = (c0 + TILE).min(cols);
            for c in c0..c1 {
                for r in r0..r1 {
                    dst[c * rows + r] = src[r * cols + c];
                }
            }
        }
    }
}
