#![allow(clippy::unwrap_used)]
//! `sonoflow bmode` and `sonoflow genscat` as a user runs them: a synthetic I/Q image whose
//! envelope decays by a known amount with depth, through the tool, compared with the library
//! called directly (the same bytes), with an independent check of what time-gain compensation
//! does to the decay, the PNG; a speckle phantom with an anechoic cyst and a +10 dB inclusion
//! through genscat → simus → rf2iq → das → bmode, its contrasts measured on the image; bad
//! inputs (an error naming the flag, no file written).

mod common;
use common::{arg as s, lcg_noise as noise, run_tool as run};
use sonoflow_beamform::Complex;
use sonoflow_fileio::npy;
use std::path::Path;

fn cli(args: &[&str]) -> (i32, String, String) {
    run("bmode", args)
}

/// Speckle-like I/Q (nz, nx) whose envelope decays as exp(−iz / decay) with depth, rounded to
/// complex64 as the file holds it.
fn decaying_iq(nz: usize, nx: usize, decay: f64) -> Vec<Complex<f64>> {
    let (re, im) = (noise(3, nz * nx), noise(4, nz * nx));
    (0..nz * nx)
        .map(|i| {
            let a = (-((i / nx) as f64) / decay).exp();
            Complex::new(f64::from((a * re[i]) as f32), f64::from((a * im[i]) as f32))
        })
        .collect()
}

fn write_iq(path: &Path, shape: &[usize], iq: &[Complex<f64>]) {
    let c: Vec<_> = iq.iter().map(|z| sonoflow_beamform::C32::new(z.re as f32, z.im as f32)).collect();
    npy::write_c64(path, shape, &c).unwrap();
}

fn read_u8(path: &Path) -> (Vec<usize>, Vec<u8>) {
    let a = npy::read(path).unwrap();
    (a.shape, a.data.iter().map(|v| *v as u8).collect())
}

/// Mean of the B-mode bytes over rows [r0, r1).
fn band_mean(img: &[u8], nx: usize, r0: usize, r1: usize) -> f64 {
    let b = &img[r0 * nx..r1 * nx];
    b.iter().map(|v| f64::from(*v)).sum::<f64>() / b.len() as f64
}

