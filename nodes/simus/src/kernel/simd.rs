//! 16-lane f32 vectors for the fast kernel, in three builds chosen at run time — AVX-512 + FMA,
//! AVX2 + FMA, and a portable array version without FMA (the scalar twin the tests compare
//! against) — so no `target-cpu=native` is needed at build time.

// Lane loops index several arrays in lockstep: plain index loops keep them vectorisable.
#![allow(clippy::needless_range_loop)]

use std::ops::Range;

use crate::kernel::{accumulate, Scratch, Tables, L, V};
use crate::params::KernelChoice;
use crate::pfield::{ArrayGeom, BlockGeom, ScattererGeom};

/// The lane-wise operations of the phasor and receive passes, which also run on half vectors.
pub(crate) trait Ops: Copy {
    fn zero() -> Self;
    fn splat(x: f32) -> Self;
    fn load(v: &V) -> Self;
    fn store(self, v: &mut V);
    fn add(self, b: Self) -> Self;
    fn mul(self, b: Self) -> Self;
    fn mul_add(self, b: Self, c: Self) -> Self;
    fn neg_mul_add(self, b: Self, c: Self) -> Self;
}

impl<T: Lanes> Ops for T {
    #[inline(always)]
    fn zero() -> Self {
        Lanes::zero()
    }
    #[inline(always)]
    fn splat(x: f32) -> Self {
        Lanes::splat(x)
    }
    #[inline(always)]
    fn load(v: &V) -> Self {
        Lanes::load(v)
    }
    #[inline(always)]
    fn store(self, v: &mut V) {
        Lanes::store(self, v)
    }
    #[inline(always)]
    fn add(self, b: Self) -> Self {
        Lanes::add(self, b)
    }
    #[inline(always)]
    fn mul(self, b: Self) -> Self {
        Lanes::mul(self, b)
    }
    #[inline(always)]
    fn mul_add(self, b: Self, c: Self) -> Self {
        Lanes::mul_add(self, b, c)
    }
    #[inline(always)]
    fn neg_mul_add(self, b: Self, c: Self) -> Self {
        Lanes::neg_mul_add(self, b, c)
    }
}

/// The vector operations the kernel needs. `mul_add(a, b, c) = a·b + c`,
/// `neg_mul_add(a, b, c) = c − a·b` (fused where the build has FMA).
pub(crate) trait Lanes: Copy {
    /// 32 architectural vector registers of this width (AVX-512): the kernel may keep more
    /// state in registers.
    const WIDE: bool = false;
    /// One vector is two registers and the build has 16 of them (AVX2): pass 1 runs on each
    /// half in turn ([`Lanes::Lo`], [`Lanes::Hi`]), so that a chunk's phasor state stays in
    /// registers. The same lane operations in the same order, so the same bits.
    const SPLIT: bool = false;
    /// Where [`Lanes::SPLIT`]: lanes 0–7 (otherwise `Self`, unused).
    type Lo: Ops;
    /// Where [`Lanes::SPLIT`]: lanes 8–15 (otherwise `Self`, unused).
    type Hi: Ops;
    /// The vector of two halves; called only where [`Lanes::SPLIT`].
    fn join(lo: Self::Lo, hi: Self::Hi) -> Self;
    fn zero() -> Self;
    fn splat(x: f32) -> Self;
    fn load(v: &V) -> Self;
    fn store(self, v: &mut V);
    fn add(self, b: Self) -> Self;
    fn sub(self, b: Self) -> Self;
    fn mul(self, b: Self) -> Self;
    fn div(self, b: Self) -> Self;
    fn mul_add(self, b: Self, c: Self) -> Self;
    fn neg_mul_add(self, b: Self, c: Self) -> Self;
    /// Sum of the 16 lanes in a fixed order (pairwise tree).
    fn hsum(self) -> f32;
    /// The lane sums of 8 vectors, each multiplied by `scale`, in a fixed order.
    #[inline(always)]
    fn hsum8(v: [Self; 8], scale: f32) -> [f32; 8] {
        v.map(|x| x.hsum() * scale)
    }
    /// Lane-wise maximum.
    fn max(self, b: Self) -> Self;
    /// `self · 2^n` for integral `n` in [−126, 127].
    fn scalef(self, n: Self) -> Self;
    /// `t − round(t)` with `t = r[l]·s` evaluated in f64, rounded to f32 (16 entries of `r`).
    fn frac_turns(r: &[f64], s: f64) -> Self;
    /// `r[l]·s` evaluated in f64, rounded to f32 (16 entries of `r`).
    fn scaled(r: &[f64], s: f64) -> Self;
}

