//! Analytic flow, MCAP and launch-file cases (from `nodes/analytic-flow/src/tests.rs`,
//! `nodes/mcap-io/tests/truncation.rs` and `errors.rs`, `tests/failures.rs`; the recording and the
//! launch files from the `testkit` modules of `sonoflow-mcap-io` and `sonoflow-launcher`).

use super::{Case, CaseResult, Check, Ctx, Expected, OrMessage, Stage};
use sonoflow_analytic_flow::{AnalyticFlow, AnalyticFlowParams, FlowKind, GridSpec, Schedule};
use sonoflow_launcher::launch::{self, Overrides};
use sonoflow_launcher::testkit::{self as launch_kit, MINIMAL_GRAPH};
use sonoflow_mcap_io::testkit::{finished_recording, first_mismatch, read_and_recover, Damaged, FinishedRecording};
use sonoflow_mcap_io::{McapIoError, McapReader, ReadOptions, RecorderWriter, WriterOptions};
use std::path::Path;

pub(super) fn cases() -> Vec<Case> {
    vec![
        Stage::AnalyticFlow.case(
            "advance-a-million-seconds",
            "a Poiseuille vessel at the speed limit v_max = 100 m/s advanced to t = 1e6 s (2.5e9 vessel lengths) and a \
             disk at the omega limit 1e5 rad/s to 1e6 s (1e11 rad); check: every scatterer stays in the vessel at its \
             radius / on its circle, velocities = the field at the new position, finite",
            Expected::Pass,
            advance_far,
        ),
        Stage::AnalyticFlow.case(
            "invalid-truth-grid",
            "a ground-truth grid with nx = 0",
            Expected::ClearError(&["grid.nx", ">= 1"]),
            invalid_grid,
        ),
        Stage::AnalyticFlow.case(
            "overlapping-packets",
            "3 packets of 8 frames at 5 kHz (1.6 ms each) started 1 ms apart",
            Expected::ClearError(&["schedule.packet_interval", "must not overlap"]),
            overlapping,
        ),
        Stage::AnalyticFlow.case(
            "zero-scatterers",
            "a density of 1e-4 per mm² in a 240 mm² vessel: rounds to no scatterer",
            Expected::ClearError(&["density_per_mm2", "at least 1 scatterer"]),
            no_scatterer,
        ),
        Stage::AnalyticFlow.case(
            "time-backwards-and-nan",
            "advance_to an earlier time, then to NaN; check: both refused, the state unchanged",
            Expected::ClearError(&["goes backwards", "time must be finite"]),
            backwards,
        ),
        Stage::Mcap.case(
            "truncated-mid-chunk",
            "a finished recording cut in the middle of its last chunk (power loss, copy cut short); check: the \
             linear read returns exactly the messages of the complete chunks, recover writes a complete file with them",
            Expected::Pass,
            truncated,
        ),
        Stage::Mcap.case(
            "zeroed-tail",
            "the last chunk and everything after it overwritten with zeros; check: as above",
            Expected::Pass,
            zeroed,
        ),
        Stage::Mcap.case(
            "corrupt-last-chunk",
            "64 flipped bytes inside the last chunk of an unfinished file (its CRC fails); check: as above",
            Expected::Pass,
            corrupt,
        ),
        Stage::Mcap.case(
            "header-only",
            "a file cut 5 bytes after its header (no chunk survives); check: 0 messages read and recovered, no error",
            Expected::Pass,
            header_only,
        ),
        Stage::Mcap.case(
            "not-an-mcap",
            "a text file and an empty file opened as recordings",
            Expected::ClearError(&["is not an MCAP file"]),
            not_mcap,
        ),
        Stage::Mcap.case(
            "refuses-to-overwrite",
            "creating a recording over an existing file (the file must be untouched)",
            Expected::ClearError(&["refusing to overwrite"]),
            overwrite,
        ),
        Stage::Launch.case(
            "good-file",
            "a minimal valid launch file (source → checker); check: it resolves",
            Expected::Pass,
            good_launch,
        ),
        Stage::Launch.case(
            "unknown-key",
            "a misspelt key in [graph]",
            Expected::ClearError(&["unknown field `colour`"]),
            unknown_key,
        ),
        Stage::Launch.case(
            "dangling-input-and-type-mismatch",
            "an input wired to a topic of the wrong type that nobody produces: both problems reported at once",
            Expected::ClearError(&[
                "carries RfFrameV3 but topic `iq` is IqFrameV3",
                "topic `iq` is consumed by checker but no node produces it",
            ]),
            dangling,
        ),
        Stage::Launch.case(
            "out-of-range-params",
            "n_channels = 0 and max_elements = 0 together: one error each",
            Expected::ClearError(&["n_channels = 0 is out of range: 1 ..= 1024", "topics.rf.max_elements = 0 is out of range"]),
            out_of_range,
        ),
        Stage::Launch.case(
            "two-producers",
            "two nodes publishing the same topic",
            Expected::ClearError(&["topic `rf` has 2 producers"]),
            two_producers,
        ),
        Stage::Launch.case(
            "bad-set-and-swap",
            "--set on a missing node and --swap to a missing variant",
            Expected::ClearError(&["no node `nosuch`", "node `source` has no variant `fast`"]),
            bad_overrides,
        ),
        Stage::Launch.case(
            "toml-syntax-error",
            "an unclosed table header",
            Expected::ClearError(&["TOML parse error"]),
            toml_syntax,
        ),
    ]
}

