//! The same-host path of a queue bridge (`docs/distribution.md`, "Same host: a
//! ring"): when a fifo or ufifo outlet and its inlet are in two processes of one
//! host (or one process), the outlet writes its numbered messages into a
//! [`coolbot::ring::Ring`] the inlet made, and rings the consumer's doorbell
//! ([`coolbot::RemoteBell`]); the consumer's own thread takes them (a
//! [`coolbot::Source`]) and hands each to the inlet's delivery, as if it had come on
//! the key: the same numbering, ledger, losses and backlog. No TCP, no Zenoh thread,
//! and, for a fifo, no wake-up of the outlet's thread: a packet the outlet's input
//! takes on the producer's thread ([`coolbot::port::Intake`]) is in the consumer's
//! input after one futex wake.
//!
//! **How the path is found.** The outlet asks `K/@ring/**` (a query carrying its host's
//! boot id, its epoch, the number it has sent, and its own doorbell); an inlet on the
//! same host makes a ring, adds the source to its consumer's bell and answers with
//! both addresses. The answer comes on a Zenoh thread and is adopted by whichever of
//! the outlet's paths sends next; until then, and whenever the ring is not usable,
//! messages go on the key as before.
//!
//! **Order.** Messages sent on the key after the question may still be on their way
//! when the first goes into the ring: the consumer takes a ring message only once the
//! key's message before it is in the consumer's input (or a second has passed: a
//! link that broke lost it, the ledger counts it, and a key message that still comes
//! after is dropped by the inlet's `Delivered`). A message longer than a quarter of
//! the ring sends the stream back to the key for good, once the consumer has taken
//! everything in the ring. When the ring is full, the outlet leaves the packets at its
//! input (whose overflow policy applies, as for a slow consumer in one process) and
//! asks the consumer to ring it when it has taken.
//!
//! **Ends.** A consumer whose inlet closed its ring is seen by the outlet at its next
//! write, one whose process ended within [`LIVENESS`] (or when the ring is full): the
//! stream goes back to the key (the messages left in the ring are lost, and counted
//! as a gone inlet's are: `crate::ledger`), and the outlet asks again later. A
//! producer that ends leaves the consumer its ring, replaced when that outlet asks
//! again, and bounded in number per inlet.

use crate::locks::lock;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, OnceLock, Weak};
use std::time::{Duration, Instant};

use coolbot::port::{FifoIn, Intake, UfifoIn};
use coolbot::ring::{Ring, RingAddress, RingWriter, WriteError};
use coolbot::{BellAddress, Chain, ConsumerBell, Packet, RemoteBell, Source, SourceGuard};
use serde::{Deserialize, Serialize};
use zenoh::Wait;

use crate::Error;
use crate::delivery::{DecodeFn, Via};
use crate::ledger::{self, Sent};
use crate::tally::Tally;

/// The bytes of messages in one ring: 64 KiB (messages up to 16 KiB).
const RING_BYTES: usize = 64 << 10;

/// How long after a refusal, or the loss of a ring, an outlet asks again; doubled
/// at each unanswered question, up to [`LONGEST_WAIT`].
const FIRST_WAIT: Duration = Duration::from_millis(100);
const LONGEST_WAIT: Duration = Duration::from_secs(10);

/// How long a question waits for its answer.
const ASK_TIMEOUT: Duration = Duration::from_secs(1);

/// How long a consumer holds a ring message whose predecessor the stream has not
/// brought: a message sent on the key just before the ring was adopted is on its
/// way; longer, the link lost it.
const GATE_PATIENCE: Duration = Duration::from_secs(1);

/// The most rings an inlet keeps (one per outlet on its host; a queue connection
/// has N producers).
const MAX_RINGS: usize = 16;

/// The keys an outlet asks its inlets for a ring on.
fn ask_key(key: &str) -> String {
    format!("{key}/@ring/**")
}

/// This host's identity: its boot id (two processes with the same one share the
/// host's memory, if each may read the other's `/proc`).
fn host() -> Option<&'static str> {
    static HOST: OnceLock<Option<String>> = OnceLock::new();
    HOST.get_or_init(|| {
        std::fs::read_to_string("/proc/sys/kernel/random/boot_id")
            .ok()
            .map(|id| id.trim().to_owned())
    })
    .as_deref()
}

