//! The input ends: tick, fifo, ufifo, last and poster inputs.

use super::*;

/// A tick input: counts event packets.
#[derive(Clone)]
pub struct TickIn {
    pub(super) inner: Arc<TickInner>,
}

pub(crate) struct TickInner {
    pub(super) core: Arc<InputCore>,
    pub(super) count: AtomicU64,
}

impl TickInner {
    pub(super) fn tick(&self) {
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
    pub(super) inner: Arc<FifoInner<T>>,
}

impl<T> Clone for FifoIn<T> {
    fn clone(&self) -> Self {
        FifoIn {
            inner: Arc::clone(&self.inner),
        }
    }
}

/// A fifo input's queue: both ends of one bounded channel.
type Queue<T> = (Sender<Parcel<T>>, Receiver<Parcel<T>>);

pub(crate) struct FifoInner<T> {
    pub(super) core: Arc<InputCore>,
    /// The queue, made by the first packet delivered or the first blocking receive:
    /// an input no packet has reached holds no buffer (a bounded channel of 16 small
    /// packets is about 1 KiB).
    channel: OnceLock<Queue<T>>,
    pub(super) policy: OverflowPolicy,
    pub(super) capacity: usize,
    pub(super) block_timeout: Duration,
    /// What may take a packet on the sender's thread instead of the queue.
    intake: OnceLock<Arc<dyn Intake<T>>>,
}

/// Takes packets delivered to a fifo input on the sending thread, ahead of the queue
/// ([`FifoIn::set_intake`]): a network outlet that writes a packet straight into
/// shared memory, sparing its own thread a wake-up.
pub trait Intake<T>: Send + Sync {
    /// Take `packet` now, on the sender's thread (true: it is not queued, does not
    /// ring the input's component and is not counted as an arrival), or leave it to
    /// the queue (false). It must not wait, and keeps order itself: it declines
    /// while packets are queued that it has not taken.
    fn offer(&self, packet: &T) -> bool;
}

impl<T: Packet> Deliver<T> for FifoInner<T> {
    fn input_bell(&self) -> Option<Arc<Doorbell>> {
        self.core.bell()
    }

    fn lost(&self, count: u64) {
        if count > 0 {
            self.core.overflowed(count);
        }
    }

    fn would_wait(&self) -> bool {
        InputEnd::room(self) == Some(0)
    }

    #[inline]
    fn deliver(&self, packet: Parcel<T>) {
        if let Some(intake) = self.intake.get()
            && intake.offer(packet.get())
        {
            return;
        }
        match self.sender().try_send(packet) {
            Ok(()) => {}
            Err(TrySendError::Full(packet)) => self.deliver_full(packet),
            // The receiver lives in `self`, so the channel cannot be disconnected.
            Err(TrySendError::Disconnected(_)) => return,
        }
        self.core.arrived();
    }
}

impl<T: Packet> FifoInner<T> {
    /// The queue, made now if no packet came yet.
    #[inline]
    fn queue(&self) -> &Queue<T> {
        self.channel
            .get_or_init(|| crossbeam_channel::bounded(self.capacity))
    }

    #[inline]
    fn sender(&self) -> &Sender<Parcel<T>> {
        &self.queue().0
    }

    /// The queue's receiving end, if a packet ever came (else nothing is queued).
    #[inline]
    pub(super) fn receiver(&self) -> Option<&Receiver<Parcel<T>>> {
        self.channel.get().map(|(_, receiver)| receiver)
    }

    /// Every packet queued now, oldest first.
    pub(super) fn drain(&self) -> impl Iterator<Item = Parcel<T>> + '_ {
        self.receiver().into_iter().flat_map(Receiver::try_iter)
    }

    /// The oldest queued packet.
    #[inline]
    fn take(&self) -> Option<Parcel<T>> {
        self.receiver()?.try_recv().ok()
    }

    /// How many packets are queued.
    pub(super) fn queued(&self) -> usize {
        self.receiver().map_or(0, Receiver::len)
    }

