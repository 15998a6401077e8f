//! Cell-list neighbour search (cell size ≥ support radius, rebuilt every step by a stable counting
//! sort, so the neighbour order of a particle is fixed by the particle indices: deterministic).

use crate::Real;

/// A periodic direction: coordinates live in `[min, min + length)`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Period {
    /// Lower bound of the periodic interval \[m\].
    pub min: Real,
    /// Period \[m\]; must hold at least 3 cells of one support radius.
    pub length: Real,
}

impl Period {
    /// Wraps `v` into `[min, min + length)`.
    #[inline]
    pub fn wrap(&self, v: Real) -> Real {
        let mut y = v - self.min;
        y -= self.length * (y / self.length).floor();
        if y >= self.length {
            y -= self.length;
        }
        self.min + y
    }

    /// Minimum-image difference.
    #[inline]
    pub fn image(&self, d: Real) -> Real {
        d - self.length * (d / self.length).round()
    }
}

/// One axis of the cell grid.
#[derive(Clone, Copy, Debug, Default)]
struct Axis {
    origin: Real,
    cell: Real,
    n: usize,
    periodic: Option<Period>,
}

impl Axis {
    fn build(v: &[Real], radius: Real, periodic: Option<Period>) -> Axis {
        match periodic {
            Some(p) => {
                let n = ((p.length / radius).floor() as usize).max(1);
                Axis { origin: p.min, cell: p.length / n as Real, n, periodic }
            }
            None => {
                let (lo, hi) = min_max(v);
                Axis { origin: lo, cell: radius, n: ((hi - lo) / radius).floor() as usize + 1, periodic: None }
            }
        }
    }

    #[inline]
    fn coord(&self, v: Real) -> usize {
        // periodic: positions outside the interval (moving walls are not wrapped) fall in their image cell
        let v = match self.periodic {
            Some(p) => p.wrap(v),
            None => v,
        };
        (((v - self.origin) / self.cell).floor().max(0.0) as usize).min(self.n - 1)
    }

    /// The (up to 3) cells next to cell `i`, `usize::MAX` for none.
    #[inline]
    fn around(&self, i: usize) -> [usize; 3] {
        let mut c = [usize::MAX; 3];
        match self.periodic {
            Some(_) if self.n >= 3 => c = [(i + self.n - 1) % self.n, i, (i + 1) % self.n],
            Some(_) => {
                for (k, j) in (0..self.n).enumerate() {
                    c[k] = j;
                }
            }
            None => {
                if i > 0 {
                    c[0] = i - 1;
                }
                c[1] = i;
                if i + 1 < self.n {
                    c[2] = i + 1;
                }
            }
        }
        c
    }

    #[inline]
    fn diff(&self, d: Real) -> Real {
        match self.periodic {
            Some(p) => p.image(d),
            None => d,
        }
    }
}

/// Uniform grid of cells holding particle indices.
#[derive(Clone, Debug, Default)]
pub struct CellList {
    ax: Axis,
    az: Axis,
    cell_start: Vec<u32>,
    sorted: Vec<u32>,
    cell_of: Vec<u32>,
    fill: Vec<u32>,
    radius2: Real,
}

impl CellList {
    /// Rebuilds the grid for positions `x`, `z`, search radius `radius` (> 0) and optional periodic
    /// directions. Reuses its allocations. Never panics; the caller guarantees finite positions and,
    /// if periodic, `length ≥ 3 radius` (checked by [`crate::SphParams::validate`]).
    pub fn build(
        &mut self,
        x: &[Real],
        z: &[Real],
        radius: Real,
        periodic_x: Option<Period>,
        periodic_z: Option<Period>,
    ) {
        let n = x.len();
        self.radius2 = radius * radius;
        self.ax = Axis::build(x, radius, periodic_x);
        self.az = Axis::build(z, radius, periodic_z);
        let ncell = self.ax.n * self.az.n;
        let mut cell_of = std::mem::take(&mut self.cell_of);
        cell_of.clear();
        cell_of.extend(x.iter().zip(z).map(|(&xi, &zi)| self.cell_index(xi, zi) as u32));
        self.cell_of = cell_of;
        self.cell_start.clear();
        self.cell_start.resize(ncell + 1, 0);
        for &c in &self.cell_of {
            self.cell_start[c as usize + 1] += 1;
        }
        for c in 0..ncell {
            self.cell_start[c + 1] += self.cell_start[c];
        }
        self.sorted.clear();
        self.sorted.resize(n, 0);
        self.fill.clear();
        self.fill.extend_from_slice(&self.cell_start[..ncell]);
        for (i, &c) in self.cell_of.iter().enumerate() {
            self.sorted[self.fill[c as usize] as usize] = i as u32;
            self.fill[c as usize] += 1;
        }
    }

