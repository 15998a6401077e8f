//! Vector Doppler: (vx, vz) per pixel by least squares on the projection geometry
//! (Shahriari & Garcia 2018 eq. 20; Yiu et al. 2014; Jensen et al. 2016 eq. 4).
//!
//! A Doppler velocity measured with transmit direction θt and receive direction θr (angles from
//! the z axis, positive towards +x) is the projection of the velocity on the bisector:
//! `v_D = a·v`, `a = −(sin θt + sin θr, cos θt + cos θr)/2` with v_D positive toward the probe
//! (MUST's sign, [`crate::estimator`]). Derivation: the round-trip delay of a scatterer at p is
//! `τ = (d_TX + d_RX)/c`; moving it by v·T changes τ by `(û_t + û_r)·v T/c` where û_t = (sin θt,
//! cos θt) is the transmit propagation direction and û_r = (sin θr, cos θr) the direction from
//! the receive aperture to p; v_D = −c Δτ/(2T).
//!
//! With J ≥ 2 angles the per-pixel normal equations `(AᵀA) v = Aᵀ v_D` are solved (J = 2 is the
//! exact solve). For θt = 0 and θr = ±φ this gives `vx = (v_D(−φ) − v_D(+φ))/sin φ`,
//! `vz = −(v_D(−φ) + v_D(+φ))/(1 + cos φ)`, i.e. the paper's eq. 20 with its Doppler values of
//! the opposite sign (paper: positive = away from the probe along the bisector, +z downwards).
//! The per-pixel projections of a [`sonoflow_beamform::DasPlan`] ([`sonoflow_beamform::DasPlan::projection`]) account
//! for the actual (possibly clipped) aperture; the nominal ones assume an ideal plane wave.

use crate::estimator::flags;
use sonoflow_beamform::error::{check_len, invalid, BeamformError, Result};

/// Projection vector `a` for transmit tilt `tx_tilt` and receive angle `rx_angle` (rad).
pub fn nominal_projection(tx_tilt: f64, rx_angle: f64) -> [f64; 2] {
    [-(tx_tilt.sin() + rx_angle.sin()) / 2.0, -(tx_tilt.cos() + rx_angle.cos()) / 2.0]
}

/// The projection geometry of one Doppler map.
#[derive(Clone, Copy, Debug)]
pub enum Projection<'a> {
    /// Ideal plane-wave geometry, the same for every pixel.
    Nominal {
        /// Transmit tilt (rad).
        tx_tilt: f64,
        /// Receive angle (rad).
        rx_angle: f64,
    },
    /// One vector per pixel (e.g. [`sonoflow_beamform::DasPlan::projection`]).
    PerPixel(&'a [[f32; 2]]),
}

impl Projection<'_> {
    /// The nominal vector of a `Nominal` geometry ([0, 0] for per-pixel ones: unused).
    fn nominal(&self) -> [f64; 2] {
        match *self {
            Projection::Nominal { tx_tilt, rx_angle } => nominal_projection(tx_tilt, rx_angle),
            Projection::PerPixel(_) => [0.0, 0.0],
        }
    }

    /// The projection vector at pixel `p`; `nominal` is this geometry's nominal vector (computed
    /// once per map by the caller).
    fn at(&self, p: usize, nominal: [f64; 2]) -> [f64; 2] {
        match self {
            Projection::Nominal { .. } => nominal,
            Projection::PerPixel(a) => [f64::from(a[p][0]), f64::from(a[p][1])],
        }
    }
}

/// One Doppler map entering the vector solve.
#[derive(Clone, Copy, Debug)]
pub struct VectorInput<'a> {
    /// Doppler velocity per pixel (m/s, positive toward the probe).
    pub velocity: &'a [f32],
    /// [`flags`] per pixel (pixels with NO_ESTIMATE are left out of the solve).
    pub flags: &'a [u8],
    /// Geometry.
    pub projection: Projection<'a>,
}

/// Result of the vector solve (row-major maps).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VectorField {
    /// Lateral velocity (m/s, +x).
    pub vx: Vec<f32>,
    /// Axial velocity (m/s, +z = deeper, away from the probe).
    pub vz: Vec<f32>,
    /// [`flags`]: NO_ESTIMATE when fewer than two usable maps or an ill-conditioned geometry
    /// (vx = vz = 0 then); ALIASING if any map used is flagged.
    pub flags: Vec<u8>,
}

