//! Resolved 3-D Stokes flow past a fixed rigid platelet ([`crate::shape`]): the resistance that
//! paper 2 (section 4.3, Algorithm 1, eq 13–17) computes with finite elements, here with a
//! boundary-element method.
//!
//! **Method: first-kind single-layer boundary integrals** (Pozrikidis 1992, *Boundary integral and
//! singularity methods for linearized viscous flow*, ch. 4; Youngren & Acrivos 1975). For a rigid
//! body the double layer drops out and the disturbance of the imposed flow u∞ is
//! w(x) = (1/8πμ) ∫ G(x, y) f(y) dS(y), G = I/r + r r/r³, with f the traction on the body; the
//! no-slip condition w = −u∞ on the body is a first-kind equation for f. A resolved finite-element
//! run meshes a 50 µm ball around a 3 µm body; the integral equation only meshes surfaces, so a
//! dense solve with ~10³ unknowns per surface is cheap, and one LU serves all right-hand sides.
//! Force and torque are integrals of f (eq 16) and come out as exact sums over panels.
//!
//! **Discretisation.** Each surface is parametrised by (β, θ): R = sin β over the disc, the top
//! sheet β < π/2 and the bottom one β > π/2 at the heights of [`crate::shape::Shape::half_thickness`]
//! (module `mesh`); uniform panels in β cluster toward the rim (1 − R ≈ (π/2 − β)²/2), where the
//! surface is vertical, and an edge lies on the rim. `n_theta = 2 n_beta` panels in θ start at
//! θ = 0, so the mesh is mirror symmetric in x → −x and z → −z to round-off: the lift of a
//! symmetric shape at ψ = 0, π/2 and the pitching torque of α_top = α_bot then vanish to
//! round-off. The unknown is piecewise constant, but as a density per parameter area:
//! f dS = σ_j sinβ dβ dθ on panel j, i.e. f = σ_j sinβ/|∂_β y × ∂_θ y|. For any ellipsoid this
//! weight is exactly the profile (x²/a⁴ + y²/b⁴ + z²/c⁴)^−½ of its traction in translation
//! (Lamb 1932, §339), which carries the inverse-square-root growth toward a thin rim; plain
//! piecewise-constant traction would have to resolve that growth over the ~Ly²/Lx rim radius. On
//! the sphere the weight is constant. The integral equation is collocated at the panels' parameter
//! centres.
//!
//! **Quadrature** (module `quadrature`): Gauss rules of 2, 3 or 6 points per direction by the
//! ratio of distance to panel diameter (≥ 4, 2, 1), recursive bisection of the physically
//! longer side below that. That resolves the near-singular integrals between the top and bottom
//! faces of thin platelets (0.07 µm apart against 0.2 µm panels at Ly = 0.15 µm, α = 0.2) and the
//! very elongated rim panels. A panel's own collocation point is handled by cutting the panel
//! into near-square cells, with a Duffy transform on the four around the point.
//!
//! **Null space.** ∫ G·n dS = 0 on a closed surface, so f is fixed only up to a multiple of the
//! normal n (which carries no force or torque). Each surface's block gets the rank-one term
//! n(x) ∫ f·n dS/(4π L) (Power & Miranda 1987 style deflation), which selects ∫ f·n = 0 and
//! keeps the LU well conditioned.
//!
//! **Outer boundary.** The paper's ball |x| = 50 µm carries Dirichlet data: uniform flow or rigid
//! rotation (also linear strain here). Write u = u∞ + w with u∞ that data extended inside; u∞ is a
//! Stokes flow, so w vanishes on the ball and equals −u∞ on the body. w has a single-layer
//! representation over both surfaces (the ball's double layer vanishes with w = 0 there, the body's
//! is a single layer of ∫ f·n-free density for rigid and linear u∞). The ball is meshed as a
//! second surface (its density is smooth: 12 × 24 panels) and the coupled system is solved. The
//! force and torque on the body are those of its density σ: u∞'s own stress (2μE for strain, 0 for
//! uniform flow and rotation) integrates to zero force and torque over a closed surface.
//! Confinement raises the drag by ≈ 9/4 · a/R (7 % for the mean platelet); it is validated
//! against the exact sphere-in-sphere results (`tests/stokes.rs`). [`Outer::FreeSpace`] drops the
//! ball.
//!
//! **Linear algebra:** `faer`'s blocked LU with partial pivoting (dense, f64, serial): the matrix
//! is non-symmetric and dense (3N × 3N, N ≈ 10³ panels), the factorisation dominates, and faer's
//! cache-blocked SIMD kernels are several times faster than an unblocked LU (nalgebra's)
//! at this size.
//!
//! **Outputs** ([`ShapeResistance`]): one factorisation, four right-hand sides (uniform x, uniform y,
//! rotation about z through the centre of mass, strain (y − y_c, x, 0)·ε about it); everything else
//! is a linear combination: the paper's D(ψ), L(ψ), T(ψ), T_r and the coefficients of
//! [`crate::coefficients`].

