//! `regulariser` node: raw vector fields → regularised vector fields with the `sonoflow-regularise`
//! library (Garcia's robust, unsupervised `smoothn`; paper 1 after eq 20). Thin: parameters,
//! plane bookkeeping, publish.
//!
//! * The velocity planes (`vx`, `vz`) are smoothed jointly (one S, shared robust weights), on the
//!   message's grid with its spacing (`dz`, `dx`) — the field is `(nz, nx)` row-major.
//! * Weights: a `weight` plane (quality in [0, 1]) from the estimator is used as smoothn weights
//!   (`weights = "auto"`, the default, when present); `weights = "power"` uses the slow-time power
//!   plane instead (smoothn normalises weights by their maximum). A `flags`
//!   plane's "no estimate" bit and non-finite velocities make a pixel missing (weight 0): the
//!   smoother fills it.
//! * With `mask = true` (default) and a `mask` plane present, pixels outside the mask are missing
//!   on input and 0 on output.
//! * Other planes (mask, weight, power, …) are passed through unchanged. The output header carries
//!   the S used, the outlier fraction (robust weight < 0.5) and whether smoothn converged.
//!
//! * `method = "divergence-free"` replaces smoothn by the stream-function fit of
//!   `sonoflow_regularise::divfree` (2-D continuity holds exactly; S by block cross-validation,
//!   noise ratio σx/σz estimated, robust), parameters in the `divergence_free` table. Its data
//!   weights are those above times a **power mask**: pixels whose `power` plane is more than
//!   `power_mask_db` (default −15 dB) below its 99th percentile are missing (no blood there; the
//!   fit extends the flow smoothly over them). The S of the previous frame starts the search of
//!   the next.
//!
//! The smoothing workspace is reused while the grid stays the same (no allocation per frame).
//! Compute time per message is process CPU time (smoothn uses rayon for the two components).

use serde::{Deserialize, Serialize};
use sonoflow_messages::types::VectorField;
use sonoflow_messages::MessageType::*;
use sonoflow_messages::{plane, MsgHeaderV1, VectorFieldHeaderV1, MAX_PLANES, VECTOR_REGULARISED};
use sonoflow_node_kit::parse_params;
use sonoflow_node_kit::PortDir::*;
use sonoflow_node_kit::{for_each, Flow};
use sonoflow_node_kit::{port, KindSpec};
use sonoflow_node_kit::{process_cpu_ns, Kit};

/// The `regulariser` node kind.
pub const SPEC: KindSpec = KindSpec {
        name: "regulariser",
        about: "robust unsupervised smoothing of vector fields (Garcia's smoothn): raw → regularised, with the S used and the outlier fraction",
        ports: &[port("raw", In, VectorFieldV1, true), port("regularised", Out, VectorFieldV1, true)],
        dynamic_inputs: false,
        dynamic_outputs: false,
        validate,
        check_wiring: None,
        input_files: &[],
        run,
};
use sonoflow_regularise::{
    wall_from_power, DivFree, DivFreeParams, Flavour, NoSlipParams, Smoothn, SmoothnParams, WeightFunction,
};

/// Which regulariser.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Garcia's robust smoothn (paper 1), the default.
    #[default]
    Smoothn,
    /// Stream-function fit: exactly divergence-free (2-D continuity), each component weighted by
    /// its noise level.
    DivergenceFree,
}

/// Where the smoothn weights come from.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum WeightSource {
    /// The `weight` plane (quality in [0, 1]) if present, else uniform.
    Auto,
    /// Uniform weights (missing values still get weight 0).
    None,
    /// The `weight` plane (an error if a message has none).
    Weight,
    /// The `power` plane (an error if a message has none), normalised by its maximum.
    Power,
}

