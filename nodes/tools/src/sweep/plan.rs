//! A sweep's plan (`sweep-plan.json`): the launch file's text as it was when the sweep started,
//! the overrides, and every point's settings — all a point needs to run anywhere (a Slurm array
//! task on another node, a resumed run) and all `collect` needs to gather the results.
//!
//! A point's folder `point-NNN` is the run's output folder; when the run has ended the task writes
//! `point-NNN/exit.json` (`{"exit": code}`), so a folder without it is a run that was killed,
//! cancelled or ran out of time.

use super::{Executor, Point};
use sonoflow_launcher::launch::{self, LaunchFile, Overrides, ResolvedGraph};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// File name of the plan inside the sweep folder.
pub const PLAN_FILE: &str = "sweep-plan.json";
/// Version of the plan's layout (a newer sonoflow refuses an unknown one with the reason).
pub const PLAN_VERSION: u32 = 1;
/// File a finished point writes into its folder.
pub const EXIT_FILE: &str = "exit.json";

/// One run of the sweep: the setting (`--vary` combination) it realises and its overrides.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PlanRun {
    pub group: usize,
    pub settings: Vec<String>,
}

/// A submitted Slurm job array and the point indices (array task ids) it runs.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Job {
    pub id: String,
    pub indices: Vec<usize>,
}

/// Everything a sweep's points need; written once when the sweep starts (jobs appended).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct Plan {
    pub version: u32,
    /// The launch file (absolute); relative paths in it resolve against its folder.
    pub launch_file: PathBuf,
    /// Its text when the sweep started (later edits of the file do not change the sweep).
    pub launch_text: String,
    pub set: Vec<String>,
    pub swap: Vec<String>,
    pub label: Option<String>,
    pub field: String,
    pub graph: String,
    /// The `--seeds` options (empty: no realisations).
    pub seeds: Vec<String>,
    /// The settings (`--vary` combinations); `runs[k].group` indexes them.
    pub settings: Vec<Vec<String>>,
    pub runs: Vec<PlanRun>,
    pub executor: Executor,
    pub slurm: Option<super::slurm::SlurmOptions>,
    /// Slurm job arrays submitted for this sweep, oldest first.
    pub jobs: Vec<Job>,
}

impl Plan {
    /// Reads `dir/sweep-plan.json`.
    pub fn load(dir: &Path) -> anyhow::Result<Plan> {
        let p = dir.join(PLAN_FILE);
        let text = std::fs::read_to_string(&p)
            .map_err(|e| anyhow::anyhow!("{}: {e} (is {} a sweep folder?)", p.display(), dir.display()))?;
        let v: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| anyhow::anyhow!("{}: not a sweep plan: {e}", p.display()))?;
        let version = v["version"].as_u64().unwrap_or(0);
        if version != u64::from(PLAN_VERSION) {
            anyhow::bail!(
                "{}: plan version {version}, this sonoflow reads version {PLAN_VERSION}: collect it with the sonoflow that made it",
                p.display()
            );
        }
        serde_json::from_value(v).map_err(|e| anyhow::anyhow!("{}: {e}", p.display()))
    }

    /// Writes `dir/sweep-plan.json` (atomically).
    pub fn save(&self, dir: &Path) -> anyhow::Result<()> {
        let text = serde_json::to_string_pretty(self)?;
        sonoflow_fileio::write_atomic(&dir.join(PLAN_FILE), text.as_bytes())?;
        Ok(())
    }

    /// The graph of run `k`: the launch text with the fixed and the run's overrides.
    pub fn graph(
        &self,
        k: usize,
        registry: &'static [sonoflow_node_kit::KindSpec],
    ) -> Result<ResolvedGraph, Vec<String>> {
        let Some(run) = self.runs.get(k) else {
            return Err(vec![format!(
                "point {k}: the sweep has {} points (0 … {})",
                self.runs.len(),
                self.runs.len().saturating_sub(1)
            )]);
        };
        let file: LaunchFile = toml::from_str(&self.launch_text)
            .map_err(|e| vec![format!("{}: {}", self.launch_file.display(), e.to_string().trim_end())])?;
        let base = self.launch_file.parent().map(Path::to_path_buf).unwrap_or_default();
        let ov = Overrides {
            set: [self.set.clone(), run.settings.clone()].concat(),
            swap: self.swap.clone(),
            lenient_files: false,
            ..Default::default()
        };
        launch::resolve(file, &base, &ov, registry)
    }
}

/// Folder of point `k`.
pub fn point_dir(dir: &Path, k: usize) -> PathBuf {
    dir.join(format!("point-{k:03}"))
}

