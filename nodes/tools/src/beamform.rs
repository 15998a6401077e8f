//! `sonoflow rf2iq`, `sonoflow das`, `sonoflow doppler`: the beamforming batch tools on `.npy`
//! files, thin wrappers of the `sonoflow-beamform` library (MUST/PyMUST `rf2iq`, `dasmtx`,
//! `iq2doppler`).
//!
//! * `rf2iq`: RF `(n_samples, n_elements)` real (the layout `sonoflow simus` writes) → I/Q
//!   complex64 of the same shape, plus a sidecar `<out>.json` (fc, fs, t0, filter).
//! * `das`: I/Q `(n_samples, n_elements)` complex → delay-and-sum image complex64 `(nz, nx)` for a
//!   plane-wave transmit, plus a sidecar `<out>.json` (grid, angles, taps).
//! * `doppler`: packet `(nz, nx, n_frames)` complex → velocity float32 `(nz, nx)` (m/s, positive
//!   toward the probe), `<stem>_power.npy` float32, `<stem>_variance.npy` float32 (m²/s²),
//!   `<stem>_flags.npy` uint8 (bit 1 = no estimate, bit 2 = aliasing suspected), plus a sidecar
//!   `<out>.json` (Nyquist velocity, estimator, flagged-pixel counts). `loupas` uses the nominal
//!   axial delay step 2·dz/c (`--dz`), not a DAS plan's per-pixel geometry (the nodes do).
//!
//! Parameter files (`--param`, `.json` or `.toml`) use MUST's names; the tools read only the keys
//! they need and ignore every other key, so a `sonoflow simus` parameter file (pitch, kerf,
//! TXnow, …) can be given as is. Keys read ([`ToolParam`]):
//!
//! | key (aliases) | rf2iq | das | doppler |
//! |---|---|---|---|
//! | `fc` (Hz) | required | required | required |
//! | `fs` (Hz) | required¹ | required¹ | — |
//! | `t0` (s) | optional¹ (0) | optional¹ (0) | — |
//! | `bandwidth` (% of fc) | optional (cut-off `min(2fc/fs, 0.5)` without) | — | — |
//! | `c` (m/s) | — | optional (1540) | optional (1540) |
//! | `pitch` (m) | — | required | — |
//! | `Nelements` (`n_elements`, `nelements`) | — | optional (the I/Q's element count) | — |
//! | `radius` (m) | — | optional¹ (absent or inf: linear array; finite: convex, MUST's geometry) | — |
//! | `fnumber` | — | optional (0 = full aperture, MUST) | — |
//! | `RXangle` (`rx_angle`, `rxangle`, rad) | — | optional (0; `--rx-angle` wins) | — |
//! | `interpolation` (`linear`/`nearest`) | — | optional (linear) | — |
//! | `PRF` (`prf`, Hz) | — | — | required |
//!
//! ¹ When the parameter file lacks `fs`/`t0`/`radius`, they are taken from the input's JSON sidecar
//! (`rf.json` written by `sonoflow simus`, `iq.json` written by `sonoflow rf2iq`), and the
//! output line says so. `rf2iq --t0` overrides both.

use serde::Deserialize;
use sonoflow_beamform::{
    to_element_major, to_sample_major, DasParams, DasPlan, Grid, Interpolation, Rf2Iq, Rf2IqParams, RfView, TxWave, C32,
};
use sonoflow_doppler::{flags, ClutterParams, DopplerEstimator, DopplerParams, Estimator, Packet, WindowShape};
use std::path::{Path, PathBuf};

