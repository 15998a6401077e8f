//! `sonoflow._native`: the compiled half of the `sonoflow` Python package (PyO3, stable ABI from
//! CPython 3.9). Each function takes numpy arrays and a JSON object of parameters that
//! deserialises straight into the library's own parameter struct (so a bad field is named by the
//! library's validation), releases the GIL while it computes, and returns numpy arrays that own
//! the library's output vectors (no copy). The PyMUST-compatible signatures, `Param` handling and
//! argument checks live in the pure-Python half (`python/sonoflow/`); this layer trusts only the
//! array shapes it is given and checks everything else again.
//!
//! Errors: every library error becomes `ValueError` with the library's message (which names the
//! field and the allowed range); a non-contiguous array becomes `TypeError`.

use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray3, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use serde::de::DeserializeOwned;
use sonoflow_beamform::{das_frames, Complex, DasParams, DasPlan, Grid, Rf2Iq, Rf2IqParams, RfView, TxWave, C32};
use sonoflow_doppler::{ClutterParams, DopplerEstimator, DopplerParams, Packet};
use sonoflow_mcap_io::{McapIoError, McapReader, ReadOptions, SharedMessageIter};
use sonoflow_messages::MessageType;
use sonoflow_regularise::{Smoothn, SmoothnParams};
use sonoflow_simus::{MustParam, ScattererSlices, Simus, SimusOptions, Transmit};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

fn value_error(what: &str, e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(format!("{what}: {e}"))
}

/// Parses `json` into `T`, naming the offending field.
fn from_json<T: DeserializeOwned>(what: &str, json: &str) -> PyResult<T> {
    let de = &mut serde_json::Deserializer::from_str(json);
    serde_path_to_error::deserialize(de).map_err(|e| {
        let path = e.path().to_string();
        if path == "." {
            value_error(what, e.inner())
        } else {
            value_error(what, format!("`{path}`: {}", e.inner()))
        }
    })
}

fn contiguous<'a, T>(name: &str, r: Result<&'a [T], numpy::AsSliceError>) -> PyResult<&'a [T]> {
    r.map_err(|_| PyTypeError::new_err(format!("{name}: the array must be C-contiguous")))
}

/// Whether every component is finite (one pass over the bits: exponent all ones is NaN or
/// infinite; faster than numpy's isfinite + all on large packets).
fn all_finite_c32(data: &[C32]) -> bool {
    let inf = |x: f32| u32::from(x.to_bits() & 0x7f80_0000 == 0x7f80_0000);
    !data.chunks(512).any(|c| c.iter().fold(0u32, |acc, x| acc | inf(x.re) | inf(x.im)) != 0)
}

/// The thread pool set by [`set_threads`] (`None`: rayon's global pool, one thread per core).
static POOL: Mutex<Option<Arc<rayon::ThreadPool>>> = Mutex::new(None);

fn pool() -> Option<Arc<rayon::ThreadPool>> {
    POOL.lock().map(|p| p.clone()).unwrap_or(None)
}

/// Runs `f` without the GIL, in the pool chosen by [`set_threads`].
fn compute<T: Send>(py: Python<'_>, f: impl FnOnce() -> T + Send) -> T {
    let p = pool();
    py.detach(move || match p {
        Some(p) => p.install(f),
        None => f(),
    })
}

/// Sets the number of worker threads of every later call (0 = one per core, the default).
#[pyfunction]
fn set_threads(n: usize) -> PyResult<()> {
    let new = if n == 0 {
        None
    } else {
        let p = rayon::ThreadPoolBuilder::new().num_threads(n).build().map_err(|e| value_error("threads", e))?;
        Some(Arc::new(p))
    };
    let mut g = POOL.lock().map_err(|_| PyValueError::new_err("threads: the pool lock is poisoned"))?;
    *g = new;
    Ok(())
}

/// The number of worker threads a call uses now.
#[pyfunction]
fn threads() -> usize {
    match pool() {
        Some(p) => p.current_num_threads(),
        None => rayon::current_num_threads(),
    }
}

/// The probe presets' names, comma-separated.
#[pyfunction]
fn probe_presets() -> &'static str {
    sonoflow_simus::PRESET_NAMES
}

/// A probe preset as JSON (sonoflow's field names: `n_elements`, `tx_now`, …).
#[pyfunction]
fn probe_preset(name: &str) -> PyResult<String> {
    let p = sonoflow_simus::Probe::preset(name).map_err(|e| value_error("probe", e))?;
    serde_json::to_string(&p).map_err(|e| value_error("probe", e))
}

/// Transmit delays (s) of a plane wave (`kind` "plane", `a` = tilt in rad), a focused wave
/// ("focused", focus (a, b)) or a diverging wave ("diverging", virtual source (a, b)).
#[pyfunction]
fn txdelay<'py>(py: Python<'py>, param_json: &str, kind: &str, a: f64, b: f64) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let parts = from_json::<MustParam>("param", param_json)?.into_parts().map_err(|e| value_error("param", e))?;
    let (probe, c) = (&parts.probe, parts.medium.c);
    let t = match kind {
        "plane" => Transmit::plane_wave(probe, c, a),
        "focused" => Transmit::focused(probe, c, a, b),
        "diverging" => Transmit::diverging(probe, c, a, b),
        _ => return Err(value_error("txdelay", format!("unknown wave `{kind}` (plane, focused, diverging)"))),
    }
    .map_err(|e| value_error("txdelay", e))?;
    Ok(PyArray1::from_vec(py, t.delays))
}

