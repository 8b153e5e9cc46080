//! Echoed outputs (`coolctl echo`): a node taps an output it was asked to echo
//! ([`crate::Node::echo`], a `coolbot::tap::Tap`) and publishes its packets as JSON,
//! from one thread of its own for all its echoes.
//!
//! A reader asks for an output by subscribing to its key,
//! `coolbot/<node>/<path>/o/<port>` ([`crate::keys::echo`]), and reads the packets on
//! the node's batch key, `coolbot/<node>/o` ([`crate::keys::echoes`]): every
//! [`ECHO_TICK`] the node publishes there one sample holding the packets every tapped
//! output sent since the last, a JSON array of [`Echoed`], each naming its output
//! (several samples if they take more than [`crate::limits::ECHO_BATCH`] together,
//! each within it: a packet over it alone, or one that does not serialize, is not
//! echoed: its place in the batch says why, with no packet, and the reader counts it
//! lost).
//! One sample a tick, however many outputs and packets, is what makes an echo cheap
//! to carry and to receive: Zenoh's costs are per sample.
//!
//! **Invariant:** the producer is never slowed. The tap is attached only while a
//! subscriber matches the output's key: an output nobody echoes costs its producer
//! nothing (attaching and detaching take the output's lock on its connections once
//! each). While attached, a packet costs its producer a clock reading and one copy
//! into the tap's queue, nothing more: the tap drops a packet its queue has no room
//! for (counted), and nothing ever waits on that queue, so the producer never wakes a
//! thread. The echo thread takes what every queue holds once per [`ECHO_TICK`],
//! writes each packet's JSON once, straight from its type, into the tick's batch, and
//! publishes the batch without waiting (congestion control `Drop`). Every packet
//! carries its sequence number and the node's drop count, so a subscriber counts
//! every packet it did not get, and the time it was sent, so that a reader places it
//! in time however it was batched.

use crate::locks::lock;
use std::borrow::Cow;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use coolbot::Handle;
use coolbot::port::Packet;
use coolbot::tap::Tap;
use crossbeam_channel::{RecvTimeoutError, Sender};
use serde::{Deserialize, Serialize};
use zenoh::Wait;

use crate::Error;

/// How many packets wait in an echo's tap before the newest are dropped.
pub const ECHO_CAPACITY: usize = 256;

/// How often the echo thread takes the packets the taps hold and publishes them: an
/// echoed output may send up to [`ECHO_CAPACITY`] packets in this time before any is
/// dropped. 50 batches a second: a live view's rate, and few enough wake-ups for
/// the node and its readers.
pub const ECHO_TICK: Duration = Duration::from_millis(20);

/// One echoed packet on the network, an element of a node's batch.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Echoed {
    /// The output, `<path>.<port>` (`robot.base.scan`).
    pub output: String,
    /// The packet's number among those the output sent since the tap was attached
    /// (when a first subscriber came; 0 first): a gap is packets this subscriber did
    /// not get.
    pub seq: u64,
    /// Packets the node dropped since the tap was attached because its queue was
    /// full.
    pub dropped: u64,
    /// When the output sent it (the node's wall clock, nanoseconds since the Unix
    /// epoch).
    pub sent: coolbot::Time,
    /// The packet, as serde writes it in JSON (`null` when it was not echoed).
    pub packet: serde_json::Value,
    /// Why the node did not echo this packet, if it did not (it does not serialize,
    /// or it is over [`crate::limits::ECHO_BATCH`] alone): the packet is lost, and a
    /// reader counts it so.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unsent: Option<String>,
}

/// An [`Echoed`] as the node writes it: the packet serialized from its own type.
#[derive(Serialize)]
struct Outgoing<'a, T> {
    output: &'a str,
    seq: u64,
    dropped: u64,
    sent: coolbot::Time,
    packet: &'a T,
    #[serde(skip_serializing_if = "Option::is_none")]
    unsent: Option<&'a str>,
}

