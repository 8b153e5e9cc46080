//! What the default ports carry: the commands of the control port `c` and the
//! monitoring port `m`'s [`Monitor`], events and subscriptions ([`crate::Handle`] is
//! how a caller reaches both).
//!
//! The monitoring state of a component lives in one [`Shared`] (a `Mutex<Monitor>`
//! written by the component's thread at each change) plus the observers' channels.
//! Every change is sent to every observer as it happens; nobody polls.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use crossbeam_channel::{Receiver, Sender, TrySendError};
use serde::{Deserialize, Serialize};

use crate::adapt::{AdaptStatus, Adaptation, Pressure};
use crate::table::{Controllable, State};
use crate::value::Value;

/// How many events an observer's channel holds; events beyond that are dropped for
/// that observer (counted for all observers in [`Monitor::dropped_events`], and for
/// each in its own [`Subscription::dropped`]). The channel grows as events wait in it,
/// up to this bound: an observer that keeps up costs little memory.
pub const OBSERVER_CAPACITY: usize = 4096;

/// How long [`crate::Handle::command`] waits for the component by default.
pub const DEFAULT_COMMAND_TIMEOUT: Duration = Duration::from_secs(2);

/// The default observable variable `result`: whether the task has finished and how.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum TaskResult {
    /// No result yet.
    #[default]
    None,
    /// The task succeeded, with complementary information.
    Success(String),
    /// The task failed, with complementary information.
    Fail(String),
}

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
    /// [`OsPriority`](crate::OsPriority); a refusal by the OS does not reject the command).
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

/// A [`crate::Handle::wait_for`] that did not see its condition in time.
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
    pub os_priority: crate::thread::OsPriority,
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
    /// The execution group the component runs in, with the group's cycle figures;
    /// `None` for a component on a thread of its own (`docs/runtime.md`, "Execution
    /// groups").
    #[serde(default)]
    pub group: Option<GroupStatus>,
}

impl Monitor {
    /// The monitoring state of component `name` of type `spec` as it starts, with
    /// its effective timing block `timing`: `starting`, nothing measured, nothing
    /// lost, its variables not yet published.
    pub(crate) fn starting(
        name: String,
        spec: &crate::spec::Spec,
        timing: &crate::spec::TimingSpec,
    ) -> Monitor {
        Monitor {
            name,
            state: State::Starting,
            user_state: None,
            result: TaskResult::None,
            error: None,
            variables: spec
                .variables
                .iter()
                .map(|v| (v.name.to_owned(), Value::Unit))
                .collect(),
            cpu_time: Duration::ZERO,
            elapsed_time: Duration::ZERO,
            missed_deadlines: 0,
            overruns: 0,
            overflows: 0,
            port_overflows: spec.inputs.iter().map(|i| (i.name.to_owned(), 0)).collect(),
            quality: 0,
            period: timing.period,
            nominal_period: timing.period,
            max_response: timing.max_response,
            priority: timing.priority,
            os_priority: crate::thread::OsPriority::Inherited,
            dropped_events: 0,
            supervision: Vec::new(),
            supervision_steps: 0,
            adaptation: AdaptStatus::default(),
            response: ResponseTimes::default(),
            group: None,
        }
    }
}

/// An execution group as each member's monitor shows it: its name, its members in
/// the order they run, and its cycles. A cycle is one pass of the group's thread
/// over its members; the group's period is the shortest period among the members
/// running a periodic section now (`running`, in a user state with a periodic
/// section), and a cycle longer than that period is an overrun (the next cycle
/// starts late for someone).
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct GroupStatus {
    /// The group's name (its thread's name).
    pub name: String,
    /// The members, in the order each cycle runs them (data-flow order).
    pub members: Vec<String>,
    /// Cycles run since the group's thread started.
    pub cycles: u64,
    /// How long the last cycle took.
    pub last_cycle: Duration,
    /// The longest cycle so far.
    pub worst_cycle: Duration,
    /// The shortest period among the members running a periodic section, as the
    /// last wait saw it; `None` while no member runs one.
    pub period: Option<Duration>,
    /// Cycles that took longer than `period`.
    pub overruns: u64,
}

