//! The `#[repr(C)]` wire structs. Field order is the layout: never reorder, only append into
//! the `reserved` words (and bump `schema_minor`) or create a `…V2` type.

use crate::wire_struct;
#[cfg(feature = "ipc")]
#[allow(unused_imports)]
use iceoryx2::prelude::ZeroCopySend;

/// Maximum number of transmit elements whose delays fit in an [`RfFrameHeaderV3`].
pub const MAX_TX_ELEMENTS: usize = 256;
/// Maximum number of planes in a map ([`DopplerMapHeaderV2`], [`VectorFieldHeaderV2`]).
pub const MAX_PLANES: usize = 8;

/// `flags` bit: last message of the stream; the payload may be empty.
pub const FLAG_END_OF_STREAM: u32 = 1;
/// `flags` bit: the message was published by `replay` from a recording.
pub const FLAG_REPLAYED: u32 = 2;
/// `flags` bit: discontinuity (restart, replay loop): consumers flush their ensembles.
pub const FLAG_RESET: u32 = 4;

wire_struct! {
    /// Common first field of every header (64 bytes).
    pub struct MsgHeaderV1 as "sonoflow_msgs/MsgHeaderV1" {
        /// Per-publisher sequence number starting at 0; a gap means a message was lost.
        pub seq: u64,
        /// Acquisition/event counter linking products to the RF frame they come from.
        pub frame_id: u64,
        /// Time of validity in seconds (simulation / acquisition time). Algorithms use this.
        pub t_valid: f64,
        /// Wall clock (UNIX ns) when the message was published; diagnostics only.
        pub t_pub_ns: u64,
        /// CPU time (ns) the producing node spent computing this message.
        pub compute_ns: u64,
        /// Bumped when a producer restarts or a replay loops.
        pub incarnation: u32,
        /// `FLAG_*` bits.
        pub flags: u32,
        /// Hash of the producing node's name.
        pub source_id: u32,
        /// Additive layout revision within the major version.
        pub schema_minor: u32,
        /// Reserved, zero.
        pub reserved: [u32; 2],
    }
}

wire_struct! {
    /// A rectangular imaging grid: node (ix, iz) at (x0 + ix·dx, z0 + iz·dz). Maps are stored
    /// row-major, index `iz·nx + ix`.
    pub struct GridV1 as "sonoflow_msgs/GridV1" {
        pub x0: f64,
        pub z0: f64,
        pub dx: f64,
        pub dz: f64,
        pub nx: u32,
        pub nz: u32,
    }
}

wire_struct! {
    /// Header of a particle snapshot (fluid particles are the acoustic scatterers).
    pub struct ParticleSnapshotHeaderV1 as "sonoflow_msgs/ParticleSnapshotHeaderV1" {
        pub common: MsgHeaderV1,
        pub n_particles: u32,
        /// Number of particles of kind `PARTICLE_FLUID`.
        pub n_fluid: u32,
        /// Time step of the solver when the snapshot was taken (0 for analytic flows).
        pub dt: f64,
        /// Bounding box x_min, x_max, z_min, z_max (m).
        pub bbox: [f32; 4],
        /// Packet index of the acquisition this snapshot is for.
        pub packet: u32,
        /// Frame index within the packet.
        pub frame_in_packet: u32,
        /// Frames per packet of the acquisition schedule (0 = unknown).
        pub packet_size: u32,
        pub reserved: u32,
    }
}

/// `ParticleV1::kind`: fluid particle.
pub const PARTICLE_FLUID: u32 = 0;
/// `ParticleV1::kind`: wall (boundary) particle.
pub const PARTICLE_WALL: u32 = 1;
/// `ParticleV1::kind`: suspended rigid particle (platelet).
pub const PARTICLE_PLATELET: u32 = 2;
/// `ParticleV1::kind`: stationary tissue scatterer (outside the lumen; not part of the truth).
pub const PARTICLE_TISSUE: u32 = 3;
/// `ParticleV1::kind`: moving tissue scatterer (pulsating wall, bulk motion; outside the lumen,
/// not part of the truth): simulated in every frame, not cached as static.
pub const PARTICLE_TISSUE_MOVING: u32 = 4;

wire_struct! {
    /// One particle (32 bytes).
    pub struct ParticleV1 as "sonoflow_msgs/ParticleV1" {
        /// Stable id for the particle's life.
        pub id: u32,
        /// `PARTICLE_FLUID`, `PARTICLE_WALL`, `PARTICLE_PLATELET` or `PARTICLE_TISSUE`.
        pub kind: u32,
        pub x: f32,
        pub z: f32,
        pub vx: f32,
        pub vz: f32,
        /// Scattering amplitude (drawn once per particle).
        pub amplitude: f32,
        pub reserved: f32,
    }
}

