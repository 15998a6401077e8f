//! `doppler` (lag-L autocorrelation, eq. 19) and `doppler-loupas` (Loupas 2-D autocorrelator)
//! nodes: thin wrappers of `sonoflow-beamform`.
//!
//! They collect the I/Q images of a packet per look (transmit tilt, receive angle, fc); at the end
//! of the packet (a frame of the next packet, or end of stream) optionally clutter-filter them,
//! estimate one Doppler map per look and solve the vector velocity by least squares over all looks
//! (nominal plane-wave or per-pixel aperture projections; looks weighted by fc², equal weights
//! when they share one band). Outputs: `vector` (vx, vz, flags, power) and, if connected, `maps`
//! (velocity, power, normalised variance, flags and the projection vector `projection_x`,
//! `projection_z` per look: the map's velocity measures projection · (vx, vz)). The two kinds differ only in their
//! default estimator, so a launch file swaps them by kind.

use serde::{Deserialize, Serialize};
use sonoflow_beamform::{
    ClutterFilter, DopplerEstimator, DopplerMap, DopplerParams, Estimator, Grid, Packet, Projection,
    VectorField as BfVectorField, VectorInput, WindowShape, C32,
};
use sonoflow_messages::types::{DopplerMap as DopplerMapMsg, IqFrame, VectorField};
use sonoflow_messages::MessageType::*;
use sonoflow_messages::{
    plane, Complex32, DopplerMapHeaderV1, IqFrameHeaderV1, MsgHeaderV1, VectorFieldHeaderV1, VECTOR_RAW,
};
use sonoflow_node_kit::parse_params;
use sonoflow_node_kit::PortDir::*;
use sonoflow_node_kit::{for_each, Flow};
use sonoflow_node_kit::{port, KindSpec};
use sonoflow_node_kit::{process_cpu_ns, Kit};
use std::collections::BTreeMap;

/// The `doppler` node kind.
pub const SPEC: KindSpec = KindSpec {
        name: "doppler",
        about: "colour + vector Doppler per packet: lag-L slow-time autocorrelation (eq. 19) per angle pair, least-squares (vx, vz)",
        ports: &[
            port("iq", In, IqFrameV1, true),
            port("vector", Out, VectorFieldV1, true),
            port("maps", Out, DopplerMapV1, false),
        ],
        dynamic_inputs: false,
        dynamic_outputs: false,
        validate: validate_doppler,
        check_wiring: None,
        input_files: &[],
        run: run_doppler,
};

/// The `doppler-loupas` node kind.
pub const SPEC_LOUPAS: KindSpec = KindSpec {
    name: "doppler-loupas",
    about: "as `doppler`, with Loupas' 2-D autocorrelator (mean RF frequency from the axial lag, no fc bias)",
    ports: &[
        port("iq", In, IqFrameV1, true),
        port("vector", Out, VectorFieldV1, true),
        port("maps", Out, DopplerMapV1, false),
    ],
    dynamic_inputs: false,
    dynamic_outputs: false,
    validate: validate_doppler,
    check_wiring: None,
    input_files: &[],
    run: run_doppler_loupas,
};

/// `doppler` / `doppler-loupas` parameters (fc, c and PRF come from the I/Q headers).
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct DopplerNodeParams {
    /// `autocorrelation` (eq. 19) or `loupas`; the default depends on the node kind.
    pub estimator: Option<Estimator>,
    /// Slow-time lag, 1 ..= 64.
    pub lag: usize,
    /// Spatial averaging window [rows (z), columns (x)], each 1 ..= 64 (MUST `M`).
    pub window: [usize; 2],
    /// `hamming` (MUST) or `boxcar`.
    pub window_shape: WindowShape,
    /// Aliasing flag threshold as a fraction of the Nyquist velocity, in (0, 1].
    pub alias_fraction: f64,
    /// Polynomial-regression clutter filter order over slow time (0 = mean removal); absent: none.
    pub clutter_order: Option<usize>,
    /// Receive aperture of the beamformer, to project each pixel's Doppler on the directions of
    /// the elements actually summed there (the array edge clips steered sub-apertures). Absent:
    /// the nominal plane-wave projection of the transmit and receive angles.
    pub aperture: Option<ApertureParams>,
}