thread_local! {
    /// On an execution group's thread: the address of the monitor of the member whose
    /// turn runs now (0 between turns, and on a component's own thread).
    static TURN: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// The member whose monitor is `shared` takes its turn on this thread (`None`: the
/// turns are over).
pub(crate) fn set_turn(shared: Option<&Arc<Shared>>) {
    TURN.set(shared.map_or(0, |shared| Arc::as_ptr(shared) as usize));
}

/// Whether `shared` is the monitor of the group member whose turn runs on this
/// thread now (`None`: no member's turn runs on it).
pub(crate) fn turn_is(shared: &Arc<Shared>) -> Option<bool> {
    let turn = TURN.get();
    (turn != 0).then_some(turn == Arc::as_ptr(shared) as usize)
}

/// An execution group's cycle figures, written by its thread only (plain loads and
/// stores, no read-modify-write) and read by every member's snapshot.
#[derive(Debug)]
pub(crate) struct GroupCycles {
    name: String,
    members: Vec<Arc<str>>,
    cycles: AtomicU64,
    last_ns: AtomicU64,
    worst_ns: AtomicU64,
    /// The period in nanoseconds; 0 for none.
    period_ns: AtomicU64,
    overruns: AtomicU64,
}

impl GroupCycles {
    pub(crate) fn new(name: &str, members: Vec<Arc<str>>) -> GroupCycles {
        GroupCycles {
            name: name.to_owned(),
            members,
            cycles: AtomicU64::new(0),
            last_ns: AtomicU64::new(0),
            worst_ns: AtomicU64::new(0),
            period_ns: AtomicU64::new(0),
            overruns: AtomicU64::new(0),
        }
    }

    /// A cycle took `took` (called by the group's thread only).
    pub(crate) fn cycle(&self, took: Duration) {
        let took = u64::try_from(took.as_nanos()).unwrap_or(u64::MAX);
        let bump = |counter: &AtomicU64| {
            counter.store(
                counter.load(Ordering::Relaxed).saturating_add(1),
                Ordering::Relaxed,
            );
        };
        bump(&self.cycles);
        self.last_ns.store(took, Ordering::Relaxed);
        if took > self.worst_ns.load(Ordering::Relaxed) {
            self.worst_ns.store(took, Ordering::Relaxed);
        }
        let period = self.period_ns.load(Ordering::Relaxed);
        if period > 0 && took > period {
            bump(&self.overruns);
        }
    }

    /// The group's period is now `period` (called by the group's thread only).
    pub(crate) fn set_period(&self, period: Option<Duration>) {
        let ns = period.map_or(0, |p| u64::try_from(p.as_nanos()).unwrap_or(u64::MAX));
        self.period_ns.store(ns, Ordering::Relaxed);
    }

    /// [`GroupCycles::status`] into `status`, in place. Every field is named (a field
    /// added to `GroupStatus` and not copied here does not compile).
    fn status_into(&self, status: &mut GroupStatus) {
        let GroupStatus {
            name,
            members,
            cycles,
            last_cycle,
            worst_cycle,
            period,
            overruns,
        } = status;
        if *name != self.name {
            name.clone_from(&self.name);
        }
        let same_members = members.len() == self.members.len()
            && members.iter().zip(&self.members).all(|(a, b)| **a == **b);
        if !same_members {
            *members = self.members.iter().map(|name| name.to_string()).collect();
        }
        let period_ns = self.period_ns.load(Ordering::Relaxed);
        *cycles = self.cycles.load(Ordering::Relaxed);
        *last_cycle = Duration::from_nanos(self.last_ns.load(Ordering::Relaxed));
        *worst_cycle = Duration::from_nanos(self.worst_ns.load(Ordering::Relaxed));
        *period = (period_ns > 0).then(|| Duration::from_nanos(period_ns));
        *overruns = self.overruns.load(Ordering::Relaxed);
    }

    fn status(&self) -> GroupStatus {
        let period = self.period_ns.load(Ordering::Relaxed);
        GroupStatus {
            name: self.name.clone(),
            members: self.members.iter().map(|name| name.to_string()).collect(),
            cycles: self.cycles.load(Ordering::Relaxed),
            last_cycle: Duration::from_nanos(self.last_ns.load(Ordering::Relaxed)),
            worst_cycle: Duration::from_nanos(self.worst_ns.load(Ordering::Relaxed)),
            period: (period > 0).then(|| Duration::from_nanos(period)),
            overruns: self.overruns.load(Ordering::Relaxed),
        }
    }
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

/// A few lines for a person: what the component is doing, its variables, its timing
/// and losses, and what went wrong (its error, a compound's last supervision step).
/// `{:#?}` shows every field.
impl std::fmt::Display for Monitor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.name, self.state)?;
        if let Some(user) = &self.user_state {
            write!(f, " in `{user}`")?;
        }
        match &self.result {
            TaskResult::None => {}
            TaskResult::Success(detail) => write!(f, ", succeeded: {detail}")?,
            TaskResult::Fail(detail) => write!(f, ", failed: {detail}")?,
        }
        if let Some(error) = &self.error {
            write!(f, "\n  error: {error}")?;
        }
        if !self.variables.is_empty() {
            let variables: Vec<String> = self
                .variables
                .iter()
                .map(|(name, value)| format!("{name} = {value}"))
                .collect();
            write!(f, "\n  {}", variables.join(", "))?;
        }
        write!(f, "\n  ")?;
        if let Some(period) = self.period {
            write!(f, "period {period:?}, ")?;
        }
        write!(
            f,
            "quality {}, cpu {:.1?}, in its calls {:.1?}; missed deadlines {}, overruns {}, \
             packets lost {}, events dropped {}",
            self.quality,
            self.cpu_time,
            self.elapsed_time,
            self.missed_deadlines,
            self.overruns,
            self.overflows,
            self.dropped_events
        )?;
        if let Some(group) = &self.group {
            write!(f, "\n  execution group `{}`", group.name)?;
        }
        if self.supervision_steps > 0 {
            write!(f, "\n  supervision steps {}", self.supervision_steps)?;
            if let Some(last) = self.supervision.last() {
                write!(f, "; the last: {last}")?;
            }
        }
        Ok(())
    }
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

