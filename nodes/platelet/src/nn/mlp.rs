//! A fully connected network y = s ⊙ (W_L ReLU(… ReLU(W_1 x̂ + b_1) …) + b_L) + m, with x̂ = (x − μ) / σ
//! the standardised input (μ, σ per input) and (m, s) the output scaling, all stored with the
//! weights. Layer l maps n_{l−1} → n_l with W_l row-major n_l × n_{l−1} (PyTorch's `Linear`
//! layout).
//!
//! **Inference** ([`Mlp::forward_with`], [`Mlp::forward_batch`], [`Mlp::forward_batch_par`]): f32,
//! in tiles of [`TILE`] samples stored feature-major (one contiguous row of `TILE` lanes per
//! neuron). A layer is then, per output neuron, a sum of weight × lane-row products: the inner
//! loop runs over the lanes with one broadcast weight, a fixed trip count and no dependence
//! between lanes, which the compiler vectorises. Every lane is computed independently, so the
//! result of a sample does not depend on which tile or thread it went through (same bits for any
//! thread count). The buffers live in a caller-owned [`MlpWorkspace`] (or one per rayon thread),
//! so the hot path does not allocate.
//!
//! **Mirror-averaged networks** ([`Mirror`], [`Mlp::with_mirror`]): an exact symmetry of the
//! data, "the target of the mirrored input M x is S y" (S flips the sign of some outputs), can be
//! built into the prediction: ŷ(x) = ½ (N(x) + S N(M x)). The layers are the plain network's; the
//! prediction then has the symmetry exactly, at twice the evaluation cost. For the platelet
//! network N, M exchanges α_top and α_bot and reflects ψ → 2π − ψ (the body mirrored about its x
//! axis), and S flips the pitching torque.
//!
//! **Training** uses the f64 weights ([`Mlp::predict`] and `super::train`); the f32 copies are
//! rebuilt whenever the weights change.

use super::NnError;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;
use std::cell::RefCell;

/// Samples per inference tile (lanes of the vectorised loops).
pub const TILE: usize = 64;

/// An exact symmetry of a network's data (module doc): the mirrored input M x exchanges the
/// inputs of each pair in `swap`, then reflects each input of `reflect` as x → p − x (a periodic
/// angle: ψ → 2π − ψ), and its target is the original one with the outputs `negate` sign-flipped.
/// M is an involution.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Mirror {
    /// Pairs of inputs exchanged.
    pub swap: Vec<(usize, usize)>,
    /// Inputs reflected x → p − x, with p.
    pub reflect: Vec<(usize, f64)>,
    /// Outputs whose sign flips.
    pub negate: Vec<usize>,
}

impl Mirror {
    /// Paper 2's platelet mirrored about its x axis for N (inputs Lx, Ly, Lz, α_top, α_bot, ψ;
    /// outputs d, l, t_p): α_top ↔ α_bot, ψ → 2π − ψ; d and l (eq 18-scaled) keep their value,
    /// t_p flips.
    pub fn platelet_n() -> Self {
        Mirror { swap: vec![(3, 4)], reflect: vec![(5, 2.0 * std::f64::consts::PI)], negate: vec![2] }
    }

    /// The same mirror for N_r and N_s (inputs Lx, Ly, Lz, α_top, α_bot): α_top ↔ α_bot; t_r and
    /// t_s keep their value.
    pub fn platelet_shape() -> Self {
        Mirror { swap: vec![(3, 4)], reflect: Vec::new(), negate: Vec::new() }
    }

    /// Checks the indices against the network's sizes (each input and output used at most once),
    /// and finite periods.
    pub fn validate(&self, n_inputs: usize, n_outputs: usize) -> Result<(), NnError> {
        let bad = |value: String, allowed| Err(NnError::Config { field: "mirror", value, allowed });
        let mut seen = vec![false; n_inputs];
        for &(a, b) in &self.swap {
            for i in [a, b] {
                if i >= n_inputs || seen[i] {
                    return bad(format!("swap {:?}", self.swap), "distinct input indices below the input count");
                }
                seen[i] = true;
            }
        }
        let mut seen = vec![false; n_inputs];
        for &(i, p) in &self.reflect {
            if i >= n_inputs || seen[i] || !p.is_finite() {
                return bad(format!("reflect {:?}", self.reflect), "distinct input indices, finite periods");
            }
            seen[i] = true;
        }
        let mut seen = vec![false; n_outputs];
        for &k in &self.negate {
            if k >= n_outputs || seen[k] {
                return bad(format!("negate {:?}", self.negate), "distinct output indices below the output count");
            }
            seen[k] = true;
        }
        Ok(())
    }

