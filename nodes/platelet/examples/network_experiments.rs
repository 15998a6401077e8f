//! One training run of a platelet network on the shipped data with a given [`TrainConfig`], and
//! its errors on the training, validation, test and generalisation samples (the measure of the
//! training report, in %): the harness of the pitching-torque study (README, "Networks").
//! Recipes are chosen on the validation samples (part of the training shapes), never on the test
//! shapes.
//!
//! `cargo run --release -p sonoflow-platelet --example network_experiments -- \
//!     [n|n_r|n_s|n_b|n_b_plain] ['{"epochs": 800, "patience": 0, "refine_iterations": 500, ...}'] [data.jsonl] [angles]`
//!
//! `n_s` trains N_s on t_s, `n_b` on the shape factor ln((1 − B)/(1 − B_e)), `n_b_plain` on
//! ln(1 − B) ([`StrainTarget`]); for these three the Jeffery period from N_s's prediction (with the
//! data's t_r, so that only N_s's error counts) is compared with the data's, per aspect class.
//!
//! The JSON is a `TrainConfig` (missing fields: defaults); `augment_mirror` / `average_mirror`
//! without a `mirror` use the platelet's ([`Mirror::platelet_n`] for N, [`Mirror::platelet_shape`]
//! for N_r and N_s).

use sonoflow_platelet::dataset::{self, NetworkData, Record};
use sonoflow_platelet::experiments::jeffery_period;
use sonoflow_platelet::nn::mlp::Mirror;
use sonoflow_platelet::nn::model::{shape_inputs, StrainTarget};
use sonoflow_platelet::nn::train::{train, validation_indices, TrainConfig};
use sonoflow_platelet::nn::{evaluate, Dataset};
use std::time::Instant;

