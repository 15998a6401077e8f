//! Open boundaries (the paper's virtual reservoirs): a plane channel fed through an inlet reservoir
//! and drained through an outlet reservoir, steady and with flow reversal.

use sonoflow_sph::setup::OpenChannelConfig;
use sonoflow_sph::testkit::row_mean_vx;
use sonoflow_sph::womersley::profile_velocity;
use sonoflow_sph::{ParticleKind, Real, Solver, SphParams, Waveform, WaveformSpec};
use std::collections::HashSet;

const RHO0: Real = 1000.0;
const NU: Real = 4e-6;

fn channel(inflow: Waveform, developed: bool) -> (OpenChannelConfig, Solver) {
    channel_with(inflow, developed, sonoflow_sph::Integrator::PredictorCorrector)
}

fn channel_with(
    inflow: Waveform,
    developed: bool,
    integrator: sonoflow_sph::Integrator,
) -> (OpenChannelConfig, Solver) {
    // L = 2 mm, 20 across (dx = 0.1 mm), 4 mm between the openings, reservoirs 4 dx deep
    // (support 3 dx at h = 1.2 dx).
    let cfg = OpenChannelConfig::validation(inflow, developed);
    // mean 0.02 m/s (Re = 10); c from Morris' criterion with the pressure gradient 12 ν ū / L² ≈
    // 0.24 m/s² over L/δ: c ≥ 0.22 m/s; take 0.5 (Ma = 0.06).
    let params = SphParams { integrator, ..cfg.solver_params(0.5) };
    let (p, bs) = cfg.build();
    let s = Solver::new(params, p, 0.0).expect("valid").with_open_boundaries(bs).expect("valid boundaries");
    (cfg, s)
}

/// Row-binned vx over x ∈ [x0, x1] against `exact(z)`, E∞ relative to `scale`.
fn profile_error(s: &Solver, dx: Real, x0: Real, x1: Real, scale: Real, exact: impl Fn(Real) -> Real) -> Real {
    let mut e: Real = 0.0;
    for row in 1..20 {
        let z = row as Real * dx;
        let u = row_mean_vx(&s.particles, z, dx, Some((x0, x1))).unwrap_or_else(|| panic!("row {row} empty"));
        e = e.max((u - exact(z)).abs() / scale);
    }
    e
}

fn assert_ids_unique_and_particles_inside(s: &Solver, cfg: &OpenChannelConfig) {
    let p = &s.particles;
    let mut seen = HashSet::new();
    for i in 0..p.len() {
        assert!(seen.insert(p.id[i]), "id {} twice", p.id[i]);
        if !p.kind[i].is_wall() {
            assert!(p.z[i] > 0.0 && p.z[i] < cfg.width, "particle id {} at z = {} crossed a plate", p.id[i], p.z[i]);
        }
        if p.kind[i] == ParticleKind::Fluid {
            assert!(
                p.x[i] > -1e-12 && p.x[i] <= cfg.length() + 1e-12,
                "fluid id {} at x = {} in a reservoir",
                p.id[i],
                p.x[i]
            );
        }
    }
}

