//! Error histograms (paper 1's figures 5–7).

use super::*;

/// Per-pixel errors of one estimated field (fractions of v_max): the evaluator's samples.
pub struct ErrorSample<'a> {
    pub name: String,
    pub ex: &'a [f64],
    pub ez: &'a [f64],
}

/// Counts of `values` in `n` equal bins over `[lo, hi)`; values below/above go to the first/last
/// bin, non-finite values nowhere.
pub fn histogram(values: &[f64], lo: f64, hi: f64, n: usize) -> Vec<usize> {
    let mut h = vec![0; n];
    if n == 0 || hi.is_nan() || lo.is_nan() || hi <= lo {
        return h;
    }
    for v in values.iter().filter(|v| v.is_finite()) {
        let k = ((v - lo) / (hi - lo) * n as f64).floor();
        let k = if k < 0.0 { 0 } else { (k as usize).min(n - 1) };
        h[k] += 1;
    }
    h
}

/// Half-width of the histogram axis (fraction of v_max): the next of 1, 2, 5 × 10^k above the
/// 99th percentile of |e| (over all fields), at least 1.5 × `criterion`.
pub fn error_axis(samples: &[&[f64]], criterion: f64) -> f64 {
    let mut a: Vec<f64> = samples.iter().flat_map(|s| s.iter()).filter(|v| v.is_finite()).map(|v| v.abs()).collect();
    a.sort_by(f64::total_cmp);
    let p = if a.is_empty() { 0.0 } else { a[((a.len() - 1) as f64 * 0.99).round() as usize] };
    let want = p.max(1.5 * criterion).min(10.0);
    let mut r = 1e-3;
    for k in 0.. {
        let base = 10f64.powi(k - 3);
        if let Some(m) = [1.0, 2.0, 5.0].iter().map(|m| m * base).find(|v| *v >= want * (1.0 - 1e-12)) {
            r = m;
            break;
        }
        if k > 8 {
            break;
        }
    }
    r
}

/// Bins of each histogram.
pub const HIST_BINS: usize = 40;
/// The paper's criteria (fractions of v_max): vx within ±10 %, vz within ±2 %.
pub const CRITERIA: [f64; 2] = [0.10, 0.02];

