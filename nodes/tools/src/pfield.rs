//! `sonoflow pfield`: MUST's PFIELD as a batch tool, a thin wrapper of
//! `sonoflow_simus::pfield_3d`: the RMS pressure field of one transmit of a linear or convex array on a
//! rectangular grid (in the imaging plane, or at an elevation `--y` off it) → float64 `.npy` of shape (nz, nx) and a JSON sidecar (grid, transmit,
//! frequency band); optionally a PNG of the field in dB.

use crate::simus::parse_file;
use sonoflow_simus::{MustParam, PfieldOptions, Probe, Transmit};
use std::path::{Path, PathBuf};

/// Arguments of `sonoflow pfield`.
#[derive(clap::Args, Debug)]
pub struct PfieldArgs {
    /// MUST-style parameters (`.json`/`.toml`: fc, pitch, kerf|width, Nelements, bandwidth, c,
    /// TXnow, TXdelay, TXapodization, attenuation, baffle) or a preset name (`L11-5v`, …).
    #[arg(long)]
    pub param: String,
    /// Grid `x0,dx,nx,z0,dz,nz` (m, m, count, m, m, count); pixel (ix, iz) at (x0 + ix·dx, z0 + iz·dz).
    #[arg(long, allow_hyphen_values = true)]
    pub grid: String,
    /// Plane wave tilted by this angle (degrees, |θ| < 90).
    #[arg(long, allow_hyphen_values = true)]
    pub tilt_deg: Option<f64>,
    /// Focused (`X,Z` with Z > 0) or diverging (virtual source, Z < 0) transmit, metres.
    #[arg(long, allow_hyphen_values = true)]
    pub focus: Option<String>,
    /// Transmit delays (s), comma-separated, one per element (NaN: element off).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub tx_delay: Option<Vec<f64>>,
    /// Elevation of the grid's plane (m): non-zero puts every point at this y, off the imaging
    /// plane, with MUST's elevation model (the probe's element `height` and elevation `focus`).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub y: f64,
    /// PFIELD options (`.json`/`.toml`: dBThresh, FrequencyStep, FullFrequencyDirectivity,
    /// ElementSplitting).
    #[arg(long)]
    pub options: Option<PathBuf>,
    /// MUST's quick options (−20 dB band, one sub-element, frequency step × 1.5).
    #[arg(long)]
    pub quick: bool,
    /// Output `.npy`: float64 (nz, nx); the sidecar is the same name with `.json`.
    #[arg(long)]
    pub out: PathBuf,
    /// Also write the field in dB (grey, 0 dB = its maximum, black at −`--png-dr` dB) as a PNG.
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// Dynamic range (dB) of the PNG, in [1, 200].
    #[arg(long, default_value_t = 40.0)]
    pub png_dr: f64,
}

