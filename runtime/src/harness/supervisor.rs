//! A compound's supervisor alone, on a virtual clock, with no thread: the
//! [`SupervisorHarness`].
//!
//! It is built from the compound's [`CompoundBuilder`] (what a generated `builder()`
//! returns): the supervisor's states, sections, `may` choices and own variables, and
//! the rules coolc compiled, run by the same runner step and evaluated by the same
//! function as a built compound's (in the same order: every rule of a state when it
//! is entered or after one of its sections, then the rules reading what changed).
//! The instances are **stand-ins**: the test sets what a rule reads of them (default
//! state, user state, result, error, quality, variables) and reads back the commands
//! the supervisor gave them, each taken as an instance would take it (a state command
//! moves the stand-in's state, a `set` its variable) unless the test asked for a
//! refusal. When the compound runs, its instances go to `running` (a substitute
//! stays `ready`), and they follow it to `suspended` and `ready`, as a built
//! compound's do.
//!
//! Not run here, because they need the instances themselves (test them with the
//! compound built and run): fault policies and the recovery queue, substitution and
//! redundancy, adaptation, and the exported ports' forwarding.

use std::ops::{Deref, DerefMut};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use crate::compound::{CompoundBuilder, Stage};
use crate::monitor::TaskResult;
use crate::monitor::{Command, Monitor};
use crate::refused::Refused;
use crate::table::State;
use crate::value::Value;

use super::{Harness, HarnessError};

/// A compound's supervisor driven on the caller's thread, its instances stood in for
/// (see the module documentation). It derefs to the [`Harness`] of the compound
/// itself: [`Harness::run`], [`Harness::advance`], [`Harness::user_state`],
/// [`Harness::variable`], [`Harness::monitor`] (its supervision steps) and the rest.
pub struct SupervisorHarness {
    harness: Harness,
    stage: Arc<Mutex<Stage>>,
}

impl std::fmt::Debug for SupervisorHarness {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Supervisor{:?}", self.harness)
    }
}

impl Deref for SupervisorHarness {
    type Target = Harness;
    fn deref(&self) -> &Harness {
        &self.harness
    }
}

impl DerefMut for SupervisorHarness {
    fn deref_mut(&mut self) -> &mut Harness {
        &mut self.harness
    }
}

impl SupervisorHarness {
    /// The compound of `builder` with stand-ins for its instances, started: it is
    /// `ready`, every instance `ready`. [`Harness::run`] runs the supervisor.
    pub fn new(builder: CompoundBuilder) -> Result<SupervisorHarness, HarnessError> {
        let (component, stage) = builder
            .stand_in()
            .map_err(|error| HarnessError::Compound(Box::new(error)))?;
        Ok(SupervisorHarness {
            harness: Harness::new(component)?,
            stage,
        })
    }

    /// [`SupervisorHarness::new`], then `running`: the supervisor enters its initial
    /// state and the instances run.
    pub fn running(builder: CompoundBuilder) -> Result<SupervisorHarness, HarnessError> {
        let mut harness = SupervisorHarness::new(builder)?;
        harness.run()?;
        Ok(harness)
    }

    fn stage(&self) -> MutexGuard<'_, Stage> {
        self.stage.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn at(&self, instance: &str) -> Result<usize, HarnessError> {
        let stage = self.stage();
        stage
            .position(instance)
            .ok_or_else(|| HarnessError::NoInstance {
                compound: self.harness.name().to_owned(),
                instance: instance.to_owned(),
                known: super::names(stage.names.iter().map(String::as_str)),
            })
    }

    /// Change what instance `instance` shows with `change` (the key a rule reads
    /// it by, `<instance>.<field>`, counts as changed), then settle: the rules reading
    /// it are evaluated, as when a built compound takes the instance's event.
    fn change(
        &mut self,
        instance: &str,
        field: &str,
        change: impl FnOnce(&mut Monitor),
    ) -> Result<(), HarnessError> {
        let index = self.at(instance)?;
        {
            let mut stage = self.stage();
            change(&mut stage.monitors[index]);
            stage.changed.insert(format!("{instance}.{field}"));
        }
        self.harness.settle()
    }

    /// Instance `instance` is now in default state `state` (e.g. `running_error`).
    pub fn set_instance_state(&mut self, instance: &str, state: State) -> Result<(), HarnessError> {
        self.change(instance, "state", |m| m.state = state)
    }

    /// Instance `instance` is now in user state `user_state`, one of its automaton's
    /// (`None`: none, as outside `running`).
    pub fn set_instance_user_state(
        &mut self,
        instance: &str,
        user_state: Option<&str>,
    ) -> Result<(), HarnessError> {
        if let Some(name) = user_state {
            let index = self.at(instance)?;
            let spec = self.stage().specs[index];
            if spec.state_index(name).is_none() {
                return Err(HarnessError::NoUserState {
                    instance: instance.to_owned(),
                    state: name.to_owned(),
                    known: super::names(spec.states.iter().map(|s| s.name)),
                });
            }
        }
        self.change(instance, "user_state", |m| {
            m.user_state = user_state.map(str::to_owned);
        })
    }

    /// Instance `instance`'s task result is now `result`.
    pub fn set_instance_result(
        &mut self,
        instance: &str,
        result: TaskResult,
    ) -> Result<(), HarnessError> {
        self.change(instance, "result", |m| m.result = result)
    }

    /// Instance `instance`'s last error is now `error`.
    pub fn set_instance_error(
        &mut self,
        instance: &str,
        error: Option<&str>,
    ) -> Result<(), HarnessError> {
        self.change(instance, "error", |m| m.error = error.map(str::to_owned))
    }

    /// Instance `instance`'s quality level is now `level`.
    pub fn set_instance_quality(
        &mut self,
        instance: &str,
        level: usize,
    ) -> Result<(), HarnessError> {
        self.change(instance, "quality", |m| m.quality = level)
    }

    /// Instance `instance`'s variable `variable` (observable or controllable, as its
    /// component declares it) is now `value`; a compound variable mapped onto it
    /// changes with it.
    pub fn set_instance_variable(
        &mut self,
        instance: &str,
        variable: &str,
        value: impl Into<Value>,
    ) -> Result<(), HarnessError> {
        let index = self.at(instance)?;
        let declared = self.stage().monitors[index]
            .variables
            .iter()
            .any(|(name, _)| name == variable);
        if !declared {
            return Err(HarnessError::NoInstanceVariable {
                instance: instance.to_owned(),
                variable: variable.to_owned(),
            });
        }
        self.stage().set_variable(index, variable, value.into());
        self.harness.settle()
    }

    /// What instance `instance` shows now (its stand-in's monitor).
    pub fn instance(&self, instance: &str) -> Result<Monitor, HarnessError> {
        let index = self.at(instance)?;
        Ok(self.stage().monitors[index].clone())
    }

    /// The commands the supervisor gave its instances since the last call, in order:
    /// `(instance, command)`, refused ones included.
    pub fn take_commands(&mut self) -> Vec<(String, Command)> {
        std::mem::take(&mut self.stage().commands)
    }

    /// The next command the supervisor gives instance `instance` is refused with
    /// `reason` (as a busy or dead instance would refuse it); several calls queue
    /// several refusals.
    pub fn refuse_next(&mut self, instance: &str, reason: Refused) -> Result<(), HarnessError> {
        self.at(instance)?;
        self.stage()
            .refusals
            .entry(instance.to_owned())
            .or_default()
            .push_back(reason);
        Ok(())
    }
}
