//! Sweeps on a Slurm cluster: the points of a sweep are the tasks of one job array
//! (`sbatch --array`); each task runs `sonoflow sweep task DIR $SLURM_ARRAY_TASK_ID` into its own
//! `point-NNN` folder. Slurm does the scheduling; this module only writes the batch script,
//! submits it, and asks `squeue` which tasks are still queued or running.
//!
//! The sweep folder and the `sonoflow` binary must be visible at the same paths on the compute
//! nodes (a shared file system), as for any Slurm job.

use super::plan::{Job, Plan};
use std::collections::BTreeSet;
use std::io::BufRead as _;
use std::path::Path;
use std::process::{Command, Stdio};

/// Batch options of a Slurm sweep (recorded in the plan, reused by `--resume`).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SlurmOptions {
    pub partition: Option<String>,
    pub time: Option<String>,
    pub cpus: u32,
    /// Further `sbatch` options, passed as given.
    pub sbatch: Vec<String>,
}

/// Name of the batch script inside the sweep folder.
pub const SCRIPT: &str = "sweep.sbatch";

/// Fails with a clear message when Slurm's client commands are not on PATH.
pub fn check_client() -> anyhow::Result<()> {
    for cmd in ["sbatch", "squeue"] {
        let found =
            std::env::var_os("PATH").map(|p| std::env::split_paths(&p).any(|d| d.join(cmd).is_file())).unwrap_or(false);
        if !found {
            anyhow::bail!(
                "--executor slurm: `{cmd}` is not on PATH; run the sweep where Slurm's client commands are (a login node of the cluster)"
            );
        }
    }
    Ok(())
}

/// `0-3,5,7-9`: the indices as an `--array` list (sorted, runs joined).
pub fn array_spec(indices: &[usize]) -> String {
    let mut v: Vec<usize> = indices.to_vec();
    v.sort_unstable();
    v.dedup();
    let mut parts = Vec::new();
    let mut i = 0;
    while i < v.len() {
        let mut j = i;
        while j + 1 < v.len() && v[j + 1] == v[j] + 1 {
            j += 1;
        }
        parts.push(if j > i { format!("{}-{}", v[i], v[j]) } else { v[i].to_string() });
        i = j + 1;
    }
    parts.join(",")
}

fn quote(s: &str) -> String {
    format!("'{}'", s.replace('\'', r"'\''"))
}

/// The `sbatch` options of the sweep in `dir` (given on sbatch's command line, so that paths
/// and user values need no quoting), before the `--array` list and `--sbatch` extras.
pub fn sbatch_options(dir: &Path, plan: &Plan, o: &SlurmOptions) -> Vec<String> {
    let name: String =
        plan.graph.chars().filter(|c| c.is_ascii_alphanumeric() || *c == '-' || *c == '_').take(40).collect();
    let mut v = vec![
        format!("--job-name=sonoflow-sweep-{name}"),
        format!("--output={}", dir.join("slurm").join("%A_%a.out").display()),
        format!("--cpus-per-task={}", o.cpus),
    ];
    if let Some(p) = &o.partition {
        v.push(format!("--partition={p}"));
    }
    if let Some(t) = &o.time {
        v.push(format!("--time={t}"));
    }
    v
}

/// The batch script: one point per array task.
pub fn script(dir: &Path, exe: &Path) -> String {
    format!(
        "#!/bin/bash\n# Written by `sonoflow sweep --executor slurm`: one sweep point per array task. The options\n# (--array, --cpus-per-task, …) are on sbatch's command line, recorded in sweep-plan.json.\nexec {} sweep task {} \"$SLURM_ARRAY_TASK_ID\"\n",
        quote(&exe.display().to_string()),
        quote(&dir.display().to_string())
    )
}

