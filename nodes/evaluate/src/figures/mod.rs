//! PNG figures of the run report (`<run>/figures/`): colour Doppler maps per angle pair, the
//! estimated vector field over the true speed, error histograms of vx and vz (paper 1's figures
//! 5–7) and the stage times. Plain slices in, a PNG file and a [`Figure`] (path, title, one-line
//! caption, size) out; no IPC, so the tests call these directly. The evaluator node draws the
//! first three at the end of its stream, the launcher the stage times after the run.
//!
//! Rendering is pure Rust: plotters' bitmap backend, text through ab_glyph with an embedded
//! subset of DejaVu Sans (`assets/fonts/`, no system font library), PNG encoding with `png`.
//! Callers treat every error as a warning ([`guarded`] also turns a panic into one): a figure
//! never makes a run fail.

use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use serde::{Deserialize, Serialize};
use sonoflow_messages::GridV1;
use std::path::Path;

mod bmode;
mod doppler_maps;
mod fields;
mod histograms;
mod lines;
mod stages;
mod vectors;
pub use bmode::*;
pub use doppler_maps::*;
pub use fields::*;
pub use histograms::*;
pub use lines::*;
pub use stages::*;
pub use vectors::*;

/// Sub-folder of the run folder holding the figures.
pub const DIR: &str = "figures";
/// File names.
pub const DOPPLER: &str = "doppler_maps.png";
pub const VECTORS: &str = "vector_field.png";
pub const ERRORS: &str = "error_histograms.png";
pub const STAGES: &str = "stage_times.png";
pub const BMODE: &str = "bmode.png";
pub const FIELDS: &str = "transmit_fields.png";

/// One written figure, as listed in `report.json` / `evaluation.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Figure {
    /// Path relative to the run folder (`figures/NAME.png`).
    pub path: String,
    pub title: String,
    /// One line: how to read it.
    pub caption: String,
    /// Size in pixels.
    pub width: u32,
    pub height: u32,
}

const FAMILY: &str = "sans-serif";
static FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans-subset.ttf");

type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;
type Chart<'a, 'b> = ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

fn de<E: std::fmt::Display>(e: E) -> anyhow::Error {
    anyhow::anyhow!("drawing: {e}")
}

fn ensure_font() -> anyhow::Result<()> {
    static OK: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    if *OK.get_or_init(|| plotters::style::register_font(FAMILY, FontStyle::Normal, FONT).is_ok()) {
        Ok(())
    } else {
        anyhow::bail!("the embedded font does not load")
    }
}

/// Runs `f`, turning an error or a panic into a warning line `"figure WHAT: …"`.
pub fn guarded<T>(what: &str, f: impl FnOnce() -> anyhow::Result<T>) -> Result<T, String> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)) {
        Ok(Ok(v)) => Ok(v),
        Ok(Err(e)) => Err(format!("figure {what}: {e:#}")),
        Err(p) => {
            let msg = p
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| p.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "panic".into());
            Err(format!("figure {what}: the plotting code panicked: {msg}"))
        }
    }
}

/// Linear map of one chart's data coordinates to image pixels (the tests probe figures with it).
#[derive(Clone, Copy, Debug)]
pub struct PanelMap {
    x: (f64, f64),
    y: (f64, f64),
}

impl PanelMap {
    fn of(c: &Chart<'_, '_>) -> Self {
        let (xr, yr) = (c.x_range(), c.y_range());
        let p0 = c.backend_coord(&(xr.start, yr.start));
        let p1 = c.backend_coord(&(xr.end, yr.end));
        let sx = if xr.end != xr.start { (p1.0 - p0.0) as f64 / (xr.end - xr.start) } else { 0.0 };
        let sy = if yr.end != yr.start { (p1.1 - p0.1) as f64 / (yr.end - yr.start) } else { 0.0 };
        Self { x: (p0.0 as f64 - sx * xr.start, sx), y: (p0.1 as f64 - sy * yr.start, sy) }
    }
    /// Pixel (column, row) of data point (x, y).
    pub fn pixel(&self, x: f64, y: f64) -> (f64, f64) {
        (self.x.0 + self.x.1 * x, self.y.0 + self.y.1 * y)
    }
}

