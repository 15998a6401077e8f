//! Test fixtures (feature `testkit`), shared by the cross-process tests (`tests/failures.rs`) and
//! the stability matrix (`sonoflow stability`): a minimal valid launch file and the malformed
//! variants of it that `sonoflow check` must refuse with one clear error per problem.

/// A minimal valid launch file: a test source (4 channels × 16 samples, 2 frames) feeding a
/// checker over the topic `rf`.
pub const MINIMAL_GRAPH: &str = r#"
[graph]
name = "g"
[topics]
rf = { type = "RfFrameV3", max_elements = 1024 }
[nodes.source]
kind = "test-source"
outputs = { rf = "rf" }
params = { n_frames = 2, n_channels = 4, n_samples = 16 }
[nodes.checker]
kind = "checker"
inputs = { rf = "rf" }
"#;

/// [`MINIMAL_GRAPH`] with a misspelt key (`colour`) in `[graph]`.
pub fn unknown_key() -> String {
    MINIMAL_GRAPH.replace("[graph]\n", "[graph]\ncolour = 1\n")
}

/// [`MINIMAL_GRAPH`] with the checker's input wired to a topic `iq` of another type that no node
/// produces (a dangling input and a type mismatch at once).
pub fn dangling_input_and_type_mismatch() -> String {
    MINIMAL_GRAPH
        .replace("inputs = { rf = \"rf\" }", "inputs = { rf = \"iq\" }")
        .replace("[topics]\n", "[topics]\niq = { type = \"IqFrameV3\", max_elements = 10 }\n")
}

/// [`MINIMAL_GRAPH`] with two parameters out of range at once (`n_channels = 0`,
/// `max_elements = 0`).
pub fn out_of_range_params() -> String {
    MINIMAL_GRAPH.replace("n_channels = 4", "n_channels = 0").replace("max_elements = 1024", "max_elements = 0")
}

/// [`MINIMAL_GRAPH`] with a second node publishing `rf`.
pub fn two_producers() -> String {
    format!("{MINIMAL_GRAPH}\n[nodes.source2]\nkind = \"test-source\"\noutputs = {{ rf = \"rf\" }}\n")
}

/// An unclosed table header.
pub const TOML_SYNTAX_ERROR: &str = "[graph\nname = 1";
