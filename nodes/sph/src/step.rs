//! What one time step reports (kept apart from the solver so that checkpoints can store it).

use crate::Real;

/// Which criterion set the time step.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum DtCriterion {
    /// Acoustic CFL: C_cfl h / (c + |u|max).
    Cfl,
    /// Viscous diffusion: C_ν h² / ν.
    Viscous,
    /// Force: C_f √(h / |a|max).
    Force,
    /// `dt_max`.
    Maximum,
    /// Shortened to land exactly on a requested output time.
    Output,
}

/// Diagnostics of the last step.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StepReport {
    /// Time step taken \[s\].
    pub dt: Real,
    /// What limited it.
    pub binding: DtCriterion,
    /// max |ρ/ρ₀ − 1| over fluid particles after the step.
    pub max_density_error: Real,
    /// Steps taken since the start.
    pub steps: u64,
}