/// Relative determinant below which the 2×2 normal matrix is considered singular.
const MIN_REL_DET: f64 = 1e-6;

/// Solves (vx, vz) for every pixel from `inputs` (all of the same length `n_pixels`).
pub fn solve_vector(inputs: &[VectorInput<'_>], out: &mut VectorField) -> Result<()> {
    solve_vector_weighted(inputs, &vec![1.0; inputs.len()], out)
}

/// [`solve_vector`] with one weight per Doppler map: the per-pixel normal equations
/// `(Aᵀ W A) v = Aᵀ W v_D`. The weight of a map is the inverse of its noise variance (relative);
/// e.g. maps demodulated at different frequencies `f` with equal phase noise have velocity noise
/// ∝ 1/f: weights ∝ f². Equal weights give [`solve_vector`] exactly.
pub fn solve_vector_weighted(inputs: &[VectorInput<'_>], weights: &[f64], out: &mut VectorField) -> Result<()> {
    let first = inputs.first().ok_or_else(|| invalid("vector inputs", 0, "at least two Doppler maps"))?;
    if inputs.len() < 2 {
        return Err(invalid("vector inputs", inputs.len(), "at least two Doppler maps"));
    }
    check_len("vector weights", weights.len(), inputs.len())?;
    if let Some(w) = weights.iter().find(|w| !(w.is_finite() && **w > 0.0 && **w <= 1e12)) {
        return Err(invalid("vector weights", w, "finite, in (0, 1e12]"));
    }
    let n = first.velocity.len();
    for inp in inputs {
        check_len("vector input velocity", inp.velocity.len(), n)?;
        check_len("vector input flags", inp.flags.len(), n)?;
        match inp.projection {
            Projection::PerPixel(a) => check_len("vector input projection", a.len(), n)?,
            Projection::Nominal { tx_tilt, rx_angle } => {
                if !(tx_tilt.is_finite() && rx_angle.is_finite()) {
                    return Err(BeamformError::InvalidParameter {
                        field: "vector projection angles",
                        value: format!("{tx_tilt}, {rx_angle}"),
                        allowed: "finite (rad)",
                    });
                }
            }
        }
    }
    out.vx.resize(n, 0.0);
    out.vz.resize(n, 0.0);
    out.flags.resize(n, 0);
    let nominal: Vec<[f64; 2]> = inputs.iter().map(|i| i.projection.nominal()).collect();
    for p in 0..n {
        let (mut a11, mut a12, mut a22, mut b1, mut b2) = (0.0f64, 0.0, 0.0, 0.0, 0.0);
        let (mut used, mut fl) = (0usize, 0u8);
        for ((inp, nom), &w) in inputs.iter().zip(&nominal).zip(weights) {
            let f = inp.flags[p];
            let v = f64::from(inp.velocity[p]);
            if f & flags::NO_ESTIMATE != 0 || !v.is_finite() {
                continue;
            }
            let a = inp.projection.at(p, *nom);
            a11 += w * a[0] * a[0];
            a12 += w * a[0] * a[1];
            a22 += w * a[1] * a[1];
            b1 += w * a[0] * v;
            b2 += w * a[1] * v;
            used += 1;
            fl |= f & flags::ALIASING;
        }
        let det = a11 * a22 - a12 * a12;
        let tr = a11 + a22;
        let well_posed = det > MIN_REL_DET * tr * tr;
        if used < 2 || !well_posed {
            out.vx[p] = 0.0;
            out.vz[p] = 0.0;
            out.flags[p] = flags::NO_ESTIMATE;
            continue;
        }
        out.vx[p] = ((a22 * b1 - a12 * b2) / det) as f32;
        out.vz[p] = ((a11 * b2 - a12 * b1) / det) as f32;
        out.flags[p] = fl;
    }
    Ok(())
}

/// Median over the pixels in `pixels` (with an estimate in look `i` and in the field solved from
/// the looks `set` without `i`) of look `i`'s residual |v_D − a·v| against that field (NaN: none).
fn leave_one_out_median(
    inputs: &[VectorInput<'_>],
    weights: &[f64],
    set: &[usize],
    i: usize,
    pixels: &[bool],
    field: &mut VectorField,
) -> Result<f64> {
    let rest: Vec<VectorInput> = set.iter().filter(|&&j| j != i).map(|&j| inputs[j]).collect();
    let rest_w: Vec<f64> = set.iter().filter(|&&j| j != i).map(|&j| weights[j]).collect();
    solve_vector_weighted(&rest, &rest_w, field)?;
    let inp = &inputs[i];
    let nom = inp.projection.nominal();
    let mut r: Vec<f64> = (0..pixels.len())
        .filter(|&p| {
            pixels[p]
                && inp.flags[p] & flags::NO_ESTIMATE == 0
                && field.flags[p] & flags::NO_ESTIMATE == 0
                && inp.velocity[p].is_finite()
        })
        .map(|p| {
            let a = inp.projection.at(p, nom);
            (f64::from(inp.velocity[p]) - a[0] * f64::from(field.vx[p]) - a[1] * f64::from(field.vz[p])).abs()
        })
        .collect();
    if r.is_empty() {
        return Ok(f64::NAN);
    }
    let mid = r.len() / 2;
    Ok(*r.select_nth_unstable_by(mid, f64::total_cmp).1)
}

/// Median of the finite values (NaN if none).
fn finite_median(v: &[f64]) -> f64 {
    let mut f: Vec<f64> = v.iter().copied().filter(|m| m.is_finite()).collect();
    if f.is_empty() {
        return f64::NAN;
    }
    let mid = f.len() / 2;
    *f.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// The looks that disagree with the others (look rejection of the vector solve). A look's
/// *residual* is the median over the pixels in `pixels` of |v_D − a·v| against the field solved
/// (with `weights`) from the other looks of the current set. Each round takes the look with the
/// largest residual and rejects it when that exceeds `factor` × the median residual of the
/// remaining looks among themselves (recomputed without it: a failed look pulls every field it
/// is part of toward itself and would inflate the yardstick); rounds go on while at least three
/// looks remain to judge by. Fewer than four looks: none rejected. Returns one flag per input
/// (true = leave it out) and the first round's residuals (m/s; NaN where a look has no usable
/// pixel).
pub fn outlier_looks(
    inputs: &[VectorInput<'_>],
    weights: &[f64],
    pixels: &[bool],
    factor: f64,
) -> Result<(Vec<bool>, Vec<f64>)> {
    if !(factor.is_finite() && factor > 1.0) {
        return Err(invalid("look_rejection", factor, "> 1 (or 0: off)"));
    }
    check_len("look rejection weights", weights.len(), inputs.len())?;
    let mut reject = vec![false; inputs.len()];
    let Some(first) = inputs.first() else { return Ok((reject, Vec::new())) };
    check_len("look rejection pixels", pixels.len(), first.velocity.len())?;
    let mut field = VectorField::default();
    let mut active: Vec<usize> = (0..inputs.len()).collect();
    let residuals = |set: &[usize], field: &mut VectorField| -> Result<Vec<f64>> {
        set.iter().map(|&i| leave_one_out_median(inputs, weights, set, i, pixels, field)).collect()
    };
    let mut first_round = Vec::new();
    while active.len() >= 4 {
        let meds = residuals(&active, &mut field)?;
        if first_round.is_empty() {
            first_round = meds.clone();
        }
        let Some(k) = (0..active.len()).filter(|&k| meds[k].is_finite()).max_by(|&a, &b| meds[a].total_cmp(&meds[b]))
        else {
            break;
        };
        let rest: Vec<usize> = active.iter().copied().filter(|&j| j != active[k]).collect();
        let typical = finite_median(&residuals(&rest, &mut field)?);
        // a NaN yardstick (no usable pixel in the rest) rejects nothing
        if meds[k].partial_cmp(&(factor * typical)) != Some(std::cmp::Ordering::Greater) {
            break;
        }
        reject[active[k]] = true;
        active = rest;
    }
    if first_round.is_empty() {
        first_round = vec![f64::NAN; inputs.len()];
    }
    Ok((reject, first_round))
}
