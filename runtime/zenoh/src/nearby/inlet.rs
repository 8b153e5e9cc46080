//! The consumer's side of the same-host path: the rings an inlet makes for the
//! outlets of its host that ask, and the source on its consumer's doorbell that takes
//! their messages, in order with the key's.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use coolbot::ring::{Ring, RingAddress};
use coolbot::{BellAddress, Chain, ConsumerBell, RemoteBell, Source, SourceGuard};
use zenoh::Wait;

use super::wire::{Answer, Ask, bell_address, bell_at, host};
use crate::Error;
use crate::delivery::{DecodeFn, Via};
use crate::locks::lock;

/// The bytes of messages in one ring: 64 KiB (messages up to 16 KiB).
const RING_BYTES: usize = 64 << 10;

/// How long a consumer holds a ring message whose predecessor the stream has not
/// brought: a message sent on the key just before the ring was adopted is on its
/// way; longer, the link lost it.
const GATE_PATIENCE: Duration = Duration::from_secs(1);

/// How many times a ring handed over to a new consumer is emptied before it is
/// closed, while its producer goes on writing (`RingSource::hand_over`).
const HAND_OVER_ROUNDS: usize = 16;

/// The most rings an inlet keeps (one per outlet on its host; a queue connection
/// has N producers).
const MAX_RINGS: usize = 16;

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
    /// The inlet's output: which consumer it feeds.
    pub(crate) output: Box<dyn Feeding>,
    pub(crate) counters: Arc<crate::shm::Counters>,
    pub(crate) replier: crate::reply::Replier,
}

/// What the rings ask of an inlet's output (a `coolbot::port::DataOut` of any
/// packet type).
pub(crate) trait Feeding: Send + Sync {
    /// The doorbell of the one component the output feeds (None: it feeds none, or
    /// several).
    fn consumer(&self) -> Option<ConsumerBell>;
    /// Whether the output feeds the component whose doorbell is at `bell`.
    fn feeds(&self, bell: BellAddress) -> bool;
    /// Call `watcher` after each change of the output's connections.
    fn on_change(&self, watcher: Box<dyn Fn() + Send + Sync>);
}

impl<T: coolbot::Packet> Feeding for coolbot::port::DataOut<T> {
    fn consumer(&self) -> Option<ConsumerBell> {
        self.consumer_bell()
    }

    fn feeds(&self, bell: BellAddress) -> bool {
        coolbot::port::DataOut::feeds(self, bell)
    }

    fn on_change(&self, watcher: Box<dyn Fn() + Send + Sync>) {
        coolbot::port::DataOut::on_change(self, watcher);
    }
}

/// One ring of an inlet: the outlet it is for, the source on the consumer's bell,
/// and that bell, rung to look at the ring again.
struct Entry {
    /// The outlet (`node/name`) and its epoch.
    outlet: (String, u64),
    /// The outlet's process.
    pid: u32,
    source: Arc<RingSource>,
    /// The consumer's bell the source is on, and where the outlet rings it.
    bell: BellAddress,
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
    /// The rings of an inlet, which follow its output to a new consumer
    /// ([`InletRings::follow_consumer`]).
    pub(crate) fn new(parts: InletParts) -> Arc<InletRings> {
        let rings = Arc::new(InletRings {
            parts,
            rings: Mutex::new((false, Vec::new())),
        });
        let follow = Arc::downgrade(&rings);
        rings.parts.output.on_change(Box::new(move || {
            if let Some(rings) = follow.upgrade() {
                rings.follow_consumer();
            }
        }));
        rings
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
        let consumer = parts
            .output
            .consumer()
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
        // Read again under the lock a change's `follow_consumer` takes: a change since
        // the first reading would otherwise leave this ring on a bell no one looks at.
        if parts
            .output
            .consumer()
            .and_then(|consumer| consumer.address())
            != Some(bell)
        {
            return Err("the inlet's consumer changed".to_owned());
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
            bell,
            consumer: ring_again,
            _guard: guard,
        });
        Ok((address, bell))
    }

    /// The inlet's output changed its connections (`DataOut::on_change`): a ring on
    /// the bell of a component the output no longer feeds (a substitution moved the
    /// connection to its substitute) would wait for that component's thread, which
    /// may never take from it again. Such rings are handed over on this thread, and
    /// their outlets go back to the key, then ask again: the answer names the new
    /// consumer's bell. A ring whose consumer is still fed stays (its thread
    /// delivers to every input the output feeds).
    pub(crate) fn follow_consumer(&self) {
        let moved: Vec<Entry> = {
            // Under the lock `answer` adds a ring under: a ring it made on the old
            // consumer is seen here, or it saw the change itself.
            let mut rings = lock(&self.rings);
            let (kept, moved) = std::mem::take(&mut rings.1)
                .into_iter()
                .partition(|entry| self.parts.output.feeds(entry.bell));
            rings.1 = kept;
            moved
        };
        for entry in moved {
            entry.source.hand_over();
            tracing::debug!(key = %self.parts.key, outlet = %entry.outlet.0, "a ring's consumer changed: its outlet goes back to the key");
        }
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
        if self.take(&mut ring, &mut gate, Via::Ring) {
            self.writer.ring();
        }
    }
}

impl RingSource {
    /// Deliver what the gate lets through; a ring that breaks is closed. True if the
    /// outlet waits to be told of the room made.
    fn take(&self, ring: &mut Ring, gate: &mut Gate, via: Via) -> bool {
        let taken = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            ring.take(|bytes| {
                if !self.may_pass(gate, bytes) {
                    return false;
                }
                // Counted before the consumer can have it. A full `block` fifo is
                // handled by the delivery as for the key: the inlet's backlog.
                self.counters.ring_taken(1);
                (self.decode)(&[bytes], via);
                true
            })
        }));
        match taken {
            Ok(Ok(taken)) => taken.writer_waits,
            Ok(Err(error)) => {
                self.broke(ring, &Chain(&error).to_string());
                false
            }
            Err(panic) => {
                self.broke(
                    ring,
                    &format!("its delivery panicked: {}", coolbot::panic_message(&*panic)),
                );
                false
            }
        }
    }
}

impl RingSource {
    /// Its consumer changed: what it holds is delivered now, to where the output
    /// goes now, until it is empty (the outlet, not told of the room made, writes
    /// only what its producer sends meanwhile; [`HAND_OVER_ROUNDS`] at most); then it
    /// is closed (the outlet writes no more into it and goes back to the key), and
    /// what was written since the last look is delivered too. Emptying it before
    /// closing keeps the key's next message from overtaking the ring's: only those
    /// written between the last two looks can meet it, and one that comes after a
    /// newer one is dropped (counted missing: `Via::HandedOver`). The gate opens for
    /// it: a key message still on its way before the ring's first is dropped when it
    /// comes (counted missing), as when the gate's patience is over. A message whose
    /// write had begun before the close and ends after the last look is lost too,
    /// and counted missing when the key brings a later number.
    fn hand_over(&self) {
        if self.broken.swap(true, Ordering::Relaxed) {
            return;
        }
        let mut ring = lock(&self.ring);
        let mut gate = lock(&self.gate);
        *gate = Gate::Open;
        for _ in 0..HAND_OVER_ROUNDS {
            if !ring.has_messages() {
                break;
            }
            self.take(&mut ring, &mut gate, Via::Ring);
        }
        ring.close();
        self.take(&mut ring, &mut gate, Via::HandedOver);
        self.writer.ring();
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
