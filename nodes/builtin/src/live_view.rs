//! `live-view` node: shows the graph's picture topics (particles, B-mode I/Q, Doppler maps,
//! vector fields) live in Foxglove over its WebSocket protocol (`sonoflow_live::LiveView`).
//! `sonoflow run SCENE --live [ADDR]` adds one; a launch file can declare one too.
//!
//! Never slows the graph: the receive loop only copies each message into the topic's
//! one-message mailbox (a newer message replaces one not yet shown); pictures are made on
//! another thread at most `max_rate_hz` per topic, and the server drops the oldest pictures for
//! a viewer that reads too slowly. It is not a recorder: the recording does not depend on it.

use serde::{Deserialize, Serialize};
use sonoflow_live::{parse_addr, LiveOptions, LiveView};
use sonoflow_messages::viz::has_picture;
use sonoflow_node_kit::{in_range, parse_params, select_loop, DynInput, KindSpec, Kit, Step};
use std::time::Duration;

/// The `live-view` node kind.
pub const SPEC: KindSpec = KindSpec::new(
    "live-view",
    "streams the picture topics to Foxglove over WebSocket while the graph runs (never slows it)",
    &[],
    validate,
    run,
)
.with_dynamic_ports(true, false)
.with_dynamic_input_types(has_picture);

/// Live-view parameters.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct LiveViewParams {
    /// `HOST:PORT` to serve on (`127.0.0.1:8765`: this machine only; `0.0.0.0:8765`: every
    /// interface; port 0: any free port, printed at start).
    pub addr: String,
    /// Topics to show; `"*"` = every topic with a picture.
    pub topics: Vec<String>,
    /// Pictures per second and topic at most (0.1–1000); the newest message wins.
    pub max_rate_hz: f64,
    /// Pictures queued per viewer before the oldest is dropped (1–100000).
    pub backlog: usize,
    /// After the last message, keep serving the newest pictures this long (s, 0–86400), or
    /// until every viewer that connected has left.
    pub linger_s: f64,
    /// Before the graph starts, wait this long (s, 0–600) for a viewer to subscribe, so it sees
    /// the run from its first message; capped at half the graph's `handshake_timeout_s`.
    pub wait_for_viewer_s: f64,
}

impl Default for LiveViewParams {
    fn default() -> Self {
        let d = LiveOptions::default();
        Self {
            addr: format!("{}:{}", d.host, d.port),
            topics: vec!["*".into()],
            max_rate_hz: d.max_rate_hz,
            backlog: d.backlog,
            linger_s: 0.0,
            wait_for_viewer_s: 0.0,
        }
    }
}

impl LiveViewParams {
    /// The server options; the error names the field.
    pub fn options(&self) -> Result<LiveOptions, String> {
        let (host, port) = parse_addr(&self.addr).map_err(|e| format!("addr: {e}"))?;
        in_range("linger_s", self.linger_s, 0.0, 86400.0)?;
        in_range("wait_for_viewer_s", self.wait_for_viewer_s, 0.0, 600.0)?;
        let o =
            LiveOptions { host, port, backlog: self.backlog, max_rate_hz: self.max_rate_hz, ..LiveOptions::default() };
        o.validate().map_err(|e| e.to_string())?;
        Ok(o)
    }
}

pub fn validate(v: &serde_json::Value) -> Result<(), String> {
    parse_params::<LiveViewParams>(v)?.options().map(|_| ())
}

pub fn run(mut kit: Kit) -> anyhow::Result<()> {
    let p: LiveViewParams = parse_params(&kit.cfg.params).map_err(anyhow::Error::msg)?;
    let opts = p.options().map_err(anyhow::Error::msg)?;
    let mut inputs: Vec<Box<dyn DynInput>> = Vec::new();
    for qos in kit.cfg.inputs.clone().values() {
        inputs.push(kit.dyn_input(qos)?);
    }
    let topics: Vec<_> = inputs.iter().map(|i| (i.topic_name().to_string(), i.kind())).collect();
    // The server starts before the handshake, so the channels are advertised and a viewer can
    // subscribe before the first message.
    let live = LiveView::start(&opts, &topics)?;
    let names: Vec<&str> = topics.iter().map(|(t, _)| t.as_str()).collect();
    eprintln!(
        "live view: {} — in Foxglove: Open connection → Foxglove WebSocket → this URL; topics: {}",
        live.url(),
        if names.is_empty() { "none (the graph has no picture topics)".to_string() } else { names.join(", ") }
    );
    if p.wait_for_viewer_s > 0.0 {
        // The peers wait for this node's handshake: stay well inside their timeout.
        let cap = 0.5 * kit.cfg.handshake_timeout_s;
        let wait = p.wait_for_viewer_s.min(cap);
        if wait < p.wait_for_viewer_s {
            eprintln!(
                "live view: wait_for_viewer_s = {} capped at {wait} s (half the graph's handshake_timeout_s)",
                p.wait_for_viewer_s
            );
        }
        eprintln!("live view: waiting up to {wait} s for a viewer before the graph starts");
        if !live.wait_for_viewer(Duration::from_secs_f64(wait)) {
            eprintln!("live view: no viewer subscribed within {wait} s; the graph starts anyway");
        }
    }
    {
        let mut hs: Vec<&mut dyn sonoflow_node_kit::Handshake> =
            inputs.iter_mut().map(|i| i.as_mut() as &mut dyn sonoflow_node_kit::Handshake).collect();
        kit.handshake(&mut hs)?;
    }
    let wakeups: Vec<_> = inputs.iter().map(|i| i.wakeup()).collect();
    select_loop(&mut kit, &wakeups, Duration::from_millis(500), |_| {
        let mut any = true;
        while any {
            any = false;
            for (index, input) in inputs.iter_mut().enumerate() {
                let got = input.receive_with(&mut |header, payload| {
                    live.offer(index, header, payload);
                    Ok(())
                })?;
                any |= got.is_some();
            }
        }
        Ok(if inputs.iter().all(|i| i.counters().2) { Step::Done } else { Step::Continue })
    })?;
    if p.linger_s > 0.0 {
        eprintln!("live view: the graph has ended; serving the last pictures for {} s", p.linger_s);
    }
    let counts = live.finish(Duration::from_secs_f64(p.linger_s));
    let summary: Vec<String> =
        counts.iter().map(|c| format!("{} {}/{} shown ({} skipped)", c.topic, c.shown, c.offered, c.skipped)).collect();
    println!("live view: {}", if summary.is_empty() { "nothing to show".into() } else { summary.join(", ") });
    kit.stats.messages_in = counts.iter().map(|c| c.offered).sum();
    kit.stats.messages_out = counts.iter().map(|c| c.shown).sum();
    kit.finish()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn params_out_of_range_name_the_field() {
        let e = |v: serde_json::Value| validate(&v).unwrap_err();
        assert!(e(serde_json::json!({ "addr": "nowhere:port" })).contains("addr"));
        assert!(e(serde_json::json!({ "linger_s": -1.0 })).contains("linger_s"));
        assert!(e(serde_json::json!({ "backlog": 0 })).contains("backlog"));
        assert!(e(serde_json::json!({ "max_rate_hz": 0.0 })).contains("max_rate_hz"));
        assert!(e(serde_json::json!({ "port": 1 })).contains("port"));
        assert!(e(serde_json::json!({ "wait_for_viewer_s": 1e9 })).contains("wait_for_viewer_s"));
        assert!(validate(&serde_json::json!({ "addr": ":0", "linger_s": 2 })).is_ok());
    }
}