impl Step {
    /// Whether the step is routine: a command the instance took, or a retry that
    /// failed (the instance stays queued and the next retry comes). The log has them
    /// at `debug`, every other step at `info`; `coolctl top` can hide them.
    pub fn is_routine(&self) -> bool {
        matches!(self, Step::Commanded { .. } | Step::RetryFailed)
    }
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
    OsPriority(crate::thread::OsPriority),
    /// The component's adaptation verdict changed (time violation, spare time, or
    /// neither).
    Pressure(Pressure),
    /// An adaptation step: a level changed, or a compound's supervisor acted.
    Adaptation(Adaptation),
}

/// What an input has lost so far (`crate::port`'s input ends count it): read by the
/// monitor for its snapshot and overflow events.
pub(crate) trait Losses: Send + Sync {
    /// Packets lost at the input in all.
    fn overflows(&self) -> u64;
}

/// `into = from.clone()`, in place: every field of `from` but `group` (which
/// [`Shared::snapshot_into`] sets), each copied only if it differs, into the
/// allocations `into` has.
fn copy_monitor(from: &Monitor, into: &mut Monitor) {
    // Every field named, so that a new one is not forgotten here.
    let Monitor {
        name,
        state,
        user_state,
        result,
        error,
        variables,
        cpu_time,
        elapsed_time,
        missed_deadlines,
        overruns,
        overflows,
        port_overflows,
        quality,
        period,
        nominal_period,
        max_response,
        priority,
        os_priority,
        dropped_events,
        supervision,
        supervision_steps,
        adaptation,
        response,
        group: _,
    } = from;
    assign(&mut into.name, name);
    into.state = *state;
    assign(&mut into.user_state, user_state);
    assign(&mut into.result, result);
    assign(&mut into.error, error);
    into.variables.truncate(variables.len());
    let (same, more) = variables.split_at(into.variables.len());
    for ((into_name, into_value), (name, value)) in into.variables.iter_mut().zip(same) {
        assign(into_name, name);
        assign_value(into_value, value);
    }
    into.variables.extend_from_slice(more);
    into.cpu_time = *cpu_time;
    into.elapsed_time = *elapsed_time;
    into.missed_deadlines = *missed_deadlines;
    into.overruns = *overruns;
    into.overflows = *overflows;
    assign_all(&mut into.port_overflows, port_overflows);
    into.quality = *quality;
    into.period = *period;
    into.nominal_period = *nominal_period;
    into.max_response = *max_response;
    into.priority = *priority;
    assign(&mut into.os_priority, os_priority);
    into.dropped_events = *dropped_events;
    assign_all(&mut into.supervision, supervision);
    into.supervision_steps = *supervision_steps;
    let AdaptStatus {
        enabled,
        level,
        max_level,
        floor,
        min_level,
        settle_periods,
        pressure,
        load,
        cpu_share,
        history,
        steps,
    } = adaptation;
    let to = &mut into.adaptation;
    to.enabled = *enabled;
    to.level = *level;
    to.max_level = *max_level;
    to.floor = *floor;
    to.min_level = *min_level;
    to.settle_periods = *settle_periods;
    assign(&mut to.pressure, pressure);
    to.load = *load;
    to.cpu_share = *cpu_share;
    assign_all(&mut to.history, history);
    to.steps = *steps;
    into.response = *response;
}

