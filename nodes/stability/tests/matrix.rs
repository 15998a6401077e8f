//! The quick stability matrix (`sonoflow stability --quick`) through the library: every case's
//! measured outcome is its expected one, and every stage of the pipeline has cases in the table.

use sonoflow_stability::{markdown_table, run_selected, Stage};

#[test]
fn quick_matrix_matches_every_expectation_and_covers_every_stage() {
    let reports = run_selected(true, None, |i, r| {
        eprintln!("[{}] {}/{}: {} ({:.2} s) {}", i + 1, r.stage.name(), r.name, r.outcome.word(), r.seconds, r.detail)
    })
    .expect("the matrix runs");
    let table = markdown_table(&reports);
    println!("{table}");
    let bad: Vec<String> = reports
        .iter()
        .filter(|r| !r.matches)
        .map(|r| {
            format!("{}/{}: expected {}, got {}: {}", r.stage.name(), r.name, r.expected, r.outcome.word(), r.detail)
        })
        .collect();
    assert!(bad.is_empty(), "cases not as expected:\n{}", bad.join("\n"));
    for s in Stage::ALL {
        assert!(table.contains(&format!("\n| {} | ", s.name())), "the table lists no {} case:\n{table}", s.name());
    }
    assert!(reports.len() >= 20, "{} cases", reports.len());
}

#[test]
fn only_selects_by_substring_and_an_unknown_one_is_an_error() {
    let r = run_selected(true, Some("launch/good-file"), |_, _| {}).expect("runs");
    assert_eq!(r.len(), 1);
    assert!(r[0].matches, "{:?}", r[0]);
    let e = run_selected(true, Some("no-such-case"), |_, _| {}).expect_err("no case");
    assert!(e.to_string().contains("no case matches"), "{e}");
}
