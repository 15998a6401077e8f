//! sonoflow node kit — the only code in the project that talks to iceoryx2.
//!
//! * **Services** `sonoflow/<run_id>/<topic>` (publish–subscribe of `[Elem]` with a user
//!   header), an event service of the same name (one notification per sample, so consumers block
//!   instead of polling) and `…/<topic>/ready` (start-up handshake). QoS is explicit and lossless:
//!   safe overflow off, `RetryUntilDelivered`, static allocation of `max_elements`.
//! * **Handshake** (DESIGN.md pitfall 1): every node creates all its ports first; a consumer
//!   waits for the producer, calls `update_connections()` and notifies `ready`; a producer waits
//!   for `expected_subscribers` ready notifications before its first send. Without it iceoryx2
//!   drops the first frames silently even on lossless services.
//! * **Zero copy**: [`Output::publish_in_place`] loans an uninitialised slice in shared memory
//!   and lets the caller write into it.
//! * **Shutdown**: SIGINT/SIGTERM become [`KitError::Terminated`] at the next wait; producers
//!   end a stream with an end-of-stream message ([`Output::publish_eos`]).
//! * **Dead-node cleanup** at start ([`cleanup_dead_nodes`]), so a crashed run never poisons
//!   the next one.
//! * **Timing**: per-message thread CPU time in every header (`compute_ns`) and per-node
//!   statistics ([`Kit::finish`]).

pub mod config;
pub mod receive;
pub mod spec;

pub use config::{NodeConfig, TopicQos, NODE_CONFIG_ENV};
use iceoryx2::port::listener::{Listener, ListenerWaitError};
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;
use iceoryx2::sample_mut::SampleMut;
pub use receive::{for_each, select_loop, transform, Flow, SelectEnd, Step, Wakeup};
use sonoflow_messages::types::{StageStats, WireMessage};
use sonoflow_messages::{MessageType, MsgHeaderV1, StageStatsHeaderV1, FLAG_END_OF_STREAM};
pub use spec::{in_range, parse_params, port, KindSpec, PortDir, PortSpec, STATS_TOPIC};
use std::mem::MaybeUninit;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// Node-kit errors.
#[derive(Debug, thiserror::Error)]
pub enum KitError {
    #[error("configuration: {0}")]
    Config(String),
    #[error("shared memory transport ({context}): {detail}")]
    Ipc { context: String, detail: String },
    #[error("timed out after {seconds:.1} s waiting for {what}")]
    Timeout { what: String, seconds: f64 },
    #[error("termination requested (SIGINT/SIGTERM)")]
    Terminated,
    #[error("port `{port}`: {detail}")]
    Port { port: String, detail: String },
    #[error("message of {len} elements exceeds the topic maximum {max} (topic `{topic}`, raise `max_elements` in the launch file)")]
    TooLarge { topic: String, len: usize, max: usize },
}

fn ipc<E: std::fmt::Debug>(context: impl Into<String>) -> impl FnOnce(E) -> KitError {
    let context = context.into();
    move |e| KitError::Ipc { context, detail: format!("{e:?}") }
}

type Svc = ipc::Service;

/// Wall clock in UNIX nanoseconds.
pub fn unix_ns() -> u64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_nanos() as u64).unwrap_or(0)
}

fn clock_ns(clock: libc::clockid_t) -> u64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes into the timespec we own.
    let rc = unsafe { libc::clock_gettime(clock, &mut ts) };
    if rc != 0 {
        return 0;
    }
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// CPU time of the calling thread (ns).
pub fn thread_cpu_ns() -> u64 {
    clock_ns(libc::CLOCK_THREAD_CPUTIME_ID)
}

/// CPU time of the whole process (ns).
pub fn process_cpu_ns() -> u64 {
    clock_ns(libc::CLOCK_PROCESS_CPUTIME_ID)
}

/// FNV-1a hash of a node name (the `source_id` of its messages).
pub fn source_id(name: &str) -> u32 {
    let mut h: u32 = 0x811c9dc5;
    for b in name.bytes() {
        h ^= b as u32;
        h = h.wrapping_mul(0x01000193);
    }
    h
}

/// iceoryx2 configuration used by every process: defaults, loaded explicitly so no process
/// depends on its working directory.
pub fn iceoryx_config() -> Config {
    Config::default()
}

/// Creates an iceoryx2 node with the project's config and log level (IOX2_LOG_LEVEL, default
/// Error). Creating a node also removes resources of dead nodes.
pub fn create_node(name: &str) -> Result<Node<Svc>, KitError> {
    create_node_with(name, true)
}

