//! Where a doorbell's words live, and how a thread sleeps on them: on Linux, in one
//! mapping of shared memory per process (a memfd), so that another process on this
//! host can ring a component's bell ([`RemoteBell`]) by mapping the same memory
//! through `/proc/<pid>/fd/<fd>` and waking the sleeping thread with a futex call,
//! which works across processes on shared memory. Elsewhere, or when the mapping
//! cannot be made, the words are on the heap and no other process reaches them.
//!
//! A bell takes a [`Pair`] of words, alone on a cache line of the mapping (a ring or a
//! clear of one bell never invalidates the line another's ringers read): its state,
//! and the index of the word its thread sleeps on, which another process's ringer
//! reads to know what to wake (the bell's own state word for a component's own
//! thread, the group's word for a member of an execution group). The mapping's first
//! line is its header: a magic number and a nonce drawn when the process made it,
//! which a [`BellAddress`] carries and [`RemoteBell::open`] checks, so that a ringer
//! never writes into a mapping that is not the one it was told of (a process that
//! ended and whose pid was taken). A ringer writes only a bell's line, and wakes only
//! a state word (the index it reads is checked to be one). A ringer that keeps an
//! address after its bell is dropped rings whichever bell takes the line next: a
//! spurious turn; and one that reads a target, stalls while that target's line is
//! given back and taken by a group member's bell, and then stores `RUNG` there, could
//! leave that member rung unseen (as before the words were shared): a generation in
//! each line would close both. The memfd is sealed at its
//! size, so no other process can shrink it under this one's mapping. A process forked
//! from one with a mapping makes its bells on the heap: the two would otherwise hand
//! out the same lines.

use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Instant;

/// A bell's two words: `state()`, and `target()`, the index of the word its thread
/// sleeps on (in the process's mapping; meaningful only there).
pub(crate) struct Pair {
    /// In the process's mapping, or on the heap ([`HEAP_PAIRS`]).
    words: &'static [AtomicU32; 2],
    /// Its place in the mapping, given back when dropped; [`HEAP`]: on the heap.
    place: u32,
}

/// The place of a pair on the heap.
const HEAP: u32 = u32::MAX;

/// Pairs on the heap given back, taken again before a new one is made: a process
/// without a mapping keeps as many as it ever had bells at once.
static HEAP_PAIRS: std::sync::Mutex<Vec<&'static [AtomicU32; 2]>> =
    std::sync::Mutex::new(Vec::new());

impl Pair {
    /// A pair whose state is `state` and whose thread sleeps on its own state word.
    pub(crate) fn new(state: u32) -> Pair {
        let pair = mapped::take().unwrap_or_else(|| {
            let given_back = HEAP_PAIRS
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .pop();
            let words = given_back
                .unwrap_or_else(|| Box::leak(Box::new([AtomicU32::new(0), AtomicU32::new(0)])));
            Pair { words, place: HEAP }
        });
        pair.state().store(state, Ordering::SeqCst);
        pair.words[1].store(pair.state_index().unwrap_or(0), Ordering::SeqCst);
        pair
    }

    pub(crate) fn state(&self) -> &AtomicU32 {
        &self.words[0]
    }

    /// The index of its state word in the process's mapping (None: on the heap).
    pub(crate) fn state_index(&self) -> Option<u32> {
        (self.place != HEAP).then(|| self.place * STRIDE)
    }

    /// Sleep on `sleeper`'s state word from now on (an execution group's word): what
    /// another process's ringer wakes.
    pub(crate) fn sleep_on(&self, sleeper: &Pair) {
        if let Some(index) = sleeper.state_index() {
            self.words[1].store(index, Ordering::SeqCst);
        }
    }

    /// Where another process on this host finds this pair (None: on the heap, or not
    /// on Linux).
    pub(crate) fn address(&self) -> Option<BellAddress> {
        if self.place == HEAP {
            return None;
        }
        mapped::address(self.place)
    }
}

impl Drop for Pair {
    fn drop(&mut self) {
        if self.place != HEAP {
            mapped::give_back(self.place);
            return;
        }
        HEAP_PAIRS
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .push(self.words);
    }
}

/// Pairs in the process's mapping (the header's among them): the bells made while
/// they are all taken are on the heap.
#[cfg(all(test, target_os = "linux"))]
pub(crate) const PAIRS_IN_A_MAPPING: u32 = mapped::PAIRS;

/// Words from one pair's start to the next's: a cache line.
const STRIDE: u32 = 16;

