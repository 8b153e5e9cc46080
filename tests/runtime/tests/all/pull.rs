//! The pull model: the consumer's request and the producer's answer (two push paths),
//! round trips, answers going to the requester only, and timeouts. The components are
//! generated (`cool/pull.cool`); the consumers hand their inputs to the test, which
//! pulls from its own thread. (A tick input pulling from a tick output, which coolc
//! refuses to declare `pull`, is in `runtime/tests/invalid_specs.rs`.)

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use coolbot::crossbeam_channel::{self, Receiver, Sender};
use coolbot::port::{FifoIn, LastIn, PosterIn};
use coolbot::{
    Command, ConnectError, Controllable, Fault, Handle, PullError, SectionResult, State, System,
};
use coolbot_runtime_tests::generated::{
    pull_goal, pull_kinds, pull_late, pull_pair, pull_producer, pull_source,
};
use coolbot_runtime_tests::support::{WAIT, eventually};

/// Answers with a counter shared by its outputs: `value` (data), `post` (poster).
struct Counting(Arc<AtomicU64>);

impl Counting {
    fn next(&self) -> u64 {
        self.0.fetch_add(1, Ordering::SeqCst) + 1
    }
}

impl pull_producer::Behavior for Counting {
    fn answer_value(&mut self, _cx: &mut pull_producer::Cx<'_>) -> Result<u64, Fault> {
        Ok(self.next())
    }
    fn answer_post(&mut self, _cx: &mut pull_producer::Cx<'_>) -> Result<u64, Fault> {
        Ok(self.next())
    }
}

/// A consumer's behaviour: hands its inputs (cloned) to the test when it starts.
struct Hand<T>(Sender<T>);

impl pull_goal::Behavior for Hand<LastIn<u64>> {
    fn start(&mut self, cx: &mut pull_goal::Cx<'_>) -> SectionResult {
        let _ = self.0.send(cx.inputs.goal.clone());
        Ok(())
    }
}

impl pull_late::Behavior for Hand<LastIn<u64>> {
    fn start(&mut self, cx: &mut pull_late::Cx<'_>) -> SectionResult {
        let _ = self.0.send(cx.inputs.late.clone());
        Ok(())
    }
}

impl pull_pair::Behavior for Hand<(LastIn<u64>, LastIn<u64>)> {
    fn start(&mut self, cx: &mut pull_pair::Cx<'_>) -> SectionResult {
        let _ = self.0.send((cx.inputs.a.clone(), cx.inputs.b.clone()));
        Ok(())
    }
}

/// `PullKinds`'s inputs.
type Kinds = (FifoIn<u64>, PosterIn<u64>);

impl pull_kinds::Behavior for Hand<Kinds> {
    fn start(&mut self, cx: &mut pull_kinds::Cx<'_>) -> SectionResult {
        let inputs = &cx.inputs;
        let _ = self.0.send((inputs.q.clone(), inputs.r.clone()));
        Ok(())
    }
}

/// A hand and the receiver its inputs arrive on.
fn hand<T>() -> (Hand<T>, Receiver<T>) {
    let (sender, receiver) = crossbeam_channel::bounded(1);
    (Hand(sender), receiver)
}

/// The inputs a consumer handed over once the system started.
fn handed<T>(receiver: &Receiver<T>) -> T {
    receiver
        .recv_timeout(WAIT)
        .expect("the consumer hands its inputs over when it starts")
}

/// An answer that always fails.
struct Unplugged;

impl pull_source::Behavior for Unplugged {
    fn answer_value(&mut self, _cx: &mut pull_source::Cx<'_>) -> Result<u64, Fault> {
        Err(Fault::message("sensor unplugged"))
    }
}

/// An answer that first commands its own component (through its handle, installed
/// once added) and records the reply, then answers 1.
struct CommandsItself {
    own: Arc<Mutex<Option<Handle>>>,
    answers: Arc<Mutex<Vec<Result<(), String>>>>,
}

impl pull_source::Behavior for CommandsItself {
    fn answer_value(&mut self, _cx: &mut pull_source::Cx<'_>) -> Result<u64, Fault> {
        let handle = self.own.lock().unwrap().clone().expect("handle installed");
        let answer = handle.command(Command::SetState(Controllable::Ready));
        self.answers
            .lock()
            .unwrap()
            .push(answer.map_err(|e| e.reason));
        Ok(1)
    }
}

/// A producer `p` whose pull outputs answer with a counter: `value` (data), `post`
/// (poster); `plain` is not `pull`.
struct Producer {
    system: System,
    answers: Arc<AtomicU64>,
}

/// The producer and `consumer` (named `c`), running.
fn producer(consumer: coolbot::Component) -> Producer {
    let answers = Arc::new(AtomicU64::new(0));
    let mut system = System::new();
    system
        .add(pull_producer::component(
            "p",
            Counting(Arc::clone(&answers)),
        ))
        .expect("add p");
    system.add(consumer).expect("add consumer");
    system.run_all().expect("run");
    Producer { system, answers }
}

