//! B-mode images and time-gain compensation, as MUST's `bmode` and `tgc`.
//!
//! [`bmode`]: the envelope |IQ| log-compressed to 8 bits over a dynamic range (dB), or a power
//! law below 1 dB, exactly MUST's formulas (computed in f64). [`tgc_gain`]: MUST's time-gain
//! compensation — the mean envelope over the lines, a robust (Theil–Sen) line through its log
//! over the middle 80 % of the samples, and the gain that flattens that line; [`mean_envelope_iq`]
//! and [`mean_envelope_rf`] (analytic signal by FFT, as `scipy.signal.hilbert`) give its input.

use crate::error::{invalid, BeamformError, Result};
use num_complex::Complex;
use rustfft::FftPlanner;

type C64 = Complex<f64>;

/// MUST `bmode(IQ, DR)`: 8-bit image of the envelope |IQ| (any layout, one value per sample).
/// `dr ≥ 1`: `255·(20·log10(|IQ|/max) + DR)/DR`; `0 < dr < 1`: `255·(|IQ|/max)^DR`; clipped to
/// [0, 255] and truncated, as MUST. An all-zero input gives zeros (MUST: 0/0). Errors: `dr` not
/// finite and > 0, a NaN or infinite sample.
pub fn bmode<T: Copy + Into<f64>>(iq: &[Complex<T>], dr: f64) -> Result<Vec<u8>> {
    if !(dr.is_finite() && dr > 0.0) {
        return Err(invalid("bmode.DR", dr, "finite and > 0 (dB; below 1 a power law)"));
    }
    let env: Vec<f64> = iq.iter().map(|z| z.re.into().hypot(z.im.into())).collect();
    if let Some(i) = env.iter().position(|e| !e.is_finite()) {
        return Err(invalid("bmode.IQ", format!("a NaN or infinite sample at {i}"), "finite samples"));
    }
    let max = env.iter().copied().fold(0.0, f64::max);
    if max == 0.0 {
        return Ok(vec![0; env.len()]);
    }
    Ok(env
        .iter()
        .map(|&e| {
            let v = if dr >= 1.0 { 255.0 * (20.0 * (e / max).log10() + dr) / dr } else { (e / max).powf(dr) * 255.0 };
            // NaN cannot occur (e ≥ 0, max > 0); −inf (e = 0) clamps to 0
            v.clamp(0.0, 255.0) as u8
        })
        .collect())
}

/// Mean over the lines of |IQ| per sample, `iq` sample-major (`n_samples × n_lines`, MUST's
/// `S(sample, line)`). Errors: length not a multiple of `n_lines`, `n_lines` = 0.
pub fn mean_envelope_iq(iq: &[Complex<f64>], n_lines: usize) -> Result<Vec<f64>> {
    check_lines(iq.len(), n_lines)?;
    Ok(iq.chunks_exact(n_lines).map(|row| row.iter().map(|z| z.norm()).sum::<f64>() / n_lines as f64).collect())
}

/// Mean over the lines of the envelope |analytic signal| of real RF, sample-major (`n_samples ×
/// n_lines`); the analytic signal of each line as `scipy.signal.hilbert` (FFT of the whole line,
/// negative frequencies zeroed, positive doubled, Nyquist and DC kept). Errors: as
/// [`mean_envelope_iq`].
pub fn mean_envelope_rf(rf: &[f64], n_lines: usize) -> Result<Vec<f64>> {
    check_lines(rf.len(), n_lines)?;
    let n = rf.len() / n_lines;
    let mut planner = FftPlanner::<f64>::new();
    let (fwd, inv) = (planner.plan_fft_forward(n), planner.plan_fft_inverse(n));
    let mut sum = vec![0.0f64; n];
    let mut line = vec![C64::default(); n];
    for l in 0..n_lines {
        for (k, v) in line.iter_mut().enumerate() {
            *v = C64::new(rf[k * n_lines + l], 0.0);
        }
        fwd.process(&mut line);
        for (k, v) in line.iter_mut().enumerate() {
            let h = if k == 0 || (n.is_multiple_of(2) && k == n / 2) {
                1.0
            } else if k < n.div_ceil(2) {
                2.0
            } else {
                0.0
            };
            *v *= h / n as f64;
        }
        inv.process(&mut line);
        for (s, v) in sum.iter_mut().zip(&line) {
            *s += v.norm();
        }
    }
    Ok(sum.iter().map(|s| s / n_lines as f64).collect())
}

fn check_lines(len: usize, n_lines: usize) -> Result<()> {
    if n_lines == 0 || !len.is_multiple_of(n_lines) || len == 0 {
        return Err(BeamformError::BadDimension {
            field: "tgc.S",
            got: len,
            allowed: "a non-empty n_samples × n_lines array (n_lines ≥ 1)",
        });
    }
    Ok(())
}

/// Largest number of points of the Theil–Sen fit (all pairs: ~n²/2 slopes); longer traces use
/// this many evenly spaced samples of the fitted range.
pub const TGC_MAX_POINTS: usize = 2000;

