//! The batch tools of the `sonoflow` command, each a thin layer of files and arguments over a
//! library crate: `simus` (scatterers → RF) `genscat` (speckle phantom), `pfield` (transmit pressure field), `rf2iq`, `das`, `iq2doppler` and `bmode` (the MUST
//! chain on `.npy` files), `smoothn` (robust smoothing of a field), `platelet` (training data, networks,
//! the five-particle experiment); `sweep` (a scene over a grid of settings, error against run
//! time); `bench` (transport and recorder benchmarks); and the recording tools `inspect` and
//! `recover`.

pub mod beamform;
pub mod bench;
pub mod bmode;
pub mod pfield;
pub mod platelet;
pub mod recording;
pub mod simus;
pub mod smoothn;
pub mod sweep;
