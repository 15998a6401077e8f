//! Unit tests of the speckle tracker (synthetic translating speckle).
use super::*;
use rand::{Rng, SeedableRng};

/// Speckle of `n_s` Gaussian blobs (σ ≈ 1.2 px across, 0.9 px deep) seen in frames that
/// translate by (`vi`, `vj`) pixels per frame; evaluated exactly at every pixel (no
/// interpolation), with the scatterers drawn over a margin so that speckle enters the image.
fn translating(seed: u64, nz: usize, nx: usize, frames: usize, vi: f64, vj: f64) -> LookImages {
    translating_iq(seed, nz, nx, frames, vi, vj)
        .into_iter()
        .map(|f| f.iter().map(|v| C32::new(v.norm(), 0.0)).collect())
        .collect()
}

/// Complex speckle (random-phase Gaussian blobs), translating as in [`translating`].
fn translating_iq(seed: u64, nz: usize, nx: usize, frames: usize, vi: f64, vj: f64) -> LookImages {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let margin = 12.0 + frames as f64 * (vi.abs() + vj.abs());
    let n_s = (nz as f64 + 2.0 * margin) as usize * (nx as f64 + 2.0 * margin) as usize / 3;
    let s: Vec<(f64, f64, C64)> = (0..n_s)
        .map(|_| {
            (
                rng.gen_range(-margin..nz as f64 + margin),
                rng.gen_range(-margin..nx as f64 + margin),
                C64::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)),
            )
        })
        .collect();
    (0..frames)
        .map(|t| {
            let (si, sj) = (vi * t as f64, vj * t as f64);
            let mut img = vec![C64::new(0.0, 0.0); nz * nx];
            for &(ci, cj, a) in &s {
                let (ci, cj) = (ci + si, cj + sj);
                let (i_lo, i_hi) = ((ci - 5.0).max(0.0) as usize, ((ci + 5.0).max(0.0) as usize).min(nz));
                let (j_lo, j_hi) = ((cj - 6.0).max(0.0) as usize, ((cj + 6.0).max(0.0) as usize).min(nx));
                for i in i_lo..i_hi {
                    for j in j_lo..j_hi {
                        let (di, dj) = (i as f64 - ci, j as f64 - cj);
                        img[i * nx + j] += a * (-(di * di) / (2.0 * 0.9 * 0.9) - dj * dj / (2.0 * 1.2 * 1.2)).exp();
                    }
                }
            }
            img.iter().map(|v| C32::new(v.re as f32, v.im as f32)).collect()
        })
        .collect()
}

fn mean_field(t: &Tracked) -> (f64, f64, usize) {
    let k: Vec<usize> = (0..t.valid.len()).filter(|&k| t.valid[k]).collect();
    let n = k.len() as f64;
    (k.iter().map(|&k| t.di[k]).sum::<f64>() / n, k.iter().map(|&k| t.dj[k]).sum::<f64>() / n, k.len())
}

#[test]
fn rigid_translation_is_tracked_without_pixel_locking_bias() {
    // Sub-pixel translations where the parabola's bias is largest (≈ 0.3 px fractions).
    for (seed, vi, vj) in [(1u64, 0.35, -0.6), (2, -0.7, 1.3), (3, 0.3, 0.45)] {
        let lag = 4;
        let img = translating(seed, 72, 72, 12, vi, vj);
        let (di_true, dj_true) = (vi * lag as f64, vj * lag as f64);
        let mag = (di_true * di_true + dj_true * dj_true).sqrt();
        let run = |subpixel| {
            let p = SpeckleParams { lag, subpixel, image: TrackedImage::Envelope, ..Default::default() };
            mean_field(&SpeckleTracker::new(p).unwrap().track(std::slice::from_ref(&img), 72, 72).unwrap())
        };
        let (fi, fj, nf) = run(Subpixel::Fourier);
        let (pi, pj, _) = run(Subpixel::Parabolic);
        let bias_f = ((fi - di_true).powi(2) + (fj - dj_true).powi(2)).sqrt() / mag;
        let bias_p = ((pi - di_true).powi(2) + (pj - dj_true).powi(2)).sqrt() / mag;
        eprintln!("seed {seed}: true ({di_true:.3}, {dj_true:.3}) fourier ({fi:.4}, {fj:.4}) {:.2} % parabolic ({pi:.4}, {pj:.4}) {:.2} % over {nf} windows", 100.0 * bias_f, 100.0 * bias_p);
        assert!(nf > 100, "{nf} valid windows");
        assert!(bias_f < 0.02, "fourier bias {bias_f}");
    }
}

