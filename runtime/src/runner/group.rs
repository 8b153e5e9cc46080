//! An execution group: several atomic components' runners on one thread
//! (`docs/runtime.md`, "Execution groups").
//!
//! Each member keeps its own runner, so its own automaton, control port, monitor,
//! timers, exceptions and `catch_unwind`: the group thread only calls
//! [`Runner::turn`] on each member in turn, in data-flow order, where a component's
//! thread would call it in its loop. A pass takes every member once, up to
//! [`TURNS_PER_PASS`] turns each while it has work; a packet a member sends during its
//! turn is at the next member's input when that member's turn looks, so a chain runs
//! through in one pass. After a pass the thread waits on all the members' doorbells at
//! once ([`Doorbell::park_any`]) until one rings or the nearest member timer is due; a
//! bell rung during the pass, or a timer already due, makes the wait return at once
//! for the next pass. Only a member cut off at its turns' limit makes the next pass
//! start without a wait.
//!
//! A pass starts by asking the processor to fetch the members' turn state into its
//! cache (`Runner::prefetch`; in a large group, [`PREFETCH_AHEAD`] members ahead of
//! the turn): after a period asleep it is mostly out of the cache, and the fetches
//! overlap instead of each turn waiting for its own in turn. The wait
//! allocates nothing, and reads the thread's CPU time once for all the members.
//!
//! Members' periodic deadlines fall on one grid, multiples of each member's period
//! from the group's start (`Runner::deadline_after`), so that members with harmonic
//! periods are due at the same instants and run in one pass.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use crate::monitor::{GroupCycles, MonitorEvent, Shared};
use crate::thread::{OsPriority, Scheduling};
use crate::wake::{Doorbell, GroupWord};

use super::{Runner, Turn};

/// The most turns one member takes in one pass while it has work, before the next
/// member's turn (a member flooded with input does not starve the others).
pub(crate) const TURNS_PER_PASS: usize = 64;

/// How many members ahead of the one whose turn begins a pass has asked the processor
/// to fetch into its cache (`Runner::prefetch`): enough for every member of a typical
/// group to be fetched at the pass's start, few enough that a large group's runners
/// (over 1 KiB each) do not push those of the next turns out of the cache.
const PREFETCH_AHEAD: usize = 16;

/// How many members' doorbells a group's wait holds without allocating.
const INLINE_BELLS: usize = 32;

/// What a group's members share: the time spent in their calls (to share out the
/// thread's CPU time) and the thread's priority.
pub(crate) struct GroupShared {
    /// The group's name.
    name: String,
    /// Nanoseconds spent in user calls, summed over the members, as published.
    elapsed: AtomicU64,
    priority: Mutex<Priority>,
}

/// The group thread's scheduling and what each member asks of it.
struct Priority {
    /// The thread's OS scheduling, once it runs.
    scheduling: Option<Scheduling>,
    /// Each member's `priority`, by member index.
    wanted: Vec<i32>,
    /// Each member's monitor, by member index.
    monitors: Vec<Arc<Shared>>,
}

/// A runner's place in a group.
pub(crate) struct Membership {
    pub(crate) index: usize,
    pub(crate) shared: Arc<GroupShared>,
}

impl GroupShared {
    fn lock(&self) -> std::sync::MutexGuard<'_, Priority> {
        self.priority.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Member `index` asks for `priority`: the thread takes the highest any member
    /// asks for, and every member's monitor shows what holds.
    pub(crate) fn apply_priority(&self, index: usize, priority: i32) {
        let mut state = self.lock();
        if let Some(wanted) = state.wanted.get_mut(index) {
            *wanted = priority;
        }
        let highest = state.wanted.iter().copied().max().unwrap_or(priority);
        let Some(scheduling) = state.scheduling.as_mut() else {
            return;
        };
        let applied = scheduling.apply(highest);
        if let OsPriority::NotApplied(why) = &applied {
            crate::limited!(&self.name, |held| tracing::warn!(
                group = %self.name,
                "priority {highest} not applied to the group's thread: {why}{held}"
            ));
        }
        for monitor in &state.monitors {
            let applied = applied.clone();
            monitor.update(|monitor| {
                if monitor.os_priority == applied {
                    return Vec::new();
                }
                monitor.os_priority = applied.clone();
                vec![MonitorEvent::OsPriority(applied)]
            });
        }
    }

    /// A member published `delta` more nanoseconds in its calls; the sum over the
    /// members, in nanoseconds.
    pub(crate) fn add_elapsed(&self, delta: u64) -> u64 {
        self.elapsed
            .fetch_add(delta, Ordering::Relaxed)
            .saturating_add(delta)
    }
}

/// The runners of one group, in the order they run.
pub(crate) struct Group {
    name: String,
    /// Each member's runner stays in the allocation it was prepared in: moved into
    /// one vector, the runners would leave as many freed holes of their size behind
    /// in the heap, which nothing allocated later fills.
    members: Vec<Option<Box<Runner>>>,
    /// The cycle figures every member's monitor shows.
    cycles: Arc<GroupCycles>,
    /// What the thread sleeps on between passes, rung through any member's bell.
    word: Arc<GroupWord>,
}

