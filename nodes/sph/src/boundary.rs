//! Open boundaries: the paper's "virtual inflow and outflow reservoirs" (§2.2, after Shahriari et
//! al. 2012a), written as bidirectional buffer zones.
//!
//! A reservoir is a rectangle outside an opening of the vessel: the opening is the segment of the
//! line through `origin` with unit normal `normal` (pointing **out of** the fluid, into the
//! reservoir), |y| ≤ `half_width` with y the lateral coordinate along t = (−n_z, n_x); the reservoir
//! covers 0 < s ≤ `depth`, s = (r − origin)·n. Buffer particles in it move with the prescribed
//! fully developed velocity (Womersley profile of the cross-section mean velocity `inflow(t)`,
//! positive **into** the domain, i.e. along −n). Their density (hence pressure) is extrapolated from
//! the fluid next to the opening with a zero normal gradient (the mean density of the fluid within
//! one kernel support of the opening, lane by lane over ±1.5 lane spacings), re-evaluated before every
//! right-hand-side evaluation, so the fluid next to the opening sees a full kernel support with the
//! imposed velocity and a Neumann pressure. (Integrating the reservoir density with the continuity
//! equation instead compresses the particles at the far side, whose support is cut off, and the
//! excess density flows into the domain: +5 % in one flow-through time of a test channel.) Every
//! step:
//! * a buffer particle that crosses the opening (s ≤ 0) becomes a fluid particle (mass flows in);
//! * a fluid particle that enters the reservoir becomes a buffer particle (mass flows out) — this is
//!   also how backflow through an inlet and regular outflow through an outlet are handled;
//! * a buffer particle beyond the far side (s > depth) is removed;
//! * in every lane (lateral positions y_j = −a + j dy, j = 1 … n − 1, dy = 2a/n, n = round(2a/dx):
//!   the walls, with their type I particles at y = ±a, take the places j = 0 and n, as in a lattice
//!   whose first fluid row lies one spacing from the wall) a new particle is created at the far side
//!   when the imposed velocity of the lane points into the domain and the outermost particle of the
//!   lane has moved more than one streamwise spacing ds = dx²/dy inwards, so every particle stands for dx² of fluid, as the lattice particles do,
//!   and the inflow mass flux is ρ₀ Σ_j u(y_j) dy (the trapezoidal rule of ρ₀Q). Ids are never reused.

use serde::{Deserialize, Serialize};

use crate::particles::{ParticleKind, Particles};
use crate::waveform::Waveform;
use crate::womersley::ProfileTable;
use crate::Real;

/// Shape of the velocity imposed across an opening.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum ProfileKind {
    /// Fully developed pulsatile profile (2D Womersley solution of the mean-velocity waveform). Default.
    #[default]
    Womersley,
    /// Parabola scaled by the mean velocity at every instant (quasi-steady, α → 0).
    Parabolic,
    /// Uniform velocity equal to the mean.
    Uniform,
}

/// One open boundary (reservoir).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OpenBoundary {
    /// Name (e.g. "inlet", "ica", "eca"), used in diagnostics.
    pub name: String,
    /// Centre of the opening \[m\] (x, z).
    pub origin: [Real; 2],
    /// Unit normal pointing out of the fluid, into the reservoir.
    pub normal: [Real; 2],
    /// Half-width a of the opening \[m\] (vessel radius).
    pub half_width: Real,
    /// Depth of the reservoir along the normal \[m\]; at least one kernel support.
    pub depth: Real,
    /// Lattice spacing dx \[m\] of the particles created in the reservoir.
    pub dx: Real,
    /// Cross-section mean velocity into the domain (along −normal) \[m/s\]; negative = outflow.
    pub inflow: Waveform,
    /// Profile across the opening.
    pub profile: ProfileKind,
    /// The imposed velocity is multiplied by a smooth ramp from 0 at t = 0 to 1 at t = `ramp_time`
    /// \[s\] (0 = no ramp).
    pub ramp_time: Real,
}

/// Mass bookkeeping of one open boundary \[kg/m\] (2D: per unit depth).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BoundaryFlux {
    /// Mass of buffer particles that became fluid (crossed the opening inwards).
    pub mass_in: Real,
    /// Mass of fluid particles that became buffer particles (crossed the opening outwards).
    pub mass_out: Real,
    /// Particles created at the far side.
    pub created: u64,
    /// Particles removed beyond the far side.
    pub removed: u64,
}

