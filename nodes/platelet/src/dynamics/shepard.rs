//! SPH interpolation of scattered fluid particles onto a [`LatticeField`]: paper 2's Algorithm 2,
//! step 2 ("transfer the local velocities … to the particle lattice and locally compute the
//! rotational velocity according to (12)") with an SPH fluid (paper 1's weakly compressible SPH,
//! the `sph-flow` node) in place of the finite element mesh.
//!
//! **Method.** Shepard-normalised kernel interpolation (Shepard 1968; the zeroth-order consistent
//! SPH interpolant, Monaghan 2005 §2): at a lattice node x
//!
//! ```text
//! v(x) = Σ_b v_b W(|x − x_b|, h) / Σ_b W(|x − x_b|, h)
//! ```
//!
//! over the fluid particles b within the kernel support, with W the M5 quartic spline (support
//! 2.5 h, the SPH solver's default) or Wendland's C² kernel (support 2 h), normalised to ∫ W dA = 1
//! exactly as in `sonoflow-sph`'s `kernel.rs`. Particle volumes cancel in the normalised form
//! provided they are equal, which is what a weakly compressible SPH with one particle mass keeps
//! to within its density error (< 1 %). The local rotation ω and the strain rate then come from
//! the lattice itself ([`LatticeField::set_velocities_masked`]: eq 12 per cell).
//!
//! **Accuracy.** The normalised interpolant reproduces constants exactly; for a linear field its
//! error is ∇v · m₁ with m₁ = Σ W (x_b − x)/Σ W the kernel's first moment over the particles (zero
//! for a symmetric neighbourhood, O(jitter/√neighbours) for a disordered one); for a curved field it
//! smooths: Σ W (v_b − v(x))/Σ W ≈ ¼ M₂ ∇²v with M₂ = ∫ r² W dA (0.799 h² quartic, 5/9 h² Wendland),
//! e.g. −u_max M₂/(2a²) for Poiseuille flow of half-width a (0.6 % of u_max for h = 0.48 mm in an
//! 8 mm tube). Eq 12 on the lattice is exact for fields linear in each cell and, at the cell centre,
//! for the quadratic Poiseuille profile, so ω inherits only the interpolation's error. The tests
//! check each of these statements against analytic fields on a jittered particle lattice.
//!
//! **Mask.** A node's fluid fraction is φ(x) = V Σ_b W(|x − x_b|, h) (≈ 1 inside the fluid, ≈ ½ on
//! a flat free surface or on a wall whose fluid particles are not on the wire, → 0 outside), with
//! the particle volume V estimated from the snapshot itself as the reciprocal of the median SPH
//! number density Σ_b W at the particles on the lattice (the wire, `ParticleSnapshotV1`, carries
//! positions and velocities but neither masses nor densities). Nodes with φ < `min_fraction` are
//! invalid and carry v = 0. The SPH solver's own interpolation (`Solver::sample_velocity`) also
//! sums over the wall particles with their no-slip velocities; those are not published, so near
//! a wall this interpolant sees only fluid and does not vanish on the wall: the mask (v = 0 on
//! nodes outside the fluid) is what brings it to zero across the last lattice cell.
//!
//! **Why here and not in `sonoflow-sph`.** The solver's interpolation needs its whole state
//! (masses, densities, wall particles, cell lists) and is a method of the running `Solver`; what
//! arrives over the wire are bare positions and velocities. The ~30 lines of kernel below keep this
//! crate free of a dependency on the SPH solver (and its build time) for the sake of two
//! polynomials; the normalisation constants are the same, and the tests integrate them.
//!
//! **Cost.** A scatter from each particle to the lattice nodes within its support: no neighbour
//! search, O(N (2κh/Δ)²) kernel evaluations for N particles and lattice spacing Δ, serial and
//! deterministic; the workspaces are kept between snapshots.

use super::flow::{FlowError, LatticeField};

