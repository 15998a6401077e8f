//! The particle set of a vessel geometry: options, scene, generator.

use std::collections::HashMap;

use serde::{Deserialize, Serialize};

use super::contour::level_set;
use super::shape::{sample_rows, Lumen, Opening, SdfGrid};
use super::{out_of_range, BranchEnd, Diameter, GeometryError, VesselGeometry};
use crate::boundary::{ramp, OpenBoundary, ProfileKind};
use crate::params::SphParams;
use crate::particles::{ParticleKind, Particles};
use crate::waveform::{Waveform, WaveformSpec};
use crate::womersley::profile_velocity;
use crate::Real;

/// Initial velocity of the fluid particles.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum InitialVelocity {
    /// Fluid at rest. Default.
    #[default]
    Rest,
    /// Every fluid particle gets the fully developed profile ([`BuildOptions::profile`]) of its
    /// branch at `t0`: along the tangent of the nearest centre-line segment (oriented start → end,
    /// i.e. in flow direction), lateral coordinate = distance from the centre-line, half-width = local
    /// radius, cross-section mean velocity = inflow(t0) · share · D_inlet / D_local (share: 1 in the
    /// inlet branch, the `flow_fraction` in an outlet branch, 0 in a closed–closed branch), times the
    /// ramp factor at `t0`. "Nearest" is the segment whose swept disks contain the particle deepest;
    /// where branches overlap (at a bifurcation) the direction changes abruptly.
    FullyDeveloped,
}

/// Options of [`VesselGeometry::build`] (SI units). Defaults: the paper's carotid case.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BuildOptions {
    /// Lattice spacing dx \[m\]; every particle stands for dx² of fluid. Default 0.15e-3 (the paper).
    pub dx: Real,
    /// Kernel support radius κh of the solver \[m\] (sizes the walls and the reservoirs). Default
    /// 0.45e-3 (quartic spline, 2.5 h with h = 1.2 dx = 0.18 mm). [`BuildOptions::for_solver`] sets it
    /// from solver parameters.
    pub support: Real,
    /// Layers of type II wall particles (at SDF = dx, 2dx, …). Default `None`: the layers k with
    /// k·dx < support (see [`BuildOptions::layers`]).
    pub wall_layers: Option<usize>,
    /// Depth of each reservoir along its normal \[m\], ≥ `support`. Default `None`: support + 2 dx.
    pub reservoir_depth: Option<Real>,
    /// Reference density ρ₀ \[kg/m³\] (density of every particle, mass ρ₀ dx²). Default 1000.
    pub rho0: Real,
    /// Kinematic viscosity ν \[m²/s\] (Womersley profiles). Default 4e-6.
    pub nu: Real,
    /// Cross-section mean velocity at the inlet \[m/s\] (into the domain); the outlets get their share.
    /// Default: the synthetic carotid waveform (peak 0.39, mean 0.1875, period 0.83 s).
    pub inflow: Waveform,
    /// Velocity profile across the openings (and of `FullyDeveloped`). Default Womersley.
    pub profile: ProfileKind,
    /// Ramp time of the imposed velocity \[s\] (see [`OpenBoundary::ramp_time`]). Default 0.
    pub ramp_time: Real,
    /// Initial velocity of the fluid. Default rest.
    pub initial_velocity: InitialVelocity,
    /// Time of the initial state \[s\] (reservoir and initial velocities are evaluated at t0). Default 0.
    pub t0: Real,
    /// A node of the fluid lattice \[m\] (x, z); the lattice is lattice_origin + (i, j)·dx. An opening
    /// whose normal is along x or z is moved along its normal (by < dx/2) so that the lattice rows lie
    /// at s = −dx/2 − k dx from it and the reservoir's first row at s = ds/2 continues the lattice
    /// (an end point exactly on a lattice line moves away from the origin's line). Default (0, 0).
    pub lattice_origin: [Real; 2],
    /// Sample the grids on rayon threads (feature `parallel`; the same result either way). Default true.
    pub parallel: bool,
    /// Iterations of the geometric relaxation of the fluid particles against the walls and the
    /// reservoirs (`super::relax`): evens out the kernel sums next to curved walls, where the cut
    /// lattice leaves its first row 0.5–1.5 dx from the wall. Default 0 (the paper's lattice as is);
    /// the `sph-flow` node uses 200.
    #[serde(default)]
    pub relax_iterations: usize,
}

