//! Scan sequences for streaming synthesis: what the `simus` node configures (probe, medium,
//! options, plane-wave tilts, transmit apodisation) and how it plans the frequency grid per
//! packet, without IPC.

use serde::{Deserialize, Serialize};

use crate::{
    FrequencyPlan, Medium, NoiseParams, Probe, Result, ScattererSlices, Simus, SimusError, SimusOptions, Transmit,
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
    /// The probe: a preset looked up, or the description.
    pub fn resolve(&self) -> Result<Probe> {
        match self {
            ProbeSpec::Preset(n) => Probe::preset(n),
            ProbeSpec::Full(p) => Ok(p.clone()),
        }
    }
}

/// How the frequency plan is chosen.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq)]
#[serde(rename_all = "kebab-case")]
pub enum PacketPlan {
    /// Fixed for each packet (same RF length and gain for every frame of a packet).
    PerPacket,
    /// MUST's rule, re-planned for every frame.
    PerCall,
}

/// A scan sequence: probe, medium, SIMUS options, plane-wave tilts and how the frequency plan
/// is chosen (the `simus` node's params).
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct ScanParams {
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
    pub plan: PacketPlan,
    /// Extra distance (m) the per-packet plan allows for scatterers moving during a packet.
    pub plan_margin: f64,
    /// Transmit apodisation: Tukey window over the elements with this taper fraction, in
    /// [0, 1] (0 = rectangular, MUST's default; 1 = Hann). A taper weakens the edge waves of the
    /// plane wave.
    pub tx_tukey: f64,
    /// Receive noise (`noise = { snr_db = …, seed = … }`, [`crate::noise`]); absent: none.
    pub noise: Option<NoiseParams>,
    /// Draw the transmit pressure fields (MUST `pfield`, quick options) over the region the
    /// scatterers occupied into the run report at the end (default true).
    pub field_figure: bool,
}

impl Default for ScanParams {
    fn default() -> Self {
        Self {
            probe: ProbeSpec::Preset("paper-5mhz".into()),
            medium: Medium::default(),
            options: SimusOptions::default(),
            tilts_deg: vec![0.0],
            prf: 10e3,
            plan: PacketPlan::PerPacket,
            plan_margin: 2e-3,
            tx_tukey: 0.0,
            noise: None,
            field_figure: true,
        }
    }
}

/// A validated scan: the probe and one transmit per tilt (tilt in rad, transmit).
pub struct Scan {
    /// The probe.
    pub probe: Probe,
    /// (tilt (rad), plane-wave transmit) per entry of `tilts_deg`.
    pub transmits: Vec<(f64, Transmit)>,
}

