//! Signed distance of a vessel geometry: swept disks ("cones") per centre-line segment, flat cuts at
//! the openings, straight reservoir extensions; openings; the sampled [`SdfGrid`].
//!
//! One segment from P₀ to P₁ (unit direction u, length L) with radius r(s) = r₀ + k s sweeps the union
//! of the disks of radius r(s) centred at P₀ + s u, s ∈ [0, L]. For a point with along-coordinate a and
//! perpendicular distance b, g(s) = √((a − s)² + b²) − r(s) is convex in s and its minimum over
//! [0, L] is at s* = clamp(a + k b / √(1 − k²)); g(s*) is the exact distance to the swept union outside
//! it and minus the largest depth into one of its disks inside (|k| < 1, see [`MAX_TAPER`]). A branch
//! is the union of its segments, cut by the half-plane behind each of its openings; the lumen is the
//! union of the branches (min over branches, max with the cuts).

use serde::{Deserialize, Serialize};

use super::{Branch, BranchEnd, VesselGeometry};
use crate::Real;

/// Shortest segment accepted \[m\].
pub const MIN_SEGMENT: Real = 1e-9;
/// Largest radius change per unit centre-line length accepted (the swept disks must not swallow
/// each other).
pub const MAX_TAPER: Real = 0.9;

/// Which end of a branch.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum EndSide {
    /// The first centre-line point.
    Start,
    /// The last centre-line point.
    End,
}

/// An open end of a branch: the flat opening the reservoir is attached to.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Opening {
    /// Name of the open boundary: the branch name, or `<name>-start` / `<name>-end` when both ends of
    /// the branch are open.
    pub name: String,
    /// Index of the branch.
    pub branch: usize,
    /// Which end.
    pub side: EndSide,
    /// The end's description (`Inlet` or `Outlet`).
    pub end: BranchEnd,
    /// Centre of the opening \[m\] (the end point, or the snapped position, see
    /// [`super::BuildOptions::lattice_origin`]).
    pub origin: [Real; 2],
    /// Unit normal out of the lumen, into the reservoir (the end segment's direction, outwards).
    pub normal: [Real; 2],
    /// Half-width \[m\]: the end radius.
    pub half_width: Real,
}

impl Opening {
    /// (s, y): distance beyond the opening along the normal and lateral coordinate (along
    /// t = (−n_z, n_x)), as [`crate::boundary::OpenBoundary::local`].
    #[inline]
    pub fn local(&self, x: Real, z: Real) -> (Real, Real) {
        let (dx, dz) = (x - self.origin[0], z - self.origin[1]);
        let n = self.normal;
        (dx * n[0] + dz * n[1], -dx * n[1] + dz * n[0])
    }

    /// True for the inlet.
    pub fn is_inlet(&self) -> bool {
        self.end == BranchEnd::Inlet
    }

    /// Outlet flow fraction (1 for the inlet).
    pub fn flow_fraction(&self) -> Real {
        match self.end {
            BranchEnd::Outlet { flow_fraction } => flow_fraction,
            _ => 1.0,
        }
    }
}

/// (origin, outward unit normal, radius) of the end of `branch` on `side` (the branch must have two
/// distinct points there; a degenerate end gets the normal (±1, 0)).
pub(crate) fn end_frame(branch: &Branch, side: EndSide) -> ([Real; 2], [Real; 2], Real) {
    let n = branch.centreline.len();
    let (i, j) = match side {
        EndSide::Start => (0, 1.min(n.saturating_sub(1))),
        EndSide::End => (n.saturating_sub(1), n.saturating_sub(2)),
    };
    let p = branch.centreline.get(i).copied().unwrap_or([0.0, 0.0]);
    let q = branch.centreline.get(j).copied().unwrap_or(p);
    let (ux, uz) = (p[0] - q[0], p[1] - q[1]);
    let len = (ux * ux + uz * uz).sqrt();
    let normal = if len > MIN_SEGMENT {
        [ux / len, uz / len]
    } else if side == EndSide::Start {
        [-1.0, 0.0]
    } else {
        [1.0, 0.0]
    };
    (p, normal, branch.radius(i))
}

