//! Clutter (wall) filters over slow time, chosen by [`ClutterParams`] (the Doppler stage's
//! `clutter` table): polynomial regression ([`ClutterFilter`], below), a Butterworth IIR
//! high-pass ([`crate::iir`]) or the SVD of the Casorati matrix ([`crate::svd`]).
//!
//! Polynomial regression high-pass (Hoeks et al. 1991; Kadi & Loupas 1995; MUST
//! `wfilt(…, 'poly', n)`, which PyMUST 0.1.9 ships broken).
//!
//! Each pixel's slow-time signal is projected on the polynomials of degree ≤ `order` over the
//! packet (an orthonormal basis built by modified Gram–Schmidt, twice, in f64) and the
//! projection is subtracted: order 0 removes the mean, order 1 also a linear drift, …
//! A signal that is a polynomial of degree ≤ order is removed exactly (to rounding).

use num_complex::Complex;
use serde::{Deserialize, Serialize};

use crate::iir::{IirHighPass, IirInit};
use crate::svd::{SvdFilter, SvdRank};

use crate::slowtime::for_each_pixel;
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
        for_each_pixel(frames, |x| self.filter_pixel(x))
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

/// Which clutter filter, and its parameters (`clutter = { type = "…", … }`).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ClutterParams {
    /// Polynomial regression: removes polynomials of degree ≤ `order` (0 ..= 8) over the packet.
    Polynomial {
        /// Degree removed (0 = the mean).
        order: usize,
    },
    /// Butterworth high-pass of order `order` (1 ..= 8) with cut-off `cutoff` (fraction of the
    /// PRF, 0 < f_c < 0.5) and initialisation `init` (`step`, the default, or `zero`).
    Iir {
        /// Filter order.
        order: usize,
        /// Cut-off, fraction of the PRF.
        cutoff: f64,
        /// Initial state.
        #[serde(default)]
        init: IirInit,
    },
    /// SVD of the Casorati matrix: `rank = r` removes r components; without `rank`, adaptive
    /// with `tissue_cutoff` (fraction of the PRF, default 0.05), `max_rank` and the energy gap
    /// `gap_db` (default 10 dB; 0 = the frequency rule alone; see [`crate::svd`]).
    Svd {
        /// Fixed rank (absent: adaptive).
        rank: Option<usize>,
        /// Adaptive rank: largest |frequency| of a tissue component, fraction of the PRF.
        #[serde(default = "default_tissue_cutoff")]
        tissue_cutoff: f64,
        /// Adaptive rank: upper bound (absent: ⌈frames/2⌉).
        max_rank: Option<usize>,
        /// Adaptive rank: energy drop (dB, 0 ..= 100) that ends the tissue subspace; 0 = none.
        #[serde(default = "default_gap_db")]
        gap_db: f64,
    },
}

fn default_tissue_cutoff() -> f64 {
    0.05
}

/// 10 dB: on the clutter carotid the tissue's components stand 13–50 dB above the next, while
/// the blood's decay by 2–6 dB from one to the next (docs/nodes.md, "Why `gap_db`").
fn default_gap_db() -> f64 {
    10.0
}

/// Ids of the clutter filters in wire headers and reports.
pub mod kind {
    /// No clutter filter.
    pub const NONE: u32 = 0;
    /// Polynomial regression.
    pub const POLYNOMIAL: u32 = 1;
    /// Butterworth IIR high-pass.
    pub const IIR: u32 = 2;
    /// SVD (Casorati matrix).
    pub const SVD: u32 = 3;
}

/// What the clutter filter did to one packet.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ClutterReport {
    /// [`kind`] of the filter.
    pub kind: u32,
    /// Polynomial degree or IIR order; the SVD rank removed.
    pub order_or_rank: usize,
    /// IIR cut-off or the SVD tissue cut-off (fraction of the PRF); 0 otherwise.
    pub cutoff: f64,
    /// SVD: fraction of the packet's energy removed; 0 otherwise.
    pub removed_energy: f64,
}

impl ClutterParams {
    /// Checks every field (errors name it); the packet size is checked when filtering.
    pub fn validate(&self) -> Result<()> {
        match *self {
            ClutterParams::Polynomial { order } if order > 8 => {
                Err(invalid("clutter.order", order, "in 0 ..= 8 (and below the packet size − 1)"))
            }
            ClutterParams::Polynomial { .. } => Ok(()),
            ClutterParams::Iir { order, cutoff, init } => IirHighPass::new(order, cutoff, init).map(|_| ()),
            ClutterParams::Svd { .. } => self.svd().map(|_| ()),
        }
    }

