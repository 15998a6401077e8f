//! `sonoflow stability`: the stability matrix. Runs the named stiff and extreme cases of every
//! stage (SPH, SIMUS, beamforming, Doppler, smoothn, analytic flow, MCAP recording, launch files,
//! platelets)
//! through the library crates — no processes, no IPC — and prints one table of
//! case → outcome, so "numerical stability on stiff and extreme cases" is one visible artefact.
//!
//! Each [`Case`] states what it stresses and its **expected** outcome:
//! * [`Expected::Pass`]: it runs and a stated physical or numerical check holds;
//! * [`Expected::ClearError`]: the library returns an error whose message names the problem
//!   (every listed substring must appear).
//!
//! The **measured** [`Outcome`] is `pass`, `clear error` or `FAILURE`: a panic (caught per case),
//! a check that does not hold (including any NaN), or an error that does not name the problem.
//! A case *matches* when the measured outcome is the expected one; `sonoflow stability` exits 0
//! iff every case matches. `--quick` runs shorter versions of the long cases (for CI).
//!
//! The cases are the crates' own stiff and extreme tests (`nodes/*/tests/`): their scenes, runs and
//! error measures come from each crate's `testkit` module (feature `testkit`), which the crate's
//! tests call too; here they are checked against the same bounds. Added are extremes a demanding
//! user would try (a scatterer on the probe face or 30 cm deep, f-number 0.01 and 1000, Doppler
//! at exactly the Nyquist velocity, 90 % missing data, a single SPH particle, an empty SPH
//! domain, …).

mod cases_beamform;
mod cases_io;
mod cases_platelet;
mod cases_simus;
mod cases_smoothn;
mod cases_sph;

use serde::Serialize;
use std::fmt::Write as _;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The pipeline stage a case belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Stage {
    /// Weakly compressible SPH (`sonoflow-sph`).
    Sph,
    /// SIMUS RF synthesis (`sonoflow-simus`).
    Simus,
    /// RF → I/Q and delay-and-sum (`sonoflow-beamform`).
    Beamform,
    /// Colour / vector Doppler and clutter filter (`sonoflow-beamform`).
    Doppler,
    /// Robust DCT smoothing (`sonoflow-regularise`).
    Smoothn,
    /// Analytic flow phantoms (`sonoflow-analytic-flow`).
    AnalyticFlow,
    /// MCAP recordings (`sonoflow-mcap-io`).
    Mcap,
    /// Launch-file checks (`sonoflow::launch`).
    Launch,
    /// Platelet suspension: Stokes solver, networks, dynamics (`sonoflow-platelet`).
    Platelet,
}

impl Stage {
    /// Every stage, in pipeline order.
    pub const ALL: [Stage; 9] = [
        Stage::Sph,
        Stage::Simus,
        Stage::Beamform,
        Stage::Doppler,
        Stage::Smoothn,
        Stage::AnalyticFlow,
        Stage::Mcap,
        Stage::Launch,
        Stage::Platelet,
    ];

    /// A case of this stage.
    pub const fn case(
        self,
        name: &'static str,
        stresses: &'static str,
        expected: Expected,
        run: fn(&Ctx) -> CaseResult,
    ) -> Case {
        Case { stage: self, name, stresses, expected, run }
    }

    /// The name printed in the table.
    pub fn name(self) -> &'static str {
        match self {
            Stage::Sph => "sph",
            Stage::Simus => "simus",
            Stage::Beamform => "beamform",
            Stage::Doppler => "doppler",
            Stage::Smoothn => "smoothn",
            Stage::AnalyticFlow => "analytic-flow",
            Stage::Mcap => "mcap",
            Stage::Launch => "launch",
            Stage::Platelet => "platelet",
        }
    }
}

/// What a case is expected to do.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Expected {
    /// Runs, and the case's check holds.
    Pass,
    /// Returns an error whose message contains every one of these substrings.
    ClearError(&'static [&'static str]),
}

impl Expected {
    /// `pass` or `clear error ("…", "…")`.
    pub fn describe(&self) -> String {
        match self {
            Expected::Pass => "pass".into(),
            Expected::ClearError(needles) => {
                let n: Vec<String> = needles.iter().map(|s| format!("'{s}'")).collect();
                format!("clear error {}", n.join(" + "))
            }
        }
    }
}

/// What a case did.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Outcome {
    /// Ran and its check held.
    Pass,
    /// Returned an error naming the problem.
    ClearError,
    /// Panicked, a check failed (e.g. a NaN, a bound exceeded), or an error did not name the
    /// problem.
    Failure,
}