/// `figures/error_histograms.png`: rows = fields, columns = vx, vz; percent of pixels per bin of
/// the error in % of v_max, with bias, RMS and |e|₇₅ in each panel.
pub fn error_histograms(dir: &Path, label: &str, heading: &str, fields: &[ErrorSample<'_>]) -> anyhow::Result<Figure> {
    error_histograms_mapped(dir, label, heading, fields).map(|r| r.0)
}

pub(super) fn error_histograms_mapped(
    dir: &Path,
    label: &str,
    heading: &str,
    fields: &[ErrorSample<'_>],
) -> anyhow::Result<(Figure, Vec<PanelMap>)> {
    if fields.is_empty() || fields.iter().all(|f| f.ex.is_empty() && f.ez.is_empty()) {
        anyhow::bail!("no error samples");
    }
    let ranges = [
        error_axis(&fields.iter().map(|f| f.ex).collect::<Vec<_>>(), CRITERIA[0]),
        error_axis(&fields.iter().map(|f| f.ez).collect::<Vec<_>>(), CRITERIA[1]),
    ];
    let (pw, ph) = (430u32, 270u32);
    let size = (2 * pw, TITLE_H + fields.len() as u32 * ph);
    let name = file_name(ERRORS, label);
    let maps = render(&dir.join(DIR).join(&name), size, |root| {
        let (top, rest) = root.split_vertically(TITLE_H);
        title_row(&top, heading)?;
        let mut maps = Vec::new();
        for (r, f) in fields.iter().enumerate() {
            for (col, (comp, e)) in [("vx", f.ex), ("vz", f.ez)].into_iter().enumerate() {
                let area = rest.clone().shrink((col as i32 * pw as i32, r as i32 * ph as i32), (pw, ph));
                let rng = ranges[col];
                let counts = histogram(e, -rng, rng, HIST_BINS);
                let total = e.iter().filter(|v| v.is_finite()).count().max(1) as f64;
                let pct: Vec<f64> = counts.iter().map(|c| 100.0 * *c as f64 / total).collect();
                let ymax = pct.iter().cloned().fold(0.0, f64::max).max(1.0) * 1.18;
                let st = crate::metrics::error_stats(e);
                let mut c = ChartBuilder::on(&area)
                    .caption(format!("{}: {comp} error ({} px)", f.name, e.len()), (FAMILY, 15))
                    .margin(MARGIN)
                    .margin_right(14)
                    .x_label_area_size(XLABEL_H)
                    .y_label_area_size(YLABEL_W)
                    .build_cartesian_2d(-100.0 * rng..100.0 * rng, 0.0..ymax)
                    .map_err(de)?;
                let (fx, fy) = (tick_format(200.0 * rng / 8.0), tick_format(ymax / 6.0));
                c.configure_mesh()
                    .disable_x_mesh()
                    .light_line_style(WHITE)
                    .x_desc(format!("({comp} − {comp}_true) / v_max (%)"))
                    .y_desc("pixels (%)")
                    .x_labels(9)
                    .y_labels(6)
                    .x_label_formatter(&fx)
                    .y_label_formatter(&fy)
                    .label_style((FAMILY, 12))
                    .axis_desc_style((FAMILY, 13))
                    .draw()
                    .map_err(de)?;
                let w = 200.0 * rng / HIST_BINS as f64;
                c.draw_series(pct.iter().enumerate().filter(|(_, p)| **p > 0.0).map(|(k, p)| {
                    let x0 = -100.0 * rng + k as f64 * w;
                    Rectangle::new([(x0 + 0.06 * w, 0.0), (x0 + 0.94 * w, *p)], BAR.filled())
                }))
                .map_err(de)?;
                let crit = 100.0 * CRITERIA[col];
                for x in [-crit, crit] {
                    c.draw_series(std::iter::once(PathElement::new(
                        vec![(x, 0.0), (x, ymax)],
                        RGBColor(200, 60, 60).stroke_width(1),
                    )))
                    .map_err(de)?;
                }
                c.draw_series(std::iter::once(PathElement::new(vec![(0.0, 0.0), (0.0, ymax)], BLACK.stroke_width(1))))
                    .map_err(de)?;
                let text = format!(
                    "bias {:+.1} %   RMS {:.1} %   |e|₇₅ {:.1} %",
                    100.0 * st.bias + 0.0,
                    100.0 * st.rms,
                    100.0 * st.abs_p75
                );
                let pos = c.backend_coord(&(-100.0 * rng, ymax));
                let font = (FAMILY, 12).into_font().color(&BLACK);
                let (tw, _) = root.estimate_text_size(&text, &font).map_err(de)?;
                // ab_glyph puts the baseline half a font size below the text position.
                let (x0, ty) = (pos.0 + 4, pos.1 + 7);
                root.draw(&Rectangle::new([(x0, ty - 6), (x0 + tw as i32 + 8, ty + 12)], WHITE.filled()))
                    .map_err(de)?;
                root.draw(&Text::new(text, (x0 + 4, ty), font)).map_err(de)?;
                maps.push(PanelMap::of(&c));
            }
        }
        Ok(maps)
    })?;
    let fig = figure(
        &name,
        heading.to_string(),
        format!(
            "Share of the vessel's pixels per bin of the error of vx and vz in % of the largest true speed (paper 1's figures 5–7); red lines: the paper's ±{:.0} % (vx) and ±{:.0} % (vz); the outermost bins also hold everything beyond the axis.",
            100.0 * CRITERIA[0],
            100.0 * CRITERIA[1]
        ),
        size,
    );
    Ok((fig, maps))
}
