//! Carrier flows for the particle dynamics: what a platelet sees of the blood at its centre of mass.
//!
//! A [`CarrierFlow`] gives, at a point and time, the velocity v, the fluid angular velocity
//! ω = ½ (∂v_y/∂x − ∂v_x/∂y) and the strain rate tensor E = ½ (∇v + ∇vᵀ) (SI). Three are provided:
//!
//! - [`SimpleShear`]: v = (γ̇ y, 0), the flow of Jeffery's orbits.
//! - [`Channel`]: paper 2's channel (section 5.1/5.2) of height H = 2 mm, walls at y = 0 and y = H,
//!   with the parabolic profile v_x = y(2 − y)/2 · v_in(t) in mm units, i.e. v_x = 2 v_in s (1 − s)
//!   with s = y/H (peak v_in/2 on the axis), v_in = 5 mm/s, optionally ramped linearly in t
//!   (section 5.1 writes v_in(t) = y(2 − y)/2 · t · v_in; the ramp factor here is min(t/t_ramp, 1)).
//! - [`LatticeField`]: velocities given on the nodes of a regular square lattice (spacing h),
//!   interpolated bilinearly; ω per lattice cell T from paper 2's eq 12,
//!   ω_T = 1/(2 d_T) Σᵢ ⟨v(xᵢ), tᵢ⟩ with d_T = √2 h the cell diameter and tᵢ the counter-clockwise
//!   unit tangent at node i of the circle through the four nodes; the strain from the same cell
//!   (gradient of the bilinear interpolant at the cell centre). Both are exact for linear fields
//!   (eq 12 equals ½ curl of the bilinear interpolant at the cell centre). Points outside the
//!   lattice are clamped onto it. Nodes carry a validity mask (all valid unless set with
//!   [`LatticeField::set_velocities_masked`]); an invalid node (no fluid there, e.g. outside the
//!   lumen of an SPH carrier) must carry v = 0, so the interpolant falls to zero across the last
//!   cell like a no-slip wall. [`super::sph_interp`] fills a lattice from scattered SPH particles.
//! - [`super::Stenosis`] (module `stenosis`): section 5.2's channel with a 25 % narrowing, from the
//!   lubrication approximation; its walls vary along x ([`CarrierFlow::local_walls`]).

/// The carrier flow at one point.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FlowSample {
    /// Velocity \[m/s\].
    pub v: [f64; 2],
    /// Fluid angular velocity ½ (∂v_y/∂x − ∂v_x/∂y) \[1/s\].
    pub omega: f64,
    /// Strain rate (E_xx, E_xy, E_yy) \[1/s\].
    pub strain: [f64; 3],
}

impl FlowSample {
    /// E'_xy from sin 2φ and cos 2φ.
    #[inline]
    pub fn body_strain_xy_sc(&self, s2: f64, c2: f64) -> f64 {
        0.5 * (self.strain[2] - self.strain[0]) * s2 + self.strain[1] * c2
    }

    /// The off-diagonal strain rate in the frame of a body rotated by φ from the lab x axis:
    /// E' = Rᵀ E R, E'_xy = ½ (E_yy − E_xx) sin 2φ + E_xy cos 2φ.
    pub fn body_strain_xy(&self, phi: f64) -> f64 {
        let (s2, c2) = (2.0 * phi).sin_cos();
        0.5 * (self.strain[2] - self.strain[0]) * s2 + self.strain[1] * c2
    }
}

