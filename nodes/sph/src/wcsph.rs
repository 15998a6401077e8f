//! Right-hand sides of the weakly compressible SPH equations (Shahriari & Garcia 2018, §2.1):
//! continuity (eq 7), equation of state (eq 8), pressure acceleration (eq 10), viscous term (eq 12,
//! or Morris et al. 1997) and body force, plus the virtual wall particles of §2.2.
//!
//! Every loop gathers over the neighbours of one particle and writes only that particle's result,
//! in the neighbour order fixed by the cell list: the results are bit-identical for any number of
//! threads.

use crate::kernel::Kernel;
use crate::neighbours::CellList;
use crate::params::{SphParams, ViscousConstant, ViscousTerm};
use crate::particles::{ParticleKind, Particles};
use crate::Real;

/// Caller-owned buffers for one right-hand-side evaluation (no allocation once warmed up).
#[derive(Clone, Debug, Default)]
pub struct Workspace {
    /// Velocity used in the interactions: fluid = own, type I = wall velocity, type II = extrapolated \[m/s\].
    pub ux: Vec<Real>,
    /// See `ux`.
    pub uz: Vec<Real>,
    /// Pressure: fluid from eq 8, walls interpolated \[Pa\].
    pub p: Vec<Real>,
    /// Density used in the interactions: fluid = own, walls from the interpolated pressure \[kg/m³\].
    pub rho: Vec<Real>,
    /// Per particle rates and sums; zero for walls.
    pub rates: Vec<Rate>,
    wall: Vec<[Real; 4]>,
}

/// Result of one right-hand-side evaluation for one particle.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Rate {
    /// Dρ/Dt \[kg/m³/s\].
    pub drho: Real,
    /// Acceleration (a_x, a_z) \[m/s²\].
    pub acc: [Real; 2],
    /// Squared distance to the nearest other particle \[m²\] (∞ without neighbours).
    pub r2min: Real,
    /// Concentration gradient ∇C = Σ V_b (1 + 0.2 (W_ab/W(Δp))⁴) ∇_a W_ab \[1/m\] (only with shifting).
    pub grad_c: [Real; 2],
    /// Velocity gradient (∂u_x/∂x, ∂u_x/∂z, ∂u_z/∂x, ∂u_z/∂z) \[1/s\] (eq 6a; only with shifting).
    pub grad_u: [Real; 4],
}

/// Constant C of the mean-value viscous term (eq 12) for `kernel` (see [`ViscousConstant`]).
/// `spacing` is the particle spacing Δp \[m\] (used by [`ViscousConstant::LatticeMoment`] only).
pub fn mean_value_constant(kernel: &Kernel, choice: ViscousConstant, spacing: Real) -> Real {
    match choice {
        ViscousConstant::SecondMoment => 4.0 / kernel.second_moment(),
        ViscousConstant::SupportRadius => 8.0 / (kernel.support_radius() * kernel.support_radius()),
        ViscousConstant::LatticeMoment => {
            let n = (kernel.support_radius() / spacing).ceil() as i64 + 1;
            let (mut m2, mut m0) = (0.0, 0.0);
            for i in -n..=n {
                for j in -n..=n {
                    let r = spacing * ((i * i + j * j) as Real).sqrt();
                    let w = kernel.w(r);
                    m2 += r * r * w;
                    m0 += w;
                }
            }
            if m2 > 0.0 {
                4.0 * m0 / m2
            } else {
                4.0 / kernel.second_moment()
            }
        }
    }
}

/// Particle spacing Δp = √(m/ρ₀) of the first non-wall particle (`h` if there is none).
pub fn particle_spacing(params: &SphParams, kernel: &Kernel, particles: &Particles) -> Real {
    particles.kind.iter().position(|k| !k.is_wall()).map_or(kernel.h, |i| (particles.mass[i] / params.rho0).sqrt())
}

/// Equation of state (eq 8) with optional background pressure: p = c²(ρ − ρ₀) + p_b.
#[inline]
pub fn pressure(params: &SphParams, rho: Real) -> Real {
    params.c * params.c * (rho - params.rho0) + params.background_pressure
}

