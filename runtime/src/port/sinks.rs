//! A data output's sinks, and how its component's thread sends to them without a lock.
//!
//! The sinks are a snapshot (`Arc<[Sink<T>]>`) under a `RwLock`, replaced whole on
//! every connection change. A sender normally holds the read lock while it delivers,
//! so that a change (the write lock) waits for deliveries in flight: once it
//! returns, no packet is on its way to a sink it removed, and the packets queued at
//! an input it replaced can be moved on without one arriving behind them.
//!
//! The read lock costs two atomic read-modify-write operations per packet, as much as
//! the rest of a delivery. So the thread that owns the output (its component's
//! thread, or its execution group's: [`OutputCore::claim_sends`]) sends without it:
//!
//! - it keeps its own copy of the snapshot, with the snapshot's version, in the
//!   sinks (`owned`: only the owner thread touches it, and never while it is
//!   delivering from it);
//! - each send marks the output `busy` (a plain store), then reads the version; if
//!   it is the cached one, it delivers to the cached snapshot and clears `busy`;
//!   otherwise it clears `busy`, reads the snapshot under the read lock, caches it
//!   and sets `busy` again before it lets the lock go, then delivers from the new
//!   copy and clears `busy` (no owner's delivery runs under the lock);
//! - a change replaces the snapshot and bumps the version under the write lock, then
//!   waits until `busy` is clear before it goes on (and releases the lock).
//!
//! Why no delivery from a replaced snapshot is in flight when a change goes on: the
//! owner's store to `busy` and its load of the version are separated by a light
//! fence, the change's bump and its load of `busy` by a heavy one ([`light_fence`],
//! [`heavy_fence`]), so that one of the two loads sees the other side's store. If the
//! change sees `busy`, it waits for the owner's clear (a release store after the
//! delivery: the delivery happens before the change goes on). If not, the owner sees
//! the new version and takes the read lock, which waits for the change (and a change
//! that takes the write lock after the owner set `busy` under the read lock sees it
//! set: the lock orders them). On Linux the
//! light fence is only a compiler fence and the heavy one the `membarrier` system
//! call (`MEMBARRIER_CMD_PRIVATE_EXPEDITED`), which makes every running thread of
//! the process execute a full barrier: a send then costs no atomic read-modify-write
//! for the lock. Elsewhere, or if the kernel refuses `membarrier`, both are
//! sequentially consistent fences (one full fence per send).
//!
//! Only the owner uses `busy` (a single writer, so plain stores suffice). A send
//! nested in the owner's delivery (a converter sending on the output it is
//! delivering for) delivers from the owner's copy too: it is part of the delivery in
//! flight, which a change waits for, so it must not wait for the read lock a waiting
//! change holds. A send from another thread delivers under the read lock; one nested
//! in such a delivery takes the read lock again, which a change waiting for the
//! write lock refuses: a converter on a shared output must not send on that output.
//! A snapshot the owner cached stays alive until its next send on the output or the
//! end of the output.

#![allow(
    unsafe_code,
    reason = "the owner's copy of the snapshot is shared by the protocol above, each use argued at its block"
)]

use std::cell::{Cell, UnsafeCell};
use std::sync::atomic::{compiler_fence, fence};

use super::*;

/// Clears the owner's `busy` flag when dropped (a release store: the delivery
/// happens before a change that sees it clear goes on).
struct Idle<'a>(&'a AtomicBool);

impl Drop for Idle<'_> {
    fn drop(&mut self) {
        self.0.store(false, Ordering::Release);
    }
}

/// A snapshot and its version.
type Versioned<T> = (u64, Arc<[Sink<T>]>);

/// Called after each change of an output's sinks ([`Sinks::watch`]).
pub(super) type Watcher = Arc<dyn Fn() + Send + Sync>;

/// The sinks of a data output (see the module's doc).
pub(crate) struct Sinks<T> {
    list: RwLock<Arc<[Sink<T>]>>,
    /// Bumped under the write lock with every change of `list`.
    version: AtomicU64,
    /// Set by the owner thread while it delivers to its cached snapshot.
    busy: AtomicBool,
    /// The owner thread's copy of the snapshot and its version. Touched only by the
    /// thread whose token is the output's `sender` (a claim that never changes),
    /// read while it delivers, written only when it is not delivering from it.
    owned: UnsafeCell<Option<Versioned<T>>>,
    /// Told after each change, on the thread that made it, with no lock of the
    /// sinks held.
    watchers: Mutex<Vec<Watcher>>,
    /// How many changes found the owner delivering and waited for it.
    #[cfg(test)]
    waited: AtomicU64,
}

