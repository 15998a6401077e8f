//! The coefficient networks as a [`CoefficientModel`]: paper 2's eq 18 scaling, its units and the
//! conversion to the SI coefficients of [`crate::coefficients`].
//!
//! **Paper units** (§4.3): length µm, speed µm/s, mass µg, viscosity μ = 3 µg/(µm·s)
//! (= 3 mPa·s). Force: µg·µm/s² = 1e-9 kg · 1e-6 m / s² = 1e-15 N ([`FORCE_UNIT`]); torque:
//! µg·µm²/s² = 1e-21 N·m ([`TORQUE_UNIT`]). The training flows have |δv| = 1 µm/s = 1e-6 m/s and
//! ω = 2π rad/s.
//!
//! **Networks.** N: (Lx, Ly, Lz \[µm\], α_top, α_bot, ψ \[rad\]) → (d, l, t_p); N_r and N_s:
//! (Lx, Ly, Lz \[µm\], α_top, α_bot) → t_r and N_s's target (below: the shape factor's g). ψ is reduced to [0, 2π), the range of the
//! training data (eq 14). A network stored with a mirror ([`super::mlp::Mirror`], the shipped
//! ones) predicts the average over the platelet and its mirror image, at twice the cost.
//!
//! **Eq 18** ([`unscale_translational`], [`scale_translational`]): D = (70 − 10 cos 2ψ) d,
//! L = 10 sin 2ψ · l, T = 2 cos ψ · t_p, T_r = 800 t_r, in paper units at |δv| = 1 µm/s and
//! ω = 2π rad/s. The paper's Algorithm 2 multiplies by 1e-6 and 1e-9 for its mm/g flow solver;
//! here the targets are SI:
//!
//! - c_d = D · 1e-15 N / (1e-6 m/s) = D · 1e-9 kg/s, likewise c_l;
//! - c_p = T · 1e-21 N·m / (1e-6 m/s) = T · 1e-15 kg·m/s;
//! - c_r = T_r · 1e-21 N·m / (2π rad/s).
//!
//! **Strain torque (an extension, not in the paper).** T_s is the torque in paper units on the
//! fixed body in the body-frame strain flow ε (y, x, 0) with ε = 2π s⁻¹ (E'_xy = ε), the rate of
//! the rotational training flow; it is scaled like T_r: T_s = 800 t_s, c_s = T_s · 1e-21 N·m /
//! (2π s⁻¹). For a thin disc c_s / c_r = B → 1 (Bretherton's shape factor), so t_s ≈ t_r = O(1).
//!
//! **Shape factor** ([`StrainTarget`]). How a platelet tumbles in shear hangs on 1 − B, not on
//! t_s: Jeffery's period 4π / (γ̇ √(1 − B²)) moves by about B δB / (1 − B²), r²/4 times δB / B for
//! an ellipsoid of aspect r (r = 20: 100 ×), and the slowest angular velocity, at the
//! flow-aligned orientation, is γ̇ (1 − B) / 2. A network predicting t_s to 0.03 % still gets the
//! period of a thin platelet wrong by several per cent. The shipped N_s therefore predicts
//! g = ln((1 − B) / (1 − B_e)), the log of 1 − B relative to that of the ellipsoid with the same
//! in-plane axes (B_e = (Lx² − Ly²)/(Lx² + Ly²), Jeffery 1922): an absolute error δg is a
//! relative error δg of 1 − B, i.e. about δg / 2 of the period and δg of the slowest rotation,
//! for every aspect ratio. c_s = c_r (1 − (1 − B_e) e^g) with c_r from N_r. `t_s` (the first
//! networks) and plain ln(1 − B) are kept as choices (`sonoflow platelet train --strain-target`);
//! the weights carry the choice in their metadata.

