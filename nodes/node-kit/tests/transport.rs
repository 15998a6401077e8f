//! The node kit over real iceoryx2 shared memory, inside one test process: publish/subscribe
//! with headers and payloads intact, sequence numbers and gap counting, end of stream,
//! `for_each`, `select_loop` over two inputs, the start-up handshake (and its timeouts), the
//! stage-statistics port, type-erased ports, and SIGTERM handling (in a child process, since a
//! signal is process-wide).
//!
//! Isolation: every test gets its own run id (`nodekit-<pid>-<n>-<test>`), so its services
//! (`sonoflow/<run_id>/…`) never meet another test's or another run's; iceoryx2 removes them
//! when the last handle drops, also when a test panics (unwinding drops the kits and ports).
//! Every test body runs under a watchdog ([`within`]) so a lost wakeup fails the test instead of
//! hanging the run. Waits are on iceoryx2 events or channels, never sleeps; timeouts are
//! generous (seconds) for a loaded machine.

#![allow(clippy::unwrap_used)]

use sonoflow_messages::types::{RfFrame, StageStats};
use sonoflow_messages::{
    MessageType, MsgHeaderV1, RfFrameHeaderV3, StageStatsHeaderV1, FLAG_END_OF_STREAM, FLAG_REPLAYED, STAGE_FINISHED,
    STAGE_RUNNING,
};
use sonoflow_node_kit::{
    for_each, is_eos, select_loop, source_id, Flow, InSample, Input, Kit, KitError, NodeConfig, Output, SelectEnd,
    Step, TopicQos, STATS_TOPIC,
};
use std::any::Any;
use std::collections::BTreeMap;
use std::process::Command;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// Longest a test may take before the watchdog fails it.
const WATCHDOG: Duration = Duration::from_secs(120);
/// Handshake timeout of the nodes that are expected to connect.
const HANDSHAKE_S: f64 = 30.0;
/// Longest wait for one message / acknowledgement.
const MSG_WAIT: Duration = Duration::from_secs(30);
/// Set in a child process started by a signal test.
const CHILD_ENV: &str = "SONOFLOW_NODEKIT_TEST_CHILD";

// ---------------------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------------------

/// A run id (service prefix) no other test, test process or sonoflow run uses.
fn run_id(test: &str) -> String {
    static N: AtomicU32 = AtomicU32::new(0);
    format!("nodekit-{}-{}-{test}", std::process::id(), N.fetch_add(1, Ordering::Relaxed))
}

/// Runs `f` on its own thread and fails the test if it does not finish within [`WATCHDOG`]
/// (a hung wait must fail, not hang the test run). A panic in `f` is re-raised here.
fn within<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = mpsc::channel();
    let h = std::thread::spawn(move || {
        let r = f();
        let _ = tx.send(());
        r
    });
    match rx.recv_timeout(WATCHDOG) {
        Ok(()) | Err(mpsc::RecvTimeoutError::Disconnected) => match h.join() {
            Ok(r) => r,
            Err(panic) => std::panic::resume_unwind(panic),
        },
        Err(mpsc::RecvTimeoutError::Timeout) => panic!("test did not finish within {WATCHDOG:?} (a wait hung)"),
    }
}

/// An `RfFrameV3` topic with one publisher and `subscribers` subscribers, all expected.
fn rf_topic(topic: &str, depth: usize, subscribers: usize) -> TopicQos {
    TopicQos {
        topic: topic.into(),
        message_type: MessageType::RfFrameV3.name().into(),
        max_elements: 64,
        depth,
        max_subscribers: subscribers.max(1),
        max_publishers: 1,
        expected_subscribers: subscribers,
    }
}

/// The config the launcher would hand node `name` (ports → topics; no stats topic).
fn node_cfg(run_id: &str, name: &str, inputs: &[(&str, &TopicQos)], outputs: &[(&str, &TopicQos)]) -> NodeConfig {
    let ports = |v: &[(&str, &TopicQos)]| -> BTreeMap<String, TopicQos> {
        v.iter().map(|(p, q)| (p.to_string(), (*q).clone())).collect()
    };
    NodeConfig {
        run_id: run_id.into(),
        node_name: name.into(),
        node_index: 0,
        kind: "test".into(),
        params: serde_json::Value::Null,
        inputs: ports(inputs),
        outputs: ports(outputs),
        stats: None,
        handshake_timeout_s: HANDSHAKE_S,
        out_dir: None,
    }
}

/// What the launcher does before starting nodes: creates every topic's services and holds them,
/// so nodes started concurrently only open them (no creation race).
fn hold_topics(run_id: &str, topics: &[&TopicQos]) -> Vec<Box<dyn Any>> {
    let launcher = sonoflow_node_kit::create_node_with("nodekit-test-launcher", false).unwrap();
    let mut held: Vec<Box<dyn Any>> =
        topics.iter().map(|q| sonoflow_node_kit::open_topic_services(&launcher, run_id, q).unwrap()).collect();
    held.push(Box::new(launcher));
    held
}

