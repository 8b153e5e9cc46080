//! The default ports: the control port `c` ([`Handle::command`]) and the monitoring
//! port `m` ([`Handle::snapshot`], [`Handle::subscribe`], [`Handle::wait_for`]).
//!
//! The monitoring state of a component lives in one [`Shared`] (a `Mutex<Monitor>`
//! written by the component's thread at each change) plus the observers' channels.
//! Every change is sent to every observer as it happens; nobody polls.

use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, Sender, TrySendError};
use serde::{Deserialize, Serialize};

use crate::adapt::{AdaptStatus, Adaptation, Pressure};
use crate::automaton::TaskResult;
use crate::port::ErasedInput;
use crate::table::{Controllable, State};
use crate::value::Value;

/// How many events an observer's channel holds; events beyond that are dropped for
/// that observer (counted for all observers in [`Monitor::dropped_events`], and for
/// each in its own [`Subscription::dropped`]). The channel grows as events wait in it,
/// up to this bound: an observer that keeps up costs little memory.
pub const OBSERVER_CAPACITY: usize = 4096;

/// How long [`Handle::command`] waits for the component by default.
pub const DEFAULT_COMMAND_TIMEOUT: Duration = Duration::from_secs(2);

/// A command through the control port `c`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Command {
    /// Force a controllable state (the default controllable variable `new_state`).
    SetState(Controllable),
    /// A new configuration (the default controllable variable `configuration`).
    Configure(Value),
    /// Set a user controllable variable by name.
    Set(String, Value),
    /// The component period (`period`).
    SetPeriod(Duration),
    /// The longest a section may run (`max_response`).
    SetMaxResponse(Duration),
    /// The priority (`priority`): applied to the component's OS thread at once (see
    /// [`OsPriority`]; a refusal by the OS does not reject the command).
    SetPriority(i32),
    /// The quality level: an index into the timing block's qualities (0 = best).
    SetQuality(usize),
    /// The adaptation level (`docs/runtime.md`, "Adaptation"): for an atomic
    /// component, its place on its degradation ladder (period steps, then quality
    /// steps), applied as `SetPeriod` and `SetQuality` would be; for a compound, the
    /// current maximum degradation level its instances may reach. A compound's
    /// supervisor degrades and promotes its instances with it.
    SetDegradation(u32),
}

/// Why a command was rejected.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("component `{component}` rejected {command}: {reason}")]
pub struct Rejected {
    /// The component's name.
    pub component: String,
    /// The command, rendered (its first `ranges::EXCERPT_CHARS` characters).
    pub command: String,
    /// Why.
    pub reason: String,
}

/// A [`Handle::wait_for`] that did not see its condition in time.
#[derive(Debug, Clone, thiserror::Error)]
#[error("component `{}` did not reach the condition within {waited:?} (state {})", last.name, last.state)]
pub struct Timeout {
    /// How long it waited.
    pub waited: Duration,
    /// The last snapshot seen.
    pub last: Box<Monitor>,
}

/// What the monitoring port `m` publishes: the default observable variables and the
/// user's observable and controllable variables.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Monitor {
    /// The component instance's name.
    pub name: String,
    /// The default automaton state.
    pub state: State,
    /// The user automaton's current state, while it has one.
    pub user_state: Option<String>,
    /// The task result.
    pub result: TaskResult,
    /// The last error (set on `starting_error` and `running_error`, kept until a
    /// restart succeeds).
    pub error: Option<String>,
    /// User variables (observable and controllable), in declaration order.
    pub variables: Vec<(String, Value)>,
    /// The component thread's CPU time (read on state changes and before the thread
    /// waits, at most every 10 ms while it is busy).
    pub cpu_time: Duration,
    /// Wall-clock time spent in user code (hooks and sections).
    pub elapsed_time: Duration,
    /// Periodic deadlines missed (see `docs/runtime.md`, "Periodic sections").
    pub missed_deadlines: u64,
    /// User calls that ran longer than `max_response`.
    pub overruns: u64,
    /// Packets lost at this component's inputs, all ports together.
    pub overflows: u64,
    /// Packets lost per input port, in declaration order; a proxy adds what the
    /// remote instance lost at its inputs, and `@network`, what was lost on the way
    /// back from it (`docs/distribution.md`).
    pub port_overflows: Vec<(String, u64)>,
    /// The quality level (0 = best).
    pub quality: usize,
    /// The component period in effect: the nominal one, or what a command or
    /// adaptation set.
    pub period: Option<Duration>,
    /// The period the component was built with (its description's `timing`, with the
    /// instance's overrides), whatever commands and adaptation do to `period`.
    #[serde(default)]
    pub nominal_period: Option<Duration>,
    /// The response bound.
    pub max_response: Option<Duration>,
    /// The priority.
    pub priority: i32,
    /// How `priority` is applied to the component's OS thread.
    pub os_priority: OsPriority,
    /// Monitoring events dropped because an observer's channel was full.
    pub dropped_events: u64,
    /// Compound components only: the last [`SUPERVISION_HISTORY`] steps the supervisor
    /// took about its instances (failures, substitutions, restarts, recoveries), oldest
    /// first. Empty for atomic components.
    pub supervision: Vec<Supervision>,
    /// Compound components only: how many supervision steps were taken in all.
    pub supervision_steps: u64,
    /// Adaptation (paper 3.6): level, verdict and the last steps.
    #[serde(default)]
    pub adaptation: AdaptStatus,
    /// Aperiodic components with a `max_response`: their response times, from a
    /// packet's arrival to the end of the `on` transition that handled it.
    #[serde(default)]
    pub response: ResponseTimes,
}

