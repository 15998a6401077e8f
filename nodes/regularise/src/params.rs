//! Parameters of [`crate::Smoothn`] (serde, validated once) and the error type.

use serde::{Deserialize, Serialize};

/// Robust weight function applied to the studentised residuals `u` (Garcia 2010, §4).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum WeightFunction {
    /// Tukey bisquare, `(1 − (u/4.685)²)²` for `u < 4.685`, else 0 (default).
    #[default]
    Bisquare,
    /// Cauchy, `1 / (1 + (u/2.385)²)`.
    Cauchy,
    /// Talworth, `1` for `u < 2.795`, else 0.
    Talworth,
}

impl WeightFunction {
    /// Weight of a studentised residual `u ≥ 0`; NaN maps to 0 (MATLAB `W(isnan(W)) = 0`).
    pub fn weight(self, u: f64) -> f64 {
        let w = match self {
            Self::Bisquare => {
                let t = u / 4.685;
                if t < 1.0 {
                    (1.0 - t * t) * (1.0 - t * t)
                } else {
                    0.0
                }
            }
            Self::Cauchy => {
                let t = u / 2.385;
                1.0 / (1.0 + t * t)
            }
            Self::Talworth => {
                if u < 2.795 {
                    1.0
                } else {
                    0.0
                }
            }
        };
        if w.is_nan() {
            0.0
        } else {
            w
        }
    }
}

/// Which published implementation to follow where they differ (see the crate documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Flavour {
    /// Garcia's MATLAB `smoothn` (and the papers): the default.
    #[default]
    Matlab,
    /// Reproduce PyMUST 0.1.9 `smoothn` quirk for quirk, for cross-checking only
    /// (orders 1 and 2 only).
    Pymust,
}

/// Parameters of the smoother. Every field has a default (`SmoothnParams::default()`), so a
/// TOML/JSON table may give any subset; unknown fields are rejected.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SmoothnParams {
    /// Smoothing parameter S (dimensionless, finite, > 0). `None` (default): chosen by minimising
    /// the generalised cross-validation score over log10 S.
    pub s: Option<f64>,
    /// Order m of the penalty (the difference operator's eigenvalues are raised to m):
    /// 1, 2 (default) or 3.
    pub order: u32,
    /// Robust smoothing: iteratively re-weighted with [`Self::weight_function`] (3 passes as
    /// MATLAB). Default false.
    pub robust: bool,
    /// Robust weight function. Default bisquare.
    pub weight_function: WeightFunction,
    /// Termination tolerance on the relative change of the smoothed field between iterations
    /// (dimensionless, in (0, 1)). Default 1e-3.
    pub tol_z: f64,
    /// Maximum number of iterations per robust pass (≥ 1). Default 100.
    pub max_iter: u32,
    /// Grid spacing along each axis (any unit, finite, > 0; only ratios matter: it is normalised by
    /// its maximum). `None` (default): equal spacing. Its length must equal the number of grid axes.
    pub spacing: Option<Vec<f64>>,
    /// Reference implementation to follow. Default [`Flavour::Matlab`].
    pub flavour: Flavour,
}

impl Default for SmoothnParams {
    fn default() -> Self {
        Self {
            s: None,
            order: 2,
            robust: false,
            weight_function: WeightFunction::Bisquare,
            tol_z: 1e-3,
            max_iter: 100,
            spacing: None,
            flavour: Flavour::Matlab,
        }
    }
}

impl SmoothnParams {
    /// Checks every field against its allowed range; the error names the field.
    pub fn validate(&self) -> Result<(), SmoothnError> {
        let bad = |field: &'static str, value: String, allowed: &'static str| {
            Err(SmoothnError::InvalidParameter { field, value, allowed })
        };
        if let Some(s) = self.s {
            if !(s.is_finite() && s > 0.0) {
                return bad("s", format!("{s}"), "a finite number > 0, or absent for automatic (GCV) selection");
            }
        }
        match (self.flavour, self.order) {
            (Flavour::Matlab, 1..=3) | (Flavour::Pymust, 1..=2) => {}
            (Flavour::Matlab, o) => return bad("order", format!("{o}"), "1, 2 or 3"),
            (Flavour::Pymust, o) => return bad("order", format!("{o}"), "1 or 2 with flavour = \"pymust\""),
        }
        if !(self.tol_z > 0.0 && self.tol_z < 1.0) {
            return bad("tol_z", format!("{}", self.tol_z), "0 < tol_z < 1");
        }
        if self.max_iter < 1 {
            return bad("max_iter", format!("{}", self.max_iter), "an integer ≥ 1");
        }
        if let Some(sp) = &self.spacing {
            if sp.is_empty() || sp.iter().any(|d| !(d.is_finite() && *d > 0.0)) {
                return bad("spacing", format!("{sp:?}"), "one finite value > 0 per grid axis");
            }
        }
        Ok(())
    }
}

/// Errors of the smoother (one variant per failure a caller can act on).
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SmoothnError {
    /// A parameter is outside its allowed range.
    #[error("invalid parameter `{field}` = {value}: allowed {allowed}")]
    InvalidParameter {
        /// Field name in [`SmoothnParams`].
        field: &'static str,
        /// The offending value.
        value: String,
        /// The allowed range.
        allowed: &'static str,
    },
    /// The grid has no axis, a zero-length axis, or there are no components.
    #[error(
        "invalid grid: shape {shape:?} with {components} component(s) (need ≥ 1 axis, every axis ≥ 1, ≥ 1 component)"
    )]
    InvalidGrid {
        /// Grid shape.
        shape: Vec<usize>,
        /// Number of components.
        components: usize,
    },
    /// A data, weight or output slice does not match the grid.
    #[error("`{what}` has {got} values but the grid needs {expected}")]
    LengthMismatch {
        /// Which argument.
        what: &'static str,
        /// Its length.
        got: usize,
        /// components × grid points (data, output) or grid points (weights).
        expected: usize,
    },
    /// `spacing` has the wrong number of entries.
    #[error("`spacing` has {got} entries but the grid has {expected} axes")]
    SpacingLength {
        /// Entries given.
        got: usize,
        /// Grid axes.
        expected: usize,
    },
    /// A weight is negative or not finite.
    #[error("weight at grid index {index} is {value}: weights must be finite and ≥ 0")]
    InvalidWeight {
        /// Flat grid index.
        index: usize,
        /// The weight.
        value: f64,
    },
    /// Every grid point is missing (NaN/±inf in some component) or has zero weight.
    #[error("no valid data: all {points} grid points are missing (NaN/±inf) or have zero weight")]
    NoValidData {
        /// Grid points.
        points: usize,
    },
}
