//! Branch-free f64 elementary functions that the compiler vectorises inside loops
//! (sin/cos of a phase in turns, exp of a non-positive argument), accurate to a few ulp.
//! Used for the per-(scatterer, element) set-up and the exact re-anchoring of the phasors.

/// 1.5·2^52: adding and subtracting it rounds an f64 of magnitude < 2^51 to the nearest integer,
/// and the low mantissa bits of the sum hold that integer in two's complement.
const MAGIC: f64 = 6_755_399_441_055_744.0;

/// `(sin 2πt, cos 2πt)` for any finite `t` with |t| < 2^49 (turns).
#[inline(always)]
pub(crate) fn sincos_turns(t: f64) -> (f64, f64) {
    let shifted = t * 4.0 + MAGIC;
    let q = shifted - MAGIC; // nearest integer to 4t (quarter turns)
    let quadrant = shifted.to_bits() & 3;
    let u = t - q * 0.25; // |u| <= 1/8 turn
    let x = u * std::f64::consts::TAU; // |x| <= pi/4
    let x2 = x * x;
    // Taylor series (Horner), truncation error < 1e-16 on |x| <= pi/4
    const S: [f64; 8] = [
        -1.0 / 1_307_674_368_000.0,
        1.0 / 6_227_020_800.0,
        -1.0 / 39_916_800.0,
        1.0 / 362_880.0,
        -1.0 / 5040.0,
        1.0 / 120.0,
        -1.0 / 6.0,
        1.0,
    ];
    const C: [f64; 9] = [
        1.0 / 20_922_789_888_000.0,
        -1.0 / 87_178_291_200.0,
        1.0 / 479_001_600.0,
        -1.0 / 3_628_800.0,
        1.0 / 40_320.0,
        -1.0 / 720.0,
        1.0 / 24.0,
        -0.5,
        1.0,
    ];
    let mut sp = 0.0;
    for a in S {
        sp = sp * x2 + a;
    }
    let s = x * sp;
    let mut c = 0.0;
    for a in C {
        c = c * x2 + a;
    }
    let swap = quadrant & 1 == 1;
    let (sv, cv) = if swap { (c, s) } else { (s, c) };
    let sin_sign = if quadrant & 2 == 2 { -1.0 } else { 1.0 };
    let cos_sign = if (quadrant + 1) & 2 == 2 { -1.0 } else { 1.0 };
    (sv * sin_sign, cv * cos_sign)
}

/// 1/k! for k = 0..=12.
const INV_FACT: [f64; 13] = [
    1.0,
    1.0,
    1.0 / 2.0,
    1.0 / 6.0,
    1.0 / 24.0,
    1.0 / 120.0,
    1.0 / 720.0,
    1.0 / 5040.0,
    1.0 / 40_320.0,
    1.0 / 362_880.0,
    1.0 / 3_628_800.0,
    1.0 / 39_916_800.0,
    1.0 / 479_001_600.0,
];

/// `exp(x)` for `x <= 0` (returns 0 below −700).
#[inline(always)]
pub(crate) fn exp_nonpos(x: f64) -> f64 {
    const LOG2E: f64 = std::f64::consts::LOG2_E;
    const LN2_HI: f64 = 6.931_471_803_691_238e-1;
    const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;
    let xc = x.clamp(-700.0, 0.0);
    let shifted = xc * LOG2E + MAGIC;
    let n = shifted - MAGIC;
    let ni = (shifted.to_bits().wrapping_sub(MAGIC.to_bits())) as i64; // = n
    let r = (xc - n * LN2_HI) - n * LN2_LO; // |r| <= ln2/2
                                            // Taylor series of e^r to r^12 (Horner), truncation error < 1e-17 on |r| <= ln2/2
    let mut p = 0.0;
    for k in (0..=12).rev() {
        p = p * r + INV_FACT[k];
    }
    let scale = f64::from_bits(((ni + 1023) as u64) << 52);
    let v = p * scale;
    if x < -700.0 {
        0.0
    } else {
        v
    }
}

/// MUST's `mysinc` in pfield: `sin(|x| + 1e-16) / (|x| + 1e-16)`.
#[inline(always)]
pub(crate) fn sinc_eps(x: f64) -> f64 {
    let a = x.abs() + 1e-16;
    let (s, _) = sincos_turns(a * (0.5 / std::f64::consts::PI));
    s / a
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sincos_turns_matches_std() {
        let mut worst = 0.0f64;
        for i in -20_000..20_000 {
            let t = i as f64 * 0.012_345_678_9 + 0.3;
            let (s, c) = sincos_turns(t);
            let a = t * std::f64::consts::TAU;
            worst = worst.max((s - a.sin()).abs()).max((c - a.cos()).abs());
        }
        // std evaluates sin(2πt) after rounding 2πt (|2πt| up to 1.5e3, ulp 2.3e-13): the
        // turn-based evaluation is the more accurate one, so compare at that level.
        assert!(worst < 1e-12, "{worst}");
        for t in [0.0, 0.25, 0.5, -0.25, 1e-9, 0.125, 0.375] {
            let (s, c) = sincos_turns(t);
            let a = t * std::f64::consts::TAU;
            assert!((s - a.sin()).abs() < 2e-16 && (c - a.cos()).abs() < 2e-16, "{t}");
        }
    }

    #[test]
    fn exp_nonpos_matches_std() {
        for i in 0..6980 {
            let x = -(i as f64) * 0.1003;
            let e = exp_nonpos(x);
            let r = x.exp();
            assert!((e - r).abs() <= 4e-16 * r, "{x}: {e} vs {r}");
        }
        assert_eq!(exp_nonpos(-800.0), 0.0);
        assert_eq!(exp_nonpos(0.0), 1.0);
    }

    #[test]
    fn sinc_eps_is_finite_at_zero() {
        assert!((sinc_eps(0.0) - 1.0).abs() < 1e-15);
        assert!((sinc_eps(std::f64::consts::PI)).abs() < 1e-15);
        assert!((sinc_eps(-1.0) - 1f64.sin()).abs() < 1e-15);
    }
}
