//! One frame of a 2-D vector field, regularised: the glue between a field given as planes (`vx`,
//! `vz` and optional `weight`, `power`, `flags`, `mask` planes, each `(nz, nx)` row-major) and
//! [`Smoothn`] / [`DivFree`]. What the `regulariser` node does to each message, without IPC.
//!
//! * The velocity planes (`vx`, `vz`) are smoothed jointly (one S, shared robust weights) with
//!   the grid's spacing `(dz, dx)`.
//! * Weights: a `weight` plane (quality in [0, 1]) is used as smoothn weights (`weights = "auto"`,
//!   the default, when present); `weights = "power"` uses the slow-time power plane instead
//!   (smoothn normalises weights by their maximum). A `flags` plane's "no estimate" bit (1) and
//!   non-finite velocities make a pixel missing (weight 0): the smoother fills it.
//! * With `mask = true` (default) and a `mask` plane present, pixels outside the mask (≤ 0.5) are
//!   missing on input and 0 on output.
//! * Other planes are passed through unchanged. The report carries the S used, the outlier
//!   fraction (robust weight < 0.5) and whether smoothn converged.
//! * A frame without any usable pixel gives zero velocities, S = 0, not converged.
//! * `method = "divergence-free"` replaces smoothn by the stream-function fit of
//!   [`crate::divfree`] (2-D continuity holds exactly; S by block cross-validation, noise ratio
//!   σx/σz estimated, robust), parameters in the `divergence_free` table. Its data weights are
//!   those above times a **power mask**: pixels whose `power` plane is more than `power_mask_db`
//!   (default −15 dB) below its 99th percentile are missing (no blood there; the fit extends the
//!   flow smoothly over them). With `no_slip`, pixels outside the lumen found from the power
//!   ([`wall_from_power`]) become a zero-velocity prior. The S of the previous frame starts the
//!   search of the next.
//! * `no_slip` with smoothn (the paper's regulariser given sonoflow's lumen, for a fair
//!   baseline): the same power mask (missing data) and wall (missing, and zero on output, as
//!   outside a `mask` plane).
//!
//! [`FieldRegulariser`] keeps the smoothing workspace (and the divergence-free fitter) while the
//! grid stays the same: no allocation per frame for smoothn.

use serde::{Deserialize, Serialize};

use crate::{
    blood_from_power, wall_from_power, DivFree, DivFreeError, DivFreeParams, NoSlipParams, Smoothn, SmoothnError,
    SmoothnParams,
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
    /// The `weight` plane (an error if a field has none).
    Weight,
    /// The `power` plane (an error if a field has none), normalised by its maximum.
    Power,
}

/// Parameters of [`FieldRegulariser`] (the `regulariser` node's parameters). The smoothing is
/// [`SmoothnParams`] itself, whose fields stand at the top level of the table (`s`, `order`,
/// `robust`, `weight_function`, `tol_z`, `max_iter`, `flavour`; `spacing` is not a parameter:
/// it comes from each frame's grid). `robust` defaults to true here (paper 1 smooths robustly).
/// Every field has a default; unknown fields are rejected, and errors name the field.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(remote = "Self", deny_unknown_fields, default)]
pub struct RegulariserParams {
    /// The smoothn parameters (top-level keys of the table, see above).
    #[serde(skip)]
    pub smoothn: SmoothnParams,
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
    /// No-slip wall (absent: off; `no_slip = {}`: on with the defaults): pixels whose smoothed
    /// power is `threshold_db` (−5) below the blood's median get a zero-velocity prior of
    /// `weight` (3); `smoothing` (0.4 mm) is the σ of the power's smoothing. Needs the `power`
    /// plane. With smoothn it is sonoflow's lumen for the paper's regulariser: pixels below the
    /// power mask (`power_mask_db`) are missing (filled by the smoothing), pixels beyond the wall
    /// are missing and zero on output, as outside a `mask` plane (`weight` is not used).
    pub no_slip: Option<NoSlipParams>,
}

/// The keys of a `regulariser` table that belong to [`SmoothnParams`].
const SMOOTHN_KEYS: [&str; 7] = ["s", "order", "robust", "weight_function", "tol_z", "max_iter", "flavour"];

/// Deserialises `table` as `T`; an error is (path inside the table, message), as the node kit
/// reports them.
fn from_table<T: serde::de::DeserializeOwned>(
    table: serde_json::Map<String, serde_json::Value>,
) -> Result<T, (String, String)> {
    serde_path_to_error::deserialize(serde_json::Value::Object(table))
        .map_err(|e| (e.path().to_string(), e.inner().to_string()))
}

/// "path: message" (just the message at the top).
fn with_path((path, msg): (String, String)) -> String {
    if path == "." {
        msg
    } else {
        format!("{path}: {msg}")
    }
}