/// The SPH kernel of the interpolation (same functions and normalisation as `sonoflow-sph`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SphKernel {
    /// M5 quartic B-spline, support 2.5 h (paper 1's kernel, the SPH solver's default).
    #[default]
    QuarticSpline,
    /// Wendland C², support 2 h.
    WendlandC2,
}

impl SphKernel {
    /// Support radius in units of h.
    pub fn support_factor(self) -> f64 {
        match self {
            SphKernel::QuarticSpline => 2.5,
            SphKernel::WendlandC2 => 2.0,
        }
    }

    /// 2-D normalisation σ₂D: W(r, h) = σ₂D / h² · f(r/h).
    pub fn sigma_2d(self) -> f64 {
        use std::f64::consts::PI;
        match self {
            SphKernel::QuarticSpline => 96.0 / (1199.0 * PI),
            SphKernel::WendlandC2 => 7.0 / (4.0 * PI),
        }
    }

    /// Dimensionless shape f(q), q = r/h.
    #[inline]
    pub fn shape(self, q: f64) -> f64 {
        match self {
            SphKernel::QuarticSpline => {
                let mut f = 0.0;
                let a = 2.5 - q;
                if a > 0.0 {
                    f += a * a * a * a;
                    let b = 1.5 - q;
                    if b > 0.0 {
                        f -= 5.0 * b * b * b * b;
                        let c = 0.5 - q;
                        if c > 0.0 {
                            f += 10.0 * c * c * c * c;
                        }
                    }
                }
                f
            }
            SphKernel::WendlandC2 => {
                if q < 2.0 {
                    let a = 1.0 - 0.5 * q;
                    let a2 = a * a;
                    a2 * a2 * (2.0 * q + 1.0)
                } else {
                    0.0
                }
            }
        }
    }

    /// W(r, h) \[1/m²\].
    #[inline]
    pub fn w(self, r: f64, h: f64) -> f64 {
        self.sigma_2d() / (h * h) * self.shape(r / h)
    }
}

fn d_min_fraction() -> f64 {
    0.5
}

/// Parameters of the interpolation.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShepardParams {
    /// Kernel. Default `quartic-spline`.
    #[serde(default)]
    pub kernel: SphKernel,
    /// Smoothing length h \[m\] (the SPH run's, e.g. 1.2 × its particle spacing). Required.
    pub h: f64,
    /// Nodes whose fluid fraction φ is below this are invalid (module doc), 0 < min_fraction ≤ 1.
    /// Default 0.5 (a node on a wall has φ ≈ ½).
    #[serde(default = "d_min_fraction")]
    pub min_fraction: f64,
}

impl ShepardParams {
    /// h in (0, 0.1 m], min_fraction in (0, 1].
    pub fn validate(&self) -> Result<(), FlowError> {
        super::flow::check("kernel_h", self.h, self.h > 0.0 && self.h <= 0.1, "0 < kernel_h <= 0.1 m")?;
        super::flow::check(
            "min_fraction",
            self.min_fraction,
            self.min_fraction > 0.0 && self.min_fraction <= 1.0,
            "0 < min_fraction <= 1",
        )
    }
}

/// What one [`ShepardInterpolator::fill`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FillReport {
    /// Particles given.
    pub particles: usize,
    /// Particles within the kernel support of at least one lattice node.
    pub used: usize,
    /// Estimated particle volume V \[m²\] (NaN when no particle lies on the lattice).
    pub volume: f64,
    /// Valid nodes (φ ≥ min_fraction).
    pub valid_nodes: usize,
    /// All nodes.
    pub nodes: usize,
}

/// Fills a [`LatticeField`] from scattered particles (module doc); keeps its workspaces.
#[derive(Clone, Debug)]
pub struct ShepardInterpolator {
    params: ShepardParams,
    sw: Vec<f64>,
    su: Vec<f64>,
    sv: Vec<f64>,
    fraction: Vec<f64>,
    density: Vec<f64>,
}

