//! One packet of beamformed images → one Doppler map per look and the vector velocity: what
//! the `doppler` node does, without IPC.
//!
//! [`PacketAssembler`] collects a packet's I/Q images per look (transmit tilt, receive angle,
//! fc); at the end of the packet (an image of the next packet, or [`PacketAssembler::finish`])
//! it optionally clutter-filters them, estimates one Doppler map per look and solves the vector
//! velocity by least squares over all looks — per-pixel projections through each look's receive
//! aperture when the images carry it (or the nominal plane-wave ones), looks weighted by fc²
//! (equal weights when they share one band) — and averages the looks' power.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use sonoflow_beamform::error::{invalid, Result};
use sonoflow_beamform::{BeamformError, Grid, C32};

use crate::aperture::{aperture_projection, Aperture};
use crate::clutter::{ClutterParams, ClutterReport};
use crate::compensate::{Compensation, FilterResponse};
use crate::estimator::{flags, DopplerEstimator, DopplerMap, DopplerParams, Estimator, Packet, WindowShape};
use crate::vector::{nominal_projection, outlier_looks, solve_vector_weighted, Projection, VectorField, VectorInput};

/// Which projection vectors the vector solve uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ProjectionMode {
    /// Per pixel, through the receive aperture each image carries (nominal where it carries none).
    #[default]
    Aperture,
    /// The nominal plane-wave projection of the transmit and receive angles everywhere.
    Nominal,
}

/// Parameters of the per-packet processing (the `doppler` node's params). fc, c and PRF come
/// with each image.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct PacketParams {
    /// `autocorrelation` (eq. 19) or `loupas`.
    pub estimator: Estimator,
    /// Slow-time lag, 1 ..= 64.
    pub lag: usize,
    /// Spatial averaging window [rows (z), columns (x)], each 1 ..= 64 (MUST `M`).
    pub window: [usize; 2],
    /// `hamming` (MUST) or `boxcar`.
    pub window_shape: WindowShape,
    /// Aliasing flag threshold as a fraction of the Nyquist velocity, in (0, 1].
    pub alias_fraction: f64,
    /// Polynomial-regression clutter filter order over slow time (0 = mean removal), 0 ..= 8;
    /// absent: none. Shorthand for `clutter = { type = "polynomial", order = … }`.
    pub clutter_order: Option<usize>,
    /// Clutter (wall) filter: `polynomial`, `iir` or `svd` with their parameters
    /// ([`ClutterParams`]); absent: none (or `clutter_order`).
    pub clutter: Option<ClutterParams>,
    /// `aperture` (per-pixel, from the images' receive aperture) or `nominal`.
    pub projection: ProjectionMode,
    /// Look rejection of the vector solve (≥ 4 looks, [`crate::vector::outlier_looks`]): a look
    /// whose median residual over the blood pixels (power within 15 dB of the 99th percentile)
    /// against the field of the other looks exceeds this many times theirs is left out and the
    /// field solved again; 0 = off. Default 4; > 1 otherwise.
    pub look_rejection: f64,
    /// Undo the clutter filter's bias of each look's mean frequency ([`crate::compensate`]):
    /// per pixel, the (mean, width) of a Gaussian blood spectrum whose filtered lag-L
    /// autocorrelation matches the measured one. Autocorrelation estimator only; without a
    /// clutter filter nothing to do. Default false (the paper's estimator).
    pub compensate_filter: bool,
}

impl Default for PacketParams {
    fn default() -> Self {
        Self {
            estimator: Estimator::Autocorrelation,
            lag: 1,
            window: [1, 1],
            window_shape: WindowShape::Hamming,
            alias_fraction: 0.9,
            clutter_order: None,
            clutter: None,
            projection: ProjectionMode::Aperture,
            look_rejection: 4.0,
            compensate_filter: false,
        }
    }
}

impl PacketParams {
    /// The estimator's parameters for a look at `fc`, `c`, `prf`.
    pub fn doppler(&self, fc: f64, c: f64, prf: f64) -> DopplerParams {
        DopplerParams {
            fc,
            c,
            prf,
            lag: self.lag,
            window: self.window,
            window_shape: self.window_shape,
            estimator: self.estimator,
            alias_fraction: self.alias_fraction,
        }
    }