fn fail(msg: String) -> ! {
    eprintln!("network_experiments: {msg}");
    std::process::exit(1)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let which = args.first().map_or("n", String::as_str).to_string();
    let mut cfg: TrainConfig = match args.get(1) {
        Some(j) => serde_json::from_str(j).unwrap_or_else(|e| fail(format!("config `{j}`: {e}"))),
        None => TrainConfig::default(),
    };
    let path = args.get(2).cloned().unwrap_or_else(|| "nodes/platelet/data/stokes-data.jsonl".into());
    let angles: usize = match args.get(3).map(|a| a.parse()) {
        None => 4,
        Some(Ok(a)) => a,
        Some(Err(e)) => fail(format!("angles: {e}")),
    };
    type Pick = fn(&NetworkData) -> &Dataset;
    let (sizes, pick, outputs): (Vec<usize>, Pick, Vec<&str>) = match which.as_str() {
        "n" => (vec![6, 50, 20, 20, 3], |d| &d.n, vec!["d", "l", "t_p"]),
        "n_r" => (vec![5, 20, 20, 20, 1], |d| &d.n_r, vec!["t_r"]),
        "n_s" | "n_b" | "n_b_plain" => (vec![5, 20, 20, 20, 1], |d| &d.n_s, vec!["y"]),
        w => fail(format!("network `{w}`: expected n, n_r, n_s, n_b or n_b_plain")),
    };
    let target = match which.as_str() {
        "n_b" => Some(StrainTarget::ShapeFactor),
        "n_b_plain" => Some(StrainTarget::LogOneMinusB),
        "n_s" => Some(StrainTarget::StrainTorque),
        _ => None,
    };
    if (cfg.augment_mirror || cfg.average_mirror) && cfg.mirror.is_none() {
        cfg.mirror = Some(if which == "n" { Mirror::platelet_n() } else { Mirror::platelet_shape() });
    }
    let records = dataset::load(std::path::Path::new(&path)).unwrap_or_else(|e| fail(e.to_string()));
    let (training, test) = dataset::split_by_shape(&records, 0.2, 1).unwrap_or_else(|e| fail(e.to_string()));
    let gen: Vec<_> = records.iter().filter(|r| r.set == dataset::Set::Generalisation).collect();
    // the angles are drawn from the tool's seed (1), as `sonoflow platelet train --seed 1` does
    let mut dtr = dataset::network_datasets(&training, angles, 1).unwrap_or_else(|e| fail(e.to_string()));
    let mut dte = dataset::network_datasets(&test, 4, 1).unwrap_or_else(|e| fail(e.to_string()));
    let mut dg = dataset::network_datasets(&gen, 4, 1).unwrap_or_else(|e| fail(e.to_string()));
    if let Some(t) = target {
        let build = |rs: &[&Record]| dataset::strain_dataset(rs, t).unwrap_or_else(|e| fail(e.to_string()));
        (dtr.n_s, dte.n_s, dg.n_s) = (build(&training), build(&test), build(&gen));
    }
    let t0 = Instant::now();
    let (net, outcome) = train(&sizes, pick(&dtr), &cfg).unwrap_or_else(|e| fail(e.to_string()));
    let secs = t0.elapsed().as_secs_f64();
    let val = pick(&dtr).subset(&validation_indices(pick(&dtr), &cfg));
    println!(
        "{which} {}: {secs:.1} s, {} epochs (best {}), refine {} (best {}), validation loss {:.3e}",
        serde_json::to_string(&cfg).unwrap_or_default(),
        outcome.epochs_run,
        outcome.best_epoch,
        outcome.refine_iterations_run,
        outcome.refine_best_iteration,
        outcome.best_validation_loss
    );
    let sets: [(&str, &Dataset); 4] =
        [("training", pick(&dtr)), ("validation", &val), ("test", pick(&dte)), ("generalisation", pick(&dg))];
    for (k, name) in outputs.iter().enumerate() {
        let mut line = format!("  {name:4}");
        for (set, d) in &sets {
            let e = evaluate(&net, d).unwrap_or_else(|e| fail(e.to_string()))[k];
            line.push_str(&format!(
                " | {set} rms {:.3}/{:.2} rel {:.3}/{:.2}",
                e.mean_rms_pct, e.max_rms_pct, e.mean_rel_pct, e.max_rel_pct
            ));
        }
        println!("{line}");
    }
    if let Some(t) = target {
        // Jeffery period from N_s's prediction and the data's t_r, against the data's
        for (set, recs) in [("test", &test), ("generalisation", &gen)] {
            let mut by_class = [(0usize, 0.0f64, 0.0f64); 4];
            for r in recs.iter() {
                let (c_r, c_s) = (r.resistance.rotation_torque, r.resistance.strain_torque);
                let mut y = [0.0];
                net.predict(&shape_inputs(&r.shape), &mut y).unwrap_or_else(|e| fail(e.to_string()));
                // t_r in eq 18's units (800 t_r = T_r at 2π rad/s; only the ratio to t_s matters)
                let t_r = c_r * 2.0 * std::f64::consts::PI / 1e-21 / 800.0;
                let b = t.strain_torque(&r.shape, t_r, y[0]) / t_r;
                // B ≥ 1 (possible for t_s ≥ t_r): no tumbling at all, an infinite period error
                let e = (jeffery_period(1.0, b) / jeffery_period(1.0, c_s / c_r) - 1.0).abs();
                let e = if e.is_finite() { e } else { f64::INFINITY };
                let aspect = r.shape.lx.max(r.shape.lz) / r.shape.ly;
                let k = [6.0, 10.0, 17.0].iter().filter(|&&a| aspect >= a).count();
                by_class[k] = (by_class[k].0 + 1, by_class[k].1 + e, by_class[k].2.max(e));
            }
            let cells: Vec<String> = ["< 6", "6-10", "10-17", ">= 17"]
                .iter()
                .zip(by_class)
                .map(|(l, (n, sum, max))| {
                    format!(
                        "aspect {l}: n {n}, period err mean {:.3} % max {:.3} %",
                        100.0 * sum / n.max(1) as f64,
                        100.0 * max
                    )
                })
                .collect();
            println!("  {set}: {}", cells.join(" | "));
        }
    }
}
