//! The paper's carotid bifurcation (§2.2) with the SPH solver alone: builds the preset at lattice
//! spacing dx, imposes the synthetic carotid waveform at the inlet and the 54/46 % split at the
//! outlets, runs to `t_end` and prints, at every `every` seconds, the diagnostics (density error,
//! kinetic energy, steps, dt criterion), the mass flux through each opening since the last print
//! and the split of the outflow, and the wall time. Optionally writes a checkpoint at the end.
//!
//! `cargo run --release -p sonoflow-sph --example carotid -- [dx_mm=0.3] [t_end=0.83] [every=0.05] [c=5.5] [shifting=0] [checkpoint_out]`
//! (with `CHECKPOINT_IN`, `t_end` is the duration after the checkpoint's time)
//! Environment: `DELTA` (δ-SPH), `TENSILE`, `PB` (background pressure), `H_OVER_DX` (1.2), `CFL` (0.25),
//! `GEOM=tube` (a straight tube instead), `CHECKPOINT_IN` (resume), `PARALLEL=0` (no rayon), `INTEGRATOR=single` (one evaluation per step), `WALL_LAYERS` (type II layers; default from the support),
//! `PAIRS=symmetric` (the fast evaluator's symmetric pair loop instead of the gather).

use sonoflow_sph::geometry::{carotid_bifurcation, BuildOptions, InitialVelocity};
use sonoflow_sph::{ProfileKind, Real, Solver, SphParams, WaveformSpec};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let get = |i: usize, d: Real| -> Result<Real, Box<dyn std::error::Error>> {
        Ok(a.get(i).map(|s| s.parse::<Real>()).transpose()?.unwrap_or(d))
    };
    let dx = get(0, 0.3)? * 1e-3;
    let t_end = get(1, 0.83)?;
    let every = get(2, 0.05)?;
    let c = get(3, 5.5)?;
    let shifting = get(4, 0.0)?;
    let ckpt_out = a.get(5).cloned();
    let h_over_dx: Real = std::env::var("H_OVER_DX").ok().and_then(|v| v.parse().ok()).unwrap_or(1.2);
    let params = SphParams {
        h: h_over_dx * dx,
        cfl: std::env::var("CFL").ok().and_then(|v| v.parse().ok()).unwrap_or(0.25),
        rho0: 1000.0,
        c,
        mu: 4e-3,
        shifting,
        tensile_correction: std::env::var("TENSILE").ok().and_then(|v| v.parse().ok()).unwrap_or(0.0),
        background_pressure: std::env::var("PB").ok().and_then(|v| v.parse().ok()).unwrap_or(0.0),
        density_diffusion: std::env::var("DELTA").ok().and_then(|v| v.parse().ok()).unwrap_or(0.0),
        dt_max: 1.0,
        parallel: std::env::var("PARALLEL").as_deref() != Ok("0"),
        symmetric_pairs: std::env::var("PAIRS").as_deref() == Ok("symmetric"),
        integrator: if std::env::var("INTEGRATOR").as_deref() == Ok("single") {
            sonoflow_sph::Integrator::SingleEvaluation
        } else {
            sonoflow_sph::Integrator::PredictorCorrector
        },
        ..Default::default()
    };
    let inflow = WaveformSpec::Carotid { peak: 0.39, mean: 0.1875, period: 0.83 }.build()?;
    let opts = BuildOptions {
        inflow,
        profile: ProfileKind::Womersley,
        initial_velocity: InitialVelocity::FullyDeveloped,
        relax_iterations: 200,
        wall_layers: std::env::var("WALL_LAYERS").ok().and_then(|v| v.parse().ok()),
        ..BuildOptions::for_solver(&params, dx)
    };
    let t0 = std::time::Instant::now();
    let geometry = match std::env::var("GEOM").as_deref() {
        Ok("tube") => sonoflow_sph::geometry::straight_tube(0.04, 8e-3, [0.0, 0.02], 0.0),
        _ => carotid_bifurcation(),
    };
    let scene = geometry.build(&opts)?;
    let names: Vec<String> = scene.boundaries.iter().map(|b| b.name.clone()).collect();
    println!(
        "carotid dx {:.3} mm: {} particles ({} fluid), built in {:.2} s; c = {c} m/s, h = {:.3} mm, shifting {shifting}",
        dx * 1e3,
        scene.particles.len(),
        scene.count(sonoflow_sph::ParticleKind::Fluid),
        t0.elapsed().as_secs_f64(),
        params.h * 1e3
    );
    let domain = scene.guard_domain();
    let mut s = match std::env::var("CHECKPOINT_IN") {
        Ok(path) => {
            let ck = sonoflow_sph::Checkpoint::read(std::path::Path::new(&path))?;
            println!("resuming from {path} at t = {} s", ck.header.time);
            Solver::from_checkpoint(params, ck, scene.boundaries, &[])?
        }
        Err(_) => Solver::new(params, scene.particles, 0.0)?.with_open_boundaries(scene.boundaries)?,
    }
    .with_domain(domain);
    let t_begin = s.time();
    let start = std::time::Instant::now();
    let cpu0 = process_cpu_s();
    let steps0 = s.steps();
    let n = (t_end / every).round().max(1.0) as usize;
    let mut last: Vec<Real> = vec![0.0; names.len()];
    let mut total_out = vec![0.0; names.len()];
    for k in 1..=n {
        let t = t_begin + t_end * k as Real / n as Real;
        s.advance_to(t)?;
        let d = s.diagnostics();
        let net: Vec<Real> = d.boundaries.iter().map(|(_, f)| f.net_in()).collect();
        let step: Vec<Real> = net.iter().zip(&last).map(|(a, b)| a - b).collect();
        for (o, v) in total_out.iter_mut().zip(&step) {
            *o += v;
        }
        last = net;
        let out: Real = -step[1..].iter().sum::<Real>();
        let split: Vec<String> = step[1..].iter().map(|v| format!("{:.1} %", -100.0 * v / out)).collect();
        let wall = start.elapsed().as_secs_f64();
        if let Some(j) = s.particles.id.iter().position(|&q| q == d.min_pair_id) {
            let pp = &s.particles;
            let (mut best, mut bk) = (Real::INFINITY, 0);
            for k in 0..pp.len() {
                let r = (pp.x[k] - pp.x[j]).hypot(pp.z[k] - pp.z[j]);
                if k != j && r < best {
                    best = r;
                    bk = k;
                }
            }
            println!(
                "   closest pair now at ({:.2}, {:.2}) mm: {:.2} dx to a {:?}; p = {:.1} Pa, {:.1} Pa; |u| = {:.3} m/s",
                pp.x[j] * 1e3,
                pp.z[j] * 1e3,
                best / dx,
                pp.kind[bk],
                c * c * (pp.rho[j] - 1000.0) + s.params().background_pressure,
                c * c * (pp.rho[bk] - 1000.0) + s.params().background_pressure,
                pp.vx[j].hypot(pp.vz[j])
            );
        }
        println!(
            "t {t:.3} s  fluid {}  max|rho/rho0-1| {:.2e}  KE {:.3e}  vmax {:.3} m/s  min pair {:.2} dx (id {})  steps {}  dt {:.2e} ({:?})  in {:.3e} out {:.3e} split {:?}  guard {}  shift ratio {:.4}  wall {:.0} s ({:.1} steps/s; CPU {:.0} s, {:.1} steps per CPU s)",
            d.n_fluid,
            d.max_density_error,
            d.kinetic_energy,
            d.max_speed,
            d.min_pair_distance / dx,
            d.min_pair_id,
            d.steps,
            d.last_step.map_or(0.0, |r| r.dt),
            d.last_step.map(|r| r.binding),
            step[0],
            out,
            split,
            d.guard_corrections,
            d.shift_ratio,
            wall,
            (d.steps - steps0) as Real / wall,
            process_cpu_s() - cpu0,
            (d.steps - steps0) as Real / (process_cpu_s() - cpu0)
        );
    }
    let out: Real = -total_out[1..].iter().sum::<Real>();
    println!(
        "whole run: inflow {:.4e} kg/m, outflow {:.4e} kg/m, split {}",
        total_out[0],
        out,
        names[1..]
            .iter()
            .zip(&total_out[1..])
            .map(|(n, v)| format!("{n} {:.2} %", -100.0 * v / out))
            .collect::<Vec<_>>()
            .join(", ")
    );
    if let Some(p) = ckpt_out {
        s.checkpoint().write(std::path::Path::new(&p))?;
        println!("checkpoint written to {p}");
    }
    Ok(())
}

/// CPU seconds (user + system) of this process so far, from /proc/self/stat (0 where unavailable):
/// robust to the other core's load, unlike the wall clock.
fn process_cpu_s() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else { return 0.0 };
    // fields after the command name (which is in parentheses): utime and stime are fields 14, 15
    let Some(rest) = stat.rfind(')').map(|i| &stat[i + 2..]) else { return 0.0 };
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |k: usize| f.get(k).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    (ticks(11) + ticks(12)) / 100.0
}
