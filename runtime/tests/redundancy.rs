//! Redundancy as the paper has it: the members of a redundant group run together on
//! the same inputs (every member receives every packet), consumers see one stream, the
//! leader's, and when the leader fails another member's output takes over with no
//! packet of the stream missing and none doubled.

mod support;

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use coolbot::port::{DataOut, FifoIn};
use coolbot::{
    Automaton, Component, CompoundBuilder, Context, Fault, InputKind, InputSpec, OnSpec,
    OutputKind, OutputSpec, OverflowPolicy, PortSet, Section, Spec, StateSpec, Step, System,
    TimingSpec, Value,
};
use support::WAIT;
use support::shell::{Idle, ShellBuilder, input, output};

const QUEUE: usize = 4096;

/// A reactive relay: each packet that arrives at `input` is sent on `output`; while
/// `fail` is set, its next section fails instead.
static RELAY: Spec = Spec {
    type_name: "Relay",
    doc: "",
    states: &[StateSpec {
        name: "relaying",
        entry: true,
        exit: false,
        periodic: None,
        on: &[OnSpec { port: 0, target: 0 }],
        after: &[],
        may: &[],
    }],
    initial: 0,
    inputs: &[InputSpec {
        name: "input",
        kind: InputKind::Fifo {
            capacity: QUEUE,
            policy: OverflowPolicy::Reject,
        },
        packet: "u64",
        pull: false,
    }],
    outputs: &[OutputSpec {
        name: "output",
        kind: OutputKind::Data,
        packet: "u64",
        pull: false,
    }],
    variables: &[],
    exceptions: &[],
    timing: TimingSpec::NONE,
};

struct Relay {
    spec: &'static Spec,
    input: FifoIn<u64>,
    output: DataOut<u64>,
    fail: Arc<AtomicBool>,
    /// While set, its next section hangs (until it is cleared, or `fail` is set).
    hold: Arc<AtomicBool>,
    relayed: Arc<AtomicU64>,
}

