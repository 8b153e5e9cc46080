//! The one clock the runtime's timers read: the real clock, or a [`VirtualClock`] a test
//! advances by hand.
//!
//! Every time the runtime measures for the user automaton goes through a [`Clock`]: the
//! runner's turn readings (so `after`, `after ... without` and periodic deadlines),
//! the duration of each section (so `max_response`, missed deadlines and the
//! adaptation detector's view of a section), and, for a [`crate::record::Recorder`]
//! given one, the recording's timestamps.
//!
//! [`Clock::real`] (the default) reads [`Instant::now`] and nothing else: one branch
//! on a field the thread owns, then the same system call as before.
//!
//! [`Clock::virtual_clock`] gives a clock that stands still until a test calls
//! [`VirtualClock::advance`]. Components of a [`crate::System`] built
//! [`with_clock`](crate::System::with_clock) then never wait on the OS for a timer
//! (a compound's supervision timing and its instances included):
//! a component with a timer due later parks until it is rung, and `advance` moves the
//! time, trips the sections that overran their `max_response` by then, rings every
//! component on the clock, and returns once each of them has looked at the new time
//! and has nothing more due (it is *settled*). So after `advance` returns, every
//! timer due up to the new time has fired, in due order, and no real time was
//! waited for: a test asserts exact sequences with no sleep.
//!
//! Settling covers timers, not data: a packet sent during the step is handled as
//! usual, and a test waits for its effect as it would with the real clock. Packets
//! that wait at a compound's exported input for room in its instance's `Block` fifo
//! are retried in real time too (`Driven::retries_data`), not at the clock's next
//! millisecond.
//!
//! A section can take time of the clock as if it computed that long
//! ([`Context::spend`](crate::Context::spend)): it waits until the clock has moved on
//! by that much, and meanwhile `advance` does not wait for it, nor for the members of
//! its execution group (its thread is busy), to settle; it is measured that long, and
//! a `max_response` it exceeds trips as it would in real time.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, PoisonError, Weak};
use std::time::{Duration, Instant};

use crate::time::nanos;
use crate::value::Time;
use crate::wake::Doorbell;

/// How long [`VirtualClock::advance`] waits (real time) for the components to settle.
pub const SETTLE_TIMEOUT: Duration = Duration::from_secs(20);

/// The clock a component's timers read. Cheap to clone.
#[derive(Clone, Default)]
pub struct Clock {
    virtual_clock: Option<Arc<VirtualClock>>,
}

impl std::fmt::Debug for Clock {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.virtual_clock {
            None => write!(f, "Clock::real"),
            Some(clock) => write!(f, "Clock::virtual({:?})", clock.elapsed()),
        }
    }
}

impl Clock {
    /// The real clock ([`Instant::now`]).
    pub fn real() -> Clock {
        Clock::default()
    }

    /// A clock that stands still until `clock` is advanced.
    pub fn virtual_clock(clock: &Arc<VirtualClock>) -> Clock {
        Clock {
            virtual_clock: Some(Arc::clone(clock)),
        }
    }

    /// The time now.
    #[inline]
    pub fn now(&self) -> Instant {
        match &self.virtual_clock {
            None => Instant::now(),
            Some(clock) => clock.now(),
        }
    }

    /// The wall-clock time now ([`Time::now`], or on a virtual clock the wall time it
    /// was made at plus the time it advanced).
    pub fn wall_now(&self) -> Time {
        match &self.virtual_clock {
            None => Time::now(),
            Some(clock) => Time::from_nanos(
                clock
                    .wall
                    .0
                    .saturating_add(clock.offset.load(Ordering::Acquire)),
            ),
        }
    }

    /// The virtual clock, if this is one.
    pub fn as_virtual(&self) -> Option<&Arc<VirtualClock>> {
        self.virtual_clock.as_ref()
    }

    /// Whether this is the real clock.
    pub fn is_real(&self) -> bool {
        self.virtual_clock.is_none()
    }
}

/// A clock that moves only when told ([`VirtualClock::advance`]).
pub struct VirtualClock {
    /// The instant the clock started at (a real reading when it was made).
    base: Instant,
    /// The wall-clock time it was made at (what `Context::now` counts from).
    wall: Time,
    /// Nanoseconds since `base`.
    offset: AtomicU64,
    state: Mutex<Members>,
    settled: Condvar,
    /// Notified when the clock moves (or a section taking its time is released).
    moved: Condvar,
    /// What the idle probe would say ([`VirtualClock::set_idle`]).
    idle: AtomicBool,
}

