//! The compound automaton: the inner [`System`] of instances, the compound's record of
//! each instance (its policy, its place in the arrangement), and how the instances
//! follow the compound's own state (the runner's compound hooks, `automaton::Driven`).

use std::panic::{AssertUnwindSafe, catch_unwind, resume_unwind};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use crate::adapt::{AdaptAction, Adaptation, Pressure};
use crate::automaton::{
    Automaton, Context, DegradationRefused, Driven, Fault, Section, ValueRefused,
};
use crate::monitor::{Command, Step};
use crate::spec::Spec;
use crate::table::{Controllable, State};
use crate::value::Value;

use super::error::RunError;
use super::exports::EXPORT_RETRY;
use super::state::{Compound, Status, command};
use super::supervisor::SupervisorCx;

/// How long a compound waits for one of its instances to leave `starting`.
pub const INSTANCE_START_TIMEOUT: Duration = Duration::from_secs(5);

/// How long a compound shutting down takes for its stop at most, from its
/// supervisor's exit section: the commands that section gives, its instances' `dead`
/// (each in turn, last declared first, each waited for at most its share of what is
/// left) and the joins of their threads. Shorter than
/// [`SHUTDOWN_TIMEOUT`](crate::SHUTDOWN_TIMEOUT), so that a system's shutdown joins a
/// compound's thread even when an instance of it is stuck in a section: the compound
/// gives up on that instance (it is sent `dead` again, which it takes when its section
/// returns), says so in a `CommandRefused` step and its log, and the system's report
/// names it (`ComponentReport::unjoined_instances`).
pub const COMPOUND_STOP_TIMEOUT: Duration = Duration::from_secs(4);

/// When a compound's stop that begins now is given up on.
fn stop_budget() -> Instant {
    crate::time::later(Instant::now(), COMPOUND_STOP_TIMEOUT)
}

impl Compound {
    /// Packets stayed at an exported input at its last forwarding (the instance's
    /// `Block` fifo was full).
    fn holds_packets(&self) -> bool {
        self.exports.iter().any(|export| export.held())
    }

    /// Start the instances (first start) or bring them back to `ready` (a restart),
    /// and restore the declared arrangement.
    pub(super) fn start_instances(&mut self, cx: &mut Context) -> Result<(), Fault> {
        let restart = self.started;
        if !self.started {
            if let Some(waker) = cx.waker() {
                self.events = self
                    .instances
                    .iter()
                    .map(|i| {
                        // Set: look at whatever came before the subscription too.
                        let flag = Arc::new(AtomicBool::new(true));
                        let events = i
                            .handle
                            .shared
                            .subscribe_flagged(waker.clone(), Arc::clone(&flag));
                        (events, flag)
                    })
                    .collect();
            }
            if let Some(system) = self.system.as_mut() {
                system.start().map_err(|source| RunError::Start {
                    compound: self.name.clone(),
                    source,
                })?;
            }
            self.started = true;
        }
        self.queue.clear();
        for index in 0..self.instances.len() {
            let instance = &mut self.instances[index];
            instance.pending = None;
            // A retry of the recovery queue not taken yet is not taken at all: its
            // answer would be taken for the next retry's.
            if let Some(retry) = instance.retry.take() {
                retry.withdraw();
            }
            instance.restarts.clear();
            instance.handled = false;
            if instance.status == Status::Destroyed {
                continue;
            }
            if instance.handle.is_stuck() {
                return Err(RunError::Stuck {
                    instance: instance.name.clone(),
                }
                .into());
            }
            instance.status = if instance.substitutes.is_some() {
                Status::Standby
            } else {
                Status::Active
            };
            let mut monitor = instance
                .handle
                .wait_for(|m| m.state != State::Starting, INSTANCE_START_TIMEOUT)
                .map_err(RunError::from)?;
            if restart && monitor.state == State::StartingError {
                // A restart starts again what could not start before (what fails
                // again is judged below). Its answer does not matter: its state does.
                let _ = command(&instance.handle, Controllable::Ready);
                monitor = instance
                    .handle
                    .wait_for(|m| m.state != State::Starting, INSTANCE_START_TIMEOUT)
                    .map_err(RunError::from)?;
            }
            if monitor.state == State::StartingError && instance.handles_start_failure() {
                // A fault its policy handles once the compound runs, as it would
                // one that came later (its substitute stands in and it goes into the
                // recovery queue, or it is ignored, or its group leads on without
                // it): a robot starts though a driver's node is not up yet.
                instance.handled = false;
                self.deferred_faults = true;
                continue;
            }
            if monitor.state == State::StartingError {
                return Err(RunError::CouldNotStart {
                    instance: instance.name.clone(),
                    error: monitor.error.unwrap_or_default(),
                }
                .into());
            }
            if monitor.state != State::Ready {
                command(&instance.handle, Controllable::Ready)?;
                let state = instance.handle.state();
                if state != State::Ready {
                    return Err(RunError::CouldNotRestart {
                        instance: instance.name.clone(),
                        state,
                    }
                    .into());
                }
            }
        }
        // A redundant group none of whose members started (or is still there) has
        // nothing to run on.
        for group in &self.groups {
            let failed = group
                .iter()
                .find(|m| self.instances[**m].handle.state() == State::StartingError);
            let none_started = group.iter().all(|m| {
                self.instances[*m].status == Status::Destroyed
                    || self.instances[*m].handle.state() == State::StartingError
            });
            if let (Some(failed), true) = (failed, none_started) {
                let first = &self.instances[*failed];
                return Err(RunError::CouldNotStart {
                    instance: first.name.clone(),
                    error: first.handle.snapshot().error.unwrap_or_default(),
                }
                .into());
            }
        }
        // Every redundant group is led by its first member again; its merged streams
        // count on from where they are.
        for group in 0..self.groups.len() {
            self.leaders[group] = self.groups[group][0];
        }
        for merged in &self.merges {
            merged.merge.reset(0);
        }
        for group in 0..self.groups.len() {
            for member in self.groups[group].clone() {
                self.joined(member);
            }
        }
        // A destroyed instance's substitute keeps standing for it.
        for index in 0..self.instances.len() {
            if self.instances[index].status == Status::Destroyed
                && let Some(substitute) = self.instances[index].substitute
                && self.instances[substitute].status == Status::Standby
            {
                self.instances[substitute].status = Status::Active;
            }
            self.refresh(index);
        }
        self.rewire()
    }

