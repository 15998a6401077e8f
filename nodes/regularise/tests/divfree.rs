//! Divergence-free (stream-function) regulariser: exactness, reproduction of an analytic flow,
//! noise reduction against smoothn with the noise anisotropy of vector Doppler, the noise-ratio
//! estimate, the choice of S, robustness and input errors.
#![allow(clippy::unwrap_used)]

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use sonoflow_regularise::divfree::divergence;
use sonoflow_regularise::{smoothn, DivFree, DivFreeError, DivFreeParams, Selection, SmoothnParams};

const NZ: usize = 40;
const NX: usize = 60;
const D: f64 = 2e-4;

/// Tilted Poiseuille channel (axis through the grid centre at `angle` from +x towards +z, width
/// `width`, centre speed `u0`): velocity and inside mask per pixel. Stream function
/// ψ(q) = u0 (q − 4q³/(3W²)), q the signed distance from the axis, so v = u(q) a exactly.
fn channel(angle_deg: f64, width: f64, u0: f64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let (s, c) = angle_deg.to_radians().sin_cos();
    let (xc, zc) = ((NX as f64 - 1.0) * D / 2.0, (NZ as f64 - 1.0) * D / 2.0);
    let (mut vx, mut vz, mut m) = (vec![0.0; NZ * NX], vec![0.0; NZ * NX], vec![0.0; NZ * NX]);
    for i in 0..NZ {
        for j in 0..NX {
            let (x, z) = (j as f64 * D - xc, i as f64 * D - zc);
            let q = -x * s + z * c;
            let p = i * NX + j;
            if q.abs() <= width / 2.0 {
                let u = u0 * (1.0 - (2.0 * q / width).powi(2));
                vx[p] = u * c;
                vz[p] = u * s;
                m[p] = 1.0;
            }
        }
    }
    (vx, vz, m)
}

fn rms_inside(a: &[f64], b: &[f64], m: &[f64]) -> f64 {
    let (mut s, mut n) = (0.0, 0.0);
    for p in 0..a.len() {
        if m[p] > 0.0 {
            s += (a[p] - b[p]).powi(2);
            n += 1.0;
        }
    }
    (s / n).sqrt()
}

fn noisy(vx: &[f64], vz: &[f64], sx: f64, sz: f64, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (nx, nz) = (Normal::new(0.0, sx).unwrap(), Normal::new(0.0, sz).unwrap());
    (vx.iter().map(|v| v + nx.sample(&mut rng)).collect(), vz.iter().map(|v| v + nz.sample(&mut rng)).collect())
}

/// The fitted field is divergence-free under the documented discrete operator to round-off, for
/// any data (here pure noise).
#[test]
fn output_is_divergence_free_to_round_off() {
    let f = DivFree::new([NZ, NX], [D, 1.5 * D], 3).unwrap();
    let (ux, uz) = noisy(&vec![0.0; NZ * NX], &vec![0.0; NZ * NX], 0.3, 0.1, 1);
    let p = DivFreeParams { s: Some(0.5), robust: false, ..Default::default() };
    let (mut vx, mut vz) = (vec![0.0; NZ * NX], vec![0.0; NZ * NX]);
    let r = f.fit(&ux, &uz, None, &p, &mut vx, &mut vz).unwrap();
    let vmax = vx.iter().chain(&vz).fold(0.0f64, |a, v| a.max(v.abs()));
    let dmax = divergence(&vx, &vz, [NZ, NX], [D, 1.5 * D]).iter().fold(0.0f64, |a, v| a.max(v.abs()));
    println!("max |div| · d / max|v| = {:.2e} (report {:.2e}), max|v| = {vmax:.3}", dmax * D / vmax, r.max_divergence);
    assert!(vmax > 1e-3, "the fit is not trivially zero");
    assert!(dmax * D / vmax < 1e-12 && r.max_divergence < 1e-12);
    // the same operator on the (non-solenoidal) data is far from zero
    let dn = divergence(&ux, &uz, [NZ, NX], [D, 1.5 * D]).iter().fold(0.0f64, |a, v| a.max(v.abs()));
    assert!(dn * D / vmax > 1e-2);
}

