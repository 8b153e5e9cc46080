//! A compound's supervisor controls its instances (paper 3.4: a compound "provides a
//! supervisor for their monitoring and control"): the [`Commander`] a supervisor
//! section receives in [`SupervisorCx::instances`](crate::SupervisorCx) brings an
//! instance to a controllable state, sets its controllable variables, gives it a new
//! configuration, period or quality, through the instance's control port.
//!
//! Every command is answered: `Ok`, or a [`CommandError`] whose [`Refused`] says why
//! (a `?` in a section turns it into the section's fault). Every command, taken or
//! refused, is a supervision step ([`Step::Commanded`], [`Step::CommandRefused`]) on
//! the compound's monitoring port, published when the section returns.
//!
//! A command never holds the compound's thread for long: an instance stuck in a
//! section that overran its `max_response` refuses at once ([`Refused::Stuck`]), and
//! an instance that does not take the command within the commander's timeout
//! ([`CompoundBuilder::command_timeout`](crate::CompoundBuilder::command_timeout),
//! default [`DEFAULT_SUPERVISOR_COMMAND_TIMEOUT`]) has it withdrawn
//! ([`Refused::Busy`]); the whole call waits at most twice that timeout (a command
//! taken just before the timeout is given as long again to finish its transition,
//! which then completes in the background).

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crate::clock::ClockWait;
use crate::handle::{Handle, Refusal};
use crate::monitor::{Command, Step, Supervision};
use crate::refused::Refused;
use crate::spec::{Spec, VarKind};
use crate::table::{Controllable, State};
use crate::value::Value;

/// How long a supervisor's command waits for an instance to take it, by default.
pub const DEFAULT_SUPERVISOR_COMMAND_TIMEOUT: Duration = Duration::from_millis(250);

/// Why an instance did not take a supervisor's command.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("instance `{instance}` did not take `{command}`")]
pub struct CommandError {
    /// The instance commanded (a local instance name of the compound).
    pub instance: String,
    /// The command, as the supervisor gave it (`suspend`, `set max_speed = 0.2`).
    pub command: String,
    /// Why it was refused.
    #[source]
    pub reason: Refused,
}

/// What answers a [`Commander`]'s commands in place of the instances' control ports:
/// the stand-ins of a supervisor harness, which record each command and take it as an
/// instance would (or refuse it as the test asks).
pub(crate) trait StandIns: Send {
    /// Take `command` for instance `instance` (checked against its spec already).
    fn command(&mut self, instance: &str, command: &Command) -> Result<(), Refused>;
}

/// One instance a [`Commander`] can command.
struct Target {
    name: String,
    /// Its control port; `None` for a stand-in's (the commander's [`StandIns`]
    /// answer).
    handle: Option<Handle>,
    spec: &'static Spec,
    /// Its quality levels: its component's, or its `timing` override's.
    levels: usize,
}

/// What a supervisor section commands its instances with (its
/// [`SupervisorCx::instances`](crate::SupervisorCx)); `coolc`'s generated `Cx` wraps
/// it in typed handles, one per instance. The compound owns it; every call runs on the
/// compound's thread and waits (boundedly: see the module documentation) for the
/// instance's answer.
pub struct Commander {
    compound: String,
    targets: Vec<Target>,
    /// Who answers instead of the instances' control ports: a supervisor harness's
    /// stand-ins (`crate::harness::supervisor`).
    stand_ins: Option<Arc<Mutex<dyn StandIns>>>,
    timeout: Duration,
    /// Steps taken since the compound last published them.
    steps: Vec<Supervision>,
    /// The compound is on its way to `dead` ([`Commander::set_stopping`]).
    stopping: bool,
    /// While it is: when its stop is given up on (each command waits at most until
    /// then).
    stop_by: Option<Instant>,
    /// The section giving commands now runs on a virtual clock: they wait in its
    /// time ([`Commander::set_clock_wait`]).
    clock_wait: Option<ClockWait>,
}

impl std::fmt::Debug for Commander {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Commander")
            .field("compound", &self.compound)
            .field("instances", &self.instances().collect::<Vec<_>>())
            .field("timeout", &self.timeout)
            .finish_non_exhaustive()
    }
}

