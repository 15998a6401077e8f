//! The compact RF window (`RfWindow::Compact`) against MUST's: half the frequency bins, the same RF
//! samples. Both plans sample the same continuous spectrum; MUST's window holds twice the longest
//! round trip, the compact one holds it once, so the echoes (which end before the round trip plus
//! the pulse margins) do not wrap in either. The difference left is the pulse's tails beyond
//! MUST's pulse duration, far below the f32 kernel's own error (fast vs exact nRMS ~2e-6), so the
//! comparisons run in the exact (f64) mode, where nothing else differs.
//!
//! Run with `--nocapture` to print the errors quoted in nodes/simus/README.md.
#![allow(clippy::unwrap_used)] // test helpers outside #[test] functions

use sonoflow_simus::{nrms, Accuracy, Medium, Probe, RfWindow, Scatterers, Simus, SimusOptions, Transmit};

fn scene(n: usize, seed: u64, z: (f32, f32)) -> Scatterers {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut s = Scatterers::default();
    for _ in 0..n {
        let rc: f32 = rng.sample(rand_distr::StandardNormal);
        s.push(rng.gen_range(-0.02f32..0.02), rng.gen_range(z.0..z.1), rc);
    }
    s
}

fn options(window: RfWindow, accuracy: Accuracy) -> SimusOptions {
    SimusOptions { window, accuracy, zero_small_values: false, ..SimusOptions::default() }
}

/// RF of both windows (MUST's first), each with its own per-call plan.
fn both(probe: &Probe, medium: &Medium, s: &Scatterers, tx: &Transmit, acc: Accuracy) -> [(Vec<f32>, usize); 2] {
    both_with(probe, medium, s, tx, options(RfWindow::Must, acc))
}

/// [`both`] with other options (their `window` is replaced).
fn both_with(probe: &Probe, medium: &Medium, s: &Scatterers, tx: &Transmit, o: SimusOptions) -> [(Vec<f32>, usize); 2] {
    [RfWindow::Must, RfWindow::Compact].map(|window| {
        let o = SimusOptions { window, ..o.clone() };
        let mut simus = Simus::new(probe.clone(), medium.clone(), o).unwrap();
        let rf = simus.simulate(s, tx).unwrap();
        (rf.data, rf.n_samples)
    })
}

/// nRMS of the compact RF against MUST's (the same length) and the largest difference relative to
/// MUST's peak.
fn compare(must: &(Vec<f32>, usize), compact: &(Vec<f32>, usize)) -> (f64, f64) {
    assert_eq!(must.1, compact.1, "sample counts");
    let peak = must.0.iter().fold(0f32, |m, v| m.max(v.abs()));
    let worst = must.0.iter().zip(&compact.0).fold(0f32, |m, (a, b)| m.max((a - b).abs()));
    (nrms(&compact.0, &must.0), f64::from(worst / peak))
}

/// Plan: about half the bins, the same band, MUST's sample count and gain step, and a window that
/// holds the longest round trip plus a pulse duration.
#[test]
fn compact_plan_has_half_the_bins() {
    let probe = Probe::paper_5mhz();
    let medium = Medium::default();
    let plan = |w| {
        let simus = Simus::new(probe.clone(), medium.clone(), options(w, Accuracy::default())).unwrap();
        simus.plan_for_max_distance(0.05, 2e-6).unwrap()
    };
    let (m, c) = (plan(RfWindow::Must), plan(RfWindow::Compact));
    assert_eq!((m.window, c.window), (RfWindow::Must, RfWindow::Compact));
    assert_eq!(m.gain_df, m.df);
    assert_eq!(c.gain_df, m.df);
    // (round trip + tp) / (2 round trip): 0.52 here
    let ratio = c.n_bins() as f64 / m.n_bins() as f64;
    assert!((0.5..=0.53).contains(&ratio), "bins {} vs {}", c.n_bins(), m.n_bins());
    let (fm, fc) = (m.band_frequencies(), c.band_frequencies());
    assert!((fm.0 - fc.0).abs() <= c.df && (fm.1 - fc.1).abs() <= c.df, "{fm:?} {fc:?}");
    assert_eq!(c.n_samples, m.n_samples);
    let round_trip = 2.0 * m.max_distance / medium.c + 2e-6;
    let tp = Simus::new(probe.clone(), medium.clone(), SimusOptions::default()).unwrap().pulse_duration();
    assert!(m.window() >= 2.0 * round_trip && c.window() >= round_trip + tp);
    // the kept samples end at least half a pulse before the window wraps
    assert!(c.n_samples as f64 / c.fs <= c.window() - tp / 2.0);
}

