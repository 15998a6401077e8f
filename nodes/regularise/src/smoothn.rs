//! The smoother: penalised least squares in the DCT-II basis with GCV, weights, missing values and
//! robust re-weighting (Garcia 2010 CSDA; Garcia 2011 Exp Fluids; MATLAB `smoothn` 2009/03 rev.
//! 2014/10). See the crate documentation for the equations and the MATLAB/PyMUST differences.

use crate::dct::{DctN, DctNScratch};
use crate::gcv::{fminbnd, leverage, leverage_1d, s_for_leverage, H_MAX, H_MIN};
use crate::kernels::{for_each_chunk, for_each_component, gamma_sums, relax, CHUNK};
use crate::nearest::Nearest;
use crate::params::{Flavour, SmoothnError, SmoothnParams, WeightFunction};
use crate::robust;

/// GCV search tolerance on log10 S (MATLAB `errp`, `optimset('TolX', 0.1)`).
const LOG10_S_TOL: f64 = 0.1;
/// Robust passes (the initial fit plus two re-weighted fits, MATLAB `RobustStep < 4`).
const ROBUST_PASSES: u32 = 3;
/// A point whose final robust weight is below this counts as an outlier in
/// [`SmoothnReport::outlier_fraction`] (for bisquare: studentised residual u > 2.96).
pub const OUTLIER_WEIGHT: f64 = 0.5;

/// What one call of [`Smoothn::smooth`] did.
#[derive(Clone, Debug, PartialEq)]
pub struct SmoothnReport {
    /// Smoothing parameter used (given, or chosen by GCV). 0 for a single-point grid without a
    /// given S (nothing to smooth).
    pub s: f64,
    /// The last pass stopped on `tol_z` before `max_iter` iterations (MATLAB `exitflag`).
    pub converged: bool,
    /// Fraction of the valid points (finite in every component, weight > 0) whose final robust
    /// weight is below [`OUTLIER_WEIGHT`]; 0 when not robust. The final weights are those computed
    /// from the final fit ([`Smoothn::robust_weights`]).
    pub outlier_fraction: f64,
    /// Iterations, summed over the robust passes.
    pub iterations: u32,
    /// Number of GCV score evaluations (0 with a given S).
    pub gcv_evaluations: u32,
    /// Bounds of the GCV search on S, from the average leverage in [1e-6, 0.99].
    pub s_bounds: [f64; 2],
    /// Automatic S ended within 0.1 (log10) of a bound (MATLAB warns: set S by hand).
    pub s_at_bound: bool,
}

/// Per-component buffers (all grid-sized).
struct Component {
    /// Component number.
    index: usize,
    /// Data with missing values set to 0.
    y: Vec<f64>,
    /// Current smoothed field.
    z: Vec<f64>,
    /// DCT of the pseudo-data `Wtot (y − z) + z` (spectral layout).
    dcty: Vec<f64>,
    buf: Vec<f64>,
    buf2: Vec<f64>,
    /// The inverse `ŷ = IDCT(Γ ∘ DCTy)` at the best GCV point so far of the current search (its
    /// log10 S in [`Smoothn::yhat_at`]), which the update after the search reuses.
    yhat: Vec<f64>,
    dct: DctNScratch,
    /// Partial sums of the last pass over this component.
    sums: [f64; 3],
}

/// The residual buffer (`buf`), as read by the robust-weight functions.
impl AsRef<[f64]> for Component {
    fn as_ref(&self) -> &[f64] {
        &self.buf
    }
}

