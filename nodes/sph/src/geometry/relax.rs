//! Relaxation of the initial particle set (pre-processing, no physics): the fluid lattice is cut
//! by curved walls, so its first row lies 0.5–1.5 dx from the wall particles and the kernel sums
//! there range from 0.84 to 1.26. A few hundred iterations of a purely geometric particle shift
//! δr = −β h² ∇C, ∇C = Σ_b V_b (1 + 0.2 (W_ab/W(dx))⁴) ∇W_ab over all particles (fluid, walls, reservoirs; only fluid
//! particles move), even out the particle concentration (the idea of the particle relaxation of
//! body-fitted SPH pre-processors, e.g. Zhu, Zhang & Hu 2021). Fluid particles are kept inside the
//! lumen (at least dx/4 from the wall) and out of the reservoirs.

use crate::kernel::{Kernel, KernelKind};
use crate::neighbours::CellList;
use crate::Real;

use super::shape::Lumen;
use super::Opening;

/// Moves `fluid` (positions) to even out Σ V W with the fixed particles `fixed`; `iterations`
/// steps of δr = −β h² ∇C (β = 0.1, |δr| ≤ 0.05 dx per iteration). Returns the largest and the
/// RMS total displacement in units of dx.
#[allow(clippy::too_many_arguments)]
pub(crate) fn relax(
    fluid: &mut [[Real; 2]],
    fixed: &[[Real; 2]],
    dx: Real,
    support: Real,
    lumen: &Lumen,
    openings: &[Opening],
    iterations: usize,
    parallel: bool,
) -> (Real, Real) {
    if iterations == 0 || fluid.is_empty() {
        return (0.0, 0.0);
    }
    let kind = KernelKind::QuarticSpline;
    let h = support / kind.support_factor();
    let kernel = Kernel::new(kind, h);
    let vol = dx * dx;
    let w_dx = kernel.w(dx);
    let start: Vec<[Real; 2]> = fluid.to_vec();
    let nf = fluid.len();
    let mut x: Vec<Real> = fluid.iter().chain(fixed).map(|p| p[0]).collect();
    let mut z: Vec<Real> = fluid.iter().chain(fixed).map(|p| p[1]).collect();
    let mut cells = CellList::default();
    let (beta, cap) = (0.1, 0.05 * dx);
    let mut grad = vec![[0.0; 2]; nf];
    for _ in 0..iterations {
        cells.build(&x, &z, kernel.support_radius(), None, None);
        let gradient = |a: usize| {
            let (mut gx, mut gz) = (0.0, 0.0);
            cells.for_each_neighbour(x[a], z[a], &x, &z, |b, ddx, ddz, r2| {
                if b == a {
                    return;
                }
                let r = r2.sqrt();
                let (w, dw) = kernel.w_dw(r);
                // Lind et al. (2012) anti-clumping weight 1 + 0.2 (W/W(dx))⁴
                let q = w / w_dx;
                let f = vol * (1.0 + 0.2 * q * q * q * q) * dw / r;
                gx += f * ddx;
                gz += f * ddz;
            });
            [gx, gz]
        };
        #[cfg(feature = "parallel")]
        if parallel {
            use rayon::prelude::*;
            grad.par_iter_mut().enumerate().for_each(|(a, g)| *g = gradient(a));
        } else {
            grad.iter_mut().enumerate().for_each(|(a, g)| *g = gradient(a));
        }
        #[cfg(not(feature = "parallel"))]
        {
            let _ = parallel;
            grad.iter_mut().enumerate().for_each(|(a, g)| *g = gradient(a));
        }
        for (a, g) in grad.iter().enumerate() {
            let (mut sx, mut sz) = (-beta * h * h * g[0], -beta * h * h * g[1]);
            let len = (sx * sx + sz * sz).sqrt();
            if len > cap {
                sx *= cap / len;
                sz *= cap / len;
            }
            let (nx, nz) = (x[a] + sx, z[a] + sz);
            let inside = lumen.signed_distance(nx, nz) <= -0.25 * dx;
            let clear = openings.iter().all(|o| {
                let (s, y) = o.local(nx, nz);
                !(s > -0.5 * dx && y.abs() < o.half_width + dx)
            });
            if inside && clear {
                x[a] = nx;
                z[a] = nz;
            }
        }
    }
    let (mut worst, mut sum) = (0.0 as Real, 0.0);
    for (a, p) in fluid.iter_mut().enumerate() {
        let d = (x[a] - start[a][0]).hypot(z[a] - start[a][1]) / dx;
        worst = worst.max(d);
        sum += d * d;
        *p = [x[a], z[a]];
    }
    (worst, (sum / nf as Real).sqrt())
}
