//! Port bridges between two nodes on loopback: every connection kind keeps its
//! semantics and cardinality across the network, pull is a query, and no packet is
//! lost without a counter and an event.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use coolbot::crossbeam_channel::{self, Receiver, Sender};
use coolbot::port::{DataOut, FifoIn};
use coolbot::{Component, InputKind, MonitorEvent, OutputKind, OverflowPolicy, System};
use coolbot_zenoh::{Error, Node};
use coolbot_zenoh_tests::generated::types::Pose;
use coolbot_zenoh_tests::generated::{
    blocking_queue, goal, growing_queue, latest, pose_source, poster_source, pull_source, queue,
    reader, small_queue, tick_source, ticks, tiny_queue, two_source, wide_queue,
};
use coolbot_zenoh_tests::support::{self, Hand, PATIENCE, pair, wait_subscribed, wait_until};
use zenoh::Wait;

fn pose(seq: u64) -> Pose {
    Pose {
        x: seq as f64 / 2.0,
        seq,
    }
}

/// `system` with `component` added (its behaviour a [`Hand`] of `hand`), run; and
/// what the component handed over when it started.
fn started<T>(
    mut system: System,
    component: impl FnOnce(Sender<T>) -> Component,
    connect: (&str, &str),
) -> (System, T) {
    let (hand, handed) = crossbeam_channel::bounded(1);
    system.add(component(hand)).unwrap();
    system.connect(connect.0, connect.1).unwrap();
    system.run_all().unwrap();
    let port = handed
        .recv_timeout(PATIENCE)
        .expect("the component hands its port over when it starts");
    (system, port)
}

/// Producer side: `source.out` (data) into an outlet of `kind` on `key`.
fn data_producer(node: &Node, key: &str, kind: InputKind) -> (System, DataOut<Pose>) {
    let mut system = System::new();
    system
        .add(node.outlet::<Pose>("outlet", key, kind).build().unwrap())
        .unwrap();
    started(
        system,
        |hand| pose_source::component("source", Hand(hand)),
        ("source.out", "outlet.input"),
    )
}

/// Consumer side: an inlet of `kind` on `key` into `sink.input`, the sink built by
/// `sink` (from `cool/bridges.cool`); and the sink's input port.
fn consumer<P>(
    node: &Node,
    key: &str,
    kind: OutputKind,
    sink: impl FnOnce(Sender<P>) -> Component,
) -> (System, P) {
    let mut system = System::new();
    system
        .add(node.inlet::<Pose>("inlet", key, kind).build().unwrap())
        .unwrap();
    started(system, sink, ("inlet.output", "sink.input"))
}

#[test]
fn fifo_packets_cross_in_order_and_none_is_lost() {
    let (a, b) = pair("fifo-a", "fifo-b");
    let key = "test/fifo";
    let (consumer, sink) = consumer(&b, key, OutputKind::Data, |hand| {
        wide_queue::component("sink", Hand(hand))
    });
    let (producer, out) = data_producer(
        &a,
        key,
        InputKind::Fifo {
            capacity: 64,
            policy: OverflowPolicy::Block,
        },
    );
    wait_subscribed(&a, key);
    for seq in 0..200 {
        out.send(pose(seq));
    }
    let mut received = Vec::new();
    while received.len() < 200 {
        match sink.recv_timeout(PATIENCE) {
            Some(packet) => received.push(packet),
            None => break,
        }
    }
    assert_eq!(received, (0..200).map(pose).collect::<Vec<_>>());
    let outlet = producer.handle("outlet").unwrap().snapshot();
    assert_eq!(outlet.overflows, 0, "{outlet:?}");
    assert_eq!(consumer.handle("sink").unwrap().snapshot().overflows, 0);
    assert!(producer.shutdown().clean());
    assert!(consumer.shutdown().clean());
}

#[test]
fn a_full_block_fifo_behind_an_inlet_holds_up_no_other_delivery_of_its_session() {
    let (a, b) = pair("held-a", "held-b");
    let (held_key, free_key) = ("test/held", "test/free");
    // Nothing reads `held`'s fifo of one: each packet after the first waits there
    // (100 ms), then is rejected and counted.
    let (held, _queue) = consumer(&b, held_key, OutputKind::Data, |hand| {
        blocking_queue::component("sink", Hand(hand))
    });
    let (free, free_queue) = consumer(&b, free_key, OutputKind::Data, |hand| {
        wide_queue::component("sink", Hand(hand))
    });
    let hop = InputKind::Fifo {
        capacity: 64,
        policy: OverflowPolicy::Reject,
    };
    let (held_producer, held_out) = data_producer(&a, held_key, hop);
    let (free_producer, free_out) = data_producer(&a, free_key, hop);
    wait_subscribed(&a, held_key);
    wait_subscribed(&a, free_key);
    const SENT: u64 = 20;
    for seq in 0..SENT {
        held_out.send(pose(seq));
    }
    let held_sink = held.handle("sink").unwrap();
    held_sink
        .wait_for(|m| m.overflows >= 1, PATIENCE)
        .expect("the second packet rejected after its wait");
    // The packet of the other bridge comes on the same link after the held ones: it
    // is delivered while they still wait, not after all of them.
    free_out.send(pose(7));
    let delivered = free_queue.recv_timeout(PATIENCE);
    let waited_out = held_sink.snapshot().overflows;
    assert_eq!(delivered, Some(pose(7)));
    assert!(
        waited_out < SENT - 1,
        "the other bridge's packet waited for every held packet's wait ({waited_out})"
    );
    // Every held packet is accounted for: one in the fifo, the others rejected after
    // their wait, none lost on the way.
    held_sink
        .wait_for(|m| m.overflows == SENT - 1, PATIENCE)
        .expect("every packet that found the fifo full rejected and counted");
    let inlet = held.handle("inlet").unwrap().snapshot();
    assert_eq!(inlet.overflows, 0, "{inlet:?}");
    assert!(held_producer.shutdown().clean());
    assert!(free_producer.shutdown().clean());
    assert!(held.shutdown().clean());
    assert!(free.shutdown().clean());
}

