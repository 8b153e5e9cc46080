//! The component thread: one loop that drives the default automaton ([`crate::table`])
//! and the user automaton of one component.
//!
//! The loop blocks in one wait on the component's doorbell ([`Doorbell`]: rung by every
//! command, every delivery to its inputs and every pull request to its outputs), with
//! the nearest timer deadline as its timeout. Each turn clears the doorbell before it
//! looks at anything (so a ring during the turn makes the next wait return at once),
//! except a turn that follows a spin which found its work by looking at the sources of
//! work directly (see `Runner::wait_for_input`), handles at most one thing, in this
//! priority order, then looks at the control port again:
//!
//! 1. control commands (all that are waiting);
//! 2. `Context::end` requested by the last user call;
//! 3. timers: a `may` choice made by the last section, then `after` transitions in
//!    declaration order, then the periodic section;
//! 4. inputs: `on port -> target` transitions, by input declaration order;
//! 5. pull requests to the component's outputs, by output declaration order.
//!
//! Every user call (hooks, sections, `choose`, handlers, `answer`, `configure`, `set`)
//! runs under `catch_unwind`.

use std::collections::VecDeque;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::adapt::{
    AdaptAction, AdaptConfig, Adaptation, Detector, Floor, Ladder, Observation, Pressure, Setting,
};
use crate::automaton::{
    Atomic, Context, DegradationRefused, Driven, Fault, Section, TransitionWaiter,
};
use crate::chain::Chain;
use crate::clock::Clock;
use crate::equalize::{Activation, Board, EqualizeConfig, Seat, ThreadStats};
use crate::handle::{ControlMessage, Reply};
use crate::idle::IdleProbe;
use crate::mailbox::{Closer, Mailbox};
use crate::monitor::{Command, MonitorEvent, Shared};
use crate::port::{ArrivalLabel, InputCore, OutputCore};
use crate::ranges::{EXCERPT_CHARS, REASON_CHARS, excerpt};
use crate::spec::{AfterSpec, InputKind, PlanStep, Spec, TimingSpec, VarKind};
use crate::table::{Action, Event, Outcome, State, next};
use crate::thread::OsPriority;
use crate::thread::{Scheduling, panic_message};
use crate::time::later;
use crate::wake::Doorbell;
use crate::watchdog::Watch;

mod adapt;
mod calls;
mod control;
pub(crate) mod group;
mod states;
mod wait;

use adapt::{Local, Pin};

/// How often, at most, a busy thread reads its CPU time (a system call) for the
/// monitor; state changes always read it.
const CPU_TIME_REFRESH: Duration = Duration::from_millis(10);

/// How long a thread waiting for input only spins before it yields and parks: a packet
/// that comes back within this time (a ping-pong, a pipeline on free cores) costs no
/// futex wake-up. A little more than a crossbeam-channel `recv` spins (127 spin hints,
/// 3.3 us on the development machine): with 2 us, a peer delayed 2-3.3 us (an
/// interrupt, a timer tick) made a component park where a bare thread on a channel
/// rode it out, and the ping-pong p99 fell into the park regime (4 us against 0.15 us)
/// in 2 of 18 rows; with 4 us in none (`benches/latency.rs`, A/B under the same
/// conditions). The sources are checked after every hint, not after batches of up to
/// 64: when both threads share one core, the spin only delays the peer, which runs
/// once this thread yields.
const SPIN: Duration = Duration::from_micros(4);

/// Spin hints (about 0.8 us on the development machine) a component waits before its
/// next turn when work was already waiting as its last turn ended: it is behind a
/// faster producer, and every turn touches the cache lines the producer writes (the
/// arrival counter, a last input's slot), slowing it down. Pausing lets a batch
/// arrive undisturbed and be handled in one turn: with both cores free, a `last`
/// consumer went from 0.7x-1.5x of a bounded channel's rate to 3x-4x, a fifo(1024)
/// from 1.4x to 2.5x (`benches/throughput.rs`). A component that keeps up, or
/// answers a request (a ping-pong), never pauses. The pause doubles with each turn
/// in a row that ends with work waiting, up to [`BATCH_PAUSE_MAX`], and is back to
/// this as soon as a turn ends with nothing waiting.
const BATCH_PAUSE: u32 = 32;

