//! Eight f32 lanes: a portable array type and an AVX2 + FMA register type with exactly the same IEEE
//! operations (`+ − × ÷ √` correctly rounded, fused multiply-add with one rounding, `max` as `a > b ? a : b`,
//! sign-bit blend, unsigned integer min), so a kernel written once over [`Lanes`] gives the same bits
//! with either type.

/// Eight f32 lanes.
///
/// # Safety
/// An implementation may assume the CPU features its operations need; a caller uses an
/// implementation `L` only when `L::available()` is true.
pub(super) unsafe trait Lanes: Copy {
    /// The CPU can run this implementation.
    fn available() -> bool;
    /// All lanes `v`.
    fn splat(v: f32) -> Self;
    /// Loads 8 consecutive f32.
    ///
    /// # Safety
    /// `p` points to 8 readable f32.
    unsafe fn load(p: *const f32) -> Self;
    /// Stores 8 consecutive f32.
    ///
    /// # Safety
    /// `p` points to 8 writable f32.
    unsafe fn store(p: *mut f32, v: Self);
    /// `self + o`.
    fn add(self, o: Self) -> Self;
    /// `self − o`.
    fn sub(self, o: Self) -> Self;
    /// `self × o`.
    fn mul(self, o: Self) -> Self;
    /// `self ÷ o`.
    fn div(self, o: Self) -> Self;
    /// `self × b + c` with one rounding.
    fn mul_add(self, b: Self, c: Self) -> Self;
    /// `self > o ? self : o`.
    fn max(self, o: Self) -> Self;
    /// √self.
    fn sqrt(self) -> Self;
    /// Per lane: `b` where the sign bit of `mask` is set, else `self`.
    fn blend(self, b: Self, mask: Self) -> Self;
    /// Lanes as u32 bit patterns: `min(self, bits(x) − k)` (unsigned, wrapping subtraction).
    fn min_bits_sub(self, x: Self, k: u32) -> Self;
    /// The lanes in order (tests).
    #[cfg(test)]
    fn to_array(self) -> [f32; 8];
    /// Sum of the lanes in f64 in a fixed order: s_i = l_i + l_(i+4) (i < 4), t_j = s_j + s_(j+2)
    /// (j < 2), t_0 + t_1.
    fn sum_f64(self) -> f64;
    /// Smallest lane as u32 bit patterns.
    fn min_bits(self) -> u32;
}

/// Sum of the lanes in f64 (see [`Lanes::sum_f64`]).
#[inline(always)]
pub(super) fn sum_f64<L: Lanes>(v: L) -> f64 {
    v.sum_f64()
}

/// Portable twin: an array of 8 f32, lane by lane.
#[derive(Clone, Copy, Debug)]
pub(super) struct Portable([f32; 8]);

#[inline(always)]
fn zip(a: [f32; 8], b: [f32; 8], f: impl Fn(f32, f32) -> f32) -> [f32; 8] {
    std::array::from_fn(|i| f(a[i], b[i]))
}

// SAFETY: plain scalar code, runs on every CPU.
unsafe impl Lanes for Portable {
    #[inline(always)]
    fn available() -> bool {
        true
    }
    #[inline(always)]
    fn splat(v: f32) -> Self {
        Portable([v; 8])
    }
    #[inline(always)]
    unsafe fn load(p: *const f32) -> Self {
        // SAFETY: the caller guarantees 8 readable f32 at p.
        Portable(unsafe { std::ptr::read_unaligned(p.cast::<[f32; 8]>()) })
    }
    #[inline(always)]
    unsafe fn store(p: *mut f32, v: Self) {
        // SAFETY: the caller guarantees 8 writable f32 at p.
        unsafe { std::ptr::write_unaligned(p.cast::<[f32; 8]>(), v.0) }
    }
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        Portable(zip(self.0, o.0, |a, b| a + b))
    }
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        Portable(zip(self.0, o.0, |a, b| a - b))
    }
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        Portable(zip(self.0, o.0, |a, b| a * b))
    }
    #[inline(always)]
    fn div(self, o: Self) -> Self {
        Portable(zip(self.0, o.0, |a, b| a / b))
    }
    #[inline(always)]
    fn mul_add(self, b: Self, c: Self) -> Self {
        Portable(std::array::from_fn(|i| self.0[i].mul_add(b.0[i], c.0[i])))
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        Portable(zip(self.0, o.0, |a, b| if a > b { a } else { b }))
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        Portable(self.0.map(f32::sqrt))
    }
    #[inline(always)]
    fn blend(self, b: Self, mask: Self) -> Self {
        Portable(std::array::from_fn(|i| if mask.0[i].is_sign_negative() { b.0[i] } else { self.0[i] }))
    }
    #[inline(always)]
    fn min_bits_sub(self, x: Self, k: u32) -> Self {
        Portable(zip(self.0, x.0, |a, b| f32::from_bits(a.to_bits().min(b.to_bits().wrapping_sub(k)))))
    }
    #[cfg(test)]
    fn to_array(self) -> [f32; 8] {
        self.0
    }
    #[inline(always)]
    fn sum_f64(self) -> f64 {
        let l = self.0.map(f64::from);
        let s = [l[0] + l[4], l[1] + l[5], l[2] + l[6], l[3] + l[7]];
        (s[0] + s[2]) + (s[1] + s[3])
    }
    #[inline(always)]
    fn min_bits(self) -> u32 {
        self.0.iter().fold(u32::MAX, |m, x| m.min(x.to_bits()))
    }
}