/// A smoothing workspace for one grid shape and component count. Reusing it for successive frames
/// of that shape allocates nothing and re-plans nothing.
pub struct Smoothn {
    shape: Vec<usize>,
    n: usize,
    plan: DctN,
    comps: Vec<Component>,
    valid: Vec<bool>,
    finite: Vec<bool>,
    w: Vec<f64>,
    wtot: Vec<f64>,
    robust_w: Vec<f64>,
    lambda_m: Vec<f64>,
    lambda_key: Option<(u32, Vec<f64>)>,
    /// `Some(n)` when `lambda_m` is an n × n array equal to its transpose (square grid, equal
    /// spacing): Γ is then divided on one triangle and mirrored.
    lambda_square: Option<usize>,
    gamma: Vec<f64>,
    power: Vec<f64>,
    /// Per-chunk partial sums of [`gamma_sums`].
    partials: Vec<[f64; 2]>,
    /// `keep` masks of the initial-guess low-pass (MATLAB, PyMUST) in spectral layout.
    keep: [Vec<bool>; 2],
    /// Squared ratio unnormalised/orthonormal DCT-II per coefficient (PyMUST GCV), on demand.
    pymust_scale: Vec<f64>,
    nearest: Nearest,
    scratch: Vec<f64>,
    medians: Vec<f64>,
    /// Normalised spacing of every axis, and of the non-singleton axes.
    spacing: Vec<f64>,
    spacing_ns: Vec<f64>,
    /// log10 S whose `ŷ` every component holds in `yhat` (None: none valid for this iteration).
    yhat_at: Option<f64>,
}

/// Smooths `data` (`components × grid`, component-major, each component row-major) in one call.
/// Convenience wrapper over [`Smoothn`]; returns the smoothed field and the report.
pub fn smoothn(
    data: &[f64],
    shape: &[usize],
    components: usize,
    weights: Option<&[f64]>,
    params: &SmoothnParams,
) -> Result<(Vec<f64>, SmoothnReport), SmoothnError> {
    let mut ws = Smoothn::new(shape, components)?;
    let mut out = vec![0.0; data.len()];
    let report = ws.smooth(data, weights, params, &mut out)?;
    Ok((out, report))
}

impl Smoothn {
    /// Plans a workspace for a row-major grid of `shape` (any number of axes, each ≥ 1) and
    /// `components ≥ 1` jointly smoothed components.
    pub fn new(shape: &[usize], components: usize) -> Result<Self, SmoothnError> {
        if shape.is_empty() || shape.contains(&0) || components == 0 {
            return Err(SmoothnError::InvalidGrid { shape: shape.to_vec(), components });
        }
        let plan = DctN::new(shape);
        let n = plan.len();
        let comps = (0..components)
            .map(|index| Component {
                index,
                y: vec![0.0; n],
                z: vec![0.0; n],
                dcty: vec![0.0; n],
                buf: vec![0.0; n],
                buf2: vec![0.0; n],
                yhat: vec![0.0; n],
                dct: plan.make_scratch(),
                sums: [0.0; 3],
            })
            .collect();
        let mut keep = [vec![false; n], vec![false; n]];
        plan.spectral_indices(|p, k| {
            keep[0][p] = k.iter().zip(shape).all(|(k, n)| *k < n.div_ceil(10));
            keep[1][p] = k.iter().zip(shape).all(|(k, n)| *k as f64 / *n as f64 <= 0.1);
        });
        Ok(Self {
            shape: shape.to_vec(),
            n,
            plan,
            comps,
            valid: vec![false; n],
            finite: vec![false; n],
            w: vec![0.0; n],
            wtot: vec![0.0; n],
            robust_w: vec![1.0; n],
            lambda_m: vec![0.0; n],
            lambda_key: None,
            lambda_square: None,
            gamma: vec![0.0; n],
            power: vec![0.0; n],
            partials: Vec::with_capacity(n.div_ceil(CHUNK)),
            keep,
            pymust_scale: Vec::new(),
            nearest: Nearest::default(),
            scratch: Vec::new(),
            medians: Vec::new(),
            spacing: Vec::new(),
            spacing_ns: Vec::new(),
            yhat_at: None,
        })
    }

    /// Grid shape.
    pub fn shape(&self) -> &[usize] {
        &self.shape
    }

    /// Number of components.
    pub fn components(&self) -> usize {
        self.comps.len()
    }

