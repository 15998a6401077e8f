//! The training data of paper 2 (Algorithm 1, §4.3) from our own resolved Stokes solves
//! ([`crate::stokes`]), and the data sets of the three networks.
//!
//! **Generation** ([`generate`]): shape `i` of a data set is drawn from its own generator seeded
//! by (seed, set, i), so a data set does not depend on the order, the thread count or on
//! interruptions. Each finished solve is appended as one JSON line to the data file and flushed,
//! so an interrupted run loses at most the solves in flight; a rerun reads the file, drops a torn
//! last line, and solves only the missing indices (resumable). Solves run in parallel on a rayon
//! pool of `threads` threads.
//!
//! - The **in-bounds** set: [`ShapeSampler::default`] (the normals of §4.1, dropped outside eq 7).
//! - The **generalisation** set (Table 1's last column): the same normals with twice the
//!   standard deviation, kept only if at least one parameter is outside eq 7's bounds and all are
//!   inside [`GENERALISATION_LIMITS`] (bodies the solver resolves; α ≥ 0.1, Ly ≥ 0.1 µm).
//!
//! A record holds the shape and its full in-plane resistance ([`ShapeResistance`]): since Stokes
//! flow is linear, D(ψ), L(ψ) and T(ψ) at any angle are exact combinations of two solves, so the
//! angles of attack are drawn when the data sets are built ([`network_datasets`]): four random
//! ψ per shape, as Algorithm 1 does.
//!
//! **Targets.** N: eq 18's (d, l, t_p) = (D / (70 − 10 cos 2ψ), L / (10 sin 2ψ), T / (2 cos ψ));
//! N_r: t_r = T_r / 800 with T_r the torque about the centre of mass for a relative rotation of
//! 2π rad/s (the dynamics' c_r; the paper's eq 14 rotates about the origin instead, which adds the
//! uniform flow −2π y_c e_x: the difference is stored in [`Record::paper_rotational_torque`]);
//! N_s: t_s = T_s / 800 with T_s the strain torque at ε = 2π s⁻¹ ([`crate::nn::model`]).
//! Angles within 1e-3 rad of a zero of sin 2ψ or cos ψ are redrawn (the scaled lift and torque
//! are 0/0 there).
use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::io::{BufRead, Write};
use std::path::Path;
use std::sync::Mutex;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::nn::data::Dataset;
use crate::nn::model::{
    network_inputs, rotational_from_si, scale_rotational, scale_translational, shape_inputs, StrainTarget,
};
use crate::nn::NnError;
use crate::shape::{Shape, ShapeSampler, BOUNDS};
use crate::stokes::{solve_shape, ShapeResistance, StokesError, StokesOptions};

/// Limits of the generalisation shapes (SI): (name, low, high).
pub const GENERALISATION_LIMITS: [(&str, f64, f64); 5] = [
    ("lx", 1.8e-6, 4.2e-6),
    ("ly", 0.1e-6, 1.5e-6),
    ("lz", 1.8e-6, 4.2e-6),
    ("alpha_top", 0.1, 3.0),
    ("alpha_bot", 0.1, 3.0),
];

/// Which data set a record belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Set {
    /// Shapes inside eq 7's bounds (training and test).
    InBounds,
    /// Shapes with at least one parameter outside eq 7's bounds.
    Generalisation,
}

/// One solved shape (one line of the data file).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Record {
    /// Data set.
    pub set: Set,
    /// Index within its data set.
    pub index: u64,
    /// The shape.
    pub shape: Shape,
    /// Its resistance in the solver's configuration.
    pub resistance: ShapeResistance,
    /// The paper's T_r (rotation about the origin, eq 14) in µm²·µg/s².
    pub paper_rotational_torque: f64,
    /// Wall time of the solve \[s\].
    pub seconds: f64,
    /// Body panels along the meridian of this solve (absent: the file header's `n_beta`; thin
    /// shapes are solved finer, [`Refinement`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub n_beta: Option<usize>,
}

impl Record {
    /// The resolution of this solve (`base`: the file header's `n_beta`).
    pub fn n_beta_or(&self, base: usize) -> usize {
        self.n_beta.unwrap_or(base)
    }
}