/// Renders on a `w × h` white canvas and writes the PNG to `path` (atomically).
fn render<T>(path: &Path, (w, h): (u32, u32), draw: impl FnOnce(&Area<'_>) -> anyhow::Result<T>) -> anyhow::Result<T> {
    ensure_font()?;
    let mut buf = vec![255u8; w as usize * h as usize * 3];
    let out = {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        let out = draw(&root)?;
        root.present().map_err(de)?;
        out
    };
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    sonoflow_fileio::write_atomic(path, &encode_png(&buf, w, h)?)?;
    Ok(out)
}

/// A figure of grid panels, at most 4 per row, under a title row `heading`, with one colour bar
/// right of them, rendered to `path`: panel k's chart is made by [`grid_chart`] from
/// `panels[k]` (title, grid; the tallest grid sets the row height) and filled by `fill(k, chart)`;
/// `bar(area)` draws the colour bar. Returns the image size and the panels' maps.
fn panel_grid(
    path: &Path,
    heading: &str,
    panels: &[(&str, &GridV1)],
    mut fill: impl FnMut(usize, &mut Chart<'_, '_>) -> anyhow::Result<()>,
    bar: impl FnOnce(&Area<'_>) -> anyhow::Result<()>,
) -> anyhow::Result<((u32, u32), Vec<PanelMap>)> {
    let cols = panels.len().clamp(1, 4);
    let rows = panels.len().div_ceil(cols);
    let plot_w = 300;
    let plot_h = panels.iter().map(|(_, g)| plot_height(g, plot_w)).max().unwrap_or(plot_w);
    let (pw, ph) = panel_size(plot_w, plot_h);
    let size = (cols as u32 * pw + BAR_W, TITLE_H + rows as u32 * ph);
    let maps = render(path, size, |root| {
        let (top, rest) = root.split_vertically(TITLE_H);
        title_row(&top, heading)?;
        let (grid_area, bar_area) = rest.split_horizontally(cols as u32 * pw);
        let mut maps = Vec::with_capacity(panels.len());
        for (k, (title, grid)) in panels.iter().enumerate() {
            let (r, col) = ((k / cols) as i32, (k % cols) as i32);
            let area = grid_area.clone().shrink((col * pw as i32, r * ph as i32), (pw, ph));
            let mut c = grid_chart(&area, title, grid)?;
            fill(k, &mut c)?;
            maps.push(PanelMap::of(&c));
        }
        bar(&bar_area.shrink((0, 0), (BAR_W, ph)))?;
        Ok(maps)
    })?;
    Ok((size, maps))
}

/// RGB8 → PNG bytes (adaptive filters, default deflate: tens of milliseconds per figure).
pub fn encode_png(rgb: &[u8], w: u32, h: u32) -> anyhow::Result<Vec<u8>> {
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, w, h);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_compression(png::Compression::Default);
        enc.set_adaptive_filter(png::AdaptiveFilterType::Adaptive);
        let mut wr = enc.write_header()?;
        wr.write_image_data(rgb)?;
        wr.finish()?;
    }
    Ok(out)
}

fn figure(name: &str, title: String, caption: String, (width, height): (u32, u32)) -> Figure {
    Figure { path: format!("{DIR}/{name}"), title, caption, width, height }
}

/// File name of figure `base` (one of the constants) for an evaluator `label`:
/// `doppler_maps.png`, or `doppler_maps-<label>.png` when the label is not empty.
pub fn file_name(base: &str, label: &str) -> String {
    match (label.is_empty(), base.strip_suffix(".png")) {
        (false, Some(stem)) => format!("{stem}-{label}.png"),
        _ => base.to_string(),
    }
}

// ---------------------------------------------------------------------------------------------
// Colour maps

/// Colour Doppler map of `t = v / v_Nyquist`: black at 0, red (t = ¼) to yellow (t ≥ 1) toward
/// the probe, blue (t = −¼) to cyan (t ≤ −1) away from it (brightness ∝ √|t|, so that slow flow
/// shows).
pub fn doppler_colour(t: f64) -> RGBColor {
    let t = if t.is_finite() { t.clamp(-1.0, 1.0) } else { 0.0 };
    let a = t.abs().sqrt();
    let main = (510.0 * a.min(0.5)).round() as u8;
    let hi = (510.0 * (a - 0.5).max(0.0)).round() as u8;
    if t >= 0.0 {
        RGBColor(main, hi, 0)
    } else {
        RGBColor(0, hi, main)
    }
}

/// Grey level of a power `db` decibels relative to the reference (40 dB span: −40 dB black,
/// 0 dB light grey 200): the background where colour Doppler shows no flow.
pub fn power_grey(db: f64) -> RGBColor {
    let l = if db.is_finite() { ((db + 40.0) / 40.0).clamp(0.0, 1.0) } else { 0.0 };
    let g = (200.0 * l).round() as u8;
    RGBColor(g, g, g)
}

