//! The interface between the runtime and a component's code: the [`Automaton`] trait
//! that generated glue implements, the [`Context`] every hook and section receives, and
//! [`Fault`], what user code returns when it fails.

use std::fmt;
use std::time::{Duration, Instant};

use crate::monitor::{Rejected, TaskResult};
use crate::refused::Refused;
use crate::spec::Spec;
use crate::table::State;
use crate::value::{ConvertError, Time, Value, ValueError};
use crate::wake::Waker;

/// Which section of a user state to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Section {
    /// Run each time the user automaton enters the state.
    Entry,
    /// Run each time the user automaton is about to leave the state.
    Exit,
    /// Run on the state's period while the automaton stays in the state.
    Periodic,
}

/// What a section returns.
pub type SectionResult = Result<(), Fault>;

/// A fault raised by user code: a declared exception (its index and a message), or any
/// other error (an undeclared fault takes the component to `running_error`).
///
/// `Fault` deliberately does not implement [`std::error::Error`], so that every error
/// type converts into it and `?` works in sections.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Fault {
    exception: Option<usize>,
    message: String,
}

impl Fault {
    /// A declared exception, by index into [`Spec::exceptions`].
    pub fn exception(index: usize, message: impl Into<String>) -> Fault {
        Fault {
            exception: Some(index),
            message: message.into(),
        }
    }

    /// An undeclared fault with a message.
    pub fn message(message: impl Into<String>) -> Fault {
        Fault {
            exception: None,
            message: message.into(),
        }
    }

    /// The declared exception's index, if this is one.
    pub fn exception_index(&self) -> Option<usize> {
        self.exception
    }

    /// The message.
    pub fn text(&self) -> &str {
        &self.message
    }
}

impl fmt::Display for Fault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.exception {
            Some(index) => write!(f, "exception #{index}: {}", self.message),
            None => f.write_str(&self.message),
        }
    }
}

/// The message is the error's, followed by each of its sources ([`Chain`](crate::Chain):
/// `instance `w` did not take `set count = 1`: `count` is observable, not
/// controllable`): a fault keeps the whole chain as text.
impl<E: std::error::Error + Send + Sync + 'static> From<E> for Fault {
    fn from(error: E) -> Fault {
        Fault::message(crate::Chain(&error).to_string())
    }
}

