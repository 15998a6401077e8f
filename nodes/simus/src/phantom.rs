//! Speckle phantoms: MUST's `genscat` 2-D scatterer distribution, seeded, with inclusions.
//!
//! MUST's `genscat([width height], meandist, I, g)`: a square grid of step
//! `a = meandist/√(2/5)` over the region `x ∈ (−width/2, width/2)`, `z ∈ (0, height)` (MUST's
//! origin: the middle of the lower edge; [`PhantomParams::z0`] shifts it), each node jittered
//! uniformly by ±a/2 in x and z, the points outside the region dropped; MUST notes that this
//! makes the mean nearest-neighbour distance ≈ `meandist`. The density is `0.4/meandist²`, so
//! [`PhantomParams::scatterers_per_cell`] gives the count per resolution cell. Amplitudes are
//! Rayleigh of mean 1 (`raylrnd(1)/√(π/2)`), times the echogenicity map when an image is given
//! (MUST: bilinear in the image, `10^(g/20·(I/max − 1))` for a dynamic range g > 1 dB,
//! `(I/max)^(1/g)` for a gamma g ≤ 1).
//!
//! sonoflow's additions and differences: a seed (ChaCha8; the same seed gives the same
//! phantom, another seed moves every scatterer), circular inclusions (anechoic — no scatterers —
//! or a level in dB), and the image sampled at pixel centres with the edge pixels extended to
//! the region's border (MUST's interpolation returns 0 in the outer half pixel). MUST's
//! random reordering is not done (it changes nothing SIMUS computes).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::error::{invalid, Result};

/// Most scatterers one phantom may hold (a 10 cm × 10 cm region at λ = 0.1 mm is ~4e5).
pub const MAX_SCATTERERS: usize = 50_000_000;

/// A circular inclusion.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Inclusion {
    /// Centre, lateral (m).
    pub x: f64,
    /// Centre, depth (m).
    pub z: f64,
    /// Radius (m), > 0.
    pub radius: f64,
    /// Echo level relative to the background (dB, amplitude × 10^(dB/20)), in [−100, 100];
    /// absent: anechoic (no scatterers inside).
    #[serde(default)]
    pub level_db: Option<f64>,
}

/// An echogenicity image (MUST's `I`): `nl` rows (depth) × `nc` columns, row-major, ≥ 0.
#[derive(Clone, Debug, PartialEq)]
pub struct Echogenicity {
    pub data: Vec<f64>,
    pub nl: usize,
    pub nc: usize,
    /// MUST's `g`: dynamic range (dB) of the image when > 1, its gamma when in (0, 1]. MUST's
    /// default 40.
    pub g: f64,
}

/// A 2-D speckle phantom.
#[derive(Clone, Debug, PartialEq)]
pub struct PhantomParams {
    /// Width (m): x from −width/2 to width/2.
    pub width: f64,
    /// Height (m): z from `z0` to `z0 + height`.
    pub height: f64,
    /// Depth of the region's top edge (m); MUST: 0.
    pub z0: f64,
    /// MUST's `meandist` (m): approximate mean distance to the nearest neighbour. MUST
    /// recommends at most the shortest wavelength at −6 dB, [`must_meandist`].
    pub meandist: f64,
    /// Seed of the positions and amplitudes.
    pub seed: u64,
    /// Inclusions, applied in order (a later one overrides an earlier one where they overlap).
    pub inclusions: Vec<Inclusion>,
    /// Echogenicity map over the region (MUST's `I`, `g`), if any.
    pub image: Option<Echogenicity>,
}

/// MUST's default `meandist` for a probe: the shortest wavelength at −6 dB,
/// `c/(fc·(1 + bandwidth/200))` (bandwidth in % of fc).
pub fn must_meandist(c: f64, fc: f64, bandwidth_pct: f64) -> f64 {
    c / (fc * (1.0 + bandwidth_pct / 200.0))
}

/// Area (m²) of a 2-D resolution cell of a pulse-echo system: the axial −6 dB extent
/// `c/(2·fc·bandwidth/100)` times the lateral one `λ·F#` (λ = c/fc, F# the receive f-number) —
/// the usual approximations, for a density in scatterers per cell.
pub fn resolution_cell_area(c: f64, fc: f64, bandwidth_pct: f64, fnumber: f64) -> f64 {
    c / (2.0 * fc * bandwidth_pct / 100.0) * (c / fc * fnumber)
}

impl PhantomParams {
    /// Scatterers per unit area (m⁻²): one per jittered grid cell, `0.4/meandist²`.
    pub fn density(&self) -> f64 {
        0.4 / (self.meandist * self.meandist)
    }

    /// Mean scatterer count in a resolution cell of `cell_area` (m², e.g. axial × lateral
    /// −6 dB width of the point-spread function).
    pub fn scatterers_per_cell(&self, cell_area: f64) -> f64 {
        self.density() * cell_area
    }

