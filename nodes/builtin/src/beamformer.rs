//! `beamformer` node: a thin wrapper of `sonoflow-beamform`.
//!
//! Each RF frame → RF→I/Q (MUST `rf2iq`) → delay-and-sum onto `grid` for the frame's plane-wave
//! tilt, once per receive angle in `rx_angles_deg` (receive sub-apertures, f-number `fnumber`) →
//! one I/Q image per receive angle. DAS plans are built on the first frame of each (tilt, RF
//! length, fs, t0, probe) and reused. `demod_fc` and `bandwidth` are one value or one per receive
//! angle (each look in its own band; an angle may repeat in another band). The Doppler nodes that
//! consume the I/Q are in [`crate::node_doppler`].

use serde::{Deserialize, Serialize};
use sonoflow_beamform::{
    Apodization, DasParams, DasPlan, Grid, Interpolation, Rf2Iq, Rf2IqParams, RfView, TxWave, C32,
};
use sonoflow_messages::types::{IqFrame, RfFrame};
use sonoflow_messages::MessageType::*;
use sonoflow_messages::{
    Complex32, GridV1, IqFrameHeaderV2, MsgHeaderV1, APODIZATION_BOXCAR, APODIZATION_HANN, SAMPLE_RF_F32,
};
use sonoflow_node_kit::parse_params;
use sonoflow_node_kit::PortDir::*;
use sonoflow_node_kit::{for_each, Flow};
use sonoflow_node_kit::{port, KindSpec};
use sonoflow_node_kit::{process_cpu_ns, Kit};
use std::collections::BTreeMap;

/// The `beamformer` node kind.
pub const SPEC: KindSpec = KindSpec {
    name: "beamformer",
    about: "RF → I/Q (MUST rf2iq) → delay-and-sum on a grid, one I/Q image per receive sub-aperture angle",
    ports: &[port("rf", In, RfFrameV2, true), port("iq", Out, IqFrameV2, true)],
    dynamic_inputs: false,
    dynamic_outputs: false,
    validate: validate_beamformer,
    check_wiring: None,
    input_files: &[],
    run: run_beamformer,
};

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
    /// Receive apodisation across each pixel's aperture: `boxcar` (default, MUST) or `hann`
    /// (side lobes below −31 dB instead of −13 dB, main lobe ~1.6× wider). It travels in the
    /// I/Q header with the rest of the receive aperture.
    pub apodization: Apodization,
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
            apodization: Apodization::Boxcar,
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
    parse_params::<BeamformerParams>(v)?.check()
}

/// Bit-exact key of everything a DAS plan depends on besides the node parameters.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
struct PlanKey {
    bits: [u64; 6],
    n_elements: u32,
    n_samples: u32,
}

fn plan_key(h: &sonoflow_messages::RfFrameHeaderV2) -> PlanKey {
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
    pub fn demod_fc(&self, h: &sonoflow_messages::RfFrameHeaderV2, j: usize) -> f64 {
        self.band_of.get(j).and_then(|&b| self.bands[b].demod_fc).unwrap_or(h.fc)
    }

    /// Receive angles (rad).
    pub fn rx_angles(&self) -> Vec<f64> {
        self.params.rx_angles_deg.iter().map(|a| a.to_radians()).collect()
    }

    /// Demodulates one RF frame (element-major f32) and prepares the DAS plans for it. Call
    /// [`Beamformer::image`] for each receive angle afterwards.
    pub fn demodulate(&mut self, h: &sonoflow_messages::RfFrameHeaderV2, rf: &[f32]) -> anyhow::Result<()> {
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
                    apodization: self.params.apodization,
                };
                v.push(DasPlan::new(&dp, &tx, &grid, ns)?);
            }
            self.plans.insert(pk, v);
        }
        Ok(())
    }

    /// Beamforms the last demodulated frame for receive angle number `j` into `out` (nz·nx).
    pub fn image(&self, h: &sonoflow_messages::RfFrameHeaderV2, j: usize, out: &mut [C32]) -> anyhow::Result<()> {
        let plans = self.plans.get(&plan_key(h)).ok_or_else(|| anyhow::anyhow!("no DAS plan for this frame"))?;
        let plan = plans.get(j).ok_or_else(|| anyhow::anyhow!("receive angle {j} out of range"))?;
        let band = self.band_of.get(j).and_then(|&b| self.bands.get(b));
        let iq = band.ok_or_else(|| anyhow::anyhow!("receive angle {j} out of range"))?;
        plan.apply(&iq.iq, out)?;
        Ok(())
    }

    /// The I/Q header of receive angle `j` for RF frame `h`.
    pub fn iq_header(&self, h: &sonoflow_messages::RfFrameHeaderV2, j: usize) -> IqFrameHeaderV2 {
        let g = &self.params.grid;
        let n_rx = self.params.rx_angles_deg.len() as u64;
        let mut ih = IqFrameHeaderV2 {
            grid: GridV1 { x0: g.x0, z0: g.z0, dx: g.dx, dz: g.dz, nx: g.nx as u32, nz: g.nz as u32 },
            fc: self.demod_fc(h, j),
            c: h.c,
            prf: h.prf,
            rx_angle: self.params.rx_angles_deg[j].to_radians(),
            tx_angle: h.tx_angle,
            packet: h.packet,
            frame_in_packet: h.frame_in_packet,
            tx_id: h.tx_id,
            pitch: h.pitch,
            element_width: h.element_width,
            fnumber: self.params.fnumber,
            n_elements: h.n_channels,
            apodization: match self.params.apodization {
                Apodization::Boxcar => APODIZATION_BOXCAR,
                Apodization::Hann => APODIZATION_HANN,
            },
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
    let p: BeamformerParams = parse_params(&kit.cfg.params).map_err(anyhow::Error::msg)?;
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

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// `demod_fc` moves the demodulation: a 3.6 MHz tone on every element becomes a constant
    /// (DC) I/Q trace when demodulated at 3.6 MHz, a 1.4 MHz beat at the RF's fc (5 MHz); the I/Q
    /// header then carries 3.6 MHz, which the Doppler nodes use to convert phase to velocity.
    #[test]
    fn demod_fc_sets_the_demodulation_and_the_iq_fc() {
        let (ns, ne, fs) = (400usize, 4usize, 20e6);
        let h = sonoflow_messages::RfFrameHeaderV2 {
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
}
