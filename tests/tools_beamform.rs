#![allow(clippy::unwrap_used)]
//! `sonoflow rf2iq`, `sonoflow das` and `sonoflow doppler` as a user runs them: real files in,
//! real files out, compared with the `sonoflow-beamform` library called directly (bit-exact: the
//! tools call the same code on the same f32/f64 data), an end-to-end SIMUS → rf2iq → das point
//! scatterer, a synthetic Doppler packet of known phase rotation, and bad inputs.

mod common;
use common::{arg as s, lcg_noise as noise, run_tool as cli};
use sonoflow_beamform::testkit::centroid;
use sonoflow_beamform::{
    to_element_major, to_sample_major, DasParams, DasPlan, Grid, Interpolation, Rf2Iq, Rf2IqParams, RfView, TxWave, C32,
};
use sonoflow_doppler::{flags, ClutterParams, DopplerEstimator, DopplerParams, Estimator, Packet};
use sonoflow_fileio::npy;
use std::path::{Path, PathBuf};

fn c32(c: &sonoflow_beamform::Complex<f64>) -> C32 {
    C32::new(c.re as f32, c.im as f32)
}

fn read_c32(p: &Path) -> (Vec<usize>, Vec<C32>) {
    let a = npy::read_complex(p).unwrap();
    (a.shape, a.data.iter().map(c32).collect())
}

fn json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

/// The paper probe as a MUST param file (`sonoflow simus` accepts it; its keys are MUST's).
const PAPER_PARAM: &str = r#"{"fc": 5e6, "pitch": 3e-4, "kerf": 35e-6, "Nelements": 128, "bandwidth": 75, "TXnow": 6}"#;

/// Synthetic RF: a 5 MHz tone burst per element with noise, sample-major (n_samples, n_elements).
fn synthetic_rf(ns: usize, ne: usize, fs: f64) -> Vec<f32> {
    let nz = noise(7, ns * ne);
    let mut rf = vec![0.0f32; ns * ne];
    for k in 0..ns {
        for e in 0..ne {
            let t = k as f64 / fs;
            let env = (-((k as f64 - 80.0 - 5.0 * e as f64) / 25.0).powi(2)).exp();
            rf[k * ne + e] = (env * (2.0 * std::f64::consts::PI * 5e6 * t).sin() + 0.05 * nz[k * ne + e]) as f32;
        }
    }
    rf
}

#[test]
fn rf2iq_tool_matches_the_library() {
    let dir = tempfile::tempdir().unwrap();
    let (ns, ne, fs) = (200, 6, 20e6);
    let rf = synthetic_rf(ns, ne, fs);
    let rf_path = dir.path().join("rf.npy");
    npy::write_f32(&rf_path, &[ns, ne], false, &rf).unwrap();

    // 1. A simus-style param file with fs, t0 and bandwidth; unknown MUST keys are ignored.
    let param = dir.path().join("p.json");
    std::fs::write(
        &param,
        r#"{"fc": 5e6, "fs": 20e6, "t0": 1e-6, "bandwidth": 60, "pitch": 3e-4, "kerf": 35e-6,
            "Nelements": 6, "TXnow": 6, "TXdelay": [0, 0, null, 0, 0, 0], "baffle": "soft"}"#,
    )
    .unwrap();
    let out = dir.path().join("iq.npy");
    let (code, stdout, stderr) = cli("rf2iq", &["--rf", s(&rf_path), "--param", s(&param), "--out", s(&out)]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("fs 20000000 Hz from --param"), "{stdout}");
    let (shape, got) = read_c32(&out);
    assert_eq!(shape, vec![ns, ne]);
    let params = Rf2IqParams { fc: 5e6, fs, bandwidth: Some(60.0), t0: 1e-6, order: 5 };
    let expect = Rf2Iq::new(params.clone()).unwrap().process_to_vec(RfView::sample_major(&rf, ns, ne)).unwrap();
    assert!(got == to_sample_major(&expect, ns, ne).unwrap(), "tool output differs from the library");
    let side = json(&out.with_extension("json"));
    assert_eq!(side["fs"].as_f64().unwrap(), fs);
    assert_eq!(side["t0"].as_f64().unwrap(), 1e-6);
    assert_eq!(side["cutoff_wn"].as_f64().unwrap(), params.cutoff());

    // 2. TOML param without fs/t0/bandwidth: fs and t0 from the `sonoflow simus` sidecar rf.json,
    //    then --t0 overrides the sidecar's t0.
    let toml_param = dir.path().join("p.toml");
    std::fs::write(&toml_param, "fc = 5e6\npitch = 3e-4\nNelements = 6\n").unwrap();
    std::fs::write(
        rf_path.with_extension("json"),
        r#"{"fs": 20e6, "t0": 2e-7, "n_samples": 200, "n_elements": 6, "kernel": "x"}"#,
    )
    .unwrap();
    let out2 = dir.path().join("iq2.npy");
    let (code, stdout, stderr) = cli("rf2iq", &["--rf", s(&rf_path), "--param", s(&toml_param), "--out", s(&out2)]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("from sidecar rf.json, t0 0.0000002 s from sidecar rf.json"), "{stdout}");
    let mut params = Rf2IqParams::new(5e6, fs, None);
    params.t0 = 2e-7;
    let expect = Rf2Iq::new(params.clone()).unwrap().process_to_vec(RfView::sample_major(&rf, ns, ne)).unwrap();
    assert!(read_c32(&out2).1 == to_sample_major(&expect, ns, ne).unwrap());
    let (code, stdout, stderr) =
        cli("rf2iq", &["--rf", s(&rf_path), "--t0", "-1e-7", "--param", s(&toml_param), "--out", s(&out2)]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("from --t0"), "{stdout}");
    params.t0 = -1e-7;
    let expect = Rf2Iq::new(params).unwrap().process_to_vec(RfView::sample_major(&rf, ns, ne)).unwrap();
    assert!(read_c32(&out2).1 == to_sample_major(&expect, ns, ne).unwrap());
}