/// SIMUS RF of one transmit. `param_json` is a MUST param (`TXdelay` set), `options_json` a
/// `SimusOptions`; `y` (scatterers off the plane): MUST's elevation model. Returns (rf (n_elements, n_samples) float32, element-major; fs; t0).
#[pyfunction]
fn simus<'py>(
    py: Python<'py>,
    x: PyReadonlyArray1<'py, f32>,
    z: PyReadonlyArray1<'py, f32>,
    rc: PyReadonlyArray1<'py, f32>,
    param_json: &str,
    options_json: &str,
    y: Option<PyReadonlyArray1<'py, f32>>,
) -> PyResult<(Bound<'py, PyAny>, f64, f64)> {
    let parts = from_json::<MustParam>("param", param_json)?.into_parts().map_err(|e| value_error("param", e))?;
    let mut options: SimusOptions = from_json("options", options_json)?;
    if options.fs.is_none() {
        options.fs = parts.fs;
    }
    let transmit = parts.transmit.ok_or_else(|| PyValueError::new_err("delays: missing (param.TXdelay)"))?;
    // the numpy buffers themselves (no copy)
    let scat = ScattererSlices {
        x: contiguous("x", x.as_slice())?,
        z: contiguous("z", z.as_slice())?,
        rc: contiguous("RC", rc.as_slice())?,
    };
    scat.validate().map_err(|e| value_error("scatterers", e))?;
    let n_el = parts.probe.n_elements;
    let mut simus = Simus::new(parts.probe, parts.medium, options).map_err(|e| value_error("simus", e))?;
    let ys = match &y {
        Some(y) => Some(contiguous("y", y.as_slice())?),
        None => None,
    };
    let rf = compute(py, || match ys {
        Some(ys) => simus.simulate_3d(scat, ys, &transmit),
        None => simus.simulate(scat, &transmit),
    })
    .map_err(|e| value_error("simus", e))?;
    let (ns, fs, t0) = (rf.n_samples, rf.fs, rf.t0);
    let arr = PyArray1::from_vec(py, rf.data).reshape([n_el, ns])?;
    Ok((arr.into_any(), fs, t0))
}

/// MUST PFIELD (RMS pressure of one transmit) at points `x`, `z` (float64), and `y` (off the
/// plane: MUST's elevation model) when given. `param_json` is a MUST
/// param (`TXdelay` set), `options_json` a `PfieldOptions`. Returns (RP float64, IDX bool, df).
#[pyfunction]
fn pfield<'py>(
    py: Python<'py>,
    x: PyReadonlyArray1<'py, f64>,
    y: Option<PyReadonlyArray1<'py, f64>>,
    z: PyReadonlyArray1<'py, f64>,
    param_json: &str,
    options_json: &str,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>, f64)> {
    let parts = from_json::<MustParam>("param", param_json)?.into_parts().map_err(|e| value_error("param", e))?;
    let options: sonoflow_simus::PfieldOptions = from_json("options", options_json)?;
    let transmit = parts.transmit.ok_or_else(|| PyValueError::new_err("delays: missing (param.TXdelay)"))?;
    let (xs, zs) = (contiguous("x", x.as_slice())?, contiguous("z", z.as_slice())?);
    let ys = match &y {
        Some(y) => Some(contiguous("y", y.as_slice())?),
        None => None,
    };
    let field = compute(py, || match ys {
        Some(ys) => sonoflow_simus::pfield_3d(&parts.probe, &parts.medium, &transmit, xs, ys, zs, &options),
        None => sonoflow_simus::pfield(&parts.probe, &parts.medium, &transmit, xs, zs, &options),
    })
    .map_err(|e| value_error("pfield", e))?;
    Ok((PyArray1::from_vec(py, field.rms).into_any(), PyArray1::from_vec(py, field.idx).into_any(), field.df))
}

/// RF (n_samples, n_channels) float32/float64, sample-major → I/Q (n_channels, n_samples)
/// complex64, channel-major. `params_json` is an `Rf2IqParams` (fc, fs, bandwidth, t0, order).
#[pyfunction]
fn rf2iq<'py>(py: Python<'py>, rf: PyReadonlyArrayDyn<'py, f64>, params_json: &str) -> PyResult<Bound<'py, PyAny>> {
    let params: Rf2IqParams = from_json("param", params_json)?;
    let [ns, ne] = rf.shape()[..] else {
        return Err(PyValueError::new_err("RF: expected 2 axes (n_samples, n_channels)"));
    };
    let data = contiguous("RF", rf.as_slice())?;
    let mut r = Rf2Iq::new(params).map_err(|e| value_error("param", e))?;
    let iq = compute(py, || r.process_to_vec(RfView::sample_major(data, ns, ne))).map_err(|e| value_error("RF", e))?;
    Ok(PyArray1::from_vec(py, iq).reshape([ne, ns])?.into_any())
}

