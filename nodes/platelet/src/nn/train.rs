//! Training of an [`Mlp`] on a [`Dataset`]: mean squared error of the *standardised* outputs
//! (each output minus its training mean, over its training standard deviation, so every output
//! weighs alike), backpropagation in f64, Adam (β₁ = 0.9, β₂ = 0.999, ε = 1e-8, Kingma & Ba 2015)
//! on mini-batches of a seeded shuffle, a cosine learning-rate decay from `learning_rate` to
//! `final_learning_rate` over `epochs`, He initialisation, and the weights of the epoch with the
//! lowest validation loss (a seeded `validation_fraction` of the training set held out), with
//! early stopping after `patience` epochs without improvement.
//!
//! Deterministic: one seed fixes the initial weights, the validation split and every shuffle; the
//! arithmetic is serial, so the same seed and data give the same bits.

use super::data::Dataset;
use super::mlp::Mlp;
use super::NnError;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// Training parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainConfig {
    /// Maximum number of epochs (passes over the training set). Default 400.
    pub epochs: usize,
    /// Samples per mini-batch. Default 64.
    pub batch_size: usize,
    /// Initial Adam step size. Default 1e-2.
    pub learning_rate: f64,
    /// Step size reached at the last epoch (cosine decay). Default 1e-5.
    pub final_learning_rate: f64,
    /// Fraction of the training set held out to pick the best weights, in [0, 0.5]; 0 uses the
    /// training loss instead. Default 0.1.
    pub validation_fraction: f64,
    /// Stop after this many epochs without a lower validation loss; 0 never stops early.
    /// Default 100.
    pub patience: usize,
    /// Seed of the initial weights, the validation split and the shuffles. Default 1.
    pub seed: u64,
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig {
            epochs: 400,
            batch_size: 64,
            learning_rate: 1e-2,
            final_learning_rate: 1e-5,
            validation_fraction: 0.1,
            patience: 100,
            seed: 1,
        }
    }
}

impl TrainConfig {
    /// Checks every field against its allowed range.
    pub fn validate(&self) -> Result<(), NnError> {
        let bad = |field, value: String, allowed| Err(NnError::Config { field, value, allowed });
        if self.epochs == 0 || self.epochs > 1_000_000 {
            return bad("epochs", self.epochs.to_string(), "1..=1000000");
        }
        if self.batch_size == 0 || self.batch_size > 1 << 20 {
            return bad("batch_size", self.batch_size.to_string(), "1..=1048576");
        }
        if !(self.learning_rate.is_finite() && self.learning_rate > 0.0 && self.learning_rate <= 1.0) {
            return bad("learning_rate", self.learning_rate.to_string(), "0 < learning_rate <= 1");
        }
        if !(self.final_learning_rate.is_finite()
            && self.final_learning_rate >= 0.0
            && self.final_learning_rate <= self.learning_rate)
        {
            return bad(
                "final_learning_rate",
                self.final_learning_rate.to_string(),
                "0 <= final_learning_rate <= learning_rate",
            );
        }
        if !(0.0..=0.5).contains(&self.validation_fraction) {
            return bad("validation_fraction", self.validation_fraction.to_string(), "0 <= validation_fraction <= 0.5");
        }
        Ok(())
    }

    /// Step size of `epoch` (0-based): cosine from `learning_rate` to `final_learning_rate`.
    pub fn learning_rate_at(&self, epoch: usize) -> f64 {
        let t = if self.epochs > 1 { epoch as f64 / (self.epochs - 1) as f64 } else { 1.0 };
        self.final_learning_rate
            + 0.5 * (self.learning_rate - self.final_learning_rate) * (1.0 + (std::f64::consts::PI * t).cos())
    }
}