impl BoundaryFlux {
    /// Net mass into the domain, `mass_in − mass_out`.
    pub fn net_in(&self) -> Real {
        self.mass_in - self.mass_out
    }
}

/// Smooth ramp 0 → 1 over [0, τ] (C¹ cubic smoothstep); 1 when τ = 0.
pub fn ramp(t: Real, tau: Real) -> Real {
    if tau <= 0.0 || t >= tau {
        1.0
    } else if t <= 0.0 {
        0.0
    } else {
        let q = t / tau;
        q * q * (3.0 - 2.0 * q)
    }
}

impl OpenBoundary {
    /// Lateral unit vector t = (−n_z, n_x).
    pub fn tangent(&self) -> [Real; 2] {
        [-self.normal[1], self.normal[0]]
    }

    /// (s, y): distance out of the fluid along the normal and lateral coordinate of (x, z).
    #[inline]
    pub fn local(&self, x: Real, z: Real) -> (Real, Real) {
        let (dx, dz) = (x - self.origin[0], z - self.origin[1]);
        let (n, t) = (self.normal, self.tangent());
        (dx * n[0] + dz * n[1], dx * t[0] + dz * t[1])
    }

    /// Quick test: false when (x, z) is certainly farther than `margin` from the opening and the
    /// reservoir (outside a square of half-side a + depth + margin around the opening's centre).
    #[inline]
    pub fn near(&self, x: Real, z: Real, margin: Real) -> bool {
        let r = self.half_width + self.depth + margin;
        (x - self.origin[0]).abs() <= r && (z - self.origin[1]).abs() <= r
    }

    /// Global position of local (s, y).
    pub fn global(&self, s: Real, y: Real) -> [Real; 2] {
        let (n, t) = (self.normal, self.tangent());
        [self.origin[0] + s * n[0] + y * t[0], self.origin[1] + s * n[1] + y * t[1]]
    }

    /// Number of intervals across the opening n = max(2, round(2a/dx)); there are n − 1 lanes.
    fn n_intervals(&self) -> usize {
        ((2.0 * self.half_width / self.dx).round() as usize).max(2)
    }

    /// Number of lanes, n − 1.
    pub fn n_lanes(&self) -> usize {
        self.n_intervals() - 1
    }

    /// Lateral spacing of the lanes dy = 2a/n.
    pub fn lane_spacing(&self) -> Real {
        2.0 * self.half_width / self.n_intervals() as Real
    }

    /// Lane whose band (|y − y_j| ≤ dy/2, the end lanes extended to the walls) holds y.
    pub fn lane_of(&self, y: Real) -> usize {
        let j = ((y + self.half_width) / self.lane_spacing()).round() as i64 - 1;
        j.clamp(0, self.n_lanes() as i64 - 1) as usize
    }

    /// Streamwise spacing ds = dx²/dy (area per particle dx²).
    pub fn stream_spacing(&self) -> Real {
        self.dx * self.dx / self.lane_spacing()
    }

    /// Lateral coordinate of lane j (0-based), y = −a + (j + 1) dy.
    pub fn lane_y(&self, j: usize) -> Real {
        -self.half_width + (j as Real + 1.0) * self.lane_spacing()
    }

    /// Checks the fields; `Err` names the field and the allowed range.
    pub fn validate(&self, support: Real) -> Result<(), String> {
        let n2 = self.normal[0] * self.normal[0] + self.normal[1] * self.normal[1];
        let bad = |f: &str, why: String| Err(format!("open boundary `{}`: `{f}` {why}", self.name));
        if !(self.origin.iter().all(|v| v.is_finite())) {
            return bad("origin", "must be finite".into());
        }
        if !(n2.is_finite() && (n2 - 1.0).abs() < 1e-9) {
            return bad("normal", format!("= {:?}: must be a unit vector", self.normal));
        }
        if !(self.dx.is_finite() && self.dx > 0.0) {
            return bad("dx", format!("= {}: allowed dx > 0 [m]", self.dx));
        }
        if !(self.half_width.is_finite() && self.half_width >= self.dx) {
            return bad("half_width", format!("= {}: allowed half_width >= dx = {} [m]", self.half_width, self.dx));
        }
        if !(self.depth.is_finite() && self.depth >= support) {
            return bad("depth", format!("= {}: allowed depth >= kernel support {support} [m]", self.depth));
        }
        if !(self.ramp_time.is_finite() && self.ramp_time >= 0.0) {
            return bad("ramp_time", format!("= {}: allowed ramp_time >= 0 [s]", self.ramp_time));
        }
        if !(self.inflow.period > 0.0 && self.inflow.period.is_finite()) {
            return bad("inflow.period", format!("= {}: allowed period > 0 [s]", self.inflow.period));
        }
        Ok(())
    }

