use super::*;

/// The straight tube at a 0.5 mm lattice, constant 0.05 m/s inflow, c = 1 m/s, no relaxation,
/// with the keys of `extra` added (or replaced).
fn tube(extra: serde_json::Value) -> serde_json::Value {
    let mut v = serde_json::json!({
        "geometry": "straight-tube", "dx": 0.5e-3, "relax_iterations": 0,
        "inflow": { "type": "constant", "value": 0.05 },
        "solver": { "c": 1.0 },
    });
    if let (Some(o), Some(e)) = (v.as_object_mut(), extra.as_object()) {
        o.extend(e.clone());
    }
    v
}

fn params(v: serde_json::Value) -> Result<Prepared, String> {
    let p: ProducerParams = serde_json::from_value(v).map_err(|e| e.to_string())?;
    p.prepare().map_err(|e| e.to_string())
}

#[test]
fn amplitudes_are_a_function_of_seed_and_id_with_the_requested_spread() {
    assert_eq!(amplitude(3, 17, 1.0), amplitude(3, 17, 1.0));
    assert_ne!(amplitude(3, 17, 1.0), amplitude(4, 17, 1.0));
    let n = 200_000u64;
    let v: Vec<f64> = (0..n).map(|id| amplitude(1, id, 2.0) as f64).collect();
    let mean = v.iter().sum::<f64>() / n as f64;
    let var = v.iter().map(|a| (a - mean).powi(2)).sum::<f64>() / n as f64;
    // standard errors: mean 2/√n = 0.0045, variance 4·√(2/n) = 0.0126
    assert!(mean.abs() < 0.02, "{mean}");
    assert!((var - 4.0).abs() < 0.06, "{var}");
    let kurt = v.iter().map(|a| (a - mean).powi(4)).sum::<f64>() / n as f64 / (var * var);
    assert!((kurt - 3.0).abs() < 0.1, "Gaussian kurtosis {kurt}");
}

#[test]
fn parameters_are_checked_with_named_fields() {
    let p = params(serde_json::json!({ "dx": 0.3e-3, "schedule": { "n_packets": 1 } })).expect("valid");
    assert!((p.solver.h - 0.36e-3).abs() < 1e-15, "h from h_over_dx");
    let p = params(serde_json::json!({ "dx": 0.3e-3, "solver": { "h": 0.5e-3 } })).expect("valid");
    assert_eq!(p.solver.h, 0.5e-3, "h given");
    let e = params(serde_json::json!({ "geometry": "aorta" })).expect_err("bad preset");
    assert!(e.contains("not a preset"), "{e}");
    let e = params(serde_json::json!({ "solver": { "c": -1.0 } })).expect_err("bad c");
    assert!(e.contains("solver.") && e.contains("`c`"), "{e}");
    let e = params(serde_json::json!({ "solver": { "speed_of_sound": 3.0 } })).expect_err("unknown");
    assert!(e.contains("speed_of_sound"), "{e}");
    let e = params(serde_json::json!({ "solver": { "kernel": "gauss" } })).expect_err("bad kernel");
    assert!(e.contains("kernel") && e.contains("gauss"), "{e}");
    let e = params(serde_json::json!({ "dx": 0.0 })).expect_err("dx");
    assert!(e.starts_with("dx = 0 is out of range"), "{e}");
    let e = params(serde_json::json!({ "inflow": { "type": "cosine", "amplitude": 1.0, "period": -1.0 } }))
        .expect_err("period");
    assert!(e.contains("inflow.period"), "{e}");
    let e = params(serde_json::json!({ "run_until": 0.0, "schedule": { "t_start": 0.5 } })).expect_err("run_until");
    assert!(e.contains("run_until"), "{e}");
    let e = params(serde_json::json!({ "bogus": 1 })).expect_err("unknown key");
    assert!(e.contains("bogus"), "{e}");
    let bad = |v: serde_json::Value| {
        let p: ProducerParams = serde_json::from_value(v).expect("parses");
        p.prepare().expect_err("invalid").field
    };
    assert_eq!(bad(serde_json::json!({ "h_over_dx": 5.0 })), "h_over_dx");
    assert_eq!(bad(serde_json::json!({ "amplitude_sigma": -1.0 })), "amplitude_sigma");
    assert_eq!(bad(serde_json::json!({ "schedule": { "prf": 0.0 } })), "schedule.prf");
    assert_eq!(
        bad(serde_json::json!({ "truth_grid": { "nx": 0, "nz": 1, "x0": 0.0, "z0": 0.0, "dx": 1.0, "dz": 1.0 } })),
        "truth_grid.nx"
    );
    assert_eq!(bad(serde_json::json!({ "solver": { "c": 0.0 } })), "solver.c");
    assert_eq!(bad(serde_json::json!({ "ramp_time": -1.0 })), "ramp_time");
}

