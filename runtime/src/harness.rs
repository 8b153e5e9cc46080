//! One component alone, on a virtual clock, with no thread: a test harness.
//!
//! A [`Harness`] takes an unstarted [`Component`] (what a generated `component()`
//! returns) and drives it on the caller's thread, through the same per-event step
//! as the component thread (`runner::Runner::turn`: control commands, `end`, timers,
//! `on` transitions, pull requests, in the runtime's priority order), so what runs is
//! exactly what the runtime would run: `start`/`stop`, entry, periodic and exit
//! sections, `on` and `after` transitions, `may` choices, exception handlers and
//! their continuity plans, the default automaton's table.
//!
//! Each input gets a feeder of its own (an output of its packet type linked to it,
//! as a connection would be: a fifo keeps its capacity and overflow policy, a last
//! input its latest value), so [`Harness::push`], [`Harness::post`] and
//! [`Harness::tick`] deliver packets as a producer would; a pull request the
//! component makes on an input is answered at once, on its own call, with the next
//! answer queued by [`Harness::answer`] (with none queued, nobody answers and the
//! pull times out after its timeout, in real time). Each output gets a collector
//! (a tap, as a recorder's: not a connection), read with [`Harness::take_sent`] and
//! [`Harness::take_ticks`]; [`Harness::pull`] asks a `pull` output for an answer.
//!
//! Time is a [`VirtualClock`] of the harness's own, which moves only in
//! [`Harness::advance`]: it steps from timer to timer (each periodic deadline and
//! `after` transition due by then fires at its own time, in due order), running the
//! component until it is quiescent at each. A section takes no time on it unless it
//! says so (`Context::spend` moves the clock on by its cost: so no `max_response`
//! overrun and no missed deadline happen unless a test advances the clock past them
//! or a section takes that much), and a `retry ... every` plan step is a timer on it. Nothing here
//! reads the real clock for the component's timers: a harness test is
//! deterministic. (The real-time readings that remain are the monitor's CPU time and
//! [`crate::Context::now`], wall-clock time for packets' stamps.)
//!
//! [`replay`] feeds a harness from an MCAP recording ([`crate::record`]).
//! [`SupervisorHarness`] drives a compound's supervisor the same way, its instances
//! stood in for by monitors the test sets ([`supervisor`]).
//!
//! coolc generates a typed wrapper per atomic component (`<module>::Harness<B>`,
//! `docs/generated-code.md`) over this one: methods per port with the component's
//! packet types, and its `Vars`, `Config`, behaviour and `UserState` read back.

pub mod replay;
pub mod supervisor;
#[cfg(test)]
mod tests;

pub use supervisor::SupervisorHarness;

use std::any::Any;
use std::collections::VecDeque;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use crate::clock::{Clock, VirtualClock};
use crate::handle::{ControlMessage, Handle, Reply};
use crate::monitor::TaskResult;
use crate::monitor::{Command, Monitor};
use crate::port::{
    Collected, ErasedInput, ErasedOutput, InKind, OutKind, Packet, PullError, TickIn,
};
use crate::runner::{Runner, Turn};
use crate::spec::Spec;
use crate::system::{Component, Prepared, prepare};
use crate::table::{Controllable, State};
use crate::value::Value;

/// The most turns [`Harness::settle`] takes at one instant before it reports that the
/// component never becomes quiescent (a `may` choice that always goes on, for one).
pub const MAX_TURNS: usize = 100_000;

