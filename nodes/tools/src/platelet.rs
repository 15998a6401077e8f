//! `sonoflow platelet data|train`: the resolved Stokes training data of paper 2 (Algorithm 1) and
//! the training of its networks (§4.2–4.3), see `sonoflow_platelet::dataset` and `::nn`.
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use sonoflow_platelet::dataset::{self, GenerateOptions, Record, Refinement, Set};
use sonoflow_platelet::nn::data::{evaluate, SetErrors, TrainingReport};
use sonoflow_platelet::nn::mlp::Mirror;
use sonoflow_platelet::nn::model::{NetworkModel, StrainTarget};
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
    /// Paper 2 §5.1: the five test particles of Table 2 — coefficient curves against the angle
    /// of incidence (figs 9–12, networks and the resolved solver) and their motion in the paper's
    /// channel (fig 14); writes CSV, PNG figures and a summary.
    Five(FiveArgs),
}

/// Arguments of `sonoflow platelet five`.
#[derive(clap::Args, Debug)]
pub struct FiveArgs {
    /// Output folder.
    #[arg(long, default_value = "runs/platelets-five")]
    pub out: PathBuf,
    /// Network weights folder.
    #[arg(long, default_value = "nodes/platelet/weights")]
    pub weights: PathBuf,
    /// Simulated time (s).
    #[arg(long, default_value_t = 60.0)]
    pub t_end: f64,
    /// Without the rotation–translation coupling (eq 6 exactly: no y-motion at all).
    #[arg(long)]
    pub no_coupling: bool,
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
    /// Finer resolutions for thin shapes: comma-separated ASPECT:N_BETA rules (a shape with
    /// max(Lx, Lz) / Ly ≥ ASPECT is solved with N_BETA; the finest matching rule wins), or
    /// `none`. Shapes of an existing file solved coarser than the rules ask are solved again.
    #[arg(long, default_value = "9:24,15:32", value_parser = parse_refine)]
    pub refine: RefineRules,
}

/// `--refine` rules.
#[derive(Clone, Debug, PartialEq)]
pub struct RefineRules(pub Vec<Refinement>);

fn parse_refine(s: &str) -> Result<RefineRules, String> {
    if s.trim() == "none" {
        return Ok(RefineRules(Vec::new()));
    }
    let mut rules = Vec::new();
    for part in s.split(',').map(str::trim) {
        let (a, n) = part.split_once(':').ok_or_else(|| format!("`{part}`: expected ASPECT:N_BETA, e.g. 9:24"))?;
        let min_aspect: f64 = a.trim().parse().map_err(|_| format!("`{a}` is not a number (ASPECT > 1)"))?;
        let n_beta: usize = n.trim().parse().map_err(|_| format!("`{n}` is not an even integer in 4 ..= 64"))?;
        if !(min_aspect.is_finite() && min_aspect > 1.0) {
            return Err(format!("ASPECT = {min_aspect}: allowed > 1"));
        }
        if n_beta & 1 == 1 || !(4..=64).contains(&n_beta) {
            return Err(format!("N_BETA = {n_beta}: allowed an even integer in 4 ..= 64"));
        }
        rules.push(Refinement { min_aspect, n_beta });
    }
    Ok(RefineRules(rules))
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
    /// Initial Adam step (cosine decay to 1e-5).
    #[arg(long, default_value_t = TrainConfig::default().learning_rate)]
    pub learning_rate: f64,
    /// Mini-batch size.
    #[arg(long, default_value_t = TrainConfig::default().batch_size)]
    pub batch_size: usize,
    /// Trainings per network from different initial weights; the lowest validation loss is kept.
    #[arg(long, default_value_t = 1)]
    pub restarts: usize,
    /// Stop after this many epochs without a better validation loss (0: never).
    #[arg(long, default_value_t = TrainConfig::default().patience)]
    pub patience: usize,
    /// Adam step at the last epoch (the cosine decay runs from --learning-rate to this).
    #[arg(long, default_value_t = TrainConfig::default().final_learning_rate)]
    pub final_learning_rate: f64,
    /// Fraction of the training shapes held out to pick the best weights (0 ..= 0.5).
    #[arg(long, default_value_t = TrainConfig::default().validation_fraction)]
    pub validation_fraction: f64,
    /// Loss weights of N's outputs d, l, t_p: three comma-separated numbers >= 0, not all 0.
    #[arg(long, default_value = "1,1,1", value_parser = parse_weights3)]
    pub n_output_weights: OutputWeights,
    /// The mirror symmetry α_top ↔ α_bot (ψ → 2π − ψ; t_p flips, everything else keeps its
    /// value): `average` predicts ½ (N(x) + S N(M x)), which has the symmetry exactly (twice the
    /// evaluation cost), `augment` adds the mirror images as training samples, `off` ignores it.
    #[arg(long, value_enum, default_value_t = MirrorUse::Average)]
    pub mirror: MirrorUse,
    /// Full-batch L-BFGS iterations after Adam (0: none).
    #[arg(long, default_value_t = 0)]
    pub refine: usize,
    /// What N_s predicts: `shape-factor` ln((1 − B)/(1 − B_e)) relative to the ellipsoid with the
    /// same in-plane axes, `log-one-minus-b` ln(1 − B), or `strain-torque` t_s (the first
    /// networks). B = c_s / c_r sets the tumbling period; see the crate README.
    #[arg(long, value_enum, default_value_t = StrainTargetArg::ShapeFactor)]
    pub strain_target: StrainTargetArg,
}

