//! Tests of the suspension driver.
#![allow(clippy::unwrap_used)]
use super::*;
use std::cell::RefCell;
use std::collections::VecDeque;

thread_local! {
    static LOG: RefCell<Vec<String>> = const { RefCell::new(Vec::new()) };
}
fn log(line: &str) {
    LOG.with(|l| l.borrow_mut().push(line.to_string()));
}
fn take_log() -> Vec<String> {
    LOG.with(|l| std::mem::take(&mut *l.borrow_mut()))
}
fn hooks() -> Hooks {
    Hooks { log, ..Default::default() }
}

fn parse(v: serde_json::Value) -> PlateletsParams {
    let p: PlateletsParams = serde_json::from_value(v).unwrap();
    p.validate().unwrap();
    p
}

/// A scripted fluid stream: these snapshots, then `then` for ever.
struct Script {
    snaps: VecDeque<FluidSnapshot>,
    then: Received,
    reads: usize,
}

impl FluidSource for Script {
    type Error = DriverError;
    fn next(&mut self, into: &mut FluidSnapshot) -> Result<Received, DriverError> {
        self.reads += 1;
        let Some(s) = self.snaps.pop_front() else { return Ok(self.then) };
        (into.t, into.frame_id) = (s.t, s.frame_id);
        into.pos.extend(s.pos);
        into.vel.extend(s.vel);
        Ok(Received::Snapshot)
    }
    fn name(&self) -> String {
        "fluid".into()
    }
}

/// Plug flow `u` (channel axes) on a jittered 0.4 mm lattice over the 12 mm × 8 mm channel,
/// given in imaging coordinates of `map` as a source would.
fn plug(map: FrameMap, t: f64, frame_id: u64, u: [f64; 2]) -> FluidSnapshot {
    let mut s = FluidSnapshot { t, frame_id, ..Default::default() };
    for j in 0..20 {
        for i in 0..30 {
            let jitter = 0.1 * (((i * 7 + j * 13) % 5) as f64 - 2.0);
            let p = [(i as f64 + 0.5 + jitter) * 4e-4, (j as f64 + 0.5 - jitter) * 4e-4];
            s.pos.push(map.to_imaging(p));
            s.vel.push(map.vel_to_imaging(u));
        }
    }
    s
}

fn fluid_params(origin: [f64; 2], angle_deg: f64, n_macro_steps: u64) -> PlateletsParams {
    parse(serde_json::json!({
        "carrier": { "type": "particles", "lattice": { "origin": [2e-3, -0.5e-3], "h": 1e-4, "nx": 61, "ny": 91 },
                     "kernel_h": 4.8e-4, "walls": [0.0, 8e-3] },
        "particles": { "count": 40 }, "model": "standin",
        "dynamics": { "sub_step": 2.5e-5, "sub_steps": 20 },
        "n_macro_steps": n_macro_steps, "origin": origin, "angle_deg": angle_deg
    }))
}

#[test]
fn fluid_particles_come_back_into_the_channel_frame_with_the_inverse_mapping() {
    let op = OutputParams { origin: [-6e-3, 19e-3], angle_deg: 25.0, ..Default::default() };
    let m = FrameMap::new(&op);
    let (p, v) = ([3e-3, 0.7e-3], [0.02, -0.004]);
    let q = m.to_imaging(p);
    let w = m.vel_to_imaging(v);
    // rotated by +25° towards +z: the channel x axis points down-right in the image
    let a = 25f64.to_radians();
    assert!((q[0] - (-6e-3 + a.cos() * 3e-3 - a.sin() * 0.7e-3)).abs() < 1e-18);
    assert!((q[1] - (19e-3 + a.sin() * 3e-3 + a.cos() * 0.7e-3)).abs() < 1e-18);
    let (pb, vb) = (m.to_channel(q), m.vel_to_channel(w));
    for k in 0..2 {
        assert!((pb[k] - p[k]).abs() < 1e-17 && (vb[k] - v[k]).abs() < 1e-17, "{pb:?} {vb:?}");
    }
}

