//! SIMUS cases (from `nodes/simus/tests/extreme.rs`).

use super::{Case, CaseResult, Check, Ctx, Expected, OrMessage, Stage};
use rand::{Rng, SeedableRng};
use sonoflow_simus::{Medium, Probe, Scatterers, Simus, SimusError, SimusOptions, Transmit};

pub(super) fn cases() -> Vec<Case> {
    fn c(name: &'static str, stresses: &'static str, expected: Expected, run: fn(&Ctx) -> CaseResult) -> Case {
        Case { stage: Stage::Simus, name, stresses, expected, run }
    }
    vec![
        c(
            "zero-scatterers",
            "an empty scene; check: an all-zero RF of the planned length (the plan covers the pulse only), not an \
             error, also into a fixed plan's buffer pre-filled with ones",
            Expected::Pass,
            zero_scatterers,
        ),
        c(
            "scatterer-on-array-face",
            "a scatterer at z = 0 on an element centre and on a sub-element centre (r = 0, |theta| = 90°: MUST's \
             distance clamp and obliquity floor); check: finite RF, no stronger than the same scatterer lambda/2 in \
             front",
            Expected::Pass,
            on_array_face,
        ),
        c(
            "grazing-angles",
            "scatterers 1 nm to 0.1 mm below the face, inside and far outside the aperture; check: finite and \
             < 10 % of the echo of a scatterer in front at 3 cm",
            Expected::Pass,
            grazing,
        ),
        c(
            "very-deep-30cm",
            "a scatterer 30 cm deep (8-element probe): > 3000 frequency bins; check: the echo envelope centroid \
             arrives at (z + d)/c within 0.1 sample",
            Expected::Pass,
            very_deep,
        ),
        c(
            "many-scatterers",
            "10⁵ (quick) / 10⁶ (full) random scatterers streamed in blocks (8 elements, -20 dB band); check: finite, \
             non-zero RF and peak memory growth < 200 MiB (far below scatterers x elements x bins)",
            Expected::Pass,
            many_scatterers,
        ),
        c(
            "nan-scatterer",
            "a NaN lateral position in row 3 of 10",
            Expected::ClearError(&["scatterer row 3", "`x`", "finite"]),
            nan_scatterer,
        ),
        c(
            "scatterer-10km-deep",
            "a finite but absurd depth (10 km: metres typed for millimetres?) in row 2",
            Expected::ClearError(&["scatterer row 2", "`z`", "magnitude <= 100"]),
            absurd_depth,
        ),
        c(
            "sampling-below-4fc",
            "fs = 19 MHz for a 5 MHz probe (MUST needs fs >= 4 fc)",
            Expected::ClearError(&["`options.fs`"]),
            bad_fs,
        ),
        c(
            "zero-bandwidth",
            "probe bandwidth 0 % (and -10 %, NaN: all must be named)",
            Expected::ClearError(&["`probe.bandwidth`"]),
            zero_bandwidth,
        ),
        c(
            "transmit-length-mismatch",
            "3 transmit delays for a 128-element probe",
            Expected::ClearError(&["`transmit.delays`", "has 3 entries, expected 128"]),
            transmit_mismatch,
        ),
        c(
            "fixed-plan-too-short",
            "a packet plan made for 1 cm used for a scatterer at 10 cm (would alias circularly)",
            Expected::ClearError(&["frequency plan too coarse"]),
            plan_too_short,
        ),
    ]
}

fn engine() -> Result<Simus, String> {
    Simus::new(Probe::paper_5mhz(), Medium::default(), SimusOptions::default()).msg()
}

fn pw0(p: &Probe) -> Result<Transmit, String> {
    Transmit::plane_wave(p, 1540.0, 0.0).msg()
}

fn finite(v: &[f32]) -> bool {
    v.iter().all(|x| x.is_finite())
}

fn peak(v: &[f32]) -> f32 {
    v.iter().fold(0.0f32, |m, x| m.max(x.abs()))
}

fn one(x: f32, z: f32) -> Result<Scatterers, String> {
    Scatterers::new(vec![x], vec![z], vec![1.0]).msg()
}