/// Sequential speed colour map (viridis' control points) of `t` in [0, 1].
pub fn speed_colour(t: f64) -> RGBColor {
    const P: [(f64, [f64; 3]); 5] = [
        (0.0, [68.0, 1.0, 84.0]),
        (0.25, [59.0, 82.0, 139.0]),
        (0.5, [33.0, 145.0, 140.0]),
        (0.75, [94.0, 201.0, 98.0]),
        (1.0, [253.0, 231.0, 37.0]),
    ];
    let t = if t.is_finite() { t.clamp(0.0, 1.0) } else { 0.0 };
    let k = P.windows(2).position(|w| t <= w[1].0).unwrap_or(P.len() - 2);
    let ((t0, c0), (t1, c1)) = (P[k], P[k + 1]);
    let f = (t - t0) / (t1 - t0);
    let c = |i: usize| (c0[i] + f * (c1[i] - c0[i])).round() as u8;
    RGBColor(c(0), c(1), c(2))
}

/// Outside the vessel in the vector figure.
pub const OUTSIDE: RGBColor = RGBColor(235, 235, 235);
/// Histogram bars, stage-time bars.
pub const BAR: RGBColor = RGBColor(31, 119, 180);
pub const BAR2: RGBColor = RGBColor(255, 127, 14);

// ---------------------------------------------------------------------------------------------
// Grid panels

fn n_of(g: &GridV1) -> (usize, usize) {
    (g.nx as usize, g.nz as usize)
}

/// Extent of the grid's cells in mm: (x_left, x_right, z_top, z_bottom).
fn extent_mm(g: &GridV1) -> (f64, f64, f64, f64) {
    let (nx, nz) = n_of(g);
    let x0 = (g.x0 - 0.5 * g.dx) * 1e3;
    let z0 = (g.z0 - 0.5 * g.dz) * 1e3;
    (x0, x0 + nx as f64 * g.dx * 1e3, z0, z0 + nz as f64 * g.dz * 1e3)
}

fn check_grid(g: &GridV1, planes: &[(&str, usize)]) -> anyhow::Result<()> {
    let (nx, nz) = n_of(g);
    if nx == 0 || nz == 0 || !(g.dx > 0.0 && g.dz > 0.0 && g.x0.is_finite() && g.z0.is_finite()) {
        anyhow::bail!("empty or invalid grid ({nx} × {nz}, dx {} m, dz {} m)", g.dx, g.dz);
    }
    for (name, len) in planes {
        if *len != nx * nz {
            anyhow::bail!("plane `{name}` has {len} values for a {nx} × {nz} grid");
        }
    }
    Ok(())
}

/// Plot-area height for a plot-area width, keeping the grid's aspect ratio where it can.
fn plot_height(g: &GridV1, plot_w: u32) -> u32 {
    let (xa, xb, za, zb) = extent_mm(g);
    ((plot_w as f64 * (zb - za) / (xb - xa)).round() as u32).clamp(120, 640)
}

const CAPTION_H: u32 = 28;
const XLABEL_H: u32 = 40;
const YLABEL_W: u32 = 50;
const MARGIN: u32 = 6;

/// Panel size for a plot area `plot_w × plot_h`.
fn panel_size(plot_w: u32, plot_h: u32) -> (u32, u32) {
    (plot_w + YLABEL_W + 2 * MARGIN, plot_h + CAPTION_H + XLABEL_H + 2 * MARGIN)
}

fn grid_chart<'a, 'b>(area: &'a Area<'b>, title: &str, g: &GridV1) -> anyhow::Result<Chart<'a, 'b>> {
    let (xa, xb, za, zb) = extent_mm(g);
    let mut c = ChartBuilder::on(area)
        .caption(title, (FAMILY, 15))
        .margin(MARGIN)
        .x_label_area_size(XLABEL_H)
        .y_label_area_size(YLABEL_W)
        .build_cartesian_2d(xa..xb, zb..za)
        .map_err(de)?;
    let fx = tick_format((xb - xa) / 6.0);
    let fz = tick_format((zb - za) / 6.0);
    c.configure_mesh()
        .disable_mesh()
        .x_desc("x (mm)")
        .y_desc("z (mm)")
        .x_labels(6)
        .y_labels(6)
        .x_label_formatter(&fx)
        .y_label_formatter(&fz)
        .label_style((FAMILY, 12))
        .axis_desc_style((FAMILY, 13))
        .draw()
        .map_err(de)?;
    Ok(c)
}

/// Tick labels with as many decimals as a tick spacing of about `step` needs.
fn tick_format(step: f64) -> impl Fn(&f64) -> String {
    let d = if step >= 1.0 {
        0
    } else if step >= 0.1 {
        1
    } else {
        2
    };
    move |v: &f64| {
        let v = if v.abs() < 1e-9 { 0.0 } else { *v };
        format!("{v:.d$}")
    }
}