/// The longest pause of a component that stays behind its producer (about 13 us on
/// the development machine). There, with both cores free, a consumer pausing 0.8 us
/// held a fifo(1024) producer to about 11 M packets/s and a `last` one to 14 M/s;
/// pausing up to 13 us, to 30 and 28 M/s (`benches/throughput.rs`). A fifo(1024) fed
/// at that rate fills in about 34 us: the longest pause leaves it room.
const BATCH_PAUSE_MAX: u32 = 512;

/// Spin hints between two clock reads while spinning (a hint takes about 25 ns on the
/// development machine, a clock read about 30 ns). A component without timers that
/// finds work while spinning starts its turn from the spin's last clock reading
/// instead of reading the clock again: the reading is normally at most this many hints
/// old (about 0.1 us; more if the thread was preempted in between), and a packet
/// handed over between spinning threads saves a clock read on its path.
const SPIN_BATCH: u32 = 4;

/// `yield_now` rounds after the spin, before parking (as crossbeam's `Backoff`): on a
/// busy machine, they let the peer this thread waits for run on its core.
const YIELD_ROUNDS: u32 = 4;

/// How user code failed.
enum Failure {
    Fault(Fault),
    Panic(String),
    /// The section overran `max_response` (its outcome is discarded): the message.
    Overrun(String),
}

/// What a continuity plan achieved.
enum Recovery {
    Recovered,
    Goto(usize),
    Failed(String),
    /// A `retry` runs the section again later ([`Retrying`]): the thread (or the
    /// group) runs on meanwhile.
    Later,
}

/// A section that failed, to be run again when `due` by its continuity plan's `retry`
/// step number `step`, `left` more times at most; the rest of the plan follows if none
/// succeeds. Nothing else of the user automaton runs meanwhile; commands are handled
/// (and, in an execution group, the other members run).
struct Retrying {
    state: usize,
    exception: usize,
    step: usize,
    left: u32,
    every: Duration,
    due: Instant,
    /// Which section it is, and what follows it once it worked or its plan ended.
    then: Then,
    /// The arrival whose transition this section is part of (an input's temporal
    /// label): its response time is measured once the transition is over.
    arrived: Option<Instant>,
    /// Where it failed and why, for the plan's messages.
    place: String,
    message: String,
}

/// What a section is part of, and so what follows it when its plan's `retry` runs it
/// later ([`Retrying`]).
#[derive(Debug, Clone, Copy)]
enum Then {
    /// The periodic section due at `deadline`, of a `period`: the next deadline is
    /// scheduled (`Runner::periodic_done`).
    Periodic { deadline: Instant, period: Duration },
    /// The entry section of the state: the state is entered (its `choose`).
    Entered,
    /// The exit section of the state on a user transition to `target`: `target` is
    /// entered.
    Enter { target: usize },
}

impl Then {
    fn section(self) -> Section {
        match self {
            Then::Periodic { .. } => Section::Periodic,
            Then::Entered => Section::Entry,
            Then::Enter { .. } => Section::Exit,
        }
    }
}

/// What one turn of the loop ([`Runner::turn`]) found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Turn {
    /// The component is dead: the loop ends.
    Dead,
    /// The user automaton does not run (`ready`, `suspended`, an error, `end`):
    /// nothing happens until a command arrives.
    Stopped,
    /// A piece of user-automaton work was done; more may be waiting.
    Worked,
    /// Nothing was due: wait for a ring or the nearest timer.
    Idle,
}

/// What a runner knows of one of its inputs: one record per input, so that looking at
/// an input reads one cache line.
#[derive(Debug, Clone, Copy)]
struct Track {
    /// The arrival counter already looked at.
    seen: u64,
    /// When the input last had an arrival (or the state was entered), for watchdogs.
    last_arrival: Instant,
    /// Arrivals since the current user state was entered, not yet used by an `on`
    /// transition.
    pending: bool,
}