impl ShepardInterpolator {
    /// Checks the parameters.
    pub fn new(params: ShepardParams) -> Result<Self, FlowError> {
        params.validate()?;
        Ok(ShepardInterpolator {
            params,
            sw: Vec::new(),
            su: Vec::new(),
            sv: Vec::new(),
            fraction: Vec::new(),
            density: Vec::new(),
        })
    }

    /// The parameters.
    pub fn params(&self) -> &ShepardParams {
        &self.params
    }

    /// Fluid fraction φ per node of the last fill (row-major `j * nx + i`).
    pub fn fraction(&self) -> &[f64] {
        &self.fraction
    }

    /// Interpolates the particles (positions `pos` \[m\], velocities `vel` \[m/s\], in the
    /// lattice's frame) onto `field`'s nodes and sets its velocities, mask, ω and strain.
    pub fn fill(&mut self, field: &mut LatticeField, pos: &[[f64; 2]], vel: &[[f64; 2]]) -> Result<FillReport, FlowError> {
        if pos.len() != vel.len() {
            return Err(FlowError::Particles(format!(
                "{} positions but {} velocities",
                pos.len(),
                vel.len()
            )));
        }
        for (b, (p, v)) in pos.iter().zip(vel).enumerate() {
            if !(p[0].is_finite() && p[1].is_finite() && v[0].is_finite() && v[1].is_finite()) {
                return Err(FlowError::Particles(format!(
                    "particle {b}: position ({}, {}) m, velocity ({}, {}) m/s: allowed finite",
                    p[0], p[1], v[0], v[1]
                )));
            }
        }
        let (nx, ny) = field.dims();
        let [ox, oy] = field.origin();
        let dl = field.spacing();
        let nn = nx * ny;
        for a in [&mut self.sw, &mut self.su, &mut self.sv] {
            a.clear();
            a.resize(nn, 0.0);
        }
        let (kernel, h) = (self.params.kernel, self.params.h);
        let r = kernel.support_factor() * h;
        let r2 = r * r;
        let norm = kernel.sigma_2d() / (h * h);
        let inv_h = 1.0 / h;
        let (imax, jmax) = ((nx - 1) as f64, (ny - 1) as f64);
        let mut used = 0usize;
        for (p, v) in pos.iter().zip(vel) {
            let (i_lo, i_hi) = (((p[0] - r - ox) / dl).ceil().max(0.0), ((p[0] + r - ox) / dl).floor().min(imax));
            let (j_lo, j_hi) = (((p[1] - r - oy) / dl).ceil().max(0.0), ((p[1] + r - oy) / dl).floor().min(jmax));
            if i_lo > i_hi || j_lo > j_hi {
                continue;
            }
            let mut any = false;
            for j in j_lo as usize..=j_hi as usize {
                let dy = oy + j as f64 * dl - p[1];
                let dy2 = dy * dy;
                if dy2 >= r2 {
                    continue;
                }
                let row = j * nx;
                for i in i_lo as usize..=i_hi as usize {
                    let dx = ox + i as f64 * dl - p[0];
                    let d2 = dx * dx + dy2;
                    if d2 >= r2 {
                        continue;
                    }
                    let w = norm * kernel.shape(d2.sqrt() * inv_h);
                    self.sw[row + i] += w;
                    self.su[row + i] += w * v[0];
                    self.sv[row + i] += w * v[1];
                    any = true;
                }
            }
            used += any as usize;
        }
        // particle volume: 1 / median number density at the particles on the lattice (bilinear
        // from the node sums, which are complete: every particle within reach contributed)
        self.density.clear();
        for p in pos {
            let fx = (p[0] - ox) / dl;
            let fy = (p[1] - oy) / dl;
            if !(fx >= 0.0 && fy >= 0.0 && fx <= imax && fy <= jmax) {
                continue;
            }
            let i = (fx as usize).min(nx - 2);
            let j = (fy as usize).min(ny - 2);
            let (sx, sy) = (fx - i as f64, fy - j as f64);
            let s = &self.sw;
            let n = (1.0 - sy) * ((1.0 - sx) * s[j * nx + i] + sx * s[j * nx + i + 1])
                + sy * ((1.0 - sx) * s[(j + 1) * nx + i] + sx * s[(j + 1) * nx + i + 1]);
            if n > 0.0 {
                self.density.push(n);
            }
        }
        let volume = if self.density.is_empty() {
            f64::NAN
        } else {
            let mid = self.density.len() / 2;
            let (_, m, _) = self.density.select_nth_unstable_by(mid, f64::total_cmp);
            1.0 / *m
        };
        self.fraction.clear();
        self.fraction.resize(nn, 0.0);
        let mut v = vec![[0.0; 2]; nn];
        let mut valid = vec![false; nn];
        let mut n_valid = 0;
        for k in 0..nn {
            let phi = if volume.is_finite() { volume * self.sw[k] } else { 0.0 };
            self.fraction[k] = phi;
            if self.sw[k] > 0.0 && phi >= self.params.min_fraction {
                v[k] = [self.su[k] / self.sw[k], self.sv[k] / self.sw[k]];
                valid[k] = true;
                n_valid += 1;
            }
        }
        field.set_velocities_masked(v, valid)?;
        Ok(FillReport { particles: pos.len(), used, volume, valid_nodes: n_valid, nodes: nn })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use rand::{Rng, SeedableRng};

    const KINDS: [SphKernel; 2] = [SphKernel::QuarticSpline, SphKernel::WendlandC2];

    /// ∫₀^κ q^p f(q) dq · 2π σ by composite Simpson with breaks at multiples of ½ (exact to rounding
    /// for the piecewise polynomials).
    fn moment(k: SphKernel, p: i32) -> f64 {
        let n = (k.support_factor() * 4096.0) as usize;
        let dq = k.support_factor() / n as f64;
        let g = |q: f64| q.powi(p) * k.shape(q);
        let mut s = g(0.0) + g(k.support_factor());
        for i in 1..n {
            s += if i % 2 == 1 { 4.0 } else { 2.0 } * g(i as f64 * dq);
        }
        s * dq / 3.0 * k.sigma_2d() * 2.0 * std::f64::consts::PI
    }

    #[test]
    fn kernels_are_normalised_with_the_sph_solvers_second_moments() {
        // the same values as sonoflow-sph's kernel tests (sph-validation.md V0.2)
        for (k, m2) in [(SphKernel::QuarticSpline, 0.79939), (SphKernel::WendlandC2, 5.0 / 9.0)] {
            assert!((moment(k, 1) - 1.0).abs() < 1e-12, "{k:?}");
            assert!((moment(k, 3) - m2).abs() < 1e-5, "{k:?}: {}", moment(k, 3));
            assert_eq!(k.shape(k.support_factor()), 0.0);
            // W(r, h) scales as 1/h²
            assert!((k.w(0.3e-3, 0.5e-3) * 0.25e-6 - k.shape(0.6) * k.sigma_2d()).abs() < 1e-12);
        }
    }

    /// Particles on a lattice of spacing dx jittered uniformly by ±jitter·dx, inside `keep`.
    fn cloud(
        dx: f64,
        extent: [f64; 4],
        jitter: f64,
        seed: u64,
        keep: impl Fn([f64; 2]) -> bool,
        v: impl Fn([f64; 2]) -> [f64; 2],
    ) -> (Vec<[f64; 2]>, Vec<[f64; 2]>) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let (mut pos, mut vel) = (Vec::new(), Vec::new());
        let nx = ((extent[1] - extent[0]) / dx).round() as usize;
        let ny = ((extent[3] - extent[2]) / dx).round() as usize;
        for j in 0..ny {
            for i in 0..nx {
                let x = [
                    extent[0] + (i as f64 + 0.5 + jitter * rng.gen_range(-1.0..1.0)) * dx,
                    extent[2] + (j as f64 + 0.5 + jitter * rng.gen_range(-1.0..1.0)) * dx,
                ];
                if keep(x) {
                    pos.push(x);
                    vel.push(v(x));
                }
            }
        }
        (pos, vel)
    }

