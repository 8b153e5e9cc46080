//! Waking a component's thread: its [`Doorbell`], rung by commands, arrivals and pull
//! requests, and the [`Waker`] that hands a ring to code outside the runtime; its
//! words (`words`) live in memory another process on this host can map, which rings
//! it through a [`RemoteBell`]. The bottom layer: it uses nothing of the crate.

mod words;

use std::sync::Arc;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use words::Pair;
pub use words::{BellAddress, RemoteBell};

/// The wake-up of one component thread: rung by every command, every delivery to its
/// inputs and every pull request to its outputs; the thread clears it at the start of
/// each turn and waits on it when a turn finds nothing to do.
///
/// One atomic state: `QUIET` (cleared, the thread is looking or spinning), `RUNG`, or
/// `SLEEPING` (the thread sleeps or is about to). A ringer swaps in `RUNG` and wakes
/// the thread only if it took `SLEEPING` away, so a ring while the thread is busy or
/// spinning touches no other cache line (each bell's words are alone on theirs in
/// the shared mapping; not on the heap, where they are when there is no mapping).
///
/// Why no wake-up is lost (the classic lost-wakeup race: a ringer sees the bell already
/// rung and skips the wake-up, while the thread has just cleared it and is about to look
/// at stale state, then sleeps):
///
/// - The thread's turn is: `clear` (a `SeqCst` swap to `QUIET`), then look at
///   everything (control queue, arrival counters, pull queues), then, if nothing was
///   found, wait: `spin` returns as soon as it sees `RUNG`; `park_until` moves
///   `QUIET` to `SLEEPING` by compare-and-swap (failing, and returning, if a ring came),
///   then sleeps while the state is `SLEEPING`: a futex wait on the state word, which
///   the kernel lets sleep only if the word still holds `SLEEPING` when it queues the
///   thread (elsewhere, a park: an unpark before it leaves a token that makes it
///   return at once). A ringer that
///   swaps `SLEEPING` away wakes the word (or the group's word: `park_any`), so the
///   thread cannot sleep through a ring that came after its `clear`: the ring either
///   changed the word before the wait (which then returns at once) or wakes the
///   thread queued on it. A wait may also return for nothing (a signal, a spurious
///   wake-up): `park_until` rechecks the state after every return.
/// - [`Doorbell::ring_strong`] (commands, pull requests: their payload is in a channel)
///   always swaps. A swap reads the newest value: if it reads `QUIET`, the thread has
///   not begun to sleep and will see `RUNG` (its compare-and-swap fails); if
///   `SLEEPING`, this ringer wakes it; if `RUNG`, the thread's next `clear` reads this
///   swap's write (or a later one: every write that follows a `RUNG` is a swap or a
///   compare-and-swap), synchronises with it, and the look that follows sees the
///   queued payload.
/// - [`Doorbell::ring`] (arrivals, the per-packet path) first does a plain load and
///   skips the swap when it reads `RUNG`. A plain load may read a stale `RUNG` that a
///   `clear` has already overwritten (only a `clear` turns `RUNG` into anything else);
///   that is what makes the race possible in general. Here the arrival counter's
///   increment, this load, the thread's `clear` and its load of the counter are all
///   `SeqCst`, so they fall in one total order: a load that reads a `RUNG` older than a
///   `clear` comes before that `clear` in the order, hence the increment (before the
///   load in program order) comes before the `clear` and before the thread's load of
///   the counter after it, which therefore sees the increment. If the load reads a
///   `RUNG` written after the thread's last `clear`, that ring makes the thread run
///   another turn, whose `clear` and look come after it, by the same argument. On
///   x86-64 and AArch64 a `SeqCst` load costs the same as an acquire load, so the fast
///   path stays one load of a cache line that stays shared while the consumer is busy.
///
/// Waiting sleeps on the state word itself (a futex on Linux, `std::thread::park`
/// elsewhere), or, for a member of an execution group, on the group's word, which a
/// ringer that took `SLEEPING` away sets and wakes (`Doorbell::park_any`); the word
/// it sleeps on is written beside the state, so that a ringer in another process
/// ([`RemoteBell`]) wakes the right one. With a timer due, it sleeps at once, so a
/// periodic component sleeps like a thread in `nanosleep` and never yields its core
/// to another process before its deadline; waiting for input
/// only, it first spins briefly on the state, then yields a few times (as a
/// crossbeam-channel `recv` does before it parks), so that a packet that comes back
/// within a few microseconds costs no futex wake-up.
pub(crate) struct Doorbell {
    /// The state, and the index of the word the thread sleeps on.
    words: Pair,
    /// Set after a command is queued on the component's control queue, before the
    /// ring ([`Doorbell::ring_command`]): a turn reads the control queue only when it
    /// finds it set, so a turn rung by an arrival touches none of the queue's cache
    /// lines. Why no command is missed: the sender's store comes after its push and
    /// before its ring, all `SeqCst` with the thread's `clear` and its load here. A
    /// load that reads `false` comes before the store in their total order, so the
    /// ring comes after the `clear` and the next wait returns at once; the next turn's
    /// load comes after the ring, sees the mark, and the queue holds the command.
    commands: AtomicBool,
    /// The thread that waits on it, once it runs (unparked where there is no futex).
    thread: OnceLock<std::thread::Thread>,
    /// The word of the execution group whose thread waits on it, if it is a member's.
    group: OnceLock<Arc<GroupWord>>,
    /// What the thread drains at the start of a rung turn ([`Source`]): made when
    /// the first is added (most bells never have one).
    sources: OnceLock<Box<Sources>>,
}

