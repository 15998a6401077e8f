//! Colour Doppler maps per angle pair.

use super::*;

/// One colour Doppler map (one transmit/receive angle pair), planes on `grid`.
pub struct DopplerPanel<'a> {
    pub title: String,
    pub grid: GridV1,
    /// Axial velocity (m/s, positive toward the probe).
    pub velocity: &'a [f32],
    /// Slow-time power (R0), for the display threshold and the grey background.
    pub power: Option<&'a [f32]>,
    /// Flag bits (1 = no estimate).
    pub flags: Option<&'a [f32]>,
    /// Aliasing limit (m/s): full colour at ±this.
    pub nyquist: f64,
}

/// Colour is shown where the power is at most this many dB below the map's 99th percentile.
pub const DOPPLER_THRESHOLD_DB: f64 = 20.0;

pub(super) fn p99(v: &[f32]) -> f64 {
    let mut s: Vec<f64> = v.iter().map(|p| *p as f64).filter(|p| p.is_finite() && *p > 0.0).collect();
    if s.is_empty() {
        return 0.0;
    }
    s.sort_by(f64::total_cmp);
    s[((s.len() - 1) as f64 * 0.99).round() as usize]
}

/// The colour of pixel `i` of a Doppler panel (`pref`: its power reference, [`p99`]).
pub(super) fn doppler_pixel(p: &DopplerPanel<'_>, i: usize, pref: f64) -> RGBColor {
    let no_est = p.flags.is_some_and(|f| (f[i] as u32) & 1 != 0);
    let db = match p.power {
        Some(pw) if pref > 0.0 => 10.0 * (pw[i] as f64 / pref).log10(),
        _ => 0.0,
    };
    if no_est || db.is_nan() || db < -DOPPLER_THRESHOLD_DB {
        power_grey(db)
    } else {
        doppler_colour(p.velocity[i] as f64 / p.nyquist)
    }
}

/// `figures/doppler_maps[-label].png`: one panel per angle pair (4 per row), a colour bar, the
/// vessel's outline where `outline` (a mask on the panels' grid) is given.
pub fn doppler_maps(
    dir: &Path,
    label: &str,
    heading: &str,
    panels: &[DopplerPanel<'_>],
    outline: Option<&[f32]>,
) -> anyhow::Result<Figure> {
    doppler_maps_mapped(dir, label, heading, panels, outline).map(|r| r.0)
}

pub(super) fn doppler_maps_mapped(
    dir: &Path,
    label: &str,
    heading: &str,
    panels: &[DopplerPanel<'_>],
    outline: Option<&[f32]>,
) -> anyhow::Result<(Figure, Vec<PanelMap>)> {
    let first = panels.first().ok_or_else(|| anyhow::anyhow!("no Doppler maps"))?;
    for p in panels {
        let n = p.velocity.len();
        let mut planes = vec![("velocity", n)];
        planes.extend(p.power.map(|v| ("power", v.len())));
        planes.extend(p.flags.map(|v| ("flags", v.len())));
        check_grid(&p.grid, &planes)?;
        if !(p.nyquist > 0.0 && p.nyquist.is_finite()) {
            anyhow::bail!("{}: Nyquist velocity {} m/s", p.title, p.nyquist);
        }
    }
    let same_vn = panels.iter().all(|p| (p.nyquist - first.nyquist).abs() <= 1e-9 * first.nyquist);
    let outline = outline.filter(|m| panels.iter().all(|p| p.grid == first.grid && m.len() == p.velocity.len()));
    let name = file_name(DOPPLER, label);
    let titled: Vec<(&str, &GridV1)> = panels.iter().map(|p| (p.title.as_str(), &p.grid)).collect();
    let fill = |k: usize, c: &mut Chart<'_, '_>| {
        let p = &panels[k];
        let pref = p.power.map(p99).unwrap_or(0.0);
        draw_cells(c, &p.grid, |i| doppler_pixel(p, i, pref))?;
        if let Some(m) = outline {
            draw_outline(c, &p.grid, m, WHITE)?;
        }
        Ok(())
    };
    let bar = |bar: &Area<'_>| {
        if same_vn {
            let vn = first.nyquist;
            colour_bar(bar, -vn, vn, "v toward probe (m/s)", |t| doppler_colour(2.0 * t - 1.0))
        } else {
            colour_bar(bar, -1.0, 1.0, "v / v_Nyquist", |t| doppler_colour(2.0 * t - 1.0))
        }
    };
    let (size, maps) = panel_grid(&dir.join(DIR).join(&name), heading, &titled, fill, bar)?;
    let fig = figure(
        &name,
        heading.to_string(),
        format!(
            "Colour Doppler per angle pair: axial velocity, red toward the probe and blue away, full colour at ± the Nyquist velocity (beyond it aliasing wraps red ↔ blue); grey (log power, 40 dB span) where the power is over {DOPPLER_THRESHOLD_DB:.0} dB below the map's 99th percentile or there is no estimate{}.",
            if outline.is_some() { "; white: the true vessel wall" } else { "" }
        ),
        size,
    );
    Ok((fig, maps))
}
