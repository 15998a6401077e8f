//! The SIMUS engine (MUST `simus`, paper 1 eq. 14–18): scatterers + transmit → RF per element.
//!
//! Per frequency bin k of the plan's band (pymust-notes §5.7):
//! `SPECT_e(k) = df·W · P(ω_k) H(ω_k)² Σ_s RC_s [Σ_e' D_e'(k) R_se'(k)] R_se(k)`,
//! then `RF_e = irfft(conj(SPECT_e), n_fft)[..n_samples]` (numpy normalisation 1/n_fft), then
//! optionally PyMUST's small-value zeroing. The work is split into fixed scatterer blocks
//! (sequential, memory bounded) and fixed ranges of bins (parallel): every bin's value is produced
//! by the same operations in the same order whatever the thread count, so the output bits do not
//! depend on it.

use std::sync::{Arc, Mutex, OnceLock};

use num_complex::Complex;
use rayon::prelude::*;
use realfft::{ComplexToReal, RealFftPlanner};

use crate::error::{Result, SimusError};
use crate::exact::{accumulate_elevation, accumulate_exact, ElevationBlock, Tables64};
use crate::grid::{FrequencyPlan, PlanInputs};
use crate::kernel::simd::Simd;
use crate::kernel::{Scratch, Tables, G, L, TX_COMPLEX, TX_REAL, TX_UNIT, V};
use crate::params::{Accuracy, Medium, PlanMode, RfWindow, SimusOptions};
use crate::pfield::{ArrayGeom, BlockGeom, ScattererGeom};
use crate::probe::Probe;
use crate::pulse::PulseModel;
use crate::scatterers::ScattererSlices;
use crate::transmit::Transmit;

/// RF of one transmit, element-major.
#[derive(Clone, Debug, PartialEq)]
pub struct RfFrame {
    /// `data[e * n_samples + k]` = element e, sample k (at `t0 + k/fs`).
    pub data: Vec<f32>,
    /// Elements.
    pub n_elements: usize,
    /// Samples per element.
    pub n_samples: usize,
    /// Sampling frequency (Hz).
    pub fs: f64,
    /// Time of sample 0 (s).
    pub t0: f64,
    /// The frequency plan used.
    pub plan: FrequencyPlan,
}

impl RfFrame {
    /// The RF of element `e`.
    pub fn element(&self, e: usize) -> &[f32] {
        &self.data[e * self.n_samples..(e + 1) * self.n_samples]
    }
}

/// One parallel unit: a fixed range of band bins and its accumulators.
#[derive(Debug, Default)]
struct Task {
    bins: std::ops::Range<usize>,
    sc: Scratch,
    /// f64 accumulator `[bin][re, im][e_pad]`.
    u: Vec<f64>,
    rbuf: Vec<f64>,
}

#[derive(Default)]
struct Workspace {
    blk: BlockGeom,
    tab: Tables,
    tab64: Tables64,
    tasks: Vec<Task>,
    fft_len: usize,
    fft: Option<Arc<dyn ComplexToReal<f64>>>,
    spec: Vec<Complex<f64>>,
    time: Vec<f64>,
    fft_scratch: Vec<Complex<f64>>,
    scale: Vec<f64>,
}

/// Reusable SIMUS engine: validated parameters, derived geometry and all working memory.
/// After the first frame of a given size, frames are simulated without allocating.
pub struct Simus {
    probe: Probe,
    medium: Medium,
    options: SimusOptions,
    geom: ArrayGeom,
    plan_inputs: PlanInputs,
    simd: Simd,
    pool: Option<rayon::ThreadPool>,
    ws: Workspace,
}

impl std::fmt::Debug for Simus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Simus")
            .field("probe", &self.probe)
            .field("medium", &self.medium)
            .field("options", &self.options)
            .field("sub_elements", &self.geom.m)
            .field("simd", &self.simd)
            .finish_non_exhaustive()
    }
}