    #[inline]
    fn cell_index(&self, x: Real, z: Real) -> usize {
        self.az.coord(z) * self.ax.n + self.ax.coord(x)
    }

    /// Particle indices sorted by cell (row-major cells, stable within a cell).
    pub fn sorted_indices(&self) -> &[u32] {
        &self.sorted
    }

    /// Calls `f(b, dx, dz, r²)` for every particle b (including a itself) with
    /// r² = dx² + dz² < radius², where (dx, dz) = r_a − r_b (minimum image when periodic).
    /// The order is fixed by the grid and the particle indices.
    #[inline]
    pub fn for_each_neighbour<F: FnMut(usize, Real, Real, Real)>(
        &self,
        xa: Real,
        za: Real,
        x: &[Real],
        z: &[Real],
        mut f: F,
    ) {
        let cols = self.ax.around(self.ax.coord(xa));
        let rows = self.az.around(self.az.coord(za));
        for jz in rows {
            if jz == usize::MAX {
                continue;
            }
            for jx in cols {
                if jx == usize::MAX {
                    continue;
                }
                let c = jz * self.ax.n + jx;
                let (s, e) = (self.cell_start[c] as usize, self.cell_start[c + 1] as usize);
                for &b in &self.sorted[s..e] {
                    let b = b as usize;
                    let dx = self.ax.diff(xa - x[b]);
                    let dz = self.az.diff(za - z[b]);
                    let r2 = dx * dx + dz * dz;
                    if r2 < self.radius2 {
                        f(b, dx, dz, r2);
                    }
                }
            }
        }
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

    fn brute(xa: Real, za: Real, x: &[Real], z: &[Real], r: Real, p: Option<Period>, q: Option<Period>) -> Vec<usize> {
        let mut v: Vec<usize> = (0..x.len())
            .filter(|&b| {
                let mut dx = xa - x[b];
                if let Some(p) = p {
                    dx -= p.length * (dx / p.length).round();
                }
                let mut dz = za - z[b];
                if let Some(q) = q {
                    dz -= q.length * (dz / q.length).round();
                }
                dx * dx + dz * dz < r * r
            })
            .collect();
        v.sort_unstable();
        v
    }

    #[test]
    fn matches_brute_force_with_and_without_periodic_x() {
        let mut s = 0x9E37_79B9_7F4A_7C15u64;
        let mut rnd = || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 11) as Real / (1u64 << 53) as Real
        };
        let n = 500;
        // a few points outside the periodic interval (moving walls are not wrapped)
        let x: Vec<Real> = (0..n)
            .map(|i| rnd() * 1.0 + if i % 50 == 0 { 1.0 } else { 0.0 } - if i % 70 == 0 { 1.0 } else { 0.0 })
            .collect();
        let z: Vec<Real> = (0..n).map(|_| rnd() * 0.7 - 0.2).collect();
        let px = Some(Period { min: 0.0, length: 1.0 });
        let pz = Some(Period { min: -0.2, length: 0.7 });
        for (p, q) in [(None, None), (px, None), (None, pz), (px, pz)] {
            let mut cl = CellList::default();
            cl.build(&x, &z, 0.13, p, q);
            for a in 0..n {
                let mut got = Vec::new();
                cl.for_each_neighbour(x[a], z[a], &x, &z, |b, _, _, _| got.push(b));
                got.sort_unstable();
                assert_eq!(got, brute(x[a], z[a], &x, &z, 0.13, p, q), "particle {a} periodic {p:?} {q:?}");
            }
        }
    }
}
