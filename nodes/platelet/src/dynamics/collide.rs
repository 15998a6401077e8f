//! Collisions (paper 2, Remark 1) and walls.
//!
//! **Reading of Remark 1.** "We treat particles as spheres with radius L_x": taken literally, the
//! collision sphere of a particle has radius f · Lx with f = 1 by default
//! (`radius_factor` of [`super::Particles::new`]; Lx is the full in-plane axis, so f = 1/2 would be the
//! sphere circumscribing the body's in-plane section). Spheres are centred at the centre of mass.
//! The model of the paper's reference \[21\] is not given; this module uses:
//!
//! - **Detection** on a regular lattice of square cells (section 5.2.1): a particle is only tested
//!   against particles of its own and of the adjacent cells. The cell size is at least the
//!   largest interaction distance 2 r_max (so no overlapping pair is missed) and at least the
//!   largest displacement per step (the paper's k V ≤ L_h); it is enlarged when the bounding box
//!   would need more than 4 N + 64 cells. Cells are filled by a counting sort into caller-owned
//!   buffers ([`CellGrid`]): no allocation once the buffers have grown.
//! - **Resolution** pair by pair in order: an impulse along the line of centres n with
//!   restitution e (1 = elastic) when the pair approaches, J = −(1 + e) (V_j − V_i)·n / (1/m_i +
//!   1/m_j), and a positional correction that moves both centres apart along n until they touch,
//!   split inversely to the masses so the centre of mass stays. Both conserve momentum exactly.
//!   Coincident centres use n = e_x.
//! - **Walls** y = lo, y = hi ([`super::flow::CarrierFlow::walls`]): a centre that left the channel
//!   is reflected back (y → 2 lo − y), and the normal velocity is reversed; if it is still
//!   outside (a jump longer than the channel) it is clamped onto the wall.
//! - **Sloped walls** y_lo(x), y_hi(x) ([`super::flow::CarrierFlow::local_walls`], the stenosis):
//!   [`walls_local`] mirrors a centre that crossed a wall about the wall's tangent line at its
//!   abscissa, p → p − 2 ((p − w)·n) n, reflects the velocity V → V − 2 (V·n) n with n the unit
//!   normal (−s, 1)/√(1 + s²) of slope s, and clamps y into the walls at the new abscissa. For
//!   slope 0 this is exactly [`walls`].

/// Buffers for the cell lattice (reused between steps).
#[derive(Clone, Debug, Default)]
pub struct CellGrid {
    cell_of: Vec<u32>,
    start: Vec<u32>,
    sorted: Vec<u32>,
    xs: Vec<f64>,
    ys: Vec<f64>,
    rs: Vec<f64>,
    /// Overlapping pairs (i < j) found by the last [`CellGrid::find_pairs`].
    pub pairs: Vec<(u32, u32)>,
    /// Cell size of the last search \[m\].
    pub cell_size: f64,
    /// Cells of the last search (nx, ny).
    pub dims: (usize, usize),
    /// Target mean particles per cell when the interaction distance allows larger cells
    /// (default 0: the smallest admissible cells).
    pub occupancy: f64,
}