impl Default for BuildOptions {
    fn default() -> Self {
        let carotid = WaveformSpec::Carotid { peak: 0.39, mean: 0.1875, period: 0.83 };
        BuildOptions {
            dx: 0.15e-3,
            support: 0.45e-3,
            wall_layers: None,
            reservoir_depth: None,
            rho0: 1000.0,
            nu: 4e-6,
            inflow: carotid.build().unwrap_or_else(|_| Waveform::constant(0.1875)),
            profile: ProfileKind::Womersley,
            ramp_time: 0.0,
            initial_velocity: InitialVelocity::Rest,
            t0: 0.0,
            lattice_origin: [0.0, 0.0],
            parallel: true,
            relax_iterations: 0,
        }
    }
}

/// Relative tolerance of the lattice tests (points exactly dx/2 from the wall or an opening count
/// as inside: aligned lattices put whole rows there).
const TIE: Real = 1e-9;
/// Sub-sampling of the wall grid: spacing dx / 4.
const FINE: Real = 4.0;
/// Largest wall grid accepted (nodes).
const MAX_GRID_NODES: usize = 60_000_000;

impl BuildOptions {
    /// Options for a solver with parameters `params` at lattice spacing `dx`: support = κh of its
    /// kernel, ρ₀ and ν = μ/ρ₀ from it; the rest default.
    pub fn for_solver(params: &SphParams, dx: Real) -> Self {
        BuildOptions {
            dx,
            support: params.kernel.support_factor() * params.h,
            rho0: params.rho0,
            nu: params.nu(),
            ..Default::default()
        }
    }

    /// Type II layers in use: `wall_layers`, or every layer a fluid particle on the wall can reach:
    /// k = 1, 2, … with k·dx < support (2 for the quartic spline's 2.5 h = 3 dx at h = 1.2 dx: the
    /// layer at 3 dx would only touch fluid that has crossed the wall, which the guard puts back).
    pub fn layers(&self) -> usize {
        self.wall_layers
            .unwrap_or_else(|| (((self.support / self.dx) * (1.0 - 1e-9)).ceil() as usize).saturating_sub(1).max(1))
    }

    /// Reservoir depth in use \[m\]: `reservoir_depth`, or support + 2 dx.
    pub fn depth(&self) -> Real {
        self.reservoir_depth.unwrap_or(self.support + 2.0 * self.dx)
    }

    /// Checks every field; the error names the first bad field and its allowed range.
    pub fn validate(&self) -> Result<(), GeometryError> {
        let check = |field: &str, v: Real, ok: bool, allowed: &str| {
            if ok && v.is_finite() {
                Ok(())
            } else {
                Err(out_of_range(field, v, allowed))
            }
        };
        check("dx", self.dx, self.dx > 0.0, "> 0 [m]")?;
        check("support", self.support, self.support > 0.0, "> 0 [m]")?;
        if let Some(l) = self.wall_layers {
            if l > 64 {
                return Err(out_of_range("wall_layers", l, "0 ..= 64"));
            }
        }
        if let Some(d) = self.reservoir_depth {
            check("reservoir_depth", d, d >= self.support, &format!(">= support = {} [m]", self.support))?;
        }
        check("rho0", self.rho0, self.rho0 > 0.0, "> 0 [kg/m^3]")?;
        check("nu", self.nu, self.nu > 0.0, "> 0 [m^2/s]")?;
        let w = &self.inflow;
        check("inflow.period", w.period, w.period > 0.0, "> 0 [s]")?;
        check("inflow.mean", w.mean, true, "finite [m/s]")?;
        if w.cos.len() != w.sin.len() {
            return Err(GeometryError::Count {
                field: "inflow.sin".into(),
                found: format!("{} terms", w.sin.len()),
                allowed: format!("as many as inflow.cos ({})", w.cos.len()),
            });
        }
        for (name, v) in [("inflow.cos", &w.cos), ("inflow.sin", &w.sin)] {
            if let Some((k, a)) = v.iter().enumerate().find(|(_, a)| !a.is_finite()) {
                return Err(out_of_range(format!("{name}[{k}]"), a, "finite [m/s]"));
            }
        }
        check("ramp_time", self.ramp_time, self.ramp_time >= 0.0, ">= 0 [s]")?;
        check("t0", self.t0, true, "finite [s]")?;
        check("lattice_origin[0]", self.lattice_origin[0], true, "finite [m]")?;
        check("lattice_origin[1]", self.lattice_origin[1], true, "finite [m]")?;
        Ok(())
    }
}

