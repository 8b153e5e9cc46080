//! Bytes a broken or hostile peer puts on a bridge's keys, from a raw Zenoh session:
//! a packet followed by anything, the bytes of another type, a payload over the
//! inlet's bound, numbers that jump and ended epochs that never were. Each is counted
//! (at the inlet's `network` input, or as one reset at its `resets` input) and nothing
//! reaches the consumer that an outlet did not send.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use coolbot::crossbeam_channel::{self, Receiver, Sender};
use coolbot::{Component, Handle, Monitor, MonitorEvent, OutputKind, System};
use coolbot_zenoh::Node;
use coolbot_zenoh_tests::generated::types::Pose;
use coolbot_zenoh_tests::generated::{goal, reader, small_queue, ticks};
use coolbot_zenoh_tests::support::{Hand, PATIENCE, pair, wait_subscribed, wait_until};
use zenoh::Wait;

fn pose(seq: u64) -> Pose {
    Pose {
        x: seq as f64 / 2.0,
        seq,
    }
}

/// A numbered data message, as an outlet of `epoch` sends its `seq`-th.
fn numbered(epoch: u64, seq: u64) -> Vec<u8> {
    postcard::to_allocvec(&(epoch, seq, pose(seq))).unwrap()
}

/// A tick message, as an outlet of `epoch` sends its `seq`-th carrying `events`.
fn ticks(epoch: u64, seq: u64, events: u64) -> Vec<u8> {
    postcard::to_allocvec(&(epoch, seq, events)).unwrap()
}

/// `bytes` with `more` after them.
fn followed(mut bytes: Vec<u8>, more: &[u8]) -> Vec<u8> {
    bytes.extend_from_slice(more);
    bytes
}

/// The consumer's system: `inlet` into `sink` (built by `sink`, connected at
/// `sink_input`), running; the sink's input port.
fn consumer<P>(
    inlet: Component,
    sink: impl FnOnce(Sender<P>) -> Component,
    sink_input: &str,
) -> (System, P) {
    let mut system = System::new();
    system.add(inlet).unwrap();
    let (hand, handed) = crossbeam_channel::bounded(1);
    system.add(sink(hand)).unwrap();
    system.connect("inlet.output", sink_input).unwrap();
    system.run_all().unwrap();
    let port = handed
        .recv_timeout(PATIENCE)
        .expect("the sink hands its port over when it starts");
    (system, port)
}

/// Put `bytes` on `key` from `node`'s session, as any peer may.
fn put(node: &Node, key: &str, bytes: Vec<u8>) {
    node.session().put(key, bytes).wait().unwrap();
}

/// Wait until the inlet's counts at `network` and `resets` are these.
fn counted(inlet: &Handle, network: u64, resets: u64) -> Monitor {
    inlet
        .wait_for(
            |m| {
                m.port_overflows
                    == [
                        ("network".to_owned(), network),
                        ("resets".to_owned(), resets),
                    ]
            },
            PATIENCE,
        )
        .unwrap_or_else(|_| {
            panic!(
                "expected {network} at `network`, {resets} at `resets`: {:?}",
                inlet.snapshot().port_overflows
            )
        })
}

/// The `Overflow` events among `events` now, as `(port, lost)`.
fn overflows(events: &Receiver<MonitorEvent>) -> Vec<(String, u64)> {
    events
        .try_iter()
        .filter_map(|event| match event {
            MonitorEvent::Overflow { port, lost, .. } => Some((port, lost)),
            _ => None,
        })
        .collect()
}

