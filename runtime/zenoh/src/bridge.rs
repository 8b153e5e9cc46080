//! Port bridges: outlets and inlets (`docs/distribution.md`, "Port bridges").
//!
//! An **outlet** stands, in the producer's system, for a remote input: its one input
//! (`input`) has that input's kind, so [`coolbot::System::connect`] applies the
//! connection's local rules, and its thread publishes what arrives on the bridge's
//! key. An **inlet** stands, in the consumer's system, for the remote output: its one
//! output (`output`) has that output's kind, and a Zenoh callback sends on it what
//! arrives on the key (no extra thread hop on the receiving side). Packets are encoded
//! with postcard, and decoded strictly (`crate::codec`); a large numbered message is
//! encoded straight into shared memory, which Zenoh passes as such to a node on the
//! same host (`crate::shm`).
//!
//! No packet is lost without a counter and an event: a packet an outlet cannot
//! publish (it does not encode, Zenoh refuses it, or nothing on the network
//! subscribes to the key) is counted as lost at the outlet's input; a packet an inlet
//! cannot decode (or that is longer than its bound) is counted as lost at the inlet's
//! `network` input, and so are the numbers missing on the way; a jump of an outlet's
//! numbering out of the ledger's window is one reset at the inlet's `resets` input
//! (`crate::ledger`); a packet that reaches a full input is handled by that input's
//! own overflow policy. Each of these is an `overflows` count and a
//! `MonitorEvent::Overflow` on the monitoring port of the bridge or of the consumer,
//! and a `tracing` warning with the reason.

use crate::locks::lock;
use std::marker::PhantomData;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use coolbot::port::{
    DataOut, ErasedInput, FifoIn, LastIn, PosterIn, PosterOut, TickIn, TickOut, UfifoIn,
};
use coolbot::{
    Automaton, Chain, Component, Context, Fault, InputKind, InputPort, InputSpec, OnSpec,
    OutputKind, OutputSpec, Packet, PortSet, Section, Spec, StateSpec, TimingSpec,
};
use serde::Serialize;
use serde::de::DeserializeOwned;
use zenoh::Wait;
use zenoh::bytes::ZBytes;
use zenoh::query::{ConsolidationMode, QueryTarget};

use crate::backlog::{Backlog, LostFn};
use crate::codec;
use crate::delivery::{DecodeFn, DeliverFn, Via};
use crate::ledger::{self, InletLedger, OutletLedger};
use crate::nearby::{
    self, Held, InletParts, InletRings, Inline, Link, Nearby, NewestFn, Queue, SameHost,
};
use crate::shm::Arena;
use crate::tally::Tally;
use crate::{Error, Node, keys};

/// The bridges of a node: its constructors of outlets and inlets.
impl Node {
    /// An outlet named `name` on bridge key `key`, standing for a remote input of
    /// `kind` (see the crate documentation and `docs/distribution.md`).
    pub fn outlet<T>(&self, name: &str, key: &str, kind: InputKind) -> OutletBuilder<'_, T> {
        OutletBuilder::new(self, name, key, kind)
    }

    /// An inlet named `name` on bridge key `key`, standing for a remote output of
    /// `kind`.
    pub fn inlet<T>(&self, name: &str, key: &str, kind: OutputKind) -> InletBuilder<'_, T> {
        InletBuilder::new(self, name, key, kind)
    }
}

/// How long a pull over the network waits for its answer unless the bridge says
/// otherwise ([`OutletBuilder::pull`], [`InletBuilder::pull`]).
pub const DEFAULT_PULL_TIMEOUT: Duration = Duration::from_secs(1);

/// The most events one tick message carries: an outlet splits a larger count, an
/// inlet counts a message claiming more as lost (it did not come from an outlet).
const MAX_EVENTS_PER_MESSAGE: u64 = 1 << 16;

/// The longest message an inlet of a data or poster connection decodes unless the
/// bridge says otherwise ([`InletBuilder::max_payload`]): 64 MiB. A longer one is
/// counted lost at the inlet's `network` input, undecoded.
pub const DEFAULT_MAX_PAYLOAD: usize = 64 << 20;

/// The longest tick message: its epoch, its number and its count of events, each a
/// `u64` of at most 10 bytes in postcard.
const MAX_TICK_MESSAGE: usize = 30;

/// How long a bridge asks the network for the other ends of its connection when it
/// is built (the liveliness look-up that checks the cardinality rules).
const LOOKUP_TIMEOUT: Duration = Duration::from_millis(500);

/// The wire name of an input kind (liveliness tokens, messages).
fn input_kind_name(kind: InputKind) -> &'static str {
    match kind {
        InputKind::Tick => "tick",
        InputKind::Fifo { .. } => "fifo",
        InputKind::Ufifo { .. } => "ufifo",
        InputKind::Last => "last",
        InputKind::Poster => "poster",
    }
}

/// Which remote input kinds an output kind connects to.
fn feeds(output: OutputKind, input: &str) -> bool {
    match output {
        OutputKind::Tick => input == "tick",
        OutputKind::Poster => input == "poster",
        OutputKind::Data => matches!(input, "last" | "fifo" | "ufifo"),
    }
}

fn output_kind_name(kind: OutputKind) -> &'static str {
    match kind {
        OutputKind::Tick => "tick",
        OutputKind::Data => "data",
        OutputKind::Poster => "poster",
    }
}

/// The liveliness tokens under `pattern`, as their keys.
fn tokens(session: &zenoh::Session, pattern: &str) -> Result<Vec<String>, Error> {
    crate::node::liveliness_keys(session, pattern, LOOKUP_TIMEOUT)
}

/// The kinds of the outlets already on `key` (from their tokens `K/@out/<kind>/..`).
fn outlet_kinds(session: &zenoh::Session, key: &str) -> Result<Vec<String>, Error> {
    let prefix = format!("{key}/@out/");
    Ok(tokens(session, &format!("{key}/@out/**"))?
        .into_iter()
        .filter_map(|token| {
            let rest = token.strip_prefix(&prefix)?;
            Some(rest.split('/').next()?.to_owned())
        })
        .collect())
}

fn encode<P: Serialize + ?Sized>(packet: &P) -> Result<Vec<u8>, String> {
    codec::encode(packet).map_err(|error| format!("does not encode: {error}"))
}

/// The spec of a forwarding component (a bridge's, a ROS 2 endpoint's): one state,
/// `forwarding`, whose entry runs at each packet on input 0 if it `reacts`; made once
/// per component built and never freed (a `Spec` is `'static`).
pub(crate) fn leak_spec(
    type_name: &'static str,
    doc: &'static str,
    inputs: Vec<InputSpec>,
    output: Option<OutputSpec>,
    reacts: bool,
) -> &'static Spec {
    let inputs: &'static [InputSpec] = Box::leak(inputs.into_boxed_slice());
    let outputs: &'static [OutputSpec] = match output {
        Some(output) => Box::leak(Box::new([output])),
        None => &[],
    };
    let on: &'static [OnSpec] = if reacts {
        &[OnSpec { port: 0, target: 0 }]
    } else {
        &[]
    };
    let states: &'static [StateSpec] = Box::leak(Box::new([StateSpec {
        name: "forwarding",
        entry: reacts,
        exit: false,
        periodic: None,
        on,
        after: &[],
        may: &[],
    }]));
    Box::leak(Box::new(Spec {
        type_name,
        doc,
        states,
        initial: 0,
        inputs,
        outputs,
        variables: &[],
        exceptions: &[],
        timing: TimingSpec::NONE,
    }))
}

