use sonoflow_platelet::{solve_shape, Outer, Shape, StokesOptions};
use std::f64::consts::PI;
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let nb: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(12);
    let mu = 3e-3;
    let a = 1.5e-6;
    for (name, outer) in [("free", Outer::FreeSpace), ("ball", Outer::Ball { radius: 50e-6, n_beta: 10 })] {
        let o = StokesOptions { n_beta: nb, outer, viscosity: mu };
        let t = std::time::Instant::now();
        let r = solve_shape(&Shape::from_um(3.0, 3.0, 3.0, 1.0, 1.0), &o).expect("solve");
        let dt = t.elapsed().as_secs_f64();
        let f0 = 6.0 * PI * mu * a;
        let t0 = 8.0 * PI * mu * a.powi(3);
        println!("{name} nb={nb} panels={:?} t={dt:.3}s drag {:.6} {:.6} rot {:.6} strain {:.3e} K {:?}", r.panels, r.force_per_flow[0][0] / f0, r.force_per_flow[1][1] / f0, r.rotation_torque / t0, r.strain_torque / t0, r.force_per_flow);
        let r = solve_shape(&Shape::default(), &o).expect("solve");
        println!("  mean platelet D0 {:.3} D90 {:.3} Tr {:.3} L0 {:.2e} L45 {:.3} T {:.2e}", r.paper_drag(0.0), r.paper_drag(PI / 2.0), r.paper_rotational_torque(), r.paper_lift(0.0), r.paper_lift(PI/4.0), r.paper_torque(0.3));
    }
}