/// `RfFrameHeaderV3::sample_format`: real RF, f32, payload `[channel][sample]`.
pub const SAMPLE_RF_F32: u32 = 0;
/// `RfFrameHeaderV3::sample_format`: I/Q interleaved f32 (re, im), payload `[channel][sample][2]`.
pub const SAMPLE_IQ_F32: u32 = 1;

wire_struct! {
    /// Header of one received RF frame (one transmit). Payload: f32, channel-major
    /// (`data[ch·n_samples + k]`), sample k at t = t0 + k/fs.
    pub struct RfFrameHeaderV3 as "sonoflow_msgs/RfFrameHeaderV3" {
        pub common: MsgHeaderV1,
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
        /// Plane-wave tilt (rad), 0 for non-plane transmits.
        pub tx_angle: f64,
        /// Pulse repetition frequency (Hz).
        pub prf: f64,
        /// Element width (m, ≤ pitch; 0 = unknown): the element directivity downstream.
        pub element_width: f64,
        /// Radius of curvature of a convex array (m, MUST `radius`); 0 = linear array. The
        /// elements lie on the arc (MUST `getElementPositions`).
        pub radius: f64,
        pub n_channels: u32,
        pub n_samples: u32,
        /// Transmit index within the sequence.
        pub tx_id: u32,
        /// `SAMPLE_RF_F32` or `SAMPLE_IQ_F32`.
        pub sample_format: u32,
        /// Packet index of this frame.
        pub packet: u32,
        /// Frame index within the packet.
        pub frame_in_packet: u32,
        /// Transmit delays (s) per element, first `n_channels` used.
        pub tx_delays: [f32; 256],
    }
}

wire_struct! {
    /// A complex sample.
    pub struct Complex32 as "sonoflow_msgs/Complex32" {
        pub re: f32,
        pub im: f32,
    }
}

wire_struct! {
    /// Header of a beamformed I/Q image for one receive angle; it carries the receive aperture
    /// the image was formed with, so a consumer needs no copy of the beamformer's config. Payload: `Complex32`, row-major
    /// on `grid` (`iz·nx + ix`).
    pub struct IqFrameHeaderV3 as "sonoflow_msgs/IqFrameHeaderV3" {
        pub common: MsgHeaderV1,
        pub grid: GridV1,
        pub fc: f64,
        pub c: f64,
        pub prf: f64,
        /// Receive steering angle (rad).
        pub rx_angle: f64,
        /// Transmit tilt (rad).
        pub tx_angle: f64,
        /// Receive aperture: element pitch (m).
        pub pitch: f64,
        /// Receive aperture: element width (m; 0 = unknown, elements then weigh equally).
        pub element_width: f64,
        /// Receive aperture: f-number of the beamformer (0 = the whole array at every pixel).
        pub fnumber: f64,
        /// Receive aperture: radius of curvature of a convex array (m); 0 = linear array.
        pub radius: f64,
        pub packet: u32,
        pub frame_in_packet: u32,
        pub tx_id: u32,
        /// Receive aperture: number of elements of the array; 0 = the aperture is unknown
        /// (consumers then use the nominal plane-wave geometry).
        pub n_elements: u32,
        /// Receive aperture: apodisation across it, `APODIZATION_*`.
        pub apodization: u32,
        pub reserved: u32,
    }
}

/// `IqFrameHeaderV3::apodization`: equal weights.
pub const APODIZATION_BOXCAR: u32 = 0;
/// `IqFrameHeaderV3::apodization`: Hann window across the aperture.
pub const APODIZATION_HANN: u32 = 1;

/// Plane ids of maps ([`DopplerMapHeaderV2::plane_ids`], [`VectorFieldHeaderV2::plane_ids`]).
pub mod plane {
    /// Unused slot.
    pub const NONE: u32 = 0;
    /// Axial (Doppler) velocity, m/s, positive toward the probe.
    pub const VELOCITY: u32 = 1;
    /// Slow-time power (R0).
    pub const POWER: u32 = 2;
    /// Normalised variance (1 − |R1|/R0).
    pub const VARIANCE: u32 = 3;
    /// Bit flags per pixel (stored as f32 integers): 1 = no estimate, 2 = aliasing suspected.
    pub const FLAGS: u32 = 4;
    /// Lateral velocity component, m/s.
    pub const VX: u32 = 5;
    /// Axial velocity component (+z = deeper), m/s.
    pub const VZ: u32 = 6;
    /// 1 inside the fluid, 0 outside.
    pub const MASK: u32 = 7;
    /// Weight / quality in [0, 1].
    pub const WEIGHT: u32 = 8;
    /// Doppler projection vector of a colour-Doppler map, lateral component: the map's
    /// `velocity` measures `projection_x·vx + projection_z·vz` (dimensionless, per pixel).
    pub const PROJECTION_X: u32 = 9;
    /// Doppler projection vector, axial component (see [`PROJECTION_X`]).
    pub const PROJECTION_Z: u32 = 10;

