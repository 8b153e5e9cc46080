//! Two processes on one host: the engines a same-host bridge could use, side by side
//! in one run. The bench spawns itself twice per measurement (a receiver, then a
//! sender, `shm peer ...`), so every figure is across two OS processes:
//!
//! - **small**: 64-byte packets one way, paced (the receiver sleeps between them, as
//!   a component does); p50 and p99 latency, stamp to arrival (`CLOCK_REALTIME`,
//!   which both processes read);
//! - **large**: 4 MiB packets at 30 Hz; CPU per packet, the sender's and the
//!   receiver's user and system time over the stream (`/proc/self/stat`) divided by
//!   the packets.
//!
//! Engines: raw Zenoh over TCP loopback (no shared memory); raw Zenoh with shared
//! memory (a provider of its own, each packet written once into a `ZShmMut` and
//! put; the descriptor still travels over the TCP link); raw iceoryx2
//! (publish-subscribe of a byte slice, an event service whose listener the receiver
//! blocks on); the coolbot bridge with shared memory off (today's TCP bridge: an
//! outlet and an inlet, `Vec<u8>` packets) and on; and the bridge with shared memory
//! on a packet that serializes its bytes as one slice (`bridge-shm-bytes`: what a
//! `Vec<u8>` costs in serde, byte by byte, set apart from what the bridge costs).
//!
//! `cargo bench -p coolbot-zenoh --bench shm` (add `-- --quick` for a smoke run).

#[path = "../../benches/common/mod.rs"]
#[macro_use]
mod common;
mod setup;

use std::io::{BufRead, BufReader};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use coolbot::port::{DataOut, FifoIn};
use coolbot::{Component, InputKind, OutputKind, OverflowPolicy, PortSet, Section, System};
use crossbeam_channel::{Sender, bounded};
use zenoh::Wait;

use common::{Figure, Glue, Goal, Mode, Samples, Table};

/// The key (Zenoh) and service name (iceoryx2) of the stream.
const KEY: &str = "bench/shm/stream";
/// The number of the last message, which ends a stream.
const END: u64 = u64::MAX;
/// How long a child may take for its whole part.
const LIMIT: Duration = Duration::from_secs(300);

/// The engines measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Engine {
    ZenohTcp,
    ZenohShm,
    Iceoryx2,
    BridgeTcp,
    BridgeShm,
    BridgeShmBytes,
}

impl Engine {
    const ALL: [Engine; 6] = [
        Engine::ZenohTcp,
        Engine::ZenohShm,
        Engine::Iceoryx2,
        Engine::BridgeTcp,
        Engine::BridgeShm,
        Engine::BridgeShmBytes,
    ];

    fn name(self) -> &'static str {
        match self {
            Engine::ZenohTcp => "zenoh-tcp",
            Engine::ZenohShm => "zenoh-shm",
            Engine::Iceoryx2 => "iceoryx2",
            Engine::BridgeTcp => "bridge-tcp",
            Engine::BridgeShm => "bridge-shm",
            Engine::BridgeShmBytes => "bridge-shm-bytes",
        }
    }

    fn parse(name: &str) -> Engine {
        Engine::ALL
            .into_iter()
            .find(|engine| engine.name() == name)
            .unwrap_or_else(|| panic!("no engine `{name}`"))
    }
}

/// One stream: `count` packets of `size` bytes, one every `period`.
#[derive(Debug, Clone, Copy)]
struct Stream {
    size: usize,
    count: usize,
    period: Duration,
}

/// What a receiver reports.
#[derive(Debug, Default)]
struct Received {
    latencies: Vec<Duration>,
    cpu: Duration,
}

/// Nanoseconds of `CLOCK_REALTIME`, which every process on the host reads alike.
fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .expect("after 1970")
        .as_nanos() as u64
}

/// This process's user and system time (`/proc/self/stat`, in clock ticks of 10 ms).
fn cpu() -> Duration {
    let stat = std::fs::read_to_string("/proc/self/stat").expect("/proc/self/stat");
    let rest = &stat[stat.rfind(')').expect("a command name") + 2..];
    let fields: Vec<&str> = rest.split(' ').collect();
    let ticks: u64 =
        fields[11].parse::<u64>().expect("utime") + fields[12].parse::<u64>().expect("stime");
    Duration::from_millis(ticks * 10)
}

