//! A last input's slot: the newest packet, handed from the producers to the readers
//! with one atomic read-modify-write per update in the common case.
//!
//! Three cells hold packets (a triple buffer): the producers' *back* cell, where the
//! next packet is written; the *middle* cell, which holds the newest packet when no
//! reader has taken it yet; the readers' *front* cell, which holds the packet read
//! last. Every cell has one of the three roles at a time. One word, the input's
//! arrival counter (`InputCore::arrivals`), says which cell is the middle (its low
//! two bits), whether the middle holds a packet no reader took (`FRESH`), and, above
//! them, the sequence number of the newest packet (1 for the first; it wraps after
//! 2^61 packets), which is the input's arrival count. So a publish stores the packet
//! and counts it in one operation:
//!
//! - a producer writes its packet into the back cell, then swaps the word for the
//!   next sequence number, `FRESH` and the back cell. The old middle becomes its back
//!   cell: if the old word was fresh, the packet there was never read, and the
//!   producer moves it out and drops it after the publish, outside any lock (a
//!   reader never waits for it);
//! - a reader that finds the word fresh moves the packet it read out of its front
//!   cell, then by compare-and-swap makes that empty cell the middle (the word's
//!   sequence number stays): the old middle is its front, with the word's sequence
//!   number. It drops the packet it moved out after it let go of its lock.
//!
//! The swap reads and writes the newest word, so the producer learns which cell it
//! may reuse from the same operation that gives the reader the new packet, and the
//! reader's compare-and-swap fails, and is tried again, if a producer published
//! between its look and its swap. Readers take turns under a mutex that no producer
//! touches. Producers take turns too (there is one back cell, and the sequence number
//! comes from the last publish), without a read-modify-write in the common case: a
//! thread that publishes alone holds a *bias* ([`Turns`]).
//!
//! The invariant, for any number of producers and readers: at most one producer
//! holds the turn (the back cell and the last sequence number) at a time, each turn
//! after the one before it; at most one reader holds the front cell; the middle
//! cell is no one's. A cell passes from one side to the other only through the
//! word, so a packet is read only once its write is over, and dropped only by the
//! side that took it out of the word's cells. The producers' half rests on each
//! thread's busy flag having that thread as its only writer ([`Turns`]).

#![allow(
    unsafe_code,
    reason = "the cells are shared by the protocol above, each use argued at its block"
)]

use std::cell::{Cell, UnsafeCell};

use crossbeam_utils::CachePadded;

use super::sinks::{backoff, heavy_fence, light_fence, token};
use super::*;

/// The word's bits below the count: the middle cell's index and `FRESH`.
const COUNT_SHIFT: u32 = 3;
/// The middle cell's index, in the word.
const MIDDLE: u64 = 0b011;
/// Set in the word while the middle cell holds a packet no reader took.
const FRESH: u64 = 0b100;

/// The newest packet of a last input (see the module's doc).
///
/// The cells, the producers' side and the readers' side have cache lines of their own:
/// a reader's lock does not take a line the producer writes.
pub(crate) struct Slot<T> {
    /// The input's core, whose arrival counter is the slot's word.
    core: Arc<InputCore>,
    cells: CachePadded<[UnsafeCell<Option<Parcel<T>>>; 3]>,
    producers: CachePadded<Producers>,
    /// The readers' side.
    front: CachePadded<Mutex<Front>>,
}

// SAFETY: the cells and `back` are shared between threads only as the module's doc
// says: `back` and the back cell by the producer whose turn it is (`Turns` gives one
// turn at a time, each turn synchronised with the one before), the front cell by the
// reader holding `front`'s lock, and the middle cell by no one; a cell changes role
// only through an atomic read-modify-write of the word (release on the side that
// gives it up, acquire on the side that takes it), whose low bits no one else writes
// (`InputCore::arrived` adds above them). Packets cross threads (`T: Send`) and
// readers clone them from shared references on any thread (`T: Sync`).
unsafe impl<T: Send + Sync> Sync for Slot<T> {}

/// The producers' side of the slot.
struct Producers {
    /// Touched only by the producer whose turn it is.
    back: UnsafeCell<Back>,
    turns: Turns,
}

/// What the producer whose turn it is knows.
struct Back {
    /// The back cell.
    index: usize,
    /// The sequence number of the last publish.
    seq: u64,
}

/// The readers' side of the slot.
struct Front {
    /// The front cell.
    index: usize,
    /// The sequence number of the packet in the front cell (0: none yet).
    seq: u64,
    /// The sequence number of the last packet taken as new.
    taken: u64,
}

/// What a reader sees, under the readers' lock: the newest packet and what it was
/// told so far.
pub(crate) struct Reading<'a, T> {
    /// The newest packet (`None` before the first), which the reader may share in
    /// place.
    pub(crate) packet: &'a mut Option<Parcel<T>>,
    /// Its sequence number (0 before the first packet).
    pub(crate) seq: u64,
    /// The sequence number of the last packet a reader took as new.
    taken: &'a mut u64,
}

