#![allow(clippy::unwrap_used)]
//! The batch tools as a user runs them: real files in, real files out, compared with the
//! libraries called directly.

mod common;
use common::bin;
use sonoflow_fileio::npy;
use sonoflow_regularise::testkit::rms_diff;
use std::path::{Path, PathBuf};
use std::process::Command;

fn smoothn_cli(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(bin()).arg("smoothn").args(args).output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A smooth 2-component field on a 30 × 40 grid with noise, 10 % gross outliers and NaNs.
fn noisy_field() -> (Vec<f64>, Vec<f64>) {
    let (ny, nx) = (30, 40);
    let mut clean = vec![0.0; 2 * ny * nx];
    let mut noisy = clean.clone();
    let mut state = 12345u64;
    let mut uniform = || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    for c in 0..2 {
        for y in 0..ny {
            for x in 0..nx {
                let i = c * ny * nx + y * nx + x;
                let (fy, fx) = (y as f64 / ny as f64, x as f64 / nx as f64);
                clean[i] = if c == 0 { (3.0 * fx).sin() * fy } else { (2.0 * fy).cos() + fx };
                noisy[i] = clean[i] + 0.05 * (uniform() - 0.5) * 3.46;
                if uniform() < 0.1 {
                    noisy[i] = 4.0 * (uniform() - 0.5);
                }
                if uniform() < 0.03 {
                    noisy[i] = f64::NAN;
                }
            }
        }
    }
    (clean, noisy)
}

/// [`noisy_field`] written as a (2, 30, 40) f64 array to `dir/field.npy`: (clean, noisy, the path).
fn noisy_field_file(dir: &Path) -> (Vec<f64>, Vec<f64>, PathBuf) {
    let (clean, noisy) = noisy_field();
    let inp = dir.join("field.npy");
    npy::write_f64(&inp, &[2, 30, 40], &noisy).unwrap();
    (clean, noisy, inp)
}

#[test]
fn smoothn_tool_matches_the_library_and_writes_a_sidecar() {
    let dir = tempfile::tempdir().unwrap();
    let (clean, noisy, inp) = noisy_field_file(dir.path());
    let out = dir.path().join("smooth.npy");
    let (code, stdout, stderr) =
        smoothn_cli(&["--in", inp.to_str().unwrap(), "--robust", "--out", out.to_str().unwrap()]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("2 component(s)"), "{stdout}");
    let got = npy::read(&out).unwrap();
    assert_eq!(got.shape, vec![2, 30, 40]);
    let params = sonoflow_regularise::SmoothnParams { robust: true, ..Default::default() };
    let (expect, report) = sonoflow_regularise::smoothn(&noisy, &[30, 40], 2, None, &params).unwrap();
    assert!(got.data == expect, "tool output differs from the library");
    let side: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(sonoflow_tools::smoothn::sidecar(&out)).unwrap()).unwrap();
    assert_eq!(side["s"].as_f64().unwrap(), report.s);
    assert_eq!(side["converged"].as_bool().unwrap(), report.converged);
    assert_eq!(side["missing_values"].as_u64().unwrap() as usize, noisy.iter().filter(|v| v.is_nan()).count());
    // Robust smoothing recovers the clean field far better than the data are (outliers of ±2).
    let finite: Vec<usize> = (0..noisy.len()).filter(|&i| noisy[i].is_finite()).collect();
    let e_data = rms_diff(
        &finite.iter().map(|&i| noisy[i]).collect::<Vec<_>>(),
        &finite.iter().map(|&i| clean[i]).collect::<Vec<_>>(),
    );
    let e_out = rms_diff(&got.data, &clean);
    assert!(e_out < 0.1 * e_data, "data {e_data}, smoothed {e_out}");
}