/// The MUST-named keys the beamforming tools read; every other key is ignored.
#[derive(Clone, Debug, Default, Deserialize)]
pub struct ToolParam {
    /// Centre (demodulation) frequency (Hz).
    pub fc: Option<f64>,
    /// RF/I/Q sampling frequency (Hz).
    pub fs: Option<f64>,
    /// Time of sample 0 (s).
    pub t0: Option<f64>,
    /// Bandwidth (% of fc) setting the rf2iq low-pass cut-off.
    pub bandwidth: Option<f64>,
    /// Speed of sound (m/s).
    pub c: Option<f64>,
    /// Element pitch (m).
    pub pitch: Option<f64>,
    /// Number of elements (MUST `Nelements`).
    #[serde(alias = "Nelements", alias = "nelements")]
    pub n_elements: Option<usize>,
    /// Radius of curvature (m, MUST `radius`): finite = convex array, inf or absent = linear.
    pub radius: Option<f64>,
    /// Receive f-number.
    pub fnumber: Option<f64>,
    /// Receive angle (rad, MUST `RXangle`).
    #[serde(alias = "RXangle", alias = "rxangle")]
    pub rx_angle: Option<f64>,
    /// DAS interpolation.
    pub interpolation: Option<Interpolation>,
    /// Receive apodisation (`boxcar`, MUST's, or `hann`).
    pub apodization: Option<sonoflow_beamform::Apodization>,
    /// Pulse repetition frequency (Hz, MUST `PRF`).
    #[serde(alias = "PRF")]
    pub prf: Option<f64>,
}

/// Arguments of `sonoflow rf2iq`.
#[derive(clap::Args, Debug)]
pub struct Rf2IqArgs {
    /// RF `.npy`, real (float32/float64/int), shape (n_samples, n_elements) as `sonoflow simus` writes.
    #[arg(long)]
    pub rf: PathBuf,
    /// Time of RF sample 0 (s); overrides `t0` of the param file and of the sidecar `<rf>.json`.
    #[arg(long, allow_hyphen_values = true)]
    pub t0: Option<f64>,
    /// MUST-style parameters (`.json`/`.toml`): fc, fs, bandwidth, t0 read; other keys ignored.
    #[arg(long)]
    pub param: PathBuf,
    /// Output `.npy`: complex64 (n_samples, n_elements); the sidecar is the same name with `.json`.
    #[arg(long)]
    pub out: PathBuf,
}

/// Arguments of `sonoflow das`.
#[derive(clap::Args, Debug)]
pub struct DasArgs {
    /// I/Q `.npy`, complex64/complex128, shape (n_samples, n_elements) as `sonoflow rf2iq` writes.
    #[arg(long)]
    pub iq: PathBuf,
    /// MUST-style parameters (`.json`/`.toml`): fc, c, fs, t0, pitch, Nelements, fnumber,
    /// RXangle, interpolation read; other keys ignored.
    #[arg(long)]
    pub param: PathBuf,
    /// Image grid `x0,dx,nx,z0,dz,nz` (m, m, count, m, m, count); pixel (ix, iz) at (x0 + ix·dx, z0 + iz·dz).
    #[arg(long, allow_hyphen_values = true)]
    pub grid: String,
    /// Receive steering angle (degrees, |θ| < 80; needs fnumber > 0 when ≠ 0). Default: RXangle (radians, MUST) of the param file, else 0.
    #[arg(long, allow_hyphen_values = true)]
    pub rx_angle: Option<f64>,
    /// Plane-wave transmit tilt (degrees, |θ| < 80; > 0 travels towards +x).
    #[arg(long, allow_hyphen_values = true, default_value_t = 0.0)]
    pub tx_angle: f64,
    /// Output `.npy`: complex64 (nz, nx); the sidecar is the same name with `.json`.
    #[arg(long)]
    pub out: PathBuf,
}

