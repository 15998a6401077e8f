//! Cell-list neighbour search (cell size ≥ support radius, rebuilt every step by a stable counting
//! sort, so the neighbour order of a particle is fixed by the particle indices: deterministic).

use crate::Real;

/// Periodic boundary along x: positions live in `[x_min, x_min + length)`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PeriodicX {
    /// Lower bound of the periodic interval \[m\].
    pub x_min: Real,
    /// Period \[m\]; must hold at least 3 cells of one support radius.
    pub length: Real,
}

impl PeriodicX {
    /// Wraps `x` into `[x_min, x_min + length)`.
    #[inline]
    pub fn wrap(&self, x: Real) -> Real {
        let mut y = x - self.x_min;
        y -= self.length * (y / self.length).floor();
        if y >= self.length {
            y -= self.length;
        }
        self.x_min + y
    }
}

/// Uniform grid of cells holding particle indices.
#[derive(Clone, Debug, Default)]
pub struct CellList {
    x0: Real,
    z0: Real,
    cell_x: Real,
    cell_z: Real,
    nx: usize,
    nz: usize,
    periodic: Option<PeriodicX>,
    cell_start: Vec<u32>,
    sorted: Vec<u32>,
    cell_of: Vec<u32>,
    radius2: Real,
}

impl CellList {
    /// Rebuilds the grid for positions `x`, `z`, search radius `radius` (> 0) and optional periodic
    /// x. Reuses its allocations. Panics never; the caller guarantees finite positions and, if
    /// periodic, `length ≥ 3 radius` (checked by [`crate::SphParams::validate`]).
    pub fn build(&mut self, x: &[Real], z: &[Real], radius: Real, periodic: Option<PeriodicX>) {
        let n = x.len();
        self.periodic = periodic;
        self.radius2 = radius * radius;
        let (zmin, zmax) = min_max(z);
        self.z0 = zmin;
        self.cell_z = radius;
        self.nz = ((zmax - zmin) / radius).floor() as usize + 1;
        match periodic {
            Some(p) => {
                self.x0 = p.x_min;
                self.nx = ((p.length / radius).floor() as usize).max(1);
                self.cell_x = p.length / self.nx as Real;
            }
            None => {
                let (xmin, xmax) = min_max(x);
                self.x0 = xmin;
                self.cell_x = radius;
                self.nx = ((xmax - xmin) / radius).floor() as usize + 1;
            }
        }
        let ncell = self.nx * self.nz;
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
        let mut fill: Vec<u32> = self.cell_start[..ncell].to_vec();
        for (i, &c) in self.cell_of.iter().enumerate() {
            self.sorted[fill[c as usize] as usize] = i as u32;
            fill[c as usize] += 1;
        }
    }

    #[inline]
    fn cell_coords(&self, x: Real, z: Real) -> (usize, usize) {
        let ix = (((x - self.x0) / self.cell_x).floor().max(0.0) as usize).min(self.nx - 1);
        let iz = (((z - self.z0) / self.cell_z).floor().max(0.0) as usize).min(self.nz - 1);
        (ix, iz)
    }

    #[inline]
    fn cell_index(&self, x: Real, z: Real) -> usize {
        let (ix, iz) = self.cell_coords(x, z);
        iz * self.nx + ix
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
        let (ix, iz) = self.cell_coords(xa, za);
        let izs = iz.saturating_sub(1)..=(iz + 1).min(self.nz - 1);
        for jz in izs {
            let mut cols = [usize::MAX; 3];
            match self.periodic {
                Some(_) if self.nx >= 3 => {
                    cols = [(ix + self.nx - 1) % self.nx, ix, (ix + 1) % self.nx];
                }
                Some(_) => {
                    for (k, c) in (0..self.nx).enumerate() {
                        cols[k] = c;
                    }
                }
                None => {
                    if ix > 0 {
                        cols[0] = ix - 1;
                    }
                    cols[1] = ix;
                    if ix + 1 < self.nx {
                        cols[2] = ix + 1;
                    }
                }
            }
            for jx in cols {
                if jx == usize::MAX {
                    continue;
                }
                let c = jz * self.nx + jx;
                let (s, e) = (self.cell_start[c] as usize, self.cell_start[c + 1] as usize);
                for &b in &self.sorted[s..e] {
                    let b = b as usize;
                    let mut dx = xa - x[b];
                    if let Some(p) = self.periodic {
                        dx -= p.length * (dx / p.length).round();
                    }
                    let dz = za - z[b];
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

    fn brute(xa: Real, za: Real, x: &[Real], z: &[Real], r: Real, p: Option<PeriodicX>) -> Vec<usize> {
        let mut v: Vec<usize> = (0..x.len())
            .filter(|&b| {
                let mut dx = xa - x[b];
                if let Some(p) = p {
                    dx -= p.length * (dx / p.length).round();
                }
                let dz = za - z[b];
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
        let x: Vec<Real> = (0..n).map(|_| rnd() * 1.0).collect();
        let z: Vec<Real> = (0..n).map(|_| rnd() * 0.7 - 0.2).collect();
        for p in [None, Some(PeriodicX { x_min: 0.0, length: 1.0 })] {
            let mut cl = CellList::default();
            cl.build(&x, &z, 0.13, p);
            for a in 0..n {
                let mut got = Vec::new();
                cl.for_each_neighbour(x[a], z[a], &x, &z, |b, _, _, _| got.push(b));
                got.sort_unstable();
                assert_eq!(got, brute(x[a], z[a], &x, &z, 0.13, p), "particle {a} periodic {p:?}");
            }
        }
    }
}
