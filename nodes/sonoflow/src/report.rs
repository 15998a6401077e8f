//! The run report: `report.json` (machine-readable) and `report.md` (human), written at the end
//! of every run; with an `evaluator` node in the graph, report.md also holds the errors against
//! ground truth (`evaluation.md`, the evaluator's table; `evaluation.json` beside it; with several
//! labelled evaluators, each one's `evaluation-<label>.md`).

use crate::run::RunReport;
use std::fmt::Write as _;
use std::path::Path;

/// Writes `report.json` and `report.md` into `dir` (atomically).
pub fn write(dir: &Path, r: &RunReport) -> anyhow::Result<()> {
    crate::nodeutil::write_atomic(&dir.join("report.json"), serde_json::to_string_pretty(r)?.as_bytes())?;
    let mut md = markdown(r);
    // The evaluators' errors against ground truth, beside the stage times.
    for f in evaluation_files(dir, "md") {
        if let Ok(e) = std::fs::read_to_string(&f) {
            md.push('\n');
            md.push_str(&e);
        }
    }
    crate::nodeutil::write_atomic(&dir.join("report.md"), md.as_bytes())?;
    Ok(())
}

/// The evaluators' files with extension `ext` in `dir`: `evaluation.<ext>` first, then
/// `evaluation-<label>.<ext>` by label.
pub fn evaluation_files(dir: &Path, ext: &str) -> Vec<std::path::PathBuf> {
    let mut v: Vec<std::path::PathBuf> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| {
                    let name = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
                    let Some(stem) = name.strip_suffix(&format!(".{ext}")) else { return false };
                    stem == "evaluation" || stem.starts_with("evaluation-")
                })
                .collect()
        })
        .unwrap_or_default();
    v.sort_by_key(|p| (p.file_stem().map(|s| s != "evaluation"), p.clone()));
    v
}

/// Human-readable report.
pub fn markdown(r: &RunReport) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# sonoflow run `{}` — {}\n", r.graph, r.status);
    let _ = writeln!(s, "- run id: `{}`", r.run_id);
    let _ = writeln!(s, "- output: `{}`", r.out_dir);
    let _ = writeln!(s, "- wall time: {:.2} s", r.wall_s);
    let _ = writeln!(s, "- shared memory reserved: {:.1} MB", r.shm_bytes as f64 / 1e6);
    for rec in &r.recordings {
        let _ = writeln!(s, "- recording: `{rec}`");
    }
    if !r.failures.is_empty() {
        let _ = writeln!(s, "\n## Failures\n");
        for f in &r.failures {
            let _ = writeln!(s, "- {f}");
        }
    }
    if !r.warnings.is_empty() {
        let _ = writeln!(s, "\n## Warnings\n");
        for w in &r.warnings {
            let _ = writeln!(s, "- {w}");
        }
    }
    let _ = writeln!(s, "\n## Stages\n");
    let _ = writeln!(
        s,
        "| node | program | exit | messages in | messages out | MB out | compute CPU (s) | ms / message | process CPU (s) | wall (s) |"
    );
    let _ = writeln!(s, "|---|---|---|---:|---:|---:|---:|---:|---:|---:|");
    for n in &r.nodes {
        match &n.stats {
            Some(st) => {
                let per = st.messages_in.max(st.messages_out).max(1) as f64;
                let _ = writeln!(
                    s,
                    "| {} | `{}` | {} | {} | {} | {:.1} | {:.3} | {:.3} | {:.3} | {:.2} |",
                    n.name,
                    n.program,
                    n.exit,
                    st.messages_in,
                    st.messages_out,
                    st.bytes_out as f64 / 1e6,
                    st.compute_ns_total as f64 / 1e9,
                    st.compute_ns_total as f64 / 1e6 / per,
                    st.cpu_ns as f64 / 1e9,
                    st.wall_ns as f64 / 1e9
                );
            }
            None => {
                let _ = writeln!(s, "| {} | `{}` | {} | – | – | – | – | – | – | – |", n.name, n.program, n.exit);
            }
        }
    }
    let _ = writeln!(
        s,
        "\nCompute CPU = thread CPU time spent producing messages (the per-message figure is also in every \
         message header, `compute_ns`); process CPU includes start-up and waiting overhead. Logs: `logs/<node>.log`."
    );
    s
}
