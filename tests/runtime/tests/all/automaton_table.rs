//! Every (state, command) pair of the default automaton, driven by the table itself:
//! a worker is brought into each state, given each command, and must end where
//! `coolbot::table::next` says, having run exactly the table's actions.

use std::sync::atomic::Ordering;
use std::time::Duration;

use coolbot::table::{Action, Event, Outcome, next};
use coolbot::{Controllable, State};
use coolbot_runtime_tests::support::{Rig, Script, WAIT, eventually};

/// Bring a fresh worker into `state`; the user automaton is in `busy` for `running`
/// and `suspended`.
fn bring(state: State) -> Rig {
    let script = Script::new();
    match state {
        State::Starting => unreachable!("starting is tested with a gated start hook"),
        State::Ready => Rig::started(script),
        State::Running | State::Suspended | State::RunningError | State::End => {
            let rig = Rig::started(script);
            rig.run_busy();
            match state {
                State::Suspended => rig.command(Controllable::Suspended).expect("suspend"),
                State::RunningError => {
                    rig.script.panic_in(Some("busy.periodic"));
                    rig.wait_state(State::RunningError);
                    // The watchdog may show `running_error` while the panicking
                    // section still unwinds (slowly, under load: past the worker's
                    // `max_response`); the fault's `stop` runs after it.
                    eventually(
                        || rig.script.log().iter().any(|hook| hook == "stop"),
                        "the fault's stop runs",
                    );
                    rig.script.panic_in(None);
                }
                State::End => {
                    rig.script.end_in_periodic.store(true, Ordering::SeqCst);
                    rig.wait_state(State::End);
                    rig.script.end_in_periodic.store(false, Ordering::SeqCst);
                }
                _ => {}
            }
            rig
        }
        State::Dead => {
            let rig = Rig::started(script);
            rig.command(Controllable::Dead).expect("dead");
            rig
        }
        State::StartingError => {
            script.start_fails.store(true, Ordering::SeqCst);
            let rig = Rig::started(script);
            rig.wait_state(State::StartingError);
            rig.script.start_fails.store(false, Ordering::SeqCst);
            rig
        }
    }
}

/// The hook log the table's actions must produce, for a fixture whose user automaton
/// is in `busy` (entered) or not entered at all.
fn expected_log(actions: &[Action], busy_entered: bool) -> Vec<String> {
    let mut log = Vec::new();
    for action in actions {
        match action {
            Action::Start => log.push("start"),
            Action::Stop => log.push("stop"),
            Action::EnterUser => log.push("idle.entry"),
            Action::ExitUser if busy_entered => log.push("busy.exit"),
            Action::ResumeUser if !busy_entered => log.push("idle.entry"),
            Action::ExitUser | Action::ResetUser | Action::ResumeUser => {}
        }
    }
    log.into_iter().map(str::to_owned).collect()
}

fn check(state: State, command: Controllable) {
    let rig = bring(state);
    assert_eq!(rig.handle.state(), state, "fixture for {state}");
    rig.script.clear_log();
    let outcome = next(state, Event::Command(command));
    let answer = rig.command(command);
    let context = format!("{state} + c:{}", command.state());
    match outcome {
        Outcome::Go { to, actions } => {
            answer.unwrap_or_else(|e| panic!("{context}: rejected: {e}"));
            let monitor = rig.wait_state(to);
            let busy_entered = matches!(state, State::Running | State::Suspended);
            assert_eq!(
                rig.script.log(),
                expected_log(actions, busy_entered),
                "{context}: hooks run"
            );
            // `error` is kept until a `start` succeeds again.
            let had_error = matches!(state, State::StartingError | State::RunningError);
            let keeps_error = had_error && !actions.contains(&Action::Start);
            assert_eq!(
                monitor.error.is_some(),
                keeps_error,
                "{context}: error {:?}",
                monitor.error
            );
            if to == State::Ready {
                assert_eq!(
                    monitor.user_state, None,
                    "{context}: no user state in ready"
                );
            }
            if to == State::Running {
                assert_eq!(
                    monitor.user_state.as_deref(),
                    Some(if state == State::Suspended {
                        "busy"
                    } else {
                        "idle"
                    })
                );
            }
        }
        Outcome::Stay => {
            answer.unwrap_or_else(|e| panic!("{context}: rejected: {e}"));
            assert_eq!(rig.handle.state(), state, "{context}: stays");
            assert_eq!(
                rig.script.log(),
                Vec::<String>::new(),
                "{context}: nothing runs"
            );
        }
        Outcome::Reject(reason) => {
            let rejected = answer.expect_err(&context);
            assert!(!reason.is_empty());
            assert!(
                rejected.to_string().contains(&rig.handle.name().to_owned()),
                "{rejected}"
            );
            assert_eq!(rig.handle.state(), state, "{context}: stays");
        }
        Outcome::Defer | Outcome::Impossible => {
            panic!("{context}: the table gives {outcome:?} for a command")
        }
    }
}