/// Like [`create_node`]; `handle_signals = false` leaves SIGINT/SIGTERM to the caller
/// (the launcher installs its own handlers).
pub fn create_node_with(name: &str, handle_signals: bool) -> Result<Node<Svc>, KitError> {
    set_log_level_from_env_or(LogLevel::Error);
    let node_name = NodeName::new(name).map_err(ipc(format!("node name `{name}`")))?;
    let mode =
        if handle_signals { SignalHandlingMode::HandleTerminationRequests } else { SignalHandlingMode::Disabled };
    NodeBuilder::new()
        .name(&node_name)
        .signal_handling_mode(mode)
        .config(&iceoryx_config())
        .create::<Svc>()
        .map_err(ipc("creating the iceoryx2 node"))
}

/// Removes the shared-memory resources of every dead iceoryx2 node on this machine. Returns the
/// number of dead nodes found.
pub fn cleanup_dead_nodes() -> Result<usize, KitError> {
    set_log_level_from_env_or(LogLevel::Error);
    let cfg = iceoryx_config();
    let mut dead = 0;
    Node::<Svc>::list(&cfg, |state| {
        if let NodeState::Dead(view) = state {
            dead += 1;
            let _ = view.try_remove_stale_resources();
        }
        CallbackProgression::Continue
    })
    .map_err(ipc("listing iceoryx2 nodes"))?;
    Ok(dead)
}

fn service_name(run_id: &str, topic: &str, suffix: &str) -> Result<ServiceName, KitError> {
    let s = format!("sonoflow/{run_id}/{topic}{suffix}");
    ServiceName::new(&s).map_err(ipc(format!("service name `{s}`")))
}

/// The three services of one topic, opened (or created) with the topic's QoS.
pub struct TopicServices<M: WireMessage> {
    pub qos: TopicQos,
    pubsub: iceoryx2::service::port_factory::publish_subscribe::PortFactory<Svc, [M::Elem], M::Header>,
    data_event: iceoryx2::service::port_factory::event::PortFactory<Svc>,
    ready_event: iceoryx2::service::port_factory::event::PortFactory<Svc>,
}

impl<M: WireMessage> TopicServices<M> {
    /// Opens or creates the services of `qos.topic`.
    pub fn open(node: &Node<Svc>, run_id: &str, qos: &TopicQos) -> Result<Self, KitError> {
        if qos.message_type != M::TYPE.name() {
            return Err(KitError::Config(format!(
                "topic `{}` carries {} but the port expects {}",
                qos.topic,
                qos.message_type,
                M::TYPE.name()
            )));
        }
        let ctx = format!("topic `{}`", qos.topic);
        let pubsub = node
            .service_builder(&service_name(run_id, &qos.topic, "")?)
            .publish_subscribe::<[M::Elem]>()
            .user_header::<M::Header>()
            .payload_alignment(Alignment::new(64).ok_or_else(|| KitError::Config("alignment".into()))?)
            .max_publishers(qos.max_publishers.max(1))
            .max_subscribers(qos.max_subscribers.max(1))
            .subscriber_max_buffer_size(qos.depth.max(1))
            .subscriber_max_borrowed_samples(config::BORROWED_SAMPLES)
            .history_size(0)
            .enable_safe_overflow(false)
            .max_nodes(qos.max_publishers.max(1) + qos.max_subscribers.max(1) + 2)
            .open_or_create()
            .map_err(ipc(ctx.clone()))?;
        let nodes = qos.max_publishers.max(1) + qos.max_subscribers.max(1) + 2;
        let data_event = node
            .service_builder(&service_name(run_id, &qos.topic, "")?)
            .event()
            .max_nodes(nodes)
            .max_notifiers(qos.max_publishers.max(1) + 1)
            .max_listeners(qos.max_subscribers.max(1) + 1)
            .open_or_create()
            .map_err(ipc(ctx.clone()))?;
        let ready_event = node
            .service_builder(&service_name(run_id, &qos.topic, "/ready")?)
            .event()
            .max_nodes(nodes)
            .max_notifiers(qos.max_subscribers.max(1) + 1)
            .max_listeners(qos.max_publishers.max(1) + 1)
            .open_or_create()
            .map_err(ipc(ctx))?;
        Ok(Self { qos: qos.clone(), pubsub, data_event, ready_event })
    }
}

/// A typed output port.
pub struct Output<M: WireMessage> {
    services: TopicServices<M>,
    publisher: Publisher<Svc, [M::Elem], M::Header>,
    notifier: Notifier<Svc>,
    ready: Listener<Svc>,
    ready_count: usize,
    seq: u64,
    source_id: u32,
    /// Messages published.
    pub sent: u64,
    /// Payload bytes published.
    pub bytes: u64,
}