/// One filled rectangle per grid cell, coloured by `colour(index)`.
fn draw_cells(c: &mut Chart<'_, '_>, g: &GridV1, colour: impl Fn(usize) -> RGBColor) -> anyhow::Result<()> {
    let (nx, nz) = n_of(g);
    let (xa, _, za, _) = extent_mm(g);
    let (dx, dz) = (g.dx * 1e3, g.dz * 1e3);
    c.draw_series((0..nz).flat_map(|iz| (0..nx).map(move |ix| (ix, iz))).map(|(ix, iz)| {
        let (x, z) = (xa + ix as f64 * dx, za + iz as f64 * dz);
        Rectangle::new([(x, z), (x + dx, z + dz)], colour(iz * nx + ix).filled())
    }))
    .map_err(de)?;
    Ok(())
}

/// Outline of `mask > 0.5` along the cell edges.
fn draw_outline(c: &mut Chart<'_, '_>, g: &GridV1, mask: &[f32], colour: RGBColor) -> anyhow::Result<()> {
    let (nx, nz) = n_of(g);
    let (xa, _, za, _) = extent_mm(g);
    let (dx, dz) = (g.dx * 1e3, g.dz * 1e3);
    let inside = |ix: usize, iz: usize| mask[iz * nx + ix] > 0.5;
    let mut segs = Vec::new();
    for iz in 0..nz {
        for ix in 0..nx {
            let (x, z) = (xa + ix as f64 * dx, za + iz as f64 * dz);
            if ix + 1 < nx && inside(ix, iz) != inside(ix + 1, iz) {
                segs.push([(x + dx, z), (x + dx, z + dz)]);
            }
            if iz + 1 < nz && inside(ix, iz) != inside(ix, iz + 1) {
                segs.push([(x, z + dz), (x + dx, z + dz)]);
            }
        }
    }
    c.draw_series(segs.into_iter().map(|s| PathElement::new(s.to_vec(), colour.stroke_width(1)))).map_err(de)?;
    Ok(())
}

/// Vertical colour bar from `lo` to `hi` (label `desc`).
fn colour_bar(area: &Area<'_>, lo: f64, hi: f64, desc: &str, colour: impl Fn(f64) -> RGBColor) -> anyhow::Result<()> {
    let mut c = ChartBuilder::on(area)
        .margin_top(CAPTION_H + MARGIN)
        .margin_bottom(XLABEL_H + MARGIN)
        .margin_right(10)
        .y_label_area_size(64)
        .build_cartesian_2d(0f64..1.0, lo..hi)
        .map_err(de)?;
    let fy = tick_format((hi - lo) / 7.0);
    c.configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_desc(desc)
        .y_labels(7)
        .y_label_formatter(&fy)
        .label_style((FAMILY, 12))
        .axis_desc_style((FAMILY, 13))
        .draw()
        .map_err(de)?;
    let n = 128;
    c.draw_series((0..n).map(|k| {
        let (a, b) = (lo + (hi - lo) * k as f64 / n as f64, lo + (hi - lo) * (k + 1) as f64 / n as f64);
        Rectangle::new([(0.0, a), (1.0, b)], colour((k as f64 + 0.5) / n as f64).filled())
    }))
    .map_err(de)?;
    Ok(())
}

fn title_row(area: &Area<'_>, title: &str) -> anyhow::Result<()> {
    area.draw(&Text::new(title.to_string(), (10, 8), (FAMILY, 17).into_font().color(&BLACK))).map_err(de)?;
    Ok(())
}

