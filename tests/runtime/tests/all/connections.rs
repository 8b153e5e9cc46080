//! Every connection kind: semantics, overflow policies with their counters and events,
//! cardinality, kind and type errors, converters, disconnecting, and what inputs do
//! while their component is not running.
//!
//! The producers `p` and consumers `c` are generated (`cool/connections.cool`), with
//! no automaton; each one's behaviour hands clones of its ports to the test when it
//! starts, and the test sends and reads on them from its own thread. The consumers
//! stay in `ready` (nothing is ever set running), so each kind's test also shows what
//! it does while its component is not running: it works exactly the same; only the
//! reading differs, which no section does then.

use std::sync::atomic::Ordering;
use std::time::Duration;

use coolbot::crossbeam_channel::{self, Receiver, Sender};
use coolbot::port::{DataOut, FifoIn, LastIn, PosterIn, PosterOut, TickIn, TickOut, UfifoIn};
use coolbot::{
    Component, ConnectError, Controllable, MonitorEvent, OverflowPolicy, SectionResult, State,
    System,
};
use coolbot_runtime_tests::generated::{
    cn_block_c, cn_block2c, cn_bytes_c, cn_bytes_p, cn_drop_oldest_c, cn_fifo1c, cn_kinds_c,
    cn_kinds_p, cn_last_c, cn_last_poster_c, cn_many_p, cn_map_p, cn_out_p, cn_posters_c,
    cn_queue_last_c, cn_queues_c, cn_reject_c, cn_tick_c, cn_tick_p, cn_types_c, cn_types_p,
    cn_ufifo_c, cn_ufifo3c,
};
use coolbot_runtime_tests::support::{Rig, Script, WAIT};

/// A behaviour that hands clones of its component's ports to the test at `start`.
struct Hand<T>(Sender<T>);

/// `hands!(make = module: Ports, |cx| ports)`: `module::Behavior` for `Hand<Ports>`,
/// and `make(name)`, the component with the receiver its ports arrive on.
macro_rules! hands {
    ($make:ident = $module:ident: $ty:ty, |$cx:ident| $ports:expr) => {
        impl $module::Behavior for Hand<$ty> {
            fn start(&mut self, $cx: &mut $module::Cx<'_>) -> SectionResult {
                let _ = self.0.send($ports);
                Ok(())
            }
        }

        fn $make(name: &str) -> (Component, Receiver<$ty>) {
            let (sender, receiver) = crossbeam_channel::bounded(1);
            ($module::component(name, Hand(sender)), receiver)
        }
    };
}

type Bytes = Vec<u8>;