#[test]
fn a_full_remote_fifo_applies_its_own_policy_and_counts() {
    let (a, b) = pair("full-a", "full-b");
    let key = "test/full";
    // Nothing reads the sink: 4 packets fit, the 6 others are rejected and counted.
    let (consumer, sink) = consumer(&b, key, OutputKind::Data, |hand| {
        tiny_queue::component("sink", Hand(hand))
    });
    let events = consumer.handle("sink").unwrap().subscribe();
    // The outlet's own queue is only the hop to the network: room for all ten.
    let (producer, out) = data_producer(
        &a,
        key,
        InputKind::Fifo {
            capacity: 64,
            policy: OverflowPolicy::Reject,
        },
    );
    wait_subscribed(&a, key);
    for seq in 0..10 {
        out.send(pose(seq));
    }
    let sink_handle = consumer.handle("sink").unwrap();
    let monitor = sink_handle
        .wait_for(|m| m.overflows == 6, PATIENCE)
        .expect("six packets counted lost at the full input");
    assert_eq!(monitor.port_overflows, vec![("input".to_owned(), 6)]);
    assert_eq!(sink.len(), 4);
    // Each loss is counted, then announced: the sixth event may follow the count.
    let mut overflow_events = 0;
    assert!(
        wait_until(PATIENCE, || {
            overflow_events += events
                .try_iter()
                .filter(
                    |event| matches!(event, MonitorEvent::Overflow { port, .. } if port == "input"),
                )
                .count();
            overflow_events >= 6
        }),
        "{overflow_events} overflow events"
    );
    assert_eq!(overflow_events, 6);
    // received + overflows = sent
    assert_eq!(sink.drain().count() as u64 + monitor.overflows, 10);
    drop((producer, consumer));
}

#[test]
fn a_packet_that_does_not_decode_is_counted_at_the_inlet() {
    let (a, b) = pair("decode-a", "decode-b");
    let key = "test/decode";
    let (consumer, sink) = consumer(&b, key, OutputKind::Data, |hand| {
        latest::component("sink", Hand(hand))
    });
    let inlet = consumer.handle("inlet").unwrap();
    let events = inlet.subscribe();
    wait_subscribed(&a, key);
    // Not a postcard `Pose`: too short.
    a.session().put(key, vec![1u8]).wait().unwrap();
    let monitor = inlet
        .wait_for(|m| m.overflows == 1, PATIENCE)
        .expect("the undecodable packet counted");
    assert_eq!(
        monitor.port_overflows,
        vec![("network".to_owned(), 1), ("resets".to_owned(), 0)]
    );
    assert!(matches!(
        events.recv_timeout(PATIENCE),
        Ok(MonitorEvent::Overflow { ref port, lost: 1, total: 1 }) if port == "network"
    ));
    assert_eq!(sink.received(), 0);
    // A good one (numbered, as an outlet sends it) still goes through.
    a.session()
        .put(key, postcard::to_allocvec(&(7u64, 1u64, pose(3))).unwrap())
        .wait()
        .unwrap();
    assert!(wait_until(PATIENCE, || sink.latest() == Some(pose(3))));
}

#[test]
fn numbers_missing_on_the_way_are_counted_lost_at_the_inlet() {
    // Messages are numbered per outlet (its epoch): the inlet counts the numbers
    // missing between two it received, so a packet lost on the way is counted.
    let (a, b) = pair("gap-a", "gap-b");
    let key = "test/gap";
    let (consumer, sink) = consumer(&b, key, OutputKind::Data, |hand| {
        small_queue::component("sink", Hand(hand))
    });
    let inlet = consumer.handle("inlet").unwrap();
    wait_subscribed(&a, key);
    let put = |epoch: u64, seq: u64| {
        a.session()
            .put(
                key,
                postcard::to_allocvec(&(epoch, seq, pose(seq))).unwrap(),
            )
            .wait()
            .unwrap();
    };
    // Outlet 7 sends 1, 2, then 5 (3 and 4 lost); outlet 9 starts at 4 (what it
    // sent before the inlet was there is not the inlet's to count), then 5.
    for (epoch, seq) in [(7, 1), (7, 2), (7, 5), (9, 4), (9, 5)] {
        put(epoch, seq);
    }
    let mut received = Vec::new();
    assert!(wait_until(PATIENCE, || {
        received.extend(sink.drain().map(|p| p.seq));
        received.len() == 5
    }));
    assert_eq!(received, [1, 2, 5, 4, 5]);
    let monitor = inlet
        .wait_for(|m| m.overflows == 2, PATIENCE)
        .expect("the two missing numbers are counted");
    assert_eq!(
        monitor.port_overflows,
        vec![("network".to_owned(), 2), ("resets".to_owned(), 0)]
    );
}