use super::mlp::{with_thread_workspace, Mlp, MlpWorkspace};
use super::NnError;
use crate::coefficients::{CoefficientModel, Rotational, Translational};
use crate::shape::Shape;
use rayon::prelude::*;
use std::f64::consts::PI;
use std::path::Path;

/// Newtons per paper force unit µg·µm/s².
pub const FORCE_UNIT: f64 = 1e-15;
/// N·m per paper torque unit µg·µm²/s².
pub const TORQUE_UNIT: f64 = 1e-21;
/// m/s per paper speed unit µm/s (the relative speed of the translational training flows).
pub const SPEED_UNIT: f64 = 1e-6;
/// Angular velocity of the rotational training flow (and strain rate of the strain flow) \[rad/s\].
pub const OMEGA_REF: f64 = 2.0 * PI;
/// Eq 18's scale of the rotational torque (and here of the strain torque).
pub const T_R_SCALE: f64 = 800.0;
/// Viscosity of the training data in paper units \[µg/(µm·s)\] (= 3e-3 Pa·s).
pub const MU_PAPER: f64 = 3.0;
/// Smallest |eq 18 factor| [`scale_translational`] divides by.
pub const MIN_FACTOR: f64 = 1e-6;

/// Eq 18's factors (70 − 10 cos 2ψ, 10 sin 2ψ, 2 cos ψ) of (d, l, t_p).
pub fn eq18_factors(psi: f64) -> [f64; 3] {
    let (s, c) = psi.sin_cos();
    let (cos2, sin2) = (c * c - s * s, 2.0 * s * c);
    [70.0 - 10.0 * cos2, 10.0 * sin2, 2.0 * c]
}

/// (d, l, t_p) → (D, L, T) in paper units (eq 18).
pub fn unscale_translational(psi: f64, scaled: [f64; 3]) -> [f64; 3] {
    let f = eq18_factors(psi);
    [f[0] * scaled[0], f[1] * scaled[1], f[2] * scaled[2]]
}

/// (D, L, T) → (d, l, t_p) (eq 18), the training targets. Fails where a factor is below
/// [`MIN_FACTOR`] in magnitude (L at ψ = kπ/2, T at ψ = π/2 + kπ): a data generator should not
/// draw those angles (noise in L or T would be amplified there).
pub fn scale_translational(psi: f64, raw: [f64; 3]) -> Result<[f64; 3], NnError> {
    let f = eq18_factors(psi);
    let mut out = [0.0; 3];
    for (k, quantity) in ["drag D", "lift L", "pitching torque T"].into_iter().enumerate() {
        if f[k].abs() < MIN_FACTOR {
            return Err(NnError::Scaling { quantity, psi, factor: f[k] });
        }
        out[k] = raw[k] / f[k];
    }
    Ok(out)
}

/// t → T = 800 t (eq 18), for t_r and t_s.
pub fn unscale_rotational(scaled: f64) -> f64 {
    T_R_SCALE * scaled
}

/// T → t = T / 800 (eq 18), for T_r and T_s.
pub fn scale_rotational(raw: f64) -> f64 {
    raw / T_R_SCALE
}

/// What N_s predicts (module doc, "Shape factor").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StrainTarget {
    /// t_s = T_s / 800, scaled like t_r (the first shipped networks).
    StrainTorque,
    /// g = ln((1 − B) / (1 − B_e)): B = c_s / c_r, B_e = (Lx² − Ly²)/(Lx² + Ly²) Jeffery's B of
    /// the ellipsoid with the platelet's in-plane axes (the default).
    ShapeFactor,
    /// ln(1 − B) without the ellipsoid's part (an ablation).
    LogOneMinusB,
}

impl StrainTarget {
    /// Every target, in the order of the ablation tables.
    pub const ALL: [StrainTarget; 3] =
        [StrainTarget::ShapeFactor, StrainTarget::LogOneMinusB, StrainTarget::StrainTorque];

