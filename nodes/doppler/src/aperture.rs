//! Per-pixel Doppler projection vectors through the beamformer's receive aperture.
//!
//! A plane wave transmitted at tilt θt and received by the elements e of the aperture that the
//! delay-and-sum beamformer sums at pixel p measures `a · v` with
//! `a = −(sin θt + ⟨sin θe⟩, cos θt + ⟨cos θe⟩)/2`, the receive direction averaged over those
//! elements (the DAS aperture rule of `sonoflow-beamform`: centred on the line through the pixel
//! at the receive angle, width `z/(F cos rx)`, clipped by the array). Near the array's edge a
//! steered sub-aperture loses its oblique elements, so the nominal plane-wave projection
//! ([`crate::nominal_projection`]) over-states the lateral sensitivity there.

use serde::{Deserialize, Serialize};
use sonoflow_beamform::error::{invalid, Result};
use sonoflow_beamform::{Apodization, Grid};

/// The receive geometry of a beamformed image (MUST names): what the I/Q frame header carries.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Aperture {
    /// Element pitch (m).
    pub pitch: f64,
    /// Number of elements.
    #[serde(alias = "Nelements")]
    pub n_elements: usize,
    /// Receive f-number, as in the beamformer (0 = the whole array at every pixel).
    pub fnumber: f64,
    /// Element width (m, ≤ pitch). When given, each element's direction is weighted by the
    /// amplitude it receives from the pixel — directivity `sinc(π·width·sin θ/λ)`, soft-baffle
    /// obliquity `cos θ` and 2-D spreading `r^−½` at fc — because the phase of the summed echo,
    /// hence the Doppler shift, follows the strong (near-normal) elements. Absent: equal weights.
    #[serde(default)]
    pub width: Option<f64>,
    /// Radius of curvature of a convex array (m, MUST `radius`); absent = linear array. The
    /// elements then lie on the arc, the f-number aperture and the element directivity are
    /// taken relative to each element's normal, as the beamformer does.
    #[serde(default)]
    pub radius: Option<f64>,
    /// Receive apodisation, as the beamformer's `apodization`: the element weights of the mean
    /// receive direction.
    #[serde(default)]
    pub apodization: Apodization,
}

impl Aperture {
    /// Checks every field (errors name the field as `aperture.<field>`).
    pub fn validate(&self) -> Result<()> {
        if !(self.fnumber.is_finite() && (0.0..=1000.0).contains(&self.fnumber)) {
            return Err(invalid("aperture.fnumber", self.fnumber, "in [0, 1000] (0 = full aperture)"));
        }
        if !(self.pitch.is_finite() && self.pitch > 0.0 && self.pitch < 0.1) {
            return Err(invalid("aperture.pitch", self.pitch, "in (0, 0.1) m"));
        }
        if !(1..=65536).contains(&self.n_elements) {
            return Err(invalid("aperture.n_elements", self.n_elements, "in 1 ..= 65536"));
        }
        if let Some(w) = self.width {
            if !(w.is_finite() && w > 0.0 && w <= self.pitch) {
                return Err(invalid("aperture.width", w, "in (0, pitch] m"));
            }
        }
        if let Some(r) = self.radius {
            let max = sonoflow_beamform::convex::max_elements(self.pitch, r);
            if !(r.is_finite() && r > 0.0 && r <= sonoflow_beamform::convex::MAX_RADIUS) {
                return Err(invalid("aperture.radius", r, "finite, > 0 and <= 1e6 m (absent: linear array)"));
            }
            if self.pitch > 2.0 * r {
                return Err(invalid("aperture.pitch", self.pitch, "<= 2·radius on a convex array"));
            }
            if self.n_elements > max {
                return Err(invalid("aperture.n_elements", self.n_elements, "at most what fits on half the arc"));
            }
        }
        Ok(())
    }
}

