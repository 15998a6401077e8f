//! Full-batch L-BFGS refinement after Adam (the module doc of `train`: Nocedal & Wright 2006,
//! Algorithm 7.4).

use super::{batch_loss, flat_parameters, set_flat_parameters, Grads, Samples, Scratch, TrainOutcome, LBFGS_MEMORY};
use crate::nn::mlp::Mlp;

/// Two-loop recursion: −H g from the stored pairs (s, y), with H₀ = (sᵀy / yᵀy) I.
fn lbfgs_direction(g: &[f64], pairs: &std::collections::VecDeque<(Vec<f64>, Vec<f64>, f64)>) -> Vec<f64> {
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let mut q = g.to_vec();
    let mut alpha = vec![0.0; pairs.len()];
    for (k, (s, y, rho)) in pairs.iter().enumerate().rev() {
        alpha[k] = rho * dot(s, &q);
        q.iter_mut().zip(y).for_each(|(q, y)| *q -= alpha[k] * y);
    }
    if let Some((s, y, _)) = pairs.back() {
        let gamma = dot(s, y) / dot(y, y);
        q.iter_mut().for_each(|v| *v *= gamma);
    }
    for (k, (s, y, rho)) in pairs.iter().enumerate() {
        let beta = rho * dot(y, &q);
        q.iter_mut().zip(s).for_each(|(q, s)| *q += (alpha[k] - beta) * s);
    }
    q.iter_mut().for_each(|v| *v = -*v);
    q
}

/// Full-batch L-BFGS from `start` (module doc); returns the iterate with the lowest validation
/// loss if one beats `start_val`.
pub(super) fn refine(
    start: &Mlp,
    samples: &Samples,
    train_idx: &[usize],
    val: &[usize],
    iterations: usize,
    start_val: f64,
    outcome: &mut TrainOutcome,
) -> Option<(Mlp, f64)> {
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let mut net = start.clone();
    let mut s = Scratch::default();
    let mut g = Grads::zeros(&net);
    let mut x = flat_parameters(&net);
    let mut f = batch_loss(&net, samples, train_idx, &mut s, Some(&mut g));
    let mut gx = g.flat();
    let mut pairs: std::collections::VecDeque<(Vec<f64>, Vec<f64>, f64)> = std::collections::VecDeque::new();
    let mut best: Option<(Mlp, f64)> = None;
    let mut best_val = start_val;
    let mut trial = net.clone();
    for it in 1..=iterations {
        let mut d = lbfgs_direction(&gx, &pairs);
        let mut slope = dot(&gx, &d);
        if slope >= 0.0 || slope.is_nan() {
            // not a descent direction: restart from steepest descent
            pairs.clear();
            d = gx.iter().map(|v| -v).collect();
            slope = dot(&gx, &d);
        }
        if pairs.is_empty() {
            // first step (or restart): a small step along −g
            let gmax = gx.iter().fold(0.0f64, |a, v| a.max(v.abs())).max(f64::MIN_POSITIVE);
            let scale = 1e-3 / gmax;
            d.iter_mut().for_each(|v| *v *= scale);
            slope *= scale;
        }
        // Armijo backtracking from the unit step
        let mut t = 1.0;
        let mut accepted = None;
        for _ in 0..40 {
            let xn: Vec<f64> = x.iter().zip(&d).map(|(a, b)| a + t * b).collect();
            set_flat_parameters(&mut trial, &xn);
            let fnew = batch_loss(&trial, samples, train_idx, &mut s, Some(&mut g));
            if fnew.is_finite() && fnew <= f + 1e-4 * t * slope {
                accepted = Some((xn, fnew));
                break;
            }
            t *= 0.5;
        }
        let Some((xn, fnew)) = accepted else { break };
        let gn = g.flat();
        let sv: Vec<f64> = xn.iter().zip(&x).map(|(a, b)| a - b).collect();
        let yv: Vec<f64> = gn.iter().zip(&gx).map(|(a, b)| a - b).collect();
        let sy = dot(&sv, &yv);
        if sy > 1e-12 * dot(&sv, &sv).sqrt() * dot(&yv, &yv).sqrt() {
            if pairs.len() == LBFGS_MEMORY {
                pairs.pop_front();
            }
            pairs.push_back((sv, yv, 1.0 / sy));
        }
        x = xn;
        f = fnew;
        gx = gn;
        set_flat_parameters(&mut net, &x);
        let v = batch_loss(&net, samples, val, &mut s, None);
        outcome.refine_iterations_run = it;
        outcome.refine_training_loss.push(f);
        outcome.refine_validation_loss.push(v);
        if v < best_val {
            best_val = v;
            outcome.refine_best_iteration = it;
            best = Some((net.clone(), v));
        }
    }
    best
}
