//! Typed port handles and the connections between them (paper 3.2, Figure 3).
//!
//! Every handle is cheap to clone (an `Arc` inside). Generated code creates one handle
//! per declared port, registers it with [`crate::PortSet`], and keeps clones for the
//! user's sections. The packet buffer of a connection lives at its input end; an
//! output keeps a snapshot of its connected inputs (`RwLock<Arc<[..]>>`, replaced only
//! on connect and disconnect), so sending takes no global lock and allocates nothing
//! beyond the clone of the packet for each extra consumer.
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
    arrivals: AtomicU64,
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
        Arc::new(InputCore {
            id: next_port_id(),
            owner: OnceLock::new(),
            arrivals: AtomicU64::new(0),
            overflows: AtomicU64::new(0),
            left_behind: AtomicU64::new(0),
            pull_waiting: AtomicBool::new(false),
            pull_signal: OnceLock::new(),
            sources: Mutex::new(Vec::new()),
        })
    }

    /// A packet or event was stored: count it, wake the component and any puller.
    #[inline]
    fn arrived(&self) {
        let owner = self.owner.get();
        // Stamp before counting: the count publishes the stamp, so a component that
        // sees the arrival also sees its time (at worst a response goes unmeasured).
        if let Some(label) = owner.and_then(|owner| owner.label.as_ref()) {
            label.stamp();
        }
        // `SeqCst`: part of the doorbell's no-lost-wake-up argument (`Doorbell`).
        self.arrivals.fetch_add(1, Ordering::SeqCst);
        if let Some(owner) = owner {
            owner.bell.ring();
        }
        if self.pull_waiting.load(Ordering::Acquire)
            && let Some(signal) = self.pull_signal.get()
        {
            let _ = signal.0.try_send(());
        }
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

    pub(crate) fn arrivals(&self) -> u64 {
        self.arrivals.load(Ordering::SeqCst)
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

// ---------------------------------------------------------------------------------
// What a harness (`crate::harness`) needs of the ports.

/// The packets an output sent to a harness's collector, in order.
pub(crate) struct Collected<T> {
    packets: Mutex<Vec<T>>,
}

impl<T> Default for Collected<T> {
    fn default() -> Self {
        Collected {
            packets: Mutex::new(Vec::new()),
        }
    }
}

impl<T: Packet> Collected<T> {
    /// The packets collected since the last call.
    pub(crate) fn take(&self) -> Vec<T> {
        std::mem::take(&mut *lock(&self.packets))
    }
}

impl<T: Packet> Deliver<T> for Collected<T> {
    fn deliver(&self, packet: Parcel<T>) {
        lock(&self.packets).push(packet.into_owned());
    }
}

/// The input end of `input` that feeds it (see `InputEnd::feeder`), not connected.
pub(crate) fn feeder_of(input: &ErasedInput) -> ErasedOutput {
    input.end.feeder()
}

/// The collector of `output` (see `OutputEnd::collector`).
pub(crate) fn collector_of(output: &ErasedOutput) -> Option<(usize, Arc<dyn Any + Send + Sync>)> {
    output.end.collector(output)
}

/// The typed data output behind `output`, if it is a `DataOut<T>`.
pub(crate) fn data_out<T: Packet>(output: &ErasedOutput) -> Option<DataOut<T>> {
    output_as::<DataOutInner<T>>(output).map(|inner| DataOut { inner })
}

/// The typed poster output behind `output`, if it is a `PosterOut<T>`.
pub(crate) fn poster_out<T: Packet>(output: &ErasedOutput) -> Option<PosterOut<T>> {
    output_as::<PosterOutInner<T>>(output).map(|inner| PosterOut { inner })
}

/// The tick output behind `output`, if it is one.
pub(crate) fn tick_out(output: &ErasedOutput) -> Option<TickOut> {
    output_as::<TickOutInner>(output).map(|inner| TickOut { inner })
}

/// Pull requests to `output` are answered by `answer`, called at once on the
/// requester's thread (a harness's canned answers).
pub(crate) fn answer_pulls_with(output: &ErasedOutput, answer: Arc<dyn Fn() + Send + Sync>) {
    output.core.set_route(PullRoute::Answer(answer));
}

/// A pull request to `output` on behalf of the input (or tap) with id `input_id`.
pub(crate) fn request_on_behalf(output: &ErasedOutput, input_id: usize) -> Result<(), PullError> {
    output.core.request(input_id)
}

/// Something that accepts packets of type `T`: an input end, a converter in front of
/// one, a compound's exported output, or a recorder's tap.
pub(crate) trait Deliver<T>: Send + Sync {
    fn deliver(&self, packet: Parcel<T>);

    /// Whether the pull request of input `id` is answered through this sink (a
    /// compound's exported output whose consumers include that input).
    fn answers(&self, _id: usize) -> bool {
        false
    }

    /// Deliver an answer to the pull request of input `id`, which this sink answers.
    fn deliver_answer(&self, packet: Parcel<T>, _id: usize) {
        self.deliver(packet);
    }

    /// `count` packets meant for this sink will never come (a redundant group's
    /// merged stream could not carry them across a failover): an input counts them
    /// as lost (an overflow, with its `MonitorEvent::Overflow`); a sink passing
    /// packets on passes the count on.
    fn lost(&self, _count: u64) {}
}

/// A converter on a connection, in front of the input end.
struct Converted<A, B> {
    convert: Arc<dyn Fn(&A) -> B + Send + Sync>,
    target: Arc<dyn Deliver<B>>,
}

impl<A: Packet, B: Packet> Deliver<A> for Converted<A, B> {
    fn deliver(&self, packet: Parcel<A>) {
        self.target
            .deliver(Parcel::Owned((self.convert)(packet.get())));
    }

    fn lost(&self, count: u64) {
        self.target.lost(count);
    }
}

/// One connected input of a data output.
struct Sink<T> {
    input_id: usize,
    target: Arc<dyn Deliver<T>>,
}

impl<T> Clone for Sink<T> {
    fn clone(&self) -> Self {
        Sink {
            input_id: self.input_id,
            target: Arc::clone(&self.target),
        }
    }
}

/// Deliver `packet` to every sink: owned to a single one, shared among several when
/// [`shares`] says so, else copied for each but the last.
#[inline]
fn dispatch<T: Packet>(sinks: &[Sink<T>], packet: Parcel<T>) {
    let Some((last, rest)) = sinks.split_last() else {
        return;
    };
    if rest.is_empty() {
        last.target.deliver(packet);
    } else if shares::<T>() {
        let shared = packet.into_shared();
        for sink in rest {
            sink.target.deliver(Parcel::Shared(Arc::clone(&shared)));
        }
        last.target.deliver(Parcel::Shared(shared));
    } else {
        for sink in rest {
            sink.target.deliver(packet.clone());
        }
        last.target.deliver(packet);
    }
}

/// Deliver an answer to input `id`'s pull request to the one sink that leads there
/// (the input itself, or an exported output in front of it). False if none does.
fn dispatch_answer<T: Packet>(sinks: &[Sink<T>], packet: Parcel<T>, id: usize) -> bool {
    if let Some(sink) = sinks.iter().find(|sink| sink.input_id == id) {
        sink.target.deliver(packet);
        true
    } else if let Some(sink) = sinks.iter().find(|sink| sink.target.answers(id)) {
        sink.target.deliver_answer(packet, id);
        true
    } else {
        false
    }
}

// ---------------------------------------------------------------------------------
// Input ends.

/// A tick input: counts event packets.
#[derive(Clone)]
pub struct TickIn {
    inner: Arc<TickInner>,
}

pub(crate) struct TickInner {
    core: Arc<InputCore>,
    count: AtomicU64,
}

impl TickInner {
    fn tick(&self) {
        self.count.fetch_add(1, Ordering::AcqRel);
        self.core.arrived();
    }
}

impl TickIn {
    /// A new, unconnected tick input.
    pub fn new() -> TickIn {
        TickIn {
            inner: Arc::new(TickInner {
                core: InputCore::new(),
                count: AtomicU64::new(0),
            }),
        }
    }

    /// The number of events since the last `take`, resetting it to zero.
    pub fn take(&self) -> u64 {
        self.inner.count.swap(0, Ordering::AcqRel)
    }

    /// Whether events are waiting to be taken.
    pub fn pending(&self) -> bool {
        self.inner.count.load(Ordering::Acquire) > 0
    }

    /// Ask the producer for an event (pull model); it arrives as a normal event.
    pub fn request(&self) -> Result<(), PullError> {
        self.inner.core.request()
    }

    /// Request an event and wait for it: returns the events taken.
    pub fn pull(&self, timeout: Duration) -> Result<u64, PullError> {
        self.inner.core.pull_with(timeout, || match self.take() {
            0 => None,
            n => Some(n),
        })
    }

    /// Events lost at this input (always zero: ticks are counted, never lost).
    pub fn overflows(&self) -> u64 {
        self.inner.core.overflows()
    }
}

impl Default for TickIn {
    fn default() -> Self {
        TickIn::new()
    }
}

/// A fifo input: a bounded queue at the input end, with an [`OverflowPolicy`].
pub struct FifoIn<T> {
    inner: Arc<FifoInner<T>>,
}

impl<T> Clone for FifoIn<T> {
    fn clone(&self) -> Self {
        FifoIn {
            inner: Arc::clone(&self.inner),
        }
    }
}

pub(crate) struct FifoInner<T> {
    core: Arc<InputCore>,
    sender: Sender<Parcel<T>>,
    receiver: Receiver<Parcel<T>>,
    policy: OverflowPolicy,
    capacity: usize,
    block_timeout: Duration,
}

impl<T: Packet> Deliver<T> for FifoInner<T> {
    fn lost(&self, count: u64) {
        if count > 0 {
            self.core.overflowed(count);
        }
    }

    #[inline]
    fn deliver(&self, packet: Parcel<T>) {
        match self.sender.try_send(packet) {
            Ok(()) => {}
            Err(TrySendError::Full(packet)) => self.deliver_full(packet),
            // The receiver lives in `self`, so the channel cannot be disconnected.
            Err(TrySendError::Disconnected(_)) => return,
        }
        self.core.arrived();
    }
}

impl<T: Packet> FifoInner<T> {
    #[cold]
    fn deliver_full(&self, packet: Parcel<T>) {
        match self.policy {
            OverflowPolicy::Reject => self.core.overflowed(1),
            OverflowPolicy::DropOldest => {
                let mut packet = packet;
                loop {
                    if self.receiver.try_recv().is_ok() {
                        self.core.overflowed(1);
                    }
                    match self.sender.try_send(packet) {
                        Ok(()) => break,
                        Err(TrySendError::Full(back)) => packet = back,
                        Err(TrySendError::Disconnected(_)) => break,
                    }
                }
            }
            OverflowPolicy::Block => {
                if self
                    .sender
                    .send_timeout(packet, self.block_timeout)
                    .is_err()
                {
                    self.core.overflowed(1);
                }
            }
        }
    }
}

impl<T: Packet> FifoIn<T> {
    /// A fifo of `capacity` packets (at least 1) with `policy` when full.
    pub fn new(capacity: usize, policy: OverflowPolicy) -> FifoIn<T> {
        FifoIn::with_block_timeout(capacity, policy, DEFAULT_BLOCK_TIMEOUT)
    }

    /// Like [`FifoIn::new`], with the producer's wait for [`OverflowPolicy::Block`].
    pub fn with_block_timeout(
        capacity: usize,
        policy: OverflowPolicy,
        block_timeout: Duration,
    ) -> FifoIn<T> {
        let capacity = capacity.max(1);
        let (sender, receiver) = crossbeam_channel::bounded(capacity);
        FifoIn {
            inner: Arc::new(FifoInner {
                core: InputCore::new(),
                sender,
                receiver,
                policy,
                capacity,
                block_timeout,
            }),
        }
    }

    /// The oldest queued packet. A packet its producer sent to several inputs is
    /// shared among them: taking it by value copies it if another input still holds
    /// it ([`FifoIn::recv_shared`] never copies).
    pub fn recv(&self) -> Option<T> {
        self.inner.receiver.try_recv().ok().map(Parcel::into_owned)
    }

    /// The oldest queued packet, behind a shared pointer: a packet sent to several
    /// inputs is not copied for this one.
    pub fn recv_shared(&self) -> Option<Arc<T>> {
        self.inner.receiver.try_recv().ok().map(Parcel::into_shared)
    }

    /// Every packet queued now, oldest first.
    pub fn drain(&self) -> impl Iterator<Item = T> + '_ {
        self.inner.receiver.try_iter().map(Parcel::into_owned)
    }

    /// The oldest queued packet as it was delivered (owned or shared).
    pub(crate) fn recv_parcel(&self) -> Option<Parcel<T>> {
        self.inner.receiver.try_recv().ok()
    }

    /// Wait up to `timeout` for a packet. This blocks the calling thread: meant for
    /// threads outside the system (tests, tools), not for sections, which should
    /// react to arrivals with `on` transitions instead.
    pub fn recv_timeout(&self, timeout: Duration) -> Option<T> {
        self.inner
            .receiver
            .recv_timeout(timeout)
            .ok()
            .map(Parcel::into_owned)
    }

    /// The number of queued packets.
    pub fn len(&self) -> usize {
        self.inner.receiver.len()
    }

    /// Whether the queue is empty.
    pub fn is_empty(&self) -> bool {
        self.inner.receiver.is_empty()
    }

    /// The queue's capacity.
    pub fn capacity(&self) -> usize {
        self.inner.capacity
    }

    /// The overflow policy.
    pub fn policy(&self) -> OverflowPolicy {
        self.inner.policy
    }

    /// Packets lost at this input so far.
    pub fn overflows(&self) -> u64 {
        self.inner.core.overflows()
    }

    /// Ask the producer(s) for a packet (pull model); it arrives as a normal packet.
    pub fn request(&self) -> Result<(), PullError> {
        self.inner.core.request()
    }

    /// Request a packet and wait for the next queued one.
    pub fn pull(&self, timeout: Duration) -> Result<T, PullError> {
        self.inner.core.pull_with(timeout, || self.recv())
    }
}

/// A ufifo input: a queue that grows by its initial size when full, up to an optional
/// cap; packets beyond the cap are rejected and counted.
pub struct UfifoIn<T> {
    inner: Arc<UfifoInner<T>>,
}

impl<T> Clone for UfifoIn<T> {
    fn clone(&self) -> Self {
        UfifoIn {
            inner: Arc::clone(&self.inner),
        }
    }
}

pub(crate) struct UfifoInner<T> {
    core: Arc<InputCore>,
    queue: Mutex<UfifoQueue<T>>,
    step: usize,
    max: Option<usize>,
}

struct UfifoQueue<T> {
    packets: VecDeque<Parcel<T>>,
    capacity: usize,
    growths: u64,
}

impl<T: Packet> Deliver<T> for UfifoInner<T> {
    fn lost(&self, count: u64) {
        if count > 0 {
            self.core.overflowed(count);
        }
    }

    fn deliver(&self, packet: Parcel<T>) {
        let stored = {
            let mut queue = lock(&self.queue);
            if queue.packets.len() >= queue.capacity {
                let grown = queue.capacity.saturating_add(self.step);
                let grown = self.max.map_or(grown, |max| grown.min(max));
                if grown > queue.capacity {
                    queue.capacity = grown;
                    queue.growths += 1;
                }
            }
            if queue.packets.len() < queue.capacity {
                queue.packets.push_back(packet);
                true
            } else {
                false
            }
        };
        if stored {
            self.core.arrived();
        } else {
            self.core.overflowed(1);
        }
    }
}

impl<T: Packet> UfifoIn<T> {
    /// A ufifo starting at `initial` packets (at least 1), growing by `initial` when
    /// full, never beyond `max` if given.
    pub fn new(initial: usize, max: Option<usize>) -> UfifoIn<T> {
        let step = initial.max(1);
        let capacity = max.map_or(step, |max| step.min(max.max(1)));
        UfifoIn {
            inner: Arc::new(UfifoInner {
                core: InputCore::new(),
                queue: Mutex::new(UfifoQueue {
                    packets: VecDeque::with_capacity(capacity),
                    capacity,
                    growths: 0,
                }),
                step,
                max,
            }),
        }
    }

    /// The oldest queued packet (copied if another input still holds it, as for
    /// [`FifoIn::recv`]).
    pub fn recv(&self) -> Option<T> {
        let packet = lock(&self.inner.queue).packets.pop_front();
        packet.map(Parcel::into_owned)
    }

    /// The oldest queued packet, behind a shared pointer (never copied).
    pub fn recv_shared(&self) -> Option<Arc<T>> {
        let packet = lock(&self.inner.queue).packets.pop_front();
        packet.map(Parcel::into_shared)
    }

    /// Every packet queued now, oldest first.
    pub fn drain(&self) -> impl Iterator<Item = T> + '_ {
        let packets = std::mem::take(&mut lock(&self.inner.queue).packets);
        packets.into_iter().map(Parcel::into_owned)
    }

    /// The oldest queued packet as it was delivered (owned or shared).
    pub(crate) fn recv_parcel(&self) -> Option<Parcel<T>> {
        lock(&self.inner.queue).packets.pop_front()
    }

    /// The number of queued packets.
    pub fn len(&self) -> usize {
        lock(&self.inner.queue).packets.len()
    }

    /// Whether the queue is empty.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The current capacity (grows by steps of the initial size).
    pub fn capacity(&self) -> usize {
        lock(&self.inner.queue).capacity
    }

    /// How many times the queue has grown.
    pub fn growths(&self) -> u64 {
        lock(&self.inner.queue).growths
    }

    /// Packets lost at this input (only beyond the cap).
    pub fn overflows(&self) -> u64 {
        self.inner.core.overflows()
    }

    /// Ask the producer(s) for a packet (pull model).
    pub fn request(&self) -> Result<(), PullError> {
        self.inner.core.request()
    }

    /// Request a packet and wait for the next queued one.
    pub fn pull(&self, timeout: Duration) -> Result<T, PullError> {
        self.inner.core.pull_with(timeout, || self.recv())
    }
}