impl<'a, T> Reading<'a, T> {
    /// Whether the packet is newer than the last one taken as new.
    pub(crate) fn is_new(&self) -> bool {
        self.seq > *self.taken
    }

    /// `f` applied to the packet, if it is new; once `f` returns, the packet is
    /// taken (if `f` unwinds, as a packet's `Clone` may, it is still new).
    pub(crate) fn take_new<R>(self, f: impl FnOnce(&mut Option<Parcel<T>>) -> R) -> Option<R> {
        if !self.is_new() {
            return None;
        }
        let result = f(self.packet);
        *self.taken = self.seq;
        Some(result)
    }
}

impl<T> Slot<T> {
    /// The input's core.
    pub(crate) fn core(&self) -> &Arc<InputCore> {
        &self.core
    }
}

impl<T: Packet> Slot<T> {
    pub(crate) fn new() -> Slot<T> {
        // Cell 0 is the front, cell 1 the middle, cell 2 the back.
        Slot {
            core: InputCore::counting_from(COUNT_SHIFT, 1),
            cells: CachePadded::new([const { UnsafeCell::new(None) }; 3]),
            producers: CachePadded::new(Producers {
                back: UnsafeCell::new(Back { index: 2, seq: 0 }),
                turns: Turns::new(),
            }),
            front: CachePadded::new(Mutex::new(Front {
                index: 0,
                seq: 0,
                taken: 0,
            })),
        }
    }

    /// Make `packet` the newest, count it and wake the consumer; the packet it
    /// replaced unread is dropped last, outside any lock.
    #[inline]
    pub(crate) fn publish(&self, packet: Parcel<T>) {
        let replaced = self
            .core
            .arrived_by(|word| self.producers.turns.run(|| self.swap_in(word, packet)));
        drop(replaced);
    }

    /// Write `packet` into the back cell and make it the middle (on the producers'
    /// turn): the packet the old middle held unread, if any.
    #[inline]
    fn swap_in(&self, word: &AtomicU64, packet: Parcel<T>) -> Option<Parcel<T>> {
        // SAFETY: `back` is the producers' and this is their turn (`Turns::run`): no
        // other reference to it exists while this one lives.
        let back = unsafe { &mut *self.producers.back.get() };
        let cell = self.cells[back.index].get();
        // SAFETY: the back cell is the producers' (its index is in `back`, which only
        // the turn's holder reads), so nothing else touches it; it is empty (the
        // packet it held was moved out when it became the back cell), so the
        // assignment runs no drop code.
        unsafe {
            debug_assert!((*cell).is_none());
            *cell = Some(packet);
        }
        back.seq = back.seq.wrapping_add(1);
        // `SeqCst`: the arrival counter's increment (the doorbell's argument); it
        // releases the packet to the reader that takes the middle, and acquires the
        // cell it gives back (a reader empties its front cell before it hands it in).
        let old = word.swap(
            (back.seq << COUNT_SHIFT) | FRESH | back.index as u64,
            Ordering::SeqCst,
        );
        back.index = (old & MIDDLE) as usize;
        // SAFETY: the swap took the old middle out of the word: it is the producers'
        // back cell now, reached through `back`, this turn's.
        unsafe { (*self.cells[back.index].get()).take() }
    }

