//! An external Doppler estimator: a separate executable, written against the wire format only
//! (`sonoflow-node-kit` + `sonoflow-messages`, no sonoflow algorithm crate), that a launch file
//! swaps in for the built-in `doppler` node:
//!
//! ```toml
//! [nodes.doppler.variants.external]
//! exec = "sonoflow-example-estimator"
//! ports = { iq = "IqFrameV3", vector = "VectorFieldV2", maps = "DopplerMapV2" }
//! ```
//! `sonoflow run launch/quickstart.toml --swap doppler=external`.
//!
//! It implements the textbook estimator on its own: per pixel and (transmit, receive) angle
//! pair, lag-L slow-time autocorrelation `R1 = Σ x_n conj(x_{n+L})`, `v = −c·PRF/(4π fc L)·arg R1`
//! (positive toward the probe), then the least-squares (vx, vz) over the angle pairs with the
//! plane-wave projection `a = −(sin θt + sin θr, cos θt + cos θr)/2`. Pixels with zero power
//! are flagged "no estimate" (velocity 0).

use sonoflow_messages::types::{DopplerMap, IqFrame, VectorField};
use sonoflow_messages::{
    plane, Complex32, DopplerMapHeaderV2, IqFrameHeaderV3, MsgHeaderV1, VectorFieldHeaderV2, VECTOR_RAW,
};
use sonoflow_node_kit::{is_eos, thread_cpu_ns, Kit, Output};
use std::collections::BTreeMap;
use std::time::Duration;

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
struct Params {
    /// Slow-time lag (1 ..= 16).
    lag: usize,
    /// The built-in node's `projection` choice: accepted so that the same launch file works,
    /// but this example always uses the nominal plane-wave projection (it says so at start)
    /// and ignores the receive aperture in the I/Q headers.
    projection: Option<String>,
}

impl Default for Params {
    fn default() -> Self {
        Self { lag: 1, projection: None }
    }
}

type Error = Box<dyn std::error::Error>;

fn main() {
    if let Err(e) = run() {
        eprintln!("sonoflow-example-estimator: {e}");
        std::process::exit(1);
    }
}

/// Frames of one (transmit, receive) angle pair within the current packet.
struct Pair {
    header: IqFrameHeaderV3,
    frames: Vec<Vec<Complex32>>,
}

struct Ports {
    vector: Output<VectorField>,
    maps: Option<Output<DopplerMap>>,
}

fn run() -> Result<(), Error> {
    let mut kit = Kit::from_env()?;
    let p: Params = kit.params()?;
    if !(1..=16).contains(&p.lag) {
        return Err(format!("params.lag = {} is out of range: 1 ..= 16", p.lag).into());
    }
    if p.projection.as_deref().is_some_and(|m| m != "nominal") {
        eprintln!(
            "sonoflow-example-estimator: `projection` ignored: this estimator uses the nominal plane-wave projection"
        );
    }
    let mut input = kit.input::<IqFrame>("iq")?;
    let mut ports = Ports {
        vector: kit.output::<VectorField>("vector")?,
        maps: if kit.cfg.outputs.contains_key("maps") { Some(kit.output::<DopplerMap>("maps")?) } else { None },
    };
    match ports.maps.as_mut() {
        Some(m) => kit.handshake(&mut [&mut input, &mut ports.vector, m])?,
        None => kit.handshake(&mut [&mut input, &mut ports.vector])?,
    }
    let mut pairs: BTreeMap<(u64, u64), Pair> = BTreeMap::new();
    let mut packet = None;
    let mut last_t = 0.0;
    'run: loop {
        while let Some(sample) = input.try_receive()? {
            let h = *sample.user_header();
            if is_eos::<IqFrame>(&h) {
                break 'run;
            }
            kit.stats.messages_in += 1;
            if packet.is_some_and(|q| q != h.packet) {
                estimate(&mut kit, &mut ports, std::mem::take(&mut pairs), p.lag)?;
            }
            packet = Some(h.packet);
            last_t = h.common.t_valid;
            let e = pairs
                .entry((h.tx_angle.to_bits(), h.rx_angle.to_bits()))
                .or_insert_with(|| Pair { header: h, frames: Vec::new() });
            e.frames.push(sample.payload().to_vec());
        }
        if kit.check_termination().is_err() {
            return Ok(());
        }
        input.wait(Duration::from_millis(200))?;
    }
    if !pairs.is_empty() {
        estimate(&mut kit, &mut ports, pairs, p.lag)?;
    }
    ports.vector.publish_eos(last_t)?;
    if let Some(m) = ports.maps.as_mut() {
        m.publish_eos(last_t)?;
    }
    kit.finish_after(&input)?;
    Ok(())
}

