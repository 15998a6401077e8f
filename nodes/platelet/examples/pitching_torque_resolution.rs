//! How accurate are the training targets themselves? Re-solves the first `count` test shapes of
//! the shipped data (the split of `sonoflow platelet train`: 20 % by shape, seed 1) at finer
//! boundary-element resolutions and reports, per eq 18 output, |y(data) − y(fine)| / rms(y), the
//! error measure of the training report (rms over the whole test set). Also checks the mirror
//! symmetry (α_top ↔ α_bot) the trainer relies on against the solver.
//!
//! `cargo run --release -p sonoflow-platelet --example pitching_torque_resolution -- \
//!     [data.jsonl] [count] [n_beta/ball_n_beta ...]`   (default: the shipped file, 24, 24/12 32/12 32/16)

use sonoflow_platelet::dataset::{self, Record};
use sonoflow_platelet::nn::model::{rotational_from_si, translational_from_si};
use sonoflow_platelet::{solve_shape, Outer, Shape, ShapeResistance, StokesOptions};
use std::time::Instant;

/// Eq 18 outputs that do not depend on ψ, in paper units: d(0) = D(0)/60, d(π/2) = D(π/2)/80,
/// l = (K_yy − K_xx)/20 (L(ψ)/(10 sin 2ψ)), t_p = T_x/2 (T(ψ)/(2 cos ψ)), t_r = T_r/800.
fn outputs(r: &ShapeResistance) -> [f64; 5] {
    let x = translational_from_si(&r.translational(0.0));
    let y = translational_from_si(&r.translational(std::f64::consts::FRAC_PI_2));
    let [t_r, _] = rotational_from_si(&r.rotational());
    [x[0] / 60.0, y[0] / 80.0, (y[0] - x[0]) / 20.0, x[2] / 2.0, t_r / 800.0]
}

const NAMES: [&str; 5] = ["drag d(0)", "drag d(π/2)", "lift l", "pitching torque t_p", "rotational torque t_r"];

fn fail(msg: String) -> ! {
    eprintln!("pitching_torque_resolution: {msg}");
    std::process::exit(1)
}