pub(crate) mod mesh;
pub(crate) mod quadrature;

use crate::coefficients::{CoefficientModel, Rotational, Translational};
use crate::shape::{Shape, ShapeError};
use faer::linalg::solvers::Solve;
use faer::Mat;
use mesh::Surface;
use nalgebra::{Matrix2, Vector2};
use quadrature::{far_rule, panel_integral, tensor_points, FarRule, Rules, Sym};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// The paper's viscosity, 3 µg/(µm·s) = 3 mPa·s.
pub const PAPER_VISCOSITY: f64 = 3e-3;
/// The paper's outer ball radius, 50 µm.
pub const PAPER_BALL_RADIUS: f64 = 50e-6;

/// What bounds the fluid.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub enum Outer {
    /// Unbounded fluid, the imposed flow at infinity.
    FreeSpace,
    /// The imposed flow as Dirichlet data on a ball centred at the origin (paper 2, eq 14).
    Ball {
        /// Radius \[m\] (paper: 50 µm).
        radius: f64,
        /// Panels along the ball's meridian (and twice as many around); its flow is smooth.
        n_beta: usize,
    },
}

/// Options of [`solve_shape`]. `Default` is the paper's configuration (ball of 50 µm, μ = 3 mPa·s)
/// at the default resolution (README: ≲ 1 % error, well under 1 s per shape).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StokesOptions {
    /// Panels along the body's meridian β ∈ [0, π] (even, 4..=64); 2·`n_beta` around it.
    /// Default 16 (512 panels).
    pub n_beta: usize,
    /// Outer boundary. Default: ball of 50 µm with 12 panels along its meridian.
    pub outer: Outer,
    /// Dynamic viscosity \[Pa·s\]. Default 3e-3 (the paper's 3 µg/(µm·s)).
    pub viscosity: f64,
}

impl Default for StokesOptions {
    fn default() -> Self {
        StokesOptions {
            n_beta: 16,
            outer: Outer::Ball { radius: PAPER_BALL_RADIUS, n_beta: 12 },
            viscosity: PAPER_VISCOSITY,
        }
    }
}

