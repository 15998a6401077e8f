//! The run report: `report.json` (machine-readable) and `report.md` (human), written at the end
//! of every run; with an `evaluator` node in the graph, report.md also holds the errors against
//! ground truth (`evaluation.md`, the evaluator's table; `evaluation.json` beside it; with several
//! labelled evaluators, each one's `evaluation-<label>.md`). Figures (`figures/*.png`): the stage
//! times always, drawn here; the evaluators' (colour Doppler, vectors, error histograms) listed
//! in their `evaluation*.json`. report.md shows each with a caption.

use sonoflow_evaluate::figures;
use sonoflow_node_kit::NodeStats;
use std::fmt::Write as _;
use std::path::Path;

/// Outcome of one node.
#[derive(Clone, Debug, serde::Serialize)]
pub struct NodeOutcome {
    pub name: String,
    pub program: String,
    pub exit: String,
    pub ok: bool,
    pub stats: Option<NodeStats>,
    pub log: String,
}

/// Machine-readable run report (`report.json`).
#[derive(Clone, Debug, serde::Serialize)]
pub struct RunReport {
    pub graph: String,
    pub run_id: String,
    pub out_dir: String,
    pub status: String,
    pub wall_s: f64,
    pub failures: Vec<String>,
    pub warnings: Vec<String>,
    pub recordings: Vec<String>,
    pub shm_bytes: u64,
    pub nodes: Vec<NodeOutcome>,
    /// PNG figures in `figures/` (paths relative to the run folder): the stage times, and the
    /// evaluator's when the graph has one. A figure that could not be drawn is a warning.
    pub figures: Vec<sonoflow_evaluate::figures::Figure>,
    /// The stage with the most busy time (wall − waiting for input − held by back-pressure):
    /// the one the others wait on.
    pub critical_path: Option<String>,
}

/// The stage-time chart's rows: every node, compute CPU and wall time in seconds.
pub fn stage_rows(r: &RunReport) -> Vec<figures::StageRow> {
    r.nodes
        .iter()
        .map(|n| figures::StageRow {
            name: n.name.clone(),
            compute_s: n.stats.as_ref().map(|s| s.compute_ns_total as f64 / 1e9),
            wall_s: n.stats.as_ref().map(|s| s.wall_ns as f64 / 1e9),
        })
        .collect()
}

/// Draws the stage-time chart into `dir/figures/` and collects the evaluators' figures from
/// `dir/evaluation*.json` into `r.figures`; every problem becomes a warning of the report.
pub fn add_figures(dir: &Path, r: &mut RunReport) {
    let heading = format!("Stage times — {} ({}, {:.2} s)", r.graph, r.status, r.wall_s);
    let rows = stage_rows(r);
    match figures::guarded("stage times", || figures::stage_times(dir, &heading, &rows)) {
        Ok(f) => r.figures.push(f),
        Err(w) => r.warnings.push(w),
    }
    for path in evaluation_files(dir, "json") {
        let Ok(text) = std::fs::read_to_string(&path) else { continue };
        match serde_json::from_str::<sonoflow_evaluate::evaluation::Evaluation>(&text) {
            Ok(e) => {
                r.figures.extend(e.figures.into_iter().filter(|f| dir.join(&f.path).is_file()));
                r.warnings.extend(e.warnings);
            }
            Err(e) => r.warnings.push(format!("{}: {e}: its figures are not listed", path.display())),
        }
    }
    // Figures other nodes drew, listed in `figures-<node>.json` (a JSON array of figures).
    for path in node_figure_lists(dir) {
        let Ok(text) = std::fs::read_to_string(&path) else { continue };
        match serde_json::from_str::<Vec<figures::Figure>>(&text) {
            Ok(f) => r.figures.extend(f.into_iter().filter(|f| dir.join(&f.path).is_file())),
            Err(e) => r.warnings.push(format!("{}: {e}: its figures are not listed", path.display())),
        }
    }
}

/// `dir/figures-*.json`, sorted by name.
fn node_figure_lists(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut v: Vec<std::path::PathBuf> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| {
                    let name = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
                    name.starts_with("figures-") && name.ends_with(".json")
                })
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

