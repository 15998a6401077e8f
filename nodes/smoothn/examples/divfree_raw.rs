//! Throwaway: divergence-free fit of raw f64 files (prototype check).
#![allow(clippy::unwrap_used)]
use sonoflow_smoothn::{DivFree, DivFreeParams};
fn rd(p: &str) -> Vec<f64> {
    std::fs::read(p).unwrap().chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().unwrap())).collect()
}
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let (nz, nx): (usize, usize) = (a[2].parse().unwrap(), a[3].parse().unwrap());
    let (dz, dx): (f64, f64) = (a[4].parse().unwrap(), a[5].parse().unwrap());
    let dir = &a[1];
    let ux = rd(&format!("{dir}/ux.bin"));
    let uz = rd(&format!("{dir}/uz.bin"));
    let w = rd(&format!("{dir}/w.bin"));
    let mut p = DivFreeParams::default();
    if let Some(s) = a.get(6) {
        if s != "gcv" {
            p.s = Some(s.parse().unwrap());
        }
    }
    if let Some(r) = a.get(7) {
        p.noise_ratio = Some(r.parse().unwrap());
    }
    if let Ok(k) = std::env::var("PROBES") {
        p.gcv_probes = k.parse().unwrap();
    }
    if let Ok(b) = std::env::var("BLOCK") {
        p.cv_block = b.parse().unwrap();
    }
    if std::env::var("NOROBUST").is_ok() {
        p.robust = false;
    }
    let t0 = std::time::Instant::now();
    let f = DivFree::new([nz, nx], [dz, dx], p.order).unwrap();
    let t1 = t0.elapsed();
    let (mut vx, mut vz) = (vec![0.0; nz * nx], vec![0.0; nz * nx]);
    let rep = f.fit(&ux, &uz, Some(&w), &p, &mut vx, &mut vz).unwrap();
    eprintln!("setup {:?}, fit {:?}: {rep:?}", t1, t0.elapsed() - t1);
    let wr = |name: &str, v: &[f64]| {
        std::fs::write(format!("{dir}/{name}"), v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>()).unwrap()
    };
    wr("vx.bin", &vx);
    wr("vz.bin", &vz);
}