    /// Checks every field (errors name it).
    pub fn validate(&self) -> Result<()> {
        self.doppler(5e6, 1540.0, 1e4).validate()?;
        if let Some(o) = self.clutter_order {
            if o > 8 {
                return Err(invalid("clutter_order", o, "in 0 ..= 8 (and below the packet size)"));
            }
            if self.clutter.is_some() {
                return Err(invalid("clutter_order", o, "absent when a `clutter` table is given (one clutter filter)"));
            }
        }
        if let Some(c) = &self.clutter {
            c.validate()?;
        }
        let r = self.look_rejection;
        if !(r == 0.0 || (r.is_finite() && r > 1.0 && r <= 1e3)) {
            return Err(invalid("look_rejection", r, "0 (off) or in (1, 1000]"));
        }
        if self.compensate_filter && self.estimator != Estimator::Autocorrelation {
            return Err(invalid(
                "compensate_filter",
                true,
                "false with estimator = \"loupas\" (the compensation models the autocorrelation estimator)",
            ));
        }
        Ok(())
    }
}

/// What the processing needs to know of one image (the I/Q frame header, without IPC types).
#[derive(Clone, Debug, PartialEq)]
pub struct LookHeader {
    /// Imaging grid.
    pub grid: Grid,
    /// Demodulation (centre) frequency (Hz).
    pub fc: f64,
    /// Speed of sound (m/s).
    pub c: f64,
    /// Pulse repetition frequency (Hz).
    pub prf: f64,
    /// Transmit tilt (rad).
    pub tx_angle: f64,
    /// Receive angle (rad).
    pub rx_angle: f64,
    /// Packet index.
    pub packet: u32,
    /// Frame counter of the image.
    pub frame_id: u64,
    /// Time of validity (s).
    pub t_valid: f64,
    /// Receive aperture the image was formed with, if known.
    pub aperture: Option<Aperture>,
}

/// One look's Doppler map of a packet.
pub struct LookMap {
    /// Header of the look's last image.
    pub header: LookHeader,
    /// Images in the packet.
    pub packet_size: usize,
    /// Nyquist velocity (m/s).
    pub nyquist: f64,
    /// Estimator used.
    pub estimator: Estimator,
    /// Velocity (m/s, toward the probe), power, normalised variance `1 − |R1|/R0`, flags.
    pub velocity: Vec<f32>,
    /// Slow-time power.
    pub power: Vec<f32>,
    /// Normalised variance.
    pub variance: Vec<f32>,
    /// Flag bits per pixel ([`crate::flags`]).
    pub flags: Vec<u8>,
    /// The projection vector per pixel that the velocity measures (`a · (vx, vz)`), through the
    /// look's aperture; None: the nominal plane-wave projection ([`LookMap::projection_planes`]).
    pub projection: Option<Vec<[f32; 2]>>,
    /// What the clutter filter did to this look's packet.
    pub clutter: ClutterReport,
    /// What `compensate_filter` did (pixels corrected and kept).
    pub compensation: Compensation,
}

impl LookMap {
    /// The projection as two planes (`a_x` then `a_z` per pixel, f32), what the map message
    /// carries.
    pub fn projection_planes(&self) -> (Vec<f32>, Vec<f32>) {
        match &self.projection {
            Some(p) => (p.iter().map(|a| a[0]).collect(), p.iter().map(|a| a[1]).collect()),
            None => {
                let n = self.velocity.len();
                let a = nominal_projection(self.header.tx_angle, self.header.rx_angle);
                (vec![a[0] as f32; n], vec![a[1] as f32; n])
            }
        }
    }
}

/// Products of one packet.
pub struct PacketProducts {
    /// One map per look, in (tx, rx, fc) order.
    pub looks: Vec<LookMap>,
    /// Vector velocity (vx, vz, flags).
    pub vector: VectorField,
    /// Mean power over the looks ([`mean_power`]).
    pub power: Vec<f32>,
    /// Grid of every look.
    pub grid: Grid,
    /// Packet index.
    pub packet: u32,
    /// Largest frame counter among the looks.
    pub frame_id: u64,
    /// Time of validity of the last look.
    pub t_valid: f64,
    /// Looks left out of the vector solve (indices into `looks`) and every look's median
    /// residual (m/s) against the field solved from the other looks; empty without look
    /// rejection.
    pub rejected_looks: Vec<usize>,
    /// See `rejected_looks`.
    pub look_residuals: Vec<f64>,
}