impl<M: WireMessage> Output<M> {
    fn new(node: &Node<Svc>, run_id: &str, qos: &TopicQos, node_name: &str) -> Result<Self, KitError> {
        let services = TopicServices::<M>::open(node, run_id, qos)?;
        let ctx = format!("output on topic `{}`", qos.topic);
        // The ready listener exists before the publisher, so no notification can be missed.
        let ready = services.ready_event.listener_builder().create().map_err(ipc(ctx.clone()))?;
        let publisher = services
            .pubsub
            .publisher_builder()
            .initial_max_slice_len(qos.max_elements.max(1))
            .allocation_strategy(AllocationStrategy::Static)
            .max_loaned_samples(config::LOANED_SAMPLES)
            .backpressure_strategy(BackpressureStrategy::RetryUntilDelivered)
            .create()
            .map_err(ipc(ctx.clone()))?;
        let notifier = services.data_event.notifier_builder().create().map_err(ipc(ctx))?;
        Ok(Self {
            services,
            publisher,
            notifier,
            ready,
            ready_count: 0,
            seq: 0,
            source_id: source_id(node_name),
            sent: 0,
            bytes: 0,
        })
    }

    /// Topic name.
    pub fn topic(&self) -> &str {
        &self.services.qos.topic
    }

    /// Maximum elements per message.
    pub fn max_elements(&self) -> usize {
        self.services.qos.max_elements
    }

    fn handshake_step(&mut self) -> Result<bool, KitError> {
        let ctx = format!("handshake on `{}`", self.topic());
        self.publisher.update_connections().map_err(ipc(ctx.clone()))?;
        let mut got = 0usize;
        self.ready.try_wait(|e| got += e.count as usize).map_err(ipc(ctx))?;
        self.ready_count += got;
        Ok(self.ready_count >= self.services.qos.expected_subscribers)
    }

    /// Loans `n` elements in shared memory, lets `fill` write every one of them in place, sets
    /// the common header fields (sequence, publish time, source) and sends.
    ///
    /// `fill` must initialise all `n` elements (they are `Pod`, so a missed element is garbage,
    /// never undefined behaviour on the type level; tests verify payloads end to end).
    pub fn publish_in_place<F>(&mut self, n: usize, header: M::Header, fill: F) -> Result<(), KitError>
    where
        F: FnOnce(&mut [MaybeUninit<M::Elem>]),
    {
        if n > self.max_elements() {
            return Err(KitError::TooLarge { topic: self.topic().to_string(), len: n, max: self.max_elements() });
        }
        let ctx = format!("publishing on `{}`", self.services.qos.topic);
        let mut sample = self.publisher.loan_slice_uninit(n).map_err(ipc(ctx.clone()))?;
        fill(sample.payload_mut());
        // SAFETY: the contract of `fill` is to write every element; elements are `Pod`.
        let sample = unsafe { sample.assume_init() };
        self.send(sample, header, n, ctx)
    }

    /// Stamps the header (sequence number, publish time, source), sends the sample of `n`
    /// elements and wakes the subscribers.
    fn send(
        &mut self,
        mut sample: SampleMut<Svc, [M::Elem], M::Header>,
        mut header: M::Header,
        n: usize,
        ctx: String,
    ) -> Result<(), KitError> {
        {
            let c = M::common_mut(&mut header);
            c.seq = self.seq;
            c.t_pub_ns = unix_ns();
            c.source_id = self.source_id;
        }
        *sample.user_header_mut() = header;
        let t0 = Instant::now();
        sample.send().map_err(ipc(ctx.clone()))?;
        add_output_wait(t0);
        self.notifier.notify().map_err(ipc(ctx))?;
        self.seq += 1;
        self.sent += 1;
        self.bytes += (n * std::mem::size_of::<M::Elem>()) as u64;
        Ok(())
    }

    /// Loans `n` zero-initialised elements in shared memory and lets `fill` compute into them
    /// (for library kernels that take `&mut [T]`); `fill` may also finish the header (e.g. set
    /// `compute_ns`). If `fill` fails, nothing is sent and its error is returned inside `Ok`.
    pub fn publish_init<F, E>(&mut self, n: usize, header: M::Header, fill: F) -> Result<Result<(), E>, KitError>
    where
        F: FnOnce(&mut [M::Elem], &mut M::Header) -> Result<(), E>,
    {
        if n > self.max_elements() {
            return Err(KitError::TooLarge { topic: self.topic().to_string(), len: n, max: self.max_elements() });
        }
        let mut header = header;
        let ctx = format!("publishing on `{}`", self.services.qos.topic);
        let mut sample = self.publisher.loan_slice_uninit(n).map_err(ipc(ctx.clone()))?;
        {
            let dst = sample.payload_mut();
            for d in dst.iter_mut() {
                d.write(M::Elem::default());
            }
            // SAFETY: every element was initialised just above.
            let init = unsafe { std::slice::from_raw_parts_mut(dst.as_mut_ptr() as *mut M::Elem, dst.len()) };
            if let Err(e) = fill(init, &mut header) {
                return Ok(Err(e));
            }
        }
        // SAFETY: initialised above.
        let sample = unsafe { sample.assume_init() };
        self.send(sample, header, n, ctx).map(Ok)
    }

