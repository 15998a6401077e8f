//! Tests of seeding, exact advection, ground truth and validation.

use super::*;

/// Half an f32 ulp for any |value| < 0.0625 m (0.0625 = 2^-4, so the ulp is
/// at most 2^-4 * 2^-23 = 2^-27 and correct rounding errs by at most 2^-28).
/// All test scenes keep every coordinate below 0.0625 m.
const HALF_ULP_POS: f64 = 1.0 / (1u64 << 28) as f64;

fn pipe_params(angle_deg: f64, v_max: f64) -> AnalyticFlowParams {
    AnalyticFlowParams {
        flow: FlowKind::Poiseuille {
            center_x: 0.001,
            center_z: 0.025,
            angle_deg,
            diameter: 6.0e-3,
            v_max,
            length: 0.04,
        },
        density_per_mm2: 5.0,
        amplitude_sigma: 1.0,
        seed: 7,
        schedule: Schedule { t_start: 0.1, ..Schedule::default() },
        max_particles: 2_000_000,
        tissue: None,
        bulk: None,
    }
}

fn disk_params(omega: f64) -> AnalyticFlowParams {
    AnalyticFlowParams {
        flow: FlowKind::RotatingDisk { center_x: 0.002, center_z: 0.03, radius: 0.01, omega },
        density_per_mm2: 7.3,
        amplitude_sigma: 2.5,
        seed: 11,
        schedule: Schedule::default(),
        max_particles: 2_000_000,
        tissue: None,
        bulk: None,
    }
}

/// Axial and transverse local coordinates of an f32 particle position.
fn pipe_local(p: &AnalyticFlowParams, x: f32, z: f32) -> (f64, f64) {
    let FlowKind::Poiseuille { center_x, center_z, angle_deg, .. } = p.flow else { panic!("not a pipe") };
    let (az, ax) = angle_deg.to_radians().sin_cos();
    let (dx, dz) = (f64::from(x) - center_x, f64::from(z) - center_z);
    (dx * ax + dz * az, -dx * az + dz * ax)
}

#[test]
fn default_params_are_valid() {
    let p = AnalyticFlowParams::default();
    // 40 mm x 6 mm vessel at 10 per mm^2.
    assert_eq!(p.particle_count().expect("valid"), 2400);
    let f = AnalyticFlow::new(&p).expect("valid");
    assert_eq!(f.particles().len(), 2400);
    assert_eq!(f.time(), 0.0);
}

