//! Clutter (wall) filter: polynomial regression high-pass over slow time (Hoeks et al. 1991;
//! Kadi & Loupas 1995; MUST `wfilt(…, 'poly', n)`, which PyMUST 0.1.9 ships broken).
//!
//! Each pixel's slow-time signal is projected on the polynomials of degree ≤ `order` over the
//! packet (an orthonormal basis built by modified Gram–Schmidt, twice, in f64) and the
//! projection is subtracted: order 0 removes the mean, order 1 also a linear drift, …
//! A signal that is a polynomial of degree ≤ order is removed exactly (to rounding).

use num_complex::Complex;

use sonoflow_beamform::error::{check_len, invalid, Result};
use sonoflow_beamform::C32;

/// Polynomial-regression clutter filter for packets of `n_frames`.
#[derive(Clone, Debug)]
pub struct ClutterFilter {
    order: usize,
    n_frames: usize,
    /// `(order + 1) × n_frames` orthonormal rows.
    basis: Vec<f64>,
}

impl ClutterFilter {
    /// Filter removing polynomials of degree ≤ `order` from packets of `n_frames`.
    /// Errors: `order ≥ n_frames − 1` (nothing would be left) or `order > 16`.
    pub fn new(order: usize, n_frames: usize) -> Result<Self> {
        if !(2..=1 << 16).contains(&n_frames) {
            return Err(invalid("clutter.n_frames", n_frames, "in [2, 65536]"));
        }
        if order > 16 || order + 1 >= n_frames {
            return Err(invalid("clutter.order", order, "in [0, 16] and < n_frames − 1"));
        }
        let n = n_frames;
        let t: Vec<f64> = (0..n).map(|k| 2.0 * k as f64 / (n - 1) as f64 - 1.0).collect();
        let mut basis = vec![0.0; (order + 1) * n];
        for d in 0..=order {
            let mut v: Vec<f64> = t.iter().map(|x| x.powi(d as i32)).collect();
            for _ in 0..2 {
                for q in 0..d {
                    let row = &basis[q * n..(q + 1) * n];
                    let dot: f64 = row.iter().zip(&v).map(|(a, b)| a * b).sum();
                    for (vi, r) in v.iter_mut().zip(row) {
                        *vi -= dot * r;
                    }
                }
            }
            let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            for (b, x) in basis[d * n..(d + 1) * n].iter_mut().zip(&v) {
                *b = x / norm;
            }
        }
        Ok(Self { order, n_frames, basis })
    }

    /// Polynomial order removed.
    pub fn order(&self) -> usize {
        self.order
    }

    fn filter_pixel(&self, x: &mut [Complex<f64>]) {
        let n = self.n_frames;
        let mut proj = vec![Complex::new(0.0, 0.0); n];
        for d in 0..=self.order {
            let row = &self.basis[d * n..(d + 1) * n];
            let c: Complex<f64> = row.iter().zip(x.iter()).map(|(r, v)| v * r).sum();
            for (p, r) in proj.iter_mut().zip(row) {
                *p += c * r;
            }
        }
        for (v, p) in x.iter_mut().zip(&proj) {
            *v -= p;
        }
    }

    /// Filters a packet given as one mutable slice per frame (all of the same length).
    pub fn apply_frames(&self, frames: &mut [&mut [C32]]) -> Result<()> {
        check_len("clutter frames", frames.len(), self.n_frames)?;
        let n_pix = frames.first().map_or(0, |f| f.len());
        for f in frames.iter() {
            check_len("clutter frame", f.len(), n_pix)?;
        }
        let mut x = vec![Complex::new(0.0f64, 0.0); self.n_frames];
        for p in 0..n_pix {
            for (xi, f) in x.iter_mut().zip(frames.iter()) {
                *xi = Complex::new(f64::from(f[p].re), f64::from(f[p].im));
            }
            self.filter_pixel(&mut x);
            for (xi, f) in x.iter().zip(frames.iter_mut()) {
                f[p] = C32::new(xi.re as f32, xi.im as f32);
            }
        }
        Ok(())
    }

    /// Filters a MUST-layout packet `data[pixel·n_frames + n]`.
    pub fn apply_pixel_major(&self, data: &mut [C32]) -> Result<()> {
        if !data.len().is_multiple_of(self.n_frames) {
            return Err(invalid("clutter packet length", data.len(), "a multiple of n_frames"));
        }
        let mut x = vec![Complex::new(0.0f64, 0.0); self.n_frames];
        for px in data.chunks_mut(self.n_frames) {
            for (xi, v) in x.iter_mut().zip(px.iter()) {
                *xi = Complex::new(f64::from(v.re), f64::from(v.im));
            }
            self.filter_pixel(&mut x);
            for (xi, v) in x.iter().zip(px.iter_mut()) {
                *v = C32::new(xi.re as f32, xi.im as f32);
            }
        }
        Ok(())
    }
}