#[cfg(target_arch = "x86_64")]
pub(super) use avx::Avx;

#[cfg(target_arch = "x86_64")]
mod avx {
    use std::arch::x86_64::*;

    use super::Lanes;

    /// One AVX register of 8 f32 (`vaddps`, `vfmadd…ps`, `vmaxps`, `vsqrtps`, …).
    #[derive(Clone, Copy, Debug)]
    pub(in crate::fast) struct Avx(__m256);

    // SAFETY: every method needs AVX2 and FMA, which `available` checks; the trait's contract makes
    // callers use this type only when it returned true (the kernels run it inside
    // `#[target_feature(enable = "avx2,fma")]` functions, where these methods are inlined).
    unsafe impl Lanes for Avx {
        #[inline(always)]
        fn available() -> bool {
            std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        }
        #[inline(always)]
        fn splat(v: f32) -> Self {
            // SAFETY: see the impl.
            Avx(unsafe { _mm256_set1_ps(v) })
        }
        #[inline(always)]
        unsafe fn load(p: *const f32) -> Self {
            // SAFETY: 8 readable f32 at p (caller); AVX (impl contract).
            Avx(unsafe { _mm256_loadu_ps(p) })
        }
        #[inline(always)]
        unsafe fn store(p: *mut f32, v: Self) {
            // SAFETY: 8 writable f32 at p (caller); AVX (impl contract).
            unsafe { _mm256_storeu_ps(p, v.0) }
        }
        #[inline(always)]
        fn add(self, o: Self) -> Self {
            // SAFETY: see the impl.
            Avx(unsafe { _mm256_add_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn sub(self, o: Self) -> Self {
            // SAFETY: see the impl.
            Avx(unsafe { _mm256_sub_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn mul(self, o: Self) -> Self {
            // SAFETY: see the impl.
            Avx(unsafe { _mm256_mul_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn div(self, o: Self) -> Self {
            // SAFETY: see the impl.
            Avx(unsafe { _mm256_div_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn mul_add(self, b: Self, c: Self) -> Self {
            // SAFETY: see the impl.
            Avx(unsafe { _mm256_fmadd_ps(self.0, b.0, c.0) })
        }
        #[inline(always)]
        fn max(self, o: Self) -> Self {
            // vmaxps returns the second operand unless the first is greater (NaN and ±0 included).
            // SAFETY: see the impl.
            Avx(unsafe { _mm256_max_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn sqrt(self) -> Self {
            // SAFETY: see the impl.
            Avx(unsafe { _mm256_sqrt_ps(self.0) })
        }
        #[inline(always)]
        fn blend(self, b: Self, mask: Self) -> Self {
            // SAFETY: see the impl.
            Avx(unsafe { _mm256_blendv_ps(self.0, b.0, mask.0) })
        }
        #[inline(always)]
        fn min_bits_sub(self, x: Self, k: u32) -> Self {
            // SAFETY: see the impl.
            unsafe {
                let d = _mm256_sub_epi32(_mm256_castps_si256(x.0), _mm256_set1_epi32(k as i32));
                Avx(_mm256_castsi256_ps(_mm256_min_epu32(_mm256_castps_si256(self.0), d)))
            }
        }
        #[cfg(test)]
        fn to_array(self) -> [f32; 8] {
            let mut a = [0.0f32; 8];
            // SAFETY: a holds 8 writable f32; AVX (impl contract).
            unsafe { _mm256_storeu_ps(a.as_mut_ptr(), self.0) };
            a
        }
        #[inline(always)]
        fn sum_f64(self) -> f64 {
            // SAFETY: see the impl.
            unsafe {
                let lo = _mm256_cvtps_pd(_mm256_castps256_ps128(self.0));
                let hi = _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(self.0));
                let s = _mm256_add_pd(lo, hi); // l_i + l_(i+4)
                let t = _mm_add_pd(_mm256_castpd256_pd128(s), _mm256_extractf128_pd::<1>(s)); // s_j + s_(j+2)
                _mm_cvtsd_f64(_mm_add_sd(t, _mm_unpackhi_pd(t, t)))
            }
        }
        #[inline(always)]
        fn min_bits(self) -> u32 {
            // SAFETY: see the impl.
            unsafe {
                let v = _mm256_castps_si256(self.0);
                let m = _mm_min_epu32(_mm256_castsi256_si128(v), _mm256_extracti128_si256::<1>(v));
                let m = _mm_min_epu32(m, _mm_shuffle_epi32::<0b01_00_11_10>(m));
                let m = _mm_min_epu32(m, _mm_shuffle_epi32::<0b10_11_00_01>(m));
                _mm_cvtsi128_si32(m) as u32
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every operation of the AVX type gives the bits of the portable one, NaN, ±0, ±∞ and
    /// subnormals included.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx_operations_match_the_portable_twin_bit_for_bit() {
        if !Avx::available() {
            eprintln!("no AVX2+FMA: nothing to compare");
            return;
        }
        let special = [0.0f32, -0.0, 1.0, -1.0, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, 1e-40, -3e-39, 2.5];
        let mut s = 0x1234_5678_9ABC_DEF0u64;
        let mut vals: Vec<f32> = special.to_vec();
        for _ in 0..4000 {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            vals.push(f32::from_bits((s >> 32) as u32));
            vals.push(((s >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * 8.0);
        }
        let get = |k: usize| -> [f32; 8] { std::array::from_fn(|i| vals[(k * 8 + i * 7) % vals.len()]) };
        for k in 0..vals.len() {
            let (a, b, c) = (get(k), get(k + 1), get(k + 3));
            // SAFETY: AVX2+FMA checked above; the arrays hold 8 f32.
            let (pa, pb, pc, va, vb, vc) = unsafe {
                (
                    Portable::load(a.as_ptr()),
                    Portable::load(b.as_ptr()),
                    Portable::load(c.as_ptr()),
                    Avx::load(a.as_ptr()),
                    Avx::load(b.as_ptr()),
                    Avx::load(c.as_ptr()),
                )
            };
            let bits = |v: [f32; 8]| v.map(f32::to_bits);
            let pairs = [
                (pa.add(pb).to_array(), va.add(vb).to_array()),
                (pa.sub(pb).to_array(), va.sub(vb).to_array()),
                (pa.mul(pb).to_array(), va.mul(vb).to_array()),
                (pa.div(pb).to_array(), va.div(vb).to_array()),
                (pa.mul_add(pb, pc).to_array(), va.mul_add(vb, vc).to_array()),
                (pa.max(pb).to_array(), va.max(vb).to_array()),
                (pa.sqrt().to_array(), va.sqrt().to_array()),
                (pa.blend(pb, pc).to_array(), va.blend(vb, vc).to_array()),
                (pa.min_bits_sub(pb, 0x1234_5678).to_array(), va.min_bits_sub(vb, 0x1234_5678).to_array()),
                (Portable::splat(a[0]).to_array(), Avx::splat(a[0]).to_array()),
            ];
            for (op, (p, v)) in pairs.iter().enumerate() {
                // Arithmetic: NaN payloads may differ, NaN-ness may not; bitwise operations: exact.
                let canon = |x: [f32; 8]| x.map(|y| if y.is_nan() && op < 7 { u32::MAX } else { y.to_bits() });
                assert_eq!(canon(*p), canon(*v), "op {op} on {a:?} {b:?} {c:?}: {:?} vs {:?}", bits(*p), bits(*v));
            }
            assert_eq!(sum_f64(pa).to_bits(), sum_f64(va).to_bits());
            assert_eq!(pa.min_bits(), va.min_bits());
        }
    }
}
