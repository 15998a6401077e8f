//! The launcher: launch files (TOML graphs) and running them.
//!
//! * [`launch`]: parse a launch file, apply `--set`/`--swap`, check everything `sonoflow check`
//!   checks (unknown keys, one producer per topic, message types, every node's parameters, input
//!   files, shared-memory budget) and resolve it into a [`launch::ResolvedGraph`].
//! * [`supervise`]: start the graph as separate processes, stream their logs and progress,
//!   supervise, stop everything in order (sources first, recorders last), and
//! * [`report`]: write the run report (`report.json`, `report.md`, figures).
//!
//! The launcher knows no node kind by name: the program hosting the kinds hands it a registry
//! (`&[sonoflow_node_kit::KindSpec]`: ports, parameter check, input files, entry point).

pub mod launch;
pub mod report;
pub mod supervise;
#[cfg(feature = "testkit")]
pub mod testkit;

pub use launch::{load, resolve, Overrides, ResolvedGraph};
pub use report::{NodeOutcome, RunReport};
pub use supervise::{default_out_dir, new_run_id, run_graph, RunOptions};
