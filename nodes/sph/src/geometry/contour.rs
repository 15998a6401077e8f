//! Level sets of a sampled function by marching squares (Lorensen & Cline 1987 in 2D), linked into
//! oriented polylines (the region below the level on the left), and resampled at a fixed arc-length
//! spacing.

use std::collections::HashMap;

use super::shape::SdfGrid;
use crate::Real;

/// A polyline; `closed` when its last point connects back to the first.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Polyline {
    pub points: Vec<[Real; 2]>,
    pub closed: bool,
}

impl Polyline {
    /// Length \[m\] (closing segment included when closed).
    pub fn length(&self) -> Real {
        let n = self.points.len();
        let m = if self.closed { n } else { n.saturating_sub(1) };
        (0..m)
            .map(|i| {
                let (a, b) = (self.points[i], self.points[(i + 1) % n]);
                (b[0] - a[0]).hypot(b[1] - a[1])
            })
            .sum()
    }

    /// Shoelace area, positive when the polyline runs counter-clockwise in the (x, z) plane (the
    /// region below the level on the left); 0 for an open polyline.
    pub fn signed_area(&self) -> Real {
        if !self.closed {
            return 0.0;
        }
        let n = self.points.len();
        0.5 * (0..n)
            .map(|i| {
                let (a, b) = (self.points[i], self.points[(i + 1) % n]);
                a[0] * b[1] - b[0] * a[1]
            })
            .sum::<Real>()
    }

    /// Points at equal arc-length spacing P/n, n = round(P/`spacing`) (at least 3 on a closed
    /// polyline, at least 1 interval on an open one, whose both ends are kept), from the first point.
    pub fn resample(&self, spacing: Real) -> Vec<[Real; 2]> {
        let total = self.length();
        let np = self.points.len();
        if np == 0 {
            return Vec::new();
        }
        if np == 1 || total <= 0.0 {
            return vec![self.points[0]];
        }
        let (n, count) = if self.closed {
            let n = ((total / spacing).round() as usize).max(3);
            (n, n)
        } else {
            let n = ((total / spacing).round() as usize).max(1);
            (n, n + 1)
        };
        let step = total / n as Real;
        let segs = if self.closed { np } else { np - 1 };
        let mut out = Vec::with_capacity(count);
        let (mut seg, mut seg_start) = (0usize, 0.0);
        for k in 0..count {
            let target = k as Real * step;
            loop {
                let (a, b) = (self.points[seg], self.points[(seg + 1) % np]);
                let len = (b[0] - a[0]).hypot(b[1] - a[1]);
                if target <= seg_start + len || seg + 1 == segs {
                    let t = if len > 0.0 { ((target - seg_start) / len).clamp(0.0, 1.0) } else { 0.0 };
                    out.push([a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]);
                    break;
                }
                seg_start += len;
                seg += 1;
            }
        }
        out
    }
}

