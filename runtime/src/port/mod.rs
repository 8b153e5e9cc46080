//! Typed port handles and the connections between them (paper 3.2, Figure 3).
//!
//! Every handle is cheap to clone (an `Arc` inside). Generated code creates one handle
//! per declared port, registers it with [`crate::PortSet`], and keeps clones for the
//! user's sections. The packet buffer of a connection lives at its input end; an
//! output keeps a snapshot of its connected inputs (`RwLock<Arc<[..]>>`, replaced only
//! on connect and disconnect), so sending takes no global lock and allocates nothing
//! beyond the clone of the packet for each extra consumer; a data output's component
//! thread sends to its own copy of the snapshot, without the lock (`sinks.rs`).
//!
//! Each delivery bumps the input's arrival counter and rings its component's
//! `Doorbell` (one three-state atomic beside the component's thread handle: a rung
//! bell means the component is already due to look, so a burst of arrivals costs one
//! wake-up and, per packet, one load of the flag).

use std::any::{Any, TypeId};
use std::collections::VecDeque;
use std::fmt;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, OnceLock, PoisonError, RwLock, Weak};
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, Sender, TrySendError};

use crate::monitor::Shared;
use crate::spec::OverflowPolicy;
use crate::wake::Doorbell;

mod delivery;
mod erased;
mod forward;
mod harness;
mod input;
mod merge;
mod output;
mod sinks;
mod slot;

pub(crate) use delivery::*;
pub use erased::*;
pub(crate) use forward::*;
pub(crate) use harness::*;
pub use input::*;
pub(crate) use merge::*;
pub use output::*;
pub(crate) use sinks::*;
pub(crate) use slot::*;

/// How long a producer waits on a full [`OverflowPolicy::Block`] fifo before the
/// packet is rejected and counted, unless the port sets its own timeout.
pub const DEFAULT_BLOCK_TIMEOUT: Duration = Duration::from_millis(100);

/// How many pull requests may wait at one output before further requests fail with
/// [`PullError::RequestQueueFull`].
pub const PULL_REQUEST_CAPACITY: usize = 64;

/// What a port carries: any clonable, sendable, shareable `'static` type.
pub trait Packet: Clone + Send + Sync + 'static {}

impl<T: Clone + Send + Sync + 'static> Packet for T {}

/// Why a pull did not return a packet.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PullError {
    /// The input is not connected to any producer.
    #[error("the input is not connected to a producer")]
    NotConnected,
    /// No answer arrived in time.
    #[error("no answer within {0:?}")]
    Timeout(Duration),
    /// The producer already has too many requests waiting.
    #[error("the producer has {PULL_REQUEST_CAPACITY} requests waiting")]
    RequestQueueFull,
}

fn lock<T>(mutex: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    // A panic while holding one of these short locks cannot leave the data half-updated
    // (every critical section is a single assignment or push), so poisoning is ignored.
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

fn read<T>(lock: &RwLock<T>) -> std::sync::RwLockReadGuard<'_, T> {
    lock.read().unwrap_or_else(PoisonError::into_inner)
}

fn write<T>(lock: &RwLock<T>) -> std::sync::RwLockWriteGuard<'_, T> {
    lock.write().unwrap_or_else(PoisonError::into_inner)
}

static NEXT_PORT_ID: AtomicUsize = AtomicUsize::new(1);

fn next_port_id() -> usize {
    NEXT_PORT_ID.fetch_add(1, Ordering::Relaxed)
}

/// The component a port belongs to: its doorbell, its monitor, the port's name.
pub(crate) struct Owner {
    pub(crate) bell: Arc<Doorbell>,
    pub(crate) shared: Weak<Shared>,
    pub(crate) port_name: &'static str,
    /// Temporal labeling of arrivals at this input, when its component measures its
    /// response time (`None`: no clock is read on delivery).
    pub(crate) label: Option<Arc<ArrivalLabel>>,
}

/// Temporal labeling (paper 3.6, "temporal labeling of input data"): when the oldest
/// packet at an input that no `on` transition has handled yet arrived. Stamped on
/// delivery (one clock read for the first packet after each handling, none for the
/// others), taken by the component's thread when an `on` transition of the input
/// fires: its response time runs from this instant to the end of that transition's
/// sections.
#[derive(Debug, Default)]
pub(crate) struct ArrivalLabel {
    /// Nanoseconds since `crate::time::epoch()`, plus one; 0: none.
    first: AtomicU64,
    /// The component's clock when it is virtual (else the real one is read).
    clock: OnceLock<Arc<crate::clock::VirtualClock>>,
}

