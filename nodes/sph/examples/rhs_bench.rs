//! Right-hand-side benchmark: the reference `wcsph::compute_rates` (with its cell-list build) against
//! `fast::compute_rates`, on carotid-sized scenes at the paper's resolution (0.15 mm lattice, ±5 %
//! jitter, quartic kernel h = 1.2 dx, mean-value viscous term eq 12):
//! * `box`: a doubly periodic square of fluid;
//! * `channel`: a 6 mm channel (40 spacings across) with 4 wall rows at each plate, periodic along x.
//!
//! Pair interactions per evaluation = ordered pairs (a, b), b ≠ a, closer than the kernel support,
//! with a a fluid particle (the rate loop), plus those with a a wall particle and b not (the wall
//! interpolation). Pairs/s/core = that count / time per evaluation / threads.
//!
//! `cargo run --release -p sonoflow-sph --example rhs_bench -- [--fast-only] [--gather] [--paper] [--avx2] [--reach=K] [n_fluid...]`
//! (default 26000 fluid particles; `--fast-only` skips timing the reference, e.g. under a profiler;
//! `--reach=K`: fast grid cells per support radius, default 2; `--gather`: the fast evaluator's
//! gather pair loop (each pair twice) instead of the symmetric one; `--paper`: the paper's scheme
//! (no shifting, no δ-SPH) instead of the defaults; `--avx2`: the AVX2 build of the lanes (16
//! registers) even where AVX-512VL is available; `--scene=box` or `--scene=channel`:
//! only that scene).

use std::time::Instant;

use sonoflow_sph::fast::{self, FastWorkspace};
use sonoflow_sph::setup::ChannelConfig;
use sonoflow_sph::testkit::splitmix;
use sonoflow_sph::wcsph::{compute_rates, Workspace};
use sonoflow_sph::{CellList, Kernel, ParticleKind, Particles, Period, Real, SphParams};

const DX: Real = 0.15e-3;
const RHO0: Real = 1000.0;

/// ±5 % jitter, a flow of 0.3 m/s with ±1 % noise, densities ±0.1 %.
fn disorder(p: &mut Particles, width: Real) {
    let mut s = 1;
    for i in 0..p.len() {
        if p.kind[i].is_wall() {
            continue;
        }
        p.x[i] += 0.05 * DX * splitmix(&mut s);
        p.z[i] += 0.05 * DX * splitmix(&mut s);
        let zeta = (p.z[i] / width).clamp(0.0, 1.0);
        p.vx[i] = 0.3 * 4.0 * zeta * (1.0 - zeta) + 3e-3 * splitmix(&mut s);
        p.vz[i] = 3e-3 * splitmix(&mut s);
        p.rho[i] = RHO0 * (1.0 + 1e-3 * splitmix(&mut s));
    }
}

fn scene_box(n_fluid: usize) -> (Particles, SphParams) {
    let n = (n_fluid as Real).sqrt().round() as usize;
    let mut p = Particles::default();
    for j in 0..n {
        for i in 0..n {
            let (x, z) = ((i as Real + 0.5) * DX, (j as Real + 0.5) * DX);
            p.push(x, z, 0.0, 0.0, RHO0, RHO0 * DX * DX, ParticleKind::Fluid, (j * n + i) as u64);
        }
    }
    let l = n as Real * DX;
    disorder(&mut p, l);
    let per = Period { min: 0.0, length: l };
    for i in 0..p.len() {
        p.x[i] = per.wrap(p.x[i]);
        p.z[i] = per.wrap(p.z[i]);
    }
    let params = SphParams { h: 1.2 * DX, periodic_x: Some(per), periodic_z: Some(per), ..Default::default() };
    (p, params)
}

fn scene_channel(n_fluid: usize) -> (Particles, SphParams) {
    let cfg = ChannelConfig {
        width: 40.0 * DX,
        n_across: 40,
        n_along: (n_fluid / 39).max(12),
        wall_layers: 3,
        rho0: RHO0,
        top_wall_velocity: 0.0,
    };
    let mut p = cfg.build();
    disorder(&mut p, cfg.width);
    let per = Period { min: 0.0, length: cfg.length() };
    for i in 0..p.len() {
        if !p.kind[i].is_wall() {
            p.x[i] = per.wrap(p.x[i]);
        }
    }
    let params = SphParams { h: 1.2 * DX, periodic_x: Some(per), body_force: [1.0, 0.0], ..Default::default() };
    (p, params)
}

/// (rate-loop pairs, wall-interpolation pairs) per evaluation.
fn count_pairs(p: &Particles, params: &SphParams, k: &Kernel) -> (usize, usize) {
    let mut cells = CellList::default();
    cells.build(&p.x, &p.z, k.support_radius(), params.periodic_x, params.periodic_z);
    let (mut rate, mut wall) = (0, 0);
    for a in 0..p.len() {
        cells.for_each_neighbour(p.x[a], p.z[a], &p.x, &p.z, |b, _, _, _| {
            if b == a {
                return;
            }
            if !p.kind[a].is_wall() {
                rate += 1;
            } else if !p.kind[b].is_wall() {
                wall += 1;
            }
        });
    }
    (rate, wall)
}

/// CPU time of all threads of this process \[s\] (Linux: sum of /proc/self/task/*/schedstat), if
/// available.
fn cpu_seconds() -> Option<Real> {
    let mut ns = 0u64;
    for t in std::fs::read_dir("/proc/self/task").ok()? {
        let s = std::fs::read_to_string(t.ok()?.path().join("schedstat")).ok()?;
        ns += s.split_whitespace().next()?.parse::<u64>().ok()?;
    }
    Some(ns as Real * 1e-9)
}