/// A doorbell's address on the wire.
type BellAt = (u32, i32, u64, u32);
/// A ring's address on the wire.
type RingAt = (u32, i32, u64, u64);

fn bell_at(a: BellAddress) -> BellAt {
    (a.pid, a.fd, a.nonce, a.pair)
}

fn bell_address((pid, fd, nonce, pair): BellAt) -> BellAddress {
    BellAddress {
        pid,
        fd,
        nonce,
        pair,
    }
}

/// An outlet's question.
#[derive(Serialize, Deserialize)]
struct Ask {
    host: String,
    epoch: u64,
    /// The number the outlet had sent on the key when it asked.
    sent: u64,
    /// The outlet's own doorbell (rung when it waits for room).
    bell: BellAt,
    /// The outlet (`node/name`): a second question of the same outlet replaces its
    /// ring.
    outlet: String,
}

/// An inlet's answer.
#[derive(Serialize, Deserialize)]
enum Answer {
    Ring {
        ring: RingAt,
        bell: BellAt,
    },
    /// Not on this host, or it cannot take a ring now (the reason).
    No(String),
}

/// The packets waiting at an outlet's input.
pub(crate) trait Queue<T>: Send + Sync {
    fn next(&self) -> Option<T>;
    fn is_empty(&self) -> bool;
    /// The doorbell of the outlet (once it is in a system).
    fn bell(&self) -> Option<ConsumerBell>;
}

impl<T: Packet> Queue<T> for FifoIn<T> {
    fn next(&self) -> Option<T> {
        self.recv()
    }
    fn is_empty(&self) -> bool {
        FifoIn::is_empty(self)
    }
    fn bell(&self) -> Option<ConsumerBell> {
        self.owner_bell()
    }
}

impl<T: Packet> Queue<T> for UfifoIn<T> {
    fn next(&self) -> Option<T> {
        self.recv()
    }
    fn is_empty(&self) -> bool {
        UfifoIn::is_empty(self)
    }
    fn bell(&self) -> Option<ConsumerBell> {
        self.owner_bell()
    }
}

/// Sends one packet on the key as the next numbered message (`crate::bridge`).
pub(crate) type Link<T> = Box<dyn Fn(&T) + Send + Sync>;

/// A ring an inlet gave: where to write, and whom to ring.
struct OnRing {
    writer: RingWriter,
    consumer: RemoteBell,
    /// When the consumer's process was last seen alive.
    seen: Instant,
}

/// How often a writing outlet looks whether its consumer's process still runs (a
/// killed process never closes its ring).
const LIVENESS: Duration = Duration::from_millis(20);

impl OnRing {
    /// Whether the consumer is gone: its ring closed (a cheap look, each time), or
    /// its process ended (a system call, at most every [`LIVENESS`]).
    fn gone(&mut self, now: bool) -> bool {
        if self.writer.is_closed() {
            return true;
        }
        if now || self.seen.elapsed() >= LIVENESS {
            if self.writer.is_gone() {
                return true;
            }
            self.seen = Instant::now();
        }
        false
    }
}

/// What an outlet's paths share, under one lock (their order).
struct Path<T> {
    ring: Option<OnRing>,
    /// A packet taken from the input that found the ring full (or a long one that
    /// waits for the ring to empty): sent before any other.
    pending: Option<T>,
    /// A message too long for the ring was sent on the key: the key for good.
    key_only: bool,
    /// When to ask again, and the wait after that.
    next_ask: Instant,
    wait: Duration,
    /// The source on the outlet's own bell (its thread forwards when the consumer
    /// rings it), and that bell's address; made on the first forward.
    own: Option<(SourceGuard, Option<BellAddress>)>,
    /// Rings the outlet when an inlet of the key goes away (a consumer's process that
    /// ended cannot ring it), so that an outlet waiting for room sees it; made when a
    /// ring is first used.
    watch: Option<zenoh::pubsub::Subscriber<()>>,
    /// The message buffer.
    buffer: Vec<u8>,
}

