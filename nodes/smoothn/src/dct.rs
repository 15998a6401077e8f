//! Orthonormal DCT-II and its inverse (DCT-III) in one and N dimensions, computed with a real FFT.
//!
//! One line of length `n` uses Makhoul's even/odd reordering (J. Makhoul 1980, "A fast cosine
//! transform in one and two dimensions", IEEE Trans. ASSP 28:27-34): `v = [x0, x2, x4, …, x5, x3, x1]`,
//! `V = FFT(v)`, `X_k = Re(e^{-iπk/2n} V_k)`, O(n log n) for every length, not only powers of two.
//! Even lengths pack `v` into `n/2` complex samples and use one complex FFT of `n/2` points
//! (`rustfft`), with the real-FFT split and the DCT twiddle fused into one pass; odd lengths use the
//! real FFT of `realfft`. Lines are transformed in blocks of [`BLOCK`] (one batched FFT call). Scaling is orthonormal (MATLAB `dct`,
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
//!
//! A plan ([`DctN`]) is immutable and shareable across threads; each thread brings its own
//! [`DctNScratch`], so repeated transforms of the same shape allocate nothing.

use std::sync::Arc;

use realfft::num_complex::Complex;
use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};
use rustfft::{Fft, FftPlanner};

type C64 = Complex<f64>;

/// Lines transformed together (one batched FFT call, one cache line of f64 per transposed write).
pub const BLOCK: usize = 8;
/// Tile edge of the cache-blocked transpose.
const TILE: usize = 16;

/// Scratch buffers of a block of 1-D transforms (sized for the longest line of a plan).
pub struct LineScratch {
    real: Vec<f64>,
    c1: Vec<C64>,
    c2: Vec<C64>,
    fft: Vec<C64>,
}

impl LineScratch {
    fn new(max_len: usize, fft_len: usize) -> Self {
        let c = BLOCK * (max_len / 2 + 1);
        Self {
            real: vec![0.0; BLOCK * max_len],
            c1: vec![C64::default(); c],
            c2: vec![C64::default(); c],
            fft: vec![C64::default(); fft_len],
        }
    }

    fn bytes(&self) -> usize {
        self.real.capacity() * 8 + (self.c1.capacity() + self.c2.capacity() + self.fft.capacity()) * 16
    }
}

enum Kernel {
    /// Even n = 2h: complex FFT of h points on `w_j = v_2j + i v_2j+1`.
    Half {
        fwd: Arc<dyn Fft<f64>>,
        inv: Arc<dyn Fft<f64>>,
        /// `−i e^{-2πik/n} / 2`, k < h (forward split of the half-length FFT).
        fwd_tw: Vec<C64>,
        /// `i e^{2πik/n} / 2`, k < h (inverse merge into the half-length FFT).
        inv_tw: Vec<C64>,
        /// `σ_k e^{-iπk/2n}`, k ≤ h (forward output twiddle).
        out_tw: Vec<C64>,
        /// `e^{iπk/2n} / (σ_k h)`, k ≤ h (inverse input twiddle, with the 1/h of the inverse FFT).
        in_tw: Vec<C64>,
    },
    /// Odd n: real FFT of n points.
    Real {
        r2c: Arc<dyn RealToComplex<f64>>,
        c2r: Arc<dyn ComplexToReal<f64>>,
        /// `σ_k (cos θ_k, sin θ_k)`, θ_k = πk/2n.
        fwd: Vec<[f64; 2]>,
        /// `(cos θ_k, sin θ_k) / (n σ_k)`, k ≤ n/2.
        inv: Vec<[f64; 2]>,
    },
}

/// Orthonormal DCT-II / DCT-III of one length.
pub struct Dct1d {
    n: usize,
    kernel: Kernel,
}