    /// Name of N_s's output in the weights' metadata (`outputs`) and the reports.
    pub fn output_name(self) -> &'static str {
        match self {
            StrainTarget::StrainTorque => "t_s",
            StrainTarget::ShapeFactor => "ln((1-B)/(1-B_e))",
            StrainTarget::LogOneMinusB => "ln(1-B)",
        }
    }

    /// The target of [`StrainTarget::output_name`].
    pub fn from_output_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|t| t.output_name() == name)
    }

    /// The training target from the shape and its (t_r, t_s) = (T_r, T_s) / 800. Fails unless
    /// 0 < t_s < t_r for the log targets (B in (0, 1): every body the solver resolves).
    pub fn target(self, shape: &Shape, t_r: f64, t_s: f64) -> Result<f64, NnError> {
        if self == StrainTarget::StrainTorque {
            return Ok(t_s);
        }
        if !(t_r.is_finite() && t_s.is_finite() && t_r > 0.0 && t_s < t_r) {
            return Err(NnError::Config {
                field: "rotational torques (t_r, t_s)",
                value: format!("({t_r}, {t_s})"),
                allowed: "t_s < t_r and t_r > 0 (a shape factor B = t_s / t_r below 1)",
            });
        }
        let ln_1mb = ((t_r - t_s) / t_r).ln();
        Ok(match self {
            StrainTarget::ShapeFactor => ln_1mb - ellipsoid_one_minus_b(shape).ln(),
            _ => ln_1mb,
        })
    }

    /// t_s from the network's output `y` and t_r (the inverse of [`StrainTarget::target`]).
    pub fn strain_torque(self, shape: &Shape, t_r: f64, y: f64) -> f64 {
        match self {
            StrainTarget::StrainTorque => y,
            StrainTarget::ShapeFactor => t_r * (1.0 - ellipsoid_one_minus_b(shape) * y.exp()),
            StrainTarget::LogOneMinusB => t_r * (1.0 - y.exp()),
        }
    }
}

/// 1 − B_e = 2 Ly² / (Lx² + Ly²) of the ellipsoid with the platelet's in-plane axes (Jeffery 1922:
/// B_e = (Lx² − Ly²)/(Lx² + Ly²) for rotation about z; exact for α = 1 in free space).
pub fn ellipsoid_one_minus_b(shape: &Shape) -> f64 {
    let (x2, y2) = (shape.lx * shape.lx, shape.ly * shape.ly);
    2.0 * y2 / (x2 + y2)
}

/// (D, L, T) in paper units at |δv| = 1 µm/s → SI coefficients (module doc).
pub fn translational_to_si(raw: [f64; 3]) -> Translational {
    Translational {
        c_d: raw[0] * FORCE_UNIT / SPEED_UNIT,
        c_l: raw[1] * FORCE_UNIT / SPEED_UNIT,
        c_p: raw[2] * TORQUE_UNIT / SPEED_UNIT,
    }
}

/// SI coefficients → (D, L, T) in paper units (the inverse of [`translational_to_si`]).
pub fn translational_from_si(c: &Translational) -> [f64; 3] {
    [c.c_d * SPEED_UNIT / FORCE_UNIT, c.c_l * SPEED_UNIT / FORCE_UNIT, c.c_p * SPEED_UNIT / TORQUE_UNIT]
}

/// (T_r, T_s) in paper units at ω = ε = 2π s⁻¹ → SI coefficients (module doc).
pub fn rotational_to_si(t_r: f64, t_s: f64) -> Rotational {
    Rotational { c_r: t_r * TORQUE_UNIT / OMEGA_REF, c_s: t_s * TORQUE_UNIT / OMEGA_REF }
}

/// SI coefficients → (T_r, T_s) in paper units (the inverse of [`rotational_to_si`]).
pub fn rotational_from_si(c: &Rotational) -> [f64; 2] {
    [c.c_r * OMEGA_REF / TORQUE_UNIT, c.c_s * OMEGA_REF / TORQUE_UNIT]
}