// ---------------------------------------------------------------------------------
// Outlets.

/// Builds an outlet: a component that stands for a remote input of a given kind and
/// publishes what arrives at its input `input` on a key expression. Made by
/// [`Node::outlet`].
#[must_use = "call build() to get the component"]
pub struct OutletBuilder<'n, T> {
    node: &'n Node,
    name: String,
    key: String,
    kind: InputKind,
    pull: Option<Duration>,
    packet: PhantomData<fn() -> T>,
}

impl<'n, T> OutletBuilder<'n, T> {
    pub(crate) fn new(node: &'n Node, name: &str, key: &str, kind: InputKind) -> Self {
        OutletBuilder {
            node,
            name: name.to_owned(),
            key: key.to_owned(),
            kind,
            pull: None,
            packet: PhantomData,
        }
    }

    /// The remote input is a `pull` input: the outlet's input is declared `pull` (the
    /// local producer's output must be too), nothing is published, and each query on
    /// `K/@pull` pulls one packet from the producer, waiting at most `timeout`.
    pub fn pull(mut self, timeout: Duration) -> Self {
        self.pull = Some(timeout);
        self
    }
}

/// The outlet's input, by kind.
enum OutletInput<T> {
    Tick(TickIn),
    Fifo(FifoIn<T>),
    Ufifo(UfifoIn<T>),
    Last(LastIn<T>),
    Poster(PosterIn<T>),
}

/// The sending side of an outlet.
struct Wire {
    key: String,
    publisher: zenoh::pubsub::Publisher<'static>,
    /// Whether a subscriber matches the key (kept by a matching listener).
    matching: Arc<AtomicBool>,
    /// Where a packet that could not be published is counted.
    losses: ErasedInput,
    /// The newest number handed to Zenoh, in a file a restarted process reads
    /// (`crate::tally`; numbered streams only).
    tally: Option<Arc<Tally>>,
    /// Where a large numbered message is written (`crate::shm`).
    arena: Arena,
}

impl Wire {
    fn lost(&self, reason: &str) {
        self.losses.count_loss(1);
        coolbot::limited!(
            &self.key,
            |held| tracing::warn!(key = %self.key, "outlet lost a packet: {reason}{held}")
        );
    }

    /// Publish one packet; `counted`: a packet nobody subscribes to is a loss (data
    /// and ticks; a poster's value stays available on query); `numbered`: the
    /// message's epoch and number, tallied before it goes to Zenoh. Whether Zenoh took
    /// it (if not, it was counted here).
    fn send(
        &self,
        bytes: Result<ZBytes, String>,
        counted: bool,
        numbered: Option<(u64, u64)>,
    ) -> bool {
        let bytes = match bytes {
            Ok(bytes) => bytes,
            Err(reason) => {
                self.lost(&reason);
                return false;
            }
        };
        // The flag follows a matching listener, which Zenoh calls a little after the
        // session learns of a subscriber: when it says no, ask the publisher itself
        // (a cold path) before counting a packet lost.
        if counted
            && !self.matching.load(Ordering::Acquire)
            && !self
                .publisher
                .matching_status()
                .wait()
                .is_ok_and(|status| status.matching())
        {
            self.lost("nothing on the network subscribes to the key");
            return false;
        }
        // Before Zenoh has it: a process killed in between reports one message more
        // than it sent (counted lost), never one less.
        let tally = self.tally.as_ref().zip(numbered);
        if let Some((tally, (_, number))) = tally {
            tally.record(number);
        }
        if let Err(error) = self.publisher.put(bytes).wait() {
            if let Some((tally, (_, number))) = tally {
                tally.record(number - 1);
            }
            self.lost(&format!("zenoh refused it: {}", Chain(&*error)));
            return false;
        }
        if let Some((epoch, number)) = numbered {
            tracing::trace!(target: ledger::LEDGER_TARGET, "{} sent {epoch} {number}", self.key);
        }
        true
    }

    /// Publish `packet` as the next numbered message of this outlet (`epoch`, the
    /// number after `sent`): a number is used only by a message Zenoh took, so an
    /// inlet that sees one missing knows it was lost on the way, not here (where it
    /// would be counted already).
    fn send_numbered<P: Serialize + ?Sized>(&self, epoch: u64, sent: &ledger::Sent, packet: &P) {
        // Only the outlet's thread numbers: the ledger's thread only reads.
        let next = sent.get() + 1;
        let message = self
            .arena
            .encode(&(epoch, next, packet))
            .map_err(|error| format!("does not encode: {error}"));
        if self.send(message, true, Some((epoch, next))) {
            sent.set(next);
        }
    }
}

/// Serves pull queries on its own thread (a pull waits for the producer).
struct PullServer {
    stop: Arc<AtomicBool>,
    queryable: Option<zenoh::query::Queryable<()>>,
    thread: Option<JoinHandle<()>>,
}

impl Drop for PullServer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        drop(self.queryable.take());
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

type PullFn = Box<dyn Fn(Duration) -> Result<Vec<u8>, String> + Send>;

/// What a poster or `last` outlet serves to a reader that asks: its latest packet,
/// with the outlet's epoch and the number it was sent with (a `last` packet Zenoh did
/// not take: 0).
struct Latest<T> {
    epoch: u64,
    number: u64,
    packet: T,
}

impl<T: Serialize> Latest<T> {
    /// The message a reader gets, as the stream would have carried it.
    fn encode(&self) -> Result<Vec<u8>, String> {
        encode(&(self.epoch, self.number, &self.packet))
    }
}

/// A pull answer: what `pull` returns, encoded as a message of the outlet's `epoch`
/// numbered 0 (an answer is not part of the numbered stream), its error as text.
fn encoded_pull<P: Serialize>(
    epoch: u64,
    pull: impl Fn(Duration) -> Result<P, coolbot::port::PullError> + Send + 'static,
) -> PullFn {
    Box::new(move |timeout| {
        pull(timeout)
            .map_err(|error| error.to_string())
            .and_then(|packet| encode(&(epoch, 0u64, packet)))
    })
}

fn pull_server(
    session: &zenoh::Session,
    key: &str,
    timeout: Duration,
    pull: PullFn,
) -> Result<PullServer, Error> {
    let (queries, received) = crossbeam_channel::bounded::<zenoh::query::Query>(64);
    let queryable = session
        .declare_queryable(format!("{key}/@pull"))
        .callback(move |query| {
            if let Err(crossbeam_channel::TrySendError::Full(query)) = queries.try_send(query) {
                let _ = query
                    .reply_err("the producer has too many pull requests waiting")
                    .wait();
            }
        })
        .wait()
        .map_err(Error::zenoh("declare the pull queryable"))?;
    let stop = Arc::new(AtomicBool::new(false));
    let stopped = Arc::clone(&stop);
    let thread = std::thread::Builder::new()
        .name(format!("cool-net:pull:{key}"))
        .spawn(move || {
            loop {
                match received.recv_timeout(Duration::from_millis(100)) {
                    Ok(query) => {
                        let result = match pull(timeout) {
                            Ok(bytes) => query.reply(query.key_expr().clone(), bytes).wait(),
                            Err(reason) => query.reply_err(reason).wait(),
                        };
                        if let Err(error) = result {
                            coolbot::limited!(query.key_expr().as_str(), |held| tracing::warn!(
                                "pull answer not sent: {}{held}",
                                Chain(&*error)
                            ));
                        }
                    }
                    Err(crossbeam_channel::RecvTimeoutError::Timeout) => {
                        if stopped.load(Ordering::Acquire) {
                            break;
                        }
                    }
                    Err(crossbeam_channel::RecvTimeoutError::Disconnected) => break,
                }
            }
        })
        .map_err(Error::spawn("pull"))?;
    Ok(PullServer {
        stop,
        queryable: Some(queryable),
        thread: Some(thread),
    })
}

