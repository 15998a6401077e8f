//! `simus` node: particle snapshots → RF frames (one per scheduled transmit) with the
//! `sonoflow-simus` library (MUST's SIMUS). Thin: parameters, frequency plan per packet, publish.
//!
//! The frequency plan (df, band, RF length) is fixed for a whole packet — computed at the first
//! frame of each packet for the scatterers' largest element distance plus `plan_margin` — so
//! every frame of a packet has the same length and gain (MUST re-plans per call, which changes the
//! gain ∝ df between frames of a moving scene). If scatterers move beyond the margin within a
//! packet the plan is recomputed and a warning printed.
//!
//! Compute time per message is process CPU time (SIMUS runs on a rayon pool).

use serde::{Deserialize, Serialize};
use sonoflow_messages::types::{ParticleSnapshot, RfFrame};
use sonoflow_messages::MessageType::*;
use sonoflow_messages::{RfFrameHeaderV2, MAX_TX_ELEMENTS, SAMPLE_RF_F32};
use sonoflow_node_kit::parse_params;
use sonoflow_node_kit::PortDir::*;
use sonoflow_node_kit::{for_each, Flow};
use sonoflow_node_kit::{port, KindSpec};
use sonoflow_node_kit::{process_cpu_ns, Kit};
use sonoflow_simus::{FrequencyPlan, Medium, Probe, Simus, SimusError, SimusOptions, Transmit};

/// The `simus` node kind.
pub const SPEC: KindSpec = KindSpec {
    name: "simus",
    about: "SIMUS RF synthesiser (MUST's model): particle snapshots → RF frames, one per plane-wave tilt",
    ports: &[port("particles", In, ParticleSnapshotV1, true), port("rf", Out, RfFrameV2, true)],
    dynamic_inputs: false,
    dynamic_outputs: false,
    validate,
    check_wiring: None,
    input_files: &[],
    run,
};

/// A probe given by MUST preset name or in full.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(untagged)]
pub enum ProbeSpec {
    /// Preset name (`paper-5mhz`, `L11-5v`, …).
    Preset(String),
    /// Full description.
    Full(Probe),
}

impl ProbeSpec {
    pub fn resolve(&self) -> Result<Probe, SimusError> {
        match self {
            ProbeSpec::Preset(n) => Probe::preset(n),
            ProbeSpec::Full(p) => Ok(p.clone()),
        }
    }
}

/// How the frequency plan is chosen.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq)]
#[serde(rename_all = "kebab-case")]
pub enum NodePlan {
    /// Fixed for each packet (same RF length and gain for every frame of a packet).
    PerPacket,
    /// MUST's rule, re-planned for every frame.
    PerCall,
}

/// `simus` node parameters.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimusNodeParams {
    /// Probe preset or description (MUST names).
    pub probe: ProbeSpec,
    /// Speed of sound and attenuation.
    pub medium: Medium,
    /// SIMUS options (MUST `options`: dB threshold, fs, accuracy mode, …).
    pub options: SimusOptions,
    /// Plane-wave tilts (degrees): one RF frame per tilt for every snapshot.
    pub tilts_deg: Vec<f64>,
    /// Pulse repetition frequency written into the RF headers (Hz).
    pub prf: f64,
    /// Frequency plan mode.
    pub plan: NodePlan,
    /// Extra distance (m) the per-packet plan allows for scatterers moving during a packet.
    pub plan_margin: f64,
    /// Transmit apodisation: Tukey window over the elements with this taper fraction, in
    /// [0, 1] (0 = rectangular, MUST's default; 1 = Hann). A taper weakens the edge waves of the
    /// plane wave.
    pub tx_tukey: f64,
}

impl Default for SimusNodeParams {
    fn default() -> Self {
        Self {
            probe: ProbeSpec::Preset("paper-5mhz".into()),
            medium: Medium::default(),
            options: SimusOptions::default(),
            tilts_deg: vec![0.0],
            prf: 10e3,
            plan: NodePlan::PerPacket,
            plan_margin: 2e-3,
            tx_tukey: 0.0,
        }
    }
}

struct Setup {
    probe: Probe,
    transmits: Vec<(f64, Transmit)>,
}