/// The openings of a geometry: the inlet first, then the outlets in branch order.
pub(crate) fn openings(geom: &VesselGeometry) -> Vec<Opening> {
    let mut out = Vec::new();
    for want_inlet in [true, false] {
        for (b, br) in geom.branches.iter().enumerate() {
            if br.centreline.len() < 2 {
                continue;
            }
            let both = br.start.is_open() && br.end.is_open();
            for side in [EndSide::Start, EndSide::End] {
                let end = br.end_on(side);
                if !end.is_open() || (end == BranchEnd::Inlet) != want_inlet {
                    continue;
                }
                let (origin, normal, r) = end_frame(br, side);
                let name = match (both, side) {
                    (false, _) => br.name.clone(),
                    (true, EndSide::Start) => format!("{}-start", br.name),
                    (true, EndSide::End) => format!("{}-end", br.name),
                };
                out.push(Opening { name, branch: b, side, end, origin, normal, half_width: r });
            }
        }
    }
    out
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct Cone {
    p0: [Real; 2],
    u: [Real; 2],
    len: Real,
    r0: Real,
    k: Real,
    c: Real,
    /// xmin, xmax, zmin, zmax of the swept disks.
    bbox: [Real; 4],
    /// Reservoir extension (not part of the branch's centre-line).
    extension: bool,
}

impl Cone {
    fn new(p0: [Real; 2], p1: [Real; 2], r0: Real, r1: Real, extension: bool) -> Self {
        let (dx, dz) = (p1[0] - p0[0], p1[1] - p0[1]);
        let len = (dx * dx + dz * dz).sqrt();
        let (u, k) = if len > MIN_SEGMENT { ([dx / len, dz / len], (r1 - r0) / len) } else { ([1.0, 0.0], 0.0) };
        let k = k.clamp(-MAX_TAPER, MAX_TAPER);
        let c = k / (1.0 - k * k).sqrt();
        let bbox = [
            (p0[0] - r0).min(p1[0] - r1),
            (p0[0] + r0).max(p1[0] + r1),
            (p0[1] - r0).min(p1[1] - r1),
            (p0[1] + r0).max(p1[1] + r1),
        ];
        Cone { p0, u, len: if len > MIN_SEGMENT { len } else { 0.0 }, r0, k, c, bbox, extension }
    }

    /// (along, perpendicular distance ≥ 0).
    #[inline(always)]
    fn frame(&self, x: Real, z: Real) -> (Real, Real) {
        let (dx, dz) = (x - self.p0[0], z - self.p0[1]);
        (dx * self.u[0] + dz * self.u[1], (dx * self.u[1] - dz * self.u[0]).abs())
    }

    #[inline(always)]
    fn sd(&self, x: Real, z: Real) -> Real {
        let (a, b) = self.frame(x, z);
        let s = (a + self.c * b).clamp(0.0, self.len);
        (a - s).hypot(b) - (self.r0 + self.k * s)
    }

    /// Lower bound of [`Self::sd`]: distance to the bounding box outside it, −∞ inside.
    #[inline(always)]
    fn bound(&self, x: Real, z: Real) -> Real {
        box_bound(&self.bbox, x, z)
    }
}

/// Lower bound of the signed distance of anything inside `bbox` (xmin, xmax, zmin, zmax): the
/// distance to the box outside it, −∞ inside.
#[inline(always)]
fn box_bound(bbox: &[Real; 4], x: Real, z: Real) -> Real {
    let ex = (bbox[0] - x).max(x - bbox[1]);
    let ez = (bbox[2] - z).max(z - bbox[3]);
    if ex <= 0.0 && ez <= 0.0 {
        Real::NEG_INFINITY
    } else {
        ex.max(0.0).hypot(ez.max(0.0))
    }
}

#[derive(Clone, Debug, PartialEq)]
struct Shape {
    cones: Vec<Cone>,
    /// (origin, normal) of the cuts (the branch's openings).
    cuts: Vec<([Real; 2], [Real; 2])>,
    /// Bounding box of the cones (with extensions).
    bbox: [Real; 4],
}

/// Where a point lies relative to the nearest branch segment (see [`Lumen::nearest_segment`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SegmentHit {
    /// Branch index.
    pub branch: usize,
    /// Segment index (from centre-line point `segment` to `segment + 1`).
    pub segment: usize,
    /// Unit tangent of the segment, from the branch's start towards its end.
    pub tangent: [Real; 2],
    /// Distance from the centre-line (to the foot of the perpendicular, clamped to the segment) \[m\].
    pub lateral: Real,
    /// Radius at the foot \[m\].
    pub radius: Real,
}