#[test]
fn smoothn_tool_fixed_s_scalar_field_with_weights() {
    let dir = tempfile::tempdir().unwrap();
    let (_, noisy) = noisy_field();
    let scalar: Vec<f64> = noisy[..1200].iter().map(|v| if v.is_finite() { *v } else { 0.0 }).collect();
    let w: Vec<f64> = (0..1200).map(|i| if i % 11 == 0 { 0.0 } else { 1.0 + (i % 3) as f64 }).collect();
    let (inp, wp, out) = (dir.path().join("f.npy"), dir.path().join("w.npy"), dir.path().join("o.npy"));
    npy::write_f32(&inp, &[30, 40], false, &scalar.iter().map(|&v| v as f32).collect::<Vec<_>>()).unwrap();
    npy::write_f64(&wp, &[30, 40], &w).unwrap();
    let args = ["--in", inp.to_str().unwrap(), "--s", "3.5", "--order", "1", "--weights", wp.to_str().unwrap()];
    let (code, _, stderr) = smoothn_cli(&[&args[..], &["--out", out.to_str().unwrap()]].concat());
    assert_eq!(code, 0, "{stderr}");
    let got = npy::read(&out).unwrap();
    assert_eq!(got.shape, vec![30, 40]);
    let input: Vec<f64> = scalar.iter().map(|&v| v as f32 as f64).collect();
    let params = sonoflow_regularise::SmoothnParams { s: Some(3.5), order: 1, ..Default::default() };
    let (expect, report) = sonoflow_regularise::smoothn(&input, &[30, 40], 1, Some(&w), &params).unwrap();
    assert!(got.data == expect);
    assert_eq!(report.s, 3.5);
}

/// `--divergence-free`: the tool writes exactly the library's stream-function fit, which is
/// divergence-free to round-off; a field that is not (2, nz, nx) is refused.
#[test]
fn smoothn_tool_divergence_free_matches_the_library() {
    let dir = tempfile::tempdir().unwrap();
    let (_, noisy, inp) = noisy_field_file(dir.path());
    let out = dir.path().join("df.npy");
    let args = ["--in", inp.to_str().unwrap(), "--divergence-free", "--order", "3", "--robust"];
    let (code, stdout, stderr) =
        smoothn_cli(&[&args[..], &["--spacing", "2e-4,2e-4", "--out", out.to_str().unwrap()]].concat());
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("divergence-free fit on [30, 40]") && stdout.contains("block CV"), "{stdout}");
    let got = npy::read(&out).unwrap();
    assert_eq!(got.shape, vec![2, 30, 40]);
    let f = sonoflow_regularise::DivFree::new([30, 40], [2e-4, 2e-4], 3).unwrap();
    let (mut vx, mut vz) = (vec![0.0; 1200], vec![0.0; 1200]);
    let p = sonoflow_regularise::DivFreeParams::default();
    let report = f.fit(&noisy[..1200], &noisy[1200..], None, &p, &mut vx, &mut vz).unwrap();
    assert!(got.data[..1200] == vx[..] && got.data[1200..] == vz[..], "tool output differs from the library");
    assert!(report.max_divergence < 1e-12);
    let side: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(sonoflow_tools::smoothn::sidecar(&out)).unwrap()).unwrap();
    assert_eq!(side["report"]["s"].as_f64().unwrap(), report.s);
    let bad = dir.path().join("bad.npy");
    npy::write_f64(&bad, &[3, 10, 40], &noisy[..1200]).unwrap();
    let (code, _, stderr) =
        smoothn_cli(&["--in", bad.to_str().unwrap(), "--divergence-free", "--out", out.to_str().unwrap()]);
    assert_ne!(code, 0);
    assert!(stderr.contains("(2, nz, nx)"), "{stderr}");
}

