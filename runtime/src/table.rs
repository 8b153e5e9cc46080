//! The default automaton (paper 3.1, Figure 2) as one transition table.
//!
//! [`next`] is the whole table: every `(state, event)` pair has exactly one
//! [`Outcome`]. The runner in `runner.rs` only executes outcomes; it never decides a
//! transition on its own. `docs/runtime.md` prints the same table for users, and the
//! tests enumerate [`State::ALL`] x [`Event::ALL`] against it.

use std::fmt;

use serde::{Deserialize, Serialize};

/// The states of the default automaton.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum State {
    /// The thread runs the `start` hook.
    Starting,
    /// Started and idle: no user section runs.
    Ready,
    /// The user automaton runs.
    Running,
    /// The user automaton is frozen in its current state: no user section runs.
    Suspended,
    /// Finished for good: the thread has ended (or is ending).
    Dead,
    /// The `start` hook failed.
    StartingError,
    /// A user section failed with no continuity plan left.
    RunningError,
    /// The task finished (`Context::end`).
    End,
}

impl State {
    /// Every state, in the order of the paper.
    pub const ALL: [State; 8] = [
        State::Starting,
        State::Ready,
        State::Running,
        State::Suspended,
        State::Dead,
        State::StartingError,
        State::RunningError,
        State::End,
    ];

    /// The paper's name: `starting`, `ready`, `running`, `suspended`, `dead`,
    /// `starting_error`, `running_error`, `end`.
    pub fn name(self) -> &'static str {
        match self {
            State::Starting => "starting",
            State::Ready => "ready",
            State::Running => "running",
            State::Suspended => "suspended",
            State::Dead => "dead",
            State::StartingError => "starting_error",
            State::RunningError => "running_error",
            State::End => "end",
        }
    }

    /// Whether the state can be forced through the control port.
    pub fn is_controllable(self) -> bool {
        matches!(
            self,
            State::Ready | State::Running | State::Suspended | State::Dead
        )
    }

    /// Whether `start` has succeeded and `stop` has not run yet in this state.
    pub fn is_started(self) -> bool {
        matches!(self, State::Ready | State::Running | State::Suspended)
    }
}

impl fmt::Display for State {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The states that can be forced through the control port (the default controllable
/// variable `new_state`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Controllable {
    /// Go to `ready`.
    Ready,
    /// Go to `running`.
    Running,
    /// Go to `suspended`.
    Suspended,
    /// Go to `dead`.
    Dead,
}

impl Controllable {
    /// Every controllable state.
    pub const ALL: [Controllable; 4] = [
        Controllable::Ready,
        Controllable::Running,
        Controllable::Suspended,
        Controllable::Dead,
    ];

    /// The default automaton state this command names.
    pub fn state(self) -> State {
        match self {
            Controllable::Ready => State::Ready,
            Controllable::Running => State::Running,
            Controllable::Suspended => State::Suspended,
            Controllable::Dead => State::Dead,
        }
    }

    /// The command as written for people (`ready`, `run`, `suspend`, `dead`), as
    /// supervision steps name it.
    pub fn verb(self) -> &'static str {
        match self {
            Controllable::Ready => "ready",
            Controllable::Running => "run",
            Controllable::Suspended => "suspend",
            Controllable::Dead => "dead",
        }
    }
}

/// What can happen to the default automaton.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Event {
    /// A `new_state` command through the control port.
    Command(Controllable),
    /// The `start` hook returned `Ok`.
    StartOk,
    /// The `start` hook returned `Err` or panicked.
    StartFailed,
    /// A user section (or `choose`, `answer`) failed with no continuity plan left, or
    /// panicked.
    Fault,
    /// User code called `Context::end`.
    Finished,
}

impl Event {
    /// Every event.
    pub const ALL: [Event; 8] = [
        Event::Command(Controllable::Ready),
        Event::Command(Controllable::Running),
        Event::Command(Controllable::Suspended),
        Event::Command(Controllable::Dead),
        Event::StartOk,
        Event::StartFailed,
        Event::Fault,
        Event::Finished,
    ];
}

impl fmt::Display for Event {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Event::Command(target) => write!(f, "c:{}", target.state()),
            Event::StartOk => f.write_str("start ok"),
            Event::StartFailed => f.write_str("start failed"),
            Event::Fault => f.write_str("fault"),
            Event::Finished => f.write_str("finished"),
        }
    }
}

