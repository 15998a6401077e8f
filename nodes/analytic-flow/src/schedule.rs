//! Plane-wave Doppler acquisition schedule: packets of frames at a fixed PRF.

use serde::{Deserialize, Serialize};

use crate::{require, ParamError};

/// Timing of a packetised Doppler acquisition.
///
/// Frame `k` of packet `p` is acquired at
/// `t_start + p * packet_interval + k / prf`. Packets must not overlap when
/// there is more than one (`packet_interval >= packet_size / prf`), so the
/// frame times are strictly increasing.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct Schedule {
    /// Pulse (frame) repetition frequency within a packet (Hz). Default 10 kHz.
    pub prf: f64,
    /// Frames per packet (Doppler ensemble length). Default 32.
    pub packet_size: u32,
    /// Number of packets. Default 1.
    pub n_packets: u32,
    /// Time between the starts of consecutive packets (s). Default 0.1.
    pub packet_interval: f64,
    /// Time of the first frame of the first packet (s). Default 0.
    pub t_start: f64,
}

impl Default for Schedule {
    fn default() -> Self {
        Self { prf: 10.0e3, packet_size: 32, n_packets: 1, packet_interval: 0.1, t_start: 0.0 }
    }
}

/// One frame of a [`Schedule`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AcquisitionTime {
    /// Acquisition time (s).
    pub t: f64,
    /// Packet index, 0-based.
    pub packet: u32,
    /// Frame index inside the packet, 0-based.
    pub frame_in_packet: u32,
    /// Global frame index over the whole schedule: `packet * packet_size + frame_in_packet`.
    pub frame_id: u64,
}

impl Schedule {
    /// Largest accepted PRF (Hz).
    pub const MAX_PRF: f64 = 1.0e7;
    /// Largest accepted total number of frames (`n_packets * packet_size`).
    pub const MAX_FRAMES: u64 = 10_000_000;
    /// Largest accepted `t_start` and `packet_interval` (s).
    pub const MAX_TIME: f64 = 1.0e6;

    /// Checks every field; the error names the field as `schedule.<name>`.
    pub fn validate(&self) -> Result<(), ParamError> {
        require(
            "schedule.prf",
            self.prf,
            self.prf.is_finite() && self.prf > 0.0 && self.prf <= Self::MAX_PRF,
            format!("finite, 0 < value <= {} Hz", Self::MAX_PRF),
        )?;
        require("schedule.packet_size", self.packet_size, self.packet_size >= 1, ">= 1")?;
        require("schedule.n_packets", self.n_packets, self.n_packets >= 1, ">= 1")?;
        require(
            "schedule.n_packets",
            self.n_packets,
            self.n_frames() <= Self::MAX_FRAMES,
            format!("n_packets * packet_size <= {} (packet_size = {})", Self::MAX_FRAMES, self.packet_size),
        )?;
        require(
            "schedule.t_start",
            self.t_start,
            self.t_start.is_finite() && (0.0..=Self::MAX_TIME).contains(&self.t_start),
            format!("finite, 0 <= value <= {} s", Self::MAX_TIME),
        )?;
        require(
            "schedule.packet_interval",
            self.packet_interval,
            self.packet_interval.is_finite() && (0.0..=Self::MAX_TIME).contains(&self.packet_interval),
            format!("finite, 0 <= value <= {} s", Self::MAX_TIME),
        )?;
        if self.n_packets > 1 {
            let duration = f64::from(self.packet_size) / self.prf;
            // Relative slack of 1e-12 so that an interval typed as exactly
            // packet_size / prf (continuous acquisition) is accepted.
            require(
                "schedule.packet_interval",
                self.packet_interval,
                self.packet_interval >= duration * (1.0 - 1e-12),
                format!(">= packet_size / prf = {duration} s when n_packets > 1 (packets must not overlap)"),
            )?;
        }
        Ok(())
    }

    /// Total number of frames, `n_packets * packet_size`.
    pub fn n_frames(&self) -> u64 {
        u64::from(self.n_packets) * u64::from(self.packet_size)
    }

    /// Time of frame `frame_in_packet` of packet `packet`:
    /// `t_start + packet * packet_interval + frame_in_packet / prf`.
    /// Meaningful for a valid schedule only.
    pub fn frame_time(&self, packet: u32, frame_in_packet: u32) -> f64 {
        self.t_start + f64::from(packet) * self.packet_interval + f64::from(frame_in_packet) / self.prf
    }

    /// All frame times in acquisition order (packet-major). Returns an empty
    /// vector if the schedule does not [`validate`](Self::validate).
    pub fn times(&self) -> Vec<AcquisitionTime> {
        if self.validate().is_err() {
            return Vec::new();
        }
        let mut out = Vec::with_capacity(usize::try_from(self.n_frames()).unwrap_or(0));
        for packet in 0..self.n_packets {
            for frame_in_packet in 0..self.packet_size {
                out.push(AcquisitionTime {
                    t: self.frame_time(packet, frame_in_packet),
                    packet,
                    frame_in_packet,
                    frame_id: u64::from(packet) * u64::from(self.packet_size) + u64::from(frame_in_packet),
                });
            }
        }
        out
    }