/// A last input: a local copy of the latest packet received.
pub struct LastIn<T> {
    inner: Arc<LastInner<T>>,
}

impl<T> Clone for LastIn<T> {
    fn clone(&self) -> Self {
        LastIn {
            inner: Arc::clone(&self.inner),
        }
    }
}

pub(crate) struct LastInner<T> {
    core: Arc<InputCore>,
    /// The latest packet and its sequence number (1 for the first packet).
    slot: Mutex<(Option<Parcel<T>>, u64)>,
    /// The sequence number the consumer last read with `take_new`.
    read_seq: AtomicU64,
}

impl<T: Packet> Deliver<T> for LastInner<T> {
    fn lost(&self, count: u64) {
        if count > 0 {
            self.core.overflowed(count);
        }
    }

    #[inline]
    fn deliver(&self, packet: Parcel<T>) {
        let replaced = {
            let mut slot = lock(&self.slot);
            slot.1 += 1;
            slot.0.replace(packet)
        };
        // (The replaced packet is dropped outside the lock.)
        drop(replaced);
        self.core.arrived();
    }
}

impl<T: Packet> LastIn<T> {
    /// A new, empty last input.
    pub fn new() -> LastIn<T> {
        LastIn {
            inner: Arc::new(LastInner {
                core: InputCore::new(),
                slot: Mutex::new((None, 0)),
                read_seq: AtomicU64::new(0),
            }),
        }
    }