/// A geometry compiled for signed-distance queries, with its openings (possibly snapped to a
/// lattice) and reservoirs of depth [`Lumen::reservoir_depth`].
#[derive(Clone, Debug, PartialEq)]
pub struct Lumen {
    shapes: Vec<Shape>,
    openings: Vec<Opening>,
    depth: Real,
    fillet: Real,
}

/// Polynomial smooth minimum min(a, b) − k/4 · max(0, 1 − |a − b|/k)² (plain min for k = 0).
#[inline]
fn smooth_min(a: Real, b: Real, k: Real) -> Real {
    let m = a.min(b);
    if k <= 0.0 || !m.is_finite() {
        return m;
    }
    let h = (1.0 - (a - b).abs() / k).max(0.0);
    m - 0.25 * k * h * h
}

impl Lumen {
    /// Compiles `geom` with the given openings (from [`VesselGeometry::openings`], possibly moved
    /// along their normals) and reservoirs of depth `depth` \[m\] (0: none). Degenerate segments are
    /// skipped, so an invalid geometry gives a meaningless but finite distance, never a panic.
    pub fn new(geom: &VesselGeometry, openings: &[Opening], depth: Real) -> Self {
        let depth = depth.max(0.0);
        let shapes = geom
            .branches
            .iter()
            .enumerate()
            .map(|(b, br)| {
                let pts = &br.centreline;
                let mut cones: Vec<Cone> = (1..pts.len())
                    .map(|i| Cone::new(pts[i - 1], pts[i], br.radius(i - 1), br.radius(i), false))
                    .filter(|c| c.len > 0.0)
                    .collect();
                if cones.is_empty() {
                    if let Some(&p) = pts.first() {
                        cones.push(Cone::new(p, p, br.radius(0), br.radius(0), false));
                    }
                }
                let mut cuts = Vec::new();
                for o in openings.iter().filter(|o| o.branch == b) {
                    let (end_point, _, _) = end_frame(br, o.side);
                    // the extension starts at the end point or the opening, whichever is further back
                    let s_end = (end_point[0] - o.origin[0]) * o.normal[0] + (end_point[1] - o.origin[1]) * o.normal[1];
                    let back = s_end.min(0.0);
                    let p0 = [o.origin[0] + back * o.normal[0], o.origin[1] + back * o.normal[1]];
                    let p1 = [o.origin[0] + depth * o.normal[0], o.origin[1] + depth * o.normal[1]];
                    let ext = Cone::new(p0, p1, o.half_width, o.half_width, true);
                    if ext.len > 0.0 {
                        cones.push(ext);
                    }
                    cuts.push((o.origin, o.normal));
                }
                let mut bbox = [Real::INFINITY, Real::NEG_INFINITY, Real::INFINITY, Real::NEG_INFINITY];
                for c in &cones {
                    bbox = [
                        bbox[0].min(c.bbox[0]),
                        bbox[1].max(c.bbox[1]),
                        bbox[2].min(c.bbox[2]),
                        bbox[3].max(c.bbox[3]),
                    ];
                }
                Shape { cones, cuts, bbox }
            })
            .collect();
        Lumen { shapes, openings: openings.to_vec(), depth, fillet: geom.fillet.max(0.0) }
    }

