//! A compound whose instances are stand-ins: the supervisor harness's compound
//! (`crate::harness::supervisor`). The supervisor (its states, sections, `may`
//! choices, own variables) and its rules are the description's, run by the same
//! runner and evaluated by the same function ([`fire`]) as a built compound's; the
//! instances are monitors a test sets ([`Stage`]), and the commands the supervisor
//! gives them are recorded and taken as an instance would take them.
//!
//! As in a built compound, the view the supervisor's sections and choices read is the
//! one taken at the last supervision turn: a state an instance reached by a command
//! given in the same section shows at the next turn.
//!
//! What a stand-in compound does not do: fault policies, the recovery queue,
//! substitution and redundancy (no instance fails on its own), adaptation, and
//! forwarding on exported ports. Those need the instances themselves: a built
//! compound on threads.

use std::collections::{HashMap, HashSet, VecDeque};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Instant;

use crate::automaton::{Automaton, Context, Driven, Fault, Section, ValueRefused};
use crate::clock::Clock;
use crate::commander::{Commander, StandIns};
use crate::monitor::{Command, Monitor};
use crate::refused::Refused;
use crate::spec::Spec;
use crate::system::Component;
use crate::table::{Controllable, State};
use crate::value::Value;

use super::builder::{CompoundBuilder, Resolved};
use super::error::CompoundError;
use super::reads::{Changed, Reads};
use super::state::Mapped;
use super::supervision::{fire, refresh_own_defaults};
use super::supervisor::Supervisor;
use super::view::{Rule, View};

/// The instances of a stand-in compound, as a test sets them and as the supervisor's
/// commands leave them.
#[derive(Debug)]
pub(crate) struct Stage {
    /// The instances' names, in declaration order.
    pub(crate) names: Vec<String>,
    /// Each instance's monitor, as the supervisor will next see it.
    pub(crate) monitors: Vec<Monitor>,
    /// Each instance's spec.
    pub(crate) specs: Vec<&'static Spec>,
    /// Whether each instance substitutes another (it stays `ready` when the compound
    /// runs, as a standby substitute does).
    standby: Vec<bool>,
    /// What changed since the supervisor last looked (rule read keys).
    pub(crate) changed: HashSet<String>,
    /// Every command the supervisor gave, in order: `(instance, command)`.
    pub(crate) commands: Vec<(String, Command)>,
    /// Refusals to give to the next commands to an instance, in order.
    pub(crate) refusals: HashMap<String, VecDeque<Refused>>,
}

