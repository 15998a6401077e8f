//! The evaluation of a run: estimated vector fields and Doppler looks against the ground truth,
//! per packet and pooled (paper 1's error measure, [`crate::metrics`]), `evaluation.json` /
//! `evaluation.md`, and the evaluation's figures (colour Doppler maps, vectors over the true
//! speed, error histograms; [`crate::figures`]). Several evaluations in one run (e.g. two
//! estimators side by side) each get a `label`: their files are then `evaluation-<label>.json` /
//! `.md` and `figures/<name>-<label>.png`.

use crate::figures::{self, Figure};
use crate::metrics::{field_error_samples, look_error, look_error_samples, FieldError, LookError, PixelGrid, Samples};
use serde::{Deserialize, Serialize};
use sonoflow_messages::{
    plane, DopplerMapHeaderV2, GridV1, VectorFieldHeaderV2, CLUTTER_IIR, CLUTTER_NONE, CLUTTER_POLYNOMIAL, CLUTTER_SVD,
};
use std::collections::BTreeMap;
use std::fmt::Write as _;

/// `evaluator` parameters.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct EvaluatorParams {
    /// Pixels count when the truth mask covers their whole (2·margin+1)² neighbourhood (0 ..= 10).
    pub margin: usize,
    /// Names this evaluation (e.g. the estimator it judges): files `evaluation-<label>.json/.md`,
    /// the label in the report's heading and log lines. Empty (default): `evaluation.json/.md`.
    /// Letters, digits, `-` and `_` only (≤ 64).
    pub label: String,
    /// Draw the report's figures into `<run>/figures/` at the end (default true).
    pub figures: bool,
    /// Dynamic range (dB) of the B-mode figure drawn from the `iq` input, in [1, 120]. Default 40
    /// (MUST `bmode`'s).
    pub bmode_dr: f64,
}

impl Default for EvaluatorParams {
    fn default() -> Self {
        Self { margin: 2, label: String::new(), figures: true, bmode_dr: 40.0 }
    }
}

impl EvaluatorParams {
    /// File stem of this evaluator's output: `evaluation` or `evaluation-<label>`.
    pub fn stem(&self) -> String {
        if self.label.is_empty() {
            "evaluation".to_string()
        } else {
            format!("evaluation-{}", self.label)
        }
    }

    /// Checks every field; the error names it and the allowed range.
    pub fn validate(&self) -> Result<(), String> {
        if self.margin > 10 {
            return Err(format!("margin = {} is out of range: 0 ..= 10", self.margin));
        }
        if !(self.bmode_dr.is_finite() && (1.0..=120.0).contains(&self.bmode_dr)) {
            return Err(format!("bmode_dr = {} is out of range: [1, 120] dB", self.bmode_dr));
        }
        if self.label.len() > 64 || !self.label.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_') {
            return Err(format!(
                "label = {:?} is not allowed: up to 64 letters, digits, `-` or `_` (it names the files evaluation-<label>.json/.md)",
                self.label
            ));
        }
        Ok(())
    }
}

/// One evaluated packet.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PacketEval {
    pub packet: u32,
    pub t_valid: f64,
    /// Field name (`raw`, `regularised`) → errors.
    pub fields: BTreeMap<String, FieldError>,
}

/// What the evaluator writes to `evaluation.json`.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Evaluation {
    /// The evaluator's `label` (empty: the graph's only evaluation).
    #[serde(default)]
    pub label: String,
    pub margin: usize,
    pub packets: Vec<PacketEval>,
    /// Per field, all packets pooled: the errors of every evaluated pixel of every packet (each
    /// relative to its packet's v_max); `pixels`/`no_estimate` summed, `v_max` the largest.
    #[serde(default)]
    pub overall: BTreeMap<String, FieldError>,
    /// Per look (transmit tilt, receive angle, band) of the `maps` input, all packets pooled: the
    /// error of its Doppler velocity against the truth projected on its direction (maps that
    /// carry `projection_x`/`projection_z` planes; empty without `maps`).
    #[serde(default)]
    pub looks: Vec<LookError>,
    /// Figures written into `<run>/figures/` (paths relative to the run folder).
    #[serde(default)]
    pub figures: Vec<Figure>,
    /// Figures that could not be drawn, and why.
    #[serde(default)]
    pub warnings: Vec<String>,
    /// The clutter filters the Doppler maps report (from their headers; empty without maps or
    /// without a clutter filter).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub clutter: Vec<ClutterUse>,
    /// Per estimated field (`raw`, `regularised`, …): the clutter filter its headers report (the
    /// looks' filter, which a regularised field passes on) and the looks used and left out; only
    /// fields made with a clutter filter or with looks left out. Here `maps` counts the field's
    /// messages (packets).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub field_clutter: BTreeMap<String, FieldClutter>,
}

/// How one estimated field was made, from its headers: the looks' clutter filter and the looks
/// the vector solve used and left out.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FieldClutter {
    /// The filter (`None` without one); `maps` counts the field's packets.
    pub filter: Option<ClutterUse>,
    /// Looks per packet (largest over the packets).
    pub looks: u32,
    /// Looks left out of the vector solve, summed over the packets.
    pub rejected_looks: u32,
}