/// An outlet's same-host path: see the module documentation.
pub(crate) struct Nearby<T, Q> {
    parts: Parts<T, Q>,
    /// Whether the outlet runs: the producer's thread writes only then.
    running: AtomicBool,
    path: Mutex<Path<T>>,
    /// An answer's ring, opened on Zenoh's thread, adopted by the next send.
    offered: Arc<Mutex<Option<OnRing>>>,
    asking: Arc<AtomicBool>,
}

/// What became of a packet offered to the ring.
enum Sent1<T> {
    Done,
    /// Not now: kept, the outlet waits to be rung.
    Wait(T),
    /// Not by the ring: on the key.
    Key(T),
}

/// Why a message did not go into the ring.
enum Unwritten {
    Ring(WriteError),
    /// It does not encode: the key's path encodes it again, and counts it.
    Encoding,
}

/// The parts of an outlet its same-host path sends with.
pub(crate) struct Parts<T, Q> {
    pub(crate) session: zenoh::Session,
    pub(crate) key: String,
    /// `node/name`.
    pub(crate) outlet: String,
    pub(crate) epoch: u64,
    pub(crate) sent: Arc<Sent>,
    pub(crate) tally: Option<Arc<Tally>>,
    pub(crate) queue: Q,
    pub(crate) link: Link<T>,
    /// Where a packet the outlet held when it was dropped is counted (its input).
    pub(crate) losses: coolbot::port::ErasedInput,
    pub(crate) counters: Arc<crate::shm::Counters>,
}

