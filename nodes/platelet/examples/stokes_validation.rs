//! Validation table of the boundary-element Stokes solver (`sonoflow_platelet::stokes`): closed
//! forms of spheres and spheroids, the sphere in the paper's 50 µm ball, and the self-convergence
//! of the thinnest platelet, for several resolutions, with the solve time per shape.
//!
//! `cargo run --release -p sonoflow-platelet --example stokes_validation [n_beta ...]`

use sonoflow_platelet::spheroid::{jeffery_factor, spheroid_resistance};
use sonoflow_platelet::{solve_shape, Outer, Shape, ShapeResistance, StokesOptions};
use std::f64::consts::PI;
use std::time::Instant;

const MU: f64 = 3e-3;

fn solve(shape: &Shape, n_beta: usize, outer: Outer) -> (ShapeResistance, f64) {
    let o = StokesOptions { n_beta, outer, viscosity: MU };
    let t = Instant::now();
    match solve_shape(shape, &o) {
        Ok(r) => (r, t.elapsed().as_secs_f64()),
        Err(e) => {
            eprintln!("solve failed: {e}");
            std::process::exit(1);
        }
    }
}

fn row(case: &str, q: &str, exact: f64, got: f64) {
    let err = if exact == 0.0 { got.abs() } else { (got - exact).abs() / exact.abs() };
    println!("| {case} | {q} | {exact:.6e} | {got:.6e} | {err:.2e} |");
}

fn main() {
    let mut res: Vec<usize> = std::env::args().skip(1).filter_map(|s| s.parse().ok()).collect();
    if res.is_empty() {
        res = vec![8, 12, 16, 24];
    }
    let ball = |n_beta| Outer::Ball { radius: 50e-6, n_beta };
    // thin platelet reference: the finest resolution
    let thin = Shape::from_um(3.5, 0.15, 3.5, 0.2, 0.2);
    let thin_ref = solve(&thin, 32, Outer::FreeSpace).0;
    let o = StokesOptions::default();
    let t = Instant::now();
    let reps = 3;
    for _ in 0..reps {
        if let Err(e) = solve_shape(&Shape::default(), &o) {
            eprintln!("solve failed: {e}");
            std::process::exit(1);
        }
    }
    println!(
        "default options (n_beta = {}, {} body panels, ball of 50 µm): {:.3} s per shape (mean of {reps}, four right-hand sides)",
        o.n_beta,
        2 * o.n_beta * o.n_beta,
        t.elapsed().as_secs_f64() / reps as f64
    );
    for &n in &res {
        println!("\n### n_beta = {n} ({} body panels)\n", 2 * n * n);
        println!("| case | quantity | exact | computed | rel. error |");
        println!("|---|---|---|---|---|");
        let a = 1.5e-6;
        let (r, _) = solve(&Shape::from_um(3.0, 3.0, 3.0, 1.0, 1.0), n, Outer::FreeSpace);
        row("sphere a=1.5 µm", "drag", 6.0 * PI * MU * a, r.force_per_flow[0][0]);
        row("sphere a=1.5 µm", "torque", 8.0 * PI * MU * a.powi(3), r.rotation_torque);
        // prolate r = 3 along x
        let (r, _) = solve(&Shape::from_um(3.0, 1.0, 1.0, 1.0, 1.0), n, Outer::FreeSpace);
        let ex = spheroid_resistance(MU, 1.5e-6, 0.5e-6);
        row("prolate 3:1", "drag along axis", ex.axial, r.force_per_flow[0][0]);
        row("prolate 3:1", "drag across", ex.transverse, r.force_per_flow[1][1]);
        row("prolate 3:1", "rotation (equatorial)", ex.rotation_equatorial, r.rotation_torque);
        row("prolate 3:1", "Jeffery B = c_s/c_r", jeffery_factor(1.5, 0.5), r.strain_torque / r.rotation_torque);
        for (name, ly) in [("oblate 1:6", 0.5), ("oblate 1:20", 0.15)] {
            let (r, _) = solve(&Shape::from_um(3.0, ly, 3.0, 1.0, 1.0), n, Outer::FreeSpace);
            let ex = spheroid_resistance(MU, 0.5 * ly * 1e-6, 1.5e-6);
            row(name, "drag edgewise (x)", ex.transverse, r.force_per_flow[0][0]);
            row(name, "drag broadside (y)", ex.axial, r.force_per_flow[1][1]);
            row(name, "rotation (equatorial)", ex.rotation_equatorial, r.rotation_torque);
            row(name, "Jeffery B = c_s/c_r", jeffery_factor(1.5, 0.5 * ly), r.strain_torque / r.rotation_torque);
        }
        let (r, _) = solve(&Shape::from_um(3.0, 3.0, 3.0, 1.0, 1.0), n, ball(12));
        let l: f64 = 1.5 / 50.0;
        let k = (1.0 - l.powi(5)) / (1.0 - 2.25 * l + 2.5 * l.powi(3) - 2.25 * l.powi(5) + l.powi(6));
        row("sphere in 50 µm ball", "drag", 6.0 * PI * MU * a * k, r.force_per_flow[0][0]);
        row("sphere in 50 µm ball", "torque", 8.0 * PI * MU * a.powi(3) / (1.0 - l.powi(3)), r.rotation_torque);
        let (r, _) = solve(&thin, n, Outer::FreeSpace);
        row("thin 3.5×0.15, α=0.2 (vs n_beta=32)", "drag x", thin_ref.force_per_flow[0][0], r.force_per_flow[0][0]);
        row("thin 3.5×0.15, α=0.2 (vs n_beta=32)", "drag y", thin_ref.force_per_flow[1][1], r.force_per_flow[1][1]);
        row("thin 3.5×0.15, α=0.2 (vs n_beta=32)", "rotation", thin_ref.rotation_torque, r.rotation_torque);
        row("thin 3.5×0.15, α=0.2 (vs n_beta=32)", "strain", thin_ref.strain_torque, r.strain_torque);
        let (r, t) = solve(&Shape::default(), n, ball(12));
        println!(
            "\nmean platelet in the 50 µm ball: D(0) = {:.2}, D(π/2) = {:.2}, L(π/4) = {:.2}, T_r = {:.1} (paper units); solve {:.3} s per shape",
            r.paper_drag(0.0),
            r.paper_drag(0.5 * PI),
            r.paper_lift(0.25 * PI),
            r.paper_rotational_torque(),
            t
        );
    }
}