impl Simus {
    /// Validates the parameters and derives the array geometry, the pulse duration and the SIMD
    /// kernel to use.
    pub fn new(probe: Probe, medium: Medium, options: SimusOptions) -> Result<Self> {
        probe.validate()?;
        medium.validate()?;
        options.validate(probe.fc)?;
        let (fc, c) = (probe.fc, medium.c);
        let geom = ArrayGeom::new(&probe, &medium, options.element_splitting, options.full_frequency_directivity);
        let pulse = PulseModel::new(fc, probe.tx_now, probe.bandwidth);
        let plan_inputs = PlanInputs {
            fc,
            c,
            fs: options.fs.unwrap_or(4.0 * fc),
            db_thresh: options.db_thresh,
            frequency_step: options.frequency_step,
            window: options.window,
            pulse,
            pulse_duration: pulse.two_way_pulse_duration(),
        };
        let pool = match options.threads {
            Some(n) => Some(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(n)
                    .build()
                    .map_err(|_| crate::error::invalid("options.threads", n, "a thread count the OS can start"))?,
            ),
            None => None,
        };
        let simd = Simd::detect(options.kernel);
        Ok(Self { probe, medium, options, geom, plan_inputs, simd, pool, ws: Workspace::default() })
    }

    /// The probe.
    pub fn probe(&self) -> &Probe {
        &self.probe
    }

    /// The medium.
    pub fn medium(&self) -> &Medium {
        &self.medium
    }

    /// The options.
    pub fn options(&self) -> &SimusOptions {
        &self.options
    }

    /// Sub-elements per element (MUST's M).
    pub fn sub_elements(&self) -> usize {
        self.geom.m
    }

