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

use serde::{Deserialize, Serialize};
use sonoflow_messages::MessageType;
use sonoflow_node_kit::{KindSpec, PortDir, TopicQos};
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
    /// Message type (`RfFrameV3`, …).
    #[serde(rename = "type")]
    pub message_type: String,
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
    /// Port types of an `exec` node (`port = "RfFrameV3"`), checked against the topics.
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
    /// Thread budget: worker threads of this node's process (1–1024; its rayon pool, through
    /// `RAYON_NUM_THREADS`, and `SONOFLOW_THREADS` for external programs). Absent: every CPU of
    /// the machine (an idle pool costs nothing, so a stage uses what the others leave idle).
    /// `--set NODE.cpus=N` sets it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cpus: Option<u32>,
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
    /// Thread budget ([`NodeDecl::cpus`]); `None`: every CPU.
    pub cpus: Option<u32>,
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

pub use sonoflow_node_kit::STATS_TOPIC;

/// Options that change a launch file from the command line.
#[derive(Clone, Debug, Default)]
pub struct Overrides {
    /// `node.param[.sub]=value`
    pub set: Vec<String>,
    /// `node=variant`
    pub swap: Vec<String>,
    /// `check` only: missing replay files are warnings instead of errors.
    pub lenient_files: bool,
    /// Nodes added to the file's `[nodes]` before `--swap` and `--set` apply (e.g. the live
    /// viewer of `sonoflow run --live`); a name the file already uses is an error.
    pub add_nodes: Vec<(String, NodeDecl)>,
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
pub fn load(path: &Path, ov: &Overrides, registry: &'static [KindSpec]) -> Result<ResolvedGraph, Vec<String>> {
    let text = std::fs::read_to_string(path).map_err(|e| vec![format!("{}: {e}", path.display())])?;
    let base_dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let file: LaunchFile =
        toml::from_str(&text).map_err(|e| vec![format!("{}: {}", path.display(), e.to_string().trim_end())])?;
    resolve(file, &base_dir, ov, registry)
        .map_err(|errs| errs.into_iter().map(|e| format!("{}: {e}", path.display())).collect())
}

/// Resolves and checks a parsed launch file.
pub fn resolve(
    mut file: LaunchFile,
    base_dir: &Path,
    ov: &Overrides,
    registry: &'static [KindSpec],
) -> Result<ResolvedGraph, Vec<String>> {
    let kind_names = registry.iter().map(|k| k.name).collect::<Vec<_>>().join(", ");
    let mut errors = Vec::new();
    let mut warnings = Vec::new();

    // Added nodes.
    for (name, decl) in &ov.add_nodes {
        if file.nodes.contains_key(name) {
            errors.push(format!("cannot add node `{name}`: the launch file already has a node of that name"));
        } else {
            file.nodes.insert(name.clone(), decl.clone());
        }
    }
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
    // --set (the keys set, for input files given relative to the working directory)
    let mut set_keys: std::collections::BTreeSet<(String, String)> = std::collections::BTreeSet::new();
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
            Some(n) if parts.len() == 2 && parts[1] == "cpus" => match raw.trim().parse::<u32>() {
                Ok(c) => n.cpus = Some(c),
                Err(_) => errors.push(format!("--set {s}: cpus is a whole number of threads, 1 ..= 1024")),
            },
            Some(n) => {
                if let Err(e) = set_path(&mut n.params, &parts[1..], parse_value(raw)) {
                    errors.push(format!("--set {s}: {e}"));
                }
                set_keys.insert((parts[0].to_string(), parts[1..].join(".")));
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
    let mut topic_types: BTreeMap<String, MessageType> = BTreeMap::new();
    for (name, t) in &file.topics {
        if !valid_name(name, "/") || name.starts_with('_') {
            errors.push(format!("topic `{name}`: names use letters, digits, `-`, `_`, `/` and do not start with `_`"));
        }
        match MessageType::parse(&t.message_type) {
            Ok(k) => {
                topic_types.insert(name.clone(), k);
            }
            Err(e) => errors.push(format!("topics.{name}.type: {e}")),
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
        cpus: Option<u32>,
    }
    let mut programs: BTreeMap<String, (Program, Option<&'static KindSpec>)> = BTreeMap::new();
    let mut wiring: BTreeMap<String, Wiring> = BTreeMap::new();
    let mut params_json: BTreeMap<String, serde_json::Value> = BTreeMap::new();
    for (name, n) in &file.nodes {
        if !valid_name(name, "") {
            errors.push(format!("node `{name}`: names use letters, digits, `-` and `_` only"));
        }
        if let Some(c) = n.cpus {
            if !(1..=1024).contains(&c) {
                errors.push(format!("nodes.{name}.cpus = {c} is out of range: 1 ..= 1024 threads"));
            }
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
                    kind_names
                ));
                continue;
            }
            (Some(k), None) => match registry.iter().find(|s| s.name == k) {
                Some(s) => (Program::Builtin(k.clone()), Some(s)),
                None => {
                    errors.push(format!("node `{name}`: kind `{k}` is unknown (built-in: {})", kind_names));
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
                if let Some(check) = spec.check_wiring {
                    if let Err(e) = check(&params, &wired) {
                        errors.push(format!("node `{name}` ({}): {e}", spec.name));
                    }
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
                    let accepts = |t: &str| match (spec.dynamic_input_types, MessageType::from_name(t)) {
                        (Some(f), Some(k)) => f(k),
                        (Some(_), None) => false,
                        (None, _) => true,
                    };
                    for w in wanted {
                        if w == "*" {
                            for (t, d) in &file.topics {
                                if accepts(&d.message_type) {
                                    inputs.insert(t.clone(), t.clone());
                                }
                            }
                        } else if let Some(d) = file.topics.get(&w) {
                            if accepts(&d.message_type) {
                                inputs.insert(w.clone(), w.clone());
                            } else {
                                errors.push(format!(
                                    "nodes.{name}.params.topics: topic `{w}` carries {}, which a {} node does not take",
                                    d.message_type, spec.name
                                ));
                            }
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
                                    if let Some(tk) = topic_types.get(topic) {
                                        if *tk != p.message_type {
                                            errors.push(format!(
                                                "node `{name}` {} `{port}` carries {} but topic `{topic}` is {}",
                                                dir.word(),
                                                p.message_type,
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
                    match n.ports.get(port).map(|k| (k, MessageType::from_name(k))) {
                        Some((_, Some(pk))) => {
                            if let Some(tk) = topic_types.get(topic) {
                                if *tk != pk {
                                    errors.push(format!(
                                        "node `{name}` port `{port}` carries {pk} but topic `{topic}` is {tk}"
                                    ));
                                }
                            }
                        }
                        Some((k, None)) => errors.push(format!(
                            "nodes.{name}.ports.{port}: {}",
                            MessageType::parse(k).err().unwrap_or_default()
                        )),
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
        wiring.insert(name.clone(), Wiring { inputs, outputs, cpus: n.cpus });
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

    // QoS.
    let mut topics_qos = BTreeMap::new();
    for (name, t) in &file.topics {
        let c = consumers.get(name.as_str()).map(Vec::len).unwrap_or(0);
        topics_qos.insert(
            name.clone(),
            TopicQos {
                topic: name.clone(),
                message_type: t.message_type.clone(),
                max_elements: t.max_elements,
                depth: t.depth,
                max_subscribers: c.max(1),
                max_publishers: 1,
                expected_subscribers: c,
            },
        );
    }
    let recorders: Vec<&String> =
        programs.iter().filter(|(_, (_, s))| s.map(|s| s.records).unwrap_or(false)).map(|(n, _)| n).collect();
    let n_stat_publishers = programs.len() - recorders.len();
    let stats = if recorders.is_empty() || n_stat_publishers == 0 {
        None
    } else {
        Some(TopicQos {
            topic: STATS_TOPIC.into(),
            message_type: MessageType::StageStatsV1.name().into(),
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
        if let Some(k) = MessageType::from_name(&q.message_type) {
            shm_bytes += q.shm_bytes(k.elem_size(), k.header_size()) * q.max_publishers as u64;
        }
    }
    if let Some(q) = &stats {
        shm_bytes += q.shm_bytes(1, MessageType::StageStatsV1.header_size()) * q.max_publishers as u64;
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

    // Input files: relative paths from the launch file resolve against its folder, those given
    // with `--set` against the working directory; each must exist and be readable.
    for (name, (_, spec)) in &programs {
        let Some(spec) = spec else { continue };
        let Some(params) = params_json.get_mut(name) else { continue };
        for key in spec.input_files {
            let from_cli = set_keys.contains(&(name.clone(), key.to_string()));
            match resolve_input_file(params, key, base_dir, from_cli) {
                Ok(()) => {}
                Err(e) => {
                    let msg = format!("nodes.{name}.params.{key}: {e}");
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
            is_recorder: spec.map(|s| s.records).unwrap_or(false),
            cpus: w.cpus,
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

/// Makes the input file named by the dotted parameter `key` absolute (against `base_dir`, or the
/// working directory for a value given on the command line) and checks that it can be read (a
/// file is opened, a folder listed). An absent parameter is fine (the node's default).
fn resolve_input_file(
    params: &mut serde_json::Value,
    key: &str,
    base_dir: &Path,
    from_cli: bool,
) -> Result<(), String> {
    let mut slot = Some(params);
    for part in key.split('.') {
        slot = slot.and_then(|v| v.get_mut(part));
    }
    let Some(slot) = slot else { return Ok(()) };
    let Some(p) = slot.as_str().map(PathBuf::from) else {
        return if slot.is_null() { Ok(()) } else { Err(format!("{slot} is not a path (a string)")) };
    };
    let full = if p.is_absolute() {
        p.clone()
    } else {
        let base =
            if from_cli || base_dir.as_os_str().is_empty() { PathBuf::from(".") } else { base_dir.to_path_buf() };
        let base = std::path::absolute(&base).unwrap_or(base);
        base.join(&p)
    };
    let readable =
        if full.is_dir() { std::fs::read_dir(&full).map(|_| ()) } else { std::fs::File::open(&full).map(|_| ()) };
    if let Err(e) = readable {
        let whence = if p.is_absolute() {
            String::new()
        } else if from_cli {
            " (relative paths given with --set resolve against the working directory)".to_string()
        } else {
            format!(" (relative paths in a launch file resolve against its folder {})", base_dir.display())
        };
        return Err(format!("`{}` cannot be read: {e}{whence}", full.display()));
    }
    *slot = serde_json::Value::String(full.display().to_string());
    Ok(())
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
rf = { type = "RfFrameV3", max_elements = 1024 }
out = { type = "RfFrameV3", max_elements = 1024 }
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

    fn no_params(_: &serde_json::Value) -> Result<(), String> {
        Ok(())
    }
    fn positive_params(v: &serde_json::Value) -> Result<(), String> {
        for (k, x) in v.as_object().into_iter().flatten().filter(|(k, _)| *k != "table") {
            match x.as_f64() {
                Some(f) if f.is_finite() && f > 0.0 => {}
                _ => return Err(format!("{k} = {x} is out of range: > 0")),
            }
        }
        Ok(())
    }
    fn never(_: sonoflow_node_kit::Kit) -> anyhow::Result<()> {
        anyhow::bail!("not run in these tests")
    }

    /// A registry of three kinds, as a program hosting node kinds hands it to the launcher.
    static REGISTRY: &[KindSpec] = &[
        KindSpec::new(
            "test-source",
            "",
            &[sonoflow_node_kit::port("rf", PortDir::Out, MessageType::RfFrameV3, true)],
            positive_params,
            never,
        ),
        KindSpec::new(
            "gain",
            "",
            &[
                sonoflow_node_kit::port("rf_in", PortDir::In, MessageType::RfFrameV3, true),
                sonoflow_node_kit::port("rf_out", PortDir::Out, MessageType::RfFrameV3, true),
            ],
            positive_params,
            never,
        )
        .with_input_files(&["table"]),
        KindSpec::new("recorder", "", &[], no_params, never).with_dynamic_ports(true, false).recording(),
        KindSpec::new("viewer", "", &[], no_params, never)
            .with_dynamic_ports(true, false)
            .with_dynamic_input_types(|k| k == MessageType::VectorFieldV2),
    ];

    fn res(ov: Overrides) -> Result<ResolvedGraph, Vec<String>> {
        resolve(toml::from_str(G).unwrap(), Path::new("."), &ov, REGISTRY)
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

    fn viewer(topics: &[&str]) -> (String, NodeDecl) {
        let mut params = toml::Table::new();
        params.insert("topics".into(), toml::Value::Array(topics.iter().map(|t| toml::Value::from(*t)).collect()));
        let decl = NodeDecl { kind: Some("viewer".into()), params, ..Default::default() };
        ("view".to_string(), decl)
    }

    #[test]
    fn added_nodes_take_only_their_types_and_are_no_recorders() {
        // The test viewer takes vector fields only: `*` finds none of the graph's RF topics.
        let g = res(Overrides { add_nodes: vec![viewer(&["*"])], ..Default::default() }).unwrap();
        let v = g.nodes.iter().find(|n| n.name == "view").unwrap();
        assert!(v.inputs.is_empty() && !v.is_recorder);
        assert_eq!(g.stats.as_ref().unwrap().max_subscribers, 1, "only the recorder gets the statistics");
        let errs = res(Overrides { add_nodes: vec![viewer(&["rf"])], ..Default::default() }).unwrap_err();
        assert!(
            errs.iter().any(|e| e.contains("topic `rf` carries RfFrameV3, which a viewer node does not take")),
            "{errs:?}"
        );
        let (_, decl) = viewer(&["*"]);
        let errs = res(Overrides { add_nodes: vec![("rec".into(), decl)], ..Default::default() }).unwrap_err();
        assert!(errs.iter().any(|e| e.contains("cannot add node `rec`")), "{errs:?}");
        // `--set` reaches an added node.
        let g = res(Overrides {
            add_nodes: vec![viewer(&["*"])],
            set: vec!["view.linger_s=2".into()],
            ..Default::default()
        })
        .unwrap();
        assert_eq!(g.nodes.iter().find(|n| n.name == "view").unwrap().params["linger_s"], 2);
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
    fn a_thread_budget_is_a_node_setting_not_a_parameter() {
        let g = res(Overrides { set: vec!["stage.cpus=1".into()], ..Default::default() }).unwrap();
        let stage = g.nodes.iter().find(|x| x.name == "stage").unwrap();
        assert_eq!(stage.cpus, Some(1));
        assert!(stage.params.get("cpus").is_none(), "not passed to the node's params");
        assert_eq!(g.nodes.iter().find(|x| x.name == "src").unwrap().cpus, None, "default: every CPU");
        let errs = res(Overrides { set: vec!["stage.cpus=0".into(), "src.cpus=two".into()], ..Default::default() })
            .unwrap_err();
        assert!(errs.iter().any(|e| e.contains("nodes.stage.cpus = 0 is out of range: 1 ..= 1024")), "{errs:?}");
        assert!(errs.iter().any(|e| e.contains("--set src.cpus=two: cpus is a whole number")), "{errs:?}");
    }

    #[test]
    fn every_problem_is_reported_at_once() {
        let errs = res(Overrides {
            set: vec!["src.n_channels=0".into(), "stage.gain=inf".into(), "nosuch.x=1".into()],
            swap: vec!["stage=double".into()],
            lenient_files: false,
            ..Default::default()
        })
        .unwrap_err();
        assert_eq!(errs.len(), 4, "{errs:#?}");
    }

    /// Input files: a relative path in the launch file resolves against the file's folder (not
    /// the working directory), one given with `--set` against the working directory; a missing
    /// one is an error naming the parameter and the rule before anything starts (a warning when
    /// lenient, as `sonoflow check` of a scene whose data are made later).
    #[test]
    fn input_files_resolve_against_the_launch_folder_and_missing_ones_are_reported() {
        let scene = tempfile::tempdir().unwrap();
        std::fs::create_dir(scene.path().join("data")).unwrap();
        std::fs::write(scene.path().join("data/t.csv"), "1,2\n").unwrap();
        let with_table =
            |t: &str| G.replace("params = { gain = 3.0 }", &format!("params = {{ gain = 3.0, table = \"{t}\" }}"));
        let resolve_in =
            |text: &str, ov: &Overrides| resolve(toml::from_str(text).unwrap(), scene.path(), ov, REGISTRY);
        let g = resolve_in(&with_table("data/t.csv"), &Overrides::default()).unwrap();
        let stage = g.nodes.iter().find(|n| n.name == "stage").unwrap();
        let got = PathBuf::from(stage.params["table"].as_str().unwrap());
        assert!(got.is_absolute(), "{got:?}");
        assert_eq!(got.canonicalize().unwrap(), scene.path().join("data/t.csv").canonicalize().unwrap());
        // Missing: an error naming the parameter, the full path and the rule.
        let errs = resolve_in(&with_table("data/none.csv"), &Overrides::default()).unwrap_err();
        assert_eq!(errs.len(), 1, "{errs:?}");
        assert!(errs[0].contains("nodes.stage.params.table") && errs[0].contains("none.csv"), "{errs:?}");
        assert!(errs[0].contains("resolve against its folder"), "{errs:?}");
        let g =
            resolve_in(&with_table("data/none.csv"), &Overrides { lenient_files: true, ..Default::default() }).unwrap();
        assert!(g.warnings.iter().any(|w| w.contains("nodes.stage.params.table")), "{:?}", g.warnings);
        // --set: relative to the working directory (the scene folder's file is not found from
        // there, and the error says which rule applied).
        let ov = Overrides { set: vec!["stage.table=\"data/t.csv\"".into()], ..Default::default() };
        let errs = resolve_in(G, &ov).unwrap_err();
        assert!(errs.iter().any(|e| e.contains("--set") && e.contains("working directory")), "{errs:?}");
        let abs = scene.path().join("data/t.csv");
        let ov = Overrides { set: vec![format!("stage.table=\"{}\"", abs.display())], ..Default::default() };
        resolve_in(G, &ov).unwrap();
    }
}
