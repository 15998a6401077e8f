//! Errors of the beamforming library: one variant per failure a caller can act on.

/// Everything that can go wrong when configuring or running the stages of this crate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BeamformError {
    /// A parameter is outside its allowed range. `field` is the MUST-style field name
    /// (`fc`, `fnumber`, `grid.dx`, …), `allowed` the range in words.
    #[error("invalid parameter `{field}` = {value}: must be {allowed}")]
    InvalidParameter {
        /// Dotted field name, e.g. `das.fnumber`.
        field: &'static str,
        /// The offending value, formatted.
        value: String,
        /// The allowed range, in words.
        allowed: &'static str,
    },
    /// An input or output buffer does not have the length its dimensions imply.
    #[error("length mismatch: `{field}` has {got} entries, expected {expected}")]
    LengthMismatch {
        /// Name of the buffer.
        field: &'static str,
        /// Its length.
        got: usize,
        /// The expected length.
        expected: usize,
    },
    /// A dimension is too small (or too large) for the method.
    #[error("`{field}` = {got} is out of range: must be {allowed}")]
    BadDimension {
        /// Name of the dimension, e.g. `rf.n_samples`.
        field: &'static str,
        /// The value given.
        got: usize,
        /// The allowed range, in words.
        allowed: &'static str,
    },
    /// The data given to a plan or estimator do not match the configuration it was built for.
    #[error("input does not match the configuration: {what}")]
    ConfigMismatch {
        /// What differs, in words.
        what: String,
    },
}

/// Result alias of this crate.
pub type Result<T, E = BeamformError> = std::result::Result<T, E>;

/// Shorthand for [`BeamformError::InvalidParameter`].
pub fn invalid(field: &'static str, value: impl std::fmt::Display, allowed: &'static str) -> BeamformError {
    BeamformError::InvalidParameter { field, value: value.to_string(), allowed }
}

/// Checks that `v` is finite and > 0.
pub fn positive(field: &'static str, v: f64) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(invalid(field, v, "finite and > 0"))
    }
}

/// Checks a buffer length.
pub fn check_len(field: &'static str, got: usize, expected: usize) -> Result<()> {
    if got == expected {
        Ok(())
    } else {
        Err(BeamformError::LengthMismatch { field, got, expected })
    }
}