    /// Writes M x into `out` (raw inputs).
    pub fn input(&self, x: &[f64], out: &mut [f64]) {
        out.copy_from_slice(x);
        for &(a, b) in &self.swap {
            out.swap(a, b);
        }
        for &(i, p) in &self.reflect {
            out[i] = p - out[i];
        }
    }

    /// S y in place.
    pub fn output(&self, y: &mut [f64]) {
        for &k in &self.negate {
            y[k] = -y[k];
        }
    }

    /// ±1 per output (the diagonal of S).
    pub fn output_signs(&self, n_outputs: usize) -> Vec<f64> {
        let mut s = vec![1.0; n_outputs];
        self.output(&mut s);
        s
    }
}

/// Caller-owned buffers of the f32 forward pass; grows on first use, then never allocates.
#[derive(Clone, Debug, Default)]
pub struct MlpWorkspace {
    a: Vec<f32>,
    b: Vec<f32>,
    /// Scaled outputs of a tile (n_out rows of `TILE` lanes).
    c: Vec<f32>,
    /// Standardised mirrored inputs of a tile (mirror-averaged networks).
    mi: Vec<f32>,
    row_in: Vec<f32>,
    row_out: Vec<f32>,
}

impl MlpWorkspace {
    /// Empty buffers (they grow to the network's widest layer on first use).
    pub fn new() -> Self {
        Self::default()
    }

    fn ensure(&mut self, mlp: &Mlp) {
        let width = mlp.sizes.iter().copied().max().unwrap_or(0) * TILE;
        if self.a.len() < width {
            self.a.resize(width, 0.0);
            self.b.resize(width, 0.0);
        }
        self.c.resize(mlp.n_outputs() * TILE, 0.0);
        if mlp.mirror.is_some() {
            self.mi.resize(mlp.n_inputs() * TILE, 0.0);
        }
        self.row_in.resize(mlp.n_inputs(), 0.0);
        self.row_out.resize(mlp.n_outputs(), 0.0);
    }
}

thread_local! {
    static WORKSPACE: RefCell<MlpWorkspace> = RefCell::new(MlpWorkspace::new());
}

/// Runs `f` with this thread's workspace (allocated once per thread, reused afterwards).
pub fn with_thread_workspace<R>(f: impl FnOnce(&mut MlpWorkspace) -> R) -> R {
    WORKSPACE.with(|ws| f(&mut ws.borrow_mut()))
}

/// A fully connected ReLU network with input standardisation and output scaling (module doc).
#[derive(Clone, Debug, PartialEq)]
pub struct Mlp {
    sizes: Vec<usize>,
    pub(crate) weights: Vec<Vec<f64>>,
    pub(crate) biases: Vec<Vec<f64>>,
    input_mean: Vec<f64>,
    input_std: Vec<f64>,
    output_mean: Vec<f64>,
    output_scale: Vec<f64>,
    w32: Vec<Vec<f32>>,
    b32: Vec<Vec<f32>>,
    in_mean32: Vec<f32>,
    in_inv_std32: Vec<f32>,
    out_mean32: Vec<f32>,
    out_scale32: Vec<f32>,
    mirror: Option<Mirror>,
}

fn check_finite(what: &str, v: &[f64]) -> Result<(), NnError> {
    match v.iter().position(|x| !x.is_finite()) {
        Some(index) => Err(NnError::NonFinite { what: what.to_string(), index }),
        None => Ok(()),
    }
}

fn check_len(what: &str, expected: usize, got: usize) -> Result<(), NnError> {
    if expected == got {
        Ok(())
    } else {
        Err(NnError::Size { what: what.to_string(), expected, got })
    }
}

