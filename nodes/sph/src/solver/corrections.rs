//! Corrections of the particle distribution between steps: particle shifting, the
//! anti-penetration guard and the reordering of the particle arrays by cell.

use super::*;

impl Solver {
    /// Particle shifting (see [`SphParams::shifting`]), with ∇C and ∇u of the half-step evaluation;
    /// parallel to the opening within one kernel support of an opening.
    pub(super) fn shift(&mut self, dt: Real) {
        let a = self.params.shifting;
        if a <= 0.0 {
            return;
        }
        let h = self.kernel.h;
        let cap = 0.1 * h;
        let p = &mut self.particles;
        let par = self.params.parallel;
        // largest speed (order-free), then the shifts chunk by chunk, the chunks' sums added in order
        let umax2 = chunks::map_ranges(par, p.len(), |r| {
            r.filter(|&i| !p.kind[i].is_wall()).fold(0.0 as Real, |m, i| m.max(p.vx[i] * p.vx[i] + p.vz[i] * p.vz[i]))
        })
        .into_iter()
        .fold(0.0 as Real, Real::max);
        let d = a * h * umax2.sqrt() * dt;
        let support = self.kernel.support_radius();
        let (kind, rates, boundaries) = (&p.kind, &self.ws.rates, &self.boundaries);
        let parts = chunks::state_chunks(&mut p.x, &mut p.z, &mut p.vx, &mut p.vz, &mut p.rho);
        let sums = chunks::map_chunks(par, parts, |c| {
            let (mut ss, mut sa) = (0.0, 0.0);
            for j in 0..c.x.len() {
                let i = c.start + j;
                if !kind[i].is_fluid() {
                    continue;
                }
                let r = &rates[i];
                let (mut sx, mut sz) = (-d * r.grad_c[0], -d * r.grad_c[1]);
                // within one support of an opening only parallel to it: the reservoir particles sit
                // on lanes and move with the imposed profile, and shifting across the opening would
                // move fluid out faster than the flow does (measured: −0.3 % of the particles in 0.1 s)
                for b in boundaries {
                    if !b.spec.near(c.x[j], c.z[j], support) {
                        continue;
                    }
                    let (s, y) = b.spec.local(c.x[j], c.z[j]);
                    if s > -support && y.abs() <= b.spec.half_width + support {
                        let n = b.spec.normal;
                        let dn = sx * n[0] + sz * n[1];
                        sx -= dn * n[0];
                        sz -= dn * n[1];
                    }
                }
                let len = (sx * sx + sz * sz).sqrt();
                if len > cap {
                    sx *= cap / len;
                    sz *= cap / len;
                }
                c.x[j] += sx;
                c.z[j] += sz;
                ss += sx * sx + sz * sz;
                sa += (c.vx[j] * c.vx[j] + c.vz[j] * c.vz[j]) * dt * dt;
                let g = r.grad_u;
                c.vx[j] += sx * g[0] + sz * g[1];
                c.vz[j] += sx * g[2] + sz * g[3];
            }
            (ss, sa)
        });
        let (ss, sa) = sums.into_iter().fold((0.0, 0.0), |(a0, a1), (b0, b1)| (a0 + b0, a1 + b1));
        self.shift_sums.0 += ss;
        self.shift_sums.1 += sa;
    }

    /// Stores the particles in cell order (row-major cells, stable; with the fast evaluator its own
    /// cells of support / reach, so that its sorted copies and the rates scattered back run through
    /// memory nearly in order; else cells of one kernel support), so that neighbours are close in
    /// memory: the flow scrambles the initial order within a few thousand steps, and the cell-sorted
    /// copies of the fast evaluator and the guard then gather from all over memory. Ids are
    /// unchanged. The new order changes the order of the neighbour sums, hence the results at the
    /// rounding level — deterministically (every 25th step, whatever the threads).
    pub(super) fn reorder_by_cell(&mut self) {
        let r = self.kernel.support_radius();
        let cell = if self.params.fast_rhs { r / self.fast.reach() as Real } else { r };
        self.cells.build(&self.particles.x, &self.particles.z, cell, self.params.periodic_x, self.params.periodic_z);
        let order = self.cells.sorted_indices();
        self.particles.permute(order);
        if self.carried && self.rates0.len() == order.len() {
            let permuted: Vec<Rate> = order.iter().map(|&i| self.rates0[i as usize]).collect();
            self.rates0 = permuted;
        }
    }

    /// Anti-penetration guard (see [`Solver::with_domain`]).
    pub(super) fn guard(&mut self, _t: Real) {
        let Some(domain) = self.domain.clone() else { return };
        if !self.motions.is_empty() {
            return;
        }
        let dx = self.kernel.h; // pushed back by ~h/2 ≈ half a particle spacing
        let e = 0.05 * dx;
        let p = &mut self.particles;
        for i in 0..p.len() {
            if !p.kind[i].is_fluid() {
                continue;
            }
            let d = domain.signed_distance(p.x[i], p.z[i]);
            if d <= 0.0 {
                continue;
            }
            let gx = domain.signed_distance(p.x[i] + e, p.z[i]) - domain.signed_distance(p.x[i] - e, p.z[i]);
            let gz = domain.signed_distance(p.x[i], p.z[i] + e) - domain.signed_distance(p.x[i], p.z[i] - e);
            let gn = (gx * gx + gz * gz).sqrt();
            if gn > 0.0 && gn.is_finite() {
                let (nx, nz) = (gx / gn, gz / gn);
                let back = d + 0.5 * dx;
                p.x[i] -= back * nx;
                p.z[i] -= back * nz;
                let vn = p.vx[i] * nx + p.vz[i] * nz;
                if vn > 0.0 {
                    p.vx[i] -= vn * nx;
                    p.vz[i] -= vn * nz;
                }
            }
            self.guard_corrections += 1;
        }
    }
}