impl FieldClutter {
    /// Adds one field header (ground truth and fields without looks add nothing).
    pub fn tally(fields: &mut BTreeMap<String, FieldClutter>, name: &str, h: &VectorFieldHeaderV2) {
        if h.n_looks == 0 && h.clutter_filter == CLUTTER_NONE {
            return;
        }
        let f = fields.entry(name.to_string()).or_default();
        f.looks = f.looks.max(h.n_looks);
        f.rejected_looks += h.rejected_looks;
        let mut uses: Vec<ClutterUse> = f.filter.take().into_iter().collect();
        ClutterUse::tally_one(&mut uses, h.clutter_filter, h.clutter_order, h.clutter_cutoff, h.clutter_removed_energy);
        f.filter = uses.pop();
    }

    /// One line for the report.
    pub fn describe(&self, name: &str) -> String {
        let filter = match &self.filter {
            Some(u) => format!("clutter filter {}", u.describe().replace(" maps)", " packets)")),
            None => "no clutter filter".to_string(),
        };
        let looks = match (self.looks, self.rejected_looks) {
            (0, _) => String::new(),
            (n, 0) => format!("; {n} looks, none left out"),
            (n, r) => format!("; {n} looks, {r} left out over the packets (look rejection)"),
        };
        format!("`{name}`: {filter}{looks}")
    }
}

/// One clutter filter as the Doppler maps of a run report it.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ClutterUse {
    /// `polynomial`, `iir` or `svd`.
    pub filter: String,
    /// IIR cut-off or the adaptive SVD's tissue cut-off (fraction of the PRF); 0 otherwise.
    pub cutoff: f64,
    /// Smallest and largest polynomial degree, IIR order or SVD rank over the maps.
    pub order_min: u32,
    pub order_max: u32,
    /// Mean fraction of the packet energy removed (SVD; 0 otherwise).
    pub removed_energy_mean: f64,
    /// Maps (looks × packets) counted.
    pub maps: usize,
}

impl ClutterUse {
    /// Adds one map's header to the tally in `uses` (nothing for maps without a clutter filter).
    pub fn tally(uses: &mut Vec<ClutterUse>, h: &DopplerMapHeaderV2) {
        Self::tally_one(uses, h.clutter_filter, h.clutter_order, h.clutter_cutoff, h.clutter_removed_energy)
    }

    /// Adds one message's filter (`CLUTTER_*`, order or rank, cut-off, energy removed) to the
    /// tally in `uses` (nothing for `CLUTTER_NONE`).
    pub fn tally_one(uses: &mut Vec<ClutterUse>, kind: u32, order: u32, cutoff: f64, removed_energy: f64) {
        let filter = match kind {
            CLUTTER_POLYNOMIAL => "polynomial",
            CLUTTER_IIR => "iir",
            CLUTTER_SVD => "svd",
            _ => return,
        };
        let i = match uses.iter().position(|u| u.filter == filter && u.cutoff == cutoff) {
            Some(i) => i,
            None => {
                let u = ClutterUse { filter: filter.into(), cutoff, order_min: u32::MAX, ..Default::default() };
                uses.push(u);
                uses.len() - 1
            }
        };
        let u = &mut uses[i];
        u.order_min = u.order_min.min(order);
        u.order_max = u.order_max.max(order);
        u.removed_energy_mean += (removed_energy - u.removed_energy_mean) / (u.maps + 1) as f64;
        u.maps += 1;
    }

    /// One line for the report.
    pub fn describe(&self) -> String {
        let what = match self.filter.as_str() {
            "polynomial" => "degree",
            "iir" => "order",
            _ => "rank",
        };
        let range = if self.order_min == self.order_max {
            format!("{what} {}", self.order_min)
        } else {
            format!("{what} {}–{}", self.order_min, self.order_max)
        };
        let cutoff = if self.cutoff > 0.0 { format!(", cut-off {:.3} PRF", self.cutoff) } else { String::new() };
        let removed = if self.filter == "svd" {
            format!(", {:.1} % of the energy removed on average", 100.0 * self.removed_energy_mean)
        } else {
            String::new()
        };
        format!("{} ({range}{cutoff}{removed}; {} maps)", self.filter, self.maps)
    }
}

/// A vector field message: header and planes.
pub type Field = (VectorFieldHeaderV2, Vec<f32>);
/// A Doppler map message: header and planes.
pub type Map = (DopplerMapHeaderV2, Vec<f32>);

/// Plane `id` of a payload of `n_planes` planes on `grid`, as listed in `plane_ids`.
pub fn find_plane<'a>(
    grid: &GridV1,
    n_planes: u32,
    plane_ids: &[u32; 8],
    data: &'a [f32],
    id: u32,
) -> Option<&'a [f32]> {
    let n = grid.nx as usize * grid.nz as usize;
    let np = (n_planes as usize).min(plane_ids.len());
    let k = plane_ids[..np].iter().position(|&p| p == id)?;
    data.get(k * n..(k + 1) * n)
}

pub fn plane_of<'a>(h: &VectorFieldHeaderV2, data: &'a [f32], id: u32) -> Option<&'a [f32]> {
    find_plane(&h.grid, h.n_planes, &h.plane_ids, data, id)
}