/// The same RF in the exact mode: a plane wave over a deep box, a steered and attenuated one, a
/// focused apodised transmit, and scatterers in the near field (from 0.5 mm), where a pulse's
/// leading half starts before t = 0 and wraps to the window's end (beyond every echo).
#[test]
fn compact_window_gives_the_same_rf() {
    let probe = Probe::paper_5mhz();
    let exact = Accuracy::Exact;
    let flat = Medium::default();
    let lossy = Medium { c: 1540.0, attenuation: 0.5 };
    let mut focused = Transmit::focused(&probe, flat.c, 0.004, 0.02).unwrap();
    focused.apodization = (0..probe.n_elements).map(|e| 0.5 + 0.5 * (e as f64 * 0.07).sin()).collect();
    let cases = [
        ("plane wave 0°, 10-50 mm", flat.clone(), Transmit::plane_wave(&probe, flat.c, 0.0).unwrap(), (0.01, 0.05)),
        (
            "plane wave 12°, attenuation 0.5",
            lossy.clone(),
            Transmit::plane_wave(&probe, 1540.0, 0.21).unwrap(),
            (0.005, 0.04),
        ),
        ("focused, apodised", flat.clone(), focused, (0.005, 0.035)),
        ("near field, 0.5-6 mm", flat.clone(), Transmit::plane_wave(&probe, flat.c, 0.0).unwrap(), (0.0005, 0.006)),
    ];
    for (seed, (name, medium, tx, z)) in cases.into_iter().enumerate() {
        let s = scene(150, 31 + seed as u64, z);
        let [m, c] = both(&probe, &medium, &s, &tx, exact.clone());
        let (e, worst) = compare(&m, &c);
        println!(
            "{name}: compact vs MUST window (exact mode) nRMS {e:.2e}, largest difference {worst:.1e} of the peak"
        );
        // the pulse tails past MUST's two-way duration: measured ≤ 1e-8; bound 10× below the
        // fast kernel's own error against the exact mode (~2e-6)
        assert!(e < 2e-7 && worst < 2e-7, "{name}: nRMS {e:e}, largest {worst:e}");
    }
}

/// MUST's `FrequencyStep` ≠ 1: finer (0.7: MUST keeps more samples than the round trip) and
/// coarser (1.5: MUST keeps fewer — its RF ends before the deepest echoes — but nothing wraps onto
/// them). The compact window keeps MUST's samples in both cases and never lets an echo wrap onto
/// them (its window holds the longer of the round trip and the kept samples, plus a pulse).
#[test]
fn compact_window_with_other_frequency_steps() {
    let probe = Probe::paper_5mhz();
    let medium = Medium::default();
    let s = scene(150, 5, (0.005, 0.045));
    let tx = Transmit::plane_wave(&probe, medium.c, 0.0).unwrap();
    for step in [0.7, 1.5] {
        let o = SimusOptions { frequency_step: step, ..options(RfWindow::Must, Accuracy::Exact) };
        let [m, c] = both_with(&probe, &medium, &s, &tx, o);
        let (e, worst) = compare(&m, &c);
        println!("FrequencyStep {step}: compact vs MUST window (exact mode) nRMS {e:.2e}, largest {worst:.1e}");
        assert!(e < 2e-7 && worst < 2e-7, "step {step}: nRMS {e:e}, largest {worst:e}");
    }
}

/// The default fast mode: the compact window changes the RF by no more than the kernel's own
/// rounding (MUST's window fast vs exact ~2e-6).
#[test]
fn compact_window_in_the_fast_mode() {
    let probe = Probe::paper_5mhz();
    let medium = Medium::default();
    let s = scene(2000, 7, (0.01, 0.05));
    let tx = Transmit::plane_wave(&probe, medium.c, 0.0).unwrap();
    let [m, c] = both(&probe, &medium, &s, &tx, Accuracy::default());
    let (e, _) = compare(&m, &c);
    println!("fast mode, 2000 scatterers: compact vs MUST window nRMS {e:.2e}");
    assert!(e < 1e-5, "{e:e}");
}

/// MUST's elevation model samples its factor on every 20th bin of MUST's own grid, so scatterers
/// off the imaging plane need MUST's window: the compact one is an error naming the field.
#[test]
fn compact_window_is_refused_off_the_imaging_plane() {
    let probe = Probe::paper_5mhz();
    let medium = Medium::default();
    let s = scene(10, 3, (0.01, 0.03));
    let y = vec![1e-3f32; s.x.len()];
    let tx = Transmit::plane_wave(&probe, medium.c, 0.0).unwrap();
    let mut simus = Simus::new(probe, medium, options(RfWindow::Compact, Accuracy::default())).unwrap();
    let e = simus.simulate_3d(&s, &y, &tx).unwrap_err().to_string();
    assert!(e.contains("options.window") && e.contains("must"), "{e}");
}
