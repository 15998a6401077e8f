//! `sonoflow sweep`: runs a scene over a grid of parameter settings and reports error against
//! run time. Every combination of the `--vary node.param=a,b,c` lists is one run (its own output
//! folder `point-NNN`, its own run id); the error comes from the scene's `evaluator`
//! (`evaluation.json`, or `evaluation-<label>.json` with `--label`), the cost from the run
//! report (compute CPU summed over the stages, and wall time). With `--seeds node.param=s1,s2,…`
//! (repeatable; several keys go together, the k-th value of each in realisation k) every setting
//! runs once per realisation and the sweep also reports mean ± sample standard deviation over
//! them. Writes `sweep.csv` (all points), `sweep.md` (table, Pareto front marked; with seeds
//! the table over realisations), `sweep-seeds.csv` (with seeds) and `sweep.svg` (error against
//! compute time, Pareto front joined).
//!
//! Every sweep first writes its plan (`sweep-plan.json`: the launch file's text, the overrides
//! and each point's settings), so that a point can run anywhere: here one after the other
//! (`--executor local`, the default), or as the tasks of a Slurm job array (`--executor slurm`,
//! [`slurm`]). `sonoflow sweep collect DIR` gathers whatever points have finished into the same
//! tables, lists the failed and missing ones, and with `--resume` runs (or resubmits) only those.

pub mod plan;
pub mod slurm;

use plan::Plan;
use sonoflow_launcher::launch;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// `sonoflow sweep`: a sweep (`sonoflow sweep FILE …`) or one of its subcommands.
#[derive(clap::Args, Debug)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct SweepCmd {
    #[command(subcommand)]
    pub sub: Option<SweepSub>,
    #[command(flatten)]
    pub args: SweepArgs,
}

/// Subcommands of `sonoflow sweep`.
#[derive(clap::Subcommand, Debug)]
pub enum SweepSub {
    /// Gather the finished points of a sweep folder into sweep.csv / sweep.md / sweep.svg; list
    /// the failed and missing points (exit status 1 if any).
    Collect {
        /// The sweep's output folder (it holds `sweep-plan.json`).
        dir: PathBuf,
        /// Run the failed and missing points again: resubmitted as a Slurm job array (only those
        /// indices) for a Slurm sweep, run here for a local one. Points still queued or running
        /// in Slurm are left alone. A failed point's folder is kept as `point-NNN.attempt-K`.
        #[arg(long)]
        resume: bool,
        /// With `--resume` on a Slurm sweep: wait until the resubmitted tasks end, then collect.
        #[arg(long)]
        wait: bool,
    },
    /// Run point INDEX of the sweep in DIR (what each Slurm array task runs).
    #[command(hide = true)]
    Task { dir: PathBuf, index: usize },
}

/// Where the points of a sweep run.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Executor {
    /// One after the other in this process's machine.
    Local,
    /// As the tasks of one Slurm job array (`sbatch --array`), each point in its own folder.
    Slurm,
}