impl PacketProducts {
    /// The clutter filter of the looks in one report, for the vector field's header: the kind
    /// and cut-off (one filter serves every look), the largest order or rank removed among the
    /// looks, and the mean energy removed. `None` without looks.
    pub fn clutter_summary(&self) -> Option<ClutterReport> {
        let first = self.looks.first()?.clutter;
        let n = self.looks.len() as f64;
        Some(ClutterReport {
            order_or_rank: self.looks.iter().map(|l| l.clutter.order_or_rank).max().unwrap_or(0),
            removed_energy: self.looks.iter().map(|l| l.clutter.removed_energy).sum::<f64>() / n,
            ..first
        })
    }
}

/// One packet's frames of one look.
pub(crate) struct Stream {
    pub header: LookHeader,
    pub frames: Vec<Vec<C32>>,
}

pub(crate) type LookKey = (u64, u64, u64);

/// Groups I/Q images into packets and, within a packet, into looks (transmit tilt, receive
/// angle, fc): the bookkeeping shared by [`PacketAssembler`] and the speckle tracker.
#[derive(Default)]
pub(crate) struct LookCollector {
    packet: Option<u32>,
    streams: BTreeMap<LookKey, Stream>,
}

impl LookCollector {
    /// Adds one image; returns the previous packet's looks if this image starts a new packet.
    pub fn push(&mut self, h: &LookHeader, frame: Vec<C32>) -> Result<Option<BTreeMap<LookKey, Stream>>> {
        let n = h.grid.nx * h.grid.nz;
        if frame.len() != n || n == 0 {
            return Err(BeamformError::ConfigMismatch {
                what: format!(
                    "I/Q frame {}: {} samples for a {}×{} grid",
                    h.frame_id,
                    frame.len(),
                    h.grid.nz,
                    h.grid.nx
                ),
            });
        }
        let done = match self.packet {
            Some(p) if p != h.packet => Some(self.take()),
            _ => None,
        };
        self.packet = Some(h.packet);
        let key = (h.tx_angle.to_bits(), h.rx_angle.to_bits(), h.fc.to_bits());
        let s = self.streams.entry(key).or_insert_with(|| Stream { header: h.clone(), frames: Vec::new() });
        if s.header.grid != h.grid {
            return Err(BeamformError::ConfigMismatch {
                what: format!("I/Q frame {}: the grid changed within packet {}", h.frame_id, h.packet),
            });
        }
        s.frames.push(frame);
        Ok(done)
    }

    /// The current packet's looks (empty if nothing is pending).
    pub fn take(&mut self) -> BTreeMap<LookKey, Stream> {
        std::mem::take(&mut self.streams)
    }
}
/// (look, grid x0/z0/dx/dz, nx, nz, aperture as text), for the projection cache.
type ProjectionKey = (LookKey, [u64; 4], usize, usize, String);

/// Collects a packet's images per look and turns each finished packet into [`PacketProducts`].
pub struct PacketAssembler {
    params: PacketParams,
    collector: LookCollector,
    map: DopplerMap,
    vec: VectorField,
    projections: BTreeMap<ProjectionKey, Vec<[f32; 2]>>,
}

impl PacketAssembler {
    /// Validates `params`.
    pub fn new(params: PacketParams) -> Result<Self> {
        params.validate()?;
        Ok(Self {
            params,
            collector: LookCollector::default(),
            map: DopplerMap::default(),
            vec: VectorField::default(),
            projections: BTreeMap::new(),
        })
    }

    /// Adds one image; returns the finished previous packet if this image starts a new one.
    pub fn push(&mut self, h: &LookHeader, frame: Vec<C32>) -> Result<Option<PacketProducts>> {
        match self.collector.push(h, frame)? {
            Some(streams) => self.process(streams),
            None => Ok(None),
        }
    }

    /// Finishes the current packet (end of stream); None if nothing is pending.
    pub fn finish(&mut self) -> Result<Option<PacketProducts>> {
        let streams = self.collector.take();
        self.process(streams)
    }