// ---- analytic flow --------------------------------------------------------------------------

fn advance_far(_: &Ctx) -> CaseResult {
    let (cx, cz, ang, dia, len) = (0.001, 0.025, 20.0f64, 6e-3, 0.04);
    let pipe = AnalyticFlowParams {
        flow: FlowKind::Poiseuille {
            center_x: cx,
            center_z: cz,
            angle_deg: ang,
            diameter: dia,
            v_max: 100.0,
            length: len,
        },
        density_per_mm2: 5.0,
        ..AnalyticFlowParams::default()
    };
    let mut f = AnalyticFlow::new(&pipe).msg()?;
    let (az, ax) = ang.to_radians().sin_cos();
    let local = |x: f32, z: f32| {
        let (dx, dz) = (f64::from(x) - cx, f64::from(z) - cz);
        (dx * ax + dz * az, -dx * az + dz * ax)
    };
    let q0: Vec<f64> = f.particles().x.iter().zip(&f.particles().z).map(|(x, z)| local(*x, *z).1).collect();
    f.advance_to(1e6).msg()?;
    let p = f.particles();
    let (mut worst_q, mut out, mut worst_v) = (0.0f64, 0usize, 0.0f64);
    for (i, q_start) in q0.iter().enumerate() {
        let (s, q) = local(p.x[i], p.z[i]);
        worst_q = worst_q.max((q - q_start).abs());
        if s.abs() > 0.5 * len + 1e-6 || !(p.x[i].is_finite() && p.z[i].is_finite()) {
            out += 1;
        }
        // a scatterer on the wall may round (f32) to just outside the fluid, where there is no field
        if let Some((u, w)) = f.velocity(f64::from(p.x[i]), f64::from(p.z[i])) {
            worst_v = worst_v.max((f64::from(p.vx[i]) - u).abs()).max((f64::from(p.vz[i]) - w).abs());
        }
    }
    let v_finite = p.vx.iter().chain(&p.vz).all(|v| v.is_finite());
    let pipe_ok = out == 0 && v_finite && worst_q < 1e-6 && worst_v < 1e-3 * 100.0;
    let disk = AnalyticFlowParams {
        flow: FlowKind::RotatingDisk { center_x: 0.002, center_z: 0.03, radius: 0.01, omega: 1e5 },
        ..AnalyticFlowParams::default()
    };
    let mut g = AnalyticFlow::new(&disk).msg()?;
    let r0: Vec<f64> = g
        .particles()
        .x
        .iter()
        .zip(&g.particles().z)
        .map(|(x, z)| (f64::from(*x) - 0.002).hypot(f64::from(*z) - 0.03))
        .collect();
    g.advance_to(1e6).msg()?;
    let gp = g.particles();
    let worst_r = (0..gp.len())
        .map(|i| ((f64::from(gp.x[i]) - 0.002).hypot(f64::from(gp.z[i]) - 0.03) - r0[i]).abs())
        .fold(0.0, |a: f64, b| if b.is_nan() { f64::NAN } else { a.max(b) });
    let disk_ok = worst_r < 1e-6;
    Ok(Check::new(
        pipe_ok && disk_ok,
        format!(
            "pipe: {} scatterers, {out} outside, radius drift {worst_q:.1e} m, velocity off by {worst_v:.1e} m/s; disk: {} \
             scatterers, radius drift {worst_r:.1e} m",
            p.len(),
            gp.len()
        ),
    ))
}