/// Submits points `indices` of the sweep in `dir` as one job array; records the job in the plan
/// (saved before waiting). With `wait`, returns when every task has ended (`sbatch --wait`);
/// `hold` submits it held (`sbatch --hold`).
pub fn submit(dir: &Path, plan: &mut Plan, indices: &[usize], wait: bool, hold: bool) -> anyhow::Result<String> {
    check_client()?;
    let Some(o) = plan.slurm.clone() else { anyhow::bail!("{}: not a Slurm sweep", dir.display()) };
    let exe = std::env::current_exe().map_err(|e| anyhow::anyhow!("finding the sonoflow binary: {e}"))?;
    std::fs::create_dir_all(dir.join("slurm"))?;
    let path = dir.join(SCRIPT);
    sonoflow_fileio::write_atomic(&path, script(dir, &exe).as_bytes())?;
    let mut cmd = Command::new("sbatch");
    cmd.arg("--parsable")
        .args(sbatch_options(dir, plan, &o))
        .arg(format!("--array={}", array_spec(indices)))
        .args(&o.sbatch);
    if wait {
        cmd.arg("--wait");
    }
    if hold {
        cmd.arg("--hold");
    }
    cmd.arg(&path).current_dir(dir).stdout(Stdio::piped()).stderr(Stdio::piped());
    let mut child = cmd.spawn().map_err(|e| anyhow::anyhow!("starting sbatch: {e}"))?;
    // `--parsable` prints "jobid[;cluster]" as soon as the array is queued (before `--wait` waits).
    let mut line = String::new();
    if let Some(out) = child.stdout.take() {
        std::io::BufReader::new(out).read_line(&mut line)?;
    }
    let id = line.trim().split(';').next().unwrap_or("").to_string();
    if !id.is_empty() && id.chars().all(|c| c.is_ascii_digit()) {
        plan.jobs.push(Job { id: id.clone(), indices: indices.to_vec() });
        plan.save(dir)?;
        if wait {
            eprintln!("sweep: Slurm job array {id} ({} task(s)) submitted; waiting for it to end", indices.len());
        }
    }
    let status = child.wait()?;
    let mut err = String::new();
    if let Some(mut e) = child.stderr.take() {
        use std::io::Read as _;
        let _ = e.read_to_string(&mut err);
    }
    if id.is_empty() || !id.chars().all(|c| c.is_ascii_digit()) {
        anyhow::bail!("sbatch refused the job array ({status}): {}{}", line.trim(), err.trim());
    }
    // With --wait, sbatch's own status is non-zero when any task failed: `collect` reports which.
    Ok(id)
}

/// Point indices of the recorded jobs that Slurm still has queued or running.
pub fn active(jobs: &[Job]) -> anyhow::Result<BTreeSet<usize>> {
    if jobs.is_empty() {
        return Ok(BTreeSet::new());
    }
    // All of this user's array tasks, one per line: "<array job id> <task id>" (a task of a
    // pending array that Slurm has not split yet shows as a range such as "[2-5%4]" or "2,4").
    let out = Command::new("squeue")
        .args(["--noheader", "--array", "--me", "--format=%F %K"])
        .output()
        .map_err(|e| anyhow::anyhow!("squeue: {e}"))?;
    if !out.status.success() {
        anyhow::bail!("squeue: {}", String::from_utf8_lossy(&out.stderr).trim());
    }
    let ids: BTreeSet<&str> = jobs.iter().map(|j| j.id.as_str()).collect();
    let mut set = BTreeSet::new();
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        let mut f = line.split_whitespace();
        let (Some(job), Some(task)) = (f.next(), f.next()) else { continue };
        if !ids.contains(job) {
            continue;
        }
        set.extend(parse_tasks(task));
    }
    Ok(set)
}

/// `3`, `[2-5%4]`, `1,3-4` → the task ids.
pub fn parse_tasks(s: &str) -> Vec<usize> {
    let s = s.trim_start_matches('[').trim_end_matches(']');
    let s = s.split('%').next().unwrap_or("");
    let mut v = Vec::new();
    for part in s.split(',') {
        match part.split_once('-') {
            Some((a, b)) => {
                if let (Ok(a), Ok(b)) = (a.parse::<usize>(), b.parse::<usize>()) {
                    v.extend(a..=b.min(a + 100_000));
                }
            }
            None => v.extend(part.parse::<usize>().ok()),
        }
    }
    v
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn array_lists_join_runs_and_squeue_ranges_expand() {
        assert_eq!(array_spec(&[5, 0, 1, 2, 3, 7, 8, 9]), "0-3,5,7-9");
        assert_eq!(array_spec(&[4]), "4");
        assert_eq!(parse_tasks("3"), [3]);
        assert_eq!(parse_tasks("[2-5%4]"), [2, 3, 4, 5]);
        assert_eq!(parse_tasks("1,3-4"), [1, 3, 4]);
        assert!(parse_tasks("N/A").is_empty());
    }

    #[test]
    fn the_options_and_the_script_name_the_task_and_quote_paths() {
        let plan: Plan = serde_json::from_value(serde_json::json!({
            "version": 1, "launch_file": "/a/b.toml", "launch_text": "", "set": [], "swap": [], "label": null,
            "field": "raw", "graph": "quick start", "seeds": [], "settings": [], "runs": [],
            "executor": "slurm", "slurm": null, "jobs": []
        }))
        .unwrap();
        let o = SlurmOptions { partition: Some("short".into()), time: Some("10:00".into()), cpus: 3, sbatch: vec![] };
        let dir = Path::new("/runs/it's here");
        assert_eq!(
            sbatch_options(dir, &plan, &o),
            [
                "--job-name=sonoflow-sweep-quickstart",
                "--output=/runs/it's here/slurm/%A_%a.out",
                "--cpus-per-task=3",
                "--partition=short",
                "--time=10:00"
            ]
        );
        let s = script(dir, Path::new("/bin/sonoflow"));
        assert!(s.ends_with("exec '/bin/sonoflow' sweep task '/runs/it'\\''s here' \"$SLURM_ARRAY_TASK_ID\"\n"), "{s}");
    }
}
