//! `beamformer` node: a thin wrapper of `sonoflow_beamform::MultiLookBeamformer`.
//!
//! Each RF frame → one I/Q image per receive angle in `rx_angles_deg` (RF→I/Q, delay-and-sum
//! onto `grid` for the frame's plane-wave tilt, receive sub-apertures at `fnumber`). Each image's
//! header carries its look (transmit tilt, receive angle, demodulation fc) and the receive
//! aperture (pitch, element count, width and a convex array's radius from the RF header;
//! f-number and apodisation from the params), so the Doppler node needs no copy of this configuration.

use sonoflow_beamform::{Apodization, BeamformerParams, MultiLookBeamformer, RfInfo, C32};
use sonoflow_messages::types::{IqFrame, RfFrame};
use sonoflow_messages::MessageType::*;
use sonoflow_messages::{
    Complex32, GridV1, IqFrameHeaderV3, MsgHeaderV1, RfFrameHeaderV3, APODIZATION_BOXCAR, APODIZATION_HANN,
    SAMPLE_RF_F32,
};
use sonoflow_node_kit::PortDir::*;
use sonoflow_node_kit::{parse_params, port, process_cpu_ns, transform, KindSpec, Kit};

/// The `beamformer` node kind.
pub const SPEC: KindSpec = KindSpec::new(
    "beamformer",
    "RF → I/Q (MUST rf2iq) → delay-and-sum on a grid, one I/Q image per receive sub-aperture angle",
    &[port("rf", In, RfFrameV3, true), port("iq", Out, IqFrameV3, true)],
    validate,
    run,
);

pub fn validate(v: &serde_json::Value) -> Result<(), String> {
    parse_params::<BeamformerParams>(v)?.validate()
}

/// A header's `radius` as the libraries take it: 0 or +∞ = a linear array (None); finite and
/// > 0 = convex. NaN and negative values are refused by [`check_radius`] before.
pub fn convex_radius(r: f64) -> Option<f64> {
    (r.is_finite() && r > 0.0).then_some(r)
}

/// The RF header's `radius` is 0 or +∞ (linear) or finite and > 0 (convex).
pub fn check_radius(h: &RfFrameHeaderV3) -> anyhow::Result<()> {
    if h.radius.is_nan() || h.radius < 0.0 {
        anyhow::bail!(
            "RF frame {}: radius = {} must be 0 or inf (linear array) or > 0 m (convex array)",
            h.common.frame_id,
            h.radius
        );
    }
    Ok(())
}

/// The library's view of an RF header.
pub fn rf_info(h: &RfFrameHeaderV3) -> RfInfo {
    RfInfo {
        fs: h.fs,
        t0: h.t0,
        fc: h.fc,
        c: h.c,
        pitch: h.pitch,
        tx_angle: h.tx_angle,
        radius: convex_radius(h.radius),
        n_elements: h.n_channels as usize,
        n_samples: h.n_samples as usize,
    }
}

/// The I/Q header of receive angle `j` for RF frame `h`.
pub fn iq_header(bf: &MultiLookBeamformer, h: &RfFrameHeaderV3, j: usize) -> IqFrameHeaderV3 {
    let p = bf.params();
    let g = &p.grid;
    let n_rx = p.rx_angles_deg.len() as u64;
    IqFrameHeaderV3 {
        common: MsgHeaderV1 {
            frame_id: h.common.frame_id * n_rx + j as u64,
            t_valid: h.common.t_valid,
            ..Default::default()
        },
        grid: GridV1 { x0: g.x0, z0: g.z0, dx: g.dx, dz: g.dz, nx: g.nx as u32, nz: g.nz as u32 },
        fc: bf.demod_fc(&rf_info(h), j),
        c: h.c,
        prf: h.prf,
        rx_angle: p.rx_angles_deg[j].to_radians(),
        tx_angle: h.tx_angle,
        packet: h.packet,
        frame_in_packet: h.frame_in_packet,
        tx_id: h.tx_id,
        pitch: h.pitch,
        element_width: h.element_width,
        fnumber: p.fnumber,
        radius: convex_radius(h.radius).unwrap_or(0.0),
        n_elements: h.n_channels,
        apodization: match p.apodization {
            Apodization::Boxcar => APODIZATION_BOXCAR,
            Apodization::Hann => APODIZATION_HANN,
        },
        ..Default::default()
    }
}

