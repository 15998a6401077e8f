//! Transmit pressure fields (MUST `pfield`), one panel per transmit.

use super::*;

/// One transmit's RMS pressure on `grid` in dB relative to the largest over all panels.
pub struct FieldPanel<'a> {
    pub title: String,
    pub grid: GridV1,
    /// dB re the maximum over all panels (≤ 0), row-major `iz·nx + ix`.
    pub db: &'a [f32],
}

/// Dynamic range of the transmit-field figure (dB).
pub const FIELD_DR: f64 = 40.0;

/// The colour of a field level (dB re max): [`speed_colour`] from −[`FIELD_DR`] to 0 dB.
pub fn field_colour(db: f64) -> RGBColor {
    speed_colour(((db + FIELD_DR) / FIELD_DR).clamp(0.0, 1.0))
}

/// `figures/transmit_fields[-label].png`: a panel per transmit (4 per row) and a dB colour bar.
pub fn transmit_fields(dir: &Path, label: &str, heading: &str, panels: &[FieldPanel<'_>]) -> anyhow::Result<Figure> {
    transmit_fields_mapped(dir, label, heading, panels).map(|r| r.0)
}

pub(super) fn transmit_fields_mapped(
    dir: &Path,
    label: &str,
    heading: &str,
    panels: &[FieldPanel<'_>],
) -> anyhow::Result<(Figure, Vec<PanelMap>)> {
    if panels.is_empty() {
        anyhow::bail!("no transmit fields");
    }
    for p in panels {
        check_grid(&p.grid, &[("db", p.db.len())])?;
    }
    let cols = panels.len().min(4);
    let rows = panels.len().div_ceil(cols);
    let plot_w = 300;
    let plot_h = panels.iter().map(|p| plot_height(&p.grid, plot_w)).max().unwrap_or(plot_w);
    let (pw, ph) = panel_size(plot_w, plot_h);
    let size = (cols as u32 * pw + BAR_W, TITLE_H + rows as u32 * ph);
    let name = file_name(FIELDS, label);
    let maps = render(&dir.join(DIR).join(&name), size, |root| {
        let (top, rest) = root.split_vertically(TITLE_H);
        title_row(&top, heading)?;
        let (grid_area, bar) = rest.split_horizontally(cols as u32 * pw);
        let mut maps = Vec::new();
        for (k, p) in panels.iter().enumerate() {
            let (r, col) = ((k / cols) as i32, (k % cols) as i32);
            let area = grid_area.clone().shrink((col * pw as i32, r * ph as i32), (pw, ph));
            let mut c = grid_chart(&area, &p.title, &p.grid)?;
            draw_cells(&mut c, &p.grid, |i| field_colour(f64::from(p.db[i])))?;
            maps.push(PanelMap::of(&c));
        }
        let bar = bar.shrink((0, 0), (BAR_W, ph));
        colour_bar(&bar, -FIELD_DR, 0.0, "RMS pressure (dB re max)", |t| field_colour(FIELD_DR * (t - 1.0)))?;
        Ok(maps)
    })?;
    let fig = figure(
        &name,
        heading.to_string(),
        format!(
            "Transmit pressure fields (MUST pfield: RMS over the pulse's band) of the run's probe, one panel per transmit, in dB re the largest; dark below −{FIELD_DR:.0} dB. They show where each transmit insonifies the scatterers."
        ),
        size,
    );
    Ok((fig, maps))
}
