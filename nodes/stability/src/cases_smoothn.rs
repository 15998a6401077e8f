//! smoothn cases (the runs of `nodes/regularise/tests/extremes.rs` and `robustness.rs`, from
//! `sonoflow_regularise::testkit`, plus 90 % missing data and 200 decades of scale), and the
//! divergence-free regulariser (`smoothn::divfree`): no data, 200 decades of scale, extreme noise
//! anisotropy, the smallest grid, a one-pixel-wide data line and the S bounds (conditioning).

use super::{Case, CaseResult, Check, Ctx, Expected, OrMessage, Stage};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use sonoflow_regularise::divfree::divergence;
use sonoflow_regularise::testkit::{
    corrupt, nan_and_infinity_runs, outlier_scene, random_mask, rms_diff, robust_auto, smooth_field, OutlierScene,
    OUTLIER_GRID,
};
use sonoflow_regularise::{smoothn, DivFree, DivFreeParams, SmoothnParams};

pub(super) fn cases() -> Vec<Case> {
    vec![
        Stage::Smoothn.case(
            "all-nan",
            "a 2-component 5 x 6 field that is NaN everywhere",
            Expected::ClearError(&["no valid data", "30 grid points"]),
            all_nan,
        ),
        Stage::Smoothn.case(
            "all-zero-weights",
            "finite data with every weight 0",
            Expected::ClearError(&["no valid data"]),
            zero_weights,
        ),
        Stage::Smoothn.case(
            "infinities-like-nan",
            "±inf at 5 points where another run has NaN (robust, automatic S); check: bit-identical results, finite",
            Expected::Pass,
            infinities,
        ),
        Stage::Smoothn.case(
            "90pc-missing",
            "a smooth 64 x 64 vector field with 90 % of the points missing at random and noise sigma = 0.05; check: \
             converged, finite, RMS error of the filled field < 0.1 (a zero or mean fill is off by ~0.6)",
            Expected::Pass,
            missing_90,
        ),
        Stage::Smoothn.case(
            "10pc-gross-outliers",
            "noise sigma = 0.1 plus 10 % of the points replaced by uniform values in ±2.5, robust bisquare; check: RMS \
             error < 0.3 x the non-robust error and < 2 x the outlier-free error",
            Expected::Pass,
            outliers,
        ),
        Stage::Smoothn.case(
            "scale-1e-100-and-1e100",
            "the same noisy field multiplied by 1e-100 and by 1e100 (automatic S); check: S identical and the result \
             scales exactly (relative 1e-9): no underflow/overflow in the GCV sums",
            Expected::Pass,
            scale_extremes,
        ),
        Stage::Smoothn.case(
            "constant-field",
            "a constant field (robust, automatic S, and S = 1e3); check: returned unchanged to 1e-13",
            Expected::Pass,
            constant,
        ),
        Stage::Smoothn.case(
            "one-by-one-grid",
            "a 1 x 1 grid with 2 components (robust): nothing to smooth; check: the value is returned",
            Expected::Pass,
            one_by_one,
        ),
        Stage::Smoothn.case(
            "order-7",
            "penalty order 7 (allowed 1, 2, 3)",
            Expected::ClearError(&["`order` = 7", "1, 2 or 3"]),
            order_7,
        ),
        Stage::Smoothn.case(
            "negative-weight",
            "a weight of -0.5 at grid index 4",
            Expected::ClearError(&["weight at grid index 4", "finite and ≥ 0"]),
            negative_weight,
        ),
        Stage::Smoothn.case(
            "divfree-all-missing",
            "divergence-free fit of a 12 x 16 field that is NaN everywhere",
            Expected::ClearError(&["no valid data"]),
            df_all_missing,
        ),
        Stage::Smoothn.case(
            "divfree-scale-1e-100-and-1e100",
            "divergence-free fit (robust, block-CV S, estimated noise ratio) of a noisy channel flow multiplied by \
             1e-100 and 1e100; check: same S (relative 1e-9) and noise ratio, the result scales (relative 1e-6: the system's \
             conditioning amplifies the last-bit differences of the scaled data)",
            Expected::Pass,
            df_scale,
        ),
        Stage::Smoothn.case(
            "divfree-noise-ratio-1000",
            "noise ratio sigma_x/sigma_z = 1000 (the lateral data carry no weight) and 0.001 (the axial none), data \
             noisy accordingly (sigma 0.05 vs 0.001 m/s), S by block CV; check: finite, divergence-free to 1e-12, the \
             well-weighted component within 2 % of u0",
            Expected::Pass,
            df_anisotropy,
        ),
        Stage::Smoothn.case(
            "divfree-smallest-grid",
            "a 5 x 5 grid (order 3 needs >= 5 per axis), robust, automatic S; check: finite, divergence-free",
            Expected::Pass,
            df_smallest,
        ),
        Stage::Smoothn.case(
            "divfree-one-pixel-line",
            "data on a single row of a 30 x 40 grid only (everything else missing); check: finite everywhere, \
             the row's vx reproduced within 1 % of u0",
            Expected::Pass,
            df_line,
        ),
        Stage::Smoothn.case(
            "divfree-s-1e-6-and-1e9",
            "given S = 1e-6 and S = 1e9 (12 decades of conditioning) on a noisy channel; check: both factorise, \
             finite, divergence-free to 1e-12",
            Expected::Pass,
            df_s_bounds,
        ),
        Stage::Smoothn.case(
            "divfree-no-slip-extremes",
            "no-slip wall from a power plane that is NaN, negative or zero everywhere (no wall may come out), and \
             the largest prior weight (100) on every pixel outside a noisy channel; check: no wall from degenerate \
             power, the fit finite and divergence-free to 1e-12, the channel's centre speed within 5 % of u0",
            Expected::Pass,
            df_no_slip,
        ),
    ]
}