/// A poster value on the wire: the outlet's epoch (its creation time), a sequence
/// number, the value. Readers keep the newest (a late reply never replaces a newer
/// post).
type Posted<T> = (u64, u64, T);

/// A data packet or a count of tick events on the wire: the outlet's epoch, the
/// message's number (1, 2, ... for each message the outlet handed to Zenoh; 0 for a
/// pull answer, which is not part of the stream), the packet. An inlet counts the
/// numbers missing between two it received as lost.
type Numbered<T> = (u64, u64, T);

pub(crate) struct Outlet<T> {
    spec: &'static Spec,
    input: OutletInput<T>,
    /// A fifo or ufifo outlet's path to a consumer on this host (`crate::nearby`):
    /// sends what waits at the input, by a ring or on the key. Dropped before the
    /// ledger: nothing is sent after its last questions.
    nearby: Option<Box<dyn SameHost>>,
    /// What the inlets acknowledge (numbered streams only: not a poster, not pull).
    /// Dropped first: its last questions go before the tally says the epoch stopped
    /// cleanly.
    _ledger: Option<OutletLedger>,
    wire: Arc<Wire>,
    pull: bool,
    epoch: u64,
    seq: Arc<AtomicU64>,
    /// The number of the last data or tick message Zenoh took.
    sent: Arc<ledger::Sent>,
    /// A poster outlet's last published value, or a `last` outlet's latest packet
    /// (with the number it went with, or 0 if Zenoh did not take it), served to
    /// readers that ask (late joiners, links that came back). Kept as the packet
    /// itself, moved here after it was sent, and encoded only when a reader asks: a
    /// large packet is not encoded twice on every send.
    posted: Arc<Mutex<Option<Arc<Latest<T>>>>>,
    published_once: bool,
    _poster_queryable: Option<zenoh::query::Queryable<()>>,
    _pull_server: Option<PullServer>,
    _token: zenoh::liveliness::LivelinessToken,
}

impl<T: Packet + Serialize + DeserializeOwned> OutletBuilder<'_, T> {
    /// Check the connection rules across the network, declare the outlet's keys and
    /// return the component (add it to the producer's system and connect the
    /// producer's output to `<name>.input`).
    pub fn build(self) -> Result<Component, Error> {
        let (name, outlet, ports) = self.parts(true)?;
        Ok(Component::new(name, Box::new(outlet), ports))
    }

    /// What [`OutletBuilder::build`] makes, unassembled: the name, the outlet, its
    /// port set (a proxy, `crate::place`, takes the outlet's input as its own);
    /// `nearby`: a queue outlet writes into a ring of a consumer on this host when it
    /// finds one (`crate::nearby`; not a proxy's).
    pub(crate) fn parts(self, nearby: bool) -> Result<(String, Outlet<T>, PortSet), Error> {
        let OutletBuilder {
            node,
            name,
            key,
            kind,
            pull,
            packet: _,
        } = self;
        keys::check_name(&name)?;
        keys::check_bridge_key(&key)?;
        if name.contains('.') {
            return Err(Error::InvalidName {
                name,
                reason: "a component name has no `.`".to_owned(),
            });
        }
        let session = node.session();
        let kind_name = input_kind_name(kind);
        // One connection, one kind; a last or poster connection has one producer; a
        // fifo or ufifo connection has one input end.
        let existing = outlet_kinds(session, &key)?;
        if let Some(other) = existing.iter().find(|k| k.as_str() != kind_name) {
            return Err(Error::Cardinality {
                key,
                rule: format!(
                    "it carries a {other} connection, and this outlet stands for a {kind_name} input"
                ),
            });
        }
        if matches!(kind, InputKind::Last | InputKind::Poster) && !existing.is_empty() {
            return Err(Error::Cardinality {
                key,
                rule: format!(
                    "a {kind_name} connection is 1 output to N inputs, and the key already has a producer"
                ),
            });
        }
        if matches!(kind, InputKind::Fifo { .. } | InputKind::Ufifo { .. }) {
            let inlets = tokens(session, &format!("{key}/@in/**"))?;
            if inlets.len() > 1 {
                return Err(Error::Cardinality {
                    key,
                    rule: format!(
                        "a {kind_name} connection is N outputs to 1 input, and {} inlets read the key",
                        inlets.len()
                    ),
                });
            }
        }
        let token = session
            .liveliness()
            .declare_token(format!("{key}/@out/{kind_name}/{}/{name}", node.name()))
            .wait()
            .map_err(Error::zenoh("declare the outlet's liveliness token"))?;

        let packet = if kind == InputKind::Tick {
            "event"
        } else {
            std::any::type_name::<T>()
        };
        let spec = leak_spec(
            "Outlet",
            "Stands for a remote input: publishes what arrives at `input` on its key.",
            vec![InputSpec {
                name: "input",
                kind,
                packet,
                pull: pull.is_some(),
            }],
            None,
            pull.is_none(),
        );
        let (input, erased): (OutletInput<T>, ErasedInput) = match kind {
            InputKind::Tick => {
                let port = TickIn::new();
                let erased = port.erased();
                (OutletInput::Tick(port), erased)
            }
            InputKind::Fifo { capacity, policy } => {
                let port = FifoIn::new(capacity, policy);
                let erased = port.erased();
                (OutletInput::Fifo(port), erased)
            }
            InputKind::Ufifo { initial, max } => {
                let port = UfifoIn::new(initial, max);
                let erased = port.erased();
                (OutletInput::Ufifo(port), erased)
            }
            InputKind::Last => {
                let port = LastIn::new();
                let erased = port.erased();
                (OutletInput::Last(port), erased)
            }
            InputKind::Poster => {
                let port = PosterIn::new();
                let erased = port.erased();
                (OutletInput::Poster(port), erased)
            }
        };
        let publisher = session
            .declare_publisher(key.clone())
            .congestion_control(zenoh::qos::CongestionControl::Block)
            .wait()
            .map_err(Error::zenoh("declare the outlet's publisher"))?;
        let matching = Arc::new(AtomicBool::new(
            publisher
                .matching_status()
                .wait()
                .map(|status| status.matching())
                .unwrap_or(false),
        ));
        let flag = Arc::clone(&matching);
        publisher
            .matching_listener()
            .callback(move |status| flag.store(status.matching(), Ordering::Release))
            .background()
            .wait()
            .map_err(Error::zenoh("listen for the outlet's subscribers"))?;
        let epoch = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as u64);
        let seq = Arc::new(AtomicU64::new(0));
        let posted = Arc::new(Mutex::new(None::<Arc<Latest<T>>>));
        let poster_queryable = if matches!(kind, InputKind::Poster | InputKind::Last)
            && pull.is_none()
        {
            let posted = Arc::clone(&posted);
            let replier = node.replier();
            Some(
                session
                    .declare_queryable(key.clone())
                    .callback(move |query| {
                        let Some(latest) = lock(&posted).clone() else {
                            return;
                        };
                        // Encoded outside the lock (the outlet's next store does not
                        // wait for it), and sent from the node's replier (a querier
                        // that does not read it holds that thread, not Zenoh's).
                        replier.send("a current value", move || {
                            let reply = match latest.encode() {
                                Ok(bytes) => query.reply(query.key_expr().clone(), bytes).wait(),
                                Err(error) => Err(error.into()),
                            };
                            if let Err(error) = reply {
                                coolbot::limited!(
                                    query.key_expr().as_str(),
                                    |held| tracing::warn!(
                                        "poster value not sent: {}{held}",
                                        Chain(&*error)
                                    )
                                );
                            }
                        });
                    })
                    .wait()
                    .map_err(Error::zenoh("declare the poster queryable"))?,
            )
        } else {
            None
        };
        let pull_server = match pull {
            Some(timeout) => {
                let pull: PullFn = match &input {
                    OutletInput::Tick(port) => {
                        let port = port.clone();
                        encoded_pull(epoch, move |t| port.pull(t))
                    }
                    OutletInput::Fifo(port) => {
                        let port = port.clone();
                        encoded_pull(epoch, move |t| port.pull(t))
                    }
                    OutletInput::Ufifo(port) => {
                        let port = port.clone();
                        encoded_pull(epoch, move |t| port.pull(t))
                    }
                    OutletInput::Last(port) => {
                        let port = port.clone();
                        encoded_pull(epoch, move |t| port.pull(t))
                    }
                    OutletInput::Poster(port) => {
                        let port = port.clone();
                        let seq = Arc::clone(&seq);
                        Box::new(move |t| {
                            port.pull(t).map_err(|e| e.to_string()).and_then(|p| {
                                let n = seq.fetch_add(1, Ordering::AcqRel) + 1;
                                encode(&(epoch, n, p))
                            })
                        })
                    }
                };
                Some(pull_server(session, &key, timeout, pull)?)
            }
            None => None,
        };
        let ports = match &input {
            OutletInput::Tick(port) => PortSet::new().input(port),
            OutletInput::Fifo(port) => PortSet::new().input(port),
            OutletInput::Ufifo(port) => PortSet::new().input(port),
            OutletInput::Last(port) => PortSet::new().input(port),
            OutletInput::Poster(port) => PortSet::new().input(port),
        };
        let sent = Arc::new(ledger::Sent::default());
        let numbered = pull.is_none() && kind != InputKind::Poster;
        // A remote placement's keys are new at every placement: no process started
        // again would read their tally.
        let tallied = numbered && !key.starts_with(keys::LINKS);
        let (tally, ended) = match node.state_directory().filter(|_| tallied) {
            Some(state) => match Tally::claim(state, node.name(), &key, epoch) {
                Some((tally, ended)) => (Some(Arc::new(tally)), ended),
                None => (None, Vec::new()),
            },
            None => (None, Vec::new()),
        };
        let retire = tally.as_ref().filter(|_| !ended.is_empty()).map(|tally| {
            let tally = Arc::clone(tally);
            Box::new(move || tally.retire()) as ledger::Retire
        });
        let ledger = if numbered {
            Some(OutletLedger::start(
                session,
                &key,
                epoch,
                Arc::clone(&sent),
                matches!(kind, InputKind::Fifo { .. } | InputKind::Ufifo { .. }),
                erased.clone(),
                ended,
                retire,
            )?)
        } else {
            None
        };
        let wire = Arc::new(Wire {
            key,
            publisher,
            matching,
            losses: erased,
            tally,
            arena: Arena::new(session, node.shared_memory_counters()),
        });
        let nearby = (nearby && pull.is_none() && node.same_host())
            .then(|| {
                let outlet = format!("{}/{name}", node.name());
                match &input {
                    OutletInput::Fifo(port) => {
                        let path = same_host(node, &wire, &sent, epoch, outlet, port.clone());
                        port.set_intake(Arc::new(Inline(Arc::downgrade(&path))));
                        Some(Box::new(Held(path)) as Box<dyn SameHost>)
                    }
                    OutletInput::Ufifo(port) => {
                        let path = same_host(node, &wire, &sent, epoch, outlet, port.clone());
                        Some(Box::new(Held(path)) as Box<dyn SameHost>)
                    }
                    _ => None,
                }
            })
            .flatten();
        let outlet = Outlet {
            spec,
            input,
            nearby,
            _ledger: ledger,
            wire,
            pull: pull.is_some(),
            epoch,
            seq,
            sent,
            posted,
            published_once: false,
            _poster_queryable: poster_queryable,
            _pull_server: pull_server,
            _token: token,
        };
        Ok((name, outlet, ports))
    }
}