impl<T: Packet + Serialize, Q: Queue<T> + 'static> Nearby<T, Q> {
    pub(crate) fn new(parts: Parts<T, Q>) -> Arc<Nearby<T, Q>> {
        Arc::new(Nearby {
            parts,
            running: AtomicBool::new(false),
            path: Mutex::new(Path {
                ring: None,
                pending: None,
                key_only: false,
                next_ask: Instant::now(),
                wait: FIRST_WAIT,
                own: None,
                watch: None,
                buffer: Vec::new(),
            }),
            offered: Arc::default(),
            asking: Arc::default(),
        })
    }

    /// The outlet started (true) or stopped: the producer's thread writes into the
    /// ring only while it runs (else its packets wait at the input, as for any
    /// component that does not run).
    pub(crate) fn set_running(&self, running: bool) {
        self.running.store(running, Ordering::Release);
    }

    /// Take a ring an answer brought.
    fn adopt(&self, path: &mut Path<T>) {
        if path.ring.is_none()
            && !path.key_only
            && let Some(ring) = lock(&self.offered).take()
        {
            path.ring = Some(ring);
            path.wait = FIRST_WAIT;
            tracing::debug!(key = %self.parts.key, "outlet writes into a ring of its consumer's process");
        }
    }

    /// Write `packet` as the next numbered message into `ring`.
    fn write(&self, ring: &mut OnRing, buffer: &mut Vec<u8>, packet: &T) -> Result<(), Unwritten> {
        let next = self.parts.sent.get() + 1;
        buffer.clear();
        match postcard::to_extend(&(self.parts.epoch, next, packet), std::mem::take(buffer)) {
            Ok(encoded) => *buffer = encoded,
            Err(error) => {
                tracing::trace!(key = %self.parts.key, "ring message does not encode: {error}");
                return Err(Unwritten::Encoding);
            }
        }
        if ring.gone(false) {
            return Err(Unwritten::Ring(WriteError::Gone));
        }
        // Tallied before the consumer can have it, as on the key.
        if let Some(tally) = &self.parts.tally {
            tally.record(next);
        }
        match ring.writer.write(buffer) {
            Ok(()) => {
                self.parts.sent.set(next);
                ring.consumer.ring();
                self.parts.counters.ring_written();
                tracing::trace!(target: ledger::LEDGER_TARGET, "{} sent {} {next}", self.parts.key, self.parts.epoch);
                Ok(())
            }
            Err(error) => {
                if let Some(tally) = &self.parts.tally {
                    tally.record(next - 1);
                }
                Err(Unwritten::Ring(error))
            }
        }
    }

    /// Offer `packet` to the ring (the outlet's thread).
    fn send_one(&self, path: &mut Path<T>, packet: T) -> Sent1<T> {
        let Path {
            ring,
            buffer,
            key_only,
            ..
        } = path;
        let Some(on) = ring.as_mut() else {
            return Sent1::Key(packet);
        };
        let wait_for = match self.write(on, buffer, &packet) {
            Ok(()) => return Sent1::Done,
            Err(Unwritten::Encoding) => return Sent1::Key(packet),
            Err(Unwritten::Ring(WriteError::Gone)) => {
                self.lost_ring(path);
                return Sent1::Key(packet);
            }
            Err(Unwritten::Ring(error)) => error,
        };
        // Full, or too long while the ring is not empty: wait for the consumer to
        // take, unless it is gone.
        if on.gone(true) {
            self.lost_ring(path);
            return Sent1::Key(packet);
        }
        on.writer.ask_to_be_rung();
        // Room made, or the ring emptied, before the request was seen: look again.
        match wait_for {
            WriteError::TooLong if on.writer.is_empty() => {
                *key_only = true;
                *ring = None;
                tracing::debug!(key = %self.parts.key, "a message too long for the ring: the outlet sends on the key from now on");
                Sent1::Key(packet)
            }
            WriteError::TooLong => Sent1::Wait(packet),
            _ => match self.write(on, buffer, &packet) {
                Ok(()) => Sent1::Done,
                Err(Unwritten::Ring(WriteError::Full)) => Sent1::Wait(packet),
                Err(_) => {
                    self.lost_ring(path);
                    Sent1::Key(packet)
                }
            },
        }
    }

    fn lost_ring(&self, path: &mut Path<T>) {
        path.ring = None;
        path.next_ask = Instant::now() + path.wait;
        tracing::debug!(key = %self.parts.key, "the consumer's ring is gone: the outlet sends on the key");
    }

    /// Send what waits at the input (the outlet's thread: its section, or its
    /// doorbell rung by the consumer).
    pub(crate) fn forward(self: &Arc<Self>) {
        // A stopped outlet sends nothing (its bell still rings for arrivals, and its
        // sources are drained on such turns); it forwards again when it starts.
        if !self.running.load(Ordering::Acquire) {
            return;
        }
        let mut path = lock(&self.path);
        if path.own.is_none()
            && let Some(bell) = self.parts.queue.bell()
        {
            let source: Arc<dyn Source> = Arc::new(OwnBell {
                nearby: Arc::downgrade(self),
            });
            let address = bell.address();
            path.own = Some((bell.add_source(source), address));
        }
        self.adopt(&mut path);
        if path.ring.is_none() && !path.key_only {
            self.ask(&mut path);
        }
        if path.ring.is_some() && path.watch.is_none() {
            path.watch = self.watch(&path);
        }
        loop {
            let Some(packet) = path.pending.take().or_else(|| self.parts.queue.next()) else {
                return;
            };
            match self.send_one(&mut path, packet) {
                Sent1::Done => {}
                Sent1::Wait(packet) => {
                    path.pending = Some(packet);
                    return;
                }
                Sent1::Key(packet) => (self.parts.link)(&packet),
            }
        }
    }

    /// A watch of the key's inlets' tokens that rings the outlet's own bell when one
    /// goes (None: it cannot be made; the outlet then sees a gone consumer at its next
    /// send).
    fn watch(&self, path: &Path<T>) -> Option<zenoh::pubsub::Subscriber<()>> {
        let own = path.own.as_ref().and_then(|(_, at)| *at)?;
        let bell = RemoteBell::open(&own).ok()?;
        self.parts
            .session
            .liveliness()
            .declare_subscriber(format!("{}/@in/**", self.parts.key))
            .callback(move |sample| {
                if sample.kind() == zenoh::sample::SampleKind::Delete {
                    bell.ring();
                }
            })
            .wait()
            .ok()
    }

    /// Ask the key's inlets for a ring, if it is time (the answer comes later).
    fn ask(&self, path: &mut Path<T>) {
        let now = Instant::now();
        if now < path.next_ask || self.asking.load(Ordering::Acquire) {
            return;
        }
        let (Some(host), Some(bell)) = (host(), path.own.as_ref().and_then(|(_, at)| *at)) else {
            // Not on Linux, or the outlet's own bell cannot be rung from another
            // process (nobody could tell it of room): the key.
            path.key_only = true;
            return;
        };
        path.next_ask = now + path.wait;
        path.wait = (path.wait * 2).min(LONGEST_WAIT);
        let ask = Ask {
            host: host.to_owned(),
            epoch: self.parts.epoch,
            sent: self.parts.sent.get(),
            bell: bell_at(bell),
            outlet: self.parts.outlet.clone(),
        };
        let Ok(payload) = postcard::to_allocvec(&ask) else {
            return;
        };
        let offered = Arc::clone(&self.offered);
        self.asking.store(true, Ordering::Release);
        let done = Asking(Arc::clone(&self.asking));
        let key = self.parts.key.clone();
        let asked = self
            .parts
            .session
            .get(ask_key(&self.parts.key))
            .payload(payload)
            .timeout(ASK_TIMEOUT)
            .callback(move |reply| {
                let _asking = &done;
                let Ok(sample) = reply.result() else {
                    return;
                };
                let bytes = sample.payload().to_bytes();
                let answer = match crate::codec::decode::<Answer>(&bytes, 256) {
                    Ok(answer) => answer,
                    Err(error) => {
                        tracing::debug!(%key, "a ring answer that does not decode: {error}");
                        return;
                    }
                };
                match answer {
                    Answer::Ring { ring, bell } => {
                        let (pid, fd, nonce, capacity) = ring;
                        let opened = RingWriter::open(&RingAddress {
                            pid,
                            fd,
                            nonce,
                            capacity,
                        })
                        .and_then(|writer| {
                            Ok(OnRing {
                                writer,
                                consumer: RemoteBell::open(&bell_address(bell))?,
                                seen: Instant::now(),
                            })
                        });
                        match opened {
                            Ok(ring) => *lock(&offered) = Some(ring),
                            Err(error) => {
                                tracing::debug!(%key, "the consumer's ring does not open: {error}");
                            }
                        }
                    }
                    Answer::No(reason) => tracing::debug!(%key, "no ring: {reason}"),
                }
            })
            .wait();
        if let Err(error) = asked {
            tracing::debug!(key = %self.parts.key, "ring question not sent: {error}");
        }
    }

    /// Write `packet` into the ring now, on the producer's thread, if the outlet runs,
    /// nothing waits before it and the ring takes it.
    fn offer(&self, packet: &T) -> bool {
        if !self.running.load(Ordering::Acquire) {
            return false;
        }
        let Ok(mut path) = self.path.try_lock() else {
            return false;
        };
        self.adopt(&mut path);
        if path.pending.is_some() || !self.parts.queue.is_empty() {
            return false;
        }
        let Path { ring, buffer, .. } = &mut *path;
        let Some(on) = ring.as_mut() else {
            return false;
        };
        self.write(on, buffer, packet).is_ok()
    }
}