/// Why a component did not take a value given through its control port: a new
/// configuration ([`Automaton::configure`]) or a controllable variable's value
/// ([`Automaton::set`], [`Supervisor::set`](crate::Supervisor::set)). The control port
/// refuses the command with its text ([`Chain`](crate::Chain)).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ValueRefused {
    /// The component has no configuration.
    #[error("the component takes no configuration")]
    NoConfiguration,
    /// A compound has no configuration of its own (its instances have theirs).
    #[error("a compound has no configuration of its own; configure its instances")]
    CompoundConfiguration,
    /// The variable is not one the component lets be set: not controllable, or not
    /// one it keeps.
    #[error("variable `{variable}` of {type_name} cannot be set")]
    NotSettable {
        /// The component type.
        type_name: &'static str,
        /// The variable's name (`?` for an index the spec does not have).
        variable: &'static str,
    },
    /// The value does not convert to the configuration's or the variable's type.
    #[error(transparent)]
    Convert(#[from] ConvertError),
    /// The value is not of the variable's kind (a number, a string, a boolean, a
    /// duration: [`Value`]'s own conversions).
    #[error(transparent)]
    Value(#[from] ValueError),
    /// A compound's mapped variable: the instance it maps to rejected the value.
    #[error(transparent)]
    Instance(#[from] Rejected),
    /// A stand-in compound's mapped variable (a supervisor harness): the command to
    /// the instance was refused.
    #[error(transparent)]
    Refused(#[from] Refused),
    /// An instance on another node (`crate::remote`): its node refused the value, or
    /// could not be asked.
    #[error("on node `{node}`")]
    Remote {
        /// The node.
        node: String,
        /// The network layer's error.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// A reason of the component's own (a hand-written automaton's).
    #[error(transparent)]
    Other(Box<dyn std::error::Error + Send + Sync>),
}

impl ValueRefused {
    /// [`ValueRefused::NotSettable`] for variable `variable` (an index into
    /// [`Spec::variables`]) of `spec`.
    pub fn not_settable(spec: &'static Spec, variable: usize) -> ValueRefused {
        ValueRefused::NotSettable {
            type_name: spec.type_name,
            variable: spec.variables.get(variable).map_or("?", |v| v.name),
        }
    }

    /// [`ValueRefused::Other`] with a reason of the component's own.
    pub fn other(reason: impl Into<Box<dyn std::error::Error + Send + Sync>>) -> ValueRefused {
        ValueRefused::Other(reason.into())
    }
}

/// The code of one component, as the runtime drives it. `coolc` generates a glue type
/// implementing this over the user's `Behavior`; the runtime calls it only on the
/// component's own thread, each call under `catch_unwind`. (`Any`: a harness,
/// `crate::harness`, reads the generated glue back through it.)
///
/// Only [`Automaton::spec`] is required: a hand-written component implements the hooks
/// it uses, and every other keeps its default (nothing to start or stop, no section,
/// no choice, no answer to a pull, no configuration, no variables of its own).
pub trait Automaton: std::any::Any + Send + 'static {
    /// The component's static shape.
    fn spec(&self) -> &'static Spec;

    /// Called in `starting` (on the first start and on every restart from an error or
    /// `end`): acquire resources, read the configuration. `Err` (or a panic) leads to
    /// `starting_error`. The default acquires nothing.
    fn start(&mut self, _cx: &mut Context) -> Result<(), Fault> {
        Ok(())
    }

    /// Called when the component leaves the started world (`ready`, `running`,
    /// `suspended`) for `dead`, `end` or `running_error`: release what `start` acquired.
    /// The default releases nothing.
    fn stop(&mut self, _cx: &mut Context) {}

    /// Run one section of one user state. The default does nothing (a component whose
    /// spec declares no sections).
    fn section(
        &mut self,
        _state: usize,
        _section: Section,
        _cx: &mut Context,
    ) -> Result<(), Fault> {
        Ok(())
    }

    /// For states with `may`: after each entry or periodic section, the target (an index
    /// into [`Spec::states`], one of the state's `may` targets) to go to, if any. The
    /// default stays.
    fn choose(&mut self, _state: usize, _cx: &mut Context) -> Option<usize> {
        None
    }

    /// The user's handler for a raised declared exception, called before its plan runs.
    /// The default does nothing (the plan runs).
    fn exception(&mut self, _exception: usize, _message: &str, _cx: &mut Context) {}

    /// A pull request arrived for output `output` (declared `pull`): compute the answer
    /// and send it on the output port; while this runs, a data output sends only to the
    /// requesting input. The default has no answer: a fault (a component that declares
    /// a `pull` output implements it).
    fn answer(&mut self, output: usize, _cx: &mut Context) -> Result<(), Fault> {
        let name = self.spec().outputs.get(output).map_or("?", |o| o.name);
        Err(Fault::message(format!(
            "output `{name}` is pulled but the component does not answer pulls"
        )))
    }

    /// A new configuration through the control port. The default refuses it (the
    /// component has no configuration: [`ValueRefused::NoConfiguration`]).
    fn configure(&mut self, _configuration: &Value) -> Result<(), ValueRefused> {
        Err(ValueRefused::NoConfiguration)
    }

    /// Set controllable variable `variable` (an index into [`Spec::variables`]). The
    /// default refuses (the component keeps no variables of its own:
    /// [`ValueRefused::NotSettable`]).
    fn set(&mut self, variable: usize, _value: &Value) -> Result<(), ValueRefused> {
        Err(ValueRefused::not_settable(self.spec(), variable))
    }

    /// The current value of variable `variable`, for the monitoring port. The default
    /// has none ([`Value::Unit`]).
    fn get(&self, _variable: usize) -> Value {
        Value::Unit
    }

    /// The current configuration, if the component has one to report (generated
    /// components do): what an instance declared `on "node"` is configured with on
    /// its node (`crate::remote`).
    fn configuration(&self) -> Option<Value> {
        None
    }

    /// After every call into the automaton (and once before `start`): report through
    /// `changes`, in index order, every variable (an index into [`Spec::variables`])
    /// whose value may differ from the one last reported, each at most once. The
    /// runtime publishes those whose [`Value`] differs from the published one, so
    /// reporting a variable that did not change costs only its conversion, and one
    /// left out is not published until it is reported.
    ///
    /// The default reports every variable, for the runtime to read with
    /// [`Automaton::get`] ([`Changes::read`]). Generated glue keeps a copy of each
    /// variable as last reported, in its Rust type, and reports only those that
    /// differ from it ([`Changes::compare`]), building a `Value` for them alone.
    fn changed_variables(&mut self, changes: &mut Changes<'_>) {
        for variable in 0..self.spec().variables.len() {
            changes.read(variable);
        }
    }
}

/// Where [`Automaton::changed_variables`] reports the variables that may have
/// changed.
#[derive(Debug)]
pub struct Changes<'a> {
    /// Each reported variable, with its value, or `None` to read with `get`.
    pub(crate) reported: &'a mut Vec<(usize, Option<Value>)>,
}

impl Changes<'_> {
    /// Variable `variable` may have changed: the runtime reads it with
    /// [`Automaton::get`] (a panic there leaves it unpublished, to be read again on
    /// the next report).
    pub fn read(&mut self, variable: usize) {
        self.reported.push((variable, None));
    }

    /// Variable `variable` may have changed, and is `value` now.
    pub fn value(&mut self, variable: usize, value: Value) {
        self.reported.push((variable, Some(value)));
    }

    /// Variable `variable` is `current`, which was `published` when last reported
    /// (`None`: never): if they differ (`!=`, so a value holding a NaN always
    /// does), reports `value(current)` and makes `published` a copy of `current`. A
    /// panic in `value` is caught: nothing is reported, and `published` keeps its
    /// value, so the variable is compared again on the next report.
    ///
    /// `T`'s `PartialEq` must say two values are equal only when their `Value`s
    /// are (as a derived one does): an equal value is not reported.
    pub fn compare<T: Clone + PartialEq>(
        &mut self,
        variable: usize,
        published: &mut Option<T>,
        current: &T,
        value: impl FnOnce(&T) -> Value,
    ) {
        if published.as_ref() == Some(current) {
            return;
        }
        let Ok(value) = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| value(current)))
        else {
            return;
        };
        match published {
            Some(published) => published.clone_from(current),
            None => *published = Some(current.clone()),
        }
        self.reported.push((variable, Some(value)));
    }
}