impl<T: Packet + Serialize> Outlet<T> {
    /// Keep `latest` for readers that ask; the one it replaces is dropped after the
    /// lock is let go (dropping a packet may run code of its own: a lent buffer's).
    fn post(&self, latest: Latest<T>) {
        let replaced = lock(&self.posted).replace(Arc::new(latest));
        drop(replaced);
    }

    /// `ports` with this outlet's input added (a proxy's input, `crate::place`).
    pub(crate) fn add_input(&self, ports: PortSet) -> PortSet {
        match &self.input {
            OutletInput::Tick(port) => ports.input(port),
            OutletInput::Fifo(port) => ports.input(port),
            OutletInput::Ufifo(port) => ports.input(port),
            OutletInput::Last(port) => ports.input(port),
            OutletInput::Poster(port) => ports.input(port),
        }
    }

    /// Publish what waits at the input (a proxy's pump, `crate::place`).
    pub(crate) fn pump(&mut self) {
        self.forward();
    }

    fn forward(&mut self) {
        if self.pull {
            // Pull answers go to the querier only, from the pull thread.
            return;
        }
        if let Some(nearby) = &self.nearby {
            nearby.forward();
            return;
        }
        let wire = &self.wire;
        let (epoch, sent) = (self.epoch, &*self.sent);
        match &self.input {
            OutletInput::Tick(port) => {
                let mut events = port.take();
                while events > 0 {
                    let batch = events.min(MAX_EVENTS_PER_MESSAGE);
                    wire.send_numbered(epoch, sent, &batch);
                    events -= batch;
                }
            }
            OutletInput::Fifo(port) => {
                for packet in port.drain() {
                    wire.send_numbered(epoch, sent, &packet);
                }
            }
            OutletInput::Ufifo(port) => {
                for packet in port.drain() {
                    wire.send_numbered(epoch, sent, &packet);
                }
            }
            OutletInput::Last(port) => {
                if let Some(packet) = port.take_new() {
                    let before = sent.get();
                    wire.send_numbered(epoch, sent, &packet);
                    // The latest, for a reader that asks (a late joiner, a link that
                    // came back), with the number it went with (a reader that had
                    // it from the stream drops it), or 0 when Zenoh did not take it.
                    let number = sent.get();
                    let number = if number > before { number } else { 0 };
                    self.post(Latest {
                        epoch,
                        number,
                        packet,
                    });
                }
            }
            OutletInput::Poster(port) => {
                let value = if self.published_once {
                    port.take_new()
                } else {
                    port.read()
                };
                if let Some(value) = value {
                    self.published_once = true;
                    let seq = self.seq.fetch_add(1, Ordering::AcqRel) + 1;
                    let latest = Latest {
                        epoch: self.epoch,
                        number: seq,
                        packet: value,
                    };
                    let bytes = latest.encode();
                    // Kept before it is sent: a reader whose subscription missed it
                    // on the stream and asks now gets it, not the one before.
                    self.post(latest);
                    wire.send(bytes.map(ZBytes::from), false, None);
                }
            }
        }
    }
}

