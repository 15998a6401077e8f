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
    let name = file_name(FIELDS, label);
    let titled: Vec<(&str, &GridV1)> = panels.iter().map(|p| (p.title.as_str(), &p.grid)).collect();
    let (size, maps) = panel_grid(
        &dir.join(DIR).join(&name),
        heading,
        &titled,
        |k, c| draw_cells(c, &panels[k].grid, |i| field_colour(f64::from(panels[k].db[i]))),
        |bar| colour_bar(bar, -FIELD_DR, 0.0, "RMS pressure (dB re max)", |t| field_colour(FIELD_DR * (t - 1.0))),
    )?;
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
