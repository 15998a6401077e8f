//! Stiff and extreme cases (sph-validation.md §e), each with a stated outcome: sound speed 10× and
//! 40× the flow speed, very low viscosity, abrupt flow reversal with and without background
//! pressure, a hydrostatic tank at rest, wall crossing, impulsive starts and injected NaNs.

use std::sync::Arc;

use sonoflow_sph::setup::{ChannelConfig, OpenChannelConfig};
use sonoflow_sph::womersley::profile_velocity;
use sonoflow_sph::{
    BlowUpCriterion, Domain, DtCriterion, ParticleKind, Particles, Period, Real, Solver, SphError, SphParams, Waveform,
    WaveformSpec,
};
use std::f64::consts::PI;

const RHO0: Real = 1000.0;
const NU: Real = 4e-6;

fn open_channel(inflow: Waveform, c: Real, background_pressure: Real, developed: bool) -> (OpenChannelConfig, Solver) {
    let cfg = OpenChannelConfig::validation(inflow, developed);
    let params = SphParams { background_pressure, ..cfg.solver_params(c) };
    let (p, bs) = cfg.build();
    let s = Solver::new(params, p, 0.0).expect("valid").with_open_boundaries(bs).expect("valid");
    (cfg, s)
}

fn mid_profile(s: &Solver, cfg: &OpenChannelConfig) -> Vec<Real> {
    cfg.mid_profile(&s.particles)
}

#[test]
fn sound_speed_10x_and_40x_the_flow_speed_give_the_same_flow_and_dt_scales_as_1_over_c() {
    // Steady open channel, ū = 0.02 m/s, u_max = 0.03 m/s: c = 0.3 (10×) and 1.2 m/s (40×).
    // Outcome: both profiles within 3 % of Poiseuille (measured 1.7 % and 0.09 %: the weak
    // compressibility error falls with Ma², 1 % density variation at 10×), within 2.5 % of u_max of
    // each other; the acoustic CFL binds and dt(10×)/dt(40×) = (1.2 + u)/(0.3 + u) within 2 %.
    let w = WaveformSpec::Constant { value: 0.02 }.build().expect("ok");
    let mut profiles = vec![];
    let mut errors = vec![];
    let mut dts = vec![];
    for c in [0.3, 1.2] {
        let (cfg, mut s) = open_channel(w.clone(), c, 0.0, true);
        s.advance_to(0.05).expect("no blow-up");
        let rep = s.step(None).expect("step");
        assert_eq!(rep.binding, DtCriterion::Cfl);
        dts.push((rep.dt, s.diagnostics().max_speed));
        let prof = mid_profile(&s, &cfg);
        let a = 0.5 * cfg.width;
        let e = prof
            .iter()
            .enumerate()
            .map(|(k, u)| {
                let z = (k + 1) as Real * cfg.dx();
                (u - 0.03 * (1.0 - ((z - a) / a).powi(2))).abs() / 0.03
            })
            .fold(0.0, Real::max);
        eprintln!(
            "c = {c}: profile E_inf {:.2} %, dt {:.3e} s, max |rho/rho0-1| {:.2e}",
            100.0 * e,
            rep.dt,
            rep.max_density_error
        );
        assert!(e <= 0.03, "c = {c}: {e}");
        profiles.push(prof);
        errors.push(e);
    }
    let diff = profiles[0].iter().zip(&profiles[1]).map(|(a, b)| (a - b).abs()).fold(0.0, Real::max) / 0.03;
    let expect = (1.2 + dts[1].1) / (0.3 + dts[0].1);
    let ratio = dts[0].0 / dts[1].0;
    eprintln!(
        "10x vs 40x: profiles differ by {:.2} % of u_max; dt ratio {ratio:.3} (expected {expect:.3})",
        100.0 * diff
    );
    assert!(diff <= 0.025, "{diff}");
    assert!(errors[1] < errors[0], "the error must fall as c rises: {errors:?}");
    assert!((ratio / expect - 1.0).abs() <= 0.02, "{ratio} vs {expect}");
}