/// How many responses [`ResponseTimes::p50`] and [`ResponseTimes::p99`] are taken
/// over.
pub const RESPONSE_WINDOW: usize = 64;

/// An aperiodic component's response times (paper 3.6: "the maximum delay for input
/// event processing", verified by "temporal labeling of input data"): from the arrival
/// of the oldest packet an `on` transition handles to the end of that transition's
/// sections, queueing included.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct ResponseTimes {
    /// The median of the last [`RESPONSE_WINDOW`] responses.
    pub p50: Duration,
    /// The 99th percentile of the last [`RESPONSE_WINDOW`] responses.
    pub p99: Duration,
    /// The longest response so far.
    pub worst: Duration,
    /// Responses measured.
    pub count: u64,
    /// Responses longer than `max_response`.
    pub late: u64,
}

/// How many supervision steps [`Monitor::supervision`] keeps.
pub const SUPERVISION_HISTORY: usize = 32;

/// One step a compound's supervisor took about one of its instances, published on the
/// compound's monitoring port ([`MonitorEvent::Supervision`]).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Supervision {
    /// The instance concerned (a local instance name of the compound).
    pub instance: String,
    /// What happened.
    pub step: Step,
    /// The instance's error or the reason, when there is one.
    pub detail: String,
}

impl std::fmt::Display for Supervision {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let instance = &self.instance;
        match &self.step {
            Step::Failed => write!(f, "{instance} failed")?,
            Step::Ignored => write!(f, "{instance} failed; ignored")?,
            Step::Propagated => write!(f, "{instance} failed; propagated")?,
            Step::Restarted => write!(f, "{instance} restarted")?,
            Step::Substituted { by } => write!(f, "{instance} substituted by {by}")?,
            Step::OutOfStep => write!(f, "{instance} out of step with its redundant group")?,
            Step::Enqueued => write!(f, "{instance} entered the recovery queue")?,
            Step::Retried => write!(f, "{instance} retried")?,
            Step::RetryFailed => write!(f, "{instance} retry failed")?,
            Step::Recovered => write!(f, "{instance} recovered")?,
            Step::Retired => write!(f, "{instance} retired (recovery deadline)")?,
            Step::Commanded { command } => write!(f, "{instance} commanded: {command}")?,
            Step::CommandRefused { command } => write!(f, "{instance} refused: {command}")?,
        }
        if !self.detail.is_empty() {
            write!(f, ": {}", self.detail)?;
        }
        Ok(())
    }
}

/// What a supervisor did (see [`Supervision`] and `docs/runtime.md`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[non_exhaustive]
pub enum Step {
    /// The instance went to `running_error` or `starting_error`.
    Failed,
    /// Its policy is `ignore`: it stays failed.
    Ignored,
    /// Its policy is `propagate` (or nothing could stand for it): the compound fails.
    Propagated,
    /// Its policy is `restart`: it was commanded back to `running`.
    Restarted,
    /// Its substitute took its place (connections moved to `by`).
    Substituted {
        /// The substitute (or, in a redundant group, the member now standing).
        by: String,
    },
    /// A redundant member stalled and was left out of packets at the compound's
    /// exported input: it no longer agrees with its group, so it stops leading or
    /// standing by and is resynchronized through the recovery queue (the detail says
    /// how many packets it missed).
    OutOfStep,
    /// It went into the recovery queue.
    Enqueued,
    /// The recovery queue restarted it (it is on probation until the next retry).
    Retried,
    /// The recovery queue tried to restart it and it did not come back to `running`
    /// (the detail says why); it stays queued until the next retry or its deadline.
    RetryFailed,
    /// It recovered and took its place back (the arrangement before the fault).
    Recovered,
    /// Its recovery deadline expired: it was destroyed (`dead`).
    Retired,
    /// A supervisor section commanded it through the compound's
    /// [`Commander`](crate::Commander), and it took the command.
    Commanded {
        /// The command, as the supervisor gave it (`suspend`, `set max_speed = 0.2`).
        command: String,
    },
    /// A supervisor section commanded it and the command was refused (the reason is
    /// the step's detail).
    CommandRefused {
        /// The command, as the supervisor gave it.
        command: String,
    },
}

