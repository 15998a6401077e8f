//! Divergence-free regularisation of 2-D vector fields: a penalised least-squares fit of a
//! **stream function**, so that the fitted velocity satisfies the 2-D continuity equation
//! `∂vx/∂x + ∂vz/∂z = 0` exactly (discretely).
//!
//! # Why
//! In vector Doppler the lateral component is far noisier than the axial one: with a 0° transmit
//! and receive angles ±φ, `vx = (v_D(−φ) − v_D(+φ))/sin φ` and `vz ∝ (v_D(−φ) + v_D(+φ))/(1 + cos φ)`,
//! so independent Doppler errors reach vx amplified by `(1 + cos φ)/sin φ` = 7.6 at φ = 15°. In a
//! 2-D incompressible flow the two components are not independent: `vx = ∂ψ/∂z`, `vz = −∂ψ/∂x`
//! for one scalar ψ. Fitting ψ to both components, each weighted by its own noise level, lets the
//! precise axial data and the mass balance carry the lateral component: along a vessel the
//! lateral noise is averaged over everything that continuity connects, not over a smoothing
//! window. This is the idea of Garcia et al.'s colour-Doppler vector flow mapping (IEEE TMI 29,
//! 2010) and Assi et al. (PMB 62, 2017), applied to both measured components.
//!
//! # Model
//! Grid `nz × nx` (rows along z, columns along x, row-major), spacing `(dz, dx)`. ψ lives on the
//! `(nz + 1) × (nx + 1)` cell corners; the velocity of pixel (i, j) is
//! `vx = (ψ[i+1,j] + ψ[i+1,j+1] − ψ[i,j] − ψ[i,j+1]) / (2 dz)`,
//! `vz = −(ψ[i,j+1] + ψ[i+1,j+1] − ψ[i,j] − ψ[i+1,j]) / (2 dx)`.
//! Then the divergence between four pixels,
//! `(vx[i,j+1] + vx[i+1,j+1] − vx[i,j] − vx[i+1,j])/(2dx) + (vz[i+1,j] + vz[i+1,j+1] − vz[i,j] − vz[i,j+1])/(2dz)`,
//! vanishes identically (a telescoping sum; [`divergence`] computes it, the tests check it).
//! ψ minimises
//!
//! `J(ψ) = Σ_p w_p [ (vx_p − ux_p)²/r² + (vz_p − uz_p)² ] + S Σ_{c∈{x,z}} Σ_{a∈{x,z}} ‖h^m D_a^m v_c‖²`
//!
//! with `u` the data, `w` the weights (0 = missing), `r = σx/σz` the noise ratio of the two
//! components, `D_a^m` the m-th finite difference along axis a divided by `d_a^m` and `h =
//! max(dz, dx)` (so S is dimensionless, in pixel units like smoothn's S). The penalty's null
//! space holds the velocity fields that are polynomials of degree < m on each axis: with the
//! default m = 3, parabolic (Poiseuille) profiles are not penalised. ψ's own null space (a
//! constant and the corner checkerboard, the only fields with zero velocity under this stencil,
//! both invisible in the velocity) is removed by pinning ψ to 0 at the corners (0, 0) and (0, 1).
//!
//! The normal equations are a sparse SPD system (about 30 non-zeros per column), solved by a
//! sparse Cholesky factorisation (faer, AMD ordering); the symbolic factorisation is computed
//! once per grid and reused for every S, weight set and frame.
//!
//! # Unsupervised choices
//! * **Noise ratio** r (absent from the parameters): the ratio of the median absolute deviations
//!   of the 5-point Laplacian of each component over the pixels whose stencil is valid — the
//!   Laplacian of a smooth flow is small next to that of pixel-scale noise.
//! * **S** (absent): minimises a four-fold **block cross-validation** score (folds are
//!   `cv_block`-pixel squares in a 2 × 2 pattern; each fold is fitted without its blocks and scored
//!   on them, RSS weighted as in J). The Doppler noise is correlated over a resolution cell, so
//!   GCV, which assumes independent noise per pixel, under-smooths it (on a carotid packet GCV
//!   picks S ≈ 0.3, block CV ≈ 3–10); `selection = "gcv"` keeps GCV
//!   (`n·RSS/(n − tr H)²`, `tr H` by Hutchinson's method with `gcv_probes` Rademacher vectors,
//!   fixed seed). The search walks log10 S in half-decade steps from a start (1, or the caller's
//!   hint) until bracketed, then refines by a parabola; S is chosen in the first pass and kept by
//!   the robust passes.
//! * **Robust** (default): as smoothn, 3 passes; after each, bisquare (or Cauchy, Talworth)
//!   weights of the studentised residual norm `‖((vx − ux)/r, vz − uz) − median‖ / (1.4826 MAD √(1 − h̄))`
//!   (per-component medians; MAD = median of those norms; h̄ = tr H / n).
//!
//! * **No-slip wall** (optional, [`DivFree::fit_with_wall`], [`wall_from_power`]): pixels outside
//!   the lumen (where the smoothed Doppler power falls below the blood's level by a threshold)
//!   get a zero-velocity prior of fixed weight. It is not data: the noise ratio, the robust
//!   weights and the cross-validation score use the measured pixels only, and every
//!   cross-validation fold keeps the whole prior. Without it the fit extrapolates the blurred
//!   near-wall Doppler (which over-reads: the resolution cell there averages only the faster
//!   interior) across the wall.
//!
//! No IPC: the `regulariser` node calls it (`method = "divergence-free"`).