    /// Shutting down: send instance `index` to `dead`, one of `left` instances still
    /// to stop. It waits as long as the instance's handle waits, and at most its share
    /// of what is left of the compound's stop budget, so that a stuck instance does
    /// not leave the healthy ones stopped after it no time to stop. One the watchdog
    /// found stuck in a section, or one whose turn comes once the budget is spent, is
    /// sent `dead` without waiting: it takes it when it can, and the `Err` says so.
    fn stop_instance(&mut self, index: usize, left: usize) -> Result<(), Fault> {
        let by = *self.stop_by.get_or_insert_with(stop_budget);
        let handle = &self.instances[index].handle;
        let share = by.saturating_duration_since(Instant::now())
            / u32::try_from(left.max(1)).unwrap_or(u32::MAX);
        let wait = share.min(handle.command_timeout);
        let why = if handle.is_stuck() {
            "it is stuck in a section past its max_response"
        } else if wait.is_zero() {
            "the compound's time to stop its instances is spent"
        } else {
            return command(
                &handle.clone().with_command_timeout(wait),
                Controllable::Dead,
            );
        };
        match handle.post(Command::SetState(Controllable::Dead)) {
            Ok(_) => Err(Fault::message(format!(
                "not waited for: {why} ({COMPOUND_STOP_TIMEOUT:?} at most in all); `dead` is queued, taken when it can"
            ))),
            Err(rejected) => Err(RunError::from(rejected).into()),
        }
    }

    /// Bring every instance that runs (or is suspended) to `target`, last declared
    /// first. A command an instance does not take is a `CommandRefused` step,
    /// published when the call returns.
    pub(super) fn instances_to(&mut self, target: Controllable, cx: &mut Context) {
        for index in (0..self.instances.len()).rev() {
            let instance = &self.instances[index];
            let state = instance.handle.state();
            let follows = match target {
                Controllable::Ready => matches!(state, State::Running | State::Suspended),
                Controllable::Suspended => {
                    state == State::Running
                        || (state == State::Ready && instance.status == Status::Active)
                }
                Controllable::Dead => state != State::Dead,
                Controllable::Running => false,
            };
            if !follows {
                continue;
            }
            // `ready` and `suspend` wait as long as a supervisor's command does; `dead`
            // (shutting down) within the compound's stop budget (`stop_instance`).
            let outcome = if target == Controllable::Dead {
                self.stop_instance(index, index + 1)
            } else {
                let bounded = instance
                    .handle
                    .clone()
                    .with_command_timeout(self.commander.timeout());
                command(&bounded, target)
            };
            if let Err(fault) = outcome {
                crate::limited!(
                    &self.name,
                    |held| tracing::warn!(compound = %self.name, "{fault}{held}")
                );
                self.step(
                    index,
                    Step::CommandRefused {
                        command: target.verb().to_owned(),
                    },
                    fault.text().to_owned(),
                );
            }
        }
        cx.supervision.append(&mut self.steps);
    }
}