/// Noise-free Poiseuille channel at 20°, data only inside the channel: the parabolic profile is in
/// the null space of the order-3 penalty, so even heavy smoothing (S = 1e3) reproduces it; what
/// is left is the O(d²) difference between the pixel-centred velocity and the stream-function
/// stencil (the profile's cubic ψ: 0.2 % of u0 at d/W = 0.04, measured 0.15 %).
#[test]
fn noise_free_poiseuille_channel_is_reproduced() {
    let (tx, tz, m) = channel(20.0, 5e-3, 0.5);
    let f = DivFree::new([NZ, NX], [D, D], 3).unwrap();
    for s in [1e-2, 1.0, 1e3] {
        let p = DivFreeParams { s: Some(s), robust: false, noise_ratio: Some(7.6), ..Default::default() };
        let (mut vx, mut vz) = (vec![0.0; NZ * NX], vec![0.0; NZ * NX]);
        f.fit(&tx, &tz, Some(&m), &p, &mut vx, &mut vz).unwrap();
        let (ex, ez) = (rms_inside(&vx, &tx, &m) / 0.5, rms_inside(&vz, &tz, &m) / 0.5);
        println!("S = {s}: RMS error x {:.3} %, z {:.3} % of u0", 100.0 * ex, 100.0 * ez);
        assert!(ex < 3e-3 && ez < 3e-3, "S = {s}: {ex} {ez}");
    }
}

/// The noise ratio of white noise is recovered from the data (MAD of the Laplacians), on top of
/// the channel flow.
#[test]
fn noise_ratio_is_estimated() {
    let (tx, tz, m) = channel(10.0, 6e-3, 0.4);
    let f = DivFree::new([NZ, NX], [D, D], 3).unwrap();
    for (sx, sz) in [(0.04, 0.005), (0.02, 0.01)] {
        let (ux, uz) = noisy(&tx, &tz, sx, sz, 3);
        let p = DivFreeParams { s: Some(1.0), robust: false, ..Default::default() };
        let (mut vx, mut vz) = (vec![0.0; NZ * NX], vec![0.0; NZ * NX]);
        let r = f.fit(&ux, &uz, Some(&m), &p, &mut vx, &mut vz).unwrap();
        println!("true ratio {:.2}, estimated {:.2}", sx / sz, r.noise_ratio);
        assert!((r.noise_ratio / (sx / sz) - 1.0).abs() < 0.1, "{}", r.noise_ratio);
    }
}

/// Vector-Doppler-like noise (σx = 7.6 σz, independent per pixel) on a 20° channel: the
/// divergence-free fit with its unsupervised choices (estimated ratio, block-CV S, robust) cuts
/// the lateral error far below smoothn's (robust, GCV; the paper's regulariser) and does not
/// lose on the axial one. Independent computation: smoothn of the same data.
#[test]
fn lateral_error_far_below_smoothn_with_anisotropic_noise() {
    let (tx, tz, m) = channel(20.0, 5e-3, 0.5);
    let (ux, uz) = noisy(&tx, &tz, 0.076, 0.01, 5);
    let f = DivFree::new([NZ, NX], [D, D], 3).unwrap();
    let (mut vx, mut vz) = (vec![0.0; NZ * NX], vec![0.0; NZ * NX]);
    let r = f.fit(&ux, &uz, Some(&m), &DivFreeParams::default(), &mut vx, &mut vz).unwrap();
    let (dx_err, dz_err) = (rms_inside(&vx, &tx, &m), rms_inside(&vz, &tz, &m));
    // smoothn, the paper's regulariser, on the same data and weights
    let mut data = ux.clone();
    data.extend_from_slice(&uz);
    let sp = SmoothnParams { robust: true, ..Default::default() };
    let (sm, _) = smoothn(&data, &[NZ, NX], 2, Some(&m), &sp).unwrap();
    let (sx_err, sz_err) = (rms_inside(&sm[..NZ * NX], &tx, &m), rms_inside(&sm[NZ * NX..], &tz, &m));
    let (rx, rz) = (rms_inside(&ux, &tx, &m), rms_inside(&uz, &tz, &m));
    println!(
        "RMS error (m/s): raw x {rx:.4} z {rz:.4}; smoothn x {sx_err:.4} z {sz_err:.4}; divergence-free x {dx_err:.4} z {dz_err:.4} (S {:.3}, ratio {:.2}, {} factorisations, outliers {:.3})",
        r.s, r.noise_ratio, r.factorisations, r.outlier_fraction
    );
    assert!(dx_err < 0.5 * sx_err, "x: {dx_err} vs smoothn {sx_err}");
    assert!(dz_err < 1.2 * sz_err, "z: {dz_err} vs smoothn {sz_err}");
    assert!(dx_err < 0.2 * rx && dz_err < 0.6 * rz);
}