    fn svd(&self) -> Result<SvdFilter> {
        let ClutterParams::Svd { rank, tissue_cutoff, max_rank, gap_db } = *self else {
            return Err(invalid("clutter.type", "not svd", "svd"));
        };
        if !(gap_db.is_finite() && (0.0..=100.0).contains(&gap_db)) {
            return Err(invalid("clutter.gap_db", gap_db, "in 0 ..= 100 dB (0: the frequency rule alone)"));
        }
        let gap_db = (gap_db > 0.0).then_some(gap_db);
        SvdFilter::new(match rank {
            Some(r) => SvdRank::Fixed(r),
            None => SvdRank::Adaptive { tissue_cutoff, max_rank, gap_db },
        })
    }

    /// [`Self::apply_frames`], and the filter as the slow-time matrix it applied to every pixel
    /// (`n × n` for `n` frames, row-major, `y_t = Σ_j H[t·n + j] x_j`; every filter here is linear
    /// in slow time): the SVD's from its removed components, the polynomial and IIR filters' by
    /// filtering the n unit impulses. What [`crate::compensate`] needs.
    pub fn apply_frames_with_response(&self, frames: &mut [&mut [C32]]) -> Result<(ClutterReport, Vec<Complex<f64>>)> {
        let n = frames.len();
        if let ClutterParams::Svd { tissue_cutoff, rank, .. } = *self {
            let o = self.svd()?.apply_frames(frames)?;
            let cutoff = if rank.is_some() { 0.0 } else { tissue_cutoff };
            let report =
                ClutterReport { kind: kind::SVD, order_or_rank: o.rank, cutoff, removed_energy: o.removed_energy };
            return Ok((report, o.slow_time_matrix(n)));
        }
        let report = self.apply_frames(frames)?;
        // pixel j of the impulse packet is the unit impulse at frame j
        let mut impulses: Vec<Vec<C32>> =
            (0..n).map(|t| (0..n).map(|j| C32::new(if t == j { 1.0 } else { 0.0 }, 0.0)).collect()).collect();
        let mut refs: Vec<&mut [C32]> = impulses.iter_mut().map(|f| f.as_mut_slice()).collect();
        self.apply_frames(&mut refs)?;
        let h = (0..n * n).map(|i| impulses[i / n][i % n]).map(|v| Complex::new(f64::from(v.re), f64::from(v.im)));
        Ok((report, h.collect()))
    }

    /// Filters a packet in MUST's pixel-major layout (`data[pixel·n_frames + frame]`) in place.
    pub fn apply_pixel_major(&self, data: &mut [C32], n_frames: usize) -> Result<ClutterReport> {
        let n_pix = data.len() / n_frames.max(1);
        let mut frames: Vec<Vec<C32>> =
            (0..n_frames).map(|t| (0..n_pix).map(|p| data[p * n_frames + t]).collect()).collect();
        let mut refs: Vec<&mut [C32]> = frames.iter_mut().map(|f| f.as_mut_slice()).collect();
        let report = self.apply_frames(&mut refs)?;
        for (t, f) in frames.iter().enumerate() {
            for (p, v) in f.iter().enumerate() {
                data[p * n_frames + t] = *v;
            }
        }
        Ok(report)
    }

    /// Filters a packet given as one mutable slice per frame.
    pub fn apply_frames(&self, frames: &mut [&mut [C32]]) -> Result<ClutterReport> {
        match *self {
            ClutterParams::Polynomial { order } => {
                ClutterFilter::new(order, frames.len())?.apply_frames(frames)?;
                Ok(ClutterReport { kind: kind::POLYNOMIAL, order_or_rank: order, ..Default::default() })
            }
            ClutterParams::Iir { order, cutoff, init } => {
                IirHighPass::new(order, cutoff, init)?.apply_frames(frames)?;
                Ok(ClutterReport { kind: kind::IIR, order_or_rank: order, cutoff, removed_energy: 0.0 })
            }
            ClutterParams::Svd { tissue_cutoff, rank, .. } => {
                let o = self.svd()?.apply_frames(frames)?;
                let cutoff = if rank.is_some() { 0.0 } else { tissue_cutoff };
                Ok(ClutterReport { kind: kind::SVD, order_or_rank: o.rank, cutoff, removed_energy: o.removed_energy })
            }
        }
    }
}
