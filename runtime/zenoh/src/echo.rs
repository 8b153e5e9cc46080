//! Echoed outputs (`coolctl echo`): a node taps an output it was asked to echo
//! ([`crate::Node::echo`], a `coolbot::tap::Tap`) and publishes each packet as JSON on
//! `coolbot/<node>/<path>/o/<port>`, from one thread of its own for all its echoes.
//!
//! **Invariant:** the producer is never slowed. The tap is attached only while a
//! subscriber matches the output's key: an output nobody echoes costs its producer
//! nothing (attaching and detaching take the output's lock on its connections once
//! each). While attached, a packet costs its producer one copy into the tap's queue
//! and nothing more: the tap drops a packet its queue has no room for (counted), and
//! nothing ever waits on that queue, so the producer never wakes a thread. The echo
//! thread takes what every queue holds once per [`ECHO_TICK`], writes each packet's
//! JSON once, straight from its type, and publishes it without waiting (congestion
//! control `Drop`). Every message carries the packet's sequence number and the
//! node's drop count, so a subscriber counts every packet it did not get.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
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

/// How often the echo thread takes the packets the taps hold: an echoed output may
/// send up to [`ECHO_CAPACITY`] packets in this time before any is dropped.
pub const ECHO_TICK: Duration = Duration::from_millis(10);

/// One echoed packet on the network.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Echoed {
    /// The packet's number among those the output sent since the tap was attached
    /// (when a first subscriber came; 0 first): a gap is packets this subscriber did
    /// not get.
    pub seq: u64,
    /// Packets the node dropped since the tap was attached because its queue was
    /// full.
    pub dropped: u64,
    /// The packet, as serde writes it in JSON.
    pub packet: serde_json::Value,
}

/// An [`Echoed`] as the node writes it: the packet serialized from its own type.
#[derive(Serialize)]
struct Outgoing<'a, T> {
    seq: u64,
    dropped: u64,
    packet: &'a T,
}

/// What a reader that passes the packet on takes of an [`Echoed`]: the packet's JSON,
/// checked and left as the node wrote it (`coolctl foxglove`'s feed).
#[cfg(feature = "foxglove")]
#[derive(Debug, Deserialize)]
pub(crate) struct EchoedRaw<'a> {
    /// The packet's JSON.
    #[serde(borrow)]
    pub packet: &'a serde_json::value::RawValue,
}

/// One echoed output: its tap while anyone listens, and where it is published.
trait Echoing: Send {
    /// Attach or detach the tap as a subscriber matches or not; publish every packet
    /// the tap holds.
    fn publish(&mut self);

    /// Packets waiting in the tap.
    #[cfg(test)]
    fn waiting(&self) -> usize;

    /// Whether a subscriber matches, as last told.
    #[cfg(test)]
    fn matched(&self) -> bool;
}

struct Port<T> {
    key: String,
    /// The component and its output's name, to attach the tap to.
    handle: Handle,
    port: String,
    /// Attached while a subscriber matches.
    tap: Option<Tap<T>>,
    publisher: zenoh::pubsub::Publisher<'static>,
    /// Whether a subscriber matches the key, as Zenoh's matching listener last said.
    matched: Arc<AtomicBool>,
    _listener: zenoh::matching::MatchingListener<()>,
}

