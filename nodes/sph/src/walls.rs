//! Moving walls and the fluid domain used by the anti-penetration guard.
//!
//! Wall particles are fixed virtual particles (paper §2.2). A wall particle with `group` = 0 never
//! moves; its `vx`, `vz` are the wall velocity used by the no-slip condition (a wall that slides along
//! itself, e.g. the lid of a cavity or a Couette plate). A wall particle with `group` = k ≥ 1 follows
//! [`WallMotion`] k − 1 rigidly: position r(t) = r(t₀) + d(t) − d(t₀), velocity ḋ(t) (vessel-wall
//! motion, the source of wall clutter in Doppler).

use serde::{Deserialize, Serialize};

use crate::waveform::{Waveform, WaveformSpec};
use crate::Real;

/// Prescribed rigid motion of a group of wall particles.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
pub enum WallMotion {
    /// Translation with velocity `direction` · f(t) (displacement `direction` · ∫f).
    Translate {
        /// Direction (components multiply f) \[1\].
        direction: [Real; 2],
        /// Speed f(t) \[m/s\].
        waveform: WaveformSpec,
    },
}

/// A [`WallMotion`] ready to evaluate.
#[derive(Clone, Debug)]
pub(crate) struct BuiltMotion {
    direction: [Real; 2],
    speed: Waveform,
}

impl BuiltMotion {
    pub(crate) fn new(m: &WallMotion, index: usize) -> Result<Self, String> {
        match m {
            WallMotion::Translate { direction, waveform } => {
                if !direction.iter().all(|v| v.is_finite()) {
                    return Err(format!("wall_motions[{index}].direction = {direction:?}: must be finite"));
                }
                let speed = waveform
                    .build()
                    .map_err(|e| format!("wall_motions[{index}].waveform.{}: {}", e.field, e.reason))?;
                Ok(BuiltMotion { direction: *direction, speed })
            }
        }
    }

    /// Displacement d(t) \[m\].
    pub(crate) fn displacement(&self, t: Real) -> [Real; 2] {
        let s = self.speed.integral(t);
        [self.direction[0] * s, self.direction[1] * s]
    }

    /// Velocity ḋ(t) \[m/s\].
    pub(crate) fn velocity(&self, t: Real) -> [Real; 2] {
        let s = self.speed.value(t);
        [self.direction[0] * s, self.direction[1] * s]
    }
}

/// The region the fluid must stay in, for the anti-penetration guard: a signed distance to the
/// wall, negative inside the fluid region \[m\]. Implemented by the geometry's sampled distance field.
pub trait Domain: Send + Sync + std::fmt::Debug {
    /// Signed distance of (x, z) to the wall (negative inside) \[m\].
    fn signed_distance(&self, x: Real, z: Real) -> Real;
}

/// The rectangle \[`min`\[0\], `max`\[0\]\] × \[`min`\[1\], `max`\[1\]\] (x, z) as the fluid region of the guard:
/// the signed distance max(min − r, r − max) over both axes (exact inside, the largest axis
/// distance outside), negative inside. The wall-domain guard of a closed box
/// ([`crate::setup::CavityConfig`], the hydrostatic tank of the tests).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoxDomain {
    /// Lower corner (x, z) \[m\].
    pub min: [Real; 2],
    /// Upper corner (x, z) \[m\].
    pub max: [Real; 2],
}

impl Domain for BoxDomain {
    fn signed_distance(&self, x: Real, z: Real) -> Real {
        (self.min[0] - x).max(x - self.max[0]).max(self.min[1] - z).max(z - self.max[1])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_domain_is_negative_inside_and_measures_the_nearest_side() {
        let b = BoxDomain { min: [0.0, 1.0], max: [2.0, 4.0] };
        assert_eq!(b.signed_distance(1.0, 2.0), -1.0); // nearest sides: x = 0, x = 2, z = 1
        assert!((b.signed_distance(1.5, 3.9) + 0.1).abs() < 1e-12); // the lid side z = 4
        assert_eq!(b.signed_distance(2.5, 2.0), 0.5);
        assert_eq!(b.signed_distance(1.0, 0.75), 0.25);
        assert_eq!(b.signed_distance(0.0, 2.0), 0.0);
    }
}