macro_rules! pairs {
    ($($name:ident: $state:ident, $command:ident;)*) => {$(
        #[test]
        fn $name() {
            check(State::$state, Controllable::$command);
        }
    )*};
}

pairs! {
    ready_ready: Ready, Ready;
    ready_running: Ready, Running;
    ready_suspended: Ready, Suspended;
    ready_dead: Ready, Dead;
    running_ready: Running, Ready;
    running_running: Running, Running;
    running_suspended: Running, Suspended;
    running_dead: Running, Dead;
    suspended_ready: Suspended, Ready;
    suspended_running: Suspended, Running;
    suspended_suspended: Suspended, Suspended;
    suspended_dead: Suspended, Dead;
    dead_ready: Dead, Ready;
    dead_running: Dead, Running;
    dead_suspended: Dead, Suspended;
    dead_dead: Dead, Dead;
    starting_error_ready: StartingError, Ready;
    starting_error_running: StartingError, Running;
    starting_error_suspended: StartingError, Suspended;
    starting_error_dead: StartingError, Dead;
    running_error_ready: RunningError, Ready;
    running_error_running: RunningError, Running;
    running_error_suspended: RunningError, Suspended;
    running_error_dead: RunningError, Dead;
    end_ready: End, Ready;
    end_running: End, Running;
    end_suspended: End, Suspended;
    end_dead: End, Dead;
}

/// The pairs above cover the table: every state but `starting` and every command.
#[test]
fn the_pairs_cover_every_state_and_command() {
    let tested = [
        State::Ready,
        State::Running,
        State::Suspended,
        State::Dead,
        State::StartingError,
        State::RunningError,
        State::End,
    ];
    for state in State::ALL {
        assert!(
            tested.contains(&state) || state == State::Starting,
            "{state} untested"
        );
        for command in Controllable::ALL {
            let outcome = next(state, Event::Command(command));
            assert_ne!(outcome, Outcome::Impossible, "{state} + {command:?}");
        }
    }
}

/// `starting`: a command sent while `start` runs is deferred, then applied in the
/// state `start` led to.
fn check_starting(command: Controllable) {
    assert_eq!(
        next(State::Starting, Event::Command(command)),
        Outcome::Defer
    );
    let script = Script::new();
    let (open, gate) = coolbot::crossbeam_channel::bounded(1);
    *script.start_gate.lock().unwrap() = Some(gate);
    let mut rig = Rig::unstarted(script);
    rig.system.start().expect("start");
    // The start hook's log is not on the monitor (nothing is announced while the hook
    // waits at its gate), so `wait_for` cannot be woken by it: poll the log.
    let waiting_since = std::time::Instant::now();
    while !rig.script.log.lock().unwrap().contains(&"start".to_owned()) {
        assert!(waiting_since.elapsed() < WAIT, "start hook entered");
        std::thread::sleep(Duration::from_millis(1));
    }
    assert_eq!(rig.handle.state(), State::Starting);
    let handle = rig.handle.clone();
    let sender = std::thread::spawn(move || handle.command(coolbot::Command::SetState(command)));
    // Give the command time to be queued behind the start hook; if it is late, it
    // still meets the state `start` led to, which is what is asserted.
    std::thread::sleep(Duration::from_millis(20));
    open.send(()).expect("open the gate");
    let answer = sender.join().expect("sender thread");
    let after_start = next(State::Starting, Event::StartOk).target(State::Starting);
    let expected = next(after_start, Event::Command(command)).target(after_start);
    answer.expect("accepted after start");
    rig.wait_state(expected);
}

#[test]
fn starting_ready() {
    check_starting(Controllable::Ready);
}

#[test]
fn starting_running() {
    check_starting(Controllable::Running);
}

#[test]
fn starting_suspended() {
    check_starting(Controllable::Suspended);
}

#[test]
fn starting_dead() {
    check_starting(Controllable::Dead);
}

#[test]
fn internal_events_only_happen_where_the_table_allows() {
    for state in State::ALL {
        for event in [Event::StartOk, Event::StartFailed] {
            assert_eq!(
                next(state, event) == Outcome::Impossible,
                state != State::Starting,
                "{state} + {event}"
            );
        }
        for event in [Event::Fault, Event::Finished] {
            assert_eq!(
                next(state, event) == Outcome::Impossible,
                state != State::Running,
                "{state} + {event}"
            );
        }
    }
}

#[test]
fn every_controllable_state_is_reachable_from_every_live_state_in_one_command() {
    for state in State::ALL {
        if state == State::Dead || state == State::Starting {
            continue;
        }
        for command in Controllable::ALL {
            let target = next(state, Event::Command(command)).target(state);
            assert_eq!(target, command.state(), "{state} + c:{}", command.state());
        }
    }
}
