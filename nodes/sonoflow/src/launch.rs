//! Launch files: parsing, `--set`/`--swap` resolution and the checks `sonoflow check` runs
//! before anything starts.
//!
//! ```toml
//! [graph]
//! name = "quickstart"
//!
//! [topics]
//! particles = { type = "ParticleSnapshotV1", max_elements = 20000, depth = 4 }
//!
//! [nodes.flow]
//! kind = "analytic-flow"                 # built-in kind, or: exec = "path/to/binary"
//! outputs = { particles = "particles" }  # port = topic
//! params = { density_per_mm2 = 10.0 }
//!
//! [nodes.recorder]
//! kind = "recorder"                      # records every topic unless params.topics says otherwise
//! ```

use crate::kinds::{self, KindSpec, PortDir};
use serde::{Deserialize, Serialize};
use sonoflow_messages::MessageKind;
use sonoflow_node_kit::TopicQos;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The `[graph]` table.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct GraphSection {
    /// Graph name (letters, digits, `-`, `_`).
    pub name: String,
    /// Free text.
    #[serde(default)]
    pub description: String,
    /// Seconds a node waits for its peers at start-up.
    #[serde(default = "d_handshake")]
    pub handshake_timeout_s: f64,
    /// Seconds the launcher waits for nodes to finish after a stop before escalating.
    #[serde(default = "d_grace")]
    pub stop_grace_s: f64,
}
fn d_handshake() -> f64 {
    30.0
}
fn d_grace() -> f64 {
    10.0
}

/// A `[topics.<name>]` entry.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct TopicDecl {
    /// Message kind (`RfFrameV1`, …).
    #[serde(rename = "type")]
    pub kind: String,
    /// Maximum payload elements per message.
    pub max_elements: usize,
    /// Queue depth per subscriber (1–64).
    #[serde(default = "d_depth")]
    pub depth: usize,
}
fn d_depth() -> usize {
    4
}

/// A selectable alternative of a node (the swap point: `--swap node=variant`).
#[derive(Clone, Debug, Deserialize, Serialize, Default)]
#[serde(deny_unknown_fields)]
pub struct VariantDecl {
    #[serde(default)]
    pub kind: Option<String>,
    #[serde(default)]
    pub exec: Option<String>,
    #[serde(default)]
    pub args: Vec<String>,
    #[serde(default)]
    pub ports: BTreeMap<String, String>,
    #[serde(default)]
    pub params: toml::Table,
}

/// A `[nodes.<name>]` entry.
#[derive(Clone, Debug, Deserialize, Serialize, Default)]
#[serde(deny_unknown_fields)]
pub struct NodeDecl {
    /// Built-in node kind (`sonoflow node <kind>`).
    #[serde(default)]
    pub kind: Option<String>,
    /// External executable speaking the node kit's wire format (path relative to the launch file).
    #[serde(default)]
    pub exec: Option<String>,
    /// Arguments of `exec`.
    #[serde(default)]
    pub args: Vec<String>,
    /// Port types of an `exec` node (`port = "RfFrameV1"`), checked against the topics.
    #[serde(default)]
    pub ports: BTreeMap<String, String>,
    /// Input port → topic.
    #[serde(default)]
    pub inputs: BTreeMap<String, String>,
    /// Output port → topic.
    #[serde(default)]
    pub outputs: BTreeMap<String, String>,
    /// Parameters (deserialised by the node into its library's params struct).
    #[serde(default)]
    pub params: toml::Table,
    /// Selected variant.
    #[serde(default)]
    pub variant: Option<String>,
    /// Alternatives.
    #[serde(default)]
    pub variants: BTreeMap<String, VariantDecl>,
}

/// A whole launch file.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct LaunchFile {
    pub graph: GraphSection,
    #[serde(default)]
    pub topics: BTreeMap<String, TopicDecl>,
    #[serde(default)]
    pub nodes: BTreeMap<String, NodeDecl>,
}

