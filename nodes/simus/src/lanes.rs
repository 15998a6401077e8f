//! The vector unit of the SIMUS kernels: 16 f32 lanes, 64-byte aligned.

/// SIMD lanes (elements per vector).
pub(crate) const L: usize = 16;

/// One vector of 16 lanes, 64-byte aligned.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C, align(64))]
pub(crate) struct V(pub [f32; L]);