#[test]
fn the_scheme_sets_the_stabilising_options_unless_the_solver_table_gives_them() {
    let opts = |v: serde_json::Value| {
        let p = params(v).expect("valid");
        (p.solver.shifting, p.solver.density_diffusion)
    };
    assert_eq!(opts(serde_json::json!({})), (2.0, 0.1), "default: stabilised");
    assert_eq!(opts(serde_json::json!({ "scheme": "stabilised" })), (2.0, 0.1));
    assert_eq!(opts(serde_json::json!({ "scheme": "paper" })), (0.0, 0.0));
    assert_eq!(opts(serde_json::json!({ "scheme": "paper", "solver": { "shifting": 1.0 } })), (1.0, 0.0));
    assert_eq!(opts(serde_json::json!({ "solver": { "density_diffusion": 0.0 } })), (2.0, 0.0));
    let e = params(serde_json::json!({ "scheme": "plain" })).expect_err("unknown scheme");
    assert!(e.contains("unknown variant `plain`, expected `stabilised` or `paper`"), "{e}");
}

#[test]
fn the_launch_files_parameters_parse_with_their_defaults() {
    let carotid: ProducerParams = toml::from_str(
        r#"
geometry = "carotid"
dx = 0.15e-3
inflow = { type = "carotid", peak = 0.39, mean = 0.1875, period = 0.83 }
initial_velocity = "fully-developed"
amplitude_sigma = 1.0
seed = 1
schedule = { prf = 10000.0, packet_size = 32, n_packets = 8, packet_interval = 0.1, t_start = 0.1001 }
truth_grid = { nx = 161, nz = 111, x0 = -0.016, z0 = 0.012, dx = 0.2e-3, dz = 0.2e-3 }
checkpoint_in = "warm.ckpt"
[solver]
c = 5.5
mu = 4e-3
rho0 = 1000.0
shifting = 2.0
density_diffusion = 0.1
integrator = "single-evaluation"
"#,
    )
    .expect("carotid.toml's params");
    let p = carotid.prepare().expect("valid");
    assert_eq!(p.solver.h, 1.2 * 0.15e-3);
    assert_eq!(p.solver.c, 5.5);
    assert_eq!(p.build.relax_iterations, 200);
    assert_eq!(carotid.stats_interval, 0.01);
    assert_eq!(carotid.checkpoint_in, Some(PathBuf::from("warm.ckpt")));
    let d: ProducerParams = serde_json::from_value(serde_json::json!({})).expect("empty table");
    assert_eq!(d, ProducerParams::default());
    assert_eq!(d.geometry, GeometrySpec::Preset("carotid".into()));
    assert_eq!((d.dx, d.h_over_dx, d.amplitude_sigma, d.seed), (0.15e-3, 1.2, 1.0, 0));
    assert_eq!(d.initial_velocity, crate::geometry::InitialVelocity::FullyDeveloped);
}