/// Per-pixel Doppler projection vectors `[a_x, a_z]` (row-major on `grid`) of a plane-wave
/// transmit at `tx` and receive angle `rx` (rad) through the aperture `a`, at centre frequency
/// `fc` and speed of sound `c` (for the element directivity). A pixel that no element reaches
/// gets `[0, 0]`.
pub fn aperture_projection(a: &Aperture, fc: f64, c: f64, tx: f64, rx: f64, grid: &Grid) -> Result<Vec<[f32; 2]>> {
    a.validate()?;
    if !(fc.is_finite() && fc > 0.0) {
        return Err(invalid("fc", fc, "finite and > 0"));
    }
    if !(c.is_finite() && c > 0.0) {
        return Err(invalid("c", c, "finite and > 0"));
    }
    let lambda = c / fc;
    if let Some(r) = a.radius {
        return Ok(convex_projection(a, r, lambda, tx, rx, grid));
    }
    let xe: Vec<f64> = (0..a.n_elements).map(|e| (e as f64 - (a.n_elements as f64 - 1.0) / 2.0) * a.pitch).collect();
    let (tan_rx, cos_rx) = (rx.tan(), rx.cos());
    let mut out = Vec::with_capacity(grid.nx * grid.nz);
    for iz in 0..grid.nz {
        let z = grid.z(iz);
        for ix in 0..grid.nx {
            let x = grid.x(ix);
            let (mut sw, mut ss, mut sc) = (0.0f64, 0.0f64, 0.0f64);
            for &e in &xe {
                let dx = x - e;
                // offset from the aperture's centre and its half-width (the beamformer's rule)
                let (off, half) = match (a.fnumber > 0.0, rx == 0.0) {
                    (false, _) => (0.0, f64::INFINITY),
                    (true, true) => (dx, z / 2.0 / a.fnumber),
                    (true, false) => (dx - z * tan_rx, z / cos_rx / 2.0 / a.fnumber),
                };
                let r = dx.hypot(z);
                if off.abs() > half || r <= 0.0 {
                    continue;
                }
                let aw = if half.is_finite() { a.apodization.weight(-off / (2.0 * half)) } else { 1.0 };
                let (sin_t, cos_t) = (dx / r, z / r);
                let w = aw
                    * match a.width {
                        None => 1.0,
                        Some(width) => {
                            let u = std::f64::consts::PI * width * sin_t / lambda;
                            let sinc = if u.abs() < 1e-12 { 1.0 } else { u.sin() / u };
                            (sinc * cos_t).abs() / r.sqrt()
                        }
                    };
                sw += w;
                ss += w * sin_t;
                sc += w * cos_t;
            }
            out.push(if sw > 0.0 {
                [(-(tx.sin() + ss / sw) / 2.0) as f32, (-(tx.cos() + sc / sw) / 2.0) as f32]
            } else {
                [0.0, 0.0]
            });
        }
    }
    Ok(out)
}

