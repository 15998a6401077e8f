//! Stationary tissue around the lumen: scatterers outside the fluid in a rectangular region,
//! with a brighter vessel-wall layer, seeded.
//!
//! **Echo level.** In fully developed speckle the beamformed power of a region is proportional
//! to scatterer density × mean squared amplitude (the same point-spread function for both), so
//! tissue of density ρ_t whose echoes are `tissue_to_blood_db` above blood of density ρ_b and
//! amplitude σ_b gets the amplitude σ_t = σ_b · √(10^(dB/10) · ρ_b / ρ_t). The wall layer
//! (`wall.thickness` outside the lumen boundary, across the vessel axis; around a disk) has
//! the tissue's density and `wall.level_db` more power. Both levels are therefore defined on
//! the beamformed data; `tests/echo_levels.rs` measures them there (SIMUS → DAS).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use crate::flow::Geometry;
use crate::motion::{Pulsation, Rigid};
use crate::{require, ParamError, Particles};

/// The vessel wall: a brighter layer of tissue just outside the lumen.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct WallLayer {
    /// Thickness outside the lumen boundary (m), in (0, 5e-3]. Default 0.6 mm (carotid
    /// intima-media thickness).
    pub thickness: f64,
    /// Echo power above the surrounding tissue (dB), in [0, 40]. Default 10.
    pub level_db: f64,
}

impl Default for WallLayer {
    fn default() -> Self {
        Self { thickness: 0.6e-3, level_db: 10.0 }
    }
}

/// Tissue parameters (`tissue = { … }` of an analytic flow; absent: no tissue).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct TissueParams {
    /// Region `[x_min, x_max, z_min, z_max]` (m) filled with tissue outside the lumen.
    pub region: [f64; 4],
    /// Scatterers per mm², in (0, 1e4]. Default 10 (as the blood's default).
    pub density_per_mm2: f64,
    /// Tissue echo power above the blood's on beamformed data (dB), in [−20, 80]. Default 40
    /// (in vivo tissue is 40–60 dB above blood).
    pub tissue_to_blood_db: f64,
    /// The vessel wall layer (absent: none).
    pub wall: Option<WallLayer>,
    /// Seed of the tissue scatterers (default 2; independent of the blood's).
    pub seed: u64,
    /// Wall pulsation (absent: the tissue is static unless the scene has `bulk` motion), see
    /// [`crate::motion`].
    pub pulsation: Option<Pulsation>,
}

impl Default for TissueParams {
    fn default() -> Self {
        Self {
            region: [-10e-3, 10e-3, 10e-3, 30e-3],
            density_per_mm2: 10.0,
            tissue_to_blood_db: 40.0,
            wall: Some(WallLayer::default()),
            seed: 2,
            pulsation: None,
        }
    }
}

impl TissueParams {
    /// Checks every field; the error names it (`tissue.…`).
    pub fn validate(&self) -> Result<(), ParamError> {
        let [x0, x1, z0, z1] = self.region;
        require(
            "tissue.region",
            format!("{:?}", self.region),
            self.region.iter().all(|v| v.is_finite()) && x1 > x0 && z1 > z0 && (x1 - x0) * (z1 - z0) <= 1e-2,
            "[x_min, x_max, z_min, z_max] in m, finite, min < max, at most 100 cm²".to_string(),
        )?;
        require(
            "tissue.density_per_mm2",
            self.density_per_mm2,
            self.density_per_mm2.is_finite() && self.density_per_mm2 > 0.0 && self.density_per_mm2 <= 1e4,
            "finite, 0 < value <= 10000 per mm^2".to_string(),
        )?;
        require(
            "tissue.tissue_to_blood_db",
            self.tissue_to_blood_db,
            self.tissue_to_blood_db.is_finite() && (-20.0..=80.0).contains(&self.tissue_to_blood_db),
            "-20 ..= 80 dB".to_string(),
        )?;
        if let Some(w) = &self.wall {
            require(
                "tissue.wall.thickness",
                w.thickness,
                w.thickness.is_finite() && w.thickness > 0.0 && w.thickness <= 5e-3,
                "0 < value <= 0.005 m".to_string(),
            )?;
            require(
                "tissue.wall.level_db",
                w.level_db,
                w.level_db.is_finite() && (0.0..=40.0).contains(&w.level_db),
                "0 ..= 40 dB".to_string(),
            )?;
        }
        if let Some(p) = &self.pulsation {
            p.validate()?;
        }
        Ok(())
    }

    /// Expected scatterer count of the region (before the lumen is cut out).
    pub fn region_count(&self) -> f64 {
        let [x0, x1, z0, z1] = self.region;
        self.density_per_mm2 * (x1 - x0) * (z1 - z0) * 1e6
    }

    /// Amplitude standard deviation of the tissue for blood of density `blood_density` (per
    /// mm²) and amplitude σ `blood_sigma` (see the module doc).
    pub fn sigma(&self, blood_density: f64, blood_sigma: f64) -> f64 {
        blood_sigma * (10f64.powf(self.tissue_to_blood_db / 10.0) * blood_density / self.density_per_mm2).sqrt()
    }
}

/// The lumen as tissue seeding and the wall pulsation need it. Implemented by the analytic
/// flows' geometry and by the SPH vessels' signed distance (sonoflow-sph).
pub trait LumenShape {
    /// Distance (m) from a point outside the lumen to its wall (≤ 0 inside; +∞ where the wall
    /// is not defined, e.g. beyond a straight vessel's ends: no wall layer, no pulsation there).
    fn outside_distance(&self, x: f64, z: f64) -> f64;
    /// Unit normal pointing away from the lumen at a point outside it ((0, 0) where undefined).
    fn outward_normal(&self, x: f64, z: f64) -> (f64, f64);
}