/// The packet: its send stamp and number, then filler.
fn stamp(packet: &mut [u8], number: u64) {
    packet[..8].copy_from_slice(&now_ns().to_le_bytes());
    packet[8..16].copy_from_slice(&number.to_le_bytes());
}

fn header(packet: &[u8]) -> (u64, u64) {
    let word = |at: usize| u64::from_le_bytes(packet[at..at + 8].try_into().expect("8 bytes"));
    (word(0), word(8))
}

/// Collects a receiver's arrivals until the end message.
struct Collector {
    latencies: Vec<Duration>,
    started: Option<Duration>,
    done: Option<Sender<Received>>,
}

impl Collector {
    fn new(done: Sender<Received>, count: usize) -> Collector {
        Collector {
            latencies: Vec::with_capacity(count),
            started: None,
            done: Some(done),
        }
    }

    fn arrived(&mut self, packet: &[u8]) {
        let arrival = now_ns();
        let (sent, number) = header(packet);
        let started = *self.started.get_or_insert_with(cpu);
        if number == END {
            if let Some(done) = self.done.take() {
                let _ = done.send(Received {
                    latencies: std::mem::take(&mut self.latencies),
                    cpu: cpu().saturating_sub(started),
                });
            }
        } else {
            self.latencies
                .push(Duration::from_nanos(arrival.saturating_sub(sent)));
        }
    }
}

/// A sender's loop: `stream.count` packets then the end, paced; then prints its CPU
/// time and waits until the driver closes its stdin (the receiver has everything: a
/// buffer of shared memory outlives its sender only while another process maps it).
fn paced(stream: Stream, mut send: impl FnMut(u64)) {
    let started = cpu();
    let mut next = Instant::now();
    for number in 0..stream.count as u64 {
        send(number);
        next += stream.period;
        if let Some(wait) = next.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
    }
    send(END);
    println!("result {}", cpu().saturating_sub(started).as_nanos());
    let _ = std::io::stdin().read_line(&mut String::new());
}

// ---------------------------------------------------------------------------------
// Raw Zenoh.

fn zenoh_receiver(
    address: &str,
    shm: bool,
    stream: Stream,
    done: Sender<Received>,
) -> (zenoh::Session, zenoh::pubsub::Subscriber<()>) {
    let session = zenoh::open(setup::config(address, &[], shm))
        .wait()
        .expect("session");
    let collector = std::sync::Mutex::new(Collector::new(done, stream.count));
    let subscriber = session
        .declare_subscriber(KEY)
        .callback(move |sample| {
            let payload = sample.payload().to_bytes();
            collector
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .arrived(&payload);
        })
        .wait()
        .expect("subscriber");
    (session, subscriber)
}

fn zenoh_sender(address: &str, shm: bool, stream: Stream) {
    let session = zenoh::open(setup::config(
        &setup::endpoint(),
        &[address.to_owned()],
        shm,
    ))
    .wait()
    .expect("session");
    setup::wait_subscribed(&session, KEY);
    let publisher = session
        .declare_publisher(KEY)
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .wait()
        .expect("publisher");
    let frame = vec![7u8; stream.size];
    if shm {
        use zenoh::shm::{BlockOn, GarbageCollect, ShmProviderBuilder};
        let provider = ShmProviderBuilder::default_backend((stream.size * 8).max(1 << 16))
            .wait()
            .expect("shared-memory provider");
        paced(stream, |number| {
            let mut buffer = provider
                .alloc(stream.size)
                .with_policy::<BlockOn<GarbageCollect>>()
                .wait()
                .expect("shared memory");
            buffer.copy_from_slice(&frame);
            stamp(&mut buffer, number);
            publisher.put(buffer).wait().expect("put");
        })
    } else {
        paced(stream, |number| {
            let mut buffer = frame.clone();
            stamp(&mut buffer, number);
            publisher.put(buffer).wait().expect("put");
        })
    }
}

// ---------------------------------------------------------------------------------
// Raw iceoryx2.

#[cfg(feature = "bench-iceoryx2")]
mod ice {
    use iceoryx2::port::backpressure_strategy::BackpressureStrategy;
    use iceoryx2::prelude::*;