fn check_sizes(sizes: &[usize]) -> Result<(), NnError> {
    if sizes.len() < 2 {
        return Err(NnError::Config {
            field: "sizes",
            value: format!("{sizes:?}"),
            allowed: "at least an input and an output size",
        });
    }
    if sizes.iter().any(|&n| n == 0 || n > 4096) {
        return Err(NnError::Config {
            field: "sizes",
            value: format!("{sizes:?}"),
            allowed: "every layer size in 1..=4096",
        });
    }
    Ok(())
}

impl Mlp {
    /// A network from its parts: `weights[l]` is n_{l+1} × n_l row-major, `biases[l]` has n_{l+1}
    /// entries; the normalisation vectors have one entry per input or output. Validates every
    /// length, finiteness, σ > 0 and s ≠ 0.
    pub fn from_parts(
        sizes: Vec<usize>,
        weights: Vec<Vec<f64>>,
        biases: Vec<Vec<f64>>,
        input_mean: Vec<f64>,
        input_std: Vec<f64>,
        output_mean: Vec<f64>,
        output_scale: Vec<f64>,
    ) -> Result<Self, NnError> {
        check_sizes(&sizes)?;
        let layers = sizes.len() - 1;
        check_len("number of weight matrices", layers, weights.len())?;
        check_len("number of bias vectors", layers, biases.len())?;
        for l in 0..layers {
            check_len(&format!("layer {l} weight entries"), sizes[l] * sizes[l + 1], weights[l].len())?;
            check_len(&format!("layer {l} bias entries"), sizes[l + 1], biases[l].len())?;
            check_finite(&format!("layer {l} weights"), &weights[l])?;
            check_finite(&format!("layer {l} biases"), &biases[l])?;
        }
        let (n_in, n_out) = (sizes[0], sizes[layers]);
        check_len("input mean entries", n_in, input_mean.len())?;
        check_len("input std entries", n_in, input_std.len())?;
        check_len("output mean entries", n_out, output_mean.len())?;
        check_len("output scale entries", n_out, output_scale.len())?;
        for (what, v) in [
            ("input mean", &input_mean),
            ("input std", &input_std),
            ("output mean", &output_mean),
            ("output scale", &output_scale),
        ] {
            check_finite(what, v)?;
        }
        if let Some(k) = input_std.iter().position(|&s| s <= 0.0) {
            return Err(NnError::Config {
                field: "input_std",
                value: format!("{} (input {k})", input_std[k]),
                allowed: "> 0",
            });
        }
        if let Some(k) = output_scale.iter().position(|&s| s == 0.0) {
            return Err(NnError::Config { field: "output_scale", value: format!("0 (output {k})"), allowed: "!= 0" });
        }
        let mut mlp = Mlp {
            sizes,
            weights,
            biases,
            input_mean,
            input_std,
            output_mean,
            output_scale,
            w32: Vec::new(),
            b32: Vec::new(),
            in_mean32: Vec::new(),
            in_inv_std32: Vec::new(),
            out_mean32: Vec::new(),
            out_scale32: Vec::new(),
            mirror: None,
        };
        mlp.sync_f32();
        Ok(mlp)
    }

    /// He initialisation (weights ~ N(0, 2 / fan_in), biases 0) from a seed, identity
    /// normalisation.
    pub fn he_init(sizes: &[usize], seed: u64) -> Result<Self, NnError> {
        check_sizes(sizes)?;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut weights = Vec::new();
        let mut biases = Vec::new();
        for l in 0..sizes.len() - 1 {
            let std = (2.0 / sizes[l] as f64).sqrt();
            let normal = Normal::new(0.0, std).map_err(|_| NnError::Config {
                field: "sizes",
                value: format!("{sizes:?}"),
                allowed: "layer sizes giving a finite He standard deviation",
            })?;
            weights.push((0..sizes[l] * sizes[l + 1]).map(|_| normal.sample(&mut rng)).collect());
            biases.push(vec![0.0; sizes[l + 1]]);
        }
        let (n_in, n_out) = (sizes[0], sizes[sizes.len() - 1]);
        Self::from_parts(
            sizes.to_vec(),
            weights,
            biases,
            vec![0.0; n_in],
            vec![1.0; n_in],
            vec![0.0; n_out],
            vec![1.0; n_out],
        )
    }