impl SimusNodeParams {
    fn setup(&self) -> Result<Setup, String> {
        let probe = self.probe.resolve().map_err(|e| format!("probe: {e}"))?;
        probe.validate().map_err(|e| e.to_string())?;
        self.medium.validate().map_err(|e| e.to_string())?;
        self.options.validate(probe.fc).map_err(|e| e.to_string())?;
        if probe.n_elements > MAX_TX_ELEMENTS {
            return Err(format!(
                "probe.n_elements = {} is out of range: 1 ..= {MAX_TX_ELEMENTS} (RF header delay table)",
                probe.n_elements
            ));
        }
        if self.tilts_deg.is_empty() || self.tilts_deg.len() > 64 {
            return Err(format!("tilts_deg has {} entries: 1 ..= 64 allowed", self.tilts_deg.len()));
        }
        if !(self.tx_tukey.is_finite() && (0.0..=1.0).contains(&self.tx_tukey)) {
            return Err(format!("tx_tukey = {} is out of range: 0 ..= 1", self.tx_tukey));
        }
        let mut transmits = Vec::new();
        for (i, t) in self.tilts_deg.iter().enumerate() {
            if !(t.is_finite() && t.abs() < 90.0) {
                return Err(format!("tilts_deg[{i}] = {t} is out of range: (-90, 90) degrees"));
            }
            let mut tx = Transmit::plane_wave(&probe, self.medium.c, t.to_radians()).map_err(|e| e.to_string())?;
            if self.tx_tukey > 0.0 {
                tx.apodization = tukey(probe.n_elements, self.tx_tukey);
            }
            transmits.push((t.to_radians(), tx));
        }
        if !(self.prf.is_finite() && self.prf > 0.0 && self.prf <= 1e7) {
            return Err(format!("prf = {} is out of range: (0, 1e7] Hz", self.prf));
        }
        if !(self.plan_margin.is_finite() && (0.0..=1.0).contains(&self.plan_margin)) {
            return Err(format!("plan_margin = {} is out of range: 0 ..= 1 m", self.plan_margin));
        }
        Ok(Setup { probe, transmits })
    }
}

/// Tukey window of `n` points with taper fraction `r` in (0, 1] (1 = Hann).
pub fn tukey(n: usize, r: f64) -> Vec<f64> {
    (0..n)
        .map(|i| {
            let u = if n > 1 { i as f64 / (n - 1) as f64 } else { 0.5 };
            let d = u.min(1.0 - u);
            if d >= r / 2.0 {
                1.0
            } else {
                0.5 * (1.0 - (std::f64::consts::PI * 2.0 * d / r).cos())
            }
        })
        .collect()
}

pub fn validate(v: &serde_json::Value) -> Result<(), String> {
    parse_params::<SimusNodeParams>(v)?.setup().map(|_| ())
}