impl Automaton for Compound {
    fn spec(&self) -> &'static Spec {
        self.spec
    }

    fn start(&mut self, cx: &mut Context) -> Result<(), Fault> {
        self.evaluated_in = None;
        self.start_instances(cx)?;
        self.adapt_start(cx);
        Ok(())
    }

    fn stop(&mut self, cx: &mut Context) {
        if cx.stopping() {
            // Shutting down: the instances go straight to `dead`, so that their own
            // exit sections and `stop` are told so too (a nested compound's supervisor
            // included), last declared first; none waits for a virtual clock first.
            if let Some(system) = &self.system {
                system.release_spending();
            }
            self.stop_by.get_or_insert_with(stop_budget);
            self.instances_to(Controllable::Dead, cx);
        } else {
            self.instances_to(Controllable::Ready, cx);
        }
    }

    fn section(&mut self, state: usize, section: Section, cx: &mut Context) -> Result<(), Fault> {
        self.sectioned = true;
        if cx.stopping() {
            // Shutting down: the budget counts from the supervisor's exit section,
            // whose commands to its instances are part of the compound's stop.
            self.stop_by.get_or_insert_with(stop_budget);
        }
        self.commander.set_stopping(cx.stopping(), self.stop_by);
        self.commander.set_clock_wait(cx.clock_wait());
        let mut scx = SupervisorCx {
            rt: cx,
            view: &self.view,
            instances: &mut self.commander,
        };
        let supervisor = &mut self.supervisor;
        let outcome = catch_unwind(AssertUnwindSafe(|| {
            supervisor.section(state, section, &mut scx)
        }));
        // The commands it gave are steps of this section, published when the call
        // returns, whether it returned or panicked (the runner handles the panic).
        cx.supervision.append(&mut self.commander.take_steps());
        outcome.unwrap_or_else(|panic| resume_unwind(panic))
    }

    fn choose(&mut self, state: usize, cx: &mut Context) -> Option<usize> {
        self.commander.set_clock_wait(cx.clock_wait());
        let mut scx = SupervisorCx {
            rt: cx,
            view: &self.view,
            instances: &mut self.commander,
        };
        let supervisor = &mut self.supervisor;
        let target = catch_unwind(AssertUnwindSafe(|| supervisor.choose(state, &mut scx)));
        cx.supervision.append(&mut self.commander.take_steps());
        target.unwrap_or_else(|panic| resume_unwind(panic))
    }

    fn exception(&mut self, _exception: usize, _message: &str, _cx: &mut Context) {}

    fn answer(&mut self, _output: usize, _cx: &mut Context) -> Result<(), Fault> {
        Ok(())
    }

    fn configure(&mut self, _configuration: &Value) -> Result<(), ValueRefused> {
        Err(ValueRefused::CompoundConfiguration)
    }

    fn set(&mut self, variable: usize, value: &Value) -> Result<(), ValueRefused> {
        if let Some(mapped) = self.mapped.get(variable) {
            let target = self.route(mapped.instance);
            self.instances[target]
                .handle
                .command(Command::Set(mapped.variable.clone(), value.clone()))?;
            return Ok(());
        }
        self.supervisor.set(variable - self.own_offset, value)
    }

    fn get(&self, variable: usize) -> Value {
        if let Some(mapped) = self.mapped.get(variable) {
            let target = self.route(mapped.instance);
            return self.view.instances[target]
                .variables
                .iter()
                .find(|(name, _)| *name == mapped.variable)
                .map_or(Value::Unit, |(_, value)| value.clone());
        }
        self.supervisor.get(variable - self.own_offset)
    }
}

/// The runner's compound hooks: the instances follow the compound's state, the
/// supervisor takes its turns.
impl Driven for Compound {
    fn before_running(&mut self, _cx: &mut Context) -> Result<(), Fault> {
        // The supervisor enters (or resumes) a state: its rules are evaluated afresh.
        self.evaluated_in = None;
        for (index, instance) in self.instances.iter().enumerate() {
            let held = self
                .coordinator
                .as_ref()
                .is_some_and(|c| c.suspended[index]);
            if instance.status == Status::Active
                && !held
                && matches!(instance.handle.state(), State::Ready | State::Suspended)
            {
                command(&instance.handle, Controllable::Running)?;
            }
        }
        Ok(())
    }