impl Stage {
    /// The position of instance `name`.
    pub(crate) fn position(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    /// Set instance `index`'s default state, as its control port would.
    fn move_to(&mut self, index: usize, state: State) {
        if self.monitors[index].state != state {
            self.monitors[index].state = state;
            self.changed.insert(format!("{}.state", self.names[index]));
        }
    }

    /// Set a variable of instance `index`.
    pub(crate) fn set_variable(&mut self, index: usize, variable: &str, value: Value) {
        let monitor = &mut self.monitors[index];
        match monitor
            .variables
            .iter_mut()
            .find(|(name, _)| name == variable)
        {
            Some((_, old)) => *old = value,
            None => monitor.variables.push((variable.to_owned(), value)),
        }
        self.changed
            .insert(format!("{}.{variable}", self.names[index]));
    }
}

impl StandIns for Stage {
    fn command(&mut self, instance: &str, command: &Command) -> Result<(), Refused> {
        let index = self.position(instance).ok_or(Refused::UnknownInstance)?;
        self.commands.push((instance.to_owned(), command.clone()));
        if let Some(refused) = self
            .refusals
            .get_mut(instance)
            .and_then(VecDeque::pop_front)
        {
            return Err(refused);
        }
        if self.monitors[index].state == State::Dead {
            return Err(Refused::Dead);
        }
        match command {
            Command::SetState(target) => {
                let state = match target {
                    Controllable::Ready => State::Ready,
                    Controllable::Running => State::Running,
                    Controllable::Suspended => State::Suspended,
                    Controllable::Dead => State::Dead,
                };
                self.move_to(index, state);
            }
            Command::Set(variable, value) => self.set_variable(index, variable, value.clone()),
            Command::SetQuality(level) if self.monitors[index].quality != *level => {
                self.monitors[index].quality = *level;
                self.changed.insert(format!("{instance}.quality"));
            }
            Command::SetPeriod(period) => self.monitors[index].period = Some(*period),
            _ => {}
        }
        Ok(())
    }
}

/// The stand-in compound's automaton: the description's supervisor and rules over a
/// [`Stage`].
pub(crate) struct StandIn {
    spec: &'static Spec,
    supervisor: Box<dyn Supervisor>,
    own_offset: usize,
    mapped: Vec<Mapped>,
    rules: Vec<Rule>,
    /// What the rules read, resolved to ids.
    reads: Reads,
    /// The read keys that changed in the current supervision turn.
    changed: Changed,
    reads_own: bool,
    /// What the rules and sections see, copied from the stage at each turn.
    view: View,
    stage: Arc<Mutex<Stage>>,
    commander: Commander,
    evaluated_in: Option<usize>,
    fresh: bool,
    sectioned: bool,
    clock: Clock,
}

impl CompoundBuilder {
    /// The compound with stand-ins for its instances: a component for a harness, and
    /// the stage the test sets the instances on. The instances the builder made are
    /// not started: only their names, specs, quality levels and variables are used.
    pub(crate) fn stand_in(mut self) -> Result<(Component, Arc<Mutex<Stage>>), CompoundError> {
        let Resolved {
            spec,
            mapped,
            rules,
            reads,
            mut view,
            ..
        } = self.resolve()?;
        let names: Vec<String> = self.instances.iter().map(|i| i.name.clone()).collect();
        // As a started compound leaves them: every instance `ready`.
        for monitor in &mut view.instances {
            monitor.state = State::Ready;
        }
        let stage = Arc::new(Mutex::new(Stage {
            names,
            monitors: view.instances.clone(),
            specs: self.instances.iter().map(|i| i.spec).collect(),
            standby: self
                .instances
                .iter()
                .map(|i| i.substitutes.is_some())
                .collect(),
            changed: HashSet::new(),
            commands: Vec::new(),
            refusals: HashMap::new(),
        }));
        let stand_ins: Arc<Mutex<dyn StandIns>> = stage.clone();
        let commander = Commander::standing_in(
            self.name.clone(),
            self.instances
                .iter()
                .map(|i| (i.name.clone(), i.spec, i.levels)),
            stand_ins,
        );
        let automaton = StandIn {
            spec,
            supervisor: self.supervisor,
            own_offset: mapped.len(),
            mapped,
            rules,
            changed: Changed::new(reads.len()),
            reads_own: reads.reads_own(),
            reads,
            view,
            stage: Arc::clone(&stage),
            commander,
            evaluated_in: None,
            fresh: false,
            sectioned: false,
            clock: Clock::real(),
        };
        Ok((
            Component::driven(self.name, Box::new(automaton), self.ports),
            stage,
        ))
    }
}

impl StandIn {
    fn stage(&self) -> std::sync::MutexGuard<'_, Stage> {
        self.stage.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Copy the stage into the view; the read keys that changed (mapped variables
    /// with the instance variables they map) go into `changed`.
    fn take_stage(&mut self) {
        self.changed.clear();
        let mut stage = self.stage.lock().unwrap_or_else(PoisonError::into_inner);
        self.view.instances.clone_from(&stage.monitors);
        let changed = std::mem::take(&mut stage.changed);
        for (at, mapped) in self.mapped.iter().enumerate() {
            let key = format!("{}.{}", stage.names[mapped.instance], mapped.variable);
            if changed.contains(&key) {
                self.changed.insert(self.reads.mapped[at]);
            }
        }
        drop(stage);
        for key in &changed {
            self.changed.insert(self.reads.id(key));
        }
        for (index, (_, value)) in self.view.own.iter_mut().enumerate() {
            let now = self.supervisor.get(index);
            if *value != now {
                *value = now;
                self.changed.insert(self.reads.own[index]);
            }
        }
    }

    /// Bring the instances that follow the compound to `target`, as a built compound
    /// does when it goes to `ready` or `suspended`.
    fn instances_to(&self, target: State) {
        let mut stage = self.stage();
        for index in (0..stage.monitors.len()).rev() {
            let state = stage.monitors[index].state;
            let follows = match target {
                State::Ready => matches!(state, State::Running | State::Suspended),
                State::Suspended => {
                    state == State::Running || (state == State::Ready && !stage.standby[index])
                }
                _ => false,
            };
            if follows {
                stage.move_to(index, target);
            }
        }
    }
}

impl Automaton for StandIn {
    fn spec(&self) -> &'static Spec {
        self.spec
    }