/// Arguments of `sonoflow doppler`.
#[derive(clap::Args, Debug)]
pub struct DopplerArgs {
    /// Packet `.npy`, complex64/complex128, shape (nz, nx, n_frames) (MUST's layout).
    #[arg(long)]
    pub packet: PathBuf,
    /// MUST-style parameters (`.json`/`.toml`): fc, c, PRF read; other keys ignored.
    #[arg(long)]
    pub param: PathBuf,
    /// Spatial Hamming window: `M` (M × M pixels) or `Mz,Mx` (rows, columns), each in [1, 64]. Default 1 (none).
    #[arg(long)]
    pub window: Option<String>,
    /// Slow-time lag in [1, 64]; the packet needs more than `lag` frames.
    #[arg(long, default_value_t = 1)]
    pub lag: usize,
    /// Estimator: `autocorrelation` (eq. 19, MUST iq2doppler) or `loupas` (2-D autocorrelator).
    #[arg(long, default_value = "autocorrelation")]
    pub estimator: String,
    /// Row spacing dz of the packet's grid (m), used by `loupas` for its nominal axial delay step 2·dz/c
    /// (0° transmit and receive). Default: `grid.dz` of the sidecar `<packet>.json` (as `sonoflow das` writes).
    #[arg(long, allow_hyphen_values = true)]
    pub dz: Option<f64>,
    /// Clutter (wall) filter before the estimator, as the Doppler node's `clutter` table in JSON:
    /// `{"type":"polynomial","order":1}`, `{"type":"iir","order":4,"cutoff":0.05}` (cut-off a
    /// fraction of the PRF), `{"type":"svd"}` (adaptive rank) or `{"type":"svd","rank":2}`.
    #[arg(long)]
    pub clutter: Option<String>,
    /// Output `.npy`: velocity float32 (nz, nx); also `<stem>_power.npy`, `<stem>_variance.npy`,
    /// `<stem>_flags.npy` and the sidecar `<stem>.json`.
    #[arg(long)]
    pub out: PathBuf,
}

fn parse_param(path: &Path) -> anyhow::Result<ToolParam> {
    let text = std::fs::read_to_string(path).map_err(|e| anyhow::anyhow!("--param {}: {e}", path.display()))?;
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    match ext.as_str() {
        "json" => {
            let de = &mut serde_json::Deserializer::from_str(&text);
            serde_path_to_error::deserialize(de)
                .map_err(|e| anyhow::anyhow!("--param {}: {} ({})", path.display(), e.inner(), e.path()))
        }
        "toml" => toml::from_str(&text).map_err(|e| anyhow::anyhow!("--param {}: {e}", path.display())),
        _ => anyhow::bail!("--param {}: use a .json or .toml file", path.display()),
    }
}

fn need(v: Option<f64>, key: &str, what: &str, param: &Path) -> anyhow::Result<f64> {
    v.ok_or_else(|| anyhow::anyhow!("--param {}: missing `{key}` ({what})", param.display()))
}

/// Checks that `--out` ends in `.npy` and that its sidecar would not overwrite an input.
pub(crate) fn check_out(out: &Path, inputs: &[&Path]) -> anyhow::Result<()> {
    if out.extension().and_then(|e| e.to_str()) != Some("npy") {
        anyhow::bail!("--out {}: must end in .npy", out.display());
    }
    let side = out.with_extension("json");
    let same = |a: &Path, b: &Path| a == b || matches!((a.canonicalize(), b.canonicalize()), (Ok(x), Ok(y)) if x == y);
    if let Some(p) = inputs.iter().find(|p| same(&side, p) || same(out, p)) {
        anyhow::bail!(
            "--out {}: it (or its sidecar {}) would overwrite the input {}",
            out.display(),
            side.display(),
            p.display()
        );
    }
    Ok(())
}

/// The JSON sidecar next to an input `.npy` (`x.npy` → `x.json`), if there is one.
pub(crate) fn read_sidecar(input: &Path, flag: &str) -> anyhow::Result<Option<(PathBuf, serde_json::Value)>> {
    let side = input.with_extension("json");
    if !side.is_file() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&side).map_err(|e| anyhow::anyhow!("{flag} sidecar {}: {e}", side.display()))?;
    let v: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| anyhow::anyhow!("{flag} sidecar {}: not valid JSON ({e}); fix or remove it", side.display()))?;
    if !v.is_object() {
        anyhow::bail!("{flag} sidecar {}: expected a JSON object; fix or remove it", side.display());
    }
    Ok(Some((side, v)))
}

/// A number in a sidecar, if present; an error if present but not a number.
fn sidecar_f64(side: &Option<(PathBuf, serde_json::Value)>, key: &str) -> anyhow::Result<Option<(f64, String)>> {
    let Some((path, v)) = side else { return Ok(None) };
    match v.get(key) {
        None | Some(serde_json::Value::Null) => Ok(None),
        Some(x) => {
            let f = x.as_f64().ok_or_else(|| {
                anyhow::anyhow!("sidecar {}: `{key}` = {x} is not a number; fix or remove it", path.display())
            })?;
            let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            Ok(Some((f, name)))
        }
    }
}