/// `--strain-target`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum StrainTargetArg {
    /// ln((1 − B)/(1 − B_e)).
    ShapeFactor,
    /// ln(1 − B).
    LogOneMinusB,
    /// t_s = T_s / 800.
    StrainTorque,
}

impl StrainTargetArg {
    fn target(self) -> StrainTarget {
        match self {
            StrainTargetArg::ShapeFactor => StrainTarget::ShapeFactor,
            StrainTargetArg::LogOneMinusB => StrainTarget::LogOneMinusB,
            StrainTargetArg::StrainTorque => StrainTarget::StrainTorque,
        }
    }

    fn name(self) -> &'static str {
        match self {
            StrainTargetArg::ShapeFactor => "shape-factor",
            StrainTargetArg::LogOneMinusB => "log-one-minus-b",
            StrainTargetArg::StrainTorque => "strain-torque",
        }
    }
}

/// Loss weights of N's three outputs (d, l, t_p).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OutputWeights(pub [f64; 3]);

impl std::fmt::Display for OutputWeights {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{},{},{}", self.0[0], self.0[1], self.0[2])
    }
}

fn parse_weights3(s: &str) -> Result<OutputWeights, String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let values: Vec<f64> = parts
        .iter()
        .map(|p| p.parse::<f64>().map_err(|_| format!("`{p}` is not a number")))
        .collect::<Result<_, _>>()?;
    let [d, l, t] = values[..] else {
        return Err(format!("expected three comma-separated weights (d, l, t_p), got {}", values.len()));
    };
    if values.iter().any(|w| !(w.is_finite() && *w >= 0.0)) || values.iter().all(|w| *w == 0.0) {
        return Err("the weights must be finite, >= 0 and not all 0".into());
    }
    Ok(OutputWeights([d, l, t]))
}

/// How training uses the platelet's mirror symmetry.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum MirrorUse {
    /// Mirror-averaged networks (exact symmetry).
    Average,
    /// Mirror images as extra training samples.
    Augment,
    /// No use of the symmetry.
    Off,
}

impl MirrorUse {
    fn name(self) -> &'static str {
        match self {
            MirrorUse::Average => "average",
            MirrorUse::Augment => "augment",
            MirrorUse::Off => "off",
        }
    }
}

