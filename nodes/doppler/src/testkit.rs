//! Test fixtures (feature `testkit`), shared by this crate's tests and the stability matrix
//! (`sonoflow stability`): synthetic slow-time packets of known phase rotation, the degenerate
//! vector geometries and the finiteness of a map. Test code: it panics where a fixture cannot be
//! built as written.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::f64::consts::PI;

use crate::{flags, solve_vector, DopplerMap, Projection, VectorField, VectorInput, C32};

/// Frames of one pixel per step: x_n = exp(i step n), zeros for None. A step of exactly π gives
/// (−1)ⁿ exactly (no sin(π n) rounding).
pub fn phase_packet(steps: &[Option<f64>], nf: usize) -> Vec<Vec<C32>> {
    (0..nf)
        .map(|n| {
            steps
                .iter()
                .map(|s| match s {
                    Some(s) if *s == PI => C32::new(if n % 2 == 0 { 1.0 } else { -1.0 }, 0.0),
                    Some(s) => {
                        let ph = s * n as f64;
                        C32::new(ph.cos() as f32, ph.sin() as f32)
                    }
                    None => C32::new(0.0, 0.0),
                })
                .collect()
        })
        .collect()
}

/// `n` one-pixel frames of a scatterer moving toward the probe at `v` m/s: the echo delay
/// 20 µs − 2 v n/(c PRF) shrinks each frame, the I/Q phase is −2π fc τ (so v > 0 reads positive).
pub fn approaching_packet(fc: f64, prf: f64, c: f64, v: f64, n: usize) -> Vec<Vec<C32>> {
    (0..n)
        .map(|k| {
            let tau = 20e-6 - 2.0 * v * k as f64 / prf / c;
            let ph = -2.0 * PI * fc * tau;
            vec![C32::new(ph.cos() as f32, ph.sin() as f32)]
        })
        .collect()
}

/// Slices of the frames, as `Packet::Frames` takes them.
pub fn frame_refs(frames: &[Vec<C32>]) -> Vec<&[C32]> {
    frames.iter().map(|f| f.as_slice()).collect()
}

/// Velocity, variance and power all finite.
pub fn map_finite(m: &DopplerMap) -> bool {
    m.velocity.iter().chain(&m.variance).chain(&m.power).all(|v| v.is_finite())
}

/// The vector solve of one pixel (Doppler 0.1 m/s) from the same receive angle twice (a singular
/// 2 × 2 system), and from two angles of which one is flagged: (flags, vx, vz) of each.
pub fn degenerate_vector_solves() -> [(u8, f32, f32); 2] {
    let d = vec![0.1f32];
    let ok = vec![0u8];
    let bad = vec![flags::NO_ESTIMATE];
    let nominal = |rx_angle| Projection::Nominal { tx_tilt: 0.0, rx_angle };
    let same = [
        VectorInput { velocity: &d, flags: &ok, projection: nominal(0.1) },
        VectorInput { velocity: &d, flags: &ok, projection: nominal(0.1) },
    ];
    let one_bad = [
        VectorInput { velocity: &d, flags: &bad, projection: nominal(-0.2) },
        VectorInput { velocity: &d, flags: &ok, projection: nominal(0.2) },
    ];
    let mut f = VectorField::default();
    [same, one_bad].map(|inputs| {
        solve_vector(&inputs, &mut f).expect("a valid vector solve");
        (f.flags[0], f.vx[0], f.vz[0])
    })
}