#[test]
fn bmode_tool_matches_the_library_and_tgc_flattens_a_known_decay() {
    let dir = tempfile::tempdir().unwrap();
    let (nz, nx, decay) = (160, 48, 40.0);
    let iq = decaying_iq(nz, nx, decay);
    let iq_path = dir.path().join("img.npy");
    write_iq(&iq_path, &[nz, nx], &iq);
    // the sidecar `sonoflow das` writes: dz half of dx → columns doubled in the PNG
    std::fs::write(
        dir.path().join("img.json"),
        r#"{"grid": {"x0": -0.005, "z0": 0.01, "dx": 2e-4, "dz": 1e-4, "nx": 48, "nz": 160}}"#,
    )
    .unwrap();

    // 1. Plain B-mode at DR 50: the library's bytes; the decay (8.686 dB per `decay` rows) shows.
    let out = dir.path().join("b.npy");
    let png_path = dir.path().join("b.png");
    let (code, stdout, err) = cli(&["--iq", s(&iq_path), "--dr", "50", "--out", s(&out), "--png", s(&png_path)]);
    assert_eq!(code, 0, "{err}");
    assert!(stdout.contains("DR 50 dB"), "{stdout}");
    let (shape, img) = read_u8(&out);
    assert_eq!(shape, vec![nz, nx]);
    assert_eq!(img, sonoflow_beamform::bmode(&iq, 50.0).unwrap());
    let side: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.with_extension("json")).unwrap()).unwrap();
    assert_eq!(side["DR_dB"], 50.0);
    assert_eq!(side["tgc"], false);
    let max = iq.iter().map(|z| z.norm()).fold(0.0, f64::max);
    assert!((side["max_envelope"].as_f64().unwrap() - max).abs() <= 1e-12 * max);
    // Rows 10–30 and 130–150 are 120 rows apart: 120/40 · 8.686 = 26.1 dB → 255·26.1/50 = 133
    // grey levels between the band means (the speckle's log-mean is the same in both bands; 20
    // rows × 48 columns of it average to within a few levels).
    let drop = band_mean(&img, nx, 10, 30) - band_mean(&img, nx, 130, 150);
    let expected = 255.0 * (120.0 / decay * 20.0 * std::f64::consts::E.log10()) / 50.0;
    assert!((drop - expected).abs() < 12.0, "grey-level drop {drop:.1}, expected {expected:.1}");

    // The PNG: 96 × 160 (columns doubled for square pixels), grey, the same bytes.
    let decoder = png::Decoder::new(std::fs::File::open(&png_path).unwrap());
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!((info.width, info.height), (2 * nx as u32, nz as u32));
    assert_eq!(info.color_type, png::ColorType::Rgb);
    for (r, c) in [(0, 0), (17, 5), (159, 47), (80, 23)] {
        let p = &buf[(r * 2 * nx + 2 * c + 1) * 3..][..3];
        assert_eq!(p, [img[r * nx + c]; 3], "pixel ({r}, {c})");
    }

    // 2. With --tgc: the library's gain applied per row, then the same compression; the decay is
    // gone (band means within a few levels instead of 133 apart).
    let out_t = dir.path().join("t.npy");
    let (code, stdout, err) = cli(&["--iq", s(&iq_path), "--dr", "50", "--tgc", "--out", s(&out_t)]);
    assert_eq!(code, 0, "{err}");
    assert!(stdout.contains("tgc"), "{stdout}");
    let env = sonoflow_beamform::mean_envelope_iq(&iq, nx).unwrap();
    let gain = sonoflow_beamform::tgc_gain(&env).unwrap();
    let compensated: Vec<_> = iq.iter().enumerate().map(|(i, z)| z * gain[i / nx]).collect();
    let (_, img_t) = read_u8(&out_t);
    assert_eq!(img_t, sonoflow_beamform::bmode(&compensated, 50.0).unwrap());
    let flat = band_mean(&img_t, nx, 10, 30) - band_mean(&img_t, nx, 130, 150);
    assert!(flat.abs() < 12.0, "after tgc the bands still differ by {flat:.1} levels");
    // the gain over the image (159 rows) is the decay's 34.5 dB, within the fit's noise
    let side: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_t.with_extension("json")).unwrap()).unwrap();
    let g = side["tgc_gain_dB_first_last"].as_array().unwrap();
    let span = g[1].as_f64().unwrap() - g[0].as_f64().unwrap();
    let expected_db = 159.0 / decay * 20.0 * std::f64::consts::E.log10();
    assert!((span - expected_db).abs() < 2.0, "tgc span {span:.2} dB, expected {expected_db:.2}");

    // 3. A packet (nz, nx, frames): one maximum over all frames, as MUST; PNG of frame 0.
    let frames = 3;
    let packet: Vec<_> = (0..nz * nx * frames).map(|i| iq[i / frames] * (1.0 + (i % frames) as f64)).collect();
    let p_path = dir.path().join("packet.npy");
    write_iq(&p_path, &[nz, nx, frames], &packet);
    let out_p = dir.path().join("p.npy");
    let (code, _, err) = cli(&["--iq", s(&p_path), "--out", s(&out_p), "--png", s(&dir.path().join("p.png"))]);
    assert_eq!(code, 0, "{err}");
    let (shape, img_p) = read_u8(&out_p);
    assert_eq!(shape, vec![nz, nx, frames]);
    assert_eq!(img_p, sonoflow_beamform::bmode(&packet, 40.0).unwrap());
}