/// `--divergence-free --no-slip --power`: exactly the library's wall and walled fit (as the
/// regulariser node's `no_slip`); `--no-slip` without `--power`, or outside `--divergence-free`,
/// is a clear error.
#[test]
fn smoothn_tool_no_slip_matches_the_library() {
    let dir = tempfile::tempdir().unwrap();
    let (_, noisy, inp) = noisy_field_file(dir.path());
    // power: a bright band over rows 8 ..= 21 (the "lumen"), 20 dB down elsewhere
    let power: Vec<f64> = (0..1200).map(|i| if (8..=21).contains(&(i / 40)) { 1.0 } else { 0.01 }).collect();
    let (pw, out) = (dir.path().join("power.npy"), dir.path().join("ns.npy"));
    npy::write_f64(&pw, &[30, 40], &power).unwrap();
    let args = ["--in", inp.to_str().unwrap(), "--divergence-free", "--order", "3", "--robust", "--no-slip"];
    let (code, _, stderr) = smoothn_cli(
        &[&args[..], &["--power", pw.to_str().unwrap(), "--spacing", "2e-4,2e-4", "--out", out.to_str().unwrap()]]
            .concat(),
    );
    assert_eq!(code, 0, "{stderr}");
    let got = npy::read(&out).unwrap();
    let ns = sonoflow_regularise::NoSlipParams::default();
    let blood: Vec<bool> = (0..1200).map(|i| noisy[i].is_finite() && noisy[1200 + i].is_finite()).collect();
    let wall = sonoflow_regularise::wall_from_power(&power, &blood, [30, 40], [2e-4, 2e-4], &ns).unwrap();
    let n_wall = wall.iter().filter(|w| **w).count();
    assert!(n_wall > 300 && n_wall < 1200 - 400, "{n_wall} wall pixels");
    let w: Vec<f64> = wall.iter().map(|o| if *o { 0.0 } else { 1.0 }).collect();
    let prior: Vec<f64> = wall.iter().map(|o| if *o { ns.weight } else { 0.0 }).collect();
    let f = sonoflow_regularise::DivFree::new([30, 40], [2e-4, 2e-4], 3).unwrap();
    let (mut vx, mut vz) = (vec![0.0; 1200], vec![0.0; 1200]);
    let p = sonoflow_regularise::DivFreeParams::default();
    f.fit_with_wall(&noisy[..1200], &noisy[1200..], Some(&w), Some(&prior), &p, None, &mut vx, &mut vz).unwrap();
    assert!(got.data[..1200] == vx[..] && got.data[1200..] == vz[..], "tool output differs from the library");
    let side: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(sonoflow_tools::smoothn::sidecar(&out)).unwrap()).unwrap();
    assert_eq!(side["wall_pixels"].as_u64().unwrap() as usize, n_wall);
    let (code, _, stderr) = smoothn_cli(&[&args[..], &["--out", out.to_str().unwrap()]].concat());
    assert_ne!(code, 0);
    assert!(stderr.contains("--no-slip needs --power"), "{stderr}");
    let (code, _, stderr) = smoothn_cli(&["--in", inp.to_str().unwrap(), "--no-slip", "--out", out.to_str().unwrap()]);
    assert_ne!(code, 0);
    assert!(stderr.contains("belong to --divergence-free"), "{stderr}");
}