/// What a reader takes of an [`Echoed`]: its output and numbers, and the packet's
/// JSON, checked and left as the node wrote it.
#[derive(Debug, Deserialize)]
pub(crate) struct EchoedRaw<'a> {
    /// The output, `<path>.<port>`.
    #[serde(borrow)]
    pub output: Cow<'a, str>,
    /// As in [`Echoed`].
    pub seq: u64,
    /// As in [`Echoed`].
    pub dropped: u64,
    /// As in [`Echoed`].
    #[cfg_attr(
        not(feature = "foxglove"),
        expect(dead_code, reason = "read by `coolctl foxglove` only")
    )]
    pub sent: coolbot::Time,
    /// The packet's JSON.
    #[serde(borrow)]
    pub packet: &'a serde_json::value::RawValue,
    /// As in [`Echoed`]: why the node did not echo this packet (lost).
    #[serde(default, borrow)]
    pub unsent: Option<Cow<'a, str>>,
}

/// The packets of one tick, written as JSON arrays of [`Echoed`] as they are taken,
/// each array within `max` bytes ([`crate::limits::ECHO_BATCH`], what a reader
/// decodes): a packet that would take the array over it closes the array and begins
/// the next, so a burst is published in several samples, none of which a reader
/// drops.
struct Batch {
    /// The array being written (unclosed).
    json: Vec<u8>,
    packets: usize,
    /// The arrays closed this tick.
    full: Vec<Vec<u8>>,
    max: usize,
}

impl Default for Batch {
    fn default() -> Batch {
        Batch::within(crate::limits::ECHO_BATCH.max)
    }
}

impl Batch {
    /// An empty batch whose arrays take at most `max` bytes each.
    fn within(max: usize) -> Batch {
        Batch {
            json: Vec::new(),
            packets: 0,
            full: Vec::new(),
            max,
        }
    }

    /// Append `packet`; on an error (it does not serialize, or its array alone would
    /// be over the bound), the batch holds the packets it held.
    fn push<T: Serialize>(&mut self, packet: &Outgoing<'_, T>) -> Result<(), String> {
        let start = self.json.len();
        self.json.push(if self.packets == 0 { b'[' } else { b',' });
        if let Err(error) = serde_json::to_writer(&mut self.json, packet) {
            self.json.truncate(start);
            return Err(format!("it does not serialize: {error}"));
        }
        // The array as it would be closed, `]` included.
        if self.json.len() < self.max {
            self.packets += 1;
            return Ok(());
        }
        if self.packets > 0 {
            // Close the array before it; it begins the next.
            let mut next = self.json.split_off(start);
            next[0] = b'[';
            self.json.push(b']');
            self.full.push(std::mem::replace(&mut self.json, next));
            self.packets = 0;
            if self.json.len() < self.max {
                self.packets = 1;
                return Ok(());
            }
        }
        let alone = self.json.len() + 1;
        self.json.clear();
        let bound = crate::limits::Limit {
            max: self.max,
            ..crate::limits::ECHO_BATCH
        };
        Err(bound
            .check(|| "its batch, with it alone".to_owned(), alone)
            .err()
            .map_or_else(
                || "it is over the bound".to_owned(),
                |over| over.to_string(),
            ))
    }

    /// Append `packet`, or, if it cannot be (it does not serialize, or it is over
    /// the bound alone), its place without it, saying why, so that a reader counts
    /// it lost even when no later packet of its output shows the gap. If it was not
    /// appended: why, and whether its place was.
    fn push_or_tell<T: Serialize>(
        &mut self,
        packet: &Outgoing<'_, T>,
    ) -> Result<(), (String, bool)> {
        let Err(error) = self.push(packet) else {
            return Ok(());
        };
        let why = coolbot::ranges::excerpt(&error, coolbot::ranges::REASON_CHARS);
        let told = self
            .push(&Outgoing {
                output: packet.output,
                seq: packet.seq,
                dropped: packet.dropped,
                sent: packet.sent,
                packet: &(),
                unsent: Some(&why),
            })
            .is_ok();
        Err((error, told))
    }