    fn start(&mut self, _cx: &mut Context) -> Result<(), Fault> {
        self.evaluated_in = None;
        Ok(())
    }

    fn stop(&mut self, _cx: &mut Context) {
        self.instances_to(State::Ready);
    }

    fn section(&mut self, state: usize, section: Section, cx: &mut Context) -> Result<(), Fault> {
        self.sectioned = true;
        self.commander.set_stopping(cx.stopping(), None);
        let mut scx = super::SupervisorCx {
            rt: cx,
            view: &self.view,
            instances: &mut self.commander,
        };
        let outcome = self.supervisor.section(state, section, &mut scx);
        cx.supervision.append(&mut self.commander.take_steps());
        outcome
    }

    fn choose(&mut self, state: usize, cx: &mut Context) -> Option<usize> {
        let mut scx = super::SupervisorCx {
            rt: cx,
            view: &self.view,
            instances: &mut self.commander,
        };
        let target = self.supervisor.choose(state, &mut scx);
        cx.supervision.append(&mut self.commander.take_steps());
        target
    }

    fn answer(&mut self, _output: usize, _cx: &mut Context) -> Result<(), Fault> {
        // A pull of an exported output gets no answer here (it times out), as the
        // stand-ins answer nothing.
        Ok(())
    }

    fn configure(&mut self, _configuration: &Value) -> Result<(), ValueRefused> {
        Err(ValueRefused::CompoundConfiguration)
    }

    fn set(&mut self, variable: usize, value: &Value) -> Result<(), ValueRefused> {
        if let Some(mapped) = self.mapped.get(variable) {
            // As a built compound does: a `set` command to the instance, recorded and
            // refused as any other.
            let mut stage = self.stage();
            let instance = stage.names[mapped.instance].clone();
            stage.command(
                &instance,
                &Command::Set(mapped.variable.clone(), value.clone()),
            )?;
            return Ok(());
        }
        self.supervisor.set(variable - self.own_offset, value)
    }

    fn get(&self, variable: usize) -> Value {
        if let Some(mapped) = self.mapped.get(variable) {
            return self.stage().monitors[mapped.instance]
                .variables
                .iter()
                .find(|(name, _)| *name == mapped.variable)
                .map_or(Value::Unit, |(_, value)| value.clone());
        }
        self.supervisor.get(variable - self.own_offset)
    }
}

impl Driven for StandIn {
    fn supervises(&self) -> bool {
        true
    }

    fn before_running(&mut self, _cx: &mut Context) -> Result<(), Fault> {
        self.evaluated_in = None;
        let mut stage = self.stage();
        for index in 0..stage.monitors.len() {
            if !stage.standby[index]
                && matches!(stage.monitors[index].state, State::Ready | State::Suspended)
            {
                stage.move_to(index, State::Running);
            }
        }
        Ok(())
    }

    fn after_transition(&mut self, _from: State, to: State, _cx: &mut Context) {
        if matches!(to, State::Ready | State::Suspended) {
            self.instances_to(to);
        }
    }

    fn set_clock(&mut self, clock: &Clock) {
        self.clock = clock.clone();
    }

    fn supervise(&mut self, state: usize, cx: &mut Context) -> Result<Option<usize>, Fault> {
        self.take_stage();
        if self.reads_own {
            refresh_own_defaults(&mut self.view, cx, &self.reads, &mut self.changed);
        }
        let entered = self.evaluated_in != Some(state);
        let sectioned = std::mem::take(&mut self.sectioned);
        self.fresh = false;
        if !entered && !sectioned && self.changed.is_empty() {
            return Ok(None);
        }
        self.evaluated_in = Some(state);
        Ok(fire(
            &self.rules,
            &self.view,
            state,
            entered || sectioned,
            &self.changed,
        ))
    }

    fn observe(&mut self, _cx: &mut Context) {
        // Observation only: the changes wait for the next supervision turn.
        let stage = self.stage.lock().unwrap_or_else(PoisonError::into_inner);
        self.view.instances.clone_from(&stage.monitors);
    }

    fn entered(&mut self, state: usize) {
        if self.evaluated_in != Some(state) {
            self.fresh = true;
        }
    }

    fn wake_at(&self) -> Option<Instant> {
        let pending = self.fresh || self.sectioned || !self.stage().changed.is_empty();
        pending.then(|| self.clock.now())
    }
}
