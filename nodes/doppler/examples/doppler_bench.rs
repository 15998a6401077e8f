//! Timing of the lag-1 autocorrelation Doppler estimate of one packet (PyMUST `iq2doppler`'s
//! work): pixel-major I/Q (nz × nx × frames, frames contiguous, as a C-order numpy array), a
//! Hamming window of M × M pixels, one rayon pool of `--threads` threads. Each timed call builds
//! the estimator and its output map, as the Python `iq2doppler` does per call. Prints the best
//! and median time of `--reps` calls (at least 1, after one warm-up call) as JSON, with a hash of the maps' bits (equal hashes: the same maps).
//!
//! ```text
//! cargo run --release -p sonoflow-doppler --example doppler_bench -- [--nz 200] [--nx 200] [--frames 32] [--m 5] [--reps 200] [--threads 1]
//! ```
#![allow(clippy::unwrap_used)]

use std::time::Instant;

use num_complex::Complex;
use rand::{Rng, SeedableRng};
use sonoflow_doppler::{DopplerEstimator, DopplerParams, Packet};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let arg = |k: &str, d: usize| {
        args.iter().position(|a| a == k).and_then(|i| args.get(i + 1)).map_or(d, |v| v.parse().unwrap())
    };
    let (nz, nx, nf, m, reps, threads) = (
        arg("--nz", 200),
        arg("--nx", 200),
        arg("--frames", 32),
        arg("--m", 5),
        arg("--reps", 200).max(1),
        arg("--threads", 1),
    );
    rayon::ThreadPoolBuilder::new().num_threads(threads).build_global().unwrap();
    // A phase ramp per pixel (Doppler shift within ±0.2 of the PRF) plus complex noise, seeded.
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let mut data = Vec::with_capacity(nz * nx * nf);
    for _ in 0..nz * nx {
        let fd: f32 = rng.gen_range(-0.2..0.2);
        for k in 0..nf {
            let ph = 2.0 * std::f32::consts::PI * fd * k as f32;
            data.push(Complex::new(
                ph.cos() + 0.2 * rng.gen_range(-1.0..1.0f32),
                ph.sin() + 0.2 * rng.gen_range(-1.0..1.0f32),
            ));
        }
    }
    let mut params = DopplerParams::new(5e6, 1540.0, 5e3);
    params.window = [m, m];
    let mut times = Vec::with_capacity(reps);
    let mut checksum = 0u64;
    for r in 0..=reps {
        let t0 = Instant::now();
        let mut est = DopplerEstimator::new(params.clone(), nx, nz, 1e-4).unwrap();
        let map = est.estimate_to_map(Packet::PixelMajor { data: &data, n_frames: nf }).unwrap();
        let dt = t0.elapsed().as_secs_f64();
        if r > 0 {
            times.push(dt);
        }
        // FNV-1a of every output's bits: equal hashes = the same maps (to compare builds).
        checksum = map
            .velocity
            .iter()
            .chain(&map.variance)
            .chain(&map.power)
            .fold(0xcbf2_9ce4_8422_2325u64, |h, v| (h ^ u64::from(v.to_bits())).wrapping_mul(0x100_0000_01b3));
    }
    times.sort_by(f64::total_cmp);
    println!(
        "{{\"shape\": [{nz}, {nx}, {nf}], \"m\": {m}, \"threads\": {threads}, \"best_ms\": {:.3}, \"median_ms\": {:.3}, \"maps_hash\": \"{checksum:016x}\"}}",
        times[0] * 1e3,
        times[times.len() / 2] * 1e3
    );
}