hands!(tick_p = cn_tick_p: (TickOut, TickOut), |cx| (cx.outputs.a.clone(), cx.outputs.b.clone()));
hands!(tick_c = cn_tick_c: (TickIn, TickIn), |cx| (cx.inputs.x.clone(), cx.inputs.y.clone()));
hands!(out_p = cn_out_p: (DataOut<u64>, DataOut<u64>), |cx| (
    cx.outputs.out.clone(),
    cx.outputs.other.clone()
));
hands!(many_p = cn_many_p: (DataOut<u64>, DataOut<u64>, PosterOut<u64>, PosterOut<u64>), |cx| (
    cx.outputs.a.clone(),
    cx.outputs.b.clone(),
    cx.outputs.pa.clone(),
    cx.outputs.pb.clone()
));
hands!(queue_last_c = cn_queue_last_c: (FifoIn<u64>, LastIn<u64>), |cx| (
    cx.inputs.q.clone(),
    cx.inputs.x.clone()
));
hands!(reject_c = cn_reject_c: FifoIn<u64>, |cx| cx.inputs.q.clone());
hands!(drop_oldest_c = cn_drop_oldest_c: FifoIn<u64>, |cx| cx.inputs.q.clone());
hands!(block_c = cn_block_c: FifoIn<u64>, |cx| cx.inputs.q.clone());
hands!(block2_c = cn_block2c: FifoIn<u64>, |cx| cx.inputs.q.clone());
hands!(fifo1_c = cn_fifo1c: FifoIn<u64>, |cx| cx.inputs.q.clone());
hands!(ufifo_c = cn_ufifo_c: (UfifoIn<u64>, UfifoIn<u64>), |cx| (
    cx.inputs.capped.clone(),
    cx.inputs.open.clone()
));
hands!(ufifo3_c = cn_ufifo3c: UfifoIn<u64>, |cx| cx.inputs.open.clone());
hands!(last_c = cn_last_c: (LastIn<u64>, LastIn<u64>), |cx| (
    cx.inputs.x.clone(),
    cx.inputs.y.clone()
));
hands!(last_poster_c = cn_last_poster_c: (LastIn<u64>, PosterIn<u64>), |cx| (
    cx.inputs.x.clone(),
    cx.inputs.r.clone()
));
hands!(queues_c = cn_queues_c: (FifoIn<u64>, FifoIn<u64>, FifoIn<u64>, UfifoIn<u64>, LastIn<u64>), |cx| (
    cx.inputs.reject.clone(),
    cx.inputs.oldest.clone(),
    cx.inputs.wide.clone(),
    cx.inputs.grows.clone(),
    cx.inputs.latest.clone()
));
hands!(bytes_p = cn_bytes_p: DataOut<Bytes>, |cx| cx.outputs.out.clone());
hands!(bytes_c = cn_bytes_c: (FifoIn<Bytes>, UfifoIn<Bytes>, LastIn<Bytes>), |cx| (
    cx.inputs.a.clone(),
    cx.inputs.b.clone(),
    cx.inputs.latest.clone()
));
hands!(map_p = cn_map_p: PosterOut<String>, |cx| cx.outputs.map.clone());
hands!(posters_c = cn_posters_c: (PosterIn<String>, PosterIn<String>), |cx| (
    cx.inputs.r1.clone(),
    cx.inputs.r2.clone()
));
hands!(kinds_p = cn_kinds_p: (TickOut, DataOut<u64>, PosterOut<u64>), |cx| (
    cx.outputs.tick.clone(),
    cx.outputs.data.clone(),
    cx.outputs.post.clone()
));
hands!(kinds_c = cn_kinds_c: (FifoIn<u64>, PosterIn<u64>, TickIn), |cx| (
    cx.inputs.q.clone(),
    cx.inputs.r.clone(),
    cx.inputs.t.clone()
));
hands!(types_p = cn_types_p: (DataOut<String>, DataOut<u64>, PosterOut<u64>), |cx| (
    cx.outputs.text.clone(),
    cx.outputs.numbers.clone(),
    cx.outputs.post.clone()
));
hands!(types_c = cn_types_c: (FifoIn<u64>, LastIn<String>, PosterIn<String>), |cx| (
    cx.inputs.q.clone(),
    cx.inputs.l.clone(),
    cx.inputs.r.clone()
));

/// A system with a producer `p` and a consumer `c`, started.
struct Pair {
    system: System,
}

impl Pair {
    /// `p` and `c` (made by [`hands!`]'s functions), started; with their ports.
    fn new<P, C>(
        (producer, p_ports): (Component, Receiver<P>),
        (consumer, c_ports): (Component, Receiver<C>),
    ) -> (Pair, P, C) {
        let mut system = System::new();
        system.add(producer).expect("add p");
        system.add(consumer).expect("add c");
        system.start().expect("start");
        for name in ["p", "c"] {
            let handle = system.handle(name).expect(name);
            handle.wait_state(State::Ready, WAIT).expect("ready");
        }
        let handed = "a component hands its ports over when it starts";
        let p = p_ports.recv_timeout(WAIT).expect(handed);
        let c = c_ports.recv_timeout(WAIT).expect(handed);
        (Pair { system }, p, c)
    }
}

#[test]
fn tick_is_n_to_m_and_counts_events() {
    let (mut pair, (a, b), (x, y)) = Pair::new(tick_p("p"), tick_c("c"));
    for (from, to) in [
        ("p.a", "c.x"),
        ("p.a", "c.y"),
        ("p.b", "c.x"),
        ("p.b", "c.y"),
    ] {
        pair.system.connect(from, to).expect(from);
    }
    a.emit();
    a.emit();
    b.emit();
    assert!(x.pending());
    assert_eq!(x.take(), 3);
    assert_eq!(x.take(), 0);
    assert!(!x.pending());
    assert_eq!(y.take(), 3);
}

#[test]
fn fifo_keeps_order_and_accepts_n_producers() {
    let (mut pair, (a, b, _, _), (q, _)) = Pair::new(many_p("p"), queue_last_c("c"));
    pair.system.connect("p.a", "c.q").expect("a");
    pair.system.connect("p.b", "c.q").expect("b");
    a.send(1);
    b.send(2);
    a.send(3);
    assert_eq!(q.len(), 3);
    assert_eq!(q.drain().collect::<Vec<_>>(), vec![1, 2, 3]);
    assert!(q.is_empty());
    assert_eq!(q.recv(), None);
}