/// Rejects a sidecar whose recorded shape differs from the array (a stale sidecar).
fn check_sidecar_shape(side: &Option<(PathBuf, serde_json::Value)>, ns: usize, ne: usize) -> anyhow::Result<()> {
    if let Some((path, v)) = side {
        let get = |k: &str| v.get(k).and_then(|x| x.as_u64());
        if let (Some(a), Some(b)) = (get("n_samples"), get("n_elements")) {
            if (a, b) != (ns as u64, ne as u64) {
                anyhow::bail!(
                    "sidecar {}: describes {a} samples × {b} elements but the array is {ns} × {ne}; regenerate or remove it",
                    path.display()
                );
            }
        }
    }
    Ok(())
}

/// A value with where it came from.
fn pick(param: Option<f64>, side: Option<(f64, String)>) -> Option<(f64, String)> {
    match (param, side) {
        (Some(v), _) => Some((v, "--param".to_string())),
        (None, Some((v, name))) => Some((v, format!("sidecar {name}"))),
        (None, None) => None,
    }
}

fn warn_disagreement(key: &str, param: Option<f64>, side: &Option<(f64, String)>) {
    if let (Some(p), Some((s, name))) = (param, side) {
        if (p - s).abs() > 1e-9 * p.abs().max(s.abs()) {
            eprintln!("warning: `{key}` = {p} in --param differs from {s} in the sidecar {name}; using {p}");
        }
    }
}

fn check_finite_c(data: &[C32], flag: &str, path: &Path, shape: &[usize]) -> anyhow::Result<()> {
    if let Some(i) = data.iter().position(|c| !(c.re.is_finite() && c.im.is_finite())) {
        anyhow::bail!(
            "{flag} {}: non-finite value at flat index {i} of shape {shape:?}; the data must be finite",
            path.display()
        );
    }
    Ok(())
}

fn to_c32(data: &[sonoflow_beamform::Complex<f64>]) -> Vec<C32> {
    data.iter().map(|c| C32::new(c.re as f32, c.im as f32)).collect()
}

pub(crate) fn write_sidecar(out: &Path, v: &serde_json::Value) -> anyhow::Result<PathBuf> {
    let side = out.with_extension("json");
    sonoflow_fileio::write_atomic(&side, serde_json::to_string_pretty(v)?.as_bytes())
        .map_err(|e| anyhow::anyhow!("{}: {e}", side.display()))?;
    Ok(side)
}

