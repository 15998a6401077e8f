#![allow(clippy::unwrap_used)]
//! The `platelets` node through the launcher: the quick version of `launch/stenosis-platelets.toml`
//! (2 000 platelets, 2 macro steps, the channel tilted by 20°) recorded to MCAP; the snapshots
//! are checked against the carrier flow computed independently here.

mod common;
use common::*;
use sonoflow_mcap_io::{McapReader, ReadOptions};
use sonoflow_messages::cdr;
use sonoflow_messages::kinds::ParticleSnapshot;
use sonoflow_messages::PARTICLE_PLATELET;
use sonoflow_platelet::dynamics::{CarrierFlow, Stenosis};

#[test]
fn stenosis_scene_records_platelets_inside_the_channel_moving_with_the_flow() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let out = run_graph(
        "launch/stenosis-platelets.toml",
        &run,
        &[
            "--set",
            "platelets.particles.count=2000",
            "--set",
            "platelets.n_macro_steps=2",
            "--set",
            "platelets.angle_deg=20.0",
        ],
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(err.contains("advection") && err.contains("coefficients (network)"), "no timing split in the log: {err}");

    let r = McapReader::open(&run.join("recording.mcap")).unwrap();
    let msgs: Vec<Vec<u8>> = r
        .messages(&ReadOptions { topics: Some(vec!["platelets".into()]), start_time: None, end_time: None })
        .unwrap()
        .map(|m| m.unwrap().data)
        .collect();
    // the initial state and one snapshot per macro step
    assert_eq!(msgs.len(), 3);

    let st = Stenosis::default(); // the scene's carrier (its values are the defaults)
    let (x0, z0) = (-6e-3, 19e-3);
    let (sa, ca) = 20f64.to_radians().sin_cos();
    let v_in = st.v_in;
    let mut first_x = Vec::new();
    for (k, m) in msgs.iter().enumerate() {
        let (h, ps) = cdr::decode::<ParticleSnapshot>(m).unwrap();
        assert_eq!(h.common.frame_id, k as u64);
        assert!((h.common.t_valid - k as f64 * 5e-3).abs() < 1e-15, "t = {}", h.common.t_valid);
        assert_eq!((h.n_particles, h.n_fluid, ps.len()), (2000, 0, 2000));
        let mut ids: Vec<u32> = ps.iter().map(|p| p.id).collect();
        ids.sort_unstable();
        assert_eq!(ids, (0..2000).collect::<Vec<u32>>(), "ids are 0..2000 once each");
        let (mut close, mut worst) = (0usize, 0.0f64);
        let mut xs = vec![0.0; 2000];
        for p in &ps {
            assert_eq!(p.kind, PARTICLE_PLATELET);
            assert!(p.amplitude.is_finite() && p.amplitude != 0.0);
            // back into channel coordinates
            let (dx, dz) = (p.x as f64 - x0, p.z as f64 - z0);
            let (x, y) = (ca * dx + sa * dz, -sa * dx + ca * dz);
            let (vx, vy) = (ca * p.vx as f64 + sa * p.vz as f64, -sa * p.vx as f64 + ca * p.vz as f64);
            xs[p.id as usize] = x;
            // inside the 12 mm channel between the local walls (f32 positions at 2 cm: ±4 nm)
            let w = st.local_walls(x).unwrap();
            assert!((-1e-8..=12e-3 + 3e-4).contains(&x), "x = {x}");
            assert!(y >= w.lo - 1e-8 && y <= w.hi + 1e-8, "id {} at ({x}, {y}) outside [{}, {}]", p.id, w.lo, w.hi);
            assert!(vx.is_finite() && vy.is_finite());
            let v = st.velocity([x, y.clamp(w.lo, w.hi)], 0.0);
            let e = (vx - v[0]).hypot(vy - v[1]);
            worst = worst.max(e);
            // relaxed (m/C_d ~ 10 ns ≪ 0.25 ms): off the flow by f32 rounding (|∇v| · 4 nm ≈ 1e-7
            // m/s) and the mid-step sampling (u |∇v| τ/2 ≈ 1e-7 m/s)
            if e < 1e-6 {
                close += 1;
            }
        }
        // a particle hit in the last sub-step's collisions keeps its impulse until the next
        // relaxation: off by at most the relative velocity of touching neighbours,
        // |∇v| (r_i + r_j) ≲ 15/s · 10 µm; ~2 pairs per sub-step among 2 000 platelets
        assert!(worst < 1.5e-4, "snapshot {k}: worst |V − v| = {worst} m/s");
        assert!(close >= 1980, "snapshot {k}: only {close} of 2000 within 1e-6 m/s of the flow (v_in {v_in})");
        if k == 0 {
            first_x = xs;
        } else {
            // carried downstream: for platelets uniform in the fluid (area A) the mean speed is
            // Q L / A with Q = v_in H / 3 and A = H L − δ_m L_s (the two cosine bumps); sampling
            // error ~0.3 · v_in/3 / √2000 ≈ 0.7 %
            let t = h.common.t_valid;
            let mean = first_x.iter().zip(&xs).map(|(a, b)| b - a).sum::<f64>() / 2000.0;
            let area = st.height * st.length - 0.5 * st.narrowing * st.height * st.bump_length;
            let expect = st.flow_rate(0.0) * st.length / area * t;
            assert!((mean - expect).abs() < 0.03 * expect, "mean displacement {mean} m, expected ≈ {expect} m");
        }
    }
    // the time split is written for the report
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("platelets.json")).unwrap()).unwrap();
    assert_eq!(j["particles"], 2000);
    assert_eq!(j["sub_steps"], 40);
    for k in ["advection_s", "collisions_s", "coefficients_s"] {
        assert!(j[k].as_f64().unwrap() > 0.0, "{k}: {}", j[k]);
    }
}