    /// The imposed-profile table of this boundary for viscosity ν (257 lateral points).
    pub fn profile_table(&self, nu: Real) -> ProfileTable {
        match self.profile {
            ProfileKind::Womersley => ProfileTable::new(&self.inflow, self.half_width, nu, 257, false),
            ProfileKind::Parabolic => ProfileTable::new(&self.inflow, self.half_width, nu, 257, true),
            ProfileKind::Uniform => ProfileTable::new(&self.inflow, self.half_width, nu, 3, true),
        }
    }

    /// Imposed velocity (global components) at lateral position y at the time the table was last
    /// set to, with the ramp factor `ramp`.
    #[inline]
    pub fn velocity(&self, table: &ProfileTable, y: Real, ramp: Real) -> [Real; 2] {
        let u = match self.profile {
            ProfileKind::Uniform => table.at(0.0) / 1.5, // the quasi-steady table holds 3/2 ū at y = 0
            _ => table.at(y),
        } * ramp;
        [-u * self.normal[0], -u * self.normal[1]]
    }

    /// Fills the reservoir with buffer particles on its lanes (s = (k + ½) ds, k = 0 … while
    /// s ≤ depth), density ρ₀, mass ρ₀ dx², velocity at time `t`, kind [`ParticleKind::Buffer`],
    /// `group` = `index` (this boundary's position in the solver's list), ids from `next_id` upwards
    /// (advanced).
    pub fn fill(&self, index: u16, rho0: Real, nu: Real, t: Real, next_id: &mut u64) -> Particles {
        let mut table = self.profile_table(nu);
        table.set_time(t);
        let r = ramp(t, self.ramp_time);
        let ds = self.stream_spacing();
        let mut p = Particles::default();
        let mass = rho0 * self.dx * self.dx;
        let mut k = 0usize;
        loop {
            let s = (k as Real + 0.5) * ds;
            if s > self.depth {
                break;
            }
            for j in 0..self.n_lanes() {
                let y = self.lane_y(j);
                let pos = self.global(s, y);
                let v = self.velocity(&table, y, r);
                p.push_grouped(pos[0], pos[1], v[0], v[1], rho0, mass, ParticleKind::Buffer, *next_id, index);
                *next_id += 1;
            }
            k += 1;
        }
        p
    }
}

/// Runtime state of one open boundary inside the solver: its description, the imposed-profile
/// table and the mass bookkeeping.
#[derive(Clone, Debug)]
pub struct BoundaryState {
    /// The boundary.
    pub spec: OpenBoundary,
    /// Mass through the opening and particles created/removed since the start.
    pub flux: BoundaryFlux,
    table: ProfileTable,
    ramp: Real,
}

impl BoundaryState {
    /// Runtime state for viscosity ν.
    pub fn new(spec: OpenBoundary, nu: Real) -> Self {
        let table = spec.profile_table(nu);
        BoundaryState { spec, flux: BoundaryFlux::default(), table, ramp: 1.0 }
    }

    /// Evaluates the imposed profile at time t.
    pub fn set_time(&mut self, t: Real) {
        self.table.set_time(t);
        self.ramp = ramp(t, self.spec.ramp_time);
    }

    /// Imposed velocity at lateral position y at the time last set.
    #[inline]
    pub fn velocity_at(&self, y: Real) -> [Real; 2] {
        self.spec.velocity(&self.table, y, self.ramp)
    }
}

/// Sets every reservoir particle's velocity to its boundary's imposed profile at time t.
pub fn impose(states: &mut [BoundaryState], p: &mut Particles, t: Real) {
    if states.is_empty() {
        return;
    }
    for s in states.iter_mut() {
        s.set_time(t);
    }
    for i in 0..p.len() {
        if p.kind[i] == ParticleKind::Buffer {
            let b = &states[p.group[i] as usize];
            let (_, y) = b.spec.local(p.x[i], p.z[i]);
            let v = b.velocity_at(y);
            p.vx[i] = v[0];
            p.vz[i] = v[1];
        }
    }
}

