//! Doppler gain of the imaging chain for a rigid translation (diagnostic).
#![allow(clippy::unwrap_used)]
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sonoflow_beamform::{DasParams, DasPlan, Grid, Interpolation, Rf2Iq, Rf2IqParams, RfView, TxWave, C32};
use sonoflow_doppler::{DopplerEstimator, DopplerParams, Estimator, Packet};
use sonoflow_simus::{Medium, Probe, Scatterers, Simus, SimusOptions, Transmit};

fn arg(name: &str, def: f64) -> f64 {
    std::env::var(name).ok().and_then(|v| v.parse().ok()).unwrap_or(def)
}

fn main() {
    let vx = arg("VX", 0.3);
    let vz = arg("VZ", 0.0);
    let (sx0, sx1, sz0, sz1) = (arg("SX0", -20e-3), arg("SX1", 20e-3), arg("SZ0", 5e-3), arg("SZ1", 35e-3));
    let density = arg("DENS", 10.0); // per mm²
    let fnum = arg("FNUM", 3.0);
    let tukey = arg("TUKEY", 0.0);
    let nframes = arg("NF", 16.0) as usize;
    let seed = arg("SEED", 1.0) as u64;
    let rxdeg = arg("RX", 15.0);
    let prf = 10e3;
    let n = ((sx1 - sx0) * (sz1 - sz0) * 1e6 * density) as usize;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let x0: Vec<f64> = (0..n).map(|_| rng.gen_range(sx0..sx1)).collect();
    let z0: Vec<f64> = (0..n).map(|_| rng.gen_range(sz0..sz1)).collect();
    let a: Vec<f32> = (0..n).map(|_| rng.gen_range(-1.0f32..1.0)).collect();
    let mut probe = Probe::paper_5mhz();
    if let Ok(bw) = std::env::var("BW") {
        probe.bandwidth = bw.parse().unwrap();
    }
    let mut opts = SimusOptions::default();
    if std::env::var("NODIR").is_ok() {
        probe.width = Some(1e-6);
        probe.kerf = Some(0.3e-3 - 1e-6);
    }
    let _ = &mut opts;
    if let Ok(pitch) = std::env::var("PITCH") {
        let pitch: f64 = pitch.parse().unwrap();
        let ne = (128.0 * 0.3e-3 / pitch).round() as usize;
        probe.pitch = pitch;
        probe.kerf = Some(pitch * 35.0 / 300.0);
        probe.width = Some(pitch - pitch * 35.0 / 300.0);
        probe.n_elements = ne;
    }
    let mut simus = Simus::new(probe.clone(), Medium::default(), opts).unwrap();
    let plan = simus.plan_for_max_distance(0.06, 5e-6).unwrap();
    let fd = arg("DEMOD", probe.fc);
    let dbw = arg("DBW", probe.bandwidth);
    let mut rf2iq = Rf2Iq::new(Rf2IqParams::new(fd, plan.fs, Some(dbw))).unwrap();
    let mut tx = Transmit::plane_wave(&probe, 1540.0, 0.0).unwrap();
    if tukey > 0.0 {
        let ne = probe.n_elements;
        tx.apodization = (0..ne)
            .map(|i| {
                let u = i as f64 / (ne - 1) as f64;
                let a = tukey / 2.0;
                if u < a {
                    0.5 * (1.0 - (std::f64::consts::PI * u / a).cos())
                } else if u > 1.0 - a {
                    0.5 * (1.0 - (std::f64::consts::PI * (1.0 - u) / a).cos())
                } else {
                    1.0
                }
            })
            .collect();
    }
    let frames: Vec<Vec<C32>> = (0..nframes)
        .map(|k| {
            let t = k as f64 / prf;
            let x: Vec<f32> = x0.iter().map(|x| (x + vx * t) as f32).collect();
            let z: Vec<f32> = z0.iter().map(|z| (z + vz * t) as f32).collect();
            let mut rf = vec![0f32; probe.n_elements * plan.n_samples];
            simus.simulate_into(&Scatterers::new(x, z, a.clone()).unwrap(), &tx, &plan, &mut rf).unwrap();
            rf2iq.process_to_vec(RfView::element_major(&rf, plan.n_samples, probe.n_elements)).unwrap()
        })
        .collect();
    let grid = Grid::spanning(-10e-3, 10e-3, 81, 10e-3, 30e-3, 81).unwrap();
    let wave = TxWave::PlaneWave { tilt: 0.0 };
    let mut maps = Vec::new();
    for rx_deg in [-rxdeg, rxdeg] {
        let rx = f64::to_radians(rx_deg);
        let p = DasParams {
            fc: fd,
            c: 1540.0,
            fs: plan.fs,
            t0: 0.0,
            pitch: probe.pitch,
            n_elements: probe.n_elements,
            radius: None,
            fnumber: fnum,
            rx_angle: rx,
            interpolation: Interpolation::Linear,
            apodization: Default::default(),
        };
        let dplan = DasPlan::new(&p, &wave, &grid, plan.n_samples).unwrap();
        let imgs: Vec<Vec<C32>> = frames.iter().map(|f| dplan.apply_to_vec(f).unwrap()).collect();
        let refs: Vec<&[C32]> = imgs.iter().map(|v| v.as_slice()).collect();
        let mut dp = DopplerParams::new(fd, 1540.0, prf);
        if std::env::var("LOUPAS").is_ok() {
            dp.estimator = Estimator::Loupas;
        }
        let m = DopplerEstimator::for_plan(dp, &dplan).unwrap().estimate_to_map(Packet::Frames(&refs)).unwrap();
        maps.push((m, rx, dplan.projection()));
    }
    // per depth band: mean vD per angle vs nominal, and vx, vz from eq 20
    let nb = 8;
    println!("vx {vx} vz {vz}; F# {fnum}; tukey {tukey}; {n} scatterers; {nframes} frames");
    println!("  z(mm)   vD-/nom    vD+/nom    vx/true   vz/true   plan-proj-x");
    for b in 0..nb {
        let (i0, i1) = (b * 81 / nb, (b + 1) * 81 / nb);
        let mut s = [0.0f64; 2];
        let mut px = 0.0;
        let mut cnt = 0.0;
        for iz in i0..i1 {
            for ix in 10..71 {
                let i = iz * 81 + ix;
                for (k, (m, _, _)) in maps.iter().enumerate() {
                    s[k] += f64::from(m.velocity[i]);
                }
                px += f64::from(maps[1].2[i][0]);
                cnt += 1.0;
            }
        }
        let (vm, vp) = (s[0] / cnt, s[1] / cnt);
        let phi = rxdeg.to_radians();
        let nom = |rx: f64| -(rx.sin() * vx + (1.0 + rx.cos()) * vz) / 2.0;
        let _ = fd;
        let ex_vx = (vm - vp) / phi.sin();
        let ex_vz = -(vm + vp) / (1.0 + phi.cos());
        let z = grid.z((i0 + i1) / 2);
        println!(
            "  {:5.1}  {:8.3}  {:8.3}  {:8.3}  {:8.3}  {:8.4}",
            z * 1e3,
            vm / nom(-phi),
            vp / nom(phi),
            if vx != 0.0 { ex_vx / vx } else { ex_vx },
            if vz != 0.0 { ex_vz / vz } else { ex_vz },
            px / cnt / (-(phi.sin()) / 2.0)
        );
    }
}