/// What went wrong driving a component in a [`Harness`].
#[derive(Debug, thiserror::Error)]
pub enum HarnessError {
    /// The component does not build (its name, spec or ports).
    #[error("the component cannot be driven")]
    Component(#[source] crate::system::Error),
    /// No input of that name.
    #[error("`{component}` has no input `{port}` (inputs: {known})")]
    NoInput {
        /// The component's name.
        component: String,
        /// The name asked for.
        port: String,
        /// The inputs it has.
        known: String,
    },
    /// No output of that name.
    #[error("`{component}` has no output `{port}` (outputs: {known})")]
    NoOutput {
        /// The component's name.
        component: String,
        /// The name asked for.
        port: String,
        /// The outputs it has.
        known: String,
    },
    /// The port's packets are of another type.
    #[error("port `{port}` carries `{actual}`, not `{requested}`")]
    WrongType {
        /// The port.
        port: String,
        /// Its packet type.
        actual: String,
        /// The type asked for.
        requested: String,
    },
    /// The port is of another kind than the operation needs.
    #[error("port `{port}` is a {kind} port: {wanted}")]
    WrongKind {
        /// The port.
        port: String,
        /// Its kind.
        kind: &'static str,
        /// What the operation needs.
        wanted: &'static str,
    },
    /// The component rejected a command.
    #[error("`{component}` rejected {command}: {reason}")]
    Rejected {
        /// The component's name.
        component: String,
        /// The command, rendered (its first `ranges::EXCERPT_CHARS` characters).
        command: String,
        /// Its reason.
        reason: String,
    },
    /// The compound does not build (a supervisor harness's builder).
    #[error("the compound cannot be driven")]
    Compound(#[source] Box<crate::compound::CompoundError>),
    /// A supervisor harness's compound has no instance of that name.
    #[error("`{compound}` has no instance `{instance}` (instances: {known})")]
    NoInstance {
        /// The compound's name.
        compound: String,
        /// The name asked for.
        instance: String,
        /// The instances it has.
        known: String,
    },
    /// An instance's automaton has no state of that name.
    #[error("instance `{instance}` has no user state `{state}` (states: {known})")]
    NoUserState {
        /// The instance.
        instance: String,
        /// The name asked for.
        state: String,
        /// The states it has.
        known: String,
    },
    /// An instance's component declares no variable of that name.
    #[error("instance `{instance}` has no variable `{variable}`")]
    NoInstanceVariable {
        /// The instance.
        instance: String,
        /// The name asked for.
        variable: String,
    },
    /// The component kept working at one instant for [`MAX_TURNS`] turns.
    #[error("`{component}` is still busy after {turns} turns at one instant (a `may` loop?)")]
    NotQuiescent {
        /// The component's name.
        component: String,
        /// The turns taken.
        turns: usize,
    },
    /// A pull request could not be made.
    #[error("pull request on `{port}`")]
    Pull {
        /// The output.
        port: String,
        /// Why.
        #[source]
        source: PullError,
    },
}

/// Canned answers to the pull requests of one input, each a send through its feeder.
type Answers = Arc<Mutex<VecDeque<Box<dyn FnOnce() + Send>>>>;

/// One input of the component and its feeder.
struct Feed {
    input: ErasedInput,
    feeder: ErasedOutput,
    answers: Answers,
}

/// One output of the component and its collector.
struct Probe {
    output: ErasedOutput,
    /// The collector's id (a pull request on its behalf is answered to it).
    id: usize,
    /// A `Collected<T>` (data, poster) or a `TickIn` (tick).
    collector: Arc<dyn Any + Send + Sync>,
}

/// One component driven on the caller's thread, on a virtual clock (see the module's
/// documentation).
pub struct Harness {
    name: String,
    spec: &'static Spec,
    runner: Runner,
    handle: Handle,
    clock: Arc<VirtualClock>,
    inputs: Vec<Feed>,
    outputs: Vec<Probe>,
}

impl std::fmt::Debug for Harness {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "Harness({}: {} at {:?})",
            self.name,
            self.spec.type_name,
            self.clock.elapsed()
        )
    }
}

fn names<'a>(names: impl Iterator<Item = &'a str>) -> String {
    let list: Vec<&str> = names.collect();
    if list.is_empty() {
        "none".to_owned()
    } else {
        list.join(", ")
    }
}

