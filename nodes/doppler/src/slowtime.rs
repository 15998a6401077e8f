//! Per-pixel access to a packet's slow-time signals, shared by the clutter filters.

use num_complex::Complex;
use sonoflow_beamform::error::{check_len, Result};
use sonoflow_beamform::C32;

/// Runs `filter` on every pixel's slow-time signal (f64) of a packet given as one mutable slice
/// per frame (all of the same length), writing the result back.
pub fn for_each_pixel(frames: &mut [&mut [C32]], mut filter: impl FnMut(&mut [Complex<f64>])) -> Result<()> {
    let n_pix = frames.first().map_or(0, |f| f.len());
    for f in frames.iter() {
        check_len("clutter frame", f.len(), n_pix)?;
    }
    let mut x = vec![Complex::new(0.0f64, 0.0); frames.len()];
    for p in 0..n_pix {
        for (xi, f) in x.iter_mut().zip(frames.iter()) {
            *xi = Complex::new(f64::from(f[p].re), f64::from(f[p].im));
        }
        filter(&mut x);
        for (xi, f) in x.iter().zip(frames.iter_mut()) {
            f[p] = C32::new(xi.re as f32, xi.im as f32);
        }
    }
    Ok(())
}
