//! Two processes on one host: the engines a same-host bridge could use, side by side
//! in one run. The bench spawns itself twice per measurement (a receiver, then a
//! sender, `shm peer ...`), so every figure is across two OS processes:
//!
//! - **small**: 64-byte packets one way, paced (the receiver sleeps between them, as
//!   a component does); p50 and p99 latency, stamp to arrival (`CLOCK_REALTIME`,
//!   which both processes read);
//! - **large**: 4 MiB packets at 30 Hz; CPU per packet, the sender's and the
//!   receiver's CPU time over the stream (`CLOCK_PROCESS_CPUTIME_ID`) divided by
//!   the packets.
//!
//! Engines: raw Zenoh over TCP loopback (no shared memory); raw Zenoh with shared
//! memory (a provider of its own, each packet written once into a `ZShmMut` and
//! put; the descriptor still travels over the TCP link); raw iceoryx2
//! (publish-subscribe of a byte slice, an event service whose listener the receiver
//! blocks on); the coolbot bridge with shared memory off (the TCP bridge: an outlet
//! and an inlet, fifo) and on: a small packet then goes through a ring of the
//! receiver's process, written on the sender's thread, a large one through Zenoh's
//! shared memory (`docs/distribution.md`, "Same host: a ring"). The bridge carries
//! a packet of one `[u8]` field as coolc generates it (its bytes serialized as one
//! slice); `bridge-shm-lent` carries it as a
//! `coolbot::Bytes`, which the receiver decodes in place, in the sender's buffer;
//! `bridge-shm-loan` fills that `Bytes` in a loan of the sender node's pool
//! (`coolbot::Bytes::loan`: the one copy of the frame, as raw Zenoh's into its
//! `ZShmMut`), which the outlet sends as it is.
//! `wake-floor` is no engine but the floor under them all: the sender copies the
//! packet into a shared mapping and wakes the receiver, asleep on a futex, with one
//! system call; what any engine pays at least to reach a receiver asleep in another
//! process. `bell` is that floor with a coolbot component as the receiver: the sender
//! copies the packet into the shared slot and rings the component's own doorbell
//! (`coolbot::RemoteBell`); the component's thread wakes, drains the slot through a
//! `coolbot::Source` into its fifo input and handles the packet in its section: the
//! bridge's ring path without its queue and accounting.
//!
//! And the fan-out (`fan`): a producer process sends 4 MiB packets at 30 Hz through
//! the bridge with shared memory to 1 and to 3 consumer processes on one `last`
//! connection, and to 3 on a fifo connection each; the producer's CPU per packet with
//! 3 consumers against 1 (no copy per consumer: about 1x; a copy each: about 3x), the
//! consumers' CPU, and the messages the producer wrote into shared memory.
//!
//! `cargo bench -p coolbot-zenoh --bench shm` (add `-- --quick` for a smoke run; name
//! engines, or `fan`, to run only those).

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
    BridgeShmLent,
    BridgeShmLoan,
    WakeFloor,
    Bell,
}

impl Engine {
    const ALL: [Engine; 9] = [
        Engine::ZenohTcp,
        Engine::ZenohShm,
        Engine::Iceoryx2,
        Engine::BridgeTcp,
        Engine::BridgeShm,
        Engine::BridgeShmLent,
        Engine::BridgeShmLoan,
        Engine::WakeFloor,
        Engine::Bell,
    ];

