//! The no-slip wall of the divergence-free fit: the wall found from a blurred power image, and the
//! zero-velocity prior beyond it against the over-read of blurred near-wall Doppler.
#![allow(clippy::unwrap_used)]

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use sonoflow_regularise::{wall_from_power, DivFree, DivFreeError, DivFreeParams, NoSlipParams, WallRule};

const NZ: usize = 40;
const NX: usize = 60;
const D: f64 = 2e-4;
/// The channel: rows whose centre is within ±HALF of the grid's centre line (4 mm wide).
const HALF: f64 = 2e-3;

fn zc() -> f64 {
    (NZ as f64 - 1.0) * D / 2.0
}

/// Abramowitz & Stegun 7.1.26 (|error| < 1.5e-7): an erf independent of the code under test.
fn erf(x: f64) -> f64 {
    let t = 1.0 / (1.0 + 0.3275911 * x.abs());
    let y = 1.0
        - (((((1.061405429 * t - 1.453152027) * t) + 1.421413741) * t - 0.284496736) * t + 0.254829592)
            * t
            * (-x * x).exp();
    y.copysign(x)
}

/// Power of a uniform blood layer |z − zc| < HALF seen through a Gaussian PSF of σ `sigma` along
/// z: ½ [erf((HALF − q)/(σ√2)) + erf((HALF + q)/(σ√2))], q = z − zc.
fn blurred_layer(q: f64, sigma: f64) -> f64 {
    let s = sigma * std::f64::consts::SQRT_2;
    0.5 * (erf((HALF - q) / s) + erf((HALF + q) / s))
}

#[test]
fn the_wall_lies_just_outside_the_lumen() {
    // PSF σ 0.3 mm; the wall rule smooths by 0.4 mm more: combined σ 0.5 mm, and −5 dB of the
    // interior level lies 0.24 mm outside the true wall (erfc(d/(σ√2)) = 2·10^−0.5).
    let power: Vec<f64> = (0..NZ * NX).map(|p| blurred_layer((p / NX) as f64 * D - zc(), 0.3e-3)).collect();
    let blood: Vec<bool> = power.iter().map(|v| *v > 10f64.powf(-1.5)).collect();
    let wall = wall_from_power(&power, &blood, [NZ, NX], [D, D], &NoSlipParams::default()).unwrap();
    for (p, &w) in wall.iter().enumerate() {
        let out = (((p / NX) as f64 * D - zc()).abs() - HALF) * 1e3; // mm outside the wall
        if out < -0.1 {
            assert!(!w, "row {}: {out:.2} mm inside the lumen marked as wall", p / NX);
        }
        if out > 0.45 {
            assert!(w, "row {}: {out:.2} mm outside the lumen not marked", p / NX);
        }
    }
    // no blood: no wall
    assert!(wall_from_power(&power, &[false; NZ * NX], [NZ, NX], [D, D], &NoSlipParams::default())
        .unwrap()
        .iter()
        .all(|w| !w));
}

/// After a clutter filter: the left half of the channel lost 10 dB of its blood echo (flow across
/// the beam), and residual tissue outside sits 25 dB below the right half's blood. The default rule
/// (5 dB below the blood's median) puts the wall inside the weak half; `two-class` (halfway between
/// the blood's and the rest's median, in dB) keeps the whole lumen and still marks the tissue
/// from 1 mm beyond the true wall on.
#[test]
fn two_class_wall_survives_a_clutter_filtered_lumen() {
    let power: Vec<f64> = (0..NZ * NX)
        .map(|p| {
            let level = if p % NX < NX / 2 { 0.1 } else { 1.0 };
            level * blurred_layer((p / NX) as f64 * D - zc(), 0.3e-3) + 10f64.powf(-2.5)
        })
        .collect();
    let blood: Vec<bool> = power.iter().map(|v| *v > 10f64.powf(-1.5) * 1.0).collect();
    let inside = |p: usize| (((p / NX) as f64 * D - zc()).abs() - HALF) * 1e3;
    let median = wall_from_power(&power, &blood, [NZ, NX], [D, D], &NoSlipParams::default()).unwrap();
    let weak_inside = (0..NZ * NX).filter(|&p| p % NX < NX / 2 && inside(p) < -0.1 && median[p]).count();
    assert!(weak_inside > 0, "the default rule is expected to cut into the weak half");
    let ns = NoSlipParams { rule: WallRule::TwoClass, ..NoSlipParams::default() };
    let wall = wall_from_power(&power, &blood, [NZ, NX], [D, D], &ns).unwrap();
    for (p, &w) in wall.iter().enumerate() {
        let out = inside(p);
        if out < -0.1 {
            assert!(!w, "pixel {p}: {out:.2} mm inside the lumen marked as wall");
        }
        if out > 1.0 {
            assert!(w, "pixel {p}: {out:.2} mm outside the lumen not marked");
        }
    }
}