impl std::fmt::Debug for VirtualClock {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "VirtualClock({:?})", self.elapsed())
    }
}

/// What a virtual clock tells as it advances: a component's `max_response` watch
/// (`crate::watchdog`), which trips the section under way if it is overdue.
pub(crate) trait Watched: Send + Sync {
    /// The clock moved to `now`.
    fn trip_if_due(&self, now: Instant);
}

/// The components on a virtual clock.
#[derive(Default)]
struct Members {
    next: u64,
    /// Each component's doorbell and the time it last settled at (`None`: busy).
    components: BTreeMap<u64, Member>,
    /// The `max_response` watches of the components on the clock.
    watches: Vec<Weak<dyn Watched>>,
    /// The offset (nanoseconds) up to which the watches have been tripped: a section
    /// taking the clock's time returns only once the time it waited for is both
    /// reached and checked against its `max_response`.
    tripped: u64,
    /// The doorbells of the components whose systems shut down
    /// ([`VirtualClock::release`]), so that one joining the clock later is released
    /// too.
    released: Vec<Weak<Doorbell>>,
}

struct Member {
    name: String,
    bell: Arc<Doorbell>,
    settled: Option<Instant>,
    /// The thread it runs on (the members of an execution group share one), once it
    /// runs ([`VirtualClock::bind_thread`]).
    thread: Option<std::thread::ThreadId>,
    /// Until when (nanoseconds since the clock's start) a section of it takes the
    /// clock's time ([`VirtualClock::spend`]).
    spending: Option<u64>,
    /// Its system is shutting down: a section taking the clock's time returns at once.
    released: bool,
    /// The command whose answer it waits for in the clock's time
    /// ([`ClockWait::wait`]); `spending` holds that wait's end.
    awaiting: Option<u64>,
}

/// A component's place on a virtual clock, taken before its thread starts (so that
/// [`VirtualClock::settle`] right after its system started waits for it): it leaves
/// the clock when dropped (its runner's end, or a thread that could not start).
pub(crate) struct ClockPlace {
    clock: Arc<VirtualClock>,
    id: u64,
}

impl ClockPlace {
    /// Join `clock` as `name`, rung through `bell`.
    pub(crate) fn join(clock: &Arc<VirtualClock>, name: &str, bell: Arc<Doorbell>) -> ClockPlace {
        ClockPlace {
            clock: Arc::clone(clock),
            id: clock.join(name, bell),
        }
    }

    /// Its id on the clock.
    pub(crate) fn id(&self) -> u64 {
        self.id
    }
}

impl Drop for ClockPlace {
    fn drop(&mut self) {
        self.clock.leave(self.id);
    }
}

/// Why [`VirtualClock::advance`] returned before every component settled.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("components still busy {timeout:?} after the clock advanced: {busy:?}")]
pub struct NotSettled {
    /// How long it waited.
    pub timeout: Duration,
    /// The components that had not settled.
    pub busy: Vec<String>,
}

/// A member of a virtual clock that waits, in a section, for another component's
/// answer (a supervisor's command to its instance): it waits in the clock's time,
/// as a section taking the clock's time does, until the answer comes or the clock
/// reaches the wait's end. Meanwhile `advance` does not wait for it: the component it
/// waits for may need the clock to move to answer.
#[derive(Clone, Debug)]
pub(crate) struct ClockWait {
    clock: Arc<VirtualClock>,
    id: u64,
}

/// How a [`ClockWait::wait`] ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Waited {
    /// The answer came (or its sender is gone).
    Answered,
    /// The clock reached the wait's end first.
    TimedOut,
    /// The member's system shuts down (or it left the clock): the wait goes on in
    /// real time.
    Off,
}

/// Given with a command by a [`ClockWait`]er: the component answering it tells the
/// waiter each time it posts an answer (and the command's message once more when it
/// is dropped, `crate::handle::ControlMessage`).
#[derive(Clone)]
pub(crate) struct AnswerNotice {
    clock: Arc<VirtualClock>,
    id: u64,
    command: u64,
}

/// What [`VirtualClock::spend`] does once the section's end is recorded, under the
/// clock's lock: post the answer that the transition takes the clock's time, and
/// clear the mark of the sender waiting for it in the clock's time (its notice).
pub(crate) type Told = (Box<dyn FnOnce() + Send>, Option<AnswerNotice>);