    fn empty_lattice(origin: [f64; 2], h: f64, nx: usize, ny: usize) -> LatticeField {
        LatticeField::new(origin, h, nx, ny, vec![[0.0; 2]; nx * ny]).unwrap()
    }

    #[test]
    fn scatter_equals_a_naive_double_loop_over_particles_and_nodes() {
        let (pos, vel) =
            cloud(0.4e-3, [-4e-3, 4e-3, -3e-3, 3e-3], 0.3, 7, |_| true, |x| [x[1] * 100.0, (x[0] * 3e3).sin()]);
        for kernel in KINDS {
            let p = ShepardParams { kernel, h: 0.48e-3, min_fraction: 0.3 };
            let mut sh = ShepardInterpolator::new(p).unwrap();
            // a lattice that sticks out of the cloud on two sides
            let mut f = empty_lattice([-2.05e-3, -4.1e-3], 0.13e-3, 60, 70);
            let rep = sh.fill(&mut f, &pos, &vel).unwrap();
            assert_eq!(rep.particles, pos.len());
            let mut worst = 0.0f64;
            for j in 0..70 {
                for i in 0..60 {
                    let x = f.node_position(i, j);
                    let (mut sw, mut su, mut sv) = (0.0, 0.0, 0.0);
                    for (b, q) in pos.iter().enumerate() {
                        let w = kernel.w((x[0] - q[0]).hypot(x[1] - q[1]), p.h);
                        sw += w;
                        su += w * vel[b][0];
                        sv += w * vel[b][1];
                    }
                    let phi = rep.volume * sw;
                    assert!((sh.fraction()[j * 60 + i] - phi).abs() < 1e-12, "fraction at ({i}, {j})");
                    assert_eq!(f.node_valid(i, j), sw > 0.0 && phi >= p.min_fraction, "mask at ({i}, {j})");
                    let got = f.node_velocity(i, j).unwrap();
                    let want = if f.node_valid(i, j) { [su / sw, sv / sw] } else { [0.0, 0.0] };
                    worst = worst.max((got[0] - want[0]).abs().max((got[1] - want[1]).abs()));
                }
            }
            assert!(worst < 1e-15, "{kernel:?}: {worst}");
            // the volume of a particle of the lattice cloud is dx² (its number density 1/dx² to
            // within the kernel sum's ripple on a jittered lattice)
            assert!((rep.volume / 0.16e-6 - 1.0).abs() < 0.02, "{kernel:?}: V = {}", rep.volume);
        }
    }

