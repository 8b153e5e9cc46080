//! Waking a component's thread: its [`Doorbell`], rung by commands, arrivals and pull
//! requests, and the [`Waker`] that hands a ring to code outside the runtime. The
//! bottom layer: it uses nothing of the crate.

use std::sync::Arc;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, AtomicU8, Ordering};
use std::time::Instant;

/// The wake-up of one component thread: rung by every command, every delivery to its
/// inputs and every pull request to its outputs; the thread clears it at the start of
/// each turn and waits on it when a turn finds nothing to do.
///
/// One atomic state: `QUIET` (cleared, the thread is looking or spinning), `RUNG`, or
/// `SLEEPING` (the thread is parked or about to park). A ringer swaps in `RUNG` and
/// unparks the thread only if it took `SLEEPING` away, so a ring while the thread is
/// busy or spinning touches no other cache line.
///
/// Why no wake-up is lost (the classic lost-wakeup race: a ringer sees the bell already
/// rung and skips the wake-up, while the thread has just cleared it and is about to look
/// at stale state, then sleeps):
///
/// - The thread's turn is: `clear` (a `SeqCst` swap to `QUIET`), then look at
///   everything (control queue, arrival counters, pull queues), then, if nothing was
///   found, wait: `spin` returns as soon as it sees `RUNG`; `park_until` moves
///   `QUIET` to `SLEEPING` by compare-and-swap (failing, and returning, if a ring came),
///   then parks until the state is no longer `SLEEPING`. A ringer that swaps
///   `SLEEPING` away unparks the thread (an unpark before the park makes the park
///   return at once: the token persists), so the thread cannot sleep through a ring
///   that came after its `clear`. Other code on the thread that parks (channels) may
///   consume the token or wake spuriously: `park_until` rechecks the state after every
///   return from `park`, and so do those channels.
/// - [`Doorbell::ring_strong`] (commands, pull requests: their payload is in a channel)
///   always swaps. A swap reads the newest value: if it reads `QUIET`, the thread has
///   not begun to sleep and will see `RUNG` (its compare-and-swap fails); if
///   `SLEEPING`, this ringer unparks it; if `RUNG`, the thread's next `clear` reads this
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
/// Waiting parks the thread (`std::thread::park`/`park_timeout`): with a timer due,
/// it parks at once, so a periodic component sleeps like a thread in `nanosleep` and
/// never yields its core to another process before its deadline; waiting for input
/// only, it first spins briefly on the state, then yields a few times (as a
/// crossbeam-channel `recv` does before it parks), so that a packet that comes back
/// within a few microseconds costs no futex wake-up.
pub(crate) struct Doorbell {
    state: AtomicU8,
    /// Set after a command is queued on the component's control queue, before the
    /// ring ([`Doorbell::ring_command`]): a turn reads the control queue only when it
    /// finds it set, so a turn rung by an arrival touches none of the queue's cache
    /// lines. Why no command is missed: the sender's store comes after its push and
    /// before its ring, all `SeqCst` with the thread's `clear` and its load here. A
    /// load that reads `false` comes before the store in their total order, so the
    /// ring comes after the `clear` and the next wait returns at once; the next turn's
    /// load comes after the ring, sees the mark, and the queue holds the command.
    commands: AtomicBool,
    /// The component's thread, once it runs.
    thread: OnceLock<std::thread::Thread>,
}

const QUIET: u8 = 0;
const RUNG: u8 = 1;
const SLEEPING: u8 = 2;

/// Spin rounds (`2^k` spin hints each, `k` below this) before parking when no timer is
/// due: 127 hints, about a microsecond.
const SPIN_ROUNDS: u32 = 7;

/// `yield_now` rounds after the spin rounds, before parking, when no timer is due.
const YIELD_ROUNDS: u32 = 4;

impl Doorbell {
    pub(crate) fn new() -> Arc<Doorbell> {
        Arc::new(Doorbell {
            state: AtomicU8::new(QUIET),
            commands: AtomicBool::new(false),
            thread: OnceLock::new(),
        })
    }

    /// Called by the component's thread before its first turn.
    pub(crate) fn attach(&self) {
        let _ = self.thread.set(std::thread::current());
    }

    /// Ring after a `SeqCst` increment of an arrival counter (see the type's doc).
    #[inline]
    pub(crate) fn ring(&self) {
        if self.state.load(Ordering::SeqCst) != RUNG {
            self.ring_strong();
        }
    }

    /// Ring after queueing a command or a pull request.
    #[inline]
    pub(crate) fn ring_strong(&self) {
        if self.state.swap(RUNG, Ordering::SeqCst) == SLEEPING
            && let Some(thread) = self.thread.get()
        {
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
        self.state.swap(QUIET, Ordering::SeqCst);
    }

    /// Whether anything rang since the last `clear` (may read a stale `QUIET`: a wait
    /// that follows is still woken).
    #[inline]
    pub(crate) fn is_rung(&self) -> bool {
        self.state.load(Ordering::SeqCst) == RUNG
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

    /// Park until rung or until `deadline` (on the component's thread).
    pub(crate) fn park_until(&self, deadline: Option<Instant>) {
        if self
            .state
            .compare_exchange(QUIET, SLEEPING, Ordering::SeqCst, Ordering::SeqCst)
            .is_err()
        {
            return; // Rung since the turn's `clear`.
        }
        loop {
            match deadline {
                None => std::thread::park(),
                Some(deadline) => {
                    let now = Instant::now();
                    if now >= deadline {
                        // Back to `QUIET`, unless a ring came meanwhile (then `RUNG`
                        // stays for the next turn's `clear`).
                        let _ = self.state.compare_exchange(
                            SLEEPING,
                            QUIET,
                            Ordering::SeqCst,
                            Ordering::SeqCst,
                        );
                        return;
                    }
                    std::thread::park_timeout(deadline - now);
                }
            }
            if self.state.load(Ordering::SeqCst) != SLEEPING {
                return;
            }
        }
    }

    /// Park until any of `bells` rings or until `deadline`: the thread of an execution
    /// group (`crate::runner::group`), to which every one of its members' bells is
    /// attached. The protocol is each bell's own, applied to all: every bell goes from
    /// `QUIET` to `SLEEPING` before the thread parks (one found `RUNG` returns at
    /// once, a ring after its move unparks the thread), and on return every bell still
    /// `SLEEPING` goes back to `QUIET`, so that a ring while the group works is a plain
    /// store, never an unpark.
    pub(crate) fn park_any(bells: &[&Doorbell], deadline: Option<Instant>) {
        let mut asleep = true;
        for bell in bells {
            if let Err(RUNG) =
                bell.state
                    .compare_exchange(QUIET, SLEEPING, Ordering::SeqCst, Ordering::SeqCst)
            {
                asleep = false;
                break;
            }
        }
        while asleep {
            match deadline {
                None => std::thread::park(),
                Some(deadline) => {
                    let now = Instant::now();
                    if now >= deadline {
                        break;
                    }
                    std::thread::park_timeout(deadline - now);
                }
            }
            asleep = bells
                .iter()
                .all(|bell| bell.state.load(Ordering::SeqCst) == SLEEPING);
        }
        for bell in bells {
            let _ =
                bell.state
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
}