#[test]
fn smoothn_tool_rejects_bad_input_with_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let inp = dir.path().join("nan.npy");
    let out = dir.path().join("o.npy");
    npy::write_f64(&inp, &[4, 5], &[f64::NAN; 20]).unwrap();
    let (i, o) = (inp.to_str().unwrap(), out.to_str().unwrap());
    let (code, _, err) = smoothn_cli(&["--in", i, "--out", o]);
    assert_eq!(code, 1);
    assert!(err.contains("every value is NaN or infinite"), "{err}");
    assert!(!out.exists(), "no output written on error");

    let good = dir.path().join("good.npy");
    npy::write_f64(&good, &[4, 5], &(0..20).map(|v| v as f64).collect::<Vec<_>>()).unwrap();
    let g = good.to_str().unwrap();
    let (code, _, err) = smoothn_cli(&["--in", g, "--order", "4", "--out", o]);
    assert_eq!(code, 1);
    assert!(err.contains("order") && err.contains("1, 2 or 3"), "{err}");
    let (code, _, err) = smoothn_cli(&["--in", g, "--s", "-1", "--out", o]);
    assert_eq!(code, 1);
    assert!(err.contains("`s`") && err.contains("> 0"), "{err}");
    let (code, _, err) = smoothn_cli(&["--in", g, "--weight-function", "huber", "--out", o]);
    assert_eq!(code, 1);
    assert!(err.contains("bisquare, cauchy, talworth"), "{err}");
    let w = dir.path().join("w.npy");
    npy::write_f64(&w, &[5, 4], &[1.0; 20]).unwrap();
    let (code, _, err) = smoothn_cli(&["--in", g, "--weights", w.to_str().unwrap(), "--out", o]);
    assert_eq!(code, 1);
    assert!(err.contains("expected the grid shape [4, 5]"), "{err}");
    npy::write_f64(&w, &[4, 5], &[-1.0; 20]).unwrap();
    let (code, _, err) = smoothn_cli(&["--in", g, "--weights", w.to_str().unwrap(), "--out", o]);
    assert_eq!(code, 1);
    assert!(err.contains("finite and ≥ 0"), "{err}");
    let (code, _, err) = smoothn_cli(&["--in", dir.path().join("missing.npy").to_str().unwrap(), "--out", o]);
    assert_eq!(code, 1);
    assert!(err.contains("missing.npy"), "{err}");
    assert!(!out.exists());
}

/// `sonoflow sweep` of the quickstart cut to one packet of 8 frames, with `args`, into `out`.
fn quick_sweep(args: &[&str], out: &std::path::Path) -> std::process::Output {
    Command::new(bin())
        .args(["sweep"])
        .arg(common::root().join("launch/quickstart.toml"))
        .args(["--set", "flow.schedule.n_packets=1", "--set", "flow.schedule.packet_size=8"])
        .args(args)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap()
}

/// `sonoflow sweep` runs every combination, and its table holds each run's own evaluation.
#[test]
fn sweep_runs_each_point_and_reports_error_against_time() {
    let dir = tempfile::tempdir().unwrap();
    let out = quick_sweep(&["--vary", "flow.density_per_mm2=2,4"], dir.path());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    let csv = std::fs::read_to_string(dir.path().join("sweep.csv")).unwrap();
    let rows: Vec<&str> = csv.lines().skip(1).collect();
    assert_eq!(rows.len(), 2, "{csv}");
    for (k, row) in rows.iter().enumerate() {
        let cols: Vec<&str> = row.split(',').collect();
        assert!(cols[1].contains(&format!("flow.density_per_mm2={}", [2, 4][k])), "{row}");
        // The error column is the mean over packets of sqrt(rms_x² + rms_z²) from that point's
        // evaluation.json.
        let ev: sonoflow_evaluate::evaluation::Evaluation = serde_json::from_str(
            &std::fs::read_to_string(dir.path().join(format!("point-{k:03}/evaluation.json"))).unwrap(),
        )
        .unwrap();
        let f = &ev.packets[0].fields["regularised"];
        let expect = f.x.rms.hypot(f.z.rms);
        let got: f64 = cols[5].parse().unwrap();
        assert!((got - expect).abs() < 1e-12, "{got} vs {expect}");
        let compute: f64 = cols[3].parse().unwrap();
        assert!(compute > 0.0);
        // and the gains (slope of the estimate against the truth) beside them
        let gx: f64 = cols[8].parse().unwrap();
        assert_eq!(Some(gx), f.gain_x, "{row}");
    }
    assert!(rows.iter().any(|r| r.ends_with(",true")), "at least one Pareto point: {csv}");
    let svg = std::fs::read_to_string(dir.path().join("sweep.svg")).unwrap();
    assert_eq!(svg.matches("<circle").count(), 2);
    // A bad value stops the sweep before anything runs.
    let bad = Command::new(bin())
        .arg("sweep")
        .arg(common::root().join("launch/quickstart.toml"))
        .args(["--vary", "flow.density_per_mm2=2,-1", "--out"])
        .arg(dir.path().join("bad"))
        .output()
        .unwrap();
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("density_per_mm2=-1"));
    assert!(!dir.path().join("bad").exists());
}