#[test]
fn an_outlet_that_cannot_send_counts_its_packets() {
    let (a, _b) = pair("lonely-a", "lonely-b");
    // Nobody subscribes to this key.
    let (producer, out) = data_producer(&a, "test/nobody", InputKind::Last);
    let outlet = producer.handle("outlet").unwrap();
    let events = outlet.subscribe();
    for seq in 0..3 {
        out.send(pose(seq));
        // One at a time, so that the last input does not merge them (by design).
        outlet
            .wait_for(|m| m.overflows == seq + 1, PATIENCE)
            .expect("each unsent packet counted");
    }
    let lost: u64 = events
        .try_iter()
        .filter_map(|event| match event {
            MonitorEvent::Overflow { lost, .. } => Some(lost),
            _ => None,
        })
        .sum();
    assert_eq!(lost, 3);
}

#[test]
fn a_last_input_keeps_the_latest_packet() {
    let (a, b) = pair("last-a", "last-b");
    let key = "test/last";
    let (_consumer, sink) = consumer(&b, key, OutputKind::Data, |hand| {
        latest::component("sink", Hand(hand))
    });
    let (_producer, out) = data_producer(&a, key, InputKind::Last);
    wait_subscribed(&a, key);
    for seq in 1..=50 {
        out.send(pose(seq));
    }
    assert!(
        wait_until(PATIENCE, || sink.latest() == Some(pose(50))),
        "latest: {:?}",
        sink.latest()
    );
}

#[test]
fn a_late_poster_reader_gets_the_current_value() {
    let (a, b) = pair("poster-a", "poster-b");
    let key = "test/poster";
    let mut producer = System::new();
    producer
        .add(
            a.outlet::<Pose>("outlet", key, InputKind::Poster)
                .build()
                .unwrap(),
        )
        .unwrap();
    let (_producer, post) = started(
        producer,
        |hand| poster_source::component("source", Hand(hand)),
        ("source.out", "outlet.input"),
    );
    post.post(pose(7));
    // The outlet publishes (to nobody yet) and keeps the value for late readers.
    std::thread::sleep(Duration::from_millis(50));

    let (consumer, reader) = consumer(&b, key, OutputKind::Poster, |hand| {
        reader::component("sink", Hand(hand))
    });
    assert!(
        wait_until(PATIENCE, || reader.read() == Some(pose(7))),
        "the late reader did not get the posted value"
    );
    wait_subscribed(&a, key);
    post.post(pose(8));
    assert!(wait_until(PATIENCE, || reader.read() == Some(pose(8))));
    assert_eq!(consumer.handle("inlet").unwrap().snapshot().overflows, 0);
}

#[test]
fn tick_events_are_counted_never_lost() {
    let (a, b) = pair("tick-a", "tick-b");
    let key = "test/tick";
    let mut consumer = System::new();
    consumer
        .add(
            b.inlet::<()>("inlet", key, OutputKind::Tick)
                .build()
                .unwrap(),
        )
        .unwrap();
    let (consumer, ticks) = started(
        consumer,
        |hand| ticks::component("sink", Hand(hand)),
        ("inlet.output", "sink.input"),
    );

    let mut producer = System::new();
    producer
        .add(
            a.outlet::<()>("outlet", key, InputKind::Tick)
                .build()
                .unwrap(),
        )
        .unwrap();
    let (producer, emit) = started(
        producer,
        |hand| tick_source::component("source", Hand(hand)),
        ("source.out", "outlet.input"),
    );
    wait_subscribed(&a, key);
    for _ in 0..25 {
        emit.emit();
    }
    let mut total = 0;
    assert!(wait_until(PATIENCE, || {
        total += ticks.take();
        total == 25
    }));
    assert_eq!(producer.handle("outlet").unwrap().snapshot().overflows, 0);
    // A message claiming more events than an outlet ever sends is counted as lost,
    // not emitted.
    a.session()
        .put(key, postcard::to_allocvec(&(7u64, 1u64, u64::MAX)).unwrap())
        .wait()
        .unwrap();
    let inlet = consumer.handle("inlet").unwrap();
    inlet
        .wait_for(|m| m.overflows == 1, PATIENCE)
        .expect("the implausible count is counted");
    assert_eq!(ticks.take(), 0);
}

