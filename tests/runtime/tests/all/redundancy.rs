//! Redundancy as the paper has it: the members of a redundant group run together on
//! the same inputs (every member receives every packet), consumers see one stream, the
//! leader's, and when the leader fails another member's output takes over with no
//! packet of the stream missing and none doubled.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use coolbot::crossbeam_channel::{self, Receiver, Sender};
use coolbot::port::{DataOut, FifoIn};
use coolbot::{Component, SectionResult, Step, System};
use coolbot_runtime_tests::convert::Convert;
use coolbot_runtime_tests::generated::{
    block_pair, converted_pair, converted_substituted_consumer, grouped_pair, quick_block_pair,
    red_block_relay, red_relay, red_sink, red_source, redundant_pair, substituted_consumer,
};
use coolbot_runtime_tests::support::{self, WAIT};

/// `RedBlockRelay`'s `block` fifo.
const BLOCK_QUEUE: usize = 4;

/// What the test holds of one relay (`RedRelay` or `RedBlockRelay`): while `fail`
/// is set, its next section fails instead; while `hold` is set, its next section
/// hangs (until it is cleared, or `fail` is set); `relayed` counts what it sent.
#[derive(Clone, Default)]
struct Member {
    fail: Arc<AtomicBool>,
    hold: Arc<AtomicBool>,
    relayed: Arc<AtomicU64>,
}

/// The relays' behaviour: each packet that arrives at `input` is sent on `output`.
struct Relaying(Member);

