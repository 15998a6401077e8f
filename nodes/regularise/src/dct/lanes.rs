//! Batched complex FFT of four lines of a power-of-two length with AVX-512, the lines as the lanes
//! of each vector: a 512-bit register holds element j of all four lines (four complex f64), so
//! every butterfly and twiddle is the same for its four lanes and the transform needs no
//! shuffles inside a line. RustFFT has no AVX-512 code and transforms one line at a time with
//! 256-bit shuffles; with this kernel a 2-D DCT of 64² or 128² takes 22–25 % less time on a Zen 5
//! host, 256² and 512² 3–14 % less (`dct_timing`, BENCHMARKS.md §11). From 1024 on its two work
//! vectors per element outgrow the L1 cache (a micro-benchmark had it slower than RustFFT at 1024
//! and 2048), so [`LanesFft::new`] plans only 16 ≤ n ≤ 512. Everything else stays with RustFFT,
//! which is also the reference of the tests (agreement to rounding; the two sum in different
//! orders).
//!
//! Algorithm: Stockham autosort, radix 4 (decimation in frequency; OTFFT's formulation), the
//! last stage radix 8 when log₂ n is odd (its even and odd outputs in turn). The first stage reads
//! the line-major input and the last one writes the line-major output through 4 × 4 transposes of
//! 128-bit blocks; the stages in between ping-pong between two element-major buffers (2n vectors,
//! L1-resident up to n = 256).
//! Unnormalised like RustFFT: forward `X_k = Σ x_j e^{−2πijk/n}`, inverse with `e^{+2πijk/n}`.

use std::arch::x86_64::*;

use super::C64;

/// Smallest and largest lengths planned (both powers of two).
pub(super) const MIN_LEN: usize = 16;
pub(super) const MAX_LEN: usize = 512;

/// AVX-512F available (cached by the standard library).
#[inline]
pub(super) fn available() -> bool {
    std::arch::is_x86_feature_detected!("avx512f")
}

/// f64 of work space [`LanesFft::process4`] needs for length `n` (2n vectors, plus room to align
/// them to 64 bytes).
pub(super) fn work_len(n: usize) -> usize {
    16 * n + 8
}

/// A planned transform of one length and direction.
pub(super) struct LanesFft {
    n: usize,
    inverse: bool,
    /// Per radix-4 stage (transform length m = n, n/4, … while m ≥ 16, then m = 4 when log₂ n is
    /// even), for p < m/4: `[cos, sin]` of `∓2π k p / m`, k = 1, 2, 3.
    twiddles: Vec<Vec<[f64; 6]>>,
}

impl LanesFft {
    /// Plans length `n` (a power of two in [`MIN_LEN`] ..= [`MAX_LEN`]) where the CPU has
    /// AVX-512F; `None` otherwise (use RustFFT).
    pub(super) fn new(n: usize, inverse: bool) -> Option<Self> {
        if !(n.is_power_of_two() && (MIN_LEN..=MAX_LEN).contains(&n) && available()) {
            return None;
        }
        let sign = if inverse { 1.0 } else { -1.0 };
        let mut twiddles = Vec::new();
        let mut m = n;
        while m >= 4 && m != 8 {
            twiddles.push(
                (0..m / 4)
                    .map(|p| {
                        let mut t = [0.0; 6];
                        for k in 1..=3 {
                            let (s, c) = (sign * std::f64::consts::TAU * (k * p) as f64 / m as f64).sin_cos();
                            (t[2 * k - 2], t[2 * k - 1]) = (c, s);
                        }
                        t
                    })
                    .collect(),
            );
            m /= 4;
        }
        Some(Self { n, inverse, twiddles })
    }

    /// Transforms the four lines of `input` (line-major, 4n complex) into `output` (the same
    /// layout); `work` holds at least [`work_len`] f64.
    pub(super) fn process4(&self, input: &[C64], output: &mut [C64], work: &mut [f64]) {
        let n = self.n;
        assert!(input.len() >= 4 * n && output.len() >= 4 * n && work.len() >= work_len(n));
        // A 64-byte aligned start inside `work` where possible (a Vec<f64> is 8-byte aligned; the
        // loads and stores are unaligned ones, so this is for speed only).
        let skip = work.as_ptr().align_offset(64).min(7);
        let work = &mut work[skip..skip + 16 * n];
        // SAFETY: planned only where AVX-512F is available (`new`); lengths asserted above.
        unsafe {
            if self.inverse {
                self.run::<true>(input, output, work);
            } else {
                self.run::<false>(input, output, work);
            }
        }
    }

