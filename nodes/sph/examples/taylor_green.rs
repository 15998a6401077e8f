//! Taylor–Green vortex (periodic box, sph-validation.md §d): prints the fitted decay rate of |u|
//! against 8π²/Re, the density error and the smallest pair distance over time.
//!
//! `cargo run --release -p sonoflow-sph --example taylor_green -- [n] [Re] [background_pressure/(ρU²)] [c/U] [t_end]`

use sonoflow_sph::{Real, Solver};
use std::f64::consts::PI;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let get = |i: usize, d: Real| -> Result<Real, Box<dyn std::error::Error>> {
        Ok(a.get(i).map(|s| s.parse::<Real>()).transpose()?.unwrap_or(d))
    };
    let n = get(0, 50.0)? as usize;
    let re = get(1, 100.0)?;
    let pb = get(2, 0.0)?;
    let c = get(3, 10.0)?;
    let t_end = get(4, 1.0)?;
    let dx = 1.0 / n as Real;
    let (p, mut params) = sonoflow_sph::setup::taylor_green(n, re, c, 0.0);
    params.background_pressure = pb;
    params.viscous_term = if std::env::var("VISC").as_deref() == Ok("morris") {
        sonoflow_sph::ViscousTerm::Morris
    } else {
        sonoflow_sph::ViscousTerm::MeanValue
    };
    params.shifting = std::env::var("SHIFT").ok().and_then(|v| v.parse().ok()).unwrap_or(0.0);
    params.density_diffusion = std::env::var("DELTA").ok().and_then(|v| v.parse().ok()).unwrap_or(0.0);
    let mut s = Solver::new(params, p, 0.0)?;
    let e0 = s.diagnostics().kinetic_energy;
    let rate = 8.0 * PI * PI / re;
    let start = std::time::Instant::now();
    let steps = 20;
    for j in 1..=steps {
        let t = t_end * j as Real / steps as Real;
        s.advance_to(t)?;
        let d = s.diagnostics();
        let eff = -(d.kinetic_energy / e0).ln() / (2.0 * t);
        println!(
            "t {t:.3}  E/E0 {:.4} (exact {:.4})  effective rate {eff:.4} (8pi^2/Re {rate:.4})  max|rho/rho0-1| {:.2e}  min pair {:.3} dx  steps {}",
            d.kinetic_energy / e0,
            (-2.0 * rate * t).exp(),
            d.max_density_error,
            d.min_pair_distance / dx,
            d.steps
        );
    }
    println!("wall {:.2} s", start.elapsed().as_secs_f64());
    Ok(())
}