/// The beamformer's receive geometry (MUST names), for per-pixel Doppler projections.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ApertureParams {
    /// Element pitch (m).
    pub pitch: f64,
    /// Number of elements.
    #[serde(alias = "Nelements")]
    pub n_elements: usize,
    /// Receive f-number (> 0), as in the beamformer.
    pub fnumber: f64,
    /// Element width (m, ≤ pitch). When given, each element's direction is weighted by the
    /// amplitude it receives from the pixel — directivity `sinc(π·width·sin θ/λ)`, soft-baffle
    /// obliquity `cos θ` and 2-D spreading `r^−½` at fc — because the phase of the summed echo,
    /// hence the Doppler shift, follows the strong (near-normal) elements. Absent: equal weights.
    #[serde(default)]
    pub width: Option<f64>,
    /// Receive apodisation, as the beamformer's `apodization` (`boxcar` default, or `hann`): the
    /// element weights of the mean receive direction.
    #[serde(default)]
    pub apodization: sonoflow_beamform::Apodization,
}

impl Default for DopplerNodeParams {
    fn default() -> Self {
        Self {
            estimator: None,
            lag: 1,
            window: [1, 1],
            window_shape: WindowShape::Hamming,
            alias_fraction: 0.9,
            clutter_order: None,
            aperture: None,
        }
    }
}

impl DopplerNodeParams {
    fn doppler(&self, fc: f64, c: f64, prf: f64, default: Estimator) -> DopplerParams {
        DopplerParams {
            fc,
            c,
            prf,
            lag: self.lag,
            window: self.window,
            window_shape: self.window_shape,
            estimator: self.estimator.unwrap_or(default),
            alias_fraction: self.alias_fraction,
        }
    }
    fn check(&self) -> Result<(), String> {
        self.doppler(5e6, 1540.0, 1e4, Estimator::Autocorrelation).validate().map_err(|e| e.to_string())?;
        if let Some(o) = self.clutter_order {
            if o > 8 {
                return Err(format!("clutter_order = {o} is out of range: 0 ..= 8 (and below the packet size)"));
            }
        }
        if let Some(a) = &self.aperture {
            let grid = Grid { x0: 0.0, z0: 0.01, dx: 1e-3, dz: 1e-3, nx: 1, nz: 1 };
            aperture_projection(a, 5e6, 1540.0, 0.0, 0.0, &grid).map_err(|e| format!("aperture: {e}"))?;
        }
        Ok(())
    }
}

pub fn validate_doppler(v: &serde_json::Value) -> Result<(), String> {
    parse_params::<DopplerNodeParams>(v)?.check()
}

/// Per-pixel Doppler projection vectors of a plane-wave transmit at `tx` and receive angle `rx`
/// (rad) through the aperture `a`: `a = −(sin θt + ⟨sin θe⟩, cos θt + ⟨cos θe⟩)/2`, the receive
/// direction averaged over the elements the beamformer sums at the pixel (the DAS aperture rule
/// of `sonoflow-beamform`: centred on the line through the pixel at `rx`, width `z/(F cos rx)`,
/// clipped by the array), with equal weights or, given `width`, the received amplitudes.
pub fn aperture_projection(
    a: &ApertureParams,
    fc: f64,
    c: f64,
    tx: f64,
    rx: f64,
    grid: &Grid,
) -> anyhow::Result<Vec<[f32; 2]>> {
    if !(a.fnumber.is_finite() && a.fnumber > 0.0 && a.fnumber <= 1000.0) {
        anyhow::bail!("fnumber = {} is out of range: (0, 1000]", a.fnumber);
    }
    if !(a.pitch.is_finite() && a.pitch > 0.0 && a.pitch < 0.1) {
        anyhow::bail!("pitch = {} is out of range: (0, 0.1) m", a.pitch);
    }
    if !(1..=65536).contains(&a.n_elements) {
        anyhow::bail!("n_elements = {} is out of range: 1 ..= 65536", a.n_elements);
    }
    if let Some(w) = a.width {
        if !(w.is_finite() && w > 0.0 && w <= a.pitch) {
            anyhow::bail!("width = {w} is out of range: (0, pitch = {}] m", a.pitch);
        }
    }
    if !(fc.is_finite() && fc > 0.0 && c.is_finite() && c > 0.0) {
        anyhow::bail!("fc = {fc} and c = {c} must be finite and > 0");
    }
    let lambda = c / fc;
    let xe: Vec<f64> = (0..a.n_elements).map(|e| (e as f64 - (a.n_elements as f64 - 1.0) / 2.0) * a.pitch).collect();
    let (tan_rx, cos_rx) = (rx.tan(), rx.cos());
    let mut out = Vec::with_capacity(grid.nx * grid.nz);
    for iz in 0..grid.nz {
        let z = grid.z(iz);
        for ix in 0..grid.nx {
            let x = grid.x(ix);
            let (mut sw, mut ss, mut sc) = (0.0f64, 0.0f64, 0.0f64);
            for &e in &xe {
                let dx = x - e;
                // offset from the aperture's centre and its half-width (the beamformer's rule)
                let (off, half) =
                    if rx == 0.0 { (dx, z / 2.0 / a.fnumber) } else { (dx - z * tan_rx, z / cos_rx / 2.0 / a.fnumber) };
                let r = dx.hypot(z);
                if off.abs() > half || r <= 0.0 {
                    continue;
                }
                let aw = a.apodization.weight(-off / (2.0 * half));
                let (sin_t, cos_t) = (dx / r, z / r);
                let w = aw
                    * match a.width {
                        None => 1.0,
                        Some(width) => {
                            let u = std::f64::consts::PI * width * sin_t / lambda;
                            let sinc = if u.abs() < 1e-12 { 1.0 } else { u.sin() / u };
                            (sinc * cos_t).abs() / r.sqrt()
                        }
                    };
                sw += w;
                ss += w * sin_t;
                sc += w * cos_t;
            }
            out.push(if sw > 0.0 {
                [(-(tx.sin() + ss / sw) / 2.0) as f32, (-(tx.cos() + sc / sw) / 2.0) as f32]
            } else {
                [0.0, 0.0]
            });
        }
    }
    Ok(out)
}