impl ScanParams {
    /// Validates every field and builds the transmits; `max_elements` bounds the probe's
    /// element count (what the caller can carry). The message names the field.
    pub fn scan(&self, max_elements: usize) -> std::result::Result<Scan, String> {
        let probe = self.probe.resolve().map_err(|e| format!("probe: {e}"))?;
        probe.validate().map_err(|e| e.to_string())?;
        self.medium.validate().map_err(|e| e.to_string())?;
        self.options.validate(probe.fc).map_err(|e| e.to_string())?;
        if probe.n_elements > max_elements {
            return Err(format!(
                "probe.n_elements = {} is out of range: 1 ..= {max_elements} (RF header delay table)",
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
        if let Some(n) = &self.noise {
            n.validate()?;
        }
        if !(self.plan_margin.is_finite() && (0.0..=1.0).contains(&self.plan_margin)) {
            return Err(format!("plan_margin = {} is out of range: 0 ..= 1 m", self.plan_margin));
        }
        Ok(Scan { probe, transmits })
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

/// Chooses the frequency plan frame by frame. Per packet, the plan (df, band, RF length) is fixed
/// at the first frame of each packet for the scatterers' largest element distance plus
/// `plan_margin`, so every frame of a packet has the same length and gain (MUST re-plans per
/// call, which changes the gain ∝ df between frames of a moving scene). If scatterers move beyond
/// the margin within a packet the plan is recomputed and [`PlanChoice::replanned_in_packet`] set.
pub struct FramePlanner {
    mode: PacketPlan,
    margin: f64,
    max_delay: f64,
    c: f64,
    x_ends: (f64, f64),
    plan: Option<FrequencyPlan>,
}

/// The plan of one frame.
pub struct PlanChoice {
    /// The frequency plan.
    pub plan: FrequencyPlan,
    /// True when scatterers moved beyond `plan_margin` within a packet and the plan changed.
    pub replanned_in_packet: bool,
}

impl FramePlanner {
    /// A planner for `scan` with the parameters `p`.
    pub fn new(p: &ScanParams, scan: &Scan) -> Self {
        let n = scan.probe.n_elements;
        Self {
            mode: p.plan,
            margin: p.plan_margin,
            max_delay: scan.transmits.iter().map(|(_, t)| t.max_delay()).fold(0.0, f64::max),
            c: p.medium.c,
            x_ends: (scan.probe.element_x(0), scan.probe.element_x(n - 1)),
            plan: None,
        }
    }

    /// The plan for a frame of scatterers `scat`; `first_in_packet` starts a new packet.
    pub fn plan(&mut self, simus: &Simus, scat: ScattererSlices<'_>, first_in_packet: bool) -> Result<PlanChoice> {
        let d = scat.max_element_distance(self.x_ends.0, self.x_ends.1);
        let mut replanned_in_packet = false;
        let replan = match (&self.plan, self.mode) {
            (None, _) | (_, PacketPlan::PerCall) => true,
            (Some(_), PacketPlan::PerPacket) if first_in_packet => true,
            (Some(pl), PacketPlan::PerPacket) => {
                let needed = d + simus.pulse_duration() * self.c;
                replanned_in_packet = needed > pl.max_distance;
                replanned_in_packet
            }
        };
        if replan {
            let margin = if self.mode == PacketPlan::PerPacket { self.margin } else { 0.0 };
            self.plan = Some(simus.plan_for_max_distance(d + margin, self.max_delay)?);
        }
        match &self.plan {
            Some(plan) => Ok(PlanChoice { plan: plan.clone(), replanned_in_packet }),
            None => Err(SimusError::InvalidParameter {
                field: "plan",
                value: "none".into(),
                allowed: "a frequency plan (internal error)",
            }),
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn transmit_fields_move_with_the_tilt() {
        // an independent check of the geometry: a plane wave tilted by θ (> 0 towards +x) moves
        // the insonified band by z·tan θ between two depths
        let p = ScanParams { tilts_deg: vec![0.0, 15.0], ..Default::default() };
        let scan = p.scan(256).unwrap();
        let f = scan.transmit_fields(&p.medium, [-0.03, 0.03, 0.01, 0.03], 121).unwrap();
        assert_eq!(f.len(), 2);
        let (nx, nz) = (f[0].nx, f[0].nz);
        assert!(nz >= 16 && f.iter().all(|t| t.rms.len() == nx * nz));
        // power-weighted lateral centre of a row
        let centre = |t: &TransmitField, iz: usize| {
            let row = &t.rms[iz * nx..(iz + 1) * nx];
            let w: f64 = row.iter().map(|v| v * v).sum();
            row.iter().enumerate().map(|(ix, v)| (t.x0 + ix as f64 * t.dx) * v * v).sum::<f64>() / w
        };
        let (top, bottom) = (0, nz - 1);
        let dz = (bottom - top) as f64 * f[0].dz;
        // 0°: centred and not moving; 15°: moving by dz·tan 15° = 5.4 mm (within 15 %)
        assert!(centre(&f[0], top).abs() < 2e-4 && centre(&f[0], bottom).abs() < 2e-4);
        let shift = centre(&f[1], bottom) - centre(&f[1], top);
        let want = dz * 15f64.to_radians().tan();
        assert!((shift / want - 1.0).abs() < 0.15, "shift {shift:.4} m, want {want:.4} m");
        assert!(scan.transmit_fields(&p.medium, [0.01, 0.0, 0.01, 0.02], 50).is_err());
    }

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
        let scan = |v: serde_json::Value| serde_json::from_value::<ScanParams>(v).unwrap().scan(256).map(|_| ());
        let e = scan(serde_json::json!({ "tx_tukey": 1.5 })).unwrap_err();
        assert!(e.contains("tx_tukey") && e.contains("0 ..= 1"), "{e}");
        assert!(scan(serde_json::json!({ "tx_tukey": 0.5 })).is_ok());
        let e = scan(serde_json::json!({ "tilts_deg": [0.0, 95.0] })).unwrap_err();
        assert!(e.contains("tilts_deg[1]"), "{e}");
    }
}

/// One transmit's RMS pressure (MUST `pfield`) on a grid: node (ix, iz) at
/// (x0 + ix·dx, z0 + iz·dz), row-major `iz·nx + ix`.
#[derive(Clone, Debug, PartialEq)]
pub struct TransmitField {
    /// Plane-wave tilt (rad).
    pub tilt: f64,
    pub x0: f64,
    pub dx: f64,
    pub nx: usize,
    pub z0: f64,
    pub dz: f64,
    pub nz: usize,
    pub rms: Vec<f64>,
}

impl Scan {
    /// The RMS pressure field of every transmit over `[x_min, x_max] × [z_min, z_max]` (m) on a
    /// grid of `nx` columns (rows in proportion, 16–240), with MUST's quick PFIELD options
    /// (−20 dB band, one sub-element per element, frequency step × 1.5): a picture of where each
    /// transmit insonifies, not a calibrated field.
    pub fn transmit_fields(&self, medium: &Medium, region: [f64; 4], nx: usize) -> crate::Result<Vec<TransmitField>> {
        let [x_min, x_max, z_min, z_max] = region;
        if !(region.iter().all(|v| v.is_finite()) && x_max > x_min && z_max > z_min && (2..=2000).contains(&nx)) {
            return Err(crate::error::invalid(
                "transmit_fields.region",
                format!("{region:?}, {nx} columns"),
                "x_max > x_min, z_max > z_min, 2–2000 columns",
            ));
        }
        let dx = (x_max - x_min) / (nx - 1) as f64;
        let nz = (((z_max - z_min) / dx).round() as usize + 1).clamp(16, 240);
        let dz = (z_max - z_min) / (nz - 1) as f64;
        let (mut xs, mut zs) = (Vec::with_capacity(nx * nz), Vec::with_capacity(nx * nz));
        for iz in 0..nz {
            for ix in 0..nx {
                xs.push(x_min + ix as f64 * dx);
                zs.push(z_min + iz as f64 * dz);
            }
        }
        let quick = crate::PfieldOptions {
            db_thresh: -20.0,
            frequency_step: 1.5,
            full_frequency_directivity: false,
            element_splitting: Some(1),
        };
        self.transmits
            .iter()
            .map(|(tilt, tx)| {
                let f = crate::pfield(&self.probe, medium, tx, &xs, &zs, &quick)?;
                Ok(TransmitField { tilt: *tilt, x0: x_min, dx, nx, z0: z_min, dz, nz, rms: f.rms })
            })
            .collect()
    }
}
