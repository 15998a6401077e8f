//! 2D vessel geometries and the initial particle set of a vessel flow: fluid lattice, boundary-conforming
//! wall particles of type I / type II and the reservoirs of the open ends (Shahriari & Garcia 2018,
//! §2.2: a carotid bifurcation, ~26 000 fluid particles on a 0.15 mm square lattice, fixed virtual wall
//! particles on (type I) and outside (type II) the wall, virtual inflow and outflow reservoirs).
//!
//! # The format
//! A [`VesselGeometry`] is a list of [`Branch`]es. A branch is a centre-line (a polyline of ≥ 2
//! points, x lateral and z depth in metres, z positive away from the probe) with a diameter that is
//! constant or given at every centre-line point (linear in between). Its lumen is the union of the
//! disks swept along the centre-line; the lumen of the geometry is the union over its branches. Each
//! end of a branch is a [`BranchEnd`]:
//! * `closed`: a rounded cap (the disk of the end point). This is also how a branch begins inside
//!   another one, e.g. the daughter branches of a bifurcation starting inside the parent's end;
//! * `inlet` (only at a branch's `start`) / `outlet` (only at its `end`): an opening, the flat cut
//!   through the end point perpendicular to the end segment, with the end diameter. A reservoir (the
//!   straight extension of the end segment beyond the opening) is attached to it at build time
//!   ([`BuildOptions::reservoir_depth`]).
//!
//! **Branches are written in flow direction**: from the inlet towards the outlets. With open ends
//! there is exactly one inlet, and every outlet carries a `flow_fraction` (> 0, summing to 1 over the
//! outlets: mass balance, 2D flow rate per unit depth Q = ū·D). A geometry without open ends (closed
//! cavity) is allowed.
//!
//! As a launch-file author writes it (the carotid preset, [`carotid_bifurcation`], is the full example):
//! ```toml
//! [[geometry.branches]]
//! name = "common"
//! centreline = [[-0.03, 0.022], [-0.002, 0.022]]
//! diameter = 8e-3
//! start = { type = "inlet" }
//! end = { type = "closed" }
//!
//! [[geometry.branches]]
//! name = "internal"
//! centreline = [[-0.004, 0.022], [0.006, 0.018], [0.02, 0.017]]
//! diameter = [6.4e-3, 7e-3, 5.55e-3]          # one per centre-line point [m]
//! start = { type = "closed" }
//! end = { type = "outlet", flow_fraction = 0.54 }
//!
//! [[geometry.branches]]
//! name = "external"
//! centreline = [[-0.004, 0.022], [0.006, 0.026], [0.02, 0.027]]
//! diameter = 4.65e-3
//! start = { type = "closed" }
//! end = { type = "outlet", flow_fraction = 0.46 }
//! ```
//!
//! # The particle set ([`VesselGeometry::build`])
//! * fluid: square lattice of spacing dx (through [`BuildOptions::lattice_origin`]), the nodes with
//!   SDF ≤ −dx/2 (inside, at least half a spacing from the wall) and s ≤ −dx/2 behind every opening
//!   (s along the opening's outward normal, within its strip |y| < a); ties (nodes exactly dx/2 away,
//!   common on aligned lattices) count as inside. An opening whose normal is along x or z is moved
//!   along it by < dx/2 to the nearest half-lattice position, so that the lattice rows lie at
//!   s = −dx/2 − k dx and the reservoir's first row at s = ds/2 continues them;
//! * walls: particles on the level sets SDF = k·dx (k = 0: type I, k = 1 … `wall_layers`: type II) of
//!   the lumen extended by the reservoirs, found by marching squares on a grid of spacing dx/4 (only
//!   cells near a level are evaluated), resampled at arc-length spacing ≈ dx, then projected onto the
//!   level by Newton steps (boundary-conforming to rounding, not a staircase). They run along the
//!   reservoirs up to their far side and never across an opening or a far side (points in the
//!   opening's strip are removed, never those of other branches); a point closer than dx/2 to an
//!   earlier one (V-shaped layers at the carina and where branches meet) is dropped;
//! * reservoirs: one [`OpenBoundary`](crate::boundary::OpenBoundary) per open end, filled by
//!   [`OpenBoundary::fill`](crate::boundary::OpenBoundary::fill);
//! * an [`SdfGrid`] of the lumen (spacing dx/2) for fast inside/outside queries.
//!
//! Ids: fluid 0 …, then walls (type I, then type II layer by layer), then the buffer particles
//! (boundary by boundary). Every particle has density ρ₀ and mass ρ₀ dx²; walls are at rest.
//!
//! **Kernel coverage.** A wall that does not lie on the lattice leaves a gap g ∈ [dx/2, 3dx/2)
//! between it and the first fluid row (the price of a lattice fluid with SDF ≤ −dx/2). With wall
//! rows at g, g + dx, … a fluid particle next to a flat wall then sees Σ (m/ρ) W = 1.255, 1.0, 0.835
//! at g = 0.5, 1, 1.5 dx (quartic spline, h = 1.2 dx). So the coverage of a generic geometry is ≥ 0.83,
//! not ≥ 0.9 everywhere: the carotid preset measures 0.886 at dx = 0.3 mm (3 of 6 476 particles below
//! 0.9) and 0.848 at 0.15 mm (32 of 26 249), at stretches of near-horizontal curved wall. At a tilted
//! (not snapped) opening the lattice ends raggedly and the coverage next to it drops to ≈ 0.77;
//! write openings along x or z where it matters.
//!
//! Modules: `shape` (signed distances, openings, the grid), `contour` (marching squares),
//! `build` (options and the generator), `presets` (straight tube, stenosis, carotid bifurcation).