    /// Replaces the input standardisation and output scaling (validated as in [`Mlp::from_parts`]);
    /// keeps the mirror.
    pub fn with_normalisation(
        self,
        input_mean: Vec<f64>,
        input_std: Vec<f64>,
        output_mean: Vec<f64>,
        output_scale: Vec<f64>,
    ) -> Result<Self, NnError> {
        let mirror = self.mirror;
        Self::from_parts(self.sizes, self.weights, self.biases, input_mean, input_std, output_mean, output_scale)?
            .with_mirror(mirror)
    }

    /// Makes the prediction mirror-averaged, ŷ(x) = ½ (N(x) + S N(M x)) (module doc), or plain
    /// (`None`). Validates the mirror against the sizes.
    pub fn with_mirror(mut self, mirror: Option<Mirror>) -> Result<Self, NnError> {
        if let Some(m) = &mirror {
            m.validate(self.n_inputs(), self.n_outputs())?;
        }
        self.mirror = mirror;
        Ok(self)
    }

    /// The mirror the prediction is averaged over, if any.
    pub fn mirror(&self) -> Option<&Mirror> {
        self.mirror.as_ref()
    }

    /// Rebuilds the f32 inference copies after the f64 weights changed.
    pub(crate) fn sync_f32(&mut self) {
        self.w32 = self.weights.iter().map(|w| w.iter().map(|&x| x as f32).collect()).collect();
        self.b32 = self.biases.iter().map(|b| b.iter().map(|&x| x as f32).collect()).collect();
        self.in_mean32 = self.input_mean.iter().map(|&x| x as f32).collect();
        self.in_inv_std32 = self.input_std.iter().map(|&x| (1.0 / x) as f32).collect();
        self.out_mean32 = self.output_mean.iter().map(|&x| x as f32).collect();
        self.out_scale32 = self.output_scale.iter().map(|&x| x as f32).collect();
    }

    /// Layer sizes, input first.
    pub fn sizes(&self) -> &[usize] {
        &self.sizes
    }
    /// Number of inputs.
    pub fn n_inputs(&self) -> usize {
        self.sizes[0]
    }
    /// Number of outputs.
    pub fn n_outputs(&self) -> usize {
        self.sizes[self.sizes.len() - 1]
    }
    /// Number of weight layers.
    pub fn n_layers(&self) -> usize {
        self.sizes.len() - 1
    }
    /// Weights of layer `l` (n_{l+1} × n_l row-major).
    pub fn weights(&self, l: usize) -> &[f64] {
        &self.weights[l]
    }
    /// Biases of layer `l`.
    pub fn biases(&self, l: usize) -> &[f64] {
        &self.biases[l]
    }
    /// Input means μ.
    pub fn input_mean(&self) -> &[f64] {
        &self.input_mean
    }
    /// Input standard deviations σ.
    pub fn input_std(&self) -> &[f64] {
        &self.input_std
    }
    /// Output offsets m.
    pub fn output_mean(&self) -> &[f64] {
        &self.output_mean
    }
    /// Output scales s.
    pub fn output_scale(&self) -> &[f64] {
        &self.output_scale
    }
    /// Number of trainable parameters.
    pub fn n_parameters(&self) -> usize {
        self.weights.iter().chain(&self.biases).map(Vec::len).sum()
    }

    /// The raw network output (before output scaling) of one standardised input, f64. `acts`
    /// receives the post-activation values of every layer (input first); reused between calls.
    pub(crate) fn forward_raw_f64(&self, x_std: &[f64], acts: &mut Vec<Vec<f64>>) {
        acts.resize(self.sizes.len(), Vec::new());
        acts[0].clear();
        acts[0].extend_from_slice(x_std);
        let layers = self.n_layers();
        for l in 0..layers {
            let (n_in, n_out) = (self.sizes[l], self.sizes[l + 1]);
            let (head, tail) = acts.split_at_mut(l + 1);
            let (x, z) = (&head[l], &mut tail[0]);
            z.clear();
            for o in 0..n_out {
                let row = &self.weights[l][o * n_in..(o + 1) * n_in];
                let s: f64 = self.biases[l][o] + row.iter().zip(x.iter()).map(|(w, v)| w * v).sum::<f64>();
                z.push(if l + 1 < layers { s.max(0.0) } else { s });
            }
        }
    }