/// Arguments of `sonoflow sweep FILE`.
#[derive(clap::Args, Debug)]
pub struct SweepArgs {
    /// Launch file; it must contain an `evaluator` node.
    #[arg(required = true)]
    pub file: Option<PathBuf>,
    /// `node.param=a,b,c`: values to try (TOML values; commas inside [ ] or { } or quotes do not
    /// split). Repeat for a grid over several parameters.
    #[arg(long = "vary", value_name = "NODE.PARAM=V1,V2,…")]
    pub vary: Vec<String>,
    /// `node.param=s1,s2,…`: realisations (e.g. `flow.seed=1,2,3`); every setting runs once per
    /// realisation and the sweep reports mean ± spread over them. Repeat to vary several seeds
    /// together (same number of values; the k-th of each in realisation k).
    #[arg(long = "seeds", value_name = "NODE.PARAM=S1,S2,…")]
    pub seeds: Vec<String>,
    /// Read the evaluator labelled so (`evaluation-<label>.json`, e.g. `subband-divfree`)
    /// instead of the unlabelled one.
    #[arg(long)]
    pub label: Option<String>,
    /// Fixed `node.param=value` for every run.
    #[arg(long = "set", value_name = "NODE.PARAM=VALUE")]
    pub set: Vec<String>,
    /// Fixed `node=variant` for every run.
    #[arg(long = "swap", value_name = "NODE=VARIANT")]
    pub swap: Vec<String>,
    /// Output folder (default `runs/<graph>-sweep-<time>`). For Slurm it must be on a file
    /// system that the compute nodes share.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Evaluated field whose error is plotted: `regularised` (default) or `raw`.
    #[arg(long, default_value = "regularised")]
    pub field: String,
    /// Where the points run: `local` (one after the other here) or `slurm` (one job array,
    /// submitted with `sbatch`; collect with `sonoflow sweep collect DIR`).
    #[arg(long, value_enum, default_value = "local")]
    pub executor: Executor,
    /// Slurm partition (`sbatch --partition`); default: the cluster's default partition.
    #[arg(long)]
    pub partition: Option<String>,
    /// Slurm time limit of each task (`sbatch --time`, e.g. `30:00`, `2:00:00`); default: the
    /// partition's.
    #[arg(long)]
    pub time: Option<String>,
    /// CPUs of each Slurm task (`sbatch --cpus-per-task`, default 2: a graph is several
    /// processes).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub cpus: Option<u32>,
    /// Further `sbatch` option, passed as given (repeatable), e.g. `--sbatch=--account=lab`.
    #[arg(long = "sbatch", value_name = "OPTION", allow_hyphen_values = true)]
    pub sbatch: Vec<String>,
    /// Slurm: wait until every task has ended (`sbatch --wait`), then collect.
    #[arg(long, conflicts_with = "hold")]
    pub wait: bool,
    /// Slurm: submit the array held (`sbatch --hold`; start it with `scontrol release JOBID`).
    /// Only this submission: `collect --resume` submits unheld.
    #[arg(long)]
    pub hold: bool,
}

/// Splits `a,b,[c,d],"e,f"` at top-level commas.
pub fn split_values(s: &str) -> Vec<String> {
    let (mut out, mut cur, mut depth, mut quote) = (Vec::new(), String::new(), 0i32, None::<char>);
    for ch in s.chars() {
        match (ch, quote) {
            ('"' | '\'', None) => quote = Some(ch),
            (c, Some(q)) if c == q => quote = None,
            ('[' | '{', None) => depth += 1,
            (']' | '}', None) => depth -= 1,
            (',', None) if depth == 0 => {
                out.push(cur.trim().to_string());
                cur.clear();
                continue;
            }
            _ => {}
        }
        cur.push(ch);
    }
    out.push(cur.trim().to_string());
    out
}

/// One sweep point's result.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Point {
    pub index: usize,
    pub settings: Vec<String>,
    pub status: String,
    /// Compute CPU summed over all stages (s).
    pub compute_s: f64,
    pub wall_s: f64,
    /// Mean over packets of the RMS vector error `sqrt(rms_x² + rms_z²)` (fraction of v_max).
    pub error_rms: f64,
    /// Mean over packets of |e|75 of x and z (fractions of v_max).
    pub x_abs_p75: f64,
    pub z_abs_p75: f64,
    /// Mean over packets of the gain of vx and vz (slope of the estimate against the truth; NaN
    /// where a true component is zero).
    pub x_gain: f64,
    pub z_gain: f64,
    pub pareto: bool,
    /// Index of the setting (the `--vary` combination) this point realises.
    pub group: usize,
}

/// Mean ± sample standard deviation over the realisations of one setting.
#[derive(Clone, Debug, PartialEq)]
pub struct Spread {
    pub settings: Vec<String>,
    /// Realisations that ran and were evaluated.
    pub n: usize,
    /// (mean, sample standard deviation) of x |e|75, z |e|75, the RMS vector error (fractions
    /// of v_max) and the compute time (s); NaN standard deviation for a single realisation.
    pub x_abs_p75: (f64, f64),
    pub z_abs_p75: (f64, f64),
    pub error_rms: (f64, f64),
    pub compute_s: (f64, f64),
}

