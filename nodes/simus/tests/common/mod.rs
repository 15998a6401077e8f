//! Shared helpers of the integration tests: a tiny .npy reader and scene loading.
#![allow(dead_code, clippy::unwrap_used)]

use std::path::{Path, PathBuf};

use sonoflow_simus::{Baffle, Medium, Probe, Scatterers, SimusOptions, Transmit};

/// Reads a little-endian float32 or float64 C-order .npy file; returns (shape, data as f32).
pub fn read_npy(path: &Path) -> (Vec<usize>, Vec<f32>) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(&bytes[..6], b"\x93NUMPY", "not an npy file");
    let (hlen, hstart) = if bytes[6] == 1 {
        (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10)
    } else {
        (u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize, 12)
    };
    let header = std::str::from_utf8(&bytes[hstart..hstart + hlen]).unwrap();
    assert!(header.contains("'fortran_order': False"), "{header}");
    let descr = header.split("'descr':").nth(1).unwrap().split('\'').nth(1).unwrap();
    let shape_txt = header.split("'shape':").nth(1).unwrap();
    let shape_txt = &shape_txt[shape_txt.find('(').unwrap() + 1..shape_txt.find(')').unwrap()];
    let shape: Vec<usize> =
        shape_txt.split(',').map(str::trim).filter(|s| !s.is_empty()).map(|s| s.parse().unwrap()).collect();
    let body = &bytes[hstart + hlen..];
    let data: Vec<f32> = match descr {
        "<f4" => body.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect(),
        "<f8" => body
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]) as f32)
            .collect(),
        d => panic!("unsupported dtype {d}"),
    };
    assert_eq!(data.len(), shape.iter().product::<usize>());
    (shape, data)
}

/// Directory of the PyMUST reference scenes.
pub fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests").join("data")
}

/// One PyMUST reference scene.
pub struct Scene {
    pub name: String,
    pub probe: Probe,
    pub medium: Medium,
    pub options: SimusOptions,
    pub transmit: Transmit,
    pub scatterers: Scatterers,
    /// PyMUST RF, element-major (transposed from PyMUST's (n_samples, n_elements)).
    pub rf: Vec<f32>,
    pub n_samples: usize,
    pub meta: serde_json::Value,
}

pub fn load_scene(name: &str) -> Scene {
    let dir = data_dir().join(name);
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("scene.json")).unwrap()).unwrap();
    let p = &meta["param"];
    let f = |k: &str| p[k].as_f64().unwrap_or_else(|| panic!("{name}: param.{k}"));
    let baffle = match &p["baffle"] {
        serde_json::Value::String(s) if s == "rigid" => Baffle::Rigid,
        serde_json::Value::Number(n) => Baffle::Impedance(n.as_f64().unwrap()),
        _ => Baffle::Soft,
    };
    let probe = Probe {
        fc: f("fc"),
        pitch: f("pitch"),
        width: Some(f("width")),
        kerf: Some(f("kerf")),
        n_elements: p["Nelements"].as_u64().unwrap() as usize,
        bandwidth: p["bandwidth"].as_f64().unwrap_or(75.0),
        baffle,
        tx_now: p["TXnow"].as_f64().unwrap_or(1.0),
        radius: None,
        focus: None,
        height: None,
    };
    let medium = Medium { c: f("c"), attenuation: f("attenuation") };
    let options = SimusOptions {
        fs: Some(f("fs")),
        db_thresh: meta["options"]["dBThresh"].as_f64().unwrap(),
        ..SimusOptions::default()
    };
    let transmit = Transmit {
        delays: p["TXdelay"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap_or(f64::NAN)).collect(),
        apodization: p["TXapodization"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect(),
    };
    let (_, x) = read_npy(&dir.join("x.npy"));
    let (_, z) = read_npy(&dir.join("z.npy"));
    let (_, rc) = read_npy(&dir.join("rc.npy"));
    let (shape, rf_sm) = read_npy(&dir.join("rf.npy"));
    let (ns, ne) = (shape[0], shape[1]);
    assert_eq!(ne, probe.n_elements);
    let mut rf = vec![0.0; ns * ne];
    for k in 0..ns {
        for e in 0..ne {
            rf[e * ns + k] = rf_sm[k * ne + e];
        }
    }
    Scene {
        name: name.to_string(),
        probe,
        medium,
        options,
        transmit,
        scatterers: Scatterers::new(x, z, rc).unwrap(),
        rf,
        n_samples: ns,
        meta,
    }
}

/// Names of all stored scenes.
pub fn scene_names() -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(data_dir())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.path().join("scene.json").exists())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// Squared envelope `x² + H{x}²` of a real signal (Hilbert transform by FFT, zero-padded to 2n).
pub fn envelope2(x: &[f32]) -> Vec<f64> {
    use num_complex::Complex;
    let n = 2 * x.len();
    let mut planner = realfft::RealFftPlanner::<f64>::new();
    let fwd = planner.plan_fft_forward(n);
    let inv = planner.plan_fft_inverse(n);
    let mut buf: Vec<f64> = x.iter().map(|v| f64::from(*v)).chain(std::iter::repeat(0.0)).take(n).collect();
    let mut spec = fwd.make_output_vec();
    fwd.process(&mut buf, &mut spec).unwrap();
    let last = spec.len() - 1;
    for (k, v) in spec.iter_mut().enumerate() {
        // Hilbert transform: multiply by -i sign(f); DC and Nyquist -> 0
        *v = if k == 0 || k == last { Complex::new(0.0, 0.0) } else { Complex::new(v.im, -v.re) };
    }
    let mut h = inv.make_output_vec();
    inv.process(&mut spec, &mut h).unwrap();
    x.iter().zip(&h).map(|(a, b)| f64::from(*a).powi(2) + (b / n as f64).powi(2)).collect()
}

/// Centroid time (s) of the squared envelope of `x` sampled at `fs` from `t0`, over the
/// samples within `half_window` seconds of `around` (to exclude other echoes, e.g. edge waves).
pub fn envelope_centroid(x: &[f32], fs: f64, t0: f64, around: f64, half_window: f64) -> f64 {
    let e = envelope2(x);
    let (mut num, mut den) = (0.0, 0.0);
    for (k, v) in e.iter().enumerate() {
        let t = t0 + k as f64 / fs;
        if (t - around).abs() <= half_window {
            num += t * v;
            den += v;
        }
    }
    num / den
}

/// One-element selection: element `i` transmits alone (all other apodisation weights 0).
pub fn single_element_transmit(n: usize, i: usize) -> Transmit {
    let mut apodization = vec![0.0; n];
    apodization[i] = 1.0;
    Transmit { delays: vec![0.0; n], apodization }
}

/// Engine without PyMUST's small-value zeroing (a non-linear step), other options default.
pub fn linear_engine(probe: &Probe, medium: &Medium, options: SimusOptions) -> sonoflow_simus::Simus {
    sonoflow_simus::Simus::new(probe.clone(), medium.clone(), SimusOptions { zero_small_values: false, ..options })
        .unwrap()
}