#[test]
fn a_packet_with_trailing_bytes_or_of_another_type_is_counted_and_not_delivered() {
    let (a, b) = pair("trailing-a", "trailing-b");
    let key = "test/hostile/trailing";
    let inlet = b
        .inlet::<Pose>("inlet", key, OutputKind::Data)
        .max_payload(32)
        .build()
        .unwrap();
    let (consumer, sink) = consumer(
        inlet,
        |hand| small_queue::component("sink", Hand(hand)),
        "sink.input",
    );
    let inlet = consumer.handle("inlet").unwrap();
    let events = inlet.subscribe();
    wait_subscribed(&a, key);

    // A valid message with anything after it.
    put(&a, key, followed(numbered(7, 1), &[0]));
    // Another type whose first bytes make a `Pose` (three floats: `x`, then `seq`
    // from the first byte of the second).
    put(
        &a,
        key,
        postcard::to_allocvec(&(7u64, 1u64, (1.0f64, 2.0f64, 3.0f64))).unwrap(),
    );
    // A valid message over the inlet's bound (32 bytes).
    let long = postcard::to_allocvec(&(u64::MAX, u64::MAX, pose(u64::MAX))).unwrap();
    assert!(long.len() > 32, "{} bytes", long.len());
    put(&a, key, long);
    counted(&inlet, 3, 0);

    // A good one still goes through, and is the only packet the sink gets.
    put(&a, key, numbered(7, 1));
    assert!(wait_until(PATIENCE, || !sink.is_empty()));
    assert_eq!(sink.drain().collect::<Vec<_>>(), [pose(1)]);
    let monitor = counted(&inlet, 3, 0);
    assert_eq!(monitor.overflows, 3);
    let mut seen = Vec::new();
    assert!(wait_until(PATIENCE, || {
        seen.extend(overflows(&events));
        seen.len() >= 3
    }));
    assert_eq!(
        seen,
        vec![("network".to_owned(), 1); 3],
        "an event per packet"
    );
}

#[test]
fn trailing_bytes_on_poster_and_tick_keys_are_counted_and_not_delivered() {
    let (a, b) = pair("trailing-kinds-a", "trailing-kinds-b");
    let (posters, events_key) = ("test/hostile/poster", "test/hostile/ticks");
    let (poster_side, reader) = consumer(
        b.inlet::<Pose>("inlet", posters, OutputKind::Poster)
            .build()
            .unwrap(),
        |hand| reader::component("sink", Hand(hand)),
        "sink.input",
    );
    let (tick_side, tick_sink) = consumer(
        b.inlet::<()>("inlet", events_key, OutputKind::Tick)
            .build()
            .unwrap(),
        |hand| ticks::component("sink", Hand(hand)),
        "sink.input",
    );
    wait_subscribed(&a, posters);
    wait_subscribed(&a, events_key);

    put(&a, posters, followed(numbered(7, 1), &[0; 8]));
    put(&a, events_key, followed(ticks(7, 1, 5), &[1]));
    // Longer than any tick message (three `u64`s), though it decodes as one.
    put(&a, events_key, followed(ticks(7, 1, 5), &[0; 40]));
    counted(&poster_side.handle("inlet").unwrap(), 1, 0);
    counted(&tick_side.handle("inlet").unwrap(), 2, 0);

    put(&a, posters, numbered(7, 2));
    put(&a, events_key, ticks(7, 1, 3));
    assert!(wait_until(PATIENCE, || reader.read() == Some(pose(2))));
    let mut total = 0;
    assert!(wait_until(PATIENCE, || {
        total += tick_sink.take();
        total >= 3
    }));
    assert_eq!(total, 3, "only the good message's events");
    counted(&poster_side.handle("inlet").unwrap(), 1, 0);
    counted(&tick_side.handle("inlet").unwrap(), 2, 0);
}

#[test]
fn a_pull_answer_with_trailing_bytes_is_counted_and_not_delivered() {
    let (a, b) = pair("pull-answer-a", "pull-answer-b");
    let key = "test/hostile/pull";
    // A peer answering every pull with a pose and one byte more.
    let answers = Arc::new(AtomicU64::new(0));
    let answered = Arc::clone(&answers);
    let _queryable = a
        .session()
        .declare_queryable(format!("{key}/@pull"))
        .callback(move |query| {
            let bytes = followed(numbered(7, 0), &[0]);
            if query.reply(query.key_expr().clone(), bytes).wait().is_ok() {
                answered.fetch_add(1, Ordering::SeqCst);
            }
        })
        .wait()
        .unwrap();
    let (consumer, goal) = consumer(
        b.inlet::<Pose>("inlet", key, OutputKind::Data)
            .pull(Duration::from_secs(5))
            .build()
            .unwrap(),
        |hand| goal::component("sink", Hand(hand)),
        "sink.goal",
    );
    let inlet = consumer.handle("inlet").unwrap();
    // The queryable may not be known on the consumer's node yet: ask until answered.
    assert!(wait_until(PATIENCE, || {
        if answers.load(Ordering::SeqCst) == 0 {
            let _ = goal.request();
        }
        inlet.snapshot().overflows > 0
    }));
    // Every answer counted (a request sent before the first answer may bring one
    // more), none delivered.
    assert!(wait_until(PATIENCE, || {
        inlet.snapshot().port_overflows
            == [
                ("network".to_owned(), answers.load(Ordering::SeqCst)),
                ("resets".to_owned(), 0),
            ]
    }));
    assert_eq!(goal.latest(), None);
}

