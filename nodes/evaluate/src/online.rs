//! A run's evaluation as its messages arrive, in any order and over any number of inputs (what
//! the `evaluator` node does, without IPC): ground-truth fields, estimated fields (by name, e.g.
//! `raw`, `regularised`) and Doppler maps are matched by packet; each estimate is evaluated as
//! soon as its packet's truth is there, its errors pooled per field, and the maps' looks pooled
//! per look. [`OnlineEvaluation::finish`] gives the [`Evaluation`] and draws the figures.

use crate::evaluation::*;
use crate::metrics::FieldError;
use sonoflow_messages::plane;
use std::collections::BTreeMap;
use std::path::Path;

/// One estimate evaluated against its packet's truth.
#[derive(Clone, Debug)]
pub struct Evaluated {
    /// The packet.
    pub packet: u32,
    /// The estimated field's name (`raw`, `regularised`, …).
    pub name: String,
    /// Its errors.
    pub error: FieldError,
    /// Frame id and time of validity of the packet's truth.
    pub frame_id: u64,
    pub t_valid: f64,
}

/// The evaluation so far: see the module doc.
pub struct OnlineEvaluation {
    params: EvaluatorParams,
    truths: BTreeMap<u32, Field>,
    estimates: BTreeMap<(u32, String), Field>,
    done: BTreeMap<u32, PacketEval>,
    fig: FigureData,
    /// Per field: pooled errors, pixels, pixels without estimate, largest v_max.
    pooled: BTreeMap<String, Pooled>,
    /// Maps waiting for their packet's truth, and the per-look pools.
    look_pending: BTreeMap<u32, Vec<Map>>,
    look_pools: BTreeMap<(u64, u64, u64), LookPool>,
    clutter: Vec<ClutterUse>,
    field_clutter: BTreeMap<String, FieldClutter>,
}

impl OnlineEvaluation {
    pub fn new(params: EvaluatorParams) -> Self {
        Self {
            params,
            truths: BTreeMap::new(),
            estimates: BTreeMap::new(),
            done: BTreeMap::new(),
            fig: FigureData::default(),
            pooled: BTreeMap::new(),
            look_pending: BTreeMap::new(),
            look_pools: BTreeMap::new(),
            clutter: Vec::new(),
            field_clutter: BTreeMap::new(),
        }
    }

    /// The parameters.
    pub fn params(&self) -> &EvaluatorParams {
        &self.params
    }

    /// A packet's ground truth (planes vx, vz, mask).
    pub fn add_truth(&mut self, truth: Field) {
        self.truths.insert(truth.0.packet, truth);
    }

    /// An estimated field named `name` (planes vx, vz, optional flags).
    pub fn add_estimate(&mut self, name: &str, est: Field) {
        FieldClutter::tally(&mut self.field_clutter, name, &est.0);
        self.estimates.insert((est.0.packet, name.to_string()), est);
    }

    /// A colour Doppler map: its look is evaluated if it carries the projection planes, and the
    /// figures keep the most recent maps.
    pub fn add_map(&mut self, m: Map) {
        ClutterUse::tally(&mut self.clutter, &m.0);
        if map_plane(&m.0, &m.1, plane::PROJECTION_X).is_some() {
            self.look_pending.entry(m.0.packet).or_default().push(m.clone());
        }
        if self.params.figures {
            self.fig.keep_map(m);
        }
    }

    /// A B-mode image of `packet` for the report's figure (kept when figures are on; the most
    /// recent 4 packets).
    pub fn add_bmode(&mut self, packet: u32, b: crate::evaluation::Bmode) {
        if self.params.figures {
            self.fig.keep_bmode(packet, b);
        }
    }

    /// Evaluates every estimate and map whose packet's truth has arrived; returns the estimates
    /// evaluated, in (packet, name) order.
    pub fn evaluate_ready(&mut self) -> anyhow::Result<Vec<Evaluated>> {
        let mut evaluated = Vec::new();
        let ready: Vec<(u32, String)> =
            self.estimates.keys().filter(|(pk, _)| self.truths.contains_key(pk)).cloned().collect();
        for key in ready {
            let (Some(est), Some(truth)) = (self.estimates.remove(&key), self.truths.get(&key.0)) else { continue };
            let (fe, smp) = evaluate_pair_samples(truth, &est, self.params.margin)?;
            let entry = self.done.entry(key.0).or_insert_with(|| PacketEval {
                packet: key.0,
                t_valid: truth.0.common.t_valid,
                fields: BTreeMap::new(),
            });
            pool(self.pooled.entry(key.1.clone()).or_default(), &fe, &smp);
            entry.fields.insert(key.1.clone(), fe.clone());
            if self.params.figures {
                let pooled = self.fig.samples.entry(key.1.clone()).or_default();
                pooled.0.extend(smp.ex);
                pooled.1.extend(smp.ez);
                self.fig.keep_estimate(key.0, truth, &key.1, est);
            }
            let (frame_id, t_valid) = (truth.0.common.frame_id, truth.0.common.t_valid);
            evaluated.push(Evaluated { packet: key.0, name: key.1, error: fe, frame_id, t_valid });
        }
        let ready: Vec<u32> = self.look_pending.keys().filter(|pk| self.truths.contains_key(pk)).copied().collect();
        for pk in ready {
            let (Some(maps), Some(truth)) = (self.look_pending.remove(&pk), self.truths.get(&pk)) else { continue };
            for m in &maps {
                pool_look(&mut self.look_pools, truth, m, self.params.margin)?;
            }
        }
        Ok(evaluated)
    }

