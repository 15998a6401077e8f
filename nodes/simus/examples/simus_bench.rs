//! Benchmark of the paper scene (Shahriari & Garcia 2018): 128-element 5 MHz probe, one 0° plane
//! wave, N scatterers (default 26 000) uniform in a 40 × 40 mm box from 10 mm depth, Gaussian
//! amplitudes, fixed seed.
//!
//! ```text
//! cargo run --release -p sonoflow-simus --example simus_bench -- [--scatterers N] [--frames F]
//!     [--threads T] [--accuracy fast|exact] [--reanchor K] [--block B] [--portable | --avx2]
//!     [--seed S] [--tilt DEG] [--ffd] [--window must|compact] [--write DIR]
//! ```
//! Prints seconds per frame (median of F frames after one warm-up frame) and GFLOP/s counted as
//! in ultrasound-anchors §4.1: `(6M + 2(M−1) + 8 + 8)` flop per (scatterer, element, bin) — M
//! phasor updates, the sub-element sum, the transmit and the receive complex MACs (30 for M = 2).
//! `--write DIR` saves the scene (`x.npy`, `z.npy`, `rc.npy`, float32), the RF (`rf.npy`, float32,
//! PyMUST's (n_samples, n_elements) layout) and `rust.json` (timings, plan) for
//! `bench/simus/side_by_side.py`.

use std::time::Instant;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use sonoflow_simus::{Accuracy, KernelChoice, Medium, Probe, RfWindow, Scatterers, Simus, SimusOptions, Transmit};

/// Writes f32 data in C order through sonoflow-fileio (atomic, npyz).
fn write_npy(path: &std::path::Path, shape: &[usize], data: &[f32]) -> std::io::Result<()> {
    sonoflow_fileio::npy::write_f32(path, shape, false, data).map_err(std::io::Error::other)
}

struct Args {
    n: usize,
    frames: usize,
    threads: Option<usize>,
    exact: bool,
    reanchor: Option<u32>,
    block: Option<u32>,
    portable: bool,
    ffd: bool,
    tilt_deg: f64,
    kernel: KernelChoice,
    seed: u64,
    window: RfWindow,
    write: Option<std::path::PathBuf>,
}

