//! `sonoflow smoothn`: the smoothn batch tool. Reads a field from `.npy` — shape
//! `(components, ny, nx)` (a vector field, components smoothed jointly) or `(ny, nx)` (a scalar
//! field); `--scalar` treats every axis of any array as a grid axis — smooths it with the
//! `sonoflow-regularise` library and writes the result (float64, same shape) plus a JSON sidecar
//! with the S used, convergence and the outlier fraction. NaN/±inf in the input are missing
//! values and are filled. `--divergence-free` fits a stream function instead (a `(2, nz, nx)`
//! field: vx then vz, rows along z; `sonoflow_regularise::divfree`).

use sonoflow_regularise::{
    wall_from_power, DivFree, DivFreeParams, Flavour, NoSlipParams, Smoothn, SmoothnParams, WeightFunction,
};
use std::path::{Path, PathBuf};

/// Arguments of `sonoflow smoothn`.
#[derive(clap::Args, Debug)]
pub struct SmoothnArgs {
    /// Input `.npy`: (components, ny, nx) or (ny, nx); float32/float64/int. NaN = missing.
    #[arg(long = "in")]
    pub input: PathBuf,
    /// Output `.npy` (float64, same shape); the sidecar is the same name with `.json`.
    #[arg(long)]
    pub out: PathBuf,
    /// Robust smoothing (iteratively re-weighted; outliers down-weighted).
    #[arg(long)]
    pub robust: bool,
    /// Smoothing parameter S (> 0). Default: chosen by generalised cross-validation.
    #[arg(long, allow_hyphen_values = true)]
    pub s: Option<f64>,
    /// Penalty order: 1, 2 or 3.
    #[arg(long, default_value_t = 2)]
    pub order: u32,
    /// Weights `.npy` of the grid's shape (finite, ≥ 0; 0 = missing).
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// Robust weight function: bisquare, cauchy or talworth.
    #[arg(long, default_value = "bisquare")]
    pub weight_function: String,
    /// Grid spacing per grid axis, comma-separated (e.g. `--spacing 0.1e-3,0.2e-3` for (dy, dx)).
    #[arg(long, value_delimiter = ',')]
    pub spacing: Option<Vec<f64>>,
    /// Tolerance on the relative change between iterations, in (0, 1).
    #[arg(long, default_value_t = 1e-3)]
    pub tol_z: f64,
    /// Iteration limit per robust pass.
    #[arg(long, default_value_t = 100)]
    pub max_iter: u32,
    /// Follow `matlab` (default, Garcia's code) or reproduce `pymust` 0.1.9.
    #[arg(long, default_value = "matlab")]
    pub flavour: String,
    /// Treat every axis as a grid axis (a 3-D scalar field instead of components × 2-D).
    #[arg(long)]
    pub scalar: bool,
    /// Divergence-free (stream-function) fit of a (2, nz, nx) field (vx, vz): 2-D continuity
    /// holds exactly; `--s` absent: block cross-validation; `--order` 2 or 3 (use 3).
    #[arg(long)]
    pub divergence_free: bool,
    /// Divergence-free fit: noise ratio σ(vx)/σ(vz) (> 0). Default: estimated from the data.
    #[arg(long)]
    pub noise_ratio: Option<f64>,
    /// Divergence-free fit: block size of the cross-validation folds, pixels (2 ..= 4096).
    #[arg(long, default_value_t = 16)]
    pub cv_block: usize,
    /// Divergence-free fit: no-slip wall from the Doppler power `--power` (as the regulariser
    /// node's `no_slip`): pixels whose smoothed power is `--no-slip-db` below the blood's median
    /// get a zero-velocity prior of `--no-slip-weight`.
    #[arg(long)]
    pub no_slip: bool,
    /// Doppler power `.npy` of the grid's shape (for `--no-slip`).
    #[arg(long)]
    pub power: Option<PathBuf>,
    /// `--no-slip` threshold (dB below the blood's median power, −30 ..= −1).
    #[arg(long, allow_hyphen_values = true, default_value_t = NoSlipParams::default().threshold_db)]
    pub no_slip_db: f64,
    /// `--no-slip` prior weight relative to the largest data weight (0 < w ≤ 100).
    #[arg(long, default_value_t = NoSlipParams::default().weight)]
    pub no_slip_weight: f64,
}