/// Poiseuille channel along x (width 60 % of the grid height, u0 = 0.5 m/s) with N(0, σ²) noise,
/// σx = 0.05, σz = 0.01 (the vector-Doppler anisotropy); returns (ux, uz, tx, tz, mask).
#[allow(clippy::type_complexity)]
fn df_channel(nz: usize, nx: usize, seed: u64) -> Result<(Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>), String> {
    df_channel_noise(nz, nx, seed, 0.05, 0.01)
}

/// [`df_channel`] with noise levels `sx`, `sz`.
#[allow(clippy::type_complexity)]
fn df_channel_noise(
    nz: usize,
    nx: usize,
    seed: u64,
    sx: f64,
    sz: f64,
) -> Result<(Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>), String> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (nxn, nzn) = (Normal::new(0.0, sx).msg()?, Normal::new(0.0, sz).msg()?);
    let n = nz * nx;
    let (mut ux, mut uz, mut tx, tz, mut m) = (vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    for i in 0..nz {
        let q = (i as f64 - (nz as f64 - 1.0) / 2.0) / (0.3 * nz as f64);
        for j in 0..nx {
            let p = i * nx + j;
            if q.abs() <= 1.0 {
                tx[p] = 0.5 * (1.0 - q * q);
                m[p] = 1.0;
            }
            ux[p] = tx[p] + nxn.sample(&mut rng);
            uz[p] = tz[p] + nzn.sample(&mut rng);
        }
    }
    Ok((ux, uz, tx, tz, m))
}

fn max_div(vx: &[f64], vz: &[f64], shape: [usize; 2]) -> f64 {
    let vmax = vx.iter().chain(vz).fold(0.0f64, |a, v| a.max(v.abs()));
    let d = divergence(vx, vz, shape, [2e-4, 2e-4]).iter().fold(0.0f64, |a, v| a.max(v.abs()));
    if vmax > 0.0 {
        d * 2e-4 / vmax
    } else {
        0.0
    }
}

fn df_all_missing(_: &Ctx) -> CaseResult {
    let f = DivFree::new([12, 16], [2e-4, 2e-4], 3).msg()?;
    let (mut vx, mut vz) = (vec![0.0; 192], vec![0.0; 192]);
    f.fit(&[f64::NAN; 192], &[f64::NAN; 192], None, &DivFreeParams::default(), &mut vx, &mut vz)
        .map(|_| Check::new(false, "returned a result from no data"))
        .msg()
}

