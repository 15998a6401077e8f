//! `sonoflow simus`: the SIMUS batch tool. Scatterers from CSV (`x,z,rc` columns, metres,
//! metres, amplitude) or `.npy` (shape (n, 3)), MUST-style parameters from JSON or TOML, RF to
//! `.npy` of shape (n_samples, n_elements) plus a JSON sidecar with fs, t0 and the frequency plan.

use sonoflow_simus::{MustParam, Probe, Scatterers, Simus, SimusOptions, Transmit};
use std::path::{Path, PathBuf};

/// Arguments of `sonoflow simus`.
#[derive(clap::Args, Debug)]
pub struct SimusArgs {
    /// Scatterers: `.csv` with columns x,z,rc (header line optional) or `.npy` of shape (n, 3).
    #[arg(long)]
    pub scatterers: PathBuf,
    /// MUST-style parameters (`.json` or `.toml`): fc, pitch, kerf|width, Nelements, bandwidth,
    /// c, fs, TXnow, TXdelay, TXapodization, attenuation, baffle — or a preset name
    /// (`paper-5mhz`, `L11-5v`, …).
    #[arg(long)]
    pub param: String,
    /// SIMUS options file (`.json`/`.toml`, MUST `options`: dBThresh, FrequencyStep, accuracy, …).
    #[arg(long)]
    pub options: Option<PathBuf>,
    /// Transmit delays (s), comma-separated, one per element (overrides TXdelay).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub tx_delay: Option<Vec<f64>>,
    /// Plane-wave tilt in degrees (overrides TXdelay).
    #[arg(long, allow_hyphen_values = true)]
    pub tilt_deg: Option<f64>,
    /// Output `.npy` (float32, shape (n_samples, n_elements)); the sidecar is the same name with `.json`.
    #[arg(long)]
    pub out: PathBuf,
}

fn read_table(path: &Path) -> anyhow::Result<String> {
    std::fs::read_to_string(path).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
}

fn parse_file<T: serde::de::DeserializeOwned>(path: &Path) -> anyhow::Result<T> {
    let text = read_table(path)?;
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    match ext.as_str() {
        "json" => {
            let de = &mut serde_json::Deserializer::from_str(&text);
            serde_path_to_error::deserialize(de)
                .map_err(|e| anyhow::anyhow!("{}: {} ({})", path.display(), e.inner(), e.path()))
        }
        "toml" => toml::from_str(&text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display())),
        _ => anyhow::bail!("{}: use a .json or .toml file", path.display()),
    }
}

/// Reads scatterers from CSV or npy.
pub fn read_scatterers(path: &Path) -> anyhow::Result<Scatterers> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    let (mut x, mut z, mut rc) = (Vec::new(), Vec::new(), Vec::new());
    match ext.as_str() {
        "npy" => {
            let a = sonoflow_fileio::npy::read(path)?;
            if a.shape.len() != 2 || a.shape[1] != 3 {
                anyhow::bail!("{}: shape {:?}, expected (n, 3) with columns x, z, rc", path.display(), a.shape);
            }
            for r in a.data.chunks_exact(3) {
                x.push(r[0] as f32);
                z.push(r[1] as f32);
                rc.push(r[2] as f32);
            }
        }
        "csv" => {
            let text = read_table(path)?;
            for (i, line) in text.lines().enumerate() {
                let line = line.trim();
                if line.is_empty() || line.starts_with('#') {
                    continue;
                }
                let cols: Vec<&str> = line.split(',').map(str::trim).collect();
                if i == 0 && cols.iter().any(|c| c.parse::<f64>().is_err()) {
                    if cols != ["x", "z", "rc"] {
                        anyhow::bail!("{}: header {:?}, expected x,z,rc", path.display(), cols);
                    }
                    continue;
                }
                if cols.len() != 3 {
                    anyhow::bail!("{} line {}: {} columns, expected x,z,rc", path.display(), i + 1, cols.len());
                }
                let v: Vec<f64> = cols
                    .iter()
                    .map(|c| c.parse::<f64>())
                    .collect::<Result<_, _>>()
                    .map_err(|e| anyhow::anyhow!("{} line {}: {e}", path.display(), i + 1))?;
                x.push(v[0] as f32);
                z.push(v[1] as f32);
                rc.push(v[2] as f32);
            }
        }
        _ => anyhow::bail!("{}: scatterers must be .csv (x,z,rc) or .npy (n, 3)", path.display()),
    }
    Ok(Scatterers::new(x, z, rc)?)
}

/// Runs the batch tool.
pub fn run_simus(a: &SimusArgs) -> anyhow::Result<i32> {
    let scat = read_scatterers(&a.scatterers)?;
    let p = Path::new(&a.param);
    let (probe, medium, mut transmit, fs) = if p.exists() {
        let mp: MustParam = parse_file(p)?;
        let parts = mp.into_parts()?;
        (parts.probe, parts.medium, parts.transmit, parts.fs)
    } else {
        let probe = Probe::preset(&a.param)
            .map_err(|e| anyhow::anyhow!("--param {}: not a file, and not a preset: {e}", a.param))?;
        (probe, sonoflow_simus::Medium::default(), None, None)
    };
    let mut options: SimusOptions = match &a.options {
        Some(f) => parse_file(f)?,
        None => SimusOptions::default(),
    };
    if options.fs.is_none() {
        options.fs = fs;
    }
    if let Some(d) = &a.tx_delay {
        let t = Transmit { delays: d.clone(), apodization: Vec::new() };
        t.validate(probe.n_elements)?;
        transmit = Some(t);
    }
    if let Some(t) = a.tilt_deg {
        if !(t.is_finite() && t.abs() < 90.0) {
            anyhow::bail!("--tilt-deg {t} is out of range: (-90, 90)");
        }
        transmit = Some(Transmit::plane_wave(&probe, medium.c, t.to_radians())?);
    }
    let transmit = match transmit {
        Some(t) => t,
        None => Transmit::zero(probe.n_elements),
    };
    let n_el = probe.n_elements;
    let mut simus = Simus::new(probe, medium, options)?;
    let start = std::time::Instant::now();
    let rf = simus.simulate(&scat, &transmit)?;
    let secs = start.elapsed().as_secs_f64();
    sonoflow_fileio::npy::write_f32(&a.out, &[rf.n_samples, n_el], true, &rf.data)?;
    let sidecar = serde_json::json!({
        "fs": rf.fs,
        "t0": rf.t0,
        "n_samples": rf.n_samples,
        "n_elements": n_el,
        "layout": "npy shape (n_samples, n_elements), sample k at t0 + k/fs",
        "plan": rf.plan,
        "band_hz": [rf.plan.frequency(rf.plan.band_first), rf.plan.frequency(rf.plan.band_last)],
        "scatterers": scat.len(),
        "seconds": secs,
        "kernel": simus.kernel_name(),
    });
    let side = a.out.with_extension("json");
    sonoflow_fileio::write_atomic(&side, serde_json::to_string_pretty(&sidecar)?.as_bytes())?;
    println!(
        "{} scatterers → {} samples × {} elements in {:.3} s: {} (+ {})",
        scat.len(),
        rf.n_samples,
        n_el,
        secs,
        a.out.display(),
        side.display()
    );
    Ok(0)
}
