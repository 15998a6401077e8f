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
    /// Extra distance (m) the per-packet plan allows for scatterers moving during a packet, in
    /// [0, 1]. Absent (default): from the packet's first snapshot, what its scatterers can move
    /// during the packet ([`packet_margin`]: each one's speed × the packet's duration, plus
    /// one wavelength), or [`FALLBACK_PLAN_MARGIN`] without speeds or packet length.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plan_margin: Option<f64>,
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
            plan_margin: None,
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
        if let Some(m) = self.plan_margin.filter(|m| !(m.is_finite() && (0.0..=1.0).contains(m))) {
            return Err(format!("plan_margin = {m} is out of range: 0 ..= 1 m"));
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

/// The per-packet plan margin (m) when neither `plan_margin` nor the scatterers' motion is known.
pub const FALLBACK_PLAN_MARGIN: f64 = 2e-3;

/// How the scatterers of a packet's first snapshot move, for the automatic plan margin.
#[derive(Clone, Copy, Debug)]
pub struct PacketMotion<'a> {
    /// Speed (m/s) of each scatterer, in the order of the scatterer slices (0 for static ones).
    pub speed: &'a [f32],
    /// Time (s) from the packet's first frame to its last: (frames − 1) / PRF.
    pub duration: f64,
}

/// The automatic per-packet plan margin (m): how much farther than now the farthest scatterer
/// can be from an element by the end of the packet, bounded by
/// `max_s (d_s + |v_s| T) − max_s d_s + λ`, with `d_s` scatterer s's distance to the farther
/// end element (at `x_ends`, z = 0), `|v_s|` its speed and `T` the packet's duration. A scatterer
/// whose speed stays at most `|v_s|` changes its distance to an element by at most `|v_s| T`
/// whatever its path (triangle inequality); λ (`wavelength`) covers a speed-up (½ a T² ≤ λ up to
/// a = 2λ/T², 64 m/s² for 32 frames at 10 kHz and 5 MHz) and scatterers that appear next to the
/// farthest ones (fluid released at an inlet). Only the farthest scatterers matter: on the
/// carotid's 32-frame packets the margin is 0.36 mm at t = 10 ms and 0.99 mm at peak systole
/// (t = 0.1 s), where the farthest scatterer actually moved out by 0.01 and 0.10 mm; the fixed
/// margin was 2 mm. A scene that outruns it is re-planned ([`PlanChoice::replanned_in_packet`]).
/// Errors: a speed that is negative or not finite (names the row), lengths that differ, a
/// duration that is negative or not finite.
pub fn packet_margin(
    scat: ScattererSlices<'_>,
    motion: PacketMotion<'_>,
    x_ends: (f64, f64),
    wavelength: f64,
) -> Result<f64> {
    if motion.speed.len() != scat.len() {
        return Err(SimusError::LengthMismatch {
            field: "motion.speed",
            got: motion.speed.len(),
            expected: scat.len(),
        });
    }
    if !(motion.duration.is_finite() && motion.duration >= 0.0) {
        return Err(crate::error::invalid("motion.duration", motion.duration, "finite and >= 0 (s)"));
    }
    let (mut now, mut later) = (0.0f64, 0.0f64);
    for (row, ((x, z), v)) in scat.x.iter().zip(scat.z).zip(motion.speed).enumerate() {
        if !(v.is_finite() && *v >= 0.0) {
            return Err(crate::error::invalid("motion.speed", format!("{v} at row {row}"), "finite and >= 0 (m/s)"));
        }
        let (x, z) = (f64::from(*x), f64::from(*z));
        let dx = (x - x_ends.0).abs().max((x - x_ends.1).abs());
        let d = (dx * dx + z * z).sqrt();
        now = now.max(d);
        later = later.max(d + f64::from(*v) * motion.duration);
    }
    Ok(later - now + wavelength)
}

