//! Analytic flow, MCAP and launch-file cases (from `nodes/analytic-flow/src/tests.rs`,
//! `nodes/mcap-io/tests/truncation.rs` and `errors.rs`, `tests/failures.rs`).

use super::{Case, CaseResult, Check, Ctx, Expected, OrMessage, Stage};
use sonoflow_analytic_flow::{AnalyticFlow, AnalyticFlowParams, FlowKind, GridSpec, Schedule};
use sonoflow_launcher::launch::{self, Overrides};
use sonoflow_mcap_io::{
    recover, ChannelSpec, McapIoError, McapReader, OutMessage, ReadOptions, RecorderWriter, WriterOptions,
};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

pub(super) fn cases() -> Vec<Case> {
    fn a(name: &'static str, stresses: &'static str, expected: Expected, run: fn(&Ctx) -> CaseResult) -> Case {
        Case { stage: Stage::AnalyticFlow, name, stresses, expected, run }
    }
    fn m(name: &'static str, stresses: &'static str, expected: Expected, run: fn(&Ctx) -> CaseResult) -> Case {
        Case { stage: Stage::Mcap, name, stresses, expected, run }
    }
    fn l(name: &'static str, stresses: &'static str, expected: Expected, run: fn(&Ctx) -> CaseResult) -> Case {
        Case { stage: Stage::Launch, name, stresses, expected, run }
    }
    vec![
        a(
            "advance-a-million-seconds",
            "a Poiseuille vessel at the speed limit v_max = 100 m/s advanced to t = 1e6 s (2.5e9 vessel lengths) and a \
             disk at the omega limit 1e5 rad/s to 1e6 s (1e11 rad); check: every scatterer stays in the vessel at its \
             radius / on its circle, velocities = the field at the new position, finite",
            Expected::Pass,
            advance_far,
        ),
        a(
            "invalid-truth-grid",
            "a ground-truth grid with nx = 0",
            Expected::ClearError(&["grid.nx", ">= 1"]),
            invalid_grid,
        ),
        a(
            "overlapping-packets",
            "3 packets of 8 frames at 5 kHz (1.6 ms each) started 1 ms apart",
            Expected::ClearError(&["schedule.packet_interval", "must not overlap"]),
            overlapping,
        ),
        a(
            "zero-scatterers",
            "a density of 1e-4 per mm² in a 240 mm² vessel: rounds to no scatterer",
            Expected::ClearError(&["density_per_mm2", "at least 1 scatterer"]),
            no_scatterer,
        ),
        a(
            "time-backwards-and-nan",
            "advance_to an earlier time, then to NaN; check: both refused, the state unchanged",
            Expected::ClearError(&["goes backwards", "time must be finite"]),
            backwards,
        ),
        m(
            "truncated-mid-chunk",
            "a finished recording cut in the middle of its last chunk (power loss, copy cut short); check: the \
             linear read returns exactly the messages of the complete chunks, recover writes a complete file with them",
            Expected::Pass,
            truncated,
        ),
        m(
            "zeroed-tail",
            "the last chunk and everything after it overwritten with zeros; check: as above",
            Expected::Pass,
            zeroed,
        ),
        m(
            "corrupt-last-chunk",
            "64 flipped bytes inside the last chunk of an unfinished file (its CRC fails); check: as above",
            Expected::Pass,
            corrupt,
        ),
        m(
            "header-only",
            "a file cut 5 bytes after its header (no chunk survives); check: 0 messages read and recovered, no error",
            Expected::Pass,
            header_only,
        ),
        m(
            "not-an-mcap",
            "a text file and an empty file opened as recordings",
            Expected::ClearError(&["is not an MCAP file"]),
            not_mcap,
        ),
        m(
            "refuses-to-overwrite",
            "creating a recording over an existing file (the file must be untouched)",
            Expected::ClearError(&["refusing to overwrite"]),
            overwrite,
        ),
        l("good-file", "a minimal valid launch file (source → checker); check: it resolves", Expected::Pass, good_launch),
        l(
            "unknown-key",
            "a misspelt key in [graph]",
            Expected::ClearError(&["unknown field `colour`"]),
            unknown_key,
        ),
        l(
            "dangling-input-and-type-mismatch",
            "an input wired to a topic of the wrong type that nobody produces: both problems reported at once",
            Expected::ClearError(&[
                "carries RfFrameV2 but topic `iq` is IqFrameV2",
                "topic `iq` is consumed by checker but no node produces it",
            ]),
            dangling,
        ),
        l(
            "out-of-range-params",
            "n_channels = 0 and max_elements = 0 together: one error each",
            Expected::ClearError(&["n_channels = 0 is out of range: 1 ..= 1024", "topics.rf.max_elements = 0 is out of range"]),
            out_of_range,
        ),
        l(
            "two-producers",
            "two nodes publishing the same topic",
            Expected::ClearError(&["topic `rf` has 2 producers"]),
            two_producers,
        ),
        l(
            "bad-set-and-swap",
            "--set on a missing node and --swap to a missing variant",
            Expected::ClearError(&["no node `nosuch`", "node `source` has no variant `fast`"]),
            bad_overrides,
        ),
        l(
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

/// Deterministic pseudo-random bytes (xorshift64*), different for every (seed, len).
fn payload(seed: u64, len: usize) -> Vec<u8> {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ (len as u64) ^ 0xD1B5_4A32_D192_ED03;
    if s == 0 {
        s = 1;
    }
    let mut out = Vec::with_capacity(len + 8);
    while out.len() < len {
        s ^= s >> 12;
        s ^= s << 25;
        s ^= s >> 27;
        out.extend_from_slice(&s.wrapping_mul(0x2545_F491_4F6C_DD1D).to_le_bytes());
    }
    out.truncate(len);
    out
}

fn spec(topic: &str) -> ChannelSpec {
    ChannelSpec {
        topic: topic.to_string(),
        message_encoding: "application/octet-stream".to_string(),
        schema_name: "bytes".to_string(),
        schema_encoding: "jsonschema".to_string(),
        schema_data: br#"{"type":"string","contentEncoding":"base64"}"#.to_vec(),
        metadata: BTreeMap::new(),
    }
}

/// A finished recording in its own folder: 60 messages of 20 KiB on two topics in 64 KiB chunks,
/// with metadata and an attachment. Returns (path, bytes, (chunk start, chunk end, messages) per chunk).
struct Finished {
    dir: PathBuf,
    bytes: Vec<u8>,
    chunks: Vec<(u64, u64, usize)>,
    n: usize,
}

fn finished(ctx: &Ctx, name: &str) -> Result<Finished, String> {
    let dir = ctx.scratch.join(name);
    std::fs::create_dir_all(&dir).msg()?;
    let path = dir.join("full.mcap");
    let opts =
        WriterOptions { chunk_size: 64 * 1024, flush_interval: Duration::from_secs(3600), ..WriterOptions::default() };
    let mut w = RecorderWriter::create(&path, opts).msg()?;
    let a = w.add_channel(spec("/a")).msg()?;
    let b = w.add_channel(spec("/b")).msg()?;
    let n = 60u32;
    for seq in 0..n {
        if seq == 3 {
            w.metadata("run", BTreeMap::from([("seed".to_string(), "7".to_string())])).msg()?;
            w.attach("config", "text/plain", b"config bytes".to_vec()).msg()?;
        }
        let t = 1000 + u64::from(seq) * 10;
        let ch = if seq % 2 == 0 { a } else { b };
        w.write(OutMessage {
            channel: ch,
            sequence: seq,
            log_time: t,
            publish_time: t,
            data: payload(u64::from(seq), 20 * 1024),
        })
        .msg()?;
    }
    w.finish().msg()?;
    let bytes = std::fs::read(&path).msg()?;
    let summary = mcap::Summary::read(&bytes).msg()?.ok_or("the finished file has no summary")?;
    let mut chunks = vec![];
    for c in &summary.chunk_indexes {
        let count = summary.stream_chunk(&bytes, c).msg()?.count();
        chunks.push((c.chunk_start_offset, c.chunk_start_offset + c.chunk_length, count));
    }
    Ok(Finished { dir, bytes, chunks, n: n as usize })
}

impl Finished {
    /// Messages in the chunks that end at or before `cut`.
    fn before(&self, cut: u64) -> usize {
        self.chunks.iter().filter(|c| c.1 <= cut).map(|c| c.2).sum()
    }
}

/// Reads a damaged copy linearly and recovers it; checks both against the first `want` messages.
fn check_damaged(f: &Finished, name: &str, bytes: &[u8], want: usize) -> CaseResult {
    let damaged = f.dir.join(format!("{name}.mcap"));
    std::fs::write(&damaged, bytes).msg()?;
    let r = McapReader::open(&damaged).msg()?;
    let got: Vec<_> = r.messages(&ReadOptions::default()).msg()?.collect::<Result<Vec<_>, _>>().msg()?;
    let in_order = got.iter().enumerate().all(|(i, m)| {
        let topic = if i % 2 == 0 { "/a" } else { "/b" };
        m.sequence == i as u32 && m.data == payload(i as u64, 20 * 1024) && m.topic == topic
    });
    let out = f.dir.join(format!("{name}-recovered.mcap"));
    let stats = recover(&damaged, &out).msg()?;
    let rr = McapReader::open(&out).msg()?;
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
            f.n,
            stats.messages,
            rr.is_complete()
        ),
    ))
}