impl<T: Packet> Sinks<T> {
    pub(super) fn new() -> Sinks<T> {
        Sinks {
            list: RwLock::new(Arc::from([])),
            version: AtomicU64::new(0),
            busy: AtomicBool::new(false),
            owned: UnsafeCell::new(None),
            watchers: Mutex::new(Vec::new()),
            #[cfg(test)]
            waited: AtomicU64::new(0),
        }
    }

    /// Call `watcher` after each change of the snapshot from now on.
    pub(super) fn watch(&self, watcher: Watcher) {
        lock(&self.watchers).push(watcher);
    }

    /// The snapshot, read-locked: no change goes on while the guard lives.
    pub(super) fn read(&self) -> std::sync::RwLockReadGuard<'_, Arc<[Sink<T>]>> {
        read(&self.list)
    }

    /// Replace the snapshot with `f` applied to a copy of it (`core`: the output's).
    pub(super) fn update(&self, core: &OutputCore, f: impl FnOnce(&mut Vec<Sink<T>>)) {
        self.update_then(core, f, || {});
    }

    /// [`Sinks::update`], then `then` before any packet is sent to the new snapshot:
    /// no delivery to the old one is in flight by then.
    pub(super) fn update_then<R>(
        &self,
        core: &OutputCore,
        f: impl FnOnce(&mut Vec<Sink<T>>),
        then: impl FnOnce() -> R,
    ) -> R {
        let mut list = write(&self.list);
        let mut items: Vec<Sink<T>> = list.iter().cloned().collect();
        f(&mut items);
        *list = Arc::from(items);
        self.version.fetch_add(1, Ordering::SeqCst);
        // An owner is set before its first send, which reads the snapshot under the
        // read lock: with none seen here, no send reads a cached one.
        if core.sender.load(Ordering::Acquire) != 0 {
            heavy_fence();
            let mut round = 0u32;
            while self.busy.load(Ordering::Acquire) {
                #[cfg(test)]
                if round == 0 {
                    self.waited.fetch_add(1, Ordering::Relaxed);
                }
                backoff(&mut round);
            }
        }
        let result = then();
        drop(list);
        // A copy of the list: a watcher may change these sinks, or add a watcher.
        let watchers = lock(&self.watchers).clone();
        for watcher in watchers {
            if let Err(panic) = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| watcher()))
            {
                tracing::error!(
                    "a watcher of an output's connections panicked: {}",
                    crate::thread::panic_message(panic.as_ref())
                );
            }
        }
        result
    }

    /// Deliver `packet` to every sink (see [`dispatch`]).
    #[inline]
    pub(super) fn send(&self, core: &OutputCore, packet: Parcel<T>) {
        let sender = core.sender.load(Ordering::Relaxed);
        let packet = if sender != 0 && sender == token() {
            if self.busy.load(Ordering::Relaxed) {
                self.send_nested(packet);
                return;
            }
            match self.send_cached(packet) {
                None => return,
                Some(packet) => packet,
            }
        } else {
            packet
        };
        self.send_locked(core, packet);
    }

    /// A send by the owner from inside its own delivery from its copy (`busy` is
    /// set): to the same copy. A change that replaced the snapshot meanwhile holds
    /// the write lock and waits for `busy` to clear, so the read lock would never
    /// come; this delivery is part of the one the change waits for.
    #[cold]
    fn send_nested(&self, packet: Parcel<T>) {
        // SAFETY: only the owner thread gets here (its token is the sender's), inside
        // its delivery from `owned` (`busy` is set only there, by this thread): the
        // outer delivery holds a shared reference to it, and `owned` is written only
        // while `busy` is clear, so this second shared reference meets no write.
        let owned = unsafe { &*self.owned.get() };
        if let Some((_, list)) = owned {
            dispatch(list, packet);
        }
    }

    /// The owner's send to its cached snapshot; the packet back if the cache is not
    /// current (then nothing was delivered).
    #[inline]
    fn send_cached(&self, packet: Parcel<T>) -> Option<Parcel<T>> {
        self.busy.store(true, Ordering::Relaxed);
        // Cleared when the delivery ends, also by a panic in it (a converter's,
        // which the component's thread catches): a change waiting for `busy` would
        // otherwise wait for ever.
        let _idle = Idle(&self.busy);
        let asymmetric = light_fence();
        let version = self.version.load(if asymmetric {
            Ordering::Relaxed
        } else {
            Ordering::SeqCst
        });
        // SAFETY: only the owner thread gets here (its token is the sender's), and
        // not from inside one of its own deliveries on this output (`busy` was
        // clear): the only writer of `owned` is this thread, which writes it only
        // while `busy` is clear, so no write happens while this reference lives.
        let owned = unsafe { &*self.owned.get() };
        match owned {
            Some((cached, list)) if *cached == version => {
                dispatch(list, packet);
                None
            }
            _ => Some(packet),
        }
    }

    /// A send under the read lock. The owner caches the snapshot it read and marks
    /// itself `busy` before it lets the lock go, then delivers from its copy: a send
    /// nested in that delivery goes to the same copy ([`Sinks::send_nested`]), and a
    /// change waits for the delivery as for any from the copy.
    #[cold]
    fn send_locked(&self, core: &OutputCore, packet: Parcel<T>) {
        let list = read(&self.list);
        let sender = core.sender.load(Ordering::Relaxed);
        if sender == 0 || sender != token() {
            dispatch(&list, packet);
            return;
        }
        let version = self.version.load(Ordering::Relaxed);
        let snapshot = Arc::clone(&list);
        // SAFETY: this is the owner thread (its token is the sender's) and it is
        // not delivering from its copy (`busy` is clear: a send nested in such a
        // delivery went to `send_nested`, and `busy` is set only by this thread):
        // no other reference to `owned` exists while this one lives.
        let replaced = unsafe { &mut *self.owned.get() }.replace((version, snapshot));
        // Set while the read lock is held: a change, which takes the write lock
        // after this unlock, sees it and waits for the delivery below.
        self.busy.store(true, Ordering::Relaxed);
        let idle = Idle(&self.busy);
        drop(list);
        // SAFETY: the owner thread, with `busy` set: `owned` is not written until
        // it clears (the write above is over).
        if let Some((_, list)) = unsafe { &*self.owned.get() } {
            dispatch(list, packet);
        }
        drop(idle);
        // (The replaced snapshot is dropped after the delivery: dropping it may drop
        // the last handle of an input, and its packets, whose drop code may send
        // here.)
        drop(replaced);
    }
}