impl Automaton for Relay {
    fn spec(&self) -> &'static Spec {
        self.spec
    }
    fn start(&mut self, _cx: &mut Context) -> Result<(), Fault> {
        Ok(())
    }
    fn stop(&mut self, _cx: &mut Context) {}
    fn section(
        &mut self,
        _state: usize,
        _section: Section,
        _cx: &mut Context,
    ) -> Result<(), Fault> {
        if self.fail.swap(false, Ordering::SeqCst) {
            return Err(Fault::message("injected"));
        }
        while self.hold.load(Ordering::SeqCst) {
            if self.fail.swap(false, Ordering::SeqCst) {
                return Err(Fault::message("injected while hung"));
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        for packet in self.input.drain() {
            self.relayed.fetch_add(1, Ordering::SeqCst);
            self.output.send(packet);
        }
        Ok(())
    }
    fn choose(&mut self, _state: usize, _cx: &mut Context) -> Option<usize> {
        None
    }
    fn exception(&mut self, _exception: usize, _message: &str, _cx: &mut Context) {}
    fn answer(&mut self, _output: usize, _cx: &mut Context) -> Result<(), Fault> {
        Ok(())
    }
    fn configure(&mut self, _configuration: &Value) -> Result<(), String> {
        Ok(())
    }
    fn set(&mut self, _variable: usize, _value: &Value) -> Result<(), String> {
        Err("no variables".to_owned())
    }
    fn get(&self, _variable: usize) -> Value {
        Value::Unit
    }
}

/// The relay with a small `Block` fifo: a producer waits while it is full.
const BLOCK_QUEUE: usize = 4;

static BLOCK_RELAY: Spec = Spec {
    type_name: "BlockRelay",
    inputs: &[InputSpec {
        name: "input",
        kind: InputKind::Fifo {
            capacity: BLOCK_QUEUE,
            policy: OverflowPolicy::Block,
        },
        packet: "u64",
        pull: false,
    }],
    ..RELAY
};

struct Member {
    fail: Arc<AtomicBool>,
    hold: Arc<AtomicBool>,
    relayed: Arc<AtomicU64>,
}

fn relay(name: &str) -> (Component, Member) {
    relay_as(name, &RELAY)
}

fn relay_as(name: &str, spec: &'static Spec) -> (Component, Member) {
    let input = match spec.inputs[0].kind {
        InputKind::Fifo { capacity, policy } => FifoIn::new(capacity, policy),
        _ => unreachable!("the relays' input is a fifo"),
    };
    let output = DataOut::new();
    let ports = PortSet::new().input(&input).output(&output);
    let member = Member {
        fail: Arc::new(AtomicBool::new(false)),
        hold: Arc::new(AtomicBool::new(false)),
        relayed: Arc::new(AtomicU64::new(0)),
    };
    let automaton = Relay {
        spec,
        input,
        output,
        fail: Arc::clone(&member.fail),
        hold: Arc::clone(&member.hold),
        relayed: Arc::clone(&member.relayed),
    };
    (Component::new(name, Box::new(automaton), ports), member)
}

/// `p` feeds compound `k` (members `a` and `b`, redundant, behind exported `in` and
/// `out`), which feeds `c`; the test sends through `p` and reads `c`'s queue.
struct Rig {
    system: System,
    send: DataOut<u64>,
    received: FifoIn<u64>,
    a: Member,
    b: Member,
}

fn rig() -> Rig {
    rig_of(&RELAY, Duration::from_secs(60))
}

/// The rig with members of `spec`, whose recovery queue retries every `retry`.
fn rig_of(spec: &'static Spec, retry: Duration) -> Rig {
    let (a_component, a) = relay_as("a", spec);
    let (b_component, b) = relay_as("b", spec);
    let k = CompoundBuilder::new("k", Idle)
        .instance(a_component)
        .instance(b_component)
        .redundant(&["a", "b"])
        .export_input::<u64>("in", "a.input")
        .export_output::<u64>("out", "a.output")
        .recovery(retry, Duration::from_secs(120))
        .build()
        .expect("build k");
    let send = DataOut::<u64>::new();
    let received = FifoIn::<u64>::new(QUEUE, OverflowPolicy::Reject);
    let mut system = System::new();
    system
        .add(
            ShellBuilder::new("p")
                .output(output("out", OutputKind::Data, false), &send)
                .build(),
        )
        .expect("add p");
    system.add(k).expect("add k");
    system
        .add(
            ShellBuilder::new("c")
                .input(
                    input(
                        "in",
                        InputKind::Fifo {
                            capacity: QUEUE,
                            policy: OverflowPolicy::Reject,
                        },
                        false,
                    ),
                    &received,
                )
                .build(),
        )
        .expect("add c");
    system.connect("p.out", "k.in").expect("p -> k");
    system.connect("k.out", "c.in").expect("k -> c");
    system.run_all().expect("run");
    Rig {
        system,
        send,
        received,
        a,
        b,
    }
}

/// Whether `step` says `b` took over from `a`.
fn took_over(step: &coolbot::Supervision) -> bool {
    step.instance == "a" && step.step == Step::Substituted { by: "b".to_owned() }
}

/// Every packet `c` receives until it has `count`, or the deadline.
fn collect(received: &FifoIn<u64>, count: usize) -> Vec<u64> {
    let deadline = Instant::now() + WAIT;
    let mut seen = Vec::new();
    while seen.len() < count && Instant::now() < deadline {
        if let Some(packet) = received.recv_timeout(Duration::from_millis(10)) {
            seen.push(packet);
        }
    }
    seen
}

#[test]
fn every_member_receives_every_packet_and_consumers_see_one_stream() {
    let rig = rig();
    for n in 1..=200 {
        rig.send.send(n);
    }
    assert_eq!(collect(&rig.received, 200), (1..=200).collect::<Vec<_>>());
    // Both members relayed everything (the standby's state is warm); the consumer
    // got each packet once.
    support::eventually(
        || rig.b.relayed.load(Ordering::SeqCst) == 200,
        "b relayed every packet",
    );
    assert_eq!(rig.a.relayed.load(Ordering::SeqCst), 200);
    assert_eq!(rig.received.recv_timeout(Duration::from_millis(50)), None);
    assert!(rig.system.shutdown().clean());
}

#[test]
fn the_stream_loses_no_packet_and_doubles_none_across_a_failover() {
    for round in 0..5 {
        let rig = rig();
        let k = rig.system.handle("k").expect("k");
        // The leader fails in the middle of a stream of numbered packets: at its
        // first section after `fail_at` was sent (the next packet's arrival runs
        // one), before the rest is sent.
        let a = k.instance("a").expect("a");
        let fail_at = 300 + round * 100;
        for n in 1..=1000u64 {
            rig.send.send(n);
            if n == fail_at {
                rig.a.fail.store(true, Ordering::SeqCst);
            }
            if n == fail_at + 1 {
                a.wait_for(|m| m.state == coolbot::State::RunningError, WAIT)
                    .expect("a fails");
            }
        }
        let seen = collect(&rig.received, 1000);
        assert_eq!(
            seen,
            (1..=1000).collect::<Vec<_>>(),
            "round {round}: every packet once, in order"
        );
        // (The step is published when the compound's turn ends, just after the
        // stream went on.)
        let monitor = k
            .wait_for(|m| m.supervision.iter().any(took_over), WAIT)
            .unwrap_or_else(|_| panic!("round {round}: b took over: {:?}", k.snapshot()));
        assert_eq!(monitor.state, coolbot::State::Running);
        assert_eq!(rig.received.recv_timeout(Duration::from_millis(50)), None);
        assert_eq!(rig.received.overflows(), 0);
        assert!(rig.system.shutdown().clean());
    }
}

#[test]
fn a_converted_connection_inside_the_compound_reads_the_merged_stream() {
    // `a` and `b` feed `t` inside the compound through a converter; `t`'s output is
    // exported. `t` sees one stream, converted, across the failover.
    let (a_component, a) = relay("a");
    let (b_component, b) = relay("b");
    let (t_component, _t) = relay("t");
    let k = CompoundBuilder::new("k", Idle)
        .instance(a_component)
        .instance(b_component)
        .instance(t_component)
        .redundant(&["a", "b"])
        .connect_via::<u64, u64>("a.output", "t.input", |n| n * 10)
        .export_input::<u64>("in", "a.input")
        .export_output::<u64>("out", "t.output")
        .build()
        .expect("build k");
    let send = DataOut::<u64>::new();
    let received = FifoIn::<u64>::new(QUEUE, OverflowPolicy::Reject);
    let mut system = System::new();
    system
        .add(
            ShellBuilder::new("p")
                .output(output("out", OutputKind::Data, false), &send)
                .build(),
        )
        .expect("add p");
    system.add(k).expect("add k");
    system
        .add(
            ShellBuilder::new("c")
                .input(
                    input(
                        "in",
                        InputKind::Fifo {
                            capacity: QUEUE,
                            policy: OverflowPolicy::Reject,
                        },
                        false,
                    ),
                    &received,
                )
                .build(),
        )
        .expect("add c");
    system.connect("p.out", "k.in").expect("p -> k");
    system.connect("k.out", "c.in").expect("k -> c");
    system.run_all().expect("run");
    let a_handle = system.handle("k").and_then(|k| k.instance("a")).expect("a");
    for n in 1..=600u64 {
        send.send(n);
        if n == 250 {
            a.fail.store(true, Ordering::SeqCst);
        }
        if n == 251 {
            a_handle
                .wait_for(|m| m.state == coolbot::State::RunningError, WAIT)
                .expect("a fails");
        }
    }
    assert_eq!(
        collect(&received, 600),
        (1..=600).map(|n| n * 10).collect::<Vec<_>>()
    );
    assert_eq!(b.relayed.load(Ordering::SeqCst), 600);
    let k = system.handle("k").expect("k");
    k.wait_for(|m| m.supervision.iter().any(took_over), WAIT)
        .expect("b took over");
    assert!(system.shutdown().clean());
}

/// Whether `step` is about `instance` and is `kind`.
fn step_of(step: &coolbot::Supervision, instance: &str, kind: &Step) -> bool {
    step.instance == instance && step.step == *kind
}

/// `b` hangs while packets `1..=sent` go through the rig one at a time (each waits
/// until the leader relayed it); returns when `b` is out of step.
fn hang_b_through(rig: &Rig, sent: u64) -> coolbot::Monitor {
    rig.b.hold.store(true, Ordering::SeqCst);
    for n in 1..=sent {
        rig.send.send(n);
        // One at a time: the compound's own fifo never fills, whatever `b` does.
        support::eventually(
            || rig.a.relayed.load(Ordering::SeqCst) == n,
            "a relays the packet while b hangs",
        );
    }
    let k = rig.system.handle("k").expect("k");
    k.wait_for(
        |m| {
            m.supervision
                .iter()
                .any(|s| step_of(s, "b", &Step::OutOfStep))
        },
        WAIT,
    )
    .unwrap_or_else(|_| panic!("b is out of step: {:?}", k.snapshot()))
}

#[test]
fn a_hung_member_does_not_stall_the_others_and_what_it_misses_is_counted_lost() {
    // `a` and `b` read the compound's exported input through `Block` fifos of 4; `b`
    // hangs in a section. Once `b`'s fifo has stayed full for `MEMBER_STALL`, `a` gets
    // every packet without waiting for `b`, and what `b` misses is counted lost at
    // its input: `b` is out of step, out of the group until it is resynchronized.
    let rig = rig_of(&BLOCK_RELAY, Duration::from_secs(60));
    let monitor = hang_b_through(&rig, 40);
    let out_of_step = monitor
        .supervision
        .iter()
        .find(|s| step_of(s, "b", &Step::OutOfStep))
        .expect("the step");
    let lost: u64 = out_of_step
        .detail
        .strip_prefix("left out of ")
        .and_then(|rest| rest.strip_suffix(" input packet(s)"))
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("the detail says what b lost: {out_of_step:?}"));
    assert!(lost >= 1, "{out_of_step:?}");
    let b = rig
        .system
        .handle("k")
        .and_then(|k| k.instance("b"))
        .expect("b");
    // What b missed, and what was queued at it when it left the group, is counted
    // and announced at its input.
    b.wait_for(|m| m.overflows >= lost + BLOCK_QUEUE as u64, WAIT)
        .unwrap_or_else(|_| panic!("b's losses are counted: {:?}", b.snapshot()));
    assert_eq!(collect(&rig.received, 40), (1..=40).collect::<Vec<_>>());
    assert_eq!(rig.received.overflows(), 0);
    rig.b.hold.store(false, Ordering::SeqCst);
    assert!(rig.system.shutdown().clean());
}

