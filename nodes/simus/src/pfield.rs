//! Per-(scatterer, sub-element) geometry of MUST's PFIELD (pymust-notes §5.3–5.6), shared by
//! the transmit and the receive path (reciprocity: one Green's function per
//! element–scatterer–frequency, paper 1 eq. 16–17).
//!
//! Each element of width W is split into M sub-elements of width W/M (M = `ceil(W/λmin)`,
//! `λmin = c/(fc(1 + bandwidth/200))`) at offsets `t_m = −W/2 + W/(2M) + m W/M` along the element:
//! `(x_e + t_m cos θ_e, z_e − t_m sin θ_e)` (θ_e, z_e = 0 on a linear array; a convex array's
//! elements are tangent to its arc, [`crate::Probe::element_positions`]). For sub-element m of
//! element e and a scatterer at (x, z), with `(dx, dz)` the vector from the sub-element:
//!
//! * `r = max(√(dx² + dz²), λ/2)` (λ = c/fc): 2-D spreading `1/√r`, clamped near the face;
//! * angle from the element's normal `θ = asin((dx + ε)/(d + ε)) − θ_e` (ε = 2^−23, MUST),
//!   obliquity `cos θ` (soft), 1 (rigid), `cos θ/(cos θ + α)` (numeric baffle), replaced by
//!   1.1921e-7 where |θ| ≥ π/2; `sin θ` and `cos θ` by the angle-difference formulas (on a linear
//!   array they are the plain ratio and its cosine, bit for bit);
//! * directivity `sinc(k W/(2M) sin θ)` at k = k(fc) (MUST default) or at every frequency;
//! * per path and frequency f: `exp(−α_Np(f) r + i 2π f r / c)`, `α_Np = att/8.69 · f[MHz] · 100` /m.
//!
//! The phasor of sub-element m is `amp · exp((−β + i 2π/c) f r)` with
//! `amp = obliquity · directivity / √r / M` (the 1/M makes the sum over m MUST's mean).
//!
//! Layout of every per-scatterer array: `[scatterer][chunk of 16 elements][sub-element][lane]`.

// Lane loops index several arrays in lockstep: plain index loops keep them vectorisable.
#![allow(clippy::needless_range_loop)]

use crate::lanes::{L, V};
use crate::math::{exp_nonpos, sinc_eps, sincos_turns};
use crate::probe::Baffle;

/// f32 machine epsilon used by PFIELD in the angle formula.
const EPS32: f64 = 1.192_092_895_507_812_5e-7;
/// `utils.eps('single')`: obliquity where |θ| ≥ π/2.
const OBLI_FLOOR: f64 = 1.1921e-7;

/// Array geometry and model constants derived once from probe, medium and options.
#[derive(Clone, Debug)]
pub(crate) struct ArrayGeom {
    /// Real elements.
    pub n_el: usize,
    /// Elements padded to a multiple of the SIMD width (padding has amplitude 0).
    pub e_pad: usize,
    /// Sub-elements per element.
    pub m: usize,
    /// Element centres, padded (padding at x = 0).
    pub xe: Vec<f64>,
    /// Element centre depths (0 on a linear array), padded.
    pub ze: Vec<f64>,
    /// cos and sin of each element's normal angle θ_e (1, 0 on a linear array), padded.
    pub cos_e: Vec<f64>,
    pub sin_e: Vec<f64>,
    /// Convex array: radius R and apothem h (behind the face: `x² + (z + h)² ≤ R²`).
    pub arc: Option<(f64, f64)>,
    /// Sub-element offsets from the element centre, `[chunk][sub-element][lane]`: x
    /// `t_m cos θ_e` and z `t_m sin(−θ_e)` (PyMUST's `xi`, `zi`).
    pub sub_x: Vec<f64>,
    pub sub_z: Vec<f64>,
    /// Element width (m).
    pub width: f64,
    /// r clamp λ/2 (m).
    pub r_min: f64,
    /// `k(fc)·(W/M)/2` (directivity at fc).
    pub kc_half_seg: f64,
    /// `(2π/c)·(W/M)/2` (directivity at any f: x = this·f·sin θ).
    pub half_seg_over_c: f64,
    /// Obliquity model.
    pub baffle: Baffle,
    /// Directivity at every frequency.
    pub ffd: bool,
    /// 1/c (s/m): the phase in turns is `f·r/c`.
    pub inv_c: f64,
    /// Attenuation in neper per (Hz·m): `att/8.69 · 1e-6 · 1e2`.
    pub beta: f64,
}