impl Group {
    /// `runners` in data-flow order: each one runs after those that feed it.
    #[allow(
        clippy::vec_box,
        reason = "each runner stays in its own allocation (see `Group::members`)"
    )]
    pub(crate) fn new(name: &str, mut runners: Vec<Box<Runner>>) -> Group {
        let shared = Arc::new(GroupShared {
            name: name.to_owned(),
            elapsed: AtomicU64::new(0),
            priority: Mutex::new(Priority {
                scheduling: None,
                wanted: vec![0; runners.len()],
                monitors: runners
                    .iter()
                    .map(|runner| Arc::clone(&runner.shared))
                    .collect(),
            }),
        });
        let cycles = Arc::new(GroupCycles::new(
            name,
            runners
                .iter()
                .map(|runner| runner.cx.name.clone())
                .collect(),
        ));
        for (index, runner) in runners.iter_mut().enumerate() {
            let _ = runner.shared.group.set(Arc::clone(&cycles));
            runner.group = Some(Membership {
                index,
                shared: Arc::clone(&shared),
            });
            // Equalization moves a thread's phase; a member's phase is the group's.
            if let Some(adapt) = runner.adapt.as_mut() {
                adapt.equalize = false;
            }
        }
        Group {
            name: name.to_owned(),
            members: runners.into_iter().map(Some).collect(),
            cycles,
            word: GroupWord::new(),
        }
    }

    /// The group thread's body.
    pub(crate) fn run(mut self) {
        crate::thread::set_timer_slack();
        let epoch = self
            .members
            .iter()
            .flatten()
            .next()
            .map(|runner| runner.time.now());
        for runner in self.members.iter_mut().flatten() {
            runner.bell.attach_to_group(&self.word);
            runner.claim_sends();
            runner.bind_clock();
            runner.anchor = epoch;
        }
        if let Some(membership) = self.members.iter().flatten().find_map(|r| r.group.as_ref()) {
            membership.shared.lock().scheduling = Some(Scheduling::of_current_thread());
        }
        for runner in self.members.iter_mut().flatten() {
            let mut priority = 0;
            runner.shared.quietly(|monitor| priority = monitor.priority);
            runner.apply_priority(priority);
            runner.begin();
        }
        tracing::debug!(group = %self.name, members = self.members.len(), "execution group runs");
        loop {
            let more = self.pass();
            if self.members.iter().all(Option::is_none) {
                break;
            }
            if !more {
                self.wait();
            }
        }
    }

    /// Every member once, in order, while it has work; true if a member still has
    /// work known to be waiting (it took its [`TURNS_PER_PASS`] turns).
    ///
    /// Anything else that came during the pass rang a member's bell or is a timer due,
    /// and [`Group::wait`] returns at once for it: the pass that would find nothing is
    /// not made.
    fn pass(&mut self) -> bool {
        let mut more = false;
        // The latest clock reading on this thread: an untimed member's turn on the
        // real clock starts from it instead of reading the clock (see
        // `Runner::untimed`; the reading is the end of the previous member's turn).
        // The first is the cycle's start.
        let start = self
            .members
            .iter()
            .flatten()
            .next()
            .map(|runner| runner.time.now());
        let mut reading = start;
        // The first `PREFETCH_AHEAD` members' turn state is fetched now, and each
        // later member's as the turn `PREFETCH_AHEAD` members before it begins.
        for runner in self.members.iter().take(PREFETCH_AHEAD).flatten() {
            runner.prefetch();
        }
        for index in 0..self.members.len() {
            if let Some(Some(ahead)) = self.members.get(index + PREFETCH_AHEAD) {
                ahead.prefetch();
            }
            let slot = &mut self.members[index];
            let Some(runner) = slot.as_mut() else {
                continue;
            };
            // The panic hook (`crate::process`) names the member whose turn it is.
            crate::monitor::set_turn(Some(&runner.shared));
            let mut turns = 0;
            loop {
                if runner.untimed && runner.time.is_real() {
                    runner.found_at = reading;
                }
                let turn = runner.turn();
                reading = Some(runner.clock);
                turns += 1;
                match turn {
                    Turn::Dead => {
                        runner.end();
                        // Dropping the runner leaves its clock and tells its handles
                        // that it has ended. Its
                        // automaton's own `Drop` is user code: a panic there ends this
                        // member only, not the group's thread.
                        let member = Arc::clone(&runner.cx.name);
                        let ended = slot.take();
                        if let Err(panic) = catch_unwind(AssertUnwindSafe(move || drop(ended))) {
                            tracing::error!(
                                group = %self.name,
                                component = %member,
                                "the component's drop panicked: {}",
                                crate::thread::panic_message(panic.as_ref())
                            );
                        }
                        break;
                    }
                    Turn::Worked if runner.idle() => break,
                    Turn::Worked if turns == TURNS_PER_PASS => {
                        more = true;
                        break;
                    }
                    Turn::Worked => {}
                    Turn::Stopped | Turn::Idle => break,
                }
            }
        }
        crate::monitor::set_turn(None);
        if let (Some(start), Some(end)) = (start, reading) {
            self.cycles.cycle(end.saturating_duration_since(start));
        }
        more
    }

    /// Wait for a ring at any member or the nearest member timer.
    fn wait(&mut self) {
        let mut deadline: Option<Instant> = None;
        let mut now = None;
        let mut period: Option<Duration> = None;
        // One reading of the thread's CPU time for all the members that refresh theirs.
        let mut cpu = None;
        let mut read_cpu = || *cpu.get_or_insert_with(super::calls::thread_cpu_time);
        for runner in self.members.iter_mut().flatten() {
            if let Some(due) = runner.next_due() {
                deadline = Some(deadline.map_or(due, |d| d.min(due)));
            }
            if let Some(own) = runner.periodic_now() {
                period = Some(period.map_or(own, |p| p.min(own)));
            }
            // One reading for all: the members share the clock.
            runner.clock = *now.get_or_insert_with(|| runner.time.now());
            runner.update_cpu_from(false, &mut read_cpu);
        }
        self.cycles.set_period(period);
        let clock = self
            .members
            .iter()
            .flatten()
            .next()
            .and_then(|runner| runner.time.as_virtual().cloned());
        // The bells in an array on the stack (no allocation per cycle), or in a vector
        // for a group larger than the array.
        let mut members = self.members.iter().flatten();
        let Some(first) = members.next() else {
            return;
        };
        let mut inline = [&*first.bell; INLINE_BELLS];
        let mut spilled = Vec::new();
        let mut count = 1;
        for runner in members {
            match inline.get_mut(count) {
                Some(slot) => *slot = &*runner.bell,
                None => {
                    if spilled.is_empty() {
                        spilled.extend_from_slice(&inline);
                    }
                    spilled.push(&*runner.bell);
                }
            }
            count += 1;
        }
        let bells: &[&Doorbell] = if spilled.is_empty() {
            &inline[..count]
        } else {
            &spilled
        };
        match clock {
            Some(clock) => {
                // A virtual timer: never a real timeout. With nothing due now, every
                // member settles and the thread waits for a ring (the clock rings
                // every member's bell when it advances).
                // A bell rung during the last pass is work at the clock's time: no
                // member settles before it is done.
                let now = clock.now();
                if deadline.is_some_and(|due| due <= now) || bells.iter().any(|b| b.is_rung()) {
                    return;
                }
                for runner in self.members.iter().flatten() {
                    if let Some(id) = runner.on_clock {
                        clock.settled(id, now, &|| !runner.control.is_empty());
                    }
                }
                Doorbell::park_any(bells, &self.word, None);
            }
            None => Doorbell::park_any(bells, &self.word, deadline),
        }
    }
}