use serde::{Deserialize, Serialize};

use crate::Real;

mod build;
mod contour;
mod presets;
mod relax;
mod shape;

pub use build::{BuildOptions, InitialVelocity, VesselScene};
pub use presets::{carotid_bifurcation, stenosis, straight_tube};
pub use shape::{EndSide, Lumen, Opening, SdfGrid, SegmentHit};

/// A vessel geometry: the union of its branches' lumens. See the module documentation for the format.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VesselGeometry {
    /// The branches (at least one), written in flow direction.
    pub branches: Vec<Branch>,
    /// Blend length k of the union of branches \[m\] (≥ 0, default 0 = sharp): the branches'
    /// signed distances d₁, d₂ are joined by the polynomial smooth minimum
    /// min(d₁, d₂) − k/4 · max(0, 1 − |d₁ − d₂|/k)², which rounds the corners where branches meet —
    /// the flow divider (carina) of a bifurcation becomes a rounded apex of radius ≈ k/2 instead of a
    /// sharp wedge, which a particle wall cannot resolve.
    #[serde(default)]
    pub fillet: Real,
}

/// One branch: a centre-line with a diameter and two ends.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Branch {
    /// Name, unique in the geometry; names the branch's open boundaries.
    pub name: String,
    /// Centre-line points (x, z) \[m\], at least 2, in flow direction, consecutive points distinct.
    pub centreline: Vec<[Real; 2]>,
    /// Lumen diameter \[m\]: one value, or one per centre-line point (linear along each segment).
    pub diameter: Diameter,
    /// The end at the first centre-line point (`closed` or `inlet`).
    pub start: BranchEnd,
    /// The end at the last centre-line point (`closed` or `outlet`).
    pub end: BranchEnd,
}

/// Diameter of a branch \[m\]: a number (constant) or a list with one value per centre-line point.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Diameter {
    /// The same diameter everywhere.
    Constant(Real),
    /// One diameter per centre-line point.
    PerPoint(Vec<Real>),
}

impl Diameter {
    /// Diameter at centre-line point `i` (a per-point list shorter than the centre-line repeats its
    /// last value; validation rejects that case).
    pub fn at(&self, i: usize) -> Real {
        match self {
            Diameter::Constant(d) => *d,
            Diameter::PerPoint(v) => v.get(i).or(v.last()).copied().unwrap_or(Real::NAN),
        }
    }
}