/// Over several steps, small and large (wrapping), every vessel particle
/// moves along the axis by exactly u(r) dt (or u(r) dt -/+ L when it left
/// through an end), keeps its transverse coordinate, and carries the field
/// velocity at its new position.
#[test]
fn poiseuille_advection_is_exact_and_periodic() {
    for &(angle, v_max) in &[(20.0, 0.5), (-35.0, -0.8), (90.0, 0.3)] {
        let p = pipe_params(angle, v_max);
        let (az, ax) = f64::to_radians(angle).sin_cos();
        let (half_d, length) = (3.0e-3, 0.04);
        let mut flow = AnalyticFlow::new(&p).expect("valid");
        let n = flow.particles().len();
        assert_eq!(n, 1200);
        let amp0 = flow.particles().amplitude.clone();
        let steps = [1e-4, 1e-4, 3.2e-3, 0.02, 0.05, 0.031];
        let mut t = flow.time();
        let mut wraps = 0usize;
        for dt in steps {
            let before = flow.particles().clone();
            t += dt;
            flow.advance_to(t).expect("forward");
            assert_eq!(flow.time(), t);
            let after = flow.particles();
            assert_eq!(after.len(), n, "count constant");
            assert_eq!(after.id, before.id);
            assert_eq!(after.amplitude, amp0, "amplitudes kept");
            // Tolerances: each f32 coordinate is within HALF_ULP_POS of the
            // exact value, so an axial/transverse displacement (2 coordinates
            // x 2 times, |ax| + |az| <= sqrt 2) errs by < 4 HALF_ULP_POS. The
            // speed is evaluated at r from rounded positions (error
            // <= 2 HALF_ULP_POS), times |du/dr| <= 4 |v_max| / D, times dt.
            let tol_d = 4.0 * HALF_ULP_POS + 4.0 * v_max.abs() / (2.0 * half_d) * 2.0 * HALF_ULP_POS * dt;
            for i in 0..n {
                let (s0, q0) = pipe_local(&p, before.x[i], before.z[i]);
                let (s1, q1) = pipe_local(&p, after.x[i], after.z[i]);
                let u = v_max * (1.0 - (q0 / half_d).powi(2));
                let d = s1 - s0;
                assert!((q1 - q0).abs() <= 4.0 * HALF_ULP_POS, "r preserved");
                let unwrapped = s0 + u * dt;
                if unwrapped.abs() < 0.5 * length - tol_d {
                    assert!((d - u * dt).abs() <= tol_d, "particle {i}: displacement {d} vs u dt {}", u * dt);
                } else {
                    // Left through an end: re-entered at the other one.
                    let k = if unwrapped > 0.0 { -1.0 } else { 1.0 };
                    let ok = (d - u * dt - k * length).abs() <= tol_d || (d - u * dt).abs() <= tol_d;
                    assert!(ok, "particle {i}: wrapped displacement {d}, u dt {}", u * dt);
                    if (d - u * dt).abs() > tol_d {
                        wraps += 1;
                    }
                }
                // Tighter check with the stored (f32) speed before the step,
                // itself the exact u(r) rounded to f32 (relative 2^-24 per
                // component, so <= 1.5 |v_max| 2^-24 along the axis): the only
                // other error is the 4 HALF_ULP_POS position rounding.
                let u_stored = f64::from(before.vx[i]) * ax + f64::from(before.vz[i]) * az;
                let tol_tight = 4.0 * HALF_ULP_POS + 2.0 * v_max.abs() * dt / (1u64 << 24) as f64;
                let d_unwrapped = if (d - u * dt).abs() > tol_d { d + length * (u * dt - d).signum() } else { d };
                assert!(
                    (d_unwrapped - u_stored * dt).abs() <= tol_tight,
                    "particle {i}: displacement {d_unwrapped} vs stored u dt {}",
                    u_stored * dt
                );
                assert!(s1.abs() <= 0.5 * length + 4.0 * HALF_ULP_POS, "stays in segment");
                // Stored velocity = field at the new position: f32 rounding
                // of v (relative 2^-24) plus the r-rounding term above.
                let u1 = v_max * (1.0 - (q1 / half_d).powi(2)).max(0.0);
                let tol_v = v_max.abs() * 1e-7 + 4.0 * v_max.abs() / (2.0 * half_d) * 2.0 * HALF_ULP_POS;
                assert!((f64::from(after.vx[i]) - u1 * ax).abs() <= tol_v);
                assert!((f64::from(after.vz[i]) - u1 * az).abs() <= tol_v);
            }
        }
        assert!(wraps > 50, "large steps must exercise the periodic wrap ({wraps})");
    }
}

/// Disk: radius preserved, unwrapped rotation angle equals omega (t - t0),
/// stored velocity is omega (-(z - zc), x - xc).
#[test]
fn disk_advection_is_exact_rotation() {
    let omega = std::f64::consts::TAU * 3.0;
    let p = disk_params(omega);
    let (cx, cz, radius) = (0.002, 0.03, 0.01);
    let mut flow = AnalyticFlow::new(&p).expect("valid");
    let n = flow.particles().len();
    let polar = |x: f32, z: f32| {
        let (dx, dz) = (f64::from(x) - cx, f64::from(z) - cz);
        (dx.hypot(dz), dz.atan2(dx))
    };
    let (rho0, mut theta_prev): (Vec<f64>, Vec<f64>) = {
        let pa = flow.particles();
        (0..n).map(|i| polar(pa.x[i], pa.z[i])).unzip()
    };
    let mut turned = vec![0.0f64; n];
    let t0 = flow.time();
    // 20 steps of 0.01 s: 0.19 rad per step (< pi, so the unwrap is
    // unambiguous), 3.77 rad in total.
    for k in 1..=20 {
        let t = t0 + 0.01 * f64::from(k);
        flow.advance_to(t).expect("forward");
        let pa = flow.particles();
        assert_eq!(pa.len(), n);
        for i in 0..n {
            let (rho, theta) = polar(pa.x[i], pa.z[i]);
            // Each rounded position errs by <= sqrt 2 HALF_ULP_POS in rho,
            // so a difference errs by <= 2.7 HALF_ULP_POS = 1.0e-8 = 1e-6 R.
            assert!((rho - rho0[i]).abs() <= 1e-6 * radius, "radius preserved, particle {i}");
            let mut step = theta - theta_prev[i];
            step -= std::f64::consts::TAU * (step / std::f64::consts::TAU).round();
            turned[i] += step;
            theta_prev[i] = theta;
            // Velocity = field at new position (f32 rounding of |v| <=
            // omega R plus omega times the position rounding).
            let (dx, dz) = (f64::from(pa.x[i]) - cx, f64::from(pa.z[i]) - cz);
            let tol_v = omega * radius * 1e-7 + omega * 2.0 * HALF_ULP_POS;
            assert!((f64::from(pa.vx[i]) + omega * dz).abs() <= tol_v);
            assert!((f64::from(pa.vz[i]) - omega * dx).abs() <= tol_v);
        }
    }
    let total = omega * (flow.time() - t0);
    let mut checked = 0;
    for i in 0..n {
        // The summed steps telescope to theta_end - theta_0 (+ 2 pi m), so
        // only two roundings matter: angle error <= 2.7 HALF_ULP_POS / rho
        // <= 5e-6 rad for rho >= 0.2 R; closer particles are skipped.
        if rho0[i] >= 0.2 * radius {
            assert!((turned[i] - total).abs() <= 1e-5, "particle {i}: {} vs {total}", turned[i]);
            checked += 1;
        }
    }
    assert!(checked > n / 2);
}