    /// The latest packet received, if any (a clone of the local copy).
    pub fn latest(&self) -> Option<T> {
        lock(&self.inner.slot).0.as_ref().map(|p| p.get().clone())
    }

    /// The latest packet received, behind a shared pointer: not copied when its
    /// producer shares it among several inputs ([`FifoIn::recv_shared`]); else moved
    /// once into a shared allocation that later reads reuse.
    pub fn latest_shared(&self) -> Option<Arc<T>> {
        let mut slot = lock(&self.inner.slot);
        Self::share(&mut slot.0)
    }

    /// The latest packet, only if it is newer than the last one `take_new` returned.
    pub fn take_new(&self) -> Option<T> {
        let slot = lock(&self.inner.slot);
        if slot.1 > self.inner.read_seq.load(Ordering::Acquire) {
            self.inner.read_seq.store(slot.1, Ordering::Release);
            slot.0.as_ref().map(|p| p.get().clone())
        } else {
            None
        }
    }

    /// [`LastIn::take_new`] behind a shared pointer (see [`LastIn::latest_shared`]).
    pub fn take_new_shared(&self) -> Option<Arc<T>> {
        let mut slot = lock(&self.inner.slot);
        if slot.1 > self.inner.read_seq.load(Ordering::Acquire) {
            self.inner.read_seq.store(slot.1, Ordering::Release);
            Self::share(&mut slot.0)
        } else {
            None
        }
    }

    /// The packet in `slot`, made shared in place if it was owned.
    fn share(slot: &mut Option<Parcel<T>>) -> Option<Arc<T>> {
        let shared = slot.take()?.into_shared();
        *slot = Some(Parcel::Shared(Arc::clone(&shared)));
        Some(shared)
    }

    /// How many packets have been received in all.
    pub fn received(&self) -> u64 {
        lock(&self.inner.slot).1
    }

    /// Ask the producer for a packet (pull model).
    pub fn request(&self) -> Result<(), PullError> {
        self.inner.core.request()
    }

    /// Request a packet and wait until a newer one than the last `take_new` arrives.
    pub fn pull(&self, timeout: Duration) -> Result<T, PullError> {
        self.inner.core.pull_with(timeout, || self.take_new())
    }
}

impl<T: Packet> Default for LastIn<T> {
    fn default() -> Self {
        LastIn::new()
    }
}

/// Where a poster input reads from: a producer's post, maybe through a converter.
pub(crate) trait PosterSource<T>: Send + Sync {
    /// The posted value and its sequence number, read together.
    fn read(&self) -> (Option<T>, u64) {
        // (Without a `seen` bound, `read_newer` always answers.)
        self.read_newer(None).unwrap_or((None, 0))
    }
    /// The sequence number of the latest post (0 before any).
    fn seq(&self) -> u64;
    /// The posted value and its sequence number, if that is above `seen` (always when
    /// `seen` is `None`), under one lock of the producer's slot.
    fn read_newer(&self, seen: Option<u64>) -> Option<(Option<T>, u64)>;
}

/// A poster input: reads the value its producer posted.
pub struct PosterIn<T> {
    inner: Arc<PosterInInner<T>>,
}

impl<T> Clone for PosterIn<T> {
    fn clone(&self) -> Self {
        PosterIn {
            inner: Arc::clone(&self.inner),
        }
    }
}

/// A poster input's source: the id of the output it reads, and that output's post.
type Linked<T> = (usize, Arc<dyn PosterSource<T>>);

pub(crate) struct PosterInInner<T> {
    core: Arc<InputCore>,
    /// What the input reads: the id of the output it is connected to (its
    /// `OutputCore` id, for `unlink` to clear only its own connection) and that
    /// output's post, maybe through a converter.
    source: RwLock<Option<Linked<T>>>,
    /// The sequence number of the post read last, in the current source's numbering:
    /// set back to 0 (nothing read) whenever the source is set or cleared, under the
    /// source's write lock, so the first post of a new producer is new.
    seen: AtomicU64,
}

impl<T: Packet> PosterIn<T> {
    /// A new, unconnected poster input.
    pub fn new() -> PosterIn<T> {
        PosterIn {
            inner: Arc::new(PosterInInner {
                core: InputCore::new(),
                source: RwLock::new(None),
                seen: AtomicU64::new(0),
            }),
        }
    }

    /// The producer's currently posted value (`None` if unconnected or nothing posted).
    pub fn read(&self) -> Option<T> {
        let source = read(&self.inner.source);
        let (value, seq) = source.as_ref()?.1.read();
        self.inner.seen.store(seq, Ordering::Release);
        value
    }