/// An RF header with recognisable values in every field a producer sets.
fn rf_header(frame_id: u64, n_channels: u32, n_samples: u32) -> RfFrameHeaderV3 {
    let mut h = RfFrameHeaderV3 {
        fs: 40e6 + frame_id as f64,
        t0: 1.5e-6,
        fc: 5.2e6,
        c: 1540.0,
        pitch: 3e-4,
        tx_angle: -0.25,
        prf: 5000.0,
        n_channels,
        n_samples,
        tx_id: 7,
        sample_format: sonoflow_messages::SAMPLE_RF_F32,
        packet: 3,
        frame_in_packet: 11,
        ..Default::default()
    };
    for (i, d) in h.tx_delays.iter_mut().enumerate() {
        *d = i as f32 * 1e-8;
    }
    h.common = MsgHeaderV1 {
        frame_id,
        t_valid: frame_id as f64 * 2e-4,
        compute_ns: 1000 + frame_id,
        incarnation: 2,
        // Overwritten by the kit:
        seq: 999,
        t_pub_ns: 1,
        source_id: 1,
        ..Default::default()
    };
    h
}

/// Payload of frame `frame_id`: distinct, non-trivial values.
fn rf_payload(frame_id: u64, n: usize) -> Vec<f32> {
    (0..n).map(|i| (frame_id as f32) * 1000.0 + i as f32 * 0.5 - 3.25).collect()
}

/// Takes the next message, blocking on the input's event (at most [`MSG_WAIT`]).
fn recv(input: &mut Input<RfFrame>) -> InSample<RfFrame> {
    let deadline = Instant::now() + MSG_WAIT;
    loop {
        if let Some(s) = input.try_receive().unwrap() {
            return s;
        }
        assert!(Instant::now() < deadline, "no message on `{}` within {MSG_WAIT:?}", input.topic());
        input.wait(Duration::from_millis(500)).unwrap();
    }
}

/// Producer and consumer nodes of one topic in this thread, handshake done.
struct Pair {
    producer: Kit,
    consumer: Kit,
    out: Output<RfFrame>,
    input: Input<RfFrame>,
}

fn pair(test: &str, depth: usize) -> Pair {
    let id = run_id(test);
    let q = rf_topic("rf", depth, 1);
    let mut producer = Kit::new(node_cfg(&id, "producer", &[], &[("rf_out", &q)])).unwrap();
    let consumer = Kit::new(node_cfg(&id, "consumer", &[("rf_in", &q)], &[])).unwrap();
    let mut out = producer.output::<RfFrame>("rf_out").unwrap();
    let mut input = consumer.input::<RfFrame>("rf_in").unwrap();
    // One thread: both ports step in the same handshake loop.
    producer.handshake(&mut [&mut out, &mut input]).unwrap();
    Pair { producer, consumer, out, input }
}

fn assert_rf_header_kept(got: &RfFrameHeaderV3, sent: &RfFrameHeaderV3) {
    // Everything but the common fields the kit sets is as sent, bit for bit.
    let (a, b) = (bytemuck::bytes_of(got), bytemuck::bytes_of(sent));
    let common = std::mem::size_of::<MsgHeaderV1>();
    assert_eq!(a.len(), b.len());
    assert!(a[common..] == b[common..], "header fields after the common header changed in transit");
    assert_eq!(got.common.frame_id, sent.common.frame_id);
    assert_eq!(got.common.t_valid.to_bits(), sent.common.t_valid.to_bits());
    assert_eq!(got.common.compute_ns, sent.common.compute_ns);
    assert_eq!(got.common.incarnation, sent.common.incarnation);
    assert_eq!(got.common.flags, 0);
}

// ---------------------------------------------------------------------------------------------
// 1. Publish / subscribe
// ---------------------------------------------------------------------------------------------

/// Three messages, one through each publish path, arrive with header and payload bit for bit,
/// consecutive sequence numbers from 0, the producer's source id and a plausible publish time.
#[test]
fn publish_subscribe_keeps_header_payload_and_numbers_messages() {
    within(|| {
        let Pair { producer: _p, consumer: _c, mut out, mut input } = pair("pubsub", 4);
        assert_eq!(out.topic(), "rf");
        assert_eq!(out.max_elements(), 64);
        let t_before = sonoflow_node_kit::unix_ns();

        let h0 = rf_header(0, 4, 8);
        let p0 = rf_payload(0, 32);
        out.publish_copy(h0, &p0).unwrap();

        let h1 = rf_header(1, 2, 3);
        let p1 = rf_payload(1, 6);
        out.publish_in_place(p1.len(), h1, |dst| {
            for (d, s) in dst.iter_mut().zip(&p1) {
                d.write(*s);
            }
        })
        .unwrap();

        let h2 = rf_header(2, 8, 8);
        let p2 = rf_payload(2, 64);
        let r = out
            .publish_init(p2.len(), h2, |dst, h| {
                assert!(dst.iter().all(|v| *v == 0.0), "publish_init must zero the slot");
                dst.copy_from_slice(&p2);
                h.common.compute_ns = 4242;
                Ok::<(), String>(())
            })
            .unwrap();
        assert_eq!(r, Ok(()));
        let t_after = sonoflow_node_kit::unix_ns();

        let mut h2_sent = h2;
        h2_sent.common.compute_ns = 4242; // set by the fill closure
        for (seq, (h, p)) in [(h0, &p0), (h1, &p1), (h2_sent, &p2)].into_iter().enumerate() {
            let s = recv(&mut input);
            let got = s.user_header();
            assert_rf_header_kept(got, &h);
            assert_eq!(got.common.seq, seq as u64, "sequence numbers count from 0 per publisher");
            assert_eq!(got.common.source_id, source_id("producer"));
            assert!((t_before..=t_after).contains(&got.common.t_pub_ns), "t_pub_ns is the publish time");
            let bits: Vec<u32> = s.payload().iter().map(|v| v.to_bits()).collect();
            let want: Vec<u32> = p.iter().map(|v| v.to_bits()).collect();
            assert_eq!(bits, want, "payload of message {seq}");
            assert!(!is_eos::<RfFrame>(got));
        }
        assert!(input.try_receive().unwrap().is_none(), "exactly three messages");
        assert_eq!((input.received, input.gaps, input.eos), (3, 0, false));
        assert_eq!(out.sent, 3);
        assert_eq!(out.bytes, ((32 + 6 + 64) * 4) as u64);
    });
}