fn parse() -> Result<Args, String> {
    let mut a = Args {
        n: 26_000,
        frames: 3,
        threads: None,
        exact: false,
        reanchor: None,
        block: None,
        portable: false,
        ffd: false,
        tilt_deg: 0.0,
        kernel: KernelChoice::Auto,
        seed: 2018,
        window: RfWindow::Must,
        write: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        let mut val = || it.next().ok_or(format!("{k} needs a value"));
        match k.as_str() {
            "--scatterers" => a.n = val()?.parse().map_err(|e| format!("{e}"))?,
            "--frames" => a.frames = val()?.parse().map_err(|e| format!("{e}"))?,
            "--threads" => a.threads = Some(val()?.parse().map_err(|e| format!("{e}"))?),
            "--accuracy" => a.exact = val()? == "exact",
            "--reanchor" => a.reanchor = Some(val()?.parse().map_err(|e| format!("{e}"))?),
            "--block" => a.block = Some(val()?.parse().map_err(|e| format!("{e}"))?),
            "--portable" => a.portable = true,
            "--ffd" => a.ffd = true,
            "--tilt" => a.tilt_deg = val()?.parse().map_err(|e| format!("{e}"))?,
            "--avx2" => a.kernel = KernelChoice::Avx2,
            "--window" => {
                a.window = match val()?.as_str() {
                    "must" => RfWindow::Must,
                    "compact" => RfWindow::Compact,
                    w => return Err(format!("--window: '{w}' is not must or compact")),
                }
            }
            "--seed" => a.seed = val()?.parse().map_err(|e| format!("{e}"))?,
            "--write" => a.write = Some(val()?.into()),
            "--help" | "-h" => return Err("see the doc comment of examples/simus_bench.rs".into()),
            _ => return Err(format!("unknown argument {k}")),
        }
    }
    Ok(a)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a = parse()?;
    let mut rng = ChaCha8Rng::seed_from_u64(a.seed);
    let mut scat = Scatterers::default();
    for _ in 0..a.n {
        let x = rng.gen_range(-20e-3f32..20e-3);
        let z = rng.gen_range(10e-3f32..50e-3);
        let rc: f32 = rng.sample(StandardNormal);
        scat.push(x, z, rc);
    }
    let probe = Probe::paper_5mhz();
    let medium = Medium::default();
    let accuracy = match (a.exact, Accuracy::default()) {
        (true, _) => Accuracy::Exact,
        (false, Accuracy::Fast { reanchor_every, scatterer_block }) => Accuracy::Fast {
            reanchor_every: a.reanchor.unwrap_or(reanchor_every),
            scatterer_block: a.block.unwrap_or(scatterer_block),
        },
        (false, other) => other,
    };
    let accuracy_txt = format!("{accuracy:?}");
    let options = SimusOptions {
        accuracy,
        threads: a.threads,
        full_frequency_directivity: a.ffd,
        kernel: if a.portable { KernelChoice::Portable } else { a.kernel },
        window: a.window,
        ..SimusOptions::default()
    };
    let mut simus = Simus::new(probe.clone(), medium.clone(), options)?;
    let tx = Transmit::plane_wave(&probe, medium.c, a.tilt_deg.to_radians())?;
    let plan = simus.plan(&scat, &tx)?;
    let mut rf = vec![0f32; probe.n_elements * plan.n_samples];
    let t = Instant::now();
    simus.simulate_into(&scat, &tx, &plan, &mut rf)?;
    let first = t.elapsed().as_secs_f64();
    let mut times = Vec::new();
    for _ in 0..a.frames {
        let t = Instant::now();
        simus.simulate_into(&scat, &tx, &plan, &mut rf)?;
        times.push(t.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    let per_frame = if times.is_empty() { first } else { times[times.len() / 2] };
    // flop counts per (scatterer, element, bin), FMA = 2: M phasor updates (6 each), the
    // sub-element sum 2(M−1), the receive complex MAC 8, and the transmit sum: 8 for general
    // delays (the model count of ultrasound-anchors §4.1), 2 as executed for a 0° plane wave with
    // unit weights (a plain sum). Full-frequency directivity adds work that is not counted.
    let m = simus.sub_elements() as f64;
    let cells = a.n as f64 * probe.n_elements as f64 * plan.n_bins() as f64 * 1e-9;
    let gflop = cells * (6.0 * m + 2.0 * (m - 1.0) + 16.0);
    let tx_flops = if a.tilt_deg == 0.0 { 2.0 } else { 8.0 };
    let gflop_exec = cells * (6.0 * m + 2.0 * (m - 1.0) + 8.0 + tx_flops);
    let threads = a.threads.unwrap_or_else(rayon::current_num_threads);
    println!(
        "scene: {} scatterers, {} elements, M = {}, {} bins ({}..={} of {}), df = {:.1} Hz, {} samples",
        a.n,
        probe.n_elements,
        simus.sub_elements(),
        plan.n_bins(),
        plan.band_first,
        plan.band_last,
        plan.n_freq,
        plan.df,
        plan.n_samples
    );
    println!("kernel: {} ({}), threads: {threads}, first frame {first:.3} s", simus.kernel_name(), accuracy_txt);
    println!(
        "s/frame: {per_frame:.4} median, {:.4} best  ({} frames: {:?})\n\
         model flops (30/cell for M = 2): {gflop:.1} GFLOP/frame -> {:.1} GFLOP/s; as executed: {:.1} GFLOP/s",
        times.first().copied().unwrap_or(first),
        times.len(),
        times.iter().map(|t| format!("{t:.3}")).collect::<Vec<_>>(),
        gflop / per_frame,
        gflop_exec / per_frame
    );
    if let Some(dir) = a.write {
        std::fs::create_dir_all(&dir)?;
        write_npy(&dir.join("x.npy"), &[a.n], &scat.x)?;
        write_npy(&dir.join("z.npy"), &[a.n], &scat.z)?;
        write_npy(&dir.join("rc.npy"), &[a.n], &scat.rc)?;
        let (ns, ne) = (plan.n_samples, probe.n_elements);
        let mut sm = vec![0f32; ns * ne];
        for e in 0..ne {
            for k in 0..ns {
                sm[k * ne + e] = rf[e * ns + k];
            }
        }
        write_npy(&dir.join("rf.npy"), &[ns, ne], &sm)?;
        let json = format!(
            "{{\"seconds_per_frame\": {per_frame}, \"first_frame_seconds\": {first}, \"threads\": {threads}, \
             \"kernel\": \"{}\", \"gflop_per_frame\": {gflop}, \"n_freq\": {}, \"band_first\": {}, \
             \"band_last\": {}, \"n_samples\": {}}}\n",
            simus.kernel_name(),
            plan.n_freq,
            plan.band_first,
            plan.band_last,
            plan.n_samples
        );
        std::fs::write(dir.join("rust.json"), json)?;
    }
    Ok(())
}