/// Send `sent` packets into a fifo of 4 with `policy` (one consumer per policy,
/// `cool/connections.cool`); return the pair, the fifo and the consumer's events.
fn overflow_case(policy: OverflowPolicy, sent: u64) -> (Pair, FifoIn<u64>, Vec<MonitorEvent>) {
    let consumer = match policy {
        OverflowPolicy::Reject => reject_c("c"),
        OverflowPolicy::DropOldest => drop_oldest_c("c"),
        OverflowPolicy::Block => block_c("c"),
    };
    let (mut pair, (out, _), q) = Pair::new(out_p("p"), consumer);
    pair.system.connect("p.out", "c.q").expect("connect");
    let events = pair.system.handle("c").expect("c").subscribe();
    for packet in 0..sent {
        out.send(packet);
    }
    let events = events.try_iter().collect();
    (pair, q, events)
}

fn lost_in(events: &[MonitorEvent]) -> u64 {
    events
        .iter()
        .map(|event| {
            if let MonitorEvent::Overflow { lost, .. } = event {
                *lost
            } else {
                0
            }
        })
        .sum()
}

#[test]
fn fifo_reject_drops_the_newest_and_counts_it() {
    let (pair, q, events) = overflow_case(OverflowPolicy::Reject, 10);
    assert_eq!(q.drain().collect::<Vec<_>>(), vec![0, 1, 2, 3]);
    assert_eq!(q.overflows(), 6);
    let monitor = pair.system.handle("c").unwrap().snapshot();
    assert_eq!(monitor.overflows, 6);
    assert_eq!(monitor.port_overflows, vec![("q".to_owned(), 6)]);
    assert_eq!(lost_in(&events), 6);
    assert!(
        matches!(events.last(), Some(MonitorEvent::Overflow { port, total: 6, .. }) if port == "q")
    );
}

#[test]
fn fifo_drop_oldest_keeps_the_newest_and_counts_the_dropped() {
    let (_pair, q, events) = overflow_case(OverflowPolicy::DropOldest, 10);
    assert_eq!(q.drain().collect::<Vec<_>>(), vec![6, 7, 8, 9]);
    assert_eq!(q.overflows(), 6);
    assert_eq!(lost_in(&events), 6);
}

#[test]
fn fifo_block_waits_then_rejects_and_counts() {
    let (_pair, q, events) = overflow_case(OverflowPolicy::Block, 6);
    assert_eq!(q.drain().collect::<Vec<_>>(), vec![0, 1, 2, 3]);
    assert_eq!(q.overflows(), 2);
    assert_eq!(lost_in(&events), 2);
}

#[test]
fn a_send_would_wait_only_at_a_full_block_fifo() {
    for policy in [
        OverflowPolicy::Block,
        OverflowPolicy::Reject,
        OverflowPolicy::DropOldest,
    ] {
        let consumer = match policy {
            OverflowPolicy::Reject => reject_c("c"),
            OverflowPolicy::DropOldest => drop_oldest_c("c"),
            OverflowPolicy::Block => block_c("c"),
        };
        let (mut pair, (out, _), q) = Pair::new(out_p("p"), consumer);
        assert!(!out.would_wait(), "{policy:?}: nothing connected");
        pair.system.connect("p.out", "c.q").expect("connect");
        for packet in 0..3 {
            out.send(packet);
        }
        assert!(!out.would_wait(), "{policy:?}: room for one more");
        out.send(3);
        assert_eq!(
            out.would_wait(),
            policy == OverflowPolicy::Block,
            "{policy:?}: full"
        );
        assert_eq!(q.recv(), Some(0));
        assert!(!out.would_wait(), "{policy:?}: room again");
    }
}

/// What a source drains: one packet, once the test says it is there.
struct OnePacket {
    there: std::sync::atomic::AtomicBool,
    out: DataOut<u64>,
}

impl coolbot::Source for OnePacket {
    fn ready(&self) -> bool {
        self.there.load(Ordering::SeqCst)
    }

    fn drain(&self) {
        if self.there.swap(false, Ordering::SeqCst) {
            self.out.send(7);
        }
    }
}