fn truncated(ctx: &Ctx) -> CaseResult {
    let f = finished(ctx, "truncated")?;
    let last = *f.chunks.last().ok_or("no chunk")?;
    let cut = last.0 + (last.1 - last.0) / 2;
    check_damaged(&f, "cut", &f.bytes[..cut as usize], f.before(cut))
}

fn zeroed(ctx: &Ctx) -> CaseResult {
    let f = finished(ctx, "zeroed")?;
    let last = *f.chunks.last().ok_or("no chunk")?;
    let mut b = f.bytes.clone();
    b[last.0 as usize..].fill(0);
    check_damaged(&f, "zeroed", &b, f.before(last.0))
}

fn corrupt(ctx: &Ctx) -> CaseResult {
    let f = finished(ctx, "corrupt")?;
    let last = *f.chunks.last().ok_or("no chunk")?;
    let mut b = f.bytes[..last.1 as usize + 10].to_vec();
    let mid = ((last.0 + last.1) / 2) as usize;
    for x in &mut b[mid..mid + 64] {
        *x ^= 0x5A;
    }
    check_damaged(&f, "corrupt", &b, f.before(last.0))
}

fn header_only(ctx: &Ctx) -> CaseResult {
    let f = finished(ctx, "header")?;
    let len = f.bytes.get(9..17).and_then(|s| s.try_into().ok()).map(u64::from_le_bytes).ok_or("short file")?;
    let header_end = 8 + 9 + len as usize;
    check_damaged(&f, "header", &f.bytes[..header_end + 5], 0)
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

const GOOD: &str = r#"
[graph]
name = "g"
[topics]
rf = { type = "RfFrameV2", max_elements = 1024 }
[nodes.source]
kind = "test-source"
outputs = { rf = "rf" }
params = { n_frames = 2, n_channels = 4, n_samples = 16 }
[nodes.checker]
kind = "checker"
inputs = { rf = "rf" }
"#;

/// What `sonoflow check` does with a launch file's text: parse, resolve, check (nothing starts).
fn check_text(text: &str, set: &[&str], swap: &[&str]) -> CaseResult {
    let ov = Overrides {
        set: set.iter().map(|s| s.to_string()).collect(),
        swap: swap.iter().map(|s| s.to_string()).collect(),
        lenient_files: true,
    };
    let file: launch::LaunchFile = toml::from_str(text).map_err(|e| e.to_string())?;
    match launch::resolve(file, Path::new("."), &ov, sonoflow_builtin::registry()) {
        Ok(g) => Ok(Check::new(true, format!("ok: {} node(s), {} topic(s)", g.nodes.len(), g.topics.len()))),
        Err(errs) => Err(format!("{} problem(s): {}", errs.len(), errs.join("; "))),
    }
}

fn good_launch(_: &Ctx) -> CaseResult {
    check_text(GOOD, &[], &[])
}

fn unknown_key(_: &Ctx) -> CaseResult {
    check_text(&GOOD.replace("[graph]\n", "[graph]\ncolour = 1\n"), &[], &[])
}

fn dangling(_: &Ctx) -> CaseResult {
    check_text(
        &GOOD
            .replace("inputs = { rf = \"rf\" }", "inputs = { rf = \"iq\" }")
            .replace("[topics]\n", "[topics]\niq = { type = \"IqFrameV2\", max_elements = 10 }\n"),
        &[],
        &[],
    )
}

fn out_of_range(_: &Ctx) -> CaseResult {
    check_text(
        &GOOD.replace("n_channels = 4", "n_channels = 0").replace("max_elements = 1024", "max_elements = 0"),
        &[],
        &[],
    )
}

fn two_producers(_: &Ctx) -> CaseResult {
    check_text(&format!("{GOOD}\n[nodes.source2]\nkind = \"test-source\"\noutputs = {{ rf = \"rf\" }}\n"), &[], &[])
}

fn bad_overrides(_: &Ctx) -> CaseResult {
    check_text(GOOD, &["nosuch.x=1"], &["source=fast"])
}

fn toml_syntax(_: &Ctx) -> CaseResult {
    check_text("[graph\nname = 1", &[], &[])
}