/// Runs `sonoflow pfield`.
pub fn run_pfield(a: &PfieldArgs) -> anyhow::Result<i32> {
    if a.out.extension().and_then(|e| e.to_str()) != Some("npy") {
        anyhow::bail!("--out {}: must end in .npy", a.out.display());
    }
    if let Some(p) = &a.png {
        if p.extension().and_then(|e| e.to_str()) != Some("png") {
            anyhow::bail!("--png {}: must end in .png", p.display());
        }
    }
    if !(a.png_dr.is_finite() && (1.0..=200.0).contains(&a.png_dr)) {
        anyhow::bail!("--png-dr {}: must be in [1, 200] dB", a.png_dr);
    }
    let grid = crate::beamform::parse_grid(&a.grid)?;
    let p = Path::new(&a.param);
    let (probe, medium, param_tx) = if p.exists() {
        let parts = parse_file::<MustParam>(p)?.into_parts()?;
        (parts.probe, parts.medium, parts.transmit)
    } else {
        let probe = Probe::preset(&a.param)
            .map_err(|e| anyhow::anyhow!("--param {}: not a file, and not a preset: {e}", a.param))?;
        (probe, sonoflow_simus::Medium::default(), None)
    };
    let given = [a.tilt_deg.is_some(), a.focus.is_some(), a.tx_delay.is_some()].iter().filter(|b| **b).count();
    if given > 1 {
        anyhow::bail!("give one of --tilt-deg, --focus, --tx-delay");
    }
    let c = medium.c;
    let (transmit, what) = if let Some(t) = a.tilt_deg {
        if !(t.is_finite() && t.abs() < 90.0) {
            anyhow::bail!("--tilt-deg {t}: must be in (-90, 90)");
        }
        (Transmit::plane_wave(&probe, c, t.to_radians())?, format!("plane wave, {t:+}°"))
    } else if let Some(f) = &a.focus {
        let v: Vec<f64> = f
            .split(',')
            .map(|s| s.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|e| anyhow::anyhow!("--focus {f}: {e}; expected X,Z (m)"))?;
        let [x0, z0] = v[..] else { anyhow::bail!("--focus {f}: expected X,Z (m), two numbers") };
        if z0 > 0.0 {
            (Transmit::focused(&probe, c, x0, z0)?, format!("focused at ({x0}, {z0}) m"))
        } else if z0 < 0.0 {
            (Transmit::diverging(&probe, c, x0, z0)?, format!("diverging from ({x0}, {z0}) m"))
        } else {
            anyhow::bail!("--focus {f}: Z must be > 0 (focused) or < 0 (diverging), not 0");
        }
    } else if let Some(d) = &a.tx_delay {
        (Transmit { delays: d.clone(), apodization: Vec::new() }, "--tx-delay".to_string())
    } else if let Some(t) = param_tx {
        (t, "TXdelay of --param".to_string())
    } else {
        anyhow::bail!("give the transmit: --tilt-deg, --focus, --tx-delay, or TXdelay in a --param file");
    };
    let mut options: PfieldOptions = match &a.options {
        Some(f) => parse_file(f)?,
        None => PfieldOptions::default(),
    };
    if a.quick {
        options = PfieldOptions {
            db_thresh: -20.0,
            element_splitting: Some(1),
            full_frequency_directivity: false,
            frequency_step: 1.5,
        };
    }
    let (nx, nz) = (grid.nx, grid.nz);
    let (mut xs, mut zs) = (Vec::with_capacity(nx * nz), Vec::with_capacity(nx * nz));
    for iz in 0..nz {
        for ix in 0..nx {
            xs.push(grid.x0 + ix as f64 * grid.dx);
            zs.push(grid.z0 + iz as f64 * grid.dz);
        }
    }
    let start = std::time::Instant::now();
    let ys = vec![a.y; xs.len()];
    let field = sonoflow_simus::pfield_3d(&probe, &medium, &transmit, &xs, &ys, &zs, &options)
        .map_err(|e| anyhow::anyhow!("{e}").context(format!("--y {}", a.y)))?;
    let secs = start.elapsed().as_secs_f64();
    let max = field.rms.iter().copied().fold(0.0, f64::max);
    let png = match &a.png {
        Some(p) => {
            let img: Vec<u8> = field
                .rms
                .iter()
                .map(|v| {
                    let db = if max > 0.0 && *v > 0.0 { 20.0 * (v / max).log10() } else { -a.png_dr };
                    (255.0 * (db + a.png_dr) / a.png_dr).clamp(0.0, 255.0) as u8
                })
                .collect();
            let rgb: Vec<u8> = img.iter().flat_map(|v| [*v; 3]).collect();
            Some((p, sonoflow_evaluate::figures::encode_png(&rgb, nx as u32, nz as u32)?))
        }
        None => None,
    };
    sonoflow_fileio::npy::write_f64(&a.out, &[nz, nx], &field.rms)?;
    if let Some((p, bytes)) = &png {
        sonoflow_fileio::write_atomic(p, bytes).map_err(|e| anyhow::anyhow!("--png {}: {e}", p.display()))?;
    }
    let sidecar = serde_json::json!({
        "grid": grid,
        "y": a.y,
        "transmit": what,
        "delays": transmit.delays,
        "options": options,
        "df": field.df,
        "band_hz": [field.band_hz.0, field.band_hz.1],
        "n_freq": field.n_freq,
        "max": max,
        "seconds": secs,
        "layout": "npy float64 shape (nz, nx): RMS pressure (MUST pfield RP), pixel (iz, ix) at (x0 + ix·dx, z0 + iz·dz)",
    });
    let side = a.out.with_extension("json");
    sonoflow_fileio::write_atomic(&side, serde_json::to_string_pretty(&sidecar)?.as_bytes())?;
    println!(
        "{what}: {nz} × {nx} field, {} frequencies in {:.2}–{:.2} MHz, in {secs:.3} s: {} (+ {}){}",
        field.n_freq,
        field.band_hz.0 / 1e6,
        field.band_hz.1 / 1e6,
        a.out.display(),
        side.display(),
        a.png.as_ref().map_or(String::new(), |p| format!(", {}", p.display()))
    );
    Ok(0)
}