/// One packet's frames of one look (tx angle, rx angle, fc).
struct Stream {
    header: IqFrameHeaderV1,
    frames: Vec<Vec<C32>>,
}

/// Products of one packet.
pub struct PacketResult {
    /// One Doppler map header + planes (velocity, power, variance, flags, projection_x,
    /// projection_z) per look.
    pub maps: Vec<(DopplerMapHeaderV1, Vec<f32>)>,
    /// The vector field header + planes (vx, vz, flags, power).
    pub vector: (VectorFieldHeaderV1, Vec<f32>),
}

/// (tx angle, rx angle, fc, grid x0/z0/dx/dz, nx, nz), as bits.
type ProjectionKey = (u64, u64, u64, [u64; 4], u32, u32);

/// What the Doppler node does per packet, without IPC.
pub struct DopplerNode {
    params: DopplerNodeParams,
    default_estimator: Estimator,
    packet: Option<u32>,
    /// Per (transmit tilt, receive angle, fc) bits: one look each.
    streams: BTreeMap<(u64, u64, u64), Stream>,
    map: DopplerMap,
    vec: BfVectorField,
    /// Per-pixel projections per (tx, rx, fc, grid) when `aperture` is set.
    projections: BTreeMap<ProjectionKey, Vec<[f32; 2]>>,
}

impl DopplerNode {
    pub fn new(params: DopplerNodeParams, default_estimator: Estimator) -> Result<Self, String> {
        params.check()?;
        Ok(Self {
            params,
            default_estimator,
            packet: None,
            streams: BTreeMap::new(),
            map: DopplerMap::default(),
            vec: BfVectorField::default(),
            projections: BTreeMap::new(),
        })
    }

    /// Adds one I/Q image; returns the finished previous packet if this image starts a new one.
    pub fn push(&mut self, h: &IqFrameHeaderV1, iq: &[Complex32]) -> anyhow::Result<Option<PacketResult>> {
        let n = h.grid.nx as usize * h.grid.nz as usize;
        if iq.len() != n || n == 0 {
            anyhow::bail!(
                "I/Q frame {}: {} samples for a {}×{} grid",
                h.common.frame_id,
                iq.len(),
                h.grid.nz,
                h.grid.nx
            );
        }
        let done = match self.packet {
            Some(p) if p != h.packet => self.finish()?,
            _ => None,
        };
        self.packet = Some(h.packet);
        let key = (h.tx_angle.to_bits(), h.rx_angle.to_bits(), h.fc.to_bits());
        let s = self.streams.entry(key).or_insert_with(|| Stream { header: *h, frames: Vec::new() });
        if s.header.grid != h.grid {
            anyhow::bail!("I/Q frame {}: the grid changed within packet {}", h.common.frame_id, h.packet);
        }
        s.frames.push(iq.iter().map(|c| C32::new(c.re, c.im)).collect());
        Ok(done)
    }