fn df_scale(_: &Ctx) -> CaseResult {
    let (nz, nx) = (24, 32);
    let (ux, uz, _, _, m) = df_channel(nz, nx, 31)?;
    let f = DivFree::new([nz, nx], [2e-4, 2e-4], 3).msg()?;
    let p = DivFreeParams::default();
    let (mut ax, mut az) = (vec![0.0; nz * nx], vec![0.0; nz * nx]);
    let r1 = f.fit(&ux, &uz, Some(&m), &p, &mut ax, &mut az).msg()?;
    let mut ok = true;
    let mut parts = vec![];
    for scale in [1e-100, 1e100] {
        let (sx, sz): (Vec<f64>, Vec<f64>) =
            (ux.iter().map(|v| v * scale).collect(), uz.iter().map(|v| v * scale).collect());
        let (mut bx, mut bz) = (vec![0.0; nz * nx], vec![0.0; nz * nx]);
        let rs = f.fit(&sx, &sz, Some(&m), &p, &mut bx, &mut bz).msg()?;
        let vmax = ax.iter().chain(&az).fold(0.0f64, |a, v| a.max(v.abs()));
        let rel =
            bx.iter().chain(&bz).zip(ax.iter().chain(&az)).map(|(b, a)| (b / scale - a).abs()).fold(0.0, f64::max)
                / vmax;
        ok &= (rs.s / r1.s - 1.0).abs() < 1e-9 && (rs.noise_ratio / r1.noise_ratio - 1.0).abs() < 1e-12 && rel < 1e-6;
        parts.push(format!("x{scale:e}: S {:.3} ({:.3}), max relative deviation {rel:.1e}", rs.s, r1.s));
    }
    Ok(Check::new(ok, parts.join("; ")))
}

fn df_anisotropy(_: &Ctx) -> CaseResult {
    let (nz, nx) = (24, 32);
    let f = DivFree::new([nz, nx], [2e-4, 2e-4], 3).msg()?;
    let mut parts = vec![];
    let mut ok = true;
    for ratio in [1000.0, 1e-3] {
        // the data match the stated ratio: noisy x and precise z, or the reverse
        let (sx, sz) = if ratio > 1.0 { (0.05, 0.001) } else { (0.001, 0.05) };
        let (ux, uz, tx, tz, m) = df_channel_noise(nz, nx, 32, sx, sz)?;
        let p = DivFreeParams { noise_ratio: Some(ratio), ..Default::default() };
        let (mut vx, mut vz) = (vec![0.0; nz * nx], vec![0.0; nz * nx]);
        let r = f.fit(&ux, &uz, Some(&m), &p, &mut vx, &mut vz).msg()?;
        let fin = vx.iter().chain(&vz).all(|v| v.is_finite());
        let div = max_div(&vx, &vz, [nz, nx]);
        // the component that keeps its weight: z for ratio 1000, x for 0.001
        let (est, truth) = if ratio > 1.0 { (&vz, &tz) } else { (&vx, &tx) };
        let err = (0..nz * nx).filter(|&p| m[p] > 0.0).map(|p| (est[p] - truth[p]).abs()).fold(0.0, f64::max) / 0.5;
        ok &= fin && div < 1e-12 && err < 0.02;
        parts.push(format!(
            "ratio {ratio}: S {:.3e}, finite {fin}, div {div:.1e}, max error {:.2} % of u0",
            r.s,
            100.0 * err
        ));
    }
    Ok(Check::new(ok, parts.join("; ")))
}

fn df_smallest(_: &Ctx) -> CaseResult {
    let (ux, uz, _, _, _) = df_channel(5, 5, 33)?;
    let f = DivFree::new([5, 5], [2e-4, 2e-4], 3).msg()?;
    let (mut vx, mut vz) = (vec![0.0; 25], vec![0.0; 25]);
    let r = f.fit(&ux, &uz, None, &DivFreeParams::default(), &mut vx, &mut vz).msg()?;
    let fin = vx.iter().chain(&vz).all(|v| v.is_finite());
    let div = max_div(&vx, &vz, [5, 5]);
    Ok(Check::new(fin && div < 1e-12, format!("S {:.3e}, finite {fin}, divergence {div:.1e}", r.s)))
}

fn df_line(_: &Ctx) -> CaseResult {
    let (nz, nx) = (30, 40);
    let n = nz * nx;
    let (mut ux, uz) = (vec![f64::NAN; n], vec![f64::NAN; n]);
    let mut uz = uz;
    for j in 0..nx {
        ux[15 * nx + j] = 0.5;
        uz[15 * nx + j] = 0.0;
    }
    let f = DivFree::new([nz, nx], [2e-4, 2e-4], 3).msg()?;
    let (mut vx, mut vz) = (vec![0.0; n], vec![0.0; n]);
    let r = f.fit(&ux, &uz, None, &DivFreeParams::default(), &mut vx, &mut vz).msg()?;
    let fin = vx.iter().chain(&vz).all(|v| v.is_finite());
    let err = (0..nx).map(|j| (vx[15 * nx + j] - 0.5).abs()).fold(0.0, f64::max) / 0.5;
    Ok(Check::new(
        fin && err < 0.01,
        format!("S {:.3e}, finite everywhere {fin}, max error on the row {:.3} % of u0", r.s, 100.0 * err),
    ))
}