/// A flow field the particles are advected in (module doc).
pub trait CarrierFlow: Send + Sync {
    /// Velocity, angular velocity and strain rate at `x` \[m\] and time `t` \[s\].
    fn sample(&self, x: [f64; 2], t: f64) -> FlowSample;
    /// Velocity v(x, t) \[m/s\].
    fn velocity(&self, x: [f64; 2], t: f64) -> [f64; 2] {
        self.sample(x, t).v
    }
    /// Fluid angular velocity ω(x, t) = ½ curl v \[1/s\].
    fn angular_velocity(&self, x: [f64; 2], t: f64) -> f64 {
        self.sample(x, t).omega
    }
    /// Strain rate (E_xx, E_xy, E_yy) \[1/s\].
    fn strain_rate(&self, x: [f64; 2], t: f64) -> [f64; 3] {
        self.sample(x, t).strain
    }
    /// Walls y = lo and y = hi the particle centres must stay between, if any (for a channel of
    /// varying gap: the outer bounds; the dynamics uses [`CarrierFlow::local_walls`]).
    fn walls(&self) -> Option<[f64; 2]> {
        None
    }
    /// The walls at abscissa x: y_lo(x) ≤ y ≤ y_hi(x) with their slopes dy/dx. Default: the
    /// straight walls of [`CarrierFlow::walls`] (slopes 0). A flow whose walls vary along x (the
    /// [`super::Stenosis`]) overrides this; the dynamics reflects centres that crossed a wall about
    /// the local wall (`collide::walls_local`), which is the plain reflection for slope 0.
    fn local_walls(&self, _x: f64) -> Option<LocalWalls> {
        self.walls().map(|[lo, hi]| LocalWalls { lo, hi, slope_lo: 0.0, slope_hi: 0.0 })
    }
}

/// The walls of a channel at one abscissa (see [`CarrierFlow::local_walls`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LocalWalls {
    /// Lower wall y_lo(x) \[m\].
    pub lo: f64,
    /// Upper wall y_hi(x) \[m\].
    pub hi: f64,
    /// dy_lo/dx.
    pub slope_lo: f64,
    /// dy_hi/dx.
    pub slope_hi: f64,
}

/// Errors of flow parameters.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FlowError {
    /// A parameter outside its allowed range.
    #[error("carrier flow: `{field}` = {value} is invalid: allowed {allowed}")]
    Invalid { field: &'static str, value: f64, allowed: &'static str },
    /// A node velocity that is NaN or infinite.
    #[error("lattice field: velocity of node {node} (row-major j * nx + i) is {value}: allowed finite")]
    NonFinite { node: usize, value: f64 },
    /// Lattice data of the wrong size.
    #[error("lattice field: {nx} x {ny} nodes need {expected} velocities, got {got}")]
    Size { nx: usize, ny: usize, expected: usize, got: usize },
    /// Scattered particle data that cannot be used (lengths, NaN).
    #[error("fluid particles: {0}")]
    Particles(String),
}

pub(crate) fn check(field: &'static str, value: f64, ok: bool, allowed: &'static str) -> Result<(), FlowError> {
    if ok && value.is_finite() {
        Ok(())
    } else {
        Err(FlowError::Invalid { field, value, allowed })
    }
}

/// v = (γ̇ y, 0): ω = −γ̇/2, E_xy = γ̇/2.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SimpleShear {
    /// Shear rate γ̇ \[1/s\].
    pub shear_rate: f64,
}

impl SimpleShear {
    /// Shear rate must be finite.
    pub fn new(shear_rate: f64) -> Result<Self, FlowError> {
        check("shear_rate", shear_rate, true, "finite")?;
        Ok(SimpleShear { shear_rate })
    }
}

impl CarrierFlow for SimpleShear {
    fn sample(&self, x: [f64; 2], _t: f64) -> FlowSample {
        let g = self.shear_rate;
        FlowSample { v: [g * x[1], 0.0], omega: -0.5 * g, strain: [0.0, 0.5 * g, 0.0] }
    }
}

/// Paper 2's parabolic channel (module doc). Defaults: H = 2 mm, v_in = 5 mm/s, no ramp.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Channel {
    /// Channel height H \[m\] (walls at y = 0 and y = H). Default 2e-3.
    pub height: f64,
    /// Inflow speed v_in \[m/s\]; the axis speed is v_in/2 (paper's profile). Default 5e-3.
    pub v_in: f64,
    /// Ramp time \[s\]: v_in is scaled by min(t / ramp, 1); `None` (default) for a steady flow.
    pub ramp: Option<f64>,
}

