//! Exact Euclidean nearest-valid-point transform on an N-D grid (the feature transform of
//! MATLAB `bwdist` / SciPy `distance_transform_edt`), used for the nearest-neighbour fill of the
//! initial guess. Separable algorithm of Felzenszwalb & Huttenlocher (2012, "Distance transforms of
//! sampled functions", Theory of Computing 8:415-428): one lower envelope of parabolas per grid
//! line and axis, O(N · points), carrying the index of the nearest valid point along.

/// Reusable buffers (grid-sized and line-sized).
#[derive(Default)]
pub(crate) struct Nearest {
    dist: Vec<f64>,
    feat: Vec<usize>,
    g: Vec<f64>,
    gf: Vec<usize>,
    v: Vec<usize>,
    z: Vec<f64>,
}

impl Nearest {
    /// After the call, `self.nearest()[p]` is the flat index of a valid point closest to `p`
    /// (Euclidean distance in index units; ties resolved by the envelope order). Needs at least one
    /// valid point.
    pub(crate) fn compute(&mut self, shape: &[usize], valid: &[bool]) {
        let len = valid.len();
        let max_n = shape.iter().copied().max().unwrap_or(1);
        self.dist.resize(len, 0.0);
        self.feat.resize(len, 0);
        self.g.resize(max_n, 0.0);
        self.gf.resize(max_n, 0);
        self.v.resize(max_n, 0);
        self.z.resize(max_n + 1, 0.0);
        for (p, ((d, f), ok)) in self.dist.iter_mut().zip(self.feat.iter_mut()).zip(valid).enumerate() {
            *d = if *ok { 0.0 } else { f64::INFINITY };
            *f = p;
        }
        let mut stride = 1;
        for a in (0..shape.len()).rev() {
            let n = shape[a];
            if n > 1 {
                let outer = len / (n * stride);
                for o in 0..outer {
                    for i in 0..stride {
                        self.line(o * n * stride + i, stride, n);
                    }
                }
            }
            stride *= n;
        }
    }

    /// Bytes held.
    pub(crate) fn bytes(&self) -> usize {
        (self.dist.capacity() + self.g.capacity() + self.z.capacity()) * std::mem::size_of::<f64>()
            + (self.feat.capacity() + self.gf.capacity() + self.v.capacity()) * std::mem::size_of::<usize>()
    }

    /// Nearest valid flat index of every point (valid after [`Self::compute`]).
    pub(crate) fn nearest(&self) -> &[usize] {
        &self.feat
    }

    /// Lower envelope of the parabolas `(p − q)² + g[q]` along one line (start `base`, `stride`).
    fn line(&mut self, base: usize, stride: usize, n: usize) {
        let Self { dist, feat, g, gf, v, z } = self;
        for q in 0..n {
            g[q] = dist[base + q * stride];
            gf[q] = feat[base + q * stride];
        }
        let Some(first) = (0..n).find(|&q| g[q].is_finite()) else {
            return;
        };
        let key = |q: usize, g: &[f64]| g[q] + (q * q) as f64;
        let mut k = 0usize;
        v[0] = first;
        z[0] = f64::NEG_INFINITY;
        z[1] = f64::INFINITY;
        for q in first + 1..n {
            if !g[q].is_finite() {
                continue;
            }
            let mut s;
            loop {
                let r = v[k];
                s = (key(q, g) - key(r, g)) / (2.0 * (q as f64 - r as f64));
                if s <= z[k] && k > 0 {
                    k -= 1;
                } else {
                    break;
                }
            }
            // With k = 0 and s ≤ z[0] = −∞ impossible, so the new parabola always enters here.
            k += 1;
            v[k] = q;
            z[k] = s;
            z[k + 1] = f64::INFINITY;
        }
        let mut k = 0usize;
        for p in 0..n {
            while z[k + 1] < p as f64 {
                k += 1;
            }
            let r = v[k];
            let dp = p as f64 - r as f64;
            dist[base + p * stride] = dp * dp + g[r];
            feat[base + p * stride] = gf[r];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn coords(mut p: usize, shape: &[usize]) -> Vec<usize> {
        let mut c = vec![0; shape.len()];
        for a in (0..shape.len()).rev() {
            c[a] = p % shape[a];
            p /= shape[a];
        }
        c
    }

    fn d2(a: &[usize], b: &[usize]) -> usize {
        a.iter().zip(b).map(|(x, y)| x.abs_diff(*y).pow(2)).sum()
    }

    #[test]
    fn nearest_valid_point_has_the_brute_force_distance() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for shape in [vec![17], vec![9, 13], vec![5, 6, 7], vec![1, 12], vec![8, 1]] {
            let len: usize = shape.iter().product();
            for density in [0.05, 0.3, 0.9] {
                let mut valid: Vec<bool> = (0..len).map(|_| rng.gen_bool(density)).collect();
                valid[len / 2] = true;
                let mut nn = Nearest::default();
                nn.compute(&shape, &valid);
                for p in 0..len {
                    let best = (0..len).filter(|&q| valid[q]).map(|q| d2(&coords(p, &shape), &coords(q, &shape))).min();
                    let got = nn.nearest()[p];
                    assert!(valid[got], "shape {shape:?}: point {p} mapped to invalid {got}");
                    assert_eq!(Some(d2(&coords(p, &shape), &coords(got, &shape))), best, "shape {shape:?}, point {p}");
                }
            }
        }
    }
}
