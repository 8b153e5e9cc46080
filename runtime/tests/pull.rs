//! The pull model: the consumer's request and the producer's answer (two push paths),
//! round trips, answers going to the requester only, and timeouts.

mod support;

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use coolbot::port::{DataOut, FifoIn, LastIn, PosterIn, PosterOut, TickIn, TickOut};
use coolbot::{
    Command, ConnectError, Controllable, Fault, InputKind, OutputKind, OverflowPolicy, PullError,
    State, System,
};
use support::shell::{ShellBuilder, input, output};
use support::{WAIT, eventually};

/// A producer `p` whose pull outputs answer with a counter: `value` (data),
/// `post` (poster), `tick` (tick); and its handle.
struct Producer {
    system: System,
    answers: Arc<AtomicU64>,
}

fn producer(extra_consumers: Vec<ShellBuilder>) -> Producer {
    let value = DataOut::<u64>::new();
    let post = PosterOut::<u64>::new();
    let tick = TickOut::new();
    let plain = DataOut::<u64>::new();
    let answers = Arc::new(AtomicU64::new(0));
    let shell = {
        let (value, post, tick, answers) = (
            value.clone(),
            post.clone(),
            tick.clone(),
            Arc::clone(&answers),
        );
        ShellBuilder::new("p")
            .output(output("value", OutputKind::Data, true), &value)
            .output(output("post", OutputKind::Poster, true), &post)
            .output(output("tick", OutputKind::Tick, true), &tick)
            .output(output("plain", OutputKind::Data, false), &plain)
            .answer(move |output| {
                let n = answers.fetch_add(1, Ordering::SeqCst) + 1;
                match output {
                    0 => value.send(n),
                    1 => post.post(n),
                    2 => tick.emit(),
                    _ => return Err(Fault::message("not a pull output")),
                }
                Ok(())
            })
    };
    let mut system = System::new();
    system.add(shell.build()).expect("add p");
    for consumer in extra_consumers {
        system.add(consumer.build()).expect("add consumer");
    }
    system.run_all().expect("run");
    Producer { system, answers }
}

#[test]
fn a_last_input_pulls_round_trips() {
    let goal = LastIn::<u64>::new();
    let mut p = producer(vec![
        ShellBuilder::new("c").input(input("goal", InputKind::Last, true), &goal),
    ]);
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
    let (a, b) = (LastIn::<u64>::new(), LastIn::<u64>::new());
    let mut p = producer(vec![
        ShellBuilder::new("c")
            .input(input("a", InputKind::Last, true), &a)
            .input(input("b", InputKind::Last, true), &b),
    ]);
    p.system.connect("p.value", "c.a").expect("a");
    p.system.connect("p.value", "c.b").expect("b");
    assert_eq!(a.pull(WAIT), Ok(1));
    assert_eq!(b.take_new(), None, "b did not ask");
    assert_eq!(b.pull(WAIT), Ok(2));
    assert_eq!(a.take_new(), None, "a did not ask again");
}

#[test]
fn fifo_poster_and_tick_inputs_pull_too() {
    let q = FifoIn::<u64>::new(4, OverflowPolicy::Reject);
    let r = PosterIn::<u64>::new();
    let t = TickIn::new();
    let mut p = producer(vec![
        ShellBuilder::new("c")
            .input(
                input(
                    "q",
                    InputKind::Fifo {
                        capacity: 4,
                        policy: OverflowPolicy::Reject,
                    },
                    true,
                ),
                &q,
            )
            .input(input("r", InputKind::Poster, true), &r)
            .input(input("t", InputKind::Tick, true), &t),
    ]);
    p.system.connect("p.value", "c.q").expect("q");
    p.system.connect("p.post", "c.r").expect("r");
    p.system.connect("p.tick", "c.t").expect("t");
    assert_eq!(q.pull(WAIT), Ok(1));
    assert_eq!(r.pull(WAIT), Ok(2));
    assert_eq!(t.pull(WAIT), Ok(1));
    // `request` alone: the answer arrives as a normal packet.
    q.request().expect("request");
    eventually(|| !q.is_empty(), "answer queued");
    assert_eq!(q.recv(), Some(4));
}

#[test]
fn a_pull_times_out_while_the_producer_does_not_run_and_is_answered_later() {
    let goal = LastIn::<u64>::new();
    let mut p = producer(vec![
        ShellBuilder::new("c").input(input("goal", InputKind::Last, true), &goal),
    ]);
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
    let goal = LastIn::<u64>::new();
    let mut p = producer(vec![
        ShellBuilder::new("c").input(input("goal", InputKind::Last, true), &goal),
    ]);
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
    let late = LastIn::<u64>::new();
    // A producer whose answer always fails (an undeclared fault).
    let value = DataOut::<u64>::new();
    let mut system = System::new();
    system
        .add(
            ShellBuilder::new("p")
                .output(output("value", OutputKind::Data, true), &value)
                .answer(|_| Err(Fault::message("sensor unplugged")))
                .build(),
        )
        .expect("p");
    system
        .add(
            ShellBuilder::new("c")
                .input(input("late", InputKind::Last, true), &late)
                .build(),
        )
        .expect("c");
    system.run_all().expect("run");
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
    let value = DataOut::<u64>::new();
    let goal = LastIn::<u64>::new();
    let own: Arc<std::sync::Mutex<Option<coolbot::Handle>>> = Arc::default();
    let answers = Arc::new(std::sync::Mutex::new(Vec::new()));
    let shell = {
        let (value, own, answers) = (value.clone(), Arc::clone(&own), Arc::clone(&answers));
        ShellBuilder::new("p")
            .output(output("value", OutputKind::Data, true), &value)
            .answer(move |_| {
                let handle = own.lock().unwrap().clone().expect("handle installed");
                let answer = handle.command(Command::SetState(Controllable::Ready));
                answers.lock().unwrap().push(answer.map_err(|e| e.reason));
                value.send(1);
                Ok(())
            })
    };
    let mut system = System::new();
    let handle = system.add(shell.build()).expect("p");
    *own.lock().unwrap() = Some(handle.clone());
    system
        .add(
            ShellBuilder::new("c")
                .input(input("goal", InputKind::Last, true), &goal)
                .build(),
        )
        .expect("c");
    system.run_all().expect("run");
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