    /// Solid-body rotation v = Ω e_z × (x − c): linear, so the Shepard interpolant errs only by
    /// ∇v · m₁ (first moment of the jittered neighbourhood) and eq 12 is exact on the lattice.
    #[test]
    fn solid_body_rotation_gives_the_rotation_rate_on_a_jittered_particle_lattice() {
        let (omega, c, dx) = (50.0, [1e-3, -0.5e-3], 0.2e-3);
        let v = |x: [f64; 2]| [-omega * (x[1] - c[1]), omega * (x[0] - c[0])];
        let (pos, vel) = cloud(dx, [-4e-3, 6e-3, -5e-3, 4e-3], 0.25, 11, |_| true, v);
        for kernel in KINDS {
            let h = 1.2 * dx;
            let mut sh = ShepardInterpolator::new(ShepardParams { kernel, h, min_fraction: 0.5 }).unwrap();
            let mut f = empty_lattice([-2e-3, -3e-3], 0.1e-3, 61, 51);
            let rep = sh.fill(&mut f, &pos, &vel).unwrap();
            assert_eq!(rep.valid_nodes, rep.nodes, "the lattice is deep inside the cloud");
            let (mut ev, mut ew) = (0.0f64, 0.0f64);
            for j in 0..51 {
                for i in 0..61 {
                    let g = f.node_velocity(i, j).unwrap();
                    let e = v(f.node_position(i, j));
                    ev = ev.max((g[0] - e[0]).hypot(g[1] - e[1]));
                    if i < 60 && j < 50 {
                        ew = ew.max((f.cell_omega(i, j).unwrap() - omega).abs());
                        let s = f.cell_strain(i, j).unwrap();
                        ew = ew.max(s[0].abs()).max(s[1].abs()).max(s[2].abs());
                    }
                }
            }
            // |∇v| = Ω; |m₁| ≲ jitter·dx/√(neighbours) ≈ 0.25 · 0.2 mm / √25 = 10 µm → 5e-4 m/s;
            // ω: m₁ varies over the kernel width h, so |∇m₁| ≲ 10 µm / 0.24 mm ≈ 4 % → 2 /s
            eprintln!("{kernel:?}: solid-body rotation: max |v − v_exact| = {ev:.2e} m/s (|v| up to {:.2} m/s), max |ω − Ω| (and |E|) = {ew:.3} 1/s of Ω = {omega}", omega * 4.3e-3);
            assert!(ev < 5e-4, "{kernel:?}: velocity error {ev}");
            assert!(ew < 0.04 * omega, "{kernel:?}: rotation error {ew}");
        }
        // unjittered: only the kernel sum's ripple on a regular lattice, which is symmetric, remains
        let (pos, vel) = cloud(dx, [-4e-3, 6e-3, -5e-3, 4e-3], 0.0, 11, |_| true, v);
        let mut sh = ShepardInterpolator::new(ShepardParams { kernel: SphKernel::QuarticSpline, h: 1.2 * dx, min_fraction: 0.5 })
            .unwrap();
        let mut f = empty_lattice([-2e-3, -3e-3], 0.1e-3, 61, 51);
        sh.fill(&mut f, &pos, &vel).unwrap();
        let ew = (0..50).flat_map(|j| (0..60).map(move |i| (i, j))).map(|(i, j)| (f.cell_omega(i, j).unwrap() - omega).abs()).fold(0.0, f64::max);
        assert!(ew < 1e-9 * omega, "regular lattice: {ew}");
    }