/// Runs point `k` of the plan into `dir/point-NNN` and writes its exit status there; an earlier
/// attempt's folder is kept as `point-NNN.attempt-K`. Returns the run's exit status.
pub fn run_point(
    plan: &Plan,
    dir: &Path,
    k: usize,
    registry: &'static [sonoflow_node_kit::KindSpec],
) -> anyhow::Result<i32> {
    let pd = point_dir(dir, k);
    if pd.exists() {
        let mut n = 1;
        let mut keep = dir.join(format!("point-{k:03}.attempt-{n}"));
        while keep.exists() {
            n += 1;
            keep = dir.join(format!("point-{k:03}.attempt-{n}"));
        }
        std::fs::rename(&pd, &keep)
            .map_err(|e| anyhow::anyhow!("keeping the earlier attempt {} as {}: {e}", pd.display(), keep.display()))?;
    }
    let opts = sonoflow_launcher::supervise::RunOptions {
        out_dir: pd.clone(),
        run_id: sonoflow_launcher::supervise::new_run_id(&plan.graph),
        quiet: true,
    };
    // Checked when the sweep started; a file the graph reads may have gone since.
    let code = match plan.graph(k, registry) {
        Err(e) => {
            eprintln!("point {k}: {}", e.join("; "));
            2
        }
        Ok(g) => match sonoflow_launcher::run_graph(&g, &opts) {
            Ok(c) => c,
            Err(e) => {
                eprintln!("point {k}: {e:#}");
                1
            }
        },
    };
    std::fs::create_dir_all(&pd)?;
    sonoflow_fileio::write_atomic(&pd.join(EXIT_FILE), serde_json::json!({ "exit": code }).to_string().as_bytes())?;
    Ok(code)
}

/// `sonoflow sweep task DIR K`: one point, as a Slurm array task runs it. Exit status: the run's.
pub fn run_task(dir: &Path, k: usize, registry: &'static [sonoflow_node_kit::KindSpec]) -> anyhow::Result<i32> {
    let plan = Plan::load(dir)?;
    let Some(run) = plan.runs.get(k) else {
        anyhow::bail!("point {k}: the sweep in {} has {} points", dir.display(), plan.runs.len());
    };
    eprintln!("sweep task: point {k}: {}", run.settings.join(", "));
    let code = run_point(&plan, dir, k, registry)?;
    let p = read_point(&plan, dir, k, &BTreeSet::new());
    eprintln!(
        "sweep task: point {k}: {} — error {:.2} % of v_max, compute {:.2} s, wall {:.2} s",
        p.status,
        100.0 * p.error_rms,
        p.compute_s,
        p.wall_s
    );
    Ok(code)
}

fn read_json(p: &Path) -> anyhow::Result<serde_json::Value> {
    let text = std::fs::read_to_string(p).map_err(|e| anyhow::anyhow!("{}: {e}", p.display()))?;
    Ok(serde_json::from_str(&text)?)
}

/// Point `k` as its folder holds it: status (ok, failed with the exit status, ended without
/// one, queued or running in Slurm — `active` — or not run), cost from the run report, error
/// from the evaluation.
pub fn read_point(plan: &Plan, dir: &Path, k: usize, active: &BTreeSet<usize>) -> Point {
    let pd = point_dir(dir, k);
    let status = if active.contains(&k) {
        "queued or running in Slurm".to_string()
    } else if let Ok(v) = read_json(&pd.join(EXIT_FILE)) {
        match v["exit"].as_i64() {
            Some(0) => "ok".into(),
            Some(c) => format!("failed (exit {c})"),
            None => format!("failed ({} unreadable)", EXIT_FILE),
        }
    } else if pd.exists() {
        let log = match plan.executor {
            Executor::Slurm => format!("; see {} and slurm/*_{k}.out", pd.join("logs").display()),
            Executor::Local => format!("; see {}", pd.join("logs").display()),
        };
        format!("failed (ended without an exit status: killed, cancelled or out of time{log})")
    } else {
        "not run".to_string()
    };
    let run = &plan.runs[k];
    let mut p = Point {
        index: k,
        settings: run.settings.clone(),
        status,
        compute_s: f64::NAN,
        wall_s: f64::NAN,
        error_rms: f64::NAN,
        x_abs_p75: f64::NAN,
        z_abs_p75: f64::NAN,
        x_gain: f64::NAN,
        z_gain: f64::NAN,
        pareto: false,
        group: run.group,
    };
    if !pd.exists() || active.contains(&k) {
        return p;
    }
    if let Ok(r) = read_json(&pd.join("report.json")) {
        p.wall_s = r["wall_s"].as_f64().unwrap_or(f64::NAN);
        p.compute_s = r["nodes"]
            .as_array()
            .map(|ns| ns.iter().filter_map(|n| n["stats"]["compute_ns_total"].as_f64()).sum::<f64>() / 1e9)
            .unwrap_or(f64::NAN);
    }
    let eval_file = match &plan.label {
        Some(l) => format!("evaluation-{l}.json"),
        None => "evaluation.json".to_string(),
    };
    match read_json(&pd.join(&eval_file)) {
        Ok(e) => {
            let fields: Vec<&serde_json::Value> = e["packets"]
                .as_array()
                .map(|ps| ps.iter().filter_map(|p| p["fields"].get(&plan.field)).collect())
                .unwrap_or_default();
            if !fields.is_empty() {
                let mean = |f: &dyn Fn(&serde_json::Value) -> f64| {
                    fields.iter().map(|v| f(v)).sum::<f64>() / fields.len() as f64
                };
                let num = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
                p.error_rms = mean(&|v| num(&v["x"]["rms"]).hypot(num(&v["z"]["rms"])));
                p.x_abs_p75 = mean(&|v| num(&v["x"]["abs_p75"]));
                p.z_abs_p75 = mean(&|v| num(&v["z"]["abs_p75"]));
                p.x_gain = mean(&|v| num(&v["gain_x"]));
                p.z_gain = mean(&|v| num(&v["gain_z"]));
            } else if p.status == "ok" {
                p.status = format!("no `{}` field evaluated", plan.field);
            }
        }
        Err(e) if p.status == "ok" => p.status = format!("no evaluation: {e}"),
        Err(_) => {}
    }
    p
}