fn zero_scatterers(_: &Ctx) -> CaseResult {
    let p = Probe::paper_5mhz();
    let mut simus = engine()?;
    let rf = simus.simulate(&Scatterers::default(), &pw0(&p)?).msg()?;
    let plan = simus.plan_for_max_distance(0.0, 0.0).msg()?;
    let ok1 = rf.plan == plan && rf.data.len() == p.n_elements * plan.n_samples && rf.n_samples > 0;
    let zeros1 = rf.data.iter().all(|v| *v == 0.0);
    let plan = simus.plan_for_max_distance(0.05, 0.0).msg()?;
    let mut out = vec![1f32; p.n_elements * plan.n_samples];
    simus.simulate_into(&Scatterers::default(), &pw0(&p)?, &plan, &mut out).msg()?;
    let zeros2 = out.iter().all(|v| *v == 0.0);
    Ok(Check::new(
        ok1 && zeros1 && zeros2,
        format!(
            "{} x {} zero samples (planned length: {ok1}); fixed-plan buffer zeroed: {zeros2}",
            p.n_elements, rf.n_samples
        ),
    ))
}

fn on_array_face(_: &Ctx) -> CaseResult {
    let p = Probe::paper_5mhz();
    let mut simus = engine()?;
    let xe = p.element_x(40) as f32;
    let sub = (p.element_x(40) - p.element_width() / 4.0) as f32;
    let front = simus.simulate(&one(xe, 1540.0 / 5e6 / 2.0)?, &pw0(&p)?).msg()?;
    let mut ok = finite(&front.data);
    let mut ratios = vec![];
    for x in [xe, sub] {
        let rf = simus.simulate(&one(x, 0.0)?, &pw0(&p)?).msg()?;
        ok &= finite(&rf.data) && peak(&rf.data) <= peak(&front.data);
        ratios.push(peak(&rf.data) / peak(&front.data));
    }
    Ok(Check::new(
        ok,
        format!(
            "finite; peak vs lambda/2 in front: element centre {:.3}, sub-element centre {:.3}",
            ratios[0], ratios[1]
        ),
    ))
}

fn grazing(_: &Ctx) -> CaseResult {
    let p = Probe::paper_5mhz();
    let mut simus = engine()?;
    let s = Scatterers::new(vec![0.03, -0.004, 0.05], vec![1e-6, 1e-9, 1e-4], vec![1.0; 3]).msg()?;
    let rf = simus.simulate(&s, &pw0(&p)?).msg()?;
    let front = simus.simulate(&one(0.0, 0.03)?, &pw0(&p)?).msg()?;
    let r = peak(&rf.data) / peak(&front.data);
    Ok(Check::new(
        finite(&rf.data) && r < 0.1,
        format!("finite: {}; peak {:.2e} of the scatterer in front", finite(&rf.data), r),
    ))
}

/// Squared envelope x² + H{x}² (Hilbert transform by FFT, zero-padded to 2n).
fn envelope2(x: &[f32]) -> Result<Vec<f64>, String> {
    use num_complex::Complex;
    let n = 2 * x.len();
    let mut planner = realfft::RealFftPlanner::<f64>::new();
    let fwd = planner.plan_fft_forward(n);
    let inv = planner.plan_fft_inverse(n);
    let mut buf: Vec<f64> = x.iter().map(|v| f64::from(*v)).chain(std::iter::repeat(0.0)).take(n).collect();
    let mut spec = fwd.make_output_vec();
    fwd.process(&mut buf, &mut spec).msg()?;
    let last = spec.len() - 1;
    for (k, v) in spec.iter_mut().enumerate() {
        *v = if k == 0 || k == last { Complex::new(0.0, 0.0) } else { Complex::new(v.im, -v.re) };
    }
    let mut h = inv.make_output_vec();
    inv.process(&mut spec, &mut h).msg()?;
    Ok(x.iter().zip(&h).map(|(a, b)| f64::from(*a).powi(2) + (b / n as f64).powi(2)).collect())
}

fn very_deep(_: &Ctx) -> CaseResult {
    let p = Probe { n_elements: 8, ..Probe::paper_5mhz() };
    let m = Medium::default();
    let o = SimusOptions { db_thresh: -40.0, zero_small_values: false, ..SimusOptions::default() };
    let mut simus = Simus::new(p.clone(), m.clone(), o).msg()?;
    let z = 0.3f32;
    let rf = simus.simulate(&one(0.0, z)?, &pw0(&p)?).msg()?;
    let d = p.element_x(3).hypot(f64::from(z));
    let want = (f64::from(z) + d) / m.c;
    let e = envelope2(rf.element(3))?;
    let (mut num, mut den) = (0.0, 0.0);
    for (k, v) in e.iter().enumerate() {
        let t = rf.t0 + k as f64 / rf.fs;
        if (t - want).abs() <= 2.5e-6 {
            num += t * v;
            den += v;
        }
    }
    let err = (num / den - want) * rf.fs;
    Ok(Check::new(
        finite(&rf.data) && rf.plan.n_freq > 3000 && err.abs() < 0.1,
        format!(
            "{} frequency bins, {} samples; echo centroid {err:+.3} samples from (z + d)/c",
            rf.plan.n_freq, rf.n_samples
        ),
    ))
}