#[test]
fn no_slip_prior_removes_the_over_read_beyond_the_wall() {
    // Poiseuille flow along x, 0.5 m/s on the axis, in the 4 mm channel. The "measured" velocity
    // is the flow blurred along z by a PSF of σ 0.6 mm, weighted by the blood's echo (so it
    // over-reads near the walls and reads the near-wall speed beyond them, wherever the echo is
    // within 15 dB of the blood), plus noise (σ 0.05 m/s in x, 0.01 in z).
    let sigma = 0.6e-3;
    let truth = |q: f64| if q.abs() < HALF { 0.5 * (1.0 - (q / HALF).powi(2)) } else { 0.0 };
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let (nx_, nz_) = (Normal::new(0.0, 0.05).unwrap(), Normal::new(0.0, 0.01).unwrap());
    let (mut ux, mut uz, mut power, mut tx) =
        (vec![0.0; NZ * NX], vec![0.0; NZ * NX], vec![0.0; NZ * NX], vec![0.0; NZ * NX]);
    for p in 0..NZ * NX {
        let q = (p / NX) as f64 * D - zc();
        // ∫ g(q − s) b(s) v(s) ds / ∫ g b, numerically over 0.01 mm
        let (mut num, mut den) = (0.0, 0.0);
        for k in -400..=400 {
            let s = q + k as f64 * 1e-5;
            let g = (-0.5 * ((s - q) / sigma).powi(2)).exp();
            if s.abs() < HALF {
                num += g * truth(s);
                den += g;
            }
        }
        power[p] = blurred_layer(q, sigma);
        ux[p] = if den > 0.0 { num / den } else { 0.0 } + nx_.sample(&mut rng);
        uz[p] = nz_.sample(&mut rng);
        tx[p] = truth(q);
    }
    let data: Vec<f64> = power.iter().map(|v| if *v > 10f64.powf(-1.5) { 1.0 } else { 0.0 }).collect();
    let blood: Vec<bool> = data.iter().map(|w| *w > 0.0).collect();
    let wall = wall_from_power(&power, &blood, [NZ, NX], [D, D], &NoSlipParams::default()).unwrap();
    let f = DivFree::new([NZ, NX], [D, D], 3).unwrap();
    let p = DivFreeParams::default();
    let fit = |w: &[f64], prior: Option<&[f64]>| {
        let (mut vx, mut vz) = (vec![0.0; NZ * NX], vec![0.0; NZ * NX]);
        let r = f.fit_with_wall(&ux, &uz, Some(w), prior, &p, None, &mut vx, &mut vz).unwrap();
        (vx, r)
    };
    let (plain, _) = fit(&data, None);
    let w_in: Vec<f64> = data.iter().zip(&wall).map(|(d, o)| if *o { 0.0 } else { *d }).collect();
    let prior: Vec<f64> = wall.iter().map(|o| if *o { 3.0 } else { 0.0 }).collect();
    let (walled, rep) = fit(&w_in, Some(&prior));
    // the prior is not data
    assert_eq!(rep.n_data, 2 * w_in.iter().filter(|w| **w > 0.0).count());
    // RMS error of vx in the lumen within 0.8 mm of the wall, and over the whole lumen
    let rms = |v: &[f64], near: bool| {
        let (mut s, mut n) = (0.0, 0.0);
        for i in 0..NZ * NX {
            let q = ((i / NX) as f64 * D - zc()).abs();
            if q < HALF && (!near || q > HALF - 0.8e-3) {
                s += (v[i] - tx[i]).powi(2);
                n += 1.0;
            }
        }
        (s / n).sqrt()
    };
    let (near0, near1) = (rms(&plain, true), rms(&walled, true));
    let (all0, all1) = (rms(&plain, false), rms(&walled, false));
    println!("near-wall vx RMS {near0:.4} → {near1:.4} m/s; lumen {all0:.4} → {all1:.4}");
    // Inside the lumen the blur itself stays (the prior cannot undo it: measured 0.103 → 0.092
    // near the wall with this seed); beyond the wall the over-read goes.
    assert!(near1 < 0.93 * near0, "near the wall: {near1} vs {near0}");
    assert!(all1 < all0, "lumen: {all1} vs {all0}");
    // beyond the wall the prior holds the flow at rest
    let beyond = (0..NZ * NX).filter(|&i| wall[i] && blood[i]).map(|i| walled[i].abs()).fold(0.0, f64::max);
    let beyond0 = (0..NZ * NX).filter(|&i| wall[i] && blood[i]).map(|i| plain[i].abs()).fold(0.0, f64::max);
    assert!(beyond < 0.5 * beyond0, "beyond the wall: {beyond} vs {beyond0} without the prior");
}

#[test]
fn bad_walls_and_parameters_are_named() {
    let f = DivFree::new([6, 6], [D, D], 3).unwrap();
    let u = vec![0.1; 36];
    let (mut vx, mut vz) = (vec![0.0; 36], vec![0.0; 36]);
    let p = DivFreeParams::default();
    let e = f.fit_with_wall(&u, &u, None, Some(&[1.0; 35]), &p, None, &mut vx, &mut vz).unwrap_err();
    assert!(matches!(e, DivFreeError::LengthMismatch { what: "wall", got: 35, .. }), "{e}");
    let mut bad = vec![0.0; 36];
    bad[3] = -1.0;
    let e = f.fit_with_wall(&u, &u, None, Some(&bad), &p, None, &mut vx, &mut vz).unwrap_err();
    assert!(e.to_string().contains("wall") && e.to_string().contains("≥ 0"), "{e}");
    for (ns, field) in [
        (NoSlipParams { threshold_db: 0.0, ..Default::default() }, "threshold_db"),
        (NoSlipParams { weight: f64::NAN, ..Default::default() }, "weight"),
        (NoSlipParams { smoothing: -1e-3, ..Default::default() }, "smoothing"),
    ] {
        let e = wall_from_power(&u, &[true; 36], [6, 6], [D, D], &ns).unwrap_err();
        assert!(e.to_string().contains(field), "{e}");
    }
    let e = wall_from_power(&u, &[true; 35], [6, 6], [D, D], &NoSlipParams::default()).unwrap_err();
    assert!(e.to_string().contains("blood"), "{e}");
}