#[test]
fn bad_platelet_parameters_are_caught_by_check() {
    let out = std::process::Command::new(bin())
        .arg("check")
        .arg(root().join("launch/stenosis-platelets.toml"))
        .args(["--set", "platelets.dynamics.coeff_every=0", "--set", "platelets.carrier.bump_length=-1.0"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_ne!(out.status.code(), Some(0));
    assert!(err.contains("nodes.platelets.params") && err.contains("bump_length"), "{err}");
}

#[test]
fn five_explicit_platelets_follow_the_ramped_channel_flow() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let out = run_graph("tests/launch/five-platelets.toml", &run, &[]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let r = McapReader::open(&run.join("recording.mcap")).unwrap();
    let msgs: Vec<Vec<u8>> = r
        .messages(&ReadOptions { topics: Some(vec!["platelets".into()]), start_time: None, end_time: None })
        .unwrap()
        .map(|m| m.unwrap().data)
        .collect();
    assert_eq!(msgs.len(), 11);
    let (x0, z0) = (-6e-3, 19e-3);
    let (h, v_in, y0) = (2e-3, 5e-3, 0.5176e-3);
    let s = y0 / h;
    let u0 = 2.0 * v_in * s * (1.0 - s); // the profile at y0, times the ramp t / 1 s
    for (k, m) in msgs.iter().enumerate() {
        let (hd, ps) = cdr::decode::<ParticleSnapshot>(m).unwrap();
        let t = hd.common.t_valid;
        assert!((t - k as f64 * 0.05).abs() < 1e-12, "t = {t}");
        assert_eq!(ps.len(), 5);
        for p in &ps {
            let (x, y) = (p.x as f64 - x0, p.z as f64 - z0);
            // carried along the streamline: x(t) = x(0) + u0 t² / 2 (ramp), y stays (f32: ±4 nm)
            let xs = 1e-3 + 1e-5 * p.id as f64;
            let dx = u0 * t * t / 2.0;
            assert!((x - xs - dx).abs() < 1e-3 * dx + 1e-8, "id {} t {t}: x {x} expected {}", p.id, xs + dx);
            assert!((y - y0).abs() < 1e-8, "id {} t {t}: y {y}", p.id);
            // relaxed onto the flow frozen at the last sub-step's mid time t − τ/2 (m/C_d ~ 10 ns)
            let v = if t == 0.0 { 0.0 } else { u0 * (t - 1.25e-4) };
            assert!((p.vx as f64 - v).abs() < 1e-5 * v + 1e-12, "id {}: vx {} vs {v}", p.id, p.vx);
            assert!((p.vz as f64).abs() < 1e-9, "id {}: vz {}", p.id, p.vz);
        }
    }
}