/// Where another process on this host finds a component's doorbell: the process,
/// the descriptor of its mapping of bells, that mapping's nonce and the bell's pair.
/// Plain numbers, to pass in any message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct BellAddress {
    /// The process that made the bell.
    pub pid: u32,
    /// Its descriptor of the mapping (`/proc/<pid>/fd/<fd>`).
    pub fd: i32,
    /// The nonce in the mapping's header.
    pub nonce: u64,
    /// The bell's pair in the mapping.
    pub pair: u32,
}

/// Sleep on `word` while it holds `value`, until `deadline` at most; may return
/// early (a signal, a spurious wake-up): the caller looks again.
pub(crate) fn sleep(word: &AtomicU32, value: u32, deadline: Option<Instant>) {
    #[cfg(target_os = "linux")]
    {
        use rustix::thread::futex;
        let timeout = deadline.map(|deadline| {
            let left = deadline.saturating_duration_since(Instant::now());
            futex::Timespec {
                tv_sec: i64::try_from(left.as_secs()).unwrap_or(i64::MAX),
                tv_nsec: i64::from(left.subsec_nanos()),
            }
        });
        // Not private: the word may be in memory another process maps.
        let _ = futex::wait(word, futex::Flags::empty(), value, timeout.as_ref());
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = (word, value);
        match deadline {
            None => std::thread::park(),
            Some(deadline) => {
                std::thread::park_timeout(deadline.saturating_duration_since(Instant::now()))
            }
        }
    }
}

/// Wake the thread sleeping on `word` (Linux; elsewhere the caller unparks it).
#[cfg(target_os = "linux")]
pub(crate) fn wake(word: &AtomicU32) {
    let _ = rustix::thread::futex::wake(word, rustix::thread::futex::Flags::empty(), 1);
}

/// A doorbell of a component of another process on this host, rung from this one
/// (the same protocol as the process's own ringers: `super::Doorbell::ring_strong`).
pub struct RemoteBell {
    #[cfg(target_os = "linux")]
    mapping: mapped::Foreign,
    #[cfg(target_os = "linux")]
    pair: u32,
}

impl std::fmt::Debug for RemoteBell {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RemoteBell").finish_non_exhaustive()
    }
}

impl RemoteBell {
    /// Map the bells of the process `address` names and check that they are the ones
    /// it names (the nonce): an error if the process is gone, is another one, or
    /// does not let this one map its memory (another user), or not on Linux.
    pub fn open(address: &BellAddress) -> std::io::Result<RemoteBell> {
        #[cfg(target_os = "linux")]
        {
            let mapping = mapped::Foreign::open(address)?;
            if address.pair < mapped::FIRST_PAIR || address.pair >= mapped::PAIRS {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::InvalidInput,
                    format!("no bell {} in that process's bells", address.pair),
                ));
            }
            Ok(RemoteBell {
                mapping,
                pair: address.pair,
            })
        }
        #[cfg(not(target_os = "linux"))]
        {
            let _ = address;
            Err(std::io::Error::new(
                std::io::ErrorKind::Unsupported,
                "bells of another process are rung on Linux only",
            ))
        }
    }

    /// Ring it: the component's thread takes a turn (it looks at its sources, as for
    /// any ring). Call it after the work it is to find is in memory it reads.
    pub fn ring(&self) {
        #[cfg(target_os = "linux")]
        {
            let words = self.mapping.words();
            let start = (self.pair * STRIDE) as usize;
            if words[start].swap(super::RUNG, Ordering::SeqCst) == super::SLEEPING {
                // What the thread sleeps on: an index the other process wrote, used only
                // if it is a bell's state word (never the header, never a target).
                let target = words[start + 1].load(Ordering::SeqCst);
                if target >= mapped::FIRST_PAIR * STRIDE
                    && target.is_multiple_of(STRIDE)
                    && let Some(sleeper) = words.get(target as usize)
                {
                    sleeper.store(super::RUNG, Ordering::SeqCst);
                    wake(sleeper);
                }
            }
        }
    }
}

#[cfg(target_os = "linux")]
mod mapped {
    //! The process's mapping of bells, and another process's.

    use super::{BellAddress, STRIDE};
    use std::sync::atomic::{AtomicU32, Ordering};
    use std::sync::{Mutex, OnceLock, PoisonError};

    /// Pairs in a mapping, a cache line each: 4 MiB of address space, backed by memory
    /// only as bells are made (a page for 64 of them).
    pub(super) const PAIRS: u32 = 1 << 16;

