//! Platelet suspension of paper 2 (`../shared/papers/fe-nn-platelet-suspensions.txt`): platelets
//! as point particles with shape, whose drag, lift and torque come from small trained networks.
//! This crate holds the algorithms without any IPC. So far: the shape model of section 4.1
//! ([`shape`]), the coefficient interface ([`coefficients`]) and the 2-D particle dynamics
//! ([`dynamics`]).

pub mod coefficients;
pub mod dynamics;
pub mod shape;

pub use coefficients::{CoefficientModel, Rotational, Translational};
pub use shape::{Shape, ShapeError, ShapeSampler};