    use super::*;

    fn name(what: &str, tag: &str) -> ServiceName {
        format!("coolbot/bench/{tag}/{what}")
            .as_str()
            .try_into()
            .expect("service name")
    }

    type Pubsub =
        iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, [u8], ()>;

    fn services(
        tag: &str,
        stream: Stream,
    ) -> (
        Node<ipc::Service>,
        Pubsub,
        iceoryx2::service::port_factory::event::PortFactory<ipc::Service>,
    ) {
        let node = NodeBuilder::new()
            .create::<ipc::Service>()
            .expect("iceoryx2 node");
        let pubsub = node
            .service_builder(&name("data", tag))
            .publish_subscribe::<[u8]>()
            .subscriber_max_buffer_size(8)
            .history_size(0)
            .enable_safe_overflow(false)
            .open_or_create()
            .expect("publish-subscribe service");
        let event = node
            .service_builder(&name("wake", tag))
            .event()
            .open_or_create()
            .expect("event service");
        let _ = stream;
        (node, pubsub, event)
    }

    pub fn receive(tag: &str, stream: Stream, ready: impl FnOnce()) -> Received {
        let (_node, pubsub, event) = services(tag, stream);
        let subscriber = pubsub.subscriber_builder().create().expect("subscriber");
        let listener = event.listener_builder().create().expect("listener");
        ready();
        let (done, result) = bounded(1);
        let mut collector = Collector::new(done, stream.count);
        loop {
            listener.timed_wait(|_| {}, LIMIT).expect("a wake-up");
            while let Some(sample) = subscriber.receive().expect("receive") {
                collector.arrived(sample.payload());
            }
            if let Ok(received) = result.try_recv() {
                return received;
            }
        }
    }

    pub fn send(tag: &str, stream: Stream) {
        let (_node, pubsub, event) = services(tag, stream);
        let publisher = pubsub
            .publisher_builder()
            .initial_max_slice_len(stream.size)
            .backpressure_strategy(BackpressureStrategy::RetryUntilDelivered)
            .create()
            .expect("publisher");
        let notifier = event.notifier_builder().create().expect("notifier");
        let deadline = Instant::now() + LIMIT;
        while pubsub.dynamic_config().number_of_subscribers() == 0
            || event.dynamic_config().number_of_listeners() == 0
        {
            assert!(Instant::now() < deadline, "no iceoryx2 subscriber");
            std::thread::sleep(Duration::from_millis(5));
        }
        let frame = vec![7u8; stream.size];
        paced(stream, |number| {
            let sample = publisher.loan_slice_uninit(stream.size).expect("a loan");
            let mut sample = sample.write_from_slice(&frame);
            stamp(sample.payload_mut(), number);
            sample.send().expect("send");
            notifier.notify().expect("notify");
        })
    }
}

// ---------------------------------------------------------------------------------
// The coolbot bridge.

one_state_spec! {
    static SINK_SPEC = "Sink",
    inputs: [("input", InputKind::Fifo { capacity: 64, policy: OverflowPolicy::Block })],
    outputs: [],
    on: [0],
    periodic: None,
}

one_state_spec! {
    static SOURCE_SPEC = "Source",
    inputs: [],
    outputs: [("output", OutputKind::Data)],
    on: [],
    periodic: None,
}

/// What the bridge carries: bytes, as a `Vec<u8>` (serde: a sequence, byte by byte) or
/// as [`Bytes`] (serde: one slice).
trait Payload:
    coolbot::Packet + serde::Serialize + serde::de::DeserializeOwned + From<Vec<u8>> + AsRef<[u8]>
{
}

impl<T> Payload for T where
    T: coolbot::Packet
        + serde::Serialize
        + serde::de::DeserializeOwned
        + From<Vec<u8>>
        + AsRef<[u8]>
{
}

/// Bytes that serialize as one slice (as `serde_bytes` does).
#[derive(Clone)]
struct Bytes(Vec<u8>);

impl From<Vec<u8>> for Bytes {
    fn from(bytes: Vec<u8>) -> Bytes {
        Bytes(bytes)
    }
}

impl AsRef<[u8]> for Bytes {
    fn as_ref(&self) -> &[u8] {
        &self.0
    }
}