/// SIGTERM (or Ctrl-C) stops a sweep: the point that was running ends, the points done are
/// written, no further point starts (before, each later point started and failed at once), and the
/// sweep exits 130.
#[test]
fn an_interrupted_sweep_stops_and_writes_what_it_has() {
    use std::io::{BufRead, BufReader};
    let dir = tempfile::tempdir().unwrap();
    let mut child = Command::new(bin())
        .args(["sweep"])
        .arg(common::root().join("launch/quickstart.toml"))
        .args(["--set", "flow.schedule.n_packets=2", "--seeds", "flow.seed=1,2,3,4", "--out"])
        .arg(dir.path())
        .stderr(std::process::Stdio::piped())
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
    let mut seen = Vec::new();
    for l in lines.by_ref() {
        let l = l.unwrap();
        let started = l.contains("sweep: point 1/4");
        seen.push(l);
        if started {
            break;
        }
    }
    std::thread::sleep(std::time::Duration::from_millis(1500));
    let killed = Command::new("kill").args(["-TERM", &child.id().to_string()]).status().unwrap();
    assert!(killed.success());
    seen.extend(lines.map_while(Result::ok));
    let status = child.wait().unwrap();
    let err = seen.join("\n");
    assert_eq!(status.code(), Some(130), "{err}");
    assert!(err.contains("sweep: interrupted during point"), "{err}");
    assert!(!err.contains("sweep: point 4/4"), "no point starts after the interrupt: {err}");
    // The table lists every point: those that ran, and the rest as not run (which
    // `sweep collect --resume` runs).
    let csv = std::fs::read_to_string(dir.path().join("sweep.csv")).unwrap();
    let rows: Vec<&str> = csv.lines().skip(1).collect();
    assert_eq!(rows.len(), 4, "{csv}");
    let not_run = rows.iter().filter(|r| r.contains(",\"not run\",")).count();
    assert!((1..4).contains(&not_run), "{csv}");
    assert!(err.contains("--resume"), "{err}");
    // `collect --resume` runs what the interrupt left (the interrupted point again, its first
    // attempt kept) and the table is complete.
    let out = Command::new(bin()).args(["sweep", "collect"]).arg(dir.path()).arg("--resume").output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    let csv = std::fs::read_to_string(dir.path().join("sweep.csv")).unwrap();
    assert_eq!(csv.lines().skip(1).filter(|r| r.contains(",\"ok\",")).count(), 4, "{csv}");
    assert!(dir.path().join("point-000").join("exit.json").exists());
}

/// `sonoflow sweep --seeds`: every setting once per realisation, and the table over realisations
/// holds the mean and sample standard deviation of the points' own figures; `--label` reads that
/// evaluator's file (a missing one is reported per point, exit 1).
#[test]
fn sweep_over_seeds_reports_mean_and_spread() {
    let dir = tempfile::tempdir().unwrap();
    let out = quick_sweep(&["--seeds", "flow.seed=1,2,3"], dir.path());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    let csv = std::fs::read_to_string(dir.path().join("sweep.csv")).unwrap();
    let x: Vec<f64> = csv.lines().skip(1).map(|r| r.split(',').nth(6).unwrap().parse().unwrap()).collect();
    assert_eq!(x.len(), 3, "{csv}");
    assert!(x[0] != x[1] && x[1] != x[2], "seeds move the scatterers: {x:?}");
    let mean = x.iter().sum::<f64>() / 3.0;
    let sd = (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / 2.0).sqrt();
    let seeds = std::fs::read_to_string(dir.path().join("sweep-seeds.csv")).unwrap();
    let row: Vec<&str> = seeds.lines().nth(1).unwrap().split(',').collect();
    assert_eq!(row[1], "3", "{seeds}");
    let (m, s): (f64, f64) = (row[2].parse().unwrap(), row[3].parse().unwrap());
    assert!((m - mean).abs() < 1e-12 && (s - sd).abs() < 1e-12, "{seeds}");
    let md = std::fs::read_to_string(dir.path().join("sweep.md")).unwrap();
    assert!(md.contains("Over 3 realisations"), "{md}");
    let labelled = quick_sweep(&["--seeds", "flow.seed=1", "--label", "nope"], &dir.path().join("labelled"));
    assert_eq!(labelled.status.code(), Some(1));
    let csv = std::fs::read_to_string(dir.path().join("labelled/sweep.csv")).unwrap();
    assert!(csv.contains("evaluation-nope.json"), "{csv}");
}