impl Harness {
    /// Build `component` with in-memory ports on a new virtual clock and run its
    /// `start` hook: it is then `ready` (or `starting_error`), as a started system
    /// leaves it. [`Harness::run`] runs its user automaton.
    pub fn new(component: Component) -> Result<Harness, HarnessError> {
        let Prepared {
            name,
            spec,
            handle,
            inputs,
            outputs,
            mut runner,
        } = prepare(component).map_err(HarnessError::Component)?;
        let clock = VirtualClock::new();
        runner.harness_on(Clock::virtual_clock(&clock));
        let inputs = inputs
            .into_iter()
            .zip(spec.inputs)
            .map(|(input, declared)| {
                let feeder = crate::port::feeder_of(&input);
                // A feeder of the input's own kind and type: linking cannot fail.
                let _ = feeder.link(&input);
                let answers: Answers = Arc::default();
                if declared.pull {
                    let queue = Arc::clone(&answers);
                    crate::port::answer_pulls_with(
                        &feeder,
                        Arc::new(move || {
                            let next = queue
                                .lock()
                                .unwrap_or_else(PoisonError::into_inner)
                                .pop_front();
                            if let Some(send) = next {
                                send();
                            }
                        }),
                    );
                }
                Feed {
                    input,
                    feeder,
                    answers,
                }
            })
            .collect();
        let outputs = outputs
            .into_iter()
            .filter_map(|output| {
                let (id, collector) = crate::port::collector_of(&output)?;
                Some(Probe {
                    output,
                    id,
                    collector,
                })
            })
            .collect();
        let mut harness = Harness {
            name,
            spec,
            runner,
            handle,
            clock,
            inputs,
            outputs,
        };
        harness.runner.begin();
        harness.settle()?;
        Ok(harness)
    }

    /// [`Harness::new`], then [`Harness::run`]: the initial user state is entered.
    pub fn running(component: Component) -> Result<Harness, HarnessError> {
        let mut harness = Harness::new(component)?;
        harness.run()?;
        Ok(harness)
    }

    // -----------------------------------------------------------------------------
    // Running.

    /// Run the component until it has nothing more to do at the current time: every
    /// command, arrival, choice and timer due now handled (the turns of a component
    /// thread up to its next wait).
    pub fn settle(&mut self) -> Result<(), HarnessError> {
        for _ in 0..MAX_TURNS {
            match self.runner.turn() {
                Turn::Worked => {}
                Turn::Idle | Turn::Stopped | Turn::Dead => {
                    // What a component's thread publishes before it waits.
                    self.runner.publish_elapsed();
                    return Ok(());
                }
            }
        }
        Err(HarnessError::NotQuiescent {
            component: self.name.clone(),
            turns: MAX_TURNS,
        })
    }

    /// Move the virtual clock forward by `by`, timer by timer: each periodic deadline
    /// and `after` transition due by then fires at its own time, in due order, and
    /// the component settles at each (and at the end).
    pub fn advance(&mut self, by: Duration) -> Result<(), HarnessError> {
        let target = crate::time::later(self.clock.now(), by);
        self.settle()?;
        while let Some(due) = self.runner.next_due().filter(|due| *due <= target) {
            let now = self.clock.now();
            self.move_clock(due.saturating_duration_since(now));
            self.settle()?;
            if self.runner.next_due() == Some(due) && due <= self.clock.now() {
                // Settled with the same timer still due: it cannot fire (a zero
                // delay re-armed at once); stop stepping rather than spin.
                break;
            }
        }
        let now = self.clock.now();
        self.move_clock(target.saturating_duration_since(now));
        self.settle()
    }

    fn move_clock(&self, by: Duration) {
        if !by.is_zero() {
            // No component is on this clock (the harness has no thread), so nothing
            // is waited for.
            let _ = self.clock.advance_with_timeout(by, Duration::ZERO);
        }
    }

    /// How far the virtual clock has been advanced since the harness was made.
    pub fn elapsed(&self) -> Duration {
        self.clock.elapsed()
    }