    /// `f` applied to the newest packet, under the readers' lock; the packet read
    /// before it is dropped after the lock is let go.
    pub(crate) fn read<R>(&self, f: impl FnOnce(Reading<'_, T>) -> R) -> R {
        // Declared before the guard, so dropped after it even when `f` unwinds (a
        // packet's `Clone` may panic): no packet's drop code runs under the lock.
        let mut read_before = None;
        let mut front = lock(&self.front);
        let word = &self.core.arrivals;
        let mut current = word.load(Ordering::Acquire);
        if current & FRESH != 0 {
            // SAFETY: the front cell is the readers', and this reader holds their lock.
            read_before = unsafe { (*self.cells[front.index].get()).take() };
            loop {
                // The emptied front cell becomes the middle, not fresh; the count stays.
                let handed = (current & !(MIDDLE | FRESH)) | front.index as u64;
                match word.compare_exchange_weak(
                    current,
                    handed,
                    Ordering::AcqRel,
                    Ordering::Acquire,
                ) {
                    Ok(_) => break,
                    // A producer published meanwhile: still fresh (only readers, one
                    // at a time, clear `FRESH`).
                    Err(now) => current = now,
                }
            }
            debug_assert!(current & FRESH != 0);
            front.index = (current & MIDDLE) as usize;
            front.seq = current >> COUNT_SHIFT;
        }
        let result = {
            let front = &mut *front;
            // SAFETY: the front cell is the readers', and this reader holds their lock
            // for as long as the reference lives (it does not outlive `f`).
            let packet = unsafe { &mut *self.cells[front.index].get() };
            f(Reading {
                packet,
                seq: front.seq,
                taken: &mut front.taken,
            })
        };
        drop(front);
        drop(read_before);
        result
    }
}

thread_local! {
    /// The calling thread's busy flag, set while it publishes under a slot's bias.
    /// Only its thread writes it; a revoker reads it through the clone kept with the
    /// grant ([`Streak::grantee`]), which keeps it alive after its thread ends.
    static FLAG: Flag = Flag(Arc::new(AtomicBool::new(false)));
    /// The address of this thread's flag, for the unlocked path (no lazy state to
    /// check): null until the thread is first granted a bias, and again from the
    /// moment its flag's owner is dropped, as the thread ends.
    static BUSY: Cell<*const AtomicBool> = const { Cell::new(std::ptr::null()) };
}

/// A thread's busy flag, owned by the thread (`FLAG`).
struct Flag(Arc<AtomicBool>);

impl Drop for Flag {
    fn drop(&mut self) {
        // From now on the thread's turns take the lock: `BUSY` never points at a
        // flag the thread no longer owns.
        BUSY.set(std::ptr::null());
    }
}

#[cfg(test)]
thread_local! {
    /// Run once by `Turns::run` between its first look at `biased` and its busy
    /// flag's set: where a test pauses a producer that is about to lose its bias.
    static BEFORE_BUSY: Cell<Option<Box<dyn FnOnce()>>> = const { Cell::new(None) };
}

/// The producers' turns: the thread that publishes alone publishes without a lock.
///
/// A thread that published `needed` times in a row under the lock is *granted* the
/// bias: `biased` holds its token, and the lock's [`Streak::grantee`] a clone of its
/// busy flag ([`FLAG`], its own, which no other thread writes). From then on it
/// marks itself busy (a plain store), reads `biased` again behind a light fence and,
/// if it is still biased, publishes without the lock. Another thread takes the lock,
/// revokes the bias (`biased` back to 0), and goes on only once the grantee's flag
/// is seen clear: the revocation's store and its look at the flag are separated by
/// the heavy fence, the grantee's store to its flag and its look at `biased` by the
/// light one (the pair the sinks use, `sinks.rs`), so one of the two looks sees the
/// other side's store: either the revoker sees the grantee busy and waits for its
/// release store (the publish happens before the revoker's), or the grantee sees
/// the revocation and takes the lock. Each revocation doubles `needed`, so a slot fed
/// by several threads at once ends up publishing under the lock, at a mutex's cost,
/// rather than revoking again and again.
///
/// The invariant: a turn is held by the thread in `run_locked` (under the lock) or
/// by the grantee between its flag's set and clear with `biased` seen equal to its
/// token, never by two at once. It rests on each flag having one writer: a thread
/// that lost its bias (it read its token in `biased` before the revocation) sets and
/// clears its own flag, which no revoker of a later grant looks at; were the flag
/// shared, its clear could hide a later grantee's publish from the next revoker.
///
/// A thread has one flag for every slot it publishes to: a revoker of one slot also
/// waits out the grantee's publishes to its other slots. That costs the revoker time
/// (the grantee's flag is clear between any two of its publishes); it never lets two
/// threads into one turn.
struct Turns {
    /// The grantee's token (`sinks::token`; 0: none). Written under `lock`, with
    /// `Streak::grantee`.
    biased: AtomicU64,
    lock: Mutex<Streak>,
    /// Revocations that waited for a publish in flight.
    #[cfg(test)]
    waited: AtomicU64,
}

/// Who published under the lock lately.
struct Streak {
    /// The thread that published last under the lock (its token; 0: none yet).
    thread: u64,
    /// How many times in a row it did.
    count: u64,
    /// How many times in a row bias a thread.
    needed: u64,
    /// The grantee's busy flag, while `biased` is not 0 (`None` exactly when it is).
    grantee: Option<Arc<AtomicBool>>,
}

impl Turns {
    fn new() -> Turns {
        Turns {
            biased: AtomicU64::new(0),
            #[cfg(test)]
            waited: AtomicU64::new(0),
            lock: Mutex::new(Streak {
                thread: 0,
                count: 0,
                needed: 1,
                grantee: None,
            }),
        }
    }

