//! Two-dimensional weakly compressible SPH (WCSPH) solver of
//! S. Shahriari and D. Garcia, "Meshfree simulations of ultrasound vector flow imaging using
//! smoothed particle hydrodynamics", *Phys. Med. Biol.* 63 (2018) 205011, §2.1–2.2 (eq 1–13).
//! No IPC: this crate works on slices and owns no process.
//!
//! * [`kernel`]: quartic spline (the paper's), Wendland C2 and cubic spline, 2D-normalised (eq 2).
//! * [`particles`]: struct-of-arrays state (x, z, vx, vz, ρ, m, kind, id).
//! * [`neighbours`]: cell list rebuilt every evaluation, optional periodic x.
//! * [`wcsph`]: continuity (eq 7), EOS (eq 8, optional background pressure), pressure term (eq 10),
//!   mean-value viscous term (eq 12, constant from the kernel's second moment) or Morris et al.
//!   (1997), body force, fixed wall particles of type I (on the wall) and type II (outside).
//! * [`fast`]: the same right-hand sides as [`wcsph`], cell-sorted and in 8 f32 lanes (AVX2 + FMA
//!   with a bit-identical portable twin), ~8× faster; the solver's default (`SphParams::fast_rhs`).
//! * [`solver`]: second-order predictor–corrector, adaptive dt (CFL, viscous, force), outputs at
//!   exact times, blow-up detection naming time, particle and criterion.
//! * [`setup`], [`analytic`]: validation set-ups (plane channels, Taylor–Green vortex, lid-driven
//!   cavity with its wall-domain guard) and Morris et al. (1997) series solutions.
//! * [`params`]: [`SphParams`]; the defaults add particle shifting and δ-SPH to the paper's scheme
//!   (stable on every validation case), [`SphParams::paper_scheme`] is the paper's as published.
//! * [`waveform`]: periodic waveforms (Fourier series; the synthetic carotid inlet waveform).
//! * [`womersley`]: 2D channel Womersley solutions (validation reference and imposed inlet profile).
//! * [`boundary`]: open boundaries — the paper's virtual inflow/outflow reservoirs.
//! * [`checkpoint`]: the solver state in one checked file (start from a saved state).
//! * [`walls`]: prescribed wall motion and the fluid domain of the anti-penetration guard.
//! * [`geometry`]: 2D vessel geometries (branches, openings; straight tube, stenosis, carotid
//!   bifurcation presets) and their initial particle set (fluid lattice, wall particles, reservoirs).
//! * [`producer`]: the flow as a scatterer producer (what the `sph-flow` node runs): parameters,
//!   scene, solver or checkpoint, the acquisition schedule as a stream of events (particle
//!   snapshots with amplitudes, SPH-interpolated truth on a grid, diagnostics instants).

pub mod analytic;
pub mod boundary;
pub mod checkpoint;
pub mod fast;
pub mod geometry;
pub mod kernel;
pub mod neighbours;
pub mod params;
pub mod particles;
pub mod producer;
pub mod setup;
pub mod solver;
mod step;
#[cfg(feature = "testkit")]
pub mod testkit;
pub mod walls;
pub mod waveform;
pub mod wcsph;
pub mod womersley;

/// Floating-point type of the solver (f64: long accumulations of small increments).
pub type Real = f64;

pub use boundary::{BoundaryFlux, OpenBoundary, ProfileKind};
pub use checkpoint::{Checkpoint, CheckpointError, CheckpointHeader};
pub use kernel::{Kernel, KernelKind};
pub use neighbours::{CellList, Period};
pub use params::{Integrator, ParamError, PulsatileForce, Scheme, SphParams, ViscousConstant, ViscousTerm};
pub use particles::{ParticleKind, Particles};
pub use solver::{BlowUpCriterion, Diagnostics, DtCriterion, Solver, SphError, StepReport};
pub use walls::{BoxDomain, Domain, WallMotion};
pub use waveform::{Waveform, WaveformSpec};
