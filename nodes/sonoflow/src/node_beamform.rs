//! `beamformer` and `doppler` / `doppler-loupas` nodes: thin wrappers of `sonoflow-beamform`.
//!
//! * `beamformer`: each RF frame → RF→I/Q (MUST `rf2iq`) → delay-and-sum onto `grid` for the
//!   frame's plane-wave tilt, once per receive angle in `rx_angles_deg` (receive sub-apertures,
//!   f-number `fnumber`) → one I/Q image per receive angle. DAS plans are built on the first
//!   frame of each (tilt, RF length, fs, t0, probe) and reused. `demod_fc` and `bandwidth` are
//!   one value or one per receive angle (each look in its own band; an angle may repeat in
//!   another band).
//! * `doppler` (lag-L autocorrelation, eq. 19) and `doppler-loupas` (Loupas 2-D autocorrelator):
//!   collect the I/Q images of a packet per look (transmit tilt, receive angle, fc); at the end
//!   of the packet (a frame of the next packet, or end of stream) optionally clutter-filter them,
//!   estimate one Doppler map per look and solve the vector velocity by least squares over all
//!   looks (nominal plane-wave or per-pixel aperture projections; looks weighted by fc², equal
//!   weights when they share one band). Outputs: `vector` (vx, vz, flags, power)
//!   and, if connected, `maps` (velocity, power, normalised variance, flags per angle pair).
//!   The two kinds differ only in their default estimator, so a launch file swaps them by kind.

use crate::kinds::parse;
use crate::nodeutil::{for_each, Flow};
use serde::{Deserialize, Serialize};
use sonoflow_beamform::{
    ClutterFilter, DasParams, DasPlan, DopplerEstimator, DopplerMap, DopplerParams, Estimator, Grid, Interpolation,
    Packet, Projection, Rf2Iq, Rf2IqParams, RfView, TxWave, VectorField as BfVectorField, VectorInput, WindowShape,
    C32,
};
use sonoflow_messages::kinds::{DopplerMap as DopplerMapMsg, IqFrame, RfFrame, VectorField};
use sonoflow_messages::{
    plane, Complex32, DopplerMapHeaderV1, GridV1, IqFrameHeaderV1, MsgHeaderV1, VectorFieldHeaderV1, SAMPLE_RF_F32,
    VECTOR_RAW,
};
use sonoflow_node_kit::{process_cpu_ns, Kit};
use std::collections::BTreeMap;

/// Imaging grid (m): node (ix, iz) at (x0 + ix·dx, z0 + iz·dz).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct GridParams {
    pub x0: f64,
    pub z0: f64,
    pub dx: f64,
    pub dz: f64,
    pub nx: usize,
    pub nz: usize,
}

impl GridParams {
    fn to_grid(&self) -> Grid {
        Grid { x0: self.x0, z0: self.z0, dx: self.dx, dz: self.dz, nx: self.nx, nz: self.nz }
    }
}

/// A beamformer parameter given once for every receive angle or once per receive angle.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(untagged)]
pub enum PerAngle {
    /// The same value for every receive angle.
    One(f64),
    /// One value per `rx_angles_deg` entry.
    Each(Vec<f64>),
}

impl PerAngle {
    /// The value for receive angle number `j`.
    pub fn get(&self, j: usize) -> Option<f64> {
        match self {
            PerAngle::One(v) => Some(*v),
            PerAngle::Each(v) => v.get(j).copied(),
        }
    }

    fn check(&self, field: &str, n_angles: usize, ok: impl Fn(f64) -> bool, range: &str) -> Result<(), String> {
        match self {
            PerAngle::One(v) if !ok(*v) => Err(format!("{field} = {v} is out of range: {range}")),
            PerAngle::One(_) => Ok(()),
            PerAngle::Each(v) => {
                if v.len() != n_angles {
                    return Err(format!(
                        "{field} has {} entries: give one value or one per rx_angles_deg entry ({n_angles})",
                        v.len()
                    ));
                }
                match v.iter().enumerate().find(|(_, x)| !ok(**x)) {
                    Some((i, x)) => Err(format!("{field}[{i}] = {x} is out of range: {range}")),
                    None => Ok(()),
                }
            }
        }
    }
}