/// The same-host path of an outlet whose input is `queue` (`crate::nearby`): it
/// numbers with the outlet's count, and sends on the key through `wire`.
fn same_host<T: Packet + Serialize, Q: Queue<T> + 'static>(
    node: &Node,
    wire: &Arc<Wire>,
    sent: &Arc<ledger::Sent>,
    epoch: u64,
    outlet: String,
    queue: Q,
) -> Arc<Nearby<T, Q>> {
    let link: Link<T> = {
        let (wire, sent) = (Arc::clone(wire), Arc::clone(sent));
        Box::new(move |packet: &T| wire.send_numbered(epoch, &sent, packet))
    };
    Nearby::new(nearby::Parts {
        session: node.session().clone(),
        key: wire.key.clone(),
        outlet,
        epoch,
        sent: Arc::clone(sent),
        tally: wire.tally.clone(),
        queue,
        link,
        losses: wire.losses.clone(),
        counters: node.shared_memory_counters(),
    })
}

impl<T: Packet + Serialize> Automaton for Outlet<T> {
    fn spec(&self) -> &'static Spec {
        self.spec
    }

    fn start(&mut self, _cx: &mut Context) -> Result<(), Fault> {
        if let Some(nearby) = &self.nearby {
            nearby.set_running(true);
        }
        Ok(())
    }

    fn stop(&mut self, _cx: &mut Context) {
        if let Some(nearby) = &self.nearby {
            nearby.set_running(false);
        }
    }

    fn section(&mut self, _state: usize, section: Section, _cx: &mut Context) -> Result<(), Fault> {
        if section == Section::Entry {
            self.forward();
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------
// Inlets.

/// Builds an inlet: a component that stands for a remote output of a given kind and
/// sends on its output `output` what arrives on a key expression. Made by
/// [`Node::inlet`].
#[must_use = "call build() to get the component"]
pub struct InletBuilder<'n, T> {
    node: &'n Node,
    name: String,
    key: String,
    kind: OutputKind,
    pull: Option<Duration>,
    max_payload: usize,
    packet: PhantomData<fn() -> T>,
}

impl<'n, T> InletBuilder<'n, T> {
    pub(crate) fn new(node: &'n Node, name: &str, key: &str, kind: OutputKind) -> Self {
        InletBuilder {
            node,
            name: name.to_owned(),
            key: key.to_owned(),
            kind,
            pull: None,
            max_payload: DEFAULT_MAX_PAYLOAD,
            packet: PhantomData,
        }
    }

    /// The longest message the inlet decodes, in bytes (a data packet or a poster
    /// value with its epoch and number; [`DEFAULT_MAX_PAYLOAD`] unless set): a longer
    /// one is counted lost at `network` without being decoded. A tick inlet's
    /// messages have a size of their own (at most 30 bytes), whatever this says.
    pub fn max_payload(mut self, bytes: usize) -> Self {
        self.max_payload = bytes;
        self
    }

    /// The remote output is a `pull` output: the inlet's output is declared `pull`
    /// (a local `pull` input may connect to it), the inlet subscribes to nothing, and
    /// each pull request from its consumer becomes a query on `K/@pull`, waiting at
    /// most `timeout` for the answers.
    pub fn pull(mut self, timeout: Duration) -> Self {
        self.pull = Some(timeout);
        self
    }
}

/// The inlet's output, by kind.
enum InletOutput<T> {
    Tick(TickOut),
    Data(DataOut<T>),
    Poster(PosterOut<T>),
}

/// How far an answer's number may run ahead of the stream for the stream's
/// messages behind it to be dropped as stale: the messages in flight on the stream
/// when the outlet answered. Further behind, the answer is forgotten and the stream
/// delivered as it comes (so a peer that answers with a made-up number can hold
/// back at most this many of a stream's packets).
const ANSWER_AHEAD: u64 = 256;

/// The outlet epochs an inlet of data remembers for [`Delivered`].
const DELIVERED_EPOCHS: usize = 16;

/// What an inlet of data delivered, per outlet epoch: the newest number the stream
/// brought, and the number of the current value an answer delivered ahead of it.
/// The current value of a `last` outlet, asked for when the inlet starts or when an
/// outlet appears, may be one the stream brought already or will bring: a reader
/// gets each packet once, and never an older one after it.
#[derive(Default)]
struct Delivered {
    /// `(epoch, newest on the stream, answered ahead of the stream, newest a ring
    /// brought)`, oldest first.
    epochs: Vec<(u64, u64, Option<u64>, u64)>,
}

impl Delivered {
    /// The newest number of `epoch` the stream brought.
    fn stream(&self, epoch: u64) -> Option<u64> {
        self.epochs
            .iter()
            .find(|(e, ..)| *e == epoch)
            .map(|(_, stream, ..)| *stream)
    }

    /// Whether message `seq` of `epoch`, come `via`, is to be delivered (and is now
    /// taken as delivered). An answer is dropped when the stream, or another
    /// answer, delivered that number or a newer one of its epoch; the stream's
    /// message is dropped when an answer delivered it, or a newer one at most
    /// [`ANSWER_AHEAD`] ahead. Anything else the stream brings is delivered (the
    /// ledger counts what is missing).
    fn fresh(&mut self, epoch: u64, seq: u64, via: Via) -> bool {
        if seq == 0 {
            // A pull answer, or a value the outlet could not number: not part of
            // the stream.
            return true;
        }
        let at = match self.epochs.iter().position(|(e, ..)| *e == epoch) {
            Some(at) => at,
            None => {
                if self.epochs.len() >= DELIVERED_EPOCHS {
                    self.epochs.remove(0);
                }
                self.epochs.push((epoch, 0, None, 0));
                self.epochs.len() - 1
            }
        };
        let (_, stream, answered, ring) = &mut self.epochs[at];
        match via {
            // A message of the key at or below one a ring of the host delivered: it
            // came after a newer one (the ring's wait for it was over,
            // `crate::nearby`), and the ledger counted it missing then. Dropped: the
            // consumer never gets a packet after a newer one. (Only the ring's
            // numbers count here, never a number of the key a peer made up.)
            Via::Stream if seq <= *ring => false,
            // The last messages of a ring handed over to a new consumer, at or below
            // a number the key delivered: the outlet went back to the key as the ring
            // closed, and the key's newer message came first; the ledger counted this
            // one missing then. Dropped, for the same reason. (Only those few: the
            // ring's other messages never give way to a number of the key.)
            Via::HandedOver if seq <= *stream => false,
            Via::Stream | Via::Ring | Via::HandedOver => {
                if via != Via::Stream {
                    *ring = (*ring).max(seq);
                }
                *stream = (*stream).max(seq);
                match *answered {
                    Some(ahead) if seq < ahead && ahead - seq <= ANSWER_AHEAD => false,
                    Some(ahead) if seq == ahead => {
                        *answered = None;
                        false
                    }
                    Some(_) => {
                        *answered = None;
                        true
                    }
                    None => true,
                }
            }
            Via::Answer | Via::Pull => {
                if seq <= *stream || answered.is_some_and(|ahead| seq <= ahead) {
                    false
                } else {
                    *answered = Some(seq);
                    true
                }
            }
        }
    }
}

struct Inlet {
    spec: &'static Spec,
    session: zenoh::Session,
    key: String,
    deliver: DeliverFn,
    pull: Option<Duration>,
    subscriber: Option<zenoh::pubsub::Subscriber<()>>,
    /// Watches the producers' outlets (their liveliness tokens), to ask for the
    /// current value again when one appears.
    watcher: Option<zenoh::pubsub::Subscriber<()>>,
    /// Answers the outlets' questions on what it has had (not a pull inlet).
    _acks: Option<zenoh::query::Queryable<()>>,
    /// Rings for outlets of this host (a data inlet, shared memory on:
    /// `crate::nearby`), and, while started, what answers their questions.
    rings: Option<Arc<InletRings>>,
    ring_questions: Option<zenoh::query::Queryable<()>>,
    _token: zenoh::liveliness::LivelinessToken,
}

/// Where an inlet counts what goes wrong on the way: `network`, each message that
/// does not decode or is missing from the numbering; `resets`, each time an outlet's
/// numbering jumped out of the ledger's window (`crate::ledger`).
struct Counters {
    network: ErasedInput,
    resets: ErasedInput,
}

/// What [`deliverer`] makes for a key: its delivery of Zenoh's payloads, the same
/// delivery of bytes this process holds (a ring's), the key's ledger, and what the
/// rings' gates read of the stream.
struct Deliverer {
    deliver: DeliverFn,
    decode: DecodeFn,
    ledger: Arc<InletLedger>,
    newest: NewestFn,
}

/// What delivers a bridge key's messages on `output` (strict decoding of payloads of
/// at most `max_payload` bytes, longer ones refused before they are copied, lent
/// when in shared memory and counted in `shared`; the ledger's count of numbers,
/// losses counted at `counters`), that ledger, and the newest number of each epoch
/// it handed on from the stream (a data output's).
fn deliverer<T: Packet + DeserializeOwned>(
    output: InletOutput<T>,
    counters: Counters,
    shared: Arc<crate::shm::Counters>,
    key: String,
    max_payload: usize,
) -> Deliverer {
    let network = Arc::new(counters.network);
    let counted = Arc::clone(&network);
    let lost_key = key.clone();
    let lost_many: LostFn = Arc::new(move |count: u64, reason: String| {
        counted.count_loss(count);
        let what = match count {
            1 => "a packet".to_owned(),
            _ => format!("{count} packets"),
        };
        coolbot::limited!(&lost_key, |held| tracing::warn!(
            key = %lost_key,
            "inlet lost {what}: {reason}{held}"
        ));
    });
    let lost = {
        let lost_many = Arc::clone(&lost_many);
        move |reason: String| lost_many(1, reason)
    };
    let ledger = Arc::new(InletLedger::new(
        network,
        Arc::new(counters.resets),
        key.clone(),
    ));
    let gaps = Arc::clone(&ledger);
    // What a data inlet delivered, per outlet epoch; read by its rings' gates
    // (`crate::nearby`) under the lock its deliveries hold while they send.
    let delivered = Arc::new(Mutex::new(Delivered::default()));
    let newest: NewestFn = {
        let delivered = Arc::clone(&delivered);
        Arc::new(move |epoch| lock(&delivered).stream(epoch))
    };
    let max = match output {
        InletOutput::Tick(_) => MAX_TICK_MESSAGE,
        InletOutput::Data(_) | InletOutput::Poster(_) => max_payload,
    };
    let decode: DecodeFn = match output {
        InletOutput::Tick(port) => {
            let lost = lost.clone();
            Arc::new(move |bytes, via| {
                match codec::decode_parts::<Numbered<u64>>(bytes, MAX_TICK_MESSAGE) {
                    Ok((_, _, events)) if events > MAX_EVENTS_PER_MESSAGE => lost(format!(
                        "{events} events in one message: more than an outlet sends ({MAX_EVENTS_PER_MESSAGE})"
                    )),
                    Ok((epoch, seq, events)) => {
                        if via.counted() {
                            gaps.received(epoch, seq);
                        }
                        for _ in 0..events {
                            port.emit();
                        }
                    }
                    Err(error) => lost(Chain(&error).to_string()),
                }
            })
        }
        InletOutput::Data(port) => {
            let delivered = Arc::clone(&delivered);
            // Packets whose delivery would wait go through a backlog: the receiving
            // thread never waits on a full `block` fifo.
            let backlog = Backlog::new(port, &key, lost_many);
            let lost = lost.clone();
            Arc::new(move |bytes, via| {
                match codec::decode_parts::<Numbered<T>>(bytes, max_payload) {
                    Ok((epoch, seq, packet)) => {
                        // Under the lock: the stream, a ring and an answer come on
                        // different threads; the ledger and `delivered` see them in one
                        // order, and the one taken as newer is sent last.
                        let mut delivered = lock(&delivered);
                        if via.counted() {
                            gaps.received(epoch, seq);
                        }
                        if !delivered.fresh(epoch, seq, via) {
                            return;
                        }
                        if via == Via::Pull {
                            // To the requester only: the port knows it only while this
                            // thread answers (no stream to keep in order with on a pull
                            // inlet).
                            backlog.send_now(packet);
                        } else {
                            let len = bytes.iter().map(|part| part.len()).sum();
                            if let Err(refused) = backlog.send(packet, len) {
                                lost(Chain(&refused).to_string());
                            }
                        }
                    }
                    Err(error) => lost(Chain(&error).to_string()),
                }
            })
        }
        InletOutput::Poster(port) => {
            let newest = Mutex::new(None::<(u64, u64)>);
            let lost = lost.clone();
            Arc::new(move |bytes, _via| {
                match codec::decode_parts::<Posted<T>>(bytes, max_payload) {
                    Ok((epoch, seq, value)) => {
                        let mut newest = lock(&newest);
                        let newer = match *newest {
                            Some((e, s)) => e != epoch || seq > s,
                            None => true,
                        };
                        if newer {
                            *newest = Some((epoch, seq));
                            port.post(value);
                        }
                    }
                    Err(error) => lost(Chain(&error).to_string()),
                }
            })
        }
    };
    let deliver: DeliverFn = {
        let decode = Arc::clone(&decode);
        Arc::new(move |payload, via| {
            if let Err(error) = shared.received(payload, max, |bytes| decode(bytes, via)) {
                lost(Chain(&error).to_string());
            }
        })
    };
    Deliverer {
        deliver,
        decode,
        ledger,
        newest,
    }
}

/// A proxy's output (`crate::place`): `ports` with a typed output of `kind` added,
/// what delivers the messages of a bridge key on it (decode, gaps, losses and resets
/// counted at `losses`), and its ledger.
pub(crate) fn proxy_output<T: Packet + DeserializeOwned>(
    node: &Node,
    ports: PortSet,
    kind: OutputKind,
    losses: ErasedInput,
    key: &str,
) -> (PortSet, DeliverFn, Arc<InletLedger>) {
    let (output, ports) = match kind {
        OutputKind::Tick => {
            let port = TickOut::new();
            let ports = ports.output(&port);
            (InletOutput::Tick(port), ports)
        }
        OutputKind::Data => {
            let port = DataOut::<T>::new();
            let ports = ports.output(&port);
            (InletOutput::Data(port), ports)
        }
        OutputKind::Poster => {
            let port = PosterOut::<T>::new();
            let ports = ports.output(&port);
            (InletOutput::Poster(port), ports)
        }
    };
    let counters = Counters {
        network: losses.clone(),
        resets: losses,
    };
    let Deliverer {
        deliver, ledger, ..
    } = deliverer(
        output,
        counters,
        node.shared_memory_counters(),
        key.to_owned(),
        DEFAULT_MAX_PAYLOAD,
    );
    (ports, deliver, ledger)
}

/// Ask the producers on `key` for their current value (a poster's, or the latest
/// packet of a remote `last` input's outlet); the answers are delivered as they come.
pub(crate) fn ask_current(
    session: &zenoh::Session,
    key: &str,
    deliver: &DeliverFn,
) -> zenoh::Result<()> {
    let deliver = Arc::clone(deliver);
    session
        .get(key.to_owned())
        .callback(move |reply| {
            if let Ok(sample) = reply.result() {
                deliver(sample.payload(), Via::Answer);
            }
        })
        .wait()
}

impl<T: Packet + Serialize + DeserializeOwned> InletBuilder<'_, T> {
    /// Check the connection rules across the network, declare the inlet's token and
    /// return the component (add it to the consumer's system and connect
    /// `<name>.output` to the consumer's input). It subscribes when it starts.
    pub fn build(self) -> Result<Component, Error> {
        let InletBuilder {
            node,
            name,
            key,
            kind,
            pull,
            max_payload,
            packet: _,
        } = self;
        keys::check_name(&name)?;
        keys::check_bridge_key(&key)?;
        if name.contains('.') {
            return Err(Error::InvalidName {
                name,
                reason: "a component name has no `.`".to_owned(),
            });
        }
        let session = node.session();
        let kind_name = output_kind_name(kind);
        let existing = outlet_kinds(session, &key)?;
        if let Some(other) = existing.iter().find(|k| !feeds(kind, k)) {
            return Err(Error::Cardinality {
                key,
                rule: format!(
                    "it carries a {other} connection, and this inlet stands for a {kind_name} output"
                ),
            });
        }
        if existing.iter().any(|k| k == "fifo" || k == "ufifo") {
            let inlets = tokens(session, &format!("{key}/@in/**"))?;
            if !inlets.is_empty() {
                return Err(Error::Cardinality {
                    key,
                    rule: "a queue connection is N outputs to 1 input, and an inlet already reads the key".to_owned(),
                });
            }
        }
        // The last chunk is the inlet's process: an outlet tells a link that came
        // back from an inlet started again (`crate::ledger`).
        let token = session
            .liveliness()
            .declare_token(format!(
                "{key}/@in/{}/{name}/{}",
                node.name(),
                ledger::process()
            ))
            .wait()
            .map_err(Error::zenoh("declare the inlet's liveliness token"))?;
        let packet = if kind == OutputKind::Tick {
            "event"
        } else {
            std::any::type_name::<T>()
        };
        let counted = |name| InputSpec {
            name,
            kind: InputKind::Tick,
            packet: "event",
            pull: false,
        };
        let spec = leak_spec(
            "Inlet",
            "Stands for a remote output: sends on `output` what arrives on its key; packets that do not decode or never arrive are counted at `network`, jumps of an outlet's numbering at `resets`.",
            vec![counted("network"), counted("resets")],
            Some(OutputSpec {
                name: "output",
                kind,
                packet,
                pull: pull.is_some(),
            }),
            false,
        );
        let (network, resets) = (TickIn::new(), TickIn::new());
        let ports = PortSet::new().input(&network).input(&resets);
        let (output, ports) = match kind {
            OutputKind::Tick => {
                let port = TickOut::new();
                let ports = ports.output(&port);
                (InletOutput::Tick(port), ports)
            }
            OutputKind::Data => {
                let port = DataOut::<T>::new();
                let ports = ports.output(&port);
                (InletOutput::Data(port), ports)
            }
            OutputKind::Poster => {
                let port = PosterOut::<T>::new();
                let ports = ports.output(&port);
                (InletOutput::Poster(port), ports)
            }
        };
        let counters = Counters {
            network: network.erased(),
            resets: resets.erased(),
        };
        // The inlet's output, asked for its consumer's doorbell when an outlet of this
        // host asks for a ring, and watched for a change of its consumer.
        let feeding = match &output {
            InletOutput::Data(port) if pull.is_none() && node.same_host() => Some(port.clone()),
            _ => None,
        };
        let Deliverer {
            deliver,
            decode,
            ledger,
            newest,
        } = deliverer(
            output,
            counters,
            node.shared_memory_counters(),
            key.clone(),
            max_payload,
        );
        let rings = feeding.map(|output| {
            InletRings::new(InletParts {
                key: key.clone(),
                answers_on: format!("{key}/@ring/{}/{name}", node.name()),
                decode,
                newest,
                output: Box::new(output),
                counters: node.shared_memory_counters(),
                replier: node.replier(),
            })
        });
        let acks = match pull {
            Some(_) => None,
            None => {
                // An outlet asks when its inlet is behind: a ring held for the key's
                // message is looked at again then.
                let rings = rings.clone();
                Some(
                    ledger::serve(node, &key, &name, ledger, move |_| {
                        if let Some(rings) = &rings {
                            rings.nudge();
                        }
                    })
                    .map_err(Error::zenoh("serve the inlet's acknowledgments"))?,
                )
            }
        };
        let inlet = Inlet {
            spec,
            session: session.clone(),
            deliver,
            key,
            pull,
            subscriber: None,
            watcher: None,
            _acks: acks,
            rings,
            ring_questions: None,
            _token: token,
        };
        Ok(Component::new(name, Box::new(inlet), ports))
    }
}

