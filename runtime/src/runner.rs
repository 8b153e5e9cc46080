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

use crossbeam_channel::{Receiver, Sender};

use crate::adapt::{
    AdaptAction, AdaptConfig, Adaptation, Detector, Floor, Ladder, Observation, Pressure, Setting,
};
use crate::automaton::{Atomic, Context, DegradationRefused, Driven, Fault, Section};
use crate::chain::Chain;
use crate::clock::Clock;
use crate::equalize::{Activation, Board, EqualizeConfig, Seat, ThreadStats};
use crate::handle::{ControlMessage, Reply};
use crate::idle::IdleProbe;
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
/// answers a request (a ping-pong), never pauses.
const BATCH_PAUSE: u32 = 32;

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

/// Everything one component thread owns.
pub(crate) struct Runner {
    automaton: Box<dyn Driven>,
    spec: &'static Spec,
    /// The effective timing block: the instance's override, else the spec's.
    timing: TimingSpec,
    cx: Context,
    shared: Arc<Shared>,
    control: Receiver<ControlMessage>,
    bell: Arc<Doorbell>,
    inputs: Vec<Arc<InputCore>>,
    outputs: Vec<Arc<OutputCore>>,
    state: State,
    /// The current user state.
    user: usize,
    /// Whether the current user state's entry has run (its exit is due on leaving).
    user_entered: bool,
    /// Arrival counters already looked at, per input.
    seen: Vec<u64>,
    /// Inputs with arrivals since the current user state was entered, not yet used by an
    /// `on` transition.
    pending: Vec<bool>,
    /// When each input last had an arrival (or the state was entered), for watchdogs.
    last_arrival: Vec<Instant>,
    entered_at: Instant,
    suspended_at: Option<Instant>,
    next_periodic: Option<Instant>,
    reanchored: bool,
    pending_choice: Option<usize>,
    deferred: VecDeque<ControlMessage>,
    max_response: Option<Duration>,
    /// The max_response watchdog's view of this component's sections (while it has a
    /// `max_response`).
    watch: Option<Arc<Watch>>,
    cpu_updated: Instant,
    /// The latest clock reading: taken once per turn and at the end of each user call,
    /// and passed down instead of reading the clock again.
    clock: Instant,
    /// The clock every reading comes from (`crate::clock`): the real one unless the
    /// system was given a virtual clock.
    time: Clock,
    /// This component's id on a virtual clock, once its thread runs.
    on_clock: Option<u64>,
    /// Whether the spec declares a `pull` output (otherwise no pull queue is looked at).
    has_pull: bool,
    /// Wall-clock time spent in user calls, and the value last published.
    elapsed: Duration,
    elapsed_published: Duration,
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
    /// supervisor adapts, `compound/adaptation.rs`).
    adapt: Option<Local>,
    /// How long the last user call ran.
    last_took: Duration,
    /// Driven by a harness (`crate::harness`) on the caller's thread, on a virtual
    /// clock of its own: a retry plan's wait advances that clock.
    harnessed: bool,
    /// Temporal labels of the inputs whose response time is measured (aperiodic
    /// components with a `max_response`; `crate::port::ArrivalLabel`).
    labels: Vec<Option<Arc<ArrivalLabel>>>,
    /// The last `RESPONSE_WINDOW` response times.
    responses: VecDeque<Duration>,
    /// Dropped last, when the thread ends: handles see their `exited` channel close.
    _exit_guard: Sender<()>,
}

