//! The multi-look beamformer: each RF frame → RF→I/Q (MUST `rf2iq`) → delay-and-sum onto one
//! grid for the frame's plane-wave tilt, once per receive angle (receive sub-apertures at one
//! f-number) → one I/Q image per look. `demod_fc` and `bandwidth` are one value or one per
//! receive angle (each look in its own band; an angle may repeat in another band). DAS plans are
//! built on the first frame of each (tilt, RF length, fs, t0, probe) and reused (at most 64 kept).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::error::{BeamformError, Result};
use crate::{Apodization, DasParams, DasPlan, Grid, Interpolation, Rf2Iq, Rf2IqParams, RfView, TxWave, C32};

/// What the beamformer needs to know of an RF frame (element-major real f32 samples).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RfInfo {
    /// Sampling frequency (Hz).
    pub fs: f64,
    /// Time of the first sample (s) relative to the transmit.
    pub t0: f64,
    /// Centre frequency (Hz).
    pub fc: f64,
    /// Speed of sound (m/s).
    pub c: f64,
    /// Element pitch (m).
    pub pitch: f64,
    /// Plane-wave tilt of the transmit (rad).
    pub tx_angle: f64,
    /// Radius of curvature of a convex array (m); None = linear array.
    pub radius: Option<f64>,
    /// Elements (channels).
    pub n_elements: usize,
    /// Samples per channel.
    pub n_samples: usize,
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

    fn check(
        &self,
        field: &str,
        n_angles: usize,
        ok: impl Fn(f64) -> bool,
        range: &str,
    ) -> std::result::Result<(), String> {
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

/// Parameters of the multi-look beamformer (the `beamformer` node's params).
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct BeamformerParams {
    /// Imaging grid; default 20 × 20 mm from 10 mm depth, 0.25 mm spacing (81 × 81).
    pub grid: Grid,
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
            grid: Grid { x0: -0.01, z0: 0.01, dx: 0.25e-3, dz: 0.25e-3, nx: 81, nz: 81 },
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
    /// Checks every field; the message names the field and its allowed range.
    pub fn validate(&self) -> std::result::Result<(), String> {
        self.grid.validate().map_err(|e| format!("grid: {e}"))?;
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

/// Bit-exact key of everything a DAS plan depends on besides the node parameters.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
struct PlanKey {
    bits: [u64; 7],
    n_elements: usize,
    n_samples: usize,
}

fn plan_key(h: &RfInfo) -> PlanKey {
    PlanKey {
        bits: [
            h.fs.to_bits(),
            h.t0.to_bits(),
            h.fc.to_bits(),
            h.c.to_bits(),
            h.pitch.to_bits(),
            h.tx_angle.to_bits(),
            h.radius.unwrap_or(0.0).to_bits(),
        ],
        n_elements: h.n_elements,
        n_samples: h.n_samples,
    }
}

/// RF → I/Q → delay-and-sum for several receive angles (looks), each in its own band if asked;
/// DAS plans cached per (RF geometry, transmit tilt), demodulators per band.
pub struct MultiLookBeamformer {
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

impl MultiLookBeamformer {
    /// Validates `params` (the error names the field).
    pub fn new(params: BeamformerParams) -> std::result::Result<Self, String> {
        params.validate()?;
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
    pub fn demod_fc(&self, h: &RfInfo, j: usize) -> f64 {
        self.band_of.get(j).and_then(|&b| self.bands[b].demod_fc).unwrap_or(h.fc)
    }

    /// Receive angles (rad).
    pub fn rx_angles(&self) -> Vec<f64> {
        self.params.rx_angles_deg.iter().map(|a| a.to_radians()).collect()
    }

    /// Demodulates one RF frame (element-major f32) and prepares the DAS plans for it. Call
    /// [`MultiLookBeamformer::image`] for each receive angle afterwards.
    pub fn demodulate(&mut self, h: &RfInfo, rf: &[f32]) -> Result<()> {
        let (ns, ne) = (h.n_samples, h.n_elements);
        for band in &mut self.bands {
            let fd = band.demod_fc.unwrap_or(h.fc);
            let key = [fd.to_bits(), h.fs.to_bits(), h.t0.to_bits()];
            if band.rf2iq.as_ref().is_none_or(|r| r.0 != key) {
                let mut p = Rf2IqParams::new(fd, h.fs, band.bandwidth);
                p.t0 = h.t0;
                band.rf2iq = Some((key, Rf2Iq::new(p)?));
            }
            let Some((_, r2i)) = band.rf2iq.as_mut() else {
                return Err(BeamformError::ConfigMismatch { what: "no demodulator".into() });
            };
            band.iq.resize(ns * ne, C32::new(0.0, 0.0));
            r2i.process(RfView::element_major(rf, ns, ne), &mut band.iq)?;
        }
        let pk = plan_key(h);
        if !self.plans.contains_key(&pk) {
            if self.plans.len() >= 64 {
                self.plans.clear();
            }
            let grid = self.params.grid.clone();
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
                    radius: h.radius,
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
    pub fn image(&self, h: &RfInfo, j: usize, out: &mut [C32]) -> Result<()> {
        let mismatch = |what: String| BeamformError::ConfigMismatch { what };
        let plans = self.plans.get(&plan_key(h)).ok_or_else(|| mismatch("no DAS plan for this frame".into()))?;
        let plan = plans.get(j).ok_or_else(|| mismatch(format!("receive angle {j} out of range")))?;
        let band = self.band_of.get(j).and_then(|&b| self.bands.get(b));
        let iq = band.ok_or_else(|| mismatch(format!("receive angle {j} out of range")))?;
        plan.apply(&iq.iq, out)
    }

    /// The parameters.
    pub fn params(&self) -> &BeamformerParams {
        &self.params
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// `demod_fc` moves the demodulation: a 3.6 MHz tone on every element becomes a constant
    /// (DC) I/Q trace when demodulated at 3.6 MHz, a 1.4 MHz beat at the RF's fc (5 MHz); the I/Q
    /// header then carries 3.6 MHz (`demod_fc`), which the Doppler node uses to convert phase to velocity.
    #[test]
    fn demod_fc_sets_the_demodulation_and_the_iq_fc() {
        let (ns, ne, fs) = (400usize, 4usize, 20e6);
        let h = RfInfo {
            fs,
            t0: 0.0,
            fc: 5e6,
            c: 1540.0,
            pitch: 0.3e-3,
            tx_angle: 0.0,
            radius: None,
            n_elements: ne,
            n_samples: ns,
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
            let mut bf = MultiLookBeamformer::new(p).unwrap();
            bf.demodulate(&h, &rf).unwrap();
            let fc = bf.demod_fc(&h, 0);
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
        let mut bf = MultiLookBeamformer::new(p).unwrap();
        bf.demodulate(&h, &rf).unwrap();
        assert_eq!((bf.demod_fc(&h, 0), bf.demod_fc(&h, 1)), (3.6e6, 5e6));
        let amp = |j: usize| bf.bands[bf.band_of[j]].iq[100..300].iter().map(|c| c.norm()).sum::<f32>() / 200.0;
        assert!(amp(0) > 0.4 && amp(1) < 0.05, "3.6 MHz look {} (tone kept), 5 MHz look {} (rejected)", amp(0), amp(1));
    }

    #[test]
    fn per_angle_band_lists_are_checked() {
        let parse = |v: serde_json::Value| serde_json::from_value::<BeamformerParams>(v).unwrap();
        let err = |v: serde_json::Value| parse(v).validate().unwrap_err();
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
        parse(serde_json::json!({"rx_angles_deg": [0.0, 0.0], "demod_fc": [3.6e6, 5e6]})).validate().unwrap();
        parse(serde_json::json!({"rx_angles_deg": [-15.0, 15.0], "demod_fc": 3.6e6, "bandwidth": [20.0, 30.0]}))
            .validate()
            .unwrap();
    }
}