#[test]
fn das_tool_matches_the_library() {
    let dir = tempfile::tempdir().unwrap();
    let (ns, ne) = (400, 16);
    let (re, im) = (noise(1, ns * ne), noise(2, ns * ne));
    let iq: Vec<C32> = re.iter().zip(&im).map(|(a, b)| C32::new(*a as f32, *b as f32)).collect();
    let iq_path = dir.path().join("iq.npy");
    npy::write_c64(&iq_path, &[ns, ne], &iq).unwrap();
    let param = dir.path().join("p.json");
    std::fs::write(
        &param,
        r#"{"fc": 5e6, "c": 1500, "fs": 20e6, "t0": 1e-6, "pitch": 3e-4, "Nelements": 16, "fnumber": 1.5,
            "kerf": 35e-6, "PRF": 1e4, "interpolation": "linear"}"#,
    )
    .unwrap();
    let out = dir.path().join("bf.npy");
    let grid_arg = "-2e-3,1e-4,41,4e-3,1e-4,31";
    let (code, stdout, stderr) = cli(
        "das",
        &[
            "--iq",
            s(&iq_path),
            "--param",
            s(&param),
            "--grid",
            grid_arg,
            "--rx-angle",
            "-15",
            "--tx-angle",
            "5",
            "--out",
            s(&out),
        ],
    );
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("31 × 41 image (tx +5°, rx -15°"), "{stdout}");
    let (shape, got) = read_c32(&out);
    assert_eq!(shape, vec![31, 41]);
    let grid = Grid { x0: -2e-3, dx: 1e-4, nx: 41, z0: 4e-3, dz: 1e-4, nz: 31 };
    let params = DasParams {
        fc: 5e6,
        c: 1500.0,
        fs: 20e6,
        t0: 1e-6,
        pitch: 3e-4,
        n_elements: 16,
        radius: None,
        fnumber: 1.5,
        rx_angle: (-15f64).to_radians(),
        interpolation: Interpolation::Linear,
        apodization: Default::default(),
    };
    let plan = DasPlan::new(&params, &TxWave::PlaneWave { tilt: 5f64.to_radians() }, &grid, ns).unwrap();
    let expect = plan.apply_to_vec(&to_element_major(&iq, ns, ne).unwrap()).unwrap();
    assert!(plan.n_taps() > 1000);
    assert!(got == expect, "tool output differs from the library");
    let side = json(&out.with_extension("json"));
    assert_eq!(side["grid"]["dz"].as_f64().unwrap(), 1e-4);
    assert_eq!(side["n_taps"].as_u64().unwrap() as usize, plan.n_taps());
}