/// Mean and sample standard deviation (n − 1); (NaN, NaN) when empty, (x, NaN) for one value.
pub fn mean_sd(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    if v.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let mean = v.iter().sum::<f64>() / n;
    if v.len() < 2 {
        return (mean, f64::NAN);
    }
    (mean, (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt())
}

/// Groups the evaluated points by setting (`group`) and summarises each over its realisations;
/// `settings[g]` names group g.
pub fn spreads(points: &[Point], settings: &[Vec<String>]) -> Vec<Spread> {
    settings
        .iter()
        .enumerate()
        .map(|(g, set)| {
            let ok: Vec<&Point> =
                points.iter().filter(|p| p.group == g && p.status == "ok" && p.error_rms.is_finite()).collect();
            let col = |f: fn(&Point) -> f64| mean_sd(&ok.iter().map(|p| f(p)).collect::<Vec<f64>>());
            Spread {
                settings: set.clone(),
                n: ok.len(),
                x_abs_p75: col(|p| p.x_abs_p75),
                z_abs_p75: col(|p| p.z_abs_p75),
                error_rms: col(|p| p.error_rms),
                compute_s: col(|p| p.compute_s),
            }
        })
        .collect()
}

/// Parses the `--seeds` options into realisations (each a list of `key=value` settings).
pub fn realisations(seeds: &[String]) -> anyhow::Result<Vec<Vec<String>>> {
    let mut columns: Vec<Vec<String>> = Vec::new();
    for v in seeds {
        let Some((key, values)) = v.split_once('=') else {
            anyhow::bail!("--seeds {v}: expected NODE.PARAM=S1,S2,…");
        };
        let vals = split_values(values);
        if vals.iter().any(String::is_empty) {
            anyhow::bail!("--seeds {v}: empty value in the list");
        }
        if let Some(first) = columns.first() {
            if first.len() != vals.len() {
                anyhow::bail!(
                    "--seeds {v}: {} values, but the first --seeds has {}: keys given together need as many values",
                    vals.len(),
                    first.len()
                );
            }
        }
        columns.push(vals.into_iter().map(|x| format!("{key}={x}")).collect());
    }
    let n = columns.first().map_or(0, Vec::len);
    Ok((0..n).map(|k| columns.iter().map(|c| c[k].clone()).collect()).collect())
}

/// Marks the points not dominated in (compute time, error).
pub fn mark_pareto(points: &mut [Point]) {
    let ok: Vec<bool> = points.iter().map(|p| p.status == "ok" && p.error_rms.is_finite()).collect();
    for i in 0..points.len() {
        points[i].pareto = ok[i]
            && !(0..points.len()).any(|j| {
                ok[j]
                    && j != i
                    && points[j].compute_s <= points[i].compute_s
                    && points[j].error_rms <= points[i].error_rms
                    && (points[j].compute_s < points[i].compute_s || points[j].error_rms < points[i].error_rms)
            });
    }
}

/// Scatter plot of error against compute time (SVG), Pareto front joined.
pub fn svg(points: &[Point], title: &str) -> String {
    let ok: Vec<&Point> = points.iter().filter(|p| p.status == "ok" && p.error_rms.is_finite()).collect();
    let (w, h, m) = (640.0, 420.0, 60.0);
    let xmax = ok.iter().map(|p| p.compute_s).fold(0.0, f64::max).max(1e-9) * 1.1;
    let ymax = ok.iter().map(|p| p.error_rms).fold(0.0, f64::max).max(1e-9) * 1.1;
    let px = |x: f64| m + (w - 2.0 * m) * x / xmax;
    let py = |y: f64| h - m - (h - 2.0 * m) * y / ymax;
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(s, r#"<rect width="100%" height="100%" fill="white"/>"#);
    let _ = writeln!(s, r#"<text x="{}" y="20" text-anchor="middle" font-size="14">{}</text>"#, w / 2.0, xml(title));
    let _ = writeln!(s, r#"<line x1="{m}" y1="{}" x2="{}" y2="{}" stroke="black"/>"#, h - m, w - m, h - m);
    let _ = writeln!(s, r#"<line x1="{m}" y1="{m}" x2="{m}" y2="{}" stroke="black"/>"#, h - m);
    for k in 0..=4 {
        let (xv, yv) = (xmax * k as f64 / 4.0, ymax * k as f64 / 4.0);
        let _ = writeln!(s, r#"<text x="{:.1}" y="{}" text-anchor="middle">{xv:.2}</text>"#, px(xv), h - m + 16.0);
        let _ = writeln!(
            s,
            r#"<text x="{}" y="{:.1}" text-anchor="end">{:.1} %</text>"#,
            m - 6.0,
            py(yv) + 4.0,
            100.0 * yv
        );
    }
    let _ = writeln!(
        s,
        r#"<text x="{}" y="{}" text-anchor="middle">compute CPU, all stages (s)</text>"#,
        w / 2.0,
        h - 18.0
    );
    let _ = writeln!(
        s,
        r#"<text x="16" y="{}" transform="rotate(-90 16 {})" text-anchor="middle">RMS vector error / v_max</text>"#,
        h / 2.0,
        h / 2.0
    );
    let mut front: Vec<&&Point> = ok.iter().filter(|p| p.pareto).collect();
    front.sort_by(|a, b| a.compute_s.total_cmp(&b.compute_s));
    if front.len() > 1 {
        let pts: Vec<String> = front.iter().map(|p| format!("{:.1},{:.1}", px(p.compute_s), py(p.error_rms))).collect();
        let _ =
            writeln!(s, r#"<polyline points="{}" fill="none" stroke="crimson" stroke-width="1.5"/>"#, pts.join(" "));
    }
    for p in &ok {
        let (fill, r) = if p.pareto { ("crimson", 5.0) } else { ("steelblue", 4.0) };
        let _ = writeln!(
            s,
            r#"<circle cx="{:.1}" cy="{:.1}" r="{r}" fill="{fill}"><title>{}</title></circle>"#,
            px(p.compute_s),
            py(p.error_rms),
            xml(&p.settings.join(", "))
        );
        let _ = writeln!(
            s,
            r#"<text x="{:.1}" y="{:.1}" font-size="10">{}</text>"#,
            px(p.compute_s) + 7.0,
            py(p.error_rms) - 5.0,
            p.index
        );
    }
    s.push_str("</svg>\n");
    s
}

fn xml(t: &str) -> String {
    t.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// `sonoflow sweep …`; `registry`: the node kinds the swept graph may use.
pub fn run_sweep(cmd: &SweepCmd, registry: &'static [sonoflow_node_kit::KindSpec]) -> anyhow::Result<i32> {
    match &cmd.sub {
        Some(SweepSub::Collect { dir, resume, wait }) => collect(dir, *resume, *wait, registry),
        Some(SweepSub::Task { dir, index }) => plan::run_task(dir, *index, registry),
        None => start(&cmd.args, registry),
    }
}

/// Plans a sweep, then runs it here or submits it to Slurm.
fn start(a: &SweepArgs, registry: &'static [sonoflow_node_kit::KindSpec]) -> anyhow::Result<i32> {
    let Some(file) = &a.file else { anyhow::bail!("sweep: give a launch file (or `sonoflow sweep collect DIR`)") };
    if a.field != "regularised" && a.field != "raw" {
        anyhow::bail!("--field {}: allowed regularised, raw", a.field);
    }
    if a.executor == Executor::Local {
        for (given, opt) in [
            (a.partition.is_some(), "--partition"),
            (a.time.is_some(), "--time"),
            (a.cpus.is_some(), "--cpus"),
            (!a.sbatch.is_empty(), "--sbatch"),
            (a.wait, "--wait"),
            (a.hold, "--hold"),
        ] {
            if given {
                anyhow::bail!("{opt} applies to Slurm sweeps only: add --executor slurm");
            }
        }
    }
    // The grid of settings.
    let mut axes: Vec<Vec<String>> = Vec::new();
    for v in &a.vary {
        let Some((key, values)) = v.split_once('=') else {
            anyhow::bail!("--vary {v}: expected NODE.PARAM=V1,V2,…");
        };
        let vals = split_values(values);
        if vals.iter().any(String::is_empty) {
            anyhow::bail!("--vary {v}: empty value in the list");
        }
        axes.push(vals.into_iter().map(|x| format!("{key}={x}")).collect());
    }
    if a.vary.is_empty() && a.seeds.is_empty() {
        anyhow::bail!("sweep: nothing to vary: give --vary NODE.PARAM=V1,V2,… and/or --seeds NODE.PARAM=S1,S2,…");
    }
    let mut settings: Vec<Vec<String>> = vec![Vec::new()];
    for axis in &axes {
        settings =
            settings.iter().flat_map(|c| axis.iter().map(move |x| [c.clone(), vec![x.clone()]].concat())).collect();
    }
    let reals = realisations(&a.seeds)?;
    // (setting index, settings of the run)
    let runs: Vec<plan::PlanRun> = if reals.is_empty() {
        settings.iter().enumerate().map(|(g, c)| plan::PlanRun { group: g, settings: c.clone() }).collect()
    } else {
        let mut runs = Vec::new();
        for (g, c) in settings.iter().enumerate() {
            runs.extend(reals.iter().map(|r| plan::PlanRun { group: g, settings: [c.clone(), r.clone()].concat() }));
        }
        runs
    };
    if runs.len() > 1000 {
        anyhow::bail!("--vary × --seeds: {} runs; at most 1000", runs.len());
    }
    let launch_file = std::path::absolute(file).map_err(|e| anyhow::anyhow!("{}: {e}", file.display()))?;
    let launch_text =
        std::fs::read_to_string(&launch_file).map_err(|e| anyhow::anyhow!("{}: {e}", launch_file.display()))?;
    let mut plan = Plan {
        version: plan::PLAN_VERSION,
        launch_file,
        launch_text,
        set: a.set.clone(),
        swap: a.swap.clone(),
        label: a.label.clone(),
        field: a.field.clone(),
        graph: String::new(),
        seeds: a.seeds.clone(),
        settings,
        runs,
        executor: a.executor,
        slurm: (a.executor == Executor::Slurm).then(|| slurm::SlurmOptions {
            partition: a.partition.clone(),
            time: a.time.clone(),
            cpus: a.cpus.unwrap_or(2),
            sbatch: a.sbatch.clone(),
        }),
        jobs: Vec::new(),
    };
    // Check every combination before running any.
    let mut errors = Vec::new();
    let mut graphs = Vec::new();
    for k in 0..plan.runs.len() {
        match plan.graph(k, registry) {
            Ok(g) => graphs.push(g),
            Err(e) => errors.extend(e.into_iter().map(|e| format!("[{}] {e}", plan.runs[k].settings.join(", ")))),
        }
    }
    if !errors.is_empty() {
        for e in &errors {
            eprintln!("error: {e}");
        }
        eprintln!("{} problem(s) found; nothing was run", errors.len());
        return Ok(2);
    }
    plan.graph = graphs.first().map(|g| g.graph.name.clone()).unwrap_or_default();
    if !graphs
        .iter()
        .all(|g| g.nodes.iter().any(|n| matches!(&n.program, launch::Program::Builtin(k) if k == "evaluator")))
    {
        anyhow::bail!("{}: a sweep needs an `evaluator` node in the graph (it measures the error)", file.display());
    }
    drop(graphs);
    if a.executor == Executor::Slurm {
        slurm::check_client()?;
    }
    let out = a
        .out
        .clone()
        .unwrap_or_else(|| sonoflow_launcher::supervise::default_out_dir(&format!("{}-sweep", plan.graph)));
    std::fs::create_dir_all(&out).map_err(|e| anyhow::anyhow!("creating {}: {e}", out.display()))?;
    let out = out.canonicalize()?;
    if out.join(plan::PLAN_FILE).exists() {
        anyhow::bail!(
            "{} already holds a sweep: gather it with `sonoflow sweep collect {}` (--resume runs what is missing), or choose another --out",
            out.display(),
            out.display()
        );
    }
    plan.save(&out)?;
    let total = plan.runs.len();
    match a.executor {
        Executor::Local => {
            for k in 0..total {
                eprintln!("sweep: point {}/{total}: {}", k + 1, plan.runs[k].settings.join(", "));
                plan::run_point(&plan, &out, k, registry)?;
                let p = plan::read_point(&plan, &out, k, &Default::default());
                eprintln!(
                    "sweep: point {}/{total}: {} — error {:.2} % of v_max, compute {:.2} s, wall {:.2} s",
                    k + 1,
                    p.status,
                    100.0 * p.error_rms,
                    p.compute_s,
                    p.wall_s
                );
                if sonoflow_launcher::supervise::interrupted() {
                    eprintln!(
                        "sweep: interrupted during point {}/{total}: the {} point(s) run so far are written, the rest not run (`sonoflow sweep collect {} --resume` runs them)",
                        k + 1,
                        k + 1,
                        out.display()
                    );
                    break;
                }
            }
            let code = report(&out, &plan, &Default::default())?;
            Ok(if sonoflow_launcher::supervise::interrupted() { 130 } else { code })
        }
        Executor::Slurm => {
            let all: Vec<usize> = (0..total).collect();
            let job = slurm::submit(&out, &mut plan, &all, a.wait, a.hold)?;
            if a.wait {
                return collect(&out, false, false, registry);
            }
            println!(
                "sweep: {total} point(s) submitted as Slurm job array {job}; when they have run: sonoflow sweep collect {}",
                out.display()
            );
            Ok(0)
        }
    }
}

/// `sonoflow sweep collect DIR [--resume [--wait]]`.
fn collect(
    dir: &Path,
    resume: bool,
    wait: bool,
    registry: &'static [sonoflow_node_kit::KindSpec],
) -> anyhow::Result<i32> {
    let mut plan = Plan::load(dir)?;
    if wait && !(resume && plan.executor == Executor::Slurm) {
        anyhow::bail!("--wait applies to `collect --resume` of a Slurm sweep only");
    }
    let active = match plan.executor {
        Executor::Slurm => slurm::active(&plan.jobs).unwrap_or_else(|e| {
            eprintln!("sweep collect: warning: cannot ask Slurm which tasks are still queued or running ({e}); every point without a result counts as missing");
            Default::default()
        }),
        Executor::Local => Default::default(),
    };
    if resume {
        let todo: Vec<usize> = (0..plan.runs.len())
            .filter(|k| !active.contains(k) && plan::read_point(&plan, dir, *k, &active).status != "ok")
            .collect();
        if todo.is_empty() {
            eprintln!("sweep collect: nothing to resume: every point has run (or is still queued or running)");
        } else {
            match plan.executor {
                Executor::Local => {
                    for (i, &k) in todo.iter().enumerate() {
                        eprintln!(
                            "sweep: resuming point {} ({}/{}): {}",
                            k,
                            i + 1,
                            todo.len(),
                            plan.runs[k].settings.join(", ")
                        );
                        plan::run_point(&plan, dir, k, registry)?;
                        if sonoflow_launcher::supervise::interrupted() {
                            break;
                        }
                    }
                }
                Executor::Slurm => {
                    let job = slurm::submit(dir, &mut plan, &todo, wait, false)?;
                    let list: Vec<String> = todo.iter().map(usize::to_string).collect();
                    eprintln!("sweep collect: point(s) {} resubmitted as Slurm job array {job}", list.join(", "));
                    if !wait {
                        println!("sweep: when they have run: sonoflow sweep collect {}", dir.display());
                        return Ok(0);
                    }
                }
            }
        }
        let active = match plan.executor {
            Executor::Slurm => slurm::active(&plan.jobs).unwrap_or_default(),
            Executor::Local => Default::default(),
        };
        return report(dir, &plan, &active);
    }
    report(dir, &plan, &active)
}

/// Gathers the points, writes the tables and the figure, lists what is not done; exit status 0
/// when every point ran and was evaluated, else 1.
fn report(dir: &Path, plan: &Plan, active: &std::collections::BTreeSet<usize>) -> anyhow::Result<i32> {
    let mut points: Vec<Point> = (0..plan.runs.len()).map(|k| plan::read_point(plan, dir, k, active)).collect();
    write_outputs(dir, plan, &mut points)?;
    let bad: Vec<&Point> = points.iter().filter(|p| p.status != "ok").collect();
    if !bad.is_empty() {
        eprintln!("sweep: {} of {} point(s) not done:", bad.len(), points.len());
        for p in &bad {
            eprintln!("  point {} ({}): {}", p.index, p.settings.join(", "), p.status);
        }
        if bad.iter().any(|p| !active.contains(&p.index)) {
            eprintln!("  run them again with: sonoflow sweep collect {} --resume", dir.display());
        }
    }
    Ok(if bad.is_empty() { 0 } else { 1 })
}

/// Writes `sweep.csv`, `sweep.md`, `sweep-seeds.csv` (with seeds) and `sweep.svg` into `out`.
fn write_outputs(out: &Path, plan: &Plan, points: &mut [Point]) -> anyhow::Result<()> {
    let name = &plan.graph;
    mark_pareto(points);
    let mut csv =
        String::from("index,settings,status,compute_s,wall_s,error_rms,x_abs_p75,z_abs_p75,x_gain,z_gain,pareto\n");
    for p in points.iter() {
        let _ = writeln!(
            csv,
            "{},\"{}\",\"{}\",{},{},{},{},{},{},{},{}",
            p.index,
            p.settings.join("; ").replace('"', "\"\""),
            p.status.replace('"', "\"\""),
            p.compute_s,
            p.wall_s,
            p.error_rms,
            p.x_abs_p75,
            p.z_abs_p75,
            p.x_gain,
            p.z_gain,
            p.pareto
        );
    }
    sonoflow_fileio::write_atomic(&out.join("sweep.csv"), csv.as_bytes())?;
    let mut md = format!(
        "# Sweep of `{}` ({} points, field `{}`)\n\nError = RMS vector error / v_max, mean over packets; ★ = Pareto front (no other point is both faster and more accurate).\n\n| # | settings | status | compute CPU (s) | wall (s) | error | x \\|e\\|₇₅ | z \\|e\\|₇₅ | |\n|---:|---|---|---:|---:|---:|---:|---:|---|\n",
        name,
        points.len(),
        plan.field
    );
    for p in points.iter() {
        let _ = writeln!(
            md,
            "| {} | {} | {} | {:.2} | {:.2} | {:.2} % | {:.1} % | {:.1} % | {} |",
            p.index,
            p.settings.join(", "),
            p.status,
            p.compute_s,
            p.wall_s,
            100.0 * p.error_rms,
            100.0 * p.x_abs_p75,
            100.0 * p.z_abs_p75,
            if p.pareto { "★" } else { "" }
        );
    }
    if !plan.seeds.is_empty() {
        let n_reals = realisations(&plan.seeds)?.len();
        let sp = spreads(points, &plan.settings);
        let pm = |(m, sd): (f64, f64)| format!("{:.2} ± {:.2} %", 100.0 * m, 100.0 * sd);
        let _ = write!(
            md,
            "\n## Over {} realisations ({})\n\nMean ± sample standard deviation over the realisations of each setting (x, z |e|₇₅: mean over packets, % of v_max).\n\n| settings | n | x \\|e\\|₇₅ | z \\|e\\|₇₅ | error | compute CPU (s) |\n|---|---:|---:|---:|---:|---:|\n",
            n_reals,
            plan.seeds.join("; ")
        );
        let mut scsv = String::from("settings,n,x_abs_p75_mean,x_abs_p75_sd,z_abs_p75_mean,z_abs_p75_sd,error_rms_mean,error_rms_sd,compute_s_mean\n");
        for s in &sp {
            let name = if s.settings.is_empty() { "(as in the file)".to_string() } else { s.settings.join(", ") };
            let _ = writeln!(
                md,
                "| {name} | {} | {} | {} | {} | {:.2} |",
                s.n,
                pm(s.x_abs_p75),
                pm(s.z_abs_p75),
                pm(s.error_rms),
                s.compute_s.0
            );
            let _ = writeln!(
                scsv,
                "\"{}\",{},{},{},{},{},{},{},{}",
                s.settings.join("; ").replace('"', "\"\""),
                s.n,
                s.x_abs_p75.0,
                s.x_abs_p75.1,
                s.z_abs_p75.0,
                s.z_abs_p75.1,
                s.error_rms.0,
                s.error_rms.1,
                s.compute_s.0
            );
            println!(
                "sweep: {name}: x |e|75 {}, z |e|75 {} over {} realisation(s)",
                pm(s.x_abs_p75),
                pm(s.z_abs_p75),
                s.n
            );
        }
        sonoflow_fileio::write_atomic(&out.join("sweep-seeds.csv"), scsv.as_bytes())?;
    }
    let _ = writeln!(md, "\n![error against run time](sweep.svg)");
    sonoflow_fileio::write_atomic(&out.join("sweep.md"), md.as_bytes())?;
    sonoflow_fileio::write_atomic(
        &out.join("sweep.svg"),
        svg(points, &format!("{name}: error against run time")).as_bytes(),
    )?;
    println!("sweep: {} point(s) → {}", points.len(), out.join("sweep.md").display());
    Ok(())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn values_split_at_top_level_commas_only() {
        assert_eq!(split_values("1, 2.5,x"), ["1", "2.5", "x"]);
        assert_eq!(split_values("[1,1],[3,3]"), ["[1,1]", "[3,3]"]);
        assert_eq!(split_values(r#""a,b",{ x = 1, y = 2 }"#), [r#""a,b""#, "{ x = 1, y = 2 }"]);
    }

    fn pt(i: usize, t: f64, e: f64) -> Point {
        Point {
            index: i,
            settings: vec![],
            status: "ok".into(),
            compute_s: t,
            wall_s: t,
            error_rms: e,
            x_abs_p75: e,
            z_abs_p75: e,
            x_gain: 1.0,
            z_gain: 1.0,
            pareto: false,
            group: 0,
        }
    }

    #[test]
    fn realisations_zip_the_seed_keys_and_spreads_summarise_each_setting() {
        let r = realisations(&["flow.seed=1,2,3".into(), "flow.position_seed=7,8,9".into()]).unwrap();
        assert_eq!(r[1], ["flow.seed=2", "flow.position_seed=8"]);
        assert!(realisations(&["a.b=1,2".into(), "c.d=1".into()]).unwrap_err().to_string().contains("as many"));
        assert!(realisations(&["a.b".into()]).is_err());
        assert_eq!(mean_sd(&[1.0, 2.0, 3.0, 4.0]), (2.5, (5.0f64 / 3.0).sqrt()));
        assert!(mean_sd(&[2.0]).1.is_nan() && mean_sd(&[]).0.is_nan());
        let mut pts = vec![pt(0, 1.0, 0.1), pt(1, 3.0, 0.3), pt(2, 2.0, 0.5), pt(3, 2.0, 0.9)];
        pts[2].group = 1;
        pts[3].group = 1;
        pts[3].status = "failed (exit 1)".into();
        let sp = spreads(&pts, &[vec!["a=1".into()], vec!["a=2".into()]]);
        assert_eq!((sp[0].n, sp[1].n), (2, 1), "failed runs are left out");
        assert!((sp[0].x_abs_p75.0 - 0.2).abs() < 1e-15 && (sp[0].x_abs_p75.1 - 0.02f64.sqrt()).abs() < 1e-15);
        assert_eq!(sp[0].compute_s.0, 2.0);
        assert_eq!(sp[1].error_rms.0, 0.5);
    }

    #[test]
    fn pareto_front_keeps_the_non_dominated_points() {
        // (time, error): 0 fast+bad, 1 dominated by 0, 2 slow+good, 3 middle, 4 dominated by 3, 5 failed.
        let mut p = vec![
            pt(0, 1.0, 0.3),
            pt(1, 2.0, 0.35),
            pt(2, 5.0, 0.1),
            pt(3, 2.0, 0.2),
            pt(4, 3.0, 0.2),
            pt(5, 0.5, 0.01),
        ];
        p[5].status = "failed (exit 1)".into();
        mark_pareto(&mut p);
        let front: Vec<usize> = p.iter().filter(|q| q.pareto).map(|q| q.index).collect();
        assert_eq!(front, [0, 2, 3]);
        let s = svg(&p, "t");
        assert_eq!(s.matches("<circle").count(), 5, "failed points are not plotted");
        assert_eq!(s.matches("fill=\"crimson\"").count(), 3);
    }
}