    /// Human-readable plane name.
    pub fn name(id: u32) -> &'static str {
        match id {
            VELOCITY => "velocity",
            POWER => "power",
            VARIANCE => "variance",
            FLAGS => "flags",
            VX => "vx",
            VZ => "vz",
            MASK => "mask",
            WEIGHT => "weight",
            PROJECTION_X => "projection_x",
            PROJECTION_Z => "projection_z",
            _ => "unused",
        }
    }
}

/// `DopplerMapHeaderV2::clutter_filter`: no clutter filter.
pub const CLUTTER_NONE: u32 = 0;
/// `DopplerMapHeaderV2::clutter_filter`: polynomial regression.
pub const CLUTTER_POLYNOMIAL: u32 = 1;
/// `DopplerMapHeaderV2::clutter_filter`: Butterworth IIR high-pass.
pub const CLUTTER_IIR: u32 = 2;
/// `DopplerMapHeaderV2::clutter_filter`: SVD of the Casorati matrix.
pub const CLUTTER_SVD: u32 = 3;

/// `DopplerMapHeaderV2::estimator`: lag-L slow-time autocorrelation (paper 1 eq. 19).
pub const ESTIMATOR_AUTOCORRELATION: u32 = 0;
/// `DopplerMapHeaderV2::estimator`: Loupas' 2-D autocorrelator.
pub const ESTIMATOR_LOUPAS: u32 = 1;
/// `DopplerMapHeaderV2::estimator`: speckle tracking; the map is the axial component of the
/// tracked field (velocity toward the probe, projection (0, −1)), variance = 1 − correlation.
pub const ESTIMATOR_SPECKLE_TRACKING: u32 = 2;

wire_struct! {
    /// Header of a colour-Doppler map for one receive angle. Payload: f32 planes,
    /// `data[p·nx·nz + iz·nx + ix]`, plane meaning in `plane_ids`.
    pub struct DopplerMapHeaderV2 as "sonoflow_msgs/DopplerMapHeaderV2" {
        pub common: MsgHeaderV1,
        pub grid: GridV1,
        pub fc: f64,
        pub c: f64,
        pub prf: f64,
        pub rx_angle: f64,
        pub tx_angle: f64,
        /// c·PRF/(4 fc): the aliasing limit (m/s).
        pub nyquist_velocity: f64,
        /// Clutter filter cut-off, a fraction of the PRF (IIR; SVD with an adaptive rank), else 0.
        pub clutter_cutoff: f64,
        /// Fraction of the packet's energy the clutter filter removed (SVD), else 0.
        pub clutter_removed_energy: f64,
        /// Clutter filter: `CLUTTER_NONE`, `CLUTTER_POLYNOMIAL`, `CLUTTER_IIR` or `CLUTTER_SVD`.
        pub clutter_filter: u32,
        /// Polynomial degree or IIR order; the SVD rank removed from this packet.
        pub clutter_order: u32,
        pub packet: u32,
        pub packet_size: u32,
        pub n_planes: u32,
        /// Which estimator produced the map: `ESTIMATOR_AUTOCORRELATION`, `ESTIMATOR_LOUPAS`,
        /// `ESTIMATOR_SPECKLE_TRACKING`; other values are free for external estimators.
        pub estimator: u32,
        pub plane_ids: [u32; 8],
    }
}

/// `VectorFieldHeaderV2::source`: raw vector Doppler.
pub const VECTOR_RAW: u32 = 0;
/// `VectorFieldHeaderV2::source`: regularised.
pub const VECTOR_REGULARISED: u32 = 1;
/// `VectorFieldHeaderV2::source`: ground truth.
pub const VECTOR_TRUTH: u32 = 2;