    /// The arrays of the tick, in order, none when no packet came; the batch is
    /// empty again.
    fn take(&mut self) -> Vec<Vec<u8>> {
        if self.packets > 0 {
            self.json.push(b']');
            self.packets = 0;
            self.full.push(std::mem::take(&mut self.json));
        }
        std::mem::take(&mut self.full)
    }
}

/// One echoed output: its tap while anyone listens.
trait Echoing: Send {
    /// Attach or detach the tap as a subscriber matches or not; append every packet
    /// the tap holds to `batch`.
    fn take(&mut self, batch: &mut Batch);

    /// Packets waiting in the tap.
    #[cfg(test)]
    fn waiting(&self) -> usize;

    /// Whether a subscriber matches, as last told.
    #[cfg(test)]
    fn matched(&self) -> bool;
}

struct Port<T> {
    /// `<path>.<port>`, as the batch names it.
    output: String,
    /// The output's own key, for the warnings.
    key: String,
    /// The component and its output's name, to attach the tap to.
    handle: Handle,
    port: String,
    /// Attached while a subscriber matches.
    tap: Option<Tap<T>>,
    /// Whether a subscriber matches the key, as Zenoh's matching listener last said.
    matched: Arc<AtomicBool>,
    /// Dropped before the publisher it listens to (fields drop in order): Zenoh logs
    /// an error for a listener whose publisher is gone.
    _listener: zenoh::matching::MatchingListener<()>,
    /// Declared on the output's key for its matching status only: the packets go in
    /// the node's batch.
    _publisher: zenoh::pubsub::Publisher<'static>,
}

impl<T: Packet + Serialize> Echoing for Port<T> {
    fn take(&mut self, batch: &mut Batch) {
        let key = &self.key;
        let matched = self.matched.load(Ordering::Acquire);
        if matched != self.tap.is_some() {
            // Detaching drops what waits: nobody listens any more.
            self.tap = None;
            if matched {
                match Tap::attach(&self.handle, &self.port, ECHO_CAPACITY) {
                    Ok(tap) => self.tap = Some(tap),
                    Err(error) => coolbot::limited!(key, |held| tracing::warn!(
                        %key, "the echo's tap cannot be attached: {error}{held}"
                    )),
                }
            }
        }
        let Some(tap) = &self.tap else {
            return;
        };
        while let Ok((seq, sent, packet)) = tap.receiver().try_recv() {
            let message = Outgoing {
                output: &self.output,
                seq,
                dropped: tap.dropped(),
                sent,
                packet: &packet,
                unsent: None,
            };
            if let Err((error, told)) = batch.push_or_tell(&message) {
                coolbot::limited!(key, |held| tracing::warn!(
                    %key,
                    "packet {seq} is not echoed: {error}{}{held}",
                    if told { "" } else { " (nor is its loss)" }
                ));
            }
        }
    }

    #[cfg(test)]
    fn waiting(&self) -> usize {
        self.tap.as_ref().map_or(0, |tap| tap.receiver().len())
    }

    #[cfg(test)]
    fn matched(&self) -> bool {
        self.matched.load(Ordering::Acquire)
    }
}

/// A node's echoes: the outputs it echoes and the one thread that publishes them,
/// started with the first. Dropping it (or [`Echoes::stop`]) ends the thread.
#[derive(Default)]
pub(crate) struct Echoes {
    ports: Arc<Mutex<Vec<Box<dyn Echoing>>>>,
    thread: Mutex<Option<(Sender<()>, JoinHandle<()>)>>,
}