/// One change on the monitoring port.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum MonitorEvent {
    /// The default automaton changed state.
    State {
        /// The previous state.
        from: State,
        /// The new state.
        to: State,
    },
    /// The user automaton changed state (`None`: it has no current state).
    UserState(Option<String>),
    /// `result` changed.
    Result(TaskResult),
    /// `error` changed.
    Error(Option<String>),
    /// A user variable changed.
    Variable {
        /// Its name.
        name: String,
        /// Its new value.
        value: Value,
    },
    /// Packets were lost at an input.
    Overflow {
        /// The input port.
        port: String,
        /// How many were lost now.
        lost: u64,
        /// How many were lost at this port in all.
        total: u64,
    },
    /// Periodic deadlines were missed.
    MissedDeadline {
        /// How many now.
        missed: u64,
        /// How many in all.
        total: u64,
    },
    /// A user call ran longer than `max_response`.
    Overrun {
        /// How long it ran.
        took: Duration,
        /// How many overruns in all.
        total: u64,
    },
    /// An aperiodic component responded later than its `max_response` (from a
    /// packet's arrival to the end of the transition that handled it): a timing
    /// violation.
    LateResponse {
        /// The response time.
        took: Duration,
        /// The bound, `max_response`.
        bound: Duration,
        /// How many late responses in all.
        total: u64,
    },
    /// The period changed.
    Period(Option<Duration>),
    /// The response bound `max_response` changed (a command).
    MaxResponse(Option<Duration>),
    /// The priority changed (a command; how it applies to the thread is
    /// [`MonitorEvent::OsPriority`]).
    Priority(i32),
    /// The quality level changed.
    Quality(usize),
    /// The configuration changed (through the control port).
    Configured,
    /// Compound components: the supervisor took a step about an instance.
    Supervision(Supervision),
    /// `priority` was applied to the component's thread, or could not be.
    OsPriority(OsPriority),
    /// The component's adaptation verdict changed (time violation, spare time, or
    /// neither).
    Pressure(Pressure),
    /// An adaptation step: a level changed, or a compound's supervisor acted.
    Adaptation(Adaptation),
}

/// How a component's `priority` is applied to its OS thread (`docs/runtime.md`,
/// "Priority"). Applying can fail (no `CAP_SYS_NICE` in a container): the component
/// runs on regardless, and this says what holds.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub enum OsPriority {
    /// Nothing applied: the thread has not started, or the priority is 0 and the thread
    /// keeps the scheduling it was created with.
    Inherited,
    /// Real-time round-robin scheduling (Linux `SCHED_RR`) at this static priority
    /// (1 to 99).
    RoundRobin(i32),
    /// Normal time-sharing scheduling at this nice value (-20, highest, to 19): a
    /// negative priority, a priority of 0 restored, or a positive priority when
    /// real-time scheduling was refused.
    Nice(i32),
    /// The OS refused, or the platform is not supported: why. The thread keeps its
    /// previous scheduling.
    NotApplied(String),
}

/// The sum of per-port loss counts, saturating (a proxy's come from the network).
pub fn total_overflows(ports: &[(String, u64)]) -> u64 {
    ports
        .iter()
        .fold(0, |total, (_, n)| total.saturating_add(*n))
}

/// The count of `port` in a list of per-port counts, added at 0 if missing.
pub(crate) fn count_at<'a>(counts: &'a mut Vec<(String, u64)>, port: &str) -> &'a mut u64 {
    let at = match counts.iter().position(|(name, _)| name == port) {
        Some(at) => at,
        None => {
            counts.push((port.to_owned(), 0));
            counts.len() - 1
        }
    };
    &mut counts[at].1
}

fn lock<T>(mutex: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The counts of one observer, shared by the publisher and the [`Subscription`].
#[derive(Debug, Default)]
struct Counts {
    /// Events published while it was subscribed (queued or dropped).
    published: AtomicU64,
    /// Events dropped because its channel was full.
    dropped: AtomicU64,
}

/// One observer: its channel and its counts.
struct Observer {
    sender: Sender<MonitorEvent>,
    counts: Arc<Counts>,
}

/// A subscription to a component's monitoring port ([`Handle::subscribe_counted`],
/// [`Handle::subscribe_waking`]): the events as they happen (it dereferences to their
/// [`Receiver`]), and how many were dropped for it because it fell behind.
///
/// An observer that does not take its events falls behind: once
/// [`OBSERVER_CAPACITY`] events wait in its channel, newer events are dropped for it
/// (never for the other observers, and the component never waits), and each drop is
/// counted in [`Subscription::dropped`] (and, for all observers together, in
/// [`Monitor::dropped_events`]). The events it does get are in order; a snapshot
/// ([`Handle::snapshot`]) always shows the current state, whatever was dropped.
pub struct Subscription {
    events: Receiver<MonitorEvent>,
    counts: Arc<Counts>,
}

impl std::fmt::Debug for Subscription {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Subscription")
            .field("queued", &self.events.len())
            .field("published", &self.published())
            .field("dropped", &self.dropped())
            .finish()
    }
}

impl Subscription {
    /// The events' channel.
    pub fn events(&self) -> &Receiver<MonitorEvent> {
        &self.events
    }

    /// How many events were dropped for this subscription so far (its channel was
    /// full: it fell behind).
    pub fn dropped(&self) -> u64 {
        self.counts.dropped.load(Ordering::Acquire)
    }

