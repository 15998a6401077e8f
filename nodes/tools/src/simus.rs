//! `sonoflow simus`: the SIMUS batch tool. Scatterers from CSV (`x,z,rc` columns, metres,
//! metres, amplitude; `x,y,z,rc` off the imaging plane: MUST's elevation model) or `.npy` (shape
//! (n, 3) or (n, 4)), MUST-style parameters from JSON or TOML, RF to
//! `.npy` of shape (n_samples, n_elements) plus a JSON sidecar with fs, t0 and the frequency plan.

use sonoflow_simus::{MustParam, Probe, Scatterers, Simus, SimusOptions, Transmit};
use std::path::{Path, PathBuf};

/// Arguments of `sonoflow simus`.
#[derive(clap::Args, Debug)]
pub struct SimusArgs {
    /// Scatterers: `.csv` with columns x,z,rc (header line optional) or `.npy` of shape (n, 3);
    /// with a y column (x,y,z,rc; (n, 4)) off the imaging plane, MUST's elevation model (element
    /// height and elevation focus of the probe).
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

pub(crate) fn parse_file<T: serde::de::DeserializeOwned>(path: &Path) -> anyhow::Result<T> {
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

/// Reads scatterers from CSV (`x,z,rc`, or `x,y,z,rc` off the imaging plane) or npy ((n, 3) or
/// (n, 4) with the same columns); the elevations y when the file has them.
pub fn read_scatterers(path: &Path) -> anyhow::Result<(Scatterers, Option<Vec<f32>>)> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    let mut rows: Vec<Vec<f64>> = Vec::new();
    let mut width = 0;
    match ext.as_str() {
        "npy" => {
            let a = sonoflow_fileio::npy::read(path)?;
            if a.shape.len() != 2 || !(a.shape[1] == 3 || a.shape[1] == 4) {
                anyhow::bail!(
                    "{}: shape {:?}, expected (n, 3) with columns x, z, rc or (n, 4) with x, y, z, rc",
                    path.display(),
                    a.shape
                );
            }
            width = a.shape[1];
            rows.extend(a.data.chunks_exact(width).map(<[f64]>::to_vec));
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
                    if cols != ["x", "z", "rc"] && cols != ["x", "y", "z", "rc"] {
                        anyhow::bail!("{}: header {:?}, expected x,z,rc or x,y,z,rc", path.display(), cols);
                    }
                    width = cols.len();
                    continue;
                }
                if width == 0 {
                    width = cols.len();
                }
                if cols.len() != width || !(width == 3 || width == 4) {
                    anyhow::bail!(
                        "{} line {}: {} columns, expected x,z,rc or x,y,z,rc throughout",
                        path.display(),
                        i + 1,
                        cols.len()
                    );
                }
                let v: Vec<f64> = cols
                    .iter()
                    .map(|c| c.parse::<f64>())
                    .collect::<Result<_, _>>()
                    .map_err(|e| anyhow::anyhow!("{} line {}: {e}", path.display(), i + 1))?;
                rows.push(v);
            }
        }
        _ => {
            anyhow::bail!("{}: scatterers must be .csv (x,z,rc or x,y,z,rc) or .npy ((n, 3) or (n, 4))", path.display())
        }
    }
    let col = |k: usize| rows.iter().map(|r| r[k] as f32).collect::<Vec<f32>>();
    if width == 4 {
        Ok((Scatterers::new(col(0), col(2), col(3))?, Some(col(1))))
    } else {
        Ok((Scatterers::new(col(0), col(1), col(2))?, None))
    }
}

