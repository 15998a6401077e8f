//! `sonoflow` — the user-facing binary: launcher (`run`, `check`), built-in node kinds
//! (`node <kind>`), recording tools (`inspect`, `recover`), benchmarks (`bench`) and the stability matrix
//! (`stability`).
//! Algorithms live in library crates; this crate wires them to the node kit.

pub mod bench;
pub mod evaluate;
pub mod figures;
pub mod kinds;
pub mod launch;
pub mod node_beamform;
pub mod node_doppler;
pub mod node_evaluate;
pub mod node_flow;
pub mod node_platelet;
pub mod node_recorder;
pub mod node_regularise;
pub mod node_replay;
pub mod node_simus;
pub mod node_sph;
pub mod node_test;
pub mod nodeutil;
pub mod npy;
pub mod report;
pub mod run;
pub mod stability;
pub mod tool_beamform;
pub mod tool_platelet;
pub mod tool_simus;
pub mod tool_smoothn;
pub mod tool_sweep;
pub mod tools;
