//! The `doppler` adapter end to end without IPC: I/Q headers → `PacketAssembler` → map and
//! vector messages.
#![allow(clippy::unwrap_used)]

use sonoflow_builtin::doppler::packet_messages;
use sonoflow_builtin::packet_node::{look_header, to_c32};
use sonoflow_doppler::{PacketAssembler, PacketParams};
use sonoflow_messages::{plane, Complex32, GridV1, IqFrameHeaderV3};

/// Looks of one angle in two bands stay two looks (streams per (tilt, angle, fc)), and the
/// vector solve weights each by fc²: uniform phase ramps of a known velocity (v_D = a·v,
/// phase step 4π fc v_D / (c PRF) per frame) give it back exactly; a look made 10 % wrong
/// moves the solution as the weighted normal equations, computed here independently, say.
#[test]
fn looks_in_two_bands_are_kept_apart_and_weighted_by_fc_squared() {
    let (nx, nz, n_frames) = (3usize, 2usize, 16usize);
    let (c, prf) = (1540.0, 1e4);
    let v = [0.20, -0.05];
    let looks = [(-15.0f64, 3.6e6), (15.0, 3.6e6), (0.0, 3.6e6), (0.0, 5e6)];
    let run = |wrong: Option<usize>| {
        let mut node = PacketAssembler::new(PacketParams::default()).unwrap();
        for (j, &(deg, fc)) in looks.iter().enumerate() {
            let a = sonoflow_doppler::nominal_projection(0.0, deg.to_radians());
            let vd = (a[0] * v[0] + a[1] * v[1]) * if wrong == Some(j) { 1.1 } else { 1.0 };
            let step = 4.0 * std::f64::consts::PI * fc * vd / (c * prf);
            for n in 0..n_frames {
                let h = IqFrameHeaderV3 {
                    grid: GridV1 { x0: 0.0, z0: 0.02, dx: 1e-4, dz: 1e-4, nx: nx as u32, nz: nz as u32 },
                    fc,
                    c,
                    prf,
                    rx_angle: deg.to_radians(),
                    frame_in_packet: n as u32,
                    ..Default::default()
                };
                let z = Complex32 { re: (step * n as f64).cos() as f32, im: (step * n as f64).sin() as f32 };
                assert!(node.push(&look_header(&h), to_c32(&vec![z; nx * nz])).unwrap().is_none());
            }
        }
        packet_messages(node.finish().unwrap().unwrap())
    };
    let r = run(None);
    assert_eq!(r.0.len(), 4, "four looks, two of them at 0°");
    let fcs: Vec<f64> = r.0.iter().map(|m| m.0.fc).collect();
    assert!(fcs.contains(&3.6e6) && fcs.contains(&5e6), "{fcs:?}");
    let n = nx * nz;
    // Each map carries the projection it was solved with, and its velocity is that
    // projection of the true velocity (what the evaluator's per-look errors rely on).
    for (mh, planes) in &r.0 {
        assert_eq!(mh.n_planes, 6);
        assert_eq!(&mh.plane_ids[4..6], &[plane::PROJECTION_X, plane::PROJECTION_Z]);
        let a = sonoflow_doppler::nominal_projection(mh.tx_angle, mh.rx_angle);
        for i in 0..n {
            let (vel, px, pz) = (planes[i], planes[4 * n + i], planes[5 * n + i]);
            assert_eq!((px, pz), (a[0] as f32, a[1] as f32));
            let want = f64::from(px) * v[0] + f64::from(pz) * v[1];
            assert!((f64::from(vel) - want).abs() < 1e-5, "{vel} vs {want}");
        }
    }
    let (vx, vz) = (&r.1 .1[..n], &r.1 .1[n..2 * n]);
    assert!(vx.iter().all(|x| (f64::from(*x) - v[0]).abs() < 1e-5), "{vx:?}");
    assert!(vz.iter().all(|z| (f64::from(*z) - v[1]).abs() < 1e-5), "{vz:?}");
    // The 5 MHz look 10 % wrong: weighted least squares with w = (fc / 5 MHz)².
    let r = run(Some(3));
    let solve = |weighted: bool| {
        let (mut m, mut b) = ([0.0f64; 3], [0.0f64; 2]);
        for (j, &(deg, fc)) in looks.iter().enumerate() {
            let a = sonoflow_doppler::nominal_projection(0.0, deg.to_radians());
            let vd = (a[0] * v[0] + a[1] * v[1]) * if j == 3 { 1.1 } else { 1.0 };
            let w = if weighted { (fc / 5e6).powi(2) } else { 1.0 };
            m = [m[0] + w * a[0] * a[0], m[1] + w * a[0] * a[1], m[2] + w * a[1] * a[1]];
            b = [b[0] + w * a[0] * vd, b[1] + w * a[1] * vd];
        }
        let det = m[0] * m[2] - m[1] * m[1];
        [(m[2] * b[0] - m[1] * b[1]) / det, (m[0] * b[1] - m[1] * b[0]) / det]
    };
    let (want, unweighted) = (solve(true), solve(false));
    let got = [f64::from(r.1 .1[0]), f64::from(r.1 .1[n])];
    assert!((got[0] - want[0]).abs() < 1e-5 && (got[1] - want[1]).abs() < 1e-5, "{got:?} vs {want:?}");
    // … not the unweighted solution (7e-4 m/s apart here, 70 × the tolerance above): the
    // 5 MHz look weighs (5/3.6)² = 1.93 times more.
    assert!((unweighted[1] - want[1]).abs() > 30.0 * 1e-5, "weighted {want:?}, unweighted {unweighted:?}");
}