/// A message larger than the topic maximum and a `publish_init` whose fill fails send nothing
/// and use no sequence number; a raw payload that is not whole elements is refused.
#[test]
fn refused_publishes_send_nothing() {
    within(|| {
        let Pair { producer: _p, consumer: _c, mut out, mut input } = pair("refused", 4);
        match out.publish_copy(rf_header(0, 1, 65), &[0.0; 65]) {
            Err(KitError::TooLarge { topic, len, max }) => assert_eq!((topic.as_str(), len, max), ("rf", 65, 64)),
            other => panic!("expected TooLarge, got {other:?}"),
        }
        let r = out.publish_init(4, rf_header(0, 1, 4), |_, _| Err("kernel failed")).unwrap();
        assert_eq!(r, Err("kernel failed"));
        match out.publish_raw(rf_header(0, 1, 1), &[0u8; 6]) {
            Err(KitError::Port { port, detail }) => {
                assert_eq!(port, "rf");
                assert!(detail.contains("not a multiple of the element size 4"), "{detail}");
            }
            other => panic!("expected a Port error, got {other:?}"),
        }
        assert_eq!((out.sent, out.bytes), (0, 0));
        assert!(input.try_receive().unwrap().is_none(), "nothing was sent");

        out.publish_copy(rf_header(5, 1, 1), &[1.0]).unwrap();
        let s = recv(&mut input);
        assert_eq!((s.user_header().common.seq, s.user_header().common.frame_id), (0, 5));
        drop(s);
        assert_eq!((input.received, input.gaps), (1, 0));
    });
}

/// `gaps` counts each jump in a publisher's sequence numbers (a lost message), per publisher;
/// `publish_raw` keeps the given sequence number and the next normal publish continues from it.
#[test]
fn gaps_count_sequence_jumps_per_publisher() {
    within(|| {
        let Pair { producer: _p, consumer: _c, mut out, mut input } = pair("gaps", 16);
        let raw = |out: &mut Output<RfFrame>, src: u32, seq: u64| {
            let mut h = rf_header(seq, 1, 2);
            h.common.seq = seq;
            h.common.source_id = src;
            out.publish_raw(h, bytemuck::cast_slice(&[seq as f32, -1.0])).unwrap();
        };
        // Source 7: 0 1 _ 3 4 _ _ 7  → two gaps (2 missing; 5 and 6 missing).
        for seq in [0, 1, 3, 4, 7] {
            raw(&mut out, 7, seq);
        }
        // Source 8 starts at 10 and interleaves with source 7: no gap, sequences are per source.
        raw(&mut out, 8, 10);
        raw(&mut out, 8, 11);
        // Back to normal publishing: continues after the last raw sequence number (11 → 12),
        // under the producer's own source id (first message of that source: no gap).
        out.publish_copy(rf_header(99, 1, 1), &[9.0]).unwrap();

        let mut seen = Vec::new();
        for _ in 0..8 {
            let s = recv(&mut input);
            let c = s.user_header().common;
            assert_eq!(s.payload().len(), if c.frame_id == 99 { 1 } else { 2 });
            seen.push((c.source_id, c.seq));
        }
        let me = source_id("producer");
        assert_eq!(seen, [(7, 0), (7, 1), (7, 3), (7, 4), (7, 7), (8, 10), (8, 11), (me, 12)]);
        assert_eq!(input.received, 8);
        assert_eq!(input.gaps, 2, "one gap per jump in a source's sequence");
    });
}

// ---------------------------------------------------------------------------------------------
// 2. End of stream and for_each
// ---------------------------------------------------------------------------------------------

/// A producer on its own thread (its own node, as in a separate process) sends 40 frames through
/// a queue of depth 3 (so it blocks on back-pressure and the consumer blocks on the event), then
/// end of stream: `for_each` sees every frame in order, then returns `true` on end of stream.
#[test]
fn end_of_stream_ends_for_each_after_every_message() {
    within(|| {
        const N: u64 = 40;
        let id = run_id("eos");
        let q = rf_topic("rf", 3, 1);
        let _held = hold_topics(&id, &[&q]);
        let (pid, pq) = (id.clone(), q.clone());
        let producer = std::thread::spawn(move || {
            let mut kit = Kit::new(node_cfg(&pid, "producer", &[], &[("rf_out", &pq)])).unwrap();
            let mut out = kit.output::<RfFrame>("rf_out").unwrap();
            kit.handshake(&mut [&mut out]).unwrap();
            for f in 0..N {
                out.publish_copy(rf_header(f, 1, 5), &rf_payload(f, 5)).unwrap();
            }
            out.publish_eos(0.125).unwrap();
            (out.sent, out.bytes)
        });

        let mut kit = Kit::new(node_cfg(&id, "consumer", &[("rf_in", &q)], &[])).unwrap();
        let mut input = kit.input::<RfFrame>("rf_in").unwrap();
        kit.handshake(&mut [&mut input]).unwrap();
        let mut frames = Vec::new();
        let ended = for_each(&mut kit, &mut input, |kit, s| {
            let h = s.user_header();
            assert_eq!(h.common.seq, h.common.frame_id);
            assert_eq!(s.payload(), rf_payload(h.common.frame_id, 5).as_slice());
            frames.push(h.common.frame_id);
            kit.stats.messages_in += 1;
            Ok(Flow::Continue)
        })
        .unwrap();
        assert!(ended, "for_each returns true at end of stream");
        assert_eq!(frames, (0..N).collect::<Vec<_>>(), "every message before the end of stream, in order");
        assert!(input.eos);
        assert_eq!((input.received, input.gaps), (N, 0), "the end-of-stream marker is not counted");
        assert_eq!(kit.stats.messages_in, N);
        assert!(input.try_receive().unwrap().is_none(), "nothing after the end of stream");
        let (sent, bytes) = producer.join().unwrap();
        assert_eq!(sent, N, "the end-of-stream marker is not counted as sent");
        assert_eq!(bytes, N * 5 * 4);
    });
}