/// Block cross-validation picks an S whose true error is close to the best of a scan, when the
/// noise is correlated over a few pixels (white noise smoothed by a 5 × 5 box) — the case where
/// GCV under-smooths.
#[test]
fn block_cv_picks_a_near_optimal_s_for_correlated_noise() {
    let (tx, tz, m) = channel(15.0, 5e-3, 0.5);
    let (wx, wz) = noisy(&vec![0.0; NZ * NX], &vec![0.0; NZ * NX], 0.2, 0.026, 9);
    let boxed = |w: &[f64]| -> Vec<f64> {
        let mut o = vec![0.0; NZ * NX];
        for i in 0..NZ {
            for j in 0..NX {
                let (mut s, mut k) = (0.0, 0.0);
                for a in i.saturating_sub(2)..(i + 3).min(NZ) {
                    for b in j.saturating_sub(2)..(j + 3).min(NX) {
                        s += w[a * NX + b];
                        k += 1.0;
                    }
                }
                o[i * NX + j] = s / k;
            }
        }
        o
    };
    let (nx_, nz_) = (boxed(&wx), boxed(&wz));
    let ux: Vec<f64> = tx.iter().zip(&nx_).map(|(a, b)| a + b).collect();
    let uz: Vec<f64> = tz.iter().zip(&nz_).map(|(a, b)| a + b).collect();
    let f = DivFree::new([NZ, NX], [D, D], 3).unwrap();
    let err = |p: &DivFreeParams| {
        let (mut vx, mut vz) = (vec![0.0; NZ * NX], vec![0.0; NZ * NX]);
        let r = f.fit(&ux, &uz, Some(&m), p, &mut vx, &mut vz).unwrap();
        (rms_inside(&vx, &tx, &m).hypot(rms_inside(&vz, &tz, &m)), r.s)
    };
    let base = DivFreeParams { robust: false, cv_block: 10, ..Default::default() };
    let scan: Vec<(f64, f64)> = [0.01, 0.1, 1.0, 10.0, 100.0, 1e3]
        .iter()
        .map(|&s| err(&DivFreeParams { s: Some(s), ..base.clone() }))
        .collect();
    let best = scan.iter().map(|e| e.0).fold(f64::INFINITY, f64::min);
    let (cv_err, cv_s) = err(&base);
    let (gcv_err, gcv_s) = err(&DivFreeParams { selection: Selection::Gcv, ..base.clone() });
    println!(
        "scan {scan:?}; block CV S {cv_s:.3} error {cv_err:.4}; GCV S {gcv_s:.3} error {gcv_err:.4}; best {best:.4}"
    );
    assert!(cv_err < 1.25 * best, "block CV {cv_err} vs best {best}");
    assert!(cv_s > gcv_s, "block CV should smooth more than GCV on correlated noise");
}