/// [`aperture_projection`] on a convex array of radius `r`: elements on the arc (MUST
/// `getElementPositions`); element e is in the aperture of pixel p iff the direction from e to
/// p is within `atan(1/(2F))` of e's normal turned by `rx` (the beamformer's rule), apodised
/// across that angle; directivity and obliquity at the angle from e's normal.
fn convex_projection(a: &Aperture, r: f64, lambda: f64, tx: f64, rx: f64, grid: &Grid) -> Vec<[f32; 2]> {
    let (xe, ze, the) = sonoflow_beamform::convex::convex_element_positions(a.pitch, a.n_elements, r);
    let alpha = if a.fnumber > 0.0 { (1.0 / (2.0 * a.fnumber)).atan() } else { f64::INFINITY };
    let mut out = Vec::with_capacity(grid.nx * grid.nz);
    for iz in 0..grid.nz {
        let z = grid.z(iz);
        for ix in 0..grid.nx {
            let x = grid.x(ix);
            let (mut sw, mut ss, mut sc) = (0.0f64, 0.0f64, 0.0f64);
            for e in 0..xe.len() {
                let (dx, dz) = (x - xe[e], z - ze[e]);
                let d = dx.hypot(dz);
                // angle of the pixel from the element's normal, and from its receive direction
                let rel = dx.atan2(dz) - the[e];
                let off = rel - rx;
                if off.abs() > alpha || d <= 0.0 {
                    continue;
                }
                let aw = if alpha.is_finite() { a.apodization.weight(-off / (2.0 * alpha)) } else { 1.0 };
                let w = aw
                    * match a.width {
                        None => 1.0,
                        Some(width) => {
                            let (sin_n, cos_n) = rel.sin_cos();
                            let u = std::f64::consts::PI * width * sin_n / lambda;
                            let sinc = if u.abs() < 1e-12 { 1.0 } else { u.sin() / u };
                            (sinc * cos_n).abs() / d.sqrt()
                        }
                    };
                sw += w;
                ss += w * dx / d;
                sc += w * dz / d;
            }
            out.push(if sw > 0.0 {
                [(-(tx.sin() + ss / sw) / 2.0) as f32, (-(tx.cos() + sc / sw) / 2.0) as f32]
            } else {
                [0.0, 0.0]
            });
        }
    }
    out
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::nominal_projection;
    use sonoflow_beamform::{DasParams, DasPlan, Interpolation, TxWave};

    #[test]
    fn aperture_projection_is_nominal_inside_the_array_and_clipped_at_its_edge() {
        let a = Aperture {
            pitch: 0.3e-3,
            n_elements: 128,
            fnumber: 1.5,
            width: None,
            radius: None,
            apodization: Apodization::Boxcar,
        };
        // Two pixels at 20 mm depth: x = 0 (both ±15° sub-apertures inside the 38 mm array) and
        // x = 12 mm (the −15° sub-aperture, centred at x + 5.4 mm, is clipped by the edge at 19 mm).
        let grid = Grid { x0: 0.0, z0: 0.02, dx: 12e-3, dz: 1e-3, nx: 2, nz: 1 };
        let rx = (-15f64).to_radians();
        let p = aperture_projection(&a, 5e6, 1540.0, 0.0, rx, &grid).unwrap();
        let nom = nominal_projection(0.0, rx);
        // Centre: the mean direction over a ±18° aperture about −15° is close to −15° itself.
        assert!((p[0][0] as f64 - nom[0]).abs() < 0.01 && (p[0][1] as f64 - nom[1]).abs() < 0.01, "{p:?} vs {nom:?}");
        // Edge: fewer oblique elements, so the lateral sensitivity |a_x| shrinks.
        assert!((p[1][0] as f64).abs() < 0.9 * nom[0].abs(), "{p:?} vs {nom:?}");
        assert!(aperture_projection(&Aperture { fnumber: -1.0, ..a.clone() }, 5e6, 1540.0, 0.0, rx, &grid).is_err());
        // Same aperture rule and element weights as the beamformer's DAS plan: its (apodisation-
        // weighted) mean delay gradient gives the same projection (float32 gradients: 1e-4), for
        // equal weights and for the Hann window, which leans on the central elements (a_x closer
        // to nominal than with equal weights).
        let mut hann = Vec::new();
        for apodization in [Apodization::Boxcar, Apodization::Hann] {
            let dp = DasParams {
                fc: 5e6,
                c: 1540.0,
                fs: 20e6,
                t0: 0.0,
                pitch: a.pitch,
                n_elements: a.n_elements,
                radius: None,
                fnumber: a.fnumber,
                rx_angle: rx,
                interpolation: Interpolation::Linear,
                apodization,
            };
            let q = aperture_projection(&Aperture { apodization, ..a.clone() }, 5e6, 1540.0, 0.0, rx, &grid).unwrap();
            let plan = DasPlan::new(&dp, &TxWave::PlaneWave { tilt: 0.0 }, &grid, 4000).unwrap().projection();
            for (q, r) in q.iter().zip(&plan) {
                assert!((q[0] - r[0]).abs() < 1e-4 && (q[1] - r[1]).abs() < 1e-4, "{apodization:?}: {q:?} vs {plan:?}");
            }
            hann = q;
        }
        assert!(
            hann[0] != p[0] && (f64::from(hann[0][0]) - nom[0]).abs() < (f64::from(p[0][0]) - nom[0]).abs(),
            "{hann:?} vs {p:?}"
        );
        // Amplitude weights (element width 0.265 mm at 5 MHz): the oblique elements of the −15°
        // sub-aperture receive less, so the effective receive angle and |a_x| are smaller.
        let wp =
            aperture_projection(&Aperture { width: Some(0.265e-3), ..a.clone() }, 5e6, 1540.0, 0.0, rx, &grid).unwrap();
        assert!(wp[0][0].abs() < 0.95 * p[0][0].abs() && wp[0][0].abs() > 0.5 * p[0][0].abs(), "{wp:?} vs {p:?}");
        // Full aperture (F# 0) at normal receive: every element counts, so at the array centre
        // the lateral components cancel (a_x = 0 by symmetry) and a_z = −(1 + ⟨cos θe⟩)/2 lies
        // between the nominal −1 and the F# 1.5 value's.
        let full = aperture_projection(&Aperture { fnumber: 0.0, ..a }, 5e6, 1540.0, 0.0, 0.0, &grid).unwrap();
        assert!(full[0][0].abs() < 1e-6, "{full:?}");
        assert!(full[0][1] > -1.0 && full[0][1] < -0.8, "{full:?}");
    }

    #[test]
    fn bad_apertures_name_the_field() {
        let a = Aperture {
            pitch: 0.3e-3,
            n_elements: 128,
            fnumber: 1.5,
            width: None,
            radius: None,
            apodization: Apodization::Boxcar,
        };
        let field = |b: Aperture| match b.validate() {
            Err(sonoflow_beamform::BeamformError::InvalidParameter { field, .. }) => field,
            other => panic!("{other:?}"),
        };
        assert_eq!(field(Aperture { pitch: 0.0, ..a.clone() }), "aperture.pitch");
        assert_eq!(field(Aperture { n_elements: 0, ..a.clone() }), "aperture.n_elements");
        assert_eq!(field(Aperture { fnumber: f64::NAN, ..a.clone() }), "aperture.fnumber");
        assert_eq!(field(Aperture { width: Some(0.4e-3), ..a.clone() }), "aperture.width");
        assert_eq!(field(Aperture { radius: Some(-0.04), ..a.clone() }), "aperture.radius");
        assert_eq!(field(Aperture { radius: Some(0.01), ..a.clone() }), "aperture.n_elements");
        assert_eq!(field(Aperture { radius: Some(0.1e-3), n_elements: 1, ..a }), "aperture.pitch");
    }

    /// On a convex array (C5-2v geometry) the projection uses the beamformer's convex aperture
    /// (angle from each element's normal, turned by the receive angle) and the elements on the
    /// arc: it equals the DAS plan's mean delay gradient, for the plane wave of tilt 0 and 8° and
    /// receive angles 0, ±12° (F# 1.5, boxcar and Hann), to 1e-4 as the linear case (measured
    /// 1.6e-6: float32 gradients).
    /// On the axis under a 0° transmit and receive the lateral component vanishes.
    #[test]
    fn convex_projection_follows_the_convex_das_aperture() {
        let a = Aperture {
            pitch: 0.508e-3,
            n_elements: 128,
            fnumber: 1.5,
            width: None,
            radius: Some(0.04957),
            apodization: Apodization::Boxcar,
        };
        let grid = Grid { x0: -0.02, z0: 0.05, dx: 0.01, dz: 0.02, nx: 5, nz: 2 };
        let mut worst = 0.0f32;
        // amplitude weights (C5-2v's element width) lean on the near-normal elements: |a_x| of
        // a steered look shrinks, as on a linear array
        let steered = |width| {
            let b = Aperture { width, ..a.clone() };
            aperture_projection(&b, 3.57e6, 1540.0, 0.0, 12f64.to_radians(), &grid).unwrap()[2]
        };
        let (plain, weighted) = (steered(None), steered(Some(0.46e-3)));
        assert!(
            weighted[0].abs() < plain[0].abs() && weighted[0].abs() > 0.5 * plain[0].abs(),
            "{weighted:?} {plain:?}"
        );
        for (tilt, rx) in [(0.0f64, 0.0f64), (0.0, 12.0), (8.0, -12.0), (8.0, 0.0)] {
            let (tilt, rx) = (tilt.to_radians(), rx.to_radians());
            for apodization in [Apodization::Boxcar, Apodization::Hann] {
                let dp = DasParams {
                    fc: 3.57e6,
                    c: 1540.0,
                    fs: 4.0 * 3.57e6,
                    t0: 0.0,
                    pitch: a.pitch,
                    n_elements: a.n_elements,
                    radius: a.radius,
                    fnumber: a.fnumber,
                    rx_angle: rx,
                    interpolation: Interpolation::Linear,
                    apodization,
                };
                let q = aperture_projection(&Aperture { apodization, ..a.clone() }, 3.57e6, 1540.0, tilt, rx, &grid)
                    .unwrap();
                let plan = DasPlan::new(&dp, &TxWave::PlaneWave { tilt }, &grid, 8000).unwrap().projection();
                for (q, r) in q.iter().zip(&plan) {
                    worst = worst.max((q[0] - r[0]).abs()).max((q[1] - r[1]).abs());
                    assert!((q[0] - r[0]).abs() < 1e-4 && (q[1] - r[1]).abs() < 1e-4, "{q:?} vs {r:?}");
                }
                if tilt == 0.0 && rx == 0.0 {
                    assert!(q[2][0].abs() < 1e-6, "on the axis: {:?}", q[2]);
                }
            }
        }
        println!("worst |projection − DAS plan| {worst:e}");
    }
}
