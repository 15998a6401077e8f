//! `evaluator` node: ground truth vs estimated vector fields, per packet (paper 1's error measure,
//! [`sonoflow_evaluate`]). Inputs: `truth` (required; planes vx, vz, mask) and any of `raw` and
//! `regularised` (planes vx, vz, optional flags), matched by packet number, and optionally
//! `maps` (the Doppler node's colour Doppler maps, for the figures) and `iq` (beamformed I/Q: the
//! B-mode figure of the first frame of a packet, from the look nearest normal incidence; other
//! frames are released unread). At the end it writes
//! `evaluation.json` and `evaluation.md` into the run folder (the launcher puts the latter into
//! `report.md`, beside the stage times), prints one line per field and, unless
//! `figures = false`, draws the report's figures into `<run>/figures/` ([`sonoflow_evaluate::figures`]):
//! the colour Doppler maps, the B-mode image (MUST `bmode`, `bmode_dr` dB), the vectors over the true speed of the last evaluated packet, and
//! the error histograms pooled over all packets. A figure that cannot be drawn is a warning in
//! `evaluation.json`, never an error of the node. Several evaluators in one graph (e.g. two
//! estimators side by side) each get a `label`: their files are then `evaluation-<label>.json` /
//! `.md` and `figures/<name>-<label>.png`.

use sonoflow_evaluate::evaluation::{markdown, Evaluation, EvaluatorParams};
use sonoflow_evaluate::figures;
use sonoflow_evaluate::online::OnlineEvaluation;
use sonoflow_messages::types::{DopplerMap, IqFrame, VectorField};
use sonoflow_messages::MessageType::*;
use sonoflow_node_kit::PortDir::*;
use sonoflow_node_kit::{is_eos, parse_params, select_loop, thread_cpu_ns, Handshake, Input, Kit, Step};
use sonoflow_node_kit::{port, KindSpec};
use std::path::Path;
use std::time::{Duration, Instant};

/// The `evaluator` node kind.
pub const SPEC: KindSpec = KindSpec::new(
    "evaluator",
    "errors of raw/regularised vector fields against the ground truth per packet (paper 1's measure) → evaluation.json/.md, the run report and its figures (with `maps`: colour Doppler)",
    &[
            port("truth", In, VectorFieldV2, true),
            port("raw", In, VectorFieldV2, false),
            port("regularised", In, VectorFieldV2, false),
            port("maps", In, DopplerMapV2, false),
            port("iq", In, IqFrameV3, false),
        ],
    validate,
    run,
);

fn validate(v: &serde_json::Value) -> Result<(), String> {
    parse_params::<EvaluatorParams>(v)?.validate()
}

