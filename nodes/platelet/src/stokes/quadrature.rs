//! Integrals of the free-space Stokeslet G(x, y) = I/r + r r/r³ (r = x − y) against the traction
//! density of one panel, ∫ G(x, y(β, θ)) sinβ dβ dθ (module doc of [`super`]): tensor Gauss rules
//! chosen by the distance/size ratio, bisection of the physically longer side when the target is
//! near, and a Duffy transform around the collocation point of the panel itself.

use super::mesh::{dist, Panel, Surface};
use crate::shape::gauss_legendre_01;

/// Symmetric 3 × 3 accumulator: xx, xy, xz, yy, yz, zz.
pub(crate) type Sym = [f64; 6];

/// Ratio ρ/diameter from which a 2-point, 3-point or 6-point tensor rule is used; below the
/// last one the rectangle is bisected. With ρ at least 2, 4 or 8 half-lengths from the centre,
/// the Bernstein-ellipse bound of Gauss–Legendre on 1/r gives relative errors of about 2e-5
/// (2 points at 8), 4e-6 (3 points at 4) and 1e-7 (6 points at 2).
const FAR_2: f64 = 4.0;
const FAR_3: f64 = 2.0;
const FAR_6: f64 = 1.0;
/// Deepest bisection (2^-40 of a panel: never reached in practice, a guard).
const MAX_DEPTH: usize = 40;
/// Points per direction of the Duffy rule on the four cells around the collocation point.
const DUFFY_N: usize = 8;
/// Largest number of cells a self panel is cut into along its long side.
const MAX_CELLS: usize = 61;

/// Gauss–Legendre rules on [0, 1] of orders 1..=8.
pub(crate) struct Rules {
    rules: Vec<Vec<(f64, f64)>>,
}

impl Rules {
    pub fn new() -> Self {
        Rules { rules: (0..=8).map(|n| if n == 0 { Vec::new() } else { gauss_legendre_01(n) }).collect() }
    }
    pub fn get(&self, n: usize) -> &[(f64, f64)] {
        &self.rules[n]
    }
}

#[inline]
fn add_stokeslet(x: &[f64; 3], y: &[f64; 3], w: f64, acc: &mut Sym) {
    let r = [x[0] - y[0], x[1] - y[1], x[2] - y[2]];
    let r2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
    let inv = 1.0 / r2.sqrt();
    let a = w * inv;
    let b = a * inv * inv;
    acc[0] += a + b * r[0] * r[0];
    acc[1] += b * r[0] * r[1];
    acc[2] += b * r[0] * r[2];
    acc[3] += a + b * r[1] * r[1];
    acc[4] += b * r[1] * r[2];
    acc[5] += a + b * r[2] * r[2];
}

/// Precomputed far-field points of a panel: (position, weight sinβ dβ dθ).
pub(crate) struct FarRule {
    pub two: Vec<([f64; 3], f64)>,
    pub three: Vec<([f64; 3], f64)>,
}

/// Tensor Gauss points of order `n` on a parameter rectangle with weights sinβ dβ dθ.
pub(crate) fn tensor_points(
    s: &Surface,
    rules: &Rules,
    n: usize,
    (b0, b1, t0, t1): (f64, f64, f64, f64),
) -> Vec<([f64; 3], f64, f64, f64)> {
    let mut out = Vec::with_capacity(n * n);
    for &(u, wu) in rules.get(n) {
        let b = b0 + u * (b1 - b0);
        for &(v, wv) in rules.get(n) {
            let t = t0 + v * (t1 - t0);
            out.push((s.point(b, t), wu * wv * (b1 - b0) * (t1 - t0) * b.sin(), b, t));
        }
    }
    out
}

pub(crate) fn far_rule(s: &Surface, rules: &Rules, p: &Panel) -> FarRule {
    let r = (p.b0, p.b1, p.t0, p.t1);
    let strip = |v: Vec<([f64; 3], f64, f64, f64)>| v.into_iter().map(|(x, w, _, _)| (x, w)).collect();
    FarRule { two: strip(tensor_points(s, rules, 2, r)), three: strip(tensor_points(s, rules, 3, r)) }
}

/// ∫ G(x, y) sinβ dβ dθ over panel `p` for a target `x`; `self_panel` when x is its collocation point.
pub(crate) fn panel_integral(
    s: &Surface,
    rules: &Rules,
    p: &Panel,
    far: &FarRule,
    x: &[f64; 3],
    self_panel: bool,
    acc: &mut Sym,
) {
    if self_panel {
        singular(s, rules, p, acc);
        return;
    }
    let ratio = dist(x, &p.centre) / p.size;
    if ratio >= FAR_2 {
        for (y, w) in &far.two {
            add_stokeslet(x, y, *w, acc);
        }
    } else if ratio >= FAR_3 {
        for (y, w) in &far.three {
            add_stokeslet(x, y, *w, acc);
        }
    } else {
        adaptive(s, rules, x, (p.b0, p.b1, p.t0, p.t1), 0, acc);
    }
}