/// `sonoflow simus` (paper probe via a MUST param file, two point scatterers) → `sonoflow rf2iq`
/// (fs, t0 from simus's sidecar) → `sonoflow das` (same param file; 0° full aperture, and ±15°
/// sub-apertures with F# 1.5 from a second file): the −3 dB main-lobe centroid lies within λ/10
/// of the scatterer (SIMUS's time zero is within 9–18 ns of the pulse centre, ≤ 14 µm).
#[test]
fn simus_rf2iq_das_focuses_a_point_scatterer() {
    let dir = tempfile::tempdir().unwrap();
    let d = |n: &str| -> PathBuf { dir.path().join(n) };
    let lambda = 1540.0 / 5e6;
    let (xs, zs) = (2.0e-3, 20.0e-3);
    std::fs::write(d("s.csv"), format!("x,z,rc\n{xs},{zs},1\n-4e-3,12e-3,1\n")).unwrap();
    std::fs::write(d("p.json"), PAPER_PARAM).unwrap();
    let (code, _, err) = cli(
        "simus",
        &["--scatterers", s(&d("s.csv")), "--param", s(&d("p.json")), "--tilt-deg", "0", "--out", s(&d("rf.npy"))],
    );
    assert_eq!(code, 0, "{err}");
    let (code, stdout, err) =
        cli("rf2iq", &["--rf", s(&d("rf.npy")), "--param", s(&d("p.json")), "--out", s(&d("iq.npy"))]);
    assert_eq!(code, 0, "{err}");
    assert!(stdout.contains("from sidecar rf.json"), "{stdout}");
    // F# 1.5 for the steered sub-apertures: MUST's param with `fnumber` added.
    std::fs::write(d("p15.json"), PAPER_PARAM.replace('}', r#", "fnumber": 1.5}"#)).unwrap();
    let grid = Grid { x0: xs - 0.5e-3, dx: 2e-5, nx: 51, z0: zs - 1.5e-3, dz: 2e-5, nz: 151 };
    let grid_arg = format!("{},{},{},{},{},{}", grid.x0, grid.dx, grid.nx, grid.z0, grid.dz, grid.nz);
    for (rx, param) in [("0", "p.json"), ("-15", "p15.json"), ("15", "p15.json")] {
        let out = d(&format!("bf{rx}.npy"));
        let (iq, param) = (d("iq.npy"), d(param));
        let args = ["--iq", s(&iq), "--param", s(&param), "--grid", &grid_arg, "--rx-angle", rx];
        let (code, _, err) = cli("das", &[&args[..], &["--out", s(&out)]].concat());
        assert_eq!(code, 0, "{err}");
        let (shape, img) = read_c32(&out);
        assert_eq!(shape, vec![grid.nz, grid.nx]);
        let (x, z) = centroid(&img, &grid).expect("main lobe inside the grid");
        let (ex, ez) = ((x - xs) / lambda, (z - zs) / lambda);
        println!("rx {rx}°: centroid error x {ex:+.4} λ, z {ez:+.4} λ");
        assert!(ex.abs() < 0.1 && ez.abs() < 0.1, "rx {rx}°: ({ex:.3}, {ez:.3}) λ");
    }
}

/// The same chain on the convex C5-2v, its geometry from a MUST param file with `radius` (the
/// tools read it; the das tool's "plane wave" is MUST's tangent-line law on the arc, as simus's
/// `--tilt-deg`): a scatterer 40 mm in front of the face on the 15° beam focuses within λ/10
/// (−3 dB centroid, F# 1.5). The radius also travels through the sidecars (simus → rf2iq → das):
/// a das param file without it focuses as well; one that says `radius = inf` (a linear array)
/// does not, with a warning.
#[test]
fn convex_simus_rf2iq_das_chain_focuses() {
    let dir = tempfile::tempdir().unwrap();
    let d = |n: &str| -> PathBuf { dir.path().join(n) };
    let probe = sonoflow_simus::Probe::preset("C5-2v").unwrap();
    let (r, h, lambda) = (probe.radius.unwrap(), probe.apothem(), 1540.0 / probe.fc);
    let (sn, cs) = 15f64.to_radians().sin_cos();
    let (xs, zs) = ((r + 0.04) * sn, (r + 0.04) * cs - h);
    std::fs::write(d("s.csv"), format!("x,z,rc\n{xs},{zs},1\n")).unwrap();
    let convex = r#"{"fc": 3.57e6, "pitch": 5.08e-4, "width": 4.6e-4, "Nelements": 128, "bandwidth": 79, "radius": 0.04957, "fnumber": 1.5}"#;
    std::fs::write(d("c.json"), convex).unwrap();
    std::fs::write(d("nor.json"), convex.replace(r#", "radius": 0.04957"#, "")).unwrap();
    std::fs::write(d("lin.toml"), "fc = 3.57e6\npitch = 5.08e-4\nNelements = 128\nradius = inf\nfnumber = 1.5\n")
        .unwrap();
    let (sc, cj, rf, iqp) = (d("s.csv"), d("c.json"), d("rf.npy"), d("iq.npy"));
    let args = ["--scatterers", s(&sc), "--param", s(&cj), "--tilt-deg", "5", "--out", s(&rf)];
    let (code, _, err) = cli("simus", &args);
    assert_eq!(code, 0, "{err}");
    assert_eq!(json(&d("rf.json"))["radius"].as_f64(), Some(0.04957));
    let (code, _, err) = cli("rf2iq", &["--rf", s(&rf), "--param", s(&d("nor.json")), "--out", s(&iqp)]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(json(&d("iq.json"))["radius"].as_f64(), Some(0.04957));
    let grid = Grid { x0: xs - 1.5e-3, dx: 3e-5, nx: 101, z0: zs - 1.5e-3, dz: 3e-5, nz: 101 };
    let grid_arg = format!("{},{},{},{},{},{}", grid.x0, grid.dx, grid.nx, grid.z0, grid.dz, grid.nz);
    let mut errors = Vec::new();
    for param in ["c.json", "nor.json", "lin.toml"] {
        let (iq, pp, out) = (d("iq.npy"), d(param), d("bf.npy"));
        let args = ["--iq", s(&iq), "--param", s(&pp), "--grid", &grid_arg, "--tx-angle", "5", "--out", s(&out)];
        let (code, _, err) = cli("das", &args);
        assert_eq!(code, 0, "{err}");
        if param == "lin.toml" {
            assert!(err.contains("warning: `radius`"), "{err}");
        }
        let (_, img) = read_c32(&out);
        let e = centroid(&img, &grid).map(|(x, z)| ((x - xs) / lambda).hypot((z - zs) / lambda));
        println!("{param}: centroid error {e:?} λ");
        errors.push(e);
    }
    assert!(errors[0].is_some_and(|e| e < 0.1), "convex: {:?}", errors[0]);
    assert_eq!(errors[1], errors[0], "the radius from the sidecar");
    assert!(errors[2].is_none_or(|e| e > 1.0), "the linear geometry should not focus: {:?}", errors[2]);
}

/// `sonoflow simus` with a y column (x,y,z,rc): MUST's elevation model, the library's
/// `simulate_3d` bit for bit; an in-plane file gives the 2-D RF, and the echoes 1.5 and 0.2 mm off
/// the plane are weaker than in it (the element height's beam at its elevation focus).
#[test]
fn simus_tool_reads_elevation() {
    let dir = tempfile::tempdir().unwrap();
    let d = |n: &str| -> PathBuf { dir.path().join(n) };
    std::fs::write(d("s3.csv"), "x,y,z,rc\n1e-3,1.5e-3,18e-3,1\n-2e-3,0.2e-3,25e-3,0.5\n").unwrap();
    std::fs::write(d("s2.csv"), "x,z,rc\n1e-3,18e-3,1\n-2e-3,25e-3,0.5\n").unwrap();
    std::fs::write(d("s0.csv"), "x,y,z,rc\n1e-3,1e-8,18e-3,1\n-2e-3,1e-8,25e-3,0.5\n").unwrap();
    for (f, out) in [("s3.csv", "rf3.npy"), ("s2.csv", "rf2.npy"), ("s0.csv", "rf0.npy")] {
        let (fp, op) = (d(f), d(out));
        let args = ["--scatterers", s(&fp), "--param", "L11-5v", "--tilt-deg", "0", "--out", s(&op)];
        let (code, _, err) = cli("simus", &args);
        assert_eq!(code, 0, "{err}");
    }
    let probe = sonoflow_simus::Probe::preset("L11-5v").unwrap();
    let medium = sonoflow_simus::Medium::default();
    let tx = sonoflow_simus::Transmit::plane_wave(&probe, medium.c, 0.0).unwrap();
    let scat = sonoflow_simus::Scatterers::new(vec![1e-3, -2e-3], vec![18e-3, 25e-3], vec![1.0, 0.5]).unwrap();
    let mut sim = sonoflow_simus::Simus::new(probe, medium, Default::default()).unwrap();
    let lib3 = sim.simulate_3d(&scat, &[1.5e-3, 0.2e-3], &tx).unwrap();
    let lib2 = sim.simulate(&scat, &tx).unwrap();
    let (f3, f2) = (npy::read(&d("rf3.npy")).unwrap(), npy::read(&d("rf2.npy")).unwrap());
    assert_eq!(f3.shape, vec![lib3.n_samples, 128]);
    // the file is sample-major (n_samples, n_elements), the library element-major
    let at = |v: &[f32], k: usize, e: usize, ns: usize| f64::from(v[e * ns + k]);
    for (file, lib) in [(&f3, &lib3), (&f2, &lib2)] {
        for k in (0..lib.n_samples).step_by(7) {
            for e in (0..128).step_by(9) {
                assert_eq!(file.data[k * 128 + e], at(&lib.data, k, e, lib.n_samples));
            }
        }
    }
    // the same scatterers in the plane with the elevation model on (y = 1e-8): stronger echoes
    let f0 = npy::read(&d("rf0.npy")).unwrap();
    let energy = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>();
    assert!(energy(&f3.data) < 0.5 * energy(&f0.data), "{} vs {}", energy(&f3.data), energy(&f0.data));
}

/// A (nz, nx, n_frames) packet `x_n = A·exp(i(φ0 − n·Δφ))`: `R1 = Σ x_n conj(x_{n+1})` has
/// argument Δφ, so `v = −c·PRF·Δφ/(4π fc)`. One pixel has no signal, one rotates by 0.95π.
fn synthetic_packet(nz: usize, nx: usize, nf: usize) -> (Vec<C32>, Vec<f64>) {
    let mut data = vec![C32::new(0.0, 0.0); nz * nx * nf];
    let mut dphi = vec![0.0; nz * nx];
    for iz in 0..nz {
        for ix in 0..nx {
            let p = iz * nx + ix;
            dphi[p] = if p == 1 { 0.95 * std::f64::consts::PI } else { -0.8 + 1.6 * p as f64 / (nz * nx) as f64 };
            let amp = if p == 2 { 0.0 } else { 1.0 + 0.1 * ix as f64 };
            let phi0 = 0.3 * iz as f64;
            for n in 0..nf {
                let ph = phi0 - n as f64 * dphi[p];
                data[p * nf + n] = C32::new((amp * ph.cos()) as f32, (amp * ph.sin()) as f32);
            }
        }
    }
    (data, dphi)
}

#[test]
fn doppler_tool_recovers_a_known_phase_rotation_and_matches_the_library() {
    let dir = tempfile::tempdir().unwrap();
    let (nz, nx, nf) = (5, 6, 12);
    let (data, dphi) = synthetic_packet(nz, nx, nf);
    let pk = dir.path().join("packet.npy");
    npy::write_c64(&pk, &[nz, nx, nf], &data).unwrap();
    let param = dir.path().join("p.toml");
    std::fs::write(&param, "fc = 5e6\nc = 1540\nPRF = 4000\npitch = 3e-4\nNelements = 128\n").unwrap();
    let (fc, c, prf) = (5e6, 1540.0, 4000.0);
    let out = dir.path().join("v.npy");
    let (code, stdout, stderr) = cli("iq2doppler", &["--packet", s(&pk), "--param", s(&param), "--out", s(&out)]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("1 no-estimate, 1 aliasing"), "{stdout}");
    let v = npy::read(&out).unwrap();
    assert_eq!(v.shape, vec![nz, nx]);
    let fl = npy::read(&dir.path().join("v_flags.npy")).unwrap();
    for (p, dphi) in dphi.iter().enumerate() {
        let expect = -c * prf * dphi / (4.0 * std::f64::consts::PI * fc);
        match p {
            2 => {
                assert_eq!(v.data[p], 0.0);
                assert_eq!(fl.data[p], f64::from(flags::NO_ESTIMATE));
            }
            1 => assert_eq!(fl.data[p], f64::from(flags::ALIASING)),
            _ => {
                assert_eq!(fl.data[p], 0.0);
                let tol = 1e-5 * expect.abs().max(1e-3);
                assert!((v.data[p] - expect).abs() <= tol, "pixel {p}: {} vs {expect}", v.data[p]);
            }
        }
    }
    let side = json(&out.with_extension("json"));
    let vn = c * prf / (4.0 * fc);
    assert!((side["nyquist_velocity"].as_f64().unwrap() - vn).abs() < 1e-12 * vn);
    assert_eq!(side["estimator"], "autocorrelation");
    assert_eq!(side["flagged"]["no_estimate"], 1);
    assert_eq!(side["flagged"]["aliasing"], 1);

    // Bit-exact with the library: windowed, lag 2, both estimators.
    for (est, name) in [(Estimator::Autocorrelation, "autocorrelation"), (Estimator::Loupas, "loupas")] {
        let out = dir.path().join(format!("w_{name}.npy"));
        let (code, _, stderr) = cli(
            "doppler",
            &[
                "--packet",
                s(&pk),
                "--param",
                s(&param),
                "--window",
                "3,2",
                "--lag",
                "2",
                "--estimator",
                name,
                "--dz",
                "1e-4",
                "--out",
                s(&out),
            ],
        );
        assert_eq!(code, 0, "{stderr}");
        let mut p = DopplerParams::new(fc, c, prf);
        p.lag = 2;
        p.window = [3, 2];
        p.estimator = est;
        let map = DopplerEstimator::new(p, nx, nz, 1e-4)
            .unwrap()
            .estimate_to_map(Packet::PixelMajor { data: &data, n_frames: nf })
            .unwrap();
        let f32s = |suffix: &str| -> Vec<f32> {
            let stem = format!("w_{name}{suffix}.npy");
            npy::read(&dir.path().join(stem)).unwrap().data.iter().map(|v| *v as f32).collect()
        };
        assert!(f32s("") == map.velocity, "{name}: velocity differs from the library");
        assert!(f32s("_power") == map.power, "{name}: power differs");
        assert!(f32s("_variance") == map.variance, "{name}: variance differs");
        let fl = npy::read(&dir.path().join(format!("w_{name}_flags.npy"))).unwrap();
        assert!(fl.data.iter().map(|v| *v as u8).collect::<Vec<_>>() == map.flags, "{name}: flags differ");
    }

    // `--clutter`: the same as the library's filter then estimator, and reported in the sidecar.
    let out = dir.path().join("svd.npy");
    let (code, _, stderr) = cli(
        "doppler",
        &["--packet", s(&pk), "--param", s(&param), "--clutter", r#"{"type":"svd","rank":1}"#, "--out", s(&out)],
    );
    assert_eq!(code, 0, "{stderr}");
    let mut frames: Vec<Vec<C32>> = (0..nf).map(|t| (0..nz * nx).map(|p| data[p * nf + t]).collect()).collect();
    let mut refs: Vec<&mut [C32]> = frames.iter_mut().map(|f| f.as_mut_slice()).collect();
    let svd = ClutterParams::Svd { rank: Some(1), tissue_cutoff: 0.05, max_rank: None, gap_db: 0.0 };
    let report = svd.apply_frames(&mut refs).unwrap();
    let refs: Vec<&[C32]> = frames.iter().map(|f| f.as_slice()).collect();
    let map = DopplerEstimator::new(DopplerParams::new(fc, c, prf), nx, nz, 1.0)
        .unwrap()
        .estimate_to_map(Packet::Frames(&refs))
        .unwrap();
    let v: Vec<f32> = npy::read(&out).unwrap().data.iter().map(|v| *v as f32).collect();
    assert!(v == map.velocity, "--clutter: velocity differs from the library");
    let side = json(&out.with_extension("json"));
    assert_eq!(side["clutter"]["order_or_rank"], 1);
    assert!((side["clutter"]["removed_energy"].as_f64().unwrap() - report.removed_energy).abs() < 1e-12);
}

/// Runs a tool expecting failure: exit code 1, every `needles` in stderr, `out` not created.
fn fails(tool: &str, args: &[&str], out: &Path, needles: &[&str]) {
    let (code, _, err) = cli(tool, args);
    assert_eq!(code, 1, "{tool} {args:?}: expected exit code 1; stderr: {err}");
    for n in needles {
        assert!(err.contains(n), "{tool} {args:?}: stderr lacks {n:?}: {err}");
    }
    assert!(!out.exists(), "{tool} {args:?}: output written on error");
    assert!(!out.with_extension("json").exists(), "{tool} {args:?}: sidecar written on error");
}

#[test]
fn beamform_tools_reject_bad_input_with_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = |n: &str| -> PathBuf { dir.path().join(n) };
    let out = d("o.npy");
    let o = s(&out);
    let rf = synthetic_rf(100, 4, 20e6);
    npy::write_f32(&d("rf.npy"), &[100, 4], false, &rf).unwrap();
    std::fs::write(d("p.json"), r#"{"fc": 5e6, "fs": 20e6, "pitch": 3e-4, "Nelements": 4, "PRF": 5000}"#).unwrap();
    let (rfp, p) = (d("rf.npy"), d("p.json"));
    let (rfp, p) = (s(&rfp), s(&p));

    // rf2iq
    std::fs::write(d("nofc.json"), r#"{"fs": 20e6}"#).unwrap();
    fails("rf2iq", &["--rf", rfp, "--param", s(&d("nofc.json")), "--out", o], &out, &["missing `fc`"]);
    std::fs::write(d("nofs.json"), r#"{"fc": 5e6}"#).unwrap();
    fails("rf2iq", &["--rf", rfp, "--param", s(&d("nofs.json")), "--out", o], &out, &["missing `fs`", "rf.json"]);
    std::fs::write(d("badfc.json"), r#"{"fc": 15e6, "fs": 20e6}"#).unwrap();
    fails("rf2iq", &["--rf", rfp, "--param", s(&d("badfc.json")), "--out", o], &out, &["rf2iq.fc", "< fs/2"]);
    std::fs::write(d("badbw.json"), r#"{"fc": 5e6, "fs": 20e6, "bandwidth": 250}"#).unwrap();
    fails("rf2iq", &["--rf", rfp, "--param", s(&d("badbw.json")), "--out", o], &out, &["rf2iq.bandwidth", "]0, 200["]);
    std::fs::write(d("type.json"), r#"{"fc": "5 MHz", "fs": 20e6}"#).unwrap();
    fails("rf2iq", &["--rf", rfp, "--param", s(&d("type.json")), "--out", o], &out, &["type.json", "fc"]);
    std::fs::write(d("p.yaml"), "fc: 5e6").unwrap();
    fails("rf2iq", &["--rf", rfp, "--param", s(&d("p.yaml")), "--out", o], &out, &[".json or .toml"]);
    fails("rf2iq", &["--rf", rfp, "--param", p, "--t0", "NaN", "--out", o], &out, &["t0", "finite"]);
    fails("rf2iq", &["--rf", rfp, "--param", p, "--out", s(&d("o.bin"))], &d("o.bin"), &["--out", ".npy"]);
    // The sidecar of --out would overwrite the param file.
    std::fs::copy(d("p.json"), d("q.json")).unwrap();
    let (code, _, err) = cli("rf2iq", &["--rf", rfp, "--param", s(&d("q.json")), "--out", s(&d("q.npy"))]);
    assert!(code == 1 && err.contains("would overwrite the input") && !d("q.npy").exists(), "{err}");
    npy::write_f32(&d("short.npy"), &[10, 4], false, &rf[..40]).unwrap();
    fails("rf2iq", &["--rf", s(&d("short.npy")), "--param", p, "--out", o], &out, &["rf.n_samples", "> 18"]);
    npy::write_f32(&d("flat.npy"), &[400], false, &rf).unwrap();
    fails("rf2iq", &["--rf", s(&d("flat.npy")), "--param", p, "--out", o], &out, &["--rf", "(n_samples, n_elements)"]);
    let mut nan = rf.clone();
    nan[9] = f32::NAN;
    npy::write_f32(&d("nan.npy"), &[100, 4], false, &nan).unwrap();
    fails("rf2iq", &["--rf", s(&d("nan.npy")), "--param", p, "--out", o], &out, &["sample 2, element 1", "finite"]);
    fails("rf2iq", &["--rf", s(&d("missing.npy")), "--param", p, "--out", o], &out, &["--rf", "missing.npy"]);
    std::fs::write(d("rf.json"), r#"{"fs": 20e6, "t0": 0, "n_samples": 99, "n_elements": 4}"#).unwrap();
    fails("rf2iq", &["--rf", rfp, "--param", p, "--out", o], &out, &["rf.json", "99 samples", "100 × 4"]);
    std::fs::remove_file(d("rf.json")).unwrap();

    // das
    let iq = vec![C32::new(1.0, 0.5); 100 * 4];
    npy::write_c64(&d("iq.npy"), &[100, 4], &iq).unwrap();
    let iqp = d("iq.npy");
    let iqp = s(&iqp);
    let g = "-1e-3,1e-4,21,1e-3,1e-4,21";
    let das = |extra: &[&str], param: &str| -> Vec<String> {
        let mut v: Vec<String> = ["--iq", iqp, "--param", param, "--out", o].iter().map(|x| x.to_string()).collect();
        v.extend(extra.iter().map(|x| x.to_string()));
        v
    };
    let run_das = |extra: &[&str], param: &str, needles: &[&str]| {
        let v = das(extra, param);
        fails("das", &v.iter().map(String::as_str).collect::<Vec<_>>(), &out, needles);
    };
    run_das(&["--grid", "-1e-3,1e-4,21,1e-3,1e-4"], p, &["--grid", "5 values", "x0,dx,nx,z0,dz,nz"]);
    run_das(&["--grid", "-1e-3,1e-4,2.5,1e-3,1e-4,21"], p, &["--grid", "nx = `2.5`"]);
    run_das(&["--grid", "-1e-3,-1e-4,21,1e-3,1e-4,21"], p, &["--grid", "grid.dx", "> 0"]);
    run_das(&["--grid", g, "--rx-angle", "85"], p, &["--rx-angle 85", "< 80"]);
    run_das(&["--grid", g, "--tx-angle", "-90"], p, &["--tx-angle -90", "< 80"]);
    run_das(&["--grid", g, "--rx-angle", "15"], p, &["das.fnumber", "> 0 when rx_angle != 0"]);
    std::fs::write(d("nopitch.json"), r#"{"fc": 5e6, "fs": 20e6}"#).unwrap();
    run_das(&["--grid", g], s(&d("nopitch.json")), &["missing `pitch`"]);
    std::fs::write(d("ne.json"), r#"{"fc": 5e6, "fs": 20e6, "pitch": 3e-4, "Nelements": 128}"#).unwrap();
    run_das(&["--grid", g], s(&d("ne.json")), &["Nelements", "128", "4 elements"]);
    std::fs::write(d("fn.json"), r#"{"fc": 5e6, "fs": 20e6, "pitch": 3e-4, "fnumber": -1}"#).unwrap();
    run_das(&["--grid", g], s(&d("fn.json")), &["das.fnumber", "[0, 1000]"]);
    std::fs::write(d("interp.json"), r#"{"fc": 5e6, "fs": 20e6, "pitch": 3e-4, "interpolation": "cubic"}"#).unwrap();
    run_das(&["--grid", g], s(&d("interp.json")), &["interpolation", "linear"]);
    let v = ["--iq", rfp, "--param", p, "--grid", g, "--out", o];
    fails("das", &v, &out, &["--iq", "<f4 is not complex", "complex64"]);

    // doppler
    let (data, _) = synthetic_packet(3, 4, 4);
    npy::write_c64(&d("pk.npy"), &[3, 4, 4], &data).unwrap();
    let pk = d("pk.npy");
    let pk = s(&pk);
    let dop = |extra: &[&str], param: &str, needles: &[&str]| {
        let v = [&["--packet", pk, "--param", param, "--out", o][..], extra].concat();
        fails("doppler", &v, &out, needles);
        assert!(!d("o_flags.npy").exists() && !d("o_power.npy").exists());
    };
    dop(&["--lag", "0"], p, &["--lag 0", "[1, 64]"]);
    dop(&["--lag", "4"], p, &["4 frame(s)", "--lag 4 needs at least 5 frames"]);
    dop(&["--window", "0"], p, &["--window 0", "[1, 64]"]);
    dop(&["--window", "3,65"], p, &["--window 3,65", "[1, 64]"]);
    dop(&["--window", "3,2,1"], p, &["--window", "Mz,Mx"]);
    dop(&["--estimator", "kasai2"], p, &["--estimator kasai2", "autocorrelation, loupas"]);
    dop(&["--estimator", "loupas"], p, &["loupas needs", "--dz"]);
    dop(&["--estimator", "loupas", "--dz", "-1"], p, &["--dz -1", "> 0"]);
    dop(&["--clutter", r#"{"type":"fir"}"#], p, &["--clutter", "unknown variant `fir`"]);
    dop(&["--clutter", r#"{"type":"iir","order":4,"cutoff":0.7}"#], p, &["--clutter", "clutter.cutoff"]);
    dop(&["--clutter", r#"{"type":"svd","rank":4}"#], p, &["--clutter", "clutter.rank = 4"]);
    std::fs::write(d("noprf.json"), r#"{"fc": 5e6}"#).unwrap();
    dop(&[], s(&d("noprf.json")), &["missing `PRF`"]);
    std::fs::write(d("badprf.json"), r#"{"fc": 5e6, "PRF": -3}"#).unwrap();
    dop(&[], s(&d("badprf.json")), &["doppler.prf", "> 0"]);
    npy::write_c64(&d("pk2.npy"), &[12, 4], &data).unwrap();
    let pk2 = d("pk2.npy");
    let v = ["--packet", s(&pk2), "--param", p, "--out", o];
    fails("doppler", &v, &out, &["--packet", "expected 3 axes (nz, nx, n_frames)"]);
}
