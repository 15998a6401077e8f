//! Robust weights from studentised residuals (Garcia 2010 CSDA §4; vector version Garcia 2011
//! Exp Fluids §2.3, MATLAB `RobustWeights`).

use crate::params::WeightFunction;

/// Tuning constant turning a median absolute deviation into a standard deviation (Gaussian).
pub const MAD_TO_SIGMA: f64 = 1.4826;

/// Median of `v` (mean of the two middle values for an even count, as MATLAB/NumPy); reorders `v`.
/// Returns NaN for an empty slice.
pub fn median(v: &mut [f64]) -> f64 {
    let n = v.len();
    if n == 0 {
        return f64::NAN;
    }
    let (left, upper, _) = v.select_nth_unstable_by(n / 2, f64::total_cmp);
    let upper = *upper;
    if n % 2 == 1 {
        upper
    } else {
        let lower = left.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        0.5 * (lower + upper)
    }
}

/// Median of `r` over the `valid` points, gathered into `scratch` (len ≥ number of valid points).
pub fn valid_median(r: &[f64], valid: &[bool], scratch: &mut [f64]) -> f64 {
    let mut m = 0;
    for (v, _) in r.iter().zip(valid).filter(|(_, ok)| **ok) {
        scratch[m] = *v;
        m += 1;
    }
    median(&mut scratch[..m])
}

/// Median absolute deviation of the residual vectors: `median over valid points of |r − mmed|₂`.
pub fn vector_mad<R: AsRef<[f64]>>(residuals: &[R], valid: &[bool], mmed: &[f64], scratch: &mut Vec<f64>) -> f64 {
    scratch.clear();
    if valid.iter().all(|v| *v) {
        // Every point valid: the same sums component by component (contiguous loops that
        // vectorise), then the square roots.
        scratch.resize(valid.len(), 0.0);
        for (c, (r, m)) in residuals.iter().zip(mmed).enumerate() {
            let r = &r.as_ref()[..scratch.len()];
            if c == 0 {
                scratch.iter_mut().zip(r).for_each(|(s, r)| *s = -0.0 + (r - m).powi(2));
            } else {
                scratch.iter_mut().zip(r).for_each(|(s, r)| *s += (r - m).powi(2));
            }
        }
        scratch.iter_mut().for_each(|s| *s = s.sqrt());
        return median(scratch);
    }
    for p in (0..valid.len()).filter(|&p| valid[p]) {
        let ad2: f64 = residuals.iter().zip(mmed).map(|(r, m)| (r.as_ref()[p] - m).powi(2)).sum();
        scratch.push(ad2.sqrt());
    }
    median(scratch)
}

/// Weights of the points `offset..offset + out.len()`: `u = |r|₂ · scale`, weight `= w(u)`
/// (`u = 0` for a zero residual, so that `scale = ∞` when MAD = 0 leaves exact fits at weight 1).
pub fn weights_of<R: AsRef<[f64]>>(residuals: &[R], offset: usize, scale: f64, wf: WeightFunction, out: &mut [f64]) {
    // |r|² component by component (contiguous loops that vectorise; the same sums in the same
    // order as summing per point), then the weight function, chosen once per call.
    let len = out.len();
    out.fill(0.0);
    for r in residuals {
        for (o, r) in out.iter_mut().zip(&r.as_ref()[offset..offset + len]) {
            *o += r * r;
        }
    }
    #[inline(always)]
    fn apply(out: &mut [f64], scale: f64, f: impl Fn(f64) -> f64) {
        for w in out.iter_mut() {
            let r2 = *w;
            let u = if r2 == 0.0 { 0.0 } else { r2.sqrt() * scale };
            *w = f(u);
        }
    }
    match wf {
        WeightFunction::Bisquare => apply(out, scale, |u| WeightFunction::Bisquare.weight(u)),
        WeightFunction::Cauchy => apply(out, scale, |u| WeightFunction::Cauchy.weight(u)),
        WeightFunction::Talworth => apply(out, scale, |u| WeightFunction::Talworth.weight(u)),
    }
}

/// `1 / (1.4826 MAD) / sqrt(1 − h)`: multiplies `|r|₂` into the studentised residual.
pub fn studentise_scale(mad: f64, h: f64) -> f64 {
    1.0 / (MAD_TO_SIGMA * mad) / (1.0 - h).sqrt()
}