/// Chooses the frequency plan frame by frame. Per packet, the plan (df, band, RF length) is fixed
/// at the first frame of each packet for the scatterers' largest element distance plus the plan
/// margin (`plan_margin`, or [`packet_margin`] from the first snapshot's motion), so every frame
/// of a packet has the same length and gain (MUST re-plans per call, which changes the gain ∝ df
/// between frames of a moving scene). With the automatic margin a new packet keeps the previous
/// packet's plan while that plan covers the new packet's reach and is no longer than the
/// [`FALLBACK_PLAN_MARGIN`] plan would be, so a steady scene keeps one grid (and its cached static
/// echoes) from packet to packet. If scatterers move beyond the margin within a packet the plan is
/// recomputed and [`PlanChoice::replanned_in_packet`] set.
pub struct FramePlanner {
    mode: PacketPlan,
    margin: Option<f64>,
    max_delay: f64,
    c: f64,
    wavelength: f64,
    x_ends: (f64, f64),
    plan: Option<FrequencyPlan>,
}

/// The plan of one frame.
pub struct PlanChoice {
    /// The frequency plan.
    pub plan: FrequencyPlan,
    /// True when scatterers moved beyond the plan margin within a packet and the plan changed.
    pub replanned_in_packet: bool,
    /// The margin (m) this frame's packet needs, on a frame that starts a packet or re-plans (0
    /// for a per-call plan); None on the other frames of a packet.
    pub margin: Option<f64>,
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
            wavelength: p.medium.c / scan.probe.fc,
            x_ends: (scan.probe.element_x(0), scan.probe.element_x(n - 1)),
            plan: None,
        }
    }

    /// The plan for a frame of scatterers `scat`; `first_in_packet` starts a new packet. `motion`
    /// (the scatterers' speeds and the packet's duration) sets the margin of a new per-packet
    /// plan when `plan_margin` is absent; without it the margin is [`FALLBACK_PLAN_MARGIN`].
    pub fn plan(
        &mut self,
        simus: &Simus,
        scat: ScattererSlices<'_>,
        motion: Option<PacketMotion<'_>>,
        first_in_packet: bool,
    ) -> Result<PlanChoice> {
        let d = scat.max_element_distance(self.x_ends.0, self.x_ends.1);
        let pad = simus.pulse_duration() * self.c;
        let per_call = self.mode == PacketPlan::PerCall;
        let new_packet = per_call || first_in_packet || self.plan.is_none();
        // within a packet: keep the plan unless a scatterer is now beyond it
        let replanned_in_packet = !new_packet && self.plan.as_ref().is_some_and(|pl| d + pad > pl.max_distance);
        let mut margin = None;
        if new_packet || replanned_in_packet {
            let m = match (per_call, self.margin, motion) {
                (true, ..) => 0.0,
                (false, Some(m), _) => m,
                (false, None, Some(mo)) => packet_margin(scat, mo, self.x_ends, self.wavelength)?,
                (false, None, None) => FALLBACK_PLAN_MARGIN,
            };
            margin = Some(m);
            // automatic margin: a new packet keeps the previous packet's plan while it covers this
            // packet's reach and is no longer than the fixed margin's plan would be (same grid
            // from packet to packet, so the static echoes stay cached)
            let keep = !per_call
                && !replanned_in_packet
                && self.margin.is_none()
                && self.plan.as_ref().is_some_and(|pl| {
                    pl.max_distance >= d + m + pad && pl.max_distance <= d + m.max(FALLBACK_PLAN_MARGIN) + pad
                });
            if !keep {
                self.plan = Some(simus.plan_for_max_distance(d + m, self.max_delay)?);
            }
        }
        match &self.plan {
            Some(plan) => Ok(PlanChoice { plan: plan.clone(), replanned_in_packet, margin }),
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

    /// The automatic margin against its closed form: the slow farthest scatterer sets it unless a
    /// closer fast one can overtake it within the packet; bad speeds and durations are refused.
    #[test]
    fn packet_margin_is_the_farthest_reach_within_the_packet() {
        let (ends, lambda, t) = ((-19.05e-3, 19.05e-3), 0.308e-3, 3.1e-3);
        let dist = |x: f64, z: f64| (x - ends.0).abs().max((x - ends.1).abs()).hypot(z);
        let (x, z) = (vec![-30e-3f32, 0.0], vec![30e-3f32, 20e-3]);
        let rc = vec![1.0f32; 2];
        let scat = ScattererSlices { x: &x, z: &z, rc: &rc };
        let d_a = dist(f64::from(x[0]), f64::from(z[0]));
        // the near scatterer (27.6 mm) at 2 m/s reaches 33.8 mm: the far one (56.1 mm) decides
        let m = packet_margin(scat, PacketMotion { speed: &[0.1, 2.0], duration: t }, ends, lambda).unwrap();
        assert!((m - (f64::from(0.1f32) * t + lambda)).abs() < 1e-12, "{m}");
        // a closer one at 10 m/s overtakes it: d_c + 10·T − d_a + λ
        let (x, z) = (vec![-30e-3f32, -25e-3], vec![30e-3f32, 30e-3]);
        let scat = ScattererSlices { x: &x, z: &z, rc: &rc };
        let d_c = dist(f64::from(x[1]), f64::from(z[1]));
        let m = packet_margin(scat, PacketMotion { speed: &[0.0, 10.0], duration: t }, ends, lambda).unwrap();
        assert!(d_c < d_a && d_c + 10.0 * t > d_a);
        assert!((m - (d_c + 10.0 * t - d_a + lambda)).abs() < 1e-12, "{m}");
        // static scatterers or a one-frame packet: one wavelength
        let m = packet_margin(scat, PacketMotion { speed: &[0.3, 0.3], duration: 0.0 }, ends, lambda).unwrap();
        assert!((m - lambda).abs() < 1e-15);
        let e = packet_margin(scat, PacketMotion { speed: &[0.1, f32::NAN], duration: t }, ends, lambda).unwrap_err();
        assert!(e.to_string().contains("motion.speed") && e.to_string().contains("row 1"), "{e}");
        let e = packet_margin(scat, PacketMotion { speed: &[0.1], duration: t }, ends, lambda).unwrap_err();
        assert!(e.to_string().contains("motion.speed"), "{e}");
        let e = packet_margin(scat, PacketMotion { speed: &[0.1, 0.1], duration: -1.0 }, ends, lambda).unwrap_err();
        assert!(e.to_string().contains("motion.duration"), "{e}");
    }

    /// A packet of scatterers moving at constant velocity keeps the first frame's automatic plan
    /// to its last frame (no re-planning), on a shorter grid than the fixed 2 mm margin; an
    /// explicit `plan_margin` and the fallback without motion plan for d + margin.
    #[test]
    fn automatic_margin_keeps_one_plan_per_packet_on_a_shorter_grid() {
        let p = ScanParams::default();
        let scan = p.scan(256).unwrap();
        let simus = Simus::new(scan.probe.clone(), p.medium.clone(), p.options.clone()).unwrap();
        let (frames, prf) = (32usize, 10e3);
        let duration = (frames - 1) as f64 / prf;
        // a 20 × 20 mm patch from 15 mm depth, every scatterer at 0.5 m/s away from the array's
        // centre (the farthest ones moving away from the far end element fastest)
        let n = 400;
        let x0: Vec<f64> = (0..n).map(|i| -10e-3 + 20e-3 * (i % 20) as f64 / 19.0).collect();
        let z0: Vec<f64> = (0..n).map(|i| 15e-3 + 20e-3 * (i / 20) as f64 / 19.0).collect();
        let v: Vec<[f64; 2]> =
            x0.iter().zip(&z0).map(|(x, z)| [0.5 * x / x.hypot(*z), 0.5 * z / x.hypot(*z)]).collect();
        let speed = vec![0.5f32; n];
        let rc = vec![1.0f32; n];
        let mut planner = FramePlanner::new(&p, &scan);
        let mut first = None;
        for k in 0..frames {
            let t = k as f64 / prf;
            let x: Vec<f32> = (0..n).map(|i| (x0[i] + v[i][0] * t) as f32).collect();
            let z: Vec<f32> = (0..n).map(|i| (z0[i] + v[i][1] * t) as f32).collect();
            let scat = ScattererSlices { x: &x, z: &z, rc: &rc };
            let c = planner.plan(&simus, scat, Some(PacketMotion { speed: &speed, duration }), k == 0).unwrap();
            assert!(!c.replanned_in_packet, "frame {k}");
            assert_eq!(c.margin.is_some(), k == 0);
            if k == 0 {
                // |v| T + λ = 0.5 m/s · 3.1 ms + 0.308 mm = 1.86 mm
                let m = c.margin.unwrap();
                assert!((m - (0.5 * duration + 1540.0 / 5e6)).abs() < 1e-6, "{m}");
                first = Some(c.plan);
            } else {
                assert_eq!(Some(&c.plan), first.as_ref());
            }
        }
        // slow scatterers: the automatic grid is shorter than the fixed 2 mm margin's
        let (x, z): (Vec<f32>, Vec<f32>) =
            (x0.iter().map(|v| *v as f32).collect(), z0.iter().map(|v| *v as f32).collect());
        let scat = ScattererSlices { x: &x, z: &z, rc: &rc };
        let slow = vec![0.05f32; n];
        let d = scat.max_element_distance(scan.probe.element_x(0), scan.probe.element_x(127));
        let auto = FramePlanner::new(&p, &scan)
            .plan(&simus, scat, Some(PacketMotion { speed: &slow, duration }), true)
            .unwrap();
        let fixed = ScanParams { plan_margin: Some(2e-3), ..Default::default() };
        let fixed = FramePlanner::new(&fixed, &scan)
            .plan(&simus, scat, Some(PacketMotion { speed: &slow, duration }), true)
            .unwrap();
        let fallback = FramePlanner::new(&p, &scan).plan(&simus, scat, None, true).unwrap();
        assert_eq!(fixed.plan, simus.plan_for_max_distance(d + 2e-3, 0.0).unwrap());
        assert_eq!(fallback.plan, fixed.plan);
        assert!(auto.plan.n_bins() < fixed.plan.n_bins(), "{} vs {}", auto.plan.n_bins(), fixed.plan.n_bins());
        let e = ScanParams { plan_margin: Some(-1e-3), ..Default::default() }.scan(256).map(|_| ()).unwrap_err();
        assert!(e.contains("plan_margin") && e.contains("0 ..= 1 m"), "{e}");
    }

    /// With the automatic margin a new packet keeps the last plan while it covers the packet's
    /// reach and is at most the fixed margin's plan; otherwise (and always with an explicit
    /// `plan_margin`) it plans anew.
    #[test]
    fn automatic_margin_keeps_the_plan_across_steady_packets() {
        let p = ScanParams::default();
        let scan = p.scan(256).unwrap();
        let simus = Simus::new(scan.probe.clone(), p.medium.clone(), p.options.clone()).unwrap();
        let speed = [0.1f32];
        let motion = Some(PacketMotion { speed: &speed, duration: 3.1e-3 });
        let rc = [1.0f32];
        let plan_at = |planner: &mut FramePlanner, z: f32| {
            let scat = ScattererSlices { x: &[0.0], z: &[z], rc: &rc };
            planner.plan(&simus, scat, motion, true).unwrap()
        };
        let mut auto = FramePlanner::new(&p, &scan);
        let first = plan_at(&mut auto, 40e-3).plan;
        // 0.5 mm nearer: the plan still covers it and is only 0.5 mm longer than needed: kept
        let c = plan_at(&mut auto, 39.5e-3);
        assert_eq!(c.plan, first);
        assert!(c.margin.unwrap() > 0.0);
        // 5 mm nearer: 5 mm longer than needed: a new, shorter plan
        let near = plan_at(&mut auto, 35e-3).plan;
        assert!(near.n_freq < first.n_freq);
        // 0.1 mm farther than the last plan was made for: beyond its reach, a new plan
        let far = plan_at(&mut auto, 35.1e-3).plan;
        assert!(far.max_distance > near.max_distance);
        // an explicit margin plans every packet anew
        let fixed = ScanParams { plan_margin: Some(1e-3), ..Default::default() };
        let mut fixed = FramePlanner::new(&fixed, &scan);
        let a = plan_at(&mut fixed, 40e-3).plan;
        let b = plan_at(&mut fixed, 39.5e-3).plan;
        assert!(b.max_distance < a.max_distance);
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