/// Inputs of N_r and N_s: (Lx, Ly, Lz \[µm\], α_top, α_bot).
pub fn shape_inputs(shape: &Shape) -> [f64; 5] {
    [shape.lx * 1e6, shape.ly * 1e6, shape.lz * 1e6, shape.alpha_top, shape.alpha_bot]
}

/// Inputs of N: the shape inputs and ψ reduced to [0, 2π).
pub fn network_inputs(shape: &Shape, psi: f64) -> [f64; 6] {
    let s = shape_inputs(shape);
    [s[0], s[1], s[2], s[3], s[4], psi.rem_euclid(2.0 * PI)]
}

/// Particles per work item (rayon task or serial step).
const CHUNK: usize = 1024;

/// Coefficients from the three networks N, N_r, N_s (module doc).
#[derive(Clone, Debug, PartialEq)]
pub struct NetworkModel {
    n: Mlp,
    n_r: Mlp,
    n_s: Mlp,
    strain: StrainTarget,
    parallel: bool,
}

fn expect_sizes(name: &str, net: &Mlp, n_in: usize, n_out: usize) -> Result<(), NnError> {
    if net.n_inputs() != n_in || net.n_outputs() != n_out {
        return Err(NnError::Config {
            field: "network sizes",
            value: format!("{name}: {:?} ({} -> {})", net.sizes(), net.n_inputs(), net.n_outputs()),
            allowed: "N: 6 inputs, 3 outputs; N_r and N_s: 5 inputs, 1 output",
        });
    }
    Ok(())
}

impl NetworkModel {
    /// From N (6 → 3), N_r (5 → 1) and N_s (5 → 1, predicting t_s: see
    /// [`NetworkModel::with_strain_target`]); serial evaluation.
    pub fn new(n: Mlp, n_r: Mlp, n_s: Mlp) -> Result<Self, NnError> {
        expect_sizes("N", &n, 6, 3)?;
        expect_sizes("N_r", &n_r, 5, 1)?;
        expect_sizes("N_s", &n_s, 5, 1)?;
        Ok(NetworkModel { n, n_r, n_s, strain: StrainTarget::StrainTorque, parallel: false })
    }

    /// What N_s predicts.
    pub fn with_strain_target(mut self, target: StrainTarget) -> Self {
        self.strain = target;
        self
    }

    /// What N_s predicts.
    pub fn strain_target(&self) -> StrainTarget {
        self.strain
    }

    /// Evaluates across rayon's threads (`true`) or on the caller's (`false`); same results.
    pub fn with_parallel(mut self, parallel: bool) -> Self {
        self.parallel = parallel;
        self
    }

    /// The networks (N, N_r, N_s).
    pub fn networks(&self) -> (&Mlp, &Mlp, &Mlp) {
        (&self.n, &self.n_r, &self.n_s)
    }

    /// Writes `n.safetensors`, `n_r.safetensors`, `n_s.safetensors` into `dir`.
    pub fn save_dir(&self, dir: &Path) -> Result<(), NnError> {
        self.n.save(&dir.join("n.safetensors"), &[("network", "N"), ("outputs", "d,l,t_p")])?;
        self.n_r.save(&dir.join("n_r.safetensors"), &[("network", "N_r"), ("outputs", "t_r")])?;
        self.n_s.save(&dir.join("n_s.safetensors"), &[("network", "N_s"), ("outputs", self.strain.output_name())])
    }