/// What the runner drives: an [`Automaton`], plus the hooks only a compound component
/// has (crate-private, so a hand-written or generated automaton implements only what it
/// uses). An atomic component's automaton is driven through [`Atomic`], which keeps
/// every hook's default; a compound's automaton (`crate::compound`) implements them.
pub(crate) trait Driven: Automaton {
    /// Whether [`Driven::supervise`] and [`Driven::wake_at`] are to be called at all.
    fn supervises(&self) -> bool {
        false
    }

    /// Whether the component's monitor shows another component's times (a remote
    /// instance's proxy mirrors its `cpu_time` and `elapsed_time`): the runner then
    /// publishes none of its own thread's.
    fn mirrors_times(&self) -> bool {
        false
    }

    /// Called on the component's thread right before the user automaton is entered or
    /// resumed (the compound's instances go to `running` first). An `Err` ends the
    /// transition in `running_error` (after `stop`), with the fault's message in
    /// `error`.
    fn before_running(&mut self, _cx: &mut Context) -> Result<(), Fault> {
        Ok(())
    }

    /// Called after a default-automaton transition from `from` ended in `to`.
    fn after_transition(&mut self, _from: State, _to: State, _cx: &mut Context) {}

    /// Called on every turn of the thread loop while the component is `running` and
    /// `state` is the current user state, before timers and inputs. `Ok(Some(target))`
    /// asks for a user transition to `target`; `Err` is a fault (`running_error`).
    fn supervise(&mut self, _state: usize, _cx: &mut Context) -> Result<Option<usize>, Fault> {
        Ok(None)
    }

    /// Called on every turn of the thread loop while the component is `suspended`:
    /// observation only (a compound's instances' events keep its view and its mapped
    /// variables current; `docs/runtime.md`, "While a compound is suspended").
    fn observe(&mut self, _cx: &mut Context) {}

    /// The next instant the thread must wake for [`Driven::supervise`] (a timer of
    /// its own), if any.
    fn wake_at(&self) -> Option<Instant> {
        None
    }