/// `*into = from.clone()`, in place: a value of the same shape (a record with the
/// same fields, a list as long, a JSON object with the same keys) takes `from`'s
/// scalars into the allocations it has.
fn assign_value(into: &mut Value, from: &Value) {
    match (&mut *into, from) {
        (Value::Str(into), Value::Str(from)) | (Value::Enum(into), Value::Enum(from)) => {
            assign(into, from);
        }
        (Value::List(into), Value::List(from)) if into.len() == from.len() => {
            for (into, from) in into.iter_mut().zip(from) {
                assign_value(into, from);
            }
        }
        (Value::Record(into), Value::Record(from))
            if into.len() == from.len() && into.iter().zip(from).all(|((a, _), (b, _))| a == b) =>
        {
            for ((_, into), (_, from)) in into.iter_mut().zip(from) {
                assign_value(into, from);
            }
        }
        (Value::Json(into), Value::Json(from)) => assign_json(into, from),
        // A scalar is copied whole (bit for bit: `==` would take `-0.0` for `0.0`).
        _ => into.clone_from(from),
    }
}

/// [`assign_value`] for JSON values.
fn assign_json(into: &mut serde_json::Value, from: &serde_json::Value) {
    use serde_json::Value as Json;
    match (&mut *into, from) {
        (Json::String(into), Json::String(from)) => assign(into, from),
        (Json::Array(into), Json::Array(from)) if into.len() == from.len() => {
            for (into, from) in into.iter_mut().zip(from) {
                assign_json(into, from);
            }
        }
        (Json::Object(into), Json::Object(from))
            if into.len() == from.len() && into.keys().zip(from.keys()).all(|(a, b)| a == b) =>
        {
            for ((_, into), (_, from)) in into.iter_mut().zip(from) {
                assign_json(into, from);
            }
        }
        _ => into.clone_from(from),
    }
}

/// `*into = from.clone()` if they differ.
fn assign<T: Clone + PartialEq>(into: &mut T, from: &T) {
    if into != from {
        into.clone_from(from);
    }
}