impl ArrivalLabel {
    /// Read arrivals on `clock` (a component on a virtual clock).
    pub(crate) fn set_clock(&self, clock: &crate::clock::Clock) {
        if let Some(clock) = clock.as_virtual() {
            let _ = self.clock.set(Arc::clone(clock));
        }
    }

    /// A packet arrived: stamp it if it is the oldest not handled.
    #[inline]
    fn stamp(&self) {
        if self.first.load(Ordering::Relaxed) != 0 {
            return;
        }
        let now = match self.clock.get() {
            Some(clock) => clock.now(),
            None => Instant::now(),
        };
        let since = now.saturating_duration_since(crate::time::epoch());
        let nanos = u64::try_from(since.as_nanos())
            .unwrap_or(u64::MAX - 1)
            .saturating_add(1);
        let _ = self
            .first
            .compare_exchange(0, nanos, Ordering::Relaxed, Ordering::Relaxed);
    }

    /// The oldest arrival not handled, if any; the label is cleared.
    pub(crate) fn take(&self) -> Option<Instant> {
        match self.first.swap(0, Ordering::AcqRel) {
            0 => None,
            nanos => Some(crate::time::epoch() + Duration::from_nanos(nanos - 1)),
        }
    }
}

/// The kind-independent part of every input end.
pub(crate) struct InputCore {
    pub(crate) id: usize,
    pub(crate) owner: OnceLock<Owner>,
    /// The arrival count, in the bits from `count_shift` up: a last input keeps its
    /// slot's state in the bits below and counts its arrivals with the same atomic
    /// operation that stores a packet (`slot.rs`).
    arrivals: AtomicU64,
    count_shift: u32,
    overflows: AtomicU64,
    /// Of `overflows`, the packets a compound's exported input left this input out
    /// of (its redundant member stalled): they put the member out of step.
    left_behind: AtomicU64,
    pull_waiting: AtomicBool,
    /// Wakes a thread waiting in `pull`: created by the first `pull` on this input.
    pull_signal: OnceLock<(Sender<()>, Receiver<()>)>,
    /// The producers this input is connected to (for pull requests).
    sources: Mutex<Vec<Arc<OutputCore>>>,
}

impl crate::monitor::Losses for InputCore {
    fn overflows(&self) -> u64 {
        InputCore::overflows(self)
    }
}

impl InputCore {
    fn new() -> Arc<InputCore> {
        InputCore::counting_from(0, 0)
    }

    /// A core whose arrival count is kept in the bits of `arrivals` from
    /// `count_shift` up, the bits below starting as `low`.
    fn counting_from(count_shift: u32, low: u64) -> Arc<InputCore> {
        Arc::new(InputCore {
            id: next_port_id(),
            owner: OnceLock::new(),
            arrivals: AtomicU64::new(low),
            count_shift,
            overflows: AtomicU64::new(0),
            left_behind: AtomicU64::new(0),
            pull_waiting: AtomicBool::new(false),
            pull_signal: OnceLock::new(),
            sources: Mutex::new(Vec::new()),
        })
    }

    /// The doorbell of the component this input is a port of, once it is in a system.
    pub(crate) fn bell(&self) -> Option<Arc<Doorbell>> {
        self.owner.get().map(|owner| Arc::clone(&owner.bell))
    }

    /// A packet or event was stored: count it, wake the component and any puller.
    #[inline]
    fn arrived(&self) {
        // (A last input's slot counts its own arrivals: `arrived_by`. Were this called
        // on its core, the bits below the count would still be left alone.)
        debug_assert_eq!(self.count_shift, 0);
        // `SeqCst`: part of the doorbell's no-lost-wake-up argument (`Doorbell`).
        self.arrived_by(|arrivals| arrivals.fetch_add(1 << self.count_shift, Ordering::SeqCst));
    }

    /// A packet is stored and counted by `count`, a `SeqCst` read-modify-write of
    /// the arrival counter that adds one to the count (a last input's publish: it
    /// stores the packet too); then the component and any puller are woken.
    #[inline]
    fn arrived_by<R>(&self, count: impl FnOnce(&AtomicU64) -> R) -> R {
        let owner = self.owner.get();
        // Stamp before counting: the count publishes the stamp, so a component that
        // sees the arrival also sees its time (at worst a response goes unmeasured).
        if let Some(label) = owner.and_then(|owner| owner.label.as_ref()) {
            label.stamp();
        }
        let counted = count(&self.arrivals);
        if let Some(owner) = owner {
            owner.bell.ring();
        }
        if self.pull_waiting.load(Ordering::Acquire)
            && let Some(signal) = self.pull_signal.get()
        {
            let _ = signal.0.try_send(());
        }
        counted
    }