/// `sonoflow platelet data` then `train` on a small data set: the weights load back as the
/// networks and reproduce the report's test error; `five` writes its figures and tables.
#[test]
fn platelet_tools_generate_train_and_run_the_five_particles() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("d.jsonl");
    let weights = dir.path().join("w");
    let run = |args: &[&str]| {
        let out = Command::new(bin()).arg("platelet").args(args).output().unwrap();
        let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
        (out.status.code().unwrap_or(-1), text)
    };
    let d = data.to_str().unwrap();
    // coarse, without the thin-shape refinement: this tests the tool, not the solver
    let coarse = [
        "data",
        "--out",
        d,
        "--shapes",
        "24",
        "--generalisation",
        "4",
        "--n-beta",
        "6",
        "--threads",
        "2",
        "--refine",
        "none",
    ];
    let (code, text) = run(&coarse);
    assert_eq!(code, 0, "{text}");
    assert!(text.contains("24 in-bounds + 4 generalisation"), "{text}");
    // resumed: nothing left to solve, same file
    let before = std::fs::read_to_string(&data).unwrap();
    let (code, text) = run(&coarse);
    assert_eq!(code, 0, "{text}");
    assert_eq!(std::fs::read_to_string(&data).unwrap(), before);
    // other solver options on the same file: refused
    let (code, text) = run(&["data", "--out", d, "--shapes", "24", "--n-beta", "8"]);
    assert_ne!(code, 0);
    assert!(text.contains("generated with"), "{text}");
    let (code, text) = run(&["train", "--data", d, "--out", weights.to_str().unwrap(), "--epochs", "30"]);
    assert_eq!(code, 0, "{text}");
    for f in ["n.safetensors", "n_r.safetensors", "n_s.safetensors", "training-report.md", "training-report.json"] {
        assert!(weights.join(f).exists(), "{f} missing: {text}");
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(weights.join("training-report.json")).unwrap()).unwrap();
    let sets = report[0]["sets"].as_array().unwrap();
    let names: Vec<&str> = sets.iter().map(|s| s["set"].as_str().unwrap()).collect();
    assert_eq!(names, ["training", "test", "generalisation"]);
    // shapes split 80/20: 19 training and 5 test shapes × 4 angles
    assert_eq!((sets[0]["n"].as_u64(), sets[1]["n"].as_u64(), sets[2]["n"].as_u64()), (Some(76), Some(20), Some(16)));
    let model = sonoflow_platelet::nn::model::NetworkModel::load_dir(&weights).unwrap();
    assert_eq!(model.networks().0.sizes(), [6, 50, 20, 20, 3]);
    let (code, text) = run(&[
        "five",
        "--weights",
        weights.to_str().unwrap(),
        "--out",
        dir.path().join("five").to_str().unwrap(),
        "--t-end",
        "2",
    ]);
    assert_eq!(code, 0, "{text}");
    for f in [
        "coefficients.csv",
        "trajectories.csv",
        "five-particles.md",
        "figures/coefficients.png",
        "figures/y_position.png",
    ] {
        assert!(dir.path().join("five").join(f).exists(), "{f} missing: {text}");
    }
    let csv = std::fs::read_to_string(dir.path().join("five/coefficients.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 5 * 361);
    let (code, text) = run(&["train", "--data", dir.path().join("none.jsonl").to_str().unwrap()]);
    assert_ne!(code, 0);
    assert!(text.contains("none.jsonl"), "{text}");
}

// ---- recordings: inspect, inspect --verify, a closed stdout ---------------------------------

/// A finished recording of 40 `RfFrameV3` messages (4096 samples each) on topic `rf`, 64 KiB
/// chunks, and a metadata record `big` with `metadata_keys` entries (for a long `inspect`
/// output). Returns the file's bytes.
fn small_recording(
    path: &std::path::Path,
    compression: sonoflow_mcap_io::Compression,
    metadata_keys: usize,
    bad_message: Option<u32>,
) -> Vec<u8> {
    use sonoflow_mcap_io::{ChannelSpec, OutMessage, RecorderWriter, WriterOptions};
    use sonoflow_messages::{cdr, MessageType};
    let kind = MessageType::RfFrameV3;
    let opts = WriterOptions { compression, chunk_size: 64 * 1024, ..WriterOptions::default() };
    let mut w = RecorderWriter::create(path, opts).unwrap();
    let rf = w
        .add_channel(ChannelSpec {
            topic: "rf".into(),
            message_encoding: "cdr".into(),
            schema_name: kind.schema_name(),
            schema_encoding: "ros2msg".into(),
            schema_data: kind.schema_text().into_bytes(),
            metadata: Default::default(),
        })
        .unwrap();
    for seq in 0..40u32 {
        let payload: Vec<u8> = (0..4096u32).flat_map(|i| ((i * 7 + seq * 100_000) as f32).to_le_bytes()).collect();
        // A malformed record: it declares one element more than it carries.
        let n = if bad_message == Some(seq) { 4097 } else { 4096 };
        let mut data = Vec::new();
        cdr::encode_bytes_into(&vec![0u8; kind.header_size()], n, &payload, &mut data);
        let t = 1_000_000 * u64::from(seq + 1);
        w.write(OutMessage { channel: rf, sequence: seq, log_time: t, publish_time: t, data }).unwrap();
    }
    if metadata_keys > 0 {
        w.metadata("big", (0..metadata_keys).map(|i| (format!("key{i:06}"), "x".repeat(40))).collect()).unwrap();
    }
    w.finish().unwrap();
    std::fs::read(path).unwrap()
}

fn inspect(args: &[&std::ffi::OsStr]) -> (i32, String, String) {
    let out = Command::new(bin()).arg("inspect").args(args).output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// `inspect` reads the summary only and says so; `--verify` reads every chunk: it passes an
/// intact file (decoded counts = summary counts), and fails on bytes flipped inside a chunk,
/// naming the chunk, although the summary (and so plain `inspect`) is still fine.
#[test]
fn inspect_verify_decodes_every_chunk_and_names_the_damaged_one() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("ok.mcap");
    let bytes = small_recording(&rec, sonoflow_mcap_io::Compression::None, 0, None);

    let (code, out, err) = inspect(&[rec.as_os_str()]);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.contains("complete MCAP (summary only; run with --verify to decode every chunk and check CRCs)"),
        "{out}"
    );
    assert!(out.contains("sonoflow_msgs/msg/RfFrameV3") && out.contains("40 messages"), "{out}");

    let (code, out, err) = inspect(&["--verify".as_ref(), rec.as_os_str()]);
    assert_eq!(code, 0, "{out}\n{err}");
    assert!(!out.contains("summary only"), "{out}");
    assert!(out.contains("messages decoded"), "{out}");
    assert!(
        out.lines()
            .any(|l| l.split_whitespace().collect::<Vec<_>>() == ["rf", "40", "decoded", "40", "in", "the", "summary"]),
        "{out}"
    );
    assert!(out.ends_with("verify: ok\n"), "{out}");

    // Flip 200 bytes inside message 20's payload (uncompressed chunks: the bytes are in the file).
    let needle: Vec<u8> = (0..64u32).flat_map(|i| ((i * 7 + 20 * 100_000) as f32).to_le_bytes()).collect();
    let at = bytes.windows(needle.len()).position(|w| w == needle.as_slice()).expect("message 20 in the file");
    let mut damaged = bytes.clone();
    for b in &mut damaged[at + 100..at + 300] {
        *b ^= 0xFF;
    }
    let bad = dir.path().join("flipped.mcap");
    std::fs::write(&bad, &damaged).unwrap();

    let (code, out, err) = inspect(&[bad.as_os_str()]);
    assert_eq!(code, 0, "the summary is intact: {err}");
    assert!(out.contains("summary only"), "{out}");

    let (code, out, err) = inspect(&["--verify".as_ref(), bad.as_os_str()]);
    assert_eq!(code, 1, "{out}\n{err}");
    let prefix = format!("sonoflow: error: {} failed verification: chunk record at byte offset ", bad.display());
    let rest = err.strip_prefix(&prefix).unwrap_or_else(|| panic!("{err}"));
    let offset: usize = rest.split(':').next().unwrap().parse().unwrap();
    assert!(offset < at && at - offset < 64 * 1024 + 20_000, "the chunk at {offset} holds byte {at}");
    assert_eq!(&bytes[offset..offset + 1], &[0x06], "a chunk record starts at {offset}");
    assert!(err.contains("Chunk CRC failed"), "{err}");
    assert!(!out.contains("verify: ok"), "{out}");

    // A record that is not a valid RfFrameV3 (CRCs fine): --verify names the message.
    let malformed = dir.path().join("malformed.mcap");
    small_recording(&malformed, sonoflow_mcap_io::Compression::Zstd, 0, Some(7));
    assert_eq!(inspect(&[malformed.as_os_str()]).0, 0);
    let (code, _, err) = inspect(&["--verify".as_ref(), malformed.as_os_str()]);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("message 7 on `rf` (log time 8000000, in the chunk at byte offset "), "{err}");
    assert!(err.contains("RfFrameV3 record declares 4097 elements but carries 16384 payload bytes"), "{err}");
}