/// What a training run did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainOutcome {
    /// Epochs run (≤ `epochs`; fewer when stopped early).
    pub epochs_run: usize,
    /// Epoch (0-based) whose weights were kept.
    pub best_epoch: usize,
    /// Validation loss (MSE of standardised outputs) of the kept weights.
    pub best_validation_loss: f64,
    /// Training loss per epoch (mean over the epoch's mini-batches, before each step).
    pub training_loss: Vec<f64>,
    /// Validation loss per epoch (after the epoch).
    pub validation_loss: Vec<f64>,
    /// Samples the steps were taken on.
    pub n_train: usize,
    /// Samples held out for validation.
    pub n_validation: usize,
}

/// Gradient buffers shaped like the network's weights and biases.
#[derive(Clone, Debug)]
pub(crate) struct Grads {
    pub(crate) w: Vec<Vec<f64>>,
    pub(crate) b: Vec<Vec<f64>>,
}

impl Grads {
    pub(crate) fn zeros(net: &Mlp) -> Self {
        Grads {
            w: net.weights.iter().map(|w| vec![0.0; w.len()]).collect(),
            b: net.biases.iter().map(|b| vec![0.0; b.len()]).collect(),
        }
    }
    fn clear(&mut self) {
        self.w.iter_mut().chain(self.b.iter_mut()).for_each(|v| v.fill(0.0));
    }
}

/// Scratch of one backpropagation.
#[derive(Default)]
struct Scratch {
    acts: Vec<Vec<f64>>,
    delta: Vec<f64>,
    next: Vec<f64>,
}

/// Adds ∂/∂θ ½‖raw(x) − t‖² of one standardised sample to `g`; returns ‖raw(x) − t‖².
fn accumulate(net: &Mlp, x: &[f64], t: &[f64], s: &mut Scratch, g: &mut Grads) -> f64 {
    net.forward_raw_f64(x, &mut s.acts);
    let layers = net.n_layers();
    let sizes = net.sizes();
    s.delta.clear();
    s.delta.extend(s.acts[layers].iter().zip(t).map(|(y, t)| y - t));
    let sq: f64 = s.delta.iter().map(|d| d * d).sum();
    for l in (0..layers).rev() {
        let (n_in, n_out) = (sizes[l], sizes[l + 1]);
        let a_prev = &s.acts[l];
        for o in 0..n_out {
            let d = s.delta[o];
            g.b[l][o] += d;
            for (gw, a) in g.w[l][o * n_in..(o + 1) * n_in].iter_mut().zip(a_prev) {
                *gw += d * a;
            }
        }
        if l > 0 {
            // δ_{l−1} = (W_lᵀ δ_l) ⊙ ReLU'(z_{l−1}); a > 0 exactly where z > 0
            s.next.clear();
            s.next.resize(n_in, 0.0);
            for o in 0..n_out {
                let d = s.delta[o];
                for (nx, w) in s.next.iter_mut().zip(&net.weights[l][o * n_in..(o + 1) * n_in]) {
                    *nx += w * d;
                }
            }
            for (nx, a) in s.next.iter_mut().zip(a_prev) {
                if *a <= 0.0 {
                    *nx = 0.0;
                }
            }
            std::mem::swap(&mut s.delta, &mut s.next);
        }
    }
    sq
}

/// Loss = mean over samples and outputs of (raw − t)², and its gradient, for standardised
/// row-major `xs` and `ts`.
#[cfg(test)]
pub(crate) fn loss_and_gradient(net: &Mlp, xs: &[f64], ts: &[f64]) -> (f64, Grads) {
    let (n_in, n_out) = (net.n_inputs(), net.n_outputs());
    let mut g = Grads::zeros(net);
    let mut s = Scratch::default();
    let n = xs.len() / n_in;
    let mut sq = 0.0;
    for (x, t) in xs.chunks_exact(n_in).zip(ts.chunks_exact(n_out)) {
        sq += accumulate(net, x, t, &mut s, &mut g);
    }
    let scale = 2.0 / (n * n_out) as f64;
    g.w.iter_mut().chain(g.b.iter_mut()).flatten().for_each(|v| *v *= scale);
    (sq / (n * n_out) as f64, g)
}