impl<'de> Deserialize<'de> for RegulariserParams {
    /// Splits the table into smoothn's keys (deserialised as [`SmoothnParams`], with
    /// `robust = true` unless given) and the rest (this struct's own fields).
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        let mut table = serde_json::Map::<String, serde_json::Value>::deserialize(d)?;
        let mut smoothn = serde_json::Map::new();
        smoothn.insert("robust".into(), true.into());
        for k in SMOOTHN_KEYS {
            if let Some(v) = table.remove(k) {
                smoothn.insert(k.into(), v);
            }
        }
        let own = from_table::<Own>(table).map_err(|(path, msg)| {
            let top_level_key = !path.contains(['.', '[']);
            if top_level_key && msg.starts_with("unknown field") {
                D::Error::custom(format!("{msg}, or one of smoothn's `{}`", SMOOTHN_KEYS.join("`, `")))
            } else {
                D::Error::custom(with_path((path, msg)))
            }
        })?;
        let smoothn = from_table(smoothn).map_err(|e| D::Error::custom(with_path(e)))?;
        Ok(Self { smoothn, ..own.0 })
    }
}

/// This struct's own fields, through the derived (remote) deserialiser.
struct Own(RegulariserParams);

impl<'de> Deserialize<'de> for Own {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        RegulariserParams::deserialize(d).map(Own)
    }
}

impl Default for RegulariserParams {
    fn default() -> Self {
        Self {
            smoothn: SmoothnParams { robust: true, ..SmoothnParams::default() },
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
    /// Checks every field (smoothn's and the divergence-free fit's); the error names the field.
    pub fn validate(&self) -> Result<(), FieldError> {
        self.smoothn(None).validate()?;
        self.divergence_free.validate().map_err(FieldError::DivergenceFreeParams)?;
        if !(self.power_mask_db.is_finite() && (-100.0..=0.0).contains(&self.power_mask_db)) {
            return Err(FieldError::PowerMaskDb(self.power_mask_db));
        }
        if let Some(ns) = &self.no_slip {
            ns.validate()?;
        }
        Ok(())
    }

    /// The smoothn parameters for a grid with spacing (dz, dx).
    pub fn smoothn(&self, spacing: Option<[f64; 2]>) -> SmoothnParams {
        SmoothnParams { spacing: spacing.map(|s| s.to_vec()), ..self.smoothn.clone() }
    }
}

/// What a plane of the field holds (planes without a role here pass through).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlaneRole {
    /// Lateral velocity component.
    Vx,
    /// Axial velocity component.
    Vz,
    /// Weight / quality in [0, 1].
    Weight,
    /// Slow-time (Doppler) power.
    Power,
    /// Bit flags per pixel (f32 integers); bit 1 = no estimate.
    Flags,
    /// 1 inside the fluid, 0 outside.
    Mask,
    /// Anything else: passed through.
    Other,
}

/// What the regularisation of one frame did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FieldReport {
    /// The smoothing parameter used (0 when nothing was measured).
    pub s: f64,
    /// Fraction of the data pixels with a robust weight < 0.5.
    pub outlier_fraction: f64,
    /// Whether smoothn converged (the divergence-free fit: always, unless nothing was measured).
    pub converged: bool,
}