/// Delay-and-sum of I/Q frames (n_frames, n_elements, n_samples) complex64 on a regular grid.
/// `params_json`: `DasParams`; `grid_json`: `Grid`; `delays`: transmit delays (s, NaN = off).
/// Returns (n_frames, nz, nx) complex64 and the number of taps.
#[pyfunction]
fn das<'py>(
    py: Python<'py>,
    iq: PyReadonlyArray3<'py, C32>,
    params_json: &str,
    grid_json: &str,
    delays: PyReadonlyArray1<'py, f64>,
) -> PyResult<(Bound<'py, PyAny>, usize)> {
    let params: DasParams = from_json("param", params_json)?;
    let grid: Grid = from_json("grid", grid_json)?;
    grid.validate().map_err(|e| value_error("x, z", e))?;
    let [nf, ne, ns] = iq.shape()[..] else {
        return Err(PyValueError::new_err("SIG: expected 3 axes"));
    };
    if ne != params.n_elements {
        return Err(value_error("SIG", format!("{ne} channels but param.Nelements = {}", params.n_elements)));
    }
    let tx = TxWave::Delays { delays: contiguous("delaysTX", delays.as_slice())?.to_vec() };
    let data = contiguous("SIG", iq.as_slice())?;
    let out = compute(py, || das_frames(&params, &tx, &grid, ns, data, nf)).map_err(|e| value_error("das", e))?;
    let (img, taps) = out;
    Ok((PyArray1::from_vec(py, img).reshape([nf, grid.nz, grid.nx])?.into_any(), taps))
}

/// The DAS plan of `das` as CSR parts: (offsets (n_pixels + 1) uint32, index uint32, w0, w1
/// complex64), rows = pixels `iz·nx + ix`, columns = sample + element · n_samples.
#[allow(clippy::type_complexity)]
#[pyfunction]
fn dasmtx<'py>(
    py: Python<'py>,
    n_samples: usize,
    params_json: &str,
    grid_json: &str,
    delays: PyReadonlyArray1<'py, f64>,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>, Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    let params: DasParams = from_json("param", params_json)?;
    let grid: Grid = from_json("grid", grid_json)?;
    grid.validate().map_err(|e| value_error("x, z", e))?;
    let tx = TxWave::Delays { delays: contiguous("delaysTX", delays.as_slice())?.to_vec() };
    let plan = compute(py, || DasPlan::new(&params, &tx, &grid, n_samples)).map_err(|e| value_error("dasmtx", e))?;
    let (o, i, w0, w1) = plan.taps();
    Ok((
        PyArray1::from_slice(py, o).into_any(),
        PyArray1::from_slice(py, i).into_any(),
        PyArray1::from_slice(py, w0).into_any(),
        PyArray1::from_slice(py, w1).into_any(),
    ))
}

/// Slow-time Doppler of a packet (nz, nx, n_frames) complex64 (MUST's layout, C order):
/// `params_json` a `DopplerParams`, `clutter_json` a `ClutterParams` or "null", `dz` the row
/// spacing (Loupas only). Returns (velocity, variance, power, flags), each (nz, nx).
#[allow(clippy::type_complexity)]
#[pyfunction]
fn iq2doppler<'py>(
    py: Python<'py>,
    iq: PyReadonlyArray3<'py, C32>,
    params_json: &str,
    clutter_json: &str,
    dz: f64,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>, Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    let params: DopplerParams = from_json("param", params_json)?;
    params.validate().map_err(|e| value_error("param", e))?;
    let clutter: Option<ClutterParams> = from_json("clutter", clutter_json)?;
    if let Some(c) = &clutter {
        c.validate().map_err(|e| value_error("clutter", e))?;
    }
    let [nz, nx, nf] = iq.shape()[..] else {
        return Err(PyValueError::new_err("IQ: expected 3 axes (nz, nx, n_frames)"));
    };
    if nf <= params.lag {
        return Err(value_error("IQ", format!("{nf} frame(s); lag {} needs at least {}", params.lag, params.lag + 1)));
    }
    let src = contiguous("IQ", iq.as_slice())?;
    let nan = || PyValueError::new_err("IQ: contains NaN or infinite values");
    let map = compute(py, || -> PyResult<_> {
        let mut data;
        let packet = match &clutter {
            Some(c) => {
                if !all_finite_c32(src) {
                    return Err(nan());
                }
                data = src.to_vec();
                c.apply_pixel_major(&mut data, nf).map_err(|e| value_error("clutter", e))?;
                Packet::PixelMajor { data: &data, n_frames: nf }
            }
            None => Packet::PixelMajor { data: src, n_frames: nf },
        };
        let mut est = DopplerEstimator::new(params.clone(), nx, nz, dz).map_err(|e| value_error("iq2doppler", e))?;
        let map = est.estimate_to_map(packet).map_err(|e| value_error("iq2doppler", e))?;
        // Without a filter the data are read once: R0 = Σ|x|² (f64, cannot overflow from f32
        // samples) is finite exactly where every sample of the pixel is, and the spatial window
        // (weights > 0) carries a non-finite value on to the pixels around it.
        if clutter.is_none() && !est.autocorrelation().0.iter().all(|r| r.is_finite()) {
            return Err(nan());
        }
        Ok(map)
    })?;
    let shape = [nz, nx];
    Ok((
        PyArray1::from_vec(py, map.velocity).reshape(shape)?.into_any(),
        PyArray1::from_vec(py, map.variance).reshape(shape)?.into_any(),
        PyArray1::from_vec(py, map.power).reshape(shape)?.into_any(),
        PyArray1::from_vec(py, map.flags).reshape(shape)?.into_any(),
    ))
}

