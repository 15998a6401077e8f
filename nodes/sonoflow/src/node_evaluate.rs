//! `evaluator` node: ground truth vs estimated vector fields, per packet (paper 1's error measure,
//! [`crate::evaluate`]). Inputs: `truth` (required; planes vx, vz, mask) and any of `raw` and
//! `regularised` (planes vx, vz, optional flags), matched by packet number. At the end it writes
//! `evaluation.json` and `evaluation.md` into the run folder (the launcher puts the latter into
//! `report.md`, beside the stage times) and prints one line per field. Several evaluators in one
//! graph (e.g. two estimators side by side) each get a `label`: their files are then
//! `evaluation-<label>.json` / `.md`.

use crate::evaluate::{field_error, FieldError};
use crate::kinds::parse;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use serde::{Deserialize, Serialize};
use sonoflow_messages::kinds::VectorField;
use sonoflow_messages::{plane, VectorFieldHeaderV1};
use sonoflow_node_kit::{is_eos, thread_cpu_ns, Input, Kit};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::time::Duration;

/// `evaluator` parameters.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct EvaluatorParams {
    /// Pixels count when the truth mask covers their whole (2·margin+1)² neighbourhood (0 ..= 10).
    pub margin: usize,
    /// Names this evaluation (e.g. the estimator it judges): files `evaluation-<label>.json/.md`,
    /// the label in the report's heading and log lines. Empty (default): `evaluation.json/.md`.
    /// Letters, digits, `-` and `_` only (≤ 64).
    pub label: String,
}

impl Default for EvaluatorParams {
    fn default() -> Self {
        Self { margin: 2, label: String::new() }
    }
}

impl EvaluatorParams {
    /// File stem of this evaluator's output: `evaluation` or `evaluation-<label>`.
    pub fn stem(&self) -> String {
        if self.label.is_empty() {
            "evaluation".to_string()
        } else {
            format!("evaluation-{}", self.label)
        }
    }
}

pub fn validate(v: &serde_json::Value) -> Result<(), String> {
    let p = parse::<EvaluatorParams>(v)?;
    crate::kinds::in_range("margin", p.margin, 0, 10)?;
    if p.label.len() > 64 || !p.label.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_') {
        return Err(format!(
            "label = {:?} is not allowed: up to 64 letters, digits, `-` or `_` (it names the files evaluation-<label>.json/.md)",
            p.label
        ));
    }
    Ok(())
}

/// One evaluated packet.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PacketEval {
    pub packet: u32,
    pub t_valid: f64,
    /// Field name (`raw`, `regularised`) → errors.
    pub fields: BTreeMap<String, FieldError>,
}

/// What the evaluator writes to `evaluation.json`.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Evaluation {
    /// The evaluator's `label` (empty: the graph's only evaluation).
    #[serde(default)]
    pub label: String,
    pub margin: usize,
    pub packets: Vec<PacketEval>,
}

type Field = (VectorFieldHeaderV1, Vec<f32>);

fn plane_of<'a>(h: &VectorFieldHeaderV1, data: &'a [f32], id: u32) -> Option<&'a [f32]> {
    let n = h.grid.nx as usize * h.grid.nz as usize;
    let np = (h.n_planes as usize).min(h.plane_ids.len());
    let k = h.plane_ids[..np].iter().position(|&p| p == id)?;
    data.get(k * n..(k + 1) * n)
}