    /// `lost` packets were lost at this input: count them and announce it.
    #[cold]
    fn overflowed(&self, lost: u64) {
        // Saturating: a count from the network (a bridge's) may be anything.
        let before = self
            .overflows
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
                Some(n.saturating_add(lost))
            })
            .unwrap_or_else(|n| n);
        let total = before.saturating_add(lost);
        if let Some(owner) = self.owner.get()
            && let Some(shared) = owner.shared.upgrade()
        {
            shared.announce_overflow(owner.port_name, lost, total);
        }
    }

    /// How many packets or events arrived (only compared, to see new ones).
    pub(crate) fn arrivals(&self) -> u64 {
        self.arrivals.load(Ordering::SeqCst) >> self.count_shift
    }

    pub(crate) fn overflows(&self) -> u64 {
        self.overflows.load(Ordering::Acquire)
    }

    pub(crate) fn left_behind(&self) -> u64 {
        self.left_behind.load(Ordering::Acquire)
    }

    pub(crate) fn add_source(&self, source: Arc<OutputCore>) {
        lock(&self.sources).push(source);
    }

    pub(crate) fn remove_source(&self, source_id: usize) {
        lock(&self.sources).retain(|source| source.id != source_id);
    }

    fn request(&self) -> Result<(), PullError> {
        let sources = lock(&self.sources);
        if sources.is_empty() {
            return Err(PullError::NotConnected);
        }
        for source in sources.iter() {
            source.request(self.id)?;
        }
        Ok(())
    }

    /// Request a packet and wait until `ready` finds one, up to `timeout`.
    fn pull_with<R>(
        &self,
        timeout: Duration,
        mut ready: impl FnMut() -> Option<R>,
    ) -> Result<R, PullError> {
        let deadline = crate::time::later(Instant::now(), timeout);
        let signal = self
            .pull_signal
            .get_or_init(|| crossbeam_channel::bounded(1));
        self.pull_waiting.store(true, Ordering::Release);
        while signal.1.try_recv().is_ok() {}
        let result = self.request().and_then(|()| {
            loop {
                if let Some(packet) = ready() {
                    break Ok(packet);
                }
                if signal.1.recv_deadline(deadline).is_err() {
                    break ready().ok_or(PullError::Timeout(timeout));
                }
            }
        });
        self.pull_waiting.store(false, Ordering::Release);
        result
    }
}

/// The kind-independent part of every output end.
pub(crate) struct OutputCore {
    pub(crate) id: usize,
    pub(crate) owner: OnceLock<Owner>,
    /// The pull-request queue: created by [`OutputCore::accept_pulls`] for outputs
    /// declared `pull` only; a request to any other output is dropped.
    requests: OnceLock<(Sender<usize>, Receiver<usize>)>,
    /// While the producer answers a pull request: the requesting input's id (0: none).
    answering_to: AtomicUsize,
    /// The thread that sends on this output without the sinks' lock (its token, see
    /// [`OutputCore::claim_sends`]; 0: none).
    sender: AtomicU64,
    /// Where pull requests go instead of this output's own queue: a compound's
    /// exported port passes them on to the port it stands for (see [`PullRoute`]).
    route: Mutex<Option<PullRoute>>,
}

/// Where a compound's exported port passes the pull requests it receives.
#[derive(Clone)]
pub(crate) enum PullRoute {
    /// The relay of an exported input, feeding the instance's input: a request from
    /// the instance becomes a request of the compound's input to its producers.
    Input(Arc<InputCore>),
    /// The compound's exported output: a request from one of its consumers goes to
    /// the instance output it follows, on behalf of the same consumer (the answer
    /// reaches that consumer only, through the forwarding).
    Output(Arc<OutputCore>),
    /// A harness's feeder (`crate::harness`): the request is answered at once, on
    /// the requester's thread, by sending the next canned answer (if any).
    Answer(Arc<dyn Fn() + Send + Sync>),
}

impl OutputCore {
    fn new() -> Arc<OutputCore> {
        Arc::new(OutputCore {
            id: next_port_id(),
            owner: OnceLock::new(),
            requests: OnceLock::new(),
            answering_to: AtomicUsize::new(0),
            sender: AtomicU64::new(0),
            route: Mutex::new(None),
        })
    }

    /// Pass the pull requests this output receives on along `route` from now on,
    /// with those already waiting in its own queue (an exported port following the
    /// instance port it stands for).
    pub(crate) fn set_route(&self, route: PullRoute) {
        *lock(&self.route) = Some(route.clone());
        while let Some(input_id) = self.next_request() {
            let _ = route.request(input_id);
        }
    }