/// The initial state of a vessel flow.
#[derive(Clone, Debug, PartialEq)]
pub struct VesselScene {
    /// All particles: fluid (ids 0 …), then walls (type I, then type II layer by layer), then the
    /// reservoirs' buffer particles (boundary by boundary). Ids are unique and consecutive.
    pub particles: Particles,
    /// One open boundary per opening, in the order of `openings` (inlet first); a buffer particle's
    /// `group` is its boundary's index here.
    pub boundaries: Vec<OpenBoundary>,
    /// The openings as used (snapped), in the order of `boundaries`.
    pub openings: Vec<Opening>,
    /// The lumen's signed distance (reservoirs excluded) sampled at spacing dx/2 over the particles'
    /// bounding box + 2 dx.
    pub sdf: SdfGrid,
    /// The signed distance of the lumen *and* the reservoirs on the same grid: the region the fluid
    /// particles may occupy, for the solver's anti-penetration guard ([`VesselScene::guard_domain`]).
    pub fluid_region: SdfGrid,
    /// The compiled geometry with the openings as used and the reservoirs, for exact queries.
    pub lumen: Lumen,
    /// Area of the lumen \[m²\] (reservoirs excluded), from the wall contour (fine-grid accuracy).
    pub lumen_area: Real,
    /// Lattice spacing dx \[m\].
    pub dx: Real,
    /// Type II layers used.
    pub wall_layers: usize,
    /// Reservoir depth used \[m\].
    pub reservoir_depth: Real,
}

impl VesselScene {
    /// The fluid region (lumen and reservoirs) as a [`crate::walls::Domain`] for
    /// [`crate::Solver::with_domain`].
    pub fn guard_domain(&self) -> std::sync::Arc<dyn crate::walls::Domain> {
        std::sync::Arc::new(self.fluid_region.clone())
    }

    /// Number of particles of `kind`.
    pub fn count(&self, kind: ParticleKind) -> usize {
        self.particles.kind.iter().filter(|&&k| k == kind).count()
    }

    /// True when (x, z) lies in the lumen (reservoirs excluded), from the grid.
    pub fn is_inside(&self, x: Real, z: Real) -> bool {
        self.sdf.is_inside(x, z)
    }
}

/// Moves an axis-aligned opening along its normal to the nearest half-lattice position.
fn snap(o: &mut Opening, origin: [Real; 2], dx: Real) {
    for (axis, &o_axis) in origin.iter().enumerate() {
        if o.normal[axis].abs() >= 1.0 - 1e-9 {
            let sign = o.normal[axis].signum();
            o.normal = [0.0, 0.0];
            o.normal[axis] = sign;
            let q = (o.origin[axis] - o_axis) / dx;
            o.origin[axis] = o_axis + ((q - 0.5).round() + 0.5) * dx;
        }
    }
}

fn check_resolution(geom: &VesselGeometry, dx: Real) -> Result<(), GeometryError> {
    let min = 4.0 * dx;
    for (b, br) in geom.branches.iter().enumerate() {
        match &br.diameter {
            Diameter::Constant(d) if *d < min => {
                return Err(out_of_range(format!("branches[{b}].diameter"), d, format!(">= 4 dx = {min} [m]")));
            }
            Diameter::PerPoint(v) => {
                if let Some((i, d)) = v.iter().enumerate().find(|(_, d)| **d < min) {
                    return Err(out_of_range(
                        format!("branches[{b}].diameter[{i}]"),
                        d,
                        format!(">= 4 dx = {min} [m]"),
                    ));
                }
            }
            _ => {}
        }
    }
    Ok(())
}

fn end_field(o: &Opening) -> String {
    match o.side {
        super::EndSide::Start => format!("branches[{}].start", o.branch),
        super::EndSide::End => format!("branches[{}].end", o.branch),
    }
}

/// The open boundary of opening `o` (see [`BuildOptions`]); `inlet_diameter` scales the outlets.
fn open_boundary(o: &Opening, inlet_diameter: Real, depth: Real, opts: &BuildOptions) -> OpenBoundary {
    let inflow = match o.end {
        BranchEnd::Outlet { flow_fraction } => {
            opts.inflow.scaled(-flow_fraction * inlet_diameter / (2.0 * o.half_width))
        }
        _ => opts.inflow.clone(),
    };
    OpenBoundary {
        name: o.name.clone(),
        origin: o.origin,
        normal: o.normal,
        half_width: o.half_width,
        depth,
        dx: opts.dx,
        inflow,
        profile: opts.profile,
        ramp_time: opts.ramp_time,
    }
}

