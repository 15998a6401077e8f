//! Regular sampling grid and ground-truth velocity images.

use serde::{Deserialize, Serialize};

use crate::{require, ParamError};

/// Regular grid in the (x, z) plane: node `(ix, iz)` lies at
/// `(x0 + ix * dx, z0 + iz * dz)` (m).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct GridSpec {
    /// Number of nodes along x.
    pub nx: u32,
    /// Number of nodes along z.
    pub nz: u32,
    /// x of node (0, 0) (m).
    pub x0: f64,
    /// z of node (0, 0) (m).
    pub z0: f64,
    /// Node spacing along x (m).
    pub dx: f64,
    /// Node spacing along z (m).
    pub dz: f64,
}

/// Ground-truth velocity sampled on a [`GridSpec`]; row-major with index
/// `iz * nx + ix`. Outside the fluid `vx = vz = 0` and `mask = 0`; inside
/// `mask = 1`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Truth {
    /// Lateral velocity (m/s).
    pub vx: Vec<f32>,
    /// Axial (depth) velocity (m/s), positive = away from the probe.
    pub vz: Vec<f32>,
    /// 1 inside the fluid, 0 outside.
    pub mask: Vec<u8>,
}

impl GridSpec {
    /// Largest accepted node count `nx * nz` (16 Mi).
    pub const MAX_NODES: u64 = 1 << 24;

    /// Checks `nx, nz >= 1`, `nx * nz <= 16 Mi`, finite origin and finite
    /// positive spacings (with a finite far corner); the error names the
    /// field as `grid.<name>`.
    pub fn validate(&self) -> Result<(), ParamError> {
        require("grid.nx", self.nx, self.nx >= 1, ">= 1")?;
        require("grid.nz", self.nz, self.nz >= 1, ">= 1")?;
        require(
            "grid.nz",
            self.nz,
            self.n_nodes() <= Self::MAX_NODES,
            format!("nx * nz <= {} (nx = {})", Self::MAX_NODES, self.nx),
        )?;
        require("grid.x0", self.x0, self.x0.is_finite(), "finite")?;
        require("grid.z0", self.z0, self.z0.is_finite(), "finite")?;
        let far_x = self.x0 + f64::from(self.nx - 1) * self.dx;
        let far_z = self.z0 + f64::from(self.nz - 1) * self.dz;
        require("grid.dx", self.dx, self.dx.is_finite() && self.dx > 0.0 && far_x.is_finite(), "finite, > 0 m")?;
        require("grid.dz", self.dz, self.dz.is_finite() && self.dz > 0.0 && far_z.is_finite(), "finite, > 0 m")?;
        Ok(())
    }

    /// `nx * nz`.
    pub fn n_nodes(&self) -> u64 {
        u64::from(self.nx) * u64::from(self.nz)
    }

    /// Position of node `(ix, iz)` (m).
    pub fn node(&self, ix: u32, iz: u32) -> (f64, f64) {
        (self.x0 + f64::from(ix) * self.dx, self.z0 + f64::from(iz) * self.dz)
    }
}