/// A source added to the bell of the component an output feeds is drained by that
/// component's thread when the bell rings, here through the bell's address in shared
/// memory (as another process on the host rings it).
#[cfg(target_os = "linux")]
#[test]
fn a_source_on_the_consumers_bell_is_drained_when_the_bell_rings() {
    let (mut pair, (out, _), q) = Pair::new(out_p("p"), reject_c("c"));
    assert!(out.consumer_bell().is_none(), "nothing connected");
    pair.system.connect("p.out", "c.q").expect("connect");
    let bell = out.consumer_bell().expect("one consumer");
    let source = std::sync::Arc::new(OnePacket {
        there: std::sync::atomic::AtomicBool::new(false),
        out: out.clone(),
    });
    let _guard = bell.add_source(source.clone());
    source.there.store(true, Ordering::SeqCst);
    let address = bell.address().expect("the bell is in shared memory");
    coolbot::RemoteBell::open(&address).unwrap().ring();
    coolbot_runtime_tests::support::eventually(
        || q.recv() == Some(7),
        "the consumer's thread drained the source",
    );
    assert!(!coolbot::Source::ready(&*source));
}

/// A source whose drain panics.
struct Panicking(std::sync::atomic::AtomicUsize);

impl coolbot::Source for Panicking {
    fn ready(&self) -> bool {
        false
    }

    fn drain(&self) {
        self.0.fetch_add(1, Ordering::SeqCst);
        panic!("a source that panics on purpose");
    }
}

/// A source that panics is removed, and costs its component nothing else: the
/// component's thread goes on taking packets, and never drains that source again.
#[test]
fn a_source_that_panics_is_removed_and_the_component_goes_on() {
    let (mut pair, (out, _), q) = Pair::new(out_p("p"), reject_c("c"));
    pair.system.connect("p.out", "c.q").expect("connect");
    let bell = out.consumer_bell().expect("one consumer");
    let source = std::sync::Arc::new(Panicking(std::sync::atomic::AtomicUsize::new(0)));
    // Added, it rings once: the thread drains it, and it panics.
    let _guard = bell.add_source(source.clone());
    coolbot_runtime_tests::support::eventually(
        || source.0.load(Ordering::SeqCst) == 1,
        "the source drained once",
    );
    // Every packet rings the bell: the thread takes them, and drains nothing more.
    for packet in 0..3 {
        out.send(packet);
        coolbot_runtime_tests::support::eventually(
            || q.recv() == Some(packet),
            "the consumer took the packet",
        );
    }
    assert_eq!(
        source.0.load(Ordering::SeqCst),
        1,
        "drained after its panic"
    );
    assert_eq!(
        pair.system.handle("c").unwrap().state(),
        State::Ready,
        "the consumer is where it was"
    );
}

#[test]
fn fifo_block_loses_nothing_when_the_consumer_keeps_up() {
    // (The producer waits up to the 100 ms a `block` fifo waits for the reader.)
    let (mut pair, (out, _), q) = Pair::new(out_p("p"), block2_c("c"));
    pair.system.connect("p.out", "c.q").expect("connect");
    let reader = {
        let q = q.clone();
        std::thread::spawn(move || {
            let mut got = Vec::new();
            while got.len() < 1000 {
                match q.recv() {
                    Some(packet) => got.push(packet),
                    None => std::thread::yield_now(),
                }
            }
            got
        })
    };
    for packet in 0..1000 {
        out.send(packet);
    }
    assert_eq!(reader.join().unwrap(), (0..1000).collect::<Vec<_>>());
    assert_eq!(q.overflows(), 0);
}

#[test]
fn ufifo_grows_by_steps_up_to_its_cap_then_counts() {
    let (mut pair, (out, _), (capped, open)) = Pair::new(out_p("p"), ufifo_c("c"));
    let events = pair.system.handle("c").unwrap().subscribe();
    pair.system.connect("p.out", "c.capped").expect("capped");
    // The same output feeds `open` too: each queue grows (or not) by its own rule.
    pair.system.connect("p.out", "c.open").expect("open");
    assert_eq!(capped.capacity(), 2);
    for packet in 0..10 {
        out.send(packet);
    }
    assert_eq!(capped.capacity(), 6);
    assert_eq!(capped.growths(), 2);
    assert_eq!(capped.len(), 6);
    assert_eq!(capped.overflows(), 4);
    assert_eq!(lost_in(&events.try_iter().collect::<Vec<_>>()), 4);
    assert_eq!(
        capped.drain().collect::<Vec<_>>(),
        (0..6).collect::<Vec<_>>()
    );
    assert!(capped.is_empty());
    assert_eq!(
        open.drain().collect::<Vec<_>>(),
        (0..10).collect::<Vec<_>>()
    );
    assert_eq!(open.overflows(), 0);
}