/// Diameter of a parameter rectangle and its chords along β and θ through the centre.
fn geometry(s: &Surface, (b0, b1, t0, t1): (f64, f64, f64, f64)) -> ([f64; 3], f64, f64, f64) {
    let (bm, tm) = (0.5 * (b0 + b1), 0.5 * (t0 + t1));
    let c = s.point(bm, tm);
    let (pb0, pb1, pt0, pt1) = (s.point(b0, tm), s.point(b1, tm), s.point(bm, t0), s.point(bm, t1));
    let mut size = dist(&c, &pb0).max(dist(&c, &pb1)).max(dist(&c, &pt0)).max(dist(&c, &pt1));
    for (bb, tt) in [(b0, t0), (b0, t1), (b1, t0), (b1, t1)] {
        size = size.max(dist(&c, &s.point(bb, tt)));
    }
    (c, 2.0 * size, dist(&pb0, &pb1), dist(&pt0, &pt1))
}

fn adaptive(s: &Surface, rules: &Rules, x: &[f64; 3], r: (f64, f64, f64, f64), depth: usize, acc: &mut Sym) {
    let (c, size, lb, lt) = geometry(s, r);
    let ratio = dist(x, &c) / size;
    let n = if ratio >= FAR_2 {
        2
    } else if ratio >= FAR_3 {
        3
    } else if ratio >= FAR_6 || depth >= MAX_DEPTH {
        6
    } else {
        0
    };
    if n > 0 {
        for (y, w, _, _) in tensor_points(s, rules, n, r) {
            add_stokeslet(x, &y, w, acc);
        }
        return;
    }
    let (b0, b1, t0, t1) = r;
    if lb >= lt {
        let bm = 0.5 * (b0 + b1);
        adaptive(s, rules, x, (b0, bm, t0, t1), depth + 1, acc);
        adaptive(s, rules, x, (bm, b1, t0, t1), depth + 1, acc);
    } else {
        let tm = 0.5 * (t0 + t1);
        adaptive(s, rules, x, (b0, b1, t0, tm), depth + 1, acc);
        adaptive(s, rules, x, (b0, b1, tm, t1), depth + 1, acc);
    }
}

/// The panel's own collocation point (its parameter centre): the panel is cut into near-square
/// cells (an odd number along its long side, so the centre is the middle of the middle cell); the
/// middle cell is split at the point into four rectangles, each integrated by a Duffy transform
/// (which cancels the 1/r singularity), the other cells adaptively.
fn singular(s: &Surface, rules: &Rules, p: &Panel, acc: &mut Sym) {
    let x = p.centre;
    let (_, _, lb, lt) = geometry(s, (p.b0, p.b1, p.t0, p.t1));
    let odd = |q: f64| -> usize {
        let k = (q.round() as usize).clamp(1, MAX_CELLS);
        if k & 1 == 1 {
            k
        } else {
            k + 1
        }
    };
    let (kb, kt) = if lb >= lt { (odd(lb / lt.max(1e-300)), 1) } else { (1, odd(lt / lb.max(1e-300))) };
    let (db, dt) = ((p.b1 - p.b0) / kb as f64, (p.t1 - p.t0) / kt as f64);
    for i in 0..kb {
        for j in 0..kt {
            let r =
                (p.b0 + i as f64 * db, p.b0 + (i + 1) as f64 * db, p.t0 + j as f64 * dt, p.t0 + (j + 1) as f64 * dt);
            if 2 * i + 1 == kb && 2 * j + 1 == kt {
                continue;
            }
            adaptive(s, rules, &x, r, 0, acc);
        }
    }
    let (bm, tm) = (0.5 * (p.b0 + p.b1), 0.5 * (p.t0 + p.t1));
    let (hb, ht) = (0.5 * db, 0.5 * dt);
    let g = rules.get(DUFFY_N);
    for (sb, st) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
        let (du, dv) = (sb * hb, st * ht);
        let area = (du * dv).abs();
        for &(a, wa) in g {
            for &(b, wb) in g {
                let w = wa * wb * a * area;
                // two triangles of the rectangle with the singular corner at (bm, tm)
                for (u, v) in [(bm + a * du, tm + a * b * dv), (bm + a * b * du, tm + a * dv)] {
                    add_stokeslet(&x, &s.point(u, v), w * u.sin(), acc);
                }
            }
        }
    }
}