impl AnswerNotice {
    /// The command's number, for [`ClockWait::wait`].
    pub(crate) fn command(&self) -> u64 {
        self.command
    }

    /// An answer was posted.
    pub(crate) fn answered(&self) {
        self.clock.answered(self.id, self.command);
    }
}

impl ClockWait {
    /// Member `id` of `clock`.
    pub(crate) fn new(clock: Arc<VirtualClock>, id: u64) -> ClockWait {
        ClockWait { clock, id }
    }

    /// The clock's time now.
    pub(crate) fn now(&self) -> Instant {
        self.clock.now()
    }

    /// Member `member` of the same clock has a command to take: it is busy until it
    /// settles again, so that an `advance` does not return between the command's
    /// post and its turn (the waiter no longer holds it up).
    pub(crate) fn busy(&self, member: u64) {
        self.clock.busy(member);
    }

    /// A new command's notice, for the component that answers it.
    pub(crate) fn notice(&self) -> AnswerNotice {
        static COMMANDS: AtomicU64 = AtomicU64::new(0);
        AnswerNotice {
            clock: Arc::clone(&self.clock),
            id: self.id,
            command: COMMANDS.fetch_add(1, Ordering::Relaxed),
        }
    }

    /// Wait until `answered()` (an answer to `command`, the number of its
    /// [`AnswerNotice`], is posted), or the clock reaches `until`.
    pub(crate) fn wait(
        &self,
        command: u64,
        until: Instant,
        answered: &dyn Fn() -> bool,
        target: Option<u64>,
    ) -> Waited {
        self.clock
            .wait_answer(self.id, command, until, answered, target)
    }
}

impl VirtualClock {
    /// A virtual clock at time zero (an instant taken from the real clock now).
    pub fn new() -> Arc<VirtualClock> {
        // `max_response` watches count from the watchdog's epoch: take it first.
        let _ = crate::time::epoch();
        Arc::new(VirtualClock {
            base: Instant::now(),
            wall: Time::now(),
            offset: AtomicU64::new(0),
            state: Mutex::new(Members::default()),
            settled: Condvar::new(),
            moved: Condvar::new(),
            idle: AtomicBool::new(true),
        })
    }

    /// The time now.
    pub fn now(&self) -> Instant {
        self.base + Duration::from_nanos(self.offset.load(Ordering::Acquire))
    }

    /// Say whether the processor has spare time, as the idle probe would
    /// ([`crate::idle`]; there is no probe on a virtual clock). Initially true: promotion
    /// then goes by the components' own section times.
    pub fn set_idle(&self, idle: bool) {
        self.idle.store(idle, Ordering::Release);
    }

    /// What [`VirtualClock::set_idle`] last said.
    pub fn idle(&self) -> bool {
        self.idle.load(Ordering::Acquire)
    }

    /// How far the clock has been advanced since it was made.
    pub fn elapsed(&self) -> Duration {
        Duration::from_nanos(self.offset.load(Ordering::Acquire))
    }

    /// Move the clock forward by `by`, then wait until every component on it has seen
    /// the new time and has nothing due (see the module's documentation).
    pub fn advance(&self, by: Duration) -> Result<(), NotSettled> {
        self.advance_with_timeout(by, SETTLE_TIMEOUT)
    }

    /// [`VirtualClock::advance`], waiting at most `timeout` (real time) for the
    /// components to settle.
    pub fn advance_with_timeout(&self, by: Duration, timeout: Duration) -> Result<(), NotSettled> {
        let mut members = self.lock();
        let offset = self
            .offset
            .load(Ordering::Acquire)
            .saturating_add(nanos(by));
        self.offset.store(offset, Ordering::Release);
        let now = self.now();
        // Sections past their `max_response` by now are tripped, as the watchdog does
        // in real time.
        members.watches.retain(|watch| watch.strong_count() > 0);
        let watches: Vec<Arc<dyn Watched>> =
            members.watches.iter().filter_map(Weak::upgrade).collect();
        for member in members.components.values_mut() {
            member.settled = None;
            member.bell.ring_strong();
        }
        drop(members);
        for watch in watches {
            watch.trip_if_due(now);
        }
        // Only now may a section taking the clock's time up to `now` return: its
        // `max_response` has been checked at `now`, whatever the threads' timing.
        {
            let mut members = self.lock();
            members.tripped = members.tripped.max(offset);
        }
        self.moved.notify_all();
        self.wait_settled(now, timeout)
    }