impl Commander {
    /// A commander for compound `compound`'s instances `(name, handle, spec, quality
    /// levels)`, each command waiting at most `timeout` for the instance to take it.
    pub(crate) fn new(
        compound: String,
        instances: impl IntoIterator<Item = (String, Handle, &'static Spec, usize)>,
        timeout: Duration,
    ) -> Commander {
        Commander {
            compound,
            targets: instances
                .into_iter()
                .map(|(name, handle, spec, levels)| Target {
                    name,
                    handle: Some(handle.with_command_timeout(timeout)),
                    spec,
                    levels,
                })
                .collect(),
            stand_ins: None,
            timeout,
            steps: Vec::new(),
            stopping: false,
            stop_by: None,
            clock_wait: None,
        }
    }

    /// A commander whose commands `stand_ins` answers for compound `compound`'s
    /// instances `(name, spec, quality levels)`: the same checks against each
    /// instance's spec, the same steps, no control port.
    pub(crate) fn standing_in(
        compound: String,
        instances: impl IntoIterator<Item = (String, &'static Spec, usize)>,
        stand_ins: Arc<Mutex<dyn StandIns>>,
    ) -> Commander {
        Commander {
            compound,
            targets: instances
                .into_iter()
                .map(|(name, spec, levels)| Target {
                    name,
                    handle: None,
                    spec,
                    levels,
                })
                .collect(),
            stand_ins: Some(stand_ins),
            timeout: Duration::ZERO,
            steps: Vec::new(),
            stopping: false,
            stop_by: None,
            clock_wait: None,
        }
    }

    /// The names of the instances it commands, in declaration order.
    pub fn instances(&self) -> impl Iterator<Item = &str> {
        self.targets.iter().map(|t| t.name.as_str())
    }

    /// How long a command waits for an instance to take it.
    pub fn timeout(&self) -> Duration {
        self.timeout
    }

    /// Bring `instance` to the controllable state `target` (`ready`, `running`,
    /// `suspended`, `dead`), as its control port's `new_state` does. Returns when the
    /// transition has run (its sections and hooks).
    pub fn state(&mut self, instance: &str, target: Controllable) -> Result<(), CommandError> {
        self.give(
            instance,
            target.verb().to_owned(),
            Command::SetState(target),
            |_| None,
        )
    }

    /// Set controllable variable `variable` of `instance` to `value`.
    pub fn set(
        &mut self,
        instance: &str,
        variable: &str,
        value: impl Into<Value>,
    ) -> Result<(), CommandError> {
        let value = value.into();
        let described = format!("set {variable} = {value}");
        let check =
            |target: &Target| match target.spec.variables.iter().find(|v| v.name == variable) {
                None => Some(Refused::UnknownVariable(variable.to_owned())),
                Some(v) if v.kind != VarKind::Controllable => {
                    Some(Refused::NotControllable(variable.to_owned()))
                }
                // Outside its declared range: refused here as the instance would.
                Some(v) => v.range.and_then(|range| {
                    range.check(&value).err().map(|outside| {
                        Refused::InvalidValue(format!("invalid value for `{variable}`: {outside}"))
                    })
                }),
            };
        let command = Command::Set(variable.to_owned(), value.clone());
        self.give(instance, described, command, check)
    }

    /// Give `instance` a new configuration (its `configuration` block's record; the
    /// fields it names replace the instance's, the others are kept).
    pub fn configure(&mut self, instance: &str, configuration: Value) -> Result<(), CommandError> {
        self.give(
            instance,
            "configure".to_owned(),
            Command::Configure(configuration),
            |_| None,
        )
    }

    /// Set the period of `instance` (within [`crate::ranges`]'s range).
    pub fn set_period(&mut self, instance: &str, period: Duration) -> Result<(), CommandError> {
        let check = |_: &Target| crate::ranges::period(period).err();
        self.give(
            instance,
            format!("period {period:?}"),
            Command::SetPeriod(period),
            check,
        )
    }

    /// Set the `max_response` of `instance` (within [`crate::ranges`]'s range).
    pub fn set_max_response(
        &mut self,
        instance: &str,
        max_response: Duration,
    ) -> Result<(), CommandError> {
        let check = |_: &Target| crate::ranges::max_response(max_response).err();
        self.give(
            instance,
            format!("max_response {max_response:?}"),
            Command::SetMaxResponse(max_response),
            check,
        )
    }

    /// Set the priority of `instance` (within [`crate::ranges`]'s range; a positive,
    /// real-time one only when the process allows them).
    pub fn set_priority(&mut self, instance: &str, priority: i32) -> Result<(), CommandError> {
        let check = |_: &Target| crate::ranges::priority(priority).err();
        self.give(
            instance,
            format!("priority {priority}"),
            Command::SetPriority(priority),
            check,
        )
    }

    /// Set the quality level of `instance` (an index into its `quality` levels, 0 the
    /// best).
    pub fn set_quality(&mut self, instance: &str, level: usize) -> Result<(), CommandError> {
        let check = |target: &Target| {
            let levels = target.levels.max(1);
            (level >= levels).then_some(Refused::QualityOutOfRange { level, levels })
        };
        self.give(
            instance,
            format!("quality {level}"),
            Command::SetQuality(level),
            check,
        )
    }

    /// Whether the compound is on its way to `dead` ([`Context::stopping`](crate::Context::stopping)
    /// of the section about to run): while it is, a command that would bring an
    /// instance to `running` is refused ([`Refused::ShuttingDown`]), and each command
    /// waits at most until `stop_by` (the compound's stop budget), if given.
    pub(crate) fn set_stopping(&mut self, stopping: bool, stop_by: Option<Instant>) {
        self.stopping = stopping;
        self.stop_by = stop_by.filter(|_| stopping);
    }

    /// The call about to give commands runs on a virtual clock (`Some`: a supervisor's
    /// section, `Context::clock_wait`): each command waits for the instance in the
    /// clock's time, its timeout counted in it, so that an instance whose section
    /// takes the clock's time (`Context::spend`) answers once the clock has moved on.
    pub(crate) fn set_clock_wait(&mut self, wait: Option<ClockWait>) {
        self.clock_wait = wait;
    }

    /// The steps taken since the last call (the compound publishes them).
    pub(crate) fn take_steps(&mut self) -> Vec<Supervision> {
        std::mem::take(&mut self.steps)
    }

    /// Give `command` (`described` for the step) to `instance`, unless `check` finds
    /// it refused from the instance's spec; record the step.
    fn give(
        &mut self,
        instance: &str,
        described: String,
        command: Command,
        check: impl FnOnce(&Target) -> Option<Refused>,
    ) -> Result<(), CommandError> {
        let outcome = if self.stopping && command == Command::SetState(Controllable::Running) {
            Err(Refused::ShuttingDown)
        } else {
            self.answer(instance, &command, check)
        };
        let (step, detail) = match &outcome {
            Ok(()) => (
                Step::Commanded {
                    command: described.clone(),
                },
                String::new(),
            ),
            Err(reason) => (
                Step::CommandRefused {
                    command: described.clone(),
                },
                reason.to_string(),
            ),
        };
        if let Err(reason) = &outcome {
            crate::limited!(
                (&self.compound, instance),
                |held| tracing::warn!(compound = %self.compound, %instance, "refused {described}: {reason}{held}")
            );
        } else {
            tracing::info!(compound = %self.compound, %instance, "commanded: {described}");
        }
        self.steps.push(Supervision {
            instance: instance.to_owned(),
            step,
            detail,
        });
        outcome.map_err(|reason| CommandError {
            instance: instance.to_owned(),
            command: described,
            reason,
        })
    }

    fn answer(
        &self,
        instance: &str,
        command: &Command,
        check: impl FnOnce(&Target) -> Option<Refused>,
    ) -> Result<(), Refused> {
        let target = self
            .targets
            .iter()
            .find(|t| t.name == instance)
            .ok_or(Refused::UnknownInstance)?;
        if let Some(refused) = check(target) {
            return Err(refused);
        }
        let Some(handle) = &target.handle else {
            return match &self.stand_ins {
                Some(stand_ins) => stand_ins
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner)
                    .command(instance, command),
                None => Err(Refused::NotStarted),
            };
        };
        if handle.is_stuck() {
            return Err(Refused::Stuck);
        }
        if handle.state() == State::Dead {
            return Err(Refused::Dead);
        }
        // Stopping: no longer than what is left of the compound's stop budget.
        let bounded;
        let (handle, timeout) = match self.stop_by {
            Some(by) => {
                let left = by
                    .saturating_duration_since(Instant::now())
                    .min(self.timeout);
                bounded = handle.clone().with_command_timeout(left);
                (&bounded, left)
            }
            None => (handle, self.timeout),
        };
        handle
            .command_refusable(command.clone(), self.clock_wait.as_ref())
            .map_err(|refusal| match refusal {
                Refusal::NotStarted => Refused::NotStarted,
                Refusal::Ended => Refused::Dead,
                Refusal::QueueFull => Refused::QueueFull,
                Refusal::Busy => Refused::Busy { waited: timeout },
                Refusal::Rejected(reason) => match command {
                    Command::Set(..) => Refused::InvalidValue(reason),
                    Command::Configure(_) => Refused::InvalidConfiguration(reason),
                    _ if handle.state() == State::Dead => Refused::Dead,
                    _ => Refused::Rejected(reason),
                },
                // The compound's thread is never an instance's thread.
                Refusal::OwnThread => Refused::Rejected(
                    "a component cannot command itself from its own thread".to_owned(),
                ),
            })
    }
}

/// What a typed instance handle's `set_<variable>` asks of its argument when the
/// variable is observable: no type has it, so a call does not compile, and the compiler
/// says why. Only controllable variables are set through an instance's control port;
/// an observable one is read from its monitoring (a supervisor's `cx.view`).
#[diagnostic::on_unimplemented(
    message = "an observable variable has no setter: only controllable variables are set",
    label = "the variable this would set is observable",
    note = "a supervisor reads an observable variable (in rules, or `cx.view.var(instance, name)`); to set it, declare it `controllable` in its component"
)]
pub trait ObservableOnly: sealed::Nothing {
    /// Never called: no value has a type with this trait.
    fn refuse(self) -> CommandError;
}

/// What keeps [`ObservableOnly`] without implementations: a trait outside code can
/// neither name nor implement.
mod sealed {
    pub trait Nothing {}
}