use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::{Llt, SymbolicLlt};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};
use faer::{MatMut, Side};
use serde::{Deserialize, Serialize};

use crate::WeightFunction;

mod select;
mod wall;
use select::{bracket_min, BlockCv};
pub use wall::{blood_from_power, wall_from_power, NoSlipParams, WallRule};

/// Parameters of [`DivFree`]. Every field has a default; unknown fields are rejected.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DivFreeParams {
    /// Smoothing parameter S (dimensionless, > 0); absent: generalised cross-validation.
    pub s: Option<f64>,
    /// Penalty order m: 2 or 3 (default; parabolic profiles are not penalised).
    pub order: u32,
    /// Noise ratio r = σ(vx)/σ(vz) of the data (> 0); absent: estimated from the data.
    pub noise_ratio: Option<f64>,
    /// Iteratively re-weighted (3 passes) against outliers. Default true.
    pub robust: bool,
    /// Robust weight function (bisquare, cauchy, talworth).
    pub weight_function: WeightFunction,
    /// How S is chosen when absent: `block-cv` (default) or `gcv`.
    pub selection: Selection,
    /// Block size (pixels, 2 ..= 4096) of the cross-validation folds; default 16. Make it larger
    /// than a resolution cell of the imaging.
    pub cv_block: usize,
    /// Random probe vectors for the trace estimate (GCV and the robust leverage), 1 ..= 64
    /// (default 8).
    pub gcv_probes: usize,
}

/// Choice of the smoothing parameter S.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Selection {
    /// Four-fold cross-validation over blocks of `cv_block` pixels (the Doppler noise is correlated
    /// over a resolution cell; block folds keep held-out noise independent of the fitted data).
    #[default]
    BlockCv,
    /// Generalised cross-validation (assumes independent noise per pixel: under-smooths
    /// correlated noise).
    Gcv,
}

impl Default for DivFreeParams {
    fn default() -> Self {
        Self {
            s: None,
            order: 3,
            noise_ratio: None,
            robust: true,
            weight_function: WeightFunction::Bisquare,
            selection: Selection::BlockCv,
            cv_block: 16,
            gcv_probes: 8,
        }
    }
}

/// Errors of the divergence-free fit.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum DivFreeError {
    /// A parameter is out of range.
    #[error("invalid parameter `{field}` = {value}: allowed {allowed}")]
    InvalidParameter {
        /// Field name.
        field: &'static str,
        /// The offending value.
        value: String,
        /// The allowed range.
        allowed: &'static str,
    },
    /// A slice does not match the grid.
    #[error("`{what}` has {got} values but the {nz} × {nx} grid needs {expected}")]
    LengthMismatch {
        /// Which argument.
        what: &'static str,
        /// Its length.
        got: usize,
        /// Expected length.
        expected: usize,
        /// Grid rows.
        nz: usize,
        /// Grid columns.
        nx: usize,
    },
    /// No pixel has data (finite components and a weight > 0).
    #[error("no valid data: every pixel is missing (non-finite) or has weight 0")]
    NoData,
    /// The sparse factorisation failed (not expected for valid input: the system is SPD).
    #[error("sparse Cholesky factorisation failed: {0}")]
    Factorisation(String),
}

/// What a fit did.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DivFreeReport {
    /// Smoothing parameter used (last pass).
    pub s: f64,
    /// Noise ratio r = σx/σz used.
    pub noise_ratio: f64,
    /// Whether S was chosen by GCV (asked for, or block CV impossible because the data region is
    /// smaller than two blocks); false: given, or block cross-validation.
    pub s_from_gcv: bool,
    /// Estimated trace of the influence matrix (last pass).
    pub trace_h: f64,
    /// Valid data values n (2 × valid pixels).
    pub n_data: usize,
    /// Fraction of valid pixels with a robust weight < 0.5.
    pub outlier_fraction: f64,
    /// Number of fits (passes × GCV evaluations).
    pub factorisations: usize,
    /// Largest |discrete divergence| of the result relative to max|v|/min(dz, dx) (round-off).
    pub max_divergence: f64,
}