    /// What never met its truth: one line per packet and field (or Doppler maps).
    pub fn unmatched(&self) -> Vec<String> {
        let est =
            self.estimates.keys().map(|(pk, name)| format!("no ground truth for packet {pk} ({name}): not evaluated"));
        let maps = self
            .look_pending
            .keys()
            .map(|pk| format!("no ground truth for packet {pk} (Doppler maps): per-look errors left out"));
        est.chain(maps).collect()
    }

    /// The evaluation: packets, pooled errors per field and per look; with `figures_dir` (and
    /// `figures = true`) the figures drawn into `figures_dir/figures/` (a figure that cannot be
    /// drawn is a warning in the evaluation).
    pub fn finish(self, figures_dir: Option<&Path>) -> Evaluation {
        let mut eval =
            Evaluation { label: self.params.label.clone(), margin: self.params.margin, ..Default::default() };
        eval.packets = self.done.into_values().collect();
        eval.overall = overall(self.pooled);
        eval.looks = looks(self.look_pools);
        eval.clutter = self.clutter;
        eval.field_clutter = self.field_clutter;
        if let (Some(dir), true) = (figures_dir, self.params.figures) {
            (eval.figures, eval.warnings) = write_figures(dir, &self.fig, eval.packets.len(), &self.params.label);
        }
        eval
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use sonoflow_messages::{GridV1, VectorFieldHeaderV2};

    fn field(packet: u32, planes: &[(u32, Vec<f32>)]) -> Field {
        let grid = GridV1 { x0: 0.0, z0: 0.0, dx: 1e-4, dz: 1e-4, nx: 12, nz: 10 };
        let mut h = VectorFieldHeaderV2 { grid, packet, n_planes: planes.len() as u32, ..Default::default() };
        for (k, (id, _)) in planes.iter().enumerate() {
            h.plane_ids[k] = *id;
        }
        h.common.frame_id = 100 + u64::from(packet);
        (h, planes.iter().flat_map(|(_, d)| d.iter().copied()).collect())
    }

    /// Estimates wait for their truth, whatever the order of arrival; each is evaluated once, as
    /// `evaluate_pair` would; the pooled figure covers both packets; what never met a truth is
    /// named.
    #[test]
    fn estimates_meet_their_truth_in_any_order() {
        let n = 120;
        let mask: Vec<f32> = (0..n).map(|i| if (i / 12) % 9 != 0 { 1.0 } else { 0.0 }).collect();
        let vx: Vec<f32> = mask.iter().map(|m| 0.3 * m).collect();
        let noisy = |k: usize| -> Vec<f32> {
            vx.iter().enumerate().map(|(i, v)| v + 0.01 * ((i * k % 5) as f32 - 2.0)).collect()
        };
        let zero = vec![0.0f32; n];
        let truth = |pk| field(pk, &[(plane::VX, vx.clone()), (plane::VZ, zero.clone()), (plane::MASK, mask.clone())]);
        let est = |pk, k| field(pk, &[(plane::VX, noisy(k)), (plane::VZ, zero.clone())]);

        let p = EvaluatorParams { margin: 0, figures: false, ..Default::default() };
        let mut ev = OnlineEvaluation::new(p);
        ev.add_estimate("raw", est(1, 3));
        ev.add_estimate("raw", est(7, 2));
        assert!(ev.evaluate_ready().unwrap().is_empty(), "no truth yet");
        ev.add_truth(truth(1));
        let done = ev.evaluate_ready().unwrap();
        assert_eq!(done.len(), 1);
        assert_eq!((done[0].packet, done[0].name.as_str(), done[0].frame_id), (1, "raw", 101));
        assert_eq!(done[0].error, evaluate_pair(&truth(1), &est(1, 3), 0).unwrap());
        assert!(ev.evaluate_ready().unwrap().is_empty(), "evaluated once");
        ev.add_truth(truth(2));
        ev.add_estimate("raw", est(2, 4));
        assert_eq!(ev.evaluate_ready().unwrap().len(), 1);
        assert_eq!(ev.unmatched(), vec!["no ground truth for packet 7 (raw): not evaluated".to_string()]);
        let e = ev.finish(None);
        assert_eq!(e.packets.iter().map(|p| p.packet).collect::<Vec<_>>(), vec![1, 2]);
        let pooled = &e.overall["raw"];
        assert_eq!(pooled.pixels, e.packets.iter().map(|p| p.fields["raw"].pixels).sum::<usize>());
        assert!(e.figures.is_empty() && e.looks.is_empty());
    }

    /// The clutter filter of every map is tallied from its header into the evaluation and its
    /// report line; maps without a filter add nothing.
    #[test]
    fn clutter_filters_of_the_maps_are_reported() {
        use sonoflow_messages::{DopplerMapHeaderV2, CLUTTER_NONE, CLUTTER_SVD};
        let mut ev = OnlineEvaluation::new(EvaluatorParams { figures: false, ..Default::default() });
        let map = |filter, rank, removed| {
            let h = DopplerMapHeaderV2 {
                clutter_filter: filter,
                clutter_order: rank,
                clutter_cutoff: 0.05,
                clutter_removed_energy: removed,
                ..Default::default()
            };
            (h, Vec::new())
        };
        ev.add_map(map(CLUTTER_NONE, 0, 0.0));
        assert!(ev.finish(None).clutter.is_empty(), "no filter: nothing reported (and nothing serialised)");
        let mut ev = OnlineEvaluation::new(EvaluatorParams { figures: false, ..Default::default() });
        for (rank, removed) in [(2, 0.99), (3, 0.97), (2, 0.98)] {
            ev.add_map(map(CLUTTER_SVD, rank, removed));
        }
        let e = ev.finish(None);
        assert_eq!(e.clutter.len(), 1);
        let c = &e.clutter[0];
        assert_eq!((c.filter.as_str(), c.order_min, c.order_max, c.maps), ("svd", 2, 3, 3));
        assert!((c.removed_energy_mean - 0.98).abs() < 1e-12);
        assert_eq!(c.describe(), "svd (rank 2–3, cut-off 0.050 PRF, 98.0 % of the energy removed on average; 3 maps)");
        assert!(markdown(&e).contains("Clutter filter: svd (rank 2–3"));
    }

    /// A vector field's header tells how it was made (without any maps): the looks' filter and
    /// the looks used and left out, tallied per field; ground truth and filterless fields without
    /// looks add nothing.
    #[test]
    fn clutter_filter_of_the_vector_fields_is_reported() {
        use sonoflow_messages::{CLUTTER_NONE, CLUTTER_POLYNOMIAL};
        let mut ev = OnlineEvaluation::new(EvaluatorParams { figures: false, ..Default::default() });
        for (packet, rejected) in [(0, 1), (1, 0)] {
            let mut raw = field(packet, &[(plane::VX, vec![0.0; 120]), (plane::VZ, vec![0.0; 120])]);
            raw.0.clutter_filter = CLUTTER_POLYNOMIAL;
            (raw.0.clutter_order, raw.0.n_looks, raw.0.rejected_looks) = (2, 10, rejected);
            ev.add_estimate("raw", raw);
            let mut plain = field(packet, &[(plane::VX, vec![0.0; 120]), (plane::VZ, vec![0.0; 120])]);
            plain.0.clutter_filter = CLUTTER_NONE;
            plain.0.n_looks = 2;
            ev.add_estimate("paper", plain);
            ev.add_estimate("external", field(packet, &[(plane::VX, vec![0.0; 120]), (plane::VZ, vec![0.0; 120])]));
        }
        let e = ev.finish(None);
        assert_eq!(e.field_clutter.len(), 2, "{:?}", e.field_clutter.keys());
        let raw = &e.field_clutter["raw"];
        assert_eq!((raw.looks, raw.rejected_looks), (10, 1));
        let f = raw.filter.as_ref().unwrap();
        assert_eq!((f.filter.as_str(), f.order_min, f.order_max, f.maps), ("polynomial", 2, 2, 2));
        assert!(e.field_clutter["paper"].filter.is_none());
        let md = markdown(&e);
        assert!(md.contains("`raw`: clutter filter polynomial (degree 2; 2 packets); 10 looks, 1 left out"), "{md}");
        assert!(md.contains("`paper`: no clutter filter; 2 looks, none left out"), "{md}");
    }
}