impl Echoes {
    /// Publish every packet output `port` of `handle` sends, of type `T`, in the
    /// batches of `node`, from its echo thread, while a subscriber matches `key`,
    /// until stopped. `tap`, attached to that output, shows it can be tapped; it is
    /// kept if a subscriber matches already.
    pub(crate) fn add<T: Packet + Serialize>(
        &self,
        session: &zenoh::Session,
        node: &str,
        (output, key): (String, String),
        (handle, port, tap): (Handle, &str, Tap<T>),
    ) -> Result<(), Error> {
        let publisher = session
            .declare_publisher(key.clone())
            .wait()
            .map_err(Error::zenoh("declare the echo publisher"))?;
        let matched = Arc::new(AtomicBool::new(false));
        let status = Arc::clone(&matched);
        // Zenoh calls it at once with the status at declaration, then on each change.
        let listener = publisher
            .matching_listener()
            .callback(move |matching| status.store(matching.matching(), Ordering::Release))
            .wait()
            .map_err(Error::zenoh("watch the echo's subscribers"))?;
        let mut thread = lock(&self.thread);
        if thread.is_none() {
            let batches = session
                .declare_publisher(crate::keys::echoes(node))
                .congestion_control(zenoh::qos::CongestionControl::Drop)
                .wait()
                .map_err(Error::zenoh("declare the echo publisher"))?;
            let (stop, stopped) = crossbeam_channel::bounded::<()>(0);
            let ports = Arc::clone(&self.ports);
            let worker = std::thread::Builder::new()
                .name(format!("cool-net:{node}:o"))
                .spawn(move || {
                    let mut batch = Batch::default();
                    // A tick at a time, until the stop sender is dropped.
                    while let Err(RecvTimeoutError::Timeout) = stopped.recv_timeout(ECHO_TICK) {
                        for port in lock(&ports).iter_mut() {
                            port.take(&mut batch);
                        }
                        for json in batch.take() {
                            if let Err(error) = batches.put(json).wait() {
                                let key = batches.key_expr().as_str();
                                coolbot::limited!(key, |held| tracing::warn!(
                                    %key, "echoes not published: {}{held}",
                                    coolbot::Chain(&*error)
                                ));
                            }
                        }
                    }
                })
                .map_err(Error::spawn("echo"))?;
            *thread = Some((stop, worker));
        }
        let tap = matched.load(Ordering::Acquire).then_some(tap);
        lock(&self.ports).push(Box::new(Port {
            output,
            key,
            handle,
            port: port.to_owned(),
            tap,
            _publisher: publisher,
            matched,
            _listener: listener,
        }));
        Ok(())
    }

    /// End the thread and the echoes: their taps leave the outputs.
    pub(crate) fn stop(&self) {
        if let Some((stop, thread)) = lock(&self.thread).take() {
            drop(stop);
            let _ = thread.join();
        }
        lock(&self.ports).clear();
    }
}

impl Drop for Echoes {
    fn drop(&mut self) {
        self.stop();
    }
}

#[cfg(test)]
mod tests {
    use std::collections::VecDeque;
    use std::time::Instant;

    use coolbot::port::DataOut;
    use coolbot::{Automaton, Component, OutputKind, OutputSpec, PortSet, Spec, StateSpec, System};
    use zenoh::handlers::FifoChannelHandler;
    use zenoh::pubsub::Subscriber;
    use zenoh::sample::Sample;

    use super::*;

    static SOURCE: Spec = Spec::new("Source", "")
        .with_states(&[StateSpec::new("idle")])
        .with_outputs(&[
            OutputSpec::new("out", OutputKind::Data, "u64"),
            OutputSpec::new("other", OutputKind::Data, "u64"),
        ]);

    /// A component that only owns its outputs; the test sends on them.
    struct Source;

