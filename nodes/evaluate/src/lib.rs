//! How wrong a run is, and the pictures that show it: the errors of estimated vector fields and
//! of each Doppler look against the ground truth (paper 1's measure: per pixel inside the
//! vessel, as a fraction of the largest true speed; [`metrics`]), the evaluation of a run
//! (`evaluation.json` / `evaluation.md`, [`evaluation`]; as messages arrive: [`online`]) and the PNG figures of run reports
//! ([`figures`]). No IPC: the `evaluator` node, the launcher's report and the tests call it.

pub mod evaluation;
pub mod figures;
pub mod metrics;
pub mod online;