/// MSE of standardised outputs over the samples `idx`.
fn loss_of(net: &Mlp, xs: &[f64], ts: &[f64], idx: &[usize], s: &mut Scratch) -> f64 {
    let (n_in, n_out) = (net.n_inputs(), net.n_outputs());
    let mut sq = 0.0;
    for &i in idx {
        net.forward_raw_f64(&xs[i * n_in..(i + 1) * n_in], &mut s.acts);
        sq += s.acts[net.n_layers()]
            .iter()
            .zip(&ts[i * n_out..(i + 1) * n_out])
            .map(|(y, t)| (y - t).powi(2))
            .sum::<f64>();
    }
    sq / (idx.len().max(1) * n_out) as f64
}

/// Adam moments.
struct Adam {
    m: Grads,
    v: Grads,
    step: i32,
}

impl Adam {
    fn update(&mut self, net: &mut Mlp, g: &Grads, lr: f64) {
        const B1: f64 = 0.9;
        const B2: f64 = 0.999;
        const EPS: f64 = 1e-8;
        self.step += 1;
        let c1 = 1.0 - B1.powi(self.step);
        let c2 = 1.0 - B2.powi(self.step);
        let params = net.weights.iter_mut().chain(net.biases.iter_mut());
        let moments =
            self.m.w.iter_mut().chain(self.m.b.iter_mut()).zip(self.v.w.iter_mut().chain(self.v.b.iter_mut()));
        let grads = g.w.iter().chain(g.b.iter());
        for ((p, (m, v)), g) in params.zip(moments).zip(grads) {
            for (((p, m), v), &g) in p.iter_mut().zip(m.iter_mut()).zip(v.iter_mut()).zip(g) {
                *m = B1 * *m + (1.0 - B1) * g;
                *v = B2 * *v + (1.0 - B2) * g * g;
                *p -= lr * (*m / c1) / ((*v / c2).sqrt() + EPS);
            }
        }
    }
}

/// Standardises all rows of `data` with `net`'s normalisation.
fn standardised(net: &Mlp, data: &Dataset) -> (Vec<f64>, Vec<f64>) {
    let n_in = net.n_inputs();
    let mut xs = vec![0.0; data.inputs().len()];
    for (x, o) in data.inputs().chunks_exact(n_in).zip(xs.chunks_exact_mut(n_in)) {
        net.standardise_f64(x, o);
    }
    let ts = data
        .targets()
        .chunks_exact(net.n_outputs())
        .flat_map(|t| t.iter().enumerate().map(|(k, v)| (v - net.output_mean()[k]) / net.output_scale()[k]))
        .collect();
    (xs, ts)
}

