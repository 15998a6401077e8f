//! `regulariser` node: raw vector fields → regularised vector fields. Thin: the parameters are
//! `sonoflow_regularise::RegulariserParams` and the work per frame is
//! `sonoflow_regularise::FieldRegulariser` (robust smoothn, or the divergence-free fit with its
//! power mask and no-slip wall; see `nodes/regularise/src/field.rs`); this file maps the
//! message's planes to their roles, and the library's report into the output header (the S
//! used, the outlier fraction, whether smoothn converged). Compute time per message is process
//! CPU time (smoothn uses rayon for the two components).

use sonoflow_messages::types::VectorField;
use sonoflow_messages::MessageType::*;
use sonoflow_messages::{plane, MsgHeaderV1, VectorFieldHeaderV2, MAX_PLANES, VECTOR_REGULARISED};
use sonoflow_node_kit::PortDir::*;
use sonoflow_node_kit::{parse_params, port, process_cpu_ns, transform, KindSpec, Kit};
use sonoflow_regularise::{FieldRegulariser, PlaneRole};

pub use sonoflow_regularise::field::{Method, WeightSource};
pub use sonoflow_regularise::RegulariserParams;

/// The `regulariser` node kind.
pub const SPEC: KindSpec = KindSpec::new(
    "regulariser",
    "robust unsupervised smoothing of vector fields (Garcia's smoothn): raw → regularised, with the S used and the outlier fraction",
    &[port("raw", In, VectorFieldV2, true), port("regularised", Out, VectorFieldV2, true)],
    validate,
    run,
);

pub fn validate(v: &serde_json::Value) -> Result<(), String> {
    parse_params::<RegulariserParams>(v)?.validate().map_err(|e| e.to_string())
}

/// The role of a wire plane id for the library.
fn role(id: u32) -> PlaneRole {
    match id {
        plane::VX => PlaneRole::Vx,
        plane::VZ => PlaneRole::Vz,
        plane::WEIGHT => PlaneRole::Weight,
        plane::POWER => PlaneRole::Power,
        plane::FLAGS => PlaneRole::Flags,
        plane::MASK => PlaneRole::Mask,
        _ => PlaneRole::Other,
    }
}

/// What the node does with one message, independent of IPC (used by the node and by tests).
pub struct Regulariser {
    lib: FieldRegulariser,
    roles: Vec<PlaneRole>,
}

impl Regulariser {
    pub fn new(params: RegulariserParams) -> Result<Self, String> {
        Ok(Self { lib: FieldRegulariser::new(params).map_err(|e| e.to_string())?, roles: Vec::new() })
    }

    /// Regularises one vector field message (header + planes) into `planes_out` (same layout and
    /// plane order as the input); returns the output header.
    pub fn process(
        &mut self,
        h: &VectorFieldHeaderV2,
        planes: &[f32],
        planes_out: &mut Vec<f32>,
    ) -> anyhow::Result<VectorFieldHeaderV2> {
        let np = h.n_planes as usize;
        if np == 0 || np > MAX_PLANES {
            anyhow::bail!("vector field frame {}: n_planes = {np} must be 1 ..= {MAX_PLANES}", h.common.frame_id);
        }
        let ids = &h.plane_ids[..np];
        self.roles.clear();
        self.roles.extend(ids.iter().map(|&id| role(id)));
        let g = &h.grid;
        let report = self
            .lib
            .process([g.nz as usize, g.nx as usize], [g.dz, g.dx], &self.roles, planes, planes_out)
            .map_err(|e| {
                let names: Vec<_> = ids.iter().map(|&i| plane::name(i)).collect();
                anyhow::anyhow!("vector field frame {} (planes {names:?}): {e}", h.common.frame_id)
            })?;
        let mut oh = *h;
        oh.common = MsgHeaderV1 { frame_id: h.common.frame_id, t_valid: h.common.t_valid, ..Default::default() };
        oh.source = VECTOR_REGULARISED;
        oh.smoothing_s = report.s;
        oh.outlier_fraction = report.outlier_fraction;
        oh.converged = report.converged as u32;
        Ok(oh)
    }
}