impl Runner {
    #[allow(
        clippy::too_many_arguments,
        reason = "one constructor wiring the thread's parts"
    )]
    pub(crate) fn new(
        name: &str,
        automaton: Box<dyn Driven>,
        timing: TimingSpec,
        adaptation: AdaptConfig,
        shared: Arc<Shared>,
        control: Receiver<ControlMessage>,
        bell: Arc<Doorbell>,
        inputs: Vec<Arc<InputCore>>,
        outputs: Vec<Arc<OutputCore>>,
        exit_guard: Sender<()>,
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
            .flatten();
        let mut runner = Runner {
            cx: Context::new(name, timing.period),
            automaton,
            spec,
            timing,
            shared,
            control,
            bell,
            inputs,
            outputs,
            state: State::Starting,
            user: spec.initial,
            user_entered: false,
            seen: vec![0; count],
            pending: vec![false; count],
            last_arrival: vec![now; count],
            entered_at: now,
            suspended_at: None,
            next_periodic: None,
            reanchored: false,
            pending_choice: None,
            deferred: VecDeque::new(),
            max_response: timing.max_response,
            watch,
            cpu_updated: now,
            clock: now,
            time: Clock::real(),
            on_clock: None,
            has_pull: spec.outputs.iter().any(|output| output.pull),
            elapsed: Duration::ZERO,
            elapsed_published: Duration::ZERO,
            published_user: None,
            supervised,
            mirrors_times,
            arrivals_count_on_entry: false,
            found_by_polling: false,
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
            harnessed: false,
            labels: Vec::new(),
            responses: VecDeque::new(),
            _exit_guard: exit_guard,
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

    /// Measure response times at these inputs (`None`: not measured).
    pub(crate) fn set_labels(&mut self, labels: Vec<Option<Arc<ArrivalLabel>>>) {
        self.labels = labels;
    }

    /// Run on `clock` (before the thread starts): every timer reads it.
    pub(crate) fn set_clock(&mut self, clock: Clock) {
        for label in self.labels.iter().flatten() {
            label.set_clock(&clock);
        }
        let now = clock.now();
        self.entered_at = now;
        self.cpu_updated = now;
        self.clock = now;
        for arrival in &mut self.last_arrival {
            *arrival = now;
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
    }

    /// On a virtual clock: this component has nothing due at the clock's time and is
    /// about to wait (see `crate::clock`).
    fn settle(&self) {
        if let (Some(clock), Some(id)) = (self.time.as_virtual(), self.on_clock) {
            clock.settled(id, clock.now());
        }
    }

    /// The thread's body.
    pub(crate) fn run(mut self) {
        self.bell.attach();
        if let Some(clock) = self.time.as_virtual() {
            self.on_clock = Some(clock.join(&self.cx.name, Arc::clone(&self.bell)));
        }
        self.run_loop();
        if let (Some(clock), Some(id)) = (self.time.as_virtual(), self.on_clock) {
            clock.leave(id);
        }
    }

    fn run_loop(&mut self) {
        crate::thread::set_timer_slack();
        self.scheduling = Some(Scheduling::of_current_thread());
        let mut priority = 0;
        self.shared.quietly(|monitor| priority = monitor.priority);
        self.apply_priority(priority);
        self.begin();
        loop {
            match self.turn() {
                Turn::Dead => break,
                Turn::Stopped => {
                    // Nothing runs: wait for the next ring (a command, or an arrival
                    // that only needs to stay where it is).
                    if !self.bell.spin() {
                        self.clock = self.time.now();
                        self.update_cpu(false);
                        self.settle();
                        self.bell.park_until(None);
                    }
                }
                // After a piece of work, wait at once when nothing else is known to be
                // waiting, instead of going round for a second full look: anything
                // that arrived since the turn's `clear` rang the bell, so the wait
                // returns at once for it, and a timer already due makes the wait's
                // deadline past.
                Turn::Worked if !self.idle() => {}
                Turn::Worked | Turn::Idle => self.block(),
            }
        }
        self.end();
    }

    /// What the thread does before its first turn (after its OS scheduling is set):
    /// publish the adaptation settings and the variables, run `start` and go to
    /// `ready` (or `starting_error`). The harness (`crate::harness`) calls it too.
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
        // One clock reading per turn (user calls start from it, and end with another),
        // or the reading the spin that found this turn's work just took.
        self.clock = match self.found_at.take() {
            Some(reading) => reading,
            None => self.time.now(),
        };
        // 1. Control first.
        if (rung || !self.deferred.is_empty()) && !self.drain_control() {
            return Turn::Dead;
        }
        if self.state != State::Running {
            if self.supervised && self.state == State::Suspended {
                self.observe_instances();
            }
            self.cx.end_requested = false;
            return Turn::Stopped;
        }
        // 2. The task finished.
        if self.cx.end_requested {
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
        while let Ok(message) = self.control.try_recv() {
            if message.take() {
                let _ = message.reply.try_send(Reply::Rejected(
                    "the component is dead: its thread has ended".to_owned(),
                ));
            }
        }
    }

    /// Handle every waiting command; false once the component is dead.
    fn drain_control(&mut self) -> bool {
        while self.state != State::Starting
            && let Some(message) = self.deferred.pop_front()
        {
            self.handle_control(message);
        }
        while self.state != State::Dead
            && let Ok(message) = self.control.try_recv()
        {
            self.handle_control(message);
        }
        self.state != State::Dead
    }

    /// Whether the last turn left nothing known to be waiting: no ring since the turn
    /// began, no input pending, no choice or end to act on, no pull request queued.
    fn idle(&self) -> bool {
        self.state == State::Running
            && !self.cx.end_requested
            && self.pending_choice.is_none()
            && (self.polled || !self.bell.is_rung())
            && !self.pending.contains(&true)
            && !self.pull_requests_waiting()
    }

    /// Whether a source of work has something for the thread: a command, an arrival
    /// not seen yet, a pull request. Everything that rings the bell of a component
    /// that is not a compound's has one of these behind it (a compound's bell is also
    /// rung by its instances' events and its `Waker`s, which leave nothing to look at).
    fn work_waiting(&self) -> bool {
        !self.deferred.is_empty()
            || !self.control.is_empty()
            || self
                .inputs
                .iter()
                .zip(&self.seen)
                .any(|(input, seen)| input.arrivals() != *seen)
            || self.pull_requests_waiting()
    }

    /// Whether a pull request waits at one of the component's pull outputs.
    fn pull_requests_waiting(&self) -> bool {
        self.has_pull && self.outputs.iter().any(|output| output.has_requests())
    }

    /// The nearest timer of the current user state (`after` transitions, the periodic
    /// deadline, a compound's own wake-up), while the user automaton runs.
    pub(crate) fn next_due(&self) -> Option<Instant> {
        if self.state != State::Running {
            return None;
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
    fn block(&mut self) {
        let deadline = self.next_due();
        // One wait on the doorbell, rung by commands, deliveries and pull requests; the
        // loop then looks at the control port first (the priority rule above). With a
        // timer due, park at once (a periodic thread sleeps like a bare one); waiting
        // for input only, spin first (`wait_for_input`). The timing counters are
        // published (a lock of the monitor) only when the thread is about to sleep.
        if deadline.is_none() {
            self.settle();
            self.wait_for_input();
            return;
        }
        self.update_cpu(false);
        if let Some(clock) = self.time.as_virtual() {
            // A virtual timer: never a real timeout. With the timer due later, settle
            // and wait for a ring (the clock rings when it advances).
            // One reading for the check and the report: settled at `now` means
            // nothing was due at `now`.
            let now = clock.now();
            if deadline.is_some_and(|due| due > now) {
                if let Some(id) = self.on_clock {
                    clock.settled(id, now);
                }
                self.bell.park_until(None);
            }
            return;
        }
        self.bell.park_until(deadline);
    }

    /// Wait for work with no timer due: spin for [`SPIN`], then yield a few times, then
    /// park. An idle component spins once, a few microseconds, then sleeps: it burns no
    /// CPU while nothing comes.
    ///
    /// While it spins, a component that is not a compound's looks at its sources of
    /// work themselves (`work_waiting`: the control queue, the arrival counters, the
    /// pull queues) rather than at the bell, and the turn that follows does not clear
    /// the bell. The bell then stays rung through a fast exchange, and every ring is a
    /// plain load of a cache line that no one writes: the ringer's swap and the
    /// thread's clear, two cache-line transfers per packet, are saved. Nothing is lost:
    /// before it parks, the thread clears the bell and looks at every source once more,
    /// so the doorbell's protocol (`wake.rs`, `Doorbell`) holds from there on. A
    /// compound's bell is also rung by events that leave no source to look at, and so
    /// is any component's on a virtual clock when the clock advances: those spin on
    /// the bell.
    fn wait_for_input(&mut self) {
        // On a virtual clock the bell also says the clock advanced (no source shows
        // that): spin on the bell, or an advance rung while polling would be cleared
        // unseen and the component never settle at the new time.
        let polling = !self.supervised && self.time.is_real();
        let found = |runner: &Runner| {
            if polling {
                runner.work_waiting()
            } else {
                runner.bell.is_rung()
            }
        };
        if polling && self.work_waiting() {
            // Work came during the turn: the component is behind a faster producer.
            // Let it deliver a batch undisturbed before the next turn (see
            // `BATCH_PAUSE`).
            for _ in 0..BATCH_PAUSE {
                std::hint::spin_loop();
            }
            self.found_by_polling = true;
            return;
        }
        let idle_since = Instant::now();
        let mut read_at = idle_since;
        'spin: loop {
            for _ in 0..SPIN_BATCH {
                if found(self) {
                    self.found_by_polling = polling;
                    self.found_at = (self.untimed && self.time.is_real()).then_some(read_at);
                    return;
                }
                std::hint::spin_loop();
            }
            read_at = Instant::now();
            if read_at.saturating_duration_since(idle_since) >= SPIN {
                break 'spin;
            }
        }
        if polling {
            // From here on, rings are what wakes the thread: clear, then look.
            self.bell.clear();
            if self.work_waiting() {
                return;
            }
        }
        for _ in 0..YIELD_ROUNDS {
            if self.bell.is_rung() {
                return;
            }
            std::thread::yield_now();
        }
        self.update_cpu(false);
        self.bell.park_until(None);
    }

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
        // 3. Timers.
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
            .filter(|on| self.pending.get(on.port) == Some(&true))
            .min_by_key(|on| on.port);
        if let Some(on) = fired {
            self.pending[on.port] = false;
            let arrived = self
                .labels
                .get(on.port)
                .and_then(Option::as_ref)
                .and_then(|label| label.take());
            self.goto(on.target, now);
            if let Some(arrived) = arrived {
                self.responded(arrived);
            }
            return true;
        }
        // 5. Pull requests.
        self.has_pull && self.serve_pulls()
    }

    fn notice_arrivals(&mut self, now: Instant) {
        for (index, input) in self.inputs.iter().enumerate() {
            let arrivals = input.arrivals();
            if arrivals != self.seen[index] {
                self.seen[index] = arrivals;
                self.pending[index] = true;
                self.last_arrival[index] = now;
            }
        }
    }

    fn after_due(&self, after: &AfterSpec) -> Instant {
        let base = match after.without {
            Some(port) => self
                .last_arrival
                .get(port)
                .map_or(self.entered_at, |t| (*t).max(self.entered_at)),
            None => self.entered_at,
        };
        later(base, after.delay)
    }

    fn period_of(&self, state: usize) -> Option<Duration> {
        self.spec.states[state]
            .periodic
            .and_then(|periodic| periodic.period.or(self.cx.period))
    }

    // -----------------------------------------------------------------------------
    // The default automaton.

    /// Run the table's outcome for `event`.
    fn apply(&mut self, event: Event) {
        let Outcome::Go { to, actions } = next(self.state, event) else {
            return;
        };
        let from = self.state;
        // On the way to `dead`, every call that remains (an exit section, `stop`) is
        // told so (`Context::stopping`); nothing comes back from `dead`.
        self.cx.stopping = to == State::Dead;
        self.run_actions(to, actions);
        if self.supervised {
            let now = self.state;
            if let Err(panic) = self.call(|automaton, cx| automaton.after_transition(from, now, cx))
            {
                self.set_error(Some(format!("panic after a transition: {panic}")));
            }
        }
    }

    /// Compound components, while suspended: observe the instances (their events keep
    /// the compound's view and mapped variables current); nothing acts.
    fn observe_instances(&mut self) {
        if let Err(panic) = self.call(|automaton, cx| automaton.observe(cx)) {
            self.set_error(Some(format!("panic in the supervisor: {panic}")));
        }
    }

    /// Compound components: let the instances run before the user automaton is entered
    /// or resumed; false (and `running_error`) if they could not.
    fn before_running(&mut self) -> bool {
        if !self.supervised {
            return true;
        }
        let message = match self.call(|automaton, cx| automaton.before_running(cx)) {
            Ok(Ok(())) => return true,
            Ok(Err(fault)) => fault.text().to_owned(),
            Err(panic) => format!("panic before running: {panic}"),
        };
        self.set_error(Some(message));
        self.run_stop();
        self.set_state(State::RunningError);
        false
    }

    fn run_actions(&mut self, to: State, actions: &[Action]) {
        for action in actions {
            match action {
                Action::Start => {
                    self.set_state(State::Starting);
                    // A restart leaves the user automaton of the failed run behind.
                    self.user_entered = false;
                    self.pending_choice = None;
                    self.publish_user(None);
                    if let Err(message) = self.run_start() {
                        self.set_error(Some(message));
                        self.set_state(State::StartingError);
                        return;
                    }
                }
                Action::Stop => self.run_stop(),
                Action::ExitUser => {
                    if let Err(message) = self.exit_user() {
                        self.set_error(Some(message));
                        if to != State::Dead {
                            self.run_stop();
                            self.set_state(State::RunningError);
                            return;
                        }
                    }
                }
                Action::ResetUser => {
                    self.user = self.spec.initial;
                    self.user_entered = false;
                    self.pending_choice = None;
                    let initial = (!self.spec.states.is_empty()).then_some(self.spec.initial);
                    self.publish_user(initial);
                }
                // The user automaton runs inside `running`: set the state first.
                Action::EnterUser => {
                    if !self.before_running() {
                        return;
                    }
                    self.set_state(to);
                    // Packets that came while it did not run (queued while `ready`,
                    // or moved to it as a substitute) are arrivals in its initial
                    // state; their wait is not a response time.
                    self.arrivals_count_on_entry = true;
                    for label in self.labels.iter().flatten() {
                        let _ = label.take();
                    }
                    self.enter(self.spec.initial, self.time.now());
                    return;
                }
                Action::ResumeUser => {
                    if !self.before_running() {
                        return;
                    }
                    // Packets that waited while it was suspended: their wait is not a
                    // response time.
                    for label in self.labels.iter().flatten() {
                        let _ = label.take();
                    }
                    self.set_state(to);
                    self.resume();
                    return;
                }
            }
        }
        if to == State::Suspended && self.state == State::Running {
            self.suspended_at = Some(self.time.now());
        }
        self.set_state(to);
    }

    fn resume(&mut self) {
        if !self.user_entered {
            self.enter(self.user, self.time.now());
            return;
        }
        // Time in a state stops while suspended: shift the timers by the pause.
        let now = self.time.now();
        if let Some(since) = self.suspended_at.take() {
            let pause = now.saturating_duration_since(since);
            self.entered_at += pause;
            self.cx.entered_at = self.entered_at;
            for arrival in &mut self.last_arrival {
                *arrival += pause;
            }
        }
        self.next_periodic = self.period_of(self.user).map(|period| later(now, period));
    }

    fn set_state(&mut self, to: State) {
        if self.state == to {
            return;
        }
        self.state = to;
        self.update_cpu(true);
        // The monitor may be there already: the watchdog moved it to `running_error`
        // while a section overran.
        self.shared.update(|monitor| {
            let from = monitor.state;
            if from == to {
                return Vec::new();
            }
            monitor.state = to;
            vec![MonitorEvent::State { from, to }]
        });
    }

    /// Set the error on the monitor; a new one is logged (the same error again, as
    /// each failed retry of a recovery sets it, is not, and a component's errors are
    /// logged at most every `log::EVERY`, with the count held back).
    fn set_error(&mut self, error: Option<String>) {
        let mut new = false;
        self.shared.update(|monitor| {
            if monitor.error == error {
                return Vec::new();
            }
            new = true;
            monitor.error.clone_from(&error);
            vec![MonitorEvent::Error(error.clone())]
        });
        if new && let Some(message) = &error {
            crate::limited!(
                &self.cx.name,
                |held| tracing::warn!(component = %self.cx.name, "{message}{held}")
            );
        }
    }

    fn publish_user(&mut self, state: Option<usize>) {
        if self.published_user == state {
            return;
        }
        self.published_user = state;
        let name = state.map(|index| self.spec.states[index].name);
        self.shared.update(|monitor| {
            if monitor.user_state.as_deref() == name {
                return Vec::new();
            }
            let name = name.map(str::to_owned);
            monitor.user_state.clone_from(&name);
            vec![MonitorEvent::UserState(name)]
        });
    }

    // -----------------------------------------------------------------------------
    // Control port.

    fn handle_control(&mut self, message: ControlMessage) {
        if !message.take() {
            return; // Withdrawn by a sender that gave up waiting.
        }
        let reply = |answer: Reply| {
            let _ = message.reply.try_send(answer);
        };
        // Out of range, whoever sends it and whatever stands behind this component
        // (a proxy's remote instance checks again on its own node).
        if let Err(refused) = crate::ranges::command(&message.command) {
            return reply(Reply::Rejected(refused.to_string()));
        }
        // A remote instance's proxy answers some commands itself (`crate::remote`);
        // only supervised automata (compounds, proxies) have anything to say.
        if self.supervised {
            match self.automaton.forward(&message.command) {
                None => {}
                Some(Ok(())) => return reply(Reply::Done),
                Some(Err(error)) => return reply(Reply::Rejected(Chain(&*error).to_string())),
            }
        }
        match &message.command {
            Command::SetState(target) => match next(self.state, Event::Command(*target)) {
                Outcome::Go { .. } => {
                    reply(Reply::Accepted);
                    self.apply(Event::Command(*target));
                    reply(Reply::Done);
                }
                Outcome::Stay => reply(Reply::Done),
                Outcome::Reject(reason) => reply(Reply::Rejected(reason.to_owned())),
                // The loop never reads commands while `start` runs, so this is not
                // reached; answering keeps the sender from waiting anyway.
                Outcome::Defer | Outcome::Impossible => reply(Reply::Rejected(format!(
                    "not applicable in state {}",
                    self.state
                ))),
            },
            Command::Configure(configuration) => {
                let configuration = configuration.clone();
                match self.call(|automaton, _| automaton.configure(&configuration)) {
                    Ok(Ok(())) => {
                        self.shared.publish(MonitorEvent::Configured);
                        reply(Reply::Done);
                    }
                    Ok(Err(refused)) => reply(Reply::Rejected(format!(
                        "invalid configuration: {}",
                        excerpt(&Chain(&refused).to_string(), REASON_CHARS)
                    ))),
                    Err(panic) => reply(Reply::Rejected(format!(
                        "panic in configure: {}",
                        excerpt(&panic, REASON_CHARS)
                    ))),
                }
            }
            Command::Set(name, value) => match self.spec.variable_index(name) {
                None => reply(Reply::Rejected(format!(
                    "no variable `{}`",
                    excerpt(name, EXCERPT_CHARS)
                ))),
                Some(index) if self.spec.variables[index].kind != VarKind::Controllable => reply(
                    Reply::Rejected(format!("`{name}` is observable, not controllable")),
                ),
                // Outside its declared range: refused, whoever asks (a supervisor,
                // coolctl, a remote compound), before the component sees it.
                Some(index)
                    if self.spec.variables[index]
                        .range
                        .is_some_and(|range| range.check(value).is_err()) =>
                {
                    let outside = self.spec.variables[index]
                        .range
                        .map(|range| range.check(value));
                    reply(Reply::Rejected(match outside {
                        Some(Err(outside)) => format!("invalid value for `{name}`: {outside}"),
                        _ => format!("invalid value for `{name}`"),
                    }))
                }
                Some(index) => {
                    let value = value.clone();
                    match self.call(|automaton, _| automaton.set(index, &value)) {
                        Ok(Ok(())) => reply(Reply::Done),
                        Ok(Err(refused)) => reply(Reply::Rejected(format!(
                            "invalid value for `{name}`: {}",
                            excerpt(&Chain(&refused).to_string(), REASON_CHARS)
                        ))),
                        Err(panic) => reply(Reply::Rejected(format!(
                            "panic in set: {}",
                            excerpt(&panic, REASON_CHARS)
                        ))),
                    }
                }
            },
            // (In range: checked above.)
            Command::SetPeriod(period) => {
                self.cx.set_period(*period);
                self.after_call();
                reply(Reply::Done);
            }
            Command::SetMaxResponse(bound) => {
                self.max_response = Some(*bound);
                match &self.watch {
                    Some(watch) => watch.set_limit(Some(*bound)),
                    None => {
                        self.watch = Some(Watch::new(
                            self.spec,
                            Arc::clone(&self.shared),
                            Some(*bound),
                            &self.time,
                        ));
                    }
                }
                let bound = *bound;
                self.shared.update(|monitor| {
                    if monitor.max_response == Some(bound) {
                        return Vec::new();
                    }
                    monitor.max_response = Some(bound);
                    vec![MonitorEvent::MaxResponse(Some(bound))]
                });
                reply(Reply::Done);
            }
            Command::SetPriority(priority) => {
                let priority = *priority;
                self.shared.update(|monitor| {
                    if monitor.priority == priority {
                        return Vec::new();
                    }
                    monitor.priority = priority;
                    vec![MonitorEvent::Priority(priority)]
                });
                self.apply_priority(priority);
                reply(Reply::Done);
            }
            Command::SetQuality(quality) => {
                let levels = self.timing.qualities.len().max(1);
                if *quality >= levels {
                    reply(Reply::Rejected(format!(
                        "quality {quality} out of range: {levels} level(s)"
                    )));
                } else {
                    self.quality_by_other_means(*quality, "quality set through the control port");
                    reply(Reply::Done);
                }
            }
            Command::SetDegradation(level) => {
                let level = *level;
                if self.supervised {
                    match self.call(|automaton, cx| automaton.set_degradation(level, cx)) {
                        Ok(Ok(())) => reply(Reply::Done),
                        Ok(Err(refused)) => reply(Reply::Rejected(refused.to_string())),
                        Err(panic) => reply(Reply::Rejected(format!(
                            "panic in set_degradation: {panic}"
                        ))),
                    }
                } else {
                    // An instance whose compound manages its level, commanded by
                    // someone else (an operator): the level is set by other means, as
                    // a period or quality is, and its supervisor keeps it (neither
                    // clamps it nor promotes below it) until the same means move it.
                    let pinned = !message.by_supervisor
                        && self
                            .shared
                            .adapt_managed
                            .load(std::sync::atomic::Ordering::Acquire);
                    match self.adapt.as_ref().map(|adapt| adapt.ladder.max_level()) {
                        None | Some(0) => reply(Reply::Rejected(
                            "no adaptation levels: the timing block has no period interval and fewer than two quality levels".to_owned(),
                        )),
                        Some(max) if level > max => reply(Reply::Rejected(
                            DegradationRefused::OutOfRange { level, max }.to_string(),
                        )),
                        Some(_) if pinned => {
                            self.pin_level(level);
                            reply(Reply::Done);
                        }
                        Some(_) if level < self.floor_level() => reply(Reply::Rejected(format!(
                            "degradation level {level} is below {}, where the period and quality set by other means stand (SetPeriod and SetQuality move them)",
                            self.floor_level()
                        ))),
                        Some(_) => {
                            self.set_level(level, "commanded through the control port");
                            reply(Reply::Done);
                        }
                    }
                }
            }
        }
    }

    /// Apply `priority` to this thread and publish what holds (an event and a log line
    /// when it changed; a refusal never fails the component).
    fn apply_priority(&mut self, priority: i32) {
        let Some(scheduling) = self.scheduling.as_mut() else {
            return;
        };
        let applied = scheduling.apply(priority);
        match &applied {
            OsPriority::Inherited => {}
            OsPriority::NotApplied(why) => crate::limited!(&self.cx.name, |held| tracing::warn!(
                component = %self.cx.name,
                "priority {priority} not applied to the thread: {why}{held}"
            )),
            how => {
                tracing::info!(component = %self.cx.name, "priority {priority} applied: {how:?}")
            }
        }
        self.shared.update(|monitor| {
            if monitor.os_priority == applied {
                return Vec::new();
            }
            monitor.os_priority = applied.clone();
            vec![MonitorEvent::OsPriority(applied)]
        });
    }

    /// A quality set by a command or a `degrade` plan step: the adaptation level and
    /// floor follow it (before the `Quality` event, which then shows them).
    fn quality_by_other_means(&mut self, quality: usize, why: &str) {
        self.cx.quality = quality;
        self.resync_level(why, Pin::Quality);
        self.set_quality(quality);
    }

    fn set_quality(&mut self, quality: usize) {
        self.cx.quality = quality;
        self.shared.update(|monitor| {
            monitor.quality = quality;
            vec![MonitorEvent::Quality(quality)]
        });
    }

    // -----------------------------------------------------------------------------
    // User calls.

    /// Run one user call under `catch_unwind`, account its time, publish its changes.
    fn call<R>(
        &mut self,
        body: impl FnOnce(&mut dyn Driven, &mut Context) -> R,
    ) -> Result<R, String> {
        self.call_watched(None, body)
            .map_err(|failure| match failure {
                Failure::Panic(message) | Failure::Overrun(message) => message,
                Failure::Fault(fault) => fault.text().to_owned(),
            })
    }

    /// [`Runner::call`] for the section `watched` (state, section): the max_response
    /// watchdog watches it, and a section that overran (tripped by the watchdog, or
    /// returning late) fails with [`Failure::Overrun`], its outcome discarded.
    fn call_watched<R>(
        &mut self,
        watched: Option<(usize, Section)>,
        body: impl FnOnce(&mut dyn Driven, &mut Context) -> R,
    ) -> Result<R, Failure> {
        // Without a watchdog (no max_response), the call starts from the turn's clock
        // reading (taken at most a few hundred nanoseconds of runner work ago, or at
        // the end of the previous call): one clock read per call saved on the
        // per-packet path. The watchdog gets a reading of its own.
        let started = if self.watch.is_some() {
            self.time.now()
        } else {
            self.clock
        };
        if let (Some((state, section)), Some(watch)) = (watched, &self.watch) {
            watch.begin(started, state, section);
        }
        let automaton = &mut *self.automaton;
        let cx = &mut self.cx;
        let result = catch_unwind(AssertUnwindSafe(|| body(automaton, cx)));
        let tripped = watched.is_some() && self.watch.as_ref().is_some_and(|watch| watch.end());
        self.clock = self.time.now();
        let took = self.clock.saturating_duration_since(started);
        self.last_took = took;
        // Elapsed time is accumulated here and published with the CPU time (see
        // `update_timing`), keeping the monitor lock off the per-call path.
        self.elapsed += took;
        let bound = self.max_response.filter(|bound| tripped || took > *bound);
        if bound.is_some() && !tripped {
            // (A tripped call was counted by the watchdog.)
            self.shared.update(|monitor| {
                monitor.overruns += 1;
                vec![MonitorEvent::Overrun {
                    took,
                    total: monitor.overruns,
                }]
            });
        }
        if let (Some((state, section)), Some(bound)) = (watched, bound) {
            self.discard_requests();
            self.after_call();
            return Err(Failure::Overrun(format!(
                "overrun in state `{}` ({section:?} section): {} {took:?}, max_response {bound:?}; its outcome was discarded",
                self.spec.states[state].name,
                if tripped { "returned after" } else { "ran" },
            )));
        }
        self.after_call();
        result.map_err(|payload| Failure::Panic(panic_message(payload.as_ref())))
    }

    /// Forget what an overrun section asked of the runtime (`end`, a result, a period):
    /// the published values stay.
    fn discard_requests(&mut self) {
        self.cx.end_requested = false;
        if self.cx.result_changed || self.cx.period_changed {
            let monitor = self.shared.snapshot();
            if self.cx.result_changed {
                self.cx.result_changed = false;
                self.cx.result = monitor.result;
            }
            if self.cx.period_changed {
                self.cx.period_changed = false;
                self.cx.period = monitor.period;
            }
        }
    }

    /// Publish what the last call changed in the context and the variables.
    fn after_call(&mut self) {
        if !self.cx.supervision.is_empty() {
            let steps = std::mem::take(&mut self.cx.supervision);
            self.shared.update(|monitor| {
                monitor.supervision_steps += steps.len() as u64;
                monitor.supervision.extend(steps.iter().cloned());
                let excess = monitor
                    .supervision
                    .len()
                    .saturating_sub(crate::monitor::SUPERVISION_HISTORY);
                monitor.supervision.drain(..excess);
                steps.into_iter().map(MonitorEvent::Supervision).collect()
            });
        }
        if self.cx.result_changed {
            self.cx.result_changed = false;
            let result = self.cx.result.clone();
            self.shared.update(|monitor| {
                monitor.result = result.clone();
                vec![MonitorEvent::Result(result)]
            });
        }
        if self.cx.period_changed {
            self.cx.period_changed = false;
            let period = self.cx.period;
            self.reanchor();
            // The level first: the `Period` event then shows where it stands.
            self.resync_level(
                "period set through the control port or by the component",
                Pin::Period,
            );
            self.shared.update(|monitor| {
                monitor.period = period;
                vec![MonitorEvent::Period(period)]
            });
        }
        self.publish_variables();
    }

    fn publish_variables(&mut self) {
        if self.spec.variables.is_empty() {
            return;
        }
        let automaton = &*self.automaton;
        let values: Vec<_> = (0..self.spec.variables.len())
            .map(|index| catch_unwind(AssertUnwindSafe(|| automaton.get(index))).ok())
            .collect();
        let spec = self.spec;
        self.shared.update(|monitor| {
            let mut events = Vec::new();
            for (index, value) in values.into_iter().enumerate() {
                let (Some(value), Some(slot)) = (value, monitor.variables.get_mut(index)) else {
                    continue;
                };
                if slot.1 != value {
                    slot.1 = value.clone();
                    events.push(MonitorEvent::Variable {
                        name: spec.variables[index].name.to_owned(),
                        value,
                    });
                }
            }
            events
        });
    }

    /// Publish the elapsed time (if it changed) and the thread's CPU time (a system
    /// call: at most once per `CPU_TIME_REFRESH` unless `force`).
    fn update_cpu(&mut self, force: bool) {
        if self.mirrors_times {
            return;
        }
        let refresh_cpu =
            force || self.clock.saturating_duration_since(self.cpu_updated) >= CPU_TIME_REFRESH;
        let cpu = if refresh_cpu {
            self.cpu_updated = self.time.now();
            cpu_time::ThreadTime::try_now()
                .ok()
                .map(|time| time.as_duration())
        } else {
            None
        };
        if cpu.is_none() && self.elapsed == self.elapsed_published {
            return;
        }
        self.elapsed_published = self.elapsed;
        let elapsed = self.elapsed;
        let clock = self.clock;
        let load = self.adapt.as_mut().map(|adapt| {
            if let Some(cpu) = cpu {
                adapt.profile(cpu, clock);
            }
            (adapt.detector.load(), adapt.cpu_share)
        });
        self.shared.quietly(|monitor| {
            monitor.elapsed_time = elapsed;
            if let Some((load, cpu_share)) = load {
                monitor.adaptation.load = load;
                monitor.adaptation.cpu_share = cpu_share;
            }
            if let Some(cpu) = cpu {
                monitor.cpu_time = cpu;
            }
        });
    }

    fn run_start(&mut self) -> Result<(), String> {
        // A ranged variable starts inside its range, however its value was given (an
        // instance's override, the variables a component was built with).
        for (index, variable) in self.spec.variables.iter().enumerate() {
            let Some(range) = variable.range else {
                continue;
            };
            let automaton = &*self.automaton;
            let Ok(value) = catch_unwind(AssertUnwindSafe(|| automaton.get(index))) else {
                continue;
            };
            if let Err(outside @ crate::OutOfRange::Outside { .. }) = range.check(&value) {
                return Err(format!(
                    "the initial value of `{}`: {outside}",
                    variable.name
                ));
            }
        }
        match self.call(|automaton, cx| automaton.start(cx)) {
            Ok(Ok(())) => {
                self.set_error(None);
                Ok(())
            }
            Ok(Err(fault)) => Err(format!("start failed: {fault}")),
            Err(panic) => Err(format!("panic in start: {panic}")),
        }
    }

    fn run_stop(&mut self) {
        if let Err(panic) = self.call(|automaton, cx| automaton.stop(cx)) {
            self.set_error(Some(format!("panic in stop: {panic}")));
        }
    }

    fn run_section(&mut self, state: usize, section: Section) -> Result<(), Failure> {
        match self.call_watched(Some((state, section)), |automaton, cx| {
            automaton.section(state, section, cx)
        }) {
            Ok(Ok(())) => Ok(()),
            Ok(Err(fault)) => Err(Failure::Fault(fault)),
            Err(failure) => Err(failure),
        }
    }

    /// Run a section and its continuity plan if it fails.
    fn section_with_plan(&mut self, state: usize, section: Section) -> Recovery {
        match self.run_section(state, section) {
            Ok(()) => Recovery::Recovered,
            Err(failure) => self.recover(state, Some(section), failure),
        }
    }

    /// Run the continuity plan for a failure in `state` (paper 3.5).
    fn recover(&mut self, state: usize, section: Option<Section>, failure: Failure) -> Recovery {
        let place = match (self.spec.states.get(state), section) {
            (Some(spec), Some(section)) => format!("state `{}` ({section:?} section)", spec.name),
            (Some(spec), None) => format!("state `{}`", spec.name),
            // No user automaton (a component that only answers pulls): no state to name.
            (None, _) => "`running`".to_owned(),
        };
        let fault = match failure {
            Failure::Panic(message) => {
                return Recovery::Failed(format!("panic in {place}: {message}"));
            }
            // No continuity plan for an overrun: its outcome is discarded.
            Failure::Overrun(message) => return Recovery::Failed(message),
            Failure::Fault(fault) => fault,
        };
        let Some(index) = fault
            .exception_index()
            .filter(|index| *index < self.spec.exceptions.len())
        else {
            return Recovery::Failed(format!("fault in {place}: {}", fault.text()));
        };
        let exception = &self.spec.exceptions[index];
        let message = fault.text().to_owned();
        if let Err(panic) = self.call(|automaton, cx| automaton.exception(index, &message, cx)) {
            return Recovery::Failed(format!(
                "panic in the handler of exception `{}`: {panic}",
                exception.name
            ));
        }
        for step in exception.plan {
            match *step {
                PlanStep::Ignore => {
                    crate::limited!(
                        (&self.cx.name, exception.name),
                        |held| tracing::warn!(component = %self.cx.name, "exception `{}` in {place} ignored: {message}{held}", exception.name)
                    );
                    return Recovery::Recovered;
                }
                PlanStep::Goto(target) if target < self.spec.states.len() => {
                    return Recovery::Goto(target);
                }
                PlanStep::Goto(_) => {}
                PlanStep::Degrade => {
                    if self.cx.quality + 1 < self.timing.qualities.len() {
                        let quality = self.cx.quality + 1;
                        self.quality_by_other_means(quality, "a `degrade` continuity plan step");
                        return Recovery::Recovered;
                    }
                }
                PlanStep::Retry { count, every } => {
                    let Some(section) = section else { continue };
                    for _ in 0..count {
                        match self.time.as_virtual().filter(|_| self.harnessed) {
                            // A harness's clock is the component's own: the retry
                            // waits on it, not in real time.
                            Some(clock) => {
                                let _ = clock.advance_with_timeout(every, Duration::ZERO);
                            }
                            None => std::thread::sleep(every),
                        }
                        self.clock = self.time.now();
                        if self.run_section(state, section).is_ok() {
                            return Recovery::Recovered;
                        }
                    }
                }
            }
        }
        Recovery::Failed(format!(
            "exception `{}` in {place}: {message}",
            exception.name
        ))
    }

    /// A failure no plan recovered: `running_error`.
    fn fail(&mut self, message: String) {
        self.set_error(Some(message));
        self.apply(Event::Fault);
    }

    // -----------------------------------------------------------------------------
    // The user automaton.

    /// Leave the current user state (its exit section), as part of a default-automaton
    /// transition.
    fn exit_user(&mut self) -> Result<(), String> {
        let result = if self.user_entered && self.spec.states[self.user].exit {
            match self.section_with_plan(self.user, Section::Exit) {
                Recovery::Failed(message) => Err(message),
                Recovery::Recovered | Recovery::Goto(_) => Ok(()),
            }
        } else {
            Ok(())
        };
        self.user_entered = false;
        self.next_periodic = None;
        self.pending_choice = None;
        self.publish_user(None);
        result
    }

    /// A user transition to `target`: the exit section of the current state, then the
    /// entry of `target`.
    fn goto(&mut self, target: usize, now: Instant) {
        if target >= self.spec.states.len() {
            self.fail(format!("transition to unknown user state #{target}"));
            return;
        }
        if self.user_entered && self.spec.states[self.user].exit {
            if let Recovery::Failed(message) = self.section_with_plan(self.user, Section::Exit) {
                self.fail(message);
                return;
            }
            if self.state != State::Running {
                return;
            }
        }
        self.enter(target, now);
    }

    /// Enter user state `target` and run its entry section.
    fn enter(&mut self, target: usize, now: Instant) {
        if self.spec.states.is_empty() {
            // No user automaton: `running` only serves pull requests.
            return;
        }
        self.user = target;
        self.user_entered = true;
        self.entered_at = now;
        self.cx.entered_at = now;
        self.suspended_at = None;
        self.pending_choice = None;
        let unseen_count = std::mem::take(&mut self.arrivals_count_on_entry);
        for (index, input) in self.inputs.iter().enumerate() {
            let arrivals = input.arrivals();
            // (Not on an event input: a tick count moved to it with a connection may
            // hold events that its previous consumer already acted on.)
            let data = !matches!(
                self.spec.inputs.get(index).map(|spec| spec.kind),
                Some(InputKind::Tick) | None
            );
            self.pending[index] = unseen_count && data && arrivals != self.seen[index];
            self.seen[index] = arrivals;
            self.last_arrival[index] = now;
            // Arrivals before the state was entered are no events in it: their stamp
            // would time a later packet's response from them.
            if !self.pending[index]
                && let Some(Some(label)) = self.labels.get(index)
            {
                let _ = label.take();
            }
        }
        self.next_periodic = self.period_of(target).map(|period| later(now, period));
        if self.supervised {
            // The supervisor evaluates the new state's rules on its next turn (its
            // `wake_at` asks for that turn at once).
            self.automaton.entered(target);
        }
        self.publish_user(Some(target));
        if self.spec.states[target].entry {
            match self.section_with_plan(target, Section::Entry) {
                Recovery::Recovered => {}
                Recovery::Goto(state) => {
                    self.pending_choice = Some(state);
                    return;
                }
                Recovery::Failed(message) => {
                    self.fail(message);
                    return;
                }
            }
        }
        self.choose(target);
    }

    /// Run the periodic section due at `deadline`; schedule the next one.
    fn periodic(&mut self, deadline: Instant) {
        let state = self.user;
        let Some(period) = self.period_of(state) else {
            self.next_periodic = None;
            return;
        };
        self.reanchored = false;
        let mut missed_any = false;
        self.cx.deadline = Some(deadline);
        let outcome = self.section_with_plan(state, Section::Periodic);
        self.cx.deadline = None;
        match outcome {
            Recovery::Recovered => {}
            Recovery::Goto(target) => self.pending_choice = Some(target),
            Recovery::Failed(message) => {
                self.fail(message);
                return;
            }
        }
        if self.state != State::Running || self.user != state {
            return;
        }
        if !self.reanchored {
            // Absolute deadlines: the next one is a period after this one, not after now
            // (the clock as the section's call ended).
            let now = self.clock;
            let mut next = later(deadline, period);
            if next <= now {
                let late = now.duration_since(next).as_nanos();
                let missed = u64::try_from(late / period.as_nanos().max(1))
                    .unwrap_or(u64::MAX)
                    .saturating_add(1);
                missed_any = true;
                self.shared.update(|monitor| {
                    monitor.missed_deadlines += missed;
                    vec![MonitorEvent::MissedDeadline {
                        missed,
                        total: monitor.missed_deadlines,
                    }]
                });
                next = later(now, period);
            }
            self.next_periodic = Some(next);
        }
        if self.adapt.as_ref().is_some_and(|adapt| adapt.enabled) {
            self.observe(self.last_took, period, missed_any);
            self.equalize(deadline, period, !self.reanchored && !missed_any);
        }
        if self.pending_choice.is_none() {
            self.choose(state);
        }
    }

    /// Equalization (`crate::equalize`): feed the seat this periodic section (when
    /// `on_time`: a period that missed its deadline or was re-anchored says nothing of
    /// its phase); when it says so, delay the next deadline once and publish an
    /// `Equalized` step.
    fn equalize(&mut self, deadline: Instant, period: Duration, on_time: bool) {
        let Some(adapt) = self.adapt.as_mut() else {
            return;
        };
        if !adapt.equalize || !self.time.is_real() {
            return; // (Phases on a virtual clock say nothing about the processor.)
        }
        // CPU time and waits since the previous periodic section ended.
        let stats = adapt
            .stats
            .get_or_insert_with(ThreadStats::of_current_thread);
        let Some((cpu, waited)) = stats.since_last() else {
            return;
        };
        if !on_time {
            return;
        }
        // Without the OS's figure: the elapsed time the thread did not spend on a CPU
        // while its section ran.
        let waited = waited.unwrap_or_else(|| self.last_took.saturating_sub(cpu));
        let name = &self.cx.name;
        let seat = adapt
            .seat
            .get_or_insert_with(|| Board::process().seat(name, EqualizeConfig::default()));
        let Some(shift) = seat.observe(Activation {
            deadline,
            cpu,
            waited,
            period,
        }) else {
            return;
        };
        let level = adapt.level;
        if let Some(next) = self.next_periodic.as_mut() {
            *next = later(*next, shift.delay);
        }
        let step = Adaptation {
            component: self.cx.name.clone(),
            action: AdaptAction::Equalized,
            from: level,
            to: level,
            period: self.cx.period,
            quality: Some(self.cx.quality),
            detail: format!(
                "phase moved {:?} later: its sections coincided with {}'s",
                shift.delay,
                shift.away_from.join("'s, ")
            ),
        };
        self.shared.adaptation_step(step, |_| {});
    }

    /// Re-anchor the periodic deadline on the current period, from now.
    fn reanchor(&mut self) {
        if self.user_entered && self.state == State::Running {
            self.next_periodic = self
                .period_of(self.user)
                .map(|period| later(self.time.now(), period));
            self.reanchored = true;
        }
    }

    /// Ask the user's `choose` for a `may` target.
    fn choose(&mut self, state: usize) {
        let may = self.spec.states[state].may;
        if may.is_empty() || self.state != State::Running || self.user != state {
            return;
        }
        match self.call(|automaton, cx| automaton.choose(state, cx)) {
            Ok(None) => {}
            Ok(Some(target)) if may.contains(&target) => self.pending_choice = Some(target),
            Ok(Some(target)) => self.fail(format!(
                "choose in state `{}` returned #{target}, not one of its `may` targets",
                self.spec.states[state].name
            )),
            Err(panic) => self.fail(format!(
                "panic in choose of state `{}`: {panic}",
                self.spec.states[state].name
            )),
        }
    }

    /// Answer waiting pull requests; true if there were any.
    fn serve_pulls(&mut self) -> bool {
        let mut served = false;
        for index in 0..self.outputs.len() {
            let output = Arc::clone(&self.outputs[index]);
            let answers = self.spec.outputs.get(index).is_some_and(|spec| spec.pull);
            while let Some(requester) = output.next_request() {
                served = true;
                if !answers {
                    continue; // Not a pull output: the request is dropped.
                }
                output.begin_answer(requester);
                let result = self.call(|automaton, cx| automaton.answer(index, cx));
                output.end_answer();
                let failure = match result {
                    Ok(Ok(())) => continue,
                    Ok(Err(fault)) => Failure::Fault(fault),
                    Err(panic) => Failure::Panic(panic),
                };
                match self.recover(self.user, None, failure) {
                    Recovery::Recovered => {}
                    Recovery::Goto(target) => {
                        self.pending_choice = Some(target);
                        return true;
                    }
                    Recovery::Failed(message) => {
                        self.fail(format!(
                            "answering a pull request on `{}`: {message}",
                            self.spec.outputs[index].name
                        ));
                        return true;
                    }
                }
            }
        }
        served
    }
}

/// A component's own adaptation: its ladder, its detector and where it stands.
struct Local {
    /// Whether detection runs (`AdaptConfig::enabled_for`).
    enabled: bool,
    ladder: Ladder,
    detector: Detector,
    /// Where the component stands: [`Ladder::level_of`] its period and quality.
    level: u32,
    /// What was set by other means (a command, a `degrade` plan step, the component's
    /// own `set_period`): promotions stop there.
    floor: Floor,
    /// `set_level` is applying a level: the period change it makes is adaptation's,
    /// not another means' (no floor from it).
    applying: bool,
    /// `hold_periods + window + 1` (published for a supervisor's settling time).
    settle_periods: u32,
    /// `Exhausted` was published for the current violation.
    exhausted: bool,
    /// The last CPU time reading and when (wall clock), for `cpu_share`.
    cpu_mark: Option<(Instant, Duration)>,
    /// The thread's CPU time over wall-clock time between readings, smoothed.
    cpu_share: f64,
    /// The process's idle probe (`crate::idle`), taken at the first observation on the
    /// real clock; `None` before, on a virtual clock, or if it could not start.
    probe: Option<IdleProbe>,
    /// Whether the probe was asked for (never, with `AdaptConfig::idle_probe` off).
    probe_asked: bool,
    /// Whether equalization may move its phase (`AdaptConfig::equalize`).
    equalize: bool,
    /// Its place on the process's equalization board (`crate::equalize`), taken at its
    /// first periodic section on the real clock.
    seat: Option<Seat>,
    /// The thread's CPU time and run-queue wait (equalization), opened on the
    /// component's thread at its first periodic section.
    stats: Option<ThreadStats>,
}

/// Which axis a change by other means set (it becomes the floor of promotions).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Pin {
    Period,
    Quality,
}

impl Local {
    /// `None` when there is nothing to adapt and nothing to detect.
    fn new(config: AdaptConfig, timing: &TimingSpec) -> Option<Local> {
        let config = config.sanitized();
        let enabled = config.enabled_for(timing);
        let ladder = Ladder::new(timing, config.period_steps);
        (enabled || ladder.max_level() > 0).then(|| Local {
            enabled,
            ladder,
            detector: Detector::new(config),
            level: 0,
            floor: Floor::default(),
            applying: false,
            settle_periods: config
                .hold_periods
                .saturating_add(config.window)
                .saturating_add(1),
            exhausted: false,
            cpu_mark: None,
            cpu_share: 0.0,
            probe: None,
            probe_asked: !config.idle_probe,
            equalize: config.equalize,
            seat: None,
            stats: None,
        })
    }

    /// Load profiling (paper 3.6.1, "CPU time versus elapsed time"): the share of a
    /// core the thread used since the last CPU time reading (taken anyway for the
    /// monitor, at most every 10 ms while busy).
    fn profile(&mut self, cpu: Duration, now: Instant) {
        if let Some((then, before)) = self.cpu_mark {
            let wall = now.saturating_duration_since(then).as_secs_f64();
            if wall >= 0.001 {
                let share = cpu.saturating_sub(before).as_secs_f64() / wall;
                self.cpu_share = 0.5 * self.cpu_share + 0.5 * share.min(1.0);
                self.cpu_mark = Some((now, cpu));
            }
        } else {
            self.cpu_mark = Some((now, cpu));
        }
    }
}

impl Runner {
    /// An `on` transition handled packets that arrived from `arrived` on: publish the
    /// response time; past `max_response` it is a late response, and a timing
    /// violation for the adaptation detector (paper 3.6).
    fn responded(&mut self, arrived: Instant) {
        let took = self.clock.saturating_duration_since(arrived);
        let Some(bound) = self.max_response else {
            return;
        };
        if self.responses.len() == crate::monitor::RESPONSE_WINDOW {
            self.responses.pop_front();
        }
        self.responses.push_back(took);
        let mut sorted: Vec<Duration> = self.responses.iter().copied().collect();
        sorted.sort_unstable();
        let at = |share: f64| sorted[((sorted.len() - 1) as f64 * share).round() as usize];
        let (p50, p99) = (at(0.5), at(0.99));
        let late = took > bound;
        self.shared.update(|monitor| {
            let response = &mut monitor.response;
            response.p50 = p50;
            response.p99 = p99;
            response.worst = response.worst.max(took);
            response.count += 1;
            if !late {
                return Vec::new();
            }
            response.late += 1;
            vec![MonitorEvent::LateResponse {
                took,
                bound,
                total: response.late,
            }]
        });
        if self.adapt.as_ref().is_some_and(|adapt| adapt.enabled) {
            self.observe(took, bound, late);
        }
    }

    /// Feed the detector one periodic section; act on a new verdict (a component no
    /// compound supervises degrades or promotes itself, one level per verdict).
    fn observe(&mut self, took: Duration, period: Duration, missed: bool) {
        let Some(adapt) = self.adapt.as_mut() else {
            return;
        };
        let now = Setting {
            period: self.cx.period,
            quality: self.cx.quality,
        };
        let reference = adapt
            .ladder
            .toward(now, adapt.level.saturating_sub(1), adapt.floor)
            .period
            .unwrap_or(period)
            .min(period);
        let idle = match self.time.as_virtual() {
            Some(clock) => clock.idle(),
            None => {
                if !adapt.probe_asked {
                    adapt.probe_asked = true;
                    adapt.probe = IdleProbe::shared();
                }
                adapt.probe.as_ref().is_none_or(IdleProbe::idle)
            }
        };
        let verdict = adapt.detector.observe(Observation {
            elapsed: took,
            period,
            missed,
            reference,
            idle,
        });
        let load = adapt.detector.load();
        // (Without a new verdict, the load is published with the timing counters.)
        let Some(verdict) = verdict else {
            return;
        };
        self.shared.set_pressure(verdict, load);
        if verdict != Pressure::Violation {
            adapt.exhausted = false;
        }
        if self
            .shared
            .adapt_managed
            .load(std::sync::atomic::Ordering::Acquire)
        {
            return; // The compound's supervisor decides.
        }
        let (level, max) = (adapt.level, adapt.ladder.max_level());
        let floor = adapt.ladder.floor_level(adapt.floor);
        match verdict {
            Pressure::Violation if level < max => {
                self.set_level(level + 1, "time violation");
            }
            Pressure::Violation if !adapt.exhausted => {
                adapt.exhausted = true;
                let step = Adaptation {
                    component: self.cx.name.clone(),
                    action: AdaptAction::Exhausted,
                    from: level,
                    to: level,
                    period: self.cx.period,
                    quality: Some(self.cx.quality),
                    detail: "time violation at the highest level".to_owned(),
                };
                self.shared.adaptation_step(step, |_| {});
            }
            Pressure::Spare if level > floor => {
                self.set_level(level - 1, "spare time");
            }
            _ => {}
        }
    }

    /// The level the period and quality set by other means stand at (promotions stop
    /// there); 0 without adaptation.
    fn floor_level(&self) -> u32 {
        self.adapt
            .as_ref()
            .map_or(0, |adapt| adapt.ladder.floor_level(adapt.floor))
    }

    /// Go towards adaptation level `target`, one axis at a time from where the
    /// component stands ([`Ladder::toward`]: a degradation stretches the period first,
    /// a promotion raises the quality first and stops at the floor), applied as the
    /// control port's `SetPeriod` and `SetQuality` are (events `Period`, `Quality`),
    /// then an `Adaptation` step; the detector starts afresh after its hold-down.
    fn set_level(&mut self, target: u32, why: &str) {
        let Some(adapt) = self.adapt.as_mut() else {
            return;
        };
        let from = adapt.level;
        let now = Setting {
            period: self.cx.period,
            quality: self.cx.quality,
        };
        let to = adapt.ladder.toward(now, target, adapt.floor);
        let level = adapt.ladder.level_of(to.period, to.quality);
        adapt.level = level;
        adapt.exhausted = false;
        let promoted = level < from;
        adapt.detector.reset(promoted);
        let load = adapt.detector.load();
        let floor = adapt.ladder.floor_level(adapt.floor);
        if to.quality != self.cx.quality {
            self.set_quality(to.quality);
        }
        if let Some(period) = to.period
            && self.cx.period != Some(period)
        {
            if let Some(adapt) = self.adapt.as_mut() {
                adapt.applying = true;
            }
            self.cx.set_period(period);
            // Publishes the period and re-anchors the schedule (the resync it asks
            // for finds the level already there).
            self.after_call();
            if let Some(adapt) = self.adapt.as_mut() {
                adapt.applying = false;
            }
        }
        self.shared.set_pressure(Pressure::Nominal, load);
        if level == from {
            return;
        }
        self.publish_move(from, level, floor, why);
    }

    /// Publish a move of the adaptation level from `from` to `level` (the floor of
    /// promotions now `floor`) as an `Adaptation` step saying `why`.
    fn publish_move(&self, from: u32, level: u32, floor: u32, why: &str) {
        let step = Adaptation {
            component: self.cx.name.clone(),
            action: if level < from {
                AdaptAction::Promoted
            } else {
                AdaptAction::Degraded
            },
            from,
            to: level,
            period: self.cx.period,
            quality: Some(self.cx.quality),
            detail: why.to_owned(),
        };
        self.shared.adaptation_step(step, |status| {
            status.level = level;
            status.min_level = floor;
        });
    }

    /// Level `level`, set by other means on an instance its compound manages (an
    /// operator's `SetDegradation`): the floor is lifted, the level set, then both
    /// axes pinned where they stand, so that the supervisor keeps it (`min_level`).
    fn pin_level(&mut self, level: u32) {
        let Some(adapt) = self.adapt.as_mut() else {
            return;
        };
        adapt.floor = Floor::default();
        self.set_level(
            level,
            "commanded through the control port (kept by its supervisor)",
        );
        let Some(adapt) = self.adapt.as_mut() else {
            return;
        };
        adapt.floor = Floor {
            quality: self.cx.quality,
            period: self
                .cx
                .period
                .filter(|period| adapt.ladder.period.is_some_and(|nominal| *period > nominal)),
        };
        let floor = adapt.ladder.floor_level(adapt.floor);
        self.shared
            .quietly(|monitor| monitor.adaptation.min_level = floor);
    }

    /// The period or quality was set by other means (a command, a `degrade` plan, the
    /// component's own `set_period`): it becomes the floor of promotions on its axis
    /// (`pin`), the level is where period and quality stand ([`Ladder::level_of`]), an
    /// `Adaptation` step says so (`why`), and the detector starts afresh.
    fn resync_level(&mut self, why: &str, pin: Pin) {
        let Some(adapt) = self.adapt.as_mut() else {
            return;
        };
        if adapt.applying {
            return; // Adaptation's own period change: `set_level` publishes it.
        }
        match pin {
            Pin::Quality => adapt.floor.quality = self.cx.quality,
            Pin::Period => {
                adapt.floor.period = self
                    .cx
                    .period
                    .filter(|period| adapt.ladder.period.is_some_and(|nominal| *period > nominal));
            }
        }
        let floor = adapt.ladder.floor_level(adapt.floor);
        let level = adapt.ladder.level_of(self.cx.period, self.cx.quality);
        if level == adapt.level {
            self.shared
                .quietly(|monitor| monitor.adaptation.min_level = floor);
            return;
        }
        let from = adapt.level;
        let promoted = level < from;
        adapt.level = level;
        adapt.exhausted = false;
        adapt.detector.reset(promoted);
        let load = adapt.detector.load();
        self.shared.set_pressure(Pressure::Nominal, load);
        self.publish_move(from, level, floor, why);
    }
}