impl Default for Channel {
    fn default() -> Self {
        Channel { height: 2e-3, v_in: 5e-3, ramp: None }
    }
}

impl Channel {
    /// Height in (0, 1 m], v_in finite, ramp > 0.
    pub fn validate(&self) -> Result<(), FlowError> {
        check("height", self.height, self.height > 0.0 && self.height <= 1.0, "0 < height <= 1 m")?;
        check("v_in", self.v_in, true, "finite")?;
        if let Some(r) = self.ramp {
            check("ramp", r, r > 0.0, "ramp > 0 s")?;
        }
        Ok(())
    }

    /// The time factor of v_in.
    pub fn ramp_factor(&self, t: f64) -> f64 {
        match self.ramp {
            Some(r) => (t / r).clamp(0.0, 1.0),
            None => 1.0,
        }
    }

    /// Axial velocity at height y \[m/s\] (0 outside the channel).
    pub fn profile(&self, y: f64, t: f64) -> f64 {
        let s = y / self.height;
        if !(0.0..=1.0).contains(&s) {
            return 0.0;
        }
        2.0 * self.v_in * self.ramp_factor(t) * s * (1.0 - s)
    }
}

impl CarrierFlow for Channel {
    fn sample(&self, x: [f64; 2], t: f64) -> FlowSample {
        let s = x[1] / self.height;
        if !(0.0..=1.0).contains(&s) {
            return FlowSample::default();
        }
        let v0 = 2.0 * self.v_in * self.ramp_factor(t);
        let dudy = v0 * (1.0 - 2.0 * s) / self.height;
        FlowSample { v: [v0 * s * (1.0 - s), 0.0], omega: -0.5 * dudy, strain: [0.0, 0.5 * dudy, 0.0] }
    }
    fn walls(&self) -> Option<[f64; 2]> {
        Some([0.0, self.height])
    }
}

/// Velocities on a regular lattice (module doc): node (i, j) at origin + (i h, j h), stored
/// row-major `v[j * nx + i]`; per cell ω (eq 12) and strain are computed once in
/// [`LatticeField::set_velocities`] (Algorithm 2, step 2).
#[derive(Clone, Debug)]
pub struct LatticeField {
    origin: [f64; 2],
    h: f64,
    nx: usize,
    ny: usize,
    v: Vec<[f64; 2]>,
    valid: Vec<bool>,
    cell_omega: Vec<f64>,
    cell_strain: Vec<[f64; 3]>,
    walls: Option<[f64; 2]>,
}

impl LatticeField {
    /// A lattice of nx × ny ≥ 2 × 2 nodes with spacing h > 0 \[m\] and velocities `v` \[m/s\].
    pub fn new(origin: [f64; 2], h: f64, nx: usize, ny: usize, v: Vec<[f64; 2]>) -> Result<Self, FlowError> {
        check("origin[0]", origin[0], true, "finite")?;
        check("origin[1]", origin[1], true, "finite")?;
        check("h", h, h > 0.0, "h > 0 m")?;
        if nx < 2 {
            return Err(FlowError::Invalid { field: "nx", value: nx as f64, allowed: "nx >= 2" });
        }
        if ny < 2 {
            return Err(FlowError::Invalid { field: "ny", value: ny as f64, allowed: "ny >= 2" });
        }
        let mut f = LatticeField {
            origin,
            h,
            nx,
            ny,
            v: Vec::new(),
            valid: Vec::new(),
            cell_omega: vec![0.0; (nx - 1) * (ny - 1)],
            cell_strain: vec![[0.0; 3]; (nx - 1) * (ny - 1)],
            walls: None,
        };
        f.set_velocities(v)?;
        Ok(f)
    }

