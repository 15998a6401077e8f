//! SIMUS cases (the extreme scenes of `nodes/simus/tests/extreme.rs`, from `sonoflow_simus::testkit`).

use super::{Case, CaseResult, Check, Ctx, Expected, OrMessage, Stage};
use sonoflow_simus::testkit::{
    all_finite, grazing_angles, many_scatterers, noisy_frame, one, pw0, random_scatterers, scatterer_on_array_face,
    very_deep_scatterer, zero_scatterers,
};
use sonoflow_simus::{Medium, Probe, Simus, SimusError, SimusOptions, Transmit};

pub(super) fn cases() -> Vec<Case> {
    vec![
        Stage::Simus.case(
            "zero-scatterers",
            "an empty scene; check: an all-zero RF of the planned length (the plan covers the pulse only), not an \
             error, also into a fixed plan's buffer pre-filled with ones",
            Expected::Pass,
            zero_scatterers_case,
        ),
        Stage::Simus.case(
            "scatterer-on-array-face",
            "a scatterer at z = 0 on an element centre and on a sub-element centre (r = 0, |theta| = 90°: MUST's \
             distance clamp and obliquity floor); check: finite RF, no stronger than the same scatterer lambda/2 in \
             front",
            Expected::Pass,
            on_array_face,
        ),
        Stage::Simus.case(
            "grazing-angles",
            "scatterers 1 nm to 0.1 mm below the face, inside and far outside the aperture; check: finite and \
             < 10 % of the echo of a scatterer in front at 3 cm",
            Expected::Pass,
            grazing,
        ),
        Stage::Simus.case(
            "very-deep-30cm",
            "a scatterer 30 cm deep (8-element probe): > 3000 frequency bins; check: the echo envelope centroid \
             arrives at (z + d)/c within 0.1 sample",
            Expected::Pass,
            very_deep,
        ),
        Stage::Simus.case(
            "many-scatterers",
            "10⁵ (quick) / 10⁶ (full) random scatterers streamed in blocks (8 elements, -20 dB band); check: finite, \
             non-zero RF and peak memory growth < 200 MiB (far below scatterers x elements x bins)",
            Expected::Pass,
            many_scatterers_case,
        ),
        Stage::Simus.case(
            "nan-scatterer",
            "a NaN lateral position in row 3 of 10",
            Expected::ClearError(&["scatterer row 3", "`x`", "finite"]),
            nan_scatterer,
        ),
        Stage::Simus.case(
            "scatterer-10km-deep",
            "a finite but absurd depth (10 km: metres typed for millimetres?) in row 2",
            Expected::ClearError(&["scatterer row 2", "`z`", "magnitude <= 100"]),
            absurd_depth,
        ),
        Stage::Simus.case(
            "sampling-below-4fc",
            "fs = 19 MHz for a 5 MHz probe (MUST needs fs >= 4 fc)",
            Expected::ClearError(&["`options.fs`"]),
            bad_fs,
        ),
        Stage::Simus.case(
            "zero-bandwidth",
            "probe bandwidth 0 % (and -10 %, NaN: all must be named)",
            Expected::ClearError(&["`probe.bandwidth`"]),
            zero_bandwidth,
        ),
        Stage::Simus.case(
            "transmit-length-mismatch",
            "3 transmit delays for a 128-element probe",
            Expected::ClearError(&["`transmit.delays`", "has 3 entries, expected 128"]),
            transmit_mismatch,
        ),
        Stage::Simus.case(
            "fixed-plan-too-short",
            "a packet plan made for 1 cm used for a scatterer at 10 cm (would alias circularly)",
            Expected::ClearError(&["frequency plan too coarse"]),
            plan_too_short,
        ),
        Stage::Simus.case(
            "snr-0-db",
            "receive noise at SNR 0 dB on a 40-scatterer frame; check: finite RF, in-band SNR measured from the \
             added noise within 0.5 dB of the set value",
            Expected::Pass,
            |_| snr_case(0.0),
        ),
        Stage::Simus.case(
            "snr-minus-10-db",
            "receive noise at SNR -10 dB (noise 10 dB above the echoes); same check",
            Expected::Pass,
            |_| snr_case(-10.0),
        ),
    ]
}