    /// How many events were published to this subscription so far: queued in its
    /// channel (taken or not) or dropped.
    pub fn published(&self) -> u64 {
        self.counts.published.load(Ordering::Acquire)
    }

    /// The events' channel alone (the counts are no longer reachable).
    pub fn into_events(self) -> Receiver<MonitorEvent> {
        self.events
    }
}

impl std::ops::Deref for Subscription {
    type Target = Receiver<MonitorEvent>;

    fn deref(&self) -> &Receiver<MonitorEvent> {
        &self.events
    }
}

/// The monitoring state of one component, shared by its thread and its handles.
pub(crate) struct Shared {
    monitor: Mutex<Monitor>,
    observers: Mutex<Vec<Observer>>,
    /// Doorbells rung after every event (compound supervisors watching this component).
    /// With, for each, a flag set before it is rung (which subscription has news).
    wakers: Mutex<Vec<(crate::automaton::Waker, Option<Arc<AtomicBool>>)>>,
    pub(crate) inputs: Vec<(&'static str, ErasedInput)>,
    dropped: AtomicU64,
    pub(crate) spawned: AtomicBool,
    /// Whether the component's thread is inside a section the max_response watchdog
    /// tripped (it has not returned yet).
    pub(crate) stuck: AtomicBool,
    /// The component's thread, once spawned.
    pub(crate) thread: std::sync::OnceLock<std::thread::ThreadId>,
    /// A compound's supervisor decides this component's adaptation level: its runner
    /// only detects and publishes its verdicts (set when the compound is built).
    pub(crate) adapt_managed: AtomicBool,
}

impl std::fmt::Debug for Shared {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Shared").finish_non_exhaustive()
    }
}