    /// Reads the three files [`NetworkModel::save_dir`] writes; N_s's target from its `outputs`
    /// metadata (absent: t_s).
    pub fn load_dir(dir: &Path) -> Result<Self, NnError> {
        let (n, _) = Mlp::load(&dir.join("n.safetensors"))?;
        let (n_r, _) = Mlp::load(&dir.join("n_r.safetensors"))?;
        let (n_s, meta) = Mlp::load(&dir.join("n_s.safetensors"))?;
        let strain = match meta.get("outputs") {
            None => StrainTarget::StrainTorque,
            Some(name) => StrainTarget::from_output_name(name).ok_or_else(|| NnError::Config {
                field: "n_s.safetensors: metadata `outputs`",
                value: name.clone(),
                allowed: "t_s, ln((1-B)/(1-B_e)) or ln(1-B)",
            })?,
        };
        Ok(Self::new(n, n_r, n_s)?.with_strain_target(strain))
    }

    fn translational_chunk(&self, shapes: &[Shape], psi: &[f64], out: &mut [Translational], ws: &mut MlpWorkspace) {
        self.n.forward_with(
            shapes.len(),
            ws,
            |i, row| {
                for (r, v) in row.iter_mut().zip(network_inputs(&shapes[i], psi[i])) {
                    *r = v as f32;
                }
            },
            |i, row| {
                let raw = unscale_translational(psi[i], [row[0] as f64, row[1] as f64, row[2] as f64]);
                out[i] = translational_to_si(raw);
            },
        );
    }

    fn rotational_chunk(&self, shapes: &[Shape], out: &mut [Rotational], ws: &mut MlpWorkspace) {
        let fill = |i: usize, row: &mut [f32]| {
            for (r, v) in row.iter_mut().zip(shape_inputs(&shapes[i])) {
                *r = v as f32;
            }
        };
        // t_r first (in c_r), then N_s's output (in c_s) turned into t_s with it
        self.n_r.forward_with(shapes.len(), ws, fill, |i, row| out[i].c_r = row[0] as f64);
        let strain = self.strain;
        self.n_s.forward_with(shapes.len(), ws, fill, |i, row| {
            out[i].c_s = strain.strain_torque(&shapes[i], out[i].c_r, row[0] as f64)
        });
        for o in out.iter_mut() {
            *o = rotational_to_si(unscale_rotational(o.c_r), unscale_rotational(o.c_s));
        }
    }
}

impl CoefficientModel for NetworkModel {
    /// Panics if the slices differ in length (a programming error).
    fn translational(&self, shapes: &[Shape], psi: &[f64], out: &mut [Translational]) {
        assert!(shapes.len() == psi.len() && psi.len() == out.len(), "translational: slices of different lengths");
        let work = |((s, p), o): ((&[Shape], &[f64]), &mut [Translational])| {
            with_thread_workspace(|ws| self.translational_chunk(s, p, o, ws))
        };
        if self.parallel {
            shapes.par_chunks(CHUNK).zip(psi.par_chunks(CHUNK)).zip(out.par_chunks_mut(CHUNK)).for_each(work);
        } else {
            shapes.chunks(CHUNK).zip(psi.chunks(CHUNK)).zip(out.chunks_mut(CHUNK)).for_each(work);
        }
    }

    /// Panics if the slices differ in length (a programming error).
    fn rotational(&self, shapes: &[Shape], out: &mut [Rotational]) {
        assert_eq!(shapes.len(), out.len(), "rotational: slices of different lengths");
        let work = |(s, o): (&[Shape], &mut [Rotational])| with_thread_workspace(|ws| self.rotational_chunk(s, o, ws));
        if self.parallel {
            shapes.par_chunks(CHUNK).zip(out.par_chunks_mut(CHUNK)).for_each(work);
        } else {
            shapes.chunks(CHUNK).zip(out.chunks_mut(CHUNK)).for_each(work);
        }
    }