/// Per-point robust weights of a (multi-component) residual field (serial reference; the smoother
/// runs the same steps with the per-component medians and the weights in parallel).
///
/// `residuals[c]` is `y_c − z_c` at every grid point (0 where data are missing), `valid` marks the
/// points with data. MATLAB: `MMED_c` = median of component c's residuals (marginal median),
/// `AD = |r − MMED|₂` over components, `MAD = median(AD)`, studentised residual
/// `u = |r|₂ / (1.4826 MAD) / sqrt(1 − h)`, weight `= weight_function(u)`.
/// `global_median` replaces the marginal medians by one median of all components' residuals
/// (PyMUST 0.1.9). A zero residual with `MAD = 0` gets `u = 0` (weight 1), where MATLAB's 0/0 gives
/// NaN and weight 0 (only exact fits reach this case).
pub fn robust_weights<R: AsRef<[f64]>>(
    residuals: &[R],
    valid: &[bool],
    h: f64,
    weight_function: WeightFunction,
    global_median: bool,
    out: &mut [f64],
) {
    let n = valid.len();
    let mut scratch = vec![0.0; n * residuals.len()];
    let mmed: Vec<f64> = if global_median {
        let all: Vec<f64> = residuals.iter().flat_map(|r| r.as_ref().to_vec()).collect();
        let valid_all: Vec<bool> = residuals.iter().flat_map(|_| valid.to_vec()).collect();
        vec![valid_median(&all, &valid_all, &mut scratch); residuals.len()]
    } else {
        residuals.iter().map(|r| valid_median(r.as_ref(), valid, &mut scratch)).collect()
    };
    let mad = vector_mad(residuals, valid, &mmed, &mut scratch);
    weights_of(residuals, 0, studentise_scale(mad, h), weight_function, out);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vector_mad_of_complete_data_matches_the_per_point_formula() {
        let r: Vec<Vec<f64>> = (0..3)
            .map(|c| (0..101).map(|i| ((i * (c + 2)) as f64 * 0.61).cos() * (1.0 + c as f64)).collect())
            .collect();
        let mmed = [0.1, -0.2, 0.05];
        for comps in 1..=3 {
            let mut per_point: Vec<f64> = (0..101)
                .map(|p| r[..comps].iter().zip(&mmed).map(|(r, m)| (r[p] - m).powi(2)).sum::<f64>().sqrt())
                .collect();
            let expected = median(&mut per_point);
            let mut scratch = Vec::new();
            let got = vector_mad(&r[..comps], &[true; 101], &mmed[..comps], &mut scratch);
            assert_eq!(got.to_bits(), expected.to_bits(), "{comps} components");
            // One invalid point: the per-point path, the same value as leaving the point out.
            let mut valid = [true; 101];
            valid[7] = false;
            per_point.clear();
            per_point.extend(
                (0..101)
                    .filter(|p| *p != 7)
                    .map(|p| r[..comps].iter().zip(&mmed).map(|(r, m)| (r[p] - m).powi(2)).sum::<f64>().sqrt()),
            );
            let got = vector_mad(&r[..comps], &valid, &mmed[..comps], &mut scratch);
            assert_eq!(got.to_bits(), median(&mut per_point).to_bits());
        }
    }

    #[test]
    fn median_matches_definition_for_odd_and_even_counts() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 2.5);
        assert_eq!(median(&mut [5.0]), 5.0);
        assert!(median(&mut []).is_nan());
    }

    #[test]
    fn weight_functions_match_their_formulas() {
        let b = WeightFunction::Bisquare;
        assert_eq!(b.weight(0.0), 1.0);
        assert!((b.weight(2.0) - (1.0 - (2.0f64 / 4.685).powi(2)).powi(2)).abs() < 1e-15);
        assert_eq!(b.weight(4.685), 0.0);
        assert_eq!(WeightFunction::Talworth.weight(2.79), 1.0);
        assert_eq!(WeightFunction::Talworth.weight(2.8), 0.0);
        assert!((WeightFunction::Cauchy.weight(2.385) - 0.5).abs() < 1e-15);
        assert_eq!(b.weight(f64::NAN), 0.0);
    }

    /// The component-by-component sums give the per-point formula's bits, for every weight function.
    #[test]
    fn weights_of_matches_the_per_point_formula() {
        let r: Vec<Vec<f64>> = (0..3)
            .map(|c| (0..203).map(|i| ((i * (c + 3)) as f64 * 0.37).sin() * (1.0 + c as f64)).collect())
            .collect();
        let mut r = r;
        r[1][7] = 0.0;
        (r[0][7], r[2][7]) = (0.0, 0.0);
        for wf in [WeightFunction::Bisquare, WeightFunction::Cauchy, WeightFunction::Talworth] {
            let (offset, scale) = (11, 0.83);
            let mut out = vec![f64::NAN; 150];
            weights_of(&r, offset, scale, wf, &mut out);
            for (i, w) in out.iter().enumerate() {
                let r2: f64 = r.iter().map(|c| c[offset + i].powi(2)).sum();
                let u = if r2 == 0.0 { 0.0 } else { r2.sqrt() * scale };
                assert_eq!(w.to_bits(), wf.weight(u).to_bits(), "{wf:?}, point {i}");
            }
        }
    }

    #[test]
    fn marginal_and_global_medians_differ_for_offset_components() {
        // Component 0 centred on +1, component 1 on −1: marginal medians remove the offsets,
        // the global median (≈ 0) does not, so the MAD and hence the weights differ.
        let r0: Vec<f64> = (0..101).map(|i| 1.0 + 0.01 * (i as f64 - 50.0)).collect();
        let r1: Vec<f64> = (0..101).map(|i| -1.0 + 0.02 * ((i * 37 % 101) as f64 - 50.0)).collect();
        let valid = vec![true; 101];
        let (mut wm, mut wg) = (vec![0.0; 101], vec![0.0; 101]);
        let bisquare = WeightFunction::Bisquare;
        robust_weights(&[&r0, &r1], &valid, 0.0, bisquare, false, &mut wm);
        robust_weights(&[&r0, &r1], &valid, 0.0, bisquare, true, &mut wg);
        assert!(wm[50] < wg[50] - 0.1, "marginal {} vs global {}", wm[50], wg[50]);
    }
}