const TITLE_H: u32 = 32;
const BAR_W: u32 = 112;

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn decode(path: &Path) -> (u32, u32, Vec<u8>) {
        let dec = png::Decoder::new(std::fs::File::open(path).unwrap());
        let mut rd = dec.read_info().unwrap();
        let mut buf = vec![0; rd.output_buffer_size()];
        let info = rd.next_frame(&mut buf).unwrap();
        assert_eq!(info.color_type, png::ColorType::Rgb);
        buf.truncate(info.buffer_size());
        (info.width, info.height, buf)
    }

    fn px(img: &(u32, u32, Vec<u8>), (x, y): (f64, f64)) -> RGBColor {
        let (x, y) = (x.round() as usize, y.round() as usize);
        let i = 3 * (y * img.0 as usize + x);
        RGBColor(img.2[i], img.2[i + 1], img.2[i + 2])
    }

    fn grid(n: u32) -> GridV1 {
        GridV1 { x0: -0.01, z0: 0.01, dx: 0.5e-3, dz: 0.5e-3, nx: n, nz: n }
    }

    /// Centre (mm) of cell (ix, iz).
    fn cell(g: &GridV1, ix: usize, iz: usize) -> (f64, f64) {
        ((g.x0 + ix as f64 * g.dx) * 1e3, (g.z0 + iz as f64 * g.dz) * 1e3)
    }

    /// A disk of radius 10 cells in a 40 × 40 grid.
    fn disk(n: usize) -> Vec<f32> {
        (0..n * n)
            .map(|i| {
                let (x, z) = ((i % n) as f64 - 19.5, (i / n) as f64 - 19.5);
                if x.hypot(z) < 10.0 {
                    1.0
                } else {
                    0.0
                }
            })
            .collect()
    }

    #[test]
    fn colour_maps_have_the_documented_ends() {
        assert_eq!(doppler_colour(0.0), RGBColor(0, 0, 0));
        assert_eq!(doppler_colour(0.25), RGBColor(255, 0, 0));
        assert_eq!(doppler_colour(0.0625), RGBColor(128, 0, 0));
        assert_eq!(doppler_colour(1.0), RGBColor(255, 255, 0));
        assert_eq!(doppler_colour(3.0), RGBColor(255, 255, 0));
        assert_eq!(doppler_colour(-0.25), RGBColor(0, 0, 255));
        assert_eq!(doppler_colour(-1.0), RGBColor(0, 255, 255));
        assert_eq!(doppler_colour(f64::NAN), RGBColor(0, 0, 0));
        assert_eq!(power_grey(0.0), RGBColor(200, 200, 200));
        assert_eq!(power_grey(-40.0), RGBColor(0, 0, 0));
        assert_eq!(power_grey(-20.0), RGBColor(100, 100, 100));
        assert_eq!(speed_colour(0.0), RGBColor(68, 1, 84));
        assert_eq!(speed_colour(1.0), RGBColor(253, 231, 37));
        assert_eq!(speed_colour(0.5), RGBColor(33, 145, 140));
        // Monotone in green across the map.
        let g: Vec<u8> = (0..=10).map(|k| speed_colour(k as f64 / 10.0).1).collect();
        assert!(g.windows(2).all(|w| w[1] > w[0]), "{g:?}");
    }

    #[test]
    fn histogram_bins_a_known_distribution() {
        // 100 values: 60 at +0.5 %, 30 at −1.5 %, 7 at +15 % (beyond the axis: last bin), 3 NaN.
        let mut v = vec![0.005; 60];
        v.extend(vec![-0.015; 30]);
        v.extend(vec![0.15; 7]);
        v.extend(vec![f64::NAN; 3]);
        let h = histogram(&v, -0.02, 0.02, 8); // bins of 0.5 %
        assert_eq!(h, vec![0, 30, 0, 0, 0, 60, 0, 7]);
        assert_eq!(histogram(&[-1.0, 0.0], 0.0, 1.0, 2), vec![2, 0], "below the range: first bin");
        assert_eq!(error_axis(&[&[0.004, -0.03]], 0.02), 0.05);
        assert_eq!(error_axis(&[&[0.004], &[0.3]], 0.10), 0.5);
        assert_eq!(error_axis(&[&[]], 0.10), 0.2);
    }

    #[test]
    fn error_histogram_bars_have_the_heights_of_the_distribution() {
        let dir = tempfile::tempdir().unwrap();
        // vx: 75 % at −5.3 %, 25 % at +7.1 %; vz: all at +1.13 % (none on a bin edge).
        let mut ex = vec![-0.053; 300];
        ex.extend(vec![0.071; 100]);
        let ez = vec![0.0113; 400];
        let f = ErrorSample { name: "raw".into(), ex: &ex, ez: &ez };
        let (fig, maps) = error_histograms_mapped(dir.path(), "", "errors", &[f]).unwrap();
        assert_eq!(fig.path, "figures/error_histograms.png");
        let img = decode(&dir.path().join(&fig.path));
        assert_eq!((img.0, img.1), (fig.width, fig.height));
        // vx axis: p99 of |e| 7.1 % < 1.5 × the 10 % criterion → ±20 %, bins of 1 %.
        let rng = 20.0;
        let w = 2.0 * rng / HIST_BINS as f64;
        let top_of_bar = |m: &PanelMap, x: f64| {
            let (cx, _) = m.pixel(x, 0.0);
            let (_, y0) = m.pixel(x, 0.0);
            // Scan upwards from the baseline while the pixel is the bar colour.
            let mut y = y0 - 2.0;
            while px(&img, (cx, y)) == BAR {
                y -= 1.0;
            }
            y + 1.0
        };
        let bin_centre = |e: f64, r: f64, w: f64| -r + ((e + r) / w).floor() * w + 0.5 * w;
        for (e, pct) in [(-5.3, 75.0), (7.1, 25.0)] {
            let x = bin_centre(e, rng, w);
            let (_, expect) = maps[0].pixel(x, pct);
            let got = top_of_bar(&maps[0], x);
            assert!((got - expect).abs() <= 2.0, "vx bar at {x} %: top at row {got}, expected {expect}");
        }
        // An empty bin has no bar.
        let (cx, y0) = maps[0].pixel(bin_centre(0.0 + 2.0 * w, rng, w), 0.0);
        assert_ne!(px(&img, (cx, y0 - 3.0)), BAR);
        // vz axis: 1.5 × 2 % → ±5 %, one bar of 100 %.
        let (rz, wz) = (5.0, 10.0 / HIST_BINS as f64);
        let x = bin_centre(1.13, rz, wz);
        let (_, expect) = maps[1].pixel(x, 100.0);
        assert!((top_of_bar(&maps[1], x) - expect).abs() <= 2.0);
    }

    #[test]
    fn doppler_map_colours_flow_inside_and_greys_low_power_outside() {
        let dir = tempfile::tempdir().unwrap();
        let n = 40;
        let g = grid(n as u32);
        let mask = disk(n);
        let vn = 0.77;
        // Inside: +¼ Nyquist in the left half, −¼ in the right half, power 1; outside: power
        // 1e-3 (−30 dB: grey) and a velocity that would be yellow if shown.
        let vel: Vec<f32> = (0..n * n)
            .map(|i| {
                if mask[i] > 0.5 {
                    if i % n < 20 {
                        0.25 * vn as f32
                    } else {
                        -0.25 * vn as f32
                    }
                } else {
                    vn as f32
                }
            })
            .collect();
        let power: Vec<f32> = mask.iter().map(|m| if *m > 0.5 { 1.0 } else { 1e-3 }).collect();
        let mut flags = vec![0.0f32; n * n];
        flags[19 * n + 15] = 1.0; // no estimate inside: grey at 0 dB
        let panels: Vec<DopplerPanel> = ["rx −15°", "rx +15°"]
            .iter()
            .map(|t| DopplerPanel {
                title: t.to_string(),
                grid: g,
                velocity: &vel,
                power: Some(&power),
                flags: Some(&flags),
                nyquist: vn,
            })
            .collect();
        let (fig, maps) = doppler_maps_mapped(dir.path(), "", "Doppler", &panels, Some(&mask)).unwrap();
        let img = decode(&dir.path().join(&fig.path));
        assert_eq!((img.0, img.1), (fig.width, fig.height));
        assert_eq!(maps.len(), 2);
        for m in &maps {
            assert_eq!(px(&img, m.pixel(cell(&g, 12, 19).0, cell(&g, 12, 19).1)), RGBColor(255, 0, 0));
            assert_eq!(px(&img, m.pixel(cell(&g, 27, 19).0, cell(&g, 27, 19).1)), RGBColor(0, 0, 255));
            assert_eq!(px(&img, m.pixel(cell(&g, 15, 19).0, cell(&g, 15, 19).1)), power_grey(0.0));
            let out = px(&img, m.pixel(cell(&g, 2, 3).0, cell(&g, 2, 3).1));
            assert_eq!(out, power_grey(-30.0), "outside the vessel: grey at −30 dB");
        }
        // The vessel outline is white, on the cell edge between inside and outside.
        let (x_edge, z) = (cell(&g, 19, 9).0, cell(&g, 19, 9).1 + 0.25);
        let p = maps[0].pixel(x_edge, z);
        let near: Vec<RGBColor> = (-1..=1).map(|d| px(&img, (p.0, p.1 + d as f64))).collect();
        assert!(near.contains(&WHITE), "{near:?}");
    }

    #[test]
    fn bmode_figure_draws_each_cell_in_its_grey_and_the_vessel_outline() {
        let dir = tempfile::tempdir().unwrap();
        let n = 40;
        let g = grid(n as u32);
        // a ramp across x: byte = 6·ix (0 … 234)
        let image: Vec<u8> = (0..n * n).map(|i| (6 * (i % n)) as u8).collect();
        let panel = BmodePanel { title: "tx 0°".into(), grid: g, image: &image, dr: 50.0 };
        let (fig, m) = bmode_figure_mapped(dir.path(), "", "B-mode", &panel, Some(&disk(n))).unwrap();
        assert_eq!(fig.path, "figures/bmode.png");
        assert!(fig.caption.contains("50 dB") && fig.caption.contains("vessel wall"), "{}", fig.caption);
        let img = decode(&dir.path().join(&fig.path));
        assert_eq!((img.0, img.1), (fig.width, fig.height));
        for (ix, iz) in [(0, 0), (5, 30), (17, 20), (39, 39), (25, 3)] {
            let (x, z) = cell(&g, ix, iz);
            let p = m.pixel(x, z);
            assert_eq!(px(&img, p), bmode_grey((6 * ix) as u8), "cell ({ix}, {iz})");
        }
        // the outline in red on the cell edge between inside and outside of the disk
        let (x_edge, z) = (cell(&g, 19, 9).0, cell(&g, 19, 9).1 + 0.25);
        let p = m.pixel(x_edge, z);
        let near: Vec<RGBColor> = (-1..=1).map(|d| px(&img, (p.0, p.1 + d as f64))).collect();
        assert!(near.contains(&RGBColor(255, 64, 64)), "{near:?}");
        // a wrong size or range is refused
        let short = BmodePanel { title: "t".into(), grid: g, image: &image[1..], dr: 50.0 };
        assert!(bmode_figure(dir.path(), "", "B", &short, None).is_err());
        let bad = BmodePanel { title: "t".into(), grid: g, image: &image, dr: f64::NAN };
        assert!(bmode_figure(dir.path(), "", "B", &bad, None).is_err());
    }

    #[test]
    fn transmit_fields_draw_each_cell_in_its_level_colour() {
        let dir = tempfile::tempdir().unwrap();
        let n = 40;
        let g = grid(n as u32);
        // levels −1 dB per column: 0 … −39 dB; a second panel at −50 dB everywhere (below the range)
        let ramp: Vec<f32> = (0..n * n).map(|i| -((i % n) as f32)).collect();
        let low = vec![-50.0f32; n * n];
        let panels = [
            FieldPanel { title: "tx 0°".into(), grid: g, db: &ramp },
            FieldPanel { title: "tx 10°".into(), grid: g, db: &low },
        ];
        let (fig, maps) = transmit_fields_mapped(dir.path(), "", "fields", &panels).unwrap();
        assert_eq!(fig.path, "figures/transmit_fields.png");
        let img = decode(&dir.path().join(&fig.path));
        assert_eq!((img.0, img.1), (fig.width, fig.height));
        for (ix, iz) in [(0, 0), (10, 5), (39, 20)] {
            let (x, z) = cell(&g, ix, iz);
            assert_eq!(px(&img, maps[0].pixel(x, z)), field_colour(-(ix as f64)), "cell ({ix}, {iz})");
            assert_eq!(px(&img, maps[1].pixel(x, z)), speed_colour(0.0), "below −40 dB: the darkest colour");
        }
        assert_eq!(field_colour(0.0), speed_colour(1.0));
        let bad = FieldPanel { title: "t".into(), grid: g, db: &ramp[1..] };
        assert!(transmit_fields(dir.path(), "", "f", &[bad]).is_err());
        assert!(transmit_fields(dir.path(), "", "f", &[]).is_err());
    }

    #[test]
    fn vector_field_colours_the_true_speed_inside_and_draws_arrows() {
        let dir = tempfile::tempdir().unwrap();
        let n = 40;
        let g = grid(n as u32);
        let mask = disk(n);
        // Solid-body rotation inside the disk, zero outside.
        let (mut tvx, mut tvz) = (vec![0.0f32; n * n], vec![0.0f32; n * n]);
        for i in 0..n * n {
            if mask[i] > 0.5 {
                let (x, z) = ((i % n) as f32 - 19.5, (i / n) as f32 - 19.5);
                tvx[i] = -0.05 * z;
                tvz[i] = 0.05 * x;
            }
        }
        let zero = vec![0.0f32; n * n];
        let panels = [
            VectorPanel { name: "zero estimate".into(), vx: &zero, vz: &zero, flags: None },
            VectorPanel { name: "exact".into(), vx: &tvx, vz: &tvz, flags: None },
        ];
        let (fig, maps) = vector_field_mapped(dir.path(), "lbl", "vectors", &g, (&tvx, &tvz, &mask), &panels).unwrap();
        assert_eq!(fig.path, "figures/vector_field-lbl.png", "a labelled evaluator's file");
        let img = decode(&dir.path().join(&fig.path));
        assert_eq!((img.0, img.1), (fig.width, fig.height));
        let speed = |i: usize| (tvx[i] as f64).hypot(tvz[i] as f64);
        let v_max = (0..n * n).filter(|i| mask[*i] > 0.5).map(speed).fold(0.0, f64::max);
        // Zero estimate: no arrows, the cells show the colour map.
        for (ix, iz) in [(19, 19), (25, 14), (12, 26), (28, 20)] {
            let i = iz * n + ix;
            let c = cell(&g, ix, iz);
            let want = speed_colour(speed(i) / v_max);
            assert_eq!(px(&img, maps[0].pixel(c.0, c.1)), want, "cell ({ix}, {iz})");
        }
        let c = cell(&g, 1, 1);
        assert_eq!(px(&img, maps[0].pixel(c.0, c.1)), OUTSIDE);
        // Exact estimate: an arrow from the sampled cell (step 3 → cells 1, 4, …; cell (28, 19)
        // moves +z): a dark grey (anti-aliased black) pixel on its shaft one cell below the tail,
        // where the colour map has no grey.
        let step = arrow_step(n, n);
        assert_eq!(step, 3);
        let (ix, iz) = (28, 19);
        assert_eq!((ix % step, iz % step), (step / 2, step / 2));
        let dark = |c: &RGBColor| c.0 == c.1 && c.1 == c.2 && c.0 < 160;
        let tail = cell(&g, ix, iz);
        let shaft = maps[1].pixel(tail.0, tail.1 + g.dz * 1e3);
        let around: Vec<RGBColor> = (-1..=1).map(|d| px(&img, (shaft.0 + d as f64, shaft.1))).collect();
        assert!(around.iter().any(dark), "{around:?}");
        // … and none in the zero panel at the same place.
        let shaft0 = maps[0].pixel(tail.0, tail.1 + g.dz * 1e3);
        let around0: Vec<RGBColor> = (-1..=1).map(|d| px(&img, (shaft0.0 + d as f64, shaft0.1))).collect();
        assert!(!around0.iter().any(dark), "{around0:?}");
    }

    #[test]
    fn stage_chart_has_one_bar_pair_per_node_of_the_right_length() {
        let dir = tempfile::tempdir().unwrap();
        let rows: Vec<StageRow> =
            [("flow", 0.2, 1.0), ("simus", 1.5, 2.0), ("beamformer", 0.8, 2.1), ("doppler", 0.05, 2.2)]
                .iter()
                .map(|(n, c, w)| StageRow { name: n.to_string(), compute_s: Some(*c), wall_s: Some(*w) })
                .chain(std::iter::once(StageRow { name: "external".into(), compute_s: None, wall_s: None }))
                .collect();
        let (fig, maps) = stage_times_mapped(dir.path(), "stages", &rows).unwrap();
        let img = decode(&dir.path().join(&fig.path));
        assert_eq!((img.0, img.1), (fig.width, fig.height));
        let m = maps[0];
        // Bands of the compute colour down a column near the axis: one per node with stats.
        let (x, _) = m.pixel(0.02, 0.0);
        let mut bands = [0usize; 2];
        let mut prev = [false; 2];
        for y in 0..img.1 {
            let c = px(&img, (x, y as f64));
            for (k, col) in [BAR, BAR2].iter().enumerate() {
                let on = c == *col;
                if on && !prev[k] {
                    bands[k] += 1;
                }
                prev[k] = on;
            }
        }
        assert_eq!(bands, [4, 4], "compute and wall bands (the legend's swatches are in the title row)");
        // The legend's swatches, in the title row.
        let legend: Vec<RGBColor> = (0..img.0).map(|x| px(&img, (x as f64, 18.0))).collect();
        assert!(legend.contains(&BAR) && legend.contains(&BAR2));
        let n = rows.len() as f64;
        for (k, r) in rows.iter().enumerate().take(4) {
            let yc = n - k as f64 - 0.5;
            let (c, w) = (r.compute_s.unwrap(), r.wall_s.unwrap());
            assert_eq!(px(&img, m.pixel(c - 0.03, yc + 0.2)), BAR, "{}", r.name);
            assert_ne!(px(&img, m.pixel(c + 0.03, yc + 0.2)), BAR, "{}", r.name);
            assert_eq!(px(&img, m.pixel(w - 0.03, yc - 0.2)), BAR2, "{}", r.name);
            assert_ne!(px(&img, m.pixel(w + 0.03, yc - 0.2)), BAR2, "{}", r.name);
        }
        // The node without statistics has no bar.
        assert_ne!(px(&img, m.pixel(0.02, 0.5 + 0.2)), BAR);
    }

    #[test]
    fn bad_input_is_an_error_not_a_panic() {
        let dir = tempfile::tempdir().unwrap();
        let g = grid(10);
        let short = vec![0.0f32; 50];
        let e = vector_field(dir.path(), "", "v", &g, (&short, &short, &short), &[]).unwrap_err();
        assert!(e.to_string().contains("50 values for a 10 × 10 grid"), "{e}");
        let e = doppler_maps(dir.path(), "", "d", &[], None).unwrap_err();
        assert!(e.to_string().contains("no Doppler maps"));
        assert!(error_histograms(dir.path(), "", "e", &[]).is_err());
        assert!(stage_times(dir.path(), "s", &[]).is_err());
        let w = guarded("boom", || -> anyhow::Result<()> { panic!("kaboom") }).unwrap_err();
        assert!(w.contains("figure boom") && w.contains("kaboom"), "{w}");
        assert!(!dir.path().join(DIR).join(VECTORS).exists());
    }
}
