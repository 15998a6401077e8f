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
    /// With `dynamic_inputs`: the message types the kind takes (`topics = ["*"]` picks the
    /// graph's topics of these types; naming another is an error). `None`: every type.
    pub dynamic_input_types: Option<fn(MessageType) -> bool>,
    /// The kind records the graph (a recorder): it also receives the stage statistics, gets the
    /// resolved launch file, starts first and stops last, and its `path` must not exist yet.
    pub records: bool,
    /// Outputs named after recorded topics (a replay node).
    pub dynamic_outputs: bool,
    /// Checks the `[params]` table (deserialise + validate); the error names the field.
    pub validate: ParamCheck,
    /// Checks between the parameters and the wired inputs that `validate` cannot make
    /// (arguments: params, names of the wired input ports).
    pub check_wiring: Option<WiringCheck>,
    /// Parameters naming files the node reads (dotted paths into `[params]`, e.g. `path`):
    /// relative paths resolve against the launch file's folder, and `sonoflow check` reports a
    /// missing or unreadable file before anything starts.
    pub input_files: &'static [&'static str],
    /// Runs the node.
    pub run: RunFn,
}

/// `validate` of a kind.
pub type ParamCheck = fn(&serde_json::Value) -> Result<(), String>;
/// `run` of a kind.
pub type RunFn = fn(Kit) -> anyhow::Result<()>;

impl KindSpec {
    /// A kind with fixed ports, no wiring check and no input files (add them with
    /// [`KindSpec::with_input_files`], [`KindSpec::with_wiring_check`], [`KindSpec::with_dynamic_ports`]).
    pub const fn new(
        name: &'static str,
        about: &'static str,
        ports: &'static [PortSpec],
        validate: ParamCheck,
        run: RunFn,
    ) -> Self {
        Self {
            name,
            about,
            ports,
            dynamic_inputs: false,
            dynamic_input_types: None,
            records: false,
            dynamic_outputs: false,
            validate,
            check_wiring: None,
            input_files: &[],
            run,
        }
    }