pub(super) fn build(geom: &VesselGeometry, opts: &BuildOptions) -> Result<VesselScene, GeometryError> {
    geom.validate()?;
    opts.validate()?;
    check_resolution(geom, opts.dx)?;
    let dx = opts.dx;
    let layers = opts.layers();
    let depth = opts.depth();
    let mut openings = geom.openings();
    for o in &mut openings {
        snap(o, opts.lattice_origin, dx);
    }
    let lumen = Lumen::new(geom, &openings, depth);

    // ---- fluid lattice
    let (lo, hi) = lumen.bounding_box();
    let [ox, oz] = opts.lattice_origin;
    let i0 = ((lo[0] - ox) / dx).floor() as i64;
    let i1 = ((hi[0] - ox) / dx).ceil() as i64;
    let j0 = ((lo[1] - oz) / dx).floor() as i64;
    let j1 = ((hi[1] - oz) / dx).ceil() as i64;
    let (ni, nj) = ((i1 - i0 + 1).max(1) as usize, (j1 - j0 + 1).max(1) as usize);
    let limit = -0.5 * dx + TIE * dx;
    let is_fluid = |x: Real, z: Real| {
        if lumen.signed_distance(x, z) > limit {
            return false;
        }
        openings.iter().all(|o| {
            let (s, y) = o.local(x, z);
            !(s > limit && s <= depth + dx && y.abs() < o.half_width)
        })
    };
    let mask = sample_rows(opts.parallel, ni, nj, |i, j| {
        let (x, z) = (ox + (i0 + i as i64) as Real * dx, oz + (j0 + j as i64) as Real * dx);
        if is_fluid(x, z) {
            1.0
        } else {
            0.0
        }
    });
    let mut fluid: Vec<[Real; 2]> = Vec::new();
    for j in 0..nj {
        for i in 0..ni {
            if mask[j * ni + i] > 0.0 {
                fluid.push([ox + (i0 + i as i64) as Real * dx, oz + (j0 + j as i64) as Real * dx]);
            }
        }
    }

    // ---- walls: level sets of the extended signed distance on a fine grid
    let h = dx / FINE;
    let pad = (layers as Real + 3.0) * dx;
    const COARSE: usize = 8;
    let cnx = (((hi[0] - lo[0] + 2.0 * pad) / (COARSE as Real * h)).ceil() as usize).max(1) + 1;
    let cnz = (((hi[1] - lo[1] + 2.0 * pad) / (COARSE as Real * h)).ceil() as usize).max(1) + 1;
    let (nx, nz) = ((cnx - 1) * COARSE + 1, (cnz - 1) * COARSE + 1);
    if nx.saturating_mul(nz) > MAX_GRID_NODES {
        return Err(out_of_range(
            "dx",
            dx,
            format!(
                "a spacing whose wall grid (dx/4) has at most {MAX_GRID_NODES} nodes for this geometry ({nx} × {nz})"
            ),
        ));
    }
    let g0 = [lo[0] - pad, lo[1] - pad];
    let ext = |x: Real, z: Real| lumen.signed_distance_with_reservoirs(x, z);
    let coarse = SdfGrid::sample(ext, g0, COARSE as Real * h, cnx, cnz, opts.parallel);
    let top = layers as Real * dx;
    let margin = COARSE as Real * h * std::f64::consts::FRAC_1_SQRT_2 + 1.01 * h;
    // per coarse cell: 0 near a level, 1 far above all levels, -1 far below level 0
    let mut class = vec![0i8; (cnx - 1) * (cnz - 1)];
    for cj in 0..cnz - 1 {
        for ci in 0..cnx - 1 {
            let v = [
                coarse.values[cj * cnx + ci],
                coarse.values[cj * cnx + ci + 1],
                coarse.values[(cj + 1) * cnx + ci],
                coarse.values[(cj + 1) * cnx + ci + 1],
            ];
            class[cj * (cnx - 1) + ci] = if v.iter().all(|&a| a > top + margin) {
                1
            } else if v.iter().all(|&a| a < -margin) {
                -1
            } else {
                0
            };
        }
    }
    let cells = |i: usize, n: usize| {
        let c = i / COARSE;
        let a = if c * COARSE == i && c > 0 { c - 1 } else { c.min(n - 2) };
        (a, c.min(n - 2))
    };
    let fine_values = sample_rows(opts.parallel, nx, nz, |i, j| {
        let (ca, cb) = cells(i, cnx);
        let (ra, rb) = (cells(j, cnz).0, cells(j, cnz).1);
        let mut far = 0i8;
        for cj in [ra, rb] {
            for ci in [ca, cb] {
                let k = class[cj * (cnx - 1) + ci];
                if k == 0 {
                    return ext(g0[0] + i as Real * h, g0[1] + j as Real * h);
                }
                far = k;
            }
        }
        // beyond every level (far above all, or below level 0): only the side matters
        if far > 0 {
            top + 2.0 * margin
        } else {
            -2.0 * margin
        }
    });
    let fine = SdfGrid { origin: g0, spacing: h, nx, nz, values: fine_values };

    let mut walls: Vec<([Real; 2], ParticleKind)> = Vec::new();
    let mut accepted: HashMap<(i64, i64), Vec<[Real; 2]>> = HashMap::new();
    let min_gap = 0.5 * dx;
    let key = |p: [Real; 2]| ((p[0] / min_gap).floor() as i64, (p[1] / min_gap).floor() as i64);
    let mut extended_area = 0.0;
    for k in 0..=layers {
        let level = k as Real * dx;
        let kind = if k == 0 { ParticleKind::WallOn } else { ParticleKind::WallOutside };
        for line in level_set(&fine, level) {
            if k == 0 {
                extended_area += line.signed_area();
            }
            for p in line.resample(dx) {
                let p = project(&ext, p, level, dx);
                let clipped = openings.iter().any(|o| {
                    let (s, y) = o.local(p[0], p[1]);
                    let tol = 1e-6 * dx;
                    // this reservoir's far side and its offsets: points of this reservoir's level
                    // sets (max(|y| − a, s − depth) = level) beyond the far side; walls of other
                    // branches nearby are closer to something else and stay
                    let far_side = s > depth + tol && (y.abs() - o.half_width).max(s - depth) <= level + tol;
                    // … and anything inside the opening's strip (level 0 on the far side)
                    let across = s > 0.0 && s <= depth + tol && y.abs() < o.half_width - 1e-3 * dx;
                    far_side || across
                });
                if clipped {
                    continue;
                }
                let (kx, kz) = key(p);
                let close = (-1..=1).any(|a| {
                    (-1..=1).any(|b| {
                        accepted
                            .get(&(kx + a, kz + b))
                            .is_some_and(|v| v.iter().any(|q| (q[0] - p[0]).hypot(q[1] - p[1]) < min_gap))
                    })
                });
                if close {
                    continue;
                }
                accepted.entry((kx, kz)).or_default().push(p);
                walls.push((p, kind));
            }
        }
    }
    let reservoir_area: Real = openings.iter().map(|o| 2.0 * o.half_width * depth).sum();
    let lumen_area = extended_area - reservoir_area;

    // ---- reservoirs
    let inlet_diameter = openings.iter().find(|o| o.is_inlet()).map_or(0.0, |o| 2.0 * o.half_width);
    let mut next_id = (fluid.len() + walls.len()) as u64;
    let mut boundaries = Vec::with_capacity(openings.len());
    let mut buffers = Particles::default();
    for (index, o) in openings.iter().enumerate() {
        let b = open_boundary(o, inlet_diameter, depth, opts);
        b.validate(opts.support).map_err(|reason| GeometryError::Boundary { field: end_field(o), reason })?;
        let p = b.fill(index as u16, opts.rho0, opts.nu, opts.t0, &mut next_id);
        for i in 0..p.len() {
            if lumen.signed_distance(p.x[i], p.z[i]) <= 0.0 {
                return Err(GeometryError::Shape {
                    field: end_field(o),
                    reason: format!(
                        "the reservoir of opening `{}` (depth {depth} m) overlaps the lumen at ({}, {}) m; allowed: \
                         reservoirs outside every branch",
                        o.name, p.x[i], p.z[i]
                    ),
                });
            }
        }
        buffers.append(&p);
        boundaries.push(b);
    }

    // ---- relaxation of the fluid against the walls and reservoirs
    if opts.relax_iterations > 0 {
        let fixed: Vec<[Real; 2]> =
            walls.iter().map(|(p, _)| *p).chain((0..buffers.len()).map(|i| [buffers.x[i], buffers.z[i]])).collect();
        super::relax::relax(
            &mut fluid,
            &fixed,
            dx,
            opts.support,
            &lumen,
            &openings,
            opts.relax_iterations,
            opts.parallel,
        );
    }

    // ---- assemble
    let mass = opts.rho0 * dx * dx;
    let mut particles = Particles::default();
    let velocities = fluid_velocities(geom, &lumen, &fluid, inlet_diameter, opts);
    for (id, (p, v)) in fluid.iter().zip(&velocities).enumerate() {
        particles.push(p[0], p[1], v[0], v[1], opts.rho0, mass, ParticleKind::Fluid, id as u64);
    }
    for (k, (p, kind)) in walls.iter().enumerate() {
        particles.push(p[0], p[1], 0.0, 0.0, opts.rho0, mass, *kind, (fluid.len() + k) as u64);
    }
    particles.append(&buffers);

    // ---- grid of the lumen's signed distance
    let (mut bl, mut bh) = ([Real::INFINITY; 2], [Real::NEG_INFINITY; 2]);
    for i in 0..particles.len() {
        bl = [bl[0].min(particles.x[i]), bl[1].min(particles.z[i])];
        bh = [bh[0].max(particles.x[i]), bh[1].max(particles.z[i])];
    }
    if particles.is_empty() {
        (bl, bh) = (lo, hi);
    }
    let sp = 0.5 * dx;
    let g_origin = [bl[0] - 2.0 * dx, bl[1] - 2.0 * dx];
    let gnx = ((bh[0] - bl[0] + 4.0 * dx) / sp).ceil() as usize + 1;
    let gnz = ((bh[1] - bl[1] + 4.0 * dx) / sp).ceil() as usize + 1;
    let sdf = SdfGrid::sample(|x, z| lumen.signed_distance(x, z), g_origin, sp, gnx, gnz, opts.parallel);
    let fluid_region =
        SdfGrid::sample(|x, z| lumen.signed_distance_with_reservoirs(x, z), g_origin, sp, gnx, gnz, opts.parallel);

    Ok(VesselScene {
        particles,
        boundaries,
        openings,
        sdf,
        fluid_region,
        lumen,
        lumen_area,
        dx,
        wall_layers: layers,
        reservoir_depth: depth,
    })
}

