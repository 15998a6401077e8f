//! Choice of the smoothing parameter S of the divergence-free fit: four-fold block
//! cross-validation and the bracketing search over log10 S.

use super::{solve, with_prior, DivFree, DivFreeError, DivFreeReport};

/// Four-fold cross-validation over square blocks of `block` pixels (fold of pixel (i, j):
/// `2·((i / block) mod 2) + (j / block) mod 2`): each fold is fitted without its blocks and scored
/// on them. Blocks larger than the correlation length of the Doppler noise (a resolution cell)
/// keep the held-out noise independent of the fitted data, which GCV assumes pixel by pixel and
/// which makes it under-smooth correlated noise.
pub(super) struct BlockCv {
    folds: Vec<(Vec<f64>, Vec<f64>)>,
    held: Vec<Vec<usize>>,
    w: Vec<f64>,
    ux: Vec<f64>,
    uz: Vec<f64>,
}

impl BlockCv {
    /// Whether every fold that holds data out leaves some data to fit.
    pub(super) fn possible(f: &DivFree, w: &[f64], block: usize) -> bool {
        let b = block.max(1);
        let mut per_fold = [0usize; 4];
        let mut total = 0usize;
        for i in 0..f.nz {
            for j in 0..f.nx {
                if w[i * f.nx + j] > 0.0 {
                    per_fold[2 * ((i / b) % 2) + (j / b) % 2] += 1;
                    total += 1;
                }
            }
        }
        per_fold.iter().all(|&k| k == 0 || k < total) && per_fold.iter().filter(|&&k| k > 0).count() >= 2
    }

    /// Folds of the data weights `w`; the zero-velocity `prior` stays whole in every fold.
    pub(super) fn new(f: &DivFree, w: &[f64], prior: &[f64], ux: &[f64], uz: &[f64], r2: f64, block: usize) -> Self {
        let (nz, nx) = (f.nz, f.nx);
        let b = block.max(1);
        let mut folds = Vec::with_capacity(4);
        let mut held = Vec::with_capacity(4);
        for k in 0..4 {
            let mut wk = w.to_vec();
            let mut h = Vec::new();
            for i in 0..nz {
                for j in 0..nx {
                    let p = i * nx + j;
                    if 2 * ((i / b) % 2) + (j / b) % 2 == k {
                        if w[p] > 0.0 {
                            h.push(p);
                        }
                        wk[p] = 0.0;
                    }
                }
            }
            let mut rhs = vec![0.0; f.n_psi];
            let ax: Vec<f64> = (0..nz * nx).map(|p| wk[p] * ux[p]).collect();
            let az: Vec<f64> = (0..nz * nx).map(|p| wk[p] * uz[p]).collect();
            f.adjoint(&ax, &az, r2, &mut rhs);
            folds.push((f.data_matrix(&with_prior(&wk, prior), r2), rhs));
            held.push(h);
        }
        Self { folds, held, w: w.to_vec(), ux: ux.to_vec(), uz: uz.to_vec() }
    }

    /// Sum over the folds of the weighted squared vector error `|v − u|²` on the held-out pixels.
    /// Unscaled by r on purpose: the held-out noise is independent of the fit, so its expectation
    /// is the true vector mean squared error plus a constant — the quantity to minimise. (Scaled
    /// by 1/r², as in J, the score would be dominated by the axial component.)
    pub(super) fn score(&self, f: &DivFree, s: f64, report: &mut DivFreeReport) -> Result<f64, DivFreeError> {
        let n = f.nz * f.nx;
        let (mut fx, mut fz) = (vec![0.0; n], vec![0.0; n]);
        let mut total = 0.0;
        for ((data, rhs), held) in self.folds.iter().zip(&self.held) {
            if held.is_empty() {
                continue;
            }
            report.factorisations += 1;
            let llt = f.factor(data, s)?;
            let mut psi = rhs.clone();
            solve(&llt, &mut psi);
            f.velocity(&psi, &mut fx, &mut fz);
            total += held
                .iter()
                .map(|&p| self.w[p] * ((fx[p] - self.ux[p]).powi(2) + (fz[p] - self.uz[p]).powi(2)))
                .sum::<f64>();
        }
        Ok(total)
    }
}

/// Minimises `f(log10 S)` from `start`: evaluates start and start ± 0.5, walks in half-decade
/// steps while the minimum sits at an end (within [−3, 6]), then refines by the parabola through
/// the best point and its neighbours. Returns log10 S.
pub(super) fn bracket_min(
    start: f64,
    mut f: impl FnMut(f64) -> Result<f64, DivFreeError>,
) -> Result<f64, DivFreeError> {
    const STEP: f64 = 0.5;
    let (lo, hi) = (-3.0, 6.0);
    let x0 = start.clamp(lo + STEP, hi - STEP);
    let mut pts: Vec<(f64, f64)> = Vec::new();
    for x in [x0 - STEP, x0, x0 + STEP] {
        pts.push((x, f(x)?));
    }
    loop {
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        let k = pts.iter().enumerate().min_by(|a, b| a.1 .1.total_cmp(&b.1 .1)).map(|(k, _)| k).unwrap_or(0);
        if k == 0 && pts[0].0 - STEP >= lo - 1e-9 {
            let x = pts[0].0 - STEP;
            pts.push((x, f(x)?));
        } else if k == pts.len() - 1 && pts[k].0 + STEP <= hi + 1e-9 {
            let x = pts[k].0 + STEP;
            pts.push((x, f(x)?));
        } else {
            if k == 0 || k == pts.len() - 1 {
                return Ok(pts[k].0);
            }
            let ((x1, y1), (x2, y2), (x3, y3)) = (pts[k - 1], pts[k], pts[k + 1]);
            let den = (x2 - x1) * (y2 - y3) - (x2 - x3) * (y2 - y1);
            if den.abs() < f64::MIN_POSITIVE || !den.is_finite() {
                return Ok(x2);
            }
            let num = (x2 - x1).powi(2) * (y2 - y3) - (x2 - x3).powi(2) * (y2 - y1);
            return Ok((x2 - 0.5 * num / den).clamp(x1, x3));
        }
    }
}