fn df_s_bounds(_: &Ctx) -> CaseResult {
    let (nz, nx) = (24, 32);
    let (ux, uz, _, _, m) = df_channel(nz, nx, 34)?;
    let f = DivFree::new([nz, nx], [2e-4, 2e-4], 3).msg()?;
    let mut parts = vec![];
    let mut ok = true;
    for s in [1e-6, 1e9] {
        let p = DivFreeParams { s: Some(s), ..Default::default() };
        let (mut vx, mut vz) = (vec![0.0; nz * nx], vec![0.0; nz * nx]);
        f.fit(&ux, &uz, Some(&m), &p, &mut vx, &mut vz).msg()?;
        let fin = vx.iter().chain(&vz).all(|v| v.is_finite());
        let div = max_div(&vx, &vz, [nz, nx]);
        ok &= fin && div < 1e-12;
        parts.push(format!("S = {s:e}: finite {fin}, divergence {div:.1e}"));
    }
    Ok(Check::new(ok, parts.join("; ")))
}

fn all_nan(_: &Ctx) -> CaseResult {
    smoothn(&[f64::NAN; 60], &[5, 6], 2, None, &SmoothnParams::default())
        .map(|_| Check::new(false, "returned a result from no data"))
        .msg()
}

fn zero_weights(_: &Ctx) -> CaseResult {
    smoothn(&[1.0; 60], &[5, 6], 2, Some(&[0.0; 30]), &SmoothnParams::default())
        .map(|_| Check::new(false, "returned a result with every weight 0"))
        .msg()
}

fn infinities(_: &Ctx) -> CaseResult {
    let [(a, ra), (b, rb)] = nan_and_infinity_runs();
    let same = a.len() == b.len() && a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()) && ra == rb;
    let fin = a.iter().all(|v| v.is_finite());
    Ok(Check::new(same && fin, format!("bit-identical: {same}, finite: {fin}, S = {:.3e}", ra.s)))
}

fn missing_90(_: &Ctx) -> CaseResult {
    let (ny, nx) = (64, 64);
    let n = ny * nx;
    let truth = smooth_field(ny, nx);
    let (mut y, _) = corrupt(&truth, 2, 0.05, 0.0, 12);
    let holes = random_mask(n, 0.9, 13);
    let missing = holes.iter().filter(|h| **h).count();
    for p in (0..n).filter(|&p| holes[p]) {
        y[p] = f64::NAN;
        y[n + p] = f64::NAN;
    }
    let (z, r) = smoothn(&y, &[ny, nx], 2, None, &SmoothnParams::default()).msg()?;
    let fin = z.iter().all(|v| v.is_finite());
    let e = rms_diff(&z, &truth);
    Ok(Check::new(
        r.converged && fin && e < 0.1,
        format!(
            "{:.1} % missing: RMS error {e:.4} (noise 0.05), converged {} after {} iterations, S = {:.3e}",
            100.0 * missing as f64 / n as f64,
            r.converged,
            r.iterations,
            r.s
        ),
    ))
}

fn outliers(_: &Ctx) -> CaseResult {
    let OutlierScene { truth, y, e_clean: ec, e_plain: e0, .. } = outlier_scene(11);
    let (z, r) = smoothn(&y, &OUTLIER_GRID, 2, None, &robust_auto()).msg()?;
    let e = rms_diff(&z, &truth);
    Ok(Check::new(
        e < 0.3 * e0 && e < 2.0 * ec && r.converged,
        format!(
            "RMS error robust {e:.4}, non-robust {e0:.4}, outlier-free {ec:.4}; {:.1} % flagged as outliers",
            100.0 * r.outlier_fraction
        ),
    ))
}

