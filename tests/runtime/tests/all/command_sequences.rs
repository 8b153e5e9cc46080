//! A property test: random sequences of control commands, kicks and crashes keep the
//! component in the state the transition table predicts, step after step.

use coolbot::table::{Event, next};
use coolbot::{Controllable, State};
use coolbot_runtime_tests::support::{Rig, Script, WAIT};
use proptest::prelude::*;

#[derive(Debug, Clone, Copy)]
enum Step {
    Command(Controllable),
    /// An event on `kick`: moves `idle` to `busy` if running.
    Kick,
    /// A panic in the next periodic section of `busy` (if running in busy).
    Crash,
    /// User code ends the task (if running in busy).
    Finish,
}

fn step() -> impl Strategy<Value = Step> {
    // `dead` ends a sequence, so it is drawn less often than the other commands.
    prop_oneof![
        3 => Just(Step::Command(Controllable::Ready)),
        4 => Just(Step::Command(Controllable::Running)),
        3 => Just(Step::Command(Controllable::Suspended)),
        1 => Just(Step::Command(Controllable::Dead)),
        4 => Just(Step::Kick),
        2 => Just(Step::Crash),
        2 => Just(Step::Finish),
    ]
}

fn run(steps: &[Step]) -> Result<(), TestCaseError> {
    let rig = Rig::started(Script::new());
    let mut model = State::Ready;
    prop_assert_eq!(rig.handle.state(), model);
    for step in steps {
        let monitor = rig.handle.snapshot();
        let in_busy =
            monitor.state == State::Running && monitor.user_state.as_deref() == Some("busy");
        match *step {
            Step::Command(command) => {
                let answer = rig.command(command);
                let expected = next(model, Event::Command(command)).target(model);
                prop_assert_eq!(
                    answer.is_ok(),
                    model != State::Dead,
                    "{:?} in {}",
                    command,
                    model
                );
                model = expected;
            }
            Step::Kick => {
                rig.feeder().kick.emit();
                if model == State::Running && !in_busy {
                    rig.wait_user("busy");
                }
            }
            Step::Crash if in_busy => {
                rig.script.panic_in(Some("busy.periodic"));
                rig.handle
                    .wait_state(State::RunningError, WAIT)
                    .map_err(|t| TestCaseError::fail(t.to_string()))?;
                rig.script.panic_in(None);
                model = next(model, Event::Fault).target(model);
            }
            Step::Finish if in_busy => {
                rig.script
                    .end_in_periodic
                    .store(true, std::sync::atomic::Ordering::SeqCst);
                rig.handle
                    .wait_state(State::End, WAIT)
                    .map_err(|t| TestCaseError::fail(t.to_string()))?;
                rig.script
                    .end_in_periodic
                    .store(false, std::sync::atomic::Ordering::SeqCst);
                model = next(model, Event::Finished).target(model);
            }
            Step::Crash | Step::Finish => {}
        }
        let state = rig.handle.state();
        prop_assert_eq!(state, model, "after {:?}", step);
        if state == State::Dead {
            break;
        }
        // In every state but running, an arrival runs nothing: after a round trip
        // through the control port (handled by the same thread), the log is empty.
        if state != State::Running {
            rig.script.clear_log();
            rig.feeder().kick.emit();
            rig.handle
                .command(coolbot::Command::SetPriority(0))
                .map_err(|e| TestCaseError::fail(e.to_string()))?;
            prop_assert_eq!(rig.script.log(), Vec::<String>::new(), "in {}", state);
            prop_assert_eq!(rig.handle.state(), model);
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn random_command_sequences_follow_the_table(steps in prop::collection::vec(step(), 1..16)) {
        run(&steps)?;
    }
}