wire_struct! {
    /// Header of a 2-component vector field. Payload: f32 planes as in the Doppler map
    /// (typically vx, vz, and mask or weight). A raw vector-Doppler field carries the clutter
    /// filter of the looks it was solved from, and a regularised one passes it on, so that a
    /// stage that sees only the vector field (an evaluator, a recording) can tell how it was made.
    pub struct VectorFieldHeaderV2 as "sonoflow_msgs/VectorFieldHeaderV2" {
        pub common: MsgHeaderV1,
        pub grid: GridV1,
        /// Smoothing parameter S used (regularised fields), else 0.
        pub smoothing_s: f64,
        /// Fraction of points down-weighted as outliers (regularised fields), else 0.
        pub outlier_fraction: f64,
        /// Clutter filter cut-off of the looks, a fraction of the PRF (IIR; SVD with an adaptive
        /// rank), else 0.
        pub clutter_cutoff: f64,
        /// Mean over the looks of the fraction of the packet's energy the clutter filter removed
        /// (SVD), else 0.
        pub clutter_removed_energy: f64,
        pub n_planes: u32,
        /// `VECTOR_RAW`, `VECTOR_REGULARISED` or `VECTOR_TRUTH`.
        pub source: u32,
        pub packet: u32,
        /// 1 if the producing iteration converged.
        pub converged: u32,
        /// Clutter filter of the looks: `CLUTTER_NONE` (also ground truth), `CLUTTER_POLYNOMIAL`,
        /// `CLUTTER_IIR` or `CLUTTER_SVD`.
        pub clutter_filter: u32,
        /// Polynomial degree or IIR order; SVD: the largest rank removed among the looks.
        pub clutter_order: u32,
        /// Looks (receive angle × band × transmit) the vector field was solved from, 0 if not a
        /// vector-Doppler field.
        pub n_looks: u32,
        /// Of those, looks left out of the solve (the Doppler node's `look_rejection`).
        pub rejected_looks: u32,
        pub plane_ids: [u32; 8],
    }
}

/// `StageStatsHeaderV1::state`: node running.
pub const STAGE_RUNNING: u32 = 0;
/// `StageStatsHeaderV1::state`: node finished normally.
pub const STAGE_FINISHED: u32 = 1;

wire_struct! {
    /// Per-message and final statistics of one node. Payload: the node name (UTF-8 bytes).
    pub struct StageStatsHeaderV1 as "sonoflow_msgs/StageStatsHeaderV1" {
        pub common: MsgHeaderV1,
        pub node_index: u32,
        /// `STAGE_RUNNING` or `STAGE_FINISHED`.
        pub state: u32,
        pub messages_in: u64,
        pub messages_out: u64,
        /// Sum of per-message compute time (thread CPU ns).
        pub compute_ns_total: u64,
        /// Process CPU time so far (ns).
        pub cpu_ns: u64,
        /// Wall time since the node started (ns).
        pub wall_ns: u64,
        /// Compute time of the last message (ns).
        pub last_compute_ns: u64,
        /// Bytes published so far.
        pub bytes_out: u64,
    }
}

/// `FlowStatsHeaderV1::binding`: acoustic CFL criterion.
pub const DT_CFL: u32 = 0;
/// `FlowStatsHeaderV1::binding`: viscous criterion.
pub const DT_VISCOUS: u32 = 1;
/// `FlowStatsHeaderV1::binding`: force criterion.
pub const DT_FORCE: u32 = 2;
/// `FlowStatsHeaderV1::binding`: `dt_max`.
pub const DT_MAXIMUM: u32 = 3;
/// `FlowStatsHeaderV1::binding`: shortened to land on an output time.
pub const DT_OUTPUT: u32 = 4;

wire_struct! {
    /// Diagnostics of a particle flow solver (SPH), one message per output time. Payload: one
    /// [`BoundaryFluxV1`] per open boundary, in the scene's order.
    pub struct FlowStatsHeaderV1 as "sonoflow_msgs/FlowStatsHeaderV1" {
        pub common: MsgHeaderV1,
        /// Time step of the last step (s).
        pub dt: f64,
        /// Steps taken since the start (of the run or of the checkpoint's run).
        pub steps: u64,
        /// max |ρ/ρ₀ − 1| over the fluid particles.
        pub max_density_error: f64,
        /// Kinetic energy of the fluid ½ Σ m |u|² (J per metre of depth).
        pub kinetic_energy: f64,
        /// Mass of the fluid (kg per metre of depth).
        pub fluid_mass: f64,
        /// Largest fluid speed (m/s).
        pub max_speed: f64,
        /// Smallest distance between a fluid particle and any other particle (m).
        pub min_pair_distance: f64,
        /// Times the anti-penetration guard put a particle back inside.
        pub guard_corrections: u64,
        /// CPU time of the solver since the start of the run (ns).
        pub solver_cpu_ns: u64,
        pub n_fluid: u32,
        pub n_buffer: u32,
        pub n_wall: u32,
        /// `DT_*`: the criterion that limited the last step.
        pub binding: u32,
        pub n_boundaries: u32,
        pub reserved: u32,
    }
}

wire_struct! {
    /// Mass bookkeeping of one open boundary since the start (kg per metre of depth).
    pub struct BoundaryFluxV1 as "sonoflow_msgs/BoundaryFluxV1" {
        /// Mass that entered the domain through the opening.
        pub mass_in: f64,
        /// Mass that left the domain through the opening.
        pub mass_out: f64,
        /// Particles created at the far side of the reservoir.
        pub created: u64,
        /// Particles removed beyond the far side of the reservoir.
        pub removed: u64,
    }
}