    /// On a virtual clock: how soon, in real time, the thread retries moving data of
    /// its own, if it has any (packets held at a compound's exported input while its
    /// instance's `Block` fifo was full). Data moves in real time on any clock: the
    /// retry is no timer of the clock, and the thread counts as settled meanwhile.
    fn retries_data(&self) -> Option<Duration> {
        None
    }

    /// The component runs on `clock` (set before its thread starts): a compound puts
    /// its own timers and its instances on it.
    fn set_clock(&mut self, _clock: &crate::clock::Clock) {}

    /// The runner entered user state `state` (by any user transition: a rule,
    /// `after`, `on`, `may`, a plan's `goto`, or the initial state), before its entry
    /// section runs. The supervisor evaluates the rules of `state` on its next turn,
    /// which the runner takes at once.
    fn entered(&mut self, _state: usize) {}

    /// `Command::SetDegradation(level)` arrived through the control port: `level` is
    /// the current maximum degradation level of the compound's instances (paper 3.6,
    /// the homogeneity interval's upper end). `Err` rejects the command with the
    /// reason.
    fn set_degradation(
        &mut self,
        _level: u32,
        _cx: &mut Context,
    ) -> Result<(), DegradationRefused> {
        Err(DegradationRefused::Off)
    }

    /// A command that arrived through the control port, before the runner applies
    /// it: `Some(answer)` answers it here and the runner does nothing more (a remote
    /// instance's proxy, `crate::remote`, forwards it to the instance).
    fn forward(
        &mut self,
        _command: &crate::monitor::Command,
    ) -> Option<Result<(), Box<dyn std::error::Error + Send + Sync>>> {
        None
    }
}

/// Why a compound refused `Command::SetDegradation` ([`Driven::set_degradation`]), or
/// a component a level out of its ladder.
#[derive(Debug, thiserror::Error)]
pub(crate) enum DegradationRefused {
    /// The compound does not adapt.
    #[error("adaptation is off in this compound")]
    Off,
    /// Beyond the highest level.
    #[error("degradation level {level} out of range: the highest is {max}")]
    OutOfRange { level: u32, max: u32 },
}

/// An atomic component's automaton as the runner drives it: every compound hook keeps
/// its default.
pub(crate) struct Atomic(pub(crate) Box<dyn Automaton>);

impl Automaton for Atomic {
    fn spec(&self) -> &'static Spec {
        self.0.spec()
    }
    fn start(&mut self, cx: &mut Context) -> Result<(), Fault> {
        self.0.start(cx)
    }
    fn stop(&mut self, cx: &mut Context) {
        self.0.stop(cx)
    }
    fn section(&mut self, state: usize, section: Section, cx: &mut Context) -> Result<(), Fault> {
        self.0.section(state, section, cx)
    }
    fn choose(&mut self, state: usize, cx: &mut Context) -> Option<usize> {
        self.0.choose(state, cx)
    }
    fn exception(&mut self, exception: usize, message: &str, cx: &mut Context) {
        self.0.exception(exception, message, cx)
    }
    fn answer(&mut self, output: usize, cx: &mut Context) -> Result<(), Fault> {
        self.0.answer(output, cx)
    }
    fn configure(&mut self, configuration: &Value) -> Result<(), ValueRefused> {
        self.0.configure(configuration)
    }
    fn set(&mut self, variable: usize, value: &Value) -> Result<(), ValueRefused> {
        self.0.set(variable, value)
    }
    fn get(&self, variable: usize) -> Value {
        self.0.get(variable)
    }
    fn configuration(&self) -> Option<Value> {
        self.0.configuration()
    }
    fn changed_variables(&mut self, changes: &mut Changes<'_>) {
        self.0.changed_variables(changes)
    }
}

impl Driven for Atomic {}

