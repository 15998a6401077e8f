//! Surfaces in the (β, θ) parametrisation and their panels (module doc of [`super`]).

use std::f64::consts::PI;

/// A closed surface x = a sinβ cosθ, z = c sinβ sinθ, y = h cosβ √(α + (1 − α) sin²β), β ∈ [0, π],
/// θ ∈ [0, 2π), with α = α_top for β ≤ π/2 and α_bot below. With R = sin β this is the platelet of
/// [`crate::shape`] (half-thickness (Ly/2) √((1 − R²)(α + (1 − α)R²))); a = c = h, α = 1 is a sphere.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Surface {
    pub a: f64,
    pub h: f64,
    pub c: f64,
    pub alpha_top: f64,
    pub alpha_bot: f64,
}

impl Surface {
    fn alpha(&self, beta: f64) -> f64 {
        if beta <= 0.5 * PI {
            self.alpha_top
        } else {
            self.alpha_bot
        }
    }

    /// The point at (β, θ).
    pub fn point(&self, beta: f64, theta: f64) -> [f64; 3] {
        let (s, co) = beta.sin_cos();
        let (st, ct) = theta.sin_cos();
        let al = self.alpha(beta);
        let g = al + (1.0 - al) * s * s;
        [self.a * s * ct, self.h * co * g.sqrt(), self.c * s * st]
    }

    /// The outward normal at (β, θ) (unit; at the poles ±e_y).
    pub fn normal(&self, beta: f64, theta: f64) -> [f64; 3] {
        let (s, co) = beta.sin_cos();
        let (st, ct) = theta.sin_cos();
        let al = self.alpha(beta);
        let g = al + (1.0 - al) * s * s;
        // ∂/∂β and ∂/∂θ divided by sin β (removes the pole degeneracy)
        let dyb = self.h * (-g + (1.0 - al) * co * co) / g.sqrt();
        let tb = [self.a * co * ct, s * dyb, self.c * co * st];
        let tt = [-self.a * st, 0.0, self.c * ct];
        // tb × tt points inward for this orientation
        let n = [-(tb[1] * tt[2] - tb[2] * tt[1]), -(tb[2] * tt[0] - tb[0] * tt[2]), -(tb[0] * tt[1] - tb[1] * tt[0])];
        let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        [n[0] / l, n[1] / l, n[2] / l]
    }
}

/// One panel: the parameter rectangle [β0, β1] × [θ0, θ1] of a surface.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Panel {
    pub surface: usize,
    pub b0: f64,
    pub b1: f64,
    pub t0: f64,
    pub t1: f64,
    /// Collocation point: the image of the parameter centre.
    pub centre: [f64; 3],
    /// Twice the largest distance from the centre to a corner or edge midpoint (a diameter).
    pub size: f64,
    /// ∫ sinβ dβ dθ over the panel (the traction density's weight, module doc of [`super`]).
    pub m0: f64,
}

/// The panels of a surface: `n_beta` uniform in β ∈ [0, π] (an edge on the rim β = π/2 when even),
/// `n_theta` uniform in θ starting at θ = 0 (mirror symmetric in x → −x and z → −z when even).
pub(crate) fn mesh(surfaces: &[Surface], index: usize, n_beta: usize, n_theta: usize) -> Vec<Panel> {
    let s = surfaces[index];
    let mut out = Vec::with_capacity(n_beta * n_theta);
    let db = PI / n_beta as f64;
    let dt = 2.0 * PI / n_theta as f64;
    for i in 0..n_beta {
        // β edges symmetric about π/2 to round-off: measured from the nearer pole
        let b0 = edge(i, n_beta, db);
        let b1 = edge(i + 1, n_beta, db);
        for j in 0..n_theta {
            let t0 = j as f64 * dt;
            let t1 = (j + 1) as f64 * dt;
            let (bm, tm) = (0.5 * (b0 + b1), 0.5 * (t0 + t1));
            let centre = s.point(bm, tm);
            let mut size: f64 = 0.0;
            for (bb, tt) in [(b0, t0), (b0, t1), (b1, t0), (b1, t1), (b0, tm), (b1, tm), (bm, t0), (bm, t1)] {
                size = size.max(dist(&centre, &s.point(bb, tt)));
            }
            let m0 = (b0.cos() - b1.cos()) * (t1 - t0);
            out.push(Panel { surface: index, b0, b1, t0, t1, centre, size: 2.0 * size, m0 });
        }
    }
    out
}

fn edge(i: usize, n: usize, d: f64) -> f64 {
    if 2 * i <= n {
        i as f64 * d
    } else {
        PI - (n - i) as f64 * d
    }
}

pub(crate) fn dist(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}