/// Portable f64 helpers shared by the builds.
#[inline(always)]
fn frac_turns_f64(t: f64) -> f32 {
    const MAGIC64: f64 = 6_755_399_441_055_744.0;
    (t - ((t + MAGIC64) - MAGIC64)) as f32
}

/// Portable build: plain arrays, separate multiply and add.
#[derive(Clone, Copy)]
pub(crate) struct Portable([f32; L]);

impl Portable {
    #[inline(always)]
    fn map2(self, b: Self, f: impl Fn(f32, f32) -> f32) -> Self {
        let mut o = [0f32; L];
        for l in 0..L {
            o[l] = f(self.0[l], b.0[l]);
        }
        Portable(o)
    }
}

impl Lanes for Portable {
    type Lo = Self;
    type Hi = Self;
    #[inline(always)]
    fn join(_: Self, _: Self) -> Self {
        unreachable!("Lanes::join is called only where SPLIT")
    }
    #[inline(always)]
    fn zero() -> Self {
        Portable([0.0; L])
    }
    #[inline(always)]
    fn splat(x: f32) -> Self {
        Portable([x; L])
    }
    #[inline(always)]
    fn load(v: &V) -> Self {
        Portable(v.0)
    }
    #[inline(always)]
    fn store(self, v: &mut V) {
        v.0 = self.0;
    }
    #[inline(always)]
    fn add(self, b: Self) -> Self {
        self.map2(b, |x, y| x + y)
    }
    #[inline(always)]
    fn sub(self, b: Self) -> Self {
        self.map2(b, |x, y| x - y)
    }
    #[inline(always)]
    fn mul(self, b: Self) -> Self {
        self.map2(b, |x, y| x * y)
    }
    #[inline(always)]
    fn div(self, b: Self) -> Self {
        self.map2(b, |x, y| x / y)
    }
    #[inline(always)]
    fn mul_add(self, b: Self, c: Self) -> Self {
        let mut o = [0f32; L];
        for l in 0..L {
            o[l] = self.0[l] * b.0[l] + c.0[l];
        }
        Portable(o)
    }
    #[inline(always)]
    fn neg_mul_add(self, b: Self, c: Self) -> Self {
        let mut o = [0f32; L];
        for l in 0..L {
            o[l] = c.0[l] - self.0[l] * b.0[l];
        }
        Portable(o)
    }
    #[inline(always)]
    fn hsum(self) -> f32 {
        let v = self.0;
        let mut a = [0f32; 8];
        for i in 0..8 {
            a[i] = v[i] + v[i + 8];
        }
        let b = [a[0] + a[4], a[1] + a[5], a[2] + a[6], a[3] + a[7]];
        let c = [b[0] + b[2], b[1] + b[3]];
        c[0] + c[1]
    }
    #[inline(always)]
    fn max(self, b: Self) -> Self {
        self.map2(b, f32::max)
    }
    #[inline(always)]
    fn scalef(self, n: Self) -> Self {
        self.map2(n, |x, n| x * f32::from_bits((((n as i32) + 127) as u32) << 23))
    }
    #[inline(always)]
    fn frac_turns(r: &[f64], s: f64) -> Self {
        let mut o = [0f32; L];
        for l in 0..L {
            o[l] = frac_turns_f64(r[l] * s);
        }
        Portable(o)
    }
    #[inline(always)]
    fn scaled(r: &[f64], s: f64) -> Self {
        let mut o = [0f32; L];
        for l in 0..L {
            o[l] = (r[l] * s) as f32;
        }
        Portable(o)
    }
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::*;
    use std::arch::x86_64::*;

