#![allow(clippy::unwrap_used)]
//! `launch/clutter-quick.toml` through the launcher, one packet (t = 0.2 s): a vessel in
//! pulsating tissue 40 dB above the blood with 20 dB receive noise, the paper's chain and
//! sonoflow's branch side by side, each with the SVD clutter filter. The pulsating wall is on
//! the wire as moving tissue; both evaluators report the filter; the regularised pooled |e|₇₅
//! stay below twice what this scene gives today (seed 1, SVD with its default 10 dB energy gap:
//! paper x 17.4 % / z 1.7 %, sonoflow x 6.3 % / z 1.6 %; before the gap: 37.0 / 3.2 % and
//! 12.4 / 2.1 %), and sonoflow's branch stays ahead of the paper's in x. The coarse
//! `launch/carotid-clutter.toml` (SPH, 128-frame packets, filter compensation) likewise, on its
//! first packet (~1.5 min).

mod common;
use common::*;
use sonoflow_messages::cdr;
use sonoflow_messages::types::{ParticleSnapshot, VectorField};
use sonoflow_messages::{CLUTTER_SVD, PARTICLE_FLUID, PARTICLE_TISSUE_MOVING, VECTOR_REGULARISED};

fn pooled(dir: &std::path::Path, file: &str) -> (f64, f64, String) {
    let e: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join(file)).unwrap()).unwrap();
    let r = &e["overall"]["regularised"];
    let filter = e["clutter"][0]["filter"].as_str().unwrap_or("none").to_string();
    (r["x"]["abs_p75"].as_f64().unwrap(), r["z"]["abs_p75"].as_f64().unwrap(), filter)
}

#[test]
fn clutter_quick_scene_keeps_its_accuracy_through_tissue_noise_and_the_svd_filter() {
    let dir = tempfile::tempdir().unwrap();
    let topics = "recorder.topics=[\"particles\", \"truth\", \"maps\", \"regularised\", \"regularised_sf\"]";
    run_graph_ok("launch/clutter-quick.toml", dir.path(), &["--set", "flow.schedule.n_packets=1", "--set", topics]);
    // The first snapshot: blood, then the pulsating tissue (moving, so SIMUS simulates it).
    let snaps = read_topic(&dir.path().join("recording.mcap"), "particles");
    assert_eq!(snaps.len(), 32);
    let (h, ps) = cdr::decode::<ParticleSnapshot>(&snaps[0]).unwrap();
    let n_tissue = ps.iter().filter(|p| p.kind == PARTICLE_TISSUE_MOVING).count();
    assert_eq!(ps.iter().filter(|p| p.kind == PARTICLE_FLUID).count(), h.n_fluid as usize);
    assert!(n_tissue > 3000 && n_tissue + h.n_fluid as usize == ps.len(), "{n_tissue} tissue scatterers");
    let moving = ps.iter().filter(|p| p.kind == PARTICLE_TISSUE_MOVING && (p.vx != 0.0 || p.vz != 0.0)).count();
    assert!(moving > n_tissue / 2, "the wall pulsates at t = 0.2 s: {moving} of {n_tissue} tissue scatterers move");

    let (px, pz, pf) = pooled(dir.path(), "evaluation.json");
    let (sx, sz, sf) = pooled(dir.path(), "evaluation-subband-divfree.json");
    eprintln!(
        "paper x {:.1} % z {:.1} %; sonoflow x {:.1} % z {:.1} %",
        100.0 * px,
        100.0 * pz,
        100.0 * sx,
        100.0 * sz
    );
    assert_eq!((pf.as_str(), sf.as_str()), ("svd", "svd"));
    // The regularised field's header still says how it was made: the looks' SVD filter (rank
    // and cut-off) and the ten looks of sonoflow's branch; the evaluator reads it from there.
    let reg = read_topic(&dir.path().join("recording.mcap"), "regularised_sf");
    let (vh, _) = cdr::decode::<VectorField>(&reg[0]).unwrap();
    assert_eq!((vh.source, vh.clutter_filter, vh.n_looks), (VECTOR_REGULARISED, CLUTTER_SVD, 10));
    assert!(vh.clutter_order >= 1 && vh.clutter_cutoff > 0.0 && vh.clutter_removed_energy > 0.9, "{vh:?}");
    let e: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("evaluation-subband-divfree.json")).unwrap())
            .unwrap();
    let fc = &e["field_clutter"]["regularised"];
    assert_eq!((fc["filter"]["filter"].as_str(), fc["looks"].as_u64()), (Some("svd"), Some(10)), "{fc}");
    assert!(px < 2.0 * 0.174 && pz < 2.0 * 0.017, "paper chain: x {px}, z {pz}");
    assert!(sx < 2.0 * 0.063 && sz < 2.0 * 0.016, "sonoflow's branch: x {sx}, z {sz}");
    assert!(sx < px, "sonoflow's branch ahead of the paper's in x: {sx} vs {px}");
}