/// What a hook or section sees of the runtime: time, `result`, `end`, period, quality.
///
/// The runtime owns one per component and passes it to every call on the component's
/// thread; changes (result, end, period) take effect when the call returns.
#[derive(Debug)]
pub struct Context {
    /// Shared with the component's handle.
    pub(crate) name: std::sync::Arc<str>,
    pub(crate) entered_at: Instant,
    pub(crate) result: TaskResult,
    pub(crate) result_changed: bool,
    pub(crate) end_requested: bool,
    pub(crate) stopping: bool,
    pub(crate) period: Option<Duration>,
    pub(crate) period_changed: bool,
    pub(crate) quality: usize,
    /// The deadline of the periodic section running now.
    pub(crate) deadline: Option<Instant>,
    pub(crate) waker: Option<Waker>,
    /// Compound components: supervision steps to publish when the call returns.
    pub(crate) supervision: Vec<crate::monitor::Supervision>,
    /// The component's monitoring state (none in a context made outside a system):
    /// compounds publish their adaptation steps through it.
    pub(crate) shared: Option<std::sync::Arc<crate::monitor::Shared>>,
    /// The clock the component's timers read (`crate::clock`).
    pub(crate) clock: crate::clock::Clock,
    /// How the component takes time of its clock ([`Context::spend`]).
    pub(crate) spends: Spends,
    /// A section of the user automaton is under way (not a hook).
    pub(crate) in_section: bool,
    /// While a command's transition runs: who to tell once one of its sections takes
    /// time of a virtual clock ([`Context::spend`]).
    pub(crate) transition_waiter: Option<TransitionWaiter>,
}

/// The sender of a command whose transition is under way, told once a section of the
/// transition takes time of a virtual clock: only the clock can end the section
/// then, and whoever moves the clock may be the one waiting, so the sender counts
/// the command as taken.
pub(crate) struct TransitionWaiter(
    pub(crate) Box<dyn FnOnce() + Send>,
    pub(crate) Option<crate::clock::AnswerNotice>,
);

impl fmt::Debug for TransitionWaiter {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("TransitionWaiter")
    }
}

/// How a component's section takes time of its clock ([`Context::spend`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(crate) enum Spends {
    /// It has not joined a virtual clock: it sleeps.
    #[default]
    Sleeping,
    /// On a virtual clock, as the member with this id.
    Member(u64),
    /// In a harness: the clock is the component's own, and moves by itself.
    Harnessed,
}

impl Context {
    /// A context for component `name` (the runtime makes these; tests of user code may
    /// too).
    pub fn new(name: impl Into<String>, period: Option<Duration>) -> Context {
        Context::named(std::sync::Arc::from(name.into()), period)
    }

    /// [`Context::new`] with the name the component's handle holds.
    pub(crate) fn named(name: std::sync::Arc<str>, period: Option<Duration>) -> Context {
        Context {
            name,
            entered_at: Instant::now(),
            result: TaskResult::None,
            result_changed: false,
            end_requested: false,
            stopping: false,
            period,
            period_changed: false,
            quality: 0,
            deadline: None,
            waker: None,
            supervision: Vec::new(),
            shared: None,
            clock: crate::clock::Clock::real(),
            spends: Spends::Sleeping,
            in_section: false,
            transition_waiter: None,
        }
    }

    /// The component's own doorbell (none in a context made outside a system): ringing
    /// it wakes the component's thread. Compound components hand it to the monitoring
    /// ports of their instances.
    pub fn waker(&self) -> Option<Waker> {
        self.waker.clone()
    }

    /// The wall-clock time now (on a virtual clock: the wall time the clock was made
    /// at, plus the time it advanced).
    pub fn now(&self) -> Time {
        self.clock.wall_now()
    }

    /// The time since the user automaton entered its current state (on the
    /// component's clock: a virtual clock's time in a test).
    pub fn in_state_for(&self) -> Duration {
        self.clock.now().saturating_duration_since(self.entered_at)
    }

    /// Set the observable `result`.
    pub fn set_result(&mut self, result: TaskResult) {
        if self.result != result {
            self.result = result;
            self.result_changed = true;
        }
    }

    /// The current `result`.
    pub fn result(&self) -> &TaskResult {
        &self.result
    }

    /// Whether the component is shutting down: this call is part of its way to `dead`
    /// (the exit section of its current user state, then `stop`), not of a transition
    /// it will come back from. A supervisor's exit section uses it to leave its
    /// instances as they are (a compound refuses to bring an instance to `running`
    /// then: [`Refused::ShuttingDown`](crate::Refused::ShuttingDown)).
    pub fn stopping(&self) -> bool {
        self.stopping
    }