#[test]
fn steady_inflow_gives_the_poiseuille_profile_and_balanced_mass_flux() {
    let u_mean = 0.02;
    let (cfg, mut s) = channel(WaveformSpec::Constant { value: u_mean }.build().expect("ok"), true);
    let dx = cfg.dx();
    let a = 0.5 * cfg.width;
    let n_fluid0 = s.diagnostics().n_fluid;
    let mass0 = s.diagnostics().fluid_mass;
    let next0 = s.next_id();
    // one flow-through time L_x / ū = 0.2 s
    let t_end = 0.2;
    s.advance_to(t_end).expect("no blow-up");
    let d = s.diagnostics();
    let umax = 1.5 * u_mean;
    let e = profile_error(&s, dx, 0.25 * cfg.length(), 0.75 * cfg.length(), umax, |z| {
        1.5 * u_mean * (1.0 - ((z - a) / a).powi(2))
    });
    let (inl, outl) = (d.boundaries[0].1, d.boundaries[1].1);
    // discrete inflow mass flux: ρ₀ Σ_j u(y_j) dy t (trapezoid of the parabola over n = 20 intervals)
    let expected_in = RHO0 * u_mean * cfg.width * t_end * (1.0 - 1.0 / (20.0 * 20.0));
    eprintln!(
        "steady open channel: E_inf {:.2} % of u_max, fluid {} -> {}, mass in {:.4e} (expected {:.4e}), out {:.4e}, created {} removed {}, max |rho/rho0-1| {:.2e}, steps {}",
        100.0 * e,
        n_fluid0,
        d.n_fluid,
        inl.net_in(),
        expected_in,
        -outl.net_in(),
        inl.created,
        outl.removed,
        d.max_density_error,
        d.steps
    );
    assert!(e <= 0.03, "profile E_inf {e}");
    assert!((inl.net_in() / expected_in - 1.0).abs() < 0.01, "inflow mass {} vs {expected_in}", inl.net_in());
    assert!(
        (-outl.net_in() / inl.net_in() - 1.0).abs() < 0.02,
        "outflow {} vs inflow {}",
        -outl.net_in(),
        inl.net_in()
    );
    // mass conservation: fluid mass change = net inflow through both openings
    let net = inl.net_in() + outl.net_in();
    assert!((d.fluid_mass - mass0 - net).abs() < 1e-9 * mass0, "mass {} -> {}, net {net}", mass0, d.fluid_mass);
    assert!((d.n_fluid as Real / n_fluid0 as Real - 1.0).abs() < 0.02, "{n_fluid0} -> {}", d.n_fluid);
    assert!(inl.created > 0 && outl.removed > 0);
    assert_eq!(s.next_id(), next0 + inl.created + outl.created, "every created particle got a fresh id");
    assert_ids_unique_and_particles_inside(&s, &cfg);
    // SPH interpolation of the velocity field (ground truth on an imaging grid): a cross-section at
    // mid-length, 41 points from wall to wall.
    let xm = 0.5 * cfg.length();
    let zs: Vec<Real> = (0..=40).map(|k| k as Real / 40.0 * cfg.width).collect();
    let xs = vec![xm; zs.len()];
    let f = s.sample_velocity(&xs, &zs);
    let mut worst: Real = 0.0;
    for (k, (&z, v)) in zs.iter().zip(&f).enumerate() {
        let exact = 1.5 * u_mean * (1.0 - ((z - a) / a).powi(2));
        if (4..=36).contains(&k) {
            worst = worst.max((v[0] - exact).abs() / umax);
            assert!((v[2] - 1.0).abs() < 0.02, "fluid fraction {} at z = {z}", v[2]);
        }
        assert!(v[1].abs() < 0.02 * umax, "vz {} at z = {z}", v[1]);
    }
    eprintln!(
        "sampled profile: E_inf {:.2} % of u_max (interior), wall value {:.2e}, wall fluid fraction {:.2}",
        100.0 * worst,
        f[0][0],
        f[0][2]
    );
    assert!(worst < 0.02, "{worst}");
    assert!(f[0][0].abs() < 0.02 * umax && f[40][0].abs() < 0.02 * umax, "no slip: {} {}", f[0][0], f[40][0]);
    // the first fluid row lies one spacing from the wall (type I particles on it), so at the wall
    // itself the fluid fraction is ≈ 1/4, and 1/2 about half a spacing inside
    assert!((0.15..0.4).contains(&f[0][2]), "fluid fraction at the wall {}", f[0][2]);
}

#[test]
fn oscillating_flow_reverses_through_both_reservoirs_and_follows_womersley() {
    oscillating_flow(sonoflow_sph::Integrator::PredictorCorrector);
}

#[test]
fn oscillating_flow_with_the_single_evaluation_integrator() {
    // the carried rates follow the particles the reservoirs remove, create and convert
    oscillating_flow(sonoflow_sph::Integrator::SingleEvaluation);
}