/// MUST `bmode`: the 8-bit log-compressed (or, below 1 dB, power-law) envelope of I/Q samples
/// (complex128, any shape, C-contiguous), as a flat uint8 array of the same length.
#[pyfunction]
fn bmode<'py>(py: Python<'py>, iq: PyReadonlyArrayDyn<'py, Complex<f64>>, dr: f64) -> PyResult<Bound<'py, PyAny>> {
    let data = contiguous("IQ", iq.as_slice())?;
    let img = compute(py, || sonoflow_beamform::bmode(data, dr)).map_err(|e| value_error("bmode", e))?;
    Ok(PyArray1::from_vec(py, img).into_any())
}

/// Speckle tracking (MUST `sptrack`) of real images `(P, M, N)` float64, frame-major, with the
/// library's params as JSON; the last pass at its window centres: (di, dj, rho, valid) of shape
/// (ni, nj) and the centres' rows and columns (0-based pixel centres).
#[pyfunction]
#[allow(clippy::type_complexity)]
fn sptrack<'py>(
    py: Python<'py>,
    images: PyReadonlyArrayDyn<'py, f64>,
    params_json: &str,
) -> PyResult<(
    Bound<'py, PyAny>,
    Bound<'py, PyAny>,
    Bound<'py, PyAny>,
    Bound<'py, PyAny>,
    Bound<'py, PyAny>,
    Bound<'py, PyAny>,
)> {
    let [p, m, n] = images.shape()[..] else {
        return Err(value_error("I", format!("expected 3 axes (rows, columns, frames), got {:?}", images.shape())));
    };
    let params: sonoflow_doppler::SpeckleParams = from_json("param", params_json)?;
    let data = contiguous("I", images.as_slice())?;
    let frames: Vec<Vec<C32>> =
        data.chunks(m * n).map(|f| f.iter().map(|v| C32::new(*v as f32, 0.0)).collect()).collect();
    debug_assert_eq!(frames.len(), p);
    let t = compute(py, || sonoflow_doppler::SpeckleTracker::new(params).and_then(|tr| tr.track(&[frames], m, n)))
        .map_err(|e| value_error("sptrack", e))?;
    let shape = [t.ni, t.nj];
    let arr = |v: Vec<f64>| -> PyResult<Bound<'py, PyAny>> {
        Ok(PyArray1::from_vec(py, v).reshape(shape).map_err(|e| value_error("sptrack", e))?.into_any())
    };
    let ic: Vec<f64> = (0..t.ni).map(|k| t.i_first + k as f64 * t.i_step).collect();
    let jc: Vec<f64> = (0..t.nj).map(|k| t.j_first + k as f64 * t.j_step).collect();
    let valid: Vec<f64> = t.valid.iter().map(|&v| f64::from(u8::from(v))).collect();
    Ok((
        arr(t.di)?,
        arr(t.dj)?,
        arr(t.rho)?,
        arr(valid)?,
        PyArray1::from_vec(py, ic).into_any(),
        PyArray1::from_vec(py, jc).into_any(),
    ))
}

/// MUST `tgc`'s gain per sample of sample-major I/Q (n_samples, n_lines) complex128.
#[pyfunction]
fn tgc_gain_iq<'py>(
    py: Python<'py>,
    iq: PyReadonlyArrayDyn<'py, Complex<f64>>,
    n_lines: usize,
) -> PyResult<Bound<'py, PyAny>> {
    let data = contiguous("S", iq.as_slice())?;
    let gain = compute(py, || {
        sonoflow_beamform::mean_envelope_iq(data, n_lines).and_then(|c| sonoflow_beamform::tgc_gain(&c))
    })
    .map_err(|e| value_error("tgc", e))?;
    Ok(PyArray1::from_vec(py, gain).into_any())
}

/// MUST `tgc`'s gain per sample of sample-major real RF (n_samples, n_lines) float64 (envelope
/// by the analytic signal, as `scipy.signal.hilbert`).
#[pyfunction]
fn tgc_gain_rf<'py>(py: Python<'py>, rf: PyReadonlyArrayDyn<'py, f64>, n_lines: usize) -> PyResult<Bound<'py, PyAny>> {
    let data = contiguous("S", rf.as_slice())?;
    let gain = compute(py, || {
        sonoflow_beamform::mean_envelope_rf(data, n_lines).and_then(|c| sonoflow_beamform::tgc_gain(&c))
    })
    .map_err(|e| value_error("tgc", e))?;
    Ok(PyArray1::from_vec(py, gain).into_any())
}

/// A seeded 2-D speckle phantom (MUST `genscat`, `sonoflow_simus::phantom`): region width ×
/// height from depth `z0`, `meandist`, inclusions as JSON (a list of `{x, z, radius, level_db?}`),
/// an optional echogenicity image (nl, nc) float64 with MUST's `g`. Returns (x, z, RC) float64.
#[pyfunction]
#[pyo3(signature = (width, height, z0, meandist, seed, inclusions_json, image=None, g=40.0))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn genscat<'py>(
    py: Python<'py>,
    width: f64,
    height: f64,
    z0: f64,
    meandist: f64,
    seed: u64,
    inclusions_json: &str,
    image: Option<PyReadonlyArrayDyn<'py, f64>>,
    g: f64,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    let inclusions: Vec<sonoflow_simus::Inclusion> = from_json("inclusions", inclusions_json)?;
    let image = match &image {
        Some(im) => {
            let [nl, nc] = im.shape()[..] else {
                return Err(value_error(
                    "I",
                    format!("expected 2 axes (rows = depth, columns), got shape {:?}", im.shape()),
                ));
            };
            Some(sonoflow_simus::phantom::Echogenicity { data: contiguous("I", im.as_slice())?.to_vec(), nl, nc, g })
        }
        None => None,
    };
    let params = sonoflow_simus::PhantomParams { width, height, z0, meandist, seed, inclusions, image };
    let ph = compute(py, || sonoflow_simus::genscat(&params)).map_err(|e| value_error("genscat", e))?;
    Ok((
        PyArray1::from_vec(py, ph.x).into_any(),
        PyArray1::from_vec(py, ph.z).into_any(),
        PyArray1::from_vec(py, ph.rc).into_any(),
    ))
}