    /// Name of the kernel build in use (`"avx512"`, `"avx2"`, `"portable"`).
    pub fn kernel_name(&self) -> &'static str {
        self.simd.name()
    }

    /// Duration (s) of MUST's two-way pulse used to pad the plan's distance.
    pub fn pulse_duration(&self) -> f64 {
        self.plan_inputs.pulse_duration
    }

    /// The frequency plan for this scene and transmit according to `options.plan`:
    /// MUST's per-call rule, or the fixed [`PlanMode::MaxDistance`] plan.
    pub fn plan<'a>(&self, scatterers: impl Into<ScattererSlices<'a>>, transmit: &Transmit) -> Result<FrequencyPlan> {
        match self.options.plan {
            PlanMode::PerCall => {
                let s = scatterers.into();
                s.validate()?;
                transmit.validate(self.probe.n_elements)?;
                let d = s.max_probe_distance(&self.probe);
                FrequencyPlan::for_max_distance(&self.plan_inputs, d, transmit.max_delay())
            }
            PlanMode::MaxDistance { max_distance, max_delay } => self.plan_for_max_distance(max_distance, max_delay),
        }
    }

    /// A plan fixed for scatterers up to `max_distance` (m) from any element and transmit delays
    /// up to `max_delay` (s): use it for every frame of a packet (same length and gain).
    pub fn plan_for_max_distance(&self, max_distance: f64, max_delay: f64) -> Result<FrequencyPlan> {
        if !(max_delay.is_finite() && max_delay >= 0.0) {
            return Err(crate::error::invalid("plan.max_delay", max_delay, "finite and >= 0 (s)"));
        }
        FrequencyPlan::for_max_distance(&self.plan_inputs, max_distance, max_delay)
    }

    /// Plans (per `options.plan`) and simulates one frame.
    pub fn simulate<'a>(&mut self, scatterers: impl Into<ScattererSlices<'a>>, transmit: &Transmit) -> Result<RfFrame> {
        let s = scatterers.into();
        let plan = self.plan(s, transmit)?;
        let n_el = self.probe.n_elements;
        let mut data = vec![0.0f32; n_el * plan.n_samples];
        self.simulate_into(s, transmit, &plan, &mut data)?;
        Ok(RfFrame { data, n_elements: n_el, n_samples: plan.n_samples, fs: plan.fs, t0: plan.t0, plan })
    }

    /// Simulates one frame with a given plan into `out`, element-major:
    /// `out[e * plan.n_samples + k]`. Zero scatterers give all-zero RF. Errors: non-finite
    /// scatterer (names the row), bad transmit, wrong `out` length, plan of another
    /// configuration, or a plan whose time window is too short for the scene.
    pub fn simulate_into<'a>(
        &mut self,
        scatterers: impl Into<ScattererSlices<'a>>,
        transmit: &Transmit,
        plan: &FrequencyPlan,
        out: &mut [f32],
    ) -> Result<()> {
        self.simulate_impl(scatterers.into(), None, transmit, plan, out)
    }

    /// [`Simus::simulate`] for scatterers off the imaging plane at elevations `y` (m, one per
    /// scatterer): with any |y| ≥ 1e-9 m, MUST's elevation model (PyMUST's rule; otherwise
    /// exactly [`Simus::simulate`]): 3-D distances, 1/r spreading both ways, no element-width
    /// factor, and each element's pattern times the multi-Gaussian beam (MGBM) of an element of
    /// `probe.height` focused at `probe.focus` in elevation (∞ when unset), on transmit and on
    /// receive, recomputed at MUST's `max(3, round(n/20))` band frequencies. The plan is the 2-D
    /// one (MUST's SIMUS too ignores y there). Evaluated in f64 whatever `accuracy` says: the
    /// phasors anchored exactly at the start of each range of bins and stepped across it (slower
    /// than the 2-D fast kernel, which steps them in f32 SIMD).
    pub fn simulate_3d<'a>(
        &mut self,
        scatterers: impl Into<ScattererSlices<'a>>,
        y: &[f32],
        transmit: &Transmit,
    ) -> Result<RfFrame> {
        let s = scatterers.into();
        let plan = self.plan(s, transmit)?;
        let n_el = self.probe.n_elements;
        let mut data = vec![0.0f32; n_el * plan.n_samples];
        self.simulate_3d_into(s, y, transmit, &plan, &mut data)?;
        Ok(RfFrame { data, n_elements: n_el, n_samples: plan.n_samples, fs: plan.fs, t0: plan.t0, plan })
    }

    /// [`Simus::simulate_3d`] with a given plan into `out` (as [`Simus::simulate_into`]).
    pub fn simulate_3d_into<'a>(
        &mut self,
        scatterers: impl Into<ScattererSlices<'a>>,
        y: &[f32],
        transmit: &Transmit,
        plan: &FrequencyPlan,
        out: &mut [f32],
    ) -> Result<()> {
        let s = scatterers.into();
        if y.len() != s.len() {
            return Err(SimusError::LengthMismatch { field: "scatterers.y", got: y.len(), expected: s.len() });
        }
        if let Some(i) = (0..y.len()).find(|&i| !(y[i].is_finite() && f64::from(y[i]).abs() <= 100.0)) {
            return Err(crate::error::invalid("scatterers.y", format!("{} at row {i}", y[i]), "finite, |y| ≤ 100 m"));
        }
        let elevation = y.iter().any(|v| f64::from(*v).abs() >= 1e-9);
        self.simulate_impl(s, elevation.then_some(y), transmit, plan, out)
    }

    fn simulate_impl(
        &mut self,
        s: ScattererSlices<'_>,
        y: Option<&[f32]>,
        transmit: &Transmit,
        plan: &FrequencyPlan,
        out: &mut [f32],
    ) -> Result<()> {
        s.validate()?;
        let elev = match y {
            Some(_) if plan.window == RfWindow::Compact => {
                // MUST's elevation factor is evaluated on every 20th bin of MUST's grid and
                // interpolated between: it depends on the grid, so only MUST's window gives MUST's RF
                return Err(crate::error::invalid(
                    "options.window",
                    "compact",
                    "\"must\" for scatterers off the imaging plane (MUST's elevation model samples MUST's own frequency grid)",
                ));
            }
            Some(y) => {
                let (h, rf) = crate::pressure::elevation_params(&self.probe)?;
                let planar = y.iter().all(|v| v.abs() < f32::EPSILON);
                Some((y, h, rf, planar))
            }
            None => None,
        };
        let n_el = self.probe.n_elements;
        transmit.validate(n_el)?;
        self.check_plan(plan)?;
        if out.len() != n_el * plan.n_samples {
            return Err(SimusError::OutputLength { got: out.len(), expected: n_el * plan.n_samples });
        }
        if self.options.frequency_step <= 1.0 {
            let d = s.max_probe_distance(&self.probe);
            let needed =
                2.0 * (d + self.plan_inputs.pulse_duration * self.medium.c) / self.medium.c + transmit.max_delay();
            if needed > plan.window() * (1.0 + 1e-12) {
                return Err(SimusError::PlanTooShort { needed_s: needed, window_s: plan.window() });
            }
        }
        self.prepare(plan, transmit);
        let pool = self.pool.take();
        match &pool {
            Some(p) => p.install(|| self.accumulate(s, plan, elev)),
            None => self.accumulate(s, plan, elev),
        }
        self.pool = pool;
        self.spectra_to_rf(plan, out, elev.is_none());
        if self.options.zero_small_values {
            zero_small_values(out);
        }
        Ok(())
    }

    fn check_plan(&self, plan: &FrequencyPlan) -> Result<()> {
        let inp = &self.plan_inputs;
        if plan.fc != inp.fc || plan.c != inp.c || plan.fs != inp.fs {
            return Err(SimusError::PlanMismatch("fc, c or fs differ from the engine's"));
        }
        let consistent = plan.n_freq >= 3
            && plan.band_first <= plan.band_last
            && plan.band_last < plan.n_freq
            && plan.band_last <= plan.n_fft / 2
            && match plan.window {
                RfWindow::Must => plan.n_samples == plan.n_fft.div_ceil(2),
                RfWindow::Compact => plan.n_samples >= 1 && plan.n_samples <= plan.n_fft,
            }
            && plan.gain_df.is_finite()
            && plan.gain_df > 0.0
            && (plan.df - 2.0 * plan.fc / (plan.n_freq - 1) as f64).abs() <= 1e-9 * plan.df;
        if !consistent {
            return Err(SimusError::PlanMismatch("inconsistent grid (df, n_freq, band, n_fft)"));
        }
        Ok(())
    }

    /// Bin tables and task partition for this plan and transmit.
    fn prepare(&mut self, plan: &FrequencyPlan, transmit: &Transmit) {
        let geom = &self.geom;
        let ep = geom.e_pad;
        let nb = plan.n_bins();
        let ws = &mut self.ws;
        let no_delays = transmit.delays.iter().all(|d| d.is_nan() || *d == 0.0);
        let unit = (0..geom.n_el).all(|e| transmit.weight(e) == 1.0);
        ws.tab.tx = match (no_delays, unit) {
            (true, true) => TX_UNIT,
            (true, false) => TX_REAL,
            _ => TX_COMPLEX,
        };
        ws.tab.freqs.clear();
        ws.tab.freqs.extend((plan.band_first..=plan.band_last).map(|k| plan.frequency(k)));
        ws.tab.d_re.resize(nb * ep / L, V::default());
        ws.tab.d_im.resize(nb * ep / L, V::default());
        ws.tab64.d_re.resize(nb * ep, 0.0);
        ws.tab64.d_im.resize(nb * ep, 0.0);
        for (kb, &f) in ws.tab.freqs.iter().enumerate() {
            for e in 0..ep {
                let (re, im) = if e < geom.n_el {
                    let w = transmit.weight(e);
                    let tau = if transmit.delays[e].is_nan() { 0.0 } else { transmit.delays[e] };
                    let (s, c) = crate::math::sincos_turns(f * tau);
                    (w * c, w * s)
                } else {
                    (0.0, 0.0)
                };
                ws.tab64.d_re[kb * ep + e] = re;
                ws.tab64.d_im[kb * ep + e] = im;
                ws.tab.d_re[kb * ep / L + e / L].0[e % L] = re as f32;
                ws.tab.d_im[kb * ep / L + e / L].0[e % L] = im as f32;
            }
        }
        // fixed partition of the band into ranges of at most `per` bins, sizes differing by <= 1
        let per = match self.options.accuracy {
            Accuracy::Fast { reanchor_every, .. } => reanchor_every as usize,
            Accuracy::Exact => 8,
        };
        // ranges of at most `per` bins (sizes differ by <= 1): also the unit of parallelism
        let n_tasks = nb.div_ceil(per).max(1);
        ws.tasks.resize_with(n_tasks, Task::default);
        for (j, t) in ws.tasks.iter_mut().enumerate() {
            t.bins = j * nb / n_tasks..(j + 1) * nb / n_tasks;
            t.u.clear();
            t.u.resize(t.bins.len() * 2 * ep, 0.0);
            t.sc.prepare(geom, t.bins.len());
        }
    }

    /// Streams the scatterers block by block into the tasks' accumulators.
    fn accumulate(&mut self, s: ScattererSlices<'_>, plan: &FrequencyPlan, elev: Option<Elevation<'_>>) {
        let block = match (&self.options.accuracy, elev) {
            (Accuracy::Fast { scatterer_block, .. }, None) => *scatterer_block as usize,
            _ => 64,
        };
        let exact = matches!(self.options.accuracy, Accuracy::Exact) || elev.is_some();
        let geom = &self.geom;
        let simd = self.simd;
        let ws = &mut self.ws;
        let mut eb = elev.map(|(_, h, rf, planar)| ElevationBlock {
            h,
            rf,
            c: self.medium.c,
            planar,
            mgbm_bins: crate::pressure::mgbm_bins(ws.tab.freqs.len()),
            ..Default::default()
        });
        let mut start = 0;
        while start < s.len() {
            let end = (start + block).min(s.len());
            setup_block(geom, simd, &s, start..end, plan.df, &mut ws.blk);
            if let (Some(eb), Some((y, ..))) = (eb.as_mut(), elev) {
                elevate_block(geom, &s, &y[start..end], start..end, &mut ws.blk, eb);
            }
            let (blk, tab, tab64) = (&ws.blk, &ws.tab, &ws.tab64);
            let ebr = eb.as_ref();
            ws.tasks.par_iter_mut().for_each(|t| {
                if let Some(el) = ebr {
                    accumulate_elevation(
                        geom,
                        blk,
                        tab64,
                        &tab.freqs,
                        plan.df,
                        t.bins.clone(),
                        &mut t.u,
                        &mut t.rbuf,
                        el,
                    );
                } else if exact {
                    accumulate_exact(geom, blk, tab64, &tab.freqs, t.bins.clone(), &mut t.u, &mut t.rbuf);
                } else {
                    simd.accumulate(geom, blk, tab, t.bins.clone(), &mut t.sc);
                    fold(&mut t.sc, &mut t.u, geom.e_pad);
                }
            });
            start = end;
        }
    }

    /// Scales the accumulated spectra (`P H² df W`) and transforms them to RF.
    fn spectra_to_rf(&mut self, plan: &FrequencyPlan, out: &mut [f32], width_factor: bool) {
        let n = plan.n_fft;
        let ws = &mut self.ws;
        if ws.fft_len != n || ws.fft.is_none() {
            // one planner per process: plans are reused across Simus instances (a Python caller
            // builds one per call; planning a length with large prime factors costs milliseconds)
            static PLANNER: OnceLock<Mutex<RealFftPlanner<f64>>> = OnceLock::new();
            let fft = PLANNER
                .get_or_init(|| Mutex::new(RealFftPlanner::new()))
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .plan_fft_inverse(n);
            ws.spec = fft.make_input_vec();
            ws.time = fft.make_output_vec();
            ws.fft_scratch = fft.make_scratch_vec();
            ws.fft = Some(fft);
            ws.fft_len = n;
        }
        let Some(fft) = ws.fft.clone() else { return };
        let ep = self.geom.e_pad;
        // SPECT = df·W · P(ω) H(ω)² · U (purely imaginary factor)
        ws.scale.clear();
        ws.scale.extend(ws.tab.freqs.iter().map(|&f| {
            let w = 2.0 * std::f64::consts::PI * f;
            let h = self.plan_inputs.pulse.probe(w);
            self.plan_inputs.pulse.pulse_im(w) * h * h * plan.gain_df * if width_factor { self.geom.width } else { 1.0 }
        }));
        let scale = &ws.scale;
        let inv_n = 1.0 / n as f64;
        for (e, rf) in out.chunks_exact_mut(plan.n_samples).enumerate() {
            ws.spec.iter_mut().for_each(|v| *v = Complex::new(0.0, 0.0));
            for t in &ws.tasks {
                for (kl, kb) in t.bins.clone().enumerate() {
                    let u = Complex::new(t.u[kl * 2 * ep + e], t.u[kl * 2 * ep + ep + e]);
                    let k = plan.band_first + kb;
                    if k < ws.spec.len() {
                        ws.spec[k] = (Complex::new(0.0, scale[kb]) * u).conj();
                    }
                }
            }
            // numpy's irfft ignores the imaginary parts of the DC (and, n even, Nyquist) bins
            ws.spec[0].im = 0.0;
            if n.is_multiple_of(2) {
                if let Some(last) = ws.spec.last_mut() {
                    last.im = 0.0;
                }
            }
            if fft.process_with_scratch(&mut ws.spec, &mut ws.time, &mut ws.fft_scratch).is_err() {
                rf.fill(0.0);
                continue;
            }
            for (o, v) in rf.iter_mut().zip(&ws.time) {
                *o = (v * inv_n) as f32;
            }
        }
    }
}