impl Dct1d {
    /// Plans a transform of length `n ≥ 1`, sharing FFT plans through the planners.
    pub fn with_planners(n: usize, complex: &mut FftPlanner<f64>, real: &mut RealFftPlanner<f64>) -> Self {
        let n = n.max(1);
        let nf = n as f64;
        let sigma = |k: usize| if k == 0 { (1.0 / nf).sqrt() } else { (2.0 / nf).sqrt() };
        let theta = |k: usize| std::f64::consts::PI * k as f64 / (2.0 * nf);
        let kernel = if n % 2 == 0 {
            let h = n / 2;
            let omega = |k: usize| C64::from_polar(1.0, -2.0 * std::f64::consts::PI * k as f64 / nf);
            let fwd_tw = (0..h).map(|k| C64::new(0.0, -0.5) * omega(k)).collect();
            let inv_tw = (0..h).map(|k| C64::new(0.0, 0.5) * omega(k).conj()).collect();
            let out_tw = (0..=h).map(|k| C64::from_polar(sigma(k), -theta(k))).collect();
            let mut in_tw: Vec<C64> = (0..=h).map(|k| C64::from_polar(1.0 / (sigma(k) * h as f64), theta(k))).collect();
            // At k = h the input pair is (X_h, −X_h): e^{iπ/4}(1 − i) = √2 exactly real.
            in_tw[h] = C64::new(std::f64::consts::SQRT_2 / (sigma(h) * h as f64), 0.0);
            Kernel::Half {
                fwd: complex.plan_fft_forward(h),
                inv: complex.plan_fft_inverse(h),
                fwd_tw,
                inv_tw,
                out_tw,
                in_tw,
            }
        } else {
            let fwd = (0..n).map(|k| [sigma(k) * theta(k).cos(), sigma(k) * theta(k).sin()]).collect();
            let inv = (0..=n / 2)
                .map(|k| {
                    let g = 1.0 / (nf * sigma(k));
                    [g * theta(k).cos(), g * theta(k).sin()]
                })
                .collect();
            Kernel::Real { r2c: real.plan_fft_forward(n), c2r: real.plan_fft_inverse(n), fwd, inv }
        };
        Self { n, kernel }
    }

    /// Plans a transform of length `n ≥ 1` with private FFT planners.
    pub fn new(n: usize) -> Self {
        Self::with_planners(n, &mut FftPlanner::new(), &mut RealFftPlanner::new())
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
        match &self.kernel {
            Kernel::Half { fwd, inv, .. } => fwd.get_outofplace_scratch_len().max(inv.get_outofplace_scratch_len()),
            Kernel::Real { r2c, c2r, .. } => r2c.get_scratch_len().max(c2r.get_scratch_len()),
        }
    }

    /// Scratch buffers for this length.
    pub fn make_scratch(&self) -> LineScratch {
        LineScratch::new(self.n, self.fft_scratch_len())
    }

    /// Orthonormal DCT-II of `x` into `y` (both of length [`Self::len`]).
    pub fn forward(&self, x: &[f64], y: &mut [f64], s: &mut LineScratch) {
        self.load_forward(&x[..self.n], s);
        self.store_forward(0, y, s);
    }

    /// Orthonormal DCT-III (inverse of [`Self::forward`]) of `y` into `x`.
    pub fn inverse(&self, y: &[f64], x: &mut [f64], s: &mut LineScratch) {
        self.load_inverse(&y[..self.n], None, s);
        self.store_inverse(0, x, s);
    }

    /// In-place orthonormal DCT-II.
    pub fn forward_in_place(&self, xy: &mut [f64], s: &mut LineScratch) {
        self.load_forward(&xy[..self.n], s);
        self.store_forward(0, xy, s);
    }

    /// In-place orthonormal DCT-III.
    pub fn inverse_in_place(&self, xy: &mut [f64], s: &mut LineScratch) {
        self.load_inverse(&xy[..self.n], None, s);
        self.store_inverse(0, xy, s);
    }

    /// Reorders and FFTs the `src.len()/n ≤ BLOCK` contiguous lines of `src`.
    fn load_forward(&self, src: &[f64], s: &mut LineScratch) {
        let n = self.n;
        let nb = src.len() / n;
        let h = n / 2;
        match &self.kernel {
            Kernel::Half { fwd, .. } => {
                // w_j = v_2j + i v_2j+1 with v = [x0, x2, …, | …, x3, x1]: from x[4j..4j+4] = (x0, x1, x2, x3),
                // w_j = (x0, x2) and w_(h−1−j) = (x3, x1); odd h has the middle w_(h/2) = (x_(n−2), x_(n−1)).
                for (x, w) in src.chunks_exact(n).zip(s.c1.chunks_exact_mut(h)) {
                    let m = h / 2;
                    let (lo, rest) = w.split_at_mut(m);
                    let (mid, hi) = rest.split_at_mut(h - 2 * m);
                    for ((c, a), b) in x.chunks_exact(4).zip(lo.iter_mut()).zip(hi.iter_mut().rev()) {
                        *a = C64::new(c[0], c[2]);
                        *b = C64::new(c[3], c[1]);
                    }
                    if let Some(c) = mid.first_mut() {
                        *c = C64::new(x[n - 2], x[n - 1]);
                    }
                }
                fwd.process_outofplace_with_scratch(&mut s.c1[..nb * h], &mut s.c2[..nb * h], &mut s.fft);
            }
            Kernel::Real { r2c, .. } => {
                for ((x, v), spec) in src.chunks_exact(n).zip(s.real.chunks_exact_mut(n)).zip(s.c1.chunks_exact_mut(h + 1)) {
                    // v = [x0, x2, …, x(n−1), …, x3, x1] (n odd).
                    let (lo, hi) = v.split_at_mut(n - h);
                    for ((a, b), pair) in lo.iter_mut().zip(hi.iter_mut().rev()).zip(x.chunks_exact(2)) {
                        *a = pair[0];
                        *b = pair[1];
                    }
                    lo[h] = x[n - 1];
                    r2c.process_with_scratch(v, spec, &mut s.fft).expect("DCT buffer lengths are fixed by the plan");
                }
            }
        }
    }