#[test]
fn params_split_validate_and_name_the_field() {
    let v = serde_json::json!({ "carrier": { "type": "stenosis" }, "particles": { "count": 10 }, "n_macro_steps": 2, "origin": [0.0, 0.02] });
    let p = parse(v);
    assert_eq!(p.suspension.count(), 10);
    assert_eq!((p.output.n_macro_steps, p.output.n_snapshots()), (2, 3));
    assert_eq!(p.output.origin, [0.0, 0.02]);
    // the same table back
    let back: PlateletsParams = serde_json::from_value(serde_json::to_value(&p).unwrap()).unwrap();
    assert_eq!(back, p);
    assert_eq!(serde_json::from_value::<PlateletsParams>(serde_json::Value::Null).unwrap(), PlateletsParams::default());
    let invalid = |v: serde_json::Value| {
        serde_json::from_value::<PlateletsParams>(v).unwrap().validate().unwrap_err().to_string()
    };
    let e = invalid(serde_json::json!({ "publish_every": 3, "n_macro_steps": 2 }));
    assert_eq!(e, "publish_every = 3 is out of range: 1 ..= 2");
    assert_eq!(invalid(serde_json::json!({ "n_macro_steps": 0 })), "n_macro_steps = 0 is out of range: 1 ..= 1000000");
    assert_eq!(invalid(serde_json::json!({ "origin": [0.0, 2.0] })), "origin[1] = 2 is out of range: -1 ..= 1 m");
    assert_eq!(invalid(serde_json::json!({ "angle_deg": 400.0 })), "angle_deg = 400 is out of range: -360 ..= 360");
    let e = invalid(serde_json::json!({ "amplitude_sigma": 0.0 }));
    assert_eq!(e, "amplitude_sigma = 0 is out of range: 0 < amplitude_sigma <= 1e6");
    assert!(invalid(serde_json::json!({ "carrier": { "type": "stenosis", "narrowing": 2.0 } })).contains("`narrowing`"));
    assert!(invalid(serde_json::json!({ "weights": "/nonexistent" })).contains("`weights`"));
    // deserialisation errors carry the path of the field
    let bad = |v: serde_json::Value| serde_json::from_value::<PlateletsParams>(v).unwrap_err().to_string();
    for (v, want) in [
        (serde_json::json!({ "particles": { "count": 10 }, "bogus": 1 }), "bogus: unknown field `bogus`"),
        (serde_json::json!({ "carrier": { "type": "pipe" } }), "carrier.type: unknown variant `pipe`"),
        (
            serde_json::json!({ "carrier": { "type": "stenosis", "narowing": 0.3 } }),
            "carrier: unknown field `narowing`",
        ),
        (serde_json::json!({ "origin": [0.0] }), "origin: invalid length 1"),
        (serde_json::json!({ "dynamics": { "sub_steps": "x" } }), "dynamics.sub_steps: invalid type"),
    ] {
        let e = bad(v);
        assert!(e.starts_with(want), "{e}");
    }
}

#[test]
fn the_particles_carrier_and_the_fluid_input_go_together() {
    let sph = serde_json::json!({ "carrier": { "type": "particles" } });
    check_fluid_input(&sph, true).unwrap();
    assert!(check_fluid_input(&sph, false).unwrap_err().contains("needs the input `particles`"));
    check_fluid_input(&serde_json::json!({ "carrier": { "type": "shear" } }), false).unwrap();
    let e = check_fluid_input(&serde_json::json!({ "carrier": { "type": "shear" } }), true).unwrap_err();
    assert!(e.contains("carrier type \"shear\" does not read it"), "{e}");
    let e = check_fluid_input(&serde_json::Value::Null, true).unwrap_err();
    assert!(e.contains("\"stenosis\" (the default)"), "{e}");
}