/// Errors of [`solve_shape`].
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum StokesError {
    /// An option outside its allowed range.
    #[error("stokes options: `{field}` = {value} is invalid: allowed {allowed}")]
    InvalidOption { field: &'static str, value: f64, allowed: &'static str },
    /// The shape is not a body.
    #[error(transparent)]
    Shape(#[from] ShapeError),
    /// The ball does not contain the body with room to spare.
    #[error("stokes options: `outer.radius` = {radius} m must exceed twice the body's largest extent {extent} m")]
    BallTooSmall { radius: f64, extent: f64 },
    /// The linear solve gave non-finite values.
    #[error("stokes solve: non-finite solution (degenerate discretisation)")]
    NonFinite,
}

impl StokesOptions {
    /// Checks the ranges (the error names the field and the allowed range).
    pub fn validate(&self) -> Result<(), StokesError> {
        let even = |n: usize, lo: usize, hi: usize| n & 1 == 0 && (lo..=hi).contains(&n);
        if !even(self.n_beta, 4, 64) {
            return Err(StokesError::InvalidOption {
                field: "n_beta",
                value: self.n_beta as f64,
                allowed: "even, 4 <= n_beta <= 64",
            });
        }
        if !(self.viscosity.is_finite() && self.viscosity > 0.0) {
            return Err(StokesError::InvalidOption {
                field: "viscosity",
                value: self.viscosity,
                allowed: "finite and > 0 Pa s",
            });
        }
        if let Outer::Ball { radius, n_beta } = self.outer {
            if !(radius.is_finite() && radius > 0.0 && radius <= 1.0) {
                return Err(StokesError::InvalidOption {
                    field: "outer.radius",
                    value: radius,
                    allowed: "finite, 0 < radius <= 1 m",
                });
            }
            if !even(n_beta, 4, 32) {
                return Err(StokesError::InvalidOption {
                    field: "outer.n_beta",
                    value: n_beta as f64,
                    allowed: "even, 4 <= n_beta <= 32",
                });
            }
        }
        Ok(())
    }
}

/// The in-plane resistance of one shape fixed at φ = 0 (SI; torques about the centre of mass
/// (0, `centre_of_mass_y`, 0), positive counter-clockwise about +z). "Per unit flow" means per
/// unit imposed velocity (1 m/s), angular velocity (1 rad/s) or strain rate (1/s).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShapeResistance {
    /// `force_per_flow[a][b]`: force along a ∈ {x, y} per unit uniform flow along b \[kg/s\].
    pub force_per_flow: [[f64; 2]; 2],
    /// Torque per unit uniform flow along x and y \[kg·m/s\].
    pub torque_per_flow: [f64; 2],
    /// Force per unit rigid rotation of the fluid about the centre of mass \[kg·m/s\].
    pub force_per_rotation: [f64; 2],
    /// Torque per unit rigid rotation about the centre of mass, c_r \[N·m·s\].
    pub rotation_torque: f64,
    /// Force per unit strain (y − y_c, x, 0)·ε \[kg·m/s\].
    pub force_per_strain: [f64; 2],
    /// Torque per unit strain rate E_xy, c_s \[N·m·s\].
    pub strain_torque: f64,
    /// Height of the centre of mass \[m\].
    pub centre_of_mass_y: f64,
    /// Viscosity the solve used \[Pa·s\].
    pub viscosity: f64,
    /// Panels on the body and on the outer ball.
    pub panels: (usize, usize),
}

/// Paper unit of force per 1 µm/s: µm·µg/s² = 1e-15 N.
const PAPER_FORCE: f64 = 1e-15;
/// Paper unit of torque: µm²·µg/s² = 1e-21 N·m.
const PAPER_TORQUE: f64 = 1e-21;

impl ShapeResistance {
    /// Drag, lift and pitching coefficients for a flow at angle ψ to the body's x axis
    /// ([`crate::coefficients`]): c_d = d·K·d, c_l = d^⊥·K·d, c_p = t·d with d = (cos ψ, sin ψ).
    pub fn translational(&self, psi: f64) -> Translational {
        let (s, c) = psi.sin_cos();
        let d = Vector2::new(c, s);
        let [[k00, k01], [k10, k11]] = self.force_per_flow;
        let f = Matrix2::new(k00, k01, k10, k11) * d;
        // d^⊥ · f = d × f (the z component)
        Translational { c_d: d.dot(&f), c_l: d.perp(&f), c_p: Vector2::from(self.torque_per_flow).dot(&d) }
    }

    /// c_r and c_s ([`crate::coefficients`]).
    pub fn rotational(&self) -> Rotational {
        Rotational { c_r: self.rotation_torque, c_s: self.strain_torque }
    }