/// Runs `sonoflow rf2iq`.
pub fn run_rf2iq(a: &Rf2IqArgs) -> anyhow::Result<i32> {
    check_out(&a.out, &[&a.rf, &a.param])?;
    let p = parse_param(&a.param)?;
    let rf = sonoflow_fileio::npy::read(&a.rf).map_err(|e| anyhow::anyhow!("--rf: {e}"))?;
    let [ns, ne] = rf.shape[..] else {
        anyhow::bail!(
            "--rf {}: shape {:?}, expected 2 axes (n_samples, n_elements) as `sonoflow simus` writes",
            a.rf.display(),
            rf.shape
        );
    };
    if let Some(i) = rf.data.iter().position(|v| !v.is_finite()) {
        anyhow::bail!(
            "--rf {}: non-finite value at sample {}, element {}; RF must be finite",
            a.rf.display(),
            i / ne.max(1),
            i % ne.max(1)
        );
    }
    let side = read_sidecar(&a.rf, "--rf")?;
    check_sidecar_shape(&side, ns, ne)?;
    let fc = need(p.fc, "fc", "centre frequency, Hz", &a.param)?;
    let side_fs = sidecar_f64(&side, "fs")?;
    warn_disagreement("fs", p.fs, &side_fs);
    let (fs, fs_from) = pick(p.fs, side_fs).ok_or_else(|| {
        anyhow::anyhow!(
            "--param {}: missing `fs` (sampling frequency, Hz) and no sidecar {} with `fs` next to --rf",
            a.param.display(),
            a.rf.with_extension("json").display()
        )
    })?;
    let side_t0 = sidecar_f64(&side, "t0")?;
    if a.t0.is_none() {
        warn_disagreement("t0", p.t0, &side_t0);
    }
    let (t0, t0_from) = match a.t0 {
        Some(t) => (t, "--t0".to_string()),
        None => pick(p.t0, side_t0).unwrap_or((0.0, "default".into())),
    };
    if !t0.is_finite() {
        anyhow::bail!("t0 = {t0} (from {t0_from}) is out of range: must be finite (s)");
    }
    // a convex array's radius travels on to `das` through the sidecars
    let radius = sidecar_f64(&side, "radius")?.map(|(r, _)| r);
    let params = Rf2IqParams { fc, fs, bandwidth: p.bandwidth, t0, order: 5 };
    let mut rf2iq = Rf2Iq::new(params.clone()).map_err(|e| anyhow::anyhow!("--param {}: {e}", a.param.display()))?;
    let start = std::time::Instant::now();
    let iq = rf2iq.process_to_vec(RfView::sample_major(&rf.data, ns, ne)).map_err(|e| anyhow::anyhow!("--rf: {e}"))?;
    let iq = to_sample_major(&iq, ns, ne)?;
    let secs = start.elapsed().as_secs_f64();
    sonoflow_fileio::npy::write_c64(&a.out, &[ns, ne], &iq)?;
    let sidecar = serde_json::json!({
        "fc": fc,
        "fs": fs,
        "t0": t0,
        "fs_from": fs_from,
        "t0_from": t0_from,
        "bandwidth": p.bandwidth,
        "cutoff_wn": params.cutoff(),
        "order": params.order,
        "n_samples": ns,
        "n_elements": ne,
        "radius": radius,
        "layout": "npy complex64 shape (n_samples, n_elements), sample k at t0 + k/fs",
        "seconds": secs,
    });
    let side_out = write_sidecar(&a.out, &sidecar)?;
    println!(
        "{ns} samples × {ne} elements → I/Q (fc {fc} Hz, fs {fs} Hz from {fs_from}, t0 {t0} s from {t0_from}, Wn {:.4}) in {secs:.3} s: {} (+ {})",
        params.cutoff(),
        a.out.display(),
        side_out.display()
    );
    Ok(0)
}

/// Parses `x0,dx,nx,z0,dz,nz`.
pub fn parse_grid(s: &str) -> anyhow::Result<Grid> {
    let usage = "expected x0,dx,nx,z0,dz,nz (m, m, count, m, m, count), e.g. -5e-3,1e-4,101,5e-3,1e-4,151";
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let [x0, dx, nx, z0, dz, nz] = parts[..] else {
        anyhow::bail!("--grid {s}: {} values, {usage}", parts.len());
    };
    let f = |name: &str, v: &str| {
        v.parse::<f64>().map_err(|_| anyhow::anyhow!("--grid {s}: {name} = `{v}` is not a number; {usage}"))
    };
    let n = |name: &str, v: &str| {
        v.parse::<usize>().map_err(|_| anyhow::anyhow!("--grid {s}: {name} = `{v}` is not a whole number ≥ 1; {usage}"))
    };
    let g = Grid {
        x0: f("x0", x0)?,
        dx: f("dx", dx)?,
        nx: n("nx", nx)?,
        z0: f("z0", z0)?,
        dz: f("dz", dz)?,
        nz: n("nz", nz)?,
    };
    g.validate().map_err(|e| anyhow::anyhow!("--grid {s}: {e}"))?;
    Ok(g)
}

fn angle_deg(flag: &str, v: f64) -> anyhow::Result<f64> {
    if !(v.is_finite() && v.abs() < 80.0) {
        anyhow::bail!("{flag} {v} is out of range: must be finite with |angle| < 80 (degrees)");
    }
    Ok(v.to_radians())
}