fn fails(args: &[&str], out: &Path, needles: &[&str]) {
    let (code, _, err) = cli(args);
    assert_eq!(code, 1, "{args:?}: expected exit code 1; stderr: {err}");
    for n in needles {
        assert!(err.contains(n), "{args:?}: stderr lacks {n:?}: {err}");
    }
    assert!(!out.exists(), "{args:?}: output written on error");
    assert!(!out.with_extension("json").exists(), "{args:?}: sidecar written on error");
}

#[test]
fn bmode_tool_rejects_bad_input_with_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let iq = decaying_iq(40, 8, 20.0);
    let ok = dir.path().join("iq.npy");
    write_iq(&ok, &[40, 8], &iq);
    let out = dir.path().join("o.npy");
    let (o, k) = (s(&out), s(&ok));
    for dr in ["0", "-3", "nan", "inf"] {
        fails(&["--iq", k, "--dr", dr, "--out", o], &out, &["--dr", "finite and > 0"]);
    }
    fails(&["--iq", k, "--out", s(&dir.path().join("o.txt"))], &dir.path().join("o.txt"), &["--out", ".npy"]);
    fails(&["--iq", k, "--out", o, "--png", s(&dir.path().join("o.jpg"))], &out, &["--png", ".png"]);
    // NaN in the data
    let mut bad = iq.clone();
    bad[17] = Complex::new(f64::NAN, 0.0);
    let nan = dir.path().join("nan.npy");
    write_iq(&nan, &[40, 8], &bad);
    fails(&["--iq", s(&nan), "--out", o], &out, &["--iq", "non-finite value at flat index 17"]);
    // real data is not I/Q
    let real = dir.path().join("real.npy");
    npy::write_f64(&real, &[40, 8], &vec![1.0; 320]).unwrap();
    fails(&["--iq", s(&real), "--out", o], &out, &["--iq"]);
    // --tgc needs lines; a PNG needs 2 or 3 axes
    let line = dir.path().join("line.npy");
    write_iq(&line, &[40], &iq[..40]);
    fails(&["--iq", s(&line), "--tgc", "--out", o], &out, &["--tgc", "≥ 2 axes"]);
    let four = dir.path().join("four.npy");
    write_iq(&four, &[5, 2, 4, 8], &iq);
    fails(&["--iq", s(&four), "--out", o, "--png", s(&dir.path().join("f.png"))], &out, &["--png", "2 axes"]);
    // too few samples along time for the fit
    let short = dir.path().join("short.npy");
    write_iq(&short, &[2, 8], &iq[..16]);
    fails(&["--iq", s(&short), "--tgc", "--out", o], &out, &["--tgc", "at least 3 samples"]);
    // the output would overwrite the input
    fails(&["--iq", k, "--out", k], &dir.path().join("nothing.npy"), &["would overwrite the input"]);
    assert!(ok.exists());
}

/// Mean |IQ|² of the beamformed image (grid x0, dx, nx, z0, dz, nz) over the pixels where `keep`.
fn mean_power(img: &[sonoflow_beamform::C32], g: [f64; 6], keep: impl Fn(f64, f64) -> bool) -> f64 {
    let [x0, dx, nx, z0, dz, _] = g;
    let (mut sum, mut n) = (0.0, 0usize);
    for (i, v) in img.iter().enumerate() {
        let (x, z) = (x0 + (i % nx as usize) as f64 * dx, z0 + (i / nx as usize) as f64 * dz);
        if keep(x, z) {
            sum += f64::from(v.norm_sqr());
            n += 1;
        }
    }
    assert!(n > 100, "{n} pixels");
    sum / n as f64
}

