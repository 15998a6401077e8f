//! Estimated vectors over the true speed.

use super::*;

/// One estimated field (planes on the truth's grid).
pub struct VectorPanel<'a> {
    pub name: String,
    pub vx: &'a [f32],
    pub vz: &'a [f32],
    /// Flag bits (1 = no estimate): no arrow.
    pub flags: Option<&'a [f32]>,
}

/// Arrow spacing (grid cells) for a grid: about 16 arrows across the larger side.
pub fn arrow_step(nx: usize, nz: usize) -> usize {
    (nx.max(nz) as f64 / 16.0).round().max(1.0) as usize
}

pub(super) fn draw_arrow(root: &Area<'_>, tail: (f64, f64), tip: (f64, f64)) -> anyhow::Result<()> {
    let (dx, dy) = (tip.0 - tail.0, tip.1 - tail.1);
    let len = dx.hypot(dy);
    if len < 1.5 {
        return Ok(());
    }
    let (ux, uy) = (dx / len, dy / len);
    let head = (0.35 * len).clamp(3.0, 7.0);
    let (c, s) = (25f64.to_radians().cos(), 25f64.to_radians().sin());
    let wing = |sgn: f64| {
        let (rx, ry) = (-ux * c - sgn * uy * s, -uy * c + sgn * ux * s);
        ((tip.0 + head * rx).round() as i32, (tip.1 + head * ry).round() as i32)
    };
    let p = |q: (f64, f64)| (q.0.round() as i32, q.1.round() as i32);
    let path = vec![p(tail), p(tip), wing(1.0), p(tip), wing(-1.0)];
    root.draw(&PathElement::new(path.clone(), WHITE.stroke_width(3))).map_err(de)?;
    root.draw(&PathElement::new(path, BLACK.stroke_width(1))).map_err(de)?;
    Ok(())
}

/// `figures/vector_field.png`: per estimate a panel with the true speed inside the vessel as
/// colour and the estimated vectors as arrows (every [`arrow_step`] cells, length ∝ speed,
/// v_max ↔ 0.9 steps, capped at twice that), plus the speed colour bar.
pub fn vector_field(
    dir: &Path,
    label: &str,
    heading: &str,
    grid: &GridV1,
    truth: (&[f32], &[f32], &[f32]),
    panels: &[VectorPanel<'_>],
) -> anyhow::Result<Figure> {
    vector_field_mapped(dir, label, heading, grid, truth, panels).map(|r| r.0)
}

pub(super) fn vector_field_mapped(
    dir: &Path,
    label: &str,
    heading: &str,
    grid: &GridV1,
    truth: (&[f32], &[f32], &[f32]),
    panels: &[VectorPanel<'_>],
) -> anyhow::Result<(Figure, Vec<PanelMap>)> {
    let (tvx, tvz, mask) = truth;
    check_grid(grid, &[("truth vx", tvx.len()), ("truth vz", tvz.len()), ("mask", mask.len())])?;
    if panels.is_empty() {
        anyhow::bail!("no estimated field");
    }
    for p in panels {
        let mut planes = vec![("vx", p.vx.len()), ("vz", p.vz.len())];
        planes.extend(p.flags.map(|f| ("flags", f.len())));
        check_grid(grid, &planes)?;
    }
    let speed: Vec<f64> = tvx.iter().zip(tvz).map(|(a, b)| (*a as f64).hypot(*b as f64)).collect();
    let v_max = speed.iter().zip(mask).filter(|(s, m)| **m > 0.5 && s.is_finite()).map(|(s, _)| *s).fold(0.0, f64::max);
    if v_max <= 0.0 {
        anyhow::bail!("the true field has no speed inside the vessel");
    }
    let (nx, nz) = n_of(grid);
    let step = arrow_step(nx, nz);
    let plot_w = 360;
    let plot_h = plot_height(grid, plot_w);
    let (pw, ph) = panel_size(plot_w, plot_h);
    let size = (panels.len() as u32 * pw + BAR_W, TITLE_H + ph);
    let (xa, _, za, _) = extent_mm(grid);
    let (dx, dz) = (grid.dx * 1e3, grid.dz * 1e3);
    let scale = 0.9 * step as f64 * dx.min(dz) / v_max; // mm per m/s
    let name = file_name(VECTORS, label);
    let maps = render(&dir.join(DIR).join(&name), size, |root| {
        let (top, rest) = root.split_vertically(TITLE_H);
        title_row(&top, heading)?;
        let (grid_area, bar) = rest.split_horizontally(panels.len() as u32 * pw);
        let mut maps = Vec::new();
        for (k, p) in panels.iter().enumerate() {
            let area = grid_area.clone().shrink((k as i32 * pw as i32, 0), (pw, ph));
            let mut c = grid_chart(&area, &p.name, grid)?;
            draw_cells(&mut c, grid, |i| if mask[i] > 0.5 { speed_colour(speed[i] / v_max) } else { OUTSIDE })?;
            let map = PanelMap::of(&c);
            for iz in (step / 2..nz).step_by(step) {
                for ix in (step / 2..nx).step_by(step) {
                    let i = iz * nx + ix;
                    let (vx, vz) = (p.vx[i] as f64, p.vz[i] as f64);
                    if mask[i] <= 0.5
                        || p.flags.is_some_and(|f| (f[i] as u32) & 1 != 0)
                        || !(vx.is_finite() && vz.is_finite())
                    {
                        continue;
                    }
                    let cap = (2.0 * v_max / vx.hypot(vz)).min(1.0);
                    let (x, z) = (xa + (ix as f64 + 0.5) * dx, za + (iz as f64 + 0.5) * dz);
                    let tip = (x + scale * cap * vx, z + scale * cap * vz);
                    draw_arrow(root, map.pixel(x, z), map.pixel(tip.0, tip.1))?;
                }
            }
            maps.push(map);
        }
        let bar = bar.shrink((0, 0), (BAR_W, ph));
        colour_bar(&bar, 0.0, v_max, "true speed (m/s)", speed_colour)?;
        Ok(maps)
    })?;
    let fig = figure(
        &name,
        heading.to_string(),
        format!(
            "Colour: the true speed inside the vessel (grey outside); arrows: the estimated velocity every {step} pixels, v_max = {v_max:.3} m/s drawn {:.2} mm long (capped at twice that); arrows should follow the colour's flow and match it in length.",
            scale * v_max
        ),
        size,
    );
    Ok((fig, maps))
}
