//! Validation of the boundary-element Stokes solver against closed forms (tolerances: about 2–3×
//! the errors measured by `examples/stokes_validation.rs` at the resolution used, README table).
//! Translation of an ellipsoid is represented exactly by the edge-weighted traction basis, so
//! only quadrature error remains there (≤ 4e-7 measured); rotation and strain converge as
//! O(h²) (1.3e-3 at n_beta = 8, 3.9e-4 at 12, 1.6e-4 at 16 for the sphere).

use sonoflow_platelet::spheroid::{jeffery_factor, spheroid_resistance};
use sonoflow_platelet::{
    solve_shape, CoefficientModel, Outer, Rotational, Shape, ShapeResistance, StokesError, StokesModel, StokesOptions,
    Translational,
};
use std::f64::consts::PI;

const MU: f64 = 3e-3;
const N: usize = 12;

fn free(n_beta: usize) -> StokesOptions {
    StokesOptions { n_beta, outer: Outer::FreeSpace, viscosity: MU }
}

fn solve(shape: &Shape, o: &StokesOptions) -> ShapeResistance {
    solve_shape(shape, o).expect("valid shape and options")
}

fn rel(got: f64, exact: f64) -> f64 {
    (got - exact).abs() / exact.abs()
}

#[test]
fn sphere_drag_and_torque_in_free_space() {
    let a = 1.5e-6;
    let r = solve(&Shape::from_um(3.0, 3.0, 3.0, 1.0, 1.0), &free(N));
    let f0 = 6.0 * PI * MU * a;
    assert!(rel(r.force_per_flow[0][0], f0) < 1e-5, "{r:?}");
    assert!(rel(r.force_per_flow[1][1], f0) < 1e-5, "{r:?}");
    // measured 3.9e-4
    assert!(rel(r.rotation_torque, 8.0 * PI * MU * a.powi(3)) < 1e-3, "{r:?}");
    // a sphere feels no strain torque and no coupling: all relative to the drag scale
    assert!(r.strain_torque.abs() < 1e-3 * r.rotation_torque, "{r:?}");
    assert!(r.force_per_flow[0][1].abs() < 1e-10 * f0, "{r:?}");
    assert!(r.torque_per_flow[0].abs() < 1e-10 * f0 * a, "{r:?}");
}

fn check_spheroid(shape: Shape, axis_a: f64, eq_b: f64, along_x_is_axial: bool, tol_rot: f64, tol_b: f64) {
    let r = solve(&shape, &free(N));
    let ex = spheroid_resistance(MU, axis_a, eq_b);
    let (fx, fy) = if along_x_is_axial { (ex.axial, ex.transverse) } else { (ex.transverse, ex.axial) };
    assert!(rel(r.force_per_flow[0][0], fx) < 1e-5, "x: {} vs {fx}", r.force_per_flow[0][0]);
    assert!(rel(r.force_per_flow[1][1], fy) < 1e-5, "y: {} vs {fy}", r.force_per_flow[1][1]);
    assert!(
        rel(r.rotation_torque, ex.rotation_equatorial) < tol_rot,
        "rot: {} vs {}",
        r.rotation_torque,
        ex.rotation_equatorial
    );
    let b = jeffery_factor(0.5 * shape.lx, 0.5 * shape.ly);
    let got = r.strain_torque / r.rotation_torque;
    assert!(rel(got, b) < tol_b, "B: {got} vs {b}");
}

#[test]
fn prolate_spheroid_3_to_1() {
    // measured at n_beta = 12: rotation 4.3e-4, B 8.2e-5
    check_spheroid(Shape::from_um(3.0, 1.0, 1.0, 1.0, 1.0), 1.5e-6, 0.5e-6, true, 1e-3, 3e-4);
}

#[test]
fn oblate_spheroid_1_to_6() {
    // measured: rotation 7.5e-4, B 9.6e-5
    check_spheroid(Shape::from_um(3.0, 0.5, 3.0, 1.0, 1.0), 0.25e-6, 1.5e-6, false, 2e-3, 3e-4);
}