    /// Publishes a copy of `payload` (one memcpy into shared memory).
    pub fn publish_copy(&mut self, header: M::Header, payload: &[M::Elem]) -> Result<(), KitError> {
        self.publish_in_place(payload.len(), header, |dst| {
            for (d, s) in dst.iter_mut().zip(payload) {
                d.write(*s);
            }
        })
    }

    /// Publishes a message keeping the given sequence number (replay: recorded headers are
    /// published unchanged apart from the `REPLAYED` flag).
    pub fn publish_raw(&mut self, header: M::Header, payload_bytes: &[u8]) -> Result<(), KitError> {
        let es = std::mem::size_of::<M::Elem>();
        if es == 0 || !payload_bytes.len().is_multiple_of(es) {
            return Err(KitError::Port {
                port: self.topic().to_string(),
                detail: format!("payload of {} bytes is not a multiple of the element size {es}", payload_bytes.len()),
            });
        }
        let n = payload_bytes.len() / es;
        if n > self.max_elements() {
            return Err(KitError::TooLarge { topic: self.topic().to_string(), len: n, max: self.max_elements() });
        }
        let ctx = format!("publishing on `{}`", self.services.qos.topic);
        let mut sample = self.publisher.loan_slice_uninit(n).map_err(ipc(ctx.clone()))?;
        {
            let dst = sample.payload_mut();
            // SAFETY: MaybeUninit<E> has the layout of E; we write all n·es bytes.
            let dst_bytes = unsafe { std::slice::from_raw_parts_mut(dst.as_mut_ptr() as *mut u8, n * es) };
            dst_bytes.copy_from_slice(payload_bytes);
        }
        // SAFETY: every byte was written above.
        let mut sample = unsafe { sample.assume_init() };
        *sample.user_header_mut() = header;
        let t0 = Instant::now();
        sample.send().map_err(ipc(ctx.clone()))?;
        add_output_wait(t0);
        self.notifier.notify().map_err(ipc(ctx))?;
        self.seq = M::common(&header).seq + 1;
        self.sent += 1;
        self.bytes += payload_bytes.len() as u64;
        Ok(())
    }

    /// Sends the end-of-stream marker (empty payload).
    pub fn publish_eos(&mut self, t_valid: f64) -> Result<(), KitError> {
        let mut h = M::Header::default();
        {
            let c = M::common_mut(&mut h);
            c.flags = FLAG_END_OF_STREAM;
            c.t_valid = t_valid;
        }
        self.publish_in_place(0, h, |_| {})?;
        self.sent -= 1;
        Ok(())
    }
}

/// A received sample of kind `M` (header and payload still in shared memory).
pub type InSample<M> = Sample<Svc, [<M as WireMessage>::Elem], <M as WireMessage>::Header>;

/// Callback receiving raw (header, payload) bytes.
pub type BytesFn<'a> = dyn FnMut(&[u8], &[u8]) -> Result<(), KitError> + 'a;

/// How long an input of a multi-publisher topic waits for all its publishers to appear before it
/// connects to those present (see `Input::handshake_step`).
pub const MULTI_PUBLISHER_GRACE: Duration = Duration::from_secs(10);

/// A typed input port.
pub struct Input<M: WireMessage> {
    services: TopicServices<M>,
    subscriber: Subscriber<Svc, [M::Elem], M::Header>,
    listener: std::rc::Rc<Listener<Svc>>,
    ready: Notifier<Svc>,
    connected: bool,
    /// When the first publisher of a multi-publisher topic was seen (handshake grace period).
    first_publisher_seen: Option<Instant>,
    /// Last sequence number per publisher (`source_id`): topics may have several publishers.
    last_seq: Vec<(u32, u64)>,
    /// Messages received (end-of-stream markers excluded).
    pub received: u64,
    /// Sequence gaps seen (messages lost upstream or by the transport).
    pub gaps: u64,
    /// End of stream seen.
    pub eos: bool,
}

impl<M: WireMessage> Input<M> {
    fn new(node: &Node<Svc>, run_id: &str, qos: &TopicQos, node_name: &str) -> Result<Self, KitError> {
        let services = TopicServices::<M>::open(node, run_id, qos)?;
        let ctx = format!("input on topic `{}`", qos.topic);
        let port = PortName::new(node_name).map_err(ipc(ctx.clone()))?;
        let subscriber = services
            .pubsub
            .subscriber_builder()
            .name(&port)
            .buffer_size(qos.depth.max(1))
            .create()
            .map_err(ipc(ctx.clone()))?;
        let listener = std::rc::Rc::new(services.data_event.listener_builder().create().map_err(ipc(ctx.clone()))?);
        let ready = services.ready_event.notifier_builder().create().map_err(ipc(ctx))?;
        Ok(Self {
            services,
            subscriber,
            listener,
            ready,
            connected: false,
            first_publisher_seen: None,
            last_seq: Vec::new(),
            received: 0,
            gaps: 0,
            eos: false,
        })
    }