/// How a resolved node is started.
#[derive(Clone, Debug, Serialize)]
pub enum Program {
    /// `sonoflow node <kind>`.
    Builtin(String),
    /// An external executable and its arguments.
    Exec(PathBuf, Vec<String>),
}

/// A node after variant/`--set` resolution, with its QoS-annotated ports.
#[derive(Clone, Debug, Serialize)]
pub struct ResolvedNode {
    pub name: String,
    pub index: u32,
    pub program: Program,
    pub params: serde_json::Value,
    pub inputs: BTreeMap<String, TopicQos>,
    pub outputs: BTreeMap<String, TopicQos>,
    pub is_recorder: bool,
}

/// A checked graph ready to start.
#[derive(Clone, Debug, Serialize)]
pub struct ResolvedGraph {
    pub graph: GraphSection,
    pub nodes: Vec<ResolvedNode>,
    pub topics: BTreeMap<String, TopicQos>,
    pub stats: Option<TopicQos>,
    /// The resolved launch file (TOML text), attached to recordings.
    pub resolved_toml: String,
    /// Non-fatal remarks.
    pub warnings: Vec<String>,
    /// Shared memory the graph needs (bytes).
    pub shm_bytes: u64,
    /// Folder of the launch file (relative paths in params resolve against it).
    pub base_dir: PathBuf,
}

/// Name of the statistics topic.
pub const STATS_TOPIC: &str = "_stats";

/// Options that change a launch file from the command line.
#[derive(Clone, Debug, Default)]
pub struct Overrides {
    /// `node.param[.sub]=value`
    pub set: Vec<String>,
    /// `node=variant`
    pub swap: Vec<String>,
    /// `check` only: missing replay files are warnings instead of errors.
    pub lenient_files: bool,
}

fn valid_name(s: &str, extra: &str) -> bool {
    !s.is_empty() && s.chars().all(|c| c.is_ascii_alphanumeric() || "-_".contains(c) || extra.contains(c))
}

/// Parses a `--set` value as a TOML value (number, bool, array, string); bare words are strings.
fn parse_value(raw: &str) -> toml::Value {
    match toml::from_str::<toml::Table>(&format!("v = {raw}")) {
        Ok(mut t) => t.remove("v").unwrap_or_else(|| toml::Value::String(raw.to_string())),
        Err(_) => toml::Value::String(raw.to_string()),
    }
}

fn set_path(table: &mut toml::Table, path: &[&str], value: toml::Value) -> Result<(), String> {
    let (first, rest) = path.split_first().ok_or("empty parameter path")?;
    if rest.is_empty() {
        table.insert(first.to_string(), value);
        return Ok(());
    }
    let entry = table.entry(first.to_string()).or_insert_with(|| toml::Value::Table(toml::Table::new()));
    match entry {
        toml::Value::Table(t) => set_path(t, rest, value),
        other => Err(format!("`{first}` is a {}, not a table", other.type_str())),
    }
}