#[test]
fn thin_oblate_spheroid_1_to_20() {
    // measured: rotation 9.5e-4, B 4.4e-4
    check_spheroid(Shape::from_um(3.0, 0.15, 3.0, 1.0, 1.0), 0.075e-6, 1.5e-6, false, 2.5e-3, 1.2e-3);
}

#[test]
fn sphere_in_the_50_um_ball_matches_haberman_sayre() {
    let a = 1.5e-6;
    let o = StokesOptions { n_beta: N, outer: Outer::Ball { radius: 50e-6, n_beta: 12 }, viscosity: MU };
    let r = solve(&Shape::from_um(3.0, 3.0, 3.0, 1.0, 1.0), &o);
    let l: f64 = a / 50e-6;
    let k = (1.0 - l.powi(5)) / (1.0 - 2.25 * l + 2.5 * l.powi(3) - 2.25 * l.powi(5) + l.powi(6));
    let f0 = 6.0 * PI * MU * a;
    // measured 2.3e-4 with the ball at n_beta = 12; the wall effect k − 1 = 7.2 % itself to 1 %
    assert!(rel(r.force_per_flow[0][0], f0 * k) < 1e-3, "{r:?}");
    assert!(rel(r.force_per_flow[0][0] / f0 - 1.0, k - 1.0) < 1e-2, "{r:?}");
    assert!(rel(r.force_per_flow[1][1], f0 * k) < 1e-3, "{r:?}");
    let t = 8.0 * PI * MU * a.powi(3) / (1.0 - l.powi(3));
    assert!(rel(r.rotation_torque, t) < 1e-3, "{r:?}");
    // paper's T_r: the sphere's centre is the origin, so it is 2π c_r in µm²·µg/s²
    assert!(rel(r.paper_rotational_torque(), 2.0 * PI * r.rotation_torque / 1e-21) < 1e-12);
}

#[test]
fn mirror_symmetry_kills_lift_and_pitching_of_symmetric_shapes() {
    // lx ≠ lz and a concave top = bottom: symmetric in x → −x and y → −y
    let shape = Shape::from_um(3.2, 0.4, 2.7, 0.5, 0.5);
    let r = solve(&shape, &StokesOptions { n_beta: 10, ..StokesOptions::default() });
    let d0 = r.paper_drag(0.0);
    for psi in [0.0, 0.5 * PI, PI, 1.5 * PI] {
        assert!(r.paper_lift(psi).abs() < 1e-10 * d0, "lift at {psi}: {}", r.paper_lift(psi));
    }
    for psi in [0.0, 0.3, 1.0, 2.0] {
        // torque scale: drag × half-length (µm)
        assert!(r.paper_torque(psi).abs() < 1e-10 * d0 * 1.6, "pitching at {psi}: {}", r.paper_torque(psi));
    }
    // but lift at 45° is O(10 %) of the drag (eq 18 scales it by 10 sin 2ψ against 70)
    assert!(r.paper_lift(0.25 * PI) > 0.05 * d0);
}

#[test]
fn asymmetric_platelet_pitches_and_its_centre_of_mass_is_used() {
    let shape = Shape::from_um(3.0, 0.6, 3.0, 0.4, 1.6);
    let r = solve(&shape, &StokesOptions { n_beta: 10, ..StokesOptions::default() });
    assert!(r.centre_of_mass_y < 0.0);
    // the pitching torque no longer vanishes at ψ = 0 (relative to the drag × half-length)
    assert!(r.paper_torque(0.0).abs() > 1e-4 * r.paper_drag(0.0) * 1.5, "{r:?}");
    // T_r (rotation about the origin) = 2π (c_r − y_c t_x)
    let tr = 2.0 * PI * (r.rotation_torque - r.centre_of_mass_y * r.torque_per_flow[0]) / 1e-21;
    assert!(rel(r.paper_rotational_torque(), tr) < 1e-12);
}