fn taylor_green(n: usize, re: Real, shifting: Real) -> Solver {
    let (p, params) = sonoflow_sph::setup::taylor_green(n, re, 10.0, shifting);
    Solver::new(params, p, 0.0).expect("valid")
}

#[test]
fn very_low_viscosity_re_1000_runs_without_blow_up_and_clumping_is_measured() {
    // Taylor–Green at Re = 1000, 40², to t = 0.5. Outcome: the paper's scheme (no shifting) clumps
    // — the smallest pair distance falls below 0.35 dx — or stops with a clear blow-up error (never a
    // NaN; measured: density error above 0.1 at t = 0.20 s, pairs at 0.37 dx); with shifting (A = 4)
    // it runs through, the smallest pair distance stays ≥ 0.5 dx (measured 0.57) and E/E₀ is within
    // 5 % of the exact e^{−16π²t/Re} (measured −2.3 %).
    let n = 40;
    let dx = 1.0 / n as Real;
    let mut plain = taylor_green(n, 1000.0, 0.0);
    let mut min_plain = Real::INFINITY;
    let mut outcome = String::from("ran to t = 0.5");
    for j in 1..=10 {
        match plain.advance_to(0.05 * j as Real) {
            Ok(_) => min_plain = min_plain.min(plain.diagnostics().min_pair_distance / dx),
            Err(e @ SphError::BlowUp { .. }) => {
                outcome = e.to_string();
                break;
            }
            Err(e) => panic!("unexpected error {e}"),
        }
    }
    eprintln!("Re 1000 without shifting: {outcome}; smallest pair distance {min_plain:.3} dx");
    assert!(min_plain < 0.35 || outcome.starts_with("blow-up"), "{min_plain} {outcome}");

    let mut shifted = taylor_green(n, 1000.0, 4.0);
    let e0 = shifted.diagnostics().kinetic_energy;
    let mut min_shift = Real::INFINITY;
    for j in 1..=10 {
        shifted.advance_to(0.05 * j as Real).expect("no blow-up with shifting");
        min_shift = min_shift.min(shifted.diagnostics().min_pair_distance / dx);
    }
    let ratio = shifted.diagnostics().kinetic_energy / e0;
    let exact = (-16.0 * PI * PI * 0.5 / 1000.0).exp();
    eprintln!("Re 1000 with shifting: E/E0 {ratio:.4} (exact {exact:.4}), smallest pair distance {min_shift:.3} dx");
    assert!(min_shift >= 0.5, "{min_shift}");
    assert!((ratio / exact - 1.0).abs() <= 0.05, "{ratio} vs {exact}");
}

/// Mean velocity that reverses from +0.02 to −0.02 m/s over 20 ms around t = 0.05 s (one period of
/// 0.2 s, back up at 0.15 s), as trigonometric interpolation of 400 samples.
fn reversing() -> Waveform {
    let (period, n) = (0.2, 400);
    let edge = |t: Real, t0: Real| -> Real {
        let q = ((t - t0) / 0.02 + 0.5).clamp(0.0, 1.0);
        0.5 - 0.5 * (PI * q).cos()
    };
    let v: Vec<Real> =
        (0..n).map(|j| j as Real * period / n as Real).map(|t| 0.02 - 0.04 * (edge(t, 0.05) - edge(t, 0.15))).collect();
    WaveformSpec::Samples { period, values: v }.build().expect("valid")
}