/// Work that reaches a component other than through its ports' own queues: packets
/// another process left in shared memory, say, which it then rings the component's
/// bell for ([`RemoteBell::ring`]). The component's thread drains each of its
/// sources at the start of every turn its bell rang for, before it looks at its
/// control port and inputs, and asks them whether they have anything while it
/// polls for work instead of sleeping. Added with [`ConsumerBell::add_source`]. A
/// source that panics is removed (and the panic logged); the component goes on.
pub trait Source: Send + Sync {
    /// Whether it has anything to drain (cheap: called while the thread polls).
    fn ready(&self) -> bool;

    /// Deliver what it has, on the component's thread (to an output connected to
    /// the component's input: the packets are then at the input for this turn). It
    /// must not wait: the thread that would empty a full input is this one. Leave
    /// what does not fit for the next turn (stop when the output
    /// [`would_wait`](crate::port::DataOut::would_wait)), and ring the bell again
    /// when it is to be drained.
    fn drain(&self);
}

/// The doorbell of the one component an output feeds ([`DataOut::consumer_bell`](crate::port::DataOut::consumer_bell)):
/// where another process on this host rings it, and the sources its thread drains.
#[derive(Clone)]
pub struct ConsumerBell {
    pub(crate) bell: Arc<Doorbell>,
}

impl std::fmt::Debug for ConsumerBell {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ConsumerBell")
            .field("address", &self.address())
            .finish_non_exhaustive()
    }
}

impl ConsumerBell {
    /// Where a process on this host rings it ([`RemoteBell::open`]); None where that
    /// cannot be (not on Linux, or its words are not in shared memory).
    pub fn address(&self) -> Option<BellAddress> {
        self.bell.address()
    }

    /// Drain `source` at the start of the component's rung turns, until the returned
    /// guard is dropped (a drain or a `ready` the thread has begun may still run once
    /// after); the bell is rung once, so that what it has now is seen.
    pub fn add_source(&self, source: Arc<dyn Source>) -> SourceGuard {
        self.bell.change_sources(|sources| {
            sources.push(Arc::clone(&source));
        });
        self.bell.ring_strong();
        SourceGuard {
            bell: Arc::clone(&self.bell),
            source,
        }
    }
}