/// Geometry of one block of scatterers (padded to a multiple of the receive group size with
/// silent scatterers).
#[derive(Clone, Debug, Default)]
pub(crate) struct BlockGeom {
    /// Scatterers in this block, padding included.
    pub n_s: usize,
    /// Path length r (m), clamped.
    pub r: Vec<f64>,
    /// Amplitude without the frequency-dependent terms (0 for padding).
    pub amp: Vec<f64>,
    /// For full-frequency directivity: `|(2π/c)(W/M)/2 · sin θ|` so that the directivity is
    /// `sinc_eps(dirb · f)`; empty otherwise.
    pub dirb: Vec<f64>,
    /// Scatterer amplitude, 0 where z < 0 (not insonified, MUST) and for padding.
    pub rc: Vec<f64>,
    /// f32 steppers `E = exp((−β + 2πi/c) df r)`, one vector per (scatterer, chunk, m).
    pub e_re: Vec<V>,
    pub e_im: Vec<V>,
}

impl BlockGeom {
    /// Resizes for `n_s` scatterers (keeps the allocation).
    pub fn resize(&mut self, n_s: usize, geom: &ArrayGeom) {
        let n = n_s * geom.m * geom.e_pad;
        self.n_s = n_s;
        self.r.resize(n, 0.0);
        self.amp.resize(n, 0.0);
        self.dirb.resize(if geom.ffd { n } else { 0 }, 0.0);
        self.rc.resize(n_s, 0.0);
        self.e_re.resize(n / L, V::default());
        self.e_im.resize(n / L, V::default());
    }
}

/// The slices of one scatterer in a [`BlockGeom`].
pub(crate) struct ScattererGeom<'a> {
    pub r: &'a mut [f64],
    pub amp: &'a mut [f64],
    pub dirb: &'a mut [f64],
    pub e_re: &'a mut [V],
    pub e_im: &'a mut [V],
}

impl ArrayGeom {
    /// The geometry of `probe` in `medium`: M = `element_splitting`, else MUST's
    /// `ceil(W/λmin)` (at most 64); `ffd`: directivity at every frequency.
    pub fn new(probe: &crate::Probe, medium: &crate::Medium, element_splitting: Option<u32>, ffd: bool) -> Self {
        let (fc, c) = (probe.fc, medium.c);
        let width = probe.element_width();
        let m = match element_splitting {
            Some(m) => m as usize,
            None => {
                let lambda_min = c / (fc * (1.0 + probe.bandwidth / 200.0));
                ((width / lambda_min).ceil() as usize).clamp(1, 64)
            }
        };
        let seg = width / m as f64;
        let n_el = probe.n_elements;
        let e_pad = n_el.div_ceil(L) * L;
        let pos = probe.element_positions();
        let at = |e: usize, f: fn(&crate::probe::ElementPosition) -> f64, pad: f64| pos.get(e).map_or(pad, f);
        let xi: Vec<f64> = (0..m).map(|i| -width / 2.0 + seg / 2.0 + i as f64 * seg).collect();
        let (mut sub_x, mut sub_z) = (vec![0.0; e_pad * m], vec![0.0; e_pad * m]);
        for c in 0..e_pad / L {
            for (j, t) in xi.iter().enumerate() {
                for l in 0..L {
                    let th = at(c * L + l, |p| p.theta, 0.0);
                    sub_x[(c * m + j) * L + l] = t * th.cos();
                    sub_z[(c * m + j) * L + l] = t * (-th).sin();
                }
            }
        }
        ArrayGeom {
            n_el,
            e_pad,
            m,
            xe: (0..e_pad).map(|e| at(e, |p| p.x, 0.0)).collect(),
            ze: (0..e_pad).map(|e| at(e, |p| p.z, 0.0)).collect(),
            cos_e: (0..e_pad).map(|e| at(e, |p| p.theta.cos(), 1.0)).collect(),
            sin_e: (0..e_pad).map(|e| at(e, |p| p.theta.sin(), 0.0)).collect(),
            arc: probe.convex_radius().map(|r| (r, probe.apothem())),
            sub_x,
            sub_z,
            width,
            r_min: c / fc / 2.0,
            kc_half_seg: 2.0 * std::f64::consts::PI * fc / c * seg / 2.0,
            half_seg_over_c: 2.0 * std::f64::consts::PI / c * seg / 2.0,
            baffle: probe.baffle,
            ffd,
            inv_c: 1.0 / c,
            beta: medium.attenuation / 8.69 * 1e-6 * 1e2,
        }
    }