/// Per-pixel Doppler projection vectors `a = (a_x, a_z)` — the velocity a look measures is
/// `a · (vx, vz)` — of a plane wave transmitted at `tx_angle` and received at `rx_angle` (rad)
/// through the receive aperture `aperture_json` (`sonoflow_doppler::Aperture`: pitch,
/// n_elements, fnumber, width, radius, apodization) at `fc` and `c`, on the grid `grid_json`:
/// what the built-in `doppler` node uses with `projection = "aperture"` (its default). Returns
/// float32 (2, nz, nx); a pixel no element reaches gets (0, 0).
#[pyfunction]
fn aperture_projection<'py>(
    py: Python<'py>,
    aperture_json: &str,
    fc: f64,
    c: f64,
    tx_angle: f64,
    rx_angle: f64,
    grid_json: &str,
) -> PyResult<Bound<'py, PyAny>> {
    let aperture: sonoflow_doppler::Aperture = from_json("aperture", aperture_json)?;
    let grid: Grid = from_json("grid", grid_json)?;
    grid.validate().map_err(|e| value_error("grid", e))?;
    for (name, a) in [("tx_angle", tx_angle), ("rx_angle", rx_angle)] {
        if !(a.is_finite() && a.abs() < std::f64::consts::FRAC_PI_2) {
            return Err(value_error(name, format!("{a}: expected finite, |angle| < pi/2 rad")));
        }
    }
    let a = compute(py, || sonoflow_doppler::aperture_projection(&aperture, fc, c, tx_angle, rx_angle, &grid))
        .map_err(|e| value_error("aperture_projection", e))?;
    let n = a.len();
    let mut planes = Vec::with_capacity(2 * n);
    planes.extend(a.iter().map(|p| p[0]));
    planes.extend(a.iter().map(|p| p[1]));
    let arr = PyArray1::from_vec(py, planes);
    Ok(arr.reshape([2, grid.nz, grid.nx])?.into_any())
}

/// Least-squares vector velocity from Doppler maps (n_looks, nz, nx) float32 (positive toward
/// the probe) with the nominal plane-wave projections of (tx, rx) angle pairs (rad), optional
/// flags (n_looks, nz, nx) uint8 (bit 0: no estimate) and per-look weights. Returns (vx, vz,
/// flags), each (nz, nx).
#[allow(clippy::type_complexity)]
#[pyfunction]
#[pyo3(signature = (vd, tx_angles, rx_angles, flags=None, weights=None))]
fn vector_doppler<'py>(
    py: Python<'py>,
    vd: PyReadonlyArray3<'py, f32>,
    tx_angles: Vec<f64>,
    rx_angles: Vec<f64>,
    flags: Option<PyReadonlyArray3<'py, u8>>,
    weights: Option<Vec<f64>>,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    let [nl, nz, nx] = vd.shape()[..] else {
        return Err(PyValueError::new_err("VD: expected (n_looks, nz, nx)"));
    };
    if tx_angles.len() != nl || rx_angles.len() != nl {
        return Err(value_error(
            "angles",
            format!("{} maps but {} transmit and {} receive angles", nl, tx_angles.len(), rx_angles.len()),
        ));
    }
    let n = nz * nx;
    let v = contiguous("VD", vd.as_slice())?;
    let zeros = vec![0u8; nl * n];
    let f = match &flags {
        Some(f) => {
            if f.shape() != vd.shape() {
                return Err(value_error("flags", format!("shape {:?}, expected VD's {:?}", f.shape(), vd.shape())));
            }
            contiguous("flags", f.as_slice())?
        }
        None => &zeros,
    };
    let w = weights.unwrap_or_else(|| vec![1.0; nl]);
    let out = compute(py, || -> PyResult<sonoflow_doppler::VectorField> {
        let inputs: Vec<sonoflow_doppler::VectorInput<'_>> = (0..nl)
            .map(|k| sonoflow_doppler::VectorInput {
                velocity: &v[k * n..(k + 1) * n],
                flags: &f[k * n..(k + 1) * n],
                projection: sonoflow_doppler::Projection::Nominal { tx_tilt: tx_angles[k], rx_angle: rx_angles[k] },
            })
            .collect();
        let mut out = sonoflow_doppler::VectorField::default();
        sonoflow_doppler::solve_vector_weighted(&inputs, &w, &mut out).map_err(|e| value_error("vector_doppler", e))?;
        Ok(out)
    })?;
    let shape = [nz, nx];
    Ok((
        PyArray1::from_vec(py, out.vx).reshape(shape)?.into_any(),
        PyArray1::from_vec(py, out.vz).reshape(shape)?.into_any(),
        PyArray1::from_vec(py, out.flags).reshape(shape)?.into_any(),
    ))
}

