//! Beamforming for plane-wave ultrasound (Shahriari & Garcia 2018,
//! *Meshfree simulations of ultrasound vector flow imaging using smoothed particle
//! hydrodynamics*, PMB 63:205011, §2.4, eq. 19–20), following MUST/PyMUST 0.1.9 conventions
//! (`rf2iq`, `dasmtx`, `iq2doppler`; see `docs/research/pymust-notes.md` §6–8).
//!
//! Pipeline, each stage a reusable object configured once and applied per frame/packet:
//!
//! 1. [`Rf2Iq`] ([`rf2iq`]): RF → I/Q by down-mixing at fc and a zero-phase Butterworth low-pass.
//! 2. [`DasPlan`] ([`das`]): delay-and-sum onto a [`Grid`] for a [`TxWave`] (plane wave at any
//!    tilt, focused, diverging, arbitrary delays), f-number receive aperture steered by a receive
//!    angle, linear interpolation and I/Q phase rotation, as a precomputed sparse operator, for
//!    linear and convex arrays ([`convex`], MUST `radius`); [`CompoundPlan`] for coherent
//!    compounding over transmits.
//!
//! Slow-time processing of the beamformed packets (clutter filter, Doppler estimators, vector
//! Doppler) lives in `sonoflow-doppler`.
//!
//! Units are SI; x lateral (0 at the array centre), z depth (> 0 into the medium). Doppler
//! velocities are positive toward the probe. No IPC: nodes and batch tools wrap this library.

pub mod bmode;
pub mod butterworth;
pub mod das;
/// Convex-array geometry (MUST `radius`), the delay-and-sum's helper module.
pub use das::convex;
pub mod error;
pub mod grid;
pub mod multilook;
pub mod rf2iq;
#[cfg(feature = "testkit")]
pub mod testkit;

pub use bmode::{bmode, mean_envelope_iq, mean_envelope_rf, tgc_gain};
pub use das::{das_frames, Apodization, CompoundPlan, DasParams, DasPlan, Interpolation, TxWave};
pub use error::{BeamformError, Result};
pub use grid::Grid;
pub use multilook::{BeamformerParams, MultiLookBeamformer, PerAngle, RfInfo};
pub use num_complex::Complex;
pub use rf2iq::{to_element_major, to_sample_major, Layout, Rf2Iq, Rf2IqParams, RfSample, RfView};

/// Complex f32 sample (I/Q).
pub type C32 = Complex<f32>;