/// `*into = from.to_vec()`, assigning only the elements that differ.
fn assign_all<T: Clone + PartialEq>(into: &mut Vec<T>, from: &[T]) {
    into.truncate(from.len());
    let (same, more) = from.split_at(into.len());
    for (into, from) in into.iter_mut().zip(same) {
        assign(into, from);
    }
    into.extend_from_slice(more);
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

/// A subscription to a component's monitoring port ([`crate::Handle::subscribe_counted`],
/// [`crate::Handle::subscribe_waking`]): the events as they happen (it dereferences to their
/// [`Receiver`]), and how many were dropped for it because it fell behind.
///
/// An observer that does not take its events falls behind: once
/// [`OBSERVER_CAPACITY`] events wait in its channel, newer events are dropped for it
/// (never for the other observers, and the component never waits), and each drop is
/// counted in [`Subscription::dropped`] (and, for all observers together, in
/// [`Monitor::dropped_events`]). The events it does get are in order; a snapshot
/// ([`crate::Handle::snapshot`]) always shows the current state, whatever was dropped.
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
    wakers: Mutex<Vec<(crate::wake::Waker, Option<Arc<AtomicBool>>)>>,
    pub(crate) inputs: Vec<(&'static str, Arc<dyn Losses>)>,
    dropped: AtomicU64,
    /// Nanoseconds spent in user calls, as the component's runner published them:
    /// the monitor's `elapsed_time`, kept outside its lock (a group member publishes
    /// it each cycle, and a store costs less than the lock).
    elapsed: AtomicU64,
    pub(crate) spawned: AtomicBool,
    /// Whether the component's thread is inside a section the max_response watchdog
    /// tripped (it has not returned yet).
    pub(crate) stuck: AtomicBool,
    /// The component's thread, once spawned.
    pub(crate) thread: std::sync::OnceLock<std::thread::ThreadId>,
    /// A compound's supervisor decides this component's adaptation level: its runner
    /// only detects and publishes its verdicts (set when the compound is built).
    pub(crate) adapt_managed: AtomicBool,
    /// The execution group the component runs in, once its thread runs.
    pub(crate) group: std::sync::OnceLock<Arc<GroupCycles>>,
    /// Its id on the virtual clock it runs on, once it joined it.
    pub(crate) clock_member: std::sync::OnceLock<u64>,
}

impl std::fmt::Debug for Shared {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Shared").finish_non_exhaustive()
    }
}