/// What happens at one end of a branch. Written as a table with a `type` (`closed`, `inlet`,
/// `outlet`) and, for an outlet only, `flow_fraction`; any other key is rejected (also on `closed`
/// and `inlet`, which serde's internally tagged unit variants would silently accept).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "BranchEndRepr", into = "BranchEndRepr")]
pub enum BranchEnd {
    /// Rounded cap (the disk of the end point); also a branch starting inside another one.
    Closed,
    /// The geometry's inlet (only as a branch's `start`): the inflow waveform is imposed here.
    Inlet,
    /// An outlet (only as a branch's `end`).
    Outlet {
        /// Fraction of the inlet flow rate leaving through this outlet, in (0, 1\]; the fractions of
        /// all outlets sum to 1.
        flow_fraction: Real,
    },
}

/// The written form of a [`BranchEnd`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct BranchEndRepr {
    #[serde(rename = "type")]
    kind: EndKind,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    flow_fraction: Option<Real>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
enum EndKind {
    Closed,
    Inlet,
    Outlet,
}

impl TryFrom<BranchEndRepr> for BranchEnd {
    type Error = String;

    fn try_from(r: BranchEndRepr) -> Result<Self, String> {
        match (r.kind, r.flow_fraction) {
            (EndKind::Closed, None) => Ok(BranchEnd::Closed),
            (EndKind::Inlet, None) => Ok(BranchEnd::Inlet),
            (EndKind::Outlet, Some(flow_fraction)) => Ok(BranchEnd::Outlet { flow_fraction }),
            (EndKind::Outlet, None) => Err("an outlet needs `flow_fraction` (its share of the inlet flow)".into()),
            (_, Some(_)) => Err("`flow_fraction` is only allowed on an outlet".into()),
        }
    }
}

impl From<BranchEnd> for BranchEndRepr {
    fn from(e: BranchEnd) -> Self {
        match e {
            BranchEnd::Closed => BranchEndRepr { kind: EndKind::Closed, flow_fraction: None },
            BranchEnd::Inlet => BranchEndRepr { kind: EndKind::Inlet, flow_fraction: None },
            BranchEnd::Outlet { flow_fraction } => {
                BranchEndRepr { kind: EndKind::Outlet, flow_fraction: Some(flow_fraction) }
            }
        }
    }
}

impl BranchEnd {
    /// True for inlets and outlets.
    pub fn is_open(&self) -> bool {
        !matches!(self, BranchEnd::Closed)
    }

    fn word(&self) -> &'static str {
        match self {
            BranchEnd::Closed => "closed",
            BranchEnd::Inlet => "inlet",
            BranchEnd::Outlet { .. } => "outlet",
        }
    }
}

/// Tolerance on the sum of the outlets' flow fractions.
pub const FLOW_FRACTION_TOLERANCE: Real = 1e-9;

/// A geometry, or its build options, outside the allowed range. Every variant names the offending
/// field by its path, e.g. `branches[1].diameter[2]`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GeometryError {
    /// A value outside its range, e.g. `branches[1].diameter[2] = -0.001: allowed > 0 [m]`.
    #[error("{field} = {value}: allowed {allowed}")]
    OutOfRange {
        /// Field path.
        field: String,
        /// Offending value, printed.
        value: String,
        /// Allowed range, in words, with the unit.
        allowed: String,
    },
    /// A list with the wrong number of entries, e.g. `branches[0].centreline: 1 point, allowed at least 2`.
    #[error("{field}: {found}, allowed {allowed}")]
    Count {
        /// Field path.
        field: String,
        /// What was found.
        found: String,
        /// What is allowed.
        allowed: String,
    },
    /// A shape that cannot be built (zero-length segment, radius changing faster than the
    /// centre-line, a branch reaching beyond its own opening, overlapping reservoirs …).
    #[error("{field}: {reason}")]
    Shape {
        /// Field path.
        field: String,
        /// What is wrong and what is allowed.
        reason: String,
    },
    /// Inconsistent open ends: no inlet with outlets, two inlets, an inlet without outlets.
    #[error("{field}: {reason}")]
    OpenEnds {
        /// Field path(s) of the ends concerned, comma-separated.
        field: String,
        /// What is wrong and what is allowed.
        reason: String,
    },
    /// The outlets' flow fractions do not sum to 1 (mass balance).
    #[error("{field}: flow fractions sum to {sum}, allowed a sum of 1 (±1e-9): the outlets carry the inlet flow")]
    FlowFractions {
        /// The outlets' `flow_fraction` fields with their values, comma-separated.
        field: String,
        /// Their sum.
        sum: Real,
    },
    /// An open boundary that [`OpenBoundary::validate`](crate::boundary::OpenBoundary::validate) rejects.
    #[error("open boundary of {field}: {reason}")]
    Boundary {
        /// Field path of the branch end.
        field: String,
        /// The boundary's own message.
        reason: String,
    },
}