/// `regulariser` node parameters (the smoothn ones are named as in `SmoothnParams`).
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct RegulariserParams {
    /// Smoothing parameter S (> 0); absent: chosen per frame by generalised cross-validation.
    pub s: Option<f64>,
    /// Penalty order: 1, 2 or 3.
    pub order: u32,
    /// Robust (iteratively re-weighted) smoothing, as paper 1 uses. Default true.
    pub robust: bool,
    /// Robust weight function: bisquare, cauchy or talworth.
    pub weight_function: WeightFunction,
    /// Relative tolerance on the smoothed field between iterations, in (0, 1).
    pub tol_z: f64,
    /// Iteration limit per robust pass (≥ 1).
    pub max_iter: u32,
    /// `matlab` (default) or `pymust`.
    pub flavour: Flavour,
    /// Weight source.
    pub weights: WeightSource,
    /// Treat pixels outside the `mask` plane as missing and zero them on output.
    pub mask: bool,
    /// `smoothn` (default) or `divergence-free`.
    pub method: Method,
    /// Parameters of the divergence-free fit (`method = "divergence-free"`): `s` (absent: block
    /// cross-validation), `order` (2, 3), `noise_ratio` (absent: estimated), `robust`,
    /// `weight_function`, `selection` (`block-cv`, `gcv`), `cv_block` (pixels), `gcv_probes`.
    pub divergence_free: DivFreeParams,
    /// Power mask of the divergence-free fit: pixels with `power` more than this many dB below the
    /// frame's 99th percentile are missing. In [−100, 0]; default −15.
    pub power_mask_db: f64,
    /// No-slip wall of the divergence-free fit (absent: off; `no_slip = {}`: on with the
    /// defaults): pixels whose smoothed power is `threshold_db` (−5) below the blood's median get
    /// a zero-velocity prior of `weight` (3); `smoothing` (0.4 mm) is the σ of the power's
    /// smoothing. Needs the `power` plane.
    pub no_slip: Option<NoSlipParams>,
}

impl Default for RegulariserParams {
    fn default() -> Self {
        let d = SmoothnParams::default();
        Self {
            s: d.s,
            order: d.order,
            robust: true,
            weight_function: d.weight_function,
            tol_z: d.tol_z,
            max_iter: d.max_iter,
            flavour: d.flavour,
            weights: WeightSource::Auto,
            mask: true,
            method: Method::Smoothn,
            divergence_free: DivFreeParams::default(),
            power_mask_db: -15.0,
            no_slip: None,
        }
    }
}

impl RegulariserParams {
    /// Checks every field (smoothn's and the divergence-free fit's).
    pub fn check(&self) -> Result<(), String> {
        self.smoothn(None).validate().map_err(|e| e.to_string())?;
        self.divergence_free.validate().map_err(|e| format!("divergence_free: {e}"))?;
        if !(self.power_mask_db.is_finite() && (-100.0..=0.0).contains(&self.power_mask_db)) {
            return Err(format!("power_mask_db = {} is out of range: -100 ..= 0 dB", self.power_mask_db));
        }
        if let Some(ns) = &self.no_slip {
            ns.validate().map_err(|e| e.to_string())?;
        }
        Ok(())
    }

    /// The library parameters for a grid with spacing (dz, dx).
    pub fn smoothn(&self, spacing: Option<[f64; 2]>) -> SmoothnParams {
        SmoothnParams {
            s: self.s,
            order: self.order,
            robust: self.robust,
            weight_function: self.weight_function,
            tol_z: self.tol_z,
            max_iter: self.max_iter,
            spacing: spacing.map(|s| s.to_vec()),
            flavour: self.flavour,
        }
    }
}

pub fn validate(v: &serde_json::Value) -> Result<(), String> {
    parse_params::<RegulariserParams>(v)?.check()
}

/// The output of a frame with no usable data: zero velocities, no S, not converged.
fn nothing_measured(
    mut oh: VectorFieldHeaderV1,
    planes_out: &mut [f32],
    velocity_planes: [usize; 2],
    n: usize,
) -> VectorFieldHeaderV1 {
    for i in velocity_planes {
        planes_out[i * n..(i + 1) * n].fill(0.0);
    }
    oh.smoothing_s = 0.0;
    oh.outlier_fraction = 0.0;
    oh.converged = 0;
    oh
}