/// Trains a network of layer `sizes` on `data` (module doc). The input standardisation and the
/// output scaling are the mean and standard deviation of `data` (a constant column gets σ = 1).
pub fn train(sizes: &[usize], data: &Dataset, cfg: &TrainConfig) -> Result<(Mlp, TrainOutcome), NnError> {
    cfg.validate()?;
    let net = Mlp::he_init(sizes, cfg.seed)?;
    if data.n_inputs() != net.n_inputs() || data.n_outputs() != net.n_outputs() {
        return Err(NnError::Size {
            what: "training data columns (inputs + outputs) for the network".into(),
            expected: net.n_inputs() + net.n_outputs(),
            got: data.n_inputs() + data.n_outputs(),
        });
    }
    if data.len() < 2 {
        return Err(NnError::Size { what: "training samples (at least)".into(), expected: 2, got: data.len() });
    }
    let (im, is) = data.input_stats();
    let (om, os) = data.target_stats();
    let mut net = net.with_normalisation(im, is, om, os)?;
    let (xs, ts) = standardised(&net, data);
    let (n_in, n_out) = (net.n_inputs(), net.n_outputs());

    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x5EED_F00D_DA7A);
    let mut order: Vec<usize> = (0..data.len()).collect();
    order.shuffle(&mut rng);
    let n_val = ((cfg.validation_fraction * data.len() as f64).round() as usize).min(data.len() - 1);
    let (val, train_idx) = order.split_at(n_val);
    let mut train_idx = train_idx.to_vec();
    let val: Vec<usize> = if n_val == 0 { train_idx.clone() } else { val.to_vec() };

    let mut adam = Adam { m: Grads::zeros(&net), v: Grads::zeros(&net), step: 0 };
    let mut g = Grads::zeros(&net);
    let mut s = Scratch::default();
    let mut best = (net.clone(), 0usize, loss_of(&net, &xs, &ts, &val, &mut s));
    let mut outcome = TrainOutcome {
        epochs_run: 0,
        best_epoch: 0,
        best_validation_loss: best.2,
        training_loss: Vec::new(),
        validation_loss: Vec::new(),
        n_train: train_idx.len(),
        n_validation: n_val,
    };
    for epoch in 0..cfg.epochs {
        let lr = cfg.learning_rate_at(epoch);
        train_idx.shuffle(&mut rng);
        let mut epoch_sq = 0.0;
        for batch in train_idx.chunks(cfg.batch_size) {
            g.clear();
            for &i in batch {
                epoch_sq +=
                    accumulate(&net, &xs[i * n_in..(i + 1) * n_in], &ts[i * n_out..(i + 1) * n_out], &mut s, &mut g);
            }
            let scale = 2.0 / (batch.len() * n_out) as f64;
            g.w.iter_mut().chain(g.b.iter_mut()).flatten().for_each(|v| *v *= scale);
            adam.update(&mut net, &g, lr);
        }
        let train_loss = epoch_sq / (train_idx.len() * n_out) as f64;
        let val_loss = loss_of(&net, &xs, &ts, &val, &mut s);
        if !val_loss.is_finite() {
            return Err(NnError::NonFinite { what: format!("validation loss at epoch {epoch}"), index: epoch });
        }
        outcome.training_loss.push(train_loss);
        outcome.validation_loss.push(val_loss);
        outcome.epochs_run = epoch + 1;
        if val_loss < best.2 {
            best = (net.clone(), epoch, val_loss);
        }
        if cfg.patience > 0 && epoch - best.1 >= cfg.patience {
            break;
        }
    }
    let (mut net, best_epoch, best_loss) = best;
    net.sync_f32();
    outcome.best_epoch = best_epoch;
    outcome.best_validation_loss = best_loss;
    Ok((net, outcome))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use rand::Rng;

    #[test]
    fn backpropagation_matches_central_differences() {
        let mut net = Mlp::he_init(&[4, 7, 5, 3], 21).expect("valid sizes");
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        for b in net.biases.iter_mut() {
            b.iter_mut().for_each(|x| *x = rng.gen_range(-0.3..0.3));
        }
        let n = 9;
        let xs: Vec<f64> = (0..n * 4).map(|_| rng.gen_range(-1.5..1.5)).collect();
        let ts: Vec<f64> = (0..n * 3).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let (loss0, g) = loss_and_gradient(&net, &xs, &ts);
        assert!(loss0 > 0.0);
        let h = 1e-6;
        let mut checked = 0;
        for l in 0..net.n_layers() {
            for is_bias in [false, true] {
                let len = if is_bias { net.biases[l].len() } else { net.weights[l].len() };
                for k in 0..len {
                    let mut plus = net.clone();
                    if is_bias {
                        plus.biases[l][k] += h;
                    } else {
                        plus.weights[l][k] += h;
                    }
                    let mut minus = net.clone();
                    if is_bias {
                        minus.biases[l][k] -= h;
                    } else {
                        minus.weights[l][k] -= h;
                    }
                    let fd = (loss_and_gradient(&plus, &xs, &ts).0 - loss_and_gradient(&minus, &xs, &ts).0) / (2.0 * h);
                    let an = if is_bias { g.b[l][k] } else { g.w[l][k] };
                    assert!(
                        (fd - an).abs() <= 1e-6 * (1.0 + an.abs()),
                        "layer {l} bias {is_bias} index {k}: fd {fd} vs {an}"
                    );
                    checked += 1;
                }
            }
        }
        assert_eq!(checked, net.n_parameters());
    }

    #[test]
    fn cosine_schedule_runs_from_the_initial_to_the_final_rate() {
        let cfg = TrainConfig { epochs: 11, learning_rate: 1e-2, final_learning_rate: 1e-4, ..Default::default() };
        assert!((cfg.learning_rate_at(0) - 1e-2).abs() < 1e-15);
        assert!((cfg.learning_rate_at(10) - 1e-4).abs() < 1e-15);
        assert!((cfg.learning_rate_at(5) - 0.5 * (1e-2 + 1e-4)).abs() < 1e-15);
        let e = TrainConfig { validation_fraction: 0.7, ..Default::default() }.validate().expect_err("too large");
        assert!(e.to_string().contains("validation_fraction"), "{e}");
    }

    /// A smooth function with the structure of eq 18: the drag of an anisotropic body,
    /// a cos²ψ + b sin²ψ, over eq 18's factor, with a, b smooth in the shape.
    pub(crate) fn eq18_like(x: &[f64]) -> f64 {
        let (lx, ly, lz, at, ab, psi) = (x[0], x[1], x[2], x[3], x[4], x[5]);
        let a = 78.0
            * (1.0
                + 0.08 * (lx - 3.0)
                + 0.05 * (lz - 3.0)
                + 0.3 * (ly - 0.5)
                + 0.04 * (at - 1.0)
                + 0.02 * (ab * ab - 1.0));
        let b = 62.0
            * (1.0
                + 0.12 * (lx - 3.0)
                + 0.09 * (lz - 3.0)
                + 0.1 * (ly - 0.5) * (ly - 0.5)
                + 0.05 * (at + ab - 2.0).sin());
        ((a + b) / 2.0 - (a - b) / 2.0 * (2.0 * psi).cos()) / (70.0 - 10.0 * (2.0 * psi).cos())
    }

    pub(crate) fn eq18_like_data(n: usize, seed: u64) -> Dataset {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let lo = [2.5, 0.15, 2.5, 0.2, 0.2, 0.0];
        let hi = [3.5, 1.0, 3.5, 2.0, 2.0, 2.0 * std::f64::consts::PI];
        let inputs: Vec<f64> =
            (0..n).flat_map(|_| (0..6).map(|k| rng.gen_range(lo[k]..hi[k])).collect::<Vec<_>>()).collect();
        let targets = inputs.chunks_exact(6).map(eq18_like).collect();
        Dataset::new(6, 1, inputs, targets).expect("finite data")
    }

    #[test]
    fn learns_an_eq18_like_function_to_well_below_one_percent() {
        let data = eq18_like_data(6000, 5);
        let (tr, te) = data.split(0.2, 3).expect("valid");
        let (min, max) = tr.targets().iter().fold((f64::INFINITY, 0.0f64), |(a, b), &y| (a.min(y), b.max(y)));
        // the target varies by tens of percent: a constant predictor would be far off
        assert!(max / min > 1.3, "{min}..{max}");
        // 150 epochs of 4 320 samples: ~1.5 s at opt-level 3; 0.2 % mean, 2 % max when written
        let cfg = TrainConfig { epochs: 150, batch_size: 64, learning_rate: 1e-2, ..Default::default() };
        let (net, outcome) = train(&[6, 50, 20, 20, 1], &tr, &cfg).expect("valid config");
        let e = crate::nn::evaluate(&net, &te).expect("sizes match")[0];
        eprintln!("eq18-like test error: {e:?}, best epoch {} of {}", outcome.best_epoch, outcome.epochs_run);
        assert!(e.mean_rel_pct < 0.3, "{e:?}");
        assert!(e.max_rel_pct < 3.0, "{e:?}");
        // deterministic: the same seed gives the same weights
        let (again, _) = train(&[6, 50, 20, 20, 1], &tr, &TrainConfig { epochs: 3, ..cfg.clone() }).expect("valid");
        let (again2, _) = train(&[6, 50, 20, 20, 1], &tr, &TrainConfig { epochs: 3, ..cfg }).expect("valid");
        assert_eq!(again, again2);
    }
}