/// Geometry and steppers of scatterers `range`, padded with silent scatterers to a multiple of
/// the receive group size, in parallel over scatterers (pure per-scatterer work: the result does
/// not depend on the thread count).
/// A 3-D scene: the scatterers' elevations, element height, elevation focus, MUST's planar
/// branch.
type Elevation<'a> = (&'a [f32], f64, f64, bool);

/// Turns a block's 2-D geometry into MUST's elevation geometry: 3-D distances (clamped to λ/2),
/// 1/r instead of 1/√r, and each element's mean distance over its sub-elements for the MGBM.
fn elevate_block(
    geom: &ArrayGeom,
    s: &ScattererSlices<'_>,
    y: &[f32],
    range: std::ops::Range<usize>,
    blk: &mut BlockGeom,
    eb: &mut ElevationBlock,
) {
    let ep = geom.e_pad;
    let nc = ep / L;
    eb.y.clear();
    eb.y.resize(blk.n_s, 0.0);
    eb.rm.clear();
    eb.rm.resize(blk.n_s * ep, 0.0);
    let (x, z) = (&s.x[range.clone()], &s.z[range]);
    for (i, (&yi, (&xi, &zi))) in y.iter().zip(x.iter().zip(z)).enumerate() {
        let (xp, zp, yp) = (f64::from(xi), f64::from(zi), f64::from(yi));
        eb.y[i] = yp;
        for c in 0..nc {
            for m in 0..geom.m {
                let base = ((i * nc + c) * geom.m + m) * L;
                for l in 0..L {
                    let e = c * L + l;
                    if e >= geom.n_el {
                        continue;
                    }
                    let (dx, dz) = geom.delta(e, m, xp, zp);
                    let r3 = (dx * dx + dz * dz + yp * yp).sqrt().max(geom.r_min);
                    blk.amp[base + l] *= blk.r[base + l].sqrt() / r3;
                    blk.r[base + l] = r3;
                    eb.rm[i * ep + e] += r3 / geom.m as f64;
                }
            }
        }
    }
}