pub fn map_plane<'a>(h: &DopplerMapHeaderV2, data: &'a [f32], id: u32) -> Option<&'a [f32]> {
    find_plane(&h.grid, h.n_planes, &h.plane_ids, data, id)
}

/// One look's errors pooled over packets: (tx, rx, fc), errors, projected truths, pixels, pixels
/// without estimate.
pub type LookPool = ((f64, f64, f64), Vec<f64>, Vec<f64>, usize, usize);

/// Adds the per-look errors of `map` against `truth` to `pools` (keyed by the look). `Ok(false)`
/// when the map carries no projection planes (nothing to compare); an error when its grid is not
/// the truth's.
pub fn pool_look(
    pools: &mut BTreeMap<(u64, u64, u64), LookPool>,
    truth: &Field,
    map: &Map,
    margin: usize,
) -> anyhow::Result<bool> {
    let (th, tv) = truth;
    let (mh, md) = map;
    let (Some(vel), Some(px), Some(pz)) = (
        map_plane(mh, md, plane::VELOCITY),
        map_plane(mh, md, plane::PROJECTION_X),
        map_plane(mh, md, plane::PROJECTION_Z),
    ) else {
        return Ok(false);
    };
    if th.grid != mh.grid {
        anyhow::bail!(
            "packet {}: the Doppler map (rx {:.1}°) is not on the truth's grid: per-look errors need the same grid",
            mh.packet,
            mh.rx_angle.to_degrees()
        );
    }
    let need = |id: u32| {
        plane_of(th, tv, id)
            .ok_or_else(|| anyhow::anyhow!("truth of packet {} has no `{}` plane", th.packet, plane::name(id)))
    };
    let grid = PixelGrid { nx: th.grid.nx as usize, nz: th.grid.nz as usize, dx: th.grid.dx, dz: th.grid.dz };
    let (e, t, pixels, no_estimate) = look_error_samples(
        (need(plane::VX)?, need(plane::VZ)?, need(plane::MASK)?),
        (vel, map_plane(mh, md, plane::FLAGS), px, pz),
        grid,
        margin,
    );
    let key = (mh.tx_angle.to_bits(), mh.rx_angle.to_bits(), mh.fc.to_bits());
    let pool = pools.entry(key).or_insert_with(|| ((mh.tx_angle, mh.rx_angle, mh.fc), Vec::new(), Vec::new(), 0, 0));
    pool.1.extend(e);
    pool.2.extend(t);
    pool.3 += pixels;
    pool.4 += no_estimate;
    Ok(true)
}

/// The pooled per-look errors, by band then receive angle.
pub fn looks(pools: BTreeMap<(u64, u64, u64), LookPool>) -> Vec<LookError> {
    let mut out: Vec<LookError> =
        pools.into_values().map(|(look, e, t, pixels, no_est)| look_error(look, &e, &t, pixels, no_est)).collect();
    out.sort_by(|a, b| {
        a.fc.total_cmp(&b.fc)
            .then(a.rx_angle_deg.total_cmp(&b.rx_angle_deg))
            .then(a.tx_angle_deg.total_cmp(&b.tx_angle_deg))
    });
    out
}

/// Errors of `est` against `truth` (same grid required).
pub fn evaluate_pair(truth: &Field, est: &Field, margin: usize) -> anyhow::Result<FieldError> {
    evaluate_pair_samples(truth, est, margin).map(|r| r.0)
}

/// [`evaluate_pair`] with the per-pixel samples (for the histograms and the pooled figures).
pub fn evaluate_pair_samples(truth: &Field, est: &Field, margin: usize) -> anyhow::Result<(FieldError, Samples)> {
    let (th, tv) = truth;
    let (eh, ev) = est;
    if th.grid != eh.grid {
        anyhow::bail!("packet {}: the estimate's grid differs from the truth's grid", th.packet);
    }
    let need = |h: &VectorFieldHeaderV2, d: &'_ [f32], id: u32, what: &str| -> anyhow::Result<Vec<f32>> {
        plane_of(h, d, id)
            .map(<[f32]>::to_vec)
            .ok_or_else(|| anyhow::anyhow!("{what} field of packet {} has no `{}` plane", h.packet, plane::name(id)))
    };
    let (tvx, tvz, mask) =
        (need(th, tv, plane::VX, "truth")?, need(th, tv, plane::VZ, "truth")?, need(th, tv, plane::MASK, "truth")?);
    let (vx, vz) = (need(eh, ev, plane::VX, "estimated")?, need(eh, ev, plane::VZ, "estimated")?);
    let flags = plane_of(eh, ev, plane::FLAGS);
    let grid = PixelGrid { nx: th.grid.nx as usize, nz: th.grid.nz as usize, dx: th.grid.dx, dz: th.grid.dz };
    Ok(field_error_samples((&tvx, &tvz, &mask), (&vx, &vz, flags), grid, margin))
}

/// What the evaluator keeps for its figures.
#[derive(Default)]
pub struct FigureData {
    /// Per field, the errors pooled over all evaluated packets.
    pub samples: BTreeMap<String, (Vec<f64>, Vec<f64>)>,
    /// Packet evaluated last (the highest number), its truth and estimates.
    pub last: Option<(u32, Field, BTreeMap<String, Field>)>,
    /// Colour Doppler maps by packet (the most recent few).
    pub maps: BTreeMap<u32, Vec<Map>>,
    /// B-mode images by packet (the most recent few), each the first frame of a packet's look
    /// nearest to normal incidence.
    pub bmodes: BTreeMap<u32, Bmode>,
}