impl Automaton for Inlet {
    fn spec(&self) -> &'static Spec {
        self.spec
    }

    /// Subscribe to the key (not for a pull inlet); a poster inlet also asks for the
    /// value posted now (a late-joining reader).
    fn start(&mut self, _cx: &mut Context) -> Result<(), Fault> {
        if self.pull.is_some() || self.subscriber.is_some() {
            return Ok(());
        }
        let deliver = Arc::clone(&self.deliver);
        let subscriber = self
            .session
            .declare_subscriber(self.key.clone())
            .callback(move |sample| deliver(sample.payload(), Via::Stream))
            .wait()
            .map_err(|error| Fault::message(format!("cannot subscribe: {}", Chain(&*error))))?;
        self.subscriber = Some(subscriber);
        if let Some(rings) = &self.rings {
            self.ring_questions = Some(rings.serve(&self.session).map_err(|error| {
                Fault::message(format!("cannot answer for rings: {}", Chain(&error)))
            })?);
        }
        // The current value of a poster, or of a data connection to a remote `last`
        // input: asked for now (a late joiner), and again whenever a producer's outlet
        // appears on the network (a producer that starts, or a link that comes back:
        // what was posted meanwhile is not lost to this reader).
        ask_current(&self.session, &self.key, &self.deliver).map_err(|error| {
            Fault::message(format!(
                "cannot ask for the current value: {}",
                Chain(&*error)
            ))
        })?;
        let (session, key, deliver) = (
            self.session.clone(),
            self.key.clone(),
            Arc::clone(&self.deliver),
        );
        let prefix = format!("{}/@out/", self.key);
        let watcher = self
            .session
            .liveliness()
            .declare_subscriber(format!("{}/@out/**", self.key))
            .callback(move |sample| {
                let kind = sample
                    .key_expr()
                    .as_str()
                    .strip_prefix(&prefix)
                    .and_then(|rest| rest.split('/').next());
                if sample.kind() == zenoh::sample::SampleKind::Put
                    && matches!(kind, Some("poster" | "last"))
                    && let Err(error) = ask_current(&session, &key, &deliver)
                {
                    coolbot::limited!(&key, |held| tracing::warn!(%key, "cannot ask for the current value again: {}{held}", Chain(&*error)));
                }
            })
            .wait()
            .map_err(|error| Fault::message(format!("cannot watch the producers: {}", Chain(&*error))))?;
        self.watcher = Some(watcher);
        Ok(())
    }

    fn stop(&mut self, _cx: &mut Context) {
        self.subscriber = None;
        self.watcher = None;
        self.ring_questions = None;
        if let Some(rings) = &self.rings {
            rings.close();
        }
    }

    /// A pull request from the consumer: one query on `K/@pull`; every answer that
    /// arrives within the timeout is sent (to the requesting input only). No answer
    /// is not a fault: the consumer's pull times out.
    fn answer(&mut self, _output: usize, _cx: &mut Context) -> Result<(), Fault> {
        let timeout = self.pull.unwrap_or(DEFAULT_PULL_TIMEOUT);
        let replies = match self
            .session
            .get(format!("{}/@pull", self.key))
            .target(QueryTarget::All)
            .consolidation(ConsolidationMode::None)
            .timeout(timeout)
            .wait()
        {
            Ok(replies) => replies,
            Err(error) => {
                coolbot::limited!(
                    &self.key,
                    |held| tracing::warn!(key = %self.key, "pull query not sent: {}{held}", Chain(&*error))
                );
                return Ok(());
            }
        };
        while let Ok(reply) = replies.recv() {
            match reply.result() {
                Ok(sample) => (self.deliver)(sample.payload(), Via::Pull),
                Err(error) => coolbot::limited!(&self.key, |held| tracing::warn!(
                    key = %self.key,
                    "pull answered with an error: {}{held}",
                    error.payload().try_to_string().unwrap_or_default()
                )),
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::{ANSWER_AHEAD, Counters, Delivered, Deliverer, InletOutput, Via, deliverer};
    use coolbot::port::{DataOut, InputPort, TickIn};
    use std::sync::Arc;
    use zenoh::bytes::ZBytes;

    /// `bytes` as Zenoh may hold a received payload: in fragments of `chunk` bytes
    /// (so that reading it as one slice copies it).
    fn fragmented(bytes: &[u8], chunk: usize) -> ZBytes {
        let mut writer = ZBytes::writer();
        for part in bytes.chunks(chunk) {
            writer.append(ZBytes::from(part.to_vec()));
        }
        writer.finish()
    }

    #[test]
    fn a_payload_over_the_bound_is_counted_lost_before_it_is_copied() {
        let network = TickIn::new();
        let resets = TickIn::new();
        let out = DataOut::<Vec<u8>>::new();
        let Deliverer { deliver, .. } = deliverer(
            InletOutput::Data(out),
            Counters {
                network: network.erased(),
                resets: resets.erased(),
            },
            Arc::default(),
            "test/over".to_owned(),
            64,
        );
        let packet = crate::codec::encode(&(1u64, 1u64, vec![7u8; 40])).unwrap();
        assert!(packet.len() <= 64);
        deliver(&fragmented(&packet, 8), Via::Stream);
        assert_eq!(
            network.overflows(),
            0,
            "a packet within the bound is delivered"
        );
        let large = crate::codec::encode(&(1u64, 2u64, vec![7u8; 1 << 20])).unwrap();
        let payload = fragmented(&large, 4096);
        assert!(payload.to_bytes().len() > 64);
        deliver(&payload, Via::Stream);
        deliver(&payload, Via::Answer);
        assert_eq!(network.overflows(), 2);
    }

    #[test]
    fn the_current_value_of_a_last_outlet_is_delivered_once_whichever_way_comes_first() {
        // The stream brought 1; the answer to the start's question is 1 as well.
        let mut delivered = Delivered::default();
        assert!(delivered.fresh(7, 1, Via::Stream));
        assert!(!delivered.fresh(7, 1, Via::Answer), "a repeat");
        assert!(delivered.fresh(7, 2, Via::Stream));
        // An answer older than what the stream brought is stale.
        assert!(!delivered.fresh(7, 1, Via::Answer), "stale");
        // The answer came first: the stream's copy is the repeat.
        let mut delivered = Delivered::default();
        assert!(delivered.fresh(7, 5, Via::Answer), "a late joiner's value");
        assert!(!delivered.fresh(7, 5, Via::Stream), "a repeat");
        assert!(delivered.fresh(7, 6, Via::Stream));
        // Another outlet epoch (the producer started again) is news.
        assert!(delivered.fresh(8, 1, Via::Answer));
        // Unnumbered answers (pulls) are never repeats.
        assert!(delivered.fresh(8, 0, Via::Answer));
        assert!(delivered.fresh(8, 0, Via::Answer));
    }

    #[test]
    fn a_key_message_after_a_newer_one_from_a_ring_is_dropped_and_a_made_up_number_drops_nothing() {
        let mut delivered = Delivered::default();
        assert!(delivered.fresh(9, 1, Via::Stream));
        // The ring's wait for 2 was over: 3 went first.
        assert!(delivered.fresh(9, 3, Via::Ring));
        assert!(!delivered.fresh(9, 2, Via::Stream), "older than the ring's");
        assert!(delivered.fresh(9, 4, Via::Ring));
        assert_eq!(delivered.stream(9), Some(4));
        // A ring handed over: the key's 7 came before the ring's last, 6.
        assert!(delivered.fresh(9, 5, Via::HandedOver));
        assert!(delivered.fresh(9, 7, Via::Stream));
        assert!(
            !delivered.fresh(9, 6, Via::HandedOver),
            "older than the key's"
        );
        // A ring's own message never gives way to a number of the key.
        assert!(delivered.fresh(9, 6, Via::Ring));
        // A number of the key far ahead (made up by a peer) holds back no honest one.
        assert!(delivered.fresh(8, 200, Via::Stream));
        assert!(delivered.fresh(8, 2, Via::Stream));
        assert!(delivered.fresh(8, 3, Via::Stream));
    }

    #[test]
    fn an_answer_ahead_of_the_stream_holds_back_the_older_packets_behind_it() {
        // The stream had 8; the answer brings 10 before the stream's 9 and 10.
        let mut delivered = Delivered::default();
        assert!(delivered.fresh(7, 8, Via::Stream));
        assert!(delivered.fresh(7, 10, Via::Answer));
        assert!(
            !delivered.fresh(7, 9, Via::Stream),
            "older than what was delivered"
        );
        assert!(!delivered.fresh(7, 10, Via::Stream), "a repeat");
        assert!(delivered.fresh(7, 11, Via::Stream));
        assert!(!delivered.fresh(7, 10, Via::Answer), "stale");
        // Two outlets interleaved on one key: each epoch keeps its own numbers.
        let mut delivered = Delivered::default();
        assert!(delivered.fresh(1, 3, Via::Stream));
        assert!(delivered.fresh(2, 5, Via::Stream));
        assert!(!delivered.fresh(1, 3, Via::Answer), "epoch 1 had it");
        assert!(!delivered.fresh(2, 4, Via::Answer), "epoch 2 had newer");
    }

    #[test]
    fn an_answer_numbered_far_ahead_holds_back_at_most_a_bounded_run_of_the_stream() {
        // A peer answers with a made-up number far ahead of the stream.
        let mut delivered = Delivered::default();
        assert!(delivered.fresh(7, 1, Via::Stream));
        assert!(delivered.fresh(7, 1_000_000, Via::Answer));
        // The stream's next packet is further behind than an honest answer runs
        // ahead: the answer is forgotten, and the stream delivered as it comes.
        assert!(delivered.fresh(7, 2, Via::Stream));
        assert!(delivered.fresh(7, 3, Via::Stream));
        // An answer just ahead holds back only the packets between.
        assert!(delivered.fresh(7, 3 + ANSWER_AHEAD, Via::Answer));
        assert!(!delivered.fresh(7, 4, Via::Stream));
        assert!(delivered.fresh(7, 4 + ANSWER_AHEAD, Via::Stream));
        assert!(delivered.fresh(7, 5 + ANSWER_AHEAD, Via::Stream));
    }
}