    /// The `meandist` that puts `n` scatterers on average in a cell of `cell_area` (m²).
    pub fn meandist_for(n: f64, cell_area: f64) -> f64 {
        (0.4 * cell_area / n).sqrt()
    }

    /// Checks every field; errors name the field and its allowed range.
    pub fn validate(&self) -> Result<()> {
        let pos = |v: f64| v.is_finite() && v > 0.0;
        if !pos(self.width) || self.width > 1.0 {
            return Err(invalid("phantom.width", self.width, "in (0, 1] m"));
        }
        if !pos(self.height) || self.height > 1.0 {
            return Err(invalid("phantom.height", self.height, "in (0, 1] m"));
        }
        if !(self.z0.is_finite() && (-1.0..=1.0).contains(&self.z0)) {
            return Err(invalid("phantom.z0", self.z0, "finite, in [-1, 1] m"));
        }
        if !pos(self.meandist) {
            return Err(invalid("phantom.meandist", self.meandist, "finite and > 0 m"));
        }
        let count = self.density() * self.width * self.height;
        if count > MAX_SCATTERERS as f64 {
            return Err(invalid(
                "phantom.meandist",
                format!("{} (≈ {count:.3e} scatterers)", self.meandist),
                "large enough for at most 5e7 scatterers in the region",
            ));
        }
        for inc in &self.inclusions {
            if !(inc.x.is_finite() && inc.z.is_finite()) {
                return Err(invalid("phantom.inclusions.x/z", format!("({}, {})", inc.x, inc.z), "finite (m)"));
            }
            if !pos(inc.radius) {
                return Err(invalid("phantom.inclusions.radius", inc.radius, "finite and > 0 m"));
            }
            if let Some(db) = inc.level_db {
                if !(db.is_finite() && (-100.0..=100.0).contains(&db)) {
                    return Err(invalid("phantom.inclusions.level_db", db, "in [-100, 100] dB (absent: anechoic)"));
                }
            }
        }
        if let Some(im) = &self.image {
            if im.nl == 0 || im.nc == 0 || im.data.len() != im.nl * im.nc {
                return Err(invalid(
                    "phantom.I",
                    format!("{} values for {} × {}", im.data.len(), im.nl, im.nc),
                    "a non-empty 2-D image",
                ));
            }
            if let Some(v) = im.data.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
                return Err(invalid("phantom.I", v, "finite and ≥ 0 everywhere"));
            }
            if !im.data.iter().any(|v| *v > 0.0) {
                return Err(invalid("phantom.I", 0.0, "not zero everywhere"));
            }
            if !pos(im.g) {
                return Err(invalid("phantom.g", im.g, "finite and > 0 (dB when > 1, a gamma when ≤ 1)"));
            }
        }
        Ok(())
    }
}

/// A generated phantom: positions (m) and amplitudes, one entry per scatterer.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Phantom {
    pub x: Vec<f64>,
    pub z: Vec<f64>,
    pub rc: Vec<f64>,
}

/// Generates the phantom of `p` (see the module documentation).
pub fn genscat(p: &PhantomParams) -> Result<Phantom> {
    p.validate()?;
    let a = p.meandist / (2.0f64 / 5.0).sqrt();
    let (xmin, xmax, zmin, zmax) = (-p.width / 2.0, p.width / 2.0, p.z0, p.z0 + p.height);
    // MUST: meshgrid(xmin:a:xmax, zmin:a:zmax), i.e. nodes xmin + i·a ≤ xmax
    let nodes = |span: f64| (span / a).floor() as usize + 1;
    let (nx, nz) = (nodes(p.width), nodes(p.height));
    let mut rng = ChaCha8Rng::seed_from_u64(p.seed);
    let norm = (std::f64::consts::PI / 2.0).sqrt();
    let image = p.image.as_ref().map(|im| {
        let max = im.data.iter().copied().fold(0.0, f64::max);
        (im, max)
    });
    let mut out = Phantom::default();
    for iz in 0..nz {
        for ix in 0..nx {
            let x = xmin + ix as f64 * a + (rng.gen::<f64>() - 0.5) * a;
            let z = zmin + iz as f64 * a + (rng.gen::<f64>() - 0.5) * a;
            // Rayleigh (σ = 1) by inversion: √(−2 ln(1 − U)), U ∈ [0, 1)
            let rc = (-2.0 * (1.0 - rng.gen::<f64>()).ln()).sqrt() / norm;
            if !(x > xmin && x < xmax && z > zmin && z < zmax) {
                continue;
            }
            let base = match image {
                Some((im, max)) => echogenicity(im, max, (x - xmin) / p.width, (z - zmin) / p.height),
                None => 1.0,
            };
            // the last inclusion that holds the point decides
            let (keep, level) = match p.inclusions.iter().rev().find(|c| (x - c.x).hypot(z - c.z) <= c.radius) {
                Some(Inclusion { level_db: None, .. }) => (false, 0.0),
                Some(Inclusion { level_db: Some(db), .. }) => (true, base * 10f64.powf(db / 20.0)),
                None => (true, base),
            };
            if keep {
                out.x.push(x);
                out.z.push(z);
                out.rc.push(rc * level);
            }
        }
    }
    Ok(out)
}