#[test]
fn a_pull_is_a_query_and_the_answer_a_reply() {
    let (a, b) = pair("pull-a", "pull-b");
    let key = "test/pull";
    // Producer: a pull output answering each request with the next pose.
    let answered = Arc::new(AtomicU64::new(0));
    let mut producer = System::new();
    producer
        .add(pull_source::component(
            "source",
            Answering(Arc::clone(&answered)),
        ))
        .unwrap();
    producer
        .add(
            a.outlet::<Pose>("outlet", key, InputKind::Last)
                .pull(Duration::from_secs(10))
                .build()
                .unwrap(),
        )
        .unwrap();
    producer.connect("source.out", "outlet.input").unwrap();
    producer.run_all().unwrap();

    // Consumer: a pull last input fed by a pull inlet.
    let mut consumer = System::new();
    consumer
        .add(
            b.inlet::<Pose>("inlet", key, OutputKind::Data)
                .pull(Duration::from_secs(10))
                .build()
                .unwrap(),
        )
        .unwrap();
    let (_consumer, goal) = started(
        consumer,
        |hand| goal::component("sink", Hand(hand)),
        ("inlet.output", "sink.goal"),
    );

    // The queryable on the producer's node may not be known yet: pull until answered.
    let mut first = None;
    assert!(wait_until(PATIENCE, || {
        first = goal.pull(Duration::from_secs(2)).ok();
        first.is_some()
    }));
    let first = first.unwrap();
    let second = goal.pull(PATIENCE).expect("a second answer");
    assert_eq!(second.seq, first.seq + 1, "one answer per request");
    assert_eq!(answered.load(Ordering::SeqCst), second.seq);
}

/// `PullSource`'s behaviour: answers each request with the next pose, counting them.
struct Answering(Arc<AtomicU64>);

impl pull_source::Behavior for Answering {
    fn answer_out(&mut self, _cx: &mut pull_source::Cx<'_>) -> Result<Pose, coolbot::Fault> {
        let n = self.0.fetch_add(1, Ordering::SeqCst) + 1;
        Ok(pose(n))
    }
}

/// The checks see the tokens a session knows of: wait until `node` knows one under
/// `pattern`.
fn wait_token(node: &Node, pattern: &str) {
    assert!(
        wait_until(PATIENCE, || {
            node.session()
                .liveliness()
                .get(pattern)
                .timeout(Duration::from_millis(500))
                .wait()
                .is_ok_and(|replies| replies.recv().is_ok())
        }),
        "no token under `{pattern}`"
    );
}

#[test]
fn connection_rules_hold_across_the_network() {
    let (a, b) = pair("rules-a", "rules-b");
    // A last connection has one producer.
    let _first = a
        .outlet::<Pose>("first", "test/rules/last", InputKind::Last)
        .build()
        .unwrap();
    wait_token(&b, "test/rules/last/@out/**");
    let error = b
        .outlet::<Pose>("second", "test/rules/last", InputKind::Last)
        .build();
    let rejected = |result: Result<Component, Error>| match result {
        Err(Error::Cardinality { rule, .. }) => rule,
        other => panic!("expected a cardinality error, got {other:?}"),
    };
    let rule = rejected(error);
    assert!(rule.contains("already has a producer"), "{rule}");
    // One key, one kind: a poster inlet cannot read a last connection.
    let rule = rejected(
        b.inlet::<Pose>("reader", "test/rules/last", OutputKind::Poster)
            .build(),
    );
    assert!(rule.contains("carries a last connection"), "{rule}");
    // A fifo connection has one input end.
    let _producer = a
        .outlet::<Pose>(
            "queue",
            "test/rules/fifo",
            InputKind::Fifo {
                capacity: 8,
                policy: OverflowPolicy::Reject,
            },
        )
        .build()
        .unwrap();
    let _reader = b
        .inlet::<Pose>("reader", "test/rules/fifo", OutputKind::Data)
        .build()
        .unwrap();
    wait_token(&a, "test/rules/fifo/@in/**");
    let rule = rejected(
        a.inlet::<Pose>("other", "test/rules/fifo", OutputKind::Data)
            .build(),
    );
    assert!(rule.contains("N outputs to 1 input"), "{rule}");
    // Bad keys and names are refused with a reason.
    assert!(matches!(
        a.outlet::<Pose>("x", "test/*", InputKind::Last).build(),
        Err(Error::InvalidName { .. })
    ));
    assert!(matches!(
        a.inlet::<Pose>("a.b", "test/ok", OutputKind::Data).build(),
        Err(Error::InvalidName { .. })
    ));
}

#[test]
fn a_node_name_is_unique_on_the_network() {
    let (a, endpoint) = support::node("unique", &[]);
    let config = coolbot_zenoh::peer_config(
        &[format!("tcp/127.0.0.1:{}", support::free_port())],
        &[endpoint],
        false,
    )
    .unwrap();
    // The second session may need a moment to learn the first one's token.
    let mut outcome = None;
    assert!(wait_until(PATIENCE, || {
        match Node::open("unique", config.clone()) {
            Err(Error::NodeNameTaken(name)) => {
                outcome = Some(name);
                true
            }
            _ => false,
        }
    }));
    assert_eq!(outcome.as_deref(), Some("unique"));
    assert_eq!(a.name(), "unique");
}