/// A few wild values (2 % of the pixels, ±1 m/s) barely move the robust fit; the plain fit is
/// pulled by them.
#[test]
fn robust_fit_ignores_outliers() {
    let (tx, tz, m) = channel(20.0, 5e-3, 0.5);
    let (mut ux, mut uz) = noisy(&tx, &tz, 0.02, 0.004, 11);
    let mut k = 0;
    for p in (7..NZ * NX).step_by(50) {
        if m[p] > 0.0 {
            ux[p] = if k % 2 == 0 { 1.0 } else { -1.0 };
            uz[p] = -ux[p];
            k += 1;
        }
    }
    let f = DivFree::new([NZ, NX], [D, D], 3).unwrap();
    let fit = |robust: bool| {
        let p = DivFreeParams { s: Some(1.0), noise_ratio: Some(5.0), robust, ..Default::default() };
        let (mut vx, mut vz) = (vec![0.0; NZ * NX], vec![0.0; NZ * NX]);
        let r = f.fit(&ux, &uz, Some(&m), &p, &mut vx, &mut vz).unwrap();
        (rms_inside(&vx, &tx, &m).hypot(rms_inside(&vz, &tz, &m)), r.outlier_fraction)
    };
    let ((e_r, out), (e_p, _)) = (fit(true), fit(false));
    println!("{k} outliers; robust error {e_r:.4} (outlier fraction {out:.3}), plain {e_p:.4}");
    assert!(e_r < 0.5 * e_p && e_r < 0.01, "robust {e_r} plain {e_p}");
    assert!(out >= 0.015, "the wild values are flagged: {out}");
}

#[test]
fn bad_input_gives_clear_errors() {
    let e = DivFree::new([3, 50], [D, D], 3).err().unwrap().to_string();
    assert!(e.contains("shape") && e.contains("order + 2"), "{e}");
    let e = DivFree::new([20, 20], [D, -D], 3).err().unwrap().to_string();
    assert!(e.contains("spacing"), "{e}");
    let e = DivFree::new([20, 20], [D, D], 4).err().unwrap().to_string();
    assert!(e.contains("order") && e.contains("2 or 3"), "{e}");
    let f = DivFree::new([10, 12], [D, D], 2).unwrap();
    let (u, mut v) = (vec![0.1; 120], vec![0.0; 120]);
    let mut w = v.clone();
    let p = DivFreeParams { order: 2, ..Default::default() };
    let e = f.fit(&u[..100], &u, None, &p, &mut v, &mut w).unwrap_err();
    assert!(matches!(e, DivFreeError::LengthMismatch { what: "ux", got: 100, expected: 120, .. }), "{e}");
    let e = f.fit(&u, &u, Some(&vec![0.0; 120]), &p, &mut v, &mut w).unwrap_err();
    assert_eq!(e, DivFreeError::NoData);
    let nan = vec![f64::NAN; 120];
    assert_eq!(f.fit(&nan, &u, None, &p, &mut v, &mut w).unwrap_err(), DivFreeError::NoData);
    let e = f.fit(&u, &u, Some(&vec![-1.0; 120]), &p, &mut v, &mut w).unwrap_err().to_string();
    assert!(e.contains("weights") && e.contains("≥ 0"), "{e}");
    for (bad, field) in [
        (DivFreeParams { s: Some(-1.0), order: 2, ..Default::default() }, "`s`"),
        (DivFreeParams { noise_ratio: Some(0.0), order: 2, ..Default::default() }, "noise_ratio"),
        (DivFreeParams { cv_block: 1, order: 2, ..Default::default() }, "cv_block"),
        (DivFreeParams { gcv_probes: 0, order: 2, ..Default::default() }, "gcv_probes"),
        (DivFreeParams { order: 3, ..Default::default() }, "order"),
    ] {
        let e = f.fit(&u, &u, None, &bad, &mut v, &mut w).unwrap_err().to_string();
        assert!(e.contains(field), "{field}: {e}");
    }
    // Missing values are filled, not propagated.
    let mut ux = u.clone();
    ux[33] = f64::NAN;
    let p = DivFreeParams { order: 2, s: Some(1.0), ..Default::default() };
    f.fit(&ux, &u, None, &p, &mut v, &mut w).unwrap();
    assert!(v.iter().chain(&w).all(|x| x.is_finite()));
}