/// The steps a transition runs, in order, on the component's thread.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Action {
    /// Enter `starting` and run the `start` hook; if it fails the transition ends in
    /// `starting_error` instead of its target.
    Start,
    /// Run the `stop` hook (a panic in it is recorded in `error`; the transition goes on).
    Stop,
    /// Reset the user automaton to its initial state and run that state's entry section.
    EnterUser,
    /// Run the exit section of the current user state (if the user automaton was
    /// entered).
    ExitUser,
    /// Reset the user automaton to its initial state without running any section: the
    /// entry runs when the component is next set running.
    ResetUser,
    /// Continue the user automaton where it was frozen; if it was reset and never
    /// entered, run the initial state's entry section.
    ResumeUser,
}

/// The outcome of one `(state, event)` pair.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Outcome {
    /// Run `actions` in order, then be in `to`. A failing user section on the way ends
    /// the transition in `running_error` (or in `dead` if `to` is `dead`); a failing
    /// `start` in `starting_error`.
    Go {
        /// The target state.
        to: State,
        /// The steps, in order.
        actions: &'static [Action],
    },
    /// Accepted; the component is already there and nothing runs.
    Stay,
    /// The command is held until the state changes (only in `starting`, while the
    /// `start` hook runs) and then looked up again.
    Defer,
    /// The command is rejected with this reason.
    Reject(&'static str),
    /// The event cannot happen in this state (an internal event of another state).
    Impossible,
}

impl Outcome {
    /// The state the automaton is in after the outcome, if every action succeeds.
    pub fn target(self, from: State) -> State {
        match self {
            Outcome::Go { to, .. } => to,
            Outcome::Stay | Outcome::Defer | Outcome::Reject(_) | Outcome::Impossible => from,
        }
    }
}

/// Shorthand for the table below.
const fn go(to: State, actions: &'static [Action]) -> Outcome {
    Outcome::Go { to, actions }
}

/// The default automaton: the outcome of `event` in `state`.
pub fn next(state: State, event: Event) -> Outcome {
    use Action::*;
    use Controllable as C;
    use Event::{Command, Fault, Finished, StartFailed, StartOk};

    match (state, event) {
        // starting: the thread is inside the `start` hook; commands wait for it.
        (State::Starting, StartOk) => go(State::Ready, &[]),
        (State::Starting, StartFailed) => go(State::StartingError, &[]),
        (State::Starting, Command(_)) => Outcome::Defer,

        // ready: started, idle.
        (State::Ready, Command(C::Ready)) => Outcome::Stay,
        (State::Ready, Command(C::Running)) => go(State::Running, &[EnterUser]),
        (State::Ready, Command(C::Suspended)) => go(State::Suspended, &[ResetUser]),
        (State::Ready, Command(C::Dead)) => go(State::Dead, &[Stop]),

        // running: the user automaton runs.
        (State::Running, Command(C::Ready)) => go(State::Ready, &[ExitUser]),
        (State::Running, Command(C::Running)) => Outcome::Stay,
        (State::Running, Command(C::Suspended)) => go(State::Suspended, &[]),
        (State::Running, Command(C::Dead)) => go(State::Dead, &[ExitUser, Stop]),
        (State::Running, Fault) => go(State::RunningError, &[Stop]),
        (State::Running, Finished) => go(State::End, &[ExitUser, Stop]),

        // suspended: the user automaton is frozen in its state.
        (State::Suspended, Command(C::Ready)) => go(State::Ready, &[ExitUser]),
        (State::Suspended, Command(C::Running)) => go(State::Running, &[ResumeUser]),
        (State::Suspended, Command(C::Suspended)) => Outcome::Stay,
        (State::Suspended, Command(C::Dead)) => go(State::Dead, &[ExitUser, Stop]),

        // starting_error: `start` failed and nothing is held; a command retries it.
        (State::StartingError, Command(C::Ready)) => go(State::Ready, &[Start]),
        (State::StartingError, Command(C::Running)) => go(State::Running, &[Start, EnterUser]),
        (State::StartingError, Command(C::Suspended)) => go(State::Suspended, &[Start, ResetUser]),
        (State::StartingError, Command(C::Dead)) => go(State::Dead, &[]),

        // running_error and end: `stop` already ran; a command restarts from `start`.
        (State::RunningError | State::End, Command(C::Ready)) => go(State::Ready, &[Start]),
        (State::RunningError | State::End, Command(C::Running)) => {
            go(State::Running, &[Start, EnterUser])
        }
        (State::RunningError | State::End, Command(C::Suspended)) => {
            go(State::Suspended, &[Start, ResetUser])
        }
        (State::RunningError | State::End, Command(C::Dead)) => go(State::Dead, &[]),

        // dead: final.
        (State::Dead, Command(_)) => Outcome::Reject("the component is dead: its thread has ended"),

        // Internal events of other states.
        (_, StartOk | StartFailed | Fault | Finished) => Outcome::Impossible,
    }
}