#[test]
fn a_member_that_fell_out_of_step_leads_only_after_it_is_resynchronized() {
    // `b` hung and was left behind at the exported input (so its own count of the
    // packets it sent is behind the stream's). It leaves the group, is resynchronized
    // by the recovery queue, and only then can lead: when `a` fails later, the stream
    // goes on with no packet missing and none doubled. (Before, `b` stayed in the
    // group out of step, led after `a`'s failure and dropped the packets it numbered
    // at or below the stream's number, with no count.)
    let rig = rig_of(&BLOCK_RELAY, Duration::from_millis(20));
    hang_b_through(&rig, 40);
    rig.b.hold.store(false, Ordering::SeqCst);
    let k = rig.system.handle("k").expect("k");
    k.wait_for(
        |m| {
            m.supervision
                .iter()
                .any(|s| step_of(s, "b", &Step::Recovered))
        },
        WAIT,
    )
    .unwrap_or_else(|_| panic!("b recovered: {:?}", k.snapshot()));
    let a = k.instance("a").expect("a");
    for n in 41..=200u64 {
        rig.send.send(n);
        if n == 120 {
            rig.a.fail.store(true, Ordering::SeqCst);
        }
        if n == 121 {
            a.wait_for(|m| m.state == coolbot::State::RunningError, WAIT)
                .expect("a fails");
        }
    }
    assert_eq!(
        collect(&rig.received, 200),
        (1..=200).collect::<Vec<_>>(),
        "every packet once, in order"
    );
    k.wait_for(|m| m.supervision.iter().any(took_over), WAIT)
        .expect("b took over");
    assert_eq!(rig.received.recv_timeout(Duration::from_millis(50)), None);
    assert_eq!(rig.received.overflows(), 0);
    assert!(rig.system.shutdown().clean());
}