#[test]
fn thinnest_platelet_converges() {
    // worst case of eq 7: Ly = 0.15 µm, α = 0.2 (centre 0.067 µm thick, 1:52)
    let shape = Shape::from_um(3.5, 0.15, 3.5, 0.2, 0.2);
    let a = solve(&shape, &free(12));
    let b = solve(&shape, &free(20));
    // measured against n_beta = 32: translation 7e-6 at 12, rotation 9e-4, strain 1.4e-3
    assert!(rel(a.force_per_flow[0][0], b.force_per_flow[0][0]) < 1e-4);
    assert!(rel(a.force_per_flow[1][1], b.force_per_flow[1][1]) < 1e-4);
    assert!(rel(a.rotation_torque, b.rotation_torque) < 2e-3, "{} {}", a.rotation_torque, b.rotation_torque);
    assert!(rel(a.strain_torque, b.strain_torque) < 3e-3, "{} {}", a.strain_torque, b.strain_torque);
}

#[test]
fn coefficients_are_the_linear_combinations_and_the_model_agrees() {
    let shape = Shape::from_um(2.8, 0.5, 3.1, 0.7, 1.3);
    let o = StokesOptions { n_beta: 8, ..StokesOptions::default() };
    let r = solve(&shape, &o);
    let psi = 0.7;
    let t = r.translational(psi);
    let k = r.force_per_flow;
    let (s, c) = psi.sin_cos();
    let d = k[0][0] * c * c + (k[0][1] + k[1][0]) * s * c + k[1][1] * s * s;
    assert!(rel(t.c_d, d) < 1e-12);
    assert!(rel(r.paper_drag(psi), d * 1e9) < 1e-12);
    let model = StokesModel { options: o };
    let mut out = [Translational::default()];
    model.translational(&[shape], &[psi], &mut out);
    assert_eq!(out[0], t);
    let mut rot = [Rotational::default()];
    model.rotational(&[shape], &mut rot);
    assert_eq!(rot[0], r.rotational());
    assert_eq!(model.name(), "stokes");
    // an invalid shape gives NaN, not a panic
    let mut out = [Translational::default()];
    model.translational(&[Shape { ly: -1.0, ..shape }], &[0.0], &mut out);
    assert!(out[0].c_d.is_nan());
}

#[test]
fn mean_platelet_in_the_paper_configuration_has_the_papers_magnitudes() {
    // eq 18 scales drag by 70 − 10 cos 2ψ (60 at 0, 80 at π/2) and T_r by 800: same magnitude
    let r = solve(&Shape::default(), &StokesOptions { n_beta: 10, ..StokesOptions::default() });
    assert!((50.0..70.0).contains(&r.paper_drag(0.0)), "{}", r.paper_drag(0.0));
    assert!((70.0..90.0).contains(&r.paper_drag(0.5 * PI)), "{}", r.paper_drag(0.5 * PI));
    assert!((600.0..1000.0).contains(&r.paper_rotational_torque()), "{}", r.paper_rotational_torque());
}

#[test]
fn options_are_validated_with_the_field_named() {
    let s = Shape::default();
    let bad = |o: StokesOptions| solve_shape(&s, &o).expect_err("invalid");
    let e = bad(StokesOptions { n_beta: 7, ..StokesOptions::default() });
    assert!(matches!(e, StokesError::InvalidOption { field: "n_beta", .. }), "{e}");
    assert!(e.to_string().contains("4 <= n_beta <= 64"));
    let e = bad(StokesOptions { viscosity: -1.0, ..StokesOptions::default() });
    assert!(matches!(e, StokesError::InvalidOption { field: "viscosity", .. }), "{e}");
    let e = bad(StokesOptions { outer: Outer::Ball { radius: 2e-6, n_beta: 10 }, ..StokesOptions::default() });
    assert!(matches!(e, StokesError::BallTooSmall { .. }), "{e}");
    let e = bad(StokesOptions { outer: Outer::Ball { radius: f64::NAN, n_beta: 10 }, ..StokesOptions::default() });
    assert!(matches!(e, StokesError::InvalidOption { field: "outer.radius", .. }), "{e}");
    let e = bad(StokesOptions { outer: Outer::Ball { radius: 5e-5, n_beta: 3 }, ..StokesOptions::default() });
    assert!(matches!(e, StokesError::InvalidOption { field: "outer.n_beta", .. }), "{e}");
    let e = solve_shape(&Shape { lx: 0.0, ..s }, &StokesOptions::default()).expect_err("invalid shape");
    assert!(matches!(e, StokesError::Shape(_)), "{e}");
    assert!(StokesOptions::default().validate().is_ok());
}