    /// The producer's posted value, only if it posted since the last `read` or
    /// `take_new` (one look at the producer instead of `is_new` then `read`).
    pub fn take_new(&self) -> Option<T> {
        let source = read(&self.inner.source);
        let (value, seq) = source
            .as_ref()?
            .1
            .read_newer(Some(self.inner.seen.load(Ordering::Acquire)))?;
        self.inner.seen.store(seq, Ordering::Release);
        value
    }

    /// Whether the producer posted since the last `read` or `take_new` (a producer
    /// connected since then counts as new as soon as it has posted).
    pub fn is_new(&self) -> bool {
        read(&self.inner.source)
            .as_ref()
            .is_some_and(|(_, source)| source.seq() > self.inner.seen.load(Ordering::Acquire))
    }

    /// Ask the producer to post (pull model).
    pub fn request(&self) -> Result<(), PullError> {
        self.inner.core.request()
    }

    /// Request a post and wait for it.
    pub fn pull(&self, timeout: Duration) -> Result<T, PullError> {
        self.inner.core.pull_with(timeout, || self.take_new())
    }
}

impl<T: Packet> Default for PosterIn<T> {
    fn default() -> Self {
        PosterIn::new()
    }
}

// ---------------------------------------------------------------------------------
// Output ends.

/// A tick output: emits event packets to every connected tick input.
#[derive(Clone)]
pub struct TickOut {
    inner: Arc<TickOutInner>,
}

pub(crate) struct TickOutInner {
    core: Arc<OutputCore>,
    targets: RwLock<Arc<[TickTarget]>>,
}

/// Where a tick output's events go: a tick input, or a compound's exported tick
/// output that passes them on to its own inputs.
#[derive(Clone)]
enum TickTarget {
    Input(Arc<TickInner>),
    Forward { id: usize, to: Arc<TickOutInner> },
}

impl TickTarget {
    /// The input's id, or the forwarding's.
    fn id(&self) -> usize {
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
    inner: Arc<DataOutInner<T>>,
}

impl<T> Clone for DataOut<T> {
    fn clone(&self) -> Self {
        DataOut {
            inner: Arc::clone(&self.inner),
        }
    }
}

pub(crate) struct DataOutInner<T> {
    core: Arc<OutputCore>,
    sinks: RwLock<Arc<[Sink<T>]>>,
}

impl<T: Packet> DataOut<T> {
    /// A new, unconnected data output.
    pub fn new() -> DataOut<T> {
        DataOut {
            inner: Arc::new(DataOutInner {
                core: OutputCore::new(),
                sinks: RwLock::new(Arc::from([])),
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
            dispatch_answer(&read(&self.inner.sinks), Parcel::Owned(packet), answering);
            return;
        }
        dispatch(&read(&self.inner.sinks), Parcel::Owned(packet));
    }

    /// Send a packet that may already be shared (a compound's relay passing on what
    /// arrived at its exported input), as [`DataOut::send`] does.
    pub(crate) fn send_parcel(&self, packet: Parcel<T>) {
        dispatch(&read(&self.inner.sinks), packet);
    }

    /// How many inputs are connected.
    pub fn consumers(&self) -> usize {
        read(&self.inner.sinks).len()
    }
}

impl<T: Packet> Default for DataOut<T> {
    fn default() -> Self {
        DataOut::new()
    }
}

/// A poster output: posts a value that connected poster inputs read.
pub struct PosterOut<T> {
    inner: Arc<PosterOutInner<T>>,
}

impl<T> Clone for PosterOut<T> {
    fn clone(&self) -> Self {
        PosterOut {
            inner: Arc::clone(&self.inner),
        }
    }
}

pub(crate) struct PosterOutInner<T> {
    core: Arc<OutputCore>,
    /// The posted value and its sequence number (1 for the first post), together
    /// under one short lock: a post takes it once, a reader once.
    slot: Mutex<(Option<T>, u64)>,
    readers: RwLock<Arc<[Arc<InputCore>]>>,
    /// Recorders' taps: each post is delivered to them too (see `tap_data`).
    taps: RwLock<Arc<[Sink<T>]>>,
    /// Whether `taps` is not empty: a post without taps reads one flag, not the list.
    tapped: AtomicBool,
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

struct ConvertedPoster<A, B> {
    convert: Arc<dyn Fn(&A) -> B + Send + Sync>,
    source: Arc<PosterOutInner<A>>,
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

// ---------------------------------------------------------------------------------
// Type-erased ports, for `PortSet`, `System::connect` and the runner.

/// The kind of an input end, erased of its packet type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum InKind {
    Tick,
    Fifo,
    Ufifo,
    Last,
    Poster,
}

impl InKind {
    pub(crate) fn name(self) -> &'static str {
        match self {
            InKind::Tick => "tick",
            InKind::Fifo => "fifo",
            InKind::Ufifo => "ufifo",
            InKind::Last => "last",
            InKind::Poster => "poster",
        }
    }
}

/// The kind of an output end, erased of its packet type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum OutKind {
    Tick,
    Data,
    Poster,
}

impl OutKind {
    pub(crate) fn name(self) -> &'static str {
        match self {
            OutKind::Tick => "tick",
            OutKind::Data => "data",
            OutKind::Poster => "poster",
        }
    }
}

/// What the type-erased code (connecting, moving a connection's input end, retiring a
/// component) asks of an input end, implemented by each typed input end. The defaults
/// are those of an input that holds no queue.
pub(crate) trait InputEnd: Any + Send + Sync {
    /// Forget the source of a poster input if it is the output with this id (an
    /// input's source may already be another output's: see `replace_link`).
    fn clear_source(&self, _output: usize) {}

    /// Move what is queued here into `to`, an input of the same kind and packet type:
    /// how many packets (or events) moved.
    fn transfer(&self, _to: &ErasedInput) -> u64 {
        0
    }

    /// Empty the queue (fifo, ufifo): how many packets were in it.
    fn discard(&self) -> u64 {
        0
    }

    /// Room left in a fifo whose policy is `Block` (`None` for every other input: a
    /// delivery to it never waits).
    fn room(&self) -> Option<usize> {
        None
    }

    /// A new, unconnected output that can feed this input (same packet type): a tick
    /// output for a tick input, a poster output for a poster input, a data output
    /// for the others. A harness (`crate::harness`) feeds inputs through these.
    fn feeder(&self) -> ErasedOutput;
}

/// What the type-erased code asks of an output end, implemented by each typed output
/// end. `output` is the erased handle of `self`; `input` has been checked for kind.
pub(crate) trait OutputEnd: Any + Send + Sync {
    /// Connect to `input`: false if it is not of this output's packet type after all.
    fn link(&self, output: &ErasedOutput, input: &ErasedInput) -> bool;

    /// Disconnect from `input`.
    fn unlink(&self, output: &ErasedOutput, input: &ErasedInput);

    /// Move the connection from `old` to `new` in one step, with what is queued.
    fn relink(&self, output: &ErasedOutput, old: &ErasedInput, new: &ErasedInput) -> bool;

    /// Make this output (`this`, a compound's exported data or poster output) follow
    /// `from`: one more sink or tap of `from`, with id `id`, passing on to this one.
    /// False if `from` is not of this output's kind and packet type.
    fn forward_from(&self, _this: &ErasedOutput, _from: &ErasedOutput, _id: usize) -> bool {
        false
    }

    /// Remove the forwarding or tap with id `id` (nothing if there is none).
    fn remove_sink(&self, id: usize);

    /// A merge of `lanes` outputs like this one (data outputs only).
    fn merge(&self, _lanes: usize) -> Option<Arc<dyn MergeEnd>> {
        None
    }