fn vm_hwm_kib() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

fn random_scatterers(n: usize, seed: u64) -> Scatterers {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut s = Scatterers::default();
    for _ in 0..n {
        s.push(rng.gen_range(-0.01f32..0.01), rng.gen_range(0.005f32..0.02), rng.gen_range(-1f32..1.0));
    }
    s
}

fn many_scatterers(ctx: &Ctx) -> CaseResult {
    let n = if ctx.quick { 100_000 } else { 1_000_000 };
    let p = Probe { n_elements: 8, ..Probe::paper_5mhz() };
    let s = random_scatterers(n, 99);
    let before = vm_hwm_kib();
    let o = SimusOptions { db_thresh: -20.0, ..SimusOptions::default() };
    let mut simus = Simus::new(p.clone(), Medium::default(), o).msg()?;
    let rf = simus.simulate(&s, &pw0(&p)?).msg()?;
    let grew = match (before, vm_hwm_kib()) {
        (Some(a), Some(b)) => Some(b.saturating_sub(a) / 1024),
        _ => None,
    };
    let ok = finite(&rf.data) && peak(&rf.data) > 0.0 && grew.is_none_or(|g| g < 200);
    let dense = n as f64 * 8.0 * rf.plan.n_freq as f64 * 8.0 / 1e9;
    Ok(Check::new(
        ok,
        format!(
            "{n} scatterers: finite, peak {:.2e}; peak memory grew {} MiB (a dense array would be {dense:.1} GB)",
            peak(&rf.data),
            grew.map(|g| g.to_string()).unwrap_or_else(|| "?".into())
        ),
    ))
}

fn nan_scatterer(_: &Ctx) -> CaseResult {
    let p = Probe::paper_5mhz();
    let mut s = random_scatterers(10, 1);
    s.x[3] = f32::NAN;
    match engine()?.simulate(&s, &pw0(&p)?) {
        Ok(rf) => Ok(Check::new(false, format!("accepted a NaN position (RF finite: {})", finite(&rf.data)))),
        Err(e @ SimusError::InvalidScatterer { row: 3, .. }) => Err(e.to_string()),
        Err(e) => Ok(Check::new(false, format!("wrong error: {e}"))),
    }
}

fn absurd_depth(_: &Ctx) -> CaseResult {
    let p = Probe::paper_5mhz();
    let mut s = random_scatterers(10, 2);
    s.z[2] = 1e4;
    engine()?.simulate(&s, &pw0(&p)?).map(|_| Check::new(true, "simulated a scatterer 10 km deep")).msg()
}

fn bad_fs(_: &Ctx) -> CaseResult {
    Simus::new(Probe::paper_5mhz(), Medium::default(), SimusOptions { fs: Some(19e6), ..Default::default() })
        .map(|_| Check::new(true, "accepted fs = 19 MHz"))
        .msg()
}

fn zero_bandwidth(_: &Ctx) -> CaseResult {
    let mut msgs = vec![];
    for bw in [0.0, -10.0, f64::NAN] {
        let p = Probe { bandwidth: bw, ..Probe::paper_5mhz() };
        match Simus::new(p, Medium::default(), SimusOptions::default()) {
            Ok(_) => return Ok(Check::new(true, format!("accepted bandwidth {bw}"))),
            Err(e) => msgs.push(e.to_string()),
        }
    }
    if msgs.iter().all(|m| m.contains("`probe.bandwidth`")) {
        Err(msgs.swap_remove(0))
    } else {
        Ok(Check::new(false, format!("not every bandwidth error names the field: {msgs:?}")))
    }
}

fn transmit_mismatch(_: &Ctx) -> CaseResult {
    let s = random_scatterers(5, 3);
    engine()?.simulate(&s, &Transmit::zero(3)).map(|_| Check::new(true, "accepted 3 delays")).msg()
}

fn plan_too_short(_: &Ctx) -> CaseResult {
    let p = Probe::paper_5mhz();
    let mut simus = engine()?;
    let plan = simus.plan_for_max_distance(0.01, 0.0).msg()?;
    let mut out = vec![0f32; p.n_elements * plan.n_samples];
    simus
        .simulate_into(&one(0.0, 0.1)?, &pw0(&p)?, &plan, &mut out)
        .map(|_| Check::new(true, "no aliasing error"))
        .msg()
}