#[test]
fn when_the_consumer_node_goes_away_the_outlet_counts_every_packet() {
    let (a, b) = pair("gone-a", "gone-b");
    let key = "test/gone";
    let queue = InputKind::Fifo {
        capacity: 64,
        policy: OverflowPolicy::Reject,
    };
    let (consumer, sink) = consumer(&b, key, OutputKind::Data, |hand| {
        queue::component("sink", Hand(hand))
    });
    let (producer, out) = data_producer(&a, key, queue);
    wait_subscribed(&a, key);
    for seq in 0..5 {
        out.send(pose(seq));
    }
    for seq in 0..5 {
        assert_eq!(sink.recv_timeout(PATIENCE), Some(pose(seq)));
    }
    // The consumer's process goes away.
    assert!(consumer.shutdown().clean());
    drop(b);
    let outlet = producer.handle("outlet").unwrap();
    assert_eq!(outlet.snapshot().overflows, 0);
    // Once the outlet knows (Zenoh tells it the subscriber is gone), every packet is
    // counted: send until the first one is, then three more.
    let mut sent = 5;
    assert!(wait_until(PATIENCE, || {
        out.send(pose(sent));
        sent += 1;
        outlet
            .wait_for(|m| m.overflows > 0, Duration::from_millis(200))
            .is_ok()
    }));
    let before = outlet.snapshot().overflows;
    for seq in 0..3 {
        out.send(pose(100 + seq));
    }
    outlet
        .wait_for(|m| m.overflows == before + 3, PATIENCE)
        .expect("every packet after the link is gone is counted");
}

#[test]
fn a_remote_ufifo_grows_and_takes_every_packet_of_a_burst() {
    let (a, b) = pair("ufifo-a", "ufifo-b");
    let key = "test/ufifo";
    // Nothing reads the sink during the burst: it grows from 16.
    let kind = InputKind::Ufifo {
        initial: 16,
        max: None,
    };
    let (consumer, sink) = consumer(&b, key, OutputKind::Data, |hand| {
        growing_queue::component("sink", Hand(hand))
    });
    let (producer, out) = data_producer(&a, key, kind);
    wait_subscribed(&a, key);
    const BURST: u64 = 5_000;
    for seq in 0..BURST {
        out.send(pose(seq));
    }
    assert!(
        wait_until(PATIENCE, || sink.len() as u64 == BURST),
        "{} of {BURST} arrived",
        sink.len()
    );
    assert!(sink.growths() > 0);
    assert!(sink.drain().map(|p| p.seq).eq(0..BURST), "order kept");
    assert_eq!(producer.handle("outlet").unwrap().snapshot().overflows, 0);
    assert_eq!(consumer.handle("sink").unwrap().snapshot().overflows, 0);
}

#[test]
fn when_the_consumer_node_comes_back_packets_flow_again() {
    // The consumer listens, the producer connects to it (and retries when it goes).
    let endpoint = format!("tcp/127.0.0.1:{}", support::free_port());
    let listening = |name: &str| {
        let config =
            coolbot_zenoh::peer_config(std::slice::from_ref(&endpoint), &[], false).unwrap();
        Node::open(name, config)
            .expect("consumer node")
            .with_state_directory(None)
    };
    let b = listening("back-b");
    let (a, _) = support::node("back-a", std::slice::from_ref(&endpoint));
    let key = "test/back";
    let queue = InputKind::Fifo {
        capacity: 64,
        policy: OverflowPolicy::Reject,
    };
    let (producer, out) = data_producer(&a, key, queue);
    let (first_consumer, first) = consumer(&b, key, OutputKind::Data, |hand| {
        queue::component("sink", Hand(hand))
    });
    wait_subscribed(&a, key);
    out.send(pose(1));
    assert_eq!(first.recv_timeout(PATIENCE), Some(pose(1)));

    // The consumer's process goes away, then comes back on the same endpoint.
    assert!(first_consumer.shutdown().clean());
    drop(b);
    let b = listening("back-b");
    let (_consumer, again) = consumer(&b, key, OutputKind::Data, |hand| {
        queue::component("sink", Hand(hand))
    });
    wait_subscribed(&a, key);
    // The producer's node may still see the old subscriber for a moment (its
    // matching status lags the broken session), and a packet sent then goes nowhere
    // (the gap docs/distribution.md names). Send until one arrives.
    let deadline = std::time::Instant::now() + PATIENCE;
    let mut sent = 1;
    let received = loop {
        sent += 1;
        out.send(pose(sent));
        if let Some(packet) = again.recv_timeout(Duration::from_millis(200)) {
            break packet;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "no packet arrived after the consumer came back ({} sent)",
            sent - 1
        );
    };
    assert!(received.seq >= 2, "{received:?}");
    assert!(producer.shutdown().clean());
}