    /// Samples a flow onto a lattice (e.g. an analytic flow, as a finite element field would be).
    /// The lattice reports the flow's [`CarrierFlow::walls`] (straight bounds); walls that vary
    /// along x ([`CarrierFlow::local_walls`], the stenosis) are not carried over.
    pub fn from_flow(
        flow: &dyn CarrierFlow,
        t: f64,
        origin: [f64; 2],
        h: f64,
        nx: usize,
        ny: usize,
    ) -> Result<Self, FlowError> {
        let mut v = Vec::with_capacity(nx * ny);
        for j in 0..ny {
            for i in 0..nx {
                v.push(flow.velocity([origin[0] + i as f64 * h, origin[1] + j as f64 * h], t));
            }
        }
        let mut f = Self::new(origin, h, nx, ny, v)?;
        f.walls = flow.walls();
        Ok(f)
    }

    /// Walls to report through [`CarrierFlow::walls`].
    pub fn with_walls(mut self, walls: Option<[f64; 2]>) -> Self {
        self.walls = walls;
        self
    }

    /// New node velocities (same lattice), every node valid; recomputes ω and the strain of every
    /// cell.
    pub fn set_velocities(&mut self, v: Vec<[f64; 2]>) -> Result<(), FlowError> {
        let n = v.len();
        self.set_velocities_masked(v, vec![true; n])
    }