    /// # Safety
    /// The CPU must support AVX-512F; `input`, `output` hold 4n complex, `work` 16n f64.
    #[target_feature(enable = "avx512f")]
    #[allow(clippy::needless_range_loop)] // lane and stage indices, as in the equations
    unsafe fn run<const INV: bool>(&self, input: &[C64], output: &mut [C64], work: &mut [f64]) {
        let n = self.n;
        // SAFETY: every index below is < n for a line (4 lines of n complex = 8n f64 in `input`
        // and `output`) and < n vectors per half of `work` (16n f64 = 2n vectors), as the stage
        // loops show: stage 1 reads elements p … p + 3n/4 + 3 < n, the middle stages index
        // q + s·(p + 3n0) < s·4n0 = n and q + s(4p + 3) < n, the last stage q + 7s < 8s = n.
        unsafe {
            let ip = input.as_ptr().cast::<f64>();
            let op = output.as_mut_ptr().cast::<f64>();
            let (lo, hi) = work.split_at_mut(8 * n);
            let (mut x, mut y) = (lo.as_mut_ptr().cast::<__m512d>(), hi.as_mut_ptr().cast::<__m512d>());
            // Stage 1 (m = n, stride 1) from the line-major input, four p at a time. (No closures
            // in this function: they would not inherit its target feature where not inlined.)
            let n0 = n / 4;
            let tw = self.twiddles[0].as_ptr().cast::<f64>();
            for p in (0..n0).step_by(4) {
                let mut v = [[_mm512_setzero_pd(); 4]; 4];
                for (k, v) in v.iter_mut().enumerate() {
                    let e = p + k * n0;
                    *v = transpose4(
                        _mm512_loadu_pd(ip.add(2 * e)),
                        _mm512_loadu_pd(ip.add(2 * (n + e))),
                        _mm512_loadu_pd(ip.add(2 * (2 * n + e))),
                        _mm512_loadu_pd(ip.add(2 * (3 * n + e))),
                    );
                }
                for i in 0..4 {
                    let r = butterfly4::<INV>(v[0][i], v[1][i], v[2][i], v[3][i]);
                    let (t, o) = (tw.add(6 * (p + i)), y.add(4 * (p + i)));
                    _mm512_storeu_pd(o.cast(), r[0]);
                    _mm512_storeu_pd(o.add(1).cast(), twiddle(r[1], t));
                    _mm512_storeu_pd(o.add(2).cast(), twiddle(r[2], t.add(2)));
                    _mm512_storeu_pd(o.add(3).cast(), twiddle(r[3], t.add(4)));
                }
            }
            std::mem::swap(&mut x, &mut y);
            let (mut m, mut s) = (n / 4, 4);
            // Middle radix-4 stages while m ≥ 16 (stride s = n/m ≥ 4, four q per step).
            for tw in &self.twiddles[1..] {
                if m < 16 {
                    break;
                }
                let n0 = m / 4;
                for p in 0..n0 {
                    let t = tw[p].as_ptr();
                    let (xp, yp) = (x.add(s * p), y.add(4 * s * p));
                    for q in (0..s).step_by(4) {
                        for u in q..q + 4 {
                            let g = xp.add(u);
                            let r = butterfly4::<INV>(
                                _mm512_loadu_pd(g.cast()),
                                _mm512_loadu_pd(g.add(s * n0).cast()),
                                _mm512_loadu_pd(g.add(2 * s * n0).cast()),
                                _mm512_loadu_pd(g.add(3 * s * n0).cast()),
                            );
                            let o = yp.add(u);
                            _mm512_storeu_pd(o.cast(), r[0]);
                            if p == 0 {
                                _mm512_storeu_pd(o.add(s).cast(), r[1]);
                                _mm512_storeu_pd(o.add(2 * s).cast(), r[2]);
                                _mm512_storeu_pd(o.add(3 * s).cast(), r[3]);
                            } else {
                                _mm512_storeu_pd(o.add(s).cast(), twiddle(r[1], t));
                                _mm512_storeu_pd(o.add(2 * s).cast(), twiddle(r[2], t.add(2)));
                                _mm512_storeu_pd(o.add(3 * s).cast(), twiddle(r[3], t.add(4)));
                            }
                        }
                    }
                }
                std::mem::swap(&mut x, &mut y);
                m /= 4;
                s *= 4;
            }
            // Last stage (one group, no outer twiddles) into the line-major output, four q at a
            // time: r[k][u] is output k of q + u.
            if m == 4 {
                for q in (0..s).step_by(4) {
                    let mut r = [[_mm512_setzero_pd(); 4]; 4];
                    for u in 0..4 {
                        let g = x.add(q + u);
                        let b = butterfly4::<INV>(
                            _mm512_loadu_pd(g.cast()),
                            _mm512_loadu_pd(g.add(s).cast()),
                            _mm512_loadu_pd(g.add(2 * s).cast()),
                            _mm512_loadu_pd(g.add(3 * s).cast()),
                        );
                        for k in 0..4 {
                            r[k][u] = b[k];
                        }
                    }
                    for (k, r) in r.iter().enumerate() {
                        let t = transpose4(r[0], r[1], r[2], r[3]);
                        for (l, t) in t.into_iter().enumerate() {
                            _mm512_storeu_pd(op.add(2 * (l * n + q + k * s)), t);
                        }
                    }
                }
            } else {
                // Radix 8 as its even outputs (a radix-4 butterfly of x_k + x_(k+4)) and then its
                // odd ones (of (x_k − x_(k+4)) w8^k), so that 16 results, not 32, wait for the
                // transposes (32 would not fit in the registers).
                for q in (0..s).step_by(4) {
                    for odd in [false, true] {
                        let mut r = [[_mm512_setzero_pd(); 4]; 4];
                        for u in 0..4 {
                            let g = x.add(q + u);
                            let mut v = [_mm512_setzero_pd(); 4];
                            for (k, v) in v.iter_mut().enumerate() {
                                let (a, b) =
                                    (_mm512_loadu_pd(g.add(k * s).cast()), _mm512_loadu_pd(g.add((k + 4) * s).cast()));
                                *v = if odd { _mm512_sub_pd(a, b) } else { _mm512_add_pd(a, b) };
                            }
                            if odd {
                                v = radix8_twiddles::<INV>(v);
                            }
                            let b = butterfly4::<INV>(v[0], v[1], v[2], v[3]);
                            for k in 0..4 {
                                r[k][u] = b[k];
                            }
                        }
                        for (k, r) in r.iter().enumerate() {
                            let t = transpose4(r[0], r[1], r[2], r[3]);
                            let k = 2 * k + usize::from(odd);
                            for (l, t) in t.into_iter().enumerate() {
                                _mm512_storeu_pd(op.add(2 * (l * n + q + k * s)), t);
                            }
                        }
                    }
                }
            }
        }
    }
}