#[test]
fn a_genscat_phantom_shows_its_cyst_and_inclusion_through_simus_das_and_bmode() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n);
    std::fs::write(
        p("p.json"),
        r#"{"fc": 5e6, "pitch": 3e-4, "kerf": 35e-6, "Nelements": 128, "bandwidth": 75, "TXnow": 2, "fnumber": 1.5}"#,
    )
    .unwrap();
    let grid = [-0.007, 1e-4, 141.0, 0.015, 5e-5, 201.0];
    let hyp = |x: f64, z: f64, cx: f64| (x - cx).hypot(z - 0.02);
    let mut bright_db = Vec::new();
    for seed in ["1", "2", "3"] {
        // 16 × 12 mm from 14 mm deep at MUST's default meandist; an anechoic cyst (r 2 mm) at
        // x = −3.5 mm and a +10 dB inclusion at +3.5 mm, both 20 mm deep
        let (code, out, err) = run(
            "genscat",
            &[
                "--region",
                "0.016,0.012",
                "--z0",
                "0.014",
                "--param",
                s(&p("p.json")),
                "--seed",
                seed,
                "--inclusion=-0.0035,0.02,0.002",
                "--inclusion",
                "0.0035,0.02,0.002,10",
                "--out",
                s(&p("s.npy")),
            ],
        );
        assert_eq!(code, 0, "{err}");
        assert!(out.contains("8.0 per mm²"), "{out}");
        // the file holds the library's phantom
        let lib = sonoflow_simus::genscat(&sonoflow_simus::PhantomParams {
            width: 0.016,
            height: 0.012,
            z0: 0.014,
            meandist: sonoflow_simus::must_meandist(1540.0, 5e6, 75.0),
            seed: seed.parse().unwrap(),
            inclusions: vec![
                sonoflow_simus::Inclusion { x: -0.0035, z: 0.02, radius: 0.002, level_db: None },
                sonoflow_simus::Inclusion { x: 0.0035, z: 0.02, radius: 0.002, level_db: Some(10.0) },
            ],
            image: None,
        })
        .unwrap();
        let file = npy::read(&p("s.npy")).unwrap();
        assert_eq!(file.shape, vec![lib.x.len(), 3]);
        assert!((0..lib.x.len()).all(|i| file.data[3 * i] == lib.x[i] && file.data[3 * i + 2] == lib.rc[i]));
        for (tool, args) in [
            ("simus", vec!["--scatterers", s(&p("s.npy")), "--param", s(&p("p.json")), "--out", s(&p("rf.npy"))]),
            ("rf2iq", vec!["--rf", s(&p("rf.npy")), "--param", s(&p("p.json")), "--out", s(&p("iq.npy"))]),
            (
                "das",
                vec![
                    "--iq",
                    s(&p("iq.npy")),
                    "--param",
                    s(&p("p.json")),
                    "--grid=-0.007,0.0001,141,0.015,0.00005,201",
                    "--out",
                    s(&p("bf.npy")),
                ],
            ),
            ("bmode", vec!["--iq", s(&p("bf.npy")), "--dr", "50", "--out", s(&p("b.npy"))]),
        ] {
            let (code, _, err) = run(tool, &args);
            assert_eq!(code, 0, "{tool}: {err}");
        }
        let img: Vec<_> = npy::read_complex(&p("bf.npy"))
            .unwrap()
            .data
            .iter()
            .map(|c| sonoflow_beamform::C32::new(c.re as f32, c.im as f32))
            .collect();
        let bg = mean_power(&img, grid, |x, z| {
            hyp(x, z, -0.0035) > 0.0028 && hyp(x, z, 0.0035) > 0.0028 && x.abs() < 0.006 && z > 0.016 && z < 0.0245
        });
        let cyst = 10.0 * (mean_power(&img, grid, |x, z| hyp(x, z, -0.0035) < 0.0013) / bg).log10();
        let bright = 10.0 * (mean_power(&img, grid, |x, z| hyp(x, z, 0.0035) < 0.0015) / bg).log10();
        // seeds 1–6 measured −14.1 ± 0.7 dB (cyst: side lobes of one plane wave fill it) and
        // +9.6 ± 0.9 dB (inclusion); a cyst half filled in would read ~−8 dB
        assert!(cyst < -10.0, "seed {seed}: cyst {cyst:.2} dB below the background");
        assert!((bright - 10.0).abs() < 2.5, "seed {seed}: inclusion {bright:.2} dB, set to 10");
        bright_db.push(bright);
        // the B-mode picture of the same image: the cyst darker than the inclusion by > 60 grey levels
        let (_, b) = read_u8(&p("b.npy"));
        let level = |cx: f64| {
            let v: Vec<f64> = (0..b.len())
                .filter(|i| hyp(-0.007 + (i % 141) as f64 * 1e-4, 0.015 + (i / 141) as f64 * 5e-5, cx) < 0.0013)
                .map(|i| f64::from(b[i]))
                .collect();
            v.iter().sum::<f64>() / v.len() as f64
        };
        assert!(level(0.0035) - level(-0.0035) > 60.0, "seed {seed}: {} vs {}", level(0.0035), level(-0.0035));
    }
    let mean = bright_db.iter().sum::<f64>() / 3.0;
    assert!((mean - 10.0).abs() < 1.5, "inclusion contrast over 3 seeds {mean:.2} dB, set to 10");

    // --per-cell: 10 scatterers per resolution cell of the paper probe at F# 2, the cell computed
    // here independently (axial c/(2·fc·0.75) × lateral λ·2); the count over the region within 2 %
    let (code, _, err) = run(
        "genscat",
        &[
            "--region",
            "0.016,0.012",
            "--param",
            s(&p("p.json")),
            "--per-cell",
            "10",
            "--fnumber",
            "2",
            "--out",
            s(&p("c.npy")),
        ],
    );
    assert_eq!(code, 0, "{err}");
    let cell = 1540.0 / (2.0 * 5e6 * 0.75) * (1540.0 / 5e6 * 2.0);
    let n = npy::read(&p("c.npy")).unwrap().shape[0] as f64;
    let want = 10.0 * 0.016 * 0.012 / cell;
    assert!((n / want - 1.0).abs() < 0.02, "{n} scatterers, want {want:.0}");
    let side: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(p("c.json")).unwrap()).unwrap();
    assert!((side["scatterers_per_cell"].as_f64().unwrap() - 10.0).abs() < 1e-9);
}