impl Outcome {
    /// The word printed in the table.
    pub fn word(self) -> &'static str {
        match self {
            Outcome::Pass => "pass",
            Outcome::ClearError => "clear error",
            Outcome::Failure => "FAILURE",
        }
    }
}

/// The result of a check that ran: whether it held, and a one-line measurement.
#[derive(Clone, Debug, PartialEq)]
pub struct Check {
    /// The stated check holds.
    pub ok: bool,
    /// One line: what was measured (e.g. "profile 1.7 % from Poiseuille").
    pub detail: String,
}

impl Check {
    /// A check that holds iff `ok`.
    pub fn new(ok: bool, detail: impl Into<String>) -> Self {
        Self { ok, detail: detail.into() }
    }
}

/// What a case function returns: `Ok` when it ran (the check may or may not hold), `Err` with
/// the library's error message when the library refused.
pub type CaseResult = Result<Check, String>;

/// Converts any displayable library error into the message a case reports.
pub(crate) trait OrMessage<T> {
    /// `map_err(|e| e.to_string())`.
    fn msg(self) -> Result<T, String>;
}

impl<T, E: std::fmt::Display> OrMessage<T> for Result<T, E> {
    fn msg(self) -> Result<T, String> {
        self.map_err(|e| e.to_string())
    }
}

/// Settings shared by the cases.
#[derive(Clone, Debug)]
pub struct Ctx {
    /// Short versions of the long cases.
    pub quick: bool,
    /// A folder for files the cases write (MCAP recordings); it exists.
    pub scratch: PathBuf,
}

/// One named case of the matrix.
#[derive(Clone, Copy)]
pub struct Case {
    /// Stage.
    pub stage: Stage,
    /// Short name, unique within the stage.
    pub name: &'static str,
    /// What it stresses, in words.
    pub stresses: &'static str,
    /// The expected outcome.
    pub expected: Expected,
    /// The case itself.
    pub run: fn(&Ctx) -> CaseResult,
}

impl Case {
    /// `stage/name`, what `--only` matches.
    pub fn id(&self) -> String {
        format!("{}/{}", self.stage.name(), self.name)
    }
}

/// One row of the matrix.
#[derive(Clone, Debug, Serialize)]
pub struct CaseReport {
    /// Stage.
    pub stage: Stage,
    /// Case name.
    pub name: String,
    /// What it stresses.
    pub stresses: String,
    /// Expected outcome, in words.
    pub expected: String,
    /// Measured outcome.
    pub outcome: Outcome,
    /// Measured outcome is the expected one.
    pub matches: bool,
    /// One line: the measurement or the error message.
    pub detail: String,
    /// Wall time of the case (s).
    pub seconds: f64,
}

/// Every case of the matrix, in stage order.
pub fn cases() -> Vec<Case> {
    let mut v = Vec::new();
    v.extend(cases_sph::cases());
    v.extend(cases_simus::cases());
    v.extend(cases_beamform::cases());
    v.extend(cases_smoothn::cases());
    v.extend(cases_io::cases());
    v.extend(cases_platelet::cases());
    v.sort_by_key(|c| c.stage);
    v
}

fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

fn panic_message(p: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = p.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = p.downcast_ref::<String>() {
        s.clone()
    } else {
        "(non-string panic payload)".into()
    }
}

/// Classifies what a case did against what it should do: (outcome, matches, detail).
pub fn classify(expected: &Expected, result: std::thread::Result<CaseResult>) -> (Outcome, bool, String) {
    let (outcome, detail) = match result {
        Err(p) => (Outcome::Failure, format!("panic: {}", panic_message(p.as_ref()))),
        Ok(Ok(c)) if c.ok => (Outcome::Pass, c.detail),
        Ok(Ok(c)) => (Outcome::Failure, format!("check failed: {}", c.detail)),
        Ok(Err(msg)) => match expected {
            Expected::ClearError(needles) => {
                let missing: Vec<&str> = needles.iter().copied().filter(|n| !msg.contains(n)).collect();
                if missing.is_empty() {
                    (Outcome::ClearError, format!("error: {msg}"))
                } else {
                    (Outcome::Failure, format!("error does not name {missing:?}: {msg}"))
                }
            }
            Expected::Pass => (Outcome::ClearError, format!("unexpected error: {msg}")),
        },
    };
    let matches =
        matches!((expected, outcome), (Expected::Pass, Outcome::Pass) | (Expected::ClearError(_), Outcome::ClearError));
    let detail = if outcome == Outcome::Pass && matches!(expected, Expected::ClearError(_)) {
        format!("no error: {detail}")
    } else {
        detail
    };
    (outcome, matches, one_line(&detail))
}

