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