/// Where a plane id sits in a header's plane list.
fn find_plane(ids: &[u32], id: u32) -> Option<usize> {
    ids.iter().position(|&p| p == id)
}

/// What the node does with one frame, independent of IPC (used by the node and by tests).
pub struct Regulariser {
    params: RegulariserParams,
    ws: Option<Smoothn>,
    /// Divergence-free fitter of the current grid (shape, spacing bits) and the last S.
    df: Option<([usize; 2], [u64; 2], DivFree)>,
    last_s: Option<f64>,
    data: Vec<f64>,
    weights: Vec<f64>,
    out: Vec<f64>,
}

impl Regulariser {
    pub fn new(params: RegulariserParams) -> Result<Self, String> {
        params.check()?;
        Ok(Self { params, ws: None, df: None, last_s: None, data: Vec::new(), weights: Vec::new(), out: Vec::new() })
    }

    /// Regularises one vector field message (header + planes) into `planes_out` (same layout and
    /// plane order as the input); returns the output header.
    pub fn process(
        &mut self,
        h: &VectorFieldHeaderV1,
        planes: &[f32],
        planes_out: &mut Vec<f32>,
    ) -> anyhow::Result<VectorFieldHeaderV1> {
        let (nx, nz) = (h.grid.nx as usize, h.grid.nz as usize);
        let n = nx * nz;
        let np = h.n_planes as usize;
        if np == 0 || np > MAX_PLANES || n == 0 || planes.len() != np * n {
            anyhow::bail!(
                "vector field frame {}: {} planes of {nz}×{nx} need {} values, got {} (n_planes must be 1 ..= {MAX_PLANES})",
                h.common.frame_id,
                np,
                np * n,
                planes.len()
            );
        }
        let ids = &h.plane_ids[..np];
        let (Some(ivx), Some(ivz)) = (find_plane(ids, plane::VX), find_plane(ids, plane::VZ)) else {
            anyhow::bail!(
                "vector field frame {} has planes {:?}: the regulariser needs `vx` and `vz`",
                h.common.frame_id,
                ids.iter().map(|&i| plane::name(i)).collect::<Vec<_>>()
            );
        };
        let plane_of = |i: usize| &planes[i * n..(i + 1) * n];
        let wsrc = match self.params.weights {
            WeightSource::None => None,
            WeightSource::Auto => find_plane(ids, plane::WEIGHT),
            WeightSource::Weight => Some(find_plane(ids, plane::WEIGHT).ok_or_else(|| {
                anyhow::anyhow!("weights = \"weight\" but frame {} has no `weight` plane", h.common.frame_id)
            })?),
            WeightSource::Power => Some(find_plane(ids, plane::POWER).ok_or_else(|| {
                anyhow::anyhow!("weights = \"power\" but frame {} has no `power` plane", h.common.frame_id)
            })?),
        };
        let mask = if self.params.mask { find_plane(ids, plane::MASK).map(plane_of) } else { None };
        let flags = find_plane(ids, plane::FLAGS).map(plane_of);

        self.data.clear();
        self.data.extend(plane_of(ivx).iter().map(|&v| v as f64));
        self.data.extend(plane_of(ivz).iter().map(|&v| v as f64));
        self.weights.clear();
        match wsrc {
            Some(i) => {
                self.weights.extend(plane_of(i).iter().map(|&w| if w.is_finite() && w > 0.0 { w as f64 } else { 0.0 }))
            }
            None => self.weights.resize(n, 1.0),
        }
        for i in 0..n {
            let outside = mask.is_some_and(|m| m[i] <= 0.5);
            let no_estimate = flags.is_some_and(|f| (f[i] as u32) & 1 != 0);
            if outside || no_estimate {
                self.weights[i] = 0.0;
            }
        }
        let any_weight = self.weights.iter().any(|&w| w > 0.0);
        let valid = (0..n).any(|i| self.weights[i] > 0.0 && self.data[i].is_finite() && self.data[n + i].is_finite());
        planes_out.clear();
        planes_out.extend_from_slice(planes);
        let mut oh = *h;
        oh.common = MsgHeaderV1 { frame_id: h.common.frame_id, t_valid: h.common.t_valid, ..Default::default() };
        oh.source = VECTOR_REGULARISED;
        if !(any_weight && valid) {
            // Nothing measured (e.g. an empty mask or every pixel flagged): zero velocities, no S.
            return Ok(nothing_measured(oh, planes_out, [ivx, ivz], n));
        }
        let shape = [nz, nx];
        if self.params.method == Method::DivergenceFree {
            return self.divergence_free(h, planes, ids, ivx, ivz, mask, planes_out, oh);
        }
        if self.ws.as_ref().is_none_or(|w| w.shape() != shape) {
            self.ws = Some(Smoothn::new(&shape, 2)?);
        }
        let Some(ws) = self.ws.as_mut() else { anyhow::bail!("no smoothing workspace") };
        let spacing = (h.grid.dx > 0.0 && h.grid.dz > 0.0).then_some([h.grid.dz, h.grid.dx]);
        let sp = self.params.smoothn(spacing);
        self.out.resize(2 * n, 0.0);
        let all_one = self.weights.iter().all(|&w| w == 1.0);
        let report = ws.smooth(&self.data, (!all_one).then_some(&self.weights[..]), &sp, &mut self.out)?;
        for i in 0..n {
            let outside = mask.is_some_and(|m| m[i] <= 0.5);
            let (vx, vz) = if outside { (0.0, 0.0) } else { (self.out[i] as f32, self.out[n + i] as f32) };
            planes_out[ivx * n + i] = vx;
            planes_out[ivz * n + i] = vz;
        }
        oh.smoothing_s = report.s;
        oh.outlier_fraction = report.outlier_fraction;
        oh.converged = report.converged as u32;
        Ok(oh)
    }
}