/// Count = round(density * area) (so within +-1), all inside, uniform, and
/// amplitudes N(0, sigma^2).
#[test]
fn seeding_count_inside_uniform_and_amplitudes() {
    // Disk: 7.3 per mm^2 * pi * 100 mm^2 = 2293.4.
    let p = disk_params(1.0);
    let flow = AnalyticFlow::new(&p).expect("valid");
    let pa = flow.particles();
    let n = pa.len();
    let expected = 7.3 * std::f64::consts::PI * 100.0;
    assert!((n as f64 - expected).abs() <= 1.0, "{n} vs {expected}");
    assert_eq!(pa.id, (0..n as u32).collect::<Vec<_>>());
    for v in [&pa.x, &pa.z, &pa.vx, &pa.vz, &pa.amplitude] {
        assert_eq!(v.len(), n);
    }
    let (cx, cz, r) = (0.002, 0.03, 0.01);
    let mut inner = 0usize;
    for i in 0..n {
        let rho = (f64::from(pa.x[i]) - cx).hypot(f64::from(pa.z[i]) - cz);
        // Inside up to f32 rounding of the position (2 HALF_ULP_POS).
        assert!(rho <= r + 2.0 * HALF_ULP_POS, "particle {i} outside: {rho}");
        if rho < r / 2f64.sqrt() {
            inner += 1;
        }
    }
    // Half the area lies within R / sqrt 2: binomial(n, 1/2), 4 standard
    // errors = 4 sqrt(n / 4).
    let four_se = 4.0 * (n as f64 / 4.0).sqrt();
    assert!((inner as f64 - n as f64 / 2.0).abs() <= four_se, "{inner} of {n}");

    // Amplitudes: mean within 4 sigma / sqrt n, std within 4 sigma / sqrt(2n)
    // (the normal-theory standard error of a sample standard deviation).
    let sigma = 2.5;
    let mean = pa.amplitude.iter().map(|&a| f64::from(a)).sum::<f64>() / n as f64;
    let var = pa.amplitude.iter().map(|&a| (f64::from(a) - mean).powi(2)).sum::<f64>() / (n as f64 - 1.0);
    let nf = n as f64;
    assert!(mean.abs() <= 4.0 * sigma / nf.sqrt(), "mean {mean}");
    assert!((var.sqrt() - sigma).abs() <= 4.0 * sigma / (2.0 * nf).sqrt(), "std {}", var.sqrt());

    // Vessel: 5 per mm^2 * 40 mm * 6 mm = 1200 exactly; uniform along and across.
    let p = pipe_params(20.0, 0.5);
    let flow = AnalyticFlow::new(&p).expect("valid");
    let pa = flow.particles();
    assert_eq!(pa.len(), 1200);
    let (mut ahead, mut core) = (0usize, 0usize);
    for i in 0..pa.len() {
        let (s, q) = pipe_local(&p, pa.x[i], pa.z[i]);
        assert!(s.abs() <= 0.02 + 4.0 * HALF_ULP_POS && q.abs() <= 3.0e-3 + 4.0 * HALF_ULP_POS);
        ahead += usize::from(s > 0.0);
        core += usize::from(q.abs() < 1.5e-3);
    }
    let four_se = 4.0 * (1200.0f64 / 4.0).sqrt();
    assert!((ahead as f64 - 600.0).abs() <= four_se, "{ahead}");
    assert!((core as f64 - 600.0).abs() <= four_se, "{core}");
}

#[test]
fn seeding_is_reproducible_and_seed_dependent() {
    let p = pipe_params(20.0, 0.5);
    let a = AnalyticFlow::new(&p).expect("valid");
    let b = AnalyticFlow::new(&p).expect("valid");
    assert_eq!(a.particles(), b.particles());
    let c = AnalyticFlow::new(&AnalyticFlowParams { seed: 8, ..p }).expect("valid");
    let same = (0..a.particles().len()).filter(|&i| a.particles().x[i] == c.particles().x[i]).count();
    assert!(same < 10, "another seed gives other positions ({same} equal)");
    assert_ne!(a.particles().amplitude, c.particles().amplitude);
}