// SAFETY: `owned` is touched by one thread only (the module's doc and the uses'
// comments); the rest is `Sync` as the snapshot's `RwLock` and atomics are, for
// sinks that may be shared between threads.
unsafe impl<T> Sync for Sinks<T> where Arc<[Sink<T>]>: Send + Sync {}

thread_local! {
    /// This thread's token (0: not drawn yet).
    static TOKEN: Cell<u64> = const { Cell::new(0) };
}

/// The calling thread's token: a number no other thread of the process has.
#[inline]
pub(super) fn token() -> u64 {
    static NEXT: AtomicU64 = AtomicU64::new(1);
    TOKEN.with(|token| match token.get() {
        0 => {
            let drawn = NEXT.fetch_add(1, Ordering::Relaxed);
            token.set(drawn);
            drawn
        }
        drawn => drawn,
    })
}

/// Wait a little longer each round (a change waiting for a send in flight, a
/// revoked bias for a publish in flight: `slot.rs`).
pub(super) fn backoff(round: &mut u32) {
    *round += 1;
    if *round < 64 {
        std::hint::spin_loop();
    } else if *round < 80 {
        std::thread::yield_now();
    } else {
        std::thread::sleep(Duration::from_micros(50));
    }
}

static ASYMMETRIC: OnceLock<bool> = OnceLock::new();

/// Whether the process's threads can be fenced by `membarrier` (registered once).
#[inline]
fn asymmetric() -> bool {
    match ASYMMETRIC.get() {
        Some(registered) => *registered,
        None => *ASYMMETRIC.get_or_init(register),
    }
}

#[cfg(all(target_os = "linux", not(miri)))]
fn register() -> bool {
    use rustix::thread::{MembarrierCommand, MembarrierQuery, membarrier, membarrier_query};
    membarrier_query()
        .contains(MembarrierQuery::PRIVATE_EXPEDITED | MembarrierQuery::REGISTER_PRIVATE_EXPEDITED)
        && membarrier(MembarrierCommand::RegisterPrivateExpedited).is_ok()
        && membarrier(MembarrierCommand::PrivateExpedited).is_ok()
}

/// (Miri runs no `membarrier`: both fences are sequentially consistent ones there.)
#[cfg(any(not(target_os = "linux"), miri))]
fn register() -> bool {
    false
}