impl Regulariser {
    /// The divergence-free fit of one frame (weights already in `self.weights`).
    #[allow(clippy::too_many_arguments)]
    fn divergence_free(
        &mut self,
        h: &VectorFieldHeaderV1,
        planes: &[f32],
        ids: &[u32],
        ivx: usize,
        ivz: usize,
        mask: Option<&[f32]>,
        planes_out: &mut [f32],
        mut oh: VectorFieldHeaderV1,
    ) -> anyhow::Result<VectorFieldHeaderV1> {
        let (nx, nz) = (h.grid.nx as usize, h.grid.nz as usize);
        let n = nx * nz;
        let (dz, dx) = (h.grid.dz, h.grid.dx);
        if !(dz.is_finite() && dz > 0.0 && dx.is_finite() && dx > 0.0) {
            anyhow::bail!("vector field frame {}: grid spacing dz = {dz}, dx = {dx} must be > 0", h.common.frame_id);
        }
        // Power mask: no blood where the power is far below the frame's 99th percentile.
        if let Some(ip) = find_plane(ids, plane::POWER) {
            let pw = &planes[ip * n..(ip + 1) * n];
            let mut sorted: Vec<f32> = pw.iter().copied().filter(|v| v.is_finite()).collect();
            sorted.sort_by(f32::total_cmp);
            let p99 = sorted.get(((sorted.len() as f64 - 1.0) * 0.99).round() as usize).copied().unwrap_or(0.0);
            let floor = f64::from(p99) * 10f64.powf(self.params.power_mask_db / 10.0);
            for (w, p) in self.weights.iter_mut().zip(pw) {
                if !(p.is_finite() && f64::from(*p) >= floor) {
                    *w = 0.0;
                }
            }
        }
        // No-slip wall: outside the lumen the velocity is pulled to zero (not data).
        let mut prior = None;
        if let Some(ns) = &self.params.no_slip {
            let Some(ip) = find_plane(ids, plane::POWER) else {
                anyhow::bail!(
                    "vector field frame {}: regulariser.no_slip needs the `power` plane (the doppler node writes it)",
                    h.common.frame_id
                );
            };
            let pw: Vec<f64> = planes[ip * n..(ip + 1) * n].iter().map(|v| f64::from(*v)).collect();
            let blood: Vec<bool> = self.weights.iter().map(|w| *w > 0.0).collect();
            let wall = wall_from_power(&pw, &blood, [nz, nx], [dz, dx], ns)?;
            for (w, out) in self.weights.iter_mut().zip(&wall) {
                if *out {
                    *w = 0.0;
                }
            }
            prior = Some(wall.iter().map(|out| if *out { ns.weight } else { 0.0 }).collect::<Vec<f64>>());
        }
        let dp = &self.params.divergence_free;
        let key = ([nz, nx], [dz.to_bits(), dx.to_bits()]);
        if self.df.as_ref().is_none_or(|(s, sp, f)| (*s, *sp) != key || f.order() != dp.order) {
            self.df = Some((key.0, key.1, DivFree::new([nz, nx], [dz, dx], dp.order)?));
        }
        let Some((_, _, df)) = self.df.as_ref() else { anyhow::bail!("no divergence-free fitter") };
        let (ux, uz) = self.data.split_at(n);
        let (mut vx, mut vz) = (vec![0.0; n], vec![0.0; n]);
        let report =
            match df.fit_with_wall(ux, uz, Some(&self.weights), prior.as_deref(), dp, self.last_s, &mut vx, &mut vz) {
                Ok(r) => r,
                Err(sonoflow_regularise::DivFreeError::NoData) => {
                    return Ok(nothing_measured(oh, planes_out, [ivx, ivz], n))
                }
                Err(e) => return Err(e.into()),
            };
        self.last_s = Some(report.s);
        for i in 0..n {
            let outside = mask.is_some_and(|m| m[i] <= 0.5);
            let (a, b) = if outside { (0.0, 0.0) } else { (vx[i] as f32, vz[i] as f32) };
            planes_out[ivx * n + i] = a;
            planes_out[ivz * n + i] = b;
        }
        oh.smoothing_s = report.s;
        oh.outlier_fraction = report.outlier_fraction;
        oh.converged = 1;
        Ok(oh)
    }
}

