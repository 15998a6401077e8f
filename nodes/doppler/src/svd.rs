//! SVD clutter (wall) filter (Demené et al. 2015, IEEE TMI 34:2271–2285): the packet as a
//! Casorati matrix S (pixels × frames). Its right singular vectors are the eigenvectors of the
//! frames × frames correlation C = Sᴴ S (faer's self-adjoint eigendecomposition, in f64), the
//! singular values σ_k = √λ_k. Tissue is spatially coherent and slow, so it fills the leading
//! (largest-energy) components; the filter removes the r leading ones: S ← S (I − V_r V_rᴴ).
//!
//! **Rank.** Fixed (`rank = r`, 1 ≤ r < frames), or adaptive (the default): a leading component
//! counts as tissue while the mean Doppler frequency of its temporal singular vector (the phase of
//! its lag-1 autocorrelation, in cycles per frame) is at most `tissue_cutoff` in magnitude; r is
//! the number of leading components, in decreasing energy, before the first faster one — the
//! singular-vector frequency criterion of Baranger et al. 2018 (IEEE TMI 37:1574), in its
//! simplest form. The adaptive rank is at most `max_rank` (default ⌈frames/2⌉, and always below
//! the packet size: the filter never removes everything).
//!
//! **Energy gap** (`gap_db`; the Doppler stage's `clutter` table sets 10 dB unless told 0). Slow blood (flow nearly across the beam) has slow
//! singular vectors too, so the frequency rule alone also removes blood whenever the tissue is
//! slow enough to leave room below the cut-off. Tissue echoes are tens of dB stronger than blood,
//! so the tissue components stand above the blood's and the noise's in energy, separated by a
//! drop: with `gap_db = g`, the rank from the frequency rule is cut back to just after the
//! *last* drop of at least g dB between consecutive singular values σ_k² / σ_{k+1}² among the
//! components it would remove (the drop to the first component kept counts). Where there is no
//! such drop (no tissue above the blood, or tissue whose spectrum falls off smoothly), the rank
//! is 0 — nothing stands out as tissue, nothing is removed.

use faer::{Mat, Side};
use num_complex::Complex;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sonoflow_beamform::error::{check_len, invalid, BeamformError, Result};
use sonoflow_beamform::C32;

/// How many components the SVD filter removes.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq)]
#[serde(untagged)]
pub enum SvdRank {
    /// Exactly this many (1 ≤ r < frames).
    Fixed(usize),
    /// Chosen per packet (see the module doc).
    Adaptive {
        /// Largest |mean frequency| of a tissue component, as a fraction of the PRF (0 < c < 0.5).
        tissue_cutoff: f64,
        /// Upper bound of the rank (absent: ⌈frames/2⌉).
        max_rank: Option<usize>,
        /// Energy gap (dB, > 0) that ends the tissue subspace (absent: frequency rule alone).
        gap_db: Option<f64>,
    },
}

/// The rank ≤ `slow` just after the last drop of at least `gap_db` between consecutive energies
/// σ_k² / σ_{k+1}² (k < slow), or 0 without such a drop. A zero singular value after a nonzero
/// one is an infinite drop; two zeros are none.
fn last_gap(singular_values: &[f64], slow: usize, gap_db: f64) -> usize {
    let ratio = 10f64.powf(gap_db / 10.0);
    (0..slow.min(singular_values.len().saturating_sub(1)))
        .rev()
        .find(|&k| {
            let (a, b) = (singular_values[k] * singular_values[k], singular_values[k + 1] * singular_values[k + 1]);
            a > 0.0 && a >= ratio * b
        })
        .map_or(0, |k| k + 1)
}

/// What one packet's SVD filtering did.
#[derive(Clone, Debug, PartialEq)]
pub struct SvdOutcome {
    /// Components removed.
    pub rank: usize,
    /// Singular values, largest first.
    pub singular_values: Vec<f64>,
    /// Mean frequency (cycles per frame) of each component's temporal singular vector, same order.
    pub frequencies: Vec<f64>,
    /// Fraction of the packet's energy removed, Σ_{k<r} σ_k² / Σ σ_k².
    pub removed_energy: f64,
    /// The removed components' eigenvectors v_k (frames long, orthonormal), largest first: each
    /// pixel's slow time x became x − Σ_k (v_kᵀ x) conj(v_k).
    pub removed: Vec<Vec<Complex<f64>>>,
}

impl SvdOutcome {
    /// The filter as a slow-time matrix H (`n × n`, row-major, `y_t = Σ_j H[t·n + j] x_j`):
    /// H = I − Σ_k conj(v_k) v_kᵀ.
    pub fn slow_time_matrix(&self, n: usize) -> Vec<Complex<f64>> {
        let mut h = vec![Complex::new(0.0, 0.0); n * n];
        for t in 0..n {
            h[t * n + t] = Complex::new(1.0, 0.0);
        }
        for v in &self.removed {
            for t in 0..n {
                for j in 0..n {
                    h[t * n + j] -= v[t].conj() * v[j];
                }
            }
        }
        h
    }
}

/// The SVD clutter filter (see the module doc).
#[derive(Clone, Debug)]
pub struct SvdFilter {
    rank: SvdRank,
}