fn invalid_grid(_: &Ctx) -> CaseResult {
    let f = AnalyticFlow::new(&AnalyticFlowParams::default()).msg()?;
    let g = GridSpec { nx: 0, nz: 3, x0: 0.0, z0: 0.0, dx: 1e-3, dz: 1e-3 };
    f.try_sample_truth(&g).map(|_| Check::new(true, "sampled a grid without columns")).msg()
}

fn overlapping(_: &Ctx) -> CaseResult {
    let p = AnalyticFlowParams {
        schedule: Schedule { prf: 5e3, packet_size: 8, n_packets: 3, packet_interval: 1e-3, t_start: 0.0 },
        ..AnalyticFlowParams::default()
    };
    AnalyticFlow::new(&p).map(|_| Check::new(true, "accepted overlapping packets")).msg()
}

fn no_scatterer(_: &Ctx) -> CaseResult {
    let p = AnalyticFlowParams { density_per_mm2: 1e-4, ..AnalyticFlowParams::default() };
    AnalyticFlow::new(&p).map(|f| Check::new(true, format!("{} scatterers", f.particles().len()))).msg()
}

fn backwards(_: &Ctx) -> CaseResult {
    let mut f = AnalyticFlow::new(&AnalyticFlowParams::default()).msg()?;
    f.advance_to(0.2).msg()?;
    let snapshot = f.particles().clone();
    let e1 = match f.advance_to(0.15) {
        Ok(()) => return Ok(Check::new(true, "went backwards without error")),
        Err(e) => e.to_string(),
    };
    let e2 = match f.advance_to(f64::NAN) {
        Ok(()) => return Ok(Check::new(false, "advanced to NaN without error")),
        Err(e) => e.to_string(),
    };
    if f.time() != 0.2 || f.particles() != &snapshot {
        return Ok(Check::new(false, "a refused call changed the state"));
    }
    Err(format!("{e1}; {e2}"))
}

// ---- MCAP -----------------------------------------------------------------------------------

/// The testkit's finished recording in its own scratch folder.
fn finished(ctx: &Ctx, name: &str) -> Result<FinishedRecording, String> {
    let dir = ctx.scratch.join(name);
    std::fs::create_dir_all(&dir).msg()?;
    Ok(finished_recording(&dir))
}

/// Reads a damaged copy linearly and recovers it; checks both against the first `want` messages.
fn check_damaged(f: &FinishedRecording, name: &str, bytes: &[u8], want: usize) -> CaseResult {
    let Damaged { reader: r, read: got, stats, recovered } = read_and_recover(f, name, bytes);
    let in_order = first_mismatch(&got, &f.expected).is_none();
    let rr = McapReader::open(&recovered).msg()?;
    let again = rr.messages(&ReadOptions::default()).msg()?.count();
    let ok = !r.is_complete()
        && got.len() == want
        && in_order
        && stats.messages == want as u64
        && rr.is_complete()
        && again == want;
    Ok(Check::new(
        ok,
        format!(
            "read {} of {} messages (expected {want}, the complete chunks), in order and intact: {in_order}; recovered {} \
             into a complete file: {}",
            got.len(),
            f.expected.len(),
            stats.messages,
            rr.is_complete()
        ),
    ))
}

