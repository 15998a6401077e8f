//! `sonoflow platelet data|train`: the resolved Stokes training data of paper 2 (Algorithm 1) and
//! the training of its networks (§4.2–4.3), see `sonoflow_platelet::dataset` and `::nn`.
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use sonoflow_platelet::dataset::{self, GenerateOptions, Record, Set};
use sonoflow_platelet::nn::data::{evaluate, SetErrors, TrainingReport};
use sonoflow_platelet::nn::model::NetworkModel;
use sonoflow_platelet::nn::train::TrainConfig;
use sonoflow_platelet::stokes::{Outer, StokesOptions, PAPER_BALL_RADIUS};

/// `sonoflow platelet …`
#[derive(clap::Subcommand, Debug)]
pub enum PlateletCmd {
    /// Generate (or resume) the resolved Stokes data set: random platelets, each solved in the
    /// paper's 50 µm ball (drag, lift, pitching, rotational and strain torque).
    Data(DataArgs),
    /// Train the networks N (6→50→20→20→3), N_r and N_s (5→20→20→20→1) on a data file; writes
    /// the weights (safetensors) and the training report (paper's Table 1 layout).
    Train(TrainArgs),
}

/// Arguments of `sonoflow platelet data`.
#[derive(clap::Args, Debug)]
pub struct DataArgs {
    /// Data file (JSON lines; appended to and resumed if it exists).
    #[arg(long, default_value = "nodes/platelet/data/stokes-data.jsonl")]
    pub out: PathBuf,
    /// Platelets inside eq 7's bounds.
    #[arg(long, default_value_t = 2000)]
    pub shapes: u64,
    /// Platelets with a parameter outside eq 7's bounds (the generalisation set).
    #[arg(long, default_value_t = 250)]
    pub generalisation: u64,
    /// Seed of the shapes.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Solver threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Body panels along the meridian (even, 4..=64).
    #[arg(long, default_value_t = StokesOptions::default().n_beta)]
    pub n_beta: usize,
    /// Free space instead of the paper's 50 µm ball.
    #[arg(long)]
    pub free_space: bool,
}

/// Arguments of `sonoflow platelet train`.
#[derive(clap::Args, Debug)]
pub struct TrainArgs {
    /// Data file written by `sonoflow platelet data`.
    #[arg(long, default_value = "nodes/platelet/data/stokes-data.jsonl")]
    pub data: PathBuf,
    /// Output folder: n.safetensors, n_r.safetensors, n_s.safetensors, training-report.{md,json}.
    #[arg(long, default_value = "nodes/platelet/weights")]
    pub out: PathBuf,
    /// Random angles of attack per shape (Algorithm 1 uses 4).
    #[arg(long, default_value_t = 4)]
    pub angles: usize,
    /// Fraction of the in-bounds shapes held back as test data.
    #[arg(long, default_value_t = 0.2)]
    pub test_fraction: f64,
    /// Training epochs (upper bound; early stopping keeps the best weights).
    #[arg(long, default_value_t = TrainConfig::default().epochs)]
    pub epochs: usize,
    /// Seed of the angles, the split and the training.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

pub fn run(cmd: &PlateletCmd) -> anyhow::Result<i32> {
    match cmd {
        PlateletCmd::Data(a) => data(a),
        PlateletCmd::Train(a) => train(a),
    }
}

fn data(a: &DataArgs) -> anyhow::Result<i32> {
    let threads = a.threads.unwrap_or_else(|| std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1));
    let defaults = StokesOptions::default();
    let stokes = StokesOptions {
        n_beta: a.n_beta,
        outer: if a.free_space {
            Outer::FreeSpace
        } else {
            match defaults.outer {
                Outer::Ball { n_beta, .. } => Outer::Ball { radius: PAPER_BALL_RADIUS, n_beta },
                Outer::FreeSpace => defaults.outer,
            }
        },
        ..defaults
    };
    let opts =
        GenerateOptions { n_shapes: a.shapes, n_generalisation: a.generalisation, seed: a.seed, threads, stokes };
    let t0 = Instant::now();
    let last = std::sync::Mutex::new(Instant::now());
    let progress = |done: u64, total: u64| {
        let mut l = last.lock().unwrap_or_else(|e| e.into_inner());
        if done == total || l.elapsed().as_secs_f64() > 5.0 {
            *l = Instant::now();
            let el = t0.elapsed().as_secs_f64();
            let eta = el / done as f64 * (total - done) as f64;
            eprintln!("platelet data: {done}/{total} solved, {el:.0} s elapsed, ~{eta:.0} s left");
        }
    };
    let records = dataset::generate(&a.out, &opts, &progress)?;
    let wall = t0.elapsed().as_secs_f64();
    let (inb, gen) = split(&records);
    let cpu: f64 = records.iter().map(|r| r.seconds).sum();
    println!(
        "{}: {} in-bounds + {} generalisation shapes ({} threads; this run {:.0} s wall; {:.3} s per solve on average over the file, {:.0} s of solver time in all)",
        a.out.display(),
        inb.len(),
        gen.len(),
        threads,
        wall,
        cpu / records.len().max(1) as f64,
        cpu
    );
    Ok(0)
}

fn split(records: &[Record]) -> (Vec<&Record>, Vec<&Record>) {
    records.iter().partition(|r| r.set == Set::InBounds)
}