    /// Keep everything `output` (this end) sends from now on, for a harness
    /// (`crate::harness`): a data or poster output gets a [`Collected`] tap (see
    /// [`tap_data`]), a tick output a tick input of its own. The tap's or input's
    /// id (a pull request on its behalf is answered to it) and the collector.
    fn collector(&self, output: &ErasedOutput) -> Option<(usize, Arc<dyn Any + Send + Sync>)>;
}

/// An input port with its packet type erased (see [`InputPort`]).
#[derive(Clone)]
pub struct ErasedInput {
    pub(crate) kind: InKind,
    pub(crate) type_id: TypeId,
    pub(crate) type_name: &'static str,
    pub(crate) core: Arc<InputCore>,
    end: Arc<dyn InputEnd>,
}

/// The typed input end behind `input`, if it is an `X`.
fn input_as<X: InputEnd>(input: &ErasedInput) -> Option<Arc<X>> {
    let any: Arc<dyn Any + Send + Sync> = input.end.clone();
    any.downcast::<X>().ok()
}

/// The typed output end behind `output`, if it is an `X`.
fn output_as<X: OutputEnd>(output: &ErasedOutput) -> Option<Arc<X>> {
    let any: Arc<dyn Any + Send + Sync> = output.end.clone();
    any.downcast::<X>().ok()
}

impl ErasedInput {
    /// How many packets a delivery can add without waiting, if a delivery to this
    /// input can wait at all (a fifo with the `Block` policy); `None` otherwise.
    pub(crate) fn room(&self) -> Option<usize> {
        self.end.room()
    }

    /// Move what is queued at this input to `to`, if it is of the same kind and packet
    /// type (otherwise nothing moves). Returns how many packets (or events) moved.
    pub(crate) fn transfer_to(&self, to: &ErasedInput) -> u64 {
        if self.type_id == to.type_id && self.kind == to.kind {
            self.end.transfer(to)
        } else {
            0
        }
    }

    /// Empty this input's queue, counting the packets as lost at it (overflows, with a
    /// `MonitorEvent::Overflow`): its component is retired and will never read them.
    /// Returns how many there were.
    pub(crate) fn discard_queued(&self) -> u64 {
        let lost = self.end.discard();
        if lost > 0 {
            self.core.overflowed(lost);
        }
        lost
    }

    /// Count `lost` packets as lost at this input, from outside its component: packets
    /// meant for it that never reached it (a network bridge's packet that did not
    /// decode, or that it could not send). They are added to the input's `overflows`
    /// and announced as a `MonitorEvent::Overflow` on its component's monitoring
    /// port, like a packet its own overflow policy dropped. Zero does nothing.
    pub fn count_loss(&self, lost: u64) {
        if lost > 0 {
            self.core.overflowed(lost);
        }
    }

    /// [`ErasedInput::count_loss`] for packets a compound's exported input left this
    /// input out of (a redundant member that stalled), counted apart too.
    pub(crate) fn count_left_behind(&self, lost: u64) {
        if lost > 0 {
            self.core.left_behind.fetch_add(lost, Ordering::AcqRel);
            self.core.overflowed(lost);
        }
    }
}

impl InputEnd for TickInner {
    fn feeder(&self) -> ErasedOutput {
        TickOut::new().erased()
    }

    fn transfer(&self, to: &ErasedInput) -> u64 {
        let Some(to) = input_as::<TickInner>(to) else {
            return 0;
        };
        let count = self.count.swap(0, Ordering::AcqRel);
        if count > 0 {
            to.count.fetch_add(count, Ordering::AcqRel);
            to.core.arrived();
        }
        count
    }
}

/// Deliver `packets` to `to` (an input of `T`): how many.
fn transfer_queue<T: Packet>(packets: Vec<Parcel<T>>, to: &ErasedInput) -> u64 {
    let count = packets.len() as u64;
    if let Some(target) = data_target::<T>(to) {
        for packet in packets {
            target.deliver(packet);
        }
    }
    count
}

impl<T: Packet> InputEnd for FifoInner<T> {
    fn feeder(&self) -> ErasedOutput {
        DataOut::<T>::new().erased()
    }

    fn transfer(&self, to: &ErasedInput) -> u64 {
        transfer_queue(self.receiver.try_iter().collect(), to)
    }

    fn discard(&self) -> u64 {
        self.receiver.try_iter().count() as u64
    }

    fn room(&self) -> Option<usize> {
        (self.policy == OverflowPolicy::Block)
            .then(|| self.capacity.saturating_sub(self.receiver.len()))
    }
}

impl<T: Packet> InputEnd for UfifoInner<T> {
    fn feeder(&self) -> ErasedOutput {
        DataOut::<T>::new().erased()
    }

    fn transfer(&self, to: &ErasedInput) -> u64 {
        let packets: Vec<Parcel<T>> = std::mem::take(&mut lock(&self.queue).packets).into();
        transfer_queue(packets, to)
    }

    fn discard(&self) -> u64 {
        std::mem::take(&mut lock(&self.queue).packets).len() as u64
    }
}

impl<T: Packet> InputEnd for LastInner<T> {
    fn feeder(&self) -> ErasedOutput {
        DataOut::<T>::new().erased()
    }

    fn transfer(&self, to: &ErasedInput) -> u64 {
        // Only a packet the old consumer has not taken yet is handed on.
        let unread = {
            let slot = lock(&self.slot);
            (slot.1 > self.read_seq.load(Ordering::Acquire))
                .then(|| slot.0.clone())
                .flatten()
        };
        match unread {
            Some(packet) => transfer_queue(vec![packet], to),
            None => 0,
        }
    }
}

impl<T: Packet> InputEnd for PosterInInner<T> {
    fn feeder(&self) -> ErasedOutput {
        PosterOut::<T>::new().erased()
    }

    fn clear_source(&self, output: usize) {
        let mut source = write(&self.source);
        if source.as_ref().is_some_and(|(id, _)| *id == output) {
            *source = None;
            // (Under the write lock: no read is between its look and its `seen`.)
            self.seen.store(0, Ordering::Release);
        }
    }
}

impl fmt::Debug for ErasedInput {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} input of {}", self.kind.name(), self.type_name)
    }
}

/// An output port with its packet type erased (see [`OutputPort`]).
#[derive(Clone)]
pub struct ErasedOutput {
    pub(crate) kind: OutKind,
    pub(crate) type_id: TypeId,
    pub(crate) type_name: &'static str,
    pub(crate) core: Arc<OutputCore>,
    end: Arc<dyn OutputEnd>,
}

impl fmt::Debug for ErasedOutput {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} output of {}", self.kind.name(), self.type_name)
    }
}

impl ErasedOutput {
    /// Connect to `input`, whose kind and packet type were already checked. Returns
    /// false if the input is not of this output's packet type after all.
    pub(crate) fn link(&self, input: &ErasedInput) -> bool {
        self.end.link(self, input)
    }

    /// Disconnect from `input`. Packets already queued at the input stay there.
    pub(crate) fn unlink(&self, input: &ErasedInput) {
        self.end.unlink(self, input)
    }

    /// Move this output's connection from input `old` to input `new` (of the same kind
    /// and type, checked by the caller) in one step, with what is queued at `old`:
    /// while it runs no packet is sent, so none is lost, duplicated or reordered.
    pub(crate) fn relink(&self, old: &ErasedInput, new: &ErasedInput) -> bool {
        self.end.relink(self, old, new)
    }
}

/// A typed input handle that can be registered with [`crate::PortSet`].
pub trait InputPort {
    /// The handle with its packet type erased.
    fn erased(&self) -> ErasedInput;
}

/// A typed output handle that can be registered with [`crate::PortSet`].
pub trait OutputPort {
    /// The handle with its packet type erased.
    fn erased(&self) -> ErasedOutput;
}

/// Packet type of event ports.
struct Event;

impl InputPort for TickIn {
    fn erased(&self) -> ErasedInput {
        ErasedInput {
            kind: InKind::Tick,
            type_id: TypeId::of::<Event>(),
            type_name: "event",
            core: Arc::clone(&self.inner.core),
            end: self.inner.clone(),
        }
    }
}

impl<T: Packet> InputPort for FifoIn<T> {
    fn erased(&self) -> ErasedInput {
        ErasedInput {
            kind: InKind::Fifo,
            type_id: TypeId::of::<T>(),
            type_name: std::any::type_name::<T>(),
            core: Arc::clone(&self.inner.core),
            end: self.inner.clone(),
        }
    }
}

