//! Cell grid of the fast evaluator: cells of side ≥ support / `reach`, particles sorted by cell
//! (row-major, stable counting sort: deterministic). The neighbour cells of a cell (`reach` cells
//! on each side) are, row by row, ≤ 2 segments of consecutive cells ([`Axis::segments`]: 2 where a
//! periodic axis wraps), each a contiguous run of the sorted order.

use crate::neighbours::Period;
use crate::Real;

/// One axis of the grid.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Axis {
    origin: Real,
    pub(super) cell: Real,
    inv_cell: Real,
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
                let cell = p.length / n as Real;
                Axis { origin: p.min, cell, inv_cell: 1.0 / cell, n, period: Some(p.length) }
            }
            None => {
                let (lo, hi) = min_max(v);
                Axis {
                    origin: lo,
                    cell,
                    inv_cell: 1.0 / cell,
                    n: ((hi - lo) / cell).floor() as usize + 1,
                    period: None,
                }
            }
        }
    }

    /// Cell of coordinate v, clamped to the grid (`y.max(0) as usize` is `floor(y).max(0) as usize`
    /// for every y, NaN included, without a libm call). A coordinate within rounding of a cell
    /// boundary may land in either cell: harmless, the pair terms vanish at the support radius.
    #[inline]
    fn coord(&self, v: Real) -> usize {
        (((v - self.origin) * self.inv_cell).max(0.0) as usize).min(self.n - 1)
    }

    /// The cells within `reach` of cell `i` as ≤ 2 segments (first, last, shift) of consecutive
    /// cells, in increasing offset; `shift` is added to the positions of the segment's particles to
    /// give their image next to cell i. Returns the segments and their count.
    #[inline]
    pub(super) fn segments(&self, i: usize, reach: usize) -> ([(usize, usize, Real); 2], usize) {
        let n = self.n;
        let none = (0, 0, 0.0);
        match self.period {
            // n > 2 reach: at most one side wraps
            Some(l) if i < reach => ([(i + n - reach, n - 1, -l), (0, i + reach, 0.0)], 2),
            Some(l) if i + reach >= n => ([(i - reach, n - 1, 0.0), (0, i + reach - n, l)], 2),
            Some(_) => ([(i - reach, i + reach, 0.0), none], 1),
            None => ([(i.saturating_sub(reach), (i + reach).min(n - 1), 0.0), none], 1),
        }
    }

    /// The cells at offsets `lo..=hi` from cell `i` (0 ≤ lo ≤ hi ≤ reach) as ≤ 2 segments (first,
    /// last, shift) as in [`Axis::segments`]: the forward half of the neighbourhood of the symmetric
    /// pass. Returns the segments and their count (0 when the span lies beyond a non-periodic end).
    #[inline]
    pub(super) fn forward(&self, i: usize, lo: usize, hi: usize) -> ([(usize, usize, Real); 2], usize) {
        let n = self.n;
        let none = (0, 0, 0.0);
        let (a, b) = (i + lo, i + hi);
        match self.period {
            Some(l) if a >= n => ([(a - n, b - n, l), none], 1),
            Some(l) if b >= n => ([(a, n - 1, 0.0), (0, b - n, l)], 2),
            Some(_) => ([(a, b, 0.0), none], 1),
            None if a >= n => ([none, none], 0),
            None => ([(a, b.min(n - 1), 0.0), none], 1),
        }
    }

    /// Periodic axes need 2 reach + 1 distinct cells (each neighbour cell visited once).
    fn supported(&self, reach: usize) -> bool {
        self.period.is_none() || self.n > 2 * reach
    }
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

    /// Centre of cell row `jz` \[m\].
    pub(super) fn az_centre(&self, jz: usize) -> Real {
        self.az.origin + (jz as Real + 0.5) * self.az.cell
    }

    /// Cells per support radius.
    pub(super) fn reach(&self) -> usize {
        self.reach
    }

    /// Cell side along z \[m\].
    pub(super) fn cell_z(&self) -> Real {
        self.az.cell
    }

    /// Period along x \[m\], if periodic.
    pub(super) fn period_x(&self) -> Option<Real> {
        self.ax.period
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