/// `beamformer` parameters.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct BeamformerParams {
    /// Imaging grid; default 20 × 20 mm from 10 mm depth, 0.25 mm spacing (81 × 81).
    pub grid: GridParams,
    /// Receive f-number (> 0 with steered receive; 0 = full aperture). Paper: 1.5 is typical.
    pub fnumber: f64,
    /// Receive steering angles (degrees), one I/Q image each. Paper: −15 and +15.
    pub rx_angles_deg: Vec<f64>,
    /// RF → I/Q low-pass: bandwidth in % of the demodulation frequency (absent: MUST's default
    /// cut-off min(2 fc/fs, 0.5)). One value for every receive angle, or a list with one entry
    /// per `rx_angles_deg` entry.
    pub bandwidth: Option<PerAngle>,
    /// Demodulation frequency (Hz) of RF → I/Q, also the I/Q images' `fc` (the Doppler nodes
    /// convert phase to velocity with it). Absent: the RF's centre frequency (MUST). A lower
    /// frequency with a narrow `bandwidth` keeps the sub-band below the grating-lobe onset
    /// `c / (pitch (1 + sin|θ_rx|))` of steered receive sub-apertures. One value, or a list with
    /// one entry per `rx_angles_deg` entry: each look in its own band (an angle may then appear
    /// twice, in two bands — e.g. the steered looks in a sub-band below their grating-lobe onset
    /// and the near-normal ones at the probe's fc, where the echoes are strongest in phase).
    pub demod_fc: Option<PerAngle>,
    /// Interpolation of the I/Q traces: `linear` (default) or `nearest`.
    pub interpolation: Interpolation,
}

impl Default for BeamformerParams {
    fn default() -> Self {
        Self {
            grid: GridParams { x0: -0.01, z0: 0.01, dx: 0.25e-3, dz: 0.25e-3, nx: 81, nz: 81 },
            fnumber: 1.5,
            rx_angles_deg: vec![-15.0, 15.0],
            bandwidth: None,
            demod_fc: None,
            interpolation: Interpolation::Linear,
        }
    }
}

impl BeamformerParams {
    fn check(&self) -> Result<(), String> {
        self.grid.to_grid().validate().map_err(|e| format!("grid: {e}"))?;
        if self.grid.nx * self.grid.nz > 4_000_000 {
            return Err(format!("grid: {} × {} pixels is out of range: at most 4 000 000", self.grid.nz, self.grid.nx));
        }
        if !(self.fnumber.is_finite() && (0.0..=1000.0).contains(&self.fnumber)) {
            return Err(format!("fnumber = {} is out of range: 0 ..= 1000 (0 = full aperture)", self.fnumber));
        }
        if self.rx_angles_deg.is_empty() || self.rx_angles_deg.len() > 16 {
            return Err(format!("rx_angles_deg has {} entries: 1 ..= 16 allowed", self.rx_angles_deg.len()));
        }
        for (i, a) in self.rx_angles_deg.iter().enumerate() {
            if !(a.is_finite() && a.abs() < 80.0) {
                return Err(format!("rx_angles_deg[{i}] = {a} is out of range: (-80, 80) degrees"));
            }
            if *a != 0.0 && self.fnumber == 0.0 {
                return Err(format!("rx_angles_deg[{i}] = {a} needs fnumber > 0 (a steered sub-aperture)"));
            }
        }
        let n = self.rx_angles_deg.len();
        if let Some(b) = &self.bandwidth {
            b.check("bandwidth", n, |b| b > 0.0 && b < 200.0, "(0, 200) % of fc")?;
        }
        if let Some(f) = &self.demod_fc {
            f.check("demod_fc", n, |f| f.is_finite() && f > 0.0 && f <= 1e9, "(0, 1e9] Hz (and below fs/2 of the RF)")?;
        }
        // Two looks of one angle must differ in their band (the Doppler node keeps a stream per
        // (transmit tilt, receive angle, fc)).
        for j in 0..n {
            for k in 0..j {
                let same_band = |p: &Option<PerAngle>| {
                    p.as_ref().map(|p| p.get(j).map(f64::to_bits)) == p.as_ref().map(|p| p.get(k).map(f64::to_bits))
                };
                if self.rx_angles_deg[j] == self.rx_angles_deg[k] && same_band(&self.demod_fc) {
                    return Err(format!(
                        "rx_angles_deg[{j}] = {} repeats rx_angles_deg[{k}] with the same demod_fc: a repeated angle needs its own demod_fc (a list, one per angle)",
                        self.rx_angles_deg[j]
                    ));
                }
            }
        }
        Ok(())
    }
}

