//! The `max_response` watchdog: one thread per process that sees a user section run
//! past its component's `max_response` without needing the section to return.
//!
//! Each component with a `max_response` has a [`Watch`]: the runner stores the start of
//! every section in it (two atomic stores before the call, one swap after: no lock, no
//! message), and the watchdog thread, which holds a list of every live watch, wakes at
//! the earliest deadline of the sections under way. A section still running at its
//! deadline is *tripped*: the watchdog publishes the overrun on the component's
//! monitoring port (`overruns` + [`MonitorEvent::Overrun`]) and moves the monitor to
//! `running_error` with an error naming the state, the section and the limit, so that a
//! supervisor's policy acts at once. The component's thread, still inside the section,
//! finds the trip when the section returns; the runner then discards the call's outcome
//! and completes the fault (see `docs/runtime.md`, "max_response").
//!
//! The watchdog thread asks for the highest real-time priority the OS allows it
//! (`SCHED_RR` 99, or the `RLIMIT_RTPRIO` limit), and stays at normal priority if
//! refused.
//!
//! A component on a [`VirtualClock`](crate::clock::VirtualClock) is not watched by
//! that thread: its sections start at virtual times, and the virtual clock trips the
//! ones past their limit each time it advances (`Watch::trip_if_due`), with the same
//! publication.
//!
//! While no section is under way, the watchdog sleeps for the smallest registered
//! `max_response` (at least [`IDLE_POLL_FLOOR`]): a section that starts while it
//! sleeps cannot reach its deadline before the watchdog wakes, so no section needs to
//! signal its start.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, OnceLock, PoisonError, Weak};
use std::time::{Duration, Instant};

use crate::automaton::Section;
use crate::clock::{Clock, Watched};
use crate::monitor::{MonitorEvent, Shared};
use crate::spec::Spec;
use crate::table::State;
use crate::time::epoch;

/// The shortest time the watchdog sleeps while no section is under way.
pub(crate) const IDLE_POLL_FLOOR: Duration = Duration::from_millis(1);

/// `Watch::slot` value of a call the watchdog has tripped.
const TRIPPED: u64 = u64::MAX;

fn lock<T>(mutex: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

fn nanos(duration: Duration) -> u64 {
    u64::try_from(duration.as_nanos()).unwrap_or(u64::MAX - 1)
}

/// The watched state of one component's sections.
pub(crate) struct Watch {
    spec: &'static Spec,
    shared: Arc<Shared>,
    /// 0: no section under way; `TRIPPED`: the watchdog tripped the current one;
    /// otherwise 1 + the nanoseconds from `epoch()` to the section's start.
    slot: AtomicU64,
    /// The current section: `state << 2 | section`.
    what: AtomicU64,
    /// `max_response` in nanoseconds (0: none).
    limit: AtomicU64,
    /// Held by the watchdog while it trips a call and publishes the trip, so that the
    /// runner, finding the trip, sees it published.
    trip: Mutex<()>,
    registered: AtomicBool,
    /// The sections' starts are read from a virtual clock, which trips them itself:
    /// the watchdog thread skips this watch.
    on_virtual_clock: AtomicBool,
}

fn section_code(section: Section) -> u64 {
    match section {
        Section::Entry => 0,
        Section::Exit => 1,
        Section::Periodic => 2,
    }
}

fn section_of(code: u64) -> Section {
    match code & 3 {
        0 => Section::Entry,
        1 => Section::Exit,
        _ => Section::Periodic,
    }
}

impl Watch {
    /// A watch for one component, registered with the watchdog if `limit` is set.
    pub(crate) fn new(
        spec: &'static Spec,
        shared: Arc<Shared>,
        limit: Option<Duration>,
        clock: &Clock,
    ) -> Arc<Watch> {
        let _ = epoch();
        let watch = Arc::new(Watch {
            spec,
            shared,
            slot: AtomicU64::new(0),
            what: AtomicU64::new(0),
            limit: AtomicU64::new(0),
            trip: Mutex::new(()),
            registered: AtomicBool::new(false),
            on_virtual_clock: AtomicBool::new(false),
        });
        watch.set_clock(clock);
        watch.set_limit(limit);
        watch
    }

    /// Watch on `clock` from now on (before the component's thread runs): a virtual
    /// clock trips the overruns itself, the watchdog thread skips this watch.
    pub(crate) fn set_clock(self: &Arc<Self>, clock: &Clock) {
        if let Some(virtual_clock) = clock.as_virtual() {
            self.on_virtual_clock.store(true, Ordering::Release);
            let watched: Arc<dyn Watched> = self.clone();
            virtual_clock.watch(Arc::downgrade(&watched));
        }
    }

    /// The virtual clock moved to `now`: trip the section under way if it started more
    /// than `max_response` before (as the runner judges a section that returns: one
    /// that took exactly `max_response` did not overrun).
    fn trip_due(&self, now: Instant) {
        let limit = self.limit.load(Ordering::Acquire);
        let token = self.slot.load(Ordering::Acquire);
        if limit == 0 || token == 0 || token == TRIPPED {
            return;
        }
        let now_n = nanos(now.saturating_duration_since(epoch()));
        if (token - 1).saturating_add(limit) < now_n {
            self.trip(token, now);
        }
    }

    /// A new `max_response` (from now on, including the section under way).
    pub(crate) fn set_limit(self: &Arc<Self>, limit: Option<Duration>) {
        let value = limit.map_or(0, |limit| nanos(limit).max(1));
        self.limit.store(value, Ordering::Release);
        if value == 0 {
            return;
        }
        let registry = registry();
        let mut entries = lock(&registry.entries);
        if !self.registered.swap(true, Ordering::AcqRel) {
            entries.push(Arc::downgrade(self));
        }
        // The watchdog may be asleep for a longer limit: let it look again. Notified
        // under the lock, so it is either waiting (and wakes) or about to look at the
        // entries (and sees the new limit): the notification cannot fall in between.
        registry.wake.notify_one();
        drop(entries);
        registry.spawn();
    }

    /// A section starts (at `started`).
    #[inline]
    pub(crate) fn begin(&self, started: Instant, state: usize, section: Section) {
        let since = nanos(started.saturating_duration_since(epoch()));
        self.what.store(
            (state as u64) << 2 | section_code(section),
            Ordering::Relaxed,
        );
        self.slot
            .store(since.saturating_add(1).min(TRIPPED - 1), Ordering::Release);
    }

    /// The section returned: true if the watchdog tripped it meanwhile (then the trip
    /// is published by the time this returns, and the component is no longer stuck).
    #[inline]
    pub(crate) fn end(&self) -> bool {
        if self.slot.swap(0, Ordering::AcqRel) != TRIPPED {
            return false;
        }
        drop(lock(&self.trip));
        self.shared.stuck.store(false, Ordering::Release);
        true
    }

    /// The watchdog: trip the call that started at `token` if it is still under way.
    fn trip(&self, token: u64, now: Instant) {
        let _guard = lock(&self.trip);
        if self
            .slot
            .compare_exchange(token, TRIPPED, Ordering::AcqRel, Ordering::Acquire)
            .is_err()
        {
            return; // It returned meanwhile: the runner judges it.
        }
        self.shared.stuck.store(true, Ordering::Release);
        let started = epoch() + Duration::from_nanos(token - 1);
        let took = now.saturating_duration_since(started);
        let limit = Duration::from_nanos(self.limit.load(Ordering::Acquire));
        let what = self.what.load(Ordering::Relaxed);
        let state = usize::try_from(what >> 2).unwrap_or(usize::MAX);
        let state_name = self.spec.states.get(state).map_or("?", |s| s.name);
        let message = format!(
            "overrun in state `{state_name}` ({:?} section): still running after {took:?}, max_response {limit:?}",
            section_of(what)
        );
        crate::limited!(std::ptr::from_ref(self).addr(), |held| tracing::warn!(
            "{message}{held}"
        ));
        self.shared.update(|monitor| {
            monitor.overruns += 1;
            let mut events = vec![MonitorEvent::Overrun {
                took,
                total: monitor.overruns,
            }];
            if monitor.state != State::Dead {
                monitor.error = Some(message.clone());
                events.push(MonitorEvent::Error(Some(message)));
                if monitor.state != State::RunningError {
                    events.push(MonitorEvent::State {
                        from: monitor.state,
                        to: State::RunningError,
                    });
                    monitor.state = State::RunningError;
                }
            }
            events
        });
    }
}

/// Every live watch, and the watchdog thread's wake-up.
struct Registry {
    entries: Mutex<Vec<Weak<Watch>>>,
    wake: Condvar,
    spawned: OnceLock<bool>,
}

fn registry() -> &'static Registry {
    static REGISTRY: OnceLock<Registry> = OnceLock::new();
    REGISTRY.get_or_init(|| Registry {
        entries: Mutex::new(Vec::new()),
        wake: Condvar::new(),
        spawned: OnceLock::new(),
    })
}