/// A straight tube through two packets of four frames: the events come in time order (pieces of
/// stepping, frames, the truth between the middle frames), then stepping to `run_until`.
#[test]
fn events_follow_the_schedule_and_the_truth_sits_at_each_packets_mid_time() {
    let prep = params(tube(serde_json::json!({
        "schedule": { "prf": 10000.0, "packet_size": 4, "n_packets": 2, "packet_interval": 0.002, "t_start": 0.001 },
        "truth_grid": { "nx": 9, "nz": 5, "x0": -0.004, "z0": 0.012, "dx": 1e-3, "dz": 4e-3 },
        "stats_interval": 5e-4, "run_until": 0.004, "seed": 3,
    })))
    .expect("valid");
    let mut producer = Producer::new(&prep, true).expect("built");
    assert!(producer.take_log()[0].contains("fluid"));
    let mut outputs = Vec::new();
    let mut stats = Vec::new();
    let mut last_time = 0.0;
    while let Some(ev) = producer.next_event().expect("runs") {
        match ev {
            Event::Advanced { time, stats: s } => {
                assert!(time > last_time);
                last_time = time;
                if let Some(pr) = s {
                    stats.push((time, pr));
                }
            }
            Event::Snapshot(s) => {
                assert_eq!(s.at.t, producer.time());
                let n = s.particles.len();
                assert!(n > 100 && s.particles.amplitude.len() == n && s.dt > 0.0);
                for i in 0..n {
                    assert!(s.particles.x[i] >= s.bbox[0] && s.particles.x[i] <= s.bbox[1]);
                    assert!(s.particles.z[i] >= s.bbox[2] && s.particles.z[i] <= s.bbox[3]);
                    assert_eq!(s.particles.amplitude[i], amplitude(3, s.particles.id[i] as u64, 1.0));
                }
                outputs.push(("frame", s.at.frame_id, s.at.t));
            }
            Event::Truth(f) => {
                assert_eq!(f.t, producer.time());
                assert_eq!(f.truth.vx.len(), 45);
                let inside: usize = f.truth.mask.iter().map(|&m| m as usize).sum();
                assert!(inside > 0 && inside < 45, "{inside}");
                for i in 0..45 {
                    if f.truth.mask[i] == 0 {
                        assert_eq!((f.truth.vx[i], f.truth.vz[i]), (0.0, 0.0));
                    }
                }
                outputs.push(("truth", f.frame_id, f.t));
            }
        }
    }
    let kinds: Vec<(&str, u64)> = outputs.iter().map(|o| (o.0, o.1)).collect();
    let f = |id| ("frame", id);
    assert_eq!(kinds, [f(0), f(1), ("truth", 2), f(2), f(3), f(4), f(5), ("truth", 6), f(6), f(7)]);
    assert_eq!(producer.time(), 0.004, "ends on run_until");
    assert_eq!(producer.last_frame_time(), outputs[9].2);
    // diagnostics instants every 0.5 ms from the start (t = 0); the pieces before the first frame
    // (1 ms) pass three of them at once, so the next three pieces report (catching up); progress in
    // 0.1 ms of simulated time
    let times: Vec<Real> = stats.iter().map(|s| s.0).collect();
    let expected = [0.001, 0.0011, 0.00115, 0.0015, 0.002, 0.0025, 0.003, 0.0035, 0.004];
    assert_eq!(times.len(), expected.len(), "{stats:?}");
    for (t, e) in times.iter().zip(expected) {
        assert!((t - e).abs() < 1e-12, "{stats:?}");
    }
    assert_eq!(stats[0].1, Progress { done: 10, total: 40 });
    assert_eq!(stats.last().map(|s| s.1), Some(Progress { done: 40, total: 40 }));
    assert!(producer.summary().contains("8 frames"), "{}", producer.summary());
    assert!(producer.write_checkpoint(None).expect("nothing to write").is_none());
}