    /// Run `f` on the producers' turn.
    #[inline]
    fn run<R>(&self, f: impl FnOnce() -> R) -> R {
        let me = token();
        // Relaxed: only a hint. `biased` holds `me` only if this thread stored it (a
        // grant is made by its grantee, under the lock); a grant revoked since is
        // caught by the look behind the fence below, which decides.
        if self.biased.load(Ordering::Relaxed) == me {
            #[cfg(test)]
            // `try_with`: a publish from another thread-local's destructor may come
            // after this one's.
            if let Ok(Some(hook)) = BEFORE_BUSY.try_with(Cell::take) {
                hook();
            }
            let flag = BUSY.get();
            if !flag.is_null() {
                // SAFETY: not null, `BUSY` points at this thread's flag, which its
                // `FLAG` owns until it is dropped (which nulls `BUSY` first), on this
                // thread, not in the middle of this call.
                let busy = unsafe { &*flag };
                // Relaxed, then the light fence: the store is ordered before the look
                // at `biased` below, the half of the pair with the revoker's heavy
                // fence. Only this thread writes `busy`.
                busy.store(true, Ordering::Relaxed);
                let asymmetric = light_fence();
                let still = self.biased.load(if asymmetric {
                    Ordering::Relaxed
                } else {
                    Ordering::SeqCst
                }) == me;
                // Release (both stores): a revoker that reads a clear (acquire) comes
                // after this thread's publish; one that read the flag clear before
                // the set above made this look see the revocation (`still` false).
                if still {
                    // (`f` runs no user code: it cannot unwind with `busy` set.)
                    let result = f();
                    busy.store(false, Ordering::Release);
                    return result;
                }
                busy.store(false, Ordering::Release);
            }
        }
        self.run_locked(me, f)
    }