fn run(mut kit: Kit) -> anyhow::Result<()> {
    let p: EvaluatorParams = parse_params(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    let Inputs { truth: mut truth_in, estimates: mut est_in, maps: mut maps_in, iq: mut iq_in } =
        Inputs::open(&mut kit)?;
    let wakeups: Vec<_> = std::iter::once(truth_in.wakeup())
        .chain(est_in.iter().map(|(_, i)| i.wakeup()))
        .chain(maps_in.iter().map(|m| m.wakeup()))
        .chain(iq_in.iter().map(|m| m.wakeup()))
        .collect();
    let mut bmodes = BmodePicker::new(p.bmode_dr, p.figures);
    let tag = if p.label.is_empty() { String::new() } else { format!(" [{}]", p.label) };
    let mut ev = OnlineEvaluation::new(p.clone());
    let (mut truth_eos, mut est_eos, mut maps_eos) = (false, vec![false; est_in.len()], maps_in.is_none());
    let mut iq_eos = iq_in.is_none();
    select_loop(&mut kit, &wakeups, Duration::from_millis(500), |kit| {
        if let Some(m) = maps_in.as_mut() {
            maps_eos |= drain(kit, m, |f| ev.add_map(f))?;
        }
        if let Some(m) = iq_in.as_mut() {
            iq_eos |= bmodes.drain(kit, m, &mut ev)?;
        }
        truth_eos |= drain(kit, &mut truth_in, |f| ev.add_truth(f))?;
        for (k, (name, input)) in est_in.iter_mut().enumerate() {
            est_eos[k] |= drain(kit, input, |f| ev.add_estimate(name, f))?;
        }
        // Evaluate every estimate whose truth has arrived (the CPU time split evenly over them).
        let t0 = thread_cpu_ns();
        let evaluated = ev.evaluate_ready()?;
        let cpu_each = (thread_cpu_ns() - t0) / evaluated.len().max(1) as u64;
        for e in &evaluated {
            let fe = &e.error;
            println!(
                "evaluator{tag}: packet {} {}: x bias {:+.1} %, |e|75 {:.1} %; z bias {:+.1} %, |e|75 {:.1} % of v_max {:.3} m/s ({} px)",
                e.packet, e.name, 100.0 * fe.x.bias, 100.0 * fe.x.abs_p75, 100.0 * fe.z.bias, 100.0 * fe.z.abs_p75, fe.v_max, fe.pixels
            );
            kit.record(e.frame_id, e.t_valid, cpu_each)?;
        }
        Ok(if truth_eos && est_eos.iter().all(|e| *e) && maps_eos && iq_eos { Step::Done } else { Step::Continue })
    })?;
    for line in ev.unmatched() {
        eprintln!("evaluator: {line}");
    }
    let dir = kit.cfg.out_dir.as_ref().map(Path::new);
    let t0 = Instant::now();
    let eval = ev.finish(dir);
    if let Some(dir) = dir {
        write(dir, &p, &eval, &tag, t0)?;
    }
    kit.stats.gaps = truth_in.gaps
        + est_in.iter().map(|(_, i)| i.gaps).sum::<u64>()
        + maps_in.as_ref().map(|m| m.gaps).unwrap_or(0)
        + iq_in.as_ref().map(|m| m.gaps).unwrap_or(0);
    kit.finish()?;
    Ok(())
}

/// The evaluator's inputs: `truth`, the estimates that are wired (`raw`, `regularised`: at least
/// one), `maps` and `iq` if wired.
struct Inputs {
    truth: Input<VectorField>,
    estimates: Vec<(String, Input<VectorField>)>,
    maps: Option<Input<DopplerMap>>,
    iq: Option<Input<IqFrame>>,
}

impl Inputs {
    /// Opens the wired inputs and completes the start-up handshake on all of them.
    fn open(kit: &mut Kit) -> anyhow::Result<Self> {
        let mut truth = kit.input::<VectorField>("truth")?;
        let mut estimates = Vec::new();
        for name in ["raw", "regularised"] {
            if kit.cfg.inputs.contains_key(name) {
                estimates.push((name.to_string(), kit.input::<VectorField>(name)?));
            }
        }
        if estimates.is_empty() {
            anyhow::bail!("evaluator: connect at least one of the inputs `raw` and `regularised`");
        }
        let mut maps = kit.cfg.inputs.contains_key("maps").then(|| kit.input::<DopplerMap>("maps")).transpose()?;
        let mut iq = kit.cfg.inputs.contains_key("iq").then(|| kit.input::<IqFrame>("iq")).transpose()?;
        let mut hs: Vec<&mut dyn Handshake> = vec![&mut truth];
        hs.extend(estimates.iter_mut().map(|(_, i)| i as &mut dyn Handshake));
        if let Some(m) = maps.as_mut() {
            hs.push(m);
        }
        if let Some(m) = iq.as_mut() {
            hs.push(m);
        }
        kit.handshake(&mut hs)?;
        Ok(Self { truth, estimates, maps, iq })
    }
}

/// `<stem>.json` and `<stem>.md` into the run folder, after the figures' log lines (drawn since
/// `t0`).
fn write(dir: &Path, p: &EvaluatorParams, eval: &Evaluation, tag: &str, t0: Instant) -> anyhow::Result<()> {
    if p.figures {
        for w in &eval.warnings {
            eprintln!("evaluator{tag}: warning: {w}");
        }
        let ms = 1e3 * t0.elapsed().as_secs_f64();
        println!("evaluator{tag}: {} figure(s) in {}/ ({ms:.0} ms)", eval.figures.len(), figures::DIR);
    }
    let stem = p.stem();
    let json = serde_json::to_string_pretty(eval)?;
    sonoflow_fileio::write_atomic(&dir.join(format!("{stem}.json")), json.as_bytes())?;
    sonoflow_fileio::write_atomic(&dir.join(format!("{stem}.md")), markdown(eval).as_bytes())?;
    Ok(())
}

/// Hands every message waiting on `input` (header and a copy of the payload) to `keep`, counted
/// in; true if the end of stream came.
fn drain<M>(
    kit: &mut Kit,
    input: &mut Input<M>,
    mut keep: impl FnMut((M::Header, Vec<M::Elem>)),
) -> anyhow::Result<bool>
where
    M: sonoflow_messages::WireMessage,
{
    while let Some(s) = input.try_receive()? {
        let h = *s.user_header();
        if is_eos::<M>(&h) {
            return Ok(true);
        }
        kit.stats.messages_in += 1;
        keep((h, s.payload().to_vec()));
    }
    Ok(false)
}

/// Picks, per packet, the first frame of the look nearest normal incidence (smallest |tx| + |rx|)
/// from the `iq` input and hands its B-mode image to the evaluation; other frames are released
/// without copying their payload.
struct BmodePicker {
    dr: f64,
    on: bool,
    /// Packet → |tx| + |rx| of the look kept.
    kept: std::collections::BTreeMap<u32, f64>,
}

impl BmodePicker {
    fn new(dr: f64, on: bool) -> Self {
        Self { dr, on, kept: Default::default() }
    }

    /// Reads every waiting frame; true at the end of stream.
    fn drain(&mut self, kit: &mut Kit, input: &mut Input<IqFrame>, ev: &mut OnlineEvaluation) -> anyhow::Result<bool> {
        while let Some(s) = input.try_receive()? {
            let h = *s.user_header();
            if is_eos::<IqFrame>(&h) {
                return Ok(true);
            }
            kit.stats.messages_in += 1;
            let score = h.tx_angle.abs() + h.rx_angle.abs();
            if !self.on || h.frame_in_packet != 0 || self.kept.get(&h.packet).is_some_and(|k| *k <= score) {
                continue;
            }
            let iq: &[sonoflow_messages::Complex32] = s.payload();
            let iq: Vec<sonoflow_beamform::C32> = iq.iter().map(|c| sonoflow_beamform::C32::new(c.re, c.im)).collect();
            let Ok(image) = sonoflow_beamform::bmode(&iq, self.dr) else {
                continue; // a frame with NaN/inf: no picture (the beamformer's own checks report it)
            };
            self.kept.insert(h.packet, score);
            let title = format!("tx {:+.1}°, rx {:+.1}°, frame 0", h.tx_angle.to_degrees(), h.rx_angle.to_degrees());
            ev.add_bmode(
                h.packet,
                sonoflow_evaluate::evaluation::Bmode {
                    title: title.replace('-', "−"),
                    grid: h.grid,
                    image,
                    dr: self.dr,
                },
            );
        }
        Ok(false)
    }
}