    /// Standardises one input row.
    pub(crate) fn standardise_f64(&self, x: &[f64], out: &mut [f64]) {
        for (k, o) in out.iter_mut().enumerate() {
            *o = (x[k] - self.input_mean[k]) / self.input_std[k];
        }
    }

    /// f64 outputs of row-major `inputs` (n × n_in) into `outputs` (n × n_out). Allocates its
    /// scratch once per call; for training and evaluation, not for the time loop.
    pub fn predict(&self, inputs: &[f64], outputs: &mut [f64]) -> Result<(), NnError> {
        let (n_in, n_out) = (self.n_inputs(), self.n_outputs());
        let n = inputs.len() / n_in;
        check_len("predict: input entries (multiple of the input size)", n * n_in, inputs.len())?;
        check_len("predict: output entries", n * n_out, outputs.len())?;
        let mut acts = Vec::new();
        let mut xs = vec![0.0; n_in];
        let mut xm = vec![0.0; n_in];
        let mut ym = vec![0.0; n_out];
        for (x, y) in inputs.chunks_exact(n_in).zip(outputs.chunks_exact_mut(n_out)) {
            self.standardise_f64(x, &mut xs);
            self.forward_raw_f64(&xs, &mut acts);
            let raw = &acts[self.n_layers()];
            for k in 0..n_out {
                y[k] = self.output_mean[k] + self.output_scale[k] * raw[k];
            }
            if let Some(m) = &self.mirror {
                m.input(x, &mut xm);
                self.standardise_f64(&xm, &mut xs);
                self.forward_raw_f64(&xs, &mut acts);
                let raw = &acts[self.n_layers()];
                for k in 0..n_out {
                    ym[k] = self.output_mean[k] + self.output_scale[k] * raw[k];
                }
                m.output(&mut ym);
                y.iter_mut().zip(&ym).for_each(|(a, b)| *a = 0.5 * (*a + b));
            }
        }
        Ok(())
    }

    /// One tile: `src` holds the standardised inputs feature-major (n_in rows of `TILE` lanes);
    /// returns whether the result is in `a` (true) or `b`.
    fn run_tile(&self, a: &mut [f32], b: &mut [f32]) -> bool {
        let layers = self.n_layers();
        let mut in_a = true;
        for l in 0..layers {
            let (n_in, n_out) = (self.sizes[l], self.sizes[l + 1]);
            let (src, dst): (&[f32], &mut [f32]) = if in_a { (&*a, &mut *b) } else { (&*b, &mut *a) };
            let src = &src[..n_in * TILE];
            let relu = l + 1 < layers;
            let w = &self.w32[l];
            for ((wrow, &bias), out) in
                w.chunks_exact(n_in).zip(&self.b32[l]).zip(dst[..n_out * TILE].chunks_exact_mut(TILE))
            {
                let mut acc = [bias; TILE];
                for (&wi, x) in wrow.iter().zip(src.chunks_exact(TILE)) {
                    for (s, &xv) in acc.iter_mut().zip(x) {
                        *s += wi * xv;
                    }
                }
                if relu {
                    for s in acc.iter_mut() {
                        *s = s.max(0.0);
                    }
                }
                out.copy_from_slice(&acc);
            }
            in_a = !in_a;
        }
        in_a
    }