    fn name(&self) -> &str {
        "network"
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shape::ShapeSampler;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A linear 6 → 3 network picking inputs: d = Lx \[µm\], l = ψ, t_p = α_top − 2 α_bot + 0.5.
    fn picking_n() -> Mlp {
        let mut w = vec![0.0; 18];
        w[0] = 1.0; // d ← Lx
        w[6 + 5] = 1.0; // l ← ψ
        w[12 + 3] = 1.0; // t_p ← α_top − 2 α_bot
        w[12 + 4] = -2.0;
        Mlp::from_parts(
            vec![6, 3],
            vec![w],
            vec![vec![0.0, 0.0, 0.5]],
            vec![0.0; 6],
            vec![1.0; 6],
            vec![0.0; 3],
            vec![1.0; 3],
        )
        .expect("valid")
    }

    /// 5 → 2 → 1: t = Σ c_k x_k + c0 through a ReLU unit (the sum is positive for these tests).
    fn linear_5(c: [f64; 5], c0: f64) -> Mlp {
        let mut w0 = vec![0.0; 5 * 2];
        w0[..5].copy_from_slice(&c);
        Mlp::from_parts(
            vec![5, 2, 1],
            vec![w0, vec![1.0, 0.0]],
            vec![vec![0.0, 0.0], vec![c0]],
            vec![0.0; 5],
            vec![1.0; 5],
            vec![0.0],
            vec![1.0],
        )
        .expect("valid")
    }

    fn model() -> NetworkModel {
        NetworkModel::new(
            picking_n(),
            linear_5([0.1, 1.0, 0.1, 0.0, 0.0], 0.2),
            linear_5([0.0, 0.0, 0.0, 0.5, 0.25], 0.0),
        )
        .expect("sizes fit")
    }

    #[test]
    fn unit_conversions_reproduce_stokes_drag_and_torque_of_a_sphere() {
        // sphere radius a: drag 6π μ a U, torque 8π μ a³ ω; once in paper units, once in SI
        let a_um = 1.5;
        let d_paper = 6.0 * PI * MU_PAPER * a_um * 1.0; // U = 1 µm/s
        let tr_paper = 8.0 * PI * MU_PAPER * a_um.powi(3) * 2.0 * PI; // ω = 2π
        let (mu, a) = (3e-3, 1.5e-6); // Pa·s, m
        let c = translational_to_si([d_paper, 0.5 * d_paper, d_paper * 0.7]); // T: force × 0.7 µm arm
        assert!((c.c_d / (6.0 * PI * mu * a) - 1.0).abs() < 1e-12, "{}", c.c_d);
        assert!((c.c_l / (3.0 * PI * mu * a) - 1.0).abs() < 1e-12);
        // pitching torque per unit speed: drag × arm (0.7e-6 m) [N·s]
        assert!((c.c_p / (6.0 * PI * mu * a * 0.7e-6) - 1.0).abs() < 1e-12, "{}", c.c_p);
        let r = rotational_to_si(tr_paper, 0.5 * tr_paper);
        assert!((r.c_r / (8.0 * PI * mu * a.powi(3)) - 1.0).abs() < 1e-12, "{}", r.c_r);
        assert!((r.c_s / (4.0 * PI * mu * a.powi(3)) - 1.0).abs() < 1e-12);
        let back = translational_from_si(&c);
        assert!((back[0] - d_paper).abs() < 1e-12 * d_paper && (back[2] - 0.7 * d_paper).abs() < 1e-12 * d_paper);
        let back = rotational_from_si(&r);
        assert!((back[0] - tr_paper).abs() < 1e-12 * tr_paper);
    }

    #[test]
    fn eq18_scaling_round_trips_and_refuses_vanishing_factors() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for _ in 0..100 {
            let psi = rng.gen_range(0.0..2.0 * PI);
            let raw = [rng.gen_range(50.0..90.0), rng.gen_range(-10.0..10.0), rng.gen_range(-2.0..2.0)];
            let f = [70.0 - 10.0 * (2.0 * psi).cos(), 10.0 * (2.0 * psi).sin(), 2.0 * psi.cos()];
            match scale_translational(psi, raw) {
                Ok(s) => {
                    for k in 0..3 {
                        assert!((s[k] * f[k] - raw[k]).abs() < 1e-12 * (1.0 + raw[k].abs()));
                    }
                    let back = unscale_translational(psi, s);
                    assert!((0..3).all(|k| (back[k] - raw[k]).abs() < 1e-12 * (1.0 + raw[k].abs())));
                }
                Err(e) => panic!("{e}"),
            }
        }
        let e = scale_translational(PI / 2.0, [60.0, 0.0, 0.0]).expect_err("sin 2ψ = 0");
        assert!(e.to_string().contains("lift"), "{e}");
        assert_eq!(scale_rotational(unscale_rotational(0.9)), 0.9);
    }