impl SvdFilter {
    /// Checks the rank rule (a fixed rank is checked against the packet at [`Self::apply_frames`]).
    pub fn new(rank: SvdRank) -> Result<Self> {
        match rank {
            SvdRank::Fixed(0) => return Err(invalid("clutter.rank", 0, "≥ 1 (or absent: adaptive)")),
            SvdRank::Adaptive { tissue_cutoff, max_rank, gap_db } => {
                if let Some(g) = gap_db {
                    if !(g.is_finite() && g > 0.0 && g <= 100.0) {
                        return Err(invalid("clutter.gap_db", g, "in (0, 100] dB"));
                    }
                }
                if !(tissue_cutoff.is_finite() && tissue_cutoff > 0.0 && tissue_cutoff < 0.5) {
                    return Err(invalid("clutter.tissue_cutoff", tissue_cutoff, "a fraction of the PRF in (0, 0.5)"));
                }
                if max_rank == Some(0) {
                    return Err(invalid("clutter.max_rank", 0, "≥ 1"));
                }
            }
            SvdRank::Fixed(_) => {}
        }
        Ok(Self { rank })
    }

    /// Filters a packet given as one mutable slice per frame (all of the same length).
    /// Errors: fewer than 2 frames, a fixed rank ≥ the packet size, non-finite samples.
    pub fn apply_frames(&self, frames: &mut [&mut [C32]]) -> Result<SvdOutcome> {
        let n = frames.len();
        if n < 2 {
            return Err(invalid("clutter packet size", n, "≥ 2 frames for the SVD filter"));
        }
        if let SvdRank::Fixed(r) = self.rank {
            if r >= n {
                return Err(BeamformError::ConfigMismatch {
                    what: format!("clutter.rank = {r} would remove the whole packet of {n} frames: use a rank < {n}"),
                });
            }
        }
        let n_pix = frames[0].len();
        for f in frames.iter() {
            check_len("clutter frame", f.len(), n_pix)?;
            if f.iter().any(|v| !(v.re.is_finite() && v.im.is_finite())) {
                return Err(invalid("clutter input", "non-finite I/Q", "finite samples for the SVD filter"));
            }
        }
        // C = Sᴴ S, upper triangle by rows in parallel.
        let rows: Vec<Vec<Complex<f64>>> = (0..n)
            .into_par_iter()
            .map(|i| {
                (i..n)
                    .map(|j| {
                        frames[i].iter().zip(frames[j].iter()).fold(Complex::new(0.0, 0.0), |acc, (a, b)| {
                            acc + Complex::new(f64::from(a.re), -f64::from(a.im))
                                * Complex::new(f64::from(b.re), f64::from(b.im))
                        })
                    })
                    .collect()
            })
            .collect();
        let c = Mat::from_fn(n, n, |i, j| if i <= j { rows[i][j - i] } else { rows[j][i - j].conj() });
        let evd = c
            .self_adjoint_eigen(Side::Lower)
            .map_err(|_| BeamformError::ConfigMismatch { what: "clutter: the SVD did not converge".into() })?;
        let (u, s) = (evd.U(), evd.S().column_vector());
        // Components by decreasing energy (faer sorts eigenvalues increasingly).
        let order: Vec<usize> = (0..n).rev().collect();
        let singular_values: Vec<f64> = order.iter().map(|&k| s[k].re.max(0.0).sqrt()).collect();
        let frequencies: Vec<f64> = order
            .iter()
            .map(|&k| {
                let r1: Complex<f64> = (0..n - 1).map(|t| u[(t + 1, k)] * u[(t, k)].conj()).sum();
                // the temporal waveform is the conjugate of the eigenvector: its frequency is −arg/2π
                -r1.arg() / std::f64::consts::TAU
            })
            .collect();
        let rank = match self.rank {
            SvdRank::Fixed(r) => r,
            SvdRank::Adaptive { tissue_cutoff, max_rank, gap_db } => {
                let cap = max_rank.unwrap_or(n.div_ceil(2)).min(n - 1);
                let slow = frequencies.iter().take(cap).take_while(|f| f.abs() <= tissue_cutoff).count();
                match gap_db {
                    None => slow,
                    Some(g) => last_gap(&singular_values, slow, g),
                }
            }
        };
        let total: f64 = singular_values.iter().map(|v| v * v).sum();
        let removed: f64 = singular_values[..rank].iter().map(|v| v * v).sum();
        let v: Vec<Vec<Complex<f64>>> = order[..rank].iter().map(|&k| (0..n).map(|t| u[(t, k)]).collect()).collect();
        if rank > 0 {
            crate::slowtime::for_each_pixel(frames, |x| {
                for vk in &v {
                    let c: Complex<f64> = x.iter().zip(vk).map(|(a, b)| a * b).sum();
                    for (xi, b) in x.iter_mut().zip(vk) {
                        *xi -= c * b.conj();
                    }
                }
            })?;
        }
        let removed_energy = if total > 0.0 { removed / total } else { 0.0 };
        Ok(SvdOutcome { rank, singular_values, frequencies, removed_energy, removed: v })
    }
}