/// `sonoflow inspect … | head`: the reader goes away after a few bytes while the command still
/// has about a megabyte to print; it must end quietly (exit status 0, or killed by SIGPIPE as
/// documented in main.rs), not panic with "failed printing to stdout: Broken pipe".
#[test]
fn a_closed_stdout_ends_the_command_quietly() {
    use std::io::Read;
    use std::os::unix::process::ExitStatusExt;
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("long.mcap");
    small_recording(&rec, sonoflow_mcap_io::Compression::Zstd, 20_000, None);
    for verify in [false, true] {
        let mut cmd = Command::new(bin());
        cmd.arg("inspect");
        if verify {
            cmd.arg("--verify");
        }
        let mut child =
            cmd.arg(&rec).stdout(std::process::Stdio::piped()).stderr(std::process::Stdio::piped()).spawn().unwrap();
        let mut stdout = child.stdout.take().unwrap();
        let mut first = [0u8; 16];
        stdout.read_exact(&mut first).unwrap();
        drop(stdout);
        let out = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(rec.to_string_lossy().as_bytes().starts_with(&first), "{:?}", String::from_utf8_lossy(&first));
        assert!(!err.contains("panicked") && !err.contains("Broken pipe"), "verify {verify}: {err}");
        assert!(err.is_empty(), "verify {verify}: nothing on stderr: {err}");
        assert!(
            out.status.success() || out.status.signal() == Some(libc::SIGPIPE),
            "verify {verify}: {:?}",
            out.status
        );
    }
}
