//! `field::FieldRegulariser`: one frame of a vector field given as planes (what the `regulariser`
//! node does per message): masks, flags and weights, nothing measured, the divergence-free fit's
//! power mask and no-slip wall, and the parameter checks.
#![allow(clippy::unwrap_used)]

use sonoflow_regularise::field::{Method, WeightSource};
use sonoflow_regularise::{
    DivFreeParams, FieldRegulariser, FieldReport, NoSlipParams, PlaneRole, PlaneRole::*, RegulariserParams,
    SmoothnParams,
};

/// A linear field on an `nz × nx` grid (spacing 0.1 mm): `vx` in the first plane, `vz` in the
/// second, the other planes 0.
fn field(nx: usize, nz: usize, planes: usize) -> Vec<f32> {
    let n = nx * nz;
    let mut v = vec![0.0f32; planes * n];
    for i in 0..n {
        v[i] = 0.1 + 0.001 * (i % nx) as f32;
        v[n + i] = -0.2 + 0.002 * (i / nx) as f32;
    }
    v
}

fn process(
    p: RegulariserParams,
    [nz, nx]: [usize; 2],
    roles: &[PlaneRole],
    v: &[f32],
) -> Result<(FieldReport, Vec<f32>), sonoflow_regularise::FieldError> {
    let mut out = Vec::new();
    let r = FieldRegulariser::new(p)?.process([nz, nx], [1e-4, 1e-4], roles, v, &mut out)?;
    Ok((r, out))
}

#[test]
fn needs_vx_and_vz_planes_of_the_grid() {
    let v = field(8, 6, 2);
    let e = process(RegulariserParams::default(), [6, 8], &[Vx, Mask], &v).unwrap_err().to_string();
    assert!(e.contains("needs `vx` and `vz`"), "{e}");
    let e = process(RegulariserParams::default(), [6, 8], &[Vx, Vz], &v[..10]).unwrap_err().to_string();
    assert!(e.contains("2 planes of 6×8 need 96 values, got 10"), "{e}");
    let p = RegulariserParams { weights: WeightSource::Power, ..Default::default() };
    let e = process(p.clone(), [6, 8], &[Vx, Vz], &v).unwrap_err().to_string();
    assert!(e.contains("no `power` plane"), "{e}");
    let e = process(
        RegulariserParams { smoothn: SmoothnParams { order: 7, ..p.smoothn.clone() }, ..p },
        [6, 8],
        &[Vx, Vz],
        &v,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("order"), "{e}");
}

#[test]
fn linear_field_is_kept_masked_pixels_zeroed_and_flagged_pixels_filled() {
    // A linear field is reproduced closely by order-2 smoothing with a small given S (the
    // reflective boundaries bend a plane slightly: measured 8e-4 m/s here, on a field that
    // spans 0.02 m/s); the flagged pixel's junk value (±50) is ignored and filled.
    let mut v = field(12, 10, 4);
    let n = 120;
    let clean = v.clone();
    for i in 0..n {
        v[2 * n + i] = if i % 12 < 10 { 1.0 } else { 0.0 };
    }
    v[3 * n + 25] = 1.0; // no estimate: value is junk
    v[25] = 50.0;
    v[n + 25] = -50.0;
    let p =
        RegulariserParams { smoothn: SmoothnParams { s: Some(0.5), ..SmoothnParams::default() }, ..Default::default() };
    let (r, out) = process(p, [10, 12], &[Vx, Vz, Mask, Flags], &v).unwrap();
    assert_eq!((r.s, r.converged), (0.5, true));
    for i in 0..n {
        if i % 12 >= 10 {
            assert_eq!((out[i], out[n + i]), (0.0, 0.0), "pixel {i} outside the mask");
        } else {
            assert!((out[i] - clean[i]).abs() < 2e-3 && (out[n + i] - clean[n + i]).abs() < 2e-3, "pixel {i}");
        }
    }
    assert_eq!(&out[2 * n..], &v[2 * n..], "mask and flags planes pass through");
}

#[test]
fn nothing_measured_gives_zeros_not_nan() {
    let mut v = field(5, 4, 3);
    v[40..].fill(0.0); // empty mask
    let (r, out) = process(RegulariserParams::default(), [4, 5], &[Vx, Vz, Mask], &v).unwrap();
    assert!(out[..40].iter().all(|&x| x == 0.0));
    assert_eq!(r, FieldReport { s: 0.0, outlier_fraction: 0.0, converged: false });
}