/// The producer's node connects to the consumer's through a forwarder the test can
/// cut. While the link is down the producer posts a new value (and sends a new latest
/// packet to a remote `last` input); when the link comes back the readers ask for
/// the current values again and get them, without another post or send.
#[test]
fn poster_and_last_readers_ask_again_when_the_link_comes_back() {
    let (b, b_endpoint) = support::node("relink-b", &[]);
    let target = b_endpoint
        .trim_start_matches("tcp/")
        .parse()
        .expect("an address");
    let forwarder = support::Forwarder::start(target);
    let (a, _) = support::node("relink-a", std::slice::from_ref(&forwarder.endpoint));
    let sees = |node: &Node, other: &str| {
        let key = format!("coolbot/{other}");
        node.session()
            .liveliness()
            .get(&key)
            .timeout(Duration::from_millis(300))
            .wait()
            .expect("liveliness query")
            .recv()
            .is_ok()
    };
    assert!(wait_until(PATIENCE, || sees(&a, "relink-b")));

    // A poster connection and a data connection to a remote `last` input.
    let mut producer = System::new();
    let (post, data) = crossbeam_channel::bounded(1);
    producer
        .add(two_source::component("source", Hand(post)))
        .unwrap();
    for (name, key, kind) in [
        ("poster-outlet", "test/relink/poster", InputKind::Poster),
        ("last-outlet", "test/relink/last", InputKind::Last),
    ] {
        producer
            .add(a.outlet::<Pose>(name, key, kind).build().unwrap())
            .unwrap();
    }
    producer
        .connect("source.post", "poster-outlet.input")
        .unwrap();
    producer
        .connect("source.data", "last-outlet.input")
        .unwrap();
    producer.run_all().unwrap();
    let (post, data) = data
        .recv_timeout(PATIENCE)
        .expect("the source hands its ports over when it starts");
    let (_posters, reader) = consumer(&b, "test/relink/poster", OutputKind::Poster, |hand| {
        reader::component("sink", Hand(hand))
    });
    let (_lasts, latest) = consumer(&b, "test/relink/last", OutputKind::Data, |hand| {
        latest::component("sink", Hand(hand))
    });
    // Both readers subscribed, as seen from the producer's node: a post published
    // before its subscription reaches the producer would not reach a reader that had
    // already asked for the (then empty) current value.
    wait_subscribed(&a, "test/relink/poster");
    wait_subscribed(&a, "test/relink/last");
    post.post(pose(1));
    data.send(pose(1));
    assert!(wait_until(PATIENCE, || reader.read() == Some(pose(1))
        && latest.latest() == Some(pose(1))));

    // The link goes down; the producer posts and sends meanwhile.
    forwarder.cut();
    assert!(
        wait_until(PATIENCE, || !sees(&a, "relink-b")),
        "the producer still sees the consumer"
    );
    post.post(pose(2));
    data.send(pose(2));
    // The link comes back: the readers get the current values.
    forwarder.restore();
    assert!(
        wait_until(PATIENCE, || reader.read() == Some(pose(2))
            && latest.latest() == Some(pose(2))),
        "after the link came back: poster {:?}, last {:?}",
        reader.read(),
        latest.latest()
    );
    assert!(producer.shutdown().clean());
}

/// An outlet keeps its tally in its node's state directory (here a temporary one),
/// except on a remote placement's keys: new at every placement, no process started
/// again would read it.
#[test]
fn an_outlet_keeps_a_tally_except_on_a_remote_placements_keys() {
    let state = tempfile::tempdir().unwrap();
    let (node, _) = support::node("tallied", &[]);
    let node = node.with_state_directory(Some(state.path().to_path_buf()));
    let queue = InputKind::Fifo {
        capacity: 4,
        policy: OverflowPolicy::Reject,
    };
    let _kept = node
        .outlet::<Pose>("kept", "test/tallied", queue)
        .build()
        .unwrap();
    let _linked = node
        .outlet::<Pose>(
            "linked",
            "coolbot-link/elsewhere/tallied-cell-arm-1/in/input",
            queue,
        )
        .build()
        .unwrap();
    let files = std::fs::read_dir(state.path().join("tallied"))
        .unwrap()
        .count();
    assert_eq!(files, 1, "the tally of `test/tallied` only");
}

/// Send `pose(seq)` for `seqs` one at a time, each taken from `sink` before the next.
fn one_by_one(out: &DataOut<Pose>, sink: &FifoIn<Pose>, seqs: std::ops::Range<u64>) {
    for seq in seqs {
        out.send(pose(seq));
        assert_eq!(sink.recv_timeout(PATIENCE), Some(pose(seq)));
    }
}

