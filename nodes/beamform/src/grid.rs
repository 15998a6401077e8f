//! The rectangular imaging grid (same fields as the wire type `GridV1`).

use serde::{Deserialize, Serialize};

use crate::error::{invalid, positive, Result};

/// Rectangular grid: node `(ix, iz)` at `(x0 + ix·dx, z0 + iz·dz)` (m); maps are row-major,
/// index `iz·nx + ix`. x is lateral (0 at the array centre), z is depth (> 0 into the medium).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Grid {
    /// Lateral position of column 0 (m).
    pub x0: f64,
    /// Depth of row 0 (m), ≥ 0.
    pub z0: f64,
    /// Column spacing (m), > 0.
    pub dx: f64,
    /// Row spacing (m), > 0.
    pub dz: f64,
    /// Columns, ≥ 1.
    pub nx: usize,
    /// Rows, ≥ 1.
    pub nz: usize,
}

impl Grid {
    /// Grid of `nx × nz` nodes spanning `[x_min, x_max] × [z_min, z_max]` (end points included;
    /// a single node sits at the minimum).
    pub fn spanning(x_min: f64, x_max: f64, nx: usize, z_min: f64, z_max: f64, nz: usize) -> Result<Self> {
        let step = |a: f64, b: f64, n: usize| if n > 1 { (b - a) / (n - 1) as f64 } else { 1.0 };
        let g = Self { x0: x_min, z0: z_min, dx: step(x_min, x_max, nx), dz: step(z_min, z_max, nz), nx, nz };
        g.validate()?;
        Ok(g)
    }

    /// Lateral position of column `ix` (m).
    pub fn x(&self, ix: usize) -> f64 {
        self.x0 + ix as f64 * self.dx
    }

    /// Depth of row `iz` (m).
    pub fn z(&self, iz: usize) -> f64 {
        self.z0 + iz as f64 * self.dz
    }

    /// `nx · nz`.
    pub fn n_pixels(&self) -> usize {
        self.nx * self.nz
    }

    /// Checks every field; the error names the field and the allowed range.
    pub fn validate(&self) -> Result<()> {
        if !(self.x0.is_finite() && self.x0.abs() <= 10.0) {
            return Err(invalid("grid.x0", self.x0, "finite with |x0| <= 10 (m)"));
        }
        if !(self.z0.is_finite() && (0.0..=10.0).contains(&self.z0)) {
            return Err(invalid("grid.z0", self.z0, "in [0, 10] (m)"));
        }
        positive("grid.dx", self.dx)?;
        positive("grid.dz", self.dz)?;
        if !(1..=1 << 20).contains(&self.nx) {
            return Err(invalid("grid.nx", self.nx, "in [1, 1048576]"));
        }
        if !(1..=1 << 20).contains(&self.nz) {
            return Err(invalid("grid.nz", self.nz, "in [1, 1048576]"));
        }
        if self.nx * self.nz > 1 << 26 {
            return Err(invalid("grid.nx*grid.nz", self.nx * self.nz, "<= 67108864 pixels"));
        }
        if (self.x(self.nx - 1)).abs() > 10.0 || self.z(self.nz - 1) > 10.0 {
            return Err(invalid(
                "grid.dx/grid.dz",
                format!("{}/{}", self.dx, self.dz),
                "such that the grid stays within 10 m",
            ));
        }
        Ok(())
    }
}