    /// The first pair a bell takes (pair 0 is the header).
    pub(super) const FIRST_PAIR: u32 = 1;

    const BYTES: usize = PAIRS as usize * STRIDE as usize * 4;

    /// The header's first word (names the layout: a pair a line).
    const MAGIC: u32 = 0xC001_BE12;

    struct Mapping {
        /// Never dropped: the words live as long as the process.
        shared: crate::mapping::Mapping,
        nonce: u64,
        /// Pairs given back, and the next never taken.
        free: Mutex<(Vec<u32>, u32)>,
        /// The process that made it (a child forked from it leaves it alone).
        owner: u32,
    }

    impl Mapping {
        fn words(&'static self) -> &'static [AtomicU32] {
            self.shared.u32s()
        }
    }

    static MAPPING: OnceLock<Option<Mapping>> = OnceLock::new();

    fn mapping() -> Option<&'static Mapping> {
        MAPPING.get_or_init(make).as_ref()
    }

    fn make() -> Option<Mapping> {
        let shared = crate::mapping::Mapping::create("coolbot-bells", BYTES).ok()?;
        let nonce = crate::mapping::nonce();
        let words = shared.u32s();
        words[0].store(MAGIC, Ordering::SeqCst);
        words[2].store(nonce as u32, Ordering::SeqCst);
        words[3].store((nonce >> 32) as u32, Ordering::SeqCst);
        Some(Mapping {
            shared,
            nonce,
            free: Mutex::new((Vec::new(), FIRST_PAIR)),
            owner: std::process::id(),
        })
    }

    /// A pair of the process's mapping, if it has one and a pair is free.
    pub(super) fn take() -> Option<super::Pair> {
        let mapping = mapping().filter(|mapping| mapping.owner == std::process::id())?;
        let pair = {
            let mut free = mapping.free.lock().unwrap_or_else(PoisonError::into_inner);
            match free.0.pop() {
                Some(pair) => pair,
                None if free.1 < PAIRS => {
                    free.1 += 1;
                    free.1 - 1
                }
                None => return None,
            }
        };
        let start = (pair * STRIDE) as usize;
        let words: &'static [AtomicU32; 2] = mapping.words()[start..start + 2].try_into().ok()?;
        Some(super::Pair { words, place: pair })
    }

    pub(super) fn give_back(pair: u32) {
        // In a forked child, the pair is the parent's, live: left alone.
        if let Some(mapping) = mapping().filter(|mapping| mapping.owner == std::process::id()) {
            // Quiet, and sleeping on itself: a ringer still holding its address (in
            // another process) rings a bell nobody waits on.
            let start = pair * STRIDE;
            mapping.words()[start as usize].store(0, Ordering::SeqCst);
            mapping.words()[start as usize + 1].store(start, Ordering::SeqCst);
            let mut free = mapping.free.lock().unwrap_or_else(PoisonError::into_inner);
            free.0.push(pair);
        }
    }

    pub(super) fn address(pair: u32) -> Option<BellAddress> {
        let mapping = mapping().filter(|mapping| mapping.owner == std::process::id())?;
        Some(BellAddress {
            pid: std::process::id(),
            fd: mapping.shared.fd()?,
            nonce: mapping.nonce,
            pair,
        })
    }

    /// Another process's mapping of bells, mapped here; unmapped when dropped.
    pub(super) struct Foreign {
        shared: crate::mapping::Mapping,
    }

    impl Foreign {
        pub(super) fn open(address: &BellAddress) -> std::io::Result<Foreign> {
            let shared = crate::mapping::Mapping::open(address.pid, address.fd, BYTES)?;
            let words = shared.u32s();
            let nonce = u64::from(words[2].load(Ordering::SeqCst))
                | (u64::from(words[3].load(Ordering::SeqCst)) << 32);
            if words[0].load(Ordering::SeqCst) != MAGIC || nonce != address.nonce {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::NotFound,
                    format!(
                        "/proc/{}/fd/{} is not the bells it was said to be (another process)",
                        address.pid, address.fd
                    ),
                ));
            }
            Ok(Foreign { shared })
        }

        pub(super) fn words(&self) -> &[AtomicU32] {
            self.shared.u32s()
        }
    }
}

#[cfg(not(target_os = "linux"))]
mod mapped {
    pub(super) fn take() -> Option<super::Pair> {
        None
    }

    pub(super) fn give_back(_pair: u32) {}

    pub(super) fn address(_pair: u32) -> Option<super::BellAddress> {
        None
    }
}