/// Everything one component thread owns.
pub(crate) struct Runner {
    automaton: Box<dyn Driven>,
    spec: &'static Spec,
    /// The effective timing block: the instance's override, else the spec's.
    timing: TimingSpec,
    cx: Context,
    shared: Arc<Shared>,
    bell: Arc<Doorbell>,
    inputs: Vec<Arc<InputCore>>,
    outputs: Vec<Arc<OutputCore>>,
    state: State,
    /// The current user state.
    user: usize,
    /// Whether the current user state's entry has run (its exit is due on leaving).
    user_entered: bool,
    /// What the runner knows of each input, by input index.
    tracks: Vec<Track>,
    entered_at: Instant,
    suspended_at: Option<Instant>,
    next_periodic: Option<Instant>,
    reanchored: bool,
    pending_choice: Option<usize>,
    /// A section retried later, by a continuity plan's `retry`.
    retrying: Option<Retrying>,
    max_response: Option<Duration>,
    /// The max_response watchdog's view of this component's sections (while it has a
    /// `max_response`).
    watch: Option<Arc<Watch>>,
    /// When the thread's CPU time is next read (`CPU_TIME_REFRESH` after the last
    /// reading): compared with the clock, which costs less than a difference.
    cpu_due: Instant,
    /// The latest clock reading: taken once per turn and at the end of each user call,
    /// and passed down instead of reading the clock again.
    clock: Instant,
    /// The clock every reading comes from (`crate::clock`): the real one unless the
    /// system was given a virtual clock.
    time: Clock,
    /// This component's id on a virtual clock, once it joined it
    /// ([`Runner::join_clock`]).
    on_clock: Option<u64>,
    /// Whether the spec declares a `pull` output (otherwise no pull queue is looked at).
    has_pull: bool,
    /// Wall-clock time spent in user calls, and the value last published, in
    /// nanoseconds (added and published each cycle: integers cost less than
    /// `Duration`'s normalised arithmetic).
    elapsed: u64,
    elapsed_published: u64,
    /// The user state last published on the monitor.
    published_user: Option<usize>,
    /// Whether the automaton is a compound's (its supervision hooks are called).
    supervised: bool,
    /// The monitor shows another component's times (`Driven::mirrors_times`).
    mirrors_times: bool,
    /// The next [`Runner::enter`] is the initial state's as the component starts
    /// running: arrivals it has not seen at its data inputs count as arrivals there.
    arrivals_count_on_entry: bool,
    /// The last wait found work by looking at the sources (`wait_for_input`), not at
    /// the bell: the next turn does not clear the bell.
    found_by_polling: bool,
    /// The next pause behind a faster producer, in spin hints (see `BATCH_PAUSE`).
    batch_pause: u32,
    /// When the last wait found its work while spinning: the spin's last clock
    /// reading, which the next turn starts from (see `SPIN_BATCH`). Only for a
    /// component without timers (`untimed`).
    found_at: Option<Instant>,
    /// No state has a periodic section or an `after` transition, and the component is
    /// not a compound: nothing times a delay from the turn's clock, so a spin's last
    /// reading may stand in for it. (A thread preempted between that reading and
    /// finding its work would start the turn from an older reading; a timer measured
    /// from it would fire early, so timed components always read the clock.)
    untimed: bool,
    /// This turn did not clear the bell (the bell may be rung for work already seen).
    polled: bool,
    /// The thread's OS scheduling (`priority`), once the thread runs.
    scheduling: Option<Scheduling>,
    /// Adaptation (paper 3.6): the ladder, the detector, the level; `None` for a
    /// component with no ladder and no detection, and for compounds (whose
    /// supervisor adapts, `compound/adaptation.rs`). Boxed: most components have
    /// none, and a group holds its members' runners side by side.
    adapt: Option<Box<Local>>,
    /// How long the last user call ran.
    last_took: Duration,
    /// The variables the automaton reported after a call (`publish_variables`),
    /// kept to reuse its buffer.
    reported: Vec<(usize, Option<crate::value::Value>)>,
    /// Driven by a harness (`crate::harness`) on the caller's thread, on a virtual
    /// clock of its own: a retry plan's wait advances that clock.
    harnessed: bool,
    /// Temporal labels of the inputs whose response time is measured (aperiodic
    /// components with a `max_response`; `crate::port::ArrivalLabel`).
    labels: Vec<Option<Arc<ArrivalLabel>>>,
    /// The last `RESPONSE_WINDOW` response times.
    responses: VecDeque<Duration>,
    /// Its place in an execution group (`group`), when it runs in one.
    group: Option<group::Membership>,
    /// The instant its periodic deadlines count from, in an execution group (the
    /// group's start): each deadline is on the grid of its period from there.
    anchor: Option<Instant>,
    /// The control port's queue. The last field, so dropped last, when the thread
    /// has ended: closing it tells the handles (`Handle::join_if_exited`), and drops
    /// the commands still queued (their senders see no answer coming).
    control: Closer<ControlMessage>,
    /// Its place on that clock: left when the runner is dropped, after everything
    /// else (declared last): the commands still queued are dropped first, and a
    /// supervisor waiting for one in the clock's time is busy again before this
    /// component leaves the settled wait.
    clock_place: Option<crate::clock::ClockPlace>,
}