/// MUST `tgc`'s gain per sample from the mean envelope `c` (n samples): a Theil–Sen line
/// `ln c(k) ≈ a + b·k` over k in [⌈n/10⌉, ⌊9n/10⌋) (slope = median of the pairwise slopes,
/// intercept = median of ln c − b·k, medians of an even count the mean of the middle two, as
/// numpy), then `gain(k) = exp(a) / exp(a + b·k)`. MUST fits at most 200 randomly chosen points
/// (a different fit per call when there are more); here every point up to [`TGC_MAX_POINTS`]
/// (the same fit as MUST's whenever MUST uses all its points), so the result is reproducible.
/// Errors: fewer than 2 points to fit, an envelope value that is not finite and > 0 there.
pub fn tgc_gain(c: &[f64]) -> Result<Vec<f64>> {
    let n = c.len();
    let (n1, n2) = (n.div_ceil(10), n * 9 / 10);
    if n2 < n1 + 2 {
        return Err(BeamformError::BadDimension { field: "tgc.S", got: n, allowed: "at least 3 samples along time" });
    }
    let step = ((n2 - n1) as f64 / TGC_MAX_POINTS as f64).max(1.0);
    let m = ((n2 - n1) as f64 / step).floor() as usize;
    let idx: Vec<usize> = (0..m).map(|i| n1 + (i as f64 * step) as usize).collect();
    let mut pts = Vec::with_capacity(m);
    for &k in &idx {
        if !(c[k].is_finite() && c[k] > 0.0) {
            return Err(invalid(
                "tgc.S",
                format!("mean envelope {} at sample {k}", c[k]),
                "finite and > 0 in the fitted range",
            ));
        }
        pts.push((k as f64, c[k].ln()));
    }
    let mut slopes = Vec::with_capacity(m * (m - 1) / 2);
    for (i, a) in pts.iter().enumerate() {
        for b in &pts[i + 1..] {
            slopes.push((b.1 - a.1) / (b.0 - a.0));
        }
    }
    let slope = median(&mut slopes);
    let mut rest: Vec<f64> = pts.iter().map(|(x, y)| y - slope * x).collect();
    let intercept = median(&mut rest);
    let c0 = (intercept + slope * 0.0).exp();
    Ok((0..n).map(|k| c0 / (intercept + slope * k as f64).exp()).collect())
}

/// numpy's median: the middle value, or the mean of the two middle values.
fn median(v: &mut [f64]) -> f64 {
    let n = v.len();
    let (_, hi, _) = v.select_nth_unstable_by(n / 2, f64::total_cmp);
    let hi = *hi;
    if n % 2 == 1 {
        return hi;
    }
    let lo = v[..n / 2].iter().copied().fold(f64::NEG_INFINITY, f64::max);
    (lo + hi) / 2.0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Envelopes 1, 0.1, 0.01, 0.001 at 40 dB: 255·(0, −20, −40, −60 dB + 40)/40 → 255, 127
    /// (127.5 truncated), 0, 0 (clipped); a power law below 1 dB; zeros; bad input.
    #[test]
    fn bmode_follows_must() {
        let iq: Vec<Complex<f32>> =
            [1.0f32, 0.1, 0.01, 0.001].iter().map(|&a| Complex::new(0.6 * a, 0.8 * a)).collect();
        assert_eq!(bmode(&iq, 40.0).unwrap(), vec![255, 127, 0, 0]);
        // 0.5 power: 255·(1, 0.316, 0.1, 0.0316) → 255, 80, 25, 8
        assert_eq!(bmode(&iq, 0.5).unwrap(), vec![255, 80, 25, 8]);
        assert_eq!(bmode(&[Complex::new(0.0f64, 0.0); 3], 40.0).unwrap(), vec![0; 3]);
        assert!(matches!(bmode(&iq, 0.0), Err(BeamformError::InvalidParameter { field: "bmode.DR", .. })));
        let bad = [Complex::new(f32::NAN, 0.0)];
        assert!(matches!(bmode(&bad, 40.0), Err(BeamformError::InvalidParameter { field: "bmode.IQ", .. })));
    }

    /// A noiseless exponential decay is flattened exactly (Theil–Sen is exact on a line), also
    /// with 20 % of the fitted samples made outliers; the RF envelope of a constant-amplitude
    /// tone is that amplitude (analytic signal).
    #[test]
    fn tgc_flattens_an_exponential_decay_robustly() {
        let n = 300;
        let a = 0.013;
        let mut c: Vec<f64> = (0..n).map(|k| 2.0 * (-a * k as f64).exp()).collect();
        let g = tgc_gain(&c).unwrap();
        for (k, g) in g.iter().enumerate() {
            assert!((g - (a * k as f64).exp()).abs() < 1e-9 * g, "sample {k}");
        }
        for k in (40..260).step_by(5) {
            c[k] *= 50.0;
        }
        let g = tgc_gain(&c).unwrap();
        assert!((g[n - 1].ln() / (n - 1) as f64 - a).abs() < 1e-3 * a, "slope with outliers");
        assert!(tgc_gain(&[1.0, 2.0]).is_err());
        assert!(tgc_gain(
            &[1.0; 30].iter().enumerate().map(|(k, v)| if k == 10 { 0.0 } else { *v }).collect::<Vec<_>>()
        )
        .is_err());

        let (ns, lines) = (256usize, 3usize);
        let rf: Vec<f64> = (0..ns * lines)
            .map(|i| (1.0 + (i % lines) as f64) * (2.0 * std::f64::consts::PI * 0.125 * (i / lines) as f64).cos())
            .collect();
        let env = mean_envelope_rf(&rf, lines).unwrap();
        assert!(env.iter().all(|e| (e - 2.0).abs() < 1e-12), "mean envelope of amplitudes 1, 2, 3");
        assert!(mean_envelope_rf(&rf[1..], lines).is_err());
    }
}