    #[test]
    fn network_model_applies_inputs_in_um_eq18_and_si_units() {
        let m = model();
        let shapes = [Shape::from_um(3.2, 0.6, 2.9, 1.3, 0.7), Shape::from_um(2.6, 0.3, 3.4, 0.4, 1.9)];
        let psi = [0.4, -0.5]; // −0.5 is fed as 2π − 0.5
        let mut out = [Translational::default(); 2];
        m.translational(&shapes, &psi, &mut out);
        for i in 0..2 {
            let s = shapes[i];
            let p = psi[i];
            let (d, l, tp) = (s.lx * 1e6, p.rem_euclid(2.0 * PI), s.alpha_top - 2.0 * s.alpha_bot + 0.5);
            let want_cd = (70.0 - 10.0 * (2.0 * p).cos()) * d * 1e-9;
            let want_cl = 10.0 * (2.0 * p).sin() * l * 1e-9;
            let want_cp = 2.0 * p.cos() * tp * 1e-15;
            assert!((out[i].c_d - want_cd).abs() < 1e-6 * want_cd.abs(), "{i}: {} vs {want_cd}", out[i].c_d);
            assert!((out[i].c_l - want_cl).abs() < 1e-6 * want_cl.abs(), "{i}: {} vs {want_cl}", out[i].c_l);
            assert!((out[i].c_p - want_cp).abs() < 1e-6 * want_cp.abs(), "{i}: {} vs {want_cp}", out[i].c_p);
        }
        let mut rot = [Rotational::default(); 2];
        m.rotational(&shapes, &mut rot);
        for i in 0..2 {
            let s = shapes[i];
            let t_r = 0.1 * s.lx * 1e6 + s.ly * 1e6 + 0.1 * s.lz * 1e6 + 0.2;
            let t_s = 0.5 * s.alpha_top + 0.25 * s.alpha_bot;
            let (want_r, want_s) = (800.0 * t_r * 1e-21 / (2.0 * PI), 800.0 * t_s * 1e-21 / (2.0 * PI));
            assert!((rot[i].c_r - want_r).abs() < 1e-6 * want_r, "{} vs {want_r}", rot[i].c_r);
            assert!((rot[i].c_s - want_s).abs() < 1e-6 * want_s);
        }
    }

    #[test]
    fn parallel_and_serial_evaluation_agree_bit_for_bit() {
        let n = Mlp::he_init(&[6, 50, 20, 20, 3], 1)
            .and_then(|m| {
                m.with_normalisation(
                    vec![3.0, 0.5, 3.0, 1.0, 1.0, PI],
                    vec![0.3, 0.2, 0.3, 0.4, 0.4, 1.8],
                    vec![1.0, 1.0, 0.1],
                    vec![0.1, 0.1, 0.1],
                )
            })
            .expect("valid");
        let nr = Mlp::he_init(&[5, 20, 20, 20, 1], 2).expect("valid");
        let ns = Mlp::he_init(&[5, 20, 20, 20, 1], 3).expect("valid");
        let serial = NetworkModel::new(n, nr, ns).expect("sizes fit");
        let par = serial.clone().with_parallel(true);
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let sampler = ShapeSampler::default();
        let k = 5000;
        let shapes: Vec<Shape> = (0..k).map(|_| sampler.sample(&mut rng)).collect();
        let psi: Vec<f64> = (0..k).map(|_| rng.gen_range(-7.0..7.0)).collect();
        let (mut a, mut b) = (vec![Translational::default(); k], vec![Translational::default(); k]);
        serial.translational(&shapes, &psi, &mut a);
        par.translational(&shapes, &psi, &mut b);
        assert_eq!(a, b);
        let (mut ra, mut rb) = (vec![Rotational::default(); k], vec![Rotational::default(); k]);
        serial.rotational(&shapes, &mut ra);
        par.rotational(&shapes, &mut rb);
        assert_eq!(ra, rb);
        assert!(a.iter().any(|c| c.c_d != a[0].c_d), "outputs vary with the inputs");
    }