    /// Topic name.
    pub fn topic(&self) -> &str {
        &self.services.qos.topic
    }

    fn handshake_step(&mut self) -> Result<bool, KitError> {
        if self.connected {
            return Ok(true);
        }
        let publishers = self.services.pubsub.dynamic_config().number_of_publishers();
        if publishers == 0 {
            return Ok(false);
        }
        // A topic with several publishers (`_stats`: one per node) is joined once all of them
        // exist: a ready notification only reaches publishers whose ready listener already
        // exists, so notifying at the first one would leave a late starter waiting for ever.
        // After MULTI_PUBLISHER_GRACE the input connects to those present (a publisher that
        // never appears, e.g. an external program without stats, must not block the graph).
        let expected = self.services.qos.max_publishers.max(1);
        if publishers < expected {
            let first = *self.first_publisher_seen.get_or_insert_with(Instant::now);
            if first.elapsed() < MULTI_PUBLISHER_GRACE {
                return Ok(false);
            }
        }
        let ctx = format!("handshake on `{}`", self.topic());
        self.subscriber.update_connections().map_err(ipc(ctx.clone()))?;
        self.ready.notify().map_err(ipc(ctx))?;
        self.connected = true;
        Ok(true)
    }

    /// Takes the next message if one is queued. End-of-stream markers set [`Input::eos`] and
    /// are returned too (check [`is_eos`]).
    pub fn try_receive(&mut self) -> Result<Option<InSample<M>>, KitError> {
        let s = self.subscriber.receive().map_err(ipc(format!("receiving on `{}`", self.services.qos.topic)))?;
        if let Some(sample) = &s {
            let c = M::common(sample.user_header());
            if c.flags & FLAG_END_OF_STREAM != 0 {
                self.eos = true;
            } else {
                match self.last_seq.iter_mut().find(|(src, _)| *src == c.source_id) {
                    Some((_, last)) => {
                        if c.seq != *last + 1 {
                            self.gaps += 1;
                        }
                        *last = c.seq;
                    }
                    None => self.last_seq.push((c.source_id, c.seq)),
                }
                self.received += 1;
            }
        }
        Ok(s)
    }

    /// Blocks until a notification arrives on this input, `timeout` passes, or a signal
    /// interrupts the wait. Callers loop and check [`Kit::check_termination`]: a SIGTERM
    /// during the wait is reported there as [`KitError::Terminated`], not as a transport error.
    pub fn wait(&self, timeout: Duration) -> Result<(), KitError> {
        let t0 = Instant::now();
        let r = self.listener.timed_wait(|_| {}, timeout);
        add_input_wait(t0);
        match r {
            Ok(_) | Err(ListenerWaitError::InterruptSignal) => Ok(()),
            Err(e) => Err(ipc(format!("waiting on `{}`", self.services.qos.topic))(e)),
        }
    }

    /// The event this input's messages raise (for [`select_loop`] over several inputs).
    pub fn wakeup(&self) -> Wakeup {
        Wakeup(self.listener.clone())
    }
}

/// Is this sample an end-of-stream marker?
pub fn is_eos<M: WireMessage>(h: &M::Header) -> bool {
    M::common(h).flags & FLAG_END_OF_STREAM != 0
}

/// Something that takes part in the start-up handshake.
pub trait Handshake {
    /// One non-blocking step; true when this port is ready.
    fn step(&mut self) -> Result<bool, KitError>;
    /// Description for timeout errors.
    fn describe(&self) -> String;
}

impl<M: WireMessage> Handshake for Output<M> {
    fn step(&mut self) -> Result<bool, KitError> {
        self.handshake_step()
    }
    fn describe(&self) -> String {
        format!(
            "{} subscriber(s) of `{}` (ready: {})",
            self.services.qos.expected_subscribers, self.services.qos.topic, self.ready_count
        )
    }
}

impl<M: WireMessage> Handshake for Input<M> {
    fn step(&mut self) -> Result<bool, KitError> {
        self.handshake_step()
    }
    fn describe(&self) -> String {
        format!("the publisher of `{}`", self.services.qos.topic)
    }
}

/// Nanoseconds this process has spent blocked in [`Input::wait`] and [`select_loop`] (waiting for
/// input) and in sending a message that a full subscriber queue held back (back-pressure);
/// [`Kit::finish`] reports them.
static WAIT_INPUT_NS: AtomicU64 = AtomicU64::new(0);
static WAIT_OUTPUT_NS: AtomicU64 = AtomicU64::new(0);

/// Adds the time since `t0` to the process's time spent waiting for input.
pub(crate) fn add_input_wait(t0: Instant) {
    WAIT_INPUT_NS.fetch_add(t0.elapsed().as_nanos() as u64, Ordering::Relaxed);
}

fn add_output_wait(t0: Instant) {
    WAIT_OUTPUT_NS.fetch_add(t0.elapsed().as_nanos() as u64, Ordering::Relaxed);
}