    /// AVX-512 build: one `__m512`.
    #[derive(Clone, Copy)]
    pub(crate) struct Avx512(__m512);

    // SAFETY (every `unsafe` block below): these methods are only reached through
    // `Simd::accumulate` after run-time detection of AVX-512F/VL/DQ/BW and FMA, and are inlined
    // into functions compiled with those features; `V` is 64-byte aligned with 16 f32.
    impl Lanes for Avx512 {
        const WIDE: bool = true;
        type Lo = Self;
        type Hi = Self;
        #[inline(always)]
        fn join(_: Self, _: Self) -> Self {
            unreachable!("Lanes::join is called only where SPLIT")
        }
        #[inline(always)]
        fn zero() -> Self {
            Avx512(unsafe { _mm512_setzero_ps() })
        }
        #[inline(always)]
        fn splat(x: f32) -> Self {
            Avx512(unsafe { _mm512_set1_ps(x) })
        }
        #[inline(always)]
        fn load(v: &V) -> Self {
            Avx512(unsafe { _mm512_load_ps(v.0.as_ptr()) })
        }
        #[inline(always)]
        fn store(self, v: &mut V) {
            unsafe { _mm512_store_ps(v.0.as_mut_ptr(), self.0) }
        }
        #[inline(always)]
        fn add(self, b: Self) -> Self {
            Avx512(unsafe { _mm512_add_ps(self.0, b.0) })
        }
        #[inline(always)]
        fn sub(self, b: Self) -> Self {
            Avx512(unsafe { _mm512_sub_ps(self.0, b.0) })
        }
        #[inline(always)]
        fn mul(self, b: Self) -> Self {
            Avx512(unsafe { _mm512_mul_ps(self.0, b.0) })
        }
        #[inline(always)]
        fn div(self, b: Self) -> Self {
            Avx512(unsafe { _mm512_div_ps(self.0, b.0) })
        }
        #[inline(always)]
        fn mul_add(self, b: Self, c: Self) -> Self {
            Avx512(unsafe { _mm512_fmadd_ps(self.0, b.0, c.0) })
        }
        #[inline(always)]
        fn neg_mul_add(self, b: Self, c: Self) -> Self {
            Avx512(unsafe { _mm512_fnmadd_ps(self.0, b.0, c.0) })
        }
        #[inline(always)]
        fn hsum(self) -> f32 {
            unsafe {
                let lo = _mm512_castps512_ps256(self.0);
                let hi = _mm512_extractf32x8_ps::<1>(self.0);
                let a = _mm256_add_ps(lo, hi); // lanes i + i+8
                let b = _mm_add_ps(_mm256_castps256_ps128(a), _mm256_extractf128_ps::<1>(a)); // + i+4
                let c = _mm_add_ps(b, _mm_movehl_ps(b, b)); // [b0+b2, b1+b3]
                let d = _mm_add_ss(c, _mm_shuffle_ps::<1>(c, c));
                _mm_cvtss_f32(d)
            }
        }
        #[inline(always)]
        fn max(self, b: Self) -> Self {
            Avx512(unsafe { _mm512_max_ps(self.0, b.0) })
        }
        /// Transposing reduction tree: 8 adds + 15 shuffles for 8 sums (vs 8 × 8 ops).
        #[inline(always)]
        fn hsum8(v: [Self; 8], scale: f32) -> [f32; 8] {
            unsafe {
                // 512 -> 256: [a.lo + a.hi | b.lo + b.hi]
                let pair = |a: __m512, b: __m512| {
                    let lo = _mm512_shuffle_f32x4::<0b01_00_01_00>(a, b);
                    let hi = _mm512_shuffle_f32x4::<0b11_10_11_10>(a, b);
                    _mm512_add_ps(lo, hi)
                };
                let u01 = pair(v[0].0, v[1].0);
                let u23 = pair(v[2].0, v[3].0);
                let u45 = pair(v[4].0, v[5].0);
                let u67 = pair(v[6].0, v[7].0);
                // 256 -> 128: [a | b | c | d], 4 partial lanes each
                let quad = |a: __m512, b: __m512| {
                    let lo = _mm512_shuffle_f32x4::<0b10_00_10_00>(a, b);
                    let hi = _mm512_shuffle_f32x4::<0b11_01_11_01>(a, b);
                    _mm512_add_ps(lo, hi)
                };
                let w0 = quad(u01, u23); // 128-bit lane j: partial sums of v[j]
                let w1 = quad(u45, u67); // 128-bit lane j: partial sums of v[4 + j]
                                         // 128 -> 64: in each 128-bit lane [w0.0 + w0.2, w0.1 + w0.3, w1.0 + w1.2, w1.1 + w1.3]
                let lo = _mm512_shuffle_ps::<0b01_00_01_00>(w0, w1);
                let hi = _mm512_shuffle_ps::<0b11_10_11_10>(w0, w1);
                let x = _mm512_add_ps(lo, hi);
                // 64 -> 32: positions 0 and 2 of each 128-bit lane hold the sums
                let y = _mm512_add_ps(x, _mm512_shuffle_ps::<0b10_11_00_01>(x, x));
                let y = _mm512_mul_ps(y, _mm512_set1_ps(scale));
                let mut out = [0f32; 16];
                _mm512_storeu_ps(out.as_mut_ptr(), y);
                [out[0], out[4], out[8], out[12], out[2], out[6], out[10], out[14]]
            }
        }
        #[inline(always)]
        fn scalef(self, n: Self) -> Self {
            Avx512(unsafe { _mm512_scalef_ps(self.0, n.0) })
        }
        #[inline(always)]
        fn frac_turns(r: &[f64], s: f64) -> Self {
            assert!(r.len() >= L);
            unsafe {
                let sv = _mm512_set1_pd(s);
                let half = |p: *const f64| {
                    let t = _mm512_mul_pd(_mm512_loadu_pd(p), sv);
                    let q = _mm512_roundscale_pd::<{ _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC }>(t);
                    _mm512_cvtpd_ps(_mm512_sub_pd(t, q))
                };
                let lo = half(r.as_ptr());
                let hi = half(r.as_ptr().add(8));
                Avx512(_mm512_insertf32x8::<1>(_mm512_castps256_ps512(lo), hi))
            }
        }
        #[inline(always)]
        fn scaled(r: &[f64], s: f64) -> Self {
            assert!(r.len() >= L);
            unsafe {
                let sv = _mm512_set1_pd(s);
                let lo = _mm512_cvtpd_ps(_mm512_mul_pd(_mm512_loadu_pd(r.as_ptr()), sv));
                let hi = _mm512_cvtpd_ps(_mm512_mul_pd(_mm512_loadu_pd(r.as_ptr().add(8)), sv));
                Avx512(_mm512_insertf32x8::<1>(_mm512_castps256_ps512(lo), hi))
            }
        }
    }