/// Errors of `est` against `truth` (same grid required).
pub fn evaluate_pair(truth: &Field, est: &Field, margin: usize) -> anyhow::Result<FieldError> {
    let (th, tv) = truth;
    let (eh, ev) = est;
    if th.grid != eh.grid {
        anyhow::bail!("packet {}: the estimate's grid differs from the truth's grid", th.packet);
    }
    let need = |h: &VectorFieldHeaderV1, d: &'_ [f32], id: u32, what: &str| -> anyhow::Result<Vec<f32>> {
        plane_of(h, d, id)
            .map(<[f32]>::to_vec)
            .ok_or_else(|| anyhow::anyhow!("{what} field of packet {} has no `{}` plane", h.packet, plane::name(id)))
    };
    let (tvx, tvz, mask) =
        (need(th, tv, plane::VX, "truth")?, need(th, tv, plane::VZ, "truth")?, need(th, tv, plane::MASK, "truth")?);
    let (vx, vz) = (need(eh, ev, plane::VX, "estimated")?, need(eh, ev, plane::VZ, "estimated")?);
    let flags = plane_of(eh, ev, plane::FLAGS);
    Ok(field_error((&tvx, &tvz, &mask), (&vx, &vz, flags), th.grid.nx as usize, th.grid.nz as usize, margin))
}

/// Markdown table of an evaluation (also used by the report).
pub fn markdown(e: &Evaluation) -> String {
    let mut s = String::new();
    if e.label.is_empty() {
        let _ = writeln!(s, "## Error against ground truth\n");
    } else {
        let _ = writeln!(s, "## Error against ground truth: `{}`\n", e.label);
    }
    let _ = writeln!(
        s,
        "Per packet, errors of vx and vz as fractions of the largest true speed, over the pixels inside the vessel (mask eroded by {} px); |e|₇₅: 75 % of the pixels are within ±this.\n",
        e.margin
    );
    let _ = writeln!(s, "| packet | field | pixels | no estimate | v_max (m/s) | x: bias | x: RMS | x: \\|e\\|₇₅ | x: ≤ 10 % | z: bias | z: RMS | z: \\|e\\|₇₅ | z: ≤ 2 % |");
    let _ = writeln!(s, "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for p in &e.packets {
        for (name, f) in &p.fields {
            let _ = writeln!(
                s,
                "| {} | {name} | {} | {} | {:.3} | {:+.1} % | {:.1} % | {:.1} % | {:.0} % | {:+.1} % | {:.1} % | {:.1} % | {:.0} % |",
                p.packet,
                f.pixels,
                f.no_estimate,
                f.v_max,
                100.0 * f.x.bias,
                100.0 * f.x.rms,
                100.0 * f.x.abs_p75,
                100.0 * f.x.within_10pct,
                100.0 * f.z.bias,
                100.0 * f.z.rms,
                100.0 * f.z.abs_p75,
                100.0 * f.z.within_2pct,
            );
        }
    }
    s
}