/// The first scatterer seeded at t_start carries the field at its position,
/// and advancing from a later t_start works the same.
#[test]
fn seeded_at_t_start_with_field_velocity() {
    let p = pipe_params(0.0, 0.5);
    let flow = AnalyticFlow::new(&p).expect("valid");
    assert_eq!(flow.time(), 0.1);
    let pa = flow.particles();
    for i in 0..pa.len() {
        let (_, q) = pipe_local(&p, pa.x[i], pa.z[i]);
        let u = 0.5 * (1.0 - (q / 3.0e-3).powi(2));
        // angle 0: velocity purely lateral; tolerance as in the advection test.
        assert!((f64::from(pa.vx[i]) - u).abs() <= 1e-7 + 0.5 / 3.0e-3 * 4.0 * HALF_ULP_POS);
        assert_eq!(pa.vz[i], 0.0);
    }
}

/// Truth equals velocity() at the nodes; the disk mask covers about
/// pi R^2 / (dx dz) nodes.
#[test]
fn sample_truth_matches_velocity_and_disk_area() {
    let flow = AnalyticFlow::new(&disk_params(4.0)).expect("valid");
    let grid = GridSpec { nx: 130, nz: 120, x0: -0.011, z0: 0.018, dx: 2.0e-4, dz: 2.5e-4 };
    let truth = flow.sample_truth(&grid);
    let n = 130 * 120;
    assert_eq!((truth.vx.len(), truth.vz.len(), truth.mask.len()), (n, n, n));
    let mut inside = 0usize;
    for iz in 0..grid.nz {
        for ix in 0..grid.nx {
            let k = (iz * grid.nx + ix) as usize;
            let (x, z) = (grid.x0 + f64::from(ix) * grid.dx, grid.z0 + f64::from(iz) * grid.dz);
            match flow.velocity(x, z) {
                Some((vx, vz)) => {
                    assert_eq!(truth.mask[k], 1);
                    assert_eq!(truth.vx[k], vx as f32);
                    assert_eq!(truth.vz[k], vz as f32);
                    inside += 1;
                }
                None => {
                    assert_eq!((truth.mask[k], truth.vx[k], truth.vz[k]), (0, 0.0, 0.0));
                }
            }
        }
    }
    // Grid covers x in [-0.011, 0.0148], z in [0.018, 0.04775]: the whole
    // disk (x in [-0.008, 0.012], z in [0.02, 0.04]). The lattice-point count
    // differs from area / cell by less than the number of cells the boundary
    // crosses, <= perimeter / min(dx, dz).
    let r = 0.01;
    let ideal = std::f64::consts::PI * r * r / (grid.dx * grid.dz);
    let tol = std::f64::consts::TAU * r / grid.dx;
    assert!((inside as f64 - ideal).abs() <= tol, "{inside} vs {ideal}");
    assert_eq!(truth.mask.iter().map(|&m| usize::from(m)).sum::<usize>(), inside);

    // Vessel: same node-wise identity.
    let flow = AnalyticFlow::new(&pipe_params(20.0, -0.4)).expect("valid");
    let truth = flow.sample_truth(&grid);
    for iz in 0..grid.nz {
        for ix in 0..grid.nx {
            let k = (iz * grid.nx + ix) as usize;
            let (x, z) = grid.node(ix, iz);
            let (vx, vz) = flow.velocity(x, z).unwrap_or((0.0, 0.0));
            assert_eq!(truth.mask[k], u8::from(flow.velocity(x, z).is_some()));
            assert_eq!((truth.vx[k], truth.vz[k]), (vx as f32, vz as f32));
        }
    }
    assert!(truth.mask.contains(&1));
    assert!(truth.vx.iter().all(|v| v.is_finite()));
}

#[test]
fn invalid_grid_is_reported() {
    let flow = AnalyticFlow::new(&AnalyticFlowParams::default()).expect("valid");
    let good = GridSpec { nx: 4, nz: 3, x0: 0.0, z0: 0.0, dx: 1e-3, dz: 1e-3 };
    good.validate().expect("valid grid");
    let cases = [
        (GridSpec { nx: 0, ..good.clone() }, "grid.nx"),
        (GridSpec { nz: 0, ..good.clone() }, "grid.nz"),
        (GridSpec { nx: 5000, nz: 5000, ..good.clone() }, "grid.nz"),
        (GridSpec { dx: 0.0, ..good.clone() }, "grid.dx"),
        (GridSpec { dz: f64::NAN, ..good.clone() }, "grid.dz"),
        (GridSpec { x0: f64::INFINITY, ..good.clone() }, "grid.x0"),
    ];
    for (g, field) in cases {
        let err = flow.try_sample_truth(&g).expect_err(field);
        assert_eq!(err.field(), field);
        assert!(err.to_string().starts_with(field), "{err}");
        assert_eq!(flow.sample_truth(&g), Truth::default());
    }
}