pub fn validate_beamformer(v: &serde_json::Value) -> Result<(), String> {
    parse::<BeamformerParams>(v)?.check()
}

/// Bit-exact key of everything a DAS plan depends on besides the node parameters.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
struct PlanKey {
    bits: [u64; 6],
    n_elements: u32,
    n_samples: u32,
}

fn plan_key(h: &sonoflow_messages::RfFrameHeaderV1) -> PlanKey {
    PlanKey {
        bits: [h.fs.to_bits(), h.t0.to_bits(), h.fc.to_bits(), h.c.to_bits(), h.pitch.to_bits(), h.tx_angle.to_bits()],
        n_elements: h.n_channels,
        n_samples: h.n_samples,
    }
}

/// What the beamformer node does per RF frame, without IPC (used by the node and the tests).
pub struct Beamformer {
    params: BeamformerParams,
    /// The distinct RF → I/Q bands (demodulation frequency, bandwidth) of the receive angles.
    bands: Vec<Band>,
    /// Band of each receive angle.
    band_of: Vec<usize>,
    plans: BTreeMap<PlanKey, Vec<DasPlan>>,
}

/// One RF → I/Q band and the last frame demodulated in it.
struct Band {
    /// `demod_fc` (None: the RF's fc).
    demod_fc: Option<f64>,
    bandwidth: Option<f64>,
    /// (fd, fs, t0) bits the demodulator was built for.
    rf2iq: Option<([u64; 3], Rf2Iq)>,
    iq: Vec<C32>,
}

impl Beamformer {
    pub fn new(params: BeamformerParams) -> Result<Self, String> {
        params.check()?;
        let mut bands: Vec<Band> = Vec::new();
        let mut band_of = Vec::new();
        for j in 0..params.rx_angles_deg.len() {
            let fd = params.demod_fc.as_ref().and_then(|p| p.get(j));
            let bw = params.bandwidth.as_ref().and_then(|p| p.get(j));
            let same = |b: &Band| {
                b.demod_fc.map(f64::to_bits) == fd.map(f64::to_bits)
                    && b.bandwidth.map(f64::to_bits) == bw.map(f64::to_bits)
            };
            match bands.iter().position(same) {
                Some(i) => band_of.push(i),
                None => {
                    band_of.push(bands.len());
                    bands.push(Band { demod_fc: fd, bandwidth: bw, rf2iq: None, iq: Vec::new() });
                }
            }
        }
        Ok(Self { params, bands, band_of, plans: BTreeMap::new() })
    }

    /// Demodulation frequency of receive angle `j` for RF frame `h`: its `demod_fc` or the RF's
    /// centre frequency.
    pub fn demod_fc(&self, h: &sonoflow_messages::RfFrameHeaderV1, j: usize) -> f64 {
        self.band_of.get(j).and_then(|&b| self.bands[b].demod_fc).unwrap_or(h.fc)
    }

    /// Receive angles (rad).
    pub fn rx_angles(&self) -> Vec<f64> {
        self.params.rx_angles_deg.iter().map(|a| a.to_radians()).collect()
    }

