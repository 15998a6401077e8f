//! Data sets, the seeded 80/20 split of paper 2 §4.3.1 and the error metrics of its Table 1.
//!
//! **Errors** ([`ErrorStats`]), per output k over a set of n samples with targets y_i and network
//! outputs ŷ_i, both in the *scaled* quantities of eq 18 (d, l, t_p, t_r — eq 18 makes them O(1)):
//!
//! - relative error of a sample: e_i = |ŷ_i − y_i| / |y_i| (∞ where y_i = 0 and ŷ_i ≠ y_i);
//!   `mean_rel_pct` = 100 · (1/n) Σ e_i, `max_rel_pct` = 100 · max e_i. This is Table 1's
//!   "avg" and "max".
//! - relative to the set's RMS: r_i = |ŷ_i − y_i| / √((1/n) Σ y_j²); `mean_rms_pct` and
//!   `max_rms_pct` likewise. For outputs that can be near zero (the pitching torque of a nearly
//!   symmetric platelet), where e_i blows up although the network is accurate.

use super::mlp::Mlp;
use super::train::{train, TrainConfig, TrainOutcome};
use super::NnError;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::fmt::Write;

/// Samples as row-major inputs (n × n_inputs) and targets (n × n_outputs), all finite.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Dataset {
    n_inputs: usize,
    n_outputs: usize,
    inputs: Vec<f64>,
    targets: Vec<f64>,
    /// Group of each sample (e.g. the shape it comes from), or empty: every sample its own group.
    /// The validation split of [`super::train::train`] keeps a group together.
    #[serde(default)]
    groups: Vec<u64>,
}

impl Dataset {
    /// Validates the lengths (a whole number of rows, the same in both) and finiteness.
    pub fn new(n_inputs: usize, n_outputs: usize, inputs: Vec<f64>, targets: Vec<f64>) -> Result<Self, NnError> {
        if n_inputs == 0 || n_outputs == 0 {
            return Err(NnError::Config {
                field: "n_inputs/n_outputs",
                value: format!("{n_inputs}/{n_outputs}"),
                allowed: ">= 1 each",
            });
        }
        let n = inputs.len() / n_inputs;
        if n * n_inputs != inputs.len() {
            return Err(NnError::Config {
                field: "inputs",
                value: format!("{} entries", inputs.len()),
                allowed: "a whole number of rows of n_inputs entries",
            });
        }
        if targets.len() != n * n_outputs {
            return Err(NnError::Size {
                what: "data set target entries".into(),
                expected: n * n_outputs,
                got: targets.len(),
            });
        }
        for (what, v) in [("data set inputs", &inputs), ("data set targets", &targets)] {
            if let Some(index) = v.iter().position(|x| !x.is_finite()) {
                return Err(NnError::NonFinite { what: what.into(), index });
            }
        }
        Ok(Dataset { n_inputs, n_outputs, inputs, targets, groups: Vec::new() })
    }

    /// The same samples with a group per sample (e.g. the shape index; samples of one group stay
    /// on one side of the validation split).
    pub fn with_groups(mut self, groups: Vec<u64>) -> Result<Self, NnError> {
        if groups.len() != self.len() {
            return Err(NnError::Size { what: "data set groups".into(), expected: self.len(), got: groups.len() });
        }
        self.groups = groups;
        Ok(self)
    }

    /// Group of each sample (empty: none given, every sample is its own group).
    pub fn groups(&self) -> &[u64] {
        &self.groups
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.inputs.len() / self.n_inputs
    }
    /// No samples.
    pub fn is_empty(&self) -> bool {
        self.inputs.is_empty()
    }
    /// Inputs per sample.
    pub fn n_inputs(&self) -> usize {
        self.n_inputs
    }
    /// Outputs per sample.
    pub fn n_outputs(&self) -> usize {
        self.n_outputs
    }
    /// All inputs, row-major.
    pub fn inputs(&self) -> &[f64] {
        &self.inputs
    }
    /// All targets, row-major.
    pub fn targets(&self) -> &[f64] {
        &self.targets
    }

    /// The samples `idx`, in that order.
    pub fn subset(&self, idx: &[usize]) -> Dataset {
        let (a, b) = (self.n_inputs, self.n_outputs);
        Dataset {
            n_inputs: a,
            n_outputs: b,
            inputs: idx.iter().flat_map(|&i| self.inputs[i * a..(i + 1) * a].iter().copied()).collect(),
            targets: idx.iter().flat_map(|&i| self.targets[i * b..(i + 1) * b].iter().copied()).collect(),
            groups: if self.groups.is_empty() { Vec::new() } else { idx.iter().map(|&i| self.groups[i]).collect() },
        }
    }