/// `v · (c + i s)` for the four complex lanes of `v`, `t = [c, s]`.
///
/// # Safety
/// The CPU must support AVX-512F; `t` points to two readable f64.
#[inline]
#[target_feature(enable = "avx512f")]
unsafe fn twiddle(v: __m512d, t: *const f64) -> __m512d {
    // SAFETY: the caller guarantees AVX-512F and two readable f64 at t.
    unsafe {
        let swapped = _mm512_permute_pd::<0x55>(v);
        _mm512_fmaddsub_pd(v, _mm512_set1_pd(*t), _mm512_mul_pd(swapped, _mm512_set1_pd(*t.add(1))))
    }
}

/// `a ∓ i b` (`MINUS`) for four complex lanes, exactly (`a·1 ∓ swap(b)` in one rounding).
///
/// # Safety
/// The CPU must support AVX-512F.
#[inline]
#[target_feature(enable = "avx512f")]
unsafe fn add_i<const MINUS: bool>(a: __m512d, b: __m512d) -> __m512d {
    let (one, swapped) = (_mm512_set1_pd(1.0), _mm512_permute_pd::<0x55>(b));
    // a − i b = (a.re + b.im, a.im − b.re): even lanes add, odd lanes subtract (fmsubadd).
    if MINUS {
        _mm512_fmsubadd_pd(a, one, swapped)
    } else {
        _mm512_fmaddsub_pd(a, one, swapped)
    }
}