/// Relative weight of the zero-velocity ridge on every pixel ([`DivFree::data_matrix`]).
const RIDGE: f64 = 1e-6;

/// A linear functional of ψ: at most `CAP` (corner, coefficient) pairs.
const CAP: usize = 24;

#[derive(Clone, Copy)]
struct Functional {
    idx: [usize; CAP],
    coef: [f64; CAP],
    len: usize,
}

impl Functional {
    fn new() -> Self {
        Self { idx: [0; CAP], coef: [0.0; CAP], len: 0 }
    }
    fn add(&mut self, i: usize, c: f64) {
        if let Some(k) = self.idx[..self.len].iter().position(|&j| j == i) {
            self.coef[k] += c;
        } else {
            self.idx[self.len] = i;
            self.coef[self.len] = c;
            self.len += 1;
        }
    }
    fn dot(&self, psi: &[f64]) -> f64 {
        (0..self.len).map(|k| self.coef[k] * psi[self.idx[k]]).sum()
    }
}

/// Binomial difference coefficients of order m (forward, `Σ c_k f[i + k]`).
fn diff_coefs(m: u32) -> &'static [f64] {
    match m {
        2 => &[1.0, -2.0, 1.0],
        _ => &[-1.0, 3.0, -3.0, 1.0],
    }
}

/// Divergence-free fitter for one grid (reusable across frames; keeps the symbolic factorisation).
pub struct DivFree {
    nz: usize,
    nx: usize,
    dz: f64,
    dx: f64,
    order: u32,
    n_psi: usize,
    /// CSC pattern of the lower triangle of the normal matrix.
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    diag: Vec<usize>,
    symbolic: SymbolicSparseColMat<usize>,
    llt_symbolic: SymbolicLlt<usize>,
    /// Penalty part of the matrix (S = 1), on the pattern.
    pen_vals: Vec<f64>,
}

impl DivFree {
    /// Prepares the fitter for an `nz × nx` grid with spacing `(dz, dx)` and penalty order
    /// `order` (2 or 3). Errors: grid smaller than `order + 2` on an axis or larger than 4·10⁶
    /// pixels, spacing not finite and > 0.
    pub fn new(shape: [usize; 2], spacing: [f64; 2], order: u32) -> Result<Self, DivFreeError> {
        let [nz, nx] = shape;
        let bad = |field, value: String, allowed| Err(DivFreeError::InvalidParameter { field, value, allowed });
        if !(order == 2 || order == 3) {
            return bad("order", format!("{order}"), "2 or 3");
        }
        let min = order as usize + 2;
        if nz < min || nx < min || nz.saturating_mul(nx) > 4_000_000 {
            return bad(
                "shape",
                format!("{nz} × {nx}"),
                "at least order + 2 pixels along each axis and at most 4 000 000 pixels",
            );
        }
        let [dz, dx] = spacing;
        if !(dz.is_finite() && dz > 0.0 && dx.is_finite() && dx > 0.0) {
            return bad("spacing", format!("{dz}, {dx}"), "finite values > 0");
        }
        let n_psi = (nz + 1) * (nx + 1);
        let mut me = Self {
            nz,
            nx,
            dz,
            dx,
            order,
            n_psi,
            col_ptr: Vec::new(),
            row_idx: Vec::new(),
            diag: Vec::new(),
            symbolic: SymbolicSparseColMat::new_checked(0, 0, vec![0], None, Vec::new()),
            llt_symbolic: SymbolicLlt::try_new(
                SymbolicSparseColMat::<usize>::new_checked(0, 0, vec![0], None, Vec::new()).as_ref(),
                Side::Lower,
            )
            .map_err(|e| DivFreeError::Factorisation(format!("{e:?}")))?,
            pen_vals: Vec::new(),
        };
        // Pattern: every pair of corners that share a data or penalty functional.
        let mut cols: Vec<Vec<usize>> = vec![Vec::new(); n_psi];
        let mut visit = |f: &Functional| {
            for a in 0..f.len {
                for b in 0..f.len {
                    let (p, q) = (f.idx[a], f.idx[b]);
                    if p >= q {
                        cols[q].push(p);
                    }
                }
            }
        };
        for i in 0..nz {
            for j in 0..nx {
                visit(&me.vx_functional(i, j));
                visit(&me.vz_functional(i, j));
            }
        }
        me.for_each_penalty(|f| visit(f));
        for (q, c) in cols.iter_mut().enumerate() {
            c.push(q); // the ridge on the diagonal
            c.sort_unstable();
            c.dedup();
        }
        let mut col_ptr = Vec::with_capacity(n_psi + 1);
        let mut row_idx = Vec::new();
        let mut diag = Vec::with_capacity(n_psi);
        col_ptr.push(0);
        for (q, c) in cols.iter().enumerate() {
            let start = row_idx.len();
            row_idx.extend_from_slice(c);
            diag.push(start + c.iter().position(|&p| p == q).unwrap_or(0));
            col_ptr.push(row_idx.len());
        }
        me.symbolic = SymbolicSparseColMat::new_checked(n_psi, n_psi, col_ptr.clone(), None, row_idx.clone());
        me.llt_symbolic = SymbolicLlt::try_new(me.symbolic.as_ref(), Side::Lower)
            .map_err(|e| DivFreeError::Factorisation(format!("{e:?}")))?;
        me.col_ptr = col_ptr;
        me.row_idx = row_idx;
        me.diag = diag;
        let mut pen = vec![0.0; me.row_idx.len()];
        me.for_each_penalty(|f| me_accumulate(&me_pattern(&me.col_ptr, &me.row_idx), &mut pen, f, 1.0));
        me.pen_vals = pen;
        Ok(me)
    }