/// A source added to a component's bell ([`ConsumerBell::add_source`]): removed when
/// dropped.
pub struct SourceGuard {
    bell: Arc<Doorbell>,
    source: Arc<dyn Source>,
}

impl std::fmt::Debug for SourceGuard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SourceGuard").finish_non_exhaustive()
    }
}

impl Drop for SourceGuard {
    fn drop(&mut self) {
        self.bell
            .change_sources(|sources| sources.retain(|s| !Arc::ptr_eq(s, &self.source)));
    }
}

/// A bell's sources, as a list replaced whole when one is added or removed (the
/// thread takes the list and lets the lock go before it calls any), and whether there
/// is any (read first, so that a bell whose sources are gone takes no lock).
struct Sources {
    list: std::sync::Mutex<Arc<[Arc<dyn Source>]>>,
    any: AtomicBool,
}

/// The word an execution group's thread sleeps on: every member's ringer that takes
/// `SLEEPING` away sets it to `RUNG` and wakes it ([`Doorbell::park_any`]).
pub(crate) struct GroupWord(Pair);

impl GroupWord {
    pub(crate) fn new() -> Arc<GroupWord> {
        Arc::new(GroupWord(Pair::new(QUIET)))
    }
}

const QUIET: u32 = 0;
const RUNG: u32 = 1;
const SLEEPING: u32 = 2;

/// Spin rounds (`2^k` spin hints each, `k` below this) before parking when no timer is
/// due: 127 hints, about a microsecond.
const SPIN_ROUNDS: u32 = 7;

/// `yield_now` rounds after the spin rounds, before parking, when no timer is due.
const YIELD_ROUNDS: u32 = 4;

impl Doorbell {
    pub(crate) fn new() -> Arc<Doorbell> {
        Arc::new(Doorbell {
            words: Pair::new(QUIET),
            commands: AtomicBool::new(false),
            thread: OnceLock::new(),
            group: OnceLock::new(),
            sources: OnceLock::new(),
        })
    }

    /// Replace the list of sources by `change` of it.
    fn change_sources(&self, change: impl FnOnce(&mut Vec<Arc<dyn Source>>)) {
        let sources = self.sources.get_or_init(|| {
            Box::new(Sources {
                list: std::sync::Mutex::new(Arc::from(Vec::new())),
                any: AtomicBool::new(false),
            })
        });
        let mut shared = sources
            .list
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let mut list = shared.to_vec();
        change(&mut list);
        sources.any.store(!list.is_empty(), Ordering::SeqCst);
        *shared = Arc::from(list);
    }