/// MUST's amplitude factor from the image at fractional position (u, v) ∈ (0, 1)² of the region
/// (u lateral, v depth): bilinear between pixel centres, edges extended; log or gamma
/// expansion.
fn echogenicity(im: &Echogenicity, max: f64, u: f64, v: f64) -> f64 {
    let coord = |t: f64, n: usize| -> (usize, usize, f64) {
        let s = (t * n as f64 - 0.5).clamp(0.0, (n - 1) as f64);
        let i0 = (s.floor() as usize).min(n - 1);
        let i1 = (i0 + 1).min(n - 1);
        (i0, i1, s - i0 as f64)
    };
    let (c0, c1, fc) = coord(u, im.nc);
    let (l0, l1, fl) = coord(v, im.nl);
    let at = |l: usize, c: usize| im.data[l * im.nc + c] / max;
    let top = at(l0, c0) * (1.0 - fc) + at(l0, c1) * fc;
    let bottom = at(l1, c0) * (1.0 - fc) + at(l1, c1) * fc;
    let i = top * (1.0 - fl) + bottom * fl;
    if im.g > 1.0 {
        10f64.powf(im.g / 20.0 * (i - 1.0))
    } else {
        i.powf(1.0 / im.g)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn base(seed: u64) -> PhantomParams {
        PhantomParams { width: 0.02, height: 0.015, z0: 0.005, meandist: 2e-4, seed, inclusions: vec![], image: None }
    }

    #[test]
    fn density_amplitudes_and_nearest_neighbour_follow_must() {
        let p = base(1);
        let ph = genscat(&p).unwrap();
        // count: one per interior grid cell, the border cells partly; within 1 % of density × area
        let expected = p.density() * p.width * p.height;
        let n = ph.x.len() as f64;
        assert!((n / expected - 1.0).abs() < 0.01, "{n} scatterers, expected {expected:.0}");
        assert!(ph.x.iter().all(|x| x.abs() < 0.01) && ph.z.iter().all(|z| *z > 0.005 && *z < 0.02));
        // Rayleigh of mean 1: mean 1 and mean square 4/π (σ_mean = 0.52/√n ≈ 0.003)
        let mean = ph.rc.iter().sum::<f64>() / n;
        let ms = ph.rc.iter().map(|r| r * r).sum::<f64>() / n;
        assert!((mean - 1.0).abs() < 0.015, "mean RC {mean}");
        assert!((ms - 4.0 / std::f64::consts::PI).abs() < 0.03, "mean square RC {ms}");
        // MUST's claim: mean nearest-neighbour distance ≈ meandist (within 10 %), on a sample
        let (xs, zs) = (&ph.x, &ph.z);
        let mut sum = 0.0;
        let probes: Vec<usize> = (0..ph.x.len()).step_by(37).collect();
        for &i in &probes {
            let d = (0..xs.len())
                .filter(|&j| j != i)
                .map(|j| (xs[i] - xs[j]).hypot(zs[i] - zs[j]))
                .fold(f64::INFINITY, f64::min);
            sum += d;
        }
        let nn = sum / probes.len() as f64;
        assert!((nn / p.meandist - 1.0).abs() < 0.1, "mean nearest-neighbour distance {nn:.3e}");
    }

    #[test]
    fn seeds_move_the_scatterers_and_repeat_exactly() {
        let (a, b, a2) = (genscat(&base(1)).unwrap(), genscat(&base(2)).unwrap(), genscat(&base(1)).unwrap());
        assert_eq!(a, a2);
        let n = a.x.len().min(b.x.len());
        let moved = (0..n).filter(|&i| a.x[i] != b.x[i] && a.z[i] != b.z[i]).count();
        assert!(moved > n * 99 / 100, "only {moved} of {n} positions changed with the seed");
    }

    #[test]
    fn inclusions_are_empty_or_scaled() {
        let mut p = base(3);
        p.inclusions = vec![
            Inclusion { x: -0.004, z: 0.012, radius: 0.002, level_db: None },
            Inclusion { x: 0.004, z: 0.012, radius: 0.002, level_db: Some(12.0) },
        ];
        let ph = genscat(&p).unwrap();
        let inside = |c: f64, i: usize| (ph.x[i] - c).hypot(ph.z[i] - 0.012) <= 0.002;
        assert_eq!((0..ph.x.len()).filter(|&i| inside(-0.004, i)).count(), 0, "the cyst holds scatterers");
        let ms = |f: &dyn Fn(usize) -> bool| {
            let v: Vec<f64> = (0..ph.x.len()).filter(|&i| f(i)).map(|i| ph.rc[i] * ph.rc[i]).collect();
            (v.iter().sum::<f64>() / v.len() as f64, v.len())
        };
        let (bright, nb) = ms(&|i| inside(0.004, i));
        let (bg, _) = ms(&|i| !inside(0.004, i) && !inside(-0.004, i));
        // 12 dB in power with ~300 Rayleigh samples inside (power's relative sd 1/√300 ≈ 6 %)
        let db = 10.0 * (bright / bg).log10();
        assert!((db - 12.0).abs() < 1.0, "inclusion {db:.2} dB above the background ({nb} scatterers)");
        // density is unchanged inside a scaled inclusion: π r² × density ± 4 sd
        let expected = std::f64::consts::PI * 4e-6 * p.density();
        assert!(
            (nb as f64 - expected).abs() < 4.0 * expected.sqrt(),
            "{nb} in the bright disk, expected {expected:.0}"
        );
    }

    #[test]
    fn an_image_sets_the_echogenicity_as_must() {
        // two columns: left at max, right at a quarter of it; g = 40 dB → right 10^(2·(0.25 − 1)) = 0.0316
        let mut p = base(4);
        p.image = Some(Echogenicity { data: vec![4.0, 1.0, 4.0, 1.0], nl: 2, nc: 2, g: 40.0 });
        let ph = genscat(&p).unwrap();
        let band = |lo: f64, hi: f64| {
            let v: Vec<f64> = (0..ph.x.len()).filter(|&i| ph.x[i] > lo && ph.x[i] < hi).map(|i| ph.rc[i]).collect();
            v.iter().sum::<f64>() / v.len() as f64
        };
        // the outer quarters are flat (edge pixels extended); Rayleigh mean 1 ± ~2 %
        let (left, right) = (band(-0.01, -0.005), band(0.005, 0.01));
        assert!((left - 1.0).abs() < 0.04, "left {left}");
        let expect = 10f64.powf(2.0 * (0.25 - 1.0));
        assert!((right / expect - 1.0).abs() < 0.04, "right {right}, expected {expect}");
        // gamma 0.5: (0.25)^(1/0.5) = 0.0625
        p.image = Some(Echogenicity { data: vec![4.0, 1.0, 4.0, 1.0], nl: 2, nc: 2, g: 0.5 });
        let ph = genscat(&p).unwrap();
        let v: Vec<f64> = (0..ph.x.len()).filter(|&i| ph.x[i] > 0.005).map(|i| ph.rc[i]).collect();
        let right = v.iter().sum::<f64>() / v.len() as f64;
        assert!((right / 0.0625 - 1.0).abs() < 0.04, "gamma: right {right}");
    }

    #[test]
    fn bad_parameters_name_the_field() {
        type Edit = Box<dyn Fn(&mut PhantomParams)>;
        let cases: Vec<(Edit, &str)> = vec![
            (Box::new(|p| p.width = 0.0), "phantom.width"),
            (Box::new(|p| p.height = f64::NAN), "phantom.height"),
            (Box::new(|p| p.meandist = -1.0), "phantom.meandist"),
            (Box::new(|p| p.meandist = 1e-8), "phantom.meandist"),
            (Box::new(|p| p.z0 = f64::INFINITY), "phantom.z0"),
            (
                Box::new(|p| p.inclusions.push(Inclusion { x: 0.0, z: 0.01, radius: 0.0, level_db: None })),
                "phantom.inclusions.radius",
            ),
            (
                Box::new(|p| p.inclusions.push(Inclusion { x: 0.0, z: 0.01, radius: 1e-3, level_db: Some(f64::NAN) })),
                "phantom.inclusions.level_db",
            ),
            (Box::new(|p| p.image = Some(Echogenicity { data: vec![1.0; 3], nl: 2, nc: 2, g: 40.0 })), "phantom.I"),
            (Box::new(|p| p.image = Some(Echogenicity { data: vec![-1.0; 4], nl: 2, nc: 2, g: 40.0 })), "phantom.I"),
            (Box::new(|p| p.image = Some(Echogenicity { data: vec![0.0; 4], nl: 2, nc: 2, g: 40.0 })), "phantom.I"),
            (Box::new(|p| p.image = Some(Echogenicity { data: vec![1.0; 4], nl: 2, nc: 2, g: 0.0 })), "phantom.g"),
        ];
        for (f, field) in cases {
            let mut p = base(1);
            f(&mut p);
            let e = genscat(&p).unwrap_err().to_string();
            assert!(e.contains(field), "{e} should name {field}");
        }
    }
}