    /// The openings.
    pub fn openings(&self) -> &[Opening] {
        &self.openings
    }

    /// Depth of the reservoirs \[m\] (0 when compiled without).
    pub fn reservoir_depth(&self) -> Real {
        self.depth
    }

    #[inline]
    fn eval(&self, x: Real, z: Real, offset: Real) -> Real {
        let mut best = Real::INFINITY;
        let k = self.fillet;
        for sh in &self.shapes {
            if box_bound(&sh.bbox, x, z) >= best + k {
                continue;
            }
            let mut d = Real::INFINITY;
            for c in &sh.cones {
                if c.bound(x, z) < d {
                    d = d.min(c.sd(x, z));
                }
            }
            for (o, n) in &sh.cuts {
                d = d.max((x - o[0]) * n[0] + (z - o[1]) * n[1] - offset);
            }
            best = smooth_min(best, d, k);
        }
        best
    }

    /// Signed distance to the lumen wall \[m\] (negative inside), the lumen cut flat at the openings
    /// (reservoirs excluded). See the module documentation for the accuracy.
    pub fn signed_distance(&self, x: Real, z: Real) -> Real {
        self.eval(x, z, 0.0)
    }

    /// Signed distance to the wall of the lumen extended by its reservoirs \[m\] (the straight
    /// extension of each open end by the reservoir depth, cut flat at the far side). The wall
    /// particles lie on its level sets.
    pub fn signed_distance_with_reservoirs(&self, x: Real, z: Real) -> Real {
        self.eval(x, z, self.depth)
    }

    /// The branch segment whose swept disks contain (x, z) deepest (smallest swept distance over the
    /// centre-line segments of all branches; reservoir extensions excluded); `None` without segments.
    pub fn nearest_segment(&self, x: Real, z: Real) -> Option<SegmentHit> {
        let mut best: Option<(Real, SegmentHit)> = None;
        for (b, sh) in self.shapes.iter().enumerate() {
            for (i, c) in sh.cones.iter().enumerate().filter(|(_, c)| !c.extension) {
                let d = c.sd(x, z);
                if best.as_ref().is_some_and(|(bd, _)| *bd <= d) {
                    continue;
                }
                let (a, perp) = c.frame(x, z);
                let foot = a.clamp(0.0, c.len);
                let hit = SegmentHit {
                    branch: b,
                    segment: i,
                    tangent: c.u,
                    lateral: (a - foot).hypot(perp),
                    radius: c.r0 + c.k * foot,
                };
                best = Some((d, hit));
            }
        }
        best.map(|(_, h)| h)
    }

    /// Bounding box ([x_min, z_min], [x_max, z_max]) \[m\] of the lumen with its reservoirs.
    pub fn bounding_box(&self) -> ([Real; 2], [Real; 2]) {
        let mut b = [Real::INFINITY, Real::NEG_INFINITY, Real::INFINITY, Real::NEG_INFINITY];
        for sh in &self.shapes {
            b = [b[0].min(sh.bbox[0]), b[1].max(sh.bbox[1]), b[2].min(sh.bbox[2]), b[3].max(sh.bbox[3])];
        }
        ([b[0], b[2]], [b[1], b[3]])
    }
}

/// A signed distance sampled on a regular grid, with O(1) bilinear lookup: the scene's "inside the
/// vessel" mask for other code (ultrasound scatterer masks, plots).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SdfGrid {
    /// Position of node (0, 0) \[m\] (x, z).
    pub origin: [Real; 2],
    /// Node spacing \[m\] (dx/2 in a built scene).
    pub spacing: Real,
    /// Nodes along x.
    pub nx: usize,
    /// Nodes along z.
    pub nz: usize,
    /// Values \[m\], row-major: node (i, j) at `values[j * nx + i]`, position origin + (i, j)·spacing.
    pub values: Vec<Real>,
}

