//! `sonoflow bmode`: the B-mode batch tool (MUST `bmode`, optionally after MUST `tgc`), a thin
//! wrapper of `sonoflow_beamform::{bmode, tgc_gain}`.
//!
//! I/Q `.npy` (complex64/complex128, any shape; axis 0 is time or depth, as `sonoflow das`
//! writes `(nz, nx)` and MUST keeps packets `(nz, nx, n_frames)`) → uint8 `.npy` of the same shape:
//! `255·(20·log10(|IQ|/max) + DR)/DR` clipped to [0, 255] (one maximum over the whole array, as
//! MUST). `--tgc` first multiplies every line (every index of the axes after the first) by MUST's
//! time-gain compensation along axis 0, fitted to the mean envelope over all lines. `--png` writes
//! the image (the first frame of a 3-axis packet) as a greyscale PNG, with square pixels when the
//! input's sidecar (`sonoflow das` writes one) gives the grid spacing. The sidecar `<out>.json`
//! records DR, the gain, the maximum envelope and the layout.

use crate::beamform::{check_out, read_sidecar, write_sidecar};
use std::path::PathBuf;

/// Arguments of `sonoflow bmode`.
#[derive(clap::Args, Debug)]
pub struct BmodeArgs {
    /// I/Q `.npy`, complex64/complex128, any shape with time or depth along axis 0 (`sonoflow das`
    /// writes (nz, nx); a packet is (nz, nx, n_frames)).
    #[arg(long)]
    pub iq: PathBuf,
    /// Dynamic range (dB), finite and > 0 (MUST `DR`; below 1 a power law |IQ/max|^DR, as MUST).
    #[arg(long = "dr", default_value_t = 40.0, allow_hyphen_values = true)]
    pub dr: f64,
    /// Time-gain compensation along axis 0 before compression (MUST `tgc`; needs ≥ 2 axes and
    /// ≥ 3 samples along axis 0).
    #[arg(long)]
    pub tgc: bool,
    /// Output `.npy`: uint8, the input's shape; the sidecar is the same name with `.json`.
    #[arg(long)]
    pub out: PathBuf,
    /// Also write the image as a greyscale PNG (2 axes, or the first frame of 3).
    #[arg(long)]
    pub png: Option<PathBuf>,
}

