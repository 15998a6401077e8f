//! Paper 2 section 5.2 performance test of the particle dynamics: ~165 000 platelets with shapes
//! from `ShapeSampler` seeded uniformly in a 2 mm × 12 mm channel with the parabolic flow (the 25 %
//! stenosis comes later), 10 macro steps × 20 sub-steps of 0.25 ms, coefficients every 10th
//! sub-step from the trained networks in `nodes/platelet/weights` (`MODEL=standin`: the
//! closed-form `DiscStandIn`). Prints the time split into advection, collisions and coefficient
//! evaluation. Serial by default (the advection runs on `threads` workers if given).
//!
//! `cargo run --release -p sonoflow-platelet --example platelet_bench [-- N [radius_factor [analytic|lattice [threads [coupled|decoupled [sort|nosort]]]]]]`
//! (N particles, default 165000; collision radius = factor × Lx, default 1 as Remark 1 reads;
//! `lattice` samples the channel onto a 10 µm lattice and uses eq 12 as Algorithm 2 step 2 does;
//! `threads` advection workers, default 1; `coupled` turns the rotation–translation coupling on;
//! the particles are sorted spatially every macro step unless `nosort`; the sort is counted as
//! collision time).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sonoflow_platelet::dynamics::{
    CarrierFlow, Channel, DiscStandIn, Dynamics, DynamicsParams, LatticeField, ParticleState, Particles, Timings,
    DEFAULT_DENSITY,
};
use sonoflow_platelet::ShapeSampler;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let n: usize = args.get(1).map(|s| s.parse()).transpose()?.unwrap_or(165_000);
    let factor: f64 = args.get(2).map(|s| s.parse()).transpose()?.unwrap_or(1.0);
    let use_lattice = args.get(3).is_some_and(|s| s == "lattice");
    let threads: usize = args.get(4).map(|s| s.parse()).transpose()?.unwrap_or(1);
    let coupling = args.get(5).is_some_and(|s| s == "coupled");
    let spatial_sort = args.get(6).is_none_or(|s| s != "nosort");
    let (length, height) = (12e-3, 2e-3);
    let channel = Channel::default();
    channel.validate()?;
    let lattice;
    let flow: &dyn CarrierFlow = if use_lattice {
        let h = 1e-5;
        lattice = LatticeField::from_flow(
            &channel,
            0.0,
            [0.0, 0.0],
            h,
            (length / h).round() as usize + 1,
            (height / h).round() as usize + 1,
        )?;
        &lattice
    } else {
        &channel
    };
    // The trained networks shipped in `nodes/platelet/weights` (MODEL=standin: the closed-form
    // stand-in instead).
    let standin = DiscStandIn::default();
    let network;
    let model: &dyn sonoflow_platelet::CoefficientModel = if std::env::var("MODEL").is_ok_and(|m| m == "standin") {
        &standin
    } else {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("weights");
        network = sonoflow_platelet::nn::model::NetworkModel::load_dir(&dir)?;
        &network
    };
    let sampler = ShapeSampler::default();
    let mut rng = ChaCha8Rng::seed_from_u64(2024);

    let t_seed = Instant::now();
    let mut p = Particles::new(DEFAULT_DENSITY, factor)?;
    p.reserve(n);
    for _ in 0..n {
        let shape = sampler.sample(&mut rng);
        let x = [rng.gen_range(0.0..length), rng.gen_range(0.0..height)];
        let f = flow.sample(x, 0.0);
        p.push(shape, ParticleState { x, phi: rng.gen_range(0.0..std::f64::consts::TAU), v: f.v, omega: f.omega })?;
    }
    let seed_s = t_seed.elapsed().as_secs_f64();

    // 20 sub-steps of 0.25 ms, coefficients every 10th
    let params = DynamicsParams { threads, coupling, spatial_sort, ..Default::default() };
    let mut d = Dynamics::new(params)?;
    let macro_k = params.sub_step * params.sub_steps as f64;
    let mut total = Timings::default();
    println!(
        "{n} particles, {threads} advection thread(s), coupling {coupling}, spatial sort {spatial_sort}, collision radius {factor} Lx, flow: {}",
        if use_lattice { "lattice 10 µm (eq 12)" } else { "analytic channel" }
    );
    println!(
        "{:>5} {:>10} {:>10} {:>12} {:>8} {:>9}",
        "step", "advect s", "collide s", "coeffs s", "pairs", "impulses"
    );
    let t_run = Instant::now();
    for step in 0..10 {
        let tm = d.macro_step(&mut p, flow, model, step as f64 * macro_k)?;
        println!(
            "{:>5} {:>10.3} {:>10.3} {:>12.3} {:>8} {:>9}",
            step,
            tm.advection.as_secs_f64(),
            tm.collisions.as_secs_f64(),
            tm.coefficients.as_secs_f64(),
            tm.pairs,
            tm.impulses
        );
        total += tm;
    }
    let run_s = t_run.elapsed().as_secs_f64();
    let per = |s: f64| 1e9 * s / (n as f64 * 200.0);
    println!();
    println!("{:<28} {:>9} {:>18}", "part", "total s", "ns/particle/step");
    for (name, s) in [
        ("advection", total.advection.as_secs_f64()),
        ("collisions + walls", total.collisions.as_secs_f64()),
        (
            if model.name() == "network" { "coefficients (networks)" } else { "coefficients (stand-in)" },
            total.coefficients.as_secs_f64(),
        ),
        ("all 200 sub-steps", run_s),
    ] {
        println!("{name:<28} {s:>9.3} {:>18.1}", per(s));
    }
    println!(
        "(seeding {seed_s:.3} s; overlapping pairs over the run {}, impulses {}, wall hits {})",
        total.pairs, total.impulses, total.wall_hits
    );
    Ok(())
}