/// A finer resolution for thin shapes: a shape whose aspect max(Lx, Lz) / Ly is at least
/// `min_aspect` is solved with `n_beta` body panels along its meridian (the finest matching rule
/// wins; never coarser than the base options). The shape factor B = c_s / c_r of thin platelets
/// converges slowest: at Lx/Ly = 20 its Jeffery period is 1.5 % off at `n_beta` 16, 0.2 % at 24
/// and 0.03 % at 32 (`examples/shape_factor_convergence.rs`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Refinement {
    /// Smallest aspect max(Lx, Lz) / Ly the rule applies to (> 1).
    pub min_aspect: f64,
    /// Body panels along the meridian (even, 4 ..= 64).
    pub n_beta: usize,
}

impl Refinement {
    /// The default rules: `n_beta` 24 from aspect 9, 32 from aspect 15 (README, "Training data").
    pub fn defaults() -> Vec<Refinement> {
        vec![Refinement { min_aspect: 9.0, n_beta: 24 }, Refinement { min_aspect: 15.0, n_beta: 32 }]
    }

    /// The resolution of `shape` under `rules` with base resolution `base`.
    pub fn n_beta_for(rules: &[Refinement], base: usize, shape: &Shape) -> usize {
        let aspect = shape.lx.max(shape.lz) / shape.ly;
        rules.iter().filter(|r| aspect >= r.min_aspect).map(|r| r.n_beta).fold(base, usize::max)
    }
}

/// Errors of the data generator.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// An option out of range.
    #[error("platelet data: `{field}` = {value} is invalid: allowed {allowed}")]
    Option { field: &'static str, value: String, allowed: &'static str },
    /// A solve failed.
    #[error("platelet data: shape {index} of the {set:?} set: {source}")]
    Solve { set: Set, index: u64, source: StokesError },
    /// A line of the data file is not a record (other than a torn last line).
    #[error("platelet data: {path}: line {line}: {reason}")]
    Format { path: String, line: usize, reason: String },
    /// The data file was written with other solver options or seed.
    #[error("platelet data: {path} was generated with {found}; this run asks for {wanted} (use another file)")]
    Mismatch { path: String, found: String, wanted: String },
    /// File system.
    #[error("platelet data: {path}: {source}")]
    Io { path: String, source: std::io::Error },
    /// Building the network data sets.
    #[error(transparent)]
    Nn(#[from] NnError),
}

/// Options of [`generate`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GenerateOptions {
    /// In-bounds shapes (1 ..= 1 000 000).
    pub n_shapes: u64,
    /// Generalisation shapes (0 ..= 1 000 000).
    pub n_generalisation: u64,
    /// Seed of the shapes.
    pub seed: u64,
    /// Solver threads (1 ..= 256).
    pub threads: usize,
    /// Solver options (the paper's configuration by default).
    pub stokes: StokesOptions,
    /// Finer resolutions for thin shapes ([`Refinement::defaults`]). Not part of the file's
    /// header: a record solved coarser than the rules ask is solved again and appended, the
    /// finest record of a shape counts.
    #[serde(default = "Refinement::defaults")]
    pub refine: Vec<Refinement>,
}

impl Default for GenerateOptions {
    fn default() -> Self {
        GenerateOptions {
            n_shapes: 2000,
            n_generalisation: 250,
            seed: 1,
            threads: 1,
            stokes: StokesOptions::default(),
            refine: Refinement::defaults(),
        }
    }
}

/// First line of a data file: what it was generated with.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct FileHeader {
    format: String,
    seed: u64,
    stokes: StokesOptions,
}

const FORMAT: &str = "sonoflow-platelet-data/1";

fn shape_rng(seed: u64, set: Set, index: u64) -> ChaCha8Rng {
    let tag = match set {
        Set::InBounds => 0x1157_0000_0000_0000u64,
        Set::Generalisation => 0x9e4e_0000_0000_0000u64,
    };
    ChaCha8Rng::seed_from_u64(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ tag ^ index)
}

/// Shape `index` of data set `set` (module doc).
pub fn draw_shape(seed: u64, set: Set, index: u64) -> Shape {
    let mut rng = shape_rng(seed, set, index);
    match set {
        Set::InBounds => ShapeSampler::default().sample(&mut rng),
        Set::Generalisation => {
            let mean = [3e-6, 0.5e-6, 3e-6, 1.0, 1.0];
            let std = [0.6e-6, 0.6e-6, 0.6e-6, 0.8, 0.8];
            loop {
                let mut v = [0.0; 5];
                for (k, x) in v.iter_mut().enumerate() {
                    // a normal with a finite positive std always constructs
                    *x = Normal::new(mean[k], std[k]).map(|n| n.sample(&mut rng)).unwrap_or(mean[k]);
                }
                let inside =
                    |lim: &[(&str, f64, f64); 5]| v.iter().zip(lim).all(|(x, (_, lo, hi))| (*lo..=*hi).contains(x));
                if inside(&GENERALISATION_LIMITS) && !inside(&BOUNDS) {
                    return Shape { lx: v[0], ly: v[1], lz: v[2], alpha_top: v[3], alpha_bot: v[4] };
                }
            }
        }
    }
}