/// Per call of `f`: (min, median) wall seconds and min CPU seconds (all threads) over 9 batches of
/// at least 0.15 s.
fn time(mut f: impl FnMut()) -> (Real, Real, Real) {
    f();
    let t = Instant::now();
    f();
    let once = t.elapsed().as_secs_f64().max(1e-6);
    let reps = ((0.15 / once).ceil() as usize).max(1);
    let mut cpu = Real::INFINITY;
    let mut v: Vec<Real> = (0..9)
        .map(|_| {
            let c0 = cpu_seconds();
            let t = Instant::now();
            for _ in 0..reps {
                f();
            }
            let wall = t.elapsed().as_secs_f64() / reps as Real;
            if let (Some(a), Some(b)) = (c0, cpu_seconds()) {
                cpu = cpu.min((b - a) / reps as Real);
            }
            wall
        })
        .collect();
    v.sort_by(Real::total_cmp);
    (v[0], v[v.len() / 2], cpu)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let fast_only = args.iter().any(|a| a == "--fast-only");
    let gather = args.iter().any(|a| a == "--gather");
    let paper = args.iter().any(|a| a == "--paper");
    let backend = if args.iter().any(|a| a == "--avx2") { fast::Backend::Avx2 } else { fast::Backend::Auto };
    let reach: Option<usize> = args.iter().find_map(|a| a.strip_prefix("--reach=")).map(str::parse).transpose()?;
    let only = args.iter().find_map(|a| a.strip_prefix("--scene="));
    let sizes: Vec<usize> =
        args.iter().filter(|a| !a.starts_with("--")).map(|s| s.parse()).collect::<Result<_, _>>()?;
    let sizes = if sizes.is_empty() { vec![26_000] } else { sizes };
    println!("wall: best and median of 9 batches; cpu: CPU time of all threads (robust to other load)");
    println!(
        "scene    n_fluid n_wall  pairs/eval  path       thr  wall ms/eval (min/med)  cpu ms  pairs/s/core wall   cpu     steps/s  speed-up"
    );
    for &n in &sizes {
        for (name, (p, params)) in [("box", scene_box(n)), ("channel", scene_channel(n))] {
            if only.is_some_and(|o| o != name) {
                continue;
            }
            params.validate()?;
            let k = Kernel::new(params.kernel, params.h);
            let (rp, wp) = count_pairs(&p, &params, &k);
            let pairs = (rp + wp) as Real;
            let n_wall = p.kind.iter().filter(|k| k.is_wall()).count();
            let g = params.body_force;
            let mut ref_ms = [0.0; 2];
            for (ti, threads) in [1usize, 2].into_iter().enumerate() {
                let mut prm = SphParams { parallel: threads > 1, symmetric_pairs: !gather, ..params.clone() };
                if paper {
                    (prm.shifting, prm.density_diffusion) = (0.0, 0.0);
                }
                let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
                let (mut ws, mut cells) = (Workspace::default(), CellList::default());
                let mut reference = || {
                    cells.build(&p.x, &p.z, k.support_radius(), prm.periodic_x, prm.periodic_z);
                    compute_rates(&prm, &k, &p, &cells, g, &mut ws);
                };
                let (rmin, rmed, rcpu) = if fast_only {
                    reference();
                    (Real::NAN, Real::NAN, Real::NAN)
                } else {
                    pool.install(|| time(reference))
                };
                let mut fws = reach.map_or_else(FastWorkspace::default, FastWorkspace::with_reach);
                let mut fws_ws = Workspace::default();
                let mut phases = [Real::INFINITY; 5];
                let mut best_call = Real::INFINITY;
                let (fmin, fmed, fcpu) = pool.install(|| {
                    time(|| {
                        let t = Instant::now();
                        fast::compute_rates_with(&prm, &k, &p, g, &mut fws_ws, &mut fws, backend);
                        best_call = best_call.min(t.elapsed().as_secs_f64());
                        for (m, v) in phases.iter_mut().zip(fws.phase_seconds()) {
                            *m = m.min(v);
                        }
                    })
                });
                ref_ms[ti] = rmin;
                let mut err: Real = 0.0;
                let mut scale: Real = 0.0;
                for (a, b) in ws.rates.iter().zip(&fws_ws.rates) {
                    for (x, y) in [(a.drho, b.drho), (a.acc[0], b.acc[0]), (a.acc[1], b.acc[1])] {
                        err = err.max((x - y).abs());
                        scale = scale.max(x.abs());
                    }
                }
                for (path, tmin, tmed, tcpu) in [
                    ("reference", rmin, rmed, rcpu),
                    (if gather { "fast-gathr" } else { "fast-symm" }, fmin, fmed, fcpu),
                ] {
                    println!(
                        "{name:8} {:7} {n_wall:6} {:11.0}  {path:10} {threads:3}  {:8.2} / {:8.2}      {:7.2}  {:10.3e} {:10.3e}  {:7.1}  {:5.2}",
                        p.len() - n_wall,
                        pairs,
                        1e3 * tmin,
                        1e3 * tmed,
                        1e3 * tcpu,
                        pairs / tmin / threads as Real,
                        pairs / tcpu,
                        1.0 / (2.0 * tmin),
                        ref_ms[0] / tmin,
                    );
                }
                println!(
                    "         (rate pairs {rp}, wall pairs {wp}; fast vs reference max rel. diff {:.1e})",
                    err / scale
                );
                let ph = phases.map(|v| 1e3 * v);
                println!(
                    "         fast: best single call {:.3} ms; phases, best of all calls [ms]: grid {:.3}, sort {:.3}, walls {:.3}, rates {:.3}, scatter {:.3}",
                    1e3 * best_call,
                    ph[0],
                    ph[1],
                    ph[2],
                    ph[3],
                    ph[4]
                );
            }
        }
    }
    Ok(())
}