pub fn run(mut kit: Kit) -> anyhow::Result<()> {
    let p: BeamformerParams = parse_params(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    let mut bf = MultiLookBeamformer::new(p).map_err(anyhow::Error::msg)?;
    let mut input = kit.input::<RfFrame>("rf")?;
    let mut out = kit.output::<IqFrame>("iq")?;
    kit.handshake(&mut [&mut input, &mut out])?;
    let n_rx = bf.params().rx_angles_deg.len();
    let mut img = vec![C32::new(0.0, 0.0); bf.params().grid.n_pixels()];
    transform(kit, &mut input, &mut out, |kit, out, sample| {
        let t0 = process_cpu_ns();
        let h = *sample.user_header();
        if h.sample_format != SAMPLE_RF_F32 {
            anyhow::bail!("RF frame {}: sample_format {} is not real f32 RF", h.common.frame_id, h.sample_format);
        }
        check_radius(&h)?;
        bf.demodulate(&rf_info(&h), sample.payload())?;
        let demod_ns = process_cpu_ns() - t0;
        for j in 0..n_rx {
            let t1 = process_cpu_ns();
            bf.image(&rf_info(&h), j, &mut img)?;
            let mut ih = iq_header(&bf, &h, j);
            let compute = process_cpu_ns() - t1 + if j == 0 { demod_ns } else { 0 };
            ih.common.compute_ns = compute;
            out.publish_in_place(img.len(), ih, |dst| {
                for (d, s) in dst.iter_mut().zip(&img) {
                    d.write(Complex32 { re: s.re, im: s.im });
                }
            })?;
            kit.published((img.len() * 8) as u64, ih.common.frame_id, ih.common.t_valid, compute)?;
        }
        Ok(())
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// The I/Q header carries each look's band and the receive aperture: pitch, element count
    /// and width from the RF header, f-number and apodisation from the params; two looks of one
    /// frame get distinct frame ids.
    #[test]
    fn iq_header_carries_the_look_and_the_receive_aperture() {
        let h = RfFrameHeaderV3 {
            fs: 20e6,
            fc: 5e6,
            c: 1540.0,
            pitch: 0.3e-3,
            element_width: 0.265e-3,
            prf: 1e4,
            n_channels: 128,
            n_samples: 400,
            sample_format: SAMPLE_RF_F32,
            ..Default::default()
        };
        let p: BeamformerParams = parse_params(&serde_json::json!({
            "rx_angles_deg": [0.0, 0.0], "demod_fc": [3.6e6, 5e6], "fnumber": 2.5, "apodization": "hann"
        }))
        .unwrap();
        let bf = MultiLookBeamformer::new(p).unwrap();
        let (a, b) = (iq_header(&bf, &h, 0), iq_header(&bf, &h, 1));
        assert_eq!((a.fc, b.fc), (3.6e6, 5e6));
        assert_ne!(a.common.frame_id, b.common.frame_id);
        assert_eq!((a.pitch, a.element_width, a.n_elements), (0.3e-3, 0.265e-3, 128));
        assert_eq!((a.fnumber, a.apodization), (2.5, APODIZATION_HANN));
        // the radius: 0 and +inf mean linear (0 in the I/Q header), a finite one passes through,
        // NaN or negative is refused with the frame named
        assert_eq!(a.radius, 0.0);
        for (r, want) in [(f64::INFINITY, 0.0), (0.04957, 0.04957)] {
            let hc = RfFrameHeaderV3 { radius: r, ..h };
            assert!(check_radius(&hc).is_ok());
            assert_eq!(iq_header(&bf, &hc, 0).radius, want);
            assert_eq!(rf_info(&hc).radius, (want > 0.0).then_some(want));
        }
        for r in [f64::NAN, -0.01] {
            let e = check_radius(&RfFrameHeaderV3 { radius: r, ..h }).unwrap_err().to_string();
            assert!(e.contains("radius") && e.contains("RF frame 0"), "{e}");
        }
    }

    #[test]
    fn beamformer_params_errors_name_the_field() {
        let e = validate(&serde_json::json!({"rx_angles_deg": [95.0]})).unwrap_err();
        assert!(e.contains("rx_angles_deg[0]"), "{e}");
        let e = validate(&serde_json::json!({"fnumber": -1.0})).unwrap_err();
        assert!(e.contains("fnumber"), "{e}");
        let e = validate(&serde_json::json!({"demod_fc": -3.6e6})).unwrap_err();
        assert!(e.contains("demod_fc") && e.contains("Hz"), "{e}");
        let e =
            validate(&serde_json::json!({"grid": {"x0": 0.0, "z0": 0.01, "dx": 0.0, "dz": 1e-4, "nx": 4, "nz": 4}}))
                .unwrap_err();
        assert!(e.contains("grid.dx"), "{e}");
    }
}