    /// Writes the coefficients of line `r` of the last [`Self::load_forward`] into `y` (length n).
    fn store_forward(&self, r: usize, y: &mut [f64], s: &LineScratch) {
        let n = self.n;
        let h = n / 2;
        let y = &mut y[..n];
        match &self.kernel {
            Kernel::Half { out_tw, fwd_tw, .. } => {
                let w = &s.c2[r * h..(r + 1) * h];
                let (v0, vh) = (w[0].re + w[0].im, w[0].re - w[0].im);
                y[0] = out_tw[0].re * v0;
                y[h] = out_tw[h].re * vh;
                let (lo, hi) = y.split_at_mut(h + 1);
                // k = 1 … h−1: V = (A + B)/2 − i ω^k (A − B)/2 with A = W_k, B = conj W_(h−k);
                // Y = σ e^{-iθ} V gives X_k = Re Y and X_(n−k) = −Im Y.
                let twiddles = out_tw[1..h].iter().zip(&fwd_tw[1..]);
                let pairs = w[1..].iter().zip(w[1..].iter().rev());
                for ((yk, ynk), ((a, b), (tw, ft))) in lo[1..].iter_mut().zip(hi.iter_mut().rev()).zip(pairs.zip(twiddles)) {
                    let (a, b) = (*a, b.conj());
                    let t = tw * ((a + b) * 0.5 + ft * (a - b));
                    *yk = t.re;
                    *ynk = -t.im;
                }
            }
            Kernel::Real { fwd, .. } => {
                let spec = &s.c1[r * (h + 1)..(r + 1) * (h + 1)];
                let (lo, hi) = y.split_at_mut(h + 1);
                for ((yk, w), v) in lo.iter_mut().zip(fwd).zip(spec) {
                    *yk = w[0] * v.re + w[1] * v.im;
                }
                for ((yk, w), v) in hi.iter_mut().zip(&fwd[h + 1..]).zip(spec[1..].iter().rev()) {
                    *yk = w[0] * v.re - w[1] * v.im;
                }
            }
        }
    }

    /// Twiddles (and optionally weights) the `src.len()/n ≤ BLOCK` coefficient lines and inverse-FFTs them.
    fn load_inverse(&self, src: &[f64], weight: Option<&[f64]>, s: &mut LineScratch) {
        let n = self.n;
        let nb = src.len() / n;
        let h = n / 2;
        match &self.kernel {
            Kernel::Half { inv, inv_tw, in_tw, .. } => {
                for r in 0..nb {
                    let x = &src[r * n..(r + 1) * n];
                    let v = &mut s.c2[r * (h + 1)..(r + 1) * (h + 1)];
                    // V_k = e^{iθ_k} (X_k − i X_(n−k)) / (σ_k h), k ≤ h; real at k = 0 (X_n = 0) and k = h.
                    let pairs = x[1..h].iter().zip(x[h + 1..].iter().rev());
                    match weight {
                        Some(g) => {
                            let g = &g[r * n..(r + 1) * n];
                            v[0] = C64::new(in_tw[0].re * (x[0] * g[0]), 0.0);
                            v[h] = C64::new(in_tw[h].re * (x[h] * g[h]), 0.0);
                            let gp = g[1..h].iter().zip(g[h + 1..].iter().rev());
                            for ((vk, tw), ((a, b), (ga, gb))) in v[1..h].iter_mut().zip(&in_tw[1..h]).zip(pairs.zip(gp)) {
                                *vk = tw * C64::new(a * ga, -(b * gb));
                            }
                        }
                        None => {
                            v[0] = C64::new(in_tw[0].re * x[0], 0.0);
                            v[h] = C64::new(in_tw[h].re * x[h], 0.0);
                            for ((vk, tw), (a, b)) in v[1..h].iter_mut().zip(&in_tw[1..h]).zip(pairs) {
                                *vk = tw * C64::new(*a, -*b);
                            }
                        }
                    }
                    // W_k = E_k + i O_k = (V_k + conj V_(h−k))/2 + i conj(ω^k) (V_k − conj V_(h−k))/2.
                    let w = &mut s.c1[r * h..(r + 1) * h];
                    for ((wk, it), (a, b)) in w.iter_mut().zip(inv_tw).zip(v[..h].iter().zip(v[1..].iter().rev())) {
                        let (a, b) = (*a, b.conj());
                        *wk = (a + b) * 0.5 + it * (a - b);
                    }
                }
                inv.process_outofplace_with_scratch(&mut s.c1[..nb * h], &mut s.c2[..nb * h], &mut s.fft);
            }
            Kernel::Real { c2r, inv, .. } => {
                for r in 0..nb {
                    let (x, spec) = (&mut s.real[r * n..(r + 1) * n], &mut s.c1[r * (h + 1)..(r + 1) * (h + 1)]);
                    match weight {
                        Some(g) => {
                            let g = &g[r * n..(r + 1) * n];
                            x.iter_mut().zip(&src[r * n..(r + 1) * n]).zip(g).for_each(|((x, a), b)| *x = a * b);
                        }
                        None => x.copy_from_slice(&src[r * n..(r + 1) * n]),
                    }
                    spec[0] = C64::new(inv[0][0] * x[0], 0.0);
                    for ((sk, g), (a, b)) in spec[1..].iter_mut().zip(&inv[1..]).zip(x[1..].iter().zip(x[1..].iter().rev())) {
                        *sk = C64::new(g[0] * a + g[1] * b, g[1] * a - g[0] * b);
                    }
                    c2r.process_with_scratch(spec, x, &mut s.fft).expect("DCT buffer lengths are fixed by the plan");
                }
            }
        }
    }

