//! `sonoflow sweep --executor slurm` against a real Slurm (slurmctld + slurmd + munge on this
//! machine, set up by `.ci/slurm-single-node.sh`, which CI runs): a quickstart sweep of 4 settings
//! × 2 seeds submitted as one job array, one task cancelled before it runs and one made to fail,
//! `collect` listing both, `collect --resume` completing them, and every number of each point's
//! `evaluation.json` equal to the same sweep run locally.
//!
//! Without Slurm on PATH the test says so and passes, unless `SONOFLOW_REQUIRE_SLURM=1` (CI).
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

fn on_path(cmd: &str) -> bool {
    std::env::var_os("PATH").is_some_and(|p| std::env::split_paths(&p).any(|d| d.join(cmd).is_file()))
}

fn slurm_up() -> bool {
    on_path("sbatch")
        && Command::new("sinfo").args(["-h", "-o", "%t"]).output().is_ok_and(|o| {
            let s = String::from_utf8_lossy(&o.stdout).to_string();
            o.status.success() && (s.contains("idle") || s.contains("mix") || s.contains("alloc"))
        })
}

fn sonoflow(args: &[&str]) -> Output {
    Command::new(common::bin()).args(args).output().unwrap()
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

/// Cancels every job array the sweep in `dir` submitted, also when the test fails.
struct CancelJobs(PathBuf);

impl Drop for CancelJobs {
    fn drop(&mut self) {
        for id in job_ids(&self.0) {
            let _ = Command::new("scancel").arg(&id).output();
        }
    }
}

fn plan(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("sweep-plan.json")).unwrap_or_default()).unwrap_or_default()
}

fn job_ids(dir: &Path) -> Vec<String> {
    plan(dir)["jobs"]
        .as_array()
        .map(|js| js.iter().filter_map(|j| j["id"].as_str().map(String::from)).collect())
        .unwrap_or_default()
}

/// Waits until Slurm no longer lists job `id` (finished, or already purged).
fn wait_for(id: &str, limit: Duration) {
    let t0 = Instant::now();
    loop {
        let o = Command::new("squeue").args(["-h", "-j", id]).output().unwrap();
        if !o.status.success() || o.stdout.iter().all(u8::is_ascii_whitespace) {
            return;
        }
        assert!(t0.elapsed() < limit, "job {id} still queued after {limit:?}: {}", String::from_utf8_lossy(&o.stdout));
        std::thread::sleep(Duration::from_millis(500));
    }
}

/// Every number in `a` equals the one at the same place in `b` (strings, such as run ids and
/// paths, may differ); returns how many numbers were compared.
fn same_numbers(a: &serde_json::Value, b: &serde_json::Value, at: &str) -> usize {
    use serde_json::Value as V;
    match (a, b) {
        (V::Number(x), V::Number(y)) => {
            assert_eq!(x.as_f64(), y.as_f64(), "{at}");
            1
        }
        (V::Array(x), V::Array(y)) => {
            assert_eq!(x.len(), y.len(), "{at}");
            x.iter().zip(y).enumerate().map(|(i, (p, q))| same_numbers(p, q, &format!("{at}[{i}]"))).sum()
        }
        (V::Object(x), V::Object(y)) => {
            assert_eq!(x.keys().collect::<Vec<_>>(), y.keys().collect::<Vec<_>>(), "{at}");
            x.iter().map(|(k, v)| same_numbers(v, &y[k], &format!("{at}.{k}"))).sum()
        }
        (V::String(_), V::String(_)) => 0,
        _ => {
            assert_eq!(a, b, "{at}");
            0
        }
    }
}

fn csv_status(dir: &Path) -> Vec<String> {
    let csv = std::fs::read_to_string(dir.join("sweep.csv")).unwrap();
    csv.lines().skip(1).map(|r| r.split('"').nth(3).unwrap_or("").to_string()).collect()
}