#[test]
fn a_schedule_before_the_checkpoint_is_refused() {
    let dir = std::env::temp_dir().join(format!("sonoflow-sph-producer-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let base = serde_json::json!({
        "geometry": "straight-tube", "dx": 0.5e-3, "relax_iterations": 0,
        "inflow": { "type": "constant", "value": 0.05 }, "solver": { "c": 1.0 },
        "schedule": { "packet_size": 1, "t_start": 0.0 }, "run_until": 0.0005, "checkpoint_out": "a.ckpt",
    });
    let mut producer = Producer::new(&params(base.clone()).expect("valid"), false).expect("built");
    while producer.next_event().expect("runs").is_some() {}
    let path = producer.write_checkpoint(Some(&dir)).expect("written").expect("a path");
    assert_eq!(path, dir.join("a.ckpt"));
    let mut resumed = base;
    resumed["checkpoint_in"] = serde_json::json!(path);
    resumed["run_until"] = serde_json::json!(0.001);
    resumed["schedule"]["t_start"] = serde_json::json!(0.0006);
    let mut producer = Producer::new(&params(resumed.clone()).expect("valid"), false).expect("resumed");
    assert_eq!(producer.time(), 0.0005);
    assert!(producer.take_log().iter().any(|l| l.starts_with("resumed from")));
    resumed["schedule"]["t_start"] = serde_json::json!(0.0001);
    let e = Producer::new(&params(resumed).expect("valid"), false).err().expect("refused");
    assert!(e.to_string().contains("before the solver's start time"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

/// Tissue around an SPH vessel (the straight tube: 8 mm wide along x at 20 mm depth, ends at
/// x = ±20 mm): outside the lumen and beside its straight extensions only, ids from 2³¹, the wall
/// layer 10 dB brighter, and the wall pulsation moves each scatterer across the axis by
/// A·w(t)·e^(−d/λ) (d = |z − 20 mm| − 4 mm, computed here), away from the lumen.
#[test]
fn tissue_surrounds_the_sph_lumen_and_its_wall_pulsates() {
    let prep = params(tube(serde_json::json!({
        "schedule": { "prf": 10000.0, "packet_size": 4, "n_packets": 2, "packet_interval": 0.1, "t_start": 0.0 },
        "tissue": { "region": [-0.03, 0.03, 0.01, 0.03], "density_per_mm2": 3.0,
                    "pulsation": { "amplitude": 0.4e-3, "period": 0.2, "decay_length": 2e-3 } },
    })))
    .expect("valid");
    let mut producer = Producer::new(&prep, false).expect("built");
    assert!(producer.take_log().iter().any(|l| l.contains("tissue") && l.contains("pulsating")));
    let mut rest: Option<Scatterers> = None;
    let mut frames = 0;
    while let Some(ev) = producer.next_event().expect("runs") {
        let Event::Snapshot(s) = ev else { continue };
        frames += 1;
        assert!(s.tissue_moves);
        let ts = &s.tissue;
        // 60 × 20 mm² minus the lumen band (60 × 8 mm²) at 3 per mm²: 2160 ± 4σ
        assert!((ts.len() as f64 - 2160.0).abs() < 4.0 * 2160f64.sqrt(), "{}", ts.len());
        assert!(ts.id.iter().all(|&id| id >= TISSUE_FIRST_ID));
        let r = rest.get_or_insert_with(|| ts.clone()); // t = 0: w = 0, the rest positions
        let phase = std::f64::consts::TAU * s.at.t / 0.2;
        let w = 0.5 * (1.0 - phase.cos());
        for i in 0..ts.len() {
            let (x0, z0) = (f64::from(r.x[i]), f64::from(r.z[i]));
            let d = (z0 - 0.02).abs() - 4e-3;
            assert!(d > 0.0, "tissue in the lumen or its extension at ({x0}, {z0})");
            let shift = w * 0.4e-3 * (-d / 2e-3).exp() * (z0 - 0.02).signum();
            let (x, z) = (f64::from(ts.x[i]), f64::from(ts.z[i]));
            assert!((x - x0).abs() < 1e-8 && (z - z0 - shift).abs() < 1e-8, "scatterer {i} at t = {}", s.at.t);
        }
        if frames == 1 {
            let (mut wall, mut deep) = (Vec::new(), Vec::new());
            for i in 0..ts.len() {
                let d = (f64::from(ts.z[i]) - 0.02).abs() - 4e-3;
                let a2 = f64::from(ts.amplitude[i]).powi(2);
                if d <= 0.6e-3 {
                    wall.push(a2)
                } else {
                    deep.push(a2)
                }
            }
            let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
            let db = 10.0 * (mean(&wall) / mean(&deep)).log10();
            assert!((db - 10.0).abs() < 2.5, "wall layer {db:.1} dB above the tissue ({} scatterers)", wall.len());
        }
    }
    assert_eq!(frames, 8);
}

/// `pulsation.waveform = "inflow"`: the wall follows the scene's inflow waveform scaled to [0, 1]
/// over its cycle, delayed by t₀ (here the carotid waveform, t₀ = 5 ms): each scatterer sits at
/// its rest position + w(t)·A·e^(−d/λ) across the axis, and its velocity is the rate of that,
/// checked against a central difference of the waveform (not its analytic derivative). A constant
/// inflow has no pulse to follow: a clear error naming the field.
#[test]
fn the_wall_can_follow_the_inflow_waveform() {
    let inflow = serde_json::json!({ "type": "carotid", "peak": 0.1, "mean": 0.05, "period": 0.83 });
    let prep = params(tube(serde_json::json!({
        "inflow": inflow.clone(),
        "schedule": { "prf": 10000.0, "packet_size": 2, "n_packets": 3, "packet_interval": 0.015, "t_start": 0.0 },
        "tissue": { "region": [-0.01, 0.01, 0.012, 0.028], "density_per_mm2": 1.0,
                    "pulsation": { "amplitude": 0.4e-3, "decay_length": 2e-3, "t0": 0.005, "waveform": "inflow" } },
    })))
    .expect("valid");
    let u: crate::waveform::WaveformSpec = serde_json::from_value(inflow).expect("spec");
    let u = u.build().expect("waveform");
    let (lo, hi) = u.range();
    let w = |t: f64| (u.value(t - 0.005) - lo) / (hi - lo);
    let mut producer = Producer::new(&prep, false).expect("built");
    let (mut rest, mut frames) = (None, 0);
    while let Some(ev) = producer.next_event().expect("runs") {
        let Event::Snapshot(s) = ev else { continue };
        frames += 1;
        let ts = &s.tissue;
        let t = s.at.t;
        let r: &Scatterers = rest.get_or_insert_with(|| {
            // undo the first frame's displacement to get the rest positions
            let mut r = ts.clone();
            for i in 0..r.len() {
                let z = f64::from(ts.z[i]);
                let side = (z - 0.02).signum();
                // d from the displaced position: solve z = z0 + w A e^{-d/λ} side with d = |z0 − 20 mm| − 4 mm
                let mut z0 = z;
                for _ in 0..50 {
                    let d = (z0 - 0.02).abs() - 4e-3;
                    z0 = z - w(t) * 0.4e-3 * (-d / 2e-3).exp() * side;
                }
                r.z[i] = z0 as f32;
            }
            r
        });
        let rate = (w(t + 1e-6) - w(t - 1e-6)) / 2e-6;
        for i in 0..ts.len() {
            let z0 = f64::from(r.z[i]);
            let d = (z0 - 0.02).abs() - 4e-3;
            let reach = 0.4e-3 * (-d / 2e-3).exp() * (z0 - 0.02).signum();
            let (z, vz) = (f64::from(ts.z[i]), f64::from(ts.vz[i]));
            assert!((z - z0 - w(t) * reach).abs() < 2e-8, "scatterer {i} at t = {t}: z {z}, rest {z0}");
            assert!(
                (vz - rate * reach).abs() < 1e-6 * (1.0 + (rate * reach).abs()),
                "scatterer {i} at t = {t}: vz {vz}"
            );
        }
    }
    assert_eq!(frames, 6);
    let e = Producer::new(
        &params(tube(serde_json::json!({
            "tissue": { "region": [-0.01, 0.01, 0.012, 0.028], "pulsation": { "waveform": "inflow" } },
        })))
        .expect("valid"),
        false,
    )
    .err()
    .expect("refused");
    assert!(e.to_string().contains("tissue.pulsation.waveform"), "{e}");
}

/// `position_seed` moves the scatterers (not only their amplitudes): each sits at its particle
/// plus a fixed offset uniform in [−dx/2, dx/2)² (mean |offset| ≈ 0.38 dx); another seed gives
/// other offsets, the same seed the same ones, the SPH solution is untouched, and the scatterer
/// moves with its particle (the offset is the same in every frame).
#[test]
fn position_seeds_move_the_scatterers() {
    let run = |seed: Option<u64>| {
        let mut v = tube(serde_json::json!({
            "schedule": { "prf": 10000.0, "packet_size": 2, "n_packets": 1, "t_start": 0.001 },
        }));
        if let Some(s) = seed {
            v["position_seed"] = serde_json::json!(s);
        }
        let prep = params(v).expect("valid");
        let mut producer = Producer::new(&prep, false).expect("built");
        let mut frames = Vec::new();
        while let Some(ev) = producer.next_event().expect("runs") {
            if let Event::Snapshot(s) = ev {
                frames.push(s.particles);
            }
        }
        frames
    };
    let (lattice, a, b, a2) = (run(None), run(Some(1)), run(Some(2)), run(Some(1)));
    assert_eq!(a, a2, "the same seed, the same positions");
    let dx = 0.5e-3;
    for (f, (l, p)) in lattice.iter().zip(&a).enumerate() {
        assert_eq!((&l.id, &l.vx, &l.amplitude), (&p.id, &p.vx, &p.amplitude), "only the positions change");
        let mut mean = 0.0;
        for i in 0..l.len() {
            let o = scatterer_offset(1, u64::from(l.id[i]), dx);
            let (ox, oz) = (f64::from(p.x[i] - l.x[i]), f64::from(p.z[i] - l.z[i]));
            assert!((ox - o[0]).abs() < 1e-8 && (oz - o[1]).abs() < 1e-8, "frame {f}, particle {i}");
            assert!(o[0].abs() <= 0.5 * dx && o[1].abs() <= 0.5 * dx);
            mean += o[0].hypot(o[1]) / l.len() as f64;
        }
        // E|offset| for a uniform square of side dx: 0.3826 dx; ±0.02 dx is > 5 standard errors here.
        assert!((mean / dx - 0.3826).abs() < 0.02, "mean offset {:.4} dx", mean / dx);
    }
    let differ = a[0].x.iter().zip(&b[0].x).filter(|(p, q)| p != q).count();
    assert!(differ > a[0].len() * 9 / 10, "another seed moves the scatterers ({differ} of {})", a[0].len());
}

/// Bulk motion moves the whole SPH scene rigidly: (1) a pure translation by (2, 1) truth-grid
/// steps at the sine's peak (the rate is zero there) shifts the truth field and its mask by
/// exactly those nodes; (2) with a rotation, every blood scatterer sits at c + R(θ)(p − c) + d and
/// moves at R v + ω × R(p − c) + ḋ (computed here independently of `Rigid`) to f32 rounding, and
/// the tissue is published as moving.
#[test]
fn bulk_motion_moves_the_sph_scene_rigidly() {
    let (g, step) =
        (serde_json::json!({ "nx": 21, "nz": 21, "x0": -0.005, "z0": 0.015, "dx": 0.5e-3, "dz": 0.5e-3 }), 0.5e-3);
    let schedule = serde_json::json!({ "prf": 10000.0, "packet_size": 2, "n_packets": 1, "t_start": 0.0 });
    let sched: Schedule = serde_json::from_value(schedule.clone()).expect("schedule");
    let t_mid = sched.packet_mid_time(0);
    let run = |bulk: serde_json::Value, tissue: bool| {
        let mut extra = serde_json::json!({ "schedule": schedule.clone(), "truth_grid": g.clone() });
        if !bulk.is_null() {
            extra["bulk"] = bulk;
        }
        if tissue {
            extra["tissue"] = serde_json::json!({ "region": [-0.01, 0.01, 0.012, 0.028], "density_per_mm2": 1.0 });
        }
        let mut producer = Producer::new(&params(tube(extra)).expect("valid"), true).expect("built");
        let (mut snaps, mut truth) = (Vec::new(), None);
        while let Some(ev) = producer.next_event().expect("runs") {
            match ev {
                Event::Snapshot(s) => snaps.push(*s),
                Event::Truth(t) => truth = Some(t.truth),
                _ => {}
            }
        }
        (snaps, truth.expect("a truth field"))
    };
    let (still, t0) = run(serde_json::Value::Null, false);
    let period = 1.0;
    let shifted = serde_json::json!({ "amplitude": [2.0 * step, step], "period": period, "t0": t_mid - period / 4.0 });
    let (_, t1) = run(shifted, false);
    let mut inside = 0;
    for iz in 0..20 {
        for ix in 0..19 {
            let (a, b) = (iz * 21 + ix, (iz + 1) * 21 + ix + 2);
            assert_eq!(t0.mask[a], t1.mask[b], "mask at node ({ix}, {iz})");
            assert!((t0.vx[a] - t1.vx[b]).abs() < 1e-6 && (t0.vz[a] - t1.vz[b]).abs() < 1e-6, "node ({ix}, {iz})");
            inside += usize::from(t0.mask[a]);
        }
    }
    assert!(inside > 100, "{inside} lumen nodes compared");

    let (theta_hat, c, a) = (5f64.to_radians(), [0.0, 0.02], [1e-3, 0.5e-3]);
    let turning = serde_json::json!({ "amplitude": a, "rotation_deg": 5.0, "center": c, "period": period, "t0": 0.0 });
    let (moved, _) = run(turning, true);
    assert!(moved.iter().all(|s| s.tissue_moves), "tissue under bulk motion is simulated in every frame");
    for (s0, s1) in still.iter().zip(&moved) {
        let t = s0.at.t;
        let k = 2.0 * std::f64::consts::PI / period;
        let (th, om) = (theta_hat * (k * t).sin(), theta_hat * k * (k * t).cos());
        let (d, dd) =
            ([a[0] * (k * t).sin(), a[1] * (k * t).sin()], [a[0] * k * (k * t).cos(), a[1] * k * (k * t).cos()]);
        let (p, q) = (&s0.particles, &s1.particles);
        assert_eq!(p.id, q.id);
        for i in 0..p.id.len() {
            let (rx, rz) = (f64::from(p.x[i]) - c[0], f64::from(p.z[i]) - c[1]);
            let (rrx, rrz) = (th.cos() * rx - th.sin() * rz, th.sin() * rx + th.cos() * rz);
            let (vx, vz) = (f64::from(p.vx[i]), f64::from(p.vz[i]));
            let x = c[0] + rrx + d[0];
            let z = c[1] + rrz + d[1];
            let ux = th.cos() * vx - th.sin() * vz - om * rrz + dd[0];
            let uz = th.sin() * vx + th.cos() * vz + om * rrx + dd[1];
            assert!(
                (f64::from(q.x[i]) - x).abs() < 1e-8 && (f64::from(q.z[i]) - z).abs() < 1e-8,
                "scatterer {i} at {t}"
            );
            assert!(
                (f64::from(q.vx[i]) - ux).abs() < 1e-6 && (f64::from(q.vz[i]) - uz).abs() < 1e-6,
                "scatterer {i} at {t}"
            );
        }
    }
    let Err(e) = params(tube(serde_json::json!({ "bulk": { "rotation_deg": 30.0 } }))) else {
        panic!("a 30° rotation is refused")
    };
    assert!(e.contains("bulk.rotation_deg"), "{e}");
}