    /// Writes the samples of line `r` of the last [`Self::load_inverse`] into `x` (length n).
    fn store_inverse(&self, r: usize, x: &mut [f64], s: &LineScratch) {
        let n = self.n;
        let h = n / 2;
        let x = &mut x[..n];
        match &self.kernel {
            Kernel::Half { .. } => {
                // Inverse of the packing in `load_forward`.
                let w = &s.c2[r * h..(r + 1) * h];
                let m = h / 2;
                let (lo, rest) = w.split_at(m);
                let (mid, hi) = rest.split_at(h - 2 * m);
                for ((c, a), b) in x.chunks_exact_mut(4).zip(lo).zip(hi.iter().rev()) {
                    c[0] = a.re;
                    c[1] = b.im;
                    c[2] = a.im;
                    c[3] = b.re;
                }
                if let Some(c) = mid.first() {
                    x[n - 2] = c.re;
                    x[n - 1] = c.im;
                }
            }
            Kernel::Real { .. } => {
                // x_2q = v_q, x_2q+1 = v_(n−1−q), n odd.
                let v = &s.real[r * n..(r + 1) * n];
                let (lo, hi) = v.split_at(n - h);
                for ((pair, a), b) in x.chunks_exact_mut(2).zip(lo).zip(hi.iter().rev()) {
                    pair[0] = *a;
                    pair[1] = *b;
                }
                x[n - 1] = lo[h];
            }
        }
    }

    /// Transforms the rows (length n) of `src` into `dst`: row-major, or transposed (n × rows)
    /// through `block` (BLOCK × n).
    #[allow(clippy::too_many_arguments)]
    fn rows(
        &self,
        src: &[f64],
        weight: Option<&[f64]>,
        dst: &mut [f64],
        inverse: bool,
        transpose: bool,
        s: &mut LineScratch,
        block: &mut [f64],
    ) {
        let n = self.n;
        let rows = src.len() / n;
        for (b, lines) in src.chunks(BLOCK * n).enumerate() {
            let r0 = b * BLOCK;
            let nb = lines.len() / n;
            if inverse {
                self.load_inverse(lines, weight.map(|w| &w[r0 * n..(r0 + nb) * n]), s);
            } else {
                self.load_forward(lines, s);
            }
            let out: &mut [f64] = if transpose { block } else { &mut dst[r0 * n..(r0 + nb) * n] };
            for (r, line) in out.chunks_exact_mut(n).take(nb).enumerate() {
                if inverse {
                    self.store_inverse(r, line, s);
                } else {
                    self.store_forward(r, line, s);
                }
            }
            if transpose {
                for (k, d) in dst.chunks_exact_mut(rows).enumerate() {
                    for (r, o) in d[r0..r0 + nb].iter_mut().enumerate() {
                        *o = block[r * n + k];
                    }
                }
            }
        }
    }