    #[test]
    fn files_round_trip_and_wrong_networks_are_refused() {
        let dir = tempfile::tempdir().expect("temp dir");
        let m = model();
        m.save_dir(dir.path()).expect("writable");
        assert_eq!(NetworkModel::load_dir(dir.path()).expect("valid files"), m);
        let e = NetworkModel::new(linear_5([0.0; 5], 0.0), linear_5([0.0; 5], 0.0), linear_5([0.0; 5], 0.0))
            .expect_err("N must take 6 inputs");
        assert!(e.to_string().contains("N: [5, 2, 1]"), "{e}");
        std::fs::remove_file(dir.path().join("n_s.safetensors")).expect("exists");
        let e = NetworkModel::load_dir(dir.path()).expect_err("missing file");
        assert!(e.to_string().contains("n_s.safetensors"), "{e}");
    }

    #[test]
    fn shape_factor_target_sets_c_s_from_c_r_and_travels_with_the_weights() {
        // N_s outputs g = 0.5 α_top + 0.25 α_bot; c_s = c_r (1 − (1 − B_e) e^g)
        for target in StrainTarget::ALL {
            let m = model().with_strain_target(target);
            let dir = tempfile::tempdir().expect("temp dir");
            m.save_dir(dir.path()).expect("writable");
            let back = NetworkModel::load_dir(dir.path()).expect("valid files");
            assert_eq!(back.strain_target(), target);
            let shapes = [Shape::from_um(3.2, 0.6, 2.9, 1.3, 0.7), Shape::from_um(2.6, 0.3, 3.4, 0.4, 1.9)];
            let mut rot = [Rotational::default(); 2];
            back.rotational(&shapes, &mut rot);
            for (s, r) in shapes.iter().zip(&rot) {
                let t_r = 0.1 * s.lx * 1e6 + s.ly * 1e6 + 0.1 * s.lz * 1e6 + 0.2;
                let g = 0.5 * s.alpha_top + 0.25 * s.alpha_bot;
                let one_minus_be = 2.0 * s.ly * s.ly / (s.lx * s.lx + s.ly * s.ly);
                let t_s = match target {
                    StrainTarget::StrainTorque => g,
                    StrainTarget::ShapeFactor => t_r * (1.0 - one_minus_be * g.exp()),
                    StrainTarget::LogOneMinusB => t_r * (1.0 - g.exp()),
                };
                let want = 800.0 * t_s * 1e-21 / (2.0 * PI);
                assert!((r.c_s - want).abs() < 1e-6 * want.abs(), "{target:?}: {} vs {want}", r.c_s);
            }
        }
        // weights of an unknown target are refused, naming the field
        let dir = tempfile::tempdir().expect("temp dir");
        model().save_dir(dir.path()).expect("writable");
        linear_5([0.0; 5], 0.0).save(&dir.path().join("n_s.safetensors"), &[("outputs", "B")]).expect("writable");
        let e = NetworkModel::load_dir(dir.path()).expect_err("unknown target");
        assert!(e.to_string().contains("outputs") && e.to_string().contains("ln(1-B)"), "{e}");
    }
}
