//! How the shipped networks turn a platelet in simple shear (issue 20): Jeffery's period
//! 4π / (γ̇ √(1 − B²)) hangs on 1 − B with B = c_s / c_r, so a small error of B is a large error of
//! the period for thin platelets (r²/4 times larger at aspect r).
//!
//! - Ellipsoids (α = 1) over a grid of eq 7's bounds (Lx, Lz ∈ [2.5, 3.5] µm, Ly from 0.15 to
//!   1 µm): Jeffery's closed form 2π/γ̇ (r + 1/r), r = Lx / Ly, is exact. The period from the
//!   networks' coefficients and the period of an orbit simulated in the suspension's `shear`
//!   carrier are within 1 % of it; the angular velocity within 2 % of Jeffery's Ω(φ) at every
//!   orientation.
//! - Platelets with α ≠ 1 (no closed form) on the shipped test split: the period from the networks
//!   within 1 % of the one from the solver's coefficients in the data (converged per shape).
use std::f64::consts::PI;

use sonoflow_platelet::experiments::{jeffery_period, rotation_errors, rotation_period};
use sonoflow_platelet::spheroid::jeffery_factor;
use sonoflow_platelet::suspension::{Suspension, SuspensionParams};
use sonoflow_platelet::testkit::shipped_model;
use sonoflow_platelet::Shape;

/// The α = 1 grid: Lx, Lz over eq 7's bounds, Ly from its minimum to 1 µm (µm).
fn ellipsoid_grid() -> Vec<Shape> {
    let mut v = Vec::new();
    for lx in [2.5, 3.0, 3.5] {
        for lz in [2.5, 3.0, 3.5] {
            for ly in [0.15, 0.2, 0.25, 0.3, 0.4, 0.5, 0.7, 1.0] {
                v.push(Shape::from_um(lx, ly, lz, 1.0, 1.0));
            }
        }
    }
    v
}

fn jeffery_b(s: &Shape) -> f64 {
    jeffery_factor(0.5 * s.lx, 0.5 * s.ly)
}

#[test]
fn network_shape_factor_gives_jeffery_periods_for_ellipsoids() {
    let model = shipped_model();
    let shapes = ellipsoid_grid();
    let b: Vec<f64> = shapes.iter().map(jeffery_b).collect();
    let errs = rotation_errors(&model, &shapes, &b);
    let worst_p = errs.iter().map(|e| e.period).fold(0.0, f64::max);
    let worst_o = errs.iter().map(|e| e.omega).fold(0.0, f64::max);
    println!(
        "α = 1 grid: period error max {:.3} %, slowest-rotation error max {:.3} %",
        100.0 * worst_p,
        100.0 * worst_o
    );
    for (s, e) in shapes.iter().zip(&errs) {
        let um = |x: f64| x * 1e6;
        assert!(
            e.period < 0.01,
            "Lx {} Ly {} Lz {} (r {:.1}): period off by {:.2} %",
            um(s.lx),
            um(s.ly),
            um(s.lz),
            e.aspect,
            100.0 * e.period
        );
        assert!(
            e.omega < 0.02,
            "Lx {} Ly {} Lz {}: Ω off by {:.2} % at the flow-aligned orientation",
            um(s.lx),
            um(s.ly),
            um(s.lz),
            100.0 * e.omega
        );
    }
}

