//! The N-D plan: 1-D transforms along every non-singleton axis with axis rotation (see the
//! parent module for the layouts).

use rustfft::FftPlanner;

use super::{Dct1d, LineScratch};

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
}

impl DctNScratch {
    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.line.bytes() + self.tmp.capacity() * 8
    }
}

impl DctN {
    /// Plans the transform of a row-major array of `shape` (last axis contiguous). Axes of
    /// length 1 are skipped (the DCT of one sample is the identity). Zero-length axes give an
    /// empty plan.
    pub fn new(shape: &[usize]) -> Self {
        let mut planner = FftPlanner::new();
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
        let tmp_len = if self.plans.len() >= 3 { self.len } else { 0 };
        DctNScratch { line: LineScratch::new(max_n, fft), tmp: vec![0.0; tmp_len] }
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

    /// [`Self::forward`] compiled for AVX2 (same operations, so the same bits).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn forward_avx2(&self, input: &[f64], output: &mut [f64], s: &mut DctNScratch) {
        self.forward_body(input, output, s);
    }

    #[inline(always)]
    fn forward_body(&self, input: &[f64], output: &mut [f64], s: &mut DctNScratch) {
        let k = self.plans.len();
        let DctNScratch { line, tmp } = s;
        if k == 0 {
            output.copy_from_slice(input);
            return;
        }
        if k == 1 {
            self.plans[0].rows(input, None, output, false, false, line);
            return;
        }
        // Step t transforms axis K-1-t (the current last axis) and rotates it to the front.
        for t in 0..k - 1 {
            let plan = &self.plans[k - 1 - t];
            let to_output = (k - 2 - t) & 1 == 0;
            match (t, to_output) {
                (0, true) => plan.rows(input, None, output, false, true, line),
                (0, false) => plan.rows(input, None, tmp, false, true, line),
                (_, true) => plan.rows(tmp, None, output, false, true, line),
                (_, false) => plan.rows(output, None, tmp, false, true, line),
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
            1 => self.plans[0].rows(input, weight, output, true, false, &mut s.line),
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
        assert!(
            [input.len(), y.len(), w.len(), work.len()].iter().all(|l| *l == self.len),
            "DctN::weighted_rss: length"
        );
        assert!(weight.is_none_or(|g| g.len() == self.len), "DctN::weighted_rss: wrong weight length");
        #[cfg(target_arch = "x86_64")]
        if avx2() {
            // SAFETY: the CPU supports AVX2 (checked at run time).
            return unsafe { self.rss_avx2(input, weight, y, w, work, s) };
        }
        self.rss_body(input, weight, y, w, work, s)
    }

    /// [`Self::weighted_rss`] compiled for AVX2 (same operations, so the same bits).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn rss_avx2(
        &self,
        input: &[f64],
        weight: Option<&[f64]>,
        y: &[f64],
        w: &[f64],
        work: &mut [f64],
        s: &mut DctNScratch,
    ) -> f64 {
        self.rss_body(input, weight, y, w, work, s)
    }

    #[inline(always)]
    fn rss_body(
        &self,
        input: &[f64],
        weight: Option<&[f64]>,
        y: &[f64],
        w: &[f64],
        work: &mut [f64],
        s: &mut DctNScratch,
    ) -> f64 {
        match self.plans.len() {
            0 => (0..self.len).map(|i| w[i] * (y[i] - weight.map_or(input[i], |g| g[i] * input[i])).powi(2)).sum(),
            1 => self.plans[0].rows_rss(input, weight, y, w, &mut s.line),
            k => {
                self.inverse_all_but_last(input, weight, work, s);
                self.plans[k - 1].rows_rss(work, None, y, w, &mut s.line)
            }
        }
    }

    /// Every inverse pass but the last (K ≥ 2 axes); the result, with only the last axis still to
    /// invert along its rows, is left in `output`.
    #[inline(always)]
    fn inverse_all_but_last(&self, input: &[f64], weight: Option<&[f64]>, output: &mut [f64], s: &mut DctNScratch) {
        let k = self.plans.len();
        let DctNScratch { line, tmp } = s;
        if k == 2 {
            // Layout (a1, a0): invert along a0 writing (a0, a1).
            self.plans[0].rows(input, weight, output, true, true, line);
            return;
        }
        // Layout rotL^(t+1)(a): invert the last axis a_t, then move the first axis to the end.
        for t in 0..k - 1 {
            let plan = &self.plans[t];
            if t == 0 {
                plan.rows(input, weight, tmp, true, false, line);
            } else {
                plan.rows(output, None, tmp, true, false, line);
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