fn scale_extremes(_: &Ctx) -> CaseResult {
    let (ny, nx) = (32, 32);
    let (y, _) = corrupt(&smooth_field(ny, nx), 2, 0.1, 0.0, 21);
    let (z1, r1) = smoothn(&y, &[ny, nx], 2, None, &SmoothnParams::default()).msg()?;
    let mut parts = vec![];
    let mut ok = true;
    for scale in [1e-100, 1e100] {
        let ys: Vec<f64> = y.iter().map(|v| v * scale).collect();
        let (zs, rs) = smoothn(&ys, &[ny, nx], 2, None, &SmoothnParams::default()).msg()?;
        let rel = zs.iter().zip(&z1).map(|(a, b)| (a / scale - b).abs()).fold(0.0, f64::max)
            / z1.iter().map(|v| v.abs()).fold(0.0, f64::max);
        let s_rel = (rs.s / r1.s - 1.0).abs();
        ok &= rel.is_finite() && rel <= 1e-9 && s_rel <= 1e-9;
        parts.push(format!("x{scale:e}: result off by {rel:.1e}, S off by {s_rel:.1e}"));
    }
    Ok(Check::new(ok, format!("S = {:.3e}; {}", r1.s, parts.join("; "))))
}

fn constant(_: &Ctx) -> CaseResult {
    let (ny, nx) = (12, 17);
    let n = ny * nx;
    let y: Vec<f64> = (0..2 * n).map(|i| if i < n { 2.5 } else { -1.25 }).collect();
    let mut worst: f64 = 0.0;
    for p in [robust_auto(), SmoothnParams { s: Some(1e3), ..SmoothnParams::default() }] {
        let (z, r) = smoothn(&y, &[ny, nx], 2, None, &p).msg()?;
        let d = z.iter().zip(&y).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        worst = if d.is_nan() || !(r.s.is_finite() && r.s > 0.0) { f64::NAN } else { worst.max(d) };
    }
    Ok(Check::new(worst < 1e-13, format!("largest change {worst:.1e}")))
}

fn one_by_one(_: &Ctx) -> CaseResult {
    let (z, r) = smoothn(&[3.0, -2.0], &[1, 1], 2, None, &robust_auto()).msg()?;
    Ok(Check::new(z == [3.0, -2.0] && r.converged, format!("returned {z:?}, converged {}", r.converged)))
}

fn order_7(_: &Ctx) -> CaseResult {
    smoothn(&[1.0, 2.0], &[2], 1, None, &SmoothnParams { order: 7, ..SmoothnParams::default() })
        .map(|_| Check::new(true, "accepted order 7"))
        .msg()
}

fn negative_weight(_: &Ctx) -> CaseResult {
    let mut w = vec![1.0; 12];
    w[4] = -0.5;
    smoothn(&[0.0; 12], &[3, 4], 1, Some(&w), &SmoothnParams::default())
        .map(|_| Check::new(true, "accepted a negative weight"))
        .msg()
}

fn df_no_slip(_: &Ctx) -> CaseResult {
    use sonoflow_regularise::{wall_from_power, NoSlipParams};
    let (nz, nx) = (24, 32);
    let n = nz * nx;
    let mut parts = vec![];
    let mut ok = true;
    for (name, v) in [("NaN", f64::NAN), ("negative", -1.0), ("zero", 0.0)] {
        let wall =
            wall_from_power(&vec![v; n], &vec![true; n], [nz, nx], [2e-4, 2e-4], &NoSlipParams::default()).msg()?;
        let k = wall.iter().filter(|w| **w).count();
        ok &= k == 0;
        parts.push(format!("{name} power: {k} wall pixels"));
    }
    let (ux, uz, _, _, m) = df_channel(nz, nx, 35)?;
    let prior: Vec<f64> = m.iter().map(|v| if *v > 0.0 { 0.0 } else { 100.0 }).collect();
    let f = DivFree::new([nz, nx], [2e-4, 2e-4], 3).msg()?;
    let (mut vx, mut vz) = (vec![0.0; n], vec![0.0; n]);
    f.fit_with_wall(&ux, &uz, Some(&m), Some(&prior), &DivFreeParams::default(), None, &mut vx, &mut vz).msg()?;
    let fin = vx.iter().chain(&vz).all(|v| v.is_finite());
    let div = max_div(&vx, &vz, [nz, nx]);
    let centre = vx[(nz / 2) * nx + nx / 2];
    let err = ((centre - 0.5) / 0.5).abs();
    ok &= fin && div < 1e-12 && err < 0.05;
    parts.push(format!("prior 100 outside: finite {fin}, divergence {div:.1e}, centre {centre:.4} m/s"));
    Ok(Check::new(ok, parts.join("; ")))
}