impl<T: Packet> InputPort for UfifoIn<T> {
    fn erased(&self) -> ErasedInput {
        ErasedInput {
            kind: InKind::Ufifo,
            type_id: TypeId::of::<T>(),
            type_name: std::any::type_name::<T>(),
            core: Arc::clone(&self.inner.core),
            end: self.inner.clone(),
        }
    }
}

impl<T: Packet> InputPort for LastIn<T> {
    fn erased(&self) -> ErasedInput {
        ErasedInput {
            kind: InKind::Last,
            type_id: TypeId::of::<T>(),
            type_name: std::any::type_name::<T>(),
            core: Arc::clone(&self.inner.core),
            end: self.inner.clone(),
        }
    }
}

impl<T: Packet> InputPort for PosterIn<T> {
    fn erased(&self) -> ErasedInput {
        ErasedInput {
            kind: InKind::Poster,
            type_id: TypeId::of::<T>(),
            type_name: std::any::type_name::<T>(),
            core: Arc::clone(&self.inner.core),
            end: self.inner.clone(),
        }
    }
}

impl OutputPort for TickOut {
    fn erased(&self) -> ErasedOutput {
        ErasedOutput {
            kind: OutKind::Tick,
            type_id: TypeId::of::<Event>(),
            type_name: "event",
            core: Arc::clone(&self.inner.core),
            end: self.inner.clone(),
        }
    }
}

impl<T: Packet> OutputPort for DataOut<T> {
    fn erased(&self) -> ErasedOutput {
        ErasedOutput {
            kind: OutKind::Data,
            type_id: TypeId::of::<T>(),
            type_name: std::any::type_name::<T>(),
            core: Arc::clone(&self.inner.core),
            end: self.inner.clone(),
        }
    }
}

impl<T: Packet> OutputPort for PosterOut<T> {
    fn erased(&self) -> ErasedOutput {
        ErasedOutput {
            kind: OutKind::Poster,
            type_id: TypeId::of::<T>(),
            type_name: std::any::type_name::<T>(),
            core: Arc::clone(&self.inner.core),
            end: self.inner.clone(),
        }
    }
}

/// Replace a snapshot list with `f` applied to a copy of it.
fn update_list<X: Clone>(list: &RwLock<Arc<[X]>>, f: impl FnOnce(&mut Vec<X>)) {
    let mut guard = write(list);
    let mut items: Vec<X> = guard.iter().cloned().collect();
    f(&mut items);
    *guard = Arc::from(items);
}

impl OutputEnd for TickOutInner {
    fn collector(&self, output: &ErasedOutput) -> Option<(usize, Arc<dyn Any + Send + Sync>)> {
        let input = TickIn::new();
        let erased = input.erased();
        self.link(output, &erased).then(|| {
            let any: Arc<dyn Any + Send + Sync> = Arc::new(input);
            (erased.core.id, any)
        })
    }

    fn link(&self, output: &ErasedOutput, input: &ErasedInput) -> bool {
        let Some(target) = input_as::<TickInner>(input) else {
            return false;
        };
        update_list(&self.targets, |targets| {
            targets.push(TickTarget::Input(target))
        });
        input.core.add_source(Arc::clone(&output.core));
        true
    }

    fn unlink(&self, output: &ErasedOutput, input: &ErasedInput) {
        update_list(&self.targets, |targets| {
            targets.retain(|t| t.id() != input.core.id)
        });
        input.core.remove_source(output.core.id);
    }

    fn relink(&self, output: &ErasedOutput, old: &ErasedInput, new: &ErasedInput) -> bool {
        let Some(target) = input_as::<TickInner>(new) else {
            return false;
        };
        let mut targets = write(&self.targets);
        let mut items: Vec<_> = targets
            .iter()
            .filter(|t| t.id() != old.core.id)
            .cloned()
            .collect();
        items.push(TickTarget::Input(target));
        *targets = Arc::from(items);
        old.end.transfer(new);
        drop(targets);
        old.core.remove_source(output.core.id);
        new.core.add_source(Arc::clone(&output.core));
        true
    }

    fn remove_sink(&self, id: usize) {
        update_list(&self.targets, |targets| targets.retain(|t| t.id() != id));
    }
}

/// The data-receiving end of `input` as a `Deliver<T>`, if it is a last, fifo or ufifo
/// input of `T`.
fn data_target<T: Packet>(input: &ErasedInput) -> Option<Arc<dyn Deliver<T>>> {
    match input.kind {
        InKind::Fifo => input_as::<FifoInner<T>>(input).map(|x| x as Arc<dyn Deliver<T>>),
        InKind::Ufifo => input_as::<UfifoInner<T>>(input).map(|x| x as Arc<dyn Deliver<T>>),
        InKind::Last => input_as::<LastInner<T>>(input).map(|x| x as Arc<dyn Deliver<T>>),
        InKind::Tick | InKind::Poster => None,
    }
}

impl<T: Packet> DataOutInner<T> {
    fn add_sink(&self, output: &ErasedOutput, input: &ErasedInput, target: Arc<dyn Deliver<T>>) {
        update_list(&self.sinks, |sinks| {
            sinks.push(Sink {
                input_id: input.core.id,
                target,
            })
        });
        input.core.add_source(Arc::clone(&output.core));
    }

    /// Replace, in one write of the sinks, the sink at input `old` by `target`
    /// (delivering to input `new`, directly or through a converter), and move what
    /// is queued at `old` to `new` (if both take the same packet type).
    fn swap_sink(
        &self,
        output: &ErasedOutput,
        old: &ErasedInput,
        new: &ErasedInput,
        target: Arc<dyn Deliver<T>>,
    ) {
        // Senders hold the read lock while delivering: under the write lock nothing is
        // in flight, so the queued packets move before any newer one arrives at `new`.
        let mut sinks = write(&self.sinks);
        let mut items: Vec<_> = sinks
            .iter()
            .filter(|sink| sink.input_id != old.core.id)
            .cloned()
            .collect();
        items.push(Sink {
            input_id: new.core.id,
            target,
        });
        *sinks = Arc::from(items);
        if old.type_id == new.type_id && old.kind == new.kind {
            old.end.transfer(new);
        }
        drop(sinks);
        old.core.remove_source(output.core.id);
        new.core.add_source(Arc::clone(&output.core));
    }
}

impl<T: Packet> OutputEnd for DataOutInner<T> {
    fn collector(&self, output: &ErasedOutput) -> Option<(usize, Arc<dyn Any + Send + Sync>)> {
        let collected = Arc::new(Collected::<T>::default());
        let id = tap_data::<T>(output, collected.clone())?;
        let any: Arc<dyn Any + Send + Sync> = collected;
        Some((id, any))
    }

    fn link(&self, output: &ErasedOutput, input: &ErasedInput) -> bool {
        match data_target::<T>(input) {
            Some(target) => {
                self.add_sink(output, input, target);
                true
            }
            None => false,
        }
    }

    fn unlink(&self, output: &ErasedOutput, input: &ErasedInput) {
        update_list(&self.sinks, |sinks| {
            sinks.retain(|sink| sink.input_id != input.core.id)
        });
        input.core.remove_source(output.core.id);
    }

    fn relink(&self, output: &ErasedOutput, old: &ErasedInput, new: &ErasedInput) -> bool {
        match data_target::<T>(new) {
            Some(target) => {
                self.swap_sink(output, old, new, target);
                true
            }
            None => false,
        }
    }

    fn forward_from(&self, this: &ErasedOutput, from: &ErasedOutput, id: usize) -> bool {
        let (Some(out), Some(to)) = (
            output_as::<DataOutInner<T>>(from),
            output_as::<DataOutInner<T>>(this),
        ) else {
            return false;
        };
        update_list(&out.sinks, |sinks| {
            sinks.push(Sink {
                input_id: id,
                target: Arc::new(DataForward { to }),
            })
        });
        true
    }