/// Reads the records of a data file; a torn last line (no newline) is dropped and reported as
/// the byte length of the good part. Returns (header, records, good length).
fn read_file(path: &Path) -> Result<Option<(FileHeader, Vec<Record>, u64)>, DataError> {
    let p = path.display().to_string();
    let io = |source| DataError::Io { path: p.clone(), source };
    let file = match std::fs::File::open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(io(e)),
    };
    let mut reader = std::io::BufReader::new(file);
    let mut good = 0u64;
    let mut header: Option<FileHeader> = None;
    let mut records = Vec::new();
    let mut line = String::new();
    for n in 1.. {
        line.clear();
        let k = reader.read_line(&mut line).map_err(io)?;
        if k == 0 {
            break;
        }
        if !line.ends_with('\n') {
            break; // torn last line: dropped
        }
        let text = line.trim_end();
        let fmt = |reason: String| DataError::Format { path: p.clone(), line: n, reason };
        if header.is_none() {
            let h: FileHeader = serde_json::from_str(text).map_err(|e| fmt(format!("not a data file header: {e}")))?;
            if h.format != FORMAT {
                return Err(fmt(format!("format `{}`, expected `{FORMAT}`", h.format)));
            }
            header = Some(h);
        } else {
            records.push(serde_json::from_str::<Record>(text).map_err(|e| fmt(e.to_string()))?);
        }
        good += k as u64;
    }
    Ok(header.map(|h| (h, records, good)))
}

/// Progress of [`generate`]: (solved so far in this run, still to solve in this run).
pub type Progress<'a> = &'a (dyn Fn(u64, u64) + Sync);