/// Runs one case, catching panics.
pub fn run_case(case: &Case, ctx: &Ctx) -> CaseReport {
    let t0 = Instant::now();
    let result = catch_unwind(AssertUnwindSafe(|| (case.run)(ctx)));
    let seconds = t0.elapsed().as_secs_f64();
    let (outcome, matches, detail) = classify(&case.expected, result);
    CaseReport {
        stage: case.stage,
        name: case.name.to_string(),
        stresses: case.stresses.to_string(),
        expected: case.expected.describe(),
        outcome,
        matches,
        detail,
        seconds,
    }
}

/// Runs `cases` in order; `progress` is called after each.
pub fn run_matrix(cases: &[Case], ctx: &Ctx, mut progress: impl FnMut(usize, &CaseReport)) -> Vec<CaseReport> {
    cases
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let r = run_case(c, ctx);
            progress(i, &r);
            r
        })
        .collect()
}

fn cell(s: &str, max: usize) -> String {
    let s = s.replace('|', "\\|");
    if s.chars().count() > max {
        let cut: String = s.chars().take(max - 1).collect();
        format!("{cut}…")
    } else {
        s
    }
}

/// The Markdown table: stage | case | expected | outcome | detail | time s, and a summary line.
pub fn markdown_table(reports: &[CaseReport]) -> String {
    let mut t = String::new();
    t.push_str("| stage | case | expected | outcome | detail | time s |\n");
    t.push_str("|---|---|---|---|---|---:|\n");
    for r in reports {
        let outcome = if r.matches { r.outcome.word().to_string() } else { format!("**{}** ✗", r.outcome.word()) };
        let _ = writeln!(
            t,
            "| {} | {} | {} | {} | {} | {:.2} |",
            r.stage.name(),
            r.name,
            cell(&r.expected, 100),
            outcome,
            cell(&r.detail, 220),
            r.seconds
        );
    }
    let bad = reports.iter().filter(|r| !r.matches).count();
    let total: f64 = reports.iter().map(|r| r.seconds).sum();
    let _ = writeln!(
        t,
        "\n{} case(s), {} as expected, {} not as expected; {:.1} s in all.",
        reports.len(),
        reports.len() - bad,
        bad,
        total
    );
    t
}

/// What each case stresses (the second section of `stability.md`).
pub fn markdown_cases(reports: &[CaseReport]) -> String {
    let mut t = String::from("| stage | case | what it stresses |\n|---|---|---|\n");
    for r in reports {
        let _ = writeln!(t, "| {} | {} | {} |", r.stage.name(), r.name, cell(&r.stresses, 400));
    }
    t
}

/// The matrix as JSON.
#[derive(Serialize)]
struct MatrixJson<'a> {
    quick: bool,
    all_as_expected: bool,
    cases: &'a [CaseReport],
}

/// Arguments of `sonoflow stability`.
#[derive(clap::Args, Debug)]
pub struct StabilityArgs {
    /// Short versions of the long cases (CI: well under a minute in release).
    #[arg(long)]
    pub quick: bool,
    /// Write stability.md and stability.json into this folder (created if missing).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Run only the cases whose `stage/name` contains this substring.
    #[arg(long)]
    pub only: Option<String>,
}

/// A scratch folder that is removed when dropped.
struct Scratch(PathBuf);