impl Shared {
    pub(crate) fn new(monitor: Monitor, inputs: Vec<(&'static str, ErasedInput)>) -> Shared {
        Shared {
            monitor: Mutex::new(monitor),
            observers: Mutex::new(Vec::new()),
            wakers: Mutex::new(Vec::new()),
            inputs,
            dropped: AtomicU64::new(0),
            spawned: AtomicBool::new(false),
            stuck: AtomicBool::new(false),
            thread: std::sync::OnceLock::new(),
            adapt_managed: AtomicBool::new(false),
        }
    }

    /// Change the monitor with `f`, and send the events `f` returned before anyone can
    /// see the change: a snapshot that shows a change implies its event is queued.
    pub(crate) fn update(&self, f: impl FnOnce(&mut Monitor) -> Vec<MonitorEvent>) {
        let mut monitor = lock(&self.monitor);
        for event in f(&mut monitor) {
            self.publish(event);
        }
    }

    /// Change the monitor with `f` without announcing anything (timing counters).
    pub(crate) fn quietly(&self, f: impl FnOnce(&mut Monitor)) {
        f(&mut lock(&self.monitor));
    }

    /// Send `event` to every observer. Lock order: the monitor (if held) before the
    /// observers; this never takes the monitor lock.
    pub(crate) fn publish(&self, event: MonitorEvent) {
        let mut observers = lock(&self.observers);
        if observers.is_empty() {
            return;
        }
        let ring = !lock(&self.wakers).is_empty();
        observers.retain(|observer| {
            // The channels are unbounded (they grow only as events wait): the bound is
            // applied here. Every send happens under this lock, so the length cannot
            // grow between the check and the send. A disconnected observer's channel is
            // emptied when its receiver goes, so the send below finds it.
            let drop_it = || {
                self.dropped.fetch_add(1, Ordering::Relaxed);
                observer.counts.published.fetch_add(1, Ordering::AcqRel);
                observer.counts.dropped.fetch_add(1, Ordering::AcqRel);
                true
            };
            if observer.sender.len() >= OBSERVER_CAPACITY {
                return drop_it();
            }
            match observer.sender.try_send(event.clone()) {
                Ok(()) => {
                    observer.counts.published.fetch_add(1, Ordering::AcqRel);
                    true
                }
                Err(TrySendError::Full(_)) => drop_it(),
                Err(TrySendError::Disconnected(_)) => false,
            }
        });
        drop(observers);
        if ring {
            for (waker, flag) in lock(&self.wakers).iter() {
                if let Some(flag) = flag {
                    flag.store(true, Ordering::Release);
                }
                waker.wake();
            }
        }
    }

    /// `lost` packets lost at input `port`, `total` by the input's own count; the
    /// event's total also has what [`Shared::add_overflows`] counted there, as the
    /// snapshot does, so that totals never go back.
    pub(crate) fn announce_overflow(&self, port: &'static str, lost: u64, total: u64) {
        let elsewhere = lock(&self.monitor)
            .port_overflows
            .iter()
            .find(|(name, _)| name == port)
            .map_or(0, |(_, n)| *n);
        self.publish(MonitorEvent::Overflow {
            port: port.to_owned(),
            lost,
            total: total.saturating_add(elsewhere),
        });
    }

    pub(crate) fn subscribe(&self) -> Subscription {
        let (sender, events) = crossbeam_channel::unbounded();
        let counts = Arc::new(Counts::default());
        lock(&self.observers).push(Observer {
            sender,
            counts: Arc::clone(&counts),
        });
        Subscription { events, counts }
    }

    /// End `subscription` now: no event is published to it (queued, dropped or
    /// counted) after this returns, so its counts are final. What is queued in it
    /// stays there.
    pub(crate) fn unsubscribe(&self, subscription: &Subscription) {
        lock(&self.observers).retain(|o| !Arc::ptr_eq(&o.counts, &subscription.counts));
    }

    pub(crate) fn subscribe_waking(&self, waker: crate::automaton::Waker) -> Subscription {
        let subscription = self.subscribe();
        lock(&self.wakers).push((waker, None));
        subscription
    }

    /// [`Shared::subscribe_waking`], also setting `flag` before each ring.
    pub(crate) fn subscribe_flagged(
        &self,
        waker: crate::automaton::Waker,
        flag: Arc<AtomicBool>,
    ) -> Receiver<MonitorEvent> {
        let subscription = self.subscribe();
        lock(&self.wakers).push((waker, Some(flag)));
        subscription.into_events()
    }

    /// Packets lost at `port` that no input of this component counted (a proxy's:
    /// lost at the remote instance's input, or on the network, port `@network`): added
    /// to the port's count and announced.
    pub(crate) fn add_overflows(&self, port: &str, lost: u64) {
        if lost == 0 {
            return;
        }
        let counted_elsewhere = {
            let mut monitor = lock(&self.monitor);
            let slot = count_at(&mut monitor.port_overflows, port);
            *slot = slot.saturating_add(lost);
            *slot
        };
        let here = self
            .inputs
            .iter()
            .find(|(name, _)| *name == port)
            .map_or(0, |(_, input)| input.core.overflows());
        self.publish(MonitorEvent::Overflow {
            port: port.to_owned(),
            lost,
            total: here.saturating_add(counted_elsewhere),
        });
    }

    pub(crate) fn snapshot(&self) -> Monitor {
        let mut monitor = lock(&self.monitor).clone();
        // The stored counts are those added by `add_overflows` (0 for most
        // components); the inputs' own counts come on top.
        let elsewhere = std::mem::take(&mut monitor.port_overflows);
        monitor.port_overflows = self
            .inputs
            .iter()
            .map(|(name, input)| ((*name).to_owned(), input.core.overflows()))
            .collect();
        for (port, lost) in elsewhere {
            let slot = count_at(&mut monitor.port_overflows, &port);
            *slot = slot.saturating_add(lost);
        }
        monitor.overflows = total_overflows(&monitor.port_overflows);
        monitor.dropped_events = self.dropped.load(Ordering::Relaxed);
        monitor
    }

    pub(crate) fn state(&self) -> State {
        lock(&self.monitor).state
    }

    /// The default and user states now, without waiting: `None` while the monitor
    /// is locked (a panic hook on the component's own thread must never block).
    #[cfg(feature = "process")]
    pub(crate) fn peek_states(&self) -> Option<(State, Option<String>)> {
        let monitor = match self.monitor.try_lock() {
            Ok(monitor) => monitor,
            Err(std::sync::TryLockError::Poisoned(poisoned)) => poisoned.into_inner(),
            Err(std::sync::TryLockError::WouldBlock) => return None,
        };
        Some((monitor.state, monitor.user_state.clone()))
    }

    /// Record adaptation step `step`: the history, the counter, and the event.
    pub(crate) fn adaptation_step(&self, step: Adaptation, f: impl FnOnce(&mut AdaptStatus)) {
        tracing::info!(component = %step.component, "adaptation: {step}");
        self.update(|monitor| {
            let status = &mut monitor.adaptation;
            f(status);
            status.steps += 1;
            status.history.push(step.clone());
            let excess = status
                .history
                .len()
                .saturating_sub(crate::adapt::ADAPTATION_HISTORY);
            status.history.drain(..excess);
            vec![MonitorEvent::Adaptation(step)]
        });
    }

    /// Publish a new verdict (an event only if it changed).
    pub(crate) fn set_pressure(&self, pressure: Pressure, load: f64) {
        self.update(|monitor| {
            monitor.adaptation.load = load;
            if monitor.adaptation.pressure == pressure {
                return Vec::new();
            }
            monitor.adaptation.pressure = pressure;
            vec![MonitorEvent::Pressure(pressure)]
        });
    }

    /// Stop ringing `bell` after events (a recorder that stopped following this
    /// component: its subscription's receiver is dropped separately).
    pub(crate) fn forget_waker(&self, bell: &Arc<crate::port::Doorbell>) {
        lock(&self.wakers).retain(|(waker, _)| !Arc::ptr_eq(&waker.bell, bell));
    }
}

/// A command on its way to the component, with the channel for its answer.
pub(crate) struct ControlMessage {
    pub(crate) command: Command,
    /// Given by the component's compound's adaptation (its supervisor managing the
    /// instance's level), not by anyone else (an operator, a policy, a test).
    pub(crate) by_supervisor: bool,
    pub(crate) reply: Sender<Reply>,
    /// `PENDING`, then `TAKEN` by the component or `WITHDRAWN` by the sender.
    pub(crate) claim: Arc<AtomicU8>,
}

pub(crate) const PENDING: u8 = 0;
pub(crate) const TAKEN: u8 = 1;
pub(crate) const WITHDRAWN: u8 = 2;

impl ControlMessage {
    /// Claim the message for execution; false if the sender withdrew it.
    pub(crate) fn take(&self) -> bool {
        self.claim
            .compare_exchange(PENDING, TAKEN, Ordering::AcqRel, Ordering::Acquire)
            .is_ok()
    }
}

/// A command queued by [`Handle::post`], whose answers [`Handle::finish`] waits for
/// (or [`Handle::poll`] looks at).
pub(crate) struct Posted {
    command: Command,
    answers: Receiver<Reply>,
    claim: Arc<AtomicU8>,
    deadline: Instant,
    /// [`Handle::poll`] saw the component take it (the transition is under way).
    accepted: bool,
}

/// The component's answers to one command.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Reply {
    /// The command is legal; for a state change, the transition starts now.
    Accepted,
    /// The transition finished.
    Done,
    /// The command was rejected.
    Rejected(String),
}

