//! Test fixtures (feature `testkit`), shared by this crate's tests and the stability matrix
//! (`sonoflow stability`): the shipped coefficient networks, a coefficient model returning fixed
//! (possibly non-physical) coefficients, and a one-platelet suspension. Test code: it panics
//! where a fixture cannot be built.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::dynamics::{ParticleState, Particles, DEFAULT_DENSITY};
use crate::nn::model::NetworkModel;
use crate::{CoefficientModel, Rotational, Shape, Translational};

/// The shipped networks (`nodes/platelet/weights`).
pub fn shipped_model() -> NetworkModel {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("weights");
    NetworkModel::load_dir(&dir).expect("the shipped weights load")
}

/// A coefficient model giving every platelet the same coefficients, whatever its shape: for
/// refused values (NaN or non-positive drag, a coupling that is not positive definite).
#[derive(Clone, Copy, Debug)]
pub struct FixedModel(pub Translational, pub Rotational);

impl FixedModel {
    /// Drag `c_d`, no lift or pitching torque, rotation resistance 1e-19.
    pub fn drag(c_d: f64) -> Self {
        FixedModel(Translational { c_d, c_l: 0.0, c_p: 0.0 }, Rotational { c_r: 1e-19, c_s: 0.0 })
    }

    /// Drag 7e-8 with a pitching torque 1e-12 that breaks positive definiteness with the coupling
    /// (c_x² > c_d c_r).
    pub fn pitchy() -> Self {
        FixedModel(Translational { c_d: 7e-8, c_l: 0.0, c_p: 1e-12 }, Rotational { c_r: 1e-19, c_s: 0.0 })
    }
}

impl CoefficientModel for FixedModel {
    fn translational(&self, _: &[Shape], _: &[f64], out: &mut [Translational]) {
        out.fill(self.0);
    }
    fn rotational(&self, _: &[Shape], out: &mut [Rotational]) {
        out.fill(self.1);
    }
    fn name(&self) -> &str {
        "fixed"
    }
}

/// One platelet of `shape` in state `s` (blood density, unit depth).
pub fn one(shape: Shape, s: ParticleState) -> Particles {
    let mut p = Particles::new(DEFAULT_DENSITY, 1.0).unwrap();
    p.push(shape, s).unwrap();
    p
}
