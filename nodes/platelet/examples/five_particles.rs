//! Paper 2 §5.1 with the shipped networks: prints the five particles' Jeffery periods and y-motion.
//! `cargo run --release -p sonoflow-platelet --example five_particles [-- t_end [coupled]]`
use sonoflow_platelet::dynamics::DynamicsParams;
use sonoflow_platelet::experiments::{curves, jeffery_period, rotation_period, run, RunOptions, Y0};
use sonoflow_platelet::nn::model::NetworkModel;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let t_end: f64 = args.get(1).map(|s| s.parse()).transpose()?.unwrap_or(40.0);
    let coupling = args.get(2).is_some_and(|s| s == "coupled");
    let m = NetworkModel::load_dir(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("weights"))?;
    let c = curves(&m, 8);
    let t0 = std::time::Instant::now();
    let tr =
        run(&m, &RunOptions { t_end, record_every: 40, dynamics: DynamicsParams { coupling, ..Default::default() } })?;
    println!("{:.2} s for {} s of motion; shear rate {:.4} 1/s", t0.elapsed().as_secs_f64(), t_end, tr.shear_rate);
    for k in 0..5 {
        let per = rotation_period(&tr.t, &tr.phi[k]);
        let jp = jeffery_period(tr.shear_rate, c.jeffery_b[k]);
        let (lo, hi) = tr.y[k].iter().fold((f64::MAX, f64::MIN), |(a, b), &y| (a.min(y), b.max(y)));
        let mean = tr.y[k].iter().sum::<f64>() / tr.y[k].len() as f64;
        println!(
            "particle {}: B {:.5}, period {:?} vs Jeffery {:.3} s; y range {:.3e} m, mean − y0 {:.3e} m, final − y0 {:.3e}",
            k + 1, c.jeffery_b[k], per, jp, hi - lo, mean - Y0, tr.y[k].last().copied().unwrap_or(Y0) - Y0
        );
    }
    Ok(())
}