/// Generates (or completes) the data file at `path` (module doc). Returns all its records,
/// sorted by (set, index).
pub fn generate(path: &Path, opts: &GenerateOptions, progress: Progress<'_>) -> Result<Vec<Record>, DataError> {
    if !(1..=1_000_000).contains(&opts.n_shapes) {
        return Err(DataError::Option {
            field: "n_shapes",
            value: opts.n_shapes.to_string(),
            allowed: "1 ..= 1000000",
        });
    }
    if opts.n_generalisation > 1_000_000 {
        return Err(DataError::Option {
            field: "n_generalisation",
            value: opts.n_generalisation.to_string(),
            allowed: "0 ..= 1000000",
        });
    }
    if !(1..=256).contains(&opts.threads) {
        return Err(DataError::Option { field: "threads", value: opts.threads.to_string(), allowed: "1 ..= 256" });
    }
    opts.stokes.validate().map_err(|source| DataError::Solve { set: Set::InBounds, index: 0, source })?;
    for r in &opts.refine {
        if !(r.min_aspect.is_finite() && r.min_aspect > 1.0) {
            return Err(DataError::Option {
                field: "refine.min_aspect",
                value: r.min_aspect.to_string(),
                allowed: "> 1",
            });
        }
        StokesOptions { n_beta: r.n_beta, ..opts.stokes }.validate().map_err(|source| DataError::Solve {
            set: Set::InBounds,
            index: 0,
            source,
        })?;
    }
    let base = opts.stokes.n_beta;
    let p = path.display().to_string();
    let io = |source| DataError::Io { path: p.clone(), source };
    let wanted = FileHeader { format: FORMAT.into(), seed: opts.seed, stokes: opts.stokes };
    let existing = read_file(path)?;
    let mut done: BTreeMap<(Set, u64), Record> = BTreeMap::new();
    let file = match existing {
        Some((h, records, good)) => {
            if h != wanted {
                return Err(DataError::Mismatch {
                    path: p.clone(),
                    found: serde_json::to_string(&h).unwrap_or_default(),
                    wanted: serde_json::to_string(&wanted).unwrap_or_default(),
                });
            }
            for r in finest(records, base) {
                done.insert((r.set, r.index), r);
            }
            let f = std::fs::OpenOptions::new().write(true).open(path).map_err(io)?;
            f.set_len(good).map_err(io)?; // drop a torn last line
            drop(f);
            std::fs::OpenOptions::new().append(true).open(path).map_err(io)?
        }
        None => {
            if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::create_dir_all(dir).map_err(io)?;
            }
            let mut f = std::fs::File::create(path).map_err(io)?;
            let h = serde_json::to_string(&wanted).map_err(|e| io(std::io::Error::other(e)))?;
            writeln!(f, "{h}").map_err(io)?;
            f
        }
    };
    let todo: Vec<(Set, u64)> = (0..opts.n_shapes)
        .map(|i| (Set::InBounds, i))
        .chain((0..opts.n_generalisation).map(|i| (Set::Generalisation, i)))
        .filter(|&(set, index)| match done.get(&(set, index)) {
            Some(r) => {
                r.n_beta_or(base) < Refinement::n_beta_for(&opts.refine, base, &draw_shape(opts.seed, set, index))
            }
            None => true,
        })
        .collect();
    let total = todo.len() as u64;
    let writer = Mutex::new((file, 0u64));
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.threads)
        .build()
        .map_err(|e| io(std::io::Error::other(e.to_string())))?;
    let solved: Result<Vec<Record>, DataError> = pool.install(|| {
        todo.par_iter()
            .map(|&(set, index)| {
                let shape = draw_shape(opts.seed, set, index);
                let n_beta = Refinement::n_beta_for(&opts.refine, base, &shape);
                let t0 = std::time::Instant::now();
                let resistance = solve_shape(&shape, &StokesOptions { n_beta, ..opts.stokes })
                    .map_err(|source| DataError::Solve { set, index, source })?;
                let record = Record {
                    set,
                    index,
                    shape,
                    resistance,
                    paper_rotational_torque: resistance.paper_rotational_torque(),
                    seconds: t0.elapsed().as_secs_f64(),
                    n_beta: Some(n_beta),
                };
                let line = serde_json::to_string(&record).map_err(|e| io(std::io::Error::other(e)))?;
                let mut w = writer.lock().unwrap_or_else(|e| e.into_inner());
                writeln!(w.0, "{line}").and_then(|_| w.0.flush()).map_err(io)?;
                w.1 += 1;
                progress(w.1, total);
                Ok(record)
            })
            .collect()
    });
    for r in solved? {
        done.insert((r.set, r.index), r);
    }
    Ok(done
        .into_values()
        .filter(|r| r.index < set_size(opts, r.set))
        .map(|r| Record { n_beta: Some(r.n_beta_or(base)), ..r })
        .collect())
}

fn set_size(opts: &GenerateOptions, set: Set) -> u64 {
    match set {
        Set::InBounds => opts.n_shapes,
        Set::Generalisation => opts.n_generalisation,
    }
}

/// One record per shape: the finest solve (the last of equal resolution), in (set, index) order.
fn finest(records: Vec<Record>, base: usize) -> Vec<Record> {
    let mut best: BTreeMap<(Set, u64), Record> = BTreeMap::new();
    for r in records {
        let key = (r.set, r.index);
        if best.get(&key).is_none_or(|b| r.n_beta_or(base) >= b.n_beta_or(base)) {
            best.insert(key, r);
        }
    }
    best.into_values().collect()
}

/// Reads all records of a data file (sorted by set and index; of a shape solved more than once,
/// the finest solve), each with its `n_beta` filled in.
pub fn load(path: &Path) -> Result<Vec<Record>, DataError> {
    let mut r = match read_file(path)? {
        Some((h, r, _)) => {
            let base = h.stokes.n_beta;
            finest(r, base).into_iter().map(|r| Record { n_beta: Some(r.n_beta_or(base)), ..r }).collect::<Vec<_>>()
        }
        None => {
            return Err(DataError::Io {
                path: path.display().to_string(),
                source: std::io::Error::new(std::io::ErrorKind::NotFound, "no such data file"),
            })
        }
    };
    r.sort_by_key(|r| (r.set, r.index));
    Ok(r)
}