    /// The harness's virtual clock.
    pub fn clock(&self) -> &Arc<VirtualClock> {
        &self.clock
    }

    /// The next timer due (time from now), while the user automaton runs.
    pub fn next_due(&self) -> Option<Duration> {
        self.runner
            .next_due()
            .map(|due| due.saturating_duration_since(self.clock.now()))
    }

    // -----------------------------------------------------------------------------
    // The control port.

    /// Send `command` through the control port, settle, and return the component's
    /// answer.
    pub fn command(&mut self, command: Command) -> Result<(), HarnessError> {
        let (message, answers) = ControlMessage::new(command.clone(), false);
        let component = self.name.clone();
        let rejected = |reason: String| HarnessError::Rejected {
            component: component.clone(),
            command: crate::ranges::excerpt_debug(&command, crate::ranges::EXCERPT_CHARS),
            reason,
        };
        if self.handle.control.post(message).is_err() {
            return Err(rejected(
                "the control queue is full or the component is dead".to_owned(),
            ));
        }
        self.handle.bell.ring_command();
        self.settle()?;
        let mut answered = false;
        while let Some(answer) = answers.take() {
            answered = true;
            if let Reply::Rejected(reason) = answer {
                return Err(rejected(reason));
            }
        }
        if answered {
            Ok(())
        } else {
            Err(rejected("no answer: the component is dead".to_owned()))
        }
    }

    /// Command a controllable state (`ready`, `running`, `suspended`, `dead`).
    pub fn set_state(&mut self, state: Controllable) -> Result<(), HarnessError> {
        self.command(Command::SetState(state))
    }

    /// Command `running`: the user automaton enters its initial state (or resumes).
    pub fn run(&mut self) -> Result<(), HarnessError> {
        self.set_state(Controllable::Running)
    }

    /// Command `suspended`.
    pub fn suspend(&mut self) -> Result<(), HarnessError> {
        self.set_state(Controllable::Suspended)
    }

    /// Set controllable variable `name` through the control port.
    pub fn set(&mut self, name: &str, value: Value) -> Result<(), HarnessError> {
        self.command(Command::Set(name.to_owned(), value))
    }

    /// A new configuration through the control port.
    pub fn configure(&mut self, configuration: Value) -> Result<(), HarnessError> {
        self.command(Command::Configure(configuration))
    }

    // -----------------------------------------------------------------------------
    // Inputs.

    fn feed(&self, port: &str) -> Result<&Feed, HarnessError> {
        self.spec
            .input_index(port)
            .and_then(|index| self.inputs.get(index))
            .ok_or_else(|| HarnessError::NoInput {
                component: self.name.clone(),
                port: port.to_owned(),
                known: names(self.spec.inputs.iter().map(|i| i.name)),
            })
    }

    fn typed<T: Packet>(&self, port: &str, input: &ErasedInput) -> Result<(), HarnessError> {
        if input.type_id == std::any::TypeId::of::<T>() {
            Ok(())
        } else {
            Err(HarnessError::WrongType {
                port: port.to_owned(),
                actual: input.type_name.to_owned(),
                requested: std::any::type_name::<T>().to_owned(),
            })
        }
    }

    /// The kind, packet type and feeder of input `port` for a packet of `T`.
    fn checked_feed<T: Packet>(&self, port: &str) -> Result<&Feed, HarnessError> {
        let feed = self.feed(port)?;
        if feed.input.kind == InKind::Tick {
            return Err(HarnessError::WrongKind {
                port: port.to_owned(),
                kind: feed.input.kind.name(),
                wanted: "a tick input takes events (tick), not packets",
            });
        }
        self.typed::<T>(port, &feed.input)?;
        Ok(feed)
    }

    /// A packet arrives at input `port` (fifo, ufifo, last: sent; poster: posted), as
    /// from a producer. It is handled at the next [`Harness::settle`] or
    /// [`Harness::advance`].
    pub fn push<T: Packet>(&mut self, port: &str, packet: T) -> Result<(), HarnessError> {
        let feed = self.checked_feed::<T>(port)?;
        send_through::<T>(&feed.feeder, packet);
        Ok(())
    }