    /// Demodulates one RF frame (element-major f32) and prepares the DAS plans for it. Call
    /// [`Beamformer::image`] for each receive angle afterwards.
    pub fn demodulate(&mut self, h: &sonoflow_messages::RfFrameHeaderV1, rf: &[f32]) -> anyhow::Result<()> {
        if h.sample_format != SAMPLE_RF_F32 {
            anyhow::bail!("RF frame {}: sample_format {} is not real f32 RF", h.common.frame_id, h.sample_format);
        }
        let (ns, ne) = (h.n_samples as usize, h.n_channels as usize);
        for band in &mut self.bands {
            let fd = band.demod_fc.unwrap_or(h.fc);
            let key = [fd.to_bits(), h.fs.to_bits(), h.t0.to_bits()];
            if band.rf2iq.as_ref().is_none_or(|r| r.0 != key) {
                let mut p = Rf2IqParams::new(fd, h.fs, band.bandwidth);
                p.t0 = h.t0;
                band.rf2iq = Some((key, Rf2Iq::new(p)?));
            }
            let Some((_, r2i)) = band.rf2iq.as_mut() else { anyhow::bail!("no demodulator") };
            band.iq.resize(ns * ne, C32::new(0.0, 0.0));
            r2i.process(RfView::element_major(rf, ns, ne), &mut band.iq)?;
        }
        let pk = plan_key(h);
        if !self.plans.contains_key(&pk) {
            if self.plans.len() >= 64 {
                self.plans.clear();
            }
            let grid = self.params.grid.to_grid();
            let tx = TxWave::PlaneWave { tilt: h.tx_angle };
            let mut v = Vec::new();
            for (j, rx) in self.rx_angles().into_iter().enumerate() {
                let dp = DasParams {
                    fc: self.demod_fc(h, j),
                    c: h.c,
                    fs: h.fs,
                    t0: h.t0,
                    pitch: h.pitch,
                    n_elements: ne,
                    fnumber: self.params.fnumber,
                    rx_angle: rx,
                    interpolation: self.params.interpolation,
                };
                v.push(DasPlan::new(&dp, &tx, &grid, ns)?);
            }
            self.plans.insert(pk, v);
        }
        Ok(())
    }

    /// Beamforms the last demodulated frame for receive angle number `j` into `out` (nz·nx).
    pub fn image(&self, h: &sonoflow_messages::RfFrameHeaderV1, j: usize, out: &mut [C32]) -> anyhow::Result<()> {
        let plans = self.plans.get(&plan_key(h)).ok_or_else(|| anyhow::anyhow!("no DAS plan for this frame"))?;
        let plan = plans.get(j).ok_or_else(|| anyhow::anyhow!("receive angle {j} out of range"))?;
        let band = self.band_of.get(j).and_then(|&b| self.bands.get(b));
        let iq = band.ok_or_else(|| anyhow::anyhow!("receive angle {j} out of range"))?;
        plan.apply(&iq.iq, out)?;
        Ok(())
    }

    /// The I/Q header of receive angle `j` for RF frame `h`.
    pub fn iq_header(&self, h: &sonoflow_messages::RfFrameHeaderV1, j: usize) -> IqFrameHeaderV1 {
        let g = &self.params.grid;
        let n_rx = self.params.rx_angles_deg.len() as u64;
        let mut ih = IqFrameHeaderV1 {
            grid: GridV1 { x0: g.x0, z0: g.z0, dx: g.dx, dz: g.dz, nx: g.nx as u32, nz: g.nz as u32 },
            fc: self.demod_fc(h, j),
            c: h.c,
            prf: h.prf,
            rx_angle: self.params.rx_angles_deg[j].to_radians(),
            tx_angle: h.tx_angle,
            packet: h.packet,
            frame_in_packet: h.frame_in_packet,
            tx_id: h.tx_id,
            ..Default::default()
        };
        ih.common = MsgHeaderV1 {
            frame_id: h.common.frame_id * n_rx + j as u64,
            t_valid: h.common.t_valid,
            ..Default::default()
        };
        ih
    }
}