fn solve(shape: &Shape, n_beta: usize, ball: usize) -> (ShapeResistance, f64) {
    let o = StokesOptions {
        n_beta,
        outer: Outer::Ball { radius: sonoflow_platelet::stokes::PAPER_BALL_RADIUS, n_beta: ball },
        ..StokesOptions::default()
    };
    let t = Instant::now();
    match solve_shape(shape, &o) {
        Ok(r) => (r, t.elapsed().as_secs_f64()),
        Err(e) => fail(format!("solve failed (n_beta {n_beta}, ball {ball}): {e}")),
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args.first().cloned().unwrap_or_else(|| "nodes/platelet/data/stokes-data.jsonl".into());
    let count: usize = match args.get(1).map(|s| s.parse()) {
        None => 24,
        Some(Ok(n)) if n > 0 => n,
        Some(_) => fail(format!("count `{}` is not a positive integer", args[1])),
    };
    let mut levels: Vec<(usize, usize)> = Vec::new();
    for a in args.iter().skip(2) {
        let parsed = a.split_once('/').and_then(|(b, o)| Some((b.parse().ok()?, o.parse().ok()?)));
        match parsed {
            Some(l) => levels.push(l),
            None => fail(format!("resolution `{a}` is not n_beta/ball_n_beta (e.g. 32/12)")),
        }
    }
    if levels.is_empty() {
        levels = vec![(24, 12), (32, 12), (32, 16)];
    }
    let records = dataset::load(std::path::Path::new(&path)).unwrap_or_else(|e| fail(e.to_string()));
    let (_, test) = dataset::split_by_shape(&records, 0.2, 1).unwrap_or_else(|e| fail(e.to_string()));
    let rms: Vec<f64> = (0..5)
        .map(|k| (test.iter().map(|r| outputs(&r.resistance)[k].powi(2)).sum::<f64>() / test.len() as f64).sqrt())
        .collect();
    println!("data: {path}, {} test shapes; rms over them: {rms:.5?}", test.len());

    // mirror check: the shape with α_top ↔ α_bot at the data's resolution
    println!("\n## Mirror symmetry (α_top ↔ α_bot), n_beta 16, ball 12\n");
    println!("| shape | K_xx | K_yy | T_x (flips) | c_r | c_s | y_c (flips) |\n|---|---:|---:|---:|---:|---:|---:|");
    for r in test.iter().take(3) {
        let s = r.shape;
        let m = Shape { alpha_top: s.alpha_bot, alpha_bot: s.alpha_top, ..s };
        let (a, _) = solve(&s, 16, 12);
        let (b, _) = solve(&m, 16, 12);
        let rel = |x: f64, y: f64| (x - y).abs() / x.abs().max(y.abs()).max(f64::MIN_POSITIVE);
        println!(
            "| {} | {:.1e} | {:.1e} | {:.1e} | {:.1e} | {:.1e} | {:.1e} |",
            r.index,
            rel(a.force_per_flow[0][0], b.force_per_flow[0][0]),
            rel(a.force_per_flow[1][1], b.force_per_flow[1][1]),
            rel(a.torque_per_flow[0], -b.torque_per_flow[0]),
            rel(a.rotation_torque, b.rotation_torque),
            rel(a.strain_torque, b.strain_torque),
            rel(a.centre_of_mass_y, -b.centre_of_mass_y),
        );
    }

    println!("\n## Data (n_beta 16, ball 12) against finer solves, first {count} test shapes\n");
    let shapes: Vec<&Record> = test.iter().copied().take(count).collect();
    let mut fine: Vec<Vec<[f64; 5]>> = vec![Vec::new(); levels.len()];
    let mut secs = vec![0.0; levels.len()];
    for (i, r) in shapes.iter().enumerate() {
        let data = outputs(&r.resistance);
        let mut line = format!("shape {:4} t_p: data {:+.6}", r.index, data[3]);
        for (j, &(nb, ball)) in levels.iter().enumerate() {
            let (res, t) = solve(&r.shape, nb, ball);
            let y = outputs(&res);
            line.push_str(&format!(", {nb}/{ball} {:+.6}", y[3]));
            fine[j].push(y);
            secs[j] += t;
        }
        eprintln!("{}/{}: {line}", i + 1, shapes.len());
    }
    println!("|y(16/12) − y(fine)| / rms(y) over the test set, %: mean / max\n");
    let mut head = String::from("| output |");
    let mut rule = String::from("|---|");
    for &(nb, ball) in &levels {
        head.push_str(&format!(" vs {nb}/{ball} |"));
        rule.push_str("---:|");
    }
    println!("{head}\n{rule}");
    for k in 0..5 {
        let mut row = format!("| {} |", NAMES[k]);
        for f in &fine {
            let e: Vec<f64> =
                shapes.iter().zip(f).map(|(r, y)| 100.0 * (outputs(&r.resistance)[k] - y[k]).abs() / rms[k]).collect();
            let mean = e.iter().sum::<f64>() / e.len() as f64;
            let max = e.iter().fold(0.0f64, |a, &b| a.max(b));
            row.push_str(&format!(" {mean:.4} / {max:.4} |"));
        }
        println!("{row}");
    }
    // the finer levels against the finest one: how converged is the finest?
    if let Some(last) = fine.last() {
        let (nb, ball) = levels[levels.len() - 1];
        println!("\nt_p of each level against {nb}/{ball}, % of rms: mean / max");
        for (j, f) in fine.iter().enumerate() {
            let e: Vec<f64> = f.iter().zip(last).map(|(a, b)| 100.0 * (a[3] - b[3]).abs() / rms[3]).collect();
            let mean = e.iter().sum::<f64>() / e.len().max(1) as f64;
            let max = e.iter().fold(0.0f64, |a, &b| a.max(b));
            println!("- {}/{}: {mean:.4} / {max:.4}", levels[j].0, levels[j].1);
        }
    }
    println!();
    for (j, &(nb, ball)) in levels.iter().enumerate() {
        println!("solve time at {nb}/{ball}: {:.2} s per shape", secs[j] / shapes.len().max(1) as f64);
    }
}