impl<T, Q> Drop for Nearby<T, Q> {
    fn drop(&mut self) {
        // A packet taken from the input and never sent: lost at the outlet's input.
        let pending = self.path.get_mut().map_or_else(
            |poisoned| poisoned.into_inner().pending.is_some(),
            |p| p.pending.is_some(),
        );
        if pending {
            self.parts.losses.count_loss(1);
        }
    }
}

/// Clears an outlet's `asking` when its question's callback is dropped: the query
/// ended (answered, timed out, or not sent).
struct Asking(Arc<AtomicBool>);

impl Drop for Asking {
    fn drop(&mut self) {
        self.0.store(false, Ordering::Release);
    }
}

/// What a fifo outlet's input offers its packets to: its path, held weakly (the
/// path holds the input).
pub(crate) struct Inline<T, Q>(pub(crate) Weak<Nearby<T, Q>>);

impl<T: Packet + Serialize, Q: Queue<T> + 'static> Intake<T> for Inline<T, Q> {
    fn offer(&self, packet: &T) -> bool {
        self.0.upgrade().is_some_and(|nearby| nearby.offer(packet))
    }
}

/// The source on an outlet's own bell: its thread forwards when rung (by the
/// consumer that made room).
struct OwnBell<T, Q> {
    nearby: Weak<Nearby<T, Q>>,
}