    #[doc(hidden)]
    pub fn pattern(&self) -> (&[usize], &[usize]) {
        (&self.col_ptr, &self.row_idx)
    }

    /// Penalty order the fitter was built with.
    pub fn order(&self) -> u32 {
        self.order
    }

    /// Grid shape `[nz, nx]`.
    pub fn shape(&self) -> [usize; 2] {
        [self.nz, self.nx]
    }

    fn corner(&self, i: usize, j: usize) -> usize {
        i * (self.nx + 1) + j
    }

    /// vx of pixel (i, j) as a functional of ψ.
    fn vx_functional(&self, i: usize, j: usize) -> Functional {
        let mut f = Functional::new();
        let c = 0.5 / self.dz;
        f.add(self.corner(i + 1, j), c);
        f.add(self.corner(i + 1, j + 1), c);
        f.add(self.corner(i, j), -c);
        f.add(self.corner(i, j + 1), -c);
        f
    }

    /// vz of pixel (i, j) as a functional of ψ.
    fn vz_functional(&self, i: usize, j: usize) -> Functional {
        let mut f = Functional::new();
        let c = 0.5 / self.dx;
        f.add(self.corner(i, j + 1), -c);
        f.add(self.corner(i + 1, j + 1), -c);
        f.add(self.corner(i, j), c);
        f.add(self.corner(i + 1, j), c);
        f
    }

    /// Calls `g` with every penalty functional `h^m D_a^m v_c` (S = 1).
    fn for_each_penalty(&self, mut g: impl FnMut(&Functional)) {
        let m = self.order as usize;
        let coefs = diff_coefs(self.order);
        let h = self.dz.max(self.dx);
        for comp in 0..2 {
            // along z
            let scale_z = (h / self.dz).powi(m as i32);
            for i in 0..self.nz - m {
                for j in 0..self.nx {
                    let mut f = Functional::new();
                    for (k, c) in coefs.iter().enumerate() {
                        let v = if comp == 0 { self.vx_functional(i + k, j) } else { self.vz_functional(i + k, j) };
                        for t in 0..v.len {
                            f.add(v.idx[t], c * scale_z * v.coef[t]);
                        }
                    }
                    g(&f);
                }
            }
            // along x
            let scale_x = (h / self.dx).powi(m as i32);
            for i in 0..self.nz {
                for j in 0..self.nx - m {
                    let mut f = Functional::new();
                    for (k, c) in coefs.iter().enumerate() {
                        let v = if comp == 0 { self.vx_functional(i, j + k) } else { self.vz_functional(i, j + k) };
                        for t in 0..v.len {
                            f.add(v.idx[t], c * scale_x * v.coef[t]);
                        }
                    }
                    g(&f);
                }
            }
        }
    }

    /// Velocity (vx, vz) of ψ on the grid.
    fn velocity(&self, psi: &[f64], vx: &mut [f64], vz: &mut [f64]) {
        for i in 0..self.nz {
            for j in 0..self.nx {
                let p = i * self.nx + j;
                vx[p] = self.vx_functional(i, j).dot(psi);
                vz[p] = self.vz_functional(i, j).dot(psi);
            }
        }
    }

    /// `Gᵀ (a_x/r², a_z)` for per-pixel values `ax`, `az` (already weighted).
    fn adjoint(&self, ax: &[f64], az: &[f64], r2: f64, out: &mut [f64]) {
        out.iter_mut().for_each(|v| *v = 0.0);
        for i in 0..self.nz {
            for j in 0..self.nx {
                let p = i * self.nx + j;
                let (fx, fz) = (self.vx_functional(i, j), self.vz_functional(i, j));
                for t in 0..fx.len {
                    out[fx.idx[t]] += fx.coef[t] * ax[p] / r2;
                }
                for t in 0..fz.len {
                    out[fz.idx[t]] += fz.coef[t] * az[p];
                }
            }
        }
    }

