//! Test fixtures (feature `testkit`), shared by this crate's tests, `sonoflow-beamform`'s and the
//! stability matrix (`sonoflow stability`): the PyMUST reference scenes (`tests/data`), the
//! paper-probe engine, point and random scatterers, the squared envelope and its centroid, and the
//! extreme scenes of `tests/extreme.rs` run to their measurements (the callers state the bounds).
//! Test code: it panics on a missing data file or a failed simulation.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::{Path, PathBuf};

use rand::{Rng, SeedableRng};

use crate::{Baffle, Medium, Probe, RfFrame, Scatterers, Simus, SimusOptions, Transmit};

/// Reads a little-endian real .npy file (through `sonoflow_fileio::npy`); returns (shape, data as
/// f32).
pub fn read_npy(path: &Path) -> (Vec<usize>, Vec<f32>) {
    let a = sonoflow_fileio::npy::read(path).unwrap_or_else(|e| panic!("{e}"));
    (a.shape, a.data.iter().map(|v| *v as f32).collect())
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
pub fn linear_engine(probe: &Probe, medium: &Medium, options: SimusOptions) -> Simus {
    Simus::new(probe.clone(), medium.clone(), SimusOptions { zero_small_values: false, ..options }).unwrap()
}

/// The paper probe (5 MHz, 128 elements) in the default medium with default options.
pub fn paper_engine() -> Simus {
    Simus::new(Probe::paper_5mhz(), Medium::default(), SimusOptions::default()).unwrap()
}

/// Plane wave at 0° for `p` (c = 1540 m/s).
pub fn pw0(p: &Probe) -> Transmit {
    Transmit::plane_wave(p, 1540.0, 0.0).unwrap()
}

/// One scatterer of reflection coefficient 1 at (x, z).
pub fn one(x: f32, z: f32) -> Scatterers {
    Scatterers::new(vec![x], vec![z], vec![1.0]).unwrap()
}

/// `n` scatterers uniform in x ∈ [−1, 1) cm, z ∈ [0.5, 2) cm, rc ∈ [−1, 1) (fixed seed).
pub fn random_scatterers(n: usize, seed: u64) -> Scatterers {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut s = Scatterers::default();
    for _ in 0..n {
        s.push(rng.gen_range(-0.01f32..0.01), rng.gen_range(0.005f32..0.02), rng.gen_range(-1f32..1.0));
    }
    s
}

/// Every sample finite.
pub fn all_finite(v: &[f32]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// Largest |sample|.
pub fn peak(v: &[f32]) -> f32 {
    v.iter().fold(0.0f32, |m, x| m.max(x.abs()))
}

/// Peak resident memory of this process (VmHWM, KiB; None where /proc is not there).
pub fn vm_hwm_kib() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// An empty scene through the paper engine: the RF of the per-call plan (which covers the pulse
/// only), that plan, and a fixed 5 cm plan's output buffer pre-filled with ones.
pub struct ZeroScene {
    pub rf: RfFrame,
    pub plan: crate::FrequencyPlan,
    pub n_elements: usize,
    pub fixed_plan_out: Vec<f32>,
}

/// Runs [`ZeroScene`].
pub fn zero_scatterers() -> ZeroScene {
    let p = Probe::paper_5mhz();
    let mut simus = paper_engine();
    let rf = simus.simulate(&Scatterers::default(), &pw0(&p)).unwrap();
    let plan = simus.plan_for_max_distance(0.0, 0.0).unwrap();
    let fixed = simus.plan_for_max_distance(0.05, 0.0).unwrap();
    let mut fixed_plan_out = vec![1f32; p.n_elements * fixed.n_samples];
    simus.simulate_into(&Scatterers::default(), &pw0(&p), &fixed, &mut fixed_plan_out).unwrap();
    ZeroScene { rf, plan, n_elements: p.n_elements, fixed_plan_out }
}

/// A scatterer on the array face (z = 0) at the centre of element 40 and at the centre of its
/// first sub-element (d = 0: r clamped to λ/2, |θ| = 90°, MUST's obliquity floor), and the same
/// scatterer λ/2 in front of the element.
pub struct ArrayFace {
    /// Peak of the scatterer in front.
    pub front_peak: f32,
    /// Peaks on the face: element centre, sub-element centre.
    pub face_peaks: [f32; 2],
    /// Every RF finite.
    pub finite: bool,
}

/// Runs [`ArrayFace`].
pub fn scatterer_on_array_face() -> ArrayFace {
    let p = Probe::paper_5mhz();
    let mut simus = paper_engine();
    let xe = p.element_x(40) as f32;
    let sub = (p.element_x(40) - p.element_width() / 4.0) as f32; // sub-element 0 of 2
    let front = simus.simulate(&one(xe, 1540.0 / 5e6 / 2.0), &pw0(&p)).unwrap();
    let mut finite = all_finite(&front.data);
    let face_peaks = [xe, sub].map(|x| {
        let rf = simus.simulate(&one(x, 0.0), &pw0(&p)).unwrap();
        finite &= all_finite(&rf.data);
        peak(&rf.data)
    });
    ArrayFace { front_peak: peak(&front.data), face_peaks, finite }
}

/// Scatterers 1 nm to 0.1 mm below the face, inside and far outside the aperture (|θ| → 90°):
/// (their RF finite, their peak / the peak of a scatterer 3 cm in front).
pub fn grazing_angles() -> (bool, f32) {
    let p = Probe::paper_5mhz();
    let mut simus = paper_engine();
    let s = Scatterers::new(vec![0.03, -0.004, 0.05], vec![1e-6, 1e-9, 1e-4], vec![1.0; 3]).unwrap();
    let rf = simus.simulate(&s, &pw0(&p)).unwrap();
    let front = simus.simulate(&one(0.0, 0.03), &pw0(&p)).unwrap();
    (all_finite(&rf.data), peak(&rf.data) / peak(&front.data))
}

/// A scatterer 30 cm deep under an 8-element paper probe (−40 dB band, no small-value zeroing).
pub struct DeepEcho {
    pub finite: bool,
    pub n_freq: usize,
    pub n_samples: usize,
    /// Envelope centroid of element 3's echo (±2.5 µs window) minus (z + d)/c, in samples.
    pub arrival_error: f64,
}

/// Runs [`DeepEcho`].
pub fn very_deep_scatterer() -> DeepEcho {
    let p = Probe { n_elements: 8, ..Probe::paper_5mhz() };
    let m = Medium::default();
    let mut simus = linear_engine(&p, &m, SimusOptions { db_thresh: -40.0, ..SimusOptions::default() });
    let z = 0.3f32;
    let rf = simus.simulate(&one(0.0, z), &pw0(&p)).unwrap();
    let d = p.element_x(3).hypot(f64::from(z));
    let want = (f64::from(z) + d) / m.c;
    let arrival_error = (envelope_centroid(rf.element(3), rf.fs, rf.t0, want, 2.5e-6) - want) * rf.fs;
    DeepEcho { finite: all_finite(&rf.data), n_freq: rf.plan.n_freq, n_samples: rf.n_samples, arrival_error }
}

/// `n` random scatterers (seed 99) streamed through an 8-element paper probe (−20 dB band).
pub struct ManyScatterers {
    pub finite: bool,
    pub peak: f32,
    pub n_freq: usize,
    /// Growth of the peak resident memory during the simulation (MiB; None without /proc).
    pub memory_growth_mib: Option<u64>,
}

/// Runs [`ManyScatterers`].
pub fn many_scatterers(n: usize) -> ManyScatterers {
    let p = Probe { n_elements: 8, ..Probe::paper_5mhz() };
    let s = random_scatterers(n, 99);
    let before = vm_hwm_kib();
    let o = SimusOptions { db_thresh: -20.0, ..SimusOptions::default() };
    let mut simus = Simus::new(p.clone(), Medium::default(), o).unwrap();
    let rf = simus.simulate(&s, &pw0(&p)).unwrap();
    let memory_growth_mib = match (before, vm_hwm_kib()) {
        (Some(a), Some(b)) => Some(b.saturating_sub(a) / 1024),
        _ => None,
    };
    ManyScatterers { finite: all_finite(&rf.data), peak: peak(&rf.data), n_freq: rf.plan.n_freq, memory_growth_mib }
}

/// Mean power per sample of `x` (channels of `n` samples each, sampled at `fs`) inside
/// [lo, hi] Hz, from each channel's FFT by Parseval.
pub fn band_power(x: &[f32], n: usize, fs: f64, lo: f64, hi: f64) -> f64 {
    let mut planner = realfft::RealFftPlanner::<f64>::new();
    let fft = planner.plan_fft_forward(n);
    let mut total = 0.0;
    for ch in x.chunks(n) {
        let mut buf: Vec<f64> = ch.iter().map(|&v| f64::from(v)).collect();
        let mut spec = fft.make_output_vec();
        fft.process(&mut buf, &mut spec).unwrap();
        for (k, s) in spec.iter().enumerate().skip(1) {
            let f = k as f64 * fs / n as f64;
            if f >= lo && f <= hi && 2 * k != n {
                total += 2.0 * s.norm_sqr();
            }
        }
    }
    total / (n as f64 * n as f64) / (x.len() / n) as f64
}

/// A clean SIMUS frame of 40 scatterers at 15–25 mm depth (paper probe, plane wave 0°), and
/// the probe.
pub fn forty_scatterer_frame() -> (RfFrame, Probe) {
    let probe = Probe::paper_5mhz();
    let n = 40;
    let x: Vec<f32> = (0..n).map(|i| -8e-3 + 16e-3 * i as f32 / n as f32).collect();
    let z: Vec<f32> = (0..n).map(|i| 15e-3 + 10e-3 * ((i * 7) % n) as f32 / n as f32).collect();
    let rc: Vec<f32> = (0..n).map(|i| if i % 2 == 0 { 1.0 } else { -0.7 }).collect();
    let mut simus = Simus::new(probe.clone(), Medium::default(), SimusOptions::default()).unwrap();
    let tx = Transmit::plane_wave(&probe, 1540.0, 0.0).unwrap();
    (simus.simulate(&Scatterers::new(x, z, rc).unwrap(), &tx).unwrap(), probe)
}

/// [`forty_scatterer_frame`] with receive noise at `snr_db`
/// (seed `seed`, frame key 0), and the SNR measured as `crate::noise` defines it: the clean
/// frame's mean power over the in-band power of the added noise. Returns (noisy data, measured
/// SNR in dB).
pub fn noisy_frame(snr_db: f64, seed: u64) -> (Vec<f32>, f64) {
    let (rf, probe) = forty_scatterer_frame();
    let params = crate::NoiseParams { snr_db, seed };
    let mut model = crate::NoiseModel::new(params, probe.fc, probe.bandwidth, rf.fs).unwrap();
    let mut noisy = rf.data.clone();
    model.add(&mut noisy, 0).unwrap();
    let noise: Vec<f32> = noisy.iter().zip(&rf.data).map(|(a, b)| a - b).collect();
    let ps = rf.data.iter().map(|&v| f64::from(v).powi(2)).sum::<f64>() / rf.data.len() as f64;
    let (lo, hi) = (probe.fc * (1.0 - probe.bandwidth / 2.0), probe.fc * (1.0 + probe.bandwidth / 2.0));
    let pn = band_power(&noise, rf.n_samples, rf.fs, lo, hi);
    (noisy, 10.0 * (ps / pn).log10())
}