/// The end-of-stream marker: empty payload, `FLAG_END_OF_STREAM`, the given time, the next
/// sequence number; `Flow::Stop` ends `for_each` early (returning false) and leaves the rest
/// of the queue in place.
#[test]
fn eos_marker_and_flow_stop() {
    within(|| {
        let Pair { producer: _p, mut consumer, mut out, mut input } = pair("stop", 8);
        for f in 0..5 {
            out.publish_copy(rf_header(f, 1, 1), &[f as f32]).unwrap();
        }
        out.publish_eos(2.5).unwrap();

        let mut seen = Vec::new();
        let ended = for_each(&mut consumer, &mut input, |_, s| {
            seen.push(s.user_header().common.frame_id);
            Ok(if seen.len() == 3 { Flow::Stop } else { Flow::Continue })
        })
        .unwrap();
        assert!(!ended, "a stop from the body is not an end of stream");
        assert_eq!(seen, [0, 1, 2]);
        assert!(!input.eos);
        assert_eq!(recv(&mut input).user_header().common.frame_id, 3, "the queue keeps the rest");
        assert_eq!(recv(&mut input).user_header().common.frame_id, 4);
        let eos = recv(&mut input);
        let h = eos.user_header();
        assert!(is_eos::<RfFrame>(h));
        assert_eq!(h.common.flags, FLAG_END_OF_STREAM);
        assert_eq!(h.common.t_valid, 2.5);
        assert_eq!(h.common.seq, 5);
        assert!(eos.payload().is_empty());
        drop(eos);
        assert!(input.eos);
        assert_eq!(input.received, 5);

        // An error from the body ends for_each with that error.
        out.publish_copy(rf_header(6, 1, 1), &[0.0]).unwrap();
        let err = for_each(&mut consumer, &mut input, |_, _| anyhow::bail!("body failed")).unwrap_err();
        assert_eq!(err.to_string(), "body failed");
    });
}

// ---------------------------------------------------------------------------------------------
// 3. select_loop over several inputs
// ---------------------------------------------------------------------------------------------

/// Two inputs fed in lock step by a producer on its own thread: it sends one message (or end of
/// stream) on `a` or `b` only after the consumer acknowledged the previous one, so every body
/// call that finds something needs a fresh wakeup from that input. With a 60 s select timeout
/// the loop could not finish in time on timeouts alone; it must end `Done` once both streams
/// ended, with both streams' messages in the order sent.
#[test]
fn select_loop_wakes_for_each_input_and_ends_when_both_streams_end() {
    within(|| {
        let id = run_id("select");
        let qa = rf_topic("a", 2, 1);
        let qb = rf_topic("b", 2, 1);
        let _held = hold_topics(&id, &[&qa, &qb]);
        // The order the producer sends in: 'a'/'b' = message, 'A'/'B' = end of stream.
        const PLAN: &str = "ababbbaaBaA";
        let (ack_tx, ack_rx) = mpsc::channel::<char>();
        let (pid, pqa, pqb) = (id.clone(), qa.clone(), qb.clone());
        let producer = std::thread::spawn(move || {
            let mut kit = Kit::new(node_cfg(&pid, "producer", &[], &[("a", &pqa), ("b", &pqb)])).unwrap();
            let mut a = kit.output::<RfFrame>("a").unwrap();
            let mut b = kit.output::<RfFrame>("b").unwrap();
            kit.handshake(&mut [&mut a, &mut b]).unwrap();
            for (i, c) in PLAN.chars().enumerate() {
                let h = rf_header(i as u64, 1, 1);
                match c {
                    'a' => a.publish_copy(h, &[i as f32]).unwrap(),
                    'b' => b.publish_copy(h, &[i as f32]).unwrap(),
                    'A' => a.publish_eos(0.0).unwrap(),
                    _ => b.publish_eos(0.0).unwrap(),
                }
                let ack = ack_rx.recv_timeout(MSG_WAIT).expect("consumer acknowledgement");
                assert_eq!(ack, c, "acknowledged out of order");
            }
        });

        let mut kit = Kit::new(node_cfg(&id, "consumer", &[("a_in", &qa), ("b_in", &qb)], &[])).unwrap();
        let mut ia = kit.input::<RfFrame>("a_in").unwrap();
        let mut ib = kit.input::<RfFrame>("b_in").unwrap();
        kit.handshake(&mut [&mut ia, &mut ib]).unwrap();
        let wakeups = [ia.wakeup(), ib.wakeup()];
        let mut got = String::new();
        let t0 = Instant::now();
        let end = select_loop(&mut kit, &wakeups, Duration::from_secs(60), |_| {
            for (input, name) in [(&mut ia, 'a'), (&mut ib, 'b')] {
                while let Some(s) = input.try_receive()? {
                    let c = if is_eos::<RfFrame>(s.user_header()) {
                        name.to_ascii_uppercase()
                    } else {
                        assert_eq!(s.payload(), [s.user_header().common.frame_id as f32]);
                        name
                    };
                    got.push(c);
                    ack_tx.send(c)?;
                }
            }
            Ok(if ia.eos && ib.eos { Step::Done } else { Step::Continue })
        })
        .unwrap();
        let elapsed = t0.elapsed();
        assert_eq!(end, SelectEnd::Done);
        assert_eq!(got, PLAN, "every message of both inputs, in the order sent");
        assert!(elapsed < Duration::from_secs(60), "woken by the inputs, not by the timeout ({elapsed:?})");
        assert_eq!((ia.received, ib.received), (5, 4));
        producer.join().unwrap();
    });
}

