//! Cell grid of the fast evaluator: cells of side ≥ support / `reach`, particles sorted by cell
//! (row-major, stable counting sort: deterministic), and for each cell the runs of the sorted order
//! that hold its neighbour cells (`reach` cells on each side), with the periodic shift of each run.
//! Three (or five) cells next to each other in a row are one contiguous run.

use crate::neighbours::Period;
use crate::Real;

/// One axis of the grid.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Axis {
    origin: Real,
    cell: Real,
    pub(super) n: usize,
    /// Period length when periodic.
    period: Option<Real>,
}

impl Axis {
    /// Same sizing as [`crate::neighbours::CellList`] with cells of `cell` (≥ support / reach).
    fn build(v: &[Real], cell: Real, periodic: Option<Period>) -> Axis {
        match periodic {
            Some(p) => {
                let n = ((p.length / cell).floor() as usize).max(1);
                Axis { origin: p.min, cell: p.length / n as Real, n, period: Some(p.length) }
            }
            None => {
                let (lo, hi) = min_max(v);
                Axis { origin: lo, cell, n: ((hi - lo) / cell).floor() as usize + 1, period: None }
            }
        }
    }

    #[inline]
    fn coord(&self, v: Real) -> usize {
        (((v - self.origin) / self.cell).floor().max(0.0) as usize).min(self.n - 1)
    }

    /// Centre of cell `i`.
    fn centre(&self, i: usize) -> Real {
        self.origin + (i as Real + 0.5) * self.cell
    }

    /// Calls `f(j, shift)` for the cells j within `reach` of cell `i`, in increasing offset; `shift` is
    /// added to the positions of cell j's particles to give their image next to cell i.
    #[inline]
    fn around(&self, i: usize, reach: usize, mut f: impl FnMut(usize, Real)) {
        let (n, r) = (self.n as isize, reach as isize);
        for d in -r..=r {
            let j = i as isize + d;
            match self.period {
                Some(l) if j < 0 => f((j + n) as usize, -l),
                Some(l) if j >= n => f((j - n) as usize, l),
                _ if j < 0 || j >= n => {}
                _ => f(j as usize, 0.0),
            }
        }
    }

    /// Periodic axes need 2 reach + 1 distinct cells (each neighbour cell visited once).
    fn supported(&self, reach: usize) -> bool {
        self.period.is_none() || self.n > 2 * reach
    }
}

/// A contiguous range of the sorted order and the shift of its positions.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Run {
    pub(super) start: usize,
    pub(super) end: usize,
    pub(super) sx: Real,
    pub(super) sz: Real,
}

/// Uniform grid with particles sorted by cell.
#[derive(Clone, Debug, Default)]
pub(super) struct Grid {
    pub(super) ax: Axis,
    pub(super) az: Axis,
    reach: usize,
    /// First sorted index of each cell (+ one past the end).
    pub(super) cell_start: Vec<u32>,
    /// Sorted position → particle index.
    pub(super) order: Vec<u32>,
    /// Particle index → sorted position.
    pub(super) rank: Vec<u32>,
    cell_of: Vec<u32>,
    fill: Vec<u32>,
}

impl Grid {
    /// Rebuilds the grid for cells of side ≥ `support / reach` (`reach` ≥ 1). Returns false (grid
    /// unusable) when a periodic axis has fewer than 2 reach + 1 cells or the grid would not fit the
    /// u32 indices.
    pub(super) fn build(
        &mut self,
        x: &[Real],
        z: &[Real],
        support: Real,
        reach: usize,
        periodic_x: Option<Period>,
        periodic_z: Option<Period>,
    ) -> bool {
        let n = x.len();
        let cell = support / reach as Real;
        self.reach = reach;
        self.ax = Axis::build(x, cell, periodic_x);
        self.az = Axis::build(z, cell, periodic_z);
        let ncell = self.ax.n.checked_mul(self.az.n);
        let fits = ncell.is_some_and(|c| c < u32::MAX as usize / 2) && n < u32::MAX as usize;
        if !fits || !self.ax.supported(reach) || !self.az.supported(reach) {
            return false;
        }
        let ncell = self.ax.n * self.az.n;
        let (ax, az) = (self.ax, self.az);
        self.cell_of.clear();
        self.cell_of.extend(x.iter().zip(z).map(|(&xi, &zi)| (az.coord(zi) * ax.n + ax.coord(xi)) as u32));
        self.cell_start.clear();
        self.cell_start.resize(ncell + 1, 0);
        for &c in &self.cell_of {
            self.cell_start[c as usize + 1] += 1;
        }
        for c in 0..ncell {
            self.cell_start[c + 1] += self.cell_start[c];
        }
        self.order.clear();
        self.order.resize(n, 0);
        self.rank.clear();
        self.rank.resize(n, 0);
        self.fill.clear();
        self.fill.extend_from_slice(&self.cell_start[..ncell]);
        for (i, &c) in self.cell_of.iter().enumerate() {
            let k = self.fill[c as usize];
            self.order[k as usize] = i as u32;
            self.rank[i] = k;
            self.fill[c as usize] += 1;
        }
        true
    }