impl Shared {
    pub(crate) fn new(monitor: Monitor, inputs: Vec<(&'static str, Arc<dyn Losses>)>) -> Shared {
        Shared {
            monitor: Mutex::new(monitor),
            observers: Mutex::new(Vec::new()),
            wakers: Mutex::new(Vec::new()),
            inputs,
            dropped: AtomicU64::new(0),
            elapsed: AtomicU64::new(0),
            spawned: AtomicBool::new(false),
            stuck: AtomicBool::new(false),
            thread: std::sync::OnceLock::new(),
            adapt_managed: AtomicBool::new(false),
            group: std::sync::OnceLock::new(),
            clock_member: std::sync::OnceLock::new(),
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

    pub(crate) fn subscribe_waking(&self, waker: crate::wake::Waker) -> Subscription {
        let subscription = self.subscribe();
        lock(&self.wakers).push((waker, None));
        subscription
    }

    /// [`Shared::subscribe_waking`], also setting `flag` before each ring.
    pub(crate) fn subscribe_flagged(
        &self,
        waker: crate::wake::Waker,
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
            .map_or(0, |(_, input)| input.overflows());
        self.publish(MonitorEvent::Overflow {
            port: port.to_owned(),
            lost,
            total: here.saturating_add(counted_elsewhere),
        });
    }

    /// Publish the time spent in user calls (the monitor's `elapsed_time`), in
    /// nanoseconds.
    pub(crate) fn set_elapsed(&self, nanos: u64) {
        self.elapsed.store(nanos, Ordering::Relaxed);
    }

    /// The time spent in user calls, as last published.
    pub(crate) fn elapsed(&self) -> Duration {
        Duration::from_nanos(self.elapsed.load(Ordering::Relaxed))
    }

    pub(crate) fn snapshot(&self) -> Monitor {
        let mut monitor = lock(&self.monitor).clone();
        monitor.elapsed_time = self.elapsed();
        // The stored counts are those added by `add_overflows` (0 for most
        // components); the inputs' own counts come on top.
        let elsewhere = std::mem::take(&mut monitor.port_overflows);
        monitor.port_overflows = self
            .inputs
            .iter()
            .map(|(name, input)| ((*name).to_owned(), input.overflows()))
            .collect();
        for (port, lost) in elsewhere {
            let slot = count_at(&mut monitor.port_overflows, &port);
            *slot = slot.saturating_add(lost);
        }
        monitor.overflows = total_overflows(&monitor.port_overflows);
        monitor.dropped_events = self.dropped.load(Ordering::Relaxed);
        monitor.group = self.group.get().map(|group| group.status());
        monitor
    }

    /// [`Shared::snapshot`] into `into`, in place: what is equal is left as it is, and
    /// what differs is copied into the allocations `into` has (a compound's view of
    /// an instance takes this at each of its events).
    pub(crate) fn snapshot_into(&self, into: &mut Monitor) {
        {
            let monitor = lock(&self.monitor);
            copy_monitor(&monitor, into);
        }
        into.elapsed_time = self.elapsed();
        // `copy_monitor` left the stored counts (those added by `add_overflows`) in
        // `port_overflows`; the inputs' own counts come on top, first, in order. Most
        // often the stored counts are the inputs' with nothing added: they are the
        // inputs' counts, in place.
        let inputs_only = into.port_overflows.len() == self.inputs.len()
            && into
                .port_overflows
                .iter()
                .zip(&self.inputs)
                .all(|((port, lost), (name, _))| *lost == 0 && port == name);
        if inputs_only {
            for ((_, lost), (_, input)) in into.port_overflows.iter_mut().zip(&self.inputs) {
                *lost = input.overflows();
            }
        } else {
            let elsewhere = std::mem::take(&mut into.port_overflows);
            into.port_overflows = self
                .inputs
                .iter()
                .map(|(name, input)| ((*name).to_owned(), input.overflows()))
                .collect();
            for (port, lost) in elsewhere {
                let slot = count_at(&mut into.port_overflows, &port);
                *slot = slot.saturating_add(lost);
            }
        }
        into.overflows = total_overflows(&into.port_overflows);
        into.dropped_events = self.dropped.load(Ordering::Relaxed);
        match (self.group.get(), &mut into.group) {
            (Some(group), Some(status)) => group.status_into(status),
            (group, status) => *status = group.map(|group| group.status()),
        }
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

    /// Record adaptation step `step`: the history, the counter, and the event; log it
    /// (at info, or at debug when `logged` is false: a step a supervisor commanded,
    /// whose own step was logged).
    pub(crate) fn adaptation_step(
        &self,
        step: Adaptation,
        logged: bool,
        f: impl FnOnce(&mut AdaptStatus),
    ) {
        if logged {
            tracing::info!(component = %step.component, "adaptation: {step}");
        } else {
            tracing::debug!(component = %step.component, "adaptation: {step}");
        }
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
    pub(crate) fn forget_waker(&self, bell: &Arc<crate::wake::Doorbell>) {
        lock(&self.wakers).retain(|(waker, _)| !Arc::ptr_eq(&waker.bell, bell));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spec::{Spec, TimingSpec};

    static SPEC: Spec = Spec {
        type_name: "Watched",
        doc: "",
        states: &[],
        initial: 0,
        inputs: &[],
        outputs: &[],
        variables: &[],
        exceptions: &[],
        timing: TimingSpec::NONE,
    };

    struct Lost(u64);

    impl Losses for Lost {
        fn overflows(&self) -> u64 {
            self.0
        }
    }

    #[test]
    fn a_monitor_reads_in_a_few_lines() {
        let mut watched = monitor(vec![("count", Value::Int(10)), ("on", Value::Bool(true))]);
        watched.state = State::Running;
        watched.user_state = Some("counting".to_owned());
        watched.period = Some(Duration::from_millis(100));
        watched.cpu_time = Duration::from_micros(1200);
        watched.elapsed_time = Duration::from_micros(300);
        watched.overflows = 2;
        assert_eq!(
            watched.to_string(),
            "watched: running in `counting`\n  count = 10, on = true\n  period 100ms, quality 0, \
             cpu 1.2ms, in its calls 300.0\u{b5}s; missed deadlines 0, overruns 0, packets lost 2, \
             events dropped 0"
        );
        watched.state = State::RunningError;
        watched.error = Some("panic in state `counting`".to_owned());
        watched.result = TaskResult::Fail("gave up".to_owned());
        watched.supervision_steps = 3;
        watched.supervision = vec![Supervision {
            instance: "arm".to_owned(),
            step: Step::Restarted,
            detail: String::new(),
        }];
        let text = watched.to_string();
        assert!(
            text.starts_with(
                "watched: running_error in `counting`, failed: gave up\n  error: panic in state `counting`\n"
            ),
            "{text}"
        );
        assert!(
            text.ends_with("\n  supervision steps 3; the last: arm restarted"),
            "{text}"
        );
    }

    fn monitor(variables: Vec<(&str, Value)>) -> Monitor {
        let mut monitor = Monitor::starting("watched".to_owned(), &SPEC, &TimingSpec::NONE);
        monitor.variables = variables
            .into_iter()
            .map(|(name, value)| (name.to_owned(), value))
            .collect();
        monitor
    }

    fn odometry(x: f64, frame: &str) -> Value {
        Value::Json(serde_json::json!({"x": x, "frame": frame, "path": [x, 1]}))
    }

    /// A view brought up to date in place is the snapshot, to the bit.
    #[test]
    fn a_snapshot_in_place_is_the_snapshot() {
        let shared = Shared::new(
            monitor(vec![]),
            vec![("scan", Arc::new(Lost(4)) as Arc<dyn Losses>)],
        );
        let mut view = shared.snapshot();
        let check = |change: &dyn Fn(&mut Monitor), view: &mut Monitor| {
            shared.quietly(|monitor| change(monitor));
            shared.snapshot_into(view);
            let snapshot = shared.snapshot();
            assert_eq!(*view, snapshot);
            assert_eq!(format!("{view:?}"), format!("{snapshot:?}"));
        };
        check(&|_| {}, &mut view);
        check(
            &|m| {
                *m = monitor(vec![
                    ("odometry", odometry(1.5, "odom")),
                    ("speed", Value::Float(0.0)),
                    ("path", Value::List(vec![Value::Int(1), Value::Int(2)])),
                    (
                        "pose",
                        Value::Record(vec![("x".to_owned(), Value::Float(1.0))]),
                    ),
                    ("mode", Value::Enum("Normal".to_owned())),
                ]);
                m.state = State::Running;
                m.user_state = Some("streaming".to_owned());
                m.port_overflows = vec![("scan".to_owned(), 0)];
            },
            &mut view,
        );
        // The same shapes with new scalars, a float's zero changing sign, a string
        // longer, a list shorter, a record with another field.
        check(
            &|m| {
                m.variables[0].1 = odometry(-2.25, "odometry");
                m.variables[1].1 = Value::Float(-0.0);
                m.variables[2].1 = Value::List(vec![Value::Int(3)]);
                m.variables[3].1 = Value::Record(vec![("y".to_owned(), Value::Float(2.0))]);
                m.variables[4].1 = Value::Enum("Degraded".to_owned());
                m.result = TaskResult::Fail("blocked".to_owned());
                m.error = Some("sensor timeout".to_owned());
            },
            &mut view,
        );
        assert!(matches!(view.variables[1].1, Value::Float(z) if z.is_sign_negative()));
        // A JSON object with other keys, a variable fewer, counts added elsewhere.
        check(
            &|m| {
                m.variables[0].1 = Value::Json(serde_json::json!({"y": -0.0}));
                m.variables.pop();
                m.port_overflows = vec![("scan".to_owned(), 2), ("@network".to_owned(), 7)];
                m.supervision.push(Supervision {
                    instance: "ranges".to_owned(),
                    step: Step::Failed,
                    detail: String::new(),
                });
            },
            &mut view,
        );
        // Another variable, a user state no more.
        check(
            &|m| {
                m.variables.push(("faults".to_owned(), Value::UInt(3)));
                m.user_state = None;
                m.port_overflows = vec![("scan".to_owned(), 0)];
            },
            &mut view,
        );
    }
}
