//! Registry of the built-in node kinds: their ports, parameter validation and entry points.

use sonoflow_messages::MessageKind;

/// Port direction.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PortDir {
    In,
    Out,
}

impl PortDir {
    pub fn word(self) -> &'static str {
        match self {
            PortDir::In => "input",
            PortDir::Out => "output",
        }
    }
}

/// One port of a kind.
pub struct PortSpec {
    pub name: &'static str,
    pub dir: PortDir,
    pub kind: MessageKind,
    pub required: bool,
}

/// A built-in node kind.
pub struct KindSpec {
    pub name: &'static str,
    pub about: &'static str,
    pub ports: &'static [PortSpec],
    /// Inputs derived from `params.topics` (recorder).
    pub dynamic_inputs: bool,
    /// Outputs named after recorded topics (replay).
    pub dynamic_outputs: bool,
    /// Checks the `[params]` table (deserialise + validate).
    pub validate: fn(&serde_json::Value) -> Result<(), String>,
    /// Runs the node.
    pub run: fn(sonoflow_node_kit::Kit) -> anyhow::Result<()>,
}

impl KindSpec {
    pub fn port(&self, name: &str, dir: PortDir) -> Option<&PortSpec> {
        self.ports.iter().find(|p| p.name == name && p.dir == dir)
    }
    pub fn port_names(&self, dir: PortDir) -> Vec<&'static str> {
        let v: Vec<_> = self.ports.iter().filter(|p| p.dir == dir).map(|p| p.name).collect();
        if v.is_empty() {
            vec!["none"]
        } else {
            v
        }
    }
}

const fn port(name: &'static str, dir: PortDir, kind: MessageKind, required: bool) -> PortSpec {
    PortSpec { name, dir, kind, required }
}

use MessageKind::*;
use PortDir::*;