/// The sender's fence: between its store to `busy` and its load of the version.
/// Returns whether it was only a compiler fence (the heavy fence does the rest).
#[inline]
pub(super) fn light_fence() -> bool {
    if asymmetric() {
        compiler_fence(Ordering::SeqCst);
        true
    } else {
        fence(Ordering::SeqCst);
        false
    }
}

/// The change's fence: between its bump of the version and its load of `busy`.
pub(super) fn heavy_fence() {
    #[cfg(target_os = "linux")]
    if asymmetric() {
        use rustix::thread::{MembarrierCommand, membarrier};
        // Registered, the expedited command cannot fail (the kernel's contract); the
        // global one (slower: it waits for every CPU) orders the same threads.
        if membarrier(MembarrierCommand::PrivateExpedited).is_err() {
            let _ = membarrier(MembarrierCommand::Global);
        }
    }
    fence(Ordering::SeqCst);
}

impl OutputCore {
    /// Let the calling thread (a component's, or its execution group's) send on this
    /// output without the sinks' lock, if no thread was let before.
    pub(crate) fn claim_sends(&self) {
        // Register for `membarrier` before any send relies on it.
        let _ = asymmetric();
        let _ = self
            .sender
            .compare_exchange(0, token(), Ordering::AcqRel, Ordering::Acquire);
    }
}

#[cfg(test)]
mod tests {
    use std::time::Instant;

    use super::*;

    /// A data output of `u64` with two fifo inputs, the output connected to `a`
    /// through a converter that lets `gate` decide when packet 2 goes on.
    struct Rig {
        out: DataOut<u64>,
        a: FifoIn<u64>,
        b: FifoIn<u64>,
    }

    fn rig(gate: Option<(Sender<()>, Receiver<()>)>) -> Rig {
        let (out, a, b) = (
            DataOut::new(),
            FifoIn::new(16, OverflowPolicy::Reject),
            FifoIn::new(16, OverflowPolicy::Reject),
        );
        let convert = move |packet: &u64| {
            if *packet == 2
                && let Some((entered, release)) = &gate
            {
                let _ = entered.send(());
                let _ = release.recv_timeout(Duration::from_secs(30));
            }
            *packet
        };
        assert!(link_converted::<u64, u64>(
            &out.erased(),
            &a.erased(),
            Arc::new(convert)
        ));
        Rig { out, a, b }
    }

    fn relink(rig: &Rig) {
        assert!(relink_converted::<u64, u64>(
            &rig.out.erased(),
            Some(&rig.a.erased()),
            &rig.b.erased(),
            Arc::new(|packet: &u64| *packet),
        ));
    }

    /// A thread that owns `out` and sends each packet it receives.
    fn owner(out: &DataOut<u64>) -> (Sender<u64>, std::thread::JoinHandle<()>) {
        let (tx, rx) = crossbeam_channel::unbounded::<u64>();
        let out = out.clone();
        let thread = std::thread::spawn(move || {
            out.erased().core.claim_sends();
            for packet in rx {
                out.send(packet);
            }
        });
        (tx, thread)
    }

    fn poll_until(what: &str, mut done: impl FnMut() -> bool) {
        let deadline = Instant::now() + Duration::from_secs(30);
        while !done() {
            assert!(Instant::now() < deadline, "timed out waiting for {what}");
            std::thread::yield_now();
        }
    }

    #[test]
    fn a_relink_waits_for_the_owners_delivery_in_flight_and_moves_its_packet() {
        let (entered_tx, entered) = crossbeam_channel::bounded(1);
        let (release, release_rx) = crossbeam_channel::bounded(1);
        let rig = Arc::new(rig(Some((entered_tx, release_rx))));
        let (send, thread) = owner(&rig.out);
        // Packet 1 is sent under the lock (and the snapshot cached), packet 2 from the
        // cache: the converter holds it there.
        send.send(1).expect("owner alive");
        send.send(2).expect("owner alive");
        entered
            .recv_timeout(Duration::from_secs(30))
            .expect("packet 2 in the converter");
        let relinked = Arc::new(AtomicBool::new(false));
        let relinker = {
            let (rig, relinked) = (Arc::clone(&rig), Arc::clone(&relinked));
            std::thread::spawn(move || {
                relink(&rig);
                relinked.store(true, Ordering::Release);
            })
        };
        // The relink replaces the snapshot, then finds packet 2 on its way and waits.
        poll_until("the relink to wait or return", || {
            relinked.load(Ordering::Acquire)
                || rig.out.inner.sinks.waited.load(Ordering::Relaxed) > 0
        });
        assert!(
            !relinked.load(Ordering::Acquire),
            "the relink returned with a delivery in flight"
        );
        release.send(()).expect("converter waiting");
        relinker.join().expect("relinker");
        drop(send);
        thread.join().expect("owner");
        // Packet 2 reached `a` before the relink moved what `a` held: both at `b`.
        assert_eq!(rig.b.drain().collect::<Vec<_>>(), [1, 2]);
        assert!(rig.a.is_empty());
    }