#[test]
fn validation_errors_name_the_field() {
    let pipe = AnalyticFlowParams::default();
    let disk = disk_params(1.0);
    let with_flow = |base: &AnalyticFlowParams, f: &dyn Fn(&mut FlowKind)| {
        let mut p = base.clone();
        f(&mut p.flow);
        p
    };
    let set_pipe = |field: &str, v: f64| {
        with_flow(&pipe, &|k| {
            if let FlowKind::Poiseuille { center_x, center_z, angle_deg, diameter, v_max, length } = k {
                *match field {
                    "center_x" => center_x,
                    "center_z" => center_z,
                    "angle_deg" => angle_deg,
                    "diameter" => diameter,
                    "v_max" => v_max,
                    _ => length,
                } = v;
            }
        })
    };
    let set_disk = |field: &str, v: f64| {
        with_flow(&disk, &|k| {
            if let FlowKind::RotatingDisk { center_x, radius, omega, .. } = k {
                *match field {
                    "center_x" => center_x,
                    "radius" => radius,
                    _ => omega,
                } = v;
            }
        })
    };
    let cases: Vec<(AnalyticFlowParams, &str)> = vec![
        (set_pipe("diameter", -1e-3), "flow.diameter"),
        (set_pipe("diameter", 0.0), "flow.diameter"),
        (set_pipe("center_x", f64::NAN), "flow.center_x"),
        // 20 "m" deep: millimetres typed as metres.
        (set_pipe("center_z", 20.0), "flow.center_z"),
        (set_pipe("angle_deg", f64::INFINITY), "flow.angle_deg"),
        (set_pipe("v_max", f64::NEG_INFINITY), "flow.v_max"),
        (set_pipe("length", 0.0), "flow.length"),
        (set_disk("radius", 0.0), "flow.radius"),
        (set_disk("radius", -0.01), "flow.radius"),
        (set_disk("omega", f64::NAN), "flow.omega"),
        (set_disk("center_x", f64::INFINITY), "flow.center_x"),
        (AnalyticFlowParams { density_per_mm2: 0.0, ..pipe.clone() }, "density_per_mm2"),
        (AnalyticFlowParams { density_per_mm2: 2e4, ..pipe.clone() }, "density_per_mm2"),
        (AnalyticFlowParams { density_per_mm2: f64::NAN, ..pipe.clone() }, "density_per_mm2"),
        // 1e-4 per mm^2 * 240 mm^2 rounds to 0 scatterers.
        (AnalyticFlowParams { density_per_mm2: 1e-4, ..pipe.clone() }, "density_per_mm2"),
        (AnalyticFlowParams { amplitude_sigma: f64::INFINITY, ..pipe.clone() }, "amplitude_sigma"),
        (AnalyticFlowParams { amplitude_sigma: 0.0, ..pipe.clone() }, "amplitude_sigma"),
        (AnalyticFlowParams { schedule: Schedule { prf: 0.0, ..Schedule::default() }, ..pipe.clone() }, "schedule.prf"),
        (
            AnalyticFlowParams { schedule: Schedule { packet_size: 0, ..Schedule::default() }, ..pipe.clone() },
            "schedule.packet_size",
        ),
        (AnalyticFlowParams { max_particles: 2399, ..pipe.clone() }, "max_particles"),
    ];
    for (p, field) in &cases {
        let err = p.validate().expect_err(field);
        assert_eq!(err.field(), *field, "{err}");
        assert!(err.to_string().starts_with(field), "{err}");
        let err2 = AnalyticFlow::new(p).expect_err(field);
        assert_eq!(err, err2);
    }
    // The particle-limit error states the expected count.
    let err = AnalyticFlowParams { max_particles: 2399, ..pipe.clone() }.validate().expect_err("too many");
    assert!(err.to_string().contains("2400"), "{err}");
    assert!(matches!(err, ParamError::TooManyParticles { expected: 2400, .. }));
}