impl Registry {
    /// Spawn the watchdog thread once per process.
    fn spawn(&'static self) {
        self.spawned.get_or_init(|| {
            let spawned = crate::thread::spawn("watchdog", move || self.run());
            if let Err(error) = &spawned {
                tracing::error!(
                    "cannot spawn the max_response watchdog ({error}): overruns are found only when sections return"
                );
            }
            spawned.is_ok()
        });
    }

    fn run(&self) {
        // Above every component thread it watches, if the OS allows: hung `SCHED_RR`
        // sections on every core must not starve it.
        match crate::thread::highest_realtime() {
            Some(level) => tracing::debug!("max_response watchdog under SCHED_RR {level}"),
            None => tracing::debug!("max_response watchdog at normal priority"),
        }
        let mut entries = lock(&self.entries);
        loop {
            let now = Instant::now();
            let now_n = nanos(now.saturating_duration_since(epoch()));
            let mut next: Option<u64> = None;
            let mut due = Vec::new();
            entries.retain(|entry| entry.strong_count() > 0);
            for entry in entries.iter() {
                let Some(watch) = entry.upgrade() else {
                    continue;
                };
                let limit = watch.limit.load(Ordering::Acquire);
                if limit == 0 || watch.on_virtual_clock.load(Ordering::Acquire) {
                    continue;
                }
                let poll = now_n.saturating_add(limit.max(nanos(IDLE_POLL_FLOOR)));
                next = Some(next.map_or(poll, |n| n.min(poll)));
                let token = watch.slot.load(Ordering::Acquire);
                if token == 0 || token == TRIPPED {
                    continue;
                }
                let deadline = (token - 1).saturating_add(limit);
                if deadline <= now_n {
                    due.push((watch, token));
                } else {
                    next = Some(next.map_or(deadline, |n| n.min(deadline)));
                }
            }
            if !due.is_empty() {
                drop(entries);
                for (watch, token) in due {
                    watch.trip(token, now);
                }
                entries = lock(&self.entries);
                continue;
            }
            entries = match next {
                None => self
                    .wake
                    .wait(entries)
                    .unwrap_or_else(PoisonError::into_inner),
                Some(next) => {
                    let sleep = Duration::from_nanos(next.saturating_sub(now_n));
                    self.wake
                        .wait_timeout(entries, sleep)
                        .unwrap_or_else(PoisonError::into_inner)
                        .0
                }
            };
        }
    }
}

impl Watched for Watch {
    fn trip_if_due(&self, now: Instant) {
        self.trip_due(now);
    }
}