/// An analytic carrier: the initial state and every `publish_every`-th macro step, each platelet
/// once with its amplitude, inside the bounding box; the report counts the steps.
#[test]
fn analytic_schedule_gives_frames_and_states() {
    let p = parse(serde_json::json!({
        "particles": { "count": 50 }, "model": "standin", "n_macro_steps": 4, "publish_every": 2, "angle_deg": 20.0
    }));
    let mut none = Script { snaps: VecDeque::new(), then: Received::Ended, reads: 0 };
    let mut d = Driver::new(p.clone(), hooks(), &mut none).unwrap().unwrap();
    let f0 = d.initial().unwrap();
    assert_eq!(f0, Frame { frame_id: 0, t: 0.0, compute_ns: 0 });
    let k = d.suspension().macro_step_length();
    let mut frames = vec![];
    while !d.done() {
        frames.push(d.step(&mut none).unwrap());
    }
    assert_eq!(none.reads, 0, "an analytic carrier reads no fluid");
    assert_eq!(frames.len(), 4);
    assert!(frames[0].is_none() && frames[2].is_none());
    let (f1, f2) = (frames[1].unwrap(), frames[3].unwrap());
    assert_eq!((f1.frame_id, f2.frame_id, d.params().output.n_snapshots()), (1, 2, 3));
    assert!((f1.t - 2.0 * k).abs() < 1e-15 && (f2.t - 4.0 * k).abs() < 1e-15 && f2.t == d.time());
    let [x0, x1, z0, z1] = d.bbox();
    let mut ids: Vec<u32> = d.states().map(|s| s.id).collect();
    ids.sort_unstable();
    assert_eq!(ids, (0..50).collect::<Vec<_>>());
    let again = Driver::new(p, hooks(), &mut none).unwrap().unwrap();
    for s in d.states() {
        assert!(s.x >= x0 && s.x <= x1 && s.z >= z0 && s.z <= z1, "{s:?}");
        let a = again.states().find(|a| a.id == s.id).unwrap().amplitude;
        assert!(s.amplitude == a && s.amplitude != 0.0 && s.amplitude.is_finite());
    }
    let r = d.finish(0);
    assert_eq!((r.particles, r.macro_steps, r.sub_steps, r.model.as_str()), (50, 4, 4 * 20, "disc-standin"));
    assert!(r.fluid.is_none() && !serde_json::to_string(&r).unwrap().contains("fluid"));
    let log = take_log();
    assert!(log.iter().any(|l| l.starts_with("t = ") && l.contains("(macro step 4/4)")), "{log:?}");
    assert!(log.iter().any(|l| l.starts_with("4 macro steps of 50 platelets")), "{log:?}");
}