#[test]
fn a_queue_bridge_to_a_consumer_on_this_host_goes_through_a_ring() {
    let (a, b) = pair("ring-a", "ring-b");
    let key = "test/ring";
    let (consumer, sink) = consumer(&b, key, OutputKind::Data, |hand| {
        wide_queue::component("sink", Hand(hand))
    });
    let (producer, out) = data_producer(
        &a,
        key,
        InputKind::Fifo {
            capacity: 64,
            policy: OverflowPolicy::Block,
        },
    );
    wait_subscribed(&a, key);
    // On the key until the inlet's answer is adopted, then by the ring.
    let mut seq = 0;
    assert!(
        wait_until(PATIENCE, || {
            one_by_one(&out, &sink, seq..seq + 1);
            seq += 1;
            a.shared_memory().ring_written > 0
        }),
        "the outlet never wrote into a ring"
    );
    let before = (a.shared_memory(), b.shared_memory());
    one_by_one(&out, &sink, seq..seq + 100);
    // A burst the sink's fifo holds, written by the producer's thread.
    let burst = seq + 100..seq + 300;
    for n in burst.clone() {
        out.send(pose(n));
    }
    for n in burst {
        assert_eq!(sink.recv_timeout(PATIENCE), Some(pose(n)));
    }
    let (written, taken) = (
        a.shared_memory().ring_written - before.0.ring_written,
        b.shared_memory().ring_taken - before.1.ring_taken,
    );
    assert_eq!((written, taken), (300, 300));
    let outlet = producer.handle("outlet").unwrap().snapshot();
    assert_eq!(outlet.overflows, 0, "{outlet:?}");
    assert_eq!(consumer.handle("sink").unwrap().snapshot().overflows, 0);
    let inlet = consumer.handle("inlet").unwrap().snapshot();
    assert_eq!(inlet.overflows, 0, "{inlet:?}");
    assert!(producer.shutdown().clean());
    assert!(consumer.shutdown().clean());
}

/// A consumer whose thread is held in its entry section until the test lets it go,
/// with a ufifo input it hands over (nothing it takes is lost).
struct Held {
    gate: Receiver<()>,
    /// Set when it leaves its entry section.
    left: Arc<std::sync::atomic::AtomicBool>,
}

impl Held {
    fn new(gate: Receiver<()>) -> Held {
        Held {
            gate,
            left: Arc::default(),
        }
    }
}

impl coolbot::Automaton for Held {
    fn spec(&self) -> &'static coolbot::Spec {
        static INPUTS: [coolbot::InputSpec; 1] = [coolbot::InputSpec {
            name: "input",
            kind: InputKind::Ufifo {
                initial: 64,
                max: None,
            },
            packet: "Pose",
            pull: false,
        }];
        static SPEC: coolbot::Spec = coolbot::Spec {
            type_name: "Held",
            doc: "Enters its state when the test lets it.",
            states: &[coolbot::StateSpec {
                name: "held",
                entry: true,
                exit: false,
                periodic: None,
                on: &[],
                after: &[],
                may: &[],
            }],
            initial: 0,
            inputs: &INPUTS,
            outputs: &[],
            variables: &[],
            exceptions: &[],
            timing: coolbot::TimingSpec::NONE,
        };
        &SPEC
    }

    fn section(
        &mut self,
        _state: usize,
        section: coolbot::Section,
        _cx: &mut coolbot::Context,
    ) -> Result<(), coolbot::Fault> {
        if section == coolbot::Section::Entry {
            let _ = self.gate.recv_timeout(PATIENCE);
            self.left.store(true, Ordering::Release);
        }
        Ok(())
    }
}

/// A consumer system: an inlet of `key` whose output goes to the first of `held`
/// (each a component with a ufifo input), all running.
fn held_consumers(
    node: &Node,
    key: &str,
    held: Vec<(&str, Held, &coolbot::port::UfifoIn<Pose>)>,
) -> System {
    let mut consumer = System::new();
    consumer
        .add(
            node.inlet::<Pose>("inlet", key, OutputKind::Data)
                .build()
                .unwrap(),
        )
        .unwrap();
    let first = held[0].0;
    for (name, component, input) in held {
        consumer
            .add(Component::new(
                name,
                Box::new(component),
                coolbot::PortSet::new().input(input),
            ))
            .unwrap();
    }
    consumer
        .connect("inlet.output", &format!("{first}.input"))
        .unwrap();
    consumer.run_all().unwrap();
    consumer
}

/// Packets sent past a ring's adoption, more than a ring of 64 KiB holds.
const MORE: u64 = 5000;

/// A producer on `key` whose outlet's input holds 8,192 packets, streaming to a
/// consumer that takes nothing: on the key until the ring is adopted (delivered
/// without the consumer's thread), then [`MORE`] packets, which fill the ring, the
/// rest waiting at the outlet. Returns the producer, its output and the packets sent.
fn filling_ring(node: &Node, key: &str) -> (System, DataOut<Pose>, u64) {
    let (producer, out) = data_producer(
        node,
        key,
        InputKind::Fifo {
            capacity: 8192,
            policy: OverflowPolicy::Block,
        },
    );
    wait_subscribed(node, key);
    let mut seq = 0;
    assert!(
        wait_until(PATIENCE, || {
            out.send(pose(seq));
            seq += 1;
            node.shared_memory().ring_written > 0
        }),
        "the outlet never wrote into a ring"
    );
    for n in seq..seq + MORE {
        out.send(pose(n));
    }
    (producer, out, seq + MORE)
}