#[test]
fn ufifo_without_cap_keeps_everything() {
    let (mut pair, (out, _), open) = Pair::new(out_p("p"), ufifo3_c("c"));
    pair.system.connect("p.out", "c.open").expect("open");
    for packet in 0..100 {
        out.send(packet);
    }
    assert_eq!(open.len(), 100);
    assert_eq!(open.capacity(), 102);
    assert_eq!(open.overflows(), 0);
    assert_eq!(open.recv(), Some(0));
}

#[test]
fn last_keeps_a_local_copy_at_each_of_n_inputs() {
    let (mut pair, (out, _), (x, y)) = Pair::new(out_p("p"), last_c("c"));
    pair.system.connect("p.out", "c.x").expect("x");
    pair.system.connect("p.out", "c.y").expect("y");
    assert_eq!(out.consumers(), 2);
    assert_eq!(x.latest(), None);
    out.send(1);
    out.send(2);
    assert_eq!(x.latest(), Some(2));
    assert_eq!(x.take_new(), Some(2));
    assert_eq!(x.take_new(), None);
    assert_eq!(x.latest(), Some(2), "the local copy stays");
    assert_eq!(y.take_new(), Some(2), "each input has its own copy");
    assert_eq!(x.received(), 2);
}

#[test]
fn last_and_poster_inputs_have_one_producer() {
    let (mut pair, (_a, _b, _pa, _pb), (_x, _r)) = Pair::new(many_p("p"), last_poster_c("c"));
    pair.system.connect("p.a", "c.x").expect("a");
    let err = pair.system.connect("p.b", "c.x").unwrap_err();
    assert_eq!(
        err.to_string(),
        "cannot connect `p.b` to `c.x`: a last connection is 1 output to N inputs, and `c.x` is already fed by `p.a`"
    );
    pair.system.connect("p.pa", "c.r").expect("pa");
    let err = pair.system.connect("p.pb", "c.r").unwrap_err();
    assert!(
        matches!(&err, ConnectError::Cardinality { rule, .. } if rule.contains("poster connection is 1 output to N inputs")),
        "{err}"
    );
}

#[test]
fn a_data_output_feeds_every_queue_with_its_own_policy() {
    // One output, four queues of different policies and a last input; a second
    // producer merges into the first queue.
    let (mut pair, (out, other), (reject, oldest, wide, grows, latest)) =
        Pair::new(out_p("p"), queues_c("c"));
    for to in ["reject", "oldest", "wide", "grows", "latest"] {
        pair.system
            .connect("p.out", &format!("c.{to}"))
            .unwrap_or_else(|e| panic!("{to}: {e}"));
    }
    pair.system
        .connect("p.other", "c.wide")
        .expect("a second producer");
    for packet in 1..=5 {
        out.send(packet);
    }
    other.send(100);
    assert_eq!(reject.drain().collect::<Vec<_>>(), [1, 2]);
    assert_eq!(reject.overflows(), 3);
    assert_eq!(oldest.drain().collect::<Vec<_>>(), [4, 5]);
    assert_eq!(oldest.overflows(), 3);
    assert_eq!(wide.drain().collect::<Vec<_>>(), [1, 2, 3, 4, 5, 100]);
    assert_eq!(wide.overflows(), 0);
    assert_eq!(grows.drain().collect::<Vec<_>>(), [1, 2, 3]);
    assert_eq!(grows.overflows(), 2);
    assert_eq!(latest.take_new(), Some(5));
}

#[test]
fn a_packet_sent_to_several_queues_is_shared_not_copied() {
    // A packet that owns memory goes to every input behind one pointer.
    let (mut pair, out, (a, b, latest)) = Pair::new(bytes_p("p"), bytes_c("c"));
    for to in ["a", "b", "latest"] {
        pair.system.connect("p.out", &format!("c.{to}")).expect(to);
    }
    out.send(vec![7; 1 << 16]);
    let (x, y) = (a.recv_shared().unwrap(), b.recv_shared().unwrap());
    let z = latest.take_new_shared().unwrap();
    assert!(std::sync::Arc::ptr_eq(&x, &y) && std::sync::Arc::ptr_eq(&x, &z));
    assert_eq!(x.len(), 1 << 16);
    // Taken by value, the packet is copied only while another input holds it: the
    // last holder takes the original allocation.
    pair.system.disconnect("p.out", "c.latest").expect("latest");
    let packet = vec![9; 16];
    let original = packet.as_ptr();
    out.send(packet);
    let first = a.recv().unwrap();
    let last = b.recv().unwrap();
    assert_eq!(
        (first.as_slice(), last.as_slice()),
        ([9; 16].as_slice(), [9; 16].as_slice())
    );
    assert_ne!(first.as_ptr(), original, "a copy while `b` still held it");
    assert_eq!(last.as_ptr(), original, "the last holder took the original");
}

