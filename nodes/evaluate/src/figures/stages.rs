//! Stage-time bar chart.

use super::*;

/// One node of the stage-time chart (None: no statistics reported).
#[derive(Clone, Debug, PartialEq)]
pub struct StageRow {
    pub name: String,
    /// Compute CPU (s): thread CPU spent producing messages.
    pub compute_s: Option<f64>,
    /// Wall time of the node's process (s).
    pub wall_s: Option<f64>,
}

/// `figures/stage_times.png`: per node a compute-CPU bar (blue) above a wall-time bar (orange).
pub fn stage_times(dir: &Path, heading: &str, rows: &[StageRow]) -> anyhow::Result<Figure> {
    stage_times_mapped(dir, heading, rows).map(|r| r.0)
}

/// Row height of the stage chart (px).
pub(super) const STAGE_ROW_H: u32 = 34;

pub(super) fn stage_times_mapped(
    dir: &Path,
    heading: &str,
    rows: &[StageRow],
) -> anyhow::Result<(Figure, Vec<PanelMap>)> {
    if rows.is_empty() {
        anyhow::bail!("no nodes");
    }
    let ok = |v: Option<f64>| v.filter(|s| s.is_finite() && *s >= 0.0);
    let xmax = rows.iter().flat_map(|r| [ok(r.compute_s), ok(r.wall_s)]).flatten().fold(0.0, f64::max);
    let xmax = if xmax > 0.0 { 1.22 * xmax } else { 1.0 };
    let n = rows.len();
    let name_w = rows.iter().map(|r| r.name.chars().count()).max().unwrap_or(4) as u32 * 8 + 20;
    let label_w = name_w.clamp(70, 260);
    let size = (760 + label_w, TITLE_H + n as u32 * STAGE_ROW_H + XLABEL_H + 40);
    let nf = n as f64;
    let maps = render(&dir.join(DIR).join(STAGES), size, |root| {
        let (top, rest) = root.split_vertically(TITLE_H);
        title_row(&top, heading)?;
        let mut c = ChartBuilder::on(&rest)
            .margin(MARGIN)
            .margin_right(20)
            .margin_top(30)
            .x_label_area_size(XLABEL_H)
            .y_label_area_size(label_w)
            .build_cartesian_2d(0.0..xmax, 0.0..nf)
            .map_err(de)?;
        c.configure_mesh()
            .disable_y_mesh()
            .light_line_style(WHITE)
            .x_desc("time (s)")
            .y_labels(0)
            .x_labels(8)
            .label_style((FAMILY, 13))
            .axis_desc_style((FAMILY, 13))
            .draw()
            .map_err(de)?;
        let yc = |k: usize| nf - k as f64 - 0.5;
        c.draw_series(rows.iter().enumerate().filter_map(|(k, r)| {
            ok(r.compute_s).map(|v| Rectangle::new([(0.0, yc(k) + 0.04), (v, yc(k) + 0.38)], BAR.filled()))
        }))
        .map_err(de)?;
        c.draw_series(rows.iter().enumerate().filter_map(|(k, r)| {
            ok(r.wall_s).map(|v| Rectangle::new([(0.0, yc(k) - 0.38), (v, yc(k) - 0.04)], BAR2.filled()))
        }))
        .map_err(de)?;
        // Legend, right of the title.
        let lx = size.0 as i32 - 330;
        for (k, (col, text)) in [(BAR, "compute CPU"), (BAR2, "wall (process)")].into_iter().enumerate() {
            let x = lx + 150 * k as i32;
            root.draw(&Rectangle::new([(x, 12), (x + 14, 24)], col.filled())).map_err(de)?;
            root.draw(&Text::new(text, (x + 20, 11), (FAMILY, 13).into_font().color(&BLACK))).map_err(de)?;
        }
        let name_style = (FAMILY, 13).into_font().color(&BLACK).pos(plotters::style::text_anchor::Pos::new(
            plotters::style::text_anchor::HPos::Right,
            plotters::style::text_anchor::VPos::Center,
        ));
        for (k, r) in rows.iter().enumerate() {
            let p = c.backend_coord(&(0.0, yc(k)));
            root.draw(&Text::new(r.name.clone(), (p.0 - 8, p.1), name_style.clone())).map_err(de)?;
            let style = (FAMILY, 12).into_font().color(&BLACK);
            match (ok(r.compute_s), ok(r.wall_s)) {
                (None, None) => {
                    let p = c.backend_coord(&(0.0, yc(k)));
                    root.draw(&Text::new("no statistics", (p.0 + 6, p.1 - 6), style)).map_err(de)?;
                }
                (cs, ws) => {
                    for (v, dy) in [(cs, 0.21), (ws, -0.21)] {
                        if let Some(v) = v {
                            let p = c.backend_coord(&(v, yc(k) + dy));
                            root.draw(&Text::new(format!("{v:.3} s"), (p.0 + 4, p.1 - 6), style.clone()))
                                .map_err(de)?;
                        }
                    }
                }
            }
        }
        // x in seconds, y in row units (row k centred at n − k − 0.5).
        Ok(vec![PanelMap::of(&c)])
    })?;
    let fig = figure(
        STAGES,
        heading.to_string(),
        "Per node, blue: compute CPU (thread CPU time spent producing messages), orange: wall time of its process, both in seconds; a long orange bar over a short blue one is a node that mostly waited.".into(),
        size,
    );
    Ok((fig, maps))
}