    /// Transforms the rows of `data` in place.
    fn rows_in_place(&self, data: &mut [f64], inverse: bool, s: &mut LineScratch) {
        let n = self.n;
        for lines in data.chunks_mut(BLOCK * n) {
            if inverse {
                self.load_inverse(lines, None, s);
            } else {
                self.load_forward(lines, s);
            }
            for (r, line) in lines.chunks_exact_mut(n).enumerate() {
                if inverse {
                    self.store_inverse(r, line, s);
                } else {
                    self.store_forward(r, line, s);
                }
            }
        }
    }
}

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
    block: Vec<f64>,
    tmp: Vec<f64>,
}

impl DctNScratch {
    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.line.bytes() + (self.block.capacity() + self.tmp.capacity()) * 8
    }
}

impl DctN {
    /// Plans the transform of a row-major array of `shape` (last axis contiguous). Axes of
    /// length 1 are skipped (the DCT of one sample is the identity). Zero-length axes give an
    /// empty plan.
    pub fn new(shape: &[usize]) -> Self {
        let (mut complex, mut real) = (FftPlanner::new(), RealFftPlanner::new());
        let len = shape.iter().product();
        let axes: Vec<usize> = if len == 0 { Vec::new() } else { (0..shape.len()).filter(|&a| shape[a] > 1).collect() };
        let plans = axes.iter().map(|&a| Dct1d::with_planners(shape[a], &mut complex, &mut real)).collect();
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
        DctNScratch { line: LineScratch::new(max_n, fft), block: vec![0.0; BLOCK * max_n], tmp: vec![0.0; tmp_len] }
    }

    /// Forward orthonormal DCT-II of the spatial array `input` into `output` (spectral layout).
    ///
    /// # Panics
    /// If a slice length differs from [`Self::len`] or the scratch belongs to another plan.
    pub fn forward(&self, input: &[f64], output: &mut [f64], s: &mut DctNScratch) {
        assert!(input.len() == self.len && output.len() == self.len, "DctN::forward: wrong slice length");
        let k = self.plans.len();
        let DctNScratch { line, block, tmp } = s;
        if k == 0 {
            output.copy_from_slice(input);
            return;
        }
        if k == 1 {
            self.plans[0].rows(input, None, output, false, false, line, block);
            return;
        }
        // Step t transforms axis K-1-t (the current last axis) and rotates it to the front.
        for t in 0..k - 1 {
            let plan = &self.plans[k - 1 - t];
            let to_output = (k - 2 - t) & 1 == 0;
            match (t, to_output) {
                (0, true) => plan.rows(input, None, output, false, true, line, block),
                (0, false) => plan.rows(input, None, tmp, false, true, line, block),
                (_, true) => plan.rows(tmp, None, output, false, true, line, block),
                (_, false) => plan.rows(output, None, tmp, false, true, line, block),
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
        let k = self.plans.len();
        let DctNScratch { line, block, tmp } = s;
        match k {
            0 => {
                for (i, (o, x)) in output.iter_mut().zip(input).enumerate() {
                    *o = weight.map_or(*x, |w| w[i] * x);
                }
            }
            1 => self.plans[0].rows(input, weight, output, true, false, line, block),
            2 => {
                // Layout (a1, a0): invert along a0 writing (a0, a1), then along a1.
                self.plans[0].rows(input, weight, output, true, true, line, block);
                self.plans[1].rows_in_place(output, true, line);
            }
            _ => {
                // Layout rotL^(t+1)(a): invert the last axis a_t, then move the first axis to the end.
                for t in 0..k - 1 {
                    let plan = &self.plans[t];
                    if t == 0 {
                        plan.rows(input, weight, tmp, true, false, line, block);
                    } else {
                        plan.rows(output, None, tmp, true, false, line, block);
                    }
                    let first = self.plans[t + 1].len();
                    transpose(tmp, output, first, self.len / first);
                }
                self.plans[k - 1].rows_in_place(output, true, line);
            }
        }
    }
}

/// Cache-blocked transpose of `src` (rows × cols, row-major) into `dst` (cols × rows).
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

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

    #[test]
    fn spectral_axes_rotate_the_non_singleton_axes() {
        assert_eq!(DctN::new(&[4, 5]).spectral_axes(), vec![1, 0]);
        assert_eq!(DctN::new(&[2, 1, 3, 4]).spectral_axes(), vec![2, 3, 0]);
        assert_eq!(DctN::new(&[1, 6]).spectral_axes(), vec![1]);
        assert!(DctN::new(&[1, 1]).spectral_axes().is_empty());
    }
}