/// Radix-4 butterfly `[Σ x_k w^{kr}]_{r=0..3}` with `w = ∓i` (forward / inverse).
///
/// # Safety
/// The CPU must support AVX-512F.
#[inline]
#[target_feature(enable = "avx512f")]
unsafe fn butterfly4<const INV: bool>(a: __m512d, b: __m512d, c: __m512d, d: __m512d) -> [__m512d; 4] {
    let (apc, amc) = (_mm512_add_pd(a, c), _mm512_sub_pd(a, c));
    let (bpd, bmd) = (_mm512_add_pd(b, d), _mm512_sub_pd(b, d));
    // SAFETY: the caller guarantees AVX-512F.
    let (minus, plus) = unsafe { (add_i::<true>(amc, bmd), add_i::<false>(amc, bmd)) };
    let (r1, r3) = if INV { (plus, minus) } else { (minus, plus) };
    [_mm512_add_pd(apc, bpd), r1, _mm512_sub_pd(apc, bpd), r3]
}

/// The twiddles `w8^k` (w8 = e^{∓iπ/4}, forward / inverse) of a radix-8 butterfly's odd half:
/// `d_k w8^k` for the differences `d_k = x_k − x_(k+4)`, k = 0 … 3 (its radix-2 step).
///
/// # Safety
/// The CPU must support AVX-512F.
#[inline]
#[target_feature(enable = "avx512f")]
unsafe fn radix8_twiddles<const INV: bool>(d: [__m512d; 4]) -> [__m512d; 4] {
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let (w1, w3) = if INV { ([h, h], [-h, h]) } else { ([h, -h], [-h, -h]) };
    // SAFETY: the caller guarantees AVX-512F; w1, w3 hold two f64.
    unsafe {
        let zero = _mm512_setzero_pd();
        [
            d[0],
            twiddle(d[1], w1.as_ptr()),
            if INV { add_i::<false>(zero, d[2]) } else { add_i::<true>(zero, d[2]) },
            twiddle(d[3], w3.as_ptr()),
        ]
    }
}

/// Transposes four vectors of four complex numbers (row l, element e → row e, element l).
///
/// # Safety
/// The CPU must support AVX-512F.
#[inline]
#[target_feature(enable = "avx512f")]
unsafe fn transpose4(r0: __m512d, r1: __m512d, r2: __m512d, r3: __m512d) -> [__m512d; 4] {
    let (t0, t1) = (_mm512_shuffle_f64x2::<0x44>(r0, r1), _mm512_shuffle_f64x2::<0xEE>(r0, r1));
    let (t2, t3) = (_mm512_shuffle_f64x2::<0x44>(r2, r3), _mm512_shuffle_f64x2::<0xEE>(r2, r3));
    [
        _mm512_shuffle_f64x2::<0x88>(t0, t2),
        _mm512_shuffle_f64x2::<0xDD>(t0, t2),
        _mm512_shuffle_f64x2::<0x88>(t1, t3),
        _mm512_shuffle_f64x2::<0xDD>(t1, t3),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use rustfft::FftPlanner;

    /// Every planned length, both directions, agrees with RustFFT to rounding: the largest
    /// difference ≤ 4e-15 of the largest output (both are O(ε log₂ n) accurate; measured ≤ 3.2e-16
    /// of it on a Zen 5 host up to n = 512, so the bound leaves ~12× room).
    #[test]
    fn lanes_fft_matches_rustfft() {
        if !available() {
            eprintln!("no AVX-512F on this CPU: the lanes FFT is not used here, nothing to compare");
            return;
        }
        assert!(LanesFft::new(8, false).is_none() && LanesFft::new(1024, false).is_none());
        assert!(LanesFft::new(96, false).is_none());
        let mut planner = FftPlanner::<f64>::new();
        let mut n = MIN_LEN;
        while n <= MAX_LEN {
            for inverse in [false, true] {
                let input: Vec<C64> = (0..4 * n)
                    .map(|i| C64::new((i as f64 * 0.37).sin() + (i % 5) as f64, (i as f64 * 1.13).cos()))
                    .collect();
                let reference = if inverse { planner.plan_fft_inverse(n) } else { planner.plan_fft_forward(n) };
                let mut expected = input.clone();
                for line in expected.chunks_exact_mut(n) {
                    reference.process(line);
                }
                let plan = LanesFft::new(n, inverse).expect("planned");
                let mut got = vec![C64::default(); 4 * n];
                let mut work = vec![f64::NAN; work_len(n)];
                plan.process4(&input, &mut got, &mut work);
                let scale = expected.iter().map(|c| c.norm()).fold(0.0, f64::max);
                let err = expected.iter().zip(&got).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
                assert!(err <= 4e-15 * scale, "n = {n}, inverse = {inverse}: {err:e} of {scale:e}");
            }
            n *= 2;
        }
    }
}