impl GeometryError {
    /// The field path the error names (for `FlowFractions` and `OpenEnds`, the list of fields).
    pub fn field(&self) -> &str {
        match self {
            GeometryError::OutOfRange { field, .. }
            | GeometryError::Count { field, .. }
            | GeometryError::Shape { field, .. }
            | GeometryError::OpenEnds { field, .. }
            | GeometryError::FlowFractions { field, .. }
            | GeometryError::Boundary { field, .. } => field,
        }
    }
}

pub(crate) fn out_of_range(
    field: impl Into<String>,
    value: impl ToString,
    allowed: impl Into<String>,
) -> GeometryError {
    GeometryError::OutOfRange { field: field.into(), value: value.to_string(), allowed: allowed.into() }
}

fn plural(n: usize, word: &str) -> String {
    if n == 1 {
        format!("1 {word}")
    } else {
        format!("{n} {word}s")
    }
}

impl Branch {
    /// Number of centre-line points.
    pub fn len(&self) -> usize {
        self.centreline.len()
    }

    /// True when the centre-line has no points.
    pub fn is_empty(&self) -> bool {
        self.centreline.is_empty()
    }

    /// Radius at centre-line point `i` \[m\].
    pub fn radius(&self, i: usize) -> Real {
        0.5 * self.diameter.at(i)
    }

    /// Centre-line length \[m\].
    pub fn length(&self) -> Real {
        self.centreline.windows(2).map(|w| ((w[1][0] - w[0][0]).powi(2) + (w[1][1] - w[0][1]).powi(2)).sqrt()).sum()
    }

    /// The end on `side`.
    pub fn end_on(&self, side: EndSide) -> BranchEnd {
        match side {
            EndSide::Start => self.start,
            EndSide::End => self.end,
        }
    }

    /// Diameter at the end on `side` \[m\].
    pub fn end_diameter(&self, side: EndSide) -> Real {
        match side {
            EndSide::Start => self.diameter.at(0),
            EndSide::End => self.diameter.at(self.len().saturating_sub(1)),
        }
    }