/// The workspace of the last `smoothn` call (one per process), reused by the next call of the
/// same grid and component count. Only workspaces up to [`SMOOTHN_CACHE_BYTES`] are kept, so a
/// large grid's memory is returned when its call ends.
static SMOOTHN_CACHE: std::sync::Mutex<Option<Smoothn>> = std::sync::Mutex::new(None);
const SMOOTHN_CACHE_BYTES: usize = 64 << 20;

fn take_cached_smoothn(grid: &[usize], components: usize) -> Option<Smoothn> {
    let mut slot = SMOOTHN_CACHE.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    slot.take_if(|ws| ws.shape() == grid && ws.components() == components)
}

fn keep_smoothn(ws: Smoothn) {
    if ws.workspace_bytes() <= SMOOTHN_CACHE_BYTES {
        *SMOOTHN_CACHE.lock().unwrap_or_else(std::sync::PoisonError::into_inner) = Some(ws);
    }
}

/// smoothn of `y` (components × grid, C order, NaN = missing) with optional weights of the
/// grid's size; `params_json` a `SmoothnParams`. Returns (z, S, converged, outlier fraction).
#[pyfunction]
#[pyo3(signature = (y, grid, components, params_json, weights=None))]
fn smoothn<'py>(
    py: Python<'py>,
    y: PyReadonlyArrayDyn<'py, f64>,
    grid: Vec<usize>,
    components: usize,
    params_json: &str,
    weights: Option<PyReadonlyArrayDyn<'py, f64>>,
) -> PyResult<(Bound<'py, PyAny>, f64, bool, f64)> {
    let params: SmoothnParams = from_json("options", params_json)?;
    params.validate().map_err(|e| value_error("options", e))?;
    let data = contiguous("y", y.as_slice())?;
    let n: usize = grid.iter().product();
    if n * components != data.len() {
        return Err(value_error("y", format!("{} values for a grid {grid:?} × {components}", data.len())));
    }
    let w = match &weights {
        Some(w) => Some(contiguous("W", w.as_slice())?),
        None => None,
    };
    if let Some(w) = w {
        if w.len() != n {
            return Err(value_error("W", format!("{} weights for a grid of {n} points", w.len())));
        }
    }
    let shape: Vec<usize> = y.shape().to_vec();
    let (out, report) = compute(py, || -> PyResult<_> {
        let mut ws = match take_cached_smoothn(&grid, components) {
            Some(ws) => ws,
            None => Smoothn::new(&grid, components).map_err(|e| value_error("y", e))?,
        };
        let mut out = vec![0.0; n * components];
        let report = ws.smooth(data, w, &params, &mut out).map_err(|e| value_error("smoothn", e))?;
        keep_smoothn(ws);
        Ok((out, report))
    })?;
    let arr = PyArray1::from_vec(py, out).reshape(shape)?;
    Ok((arr.into_any(), report.s, report.converged, report.outlier_fraction))
}

fn mcap_error(e: McapIoError) -> PyErr {
    match e {
        McapIoError::Io { .. } => pyo3::exceptions::PyOSError::new_err(e.to_string()),
        _ => PyValueError::new_err(e.to_string()),
    }
}

/// The wire layout of the message type whose MCAP schema is `schema`: (type name, header size,
/// element size, ros2msg schema text). The schema text is generated from the wire structs
/// (`sonoflow-messages`), so Python decodes records without a copy of the layout.
#[pyfunction]
fn wire_layout(schema: &str) -> PyResult<(String, usize, usize, String)> {
    let k = MessageType::from_schema_name(schema).map_err(|e| value_error("schema", e))?;
    Ok((k.name().to_string(), k.header_size(), k.elem_size(), k.schema_text()))
}

/// An MCAP recording opened for reading (complete or unfinished).
#[pyclass(name = "RecordingReader", module = "sonoflow._native", frozen)]
struct RecordingReader {
    reader: Arc<McapReader>,
}

#[pymethods]
impl RecordingReader {
    #[new]
    fn new(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let reader = py.detach(|| McapReader::open(&path)).map_err(mcap_error)?;
        Ok(Self { reader: Arc::new(reader) })
    }

    /// (topic, schema name, message count or None) per channel.
    fn topics(&self) -> Vec<(String, String, Option<u64>)> {
        self.reader.topics().into_iter().map(|t| (t.topic, t.schema_name, t.message_count)).collect()
    }

    /// Whether the file was finished (summary and footer written).
    fn is_complete(&self) -> bool {
        self.reader.is_complete()
    }

    /// What could be read of an unfinished file (None for a complete one).
    fn unfinished_note(&self) -> Option<String> {
        self.reader.unfinished_note()
    }

    /// The metadata records: (name, {key: value}).
    fn metadata(&self) -> Vec<(String, BTreeMap<String, String>)> {
        self.reader.metadata()
    }

    /// Messages in log-time order: `topics` (None = all), log time in [start, end) ns.
    #[pyo3(signature = (topics=None, start=None, end=None))]
    fn messages(&self, topics: Option<Vec<String>>, start: Option<u64>, end: Option<u64>) -> PyResult<MessageIter> {
        let opts = ReadOptions { topics, start_time: start, end_time: end };
        let it = self.reader.shared_messages(&opts).map_err(mcap_error)?;
        Ok(MessageIter { it })
    }
}