    impl Automaton for Source {
        fn spec(&self) -> &'static Spec {
            &SOURCE
        }
    }

    const KEY: &str = "coolbot/test/source/o/out";
    const OTHER: &str = "coolbot/test/source/o/other";
    const BATCHES: &str = "coolbot/test/o";
    const PATIENCE: Duration = Duration::from_secs(30);

    /// A running `source`, its outputs echoed by node `test` ([`KEY`], [`OTHER`]),
    /// on a session of its own (no network).
    struct Fixture {
        session: zenoh::Session,
        system: System,
        out: DataOut<u64>,
        other: DataOut<u64>,
        echoes: Echoes,
    }

    fn fixture() -> Fixture {
        let (out, other) = (DataOut::<u64>::new(), DataOut::<u64>::new());
        let mut system = System::new();
        system
            .add(Component::new(
                "source",
                Box::new(Source),
                PortSet::new().output(&out).output(&other),
            ))
            .unwrap();
        system.run_all().unwrap();
        let session = zenoh::open(crate::peer_config(&[], &[], false).unwrap())
            .wait()
            .unwrap();
        let handle = system.handle("source").unwrap();
        let echoes = Echoes::default();
        for (port, key) in [("out", KEY), ("other", OTHER)] {
            let tap = Tap::<u64>::attach(&handle, port, ECHO_CAPACITY).unwrap();
            echoes
                .add(
                    &session,
                    "test",
                    (format!("source.{port}"), key.to_owned()),
                    (handle.clone(), port, tap),
                )
                .unwrap();
        }
        Fixture {
            session,
            system,
            out,
            other,
            echoes,
        }
    }

    /// Poll `condition` until it holds (a generous limit for a loaded machine).
    fn until(mut condition: impl FnMut() -> bool) {
        let deadline = Instant::now() + PATIENCE;
        while !condition() {
            assert!(Instant::now() < deadline, "the condition never held");
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    /// A reader of the node's batches, asking for some outputs.
    struct Reader {
        batches: Subscriber<FifoChannelHandler<Sample>>,
        _asking: Vec<Subscriber<()>>,
        /// Packets of batches received, not yet read.
        pending: VecDeque<Echoed>,
    }

    impl Reader {
        /// The next batch, whole.
        fn batch(&self) -> Vec<Echoed> {
            let sample = self
                .batches
                .recv_timeout(PATIENCE)
                .unwrap()
                .expect("a batch of echoed packets");
            serde_json::from_slice(&sample.payload().to_bytes()).unwrap()
        }

        /// The next packet.
        fn next(&mut self) -> Echoed {
            while self.pending.is_empty() {
                let batch = self.batch();
                self.pending.extend(batch);
            }
            self.pending.pop_front().unwrap()
        }
    }

    impl Fixture {
        /// Run `f` on the echoed outputs while the echo thread cannot take from their
        /// taps (each tick's work waits for the ports' lock).
        fn held<R>(&self, f: impl FnOnce(&[Box<dyn Echoing>]) -> R) -> R {
            let ports = lock(&self.echoes.ports);
            f(&ports)
        }

        /// A reader asking for the outputs of `keys`, once the echo knows it and has
        /// tapped them (their only consumer).
        fn subscribe(&self, keys: &[&str]) -> Reader {
            let batches = self.session.declare_subscriber(BATCHES).wait().unwrap();
            let asking = keys
                .iter()
                .map(|key| {
                    self.session
                        .declare_subscriber(*key)
                        .callback(|_| {})
                        .wait()
                        .unwrap()
                })
                .collect();
            let index = |key: &str| usize::from(key == OTHER);
            until(|| self.held(|ports| keys.iter().all(|key| ports[index(key)].matched())));
            for key in keys {
                let output = if *key == OTHER {
                    &self.other
                } else {
                    &self.out
                };
                until(|| output.consumers() == 1);
            }
            Reader {
                batches,
                _asking: asking,
                pending: VecDeque::new(),
            }
        }

        fn finish(self) {
            self.echoes.stop();
            assert!(self.system.shutdown().clean());
        }
    }

    /// The producer's sends only fill the tap; the echo thread takes them at its
    /// tick. Packets beyond the tap's capacity by then are dropped and counted: the
    /// messages say how many, and a subscriber sees the gap.
    #[test]
    fn packets_wait_for_the_tick_and_those_beyond_the_capacity_are_counted() {
        let fixture = fixture();
        let mut reader = fixture.subscribe(&[KEY]);
        let extra = 10;
        let capacity = ECHO_CAPACITY as u64;
        fixture.held(|ports| {
            for n in 0..capacity + extra {
                fixture.out.send(n);
            }
            assert_eq!(ports[0].waiting(), ECHO_CAPACITY);
        });
        for n in 0..capacity {
            let message = reader.next();
            assert_eq!(message.output, "source.out");
            assert_eq!((message.seq, message.packet.as_u64()), (n, Some(n)));
            assert_eq!(message.dropped, extra);
        }
        fixture.out.send(7);
        let after = reader.next();
        assert_eq!(after.seq, capacity + extra, "the gap");
        assert_eq!(after.dropped, extra);
        fixture.finish();
    }

    /// What every tapped output sent in a tick goes in one sample on the node's batch
    /// key, in order per output, each packet naming its output and stamped with the
    /// time it was sent.
    #[test]
    fn a_tick_publishes_the_packets_of_every_output_in_one_sample() {
        let fixture = fixture();
        let reader = fixture.subscribe(&[KEY, OTHER]);
        let before = coolbot::Time::now();
        fixture.held(|_| {
            for n in 0..3 {
                fixture.out.send(n);
                fixture.other.send(100 + n);
            }
        });
        let after = coolbot::Time::now();
        let batch = reader.batch();
        assert!(
            batch
                .iter()
                .all(|echoed| (before..=after).contains(&echoed.sent)),
            "each stamped when it was sent: {batch:?}"
        );
        let of = |output: &str| -> Vec<(u64, Option<u64>)> {
            batch
                .iter()
                .filter(|echoed| echoed.output == output)
                .map(|echoed| (echoed.seq, echoed.packet.as_u64()))
                .collect()
        };
        assert_eq!(batch.len(), 6, "one sample: {batch:?}");
        assert_eq!(of("source.out"), [(0, Some(0)), (1, Some(1)), (2, Some(2))]);
        assert_eq!(
            of("source.other"),
            [(0, Some(100)), (1, Some(101)), (2, Some(102))]
        );
        fixture.finish();
    }

    /// A tick's packets that take more than the batch's bound together are closed
    /// into several arrays, each within it, in order and none lost; a packet over it
    /// alone is not echoed, and the batch is as it was.
    #[test]
    fn a_burst_is_batched_within_the_bound() {
        let packet = |seq: u64, text: &str| {
            let mut batch = Batch::within(usize::MAX);
            let text = text.to_owned();
            batch
                .push(&Outgoing {
                    output: "source.out",
                    seq,
                    dropped: 0,
                    sent: coolbot::Time::from_nanos(seq),
                    packet: &text,
                    unsent: None,
                })
                .unwrap();
            batch.take().concat().len()
        };
        // Room for three such packets an array, not four.
        let one = packet(0, "xxxxxxxx");
        let max = 3 * one + 1;
        let mut batch = Batch::within(max);
        for seq in 0..10 {
            let text = "xxxxxxxx".to_owned();
            let echoed = Outgoing {
                output: "source.out",
                seq,
                dropped: 0,
                sent: coolbot::Time::from_nanos(seq),
                packet: &text,
                unsent: None,
            };
            batch.push(&echoed).unwrap();
        }
        let huge = "y".repeat(max);
        let over = batch.push(&Outgoing {
            output: "source.out",
            seq: 10,
            dropped: 0,
            sent: coolbot::Time::from_nanos(10),
            packet: &huge,
            unsent: None,
        });
        assert!(
            over.as_ref()
                .is_err_and(|error| error.contains("over the limit ECHO_BATCH")),
            "{over:?}"
        );
        let arrays = batch.take();
        assert!(
            arrays.iter().all(|array| array.len() <= max),
            "{:?}",
            arrays.iter().map(Vec::len).collect::<Vec<_>>()
        );
        let seqs: Vec<Vec<u64>> = arrays
            .iter()
            .map(|array| {
                serde_json::from_slice::<Vec<Echoed>>(array)
                    .unwrap()
                    .iter()
                    .map(|echoed| echoed.seq)
                    .collect()
            })
            .collect();
        assert_eq!(seqs, [vec![0, 1, 2], vec![3, 4, 5], vec![6, 7, 8], vec![9]]);
        assert!(batch.take().is_empty(), "the batch is empty again");
    }

    static TEXTS: Spec = Spec::new("Texts", "")
        .with_states(&[StateSpec::new("idle")])
        .with_outputs(&[OutputSpec::new("out", OutputKind::Data, "String")]);

    /// A component that only owns an output of texts; the test sends on it.
    struct Texts;

    impl Automaton for Texts {
        fn spec(&self) -> &'static Spec {
            &TEXTS
        }
    }

    /// A packet the node cannot echo (over the batch's bound alone) takes its place
    /// in the batch without its value, saying why: a reader counts it lost even when
    /// it is the last its output sends (no later packet shows the gap).
    #[test]
    fn a_packet_not_echoed_is_told_lost_in_its_place_even_the_last() {
        let out = DataOut::<String>::new();
        let mut system = System::new();
        system
            .add(Component::new(
                "texts",
                Box::new(Texts),
                PortSet::new().output(&out),
            ))
            .unwrap();
        system.run_all().unwrap();
        let session = zenoh::open(crate::peer_config(&[], &[], false).unwrap())
            .wait()
            .unwrap();
        let handle = system.handle("texts").unwrap();
        let echoes = Echoes::default();
        let key = "coolbot/test/texts/o/out";
        let tap = Tap::<String>::attach(&handle, "out", ECHO_CAPACITY).unwrap();
        echoes
            .add(
                &session,
                "test",
                ("texts.out".to_owned(), key.to_owned()),
                (handle.clone(), "out", tap),
            )
            .unwrap();
        let _asking = session
            .declare_subscriber(key)
            .callback(|_| {})
            .wait()
            .unwrap();
        // Tapped by the echo thread once a subscriber matches.
        until(|| lock(&echoes.ports)[0].matched());
        until(|| out.consumers() == 1);
        let arrays = {
            // The echo thread takes nothing meanwhile.
            let mut ports = lock(&echoes.ports);
            out.send("short".to_owned());
            out.send("x".repeat(1000));
            let mut batch = Batch::within(500);
            ports[0].take(&mut batch);
            batch.take()
        };
        let echoed: Vec<Echoed> = arrays
            .iter()
            .flat_map(|array| serde_json::from_slice::<Vec<Echoed>>(array).unwrap())
            .collect();
        assert_eq!(echoed.len(), 2, "{echoed:?}");
        assert_eq!(
            (echoed[0].seq, &echoed[0].packet, &echoed[0].unsent),
            (0, &serde_json::json!("short"), &None)
        );
        assert_eq!(
            (echoed[1].seq, &echoed[1].packet),
            (1, &serde_json::Value::Null)
        );
        assert!(
            echoed[1]
                .unsent
                .as_deref()
                .is_some_and(|why| why.contains("over the limit ECHO_BATCH = 500 bytes")),
            "{echoed:?}"
        );
        echoes.stop();
        assert!(system.shutdown().clean());
    }

    /// The output is tapped only while a subscriber matches: before the first and
    /// after the last, its sends reach its connections only. A subscriber's first
    /// packet is the first sent once the tap is attached, numbered 0. An output
    /// nobody asks for is not in the batches.
    #[test]
    fn an_output_is_tapped_only_while_someone_listens() {
        let fixture = fixture();
        let consumers = || fixture.out.consumers();
        until(|| consumers() == 0);
        for n in 0..2 * ECHO_CAPACITY as u64 {
            fixture.out.send(n);
        }
        let mut reader = fixture.subscribe(&[KEY]);
        fixture.other.send(1);
        fixture.out.send(1000);
        let message = reader.next();
        assert_eq!(message.output, "source.out");
        assert_eq!((message.seq, message.dropped), (0, 0));
        assert_eq!(message.packet, serde_json::json!(1000));
        assert_eq!(fixture.other.consumers(), 0, "`other` is not tapped");
        drop(reader);
        until(|| !fixture.held(|ports| ports[0].matched()));
        until(|| consumers() == 0);
        fixture.finish();
    }
}
