//! Point scatterers in structure-of-arrays layout.

use crate::error::{Result, SimusError};

/// Largest accepted |x|, |z| (m).
const MAX_POSITION: f64 = 100.0;
/// Largest accepted |rc| (keeps every f32 intermediate far from overflow).
const MAX_AMPLITUDE: f64 = 1e20;

/// Point scatterers (monopoles): positions (m) and amplitudes (MUST `RC`, the paper's BSC),
/// one entry per scatterer in each vector. Positions are f32, as PyMUST casts them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scatterers {
    /// Lateral position (m).
    pub x: Vec<f32>,
    /// Depth (m), positive into the medium. Scatterers with z < 0 (behind the array) are not
    /// insonified (MUST) but count for the frequency plan.
    pub z: Vec<f32>,
    /// Reflection coefficient / amplitude (dimensionless, any sign).
    pub rc: Vec<f32>,
}

/// Borrowed scatterer arrays, e.g. straight from a particle message.
#[derive(Clone, Copy, Debug)]
pub struct ScattererSlices<'a> {
    /// Lateral position (m).
    pub x: &'a [f32],
    /// Depth (m).
    pub z: &'a [f32],
    /// Amplitude.
    pub rc: &'a [f32],
}

impl Scatterers {
    /// Builds from three vectors of the same length.
    pub fn new(x: Vec<f32>, z: Vec<f32>, rc: Vec<f32>) -> Result<Self> {
        let s = Self { x, z, rc };
        s.as_slices().check_lengths()?;
        Ok(s)
    }

    /// Number of scatterers.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// True when there are none.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// Appends one scatterer.
    pub fn push(&mut self, x: f32, z: f32, rc: f32) {
        self.x.push(x);
        self.z.push(z);
        self.rc.push(rc);
    }

    /// Borrowed view.
    pub fn as_slices(&self) -> ScattererSlices<'_> {
        ScattererSlices { x: &self.x, z: &self.z, rc: &self.rc }
    }

    /// Lengths equal and every value finite; the error names the first bad row.
    pub fn validate(&self) -> Result<()> {
        self.as_slices().validate()
    }
}

impl<'a> From<&'a Scatterers> for ScattererSlices<'a> {
    fn from(s: &'a Scatterers) -> Self {
        s.as_slices()
    }
}

impl<'a> ScattererSlices<'a> {
    /// Number of scatterers.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// True when there are none.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    fn check_lengths(&self) -> Result<()> {
        for (field, got) in [("scatterers.z", self.z.len()), ("scatterers.rc", self.rc.len())] {
            if got != self.x.len() {
                return Err(SimusError::LengthMismatch { field, got, expected: self.x.len() });
            }
        }
        Ok(())
    }

    /// Lengths equal, every value finite, |x|, |z| ≤ 100 m, |rc| ≤ 1e20; the error names the
    /// first bad row.
    pub fn validate(&self) -> Result<()> {
        self.check_lengths()?;
        for (row, ((x, z), rc)) in self.x.iter().zip(self.z).zip(self.rc).enumerate() {
            for (field, v, limit) in [("x", x, MAX_POSITION), ("z", z, MAX_POSITION), ("rc", rc, MAX_AMPLITUDE)] {
                if !(v.is_finite() && f64::from(v.abs()) <= limit) {
                    return Err(SimusError::InvalidScatterer { row, field, value: f64::from(*v), limit });
                }
            }
        }
        Ok(())
    }

    /// Largest element–scatterer distance (m) over all scatterers (z < 0 included, as MUST).
    /// 0 without scatterers.
    pub fn max_element_distance(&self, x_first: f64, x_last: f64) -> f64 {
        // the farthest element of a linear array is one of its two end elements
        let mut d2max = 0.0f64;
        for (x, z) in self.x.iter().zip(self.z) {
            let (x, z) = (f64::from(*x), f64::from(*z));
            let dx = (x - x_first).abs().max((x - x_last).abs());
            d2max = d2max.max(dx * dx + z * z);
        }
        d2max.sqrt()
    }

    /// Largest distance (m) from any scatterer to any element centre of `probe` (MUST's `maxD`
    /// before the pulse length): [`Self::max_element_distance`] for a linear array. On a convex
    /// array the distance from a point to the arc's points grows with their angle from the
    /// point's direction seen from the circle's centre (0, −h), so for a point above the centre
    /// (z > −h: the arc spans less than half the circle) the farthest element is an end one;
    /// below it, every element is tried.
    pub fn max_probe_distance(&self, probe: &crate::Probe) -> f64 {
        let n = probe.n_elements;
        if probe.convex_radius().is_none() {
            return self.max_element_distance(probe.element_x(0), probe.element_x(n - 1));
        }
        let (pos, h) = (probe.element_positions(), probe.apothem());
        let ends = [pos[0], pos[n - 1]];
        let mut d2max = 0.0f64;
        for (x, z) in self.x.iter().zip(self.z) {
            let (x, z) = (f64::from(*x), f64::from(*z));
            let els: &[crate::ElementPosition] = if z > -h { &ends } else { &pos };
            for p in els {
                d2max = d2max.max((x - p.x) * (x - p.x) + (z - p.z) * (z - p.z));
            }
        }
        d2max.sqrt()
    }
}