/// Writes `report.json` and `report.md` into `dir` (atomically).
pub fn write(dir: &Path, r: &RunReport) -> anyhow::Result<()> {
    sonoflow_fileio::write_atomic(&dir.join("report.json"), serde_json::to_string_pretty(r)?.as_bytes())?;
    let mut md = markdown(r);
    // The evaluators' errors against ground truth, beside the stage times.
    for f in evaluation_files(dir, "md") {
        if let Ok(e) = std::fs::read_to_string(&f) {
            md.push('\n');
            md.push_str(&e);
        }
    }
    md.push_str(&figures_markdown(&r.figures));
    sonoflow_fileio::write_atomic(&dir.join("report.md"), md.as_bytes())?;
    Ok(())
}

/// The figures section of report.md: each figure linked, with its caption.
pub fn figures_markdown(figs: &[figures::Figure]) -> String {
    let mut s = String::new();
    if figs.is_empty() {
        return s;
    }
    let _ = writeln!(s, "\n## Figures\n");
    for f in figs {
        let _ = writeln!(s, "![{}]({})\n", f.title, f.path);
        let _ = writeln!(s, "*{}* {}\n", f.title, f.caption);
    }
    s
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
        "| node | program | exit | messages in | messages out | MB out | compute CPU (s) | ms / message | process CPU (s) | wall (s) | waiting for input (s) | held by back-pressure (s) | busy |"
    );
    let _ = writeln!(s, "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for n in &r.nodes {
        match &n.stats {
            Some(st) => {
                let per = st.messages_in.max(st.messages_out).max(1) as f64;
                let _ = writeln!(
                    s,
                    "| {} | `{}` | {} | {} | {} | {:.1} | {:.3} | {:.3} | {:.3} | {:.2} | {:.2} | {:.2} | {:.0} % |",
                    n.name,
                    n.program,
                    n.exit,
                    st.messages_in,
                    st.messages_out,
                    st.bytes_out as f64 / 1e6,
                    st.compute_ns_total as f64 / 1e9,
                    st.compute_ns_total as f64 / 1e6 / per,
                    st.cpu_ns as f64 / 1e9,
                    st.wall_ns as f64 / 1e9,
                    st.wait_input_ns as f64 / 1e9,
                    st.wait_output_ns as f64 / 1e9,
                    100.0 * busy_fraction(st)
                );
            }
            None => {
                let _ = writeln!(
                    s,
                    "| {} | `{}` | {} | – | – | – | – | – | – | – | – | – | – |",
                    n.name, n.program, n.exit
                );
            }
        }
    }
    let _ = writeln!(
        s,
        "\nCompute CPU = thread CPU time spent producing messages (the per-message figure is also in every \
         message header, `compute_ns`); process CPU includes start-up and waiting overhead. Waiting for input = \
         wall time blocked until an upstream message arrived; held by back-pressure = wall time a send waited for \
         a full downstream queue; busy = the rest of the stage's wall time (work, start-up, pacing). Logs: \
         `logs/<node>.log`."
    );
    if let Some(c) = critical_stage(r) {
        let st = c.stats.as_ref().map(|st| (busy_fraction(st), st.wall_ns as f64 / 1e9)).unwrap_or((0.0, 0.0));
        let _ = writeln!(
            s,
            "\n**Critical path:** `{}` — busy {:.0} % of its {:.1} s (the stage with the most busy time; the stages \
             after it wait for its messages, those before it are held back by it).",
            c.name,
            100.0 * st.0,
            st.1
        );
    }
    s
}

/// Share of a stage's wall time it was neither waiting for input nor held by back-pressure.
pub fn busy_fraction(st: &NodeStats) -> f64 {
    if st.wall_ns == 0 {
        return 0.0;
    }
    let waits = st.wait_input_ns.saturating_add(st.wait_output_ns).min(st.wall_ns);
    (st.wall_ns - waits) as f64 / st.wall_ns as f64
}

/// The stage with the most busy time (wall − waiting for input − back-pressure): the one the
/// others wait on.
pub fn critical_stage(r: &RunReport) -> Option<&NodeOutcome> {
    r.nodes
        .iter()
        .filter_map(|n| n.stats.as_ref().map(|st| (n, st.wall_ns.saturating_sub(st.wait_input_ns + st.wait_output_ns))))
        .max_by_key(|(_, busy)| *busy)
        .map(|(n, _)| n)
}
