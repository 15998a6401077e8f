//! # sonoflow-simus
//!
//! SIMUS RF synthesiser: the 2-D frequency-domain ultrasound simulator of Garcia's MUST toolbox
//! (Shahriari & Garcia 2018, *Meshfree simulations of ultrasound vector flow imaging using
//! smoothed particle hydrodynamics*, Phys. Med. Biol. 63 205011, section 2.3, eq. 14–18; MUST
//! `simus.m`/`pfield.m`, reproduced from PyMUST 0.1.9), written to match PyMUST to
//! nRMS ≤ 1e-4 and to run far faster.
//!
//! A uniform linear or convex array ([`Probe`]) transmits a windowed sine of `TXnow` cycles, shaped by the
//! probe's one-way response (module [`pulse`]), with per-element delays and apodisation
//! ([`Transmit`]). Each element is split into M sub-elements; in the far field of each
//! sub-element the field is `obliquity · directivity · exp((−α + ik) r) / √r` (eq. 14–16, module
//! `pfield`). Scatterers ([`Scatterers`], amplitudes = BSC of eq. 18) re-radiate as monopoles
//! (single scattering), and by reciprocity the same Green's function carries the echo back
//! (eq. 17): per frequency bin,
//!
//! `SPECT_e(k) = df·W · P(ω) H(ω)² Σ_s RC_s [Σ_e' D_e'(ω) R_se'(ω)] R_se(ω)`,
//!
//! with `D_e = apod_e·exp(iωτ_e)`, `R_se = Σ_m` sub-element phasors. The RF is the inverse real
//! FFT of the conjugated spectrum on MUST's grid ([`FrequencyPlan`], module [`grid`] documents
//! exactly how the grid and the band are chosen), scaled exactly as PyMUST (`SPECT *= df·W`,
//! `RF = irfft(conj(SPECT), nf)[:(nf+1)//2]`, amplitude ∝ df/fs), followed by PyMUST's −100 dB
//! small-value zeroing ([`SimusOptions::zero_small_values`]). Sample k is at `t0 + k/fs`,
//! `t0 = 0` = the instant the centre of the pulse leaves an element with zero delay.
//!
//! ## Use
//! ```
//! use sonoflow_simus::{Medium, Probe, Scatterers, Simus, SimusOptions, Transmit};
//! let probe = Probe::preset("paper-5mhz").unwrap();
//! let mut simus = Simus::new(probe.clone(), Medium::default(), SimusOptions::default()).unwrap();
//! let scat = Scatterers::new(vec![0.0], vec![0.01], vec![1.0]).unwrap();
//! let tx = Transmit::plane_wave(&probe, 1540.0, 0.0).unwrap();
//! let rf = simus.simulate(&scat, &tx).unwrap(); // RF element-major, rf.fs, rf.t0, rf.plan
//! assert_eq!(rf.data.len(), 128 * rf.n_samples);
//! ```
//! For a packet, plan once ([`Simus::plan_for_max_distance`] or [`PlanMode::MaxDistance`]) and
//! call [`Simus::simulate_into`] with a caller-owned buffer: same length and gain for every frame,
//! no allocation after the first frame.
//!
//! ## Numerics
//! [`Accuracy::Fast`] (default) steps the phasors `P ← P·exp(iΔk r)` in complex f32 like MUST but
//! re-anchors them exactly (f64 phase) every ≤ 128 bins, vectorised over elements (AVX-512/AVX2
//! with FMA chosen at run time, portable fallback), in parallel over fixed ranges of bins and
//! streaming fixed blocks of scatterers: memory is independent of the number of scatterers and
//! the output bits do not depend on the thread count. [`Accuracy::Exact`] evaluates every phasor
//! directly in f64 (reference). [`nrms`] measures any mode against another.
//!
//! Differences from PyMUST (all below its own 3e-5 float32 error): distances are kept in f64
//! (PyMUST rounds them to f32), the phasor recursion is re-anchored (PyMUST drifts by up to
//! 3.3e-5 rad across the band), sums and the inverse FFT are f64. Scatterers off the imaging
//! plane ([`Simus::simulate_3d`]) get MUST's elevation model (element height, elevation focus,
//! MGBM) on the exact kernel. Convex arrays (`Probe::radius`, C5-2v) as MUST: elements on the
//! arc ([`Probe::element_positions`]), sub-elements along each element, angles from each
//! element's normal, no field behind the face. Chirps (`TXfreqsweep`), receive delays and MLT
//! (several delay rows) are not implemented.

mod error;
mod exact;
pub mod grid;
mod kernel;
mod lanes;
mod math;
mod must;
pub mod noise;
mod params;
mod pfield;
pub mod phantom;
pub mod pressure;
mod probe;
pub mod pulse;
pub mod scan;
mod scatterers;
mod simus;
pub mod statics;
#[cfg(feature = "testkit")]
pub mod testkit;
mod transmit;

pub use error::{Result, SimusError};
pub use grid::FrequencyPlan;
pub use must::{MustParam, MustParts};
pub use noise::{NoiseModel, NoiseParams};
pub use params::{Accuracy, KernelChoice, Medium, PlanMode, RfWindow, SimusOptions};
pub use phantom::{genscat, must_meandist, resolution_cell_area, Inclusion, Phantom, PhantomParams};
pub use pressure::{pfield, pfield_3d, PfieldOptions, PressureField};
pub use probe::{Baffle, ElementPosition, Probe, PRESET_NAMES};
pub use scan::{
    packet_margin, tukey, FramePlanner, PacketMotion, PacketPlan, PlanChoice, ProbeSpec, Scan, ScanParams,
    TransmitField, FALLBACK_PLAN_MARGIN,
};
pub use scatterers::{ScattererSlices, Scatterers};
pub use simus::{zero_small_values, RfFrame, Simus};
pub use statics::StaticEchoes;
pub use transmit::Transmit;

/// Normalised RMS difference `‖a − b‖₂ / ‖b‖₂` (f64 sums); `b` is the reference. Returns 0 when
/// both are all zero, +∞ when only `b` is, NaN if the lengths differ.
pub fn nrms(a: &[f32], b: &[f32]) -> f64 {
    if a.len() != b.len() {
        return f64::NAN;
    }
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for (x, y) in a.iter().zip(b) {
        let d = f64::from(*x) - f64::from(*y);
        num += d * d;
        den += f64::from(*y) * f64::from(*y);
    }
    if den == 0.0 {
        return if num == 0.0 { 0.0 } else { f64::INFINITY };
    }
    (num / den).sqrt()
}

#[cfg(test)]
mod tests;