#[test]
fn iq_images_and_several_looks_are_tracked() {
    // Two looks of the same motion with independent speckle, tracked on the complex I/Q.
    let (vi, vj, lag) = (0.4, -0.7, 4);
    let looks = [translating_iq(7, 64, 64, 12, vi, vj), translating_iq(8, 64, 64, 12, vi, vj)];
    let p = SpeckleParams { lag, image: TrackedImage::Iq, ..Default::default() };
    let (fi, fj, nf) = mean_field(&SpeckleTracker::new(p).unwrap().track(&looks, 64, 64).unwrap());
    let (ti, tj) = (vi * lag as f64, vj * lag as f64);
    let bias = ((fi - ti).powi(2) + (fj - tj).powi(2)).sqrt() / (ti * ti + tj * tj).sqrt();
    eprintln!("iq: ({fi:.4}, {fj:.4}) for ({ti}, {tj}): {:.2} % over {nf} windows", 100.0 * bias);
    assert!(nf > 100 && bias < 0.02, "{bias} {nf}");
}

#[test]
fn the_assembler_turns_pixels_into_metres_per_second() {
    // 0.45 px/frame down and 0.3 px/frame right on a 0.1 × 0.2 mm grid at 5 kHz (default lag 10:
    // 4.5 and 3 px): vz = 0.45·0.1e-3·5000 = 0.225 m/s, vx = 0.3·0.2e-3·5000 = 0.3 m/s.
    let (nz, nx, frames) = (64, 64, 16);
    let imgs = translating(11, nz, nx, frames, 0.45, 0.3);
    let grid = Grid { x0: -3e-3, z0: 10e-3, dx: 0.2e-3, dz: 0.1e-3, nx, nz };
    let mut asm = SpeckleAssembler::new(SpeckleParams::default()).unwrap();
    for packet in 0..2u32 {
        for (t, img) in imgs.iter().enumerate() {
            let h = LookHeader {
                grid: grid.clone(),
                fc: 5e6,
                c: 1540.0,
                prf: 5000.0,
                tx_angle: 0.0,
                rx_angle: 0.0,
                packet,
                frame_id: (packet as usize * frames + t) as u64,
                t_valid: 0.0,
                aperture: None,
            };
            let done = asm.push(&h, img.clone()).unwrap();
            assert_eq!(done.is_some(), packet == 1 && t == 0);
        }
    }
    let r = asm.finish().unwrap().unwrap();
    assert_eq!((r.packet, r.n_looks, r.frames), (1, 1, frames));
    let valid: Vec<usize> = (0..nz * nx).filter(|&i| r.flags[i] == 0).collect();
    let mean = |v: &[f32]| valid.iter().map(|&i| f64::from(v[i])).sum::<f64>() / valid.len() as f64;
    let (vx, vz) = (mean(&r.vx), mean(&r.vz));
    eprintln!("vx {vx:.4} vz {vz:.4} over {} px", valid.len());
    assert!(valid.len() > nz * nx * 9 / 10);
    assert!((vx / 0.3 - 1.0).abs() < 0.03 && (vz / 0.225 - 1.0).abs() < 0.03, "{vx} {vz}");
    assert!(r.weight.iter().zip(&r.flags).all(|(w, f)| (*f == 0) == (*w > 0.0) && *w <= 1.0));
    // Too short a packet for the lag is an error naming it.
    let mut asm = SpeckleAssembler::new(SpeckleParams { lag: 20, ..Default::default() }).unwrap();
    let h = LookHeader {
        grid,
        fc: 5e6,
        c: 1540.0,
        prf: 5000.0,
        tx_angle: 0.0,
        rx_angle: 0.0,
        packet: 0,
        frame_id: 0,
        t_valid: 0.0,
        aperture: None,
    };
    for img in &imgs {
        asm.push(&h, img.clone()).unwrap();
    }
    let e = asm.finish().err().unwrap().to_string();
    assert!(e.contains("lag = 20"), "{e}");
}