impl<T: Packet + Serialize, Q: Queue<T> + 'static> Source for OwnBell<T, Q> {
    /// A packet waits, and the ring has emptied or is gone (not while the consumer
    /// has still to take: the thread sleeps until it rings).
    fn ready(&self) -> bool {
        self.nearby.upgrade().is_some_and(|nearby| {
            nearby.running.load(Ordering::Acquire)
                && nearby.path.try_lock().is_ok_and(|path| {
                    path.pending.is_some()
                        && path
                            .ring
                            .as_ref()
                            .is_none_or(|ring| ring.writer.is_empty() || ring.writer.is_closed())
                })
        })
    }

    fn drain(&self) {
        if let Some(nearby) = self.nearby.upgrade() {
            nearby.forward();
        }
    }
}

/// What an outlet calls on its same-host path.
pub(crate) trait SameHost: Send + Sync {
    /// Send what waits at the input (the outlet's thread).
    fn forward(&self);
    /// The outlet started (true) or stopped.
    fn set_running(&self, running: bool);
}

/// An outlet's same-host path, as the outlet holds it.
pub(crate) struct Held<T, Q>(pub(crate) Arc<Nearby<T, Q>>);

impl<T: Packet + Serialize, Q: Queue<T> + 'static> SameHost for Held<T, Q> {
    fn forward(&self) {
        self.0.forward();
    }

    fn set_running(&self, running: bool) {
        self.0.set_running(running);
    }
}

// ---------------------------------------------------------------------------------
// The inlet's side.

/// The newest number of an outlet epoch the inlet has handed to its consumer's input
/// from the key (None: none yet).
pub(crate) type NewestFn = Arc<dyn Fn(u64) -> Option<u64> + Send + Sync>;

/// What an inlet's rings are made with.
pub(crate) struct InletParts {
    pub(crate) key: String,
    /// Where it answers: `K/@ring/<node>/<name>` (under its node's name, as its
    /// acknowledgments: access rules let a node answer only under its own).
    pub(crate) answers_on: String,
    /// The inlet's delivery of a message this process holds (a ring's is copied out
    /// of the ring before it is handed on).
    pub(crate) decode: DecodeFn,
    pub(crate) newest: NewestFn,
    /// The consumer's doorbell (the one component the inlet's output feeds).
    pub(crate) consumer: Box<dyn Fn() -> Option<ConsumerBell> + Send + Sync>,
    pub(crate) counters: Arc<crate::shm::Counters>,
    pub(crate) replier: crate::reply::Replier,
}

/// One ring of an inlet: the outlet it is for, the source on the consumer's bell,
/// and that bell, rung to look at the ring again.
struct Entry {
    /// The outlet (`node/name`) and its epoch.
    outlet: (String, u64),
    /// The outlet's process.
    pid: u32,
    source: Arc<RingSource>,
    consumer: RemoteBell,
    _guard: SourceGuard,
}

/// An inlet's rings: made when an outlet of its host asks, drained by its consumer's
/// thread.
pub(crate) struct InletRings {
    parts: InletParts,
    /// Whether it answers (the inlet runs), and its rings; under one lock, so that a
    /// question answered as the inlet stops leaves no ring behind.
    rings: Mutex<(bool, Vec<Entry>)>,
}

impl InletRings {
    pub(crate) fn new(parts: InletParts) -> Arc<InletRings> {
        Arc::new(InletRings {
            parts,
            rings: Mutex::new((false, Vec::new())),
        })
    }

    /// Drop every ring (the inlet stopped): their outlets go back to the key.
    pub(crate) fn close(&self) {
        let rings = {
            let mut rings = lock(&self.rings);
            rings.0 = false;
            std::mem::take(&mut rings.1)
        };
        drop(rings);
    }

    /// The outlet's ledger asked what the inlet has had: a ring whose first message
    /// waits for the key's message before it is looked at again (the gate's patience
    /// has no timer of its own; an outlet asks when its inlet is behind).
    pub(crate) fn nudge(&self) {
        for entry in &lock(&self.rings).1 {
            if entry.source.held() {
                entry.consumer.ring();
            }
        }
    }

