//! Times the three 2-D DCT operations that robust `smoothn` repeats — the forward transform, the
//! inverse of `Γ ∘ Y` and the weighted residual sum of that inverse (one GCV evaluation) — on an
//! `n × n` grid, one thread, best of `batches` batches of 20 calls each.
//!
//! ```text
//! cargo run --release -p sonoflow-regularise --example dct_timing -- [n (128)] [batches (50)]
//! ```
use std::time::Instant;

use sonoflow_regularise::dct::DctN;

type Res<T> = Result<T, Box<dyn std::error::Error>>;

fn main() -> Res<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize, name: &str, default: usize| -> Res<usize> {
        args.get(i).map_or(Ok(default), |s| s.parse().map_err(|e| format!("{name} = {s:?}: {e}").into()))
    };
    let (n, batches) = (arg(0, "n", 128)?, arg(1, "batches", 50)?);
    if !(2..=4096).contains(&n) || batches == 0 {
        return Err(format!("n = {n} must be in 2..=4096 and batches = {batches} at least 1").into());
    }
    let plan = DctN::new(&[n, n]);
    let mut s = plan.make_scratch();
    let len = n * n;
    let x: Vec<f64> = (0..len).map(|i| ((i * 7919) % 1000) as f64 / 1000.0 - 0.5).collect();
    let g: Vec<f64> = (0..len).map(|i| 1.0 / (1.0 + (i % 97) as f64)).collect();
    let (mut y, mut z, mut work) = (vec![0.0; len], vec![0.0; len], vec![0.0; len]);
    let time = |f: &mut dyn FnMut()| {
        let mut best = f64::MAX;
        for _ in 0..batches {
            let t0 = Instant::now();
            for _ in 0..20 {
                f();
            }
            best = best.min(t0.elapsed().as_secs_f64() / 20.0);
        }
        best * 1e6
    };
    let forward = time(&mut || plan.forward(&x, &mut y, &mut s));
    let inverse = time(&mut || plan.inverse_weighted(&y, Some(&g), &mut z, &mut s));
    let mut rss = 0.0;
    let gcv = time(&mut || rss = plan.weighted_rss(&y, Some(&g), &x, &g, &mut work, &mut s));
    println!(
        "{{\"n\": {n}, \"forward_us\": {forward:.2}, \"inverse_weighted_us\": {inverse:.2}, \"weighted_rss_us\": {gcv:.2}, \"rss\": {rss:.6e}}}"
    );
    Ok(())
}