    fn name(self) -> &'static str {
        match self {
            Engine::ZenohTcp => "zenoh-tcp",
            Engine::ZenohShm => "zenoh-shm",
            Engine::Iceoryx2 => "iceoryx2",
            Engine::BridgeTcp => "bridge-tcp",
            Engine::BridgeShm => "bridge-shm",
            Engine::BridgeShmLent => "bridge-shm-lent",
            Engine::BridgeShmLoan => "bridge-shm-loan",
            Engine::WakeFloor => "wake-floor",
            Engine::Bell => "bell",
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

/// This process's CPU time, user and system (`CLOCK_PROCESS_CPUTIME_ID`: to the
/// nanosecond, where `/proc/self/stat` counts 10 ms ticks, as much as a tenth of a
/// 4 MiB packet's figure over 300 packets).
fn cpu() -> Duration {
    cpu_time::ProcessTime::now().as_duration()
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
// The floor: one futex wake-up a packet.

/// What no same-host engine can beat for a receiver that sleeps between packets: the
/// sender copies the packet into a shared mapping, publishes its number, and wakes the
/// receiver with one futex call; the receiver sleeps on that number and reads the
/// packet in place. One slot, no queue, no discovery, no loss accounting: not an
/// engine a bridge could use, but the cost of the one wake-up that any engine pays
/// to reach a sleeping thread in another process.
mod floor {
    use std::fs::{File, OpenOptions};
    use std::sync::atomic::{AtomicU32, Ordering};

    use memmap2::MmapMut;
    use rustix::thread::futex;

    use super::*;

    /// The packet's number (the futex word), then the number the receiver last took.
    pub(super) const NUMBER: usize = 0;
    pub(super) const TAKEN: usize = 64;
    /// Where the packet starts, a cache line after the two words.
    const DATA: usize = 128;

    pub(super) struct Slot {
        map: MmapMut,
        size: usize,
    }

    impl Slot {
        /// Map `path` (made `DATA + size` bytes long if `create`).
        #[allow(
            unsafe_code,
            reason = "a shared mapping of a file only the bench opens"
        )]
        pub(super) fn map(path: &str, size: usize, create: bool) -> Slot {
            let file: File = OpenOptions::new()
                .read(true)
                .write(true)
                .create(create)
                .truncate(create)
                .open(path)
                .expect("the slot's file");
            if create {
                file.set_len((DATA + size) as u64).expect("the slot's size");
            }
            // SAFETY: the file is the bench's own, opened by its two processes only,
            // and never truncated while mapped; what each process writes is ordered by
            // the two words (a packet is written before its number, read after it).
            let map = unsafe { MmapMut::map_mut(&file) }.expect("a shared mapping");
            Slot { map, size }
        }

        pub(super) fn word(&self, at: usize) -> &AtomicU32 {
            let bytes = &self.map[at..at + 4];
            // SAFETY: 4 bytes inside the mapping, aligned to 4 (the mapping is
            // page-aligned and `at` a multiple of 64), only ever used as an atomic.
            #[allow(unsafe_code, reason = "an atomic word in a shared mapping")]
            unsafe {
                &*bytes.as_ptr().cast::<AtomicU32>()
            }
        }

        pub(super) fn packet(&self) -> &[u8] {
            &self.map[DATA..DATA + self.size]
        }

        pub(super) fn packet_mut(&mut self) -> &mut [u8] {
            &mut self.map[DATA..DATA + self.size]
        }
    }

    pub fn receive(path: &str, stream: Stream, ready: impl FnOnce()) -> Received {
        let slot = Slot::map(path, stream.size, true);
        ready();
        let (done, result) = bounded(1);
        let mut collector = Collector::new(done, stream.count);
        let mut taken = 0u32;
        let deadline = Instant::now() + LIMIT;
        loop {
            let number = slot.word(NUMBER);
            while number.load(Ordering::Acquire) == taken {
                assert!(Instant::now() < deadline, "no packet in {LIMIT:?}");
                // Returns at once if the number moved since the load (EAGAIN).
                let _ = futex::wait(
                    number,
                    futex::Flags::empty(),
                    taken,
                    Some(&futex::Timespec {
                        tv_sec: 1,
                        tv_nsec: 0,
                    }),
                );
            }
            taken = number.load(Ordering::Acquire);
            collector.arrived(slot.packet());
            slot.word(TAKEN).store(taken, Ordering::Release);
            if let Ok(received) = result.try_recv() {
                let _ = std::fs::remove_file(path);
                return received;
            }
        }
    }

    pub fn send(path: &str, stream: Stream) {
        let mut slot = Slot::map(path, stream.size, false);
        let frame = vec![7u8; stream.size];
        let mut number = 0u32;
        paced(stream, |header| {
            // The receiver took the last packet long before (a packet every 500 us at
            // most); wait for it all the same rather than write over it.
            while slot.word(TAKEN).load(Ordering::Acquire) != number {
                std::thread::yield_now();
            }
            let packet = slot.packet_mut();
            packet.copy_from_slice(&frame);
            stamp(packet, header);
            number = number.wrapping_add(1);
            slot.word(NUMBER).store(number, Ordering::Release);
            futex::wake(slot.word(NUMBER), futex::Flags::empty(), 1).expect("a futex wake");
        })
    }
}

// ---------------------------------------------------------------------------------
// The floor with a component as the receiver: its own doorbell rung from the sender.

mod bell {
    use std::sync::Arc;
    use std::sync::atomic::{AtomicU32, Ordering};