    /// Answer the outlets' questions (until the queryable is dropped).
    pub(crate) fn serve(
        self: &Arc<Self>,
        session: &zenoh::Session,
    ) -> Result<zenoh::query::Queryable<()>, Error> {
        lock(&self.rings).0 = true;
        let rings = Arc::downgrade(self);
        session
            .declare_queryable(&self.parts.answers_on)
            .callback(move |query| {
                let Some(rings) = rings.upgrade() else {
                    return;
                };
                let Some(payload) = query.payload() else {
                    return;
                };
                let Ok(ask) = crate::codec::decode_payload::<Ask>(payload, 1024) else {
                    return;
                };
                let answer = match rings.answer(ask) {
                    Ok((ring, bell)) => Answer::Ring {
                        ring: (ring.pid, ring.fd, ring.nonce, ring.capacity),
                        bell: bell_at(bell),
                    },
                    Err(reason) => Answer::No(reason),
                };
                let Ok(bytes) = postcard::to_allocvec(&answer) else {
                    return;
                };
                // On its own key (access rules allow a node's replies there only), from
                // the node's replier (a querier that does not read holds that thread,
                // not Zenoh's).
                let key = rings.parts.answers_on.clone();
                rings.parts.replier.send("a ring's answer", move || {
                    let _ = query.reply(key, bytes).wait();
                });
            })
            .wait()
            .map_err(Error::zenoh("declare the inlet's ring queryable"))
    }

    fn answer(&self, ask: Ask) -> Result<(RingAddress, BellAddress), String> {
        let parts = &self.parts;
        if host() != Some(ask.host.as_str()) {
            return Err("another host".to_owned());
        }
        let outlet = (ask.outlet, ask.epoch);
        {
            // What can be refused is refused before anything is made.
            let mut rings = lock(&self.rings);
            if !rings.0 {
                return Err("the inlet is not running".to_owned());
            }
            rings.1.retain(|entry| !entry.ended());
            if let Some(entry) = rings.1.iter().find(|entry| entry.outlet == outlet)
                && !entry.source.unused()
            {
                // An outlet that has written into its ring does not ask again while
                // the ring works: a question that says it is that outlet is another
                // peer's, or came too late.
                return Err("that outlet has a ring in use".to_owned());
            }
            if rings.1.len() >= MAX_RINGS && !rings.1.iter().any(|e| e.outlet == outlet) {
                return Err(format!("the inlet has {MAX_RINGS} rings in use"));
            }
        }
        let consumer = (parts.consumer)()
            .ok_or("the inlet's output does not feed one input directly (no consumer to ring)")?;
        let bell = consumer
            .address()
            .ok_or("the consumer's doorbell is not in shared memory")?;
        let writer = RemoteBell::open(&bell_address(ask.bell))
            .map_err(|error| format!("the outlet's bell: {error}"))?;
        let ring_again =
            RemoteBell::open(&bell).map_err(|error| format!("the consumer's bell: {error}"))?;
        let ring = Ring::new(RING_BYTES).map_err(|error| format!("no ring: {error}"))?;
        let address = ring.address().ok_or("the ring has no address")?;
        let source = Arc::new(RingSource {
            ring: Mutex::new(ring),
            decode: Arc::clone(&parts.decode),
            newest: Arc::clone(&parts.newest),
            writer,
            gate: Mutex::new(Gate::Closed {
                asked_at: ask.sent,
                since: None,
            }),
            counters: Arc::clone(&parts.counters),
            key: parts.key.clone(),
            broken: AtomicBool::new(false),
        });
        let mut rings = lock(&self.rings);
        if !rings.0 {
            return Err("the inlet is not running".to_owned());
        }
        let entries = &mut rings.1;
        entries.retain(|entry| entry.outlet != outlet);
        if entries.len() >= MAX_RINGS {
            return Err(format!("the inlet has {MAX_RINGS} rings in use"));
        }
        let guard = consumer.add_source(Arc::clone(&source) as Arc<dyn Source>);
        entries.push(Entry {
            outlet,
            pid: ask.bell.0,
            source,
            consumer: ring_again,
            _guard: guard,
        });
        Ok((address, bell))
    }
}

impl Entry {
    /// Whether its outlet will not write into it again: the ring broke, or the
    /// outlet's process ended.
    fn ended(&self) -> bool {
        self.source.broken.load(Ordering::Relaxed) || coolbot::ring::process_ended(self.pid)
    }
}