#[test]
fn abrupt_flow_reversal_with_and_without_background_pressure() {
    // The inflow reverses within 20 ms (|dū/dt| ≈ 3 m/s²): pressure falls below the reference
    // (negative gauge pressure with the paper's p_b = 0) on the decelerating side. c = 3 m/s
    // (Morris: c² ≥ |dū/dt| L/δ, and the acoustic transit time L/c = 1.3 ms ≪ 20 ms). Outcome: both
    // runs never blow up; with p_b = 0 the flow follows the analytic channel solution (the Womersley
    // profile of the imposed mean velocity) within 3 % of the peak velocity across the reversal
    // (measured 2.0 %, smallest pair distance 0.90 dx); p_b = 2 ρ₀ c² δ (δ = 0.01) is worse here
    // (measured 19.5 % of the peak velocity, smallest pair distance 0.47 dx, `sonoflow stability`).
    let w = reversing();
    let mut report = vec![];
    let c = 3.0;
    for pb in [0.0, 2.0 * RHO0 * c * c * 0.01] {
        let (cfg, mut s) = open_channel(w.clone(), c, pb, true);
        let a = 0.5 * cfg.width;
        let (mut worst, mut pmin, mut min_pair): (Real, Real, Real) = (0.0, Real::INFINITY, Real::INFINITY);
        for j in 1..=8 {
            let t = 0.04 + 0.005 * j as Real; // 0.045 … 0.08 s: across the reversal
            s.advance_to(t).expect("no blow-up");
            let prof = mid_profile(&s, &cfg);
            for (k, u) in prof.iter().enumerate() {
                let z = (k + 1) as Real * cfg.dx();
                worst = worst.max((u - profile_velocity(&w, z - a, t, a, NU)).abs() / 0.03);
            }
            let d = s.diagnostics();
            min_pair = min_pair.min(d.min_pair_distance / cfg.dx());
            let p = &s.particles;
            for i in 0..p.len() {
                if p.kind[i] == ParticleKind::Fluid {
                    pmin = pmin.min(c * c * (p.rho[i] - RHO0));
                }
            }
        }
        eprintln!(
            "reversal, p_b = {pb:.0} Pa: worst profile error {:.2} % of 0.03 m/s, min gauge pressure (c² (rho - rho0)) {pmin:.2} Pa, smallest pair distance {min_pair:.3} dx",
            100.0 * worst
        );
        report.push((worst, pmin, min_pair));
    }
    assert!(report[0].0 <= 0.03 && report[0].2 > 0.7, "p_b = 0: {:?}", report[0]);
    assert!(report[0].1 < 0.0, "the reversal must produce negative gauge pressure: {}", report[0].1);
    assert!(report[1].0 > report[0].0, "documented: background pressure is worse here: {report:?}");
}

/// Signed distance to the walls of a box [0, w] × [0, h] (negative inside).
#[derive(Debug)]
struct BoxDomain {
    w: Real,
    h: Real,
}

impl Domain for BoxDomain {
    fn signed_distance(&self, x: Real, z: Real) -> Real {
        (-x).max(x - self.w).max(-z).max(z - self.h)
    }
}