#[test]
fn weight_plane_is_used_as_weights() {
    // Half the pixels carry a wrong value with weight 0: the result ignores them entirely.
    let n = 80;
    let p =
        RegulariserParams { smoothn: SmoothnParams { s: Some(0.5), ..SmoothnParams::default() }, ..Default::default() };
    let (_, reference) = process(p.clone(), [8, 10], &[Vx, Vz], &field(10, 8, 2)).unwrap();
    let mut v = field(10, 8, 3);
    for i in 0..n {
        v[2 * n + i] = 1.0;
    }
    v[2 * n + 33] = 0.0;
    v[33] = 9.0;
    let (_, out) = process(p.clone(), [8, 10], &[Vx, Vz, Weight], &v).unwrap();
    let d = (out[33] - reference[33]).abs();
    assert!(d < 0.02, "weight-0 outlier leaked: {d}");
    let p = RegulariserParams { weights: WeightSource::None, ..p };
    let (_, out) = process(p, [8, 10], &[Vx, Vz, Weight], &v).unwrap();
    assert!((out[33] - reference[33]).abs() > 0.1, "without weights the outlier shows");
}

/// `method = "divergence-free"`: a horizontal Poiseuille channel with noisy data inside and
/// junk (±3 m/s) where the power plane says there is no blood. The power mask keeps the junk
/// out (error inside ≪ the junk); without it the junk leaks into a plain fit (the robust
/// weights would also catch junk this gross); the output is divergence-free.
#[test]
fn divergence_free_method_uses_the_power_mask() {
    let (nx, nz) = (40usize, 30usize);
    let mut v = field(nx, nz, 3);
    let n = nx * nz;
    let mut truth = vec![0.0f64; n];
    let mut state = 7u64;
    let mut noise = || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    for i in 0..n {
        let q = ((i / nx) as f64 - 14.5) / 9.0;
        if q.abs() < 1.0 {
            truth[i] = 0.5 * (1.0 - q * q);
            v[i] = (truth[i] + 0.1 * noise()) as f32;
            v[n + i] = (0.015 * noise()) as f32;
            v[2 * n + i] = 1.0;
        } else {
            v[i] = if i % 2 == 0 { 3.0 } else { -3.0 };
            v[n + i] = -v[i];
            v[2 * n + i] = 1e-4; // −40 dB: no blood
        }
    }
    let err = |p: RegulariserParams| -> (f64, FieldReport, Vec<f32>) {
        let (r, out) = process(p, [nz, nx], &[Vx, Vz, Power], &v).unwrap();
        let inside: Vec<usize> = (0..n).filter(|&i| v[2 * n + i] == 1.0).collect();
        let e = inside.iter().map(|&i| (out[i] as f64 - truth[i]).abs()).sum::<f64>() / inside.len() as f64;
        (e, r, out)
    };
    let plain = DivFreeParams { robust: false, ..Default::default() };
    let df = RegulariserParams { method: Method::DivergenceFree, divergence_free: plain, ..Default::default() };
    let (e_mask, r, out) = err(df.clone());
    let (e_none, _, _) = err(RegulariserParams { power_mask_db: -100.0, ..df });
    assert!(r.s > 0.0 && r.converged);
    assert!(e_mask < 0.02 && e_none > 3.0 * e_mask, "mean |error| inside: masked {e_mask}, unmasked {e_none}");
    let vx: Vec<f64> = out[..n].iter().map(|&x| x as f64).collect();
    let vz: Vec<f64> = out[n..2 * n].iter().map(|&x| x as f64).collect();
    let d = sonoflow_regularise::divfree::divergence(&vx, &vz, [nz, nx], [1e-4, 1e-4]);
    // f32 output: divergence at the f32 rounding of velocities of 0.5 m/s over 1e-4 m
    assert!(d.iter().all(|x| x.abs() < 1e-2), "{:?}", d.iter().fold(0.0f64, |a, x| a.max(x.abs())));
    // the divergence-free fit needs a positive spacing
    let p = RegulariserParams { method: Method::DivergenceFree, ..Default::default() };
    let e = FieldRegulariser::new(p).unwrap().process([nz, nx], [0.0, 1e-4], &[Vx, Vz], &v[..2 * n], &mut Vec::new());
    assert!(e.unwrap_err().to_string().contains("grid spacing dz = 0"));
}