    /// Number of cells.
    pub(super) fn cells(&self) -> usize {
        self.cell_start.len() - 1
    }

    /// Sorted range of cell `c`.
    #[inline]
    pub(super) fn range(&self, c: usize) -> (usize, usize) {
        (self.cell_start[c] as usize, self.cell_start[c + 1] as usize)
    }

    /// Centre of cell `c` \[m\].
    pub(super) fn centre(&self, c: usize) -> (Real, Real) {
        (self.ax.centre(c % self.ax.n), self.az.centre(c / self.ax.n))
    }

    /// Fills `out` with the non-empty runs holding the neighbour cells of cell `c` (rows bottom to top,
    /// each row left to right). Returns the offset of cell c's own particles in the concatenation
    /// of the runs.
    pub(super) fn runs(&self, c: usize, out: &mut Vec<Run>) -> usize {
        out.clear();
        let nx = self.ax.n;
        let (cx, cz) = (c % nx, c / nx);
        let mut offset = 0;
        let mut own = 0;
        self.az.around(cz, self.reach, |jz, sz| {
            // consecutive columns with the same shift are one contiguous run
            let mut cur: Option<(usize, usize, Real)> = None; // (first col, last col, shift)
            let flush = |r: (usize, usize, Real), out: &mut Vec<Run>, offset: &mut usize, own: &mut usize| {
                let (s, e) = (self.cell_start[jz * nx + r.0] as usize, self.cell_start[jz * nx + r.1 + 1] as usize);
                if jz == cz && sz == 0.0 && r.2 == 0.0 && (r.0..=r.1).contains(&cx) {
                    *own = *offset + self.cell_start[c] as usize - s;
                }
                if e > s {
                    out.push(Run { start: s, end: e, sx: r.2, sz });
                    *offset += e - s;
                }
            };
            self.ax.around(cx, self.reach, |jx, sx| match cur {
                Some((a, b, s)) if jx == b + 1 && s == sx => cur = Some((a, jx, s)),
                Some(r) => {
                    flush(r, out, &mut offset, &mut own);
                    cur = Some((jx, jx, sx));
                }
                None => cur = Some((jx, jx, sx)),
            });
            if let Some(r) = cur {
                flush(r, out, &mut offset, &mut own);
            }
        });
        own
    }
}

fn min_max(v: &[Real]) -> (Real, Real) {
    let (lo, hi) = v.iter().fold((Real::INFINITY, Real::NEG_INFINITY), |(lo, hi), &a| (lo.min(a), hi.max(a)));
    if lo.is_finite() && hi.is_finite() {
        (lo, hi)
    } else {
        (0.0, 0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The runs of every cell cover exactly the particles within the support (minimum image), each
    /// once, for reach 1 and 2 and every periodic combination.
    #[test]
    fn runs_cover_every_neighbour_once() {
        let mut s = 0x9E37_79B9_7F4A_7C15u64;
        let mut rnd = || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 11) as Real / (1u64 << 53) as Real
        };
        let n = 600;
        let x: Vec<Real> = (0..n).map(|_| rnd()).collect();
        let z: Vec<Real> = (0..n).map(|_| rnd() * 0.7 - 0.2).collect();
        let px = Some(Period { min: 0.0, length: 1.0 });
        let pz = Some(Period { min: -0.2, length: 0.7 });
        let r = 0.13;
        for reach in [1, 2] {
            for (p, q) in [(None, None), (px, None), (None, pz), (px, pz)] {
                let mut g = Grid::default();
                assert!(g.build(&x, &z, r, reach, p, q));
                let mut runs = Vec::new();
                for a in 0..n {
                    let k = g.rank[a] as usize;
                    let c = (0..g.cells()).find(|&c| (g.range(c).0..g.range(c).1).contains(&k)).expect("cell");
                    let own = g.runs(c, &mut runs);
                    let mut seen = Vec::new();
                    let mut off = 0;
                    for run in &runs {
                        for kb in run.start..run.end {
                            if off + kb - run.start == own + k - g.range(c).0 {
                                assert_eq!(kb, k, "own offset");
                            }
                            let b = g.order[kb] as usize;
                            let (dx, dz) = (x[a] - (x[b] + run.sx), z[a] - (z[b] + run.sz));
                            if dx * dx + dz * dz < r * r {
                                seen.push(b);
                            }
                        }
                        off += run.end - run.start;
                    }
                    seen.sort_unstable();
                    let mut want: Vec<usize> = (0..n)
                        .filter(|&b| {
                            let dx = p.map_or(x[a] - x[b], |p| p.image(x[a] - x[b]));
                            let dz = q.map_or(z[a] - z[b], |q| q.image(z[a] - z[b]));
                            dx * dx + dz * dz < r * r
                        })
                        .collect();
                    want.sort_unstable();
                    assert_eq!(seen, want, "particle {a} reach {reach} periodic {p:?} {q:?}");
                }
            }
        }
    }
}