#[test]
fn genscat_tool_rejects_bad_input_with_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s.npy");
    let o = s(&out);
    let cases: [(&[&str], &[&str]); 9] = [
        (&["--region", "0.01,0.01", "--per-cell", "5"], &["--per-cell needs --param"]),
        (&["--region", "0.01,0.01", "--per-cell", "0", "--param", "L11-5v"], &["--per-cell", "(0, 1000]"]),
        (&["--region", "0.01,0.01", "--per-cell", "5", "--meandist", "1e-4"], &["not both"]),
        (&["--region", "0.01", "--meandist", "1e-4"], &["--region", "WIDTH,HEIGHT"]),
        (&["--region", "0.01,x", "--meandist", "1e-4"], &["--region"]),
        (&["--region", "0.01,0.01"], &["--meandist", "--param"]),
        (&["--region", "0.01,0.01", "--meandist", "0"], &["phantom.meandist"]),
        (&["--region", "0.01,0.01", "--param", "no-such-probe"], &["--param", "preset"]),
        (&["--region", "0.01,0.01", "--meandist", "1e-4", "--inclusion", "0,0.005,0"], &["phantom.inclusions.radius"]),
    ];
    for (args, needles) in cases {
        let mut a = args.to_vec();
        a.extend(["--out", o]);
        let (code, _, err) = run("genscat", &a);
        assert_eq!(code, 1, "{a:?}: {err}");
        for n in needles {
            assert!(err.contains(n), "{a:?}: stderr lacks {n:?}: {err}");
        }
        assert!(!out.exists() && !out.with_extension("json").exists(), "{a:?}: written on error");
    }
}