/// With nothing arriving, `select_loop` calls the body again after each timeout and ends
/// `Done` when the body says so.
#[test]
fn select_loop_calls_the_body_again_after_a_timeout() {
    within(|| {
        let id = run_id("select-timeout");
        let q = rf_topic("quiet", 2, 1);
        let mut kit = Kit::new(node_cfg(&id, "consumer", &[("in", &q)], &[])).unwrap();
        let input = kit.input::<RfFrame>("in").unwrap();
        let mut calls = 0;
        let t0 = Instant::now();
        let end = select_loop(&mut kit, &[input.wakeup()], Duration::from_millis(100), |_| {
            calls += 1;
            Ok(if calls == 3 { Step::Done } else { Step::Continue })
        })
        .unwrap();
        assert_eq!(end, SelectEnd::Done);
        assert_eq!(calls, 3);
        assert!(t0.elapsed() >= Duration::from_millis(200), "two timeouts passed ({:?})", t0.elapsed());

        // An error from the body ends the loop with it.
        let err = select_loop(&mut kit, &[input.wakeup()], Duration::from_millis(10), |_| anyhow::bail!("bad input"))
            .unwrap_err();
        assert_eq!(err.to_string(), "bad input");
    });
}

// ---------------------------------------------------------------------------------------------
// 4. Start-up handshake
// ---------------------------------------------------------------------------------------------

/// Producer and consumer as separate nodes on separate threads, each running only its own
/// handshake, in both start orders (the second node is created only after the first one's
/// ports exist): the handshake completes and the very first frame after it arrives (without the
/// handshake iceoryx2 drops early frames). `consumer_first` = the launcher's order.
fn handshake_then_first_frame(test: &str, consumer_first: bool) {
    let id = run_id(test);
    let q = rf_topic("rf", 4, 1);
    let _held = hold_topics(&id, &[&q]);
    let (created_tx, created_rx) = mpsc::channel::<()>();
    let (pid, pq) = (id.clone(), q.clone());
    let start_producer = move |created: Option<mpsc::Sender<()>>| {
        std::thread::spawn(move || {
            let mut kit = Kit::new(node_cfg(&pid, "producer", &[], &[("rf_out", &pq)])).unwrap();
            let mut out = kit.output::<RfFrame>("rf_out").unwrap();
            if let Some(c) = created {
                c.send(()).unwrap();
            }
            kit.handshake(&mut [&mut out]).unwrap();
            out.publish_copy(rf_header(0, 1, 2), &[1.0, 2.0]).unwrap();
            out.publish_eos(0.0).unwrap();
        })
    };
    let (cid, cq) = (id.clone(), q.clone());
    let start_consumer = move |created: Option<mpsc::Sender<()>>| {
        std::thread::spawn(move || {
            let mut kit = Kit::new(node_cfg(&cid, "consumer", &[("rf_in", &cq)], &[])).unwrap();
            let mut input = kit.input::<RfFrame>("rf_in").unwrap();
            if let Some(c) = created {
                c.send(()).unwrap();
            }
            kit.handshake(&mut [&mut input]).unwrap();
            let mut frames = Vec::new();
            let ended = for_each(&mut kit, &mut input, |_, s| {
                frames.push((s.user_header().common.seq, s.payload().to_vec()));
                Ok(Flow::Continue)
            })
            .unwrap();
            (ended, frames, input.gaps)
        })
    };
    let (producer, consumer) = if consumer_first {
        let c = start_consumer(Some(created_tx));
        created_rx.recv_timeout(MSG_WAIT).unwrap();
        (start_producer(None), c)
    } else {
        let p = start_producer(Some(created_tx));
        created_rx.recv_timeout(MSG_WAIT).unwrap();
        (p, start_consumer(None))
    };
    producer.join().unwrap();
    let (ended, frames, gaps) = consumer.join().unwrap();
    assert!(ended);
    assert_eq!(frames, [(0, vec![1.0, 2.0])], "the first frame after the handshake is delivered");
    assert_eq!(gaps, 0);
}

#[test]
fn handshake_completes_consumer_started_first() {
    within(|| handshake_then_first_frame("hs-consumer-first", true));
}

#[test]
fn handshake_completes_producer_started_first() {
    within(|| handshake_then_first_frame("hs-producer-first", false));
}