/// Per-node counters reported at the end.
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
pub struct NodeStats {
    pub node: String,
    pub kind: String,
    pub messages_in: u64,
    pub messages_out: u64,
    pub bytes_out: u64,
    pub compute_ns_total: u64,
    pub cpu_ns: u64,
    pub wall_ns: u64,
    pub gaps: u64,
    /// Wall time blocked waiting for an input message (ns).
    #[serde(default)]
    pub wait_input_ns: u64,
    /// Wall time blocked sending, held back by a full downstream queue (ns).
    #[serde(default)]
    pub wait_output_ns: u64,
}

/// Prefix of the one-line JSON statistics a node prints to stdout at the end (parsed by the
/// launcher for the run report).
pub const STATS_LINE_PREFIX: &str = "SONOFLOW_STATS ";
/// Prefix of progress lines (`done/total`) parsed by the launcher.
pub const PROGRESS_LINE_PREFIX: &str = "SONOFLOW_PROGRESS ";

/// A running node: its iceoryx2 node, config, stats port and timers.
pub struct Kit {
    node: Node<Svc>,
    pub cfg: NodeConfig,
    stats_out: Option<Output<StageStats>>,
    started: Instant,
    /// Counters; nodes add to them (`messages_in`, `compute_ns_total`, …).
    pub stats: NodeStats,
}

impl Kit {
    /// Starts a node from the `SONOFLOW_NODE_CONFIG` environment variable.
    pub fn from_env() -> Result<Self, KitError> {
        Self::new(NodeConfig::from_env()?)
    }

    /// Starts a node from a config.
    pub fn new(cfg: NodeConfig) -> Result<Self, KitError> {
        let node = create_node(&cfg.node_name)?;
        let stats_out = match &cfg.stats {
            Some(q) => Some(Output::new(&node, &cfg.run_id, q, &cfg.node_name)?),
            None => None,
        };
        let stats = NodeStats { node: cfg.node_name.clone(), kind: cfg.kind.clone(), ..Default::default() };
        let kit = Self { node, cfg, stats_out, started: Instant::now(), stats };
        // iceoryx2 installs its SIGINT/SIGTERM handlers lazily, at the first termination check.
        // Check once now, so a signal that arrives before the node's first wait (a long set-up,
        // a handshake that completed at once) becomes `Terminated` at the next check instead of
        // killing the process without end of stream or statistics.
        kit.check_termination()?;
        Ok(kit)
    }

    /// Deserialises the node's `[params]` into `P` (unknown keys rejected by `P`'s serde attributes).
    pub fn params<P: serde::de::DeserializeOwned>(&self) -> Result<P, KitError> {
        let v = if self.cfg.params.is_null() { serde_json::json!({}) } else { self.cfg.params.clone() };
        serde_json::from_value(v).map_err(|e| KitError::Config(format!("node `{}` params: {e}", self.cfg.node_name)))
    }

    /// Opens the output port `port`.
    pub fn output<M: WireMessage>(&self, port: &str) -> Result<Output<M>, KitError> {
        let q = self.cfg.outputs.get(port).ok_or_else(|| KitError::Port {
            port: port.into(),
            detail: format!("node `{}` has no output `{port}` wired in the launch file", self.cfg.node_name),
        })?;
        Output::new(&self.node, &self.cfg.run_id, q, &self.cfg.node_name)
    }

    /// Opens the input port `port`.
    pub fn input<M: WireMessage>(&self, port: &str) -> Result<Input<M>, KitError> {
        let q = self.cfg.inputs.get(port).ok_or_else(|| KitError::Port {
            port: port.into(),
            detail: format!("node `{}` has no input `{port}` wired in the launch file", self.cfg.node_name),
        })?;
        Input::new(&self.node, &self.cfg.run_id, q, &self.cfg.node_name)
    }

    /// Opens an input on an explicit topic (recorder).
    pub fn input_for<M: WireMessage>(&self, qos: &TopicQos) -> Result<Input<M>, KitError> {
        Input::new(&self.node, &self.cfg.run_id, qos, &self.cfg.node_name)
    }

    /// Opens an output on an explicit topic (replay).
    pub fn output_for<M: WireMessage>(&self, qos: &TopicQos) -> Result<Output<M>, KitError> {
        Output::new(&self.node, &self.cfg.run_id, qos, &self.cfg.node_name)
    }