fn setup_block(
    geom: &ArrayGeom,
    simd: Simd,
    s: &ScattererSlices<'_>,
    range: std::ops::Range<usize>,
    df: f64,
    blk: &mut BlockGeom,
) {
    let n = range.len();
    blk.resize(n.div_ceil(G) * G, geom);
    let stride = geom.m * geom.e_pad;
    let (x, z, rc) = (&s.x[range.clone()], &s.z[range.clone()], &s.rc[range]);
    for (i, v) in blk.rc.iter_mut().enumerate() {
        *v = if i >= n || geom.is_behind(f64::from(x[i]), f64::from(z[i])) { 0.0 } else { f64::from(rc[i]) };
    }
    let one = |i: usize, out: ScattererGeom<'_>| {
        if i < n {
            simd.setup(geom, x[i], z[i], df, false, out);
        } else {
            simd.setup(geom, 0.0, 1.0, df, true, out);
        }
    };
    let geo = blk.r.par_chunks_mut(stride).zip(blk.amp.par_chunks_mut(stride));
    let steps = blk.e_re.par_chunks_mut(stride / L).zip(blk.e_im.par_chunks_mut(stride / L));
    if geom.ffd {
        geo.zip(steps)
            .zip(blk.dirb.par_chunks_mut(stride))
            .enumerate()
            .for_each(|(i, (((r, amp), (e_re, e_im)), dirb))| one(i, ScattererGeom { r, amp, dirb, e_re, e_im }));
    } else {
        geo.zip(steps)
            .enumerate()
            .for_each(|(i, ((r, amp), (e_re, e_im)))| one(i, ScattererGeom { r, amp, dirb: &mut [], e_re, e_im }));
    }
}