    /// Fits the divergence-free field to `ux`, `uz` (row-major `nz × nx`, m/s; non-finite =
    /// missing) with optional per-pixel weights (finite, ≥ 0; 0 = missing). Writes `vx`, `vz`.
    pub fn fit(
        &self,
        ux: &[f64],
        uz: &[f64],
        weights: Option<&[f64]>,
        params: &DivFreeParams,
        vx: &mut [f64],
        vz: &mut [f64],
    ) -> Result<DivFreeReport, DivFreeError> {
        self.fit_warm(ux, uz, weights, params, None, vx, vz)
    }

    /// [`DivFree::fit`] with a starting point for the search of S (e.g. the S of the previous
    /// frame of the same scene): the search then usually needs three evaluations.
    #[allow(clippy::too_many_arguments)]
    pub fn fit_warm(
        &self,
        ux: &[f64],
        uz: &[f64],
        weights: Option<&[f64]>,
        params: &DivFreeParams,
        s_hint: Option<f64>,
        vx: &mut [f64],
        vz: &mut [f64],
    ) -> Result<DivFreeReport, DivFreeError> {
        self.fit_with_wall(ux, uz, weights, None, params, s_hint, vx, vz)
    }

    /// [`DivFree::fit_warm`] with a no-slip prior: `wall` (per pixel, finite, ≥ 0, relative to the
    /// largest data weight) pulls the velocity to zero there (module doc). Give the wall pixels
    /// weight 0 in `weights` (their Doppler is not blood flow).
    #[allow(clippy::too_many_arguments)]
    pub fn fit_with_wall(
        &self,
        ux: &[f64],
        uz: &[f64],
        weights: Option<&[f64]>,
        wall: Option<&[f64]>,
        params: &DivFreeParams,
        s_hint: Option<f64>,
        vx: &mut [f64],
        vz: &mut [f64],
    ) -> Result<DivFreeReport, DivFreeError> {
        validate(params)?;
        if params.order != self.order {
            return Err(DivFreeError::InvalidParameter {
                field: "order",
                value: format!("{}", params.order),
                allowed: "the order the fitter was built with",
            });
        }
        let n = self.nz * self.nx;
        let len = |what, got: usize| {
            if got == n {
                Ok(())
            } else {
                Err(DivFreeError::LengthMismatch { what, got, expected: n, nz: self.nz, nx: self.nx })
            }
        };
        len("ux", ux.len())?;
        len("uz", uz.len())?;
        len("vx", vx.len())?;
        len("vz", vz.len())?;
        for (field, w) in [("weights", weights), ("wall", wall)] {
            let Some(w) = w else { continue };
            len(field, w.len())?;
            if let Some(bad) = w.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
                return Err(DivFreeError::InvalidParameter {
                    field,
                    value: format!("{bad}"),
                    allowed: "finite values ≥ 0",
                });
            }
        }
        let prior: Vec<f64> = wall.map(<[f64]>::to_vec).unwrap_or_else(|| vec![0.0; n]);
        // Base weights: given weights (normalised by their maximum), 0 where data are missing.
        let wmax = weights.map(|w| w.iter().cloned().fold(0.0, f64::max)).unwrap_or(1.0);
        let base: Vec<f64> = (0..n)
            .map(|p| {
                let w = weights.map(|w| w[p] / wmax).unwrap_or(1.0);
                if ux[p].is_finite() && uz[p].is_finite() && w > 0.0 && w.is_finite() {
                    w
                } else {
                    0.0
                }
            })
            .collect();
        let n_valid = base.iter().filter(|w| **w > 0.0).count();
        if n_valid == 0 {
            return Err(DivFreeError::NoData);
        }
        let ux0: Vec<f64> = ux.iter().map(|v| if v.is_finite() { *v } else { 0.0 }).collect();
        let uz0: Vec<f64> = uz.iter().map(|v| if v.is_finite() { *v } else { 0.0 }).collect();
        let r = match params.noise_ratio {
            Some(r) => r,
            None => self.estimate_noise_ratio(&ux0, &uz0, &base),
        };
        let r2 = r * r;
        let mut report = DivFreeReport { noise_ratio: r, n_data: 2 * n_valid, ..Default::default() };
        let mut w = base.clone();
        let passes = if params.robust { 3 } else { 1 };
        let probes = make_probes(params.gcv_probes, n);
        let mut psi = vec![0.0; self.n_psi];
        let mut s_used = params.s;
        for pass in 0..passes {
            let data_vals = self.data_matrix(&with_prior(&w, &prior), r2);
            let mut rhs = vec![0.0; self.n_psi];
            let wx: Vec<f64> = (0..n).map(|p| w[p] * ux0[p]).collect();
            let wz: Vec<f64> = (0..n).map(|p| w[p] * uz0[p]).collect();
            self.adjoint(&wx, &wz, r2, &mut rhs);
            let n_eff = 2.0 * w.iter().filter(|v| **v > 0.0).count() as f64;
            // S: given, or chosen once (first pass) by block cross-validation or GCV.
            let s = match s_used {
                Some(s) => s,
                None => {
                    report.s_from_gcv = false;
                    let hint = s_hint.filter(|h| h.is_finite() && *h > 0.0).map(f64::log10).unwrap_or(1.0);
                    let best = match params.selection {
                        Selection::BlockCv if BlockCv::possible(self, &w, params.cv_block) => {
                            let cv = BlockCv::new(self, &w, &prior, &ux0, &uz0, r2, params.cv_block);
                            bracket_min(hint, |ls| cv.score(self, 10f64.powf(ls), &mut report))?
                        }
                        // Block CV needs data outside every fold (grid or data region smaller
                        // than two blocks): fall back to GCV.
                        _ => bracket_min(hint, |ls| {
                            report.s_from_gcv = true;
                            let s = 10f64.powf(ls);
                            report.factorisations += 1;
                            let llt = self.factor(&data_vals, s)?;
                            let mut psi_s = rhs.clone();
                            solve(&llt, &mut psi_s);
                            let rss = self.rss(&psi_s, &w, &ux0, &uz0, r2);
                            let tr = self.trace_h(&llt, &w, r2, &probes);
                            Ok(n_eff * rss / (n_eff - tr).max(1e-9 * n_eff).powi(2))
                        })?,
                    };
                    10f64.powf(best)
                }
            };
            s_used = Some(s);
            report.factorisations += 1;
            let llt = self.factor(&data_vals, s)?;
            psi.clone_from(&rhs);
            solve(&llt, &mut psi);
            let tr = self.trace_h(&llt, &w, r2, &probes);
            report.s = s;
            report.trace_h = tr;
            self.velocity(&psi, vx, vz);
            if pass + 1 < passes {
                // Robust weights from the studentised residual norm (as smoothn: per-component
                // medians removed, MAD = median of the norms of the centred residual vectors).
                let h = (tr / n_eff).clamp(0.0, 0.99);
                let idx: Vec<usize> = (0..n).filter(|&p| base[p] > 0.0).collect();
                let mut rx: Vec<f64> = idx.iter().map(|&p| (vx[p] - ux0[p]) / r).collect();
                let mut rz: Vec<f64> = idx.iter().map(|&p| vz[p] - uz0[p]).collect();
                let (mx, mz) = (median(&mut rx.clone()), median(&mut rz.clone()));
                let norms: Vec<f64> = rx.iter_mut().zip(rz.iter_mut()).map(|(a, b)| (*a - mx).hypot(*b - mz)).collect();
                let mad = median(&mut norms.clone());
                let scale = 1.4826 * mad * (1.0 - h).sqrt();
                for (&p, nrm) in idx.iter().zip(&norms) {
                    let u = if scale > 0.0 { nrm / scale } else { 0.0 };
                    w[p] = base[p] * params.weight_function.weight(u);
                }
            }
        }
        let outliers = (0..n).filter(|&p| base[p] > 0.0 && w[p] < 0.5 * base[p]).count();
        report.outlier_fraction = if params.robust { outliers as f64 / n_valid as f64 } else { 0.0 };
        let vmax = vx.iter().chain(vz.iter()).fold(0.0f64, |a, v| a.max(v.abs()));
        let dmax =
            divergence(vx, vz, [self.nz, self.nx], [self.dz, self.dx]).iter().fold(0.0f64, |a, v| a.max(v.abs()));
        report.max_divergence = if vmax > 0.0 { dmax * self.dz.min(self.dx) / vmax } else { 0.0 };
        Ok(report)
    }

    /// Weighted residual sum of squares of ψ against the data (x scaled by 1/r).
    fn rss(&self, psi: &[f64], w: &[f64], ux: &[f64], uz: &[f64], r2: f64) -> f64 {
        let n = self.nz * self.nx;
        let (mut fx, mut fz) = (vec![0.0; n], vec![0.0; n]);
        self.velocity(psi, &mut fx, &mut fz);
        (0..n).map(|p| w[p] * ((fx[p] - ux[p]).powi(2) / r2 + (fz[p] - uz[p]).powi(2))).sum()
    }

    /// Data part of the normal matrix for weights `w`, on the pattern.
    ///
    /// Every pixel also gets a vanishing weight `RIDGE × max w` towards zero velocity (the
    /// right-hand side does not see it): where the data leave the penalty's null space
    /// undetermined (data on one line, a cross-validation fold without data) the system stays
    /// positive definite and the undetermined part of the flow goes to zero; where there are
    /// data it changes the fit by a relative 1e-6.
    fn data_matrix(&self, w: &[f64], r2: f64) -> Vec<f64> {
        let pat = me_pattern(&self.col_ptr, &self.row_idx);
        let mut vals = vec![0.0; self.row_idx.len()];
        let ridge = RIDGE * w.iter().cloned().fold(0.0, f64::max).max(f64::MIN_POSITIVE);
        for i in 0..self.nz {
            for j in 0..self.nx {
                let wp = w[i * self.nx + j] + ridge;
                me_accumulate(&pat, &mut vals, &self.vx_functional(i, j), wp / r2);
                me_accumulate(&pat, &mut vals, &self.vz_functional(i, j), wp);
            }
        }
        vals
    }

    /// Numeric Cholesky factor of `data + S·penalty + ε I`.
    fn factor(&self, data: &[f64], s: f64) -> Result<Llt<usize, f64>, DivFreeError> {
        let mut vals: Vec<f64> = data.iter().zip(&self.pen_vals).map(|(a, b)| a + s * b).collect();
        // ψ's null space (a constant and the corner checkerboard, invisible in the velocity) is
        // removed exactly by pinning ψ at corners (0, 0) and (0, 1) to 0: a unique minimiser
        // with the same velocity, and no ridge that would compete with the data or the penalty.
        let mean_diag = self.diag.iter().map(|&k| vals[k]).sum::<f64>() / self.diag.len() as f64;
        let pin = if mean_diag > 0.0 && mean_diag.is_finite() { mean_diag } else { 1.0 };
        for &k in &self.diag[..2] {
            vals[k] += pin;
        }
        Llt::try_new_with_symbolic(
            self.llt_symbolic.clone(),
            SparseColMatRef::new(self.symbolic.as_ref(), &vals),
            Side::Lower,
        )
        .map_err(|e| DivFreeError::Factorisation(format!("{e:?}")))
    }

    /// Hutchinson estimate of tr H, H = W½G (GᵀWG + S P)⁻¹ GᵀW½ in the r-scaled data space.
    fn trace_h(&self, llt: &Llt<usize, f64>, w: &[f64], r2: f64, probes: &[Vec<f64>]) -> f64 {
        let n = self.nz * self.nx;
        let r = r2.sqrt();
        let mut acc = 0.0;
        let mut y = vec![0.0; self.n_psi];
        let (mut fx, mut fz) = (vec![0.0; n], vec![0.0; n]);
        for z in probes {
            // data-space probe (zx, zz) in r-scaled units: x part enters as W½ zx · r (so that
            // Gᵀ(·/r²) applies 1/r), z part as W½ zz.
            let ax: Vec<f64> = (0..n).map(|p| w[p].sqrt() * z[p] * r).collect();
            let az: Vec<f64> = (0..n).map(|p| w[p].sqrt() * z[n + p]).collect();
            self.adjoint(&ax, &az, r2, &mut y);
            solve(llt, &mut y);
            self.velocity(&y, &mut fx, &mut fz);
            acc += (0..n).map(|p| w[p].sqrt() * (z[p] * fx[p] / r + z[n + p] * fz[p])).sum::<f64>();
        }
        acc / probes.len() as f64
    }

    /// r = MAD(Laplacian of ux) / MAD(Laplacian of uz) over pixels whose 5-point stencil has data,
    /// clamped to [0.1, 100]; 1 when fewer than 16 such pixels.
    fn estimate_noise_ratio(&self, ux: &[f64], uz: &[f64], w: &[f64]) -> f64 {
        let (nz, nx) = (self.nz, self.nx);
        let (mut lx, mut lz) = (Vec::new(), Vec::new());
        for i in 1..nz - 1 {
            for j in 1..nx - 1 {
                let p = i * nx + j;
                let st = [p, p - 1, p + 1, p - nx, p + nx];
                if st.iter().all(|&q| w[q] > 0.0) {
                    let lap = |u: &[f64]| u[p - 1] + u[p + 1] + u[p - nx] + u[p + nx] - 4.0 * u[p];
                    lx.push(lap(ux));
                    lz.push(lap(uz));
                }
            }
        }
        if lx.len() < 16 {
            return 1.0;
        }
        let mad = |v: &mut Vec<f64>| {
            let m = median(v);
            let mut d: Vec<f64> = v.iter().map(|x| (x - m).abs()).collect();
            median(&mut d)
        };
        let (a, b) = (mad(&mut lx), mad(&mut lz));
        if !(a > 0.0 && b > 0.0) {
            return 1.0;
        }
        (a / b).clamp(0.1, 100.0)
    }
}