    /// Plane Poiseuille flow u = u_max (1 − y²/a²) between walls at y = ±a, fluid particles only
    /// inside: in the interior (one support away from the walls) the interpolant is the exact
    /// profile smoothed by the kernel, u + ¼ M₂ u'' = u − u_max M₂/(2a²), to within the jitter
    /// term; eq 12 gives ω = −½ u'(y) = u_max y/a² at the cell centres; nodes on the walls have
    /// φ ≈ ½, nodes outside are invalid and carry 0.
    #[test]
    fn poiseuille_profile_is_reproduced_with_the_kernels_smoothing_bias_and_the_wall_mask() {
        let (u_max, a, dx) = (0.075, 4e-3, 0.4e-3);
        let v = |x: [f64; 2]| [u_max * (1.0 - (x[1] / a).powi(2)), 0.0];
        let (pos, vel) = cloud(dx, [-12e-3, 12e-3, -a, a], 0.2, 3, |x| x[1].abs() < a, v);
        for kernel in KINDS {
            let h = 1.2 * dx;
            let m2 = moment(kernel, 3) * h * h;
            let bias = -u_max * m2 / (2.0 * a * a);
            let mut sh = ShepardInterpolator::new(ShepardParams { kernel, h, min_fraction: 0.5 }).unwrap();
            let dl = 0.1e-3;
            let mut f = empty_lattice([-4e-3, -5e-3], dl, 81, 101);
            let rep = sh.fill(&mut f, &pos, &vel).unwrap();
            let support = kernel.support_factor() * h;
            let (mut eu, mut eb, mut ev, mut ew, mut n_int) = (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0);
            let mut wall_phi = Vec::new();
            for j in 0..101 {
                for i in 0..81 {
                    let x = f.node_position(i, j);
                    let g = f.node_velocity(i, j).unwrap();
                    let phi = sh.fraction()[j * 81 + i];
                    if x[1].abs() > a + support {
                        assert!(!f.node_valid(i, j) && g == [0.0, 0.0] && phi == 0.0, "outside at y = {}", x[1]);
                    } else if x[1].abs() < a - support {
                        assert!(f.node_valid(i, j) && (phi - 1.0).abs() < 0.05, "inside at y = {}: φ = {phi}", x[1]);
                        let e = v(x)[0];
                        eu = eu.max((g[0] - e).abs());
                        eb = eb.max((g[0] - e - bias).abs());
                        ev = ev.max(g[1].abs());
                        n_int += 1;
                        if i < 80 && j < 100 && x[1] + dl < a - support {
                            let yc = x[1] + 0.5 * dl;
                            ew = ew.max((f.cell_omega(i, j).unwrap() - u_max * yc / (a * a)).abs());
                        }
                    }
                    if (x[1].abs() - a).abs() < 1e-9 {
                        wall_phi.push(phi);
                    }
                }
            }
            let w_mean = wall_phi.iter().sum::<f64>() / wall_phi.len() as f64;
            eprintln!(
                "{kernel:?}: Poiseuille ({n_int} interior nodes, V = {:.3} dx²): max |u − u_exact| = {:.3} % of u_max, \
                 max |u − (u_exact + M2 u''/4)| = {:.3} % (bias {:.3} %), max |v| = {:.3} %, max |ω − ω_exact| = {:.2} % of u_max/a, wall φ = {w_mean:.3}",
                rep.volume / (dx * dx),
                100.0 * eu / u_max,
                100.0 * eb / u_max,
                100.0 * bias / u_max,
                100.0 * ev / u_max,
                100.0 * ew / (u_max / a)
            );
            // the smoothing bias is the whole error but the jitter term (|∇u| m₁ ≲ u_max · 2/a ·
            // 0.2 dx/√25 ≈ 0.3 % of u_max at the walls' side of the interior)
            assert!(eu < bias.abs() + 0.004 * u_max, "{kernel:?}: {eu}");
            assert!(eb < 0.004 * u_max, "{kernel:?}: {eb}");
            assert!(ev < 0.004 * u_max, "{kernel:?}: {ev}");
            // ω = u_max y/a² up to u_max/a · 4e-3 · 2: differences of the jitter term over a cell
            assert!(ew < 0.02 * u_max / a, "{kernel:?}: {ew}");
            // a node on the wall sees half a neighbourhood
            assert!((w_mean - 0.5).abs() < 0.06, "{kernel:?}: wall φ {w_mean}");
        }
    }