    #[test]
    fn the_owners_next_send_follows_a_change_made_by_another_thread() {
        let rig = rig(None);
        let (send, thread) = owner(&rig.out);
        send.send(1).expect("owner alive");
        poll_until("packet 1 at a", || rig.a.len() == 1);
        // Cached now: the next send reads the version, sees the change, reads the new
        // snapshot.
        relink(&rig);
        send.send(2).expect("owner alive");
        poll_until("packet 2 at b", || rig.b.len() == 2);
        rig.out.erased().unlink(&rig.b.erased());
        send.send(3).expect("owner alive");
        send.send(4).expect("owner alive");
        drop(send);
        thread.join().expect("owner");
        assert_eq!(rig.b.drain().collect::<Vec<_>>(), [1, 2]);
        assert!(rig.a.is_empty());
    }

    /// Connects `out` to `a` through a converter that, converting packet 2, sends
    /// packet 10 on `out` (after `gate`'s signal and release, if given). Returns the
    /// converter's handle of `out`: emptied at the end of the test, or the output and
    /// its converter keep each other alive.
    fn resending(
        out: &DataOut<u64>,
        a: &FifoIn<u64>,
        gate: Option<(Sender<()>, Receiver<()>)>,
    ) -> Arc<Mutex<Option<DataOut<u64>>>> {
        let again = Arc::new(Mutex::new(None::<DataOut<u64>>));
        let inner = Arc::clone(&again);
        let convert = move |packet: &u64| {
            if *packet == 2 {
                if let Some((entered, release)) = &gate {
                    let _ = entered.send(());
                    let _ = release.recv_timeout(Duration::from_secs(30));
                }
                if let Some(out) = inner.lock().expect("the output").as_ref() {
                    out.send(10);
                }
            }
            *packet
        };
        assert!(link_converted::<u64, u64>(
            &out.erased(),
            &a.erased(),
            Arc::new(convert)
        ));
        *again.lock().expect("the output") = Some(out.clone());
        again
    }

    #[test]
    fn a_send_nested_in_the_owners_delivery_keeps_the_owners_copy() {
        // The converter to `a` sends packet 10 on the output it is delivering for,
        // each time it converts packet 2: both times nested in a delivery from the
        // owner's copy (packet 1 cached it).
        let (out, a) = (
            DataOut::<u64>::new(),
            FifoIn::new(16, OverflowPolicy::Reject),
        );
        let nested = resending(&out, &a, None);
        let (send, thread) = owner(&out);
        for packet in [1, 2, 3, 2] {
            send.send(packet).expect("owner alive");
        }
        drop(send);
        thread.join().expect("owner");
        // The nested packet arrives before the one whose conversion sent it.
        assert_eq!(a.drain().collect::<Vec<u64>>(), [1, 10, 2, 3, 10, 2]);
        nested.lock().expect("the output").take();
    }

    #[test]
    fn a_send_nested_in_the_owners_delivery_from_its_copy_does_not_wait_for_a_relink() {
        // Packet 1 caches the snapshot: packet 2 goes from the owner's copy.
        nested_send_during_a_relink(&[1], &[1, 10, 2]);
    }

    #[test]
    fn a_send_nested_in_the_owners_first_delivery_does_not_wait_for_a_relink() {
        // Packet 2 is the first: the owner reads the snapshot under the lock.
        nested_send_during_a_relink(&[], &[10, 2]);
    }

