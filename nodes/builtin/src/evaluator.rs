//! `evaluator` node: ground truth vs estimated vector fields, per packet (paper 1's error measure,
//! [`sonoflow_evaluate`]). Inputs: `truth` (required; planes vx, vz, mask) and any of `raw` and
//! `regularised` (planes vx, vz, optional flags), matched by packet number, and optionally
//! `maps` (the Doppler node's colour Doppler maps, for the figures). At the end it writes
//! `evaluation.json` and `evaluation.md` into the run folder (the launcher puts the latter into
//! `report.md`, beside the stage times), prints one line per field and, unless
//! `figures = false`, draws the report's figures into `<run>/figures/` ([`sonoflow_evaluate::figures`]):
//! the colour Doppler maps and the vectors over the true speed of the last evaluated packet, and
//! the error histograms pooled over all packets. A figure that cannot be drawn is a warning in
//! `evaluation.json`, never an error of the node. Several evaluators in one graph (e.g. two
//! estimators side by side) each get a `label`: their files are then `evaluation-<label>.json` /
//! `.md` and `figures/<name>-<label>.png`.

use sonoflow_evaluate::evaluation::*;
use sonoflow_evaluate::figures;
use sonoflow_messages::plane;
use sonoflow_messages::types::{DopplerMap, VectorField};
use sonoflow_messages::MessageType::*;
use sonoflow_node_kit::PortDir::*;
use sonoflow_node_kit::{is_eos, parse_params, select_loop, thread_cpu_ns, Input, Kit, Step};
use sonoflow_node_kit::{port, KindSpec};
use std::collections::BTreeMap;
use std::time::Duration;

/// The `evaluator` node kind.
pub const SPEC: KindSpec = KindSpec::new(
    "evaluator",
    "errors of raw/regularised vector fields against the ground truth per packet (paper 1's measure) → evaluation.json/.md, the run report and its figures (with `maps`: colour Doppler)",
    &[
            port("truth", In, VectorFieldV1, true),
            port("raw", In, VectorFieldV1, false),
            port("regularised", In, VectorFieldV1, false),
            port("maps", In, DopplerMapV1, false),
        ],
    validate,
    run,
);

fn validate(v: &serde_json::Value) -> Result<(), String> {
    parse_params::<EvaluatorParams>(v)?.validate()
}

fn run(mut kit: Kit) -> anyhow::Result<()> {
    let p: EvaluatorParams = parse_params(&kit.cfg.params).map_err(anyhow::Error::msg)?;
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
    let mut maps_in = match kit.cfg.inputs.contains_key("maps") {
        true => Some(kit.input::<DopplerMap>("maps")?),
        false => None,
    };
    {
        let mut hs: Vec<&mut dyn sonoflow_node_kit::Handshake> = vec![&mut truth_in];
        for (_, i) in est_in.iter_mut() {
            hs.push(i);
        }
        if let Some(m) = maps_in.as_mut() {
            hs.push(m);
        }
        kit.handshake(&mut hs)?;
    }
    let wakeups: Vec<_> = std::iter::once(truth_in.wakeup())
        .chain(est_in.iter().map(|(_, i)| i.wakeup()))
        .chain(maps_in.iter().map(|m| m.wakeup()))
        .collect();
    let mut truths: BTreeMap<u32, Field> = BTreeMap::new();
    let mut estimates: BTreeMap<(u32, String), Field> = BTreeMap::new();
    let mut eval = Evaluation { label: p.label.clone(), margin: p.margin, ..Default::default() };
    let tag = if p.label.is_empty() { String::new() } else { format!(" [{}]", p.label) };
    let mut done: BTreeMap<u32, PacketEval> = BTreeMap::new();
    let mut fig = FigureData::default();
    // per field: pooled x and z errors, pixels, pixels without estimate, largest v_max
    let mut pooled_all: BTreeMap<String, Pooled> = BTreeMap::new();
    let mut truth_eos = false;
    let mut est_eos = vec![false; est_in.len()];
    let mut maps_eos = maps_in.is_none();
    // maps waiting for their packet's truth, and the per-look pools
    let mut look_pending: BTreeMap<u32, Vec<Map>> = BTreeMap::new();
    let mut look_pools: BTreeMap<(u64, u64, u64), LookPool> = BTreeMap::new();
    select_loop(&mut kit, &wakeups, Duration::from_millis(500), |kit| {
        if let Some(m) = maps_in.as_mut() {
            while let Some(s) = m.try_receive()? {
                let h = *s.user_header();
                if is_eos::<DopplerMap>(&h) {
                    maps_eos = true;
                    break;
                }
                kit.stats.messages_in += 1;
                let m = (h, s.payload().to_vec());
                if map_plane(&m.0, &m.1, plane::PROJECTION_X).is_some() {
                    look_pending.entry(h.packet).or_default().push(m.clone());
                }
                if p.figures {
                    fig.keep_map(m);
                }
            }
        }
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
            let (fe, smp) = evaluate_pair_samples(truth, &est, p.margin)?;
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
            pool(pooled_all.entry(key.1.clone()).or_default(), &fe, &smp);
            entry.fields.insert(key.1.clone(), fe);
            if p.figures {
                let pooled = fig.samples.entry(key.1.clone()).or_default();
                pooled.0.extend(smp.ex);
                pooled.1.extend(smp.ez);
                fig.keep_estimate(key.0, truth, &key.1, est);
            }
            kit.record(truth.0.common.frame_id, truth.0.common.t_valid, thread_cpu_ns() - t0)?;
        }
        let ready: Vec<u32> = look_pending.keys().filter(|pk| truths.contains_key(pk)).copied().collect();
        for pk in ready {
            let (Some(maps), Some(truth)) = (look_pending.remove(&pk), truths.get(&pk)) else { continue };
            for m in &maps {
                pool_look(&mut look_pools, truth, m, p.margin)?;
            }
        }
        Ok(if truth_eos && est_eos.iter().all(|e| *e) && maps_eos { Step::Done } else { Step::Continue })
    })?;
    for (pk, name) in estimates.keys() {
        eprintln!("evaluator: no ground truth for packet {pk} ({name}): not evaluated");
    }
    for pk in look_pending.keys() {
        eprintln!("evaluator: no ground truth for packet {pk} (Doppler maps): per-look errors left out");
    }
    eval.packets = done.into_values().collect();
    eval.overall = overall(pooled_all);
    eval.looks = looks(look_pools);
    if let Some(dir) = &kit.cfg.out_dir {
        let dir = std::path::Path::new(dir);
        if p.figures {
            let t0 = std::time::Instant::now();
            (eval.figures, eval.warnings) = write_figures(dir, &fig, eval.packets.len(), &p.label);
            for w in &eval.warnings {
                eprintln!("evaluator{tag}: warning: {w}");
            }
            println!(
                "evaluator{tag}: {} figure(s) in {}/ ({:.0} ms)",
                eval.figures.len(),
                figures::DIR,
                1e3 * t0.elapsed().as_secs_f64()
            );
        }
        let stem = p.stem();
        sonoflow_fileio::write_atomic(
            &dir.join(format!("{stem}.json")),
            serde_json::to_string_pretty(&eval)?.as_bytes(),
        )?;
        sonoflow_fileio::write_atomic(&dir.join(format!("{stem}.md")), markdown(&eval).as_bytes())?;
    }
    kit.stats.gaps =
        truth_in.gaps + est_in.iter().map(|(_, i)| i.gaps).sum::<u64>() + maps_in.as_ref().map(|m| m.gaps).unwrap_or(0);
    kit.finish()?;
    Ok(())
}