#[test]
fn a_forged_jump_in_the_numbers_is_one_reset_not_a_count_of_missing_packets() {
    let (a, b) = pair("jump-a", "jump-b");
    let key = "test/hostile/jump";
    let (consumer, sink) = consumer(
        b.inlet::<Pose>("inlet", key, OutputKind::Data)
            .build()
            .unwrap(),
        |hand| small_queue::component("sink", Hand(hand)),
        "sink.input",
    );
    let inlet = consumer.handle("inlet").unwrap();
    let events = inlet.subscribe();
    wait_subscribed(&a, key);
    // Outlet 7 sends 1 and 2; a peer puts number 10^12 of the same epoch; outlet 7
    // goes on with 3 and 5 (4 lost on the way).
    for seq in [1, 2, 1_000_000_000_000, 3, 5] {
        put(&a, key, numbered(7, seq));
    }
    let mut received = Vec::new();
    assert!(wait_until(PATIENCE, || {
        received.extend(sink.drain().map(|p| p.seq));
        received.len() == 5
    }));
    assert_eq!(received, [1, 2, 1_000_000_000_000, 3, 5]);
    let monitor = counted(&inlet, 1, 1);
    assert_eq!(monitor.overflows, 2);
    let mut seen = Vec::new();
    assert!(wait_until(PATIENCE, || {
        seen.extend(overflows(&events));
        seen.len() == 2
    }));
    seen.sort();
    assert_eq!(seen, [("network".to_owned(), 1), ("resets".to_owned(), 1)]);
}

/// Ask the inlets of `key` what they have had, from `node`, as an outlet does,
/// with `report` as the question's report of ended epochs: their answers.
fn question(node: &Node, key: &str, report: Vec<u8>) -> usize {
    let replies = node
        .session()
        .get(format!("{key}/@ack/**"))
        .payload(report)
        .timeout(Duration::from_secs(5))
        .wait()
        .unwrap();
    let mut answers = 0;
    while let Ok(reply) = replies.recv() {
        answers += usize::from(reply.result().is_ok());
    }
    answers
}

#[test]
fn a_forged_report_of_an_ended_epoch_is_one_reset_however_often_it_is_asked() {
    let (a, b) = pair("report-a", "report-b");
    let key = "test/hostile/report";
    let (consumer, sink) = consumer(
        b.inlet::<Pose>("inlet", key, OutputKind::Data)
            .build()
            .unwrap(),
        |hand| small_queue::component("sink", Hand(hand)),
        "sink.input",
    );
    let inlet = consumer.handle("inlet").unwrap();
    let events = inlet.subscribe();
    wait_subscribed(&a, key);
    for seq in 1..=3 {
        put(&a, key, numbered(7, seq));
    }
    assert!(wait_until(PATIENCE, || sink.len() == 3));
    // The inlet's acknowledgment queryable may not be known on `a` yet.
    let report = |ended: &[(u64, u64)]| postcard::to_allocvec(&ended.to_vec()).unwrap();
    assert!(wait_until(PATIENCE, || question(&a, key, report(&[])) == 1));

    // Epoch 7 said to have ended at 10^12, three times (an outlet repeats its
    // report every round): one reset. An epoch the inlet never had: nothing.
    for _ in 0..3 {
        let forged = report(&[(7, 1_000_000_000_000), (8, 1 << 40)]);
        assert_eq!(question(&a, key, forged), 1);
    }
    counted(&inlet, 0, 1);
    // A report with a byte after it is no report.
    assert_eq!(question(&a, key, followed(report(&[(7, 10)]), &[0])), 1);
    // A report within reach counts what the inlet never received: 4 to 10.
    assert_eq!(question(&a, key, report(&[(7, 10)])), 1);
    let monitor = counted(&inlet, 7, 1);
    assert_eq!(monitor.overflows, 8);
    let mut seen = Vec::new();
    assert!(wait_until(PATIENCE, || {
        seen.extend(overflows(&events));
        seen.len() == 2
    }));
    assert_eq!(seen, [("resets".to_owned(), 1), ("network".to_owned(), 7)]);
}
