//! Cost of the divergence-free regulariser on the carotid scene's grid (161 × 111 pixels, 0.2 mm):
//! a wavy Poiseuille-like channel (axis z0(x) = A sin(2πx/L), A = 1.5 mm, L = 20 mm; stream
//! function ψ = f(z − z0(x)), so the flow is divergence-free but not in the penalty's null space)
//! with vector-Doppler-like noise (σx = 7.6 σz), about 60 % of the pixels inside. Prints a Markdown table: symbolic set-up, the fit with a given S, the fit with S by
//! block cross-validation from a cold start and warm-started at the chosen S, robust and not,
//! with the number of Cholesky factorisations each needed and the RMS errors.
//!
//! `cargo run --release -p sonoflow-regularise --example divfree_bench [-- NZ NX]`
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use sonoflow_regularise::{smoothn, DivFree, DivFreeParams, SmoothnParams};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<usize> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    let (nz, nx) = (args.first().copied().unwrap_or(111), args.get(1).copied().unwrap_or(161));
    let d = 2e-4;
    let n = nz * nx;
    // wavy channel: q = z − z0(x), u(q) = 0.5 (1 − (2q/W)²), v = (u, u z0'(x))
    let width = 0.6 * nz as f64 * d;
    let (amp, wl) = (1.5e-3, 20e-3);
    let (mut tx, mut tz, mut m) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    for i in 0..nz {
        for j in 0..nx {
            let (x, z) = ((j as f64 - nx as f64 / 2.0) * d, (i as f64 - nz as f64 / 2.0) * d);
            let k = std::f64::consts::TAU / wl;
            let q = z - amp * (k * x).sin();
            if q.abs() <= width / 2.0 {
                let u = 0.5 * (1.0 - (2.0 * q / width).powi(2));
                let p = i * nx + j;
                (tx[p], tz[p], m[p]) = (u, u * amp * k * (k * x).cos(), 1.0);
            }
        }
    }
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let (nxn, nzn) = (Normal::new(0.0, 0.076)?, Normal::new(0.0, 0.01)?);
    let ux: Vec<f64> = tx.iter().map(|v| v + nxn.sample(&mut rng)).collect();
    let uz: Vec<f64> = tz.iter().map(|v| v + nzn.sample(&mut rng)).collect();
    let rms = |a: &[f64], b: &[f64]| {
        let k: Vec<usize> = (0..n).filter(|&p| m[p] > 0.0).collect();
        (k.iter().map(|&p| (a[p] - b[p]).powi(2)).sum::<f64>() / k.len() as f64).sqrt()
    };
    println!(
        "Divergence-free regulariser, {nz} × {nx} pixels ({} inside), threads: rayon default",
        m.iter().filter(|v| **v > 0.0).count()
    );
    println!();
    println!("| step | time (s) | factorisations | S | RMS error x / z (m/s) |");
    println!("|---|---:|---:|---:|---|");
    let t = Instant::now();
    let f = DivFree::new([nz, nx], [d, d], 3)?;
    println!("| symbolic set-up (pattern, AMD ordering, symbolic Cholesky) | {:.3} | | | |", t.elapsed().as_secs_f64());
    let (mut vx, mut vz) = (vec![0.0; n], vec![0.0; n]);
    let mut run = |name: &str, p: &DivFreeParams, hint: Option<f64>| -> Result<f64, Box<dyn std::error::Error>> {
        let t = Instant::now();
        let r = f.fit_warm(&ux, &uz, Some(&m), p, hint, &mut vx, &mut vz)?;
        println!(
            "| {name} | {:.3} | {} | {:.3} | {:.4} / {:.4} |",
            t.elapsed().as_secs_f64(),
            r.factorisations,
            r.s,
            rms(&vx, &tx),
            rms(&vz, &tz)
        );
        Ok(r.s)
    };
    run(
        "given S = 3, not robust (one factorisation + trace probes)",
        &DivFreeParams { s: Some(3.0), robust: false, ..Default::default() },
        None,
    )?;
    let s_cv = run(
        "block-CV S from a cold start (S = 10), not robust",
        &DivFreeParams { robust: false, ..Default::default() },
        None,
    )?;
    run(
        "block-CV S warm-started at the chosen S, not robust",
        &DivFreeParams { robust: false, ..Default::default() },
        Some(s_cv),
    )?;
    run("block-CV S, robust (3 passes), cold start: the node's default", &DivFreeParams::default(), None)?;
    run("block-CV S, robust, warm start (the node's later frames)", &DivFreeParams::default(), Some(s_cv))?;
    let mut data = ux.clone();
    data.extend_from_slice(&uz);
    let t = Instant::now();
    let (sm, r) = smoothn(&data, &[nz, nx], 2, Some(&m), &SmoothnParams { robust: true, ..Default::default() })?;
    println!(
        "| smoothn, robust, GCV (paper 1's regulariser), for comparison | {:.3} | | {:.3} | {:.4} / {:.4} |",
        t.elapsed().as_secs_f64(),
        r.s,
        rms(&sm[..n], &tx),
        rms(&sm[n..], &tz)
    );
    Ok(())
}