/// A B-mode image for the report: its title, grid, MUST `bmode` bytes and dynamic range (dB).
#[derive(Clone, Debug)]
pub struct Bmode {
    pub title: String,
    pub grid: GridV1,
    pub image: Vec<u8>,
    pub dr: f64,
}

impl FigureData {
    pub fn keep_estimate(&mut self, packet: u32, truth: &Field, name: &str, est: Field) {
        match &mut self.last {
            Some((p, _, fields)) if *p == packet => {
                fields.insert(name.to_string(), est);
            }
            Some((p, _, _)) if *p > packet => {}
            _ => self.last = Some((packet, truth.clone(), BTreeMap::from([(name.to_string(), est)]))),
        }
    }

    /// Keeps a packet's B-mode image (the most recent 4 packets).
    pub fn keep_bmode(&mut self, packet: u32, b: Bmode) {
        self.bmodes.insert(packet, b);
        while self.bmodes.len() > 4 {
            self.bmodes.pop_first();
        }
    }

    pub fn keep_map(&mut self, m: Map) {
        self.maps.entry(m.0.packet).or_default().push(m);
        while self.maps.len() > 4 {
            self.maps.pop_first();
        }
    }
}

/// Draws the evaluator's figures into `dir/figures/` (file names and headings carry a non-empty
/// `label`): (figures written, warnings).
pub fn write_figures(
    dir: &std::path::Path,
    data: &FigureData,
    n_packets: usize,
    label: &str,
) -> (Vec<Figure>, Vec<String>) {
    let (mut figs, mut warns) = (Vec::new(), Vec::new());
    let tag = if label.is_empty() { String::new() } else { format!(" — {label}") };
    let mut keep = |r: Result<Figure, String>| match r {
        Ok(f) => figs.push(f),
        Err(w) => warns.push(w),
    };
    let last = data.last.as_ref();
    // Colour Doppler maps: the last evaluated packet's, else the latest received.
    let maps = last.and_then(|(p, _, _)| data.maps.get_key_value(p)).or_else(|| data.maps.last_key_value());
    if let Some((packet, maps)) = maps {
        keep(figures::guarded("doppler maps", || {
            let mut maps: Vec<&Map> = maps.iter().collect();
            maps.sort_by(|a, b| {
                (a.0.fc, a.0.tx_angle, a.0.rx_angle)
                    .partial_cmp(&(b.0.fc, b.0.tx_angle, b.0.rx_angle))
                    .unwrap_or(std::cmp::Ordering::Equal)
            });
            // Looks in more than one band (the beamformer's per-angle demod_fc): name the band.
            let bands = maps.iter().any(|m| m.0.fc.to_bits() != maps[0].0.fc.to_bits());
            // degrees: whole ones without decimals, −7.5 as such (not rounded to −8)
            let deg = |r: f64| {
                let d = r.to_degrees();
                let a = d.abs();
                let a = if (a - a.round()).abs() < 0.05 { format!("{a:.0}") } else { format!("{a:.1}") };
                if d < 0.0 && a != "0" {
                    format!("-{a}")
                } else {
                    a
                }
            };
            let panels: Vec<figures::DopplerPanel> = maps
                .iter()
                .map(|(h, d)| {
                    let plane = |id: u32| map_plane(h, d, id);
                    let velocity = plane(plane::VELOCITY)
                        .ok_or_else(|| anyhow::anyhow!("map of packet {} has no `velocity` plane", h.packet))?;
                    Ok(figures::DopplerPanel {
                        title: format!(
                            "tx {}°, rx {}{}°{}",
                            deg(h.tx_angle),
                            if deg(h.rx_angle).starts_with('-') { "" } else { "+" },
                            deg(h.rx_angle),
                            if bands { format!(", {:.1} MHz", h.fc / 1e6) } else { String::new() }
                        )
                        .replace('-', "−"),
                        grid: h.grid,
                        velocity,
                        power: plane(plane::POWER),
                        flags: plane(plane::FLAGS),
                        nyquist: h.nyquist_velocity,
                    })
                })
                .collect::<anyhow::Result<_>>()?;
            // The vessel outline when the truth of that packet is on the maps' grid.
            let outline = last
                .filter(|(p, t, _)| p == packet && maps.first().is_some_and(|m| m.0.grid == t.0.grid))
                .and_then(|(_, t, _)| plane_of(&t.0, &t.1, plane::MASK));
            figures::doppler_maps(dir, label, &format!("Colour Doppler, packet {packet}{tag}"), &panels, outline)
        }));
    }
    // B-mode: the packet of the Doppler maps (else the last evaluated, else the latest).
    let want = maps.map(|(p, _)| *p).or(last.map(|(p, _, _)| *p));
    let bmode = want.and_then(|p| data.bmodes.get_key_value(&p)).or_else(|| data.bmodes.last_key_value());
    if let Some((packet, b)) = bmode {
        keep(figures::guarded("bmode", || {
            let outline = last
                .filter(|(p, t, _)| p == packet && t.0.grid == b.grid)
                .and_then(|(_, t, _)| plane_of(&t.0, &t.1, plane::MASK));
            let panel = figures::BmodePanel { title: b.title.clone(), grid: b.grid, image: &b.image, dr: b.dr };
            figures::bmode_figure(dir, label, &format!("B-mode, packet {packet}{tag}"), &panel, outline)
        }));
    }
    if let Some((packet, truth, fields)) = last {
        keep(figures::guarded("vector field", || {
            let (th, tv) = truth;
            let need = |id: u32| {
                plane_of(th, tv, id).ok_or_else(|| anyhow::anyhow!("truth has no `{}` plane", plane::name(id)))
            };
            let (tvx, tvz, mask) = (need(plane::VX)?, need(plane::VZ)?, need(plane::MASK)?);
            let mut panels = Vec::new();
            for (name, (h, d)) in fields {
                if h.grid != th.grid {
                    continue;
                }
                if let (Some(vx), Some(vz)) = (plane_of(h, d, plane::VX), plane_of(h, d, plane::VZ)) {
                    panels.push(figures::VectorPanel {
                        name: name.clone(),
                        vx,
                        vz,
                        flags: plane_of(h, d, plane::FLAGS),
                    });
                }
            }
            figures::vector_field(
                dir,
                label,
                &format!(
                    "Estimated vectors over the true speed, packet {packet} (t = {:.4} s){tag}",
                    th.common.t_valid
                ),
                &th.grid,
                (tvx, tvz, mask),
                &panels,
            )
        }));
    }
    if !data.samples.is_empty() {
        keep(figures::guarded("error histograms", || {
            let fields: Vec<figures::ErrorSample> = data
                .samples
                .iter()
                .map(|(name, (ex, ez))| figures::ErrorSample { name: name.clone(), ex, ez })
                .collect();
            let pooled = if n_packets == 1 { "1 packet".to_string() } else { format!("{n_packets} packets pooled") };
            figures::error_histograms(dir, label, &format!("Errors against ground truth ({pooled}){tag}"), &fields)
        }));
    }
    (figs, warns)
}