/// Iterator over a recording's messages: (topic, schema, sequence, log_time, publish_time, bytes).
#[pyclass(module = "sonoflow._native", unsendable)]
struct MessageIter {
    it: SharedMessageIter,
}

#[pymethods]
impl MessageIter {
    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    #[allow(clippy::type_complexity)]
    fn __next__<'py>(
        &mut self,
        py: Python<'py>,
    ) -> PyResult<Option<(String, String, u32, u64, u64, Bound<'py, pyo3::types::PyBytes>)>> {
        match self.it.next() {
            None => Ok(None),
            Some(Err(e)) => Err(mcap_error(e)),
            Some(Ok(m)) => Ok(Some((
                m.topic,
                m.schema_name,
                m.sequence,
                m.log_time,
                m.publish_time,
                pyo3::types::PyBytes::new(py, &m.data),
            ))),
        }
    }
}

/// The wire constants a node written in Python needs: plane ids, vector sources, header flags.
#[pyfunction]
fn wire_constants() -> BTreeMap<&'static str, u32> {
    use sonoflow_messages::plane;
    BTreeMap::from([
        ("PLANE_NONE", plane::NONE),
        ("PLANE_VELOCITY", plane::VELOCITY),
        ("PLANE_POWER", plane::POWER),
        ("PLANE_VARIANCE", plane::VARIANCE),
        ("PLANE_FLAGS", plane::FLAGS),
        ("PLANE_VX", plane::VX),
        ("PLANE_VZ", plane::VZ),
        ("PLANE_MASK", plane::MASK),
        ("PLANE_WEIGHT", plane::WEIGHT),
        ("PLANE_PROJECTION_X", plane::PROJECTION_X),
        ("PLANE_PROJECTION_Z", plane::PROJECTION_Z),
        ("VECTOR_RAW", sonoflow_messages::VECTOR_RAW),
        ("APODIZATION_HANN", sonoflow_messages::APODIZATION_HANN),
        ("VECTOR_REGULARISED", sonoflow_messages::VECTOR_REGULARISED),
        ("VECTOR_TRUTH", sonoflow_messages::VECTOR_TRUTH),
        ("FLAG_END_OF_STREAM", sonoflow_messages::FLAG_END_OF_STREAM),
        ("FLAG_REPLAYED", sonoflow_messages::FLAG_REPLAYED),
        ("FLAG_RESET", sonoflow_messages::FLAG_RESET),
    ])
}

fn kit_error(e: sonoflow_node_kit::KitError) -> PyErr {
    match e {
        sonoflow_node_kit::KitError::Terminated => {
            pyo3::exceptions::PyKeyboardInterrupt::new_err("terminated (SIGINT/SIGTERM)")
        }
        e => pyo3::exceptions::PyRuntimeError::new_err(e.to_string()),
    }
}

/// A graph node written in Python: the node kit's ports (`SONOFLOW_NODE_CONFIG`, set by the
/// launcher for an `exec` node), type-erased: messages in and out as header and payload bytes.
#[pyclass(module = "sonoflow._native", unsendable)]
struct NodeKit {
    kit: Option<sonoflow_node_kit::Kit>,
    inputs: BTreeMap<String, Box<dyn sonoflow_node_kit::DynInput>>,
    outputs: BTreeMap<String, Box<dyn sonoflow_node_kit::DynOutput>>,
    eos: BTreeMap<String, bool>,
}

impl NodeKit {
    fn kit(&mut self) -> PyResult<&mut sonoflow_node_kit::Kit> {
        self.kit.as_mut().ok_or_else(|| pyo3::exceptions::PyRuntimeError::new_err("the node is finished"))
    }
}

#[pymethods]
impl NodeKit {
    /// Starts the node from the launcher's environment and completes the start-up handshake on
    /// every wired port. (The node kit's shared-memory ports belong to the thread that made them, so the GIL stays
    /// held here and in every method; `receive` never blocks.)
    #[new]
    fn new() -> PyResult<Self> {
        let build = || -> Result<Self, sonoflow_node_kit::KitError> {
            let mut kit = sonoflow_node_kit::Kit::from_env()?;
            let mut inputs = BTreeMap::new();
            for (port, q) in kit.cfg.inputs.clone() {
                inputs.insert(port, kit.dyn_input(&q)?);
            }
            let mut outputs = BTreeMap::new();
            for (port, q) in kit.cfg.outputs.clone() {
                outputs.insert(port, kit.dyn_output(&q)?);
            }
            {
                let mut ports: Vec<&mut dyn sonoflow_node_kit::Handshake> = Vec::new();
                for i in inputs.values_mut() {
                    ports.push(i.as_mut() as &mut dyn sonoflow_node_kit::Handshake);
                }
                for o in outputs.values_mut() {
                    ports.push(o.as_mut() as &mut dyn sonoflow_node_kit::Handshake);
                }
                kit.handshake(&mut ports)?;
            }
            let eos = inputs.keys().map(|k| (k.clone(), false)).collect();
            Ok(Self { kit: Some(kit), inputs, outputs, eos })
        };
        build().map_err(kit_error)
    }