pub fn run(mut kit: Kit) -> anyhow::Result<()> {
    let p: SimusNodeParams = parse_params(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    let Setup { probe, transmits } = p.setup().map_err(anyhow::Error::msg)?;
    let mut simus = Simus::new(probe.clone(), p.medium.clone(), p.options.clone())?;
    let mut input = kit.input::<ParticleSnapshot>("particles")?;
    let mut out = kit.output::<RfFrame>("rf")?;
    kit.handshake(&mut [&mut input, &mut out])?;
    let n_el = probe.n_elements;
    let max_delay = transmits.iter().map(|(_, t)| t.max_delay()).fold(0.0, f64::max);
    let (mut xs, mut zs, mut rcs) = (Vec::new(), Vec::new(), Vec::new());
    let mut plan: Option<FrequencyPlan> = None;
    let mut last_t = 0.0;
    let (x_first, x_last) = (probe.element_x(0), probe.element_x(n_el - 1));
    for_each(&mut kit, &mut input, |kit, sample| {
        let t0 = process_cpu_ns();
        let h = *sample.user_header();
        xs.clear();
        zs.clear();
        rcs.clear();
        for q in sample.payload() {
            xs.push(q.x);
            zs.push(q.z);
            rcs.push(q.amplitude);
        }
        let scat = sonoflow_simus::ScattererSlices { x: &xs, z: &zs, rc: &rcs };
        let d = scat.max_element_distance(x_first, x_last);
        let replan = match (&plan, p.plan) {
            (None, _) | (_, NodePlan::PerCall) => true,
            (Some(_), NodePlan::PerPacket) if h.frame_in_packet == 0 => true,
            (Some(pl), NodePlan::PerPacket) => {
                let needed = d + simus.pulse_duration() * p.medium.c;
                if needed > pl.max_distance {
                    eprintln!(
                        "simus: scatterers moved beyond plan_margin within packet {} (frame {}): re-planning; raise plan_margin to keep one plan per packet",
                        h.packet, h.frame_in_packet
                    );
                    true
                } else {
                    false
                }
            }
        };
        if replan {
            let margin = if p.plan == NodePlan::PerPacket { p.plan_margin } else { 0.0 };
            plan = Some(simus.plan_for_max_distance(d + margin, max_delay)?);
        }
        let Some(pl) = plan.clone() else { anyhow::bail!("no frequency plan") };
        let plan_ns = process_cpu_ns() - t0;
        kit.stats.messages_in += 1;
        for (tx_id, (angle, tx)) in transmits.iter().enumerate() {
            let t1 = process_cpu_ns();
            let mut rh = RfFrameHeaderV2 {
                fs: pl.fs,
                t0: pl.t0,
                fc: probe.fc,
                c: p.medium.c,
                pitch: probe.pitch,
                tx_angle: *angle,
                prf: p.prf,
                element_width: Some(probe.element_width()).filter(|w| w.is_finite()).unwrap_or(0.0),
                n_channels: n_el as u32,
                n_samples: pl.n_samples as u32,
                tx_id: tx_id as u32,
                sample_format: SAMPLE_RF_F32,
                packet: h.packet,
                frame_in_packet: h.frame_in_packet,
                ..Default::default()
            };
            for e in 0..n_el {
                rh.tx_delays[e] = tx.delays[e] as f32;
            }
            rh.common.frame_id = h.common.frame_id * transmits.len() as u64 + tx_id as u64;
            rh.common.t_valid = h.common.t_valid;
            let n = n_el * pl.n_samples;
            let r = out.publish_init(n, rh, |buf, hdr| {
                simus.simulate_into(scat, tx, &pl, buf)?;
                hdr.common.compute_ns = process_cpu_ns() - t1 + if tx_id == 0 { plan_ns } else { 0 };
                Ok::<(), SimusError>(())
            })?;
            r?;
            let compute = process_cpu_ns() - t1 + if tx_id == 0 { plan_ns } else { 0 };
            kit.stats.messages_out += 1;
            kit.stats.bytes_out += (n * 4) as u64;
            kit.record(rh.common.frame_id, h.common.t_valid, compute)?;
        }
        last_t = h.common.t_valid;
        Ok(Flow::Continue)
    })?;
    out.publish_eos(last_t)?;
    kit.stats.gaps = input.gaps;
    kit.finish()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tukey_window_is_flat_in_the_middle_and_tapers_to_zero() {
        // r = 1: Hann, 0.5 (1 − cos 2πi/(n−1)); r = 0.5: flat over the middle half.
        let n = 129;
        let hann = tukey(n, 1.0);
        for (i, w) in hann.iter().enumerate() {
            let exact = 0.5 * (1.0 - (2.0 * std::f64::consts::PI * i as f64 / (n - 1) as f64).cos());
            assert!((w - exact).abs() < 1e-12, "{i}: {w} vs {exact}");
        }
        let t = tukey(n, 0.5);
        assert_eq!(t[0], 0.0);
        assert!(t[32..=96].iter().all(|&w| w == 1.0));
        assert!((t[16] - 0.5).abs() < 1e-12, "{}", t[16]);
        assert!(t.iter().zip(t.iter().rev()).all(|(a, b)| (a - b).abs() < 1e-12));
        // Out of range: a clear error naming the field.
        let bad = serde_json::json!({ "tx_tukey": 1.5 });
        let e = validate(&bad).unwrap_err();
        assert!(e.contains("tx_tukey") && e.contains("0 ..= 1"), "{e}");
        assert!(validate(&serde_json::json!({ "tx_tukey": 0.5 })).is_ok());
    }
}
