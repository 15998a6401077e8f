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

/// Per-pixel slow-time signals (f64).
pub type SlowTime = Vec<Vec<num_complex::Complex<f64>>>;

/// A synthetic clutter scene of `n_pix` pixels × `n_frames` frames: tissue `tissue_db` above
/// the blood in power, one component per entry of `tissue_freqs` (a complex Gaussian amplitude
/// per pixel times e^{i2π f t}, f in cycles per frame), and blood with a complex Gaussian
/// amplitude per pixel at a frequency spread linearly over `blood_band` across the pixels.
/// Returns (tissue + blood, blood alone). Deterministic in `seed` (splitmix64, Box–Muller).
pub fn tissue_and_blood(
    n_pix: usize,
    n_frames: usize,
    tissue_db: f64,
    tissue_freqs: &[f64],
    blood_band: (f64, f64),
    seed: u64,
) -> (SlowTime, SlowTime) {
    use num_complex::Complex;
    let mut state = seed;
    let mut uniform = move || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut gauss = move || {
        let (u, v) = (uniform().max(1e-300), uniform());
        Complex::from_polar((-u.ln()).sqrt(), 2.0 * PI * v)
    };
    let amp = 10f64.powf(tissue_db / 20.0);
    let tone = |f: f64, t: usize| Complex::from_polar(1.0, 2.0 * PI * f * t as f64);
    let mut mixed = Vec::with_capacity(n_pix);
    let mut blood = Vec::with_capacity(n_pix);
    for p in 0..n_pix {
        let tissue: Vec<Complex<f64>> = tissue_freqs.iter().map(|_| gauss() * amp).collect();
        let (a, f) = (gauss(), blood_band.0 + (blood_band.1 - blood_band.0) * p as f64 / n_pix as f64);
        let b: Vec<Complex<f64>> = (0..n_frames).map(|t| a * tone(f, t)).collect();
        mixed.push(
            (0..n_frames)
                .map(|t| b[t] + tissue.iter().zip(tissue_freqs).map(|(c, &fk)| c * tone(fk, t)).sum::<Complex<f64>>())
                .collect(),
        );
        blood.push(b);
    }
    (mixed, blood)
}

/// The packet as frames (f32) from per-pixel slow-time signals.
pub fn frames_of(pixels: &[Vec<num_complex::Complex<f64>>]) -> Vec<Vec<C32>> {
    let n = pixels.first().map_or(0, |p| p.len());
    (0..n).map(|t| pixels.iter().map(|p| C32::new(p[t].re as f32, p[t].im as f32)).collect()).collect()
}

/// Per-pixel slow-time signals (f64) from frames.
pub fn pixels_of(frames: &[Vec<C32>]) -> SlowTime {
    let n_pix = frames.first().map_or(0, |f| f.len());
    (0..n_pix)
        .map(|p| frames.iter().map(|f| num_complex::Complex::new(f64::from(f[p].re), f64::from(f[p].im))).collect())
        .collect()
}

/// Mean lag-1 Doppler frequency (cycles per frame, from the autocorrelation summed over the
/// pixels) and mean power of per-pixel slow-time signals.
pub fn frequency_and_power(pixels: &[Vec<num_complex::Complex<f64>>]) -> (f64, f64) {
    let r1: num_complex::Complex<f64> = pixels.iter().flat_map(|p| p.windows(2).map(|w| w[1] * w[0].conj())).sum();
    let n: usize = pixels.iter().map(|p| p.len()).sum();
    let p = pixels.iter().flatten().map(|v| v.norm_sqr()).sum::<f64>() / n.max(1) as f64;
    (r1.arg() / (2.0 * PI), p)
}