/// `no_slip`: beyond the channel's walls the power is 8 dB below the blood (within the −15 dB
/// mask, so those pixels are data) and the Doppler over-reads there (0.2 m/s, as blurred
/// near-wall Doppler does). With the no-slip wall those pixels become a zero-velocity prior
/// and the lumen's error drops, for the divergence-free fit and for smoothn given the same lumen
/// (zero beyond the wall on output); without a power plane it is a clear error.
#[test]
fn no_slip_wall_from_the_power_plane() {
    let (nx, nz) = (40usize, 40usize);
    let mut v = field(nx, nz, 3);
    let n = nx * nz;
    let mut truth = vec![0.0f64; n];
    for i in 0..n {
        let q = ((i / nx) as f64 - 19.5) / 10.0;
        if q.abs() < 1.0 {
            truth[i] = 0.5 * (1.0 - q * q);
            v[i] = truth[i] as f32;
            v[2 * n + i] = 1.0;
        } else {
            v[i] = 0.2;
            v[2 * n + i] = 10f32.powf(-0.8);
        }
    }
    let err_of = |p: RegulariserParams, v: &[f32]| -> f64 {
        let (_, out) = process(p, [nz, nx], &[Vx, Vz, Power], v).unwrap();
        let inside: Vec<usize> = (0..n).filter(|&i| v[2 * n + i] == 1.0).collect();
        (inside.iter().map(|&i| (out[i] as f64 - truth[i]).powi(2)).sum::<f64>() / inside.len() as f64).sqrt()
    };
    let err = |p: RegulariserParams| err_of(p, &v);
    let df = RegulariserParams {
        method: Method::DivergenceFree,
        divergence_free: DivFreeParams { robust: false, s: Some(1.0), ..Default::default() },
        ..Default::default()
    };
    let e_plain = err(df.clone());
    let e_wall = err(RegulariserParams { no_slip: Some(NoSlipParams::default()), ..df.clone() });
    assert!(e_wall < 0.5 * e_plain, "RMS error in the lumen: {e_wall} with the wall, {e_plain} without");
    // The paper's smoothn given the same lumen: power-masked pixels missing, pixels beyond the
    // wall missing and zero on output, the lumen fitted as without (a noisy channel flow, vz = 0).
    let mut channel = v.clone();
    channel[n..2 * n].fill(0.0);
    let mut state = 7u64;
    for i in 0..n {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        channel[i] += 0.05 * (((state >> 33) as f64 / (1u64 << 31) as f64) - 0.5) as f32;
        if i / nx < 2 || i / nx >= nz - 2 {
            channel[2 * n + i] = 1e-3; // far outside: below the −15 dB power mask
        }
    }
    let sm = RegulariserParams { smoothn: SmoothnParams { robust: true, ..Default::default() }, ..Default::default() };
    let with_lumen = RegulariserParams { no_slip: Some(NoSlipParams::default()), ..sm.clone() };
    let (e_sm, e_sm_wall) = (err_of(sm.clone(), &channel), err_of(with_lumen.clone(), &channel));
    eprintln!("smoothn: RMS error in the lumen {e_sm_wall} with sonoflow's lumen, {e_sm} without");
    assert!(e_sm_wall < 0.9 * e_sm, "smoothn: {e_sm_wall} with the lumen, {e_sm} without");
    let (_, plain) = process(sm.clone(), [nz, nx], &[Vx, Vz, Power], &channel).unwrap();
    let (_, out) = process(with_lumen, [nz, nx], &[Vx, Vz, Power], &channel).unwrap();
    let row = |r: usize| (0..nx).map(move |c| r * nx + c);
    // rows 2 and 37: data (−8 dB) but beyond the wall; rows 0 and 39: power-masked, also beyond
    for i in row(0).chain(row(2)).chain(row(37)).chain(row(39)) {
        assert!(out[i] == 0.0 && out[n + i] == 0.0, "pixel {i}: {} {}", out[i], out[n + i]);
        assert!(plain[i] > 0.1, "pixel {i} without the lumen: {}", plain[i]);
    }
    let e =
        process(RegulariserParams { no_slip: Some(NoSlipParams::default()), ..sm }, [nz, nx], &[Vx, Vz], &v[..2 * n]);
    assert!(e.unwrap_err().to_string().contains("no_slip"));
    // no power plane: a clear error
    let p = RegulariserParams { no_slip: Some(NoSlipParams::default()), ..df };
    let e = process(p, [nz, nx], &[Vx, Vz, Other], &v).unwrap_err().to_string();
    assert!(e.contains("no_slip") && e.contains("power"), "{e}");
}