impl serde::Serialize for Bytes {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_bytes(&self.0)
    }
}

impl<'de> serde::Deserialize<'de> for Bytes {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Bytes, D::Error> {
        struct Visit;
        impl serde::de::Visitor<'_> for Visit {
            type Value = Bytes;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("bytes")
            }
            fn visit_bytes<E: serde::de::Error>(self, bytes: &[u8]) -> Result<Bytes, E> {
                Ok(Bytes(bytes.to_vec()))
            }
        }
        deserializer.deserialize_bytes(Visit)
    }
}

const BRIDGE: InputKind = InputKind::Fifo {
    capacity: 64,
    policy: OverflowPolicy::Block,
};

fn bridge_receiver<P: Payload>(
    address: &str,
    shm: bool,
    stream: Stream,
    done: Sender<Received>,
) -> (tempfile::TempDir, coolbot_zenoh::Node, System) {
    let state = setup::state_directory();
    let node = setup::node("receiver", setup::config(address, &[], shm), state.path());
    let input = FifoIn::<P>::new(64, OverflowPolicy::Block);
    let mut collector = Collector::new(done, stream.count);
    let ports = PortSet::new().input(&input);
    let sink = Component::new(
        "sink",
        Glue::boxed(
            &SINK_SPEC,
            Box::new(move |section, _| {
                if section == Section::Entry {
                    while let Some(packet) = input.recv() {
                        collector.arrived(packet.as_ref());
                    }
                }
                Ok(())
            }),
        ),
        ports,
    );
    let mut system = System::new();
    system.add(sink).expect("sink");
    system
        .add(
            node.inlet::<P>("from_sender", KEY, OutputKind::Data)
                .build()
                .expect("inlet"),
        )
        .expect("inlet");
    system
        .connect("from_sender.output", "sink.input")
        .expect("connect");
    system.run_all().expect("run");
    (state, node, system)
}

fn bridge_sender<P: Payload>(address: &str, shm: bool, stream: Stream) {
    let state = setup::state_directory();
    let node = setup::node(
        "sender",
        setup::config(&setup::endpoint(), &[address.to_owned()], shm),
        state.path(),
    );
    let output = DataOut::<P>::new();
    let mut system = System::new();
    system
        .add(Component::new(
            "source",
            Glue::boxed(&SOURCE_SPEC, Box::new(|_, _| Ok(()))),
            PortSet::new().output(&output),
        ))
        .expect("source");
    system
        .add(
            node.outlet::<P>("to_receiver", KEY, BRIDGE)
                .build()
                .expect("outlet"),
        )
        .expect("outlet");
    system
        .connect("source.output", "to_receiver.input")
        .expect("connect");
    system.run_all().expect("run");
    setup::wait_subscribed(node.session(), KEY);
    let frame = vec![7u8; stream.size];
    paced(stream, |number| {
        let mut packet = frame.clone();
        stamp(&mut packet, number);
        output.send(P::from(packet));
    });
    let lost = system
        .handle("to_receiver")
        .map_or(0, |handle| handle.snapshot().overflows);
    assert_eq!(lost, 0, "the outlet lost packets");
    assert!(system.shutdown().clean(), "unclean shutdown");
    drop(state);
}

// ---------------------------------------------------------------------------------
// The processes.