    /// The f32 forward pass over `n` samples: `fill(i, row)` writes the raw inputs of sample `i`
    /// into `row` (n_in entries), `emit(i, row)` receives its scaled outputs (n_out entries). No
    /// allocation once `ws` has grown to this network.
    pub fn forward_with<F, G>(&self, n: usize, ws: &mut MlpWorkspace, mut fill: F, mut emit: G)
    where
        F: FnMut(usize, &mut [f32]),
        G: FnMut(usize, &[f32]),
    {
        ws.ensure(self);
        let (n_in, n_out) = (self.n_inputs(), self.n_outputs());
        let MlpWorkspace { a, b, c, mi, row_in, row_out } = ws;
        let mirror = self.mirror.as_ref();
        let mut start = 0;
        while start < n {
            let m = TILE.min(n - start);
            for s in 0..m {
                fill(start + s, row_in);
                for k in 0..n_in {
                    a[k * TILE + s] = (row_in[k] - self.in_mean32[k]) * self.in_inv_std32[k];
                }
                if let Some(mr) = mirror {
                    for &(i, j) in &mr.swap {
                        row_in.swap(i, j);
                    }
                    for &(i, p) in &mr.reflect {
                        row_in[i] = p as f32 - row_in[i];
                    }
                    for k in 0..n_in {
                        mi[k * TILE + s] = (row_in[k] - self.in_mean32[k]) * self.in_inv_std32[k];
                    }
                }
            }
            for k in 0..n_in {
                a[k * TILE + m..(k + 1) * TILE].fill(0.0);
                if mirror.is_some() {
                    mi[k * TILE + m..(k + 1) * TILE].fill(0.0);
                }
            }
            let out: &[f32] = if self.run_tile(a, b) { a } else { b };
            // scaled outputs of the plain pass
            for k in 0..n_out {
                for s in 0..m {
                    c[k * TILE + s] = self.out_mean32[k] + self.out_scale32[k] * out[k * TILE + s];
                }
            }
            if let Some(mr) = mirror {
                // ½ (N(x) + S N(M x)) in scaled units
                a[..n_in * TILE].copy_from_slice(&mi[..n_in * TILE]);
                let out: &[f32] = if self.run_tile(a, b) { a } else { b };
                for k in 0..n_out {
                    let sign = if mr.negate.contains(&k) { -1.0f32 } else { 1.0 };
                    for s in 0..m {
                        let y = self.out_mean32[k] + self.out_scale32[k] * out[k * TILE + s];
                        c[k * TILE + s] = 0.5 * (c[k * TILE + s] + sign * y);
                    }
                }
            }
            for s in 0..m {
                for k in 0..n_out {
                    row_out[k] = c[k * TILE + s];
                }
                emit(start + s, row_out);
            }
            start += m;
        }
    }

    /// f32 outputs of row-major `inputs` (n × n_in) into `outputs` (n × n_out), serial.
    pub fn forward_batch(&self, inputs: &[f32], outputs: &mut [f32], ws: &mut MlpWorkspace) -> Result<(), NnError> {
        let (n_in, n_out) = (self.n_inputs(), self.n_outputs());
        let n = inputs.len() / n_in;
        check_len("forward: input entries (multiple of the input size)", n * n_in, inputs.len())?;
        check_len("forward: output entries", n * n_out, outputs.len())?;
        self.forward_with(
            n,
            ws,
            |i, row| row.copy_from_slice(&inputs[i * n_in..(i + 1) * n_in]),
            |i, row| outputs[i * n_out..(i + 1) * n_out].copy_from_slice(row),
        );
        Ok(())
    }