/// The macro step [t, t + k] uses the latest snapshot with time ≤ t + k: finer snapshots are
/// skipped, a coarser one carries two steps, the last one the steps after the stream ends
/// (said once); the fluid arrives in imaging coordinates and the platelets leave in them.
#[test]
fn fluid_snapshots_pair_with_macro_steps_by_time() {
    let (origin, angle) = ([-4e-3, 16e-3], 25.0);
    let p = fluid_params(origin, angle, 5);
    let map = FrameMap::new(&p.output);
    let k = 5e-4;
    let times = [0.1, 0.1 + 0.5 * k, 0.1 + k, 0.1 + 3.0 * k];
    let snaps = times.iter().enumerate().map(|(i, &t)| plug(map, t, i as u64, [0.01 * (i + 1) as f64, 0.0]));
    let mut src = Script { snaps: snaps.collect(), then: Received::Ended, reads: 0 };
    take_log();
    let mut d = Driver::new(p, hooks(), &mut src).unwrap().unwrap();
    assert_eq!((src.reads, d.time()), (1, 0.1));
    let check_speed = |d: &Driver, u: f64| {
        let want = map.vel_to_imaging([u, 0.0]);
        for s in d.states() {
            let e = (s.vx as f64 - want[0]).hypot(s.vz as f64 - want[1]);
            assert!(e < 1e-6 * u, "id {}: ({}, {}) against {want:?}", s.id, s.vx, s.vz);
        }
    };
    check_speed(&d, 0.01);
    // step 1 (to 0.1 + k): snapshots 1 and 2, one fill with 2; snapshot 3 read and kept
    assert!(d.step(&mut src).unwrap().is_some());
    assert_eq!(src.reads, 4);
    // the platelets relax within a sub-step: they move with the snapshot of the step
    check_speed(&d, 0.03);
    d.step(&mut src).unwrap(); // to 0.1 + 2k: still snapshot 2
    check_speed(&d, 0.03);
    d.step(&mut src).unwrap(); // to 0.1 + 3k: snapshot 3, then the end of the stream
    check_speed(&d, 0.04);
    assert_eq!(src.reads, 5);
    d.step(&mut src).unwrap();
    d.step(&mut src).unwrap();
    assert!(d.done());
    d.drain(&mut src).unwrap();
    assert_eq!(src.reads, 5, "the stream has ended");
    let r = d.finish(5).fluid.unwrap();
    assert_eq!((r.snapshots_received, r.lattice_fills, r.first_t, r.last_used_t), (5, 3, 0.1, times[3]));
    let log = take_log();
    let filled: Vec<&String> = log.iter().filter(|l| l.contains("fluid snapshot")).collect();
    assert!(filled[0].starts_with("seeded in fluid snapshot 0 (t = 0.100000 s): 600 fluid particles"), "{filled:?}");
    assert!(
        filled[1].starts_with("macro step to fluid snapshot 2 ")
            && filled[2].starts_with("macro step to fluid snapshot 3 ")
    );
    assert_eq!(log.iter().filter(|l| l.starts_with("the fluid stream ended")).count(), 1, "{log:?}");
    assert_eq!(log.iter().filter(|l| l.starts_with("lattice fills")).count(), 5);
}

#[test]
fn a_stopped_or_bad_fluid_stream() {
    let p = fluid_params([0.0, 0.0], 0.0, 3);
    let map = FrameMap::new(&p.output);
    let script = |snaps: Vec<FluidSnapshot>, then| Script { snaps: snaps.into(), then, reads: 0 };
    // stopped before the first snapshot: nothing to run
    assert!(Driver::new(p.clone(), hooks(), &mut script(vec![], Received::Stopped)).unwrap().is_none());
    // stopped while waiting for the second: done, and draining reads nothing more
    let mut src = script(vec![plug(map, 0.0, 0, [0.01, 0.0])], Received::Stopped);
    let mut d = Driver::new(p.clone(), hooks(), &mut src).unwrap().unwrap();
    assert!(d.step(&mut src).unwrap().is_none() && d.done());
    d.drain(&mut src).unwrap();
    assert_eq!(src.reads, 2);
    assert_eq!(d.finish(1).macro_steps, 0);
    // errors name the stream
    let e = Driver::new(p.clone(), hooks(), &mut script(vec![], Received::Ended)).err().unwrap().to_string();
    assert_eq!(e, "the fluid stream on `fluid` ended before its first snapshot");
    let e = Driver::new(p.clone(), hooks(), &mut script(vec![plug(map, f64::NAN, 4, [0.0; 2])], Received::Ended));
    assert_eq!(e.err().unwrap().to_string(), "fluid snapshot 4 on `fluid` has t_valid = NaN");
    let empty = FluidSnapshot { t: 0.5, frame_id: 2, ..Default::default() };
    let e = Driver::new(p, hooks(), &mut script(vec![empty], Received::Ended)).err().unwrap().to_string();
    assert!(e.starts_with("fluid snapshot 2 (t = 0.5 s) on `fluid` has no particles of kind PARTICLE_FLUID"), "{e}");
    take_log();
}