    /// (training, test): a seeded shuffle, then the first round((1 − `test_fraction`) n) samples
    /// train. The paper uses `test_fraction` = 0.2.
    pub fn split(&self, test_fraction: f64, seed: u64) -> Result<(Dataset, Dataset), NnError> {
        if !(test_fraction > 0.0 && test_fraction < 1.0) {
            return Err(NnError::Config {
                field: "test_fraction",
                value: test_fraction.to_string(),
                allowed: "0 < test_fraction < 1",
            });
        }
        let mut idx: Vec<usize> = (0..self.len()).collect();
        idx.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
        let n_train = ((1.0 - test_fraction) * self.len() as f64).round() as usize;
        Ok((self.subset(&idx[..n_train]), self.subset(&idx[n_train..])))
    }

    fn column_stats(v: &[f64], width: usize) -> (Vec<f64>, Vec<f64>) {
        let n = (v.len() / width).max(1) as f64;
        let mut mean = vec![0.0; width];
        for row in v.chunks_exact(width) {
            mean.iter_mut().zip(row).for_each(|(m, x)| *m += x / n);
        }
        let mut var = vec![0.0; width];
        for row in v.chunks_exact(width) {
            var.iter_mut().zip(row).zip(&mean).for_each(|((s, x), m)| *s += (x - m).powi(2) / n);
        }
        let std = var
            .iter()
            .zip(&mean)
            .map(|(v, m): (&f64, &f64)| {
                let s = v.sqrt();
                // a constant column: no scaling rather than a division by ~0
                if s > 1e-12 * (1.0 + m.abs()) {
                    s
                } else {
                    1.0
                }
            })
            .collect();
        (mean, std)
    }

    /// Mean and standard deviation of each input (σ = 1 for a constant column).
    pub fn input_stats(&self) -> (Vec<f64>, Vec<f64>) {
        Self::column_stats(&self.inputs, self.n_inputs)
    }
    /// Mean and standard deviation of each target (σ = 1 for a constant column).
    pub fn target_stats(&self) -> (Vec<f64>, Vec<f64>) {
        Self::column_stats(&self.targets, self.n_outputs)
    }
}

/// Error statistics of one output over one set, in % (module doc).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ErrorStats {
    /// Mean of |ŷ − y| / |y| \[%\].
    pub mean_rel_pct: f64,
    /// Max of |ŷ − y| / |y| \[%\].
    pub max_rel_pct: f64,
    /// Mean of |ŷ − y| / rms(y) \[%\].
    pub mean_rms_pct: f64,
    /// Max of |ŷ − y| / rms(y) \[%\].
    pub max_rms_pct: f64,
}

/// The errors of every output over one named set.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SetErrors {
    /// "training", "test" or "generalisation".
    pub set: String,
    /// Samples in the set.
    pub n: usize,
    /// One entry per output.
    pub per_output: Vec<ErrorStats>,
}

/// Errors of `net` on `data` (module doc), from the f64 forward pass.
pub fn evaluate(net: &Mlp, data: &Dataset) -> Result<Vec<ErrorStats>, NnError> {
    if data.n_inputs() != net.n_inputs() || data.n_outputs() != net.n_outputs() {
        return Err(NnError::Size {
            what: "evaluation data columns (inputs + outputs) for the network".into(),
            expected: net.n_inputs() + net.n_outputs(),
            got: data.n_inputs() + data.n_outputs(),
        });
    }
    let k_out = net.n_outputs();
    let mut pred = vec![0.0; data.targets().len()];
    net.predict(data.inputs(), &mut pred)?;
    let n = data.len().max(1) as f64;
    let mut out = Vec::with_capacity(k_out);
    for k in 0..k_out {
        let col = || data.targets().iter().skip(k).step_by(k_out).zip(pred.iter().skip(k).step_by(k_out));
        let rms = (col().map(|(y, _)| y * y).sum::<f64>() / n).sqrt();
        let (mut s_rel, mut m_rel, mut s_rms, mut m_rms) = (0.0, 0.0f64, 0.0, 0.0f64);
        for (y, p) in col() {
            let d = (p - y).abs();
            let rel = if d == 0.0 { 0.0 } else { d / y.abs() };
            let r = if d == 0.0 { 0.0 } else { d / rms };
            s_rel += rel;
            m_rel = m_rel.max(rel);
            s_rms += r;
            m_rms = m_rms.max(r);
        }
        out.push(ErrorStats {
            mean_rel_pct: 100.0 * s_rel / n,
            max_rel_pct: 100.0 * m_rel,
            mean_rms_pct: 100.0 * s_rms / n,
            max_rms_pct: 100.0 * m_rms,
        });
    }
    Ok(out)
}