    /// Turns one packet's looks into its products.
    fn process(&mut self, streams: BTreeMap<LookKey, Stream>) -> Result<Option<PacketProducts>> {
        let Some(first) = streams.values().next().map(|s| s.header.clone()) else {
            return Ok(None);
        };
        let (nx, nz) = (first.grid.nx, first.grid.nz);
        let n = nx * nz;
        let mut looks = Vec::with_capacity(streams.len());
        let mut frame_id = 0;
        let mut t_valid = 0.0;
        for s in streams.into_values() {
            let h = s.header;
            if s.frames.iter().any(|f| f.len() != n) || h.grid != first.grid {
                return Err(BeamformError::ConfigMismatch {
                    what: format!("packet {}: the angle pairs do not share one grid", h.packet),
                });
            }
            let dp = self.params.doppler(h.fc, h.c, h.prf);
            if s.frames.len() <= dp.lag {
                return Err(BeamformError::ConfigMismatch {
                    what: format!(
                        "packet {} (rx {:.1}°): {} frame(s), need more than lag = {}",
                        h.packet,
                        h.rx_angle.to_degrees(),
                        s.frames.len(),
                        dp.lag
                    ),
                });
            }
            let mut frames = s.frames;
            if let Some(order) = self.params.clutter_order {
                if order + 1 >= frames.len() {
                    return Err(BeamformError::ConfigMismatch {
                        what: format!(
                            "clutter_order = {order} needs a packet of more than {} frames, got {}",
                            order + 1,
                            frames.len()
                        ),
                    });
                }
            }
            let clutter = match (&self.params.clutter, self.params.clutter_order) {
                (Some(c), _) => Some(c.clone()),
                (None, Some(order)) => Some(ClutterParams::Polynomial { order }),
                (None, None) => None,
            };
            let mut clutter_report = ClutterReport::default();
            let mut response = None;
            if let Some(c) = clutter {
                let mut refs: Vec<&mut [C32]> = frames.iter_mut().map(|f| f.as_mut_slice()).collect();
                if self.params.compensate_filter {
                    let (report, h) = c.apply_frames_with_response(&mut refs)?;
                    clutter_report = report;
                    response = Some(FilterResponse::new(&h, frames.len(), dp.lag)?);
                } else {
                    clutter_report = c.apply_frames(&mut refs)?;
                }
            }
            let mut est = DopplerEstimator::new(dp.clone(), nx, nz, h.grid.dz)?;
            if dp.estimator == Estimator::Loupas {
                // Nominal axial delay step of this angle pair: (cos θt + cos θr)·dz/c.
                let step = (h.tx_angle.cos() + h.rx_angle.cos()) * h.grid.dz / h.c;
                est.set_axial_step(&vec![step; n])?;
            }
            let refs: Vec<&[C32]> = frames.iter().map(|f| f.as_slice()).collect();
            est.estimate(Packet::Frames(&refs), &mut self.map)?;
            let mut compensation = Compensation::default();
            if let Some(r) = &response {
                let (r0, r_lag) = est.autocorrelation();
                let valid: Vec<bool> = self.map.flags.iter().map(|f| f & flags::NO_ESTIMATE == 0).collect();
                let scale = h.c * h.prf / (2.0 * h.fc);
                compensation = r.correct(r0, r_lag, &valid, scale, &mut self.map.velocity);
            }
            let vn = self.map.nyquist;
            let norm = 2.0 * (vn / std::f64::consts::PI).powi(2);
            let projection = self.projection(&h)?;
            frame_id = frame_id.max(h.frame_id);
            t_valid = h.t_valid;
            looks.push(LookMap {
                packet_size: frames.len(),
                nyquist: vn,
                estimator: dp.estimator,
                velocity: self.map.velocity.clone(),
                power: self.map.power.clone(),
                variance: self.map.variance.iter().map(|v| (*v as f64 / norm) as f32).collect(),
                flags: self.map.flags.clone(),
                projection,
                clutter: clutter_report,
                compensation,
                header: h,
            });
        }
        if looks.len() < 2 {
            return Err(BeamformError::ConfigMismatch {
                what: format!(
                    "packet {}: vector Doppler needs at least two (transmit, receive) angle pairs, got {} — give the beamformer two rx_angles_deg",
                    first.packet,
                    looks.len()
                ),
            });
        }
        let inputs: Vec<VectorInput> = looks
            .iter()
            .map(|l| VectorInput {
                velocity: &l.velocity,
                flags: &l.flags,
                projection: match &l.projection {
                    Some(p) => Projection::PerPixel(p),
                    None => Projection::Nominal { tx_tilt: l.header.tx_angle, rx_angle: l.header.rx_angle },
                },
            })
            .collect();
        // Looks in different bands (the beamformer's per-angle `demod_fc`): equal phase noise
        // means velocity noise ∝ 1/fc, so each look is weighted by (fc / highest fc)²; the power
        // plane averages each look's power relative to its own mean (the bands' echo levels
        // differ by orders of magnitude). One band: equal weights and the plain mean.
        let f_max = looks.iter().map(|l| l.header.fc).fold(0.0f64, f64::max);
        let weights: Vec<f64> = looks.iter().map(|l| (l.header.fc / f_max).powi(2)).collect();
        solve_vector_weighted(&inputs, &weights, &mut self.vec)?;
        let look_power: Vec<&[f32]> = looks.iter().map(|l| l.power.as_slice()).collect();
        let one_band = looks.iter().all(|l| l.header.fc.to_bits() == first.fc.to_bits());
        let power = mean_power(&look_power, one_band);
        let (mut rejected_looks, mut look_residuals) = (Vec::new(), Vec::new());
        if self.params.look_rejection > 0.0 && inputs.len() >= 4 {
            let mut sorted: Vec<f32> = power.iter().copied().filter(|v| v.is_finite()).collect();
            sorted.sort_by(f32::total_cmp);
            let p99 = sorted.get(((sorted.len() as f64 - 1.0) * 0.99).round() as usize).copied().unwrap_or(0.0);
            let blood: Vec<bool> =
                power.iter().map(|v| v.is_finite() && f64::from(*v) >= f64::from(p99) * 10f64.powf(-1.5)).collect();
            let (reject, medians) = outlier_looks(&inputs, &weights, &blood, self.params.look_rejection)?;
            look_residuals = medians;
            rejected_looks = (0..reject.len()).filter(|&i| reject[i]).collect();
            if !rejected_looks.is_empty() {
                let keep: Vec<usize> = (0..reject.len()).filter(|&i| !reject[i]).collect();
                let kept: Vec<VectorInput> = keep.iter().map(|&i| inputs[i]).collect();
                let kept_w: Vec<f64> = keep.iter().map(|&i| weights[i]).collect();
                solve_vector_weighted(&kept, &kept_w, &mut self.vec)?;
            }
        }
        Ok(Some(PacketProducts {
            looks,
            vector: self.vec.clone(),
            power,
            grid: first.grid.clone(),
            packet: first.packet,
            frame_id,
            t_valid,
            rejected_looks,
            look_residuals,
        }))
    }

