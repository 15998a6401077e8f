//! Errors of the SIMUS library: one variant per failure a caller can act on.

/// Everything that can go wrong when configuring or running [`crate::Simus`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimusError {
    /// A parameter is outside its allowed range. `field` is the MUST-style field name
    /// (`probe.fc`, `options.fs`, …), `allowed` the range in words.
    #[error("invalid parameter `{field}` = {value}: must be {allowed}")]
    InvalidParameter {
        /// Dotted field name, e.g. `probe.bandwidth`.
        field: &'static str,
        /// The offending value, formatted.
        value: String,
        /// The allowed range, in words.
        allowed: &'static str,
    },
    /// A scatterer has a non-finite (or absurdly large) position or amplitude.
    #[error("scatterer row {row}: `{field}` = {value} must be finite with magnitude <= {limit}")]
    InvalidScatterer {
        /// Index of the scatterer (row of the x, z, rc arrays).
        row: usize,
        /// `x`, `z` or `rc`.
        field: &'static str,
        /// The offending value.
        value: f64,
        /// Largest magnitude accepted (100 m for positions, 1e20 for amplitudes).
        limit: f64,
    },
    /// Two arrays that must have the same length do not.
    #[error("length mismatch: `{field}` has {got} entries, expected {expected}")]
    LengthMismatch {
        /// Name of the array that has the wrong length.
        field: &'static str,
        /// Its length.
        got: usize,
        /// The expected length.
        expected: usize,
    },
    /// An unknown probe preset name.
    #[error("unknown probe `{name}`; known presets: {known}")]
    UnknownProbe {
        /// The requested name.
        name: String,
        /// Comma-separated list of supported names.
        known: &'static str,
    },
    /// The elements of a convex array do not fit on less than half of its circle.
    #[error("invalid parameter `probe.n_elements` = {n_elements}: a convex array of radius {radius} m holds at most {max} elements at this pitch (the arc must span less than half the circle)")]
    ArcTooShort {
        /// The element count asked for.
        n_elements: usize,
        /// Radius of curvature (m).
        radius: f64,
        /// The largest count that fits.
        max: usize,
    },
    /// The output slice given to `simulate_into` has the wrong length.
    #[error("output buffer has {got} samples, the plan needs n_elements × n_samples = {expected}")]
    OutputLength {
        /// Length of the slice passed in.
        got: usize,
        /// `n_elements * plan.n_samples`.
        expected: usize,
    },
    /// A fixed frequency plan is too coarse for this scene: the longest round trip does not fit
    /// into the plan's time window (1/df) and would alias circularly.
    #[error(
        "frequency plan too coarse for this scene: the longest round trip is {needed_s:.4e} s but the plan's \
         window is {window_s:.4e} s (1/df); plan for a larger max distance"
    )]
    PlanTooShort {
        /// 2·max distance/c + max delay + pulse length, in s.
        needed_s: f64,
        /// 1/df of the plan, in s.
        window_s: f64,
    },
    /// The output contained a non-finite value (cannot happen with validated inputs; reported
    /// instead of returning NaN).
    #[error("numerical failure: non-finite RF sample at element {element}, sample {sample}")]
    NonFiniteOutput {
        /// Element of the first bad sample.
        element: usize,
        /// Sample index.
        sample: usize,
    },
    /// The plan was made for a different probe / sampling configuration.
    #[error("frequency plan does not match this engine: {0}")]
    PlanMismatch(&'static str),
}

/// Shorthand for results of this crate.
pub type Result<T> = std::result::Result<T, SimusError>;

/// Builds an [`SimusError::InvalidParameter`].
pub(crate) fn invalid(field: &'static str, value: impl std::fmt::Display, allowed: &'static str) -> SimusError {
    SimusError::InvalidParameter { field, value: value.to_string(), allowed }
}