/// A trained network's accuracy in the layout of Table 1, and how the training went.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainingReport {
    /// Network name ("N", "N_r", "N_s").
    pub network: String,
    /// Layer sizes.
    pub sizes: Vec<usize>,
    /// Output names (rows of the table).
    pub outputs: Vec<String>,
    /// Training, test and (if given) generalisation errors.
    pub sets: Vec<SetErrors>,
    /// The training run.
    pub outcome: TrainOutcome,
}

impl TrainingReport {
    /// Table 1 as markdown: one row per output, avg and max per set; first the relative error,
    /// then the error relative to the set's RMS.
    pub fn to_markdown(&self) -> String {
        let sizes: Vec<String> = self.sizes.iter().map(ToString::to_string).collect();
        let mut s = String::new();
        for (title, rms) in
            [("relative error |ŷ − y| / |y|", false), ("error relative to the set's RMS |ŷ − y| / rms(y)", true)]
        {
            let _ = writeln!(s, "{} ({}), {title}, %:\n", self.network, sizes.join("-"));
            let mut head = String::from("| output |");
            let mut rule = String::from("|---|");
            for set in &self.sets {
                let _ = write!(head, " {} avg | {} max |", set.set, set.set);
                rule.push_str("---:|---:|");
            }
            let _ = writeln!(s, "{head}\n{rule}");
            for (k, name) in self.outputs.iter().enumerate() {
                let _ = write!(s, "| {name} |");
                for set in &self.sets {
                    let e = set.per_output.get(k);
                    let (a, m) = match e {
                        Some(e) if rms => (e.mean_rms_pct, e.max_rms_pct),
                        Some(e) => (e.mean_rel_pct, e.max_rel_pct),
                        None => (f64::NAN, f64::NAN),
                    };
                    let _ = write!(s, " {a:.2} | {m:.2} |");
                }
                s.push('\n');
            }
            s.push('\n');
        }
        let o = &self.outcome;
        let _ = writeln!(
            s,
            "{} training / {} validation samples, {} epochs, best epoch {} (validation MSE of standardised outputs {:.3e}); sets: {}",
            o.n_train,
            o.n_validation,
            o.epochs_run,
            o.best_epoch,
            o.best_validation_loss,
            self.sets.iter().map(|x| format!("{} n = {}", x.set, x.n)).collect::<Vec<_>>().join(", ")
        );
        if o.refine_iterations_run > 0 {
            let _ = writeln!(
                s,
                "\nL-BFGS refinement: {} iteration(s), kept {} (0: Adam's weights).",
                o.refine_iterations_run, o.refine_best_iteration
            );
        }
        s
    }
}