/// The density gradient `ρ₀ g / c²` of hydrostatic balance under the body force `g` (linear
/// equation of state: `∇p = c² ∇ρ = ρ g`, ρ ≈ ρ₀), zero along a periodic axis (no pressure
/// gradient balances a force there) and without density diffusion. δ-SPH diffuses the density
/// relative to it (Fourtakas et al. 2019, "dynamic density"): `ρ_b − ρ_a − k·(r_b − r_a)`, so
/// that a fluid at rest under gravity keeps its hydrostatic density profile; Molteni &
/// Colagrossi's plain `ρ_b − ρ_a` diffuses that profile away and lets the column sink onto the
/// bottom wall (pressure gradient 74 % of ρ₀ g in the tank of `testkit::hydrostatic_tank`).
pub fn hydrostatic_density_gradient(params: &SphParams, g: [Real; 2]) -> [Real; 2] {
    if params.density_diffusion <= 0.0 {
        return [0.0, 0.0];
    }
    let k = params.rho0 / (params.c * params.c);
    [if params.periodic_x.is_some() { 0.0 } else { k * g[0] }, if params.periodic_z.is_some() { 0.0 } else { k * g[1] }]
}

#[inline]
fn map_indices<T, F>(parallel: bool, n: usize, out: &mut Vec<T>, f: F)
where
    T: Send,
    F: Fn(usize) -> T + Sync + Send,
{
    #[cfg(feature = "parallel")]
    if parallel {
        use rayon::prelude::*;
        (0..n).into_par_iter().map(f).collect_into_vec(out);
        return;
    }
    let _ = parallel;
    out.clear();
    out.extend((0..n).map(f));
}