fn train(a: &TrainArgs) -> anyhow::Result<i32> {
    let records = dataset::load(&a.data)?;
    let (inb, gen) = split(&records);
    if inb.len() < 10 {
        anyhow::bail!("{}: {} in-bounds shapes; training needs at least 10", a.data.display(), inb.len());
    }
    if !(a.test_fraction > 0.0 && a.test_fraction < 1.0) {
        anyhow::bail!("--test-fraction = {} is out of range: (0, 1)", a.test_fraction);
    }
    // Split by shape, not by sample: a shape's angles of attack are exact combinations of the
    // same two solves, so a test shape must not also be seen in training.
    let mut order: Vec<usize> = (0..inb.len()).collect();
    {
        use rand::seq::SliceRandom;
        use rand::SeedableRng;
        order.shuffle(&mut rand_chacha::ChaCha8Rng::seed_from_u64(a.seed));
    }
    let n_test = ((inb.len() as f64 * a.test_fraction).round() as usize).clamp(1, inb.len() - 1);
    let test: Vec<&Record> = order[..n_test].iter().map(|&i| inb[i]).collect();
    let training: Vec<&Record> = order[n_test..].iter().map(|&i| inb[i]).collect();
    let dtr = dataset::network_datasets(&training, a.angles, a.seed)?;
    let dte = dataset::network_datasets(&test, a.angles, a.seed)?;
    let dg = if gen.is_empty() { None } else { Some(dataset::network_datasets(&gen, a.angles, a.seed)?) };
    let cfg = TrainConfig { epochs: a.epochs, seed: a.seed, ..TrainConfig::default() };
    cfg.validate()?;
    let t0 = Instant::now();
    let mut reports: Vec<TrainingReport> = Vec::new();
    let mut nets = Vec::new();
    type Pick = fn(&dataset::NetworkData) -> &sonoflow_platelet::nn::data::Dataset;
    let nets_spec: [(&str, Vec<usize>, Vec<&str>, Pick); 3] = [
        ("N", vec![6, 50, 20, 20, 3], vec!["drag d", "lift l", "pitching torque t_p"], |d| &d.n),
        ("N_r", vec![5, 20, 20, 20, 1], vec!["rotational torque t_r"], |d| &d.n_r),
        ("N_s", vec![5, 20, 20, 20, 1], vec!["strain torque t_s"], |d| &d.n_s),
    ];
    for (name, sizes, outputs, pick) in nets_spec {
        let t = Instant::now();
        let (net, outcome) = sonoflow_platelet::nn::train::train(&sizes, pick(&dtr), &cfg)?;
        let mut sets = vec![
            SetErrors { set: "training".into(), n: pick(&dtr).len(), per_output: evaluate(&net, pick(&dtr))? },
            SetErrors { set: "test".into(), n: pick(&dte).len(), per_output: evaluate(&net, pick(&dte))? },
        ];
        if let Some(g) = &dg {
            sets.push(SetErrors {
                set: "generalisation".into(),
                n: pick(g).len(),
                per_output: evaluate(&net, pick(g))?,
            });
        }
        eprintln!(
            "platelet train: {name} trained in {:.1} s ({} epochs)",
            t.elapsed().as_secs_f64(),
            outcome.epochs_run
        );
        reports.push(TrainingReport {
            network: name.into(),
            sizes: sizes.clone(),
            outputs: outputs.iter().map(|s| s.to_string()).collect(),
            sets,
            outcome,
        });
        nets.push(net);
    }
    let mut it = nets.into_iter();
    let (n, n_r, n_s) = match (it.next(), it.next(), it.next()) {
        (Some(a), Some(b), Some(c)) => (a, b, c),
        _ => anyhow::bail!("internal: three networks expected"),
    };
    let model = NetworkModel::new(n, n_r, n_s)?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    model.save_dir(&a.out)?;
    let secs = t0.elapsed().as_secs_f64();
    write_report(&a.out, &a.data, &records, &reports, a, secs)?;
    println!("weights and training report in {} ({secs:.0} s of training)", a.out.display());
    Ok(0)
}

fn write_report(
    out: &Path,
    data: &Path,
    records: &[Record],
    reports: &[TrainingReport],
    a: &TrainArgs,
    secs: f64,
) -> anyhow::Result<()> {
    let (inb, gen) = split(records);
    let mut md = format!(
        "# Platelet networks: training report\n\nData: `{}` — {} in-bounds shapes (eq 7) × {} angles of attack for N, {} generalisation shapes (a parameter outside eq 7). Split {:.0}/{:.0} % (training/test) by shape, seed {}. Training: {:.0} s on this machine.\n\nErrors: relative errors of the eq 18-scaled outputs, |ŷ − y| / |y|, in %: mean (avg) and maximum, as in paper 2's Table 1. The second table divides by the RMS of |y| over the set instead (for outputs that can be near zero, e.g. the pitching torque of symmetric platelets).\n\nReproduce: `sonoflow platelet train --data {} --out {}`.\n\n",
        data.display(),
        inb.len(),
        a.angles,
        gen.len(),
        100.0 * (1.0 - a.test_fraction),
        100.0 * a.test_fraction,
        a.seed,
        secs,
        data.display(),
        out.display()
    );
    for r in reports {
        md.push_str(&r.to_markdown());
        md.push('\n');
    }
    std::fs::write(out.join("training-report.md"), md).with_context(|| format!("writing {}", out.display()))?;
    let json = serde_json::to_string_pretty(reports)?;
    std::fs::write(out.join("training-report.json"), json).with_context(|| format!("writing {}", out.display()))?;
    Ok(())
}