    /// The same kind reading the files named by these params.
    pub const fn with_input_files(mut self, input_files: &'static [&'static str]) -> Self {
        self.input_files = input_files;
        self
    }

    /// The same kind with a params-against-wiring check.
    pub const fn with_wiring_check(mut self, check: WiringCheck) -> Self {
        self.check_wiring = Some(check);
        self
    }

    /// The same kind with inputs and/or outputs named after topics.
    pub const fn with_dynamic_ports(mut self, inputs: bool, outputs: bool) -> Self {
        self.dynamic_inputs = inputs;
        self.dynamic_outputs = outputs;
        self
    }

    /// The same kind with dynamic inputs limited to the message types `accepts` takes.
    pub const fn with_dynamic_input_types(mut self, accepts: fn(MessageType) -> bool) -> Self {
        self.dynamic_input_types = Some(accepts);
        self
    }

    /// The same kind as a recorder of the graph (see [`KindSpec::records`]).
    pub const fn recording(mut self) -> Self {
        self.records = true;
        self
    }

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

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use serde::Deserialize;
    use serde_json::json;

    #[derive(Debug, Deserialize, PartialEq)]
    #[serde(deny_unknown_fields)]
    struct Grid {
        nx: u32,
        #[serde(default)]
        dx: f64,
    }

    #[derive(Debug, Deserialize, PartialEq)]
    #[serde(deny_unknown_fields)]
    struct Params {
        grid: Grid,
        #[serde(default = "two")]
        gain: f32,
        #[serde(default)]
        layers: Vec<Grid>,
    }

    fn two() -> f32 {
        2.0
    }

    #[test]
    fn parse_params_reads_values_and_defaults() {
        let p: Params = parse_params(&json!({ "grid": { "nx": 64, "dx": 0.5 } })).unwrap();
        assert_eq!(p, Params { grid: Grid { nx: 64, dx: 0.5 }, gain: 2.0, layers: vec![] });
    }

    #[test]
    fn parse_params_errors_name_the_field() {
        let e = parse_params::<Params>(&json!({ "grid": { "nx": "many" } })).unwrap_err();
        assert!(e.starts_with("grid.nx: invalid type: string \"many\""), "{e}");

        let e = parse_params::<Params>(&json!({ "grid": { "nx": 1 }, "gain": true })).unwrap_err();
        assert!(e.starts_with("gain: invalid type: boolean"), "{e}");

        let e =
            parse_params::<Params>(&json!({ "grid": { "nx": 1 }, "layers": [{ "nx": 1 }, { "nx": -3 }] })).unwrap_err();
        assert!(e.starts_with("layers[1].nx: invalid value: integer `-3`"), "{e}");

        let e = parse_params::<Params>(&json!({ "grid": { "nx": 1, "ny": 2 } })).unwrap_err();
        assert!(e.contains("unknown field `ny`"), "{e}");
        assert!(e.starts_with("grid"), "the path to the unknown key: {e}");

        let e = parse_params::<Params>(&json!({ "grid": { "nx": 1 }, "gian": 2.0 })).unwrap_err();
        assert!(e.contains("unknown field `gian`, expected one of `grid`, `gain`, `layers`"), "{e}");

        let e = parse_params::<Params>(&json!({ "grid": { "dx": 1.0 } })).unwrap_err();
        assert!(e.starts_with("grid: missing field `nx`"), "{e}");
    }

    #[test]
    fn parse_params_null_is_an_empty_table() {
        #[derive(Debug, Deserialize, PartialEq, Default)]
        #[serde(deny_unknown_fields, default)]
        struct AllDefault {
            gain: f32,
        }
        assert_eq!(parse_params::<AllDefault>(&serde_json::Value::Null).unwrap(), AllDefault::default());
        // A required field is still required when the table is absent: the message names it.
        let e = parse_params::<Params>(&serde_json::Value::Null).unwrap_err();
        assert_eq!(e, "missing field `grid`");
        // Not a table at all.
        let e = parse_params::<Params>(&json!("gain = 2")).unwrap_err();
        assert!(e.starts_with("invalid type: string \"gain = 2\", expected struct Params"), "{e}");
    }

    #[test]
    fn in_range_is_inclusive_and_names_the_field() {
        assert_eq!(in_range("depth", 1, 1, 8), Ok(()));
        assert_eq!(in_range("depth", 8, 1, 8), Ok(()));
        assert_eq!(in_range("depth", 9, 1, 8), Err("depth = 9 is out of range: 1 ..= 8".to_string()));
        assert_eq!(in_range("depth", 0, 1, 8), Err("depth = 0 is out of range: 1 ..= 8".to_string()));
        assert_eq!(in_range("grid.dx", -0.5, 0.0, 1.0), Err("grid.dx = -0.5 is out of range: 0 ..= 1".to_string()));
        // NaN is never in range.
        assert_eq!(
            in_range("gain", f64::NAN, -1e30, 1e30),
            Err("gain = NaN is out of range: -1000000000000000000000000000000 ..= 1000000000000000000000000000000"
                .to_string())
        );
    }

    fn run(_: Kit) -> anyhow::Result<()> {
        Ok(())
    }

    fn validate(v: &serde_json::Value) -> Result<(), String> {
        parse_params::<Params>(v).map(|_| ())
    }

    const SPEC: KindSpec = KindSpec::new(
        "test",
        "a test kind",
        &[
            port("rf_in", PortDir::In, MessageType::RfFrameV3, true),
            port("iq_in", PortDir::In, MessageType::IqFrameV3, false),
            port("rf_in", PortDir::Out, MessageType::RfFrameV3, true),
        ],
        validate,
        run,
    );

    #[test]
    fn kind_spec_finds_ports_by_name_and_direction() {
        let p = SPEC.port("rf_in", PortDir::In).unwrap();
        assert_eq!((p.message_type, p.required), (MessageType::RfFrameV3, true));
        assert_eq!(SPEC.port("iq_in", PortDir::In).map(|p| p.required), Some(false));
        assert_eq!(SPEC.port("rf_in", PortDir::Out).map(|p| p.dir), Some(PortDir::Out));
        assert!(SPEC.port("iq_in", PortDir::Out).is_none());
        assert_eq!(SPEC.port_names(PortDir::In), ["rf_in", "iq_in"]);
        assert_eq!(SPEC.port_names(PortDir::Out), ["rf_in"]);
        let none = KindSpec { ports: &[], ..SPEC };
        assert_eq!(none.port_names(PortDir::Out), ["none"]);
        assert_eq!((PortDir::In.word(), PortDir::Out.word()), ("input", "output"));
        assert!((SPEC.validate)(&json!({ "grid": { "nx": 1 } })).is_ok());
        assert!((SPEC.validate)(&json!({})).unwrap_err().contains("grid"));
    }
}