pub fn run(mut kit: Kit) -> anyhow::Result<()> {
    let p: EvaluatorParams = parse(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    let mut truth_in = kit.input::<VectorField>("truth")?;
    let mut est_in: Vec<(String, Input<VectorField>)> = Vec::new();
    for name in ["raw", "regularised"] {
        if kit.cfg.inputs.contains_key(name) {
            est_in.push((name.to_string(), kit.input::<VectorField>(name)?));
        }
    }
    if est_in.is_empty() {
        anyhow::bail!("evaluator: connect at least one of the inputs `raw` and `regularised`");
    }
    {
        let mut hs: Vec<&mut dyn sonoflow_node_kit::Handshake> = vec![&mut truth_in];
        for (_, i) in est_in.iter_mut() {
            hs.push(i);
        }
        kit.handshake(&mut hs)?;
    }
    let waitset =
        WaitSetBuilder::new().create::<ipc::Service>().map_err(|e| anyhow::anyhow!("creating the WaitSet: {e:?}"))?;
    let listeners: Vec<_> =
        std::iter::once(truth_in.listener()).chain(est_in.iter().map(|(_, i)| i.listener())).collect();
    let mut guards = Vec::new();
    for l in &listeners {
        guards.push(waitset.attach_notification(l.as_ref()).map_err(|e| anyhow::anyhow!("WaitSet attach: {e:?}"))?);
    }
    let mut truths: BTreeMap<u32, Field> = BTreeMap::new();
    let mut estimates: BTreeMap<(u32, String), Field> = BTreeMap::new();
    let mut eval = Evaluation { label: p.label.clone(), margin: p.margin, packets: Vec::new() };
    let tag = if p.label.is_empty() { String::new() } else { format!(" [{}]", p.label) };
    let mut done: BTreeMap<u32, PacketEval> = BTreeMap::new();
    let mut truth_eos = false;
    let mut est_eos = vec![false; est_in.len()];
    loop {
        while let Some(s) = truth_in.try_receive()? {
            let h = *s.user_header();
            if is_eos::<VectorField>(&h) {
                truth_eos = true;
                break;
            }
            kit.stats.messages_in += 1;
            truths.insert(h.packet, (h, s.payload().to_vec()));
        }
        for (k, (name, input)) in est_in.iter_mut().enumerate() {
            while let Some(s) = input.try_receive()? {
                let h = *s.user_header();
                if is_eos::<VectorField>(&h) {
                    est_eos[k] = true;
                    break;
                }
                kit.stats.messages_in += 1;
                estimates.insert((h.packet, name.clone()), (h, s.payload().to_vec()));
            }
        }
        // Evaluate every estimate whose truth has arrived.
        let ready: Vec<(u32, String)> = estimates.keys().filter(|(pk, _)| truths.contains_key(pk)).cloned().collect();
        for key in ready {
            let t0 = thread_cpu_ns();
            let Some(est) = estimates.remove(&key) else { continue };
            let Some(truth) = truths.get(&key.0) else { continue };
            let fe = evaluate_pair(truth, &est, p.margin)?;
            println!(
                "evaluator{tag}: packet {} {}: x bias {:+.1} %, |e|75 {:.1} %; z bias {:+.1} %, |e|75 {:.1} % of v_max {:.3} m/s ({} px)",
                key.0,
                key.1,
                100.0 * fe.x.bias,
                100.0 * fe.x.abs_p75,
                100.0 * fe.z.bias,
                100.0 * fe.z.abs_p75,
                fe.v_max,
                fe.pixels
            );
            let entry = done.entry(key.0).or_insert_with(|| PacketEval {
                packet: key.0,
                t_valid: truth.0.common.t_valid,
                fields: BTreeMap::new(),
            });
            entry.fields.insert(key.1.clone(), fe);
            kit.record(truth.0.common.frame_id, truth.0.common.t_valid, thread_cpu_ns() - t0)?;
        }
        if truth_eos && est_eos.iter().all(|e| *e) {
            break;
        }
        match waitset.wait_and_process_once_with_timeout(|_| CallbackProgression::Continue, Duration::from_millis(500))
        {
            Ok(WaitSetRunResult::TerminationRequest) | Ok(WaitSetRunResult::Interrupt) => break,
            Ok(_) => {}
            Err(e) => anyhow::bail!("WaitSet: {e:?}"),
        }
        for l in &listeners {
            let _ = l.try_wait(|_| {});
        }
        if kit.check_termination().is_err() {
            break;
        }
    }
    drop(guards);
    for (pk, name) in estimates.keys() {
        eprintln!("evaluator: no ground truth for packet {pk} ({name}): not evaluated");
    }
    eval.packets = done.into_values().collect();
    if let Some(dir) = &kit.cfg.out_dir {
        let dir = std::path::Path::new(dir);
        let stem = p.stem();
        crate::nodeutil::write_atomic(
            &dir.join(format!("{stem}.json")),
            serde_json::to_string_pretty(&eval)?.as_bytes(),
        )?;
        crate::nodeutil::write_atomic(&dir.join(format!("{stem}.md")), markdown(&eval).as_bytes())?;
    }
    kit.stats.gaps = truth_in.gaps + est_in.iter().map(|(_, i)| i.gaps).sum::<u64>();
    kit.finish()?;
    Ok(())
}