    use super::floor::{NUMBER, Slot, TAKEN};
    use super::*;

    /// The receiver's drain of the slot, on the sink component's thread: the packet
    /// whose number is new, sent on the feeder's output into the sink's input.
    struct Drain {
        slot: Slot,
        taken: AtomicU32,
        output: DataOut<Frame>,
    }

    impl coolbot::Source for Drain {
        fn ready(&self) -> bool {
            self.slot.word(NUMBER).load(Ordering::Acquire) != self.taken.load(Ordering::Relaxed)
        }

        fn drain(&self) {
            let number = self.slot.word(NUMBER).load(Ordering::Acquire);
            if number == self.taken.load(Ordering::Relaxed) {
                return;
            }
            self.output.send(Frame {
                bytes: self.slot.packet().to_vec(),
            });
            self.taken.store(number, Ordering::Relaxed);
            self.slot.word(TAKEN).store(number, Ordering::Release);
        }
    }

    /// A sink component fed by a feeder whose output the drain sends on; prints
    /// `ready` with the sink's bell address, for the sender.
    pub fn receive(path: &str, stream: Stream) -> Received {
        let slot = Slot::map(path, stream.size, true);
        let (done, result) = bounded(1);
        let sink = sink::<Frame>(Collector::new(done, stream.count));
        let output = DataOut::<Frame>::new();
        let mut system = System::new();
        system.add(sink).expect("sink");
        system
            .add(Component::new(
                "feeder",
                Glue::boxed(&SOURCE_SPEC, Box::new(|_, _| Ok(()))),
                PortSet::new().output(&output),
            ))
            .expect("feeder");
        system
            .connect("feeder.output", "sink.input")
            .expect("connect");
        system.run_all().expect("run");
        let bell = output.consumer_bell().expect("one consumer");
        let address = bell.address().expect("the sink's bell in shared memory");
        let _source = bell.add_source(Arc::new(Drain {
            slot,
            taken: AtomicU32::new(0),
            output,
        }));
        println!(
            "ready {} {} {} {}",
            address.pid, address.fd, address.nonce, address.pair
        );
        let received = common::expect(&result, LIMIT, "bell stream");
        assert!(system.shutdown().clean(), "unclean shutdown");
        let _ = std::fs::remove_file(path);
        received
    }