    /// AVX2 build: two `__m256`.
    #[derive(Clone, Copy)]
    pub(crate) struct Avx2(__m256, __m256);

    /// Half `H` ∈ {0, 1} (lanes 8H … 8H + 7) of an [`Avx2`] vector: loads and stores that half
    /// of a `V` (any other `H` fails to compile).
    #[derive(Clone, Copy)]
    pub(crate) struct Avx2Half<const H: usize>(__m256);

    // SAFETY: as for `Avx2` (reached only from the AVX2 + FMA build); `V` is 64-byte aligned
    // with 16 f32, so for H ≤ 1 (asserted at compile time) each half is inside it and 32-byte
    // aligned.
    impl<const H: usize> Ops for Avx2Half<H> {
        #[inline(always)]
        fn zero() -> Self {
            Avx2Half(unsafe { _mm256_setzero_ps() })
        }
        #[inline(always)]
        fn splat(x: f32) -> Self {
            Avx2Half(unsafe { _mm256_set1_ps(x) })
        }
        #[inline(always)]
        fn load(v: &V) -> Self {
            const { assert!(H < 2) };
            Avx2Half(unsafe { _mm256_load_ps(v.0.as_ptr().add(8 * H)) })
        }
        #[inline(always)]
        fn store(self, v: &mut V) {
            const { assert!(H < 2) };
            unsafe { _mm256_store_ps(v.0.as_mut_ptr().add(8 * H), self.0) }
        }
        #[inline(always)]
        fn add(self, b: Self) -> Self {
            Avx2Half(unsafe { _mm256_add_ps(self.0, b.0) })
        }
        #[inline(always)]
        fn mul(self, b: Self) -> Self {
            Avx2Half(unsafe { _mm256_mul_ps(self.0, b.0) })
        }
        #[inline(always)]
        fn mul_add(self, b: Self, c: Self) -> Self {
            Avx2Half(unsafe { _mm256_fmadd_ps(self.0, b.0, c.0) })
        }
        #[inline(always)]
        fn neg_mul_add(self, b: Self, c: Self) -> Self {
            Avx2Half(unsafe { _mm256_fnmadd_ps(self.0, b.0, c.0) })
        }
    }