/// Look rejection on a realisation where one of sonoflow's ten looks fails after the SVD (tissue
/// seed 11, noise seed 21, first packet): the −15° look of the 3.6 MHz sub-band is left out of
/// the vector solve (logged), and sonoflow's regularised x error stays below twice today's
/// (measured x 4.6 %, z 1.7 %); with `look_rejection = 0` the failed look drags the field (x 51.0 %,
/// z 6.6 %).
#[test]
fn look_rejection_leaves_out_the_failed_look_of_a_clutter_realisation() {
    let mut x = Vec::new();
    for (rejection, log_line) in [("4.0", true), ("0.0", false)] {
        let dir = tempfile::tempdir().unwrap();
        let set_rejection = format!("doppler_sf.look_rejection={rejection}");
        let out = run_graph_ok(
            "launch/clutter-quick.toml",
            dir.path(),
            &[
                "--set",
                "flow.schedule.n_packets=1",
                "--set",
                "flow.tissue.seed=11",
                "--set",
                "simus.noise.seed=21",
                "--set",
                &set_rejection,
                "--set",
                "recorder.topics=[\"regularised_sf\"]",
            ],
        );
        let err = String::from_utf8_lossy(&out.stderr);
        let line = err.lines().find(|l| l.contains("left out of the vector solve"));
        assert_eq!(line.is_some(), log_line, "look_rejection {rejection}: {line:?}");
        if let Some(l) = line {
            assert!(l.contains("rx -15.00° at 3.60 MHz"), "{l}");
        }
        let (sx, sz, _) = pooled(dir.path(), "evaluation-subband-divfree.json");
        let e: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.path().join("evaluation-subband-divfree.json")).unwrap())
                .unwrap();
        let left_out = e["field_clutter"]["raw"]["rejected_looks"].as_u64();
        assert_eq!(left_out, Some(u64::from(log_line)), "the raw field's header counts the look left out");
        eprintln!("look_rejection {rejection}: sonoflow x {:.1} % z {:.1} %", 100.0 * sx, 100.0 * sz);
        x.push((sx, sz));
    }
    assert!(x[0].0 < 2.0 * 0.046 && x[0].1 < 2.0 * 0.017, "with look rejection: {:?}", x[0]);
    assert!(x[1].0 > 3.0 * x[0].0, "without it the failed look drags x: {x:?}");
}

/// `launch/carotid-clutter.toml` on the coarse lattice (0.3 mm), its first packet (t = 0.1 s, 128
/// frames, the file's seeds): the SPH carotid in pulsating tissue with noise, SVD in both chains,
/// and in sonoflow's branch the filter compensation (logged per packet). Regularised |e|₇₅ today:
/// paper x 12.2 % / z 1.65 %, sonoflow x 4.9 % / z 0.83 % (without the compensation sonoflow's x
/// is about twice that: 10.5 % against 6.0 % over seeds 1–3, docs/results.md); asserted below
/// twice today's, and sonoflow's branch ahead in x.
#[test]
fn carotid_clutter_scene_keeps_its_accuracy_with_the_filter_compensation() {
    let dir = tempfile::tempdir().unwrap();
    let out = run_graph_ok(
        "launch/carotid-clutter.toml",
        dir.path(),
        &[
            "--set",
            "flow.dx=0.3e-3",
            "--set",
            "flow.schedule.n_packets=1",
            "--set",
            "recorder.topics=[\"regularised\", \"regularised_sf\"]",
        ],
    );
    let err = String::from_utf8_lossy(&out.stderr);
    let line = err.lines().find(|l| l.contains("compensate_filter corrected")).unwrap_or("");
    let share: f64 =
        line.split("corrected ").nth(1).and_then(|r| r.split(' ').next()).and_then(|v| v.parse().ok()).unwrap_or(0.0);
    assert!(share > 90.0, "most estimates compensated: {line:?}");
    let (px, pz, pf) = pooled(dir.path(), "evaluation.json");
    let (sx, sz, sf) = pooled(dir.path(), "evaluation-subband-divfree.json");
    eprintln!(
        "carotid-clutter packet 0: paper x {:.1} % z {:.2} %; sonoflow x {:.1} % z {:.2} %",
        100.0 * px,
        100.0 * pz,
        100.0 * sx,
        100.0 * sz
    );
    assert_eq!((pf.as_str(), sf.as_str()), ("svd", "svd"));
    assert!(px < 2.0 * 0.122 && pz < 2.0 * 0.0165, "paper chain: x {px}, z {pz}");
    assert!(sx < 2.0 * 0.049 && sz < 2.0 * 0.0083, "sonoflow's branch: x {sx}, z {sz}");
    assert!(sx < px, "sonoflow's branch ahead of the paper's in x: {sx} vs {px}");
}
