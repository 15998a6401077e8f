//! Echoes of scatterers that do not move (stationary tissue), computed once per (frequency
//! plan, transmit) and added to every frame: SIMUS is linear in the scatterers, so the RF of a
//! scene is the sum of the RF of its parts (to f32 rounding: the sums run in another order).
//! A packet's frames share one plan, so static tissue costs one simulation per transmit and plan
//! instead of one per frame.

use crate::{FrequencyPlan, Result, ScattererSlices, Simus, Transmit};

/// The static scatterers and their cached RF (see the module doc).
#[derive(Clone, Debug, Default)]
pub struct StaticEchoes {
    x: Vec<f32>,
    z: Vec<f32>,
    rc: Vec<f32>,
    /// (plan, transmit index, element-major RF).
    cache: Vec<(FrequencyPlan, usize, Vec<f32>)>,
    simulated: usize,
}

impl StaticEchoes {
    /// Sets the static scatterers; the cache is kept only if they are exactly the previous ones.
    pub fn set(&mut self, x: &[f32], z: &[f32], rc: &[f32]) {
        if self.x != x || self.z != z || self.rc != rc {
            (self.x, self.z, self.rc) = (x.to_vec(), z.to_vec(), rc.to_vec());
            self.cache.clear();
        }
    }

    /// True without static scatterers.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// How many times the static RF was simulated (cache misses).
    pub fn simulated(&self) -> usize {
        self.simulated
    }

    /// Adds the static scatterers' RF for transmit `tx` (index `tx_id`) on `plan` to `out`
    /// (element-major, as [`Simus::simulate_into`] writes it), simulating it on a cache miss.
    /// Keeps the most recent 8 (plan, transmit) entries.
    pub fn add_into(
        &mut self,
        simus: &mut Simus,
        tx: &Transmit,
        tx_id: usize,
        plan: &FrequencyPlan,
        out: &mut [f32],
    ) -> Result<()> {
        if self.is_empty() {
            return Ok(());
        }
        let i = match self.cache.iter().position(|(p, t, _)| *t == tx_id && p == plan) {
            Some(i) => i,
            None => {
                let mut rf = vec![0f32; out.len()];
                simus.simulate_into(ScattererSlices { x: &self.x, z: &self.z, rc: &self.rc }, tx, plan, &mut rf)?;
                self.simulated += 1;
                if self.cache.len() == 8 {
                    self.cache.remove(0);
                }
                self.cache.push((plan.clone(), tx_id, rf));
                self.cache.len() - 1
            }
        };
        for (o, s) in out.iter_mut().zip(&self.cache[i].2) {
            *o += s;
        }
        Ok(())
    }
}