pub fn run(mut kit: Kit) -> anyhow::Result<()> {
    let p: RegulariserParams = parse_params(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    let max_iter = p.smoothn.max_iter;
    let mut reg = Regulariser::new(p).map_err(anyhow::Error::msg)?;
    let mut input = kit.input::<VectorField>("raw")?;
    let mut out = kit.output::<VectorField>("regularised")?;
    kit.handshake(&mut [&mut input, &mut out])?;
    let mut planes = Vec::new();
    let mut not_converged = 0u64;
    transform(kit, &mut input, &mut out, |kit, out, sample| {
        let t0 = process_cpu_ns();
        let h = *sample.user_header();
        let mut oh = reg.process(&h, sample.payload(), &mut planes)?;
        if oh.converged == 0 && oh.smoothing_s > 0.0 {
            not_converged += 1;
            if not_converged == 1 {
                eprintln!(
                    "regulariser: frame {} did not converge within max_iter = {max_iter} (raise max_iter or tol_z); further cases counted in the stats",
                    h.common.frame_id
                );
            }
        }
        oh.common.compute_ns = process_cpu_ns() - t0;
        Ok(kit.publish_copy(out, oh, &planes)?)
    })?;
    if not_converged > 0 {
        eprintln!("regulariser: {not_converged} frame(s) did not converge");
    }
    Ok(())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use sonoflow_messages::GridV1;

    fn field(nx: u32, nz: u32, ids: &[u32]) -> (VectorFieldHeaderV2, Vec<f32>) {
        let mut h = VectorFieldHeaderV2 {
            grid: GridV1 { x0: 0.0, z0: 0.0, dx: 1e-4, dz: 1e-4, nx, nz },
            n_planes: ids.len() as u32,
            ..Default::default()
        };
        h.plane_ids[..ids.len()].copy_from_slice(ids);
        h.common.frame_id = 3;
        h.common.t_valid = 0.25;
        h.common.compute_ns = 99;
        let n = (nx * nz) as usize;
        let mut v = vec![0.0f32; ids.len() * n];
        for i in 0..n {
            v[i] = 0.1 + 0.001 * (i % nx as usize) as f32;
            v[n + i] = -0.2 + 0.002 * (i / nx as usize) as f32;
        }
        (h, v)
    }

    #[test]
    fn errors_name_the_frame_the_planes_and_the_parameter() {
        let (h, v) = field(8, 6, &[plane::VX, plane::MASK]);
        let mut r = Regulariser::new(RegulariserParams::default()).unwrap();
        let e = r.process(&h, &v, &mut Vec::new()).unwrap_err().to_string();
        assert!(e.contains("frame 3") && e.contains("[\"vx\", \"mask\"]") && e.contains("needs `vx` and `vz`"), "{e}");
        let (h, v) = field(8, 6, &[plane::VX, plane::VZ]);
        let e = r.process(&h, &v[..10], &mut Vec::new()).unwrap_err().to_string();
        assert!(e.contains("need 96 values, got 10"), "{e}");
        let e = r.process(&VectorFieldHeaderV2 { n_planes: 99, ..h }, &v, &mut Vec::new()).unwrap_err().to_string();
        assert!(e.contains("n_planes = 99"), "{e}");
        let mut p = RegulariserParams { weights: WeightSource::Power, ..Default::default() };
        let e = Regulariser::new(p.clone()).unwrap().process(&h, &v, &mut Vec::new()).unwrap_err().to_string();
        assert!(e.contains("no `power` plane"), "{e}");
        p.smoothn.order = 7;
        assert!(Regulariser::new(p).err().unwrap().contains("order"));
        let e = validate(&serde_json::json!({"power_mask_db": 5.0})).unwrap_err();
        assert!(e.contains("power_mask_db") && e.contains("-100 ..= 0"), "{e}");
        let e = validate(&serde_json::json!({"divergence_free": {"cv_block": 1}})).unwrap_err();
        assert!(e.contains("cv_block"), "{e}");
        let e = validate(&serde_json::json!({"no_slip": {"threshold_db": 3.0}})).unwrap_err();
        assert!(e.contains("no_slip.threshold_db") && e.contains("−30 ..= −1"), "{e}");
        assert!(validate(&serde_json::json!({"weights": "quality"})).unwrap_err().contains("weights"));
        assert!(validate(&serde_json::json!({"spacing": [1.0, 1.0]})).is_err(), "not a node parameter");
    }

    /// The wire plane ids reach the library as roles (mask, flags, weight, power; an unknown
    /// plane passes through), the output is the library's, and the header carries its report.
    #[test]
    fn planes_map_to_roles_and_the_report_to_the_header() {
        let ids = [plane::VARIANCE, plane::VZ, plane::FLAGS, plane::VX, plane::MASK, plane::WEIGHT, plane::POWER];
        let roles = [
            PlaneRole::Other,
            PlaneRole::Vz,
            PlaneRole::Flags,
            PlaneRole::Vx,
            PlaneRole::Mask,
            PlaneRole::Weight,
            PlaneRole::Power,
        ];
        let (mut h, mut v) = field(12, 10, &ids);
        // the looks' clutter filter passes on to the regularised field
        h.clutter_filter = sonoflow_messages::CLUTTER_SVD;
        (h.clutter_order, h.clutter_cutoff, h.clutter_removed_energy) = (3, 0.05, 0.999);
        (h.n_looks, h.rejected_looks) = (10, 1);
        let n = 120;
        for i in 0..n {
            v[3 * n + i] = v[i]; // vx in plane 3, vz (the field's second plane) in plane 1
            v[i] = 7.0;
            v[4 * n + i] = if i % 12 < 10 { 1.0 } else { 0.0 };
            v[5 * n + i] = 0.5 + 0.5 * ((i % 5) as f32 / 4.0);
            v[6 * n + i] = 1.0 + i as f32;
        }
        v[2 * n + 25] = 1.0;
        v[3 * n + 25] = 50.0;
        for method in [Method::Smoothn, Method::DivergenceFree] {
            let p = RegulariserParams { method, ..Default::default() };
            let mut out = Vec::new();
            let oh = Regulariser::new(p.clone()).unwrap().process(&h, &v, &mut out).unwrap();
            let mut expect = Vec::new();
            let rep =
                FieldRegulariser::new(p).unwrap().process([10, 12], [1e-4, 1e-4], &roles, &v, &mut expect).unwrap();
            assert!(out == expect, "{method:?}: the node's planes are the library's");
            assert!(rep.s > 0.0 && rep.converged);
            assert_eq!((oh.smoothing_s, oh.outlier_fraction, oh.converged), (rep.s, rep.outlier_fraction, 1));
            assert_eq!(
                (oh.source, oh.common.frame_id, oh.common.t_valid, oh.common.compute_ns),
                (VECTOR_REGULARISED, 3, 0.25, 0)
            );
            assert_eq!((oh.grid, oh.n_planes, oh.plane_ids), (h.grid, h.n_planes, h.plane_ids));
            assert_eq!(
                (oh.clutter_filter, oh.clutter_order, oh.clutter_cutoff, oh.clutter_removed_energy),
                (sonoflow_messages::CLUTTER_SVD, 3, 0.05, 0.999)
            );
            assert_eq!((oh.n_looks, oh.rejected_looks), (10, 1));
            assert!(out[3 * n + 11] == 0.0 && out[n + 11] == 0.0 && out[3 * n + 12] != 0.0, "outside the mask: 0");
            assert!((out[3 * n + 25] - out[3 * n + 24]).abs() < 0.05, "the flagged pixel is filled");
            assert_eq!(&out[..n], &v[..n], "unknown plane passes through");
        }
    }
}
