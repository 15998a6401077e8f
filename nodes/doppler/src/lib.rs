//! Slow-time processing of beamformed I/Q packets (Shahriari & Garcia 2018, PMB 63:205011,
//! eq. 19–20; MUST/PyMUST 0.1.9 `iq2doppler`):
//!
//! 1. [`ClutterParams`] ([`clutter`]): clutter (wall) filters over slow time — polynomial
//!    regression ([`ClutterFilter`]), Butterworth high-pass ([`IirHighPass`], [`iir`]), SVD of the
//!    Casorati matrix with fixed or adaptive rank ([`SvdFilter`], [`svd`]).
//! 2. [`DopplerEstimator`] ([`estimator`]): lag-L autocorrelation (eq. 19) or Loupas 2-D
//!    autocorrelator, spatial window, power, variance and per-pixel flags.
//! 3. [`solve_vector`] ([`vector`]): least-squares (vx, vz) from two or more looks (eq. 20),
//!    nominal or per-pixel projections, optional per-look weights.
//! 4. [`aperture_projection`] ([`aperture`]): per-pixel Doppler projection vectors through the
//!    beamformer's receive aperture (the array edge clips steered sub-apertures).
//! 5. [`PacketAssembler`] ([`packet`]): collects a packet's images per look (transmit tilt,
//!    receive angle, fc), estimates one map per look and solves the vector velocity with
//!    fc²-weighted looks and band-normalised power: what the `doppler` node does, without IPC.
//! 6. [`SpeckleAssembler`] ([`sptrack`]): speckle tracking (MUST `sptrack`), the alternative to
//!    Doppler: envelope block matching between frames `t` and `t + lag`, multi-pass, sub-pixel,
//!    the same vector field on the image grid: what the `speckle-tracking` node does.
//!
//! Units are SI; x lateral, z depth. Doppler velocities are positive toward the probe. Errors are
//! `sonoflow_beamform`'s [`BeamformError`] (the field names say which stage).

pub mod aperture;
pub mod clutter;
pub mod compensate;
pub mod estimator;
pub mod iir;
mod lag_sums;
pub mod packet;
pub mod slowtime;
pub mod sptrack;
pub mod svd;
#[cfg(feature = "testkit")]
pub mod testkit;
pub mod vector;

pub use aperture::{aperture_projection, Aperture};
pub use clutter::{ClutterFilter, ClutterParams, ClutterReport};
pub use compensate::{Compensation, FilterResponse};
pub use estimator::{flags, DopplerEstimator, DopplerMap, DopplerParams, Estimator, Packet, WindowShape};
pub use iir::{IirHighPass, IirInit};
pub use packet::{mean_power, LookHeader, LookMap, PacketAssembler, PacketParams, PacketProducts, ProjectionMode};
pub use sonoflow_beamform::error::{BeamformError, Result};
pub use sonoflow_beamform::{Grid, C32};
pub use sptrack::{SpeckleAssembler, SpeckleParams, SpeckleProducts, SpeckleTracker, Subpixel, Tracked, TrackedImage};
pub use svd::{SvdFilter, SvdOutcome, SvdRank};
pub use vector::{
    nominal_projection, outlier_looks, solve_vector, solve_vector_weighted, Projection, VectorField, VectorInput,
};
