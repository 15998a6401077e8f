//! Platelet cases (from `nodes/platelet/tests/dynamics.rs`, `stokes.rs` and `networks.rs`, with the
//! fixtures of `sonoflow_platelet::testkit`, plus a pile-up of overlapping platelets and shapes far
//! outside the networks' training range).

use super::{Case, CaseResult, Check, Ctx, Expected, OrMessage, Stage};
use sonoflow_platelet::dynamics::{
    CarrierFlow, Channel, DiscStandIn, Dynamics, DynamicsParams, Integrator, ParticleState, Particles, SimpleShear,
    DEFAULT_DENSITY,
};
use sonoflow_platelet::testkit::{one, shipped_model, FixedModel};
use sonoflow_platelet::{solve_shape, CoefficientModel, Outer, Rotational, Shape, StokesOptions, Translational};

pub(super) fn cases() -> Vec<Case> {
    vec![
        Stage::Platelet.case(
            "stiff-relaxation-exponential",
            "a platelet (relaxation times ~20 ns) in shear at the paper's 0.25 ms sub-step, 400 sub-steps, exponential \
             integrator; check: V equals the flow to 1e-9 relative, finite",
            Expected::Pass,
            stiff_exponential,
        ),
        Stage::Platelet.case(
            "stiff-relaxation-explicit",
            "the same with forward Euler (stable only below ~2e-8 s)",
            Expected::ClearError(&["allowed finite", "explicit step above the stability limit"]),
            stiff_explicit,
        ),
        Stage::Platelet.case(
            "thinnest-platelet-stokes",
            "Stokes solve of the thinnest platelet of eq 7 (3.5 x 0.15 x 3.5 um, alpha 0.2: 1:50 thin) in the 50 um \
             ball at two resolutions; check: drag and rotation torque agree to 2e-3, lift of the symmetric body ~0",
            Expected::Pass,
            thinnest,
        ),
        Stage::Platelet.case(
            "ball-too-small",
            "the confining ball (radius 2 um) smaller than the platelet",
            Expected::ClearError(&["outer.radius", "must exceed"]),
            ball_too_small,
        ),
        Stage::Platelet.case(
            "model-gives-nan",
            "a coefficient model returning NaN drag",
            Expected::ClearError(&["c_d", "finite and > 0"]),
            model_nan,
        ),
        Stage::Platelet.case(
            "coupling-not-positive-definite",
            "rotation-translation coupling with c_x^2 > c_d c_r (no physical body)",
            Expected::ClearError(&["c_x^2 < c_d c_r"]),
            coupling_bad,
        ),
        Stage::Platelet.case(
            "pile-up-200-overlapping",
            "200 platelets started at the same point in a channel (every pair overlapping), collisions on; check: \
             finite, all inside the walls, the pile pushed apart over > 10 radii",
            Expected::Pass,
            pile_up,
        ),
        Stage::Platelet.case(
            "networks-far-outside-eq7",
            "the shipped networks on shapes far outside eq 7 (Lx 1 and 10 um, Ly 3 um, alpha 0.05 and 5); check: \
             every coefficient finite (the dynamics refuses non-physical ones with a clear error)",
            Expected::Pass,
            networks_far_out,
        ),
        Stage::Platelet.case(
            "zero-sub-steps",
            "dynamics parameters with 0 sub-steps per macro step",
            Expected::ClearError(&["sub_steps"]),
            zero_sub_steps,
        ),
    ]
}

fn one_platelet(flow: &dyn CarrierFlow) -> Particles {
    let x = [1e-3, 0.6e-3];
    let f = flow.sample(x, 0.0);
    one(Shape::default(), ParticleState { x, phi: 0.3, v: [f.v[0] * 0.5, f.v[1] + 1e-4], omega: 0.0 })
}

fn stiff(integrator: Integrator) -> CaseResult {
    let flow = SimpleShear::new(50.0).msg()?;
    let mut p = one_platelet(&flow);
    let mut d = Dynamics::new(DynamicsParams { integrator, collisions: false, ..Default::default() }).msg()?;
    for k in 0..20 {
        d.macro_step(&mut p, &flow, &DiscStandIn::default(), k as f64 * 5e-3).msg()?;
    }
    let v = flow.sample([p.x[0], p.y[0]], 0.1).v;
    let err = (p.vx[0] - v[0]).hypot(p.vy[0] - v[1]) / v[0].hypot(v[1]).max(1e-30);
    Ok(Check::new(err.is_finite() && err < 1e-9, format!("|V - v| / |v| = {err:.1e} after 400 sub-steps")))
}

fn stiff_exponential(_: &Ctx) -> CaseResult {
    stiff(Integrator::Exponential)
}

fn stiff_explicit(_: &Ctx) -> CaseResult {
    stiff(Integrator::ExplicitEuler)
}