#[test]
fn packets_missing_at_a_failover_are_counted_lost_at_the_consumers() {
    // The leader `a` hangs while `b` runs on: `b` gets further ahead of the stream
    // than its backlog keeps. When `a` fails, `b` leads from its backlog; the packets
    // neither could give are counted lost at the consumer: sent = received + lost.
    let rig = rig();
    rig.a.hold.store(true, Ordering::SeqCst);
    let backlog = 1024; // `port::MERGE_BACKLOG`
    let sent = backlog as u64 + 300;
    for n in 1..=sent {
        rig.send.send(n);
    }
    support::eventually(
        || rig.b.relayed.load(Ordering::SeqCst) == sent,
        "b relayed every packet",
    );
    rig.a.fail.store(true, Ordering::SeqCst);
    let k = rig.system.handle("k").expect("k");
    k.wait_for(|m| m.supervision.iter().any(took_over), WAIT)
        .expect("b took over");
    let seen = collect(&rig.received, backlog);
    let first = sent - backlog as u64 + 1;
    assert_eq!(
        seen,
        (first..=sent).collect::<Vec<_>>(),
        "b's backlog, in order"
    );
    assert_eq!(rig.received.recv_timeout(Duration::from_millis(50)), None);
    assert_eq!(
        rig.received.overflows(),
        first - 1,
        "the packets missing from the stream are counted lost at the consumer"
    );
    assert_eq!(seen.len() as u64 + rig.received.overflows(), sent);
    let c = rig.system.handle("c").expect("c");
    c.wait_for(|m| m.overflows == first - 1, WAIT)
        .expect("the loss is announced on the consumer's monitoring port");
    rig.a.hold.store(false, Ordering::SeqCst);
    assert!(rig.system.shutdown().clean());
}