    /// Wait until every component has settled at `now` or later.
    fn wait_settled(&self, now: Instant, timeout: Duration) -> Result<(), NotSettled> {
        let deadline = crate::time::later(Instant::now(), timeout);
        let mut members = self.lock();
        loop {
            // A thread whose section takes the clock's time past `now` is busy until
            // then: its members are not waited for.
            let at = nanos(now.saturating_duration_since(self.base));
            let spending: Vec<std::thread::ThreadId> = members
                .components
                .values()
                .filter(|member| member.spending.is_some_and(|end| end > at))
                .filter_map(|member| member.thread)
                .collect();
            let busy: Vec<String> = members
                .components
                .values()
                .filter(|member| {
                    member.settled.is_none_or(|at| at < now)
                        && !member
                            .thread
                            .is_some_and(|thread| spending.contains(&thread))
                })
                .map(|member| member.name.clone())
                .collect();
            if busy.is_empty() {
                return Ok(());
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(NotSettled { timeout, busy });
            }
            members = self
                .settled
                .wait_timeout(members, left)
                .unwrap_or_else(PoisonError::into_inner)
                .0;
        }
    }

    /// Wait until every component on the clock has settled at the current time (for
    /// a test that just started or commanded its components).
    pub fn settle(&self) -> Result<(), NotSettled> {
        self.wait_settled(self.now(), SETTLE_TIMEOUT)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Members> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// A component joins the clock: its id, to report with.
    pub(crate) fn join(&self, name: &str, bell: Arc<Doorbell>) -> u64 {
        let mut members = self.lock();
        let id = members.next;
        members.next += 1;
        let released = members
            .released
            .iter()
            .any(|gone| std::ptr::eq(gone.as_ptr(), Arc::as_ptr(&bell)));
        members.components.insert(
            id,
            Member {
                name: name.to_owned(),
                bell,
                settled: None,
                thread: None,
                spending: None,
                released,
                awaiting: None,
            },
        );
        id
    }

    /// Component `id` runs on the calling thread from now on.
    pub(crate) fn bind_thread(&self, id: u64) {
        if let Some(member) = self.lock().components.get_mut(&id) {
            member.thread = Some(std::thread::current().id());
        }
    }

    /// A component's thread ended.
    pub(crate) fn leave(&self, id: u64) {
        self.lock().components.remove(&id);
        self.settled.notify_all();
    }

    /// A component has nothing due at `at` (its turn's reading) and is about to wait.
    pub(crate) fn settled(&self, id: u64, at: Instant, queued: &dyn Fn() -> bool) {
        let mut members = self.lock();
        // A command queued by a waiter in the clock's time (`wait_answer`, which
        // marks the component busy under this lock after queuing it): not settled.
        if queued() {
            return;
        }
        if let Some(member) = members.components.get_mut(&id) {
            member.settled = Some(at);
        }
        drop(members);
        self.settled.notify_all();
    }

    /// A component has work at the clock's time (a command it is handling): it is
    /// busy until it settles again, so that [`VirtualClock::settle`] after a command
    /// waits for what the command caused.
    pub(crate) fn busy(&self, id: u64) {
        if let Some(member) = self.lock().components.get_mut(&id) {
            member.settled = None;
        }
    }

    /// The section of component `id` under way takes `cost` of the clock's time: wait
    /// until the clock has moved on by `cost` (see the module's documentation), or
    /// the component's system shuts down ([`VirtualClock::release`]). `told` is
    /// called once the section's end is recorded (a command waiting for the
    /// transition this section is part of learns it there: an advance made after it
    /// learns counts from the same time).
    pub(crate) fn spend(&self, id: u64, cost: Duration, told: Option<Told>) {
        let mut members = self.lock();
        let end = self
            .offset
            .load(Ordering::Acquire)
            .saturating_add(nanos(cost));
        match members.components.get_mut(&id) {
            Some(member) if !member.released => member.spending = Some(end),
            _ => return,
        }
        if let Some((post, notice)) = told {
            // After the end is recorded: whoever learns it and then advances the
            // clock counts from the same time. Under the lock, before the settled
            // wait is woken: a supervisor waiting for the answer in the clock's time
            // is busy again before `advance` can find this member out of its wait
            // (the answers' lock is taken under the clock's, as `wait_answer` does).
            post();
            if let Some(notice) = notice
                && let Some(member) = members.components.get_mut(&notice.id)
                && member.awaiting == Some(notice.command)
            {
                member.awaiting = None;
                member.spending = None;
            }
            self.moved.notify_all();
        }
        self.settled.notify_all();
        while members.tripped < end
            && members
                .components
                .get(&id)
                .is_some_and(|member| !member.released)
        {
            members = self
                .moved
                .wait(members)
                .unwrap_or_else(PoisonError::into_inner);
        }
        if let Some(member) = members.components.get_mut(&id) {
            member.spending = None;
        }
    }

    /// [`ClockWait::wait`]: member `id` waits for an answer to `command`.
    fn wait_answer(
        &self,
        id: u64,
        command: u64,
        until: Instant,
        answered: &dyn Fn() -> bool,
        target: Option<u64>,
    ) -> Waited {
        let end = nanos(until.saturating_duration_since(self.base));
        let mut members = self.lock();
        if answered() {
            return Waited::Answered;
        }
        // The component commanded is busy with the command from now on, before this
        // member leaves the settled wait: an `advance` under way waits for it.
        if let Some(target) = target.and_then(|target| members.components.get_mut(&target)) {
            target.settled = None;
        }
        match members.components.get_mut(&id) {
            Some(member) if !member.released => {
                member.spending = Some(end);
                member.awaiting = Some(command);
            }
            _ => {
                if let Some(target) = target.and_then(|target| members.components.get_mut(&target))
                    && !target.released
                {
                    target.released = true;
                    drop(members);
                    self.moved.notify_all();
                }
                return Waited::Off;
            }
        }
        self.settled.notify_all();
        let waited = loop {
            if answered() {
                break Waited::Answered;
            }
            let tripped = members.tripped;
            let Some(member) = members.components.get_mut(&id) else {
                break Waited::Off;
            };
            if member.released {
                break Waited::Off;
            }
            if tripped >= end {
                break Waited::TimedOut;
            }
            if member.awaiting.is_none() {
                // Told of an answer that is not there to take (the command's message
                // was dropped before its answers closed): still waiting.
                member.spending = Some(end);
                member.awaiting = Some(command);
                self.settled.notify_all();
            }
            members = self
                .moved
                .wait(members)
                .unwrap_or_else(PoisonError::into_inner);
        };
        if let Some(member) = members.components.get_mut(&id)
            && member.awaiting == Some(command)
        {
            member.awaiting = None;
            member.spending = None;
        }
        if waited == Waited::Off {
            // Its system shuts down, and with it the component it commands (a
            // compound's instance): a section of that one taking the clock's time
            // returns too, so that the command, waited for in real time from now
            // on, is taken rather than outlasted.
            if let Some(target) = target.and_then(|target| members.components.get_mut(&target))
                && !target.released
            {
                target.released = true;
                drop(members);
                self.moved.notify_all();
            }
        }
        waited
    }

    /// An answer to `command`, which member `id` may be waiting for, was posted: the
    /// member no longer waits in the clock's time (it is busy again: an `advance`
    /// from now on waits for it to settle), and it is woken.
    fn answered(&self, id: u64, command: u64) {
        let mut members = self.lock();
        if let Some(member) = members.components.get_mut(&id)
            && member.awaiting == Some(command)
        {
            member.awaiting = None;
            member.spending = None;
        }
        drop(members);
        self.moved.notify_all();
    }

    /// The components whose doorbells are `bells` are shutting down: a section of
    /// theirs taking the clock's time returns at once, now and from now on.
    pub(crate) fn release(&self, bells: &[&Arc<Doorbell>]) {
        let mut members = self.lock();
        for member in members.components.values_mut() {
            if bells.iter().any(|bell| Arc::ptr_eq(bell, &member.bell)) {
                member.released = true;
            }
        }
        members.released.retain(|gone| gone.strong_count() > 0);
        members
            .released
            .extend(bells.iter().map(|bell| Arc::downgrade(bell)));
        drop(members);
        self.moved.notify_all();
    }

    /// Watch a component's sections against its `max_response` on this clock.
    pub(crate) fn watch(&self, watch: Weak<dyn Watched>) {
        self.lock().watches.push(watch);
    }
}