    // SAFETY: as for `Avx512`, with AVX2 and FMA detected.
    impl Lanes for Avx2 {
        const SPLIT: bool = true;
        type Lo = Avx2Half<0>;
        type Hi = Avx2Half<1>;
        #[inline(always)]
        fn join(lo: Avx2Half<0>, hi: Avx2Half<1>) -> Self {
            Avx2(lo.0, hi.0)
        }
        #[inline(always)]
        fn zero() -> Self {
            unsafe { Avx2(_mm256_setzero_ps(), _mm256_setzero_ps()) }
        }
        #[inline(always)]
        fn splat(x: f32) -> Self {
            unsafe { Avx2(_mm256_set1_ps(x), _mm256_set1_ps(x)) }
        }
        #[inline(always)]
        fn load(v: &V) -> Self {
            unsafe { Avx2(_mm256_load_ps(v.0.as_ptr()), _mm256_load_ps(v.0.as_ptr().add(8))) }
        }
        #[inline(always)]
        fn store(self, v: &mut V) {
            unsafe {
                _mm256_store_ps(v.0.as_mut_ptr(), self.0);
                _mm256_store_ps(v.0.as_mut_ptr().add(8), self.1);
            }
        }
        #[inline(always)]
        fn add(self, b: Self) -> Self {
            unsafe { Avx2(_mm256_add_ps(self.0, b.0), _mm256_add_ps(self.1, b.1)) }
        }
        #[inline(always)]
        fn sub(self, b: Self) -> Self {
            unsafe { Avx2(_mm256_sub_ps(self.0, b.0), _mm256_sub_ps(self.1, b.1)) }
        }
        #[inline(always)]
        fn mul(self, b: Self) -> Self {
            unsafe { Avx2(_mm256_mul_ps(self.0, b.0), _mm256_mul_ps(self.1, b.1)) }
        }
        #[inline(always)]
        fn div(self, b: Self) -> Self {
            unsafe { Avx2(_mm256_div_ps(self.0, b.0), _mm256_div_ps(self.1, b.1)) }
        }
        #[inline(always)]
        fn mul_add(self, b: Self, c: Self) -> Self {
            unsafe { Avx2(_mm256_fmadd_ps(self.0, b.0, c.0), _mm256_fmadd_ps(self.1, b.1, c.1)) }
        }
        #[inline(always)]
        fn neg_mul_add(self, b: Self, c: Self) -> Self {
            unsafe { Avx2(_mm256_fnmadd_ps(self.0, b.0, c.0), _mm256_fnmadd_ps(self.1, b.1, c.1)) }
        }
        #[inline(always)]
        fn hsum(self) -> f32 {
            unsafe {
                let a = _mm256_add_ps(self.0, self.1);
                let b = _mm_add_ps(_mm256_castps256_ps128(a), _mm256_extractf128_ps::<1>(a));
                let c = _mm_add_ps(b, _mm_movehl_ps(b, b));
                let d = _mm_add_ss(c, _mm_shuffle_ps::<1>(c, c));
                _mm_cvtss_f32(d)
            }
        }
        #[inline(always)]
        fn max(self, b: Self) -> Self {
            unsafe { Avx2(_mm256_max_ps(self.0, b.0), _mm256_max_ps(self.1, b.1)) }
        }
        #[inline(always)]
        fn scalef(self, n: Self) -> Self {
            unsafe {
                let f = |x: __m256, n: __m256| {
                    let e = _mm256_slli_epi32::<23>(_mm256_add_epi32(_mm256_cvtps_epi32(n), _mm256_set1_epi32(127)));
                    _mm256_mul_ps(x, _mm256_castsi256_ps(e))
                };
                Avx2(f(self.0, n.0), f(self.1, n.1))
            }
        }
        #[inline(always)]
        fn frac_turns(r: &[f64], s: f64) -> Self {
            assert!(r.len() >= L);
            unsafe {
                let sv = _mm256_set1_pd(s);
                let q = |p: *const f64| {
                    let t = _mm256_mul_pd(_mm256_loadu_pd(p), sv);
                    let q = _mm256_round_pd::<{ _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC }>(t);
                    _mm256_cvtpd_ps(_mm256_sub_pd(t, q))
                };
                let p = r.as_ptr();
                Avx2(_mm256_set_m128(q(p.add(4)), q(p)), _mm256_set_m128(q(p.add(12)), q(p.add(8))))
            }
        }
        #[inline(always)]
        fn scaled(r: &[f64], s: f64) -> Self {
            assert!(r.len() >= L);
            unsafe {
                let sv = _mm256_set1_pd(s);
                let q = |p: *const f64| _mm256_cvtpd_ps(_mm256_mul_pd(_mm256_loadu_pd(p), sv));
                let p = r.as_ptr();
                Avx2(_mm256_set_m128(q(p.add(4)), q(p)), _mm256_set_m128(q(p.add(12)), q(p.add(8))))
            }
        }
    }

