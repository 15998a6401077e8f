//! Body-force Poiseuille start-up (Morris, Fox & Zhu 1997) at several resolutions and sound speeds:
//! prints E∞ and E₂ (% of u_max) against the series solution.
//!
//! `cargo run --release -p sonoflow-sph --example poiseuille -- [t_end] [c] [n_across...]`
//! (`CONTINUOUS=1`: eq 12's constant from the continuous second moment instead of the lattice one)

use sonoflow_sph::analytic::poiseuille;
use sonoflow_sph::setup::ChannelConfig;
use sonoflow_sph::{Period, Real, Solver, SphParams};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let t_end: Real = args.first().map(|s| s.parse()).transpose()?.unwrap_or(0.225);
    let c: Real = args.get(1).map(|s| s.parse()).transpose()?.unwrap_or(1e-2);
    let ns: Vec<usize> = if args.len() > 2 {
        args[2..].iter().map(|s| s.parse()).collect::<Result<_, _>>()?
    } else {
        vec![10, 20, 40, 80]
    };
    let (l, nu, f, rho0) = (1e-3, 1e-6, 2e-4, 1000.0);
    let umax = f * l * l / (8.0 * nu);
    for n in ns {
        let cfg = ChannelConfig { width: l, n_across: n, n_along: 12, wall_layers: 3, rho0, top_wall_velocity: 0.0 };
        let dx = cfg.dx();
        let params = SphParams {
            h: 1.2 * dx,
            rho0,
            c,
            mu: nu * rho0,
            body_force: [f, 0.0],
            periodic_x: Some(Period { min: 0.0, length: cfg.length() }),
            dt_max: 1.0,
            integrator: if std::env::var("INTEGRATOR").as_deref() == Ok("single") {
                sonoflow_sph::Integrator::SingleEvaluation
            } else {
                sonoflow_sph::Integrator::PredictorCorrector
            },
            viscous_constant: if std::env::var("CONTINUOUS").is_ok() {
                sonoflow_sph::ViscousConstant::SecondMoment
            } else {
                sonoflow_sph::ViscousConstant::LatticeMoment
            },
            ..Default::default()
        };
        let mut s = Solver::new(params, cfg.build(), 0.0)?;
        let start = std::time::Instant::now();
        let rep = s.advance_to(t_end)?;
        let secs = start.elapsed().as_secs_f64();
        let p = &s.particles;
        let (mut einf, mut e2, mut cnt) = (0.0 as Real, 0.0, 0);
        for j in 1..n {
            let z = j as Real * dx;
            let (mut sum, mut k) = (0.0, 0);
            for i in 0..p.len() {
                if !p.kind[i].is_wall() && ((p.z[i] - z).abs() < 0.5 * dx) {
                    sum += p.vx[i];
                    k += 1;
                }
            }
            if k > 0 {
                let e = (sum / k as Real - poiseuille(z, t_end, f, nu, l, 200)).abs() / umax;
                einf = einf.max(e);
                e2 += e * e;
                cnt += 1;
            }
        }
        let e2 = (e2 / cnt.max(1) as Real).sqrt();
        let steps = rep.map(|r| r.steps).unwrap_or(0);
        println!(
            "n_across {n:3}  c {c:.1e}  t {t_end}  E_inf {:.4} %  E2 {:.4} %  steps {steps}  wall {secs:.2} s",
            100.0 * einf,
            100.0 * e2
        );
    }
    Ok(())
}