/// Newton steps onto {f = level} along the numerical gradient; keeps `p` when the step would be
/// large (a kink of f) or the gradient degenerate.
fn project(f: &impl Fn(Real, Real) -> Real, p: [Real; 2], level: Real, dx: Real) -> [Real; 2] {
    let e = 1e-4 * dx;
    let mut q = p;
    for _ in 0..3 {
        let v = f(q[0], q[1]) - level;
        if v.abs() < 1e-12 * dx {
            break;
        }
        let gx = (f(q[0] + e, q[1]) - f(q[0] - e, q[1])) / (2.0 * e);
        let gz = (f(q[0], q[1] + e) - f(q[0], q[1] - e)) / (2.0 * e);
        let g2 = gx * gx + gz * gz;
        if g2 < 0.25 {
            return p;
        }
        q = [q[0] - v * gx / g2, q[1] - v * gz / g2];
    }
    if (q[0] - p[0]).hypot(q[1] - p[1]) > 0.25 * dx {
        p
    } else {
        q
    }
}

/// Velocities of the fluid particles (see [`InitialVelocity`]).
fn fluid_velocities(
    geom: &VesselGeometry,
    lumen: &Lumen,
    fluid: &[[Real; 2]],
    inlet_diameter: Real,
    opts: &BuildOptions,
) -> Vec<[Real; 2]> {
    if opts.initial_velocity == InitialVelocity::Rest || inlet_diameter <= 0.0 {
        return vec![[0.0, 0.0]; fluid.len()];
    }
    let shares = geom.flow_shares();
    let (t, r) = (opts.t0, ramp(opts.t0, opts.ramp_time));
    let mean = opts.inflow.value(t);
    fluid
        .iter()
        .map(|p| {
            let Some(hit) = lumen.nearest_segment(p[0], p[1]) else {
                return [0.0, 0.0];
            };
            let share = shares.get(hit.branch).copied().unwrap_or(0.0);
            if share == 0.0 {
                return [0.0, 0.0];
            }
            let a = hit.radius;
            let scale = share * inlet_diameter / (2.0 * a);
            let y = hit.lateral.min(a);
            let u = match opts.profile {
                ProfileKind::Womersley => profile_velocity(&opts.inflow, y, t, a, opts.nu) * scale,
                ProfileKind::Parabolic => 1.5 * mean * scale * (1.0 - (y / a) * (y / a)),
                ProfileKind::Uniform => mean * scale,
            } * r;
            [u * hit.tangent[0], u * hit.tangent[1]]
        })
        .collect()
}
