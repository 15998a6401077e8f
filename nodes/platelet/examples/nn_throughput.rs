//! Forward-pass throughput of the coefficient networks (paper 2's architectures, He-initialised
//! weights: the speed does not depend on the values): 165 000 platelets evaluated 20 times, on
//! one thread (the serial path) and on rayon's threads, plain and mirror-averaged (two passes per
//! prediction, `Mlp::with_mirror`).
//!
//! `cargo run --release -p sonoflow-platelet --example nn_throughput`

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sonoflow_platelet::nn::mlp::Mirror;
use sonoflow_platelet::nn::{Mlp, NetworkModel};
use sonoflow_platelet::{CoefficientModel, Rotational, Shape, ShapeSampler, Translational};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let n = Mlp::he_init(&[6, 50, 20, 20, 3], 1)?;
    let n_r = Mlp::he_init(&[5, 20, 20, 20, 1], 2)?;
    let n_s = Mlp::he_init(&[5, 20, 20, 20, 1], 3)?;
    let serial = NetworkModel::new(n.clone(), n_r.clone(), n_s.clone())?;
    let parallel = serial.clone().with_parallel(true);
    let mirrored = NetworkModel::new(
        n.with_mirror(Some(Mirror::platelet_n()))?,
        n_r.with_mirror(Some(Mirror::platelet_shape()))?,
        n_s.with_mirror(Some(Mirror::platelet_shape()))?,
    )?;
    let mirrored_parallel = mirrored.clone().with_parallel(true);
    let (particles, repeats) = (165_000, 20);
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let sampler = ShapeSampler::default();
    let shapes: Vec<Shape> = (0..particles).map(|_| sampler.sample(&mut rng)).collect();
    let psi: Vec<f64> = (0..particles).map(|_| rng.gen_range(0.0..std::f64::consts::TAU)).collect();
    let mut out = vec![Translational::default(); particles];
    let mut rot = vec![Rotational::default(); particles];
    for (name, model) in [
        ("serial (1 thread)", &serial),
        ("rayon", &parallel),
        ("mirror-averaged, serial (1 thread)", &mirrored),
        ("mirror-averaged, rayon", &mirrored_parallel),
    ] {
        model.translational(&shapes, &psi, &mut out); // warm-up: workspaces grow
        let t = Instant::now();
        for _ in 0..repeats {
            model.translational(&shapes, &psi, &mut out);
        }
        let dt = t.elapsed().as_secs_f64();
        let t = Instant::now();
        model.rotational(&shapes, &mut rot);
        let dr = t.elapsed().as_secs_f64();
        println!(
            "{name}: N (6-50-20-20-3) {particles} x {repeats} in {dt:.3} s = {:.2e} particles/s; N_r + N_s once in {dr:.4} s = {:.2e} particles/s",
            (particles * repeats) as f64 / dt,
            particles as f64 / dr
        );
    }
    let sum: f64 = out.iter().map(|c| c.c_d).sum::<f64>() + rot.iter().map(|c| c.c_r).sum::<f64>();
    println!("(checksum {sum:.6e})");
    Ok(())
}