    /// Fills one scatterer's geometry and steppers (`df` = frequency step). `silent` scatterers
    /// (padding) get amplitude 0. Branch-free inner loops: the compiler vectorises them in the
    /// SIMD builds of [`crate::kernel::simd::Simd::setup`].
    #[inline(always)]
    pub fn scatterer(&self, x: f32, z: f32, df: f64, silent: bool, out: ScattererGeom<'_>) {
        let (x, z) = (f64::from(x), f64::from(z));
        let inv_m = if silent { 0.0 } else { 1.0 / self.m as f64 };
        // obliquity = (a1 cos + a0) / (b1 cos + b0)
        let (a1, a0, b1, b0) = match self.baffle {
            Baffle::Soft => (1.0, 0.0, 0.0, 1.0),
            Baffle::Rigid => (0.0, 1.0, 0.0, 1.0),
            Baffle::Impedance(a) => (1.0, 0.0, 1.0, a),
        };
        let (ffd, kc, hs, r_min) = (self.ffd, self.kc_half_seg, self.half_seg_over_c, self.r_min);
        let nc = self.e_pad / L;
        for c in 0..nc {
            let (xe, ze) = (&self.xe[c * L..(c + 1) * L], &self.ze[c * L..(c + 1) * L]);
            let (ce, se) = (&self.cos_e[c * L..(c + 1) * L], &self.sin_e[c * L..(c + 1) * L]);
            for m in 0..self.m {
                let base = (c * self.m + m) * L;
                let (sx, sz) = (&self.sub_x[base..base + L], &self.sub_z[base..base + L]);
                let (r, amp) = (&mut out.r[base..base + L], &mut out.amp[base..base + L]);
                let mut sin_t = [0f64; L];
                for l in 0..L {
                    let dx = (x - sx[l]) - xe[l];
                    let dz = (z - sz[l]) - ze[l];
                    let d = (dx * dx + dz * dz).sqrt();
                    let rr = d.max(r_min);
                    let s = ((dx + EPS32) / (d + EPS32)).clamp(-1.0, 1.0);
                    let cs = ((1.0 - s) * (1.0 + s)).sqrt();
                    // θ = asin(s) − θ_e; on a linear array (1, 0): exactly s and cs
                    let sin = s * ce[l] - cs * se[l];
                    let cos = cs * ce[l] + s * se[l];
                    let obli = (a1 * cos + a0) / (b1 * cos + b0);
                    let obli = if cos <= 0.0 { OBLI_FLOOR } else { obli };
                    let dir = if ffd { 1.0 } else { sinc_eps(kc * sin) };
                    let pad = if c * L + l < self.n_el { inv_m } else { 0.0 };
                    r[l] = rr;
                    amp[l] = obli * dir / rr.sqrt() * pad;
                    sin_t[l] = sin;
                }
                if ffd {
                    for l in 0..L {
                        out.dirb[base + l] = (hs * sin_t[l]).abs();
                    }
                }
                let (er, ei) = (&mut out.e_re[c * self.m + m], &mut out.e_im[c * self.m + m]);
                let mut att = [1f64; L];
                if self.beta > 0.0 {
                    for l in 0..L {
                        att[l] = exp_nonpos(-self.beta * df * r[l]);
                    }
                }
                for l in 0..L {
                    let (s, c) = sincos_turns(df * r[l] * self.inv_c);
                    er.0[l] = (att[l] * c) as f32;
                    ei.0[l] = (att[l] * s) as f32;
                }
            }
        }
    }

    /// MUST's `isOUT`: (x, z) behind the face of the array (z < 0, or inside the circle of a
    /// convex array's arc), where the field is set to 0.
    #[inline(always)]
    pub fn is_behind(&self, x: f64, z: f64) -> bool {
        crate::probe::behind_face(x, z, self.arc)
    }

    /// Offset (x, z) of sub-element `m` of element `e` from the element's centre.
    #[inline(always)]
    pub fn sub_offset(&self, e: usize, m: usize) -> (f64, f64) {
        let i = ((e / L) * self.m + m) * L + e % L;
        (self.sub_x[i], self.sub_z[i])
    }

    /// Distance components `(dx, dz)` from sub-element `m` of element `e` to (x, z), in the
    /// order of operations of [`Self::scatterer`].
    #[inline(always)]
    pub fn delta(&self, e: usize, m: usize, x: f64, z: f64) -> (f64, f64) {
        let (sx, sz) = self.sub_offset(e, m);
        ((x - sx) - self.xe[e], (z - sz) - self.ze[e])
    }

    /// Exact phasor `amp·exp((−β + 2πi/c) f r)` (without full-frequency directivity).
    #[inline(always)]
    pub fn phasor(&self, amp: f64, r: f64, f: f64) -> (f64, f64) {
        let (s, c) = sincos_turns(f * r * self.inv_c);
        let a = if self.beta > 0.0 { amp * exp_nonpos(-self.beta * f * r) } else { amp };
        (a * c, a * s)
    }
}