#[test]
fn advance_to_rejects_backwards_and_non_finite() {
    let mut flow = AnalyticFlow::new(&pipe_params(20.0, 0.5)).expect("valid");
    flow.advance_to(0.2).expect("forward");
    let snapshot = flow.particles().clone();
    flow.advance_to(0.2).expect("same time is a no-op");
    assert_eq!(flow.particles(), &snapshot);
    let err = flow.advance_to(0.15).expect_err("backwards");
    assert!(matches!(err, FlowError::TimeWentBackwards { requested, current } if requested == 0.15 && current == 0.2));
    assert!(matches!(flow.advance_to(f64::NAN), Err(FlowError::NonFiniteTime(_))));
    assert!(matches!(flow.advance_to(f64::INFINITY), Err(FlowError::NonFiniteTime(_))));
    assert_eq!(flow.time(), 0.2);
    assert_eq!(flow.particles(), &snapshot, "failed calls leave the state unchanged");
}

/// Advancing in one jump or in many steps gives the same state: positions
/// are closed-form functions of the seeding state and time.
#[test]
fn stepping_is_path_independent() {
    let p = disk_params(-5.0);
    let mut one = AnalyticFlow::new(&p).expect("valid");
    let mut many = AnalyticFlow::new(&p).expect("valid");
    let times: Vec<f64> = p.schedule.times().iter().map(|a| a.t + 0.37).collect();
    for &t in &times {
        many.advance_to(t).expect("forward");
    }
    one.advance_to(times[times.len() - 1]).expect("forward");
    assert_eq!(one.particles(), many.particles());
}

#[test]
fn params_from_toml() {
    let text = r#"
        density_per_mm2 = 4.0
        seed = 3
        [flow]
        type = "rotating-disk"
        center_x = 0.0
        center_z = 0.03
        radius = 0.008
        omega = 6.28
        [schedule]
        prf = 5000.0
        n_packets = 4
    "#;
    let p: AnalyticFlowParams = toml::from_str(text).expect("parse");
    assert_eq!(p.seed, 3);
    assert_eq!(p.schedule.packet_size, 32);
    assert_eq!(p.max_particles, 2_000_000);
    assert!(matches!(p.flow, FlowKind::RotatingDisk { radius, .. } if radius == 0.008));
    p.validate().expect("valid");
    assert!(toml::from_str::<AnalyticFlowParams>("densty_per_mm2 = 4.0").is_err());
    assert!(toml::from_str::<AnalyticFlowParams>("[flow]\ntype = \"rotating-disk\"\nradius = 0.01").is_err());
    let json = serde_json::to_string(&p).expect("serialize");
    assert_eq!(serde_json::from_str::<AnalyticFlowParams>(&json).expect("parse"), p);
}