impl CellGrid {
    /// All pairs i < j with |X_i − X_j| < r_i + r_j, into `self.pairs` (in cell order).
    /// `min_cell` is a lower bound of the cell size \[m\] (e.g. the largest displacement per step).
    pub fn find_pairs(&mut self, x: &[f64], y: &[f64], r: &[f64], min_cell: f64) -> &[(u32, u32)] {
        self.pairs.clear();
        let n = x.len();
        if n < 2 {
            return &self.pairs;
        }
        let (mut x0, mut x1, mut y0, mut y1, mut rmax) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN, 0.0f64);
        for i in 0..n {
            x0 = x0.min(x[i]);
            x1 = x1.max(x[i]);
            y0 = y0.min(y[i]);
            y1 = y1.max(y[i]);
            rmax = rmax.max(r[i]);
        }
        // at least the interaction distance and the displacement; for sparse sets about one
        // particle per cell (`occupancy`), where the per-cell overhead and the candidate tests
        // balance
        let fill = ((x1 - x0) * (y1 - y0) * self.occupancy.max(0.0) / n as f64).sqrt();
        let mut cs = (2.0 * rmax).max(min_cell).max(fill).max(1e-300);
        let max_cells = 4 * n + 64;
        let dims = |cs: f64| (((x1 - x0) / cs) as usize + 1, ((y1 - y0) / cs) as usize + 1);
        let (mut nx, mut ny) = dims(cs);
        while (nx as f64) * (ny as f64) > max_cells as f64 {
            cs *= 1.5;
            (nx, ny) = dims(cs);
        }
        self.cell_size = cs;
        self.dims = (nx, ny);
        let ncell = nx * ny;
        self.cell_of.clear();
        self.start.clear();
        self.start.resize(ncell + 1, 0);
        for i in 0..n {
            let cx = (((x[i] - x0) / cs) as usize).min(nx - 1);
            let cy = (((y[i] - y0) / cs) as usize).min(ny - 1);
            let c = (cy * nx + cx) as u32;
            self.cell_of.push(c);
            self.start[c as usize + 1] += 1;
        }
        for c in 0..ncell {
            self.start[c + 1] += self.start[c];
        }
        self.sorted.clear();
        self.sorted.resize(n, 0);
        // fill with a running cursor per cell (reuse `start` shifted by one afterwards)
        for i in 0..n {
            let c = self.cell_of[i] as usize;
            let slot = self.start[c] as usize;
            self.sorted[slot] = i as u32;
            self.start[c] += 1;
        }
        // `start[c]` now holds the end of cell c = the start of cell c + 1: shift back
        for c in (1..=ncell).rev() {
            self.start[c] = self.start[c - 1];
        }
        self.start[0] = 0;
        // gather the positions in cell order: the neighbour loops then read contiguous memory
        self.xs.clear();
        self.ys.clear();
        self.rs.clear();
        for &i in &self.sorted {
            let i = i as usize;
            self.xs.push(x[i]);
            self.ys.push(y[i]);
            self.rs.push(r[i]);
        }
        // locals: the inner loop must not reload the buffers through `self` after each push
        let mut pairs = std::mem::take(&mut self.pairs);
        let (xs, ys, rs, start, sorted) = (&self.xs[..], &self.ys[..], &self.rs[..], &self.start[..], &self.sorted[..]);
        let mut a = 0;
        for cy in 0..ny {
            for cx in 0..nx {
                let c = cy * nx + cx;
                let end = start[c + 1] as usize;
                // forward half of the neighbours: each pair once
                let right = cx + 1 < nx;
                let up = cy + 1 < ny;
                let mut nb = [(0usize, 0usize); 4];
                let mut m = 0;
                if right {
                    nb[m] = (start[c + 1] as usize, start[c + 2] as usize);
                    m += 1;
                }
                if up {
                    let u = c + nx;
                    let lo = if cx > 0 { u - 1 } else { u };
                    let hi = if right { u + 1 } else { u };
                    // cells u − 1, u, u + 1 of the row above are contiguous in cell order
                    nb[m] = (start[lo] as usize, start[hi + 1] as usize);
                    m += 1;
                }
                while a < end {
                    let (xi, yi, ri) = (xs[a], ys[a], rs[a]);
                    let i = sorted[a];
                    let test = |b: usize, pairs: &mut Vec<(u32, u32)>| {
                        let (ddx, ddy) = (xs[b] - xi, ys[b] - yi);
                        let rr = ri + rs[b];
                        if ddx * ddx + ddy * ddy < rr * rr {
                            let j = sorted[b];
                            pairs.push(if i < j { (i, j) } else { (j, i) });
                        }
                    };
                    for b in a + 1..end {
                        test(b, &mut pairs);
                    }
                    for &(lo, hi) in &nb[..m] {
                        for b in lo..hi {
                            test(b, &mut pairs);
                        }
                    }
                    a += 1;
                }
            }
        }
        self.pairs = pairs;
        &self.pairs
    }
}

/// All overlapping pairs by testing every pair (reference for tests).
pub fn all_pairs(x: &[f64], y: &[f64], r: &[f64]) -> Vec<(u32, u32)> {
    let mut out = Vec::new();
    for i in 0..x.len() {
        for j in i + 1..x.len() {
            let (dx, dy) = (x[j] - x[i], y[j] - y[i]);
            let rr = r[i] + r[j];
            if dx * dx + dy * dy < rr * rr {
                out.push((i as u32, j as u32));
            }
        }
    }
    out
}

