//! What the launcher hands every node process (JSON in the `SONOFLOW_NODE_CONFIG` environment
//! variable): run id (service prefix), ports with their topics and QoS, and parameters.

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Environment variable carrying the [`NodeConfig`] JSON.
pub const NODE_CONFIG_ENV: &str = "SONOFLOW_NODE_CONFIG";

/// Quality of service of one topic. Every process opening the topic must use the same values,
/// so the launcher computes them once and hands them out.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TopicQos {
    /// Topic name (service `sonoflow/<run_id>/<topic>`).
    pub topic: String,
    /// Message type name (`RfFrameV3`, …).
    pub message_type: String,
    /// Maximum payload elements per message (hard limit of the shared-memory slots).
    pub max_elements: usize,
    /// Queue depth per subscriber.
    pub depth: usize,
    /// Maximum number of subscribers (= consumers declared in the launch file).
    pub max_subscribers: usize,
    /// Maximum number of publishers.
    pub max_publishers: usize,
    /// Number of subscribers a publisher waits for before its first send.
    pub expected_subscribers: usize,
}

/// Per-subscriber borrowed samples (fixed).
pub const BORROWED_SAMPLES: usize = 2;
/// Per-publisher loaned samples (fixed).
pub const LOANED_SAMPLES: usize = 1;

impl TopicQos {
    /// Shared memory one publisher of this topic maps (bytes), header included.
    pub fn shm_bytes(&self, elem_size: usize, header_size: usize) -> u64 {
        let slots = self.max_subscribers * (self.depth + BORROWED_SAMPLES) + LOANED_SAMPLES;
        (slots as u64) * (self.max_elements as u64 * elem_size as u64 + header_size as u64 + 64)
    }
}

/// Everything a node process needs to start.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct NodeConfig {
    /// Unique per run; all services live under `sonoflow/<run_id>/`.
    pub run_id: String,
    /// Node name in the launch file.
    pub node_name: String,
    /// Index of the node in the launch file (stable).
    pub node_index: u32,
    /// Node kind (built-in kind or `exec`).
    pub kind: String,
    /// The node's `[params]` table.
    #[serde(default)]
    pub params: serde_json::Value,
    /// Input port → topic.
    #[serde(default)]
    pub inputs: BTreeMap<String, TopicQos>,
    /// Output port → topic.
    #[serde(default)]
    pub outputs: BTreeMap<String, TopicQos>,
    /// Stage-statistics topic (every node publishes to it unless `None`).
    #[serde(default)]
    pub stats: Option<TopicQos>,
    /// Seconds to wait for peers during the start-up handshake.
    #[serde(default = "default_handshake")]
    pub handshake_timeout_s: f64,
    /// Output directory of the run (for nodes that write files).
    #[serde(default)]
    pub out_dir: Option<String>,
}

fn default_handshake() -> f64 {
    30.0
}

impl NodeConfig {
    /// Reads the config from the environment.
    pub fn from_env() -> Result<Self, crate::KitError> {
        let s = std::env::var(NODE_CONFIG_ENV).map_err(|_| {
            crate::KitError::Config(format!(
                "environment variable {NODE_CONFIG_ENV} is not set: node processes are started by `sonoflow run`"
            ))
        })?;
        serde_json::from_str(&s).map_err(|e| crate::KitError::Config(format!("{NODE_CONFIG_ENV}: {e}")))
    }
}