    /// Raises KeyboardInterrupt once SIGINT/SIGTERM was received.
    fn check_termination(&mut self) -> PyResult<()> {
        self.kit()?.check_termination().map_err(kit_error)
    }

    /// The node's name.
    fn name(&mut self) -> PyResult<String> {
        Ok(self.kit()?.cfg.node_name.clone())
    }

    /// The node's `[params]` as JSON.
    fn params(&mut self) -> PyResult<String> {
        Ok(self.kit()?.cfg.params.to_string())
    }

    /// {port: message type} of the inputs and of the outputs.
    #[allow(clippy::type_complexity)]
    fn ports(&mut self) -> (BTreeMap<String, String>, BTreeMap<String, String>) {
        let i = self.inputs.iter().map(|(k, v)| (k.clone(), v.kind().name().to_string())).collect();
        let o = self.outputs.iter().map(|(k, v)| (k.clone(), v.kind().name().to_string())).collect();
        (i, o)
    }

    /// Takes the next message of input `port` without waiting: (header bytes, payload bytes),
    /// `False` at (and after) end of stream, `None` when nothing is queued.
    fn try_receive<'py>(&mut self, py: Python<'py>, port: &str) -> PyResult<Bound<'py, PyAny>> {
        if self.eos.get(port).copied().unwrap_or(false) {
            return Ok(pyo3::types::PyBool::new(py, false).to_owned().into_any());
        }
        let input = self
            .inputs
            .get_mut(port)
            .ok_or_else(|| value_error("port", format!("`{port}` is not an input of this node")))?;
        let mut msg = None;
        let got = input
            .receive_with(&mut |h, p| {
                msg = Some((h.to_vec(), p.to_vec()));
                Ok(())
            })
            .map_err(kit_error)?;
        match (got, msg) {
            (None, _) => Ok(py.None().into_bound(py)),
            (Some(true), _) => {
                self.eos.insert(port.to_string(), true);
                Ok(pyo3::types::PyBool::new(py, false).to_owned().into_any())
            }
            (Some(false), Some((h, p))) => {
                self.kit()?.stats.messages_in += 1;
                let t = (pyo3::types::PyBytes::new(py, &h), pyo3::types::PyBytes::new(py, &p));
                Ok(t.into_pyobject(py)?.into_any())
            }
            (Some(false), None) => Err(pyo3::exceptions::PyRuntimeError::new_err("receive: message without bytes")),
        }
    }

    /// Publishes (header bytes, payload bytes) on output `port` and counts it (`compute_ns` of
    /// the header: the stage statistics).
    fn publish(
        &mut self,
        port: &str,
        header: &[u8],
        payload: &[u8],
        frame_id: u64,
        t_valid: f64,
        compute_ns: u64,
    ) -> PyResult<()> {
        let out = self
            .outputs
            .get_mut(port)
            .ok_or_else(|| value_error("port", format!("`{port}` is not an output of this node")))?;
        out.publish_bytes(header, payload, 0).map_err(kit_error)?;
        self.kit()?.published(payload.len() as u64, frame_id, t_valid, compute_ns).map_err(kit_error)
    }

    /// Sends end of stream on every output and ends the node (statistics line for the report).
    fn finish(&mut self, t_valid: f64) -> PyResult<()> {
        for o in self.outputs.values_mut() {
            o.eos(t_valid).map_err(kit_error)?;
        }
        let mut kit =
            self.kit.take().ok_or_else(|| pyo3::exceptions::PyRuntimeError::new_err("the node is finished"))?;
        kit.stats.gaps = self.inputs.values().map(|i| i.counters().1).sum();
        kit.finish().map_err(kit_error)?;
        Ok(())
    }
}

/// The native module.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(set_threads, m)?)?;
    m.add_function(wrap_pyfunction!(threads, m)?)?;
    m.add_function(wrap_pyfunction!(probe_presets, m)?)?;
    m.add_function(wrap_pyfunction!(probe_preset, m)?)?;
    m.add_function(wrap_pyfunction!(txdelay, m)?)?;
    m.add_function(wrap_pyfunction!(simus, m)?)?;
    m.add_function(wrap_pyfunction!(rf2iq, m)?)?;
    m.add_function(wrap_pyfunction!(das, m)?)?;
    m.add_function(wrap_pyfunction!(dasmtx, m)?)?;
    m.add_function(wrap_pyfunction!(iq2doppler, m)?)?;
    m.add_function(wrap_pyfunction!(bmode, m)?)?;
    m.add_function(wrap_pyfunction!(tgc_gain_iq, m)?)?;
    m.add_function(wrap_pyfunction!(tgc_gain_rf, m)?)?;
    m.add_function(wrap_pyfunction!(genscat, m)?)?;
    m.add_function(wrap_pyfunction!(sptrack, m)?)?;
    m.add_function(wrap_pyfunction!(pfield, m)?)?;
    m.add_function(wrap_pyfunction!(smoothn, m)?)?;
    m.add_function(wrap_pyfunction!(vector_doppler, m)?)?;
    m.add_function(wrap_pyfunction!(aperture_projection, m)?)?;
    m.add_function(wrap_pyfunction!(wire_layout, m)?)?;
    m.add_class::<RecordingReader>()?;
    m.add_class::<MessageIter>()?;
    m.add_function(wrap_pyfunction!(wire_constants, m)?)?;
    m.add_class::<NodeKit>()?;
    Ok(())
}