    /// `address`: the slot's path, then the sink's bell (pid, fd, nonce, pair).
    pub fn send(address: &str, stream: Stream) {
        let fields: Vec<&str> = address.split(' ').collect();
        let number = |at: usize| fields[at].parse::<u64>().expect("a number");
        let bell = coolbot::RemoteBell::open(&coolbot::BellAddress {
            pid: number(1) as u32,
            fd: number(2) as i32,
            nonce: number(3),
            pair: number(4) as u32,
        })
        .expect("the receiver's bell");
        let mut slot = Slot::map(fields[0], stream.size, false);
        let frame = vec![7u8; stream.size];
        let mut count = 0u32;
        paced(stream, |header| {
            while slot.word(TAKEN).load(Ordering::Acquire) != count {
                std::thread::yield_now();
            }
            let packet = slot.packet_mut();
            packet.copy_from_slice(&frame);
            stamp(packet, header);
            count = count.wrapping_add(1);
            slot.word(NUMBER).store(count, Ordering::SeqCst);
            bell.ring();
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

/// The receiving component, `sink`: each packet at its fifo input `input` goes to
/// `collector`.
fn sink<P: Payload>(mut collector: Collector) -> Component {
    let input = FifoIn::<P>::new(64, OverflowPolicy::Block);
    let ports = PortSet::new().input(&input);
    Component::new(
        "sink",
        Glue::boxed(
            &SINK_SPEC,
            Box::new(move |section, _| {
                if section == Section::Entry {
                    while let Some(packet) = input.recv() {
                        collector.arrived(packet.bytes());
                    }
                }
                Ok(())
            }),
        ),
        ports,
    )
}

/// What the bridge carries: a packet of one `[u8]` field, as coolc generates it (its
/// bytes serialized as one slice).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
struct Frame {
    #[serde(with = "coolbot::serde_with::As::<coolbot::serde_with::Bytes>")]
    bytes: Vec<u8>,
}

/// The same packet with its bytes a `coolbot::Bytes`, which a receiver on this host
/// decodes in place (`bridge-shm-lent`).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
struct LentFrame {
    bytes: coolbot::Bytes,
}

/// The same packet, its bytes filled in a loan of the sender node's pool
/// (`bridge-shm-loan`).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
struct LoanedFrame {
    bytes: coolbot::Bytes,
}

/// A packet of bytes the bridge carries.
trait Payload: coolbot::Packet + serde::Serialize + serde::de::DeserializeOwned {
    fn wrap(bytes: Vec<u8>) -> Self;
    fn bytes(&self) -> &[u8];

    /// Packet `number`: a copy of `frame` (as a driver fills a buffer of its own),
    /// stamped.
    fn make(frame: &[u8], number: u64) -> Self {
        let mut packet = frame.to_vec();
        stamp(&mut packet, number);
        Self::wrap(packet)
    }
}

impl Payload for LoanedFrame {
    fn wrap(bytes: Vec<u8>) -> LoanedFrame {
        LoanedFrame {
            bytes: bytes.into(),
        }
    }

    fn bytes(&self) -> &[u8] {
        &self.bytes
    }

    /// The copy of `frame` made into a loan of the node's pool.
    fn make(frame: &[u8], number: u64) -> LoanedFrame {
        let mut packet = coolbot::Bytes::loan(frame.len());
        packet.copy_from_slice(frame);
        stamp(&mut packet, number);
        LoanedFrame {
            bytes: packet.freeze(),
        }
    }
}

impl Payload for Frame {
    fn wrap(bytes: Vec<u8>) -> Frame {
        Frame { bytes }
    }

    fn bytes(&self) -> &[u8] {
        &self.bytes
    }
}

impl Payload for LentFrame {
    fn wrap(bytes: Vec<u8>) -> LentFrame {
        LentFrame {
            bytes: bytes.into(),
        }
    }

    fn bytes(&self) -> &[u8] {
        &self.bytes
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
    bridge_receiver_on::<P>(KEY, address, shm, stream, done)
}

/// A receiver node listening on `address`: an inlet on `key` into a sink.
fn bridge_receiver_on<P: Payload>(
    key: &str,
    address: &str,
    shm: bool,
    stream: Stream,
    done: Sender<Received>,
) -> (tempfile::TempDir, coolbot_zenoh::Node, System) {
    let state = setup::state_directory();
    let node = setup::node("receiver", setup::config(address, &[], shm), state.path());
    let sink = sink::<P>(Collector::new(done, stream.count));
    let mut system = System::new();
    system.add(sink).expect("sink");
    system
        .add(
            node.inlet::<P>("from_sender", key, OutputKind::Data)
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
    bridge_sender_to::<P>(&[address.to_owned()], &[(KEY, 1)], BRIDGE, shm, stream);
}

/// How many inlets `session` knows on `key` (their liveliness tokens).
fn inlets(session: &zenoh::Session, key: &str) -> usize {
    session
        .liveliness()
        .get(format!("{key}/@in/**"))
        .wait()
        .map_or(0, |replies| {
            replies
                .iter()
                .filter(|reply| reply.result().is_ok())
                .count()
        })
}

/// A sender node connected to `addresses`: one source whose output feeds an outlet
/// of `kind` on each key of `keys`; each key has as many inlets as it says, which the
/// sender waits for before it streams.
fn bridge_sender_to<P: Payload>(
    addresses: &[String],
    keys: &[(&str, usize)],
    kind: InputKind,
    shm: bool,
    stream: Stream,
) {
    let state = setup::state_directory();
    let node = setup::node(
        "sender",
        setup::config(&setup::endpoint(), addresses, shm),
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
    let outlets: Vec<String> = (0..keys.len())
        .map(|i| format!("to_receiver_{i}"))
        .collect();
    for (outlet, (key, _)) in outlets.iter().zip(keys) {
        system
            .add(node.outlet::<P>(outlet, key, kind).build().expect("outlet"))
            .expect("outlet");
        system
            .connect("source.output", &format!("{outlet}.input"))
            .expect("connect");
    }
    system.run_all().expect("run");
    for (key, count) in keys {
        setup::wait_subscribed(node.session(), key);
        let deadline = Instant::now() + LIMIT;
        while inlets(node.session(), key) < *count {
            assert!(Instant::now() < deadline, "{count} inlets on `{key}`");
            std::thread::sleep(Duration::from_millis(5));
        }
    }
    let frame = vec![7u8; stream.size];
    paced(stream, |number| output.send(P::make(&frame, number)));
    for outlet in &outlets {
        let lost = system
            .handle(outlet)
            .map_or(0, |handle| handle.snapshot().overflows);
        assert_eq!(lost, 0, "the outlet lost packets");
    }
    let shared = node.shared_memory();
    println!(
        "shared {} {} {}",
        shared.shared, shared.copied, shared.in_place
    );
    eprintln!("    the sender's node: {shared:?}");
    assert!(system.shutdown().clean(), "unclean shutdown");
    drop(state);
}

// ---------------------------------------------------------------------------------
// Fan-out: one producer, consumers in processes of their own.

/// How a producer reaches its consumers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Fan {
    /// One `last` connection: one outlet, one key, an inlet in each consumer.
    Last,
    /// One fifo connection per consumer (a fifo is N outputs to 1 input): an outlet
    /// and a key for each, all fed by the one output.
    Fifos,
}

impl Fan {
    fn name(self) -> &'static str {
        match self {
            Fan::Last => "last",
            Fan::Fifos => "fifos",
        }
    }

    /// The key of consumer `i`.
    fn key(self, i: usize) -> String {
        match self {
            Fan::Last => format!("{KEY}/fan"),
            Fan::Fifos => format!("{KEY}/fan_{i}"),
        }
    }
}

/// A fan-out child's part: `fan receive <address> <key> <size> <count> <period_ns>`,
/// or `fan send <last|fifos> <consumers> <address,...> <size> <count> <period_ns>`.
fn fan_peer(args: &[String]) {
    let number = |at: usize| -> u64 { args[at].parse().expect("a number") };
    let stream = |at: usize| Stream {
        size: number(at) as usize,
        count: number(at + 1) as usize,
        period: Duration::from_nanos(number(at + 2)),
    };
    match args[0].as_str() {
        "receive" => {
            let stream = stream(3);
            let (done, result) = bounded(1);
            let (_state, _node, system) =
                bridge_receiver_on::<Frame>(&args[2], &args[1], true, stream, done);
            println!("ready");
            let received = common::expect(&result, LIMIT, "fan-out stream");
            let lost = system
                .handle("from_sender")
                .map_or(0, |handle| handle.snapshot().overflows);
            assert_eq!(lost, 0, "the inlet counted losses");
            assert!(system.shutdown().clean(), "unclean shutdown");
            let samples = Samples::new(received.latencies);
            println!(
                "result {} {} {}",
                samples.len(),
                received.cpu.as_nanos(),
                samples.p50().as_nanos()
            );
        }
        "send" => {
            let fan = if args[1] == Fan::Last.name() {
                Fan::Last
            } else {
                Fan::Fifos
            };
            let consumers = number(2) as usize;
            let addresses: Vec<String> = args[3].split(',').map(str::to_owned).collect();
            let keys: Vec<String> = (0..consumers).map(|i| fan.key(i)).collect();
            let (keys, kind): (Vec<(&str, usize)>, InputKind) = match fan {
                Fan::Last => (vec![(&keys[0], consumers)], InputKind::Last),
                Fan::Fifos => (keys.iter().map(|k| (k.as_str(), 1)).collect(), BRIDGE),
            };
            bridge_sender_to::<Frame>(&addresses, &keys, kind, true, stream(4));
        }
        other => panic!("no fan-out role `{other}`"),
    }
}

/// A fan-out run: CPU per packet of the producer and of the average consumer, the
/// fewest packets a consumer received, its p50 latency, and the messages the producer
/// wrote into shared memory and copied.
struct FanRun {
    producer: Duration,
    consumer: Duration,
    received: u64,
    p50: Duration,
    shared: (u64, u64),
}

fn fan(fan: Fan, consumers: usize, stream: Stream) -> FanRun {
    let me = std::env::current_exe().expect("this bench's path");
    let numbers = [
        stream.size.to_string(),
        stream.count.to_string(),
        stream.period.as_nanos().to_string(),
    ];
    let mut receivers = Vec::new();
    let mut addresses = Vec::new();
    for i in 0..consumers {
        let address = setup::endpoint();
        let mut child = Command::new(&me)
            .args(["fan", "receive", &address, &fan.key(i)])
            .args(&numbers)
            .stdout(Stdio::piped())
            .spawn()
            .expect("spawn a consumer");
        let mut stdout = BufReader::new(child.stdout.take().expect("its stdout"));
        line(&mut stdout, "ready");
        receivers.push((child, stdout));
        addresses.push(address);
    }
    let mut sender = Command::new(&me)
        .args([
            "fan",
            "send",
            fan.name(),
            &consumers.to_string(),
            &addresses.join(","),
        ])
        .args(&numbers)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("spawn the producer");
    let mut from_sender = BufReader::new(sender.stdout.take().expect("its stdout"));
    let sent = line(&mut from_sender, "result");
    let results: Vec<Vec<u64>> = receivers
        .iter_mut()
        .map(|(_, stdout)| line(stdout, "result"))
        .collect();
    drop(sender.stdin.take());
    let shared = line(&mut from_sender, "shared");
    assert!(
        sender.wait().expect("producer").success(),
        "producer failed"
    );
    for (mut child, _) in receivers {
        assert!(child.wait().expect("consumer").success(), "consumer failed");
    }
    let packets = stream.count as u32;
    let consumer_cpu: u64 = results.iter().map(|r| r[1]).sum();
    FanRun {
        producer: Duration::from_nanos(sent[0]) / packets,
        consumer: Duration::from_nanos(consumer_cpu) / (packets * consumers as u32),
        received: results.iter().map(|r| r[0]).min().unwrap_or(0),
        p50: Duration::from_nanos(results.iter().map(|r| r[2]).max().unwrap_or(0)),
        shared: (shared[0], shared[1]),
    }
}

/// The fan-out rows: a 4 MiB packet at 30 Hz to 1 and to 3 consumer processes
/// through one `last` connection, and to 3 through a fifo connection each.
fn fan_out(table: &mut Table, large: Stream) {
    let one = fan(Fan::Last, 1, large);
    let three = fan(Fan::Last, 3, large);
    let fifos = fan(Fan::Fifos, 3, large);
    for (what, run) in [
        ("1 consumer", &one),
        ("3 consumers, one last connection", &three),
        ("3 consumers, a fifo connection each", &fifos),
    ] {
        println!(
            "  fan-out to {what}: producer {:?} CPU per packet, consumer {:?}; fewest received {} of {}, p50 {:?}; written into shared memory {}, copied {}",
            run.producer,
            run.consumer,
            run.received,
            large.count,
            run.p50,
            run.shared.0,
            run.shared.1,
        );
    }
    table.row(
        "4 MiB fan-out, producer CPU/packet, 3 consumers vs 1 (one last connection)",
        Figure::Time(three.producer),
        Figure::Time(one.producer),
        Goal::AtMost(1.5),
    );
    table.row(
        "4 MiB fan-out, consumer CPU/packet, 3 consumers vs 1",
        Figure::Time(three.consumer),
        Figure::Time(one.consumer),
        Goal::None,
    );
    table.row(
        "4 MiB fan-out, producer CPU/packet, 3 fifo connections vs 1 consumer",
        Figure::Time(fifos.producer),
        Figure::Time(one.producer),
        Goal::None,
    );
    table.note(&format!(
        "fan-out: packets whose bytes serialize as one slice, {} at 30 Hz; messages written into shared memory by the producer (the end message included): 1 consumer {}, 3 on one last connection {}, 3 on a fifo each {}",
        large.count, one.shared.0, three.shared.0, fifos.shared.0
    ));
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
                Engine::BridgeTcp
                | Engine::BridgeShm
                | Engine::BridgeShmLent
                | Engine::BridgeShmLoan => {
                    let (_state, _node, system) = if engine == Engine::BridgeShmLent {
                        bridge_receiver::<LentFrame>(address, true, stream, done)
                    } else if engine == Engine::BridgeShmLoan {
                        bridge_receiver::<LoanedFrame>(address, true, stream, done)
                    } else {
                        bridge_receiver::<Frame>(address, engine == Engine::BridgeShm, stream, done)
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
                Engine::WakeFloor => floor::receive(address, stream, ready),
                Engine::Bell => bell::receive(address, stream),
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
                    bridge_sender::<Frame>(address, engine == Engine::BridgeShm, stream)
                }
                Engine::BridgeShmLent => bridge_sender::<LentFrame>(address, true, stream),
                Engine::BridgeShmLoan => bridge_sender::<LoanedFrame>(address, true, stream),
                Engine::WakeFloor => floor::send(address, stream),
                Engine::Bell => bell::send(address, stream),
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
        Engine::WakeFloor | Engine::Bell => std::env::temp_dir()
            .join(format!("coolbot-bench-floor-{}-{tag}", std::process::id()))
            .display()
            .to_string(),
        _ => setup::endpoint(),
    };
    let (mut receiver, mut from_receiver) = spawn(engine, "receive", &address, stream);
    let ready = line(&mut from_receiver, "ready");
    // The bell engine's sender also needs the receiver's bell.
    let address = match engine {
        Engine::Bell => std::iter::once(address)
            .chain(ready.iter().map(u64::to_string))
            .collect::<Vec<_>>()
            .join(" "),
        _ => address,
    };
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
    match args.first().map(String::as_str) {
        Some("peer") => return peer(&args[1..]),
        Some("fan") => return fan_peer(&args[1..]),
        _ => {}
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
        "Processes on one host: the bridge with shared memory against the engines, and its fan-out",
        mode,
    );
    // `-- fan`: the fan-out rows (also when no engine is chosen).
    let fans = chosen.is_empty() || chosen.iter().any(|c| c == "fan");
    // The floor against the TCP bridge: the least ratio an engine that wakes a
    // sleeping receiver once a packet can reach against it on this machine; and that
    // floor with a component as the receiver, its own bell rung by the sender.
    let floors = |table: &mut Table| {
        for engine in [Engine::WakeFloor, Engine::Bell] {
            if let (Some((floor, _)), Some((tcp, _))) = (figure(engine), figure(Engine::BridgeTcp))
            {
                table.row(
                    &format!("64 B p50, {} vs bridge-tcp", engine.name()),
                    Figure::Time(floor.latencies.0),
                    Figure::Time(tcp.latencies.0),
                    Goal::None,
                );
            }
        }
        if let (Some((bell, _)), Some((floor, _))) =
            (figure(Engine::Bell), figure(Engine::WakeFloor))
        {
            table.row(
                "64 B p50, bell vs wake-floor",
                Figure::Time(bell.latencies.0),
                Figure::Time(floor.latencies.0),
                Goal::None,
            );
        }
    };
    let Some((shm_small, shm_large)) = figure(Engine::BridgeShm) else {
        floors(&mut table);
        if fans {
            fan_out(&mut table, large);
        }
        table.print();
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
    against(&mut table, Engine::WakeFloor, (Goal::None, Goal::None));
    floors(&mut table);
    // The same goals for a packet whose bytes the receiver reads in place, and for
    // one filled in a loan of the pool.
    for engine in [Engine::BridgeShmLent, Engine::BridgeShmLoan] {
        let Some((_, packet)) = figure(engine) else {
            continue;
        };
        for (baseline, goal) in [
            (Engine::ZenohShm, Goal::AtMost(1.2)),
            (Engine::Iceoryx2, Goal::AtMost(1.2)),
            (Engine::BridgeTcp, Goal::AtMost(0.2)),
        ] {
            if let Some((_, large)) = figure(baseline) {
                table.row(
                    &format!("4 MiB CPU/packet, {} vs {}", engine.name(), baseline.name()),
                    Figure::Time(packet.cpu_per_packet),
                    Figure::Time(large.cpu_per_packet),
                    goal,
                );
            }
        }
    }
    table.note(&format!(
        "64 B: {} packets one every {:?}; 4 MiB: {} packets at 30 Hz; CPU time of both processes (CLOCK_PROCESS_CPUTIME_ID)",
        small.count, small.period, large.count
    ));
    if fans {
        fan_out(&mut table, large);
    }
    table.print();
}