/// Why a command did not go through, before it is rendered into [`Rejected::reason`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Refusal {
    /// The component's thread has not been spawned.
    NotStarted,
    /// The command was given on the component's own thread.
    OwnThread,
    /// The component's control queue is full.
    QueueFull,
    /// The component's thread has ended.
    Ended,
    /// The component did not take the command within the handle's command timeout
    /// (a section still running); the command was withdrawn.
    Busy,
    /// The component rejected it, for this reason.
    Rejected(String),
}

impl Refusal {
    /// The reason as [`Rejected::reason`] words it.
    fn describe(self, timeout: Duration) -> String {
        match self {
            Refusal::NotStarted => "the component has not been started (System::start)".to_owned(),
            Refusal::OwnThread => {
                "a component cannot command itself from its own thread (use Context::end to finish)"
                    .to_owned()
            }
            Refusal::QueueFull | Refusal::Ended => {
                "the component's thread has ended or its control queue is full".to_owned()
            }
            Refusal::Busy => format!(
                "busy: the component did not take the command within {timeout:?}; withdrawn"
            ),
            Refusal::Rejected(reason) => reason,
        }
    }
}

/// The control port `c` and monitoring port `m` of one component. Cheap to clone,
/// `Send`; any number of handles may exist.
#[derive(Clone)]
pub struct Handle {
    pub(crate) name: Arc<str>,
    pub(crate) shared: Arc<Shared>,
    pub(crate) control: Sender<ControlMessage>,
    /// The component's doorbell: rung after each command is queued.
    pub(crate) bell: Arc<crate::port::Doorbell>,
    pub(crate) exited: Receiver<()>,
    pub(crate) join: Arc<Mutex<Option<JoinHandle<()>>>>,
    pub(crate) command_timeout: Duration,
    /// A compound's instances' handles, in declaration order (empty for an atomic
    /// component). They hold the instances' ports only, never the compound's inner
    /// system: the instances' threads end with the compound whatever handles remain.
    pub(crate) instances: Arc<[Handle]>,
    /// The component's output ports by name, in declaration order (recorder taps).
    pub(crate) outputs: Arc<[(&'static str, crate::port::ErasedOutput)]>,
    /// The component's static shape (a compound's as built: exported ports, mapped
    /// variables).
    pub(crate) spec: &'static crate::Spec,
}

impl std::fmt::Debug for Handle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Handle({})", self.name)
    }
}

