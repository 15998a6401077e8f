#![allow(clippy::unwrap_used)]
//! Speckle tracking (the `speckle-tracking` node, MUST `sptrack`) swapped in for the Doppler
//! estimator in whole graphs: a rigid translation (its bias), the quickstart vessel and the
//! rotating disk (its errors against the truth, as the evaluator reports them).

mod common;
use common::*;
use sonoflow_evaluate::evaluation::Evaluation;
use sonoflow_messages::cdr;
use sonoflow_messages::types::{DopplerMap, VectorField};

fn evaluation(dir: &std::path::Path) -> Evaluation {
    serde_json::from_str(&std::fs::read_to_string(dir.join("evaluation.json")).unwrap()).unwrap()
}

/// A plug band translating at 0.5 m/s along 20° on a 0.1 mm grid: the bias of each component
/// (gain − 1 over the image) stays below 2 % of the displacement at the default lag 10 (4.7 px
/// lateral per pair) on seeds 1 and 3 and at lag 12 on seed 2. Measured gains x / z: lag 10
/// seeds 1–3 1.011 … 1.012 / 1.015 … 1.018, lag 12 1.013 / 0.990 (seeds 1–3: x +0.9 … +1.4 %,
/// z −0.9 … −1.1 %), lag 16 0.998 / 1.009; shorter lags are worse (lag 8 0.966, lag 4 1.071 in x:
/// docs/nodes.md, "speckle-tracking").
#[test]
fn rigid_translation_bias_is_below_two_percent() {
    for (seed, lag) in [(1, 10), (3, 10), (2, 12)] {
        let dir = tempfile::tempdir().unwrap();
        let (seed_s, lag_s) = (format!("flow.seed={seed}"), format!("doppler.lag={lag}"));
        run_graph_ok("tests/launch/plug-speckle.toml", dir.path(), &["--set", &seed_s, "--set", &lag_s]);
        let ev = evaluation(dir.path());
        let raw = &ev.packets[0].fields["raw"];
        let (gx, gz) = (raw.gain_x.unwrap(), raw.gain_z.unwrap());
        println!("seed {seed} lag {lag}: gain x {gx:.4}, z {gz:.4}; no estimate {} of {}", raw.no_estimate, raw.pixels);
        assert!((gx - 1.0).abs() < 0.02 && (gz - 1.0).abs() < 0.02, "seed {seed} lag {lag}: gains {gx} {gz}");
        assert!(raw.pixels > 5000 && raw.no_estimate * 50 < raw.pixels, "{raw:?}");
    }
}

/// `--swap doppler=speckle` on the quickstart: the vector field and the axial map carry the
/// speckle tracker's planes, and its errors (measured: raw x |e|₇₅ 6.3 %, z 4.0 % of v_max; the
/// autocorrelation estimator's raw x is 24.7 %) stay under bounds that twice today's fails.
#[test]
fn quickstart_speckle_tracking_measures_the_vessel() {
    let dir = tempfile::tempdir().unwrap();
    run_graph_ok("launch/quickstart.toml", dir.path(), &["--swap", "doppler=speckle"]);
    let rec = dir.path().join("recording.mcap");
    let (vh, v) = cdr::decode::<VectorField>(&read_topic(&rec, "vector")[0]).unwrap();
    let n = (vh.grid.nx * vh.grid.nz) as usize;
    assert_eq!(vh.n_planes, 5);
    assert_eq!(vh.plane_ids[4], sonoflow_messages::plane::WEIGHT);
    assert!(v[4 * n..5 * n].iter().all(|w| (0.0..=1.0).contains(w)));
    let maps = read_topic(&rec, "maps");
    assert_eq!(maps.len(), 2, "one axial map per packet");
    let (mh, m) = cdr::decode::<DopplerMap>(&maps[0]).unwrap();
    assert_eq!(mh.estimator, sonoflow_messages::ESTIMATOR_SPECKLE_TRACKING);
    // The map is the axial component toward the probe.
    assert!((0..n).all(|i| m[i] == -v[n + i]));
    let ev = evaluation(dir.path());
    let raw = &ev.overall["raw"];
    println!("quickstart speckle: x |e|75 {:.4}, z {:.4}", raw.x.abs_p75, raw.z.abs_p75);
    assert!(raw.x.abs_p75 < 0.11 && raw.z.abs_p75 < 0.07, "{raw:?}");
    assert!(raw.no_estimate * 20 < raw.pixels, "{raw:?}");
}

/// The rotating disk (not used to choose the defaults): measured raw x |e|₇₅ 4.0 %, z 3.9 %.
#[test]
fn rotating_disk_speckle_tracking() {
    let dir = tempfile::tempdir().unwrap();
    run_graph_ok("launch/rotating-disk.toml", dir.path(), &["--swap", "doppler=speckle"]);
    let raw = &evaluation(dir.path()).overall["raw"];
    println!("rotating disk speckle: x |e|75 {:.4}, z {:.4}", raw.x.abs_p75, raw.z.abs_p75);
    assert!(raw.x.abs_p75 < 0.06 && raw.z.abs_p75 < 0.07, "{raw:?}");
}