    fn remove_sink(&self, id: usize) {
        update_list(&self.sinks, |sinks| {
            sinks.retain(|sink| sink.input_id != id)
        });
    }

    fn merge(&self, lanes: usize) -> Option<Arc<dyn MergeEnd>> {
        Some(DataOutInner::<T>::new_merge(lanes))
    }
}

fn set_poster_source<T: Packet>(
    output: &ErasedOutput,
    input: &ErasedInput,
    source: Arc<dyn PosterSource<T>>,
    out_readers: &RwLock<Arc<[Arc<InputCore>]>>,
) -> bool {
    let Some(reader) = input_as::<PosterInInner<T>>(input) else {
        return false;
    };
    {
        let mut slot = write(&reader.source);
        *slot = Some((output.core.id, source));
        // A new source numbers its posts from 1: nothing of it has been read yet.
        reader.seen.store(0, Ordering::Release);
    }
    update_list(out_readers, |readers| readers.push(Arc::clone(&input.core)));
    input.core.add_source(Arc::clone(&output.core));
    true
}

impl<T: Packet> OutputEnd for PosterOutInner<T> {
    fn collector(&self, output: &ErasedOutput) -> Option<(usize, Arc<dyn Any + Send + Sync>)> {
        let collected = Arc::new(Collected::<T>::default());
        let id = tap_data::<T>(output, collected.clone())?;
        let any: Arc<dyn Any + Send + Sync> = collected;
        Some((id, any))
    }

    fn link(&self, output: &ErasedOutput, input: &ErasedInput) -> bool {
        let Some(this) = output_as::<PosterOutInner<T>>(output) else {
            return false;
        };
        let source: Arc<dyn PosterSource<T>> = this;
        set_poster_source(output, input, source, &self.readers)
    }

    fn unlink(&self, output: &ErasedOutput, input: &ErasedInput) {
        update_list(&self.readers, |readers| {
            readers.retain(|r| r.id != input.core.id)
        });
        // The input's packet type may differ from T (a converter): clear its source
        // through the input's own end, only if it still reads this output (a replacing
        // connection may have been made first).
        input.end.clear_source(output.core.id);
        input.core.remove_source(output.core.id);
    }

    fn relink(&self, output: &ErasedOutput, old: &ErasedInput, new: &ErasedInput) -> bool {
        // A poster input holds no queue: it reads the producer's post.
        if !self.link(output, new) {
            return false;
        }
        self.unlink(output, old);
        true
    }

    fn forward_from(&self, this: &ErasedOutput, from: &ErasedOutput, id: usize) -> bool {
        let (Some(out), Some(to)) = (
            output_as::<PosterOutInner<T>>(from),
            output_as::<PosterOutInner<T>>(this),
        ) else {
            return false;
        };
        out.add_tap(Sink {
            input_id: id,
            target: Arc::new(PosterForward {
                to: PosterOut { inner: to },
            }),
        });
        true
    }

    fn remove_sink(&self, id: usize) {
        let mut taps = write(&self.taps);
        let kept: Vec<Sink<T>> = taps
            .iter()
            .filter(|tap| tap.input_id != id)
            .cloned()
            .collect();
        self.tapped.store(!kept.is_empty(), Ordering::Release);
        *taps = Arc::from(kept);
    }
}

impl<T: Packet> PosterOutInner<T> {
    /// Deliver every post to `tap` too (a recorder's tap, an exported output).
    fn add_tap(&self, tap: Sink<T>) {
        let mut taps = write(&self.taps);
        let mut list: Vec<Sink<T>> = taps.iter().cloned().collect();
        list.push(tap);
        *taps = Arc::from(list);
        self.tapped.store(true, Ordering::Release);
    }
}

/// Connect a data or poster output of `A` to an input of `B` through `convert`.
/// Returns false if the kinds or types do not match `A` and `B`.
pub(crate) fn link_converted<A: Packet, B: Packet>(
    output: &ErasedOutput,
    input: &ErasedInput,
    convert: Arc<dyn Fn(&A) -> B + Send + Sync>,
) -> bool {
    match output.kind {
        OutKind::Data => match (
            output_as::<DataOutInner<A>>(output),
            data_target::<B>(input),
        ) {
            (Some(out), Some(target)) => {
                out.add_sink(output, input, Arc::new(Converted { convert, target }));
                true
            }
            _ => false,
        },
        OutKind::Poster => {
            let Some(out) = output_as::<PosterOutInner<A>>(output) else {
                return false;
            };
            let source: Arc<dyn PosterSource<B>> = Arc::new(ConvertedPoster {
                convert,
                source: Arc::clone(&out),
            });
            set_poster_source(output, input, source, &out.readers)
        }
        OutKind::Tick => false,
    }
}

/// [`link_converted`], replacing `output`'s connection to input `old` (if given) in
/// one step: a data output's sink is swapped under one write of its sinks, with the
/// packets queued at `old` moved to `input` (no packet sent meanwhile is lost); a
/// poster's readers are switched (a poster input holds no queue).
pub(crate) fn relink_converted<A: Packet, B: Packet>(
    output: &ErasedOutput,
    old: Option<&ErasedInput>,
    input: &ErasedInput,
    convert: Arc<dyn Fn(&A) -> B + Send + Sync>,
) -> bool {
    let Some(old) = old else {
        return link_converted(output, input, convert);
    };
    match output.kind {
        OutKind::Data => match (
            output_as::<DataOutInner<A>>(output),
            data_target::<B>(input),
        ) {
            (Some(out), Some(target)) => {
                out.swap_sink(output, old, input, Arc::new(Converted { convert, target }));
                true
            }
            _ => false,
        },
        OutKind::Poster => {
            if !link_converted(output, input, convert) {
                return false;
            }
            output.unlink(old);
            true
        }
        OutKind::Tick => false,
    }
}

// ---------------------------------------------------------------------------------
// Forwarding: a compound's exported output following the instance output behind it,
// and recorders' taps.

/// A compound's exported data output as a sink of the instance output it follows.
struct DataForward<T> {
    to: Arc<DataOutInner<T>>,
}

impl<T: Packet> Deliver<T> for DataForward<T> {
    fn deliver(&self, packet: Parcel<T>) {
        dispatch(&read(&self.to.sinks), packet);
    }

    fn answers(&self, id: usize) -> bool {
        read(&self.to.sinks)
            .iter()
            .any(|sink| sink.input_id == id || sink.target.answers(id))
    }

    fn deliver_answer(&self, packet: Parcel<T>, id: usize) {
        dispatch_answer(&read(&self.to.sinks), packet, id);
    }

    fn lost(&self, count: u64) {
        for sink in read(&self.to.sinks).iter() {
            sink.target.lost(count);
        }
    }
}

/// A compound's exported poster output as a tap of the instance output it follows.
struct PosterForward<T> {
    to: PosterOut<T>,
}

impl<T: Packet> Deliver<T> for PosterForward<T> {
    fn deliver(&self, packet: Parcel<T>) {
        self.to.post(packet.into_owned());
    }
}

/// Pass every packet, post or event `from` produces on to `to` (a compound's exported
/// output following the instance behind it), synchronously on the producer's thread,
/// and the pull requests `to` receives back to `from`. Data packets are not copied
/// for this (the exported output is one more sink of `from`, sharing packets as any
/// sink does); a post is copied once into `to`'s slot. Returns the forwarding's id
/// for [`unforward`], or `None` if the two are not of the same kind and packet type.
pub(crate) fn forward(from: &ErasedOutput, to: &ErasedOutput) -> Option<usize> {
    if from.kind != to.kind || from.type_id != to.type_id {
        return None;
    }
    let id = next_port_id();
    match to.kind {
        OutKind::Tick => {
            let out = output_as::<TickOutInner>(from)?;
            let target = output_as::<TickOutInner>(to)?;
            update_list(&out.targets, |targets| {
                targets.push(TickTarget::Forward { id, to: target })
            });
        }
        OutKind::Data | OutKind::Poster => {
            // The typed half: `to` knows its packet type.
            if !to.end.forward_from(to, from, id) {
                return None;
            }
        }
    }
    to.core.set_route(PullRoute::Output(Arc::clone(&from.core)));
    Some(id)
}