impl SdfGrid {
    /// Samples `f` on `nx` × `nz` nodes (each at least 2) from `origin` with `spacing`.
    pub fn sample<F>(f: F, origin: [Real; 2], spacing: Real, nx: usize, nz: usize, parallel: bool) -> Self
    where
        F: Fn(Real, Real) -> Real + Sync,
    {
        let (nx, nz) = (nx.max(2), nz.max(2));
        let values =
            sample_rows(parallel, nx, nz, |i, j| f(origin[0] + i as Real * spacing, origin[1] + j as Real * spacing));
        SdfGrid { origin, spacing, nx, nz, values }
    }

    /// Position of node (i, j) \[m\].
    pub fn node(&self, i: usize, j: usize) -> [Real; 2] {
        [self.origin[0] + i as Real * self.spacing, self.origin[1] + j as Real * self.spacing]
    }

    /// Bilinear interpolation at (x, z) \[m\]. Outside the grid: the value at the nearest grid point
    /// plus the distance to it (the grid of a scene extends beyond the walls, so this stays positive).
    pub fn value(&self, x: Real, z: Real) -> Real {
        let fx = (x - self.origin[0]) / self.spacing;
        let fz = (z - self.origin[1]) / self.spacing;
        let (mx, mz) = ((self.nx - 1) as Real, (self.nz - 1) as Real);
        let (cx, cz) = (fx.clamp(0.0, mx), fz.clamp(0.0, mz));
        let outside = ((fx - cx).hypot(fz - cz)) * self.spacing;
        let i = (cx.floor() as usize).min(self.nx - 2);
        let j = (cz.floor() as usize).min(self.nz - 2);
        let (tx, tz) = (cx - i as Real, cz - j as Real);
        let v = |i: usize, j: usize| self.values[j * self.nx + i];
        let a = v(i, j) * (1.0 - tx) + v(i + 1, j) * tx;
        let b = v(i, j + 1) * (1.0 - tx) + v(i + 1, j + 1) * tx;
        a * (1.0 - tz) + b * tz + outside
    }

    /// True when (x, z) is inside (interpolated value < 0).
    pub fn is_inside(&self, x: Real, z: Real) -> bool {
        self.value(x, z) < 0.0
    }
}

impl crate::walls::Domain for SdfGrid {
    fn signed_distance(&self, x: Real, z: Real) -> Real {
        self.value(x, z)
    }
}

/// Evaluates `f(i, j)` on an nx × nz grid, row-major, rows on rayon threads when `parallel` (same
/// result either way).
pub(crate) fn sample_rows<F>(parallel: bool, nx: usize, nz: usize, f: F) -> Vec<Real>
where
    F: Fn(usize, usize) -> Real + Sync,
{
    let row = |j: usize| (0..nx).map(|i| f(i, j)).collect::<Vec<Real>>();
    #[cfg(feature = "parallel")]
    if parallel {
        use rayon::prelude::*;
        let rows: Vec<Vec<Real>> = (0..nz).into_par_iter().map(row).collect();
        return rows.concat();
    }
    let _ = parallel;
    (0..nz).flat_map(row).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cone_distance_is_exact_outside_a_tapered_segment() {
        // Brute force: min over many disks along the segment.
        let c = Cone::new([0.0, 0.0], [0.01, 0.002], 0.002, 0.001, false);
        for (x, z) in [(0.005, 0.006), (-0.004, 0.001), (0.013, 0.004), (0.006, -0.003), (0.003, 0.0005)] {
            let mut best = Real::INFINITY;
            for m in 0..=20000 {
                let s = m as Real / 20000.0;
                let (px, pz) = (0.01 * s, 0.002 * s);
                let r = 0.002 - 0.001 * s;
                best = best.min((x - px).hypot(z - pz) - r);
            }
            assert!((c.sd(x, z) - best).abs() < 1e-9, "({x}, {z}): {} vs {best}", c.sd(x, z));
        }
    }
}