    /// A value posted for poster input `port` (the same as [`Harness::push`]).
    pub fn post<T: Packet>(&mut self, port: &str, packet: T) -> Result<(), HarnessError> {
        self.push(port, packet)
    }

    /// An event arrives at tick input `port`.
    pub fn tick(&mut self, port: &str) -> Result<(), HarnessError> {
        let feed = self.feed(port)?;
        match crate::port::tick_out(&feed.feeder) {
            Some(out) => {
                out.emit();
                Ok(())
            }
            None => Err(HarnessError::WrongKind {
                port: port.to_owned(),
                kind: feed.input.kind.name(),
                wanted: "only a tick input takes events (data inputs: push)",
            }),
        }
    }

    /// Queue `packet` as the answer to the next pull request the component makes on
    /// input `port` (declared `pull`); answers go out one per request, in order.
    pub fn answer<T: Packet>(&mut self, port: &str, packet: T) -> Result<(), HarnessError> {
        let feed = self.checked_feed::<T>(port)?;
        let feeder = feed.feeder.clone();
        self.queue_answer(port, Box::new(move || send_through::<T>(&feeder, packet)))
    }

    /// Queue an event as the answer to the next pull request on tick input `port`.
    pub fn answer_tick(&mut self, port: &str) -> Result<(), HarnessError> {
        let feed = self.feed(port)?;
        let Some(out) = crate::port::tick_out(&feed.feeder) else {
            return Err(HarnessError::WrongKind {
                port: port.to_owned(),
                kind: feed.input.kind.name(),
                wanted: "answer_tick answers tick inputs (data inputs: answer)",
            });
        };
        self.queue_answer(port, Box::new(move || out.emit()))
    }

    fn queue_answer(
        &mut self,
        port: &str,
        send: Box<dyn FnOnce() + Send>,
    ) -> Result<(), HarnessError> {
        let index = self.spec.input_index(port).unwrap_or_default();
        if !self.spec.inputs[index].pull {
            return Err(HarnessError::WrongKind {
                port: port.to_owned(),
                kind: self.inputs[index].input.kind.name(),
                wanted: "only an input declared `pull` makes pull requests",
            });
        }
        self.inputs[index]
            .answers
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push_back(send);
        Ok(())
    }

    // -----------------------------------------------------------------------------
    // Outputs.

    fn probe(&self, port: &str) -> Result<&Probe, HarnessError> {
        self.spec
            .output_index(port)
            .and_then(|index| self.outputs.get(index))
            .ok_or_else(|| HarnessError::NoOutput {
                component: self.name.clone(),
                port: port.to_owned(),
                known: names(self.spec.outputs.iter().map(|o| o.name)),
            })
    }

    /// The packets data output `port` sent (or poster output `port` posted) since
    /// the last call, in order.
    pub fn take_sent<T: Packet>(&mut self, port: &str) -> Result<Vec<T>, HarnessError> {
        let probe = self.probe(port)?;
        match Arc::clone(&probe.collector).downcast::<Collected<T>>() {
            Ok(collected) => Ok(collected.take()),
            Err(_) if probe.output.kind == OutKind::Tick => Err(HarnessError::WrongKind {
                port: port.to_owned(),
                kind: probe.output.kind.name(),
                wanted: "a tick output sends events (take_ticks)",
            }),
            Err(_) => Err(HarnessError::WrongType {
                port: port.to_owned(),
                actual: probe.output.type_name.to_owned(),
                requested: std::any::type_name::<T>().to_owned(),
            }),
        }
    }

    /// The events tick output `port` emitted since the last call.
    pub fn take_ticks(&mut self, port: &str) -> Result<u64, HarnessError> {
        let probe = self.probe(port)?;
        match probe.collector.downcast_ref::<TickIn>() {
            Some(ticks) => Ok(ticks.take()),
            None => Err(HarnessError::WrongKind {
                port: port.to_owned(),
                kind: probe.output.kind.name(),
                wanted: "only a tick output emits events (take_sent)",
            }),
        }
    }