/// A child's part: `peer <engine> <role> <address> <size> <count> <period_ns>`.
fn peer(args: &[String]) {
    let engine = Engine::parse(&args[0]);
    let role = args[1].as_str();
    let address = args[2].as_str();
    let stream = Stream {
        size: args[3].parse().expect("size"),
        count: args[4].parse().expect("count"),
        period: Duration::from_nanos(args[5].parse().expect("period")),
    };
    let ready = || println!("ready");
    match role {
        "receive" => {
            let (done, result) = bounded(1);
            let received = match engine {
                Engine::ZenohTcp | Engine::ZenohShm => {
                    let _held = zenoh_receiver(address, engine == Engine::ZenohShm, stream, done);
                    ready();
                    common::expect(&result, LIMIT, "zenoh stream")
                }
                Engine::BridgeTcp | Engine::BridgeShm | Engine::BridgeShmBytes => {
                    let (_state, _node, system) = if engine == Engine::BridgeShmBytes {
                        bridge_receiver::<Bytes>(address, true, stream, done)
                    } else {
                        bridge_receiver::<Vec<u8>>(
                            address,
                            engine == Engine::BridgeShm,
                            stream,
                            done,
                        )
                    };
                    ready();
                    let received = common::expect(&result, LIMIT, "bridge stream");
                    let lost = system
                        .handle("from_sender")
                        .map_or(0, |handle| handle.snapshot().overflows);
                    assert_eq!(lost, 0, "the inlet counted losses");
                    assert!(system.shutdown().clean(), "unclean shutdown");
                    received
                }
                #[cfg(feature = "bench-iceoryx2")]
                Engine::Iceoryx2 => ice::receive(address, stream, ready),
                #[cfg(not(feature = "bench-iceoryx2"))]
                Engine::Iceoryx2 => unreachable!("iceoryx2 is measured with `bench-iceoryx2`"),
            };
            let samples = Samples::new(received.latencies);
            println!(
                "result {} {} {} {} {}",
                samples.len(),
                received.cpu.as_nanos(),
                samples.p50().as_nanos(),
                samples.p99().as_nanos(),
                samples.max().as_nanos()
            );
        }
        "send" => {
            match engine {
                Engine::ZenohTcp | Engine::ZenohShm => {
                    zenoh_sender(address, engine == Engine::ZenohShm, stream)
                }
                Engine::BridgeTcp | Engine::BridgeShm => {
                    bridge_sender::<Vec<u8>>(address, engine == Engine::BridgeShm, stream)
                }
                Engine::BridgeShmBytes => bridge_sender::<Bytes>(address, true, stream),
                #[cfg(feature = "bench-iceoryx2")]
                Engine::Iceoryx2 => ice::send(address, stream),
                #[cfg(not(feature = "bench-iceoryx2"))]
                Engine::Iceoryx2 => unreachable!("iceoryx2 is measured with `bench-iceoryx2`"),
            };
        }
        other => panic!("no role `{other}`"),
    }
}

fn spawn(
    engine: Engine,
    role: &str,
    address: &str,
    stream: Stream,
) -> (Child, BufReader<ChildStdout>) {
    let mut child = Command::new(std::env::current_exe().expect("this bench's path"))
        .args([
            "peer",
            engine.name(),
            role,
            address,
            &stream.size.to_string(),
            &stream.count.to_string(),
            &stream.period.as_nanos().to_string(),
        ])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("spawn a peer");
    let stdout = BufReader::new(child.stdout.take().expect("its stdout"));
    (child, stdout)
}

/// The next line of `stdout` starting with `word`, its other fields as numbers.
fn line(stdout: &mut BufReader<ChildStdout>, word: &str) -> Vec<u64> {
    let mut text = String::new();
    loop {
        text.clear();
        assert!(
            stdout.read_line(&mut text).expect("a peer's output") > 0,
            "a peer ended before `{word}`"
        );
        if let Some(rest) = text.trim().strip_prefix(word) {
            return rest
                .split_whitespace()
                .map(|field| field.parse().expect("a number"))
                .collect();
        }
    }
}

/// One stream over `engine` between two new processes.
struct Run {
    latencies: (Duration, Duration, Duration),
    received: u64,
    cpu_per_packet: Duration,
}