impl Relaying {
    fn relay(&mut self, input: &FifoIn<u64>, output: &DataOut<u64>) -> SectionResult {
        let member = &self.0;
        if member.fail.swap(false, Ordering::SeqCst) {
            return Err(coolbot::Fault::message("injected"));
        }
        while member.hold.load(Ordering::SeqCst) {
            if member.fail.swap(false, Ordering::SeqCst) {
                return Err(coolbot::Fault::message("injected while hung"));
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        for packet in input.drain() {
            member.relayed.fetch_add(1, Ordering::SeqCst);
            output.send(packet);
        }
        Ok(())
    }
}

impl red_relay::Behavior for Relaying {
    fn relaying_entry(&mut self, cx: &mut red_relay::Cx<'_>) -> SectionResult {
        self.relay(&cx.inputs.input, &cx.outputs.output)
    }
}

impl red_block_relay::Behavior for Relaying {
    fn relaying_entry(&mut self, cx: &mut red_block_relay::Cx<'_>) -> SectionResult {
        self.relay(&cx.inputs.input, &cx.outputs.output)
    }
}

/// The parts of a compound of relays: each instance's `Member`, by name (a clone
/// given to the generated builder shares them with the test's).
#[derive(Clone, Default)]
struct Relays {
    members: Arc<Mutex<HashMap<&'static str, Member>>>,
}

impl Relays {
    fn relaying(&mut self, instance: &'static str) -> Relaying {
        let mut members = self.members.lock().unwrap();
        Relaying(members.entry(instance).or_default().clone())
    }

    fn member(&self, instance: &str) -> Member {
        self.members.lock().unwrap()[instance].clone()
    }
}

/// A supervisor without sections (the compounds of relays have none).
struct NoSections;

/// `Relays` as the parts of compound `$module` of relays `$relay` named `$instance`.
macro_rules! relays {
    ($module:ident, $relay:ident: $($instance:ident),+) => {
        impl $module::Supervisor for NoSections {}

        impl $module::Parts for Relays {
            fn supervisor(&mut self) -> impl $module::Supervisor {
                NoSections
            }
            $(
                fn $instance(&mut self) -> impl $relay::Behavior {
                    self.relaying(stringify!($instance))
                }
            )+
        }
    };
}

relays!(redundant_pair, red_relay: a, b);
relays!(block_pair, red_block_relay: a, b);
relays!(grouped_pair, red_relay: a, b);
relays!(quick_block_pair, red_block_relay: a, b);
relays!(converted_pair, red_relay: a, b, t);
relays!(substituted_consumer, red_relay: a, b, t, t2);
relays!(converted_substituted_consumer, red_relay: a, b, t, t2);

/// `RedSource`'s behaviour: it hands a clone of its output to the test at start.
struct HandOut(Sender<DataOut<u64>>);

impl red_source::Behavior for HandOut {
    fn start(&mut self, cx: &mut red_source::Cx<'_>) -> SectionResult {
        let _ = self.0.send(cx.outputs.out.clone());
        Ok(())
    }
}

/// `RedSink`'s behaviour: it hands a clone of its queue to the test at start.
struct HandIn(Sender<FifoIn<u64>>);

impl red_sink::Behavior for HandIn {
    fn start(&mut self, cx: &mut red_sink::Cx<'_>) -> SectionResult {
        let _ = self.0.send(cx.inputs.inbox.clone());
        Ok(())
    }
}

/// `p` (a `RedSource`) feeds compound `k` (whose exported `input` and `output` stand
/// for its redundant members `a` and `b`, or for `t`), which feeds `c` (a
/// `RedSink`); the test sends through `p` and reads `c`'s queue.
struct Rig {
    system: System,
    send: DataOut<u64>,
    received: FifoIn<u64>,
    a: Member,
    b: Member,
}

/// Whatever a handing behaviour handed over once the system runs.
fn handed<T>(from: &Receiver<T>) -> T {
    from.recv_timeout(WAIT).expect("handed over at start")
}

/// The rig around compound `k`, whose instances' behaviours are `relays`'.
fn rig_around(k: Component, relays: &Relays) -> Rig {
    let (out, send) = crossbeam_channel::bounded(1);
    let (inbox, received) = crossbeam_channel::bounded(1);
    let mut system = System::new();
    system
        .add(red_source::component("p", HandOut(out)))
        .expect("add p");
    system.add(k).expect("add k");
    system
        .add(red_sink::component("c", HandIn(inbox)))
        .expect("add c");
    system.connect("p.out", "k.input").expect("p -> k");
    system.connect("k.output", "c.inbox").expect("k -> c");
    system.run_all().expect("run");
    Rig {
        system,
        send: handed(&send),
        received: handed(&received),
        a: relays.member("a"),
        b: relays.member("b"),
    }
}

/// The rig around a `RedundantPair`.
fn rig() -> Rig {
    let relays = Relays::default();
    let k = redundant_pair::component("k", relays.clone()).expect("build k");
    rig_around(k, &relays)
}

/// Wait until `events` (a subscription taken before) announce `state`: a state that may
/// last less than a snapshot's look (a recovery queue restarts the member within
/// milliseconds) is never missed.
fn entered(events: &Receiver<coolbot::MonitorEvent>, state: coolbot::State) {
    let deadline = Instant::now() + WAIT;
    loop {
        match events.recv_deadline(deadline) {
            Ok(coolbot::MonitorEvent::State { to, .. }) if to == state => return,
            Ok(_) => {}
            Err(_) => panic!("no move to {state} within {WAIT:?}"),
        }
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
        let events = k.instance("a").expect("a").subscribe();
        let fail_at = 300 + round * 100;
        for n in 1..=1000u64 {
            rig.send.send(n);
            if n == fail_at {
                rig.a.fail.store(true, Ordering::SeqCst);
            }
            if n == fail_at + 1 {
                entered(&events, coolbot::State::RunningError);
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
fn members_of_an_execution_group_fail_over_with_no_packet_lost_or_doubled() {
    // `a` and `b` share one thread: the leader fails in the middle of the stream, and
    // `b`, on the same thread, takes over with the stream exact.
    let relays = Relays::default();
    let k = grouped_pair::component("k", relays.clone()).expect("build k");
    let rig = rig_around(k, &relays);
    let k = rig.system.handle("k").expect("k");
    let (a, b) = (
        k.instance("a").expect("a").snapshot(),
        k.instance("b").expect("b").snapshot(),
    );
    let group = a.group.expect("a runs in the group");
    assert_eq!(
        (group.name.as_str(), &group.members),
        ("pair", &vec!["a".to_owned(), "b".to_owned()])
    );
    assert_eq!(b.group.map(|g| g.name), Some("pair".to_owned()));
    let events = k.instance("a").expect("a").subscribe();
    for n in 1..=1000u64 {
        rig.send.send(n);
        if n == 400 {
            rig.a.fail.store(true, Ordering::SeqCst);
        }
        if n == 401 {
            entered(&events, coolbot::State::RunningError);
        }
    }
    assert_eq!(collect(&rig.received, 1000), (1..=1000).collect::<Vec<_>>());
    let monitor = k
        .wait_for(|m| m.supervision.iter().any(took_over), WAIT)
        .unwrap_or_else(|_| panic!("b took over: {:?}", k.snapshot()));
    assert_eq!(monitor.state, coolbot::State::Running);
    assert_eq!(rig.b.relayed.load(Ordering::SeqCst), 1000);
    assert_eq!(rig.received.recv_timeout(Duration::from_millis(50)), None);
    assert_eq!(rig.received.overflows(), 0);
    assert!(rig.system.shutdown().clean());
}

#[test]
fn a_converted_connection_inside_the_compound_reads_the_merged_stream() {
    // `a` and `b` feed `t` inside the compound through a converter; `t`'s output is
    // exported. `t` sees one stream, converted, across the failover.
    let relays = Relays::default();
    let k = converted_pair::component::<Convert>("k", relays.clone()).expect("build k");
    let Rig {
        system,
        send,
        received,
        a,
        b,
    } = rig_around(k, &relays);
    let events = system
        .handle("k")
        .and_then(|k| k.instance("a"))
        .expect("a")
        .subscribe();
    for n in 1..=600u64 {
        send.send(n);
        if n == 250 {
            a.fail.store(true, Ordering::SeqCst);
        }
        if n == 251 {
            entered(&events, coolbot::State::RunningError);
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
    let relays = Relays::default();
    let k = block_pair::component("k", relays.clone()).expect("build k");
    let rig = rig_around(k, &relays);
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
    let relays = Relays::default();
    let k = quick_block_pair::component("k", relays.clone()).expect("build k");
    let rig = rig_around(k, &relays);
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
    let events = k.instance("a").expect("a").subscribe();
    for n in 41..=200u64 {
        rig.send.send(n);
        if n == 120 {
            rig.a.fail.store(true, Ordering::SeqCst);
        }
        if n == 121 {
            entered(&events, coolbot::State::RunningError);
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

/// `a` and `b` (redundant) feed `t` inside the compound (`SubstitutedConsumer`, or
/// with `convert` `ConvertedSubstitutedConsumer`, whose `RedTimesTen` is what
/// `convert` expects); `t2` substitutes `t`, whose output is exported. `t` hangs with packets
/// queued, then fails: its queue moves to `t2` with the connection (and its
/// converter), as for any consumer, and nothing is lost.
fn substituted_consumer_keeps_the_queue(convert: Option<fn(&u64) -> u64>) {
    let relays = Relays::default();
    let k = match convert {
        Some(_) => converted_substituted_consumer::component::<Convert>("k", relays.clone()),
        None => substituted_consumer::component("k", relays.clone()),
    }
    .expect("build k");
    let Rig {
        system,
        send,
        received,
        a,
        ..
    } = rig_around(k, &relays);
    let (t, t2) = (relays.member("t"), relays.member("t2"));
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