    /// New node velocities and validity mask (same lattice, both row-major); recomputes ω and the
    /// strain of every cell. Invalid nodes should carry v = 0 (module doc); their velocities are
    /// used as given.
    pub fn set_velocities_masked(&mut self, v: Vec<[f64; 2]>, valid: Vec<bool>) -> Result<(), FlowError> {
        let (nx, ny) = (self.nx, self.ny);
        if v.len() != nx * ny {
            return Err(FlowError::Size { nx, ny, expected: nx * ny, got: v.len() });
        }
        if valid.len() != nx * ny {
            return Err(FlowError::Size { nx, ny, expected: nx * ny, got: valid.len() });
        }
        for (k, vk) in v.iter().enumerate() {
            for c in vk {
                if !c.is_finite() {
                    return Err(FlowError::NonFinite { node: k, value: *c });
                }
            }
        }
        self.v = v;
        self.valid = valid;
        let h = self.h;
        let d_t = std::f64::consts::SQRT_2 * h;
        // nodes counter-clockwise from the lower left, offsets from the cell centre (units of h/2)
        const CORNERS: [(usize, usize, f64, f64); 4] =
            [(0, 0, -1.0, -1.0), (1, 0, 1.0, -1.0), (1, 1, 1.0, 1.0), (0, 1, -1.0, 1.0)];
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                let mut circ = 0.0;
                for &(di, dj, rx, ry) in &CORNERS {
                    let vn = self.v[(j + dj) * nx + i + di];
                    // t = e_z × r / |r|, |r| = √2 h/2 with r = (rx, ry) h/2
                    let (tx, ty) = (-ry / std::f64::consts::SQRT_2, rx / std::f64::consts::SQRT_2);
                    circ += vn[0] * tx + vn[1] * ty;
                }
                let c = j * (nx - 1) + i;
                self.cell_omega[c] = circ / (2.0 * d_t);
                let [v00, v10, v01, v11] = [
                    self.v[j * nx + i],
                    self.v[j * nx + i + 1],
                    self.v[(j + 1) * nx + i],
                    self.v[(j + 1) * nx + i + 1],
                ];
                let dx = |k: usize| (v10[k] + v11[k] - v00[k] - v01[k]) / (2.0 * h);
                let dy = |k: usize| (v01[k] + v11[k] - v00[k] - v10[k]) / (2.0 * h);
                self.cell_strain[c] = [dx(0), 0.5 * (dy(0) + dx(1)), dy(1)];
            }
        }
        Ok(())
    }

    /// ω of cell (i, j) from eq 12.
    pub fn cell_omega(&self, i: usize, j: usize) -> Option<f64> {
        (i + 1 < self.nx && j + 1 < self.ny).then(|| self.cell_omega[j * (self.nx - 1) + i])
    }

    /// Strain rate (E_xx, E_xy, E_yy) of cell (i, j).
    pub fn cell_strain(&self, i: usize, j: usize) -> Option<[f64; 3]> {
        (i + 1 < self.nx && j + 1 < self.ny).then(|| self.cell_strain[j * (self.nx - 1) + i])
    }

    /// Position of node (0, 0) \[m\].
    pub fn origin(&self) -> [f64; 2] {
        self.origin
    }

    /// Node spacing h \[m\].
    pub fn spacing(&self) -> f64 {
        self.h
    }

    /// Nodes along x and y.
    pub fn dims(&self) -> (usize, usize) {
        (self.nx, self.ny)
    }

    /// Position of node (i, j) \[m\].
    pub fn node_position(&self, i: usize, j: usize) -> [f64; 2] {
        [self.origin[0] + i as f64 * self.h, self.origin[1] + j as f64 * self.h]
    }

    /// Velocity of node (i, j) \[m/s\].
    pub fn node_velocity(&self, i: usize, j: usize) -> Option<[f64; 2]> {
        (i < self.nx && j < self.ny).then(|| self.v[j * self.nx + i])
    }

    /// Whether node (i, j) is valid (has fluid; module doc).
    pub fn node_valid(&self, i: usize, j: usize) -> bool {
        i < self.nx && j < self.ny && self.valid[j * self.nx + i]
    }

    /// Number of valid nodes.
    pub fn valid_nodes(&self) -> usize {
        self.valid.iter().filter(|&&b| b).count()
    }

    /// Whether `x` lies on the lattice (not clamped) in a cell whose four nodes are valid.
    pub fn cell_valid_at(&self, x: [f64; 2]) -> bool {
        let fx = (x[0] - self.origin[0]) / self.h;
        let fy = (x[1] - self.origin[1]) / self.h;
        if !(fx >= 0.0 && fy >= 0.0 && fx <= (self.nx - 1) as f64 && fy <= (self.ny - 1) as f64) {
            return false;
        }
        let i = (fx as usize).min(self.nx - 2);
        let j = (fy as usize).min(self.ny - 2);
        let nx = self.nx;
        self.valid[j * nx + i]
            && self.valid[j * nx + i + 1]
            && self.valid[(j + 1) * nx + i]
            && self.valid[(j + 1) * nx + i + 1]
    }
}

impl CarrierFlow for LatticeField {
    fn sample(&self, x: [f64; 2], _t: f64) -> FlowSample {
        let fx = ((x[0] - self.origin[0]) / self.h).clamp(0.0, (self.nx - 1) as f64);
        let fy = ((x[1] - self.origin[1]) / self.h).clamp(0.0, (self.ny - 1) as f64);
        let i = (fx as usize).min(self.nx - 2);
        let j = (fy as usize).min(self.ny - 2);
        let (sx, sy) = (fx - i as f64, fy - j as f64);
        let nx = self.nx;
        let (v00, v10, v01, v11) =
            (self.v[j * nx + i], self.v[j * nx + i + 1], self.v[(j + 1) * nx + i], self.v[(j + 1) * nx + i + 1]);
        let bil =
            |k: usize| (1.0 - sy) * ((1.0 - sx) * v00[k] + sx * v10[k]) + sy * ((1.0 - sx) * v01[k] + sx * v11[k]);
        let c = j * (nx - 1) + i;
        FlowSample { v: [bil(0), bil(1)], omega: self.cell_omega[c], strain: self.cell_strain[c] }
    }
    fn walls(&self) -> Option<[f64; 2]> {
        self.walls
    }
}
