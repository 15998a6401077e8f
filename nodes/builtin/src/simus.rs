//! `simus` node: particle snapshots → RF frames (one per scheduled transmit) with the
//! `sonoflow-simus` library (MUST's SIMUS). Thin: the scan (`sonoflow_simus::ScanParams`) and
//! its per-packet frequency plan (`FramePlanner`) come from the library; this file wires the
//! topics and fills the RF headers (element width included, for the beamformer's I/Q headers).
//!
//! Compute time per message is process CPU time (SIMUS runs on a rayon pool). At the end, unless
//! `field_figure = false`, the transmit pressure fields over the region the scatterers occupied
//! go into the run report (`figures/transmit_fields.png`, listed in `figures-<node>.json`).

use sonoflow_messages::types::{ParticleSnapshot, RfFrame};
use sonoflow_messages::MessageType::*;
use sonoflow_messages::{
    ParticleSnapshotHeaderV1, ParticleV1, RfFrameHeaderV3, MAX_TX_ELEMENTS, PARTICLE_TISSUE, PARTICLE_TISSUE_MOVING,
    SAMPLE_RF_F32,
};
use sonoflow_node_kit::PortDir::*;
use sonoflow_node_kit::{parse_params, port, process_cpu_ns, transform, KindSpec, Kit};
use sonoflow_simus::{
    FramePlanner, FrequencyPlan, NoiseModel, NoiseParams, PacketMotion, Scan, ScanParams, Simus, StaticEchoes, Transmit,
};

/// The `simus` node kind.
pub const SPEC: KindSpec = KindSpec::new(
    "simus",
    "SIMUS RF synthesiser (MUST's model): particle snapshots → RF frames, one per plane-wave tilt",
    &[port("particles", In, ParticleSnapshotV1, true), port("rf", Out, RfFrameV3, true)],
    validate,
    run,
);

pub fn validate(v: &serde_json::Value) -> Result<(), String> {
    parse_params::<ScanParams>(v)?.scan(MAX_TX_ELEMENTS).map(|_| ())
}