    /// The sources now, if any (the lock is let go before any is called: a source
    /// may add or remove one).
    #[inline]
    fn sources_now(&self) -> Option<Arc<[Arc<dyn Source>]>> {
        let sources = self.sources.get()?;
        if !sources.any.load(Ordering::Acquire) {
            return None;
        }
        Some(Arc::clone(
            &sources
                .list
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner),
        ))
    }

    /// Call `f` on `source` on the component's thread: a panic removes the source.
    fn call_source<R>(
        &self,
        source: &Arc<dyn Source>,
        f: impl FnOnce(&dyn Source) -> R,
    ) -> Option<R> {
        match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| f(&**source))) {
            Ok(result) => Some(result),
            Err(_) => {
                // (The panic hook has logged the panic itself.)
                tracing::error!("a source of a component's work panicked: it is removed");
                self.change_sources(|sources| sources.retain(|s| !Arc::ptr_eq(s, source)));
                None
            }
        }
    }

    /// Drain every source (at the start of a rung turn, on the component's thread).
    #[inline]
    pub(crate) fn drain_sources(&self) {
        if let Some(sources) = self.sources_now() {
            for source in sources.iter() {
                self.call_source(source, |source| source.drain());
            }
        }
    }

    /// Whether a source has anything (the thread polls for work).
    #[inline]
    pub(crate) fn sources_ready(&self) -> bool {
        self.sources_now().is_some_and(|sources| {
            sources
                .iter()
                .any(|source| self.call_source(source, |source| source.ready()) == Some(true))
        })
    }

    /// The word a turn reads first (whether the bell rang): in the process's mapping
    /// of bells, not beside the rest of the doorbell. An execution group asks the
    /// processor to fetch it before its members' turns (`crate::runner::group`).
    pub(crate) fn state(&self) -> &std::sync::atomic::AtomicU32 {
        self.words.state()
    }

    /// Called by the component's thread before its first turn.
    pub(crate) fn attach(&self) {
        let _ = self.thread.set(std::thread::current());
    }

    /// Called by an execution group's thread, for each member, before its first
    /// pass: the thread sleeps on `group`'s word.
    pub(crate) fn attach_to_group(&self, group: &Arc<GroupWord>) {
        let _ = self.thread.set(std::thread::current());
        self.words.sleep_on(&group.0);
        let _ = self.group.set(Arc::clone(group));
    }

    /// Where a process on this host rings it ([`RemoteBell::open`]): None if its
    /// words are not in shared memory (not on Linux, or no mapping could be made),
    /// or if it is a member of a group whose word is not.
    pub(crate) fn address(&self) -> Option<BellAddress> {
        if let Some(group) = self.group.get()
            && group.0.state_index().is_none()
        {
            return None;
        }
        self.words.address()
    }

    /// Ring after a `SeqCst` increment of an arrival counter (see the type's doc).
    #[inline]
    pub(crate) fn ring(&self) {
        if self.state().load(Ordering::SeqCst) != RUNG {
            self.ring_strong();
        }
    }

    /// Ring after queueing a command or a pull request.
    #[inline]
    pub(crate) fn ring_strong(&self) {
        if self.state().swap(RUNG, Ordering::SeqCst) == SLEEPING {
            self.wake_sleeper();
        }
    }

    /// The thread sleeps (a ring took `SLEEPING` away): wake it.
    #[cold]
    fn wake_sleeper(&self) {
        #[cfg(target_os = "linux")]
        match self.group.get() {
            Some(group) => {
                group.0.state().store(RUNG, Ordering::SeqCst);
                words::wake(group.0.state());
            }
            None => words::wake(self.state()),
        }
        #[cfg(not(target_os = "linux"))]
        if let Some(thread) = self.thread.get() {
            thread.unpark();
        }
    }

    /// Ring after queueing a command on the component's control queue.
    #[inline]
    pub(crate) fn ring_command(&self) {
        self.commands.store(true, Ordering::SeqCst);
        self.ring_strong();
    }

    /// Whether a command was queued since the last call that said so (then the mark
    /// is cleared: the caller reads the control queue until it is empty).
    #[inline]
    pub(crate) fn take_commands(&self) -> bool {
        self.commands.load(Ordering::SeqCst) && self.commands.swap(false, Ordering::SeqCst)
    }

    /// The thread starts a turn: rings from now on wake it again.
    #[inline]
    pub(crate) fn clear(&self) {
        self.state().swap(QUIET, Ordering::SeqCst);
    }

    /// Whether anything rang since the last `clear` (may read a stale `QUIET`: a wait
    /// that follows is still woken).
    #[inline]
    pub(crate) fn is_rung(&self) -> bool {
        self.state().load(Ordering::SeqCst) == RUNG
    }

    /// Spin, then yield, briefly, until rung: true if it rang (on the component's
    /// thread, before `park_until` when no timer is due).
    pub(crate) fn spin(&self) -> bool {
        for round in 0..SPIN_ROUNDS {
            if self.is_rung() {
                return true;
            }
            for _ in 0..1u32 << round {
                std::hint::spin_loop();
            }
        }
        for _ in 0..YIELD_ROUNDS {
            if self.is_rung() {
                return true;
            }
            std::thread::yield_now();
        }
        self.is_rung()
    }

    /// Sleep until rung or until `deadline` (on the component's thread).
    pub(crate) fn park_until(&self, deadline: Option<Instant>) {
        let state = self.state();
        if state
            .compare_exchange(QUIET, SLEEPING, Ordering::SeqCst, Ordering::SeqCst)
            .is_err()
        {
            return; // Rung since the turn's `clear`.
        }
        loop {
            if deadline.is_some_and(|deadline| Instant::now() >= deadline) {
                // Back to `QUIET`, unless a ring came meanwhile (then `RUNG` stays for
                // the next turn's `clear`).
                let _ = state.compare_exchange(SLEEPING, QUIET, Ordering::SeqCst, Ordering::SeqCst);
                return;
            }
            words::sleep(state, SLEEPING, deadline);
            if state.load(Ordering::SeqCst) != SLEEPING {
                return;
            }
        }
    }

    /// Sleep until any of `bells` rings or until `deadline`: the thread of an
    /// execution group (`crate::runner::group`), to which every one of its members'
    /// bells is attached with `group` ([`Doorbell::attach_to_group`]). Every bell goes
    /// from `QUIET` to `SLEEPING` before the thread sleeps (one found `RUNG` returns at
    /// once); the thread sleeps on the group's word, which a ringer that takes
    /// `SLEEPING` away from a bell sets to `RUNG` before it wakes it. No ring is lost:
    /// the thread sets the word to `SLEEPING` before it looks at the bells, and sleeps
    /// only while the word still says so; a ring that a look missed came after it, so
    /// its ringer's store of `RUNG` comes after the thread's store of `SLEEPING`, and
    /// the sleep returns (at once, or woken). On return every bell still `SLEEPING`
    /// goes back to `QUIET`, so that a ring while the group works is a plain store,
    /// never a wake-up.
    pub(crate) fn park_any(bells: &[&Doorbell], group: &GroupWord, deadline: Option<Instant>) {
        let word = group.0.state();
        let asleep = bells.iter().all(|bell| {
            bell.state()
                .compare_exchange(QUIET, SLEEPING, Ordering::SeqCst, Ordering::SeqCst)
                != Err(RUNG)
        });
        if asleep {
            loop {
                word.store(SLEEPING, Ordering::SeqCst);
                if bells
                    .iter()
                    .any(|bell| bell.state().load(Ordering::SeqCst) != SLEEPING)
                    || deadline.is_some_and(|deadline| Instant::now() >= deadline)
                {
                    break;
                }
                words::sleep(word, SLEEPING, deadline);
            }
        }
        for bell in bells {
            let _ =
                bell.state()
                    .compare_exchange(SLEEPING, QUIET, Ordering::SeqCst, Ordering::SeqCst);
        }
    }
}

