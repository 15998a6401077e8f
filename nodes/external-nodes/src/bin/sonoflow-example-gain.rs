//! An external node: a separate executable that speaks the node kit's wire format. A launch file
//! names it with `exec = "sonoflow-example-gain"` and declares its port types:
//!
//! ```toml
//! [nodes.gain]
//! exec = "sonoflow-example-gain"
//! ports = { rf_in = "RfFrameV3", rf_out = "RfFrameV3" }
//! inputs = { rf_in = "rf" }
//! outputs = { rf_out = "rf_gain" }
//! params = { gain = 2.0 }
//! ```
//!
//! Everything a node needs is in `sonoflow-node-kit` + `sonoflow-messages`: read the config
//! from the environment, open ports, handshake, loop, publish, send end of stream.

use sonoflow_messages::types::RfFrame;
use sonoflow_messages::MsgHeaderV1;
use sonoflow_node_kit::{is_eos, thread_cpu_ns, Kit, KitError};
use std::time::Duration;

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Params {
    gain: f32,
}

fn main() {
    if let Err(e) = run() {
        eprintln!("sonoflow-example-gain: {e}");
        std::process::exit(1);
    }
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    let mut kit = Kit::from_env()?;
    let p: Params = kit.params()?;
    if !p.gain.is_finite() {
        return Err(format!("params.gain = {} must be finite", p.gain).into());
    }
    let mut input = kit.input::<RfFrame>("rf_in")?;
    let mut output = kit.output::<RfFrame>("rf_out")?;
    kit.handshake(&mut [&mut input, &mut output])?;
    let mut last_t = 0.0;
    'run: loop {
        while let Some(sample) = input.try_receive()? {
            if is_eos::<RfFrame>(sample.user_header()) {
                break 'run;
            }
            let t0 = thread_cpu_ns();
            let mut h = *sample.user_header();
            h.common = MsgHeaderV1 { frame_id: h.common.frame_id, t_valid: h.common.t_valid, ..Default::default() };
            last_t = h.common.t_valid;
            let src = sample.payload();
            output.publish_in_place(src.len(), h, |dst| {
                for (d, s) in dst.iter_mut().zip(src) {
                    d.write(s * p.gain);
                }
            })?;
            kit.stats.messages_in += 1;
            kit.stats.messages_out += 1;
            kit.record(h.common.frame_id, h.common.t_valid, thread_cpu_ns() - t0)?;
        }
        match kit.check_termination() {
            Err(KitError::Terminated) => break,
            r => r?,
        }
        input.wait(Duration::from_millis(200))?;
    }
    output.publish_eos(last_t)?;
    kit.finish()?;
    Ok(())
}
