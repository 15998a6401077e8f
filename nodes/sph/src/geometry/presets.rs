//! Preset geometries: straight tube, cosine stenosis, the paper's carotid bifurcation.

use super::{Branch, BranchEnd, Diameter, VesselGeometry};
use crate::Real;

/// A straight tube of `length` and `diameter` \[m\] centred at `centre` \[m\], flow direction at
/// `angle` \[rad\] from +x towards +z: one branch `tube` from centre − L/2 (cos, sin) (inlet) to
/// centre + L/2 (cos, sin) (outlet, flow fraction 1). At angle 0 (or a multiple of π/2) the openings
/// are axis-aligned and snap to the lattice.
pub fn straight_tube(length: Real, diameter: Real, centre: [Real; 2], angle: Real) -> VesselGeometry {
    let (c, s) = (angle.cos(), angle.sin());
    let half = 0.5 * length;
    VesselGeometry {
        fillet: 0.0,
        branches: vec![Branch {
            name: "tube".into(),
            centreline: vec![
                [centre[0] - half * c, centre[1] - half * s],
                [centre[0] + half * c, centre[1] + half * s],
            ],
            diameter: Diameter::Constant(diameter),
            start: BranchEnd::Inlet,
            end: BranchEnd::Outlet { flow_fraction: 1.0 },
        }],
    }
}

/// A straight tube (as [`straight_tube`]) with a smooth cosine narrowing at mid-length:
/// D(s) = D [1 − f (1 + cos(2π (s − L/2) / w)) / 2] for |s − L/2| < w/2, D elsewhere, with
/// f = `narrowing_fraction` (diameter reduction at the throat, 0.5 = 50 %, in [0, 1)) and
/// w = `stenosis_length`. The narrowing is sampled by 32 segments; the straight parts before and
/// after it are single segments (each must be at least D/2 long: L ≥ w + D).
pub fn stenosis(
    length: Real,
    diameter: Real,
    narrowing_fraction: Real,
    stenosis_length: Real,
    centre: [Real; 2],
    angle: Real,
) -> VesselGeometry {
    let (c, s) = (angle.cos(), angle.sin());
    let n = 32;
    let mut arc = vec![0.0];
    for k in 0..=n {
        arc.push(0.5 * (length - stenosis_length) + stenosis_length * k as Real / n as Real);
    }
    arc.push(length);
    let d = |a: Real| {
        let q = (a - 0.5 * length) / stenosis_length;
        if q.abs() < 0.5 {
            diameter * (1.0 - narrowing_fraction * 0.5 * (1.0 + (2.0 * std::f64::consts::PI * q).cos()))
        } else {
            diameter
        }
    };
    let p0 = [centre[0] - 0.5 * length * c, centre[1] - 0.5 * length * s];
    VesselGeometry {
        fillet: 0.0,
        branches: vec![Branch {
            name: "stenosis".into(),
            centreline: arc.iter().map(|a| [p0[0] + a * c, p0[1] + a * s]).collect(),
            diameter: Diameter::PerPoint(arc.iter().map(|&a| d(a)).collect()),
            start: BranchEnd::Inlet,
            end: BranchEnd::Outlet { flow_fraction: 1.0 },
        }],
    }
}

/// A centre-line from `start` with initial heading `heading` \[rad\] (from +x towards +z) made of
/// pieces (length \[m\], turn \[rad\]): straight when turn = 0, otherwise a circular arc sampled by
/// chords of at most 5°. Returns the points and their arc-length positions.
fn path(start: [Real; 2], heading: Real, pieces: &[(Real, Real)]) -> (Vec<[Real; 2]>, Vec<Real>) {
    let mut pts = vec![start];
    let mut arc = vec![0.0];
    let (mut p, mut th, mut s) = (start, heading, 0.0);
    for &(len, turn) in pieces {
        let n = ((turn.abs() / 5f64.to_radians()).ceil() as usize).max(1);
        let (dl, dth) = (len / n as Real, turn / n as Real);
        for _ in 0..n {
            // chord of an arc of length dl turning by dth: length 2R sin(dth/2), direction th + dth/2
            let chord = if dth == 0.0 { dl } else { 2.0 * dl / dth * (0.5 * dth).sin() };
            let dir = th + 0.5 * dth;
            p = [p[0] + chord * dir.cos(), p[1] + chord * dir.sin()];
            th += dth;
            s += dl;
            pts.push(p);
            arc.push(s);
        }
    }
    (pts, arc)
}

/// Length of the straight piece at −25° of the internal centre-line \[mm\].
const ICA_STRAIGHT: Real = 4.58765;
/// Length of the straight piece at +25° of the external centre-line \[mm\].
const ECA_STRAIGHT: Real = 4.29188;

/// Smooth step 0 → 1 over [a, b] (cosine).
fn blend(s: Real, a: Real, b: Real) -> Real {
    if s <= a {
        0.0
    } else if s >= b {
        1.0
    } else {
        0.5 * (1.0 - (std::f64::consts::PI * (s - a) / (b - a)).cos())
    }
}

/// Blend length of the carotid preset's branch union \[m\] (see [`super::VesselGeometry::fillet`]).
pub const CAROTID_FILLET: Real = 1.0e-3;