fn merge(base: &mut toml::Table, over: &toml::Table) {
    for (k, v) in over {
        match (base.get_mut(k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge(b, o),
            _ => {
                base.insert(k.clone(), v.clone());
            }
        }
    }
}

/// Reads, resolves and checks a launch file. Returns every problem found (nothing is started).
pub fn load(path: &Path, ov: &Overrides) -> Result<ResolvedGraph, Vec<String>> {
    let text = std::fs::read_to_string(path).map_err(|e| vec![format!("{}: {e}", path.display())])?;
    let base_dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let file: LaunchFile =
        toml::from_str(&text).map_err(|e| vec![format!("{}: {}", path.display(), e.to_string().trim_end())])?;
    resolve(file, &base_dir, ov).map_err(|errs| errs.into_iter().map(|e| format!("{}: {e}", path.display())).collect())
}

/// Resolves and checks a parsed launch file.
pub fn resolve(mut file: LaunchFile, base_dir: &Path, ov: &Overrides) -> Result<ResolvedGraph, Vec<String>> {
    let mut errors = Vec::new();
    let mut warnings = Vec::new();

    // --swap
    for s in &ov.swap {
        match s.split_once('=') {
            Some((node, variant)) => match file.nodes.get_mut(node) {
                Some(n) if n.variants.contains_key(variant) => n.variant = Some(variant.to_string()),
                Some(n) => errors.push(format!(
                    "--swap {s}: node `{node}` has no variant `{variant}` (variants: {})",
                    if n.variants.is_empty() {
                        "none".into()
                    } else {
                        n.variants.keys().cloned().collect::<Vec<_>>().join(", ")
                    }
                )),
                None => errors.push(format!("--swap {s}: no node `{node}`")),
            },
            None => errors.push(format!("--swap {s}: expected NODE=VARIANT")),
        }
    }
    // Apply variants.
    for (name, n) in file.nodes.iter_mut() {
        if let Some(v) = n.variant.clone() {
            let Some(var) = n.variants.get(&v).cloned() else {
                errors.push(format!("node `{name}`: variant `{v}` is not defined under [nodes.{name}.variants]"));
                continue;
            };
            if var.kind.is_some() || var.exec.is_some() {
                n.kind = var.kind.clone();
                n.exec = var.exec.clone();
                n.args = var.args.clone();
            }
            if !var.ports.is_empty() {
                n.ports = var.ports.clone();
            }
            merge(&mut n.params, &var.params);
        }
    }
    // --set
    for s in &ov.set {
        let Some((key, raw)) = s.split_once('=') else {
            errors.push(format!("--set {s}: expected NODE.PARAM=VALUE"));
            continue;
        };
        let parts: Vec<&str> = key.split('.').collect();
        if parts.len() < 2 || parts.iter().any(|p| p.is_empty()) {
            errors.push(format!("--set {s}: expected NODE.PARAM=VALUE"));
            continue;
        }
        match file.nodes.get_mut(parts[0]) {
            Some(n) => {
                if let Err(e) = set_path(&mut n.params, &parts[1..], parse_value(raw)) {
                    errors.push(format!("--set {s}: {e}"));
                }
            }
            None => errors.push(format!(
                "--set {s}: no node `{}` (nodes: {})",
                parts[0],
                file.nodes.keys().cloned().collect::<Vec<_>>().join(", ")
            )),
        }
    }

    // [graph]
    if !valid_name(&file.graph.name, "") {
        errors.push(format!("graph.name = {:?}: use letters, digits, `-` and `_` only", file.graph.name));
    }
    if !(file.graph.handshake_timeout_s.is_finite() && (0.1..=600.0).contains(&file.graph.handshake_timeout_s)) {
        errors.push(format!(
            "graph.handshake_timeout_s = {} is out of range: 0.1 ..= 600",
            file.graph.handshake_timeout_s
        ));
    }
    if !(file.graph.stop_grace_s.is_finite() && (0.1..=600.0).contains(&file.graph.stop_grace_s)) {
        errors.push(format!("graph.stop_grace_s = {} is out of range: 0.1 ..= 600", file.graph.stop_grace_s));
    }

    // [topics]
    let mut topic_kinds: BTreeMap<String, MessageKind> = BTreeMap::new();
    for (name, t) in &file.topics {
        if !valid_name(name, "/") || name.starts_with('_') {
            errors.push(format!("topic `{name}`: names use letters, digits, `-`, `_`, `/` and do not start with `_`"));
        }
        match MessageKind::from_name(&t.kind) {
            Some(k) => {
                topic_kinds.insert(name.clone(), k);
            }
            None => errors.push(format!(
                "topics.{name}.type = {:?} is not a message type (allowed: {})",
                t.kind,
                MessageKind::ALL
                    .iter()
                    .filter(|k| **k != MessageKind::StageStatsV1)
                    .map(|k| k.name())
                    .collect::<Vec<_>>()
                    .join(", ")
            )),
        }
        if !(1..=(1usize << 28)).contains(&t.max_elements) {
            errors.push(format!("topics.{name}.max_elements = {} is out of range: 1 ..= 268435456", t.max_elements));
        }
        if !(1..=64).contains(&t.depth) {
            errors.push(format!("topics.{name}.depth = {} is out of range: 1 ..= 64", t.depth));
        }
    }

    if file.nodes.is_empty() {
        errors.push("the graph has no [nodes]".into());
    }

    // Nodes: programs, ports, params.
    struct Wiring {
        inputs: BTreeMap<String, String>,
        outputs: BTreeMap<String, String>,
    }
    let mut programs: BTreeMap<String, (Program, Option<&'static KindSpec>)> = BTreeMap::new();
    let mut wiring: BTreeMap<String, Wiring> = BTreeMap::new();
    let mut params_json: BTreeMap<String, serde_json::Value> = BTreeMap::new();
    for (name, n) in &file.nodes {
        if !valid_name(name, "") {
            errors.push(format!("node `{name}`: names use letters, digits, `-` and `_` only"));
        }
        let params = match serde_json::to_value(&n.params) {
            Ok(v) => v,
            Err(e) => {
                errors.push(format!("nodes.{name}.params: {e}"));
                serde_json::Value::Null
            }
        };
        let (program, spec) = match (&n.kind, &n.exec) {
            (Some(_), Some(_)) => {
                errors.push(format!("node `{name}`: give either `kind` or `exec`, not both"));
                continue;
            }
            (None, None) => {
                errors.push(format!(
                    "node `{name}`: needs `kind = \"…\"` (built-in: {}) or `exec = \"path\"`",
                    kinds::names().join(", ")
                ));
                continue;
            }
            (Some(k), None) => match kinds::spec(k) {
                Some(s) => (Program::Builtin(k.clone()), Some(s)),
                None => {
                    errors.push(format!(
                        "node `{name}`: kind `{k}` is unknown (built-in: {})",
                        kinds::names().join(", ")
                    ));
                    continue;
                }
            },
            (None, Some(e)) => {
                let p = resolve_exec(e, base_dir);
                match p {
                    Some(p) => (Program::Exec(p, n.args.clone()), None),
                    None => {
                        errors.push(format!(
                            "node `{name}`: exec `{e}` not found (relative to {} or on PATH) or not executable",
                            base_dir.display()
                        ));
                        continue;
                    }
                }
            }
        };
        let mut inputs = n.inputs.clone();
        let outputs = n.outputs.clone();
        // Port checks.
        match spec {
            Some(spec) => {
                if let Err(e) = (spec.validate)(&params) {
                    errors.push(format!("nodes.{name}.params: {e}"));
                }
                let wired: Vec<&str> = inputs.keys().map(String::as_str).collect();
                if let Err(e) = kinds::check_wiring(spec.name, &params, &wired) {
                    errors.push(format!("node `{name}` ({}): {e}", spec.name));
                }
                if spec.dynamic_inputs {
                    // Recorder: inputs derived from params.topics.
                    if !inputs.is_empty() {
                        errors.push(format!("node `{name}` ({}): set `params.topics` instead of `inputs`", spec.name));
                    }
                    inputs.clear();
                    let wanted: Vec<String> = params
                        .get("topics")
                        .and_then(|v| v.as_array())
                        .map(|a| a.iter().filter_map(|s| s.as_str().map(String::from)).collect())
                        .unwrap_or_else(|| vec!["*".to_string()]);
                    for w in wanted {
                        if w == "*" {
                            for t in file.topics.keys() {
                                inputs.insert(t.clone(), t.clone());
                            }
                        } else if file.topics.contains_key(&w) {
                            inputs.insert(w.clone(), w.clone());
                        } else {
                            errors.push(format!("nodes.{name}.params.topics: no topic `{w}`"));
                        }
                    }
                } else {
                    for (dir, map) in [(PortDir::In, &inputs), (PortDir::Out, &outputs)] {
                        for (port, topic) in map.iter() {
                            if spec.dynamic_outputs && dir == PortDir::Out {
                                continue;
                            }
                            match spec.port(port, dir) {
                                Some(p) => {
                                    if let Some(tk) = topic_kinds.get(topic) {
                                        if *tk != p.kind {
                                            errors.push(format!(
                                                "node `{name}` {} `{port}` carries {} but topic `{topic}` is {}",
                                                dir.word(),
                                                p.kind,
                                                tk
                                            ));
                                        }
                                    }
                                }
                                None => errors.push(format!(
                                    "node `{name}` ({}): no {} port `{port}` (allowed: {})",
                                    spec.name,
                                    dir.word(),
                                    spec.port_names(dir).join(", ")
                                )),
                            }
                        }
                    }
                    for p in spec.ports.iter().filter(|p| p.required) {
                        let map = if p.dir == PortDir::In { &inputs } else { &outputs };
                        if !map.contains_key(p.name) {
                            errors.push(format!(
                                "node `{name}` ({}): required {} port `{}` is not wired",
                                spec.name,
                                p.dir.word(),
                                p.name
                            ));
                        }
                    }
                }
            }
            None => {
                for (port, topic) in inputs.iter().chain(outputs.iter()) {
                    match n.ports.get(port).map(|k| (k, MessageKind::from_name(k))) {
                        Some((_, Some(pk))) => {
                            if let Some(tk) = topic_kinds.get(topic) {
                                if *tk != pk {
                                    errors.push(format!(
                                        "node `{name}` port `{port}` carries {pk} but topic `{topic}` is {tk}"
                                    ));
                                }
                            }
                        }
                        Some((k, None)) => {
                            errors.push(format!("nodes.{name}.ports.{port} = {k:?} is not a message type"))
                        }
                        None => errors.push(format!(
                            "node `{name}` (exec): port `{port}` needs its type in `ports = {{ {port} = \"…\" }}`"
                        )),
                    }
                }
            }
        }
        for (port, topic) in inputs.iter().chain(outputs.iter()) {
            if !file.topics.contains_key(topic) {
                errors.push(format!("node `{name}` port `{port}` → topic `{topic}` is not declared under [topics]"));
            }
        }
        programs.insert(name.clone(), (program, spec));
        wiring.insert(name.clone(), Wiring { inputs, outputs });
        params_json.insert(name.clone(), params);
    }

    // Producers and consumers per topic.
    let mut producers: BTreeMap<&str, Vec<&str>> = BTreeMap::new();
    let mut consumers: BTreeMap<&str, Vec<&str>> = BTreeMap::new();
    for (name, w) in &wiring {
        for t in w.outputs.values() {
            producers.entry(t.as_str()).or_default().push(name.as_str());
        }
        for t in w.inputs.values() {
            consumers.entry(t.as_str()).or_default().push(name.as_str());
        }
    }
    for t in file.topics.keys() {
        let p = producers.get(t.as_str()).map(Vec::len).unwrap_or(0);
        let c = consumers.get(t.as_str()).map(Vec::len).unwrap_or(0);
        if p > 1 {
            errors.push(format!(
                "topic `{t}` has {p} producers ({}): exactly one is allowed",
                producers[t.as_str()].join(", ")
            ));
        }
        if p == 0 && c > 0 {
            errors.push(format!(
                "topic `{t}` is consumed by {} but no node produces it (dangling input)",
                consumers[t.as_str()].join(", ")
            ));
        }
        if p == 0 && c == 0 {
            warnings.push(format!("topic `{t}` is declared but not used"));
        }
        if p == 1 && c == 0 {
            warnings.push(format!("topic `{t}` is produced but nobody consumes or records it"));
        }
    }

    // A Doppler node's `aperture` describes the receive aperture of the beamformer feeding it:
    // its per-pixel projections are wrong if f-number or apodisation differ.
    for (name, (_, spec)) in &programs {
        if !spec.is_some_and(|s| s.name == "doppler" || s.name == "doppler-loupas") {
            continue;
        }
        let Some(topic) = wiring.get(name).and_then(|w| w.inputs.get("iq")) else { continue };
        let Some(&[src]) = producers.get(topic.as_str()).map(Vec::as_slice) else { continue };
        if !programs.get(src).is_some_and(|(_, sp)| sp.is_some_and(|s| s.name == "beamformer")) {
            continue;
        }
        let (Some(dv), Some(bv)) = (params_json.get(name), params_json.get(src)) else { continue };
        let (Ok(d), Ok(b)) = (
            crate::kinds::parse::<crate::node_doppler::DopplerNodeParams>(dv),
            crate::kinds::parse::<crate::node_beamform::BeamformerParams>(bv),
        ) else {
            continue;
        };
        if let Some(a) = &d.aperture {
            if a.fnumber.to_bits() != b.fnumber.to_bits() {
                errors.push(format!(
                    "nodes.{name}.params.aperture.fnumber = {} but its beamformer `{src}` has fnumber = {}: they must match (the per-pixel Doppler projections follow the beamformer's aperture)",
                    a.fnumber, b.fnumber
                ));
            }
            if a.apodization != b.apodization {
                errors.push(format!(
                    "nodes.{name}.params.aperture.apodization = \"{}\" but its beamformer `{src}` has apodization = \"{}\": they must match (the per-pixel Doppler projections weight the elements as the beamformer does)",
                    format!("{:?}", a.apodization).to_lowercase(),
                    format!("{:?}", b.apodization).to_lowercase()
                ));
            }
        }
    }

    // QoS.
    let mut topics_qos = BTreeMap::new();
    for (name, t) in &file.topics {
        let c = consumers.get(name.as_str()).map(Vec::len).unwrap_or(0);
        topics_qos.insert(
            name.clone(),
            TopicQos {
                topic: name.clone(),
                kind: t.kind.clone(),
                max_elements: t.max_elements,
                depth: t.depth,
                max_subscribers: c.max(1),
                max_publishers: 1,
                expected_subscribers: c,
            },
        );
    }
    let recorders: Vec<&String> =
        programs.iter().filter(|(_, (_, s))| s.map(|s| s.dynamic_inputs).unwrap_or(false)).map(|(n, _)| n).collect();
    let n_stat_publishers = programs.len() - recorders.len();
    let stats = if recorders.is_empty() || n_stat_publishers == 0 {
        None
    } else {
        Some(TopicQos {
            topic: STATS_TOPIC.into(),
            kind: MessageKind::StageStatsV1.name().into(),
            max_elements: 256,
            depth: 64,
            max_subscribers: recorders.len(),
            max_publishers: n_stat_publishers,
            expected_subscribers: recorders.len(),
        })
    };

    // Shared-memory budget.
    let mut shm_bytes = 0u64;
    for q in topics_qos.values() {
        if let Some(k) = MessageKind::from_name(&q.kind) {
            shm_bytes += q.shm_bytes(k.elem_size(), k.header_size()) * q.max_publishers as u64;
        }
    }
    if let Some(q) = &stats {
        shm_bytes += q.shm_bytes(1, MessageKind::StageStatsV1.header_size()) * q.max_publishers as u64;
    }
    if let Some(avail) = shm_available() {
        if shm_bytes > avail {
            errors.push(format!(
                "the graph needs {:.1} MB of shared memory but /dev/shm has {:.1} MB free: lower max_elements/depth or enlarge /dev/shm",
                shm_bytes as f64 / 1e6,
                avail as f64 / 1e6
            ));
        }
    }

    // Replay files.
    for (name, (_, spec)) in &programs {
        if spec.map(|s| s.name == "replay").unwrap_or(false) {
            if let Some(p) = params_json.get(name).and_then(|v| v.get("path")).and_then(|v| v.as_str()) {
                let full = base_dir.join(p);
                if !Path::new(p).exists() && !full.exists() {
                    let msg = format!("nodes.{name}.params.path: recording `{p}` does not exist");
                    if ov.lenient_files {
                        warnings.push(msg)
                    } else {
                        errors.push(msg)
                    }
                }
            }
        }
    }

    if !errors.is_empty() {
        return Err(errors);
    }

    let mut nodes = Vec::new();
    for (index, (name, (program, spec))) in programs.into_iter().enumerate() {
        let w = &wiring[&name];
        let q = |m: &BTreeMap<String, String>| -> BTreeMap<String, TopicQos> {
            m.iter().filter_map(|(p, t)| topics_qos.get(t).map(|q| (p.clone(), q.clone()))).collect()
        };
        nodes.push(ResolvedNode {
            index: index as u32,
            program,
            params: params_json.remove(&name).unwrap_or(serde_json::Value::Null),
            inputs: q(&w.inputs),
            outputs: q(&w.outputs),
            is_recorder: spec.map(|s| s.dynamic_inputs).unwrap_or(false),
            name,
        });
    }
    let resolved_toml = toml::to_string_pretty(&file).unwrap_or_default();
    Ok(ResolvedGraph {
        graph: file.graph,
        nodes,
        topics: topics_qos,
        stats,
        resolved_toml,
        warnings,
        shm_bytes,
        base_dir: base_dir.to_path_buf(),
    })
}

fn resolve_exec(e: &str, base_dir: &Path) -> Option<PathBuf> {
    use std::os::unix::fs::PermissionsExt;
    let is_exec = |p: &Path| p.is_file() && p.metadata().map(|m| m.permissions().mode() & 0o111 != 0).unwrap_or(false);
    let p = Path::new(e);
    if p.is_absolute() {
        return is_exec(p).then(|| p.to_path_buf());
    }
    if e.contains('/') {
        let full = base_dir.join(p);
        if is_exec(&full) {
            return full.canonicalize().ok();
        }
        return is_exec(p).then(|| p.canonicalize().ok()).flatten();
    }
    // Next to the sonoflow binary (cargo builds them together), then PATH.
    if let Some(dir) = std::env::current_exe().ok().and_then(|x| x.parent().map(Path::to_path_buf)) {
        let c = dir.join(e);
        if is_exec(&c) {
            return Some(c);
        }
    }
    std::env::var_os("PATH").and_then(|paths| std::env::split_paths(&paths).map(|d| d.join(e)).find(|c| is_exec(c)))
}

/// Free bytes in /dev/shm, if it exists.
pub fn shm_available() -> Option<u64> {
    let path = std::ffi::CString::new("/dev/shm").ok()?;
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    // SAFETY: statvfs writes into the struct we own; the path is a valid C string.
    let rc = unsafe { libc::statvfs(path.as_ptr(), &mut st) };
    (rc == 0).then(|| st.f_bavail as u64 * st.f_frsize as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    const G: &str = r#"
[graph]
name = "g"
[topics]
rf = { type = "RfFrameV1", max_elements = 1024 }
out = { type = "RfFrameV1", max_elements = 1024 }
[nodes.src]
kind = "test-source"
outputs = { rf = "rf" }
params = { n_frames = 2, n_channels = 4, n_samples = 16 }
[nodes.stage]
kind = "gain"
inputs = { rf_in = "rf" }
outputs = { rf_out = "out" }
params = { gain = 3.0 }
[nodes.stage.variants.half]
params = { gain = 0.5 }
[nodes.rec]
kind = "recorder"
"#;

    fn res(ov: Overrides) -> Result<ResolvedGraph, Vec<String>> {
        resolve(toml::from_str(G).unwrap(), Path::new("."), &ov)
    }

    #[test]
    fn qos_counts_consumers_and_recorder() {
        let g = res(Overrides::default()).unwrap();
        // rf: gain + recorder; out: recorder only.
        assert_eq!(g.topics["rf"].expected_subscribers, 2);
        assert_eq!(g.topics["out"].expected_subscribers, 1);
        let st = g.stats.as_ref().unwrap();
        assert_eq!((st.max_publishers, st.max_subscribers), (2, 1));
        let rec = g.nodes.iter().find(|n| n.name == "rec").unwrap();
        assert!(rec.is_recorder);
        assert_eq!(rec.inputs.keys().cloned().collect::<Vec<_>>(), vec!["out", "rf"]);
        // Shared memory: per topic (subscribers × (depth + 2) + 1) slots of the max payload.
        let per = |subs: u64| (subs * 6 + 1) * (1024 * 4 + 1168 + 64);
        assert!(g.shm_bytes >= per(2) + per(1));
    }

    #[test]
    fn set_and_swap_change_params() {
        let g = res(Overrides { set: vec!["src.n_frames=7".into(), "stage.gain=1.25".into()], ..Default::default() })
            .unwrap();
        let p = |n: &str| g.nodes.iter().find(|x| x.name == n).unwrap().params.clone();
        assert_eq!(p("src")["n_frames"], 7);
        assert_eq!(p("stage")["gain"], 1.25);
        let g = res(Overrides { swap: vec!["stage=half".into()], ..Default::default() }).unwrap();
        assert_eq!(g.nodes.iter().find(|x| x.name == "stage").unwrap().params["gain"], 0.5);
        // Strings, arrays and nested tables.
        assert_eq!(parse_value("abc"), toml::Value::String("abc".into()));
        assert_eq!(parse_value("[1, 2]"), toml::Value::Array(vec![1.into(), 2.into()]));
        let mut t = toml::Table::new();
        set_path(&mut t, &["a", "b"], 3.into()).unwrap();
        assert_eq!(t["a"]["b"], toml::Value::Integer(3));
        assert!(set_path(&mut t, &["a", "b", "c"], 1.into()).is_err());
    }

    #[test]
    fn every_problem_is_reported_at_once() {
        let errs = res(Overrides {
            set: vec!["src.n_channels=0".into(), "stage.gain=inf".into(), "nosuch.x=1".into()],
            swap: vec!["stage=double".into()],
            lenient_files: false,
        })
        .unwrap_err();
        assert_eq!(errs.len(), 4, "{errs:#?}");
    }

    /// A Doppler node's `aperture` must describe the beamformer that feeds it.
    #[test]
    fn doppler_aperture_must_match_its_beamformer() {
        let g = |bf: &str, ap: &str| {
            let text = format!(
                r#"
[graph]
name = "g"
[topics]
rf = {{ type = "RfFrameV1", max_elements = 1024 }}
iq = {{ type = "IqFrameV1", max_elements = 1024 }}
vector = {{ type = "VectorFieldV1", max_elements = 4096 }}
[nodes.src]
kind = "test-source"
outputs = {{ rf = "rf" }}
[nodes.bf]
kind = "beamformer"
inputs = {{ rf = "rf" }}
outputs = {{ iq = "iq" }}
params = {{ {bf} }}
[nodes.dop]
kind = "doppler"
inputs = {{ iq = "iq" }}
outputs = {{ vector = "vector" }}
params = {{ aperture = {{ pitch = 3e-4, n_elements = 128, {ap} }} }}
[nodes.rec]
kind = "recorder"
"#
            );
            resolve(toml::from_str(&text).unwrap(), Path::new("."), &Overrides::default())
        };
        assert!(g(r#"fnumber = 2.5, apodization = "hann""#, r#"fnumber = 2.5, apodization = "hann""#).is_ok());
        // defaults on both sides: f-number 1.5, boxcar
        assert!(g("", "fnumber = 1.5").is_ok());
        let errs = g(r#"fnumber = 2.5, apodization = "hann""#, "fnumber = 3.0").unwrap_err();
        assert_eq!(errs.len(), 2, "{errs:#?}");
        assert!(
            errs[0].contains("nodes.dop.params.aperture.fnumber = 3 but its beamformer `bf` has fnumber = 2.5"),
            "{errs:?}"
        );
        assert!(
            errs[1].contains(r#"aperture.apodization = "boxcar" but its beamformer `bf` has apodization = "hann""#),
            "{errs:?}"
        );
    }
}