    #[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw,avx2,fma")]
    pub(super) fn run_avx512(geom: &ArrayGeom, blk: &BlockGeom, tab: &Tables, bins: Range<usize>, sc: &mut Scratch) {
        accumulate::<Avx512>(geom, blk, tab, bins, sc)
    }

    #[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw,avx2,fma")]
    pub(super) fn setup_avx512(geom: &ArrayGeom, x: f32, z: f32, df: f64, silent: bool, out: ScattererGeom<'_>) {
        geom.scatterer(x, z, df, silent, out)
    }

    #[target_feature(enable = "avx2,fma")]
    pub(super) fn setup_avx2(geom: &ArrayGeom, x: f32, z: f32, df: f64, silent: bool, out: ScattererGeom<'_>) {
        geom.scatterer(x, z, df, silent, out)
    }

    #[target_feature(enable = "avx2,fma")]
    pub(super) fn run_avx2(geom: &ArrayGeom, blk: &BlockGeom, tab: &Tables, bins: Range<usize>, sc: &mut Scratch) {
        accumulate::<Avx2>(geom, blk, tab, bins, sc)
    }
}

/// Which build of the kernel runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Simd {
    /// x86-64 with AVX-512F/VL/DQ/BW and FMA.
    #[cfg(target_arch = "x86_64")]
    Avx512,
    /// x86-64 with AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    Avx2,
    /// Baseline target, separate multiply and add (the scalar twin).
    Portable,
}

