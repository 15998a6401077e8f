//! Paper 2's §5.1 experiment: the five test particles of Table 2 — their coefficient curves
//! against the angle of incidence (figs 9–12) and their motion in the paper's channel (fig 14).
//!
//! The channel is 2 mm high with the paper's parabolic profile v = y(2 − y)/2 · v_in (mm units,
//! v_in = 5 mm/s, steady); the particles start at x = 0, y = 0.5176 mm (below the axis, where the
//! shear rate is γ̇ = (1 − y) v_in = 2.41 s⁻¹), φ = 0, moving with the fluid. Collisions are off
//! (the five are far apart in the paper's figure; here they run in separate copies of the
//! channel, so each trajectory is that particle's alone).
//!
//! **What the model predicts.** With eq 6 and the exact relaxation the centre of mass follows
//! its streamline (δv → 0 within nanoseconds) and the body rotates in a Jeffery orbit with
//! B = c_s / c_r: period T = 4π / (γ̇ √(1 − B²)) = 2π/γ̇ (r + 1/r) for an ellipsoid. A y-oscillation needs a force at δv = 0; with
//! the rotation–translation coupling on ([`crate::dynamics::DynamicsParams::coupling`]) the
//! pitching torque's reciprocal force moves the centre of mass of the asymmetric particles
//! periodically with the orbit (the paper's "centre of pressure ≠ centre of mass"), with no net
//! drift (Stokes flow is reversible). The paper's slow drift toward the axis is not reproduced.
use std::f64::consts::PI;

use crate::coefficients::{CoefficientModel, Rotational, Translational};
use crate::dynamics::{CarrierFlow, Channel, Dynamics, DynamicsError, DynamicsParams, ParticleState, Particles};
use crate::shape::Shape;

/// Table 2 (µm): Lx, Ly, Lz, α_top (α₁), α_bot (α₂).
pub const TABLE2: [[f64; 5]; 5] = [
    [3.0, 0.5, 3.0, 1.0, 1.0],
    [3.1, 0.8, 2.5, 1.7, 1.7],
    [2.7, 0.2, 3.2, 0.3, 0.3],
    [3.1, 0.7, 2.8, 0.3, 1.7],
    [2.8, 0.3, 3.1, 1.7, 0.3],
];

/// Start height of the five particles \[m\] (§5.1).
pub const Y0: f64 = 0.5176e-3;

/// The five shapes of Table 2.
pub fn table2_shapes() -> [Shape; 5] {
    TABLE2.map(|p| Shape::from_um(p[0], p[1], p[2], p[3], p[4]))
}

/// Coefficient curves of the five particles (paper units of Algorithm 1: µm, µm/s, µg; D, L in
/// µm·µg/s² at |δv| = 1 µm/s, T in µm²·µg/s², T_r at ω = 2π s⁻¹).
#[derive(Clone, Debug, serde::Serialize)]
pub struct Curves {
    /// Angles of incidence \[rad\].
    pub psi: Vec<f64>,
    /// Per particle: drag D(ψ).
    pub drag: Vec<Vec<f64>>,
    /// Per particle: lift L(ψ).
    pub lift: Vec<Vec<f64>>,
    /// Per particle: pitching torque T(ψ).
    pub pitching: Vec<Vec<f64>>,
    /// Per particle: rotational torque T_r (orientation independent, fig 11).
    pub rotational: Vec<f64>,
    /// Per particle: Jeffery's B = c_s / c_r.
    pub jeffery_b: Vec<f64>,
}

/// The curves of [`TABLE2`] from `model` at `n` angles over [0, 2π).
pub fn curves(model: &dyn CoefficientModel, n: usize) -> Curves {
    let psi: Vec<f64> = (0..n).map(|k| 2.0 * PI * k as f64 / n as f64).collect();
    let shapes = table2_shapes();
    let mut out = Curves {
        psi: psi.clone(),
        drag: Vec::new(),
        lift: Vec::new(),
        pitching: Vec::new(),
        rotational: Vec::new(),
        jeffery_b: Vec::new(),
    };
    let mut rot = [Rotational::default(); 5];
    model.rotational(&shapes, &mut rot);
    for (s, r) in shapes.iter().zip(rot) {
        let mut c = vec![Translational::default(); n];
        model.translational(&vec![*s; n], &psi, &mut c);
        out.drag.push(c.iter().map(|c| c.c_d * 1e-6 / 1e-15).collect());
        out.lift.push(c.iter().map(|c| c.c_l * 1e-6 / 1e-15).collect());
        out.pitching.push(c.iter().map(|c| c.c_p * 1e-6 / 1e-21).collect());
        out.rotational.push(r.c_r * 2.0 * PI / 1e-21);
        out.jeffery_b.push(r.c_s / r.c_r);
    }
    out
}

/// Options of [`run`].
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct RunOptions {
    /// Simulated time \[s\] (0 < t ≤ 3600).
    pub t_end: f64,
    /// Record every this many sub-steps (≥ 1).
    pub record_every: usize,
    /// The dynamics (sub-step, coefficient refresh, coupling…); collisions are turned off.
    pub dynamics: DynamicsParams,
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions { t_end: 40.0, record_every: 400, dynamics: DynamicsParams::default() }
    }
}