    /// The owner sends `before`, then packet 2, which the converter to `a` holds
    /// until released, then sends packet 10 on the same output. Meanwhile a relink
    /// replaces the snapshot and waits, under the write lock, for that delivery; the
    /// relink must return, and `b` hold `expected`.
    fn nested_send_during_a_relink(before: &[u64], expected: &[u64]) {
        let (entered_tx, entered) = crossbeam_channel::bounded(1);
        let (release, release_rx) = crossbeam_channel::bounded::<()>(1);
        let (out, a, b) = (
            DataOut::<u64>::new(),
            FifoIn::<u64>::new(16, OverflowPolicy::Reject),
            FifoIn::<u64>::new(16, OverflowPolicy::Reject),
        );
        let again = resending(&out, &a, Some((entered_tx, release_rx)));
        let (send, thread) = owner(&out);
        for packet in before.iter().chain(&[2]) {
            send.send(*packet).expect("owner alive");
        }
        entered
            .recv_timeout(Duration::from_secs(30))
            .expect("packet 2 in the converter");
        let relinked = Arc::new(AtomicBool::new(false));
        let relinker = {
            let (out, a, b, relinked) = (out.clone(), a.clone(), b.clone(), Arc::clone(&relinked));
            std::thread::spawn(move || {
                assert!(relink_converted::<u64, u64>(
                    &out.erased(),
                    Some(&a.erased()),
                    &b.erased(),
                    Arc::new(|packet: &u64| *packet),
                ));
                relinked.store(true, Ordering::Release);
            })
        };
        poll_until("the relink to wait for the delivery", || {
            out.inner.sinks.waited.load(Ordering::Relaxed) > 0
        });
        release.send(()).expect("converter waiting");
        // Deadlocked, the relink would never return: the nested send waiting for the
        // read lock, the relink for the delivery that sends it. (Had the delivery
        // held the read lock, the relink would not have reached its wait above.)
        poll_until("the relink to return", || relinked.load(Ordering::Acquire));
        relinker.join().expect("relinker");
        drop(send);
        thread.join().expect("owner");
        again.lock().expect("the output").take();
        // Every delivery was in flight before the relink moved what `a` held.
        assert_eq!(b.drain().collect::<Vec<u64>>(), expected);
        assert!(a.is_empty());
    }

    #[test]
    fn a_panic_in_the_owners_delivery_leaves_no_change_waiting() {
        let (out, a) = (
            DataOut::<u64>::new(),
            FifoIn::new(16, OverflowPolicy::Reject),
        );
        let convert = |packet: &u64| {
            assert!(*packet != 2, "a converter that panics on 2");
            *packet
        };
        assert!(link_converted::<u64, u64>(
            &out.erased(),
            &a.erased(),
            Arc::new(convert)
        ));
        let owner = {
            let out = out.clone();
            std::thread::spawn(move || {
                out.erased().core.claim_sends();
                // Packet 1 under the lock (the snapshot cached), 2 from the cache:
                // its converter panics, and the thread catches it, as a
                // component's thread does.
                out.send(1);
                let caught = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| out.send(2)));
                assert!(caught.is_err(), "the converter panicked");
                out.send(3);
            })
        };
        owner.join().expect("owner");
        // A change waits for the owner's delivery in flight: there is none.
        let unlinked = Arc::new(AtomicBool::new(false));
        let changer = {
            let (out, a, unlinked) = (out.clone(), a.clone(), Arc::clone(&unlinked));
            std::thread::spawn(move || {
                out.erased().unlink(&a.erased());
                unlinked.store(true, Ordering::Release);
            })
        };
        poll_until("the unlink to return", || unlinked.load(Ordering::Acquire));
        changer.join().expect("changer");
        assert_eq!(a.drain().collect::<Vec<u64>>(), [1, 3]);
    }

    #[test]
    fn a_watcher_is_told_of_each_change_after_it_is_made_and_may_send() {
        let rig = rig(None);
        // What the output feeds, seen by the watcher, and a packet it sends then: the
        // change is over (no lock of the output held), so the packet goes to the
        // input the change made.
        let seen = Arc::new(Mutex::new(Vec::new()));
        {
            // Held weakly, as a watcher should hold its output.
            let (output, seen) = (Arc::downgrade(&rig.out.inner), Arc::clone(&seen));
            rig.out.on_change(move || {
                let Some(inner) = output.upgrade() else {
                    return;
                };
                let out = DataOut { inner };
                let consumers = out.consumers();
                lock(&seen).push(consumers);
                out.send(100 + consumers as u64);
            });
        }
        rig.out.send(1);
        assert!(lock(&seen).is_empty(), "a send is no change");
        relink(&rig);
        assert_eq!(*lock(&seen), [1]);
        rig.out.erased().unlink(&rig.b.erased());
        assert_eq!(*lock(&seen), [1, 0]);
        // Packet 1, queued at `a`, moved to `b` by the relink before the watcher's.
        assert_eq!(rig.a.drain().count(), 0);
        assert_eq!(rig.b.drain().collect::<Vec<u64>>(), [1, 101]);
    }
}
