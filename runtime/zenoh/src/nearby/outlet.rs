//! The producer's side of the same-host path: an outlet that asks for a ring, writes
//! into it (on the producer's thread for a fifo), and goes back to the key when the
//! ring is gone or a message does not fit.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, Weak};
use std::time::{Duration, Instant};

use coolbot::port::{FifoIn, Intake, UfifoIn};
use coolbot::ring::{RingAddress, RingWriter, WriteError};
use coolbot::{BellAddress, ConsumerBell, Packet, RemoteBell, Source, SourceGuard};
use serde::Serialize;
use zenoh::Wait;

use super::wire::{Answer, Ask, ask_key, bell_address, bell_at, host};
use crate::ledger::{self, Sent};
use crate::locks::lock;
use crate::tally::Tally;

/// How long after a refusal, or the loss of a ring, an outlet asks again; doubled
/// at each unanswered question, up to [`LONGEST_WAIT`].
const FIRST_WAIT: Duration = Duration::from_millis(100);
const LONGEST_WAIT: Duration = Duration::from_secs(10);

/// How long a question waits for its answer.
const ASK_TIMEOUT: Duration = Duration::from_secs(1);

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
