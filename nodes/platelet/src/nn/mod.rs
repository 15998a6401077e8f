//! The coefficient networks of paper 2, sections 4.2–4.4: small fully connected ReLU networks that
//! map a platelet's shape (and the effective angle of attack) to its scaled drag, lift and torques.
//!
//! - [`mlp`]: the network [`Mlp`] (any layer sizes, ReLU on hidden layers, linear output, input
//!   standardisation and output scaling stored with the weights), a batched f32 forward pass for
//!   inference and an f64 path for training.
//! - [`mod@train`]: backpropagation of the mean squared error, Adam with a cosine learning-rate
//!   schedule, seeded mini-batches, He initialisation, best weights on a validation split (by
//!   shape), optional per-output loss weights, mirror augmentation or mirror-averaged networks
//!   ([`mlp::Mirror`]: the platelet mirrored about its x axis), full-batch L-BFGS refinement.
//! - [`data`]: data sets, the seeded 80/20 split and the error metrics of the paper's Table 1
//!   ([`TrainingReport`]).
//! - [`safetensors`]: weights on disk in the safetensors format (read and written with the
//!   `safetensors` crate), validated on load.
//! - [`model`]: the eq 18 scaling, the unit conversion to SI and [`NetworkModel`], a
//!   [`crate::CoefficientModel`] made of the three networks N, N_r and N_s.
//!
//! **Why no machine-learning crate.** The networks have at most ~1 800 weights and are trained on
//! at most some 10⁵ samples on a CPU. A hand-written MLP with backpropagation and Adam is ~400
//! lines, has no heavyweight dependency (no libtorch, no BLAS, no GPU runtime), is bit-for-bit
//! deterministic for a given seed, and its inference kernel is written for exactly this shape of
//! problem (tiny layers, large batches), which a general framework does not do better.

pub mod data;
pub mod mlp;
pub mod model;
pub mod safetensors;
pub mod train;

pub use data::{evaluate, train_and_report, Dataset, ErrorStats, SetErrors, TrainingReport};
pub use mlp::{Mlp, MlpWorkspace};
pub use model::NetworkModel;
pub use train::{train, TrainConfig, TrainOutcome};

/// Errors of the network module.
#[derive(Debug, thiserror::Error)]
pub enum NnError {
    /// A parameter outside its allowed range.
    #[error("network: `{field}` = {value} is invalid: allowed {allowed}")]
    Config { field: &'static str, value: String, allowed: &'static str },
    /// Inconsistent array lengths or layer sizes.
    #[error("network: {what}: expected {expected}, got {got}")]
    Size { what: String, expected: usize, got: usize },
    /// A value that must be finite is not.
    #[error("network: {what} contains a non-finite value at index {index}")]
    NonFinite { what: String, index: usize },
    /// A file that is not a valid network file.
    #[error("network file {path}: {reason}")]
    Format { path: String, reason: String },
    /// A tensor in a network file that is missing or inconsistent.
    #[error("network file {path}: tensor `{tensor}`: {reason}")]
    Tensor { path: String, tensor: String, reason: String },
    /// Reading or writing a file failed.
    #[error("network file {path}: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    /// A quantity cannot be scaled by eq 18 because its factor vanishes at this angle.
    #[error("eq 18 scaling of `{quantity}` at psi = {psi} rad: the factor {factor} is too close to 0")]
    Scaling { quantity: &'static str, psi: f64, factor: f64 },
}