    fn validate(&self, b: usize) -> Result<(), GeometryError> {
        let f = |s: &str| format!("branches[{b}].{s}");
        if self.name.trim().is_empty() {
            return Err(out_of_range(f("name"), format!("{:?}", self.name), "a non-empty name"));
        }
        let n = self.centreline.len();
        if n < 2 {
            return Err(GeometryError::Count {
                field: f("centreline"),
                found: plural(n, "point"),
                allowed: "at least 2".into(),
            });
        }
        for (i, p) in self.centreline.iter().enumerate() {
            for (c, v) in p.iter().enumerate() {
                if !v.is_finite() {
                    return Err(out_of_range(f(&format!("centreline[{i}][{c}]")), v, "finite [m]"));
                }
            }
        }
        match &self.diameter {
            Diameter::Constant(d) => {
                if !(d.is_finite() && *d > 0.0) {
                    return Err(out_of_range(f("diameter"), d, "> 0 [m]"));
                }
            }
            Diameter::PerPoint(v) => {
                if v.len() != n {
                    return Err(GeometryError::Count {
                        field: f("diameter"),
                        found: plural(v.len(), "value"),
                        allowed: format!("one number, or one value per centre-line point ({n})"),
                    });
                }
                for (i, d) in v.iter().enumerate() {
                    if !(d.is_finite() && *d > 0.0) {
                        return Err(out_of_range(f(&format!("diameter[{i}]")), d, "> 0 [m]"));
                    }
                }
            }
        }
        for i in 1..n {
            let (p, q) = (self.centreline[i - 1], self.centreline[i]);
            let len = ((q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2)).sqrt();
            if len <= shape::MIN_SEGMENT {
                return Err(GeometryError::Shape {
                    field: f(&format!("centreline[{i}]")),
                    reason: format!(
                        "segment from centreline[{}] has length {len} m, allowed a length > {} m (no repeated points)",
                        i - 1,
                        shape::MIN_SEGMENT
                    ),
                });
            }
            let dr = (self.radius(i) - self.radius(i - 1)).abs();
            if dr >= shape::MAX_TAPER * len {
                return Err(GeometryError::Shape {
                    field: f(&format!("diameter[{i}]")),
                    reason: format!(
                        "the radius changes by {dr} m over a segment of {len} m, allowed |Δr| < {} × segment length",
                        shape::MAX_TAPER
                    ),
                });
            }
        }
        if let BranchEnd::Outlet { .. } = self.start {
            return Err(out_of_range(
                f("start"),
                self.start.word(),
                "closed or inlet (branches are written in flow direction: an outlet is a branch's end)",
            ));
        }
        match self.end {
            BranchEnd::Closed => {}
            BranchEnd::Outlet { flow_fraction } => {
                if !(flow_fraction.is_finite() && flow_fraction > 0.0 && flow_fraction <= 1.0) {
                    return Err(out_of_range(f("end.flow_fraction"), flow_fraction, "0 < flow_fraction <= 1"));
                }
            }
            BranchEnd::Inlet => {
                return Err(out_of_range(
                    f("end"),
                    "inlet",
                    "closed or outlet (branches are written in flow direction: an inlet is a branch's start)",
                ))
            }
        }
        // The flat cut of an opening must only remove the end cap: every other centre-line disk lies
        // behind the opening's line.
        for side in [EndSide::Start, EndSide::End] {
            if !self.end_on(side).is_open() {
                continue;
            }
            let (origin, normal, _) = shape::end_frame(self, side);
            let end_index = match side {
                EndSide::Start => 0,
                EndSide::End => n - 1,
            };
            for (i, p) in self.centreline.iter().enumerate() {
                if i == end_index {
                    continue;
                }
                let s = (p[0] - origin[0]) * normal[0] + (p[1] - origin[1]) * normal[1];
                let beyond = s + self.radius(i);
                if beyond > 1e-9 * self.radius(i) {
                    let side_name = if side == EndSide::Start { "start" } else { "end" };
                    return Err(GeometryError::Shape {
                        field: f(&format!("centreline[{i}]")),
                        reason: format!(
                            "its disk reaches {beyond} m beyond the opening at the branch's {side_name}; allowed: \
                             every centre-line disk other than the end point's lies behind its opening (make the \
                             end segment straight and at least one radius long)"
                        ),
                    });
                }
            }
        }
        Ok(())
    }
}