pub fn run_beamformer(mut kit: Kit) -> anyhow::Result<()> {
    let p: BeamformerParams = parse(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    let mut bf = Beamformer::new(p).map_err(anyhow::Error::msg)?;
    let mut input = kit.input::<RfFrame>("rf")?;
    let mut out = kit.output::<IqFrame>("iq")?;
    kit.handshake(&mut [&mut input, &mut out])?;
    let n_rx = bf.params.rx_angles_deg.len();
    let mut img = vec![C32::new(0.0, 0.0); bf.params.grid.nx * bf.params.grid.nz];
    let mut last_t = 0.0;
    for_each(&mut kit, &mut input, |kit, sample| {
        let t0 = process_cpu_ns();
        let h = *sample.user_header();
        bf.demodulate(&h, sample.payload())?;
        let demod_ns = process_cpu_ns() - t0;
        kit.stats.messages_in += 1;
        for j in 0..n_rx {
            let t1 = process_cpu_ns();
            bf.image(&h, j, &mut img)?;
            let mut ih = bf.iq_header(&h, j);
            let compute = process_cpu_ns() - t1 + if j == 0 { demod_ns } else { 0 };
            ih.common.compute_ns = compute;
            out.publish_in_place(img.len(), ih, |dst| {
                for (d, s) in dst.iter_mut().zip(&img) {
                    d.write(Complex32 { re: s.re, im: s.im });
                }
            })?;
            kit.stats.messages_out += 1;
            kit.stats.bytes_out += (img.len() * 8) as u64;
            kit.record(ih.common.frame_id, ih.common.t_valid, compute)?;
        }
        last_t = h.common.t_valid;
        Ok(Flow::Continue)
    })?;
    out.publish_eos(last_t)?;
    kit.stats.gaps = input.gaps;
    kit.finish()?;
    Ok(())
}

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
    parse::<DopplerNodeParams>(v)?.check()
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
                let inside = if rx == 0.0 {
                    dx.abs() <= z / 2.0 / a.fnumber
                } else {
                    (dx - z * tan_rx).abs() <= z / cos_rx / 2.0 / a.fnumber
                };
                let r = dx.hypot(z);
                if !inside || r <= 0.0 {
                    continue;
                }
                let (sin_t, cos_t) = (dx / r, z / r);
                let w = match a.width {
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

/// One packet's frames of one (tx angle, rx angle) pair.
struct Stream {
    header: IqFrameHeaderV1,
    frames: Vec<Vec<C32>>,
}

/// Products of one packet.
pub struct PacketResult {
    /// One Doppler map header + planes (velocity, power, variance, flags) per angle pair.
    pub maps: Vec<(DopplerMapHeaderV1, Vec<f32>)>,
    /// The vector field header + planes (vx, vz, flags, power).
    pub vector: (VectorFieldHeaderV1, Vec<f32>),
}

/// (tx angle, rx angle, grid x0/z0/dx/dz, nx, nz), as bits.
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
    /// Per-pixel projections per (tx, rx, grid) when `aperture` is set.
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
        let mut power_sum = vec![0.0f32; n];
        let mut look_power: Vec<Vec<f32>> = Vec::new();
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
            for (ps, p) in power_sum.iter_mut().zip(&self.map.power) {
                *ps += p;
            }
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
            look_power.push(self.map.power.clone());
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
        if let Some(a) = &self.params.aperture {
            let g = first.grid;
            let grid = Grid { x0: g.x0, z0: g.z0, dx: g.dx, dz: g.dz, nx: g.nx as usize, nz: g.nz as usize };
            for (tx, rx, fc) in &angles {
                let key =
                    (tx.to_bits(), rx.to_bits(), fc.to_bits(), [g.x0, g.z0, g.dx, g.dz].map(f64::to_bits), g.nx, g.nz);
                if let std::collections::btree_map::Entry::Vacant(e) = self.projections.entry(key) {
                    e.insert(aperture_projection(a, *fc, first.c, *tx, *rx, &grid)?);
                }
            }
        }
        let g = first.grid;
        let projections: Vec<Option<&Vec<[f32; 2]>>> = angles
            .iter()
            .map(|(tx, rx, fc)| {
                self.projections.get(&(
                    tx.to_bits(),
                    rx.to_bits(),
                    fc.to_bits(),
                    [g.x0, g.z0, g.dx, g.dz].map(f64::to_bits),
                    g.nx,
                    g.nz,
                ))
            })
            .collect();
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
        let k = velocities.len() as f32;
        if angles.iter().any(|a| a.2.to_bits() != first.fc.to_bits()) {
            let means: Vec<f64> =
                look_power.iter().map(|p| p.iter().map(|&v| f64::from(v)).sum::<f64>() / n as f64).collect();
            let overall = means.iter().sum::<f64>() / means.len() as f64;
            for (i, ps) in power_sum.iter_mut().enumerate() {
                let rel: f64 =
                    look_power.iter().zip(&means).map(|(p, &m)| if m > 0.0 { f64::from(p[i]) / m } else { 0.0 }).sum();
                *ps = (rel * overall) as f32;
            }
        }
        let mut planes = Vec::with_capacity(4 * n);
        planes.extend_from_slice(&self.vec.vx);
        planes.extend_from_slice(&self.vec.vz);
        planes.extend(self.vec.flags.iter().map(|f| *f as f32));
        planes.extend(power_sum.iter().map(|p| p / k));
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

fn run_doppler_with(mut kit: Kit, default: Estimator) -> anyhow::Result<()> {
    let p: DopplerNodeParams = parse(&kit.cfg.params).map_err(anyhow::Error::msg)?;
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

    #[test]
    fn aperture_projection_is_nominal_inside_the_array_and_clipped_at_its_edge() {
        let a = ApertureParams { pitch: 0.3e-3, n_elements: 128, fnumber: 1.5, width: None };
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
        // Same aperture rule as the beamformer's DAS plan: its mean delay gradient gives the same
        // equal-weight projection (float32 gradients: 1e-4).
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
        };
        let plan = DasPlan::new(&dp, &TxWave::PlaneWave { tilt: 0.0 }, &grid, 4000).unwrap().projection();
        for (q, r) in p.iter().zip(&plan) {
            assert!((q[0] - r[0]).abs() < 1e-4 && (q[1] - r[1]).abs() < 1e-4, "{p:?} vs {plan:?}");
        }
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

    /// `demod_fc` moves the demodulation: a 3.6 MHz tone on every element becomes a constant
    /// (DC) I/Q trace when demodulated at 3.6 MHz, a 1.4 MHz beat at the RF's fc (5 MHz); the I/Q
    /// header then carries 3.6 MHz, which the Doppler nodes use to convert phase to velocity.
    #[test]
    fn demod_fc_sets_the_demodulation_and_the_iq_fc() {
        let (ns, ne, fs) = (400usize, 4usize, 20e6);
        let h = sonoflow_messages::RfFrameHeaderV1 {
            fs,
            fc: 5e6,
            c: 1540.0,
            pitch: 0.3e-3,
            prf: 1e4,
            n_channels: ne as u32,
            n_samples: ns as u32,
            sample_format: SAMPLE_RF_F32,
            ..Default::default()
        };
        let rf: Vec<f32> =
            (0..ne * ns).map(|k| (2.0 * std::f64::consts::PI * 3.6e6 * (k % ns) as f64 / fs).cos() as f32).collect();
        let phase_spread = |demod: Option<f64>| {
            let p = BeamformerParams {
                demod_fc: demod.map(PerAngle::One),
                bandwidth: Some(PerAngle::One(20.0)),
                fnumber: 1.0,
                ..Default::default()
            };
            let mut bf = Beamformer::new(p).unwrap();
            bf.demodulate(&h, &rf).unwrap();
            let fc = bf.iq_header(&h, 0).fc;
            // phase change along the middle of element 0's trace (away from the filter's edges)
            let mid = &bf.bands[0].iq[100..300];
            let dphi = mid.windows(2).map(|w| (w[1] * w[0].conj()).arg().abs()).fold(0.0f32, f32::max);
            (fc, dphi, mid.iter().map(|c| c.norm()).sum::<f32>() / 200.0)
        };
        let (fc, dphi, amp) = phase_spread(Some(3.6e6));
        assert_eq!(fc, 3.6e6);
        assert!(dphi < 1e-3 && amp > 0.4, "at 3.6 MHz the tone is DC: phase step {dphi}, amplitude {amp}");
        let (fc, _, amp) = phase_spread(None);
        assert_eq!(fc, 5e6);
        assert!(amp < 0.05, "a 20 % band around 5 MHz rejects the 3.6 MHz tone: amplitude {amp}");

        // Per-angle bands: the same angle twice, at 3.6 MHz (20 %) and at 5 MHz (20 %): each look
        // gets its own demodulation and its own `fc` in the I/Q header.
        let p = BeamformerParams {
            rx_angles_deg: vec![0.0, 0.0],
            demod_fc: Some(PerAngle::Each(vec![3.6e6, 5e6])),
            bandwidth: Some(PerAngle::One(20.0)),
            fnumber: 1.0,
            ..Default::default()
        };
        let mut bf = Beamformer::new(p).unwrap();
        bf.demodulate(&h, &rf).unwrap();
        assert_eq!((bf.iq_header(&h, 0).fc, bf.iq_header(&h, 1).fc), (3.6e6, 5e6));
        assert_ne!(bf.iq_header(&h, 0).common.frame_id, bf.iq_header(&h, 1).common.frame_id);
        let amp = |j: usize| bf.bands[bf.band_of[j]].iq[100..300].iter().map(|c| c.norm()).sum::<f32>() / 200.0;
        assert!(amp(0) > 0.4 && amp(1) < 0.05, "3.6 MHz look {} (tone kept), 5 MHz look {} (rejected)", amp(0), amp(1));
    }

    #[test]
    fn per_angle_band_lists_are_checked() {
        let err = |v: serde_json::Value| validate_beamformer(&v).unwrap_err();
        let e = err(serde_json::json!({"rx_angles_deg": [-15.0, 0.0, 15.0], "demod_fc": [3.6e6, 5e6]}));
        assert!(e.contains("demod_fc has 2 entries") && e.contains("(3)"), "{e}");
        let e = err(serde_json::json!({"rx_angles_deg": [-15.0, 15.0], "bandwidth": [20.0, 250.0]}));
        assert!(e.contains("bandwidth[1] = 250") && e.contains("(0, 200)"), "{e}");
        let e = err(serde_json::json!({"rx_angles_deg": [-15.0, 15.0], "demod_fc": [3.6e6, 0.0]}));
        assert!(e.contains("demod_fc[1] = 0"), "{e}");
        // A repeated angle needs its own band.
        let e = err(serde_json::json!({"rx_angles_deg": [0.0, 15.0, 0.0]}));
        assert!(e.contains("rx_angles_deg[2] = 0 repeats rx_angles_deg[0]"), "{e}");
        let e = err(serde_json::json!({"rx_angles_deg": [0.0, 0.0], "demod_fc": 3.6e6}));
        assert!(e.contains("repeats"), "{e}");
        validate_beamformer(&serde_json::json!({"rx_angles_deg": [0.0, 0.0], "demod_fc": [3.6e6, 5e6]})).unwrap();
        validate_beamformer(
            &serde_json::json!({"rx_angles_deg": [-15.0, 15.0], "demod_fc": 3.6e6, "bandwidth": [20.0, 30.0]}),
        )
        .unwrap();
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