impl<T: Packet + Serialize> Echoing for Port<T> {
    fn publish(&mut self) {
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
        while let Ok((seq, packet)) = tap.receiver().try_recv() {
            let message = Outgoing {
                seq,
                dropped: tap.dropped(),
                packet: &packet,
            };
            match serde_json::to_vec(&message) {
                Ok(json) => {
                    if let Err(error) = self.publisher.put(json).wait() {
                        coolbot::limited!(
                            key,
                            |held| tracing::warn!(%key, "echo not published: {}{held}", coolbot::Chain(&*error))
                        );
                    }
                }
                Err(error) => coolbot::limited!(
                    key,
                    |held| tracing::warn!(%key, "packet {seq} does not serialize: {error}{held}")
                ),
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

fn lock<T>(mutex: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

/// A node's echoes: the outputs it echoes and the one thread that publishes them,
/// started with the first. Dropping it (or [`Echoes::stop`]) ends the thread.
#[derive(Default)]
pub(crate) struct Echoes {
    ports: Arc<Mutex<Vec<Box<dyn Echoing>>>>,
    thread: Mutex<Option<(Sender<()>, JoinHandle<()>)>>,
}

impl Echoes {
    /// Publish every packet output `port` of `handle` sends, of type `T`, on `key`,
    /// from the echo thread of `node`, while a subscriber matches `key`, until stopped.
    /// `tap`, attached to that output, shows it can be tapped; it is kept if a
    /// subscriber matches already.
    pub(crate) fn add<T: Packet + Serialize>(
        &self,
        session: &zenoh::Session,
        node: &str,
        key: String,
        (handle, port, tap): (Handle, &str, Tap<T>),
    ) -> Result<(), Error> {
        let publisher = session
            .declare_publisher(key.clone())
            .congestion_control(zenoh::qos::CongestionControl::Drop)
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
            let (stop, stopped) = crossbeam_channel::bounded::<()>(0);
            let ports = Arc::clone(&self.ports);
            let worker = std::thread::Builder::new()
                .name(format!("cool-net:{node}:o"))
                .spawn(move || {
                    // A tick at a time, until the stop sender is dropped.
                    while let Err(RecvTimeoutError::Timeout) = stopped.recv_timeout(ECHO_TICK) {
                        for port in lock(&ports).iter_mut() {
                            port.publish();
                        }
                    }
                })
                .map_err(Error::spawn("echo"))?;
            *thread = Some((stop, worker));
        }
        let tap = matched.load(Ordering::Acquire).then_some(tap);
        lock(&self.ports).push(Box::new(Port {
            key,
            handle,
            port: port.to_owned(),
            tap,
            publisher,
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
    use std::time::Instant;

    use coolbot::port::DataOut;
    use coolbot::{
        Automaton, Component, OutputKind, OutputSpec, PortSet, Spec, StateSpec, System, TimingSpec,
    };
    use zenoh::handlers::FifoChannelHandler;
    use zenoh::pubsub::Subscriber;
    use zenoh::sample::Sample;

    use super::*;

    static SOURCE: Spec = Spec {
        type_name: "Source",
        doc: "",
        states: &[StateSpec {
            name: "idle",
            entry: false,
            exit: false,
            periodic: None,
            on: &[],
            after: &[],
            may: &[],
        }],
        initial: 0,
        inputs: &[],
        outputs: &[OutputSpec {
            name: "out",
            kind: OutputKind::Data,
            packet: "u64",
            pull: false,
        }],
        variables: &[],
        exceptions: &[],
        timing: TimingSpec::NONE,
    };

    /// A component that only owns its output; the test sends on it.
    struct Source;

    impl Automaton for Source {
        fn spec(&self) -> &'static Spec {
            &SOURCE
        }
    }

    const KEY: &str = "coolbot/test/source/o/out";
    const PATIENCE: Duration = Duration::from_secs(30);

    /// A running `source`, its output echoed on [`KEY`], on a session of its own (no
    /// network).
    struct Fixture {
        session: zenoh::Session,
        system: System,
        out: DataOut<u64>,
        echoes: Echoes,
    }

    fn fixture() -> Fixture {
        let out = DataOut::<u64>::new();
        let mut system = System::new();
        system
            .add(Component::new(
                "source",
                Box::new(Source),
                PortSet::new().output(&out),
            ))
            .unwrap();
        system.run_all().unwrap();
        let session = zenoh::open(crate::peer_config(&[], &[], false).unwrap())
            .wait()
            .unwrap();
        let handle = system.handle("source").unwrap();
        let tap = Tap::<u64>::attach(&handle, "out", ECHO_CAPACITY).unwrap();
        let echoes = Echoes::default();
        echoes
            .add(&session, "test", KEY.to_owned(), (handle, "out", tap))
            .unwrap();
        Fixture {
            session,
            system,
            out,
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

    impl Fixture {
        /// Run `f` on the echoed output while the echo thread cannot take from its
        /// tap (each tick's work waits for the ports' lock).
        fn held<R>(&self, f: impl FnOnce(&dyn Echoing) -> R) -> R {
            let ports = lock(&self.echoes.ports);
            f(&*ports[0])
        }

        /// A subscriber to the echo, once the echo knows it and has tapped the
        /// output (its only consumer).
        fn subscribe(&self) -> Subscriber<FifoChannelHandler<Sample>> {
            let subscriber = self.session.declare_subscriber(KEY).wait().unwrap();
            until(|| self.held(|port| port.matched()));
            until(|| self.out.consumers() == 1);
            subscriber
        }

        fn finish(self) {
            self.echoes.stop();
            assert!(self.system.shutdown().clean());
        }
    }

    fn next(subscriber: &Subscriber<FifoChannelHandler<Sample>>) -> Echoed {
        let sample = subscriber
            .recv_timeout(PATIENCE)
            .unwrap()
            .expect("an echoed packet");
        serde_json::from_slice(&sample.payload().to_bytes()).unwrap()
    }

    /// The producer's sends only fill the tap; the echo thread takes them at its
    /// tick. Packets beyond the tap's capacity by then are dropped and counted: the
    /// messages say how many, and a subscriber sees the gap.
    #[test]
    fn packets_wait_for_the_tick_and_those_beyond_the_capacity_are_counted() {
        let fixture = fixture();
        let subscriber = fixture.subscribe();
        let extra = 10;
        let capacity = ECHO_CAPACITY as u64;
        fixture.held(|port| {
            for n in 0..capacity + extra {
                fixture.out.send(n);
            }
            assert_eq!(port.waiting(), ECHO_CAPACITY);
        });
        for n in 0..capacity {
            let message = next(&subscriber);
            assert_eq!((message.seq, message.packet.as_u64()), (n, Some(n)));
            assert_eq!(message.dropped, extra);
        }
        fixture.out.send(7);
        let after = next(&subscriber);
        assert_eq!(after.seq, capacity + extra, "the gap");
        assert_eq!(after.dropped, extra);
        fixture.finish();
    }

    /// The output is tapped only while a subscriber matches: before the first and
    /// after the last, its sends reach its connections only. A subscriber's first
    /// packet is the first sent once the tap is attached, numbered 0.
    #[test]
    fn an_output_is_tapped_only_while_someone_listens() {
        let fixture = fixture();
        let consumers = || fixture.out.consumers();
        until(|| consumers() == 0);
        for n in 0..2 * ECHO_CAPACITY as u64 {
            fixture.out.send(n);
        }
        let subscriber = fixture.subscribe();
        fixture.out.send(1000);
        let message = next(&subscriber);
        assert_eq!((message.seq, message.dropped), (0, 0));
        assert_eq!(message.packet, serde_json::json!(1000));
        drop(subscriber);
        until(|| !fixture.held(|port| port.matched()));
        until(|| consumers() == 0);
        fixture.finish();
    }
}