pub fn run(mut kit: Kit) -> anyhow::Result<()> {
    let p: ScanParams = parse_params(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    let scan = p.scan(MAX_TX_ELEMENTS).map_err(anyhow::Error::msg)?;
    let mut planner = FramePlanner::new(&p, &scan);
    let mut simus = Simus::new(scan.probe.clone(), p.medium.clone(), p.options.clone())?;
    let mut input = kit.input::<ParticleSnapshot>("particles")?;
    let mut out = kit.output::<RfFrame>("rf")?;
    kit.handshake(&mut [&mut input, &mut out])?;
    let n_el = scan.probe.n_elements;
    let (out_dir, node) = (kit.cfg.out_dir.clone(), kit.cfg.node_name.clone());
    let (mut scene, mut statics) = (Scene::default(), StaticEchoes::default());
    let mut noise: Option<NoiseModel> = None;
    transform(kit, &mut input, &mut out, |kit, out, sample| {
        let t0 = process_cpu_ns();
        let h = *sample.user_header();
        scene.fill(sample.payload());
        scene.extend_region();
        let all = sonoflow_simus::ScattererSlices { x: &scene.x, z: &scene.z, rc: &scene.rc };
        // the packet's duration for the automatic plan margin (unknown packet length: none)
        let motion = (h.packet_size > 0)
            .then(|| PacketMotion { speed: &scene.speed, duration: f64::from(h.packet_size - 1) / p.prf });
        let choice = planner.plan(&simus, all, motion, h.frame_in_packet == 0)?;
        let m = scene.n_moving;
        statics.set(&scene.x[m..], &scene.z[m..], &scene.rc[m..]);
        let scat = sonoflow_simus::ScattererSlices { x: &scene.x[..m], z: &scene.z[..m], rc: &scene.rc[..m] };
        if choice.replanned_in_packet {
            eprintln!(
                "simus: scatterers moved beyond the plan margin within packet {} (frame {}): re-planning; set plan_margin (m) to keep one plan per packet",
                h.packet, h.frame_in_packet
            );
        }
        let pl = choice.plan;
        let plan_ns = process_cpu_ns() - t0;
        for (tx_id, (_, tx)) in scan.transmits.iter().enumerate() {
            let t1 = process_cpu_ns();
            let rh = rf_header(&p, &scan, &pl, &h, tx_id);
            let n = n_el * pl.n_samples;
            if let (Some(np), None) = (&p.noise, &noise) {
                noise = Some(noise_model(np, &scan, &pl, sample.payload(), tx, &mut simus)?);
            }
            let r = out.publish_init(n, rh, |buf, hdr| {
                simus.simulate_into(scat, tx, &pl, buf)?;
                statics.add_into(&mut simus, tx, tx_id, &pl, buf)?;
                if let Some(m) = noise.as_mut() {
                    m.add(buf, hdr.common.frame_id).map_err(anyhow::Error::msg)?;
                }
                hdr.common.compute_ns = process_cpu_ns() - t1 + if tx_id == 0 { plan_ns } else { 0 };
                Ok::<(), anyhow::Error>(())
            })?;
            r?;
            let compute = process_cpu_ns() - t1 + if tx_id == 0 { plan_ns } else { 0 };
            kit.published((n * 4) as u64, rh.common.frame_id, h.common.t_valid, compute)?;
        }
        Ok(())
    })?;
    if let (true, Some(dir), Some(region)) = (p.field_figure, out_dir, scene.region) {
        if let Err(e) = field_figure(&scan, &p, region, std::path::Path::new(&dir), &node) {
            eprintln!("simus: warning: transmit field figure: {e:#}");
        }
    }
    Ok(())
}

/// The transmit fields over the scatterers' region (10 % margins, from at least λ in front of the
/// face, at least
/// 0.65 aperture either side) into
/// `dir/figures/transmit_fields.png`, listed in `dir/figures-<node>.json` for the report.
fn field_figure(scan: &Scan, p: &ScanParams, r: [f32; 4], dir: &std::path::Path, node: &str) -> anyhow::Result<()> {
    use sonoflow_evaluate::figures;
    let [x0, x1, z0, z1] = r.map(f64::from);
    let (mx, mz) = (0.1 * (x1 - x0).max(1e-3), 0.1 * (z1 - z0).max(1e-3));
    let lambda = p.medium.c / scan.probe.fc;
    // laterally at least 0.65 aperture either side, so that the edges of each wave show
    let half = 0.65 * scan.probe.n_elements as f64 * scan.probe.pitch;
    // from λ in front of the face: the apex of a convex array's arc, z = 0 for a linear one
    let face = scan.probe.convex_radius().map_or(0.0, |r| r - scan.probe.apothem());
    let top = face + lambda;
    let region = [(x0 - mx).min(-half), (x1 + mx).max(half), (z0 - mz).max(top), (z1 + mz).max(top + 2e-3)];
    let fields = scan.transmit_fields(&p.medium, region, 96)?;
    let max = fields.iter().flat_map(|f| f.rms.iter().copied()).fold(0.0, f64::max);
    let db: Vec<Vec<f32>> =
        fields.iter().map(|f| f.rms.iter().map(|v| (20.0 * (v / max).log10()).max(-200.0) as f32).collect()).collect();
    let panels: Vec<figures::FieldPanel> = fields
        .iter()
        .zip(&db)
        .map(|(f, db)| figures::FieldPanel {
            title: format!("tx {:+.1}°", f.tilt.to_degrees()).replace('-', "−"),
            grid: sonoflow_messages::GridV1 {
                x0: f.x0,
                z0: f.z0,
                dx: f.dx,
                dz: f.dz,
                nx: f.nx as u32,
                nz: f.nz as u32,
            },
            db,
        })
        .collect();
    let heading =
        format!("Transmit pressure fields — {} elements, {:.1} MHz", scan.probe.n_elements, scan.probe.fc / 1e6);
    let fig = figures::transmit_fields(dir, "", &heading, &panels)?;
    let list = serde_json::to_string_pretty(&[fig])?;
    sonoflow_fileio::write_atomic(&dir.join(format!("figures-{node}.json")), list.as_bytes())?;
    Ok(())
}

/// The header of transmit `tx_id`'s RF frame for the particle snapshot `h`: the frame's sampling
/// (`pl`), the probe and medium, the transmit (tilt, delays), the packet position; frame ids
/// count transmits within frames.
fn rf_header(
    p: &ScanParams,
    scan: &Scan,
    pl: &FrequencyPlan,
    h: &ParticleSnapshotHeaderV1,
    tx_id: usize,
) -> RfFrameHeaderV3 {
    let (probe, (angle, tx)) = (&scan.probe, &scan.transmits[tx_id]);
    let mut rh = RfFrameHeaderV3 {
        fs: pl.fs,
        t0: pl.t0,
        fc: probe.fc,
        c: p.medium.c,
        pitch: probe.pitch,
        tx_angle: *angle,
        prf: p.prf,
        element_width: Some(probe.element_width()).filter(|w| w.is_finite()).unwrap_or(0.0),
        radius: probe.convex_radius().unwrap_or(0.0),
        n_channels: probe.n_elements as u32,
        n_samples: pl.n_samples as u32,
        tx_id: tx_id as u32,
        sample_format: SAMPLE_RF_F32,
        packet: h.packet,
        frame_in_packet: h.frame_in_packet,
        ..Default::default()
    };
    for (d, &t) in rh.tx_delays.iter_mut().zip(&tx.delays) {
        *d = t as f32;
    }
    rh.common.frame_id = h.common.frame_id * scan.transmits.len() as u64 + tx_id as u64;
    rh.common.t_valid = h.common.t_valid;
    rh
}

/// A snapshot's scatterers as SIMUS slices: the moving ones first (`..n_moving`: blood,
/// platelets, moving tissue), then the stationary tissue (`PARTICLE_TISSUE`), whose RF
/// [`StaticEchoes`] computes once per plan; and their speeds (for the plan margin).
#[derive(Default)]
struct Scene {
    x: Vec<f32>,
    z: Vec<f32>,
    rc: Vec<f32>,
    /// |v| (m/s) of each scatterer, same order.
    speed: Vec<f32>,
    n_moving: usize,
    /// [x_min, x_max, z_min, z_max] of every scatterer in front of the array seen so far.
    region: Option<[f32; 4]>,
}

impl Scene {
    fn fill(&mut self, particles: &[ParticleV1]) {
        self.x.clear();
        self.z.clear();
        self.rc.clear();
        self.speed.clear();
        let moving = particles.iter().filter(|q| q.kind != PARTICLE_TISSUE);
        let tissue = particles.iter().filter(|q| q.kind == PARTICLE_TISSUE);
        for q in moving.chain(tissue) {
            self.x.push(q.x);
            self.z.push(q.z);
            self.rc.push(q.amplitude);
            self.speed.push(q.vx.hypot(q.vz));
        }
        self.n_moving = particles.iter().filter(|q| q.kind != PARTICLE_TISSUE).count();
    }

    /// Grows [`Scene::region`] by this snapshot's scatterers (z > 0, finite).
    fn extend_region(&mut self) {
        for (x, z) in self.x.iter().zip(&self.z) {
            if !(x.is_finite() && z.is_finite() && *z > 0.0) {
                continue;
            }
            let r = self.region.get_or_insert([*x, *x, *z, *z]);
            *r = [r[0].min(*x), r[1].max(*x), r[2].min(*z), r[3].max(*z)];
        }
    }
}

/// The receive-noise model, calibrated so that its SNR is against the blood: on the RF of the
/// snapshot's non-tissue scatterers (neither static nor moving tissue) for transmit `tx`.
fn noise_model(
    np: &NoiseParams,
    scan: &Scan,
    pl: &FrequencyPlan,
    particles: &[ParticleV1],
    tx: &Transmit,
    simus: &mut Simus,
) -> anyhow::Result<NoiseModel> {
    let mut m = NoiseModel::new(np.clone(), scan.probe.fc, scan.probe.bandwidth, pl.fs).map_err(anyhow::Error::msg)?;
    let (mut x, mut z, mut rc) = (Vec::new(), Vec::new(), Vec::new());
    let blood = |q: &&ParticleV1| q.kind != PARTICLE_TISSUE && q.kind != PARTICLE_TISSUE_MOVING;
    for q in particles.iter().filter(blood) {
        x.push(q.x);
        z.push(q.z);
        rc.push(q.amplitude);
    }
    let mut rf = vec![0f32; scan.probe.n_elements * pl.n_samples];
    simus.simulate_into(sonoflow_simus::ScattererSlices { x: &x, z: &z, rc: &rc }, tx, pl, &mut rf)?;
    m.calibrate(&rf).map_err(anyhow::Error::msg)?;
    Ok(m)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// The RF header's delay table bounds the probe: a clear error naming the field.
    #[test]
    fn probes_beyond_the_header_delay_table_are_refused() {
        let mut probe = serde_json::to_value(sonoflow_simus::Probe::paper_5mhz()).unwrap();
        probe["n_elements"] = serde_json::json!(MAX_TX_ELEMENTS + 1);
        let e = validate(&serde_json::json!({ "probe": probe })).unwrap_err();
        assert!(e.contains("probe.n_elements") && e.contains("256"), "{e}");
        assert!(validate(&serde_json::json!({ "tx_tukey": 0.5 })).is_ok());
    }
}