#[test]
fn simulated_orbits_in_the_shear_carrier_have_jeffery_periods() {
    let shapes = ellipsoid_grid();
    let rate = 100.0; // γ̇ h = 0.025 at the default sub-step: the exponential integrator's error is ~1e-5
                      // on the line y = 0 the shear flow is at rest: no platelet leaves the carrier's box
    let list: Vec<String> = shapes
        .iter()
        .enumerate()
        .map(|(i, s)| {
            format!(
                r#"{{"lx_um": {}, "ly_um": {}, "lz_um": {}, "alpha_top": 1, "alpha_bot": 1, "x": {}, "y": 0.0}}"#,
                s.lx * 1e6,
                s.ly * 1e6,
                s.lz * 1e6,
                1e-5 * (i + 1) as f64
            )
        })
        .collect();
    let json = format!(
        r#"{{"carrier": {{"type": "shear", "rate": {rate}}}, "dynamics": {{"collisions": false}}, "particles": [{}]}}"#,
        list.join(", ")
    );
    let params: SuspensionParams = serde_json::from_str(&json).expect("valid parameters");
    let mut susp = Suspension::new(&params).expect("a suspension with the shipped networks");
    // half a turn of the slowest platelet and a little more (crossings of φ = kπ)
    let t_end = 0.55 * shapes.iter().map(|s| jeffery_period(rate, jeffery_b(s))).fold(0.0, f64::max);
    let n = susp.particles.len();
    let (mut t, mut phi) = (vec![0.0], vec![vec![0.0]; n]);
    let mut worst_omega: f64 = 0.0;
    while susp.time() < t_end {
        susp.macro_step().expect("a macro step");
        t.push(susp.time());
        for (i, (p, s)) in phi.iter_mut().zip(&shapes).enumerate() {
            let st = susp.particles.state(i).expect("particle i");
            p.push(st.phi);
            // Jeffery's Ω(φ) = −γ̇/2 (1 − B cos 2φ) at the simulated orientation
            let om = -0.5 * rate * (1.0 - jeffery_b(s) * (2.0 * st.phi).cos());
            worst_omega = worst_omega.max(((st.omega - om) / om).abs());
        }
    }
    let mut worst: f64 = 0.0;
    for (p, s) in phi.iter().zip(&shapes) {
        let r = s.lx / s.ly;
        let exact = 2.0 * PI / rate * (r + 1.0 / r);
        let measured = rotation_period(&t, p).expect("at least half a turn");
        let e = (measured / exact - 1.0).abs();
        worst = worst.max(e);
        assert!(
            e < 0.01,
            "Lx {:e} Ly {:e} Lz {:e} (r {r:.1}): simulated period {measured} s vs Jeffery {exact} s",
            s.lx,
            s.ly,
            s.lz
        );
    }
    println!("simulated orbits: period error max {:.3} %, Ω error max {:.3} %", 100.0 * worst, 100.0 * worst_omega);
    assert!(worst_omega < 0.02, "Ω off Jeffery's Ω(φ) by {:.2} %", 100.0 * worst_omega);
}

/// α ≠ 1: no closed form; the data's solver coefficients (each shape at its converged resolution)
/// are the reference. Every test shape of the shipped split (80/20 by shape, seed 1).
#[test]
fn network_periods_match_the_converged_solver_on_the_test_shapes() {
    use sonoflow_platelet::dataset::{load, split_by_shape};
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let records = load(&root.join("data/stokes-data.jsonl")).expect("the shipped data load");
    let (_, test) = split_by_shape(&records, 0.2, 1).expect("split");
    let test: Vec<_> = test.into_iter().filter(|r| r.shape.alpha_top != 1.0 || r.shape.alpha_bot != 1.0).collect();
    assert!(test.len() > 700, "{} test shapes with α ≠ 1", test.len());
    let shapes: Vec<Shape> = test.iter().map(|r| r.shape).collect();
    let b: Vec<f64> = test.iter().map(|r| r.resistance.strain_torque / r.resistance.rotation_torque).collect();
    let errs = rotation_errors(&shipped_model(), &shapes, &b);
    let mean = errs.iter().map(|e| e.period).sum::<f64>() / errs.len() as f64;
    let worst = errs.iter().map(|e| e.period).fold(0.0, f64::max);
    println!("test shapes (α ≠ 1): period error mean {:.3} %, max {:.3} %", 100.0 * mean, 100.0 * worst);
    for (r, e) in test.iter().zip(&errs) {
        assert!(
            e.period < 0.01,
            "shape {} ({:?}, aspect {:.1}): period off by {:.2} %",
            r.index,
            r.shape,
            e.aspect,
            100.0 * e.period
        );
    }
}