fn run(engine: Engine, stream: Stream, tag: usize) -> Run {
    let address = match engine {
        Engine::Iceoryx2 => format!("{}-{tag}", std::process::id()),
        _ => setup::endpoint(),
    };
    let (mut receiver, mut from_receiver) = spawn(engine, "receive", &address, stream);
    line(&mut from_receiver, "ready");
    let (mut sender, mut from_sender) = spawn(engine, "send", &address, stream);
    let sent = line(&mut from_sender, "result");
    let received = line(&mut from_receiver, "result");
    drop(sender.stdin.take());
    assert!(sender.wait().expect("sender").success(), "sender failed");
    assert!(
        receiver.wait().expect("receiver").success(),
        "receiver failed"
    );
    let nanos = Duration::from_nanos;
    Run {
        latencies: (nanos(received[2]), nanos(received[3]), nanos(received[4])),
        received: received[0],
        cpu_per_packet: nanos(sent[0] + received[1]) / stream.count as u32,
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(String::as_str) == Some("peer") {
        peer(&args[1..]);
        return;
    }
    let mode = Mode::from_env();
    let small = Stream {
        size: 64,
        count: mode.scale(10_000, 1_000),
        period: Duration::from_micros(500),
    };
    let large = Stream {
        size: 4 << 20,
        count: mode.scale(300, 60),
        period: Duration::from_secs(1) / 30,
    };
    let mut figures = Vec::new();
    // `-- zenoh-shm iceoryx2`: only those engines.
    let chosen: Vec<String> = args
        .iter()
        .filter(|a| !a.starts_with('-'))
        .cloned()
        .collect();
    let measured = Engine::ALL
        .into_iter()
        .filter(|engine| cfg!(feature = "bench-iceoryx2") || *engine != Engine::Iceoryx2)
        .filter(|engine| chosen.is_empty() || chosen.iter().any(|c| c == engine.name()));
    for (tag, engine) in measured.enumerate() {
        let a = run(engine, small, 2 * tag);
        let b = run(engine, large, 2 * tag + 1);
        println!(
            "  {}: 64 B p50 {:?} p99 {:?} max {:?} ({} packets); 4 MiB at 30 Hz: {:?} CPU per packet ({} packets, p50 {:?})",
            engine.name(),
            a.latencies.0,
            a.latencies.1,
            a.latencies.2,
            a.received,
            b.cpu_per_packet,
            b.received,
            b.latencies.0,
        );
        figures.push((engine, a, b));
    }
    let figure = |engine: Engine| {
        figures
            .iter()
            .find(|(e, _, _)| *e == engine)
            .map(|(_, a, b)| (a, b))
    };
    let mut table = Table::new(
        "Two processes on one host: the bridge with shared memory against the engines",
        mode,
    );
    let Some((shm_small, shm_large)) = figure(Engine::BridgeShm) else {
        return;
    };
    let against = |table: &mut Table, baseline: Engine, goals: (Goal, Goal)| {
        let Some((small, large)) = figure(baseline) else {
            table.note(&format!("{} not measured in this run", baseline.name()));
            return;
        };
        table.row(
            &format!("64 B p50, bridge-shm vs {}", baseline.name()),
            Figure::Time(shm_small.latencies.0),
            Figure::Time(small.latencies.0),
            goals.0,
        );
        table.row(
            &format!("64 B p99, bridge-shm vs {}", baseline.name()),
            Figure::Time(shm_small.latencies.1),
            Figure::Time(small.latencies.1),
            Goal::None,
        );
        table.row(
            &format!("4 MiB CPU/packet, bridge-shm vs {}", baseline.name()),
            Figure::Time(shm_large.cpu_per_packet),
            Figure::Time(large.cpu_per_packet),
            goals.1,
        );
    };
    against(
        &mut table,
        Engine::ZenohShm,
        (Goal::AtMost(1.5), Goal::AtMost(1.2)),
    );
    against(
        &mut table,
        Engine::Iceoryx2,
        (Goal::AtMost(1.5), Goal::AtMost(1.2)),
    );
    against(
        &mut table,
        Engine::BridgeTcp,
        (Goal::AtMost(0.2), Goal::AtMost(0.2)),
    );
    against(&mut table, Engine::ZenohTcp, (Goal::None, Goal::None));
    if let Some((small, large)) = figure(Engine::BridgeShmBytes) {
        table.row(
            "64 B p50, bridge-shm-bytes vs zenoh-shm",
            Figure::Time(small.latencies.0),
            Figure::Time(
                figure(Engine::ZenohShm).map_or(small.latencies.0, |(s, _)| s.latencies.0),
            ),
            Goal::None,
        );
        table.row(
            "4 MiB CPU/packet, bridge-shm-bytes vs zenoh-shm",
            Figure::Time(large.cpu_per_packet),
            Figure::Time(
                figure(Engine::ZenohShm).map_or(large.cpu_per_packet, |(_, l)| l.cpu_per_packet),
            ),
            Goal::None,
        );
    }
    table.note(&format!(
        "64 B: {} packets one every {:?}; 4 MiB: {} packets at 30 Hz; CPU from /proc/self/stat (10 ms ticks) of both processes",
        small.count, small.period, large.count
    ));
    table.print();
}