/// Splits an array shape into (grid shape, components).
pub fn split_shape(shape: &[usize], scalar: bool) -> anyhow::Result<(Vec<usize>, usize)> {
    if shape.is_empty() || shape.contains(&0) {
        anyhow::bail!("--in: shape {shape:?} is empty; need (components, ny, nx) or (ny, nx) with every axis ≥ 1");
    }
    Ok(match (shape.len(), scalar) {
        (1 | 2, _) | (_, true) => (shape.to_vec(), 1),
        _ => (shape[1..].to_vec(), shape[0]),
    })
}

fn parse_enum<T: serde::de::DeserializeOwned>(field: &str, v: &str, allowed: &str) -> anyhow::Result<T> {
    serde_json::from_value(serde_json::Value::String(v.to_ascii_lowercase()))
        .map_err(|_| anyhow::anyhow!("--{field} {v}: allowed {allowed}"))
}

/// `--divergence-free`: the stream-function fit of a (2, nz, nx) field.
fn run_divergence_free(a: &SmoothnArgs, weight_function: WeightFunction) -> anyhow::Result<i32> {
    let arr = sonoflow_fileio::npy::read(&a.input)?;
    let [2, nz, nx] = arr.shape[..] else {
        anyhow::bail!(
            "--in {}: shape {:?}; --divergence-free needs (2, nz, nx): vx then vz",
            a.input.display(),
            arr.shape
        );
    };
    let spacing = match a.spacing.as_deref() {
        None => [1.0, 1.0],
        Some(&[dz, dx]) => [dz, dx],
        Some(sp) => anyhow::bail!("--spacing {sp:?}: --divergence-free needs two values dz,dx"),
    };
    let params = DivFreeParams {
        s: a.s,
        order: a.order,
        noise_ratio: a.noise_ratio,
        robust: a.robust,
        weight_function,
        cv_block: a.cv_block,
        ..Default::default()
    };
    params.validate()?;
    let n = nz * nx;
    let grid_file = |flag: &str, p: &PathBuf| -> anyhow::Result<Vec<f64>> {
        let w = sonoflow_fileio::npy::read(p)?;
        if w.shape != [nz, nx] {
            anyhow::bail!("--{flag} {}: shape {:?}, expected the grid shape [{nz}, {nx}]", p.display(), w.shape);
        }
        Ok(w.data)
    };
    let mut weights = a.weights.as_ref().map(|p| grid_file("weights", p)).transpose()?;
    // no-slip wall: the wall pixels' Doppler is dropped, a zero-velocity prior takes its place
    let ns = NoSlipParams { threshold_db: a.no_slip_db, weight: a.no_slip_weight, ..Default::default() };
    let prior = match (a.no_slip, &a.power) {
        (false, None) => None,
        (false, Some(_)) => anyhow::bail!("--power is only used with --no-slip"),
        (true, None) => anyhow::bail!("--no-slip needs --power (the Doppler power, grid shape [{nz}, {nx}])"),
        (true, Some(p)) => {
            let power = grid_file("power", p)?;
            let w = weights.get_or_insert_with(|| vec![1.0; n]);
            let blood: Vec<bool> =
                (0..n).map(|i| w[i] > 0.0 && arr.data[i].is_finite() && arr.data[n + i].is_finite()).collect();
            let wall = wall_from_power(&power, &blood, [nz, nx], spacing, &ns)
                .map_err(|e| anyhow::anyhow!("--no-slip-db / --no-slip-weight / --spacing: {e}"))?;
            for (wi, out) in w.iter_mut().zip(&wall) {
                if *out {
                    *wi = 0.0;
                }
            }
            Some(wall.iter().map(|out| if *out { ns.weight } else { 0.0 }).collect::<Vec<f64>>())
        }
    };
    let start = std::time::Instant::now();
    let f = DivFree::new([nz, nx], spacing, a.order)?;
    let (mut vx, mut vz) = (vec![0.0; n], vec![0.0; n]);
    let report = f.fit_with_wall(
        &arr.data[..n],
        &arr.data[n..],
        weights.as_deref(),
        prior.as_deref(),
        &params,
        None,
        &mut vx,
        &mut vz,
    )?;
    let secs = start.elapsed().as_secs_f64();
    vx.extend_from_slice(&vz);
    sonoflow_fileio::npy::write_f64(&a.out, &arr.shape, &vx)?;
    let sidecar = serde_json::json!({
        "method": "divergence-free",
        "report": report,
        "grid": [nz, nx],
        "spacing": spacing,
        "params": params,
        "no_slip": a.no_slip.then_some(&ns),
        "wall_pixels": prior.as_ref().map(|p| p.iter().filter(|v| **v > 0.0).count()),
        "seconds": secs,
    });
    let side = a.out.with_extension("json");
    sonoflow_fileio::write_atomic(&side, serde_json::to_string_pretty(&sidecar)?.as_bytes())?;
    println!(
        "divergence-free fit on [{nz}, {nx}]: S = {:.4e}{}, noise ratio {:.2}, {:.1} % outliers, {} factorisations, {:.3} s → {} (+ {})",
        report.s,
        if a.s.is_some() { " (given)" } else if report.s_from_gcv { " (GCV)" } else { " (block CV)" },
        report.noise_ratio,
        100.0 * report.outlier_fraction,
        report.factorisations,
        secs,
        a.out.display(),
        side.display()
    );
    Ok(0)
}