    /// Runs the start-up handshake over all the given ports (and the stats port) until every
    /// one is ready, or fails after `handshake_timeout_s`.
    pub fn handshake(&mut self, ports: &mut [&mut dyn Handshake]) -> Result<(), KitError> {
        let deadline = Instant::now() + Duration::from_secs_f64(self.cfg.handshake_timeout_s.max(0.1));
        loop {
            let mut all = true;
            for p in ports.iter_mut() {
                all &= p.step()?;
            }
            if let Some(s) = self.stats_out.as_mut() {
                all &= s.step()?;
            }
            if all {
                return Ok(());
            }
            if Instant::now() > deadline {
                let mut missing: Vec<String> = Vec::new();
                for p in ports.iter_mut() {
                    if !p.step()? {
                        missing.push(p.describe());
                    }
                }
                if let Some(s) = self.stats_out.as_mut() {
                    if !s.step()? {
                        missing.push(s.describe());
                    }
                }
                return Err(KitError::Timeout { what: missing.join(", "), seconds: self.cfg.handshake_timeout_s });
            }
            self.check_termination()?;
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    /// Returns `Err(Terminated)` if SIGINT/SIGTERM was received.
    pub fn check_termination(&self) -> Result<(), KitError> {
        match self.node.wait(Duration::ZERO) {
            Ok(()) => Ok(()),
            Err(_) => Err(KitError::Terminated),
        }
    }

    /// The iceoryx2 node (for WaitSets).
    pub fn node(&self) -> &Node<Svc> {
        &self.node
    }

    /// Counts one published message of `bytes` payload bytes and records its timing
    /// ([`Kit::record`]).
    pub fn published(&mut self, bytes: u64, frame_id: u64, t_valid: f64, compute_ns: u64) -> Result<(), KitError> {
        self.stats.messages_out += 1;
        self.stats.bytes_out += bytes;
        self.record(frame_id, t_valid, compute_ns)
    }

    /// Publishes a copy of `payload` under `header` on `out`, counts it and records its timing
    /// (the header's frame id, time and `compute_ns`).
    pub fn publish_copy<M: WireMessage>(
        &mut self,
        out: &mut Output<M>,
        header: M::Header,
        payload: &[M::Elem],
    ) -> Result<(), KitError> {
        out.publish_copy(header, payload)?;
        let c = *M::common(&header);
        self.published(std::mem::size_of_val(payload) as u64, c.frame_id, c.t_valid, c.compute_ns)
    }

    /// Ends a node whose input was `input`: its sequence gaps into the statistics, then
    /// [`Kit::finish`].
    pub fn finish_after<M: WireMessage>(mut self, input: &Input<M>) -> Result<NodeStats, KitError> {
        self.stats.gaps = input.gaps;
        self.finish()
    }

    /// Records one processed message (compute time measured by the caller) and publishes a
    /// stage-statistics message.
    pub fn record(&mut self, frame_id: u64, t_valid: f64, compute_ns: u64) -> Result<(), KitError> {
        self.stats.compute_ns_total += compute_ns;
        self.publish_stats(frame_id, t_valid, compute_ns, false)
    }

    fn publish_stats(&mut self, frame_id: u64, t_valid: f64, compute_ns: u64, last: bool) -> Result<(), KitError> {
        let Some(out) = self.stats_out.as_mut() else { return Ok(()) };
        let mut h = StageStatsHeaderV1 {
            node_index: self.cfg.node_index,
            state: if last { sonoflow_messages::STAGE_FINISHED } else { sonoflow_messages::STAGE_RUNNING },
            messages_in: self.stats.messages_in,
            messages_out: self.stats.messages_out,
            compute_ns_total: self.stats.compute_ns_total,
            cpu_ns: process_cpu_ns(),
            wall_ns: self.started.elapsed().as_nanos() as u64,
            last_compute_ns: compute_ns,
            bytes_out: self.stats.bytes_out,
            ..Default::default()
        };
        h.common = MsgHeaderV1 { frame_id, t_valid, compute_ns, ..Default::default() };
        if last {
            h.common.flags = FLAG_END_OF_STREAM;
        }
        let name = self.cfg.node_name.as_bytes().to_vec();
        out.publish_copy(h, &name)
    }

    /// Prints a progress line the launcher shows.
    pub fn progress(&self, done: u64, total: u64) {
        println!("{PROGRESS_LINE_PREFIX}{done}/{total}");
    }

    /// Finishes the node: final statistics message (end of stream on the stats topic) and the
    /// statistics line on stdout.
    pub fn finish(mut self) -> Result<NodeStats, KitError> {
        self.stats.cpu_ns = process_cpu_ns();
        self.stats.wall_ns = self.started.elapsed().as_nanos() as u64;
        self.stats.wait_input_ns = WAIT_INPUT_NS.load(Ordering::Relaxed);
        self.stats.wait_output_ns = WAIT_OUTPUT_NS.load(Ordering::Relaxed);
        self.publish_stats(0, 0.0, 0, true)?;
        let line = serde_json::to_string(&self.stats).unwrap_or_default();
        println!("{STATS_LINE_PREFIX}{line}");
        Ok(self.stats)
    }
}

/// Opens (creating if needed) the services of a topic of any kind and keeps them alive while
/// the returned handle lives (the launcher holds every topic of the graph).
pub fn open_topic_services(node: &Node<Svc>, run_id: &str, qos: &TopicQos) -> Result<Box<dyn std::any::Any>, KitError> {
    let kind = MessageType::from_name(&qos.message_type)
        .ok_or_else(|| KitError::Config(format!("topic `{}`: unknown kind {}", qos.topic, qos.message_type)))?;
    sonoflow_messages::with_type!(kind, M => Ok(Box::new(TopicServices::<M>::open(node, run_id, qos)?) as Box<dyn std::any::Any>))
}

/// A type-erased input (recorder: one per recorded topic, whatever its kind).
pub trait DynInput: Handshake {
    /// Message kind of the topic.
    fn kind(&self) -> MessageType;
    /// Topic name.
    fn topic_name(&self) -> &str;
    /// Takes one message and hands `f` its header and payload bytes (still in shared memory).
    /// Returns `None` when the queue is empty, `Some(true)` for an end-of-stream marker (not
    /// passed to `f`), `Some(false)` after `f` ran.
    fn receive_with(&mut self, f: &mut BytesFn<'_>) -> Result<Option<bool>, KitError>;
    /// The event this input's messages raise (for [`select_loop`]).
    fn wakeup(&self) -> Wakeup;
    /// (received, gaps, end of stream seen)
    fn counters(&self) -> (u64, u64, bool);
}

impl<M: WireMessage> DynInput for Input<M> {
    fn kind(&self) -> MessageType {
        M::TYPE
    }
    fn topic_name(&self) -> &str {
        self.topic()
    }
    fn receive_with(&mut self, f: &mut BytesFn<'_>) -> Result<Option<bool>, KitError> {
        match self.try_receive()? {
            None => Ok(None),
            Some(sample) => {
                if is_eos::<M>(sample.user_header()) {
                    return Ok(Some(true));
                }
                f(bytemuck::bytes_of(sample.user_header()), bytemuck::cast_slice(sample.payload()))?;
                Ok(Some(false))
            }
        }
    }
    fn wakeup(&self) -> Wakeup {
        Wakeup(self.listener.clone())
    }
    fn counters(&self) -> (u64, u64, bool) {
        (self.received, self.gaps, self.eos)
    }
}

/// A type-erased output (replay: one per replayed topic).
pub trait DynOutput: Handshake {
    /// Message kind of the topic.
    fn kind(&self) -> MessageType;
    /// Topic name.
    fn topic_name(&self) -> &str;
    /// Publishes a message from raw header and payload bytes, keeping the header as given
    /// except that `extra_flags` are OR-ed into its flags.
    fn publish_bytes(&mut self, header: &[u8], payload: &[u8], extra_flags: u32) -> Result<(), KitError>;
    /// Sends end of stream.
    fn eos(&mut self, t_valid: f64) -> Result<(), KitError>;
    /// Messages sent.
    fn sent(&self) -> u64;
}

impl<M: WireMessage> DynOutput for Output<M> {
    fn kind(&self) -> MessageType {
        M::TYPE
    }
    fn topic_name(&self) -> &str {
        self.topic()
    }
    fn publish_bytes(&mut self, header: &[u8], payload: &[u8], extra_flags: u32) -> Result<(), KitError> {
        if header.len() != std::mem::size_of::<M::Header>() {
            return Err(KitError::Port {
                port: self.topic().to_string(),
                detail: format!(
                    "header of {} bytes, {} expects {}",
                    header.len(),
                    M::TYPE,
                    std::mem::size_of::<M::Header>()
                ),
            });
        }
        let mut h: M::Header = bytemuck::pod_read_unaligned(header);
        M::common_mut(&mut h).flags |= extra_flags;
        self.publish_raw(h, payload)
    }
    fn eos(&mut self, t_valid: f64) -> Result<(), KitError> {
        self.publish_eos(t_valid)
    }
    fn sent(&self) -> u64 {
        self.sent
    }
}

impl Kit {
    /// Opens a type-erased input on `qos.topic` (kind from `qos.message_type`).
    pub fn dyn_input(&self, qos: &TopicQos) -> Result<Box<dyn DynInput>, KitError> {
        let kind = MessageType::from_name(&qos.message_type)
            .ok_or_else(|| KitError::Config(format!("topic `{}`: unknown kind {}", qos.topic, qos.message_type)))?;
        sonoflow_messages::with_type!(kind, M => Ok(Box::new(self.input_for::<M>(qos)?) as Box<dyn DynInput>))
    }

    /// Opens a type-erased output on `qos.topic`.
    pub fn dyn_output(&self, qos: &TopicQos) -> Result<Box<dyn DynOutput>, KitError> {
        let kind = MessageType::from_name(&qos.message_type)
            .ok_or_else(|| KitError::Config(format!("topic `{}`: unknown kind {}", qos.topic, qos.message_type)))?;
        sonoflow_messages::with_type!(kind, M => Ok(Box::new(self.output_for::<M>(qos)?) as Box<dyn DynOutput>))
    }
}