#[test]
fn poster_inputs_read_the_producers_latest_post() {
    let (mut pair, post, (r1, r2)) = Pair::new(map_p("p"), posters_c("c"));
    assert_eq!(r1.read(), None, "unconnected");
    pair.system.connect("p.map", "c.r1").expect("r1");
    pair.system.connect("p.map", "c.r2").expect("r2");
    assert_eq!(r1.read(), None, "nothing posted");
    post.post("v1".to_owned());
    post.post("v2".to_owned());
    assert!(r1.is_new());
    assert_eq!(r1.read().as_deref(), Some("v2"));
    assert!(!r1.is_new());
    assert_eq!(r1.read().as_deref(), Some("v2"), "reading does not consume");
    assert_eq!(r2.take_new().as_deref(), Some("v2"), "r2 had not read v2");
    assert_eq!(r2.take_new(), None, "take_new returns each post once");
    assert_eq!(r2.read().as_deref(), Some("v2"), "read still sees it");
    post.post("v3".to_owned());
    assert_eq!(r1.take_new().as_deref(), Some("v3"));
    assert!(!r1.is_new(), "take_new marks the post as read");
    assert_eq!(post.posted().as_deref(), Some("v3"));
    pair.system.disconnect("p.map", "c.r1").expect("disconnect");
    assert_eq!(r1.read(), None, "a disconnected poster input reads nothing");
    assert_eq!(r2.read().as_deref(), Some("v3"));
    assert_eq!(r1.take_new(), None, "nor does take_new");
}

#[test]
fn kinds_that_cannot_connect_are_rejected() {
    let (mut pair, _, _) = Pair::new(kinds_p("p"), kinds_c("c"));
    let err = pair.system.connect("p.tick", "c.q").unwrap_err();
    assert_eq!(
        err.to_string(),
        "cannot connect tick output `p.tick` to fifo input `c.q`: a tick output connects only to tick inputs"
    );
    let err = pair.system.connect("p.data", "c.r").unwrap_err();
    assert!(
        matches!(
            err,
            ConnectError::KindMismatch {
                from_kind: "data",
                to_kind: "poster",
                ..
            }
        ),
        "{err}"
    );
    let err = pair.system.connect("p.post", "c.t").unwrap_err();
    assert!(
        matches!(
            err,
            ConnectError::KindMismatch {
                from_kind: "poster",
                to_kind: "tick",
                ..
            }
        ),
        "{err}"
    );
    // Addresses.
    assert!(matches!(
        pair.system.connect("ptick", "c.q"),
        Err(ConnectError::BadAddress { .. })
    ));
    assert!(matches!(
        pair.system.connect("x.tick", "c.q"),
        Err(ConnectError::UnknownInstance { .. })
    ));
    // The error names the component's type (`CnKindsP`, `cool/connections.cool`).
    let err = pair.system.connect("p.nope", "c.q").unwrap_err();
    assert_eq!(
        err.to_string(),
        "`p.nope`: component `p` (CnKindsP) has no output port `nope`"
    );
    let err = pair.system.connect("p.data", "c.tick").unwrap_err();
    assert!(
        matches!(
            err,
            ConnectError::UnknownPort {
                direction: "input",
                ..
            }
        ),
        "{err}"
    );
    // An input given as the source is not an output.
    assert!(matches!(
        pair.system.connect("c.q", "c.q"),
        Err(ConnectError::UnknownPort {
            direction: "output",
            ..
        })
    ));
}

