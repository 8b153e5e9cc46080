//! The output ends: tick, data and poster outputs.

use super::*;

/// A tick output: emits event packets to every connected tick input.
#[derive(Clone)]
pub struct TickOut {
    pub(super) inner: Arc<TickOutInner>,
}

pub(crate) struct TickOutInner {
    pub(super) core: Arc<OutputCore>,
    pub(super) targets: RwLock<Arc<[TickTarget]>>,
}

/// Where a tick output's events go: a tick input, or a compound's exported tick
/// output that passes them on to its own inputs.
#[derive(Clone)]
pub(super) enum TickTarget {
    Input(Arc<TickInner>),
    Forward { id: usize, to: Arc<TickOutInner> },
}

impl TickTarget {
    /// The input's id, or the forwarding's.
    pub(super) fn id(&self) -> usize {
        match self {
            TickTarget::Input(input) => input.core.id,
            TickTarget::Forward { id, .. } => *id,
        }
    }

    /// Whether input `id`'s pull request is answered through this target.
    fn answers(&self, id: usize) -> bool {
        match self {
            TickTarget::Input(input) => input.core.id == id,
            TickTarget::Forward { to, .. } => read(&to.targets).iter().any(|t| t.answers(id)),
        }
    }
}

impl TickOutInner {
    /// One event to every target, or only along the way to input `answering` (not 0).
    fn emit(&self, answering: usize) {
        for target in read(&self.targets).iter() {
            if answering != 0 && !target.answers(answering) {
                continue;
            }
            match target {
                TickTarget::Input(input) => input.tick(),
                TickTarget::Forward { to, .. } => to.emit(answering),
            }
        }
    }
}

impl TickOut {
    /// A new, unconnected tick output.
    pub fn new() -> TickOut {
        TickOut {
            inner: Arc::new(TickOutInner {
                core: OutputCore::new(),
                targets: RwLock::new(Arc::from([])),
            }),
        }
    }

    /// Emit one event to every connected input (only the requester while answering a
    /// pull request).
    pub fn emit(&self) {
        let answering = self.inner.core.answering_to.load(Ordering::Relaxed);
        self.inner.emit(answering);
    }
}

impl Default for TickOut {
    fn default() -> Self {
        TickOut::new()
    }
}

/// A data output: sends packets to connected last, fifo and ufifo inputs.
pub struct DataOut<T> {
    pub(super) inner: Arc<DataOutInner<T>>,
}

impl<T> Clone for DataOut<T> {
    fn clone(&self) -> Self {
        DataOut {
            inner: Arc::clone(&self.inner),
        }
    }
}

pub(crate) struct DataOutInner<T> {
    pub(super) core: Arc<OutputCore>,
    pub(super) sinks: Sinks<T>,
}

impl<T: Packet> DataOut<T> {
    /// A new, unconnected data output.
    pub fn new() -> DataOut<T> {
        DataOut {
            inner: Arc::new(DataOutInner {
                core: OutputCore::new(),
                sinks: Sinks::new(),
            }),
        }
    }

    /// Send a packet to every connected input. One input gets the packet itself;
    /// several share it (one allocation, no copy) when it owns memory or is large
    /// (see `docs/runtime.md`, "Fan-out"), else each gets a copy. While the
    /// component answers a pull request, only the requesting input gets it.
    #[inline]
    pub fn send(&self, packet: T) {
        let answering = self.inner.core.answering_to.load(Ordering::Relaxed);
        if answering != 0 {
            dispatch_answer(&self.inner.sinks.read(), Parcel::Owned(packet), answering);
            return;
        }
        self.inner
            .sinks
            .send(&self.inner.core, Parcel::Owned(packet));
    }

    /// Send a packet that may already be shared (a compound's relay passing on what
    /// arrived at its exported input), as [`DataOut::send`] does.
    pub(crate) fn send_parcel(&self, packet: Parcel<T>) {
        self.inner.sinks.send(&self.inner.core, packet);
    }

    /// How many inputs are connected.
    pub fn consumers(&self) -> usize {
        self.inner.sinks.read().len()
    }

    /// Whether a [`DataOut::send`] now would wait for room: a connected fifo whose
    /// policy is `Block` is full (directly, behind a converter, or behind a
    /// compound's exported port). A sender that must not wait (a network inlet,
    /// which delivers on a thread shared by its whole session) hands the packet to a
    /// thread of its own instead.
    pub fn would_wait(&self) -> bool {
        would_wait(&self.inner.sinks.read())
    }

    /// Call `watcher` after each change of this output's connections from now on (a
    /// connection made, removed, or moved to another input, as a substitution does),
    /// on the thread that made the change, once the output sends to its new inputs,
    /// with no lock of the output held: what keeps a view of where the output goes
    /// (its [`DataOut::consumer_bell`]) looks again. A watcher that panics is logged
    /// and the change goes on. Watchers stay as long as the output: one that holds
    /// the output itself keeps it alive (hold what it needs weakly).
    pub fn on_change(&self, watcher: impl Fn() + Send + Sync + 'static) {
        self.inner.sinks.watch(Arc::new(watcher));
    }