    /// Mean of the frame times of packet `p`:
    /// `t_start + p * packet_interval + (packet_size - 1) / (2 prf)`.
    /// Meaningful for a valid schedule only (`p` may exceed `n_packets`; the
    /// formula is simply extended).
    pub fn packet_mid_time(&self, p: u32) -> f64 {
        let half_span = f64::from(self.packet_size.saturating_sub(1)) / (2.0 * self.prf);
        self.t_start + f64::from(p) * self.packet_interval + half_span
    }

    /// Time of the last frame (`frame_time(n_packets - 1, packet_size - 1)`).
    pub fn end_time(&self) -> f64 {
        self.frame_time(self.n_packets.saturating_sub(1), self.packet_size.saturating_sub(1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sched() -> Schedule {
        Schedule { prf: 5.0e3, packet_size: 8, n_packets: 3, packet_interval: 0.05, t_start: 0.25 }
    }

    /// Times are a handful of f64 operations on O(1) values, so a 1e-12 s
    /// tolerance (a few thousand ulps) only guards against formula errors.
    #[test]
    fn packet_structure_and_frame_ids() {
        let s = sched();
        s.validate().expect("valid");
        let t = s.times();
        assert_eq!(t.len(), 24);
        assert_eq!(s.n_frames(), 24);
        for (i, a) in t.iter().enumerate() {
            assert_eq!(a.frame_id, i as u64);
            assert_eq!(a.packet, i as u32 / 8);
            assert_eq!(a.frame_in_packet, i as u32 % 8);
            let expect = 0.25 + f64::from(a.packet) * 0.05 + f64::from(a.frame_in_packet) / 5.0e3;
            assert!((a.t - expect).abs() < 1e-12, "{a:?}");
        }
        for w in t.windows(2) {
            assert!(w[1].t > w[0].t, "times strictly increasing");
            assert!(w[1].frame_id > w[0].frame_id);
            let dt = w[1].t - w[0].t;
            if w[1].packet == w[0].packet {
                assert!((dt - 2.0e-4).abs() < 1e-12, "intra-packet spacing 1/prf");
            } else {
                // Gap between last frame of a packet and the next packet start.
                assert!((dt - (0.05 - 7.0 * 2.0e-4)).abs() < 1e-12);
            }
        }
        assert!((s.end_time() - t[23].t).abs() < 1e-15);
    }

    #[test]
    fn mid_time_is_mean_of_packet_frames() {
        let s = sched();
        let t = s.times();
        for p in 0..3u32 {
            let frames: Vec<f64> = t.iter().filter(|a| a.packet == p).map(|a| a.t).collect();
            let mean = frames.iter().sum::<f64>() / frames.len() as f64;
            assert!((s.packet_mid_time(p) - mean).abs() < 1e-12, "packet {p}");
        }
        // Single-frame packet: mid time is the frame time.
        let one = Schedule { packet_size: 1, ..sched() };
        assert_eq!(one.packet_mid_time(2), one.frame_time(2, 0));
    }

    #[test]
    fn default_is_valid_and_continuous_interval_accepted() {
        Schedule::default().validate().expect("default valid");
        assert_eq!(Schedule::default().times().len(), 32);
        let s = Schedule { prf: 10.0e3, packet_size: 32, n_packets: 4, packet_interval: 0.0032, t_start: 0.0 };
        s.validate().expect("back-to-back packets are fine");
        let t = s.times();
        for w in t.windows(2) {
            assert!((w[1].t - w[0].t - 1e-4).abs() < 1e-12);
        }
    }

    #[test]
    fn invalid_schedules_name_the_field() {
        let cases: Vec<(Schedule, &str)> = vec![
            (Schedule { prf: 0.0, ..sched() }, "schedule.prf"),
            (Schedule { prf: f64::NAN, ..sched() }, "schedule.prf"),
            (Schedule { packet_size: 0, ..sched() }, "schedule.packet_size"),
            (Schedule { n_packets: 0, ..sched() }, "schedule.n_packets"),
            (Schedule { n_packets: 1_000_000, packet_size: 1_000, ..sched() }, "schedule.n_packets"),
            (Schedule { t_start: -1.0, ..sched() }, "schedule.t_start"),
            (Schedule { t_start: f64::INFINITY, ..sched() }, "schedule.t_start"),
            // 8 frames at 5 kHz last 1.6 ms; 1 ms interval would overlap.
            (Schedule { packet_interval: 1e-3, ..sched() }, "schedule.packet_interval"),
        ];
        for (s, field) in cases {
            let err = s.validate().expect_err(field);
            let msg = err.to_string();
            assert!(msg.starts_with(field), "{msg}");
            assert!(s.times().is_empty(), "invalid schedule yields no times");
        }
    }

    #[test]
    fn toml_partial_uses_defaults_and_rejects_unknown() {
        let s: Schedule = toml::from_str("prf = 4000.0\nn_packets = 2").expect("parse");
        assert_eq!(s.prf, 4000.0);
        assert_eq!(s.n_packets, 2);
        assert_eq!(s.packet_size, 32);
        assert!(toml::from_str::<Schedule>("prf_hz = 4000.0").is_err());
    }
}
