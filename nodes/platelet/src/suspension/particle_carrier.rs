//! The carrier of a suspension in a fluid given as particles (the `suspension` module doc:
//! "Carrier from fluid particles").

use super::{invalid, SuspensionError};
use crate::dynamics::{FlowError, InterpOrder, InterpParams, SphKernel};

fn d_min_fraction() -> f64 {
    0.4
}

/// Largest number of lattice nodes of a `particles` carrier.
pub const MAX_LATTICE_NODES: usize = 4_000_000;
/// Largest kernel support of a `particles` carrier, in lattice spacings (cost per particle and
/// snapshot ∝ its square).
pub const MAX_SUPPORT_SPACINGS: f64 = 64.0;

/// A regular square lattice in channel coordinates: node (i, j) at origin + (i h, j h).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LatticeSpec {
    /// Position of node (0, 0) \[m\] (channel coordinates).
    pub origin: [f64; 2],
    /// Node spacing \[m\].
    pub h: f64,
    /// Nodes along x (≥ 2).
    pub nx: usize,
    /// Nodes along y (≥ 2).
    pub ny: usize,
}

/// The carrier of a suspension in a fluid given as particles (module doc; e.g. the SPH node's
/// snapshots, mapped into channel coordinates by the caller).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParticleCarrier {
    /// The lattice the fluid velocity is interpolated onto (Algorithm 2's particle lattice).
    pub lattice: LatticeSpec,
    /// SPH smoothing length of the interpolation \[m\] (that of the SPH run, e.g. 1.2 × its
    /// particle spacing). Required.
    pub kernel_h: f64,
    /// Kernel: `quartic-spline` (default, the SPH solver's) or `wendland-c2`.
    #[serde(default)]
    pub kernel: SphKernel,
    /// Lattice nodes with a fluid fraction below this carry no flow (0 < value <= 1). Default 0.4
    /// (a node on a flat wall has ½; module `dynamics::sph_interp`).
    #[serde(default = "d_min_fraction")]
    pub min_fraction: f64,
    /// Interpolant: `linear` (default; first-order moving least squares, exact for linear
    /// fields) or `shepard` (normalised kernel sum).
    #[serde(default)]
    pub interpolation: InterpOrder,
    /// Straight walls y = lo and y = hi \[m\] the platelet centres are kept between (reflection,
    /// as in the analytic channel); absent (default): none (the mask alone stops the flow at
    /// the lumen's edge).
    #[serde(default)]
    pub walls: Option<[f64; 2]>,
}

impl ParticleCarrier {
    /// The interpolation's parameters.
    pub fn interp(&self) -> InterpParams {
        InterpParams {
            kernel: self.kernel,
            h: self.kernel_h,
            min_fraction: self.min_fraction,
            order: self.interpolation,
        }
    }

    /// Every field in range (errors name `carrier.<field>`).
    pub fn validate(&self) -> Result<(), SuspensionError> {
        let l = &self.lattice;
        for (k, o) in l.origin.iter().enumerate() {
            if !(o.is_finite() && o.abs() <= 1.0) {
                return Err(invalid(format!("carrier.lattice.origin[{k}]"), o, "-1 ..= 1 m"));
            }
        }
        if !(l.h.is_finite() && l.h > 0.0 && l.h <= 0.1) {
            return Err(invalid("carrier.lattice.h", l.h, "0 < h <= 0.1 m"));
        }
        if l.nx < 2 || l.ny < 2 || l.nx.saturating_mul(l.ny) > MAX_LATTICE_NODES {
            return Err(invalid(
                "carrier.lattice.(nx, ny)",
                format!("({}, {})", l.nx, l.ny),
                format!("nx >= 2, ny >= 2, nx * ny <= {MAX_LATTICE_NODES}"),
            ));
        }
        self.interp().validate().map_err(|e| match e {
            FlowError::Invalid { field, value, allowed } => invalid(format!("carrier.{field}"), value, allowed),
            e => SuspensionError::Flow(e),
        })?;
        let support = self.kernel.support_factor() * self.kernel_h;
        if support > MAX_SUPPORT_SPACINGS * l.h {
            return Err(invalid(
                "carrier.kernel_h",
                self.kernel_h,
                format!(
                    "a kernel support ({} h) of at most {MAX_SUPPORT_SPACINGS} lattice spacings: kernel_h <= {} m with lattice.h = {} m",
                    self.kernel.support_factor(),
                    MAX_SUPPORT_SPACINGS * l.h / self.kernel.support_factor(),
                    l.h
                ),
            ));
        }
        if let Some([lo, hi]) = self.walls {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(invalid("carrier.walls", format!("[{lo}, {hi}]"), "[lo, hi] with lo < hi (m)"));
            }
            let b = self.bbox();
            if b[2] >= b[3] {
                return Err(invalid(
                    "carrier.walls",
                    format!("[{lo}, {hi}]"),
                    format!(
                        "walls overlapping the lattice's y range [{}, {}] m",
                        l.origin[1],
                        l.origin[1] + (l.ny - 1) as f64 * l.h
                    ),
                ));
            }
        }
        Ok(())
    }

    /// x range and y range of the lattice (y clipped to the walls).
    pub(super) fn bbox(&self) -> [f64; 4] {
        let l = &self.lattice;
        let mut b =
            [l.origin[0], l.origin[0] + (l.nx - 1) as f64 * l.h, l.origin[1], l.origin[1] + (l.ny - 1) as f64 * l.h];
        if let Some([lo, hi]) = self.walls {
            b[2] = b[2].max(lo);
            b[3] = b[3].min(hi);
        }
        b
    }
}