impl Scratch {
    fn new(parent: &Path) -> anyhow::Result<Self> {
        let nanos =
            std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_nanos()).unwrap_or(0);
        let p = parent.join(format!("sonoflow-stability-{}-{nanos}", std::process::id()));
        std::fs::create_dir_all(&p).map_err(|e| anyhow::anyhow!("creating scratch folder {}: {e}", p.display()))?;
        Ok(Self(p))
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Runs the matrix with a fresh scratch folder (removed afterwards): the library entry point.
pub fn run_selected(
    quick: bool,
    only: Option<&str>,
    progress: impl FnMut(usize, &CaseReport),
) -> anyhow::Result<Vec<CaseReport>> {
    let selected: Vec<Case> = cases().into_iter().filter(|c| only.is_none_or(|s| c.id().contains(s))).collect();
    if selected.is_empty() {
        anyhow::bail!("--only {only:?}: no case matches (cases are named stage/name, e.g. sph/hydrostatic-tank)");
    }
    let scratch = Scratch::new(&std::env::temp_dir())?;
    let ctx = Ctx { quick, scratch: scratch.0.clone() };
    Ok(run_matrix(&selected, &ctx, progress))
}

/// `sonoflow stability`: prints the table; exit code 0 iff every case is as expected.
pub fn run(args: &StabilityArgs) -> anyhow::Result<i32> {
    let n = cases().into_iter().filter(|c| args.only.as_deref().is_none_or(|s| c.id().contains(s))).count();
    let reports = run_selected(args.quick, args.only.as_deref(), |i, r| {
        eprintln!(
            "[{}/{n}] {}/{}: {}{} ({:.2} s)",
            i + 1,
            r.stage.name(),
            r.name,
            r.outcome.word(),
            if r.matches { "" } else { " — NOT AS EXPECTED" },
            r.seconds
        );
    })?;
    let table = markdown_table(&reports);
    println!("{table}");
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir).map_err(|e| anyhow::anyhow!("creating {}: {e}", dir.display()))?;
        let md = format!(
            "# Stability matrix ({} mode)\n\nGenerated by `sonoflow stability{}`. Expected: `pass` = runs and the stated \
             check holds; `clear error` = the library returns an error naming the problem (the quoted substrings). \
             A row marked ✗ is not as expected.\n\n{table}\n## Cases\n\n{}",
            if args.quick { "quick" } else { "full" },
            if args.quick { " --quick" } else { "" },
            markdown_cases(&reports)
        );
        let p = dir.join("stability.md");
        std::fs::write(&p, md).map_err(|e| anyhow::anyhow!("writing {}: {e}", p.display()))?;
        let all = reports.iter().all(|r| r.matches);
        let json =
            serde_json::to_string_pretty(&MatrixJson { quick: args.quick, all_as_expected: all, cases: &reports })?;
        let p = dir.join("stability.json");
        std::fs::write(&p, json).map_err(|e| anyhow::anyhow!("writing {}: {e}", p.display()))?;
        eprintln!("wrote {} and stability.json", dir.join("stability.md").display());
    }
    Ok(if reports.iter().all(|r| r.matches) { 0 } else { 1 })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ok(_: &Ctx) -> CaseResult {
        Ok(Check::new(true, "fine"))
    }
    fn failed_check(_: &Ctx) -> CaseResult {
        Ok(Check::new(false, "1.5 > 1"))
    }
    fn named_error(_: &Ctx) -> CaseResult {
        Err("invalid parameter `cfl` = 1.5".into())
    }
    fn panics(_: &Ctx) -> CaseResult {
        panic!("boom")
    }

    fn report(expected: Expected, run: fn(&Ctx) -> CaseResult) -> CaseReport {
        let case = Stage::Sph.case("t", "test", expected, run);
        run_case(&case, &Ctx { quick: true, scratch: std::env::temp_dir() })
    }

    #[test]
    fn a_wrong_expectation_is_reported_as_a_mismatch() {
        // A case that passes but was expected to fail with an error is not as expected.
        let r = report(Expected::ClearError(&["cfl"]), ok);
        assert_eq!((r.outcome, r.matches), (Outcome::Pass, false));
        assert!(r.detail.starts_with("no error"), "{}", r.detail);
        // An error where a pass was expected.
        let r = report(Expected::Pass, named_error);
        assert_eq!((r.outcome, r.matches), (Outcome::ClearError, false));
        // An error that does not name the expected problem is a failure.
        let r = report(Expected::ClearError(&["dt_max"]), named_error);
        assert_eq!((r.outcome, r.matches), (Outcome::Failure, false));
        assert!(r.detail.contains("dt_max"), "{}", r.detail);
        // A check that does not hold, and a panic, are failures whatever was expected.
        for e in [Expected::Pass, Expected::ClearError(&["x"])] {
            let r = report(e, failed_check);
            assert_eq!((r.outcome, r.matches), (Outcome::Failure, false));
            let r = report(e, panics);
            assert_eq!((r.outcome, r.matches), (Outcome::Failure, false));
            assert!(r.detail.contains("panic: boom"), "{}", r.detail);
        }
        // And the right expectations match.
        assert!(report(Expected::Pass, ok).matches);
        assert!(report(Expected::ClearError(&["`cfl`", "1.5"]), named_error).matches);
        let table = markdown_table(&[report(Expected::Pass, failed_check)]);
        assert!(table.contains("**FAILURE** ✗") && table.contains("1 not as expected"), "{table}");
    }

    #[test]
    fn case_names_are_unique_and_every_stage_has_cases() {
        let all = cases();
        let mut ids: Vec<String> = all.iter().map(Case::id).collect();
        ids.sort();
        let n = ids.len();
        ids.dedup();
        assert_eq!(ids.len(), n, "duplicate case names");
        for s in Stage::ALL {
            assert!(all.iter().any(|c| c.stage == s), "no case for {}", s.name());
        }
    }
}