/// Stop a forwarding made by [`forward`], or remove a tap [`tap_data`] added.
pub(crate) fn unforward(from: &ErasedOutput, id: usize) {
    from.end.remove_sink(id);
}

/// Deliver every packet `from` sends (a data output) or posts (a poster output) to
/// `tap` as well (a recorder's tap), on the producer's thread: the tap is one more
/// sink (sharing a packet it gets with the other sinks, see [`shares`]). Returns the
/// tap's id for [`unforward`], or `None` if `from` is neither a data nor a poster
/// output of `T`. A tap is no connection: `System::connections` does not list it.
pub(crate) fn tap_data<T: Packet>(from: &ErasedOutput, tap: Arc<dyn Deliver<T>>) -> Option<usize> {
    let id = next_port_id();
    let sink = Sink {
        input_id: id,
        target: tap,
    };
    if let Some(out) = output_as::<DataOutInner<T>>(from) {
        update_list(&out.sinks, |sinks| sinks.push(sink));
    } else {
        output_as::<PosterOutInner<T>>(from)?.add_tap(sink);
    }
    Some(id)
}

// ---------------------------------------------------------------------------------
// Merging a redundant group's outputs into one stream.

/// How many packets a member that does not lead its group keeps, ahead of the stream,
/// for the moment it leads.
pub(crate) const MERGE_BACKLOG: usize = 1024;

/// A redundant group's data output as one stream (see `docs/runtime.md`,
/// "Redundancy"): every member's output is a lane, numbered by the packets it sent;
/// the stream carries the leader's packets, each sequence number once; the other
/// lanes keep their packets ahead of the stream (up to [`MERGE_BACKLOG`]) so that,
/// when another member leads, the stream goes on from its backlog with no number
/// missing and none doubled.
pub(crate) trait MergeEnd: Send + Sync {
    /// The merged stream's output (consumers connect to it, not to the members).
    fn output(&self) -> ErasedOutput;
    /// Make member output `from` lane `lane` (kind and type checked): false if it is
    /// not a data output of the stream's packet type.
    fn attach(&self, lane: usize, from: &ErasedOutput) -> bool;
    /// Lane `lane` leads from now on: its packets ahead of the stream go out now.
    /// Returns how many went out, and how many numbers were missing before them
    /// (packets its backlog could not keep), which are counted as lost at every
    /// input the stream feeds (directly, through a converter, or through a
    /// compound's exported output).
    fn lead(&self, lane: usize) -> (u64, u64);
    /// Lane `lane` (a member back from recovery) counts on from the stream's number.
    fn rejoin(&self, lane: usize);
    /// Every lane counts on from the stream's number, and `lane` leads (a restart of
    /// the compound: every member starts again).
    fn reset(&self, lane: usize);
}

struct Lane<T> {
    sent: u64,
    backlog: VecDeque<(u64, Parcel<T>)>,
    core: Option<Arc<OutputCore>>,
}

struct MergeState<T> {
    leader: usize,
    /// The number of the last packet of the stream.
    delivered: u64,
    lanes: Vec<Lane<T>>,
}

struct Merge<T> {
    out: DataOut<T>,
    state: Mutex<MergeState<T>>,
}

impl<T: Packet> Merge<T> {
    fn arrive(&self, lane: usize, packet: Parcel<T>) {
        let mut state = lock(&self.state);
        let state = &mut *state;
        let leader = state.leader;
        let seq = {
            let lane = &mut state.lanes[lane];
            lane.sent += 1;
            lane.sent
        };
        if seq <= state.delivered {
            return; // Already in the stream (sent by the member that led then).
        }
        if lane == leader {
            state.delivered = seq;
            for other in &mut state.lanes {
                while other.backlog.front().is_some_and(|(s, _)| *s <= seq) {
                    other.backlog.pop_front();
                }
            }
            // Under the lock: the stream keeps its order.
            self.out.send_parcel(packet);
        } else {
            let backlog = &mut state.lanes[lane].backlog;
            backlog.push_back((seq, packet));
            if backlog.len() > MERGE_BACKLOG {
                backlog.pop_front();
            }
        }
    }

    fn route_pulls(&self, state: &MergeState<T>) {
        if let Some(core) = &state.lanes[state.leader].core {
            self.out
                .inner
                .core
                .set_route(PullRoute::Output(Arc::clone(core)));
        }
    }
}

/// One member's output as a lane of a merge.
struct LaneSink<T> {
    merge: Arc<Merge<T>>,
    lane: usize,
}

impl<T: Packet> Deliver<T> for LaneSink<T> {
    fn deliver(&self, packet: Parcel<T>) {
        self.merge.arrive(self.lane, packet);
    }

    fn answers(&self, id: usize) -> bool {
        read(&self.merge.out.inner.sinks)
            .iter()
            .any(|sink| sink.input_id == id || sink.target.answers(id))
    }

    fn deliver_answer(&self, packet: Parcel<T>, id: usize) {
        // A pull answer is for its requester, not part of the stream.
        dispatch_answer(&read(&self.merge.out.inner.sinks), packet, id);
    }
}

impl<T: Packet> MergeEnd for Arc<Merge<T>> {
    fn output(&self) -> ErasedOutput {
        self.out.erased()
    }

    fn attach(&self, lane: usize, from: &ErasedOutput) -> bool {
        let Some(out) = output_as::<DataOutInner<T>>(from) else {
            return false;
        };
        let sink = LaneSink {
            merge: Arc::clone(self),
            lane,
        };
        update_list(&out.sinks, |sinks| {
            sinks.push(Sink {
                input_id: next_port_id(),
                target: Arc::new(sink),
            })
        });
        let mut state = lock(&self.state);
        state.lanes[lane].core = Some(Arc::clone(&from.core));
        if lane == state.leader {
            self.route_pulls(&state);
        }
        true
    }

    fn lead(&self, lane: usize) -> (u64, u64) {
        let mut state = lock(&self.state);
        state.leader = lane;
        self.route_pulls(&state);
        let backlog = std::mem::take(&mut state.lanes[lane].backlog);
        let (mut replayed, mut missing) = (0, 0);
        for (seq, packet) in backlog {
            if seq > state.delivered {
                missing += seq - state.delivered - 1;
                state.delivered = seq;
                replayed += 1;
                self.out.send_parcel(packet);
            }
        }
        if missing > 0 {
            // The stream's consumers never get them: lost there, counted and
            // announced, so that sent = received + lost holds at each of them.
            for sink in read(&self.out.inner.sinks).iter() {
                sink.target.lost(missing);
            }
        }
        (replayed, missing)
    }

    fn rejoin(&self, lane: usize) {
        let mut state = lock(&self.state);
        let delivered = state.delivered;
        let lane = &mut state.lanes[lane];
        lane.sent = delivered;
        lane.backlog.clear();
    }

    fn reset(&self, lane: usize) {
        let mut state = lock(&self.state);
        let delivered = state.delivered;
        for each in &mut state.lanes {
            each.sent = delivered;
            each.backlog.clear();
        }
        state.leader = lane;
        self.route_pulls(&state);
    }
}

impl ErasedOutput {
    /// A merge of `lanes` outputs of this output's kind and packet type (a redundant
    /// group's data output), or `None` for a tick or poster output.
    pub(crate) fn merge(&self, lanes: usize) -> Option<Arc<dyn MergeEnd>> {
        self.end.merge(lanes)
    }
}

impl<T: Packet> DataOutInner<T> {
    fn new_merge(lanes: usize) -> Arc<dyn MergeEnd> {
        let out = DataOut::<T>::new();
        // The merged output answers pull requests (routed to the leader).
        out.inner.core.accept_pulls();
        Arc::new(Arc::new(Merge {
            out,
            state: Mutex::new(MergeState {
                leader: 0,
                delivered: 0,
                lanes: (0..lanes)
                    .map(|_| Lane {
                        sent: 0,
                        backlog: VecDeque::new(),
                        core: None,
                    })
                    .collect(),
            }),
        }))
    }
}