fn expect_timeout(r: Result<(), KitError>, seconds: f64) -> String {
    match r {
        Err(KitError::Timeout { what, seconds: s }) => {
            assert_eq!(s, seconds);
            let msg = KitError::Timeout { what: what.clone(), seconds: s }.to_string();
            assert!(msg.starts_with(&format!("timed out after {seconds:.1} s waiting for ")), "{msg}");
            what
        }
        other => panic!("expected a handshake timeout, got {other:?}"),
    }
}

/// Without its subscribers a producer's handshake fails after `handshake_timeout_s` (not
/// before), naming the topic and how many subscribers it expected and got; a consumer without
/// its publisher likewise names the topic.
#[test]
fn handshake_times_out_naming_the_missing_peer() {
    within(|| {
        let id = run_id("hs-timeout");
        // Two subscribers expected, one present.
        let q = rf_topic("rf", 2, 2);
        let lonely = rf_topic("nobody-publishes", 2, 1);
        let mut pcfg = node_cfg(&id, "producer", &[], &[("rf_out", &q)]);
        pcfg.handshake_timeout_s = 0.5;
        let mut producer = Kit::new(pcfg).unwrap();
        let mut ccfg = node_cfg(&id, "consumer", &[("rf_in", &q), ("lonely", &lonely)], &[]);
        ccfg.handshake_timeout_s = 0.3;
        let mut consumer = Kit::new(ccfg).unwrap();
        let mut out = producer.output::<RfFrame>("rf_out").unwrap();
        let mut input = consumer.input::<RfFrame>("rf_in").unwrap();
        let mut lonely_in = consumer.input::<RfFrame>("lonely").unwrap();

        let t0 = Instant::now();
        let what = expect_timeout(producer.handshake(&mut [&mut out, &mut input]), 0.5);
        assert!(t0.elapsed() >= Duration::from_millis(500), "not before the timeout ({:?})", t0.elapsed());
        assert_eq!(what, "2 subscriber(s) of `rf` (ready: 1)");

        let t0 = Instant::now();
        let what = expect_timeout(consumer.handshake(&mut [&mut input, &mut lonely_in]), 0.3);
        assert!(t0.elapsed() >= Duration::from_millis(300));
        assert_eq!(what, "the publisher of `nobody-publishes`", "only the missing peer is named");
    });
}

/// A topic with several publishers (`_stats`: one per node): the input joins once all of them
/// exist, every publisher's handshake completes, and messages from both arrive with no gap
/// counted although their sequence numbers interleave.
#[test]
fn handshake_with_two_publishers_on_one_topic() {
    within(|| {
        let id = run_id("hs-two-pub");
        let q = TopicQos { max_publishers: 2, ..rf_topic("shared", 8, 1) };
        let mut p1 = Kit::new(node_cfg(&id, "p1", &[], &[("out", &q)])).unwrap();
        let p2 = Kit::new(node_cfg(&id, "p2", &[], &[("out", &q)])).unwrap();
        let c = Kit::new(node_cfg(&id, "c", &[("in", &q)], &[])).unwrap();
        let mut o1 = p1.output::<RfFrame>("out").unwrap();
        let mut input = c.input::<RfFrame>("in").unwrap();
        // Only one publisher exists yet: the input waits for the second (grace period 10 s).
        let mut first = Kit::new(NodeConfig { handshake_timeout_s: 0.2, ..node_cfg(&id, "x", &[], &[]) }).unwrap();
        let what = expect_timeout(first.handshake(&mut [&mut input, &mut o1]), 0.2);
        assert!(what.contains("the publisher of `shared`"), "{what}");
        drop(first);

        let mut o2 = p2.output::<RfFrame>("out").unwrap();
        p1.handshake(&mut [&mut input, &mut o1, &mut o2]).unwrap();
        for f in 0..3 {
            o1.publish_copy(rf_header(f, 1, 1), &[1.0]).unwrap();
            o2.publish_copy(rf_header(f, 1, 1), &[2.0]).unwrap();
        }
        let mut by_source = BTreeMap::<u32, Vec<u64>>::new();
        for _ in 0..6 {
            let s = recv(&mut input);
            by_source.entry(s.user_header().common.source_id).or_default().push(s.user_header().common.seq);
        }
        assert_eq!(by_source.get(&source_id("p1")), Some(&vec![0, 1, 2]));
        assert_eq!(by_source.get(&source_id("p2")), Some(&vec![0, 1, 2]));
        assert_eq!((input.received, input.gaps), (6, 0));
    });
}

/// A port the launch file did not wire, and a topic whose message type is not the port's, are
/// errors naming the port / topic and both types.
#[test]
fn unwired_port_and_wrong_message_type_are_named() {
    within(|| {
        let id = run_id("ports");
        let q = rf_topic("rf", 2, 1);
        let kit = Kit::new(node_cfg(&id, "n", &[("rf_in", &q)], &[])).unwrap();
        match kit.output::<RfFrame>("rf_out") {
            Err(KitError::Port { port, detail }) => {
                assert_eq!(port, "rf_out");
                assert!(detail.contains("node `n` has no output `rf_out`"), "{detail}");
            }
            Err(e) => panic!("expected a Port error, got {e}"),
            Ok(_) => panic!("expected a Port error"),
        }
        match kit.input::<StageStats>("rf_in") {
            Err(KitError::Config(msg)) => {
                assert_eq!(msg, "topic `rf` carries RfFrameV3 but the port expects StageStatsV1");
            }
            Err(e) => panic!("expected a Config error, got {e}"),
            Ok(_) => panic!("expected a Config error"),
        }
    });
}

