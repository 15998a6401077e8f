//! Platelet suspension of paper 2 (`../shared/papers/fe-nn-platelet-suspensions.txt`): platelets
//! as point particles with shape, whose drag, lift and torque come from small trained networks.
//! This crate holds the algorithms without any IPC. So far: the shape model of section 4.1
//! ([`shape`]), the coefficient interface of eq 6 ([`coefficients`]), closed forms of spheroids
//! ([`spheroid`]), a boundary-element Stokes solver for the resolved runs of section 4.3
//! ([`stokes`]), the training data ([`dataset`]), the 2-D particle dynamics
//! ([`dynamics`], with the stenosed channel of section 5.2 and SPH fluid particles interpolated
//! onto the particle lattice as the carrier), the networks of sections 4.2–4.4 ([`nn`])
//! and a ready-to-run suspension built from serde parameters ([`suspension`]).

pub mod coefficients;
pub mod dataset;
pub mod dynamics;
pub mod experiments;
pub mod nn;
pub mod shape;
pub mod spheroid;
pub mod stokes;
pub mod suspension;
#[cfg(feature = "testkit")]
pub mod testkit;

pub use coefficients::{CoefficientModel, Rotational, Translational};
pub use shape::{Shape, ShapeError, ShapeSampler};
pub use stokes::{solve_shape, Outer, ShapeResistance, StokesError, StokesModel, StokesOptions};