/// Tissue: outside the lumen only, static, about density × (region − lumen) scatterers, ids
/// after the blood's, seeded; the wall layer's amplitudes carry its level; the blood is
/// unchanged by adding tissue.
#[test]
fn tissue_fills_the_region_outside_the_lumen() {
    let blood_only = AnalyticFlow::new(&pipe_params(10.0, 0.3)).unwrap();
    let t = TissueParams { region: [-0.01, 0.012, 0.015, 0.035], density_per_mm2: 4.0, ..TissueParams::default() };
    let p = AnalyticFlowParams { tissue: Some(t.clone()), ..pipe_params(10.0, 0.3) };
    let mut flow = AnalyticFlow::new(&p).unwrap();
    assert_eq!(flow.particles(), blood_only.particles(), "the blood does not depend on the tissue");
    let ts = flow.tissue().clone();
    let geom = crate::flow::Geometry::from_kind(&p.flow);
    let n_blood = flow.particles().len() as u32;
    let lumen_mm2 = (0..200 * 200)
        .filter(|k| {
            let (x, z) =
                (-0.01 + 0.022 * ((k % 200) as f64 + 0.5) / 200.0, 0.015 + 0.02 * ((k / 200) as f64 + 0.5) / 200.0);
            geom.velocity(x, z).is_some()
        })
        .count() as f64
        / 40_000.0
        * 440.0;
    let expect = 4.0 * (440.0 - lumen_mm2);
    assert!(
        (ts.len() as f64 - expect).abs() < 4.0 * expect.sqrt(),
        "{} tissue scatterers, expected ≈ {expect:.0}",
        ts.len()
    );
    assert_eq!(ts.id[0], n_blood);
    let sigma = t.sigma(p.density_per_mm2, p.amplitude_sigma);
    assert!((sigma - 100.0 * (5.0f64 / 4.0).sqrt()).abs() < 1e-9, "40 dB and the density ratio: {sigma}");
    let (mut wall, mut rest) = (Vec::new(), Vec::new());
    for i in 0..ts.len() {
        let (x, z) = (f64::from(ts.x[i]), f64::from(ts.z[i]));
        assert!(geom.velocity(x, z).is_none(), "tissue inside the lumen at ({x}, {z})");
        assert_eq!((ts.vx[i], ts.vz[i]), (0.0, 0.0));
        let a2 = f64::from(ts.amplitude[i]).powi(2);
        if geom.outside_distance(x, z) <= 0.6e-3 {
            wall.push(a2)
        } else {
            rest.push(a2)
        }
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let wall_db = 10.0 * (mean(&wall) / mean(&rest)).log10();
    assert!((wall_db - 10.0).abs() < 1.5, "wall layer {wall_db:.2} dB above the tissue ({} scatterers)", wall.len());
    flow.advance_to(0.2).unwrap();
    assert_eq!(flow.tissue(), &ts, "static");
    let again = AnalyticFlow::new(&p).unwrap();
    assert_eq!(again.tissue(), &ts, "seeded");
    let other =
        AnalyticFlow::new(&AnalyticFlowParams { tissue: Some(TissueParams { seed: 3, ..t }), ..p.clone() }).unwrap();
    assert_ne!(other.tissue().x, ts.x, "another seed moves the scatterers");
    let bad =
        AnalyticFlowParams { tissue: Some(TissueParams { tissue_to_blood_db: 99.0, ..TissueParams::default() }), ..p };
    assert!(bad.validate().unwrap_err().to_string().starts_with("tissue.tissue_to_blood_db"));
}

/// Wall pulsation: every tissue scatterer sits at its rest position + w(t)·A·e^(−d/λ)·n with
/// d and n computed here from the vessel's axis (independently of `Geometry`), to f32 rounding;
/// its velocity is the derivative; it never enters the lumen; the blood and the truth are
/// unchanged; the wire kind is "moving".
#[test]
fn wall_pulsation_follows_the_waveform() {
    let pulse = Pulsation { amplitude: 0.4e-3, period: 0.5, decay_length: 2e-3, t0: 0.05, ..Pulsation::default() };
    let t = TissueParams {
        region: [-0.01, 0.012, 0.015, 0.035],
        density_per_mm2: 2.0,
        pulsation: Some(pulse.clone()),
        ..TissueParams::default()
    };
    let p = AnalyticFlowParams { tissue: Some(t.clone()), ..pipe_params(10.0, 0.3) };
    // An analytic flow has no inflow waveform for the wall to follow: a clear error.
    let inflow = Pulsation { waveform: crate::PulsationWaveform::Inflow, ..pulse.clone() };
    let bad = AnalyticFlowParams { tissue: Some(TissueParams { pulsation: Some(inflow), ..t }), ..p.clone() };
    let e = AnalyticFlow::new(&bad).unwrap_err().to_string();
    assert!(e.contains("tissue.pulsation.waveform") && e.contains("sph-flow"), "{e}");
    let mut flow = AnalyticFlow::new(&p).unwrap();
    let mut still = AnalyticFlow::new(&AnalyticFlowParams { tissue: None, ..p.clone() }).unwrap();
    assert!(flow.tissue_moves() && !still.tissue_moves());
    // The rest positions: at t0 + k·T the waveform is 0.
    flow.advance_to(0.55).unwrap();
    let rest = flow.tissue().clone();
    let (cx, cz, th) = (0.001f64, 0.025f64, 10f64.to_radians());
    let (ax, az) = (th.cos(), th.sin());
    let grid = GridSpec { nx: 30, nz: 30, x0: -0.01, z0: 0.015, dx: 0.7e-3, dz: 0.7e-3 };
    for time in [0.6, 0.675, 0.8, 0.93] {
        flow.advance_to(time).unwrap();
        still.advance_to(time).unwrap();
        assert_eq!(flow.particles(), still.particles(), "the blood does not feel the pulsation");
        assert_eq!(flow.sample_truth(&grid), still.sample_truth(&grid), "nor does the truth");
        let phase = std::f64::consts::TAU * (time - 0.05) / 0.5;
        let (w, dw) = (0.5 * (1.0 - phase.cos()), 0.5 * std::f64::consts::TAU / 0.5 * phase.sin());
        let ts = flow.tissue();
        let mut max_shift: f64 = 0.0;
        for i in 0..ts.len() {
            let (x0, z0) = (f64::from(rest.x[i]), f64::from(rest.z[i]));
            let (s, q) = ((x0 - cx) * ax + (z0 - cz) * az, -(x0 - cx) * az + (z0 - cz) * ax);
            let reach = if s.abs() <= 0.02 { 0.4e-3 * (-(q.abs() - 3e-3) / 2e-3).exp() } else { 0.0 };
            let (nx, nz) = (-az * q.signum(), ax * q.signum());
            let (x, z) = (f64::from(ts.x[i]), f64::from(ts.z[i]));
            assert!((x - (x0 + w * reach * nx)).abs() <= 2.0 * HALF_ULP_POS, "x of {i} at t = {time}");
            assert!((z - (z0 + w * reach * nz)).abs() <= 2.0 * HALF_ULP_POS, "z of {i} at t = {time}");
            assert!((f64::from(ts.vx[i]) - dw * reach * nx).abs() <= 1e-9, "vx of {i}");
            assert!((f64::from(ts.vz[i]) - dw * reach * nz).abs() <= 1e-9, "vz of {i}");
            let q_now = -(x - cx) * az + (z - cz) * ax;
            assert!(q_now.abs() >= q.abs() - 2.0 * HALF_ULP_POS, "moved towards the lumen");
            max_shift = max_shift.max((x - x0).hypot(z - z0));
        }
        assert!(max_shift > 0.9 * 0.4e-3 * w, "the wall moves by A·w(t): {max_shift} at w = {w}");
    }
}

/// Bulk motion: blood and tissue move rigidly with the scene; blood velocities are the
/// lab-frame ones (the flow's turned, plus the rotation and translation rates); the truth follows
/// the lumen and matches the scatterers that sit at its nodes.
#[test]
fn bulk_motion_moves_the_whole_scene_rigidly() {
    let bulk =
        BulkMotion { amplitude: [1.5e-3, -0.8e-3], rotation_deg: 4.0, center: [0.0, 0.02], period: 1.0, t0: 0.1 };
    let tissue = TissueParams { region: [-0.01, 0.012, 0.015, 0.035], density_per_mm2: 1.0, ..TissueParams::default() };
    let base = AnalyticFlowParams { tissue: Some(tissue), ..pipe_params(10.0, 0.3) };
    let p = AnalyticFlowParams { bulk: Some(bulk.clone()), ..base.clone() };
    let mut flow = AnalyticFlow::new(&p).unwrap();
    let mut still = AnalyticFlow::new(&base).unwrap();
    assert!(flow.tissue_moves() && !still.tissue_moves());
    let grid = GridSpec { nx: 40, nz: 40, x0: -0.01, z0: 0.015, dx: 0.5e-3, dz: 0.5e-3 };
    for time in [0.1, 0.27, 0.4, 0.61] {
        flow.advance_to(time).unwrap();
        still.advance_to(time).unwrap();
        let r = bulk.at(time);
        let (a, b) = (flow.particles(), still.particles());
        for i in 0..a.len() {
            let [x, z, vx, vz] = r.apply(f64::from(b.x[i]), f64::from(b.z[i]), f64::from(b.vx[i]), f64::from(b.vz[i]));
            assert!((f64::from(a.x[i]) - x).abs() < 1e-8 && (f64::from(a.z[i]) - z).abs() < 1e-8, "blood {i}");
            assert!((f64::from(a.vx[i]) - vx).abs() < 1e-6 && (f64::from(a.vz[i]) - vz).abs() < 1e-6, "blood {i}");
        }
        let (a, b) = (flow.tissue(), still.tissue());
        for i in 0..a.len() {
            let [x, z, vx, vz] = r.apply(f64::from(b.x[i]), f64::from(b.z[i]), 0.0, 0.0);
            assert!((f64::from(a.x[i]) - x).abs() < 1e-8 && (f64::from(a.z[i]) - z).abs() < 1e-8, "tissue {i}");
            assert!((f64::from(a.vx[i]) - vx).abs() < 1e-9 && (f64::from(a.vz[i]) - vz).abs() < 1e-9, "tissue {i}");
        }
        // The truth is the lab-frame field: the rigid velocity field's value at a node, flow
        // turned with the scene, inside the moved lumen only.
        let truth = flow.sample_truth_at(&grid, time).unwrap();
        let still_mask = still.sample_truth(&grid).mask;
        let (mut inside, mut changed) = (0, 0);
        for iz in 0..grid.nz {
            for ix in 0..grid.nx {
                let k = (iz * grid.nx + ix) as usize;
                let (x, z) = grid.node(ix, iz);
                let (sx, sz) = r.invert(x, z);
                match flow.velocity(sx, sz) {
                    Some((u, w)) => {
                        let [_, _, u, w] = r.apply(sx, sz, u, w);
                        assert_eq!(truth.mask[k], 1);
                        assert!((f64::from(truth.vx[k]) - u).abs() < 1e-6 && (f64::from(truth.vz[k]) - w).abs() < 1e-6);
                        inside += 1;
                    }
                    None => assert_eq!(truth.mask[k], 0),
                }
                changed += usize::from(truth.mask[k] != still_mask[k]);
            }
        }
        assert!(inside > 100, "{inside} nodes in the lumen");
        if time != 0.1 {
            assert!(changed > 0, "the lumen moved at t = {time}");
        }
    }
}