fn engine() -> Result<Simus, String> {
    Simus::new(Probe::paper_5mhz(), Medium::default(), SimusOptions::default()).msg()
}

fn zero_scatterers_case(_: &Ctx) -> CaseResult {
    let z = zero_scatterers();
    let ok1 = z.rf.plan == z.plan && z.rf.data.len() == z.n_elements * z.plan.n_samples && z.rf.n_samples > 0;
    let zeros1 = z.rf.data.iter().all(|v| *v == 0.0);
    let zeros2 = z.fixed_plan_out.iter().all(|v| *v == 0.0);
    Ok(Check::new(
        ok1 && zeros1 && zeros2,
        format!(
            "{} x {} zero samples (planned length: {ok1}); fixed-plan buffer zeroed: {zeros2}",
            z.n_elements, z.rf.n_samples
        ),
    ))
}

fn on_array_face(_: &Ctx) -> CaseResult {
    let face = scatterer_on_array_face();
    let ok = face.finite && face.face_peaks.iter().all(|p| *p <= face.front_peak);
    let [a, b] = face.face_peaks.map(|p| p / face.front_peak);
    Ok(Check::new(
        ok,
        format!("finite: {}; peak vs lambda/2 in front: element centre {a:.3}, sub-element centre {b:.3}", face.finite),
    ))
}

fn grazing(_: &Ctx) -> CaseResult {
    let (finite, r) = grazing_angles();
    Ok(Check::new(finite && r < 0.1, format!("finite: {finite}; peak {r:.2e} of the scatterer in front")))
}

fn very_deep(_: &Ctx) -> CaseResult {
    let d = very_deep_scatterer();
    Ok(Check::new(
        d.finite && d.n_freq > 3000 && d.arrival_error.abs() < 0.1,
        format!(
            "{} frequency bins, {} samples; echo centroid {:+.3} samples from (z + d)/c",
            d.n_freq, d.n_samples, d.arrival_error
        ),
    ))
}

fn many_scatterers_case(ctx: &Ctx) -> CaseResult {
    let n = if ctx.quick { 100_000 } else { 1_000_000 };
    let m = many_scatterers(n);
    let ok = m.finite && m.peak > 0.0 && m.memory_growth_mib.is_none_or(|g| g < 200);
    let dense = n as f64 * 8.0 * m.n_freq as f64 * 8.0 / 1e9;
    Ok(Check::new(
        ok,
        format!(
            "{n} scatterers: finite {}, peak {:.2e}; peak memory grew {} MiB (a dense array would be {dense:.1} GB)",
            m.finite,
            m.peak,
            m.memory_growth_mib.map(|g| g.to_string()).unwrap_or_else(|| "?".into())
        ),
    ))
}

fn nan_scatterer(_: &Ctx) -> CaseResult {
    let p = Probe::paper_5mhz();
    let mut s = random_scatterers(10, 1);
    s.x[3] = f32::NAN;
    match engine()?.simulate(&s, &pw0(&p)) {
        Ok(rf) => Ok(Check::new(false, format!("accepted a NaN position (RF finite: {})", all_finite(&rf.data)))),
        Err(e @ SimusError::InvalidScatterer { row: 3, .. }) => Err(e.to_string()),
        Err(e) => Ok(Check::new(false, format!("wrong error: {e}"))),
    }
}

fn absurd_depth(_: &Ctx) -> CaseResult {
    let p = Probe::paper_5mhz();
    let mut s = random_scatterers(10, 2);
    s.z[2] = 1e4;
    engine()?.simulate(&s, &pw0(&p)).map(|_| Check::new(true, "simulated a scatterer 10 km deep")).msg()
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
    simus.simulate_into(&one(0.0, 0.1), &pw0(&p), &plan, &mut out).map(|_| Check::new(true, "no aliasing error")).msg()
}

fn snr_case(snr_db: f64) -> CaseResult {
    let (noisy, measured) = noisy_frame(snr_db, 11);
    let finite = noisy.iter().all(|v| v.is_finite());
    Ok(Check::new(
        finite && (measured - snr_db).abs() < 0.5,
        format!("finite: {finite}; measured SNR {measured:.2} dB for {snr_db} dB"),
    ))
}