/// Runs `sonoflow das`.
pub fn run_das(a: &DasArgs) -> anyhow::Result<i32> {
    check_out(&a.out, &[&a.iq, &a.param])?;
    let grid = parse_grid(&a.grid)?;
    let tx_tilt = angle_deg("--tx-angle", a.tx_angle)?;
    let p = parse_param(&a.param)?;
    let (rx_angle, rx_deg) = match a.rx_angle {
        Some(d) => (angle_deg("--rx-angle", d)?, d),
        None => (p.rx_angle.unwrap_or(0.0), p.rx_angle.unwrap_or(0.0).to_degrees()),
    };
    let iq = sonoflow_fileio::npy::read_complex(&a.iq).map_err(|e| anyhow::anyhow!("--iq: {e}"))?;
    let [ns, ne] = iq.shape[..] else {
        anyhow::bail!(
            "--iq {}: shape {:?}, expected 2 axes (n_samples, n_elements) as `sonoflow rf2iq` writes",
            a.iq.display(),
            iq.shape
        );
    };
    let data = to_c32(&iq.data);
    check_finite_c(&data, "--iq", &a.iq, &iq.shape)?;
    let n_elements = p.n_elements.unwrap_or(ne);
    if n_elements != ne {
        anyhow::bail!(
            "--param {}: `Nelements` = {n_elements} but --iq {} has {ne} elements (shape {:?})",
            a.param.display(),
            a.iq.display(),
            iq.shape
        );
    }
    let side = read_sidecar(&a.iq, "--iq")?;
    check_sidecar_shape(&side, ns, ne)?;
    let side_fs = sidecar_f64(&side, "fs")?;
    warn_disagreement("fs", p.fs, &side_fs);
    let (fs, fs_from) = pick(p.fs, side_fs).ok_or_else(|| {
        anyhow::anyhow!(
            "--param {}: missing `fs` (sampling frequency, Hz) and no sidecar {} with `fs` next to --iq",
            a.param.display(),
            a.iq.with_extension("json").display()
        )
    })?;
    let side_t0 = sidecar_f64(&side, "t0")?;
    warn_disagreement("t0", p.t0, &side_t0);
    let (t0, t0_from) = pick(p.t0, side_t0).unwrap_or((0.0, "default".into()));
    // the radius: --param's (inf = linear), else the sidecar's (written by simus → rf2iq)
    let side_radius = sidecar_f64(&side, "radius")?;
    let radius = match (p.radius, &side_radius) {
        (Some(r), _) => {
            let (param_r, side_r) = (Some(r).filter(|r| *r != f64::INFINITY), side_radius.as_ref().map(|s| s.0));
            if param_r != side_r && side.is_some() {
                eprintln!(
                    "warning: `radius` = {r} in --param differs from the sidecar's ({}); using {r}",
                    side_r.map_or("linear".to_string(), |v| v.to_string())
                );
            }
            param_r
        }
        (None, Some((r, name))) => {
            eprintln!("convex array: radius {r} m from the sidecar {name}");
            Some(*r)
        }
        (None, None) => None,
    };
    let params = DasParams {
        fc: need(p.fc, "fc", "centre frequency, Hz", &a.param)?,
        c: p.c.unwrap_or(1540.0),
        fs,
        t0,
        pitch: need(p.pitch, "pitch", "element pitch, m", &a.param)?,
        n_elements,
        radius,
        fnumber: p.fnumber.unwrap_or(0.0),
        rx_angle,
        interpolation: p.interpolation.unwrap_or_default(),
        apodization: p.apodization.unwrap_or_default(),
    };
    let tx = TxWave::PlaneWave { tilt: tx_tilt };
    let start = std::time::Instant::now();
    let plan =
        DasPlan::new(&params, &tx, &grid, ns).map_err(|e| anyhow::anyhow!("--param {}: {e}", a.param.display()))?;
    let em = to_element_major(&data, ns, ne)?;
    let img = plan.apply_to_vec(&em)?;
    let secs = start.elapsed().as_secs_f64();
    if plan.n_taps() == 0 {
        eprintln!("warning: no element contributes to any pixel (grid outside the I/Q time window or aperture?)");
    }
    sonoflow_fileio::npy::write_c64(&a.out, &[grid.nz, grid.nx], &img)?;
    let sidecar = serde_json::json!({
        "grid": grid,
        "params": params,
        "tx": tx,
        "tx_angle_deg": a.tx_angle,
        "rx_angle_deg": rx_deg,
        "fs_from": fs_from,
        "t0_from": t0_from,
        "n_samples": ns,
        "n_taps": plan.n_taps(),
        "layout": "npy complex64 shape (nz, nx), pixel (iz, ix) at (x0 + ix·dx, z0 + iz·dz)",
        "seconds": secs,
    });
    let side_out = write_sidecar(&a.out, &sidecar)?;
    println!(
        "{ns} × {ne} I/Q → {} × {} image (tx {:+}°, rx {:+}°, F# {}, fs from {fs_from}, t0 from {t0_from}, {} taps) in {secs:.3} s: {} (+ {})",
        grid.nz,
        grid.nx,
        a.tx_angle,
        rx_deg,
        params.fnumber,
        plan.n_taps(),
        a.out.display(),
        side_out.display()
    );
    Ok(0)
}