    /// Final robust weight of every grid point from the last call (1 when not robust, 0 where
    /// data are missing).
    pub fn robust_weights(&self) -> &[f64] {
        &self.robust_w
    }

    /// Bytes held by the workspace (for checking that memory grows linearly with the grid).
    pub fn workspace_bytes(&self) -> usize {
        let f = std::mem::size_of::<f64>();
        let per_comp: usize = self
            .comps
            .iter()
            .map(|c| {
                (c.y.capacity() + c.z.capacity() + c.dcty.capacity() + c.buf.capacity() + c.buf2.capacity()) * f
                    + c.yhat.capacity() * f
                    + c.dct.bytes()
            })
            .sum();
        let grid = (self.w.capacity() + self.wtot.capacity() + self.robust_w.capacity() + self.lambda_m.capacity()) * f
            + (self.gamma.capacity() + self.power.capacity() + self.pymust_scale.capacity() + self.scratch.capacity())
                * f
            + self.valid.capacity()
            + self.finite.capacity()
            + self.keep[0].capacity()
            + self.keep[1].capacity();
        per_comp + grid + self.nearest.bytes()
    }

    /// Smooths `data` (`components × grid`, component-major; NaN and ±inf are missing values) with
    /// optional per-point `weights` (grid-sized, finite, ≥ 0) into `out` (same layout as `data`).
    pub fn smooth(
        &mut self,
        data: &[f64],
        weights: Option<&[f64]>,
        params: &SmoothnParams,
        out: &mut [f64],
    ) -> Result<SmoothnReport, SmoothnError> {
        // Run on a rayon worker so that the calling thread takes part in every parallel section
        // (one hand-off per call instead of one per section).
        #[cfg(feature = "parallel")]
        if rayon::current_thread_index().is_none() && rayon::current_num_threads() > 1 {
            return rayon::scope(|_| self.smooth_dispatch(data, weights, params, out));
        }
        self.smooth_dispatch(data, weights, params, out)
    }