impl VesselGeometry {
    /// Checks the geometry; the error names the first bad field (see [`GeometryError`]). The
    /// resolution-dependent checks (diameter ≥ 4 dx, reservoir depth) are made by [`Self::build`].
    pub fn validate(&self) -> Result<(), GeometryError> {
        if !(self.fillet.is_finite() && self.fillet >= 0.0) {
            return Err(out_of_range("fillet", self.fillet, ">= 0 [m]"));
        }
        if self.branches.is_empty() {
            return Err(GeometryError::Count {
                field: "branches".into(),
                found: "0 branches".into(),
                allowed: "at least 1".into(),
            });
        }
        for (b, br) in self.branches.iter().enumerate() {
            br.validate(b)?;
            if let Some(a) = self.branches[..b].iter().position(|o| o.name == br.name) {
                return Err(out_of_range(
                    format!("branches[{b}].name"),
                    format!("{:?}", br.name),
                    format!("a name not used by another branch (branches[{a}] has it)"),
                ));
            }
        }
        let inlets: Vec<String> = self
            .branches
            .iter()
            .enumerate()
            .filter(|(_, br)| br.start == BranchEnd::Inlet)
            .map(|(b, _)| format!("branches[{b}].start"))
            .collect();
        let outlets: Vec<(String, Real)> = self
            .branches
            .iter()
            .enumerate()
            .filter_map(|(b, br)| match br.end {
                BranchEnd::Outlet { flow_fraction } => {
                    Some((format!("branches[{b}].end.flow_fraction"), flow_fraction))
                }
                _ => None,
            })
            .collect();
        if inlets.len() > 1 {
            return Err(GeometryError::OpenEnds {
                field: inlets.join(", "),
                reason: format!("{} inlets, allowed exactly one", inlets.len()),
            });
        }
        if inlets.is_empty() && !outlets.is_empty() {
            let names: Vec<&str> = outlets.iter().map(|(f, _)| f.as_str()).collect();
            return Err(GeometryError::OpenEnds {
                field: names.join(", "),
                reason:
                    "outlets without an inlet, allowed exactly one inlet (a branch's start) when there are open ends"
                        .into(),
            });
        }
        if !inlets.is_empty() {
            let sum: Real = outlets.iter().map(|(_, v)| v).sum();
            if outlets.is_empty() {
                return Err(GeometryError::OpenEnds {
                    field: inlets.join(", "),
                    reason: "an inlet without outlets, allowed at least one outlet carrying the inlet flow".into(),
                });
            }
            if (sum - 1.0).abs() > FLOW_FRACTION_TOLERANCE {
                let list: Vec<String> = outlets.iter().map(|(f, v)| format!("{f} = {v}")).collect();
                return Err(GeometryError::FlowFractions { field: list.join(", "), sum });
            }
        }
        Ok(())
    }

    /// The openings (inlet first, then the outlets in branch order), at their unsnapped positions.
    pub fn openings(&self) -> Vec<Opening> {
        shape::openings(self)
    }

    /// The compiled lumen (no reservoirs, openings at their centre-line end points) for repeated
    /// signed-distance queries.
    pub fn lumen(&self) -> Lumen {
        Lumen::new(self, &self.openings(), 0.0)
    }

    /// Approximate signed distance to the lumen wall \[m\]: negative inside, exact outside (distance to
    /// the union of the swept disks, cut flat at the openings), inside the largest depth into one
    /// swept disk (a lower bound of the true depth; exact in straight constant-diameter tubes).
    /// Compiles the geometry on every call: for many queries use [`Self::lumen`] or the scene's
    /// [`SdfGrid`].
    pub fn signed_distance(&self, x: Real, z: Real) -> Real {
        self.lumen().signed_distance(x, z)
    }

    /// Builds the particle set at resolution `opts.dx` (validates the geometry and the options first).
    pub fn build(&self, opts: &BuildOptions) -> Result<VesselScene, GeometryError> {
        build::build(self, opts)
    }

    /// Mean-velocity scale of every branch: the factor s_b such that the cross-section mean velocity
    /// in branch b at diameter D is `inflow · s_b · D_inlet / D`, i.e. the branch's share of the inlet
    /// flow rate (inlet branch 1, outlet branch its `flow_fraction`, closed–closed branch 0).
    pub fn flow_shares(&self) -> Vec<Real> {
        self.branches
            .iter()
            .map(|br| match (br.start, br.end) {
                (BranchEnd::Inlet, _) => 1.0,
                (_, BranchEnd::Outlet { flow_fraction }) => flow_fraction,
                _ => 0.0,
            })
            .collect()
    }
}
