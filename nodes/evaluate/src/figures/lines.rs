//! Line charts: a grid of panels, each with several labelled series (the platelet figures).
use super::*;

/// One panel of [`line_panels`].
pub struct LinePanel<'a> {
    pub title: &'a str,
    pub x_desc: &'a str,
    pub y_desc: &'a str,
    /// (label, points) per series; non-finite points are skipped.
    pub series: Vec<(String, Vec<(f64, f64)>)>,
}

/// Series colours (distinguishable, print-safe).
const PALETTE: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(90, 90, 90),
];

fn range_of(panel: &LinePanel<'_>) -> anyhow::Result<((f64, f64), (f64, f64))> {
    let pts = panel.series.iter().flat_map(|(_, p)| p.iter()).filter(|(x, y)| x.is_finite() && y.is_finite());
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in pts {
        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
    }
    if x0 > x1 {
        anyhow::bail!("panel `{}` has no finite point", panel.title);
    }
    if x1 - x0 <= 0.0 {
        x1 = x0 + 1.0;
    }
    let pad = if y1 > y0 { 0.06 * (y1 - y0) } else { 0.5 * y0.abs().max(1e-30) };
    Ok(((x0, x1), (y0 - pad, y1 + pad)))
}

/// Writes `dir/figures/name`: `panels` in a grid of `columns`, with a legend per panel.
pub fn line_panels(
    dir: &Path,
    name: &str,
    heading: &str,
    caption: &str,
    columns: usize,
    panels: &[LinePanel<'_>],
) -> anyhow::Result<Figure> {
    if panels.is_empty() || columns == 0 {
        anyhow::bail!("no panels");
    }
    let rows = panels.len().div_ceil(columns);
    let (pw, ph) = (470u32, 300u32);
    let size = (columns as u32 * pw, TITLE_H + rows as u32 * ph);
    render(&dir.join(DIR).join(name), size, |root| {
        let (top, rest) = root.split_vertically(TITLE_H);
        title_row(&top, heading)?;
        for (k, p) in panels.iter().enumerate() {
            let (r, col) = (k / columns, k % columns);
            let area = rest.clone().shrink((col as i32 * pw as i32, r as i32 * ph as i32), (pw, ph));
            let ((x0, x1), (y0, y1)) = range_of(p)?;
            let mut c = ChartBuilder::on(&area)
                .caption(p.title, (FAMILY, 15))
                .margin(MARGIN)
                .margin_right(14)
                .x_label_area_size(XLABEL_H)
                .y_label_area_size(YLABEL_W + 10)
                .build_cartesian_2d(x0..x1, y0..y1)
                .map_err(de)?;
            let (fx, fy) = (tick_format((x1 - x0) / 6.0), tick_format((y1 - y0) / 6.0));
            c.configure_mesh()
                .light_line_style(RGBColor(235, 235, 235))
                .x_desc(p.x_desc)
                .y_desc(p.y_desc)
                .x_labels(7)
                .y_labels(6)
                .x_label_formatter(&fx)
                .y_label_formatter(&fy)
                .label_style((FAMILY, 12))
                .axis_desc_style((FAMILY, 13))
                .draw()
                .map_err(de)?;
            for (s, (label, pts)) in p.series.iter().enumerate() {
                let colour = PALETTE[s % PALETTE.len()];
                let finite: Vec<(f64, f64)> =
                    pts.iter().copied().filter(|(x, y)| x.is_finite() && y.is_finite()).collect();
                c.draw_series(LineSeries::new(finite, colour.stroke_width(2)))
                    .map_err(de)?
                    .label(label.clone())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], colour.stroke_width(2)));
            }
            c.configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(RGBColor(180, 180, 180))
                .label_font((FAMILY, 11))
                .position(SeriesLabelPosition::UpperRight)
                .draw()
                .map_err(de)?;
        }
        Ok(())
    })?;
    Ok(figure(name, heading.to_string(), caption.to_string(), size))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_panels_draw_each_series_in_its_colour() {
        let dir = tempfile::tempdir().expect("tmp");
        let line = |a: f64| (0..50).map(|k| (k as f64, a)).collect::<Vec<_>>();
        let panel = LinePanel {
            title: "t",
            x_desc: "x",
            y_desc: "y",
            series: vec![("a".into(), line(1.0)), ("b".into(), line(3.0))],
        };
        let f = line_panels(dir.path(), "l.png", "heading", "caption", 1, &[panel]).expect("figure");
        assert_eq!(f.path, "figures/l.png");
        let file = std::fs::File::open(dir.path().join(&f.path)).expect("png");
        let mut dec = png::Decoder::new(std::io::BufReader::new(file)).read_info().expect("decode");
        let mut buf = vec![0; dec.output_buffer_size()];
        let info = dec.next_frame(&mut buf).expect("frame");
        let has = |c: RGBColor| buf.chunks(3).any(|p| p == [c.0, c.1, c.2]);
        assert_eq!((info.width, info.height), (f.width, f.height));
        assert!(has(PALETTE[0]) && has(PALETTE[1]) && !has(PALETTE[2]));
        let empty =
            LinePanel { title: "e", x_desc: "x", y_desc: "y", series: vec![("n".into(), vec![(f64::NAN, 1.0)])] };
        assert!(line_panels(dir.path(), "e.png", "h", "c", 1, &[empty]).is_err());
    }
}
