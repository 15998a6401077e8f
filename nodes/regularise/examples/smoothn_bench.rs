//! Times robust smoothing with automatic S of a vector field (default 2 × 200 × 200 with noise and
//! 10 % gross outliers), reusing one workspace across repeats.
//!
//! ```text
//! cargo run --release -p sonoflow-regularise --example smoothn_bench -- \
//!     [--in field.npy] [--out smoothed.npy] [--ny 200] [--nx 200] [--repeats 20] [--flavour matlab|pymust]
//! ```
//! `--in` reads a real `.npy` of shape (components, ny, nx) (as written by
//! `bench/smoothn/side_by_side.py`; f4, f8, i4, i8 or u1, C or Fortran order, read by sonoflow-fileio);
//! without it the field is generated from a fixed seed. Prints one JSON line with the timings (ms)
//! and the result summary.
use std::path::Path;
use std::time::Instant;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use sonoflow_fileio::npy;
use sonoflow_regularise::{Flavour, Smoothn, SmoothnParams};

type Res<T> = Result<T, Box<dyn std::error::Error>>;

/// Smooth 2-component field + N(0, 0.1²) noise + 10 % outliers uniform in ±2.5.
fn generate(ny: usize, nx: usize) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let normal = Normal::new(0.0, 0.1).unwrap_or_else(|_| unreachable!());
    let n = ny * nx;
    let mut f = vec![0.0; 2 * n];
    for p in 0..n {
        let (y, x) = ((p / nx) as f64 / ny as f64, (p % nx) as f64 / nx as f64);
        f[p] = (std::f64::consts::TAU * x).cos() * (std::f64::consts::PI * y).sin() + normal.sample(&mut rng);
        f[n + p] = (std::f64::consts::TAU * x).sin() * (std::f64::consts::PI * y).cos() + normal.sample(&mut rng);
        if rng.gen_bool(0.1) {
            f[p] = rng.gen_range(-2.5..2.5);
            f[n + p] = rng.gen_range(-2.5..2.5);
        }
    }
    f
}

fn main() -> Res<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |name: &str| args.iter().position(|a| a == name).and_then(|i| args.get(i + 1)).cloned();
    let repeats: usize = arg("--repeats").map_or(Ok(20), |s| s.parse())?;
    let flavour = match arg("--flavour").as_deref() {
        None | Some("matlab") => Flavour::Matlab,
        Some("pymust") => Flavour::Pymust,
        Some(other) => return Err(format!("--flavour {other}: expected matlab or pymust").into()),
    };
    let (shape, data) = match arg("--in") {
        Some(path) => {
            let a = npy::read(Path::new(&path))?;
            (a.shape, a.data)
        }
        None => {
            let ny: usize = arg("--ny").map_or(Ok(200), |s| s.parse())?;
            let nx: usize = arg("--nx").map_or(Ok(200), |s| s.parse())?;
            (vec![2, ny, nx], generate(ny, nx))
        }
    };
    let (components, grid) = match shape.as_slice() {
        [c, rest @ ..] if !rest.is_empty() => (*c, rest.to_vec()),
        _ => return Err(format!("need shape (components, ...grid), got {shape:?}").into()),
    };
    let params = SmoothnParams { robust: true, flavour, ..SmoothnParams::default() };
    let mut out = vec![0.0; data.len()];
    let t = Instant::now();
    let mut ws = Smoothn::new(&grid, components)?;
    let plan_ms = t.elapsed().as_secs_f64() * 1e3;
    let t = Instant::now();
    let mut report = ws.smooth(&data, None, &params, &mut out)?;
    let first_ms = t.elapsed().as_secs_f64() * 1e3;
    let mut times = Vec::with_capacity(repeats);
    for _ in 0..repeats {
        let t = Instant::now();
        report = ws.smooth(&data, None, &params, &mut out)?;
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    let median = times.get(times.len() / 2).copied().unwrap_or(first_ms);
    let min = times.first().copied().unwrap_or(first_ms);
    if let Some(path) = arg("--out") {
        npy::write_f64(Path::new(&path), &shape, &out)?;
    }
    println!(
        "{{\"shape\": {shape:?}, \"threads\": {}, \"flavour\": \"{flavour:?}\", \"plan_ms\": {plan_ms:.3}, \"first_ms\": {first_ms:.3}, \
         \"median_ms\": {median:.3}, \"min_ms\": {min:.3}, \"repeats\": {repeats}, \"s\": {}, \"iterations\": {}, \
         \"gcv_evaluations\": {}, \"outlier_fraction\": {}, \"converged\": {}}}",
        rayon_threads(),
        report.s,
        report.iterations,
        report.gcv_evaluations,
        report.outlier_fraction,
        report.converged
    );
    Ok(())
}

fn rayon_threads() -> usize {
    rayon::current_num_threads()
}