/// Estimates one packet and publishes its maps and vector field.
fn estimate(kit: &mut Kit, ports: &mut Ports, pairs: BTreeMap<(u64, u64), Pair>, lag: usize) -> Result<(), Error> {
    let t0 = thread_cpu_ns();
    let first = match pairs.values().next() {
        Some(p) => p.header,
        None => return Ok(()),
    };
    let n = first.grid.nx as usize * first.grid.nz as usize;
    if pairs.len() < 2 {
        return Err(
            format!("packet {}: vector Doppler needs two angle pairs, got {}", first.packet, pairs.len()).into()
        );
    }
    // Normal equations per pixel: Σ a aᵀ and Σ a v_D.
    let mut ata = vec![[0.0f64; 3]; n];
    let mut atb = vec![[0.0f64; 2]; n];
    let mut used = vec![0u32; n];
    let mut power_mean = vec![0.0f32; n];
    let mut frame_id = 0;
    for pair in pairs.values() {
        let h = pair.header;
        if pair.frames.len() <= lag || pair.frames.iter().any(|f| f.len() != n) {
            return Err(format!(
                "packet {}: {} frame(s) of the wrong size or too few for lag {lag}",
                h.packet,
                pair.frames.len()
            )
            .into());
        }
        if h.radius.is_finite() && h.radius > 0.0 {
            return Err(format!(
                "packet {}: the looks come from a convex array (radius {} m): their receive angles are taken from \
                 each element's normal, which this example's nominal plane-wave projection does not model \
                 (use the built-in `doppler` node)",
                h.packet, h.radius
            )
            .into());
        }
        let vn = h.c * h.prf / (4.0 * h.fc * lag as f64);
        let a = [-(h.tx_angle.sin() + h.rx_angle.sin()) / 2.0, -(h.tx_angle.cos() + h.rx_angle.cos()) / 2.0];
        let mut planes = vec![0.0f32; 3 * n];
        for i in 0..n {
            let (mut re, mut im, mut r0) = (0.0f64, 0.0f64, 0.0f64);
            for k in 0..pair.frames.len() {
                let x = pair.frames[k][i];
                r0 += (x.re as f64).powi(2) + (x.im as f64).powi(2);
                if k + lag < pair.frames.len() {
                    let y = pair.frames[k + lag][i];
                    // x · conj(y)
                    re += x.re as f64 * y.re as f64 + x.im as f64 * y.im as f64;
                    im += x.im as f64 * y.re as f64 - x.re as f64 * y.im as f64;
                }
            }
            planes[n + i] = r0 as f32;
            power_mean[i] += r0 as f32 / pairs.len() as f32;
            if r0 > 0.0 && (re != 0.0 || im != 0.0) && re.is_finite() && im.is_finite() {
                let v = -vn * im.atan2(re) / std::f64::consts::PI;
                planes[i] = v as f32;
                ata[i][0] += a[0] * a[0];
                ata[i][1] += a[0] * a[1];
                ata[i][2] += a[1] * a[1];
                atb[i][0] += a[0] * v;
                atb[i][1] += a[1] * v;
                used[i] += 1;
            } else {
                planes[2 * n + i] = 1.0; // no estimate
            }
        }
        frame_id = h.common.frame_id.max(frame_id);
        if let Some(m) = ports.maps.as_mut() {
            let mut mh = DopplerMapHeaderV2 {
                grid: h.grid,
                fc: h.fc,
                c: h.c,
                prf: h.prf,
                rx_angle: h.rx_angle,
                tx_angle: h.tx_angle,
                nyquist_velocity: vn,
                packet: h.packet,
                packet_size: pair.frames.len() as u32,
                n_planes: 3,
                estimator: 100,
                ..Default::default()
            };
            mh.plane_ids[..3].copy_from_slice(&[plane::VELOCITY, plane::POWER, plane::FLAGS]);
            mh.common = MsgHeaderV1 { frame_id: h.common.frame_id, t_valid: h.common.t_valid, ..Default::default() };
            m.publish_copy(mh, &planes)?;
            kit.stats.messages_out += 1;
        }
    }
    let mut out = vec![0.0f32; 4 * n];
    for i in 0..n {
        out[3 * n + i] = power_mean[i];
        let [a11, a12, a22] = ata[i];
        let det = a11 * a22 - a12 * a12;
        if used[i] < 2 || det <= 1e-6 * (a11 + a22).powi(2) {
            out[2 * n + i] = 1.0;
            continue;
        }
        out[i] = ((a22 * atb[i][0] - a12 * atb[i][1]) / det) as f32;
        out[n + i] = ((a11 * atb[i][1] - a12 * atb[i][0]) / det) as f32;
    }
    let mut vh = VectorFieldHeaderV2 {
        grid: first.grid,
        n_planes: 4,
        source: VECTOR_RAW,
        packet: first.packet,
        converged: 1,
        n_looks: pairs.len() as u32,
        ..Default::default()
    };
    vh.plane_ids[..4].copy_from_slice(&[plane::VX, plane::VZ, plane::FLAGS, plane::POWER]);
    let compute = thread_cpu_ns() - t0;
    vh.common = MsgHeaderV1 { frame_id, t_valid: first.common.t_valid, compute_ns: compute, ..Default::default() };
    ports.vector.publish_copy(vh, &out)?;
    kit.stats.messages_out += 1;
    kit.record(frame_id, vh.common.t_valid, compute)?;
    Ok(())
}