#[test]
fn hydrostatic_tank_stays_at_rest_with_the_right_bottom_pressure() {
    // Closed 2 × 2 mm box full of fluid under gravity g = 9.81 m/s² (+z is down), 20 × 20 lattice,
    // c = 10 √(gH), initial density hydrostatic. Run 20 √(H/g). Outcome: spurious currents grow
    // to 1.6 % of √(gH) around t ≈ 8 √(H/g) and then decay (kinetic energy at the end 5–7 % of its
    // peak, final largest speed 0.3–0.6 % of √(gH): f64 reference / fast f32 pair terms); the pressure of the deepest fluid row is
    // ρ₀ g z within 2 % (measured 0.17 %); no particle leaves the box (the guard never fires).
    let (hgt, n, g) = (2e-3, 20usize, 9.81);
    let dx = hgt / n as Real;
    let c = 10.0 * (g * hgt).sqrt();
    let mut p = Particles::default();
    let mut id = 0u64;
    let lay = 3i64;
    let nn = n as i64;
    for j in -lay..=nn + lay {
        for i in -lay..=nn + lay {
            let (x, z) = (i as Real * dx, j as Real * dx);
            let inside = (1..nn).contains(&i) && (1..nn).contains(&j);
            let on = !inside && (0..=nn).contains(&i) && (0..=nn).contains(&j);
            let kind = if inside {
                ParticleKind::Fluid
            } else if on {
                ParticleKind::WallOn
            } else {
                ParticleKind::WallOutside
            };
            // hydrostatic: p = ρ₀ g z (free level at z = 0, the lid), ρ = ρ₀ + p/c²
            let rho = RHO0 + RHO0 * g * z.clamp(0.0, hgt) / (c * c);
            p.push(x, z, 0.0, 0.0, rho, RHO0 * dx * dx, kind, id);
            id += 1;
        }
    }
    let params =
        SphParams { h: 1.2 * dx, rho0: RHO0, c, mu: 1e-3, body_force: [0.0, g], dt_max: 1.0, ..Default::default() };
    let mut s = Solver::new(params, p, 0.0).expect("valid").with_domain(Arc::new(BoxDomain { w: hgt, h: hgt }));
    let t_end = 20.0 * (hgt / g).sqrt();
    let (mut vmax, mut ke_peak): (Real, Real) = (0.0, 0.0);
    for j in 1..=10 {
        s.advance_to(t_end * j as Real / 10.0).expect("no blow-up");
        let d = s.diagnostics();
        vmax = vmax.max(d.max_speed);
        ke_peak = ke_peak.max(d.kinetic_energy);
    }
    let d = s.diagnostics();
    let pt = &s.particles;
    let zb = (nn - 1) as Real * dx;
    let (mut sum, mut cnt) = (0.0, 0);
    for i in 0..pt.len() {
        if pt.kind[i] == ParticleKind::Fluid && (pt.z[i] - zb).abs() < 0.5 * dx {
            sum += c * c * (pt.rho[i] - RHO0);
            cnt += 1;
        }
        if pt.kind[i] == ParticleKind::Fluid {
            assert!(pt.x[i] > 0.0 && pt.x[i] < hgt && pt.z[i] > 0.0 && pt.z[i] < hgt, "id {} left the box", pt.id[i]);
        }
    }
    let p_bottom = sum / cnt as Real;
    let expect = RHO0 * g * zb;
    let u_ref = (g * hgt).sqrt();
    eprintln!(
        "hydrostatic: peak speed {:.3} % of sqrt(gH), final {:.3} %, final KE {:.3} of its peak, bottom-row pressure {p_bottom:.3} Pa vs {expect:.3} Pa, guard corrections {}",
        100.0 * vmax / u_ref,
        100.0 * d.max_speed / u_ref,
        d.kinetic_energy / ke_peak,
        d.guard_corrections
    );
    assert!(vmax <= 0.03 * u_ref, "{vmax}");
    assert!(d.max_speed <= 1e-2 * u_ref, "final speed {}", d.max_speed);
    assert!(d.kinetic_energy <= 0.2 * ke_peak, "kinetic energy must decay: {} of peak {ke_peak}", d.kinetic_energy);
    assert!((p_bottom / expect - 1.0).abs() <= 0.02, "{p_bottom} vs {expect}");
    assert_eq!(d.guard_corrections, 0);
}

