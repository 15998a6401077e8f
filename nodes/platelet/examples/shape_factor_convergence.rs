//! Convergence of the shape factor B = c_s / c_r, and of the Jeffery period it sets, with the
//! solver's resolution `n_beta`, for thin platelets (issue 20).
//!
//! The tumbling period in simple shear is 4π / (γ̇ √(1 − B²)): its relative error is about
//! B δB / (1 − B²), r²/4 times the error of B for an ellipsoid of aspect r. For each shape
//! (ellipsoids α = 1, where Jeffery's B = (Lx² − Ly²)/(Lx² + Ly²) is exact in free space, and
//! concave/convex platelets α = 0.2, 2) the period factor 1/√(1 − B²) at each `n_beta` is compared
//! with the finest resolution and, for α = 1, with Jeffery's closed form. The solves use the
//! paper's 50 µm ball, as the training data do.
//!
//! `cargo run --release -p sonoflow-platelet --example shape_factor_convergence [n_beta ...]`
//! (default 16 24 32 40; the finest is the reference).

use sonoflow_platelet::{solve_shape, Shape, StokesOptions};
use std::time::Instant;

fn main() {
    let mut res: Vec<usize> = std::env::args().skip(1).filter_map(|s| s.parse().ok()).collect();
    if res.is_empty() {
        res = vec![16, 24, 32, 40];
    }
    res.sort_unstable();
    let shapes = [
        (3.0, 0.15, 3.0, 1.0),
        (3.0, 0.2, 3.0, 1.0),
        (3.0, 0.3, 3.0, 1.0),
        (3.5, 0.15, 2.5, 1.0),
        (2.5, 0.15, 3.5, 1.0),
        (3.0, 0.15, 3.0, 0.2),
        (3.0, 0.2, 3.0, 0.2),
        (3.0, 0.3, 3.0, 0.2),
        (3.0, 0.15, 3.0, 2.0),
        (3.0, 0.3, 3.0, 2.0),
    ];
    print!("| Lx, Ly, Lz (µm), α | r = Lx/Ly |");
    for n in &res {
        print!(" n_beta {n}: period error vs finest |");
    }
    println!(" finest vs Jeffery | time per solve (s) |");
    println!("|---|---:|{}---:|---|", "---:|".repeat(res.len()));
    for (lx, ly, lz, a) in shapes {
        let shape = Shape::from_um(lx, ly, lz, a, a);
        let mut factors = Vec::new();
        let mut times = Vec::new();
        for &n in &res {
            let o = StokesOptions { n_beta: n, ..StokesOptions::default() };
            let t = Instant::now();
            let r = match solve_shape(&shape, &o) {
                Ok(r) => r,
                Err(e) => {
                    eprintln!("solve failed: {e}");
                    std::process::exit(1);
                }
            };
            times.push(t.elapsed().as_secs_f64());
            let b = r.strain_torque / r.rotation_torque;
            factors.push((b, 1.0 / (1.0 - b * b).sqrt()));
        }
        let (b_ref, p_ref) = factors[factors.len() - 1];
        print!("| {lx}, {ly}, {lz}, {a} | {:.1} |", lx / ly);
        for (_, p) in &factors {
            print!(" {:+.3} % |", 100.0 * (p / p_ref - 1.0));
        }
        let jeff = if a == 1.0 {
            let bj = (lx * lx - ly * ly) / (lx * lx + ly * ly);
            format!("{:+.3} % (B {b_ref:.6} vs {bj:.6})", 100.0 * (p_ref * (1.0 - bj * bj).sqrt() - 1.0))
        } else {
            format!("— (B {b_ref:.6})")
        };
        let ts: Vec<String> = times.iter().map(|t| format!("{t:.1}")).collect();
        println!(" {jeff} | {} |", ts.join(", "));
    }
}