impl Runner {
    /// Ask the processor to bring into its cache what this member's turn reads:
    /// whether its bell rang (first: a word in the process's mapping of bells, away
    /// from the rest of the doorbell), its runner, doorbell, inputs and outputs, and
    /// its current state's description.
    /// After the group's thread slept a period, these are mostly out of the cache; a
    /// turn that met them one by one would wait for each in turn, where the
    /// prefetches for all the members overlap (and with the first members' work).
    fn prefetch(&self) {
        prefetch(self.bell.state());
        prefetch(self);
        prefetch(&*self.bell);
        for input in &self.inputs {
            prefetch(&**input);
        }
        for output in &self.outputs {
            prefetch(&**output);
        }
        prefetch(self.tracks.as_slice());
        prefetch(self.labels.as_slice());
        if let Some(state) = self.spec.states.get(self.user) {
            prefetch(state);
        }
    }
}

/// A cache line's size on the processors the runtime runs on.
const LINE: usize = 64;

/// Ask the processor to bring every cache line of `value` into its cache (a hint:
/// a no-op where the processor has no prefetch instruction the runtime uses).
#[inline]
fn prefetch<T: ?Sized>(value: &T) {
    let start = std::ptr::from_ref(value).cast::<u8>();
    for offset in (0..size_of_val(value)).step_by(LINE) {
        prefetch_line(start.wrapping_add(offset));
    }
}

#[cfg(target_arch = "x86_64")]
#[inline]
fn prefetch_line(at: *const u8) {
    use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
    // SAFETY: `prefetch` is a hint that reads nothing the program sees and cannot
    // fault, whatever the address; `at` lies inside a live value anyway. SSE, which
    // the intrinsic needs, is part of every x86_64 processor.
    #[allow(unsafe_code, reason = "a prefetch hint: no memory is read or written")]
    unsafe {
        _mm_prefetch::<_MM_HINT_T0>(at.cast::<i8>());
    }
}

#[cfg(not(target_arch = "x86_64"))]
#[inline]
fn prefetch_line(_at: *const u8) {}