#[test]
fn a_substituted_consumer_of_a_merged_stream_hands_its_queue_to_its_substitute() {
    substituted_consumer_keeps_the_queue(None);
}

#[test]
fn a_substituted_consumer_behind_a_converter_hands_its_queue_to_its_substitute() {
    substituted_consumer_keeps_the_queue(Some(|n| n * 10));
}

/// `a` and `b` (redundant) feed `t` inside the compound (through `convert`, if
/// given); `t2` substitutes `t`, whose output is exported. `t` hangs with packets
/// queued, then fails: its queue moves to `t2` with the connection (and its
/// converter), as for any consumer, and nothing is lost.
fn substituted_consumer_keeps_the_queue(convert: Option<fn(&u64) -> u64>) {
    let (a_component, a) = relay("a");
    let (b_component, _) = relay("b");
    let (t_component, t) = relay("t");
    let (t2_component, t2) = relay("t2");
    let k = CompoundBuilder::new("k", Idle);
    let k = match convert {
        Some(convert) => k.connect_via::<u64, u64>("a.output", "t.input", convert),
        None => k.connect("a.output", "t.input"),
    };
    let k = k
        .instance(a_component)
        .instance(b_component)
        .instance(t_component)
        .instance(t2_component)
        .redundant(&["a", "b"])
        .substitute("t2", "t")
        .on_error("t", coolbot::Policy::Substitute)
        .export_input::<u64>("in", "a.input")
        .export_output::<u64>("out", "t.output")
        .recovery(Duration::from_secs(60), Duration::from_secs(120))
        .build()
        .expect("build k");
    let send = DataOut::<u64>::new();
    let received = FifoIn::<u64>::new(QUEUE, OverflowPolicy::Reject);
    let mut system = System::new();
    system
        .add(
            ShellBuilder::new("p")
                .output(output("out", OutputKind::Data, false), &send)
                .build(),
        )
        .expect("add p");
    system.add(k).expect("add k");
    system
        .add(
            ShellBuilder::new("c")
                .input(
                    input(
                        "in",
                        InputKind::Fifo {
                            capacity: QUEUE,
                            policy: OverflowPolicy::Reject,
                        },
                        false,
                    ),
                    &received,
                )
                .build(),
        )
        .expect("add c");
    system.connect("p.out", "k.in").expect("p -> k");
    system.connect("k.out", "c.in").expect("k -> c");
    system.run_all().expect("run");
    t.hold.store(true, Ordering::SeqCst);
    let k = system.handle("k").expect("k");
    for n in 1..=50u64 {
        send.send(n);
    }
    // The leader relayed every packet: each is in the stream, so queued at `t` (the
    // stream is delivered on the leader's thread as it sends).
    support::eventually(
        || a.relayed.load(Ordering::SeqCst) == 50,
        "the stream carried every packet",
    );
    assert_eq!(t.relayed.load(Ordering::SeqCst), 0, "t holds them");
    t.fail.store(true, Ordering::SeqCst);
    k.wait_for(
        |m| {
            m.supervision.iter().any(|s| {
                s.instance == "t"
                    && s.step
                        == Step::Substituted {
                            by: "t2".to_owned(),
                        }
            })
        },
        WAIT,
    )
    .expect("t2 substitutes t");
    let expected = |n: u64| convert.map_or(n, |convert| convert(&n));
    assert_eq!(
        collect(&received, 50),
        (1..=50).map(expected).collect::<Vec<_>>(),
        "t2 relays what was queued at t, then the rest"
    );
    assert_eq!(t2.relayed.load(Ordering::SeqCst), 50);
    assert_eq!(t.relayed.load(Ordering::SeqCst), 0);
    t.hold.store(false, Ordering::SeqCst);
    assert!(system.shutdown().clean());
}