/// Recorded motion of the five particles.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Trajectories {
    /// Times \[s\].
    pub t: Vec<f64>,
    /// Per particle: centre-of-mass height y(t) \[m\].
    pub y: Vec<Vec<f64>>,
    /// Per particle: vertical velocity \[m/s\].
    pub vy: Vec<Vec<f64>>,
    /// Per particle: orientation φ(t), unwrapped \[rad\].
    pub phi: Vec<Vec<f64>>,
    /// Local shear rate at Y0 \[1/s\].
    pub shear_rate: f64,
}

/// Runs the five particles in the paper's channel (module doc).
pub fn run(model: &dyn CoefficientModel, opts: &RunOptions) -> Result<Trajectories, DynamicsError> {
    if !(opts.t_end.is_finite() && opts.t_end > 0.0 && opts.t_end <= 3600.0) {
        return Err(DynamicsError::Invalid { field: "t_end", value: opts.t_end, allowed: "0 < t_end <= 3600 s" });
    }
    if opts.record_every == 0 {
        return Err(DynamicsError::Invalid { field: "record_every", value: 0.0, allowed: ">= 1" });
    }
    let params = DynamicsParams { collisions: false, ..opts.dynamics };
    params.validate()?;
    let flow = Channel::default();
    let steps = (opts.t_end / params.sub_step).ceil() as usize;
    let mut tr = Trajectories {
        t: Vec::new(),
        y: vec![Vec::new(); 5],
        vy: vec![Vec::new(); 5],
        phi: vec![Vec::new(); 5],
        shear_rate: 2.0 * flow.v_in * (1.0 - 2.0 * Y0 / flow.height) / flow.height,
    };
    for (k, s) in table2_shapes().into_iter().enumerate() {
        let mut p = Particles::new(crate::dynamics::DEFAULT_DENSITY, 1.0)?;
        let f = flow.sample([0.0, Y0], 0.0);
        p.push(s, ParticleState { x: [0.0, Y0], phi: 0.0, v: f.v, omega: f.omega })?;
        let mut d = Dynamics::new(params)?;
        for step in 0..=steps {
            if step % opts.record_every == 0 {
                if k == 0 {
                    tr.t.push(step as f64 * params.sub_step);
                }
                tr.y[k].push(p.y[0]);
                tr.vy[k].push(p.vy[0]);
                tr.phi[k].push(p.phi[0]);
            }
            if step < steps {
                d.sub_step(&mut p, &flow, model, step as f64 * params.sub_step)?;
            }
        }
    }
    Ok(tr)
}

/// Period of a monotonically turning angle φ(t) from its crossings of multiples of π (the body is
/// symmetric under φ → φ + π): mean time per half turn × 2. `None` with fewer than 2 crossings.
pub fn rotation_period(t: &[f64], phi: &[f64]) -> Option<f64> {
    let mut crossings = Vec::new();
    for i in 1..phi.len().min(t.len()) {
        let (a, b) = (phi[i - 1] / PI, phi[i] / PI);
        if a.floor() != b.floor() {
            let level = if b < a { a.floor() } else { b.floor() };
            let f = (level - a) / (b - a);
            crossings.push(t[i - 1] + f * (t[i] - t[i - 1]));
        }
    }
    if crossings.len() < 2 {
        return None;
    }
    let n = crossings.len() - 1;
    Some(2.0 * (crossings[n] - crossings[0]) / n as f64)
}

/// Jeffery's period 4π / (γ̇ √(1 − B²)) in simple shear γ̇ (a full turn; with B = (r² − 1)/(r² + 1)
/// this is 2π/γ̇ (r + 1/r)).
pub fn jeffery_period(shear_rate: f64, b: f64) -> f64 {
    4.0 * PI / (shear_rate.abs() * (1.0 - b * b).sqrt())
}

/// How well a model's shape factor B = c_s / c_r sets a platelet's rotation in simple shear,
/// against a reference B (the converged solver, or Jeffery's closed form).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RotationError {
    /// Aspect max(Lx, Lz) / Ly of the shape.
    pub aspect: f64,
    /// |T / T_ref − 1| of Jeffery's period 4π / (γ̇ √(1 − B²)).
    pub period: f64,
    /// The largest |Ω / Ω_ref − 1| over all orientations φ of Ω(φ) = −γ̇/2 (1 − B cos 2φ):
    /// |B − B_ref| / (1 − |B_ref|), at the flow-aligned orientation where the platelet turns slowest.
    pub omega: f64,
}

/// The rotation errors of `model`'s shape factor on `shapes` against the reference `b_ref`.
pub fn rotation_errors(model: &dyn CoefficientModel, shapes: &[Shape], b_ref: &[f64]) -> Vec<RotationError> {
    let mut rot = vec![Rotational::default(); shapes.len()];
    model.rotational(shapes, &mut rot);
    shapes
        .iter()
        .zip(&rot)
        .zip(b_ref)
        .map(|((s, r), &b0)| {
            let b = r.c_s / r.c_r;
            RotationError {
                aspect: s.lx.max(s.lz) / s.ly,
                period: (jeffery_period(1.0, b) / jeffery_period(1.0, b0) - 1.0).abs(),
                omega: (b - b0).abs() / (1.0 - b0.abs()),
            }
        })
        .collect()
}