/// Sets every reservoir particle's density to the mean density of the fluid within `support` of
/// its opening, in its lane's neighbourhood (±1.5 lane spacings; the whole opening if that is empty;
/// ρ₀ if there is no fluid next to the opening at all). `sums` is scratch space.
pub fn extrapolate_density(
    states: &[BoundaryState],
    p: &mut Particles,
    support: Real,
    rho0: Real,
    sums: &mut Vec<(Real, u32)>,
) {
    // one pass over the particles for all openings: opening g's lanes at offsets[g] .. offsets[g+1]
    // − 1 of `sums`, its whole-opening sum at offsets[g+1] − 1
    let mut offsets = Vec::with_capacity(states.len() + 1);
    offsets.push(0);
    for b in states {
        offsets.push(offsets[offsets.len() - 1] + b.spec.n_lanes() + 1);
    }
    sums.clear();
    sums.resize(offsets[states.len()], (0.0, 0));
    for i in 0..p.len() {
        if p.kind[i] != ParticleKind::Fluid {
            continue;
        }
        for (g, b) in states.iter().enumerate() {
            if !b.spec.near(p.x[i], p.z[i], support) {
                continue;
            }
            let (s, y) = b.spec.local(p.x[i], p.z[i]);
            if s > 0.0 || s < -support || y.abs() > b.spec.half_width {
                continue;
            }
            let n = b.spec.n_lanes();
            let dy = b.spec.lane_spacing();
            let own = &mut sums[offsets[g]..offsets[g + 1]];
            let j = b.spec.lane_of(y);
            let k0 = j.saturating_sub(2);
            for (k, sum) in own[..n].iter_mut().enumerate().skip(k0).take(5) {
                if (y - b.spec.lane_y(k)).abs() <= 1.5 * dy {
                    sum.0 += p.rho[i];
                    sum.1 += 1;
                }
            }
            own[n].0 += p.rho[i];
            own[n].1 += 1;
        }
    }
    for i in 0..p.len() {
        if p.kind[i] != ParticleKind::Buffer {
            continue;
        }
        let g = p.group[i] as usize;
        let Some(b) = states.get(g) else { continue };
        let own = &sums[offsets[g]..offsets[g + 1]];
        let n = b.spec.n_lanes();
        let all = if own[n].1 > 0 { own[n].0 / own[n].1 as Real } else { rho0 };
        let (_, y) = b.spec.local(p.x[i], p.z[i]);
        let (sum, cnt) = own[b.spec.lane_of(y)];
        p.rho[i] = if cnt > 0 { sum / cnt as Real } else { all };
    }
}