    /// The projection vectors of look `h` through its aperture (cached per look, grid and
    /// aperture); None: nominal.
    fn projection(&mut self, h: &LookHeader) -> Result<Option<Vec<[f32; 2]>>> {
        let aperture = match (self.params.projection, &h.aperture) {
            (ProjectionMode::Aperture, Some(a)) => a,
            (ProjectionMode::Nominal, Some(a)) if a.radius.is_some() => {
                // the plane-wave directions from the z axis do not describe looks steered from
                // the normals of a convex array's elements
                return Err(invalid(
                    "projection",
                    "nominal",
                    "\"aperture\" for the looks of a convex array (their receive angles are taken from each element's normal)",
                ));
            }
            _ => return Ok(None),
        };
        let g = &h.grid;
        let key = (
            (h.tx_angle.to_bits(), h.rx_angle.to_bits(), h.fc.to_bits()),
            [g.x0, g.z0, g.dx, g.dz].map(f64::to_bits),
            g.nx,
            g.nz,
            format!("{aperture:?} c={}", h.c.to_bits()),
        );
        if let Some(p) = self.projections.get(&key) {
            return Ok(Some(p.clone()));
        }
        let p = aperture_projection(aperture, h.fc, h.c, h.tx_angle, h.rx_angle, g)?;
        self.projections.insert(key, p.clone());
        Ok(Some(p))
    }
}

/// The vector field's `power` plane from the looks' power maps: their mean; with looks in
/// several bands, the mean of each look's power relative to its own mean (the bands' echo levels
/// differ by orders of magnitude), scaled by the looks' mean level.
pub fn mean_power(looks: &[&[f32]], one_band: bool) -> Vec<f32> {
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