/// Rings a component's doorbell: the thread wakes and looks for work (see
/// [`Context::waker`](crate::Context::waker)).
#[derive(Clone)]
pub struct Waker {
    pub(crate) bell: Arc<Doorbell>,
}

impl std::fmt::Debug for Waker {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Waker").finish_non_exhaustive()
    }
}

impl Waker {
    /// Wake the component's thread (a no-op if it is already due to wake).
    pub fn wake(&self) {
        self.bell.ring_strong();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_a_command_ring_marks_commands_and_taking_the_mark_clears_it() {
        let bell = Doorbell::new();
        assert!(!bell.take_commands());
        // An arrival's ring and a pull request's leave no mark.
        bell.ring();
        bell.ring_strong();
        assert!(bell.is_rung());
        assert!(!bell.take_commands());
        bell.clear();
        // A command's ring marks it, once however many came.
        bell.ring_command();
        bell.ring_command();
        assert!(bell.is_rung());
        assert!(bell.take_commands());
        assert!(!bell.take_commands());
    }

    /// The environment variable that gives [`ring_from_a_child`] the bell to ring.
    #[cfg(target_os = "linux")]
    const RING: &str = "COOLBOT_TEST_RING";

    /// Run `ring_from_a_child` in another process (this test binary again), ringing
    /// `address`, and wait for it to end.
    #[cfg(target_os = "linux")]
    fn ring_from_another_process(address: BellAddress) {
        let status = std::process::Command::new(std::env::current_exe().unwrap())
            .args([
                "--ignored",
                "--exact",
                "wake::tests::ring_from_a_child",
                "--test-threads=1",
            ])
            .env(
                RING,
                format!(
                    "{} {} {} {}",
                    address.pid, address.fd, address.nonce, address.pair
                ),
            )
            .stdout(std::process::Stdio::null())
            .status()
            .unwrap();
        assert!(status.success(), "the ringing process failed: {status}");
    }

    /// The other process of the remote-ring tests: rings the bell its environment
    /// names.
    #[cfg(target_os = "linux")]
    #[test]
    #[ignore = "run by the remote-ring tests, in a process of their own"]
    fn ring_from_a_child() {
        let given = std::env::var(RING).expect("run by a remote-ring test");
        let numbers: Vec<&str> = given.split(' ').collect();
        let address = BellAddress {
            pid: numbers[0].parse().unwrap(),
            fd: numbers[1].parse().unwrap(),
            nonce: numbers[2].parse().unwrap(),
            pair: numbers[3].parse().unwrap(),
        };
        RemoteBell::open(&address).unwrap().ring();
    }

    /// Whether `bell` was rung when a thread asleep on it woke: the thread parks on
    /// it, and once it sleeps `ring` is called.
    #[cfg(target_os = "linux")]
    fn thread_woken_by(bell: &Arc<Doorbell>, ring: impl FnOnce()) -> bool {
        let (woke, woken) = std::sync::mpsc::channel();
        let sleeper = {
            let bell = Arc::clone(bell);
            std::thread::spawn(move || {
                bell.attach();
                bell.park_until(None);
                woke.send(bell.is_rung()).unwrap();
            })
        };
        // Asleep (or about to be: a ring before the sleep returns it at once).
        while bell.state().load(Ordering::SeqCst) != SLEEPING {
            std::thread::yield_now();
        }
        ring();
        let rung = woken
            .recv_timeout(std::time::Duration::from_secs(60))
            .expect("woken by the ring");
        sleeper.join().unwrap();
        rung
    }

    /// Which of `first` and `second` were rung when a group's thread asleep on both
    /// (through `word`) woke: once it sleeps `ring` is called.
    #[cfg(target_os = "linux")]
    fn group_woken_by(
        (first, second): (&Arc<Doorbell>, &Arc<Doorbell>),
        word: &Arc<GroupWord>,
        ring: impl FnOnce(),
    ) -> (bool, bool) {
        let (woke, woken) = std::sync::mpsc::channel();
        let group = {
            let (first, second, word) = (Arc::clone(first), Arc::clone(second), Arc::clone(word));
            std::thread::spawn(move || {
                first.attach_to_group(&word);
                second.attach_to_group(&word);
                Doorbell::park_any(&[&first, &second], &word, None);
                woke.send((first.is_rung(), second.is_rung())).unwrap();
            })
        };
        while word.0.state().load(Ordering::SeqCst) != SLEEPING
            || second.state().load(Ordering::SeqCst) != SLEEPING
        {
            std::thread::yield_now();
        }
        ring();
        let rung = woken
            .recv_timeout(std::time::Duration::from_secs(60))
            .expect("woken by the ring");
        group.join().unwrap();
        rung
    }

    /// A thread asleep on its bell is woken by a ring from another process, and only
    /// by a ring: the bell is `RUNG` when it returns.
    #[cfg(target_os = "linux")]
    #[test]
    fn another_process_wakes_a_thread_asleep_on_its_bell() {
        let bell = Doorbell::new();
        let address = bell.address().expect("the bell is in shared memory");
        assert!(thread_woken_by(&bell, || ring_from_another_process(
            address
        )));
    }

    /// The same for a member of an execution group: the ringer wakes the group's
    /// thread, asleep on the group's word.
    #[cfg(target_os = "linux")]
    #[test]
    fn another_process_wakes_a_group_asleep_on_a_members_bell() {
        let (first, second) = (Doorbell::new(), Doorbell::new());
        let address = second.address().expect("the bell is in shared memory");
        let rung = group_woken_by((&first, &second), &GroupWord::new(), || {
            ring_from_another_process(address);
        });
        assert_eq!(rung, (false, true));
    }

    /// The environment variable that makes [`on_the_heap`] run (in a process of its
    /// own: it takes every bell of the process's mapping).
    #[cfg(target_os = "linux")]
    const HEAP: &str = "COOLBOT_TEST_HEAP_BELLS";

    /// Bells on the heap (the process's mapping of bells is full, or none could be
    /// made: they are what a process off Linux has) ring, wake and group as mapped
    /// ones; [`on_the_heap`], in another process.
    #[cfg(target_os = "linux")]
    #[test]
    fn bells_on_the_heap_wake_a_thread_and_a_group() {
        let output = std::process::Command::new(std::env::current_exe().unwrap())
            .args([
                "--ignored",
                "--exact",
                "wake::tests::on_the_heap",
                "--test-threads=1",
            ])
            .env(HEAP, "1")
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&output.stdout);
        assert!(
            output.status.success(),
            "the process with bells on the heap failed: {}\n{stdout}\n{}",
            output.status,
            String::from_utf8_lossy(&output.stderr)
        );
        assert!(stdout.contains("1 passed"), "{stdout}");
    }