    /// Run `f` under the lock, revoking the bias first if a thread holds it.
    #[cold]
    fn run_locked<R>(&self, me: u64, f: impl FnOnce() -> R) -> R {
        let mut streak = lock(&self.lock);
        if let Some(busy) = streak.grantee.take() {
            // SeqCst, then the heavy fence: the revocation is ordered before the look
            // at the grantee's flag below (the other half of the pair in `run`).
            self.biased.store(0, Ordering::SeqCst);
            heavy_fence();
            // A read-modify-write reads the newest value of the flag: `false` means
            // the grantee's last publish is over (acquire, of its release store), and
            // this one comes after it; a later set by the grantee sees the revocation
            // (the fences' pair) and takes the lock.
            let mut round = 0;
            while busy
                .compare_exchange(false, false, Ordering::Acquire, Ordering::Relaxed)
                .is_err()
            {
                #[cfg(test)]
                if round == 0 {
                    self.waited.fetch_add(1, Ordering::Relaxed);
                }
                backoff(&mut round);
            }
            streak.needed = streak.needed.saturating_mul(2);
        }
        debug_assert_eq!(self.biased.load(Ordering::Relaxed), 0);
        let result = f();
        if streak.thread == me {
            streak.count = streak.count.saturating_add(1);
        } else {
            streak.thread = me;
            streak.count = 1;
        }
        // (`try_with` fails only once the thread's flag is dropped, as it ends: no
        // grant then.)
        if streak.count >= streak.needed
            && let Ok(busy) = FLAG.try_with(|flag| {
                BUSY.set(Arc::as_ptr(&flag.0));
                Arc::clone(&flag.0)
            })
        {
            streak.grantee = Some(busy);
            // Relaxed: only this thread acts on `me` in `biased` (its fast path,
            // which sees its own store), and it holds the lock here, after every
            // publish before this one.
            self.biased.store(me, Ordering::Relaxed);
        }
        result
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Barrier;
    use std::sync::atomic::AtomicUsize;
    use std::thread::{self, ThreadId};

    use super::*;

    /// Publishes per producer thread in the racing tests (Miri runs far fewer).
    const UPDATES: u64 = if cfg!(miri) { 40 } else { 1_000_000 };

    /// Packets the reader takes while it races a producer, at least.
    const TAKES: u64 = if cfg!(miri) { 3 } else { 100 };

    /// Publishes per producer thread when several race (Miri runs far fewer).
    const PRODUCER_UPDATES: u64 = if cfg!(miri) { 20 } else { 100_000 };

    /// Turns per thread in the mutual exclusion test (Miri runs far fewer).
    const TURNS: u64 = if cfg!(miri) { 60 } else { 200_000 };

    /// Fails the test when a wait for the other threads has lasted too long.
    struct Patience(Instant);

    impl Patience {
        fn new() -> Patience {
            Patience(Instant::now() + Duration::from_secs(60))
        }

        fn check(&self, what: &str) {
            assert!(Instant::now() < self.0, "still waiting for {what}");
        }
    }

    fn deliver<T: Packet>(input: &LastIn<T>, packet: T) {
        input.inner.deliver(Parcel::Owned(packet));
    }

    /// The reader's view: the newest packet's sequence number.
    fn seq<T: Packet>(input: &LastIn<T>) -> u64 {
        input.inner.slot.read(|reading| reading.seq)
    }

    /// A packet that counts its copies made and dropped.
    #[derive(Debug)]
    struct Counted {
        value: (u64, u64),
        made: Arc<AtomicUsize>,
        dropped: Arc<AtomicUsize>,
    }

    impl Counted {
        fn new(value: (u64, u64), made: &Arc<AtomicUsize>, dropped: &Arc<AtomicUsize>) -> Self {
            made.fetch_add(1, Ordering::Relaxed);
            Counted {
                value,
                made: Arc::clone(made),
                dropped: Arc::clone(dropped),
            }
        }
    }

    impl Clone for Counted {
        fn clone(&self) -> Self {
            Counted::new(self.value, &self.made, &self.dropped)
        }
    }

    impl Drop for Counted {
        fn drop(&mut self) {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }

    #[test]
    fn a_read_leaves_the_arrival_count_and_each_publish_adds_one() {
        let input = LastIn::<u64>::new();
        let core = Arc::clone(input.inner.core());
        assert_eq!(
            (core.arrivals(), input.received(), input.latest()),
            (0, 0, None)
        );
        deliver(&input, 10);
        assert_eq!(core.arrivals(), 1);
        // Taking the packet moves cells in the word, not the count: the component
        // sees no arrival that did not happen.
        assert_eq!(input.take_new(), Some(10));
        assert_eq!(core.arrivals(), 1);
        assert_eq!(input.take_new(), None);
        assert_eq!(input.latest(), Some(10));
        deliver(&input, 11);
        deliver(&input, 12);
        assert_eq!((core.arrivals(), input.received()), (3, 3));
        assert_eq!(input.latest(), Some(12));
        assert_eq!(core.arrivals(), 3);
        assert_eq!(input.take_new(), Some(12));
        assert_eq!(seq(&input), 3);
    }

    #[test]
    fn updates_racing_a_reader_keep_their_numbers_and_never_go_back() {
        let input = LastIn::<u64>::new();
        let taken = Arc::new(AtomicU64::new(0));
        let start = Arc::new(Barrier::new(2));
        let producer = {
            let (input, taken, start) = (input.clone(), Arc::clone(&taken), Arc::clone(&start));
            thread::spawn(move || {
                start.wait();
                // Packet `n` is the `n`-th sent: its sequence number must be `n`. On
                // until the reader has taken a few while it raced.
                let (patience, mut n) = (Patience::new(), 0);
                while n < UPDATES || taken.load(Ordering::Relaxed) < TAKES {
                    patience.check("the reader's takes");
                    n += 1;
                    deliver(&input, n);
                }
                n
            })
        };
        start.wait();
        let mut last = 0;
        while !producer.is_finished() {
            let (packet, seq) = input
                .inner
                .slot
                .read(|reading| (reading.packet.as_ref().map(|p| *p.get()), reading.seq));
            assert!(
                seq >= last,
                "the sequence number went back: {last} then {seq}"
            );
            assert_eq!(
                packet.unwrap_or(0),
                seq,
                "a packet read with another's number"
            );
            if let Some(newer) = input.take_new() {
                assert!(newer > last, "take_new gave {newer} after {last}");
                last = newer;
                taken.fetch_add(1, Ordering::Relaxed);
            }
        }
        let sent = producer.join().expect("producer");
        assert_eq!(input.received(), sent);
        assert_eq!(seq(&input), sent);
        assert_eq!(input.take_new(), (last < sent).then_some(sent));
        assert_eq!((input.latest(), input.take_new()), (Some(sent), None));
    }

    #[test]
    fn producers_in_turn_and_at_once_lose_no_number_and_drop_each_packet_once() {
        const PRODUCERS: u64 = 3;
        let made = Arc::new(AtomicUsize::new(0));
        let dropped = Arc::new(AtomicUsize::new(0));
        let input = LastIn::<Counted>::new();
        // In turn first: each thread's first publish revokes the bias of the one
        // before.
        for producer in 0..PRODUCERS {
            let (to, made, dropped) = (input.clone(), Arc::clone(&made), Arc::clone(&dropped));
            thread::spawn(move || deliver(&to, Counted::new((producer, 0), &made, &dropped)))
                .join()
                .expect("producer");
            assert_eq!(seq(&input), producer + 1);
            let newest = input.take_new().map(|packet| packet.value);
            assert_eq!(newest, Some((producer, 0)));
        }
        // Then at once, while a reader checks that each producer's packets come in
        // the order sent and no number goes back.
        let start = Arc::new(Barrier::new(PRODUCERS as usize + 1));
        let producers: Vec<_> = (0..PRODUCERS)
            .map(|producer| {
                let input = input.clone();
                let (made, dropped, start) =
                    (Arc::clone(&made), Arc::clone(&dropped), Arc::clone(&start));
                thread::spawn(move || {
                    start.wait();
                    for n in 1..=PRODUCER_UPDATES {
                        deliver(&input, Counted::new((producer, n), &made, &dropped));
                    }
                })
            })
            .collect();
        start.wait();
        let total = PRODUCERS * (PRODUCER_UPDATES + 1);
        let mut newest = [0; PRODUCERS as usize];
        let mut last_seq = PRODUCERS;
        let patience = Patience::new();
        while !producers.iter().all(thread::JoinHandle::is_finished) {
            patience.check("the producers");
            if let Some(packet) = input.take_new() {
                let (producer, n) = packet.value;
                let newest = &mut newest[producer as usize];
                assert!(
                    n > *newest,
                    "producer {producer}: packet {n} after {newest}"
                );
                *newest = n;
            }
            let now = seq(&input);
            assert!(
                now >= last_seq,
                "the sequence number went back: {last_seq} then {now}"
            );
            last_seq = now;
            thread::yield_now();
        }
        for producer in producers {
            producer.join().expect("producer");
        }
        assert_eq!(seq(&input), total);
        assert_eq!(input.received(), total);
        let survivor = input.latest().expect("a packet").value;
        assert_eq!(
            survivor.1, PRODUCER_UPDATES,
            "a last publish holds the newest"
        );
        drop(input);
        // Every packet made (sent or cloned by a reader) was dropped once: replaced
        // ones by their producers, read ones by the reader, the last with the input.
        assert_eq!(
            dropped.load(Ordering::Relaxed),
            made.load(Ordering::Relaxed)
        );
    }

    /// A packet whose drop reports its thread, then waits until told to go on.
    struct Held {
        dropping: Sender<ThreadId>,
        go_on: Receiver<()>,
    }

    impl Clone for Held {
        fn clone(&self) -> Self {
            Held {
                dropping: self.dropping.clone(),
                go_on: self.go_on.clone(),
            }
        }
    }

    impl Drop for Held {
        fn drop(&mut self) {
            if self.dropping.send(thread::current().id()).is_ok() {
                let _ = self.go_on.recv_timeout(Duration::from_secs(30));
            }
        }
    }

    /// `f` on another thread, which must return within the test's patience.
    fn returns(what: &str, f: impl FnOnce() + Send + 'static) {
        let (done, finished) = crossbeam_channel::bounded(1);
        thread::spawn(move || {
            f();
            let _ = done.send(());
        });
        finished
            .recv_timeout(Duration::from_secs(10))
            .unwrap_or_else(|_| panic!("{what} waited for a drop in progress"));
    }

    #[test]
    fn a_replaced_packet_is_dropped_by_its_producer_outside_the_slot() {
        let (dropping, dropped) = crossbeam_channel::unbounded();
        let (go_on, wait) = crossbeam_channel::unbounded();
        let input = LastIn::<Option<Held>>::new();
        let held = Held {
            dropping,
            go_on: wait,
        };
        let producer = {
            let input = input.clone();
            thread::spawn(move || {
                deliver(&input, Some(held));
                // Replaces the held packet unread: its drop runs here.
                deliver(&input, None);
                thread::current().id()
            })
        };
        let on = dropped
            .recv_timeout(Duration::from_secs(30))
            .expect("the replaced packet dropped");
        // While that drop runs, a reader reads and another producer publishes.
        let reader = input.clone();
        returns("a reader", move || {
            assert_eq!(reader.take_new().map(|p| p.is_none()), Some(true))
        });
        let other = input.clone();
        returns("another producer", move || deliver(&other, None));
        go_on.send(()).expect("the drop waits");
        let producer = producer.join().expect("producer");
        assert_eq!(
            on, producer,
            "the replaced packet was dropped off its producer"
        );
        assert_eq!(input.received(), 3);
    }

    #[test]
    fn a_packet_read_before_is_dropped_by_its_reader_outside_the_readers_lock() {
        let (dropping, dropped) = crossbeam_channel::unbounded();
        let (go_on, wait) = crossbeam_channel::unbounded();
        let input = LastIn::<Option<Held>>::new();
        deliver(
            &input,
            Some(Held {
                dropping,
                go_on: wait,
            }),
        );
        // The reader keeps its copy of the packet it read (its clone was dropped at
        // once: let it go on).
        let reader = {
            let input = input.clone();
            thread::spawn(move || {
                let copy = input.take_new();
                drop(copy);
                thread::current().id()
            })
        };
        assert_eq!(
            dropped.recv_timeout(Duration::from_secs(30)),
            Ok(reader.thread().id())
        );
        go_on.send(()).expect("the drop waits");
        reader.join().expect("reader");
        deliver(&input, None);
        let reader = {
            let input = input.clone();
            // Taking the new packet lets the one read before go: dropped here.
            thread::spawn(move || {
                assert!(input.take_new().is_some());
                thread::current().id()
            })
        };
        let on = dropped
            .recv_timeout(Duration::from_secs(30))
            .expect("the packet read before dropped");
        let other = input.clone();
        returns("another reader", move || {
            assert_eq!(other.latest().map(|p| p.is_none()), Some(true))
        });
        go_on.send(()).expect("the drop waits");
        assert_eq!(on, reader.join().expect("reader"));
    }

    /// A packet of several words, each the update's number: a read that mixed two
    /// writes shows two numbers.
    type Wide = [u64; 8];

    #[test]
    fn four_producers_and_two_readers_tear_nothing_and_count_every_update() {
        const PRODUCERS: u64 = 4;
        const READERS: usize = 2;
        let input = LastIn::<Wide>::new();
        let start = Arc::new(Barrier::new(PRODUCERS as usize + READERS));
        let done = Arc::new(AtomicU64::new(0));
        let producers: Vec<_> = (0..PRODUCERS)
            .map(|producer| {
                let (input, start, done) = (input.clone(), Arc::clone(&start), Arc::clone(&done));
                thread::spawn(move || {
                    start.wait();
                    for n in 1..=PRODUCER_UPDATES {
                        // Every update's number is distinct: its producer in the low
                        // bits.
                        deliver(&input, [n * PRODUCERS + producer; 8]);
                        if n % 64 == 0 {
                            // Bursts: a producer alone for a while earns the bias,
                            // which the next one revokes.
                            thread::yield_now();
                        }
                    }
                    done.fetch_add(1, Ordering::Release);
                })
            })
            .collect();
        let readers: Vec<_> = (0..READERS)
            .map(|_| {
                let (input, start, done) = (input.clone(), Arc::clone(&start), Arc::clone(&done));
                thread::spawn(move || {
                    start.wait();
                    let (patience, mut last_seq, mut reads) = (Patience::new(), 0, 0u64);
                    let mut newest = [0; PRODUCERS as usize];
                    while done.load(Ordering::Acquire) < PRODUCERS {
                        patience.check("the producers");
                        let (packet, seq) = input.inner.slot.read(|reading| {
                            (reading.packet.as_ref().map(|p| *p.get()), reading.seq)
                        });
                        assert!(
                            seq >= last_seq,
                            "the sequence number went back: {last_seq} then {seq}"
                        );
                        last_seq = seq;
                        if let Some(packet) = packet {
                            assert!(
                                packet.iter().all(|word| *word == packet[0]),
                                "a torn packet: {packet:?}"
                            );
                            let (producer, n) = (packet[0] % PRODUCERS, packet[0] / PRODUCERS);
                            let newest = &mut newest[producer as usize];
                            assert!(n >= *newest, "producer {producer}: {n} after {newest}");
                            *newest = n;
                        }
                        reads += 1;
                        if reads % 16 == 0 {
                            thread::yield_now();
                        }
                    }
                })
            })
            .collect();
        for handle in producers.into_iter().chain(readers) {
            handle.join().expect("a producer or reader");
        }
        let total = PRODUCERS * PRODUCER_UPDATES;
        assert_eq!(
            input.received(),
            total,
            "an update was lost or counted twice"
        );
        assert_eq!(seq(&input), total);
        let last = input.latest().expect("a packet");
        assert!(last.iter().all(|word| *word == last[0]));
        assert_eq!(
            last[0] / PRODUCERS,
            PRODUCER_UPDATES,
            "the newest is a last update"
        );
    }

    /// A counter that only the turn's holder touches, with no atomic of its own: two
    /// holders at once lose increments (and Miri reports the data race).
    struct Counter(UnsafeCell<u64>);

    // SAFETY: the test's threads touch the counter only on the producers' turn.
    unsafe impl Sync for Counter {}

    #[test]
    fn turns_are_held_by_one_thread_at_a_time_in_bursts_and_at_once() {
        const THREADS: u64 = 4;
        let turns = Arc::new(Turns::new());
        let counter = Arc::new(Counter(UnsafeCell::new(0)));
        let start = Arc::new(Barrier::new(THREADS as usize));
        let threads: Vec<_> = (0..THREADS)
            .map(|id| {
                let (turns, counter, start) =
                    (Arc::clone(&turns), Arc::clone(&counter), Arc::clone(&start));
                thread::spawn(move || {
                    start.wait();
                    for n in 0..TURNS {
                        turns.run(|| {
                            // SAFETY: the turn is this thread's (the property tested).
                            unsafe {
                                let value = std::ptr::read_volatile(counter.0.get());
                                std::ptr::write_volatile(counter.0.get(), value + 1);
                            }
                        });
                        // Bursts of different lengths per thread: each earns the bias
                        // now and then and loses it to the others.
                        if n % (8 << id) == 0 {
                            thread::yield_now();
                        }
                    }
                })
            })
            .collect();
        for handle in threads {
            handle.join().expect("a thread");
        }
        // SAFETY: every thread that touched the counter was joined.
        assert_eq!(unsafe { *counter.0.get() }, THREADS * TURNS);
    }

    #[test]
    fn a_producer_that_lost_the_bias_does_not_let_a_third_into_the_next_holders_turn() {
        let turns = Arc::new(Turns::new());
        // Set while the second holder's turn runs; a turn that starts meanwhile
        // overlaps it.
        let inside = Arc::new(AtomicBool::new(false));
        let overlapped = Arc::new(AtomicBool::new(false));
        // The first producer: one turn under the lock grants it the bias; its next
        // turn stops after its first look at `biased` (it is still its own).
        let (paused_tx, paused) = crossbeam_channel::bounded(1);
        let (resume_tx, resume) = crossbeam_channel::bounded::<()>(1);
        let first = {
            let (turns, inside, overlapped) = (
                Arc::clone(&turns),
                Arc::clone(&inside),
                Arc::clone(&overlapped),
            );
            thread::spawn(move || {
                turns.run(|| ());
                assert_eq!(turns.biased.load(Ordering::Relaxed), token());
                BEFORE_BUSY.set(Some(Box::new(move || {
                    paused_tx.send(()).expect("the test waits");
                    let _ = resume.recv_timeout(Duration::from_secs(30));
                })));
                turns.run(|| {
                    if inside.load(Ordering::SeqCst) {
                        overlapped.store(true, Ordering::SeqCst);
                    }
                });
            })
        };
        paused
            .recv_timeout(Duration::from_secs(30))
            .expect("the first producer paused");
        // The second revokes that bias, earns it with two turns in a row, and holds
        // its next turn, unlocked, until told.
        let (holding_tx, holding) = crossbeam_channel::bounded(1);
        let (leave_tx, leave) = crossbeam_channel::bounded::<()>(1);
        let second = {
            let (turns, inside) = (Arc::clone(&turns), Arc::clone(&inside));
            thread::spawn(move || {
                turns.run(|| ());
                turns.run(|| ());
                assert_eq!(turns.biased.load(Ordering::Relaxed), token());
                turns.run(|| {
                    inside.store(true, Ordering::SeqCst);
                    holding_tx.send(()).expect("the test waits");
                    let _ = leave.recv_timeout(Duration::from_secs(30));
                    inside.store(false, Ordering::SeqCst);
                });
            })
        };
        holding
            .recv_timeout(Duration::from_secs(30))
            .expect("the second producer holds its turn");
        // The first goes on: it finds its bias gone, so it takes the lock and revokes
        // the second's, which must wait for the turn in progress.
        resume_tx.send(()).expect("the first producer waits");
        let patience = Patience::new();
        while turns.waited.load(Ordering::Relaxed) == 0 && !first.is_finished() {
            patience.check("the first producer");
            thread::yield_now();
        }
        leave_tx.send(()).expect("the second producer waits");
        first.join().expect("the first producer");
        second.join().expect("the second producer");
        assert!(
            !overlapped.load(Ordering::SeqCst),
            "a turn ran inside the bias holder's"
        );
        assert_eq!(turns.waited.load(Ordering::Relaxed), 1);
    }

    /// A packet whose `Clone` panics.
    #[derive(Default)]
    struct Fragile {
        /// Reports its drop, and waits (the packet read before the one that panics).
        held: Option<Held>,
    }

    impl Clone for Fragile {
        fn clone(&self) -> Self {
            match &self.held {
                Some(held) => Fragile {
                    held: Some(held.clone()),
                },
                None => panic!("this packet cannot be cloned"),
            }
        }
    }

    #[test]
    fn a_panicking_clone_leaves_the_slot_usable_and_drops_nothing_under_the_readers_lock() {
        let (dropping, dropped) = crossbeam_channel::unbounded();
        let (go_on, wait) = crossbeam_channel::unbounded();
        let input = LastIn::<Fragile>::new();
        deliver(
            &input,
            Fragile {
                held: Some(Held {
                    dropping,
                    go_on: wait,
                }),
            },
        );
        // The reader's clone is dropped at once: let it go on.
        let reader = {
            let input = input.clone();
            thread::spawn(move || drop(input.take_new()))
        };
        dropped
            .recv_timeout(Duration::from_secs(30))
            .expect("the clone dropped");
        go_on.send(()).expect("the drop waits");
        reader.join().expect("reader");
        // The next packet's clone panics, after the read took the packet read before
        // out of its cell: that packet is dropped as the reader unwinds.
        deliver(&input, Fragile::default());
        let reader = {
            let input = input.clone();
            thread::spawn(move || {
                std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| input.take_new())).is_err()
            })
        };
        dropped
            .recv_timeout(Duration::from_secs(30))
            .expect("the packet read before dropped");
        let other = input.clone();
        returns("another reader", move || {
            assert_eq!(other.inner.slot.read(|reading| reading.seq), 2)
        });
        go_on.send(()).expect("the drop waits");
        assert!(reader.join().expect("reader"), "the clone did not panic");
        // The slot goes on: the packet whose clone panicked is still new, and the
        // next update replaces it.
        assert!(input.inner.slot.read(|reading| reading.is_new()));
        deliver(&input, Fragile::default());
        assert_eq!(input.received(), 3);
        assert_eq!(seq(&input), 3);
        let read = input
            .inner
            .slot
            .read(|reading| reading.take_new(|packet| packet.is_some()));
        assert_eq!(read, Some(true));
        assert!(input.take_new().is_none());
    }
}
