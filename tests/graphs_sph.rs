#![allow(clippy::unwrap_used)]
//! The SPH fluid producer as a process in a graph: snapshots at the acquisition times with stable
//! ids and amplitudes, SPH ground truth against the analytic profile, diagnostics, and a run resumed
//! from the checkpoint of another run.

mod common;
use common::*;
use sonoflow_messages::cdr;
use sonoflow_messages::types::{FlowStats, ParticleSnapshot, VectorField};
use sonoflow_messages::{plane, DT_CFL, DT_OUTPUT};
use std::collections::HashMap;

#[test]
fn sph_tube_publishes_scatterers_truth_and_diagnostics_and_resumes_from_its_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("a");
    let out = run_graph("tests/launch/sph-tube.toml", &a, &[]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    let rec = a.join("recording.mcap");

    // 8 snapshots at the schedule's times, fluid only, ids unique, amplitudes fixed per id
    let snaps = read_topic(&rec, "particles");
    assert_eq!(snaps.len(), 8);
    let mut amp: HashMap<u32, f32> = HashMap::new();
    for (k, m) in snaps.iter().enumerate() {
        let (h, ps) = cdr::decode::<ParticleSnapshot>(m).unwrap();
        assert_eq!(h.common.frame_id, k as u64);
        assert!((h.common.t_valid - k as f64 * 1e-4).abs() < 1e-15, "frame time {}", h.common.t_valid);
        assert_eq!((h.packet, h.frame_in_packet, h.packet_size), (0, k as u32, 8));
        assert!(ps.len() > 1800 && ps.len() < 2100, "{} fluid particles", ps.len());
        let mut seen = std::collections::HashSet::new();
        for p in &ps {
            assert!(seen.insert(p.id), "id {} twice", p.id);
            let a0 = *amp.entry(p.id).or_insert(p.amplitude);
            assert_eq!(a0.to_bits(), p.amplitude.to_bits(), "amplitude of id {} changed", p.id);
            // inside the 8 mm tube at 20 mm depth
            assert!((p.z - 0.02).abs() < 4e-3, "particle {} at z = {}", p.id, p.z);
        }
    }
    // amplitudes N(0, 1): sample mean and variance over ~1 900 particles (standard errors 0.023, 0.032)
    let v: Vec<f64> = amp.values().map(|&a| a as f64).collect();
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    let var = v.iter().map(|a| (a - mean).powi(2)).sum::<f64>() / v.len() as f64;
    assert!(mean.abs() < 0.1 && (var - 1.0).abs() < 0.15, "amplitudes mean {mean} var {var}");

    // ground truth at the packet's mid time: the Poiseuille profile 1.5 ū (1 − y²/a²) in the tube
    let truth = read_topic(&rec, "truth");
    assert_eq!(truth.len(), 1);
    let (h, f) = cdr::decode::<VectorField>(&truth[0]).unwrap();
    assert!((h.common.t_valid - 3.5e-4).abs() < 1e-12, "mid time {}", h.common.t_valid);
    assert_eq!(&h.plane_ids[..3], &[plane::VX, plane::VZ, plane::MASK]);
    let (nx, nz) = (h.grid.nx as usize, h.grid.nz as usize);
    let nn = nx * nz;
    let (mut worst, mut inside) = (0.0f64, 0);
    for iz in 0..nz {
        for ix in 0..nx {
            let i = iz * nx + ix;
            let (x, z) = (h.grid.x0 + ix as f64 * h.grid.dx, h.grid.z0 + iz as f64 * h.grid.dz);
            let y = z - 0.02;
            let m = f[2 * nn + i];
            // (a pixel exactly on the wall is a tie that the rounding of the sampled SDF decides)
            if (y.abs() - 4e-3).abs() > 1e-9 {
                assert_eq!(m == 1.0, y.abs() < 4e-3, "mask at z = {z}");
            }
            // away from the ends of the tube (±20 mm) and half a spacing or more inside the wall
            if m == 1.0 && x.abs() < 0.01 && y.abs() < 3.5e-3 {
                let exact = 1.5 * 0.05 * (1.0 - (y / 4e-3).powi(2));
                worst = worst.max((f[i] as f64 - exact).abs() / 0.075);
                assert!((f[nn + i] as f64).abs() < 0.02 * 0.075, "vz {} at ({x}, {z})", f[nn + i]);
                inside += 1;
            }
        }
    }
    eprintln!("SPH truth vs Poiseuille: worst {:.2} % of u_max over {inside} pixels", 100.0 * worst);
    assert!(inside > 200);
    assert!(worst < 0.03, "{worst}");

    // diagnostics: one message per frame plus the periodic and final ones; two boundaries
    let stats = read_topic(&rec, "flow_stats");
    assert!(stats.len() >= 9, "{} stats messages", stats.len());
    let (last, flux) = cdr::decode::<FlowStats>(stats.last().unwrap()).unwrap();
    assert_eq!(flux.len(), 2);
    assert!((last.common.t_valid - 0.002).abs() < 1e-12, "ran until 0.002 s: {}", last.common.t_valid);
    assert!(last.max_density_error < 0.01 && last.kinetic_energy > 0.0 && last.n_fluid > 1800);
    assert!([DT_CFL, DT_OUTPUT].contains(&last.binding));
    assert_eq!(last.guard_corrections, 0);

    // a second run continues from the checkpoint at t = 0.002 s with a later schedule
    let ckpt = a.join("flow.ckpt");
    assert!(ckpt.exists());
    let b = dir.path().join("b");
    let set_ck = format!("flow.checkpoint_in={:?}", ckpt.display().to_string());
    let out = run_graph(
        "tests/launch/sph-tube.toml",
        &b,
        &["--set", &set_ck, "--set", "flow.schedule.t_start=0.003", "--set", "flow.run_until=0.004"],
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(err.contains("resumed from"), "{err}");
    let snaps_b = read_topic(&b.join("recording.mcap"), "particles");
    assert_eq!(snaps_b.len(), 8);
    let (h0, ps0) = cdr::decode::<ParticleSnapshot>(&snaps_b[0]).unwrap();
    assert!((h0.common.t_valid - 0.003).abs() < 1e-15);
    // the same particles (ids) with the same amplitudes
    for p in &ps0 {
        if let Some(a0) = amp.get(&p.id) {
            assert_eq!(a0.to_bits(), p.amplitude.to_bits());
        }
    }
    let known = ps0.iter().filter(|p| amp.contains_key(&p.id)).count();
    assert!(known as f64 > 0.95 * ps0.len() as f64, "{known} of {} ids known", ps0.len());
    // a schedule before the checkpoint's time is refused with a clear error
    let c = dir.path().join("c");
    let out = run_graph("tests/launch/sph-tube.toml", &c, &["--set", &set_ck]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_ne!(out.status.code(), Some(0));
    assert!(err.contains("before the solver's start time"), "{err}");
}

/// The paper's chain on the SPH carotid, coarse (0.3 mm lattice, one packet right after the start):
/// SPH → SIMUS → beamformer (∓15°, F# 3) → Doppler → regulariser → evaluator. The Doppler estimate
/// is compared with the SPH velocity itself: z within a few per cent of v_max for 75 % of the pixels
/// (measured 2.5 %), x within 30 % (measured 18 %: the cross-beam component is the hard one); the
/// vessel fills the evaluated region (thousands of pixels) and the outflow split is the imposed one.
#[test]
fn carotid_chain_on_a_coarse_lattice_reports_its_error_against_the_sph_truth() {
    let dir = tempfile::tempdir().unwrap();
    let out = run_graph(
        "launch/carotid.toml",
        dir.path(),
        &["--set", "flow.dx=0.3e-3", "--set", "flow.schedule.n_packets=1", "--set", "flow.schedule.t_start=0.0101"],
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    let eval: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("evaluation.json")).unwrap()).unwrap();
    let reg = &eval["packets"][0]["fields"]["regularised"];
    let (px, ez, ex) =
        (reg["pixels"].as_u64().unwrap(), reg["z"]["abs_p75"].as_f64().unwrap(), reg["x"]["abs_p75"].as_f64().unwrap());
    eprintln!("carotid 0.3 mm, packet at 10 ms: {px} px, |e|75 z {:.1} %, x {:.1} %", 100.0 * ez, 100.0 * ex);
    assert!(px > 4000, "{px} pixels");
    assert!(ez < 0.05, "z |e|75 {ez}");
    assert!(ex < 0.30, "x |e|75 {ex}");
    let line = err.lines().find(|l| l.contains("outflow split")).expect("split line");
    let share = |name: &str| -> f64 {
        let rest = &line[line.find(name).unwrap() + name.len()..];
        rest.trim_start().split(' ').next().unwrap().parse().unwrap()
    };
    assert!((share("internal") - 54.0).abs() < 3.0 && (share("external") - 46.0).abs() < 3.0, "{line}");
    let report = std::fs::read_to_string(dir.path().join("report.md")).unwrap();
    assert!(report.contains("sph-flow") && report.contains("Error against ground truth"), "{report}");
    // sonoflow's branch on the same RF (five receive angles in a sub-band below the grating-lobe
    // onset and five near-normal ones at 5 MHz, Hann receive apodisation at F# 2.5, fc²-weighted
    // vector solve, divergence-free regulariser with the no-slip wall): the paper chain's lateral
    // bias (grating lobes of the ±15° sub-apertures: measured −8.4 %) is gone (−0.3 %) and the
    // lateral |e|75 drops from 18.2 to 3.1 % (z: 2.5 → 1.0 %). Asserted tightly enough that a
    // regression to twice today's error fails (measured 3.15 % / 1.02 %; the chain is deterministic).
    let sf: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("evaluation-subband-divfree.json")).unwrap()).unwrap();
    let sreg = &sf["packets"][0]["fields"]["regularised"];
    let (sz, sx) = (sreg["z"]["abs_p75"].as_f64().unwrap(), sreg["x"]["abs_p75"].as_f64().unwrap());
    let (bias_paper, bias_sf) = (reg["x"]["bias"].as_f64().unwrap(), sreg["x"]["bias"].as_f64().unwrap());
    eprintln!(
        "subband-divfree: |e|75 z {:.1} %, x {:.1} %; x bias {:+.1} % (paper chain {:+.1} %)",
        100.0 * sz,
        100.0 * sx,
        100.0 * bias_sf,
        100.0 * bias_paper
    );
    assert_eq!(sreg["pixels"], reg["pixels"]);
    assert!(bias_paper < -0.04 && bias_sf.abs() < 0.04, "x bias: paper {bias_paper}, subband-divfree {bias_sf}");
    assert!(sx < 0.6 * ex && sz < ez, "subband-divfree x {sx} z {sz} vs paper x {ex} z {ez}");
    assert!(sx < 2.0 * 0.0315 && sz < 2.0 * 0.0102, "subband-divfree x {sx}, z {sz}: twice today's 3.15 % / 1.02 %");
    // The paper's chain given sonoflow's lumen (smoothn with the power mask and no-slip wall as a
    // mask; the fair baseline of issue 19): same pixels, no figures; measured x 19.9 %, z 2.71 %
    // (unmasked 18.2 / 2.5 %: the lumen alone does not buy the paper's chain anything).
    let pl: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("evaluation-paper-lumen.json")).unwrap()).unwrap();
    let preg = &pl["packets"][0]["fields"]["regularised"];
    let (plx, plz) = (preg["x"]["abs_p75"].as_f64().unwrap(), preg["z"]["abs_p75"].as_f64().unwrap());
    eprintln!("paper-lumen: |e|75 z {:.2} %, x {:.2} %", 100.0 * plz, 100.0 * plx);
    assert_eq!(preg["pixels"], reg["pixels"]);
    assert!(plx < 2.0 * 0.199 && plz < 2.0 * 0.0271, "paper-lumen x {plx}, z {plz}: twice today's 19.9 / 2.71 %");
    // The figures on the carotid's 161 × 111 grid, the second evaluator's with its label.
    let mut figs = checked_figures(dir.path());
    figs.sort();
    assert_eq!(
        figs,
        [
            "bmode.png",
            "doppler_maps-subband-divfree.png",
            "doppler_maps.png",
            "error_histograms-subband-divfree.png",
            "error_histograms.png",
            "stage_times.png",
            "transmit_fields.png",
            "vector_field-subband-divfree.png",
            "vector_field.png"
        ]
    );

    // replay-estimators on this recording: no fluid, SIMUS or beamforming; the autocorrelation
    // estimator on the replayed I/Q gives exactly the errors of the original run (bit-identical
    // replay), Loupas' estimator its own, both in the report
    let re = dir.path().join("replay");
    let rec = dir.path().join("recording.mcap");
    let set_path = format!("replay.path={:?}", rec.display().to_string());
    let out = run_graph("launch/replay-estimators.toml", &re, &["--set", &set_path]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    let read =
        |p: std::path::PathBuf| -> serde_json::Value { serde_json::from_slice(&std::fs::read(p).unwrap()).unwrap() };
    let ac = read(re.join("evaluation-autocorrelation.json"));
    let lp = read(re.join("evaluation-loupas.json"));
    assert_eq!(ac["label"], "autocorrelation");
    for field in ["raw", "regularised"] {
        assert_eq!(ac["packets"][0]["fields"][field], eval["packets"][0]["fields"][field], "{field}");
        let l = &lp["packets"][0]["fields"][field];
        assert_eq!(l["pixels"], ac["packets"][0]["fields"][field]["pixels"], "{field}");
        let (lz, lx) = (l["z"]["abs_p75"].as_f64().unwrap(), l["x"]["abs_p75"].as_f64().unwrap());
        eprintln!("replayed, loupas {field}: |e|75 z {:.1} %, x {:.1} %", 100.0 * lz, 100.0 * lx);
        // the same I/Q: Loupas' estimate is close to the autocorrelation one, not the same bits
        assert!(lz < 0.05 && lx < 0.30, "loupas {field}: z {lz}, x {lx}");
        assert_ne!(l, &ac["packets"][0]["fields"][field], "loupas gave the autocorrelation's errors");
    }
    // Speckle tracking on the same I/Q, in the same report (its figures are checked below).
    let sp = read(re.join("evaluation-speckle.json"));
    let s = &sp["packets"][0]["fields"]["raw"];
    assert_eq!(s["pixels"], ac["packets"][0]["fields"]["raw"]["pixels"]);
    eprintln!("replayed, speckle raw: |e|75 x {}, z {}", s["x"]["abs_p75"], s["z"]["abs_p75"]);
    assert!(s["x"]["abs_p75"].as_f64().unwrap().is_finite() && s["z"]["abs_p75"].as_f64().unwrap().is_finite());
    let report = std::fs::read_to_string(re.join("report.md")).unwrap();
    assert!(
        report.contains("Error against ground truth: `autocorrelation`")
            && report.contains("Error against ground truth: `loupas`")
            && report.contains("Error against ground truth: `speckle`"),
        "{report}"
    );
    // Each labelled evaluator draws its own figures, beside the launcher's stage times.
    let mut figs = checked_figures(&re);
    figs.sort();
    let want: Vec<String> = ["autocorrelation", "loupas", "speckle"]
        .iter()
        .flat_map(|l| ["doppler_maps", "error_histograms", "vector_field"].map(|f| format!("{f}-{l}.png")))
        .chain(["stage_times.png".to_string(), "bmode-autocorrelation.png".to_string()])
        .collect();
    let mut want = want;
    want.sort();
    assert_eq!(figs, want);
    let nodes =
        read(re.join("report.json"))["nodes"].as_array().unwrap().iter().map(|n| n["name"].clone()).collect::<Vec<_>>();
    assert!(!nodes.iter().any(|n| n == "flow" || n == "simus" || n == "beamformer"), "{nodes:?}");
    let cpu = |v: &serde_json::Value| -> f64 {
        v["nodes"].as_array().unwrap().iter().filter_map(|n| n["stats"]["compute_ns_total"].as_f64()).sum::<f64>() / 1e9
    };
    eprintln!(
        "compute CPU: original run {:.2} s, replay-estimators {:.2} s",
        cpu(&read(dir.path().join("report.json"))),
        cpu(&read(re.join("report.json")))
    );
}