#[test]
fn packet_types_are_checked_and_converters_bridge_them() {
    let (mut pair, (text, numbers, post), (q, l, r)) = Pair::new(types_p("p"), types_c("c"));
    let err = pair.system.connect("p.text", "c.q").unwrap_err();
    assert_eq!(
        err.to_string(),
        "cannot connect `p.text` to `c.q`: the output carries `alloc::string::String` but the input expects `u64` (use a converter: connect_via)"
    );
    assert!(matches!(
        pair.system.connect("p.post", "c.r"),
        Err(ConnectError::TypeMismatch { .. })
    ));
    // A converter with the wrong types is refused, naming them.
    let err = pair
        .system
        .connect_via("p.numbers", "c.l", |n: &u32| n.to_string())
        .unwrap_err();
    assert!(
        matches!(&err, ConnectError::ConverterMismatch { converter, .. } if converter == "u32 -> alloc::string::String"),
        "{err}"
    );
    // Converters on a data connection (producer side) and a poster (reader side).
    pair.system
        .connect_via("p.text", "c.q", |s: &String| s.len() as u64)
        .expect("text -> q");
    pair.system
        .connect_via("p.numbers", "c.l", |n: &u64| format!("#{n}"))
        .expect("numbers -> l");
    pair.system
        .connect_via("p.post", "c.r", |n: &u64| format!("post {n}"))
        .expect("post -> r");
    text.send("hello".to_owned());
    numbers.send(7);
    post.post(3);
    assert_eq!(q.recv(), Some(5));
    assert_eq!(l.latest().as_deref(), Some("#7"));
    assert_eq!(r.read().as_deref(), Some("post 3"));
    // Converted connections disconnect like any other.
    pair.system
        .disconnect("p.numbers", "c.l")
        .expect("disconnect");
    numbers.send(8);
    assert_eq!(l.latest().as_deref(), Some("#7"));
    pair.system
        .disconnect("p.post", "c.r")
        .expect("disconnect poster");
    assert_eq!(r.read(), None);
}

#[test]
fn disconnecting_while_running_keeps_queued_packets() {
    let (mut pair, (out, _), (q, x)) = Pair::new(out_p("p"), queue_last_c("c"));
    pair.system.run_all().expect("run");
    pair.system.connect("p.out", "c.q").expect("q");
    pair.system.connect("p.out", "c.x").expect("x");
    let err = pair.system.connect("p.out", "c.q").unwrap_err();
    assert_eq!(
        err,
        ConnectError::AlreadyConnected {
            from: "p.out".to_owned(),
            to: "c.q".to_owned()
        }
    );
    out.send(1);
    out.send(2);
    pair.system
        .disconnect("p.out", "c.q")
        .expect("disconnect q");
    pair.system
        .disconnect("p.out", "c.x")
        .expect("disconnect x");
    out.send(3);
    assert_eq!(
        q.drain().collect::<Vec<_>>(),
        vec![1, 2],
        "queued packets stay, later ones do not arrive"
    );
    assert_eq!(x.latest(), Some(2));
    let err = pair.system.disconnect("p.out", "c.q").unwrap_err();
    assert_eq!(err.to_string(), "`p.out` is not connected to `c.q`");
    // Reconnecting works and the queue goes on.
    pair.system.connect("p.out", "c.q").expect("reconnect");
    out.send(4);
    assert_eq!(q.recv(), Some(4));
    assert_eq!(
        pair.system.connections(),
        vec![("p.out".to_owned(), "c.q".to_owned())]
    );
}

#[test]
fn inputs_keep_working_while_the_component_is_ready_and_no_section_runs() {
    let rig = Rig::started(Script::new());
    assert_eq!(rig.handle.state(), State::Ready);
    for packet in 0..6 {
        rig.feeder().data.send(packet);
    }
    rig.feeder().kick.emit();
    rig.feeder().feed.send(41);
    rig.feeder().feed.send(42);
    let inputs = rig.script.inputs();
    assert_eq!(inputs.data.len(), 4, "the fifo keeps queueing");
    assert_eq!(inputs.data.overflows(), 2, "and overflows by its policy");
    assert!(inputs.kick.pending(), "the tick counts");
    assert_eq!(inputs.feed.latest(), Some(42), "last keeps the latest");
    assert_eq!(rig.script.log(), vec!["start"], "no section ran");
    // Going running enters `idle`: the packets that came while it was ready are
    // arrivals there, and fire `on data`; `busy` reads everything queued.
    rig.command(Controllable::Running).expect("running");
    rig.wait_user("busy");
    rig.handle
        .wait_for(|m| m.variables[0].1 == coolbot::Value::UInt(4), WAIT)
        .expect("count");
    assert_eq!(rig.script.received.load(Ordering::SeqCst), 4);
}