impl Runner {
    #[allow(
        clippy::too_many_arguments,
        reason = "one constructor wiring the thread's parts"
    )]
    pub(crate) fn new(
        name: Arc<str>,
        automaton: Box<dyn Driven>,
        timing: TimingSpec,
        adaptation: AdaptConfig,
        shared: Arc<Shared>,
        control: Arc<Mailbox<ControlMessage>>,
        bell: Arc<Doorbell>,
        inputs: Vec<Arc<InputCore>>,
        outputs: Vec<Arc<OutputCore>>,
    ) -> Runner {
        let spec = automaton.spec();
        let now = Instant::now();
        let count = inputs.len();
        let supervised = automaton.supervises();
        let mirrors_times = automaton.mirrors_times();
        let watch = timing
            .max_response
            .map(|limit| Watch::new(spec, Arc::clone(&shared), Some(limit), &Clock::real()));
        let adapt = (!supervised)
            .then(|| Local::new(adaptation, &timing))
            .flatten()
            .map(Box::new);
        let mut runner = Runner {
            cx: Context::named(name, timing.period),
            automaton,
            spec,
            timing,
            shared,
            control: Closer::taker(control),
            bell,
            inputs,
            outputs,
            state: State::Starting,
            user: spec.initial,
            user_entered: false,
            tracks: vec![
                Track {
                    seen: 0,
                    last_arrival: now,
                    pending: false,
                };
                count
            ],
            entered_at: now,
            suspended_at: None,
            next_periodic: None,
            reanchored: false,
            pending_choice: None,
            retrying: None,
            max_response: timing.max_response,
            watch,
            cpu_due: now + CPU_TIME_REFRESH,
            clock: now,
            time: Clock::real(),
            on_clock: None,
            clock_place: None,
            has_pull: spec.outputs.iter().any(|output| output.pull),
            elapsed: 0,
            elapsed_published: 0,
            published_user: None,
            supervised,
            mirrors_times,
            arrivals_count_on_entry: false,
            found_by_polling: false,
            batch_pause: BATCH_PAUSE,
            found_at: None,
            untimed: !supervised
                && spec
                    .states
                    .iter()
                    .all(|state| state.periodic.is_none() && state.after.is_empty()),
            polled: false,
            scheduling: None,
            adapt,
            last_took: Duration::ZERO,
            reported: Vec::new(),
            harnessed: false,
            labels: Vec::new(),
            responses: VecDeque::new(),
            group: None,
            anchor: None,
        };
        runner.cx.shared = Some(Arc::clone(&runner.shared));
        runner.cx.waker = Some(crate::wake::Waker {
            bell: Arc::clone(&runner.bell),
        });
        runner
    }

    /// The component's code (the harness reads the generated glue through it): an
    /// atomic component's own automaton, not the `Atomic` wrapper around it.
    pub(crate) fn automaton(&self) -> &dyn std::any::Any {
        let driven: &dyn std::any::Any = &*self.automaton;
        match driven.downcast_ref::<Atomic>() {
            Some(atomic) => {
                let inner: &dyn std::any::Any = &*atomic.0;
                inner
            }
            None => driven,
        }
    }

    /// [`Runner::automaton`], mutable.
    pub(crate) fn automaton_mut(&mut self) -> &mut dyn std::any::Any {
        let driven: &mut dyn std::any::Any = &mut *self.automaton;
        if driven.is::<Atomic>() {
            if let Some(atomic) = driven.downcast_mut::<Atomic>() {
                let inner: &mut dyn std::any::Any = &mut *atomic.0;
                return inner;
            }
            unreachable!("checked just above");
        }
        driven
    }

    /// Whether the automaton is a compound's or a proxy's (it supervises): it cannot
    /// join an execution group.
    pub(crate) fn supervises(&self) -> bool {
        self.supervised
    }

    /// Measure response times at these inputs (`None`: not measured).
    pub(crate) fn set_labels(&mut self, labels: Vec<Option<Arc<ArrivalLabel>>>) {
        self.labels = labels;
    }

    /// Join the virtual clock it runs on, if it does and has not yet: before its
    /// thread starts (`System`'s spawn), so that an `advance` or a `settle` right after
    /// the system started waits for it; its thread binds itself to the place when it
    /// runs.
    pub(crate) fn join_clock(&mut self) {
        if self.on_clock.is_some() {
            return;
        }
        if let Some(clock) = self.time.as_virtual() {
            let place =
                crate::clock::ClockPlace::join(clock, &self.cx.name, Arc::clone(&self.bell));
            self.on_clock = Some(place.id());
            let _ = self.shared.clock_member.set(place.id());
            self.cx.spends = crate::automaton::Spends::Member(place.id());
            self.clock_place = Some(place);
        }
    }

    /// The calling thread runs it from now on: joined to its virtual clock (if it was
    /// not yet), bound to the thread there.
    pub(super) fn bind_clock(&mut self) {
        self.join_clock();
        if let (Some(clock), Some(id)) = (self.time.as_virtual(), self.on_clock) {
            clock.bind_thread(id);
        }
    }

    /// Run on `clock` (before the thread starts): every timer reads it.
    pub(crate) fn set_clock(&mut self, clock: Clock) {
        for label in self.labels.iter().flatten() {
            label.set_clock(&clock);
        }
        let now = clock.now();
        self.entered_at = now;
        self.cpu_due = now + CPU_TIME_REFRESH;
        self.clock = now;
        for track in &mut self.tracks {
            track.last_arrival = now;
        }
        self.cx.entered_at = now;
        self.cx.clock = clock.clone();
        self.automaton.set_clock(&clock);
        self.time = clock;
        if let Some(watch) = &self.watch {
            watch.set_clock(&self.time);
        }
    }

    /// Driven by a harness on `clock` (its own virtual clock), with no thread.
    pub(crate) fn harness_on(&mut self, clock: Clock) {
        self.set_clock(clock);
        self.harnessed = true;
        self.cx.spends = crate::automaton::Spends::Harnessed;
    }

    /// On a virtual clock: this component has nothing due at the clock's time and is
    /// about to wait (see `crate::clock`).
    fn settle(&self) {
        if let (Some(clock), Some(id)) = (self.time.as_virtual(), self.on_clock) {
            clock.settled(id, clock.now(), &|| !self.control.is_empty());
        }
    }

    pub(crate) fn begin(&mut self) {
        if let Some(adapt) = &self.adapt {
            let (enabled, max_level) = (adapt.enabled, adapt.ladder.max_level());
            let settle_periods = adapt.settle_periods;
            self.shared.quietly(|monitor| {
                monitor.adaptation.enabled = enabled;
                monitor.adaptation.max_level = max_level;
                monitor.adaptation.settle_periods = settle_periods;
            });
        }
        self.clock = self.time.now();
        self.publish_variables();
        match self.run_start() {
            Ok(()) => self.apply(Event::StartOk),
            Err(message) => {
                self.set_error(Some(message));
                self.apply(Event::StartFailed);
            }
        }
    }

    /// One turn of the loop, everything but the wait: the runtime's semantics per
    /// event, in one place, shared by the component thread and by the harness
    /// (`crate::harness`), which calls it until it returns something other than
    /// [`Turn::Worked`].
    pub(crate) fn turn(&mut self) -> Turn {
        // Before looking at anything: a ring from now on wakes the next wait. Not
        // after a wait that found its work by looking at the sources themselves
        // (`wait_for_input`): the bell then stays rung, so that producers only read
        // it, until the thread is about to park.
        self.polled = std::mem::take(&mut self.found_by_polling);
        // Whether anything rang since the last clear. If not, the bell is already
        // quiet and needs no clearing (the clear would write the value it reads:
        // a ring after this load still leaves the bell rung for the next wait),
        // and the control queue needs no reading: a command rings after it is
        // queued, so one queued but not rung yet rings before the next wait, which
        // then returns at once. Saves an atomic swap and the read of a cold
        // channel on every timer wake-up.
        let rung = self.polled || self.bell.is_rung();
        if rung && !self.polled {
            self.bell.clear();
        }
        // Sources of work outside the ports (`crate::Source`): at the inputs now.
        if rung {
            self.bell.drain_sources();
        }
        // One clock reading per turn (user calls start from it, and end with another),
        // or the reading the spin that found this turn's work just took.
        self.clock = match self.found_at.take() {
            Some(reading) => reading,
            None => self.time.now(),
        };
        // 1. Control first. The control queue is read only when a command was queued
        // (`Doorbell::take_commands`), or when the wait that found this turn's work
        // looked at the queue itself.
        let commands = self.polled || (rung && self.bell.take_commands());
        if rung && !self.drain_control(commands) {
            return Turn::Dead;
        }
        if self.state != State::Running {
            if self.supervised && self.state == State::Suspended {
                self.observe_instances();
            }
            self.cx.end_requested = false;
            return Turn::Stopped;
        }
        // 2. The task finished (once a section's retries are over: a section that
        // asked to end and failed is retried first, as on a thread that slept
        // through its retries).
        if self.cx.end_requested && self.retrying.is_none() {
            self.cx.end_requested = false;
            self.apply(Event::Finished);
            return Turn::Worked;
        }
        let now = self.clock;
        self.notice_arrivals(now);
        if self.step(now) {
            Turn::Worked
        } else {
            Turn::Idle
        }
    }

    /// What the thread does after its last turn: publish its CPU time, and answer the
    /// commands that arrived while the component went dead.
    pub(crate) fn end(&mut self) {
        self.update_cpu(true);
        while let Some(message) = self.control.take() {
            if message.take() {
                message.answer(Reply::Rejected(
                    "the component is dead: its thread has ended".to_owned(),
                ));
            }
        }
    }

    /// With `commands`, handle every waiting command; false once the component is
    /// dead.
    fn drain_control(&mut self, commands: bool) -> bool {
        // (`take` looks at the queue's length before it locks: a bell rung by a
        // delivery finds no command far more often than one.)
        if !commands {
            return self.state != State::Dead;
        }
        if self.state != State::Dead
            && !self.control.is_empty()
            && let (Some(clock), Some(id)) = (self.time.as_virtual(), self.on_clock)
        {
            // Busy before any reply: a test that commanded it and settles the clock
            // waits for the rest of this turn (and, in a group, of the pass).
            clock.busy(id);
        }
        while self.state != State::Dead
            && let Some(message) = self.control.take()
        {
            self.handle_control(message);
        }
        self.state != State::Dead
    }

    /// Whether the last turn left nothing known to be waiting: no ring since the turn
    /// began, no input pending, no choice or end to act on, no pull request queued.
    fn pull_requests_waiting(&self) -> bool {
        self.has_pull && self.outputs.iter().any(|output| output.has_requests())
    }

    /// The nearest timer of the current user state (`after` transitions, the periodic
    /// deadline, a compound's own wake-up), while the user automaton runs; while a
    /// section waits for its retry, only the retry.
    pub(crate) fn next_due(&self) -> Option<Instant> {
        if self.state != State::Running {
            return None;
        }
        if let Some(retrying) = &self.retrying {
            return Some(retrying.due);
        }
        let state_spec = self.spec.states.get(self.user)?;
        let mut deadline = self.next_periodic;
        for after in state_spec.after {
            let due = self.after_due(after);
            deadline = Some(deadline.map_or(due, |d| d.min(due)));
        }
        if self.supervised
            && let Some(due) = self.automaton.wake_at()
        {
            deadline = Some(deadline.map_or(due, |d| d.min(due)));
        }
        deadline
    }

    /// Wait for a command, an arrival or the nearest timer.
    /// Do the most urgent piece of user-automaton work; false if there was none.
    fn step(&mut self, now: Instant) -> bool {
        if self.supervised {
            let state = self.user;
            match self.call(|automaton, cx| automaton.supervise(state, cx)) {
                Ok(Ok(None)) => {}
                Ok(Ok(Some(target))) => {
                    self.goto(target, self.time.now());
                    return true;
                }
                Ok(Err(fault)) => {
                    self.fail(fault.text().to_owned());
                    return true;
                }
                Err(panic) => {
                    self.fail(format!("panic in the supervisor: {panic}"));
                    return true;
                }
            }
        }
        let Some(state_spec) = self.spec.states.get(self.user) else {
            // No user automaton: only pull requests.
            return self.has_pull && self.serve_pulls();
        };
        // 3. Timers: first a section's retry, which waits for nothing else.
        if let Some(retrying) = &self.retrying {
            return now >= retrying.due && self.retry_due();
        }
        if let Some(target) = self.pending_choice.take() {
            self.goto(target, now);
            return true;
        }
        for after in state_spec.after {
            if now >= self.after_due(after) {
                self.goto(after.target, now);
                return true;
            }
        }
        if let Some(deadline) = self.next_periodic
            && now >= deadline
        {
            self.periodic(deadline);
            return true;
        }
        // 4. Inputs, in declaration order.
        let fired = state_spec
            .on
            .iter()
            .filter(|on| self.tracks.get(on.port).is_some_and(|track| track.pending))
            .min_by_key(|on| on.port);
        if let Some(on) = fired {
            self.tracks[on.port].pending = false;
            let arrived = self
                .labels
                .get(on.port)
                .and_then(Option::as_ref)
                .and_then(|label| label.take());
            self.goto(on.target, now);
            self.respond_when_done(arrived);
            return true;
        }
        // 5. Pull requests.
        self.has_pull && self.serve_pulls()
    }

    fn notice_arrivals(&mut self, now: Instant) {
        for (input, track) in self.inputs.iter().zip(&mut self.tracks) {
            let arrivals = input.arrivals();
            if arrivals != track.seen {
                track.seen = arrivals;
                track.pending = true;
                track.last_arrival = now;
            }
        }
    }

    fn after_due(&self, after: &AfterSpec) -> Instant {
        let base = match after.without {
            Some(port) => self.tracks.get(port).map_or(self.entered_at, |track| {
                track.last_arrival.max(self.entered_at)
            }),
            None => self.entered_at,
        };
        later(base, after.delay)
    }

    /// The first periodic deadline after `now` for `period`: a period later, or in an
    /// execution group the next instant of its grid (multiples of `period` from the
    /// group's start), so that members with harmonic periods are due together.
    fn deadline_after(&self, now: Instant, period: Duration) -> Instant {
        let Some(anchor) = self.anchor else {
            return later(now, period);
        };
        let step = period.as_nanos().max(1);
        let steps = now.saturating_duration_since(anchor).as_nanos() / step + 1;
        let offset = steps.saturating_mul(step);
        later(
            anchor,
            Duration::from_nanos(u64::try_from(offset).unwrap_or(u64::MAX)),
        )
    }

    /// The period of the periodic section the component runs now: `None` unless it
    /// is `running` in a user state with a periodic section (not suspended, not
    /// starting, not in a state without one).
    pub(crate) fn periodic_now(&self) -> Option<Duration> {
        if self.state != State::Running || !self.user_entered {
            return None;
        }
        self.next_periodic?;
        self.period_of(self.user)
    }

    fn period_of(&self, state: usize) -> Option<Duration> {
        self.spec.states[state]
            .periodic
            .and_then(|periodic| periodic.period.or(self.cx.period))
    }
}
