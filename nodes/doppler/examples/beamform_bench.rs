//! Timing of the beamforming chain on the paper configuration: rf2iq per frame, DAS (grid
//! 200×200, 128 elements, F-number 3, 0° plane wave) set-up and per frame, Doppler per 32-frame
//! packet. `bench/beamform/side_by_side.sh` runs it next to PyMUST on the same data.
//!
//! ```text
//! cargo run --release -p sonoflow-doppler --example beamform_bench -- [--reps N] [--write DIR]
//! ```
//! `--write DIR` stores rf.npy (float32, n_samples × 128), das.npy (complex64 200×200, frame 0),
//! packet.npy (complex64 200×200×32), velocity.npy (float32 200×200) and rust.json (timings).
#![allow(clippy::unwrap_used)]

use std::time::Instant;

use sonoflow_beamform::{DasParams, DasPlan, Grid, Interpolation, Rf2Iq, Rf2IqParams, RfView, TxWave, C32};
use sonoflow_doppler::{DopplerEstimator, DopplerParams, Packet};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let arg = |k: &str| args.iter().position(|a| a == k).and_then(|i| args.get(i + 1)).cloned();
    let reps: usize = arg("--reps").map_or(20, |s| s.parse().unwrap());
    let write = arg("--write").map(std::path::PathBuf::from);
    let (ne, ns, nf, fs) = (128usize, 1600usize, 32usize, 20e6);
    // deterministic RF: band-limited-looking noise (xorshift), one trace per element
    let mut s = 0x2545_f491_4f6c_dd1du64;
    let rf: Vec<f32> = (0..ns * ne)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32 - 0.5
        })
        .collect(); // sample-major (n_samples, n_elements), as numpy
    let mut rf2iq = Rf2Iq::new(Rf2IqParams::new(5e6, fs, Some(75.0))).unwrap();
    let mut iq = vec![C32::new(0.0, 0.0); ns * ne];
    let mut t_iq = Vec::new();
    for _ in 0..reps {
        let t = Instant::now();
        rf2iq.process(RfView::sample_major(&rf, ns, ne), &mut iq).unwrap();
        t_iq.push(t.elapsed().as_secs_f64());
    }
    let params = DasParams {
        fc: 5e6,
        c: 1540.0,
        fs,
        t0: 0.0,
        pitch: 0.30e-3,
        n_elements: ne,
        radius: None,
        fnumber: 3.0,
        rx_angle: 0.0,
        interpolation: Interpolation::Linear,
        apodization: Default::default(),
    };
    let grid = Grid::spanning(-19e-3, 19e-3, 200, 5e-3, 45e-3, 200).unwrap();
    let tx = TxWave::PlaneWave { tilt: 0.0 };
    let mut t_setup = Vec::new();
    let mut plan = None;
    for _ in 0..reps.min(10) {
        let t = Instant::now();
        plan = Some(DasPlan::new(&params, &tx, &grid, ns).unwrap());
        t_setup.push(t.elapsed().as_secs_f64());
    }
    let plan = plan.unwrap();
    let mut img = vec![C32::new(0.0, 0.0); grid.n_pixels()];
    let mut t_apply = Vec::new();
    for _ in 0..reps {
        let t = Instant::now();
        plan.apply(&iq, &mut img).unwrap();
        t_apply.push(t.elapsed().as_secs_f64());
    }
    // a packet: the frame's I/Q with a per-frame phase ramp (a uniform axial motion)
    let packet: Vec<Vec<C32>> = (0..nf)
        .map(|n| {
            let r = C32::from_polar(1.0, -0.3 * n as f32);
            img.iter().map(|v| v * r).collect()
        })
        .collect();
    let refs: Vec<&[C32]> = packet.iter().map(|v| v.as_slice()).collect();
    let mut est = DopplerEstimator::new(DopplerParams::new(5e6, 1540.0, 10e3), grid.nx, grid.nz, grid.dz).unwrap();
    let mut map = est.estimate_to_map(Packet::Frames(&refs)).unwrap();
    let mut t_dop = Vec::new();
    for _ in 0..reps {
        let t = Instant::now();
        est.estimate(Packet::Frames(&refs), &mut map).unwrap();
        t_dop.push(t.elapsed().as_secs_f64());
    }
    let threads = rayon::current_num_threads();
    let (ti, ts, ta, td) = (median(t_iq), median(t_setup), median(t_apply), median(t_dop));
    println!("threads {threads}, {ne} elements × {ns} samples, grid 200×200, F# 3, {} taps", plan.n_taps());
    println!("rf2iq           {:8.3} ms/frame", ti * 1e3);
    println!("DAS set-up      {:8.3} ms", ts * 1e3);
    println!("DAS apply       {:8.3} ms/frame", ta * 1e3);
    println!("DAS set-up + 1  {:8.3} ms", (ts + ta) * 1e3);
    println!("Doppler         {:8.3} ms/packet of {nf}", td * 1e3);
    if let Some(dir) = write {
        std::fs::create_dir_all(&dir).unwrap();
        use sonoflow_fileio::npy;
        npy::write_f32(&dir.join("rf.npy"), &[ns, ne], false, &rf).unwrap();
        npy::write_c64(&dir.join("das.npy"), &[200, 200], &img).unwrap();
        let pm: Vec<C32> = (0..grid.n_pixels()).flat_map(|p| packet.iter().map(move |f| f[p])).collect();
        npy::write_c64(&dir.join("packet.npy"), &[200, 200, nf], &pm).unwrap();
        npy::write_f32(&dir.join("velocity.npy"), &[200, 200], false, &map.velocity).unwrap();
        let json = format!(
            "{{\"threads\": {threads}, \"rf2iq_s\": {ti}, \"das_setup_s\": {ts}, \"das_apply_s\": {ta}, \"doppler_s\": {td}, \"taps\": {}, \"n_samples\": {ns}}}",
            plan.n_taps()
        );
        std::fs::write(dir.join("rust.json"), json).unwrap();
    }
}
