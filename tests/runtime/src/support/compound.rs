//! One way to build and drive a compound in a test: a system holding the compound
//! (built from its generated module, or with the runtime's `CompoundBuilder` over
//! generated instances), on the real clock or on a virtual one; start it, command it,
//! wait for it or one of its instances to reach a state or user state or for a
//! supervision step, step the virtual clock, and reach the scripts of the instances
//! that follow a [`Script`] ([`Scripts`]).

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use coolbot::{
    Clock, Command, Component, Controllable, Handle, Monitor, Report, State, Step, Supervision,
    System, VirtualClock,
};

use super::{Injected, Script, Scripted, WAIT};

/// The scripts of a compound's scripted instances, by instance name: a `Parts`
/// implementation gives instance `w` the behaviour [`Scripts::scripted`]`("w")`, and
/// the test reaches the same script with [`Scripts::of`]`("w")`.
#[derive(Clone, Default)]
pub struct Scripts {
    scripts: Arc<Mutex<HashMap<String, Arc<Script>>>>,
}

impl Scripts {
    pub fn new() -> Scripts {
        Scripts::default()
    }

    /// The script of instance `name` (made on first use).
    pub fn of(&self, name: &str) -> Arc<Script> {
        Arc::clone(
            self.scripts
                .lock()
                .unwrap()
                .entry(name.to_owned())
                .or_default(),
        )
    }

    /// A behaviour for instance `name`, following its script.
    pub fn scripted(&self, name: &str) -> Scripted {
        Scripted::new(&self.of(name))
    }

    /// Inject `fault` into instance `name`'s script.
    pub fn inject(&self, name: &str, fault: Option<Injected>) {
        self.of(name).inject(fault);
    }
}

/// A system holding compound `name` (and whatever else the test adds before it
/// starts), the compound's handle, and the virtual clock the system runs on, if any.
pub struct CompoundRig {
    pub system: System,
    pub compound: Handle,
    pub clock: Option<Arc<VirtualClock>>,
}

impl CompoundRig {
    /// `compound` added to a new system on the real clock (not started).
    pub fn new(compound: Result<Component, coolbot::CompoundError>) -> CompoundRig {
        CompoundRig::in_system(System::new(), None, compound)
    }

    /// `compound` added to a new system on a new virtual clock (not started).
    pub fn on_virtual_clock(compound: Result<Component, coolbot::CompoundError>) -> CompoundRig {
        let clock = VirtualClock::new();
        let system = System::with_clock(Clock::virtual_clock(&clock));
        CompoundRig::in_system(system, Some(clock), compound)
    }

    fn in_system(
        mut system: System,
        clock: Option<Arc<VirtualClock>>,
        compound: Result<Component, coolbot::CompoundError>,
    ) -> CompoundRig {
        let compound = compound.unwrap_or_else(|error| panic!("the compound builds: {error}"));
        let compound = system.add(compound).expect("add the compound");
        CompoundRig {
            system,
            compound,
            clock,
        }
    }

    /// Add another component beside the compound (before the system starts).
    pub fn add(&mut self, component: Component) -> Handle {
        self.system.add(component).expect("add")
    }

    /// Connect `from` to `to` in the system (before it starts).
    pub fn connect(&mut self, from: &str, to: &str) {
        self.system
            .connect(from, to)
            .unwrap_or_else(|error| panic!("connect {from} -> {to}: {error}"));
    }

    /// Start the system and wait until the compound left `starting`.
    pub fn start(&mut self) {
        self.system.start().expect("start");
        self.compound
            .wait_for(|m| m.state != State::Starting, WAIT)
            .expect("the compound left starting");
    }

    /// Start the system and command every component to `running`.
    pub fn run(&mut self) {
        self.system.run_all().expect("run");
    }

    /// Command the compound to `target`.
    pub fn command(&self, target: Controllable) -> Result<(), coolbot::Rejected> {
        self.compound.command(Command::SetState(target))
    }

    /// The handle of instance `path` (`a.b` for `b` inside nested compound `a`).
    pub fn instance(&self, path: &str) -> Handle {
        self.compound
            .instance(path)
            .unwrap_or_else(|| panic!("no instance {path}"))
    }

    /// Wait until the compound is in `state`.
    pub fn wait_state(&self, state: State) -> Monitor {
        wait_state(&self.compound, state)
    }

    /// Wait until the compound runs in supervisor state `user`.
    pub fn wait_user(&self, user: &str) -> Monitor {
        wait_user(&self.compound, user)
    }

    /// Wait until instance `path` is in `state`.
    pub fn wait_instance_state(&self, path: &str, state: State) -> Monitor {
        wait_state(&self.instance(path), state)
    }

    /// Wait until instance `path` runs in user state `user`.
    pub fn wait_instance_user(&self, path: &str, user: &str) -> Monitor {
        wait_user(&self.instance(path), user)
    }

    /// Wait until the compound published at least `times` supervision steps about
    /// `instance` that satisfy `step`.
    pub fn wait_steps(
        &self,
        instance: &str,
        times: usize,
        step: impl Fn(&Step) -> bool,
    ) -> Monitor {
        self.compound
            .wait_for(
                |m| count_where(&m.supervision, instance, &step) >= times,
                WAIT,
            )
            .unwrap_or_else(|_| {
                panic!(
                    "{times} step(s) about {instance}: {:?}",
                    self.compound.snapshot().supervision
                )
            })
    }

    /// How many supervision steps `step` about `instance` the compound published.
    pub fn steps(&self, instance: &str, step: &Step) -> usize {
        count(&self.compound.snapshot().supervision, instance, step)
    }

    /// Advance the virtual clock by `by`, until every component settled.
    pub fn advance(&self, by: Duration) {
        self.clock
            .as_ref()
            .expect("a rig on a virtual clock")
            .advance(by)
            .expect("the components settle");
    }

    /// Shut the system down.
    pub fn shutdown(self) -> Report {
        self.system.shutdown()
    }
}

/// How many of `steps` are `step` about `instance`.
pub fn count(steps: &[Supervision], instance: &str, step: &Step) -> usize {
    count_where(steps, instance, |s| s == step)
}

fn count_where(steps: &[Supervision], instance: &str, step: impl Fn(&Step) -> bool) -> usize {
    steps
        .iter()
        .filter(|s| s.instance == instance && step(&s.step))
        .count()
}

/// Wait until `handle` is in `state`.
pub fn wait_state(handle: &Handle, state: State) -> Monitor {
    handle
        .wait_state(state, WAIT)
        .unwrap_or_else(|t| panic!("{}: {t}", handle.name()))
}

/// Wait until `handle` runs in user state `user`.
pub fn wait_user(handle: &Handle, user: &str) -> Monitor {
    handle
        .wait_for(
            |m| m.user_state.as_deref() == Some(user) && m.state == State::Running,
            WAIT,
        )
        .unwrap_or_else(|t| panic!("{}: {t}", handle.name()))
}