    #[cold]
    fn deliver_full(&self, packet: Parcel<T>) {
        match self.policy {
            OverflowPolicy::Reject => self.core.overflowed(1),
            OverflowPolicy::DropOldest => {
                let mut packet = packet;
                loop {
                    if self.take().is_some() {
                        self.core.overflowed(1);
                    }
                    match self.sender().try_send(packet) {
                        Ok(()) => break,
                        Err(TrySendError::Full(back)) => packet = back,
                        Err(TrySendError::Disconnected(_)) => break,
                    }
                }
            }
            OverflowPolicy::Block => {
                if self
                    .sender()
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
        FifoIn {
            inner: Arc::new(FifoInner {
                core: InputCore::new(),
                channel: OnceLock::new(),
                policy,
                capacity,
                block_timeout,
                intake: OnceLock::new(),
            }),
        }
    }

    /// Let `intake` take each packet delivered from now on, on the sender's thread,
    /// before it is queued; false (and nothing changes) if the input has one already.
    pub fn set_intake(&self, intake: Arc<dyn Intake<T>>) -> bool {
        self.inner.intake.set(intake).is_ok()
    }

    /// The doorbell of the component this input is a port of, once the component is
    /// in a system: where another process on this host rings it
    /// ([`ConsumerBell::address`](crate::ConsumerBell::address)), and the sources its
    /// thread drains.
    pub fn owner_bell(&self) -> Option<crate::ConsumerBell> {
        self.inner
            .core
            .bell()
            .map(|bell| crate::ConsumerBell { bell })
    }

    /// The oldest queued packet. A packet its producer sent to several inputs is
    /// shared among them: taking it by value copies it if another input still holds
    /// it ([`FifoIn::recv_shared`] never copies).
    pub fn recv(&self) -> Option<T> {
        self.inner.take().map(Parcel::into_owned)
    }

    /// The oldest queued packet, behind a shared pointer: a packet sent to several
    /// inputs is not copied for this one.
    pub fn recv_shared(&self) -> Option<Arc<T>> {
        self.inner.take().map(Parcel::into_shared)
    }

    /// Every packet queued now, oldest first.
    pub fn drain(&self) -> impl Iterator<Item = T> + '_ {
        self.inner.drain().map(Parcel::into_owned)
    }

    /// The oldest queued packet as it was delivered (owned or shared).
    pub(crate) fn recv_parcel(&self) -> Option<Parcel<T>> {
        self.inner.take()
    }

    /// Wait up to `timeout` for a packet. This blocks the calling thread: meant for
    /// threads outside the system (tests, tools), not for sections, which should
    /// react to arrivals with `on` transitions instead.
    pub fn recv_timeout(&self, timeout: Duration) -> Option<T> {
        self.inner
            .queue()
            .1
            .recv_timeout(timeout)
            .ok()
            .map(Parcel::into_owned)
    }

    /// The number of queued packets.
    pub fn len(&self) -> usize {
        self.inner.queued()
    }

    /// Whether the queue is empty.
    pub fn is_empty(&self) -> bool {
        self.inner.queued() == 0
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
    pub(super) inner: Arc<UfifoInner<T>>,
}

impl<T> Clone for UfifoIn<T> {
    fn clone(&self) -> Self {
        UfifoIn {
            inner: Arc::clone(&self.inner),
        }
    }
}

pub(crate) struct UfifoInner<T> {
    pub(super) core: Arc<InputCore>,
    pub(super) queue: Mutex<UfifoQueue<T>>,
    pub(super) step: usize,
    pub(super) max: Option<usize>,
}

pub(super) struct UfifoQueue<T> {
    pub(super) packets: VecDeque<Parcel<T>>,
    pub(super) capacity: usize,
    pub(super) growths: u64,
}

impl<T: Packet> Deliver<T> for UfifoInner<T> {
    fn input_bell(&self) -> Option<Arc<Doorbell>> {
        self.core.bell()
    }

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
    /// The doorbell of the component this input is a port of, once the component is
    /// in a system (as [`FifoIn::owner_bell`]).
    pub fn owner_bell(&self) -> Option<crate::ConsumerBell> {
        self.inner
            .core
            .bell()
            .map(|bell| crate::ConsumerBell { bell })
    }

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
    pub(super) inner: Arc<LastInner<T>>,
}

impl<T> Clone for LastIn<T> {
    fn clone(&self) -> Self {
        LastIn {
            inner: Arc::clone(&self.inner),
        }
    }
}

pub(crate) struct LastInner<T> {
    /// The latest packet, its sequence number (1 for the first packet) and the one
    /// the consumer last read with `take_new`; its core is the input's.
    pub(super) slot: Slot<T>,
}

impl<T> LastInner<T> {
    pub(super) fn core(&self) -> &Arc<InputCore> {
        self.slot.core()
    }
}

impl<T: Packet> Deliver<T> for LastInner<T> {
    fn input_bell(&self) -> Option<Arc<Doorbell>> {
        self.core().bell()
    }

    fn lost(&self, count: u64) {
        if count > 0 {
            self.core().overflowed(count);
        }
    }

    #[inline]
    fn deliver(&self, packet: Parcel<T>) {
        // (The replaced packet is dropped outside any lock.)
        self.slot.publish(packet);
    }
}

impl<T: Packet> LastIn<T> {
    /// A new, empty last input.
    pub fn new() -> LastIn<T> {
        LastIn {
            inner: Arc::new(LastInner { slot: Slot::new() }),
        }
    }

    /// The latest packet received, if any (a clone of the local copy).
    pub fn latest(&self) -> Option<T> {
        self.inner
            .slot
            .read(|reading| reading.packet.as_ref().map(|p| p.get().clone()))
    }

    /// The latest packet received, behind a shared pointer: not copied when its
    /// producer shares it among several inputs ([`FifoIn::recv_shared`]); else moved
    /// once into a shared allocation that later reads reuse.
    pub fn latest_shared(&self) -> Option<Arc<T>> {
        self.inner.slot.read(|reading| Self::share(reading.packet))
    }

    /// The latest packet, only if it is newer than the last one `take_new` returned.
    pub fn take_new(&self) -> Option<T> {
        self.inner.slot.read(|reading| {
            reading
                .take_new(|packet| packet.as_ref().map(|p| p.get().clone()))
                .flatten()
        })
    }

    /// [`LastIn::take_new`] behind a shared pointer (see [`LastIn::latest_shared`]).
    pub fn take_new_shared(&self) -> Option<Arc<T>> {
        self.inner
            .slot
            .read(|reading| reading.take_new(Self::share).flatten())
    }

    /// The packet in `slot`, made shared in place if it was owned.
    fn share(slot: &mut Option<Parcel<T>>) -> Option<Arc<T>> {
        let shared = slot.take()?.into_shared();
        *slot = Some(Parcel::Shared(Arc::clone(&shared)));
        Some(shared)
    }

    /// How many packets have been received in all.
    pub fn received(&self) -> u64 {
        self.inner.core().arrivals()
    }

    /// Ask the producer for a packet (pull model).
    pub fn request(&self) -> Result<(), PullError> {
        self.inner.core().request()
    }

    /// Request a packet and wait until a newer one than the last `take_new` arrives.
    pub fn pull(&self, timeout: Duration) -> Result<T, PullError> {
        self.inner.core().pull_with(timeout, || self.take_new())
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
    pub(super) inner: Arc<PosterInInner<T>>,
}

impl<T> Clone for PosterIn<T> {
    fn clone(&self) -> Self {
        PosterIn {
            inner: Arc::clone(&self.inner),
        }
    }
}

/// A poster input's source: the id of the output it reads, and that output's post.
pub(super) type Linked<T> = (usize, Arc<dyn PosterSource<T>>);

pub(crate) struct PosterInInner<T> {
    pub(super) core: Arc<InputCore>,
    /// What the input reads: the id of the output it is connected to (its
    /// `OutputCore` id, for `unlink` to clear only its own connection) and that
    /// output's post, maybe through a converter.
    pub(super) source: RwLock<Option<Linked<T>>>,
    /// The sequence number of the post read last, in the current source's numbering:
    /// set back to 0 (nothing read) whenever the source is set or cleared, under the
    /// source's write lock, so the first post of a new producer is new.
    pub(super) seen: AtomicU64,
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fifo_holds_no_queue_until_its_first_packet_and_then_queues_as_before() {
        let (out, fifo) = (
            DataOut::<u64>::new(),
            FifoIn::<u64>::new(2, OverflowPolicy::Reject),
        );
        assert!(out.erased().link(&fifo.erased()));
        // Connected, nothing sent: no queue, and it reads as empty.
        assert!(fifo.inner.channel.get().is_none());
        assert_eq!((fifo.recv(), fifo.len(), fifo.is_empty()), (None, 0, true));
        assert_eq!(fifo.drain().count(), 0);
        assert!(fifo.inner.channel.get().is_none());
        for packet in 1..=3 {
            out.send(packet);
        }
        assert!(fifo.inner.channel.get().is_some());
        // Its capacity and policy hold: the third packet was rejected and counted.
        assert_eq!((fifo.len(), fifo.overflows()), (2, 1));
        assert_eq!(fifo.drain().collect::<Vec<_>>(), [1, 2]);
    }

    #[test]
    fn a_receiver_waiting_before_the_first_packet_gets_it() {
        let (out, fifo) = (
            DataOut::<u64>::new(),
            FifoIn::<u64>::new(4, OverflowPolicy::Reject),
        );
        assert!(out.erased().link(&fifo.erased()));
        let waiting = fifo.clone();
        let receiver = std::thread::spawn(move || waiting.recv_timeout(Duration::from_secs(30)));
        // Sent whether the receiver made the queue already or not: one queue either way.
        out.send(7);
        assert_eq!(receiver.join().expect("receiver"), Some(7));
    }
}