#[test]
fn the_guard_puts_back_a_particle_pushed_through_a_wall_and_counts_it() {
    // A fluid particle placed outside the channel (as a too-large step would): the guard (every 4th
    // step) moves it back half a spacing inside and removes its outward velocity.
    let cfg =
        ChannelConfig { width: 1e-3, n_across: 10, n_along: 12, wall_layers: 3, rho0: RHO0, top_wall_velocity: 0.0 };
    let dx = cfg.dx();
    let mut p = cfg.build();
    let i = (0..p.len()).find(|&i| p.kind[i] == ParticleKind::Fluid).expect("fluid");
    p.z[i] = -0.3 * dx;
    p.vz[i] = -1e-4;
    let id = p.id[i];
    let params = SphParams {
        h: 1.2 * dx,
        rho0: RHO0,
        c: 1e-2,
        mu: 1e-3,
        periodic_x: Some(Period { min: 0.0, length: cfg.length() }),
        dt_max: 1.0,
        ..Default::default()
    };
    let mut s = Solver::new(params, p, 0.0).expect("valid").with_domain(Arc::new(BoxDomain { w: 1.0, h: 1e-3 }));
    // the guard runs every 4th step
    for _ in 0..4 {
        s.step(None).expect("step");
    }
    let j = s.particles.id.iter().position(|&k| k == id).expect("still there");
    assert!(s.particles.z[j] > 0.0, "put back inside: z = {}", s.particles.z[j]);
    assert!(s.particles.vz[j] >= 0.0);
    assert_eq!(s.diagnostics().guard_corrections, 1);
}

#[test]
fn impulsive_start_with_too_small_c_stops_with_a_clear_error_and_with_morris_c_runs() {
    // Fluid at rest, reservoirs imposing 0.02 m/s oscillating at 20 Hz from t = 0 (|dū/dt| = 2.5 m/s²):
    // Morris' criterion c² ≥ |a| L/δ asks for c ≥ 1 m/s. Outcome: with c = 0.3 the density error
    // passes the limit and the run stops naming the time, the particle and the criterion; with
    // c = 1.2 it runs through.
    let w = WaveformSpec::Cosine { amplitude: 0.02, period: 0.05, phase: 0.0, offset: 0.0 }.build().expect("ok");
    let (_, mut weak) = open_channel(w.clone(), 0.3, 0.0, false);
    let e = weak.advance_to(0.05).expect_err("must stop");
    eprintln!("impulsive start, c = 0.3: {e}");
    match &e {
        SphError::BlowUp { criterion: BlowUpCriterion::DensityError { .. }, time, .. } => assert!(*time < 0.05),
        other => panic!("unexpected {other}"),
    }
    let (_, mut ok) = open_channel(w, 1.2, 0.0, false);
    ok.advance_to(0.05).expect("runs with Morris' c");
    assert!(ok.diagnostics().max_density_error < 0.05);
}

#[test]
fn an_injected_nan_stops_the_run_naming_the_particle() {
    let cfg =
        ChannelConfig { width: 1e-3, n_across: 10, n_along: 12, wall_layers: 3, rho0: RHO0, top_wall_velocity: 0.0 };
    let params = SphParams {
        h: 1.2 * cfg.dx(),
        rho0: RHO0,
        c: 1e-2,
        mu: 1e-3,
        periodic_x: Some(Period { min: 0.0, length: cfg.length() }),
        dt_max: 1.0,
        ..Default::default()
    };
    let mut s = Solver::new(params, cfg.build(), 0.0).expect("valid");
    s.advance_to(1e-3).expect("ok");
    let i = (0..s.particles.len()).find(|&i| s.particles.kind[i] == ParticleKind::Fluid).expect("fluid");
    let id = s.particles.id[i];
    s.particles.vx[i] = Real::NAN;
    let e = s.step(None).expect_err("NaN must stop the run");
    eprintln!("{e}");
    assert!(matches!(e, SphError::BlowUp { criterion: BlowUpCriterion::NonFinite { .. }, .. }), "{e}");
    assert!(e.to_string().contains("non-finite"), "{e}");
    // the NaN spreads to neighbours through the sums; the reported particle is the first in memory
    // with a non-finite rate, which is the injected one or a neighbour of it
    if let SphError::BlowUp { particle_id, .. } = e {
        let k = s.particles.id.iter().position(|&q| q == particle_id).expect("id");
        let d = ((s.particles.x[k] - s.particles.x[i]).powi(2) + (s.particles.z[k] - s.particles.z[i]).powi(2)).sqrt();
        assert!(
            d <= s.kernel().support_radius() + 1e-12,
            "reported id {particle_id} is {d} m from the injected id {id}"
        );
    }
}