/// Runs `sonoflow bmode`.
pub fn run_bmode(a: &BmodeArgs) -> anyhow::Result<i32> {
    check_out(&a.out, &[&a.iq])?;
    if let Some(p) = &a.png {
        if p.extension().and_then(|e| e.to_str()) != Some("png") {
            anyhow::bail!("--png {}: must end in .png", p.display());
        }
    }
    if !(a.dr.is_finite() && a.dr > 0.0) {
        anyhow::bail!("--dr {}: the dynamic range must be finite and > 0 (dB; below 1 a power law)", a.dr);
    }
    let iq = sonoflow_fileio::npy::read_complex(&a.iq).map_err(|e| anyhow::anyhow!("--iq: {e}"))?;
    let shape = iq.shape.clone();
    if iq.data.is_empty() {
        anyhow::bail!("--iq {}: shape {shape:?} holds no samples", a.iq.display());
    }
    if let Some(i) = iq.data.iter().position(|c| !(c.re.is_finite() && c.im.is_finite())) {
        anyhow::bail!(
            "--iq {}: non-finite value at flat index {i} of shape {shape:?}; the data must be finite",
            a.iq.display()
        );
    }
    let mut data = iq.data;
    let mut gain_db = None;
    if a.tgc {
        if shape.len() < 2 {
            anyhow::bail!(
                "--tgc: --iq {} has shape {shape:?}; it needs ≥ 2 axes (time or depth first)",
                a.iq.display()
            );
        }
        let n_lines = data.len() / shape[0];
        let env = sonoflow_beamform::mean_envelope_iq(&data, n_lines).map_err(|e| anyhow::anyhow!("--tgc: {e}"))?;
        let gain = sonoflow_beamform::tgc_gain(&env).map_err(|e| anyhow::anyhow!("--tgc: {e}"))?;
        for (row, g) in data.chunks_exact_mut(n_lines).zip(&gain) {
            row.iter_mut().for_each(|z| *z *= *g);
        }
        let db = |g: f64| 20.0 * g.log10();
        gain_db = Some((db(gain[0]), db(gain[gain.len() - 1])));
    }
    let img = sonoflow_beamform::bmode(&data, a.dr).map_err(|e| anyhow::anyhow!("--dr/--iq: {e}"))?;
    let max_env = data.iter().map(|z| z.norm()).fold(0.0, f64::max);
    let side = read_sidecar(&a.iq, "--iq")?;
    let grid = side.as_ref().and_then(|(_, v)| v.get("grid")).cloned();
    // everything that can be refused is checked before the first file is written
    let png = match &a.png {
        Some(p) => Some((p, png_bytes(&shape, &img, grid.as_ref())?)),
        None => None,
    };
    sonoflow_fileio::npy::write_u8(&a.out, &shape, &img)?;
    let png = match png {
        Some((p, (bytes, w, h))) => {
            sonoflow_fileio::write_atomic(p, &bytes).map_err(|e| anyhow::anyhow!("--png {}: {e}", p.display()))?;
            Some((p.clone(), w, h))
        }
        None => None,
    };
    let sidecar = serde_json::json!({
        "input": a.iq.display().to_string(),
        "DR_dB": a.dr,
        "tgc": a.tgc,
        "tgc_gain_dB_first_last": gain_db.map(|(f, l)| [f, l]),
        "max_envelope": max_env,
        "grid": grid,
        "png": png.as_ref().map(|(p, w, h)| serde_json::json!({"path": p.display().to_string(), "width": w, "height": h})),
        "layout": "npy uint8, the input's shape; 255·(20·log10(|IQ|/max) + DR)/DR clipped to [0, 255] (MUST bmode)",
    });
    let side_out = write_sidecar(&a.out, &sidecar)?;
    let tgc = gain_db.map_or(String::new(), |(f, l)| format!(", tgc {f:+.1} → {l:+.1} dB"));
    println!(
        "{shape:?} I/Q → B-mode, DR {} dB{tgc}: {} (+ {}){}",
        a.dr,
        a.out.display(),
        side_out.display(),
        png.map_or(String::new(), |(p, w, h)| format!(", {} ({w} × {h})", p.display()))
    );
    Ok(0)
}

/// Writes `img` (2 axes (rows, cols), or the first frame of (rows, cols, frames)) as a greyscale
/// PNG; rows and columns repeated so pixels are square when `grid` gives `dx` and `dz` (each
/// repeat at most 16, the longer side at most 4096 pixels). Returns (PNG bytes, width, height).
fn png_bytes(shape: &[usize], img: &[u8], grid: Option<&serde_json::Value>) -> anyhow::Result<(Vec<u8>, u32, u32)> {
    let (rows, cols, frames) = match shape {
        [r, c] => (*r, *c, 1),
        [r, c, f] => (*r, *c, *f),
        _ => anyhow::bail!("--png: the image has shape {shape:?}; a PNG needs 2 axes (nz, nx) or 3 (nz, nx, n_frames)"),
    };
    let spacing = |k: &str| grid.and_then(|g| g.get(k)).and_then(serde_json::Value::as_f64).filter(|d| *d > 0.0);
    let (rep_z, rep_x) = match (spacing("dz"), spacing("dx")) {
        (Some(dz), Some(dx)) => {
            let r = |d: f64| ((d / dz.min(dx)).round() as usize).clamp(1, 16);
            (r(dz), r(dx))
        }
        _ => (1, 1),
    };
    let (h, w) = (rows * rep_z, cols * rep_x);
    if h.max(w) > 4096 {
        anyhow::bail!("--png: {w} × {h} pixels (after square-pixel scaling) exceeds 4096 on a side");
    }
    let mut rgb = Vec::with_capacity(3 * w * h);
    for r in 0..h {
        for c in 0..w {
            let v = img[((r / rep_z) * cols + c / rep_x) * frames];
            rgb.extend_from_slice(&[v, v, v]);
        }
    }
    Ok((sonoflow_evaluate::figures::encode_png(&rgb, w as u32, h as u32)?, w as u32, h as u32))
}