/// Evaluates Dρ/Dt and the acceleration of every non-wall particle (fluid and reservoir) into
/// `ws.rates`, after filling the wall particles' velocity, pressure and density. `g` is the body
/// force per unit mass at the evaluation time. `cells` must have been built on the current positions
/// with radius ≥ the kernel support.
pub fn compute_rates(
    params: &SphParams,
    kernel: &Kernel,
    particles: &Particles,
    cells: &CellList,
    g: [Real; 2],
    ws: &mut Workspace,
) {
    let n = particles.len();
    let (x, z) = (&particles.x[..], &particles.z[..]);
    let kind = &particles.kind[..];
    ws.ux.clear();
    ws.ux.extend_from_slice(&particles.vx);
    ws.uz.clear();
    ws.uz.extend_from_slice(&particles.vz);
    ws.rho.clear();
    ws.rho.extend_from_slice(&particles.rho);
    ws.p.clear();
    ws.p.extend(particles.rho.iter().map(|&r| pressure(params, r)));

    // Wall particles: Shepard interpolation over the fluid (Adami et al. 2012 form of the paper's
    // type I/II conditions): p_w = (Σ p_f W + g·Σ ρ_f r_wf W) / Σ W; type II u = 2 u_wall − ũ.
    {
        let (ux, uz, p) = (&ws.ux[..], &ws.uz[..], &ws.p[..]);
        map_indices(params.parallel, n, &mut ws.wall, |w| {
            if !kind[w].is_wall() {
                return [0.0; 4];
            }
            let (mut sw, mut sux, mut suz, mut sp) = (0.0, 0.0, 0.0, 0.0);
            cells.for_each_neighbour(x[w], z[w], x, z, |b, dx, dz, r2| {
                if kind[b].is_wall() {
                    return;
                }
                let wgt = kernel.w(r2.sqrt());
                sw += wgt;
                sux += ux[b] * wgt;
                suz += uz[b] * wgt;
                sp += (p[b] + particles.rho[b] * (g[0] * dx + g[1] * dz)) * wgt;
            });
            let (vwx, vwz) = (particles.vx[w], particles.vz[w]);
            if sw > 0.0 {
                let pw = sp / sw;
                let rw = params.rho0 + (pw - params.background_pressure) / (params.c * params.c);
                match kind[w] {
                    ParticleKind::WallOutside => [2.0 * vwx - sux / sw, 2.0 * vwz - suz / sw, pw, rw],
                    _ => [vwx, vwz, pw, rw],
                }
            } else {
                [vwx, vwz, params.background_pressure, params.rho0]
            }
        });
    }
    for (i, wv) in ws.wall.iter().enumerate() {
        if kind[i].is_wall() {
            ws.ux[i] = wv[0];
            ws.uz[i] = wv[1];
            ws.p[i] = wv[2];
            ws.rho[i] = wv[3];
        }
    }

    let (ux, uz, p, rho, m) = (&ws.ux[..], &ws.uz[..], &ws.p[..], &ws.rho[..], &particles.mass[..]);
    let mean_value = params.viscous_term == ViscousTerm::MeanValue;
    let c_visc = mean_value_constant(kernel, params.viscous_constant, particle_spacing(params, kernel, particles));
    let mu = params.mu;
    let eta2 = 0.01 * kernel.h * kernel.h;
    let w0 = kernel.w(0.0);
    let delta_hc2 = 2.0 * params.density_diffusion * kernel.h * params.c;
    let diffusion = params.density_diffusion > 0.0;
    let hk = hydrostatic_density_gradient(params, g);
    let hydro = hk != [0.0, 0.0];
    let shifting = params.shifting > 0.0;
    let eps_t = params.tensile_correction;
    let tensile = eps_t > 0.0;
    map_indices(params.parallel, n, &mut ws.rates, |a| {
        if kind[a].is_wall() {
            return Rate::default();
        }
        // W at the particle spacing Δp = √(m/ρ₀), for the anti-clumping term of the shifting gradient
        let w_dp = if shifting || tensile { kernel.w((m[a] / params.rho0).sqrt()) } else { 1.0 };
        let (mut gcx, mut gcz) = (0.0, 0.0);
        let mut gu = [0.0; 4];
        let (uax, uaz, ra) = (ux[a], uz[a], rho[a]);
        let pa_term = p[a] / (ra * ra);
        let ra_art = if p[a] < 0.0 { -eps_t * pa_term } else { 0.0 };
        let (mut drho, mut apx, mut apz) = (0.0, 0.0, 0.0);
        let (mut numx, mut numz, mut den) = (0.0, 0.0, m[a] / ra * w0);
        let (mut mvx, mut mvz) = (0.0, 0.0);
        let mut r2min = Real::INFINITY;
        cells.for_each_neighbour(x[a], z[a], x, z, |b, dx, dz, r2| {
            if b == a {
                return;
            }
            r2min = r2min.min(r2);
            let r = r2.sqrt();
            let (wgt, dw) = kernel.w_dw(r);
            let f = dw / r; // ∇_a W_ab = (dx, dz) f
            let (gx, gz) = (dx * f, dz * f);
            let (dux, duz) = (uax - ux[b], uaz - uz[b]);
            let rb = rho[b];
            drho += m[b] * (dux * gx + duz * gz);
            if diffusion && !kind[b].is_wall() {
                // δ-SPH (Molteni & Colagrossi 2009): δ h c Σ 2(ρ_b − ρ_a) (r_ba·∇_a W)/r² V_b, the
                // density difference relative to hydrostatic balance ((dx, dz) = r_a − r_b)
                let d = if hydro { (rb - ra) + (hk[0] * dx + hk[1] * dz) } else { rb - ra };
                drho -= delta_hc2 * d * (dx * gx + dz * gz) / (r2 + eta2) * m[b] / rb;
            }
            if shifting {
                let vb = m[b] / rb;
                let q = wgt / w_dp;
                let q2 = q * q;
                let corr = vb * (1.0 + 0.2 * q2 * q2);
                gcx += corr * gx;
                gcz += corr * gz;
                gu[0] -= vb * dux * gx;
                gu[1] -= vb * dux * gz;
                gu[2] -= vb * duz * gx;
                gu[3] -= vb * duz * gz;
            }
            let pbt = p[b] / (rb * rb);
            let mut pt = m[b] * (pbt + pa_term);
            if tensile {
                // Monaghan (2000) artificial pressure R_ab (W_ab / W(Δp))⁴ against pairing under tension
                let rb_art = if p[b] < 0.0 { -eps_t * pbt } else { 0.0 };
                let f = wgt / w_dp;
                let f2 = f * f;
                pt += m[b] * (ra_art + rb_art) * f2 * f2;
            }
            apx -= pt * gx;
            apz -= pt * gz;
            if mean_value {
                let vb = m[b] / rb * wgt;
                numx -= dux * vb;
                numz -= duz * vb;
                den += vb;
            } else {
                let coef = m[b] * 2.0 * mu / (ra * rb) * (r * dw) / (r2 + eta2);
                mvx += coef * dux;
                mvz += coef * duz;
            }
        });
        let (avx, avz) = if mean_value {
            let s = c_visc * mu / ra / den;
            (s * numx, s * numz)
        } else {
            (mvx, mvz)
        };
        Rate { drho, acc: [apx + avx + g[0], apz + avz + g[1]], r2min, grad_c: [gcx, gcz], grad_u: gu }
    });
}