/// The finished recording in the scratch folder `name`, damaged by `damage` (which also says how
/// many messages survive), read linearly and recovered.
fn damaged(ctx: &Ctx, name: &str, damage: fn(&FinishedRecording) -> (Vec<u8>, usize)) -> CaseResult {
    let f = finished(ctx, name)?;
    let (bytes, want) = damage(&f);
    check_damaged(&f, name, &bytes, want)
}

fn truncated(ctx: &Ctx) -> CaseResult {
    damaged(ctx, "truncated", FinishedRecording::cut_in_last_chunk)
}

fn zeroed(ctx: &Ctx) -> CaseResult {
    damaged(ctx, "zeroed", FinishedRecording::zeroed_tail)
}

fn corrupt(ctx: &Ctx) -> CaseResult {
    damaged(ctx, "corrupt", FinishedRecording::corrupt_last_chunk)
}

fn header_only(ctx: &Ctx) -> CaseResult {
    damaged(ctx, "header", |f| (f.bytes[..f.header_end() + 5].to_vec(), 0))
}

fn not_mcap(ctx: &Ctx) -> CaseResult {
    let mut msgs = vec![];
    for (name, content) in [("text.mcap", &b"this is plainly not an MCAP file\n"[..]), ("empty.mcap", &b""[..])] {
        let path = ctx.scratch.join(name);
        std::fs::write(&path, content).msg()?;
        match McapReader::open(&path) {
            Ok(_) => return Ok(Check::new(false, format!("{name} opened as a recording"))),
            Err(e @ McapIoError::NotMcap { .. }) => msgs.push(e.to_string()),
            Err(e) => return Ok(Check::new(false, format!("{name}: wrong error {e}"))),
        }
    }
    Err(msgs.join("; "))
}

fn overwrite(ctx: &Ctx) -> CaseResult {
    let path: &Path = &ctx.scratch.join("precious.mcap");
    std::fs::write(path, b"precious").msg()?;
    let r = RecorderWriter::create(path, WriterOptions::default());
    let untouched = std::fs::read(path).msg()? == b"precious";
    match r {
        Ok(_) => Ok(Check::new(true, "overwrote an existing file")),
        Err(_) if !untouched => Ok(Check::new(false, "refused but the file changed")),
        Err(e) => Err(e.to_string()),
    }
}

// ---- launch files ---------------------------------------------------------------------------

/// What `sonoflow check` does with a launch file's text: parse, resolve, check (nothing starts).
fn check_text(text: &str, set: &[&str], swap: &[&str]) -> CaseResult {
    let ov = Overrides {
        set: set.iter().map(|s| s.to_string()).collect(),
        swap: swap.iter().map(|s| s.to_string()).collect(),
        lenient_files: true,
        ..Default::default()
    };
    let file: launch::LaunchFile = toml::from_str(text).map_err(|e| e.to_string())?;
    match launch::resolve(file, Path::new("."), &ov, sonoflow_builtin::registry()) {
        Ok(g) => Ok(Check::new(true, format!("ok: {} node(s), {} topic(s)", g.nodes.len(), g.topics.len()))),
        Err(errs) => Err(format!("{} problem(s): {}", errs.len(), errs.join("; "))),
    }
}

fn good_launch(_: &Ctx) -> CaseResult {
    check_text(MINIMAL_GRAPH, &[], &[])
}

fn unknown_key(_: &Ctx) -> CaseResult {
    check_text(&launch_kit::unknown_key(), &[], &[])
}

fn dangling(_: &Ctx) -> CaseResult {
    check_text(&launch_kit::dangling_input_and_type_mismatch(), &[], &[])
}

fn out_of_range(_: &Ctx) -> CaseResult {
    check_text(&launch_kit::out_of_range_params(), &[], &[])
}

fn two_producers(_: &Ctx) -> CaseResult {
    check_text(&launch_kit::two_producers(), &[], &[])
}

fn bad_overrides(_: &Ctx) -> CaseResult {
    check_text(MINIMAL_GRAPH, &["nosuch.x=1"], &["source=fast"])
}

fn toml_syntax(_: &Ctx) -> CaseResult {
    check_text(launch_kit::TOML_SYNTAX_ERROR, &[], &[])
}
