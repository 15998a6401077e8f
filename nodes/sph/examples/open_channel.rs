//! Plane channel between two open boundaries (inlet and outlet reservoirs): prints the density and
//! velocity along the channel, the mass bookkeeping and the profile error over time.
//!
//! `cargo run --release -p sonoflow-sph --example open_channel -- [u_mean] [t_end] [c]`
use sonoflow_sph::setup::OpenChannelConfig;
use sonoflow_sph::{Real, Solver, WaveformSpec};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let get = |i: usize, d: Real| -> Result<Real, Box<dyn std::error::Error>> {
        Ok(a.get(i).map(|s| s.parse::<Real>()).transpose()?.unwrap_or(d))
    };
    let (u_mean, t_end, c) = (get(0, 0.02)?, get(1, 0.2)?, get(2, 0.5)?);
    // the validation channel of the tests (L = 2 mm, 20 across, 4 mm between the openings)
    let cfg = OpenChannelConfig::validation(WaveformSpec::Constant { value: u_mean }.build()?, true);
    let dx = cfg.dx();
    let params = cfg.solver_params(c);
    let (p, bs) = cfg.build();
    let mut s = Solver::new(params, p, 0.0)?.with_open_boundaries(bs)?;
    for k in 1..=10 {
        let t = t_end * k as Real / 10.0;
        s.advance_to(t)?;
        let d = s.diagnostics();
        let p = &s.particles;
        let nb = 12;
        let (x0, x1) = (-4.0 * dx, cfg.length() + 4.0 * dx);
        let (mut rho, mut u, mut n) = (vec![0.0; nb], vec![0.0; nb], vec![0usize; nb]);
        for i in 0..p.len() {
            if p.kind[i].is_wall() {
                continue;
            }
            let b = (((p.x[i] - x0) / (x1 - x0) * nb as Real).floor().max(0.0) as usize).min(nb - 1);
            rho[b] += p.rho[i] / 1000.0 - 1.0;
            u[b] += p.vx[i];
            n[b] += 1;
        }
        let fmt = |v: &[Real]| {
            v.iter().zip(&n).map(|(a, &k)| format!("{:+.2e}", a / k.max(1) as Real)).collect::<Vec<_>>().join(" ")
        };
        println!("t {t:.3} fluid {} buffer {} max|rho/rho0-1| {:.3e}", d.n_fluid, d.n_buffer, d.max_density_error);
        println!("   rho-1: {}", fmt(&rho));
        println!("   u:     {}", fmt(&u));
        for (name, f) in &d.boundaries {
            println!(
                "   {name}: in {:.4e} out {:.4e} created {} removed {}",
                f.mass_in, f.mass_out, f.created, f.removed
            );
        }
    }
    Ok(())
}