/// Parses `--window M` or `--window Mz,Mx`.
pub fn parse_window(s: &str) -> anyhow::Result<[usize; 2]> {
    let bad = || anyhow::anyhow!("--window {s}: expected M or Mz,Mx (rows, columns), each a whole number in [1, 64]");
    let v: Vec<usize> = s.split(',').map(|t| t.trim().parse::<usize>().map_err(|_| bad())).collect::<Result<_, _>>()?;
    let w = match v[..] {
        [m] => [m, m],
        [mz, mx] => [mz, mx],
        _ => return Err(bad()),
    };
    if w.iter().any(|m| !(1..=64).contains(m)) {
        return Err(bad());
    }
    Ok(w)
}

fn sibling(out: &Path, suffix: &str) -> PathBuf {
    let stem = out.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    out.with_file_name(format!("{stem}_{suffix}.npy"))
}

/// Runs `sonoflow doppler`.
pub fn run_iq2doppler(a: &DopplerArgs) -> anyhow::Result<i32> {
    let (power_path, var_path, flags_path) =
        (sibling(&a.out, "power"), sibling(&a.out, "variance"), sibling(&a.out, "flags"));
    check_out(&a.out, &[&a.packet, &a.param])?;
    for p in [&power_path, &var_path, &flags_path] {
        if p == &a.packet || p == &a.param {
            anyhow::bail!("--out {}: {} would overwrite an input", a.out.display(), p.display());
        }
    }
    let window = match &a.window {
        Some(s) => parse_window(s)?,
        None => [1, 1],
    };
    if !(1..=64).contains(&a.lag) {
        anyhow::bail!("--lag {} is out of range: must be in [1, 64]", a.lag);
    }
    let estimator = match a.estimator.to_ascii_lowercase().as_str() {
        "autocorrelation" => Estimator::Autocorrelation,
        "loupas" => Estimator::Loupas,
        _ => anyhow::bail!("--estimator {}: allowed autocorrelation, loupas", a.estimator),
    };
    if let Some(dz) = a.dz {
        if !(dz.is_finite() && dz > 0.0) {
            anyhow::bail!("--dz {dz} is out of range: must be finite and > 0 (m)");
        }
    }
    let p = parse_param(&a.param)?;
    let params = DopplerParams {
        fc: need(p.fc, "fc", "centre frequency, Hz", &a.param)?,
        c: p.c.unwrap_or(1540.0),
        prf: need(p.prf, "PRF", "pulse repetition frequency, Hz", &a.param)?,
        lag: a.lag,
        window,
        window_shape: WindowShape::Hamming,
        estimator,
        alias_fraction: 0.9,
    };
    params.validate().map_err(|e| anyhow::anyhow!("--param {}: {e}", a.param.display()))?;
    let pk = sonoflow_fileio::npy::read_complex(&a.packet).map_err(|e| anyhow::anyhow!("--packet: {e}"))?;
    let [nz, nx, nf] = pk.shape[..] else {
        anyhow::bail!("--packet {}: shape {:?}, expected 3 axes (nz, nx, n_frames)", a.packet.display(), pk.shape);
    };
    if nz == 0 || nx == 0 {
        anyhow::bail!("--packet {}: shape {:?} has no pixels", a.packet.display(), pk.shape);
    }
    if nf <= a.lag {
        anyhow::bail!(
            "--packet {}: {nf} frame(s) (shape {:?}); --lag {} needs at least {} frames",
            a.packet.display(),
            pk.shape,
            a.lag,
            a.lag + 1
        );
    }
    let dz = match (a.dz, estimator) {
        (Some(dz), _) => dz,
        (None, Estimator::Autocorrelation) => 1.0, // unused by the autocorrelation estimator
        (None, Estimator::Loupas) => {
            let side = read_sidecar(&a.packet, "--packet")?;
            let dz = side.as_ref().and_then(|(_, v)| v.get("grid")?.get("dz")?.as_f64());
            match dz {
                Some(dz) if dz.is_finite() && dz > 0.0 => dz,
                _ => anyhow::bail!(
                    "--estimator loupas needs the row spacing: give --dz (m) or a sidecar {} with grid.dz",
                    a.packet.with_extension("json").display()
                ),
            }
        }
    };
    let clutter = match &a.clutter {
        Some(s) => {
            let c: ClutterParams = serde_json::from_str(s).map_err(|e| anyhow::anyhow!("--clutter {s}: {e}"))?;
            c.validate().map_err(|e| anyhow::anyhow!("--clutter {s}: {e}"))?;
            Some(c)
        }
        None => None,
    };
    let mut data = to_c32(&pk.data);
    let start = std::time::Instant::now();
    let clutter_report = match &clutter {
        Some(c) => Some(c.apply_pixel_major(&mut data, nf).map_err(|e| anyhow::anyhow!("--clutter: {e}"))?),
        None => None,
    };
    let mut est = DopplerEstimator::new(params.clone(), nx, nz, dz)?;
    let map = est.estimate_to_map(Packet::PixelMajor { data: &data, n_frames: nf })?;
    let secs = start.elapsed().as_secs_f64();
    let count = |bit: u8| map.flags.iter().filter(|f| **f & bit != 0).count();
    let (no_est, alias) = (count(flags::NO_ESTIMATE), count(flags::ALIASING));
    let shape = [nz, nx];
    sonoflow_fileio::npy::write_f32(&a.out, &shape, false, &map.velocity)?;
    sonoflow_fileio::npy::write_f32(&power_path, &shape, false, &map.power)?;
    sonoflow_fileio::npy::write_f32(&var_path, &shape, false, &map.variance)?;
    sonoflow_fileio::npy::write_u8(&flags_path, &shape, &map.flags)?;
    let name = |p: &Path| p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let sidecar = serde_json::json!({
        "nyquist_velocity": map.nyquist,
        "estimator": estimator,
        "lag": a.lag,
        "window": window,
        "window_shape": WindowShape::Hamming,
        "fc": params.fc,
        "c": params.c,
        "prf": params.prf,
        "dz": if estimator == Estimator::Loupas { Some(dz) } else { None },
        "alias_fraction": params.alias_fraction,
        "n_frames": nf,
        "pixels": nz * nx,
        "flagged": { "no_estimate": no_est, "aliasing": alias },
        "files": {
            "velocity": name(&a.out),
            "power": name(&power_path),
            "variance": name(&var_path),
            "flags": name(&flags_path),
        },
        "conventions": "shape (nz, nx); velocity m/s float32, positive toward the probe, 0 where no estimate; power = R0 float32; variance = 2 (V_N/pi)^2 (1 - |R1|/R0) m^2/s^2 float32; flags uint8 bits: 1 = no estimate, 2 = aliasing suspected (|arg R1| > 0.9 pi)",
        "seconds": secs,
    });
    let mut sidecar = sidecar;
    if let (Some(c), Some(r)) = (&clutter, &clutter_report) {
        sidecar["clutter"] = serde_json::json!({
            "params": c, "order_or_rank": r.order_or_rank, "cutoff": r.cutoff, "removed_energy": r.removed_energy,
        });
    }
    let side_out = write_sidecar(&a.out, &sidecar)?;
    println!(
        "{nz} × {nx} × {nf} packet → Doppler ({}, lag {}, window {}×{}, V_N {:.4} m/s): {no_est} no-estimate, {alias} aliasing pixels in {secs:.3} s: {} (+ _power, _variance, _flags, {})",
        a.estimator.to_ascii_lowercase(),
        a.lag,
        window[0],
        window[1],
        map.nyquist,
        a.out.display(),
        side_out.display()
    );
    Ok(0)
}
