//! Lid-driven cavity (closed box, [`sonoflow_sph::setup::CavityConfig`]): prints, every half
//! convective time L/U, the density error, the smallest pair distance, the guard's corrections and
//! the kinetic energy; with the library defaults, or the paper's scheme with `SCHEME=paper`
//! (`SHIFT=…`, `DELTA=…` override the shifting coefficient and δ).
//!
//! `cargo run --release -p sonoflow-sph --example cavity -- [n=50] [Re=100] [t_end/(L/U)=30]`

use sonoflow_sph::setup::CavityConfig;
use sonoflow_sph::{Real, Scheme};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let get = |i: usize, d: Real| -> Result<Real, Box<dyn std::error::Error>> {
        Ok(a.get(i).map(|s| s.parse::<Real>()).transpose()?.unwrap_or(d))
    };
    let n = get(0, 50.0)? as usize;
    let re = get(1, 100.0)?;
    let t_end = get(2, 30.0)?;
    let cfg = CavityConfig::new(1.0, 1.0, re, n);
    let scheme = if std::env::var("SCHEME").as_deref() == Ok("paper") { Scheme::Paper } else { Scheme::Stabilised };
    let mut params = scheme.apply(cfg.solver_params());
    if let Some(v) = std::env::var("SHIFT").ok().and_then(|v| v.parse().ok()) {
        params.shifting = v;
    }
    if let Some(v) = std::env::var("DELTA").ok().and_then(|v| v.parse().ok()) {
        params.density_diffusion = v;
    }
    println!("cavity Re {re}, {n} spacings per side, shifting {}, delta {}", params.shifting, params.density_diffusion);
    let mut s = cfg.solver(params)?;
    let start = std::time::Instant::now();
    let mut t = 0.0;
    while t < t_end - 1e-9 {
        t = (t + 0.5).min(t_end);
        let r = s.advance_to(t * cfg.time_unit());
        let d = s.diagnostics();
        println!(
            "t {t:5.1} L/U  max|rho/rho0-1| {:.2e}  min pair {:.3} dx  guard {}  outside {}  KE {:.4e}  steps {}  wall {:.1} s",
            d.max_density_error,
            d.min_pair_distance / cfg.dx(),
            d.guard_corrections,
            cfg.fluid_outside(&s.particles),
            d.kinetic_energy,
            d.steps,
            start.elapsed().as_secs_f64()
        );
        r?;
    }
    Ok(())
}