/// Runs the batch tool.
pub fn run_simus(a: &SimusArgs) -> anyhow::Result<i32> {
    let (scat, y) = read_scatterers(&a.scatterers)?;
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
    let rf = match &y {
        Some(y) => simus.simulate_3d(&scat, y, &transmit)?,
        None => simus.simulate(&scat, &transmit)?,
    };
    let secs = start.elapsed().as_secs_f64();
    sonoflow_fileio::npy::write_f32(&a.out, &[rf.n_samples, n_el], true, &rf.data)?;
    let sidecar = serde_json::json!({
        "fs": rf.fs,
        "t0": rf.t0,
        "n_samples": rf.n_samples,
        "n_elements": n_el,
        "radius": simus.probe().convex_radius(),
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

/// Arguments of `sonoflow genscat`.
#[derive(clap::Args, Debug)]
pub struct GenscatArgs {
    /// Region `WIDTH,HEIGHT` (m): x in (−WIDTH/2, WIDTH/2), z in (z0, z0 + HEIGHT) (MUST `genscat`).
    #[arg(long)]
    pub region: String,
    /// Depth of the region's top edge (m); MUST: 0.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub z0: f64,
    /// Mean nearest-neighbour distance (m). Default: MUST's, c/(fc·(1 + bandwidth/200)) of `--param`.
    #[arg(long)]
    pub meandist: Option<f64>,
    /// Scatterers per resolution cell instead of `--meandist` (needs `--param`; the cell is
    /// c/(2·fc·bandwidth) axially × λ·F# laterally), in (0, 1000].
    #[arg(long)]
    pub per_cell: Option<f64>,
    /// Receive f-number of the resolution cell (`--per-cell` and the sidecar's count per cell), > 0.
    #[arg(long, default_value_t = 1.5)]
    pub fnumber: f64,
    /// Probe preset or MUST-style parameter file, for the default `--meandist`.
    #[arg(long)]
    pub param: Option<String>,
    /// Seed of positions and amplitudes (another seed moves every scatterer).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// An inclusion `x,z,radius[,level_dB]` (m, m, m, dB); without a level: anechoic. Repeatable;
    /// a later one overrides an earlier one where they overlap.
    #[arg(long = "inclusion", allow_hyphen_values = true)]
    pub inclusions: Vec<String>,
    /// Output `.npy`: float64 (n, 3) columns x, z, rc, as `sonoflow simus --scatterers` reads; the
    /// sidecar is the same name with `.json`.
    #[arg(long)]
    pub out: PathBuf,
}

/// Runs `sonoflow genscat`.
pub fn run_genscat(a: &GenscatArgs) -> anyhow::Result<i32> {
    if a.out.extension().and_then(|e| e.to_str()) != Some("npy") {
        anyhow::bail!("--out {}: must end in .npy", a.out.display());
    }
    let dims: Vec<f64> = a
        .region
        .split(',')
        .map(|v| v.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| anyhow::anyhow!("--region {}: {e}; expected WIDTH,HEIGHT (m)", a.region))?;
    let [width, height] = dims[..] else {
        anyhow::bail!("--region {}: expected WIDTH,HEIGHT (m), two numbers", a.region);
    };
    if !(a.fnumber.is_finite() && a.fnumber > 0.0) {
        anyhow::bail!("--fnumber {}: must be finite and > 0", a.fnumber);
    }
    // the probe and medium of --param, for MUST's default meandist and the resolution cell
    let probe = match &a.param {
        Some(param) => {
            let p = Path::new(param);
            Some(if p.exists() {
                let parts = parse_file::<MustParam>(p)?.into_parts()?;
                (parts.probe, parts.medium.c)
            } else {
                let probe = Probe::preset(param)
                    .map_err(|e| anyhow::anyhow!("--param {param}: not a file, and not a preset: {e}"))?;
                (probe, sonoflow_simus::Medium::default().c)
            })
        }
        None => None,
    };
    let cell = probe.as_ref().map(|(p, c)| sonoflow_simus::resolution_cell_area(*c, p.fc, p.bandwidth, a.fnumber));
    let (meandist, from) = match (a.meandist, a.per_cell, &probe) {
        (Some(_), Some(_), _) => anyhow::bail!("give --meandist or --per-cell, not both"),
        (Some(m), None, _) => (m, "--meandist".to_string()),
        (None, Some(n), _) if !(n.is_finite() && n > 0.0 && n <= 1000.0) => {
            anyhow::bail!("--per-cell {n}: must be in (0, 1000] scatterers per resolution cell")
        }
        (None, Some(n), Some(_)) => (
            sonoflow_simus::PhantomParams::meandist_for(n, cell.unwrap_or(f64::NAN)),
            format!("--per-cell {n} (cell {:.4} mm² at F# {})", cell.unwrap_or(f64::NAN) * 1e6, a.fnumber),
        ),
        (None, Some(_), None) => anyhow::bail!("--per-cell needs --param (the probe's fc and bandwidth set the cell)"),
        (None, None, Some((p, c))) => (
            sonoflow_simus::must_meandist(*c, p.fc, p.bandwidth),
            format!("MUST's default for --param {}", a.param.as_deref().unwrap_or("")),
        ),
        (None, None, None) => {
            anyhow::bail!("give --meandist (m), --per-cell N, or --param (a probe, for MUST's default meandist)")
        }
    };
    let mut inclusions = Vec::new();
    for s in &a.inclusions {
        let v: Vec<f64> = s
            .split(',')
            .map(|v| v.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|e| anyhow::anyhow!("--inclusion {s}: {e}; expected x,z,radius[,level_dB]"))?;
        let (x, z, radius, level_db) = match v[..] {
            [x, z, r] => (x, z, r, None),
            [x, z, r, db] => (x, z, r, Some(db)),
            _ => anyhow::bail!("--inclusion {s}: expected x,z,radius[,level_dB] (3 or 4 numbers)"),
        };
        inclusions.push(sonoflow_simus::Inclusion { x, z, radius, level_db });
    }
    let params =
        sonoflow_simus::PhantomParams { width, height, z0: a.z0, meandist, seed: a.seed, inclusions, image: None };
    let ph = sonoflow_simus::genscat(&params)?;
    let data: Vec<f64> = (0..ph.x.len()).flat_map(|i| [ph.x[i], ph.z[i], ph.rc[i]]).collect();
    sonoflow_fileio::npy::write_f64(&a.out, &[ph.x.len(), 3], &data)?;
    let sidecar = serde_json::json!({
        "scatterers": ph.x.len(),
        "region": {"x": [-width / 2.0, width / 2.0], "z": [a.z0, a.z0 + height]},
        "meandist": meandist,
        "meandist_from": from,
        "density_per_mm2": params.density() * 1e-6,
        "resolution_cell_mm2": cell.map(|a| a * 1e6),
        "fnumber": a.fnumber,
        "scatterers_per_cell": cell.map(|a| params.scatterers_per_cell(a)),
        "seed": a.seed,
        "inclusions": params.inclusions,
        "layout": "npy float64 shape (n, 3): x, z (m), rc (Rayleigh of mean 1 × inclusion level)",
    });
    let side = a.out.with_extension("json");
    sonoflow_fileio::write_atomic(&side, serde_json::to_string_pretty(&sidecar)?.as_bytes())?;
    println!(
        "{} scatterers ({:.1} per mm², meandist {:.3e} m, seed {}): {} (+ {})",
        ph.x.len(),
        params.density() * 1e-6,
        meandist,
        a.seed,
        a.out.display(),
        side.display()
    );
    Ok(0)
}