/// The 2D carotid bifurcation of Shahriari & Garcia (2018, §2.2; diameters of Zhao et al. 2003):
/// common carotid (CCA) 8 mm, internal (ICA) 5.55 mm with a carotid bulb, external (ECA) 4.65 mm,
/// outlet split 54 % ICA / 46 % ECA. Flow from left to right; the probe is at z = 0 and images
/// x ∈ [−19, 19] mm; the flow divider (carina) apex is at x ≈ 0.2 mm, z ≈ 23.1 mm, and 19 mm of each
/// daughter branch lies in that window. Lengths are chosen so that the lumen holds ≈ 26 000 fluid
/// particles on a 0.15 mm lattice (the paper's count): 26 249 at dx = 0.15 mm, 6 476 at 0.3 mm
/// (lattice through the origin).
///
/// Every number (mm, degrees):
/// * **common** (inlet → closed): centre-line z = 22.05 from x = −40.5 (inlet, normal −x) to x = −6
///   (closed end: its rounded cap reaches x = −2), diameter 8; walls at z = 18.05 and 26.05.
/// * **internal** (closed → outlet, flow fraction 0.54): starts at (−9, 21.25) with heading 0 (its
///   upper wall then runs along the CCA's upper wall), then: 2 straight; an arc turning 25° towards
///   the probe (−z) over 6; 4.58765 straight at −25°; an arc turning back by 25° over 8; straight to
///   x = 25 (outlet, normal +x, centre z = 16.305). Arcs are sampled by chords of 5°. Diameter: 6.4
///   at the start, a cosine rise to the bulb maximum 7.0 at arc length 5, a cosine taper to 5.55 at
///   arc length 18, 5.55 beyond.
/// * **external** (closed → outlet, flow fraction 0.46): starts at (−9, 23.725) with heading 0 (its
///   lower wall runs along the CCA's lower wall), then the mirror image of the internal centre-line
///   (turning 25° away from the probe and back) with a 4.29188 straight, straight to x = 25 (outlet,
///   normal +x, centre z = 28.545). Diameter 4.65.
///
/// The three openings are axis-aligned, so their reservoirs snap to the lattice. The odd decimals
/// place the straight walls (CCA, the daughters' outlet parts) so that the first lattice row inside
/// lies 0.6–0.9 dx from them at both dx = 0.15 and 0.3 mm (lattice through the origin): there the
/// kernel sum of a fluid particle is 1.0–1.2 (a row at the worst offset, 1.5 dx, sees 0.835; see
/// [`super::VesselGeometry::build`]). The carina is the sharp corner where the internal branch's
/// lower wall meets the external branch's upper wall, past the CCA's cap; the wall between the
/// daughters is 1 mm thick 1 mm past the apex, 2 mm at 2 mm, 7 mm at x = 10. The union is blended
/// with `CAROTID_FILLET`, which rounds that corner into an apex of ≈ 0.5 mm radius (a sharp wedge
/// has too few wall particles at its tip to hold the fluid off it: particles pile up at the
/// stagnation point).
pub fn carotid_bifurcation() -> VesselGeometry {
    let mm = 1e-3;
    let deg = std::f64::consts::PI / 180.0;
    let z_axis = 22.05e-3;
    let r_cca = 4e-3;
    let x_in = -40.5e-3;
    let x_cca_end = -6e-3;
    let x_daughter = -9e-3;
    let x_out = 25e-3;
    let (d_start, d_bulb, d_ica, d_eca) = (6.4e-3, 7e-3, 5.55e-3, 4.65e-3);
    let (s_bulb, s_taper) = (5.0 * mm, 18.0 * mm);
    let turn = 25.0 * deg;

    let daughter = |z0: Real, sign: Real, straight: Real| {
        let pieces = [(2.0 * mm, 0.0), (6.0 * mm, -sign * turn), (straight, 0.0), (8.0 * mm, sign * turn)];
        let (mut pts, mut arc) = path([x_daughter, z0], 0.0, &pieces);
        let last = pts[pts.len() - 1];
        let s_last = arc[arc.len() - 1];
        arc.push(s_last + (x_out - last[0]));
        pts.push([x_out, last[1]]);
        (pts, arc)
    };
    let (ica_pts, ica_arc) = daughter(z_axis - r_cca + 0.5 * d_start, 1.0, ICA_STRAIGHT * mm);
    let (eca_pts, _) = daughter(z_axis + r_cca - 0.5 * d_eca, -1.0, ECA_STRAIGHT * mm);
    let ica_d: Vec<Real> = ica_arc
        .iter()
        .map(|&s| {
            let up = d_start + (d_bulb - d_start) * blend(s, 0.0, s_bulb);
            up + (d_ica - d_bulb) * blend(s, s_bulb, s_taper)
        })
        .collect();
    VesselGeometry {
        fillet: CAROTID_FILLET,
        branches: vec![
            Branch {
                name: "common".into(),
                centreline: vec![[x_in, z_axis], [x_cca_end, z_axis]],
                diameter: Diameter::Constant(2.0 * r_cca),
                start: BranchEnd::Inlet,
                end: BranchEnd::Closed,
            },
            Branch {
                name: "internal".into(),
                centreline: ica_pts,
                diameter: Diameter::PerPoint(ica_d),
                start: BranchEnd::Closed,
                end: BranchEnd::Outlet { flow_fraction: 0.54 },
            },
            Branch {
                name: "external".into(),
                centreline: eca_pts,
                diameter: Diameter::Constant(d_eca),
                start: BranchEnd::Closed,
                end: BranchEnd::Outlet { flow_fraction: 0.46 },
            },
        ],
    }
}