/// The level set {f = `level`} of the grid as oriented polylines (below the level on the left).
/// Nodes exactly at the level count as above. Saddle cells are resolved by the cell-centre mean.
/// Polylines come in a deterministic order (by the first cell met in a row-major scan).
pub(crate) fn level_set(grid: &SdfGrid, level: Real) -> Vec<Polyline> {
    let (nx, nz) = (grid.nx, grid.nz);
    let g = |i: usize, j: usize| grid.values[j * nx + i] - level;
    let h_edge = |i: usize, j: usize| 2 * (j * nx + i) as u64;
    let v_edge = |i: usize, j: usize| 2 * (j * nx + i) as u64 + 1;
    // oriented segments (from edge, to edge)
    let mut segs: Vec<(u64, u64)> = Vec::new();
    for j in 0..nz - 1 {
        for i in 0..nx - 1 {
            let c = [g(i, j), g(i + 1, j), g(i + 1, j + 1), g(i, j + 1)];
            let inside = c.map(|v| v < 0.0);
            if inside.iter().all(|&b| b) || inside.iter().all(|&b| !b) {
                continue;
            }
            let edges = [h_edge(i, j), v_edge(i + 1, j), h_edge(i, j + 1), v_edge(i, j)];
            let crossing: Vec<usize> = (0..4).filter(|&e| inside[e] != inside[(e + 1) % 4]).collect();
            let mut push = |a: usize, b: usize| {
                // corners met going counter-clockwise from edge a to edge b lie right of a → b
                let corner_inside = inside[(a + 1) % 4];
                if corner_inside {
                    segs.push((edges[b], edges[a]));
                } else {
                    segs.push((edges[a], edges[b]));
                }
            };
            if crossing.len() == 2 {
                push(crossing[0], crossing[1]);
            } else {
                let centre_inside = (c[0] + c[1] + c[2] + c[3]) * 0.25 < 0.0;
                if centre_inside == inside[0] {
                    // c0 and c2 connected through the centre: c1 and c3 are cut off
                    push(0, 1);
                    push(2, 3);
                } else {
                    push(1, 2);
                    push(3, 0);
                }
            }
        }
    }
    let point = |e: u64| -> [Real; 2] {
        let node = (e / 2) as usize;
        let (i, j) = (node % nx, node / nx);
        let (i2, j2) = if e & 1 == 0 { (i + 1, j) } else { (i, j + 1) };
        let (va, vb) = (g(i, j), g(i2, j2));
        let t = if va == vb { 0.5 } else { (va / (va - vb)).clamp(0.0, 1.0) };
        let (pa, pb) = (grid.node(i, j), grid.node(i2, j2));
        [pa[0] + t * (pb[0] - pa[0]), pa[1] + t * (pb[1] - pa[1])]
    };
    let from: HashMap<u64, usize> = segs.iter().enumerate().map(|(k, s)| (s.0, k)).collect();
    let to: HashMap<u64, usize> = segs.iter().enumerate().map(|(k, s)| (s.1, k)).collect();
    let mut used = vec![false; segs.len()];
    let mut out = Vec::new();
    for k0 in 0..segs.len() {
        if used[k0] {
            continue;
        }
        // walk back to the beginning of an open chain (a closed loop returns to k0)
        let mut start = k0;
        while let Some(&p) = to.get(&segs[start].0) {
            if p == k0 || used[p] {
                break;
            }
            start = p;
        }
        let mut pts = vec![point(segs[start].0)];
        let mut k = start;
        let mut closed = false;
        loop {
            used[k] = true;
            match from.get(&segs[k].1) {
                Some(&n) if n == start => {
                    closed = true;
                    break;
                }
                Some(&n) if !used[n] => {
                    pts.push(point(segs[k].1));
                    k = n;
                }
                _ => {
                    pts.push(point(segs[k].1));
                    break;
                }
            }
        }
        out.push(Polyline { points: pts, closed });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn circle_level_set_is_one_counter_clockwise_loop_with_the_right_area_and_length() {
        let r = 0.3;
        let grid = SdfGrid::sample(|x, z| x.hypot(z) - r, [-0.5, -0.5], 0.01, 101, 101, false);
        let lines = level_set(&grid, 0.0);
        assert_eq!(lines.len(), 1);
        let l = &lines[0];
        assert!(l.closed);
        let area = l.signed_area();
        assert!((area / (std::f64::consts::PI * r * r) - 1.0).abs() < 1e-3, "{area}");
        assert!((l.length() / (2.0 * std::f64::consts::PI * r) - 1.0).abs() < 1e-3);
        let pts = l.resample(0.05);
        assert_eq!(pts.len(), (2.0 * std::f64::consts::PI * r / 0.05).round() as usize);
        for w in pts.windows(2) {
            let d = (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]);
            assert!((d / 0.05 - 1.0).abs() < 0.03, "{d}");
        }
        // a larger level gives a larger circle, a level below the minimum nothing
        assert!(level_set(&grid, 0.1)[0].signed_area() > area);
        assert!(level_set(&grid, -0.4).is_empty());
    }

    #[test]
    fn two_disks_give_two_loops_and_an_annulus_a_hole() {
        let f = |x: Real, z: Real| ((x - 0.2).hypot(z) - 0.1).min((x + 0.2).hypot(z) - 0.1);
        let grid = SdfGrid::sample(f, [-0.5, -0.5], 0.01, 101, 101, false);
        assert_eq!(level_set(&grid, 0.0).len(), 2);
        let ring = |x: Real, z: Real| (x.hypot(z) - 0.3).abs() - 0.1;
        let grid = SdfGrid::sample(ring, [-0.5, -0.5], 0.01, 101, 101, false);
        let lines = level_set(&grid, 0.0);
        assert_eq!(lines.len(), 2);
        let area: Real = lines.iter().map(|l| l.signed_area()).sum();
        let exact = std::f64::consts::PI * (0.4 * 0.4 - 0.2 * 0.2);
        assert!((area / exact - 1.0).abs() < 2e-3, "{area} vs {exact}");
    }
}