static KINDS: &[KindSpec] = &[
    KindSpec {
        name: "analytic-flow",
        about: "scatterers moved by an analytic flow (Poiseuille vessel, rotating disk, plug band) at the acquisition times, plus the exact field as ground truth",
        ports: &[port("particles", Out, ParticleSnapshotV1, true), port("truth", Out, VectorFieldV1, false)],
        dynamic_inputs: false,
        dynamic_outputs: false,
        validate: crate::node_flow::validate,
        run: crate::node_flow::run,
    },
    KindSpec {
        name: "sph-flow",
        about: "weakly compressible SPH blood flow (paper 1 §2.1–2.2) in a vessel geometry (carotid bifurcation preset): fluid particles = scatterers at the acquisition times, SPH-interpolated ground truth, solver diagnostics",
        ports: &[
            port("particles", Out, ParticleSnapshotV1, true),
            port("truth", Out, VectorFieldV1, false),
            port("stats", Out, FlowStatsV1, false),
        ],
        dynamic_inputs: false,
        dynamic_outputs: false,
        validate: crate::node_sph::validate,
        run: crate::node_sph::run,
    },
    KindSpec {
        name: "platelets",
        about: "platelet suspension (paper 2, Algorithm 2: point particles with shape, trained coefficient networks) in an analytic carrier (straight or stenosed channel, shear) or in fluid snapshots on the input `particles` (SPH, interpolated onto a lattice; carrier type \"particles\"): platelet snapshots every few macro steps, with the time split advection / collisions / coefficients",
        ports: &[port("particles", In, ParticleSnapshotV1, false), port("particles", Out, ParticleSnapshotV1, true)],
        dynamic_inputs: false,
        dynamic_outputs: false,
        validate: crate::node_platelet::validate,
        run: crate::node_platelet::run,
    },
    KindSpec {
        name: "simus",
        about: "SIMUS RF synthesiser (MUST's model): particle snapshots → RF frames, one per plane-wave tilt",
        ports: &[port("particles", In, ParticleSnapshotV1, true), port("rf", Out, RfFrameV1, true)],
        dynamic_inputs: false,
        dynamic_outputs: false,
        validate: crate::node_simus::validate,
        run: crate::node_simus::run,
    },
    KindSpec {
        name: "beamformer",
        about: "RF → I/Q (MUST rf2iq) → delay-and-sum on a grid, one I/Q image per receive sub-aperture angle",
        ports: &[port("rf", In, RfFrameV1, true), port("iq", Out, IqFrameV1, true)],
        dynamic_inputs: false,
        dynamic_outputs: false,
        validate: crate::node_beamform::validate_beamformer,
        run: crate::node_beamform::run_beamformer,
    },
    KindSpec {
        name: "doppler",
        about: "colour + vector Doppler per packet: lag-L slow-time autocorrelation (eq. 19) per angle pair, least-squares (vx, vz)",
        ports: &[
            port("iq", In, IqFrameV1, true),
            port("vector", Out, VectorFieldV1, true),
            port("maps", Out, DopplerMapV1, false),
        ],
        dynamic_inputs: false,
        dynamic_outputs: false,
        validate: crate::node_doppler::validate_doppler,
        run: crate::node_doppler::run_doppler,
    },
    KindSpec {
        name: "doppler-loupas",
        about: "as `doppler`, with Loupas' 2-D autocorrelator (mean RF frequency from the axial lag, no fc bias)",
        ports: &[
            port("iq", In, IqFrameV1, true),
            port("vector", Out, VectorFieldV1, true),
            port("maps", Out, DopplerMapV1, false),
        ],
        dynamic_inputs: false,
        dynamic_outputs: false,
        validate: crate::node_doppler::validate_doppler,
        run: crate::node_doppler::run_doppler_loupas,
    },
    KindSpec {
        name: "regulariser",
        about: "robust unsupervised smoothing of vector fields (Garcia's smoothn): raw → regularised, with the S used and the outlier fraction",
        ports: &[port("raw", In, VectorFieldV1, true), port("regularised", Out, VectorFieldV1, true)],
        dynamic_inputs: false,
        dynamic_outputs: false,
        validate: crate::node_regularise::validate,
        run: crate::node_regularise::run,
    },
    KindSpec {
        name: "evaluator",
        about: "errors of raw/regularised vector fields against the ground truth per packet (paper 1's measure) → evaluation.json/.md, the run report and its figures (with `maps`: colour Doppler)",
        ports: &[
            port("truth", In, VectorFieldV1, true),
            port("raw", In, VectorFieldV1, false),
            port("regularised", In, VectorFieldV1, false),
            port("maps", In, DopplerMapV1, false),
        ],
        dynamic_inputs: false,
        dynamic_outputs: false,
        validate: crate::node_evaluate::validate,
        run: crate::node_evaluate::run,
    },
    KindSpec {
        name: "recorder",
        about: "records topics to MCAP (lossless, chunk-compressed, Foxglove pictures)",
        ports: &[],
        dynamic_inputs: true,
        dynamic_outputs: false,
        validate: crate::node_recorder::validate,
        run: crate::node_recorder::run,
    },
    KindSpec {
        name: "replay",
        about: "publishes the topics of an MCAP recording into the graph (outputs: recorded topic = graph topic)",
        ports: &[],
        dynamic_inputs: false,
        dynamic_outputs: true,
        validate: crate::node_replay::validate,
        run: crate::node_replay::run,
    },
    KindSpec {
        name: "test-source",
        about: "deterministic RF test frames (pattern from seed and sequence number)",
        ports: &[port("rf", Out, RfFrameV1, true)],
        dynamic_inputs: false,
        dynamic_outputs: false,
        validate: crate::node_test::validate_source,
        run: crate::node_test::run_source,
    },
    KindSpec {
        name: "gain",
        about: "multiplies RF frames by a constant (a minimal processing stage)",
        ports: &[port("rf_in", In, RfFrameV1, true), port("rf_out", Out, RfFrameV1, true)],
        dynamic_inputs: false,
        dynamic_outputs: false,
        validate: crate::node_test::validate_gain,
        run: crate::node_test::run_gain,
    },
    KindSpec {
        name: "field-noise",
        about: "adds Gaussian noise, gross outliers and missing pixels to vector fields (deterministic; exercises the regulariser)",
        ports: &[port("clean", In, VectorFieldV1, true), port("noisy", Out, VectorFieldV1, true)],
        dynamic_inputs: false,
        dynamic_outputs: false,
        validate: crate::node_test::validate_field_noise,
        run: crate::node_test::run_field_noise,
    },
    KindSpec {
        name: "checker",
        about: "verifies test-source frames (× gain) bit for bit and writes <node>.json in the run folder",
        ports: &[port("rf", In, RfFrameV1, true)],
        dynamic_inputs: false,
        dynamic_outputs: false,
        validate: crate::node_test::validate_checker,
        run: crate::node_test::run_checker,
    },
];

/// Looks a kind up by name.
pub fn spec(name: &str) -> Option<&'static KindSpec> {
    KINDS.iter().find(|k| k.name == name)
}

/// Names of all kinds.
pub fn names() -> Vec<&'static str> {
    KINDS.iter().map(|k| k.name).collect()
}

/// All kinds.
pub fn all() -> &'static [KindSpec] {
    KINDS
}

/// Checks between a node's parameters and its wiring that `validate` (params only) cannot make:
/// for `platelets`, the carrier `particles` goes with the input `particles`.
pub fn check_wiring(kind: &str, params: &serde_json::Value, inputs: &[&str]) -> Result<(), String> {
    match kind {
        "platelets" => crate::node_platelet::check_wiring(params, inputs.contains(&"particles")),
        _ => Ok(()),
    }
}

/// Deserialises params (`null` = empty table) into `P`.
pub fn parse<P: serde::de::DeserializeOwned>(v: &serde_json::Value) -> Result<P, String> {
    let v = if v.is_null() { serde_json::json!({}) } else { v.clone() };
    serde_path_to_error::deserialize(v).map_err(|e| {
        let path = e.path().to_string();
        if path == "." {
            e.inner().to_string()
        } else {
            format!("{path}: {}", e.inner())
        }
    })
}

/// Range check helper: `Err("field = v is out of range: lo ..= hi")`.
pub fn in_range<T: PartialOrd + std::fmt::Display>(field: &str, v: T, lo: T, hi: T) -> Result<(), String> {
    if v >= lo && v <= hi {
        Ok(())
    } else {
        Err(format!("{field} = {v} is out of range: {lo} ..= {hi}"))
    }
}