/// Markdown table of an evaluation (also used by the report).
pub fn markdown(e: &Evaluation) -> String {
    let mut s = String::new();
    if e.label.is_empty() {
        let _ = writeln!(s, "## Error against ground truth\n");
    } else {
        let _ = writeln!(s, "## Error against ground truth: `{}`\n", e.label);
    }
    let _ = writeln!(
        s,
        "Per packet, errors of vx and vz as fractions of the largest true speed, over the pixels inside the vessel (mask eroded by {} px); |e|₇₅: 75 % of the pixels are within ±this.\n",
        e.margin
    );
    let _ = writeln!(s, "| packet | field | pixels | no estimate | v_max (m/s) | x: bias | x: RMS | x: \\|e\\|₇₅ | x: ≤ 10 % | z: bias | z: RMS | z: \\|e\\|₇₅ | z: ≤ 2 % |");
    let _ = writeln!(s, "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    let rows = e.packets.iter().flat_map(|p| p.fields.iter().map(|(n, f)| (p.packet.to_string(), n, f)));
    let all =
        if e.packets.len() > 1 { e.overall.iter().map(|(n, f)| ("all".to_string(), n, f)).collect() } else { vec![] };
    {
        for (packet, name, f) in rows.chain(all) {
            let _ = writeln!(
                s,
                "| {} | {name} | {} | {} | {:.3} | {:+.1} % | {:.1} % | {:.1} % | {:.0} % | {:+.1} % | {:.1} % | {:.1} % | {:.0} % |",
                packet,
                f.pixels,
                f.no_estimate,
                f.v_max,
                100.0 * f.x.bias,
                100.0 * f.x.rms,
                100.0 * f.x.abs_p75,
                100.0 * f.x.within_10pct,
                100.0 * f.z.bias,
                100.0 * f.z.rms,
                100.0 * f.z.abs_p75,
                100.0 * f.z.within_2pct,
            );
        }
    }
    // where the error is: all packets pooled (or the only packet)
    let located: Vec<(&String, &FieldError)> = if e.packets.len() > 1 {
        e.overall.iter().collect()
    } else {
        e.packets.iter().flat_map(|p| p.fields.iter()).collect()
    };
    if located.iter().any(|(_, f)| !f.by_wall_distance.is_empty()) {
        let _ = writeln!(
            s,
            "\nWhere the error is ({}): by distance to the vessel wall (from the pixel to the nearest pixel outside the vessel). Gain: the slope of the estimate against the truth (Σ v·v_true / Σ v_true²; 1: no scale error). A velocity blurred over a resolution cell reads gain > 1 near the walls and < 1 in the centre.\n",
            if e.packets.len() > 1 { "all packets pooled" } else { "the packet" }
        );
        let _ = writeln!(s, "| field | distance to wall | pixels | x: bias | x: \\|e\\|₇₅ | x: gain | z: bias | z: \\|e\\|₇₅ | z: gain |");
        let _ = writeln!(s, "|---|---|---:|---:|---:|---:|---:|---:|---:|");
        let g = |v: Option<f64>| v.map_or("—".to_string(), |v| format!("{v:.3}"));
        for (name, f) in located {
            for b in &f.by_wall_distance {
                let range = match b.to_m {
                    Some(t) => format!("{:.0}–{:.0} mm", 1e3 * b.from_m, 1e3 * t),
                    None => format!("≥ {:.0} mm", 1e3 * b.from_m),
                };
                let _ = writeln!(
                    s,
                    "| {name} | {range} | {} | {:+.1} % | {:.1} % | {} | {:+.1} % | {:.1} % | {} |",
                    b.pixels,
                    100.0 * b.x.bias,
                    100.0 * b.x.abs_p75,
                    g(b.x.gain),
                    100.0 * b.z.bias,
                    100.0 * b.z.abs_p75,
                    g(b.z.gain)
                );
            }
            let _ = writeln!(
                s,
                "| {name} | all | {} | {:+.1} % | {:.1} % | {} | {:+.1} % | {:.1} % | {} |",
                f.pixels - f.no_estimate,
                100.0 * f.x.bias,
                100.0 * f.x.abs_p75,
                g(f.gain_x),
                100.0 * f.z.bias,
                100.0 * f.z.abs_p75,
                g(f.gain_z)
            );
        }
    }
    for c in &e.clutter {
        let _ = writeln!(s, "\nClutter filter: {}.", c.describe());
    }
    if !e.field_clutter.is_empty() {
        let _ = writeln!(s, "\nHow the fields were made (their headers):\n");
        for (name, f) in &e.field_clutter {
            let _ = writeln!(s, "- {}.", f.describe(name));
        }
    }
    if !e.looks.is_empty() {
        let _ = writeln!(
            s,
            "\nPer look ({}): each look's Doppler velocity against the true velocity projected on its direction (the map's projection vector), in % of v_max, before the vector solve mixes the looks. Gain below 1: the look under-reads (e.g. blur, or the echoes' mean frequency below the demodulation frequency); above 1: over-reads.\n",
            if e.packets.len() > 1 { "all packets pooled" } else { "the packet" }
        );
        let _ = writeln!(s, "| tx | rx | fc (MHz) | pixels | bias | RMS | \\|e\\|₇₅ | gain |");
        let _ = writeln!(s, "|---:|---:|---:|---:|---:|---:|---:|---:|");
        // angles to 0.01° without trailing zeros (−3.75°, 7.5°, 0°)
        let deg = |a: f64| {
            let r = (a * 100.0).round() / 100.0;
            format!("{}", if r == 0.0 { 0.0 } else { r })
        };
        for l in &e.looks {
            let _ = writeln!(
                s,
                "| {}° | {}° | {:.2} | {} | {:+.2} % | {:.2} % | {:.2} % | {} |",
                deg(l.tx_angle_deg),
                deg(l.rx_angle_deg),
                l.fc / 1e6,
                l.pixels - l.no_estimate,
                100.0 * l.error.bias,
                100.0 * l.error.rms,
                100.0 * l.error.abs_p75,
                l.gain.map_or("—".to_string(), |g| format!("{g:.3}"))
            );
        }
    }
    s
}

/// One field's errors pooled over packets: the samples of every evaluated pixel, pixels, pixels
/// without estimate, the largest v_max.
pub type Pooled = (Samples, usize, usize, f64);

/// Adds one packet's evaluation of a field to its pool.
pub fn pool(into: &mut Pooled, fe: &FieldError, samples: &Samples) {
    into.0.append(samples);
    (into.1, into.2, into.3) = (into.1 + fe.pixels, into.2 + fe.no_estimate, into.3.max(fe.v_max));
}

/// Overall errors per field from the pooled samples (see [`Evaluation::overall`]).
pub fn overall(pooled: BTreeMap<String, Pooled>) -> BTreeMap<String, FieldError> {
    pooled
        .into_iter()
        .map(|(name, (smp, pixels, no_estimate, v_max))| (name, smp.field_error(pixels, no_estimate, v_max)))
        .collect()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use sonoflow_messages::GridV1;

    fn field(grid: GridV1, packet: u32, planes: &[(u32, Vec<f32>)]) -> Field {
        let mut h = VectorFieldHeaderV2 { grid, packet, n_planes: planes.len() as u32, ..Default::default() };
        for (k, (id, _)) in planes.iter().enumerate() {
            h.plane_ids[k] = *id;
        }
        (h, planes.iter().flat_map(|(_, d)| d.iter().copied()).collect())
    }

    #[test]
    fn figures_of_the_last_packet_and_a_bad_map_is_a_warning() {
        let dir = tempfile::tempdir().unwrap();
        let grid = GridV1 { x0: -0.005, z0: 0.01, dx: 0.25e-3, dz: 0.25e-3, nx: 41, nz: 41 };
        let n = 41 * 41;
        let mask: Vec<f32> = (0..n).map(|i: usize| if (i / 41).abs_diff(20) < 8 { 1.0 } else { 0.0 }).collect();
        let vx: Vec<f32> = mask.iter().map(|m| 0.4 * m).collect();
        let zero = vec![0.0f32; n];
        let truth = field(grid, 3, &[(plane::VX, vx.clone()), (plane::VZ, zero.clone()), (plane::MASK, mask)]);
        let noisy: Vec<f32> = vx.iter().enumerate().map(|(i, v)| v + 0.02 * ((i % 7) as f32 - 3.0)).collect();
        let mut fig = FigureData::default();
        for (packet, name, est) in [(2, "raw", &noisy), (3, "raw", &noisy), (3, "regularised", &vx), (1, "raw", &vx)] {
            let e = field(grid, packet, &[(plane::VX, est.clone()), (plane::VZ, zero.clone())]);
            let (_, Samples { ex, ez, .. }) = evaluate_pair_samples(&truth, &e, 2).unwrap();
            let s = fig.samples.entry(name.to_string()).or_default();
            s.0.extend(ex);
            s.1.extend(ez);
            fig.keep_estimate(packet, &truth, name, e);
        }
        // Kept: packet 3 with both fields (packet 1 arrived late and is older).
        let (p, _, fields) = fig.last.as_ref().unwrap();
        assert_eq!(
            (*p, fields.keys().cloned().collect::<Vec<_>>()),
            (3, vec!["raw".to_string(), "regularised".into()])
        );
        // A map without a velocity plane: the Doppler figure fails, the others are drawn.
        let mut mh = DopplerMapHeaderV2 { grid, packet: 3, n_planes: 1, nyquist_velocity: 0.77, ..Default::default() };
        mh.plane_ids[0] = plane::POWER;
        fig.keep_map((mh, vec![1.0; n]));
        let (figs, warns) = write_figures(dir.path(), &fig, 3, "");
        let paths: Vec<&str> = figs.iter().map(|f| f.path.as_str()).collect();
        assert_eq!(paths, ["figures/vector_field.png", "figures/error_histograms.png"]);
        assert!(figs[1].title.contains("3 packets pooled"), "{}", figs[1].title);
        assert_eq!(warns.len(), 1);
        assert!(warns[0].contains("figure doppler maps") && warns[0].contains("no `velocity` plane"), "{warns:?}");
        assert!(dir.path().join("figures/vector_field.png").is_file());
        assert!(!dir.path().join("figures/doppler_maps.png").exists());
        // Maps of more than 4 packets: the oldest are dropped.
        for p in 4..10 {
            fig.keep_map((DopplerMapHeaderV2 { packet: p, ..Default::default() }, Vec::new()));
        }
        assert_eq!(fig.maps.keys().copied().collect::<Vec<_>>(), [6, 7, 8, 9]);
    }

    #[test]
    fn overall_pools_the_pixels_of_every_packet() {
        let grid = GridV1 { x0: -0.005, z0: 0.01, dx: 0.25e-3, dz: 0.25e-3, nx: 21, nz: 21 };
        let n = 21 * 21;
        let mask: Vec<f32> = (0..n).map(|i: usize| if (i / 21).abs_diff(10) < 6 { 1.0 } else { 0.0 }).collect();
        let vx: Vec<f32> = mask.iter().map(|m| 0.5 * m).collect();
        let zero = vec![0.0f32; n];
        let truth = |packet| {
            field(grid, packet, &[(plane::VX, vx.clone()), (plane::VZ, zero.clone()), (plane::MASK, mask.clone())])
        };
        // packet 0 reads vx 1 % of v_max high everywhere, packet 1 3 % low
        let mut pooled: BTreeMap<String, Pooled> = BTreeMap::new();
        let mut per_packet = Vec::new();
        for (packet, off) in [(0u32, 0.005f32), (1, -0.015)] {
            let est: Vec<f32> = vx.iter().map(|v| v + off).collect();
            let e = field(grid, packet, &[(plane::VX, est), (plane::VZ, zero.clone())]);
            let (fe, smp) = evaluate_pair_samples(&truth(packet), &e, 2).unwrap();
            pool(pooled.entry("raw".into()).or_default(), &fe, &smp);
            per_packet.push((fe, smp));
        }
        let one = overall(BTreeMap::from([("raw".to_string(), {
            let (fe, smp) = &per_packet[0];
            (smp.clone(), fe.pixels, fe.no_estimate, fe.v_max)
        })]));
        let per_packet: Vec<FieldError> = per_packet.into_iter().map(|p| p.0).collect();
        // one packet: exactly that packet's statistics
        assert_eq!(one["raw"], per_packet[0]);
        let all = overall(pooled);
        let o = &all["raw"];
        assert_eq!(o.pixels, per_packet[0].pixels + per_packet[1].pixels);
        assert!(o.pixels > 100);
        // equal pixel counts: the pooled bias is the mean of +1 % and −3 %, half the pixels within ±2 %
        assert!((o.x.bias - (-0.01)).abs() < 1e-6, "{}", o.x.bias);
        assert!((o.x.within_2pct - 0.5).abs() < 1e-9, "{}", o.x.within_2pct);
        assert!((o.x.abs_p75 - 0.03).abs() < 1e-6, "{}", o.x.abs_p75);
        let md = markdown(&Evaluation { packets: vec![], overall: all, ..Default::default() });
        assert!(!md.contains("| all |"), "a single or no packet has no overall row");
    }

    /// Per-look errors: a look reading 5 % high has gain 1.05 and its bias is 5 % of the mean
    /// projected truth; the two looks (steered ±15°, per-pixel projections that vary over the
    /// grid) are kept apart and pooled over packets; a map without projection planes is skipped,
    /// one on another grid is an error.
    #[test]
    fn per_look_errors_against_the_projected_truth() {
        let grid = GridV1 { x0: -0.004, z0: 0.01, dx: 0.25e-3, dz: 0.25e-3, nx: 33, nz: 25 };
        let (nx, n) = (33usize, 33 * 25);
        let mask: Vec<f32> = (0..n).map(|i: usize| if (i / nx).abs_diff(12) < 8 { 1.0 } else { 0.0 }).collect();
        // a sheared flow: vx varies with depth, vz with x
        let tvx: Vec<f32> = (0..n).map(|i| mask[i] * (0.1 + 0.02 * (i / nx) as f32)).collect();
        let tvz: Vec<f32> = (0..n).map(|i| mask[i] * 0.002 * (i % nx) as f32).collect();
        let truth = |packet| {
            field(grid, packet, &[(plane::VX, tvx.clone()), (plane::VZ, tvz.clone()), (plane::MASK, mask.clone())])
        };
        let map = |packet: u32, rx_deg: f64, scale: f32, with_projection: bool| -> Map {
            // nominal plane-wave projection of a 0° transmit and receive angle rx: −(sin tx + sin rx, cos tx + cos rx)/2
            let rx = rx_deg.to_radians();
            let a = [-rx.sin() / 2.0, -(1.0 + rx.cos()) / 2.0];
            // a projection that varies over the grid, as the per-pixel aperture's does
            let px: Vec<f32> = (0..n).map(|i| a[0] as f32 * (1.0 + 0.001 * (i % nx) as f32)).collect();
            let pz: Vec<f32> = (0..n).map(|i| a[1] as f32 * (1.0 - 0.001 * (i / nx) as f32)).collect();
            let vel: Vec<f32> = (0..n).map(|i| scale * (px[i] * tvx[i] + pz[i] * tvz[i])).collect();
            let mut h =
                DopplerMapHeaderV2 { grid, packet, rx_angle: rx_deg.to_radians(), fc: 5e6, ..Default::default() };
            let mut planes: Vec<(u32, Vec<f32>)> = vec![(plane::VELOCITY, vel), (plane::POWER, vec![1.0; n])];
            if with_projection {
                planes.extend([(plane::PROJECTION_X, px), (plane::PROJECTION_Z, pz)]);
            }
            h.n_planes = planes.len() as u32;
            for (k, (id, _)) in planes.iter().enumerate() {
                h.plane_ids[k] = *id;
            }
            (h, planes.into_iter().flat_map(|(_, d)| d).collect())
        };
        let mut pools = BTreeMap::new();
        for packet in [0u32, 1] {
            assert!(pool_look(&mut pools, &truth(packet), &map(packet, -15.0, 1.05, true), 2).unwrap());
            assert!(pool_look(&mut pools, &truth(packet), &map(packet, 15.0, 1.0, true), 2).unwrap());
            assert!(!pool_look(&mut pools, &truth(packet), &map(packet, 0.0, 1.0, false), 2).unwrap());
        }
        let out = looks(pools);
        assert_eq!(out.len(), 2);
        let (minus, plus) = (&out[0], &out[1]);
        assert_eq!((minus.rx_angle_deg.round(), plus.rx_angle_deg.round()), (-15.0, 15.0));
        // counted pixels: rows 5..=19 inside, eroded by 2 → rows 7..=17 (11), columns 2..=30 (29), two packets
        assert_eq!(minus.pixels, 2 * 11 * 29);
        assert_eq!(minus.no_estimate, 0);
        assert!((minus.gain.unwrap() - 1.05).abs() < 1e-5, "{:?}", minus.gain);
        assert!((plus.gain.unwrap() - 1.0).abs() < 1e-6, "{:?}", plus.gain);
        assert!(plus.error.abs_p75 < 1e-6 && plus.error.bias.abs() < 1e-6, "{:?}", plus.error);
        // bias of the 5 % look = 0.05 × mean projected truth / v_max, computed independently
        let v_max =
            (0..n).filter(|&i| mask[i] > 0.5).map(|i| f64::from(tvx[i]).hypot(f64::from(tvz[i]))).fold(0.0, f64::max);
        let (h, d) = map(0, -15.0, 1.0, true);
        let proj = |i: usize| f64::from(d[2 * n + i]) * f64::from(tvx[i]) + f64::from(d[3 * n + i]) * f64::from(tvz[i]);
        let counted: Vec<usize> = (7..=17).flat_map(|iz| (2..=30).map(move |ix| iz * nx + ix)).collect();
        let want = 0.05 * counted.iter().map(|&i| proj(i)).sum::<f64>() / counted.len() as f64 / v_max;
        assert!((minus.error.bias - want).abs() < 1e-6, "{} vs {want}", minus.error.bias);
        assert!(want.abs() > 1e-3);
        // the report's table
        let md = markdown(&Evaluation { looks: out.clone(), ..Default::default() });
        assert!(md.contains("Per look") && md.contains("| 0° | -15° | 5.00 |") && md.contains("1.050"), "{md}");
        // a map on another grid
        let mut other = (h, d);
        other.0.grid.nx = 11;
        let e = pool_look(&mut BTreeMap::new(), &truth(0), &other, 2).unwrap_err().to_string();
        assert!(e.contains("not on the truth's grid"), "{e}");
    }
}
