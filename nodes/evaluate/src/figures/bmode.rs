//! The B-mode image of a beamformed I/Q frame.

use super::*;

/// One B-mode image on `grid`: MUST `bmode` bytes (0 = `dr` dB or more below the maximum, 255 =
/// the maximum), row-major `iz·nx + ix`.
pub struct BmodePanel<'a> {
    pub title: String,
    pub grid: GridV1,
    pub image: &'a [u8],
    /// Dynamic range (dB) the bytes span.
    pub dr: f64,
}

/// The grey of a B-mode byte.
pub fn bmode_grey(v: u8) -> RGBColor {
    RGBColor(v, v, v)
}

/// `figures/bmode[-label].png`: the image in its geometry (mm), a dB colour bar, the vessel's
/// outline in red where `outline` (a mask on the image's grid) is given.
pub fn bmode_figure(
    dir: &Path,
    label: &str,
    heading: &str,
    panel: &BmodePanel<'_>,
    outline: Option<&[f32]>,
) -> anyhow::Result<Figure> {
    bmode_figure_mapped(dir, label, heading, panel, outline).map(|r| r.0)
}

pub(super) fn bmode_figure_mapped(
    dir: &Path,
    label: &str,
    heading: &str,
    p: &BmodePanel<'_>,
    outline: Option<&[f32]>,
) -> anyhow::Result<(Figure, PanelMap)> {
    let n = (p.grid.nx as usize) * (p.grid.nz as usize);
    if p.image.len() != n || n == 0 {
        anyhow::bail!("{}: {} bytes for a {} × {} grid", p.title, p.image.len(), p.grid.nz, p.grid.nx);
    }
    if !(p.dr.is_finite() && p.dr > 0.0) {
        anyhow::bail!("{}: dynamic range {} dB", p.title, p.dr);
    }
    let outline = outline.filter(|m| m.len() == n);
    let plot_w = 420;
    let plot_h = plot_height(&p.grid, plot_w);
    let (pw, ph) = panel_size(plot_w, plot_h);
    let size = (pw + BAR_W, TITLE_H + ph);
    let name = file_name(BMODE, label);
    let map = render(&dir.join(DIR).join(&name), size, |root| {
        let (top, rest) = root.split_vertically(TITLE_H);
        title_row(&top, heading)?;
        let (area, bar) = rest.split_horizontally(pw);
        let mut c = grid_chart(&area, &p.title, &p.grid)?;
        draw_cells(&mut c, &p.grid, |i| bmode_grey(p.image[i]))?;
        if let Some(m) = outline {
            draw_outline(&mut c, &p.grid, m, RGBColor(255, 64, 64))?;
        }
        let bar = bar.shrink((0, 0), (BAR_W, ph));
        colour_bar(&bar, -p.dr, 0.0, "echo (dB re max)", |t| bmode_grey((255.0 * t).round() as u8))?;
        Ok(PanelMap::of(&c))
    })?;
    let fig = figure(
        &name,
        heading.to_string(),
        format!(
            "B-mode (MUST bmode): the envelope of the beamformed I/Q, log-compressed over {:.0} dB (black: {:.0} dB or more below the image's maximum){}.",
            p.dr,
            p.dr,
            if outline.is_some() { "; red: the true vessel wall" } else { "" }
        ),
        size,
    );
    Ok((fig, map))
}