    #[test]
    fn bad_input_is_refused_with_the_particle_named() {
        let mut sh = ShepardInterpolator::new(ShepardParams { kernel: SphKernel::QuarticSpline, h: 1e-4, min_fraction: 0.5 })
            .unwrap();
        let mut f = empty_lattice([0.0; 2], 1e-4, 3, 3);
        let e = sh.fill(&mut f, &[[0.0; 2]; 2], &[[0.0; 2]; 1]).unwrap_err().to_string();
        assert!(e.contains("2 positions but 1 velocities"), "{e}");
        let e = sh.fill(&mut f, &[[0.0; 2], [f64::NAN, 0.0]], &[[0.0; 2]; 2]).unwrap_err().to_string();
        assert!(e.contains("particle 1") && e.contains("finite"), "{e}");
        // no particle near the lattice: all invalid, volume unknown
        let rep = sh.fill(&mut f, &[[1.0, 1.0]], &[[1.0, 0.0]]).unwrap();
        assert_eq!((rep.used, rep.valid_nodes), (0, 0));
        assert!(rep.volume.is_nan());
        assert!(!f.cell_valid_at([1e-4, 1e-4]));
        for (h, mf, field) in [(0.0, 0.5, "kernel_h"), (1e-4, 0.0, "min_fraction"), (1e-4, 1.5, "min_fraction")] {
            let e = ShepardInterpolator::new(ShepardParams { kernel: SphKernel::WendlandC2, h, min_fraction: mf })
                .unwrap_err()
                .to_string();
            assert!(e.contains(&format!("`{field}`")), "{e}");
        }
    }
}