impl LumenShape for Geometry {
    fn outside_distance(&self, x: f64, z: f64) -> f64 {
        Geometry::outside_distance(self, x, z)
    }
    fn outward_normal(&self, x: f64, z: f64) -> (f64, f64) {
        Geometry::outward_normal(self, x, z)
    }
}

/// Tissue scatterers around a lumen and their motion.
#[derive(Clone, Debug, Default)]
pub struct Tissue {
    pulsation: Option<Pulsation>,
    particles: Particles,
    /// `[x₀, z₀, n_x·r, n_z·r]` per scatterer: rest position, outward normal × reach
    /// ([`Pulsation::reach`]) so that it sits at (x₀, z₀) + w(t)·(n_x·r, n_z·r).
    rest: Vec<[f64; 4]>,
}

impl Tissue {
    /// Seeds the tissue: uniform in the region, outside the lumen, amplitudes N(0, σ²) with σ
    /// from [`TissueParams::sigma`] for blood of `blood_density` (per mm²) and amplitude σ
    /// `blood_sigma` (× 10^(level/20) in the wall layer). Ids start at `first_id`; positions
    /// are the rest positions, velocities 0 until [`update`](Self::update).
    pub fn new(
        t: &TissueParams,
        lumen: &impl LumenShape,
        blood_density: f64,
        blood_sigma: f64,
        first_id: u32,
    ) -> Result<Self, ParamError> {
        t.validate()?;
        let sigma = t.sigma(blood_density, blood_sigma);
        let wall_gain = t.wall.as_ref().map_or(1.0, |w| 10f64.powf(w.level_db / 20.0));
        let bad = |e: rand_distr::NormalError| ParamError::OutOfRange {
            field: "tissue.tissue_to_blood_db",
            value: t.tissue_to_blood_db.to_string(),
            allowed: e.to_string(),
        };
        let normal = Normal::new(0.0, sigma).map_err(bad)?;
        let mut rng = ChaCha8Rng::seed_from_u64(t.seed);
        let n = t.region_count().round() as usize;
        let [x0, x1, z0, z1] = t.region;
        let mut p = Particles::default();
        let mut rest = Vec::new();
        for _ in 0..n {
            let x = x0 + (x1 - x0) * rng.gen::<f64>();
            let z = z0 + (z1 - z0) * rng.gen::<f64>();
            let a = normal.sample(&mut rng);
            let d = lumen.outside_distance(x, z);
            if d.is_nan() || d <= 0.0 {
                continue; // the lumen: blood only
            }
            let in_wall = t.wall.as_ref().is_some_and(|w| d <= w.thickness);
            p.id.push(first_id + p.id.len() as u32);
            p.x.push(x as f32);
            p.z.push(z as f32);
            p.vx.push(0.0);
            p.vz.push(0.0);
            p.amplitude.push((if in_wall { a * wall_gain } else { a }) as f32);
            let (x, z) = (f64::from(x as f32), f64::from(z as f32));
            let reach = t.pulsation.as_ref().map_or(0.0, |pu| pu.reach(lumen.outside_distance(x, z)));
            let (nx, nz) = lumen.outward_normal(x, z);
            rest.push([x, z, nx * reach, nz * reach]);
        }
        Ok(Self { pulsation: t.pulsation.clone(), particles: p, rest })
    }

    /// The scatterers at the last [`update`](Self::update) (rest positions before).
    pub fn particles(&self) -> &Particles {
        &self.particles
    }

    /// True when the wall pulsates (non-zero amplitude).
    pub fn pulsates(&self) -> bool {
        self.pulsation.as_ref().is_some_and(|p| p.amplitude > 0.0) && !self.particles.is_empty()
    }

    /// Moves the tissue to time `t`: rest position + w(t)·reach·n (pulsation), then the bulk
    /// motion `rigid`; velocities are the exact derivatives. Nothing to do for static tissue.
    pub fn update(&mut self, t: f64, rigid: Option<&Rigid>) {
        let wd = self.pulsation.as_ref().map_or((0.0, 0.0), |p| p.waveform(t));
        self.place(wd, rigid);
    }

    /// The pulsation's waveform kind (None: no pulsation).
    pub fn waveform_kind(&self) -> Option<crate::motion::PulsationWaveform> {
        self.pulsation.as_ref().map(|p| p.waveform)
    }

    /// Moves the tissue to the waveform value `w` with rate `dw` (1/s): rest position + w·reach·n,
    /// then the bulk motion `rigid` (how a producer with its own waveform, e.g. the SPH inflow,
    /// drives the wall).
    pub fn place(&mut self, (w, dw): (f64, f64), rigid: Option<&Rigid>) {
        if !self.pulsates() && rigid.is_none() {
            return;
        }
        let p = &mut self.particles;
        for (i, &[x0, z0, px, pz]) in self.rest.iter().enumerate() {
            let (x, z, vx, vz) = (x0 + w * px, z0 + w * pz, dw * px, dw * pz);
            let [x, z, vx, vz] = match rigid {
                Some(r) => r.apply(x, z, vx, vz),
                None => [x, z, vx, vz],
            };
            p.x[i] = x as f32;
            p.z[i] = z as f32;
            p.vx[i] = vx as f32;
            p.vz[i] = vz as f32;
        }
    }
}
