//! A component without an `automaton` (the language allows at most one): it goes to
//! `running` with no user state, and there it answers pull requests, on its thread in
//! a system and on the caller's thread in its harness.

use std::time::Duration;

use coolbot::crossbeam_channel::{self, Sender};
use coolbot::port::LastIn;
use coolbot::{Command, Controllable, State, System};
use coolbot_runtime_tests::generated::counter::{self, Behavior, Cx, Harness};
use coolbot_runtime_tests::generated::puller;
use coolbot_runtime_tests::support::WAIT;

/// Answers 10, 20, 30, ... and counts the pulls.
struct Counting;

impl Behavior for Counting {
    fn answer_next(&mut self, cx: &mut Cx<'_>) -> Result<u64, coolbot::Fault> {
        cx.vars.asked += 1;
        Ok(cx.vars.asked * 10)
    }
}

/// Hands the puller's input to the test when it starts.
struct Hand(Sender<LastIn<u64>>);

impl puller::Behavior for Hand {
    fn start(&mut self, cx: &mut puller::Cx<'_>) -> coolbot::SectionResult {
        let _ = self.0.send(cx.inputs.next.clone());
        Ok(())
    }
}

#[test]
fn without_an_automaton_it_runs_with_no_user_state_and_answers_pulls() {
    let mut system = System::new();
    let handle = system
        .add(counter::component("c", Counting))
        .expect("a spec without states is accepted");
    let (hand, input) = crossbeam_channel::bounded(1);
    let puller = system.add(puller::component("p", Hand(hand))).expect("add");
    system.connect("c.next", "p.next").expect("connect");
    system.start().expect("start");
    for component in [&handle, &puller] {
        component
            .command(Command::SetState(Controllable::Running))
            .expect("running");
        let monitor = component.wait_state(State::Running, WAIT).expect("running");
        assert_eq!(monitor.user_state, None);
    }
    let input = input.recv_timeout(WAIT).expect("the puller started");
    for expected in [10, 20, 30] {
        assert_eq!(input.pull(WAIT), Ok(expected));
    }
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

#[test]
fn its_harness_answers_pulls_without_a_thread() {
    let mut harness = Harness::running(Counting).expect("harness");
    assert_eq!(harness.state(), State::Running);
    assert_eq!(harness.user_state(), None);
    harness.pull_next().expect("pull");
    harness.pull_next().expect("pull");
    assert_eq!(harness.sent_next().expect("sent"), [10, 20]);
    assert_eq!(harness.vars().asked, 2);
    harness.advance(Duration::from_secs(1)).expect("advance");
    assert_eq!(harness.state(), State::Running);
}

/// Fails every pull.
struct Refusing;

impl Behavior for Refusing {
    fn answer_next(&mut self, _cx: &mut Cx<'_>) -> Result<u64, coolbot::Fault> {
        Err(coolbot::Fault::message("no count"))
    }
}

#[test]
fn a_failed_answer_takes_it_to_running_error() {
    // No user state to name: the error names the port and the fault.
    let mut harness = Harness::running(Refusing).expect("harness");
    let _ = harness.pull_next();
    assert_eq!(harness.state(), State::RunningError);
    let error = harness.error().expect("an error");
    assert!(
        error.contains("answering a pull request on `next`") && error.contains("no count"),
        "{error}"
    );
}