    /// Finishes the current packet (end of stream); None if nothing is pending.
    pub fn finish(&mut self) -> anyhow::Result<Option<PacketResult>> {
        if self.streams.is_empty() {
            return Ok(None);
        }
        let streams = std::mem::take(&mut self.streams);
        let first = match streams.values().next() {
            Some(s) => s.header,
            None => return Ok(None),
        };
        let (nx, nz) = (first.grid.nx as usize, first.grid.nz as usize);
        let n = nx * nz;
        let mut maps = Vec::new();
        let mut angles = Vec::new();
        let mut velocities: Vec<(Vec<f32>, Vec<u8>)> = Vec::new();
        let mut frame_id = 0;
        let mut t_valid = 0.0;
        for s in streams.into_values() {
            let h = s.header;
            if s.frames.iter().any(|f| f.len() != n) || h.grid != first.grid {
                anyhow::bail!("packet {}: the angle pairs do not share one grid", h.packet);
            }
            let dp = self.params.doppler(h.fc, h.c, h.prf, self.default_estimator);
            if s.frames.len() <= dp.lag {
                anyhow::bail!(
                    "packet {} (rx {:.1}°): {} frame(s), need more than lag = {}",
                    h.packet,
                    h.rx_angle.to_degrees(),
                    s.frames.len(),
                    dp.lag
                );
            }
            let mut frames = s.frames;
            if let Some(order) = self.params.clutter_order {
                if order + 1 >= frames.len() {
                    anyhow::bail!(
                        "clutter_order = {order} needs a packet of more than {} frames, got {}",
                        order + 1,
                        frames.len()
                    );
                }
                let cf = ClutterFilter::new(order, frames.len())?;
                let mut refs: Vec<&mut [C32]> = frames.iter_mut().map(|f| f.as_mut_slice()).collect();
                cf.apply_frames(&mut refs)?;
            }
            let mut est = DopplerEstimator::new(dp.clone(), nx, nz, h.grid.dz)?;
            if dp.estimator == Estimator::Loupas {
                // Nominal axial delay step of this angle pair: (cos θt + cos θr)·dz/c.
                let step = (h.tx_angle.cos() + h.rx_angle.cos()) * h.grid.dz / h.c;
                est.set_axial_step(&vec![step; n])?;
            }
            let refs: Vec<&[C32]> = frames.iter().map(|f| f.as_slice()).collect();
            est.estimate(Packet::Frames(&refs), &mut self.map)?;
            let vn = self.map.nyquist;
            let norm = 2.0 * (vn / std::f64::consts::PI).powi(2);
            let mut planes = Vec::with_capacity(4 * n);
            planes.extend_from_slice(&self.map.velocity);
            planes.extend_from_slice(&self.map.power);
            planes.extend(self.map.variance.iter().map(|v| (*v as f64 / norm) as f32));
            planes.extend(self.map.flags.iter().map(|f| *f as f32));
            let mut mh = DopplerMapHeaderV1 {
                grid: h.grid,
                fc: h.fc,
                c: h.c,
                prf: h.prf,
                rx_angle: h.rx_angle,
                tx_angle: h.tx_angle,
                nyquist_velocity: vn,
                packet: h.packet,
                packet_size: frames.len() as u32,
                n_planes: 4,
                estimator: match dp.estimator {
                    Estimator::Autocorrelation => 0,
                    Estimator::Loupas => 1,
                },
                ..Default::default()
            };
            mh.plane_ids[..4].copy_from_slice(&[plane::VELOCITY, plane::POWER, plane::VARIANCE, plane::FLAGS]);
            frame_id = frame_id.max(h.common.frame_id);
            t_valid = h.common.t_valid;
            mh.common = MsgHeaderV1 { frame_id: h.common.frame_id, t_valid: h.common.t_valid, ..Default::default() };
            angles.push((h.tx_angle, h.rx_angle, h.fc));
            velocities.push((self.map.velocity.clone(), self.map.flags.clone()));
            maps.push((mh, planes));
        }
        if velocities.len() < 2 {
            anyhow::bail!(
                "packet {}: vector Doppler needs at least two (transmit, receive) angle pairs, got {} — give the beamformer two rx_angles_deg",
                first.packet,
                velocities.len()
            );
        }
        let g = first.grid;
        let key = |&(tx, rx, fc): &(f64, f64, f64)| -> ProjectionKey {
            (tx.to_bits(), rx.to_bits(), fc.to_bits(), [g.x0, g.z0, g.dx, g.dz].map(f64::to_bits), g.nx, g.nz)
        };
        if let Some(a) = &self.params.aperture {
            let grid = Grid { x0: g.x0, z0: g.z0, dx: g.dx, dz: g.dz, nx: g.nx as usize, nz: g.nz as usize };
            for look in &angles {
                if let std::collections::btree_map::Entry::Vacant(e) = self.projections.entry(key(look)) {
                    let (tx, rx, fc) = *look;
                    e.insert(aperture_projection(a, fc, first.c, tx, rx, &grid)?);
                }
            }
        }
        let projections: Vec<Option<&Vec<[f32; 2]>>> = angles.iter().map(|l| self.projections.get(&key(l))).collect();
        // Each map carries the projection its velocity was solved with (planes `projection_x`,
        // `projection_z`): the evaluator compares every look with the truth projected the same way.
        for (((mh, planes), &(tx, rx, _)), pr) in maps.iter_mut().zip(&angles).zip(&projections) {
            match (&self.params.aperture, pr) {
                (Some(_), Some(p)) => {
                    planes.extend(p.iter().map(|a| a[0]));
                    planes.extend(p.iter().map(|a| a[1]));
                }
                _ => {
                    let a = sonoflow_beamform::nominal_projection(tx, rx);
                    planes.extend(std::iter::repeat_n(a[0] as f32, n));
                    planes.extend(std::iter::repeat_n(a[1] as f32, n));
                }
            }
            mh.n_planes = 6;
            mh.plane_ids[4..6].copy_from_slice(&[plane::PROJECTION_X, plane::PROJECTION_Z]);
        }
        let inputs: Vec<VectorInput> = velocities
            .iter()
            .zip(&angles)
            .zip(&projections)
            .map(|(((v, f), (tx, rx, _)), pr)| VectorInput {
                velocity: v,
                flags: f,
                projection: match (&self.params.aperture, pr) {
                    (Some(_), Some(p)) => Projection::PerPixel(p),
                    _ => Projection::Nominal { tx_tilt: *tx, rx_angle: *rx },
                },
            })
            .collect();
        // Looks in different bands (the beamformer's per-angle `demod_fc`): equal phase noise
        // means velocity noise ∝ 1/fc, so each look is weighted by (fc / highest fc)²; the power
        // plane averages each look's power relative to its own mean (the bands' echo levels
        // differ by orders of magnitude). One band: equal weights and the plain mean, as before.
        let f_max = angles.iter().map(|a| a.2).fold(0.0f64, f64::max);
        let weights: Vec<f64> = angles.iter().map(|a| (a.2 / f_max).powi(2)).collect();
        sonoflow_beamform::solve_vector_weighted(&inputs, &weights, &mut self.vec)?;
        let look_power: Vec<&[f32]> = maps.iter().map(|(_, planes)| &planes[n..2 * n]).collect();
        let one_band = angles.iter().all(|a| a.2.to_bits() == first.fc.to_bits());
        let power = mean_power(&look_power, one_band);
        let mut planes = Vec::with_capacity(4 * n);
        planes.extend_from_slice(&self.vec.vx);
        planes.extend_from_slice(&self.vec.vz);
        planes.extend(self.vec.flags.iter().map(|f| *f as f32));
        planes.extend_from_slice(&power);
        let mut vh = VectorFieldHeaderV1 {
            grid: first.grid,
            n_planes: 4,
            source: VECTOR_RAW,
            packet: first.packet,
            converged: 1,
            ..Default::default()
        };
        vh.plane_ids[..4].copy_from_slice(&[plane::VX, plane::VZ, plane::FLAGS, plane::POWER]);
        vh.common = MsgHeaderV1 { frame_id, t_valid, ..Default::default() };
        Ok(Some(PacketResult { maps, vector: (vh, planes) }))
    }
}