    /// Give this output its pull-request queue (it is declared `pull`).
    pub(crate) fn accept_pulls(&self) {
        self.requests
            .get_or_init(|| crossbeam_channel::bounded(PULL_REQUEST_CAPACITY));
    }

    fn request(&self, input_id: usize) -> Result<(), PullError> {
        let route = lock(&self.route).clone();
        if let Some(route) = route {
            return route.request(input_id);
        }
        let Some(requests) = self.requests.get() else {
            // Not a pull output: nobody answers, as if the producer dropped it.
            return Ok(());
        };
        match requests.0.try_send(input_id) {
            Ok(()) => {
                if let Some(owner) = self.owner.get() {
                    owner.bell.ring_strong();
                }
                Ok(())
            }
            Err(TrySendError::Full(_)) => Err(PullError::RequestQueueFull),
            Err(TrySendError::Disconnected(_)) => Err(PullError::NotConnected),
        }
    }

    /// The next waiting pull request (the requesting input's id).
    pub(crate) fn next_request(&self) -> Option<usize> {
        self.requests.get()?.1.try_recv().ok()
    }

    /// Whether pull requests are waiting.
    pub(crate) fn has_requests(&self) -> bool {
        self.requests
            .get()
            .is_some_and(|requests| !requests.1.is_empty())
    }

    pub(crate) fn begin_answer(&self, input_id: usize) {
        self.answering_to.store(input_id, Ordering::Relaxed);
    }

    pub(crate) fn end_answer(&self) {
        self.answering_to.store(0, Ordering::Relaxed);
    }
}

/// A packet on its way to an input end: owned when one input gets it, shared (one
/// allocation, no copy) when several do and copying it would cost more than sharing
/// ([`shares`]). A consumer that takes a shared packet by value copies it only if
/// another consumer still holds it (the last one takes the original).
pub(crate) enum Parcel<T> {
    /// The only input that gets this packet.
    Owned(T),
    /// One of several inputs that get this packet.
    Shared(Arc<T>),
}

impl<T: Packet> Parcel<T> {
    /// The packet, read in place.
    #[inline]
    pub(crate) fn get(&self) -> &T {
        match self {
            Parcel::Owned(packet) => packet,
            Parcel::Shared(packet) => packet,
        }
    }

    /// The packet by value: copied only if another input still holds it.
    #[inline]
    pub(crate) fn into_owned(self) -> T {
        match self {
            Parcel::Owned(packet) => packet,
            Parcel::Shared(packet) => Arc::try_unwrap(packet).unwrap_or_else(|p| (*p).clone()),
        }
    }

    /// The packet behind a shared pointer (no copy).
    #[inline]
    pub(crate) fn into_shared(self) -> Arc<T> {
        match self {
            Parcel::Owned(packet) => Arc::new(packet),
            Parcel::Shared(packet) => packet,
        }
    }
}

impl<T> Clone for Parcel<T>
where
    T: Packet,
{
    fn clone(&self) -> Self {
        match self {
            Parcel::Owned(packet) => Parcel::Owned(packet.clone()),
            Parcel::Shared(packet) => Parcel::Shared(Arc::clone(packet)),
        }
    }
}

/// Whether a packet sent to several inputs is shared rather than copied for each: when
/// its type owns memory elsewhere (it has drop glue: a `Vec`, a `String`, a `Box`), or
/// is larger than 256 bytes. A small plain-data packet is cheaper to copy than to
/// allocate once and count references to.
#[inline]
pub(crate) const fn shares<T>() -> bool {
    std::mem::needs_drop::<T>() || size_of::<T>() > 256
}

/// Move the pull requests waiting at `from` to `to` (an instance's stand-in now
/// answers its consumers): returns how many moved, and how many `to` refused (its
/// request queue full; their pullers time out).
pub(crate) fn move_requests(from: &ErasedOutput, to: &ErasedOutput) -> (u64, u64) {
    let (mut moved, mut refused) = (0, 0);
    while let Some(input_id) = from.core.next_request() {
        match to.core.request(input_id) {
            Ok(()) => moved += 1,
            Err(_) => refused += 1,
        }
    }
    (moved, refused)
}

impl PullRoute {
    fn request(&self, input_id: usize) -> Result<(), PullError> {
        match self {
            PullRoute::Input(input) => input.request(),
            PullRoute::Output(output) => output.request(input_id),
            PullRoute::Answer(answer) => {
                answer();
                Ok(())
            }
        }
    }
}