    /// The doorbell of the component this output feeds, if it feeds exactly one input
    /// directly (no converter, no compound's exported port between them): what
    /// another process on this host rings after it leaves packets for a
    /// [`Source`](crate::Source) that sends them on this output.
    pub fn consumer_bell(&self) -> Option<crate::ConsumerBell> {
        match &self.inner.sinks.read()[..] {
            [sink] => sink
                .target
                .input_bell()
                .map(|bell| crate::ConsumerBell { bell }),
            _ => None,
        }
    }

    /// Whether one of the inputs this output feeds directly belongs to the component
    /// whose doorbell is at `bell` (see [`DataOut::consumer_bell`]).
    pub fn feeds(&self, bell: crate::BellAddress) -> bool {
        self.inner.sinks.read().iter().any(|sink| {
            sink.target
                .input_bell()
                .is_some_and(|own| own.address() == Some(bell))
        })
    }
}

impl<T: Packet> Default for DataOut<T> {
    fn default() -> Self {
        DataOut::new()
    }
}

/// A poster output: posts a value that connected poster inputs read.
pub struct PosterOut<T> {
    pub(super) inner: Arc<PosterOutInner<T>>,
}

impl<T> Clone for PosterOut<T> {
    fn clone(&self) -> Self {
        PosterOut {
            inner: Arc::clone(&self.inner),
        }
    }
}

pub(crate) struct PosterOutInner<T> {
    pub(super) core: Arc<OutputCore>,
    /// The posted value and its sequence number (1 for the first post), together
    /// under one short lock: a post takes it once, a reader once.
    pub(super) slot: Mutex<(Option<T>, u64)>,
    pub(super) readers: RwLock<Arc<[Arc<InputCore>]>>,
    /// Recorders' taps: each post is delivered to them too (see `tap_data`).
    pub(super) taps: RwLock<Arc<[Sink<T>]>>,
    /// Whether `taps` is not empty: a post without taps reads one flag, not the list.
    pub(super) tapped: AtomicBool,
}

impl<T> PosterOutInner<T> {
    /// `f` applied to the posted value and its sequence number, if that is above
    /// `seen` (always when `seen` is `None`).
    fn with_newer<R>(
        &self,
        seen: Option<u64>,
        f: impl FnOnce(&Option<T>) -> R,
    ) -> Option<(R, u64)> {
        let slot = lock(&self.slot);
        if seen.is_some_and(|seen| slot.1 <= seen) {
            return None;
        }
        Some((f(&slot.0), slot.1))
    }
}

impl<T: Packet> PosterSource<T> for PosterOutInner<T> {
    fn seq(&self) -> u64 {
        lock(&self.slot).1
    }

    fn read_newer(&self, seen: Option<u64>) -> Option<(Option<T>, u64)> {
        self.with_newer(seen, Option::clone)
    }
}

pub(super) struct ConvertedPoster<A, B> {
    pub(super) convert: Arc<dyn Fn(&A) -> B + Send + Sync>,
    pub(super) source: Arc<PosterOutInner<A>>,
}

impl<A: Packet, B: Packet> PosterSource<B> for ConvertedPoster<A, B> {
    fn seq(&self) -> u64 {
        self.source.seq()
    }

    fn read_newer(&self, seen: Option<u64>) -> Option<(Option<B>, u64)> {
        self.source.with_newer(seen, |value| {
            value.as_ref().map(|value| (self.convert)(value))
        })
    }
}

impl<T: Packet> PosterOut<T> {
    /// A new poster output with nothing posted.
    pub fn new() -> PosterOut<T> {
        PosterOut {
            inner: Arc::new(PosterOutInner {
                core: OutputCore::new(),
                slot: Mutex::new((None, 0)),
                readers: RwLock::new(Arc::from([])),
                taps: RwLock::new(Arc::from([])),
                tapped: AtomicBool::new(false),
            }),
        }
    }

    /// Post a value: connected poster inputs read it from now on and are woken.
    pub fn post(&self, packet: T) {
        if self.inner.tapped.load(Ordering::Acquire) {
            for tap in read(&self.inner.taps).iter() {
                tap.target.deliver(Parcel::Owned(packet.clone()));
            }
        }
        {
            let mut slot = lock(&self.inner.slot);
            slot.0 = Some(packet);
            slot.1 += 1;
        }
        for reader in read(&self.inner.readers).iter() {
            reader.arrived();
        }
    }

    /// The value posted now.
    pub fn posted(&self) -> Option<T> {
        lock(&self.inner.slot).0.clone()
    }
}

impl<T: Packet> Default for PosterOut<T> {
    fn default() -> Self {
        PosterOut::new()
    }
}