/// Splits `data` into training and test (`test_fraction`, seeded by `cfg.seed`), trains on the
/// training part and reports the errors on training, test and, if given, the `generalisation`
/// set (e.g. shapes outside eq 7's bounds).
pub fn train_and_report(
    network: &str,
    sizes: &[usize],
    outputs: &[&str],
    data: &Dataset,
    generalisation: Option<&Dataset>,
    test_fraction: f64,
    cfg: &TrainConfig,
) -> Result<(Mlp, TrainingReport), NnError> {
    if outputs.len() != data.n_outputs() {
        return Err(NnError::Size { what: "output names".into(), expected: data.n_outputs(), got: outputs.len() });
    }
    let (tr, te) = data.split(test_fraction, cfg.seed)?;
    let (net, outcome) = train(sizes, &tr, cfg)?;
    let mut sets = vec![
        SetErrors { set: "training".into(), n: tr.len(), per_output: evaluate(&net, &tr)? },
        SetErrors { set: "test".into(), n: te.len(), per_output: evaluate(&net, &te)? },
    ];
    if let Some(g) = generalisation {
        sets.push(SetErrors { set: "generalisation".into(), n: g.len(), per_output: evaluate(&net, g)? });
    }
    let report = TrainingReport {
        network: network.into(),
        sizes: sizes.to_vec(),
        outputs: outputs.iter().map(|s| s.to_string()).collect(),
        sets,
        outcome,
    };
    Ok((net, report))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_is_seeded_disjoint_and_complete() {
        let n = 101;
        let d = Dataset::new(1, 1, (0..n).map(f64::from).collect(), (0..n).map(|i| f64::from(i) * 2.0).collect())
            .expect("valid data");
        let (a, b) = d.split(0.2, 9).expect("valid fraction");
        assert_eq!((a.len(), b.len()), (81, 20));
        let mut all: Vec<f64> = a.inputs().iter().chain(b.inputs()).copied().collect();
        all.sort_by(f64::total_cmp);
        assert_eq!(all, (0..n).map(f64::from).collect::<Vec<_>>());
        // targets stay with their inputs
        assert!(a.inputs().iter().zip(a.targets()).all(|(x, y)| *y == 2.0 * x));
        assert_eq!(d.split(0.2, 9).expect("valid").0, a);
        assert_ne!(d.split(0.2, 10).expect("valid").0, a);
        assert!(d.split(1.0, 9).is_err());
    }

    #[test]
    fn errors_follow_their_definitions() {
        // identity network: ŷ = x; targets y, predictions x
        let net =
            Mlp::from_parts(vec![1, 1], vec![vec![1.0]], vec![vec![0.0]], vec![0.0], vec![1.0], vec![0.0], vec![1.0])
                .expect("valid");
        let y = [1.0, -2.0, 4.0, 0.5];
        let p = [1.1, -2.0, 3.0, 0.5];
        let d = Dataset::new(1, 1, p.to_vec(), y.to_vec()).expect("valid");
        let e = evaluate(&net, &d).expect("sizes match")[0];
        let rel = [0.1, 0.0, 0.25, 0.0];
        assert!((e.mean_rel_pct - 100.0 * rel.iter().sum::<f64>() / 4.0).abs() < 1e-9);
        assert!((e.max_rel_pct - 25.0).abs() < 1e-9);
        let rms = ((1.0 + 4.0 + 16.0 + 0.25) / 4.0f64).sqrt();
        assert!((e.mean_rms_pct - 100.0 * 1.1 / 4.0 / rms).abs() < 1e-9);
        assert!((e.max_rms_pct - 100.0 / rms).abs() < 1e-9);
        let bad = Dataset::new(1, 1, vec![1.0, f64::NAN], vec![1.0, 2.0]).expect_err("NaN input");
        assert!(bad.to_string().contains("inputs") && bad.to_string().contains("index 1"), "{bad}");
    }

    #[test]
    fn report_has_table_1_layout_and_the_errors_of_the_split() {
        let data = crate::nn::train::tests::eq18_like_data(300, 1);
        let gen = crate::nn::train::tests::eq18_like_data(50, 2);
        let cfg = TrainConfig { epochs: 5, seed: 4, ..Default::default() };
        let (net, r) = train_and_report("N", &[6, 8, 1], &["d"], &data, Some(&gen), 0.2, &cfg).expect("valid");
        let names: Vec<(&str, usize)> = r.sets.iter().map(|s| (s.set.as_str(), s.n)).collect();
        assert_eq!(names, [("training", 240), ("test", 60), ("generalisation", 50)]);
        // the test errors are those of the same seeded split, recomputed
        let (_, te) = data.split(0.2, 4).expect("valid");
        assert_eq!(r.sets[1].per_output, evaluate(&net, &te).expect("sizes match"));
        let md = r.to_markdown();
        assert!(md.contains("| output | training avg | training max | test avg | test max | generalisation avg | generalisation max |"), "{md}");
        let e: Vec<ErrorStats> = r.sets.iter().map(|s| s.per_output[0]).collect();
        let row = format!(
            "| d | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} |",
            e[0].mean_rel_pct,
            e[0].max_rel_pct,
            e[1].mean_rel_pct,
            e[1].max_rel_pct,
            e[2].mean_rel_pct,
            e[2].max_rel_pct
        );
        assert!(md.contains(&row), "{row}\n{md}");
        let row = format!("| d | {:.2} | {:.2} |", e[0].mean_rms_pct, e[0].max_rms_pct);
        assert!(md.contains(&row), "{md}");
        assert!(serde_json::to_string(&r).expect("serialisable").contains("\"generalisation\""));
        assert!(train_and_report("N", &[6, 8, 1], &["d", "l"], &data, None, 0.2, &cfg).is_err());
    }
}