/// Mutable views of the arrays a collision changes.
pub struct CollisionState<'a> {
    /// Positions.
    pub x: &'a mut [f64],
    /// Positions.
    pub y: &'a mut [f64],
    /// Velocities.
    pub vx: &'a mut [f64],
    /// Velocities.
    pub vy: &'a mut [f64],
    /// Masses.
    pub m: &'a [f64],
    /// Collision radii.
    pub r: &'a [f64],
}

/// Resolves the pairs in order (module doc); returns how many were approaching (got an impulse).
pub fn resolve(s: &mut CollisionState<'_>, pairs: &[(u32, u32)], restitution: f64) -> usize {
    let mut impulses = 0;
    for &(i, j) in pairs {
        let (i, j) = (i as usize, j as usize);
        let (dx, dy) = (s.x[j] - s.x[i], s.y[j] - s.y[i]);
        let d = dx.hypot(dy);
        let overlap = s.r[i] + s.r[j] - d;
        if overlap <= 0.0 {
            continue; // separated by an earlier correction
        }
        let (nx, ny) = if d > 0.0 { (dx / d, dy / d) } else { (1.0, 0.0) };
        let (mi, mj) = (s.m[i], s.m[j]);
        let vn = (s.vx[j] - s.vx[i]) * nx + (s.vy[j] - s.vy[i]) * ny;
        if vn < 0.0 {
            let jimp = -(1.0 + restitution) * vn / (1.0 / mi + 1.0 / mj);
            s.vx[i] -= jimp * nx / mi;
            s.vy[i] -= jimp * ny / mi;
            s.vx[j] += jimp * nx / mj;
            s.vy[j] += jimp * ny / mj;
            impulses += 1;
        }
        let (wi, wj) = (mj / (mi + mj), mi / (mi + mj));
        s.x[i] -= overlap * wi * nx;
        s.y[i] -= overlap * wi * ny;
        s.x[j] += overlap * wj * nx;
        s.y[j] += overlap * wj * ny;
    }
    impulses
}

/// Keeps centres in lo ≤ y ≤ hi (module doc); returns how many were put back.
pub fn walls(y: &mut [f64], vy: &mut [f64], lo: f64, hi: f64) -> usize {
    let mut n = 0;
    for (y, vy) in y.iter_mut().zip(vy.iter_mut()) {
        if *y < lo {
            *y = (2.0 * lo - *y).min(hi);
            *vy = -*vy;
            n += 1;
        } else if *y > hi {
            *y = (2.0 * hi - *y).max(lo);
            *vy = -*vy;
            n += 1;
        }
    }
    n
}

/// Keeps centres between walls that vary along x (module doc); `walls_at(x)` gives the walls at
/// abscissa x (`None`: no walls there). Returns how many were put back.
pub fn walls_local<F>(x: &mut [f64], y: &mut [f64], vx: &mut [f64], vy: &mut [f64], walls_at: F) -> usize
where
    F: Fn(f64) -> Option<super::flow::LocalWalls>,
{
    let mut n = 0;
    for i in 0..y.len() {
        let Some(w) = walls_at(x[i]) else { continue };
        let (wy, s) = if y[i] < w.lo {
            (w.lo, w.slope_lo)
        } else if y[i] > w.hi {
            (w.hi, w.slope_hi)
        } else {
            continue;
        };
        n += 1;
        if s == 0.0 {
            // the straight wall, bit for bit as `walls`
            y[i] = if wy == w.lo { (2.0 * w.lo - y[i]).min(w.hi) } else { (2.0 * w.hi - y[i]).max(w.lo) };
            vy[i] = -vy[i];
            continue;
        }
        let inv = 1.0 / (1.0 + s * s);
        // mirror about the tangent line through (x, wy): (p − w)·n n = (y − wy)/(1 + s²) (−s, 1)
        let d = (y[i] - wy) * inv;
        let xn = x[i] + 2.0 * s * d;
        let yn = y[i] - 2.0 * d;
        // V − 2 (V·n) n, (V·n) n = (−s vx + vy)/(1 + s²) (−s, 1)
        let vn = (-s * vx[i] + vy[i]) * inv;
        vx[i] += 2.0 * s * vn;
        vy[i] -= 2.0 * vn;
        let w2 = walls_at(xn).unwrap_or(w);
        x[i] = xn;
        y[i] = yn.clamp(w2.lo, w2.hi.max(w2.lo));
    }
    n
}