    /// Finish the task: when the current call returns, the exit section of the current
    /// user state runs and the default automaton goes to `end`.
    pub fn end(&mut self) {
        self.end_requested = true;
    }

    /// The component period.
    pub fn period(&self) -> Option<Duration> {
        self.period
    }

    /// Change the component period; periodic deadlines re-anchor on the new period when
    /// the current call returns. A zero period is ignored.
    pub fn set_period(&mut self, period: Duration) {
        if !period.is_zero() && self.period != Some(period) {
            self.period = Some(period);
            self.period_changed = true;
        }
    }

    /// The current quality level: an index into the timing block's `quality` list
    /// (0 = best).
    pub fn quality(&self) -> usize {
        self.quality
    }

    /// The deadline of the periodic section running now (`None` in other sections):
    /// it started `Instant::now() - deadline` late. The runtime's clock: on a virtual
    /// clock, an instant of that clock.
    pub fn deadline(&self) -> Option<Instant> {
        self.deadline
    }

    /// The component instance's name.
    pub fn component_name(&self) -> &str {
        &self.name
    }

    /// How a command this call gives waits: in the time of a virtual clock in a
    /// section of a member of one (as [`Context::spend`] takes its time), else in
    /// real time (`None`).
    pub(crate) fn clock_wait(&self) -> Option<crate::clock::ClockWait> {
        self.in_section.then(|| self.member_clock_wait()).flatten()
    }

    /// Waiting in the time of the virtual clock this component is a member of (in or
    /// out of a section), if it is one's.
    pub(crate) fn member_clock_wait(&self) -> Option<crate::clock::ClockWait> {
        match (self.spends, self.clock.as_virtual()) {
            (Spends::Member(id), Some(clock)) => Some(crate::clock::ClockWait::new(
                std::sync::Arc::clone(clock),
                id,
            )),
            _ => None,
        }
    }

    /// Take `cost` of time in the section under way, as if it computed that long (a
    /// simulated workload, a model of a slow driver): the section is measured that
    /// much longer, and a `max_response` it exceeds trips. On the real clock the
    /// thread sleeps for `cost`. On a virtual clock it waits until the clock has moved
    /// on by `cost`, and `VirtualClock::advance` does not wait for it meanwhile, nor
    /// for the other members of its execution group (their thread is busy): the
    /// components on other threads run on, as they would on the real clock; a section
    /// whose system shuts down stops waiting. In a
    /// [`Harness`](crate::harness::Harness), whose clock is the component's own, the
    /// clock moves on by `cost`. On a virtual clock only the entry, exit and periodic
    /// sections take its time: in the other calls of an automaton (the `start` and
    /// `stop` hooks, an exception handler, a `may` choice, a pull's answer) `spend`
    /// takes none, since their callers wait for them in real time (on the real clock
    /// it sleeps in all of them). A command whose transition runs a section that
    /// takes the clock's time counts as taken once the section does.
    pub fn spend(&mut self, cost: Duration) {
        if cost.is_zero() {
            return;
        }
        if !self.in_section && !self.clock.is_real() {
            return;
        }
        match (self.spends, self.clock.as_virtual()) {
            (Spends::Member(id), Some(clock)) => {
                let told = self
                    .transition_waiter
                    .take()
                    .map(|waiter| (waiter.0, waiter.1));
                clock.spend(id, cost, told);
            }
            (Spends::Harnessed, Some(clock)) => {
                // Nothing else runs on a harness's clock: none to wait for.
                let _ = clock.advance_with_timeout(cost, Duration::ZERO);
            }
            (_, None) => std::thread::sleep(cost),
            // On a virtual clock it has not joined (a context made by hand): the
            // clock would never be waited for.
            (Spends::Sleeping, Some(_)) => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::Context;
    use crate::clock::{Clock, VirtualClock};

    #[test]
    fn the_context_reads_the_component_clock() {
        let clock = VirtualClock::new();
        let mut cx = Context::new("c", None);
        cx.clock = Clock::virtual_clock(&clock);
        cx.entered_at = clock.now();
        let wall = cx.now();
        clock
            .advance(Duration::from_millis(7))
            .expect("no component");
        assert_eq!(cx.in_state_for(), Duration::from_millis(7));
        assert_eq!(cx.now().0 - wall.0, 7_000_000);
    }
}