    /// The other process of [`bells_on_the_heap_wake_a_thread_and_a_group`]: takes
    /// every pair of the mapping, then checks the heap's bells.
    #[cfg(target_os = "linux")]
    #[test]
    #[ignore = "run by bells_on_the_heap_wake_a_thread_and_a_group, in a process of its own"]
    fn on_the_heap() {
        assert!(std::env::var_os(HEAP).is_some(), "run by its test");
        // Every pair of the mapping taken: the next bells are on the heap.
        let mut mapped = Vec::new();
        let heap = loop {
            let bell = Doorbell::new();
            if bell.address().is_none() {
                break bell;
            }
            mapped.push(bell);
        };
        // No mapping could be made here (no memfd): every bell is on the heap, and
        // what is about the mapping is not checked.
        let has_mapping = !mapped.is_empty();
        if has_mapping {
            assert_eq!(mapped.len(), (words::PAIRS_IN_A_MAPPING - 1) as usize);
        }
        // A thread asleep on a bell on the heap is woken by a ring.
        assert!(thread_woken_by(&heap, || heap.ring()), "woken by the ring");

        // A group on the heap (its word and its members' bells): a ring of the second
        // member wakes the thread, asleep on the group's word.
        let (first, second, word) = (Doorbell::new(), Doorbell::new(), GroupWord::new());
        assert!(first.address().is_none() && second.address().is_none());
        let rung = group_woken_by((&first, &second), &word, || second.ring());
        assert_eq!(rung, (false, true));

        if !has_mapping {
            return;
        }
        // A bell of the mapping in a group whose word is on the heap: no other process
        // could wake the group's thread through it, so it gives no address.
        drop(mapped.pop());
        let member = Doorbell::new();
        assert!(
            member.address().is_some(),
            "a pair given back is taken again"
        );
        member.attach_to_group(&word);
        assert!(member.address().is_none());
    }

    /// A ringer that names a mapping that is not the one it was told of (another
    /// nonce: a process that ended and whose pid was taken) is refused.
    #[cfg(target_os = "linux")]
    #[test]
    fn a_bell_address_with_another_nonce_is_refused() {
        let bell = Doorbell::new();
        let mut address = bell.address().unwrap();
        assert!(RemoteBell::open(&address).is_ok());
        address.nonce ^= 1;
        let refused = RemoteBell::open(&address).unwrap_err();
        assert_eq!(refused.kind(), std::io::ErrorKind::NotFound, "{refused}");
        address.nonce ^= 1;
        address.pair = 0;
        assert!(RemoteBell::open(&address).is_err(), "the header is no bell");
    }
}