    /// Paper's D(ψ) for |v| = 1 µm/s, in µm·µg/s² (Algorithm 1; the paper's μ if the options had it).
    pub fn paper_drag(&self, psi: f64) -> f64 {
        self.translational(psi).c_d * 1e-6 / PAPER_FORCE
    }

    /// Paper's L(ψ) in µm·µg/s².
    pub fn paper_lift(&self, psi: f64) -> f64 {
        self.translational(psi).c_l * 1e-6 / PAPER_FORCE
    }

    /// Paper's T(ψ) (pitching torque about the centre of mass) in µm²·µg/s².
    pub fn paper_torque(&self, psi: f64) -> f64 {
        self.translational(psi).c_p * 1e-6 / PAPER_TORQUE
    }

    /// Paper's T_r: torque about the centre of mass for the rotation 2π(−y, x, 0) about the
    /// origin (eq 14), in µm²·µg/s². That flow is the rotation about the centre of mass plus the
    /// uniform flow (−2π y_c, 0, 0).
    pub fn paper_rotational_torque(&self) -> f64 {
        2.0 * PI * (self.rotation_torque - self.centre_of_mass_y * self.torque_per_flow[0]) / PAPER_TORQUE
    }
}

/// Solves the four problems of one shape with one factorisation (module doc).
pub fn solve_shape(shape: &Shape, options: &StokesOptions) -> Result<ShapeResistance, StokesError> {
    shape.validate()?;
    options.validate()?;
    // work in µm with μ = 1; scaled back at the end
    let um = 1e6;
    let body = Surface {
        a: 0.5 * shape.lx * um,
        h: 0.5 * shape.ly * um,
        c: 0.5 * shape.lz * um,
        alpha_top: shape.alpha_top,
        alpha_bot: shape.alpha_bot,
    };
    let extent =
        0.5 * shape.lx.max(shape.lz).max(2.0 * shape.max_half_thickness(true).max(shape.max_half_thickness(false)));
    let mut surfaces = vec![body];
    let mut panels = mesh::mesh(&surfaces, 0, options.n_beta, 2 * options.n_beta);
    let n_body = panels.len();
    if let Outer::Ball { radius, n_beta } = options.outer {
        if radius <= 2.0 * extent {
            return Err(StokesError::BallTooSmall { radius, extent });
        }
        let r = radius * um;
        surfaces.push(Surface { a: r, h: r, c: r, alpha_top: 1.0, alpha_bot: 1.0 });
        panels.extend(mesh::mesh(&surfaces, 1, n_beta, 2 * n_beta));
    }
    let n = panels.len();
    let rules = Rules::new();
    let far: Vec<FarRule> = panels.iter().map(|p| far_rule(&surfaces[p.surface], &rules, p)).collect();

    // moments of each panel: ∫ y sinβ, ∫ n sinβ (4-point rule; smooth integrands)
    let mut m1 = vec![[0.0; 3]; n];
    let mut nm = vec![[0.0; 3]; n];
    for (k, p) in panels.iter().enumerate() {
        let s = &surfaces[p.surface];
        for (y, w, b, t) in tensor_points(s, &rules, 4, (p.b0, p.b1, p.t0, p.t1)) {
            let nn = s.normal(b, t);
            for d in 0..3 {
                m1[k][d] += w * y[d];
                nm[k][d] += w * nn[d];
            }
        }
    }
    let normals: Vec<[f64; 3]> =
        panels.iter().map(|p| surfaces[p.surface].normal(0.5 * (p.b0 + p.b1), 0.5 * (p.t0 + p.t1))).collect();
    let length: Vec<f64> = surfaces.iter().map(|s| s.a.max(s.c).max(s.h)).collect();

    let dim = 3 * n;
    let mut a = Mat::<f64>::zeros(dim, dim);
    let inv8pi = 1.0 / (8.0 * PI);
    for (j, pj) in panels.iter().enumerate() {
        let s = &surfaces[pj.surface];
        for (i, pi) in panels.iter().enumerate() {
            let mut acc: Sym = [0.0; 6];
            panel_integral(s, &rules, pj, &far[j], &pi.centre, i == j, &mut acc);
            let g = [[acc[0], acc[1], acc[2]], [acc[1], acc[3], acc[4]], [acc[2], acc[4], acc[5]]];
            let defl = if pi.surface == pj.surface { 1.0 / (4.0 * PI * length[pj.surface]) } else { 0.0 };
            for (r, grow) in g.iter().enumerate() {
                for (c, gv) in grow.iter().enumerate() {
                    a[(3 * i + r, 3 * j + c)] = inv8pi * gv + defl * normals[i][r] * nm[j][c];
                }
            }
        }
    }

    let yc = shape.centre_of_mass_y() * um;
    let mut rhs = Mat::<f64>::zeros(dim, 4);
    for (i, p) in panels.iter().take(n_body).enumerate() {
        let [x, y, _] = p.centre;
        let u = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-(y - yc), x, 0.0], [y - yc, x, 0.0]];
        for (k, uk) in u.iter().enumerate() {
            for d in 0..3 {
                rhs[(3 * i + d, k)] = uk[d];
            }
        }
    }
    let lu = a.partial_piv_lu();
    lu.solve_in_place(&mut rhs);

    // force and torque (about the centre of mass) on the body for each right-hand side
    let mut force = [[0.0; 3]; 4];
    let mut torque = [0.0; 4];
    for (j, p) in panels.iter().take(n_body).enumerate() {
        for k in 0..4 {
            let sg = [rhs[(3 * j, k)], rhs[(3 * j + 1, k)], rhs[(3 * j + 2, k)]];
            for d in 0..3 {
                force[k][d] += p.m0 * sg[d];
            }
            // z component of ∫ (y − c) × f
            torque[k] += m1[j][0] * sg[1] - (m1[j][1] - yc * p.m0) * sg[0];
        }
    }
    if force.iter().flatten().chain(torque.iter()).any(|v| !v.is_finite()) {
        return Err(StokesError::NonFinite);
    }
    let mu = options.viscosity;
    let (l1, l2, l3) = (mu * 1e-6, mu * 1e-12, mu * 1e-18);
    Ok(ShapeResistance {
        force_per_flow: [[l1 * force[0][0], l1 * force[1][0]], [l1 * force[0][1], l1 * force[1][1]]],
        torque_per_flow: [l2 * torque[0], l2 * torque[1]],
        force_per_rotation: [l2 * force[2][0], l2 * force[2][1]],
        rotation_torque: l3 * torque[2],
        force_per_strain: [l2 * force[3][0], l2 * force[3][1]],
        strain_torque: l3 * torque[3],
        centre_of_mass_y: shape.centre_of_mass_y(),
        viscosity: mu,
        panels: (n_body, n - n_body),
    })
}

/// The solver as a [`CoefficientModel`] (one full solve per shape and call: slow, for tests and
/// references). A shape that fails to solve gets NaN coefficients.
#[derive(Clone, Copy, Debug, Default)]
pub struct StokesModel {
    /// Options of every solve.
    pub options: StokesOptions,
}

impl CoefficientModel for StokesModel {
    fn translational(&self, shapes: &[Shape], psi: &[f64], out: &mut [Translational]) {
        for ((s, &p), o) in shapes.iter().zip(psi).zip(out.iter_mut()) {
            *o = match solve_shape(s, &self.options) {
                Ok(r) => r.translational(p),
                Err(_) => Translational { c_d: f64::NAN, c_l: f64::NAN, c_p: f64::NAN },
            };
        }
    }

    fn rotational(&self, shapes: &[Shape], out: &mut [Rotational]) {
        for (s, o) in shapes.iter().zip(out.iter_mut()) {
            *o = match solve_shape(s, &self.options) {
                Ok(r) => r.rotational(),
                Err(_) => Rotational { c_r: f64::NAN, c_s: f64::NAN },
            };
        }
    }

    fn name(&self) -> &str {
        "stokes"
    }
}