/// Errors of [`FieldRegulariser`] and [`RegulariserParams::validate`].
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FieldError {
    /// A smoothn parameter is out of range, or smoothn failed.
    #[error(transparent)]
    Smoothn(#[from] SmoothnError),
    /// A parameter of the `divergence_free` table is out of range.
    #[error("divergence_free: {0}")]
    DivergenceFreeParams(DivFreeError),
    /// The divergence-free fit (or a `no_slip` parameter) failed.
    #[error(transparent)]
    DivFree(#[from] DivFreeError),
    /// `power_mask_db` is out of range.
    #[error("power_mask_db = {0} is out of range: -100 ..= 0 dB")]
    PowerMaskDb(f64),
    /// The planes do not match the grid.
    #[error("{planes} planes of {nz}×{nx} need {expected} values, got {got}")]
    Layout {
        /// Number of planes (roles).
        planes: usize,
        /// Grid rows.
        nz: usize,
        /// Grid columns.
        nx: usize,
        /// planes × nz × nx.
        expected: usize,
        /// Values given.
        got: usize,
    },
    /// No `vx` or no `vz` plane.
    #[error("the regulariser needs `vx` and `vz` planes")]
    NoVelocity,
    /// `weights = "weight"` / `"power"` but the plane is absent.
    #[error("weights = \"{0}\" but the field has no `{0}` plane")]
    NoWeightPlane(&'static str),
    /// `no_slip` without a `power` plane.
    #[error("no_slip needs the `power` plane (the doppler node writes it)")]
    NoSlipNeedsPower,
    /// The divergence-free fit needs a positive grid spacing.
    #[error("grid spacing dz = {dz}, dx = {dx} must be > 0")]
    Spacing {
        /// Axial spacing.
        dz: f64,
        /// Lateral spacing.
        dx: f64,
    },
}

/// Regularises the frames of a vector field one at a time (module doc); reuses its workspaces
/// while the grid stays the same.
pub struct FieldRegulariser {
    params: RegulariserParams,
    ws: Option<Smoothn>,
    /// Divergence-free fitter of the current grid (shape, spacing bits) and the last S.
    df: Option<([usize; 2], [u64; 2], DivFree)>,
    last_s: Option<f64>,
    data: Vec<f64>,
    weights: Vec<f64>,
    out: Vec<f64>,
}

/// Where a role first occurs in the plane list.
fn find(roles: &[PlaneRole], role: PlaneRole) -> Option<usize> {
    roles.iter().position(|&r| r == role)
}

/// Velocity planes `ivx`, `ivz` of `planes_out` from the fit, 0 outside the mask.
fn write_velocity(planes_out: &mut [f32], [ivx, ivz]: [usize; 2], mask: Option<&[f32]>, vx: &[f64], vz: &[f64]) {
    let n = vx.len();
    for i in 0..n {
        let outside = mask.is_some_and(|m| m[i] <= 0.5);
        let (a, b) = if outside { (0.0, 0.0) } else { (vx[i] as f32, vz[i] as f32) };
        planes_out[ivx * n + i] = a;
        planes_out[ivz * n + i] = b;
    }
}

/// The output of a frame with no usable data: zero velocities, no S, not converged.
fn nothing_measured(planes_out: &mut [f32], velocity_planes: [usize; 2], n: usize) -> FieldReport {
    for i in velocity_planes {
        planes_out[i * n..(i + 1) * n].fill(0.0);
    }
    FieldReport { s: 0.0, outlier_fraction: 0.0, converged: false }
}

impl FieldRegulariser {
    /// A regulariser with checked parameters.
    pub fn new(params: RegulariserParams) -> Result<Self, FieldError> {
        params.validate()?;
        Ok(Self { params, ws: None, df: None, last_s: None, data: Vec::new(), weights: Vec::new(), out: Vec::new() })
    }

    /// The parameters.
    pub fn params(&self) -> &RegulariserParams {
        &self.params
    }

    /// Regularises one frame: `planes` holds `roles.len()` planes of the `shape = [nz, nx]` grid
    /// (row-major, plane after plane) with spacing `[dz, dx]`. `planes_out` receives the same
    /// planes in the same order, `vx` and `vz` regularised (the first plane of each role counts).
    pub fn process(
        &mut self,
        shape: [usize; 2],
        spacing: [f64; 2],
        roles: &[PlaneRole],
        planes: &[f32],
        planes_out: &mut Vec<f32>,
    ) -> Result<FieldReport, FieldError> {
        let [nz, nx] = shape;
        let n = nx * nz;
        let np = roles.len();
        if np == 0 || n == 0 || planes.len() != np * n {
            return Err(FieldError::Layout { planes: np, nz, nx, expected: np * n, got: planes.len() });
        }
        let (Some(ivx), Some(ivz)) = (find(roles, PlaneRole::Vx), find(roles, PlaneRole::Vz)) else {
            return Err(FieldError::NoVelocity);
        };
        let plane_of = |i: usize| &planes[i * n..(i + 1) * n];
        let wsrc = match self.params.weights {
            WeightSource::None => None,
            WeightSource::Auto => find(roles, PlaneRole::Weight),
            WeightSource::Weight => Some(find(roles, PlaneRole::Weight).ok_or(FieldError::NoWeightPlane("weight"))?),
            WeightSource::Power => Some(find(roles, PlaneRole::Power).ok_or(FieldError::NoWeightPlane("power"))?),
        };
        let mask = if self.params.mask { find(roles, PlaneRole::Mask).map(plane_of) } else { None };
        let flags = find(roles, PlaneRole::Flags).map(plane_of);

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
        if !(any_weight && valid) {
            // Nothing measured (e.g. an empty mask or every pixel flagged): zero velocities, no S.
            return Ok(nothing_measured(planes_out, [ivx, ivz], n));
        }
        if self.params.method == Method::DivergenceFree {
            let power = find(roles, PlaneRole::Power).map(plane_of);
            return self.divergence_free(shape, spacing, power, [ivx, ivz], mask, planes_out);
        }
        // sonoflow's lumen for smoothn (`no_slip`): the divergence-free fit's power mask (missing
        // data) and wall (missing data, zero on output).
        let mut lumen: Option<Vec<f32>> = None;
        if let Some(ns) = self.params.no_slip.clone() {
            let Some(pw) = find(roles, PlaneRole::Power).map(plane_of) else {
                return Err(FieldError::NoSlipNeedsPower);
            };
            self.power_mask(pw);
            let wall = self.wall(pw, shape, spacing, &ns)?;
            let inside = |i: usize| !wall[i] && !mask.is_some_and(|m| m[i] <= 0.5);
            for (i, w) in self.weights.iter_mut().enumerate() {
                if !inside(i) {
                    *w = 0.0;
                }
            }
            if !self.weights.iter().any(|&w| w > 0.0) {
                return Ok(nothing_measured(planes_out, [ivx, ivz], n));
            }
            lumen = Some((0..n).map(|i| if inside(i) { 1.0 } else { 0.0 }).collect());
        }
        let ws = match &mut self.ws {
            Some(w) if w.shape() == shape => w,
            slot => slot.insert(Smoothn::new(&shape, 2)?),
        };
        let [dz, dx] = spacing;
        let sp = self.params.smoothn((dx > 0.0 && dz > 0.0).then_some([dz, dx]));
        self.out.resize(2 * n, 0.0);
        let all_one = self.weights.iter().all(|&w| w == 1.0);
        let report = ws.smooth(&self.data, (!all_one).then_some(&self.weights[..]), &sp, &mut self.out)?;
        let (vx, vz) = self.out.split_at(n);
        write_velocity(planes_out, [ivx, ivz], lumen.as_deref().or(mask), vx, vz);
        Ok(FieldReport { s: report.s, outlier_fraction: report.outlier_fraction, converged: report.converged })
    }

    /// The power mask: weight 0 where the power is more than `power_mask_db` below the frame's
    /// 99th percentile (no blood there).
    fn power_mask(&mut self, power: &[f32]) {
        for (w, blood) in self.weights.iter_mut().zip(blood_from_power(power, self.params.power_mask_db)) {
            if !blood {
                *w = 0.0;
            }
        }
    }

    /// The no-slip wall from the power, the blood being the pixels with weight (after the
    /// power mask).
    fn wall(
        &self,
        power: &[f32],
        shape: [usize; 2],
        spacing: [f64; 2],
        ns: &NoSlipParams,
    ) -> Result<Vec<bool>, FieldError> {
        let pw: Vec<f64> = power.iter().map(|v| f64::from(*v)).collect();
        let blood: Vec<bool> = self.weights.iter().map(|w| *w > 0.0).collect();
        Ok(wall_from_power(&pw, &blood, shape, spacing, ns)?)
    }

    /// The divergence-free fit of one frame (weights already in `self.weights`).
    fn divergence_free(
        &mut self,
        [nz, nx]: [usize; 2],
        [dz, dx]: [f64; 2],
        power: Option<&[f32]>,
        velocity_planes: [usize; 2],
        mask: Option<&[f32]>,
        planes_out: &mut [f32],
    ) -> Result<FieldReport, FieldError> {
        let n = nx * nz;
        if !(dz.is_finite() && dz > 0.0 && dx.is_finite() && dx > 0.0) {
            return Err(FieldError::Spacing { dz, dx });
        }
        // Power mask: no blood where the power is far below the frame's 99th percentile.
        if let Some(pw) = power {
            self.power_mask(pw);
        }
        // No-slip wall: outside the lumen the velocity is pulled to zero (not data).
        let mut prior = None;
        if let Some(ns) = &self.params.no_slip {
            let Some(pw) = power else { return Err(FieldError::NoSlipNeedsPower) };
            let wall = self.wall(pw, [nz, nx], [dz, dx], ns)?;
            for (w, out) in self.weights.iter_mut().zip(&wall) {
                if *out {
                    *w = 0.0;
                }
            }
            prior = Some(wall.iter().map(|out| if *out { ns.weight } else { 0.0 }).collect::<Vec<f64>>());
        }
        let dp = &self.params.divergence_free;
        let key = ([nz, nx], [dz.to_bits(), dx.to_bits()]);
        let df = match &mut self.df {
            Some((s, sp, f)) if (*s, *sp) == key && f.order() == dp.order => &*f,
            slot => &slot.insert((key.0, key.1, DivFree::new([nz, nx], [dz, dx], dp.order)?)).2,
        };
        let (ux, uz) = self.data.split_at(n);
        let (mut vx, mut vz) = (vec![0.0; n], vec![0.0; n]);
        let report =
            match df.fit_with_wall(ux, uz, Some(&self.weights), prior.as_deref(), dp, self.last_s, &mut vx, &mut vz) {
                Ok(r) => r,
                Err(DivFreeError::NoData) => return Ok(nothing_measured(planes_out, velocity_planes, n)),
                Err(e) => return Err(e.into()),
            };
        self.last_s = Some(report.s);
        write_velocity(planes_out, velocity_planes, mask, &vx, &vz);
        Ok(FieldReport { s: report.s, outlier_fraction: report.outlier_fraction, converged: true })
    }
}