/// Whether a ring's first messages may be taken yet.
enum Gate {
    /// Not until the stream brought the message before the ring's first: the
    /// outlet's number when it asked (messages up to it came before the question on
    /// the key), and when the first message was held.
    Closed {
        asked_at: u64,
        since: Option<Instant>,
    },
    Open,
}

/// One outlet's ring, drained by the consumer's thread.
struct RingSource {
    ring: Mutex<Ring>,
    decode: DecodeFn,
    newest: NewestFn,
    /// The outlet's bell, rung when it waits for room and when the ring closes.
    writer: RemoteBell,
    gate: Mutex<Gate>,
    counters: Arc<crate::shm::Counters>,
    key: String,
    broken: AtomicBool,
}

impl RingSource {
    /// Whether its outlet never wrote into it (an answer it did not adopt).
    fn unused(&self) -> bool {
        self.ring.try_lock().is_ok_and(|ring| ring.is_unused())
    }

    /// Whether its first message is held, waiting for the key.
    fn held(&self) -> bool {
        self.gate
            .try_lock()
            .is_ok_and(|gate| matches!(*gate, Gate::Closed { since: Some(_), .. }))
    }

    /// Whether the gate lets a message through now, or may (not yet looked at, or
    /// its patience is over).
    fn gate_may_open(&self) -> bool {
        self.gate.try_lock().is_ok_and(|gate| match *gate {
            Gate::Open | Gate::Closed { since: None, .. } => true,
            Gate::Closed {
                since: Some(since), ..
            } => since.elapsed() >= GATE_PATIENCE,
        })
    }

    /// Whether the message `bytes` (numbered) may be delivered now.
    fn may_pass(&self, gate: &mut Gate, bytes: &[u8]) -> bool {
        let Gate::Closed { asked_at, since } = gate else {
            return true;
        };
        let Ok(((epoch, seq), _)) = postcard::take_from_bytes::<(u64, u64)>(bytes) else {
            // Not numbered: delivered, and the delivery counts it lost.
            *gate = Gate::Open;
            return true;
        };
        let before = seq.saturating_sub(1);
        let waited = since.is_some_and(|since| since.elapsed() >= GATE_PATIENCE);
        // The key's message before it handed to the consumer's input (not merely
        // received: `newest` is read under the lock the key's delivery holds while it
        // sends).
        if before <= *asked_at || (self.newest)(epoch).is_some_and(|n| n >= before) || waited {
            *gate = Gate::Open;
            return true;
        }
        since.get_or_insert_with(Instant::now);
        false
    }

    /// Close it: what was left in it is dropped (the numbers are counted missing
    /// when the key brings the next), and the outlet, told, goes back to the key.
    fn broke(&self, ring: &Ring, why: &str) {
        self.broken.store(true, Ordering::Relaxed);
        ring.close();
        self.writer.ring();
        tracing::warn!(key = %self.key, "inlet dropped what was left in a ring: {why}");
    }
}

impl Source for RingSource {
    /// Messages wait, and the gate may let them by.
    fn ready(&self) -> bool {
        !self.broken.load(Ordering::Relaxed)
            && self.ring.try_lock().is_ok_and(|ring| ring.has_messages())
            && self.gate_may_open()
    }

    fn drain(&self) {
        if self.broken.load(Ordering::Relaxed) {
            return;
        }
        let mut ring = lock(&self.ring);
        let mut gate = lock(&self.gate);
        let taken = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            ring.take(|bytes| {
                if !self.may_pass(&mut gate, bytes) {
                    return false;
                }
                // Counted before the consumer can have it. A full `block` fifo is
                // handled by the delivery as for the key: the inlet's backlog.
                self.counters.ring_taken(1);
                (self.decode)(&[bytes], Via::Ring);
                true
            })
        }));
        match taken {
            Ok(Ok(taken)) => {
                if taken.writer_waits {
                    self.writer.ring();
                }
            }
            Ok(Err(error)) => self.broke(&ring, &Chain(&error).to_string()),
            Err(panic) => self.broke(
                &ring,
                &format!("its delivery panicked: {}", coolbot::panic_message(&*panic)),
            ),
        }
    }
}

impl Drop for RingSource {
    fn drop(&mut self) {
        // Closed before its memory goes: the outlet, perhaps waiting for room, is
        // told now.
        lock(&self.ring).close();
        self.writer.ring();
    }
}