    /// [`Self::smooth_here`] compiled for AVX2 where the CPU has it: the element-wise loops of the
    /// iteration (pseudo-data, residuals, weights, medians' inputs) then use 4-lane vectors. No
    /// FMA is enabled and no sum is reordered, so the results are the same bits either way.
    fn smooth_dispatch(
        &mut self,
        data: &[f64],
        weights: Option<&[f64]>,
        params: &SmoothnParams,
        out: &mut [f64],
    ) -> Result<SmoothnReport, SmoothnError> {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked at run time).
            return unsafe { self.smooth_avx2(data, weights, params, out) };
        }
        self.smooth_here(data, weights, params, out)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn smooth_avx2(
        &mut self,
        data: &[f64],
        weights: Option<&[f64]>,
        params: &SmoothnParams,
        out: &mut [f64],
    ) -> Result<SmoothnReport, SmoothnError> {
        self.smooth_here(data, weights, params, out)
    }

    #[inline(always)]
    fn smooth_here(
        &mut self,
        data: &[f64],
        weights: Option<&[f64]>,
        params: &SmoothnParams,
        out: &mut [f64],
    ) -> Result<SmoothnReport, SmoothnError> {
        params.validate()?;
        let (n, ncomp) = (self.n, self.comps.len());
        let check = |what, got: usize, expected| {
            if got == expected {
                Ok(())
            } else {
                Err(SmoothnError::LengthMismatch { what, got, expected })
            }
        };
        check("data", data.len(), n * ncomp)?;
        check("out", out.len(), n * ncomp)?;
        if let Some(w) = weights {
            check("weights", w.len(), n)?;
        }
        if let Some(sp) = &params.spacing {
            if sp.len() != self.shape.len() {
                return Err(SmoothnError::SpacingLength { got: sp.len(), expected: self.shape.len() });
            }
        }
        let pym = params.flavour == Flavour::Pymust;

        let (nof, max_w) = self.ingest(data, weights, pym)?;
        let mut is_weighted = if pym { self.w.iter().any(|w| *w != 1.0) } else { self.w.iter().any(|w| *w < 1.0) };

        let m = params.order;
        // Normalised spacing over all axes (MATLAB dI = dI/max(dI)), and over non-singleton axes.
        self.spacing.clear();
        match &params.spacing {
            Some(sp) => {
                let mx = sp.iter().copied().fold(0.0, f64::max);
                self.spacing.extend(sp.iter().map(|d| d / mx));
            }
            None => self.spacing.resize(self.shape.len(), 1.0),
        }
        self.spacing_ns.clear();
        self.spacing_ns.extend(self.shape.iter().zip(&self.spacing).filter(|(n, _)| **n > 1).map(|(_, d)| *d));
        let n_dims = self.spacing_ns.len() as u32;
        let s_bounds = if pym {
            let s_min = if m == 2 {
                let t = (1.0 + (1.0 + 8.0 * H_MAX.powf(2.0)).sqrt()) / 4.0 / H_MAX.powf(4.0);
                (t - 1.0) / 16.0
            } else {
                s_for_leverage(H_MAX, m, 1)
            };
            [s_min, s_for_leverage(H_MIN, m, 1)]
        } else {
            [s_for_leverage(H_MAX, m, n_dims), s_for_leverage(H_MIN, m, n_dims)]
        };

        if n == 1 {
            out.copy_from_slice(data);
            return Ok(SmoothnReport {
                s: params.s.unwrap_or(0.0),
                converged: true,
                outlier_fraction: 0.0,
                iterations: 0,
                gcv_evaluations: 0,
                s_bounds,
                s_at_bound: false,
            });
        }
        self.update_lambda(m);
        if pym && self.pymust_scale.len() != n {
            self.pymust_scale.resize(n, 0.0);
            let (shape, scale) = (&self.shape, &mut self.pymust_scale);
            self.plan.spectral_indices(|p, k| {
                scale[p] = k.iter().zip(shape).map(|(k, n)| if *k == 0 { 4.0 } else { 2.0 } * *n as f64).product();
            });
        }

        // Initial guess (weighted/missing data) or zeros.
        if is_weighted {
            self.initial_guess(nof < n, pym);
        } else {
            self.comps.iter_mut().for_each(|c| c.z.fill(0.0));
        }

        let auto = params.s.is_none();
        let mut s = params.s.unwrap_or(s_bounds[0]);
        if !auto {
            self.set_gamma(s);
        }
        self.wtot.copy_from_slice(&self.w);
        let rf = if is_weighted { 1.75 } else { 1.0 };
        let (noe, nof) = (n as f64, nof as f64);
        let (mut iterations, mut gcv_evaluations, mut converged) = (0u32, 0u32, false);
        for pass in 1..=ROBUST_PASSES {
            let sum_wtot: f64 = self.wtot.iter().sum();
            let fast_rss = if pym { sum_wtot / max_w / noe > 0.95 } else { sum_wtot / noe > 0.9 };
            let mut tol = 1.0f64;
            let mut nit = 0u32;
            while tol > params.tol_z && nit < params.max_iter {
                nit += 1;
                let (plan, wtot) = (&self.plan, &self.wtot);
                for_each_component(&mut self.comps, |c| {
                    // DCT of the pseudo-data Wtot (y − z) + z.
                    plan.forward_pseudo((&c.y, &c.z, wtot), &mut c.buf, &mut c.dcty, &mut c.dct);
                });
                if auto && nit.is_power_of_two() {
                    let (p, evals) = self.minimise_gcv(s_bounds, fast_rss, pym, nof, noe);
                    gcv_evaluations += evals;
                    s = 10f64.powf(p);
                    self.set_gamma(s);
                }
                let (plan, gamma) = (&self.plan, &self.gamma);
                // The GCV search just computed ŷ at the chosen S (same Γ bits, same transform):
                // reuse it instead of transforming again.
                let reuse = self.yhat_at.take().is_some_and(|p| 10f64.powf(p).to_bits() == s.to_bits());
                for_each_component(&mut self.comps, |c| {
                    if reuse {
                        c.sums = relax(&mut c.z, &c.yhat, rf);
                    } else {
                        plan.inverse_weighted(&c.dcty, Some(gamma), &mut c.buf2, &mut c.dct);
                        c.sums = relax(&mut c.z, &c.buf2, rf);
                    }
                });
                let sum = |i: usize| self.comps.iter().map(|c| c.sums[i]).sum::<f64>();
                // MATLAB: ‖z_old − z‖/‖z‖ (new iterate); PyMUST divides by the old iterate, and in its
                // first pass z0 aliases z so the change reads 0 and the pass stops after one iteration.
                let denominator = if pym { sum(2) } else { sum(1) };
                tol = if !is_weighted || (pym && pass == 1) { 0.0 } else { sum(0).sqrt() / denominator.sqrt() };
            }
            iterations += nit;
            converged = nit < params.max_iter;
            if !params.robust {
                break;
            }
            self.reweight(s, m, params.weight_function, pym);
            is_weighted = true;
        }

        for (c, comp) in self.comps.iter().enumerate() {
            out[c * n..(c + 1) * n].copy_from_slice(&comp.z);
        }
        let n_valid = self.valid.iter().filter(|v| **v).count();
        let outliers = if params.robust {
            self.robust_w.iter().zip(&self.valid).filter(|(r, v)| **v && **r < OUTLIER_WEIGHT).count()
        } else {
            0
        };
        let near = |b: f64| (s.log10() - b.log10()).abs() < LOG10_S_TOL;
        Ok(SmoothnReport {
            s,
            converged,
            outlier_fraction: outliers as f64 / n_valid as f64,
            iterations,
            gcv_evaluations,
            s_bounds,
            s_at_bound: auto && (near(s_bounds[0]) || near(s_bounds[1])),
        })
    }

    /// Copies the data (missing values → 0), marks finite points, checks and stores the weights
    /// (0 where data are missing; divided by their maximum for MATLAB). Returns (finite points, max W).
    fn ingest(&mut self, data: &[f64], weights: Option<&[f64]>, pym: bool) -> Result<(usize, f64), SmoothnError> {
        let (n, ncomp) = (self.n, self.comps.len());
        // Missing values and weights (zero weight where any component is not finite).
        // Component by component and point by point in contiguous loops (they vectorise); the
        // same mask, weights, count and maximum as one loop over the points.
        if let Some(w) = weights {
            if let Some(p) = w.iter().position(|wp| !(wp.is_finite() && *wp >= 0.0)) {
                return Err(SmoothnError::InvalidWeight { index: p, value: w[p] });
            }
        }
        for (c, comp) in data.chunks_exact(n).take(ncomp).enumerate() {
            if c == 0 {
                self.finite.iter_mut().zip(comp).for_each(|(f, d)| *f = d.is_finite());
            } else {
                self.finite.iter_mut().zip(comp).for_each(|(f, d)| *f &= d.is_finite());
            }
        }
        match weights {
            Some(w) => {
                self.w.iter_mut().zip(w).zip(&self.finite).for_each(|((o, w), f)| *o = if *f { *w } else { 0.0 })
            }
            None => self.w.iter_mut().zip(&self.finite).for_each(|(o, f)| *o = if *f { 1.0 } else { 0.0 }),
        }
        let nof = self.finite.iter().filter(|f| **f).count();
        let max_w = self.w.iter().fold(0.0f64, |m, w| m.max(*w));
        if max_w <= 0.0 {
            return Err(SmoothnError::NoValidData { points: n });
        }
        if !pym {
            self.w.iter_mut().for_each(|w| *w /= max_w);
        }
        for (v, w) in self.valid.iter_mut().zip(&self.w) {
            *v = *w > 0.0;
        }
        for (c, comp) in self.comps.iter_mut().enumerate() {
            for ((y, d), fin) in comp.y.iter_mut().zip(&data[c * n..(c + 1) * n]).zip(&self.finite) {
                *y = if *fin { *d } else { 0.0 };
            }
        }
        self.robust_w.iter_mut().zip(&self.valid).for_each(|(r, v)| *r = if *v { 1.0 } else { 0.0 });
        Ok((nof, max_w))
    }

    /// Robust step: weights from the studentised residuals of the current fit, `Wtot = W · w(u)`.
    fn reweight(&mut self, s: f64, m: u32, wf: WeightFunction, pym: bool) {
        let h = if pym {
            match m {
                1 => 1.0 / (1.0 + 8.0 * s / self.spacing[0]).sqrt(),
                _ => leverage_1d(s / self.spacing[0].powi(4), 2),
            }
        } else {
            leverage(s, m, &self.spacing_ns)
        };
        // Residuals and (MATLAB) per-component medians, in parallel.
        let finite = &self.finite;
        for_each_component(&mut self.comps, |c| {
            for ((b, y), z) in c.buf.iter_mut().zip(&c.y).zip(&c.z) {
                *b = y - z;
            }
            if !pym {
                c.sums[0] = robust::valid_median(&c.buf, finite, &mut c.buf2);
            }
        });
        self.medians.clear();
        if pym {
            // One median of every component's residuals (PyMUST).
            self.scratch.clear();
            let all = finite.iter().all(|f| *f);
            for c in &self.comps {
                if all {
                    self.scratch.extend_from_slice(&c.buf);
                } else {
                    self.scratch.extend(c.buf.iter().zip(finite).filter(|(_, ok)| **ok).map(|(v, _)| *v));
                }
            }
            let m = robust::median(&mut self.scratch);
            self.medians.resize(self.comps.len(), m);
        } else {
            self.medians.extend(self.comps.iter().map(|c| c.sums[0]));
        }
        let mad = robust::vector_mad(&self.comps, finite, &self.medians, &mut self.scratch);
        let scale = robust::studentise_scale(mad, h);
        let comps = &self.comps;
        for_each_chunk(&mut self.robust_w, |i, out| robust::weights_of(comps, i * CHUNK, scale, wf, out));
        for ((wt, w), r) in self.wtot.iter_mut().zip(&self.w).zip(&mut self.robust_w) {
            if *w == 0.0 {
                *r = 0.0;
            }
            *wt = w * *r;
        }
    }

    /// Λ^m in spectral layout: `Λ(k) = Σ_a (2 − 2cos(π k_a / n_a)) / dI_a²`, cached per (m, dI).
    fn update_lambda(&mut self, m: u32) {
        if self.lambda_key.as_ref().is_some_and(|(km, ks)| *km == m && *ks == self.spacing) {
            return;
        }
        let (shape, lm, spacing) = (&self.shape, &mut self.lambda_m, &self.spacing);
        // each axis' terms once (n_a cosines, not one per sample and axis), summed per sample
        // in axis order as before
        let terms: Vec<Vec<f64>> = shape
            .iter()
            .zip(spacing)
            .map(|(&n, d)| {
                (0..n).map(|k| (2.0 - 2.0 * (std::f64::consts::PI * k as f64 / n as f64).cos()) / (d * d)).collect()
            })
            .collect();
        self.plan.spectral_indices(|p, k| {
            let mut l = 0.0;
            for (k, t) in k.iter().zip(&terms) {
                l += t[*k];
            }
            lm[p] = l.powi(m as i32);
        });
        self.lambda_key = Some((m, self.spacing.clone()));
        self.lambda_square = match self.shape[..] {
            [a, b] if a == b && (0..a).all(|i| (0..i).all(|j| lm[i * a + j].to_bits() == lm[j * a + i].to_bits())) => {
                Some(a)
            }
            _ => None,
        };
    }

    /// `Γ = 1 / (1 + S Λ^m)`.
    fn set_gamma(&mut self, s: f64) {
        // The GCV's kernel (the same operation per element, vectorised); its sums are not needed.
        gamma_sums(&mut self.gamma, &self.lambda_m, None, s, self.lambda_square, &mut self.partials);
    }

    /// Minimises the GCV score over log10 S; returns (log10 S, evaluations).
    fn minimise_gcv(&mut self, bounds: [f64; 2], fast_rss: bool, pym: bool, nof: f64, noe: f64) -> (f64, u32) {
        if fast_rss {
            // RSS = Σ_k (Γ_k − 1)² Σ_c DCTy_c(k)²: no inverse transform needed (Parseval).
            self.power.fill(0.0);
            for c in &self.comps {
                for (p, d) in self.power.iter_mut().zip(&c.dcty) {
                    *p += d * d;
                }
            }
            if pym {
                self.power.iter_mut().zip(&self.pymust_scale).for_each(|(p, f)| *p *= f);
            }
        }
        // The best score so far, by fminbnd's own rule (a new point replaces the best when its
        // score is ≤ the best's; the first point is the best), so that `yhat` ends at its minimum.
        let mut best_score: Option<f64> = None;
        self.yhat_at = None;
        let score = |p: f64| -> f64 {
            let s = 10f64.powf(p);
            let power = fast_rss.then_some(self.power.as_slice());
            let [tr_h, fast] =
                gamma_sums(&mut self.gamma, &self.lambda_m, power, s, self.lambda_square, &mut self.partials);
            let rss = if fast_rss {
                fast
            } else {
                // Σ over valid points of Wtot (y − ŷ)²; Wtot = 0 (exactly) where data are missing.
                // ŷ is kept in buf2 (buf: work space of 3-D and higher transforms).
                let (plan, gamma, wtot) = (&self.plan, &self.gamma, &self.wtot);
                for_each_component(&mut self.comps, |c| {
                    let (y, work, keep) = (&c.y, &mut c.buf, Some(&mut c.buf2[..]));
                    c.sums[0] = plan.weighted_rss_keep(&c.dcty, Some(gamma), (y, wtot), work, keep, &mut c.dct);
                });
                self.comps.iter().map(|c| c.sums[0]).sum()
            };
            let denom = 1.0 - tr_h / noe;
            let score = rss / nof / (denom * denom);
            if !fast_rss && best_score.is_none_or(|b| score <= b) {
                best_score = Some(score);
                self.comps.iter_mut().for_each(|c| std::mem::swap(&mut c.yhat, &mut c.buf2));
                self.yhat_at = Some(p);
            }
            score
        };
        let best = fminbnd(score, bounds[0].log10(), bounds[1].log10(), LOG10_S_TOL);
        if self.yhat_at.is_some_and(|p| p.to_bits() != best.x.to_bits()) {
            self.yhat_at = None;
        }
        (best.x, best.evaluations)
    }

    /// MATLAB `InitialGuess`: nearest-neighbour fill of the missing values, then keep only the
    /// lowest `ceil(n_a/10)` DCT coefficients along every axis, per component. PyMUST keeps
    /// `k_a/n_a ≤ 0.1` and zeroes every component after the first (its mask spans the component
    /// axis too).
    fn initial_guess(&mut self, missing: bool, pym: bool) {
        if missing {
            self.nearest.compute(&self.shape, &self.finite);
        }
        let nearest = self.nearest.nearest();
        let (plan, finite, keep) = (&self.plan, &self.finite, &self.keep[usize::from(pym)]);
        let ncomp = self.comps.len() as f64;
        for_each_component(&mut self.comps, |c| {
            if pym && c.index as f64 / ncomp > 0.1 {
                c.z.fill(0.0);
                return;
            }
            for (p, b) in c.buf.iter_mut().enumerate() {
                *b = if !missing || finite[p] { c.y[p] } else { c.y[nearest[p]] };
            }
            plan.forward(&c.buf, &mut c.buf2, &mut c.dct);
            for (v, k) in c.buf2.iter_mut().zip(keep) {
                if !k {
                    *v = 0.0;
                }
            }
            plan.inverse(&c.buf2, &mut c.z, &mut c.dct);
        });
    }
}