/// Adds the f32 partial sums of a block to the f64 accumulator and clears them.
fn fold(sc: &mut Scratch, u: &mut [f64], ep: usize) {
    let nc = ep / L;
    for (kl, row) in u.chunks_exact_mut(2 * ep).enumerate() {
        let (u_re, u_im) = row.split_at_mut(ep);
        for c in 0..nc {
            let (sr, si) = (&mut sc.s_re[kl * nc + c], &mut sc.s_im[kl * nc + c]);
            for l in 0..L {
                u_re[c * L + l] += f64::from(sr.0[l]);
                u_im[c * L + l] += f64::from(si.0[l]);
            }
            *sr = V::default();
            *si = V::default();
        }
    }
}

/// Below this ρ the factor of [`zero_small_values`] is exactly 0: ½(1 + tanh(−7.6)) = 2.5e-7,
/// which rounds to 0 steps of 1e-6.
pub(crate) const ZERO_BELOW: f64 = 2.4e-6;

/// PyMUST simus.py step 10: `RF *= round(½(1 + tanh((ρ − 1e-5)/1e-6)) / 1e-6)·1e-6`,
/// `ρ = |RF| / max|RF|` — a quantised soft threshold at −100 dB. No-op on an all-zero frame.
pub fn zero_small_values(rf: &mut [f32]) {
    let peak = rf.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    if peak <= 0.0 || !peak.is_finite() {
        return;
    }
    let thr = 1e-5f64;
    for v in rf.iter_mut() {
        let rho = f64::from(v.abs()) / f64::from(peak);
        if rho > thr + 2e-5 {
            continue; // factor is exactly 1 there
        }
        if rho < ZERO_BELOW {
            // the quantised factor is exactly 0 there (the step < 2.6e-7 rounds to 0 µ-steps);
            // skipping tanh and round leaves the same bits, signed zero included
            *v = (f64::from(*v) * 0.0) as f32;
            continue;
        }
        let step = 0.5 * (1.0 + ((rho - thr) / (thr / 10.0)).tanh());
        let q = (step / (thr / 10.0)).round() * (thr / 10.0);
        *v = (f64::from(*v) * q) as f32;
    }
}