/// After a step ending at time t (profiles already set to t by [`impose`]): moves particles between
/// the fluid and the reservoirs, removes reservoir particles beyond the far side and creates new ones
/// at the far side of every lane that has room (module documentation). New particles get ids from
/// `next_id` upwards, mass ρ₀dx², the density of the lane's outermost particle (the extrapolated
/// one) and the imposed velocity. `keep` is scratch space.
pub fn exchange(states: &mut [BoundaryState], p: &mut Particles, rho0: Real, next_id: &mut u64, keep: &mut Vec<bool>) {
    if states.is_empty() {
        return;
    }
    keep.clear();
    keep.resize(p.len(), true);
    let mut any_removed = false;
    for i in 0..p.len() {
        match p.kind[i] {
            ParticleKind::Fluid => {
                for (g, b) in states.iter_mut().enumerate() {
                    if !b.spec.near(p.x[i], p.z[i], 0.0) {
                        continue;
                    }
                    let (s, y) = b.spec.local(p.x[i], p.z[i]);
                    if s > 0.0 && s <= b.spec.depth && y.abs() <= b.spec.half_width + 0.5 * b.spec.dx {
                        p.kind[i] = ParticleKind::Buffer;
                        p.group[i] = g as u16;
                        b.flux.mass_out += p.mass[i];
                        let v = b.velocity_at(y);
                        p.vx[i] = v[0];
                        p.vz[i] = v[1];
                        break;
                    }
                }
            }
            ParticleKind::Buffer => {
                let b = &mut states[p.group[i] as usize];
                let (s, _) = b.spec.local(p.x[i], p.z[i]);
                if s <= 0.0 {
                    p.kind[i] = ParticleKind::Fluid;
                    p.group[i] = 0;
                    b.flux.mass_in += p.mass[i];
                } else if s > b.spec.depth {
                    keep[i] = false;
                    any_removed = true;
                    b.flux.removed += 1;
                }
            }
            _ => {}
        }
    }
    if any_removed {
        p.retain_indices(keep);
    }
    // Creation at the far side, lane by lane: per boundary and lane the outermost s and its
    // density, from one pass over the particles.
    let mut created = Particles::default();
    let mut outers: Vec<Vec<(Real, Real)>> =
        states.iter().map(|b| vec![(-0.5 * b.spec.stream_spacing(), rho0); b.spec.n_lanes()]).collect();
    for i in 0..p.len() {
        if p.kind[i] == ParticleKind::Buffer {
            let g = p.group[i] as usize;
            let b = &states[g];
            let (s, y) = b.spec.local(p.x[i], p.z[i]);
            let j = b.spec.lane_of(y);
            let o = &mut outers[g][j];
            if s > o.0 {
                *o = (s, p.rho[i]);
            }
        }
    }
    for ((g, b), outer) in states.iter_mut().enumerate().zip(&outers) {
        let ds = b.spec.stream_spacing();
        let mass = rho0 * b.spec.dx * b.spec.dx;
        for (j, &(mut s_out, rho)) in outer.iter().enumerate() {
            let y = b.spec.lane_y(j);
            let v = b.velocity_at(y);
            // only lanes that flow into the domain need new particles at the far side
            if v[0] * b.spec.normal[0] + v[1] * b.spec.normal[1] >= 0.0 {
                continue;
            }
            while s_out + ds <= b.spec.depth {
                s_out += ds;
                let pos = b.spec.global(s_out, y);
                created.push_grouped(pos[0], pos[1], v[0], v[1], rho, mass, ParticleKind::Buffer, *next_id, g as u16);
                *next_id += 1;
                b.flux.created += 1;
            }
        }
    }
    if !created.is_empty() {
        p.append(&created);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::waveform::WaveformSpec;

    fn inlet() -> OpenBoundary {
        OpenBoundary {
            name: "inlet".into(),
            origin: [0.0, 0.02],
            normal: [-1.0, 0.0],
            half_width: 4e-3,
            depth: 0.6e-3,
            dx: 0.15e-3,
            inflow: WaveformSpec::Constant { value: 0.2 }.build().expect("ok"),
            profile: ProfileKind::Womersley,
            ramp_time: 0.0,
        }
    }

    #[test]
    fn fill_covers_the_reservoir_with_lattice_area_per_particle() {
        let b = inlet();
        let mut id = 100;
        let p = b.fill(3, 1000.0, 4e-6, 0.0, &mut id);
        let n_rows = p.len() / b.n_lanes();
        assert_eq!(n_rows * b.n_lanes(), p.len());
        assert_eq!(id, 100 + p.len() as u64);
        // area per particle is dx²; lanes one lane spacing from the walls
        assert!((b.lane_spacing() * b.stream_spacing() / (b.dx * b.dx) - 1.0).abs() < 1e-12);
        assert!((b.lane_y(0) + b.half_width - b.lane_spacing()).abs() < 1e-15);
        assert!((b.half_width - b.lane_y(b.n_lanes() - 1) - b.lane_spacing()).abs() < 1e-15);
        assert_eq!(b.lane_of(b.lane_y(3) + 0.4 * b.lane_spacing()), 3);
        assert_eq!(b.lane_of(-b.half_width), 0);
        for i in 0..p.len() {
            let (s, y) = b.local(p.x[i], p.z[i]);
            assert!(s > 0.0 && s <= b.depth && y.abs() < b.half_width, "{s} {y}");
            assert_eq!(p.group[i], 3);
            assert_eq!(p.kind[i], ParticleKind::Buffer);
            // inflow through a left-facing opening moves along +x; parabola-like profile (steady)
            let expect = 1.5 * 0.2 * (1.0 - (y / b.half_width).powi(2));
            assert!((p.vx[i] - expect).abs() < 1e-3 * 0.3 && p.vz[i].abs() < 1e-15, "{} vs {expect}", p.vx[i]);
        }
    }

    #[test]
    fn validation_names_the_field() {
        let mut b = inlet();
        b.normal = [1.0, 1.0];
        assert!(b.validate(0.45e-3).expect_err("bad").contains("`normal`"));
        let b = inlet();
        assert!(b.validate(0.7e-3).expect_err("shallow").contains("`depth`"));
        assert!(b.validate(0.45e-3).is_ok());
    }

    #[test]
    fn ramp_is_smooth_and_bounded() {
        assert_eq!(ramp(-1.0, 0.1), 0.0);
        assert_eq!(ramp(0.2, 0.1), 1.0);
        assert_eq!(ramp(0.05, 0.1), 0.5);
        assert_eq!(ramp(0.05, 0.0), 1.0);
    }
}