impl Simd {
    /// The best build this CPU supports within `choice`.
    pub fn detect(choice: KernelChoice) -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::is_x86_feature_detected as has;
            let avx512 = has!("avx512f") && has!("avx512vl") && has!("avx512dq") && has!("avx512bw") && has!("fma");
            if choice == KernelChoice::Auto && avx512 {
                return Simd::Avx512;
            }
            if choice != KernelChoice::Portable && has!("avx2") && has!("fma") {
                return Simd::Avx2;
            }
        }
        let _ = choice;
        Simd::Portable
    }

    /// Short name for reports.
    pub fn name(self) -> &'static str {
        match self {
            #[cfg(target_arch = "x86_64")]
            Simd::Avx512 => "avx512",
            #[cfg(target_arch = "x86_64")]
            Simd::Avx2 => "avx2",
            Simd::Portable => "portable",
        }
    }

    /// Runs [`ArrayGeom::scatterer`] with this build (the compiler vectorises it for the target).
    pub fn setup(self, geom: &ArrayGeom, x: f32, z: f32, df: f64, silent: bool, out: ScattererGeom<'_>) {
        match self {
            // SAFETY: as in `accumulate` below.
            #[cfg(target_arch = "x86_64")]
            Simd::Avx512 => unsafe { x86::setup_avx512(geom, x, z, df, silent, out) },
            #[cfg(target_arch = "x86_64")]
            Simd::Avx2 => unsafe { x86::setup_avx2(geom, x, z, df, silent, out) },
            Simd::Portable => geom.scatterer(x, z, df, silent, out),
        }
    }

    /// Runs [`accumulate`] with this build.
    pub fn accumulate(self, geom: &ArrayGeom, blk: &BlockGeom, tab: &Tables, bins: Range<usize>, sc: &mut Scratch) {
        match self {
            // SAFETY: `detect` returns these variants only after checking, on the running CPU,
            // every feature the functions are compiled with.
            #[cfg(target_arch = "x86_64")]
            Simd::Avx512 => unsafe { x86::run_avx512(geom, blk, tab, bins, sc) },
            #[cfg(target_arch = "x86_64")]
            Simd::Avx2 => unsafe { x86::run_avx2(geom, blk, tab, bins, sc) },
            Simd::Portable => accumulate::<Portable>(geom, blk, tab, bins, sc),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vectors() -> [[f32; L]; 8] {
        let mut v = [[0f32; L]; 8];
        for (i, row) in v.iter_mut().enumerate() {
            for (l, x) in row.iter_mut().enumerate() {
                *x = ((i * 37 + l * 11) % 23) as f32 * 0.37 - 3.1 + i as f32;
            }
        }
        v
    }

    #[test]
    fn hsum_and_hsum8_of_every_build_agree() {
        let v = vectors();
        let want: Vec<f32> = v.iter().map(|r| r.iter().map(|x| f64::from(*x)).sum::<f64>() as f32 * 0.5).collect();
        let p = Portable::hsum8(v.map(Portable), 0.5);
        for i in 0..8 {
            assert!((p[i] - want[i]).abs() < 1e-5, "portable {i}");
        }
        #[cfg(target_arch = "x86_64")]
        if Simd::detect(KernelChoice::Auto) == Simd::Avx512 {
            let got = x86::Avx512::hsum8(v.map(|r| <x86::Avx512 as Lanes>::load(&V(r))), 0.5);
            for i in 0..8 {
                assert!((got[i] - want[i]).abs() < 1e-5, "avx512 {i}: {} vs {}", got[i], want[i]);
                let one = <x86::Avx512 as Lanes>::load(&V(v[i])).hsum() * 0.5;
                assert!((one - want[i]).abs() < 1e-5, "avx512 hsum {i}");
            }
        }
        #[cfg(target_arch = "x86_64")]
        if Simd::detect(KernelChoice::Avx2) == Simd::Avx2 {
            let got = x86::Avx2::hsum8(v.map(|r| <x86::Avx2 as Lanes>::load(&V(r))), 0.5);
            for i in 0..8 {
                assert!((got[i] - want[i]).abs() < 1e-5, "avx2 {i}");
            }
        }
    }
}