/// Data weights plus the zero-velocity prior (for the normal matrix only: the prior's right-hand
/// side is zero).
fn with_prior(w: &[f64], prior: &[f64]) -> Vec<f64> {
    w.iter().zip(prior).map(|(a, b)| a + b).collect()
}

/// Column pattern view used for accumulation.
struct Pattern<'a> {
    col_ptr: &'a [usize],
    row_idx: &'a [usize],
}

fn me_pattern<'a>(col_ptr: &'a [usize], row_idx: &'a [usize]) -> Pattern<'a> {
    Pattern { col_ptr, row_idx }
}

/// Adds `scale · f fᵀ` (lower triangle) to `vals`.
fn me_accumulate(pat: &Pattern<'_>, vals: &mut [f64], f: &Functional, scale: f64) {
    for a in 0..f.len {
        for b in 0..f.len {
            let (p, q) = (f.idx[a], f.idx[b]);
            if p < q {
                continue;
            }
            let rows = &pat.row_idx[pat.col_ptr[q]..pat.col_ptr[q + 1]];
            if let Ok(k) = rows.binary_search(&p) {
                vals[pat.col_ptr[q] + k] += scale * f.coef[a] * f.coef[b];
            }
        }
    }
}

fn solve(llt: &Llt<usize, f64>, b: &mut [f64]) {
    let n = b.len();
    llt.solve_in_place(MatMut::from_column_major_slice_mut(b, n, 1));
}