pub fn run_platelet(cmd: &PlateletCmd) -> anyhow::Result<i32> {
    match cmd {
        PlateletCmd::Data(a) => data(a),
        PlateletCmd::Train(a) => train(a),
        PlateletCmd::Five(a) => five(a),
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
    let opts = GenerateOptions {
        n_shapes: a.shapes,
        n_generalisation: a.generalisation,
        seed: a.seed,
        threads,
        stokes,
        refine: a.refine.0.clone(),
    };
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
    // the options first: a bad value fails before the data are read
    if !(a.test_fraction > 0.0 && a.test_fraction < 1.0) {
        anyhow::bail!("--test-fraction = {} is out of range: (0, 1)", a.test_fraction);
    }
    if a.restarts == 0 {
        anyhow::bail!("--restarts must be at least 1");
    }
    let cfg = TrainConfig {
        epochs: a.epochs,
        seed: a.seed,
        learning_rate: a.learning_rate,
        final_learning_rate: a.final_learning_rate,
        validation_fraction: a.validation_fraction,
        batch_size: a.batch_size,
        patience: a.patience,
        augment_mirror: a.mirror == MirrorUse::Augment,
        average_mirror: a.mirror == MirrorUse::Average,
        refine_iterations: a.refine,
        ..TrainConfig::default()
    };
    // N's mirror and loss weights; N_r and N_s: α_top ↔ α_bot, nothing flips
    let n_cfg = TrainConfig {
        mirror: Some(Mirror::platelet_n()),
        output_weights: a.n_output_weights.0.to_vec(),
        ..cfg.clone()
    };
    let shape_cfg = TrainConfig { mirror: Some(Mirror::platelet_shape()), ..cfg };
    n_cfg.validate().context("sonoflow platelet train: bad option (--epochs, --batch-size, --learning-rate, --final-learning-rate, --validation-fraction, --refine)")?;
    let records = dataset::load(&a.data)?;
    let (inb, gen) = split(&records);
    if inb.len() < 10 {
        anyhow::bail!("{}: {} in-bounds shapes; training needs at least 10", a.data.display(), inb.len());
    }
    // split by shape (the same split for every experiment with this seed)
    let (training, test) = dataset::split_by_shape(&records, a.test_fraction, a.seed)?;
    let dtr = dataset::network_datasets(&training, a.angles, a.seed)?;
    let dte = dataset::network_datasets(&test, a.angles, a.seed)?;
    let dg = if gen.is_empty() { None } else { Some(dataset::network_datasets(&gen, a.angles, a.seed)?) };
    let target = a.strain_target.target();
    let s_name = match target {
        StrainTarget::StrainTorque => "strain torque t_s".to_string(),
        t => format!("shape factor {}", t.output_name()),
    };
    // N_s's data sets for the chosen target (t_s: as built with N_r's)
    let strain = |rs: &[&Record]| dataset::strain_dataset(rs, target);
    let s_sets = [strain(&training)?, strain(&test)?, if gen.is_empty() { strain(&training)? } else { strain(&gen)? }];
    let t0 = Instant::now();
    let mut reports: Vec<TrainingReport> = Vec::new();
    let mut nets = Vec::new();
    use sonoflow_platelet::nn::data::Dataset;
    /// Name, layer sizes, output names, its data (training, test, generalisation), its training configuration.
    type NetSpec<'a> = (&'a str, Vec<usize>, Vec<&'a str>, [Option<&'a Dataset>; 3], &'a TrainConfig);
    let nets_spec: [NetSpec; 3] = [
        (
            "N",
            vec![6, 50, 20, 20, 3],
            vec!["drag d", "lift l", "pitching torque t_p"],
            [Some(&dtr.n), Some(&dte.n), dg.as_ref().map(|g| &g.n)],
            &n_cfg,
        ),
        (
            "N_r",
            vec![5, 20, 20, 20, 1],
            vec!["rotational torque t_r"],
            [Some(&dtr.n_r), Some(&dte.n_r), dg.as_ref().map(|g| &g.n_r)],
            &shape_cfg,
        ),
        (
            "N_s",
            vec![5, 20, 20, 20, 1],
            vec![s_name.as_str()],
            [Some(&s_sets[0]), Some(&s_sets[1]), dg.as_ref().map(|_| &s_sets[2])],
            &shape_cfg,
        ),
    ];
    for (name, sizes, outputs, [d_train, d_test, d_gen], cfg) in nets_spec {
        let (Some(d_train), Some(d_test)) = (d_train, d_test) else { anyhow::bail!("internal: no training data") };
        let t = Instant::now();
        // `restarts` trainings from different initial weights and shuffles (the shape split stays
        // the same); the one with the lowest validation loss (part of the training shapes, never
        // the test shapes) is kept
        let mut best: Option<(sonoflow_platelet::nn::mlp::Mlp, sonoflow_platelet::nn::train::TrainOutcome)> = None;
        for r in 0..a.restarts {
            let c = TrainConfig { seed: cfg.seed.wrapping_add(1000 * r as u64), ..cfg.clone() };
            let (net, outcome) = sonoflow_platelet::nn::train::train(&sizes, d_train, &c)?;
            eprintln!("platelet train: {name} restart {r}: validation MSE {:.3e}", outcome.best_validation_loss);
            if best.as_ref().is_none_or(|(_, o)| outcome.best_validation_loss < o.best_validation_loss) {
                best = Some((net, outcome));
            }
        }
        let Some((net, outcome)) = best else { anyhow::bail!("--restarts must be at least 1") };
        let mut sets = vec![
            SetErrors { set: "training".into(), n: d_train.len(), per_output: evaluate(&net, d_train)? },
            SetErrors { set: "test".into(), n: d_test.len(), per_output: evaluate(&net, d_test)? },
        ];
        if let Some(g) = d_gen {
            sets.push(SetErrors { set: "generalisation".into(), n: g.len(), per_output: evaluate(&net, g)? });
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
    let model = NetworkModel::new(n, n_r, n_s)?.with_strain_target(target);
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    model.save_dir(&a.out)?;
    let secs = t0.elapsed().as_secs_f64();
    let rotation = rotation_table(&model, &[("training", &training), ("test", &test), ("generalisation", &gen)]);
    write_report(&a.out, &a.data, &records, &reports, &rotation, a, secs)?;
    println!("weights and training report in {} ({secs:.0} s of training)", a.out.display());
    Ok(0)
}

/// Aspect classes of the rotation table (max(Lx, Lz) / Ly).
const ASPECT_CLASSES: [(f64, f64); 4] = [(0.0, 6.0), (6.0, 10.0), (10.0, 17.0), (17.0, f64::INFINITY)];

/// The rotation the networks give (Jeffery period and slowest angular velocity from B = c_s / c_r)
/// against the data's (the converged solver's) B, per set and aspect class, as markdown.
fn rotation_table(model: &NetworkModel, sets: &[(&str, &[&Record])]) -> String {
    use sonoflow_platelet::experiments::rotation_errors;
    use std::fmt::Write as _;
    let mut md = String::from(
        "Rotation in simple shear from the networks' shape factor B = c_s / c_r against the data's (the solver's, at each shape's resolution): Jeffery's period 4π / (γ̇ √(1 − B²)) and the slowest angular velocity γ̇ (1 − B) / 2 (the largest error over all orientations), |error| in %, mean / max, by aspect max(Lx, Lz) / Ly:\n\n| set | aspect | shapes | period avg | period max | Ω avg | Ω max |\n|---|---|---:|---:|---:|---:|---:|\n",
    );
    for (name, recs) in sets {
        if recs.is_empty() {
            continue;
        }
        let shapes: Vec<_> = recs.iter().map(|r| r.shape).collect();
        let b: Vec<f64> = recs.iter().map(|r| r.resistance.strain_torque / r.resistance.rotation_torque).collect();
        let errs = rotation_errors(model, &shapes, &b);
        let classes = ASPECT_CLASSES.iter().map(|&(lo, hi)| (format!("{lo:.0}–{hi:.0}").replace("–inf", "+"), lo, hi));
        for (label, lo, hi) in std::iter::once(("all".to_string(), 0.0, f64::INFINITY)).chain(classes) {
            let e: Vec<_> = errs.iter().filter(|e| e.aspect >= lo && e.aspect < hi).collect();
            if e.is_empty() {
                continue;
            }
            let k = e.len() as f64;
            let (pa, pm) =
                (e.iter().map(|e| e.period).sum::<f64>() / k, e.iter().map(|e| e.period).fold(0.0, f64::max));
            let (oa, om) = (e.iter().map(|e| e.omega).sum::<f64>() / k, e.iter().map(|e| e.omega).fold(0.0, f64::max));
            let _ = writeln!(
                md,
                "| {name} | {label} | {} | {:.3} | {:.3} | {:.3} | {:.3} |",
                e.len(),
                100.0 * pa,
                100.0 * pm,
                100.0 * oa,
                100.0 * om
            );
        }
    }
    md
}

fn write_report(
    out: &Path,
    data: &Path,
    records: &[Record],
    reports: &[TrainingReport],
    rotation: &str,
    a: &TrainArgs,
    secs: f64,
) -> anyhow::Result<()> {
    let (inb, gen) = split(records);
    let mut md = format!(
        "# Platelet networks: training report\n\nData: `{}` — {} in-bounds shapes (eq 7) × {} angles of attack for N, {} generalisation shapes (a parameter outside eq 7). Split {:.0}/{:.0} % (training/test) by shape, seed {}; {} epoch(s) at most, {} restart(s) per network (kept: the lowest validation loss). Training: {:.0} s on this machine.\n\nErrors: relative errors of the eq 18-scaled outputs, |ŷ − y| / |y|, in %: mean (avg) and maximum, as in paper 2's Table 1. The second table divides by the RMS of |y| over the set instead (for outputs that can be near zero, e.g. the pitching torque of symmetric platelets).\n\nRecipe: Adam, batch {}, cosine step {:e} → {:e}, validation {} of the training shapes; mirror symmetry: {}; loss weights of N (d, l, t_p): {}; L-BFGS refinement: {} iteration(s); N_s predicts {}.\n\nReproduce: `sonoflow platelet train --data {} --out {} --epochs {} --patience {} --restarts {} --seed {} --batch-size {} --learning-rate {} --final-learning-rate {} --validation-fraction {} --mirror {} --n-output-weights {} --refine {} --strain-target {}`.\n\n",
        data.display(),
        inb.len(),
        a.angles,
        gen.len(),
        100.0 * (1.0 - a.test_fraction),
        100.0 * a.test_fraction,
        a.seed,
        a.epochs,
        a.restarts,
        secs,
        a.batch_size,
        a.learning_rate,
        a.final_learning_rate,
        a.validation_fraction,
        match a.mirror {
            MirrorUse::Average => "mirror-averaged networks, ŷ = ½ (N(x) + S N(M x)) (M: α_top ↔ α_bot, ψ → 2π − ψ; S flips t_p)",
            MirrorUse::Augment => "mirror images added to the training samples",
            MirrorUse::Off => "not used",
        },
        a.n_output_weights,
        a.refine,
        a.strain_target.target().output_name(),
        data.display(),
        out.display(),
        a.epochs,
        a.patience,
        a.restarts,
        a.seed,
        a.batch_size,
        a.learning_rate,
        a.final_learning_rate,
        a.validation_fraction,
        a.mirror.name(),
        a.n_output_weights,
        a.refine,
        a.strain_target.name()
    );
    for r in reports {
        md.push_str(&r.to_markdown());
        md.push('\n');
    }
    md.push_str(rotation);
    std::fs::write(out.join("training-report.md"), md).with_context(|| format!("writing {}", out.display()))?;
    let json = serde_json::to_string_pretty(reports)?;
    std::fs::write(out.join("training-report.json"), json).with_context(|| format!("writing {}", out.display()))?;
    Ok(())
}

fn five(a: &FiveArgs) -> anyhow::Result<i32> {
    use sonoflow_evaluate::figures::{line_panels, LinePanel};
    use sonoflow_platelet::dynamics::DynamicsParams;
    use sonoflow_platelet::experiments::{self, RunOptions, Y0};
    use std::fmt::Write as _;
    let model = NetworkModel::load_dir(&a.weights)
        .with_context(|| format!("loading the networks from {}", a.weights.display()))?;
    let t0 = Instant::now();
    let net = experiments::curves(&model, 361);
    let coupling = !a.no_coupling;
    let tr = experiments::run(
        &model,
        &RunOptions { t_end: a.t_end, record_every: 40, dynamics: DynamicsParams { coupling, ..Default::default() } },
    )?;
    let t_net = t0.elapsed().as_secs_f64();
    // the resolved solver on the same particles (all angles from one solve per particle)
    let t1 = Instant::now();
    let solved: Vec<_> = experiments::table2_shapes()
        .iter()
        .map(|s| {
            // at the training data's resolution for this shape (thin shapes finer)
            let base = StokesOptions::default();
            let n_beta = Refinement::n_beta_for(&Refinement::defaults(), base.n_beta, s);
            sonoflow_platelet::solve_shape(s, &StokesOptions { n_beta, ..base })
        })
        .collect::<Result<_, _>>()?;
    let t_solve = t1.elapsed().as_secs_f64();
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let mut csv = String::from(
        "particle,psi,drag_network,drag_stokes,lift_network,lift_stokes,pitching_network,pitching_stokes\n",
    );
    let mut worst = [0.0f64; 5];
    for (k, (r, w)) in solved.iter().zip(worst.iter_mut()).enumerate() {
        for (j, &psi) in net.psi.iter().enumerate() {
            let (d, l, t) = (r.paper_drag(psi), r.paper_lift(psi), r.paper_torque(psi));
            *w = w.max((net.drag[k][j] - d).abs() / d).max((net.lift[k][j] - l).abs() / d);
            let _ = writeln!(
                csv,
                "{},{psi:.6},{:.6},{d:.6},{:.6},{l:.6},{:.6},{t:.6}",
                k + 1,
                net.drag[k][j],
                net.lift[k][j],
                net.pitching[k][j]
            );
        }
    }
    std::fs::write(a.out.join("coefficients.csv"), csv)?;
    let mut csv = String::from("t");
    for k in 1..=5 {
        let _ = write!(csv, ",y{k}_m,vy{k}_m_s,phi{k}_rad");
    }
    csv.push('\n');
    for (i, t) in tr.t.iter().enumerate() {
        let _ = write!(csv, "{t:.6}");
        for k in 0..5 {
            let _ = write!(csv, ",{:.12e},{:.6e},{:.6}", tr.y[k][i], tr.vy[k][i], tr.phi[k][i]);
        }
        csv.push('\n');
    }
    std::fs::write(a.out.join("trajectories.csv"), csv)?;
    let deg: Vec<f64> = net.psi.iter().map(|p| p.to_degrees()).collect();
    let per = |q: &Vec<Vec<f64>>| -> Vec<(String, Vec<(f64, f64)>)> {
        (0..5)
            .map(|k| (format!("particle {}", k + 1), deg.iter().copied().zip(q[k].iter().copied()).collect()))
            .collect()
    };
    let rot: Vec<Vec<f64>> = net.rotational.iter().map(|r| vec![*r; deg.len()]).collect();
    let f1 = line_panels(
        &a.out,
        "coefficients.png",
        "Five test particles (Table 2): coefficients from the networks against the angle of incidence",
        "Paper units of Algorithm 1 (um, um/s, ug): D, L at |dv| = 1 um/s, T about the centre of mass, T_r at 2 pi rad/s; paper 2 figs 9-12.",
        2,
        &[
            LinePanel { title: "drag D (fig 9)", x_desc: "angle of incidence psi (deg)", y_desc: "D (um ug/s^2)", series: per(&net.drag) },
            LinePanel { title: "lift L (fig 10)", x_desc: "angle of incidence psi (deg)", y_desc: "L (um ug/s^2)", series: per(&net.lift) },
            LinePanel { title: "rotational torque T_r (fig 11)", x_desc: "angle of incidence psi (deg)", y_desc: "T_r (um^2 ug/s^2)", series: per(&rot) },
            LinePanel { title: "pitching torque T (fig 12)", x_desc: "angle of incidence psi (deg)", y_desc: "T (um^2 ug/s^2)", series: per(&net.pitching) },
        ],
    )?;
    let ys: Vec<(String, Vec<(f64, f64)>)> = (0..5)
        .map(|k| {
            (format!("particle {}", k + 1), tr.t.iter().copied().zip(tr.y[k].iter().map(|y| (y - Y0) * 1e9)).collect())
        })
        .collect();
    let phis: Vec<(String, Vec<(f64, f64)>)> = (0..5)
        .map(|k| {
            (
                format!("particle {}", k + 1),
                tr.t.iter().copied().zip(tr.phi[k].iter().map(|p| p.to_degrees())).collect(),
            )
        })
        .collect();
    let f2 = line_panels(
        &a.out,
        "y_position.png",
        &format!(
            "Five test particles in the 2 mm channel from y = 0.5176 mm (coupling {})",
            if coupling { "on" } else { "off" }
        ),
        "Centre-of-mass height minus its start (nm, paper 2 fig 14) and orientation (Jeffery orbits) over time.",
        2,
        &[
            LinePanel { title: "y - y0 (fig 14)", x_desc: "t (s)", y_desc: "y - y0 (nm)", series: ys },
            LinePanel { title: "orientation phi", x_desc: "t (s)", y_desc: "phi (deg)", series: phis },
        ],
    )?;
    let mut md = format!(
        "# Five test particles (paper 2, §5.1)\n\nNetworks `{}`; channel 2 mm, v_in = 5 mm/s, start y = 0.5176 mm (shear rate {:.4} 1/s), {} s of motion, sub-step 0.25 ms, coefficients every 10th, rotation–translation coupling {}. Networks + dynamics: {t_net:.2} s; the resolved solver on the five shapes: {t_solve:.1} s.\n\n| particle | Lx × Ly × Lz (µm), α_top, α_bot | B = c_s/c_r (networks) | Jeffery period 4π/(γ̇√(1−B²)) | measured period | B (solver) | period with the solver's B | y range (nm) | y(end) − y0 (nm) | networks vs solver (drag, lift; % of D) |\n|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        a.weights.display(),
        tr.shear_rate,
        a.t_end,
        if coupling { "on" } else { "off" }
    );
    for (k, ((p, w), r)) in experiments::TABLE2.iter().zip(worst).zip(&solved).enumerate() {
        let b_solver = r.strain_torque / r.rotation_torque;
        let jp_solver = experiments::jeffery_period(tr.shear_rate, b_solver);
        let jp = experiments::jeffery_period(tr.shear_rate, net.jeffery_b[k]);
        let mp = experiments::rotation_period(&tr.t, &tr.phi[k]).map_or("–".to_string(), |v| format!("{v:.3} s"));
        let (lo, hi) = tr.y[k].iter().fold((f64::MAX, f64::MIN), |(a, b), &y| (a.min(y), b.max(y)));
        let end = tr.y[k].last().copied().unwrap_or(Y0) - Y0;
        let _ = writeln!(
            md,
            "| {} | {} × {} × {}, {}, {} | {:.5} | {jp:.3} s | {mp} | {b_solver:.5} | {jp_solver:.3} s | {:.2} | {:+.2} | {:.2} |",
            k + 1,
            p[0],
            p[1],
            p[2],
            p[3],
            p[4],
            net.jeffery_b[k],
            (hi - lo) * 1e9,
            end * 1e9,
            100.0 * w
        );
    }
    md.push_str("\nFor thin platelets B is close to 1 and the period ∝ 1/√(1 − B²) is very sensitive to it: a 0.1 % error of B changes the period of particle 3 by ~10 %.\n");
    md.push_str("\nFigures: `figures/coefficients.png` (figs 9–12), `figures/y_position.png` (fig 14). Data: `coefficients.csv`, `trajectories.csv`.\n");
    std::fs::write(a.out.join("five-particles.md"), &md)?;
    println!("{md}");
    println!("figures: {}, {}", a.out.join(&f1.path).display(), a.out.join(&f2.path).display());
    Ok(0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(clap::Parser, Debug)]
    struct Cli {
        #[command(subcommand)]
        cmd: PlateletCmd,
    }

    /// `platelet <sub> <extra…>` parsed.
    fn parse(sub: &str, extra: &[&str]) -> Result<PlateletCmd, String> {
        let mut argv = vec!["platelet", sub];
        argv.extend_from_slice(extra);
        Cli::try_parse_from(argv).map(|c| c.cmd).map_err(|e| e.to_string())
    }

    fn train_args(extra: &[&str]) -> Result<TrainArgs, String> {
        match parse("train", extra)? {
            PlateletCmd::Train(a) => Ok(a),
            other => Err(format!("{other:?}")),
        }
    }

    #[test]
    fn trainer_options_parse_and_bad_values_are_named() {
        let a = train_args(&[]).expect("defaults");
        assert_eq!(a.mirror, MirrorUse::Average);
        assert_eq!(a.n_output_weights, OutputWeights([1.0, 1.0, 1.0]));
        assert_eq!(a.refine, 0);
        let a =
            train_args(&["--mirror", "augment", "--n-output-weights", "1, 1,2.5", "--refine", "30"]).expect("valid");
        assert_eq!((a.mirror, a.n_output_weights, a.refine), (MirrorUse::Augment, OutputWeights([1.0, 1.0, 2.5]), 30));
        assert_eq!(a.n_output_weights.to_string(), "1,1,2.5");
        assert_eq!(a.strain_target, StrainTargetArg::ShapeFactor);
        let a = train_args(&["--strain-target", "strain-torque"]).expect("valid");
        assert_eq!(a.strain_target.target(), StrainTarget::StrainTorque);
        for (args, needle) in [
            (&["--mirror", "sideways"][..], "sideways"),
            (&["--n-output-weights", "1,2"], "three comma-separated"),
            (&["--n-output-weights", "1,x,2"], "`x` is not a number"),
            (&["--n-output-weights", "1,-1,2"], ">= 0"),
            (&["--n-output-weights", "0,0,0"], "not all 0"),
            (&["--refine", "many"], "--refine"),
            (&["--strain-target", "b"], "--strain-target"),
        ] {
            let e = train_args(args).expect_err("invalid");
            assert!(e.contains(needle), "{args:?}: {e}");
        }
    }

    fn data_args(extra: &[&str]) -> Result<DataArgs, String> {
        match parse("data", extra)? {
            PlateletCmd::Data(a) => Ok(a),
            other => Err(format!("{other:?}")),
        }
    }

    #[test]
    fn refinement_rules_parse_and_default_to_the_library_rules() {
        assert_eq!(data_args(&[]).expect("defaults").refine.0, Refinement::defaults());
        assert!(data_args(&["--refine", "none"]).expect("valid").refine.0.is_empty());
        let a = data_args(&["--refine", "5:20, 12:40"]).expect("valid");
        assert_eq!(
            a.refine.0,
            [Refinement { min_aspect: 5.0, n_beta: 20 }, Refinement { min_aspect: 12.0, n_beta: 40 }]
        );
        for (arg, needle) in [
            ("12", "ASPECT:N_BETA"),
            ("x:24", "`x` is not a number"),
            ("0.5:24", "allowed > 1"),
            ("9:23", "even integer"),
            ("9:80", "even integer"),
        ] {
            let e = data_args(&["--refine", arg]).expect_err("invalid");
            assert!(e.contains(needle), "{arg}: {e}");
        }
    }

    #[test]
    fn out_of_range_trainer_values_fail_before_the_data_are_read() {
        let dir = tempfile::tempdir().expect("temp dir");
        let missing = dir.path().join("none.jsonl");
        let d = missing.to_str().expect("utf-8 path");
        for (args, needle) in [
            (&["--final-learning-rate", "0.5"][..], "final_learning_rate"),
            (&["--learning-rate", "0"], "learning_rate"),
            (&["--validation-fraction", "0.7"], "validation_fraction"),
            (&["--refine", "2000000"], "refine_iterations"),
            (&["--restarts", "0"], "--restarts"),
            (&["--test-fraction", "1"], "--test-fraction"),
        ] {
            let mut argv = vec!["--data", d];
            argv.extend_from_slice(args);
            let e = train(&train_args(&argv).expect("parses")).expect_err("out of range");
            let text = format!("{e:#}");
            assert!(text.contains(needle) && !text.contains("none.jsonl"), "{args:?}: {text}");
        }
        // valid options: then the missing data file is reported
        let e = train(&train_args(&["--data", d]).expect("valid")).expect_err("no file");
        assert!(e.to_string().contains("none.jsonl"), "{e}");
    }
}