#[test]
fn pfield_tool_matches_the_library_and_rejects_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("f.npy");
    let grid = "-0.004,0.0004,21,0.002,0.001,19";
    let (code, stdout, err) = run(
        "pfield",
        &[
            "--param",
            "L11-5v",
            "--grid",
            grid,
            "--focus=-0.001,0.012",
            "--out",
            s(&out),
            "--png",
            s(&dir.path().join("f.png")),
        ],
    );
    assert_eq!(code, 0, "{err}");
    assert!(stdout.contains("focused at (-0.001, 0.012) m"), "{stdout}");
    let probe = sonoflow_simus::Probe::preset("L11-5v").unwrap();
    let medium = sonoflow_simus::Medium::default();
    let tx = sonoflow_simus::Transmit::focused(&probe, medium.c, -0.001, 0.012).unwrap();
    let (mut xs, mut zs) = (Vec::new(), Vec::new());
    for iz in 0..19 {
        for ix in 0..21 {
            xs.push(-0.004 + ix as f64 * 0.0004);
            zs.push(0.002 + iz as f64 * 0.001);
        }
    }
    let lib = sonoflow_simus::pfield(&probe, &medium, &tx, &xs, &zs, &Default::default()).unwrap();
    let file = npy::read(&out).unwrap();
    assert_eq!(file.shape, vec![19, 21]);
    assert_eq!(file.data, lib.rms);
    let side: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.with_extension("json")).unwrap()).unwrap();
    assert_eq!(side["n_freq"].as_u64().unwrap() as usize, lib.n_freq);
    // the focus is where the field peaks (row of z = 12 mm, column of x = −1.2 … −0.8 mm)
    let imax = (0..file.data.len()).max_by(|a, b| file.data[*a].total_cmp(&file.data[*b])).unwrap();
    assert!(
        (xs[imax] + 0.001).abs() <= 0.0004 && (zs[imax] - 0.012).abs() <= 0.002,
        "peak at ({}, {})",
        xs[imax],
        zs[imax]
    );

    // Off the plane (--y 1 mm): MUST's elevation model, as the library's pfield_3d.
    let (code, _, err) =
        run("pfield", &["--param", "L11-5v", "--grid", grid, "--focus=-0.001,0.012", "--y", "0.001", "--out", s(&out)]);
    assert_eq!(code, 0, "{err}");
    let lib3 =
        sonoflow_simus::pfield_3d(&probe, &medium, &tx, &xs, &vec![1e-3; xs.len()], &zs, &Default::default()).unwrap();
    assert_eq!(npy::read(&out).unwrap().data, lib3.rms);
    assert_ne!(lib3.rms, lib.rms);

    let o = s(&out);
    std::fs::remove_file(&out).unwrap();
    std::fs::remove_file(out.with_extension("json")).unwrap();
    let cases: [(&[&str], &str); 7] = [
        (&["--param", "L11-5v", "--grid", grid], "give the transmit"),
        (&["--param", "L11-5v", "--grid", grid, "--tilt-deg", "3", "--focus", "0,0.01"], "one of"),
        (&["--param", "L11-5v", "--grid", grid, "--focus", "0,0"], "Z must be"),
        (&["--param", "L11-5v", "--grid", "1,2,3", "--tilt-deg", "0"], "--grid"),
        (&["--param", "no-probe", "--grid", grid, "--tilt-deg", "0"], "--param"),
        (&["--param", "L11-5v", "--grid", grid, "--tx-delay", "0,0"], "transmit.delays"),
        (&["--param", "L11-5v", "--grid", grid, "--tilt-deg", "0", "--y", "NaN"], "pfield.y"),
    ];
    for (args, needle) in cases {
        let mut a = args.to_vec();
        a.extend(["--out", o]);
        let (code, _, err) = run("pfield", &a);
        assert_eq!(code, 1, "{a:?}: {err}");
        assert!(err.contains(needle), "{a:?}: stderr lacks {needle:?}: {err}");
        assert!(!out.exists(), "{a:?}: written on error");
    }
}