/// The vector field's `power` plane from the looks' power maps: their mean; with looks in
/// several bands, the mean of each look's power relative to its own mean (the bands' echo levels
/// differ by orders of magnitude), scaled by the looks' mean level.
fn mean_power(looks: &[&[f32]], one_band: bool) -> Vec<f32> {
    let n = looks.first().map_or(0, |p| p.len());
    let k = looks.len() as f32;
    if one_band {
        let mut sum = vec![0.0f32; n];
        for p in looks {
            for (s, v) in sum.iter_mut().zip(p.iter()) {
                *s += v;
            }
        }
        return sum.iter().map(|s| s / k).collect();
    }
    let means: Vec<f64> = looks.iter().map(|p| p.iter().map(|&v| f64::from(v)).sum::<f64>() / n as f64).collect();
    let overall = means.iter().sum::<f64>() / means.len() as f64;
    (0..n)
        .map(|i| {
            let rel: f64 =
                looks.iter().zip(&means).map(|(p, &m)| if m > 0.0 { f64::from(p[i]) / m } else { 0.0 }).sum();
            (rel * overall) as f32 / k
        })
        .collect()
}

fn run_doppler_with(mut kit: Kit, default: Estimator) -> anyhow::Result<()> {
    let p: DopplerNodeParams = parse_params(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    let mut node = DopplerNode::new(p, default).map_err(anyhow::Error::msg)?;
    let mut input = kit.input::<IqFrame>("iq")?;
    let mut vout = kit.output::<VectorField>("vector")?;
    let mut mout = match kit.cfg.outputs.contains_key("maps") {
        true => Some(kit.output::<DopplerMapMsg>("maps")?),
        false => None,
    };
    match mout.as_mut() {
        Some(m) => kit.handshake(&mut [&mut input, &mut vout, m])?,
        None => kit.handshake(&mut [&mut input, &mut vout])?,
    }
    let mut last_t = 0.0;
    let mut publish = |kit: &mut Kit, r: PacketResult, compute: u64| -> anyhow::Result<()> {
        if let Some(m) = mout.as_mut() {
            for (mut h, planes) in r.maps {
                h.common.compute_ns = compute;
                m.publish_copy(h, &planes)?;
                kit.stats.messages_out += 1;
            }
        }
        let (mut vh, planes) = r.vector;
        vh.common.compute_ns = compute;
        vout.publish_copy(vh, &planes)?;
        kit.stats.messages_out += 1;
        kit.stats.bytes_out += (planes.len() * 4) as u64;
        kit.record(vh.common.frame_id, vh.common.t_valid, compute)?;
        Ok(())
    };
    let mut acc_ns = 0u64;
    for_each(&mut kit, &mut input, |kit, sample| {
        let t0 = process_cpu_ns();
        let h = *sample.user_header();
        let done = node.push(&h, sample.payload())?;
        kit.stats.messages_in += 1;
        acc_ns += process_cpu_ns() - t0;
        if let Some(r) = done {
            publish(kit, r, acc_ns)?;
            acc_ns = 0;
        }
        last_t = h.common.t_valid;
        Ok(Flow::Continue)
    })?;
    let t0 = process_cpu_ns();
    if let Some(r) = node.finish()? {
        acc_ns += process_cpu_ns() - t0;
        publish(&mut kit, r, acc_ns)?;
    }
    vout.publish_eos(last_t)?;
    if let Some(m) = mout.as_mut() {
        m.publish_eos(last_t)?;
    }
    kit.stats.gaps = input.gaps;
    kit.finish()?;
    Ok(())
}

pub fn run_doppler(kit: Kit) -> anyhow::Result<()> {
    run_doppler_with(kit, Estimator::Autocorrelation)
}

pub fn run_doppler_loupas(kit: Kit) -> anyhow::Result<()> {
    run_doppler_with(kit, Estimator::Loupas)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::beamformer::validate_beamformer;
    use sonoflow_beamform::{Apodization, DasParams, DasPlan, Interpolation, TxWave};
    use sonoflow_messages::GridV1;

    #[test]
    fn aperture_projection_is_nominal_inside_the_array_and_clipped_at_its_edge() {
        let a = ApertureParams {
            pitch: 0.3e-3,
            n_elements: 128,
            fnumber: 1.5,
            width: None,
            apodization: Apodization::Boxcar,
        };
        // Two pixels at 20 mm depth: x = 0 (both ±15° sub-apertures inside the 38 mm array) and
        // x = 12 mm (the −15° sub-aperture, centred at x + 5.4 mm, is clipped by the edge at 19 mm).
        let grid = Grid { x0: 0.0, z0: 0.02, dx: 12e-3, dz: 1e-3, nx: 2, nz: 1 };
        let rx = (-15f64).to_radians();
        let p = aperture_projection(&a, 5e6, 1540.0, 0.0, rx, &grid).unwrap();
        let nom = sonoflow_beamform::nominal_projection(0.0, rx);
        // Centre: the mean direction over a ±18° aperture about −15° is close to −15° itself.
        assert!((p[0][0] as f64 - nom[0]).abs() < 0.01 && (p[0][1] as f64 - nom[1]).abs() < 0.01, "{p:?} vs {nom:?}");
        // Edge: fewer oblique elements, so the lateral sensitivity |a_x| shrinks.
        assert!((p[1][0] as f64).abs() < 0.9 * nom[0].abs(), "{p:?} vs {nom:?}");
        assert!(
            aperture_projection(&ApertureParams { fnumber: 0.0, ..a.clone() }, 5e6, 1540.0, 0.0, rx, &grid).is_err()
        );
        // Same aperture rule and element weights as the beamformer's DAS plan: its (apodisation-
        // weighted) mean delay gradient gives the same projection (float32 gradients: 1e-4), for
        // equal weights and for the Hann window, which leans on the central elements (a_x closer
        // to nominal than with equal weights).
        let mut hann = Vec::new();
        for apodization in [Apodization::Boxcar, Apodization::Hann] {
            let dp = DasParams {
                fc: 5e6,
                c: 1540.0,
                fs: 20e6,
                t0: 0.0,
                pitch: a.pitch,
                n_elements: a.n_elements,
                fnumber: a.fnumber,
                rx_angle: rx,
                interpolation: Interpolation::Linear,
                apodization,
            };
            let q =
                aperture_projection(&ApertureParams { apodization, ..a.clone() }, 5e6, 1540.0, 0.0, rx, &grid).unwrap();
            let plan = DasPlan::new(&dp, &TxWave::PlaneWave { tilt: 0.0 }, &grid, 4000).unwrap().projection();
            for (q, r) in q.iter().zip(&plan) {
                assert!((q[0] - r[0]).abs() < 1e-4 && (q[1] - r[1]).abs() < 1e-4, "{apodization:?}: {q:?} vs {plan:?}");
            }
            hann = q;
        }
        assert!(
            hann[0] != p[0] && (f64::from(hann[0][0]) - nom[0]).abs() < (f64::from(p[0][0]) - nom[0]).abs(),
            "{hann:?} vs {p:?}"
        );
        // Amplitude weights (element width 0.265 mm at 5 MHz): the oblique elements of the −15°
        // sub-aperture receive less, so the effective receive angle and |a_x| are smaller.
        let wp =
            aperture_projection(&ApertureParams { width: Some(0.265e-3), ..a }, 5e6, 1540.0, 0.0, rx, &grid).unwrap();
        assert!(wp[0][0].abs() < 0.95 * p[0][0].abs() && wp[0][0].abs() > 0.5 * p[0][0].abs(), "{wp:?} vs {p:?}");
    }

    #[test]
    fn doppler_params_errors_name_the_field() {
        let bad = |v: serde_json::Value, needle: &str| {
            let e = validate_doppler(&v).unwrap_err();
            assert!(e.contains(needle), "{e}");
        };
        bad(serde_json::json!({"lag": 0}), "lag");
        bad(serde_json::json!({"window": [0, 3]}), "window");
        bad(serde_json::json!({"clutter_order": 20}), "clutter_order");
        bad(serde_json::json!({"aperture": {"pitch": 3e-4, "n_elements": 128, "fnumber": 0.0}}), "fnumber");
        bad(serde_json::json!({"estimator": "music"}), "estimator");
        let e = validate_beamformer(&serde_json::json!({"rx_angles_deg": [95.0]})).unwrap_err();
        assert!(e.contains("rx_angles_deg[0]"), "{e}");
        let e = validate_beamformer(&serde_json::json!({"fnumber": 0.0})).unwrap_err();
        assert!(e.contains("fnumber > 0"), "{e}");
        let e = validate_beamformer(&serde_json::json!({"demod_fc": -3.6e6})).unwrap_err();
        assert!(e.contains("demod_fc") && e.contains("Hz"), "{e}");
    }

    /// Looks of one angle in two bands stay two looks (streams per (tilt, angle, fc)), and the
    /// vector solve weights each by fc²: uniform phase ramps of a known velocity (v_D = a·v,
    /// phase step 4π fc v_D / (c PRF) per frame) give it back exactly; a look made 10 % wrong
    /// moves the solution as the weighted normal equations, computed here independently, say.
    #[test]
    fn looks_in_two_bands_are_kept_apart_and_weighted_by_fc_squared() {
        let (nx, nz, n_frames) = (3usize, 2usize, 16usize);
        let (c, prf) = (1540.0, 1e4);
        let v = [0.20, -0.05];
        let looks = [(-15.0f64, 3.6e6), (15.0, 3.6e6), (0.0, 3.6e6), (0.0, 5e6)];
        let run = |wrong: Option<usize>| {
            let mut node = DopplerNode::new(DopplerNodeParams::default(), Estimator::Autocorrelation).unwrap();
            for (j, &(deg, fc)) in looks.iter().enumerate() {
                let a = sonoflow_beamform::nominal_projection(0.0, deg.to_radians());
                let vd = (a[0] * v[0] + a[1] * v[1]) * if wrong == Some(j) { 1.1 } else { 1.0 };
                let step = 4.0 * std::f64::consts::PI * fc * vd / (c * prf);
                for n in 0..n_frames {
                    let h = IqFrameHeaderV1 {
                        grid: GridV1 { x0: 0.0, z0: 0.02, dx: 1e-4, dz: 1e-4, nx: nx as u32, nz: nz as u32 },
                        fc,
                        c,
                        prf,
                        rx_angle: deg.to_radians(),
                        frame_in_packet: n as u32,
                        ..Default::default()
                    };
                    let z = Complex32 { re: (step * n as f64).cos() as f32, im: (step * n as f64).sin() as f32 };
                    assert!(node.push(&h, &vec![z; nx * nz]).unwrap().is_none());
                }
            }
            node.finish().unwrap().unwrap()
        };
        let r = run(None);
        assert_eq!(r.maps.len(), 4, "four looks, two of them at 0°");
        let fcs: Vec<f64> = r.maps.iter().map(|m| m.0.fc).collect();
        assert!(fcs.contains(&3.6e6) && fcs.contains(&5e6), "{fcs:?}");
        let n = nx * nz;
        // Each map carries the projection it was solved with, and its velocity is that
        // projection of the true velocity (what the evaluator's per-look errors rely on).
        for (mh, planes) in &r.maps {
            assert_eq!(mh.n_planes, 6);
            assert_eq!(&mh.plane_ids[4..6], &[plane::PROJECTION_X, plane::PROJECTION_Z]);
            let a = sonoflow_beamform::nominal_projection(mh.tx_angle, mh.rx_angle);
            for i in 0..n {
                let (vel, px, pz) = (planes[i], planes[4 * n + i], planes[5 * n + i]);
                assert_eq!((px, pz), (a[0] as f32, a[1] as f32));
                let want = f64::from(px) * v[0] + f64::from(pz) * v[1];
                assert!((f64::from(vel) - want).abs() < 1e-5, "{vel} vs {want}");
            }
        }
        let (vx, vz) = (&r.vector.1[..n], &r.vector.1[n..2 * n]);
        assert!(vx.iter().all(|x| (f64::from(*x) - v[0]).abs() < 1e-5), "{vx:?}");
        assert!(vz.iter().all(|z| (f64::from(*z) - v[1]).abs() < 1e-5), "{vz:?}");
        // The 5 MHz look 10 % wrong: weighted least squares with w = (fc / 5 MHz)².
        let r = run(Some(3));
        let solve = |weighted: bool| {
            let (mut m, mut b) = ([0.0f64; 3], [0.0f64; 2]);
            for (j, &(deg, fc)) in looks.iter().enumerate() {
                let a = sonoflow_beamform::nominal_projection(0.0, deg.to_radians());
                let vd = (a[0] * v[0] + a[1] * v[1]) * if j == 3 { 1.1 } else { 1.0 };
                let w = if weighted { (fc / 5e6).powi(2) } else { 1.0 };
                m = [m[0] + w * a[0] * a[0], m[1] + w * a[0] * a[1], m[2] + w * a[1] * a[1]];
                b = [b[0] + w * a[0] * vd, b[1] + w * a[1] * vd];
            }
            let det = m[0] * m[2] - m[1] * m[1];
            [(m[2] * b[0] - m[1] * b[1]) / det, (m[0] * b[1] - m[1] * b[0]) / det]
        };
        let (want, unweighted) = (solve(true), solve(false));
        let got = [f64::from(r.vector.1[0]), f64::from(r.vector.1[n])];
        assert!((got[0] - want[0]).abs() < 1e-5 && (got[1] - want[1]).abs() < 1e-5, "{got:?} vs {want:?}");
        // … not the unweighted solution (7e-4 m/s apart here, 70 × the tolerance above): the
        // 5 MHz look weighs (5/3.6)² = 1.93 times more.
        assert!((unweighted[1] - want[1]).abs() > 30.0 * 1e-5, "weighted {want:?}, unweighted {unweighted:?}");
    }
}