fn thinnest(ctx: &Ctx) -> CaseResult {
    let s = Shape::from_um(3.5, 0.15, 3.5, 0.2, 0.2);
    let (lo, hi) = if ctx.quick { (10, 14) } else { (12, 20) };
    let a = solve_shape(&s, &StokesOptions { n_beta: lo, ..Default::default() }).msg()?;
    let b = solve_shape(&s, &StokesOptions { n_beta: hi, ..Default::default() }).msg()?;
    let dd = (a.force_per_flow[1][1] - b.force_per_flow[1][1]).abs() / b.force_per_flow[1][1];
    let dr = (a.rotation_torque - b.rotation_torque).abs() / b.rotation_torque;
    let lift = b.translational(std::f64::consts::FRAC_PI_2).c_l.abs() / b.force_per_flow[1][1];
    Ok(Check::new(
        dd < 2e-3 && dr < 2e-3 && lift < 1e-9,
        format!("n_beta {lo} vs {hi}: drag {dd:.1e}, rotation {dr:.1e}; |lift(pi/2)| / drag {lift:.0e}"),
    ))
}

fn ball_too_small(_: &Ctx) -> CaseResult {
    let o = StokesOptions { outer: Outer::Ball { radius: 2e-6, n_beta: 8 }, ..Default::default() };
    solve_shape(&Shape::default(), &o).msg().map(|_| Check::new(false, "solved"))
}

fn model_nan(_: &Ctx) -> CaseResult {
    let flow = Channel::default();
    let mut p = one_platelet(&flow);
    let m = FixedModel::drag(f64::NAN);
    let mut d = Dynamics::new(DynamicsParams::default()).msg()?;
    d.macro_step(&mut p, &flow, &m, 0.0).msg().map(|_| Check::new(false, "stepped"))
}

fn coupling_bad(_: &Ctx) -> CaseResult {
    let flow = Channel::default();
    let mut p = one_platelet(&flow);
    let m = FixedModel::pitchy();
    let mut d = Dynamics::new(DynamicsParams { coupling: true, ..Default::default() }).msg()?;
    d.macro_step(&mut p, &flow, &m, 0.0).msg().map(|_| Check::new(false, "stepped"))
}

fn pile_up(_: &Ctx) -> CaseResult {
    let flow = Channel::default();
    let mut p = Particles::new(DEFAULT_DENSITY, 1.0).msg()?;
    let x = [1e-3, 1e-3];
    let v = flow.sample(x, 0.0).v;
    for k in 0..200 {
        let s = Shape::from_um(2.5 + 0.005 * k as f64, 0.5, 3.0, 1.0, 1.0);
        p.push(s, ParticleState { x, phi: 0.01 * k as f64, v, omega: 0.0 }).msg()?;
    }
    let mut d = Dynamics::new(DynamicsParams::default()).msg()?;
    let mut impulses = 0;
    for k in 0..4 {
        impulses += d.macro_step(&mut p, &flow, &DiscStandIn::default(), k as f64 * 5e-3).msg()?.impulses;
    }
    let finite = (0..p.len()).all(|i| p.x[i].is_finite() && p.y[i].is_finite() && p.vx[i].is_finite());
    let inside = p.y.iter().all(|&y| (0.0..=2e-3).contains(&y));
    let spread = |v: &[f64]| v.iter().fold(f64::MIN, |a, &b| a.max(b)) - v.iter().fold(f64::MAX, |a, &b| a.min(b));
    let (sx, sy) = (spread(&p.x), spread(&p.y));
    // the overlaps are pushed apart (coincident centres along x): the pile spreads over many radii
    Ok(Check::new(
        finite && inside && sx.hypot(sy) > 10.0 * 3e-6,
        format!(
            "{impulses} impulses; finite {finite}, inside the walls {inside}, spread {:.0} x {:.0} um",
            sx * 1e6,
            sy * 1e6
        ),
    ))
}

fn networks_far_out(_: &Ctx) -> CaseResult {
    let m = shipped_model();
    let shapes = [
        Shape::from_um(1.0, 0.5, 1.0, 1.0, 1.0),
        Shape::from_um(10.0, 0.5, 10.0, 1.0, 1.0),
        Shape::from_um(3.0, 3.0, 3.0, 1.0, 1.0),
        Shape::from_um(3.0, 0.5, 3.0, 0.05, 5.0),
    ];
    let psi = [0.3, 1.2, 2.5, 4.0];
    let mut t = [Translational::default(); 4];
    let mut r = [Rotational::default(); 4];
    m.translational(&shapes, &psi, &mut t);
    m.rotational(&shapes, &mut r);
    let finite = t.iter().all(|c| c.c_d.is_finite() && c.c_l.is_finite() && c.c_p.is_finite())
        && r.iter().all(|c| c.c_r.is_finite() && c.c_s.is_finite());
    let neg = t.iter().filter(|c| c.c_d <= 0.0).count() + r.iter().filter(|c| c.c_r <= 0.0).count();
    Ok(Check::new(
        finite,
        format!("finite {finite}; {neg} non-positive drag/rotation coefficient(s) (refused by the dynamics)"),
    ))
}

fn zero_sub_steps(_: &Ctx) -> CaseResult {
    Dynamics::new(DynamicsParams { sub_steps: 0, ..Default::default() }).msg().map(|_| Check::new(false, "accepted"))
}