#[test]
fn a_slurm_sweep_equals_the_local_one_and_resume_completes_the_failed_tasks() {
    if !slurm_up() {
        assert_ne!(
            std::env::var("SONOFLOW_REQUIRE_SLURM").as_deref(),
            Ok("1"),
            "SONOFLOW_REQUIRE_SLURM=1 but no Slurm answers here (bash .ci/slurm-single-node.sh sets one up)"
        );
        eprintln!("skipped: no Slurm on this machine (sudo bash .ci/slurm-single-node.sh sets one up)");
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let (local, slurm) = (tmp.path().join("local"), tmp.path().join("slurm"));
    let _cancel = CancelJobs(slurm.clone());
    let quickstart = common::root().join("launch/quickstart.toml");
    let sweep = |extra: &[&str], out: &Path| {
        let mut a = vec![
            "sweep",
            quickstart.to_str().unwrap(),
            "--set",
            "flow.schedule.n_packets=1",
            "--set",
            "flow.schedule.packet_size=8",
            "--vary",
            "flow.density_per_mm2=2,3,4,5",
            "--seeds",
            "flow.seed=1,2",
            "--out",
            out.to_str().unwrap(),
        ];
        a.extend_from_slice(extra);
        sonoflow(&a)
    };

    // Submitted held, so that the test can cancel and break tasks before any runs.
    let o = sweep(&["--executor", "slurm", "--cpus", "1", "--hold"], &slurm);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(text(&o).contains("8 point(s) submitted as Slurm job array"), "{}", text(&o));
    let ids = job_ids(&slurm);
    assert_eq!(ids.len(), 1);
    let id = ids[0].clone();
    assert_eq!(plan(&slurm)["jobs"][0]["indices"], serde_json::json!([0, 1, 2, 3, 4, 5, 6, 7]));
    // While queued, collect reports the points as queued and does not count them missing.
    let o = sonoflow(&["sweep", "collect", slurm.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(csv_status(&slurm).iter().all(|s| s == "queued or running in Slurm"), "{:?}", csv_status(&slurm));
    assert!(!text(&o).contains("--resume"), "nothing to resume while all are queued: {}", text(&o));

    // Task 3 cancelled before it runs; task 5 (density 4, seed 2) made to fail: its density
    // becomes -1 in the plan, which the task refuses (exit 2).
    let cancelled = Command::new("scancel").arg(format!("{id}_3")).output().unwrap();
    assert!(cancelled.status.success(), "{}", text(&cancelled));
    let plan_path = slurm.join("sweep-plan.json");
    let original = std::fs::read_to_string(&plan_path).unwrap();
    assert!(original.contains("\"flow.density_per_mm2=4\",\n        \"flow.seed=2\""), "{original}");
    let mut broken = plan(&slurm);
    broken["runs"][5]["settings"][0] = "flow.density_per_mm2=-1".into();
    std::fs::write(&plan_path, serde_json::to_string_pretty(&broken).unwrap()).unwrap();
    let released = Command::new("scontrol").args(["release", &id]).output().unwrap();
    assert!(released.status.success(), "{}", text(&released));
    wait_for(&id, Duration::from_secs(900));

    let o = sonoflow(&["sweep", "collect", slurm.to_str().unwrap()]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(t.contains("2 of 8 point(s) not done"), "{t}");
    assert!(t.contains("point 3 (flow.density_per_mm2=3, flow.seed=2): not run"), "{t}");
    assert!(t.contains("point 5 (flow.density_per_mm2=-1, flow.seed=2): failed (exit 2)"), "{t}");
    assert!(t.contains("--resume"), "{t}");
    let st = csv_status(&slurm);
    assert_eq!(st.iter().filter(|s| *s == "ok").count(), 6, "{st:?}");
    assert!(slurm.join("slurm").join(format!("{id}_5.out")).exists(), "the task's Slurm log is kept");

    // Mended; --resume resubmits only points 3 and 5 and waits for them.
    std::fs::write(&plan_path, &original).unwrap();
    let o = sonoflow(&["sweep", "collect", slurm.to_str().unwrap(), "--resume", "--wait"]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(0), "{t}");
    assert!(t.contains("point(s) 3, 5 resubmitted as Slurm job array"), "{t}");
    let jobs = plan(&slurm)["jobs"].clone();
    assert_eq!(jobs.as_array().map(Vec::len), Some(2), "{jobs}");
    assert_eq!(jobs[1]["indices"], serde_json::json!([3, 5]));
    assert!(slurm.join("point-005.attempt-1").is_dir(), "the failed attempt is kept");
    assert!(csv_status(&slurm).iter().all(|s| s == "ok"), "{:?}", csv_status(&slurm));

    // The same sweep here, one point after the other: every number of every evaluation equal.
    let o = sweep(&[], &local);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let mut compared = 0;
    for k in 0..8 {
        let read = |d: &Path| -> serde_json::Value {
            serde_json::from_str(&std::fs::read_to_string(d.join(format!("point-{k:03}/evaluation.json"))).unwrap())
                .unwrap()
        };
        compared += same_numbers(&read(&local), &read(&slurm), &format!("point {k}"));
    }
    assert!(compared > 8 * 20, "only {compared} numbers compared");
    eprintln!("{compared} numbers of 8 evaluations equal between the local and the Slurm sweep");
    // and so the tables' error columns
    let cols = |d: &Path| -> Vec<Vec<String>> {
        let csv = std::fs::read_to_string(d.join("sweep.csv")).unwrap();
        csv.lines().skip(1).map(|r| r.rsplit(',').skip(1).take(5).map(String::from).collect()).collect()
    };
    assert_eq!(cols(&local), cols(&slurm));
    assert_eq!(
        std::fs::read_to_string(local.join("sweep-seeds.csv"))
            .unwrap()
            .lines()
            .map(|l| l.rsplit_once(',').map_or(l, |x| x.0).to_string())
            .collect::<Vec<_>>(),
        std::fs::read_to_string(slurm.join("sweep-seeds.csv"))
            .unwrap()
            .lines()
            .map(|l| l.rsplit_once(',').map_or(l, |x| x.0).to_string())
            .collect::<Vec<_>>(),
        "the spread over seeds (compute time aside)"
    );
}