/// The parameters as the launch files write them (flat keys; the divergence-free fit and the
/// no-slip wall in tables); defaults; errors name the field.
#[test]
fn parameters_from_toml_defaults_and_checks() {
    let p: RegulariserParams = toml::from_str(
        "robust = true\norder = 2\nweights = \"auto\"\nmask = true\nmethod = \"divergence-free\"\nno_slip = {}\n\
         divergence_free = { cv_block = 8 }\npower_mask_db = -20.0\ns = 2.0\ntol_z = 1e-4\nmax_iter = 50\n\
         flavour = \"matlab\"\nweight_function = \"cauchy\"",
    )
    .unwrap();
    assert_eq!((p.method, p.divergence_free.cv_block, p.power_mask_db), (Method::DivergenceFree, 8, -20.0));
    assert_eq!(p.no_slip, Some(NoSlipParams::default()));
    let sp = p.smoothn(Some([2e-4, 1e-4]));
    assert_eq!((sp.s, sp.order, sp.robust, sp.tol_z, sp.max_iter), (Some(2.0), 2, true, 1e-4, 50));
    assert_eq!(sp.spacing, Some(vec![2e-4, 1e-4]));
    let d = RegulariserParams::default();
    assert!(d.smoothn.robust && d.mask && d.weights == WeightSource::Auto && d.method == Method::Smoothn);
    assert_eq!(
        (d.smoothn.s, d.smoothn.order, d.smoothn.tol_z, d.smoothn.max_iter, d.power_mask_db, d.no_slip),
        (None, 2, 1e-3, 100, -15.0, None)
    );
    assert!(toml::from_str::<RegulariserParams>("spacing = [1.0, 1.0]").is_err(), "not a node parameter");
    let check = |t: &str| toml::from_str::<RegulariserParams>(t).unwrap().validate().unwrap_err().to_string();
    let e = check("power_mask_db = 5.0");
    assert!(e.contains("power_mask_db") && e.contains("-100 ..= 0"), "{e}");
    let e = check("divergence_free = { cv_block = 1 }");
    assert!(e.starts_with("divergence_free: ") && e.contains("cv_block"), "{e}");
    let e = check("no_slip = { threshold_db = 3.0 }");
    assert!(e.contains("no_slip.threshold_db") && e.contains("−30 ..= −1"), "{e}");
    assert!(check("s = 0.0").contains("`s` = 0"));
    assert!(check("order = 5").contains("1, 2 or 3"));
    assert!(toml::from_str::<RegulariserParams>("no_slip = { wall = 3.0 }").is_err());
}

/// The smoothn keys of the table are `SmoothnParams` itself (no copy): values and errors come
/// from it; `robust` defaults to true unless given; an unknown key's error lists both sets of
/// keys; errors inside a nested table keep their path.
#[test]
fn smoothn_keys_deserialise_into_smoothn_params() {
    let p: RegulariserParams = toml::from_str("order = 3\ntol_z = 0.01\nmax_iter = 7\nmask = false").unwrap();
    let expect = SmoothnParams { order: 3, tol_z: 0.01, max_iter: 7, robust: true, ..SmoothnParams::default() };
    assert_eq!(p.smoothn, expect);
    assert!(!p.mask);
    let p: RegulariserParams = toml::from_str("robust = false").unwrap();
    assert!(!p.smoothn.robust, "a given robust is kept");
    let e = toml::from_str::<RegulariserParams>("ordr = 2").unwrap_err().to_string();
    assert!(e.contains("unknown field `ordr`") && e.contains("`power_mask_db`") && e.contains("`max_iter`"), "{e}");
    let e = toml::from_str::<RegulariserParams>("max_iter = \"many\"").unwrap_err().to_string();
    assert!(e.contains("max_iter: invalid type: string \"many\""), "{e}");
    let e = toml::from_str::<RegulariserParams>("divergence_free = { cv_blok = 8 }").unwrap_err().to_string();
    assert!(e.contains("divergence_free") && e.contains("unknown field `cv_blok`"), "{e}");
}