/// The in-bounds records of `records` split by shape into (training, test): a shuffle seeded by
/// `seed` of the in-bounds records in their (index) order, the first round(`test_fraction` n)
/// (at least one, at most n − 1) are test shapes. By shape, not by sample: a shape's angles of
/// attack are exact combinations of the same solves, so a test shape must never be seen in
/// training. `sonoflow platelet train` and the experiments use this one split.
pub fn split_by_shape(
    records: &[Record],
    test_fraction: f64,
    seed: u64,
) -> Result<(Vec<&Record>, Vec<&Record>), DataError> {
    if !(test_fraction > 0.0 && test_fraction < 1.0) {
        return Err(DataError::Option {
            field: "test_fraction",
            value: test_fraction.to_string(),
            allowed: "0 < test_fraction < 1",
        });
    }
    let mut inb: Vec<&Record> = records.iter().filter(|r| r.set == Set::InBounds).collect();
    inb.sort_by_key(|r| r.index);
    if inb.len() < 2 {
        return Err(DataError::Option {
            field: "in-bounds shapes",
            value: inb.len().to_string(),
            allowed: "at least 2 to split",
        });
    }
    let mut order: Vec<usize> = (0..inb.len()).collect();
    {
        use rand::seq::SliceRandom;
        order.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
    }
    let n_test = ((inb.len() as f64 * test_fraction).round() as usize).clamp(1, inb.len() - 1);
    let test = order[..n_test].iter().map(|&i| inb[i]).collect();
    let training = order[n_test..].iter().map(|&i| inb[i]).collect();
    Ok((training, test))
}

/// Draws an angle of attack in [0, 2π) away (1e-3 rad) from the zeros of sin 2ψ and cos ψ.
fn draw_angle(rng: &mut ChaCha8Rng) -> f64 {
    loop {
        let psi: f64 = rng.gen_range(0.0..2.0 * PI);
        let to_zero = (psi / (PI / 2.0)).fract();
        let d = to_zero.min(1.0 - to_zero) * PI / 2.0;
        if d > 1e-3 {
            return psi;
        }
    }
}

/// The data sets of one data set's records: N (inputs Lx, Ly, Lz \[µm\], α_top, α_bot, ψ;
/// targets d, l, t_p; `angles` random ψ per shape), N_r (targets t_r) and N_s (targets t_s).
pub struct NetworkData {
    /// Drag, lift and pitching torque network.
    pub n: Dataset,
    /// Rotational torque network.
    pub n_r: Dataset,
    /// Strain torque network.
    pub n_s: Dataset,
}

/// Builds the network data sets of `records` (module doc), `angles` (1 ..= 64) ψ per shape drawn
/// from `seed`. N's samples are grouped by shape (their position in `records`), so that a
/// validation split keeps a shape's angles together.
pub fn network_datasets(records: &[&Record], angles: usize, seed: u64) -> Result<NetworkData, DataError> {
    if !(1..=64).contains(&angles) {
        return Err(DataError::Option { field: "angles", value: angles.to_string(), allowed: "1 ..= 64" });
    }
    let (mut xi, mut yi, mut xr, mut yr, mut ys) = (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut gi = Vec::new();
    for (g, r) in records.iter().enumerate() {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ shape_rng(seed, r.set, r.index).gen::<u64>());
        for _ in 0..angles {
            let psi = draw_angle(&mut rng);
            let t = r.resistance.translational(psi);
            let raw = crate::nn::model::translational_from_si(&t);
            xi.extend_from_slice(&network_inputs(&r.shape, psi));
            yi.extend_from_slice(&scale_translational(psi, raw)?);
            gi.push(g as u64);
        }
        let [t_r, t_s] = rotational_from_si(&r.resistance.rotational());
        xr.extend_from_slice(&shape_inputs(&r.shape));
        yr.push(scale_rotational(t_r));
        ys.push(scale_rotational(t_s));
    }
    Ok(NetworkData {
        n: Dataset::new(6, 3, xi, yi)?.with_groups(gi)?,
        n_r: Dataset::new(5, 1, xr.clone(), yr)?,
        n_s: Dataset::new(5, 1, xr, ys)?,
    })
}

/// N_s's data set for `target` ([`StrainTarget`]): inputs as N_r's, one sample per record.
pub fn strain_dataset(records: &[&Record], target: StrainTarget) -> Result<Dataset, DataError> {
    let (mut x, mut y) = (Vec::new(), Vec::new());
    for r in records {
        let [t_r, t_s] = rotational_from_si(&r.resistance.rotational());
        x.extend_from_slice(&shape_inputs(&r.shape));
        y.push(target.target(&r.shape, scale_rotational(t_r), scale_rotational(t_s))?);
    }
    Ok(Dataset::new(5, 1, x, y)?)
}