pub fn run(mut kit: Kit) -> anyhow::Result<()> {
    let p: RegulariserParams = parse_params(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    let mut reg = Regulariser::new(p).map_err(anyhow::Error::msg)?;
    let mut input = kit.input::<VectorField>("raw")?;
    let mut out = kit.output::<VectorField>("regularised")?;
    kit.handshake(&mut [&mut input, &mut out])?;
    let mut planes = Vec::new();
    let mut last_t = 0.0;
    let mut not_converged = 0u64;
    for_each(&mut kit, &mut input, |kit, sample| {
        let t0 = process_cpu_ns();
        let h = *sample.user_header();
        let oh = reg.process(&h, sample.payload(), &mut planes)?;
        if oh.converged == 0 && oh.smoothing_s > 0.0 {
            not_converged += 1;
            if not_converged == 1 {
                eprintln!(
                    "regulariser: frame {} did not converge within max_iter = {} (raise max_iter or tol_z); further cases counted in the stats",
                    h.common.frame_id, reg.params.max_iter
                );
            }
        }
        let compute = process_cpu_ns() - t0;
        let mut oh = oh;
        oh.common.compute_ns = compute;
        out.publish_copy(oh, &planes)?;
        kit.stats.messages_in += 1;
        kit.stats.messages_out += 1;
        kit.stats.bytes_out += (planes.len() * 4) as u64;
        kit.record(oh.common.frame_id, oh.common.t_valid, compute)?;
        last_t = oh.common.t_valid;
        Ok(Flow::Continue)
    })?;
    out.publish_eos(last_t)?;
    if not_converged > 0 {
        eprintln!("regulariser: {not_converged} frame(s) did not converge");
    }
    kit.stats.gaps = input.gaps;
    kit.finish()?;
    Ok(())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use sonoflow_messages::GridV1;

    fn field(nx: u32, nz: u32, ids: &[u32]) -> (VectorFieldHeaderV1, Vec<f32>) {
        let mut h = VectorFieldHeaderV1 {
            grid: GridV1 { x0: 0.0, z0: 0.0, dx: 1e-4, dz: 1e-4, nx, nz },
            n_planes: ids.len() as u32,
            ..Default::default()
        };
        h.plane_ids[..ids.len()].copy_from_slice(ids);
        let n = (nx * nz) as usize;
        let mut v = vec![0.0f32; ids.len() * n];
        for i in 0..n {
            v[i] = 0.1 + 0.001 * (i % nx as usize) as f32;
            v[n + i] = -0.2 + 0.002 * (i / nx as usize) as f32;
        }
        (h, v)
    }

    #[test]
    fn needs_vx_and_vz_planes() {
        let (h, v) = field(8, 6, &[plane::VX, plane::MASK]);
        let mut r = Regulariser::new(RegulariserParams::default()).unwrap();
        let e = r.process(&h, &v, &mut Vec::new()).unwrap_err().to_string();
        assert!(e.contains("needs `vx` and `vz`"), "{e}");
        let (h, v) = field(8, 6, &[plane::VX, plane::VZ]);
        let e = r.process(&h, &v[..10], &mut Vec::new()).unwrap_err().to_string();
        assert!(e.contains("need 96 values, got 10"), "{e}");
        let mut p = RegulariserParams { weights: WeightSource::Power, ..Default::default() };
        let e = Regulariser::new(p.clone()).unwrap().process(&h, &v, &mut Vec::new()).unwrap_err().to_string();
        assert!(e.contains("no `power` plane"), "{e}");
        p.order = 7;
        assert!(Regulariser::new(p).err().unwrap().contains("order"));
    }

    #[test]
    fn linear_field_is_kept_masked_pixels_zeroed_and_flagged_pixels_filled() {
        // A linear field is reproduced closely by order-2 smoothing with a small given S (the
        // reflective boundaries bend a plane slightly: measured 8e-4 m/s here, on a field that
        // spans 0.02 m/s); the flagged pixel's junk value (±50) is ignored and filled.
        let (h, mut v) = field(12, 10, &[plane::VX, plane::VZ, plane::MASK, plane::FLAGS]);
        let n = 120;
        let clean = v.clone();
        for i in 0..n {
            v[2 * n + i] = if i % 12 < 10 { 1.0 } else { 0.0 };
        }
        v[3 * n + 25] = 1.0; // no estimate: value is junk
        v[25] = 50.0;
        v[n + 25] = -50.0;
        let p = RegulariserParams { s: Some(0.5), robust: false, ..Default::default() };
        let mut r = Regulariser::new(p).unwrap();
        let mut out = Vec::new();
        let oh = r.process(&h, &v, &mut out).unwrap();
        assert_eq!((oh.source, oh.smoothing_s, oh.converged), (VECTOR_REGULARISED, 0.5, 1));
        for i in 0..n {
            if i % 12 >= 10 {
                assert_eq!((out[i], out[n + i]), (0.0, 0.0), "pixel {i} outside the mask");
            } else {
                assert!((out[i] - clean[i]).abs() < 2e-3 && (out[n + i] - clean[n + i]).abs() < 2e-3, "pixel {i}");
            }
        }
        assert_eq!(&out[2 * n..], &v[2 * n..], "mask and flags planes pass through");
    }

    #[test]
    fn nothing_measured_gives_zeros_not_nan() {
        let (h, mut v) = field(5, 4, &[plane::VX, plane::VZ, plane::MASK]);
        v[40..].fill(0.0); // empty mask
        let mut r = Regulariser::new(RegulariserParams::default()).unwrap();
        let mut out = Vec::new();
        let oh = r.process(&h, &v, &mut out).unwrap();
        assert!(out[..40].iter().all(|&x| x == 0.0));
        assert_eq!((oh.smoothing_s, oh.converged), (0.0, 0));
    }

    #[test]
    fn weight_plane_is_used_as_weights() {
        // Half the pixels carry a wrong value with weight 0: the result ignores them entirely.
        let (h, mut v) = field(10, 8, &[plane::VX, plane::VZ, plane::WEIGHT]);
        let n = 80;
        let reference = {
            let (h2, v2) = field(10, 8, &[plane::VX, plane::VZ]);
            let mut o = Vec::new();
            let p = RegulariserParams { s: Some(0.5), robust: false, ..Default::default() };
            Regulariser::new(p).unwrap().process(&h2, &v2, &mut o).unwrap();
            o
        };
        for i in 0..n {
            v[2 * n + i] = 1.0;
        }
        v[2 * n + 33] = 0.0;
        v[33] = 9.0;
        let p = RegulariserParams { s: Some(0.5), robust: false, ..Default::default() };
        let mut out = Vec::new();
        Regulariser::new(p).unwrap().process(&h, &v, &mut out).unwrap();
        let d = (out[33] - reference[33]).abs();
        assert!(d < 0.02, "weight-0 outlier leaked: {d}");
        let p = RegulariserParams { s: Some(0.5), robust: false, weights: WeightSource::None, ..Default::default() };
        Regulariser::new(p).unwrap().process(&h, &v, &mut out).unwrap();
        assert!((out[33] - reference[33]).abs() > 0.1, "without weights the outlier shows");
    }

    /// `method = "divergence-free"`: a horizontal Poiseuille channel with noisy data inside and
    /// junk (±3 m/s) where the power plane says there is no blood. The power mask keeps the junk
    /// out (error inside ≪ the junk); without it the junk leaks into a plain fit (the robust
    /// weights would also catch junk this gross); the output is divergence-free.
    #[test]
    fn divergence_free_method_uses_the_power_mask() {
        let (nx, nz) = (40u32, 30u32);
        let (h, mut v) = field(nx, nz, &[plane::VX, plane::VZ, plane::POWER]);
        let n = (nx * nz) as usize;
        let mut truth = vec![0.0f64; n];
        let mut state = 7u64;
        let mut noise = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for i in 0..n {
            let q = ((i / nx as usize) as f64 - 14.5) / 9.0;
            if q.abs() < 1.0 {
                truth[i] = 0.5 * (1.0 - q * q);
                v[i] = (truth[i] + 0.1 * noise()) as f32;
                v[n + i] = (0.015 * noise()) as f32;
                v[2 * n + i] = 1.0;
            } else {
                v[i] = if i % 2 == 0 { 3.0 } else { -3.0 };
                v[n + i] = -v[i];
                v[2 * n + i] = 1e-4; // −40 dB: no blood
            }
        }
        let err = |p: RegulariserParams| -> (f64, VectorFieldHeaderV1, Vec<f32>) {
            let mut out = Vec::new();
            let oh = Regulariser::new(p).unwrap().process(&h, &v, &mut out).unwrap();
            let inside: Vec<usize> = (0..n).filter(|&i| v[2 * n + i] == 1.0).collect();
            let e = inside.iter().map(|&i| (out[i] as f64 - truth[i]).abs()).sum::<f64>() / inside.len() as f64;
            (e, oh, out)
        };
        let plain = DivFreeParams { robust: false, ..Default::default() };
        let df = RegulariserParams { method: Method::DivergenceFree, divergence_free: plain, ..Default::default() };
        let (e_mask, oh, out) = err(df.clone());
        let (e_none, _, _) = err(RegulariserParams { power_mask_db: -100.0, ..df });
        assert!(oh.smoothing_s > 0.0 && oh.converged == 1);
        assert!(e_mask < 0.02 && e_none > 3.0 * e_mask, "mean |error| inside: masked {e_mask}, unmasked {e_none}");
        let vx: Vec<f64> = out[..n].iter().map(|&x| x as f64).collect();
        let vz: Vec<f64> = out[n..2 * n].iter().map(|&x| x as f64).collect();
        let d = sonoflow_regularise::divfree::divergence(&vx, &vz, [nz as usize, nx as usize], [1e-4, 1e-4]);
        // f32 output: divergence at the f32 rounding of velocities of 0.5 m/s over 1e-4 m
        assert!(d.iter().all(|x| x.abs() < 1e-2), "{:?}", d.iter().fold(0.0f64, |a, x| a.max(x.abs())));
        let e = validate(&serde_json::json!({"power_mask_db": 5.0})).unwrap_err();
        assert!(e.contains("power_mask_db") && e.contains("-100 ..= 0"), "{e}");
        let e = validate(&serde_json::json!({"divergence_free": {"cv_block": 1}})).unwrap_err();
        assert!(e.contains("cv_block"), "{e}");
    }

    /// `no_slip`: beyond the channel's walls the power is 8 dB below the blood (within the −15 dB
    /// mask, so those pixels are data) and the Doppler over-reads there (0.2 m/s, as blurred
    /// near-wall Doppler does). With the no-slip wall those pixels become a zero-velocity prior
    /// and the lumen's error drops; without a power plane it is a clear error; bad values are
    /// named.
    #[test]
    fn no_slip_wall_from_the_power_plane() {
        let (nx, nz) = (40u32, 40u32);
        let (h, mut v) = field(nx, nz, &[plane::VX, plane::VZ, plane::POWER]);
        let n = (nx * nz) as usize;
        let mut truth = vec![0.0f64; n];
        for i in 0..n {
            let q = ((i / nx as usize) as f64 - 19.5) / 10.0;
            if q.abs() < 1.0 {
                truth[i] = 0.5 * (1.0 - q * q);
                v[i] = truth[i] as f32;
                v[2 * n + i] = 1.0;
            } else {
                v[i] = 0.2;
                v[2 * n + i] = 10f32.powf(-0.8);
            }
        }
        let err = |p: RegulariserParams| -> f64 {
            let mut out = Vec::new();
            Regulariser::new(p).unwrap().process(&h, &v, &mut out).unwrap();
            let inside: Vec<usize> = (0..n).filter(|&i| v[2 * n + i] == 1.0).collect();
            (inside.iter().map(|&i| (out[i] as f64 - truth[i]).powi(2)).sum::<f64>() / inside.len() as f64).sqrt()
        };
        let df = RegulariserParams {
            method: Method::DivergenceFree,
            divergence_free: DivFreeParams { robust: false, s: Some(1.0), ..Default::default() },
            ..Default::default()
        };
        let e_plain = err(df.clone());
        let e_wall = err(RegulariserParams { no_slip: Some(NoSlipParams::default()), ..df.clone() });
        assert!(e_wall < 0.5 * e_plain, "RMS error in the lumen: {e_wall} with the wall, {e_plain} without");
        // no power plane: a clear error
        let (h2, v2) = field(nx, nz, &[plane::VX, plane::VZ]);
        let mut out = Vec::new();
        let p = RegulariserParams { no_slip: Some(NoSlipParams::default()), ..df };
        let e = Regulariser::new(p).unwrap().process(&h2, &v2, &mut out).unwrap_err().to_string();
        assert!(e.contains("no_slip") && e.contains("power"), "{e}");
        let e = validate(&serde_json::json!({"no_slip": {"threshold_db": 3.0}})).unwrap_err();
        assert!(e.contains("no_slip.threshold_db") && e.contains("−30 ..= −1"), "{e}");
        let e = validate(&serde_json::json!({"no_slip": {"wall": 3.0}})).unwrap_err();
        assert!(e.contains("wall"), "{e}");
    }
}
