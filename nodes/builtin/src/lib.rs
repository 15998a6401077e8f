//! The built-in node kinds of sonoflow: one thin adapter per kind between the node kit
//! (`sonoflow-node-kit`: ports, handshake, the per-message loop) and a library crate that holds
//! the algorithm. Each module is named after its kind (`sph-flow` → [`sph_flow`]) and exports
//! the kind's [`KindSpec`] (`SPEC`): ports, the check of its `[params]`, the files it reads, its
//! entry point. [`registry`] lists them for the launcher and `sonoflow node <kind>`.
//! [`flow_topics`] is shared by the two flow producers (particle snapshots, truth fields).

use sonoflow_node_kit::KindSpec;

pub mod analytic_flow;
pub mod beamformer;
pub mod checker;
pub mod doppler;
pub mod evaluator;
pub mod field_noise;
pub mod flow_topics;
pub mod gain;
pub mod live_view;
pub mod packet_node;
pub mod platelets;
pub mod recorder;
pub mod regulariser;
pub mod replay;
pub mod simus;
pub mod speckle_tracking;
pub mod sph_flow;
pub mod test_source;

static KINDS: &[KindSpec] = &[
    analytic_flow::SPEC,
    sph_flow::SPEC,
    platelets::SPEC,
    simus::SPEC,
    beamformer::SPEC,
    doppler::SPEC,
    speckle_tracking::SPEC,
    regulariser::SPEC,
    evaluator::SPEC,
    recorder::SPEC,
    live_view::SPEC,
    replay::SPEC,
    test_source::SPEC,
    gain::SPEC,
    field_noise::SPEC,
    checker::SPEC,
];

/// Every built-in node kind.
pub fn registry() -> &'static [KindSpec] {
    KINDS
}