#[test]
fn arrivals_while_suspended_fire_on_resume() {
    // On a virtual clock: advancing it makes every component take a turn and settle
    // after the packets have arrived, so "nothing runs" is seen, not waited for.
    let clock = coolbot::VirtualClock::new();
    let script = Script::new();
    let component = coolbot_runtime_tests::support::worker("w", &script);
    let rig = Rig::start(Rig::with(
        System::with_clock(coolbot::Clock::virtual_clock(&clock)),
        script,
        component,
    ));
    rig.command(Controllable::Running).expect("running");
    rig.wait_user("idle");
    rig.command(Controllable::Suspended).expect("suspend");
    rig.script.clear_log();
    rig.feeder().data.send(7);
    rig.feeder().data.send(8);
    // The packets wait; nothing runs while suspended.
    clock.advance(Duration::from_millis(30)).expect("settled");
    assert_eq!(rig.script.log(), Vec::<String>::new());
    assert_eq!(rig.script.inputs().data.len(), 2);
    rig.command(Controllable::Running).expect("resume");
    rig.wait_user("busy");
    rig.handle
        .wait_for(|m| m.variables[0].1 == coolbot::Value::UInt(2), WAIT)
        .expect("count");
    assert_eq!(rig.script.log(), vec!["busy.entry"]);
}

#[test]
fn every_observer_gets_every_event_and_a_slow_one_loses_only_its_own() {
    let (mut pair, (out, _), q) = Pair::new(out_p("p"), fifo1_c("c"));
    pair.system.connect("p.out", "c.q").expect("connect");
    let handle = pair.system.handle("c").unwrap();
    handle.wait_state(State::Ready, WAIT).expect("ready");
    let (first, second) = (handle.subscribe(), handle.subscribe());
    let sent = coolbot::OBSERVER_CAPACITY as u64 + 100;
    // One packet fills the queue; every other one overflows and is announced.
    // `first` keeps up; `second` never reads.
    let mut first_got = 0;
    for packet in 0..=sent {
        out.send(packet);
        first_got += first.try_iter().count() as u64;
    }
    assert_eq!(q.overflows(), sent);
    assert_eq!(first_got, sent);
    assert_eq!(second.try_iter().count(), coolbot::OBSERVER_CAPACITY);
    assert_eq!(handle.snapshot().dropped_events, 100);
}

#[test]
fn a_poster_input_sees_the_first_post_of_a_new_producer_at_once() {
    let (mut pair, (_, _, pa, pb), (_, r)) = Pair::new(many_p("p"), last_poster_c("c"));
    pair.system.connect("p.pa", "c.r").expect("pa");
    for n in 0..5 {
        pa.post(n);
    }
    assert_eq!(r.take_new(), Some(4));
    assert!(!r.is_new());
    // The producer is replaced (as a substitute takes over): a new source, whose
    // posts are numbered from 1 again.
    pair.system.disconnect("p.pa", "c.r").expect("disconnect");
    assert_eq!(r.read(), None, "a disconnected poster input reads nothing");
    pair.system.connect("p.pb", "c.r").expect("pb");
    assert!(!r.is_new(), "pb has posted nothing yet");
    pb.post(100);
    assert!(r.is_new(), "the new producer's first post is new");
    assert_eq!(
        r.take_new(),
        Some(100),
        "the new producer's first post is new"
    );
    assert_eq!(r.take_new(), None);
    // Back to pa, whose latest post (4, sequence 5) was read from the old source:
    // it is new for the new source.
    pair.system
        .disconnect("p.pb", "c.r")
        .expect("disconnect pb");
    pair.system.connect("p.pa", "c.r").expect("pa again");
    assert!(r.is_new());
    assert_eq!(r.take_new(), Some(4));
    assert!(!r.is_new());
}

#[test]
fn a_counted_subscription_counts_what_it_was_sent_and_what_it_lost() {
    let (mut pair, (out, _), q) = Pair::new(out_p("p"), fifo1_c("c"));
    pair.system.connect("p.out", "c.q").expect("connect");
    let handle = pair.system.handle("c").unwrap();
    let (keeps_up, falls_behind) = (handle.subscribe_counted(), handle.subscribe_counted());
    let before = handle.snapshot().dropped_events;
    let sent = coolbot::OBSERVER_CAPACITY as u64 + 250;
    // One packet fills the queue; every other one overflows and is announced: one
    // event each. `keeps_up` reads as they come; `falls_behind` never reads.
    let mut got = 0;
    for packet in 0..=sent {
        out.send(packet);
        got += keeps_up.try_iter().count() as u64;
    }
    assert_eq!(q.overflows(), sent);
    assert_eq!(
        (keeps_up.published(), keeps_up.dropped(), got),
        (sent, 0, sent)
    );
    assert_eq!(falls_behind.published(), sent);
    assert_eq!(falls_behind.dropped(), 250, "its own losses, counted");
    assert_eq!(
        falls_behind.events().try_iter().count() as u64 + falls_behind.dropped(),
        sent
    );
    assert_eq!(handle.snapshot().dropped_events - before, 250);
}