fn validate(p: &DivFreeParams) -> Result<(), DivFreeError> {
    let bad = |field, value: String, allowed| Err(DivFreeError::InvalidParameter { field, value, allowed });
    if let Some(s) = p.s {
        if !(s.is_finite() && s > 0.0) {
            return bad("s", format!("{s}"), "a finite number > 0, or absent for GCV");
        }
    }
    if !(p.order == 2 || p.order == 3) {
        return bad("order", format!("{}", p.order), "2 or 3");
    }
    if let Some(r) = p.noise_ratio {
        if !(r.is_finite() && r > 0.0 && r <= 1e3) {
            return bad("noise_ratio", format!("{r}"), "in (0, 1000], or absent to estimate it");
        }
    }
    if !(2..=4096).contains(&p.cv_block) {
        return bad("cv_block", format!("{}", p.cv_block), "2 ..= 4096 pixels");
    }
    if !(1..=64).contains(&p.gcv_probes) {
        return bad("gcv_probes", format!("{}", p.gcv_probes), "1 ..= 64");
    }
    Ok(())
}

impl DivFreeParams {
    /// Checks every field; the error names it and its allowed range.
    pub fn validate(&self) -> Result<(), DivFreeError> {
        validate(self)
    }
}

/// Rademacher probes (±1) over the 2n data values, from a fixed seed (splitmix64).
fn make_probes(k: usize, n: usize) -> Vec<Vec<f64>> {
    let mut state: u64 = 0x0005_eed0_fd1f_f4ee;
    let mut next = || {
        state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    };
    (0..k).map(|_| (0..2 * n).map(|_| if next() & 1 == 0 { 1.0 } else { -1.0 }).collect()).collect()
}

/// Median (sorts `v`); 0 for an empty slice.
fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

/// Discrete divergence between each 2 × 2 block of pixels (`(nz − 1) × (nx − 1)`, row-major), the
/// operator under which the fitted fields are exactly divergence-free:
/// `(vx[i,j+1] + vx[i+1,j+1] − vx[i,j] − vx[i+1,j])/(2dx) + (vz[i+1,j] + vz[i+1,j+1] − vz[i,j] − vz[i,j+1])/(2dz)`.
pub fn divergence(vx: &[f64], vz: &[f64], shape: [usize; 2], spacing: [f64; 2]) -> Vec<f64> {
    let [nz, nx] = shape;
    let [dz, dx] = spacing;
    let mut out = Vec::with_capacity(nz.saturating_sub(1) * nx.saturating_sub(1));
    for i in 0..nz.saturating_sub(1) {
        for j in 0..nx.saturating_sub(1) {
            let p = i * nx + j;
            let ddx = (vx[p + 1] + vx[p + nx + 1] - vx[p] - vx[p + nx]) / (2.0 * dx);
            let ddz = (vz[p + nx] + vz[p + nx + 1] - vz[p] - vz[p + 1]) / (2.0 * dz);
            out.push(ddx + ddz);
        }
    }
    out
}
