//! Stiff and extreme cases (sph-validation.md §e), each with a stated outcome: sound speed 10× and
//! 40× the flow speed, very low viscosity, abrupt flow reversal with and without background
//! pressure, a hydrostatic tank at rest, wall crossing, impulsive starts and injected NaNs.

use sonoflow_sph::testkit::{
    advance_in_segments, distance_to_id, guard_run, hydrostatic_tank, hydrostatic_tank_tuned, hydrostatic_tank_with,
    impulsive_start, injected_nan, is_density_blow_up_before, reversal, reversal_with, reversing, steady_channel,
    taylor_green, taylor_green_decay, RHO0,
};
use sonoflow_sph::{BlowUpCriterion, DtCriterion, Real, Scheme, Solver, SphError};

#[test]
fn sound_speed_10x_and_40x_the_flow_speed_give_the_same_flow_and_dt_scales_as_1_over_c() {
    // Steady open channel, ū = 0.02 m/s, u_max = 0.03 m/s: c = 0.3 (10×) and 1.2 m/s (40×).
    // Outcome: both profiles within 3 % of Poiseuille (library defaults: measured 1.40 % and 0.41 %;
    // the paper's scheme 1.67 % and 0.09 %: the weak compressibility error falls with Ma², 1 %
    // density variation at 10×, down to the ~0.4 % of the stabilising options at 40×), within 2.5 %
    // of u_max of each other (1.56 %); the acoustic CFL binds and dt(10×)/dt(40×) =
    // (1.2 + u)/(0.3 + u) within 2 %.
    let mut profiles = vec![];
    let mut errors = vec![];
    let mut dts = vec![];
    for c in [0.3, 1.2] {
        let run = steady_channel(c, 0.05).expect("no blow-up");
        let (rep, e) = (&run.report, run.error);
        assert_eq!(rep.binding, DtCriterion::Cfl);
        dts.push((rep.dt, run.solver.diagnostics().max_speed));
        eprintln!(
            "c = {c}: profile E_inf {:.2} %, dt {:.3e} s, max |rho/rho0-1| {:.2e}",
            100.0 * e,
            rep.dt,
            rep.max_density_error
        );
        assert!(e <= 0.03, "c = {c}: {e}");
        profiles.push(run.profile);
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

#[test]
fn very_low_viscosity_re_1000_runs_without_blow_up_and_clumping_is_measured() {
    // Taylor–Green at Re = 1000, 40², to t = 0.5. Outcome: the paper's scheme (no shifting) clumps
    // — the smallest pair distance falls below 0.35 dx — or stops with a clear blow-up error (never a
    // NaN; measured: density error above 0.1 at t = 0.20 s, pairs at 0.37 dx); with shifting (A = 4)
    // it runs through, the smallest pair distance stays ≥ 0.5 dx (measured 0.57) and E/E₀ is within
    // 5 % of the exact e^{−16π²t/Re} (measured −0.6 %). The library defaults (A = 2, δ-SPH 0.1) run
    // through as well (pairs ≥ 0.5 dx, measured 0.56) but decay too fast: E/E₀ −12.6 % at t = 0.5
    // (A = 2 keeps the lattice less regular than A = 4 at Re 1000; bar 20 %).
    let n = 40;
    let dx = 1.0 / n as Real;
    let mut plain = taylor_green(n, 1000.0, 0.0).expect("valid");
    let (min_plain, err) = advance_in_segments(&mut plain, dx, 10);
    let outcome = match err {
        None => String::from("ran to t = 0.5"),
        Some(e @ SphError::BlowUp { .. }) => e.to_string(),
        Some(e) => panic!("unexpected error {e}"),
    };
    eprintln!("Re 1000 without shifting: {outcome}; smallest pair distance {min_plain:.3} dx");
    assert!(min_plain < 0.35 || outcome.starts_with("blow-up"), "{min_plain} {outcome}");

    let mut shifted = taylor_green(n, 1000.0, 4.0).expect("valid");
    let e0 = shifted.diagnostics().kinetic_energy;
    let (min_shift, err) = advance_in_segments(&mut shifted, dx, 10);
    assert!(err.is_none(), "no blow-up with shifting: {err:?}");
    let (ratio, exact) = taylor_green_decay(&shifted, e0, 0.5, 1000.0);
    eprintln!("Re 1000 with shifting: E/E0 {ratio:.4} (exact {exact:.4}), smallest pair distance {min_shift:.3} dx");
    assert!(min_shift >= 0.5, "{min_shift}");
    assert!((ratio / exact - 1.0).abs() <= 0.05, "{ratio} vs {exact}");

    let (p, params) = sonoflow_sph::setup::taylor_green(n, 1000.0, 10.0, 0.0);
    let mut defaults = Solver::new(Scheme::Stabilised.apply(params), p, 0.0).expect("valid");
    let e0 = defaults.diagnostics().kinetic_energy;
    let (min_default, err) = advance_in_segments(&mut defaults, dx, 10);
    assert!(err.is_none(), "no blow-up with the defaults: {err:?}");
    let (ratio, exact) = taylor_green_decay(&defaults, e0, 0.5, 1000.0);
    eprintln!(
        "Re 1000 with the defaults (A = 2, delta 0.1): E/E0 {ratio:.4} (exact {exact:.4}, {:+.1} %), smallest pair distance {min_default:.3} dx",
        100.0 * (ratio / exact - 1.0)
    );
    assert!(min_default >= 0.5, "{min_default}");
    assert!((ratio / exact - 1.0).abs() <= 0.2, "{ratio} vs {exact}");
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
    // These bars are for the paper's scheme; the library defaults (shifting A = 2, δ-SPH 0.1) with
    // p_b = 0 run through as well, 3.05 % of the peak velocity (δ-SPH alone 3.18 %, shifting alone
    // 1.05 %), pairs 0.79 dx; bar 4 %.
    // reversal at 0.05 s (one period of 0.2 s, back up at 0.15 s)
    let w = reversing(0.05);
    let mut report = vec![];
    let c = 3.0;
    for pb in [0.0, 2.0 * RHO0 * c * c * 0.01] {
        // 0.045 … 0.08 s: across the reversal
        let r = reversal(&w, c, pb, 0.045, 8).expect("no blow-up");
        let (worst, pmin, min_pair) = (r.worst, r.min_gauge_pressure, r.min_pair);
        eprintln!(
            "reversal, p_b = {pb:.0} Pa: worst profile error {:.2} % of 0.03 m/s, min gauge pressure (c² (rho - rho0)) {pmin:.2} Pa, smallest pair distance {min_pair:.3} dx",
            100.0 * worst
        );
        report.push((worst, pmin, min_pair));
    }
    assert!(report[0].0 <= 0.03 && report[0].2 > 0.7, "p_b = 0: {:?}", report[0]);
    assert!(report[0].1 < 0.0, "the reversal must produce negative gauge pressure: {}", report[0].1);
    assert!(report[1].0 > report[0].0, "documented: background pressure is worse here: {report:?}");

    let r = reversal_with(&w, c, 0.0, 0.045, 8, Scheme::Stabilised).expect("no blow-up with the defaults");
    eprintln!(
        "reversal with the defaults (A = 2, delta 0.1), p_b = 0: worst profile error {:.2} % of 0.03 m/s, min gauge pressure {:.2} Pa, smallest pair distance {:.3} dx",
        100.0 * r.worst,
        r.min_gauge_pressure,
        r.min_pair
    );
    assert!(r.worst <= 0.04 && r.min_pair > 0.7 && r.min_gauge_pressure < 0.0, "defaults: {r:?}");
}

#[test]
fn hydrostatic_tank_stays_at_rest_with_the_right_bottom_pressure() {
    // Closed 2 × 2 mm box full of fluid under gravity g = 9.81 m/s² (+z is down), 20 × 20 lattice,
    // c = 10 √(gH), initial density hydrostatic. Run 20 √(H/g). Outcome: spurious currents grow
    // to 1.6 % of √(gH) around t ≈ 8 √(H/g) and then decay (kinetic energy at the end 5–7 % of its
    // peak, final largest speed 0.3–0.6 % of √(gH): f64 reference / fast f32 pair terms); the pressure of the deepest fluid row is
    // ρ₀ g z within 2 % (measured −1.1 %); no particle leaves the box (the guard never fires).
    // The paper's scheme (`hydrostatic_tank`); the defaults below.
    let h = hydrostatic_tank(20.0).expect("no blow-up");
    let (vmax, u_ref, p_bottom, expect) = (h.peak_speed, h.u_ref, h.p_bottom, h.p_expected);
    eprintln!(
        "hydrostatic: peak speed {:.3} % of sqrt(gH), final {:.3} %, final KE {:.3} of its peak, bottom-row pressure {p_bottom:.3} Pa vs {expect:.3} Pa, guard corrections {}",
        100.0 * vmax / u_ref,
        100.0 * h.final_speed / u_ref,
        h.final_ke / h.peak_ke,
        h.guard_corrections
    );
    assert_eq!(h.outside, 0, "fluid particles left the box");
    assert!(vmax <= 0.03 * u_ref, "{vmax}");
    assert!(h.final_speed <= 1e-2 * u_ref, "final speed {}", h.final_speed);
    assert!(h.final_ke <= 0.2 * h.peak_ke, "kinetic energy must decay: {} of peak {}", h.final_ke, h.peak_ke);
    assert!((p_bottom / expect - 1.0).abs() <= 0.02, "{p_bottom} vs {expect}");
    // the pressure difference across the column balances gravity (measured 1.023)
    assert!((h.gradient_ratio() - 1.0).abs() <= 0.05, "gradient ratio {}", h.gradient_ratio());
    assert_eq!(h.guard_corrections, 0);
}

#[test]
fn hydrostatic_tank_with_the_defaults_stays_at_rest_and_balances_gravity_but_shifting_offsets_the_level() {
    // The same tank with the library defaults (shifting A = 2, δ-SPH 0.1). Outcome: at rest as with
    // the paper's scheme (spurious speed ≤ 3 % of √(gH), measured 1.8 %; kinetic energy decays to
    // 14 % of its peak; nothing leaves, the guard never fires); the pressure difference across
    // the column balances gravity (δ-SPH diffuses the density relative to hydrostatic balance,
    // `wcsph::hydrostatic_density_gradient`; measured 1.044 of ρ₀ g Δz; with plain Molteni–
    // Colagrossi diffusion it was 0.74 and the column sank onto the bottom wall), but the level
    // is offset: the deepest row's pressure is 20 % above ρ₀ g z (was 33 %), the same offset
    // (≈ 3.5 Pa, 0.2 % of compression) in every row, from shifting, which moves particles without
    // changing their density (README, "Defaults"). Bars: stability as above, gradient within
    // 7 %, bottom pressure within 30 % (twice today's errors fail them, as the 0.74 and 33 % before).
    let h = hydrostatic_tank_with(20.0, Scheme::Stabilised).expect("no blow-up");
    let perr = h.p_bottom / h.p_expected - 1.0;
    eprintln!(
        "hydrostatic with the defaults: peak speed {:.3} % of sqrt(gH), final KE {:.3} of its peak, bottom-row pressure {:.3} Pa vs {:.3} Pa ({:+.1} %), top row {:.3} Pa vs {:.3} Pa, gradient ratio {:.3}, guard corrections {}",
        100.0 * h.peak_speed / h.u_ref,
        h.final_ke / h.peak_ke,
        h.p_bottom,
        h.p_expected,
        100.0 * perr,
        h.p_top,
        h.p_top_expected,
        h.gradient_ratio(),
        h.guard_corrections
    );
    assert_eq!(h.outside, 0, "fluid particles left the box");
    assert_eq!(h.guard_corrections, 0);
    assert!(h.peak_speed <= 0.03 * h.u_ref, "{}", h.peak_speed);
    assert!(h.final_ke <= 0.2 * h.peak_ke, "kinetic energy must decay: {} of peak {}", h.final_ke, h.peak_ke);
    assert!((h.gradient_ratio() - 1.0).abs() <= 0.07, "gradient ratio {}", h.gradient_ratio());
    assert!(perr.abs() <= 0.3, "{} vs {}", h.p_bottom, h.p_expected);
}

#[test]
fn hydrostatic_tank_with_density_diffusion_alone_keeps_the_hydrostatic_profile() {
    // δ-SPH 0.1 without shifting: the density is diffused relative to hydrostatic balance, so the
    // profile stays (measured: bottom row −4 %, gradient ratio 1.01; with plain Molteni–Colagrossi
    // diffusion the bottom row was +9 % with a gradient ratio of 0.76). Bars: bottom within 6 %,
    // gradient within 5 %, at rest, nothing leaves.
    let h =
        hydrostatic_tank_tuned(20.0, |p| sonoflow_sph::SphParams { density_diffusion: 0.1, ..p }).expect("no blow-up");
    let perr = h.p_bottom / h.p_expected - 1.0;
    eprintln!(
        "hydrostatic, δ-SPH alone: peak speed {:.3} % of sqrt(gH), bottom-row pressure {:+.1} %, gradient ratio {:.3}",
        100.0 * h.peak_speed / h.u_ref,
        100.0 * perr,
        h.gradient_ratio()
    );
    assert_eq!(h.outside, 0, "fluid particles left the box");
    assert!(h.peak_speed <= 0.03 * h.u_ref, "{}", h.peak_speed);
    assert!((h.gradient_ratio() - 1.0).abs() <= 0.05, "gradient ratio {}", h.gradient_ratio());
    assert!(perr.abs() <= 0.06, "{} vs {}", h.p_bottom, h.p_expected);
}

#[test]
fn the_guard_puts_back_a_particle_pushed_through_a_wall_and_counts_it() {
    // A fluid particle placed outside the channel (as a too-large step would): the guard (every 4th
    // step) moves it back half a spacing inside and removes its outward velocity.
    let g = guard_run().expect("steps");
    assert!(g.z > 0.0, "put back inside: z = {}", g.z);
    assert!(g.vz >= 0.0);
    assert_eq!(g.corrections, 1);
}

#[test]
fn impulsive_start_with_too_small_c_stops_with_a_clear_error_and_with_morris_c_runs() {
    // Fluid at rest, reservoirs imposing 0.02 m/s oscillating at 20 Hz from t = 0 (|dū/dt| = 2.5 m/s²):
    // Morris' criterion c² ≥ |a| L/δ asks for c ≥ 1 m/s. Outcome: with c = 0.3 the density error
    // passes the limit and the run stops naming the time, the particle and the criterion; with
    // c = 1.2 it runs through.
    let mut weak = impulsive_start(0.3).expect("valid");
    let e = weak.advance_to(0.05).expect_err("must stop");
    eprintln!("impulsive start, c = 0.3: {e}");
    assert!(is_density_blow_up_before(&e, 0.05), "unexpected {e}");
    let mut ok = impulsive_start(1.2).expect("valid");
    ok.advance_to(0.05).expect("runs with Morris' c");
    assert!(ok.diagnostics().max_density_error < 0.05);
}

#[test]
fn an_injected_nan_stops_the_run_naming_the_particle() {
    let (mut s, i) = injected_nan().expect("runs to the injection");
    let id = s.particles.id[i];
    let e = s.step(None).expect_err("NaN must stop the run");
    eprintln!("{e}");
    assert!(matches!(e, SphError::BlowUp { criterion: BlowUpCriterion::NonFinite { .. }, .. }), "{e}");
    assert!(e.to_string().contains("non-finite"), "{e}");
    // the NaN spreads to neighbours through the sums; the reported particle is the first in memory
    // with a non-finite rate, which is the injected one or a neighbour of it
    if let SphError::BlowUp { particle_id, .. } = e {
        let d = distance_to_id(&s, i, particle_id).expect("id");
        assert!(
            d <= s.kernel().support_radius() + 1e-12,
            "reported id {particle_id} is {d} m from the injected id {id}"
        );
    }
}