pub fn run_smoothn(a: &SmoothnArgs) -> anyhow::Result<i32> {
    if a.divergence_free {
        let weight_function: WeightFunction =
            parse_enum("weight-function", &a.weight_function, "bisquare, cauchy, talworth")?;
        return run_divergence_free(a, weight_function);
    }
    if a.no_slip || a.power.is_some() {
        anyhow::bail!("--no-slip and --power belong to --divergence-free");
    }
    let arr = sonoflow_fileio::npy::read(&a.input)?;
    let (grid, components) = split_shape(&arr.shape, a.scalar)?;
    let n: usize = grid.iter().product();
    let weight_function: WeightFunction =
        parse_enum("weight-function", &a.weight_function, "bisquare, cauchy, talworth")?;
    let flavour: Flavour = parse_enum("flavour", &a.flavour, "matlab, pymust")?;
    let params = SmoothnParams {
        s: a.s,
        order: a.order,
        robust: a.robust,
        weight_function,
        tol_z: a.tol_z,
        max_iter: a.max_iter,
        spacing: a.spacing.clone(),
        flavour,
    };
    params.validate()?;
    let weights = match &a.weights {
        Some(p) => {
            let w = sonoflow_fileio::npy::read(p)?;
            if w.shape != grid {
                anyhow::bail!("--weights {}: shape {:?}, expected the grid shape {:?}", p.display(), w.shape, grid);
            }
            if let Some((i, v)) = w.data.iter().enumerate().find(|(_, v)| !(v.is_finite() && **v >= 0.0)) {
                anyhow::bail!("--weights {}: value {v} at flat index {i}; weights must be finite and ≥ 0", p.display());
            }
            Some(w.data)
        }
        None => None,
    };
    let missing = arr.data.iter().filter(|v| !v.is_finite()).count();
    if missing == arr.data.len() {
        anyhow::bail!("--in {}: every value is NaN or infinite; nothing to smooth", a.input.display());
    }
    let start = std::time::Instant::now();
    let mut ws = Smoothn::new(&grid, components)?;
    let mut out = vec![0.0; n * components];
    let report = ws.smooth(&arr.data, weights.as_deref(), &params, &mut out)?;
    let secs = start.elapsed().as_secs_f64();
    sonoflow_fileio::npy::write_f64(&a.out, &arr.shape, &out)?;
    let sidecar = serde_json::json!({
        "s": report.s,
        "converged": report.converged,
        "outlier_fraction": report.outlier_fraction,
        "iterations": report.iterations,
        "gcv_evaluations": report.gcv_evaluations,
        "s_bounds": report.s_bounds,
        "s_at_bound": report.s_at_bound,
        "grid": grid,
        "components": components,
        "missing_values": missing,
        "params": params,
        "seconds": secs,
    });
    let side = a.out.with_extension("json");
    sonoflow_fileio::write_atomic(&side, serde_json::to_string_pretty(&sidecar)?.as_bytes())?;
    if report.s_at_bound {
        eprintln!(
            "warning: S = {:.3e} is at a bound of the GCV search {:?}: consider setting --s",
            report.s, report.s_bounds
        );
    }
    if !report.converged {
        eprintln!("warning: did not converge within --max-iter {} (raise it or --tol-z)", a.max_iter);
    }
    println!(
        "{components} component(s) on {grid:?}: S = {:.4e}{}, {} iterations, {:.1} % outliers, {} missing filled, {:.3} s → {} (+ {})",
        report.s,
        if a.s.is_some() { " (given)" } else { " (GCV)" },
        report.iterations,
        100.0 * report.outlier_fraction,
        missing,
        secs,
        a.out.display(),
        side.display()
    );
    Ok(0)
}

/// Path helper for tests: the sidecar of an output file.
pub fn sidecar(out: &Path) -> PathBuf {
    out.with_extension("json")
}