// ---------------------------------------------------------------------------------------------
// Stage statistics and type-erased ports (recorder / replay)
// ---------------------------------------------------------------------------------------------

fn stats_topic(publishers: usize, subscribers: usize) -> TopicQos {
    TopicQos {
        topic: STATS_TOPIC.into(),
        message_type: MessageType::StageStatsV1.name().into(),
        max_elements: 256,
        depth: 16,
        max_subscribers: subscribers.max(1),
        max_publishers: publishers,
        expected_subscribers: subscribers,
    }
}

/// A node with a stats topic takes part in the handshake with it; `record` publishes a running
/// stage-statistics message and `finish` a final one with end of stream (payload: the node
/// name), and returns the counters.
#[test]
fn stats_port_records_and_finishes() {
    within(|| {
        let id = run_id("stats");
        let sq = stats_topic(1, 1);
        let mut cfg = node_cfg(&id, "worker", &[], &[]);
        cfg.node_index = 3;
        cfg.stats = Some(sq.clone());
        let mut kit = Kit::new(cfg).unwrap();
        let recorder = Kit::new(node_cfg(&id, "rec", &[], &[])).unwrap();
        let mut stats_in = recorder.input_for::<StageStats>(&sq).unwrap();
        kit.handshake(&mut [&mut stats_in]).unwrap();

        kit.stats.messages_in = 5;
        kit.stats.messages_out = 4;
        kit.record(17, 0.5, 1234).unwrap();
        let recv_stats = |input: &mut Input<StageStats>| -> (StageStatsHeaderV1, Vec<u8>) {
            let deadline = Instant::now() + MSG_WAIT;
            loop {
                if let Some(s) = input.try_receive().unwrap() {
                    return (*s.user_header(), s.payload().to_vec());
                }
                assert!(Instant::now() < deadline, "no stats message");
                input.wait(Duration::from_millis(500)).unwrap();
            }
        };
        let (h, name) = recv_stats(&mut stats_in);
        assert_eq!(name, b"worker");
        assert_eq!((h.node_index, h.state, h.messages_in, h.messages_out), (3, STAGE_RUNNING, 5, 4));
        assert_eq!((h.common.frame_id, h.common.t_valid, h.last_compute_ns, h.compute_ns_total), (17, 0.5, 1234, 1234));
        assert_eq!(h.common.flags & FLAG_END_OF_STREAM, 0);

        let stats = kit.finish().unwrap();
        assert_eq!((stats.node.as_str(), stats.messages_in, stats.compute_ns_total), ("worker", 5, 1234));
        assert!(stats.wall_ns > 0);
        let (h, name) = recv_stats(&mut stats_in);
        assert_eq!(name, b"worker");
        assert_eq!(h.state, STAGE_FINISHED);
        assert_eq!(h.common.flags & FLAG_END_OF_STREAM, FLAG_END_OF_STREAM);
        assert!(stats_in.eos);
        assert_eq!((stats_in.received, stats_in.gaps), (1, 0));
    });
}

/// When the only thing missing is the stats subscriber (a recorder that never started), the
/// handshake timeout names the stats topic.
#[test]
fn handshake_timeout_names_a_missing_stats_subscriber() {
    within(|| {
        let id = run_id("stats-timeout");
        let mut cfg = node_cfg(&id, "worker", &[], &[]);
        cfg.stats = Some(stats_topic(1, 1));
        cfg.handshake_timeout_s = 0.2;
        let mut kit = Kit::new(cfg).unwrap();
        let what = expect_timeout(kit.handshake(&mut []), 0.2);
        assert_eq!(what, "1 subscriber(s) of `_stats` (ready: 0)");
    });
}

/// Replay → recorder path: a type-erased output republishes raw header bytes keeping the
/// recorded sequence number and adding flags; a type-erased input hands the same header and
/// payload bytes to its callback and reports end of stream separately.
#[test]
fn dyn_ports_pass_raw_bytes() {
    within(|| {
        let id = run_id("dyn");
        let q = rf_topic("rf", 4, 1);
        let mut producer = Kit::new(node_cfg(&id, "replay", &[], &[])).unwrap();
        let consumer = Kit::new(node_cfg(&id, "rec", &[], &[])).unwrap();
        let mut out = producer.dyn_output(&q).unwrap();
        let mut input = consumer.dyn_input(&q).unwrap();
        assert_eq!((out.kind(), out.topic_name()), (MessageType::RfFrameV3, "rf"));
        assert_eq!((input.kind(), input.topic_name()), (MessageType::RfFrameV3, "rf"));
        producer.handshake(&mut [out.as_mut(), input.as_mut()]).unwrap();

        let mut h = rf_header(8, 1, 3);
        h.common.seq = 41;
        h.common.source_id = 77;
        let payload = [0.5f32, -1.0, 3.0];
        let err = out.publish_bytes(&bytemuck::bytes_of(&h)[1..], bytemuck::cast_slice(&payload), 0).unwrap_err();
        assert!(err.to_string().contains("RfFrameV3 expects"), "{err}");
        out.publish_bytes(bytemuck::bytes_of(&h), bytemuck::cast_slice(&payload), FLAG_REPLAYED).unwrap();
        out.eos(9.0).unwrap();
        assert_eq!(out.sent(), 1);

        // Same thread: both messages are in the input's queue once the sends returned.
        let mut got: Vec<(Vec<u8>, Vec<u8>)> = Vec::new();
        let mut keep = |hb: &[u8], pb: &[u8]| -> Result<(), KitError> {
            got.push((hb.to_vec(), pb.to_vec()));
            Ok(())
        };
        assert_eq!(input.receive_with(&mut keep).unwrap(), Some(false), "a message");
        assert_eq!(input.receive_with(&mut keep).unwrap(), Some(true), "end of stream");
        assert_eq!(input.receive_with(&mut keep).unwrap(), None, "nothing more");
        assert_eq!(got.len(), 1, "the end-of-stream marker is not passed to the callback");
        let mut want = h;
        want.common.flags |= FLAG_REPLAYED;
        assert_eq!(got[0].0, bytemuck::bytes_of(&want), "header kept byte for byte, flags added");
        assert_eq!(got[0].1, bytemuck::cast_slice::<f32, u8>(&payload));
        assert_eq!(input.counters(), (1, 0, true));
    });
}