    /// As [`Mlp::forward_batch`], in chunks of 16 tiles across rayon's threads, each with its
    /// thread's workspace. Same bits as the serial pass.
    pub fn forward_batch_par(&self, inputs: &[f32], outputs: &mut [f32]) -> Result<(), NnError> {
        let (n_in, n_out) = (self.n_inputs(), self.n_outputs());
        let n = inputs.len() / n_in;
        check_len("forward: input entries (multiple of the input size)", n * n_in, inputs.len())?;
        check_len("forward: output entries", n * n_out, outputs.len())?;
        const CHUNK: usize = 16 * TILE;
        inputs
            .par_chunks(CHUNK * n_in)
            .zip(outputs.par_chunks_mut(CHUNK * n_out))
            .try_for_each(|(x, y)| with_thread_workspace(|ws| self.forward_batch(x, y, ws)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng;

    fn net() -> Mlp {
        let m = Mlp::he_init(&[6, 50, 20, 20, 3], 7).expect("valid sizes");
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut m = m
            .with_normalisation(
                (0..6).map(|k| k as f64 * 0.5).collect(),
                (0..6).map(|k| 0.5 + k as f64 * 0.1).collect(),
                vec![1.0, -2.0, 0.5],
                vec![0.3, 2.0, -1.0],
            )
            .expect("valid normalisation");
        // non-zero biases so that they are tested too
        for b in m.biases.iter_mut() {
            for x in b.iter_mut() {
                *x = rng.gen_range(-0.5..0.5);
            }
        }
        m.sync_f32();
        m
    }

    /// Naive reference: the formula of the module doc, written out in f64 with indices.
    #[allow(clippy::needless_range_loop)]
    fn reference(m: &Mlp, x: &[f64]) -> Vec<f64> {
        let mut a: Vec<f64> = x.iter().enumerate().map(|(k, v)| (v - m.input_mean()[k]) / m.input_std()[k]).collect();
        for l in 0..m.n_layers() {
            let (n_in, n_out) = (m.sizes()[l], m.sizes()[l + 1]);
            let mut z = vec![0.0; n_out];
            for (o, zo) in z.iter_mut().enumerate() {
                *zo = m.biases(l)[o];
                for i in 0..n_in {
                    *zo += m.weights(l)[o * n_in + i] * a[i];
                }
                if l + 1 < m.n_layers() {
                    *zo = zo.max(0.0);
                }
            }
            a = z;
        }
        a.iter().enumerate().map(|(k, v)| m.output_mean()[k] + m.output_scale()[k] * v).collect()
    }

    #[test]
    fn f32_and_f64_paths_match_the_naive_formula() {
        let m = net();
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let n = 3 * TILE + 5; // full tiles and a partial one
        let x64: Vec<f64> = (0..n * 6).map(|_| rng.gen_range(-1.0..4.0)).collect();
        let x32: Vec<f32> = x64.iter().map(|&v| v as f32).collect();
        let mut y64 = vec![0.0; n * 3];
        let mut y32 = vec![0.0f32; n * 3];
        m.predict(&x64, &mut y64).expect("sizes match");
        m.forward_batch(&x32, &mut y32, &mut MlpWorkspace::new()).expect("sizes match");
        for i in 0..n {
            let r = reference(&m, &x64[i * 6..(i + 1) * 6]);
            for k in 0..3 {
                assert!((y64[i * 3 + k] - r[k]).abs() <= 1e-12 * (1.0 + r[k].abs()), "f64 sample {i}");
                let e = (y32[i * 3 + k] as f64 - r[k]).abs();
                assert!(e <= 1e-4 * (1.0 + r[k].abs()), "f32 sample {i} output {k}: {} vs {}", y32[i * 3 + k], r[k]);
            }
        }
    }

    #[test]
    fn parallel_pass_gives_the_same_bits_as_the_serial_one() {
        let m = net();
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let n = 40 * TILE + 17;
        let x: Vec<f32> = (0..n * 6).map(|_| rng.gen_range(-1.0..4.0)).collect();
        let mut serial = vec![0.0f32; n * 3];
        let mut par = vec![1.0f32; n * 3];
        m.forward_batch(&x, &mut serial, &mut MlpWorkspace::new()).expect("sizes match");
        m.forward_batch_par(&x, &mut par).expect("sizes match");
        assert!(serial.iter().zip(&par).all(|(a, b)| a.to_bits() == b.to_bits()));
        // and a sample's result does not depend on its position in a tile
        let mut one = vec![0.0f32; 3];
        m.forward_batch(&x[6 * 100..6 * 101], &mut one, &mut MlpWorkspace::new()).expect("sizes match");
        assert_eq!(one, serial[300..303]);
    }

    #[test]
    fn mirror_averaged_prediction_is_the_average_over_the_mirror_in_both_paths() {
        let plain = net();
        let m = plain.clone().with_mirror(Some(Mirror::platelet_n())).expect("fits 6 -> 3");
        let mut rng = ChaCha8Rng::seed_from_u64(17);
        let n = 2 * TILE + 9;
        let x64: Vec<f64> = (0..n * 6).map(|_| rng.gen_range(0.1..6.0)).collect();
        let mut y = vec![0.0; n * 3];
        m.predict(&x64, &mut y).expect("sizes match");
        let mut y32 = vec![0.0f32; n * 3];
        let x32: Vec<f32> = x64.iter().map(|&v| v as f32).collect();
        m.forward_batch(&x32, &mut y32, &mut MlpWorkspace::new()).expect("sizes match");
        for i in 0..n {
            let x = &x64[i * 6..(i + 1) * 6];
            // M x by hand: α_top ↔ α_bot, ψ → 2π − ψ
            let mx = [x[0], x[1], x[2], x[4], x[3], 2.0 * std::f64::consts::PI - x[5]];
            let (a, b) = (reference(&plain, x), reference(&plain, &mx));
            let want = [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1]), 0.5 * (a[2] - b[2])];
            for k in 0..3 {
                assert!((y[i * 3 + k] - want[k]).abs() <= 1e-12 * (1.0 + want[k].abs()), "f64 sample {i} output {k}");
                let e = (y32[i * 3 + k] as f64 - want[k]).abs();
                assert!(
                    e <= 1e-4 * (1.0 + want[k].abs()),
                    "f32 sample {i} output {k}: {} vs {}",
                    y32[i * 3 + k],
                    want[k]
                );
            }
            // exactly symmetric: the prediction at M x is S ŷ(x)
            let mut ym = [0.0; 3];
            m.predict(&mx, &mut ym).expect("sizes match");
            assert!((ym[0] - y[i * 3]).abs() <= 1e-12 * (1.0 + ym[0].abs()));
            assert!((ym[2] + y[i * 3 + 2]).abs() <= 1e-12 * (1.0 + ym[2].abs()));
        }
        // a tile's lanes stay independent with the mirror too
        let mut par = vec![0.0f32; n * 3];
        m.forward_batch_par(&x32, &mut par).expect("sizes match");
        assert!(par.iter().zip(&y32).all(|(a, b)| a.to_bits() == b.to_bits()));
        // a mirror that does not fit the sizes is refused
        let e = plain
            .with_mirror(Some(Mirror { swap: vec![(3, 6)], reflect: vec![], negate: vec![] }))
            .expect_err("input 6");
        assert!(e.to_string().contains("mirror"), "{e}");
        let e = Mirror { swap: vec![(1, 2)], reflect: vec![(2, 1.0)], negate: vec![3] }
            .validate(6, 3)
            .expect_err("output 3");
        assert!(e.to_string().contains("negate"), "{e}");
        assert!(Mirror { swap: vec![(1, 2), (2, 3)], reflect: vec![], negate: vec![] }.validate(6, 3).is_err());
        assert!(Mirror { swap: vec![], reflect: vec![(5, f64::NAN)], negate: vec![] }.validate(6, 3).is_err());
    }

    #[test]
    fn bad_parts_are_rejected_with_the_field_named() {
        let m = net();
        let e = Mlp::from_parts(
            vec![6, 50, 20, 20, 3],
            m.weights.clone(),
            m.biases.clone(),
            vec![0.0; 6],
            vec![1.0, 1.0, 0.0, 1.0, 1.0, 1.0],
            vec![0.0; 3],
            vec![1.0; 3],
        )
        .expect_err("zero std");
        assert!(e.to_string().contains("input_std"), "{e}");
        let mut w = m.weights.clone();
        w[1][3] = f64::NAN;
        let e = Mlp::from_parts(
            m.sizes.clone(),
            w,
            m.biases.clone(),
            vec![0.0; 6],
            vec![1.0; 6],
            vec![0.0; 3],
            vec![1.0; 3],
        )
        .expect_err("NaN weight");
        assert!(e.to_string().contains("layer 1 weights") && e.to_string().contains("index 3"), "{e}");
        let e = Mlp::he_init(&[6], 1).expect_err("one layer size");
        assert!(e.to_string().contains("sizes"), "{e}");
        let mut y = vec![0.0; 5];
        assert!(m.predict(&[0.0; 12], &mut y).is_err());
    }
}