#[test]
fn a_last_input_pulls_round_trips() {
    let (hand, goal) = hand();
    let mut p = producer(pull_goal::component("c", hand));
    let goal = handed(&goal);
    assert_eq!(
        goal.pull(Duration::from_millis(1)),
        Err(PullError::NotConnected)
    );
    p.system.connect("p.value", "c.goal").expect("connect");
    assert_eq!(goal.pull(WAIT), Ok(1));
    assert_eq!(goal.pull(WAIT), Ok(2));
    assert_eq!(goal.latest(), Some(2));
    assert_eq!(p.answers.load(Ordering::SeqCst), 2);
}

#[test]
fn the_answer_goes_to_the_requester_only() {
    let (hand, inputs) = hand();
    let mut p = producer(pull_pair::component("c", hand));
    let (a, b) = handed(&inputs);
    p.system.connect("p.value", "c.a").expect("a");
    p.system.connect("p.value", "c.b").expect("b");
    assert_eq!(a.pull(WAIT), Ok(1));
    assert_eq!(b.take_new(), None, "b did not ask");
    assert_eq!(b.pull(WAIT), Ok(2));
    assert_eq!(a.take_new(), None, "a did not ask again");
}

#[test]
fn fifo_poster_and_tick_inputs_pull_too() {
    let (hand, inputs) = hand::<Kinds>();
    let mut p = producer(pull_kinds::component("c", hand));
    let (q, r) = handed(&inputs);
    p.system.connect("p.value", "c.q").expect("q");
    p.system.connect("p.post", "c.r").expect("r");
    assert_eq!(q.pull(WAIT), Ok(1));
    assert_eq!(r.pull(WAIT), Ok(2));
    // (The tick input's pull: `runtime/tests/invalid_specs.rs`; the counter's third
    // answer is now the fifo's.)
    // `request` alone: the answer arrives as a normal packet.
    q.request().expect("request");
    eventually(|| !q.is_empty(), "answer queued");
    assert_eq!(q.recv(), Some(3));
}

#[test]
fn a_pull_times_out_while_the_producer_does_not_run_and_is_answered_later() {
    let (hand, goal) = hand();
    let mut p = producer(pull_goal::component("c", hand));
    let goal = handed(&goal);
    p.system.connect("p.value", "c.goal").expect("connect");
    let producer = p.system.handle("p").unwrap();
    producer
        .command(Command::SetState(Controllable::Suspended))
        .expect("suspend");
    assert_eq!(
        goal.pull(Duration::from_millis(20)),
        Err(PullError::Timeout(Duration::from_millis(20)))
    );
    assert_eq!(
        p.answers.load(Ordering::SeqCst),
        0,
        "no answer while suspended"
    );
    // The request waited at the producer: running again answers it.
    producer
        .command(Command::SetState(Controllable::Running))
        .expect("resume");
    eventually(|| goal.latest() == Some(1), "late answer");
    assert_eq!(producer.state(), State::Running);
}

#[test]
fn a_pull_input_needs_a_pull_output() {
    let (hand, _goal) = hand::<LastIn<u64>>();
    let mut p = producer(pull_goal::component("c", hand));
    let err = p.system.connect("p.plain", "c.goal").unwrap_err();
    assert_eq!(
        err,
        ConnectError::PullMismatch {
            from: "p.plain".to_owned(),
            to: "c.goal".to_owned()
        }
    );
    assert_eq!(
        err.to_string(),
        "cannot connect `p.plain` to pull input `c.goal`: `p.plain` is not declared `pull`"
    );
}

#[test]
fn a_failing_answer_takes_the_producer_to_running_error() {
    // A producer whose answer always fails (an undeclared fault).
    let mut system = System::new();
    system
        .add(pull_source::component("p", Unplugged))
        .expect("p");
    let (hand, late) = hand();
    system.add(pull_late::component("c", hand)).expect("c");
    system.run_all().expect("run");
    let late = handed(&late);
    system.connect("p.value", "c.late").expect("connect");
    assert_eq!(
        late.pull(Duration::from_millis(50)),
        Err(PullError::Timeout(Duration::from_millis(50)))
    );
    let producer = system.handle("p").unwrap();
    let monitor = producer
        .wait_state(State::RunningError, WAIT)
        .expect("running_error");
    let error = monitor.error.expect("error");
    assert!(
        error.contains("answering a pull request on `value`") && error.contains("sensor unplugged"),
        "{error}"
    );
    assert_eq!(
        system.handle("c").unwrap().state(),
        State::Running,
        "the consumer goes on"
    );
}

#[test]
fn a_component_commanding_itself_is_refused_at_once() {
    let own: Arc<Mutex<Option<Handle>>> = Arc::default();
    let answers = Arc::new(Mutex::new(Vec::new()));
    let commanding = CommandsItself {
        own: Arc::clone(&own),
        answers: Arc::clone(&answers),
    };
    let mut system = System::new();
    let handle = system
        .add(pull_source::component("p", commanding))
        .expect("p");
    *own.lock().unwrap() = Some(handle.clone());
    let (hand, goal) = hand();
    system.add(pull_goal::component("c", hand)).expect("c");
    system.run_all().expect("run");
    let goal = handed(&goal);
    system.connect("p.value", "c.goal").expect("connect");
    assert_eq!(goal.pull(WAIT), Ok(1));
    assert_eq!(
        *answers.lock().unwrap(),
        vec![Err(
            "a component cannot command itself from its own thread (use Context::end to finish)"
                .to_owned()
        )]
    );
    assert_eq!(handle.state(), State::Running);
}