// ---------------------------------------------------------------------------------------------
// SIGTERM (child processes: a signal reaches the whole test process)
// ---------------------------------------------------------------------------------------------

/// Runs the ignored test `name` of this binary in a child process (with [`CHILD_ENV`] set) and
/// returns its stdout; fails if it fails or takes more than a minute.
fn run_child(name: &str) -> String {
    let exe = std::env::current_exe().unwrap();
    let mut child = Command::new(exe)
        .args([name, "--exact", "--ignored", "--nocapture", "--test-threads=1"])
        .env(CHILD_ENV, "1")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        if child.try_wait().unwrap().is_some() {
            break;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("child test `{name}` did not finish within 60 s");
        }
        std::thread::sleep(Duration::from_millis(20)); // polling a child process: no event to wait on
    }
    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "child test `{name}` failed ({}):\n{stdout}\n{stderr}", out.status);
    stdout
}

fn is_child() -> bool {
    std::env::var_os(CHILD_ENV).is_some()
}

/// SIGTERM to the calling thread: its handler has run when this returns (a process-directed
/// `kill` may be handled later by another thread, e.g. the test harness's main thread).
fn sigterm_self() {
    // SAFETY: plain libc calls on the calling thread.
    let rc = unsafe { libc::pthread_kill(libc::pthread_self(), libc::SIGTERM) };
    assert_eq!(rc, 0);
}

#[test]
fn select_loop_ends_terminated_on_sigterm() {
    let out = run_child("child_select_loop_sigterm");
    assert!(out.contains("CHILD OK select_loop Terminated after 2 calls"), "{out}");
}

#[test]
#[ignore = "run by select_loop_ends_terminated_on_sigterm in a child process"]
fn child_select_loop_sigterm() {
    if !is_child() {
        return;
    }
    let id = run_id("child-select");
    let q = rf_topic("rf", 2, 1);
    let mut kit = Kit::new(node_cfg(&id, "consumer", &[("in", &q)], &[])).unwrap();
    let input = kit.input::<RfFrame>("in").unwrap();
    let mut calls = 0;
    let t0 = Instant::now();
    let end = select_loop(&mut kit, &[input.wakeup()], Duration::from_secs(60), |_| {
        calls += 1;
        if calls == 1 {
            sigterm_self();
        }
        Ok(Step::Continue)
    })
    .unwrap();
    assert_eq!(end, SelectEnd::Terminated);
    assert_eq!(calls, 2, "the body runs once more after the termination request");
    assert!(t0.elapsed() < Duration::from_secs(60), "ended by the signal, not the timeout");
    println!("CHILD OK select_loop {end:?} after {calls} calls");
}

#[test]
fn for_each_ends_on_sigterm_during_its_wait() {
    let out = run_child("child_for_each_sigterm");
    assert!(out.contains("CHILD OK for_each ended=false"), "{out}");
}

#[test]
#[ignore = "run by for_each_ends_on_sigterm_during_its_wait in a child process"]
fn child_for_each_sigterm() {
    if !is_child() {
        return;
    }
    let Pair { producer: _p, mut consumer, out: _out, mut input } = pair("child-for-each", 2);
    // SAFETY: plain libc calls; the signal goes to this (the waiting) thread.
    let me = unsafe { libc::pthread_self() };
    let signaller = std::thread::spawn(move || {
        // Aim for the moment for_each blocks in its wait; any moment must give the same result.
        std::thread::sleep(Duration::from_millis(300));
        // SAFETY: `me` is alive: it joins this thread after for_each returns.
        unsafe { libc::pthread_kill(me, libc::SIGTERM) };
    });
    let ended = for_each(&mut consumer, &mut input, |_, _| Ok(Flow::Continue));
    signaller.join().unwrap();
    let ended = ended.unwrap();
    assert!(!ended, "a termination request is not an end of stream");
    println!("CHILD OK for_each ended={ended}");
}

#[test]
fn sigterm_before_the_first_wait_becomes_terminated() {
    let out = run_child("child_early_sigterm");
    assert!(out.contains("CHILD OK early SIGTERM -> Terminated"), "{out}");
}

#[test]
#[ignore = "run by sigterm_before_the_first_wait_becomes_terminated in a child process"]
fn child_early_sigterm() {
    if !is_child() {
        return;
    }
    let id = run_id("child-early");
    let kit = Kit::new(node_cfg(&id, "n", &[], &[])).unwrap();
    // A node busy before its first wait (long set-up) is asked to stop: it must end cleanly at
    // the next check, not die of the signal.
    sigterm_self();
    assert!(matches!(kit.check_termination(), Err(KitError::Terminated)));
    println!("CHILD OK early SIGTERM -> Terminated");
}