    fn after_transition(&mut self, _from: State, to: State, cx: &mut Context) {
        match to {
            State::Ready => self.instances_to(Controllable::Ready, cx),
            State::Suspended => self.instances_to(Controllable::Suspended, cx),
            State::Dead => {
                if let Some(system) = self.system.take() {
                    let by = *self.stop_by.get_or_insert_with(stop_budget);
                    let report = system.shutdown_by(by);
                    if !report.clean() {
                        tracing::warn!(compound = %self.name, "instances not joined: {report:?}");
                    }
                }
            }
            _ => {}
        }
    }

    fn supervises(&self) -> bool {
        true
    }

    fn set_clock(&mut self, clock: &crate::clock::Clock) {
        // Before the compound's thread starts, so before its instances start.
        self.clock = clock.clone();
        if let Some(system) = self.system.as_mut() {
            system.set_clock(clock.clone());
        }
    }

    fn supervise(&mut self, state: usize, cx: &mut Context) -> Result<Option<usize>, Fault> {
        self.clock_wait = cx.member_clock_wait();
        let outcome = self.supervise_turn(state, cx);
        if let Some(coordinator) = self.coordinator.as_mut()
            && coordinator
                .settle_until
                .is_some_and(|until| self.clock.now() >= until)
        {
            // Settled: promotion may be due.
            coordinator.settle_until = None;
            coordinator.dirty = true;
        }
        if outcome.is_ok() && self.coordinator.as_ref().is_some_and(|c| c.dirty) {
            self.adapt_turn(cx);
        }
        cx.supervision.append(&mut self.steps);
        outcome
    }

    fn observe(&mut self, cx: &mut Context) {
        self.observe_turn();
        cx.supervision.append(&mut self.steps);
    }

    fn set_degradation(&mut self, level: u32, cx: &mut Context) -> Result<(), DegradationRefused> {
        let name = self.name.clone();
        let Some(coordinator) = self.coordinator.as_mut() else {
            return Err(DegradationRefused::Off);
        };
        if level > coordinator.max_level {
            return Err(DegradationRefused::OutOfRange {
                level,
                max: coordinator.max_level,
            });
        }
        let from = coordinator.cap;
        coordinator.cap = level;
        coordinator.floor = level.saturating_sub(coordinator.config.width);
        coordinator.initialized = true;
        coordinator.dirty = true;
        if from != level {
            let step = Adaptation {
                component: name,
                action: if level > from {
                    AdaptAction::Degraded
                } else {
                    AdaptAction::Promoted
                },
                from,
                to: level,
                period: None,
                quality: None,
                detail: "current maximum level of the instances, set through the control port"
                    .to_owned(),
            };
            let floor = coordinator.floor;
            if let Some(shared) = &cx.shared {
                shared.adaptation_step(step, true, |status| {
                    status.level = level;
                    status.floor = floor;
                });
                // The verdict published so far was about the previous level: withdraw
                // it, as an atomic component does when its level changes, so that the
                // supervisor above does not act on it again before this compound's
                // next turn judges the new level.
                let load = shared.snapshot().adaptation.load;
                shared.set_pressure(Pressure::Nominal, load);
            }
        }
        Ok(())
    }

    fn entered(&mut self, state: usize) {
        // Whatever led there (a rule, `after`, `on`, `may`), the next turn, taken at
        // once, evaluates every rule of the entered state. (Re-entering the state
        // whose rules were evaluated last changes nothing they read: as before, only
        // changes make them evaluated again, so a rule leading back to its own state
        // does not fire in a loop.)
        if self.evaluated_in != Some(state) {
            self.fresh = true;
        }
    }

    fn retries_data(&self) -> Option<Duration> {
        (!self.clock.is_real() && self.holds_packets()).then_some(EXPORT_RETRY)
    }

    fn wake_at(&self) -> Option<Instant> {
        let queue = self.queue.iter().map(|entry| {
            entry
                .next
                .min(crate::time::later(entry.since, self.deadline))
        });
        // A stuck instance's return is an event; its deadline is a timer.
        let restarts = self.instances.iter().filter_map(|i| {
            let pending = i.pending?;
            Some(if i.handle.is_stuck() {
                crate::time::later(pending.since, self.deadline)
            } else {
                pending.due
            })
        });
        let dirty = self.coordinator.as_ref().is_some_and(|c| c.dirty);
        let settle = self.coordinator.as_ref().and_then(|c| c.settle_until);
        let fresh = (self.fresh || self.sectioned || dirty).then(|| self.clock.now());
        // Packets held at an exported input (the instance's `Block` fifo was full):
        // retried soon (on a virtual clock in real time: `retries_data`).
        let held = (self.clock.is_real() && self.holds_packets())
            .then(|| crate::time::later(self.clock.now(), EXPORT_RETRY));
        queue
            .chain(restarts)
            .chain(fresh)
            .chain(held)
            .chain(settle)
            .chain(self.next_timed)
            .min()
    }
}
