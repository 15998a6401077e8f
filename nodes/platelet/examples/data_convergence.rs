//! The training data's own convergence error (issue 20): shapes of each resolution class of the
//! data file (the `--refine` rules of `sonoflow platelet data`: n_beta 16, 24 or 32 by aspect
//! max(Lx, Lz) / Ly) are solved again 8 panels finer along the meridian, and every coefficient
//! the networks learn is compared: drag D(0) and D(π/2), lift L(π/4) (relative), the pitching
//! torque t_p (relative to its RMS over the class, since it vanishes for symmetric shapes), t_r,
//! t_s, and the Jeffery period from B = t_s / t_r: the largest |difference| over the class.
//!
//! `cargo run --release -p sonoflow-platelet --example data_convergence [data.jsonl] [shapes per class]`
//! (default: the shipped file, 6 shapes per class; the first in-bounds shapes of each class, and of
//! the generalisation set's thinnest class).

use sonoflow_platelet::dataset::{self, Record, Refinement, Set};
use sonoflow_platelet::experiments::jeffery_period;
use sonoflow_platelet::{solve_shape, ShapeResistance, StokesOptions};

fn fail(msg: String) -> ! {
    eprintln!("data_convergence: {msg}");
    std::process::exit(1)
}

/// (D(0), D(π/2), L(π/4), t_p, t_r, t_s, period) of a solve.
fn quantities(r: &ShapeResistance) -> [f64; 7] {
    let q = std::f64::consts::FRAC_PI_4;
    let tp = r.paper_torque(0.0) / 2.0; // eq 18: T = 2 cos ψ t_p
    let b = r.strain_torque / r.rotation_torque;
    [
        r.paper_drag(0.0),
        r.paper_drag(std::f64::consts::FRAC_PI_2),
        r.paper_lift(q),
        tp,
        r.rotation_torque,
        r.strain_torque,
        jeffery_period(1.0, b),
    ]
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args.first().cloned().unwrap_or_else(|| "nodes/platelet/data/stokes-data.jsonl".into());
    let k: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(6);
    let records = dataset::load(std::path::Path::new(&path)).unwrap_or_else(|e| fail(e.to_string()));
    let rules = Refinement::defaults();
    let base = StokesOptions::default();
    let classes = [(Set::InBounds, 16), (Set::InBounds, 24), (Set::InBounds, 32), (Set::Generalisation, 32)];
    println!("| set | n_beta (vs +8) | shapes | aspect | D(0) | D(π/2) | L(π/4) | t_p (of RMS) | t_r | t_s | period |");
    println!("|---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|");
    for (set, n_beta) in classes {
        let picked: Vec<&Record> = records
            .iter()
            .filter(|r| r.set == set && r.n_beta == Some(n_beta))
            .filter(|r| Refinement::n_beta_for(&rules, base.n_beta, &r.shape) == n_beta)
            .take(k)
            .collect();
        if picked.is_empty() {
            continue;
        }
        let mut max = [0.0f64; 7];
        let mut tp_sq = 0.0;
        let mut tp_err = 0.0f64;
        let (mut a_lo, mut a_hi) = (f64::INFINITY, 0.0f64);
        for r in &picked {
            let fine = solve_shape(&r.shape, &StokesOptions { n_beta: n_beta + 8, ..base })
                .unwrap_or_else(|e| fail(e.to_string()));
            let (q0, q1) = (quantities(&r.resistance), quantities(&fine));
            for j in [0, 1, 2, 4, 5, 6] {
                max[j] = max[j].max((q0[j] / q1[j] - 1.0).abs());
            }
            tp_sq += q1[3] * q1[3];
            tp_err = tp_err.max((q0[3] - q1[3]).abs());
            let a = r.shape.lx.max(r.shape.lz) / r.shape.ly;
            (a_lo, a_hi) = (a_lo.min(a), a_hi.max(a));
        }
        max[3] = tp_err / (tp_sq / picked.len() as f64).sqrt();
        let cells: Vec<String> = max.iter().map(|e| format!("{:.1e}", e)).collect();
        println!(
            "| {set:?} | {n_beta} (vs {}) | {} | {a_lo:.1}–{a_hi:.1} | {} |",
            n_beta + 8,
            picked.len(),
            cells.join(" | ")
        );
    }
}