fn oscillating_flow(integrator: sonoflow_sph::Integrator) {
    // Zero-mean oscillating flow rate, T = 0.2 s, ū amplitude 0.02 m/s (α = a √(ω/ν) = 2.8): the
    // inlet becomes an outlet half of the time (backflow through both reservoirs).
    let period = 0.2;
    let w = WaveformSpec::Cosine { amplitude: 0.02, period, phase: 0.0, offset: 0.0 }.build().expect("ok");
    let (cfg, mut s) = channel_with(w.clone(), true, integrator);
    let dx = cfg.dx();
    let a = 0.5 * cfg.width;
    let n_fluid0 = s.diagnostics().n_fluid;
    let mut worst: Real = 0.0;
    for k in 1..=8 {
        let t = 0.125 * period * k as Real + period; // second period, 8 phases
        if k == 1 {
            s.advance_to(period).expect("no blow-up");
        }
        s.advance_to(t).expect("no blow-up");
        let e = profile_error(&s, dx, 0.25 * cfg.length(), 0.75 * cfg.length(), 0.03, |z| {
            profile_velocity(&w, z - a, t, a, NU)
        });
        worst = worst.max(e);
        assert_ids_unique_and_particles_inside(&s, &cfg);
    }
    let d = s.diagnostics();
    let (inl, outl) = (d.boundaries[0].1, d.boundaries[1].1);
    eprintln!(
        "oscillating open channel ({integrator:?}): worst E_inf {:.2} % of 0.03 m/s over 8 phases, fluid {} -> {}, inlet in/out {:.3e}/{:.3e}, outlet in/out {:.3e}/{:.3e}, created {}/{}, removed {}/{}",
        100.0 * worst,
        n_fluid0,
        d.n_fluid,
        inl.mass_in,
        inl.mass_out,
        outl.mass_in,
        outl.mass_out,
        inl.created,
        outl.created,
        inl.removed,
        outl.removed
    );
    assert!(worst <= 0.03, "profile error {worst}");
    // both openings saw flow in both directions
    assert!(inl.mass_out > 0.0 && outl.mass_in > 0.0, "no backflow seen");
    assert!(inl.removed > 0 && outl.created > 0);
    assert!((d.n_fluid as Real / n_fluid0 as Real - 1.0).abs() < 0.03, "{n_fluid0} -> {}", d.n_fluid);
}

#[test]
fn a_run_continued_from_a_checkpoint_is_bit_identical_and_bad_files_are_refused() {
    let w = WaveformSpec::Cosine { amplitude: 0.02, period: 0.2, phase: 0.3, offset: 0.005 }.build().expect("ok");
    let (cfg, mut a) = channel(w, true);
    a.advance_to(0.01).expect("ok");
    let dir = std::env::temp_dir().join(format!("sonoflow-sph-ckpt-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let path = dir.join("state.ckpt");
    a.checkpoint().write(&path).expect("write");
    let temporaries: Vec<_> = std::fs::read_dir(&dir)
        .expect("list dir")
        .map(|e| e.expect("dir entry").file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".tmp"))
        .collect();
    assert!(temporaries.is_empty(), "temporary file renamed away, found {temporaries:?}");
    let ck = sonoflow_sph::Checkpoint::read(&path).expect("read");
    assert_eq!(ck.header.time, 0.01);
    let params = a.params().clone();
    let mut b = Solver::from_checkpoint(params.clone(), ck, cfg.boundaries(), &[]).expect("resume");
    a.advance_to(0.02).expect("ok");
    b.advance_to(0.02).expect("ok");
    assert_eq!(a.particles, b.particles, "continued run differs");
    assert_eq!(a.diagnostics(), b.diagnostics());
    // other boundaries → refused; truncated / corrupted / foreign files → clear errors
    let ck = sonoflow_sph::Checkpoint::read(&path).expect("read");
    let e = Solver::from_checkpoint(params, ck, cfg.boundaries()[..1].to_vec(), &[]).expect_err("mismatch");
    assert!(e.to_string().contains("open boundaries"), "{e}");
    let bytes = std::fs::read(&path).expect("read");
    let short = dir.join("short.ckpt");
    std::fs::write(&short, &bytes[..bytes.len() / 2]).expect("write");
    let e = sonoflow_sph::Checkpoint::read(&short).expect_err("truncated");
    assert!(e.to_string().contains("truncated or corrupted"), "{e}");
    let mut flipped = bytes.clone();
    flipped[bytes.len() / 3] ^= 0x40;
    let bad = dir.join("flipped.ckpt");
    std::fs::write(&bad, &flipped).expect("write");
    assert!(sonoflow_sph::Checkpoint::read(&bad).expect_err("corrupt").to_string().contains("checksum"));
    std::fs::write(&bad, b"hello world, not a checkpoint at all").expect("write");
    assert!(sonoflow_sph::Checkpoint::read(&bad).expect_err("foreign").to_string().contains("bad magic"));
    let e = sonoflow_sph::Checkpoint::read(&dir.join("missing.ckpt")).expect_err("missing");
    assert!(e.to_string().contains("missing.ckpt"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}