    /// The value poster output `port` holds now.
    pub fn posted<T: Packet>(&self, port: &str) -> Result<Option<T>, HarnessError> {
        let probe = self.probe(port)?;
        match crate::port::poster_out::<T>(&probe.output) {
            Some(out) => Ok(out.posted()),
            None if probe.output.kind != OutKind::Poster => Err(HarnessError::WrongKind {
                port: port.to_owned(),
                kind: probe.output.kind.name(),
                wanted: "only a poster output holds a value (take_sent)",
            }),
            None => Err(HarnessError::WrongType {
                port: port.to_owned(),
                actual: probe.output.type_name.to_owned(),
                requested: std::any::type_name::<T>().to_owned(),
            }),
        }
    }

    /// Ask `pull` output `port` for a packet, as a consumer's pull would, and settle:
    /// the answer is then in [`Harness::take_sent`] (or [`Harness::take_ticks`]).
    pub fn pull(&mut self, port: &str) -> Result<(), HarnessError> {
        let probe = self.probe(port)?;
        crate::port::request_on_behalf(&probe.output, probe.id).map_err(|source| {
            HarnessError::Pull {
                port: port.to_owned(),
                source,
            }
        })?;
        self.settle()
    }

    // -----------------------------------------------------------------------------
    // What the component shows.

    /// Its monitoring port's snapshot: state, user state, result, error, variables,
    /// quality, period, counters.
    pub fn monitor(&self) -> Monitor {
        self.handle.snapshot()
    }

    /// The default automaton's state.
    pub fn state(&self) -> State {
        self.monitor().state
    }

    /// The user automaton's state, while it has one.
    pub fn user_state(&self) -> Option<String> {
        self.monitor().user_state
    }

    /// The task result.
    pub fn result(&self) -> TaskResult {
        self.monitor().result
    }

    /// The last error.
    pub fn error(&self) -> Option<String> {
        self.monitor().error
    }

    /// The quality level (0 = best).
    pub fn quality(&self) -> usize {
        self.monitor().quality
    }

    /// Observable or controllable variable `name`, as the monitoring port shows it.
    pub fn variable(&self, name: &str) -> Option<Value> {
        self.monitor()
            .variables
            .into_iter()
            .find(|(variable, _)| variable == name)
            .map(|(_, value)| value)
    }

    /// The component's code (generated glue) as `A`, if it is one: the typed
    /// wrappers read variables, configuration and behaviour through it.
    pub fn automaton<A: Any>(&self) -> Option<&A> {
        self.runner.automaton().downcast_ref::<A>()
    }

    /// [`Harness::automaton`], mutable.
    pub fn automaton_mut<A: Any>(&mut self) -> Option<&mut A> {
        self.runner.automaton_mut().downcast_mut::<A>()
    }

    /// The component's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The component's static shape.
    pub fn spec(&self) -> &'static Spec {
        self.spec
    }

    /// The time on the harness's clock now (for comparing with times the component
    /// saw: `Context` readings come from the same clock).
    pub fn now(&self) -> Instant {
        self.clock.now()
    }
}

/// Answers still queued hold their feeder, whose pull route holds the queue: dropped
/// here, so no cycle outlives the harness.
impl Drop for Harness {
    fn drop(&mut self) {
        for feed in &self.inputs {
            feed.answers
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .clear();
        }
    }
}

/// Send (data) or post (poster) `packet` through `feeder`, an output of `T` the
/// harness made for an input of `T`.
fn send_through<T: Packet>(feeder: &ErasedOutput, packet: T) {
    if let Some(out) = crate::port::data_out::<T>(feeder) {
        out.send(packet);
    } else if let Some(out) = crate::port::poster_out::<T>(feeder) {
        out.post(packet);
    }
}
