//! What the two flow producers (`analytic-flow`, `sph-flow`) put on the wire: a frame's fluid
//! particles (the scatterers) as `ParticleSnapshotV1`, a packet's ground truth as
//! `VectorFieldV2` (planes vx, vz, mask).

use sonoflow_analytic_flow::{AcquisitionTime, GridSpec, Particles, Truth};
use sonoflow_messages::types::{ParticleSnapshot, VectorField};
use sonoflow_messages::*;
use sonoflow_node_kit::Output;

/// Publishes the fluid particles `ps` of frame `at` (of a schedule with `packet_size` frames per
/// packet; `dt` the solver step, 0 for an analytic flow) with their bounding box, followed by the
/// `tissue` scatterers (kind `PARTICLE_TISSUE_MOVING` if `tissue_moves`, else
/// `PARTICLE_TISSUE`; `n_fluid` counts the fluid only).
/// An error naming the topic if they do not fit its `max_elements`.
pub fn publish_fluid(
    out: &mut Output<ParticleSnapshot>,
    at: &AcquisitionTime,
    packet_size: u32,
    dt: f64,
    ps: &Particles,
    tissue: &Particles,
    tissue_moves: bool,
) -> anyhow::Result<()> {
    let n = ps.len() + tissue.len();
    if n > out.max_elements() {
        anyhow::bail!(
            "the flow has {n} scatterers (fluid and tissue) but topic `{}` allows max_elements = {}: raise it in the launch file",
            out.topic(),
            out.max_elements()
        );
    }
    let mut h = ParticleSnapshotHeaderV1 {
        n_particles: n as u32,
        n_fluid: ps.len() as u32,
        dt,
        bbox: ps.bbox(),
        packet: at.packet,
        frame_in_packet: at.frame_in_packet,
        packet_size,
        ..Default::default()
    };
    h.common.frame_id = at.frame_id;
    h.common.t_valid = at.t;
    out.publish_in_place(n, h, |dst| {
        let tissue_kind = if tissue_moves { PARTICLE_TISSUE_MOVING } else { PARTICLE_TISSUE };
        let all = [(ps, PARTICLE_FLUID), (tissue, tissue_kind)];
        let src = all.iter().flat_map(|(p, kind)| (0..p.len()).map(move |i| (*p, *kind, i)));
        for (d, (p, kind, i)) in dst.iter_mut().zip(src) {
            d.write(ParticleV1 {
                id: p.id[i],
                kind,
                x: p.x[i],
                z: p.z[i],
                vx: p.vx[i],
                vz: p.vz[i],
                amplitude: p.amplitude[i],
                reserved: 0.0,
            });
        }
    })?;
    Ok(())
}

/// Publishes the ground truth of `packet` on `grid` (frame id and time as the producer defines
/// them for the packet).
pub fn publish_truth(
    out: &mut Output<VectorField>,
    grid: &GridSpec,
    truth: &Truth,
    packet: u32,
    frame_id: u64,
    t: f64,
) -> anyhow::Result<()> {
    let nn = truth.vx.len();
    let mut vh = VectorFieldHeaderV2 {
        grid: GridV1 { x0: grid.x0, z0: grid.z0, dx: grid.dx, dz: grid.dz, nx: grid.nx, nz: grid.nz },
        n_planes: 3,
        source: VECTOR_TRUTH,
        packet,
        converged: 1,
        ..Default::default()
    };
    vh.plane_ids[..3].copy_from_slice(&[plane::VX, plane::VZ, plane::MASK]);
    vh.common.frame_id = frame_id;
    vh.common.t_valid = t;
    out.publish_in_place(3 * nn, vh, |dst| {
        for i in 0..nn {
            dst[i].write(truth.vx[i]);
            dst[nn + i].write(truth.vz[i]);
            dst[2 * nn + i].write(truth.mask[i] as f32);
        }
    })?;
    Ok(())
}