impl Handle {
    /// The component instance's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The component's static shape: its type, states, ports, variables (with their
    /// kinds and types) and timing; a compound's as built, with its exported ports
    /// and mapped variables.
    pub fn spec(&self) -> &'static crate::Spec {
        self.spec
    }

    /// The names of a compound's instances (its direct ones, in declaration order);
    /// empty for an atomic component.
    pub fn instances(&self) -> Vec<String> {
        self.instances.iter().map(|h| h.name.to_string()).collect()
    }

    /// The control and monitoring ports of the instance at `path` inside this
    /// compound: instance names separated by `.`, through nested compounds (`"base"`,
    /// `"base.motion"`). `None` for an atomic component, an unknown name or a malformed
    /// path (empty, or with an empty segment).
    ///
    /// The handle returned is the instance's own (commands reach it, snapshots are
    /// live), as [`CompoundBuilder::instance_handle`](crate::CompoundBuilder::instance_handle)
    /// gives on the builder. Commanding an instance goes around its compound's
    /// supervisor, which sees the change as it sees any of the instance's changes
    /// (a fault forced this way is handled by the instance's policy).
    pub fn instance(&self, path: &str) -> Option<Handle> {
        let mut handle = self;
        for name in path.split('.') {
            handle = handle.instances.iter().find(|h| &*h.name == name)?;
        }
        Some(handle.clone())
    }

    /// A handle whose commands wait at most `timeout` for the component.
    pub fn with_command_timeout(mut self, timeout: Duration) -> Handle {
        self.command_timeout = timeout;
        self
    }

    fn rejected(&self, command: &Command, reason: impl Into<String>) -> Rejected {
        Rejected {
            component: self.name.to_string(),
            command: crate::ranges::excerpt_debug(command, crate::ranges::EXCERPT_CHARS),
            reason: reason.into(),
        }
    }

    /// Send a command through the control port and wait for its answer.
    ///
    /// The component answers when its thread next looks at its control port: at once
    /// if it is waiting, or when the user section it is running returns. A state change
    /// returns after the transition has run (its sections and hooks), so the monitor
    /// shows the new state; `SetState(Dead)` also joins the thread. If the component does
    /// not take the command within the handle's command timeout (a section running
    /// longer than that), the command is withdrawn and rejected as busy; if it took it
    /// but the transition is still running at the timeout, `Ok` is returned and the
    /// transition completes later.
    pub fn command(&self, command: Command) -> Result<(), Rejected> {
        let posted = self.post(command)?;
        self.finish(posted)
    }

    /// The first half of [`Handle::command`]: queue the command and ring the
    /// component, without waiting ([`System::run_all`](crate::System::run_all) posts to
    /// every component before it waits for any).
    pub(crate) fn post(&self, command: Command) -> Result<Posted, Rejected> {
        let rendered = command.clone();
        self.post_command(command)
            .map_err(|refusal| self.rejected(&rendered, refusal.describe(self.command_timeout)))
    }

    /// [`Handle::post`], with why it failed as a [`Refusal`].
    pub(crate) fn post_command(&self, command: Command) -> Result<Posted, Refusal> {
        self.post_from(command, false)
    }

    /// [`Handle::post`] for a compound's adaptation managing this instance's level
    /// (`crate::compound::adaptation`): the instance tells it from an operator's.
    pub(crate) fn post_by_supervisor(&self, command: Command) -> Result<Posted, Rejected> {
        let rendered = command.clone();
        self.post_from(command, true)
            .map_err(|refusal| self.rejected(&rendered, refusal.describe(self.command_timeout)))
    }

    fn post_from(&self, command: Command, by_supervisor: bool) -> Result<Posted, Refusal> {
        if !self.shared.spawned.load(Ordering::Acquire) {
            return Err(Refusal::NotStarted);
        }
        if self.shared.thread.get() == Some(&std::thread::current().id()) {
            // The thread would wait for itself until the timeout.
            return Err(Refusal::OwnThread);
        }
        let deadline = crate::thread::later(Instant::now(), self.command_timeout);
        let (reply, answers) = crossbeam_channel::bounded(2);
        let claim = Arc::new(AtomicU8::new(PENDING));
        let message = ControlMessage {
            command: command.clone(),
            by_supervisor,
            reply,
            claim: Arc::clone(&claim),
        };
        match self.control.try_send(message) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) => return Err(Refusal::QueueFull),
            Err(TrySendError::Disconnected(_)) => return Err(Refusal::Ended),
        }
        self.bell.ring_strong();
        Ok(Posted {
            command,
            answers,
            claim,
            deadline,
            accepted: false,
        })
    }

    /// Look at the answers to `posted`, waiting at most `wait`: `None` while the
    /// component has not finished with it (not taken yet, or its transition still
    /// running) and its deadline has not passed; otherwise its outcome, as
    /// [`Handle::command`] gives it (a command not taken by its deadline is withdrawn
    /// and rejected as busy; one taken whose transition outlasts it counts as done).
    /// For a caller that must not wait for a component that may be busy (a compound's
    /// recovery queue: its thread passes packets on meanwhile).
    pub(crate) fn poll(&self, posted: &mut Posted, wait: Duration) -> Option<Result<(), Rejected>> {
        let until = crate::thread::later(Instant::now(), wait);
        loop {
            match posted.answers.recv_deadline(until) {
                Ok(Reply::Accepted) => posted.accepted = true,
                Ok(Reply::Done) => return Some(Ok(())),
                Ok(Reply::Rejected(reason)) => {
                    return Some(Err(self.rejected(&posted.command, reason)));
                }
                Err(_) => break,
            }
        }
        if Instant::now() < posted.deadline {
            return None;
        }
        if posted.accepted {
            return Some(Ok(()));
        }
        match posted
            .claim
            .compare_exchange(PENDING, WITHDRAWN, Ordering::AcqRel, Ordering::Acquire)
        {
            Ok(_) => Some(Err(self.rejected(
                &posted.command,
                Refusal::Busy.describe(self.command_timeout),
            ))),
            // Taken just now: its answers come.
            Err(_) => {
                posted.accepted = true;
                None
            }
        }
    }

    /// The second half of [`Handle::command`]: wait for the answers to `posted`.
    pub(crate) fn finish(&self, posted: Posted) -> Result<(), Rejected> {
        let rendered = posted.command.clone();
        self.finish_command(posted)
            .map_err(|refusal| self.rejected(&rendered, refusal.describe(self.command_timeout)))
    }

    /// [`Handle::finish`], with why it failed as a [`Refusal`].
    pub(crate) fn finish_command(&self, posted: Posted) -> Result<(), Refusal> {
        let Posted {
            command,
            answers,
            claim,
            deadline,
            accepted: _,
        } = posted;
        let is_dead = command == Command::SetState(Controllable::Dead);
        match answers.recv_deadline(deadline) {
            Ok(Reply::Accepted) => {}
            Ok(Reply::Done) => return Ok(()),
            Ok(Reply::Rejected(reason)) => return Err(Refusal::Rejected(reason)),
            Err(_) => {
                if claim
                    .compare_exchange(PENDING, WITHDRAWN, Ordering::AcqRel, Ordering::Acquire)
                    .is_ok()
                {
                    return Err(Refusal::Busy);
                }
                // Taken just now: the transition is under way.
                if answers
                    .recv_deadline(crate::thread::later(Instant::now(), self.command_timeout))
                    .is_err()
                    && !is_dead
                {
                    return Ok(());
                }
            }
        }
        // Accepted: wait for the transition to finish.
        let _ = answers.recv_deadline(deadline);
        if is_dead {
            self.join_if_exited(deadline);
        }
        Ok(())
    }

    /// [`Handle::command`] with why it failed as a [`Refusal`] (a compound's
    /// supervisor commanding its instances: `crate::commander`).
    pub(crate) fn command_refusable(&self, command: Command) -> Result<(), Refusal> {
        let posted = self.post_command(command)?;
        self.finish_command(posted)
    }

    /// Wait (until `deadline`) for the thread to end, then join it.
    pub(crate) fn join_if_exited(&self, deadline: Instant) -> Option<Result<(), String>> {
        // The thread holds the sender of `exited`; the channel disconnects when it ends.
        match self.exited.recv_deadline(deadline) {
            Err(crossbeam_channel::RecvTimeoutError::Disconnected) => {}
            _ => return None,
        }
        let handle = lock(&self.join).take()?;
        Some(crate::thread::join(handle))
    }

    /// A copy of everything the monitoring port publishes now.
    pub fn snapshot(&self) -> Monitor {
        self.shared.snapshot()
    }

    /// The default automaton state now.
    pub fn state(&self) -> State {
        self.shared.state()
    }

    /// Whether the component's thread is inside a section that overran its
    /// `max_response` and has not returned yet (the watchdog moved the component to
    /// `running_error`; commands wait until the section returns).
    pub fn is_stuck(&self) -> bool {
        self.shared.stuck.load(Ordering::Acquire)
    }

    /// A new observer: every change from now on, as it happens, up to
    /// [`OBSERVER_CAPACITY`] events waiting (beyond that, events are dropped for it:
    /// [`Handle::subscribe_counted`] tells how many).
    pub fn subscribe(&self) -> Receiver<MonitorEvent> {
        self.shared.subscribe().into_events()
    }

    /// [`Handle::subscribe`], with the counts of what was published to this observer
    /// and dropped for it ([`Subscription::dropped`]): an observer that must not lose
    /// events silently (a recorder, a bridge, a live display) uses this.
    pub fn subscribe_counted(&self) -> Subscription {
        self.shared.subscribe()
    }

    /// A new counted observer whose every event also rings `waker` (a recorder or a
    /// compound's supervisor: its thread wakes on each change, no polling).
    pub fn subscribe_waking(&self, waker: crate::automaton::Waker) -> Subscription {
        self.shared.subscribe_waking(waker)
    }

    /// Wait until `pred` holds for the monitor, woken by monitoring events (no polling),
    /// for at most `timeout`. `pred` is evaluated on each event, so it should depend on
    /// the monitor only (a change nobody announces does not wake the wait).
    pub fn wait_for(
        &self,
        pred: impl Fn(&Monitor) -> bool,
        timeout: Duration,
    ) -> Result<Monitor, Timeout> {
        let deadline = crate::thread::later(Instant::now(), timeout);
        // Most waits are already satisfied: look before subscribing (a subscription
        // allocates a channel and costs every publication a send until it is dropped).
        let monitor = self.snapshot();
        if pred(&monitor) {
            return Ok(monitor);
        }
        // Subscribe, then look again: a change between the two looks is either in the
        // second snapshot or announced on the channel.
        let events = self.shared.subscribe();
        loop {
            let monitor = self.snapshot();
            if pred(&monitor) {
                return Ok(monitor);
            }
            match events.recv_deadline(deadline) {
                Ok(_) => {}
                Err(_) => {
                    let monitor = self.snapshot();
                    if pred(&monitor) {
                        return Ok(monitor);
                    }
                    return Err(Timeout {
                        waited: timeout,
                        last: Box::new(monitor),
                    });
                }
            }
        }
    }

    /// Shorthand: wait until the default automaton is in `state`.
    pub fn wait_state(&self, state: State, timeout: Duration) -> Result<Monitor, Timeout> {
        self.wait_for(|monitor| monitor.state == state, timeout)
    }
}