#[test]
fn a_full_ring_holds_the_packets_at_the_outlet_until_the_consumer_takes() {
    let (a, b) = pair("full-a", "full-b");
    let key = "test/full-ring";
    let (open, gate) = crossbeam_channel::bounded::<()>(0);
    let input = coolbot::port::UfifoIn::<Pose>::new(64, None);
    let consumer = held_consumers(&b, key, vec![("held", Held::new(gate), &input)]);
    let (producer, _out, total) = filling_ring(&a, key);
    // Nothing is taken from the ring while the consumer is held: it fills, and the
    // rest waits at the outlet.
    let written = a.shared_memory().ring_written;
    assert!(written < MORE, "{written} messages in a ring of 64 KiB");
    open.send(()).expect("the consumer is held");
    let received = received_until(&input, total - 1);
    assert_eq!(received, (0..total).collect::<Vec<_>>());
    let outlet = producer.handle("outlet").unwrap().snapshot();
    assert_eq!(outlet.overflows, 0, "{outlet:?}");
    let inlet = consumer.handle("inlet").unwrap().snapshot();
    assert_eq!(inlet.overflows, 0, "{inlet:?}");
    assert!(a.shared_memory().ring_written >= MORE);
    assert!(producer.shutdown().clean());
    assert!(consumer.shutdown().clean());
}

/// Take packets from `input` until `last` arrives (or the patience runs out).
fn received_until(input: &coolbot::port::UfifoIn<Pose>, last: u64) -> Vec<u64> {
    let mut received = Vec::new();
    let deadline = std::time::Instant::now() + PATIENCE;
    while received.last() != Some(&last) && std::time::Instant::now() < deadline {
        match input.recv() {
            Some(packet) => received.push(packet.seq),
            None => std::thread::sleep(Duration::from_millis(1)),
        }
    }
    received
}

#[test]
fn a_ring_follows_its_inlet_to_a_new_consumer_when_the_old_one_is_stuck() {
    let (a, b) = pair("moved-a", "moved-b");
    let key = "test/moved-ring";
    // `stuck` never leaves its entry section while the test runs; `spare` has no
    // gate to wait for.
    let (hold, stuck_gate) = crossbeam_channel::bounded::<()>(0);
    let (_, spare_gate) = crossbeam_channel::bounded::<()>(0);
    let stuck_input = coolbot::port::UfifoIn::<Pose>::new(64, None);
    let spare_input = coolbot::port::UfifoIn::<Pose>::new(64, None);
    let stuck = Held::new(stuck_gate);
    let stuck_left = Arc::clone(&stuck.left);
    let mut consumer = held_consumers(
        &b,
        key,
        vec![
            ("stuck", stuck, &stuck_input),
            ("spare", Held::new(spare_gate), &spare_input),
        ],
    );
    // More than the ring holds: the rest waits at the outlet for the stuck consumer.
    let (producer, out, seq) = filling_ring(&a, key);
    // The output goes to `spare` now, as a substitution moves it. While it feeds
    // both, the ring stays on `stuck`'s bell; once it no longer feeds `stuck`, the
    // ring is handed over before `disconnect` returns.
    let full = b.shared_memory().ring_taken;
    consumer.connect("inlet.output", "spare.input").unwrap();
    assert_eq!(
        b.shared_memory().ring_taken,
        full,
        "the ring stays while the output still feeds `stuck`"
    );
    consumer.disconnect("inlet.output", "stuck.input").unwrap();
    let handed_over = b.shared_memory().ring_taken;
    assert!(
        handed_over > full,
        "what the ring held was delivered as it was handed over"
    );
    // Every packet reaches `spare` in order from the change on, through the key and
    // then through a ring on its own bell.
    const AFTER: u64 = 2000;
    for n in seq..seq + AFTER {
        out.send(pose(n));
    }
    let total = seq + AFTER;
    let received = received_until(&spare_input, total - 1);
    let from = *received.first().expect("spare received nothing");
    let in_order = received.iter().copied().eq(from..total);
    assert!(
        in_order,
        "spare took {} packets from {from} to {:?}, not every one to {}",
        received.len(),
        received.last(),
        total - 1
    );
    assert!(
        from < seq,
        "what waited in the ring and at the outlet went to spare (from {from})"
    );
    // Then through a ring on `spare`'s bell: taken by its thread (the old ring is
    // gone, and `stuck` takes nothing).
    let mut next = total;
    assert!(
        wait_until(PATIENCE, || {
            out.send(pose(next));
            assert_eq!(received_until(&spare_input, next).last(), Some(&next));
            next += 1;
            b.shared_memory().ring_taken > handed_over
        }),
        "no packet went through a ring of spare"
    );
    assert!(
        !stuck_left.load(Ordering::Acquire),
        "stuck was held all along (none of it was its thread's doing)"
    );
    let inlet = consumer.handle("inlet").unwrap().snapshot();
    assert_eq!(inlet.overflows, 0, "{inlet:?}");
    assert!(producer.shutdown().clean());
    drop(hold);
    assert!(consumer.shutdown().clean());
}
