//! How a node kind describes itself to the launcher: its ports, the check of its `[params]`, the
//! files it reads, and its entry point. A program that hosts node kinds (the `sonoflow` binary)
//! hands the launcher a registry (`&[KindSpec]`); the launcher knows no kind by name.

use crate::Kit;

/// Name of the stage-statistics topic (every node publishes to it; recorders record it).
pub const STATS_TOPIC: &str = "_stats";
use sonoflow_messages::MessageType;

/// Port direction.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PortDir {
    In,
    Out,
}

impl PortDir {
    /// `input` or `output`.
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
    pub message_type: MessageType,
    pub required: bool,
}

/// A port (for the `ports` tables of the kinds).
pub const fn port(name: &'static str, dir: PortDir, message_type: MessageType, required: bool) -> PortSpec {
    PortSpec { name, dir, message_type, required }
}

/// Cross-check of a node's params against the topics wired to its inputs.
pub type WiringCheck = fn(&serde_json::Value, &[&str]) -> Result<(), String>;

/// A node kind: what `sonoflow kinds` lists, what `sonoflow check` checks, what `sonoflow node
/// <kind>` runs.
pub struct KindSpec {
    /// The kind's name in launch files (`kind = "…"`).
    pub name: &'static str,
    /// One line for `sonoflow kinds`.
    pub about: &'static str,
    pub ports: &'static [PortSpec],
    /// Inputs derived from `params.topics` (a recorder: every topic it records is an input).
    pub dynamic_inputs: bool,
    /// Outputs named after recorded topics (a replay node).
    pub dynamic_outputs: bool,
    /// Checks the `[params]` table (deserialise + validate); the error names the field.
    pub validate: fn(&serde_json::Value) -> Result<(), String>,
    /// Checks between the parameters and the wired inputs that `validate` cannot make
    /// (arguments: params, names of the wired input ports).
    pub check_wiring: Option<WiringCheck>,
    /// Parameters naming files the node reads (dotted paths into `[params]`, e.g. `path`):
    /// relative paths resolve against the launch file's folder, and `sonoflow check` reports a
    /// missing or unreadable file before anything starts.
    pub input_files: &'static [&'static str],
    /// Runs the node.
    pub run: fn(Kit) -> anyhow::Result<()>,
}

impl KindSpec {
    /// The port `name` of direction `dir`.
    pub fn port(&self, name: &str, dir: PortDir) -> Option<&PortSpec> {
        self.ports.iter().find(|p| p.name == name && p.dir == dir)
    }

    /// Names of the ports of direction `dir` (`["none"]` if it has none).
    pub fn port_names(&self, dir: PortDir) -> Vec<&'static str> {
        let v: Vec<_> = self.ports.iter().filter(|p| p.dir == dir).map(|p| p.name).collect();
        if v.is_empty() {
            vec!["none"]
        } else {
            v
        }
    }
}

/// Deserialises a node's params (`null` = empty table) into `P`; the error names the field
/// path (`grid.nx: invalid type …`).
pub fn parse_params<P: serde::de::DeserializeOwned>(v: &serde_json::Value) -> Result<P, String> {
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

/// Range check: `Err("field = v is out of range: lo ..= hi")`.
pub fn in_range<T: PartialOrd + std::fmt::Display>(field: &str, v: T, lo: T, hi: T) -> Result<(), String> {
    if v >= lo && v <= hi {
        Ok(())
    } else {
        Err(format!("{field} = {v} is out of range: {lo} ..= {hi}"))
    }
}
