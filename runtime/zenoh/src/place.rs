//! Remote instances from the description (`docs/distribution.md`, "Remote instances
//! from the description"): the [`Placer`] a process installs so that its compounds'
//! `instance x: T on "node";` run on that node, each behind a proxy
//! (`coolbot::remote`).
//!
//! For each such instance the placer makes the proxy's ports from the [`Registry`](crate::agent::Registry)
//! (the packet type of each port, as the generated `register` functions declare it):
//! each input publishes what arrives on a bridge key of its own, each output sends
//! what arrives on one. The proxy's far end asks the agent of the named node to build the
//! instance with the same keys ([`crate::agent`]), mirrors its monitoring port,
//! forwards commands to its control port, and watches the node's liveliness token:
//! the node lost is a fault of the proxy within the Zenoh session's lease
//! ([`crate::peer_config`]'s `lease`).

use crate::locks::lock;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use coolbot::port::{InputPort, TickIn};
use coolbot::remote::{NetworkError, Placement, Remote, RemoteEnd};
use coolbot::{Chain, Command, Monitor, MonitorEvent, OutputKind, PortSet, Waker};
use zenoh::Wait;
use zenoh::sample::SampleKind;

use crate::agent::{Instantiate, Pump, RemoteInput, RemoteTiming, Wire, instantiate};
use crate::delivery::{DeliverFn, Via};
use crate::{ControlReply, Error, Node, keys};

/// How long an instantiation, a command or a snapshot query waits for the other node
/// unless the placer says otherwise.
pub const DEFAULT_REMOTE_TIMEOUT: Duration = Duration::from_secs(5);

/// The queue a remote instance's data output feeds on its node before the network
/// (the agent's outlet: a ufifo input of this initial size, growing to the cap).
const REMOTE_QUEUE: (usize, usize) = (64, 65_536);

/// How often a proxy asks for its remote instance's snapshot, for what changes without
/// an event (its CPU and elapsed time), for what an event lost on the way would have
/// set (its state, error, result...), and to know that the instance is still heard
/// (at most: a third of the placer's silence bound, [`Placer::silence`]).
pub const TIMES_REFRESH: Duration = Duration::from_secs(1);

/// How long a proxy's remote instance may leave its snapshot unanswered, while its
/// node lives, before the proxy fails (unless the placer says otherwise).
pub const DEFAULT_SILENCE: Duration = Duration::from_secs(3);

/// How long a proxy's first start waits for its node and the node's agent at most
/// (or the placer's timeout, if shorter): less than the compound's wait for it
/// ([`coolbot::compound::INSTANCE_START_TIMEOUT`]), so that the start fails with the
/// proxy's reason, which names the node, rather than the compound's timeout.
pub const FIRST_START: Duration = Duration::from_secs(4);

/// How soon a proxy asks again for the first snapshot of an instance just built
/// when nothing here knew where to send the question yet.
const REASK: Duration = Duration::from_millis(10);

/// How long a proxy's first start waits for its instance's first snapshot at least,
/// however long the instantiation took of [`FIRST_START`]. With it the start stays
/// within the compound's wait ([`coolbot::compound::INSTANCE_START_TIMEOUT`]).
const FIRST_SNAPSHOT: Duration = Duration::from_millis(500);

/// The nodes this process's proxies watch that are lost now, by the placing session
/// and the node's name: since when, and how many instantiations were refused
/// meanwhile. A node's loss and its return are logged once each, however many proxies
/// stand for instances on it.
static LOST: Mutex<BTreeMap<(String, String), Lost>> = Mutex::new(BTreeMap::new());

/// One lost node ([`LOST`]).
struct Lost {
    /// Why, with the wall-clock time of the loss: the same text for every proxy.
    reason: String,
    since: Instant,
    refused: u64,
}

/// The node `on`, watched from the session `here`, is lost (its liveliness token
/// was withdrawn): logged the first time; why, the same for every proxy on it.
fn node_lost(here: &str, on: &str) -> String {
    let mut lost = lock(&LOST);
    let entry = lost
        .entry((here.to_owned(), on.to_owned()))
        .or_insert_with(|| {
            let reason = format!(
                "node `{on}` is lost (since {}: its liveliness token was withdrawn)",
                clock_time(SystemTime::now())
            );
            tracing::warn!(
                "{reason}; what runs there is a fault of its proxies, and no instantiation \
                 is sent to it until it is back"
            );
            Lost {
                reason,
                since: Instant::now(),
                refused: 0,
            }
        });
    entry.reason.clone()
}

/// The node `on` is back (its token again): logged once, with how long it was lost,
/// at the loss's level (whoever sees the loss sees the return).
fn node_back(here: &str, on: &str) {
    if let Some(lost) = lock(&LOST).remove(&(here.to_owned(), on.to_owned())) {
        tracing::warn!(
            "node `{on}` is back after {:.1?} lost ({} instantiation(s) refused here meanwhile)",
            lost.since.elapsed(),
            lost.refused
        );
    }
}

/// An instantiation on the lost node `on` refused without asking (counted).
fn refused_while_lost(here: &str, on: &str) {
    if let Some(lost) = lock(&LOST).get_mut(&(here.to_owned(), on.to_owned())) {
        lost.refused += 1;
    }
}

/// `t` as `HH:MM:SS UTC`.
fn clock_time(t: SystemTime) -> String {
    let seconds = t.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs()) % 86_400;
    format!(
        "{:02}:{:02}:{:02} UTC",
        seconds / 3600,
        seconds / 60 % 60,
        seconds % 60
    )
}

/// Why an instance declared `on "node"` could not be placed, built, commanded, pulled
/// or heard: what its proxy's fault says after the node (`coolbot::remote`).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PlaceError {
    /// The component type is not registered with the placer.
    #[error(
        "component type `{0}` is not registered with this node's placer (call its generated \
         `register` function)"
    )]
    NotRegistered(&'static str),
    /// A port of the type is not registered.
    #[error(
        "port `{port}` of `{type_name}` was not registered (call its generated `register` \
         function)"
    )]
    PortNotRegistered {
        /// The component type.
        type_name: &'static str,
        /// The port.
        port: &'static str,
    },
    /// A name the instance would have on its node is over a limit.
    #[error(transparent)]
    Exceeded(#[from] crate::limits::Exceeded),
    /// The network: Zenoh, a name, the agent's answer.
    #[error(transparent)]
    Network(#[from] Error),
    /// The node is lost (its liveliness token was withdrawn): why, with since when.
    #[error("{0}")]
    Lost(String),
    /// The instance's monitoring port fell silent while its node lives: why.
    #[error("{0}")]
    Silent(String),
    /// No liveliness token of the node was seen while asking for the instance.
    #[error(
        "node `{node}` is not there: no liveliness token of it was seen in {asking:.1?} of \
         asking for the instance every 100 ms (is it started, and reachable from node \
         `{here}`?)"
    )]
    NotThere {
        /// The node.
        node: String,
        /// The placing node.
        here: String,
        /// How long it asked.
        asking: Duration,
    },
    /// The node is there, but no agent answered however often it was asked.
    #[error("asked every 100 ms for {asking:.1?}")]
    Unanswered {
        /// How long it asked.
        asking: Duration,
        /// The last answer: none ([`Error::NoAgent`]).
        #[source]
        source: Box<Error>,
    },
    /// The instance's node did not answer a command or a snapshot query in time.
    #[error("node `{node}` did not answer for `{instance}` (waited {waited:.1?})")]
    NoAnswer {
        /// The node.
        node: String,
        /// The instance there.
        instance: String,
        /// How long it waited: the timeout, or less where nothing here knew where to
        /// send the question (the node gone, or its instance not known here yet).
        waited: Duration,
    },
    /// The remote instance rejected a command (its reason).
    #[error("{0}")]
    Rejected(String),
    /// A pull of an output that is not declared `pull`.
    #[error("output #{0} is not a pull output")]
    NotPull(usize),
    /// No answer to a pull in time.
    #[error("node `{node}` did not answer the pull within {waited:?}")]
    PullUnanswered {
        /// The node.
        node: String,
        /// How long it waited.
        waited: Duration,
    },
}

/// Places the `on "node"` instances of compounds on their nodes (install it with
/// [`Placer::install`] on the thread that builds them, before building them).
pub struct Placer {
    node: Arc<Node>,
    registry: Arc<crate::agent::Registry>,
    timeout: Duration,
    silence: Duration,
}

impl std::fmt::Debug for Placer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Placer({})", self.node.name())
    }
}

impl Placer {
    /// A placer on `node` knowing the component types of `registry`.
    pub fn new(node: Arc<Node>, registry: impl Into<Arc<crate::agent::Registry>>) -> Placer {
        Placer {
            node,
            registry: registry.into(),
            timeout: DEFAULT_REMOTE_TIMEOUT,
            silence: DEFAULT_SILENCE,
        }
    }

    /// How long a remote instance's monitoring port may stay unanswered (no event, no
    /// answer to the snapshot its proxy asks for every third of it, at most every
    /// [`TIMES_REFRESH`]) while its node lives, before its proxy fails with the reason
    /// and the compound's policy acts. At least 30 ms.
    pub fn silence(mut self, silence: Duration) -> Placer {
        self.silence = silence.max(Duration::from_millis(30));
        self
    }

    /// How long an instantiation, a command or a query waits for the other node.
    pub fn timeout(mut self, timeout: Duration) -> Placer {
        self.timeout = timeout;
        self
    }

    /// Install this placer on this thread while the guard lives
    /// ([`coolbot::remote::install`]).
    pub fn install(self) -> coolbot::remote::Installed {
        coolbot::remote::install(Arc::new(self))
    }
}

/// The root of a proxy's names on the instance's node: the placing node, the
/// compound, the instance, and this proxy's epoch (its creation time), so that a
/// process started again never meets the names of its previous run. Its bridge keys
/// live under it; each instantiation adds a generation (`<root>-1`, `<root>-2`, ...),
/// so that the instance can be built again while its node may still hold the name of
/// an earlier one (not yet found dead, or on a node that was unreachable). The root
/// begins with the placing node's namespace ([`keys::namespace`]): the agent builds
/// only in the namespace of the node that asks (`crate::agent`).
fn remote_root(from: &str, placement: &Placement) -> String {
    let epoch = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |elapsed| elapsed.as_nanos() as u32);
    format!(
        "{}{}-{}-{epoch:08x}",
        keys::namespace(from),
        placement.compound,
        placement.name
    )
}

impl coolbot::remote::Placer for Placer {
    fn place(&self, placement: &Placement) -> Result<Option<Remote>, NetworkError> {
        Ok(self.place_here(placement)?)
    }
}

impl Placer {
    /// [`coolbot::remote::Placer::place`], with this crate's error.
    fn place_here(&self, placement: &Placement) -> Result<Option<Remote>, PlaceError> {
        Ok(self.far_end(placement)?.map(|(ports, end)| Remote {
            ports,
            end: Box::new(end),
        }))
    }

    /// The proxy's ports and far end for `placement` (`None`: it runs here).
    fn far_end(&self, placement: &Placement) -> Result<Option<(PortSet, End)>, PlaceError> {
        if placement.node == self.node.name() {
            return Ok(None);
        }
        let spec = placement.spec;
        let factory = self
            .registry
            .types
            .get(spec.type_name)
            .ok_or(PlaceError::NotRegistered(spec.type_name))?;
        let root = remote_root(self.node.name(), placement);
        keys::check_name(&root)?;
        // The names the agent will be given, checked here against its limit, so that
        // a description whose names are too long fails when it is built, not on the
        // other node at start: the instance's (`<root>-<generation>`, the generation
        // up to ten digits) and this node's, its owner.
        crate::limits::NAME
            .check(
                || {
                    format!(
                        "the name `{root}-<generation>` of `{}` on node `{}`",
                        placement.name, placement.node
                    )
                },
                root.len() + 1 + u32::MAX.to_string().len(),
            )
            .and_then(|()| {
                crate::limits::NAME.check(
                    || format!("the name of node `{}`", self.node.name()),
                    self.node.name().len(),
                )
            })?;
        let base = format!("{}{}/{root}", keys::LINKS, placement.node);
        let bridge = |port: &'static str| {
            factory
                .ports
                .get(port)
                .ok_or(PlaceError::PortNotRegistered {
                    type_name: spec.type_name,
                    port,
                })
        };
        let mut ports = PortSet::new();
        let mut pumps = Vec::new();
        let mut wires = Vec::new();
        for input in spec.inputs {
            let key = format!("{base}/in/{}", input.name);
            // A pull input: the remote instance's requests come back as queries, which
            // the proxy's input serves by pulling from its producer here.
            let pull = input.pull.then_some(crate::DEFAULT_PULL_TIMEOUT);
            let (with, pump) =
                bridge(input.name)?.proxy_input(&self.node, &key, input.kind, pull, ports)?;
            ports = with;
            pumps.push(pump);
            wires.push(Wire::Input {
                port: input.name.to_owned(),
                key,
            });
        }
        // Losses on the way in are counted at an input of the proxy's own, not one of
        // its ports: the proxy's monitor shows them at port `network` (`End::view`).
        let losses = TickIn::new();
        let shared = Arc::new(Shared {
            inputs: spec.inputs,
            ..Shared::default()
        });
        let mut outputs = Vec::new();
        for output in spec.outputs {
            let key = format!("{base}/out/{}", output.name);
            let (with, deliver, ledger) = bridge(output.name)?.proxy_output(
                &self.node,
                ports,
                output.kind,
                losses.erased(),
                &key,
            );
            let deliver = waking_on_loss(deliver, losses.clone(), Arc::clone(&shared));
            ports = with;
            let to = match output.kind {
                OutputKind::Tick => RemoteInput::Tick,
                OutputKind::Poster => RemoteInput::Poster,
                OutputKind::Data => RemoteInput::Ufifo {
                    initial: REMOTE_QUEUE.0,
                    max: Some(REMOTE_QUEUE.1),
                },
            };
            wires.push(Wire::Output {
                port: output.name.to_owned(),
                key: key.clone(),
                to,
            });
            outputs.push(ProxyOutput {
                key,
                deliver,
                ledger,
                poster: output.kind == OutputKind::Poster,
                pull: output.pull,
            });
        }
        let request = Instantiate {
            type_name: spec.type_name.to_owned(),
            name: root.clone(),
            wires,
            configuration: placement.configuration.clone(),
            variables: placement.variables.clone(),
            timing: Some(RemoteTiming {
                // Sanitized: JSON has no NaN (the runtime would sanitize it anyway).
                adaptation: Some(placement.adaptation.sanitized()),
                ..placement.timing.into()
            }),
            run: false,
            owner: Some(self.node.name().to_owned()),
        };
        let mut end = End {
            node: Arc::clone(&self.node),
            on: placement.node.clone(),
            root,
            generation: 0,
            name: String::new(),
            request,
            timeout: self.timeout,
            pumps,
            outputs,
            subscribers: Vec::new(),
            acks: Vec::new(),
            shared,
            asked_before: false,
            built: false,
            maybe_built: false,
            silence: self.silence,
            gone: None,
            times_asked: None,
            losses,
            reported_losses: 0,
            losses_before: 0,
        };
        end.listen()?;
        Ok(Some((ports, end)))
    }
}

/// What the Zenoh callbacks of one proxy tell its thread.
#[derive(Default)]
struct Shared {
    /// The remote monitoring port as last heard.
    view: Mutex<Option<Mirrored>>,
    /// The instance's inputs, in declaration order: the only ports whose losses the
    /// view shows (with [`NETWORK`]).
    inputs: &'static [coolbot::InputSpec],
    /// Whether `view` changed since the proxy last read it.
    changed: AtomicBool,
    /// Why the current generation is lost with its node, if it is (until a new one
    /// is built).
    lost: Mutex<Option<String>>,
    /// Why the node is lost, while it is (its token withdrawn, not back yet): no
    /// instantiation is sent to it meanwhile.
    absent: Mutex<Option<String>>,
    /// Whether the node's liveliness token was ever seen.
    seen: AtomicBool,
    /// Monitoring events and snapshots of the instance that did not decode, were
    /// over their limit ([`crate::limits::EVENT`], [`crate::limits::SNAPSHOT`]) or
    /// named ports the instance does not have (dropped).
    bad_events: AtomicU64,
    /// The monitoring key of the instance's current generation.
    monitor_key: Mutex<String>,
    /// Since when the proxy has asked the current generation for its snapshot without
    /// hearing from it (no answer, no event); `None` while it is heard.
    unanswered_since: Mutex<Option<Instant>>,
    waker: Mutex<Option<Waker>>,
}

impl Shared {
    fn ring(&self) {
        if let Some(waker) = lock(&self.waker).as_ref() {
            waker.wake();
        }
    }

    /// The current generation was heard from (an event, a snapshot).
    fn heard(&self) {
        *lock(&self.unanswered_since) = None;
    }
}

/// One output of a proxy: what the remote instance sends on it arrives on `key`.
struct ProxyOutput {
    key: String,
    deliver: DeliverFn,
    /// What it has had of the remote outlets: acknowledged on `key/@ack/<node>/proxy`,
    /// which is how an outlet started again after a kill of the instance's node
    /// reports what its predecessor sent (`crate::ledger`).
    ledger: Arc<crate::ledger::InletLedger>,
    /// A poster: asked for its value again after each instantiation (a late joiner's).
    poster: bool,
    /// A pull output: each request of a consumer here is a query on `key/@pull`.
    pull: bool,
}

/// The far end of one proxy: the remote instance, seen from here.
struct End {
    node: Arc<Node>,
    /// The node the instance runs on.
    on: String,
    /// The root of its names there ([`remote_root`]).
    root: String,
    /// How many times it was built.
    generation: u32,
    /// Its name there now (`<root>-<generation>`).
    name: String,
    request: Instantiate,
    timeout: Duration,
    pumps: Vec<Pump>,
    /// The proxy's outputs, in declaration order.
    outputs: Vec<ProxyOutput>,
    subscribers: Vec<zenoh::pubsub::Subscriber<()>>,
    /// The outputs' acknowledgment queryables.
    acks: Vec<zenoh::query::Queryable<()>>,
    shared: Arc<Shared>,
    /// Whether a generation was ever asked for: only the first start is patient.
    asked_before: bool,
    /// Whether the current generation was built and seen (its snapshot came): a
    /// failed attempt leaves it unbuilt, and the next start tries a new one.
    built: bool,
    /// Whether the current generation may exist on its node though it is not
    /// `built`: its instantiation's answer did not come, or its snapshot did not.
    /// The next instantiation, or the release, sends it to `dead`.
    maybe_built: bool,
    /// How long the current generation may go unheard ([`Placer::silence`]).
    silence: Duration,
    /// Why the current generation is gone while its node lives (it fell silent), if
    /// it is: it is built again before it runs ([`RemoteEnd::needs_instance`]).
    gone: Option<String>,
    /// When the remote snapshot (for its times) was last asked for.
    times_asked: Option<Instant>,
    /// Messages lost on the way here: packets on the outputs' keys that do not decode
    /// or are missing from the numbering (counted by their deliverers).
    losses: TickIn,
    /// The network losses the view last reported.
    reported_losses: u64,
    /// The network losses counted before the current generation was built (the view
    /// reports this generation's, as the remote instance's own counts are).
    losses_before: u64,
}

impl End {
    /// Messages lost on the way here, over every generation.
    fn network_losses(&self) -> u64 {
        self.losses.overflows() + self.shared.bad_events.load(Ordering::Acquire)
    }

    /// Subscribe to the outputs' keys, the instance's monitoring events and the
    /// node's liveliness.
    fn listen(&mut self) -> Result<(), Error> {
        let session = self.node.session();
        // A pull output's answers come as replies to its queries, not on the key.
        for output in self.outputs.iter().filter(|output| !output.pull) {
            let deliver = Arc::clone(&output.deliver);
            self.subscribers.push(
                session
                    .declare_subscriber(output.key.clone())
                    .callback(move |sample| deliver(sample.payload(), Via::Stream))
                    .wait()
                    .map_err(Error::zenoh("subscribe to a remote output"))?,
            );
            if !output.poster {
                let shared = Arc::clone(&self.shared);
                self.acks.push(
                    crate::ledger::serve(
                        &self.node,
                        &output.key,
                        "proxy",
                        Arc::clone(&output.ledger),
                        move |counted| {
                            if counted {
                                shared.changed.store(true, Ordering::Release);
                                shared.ring();
                            }
                        },
                    )
                    .map_err(Error::zenoh("serve a proxy output's acknowledgments"))?,
                );
            }
        }
        let shared = Arc::clone(&self.shared);
        self.subscribers.push(
            session
                .declare_subscriber(keys::monitor(&self.on, &format!("{}-$*", self.root)))
                .callback(move |sample| {
                    // The instance of this generation only (not its bridges, not an
                    // earlier generation).
                    if *lock(&shared.monitor_key) != sample.key_expr().as_str() {
                        return;
                    }
                    let Some(event) = decode_or_count::<MonitorEvent>(
                        &sample,
                        crate::limits::EVENT,
                        "a monitoring event",
                        &shared,
                    ) else {
                        return;
                    };
                    shared.heard();
                    let mut view = lock(&shared.view);
                    if let Some(view) = view.as_mut() {
                        if !view.event(event, shared.inputs) {
                            coolbot::limited!(sample.key_expr().as_str(), |held| tracing::warn!(
                                key = %sample.key_expr(),
                                "a monitoring event about a port the instance does not have \
                                 was dropped{held}"
                            ));
                            shared.bad_events.fetch_add(1, Ordering::AcqRel);
                        }
                        shared.changed.store(true, Ordering::Release);
                    }
                    drop(view);
                    shared.ring();
                })
                .wait()
                .map_err(Error::zenoh("subscribe to the remote monitoring events"))?,
        );
        let shared = Arc::clone(&self.shared);
        let on = self.on.clone();
        let here = session.zid().to_string();
        self.subscribers.push(
            session
                .liveliness()
                .declare_subscriber(keys::node_token(&self.on))
                // The token as it is now too, so that a first start knows whether the
                // node is there.
                .history(true)
                .callback(move |sample| {
                    match sample.kind() {
                        SampleKind::Delete => {
                            let reason = node_lost(&here, &on);
                            *lock(&shared.lost) = Some(reason.clone());
                            *lock(&shared.absent) = Some(reason);
                        }
                        SampleKind::Put => {
                            shared.seen.store(true, Ordering::Release);
                            *lock(&shared.absent) = None;
                            // (Whichever proxy hears it first; also one placed while
                            // the node was away, when no proxy that heard the loss
                            // is left.)
                            node_back(&here, &on);
                        }
                    }
                    shared.ring();
                })
                .wait()
                .map_err(Error::zenoh("watch the node's liveliness"))?,
        );
        Ok(())
    }

    /// Give `command` to the instance's current generation; its answer.
    fn send(&self, command: &Command) -> Result<(), PlaceError> {
        let json = serde_json::to_vec(command).map_err(|source| Error::Json {
            what: "the command".to_owned(),
            decoding: false,
            source,
        })?;
        let asked = Instant::now();
        let replies = self
            .node
            .session()
            .get(keys::control(&self.on, &self.name))
            .payload(json)
            .timeout(self.timeout)
            .wait()
            .map_err(Error::zenoh("send a command"))?;
        let sample = self.answer(replies.recv().ok(), asked)?;
        self.within(
            sample.payload(),
            crate::limits::REPLY,
            "the control port's answer",
        )?;
        match serde_json::from_slice::<ControlReply>(&sample.payload().to_bytes()) {
            Ok(ControlReply::Accepted) => Ok(()),
            Ok(ControlReply::Rejected { reason }) => Err(PlaceError::Rejected(reason)),
            Err(source) => Err(self.undecodable(source)),
        }
    }

    /// The sample of the instance's node's answer to a question `asked` then (`None`:
    /// none came in time, or nothing here knew where to send the question).
    fn answer(
        &self,
        reply: Option<zenoh::query::Reply>,
        asked: Instant,
    ) -> Result<zenoh::sample::Sample, PlaceError> {
        let reply = reply.ok_or_else(|| PlaceError::NoAnswer {
            node: self.on.clone(),
            instance: self.name.clone(),
            waited: asked.elapsed(),
        })?;
        reply.into_result().map_err(|error| {
            Error::ErrorReply {
                node: self.on.clone(),
                reason: error
                    .payload()
                    .try_to_string()
                    .unwrap_or_default()
                    .into_owned(),
            }
            .into()
        })
    }

    /// `Ok` if the instance's node's answer `payload` (`what`) is within `limit`:
    /// checked before its bytes are copied or decoded.
    fn within(
        &self,
        payload: &zenoh::bytes::ZBytes,
        limit: crate::limits::Limit,
        what: &str,
    ) -> Result<(), PlaceError> {
        limit
            .check(|| what.to_owned(), payload.len())
            .map_err(|source| {
                Error::TooLarge {
                    node: self.on.clone(),
                    source,
                }
                .into()
            })
    }

    /// The instance's node's answer does not decode.
    fn undecodable(&self, source: serde_json::Error) -> PlaceError {
        Error::Json {
            what: format!("node `{}`'s answer", self.on),
            decoding: true,
            source,
        }
        .into()
    }

    /// Every [`End::refresh`], ask for the remote snapshot without waiting for it: it
    /// goes into the view when it comes (`Mirrored::reconcile`: its CPU and elapsed
    /// time, which change without an event, and what an event lost on the way would
    /// have set), the proxy is woken, and the instance counts as heard.
    fn ask_times(&mut self) {
        let every = self.refresh();
        if !self.built
            || self.gone.is_some()
            || self
                .times_asked
                .is_some_and(|asked| asked.elapsed() < every)
        {
            return;
        }
        let now = Instant::now();
        // Silence counts from the first question left unanswered, however long the
        // proxy's thread took between questions (a pull or a command to a station
        // that does not answer holds it); anything heard from the instance, or an
        // answer to a command, starts it again.
        self.times_asked = Some(now);
        lock(&self.shared.unanswered_since).get_or_insert(now);
        let shared = Arc::clone(&self.shared);
        // The events mirrored before the question: the answer does not undo what an
        // event mirrored after it set (`Mirrored::reconcile`).
        let before = lock(&self.shared.view)
            .as_ref()
            .map_or(0, |view| view.events);
        let key = keys::monitor(&self.on, &self.name);
        let asked = self
            .node
            .session()
            .get(&key)
            .timeout(self.timeout)
            .callback(move |reply| {
                let Ok(sample) = reply.result() else {
                    return;
                };
                // The current generation's answer only.
                if *lock(&shared.monitor_key) != sample.key_expr().as_str() {
                    return;
                }
                let Some(snapshot) = decode_or_count::<Monitor>(
                    sample,
                    crate::limits::SNAPSHOT,
                    "a snapshot",
                    &shared,
                ) else {
                    return;
                };
                shared.heard();
                if let Some(view) = lock(&shared.view).as_mut()
                    && !view.reconcile(snapshot, before, shared.inputs)
                {
                    shared.bad_events.fetch_add(1, Ordering::AcqRel);
                }
                shared.changed.store(true, Ordering::Release);
                shared.ring();
            })
            .wait();
        if let Err(error) = asked {
            tracing::debug!(instance = %self.name, "the snapshot was not asked for: {}", Chain(&*error));
        }
    }

    /// How often the remote snapshot is asked for.
    fn refresh(&self) -> Duration {
        TIMES_REFRESH.min(self.silence / 3)
    }

    /// Whether the current generation has gone unheard for longer than the bound (it
    /// is then gone, with the reason).
    fn judge_silence(&mut self) {
        if self.gone.is_some() || !self.built {
            return;
        }
        let Some(since) = *lock(&self.shared.unanswered_since) else {
            return;
        };
        let silent = since.elapsed();
        if silent > self.silence {
            self.gone = Some(format!(
                "the monitoring port of `{}` on node `{}` has not answered for {silent:.1?} \
                 (the bound is {:?}), though the node lives",
                self.name, self.on, self.silence
            ));
        }
    }

    /// Whether the current generation's view shows it dead.
    fn dead(&self) -> bool {
        lock(&self.shared.view)
            .as_ref()
            .is_some_and(|view| view.view.state == coolbot::State::Dead)
    }

    /// The remote instance's snapshot, asked for now.
    fn snapshot(&self) -> Result<Monitor, PlaceError> {
        self.ask_snapshot(Instant::now(), self.timeout)
    }

    /// The snapshot of a generation its node has just built, by `deadline`. The node
    /// declared the snapshot's queryable before it answered the request, but this
    /// node may learn of the declaration after the answer (Zenoh orders neither
    /// against the other): a question nothing here routes yet ends at once,
    /// unanswered. So it is asked again every [`REASK`], each question waiting at most
    /// until `deadline`, until one is answered, the deadline passes, or the node is
    /// known lost.
    fn first_snapshot(&self, deadline: Instant) -> Result<Monitor, PlaceError> {
        let first = Instant::now();
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.ask_snapshot(first, left.max(REASK)) {
                Err(PlaceError::NoAnswer { .. })
                    if left > REASK && lock(&self.shared.lost).is_none() =>
                {
                    std::thread::sleep(REASK);
                }
                answer => return answer,
            }
        }
    }

    /// The remote instance's snapshot, asked for now and waited for at most `wait`;
    /// a failure tells the time since `asked`.
    fn ask_snapshot(&self, asked: Instant, wait: Duration) -> Result<Monitor, PlaceError> {
        let replies = self
            .node
            .session()
            .get(keys::monitor(&self.on, &self.name))
            .timeout(wait)
            .wait()
            .map_err(Error::zenoh("ask for the remote snapshot"))?;
        let sample = self.answer(replies.recv().ok(), asked)?;
        self.within(sample.payload(), crate::limits::SNAPSHOT, "the snapshot")?;
        serde_json::from_slice(&sample.payload().to_bytes())
            .map_err(|source| self.undecodable(source))
    }
}

/// `deliver`, which also wakes the proxy when a message was lost (it then shows the
/// loss on its monitor at once).
fn waking_on_loss(deliver: DeliverFn, losses: TickIn, shared: Arc<Shared>) -> DeliverFn {
    Arc::new(move |payload: &zenoh::bytes::ZBytes, via| {
        let before = losses.overflows();
        deliver(payload, via);
        if losses.overflows() != before {
            shared.changed.store(true, Ordering::Release);
            shared.ring();
        }
    })
}

/// The pseudo-port at which a proxy's monitor counts messages lost on the network.
const NETWORK: &str = "@network";

/// `payload` as a JSON `T` (`what`, for the reason), decoded only when it is within
/// `limit`: its length is checked before its bytes are copied.
fn decode_json<T: serde::de::DeserializeOwned>(
    payload: &zenoh::bytes::ZBytes,
    limit: crate::limits::Limit,
    what: &str,
) -> Result<T, String> {
    limit
        .check(|| what.to_owned(), payload.len())
        .map_err(|exceeded| exceeded.to_string())?;
    serde_json::from_slice(&payload.to_bytes()).map_err(|error| {
        format!(
            "{what} that does not decode ({})",
            coolbot::ranges::excerpt(&error.to_string(), coolbot::ranges::REASON_CHARS)
        )
    })
}

/// `sample`'s payload as a JSON `T` ([`decode_json`]); one that is over `limit` or
/// does not decode is dropped, logged (rate-limited) and counted at the proxy's
/// `@network` ([`Shared::bad_events`]), and the proxy is woken to show it.
fn decode_or_count<T: serde::de::DeserializeOwned>(
    sample: &zenoh::sample::Sample,
    limit: crate::limits::Limit,
    what: &str,
    shared: &Shared,
) -> Option<T> {
    match decode_json(sample.payload(), limit, what) {
        Ok(decoded) => Some(decoded),
        Err(why) => {
            coolbot::limited!(sample.key_expr().as_str(), |held| tracing::warn!(
                key = %sample.key_expr(),
                "{why}: dropped{held}"
            ));
            shared.bad_events.fetch_add(1, Ordering::AcqRel);
            shared.ring();
            None
        }
    }
}

/// The fields of a monitoring port that events set, one at a time.
#[derive(Debug, Clone, Copy)]
enum Field {
    State,
    UserState,
    Result,
    Error,
    Variables,
    Quality,
    Period,
    MaxResponse,
    Priority,
}

/// How many [`Field`]s there are.
const FIELDS: usize = 9;

/// The remote monitoring port as a proxy mirrors it: the last snapshot, with the
/// events heard since applied. Each snapshot asked for (every [`End::refresh`])
/// replaces what the events set, so that an event lost on the way (Zenoh drops
/// events for a subscriber that falls behind) is made good at the next one; but not
/// a field that an event heard after the question set, which may be newer than the
/// answer.
#[derive(Debug, Clone)]
struct Mirrored {
    view: Monitor,
    /// How many events were mirrored into this view.
    events: u64,
    /// For each [`Field`], the count of `events` when one last set it.
    set_at: [u64; FIELDS],
}

/// Keep the losses of `inputs` and of [`NETWORK`] only: whether any other port was
/// dropped.
fn keep_known_ports(ports: &mut Vec<(String, u64)>, inputs: &[coolbot::InputSpec]) -> bool {
    let before = ports.len();
    ports.retain(|(port, _)| known_port(port, inputs));
    ports.len() != before
}

/// Whether the view shows losses at `port`: one of the instance's inputs, or
/// [`NETWORK`].
fn known_port(port: &str, inputs: &[coolbot::InputSpec]) -> bool {
    port == NETWORK || inputs.iter().any(|input| input.name == port)
}

/// The count at `port` in `counts`, added (at 0) if it is not there.
fn count_at<'a>(counts: &'a mut Vec<(String, u64)>, port: &str) -> &'a mut u64 {
    let at = match counts.iter().position(|(name, _)| name == port) {
        Some(at) => at,
        None => {
            counts.push((port.to_owned(), 0));
            counts.len() - 1
        }
    };
    &mut counts[at].1
}

impl Mirrored {
    /// The view a first snapshot shows (losses at ports the instance does not have
    /// are left out).
    fn new(mut view: Monitor, inputs: &[coolbot::InputSpec]) -> Mirrored {
        keep_known_ports(&mut view.port_overflows, inputs);
        view.overflows = coolbot::total_overflows(&view.port_overflows);
        Mirrored {
            view,
            events: 0,
            set_at: [0; FIELDS],
        }
    }

    /// Apply one monitoring event; `false` if it was dropped (losses at a port the
    /// instance does not have: a made-up name would stay in the view for good).
    fn event(&mut self, event: MonitorEvent, inputs: &[coolbot::InputSpec]) -> bool {
        self.events += 1;
        let view = &mut self.view;
        let field = match event {
            MonitorEvent::Overflow { port, total, .. } => {
                if !known_port(&port, inputs) {
                    return false;
                }
                let slot = count_at(&mut view.port_overflows, &port);
                *slot = (*slot).max(total);
                view.overflows = coolbot::total_overflows(&view.port_overflows);
                return true;
            }
            MonitorEvent::LateResponse { total, .. } => {
                view.response.late = view.response.late.max(total);
                return true;
            }
            MonitorEvent::MissedDeadline { total, .. } => {
                view.missed_deadlines = view.missed_deadlines.max(total);
                return true;
            }
            MonitorEvent::Overrun { total, .. } => {
                view.overruns = view.overruns.max(total);
                return true;
            }
            MonitorEvent::Period(period) => {
                view.period = period;
                Field::Period
            }
            MonitorEvent::MaxResponse(bound) => {
                view.max_response = bound;
                Field::MaxResponse
            }
            MonitorEvent::Priority(priority) => {
                view.priority = priority;
                Field::Priority
            }
            MonitorEvent::Quality(level) => {
                view.quality = level;
                Field::Quality
            }
            MonitorEvent::State { to, .. } => {
                view.state = to;
                Field::State
            }
            MonitorEvent::UserState(state) => {
                view.user_state = state;
                Field::UserState
            }
            MonitorEvent::Result(result) => {
                view.result = result;
                Field::Result
            }
            MonitorEvent::Error(error) => {
                view.error = error;
                Field::Error
            }
            MonitorEvent::Variable { name, value } => {
                if let Some(slot) = view.variables.iter_mut().find(|(n, _)| *n == name) {
                    slot.1 = value;
                }
                Field::Variables
            }
            _ => return true,
        };
        self.set_at[field as usize] = self.events;
        true
    }

    /// Take `snapshot`, asked for when `asked` events had been mirrored, as the
    /// view: but for the fields an event mirrored since set (the event may be newer
    /// than the answer), and the counts, which only grow (an event may have brought
    /// a higher one). `false` if it showed losses at ports the instance does not
    /// have (left out).
    fn reconcile(
        &mut self,
        mut snapshot: Monitor,
        asked: u64,
        inputs: &[coolbot::InputSpec],
    ) -> bool {
        let unknown = keep_known_ports(&mut snapshot.port_overflows, inputs);
        let view = &self.view;
        let newer = |field: Field| self.set_at[field as usize] > asked;
        if newer(Field::State) {
            snapshot.state = view.state;
        }
        if newer(Field::UserState) {
            snapshot.user_state.clone_from(&view.user_state);
        }
        if newer(Field::Result) {
            snapshot.result = view.result.clone();
        }
        if newer(Field::Error) {
            snapshot.error.clone_from(&view.error);
        }
        if newer(Field::Variables) {
            snapshot.variables.clone_from(&view.variables);
        }
        if newer(Field::Quality) {
            snapshot.quality = view.quality;
        }
        if newer(Field::Period) {
            snapshot.period = view.period;
        }
        if newer(Field::MaxResponse) {
            snapshot.max_response = view.max_response;
        }
        if newer(Field::Priority) {
            snapshot.priority = view.priority;
        }
        snapshot.missed_deadlines = snapshot.missed_deadlines.max(view.missed_deadlines);
        snapshot.overruns = snapshot.overruns.max(view.overruns);
        snapshot.response.late = snapshot.response.late.max(view.response.late);
        for (port, total) in &view.port_overflows {
            let slot = count_at(&mut snapshot.port_overflows, port);
            *slot = (*slot).max(*total);
        }
        snapshot.overflows = coolbot::total_overflows(&snapshot.port_overflows);
        self.view = snapshot;
        !unknown
    }

    /// Take `snapshot`, asked for after a command, as the view, whole: an answer to
    /// a question asked before it (which may show the state before the command)
    /// changes none of the fields events set.
    fn replace(&mut self, snapshot: Monitor, inputs: &[coolbot::InputSpec]) {
        let events = self.events + 1;
        *self = Mirrored::new(snapshot, inputs);
        self.events = events;
        self.set_at = [events; FIELDS];
    }
}

impl End {
    /// [`RemoteEnd::instantiate`].
    fn build(&mut self, waker: Option<Waker>) -> Result<(), PlaceError> {
        // A node known lost is not asked: its loss was logged once, and each retry
        // fails at once with the same reason (its return is logged once too).
        if let Some(absent) = lock(&self.shared.absent).clone() {
            refused_while_lost(&self.node.session().zid().to_string(), &self.on);
            return Err(PlaceError::Lost(absent));
        }
        // What the last generation's view had not reported yet is reported with this
        // generation's: nothing lost on the network goes uncounted.
        self.losses_before += self.reported_losses;
        self.reported_losses = 0;
        *lock(&self.shared.waker) = waker;
        *lock(&self.shared.view) = None;
        if self.built || self.maybe_built {
            // An earlier generation may still run (its node was unreachable, not
            // gone, or its answer was lost): it goes first, so that two never serve
            // the same keys. Its node also sends it to `dead` when it sees this node
            // lost (`Instantiate::owner`).
            let dead = Command::SetState(coolbot::Controllable::Dead);
            if let Err(error) = self.send(&dead) {
                tracing::debug!(instance = %self.name, "the earlier generation: {}", Chain(&error));
            }
        }
        self.generation += 1;
        self.built = false;
        // Until the agent answers, this generation may be built there.
        self.maybe_built = true;
        // Nothing asked of this generation yet: its silence starts with its first
        // question.
        *lock(&self.shared.unanswered_since) = None;
        self.times_asked = None;
        self.name = format!("{}-{}", self.root, self.generation);
        self.request.name = self.name.clone();
        *lock(&self.shared.monitor_key) = keys::monitor(&self.on, &self.name);
        // The first time, the node may not be reachable yet (a robot and its station
        // started together): ask again every 100 ms while nothing answers, for the
        // placer's timeout or `FIRST_START`, whichever is shorter, the first snapshot
        // included. Later (a retry of the recovery queue, whether or not the first
        // start built anything) once: the queue retries, and the proxy's thread stays
        // free for its commands.
        let patient = !std::mem::replace(&mut self.asked_before, true);
        let asked = Instant::now();
        let deadline = asked
            + if patient {
                self.timeout.min(FIRST_START)
            } else {
                self.timeout
            };
        loop {
            // A first start's question waits at most what is left (and at least a
            // moment).
            let wait = if patient {
                deadline
                    .saturating_duration_since(Instant::now())
                    .max(Duration::from_millis(100))
            } else {
                self.timeout
            };
            match instantiate(&self.node, &self.on, &self.request, wait) {
                Ok(()) => break,
                Err(Error::NoAgent { .. } | Error::Busy { .. })
                    if patient && Instant::now() < deadline =>
                {
                    std::thread::sleep(Duration::from_millis(100));
                }
                Err(error @ Error::NoAgent { .. }) if patient => {
                    let asking = asked.elapsed();
                    return Err(if self.shared.seen.load(Ordering::Acquire) {
                        PlaceError::Unanswered {
                            asking,
                            source: Box::new(error),
                        }
                    } else {
                        PlaceError::NotThere {
                            node: self.on.clone(),
                            here: self.node.name().to_owned(),
                            asking,
                        }
                    });
                }
                Err(error @ (Error::Refused { .. } | Error::Busy { .. })) => {
                    // Refused by the agent: nothing was built.
                    self.maybe_built = false;
                    return Err(error.into());
                }
                Err(error) => return Err(error.into()),
            }
        }
        // Built there. Seen once its snapshot comes: a start that fails on it leaves
        // the generation unbuilt (the next start builds a new one and sends this one
        // to `dead`), so that the proxy never runs an instance it cannot see.
        self.gone = None;
        *lock(&self.shared.lost) = None;
        // Patient, the first snapshot has what is left of the first start's time (but
        // at least `FIRST_SNAPSHOT`): the whole start stays within the compound's wait
        // for its instances.
        let snapshot_by = if patient {
            deadline.max(Instant::now() + FIRST_SNAPSHOT)
        } else {
            Instant::now() + self.timeout
        };
        let snapshot = self.first_snapshot(snapshot_by)?;
        self.built = true;
        self.maybe_built = false;
        self.shared.heard();
        *lock(&self.shared.view) = Some(Mirrored::new(snapshot, self.shared.inputs));
        self.shared.changed.store(true, Ordering::Release);
        // A poster's current value, for the proxy's readers.
        for output in &self.outputs {
            if output.poster && !output.pull {
                let deliver = Arc::clone(&output.deliver);
                let _ = self
                    .node
                    .session()
                    .get(output.key.clone())
                    .callback(move |reply| {
                        if let Ok(sample) = reply.result() {
                            deliver(sample.payload(), Via::Answer);
                        }
                    })
                    .wait();
            }
        }
        Ok(())
    }
    /// [`RemoteEnd::command`].
    fn command_here(&mut self, command: &Command) -> Result<(), PlaceError> {
        if let Some(lost) = lock(&self.shared.lost).clone() {
            return Err(PlaceError::Lost(lost));
        }
        if let Some(gone) = self.gone.clone() {
            return Err(PlaceError::Silent(gone));
        }
        self.send(command)?;
        // The instance answered: it is heard.
        self.shared.heard();
        if *command == Command::SetState(coolbot::Controllable::Ready) {
            // Restarted in place (or stopped): what the view showed before (an error,
            // `end`) is history; the snapshot shows the state it is in now.
            if let Ok(snapshot) = self.snapshot() {
                if let Some(view) = lock(&self.shared.view).as_mut() {
                    view.replace(snapshot, self.shared.inputs);
                }
                self.shared.changed.store(true, Ordering::Release);
            }
        }
        Ok(())
    }
    /// [`RemoteEnd::pull`].
    fn pull_here(&mut self, output: usize) -> Result<(), PlaceError> {
        let Some(output) = self.outputs.get(output).filter(|output| output.pull) else {
            return Err(PlaceError::NotPull(output));
        };
        if let Some(lost) = lock(&self.shared.lost).clone() {
            return Err(PlaceError::Lost(lost));
        }
        let replies = self
            .node
            .session()
            .get(format!("{}/@pull", output.key))
            .timeout(crate::DEFAULT_PULL_TIMEOUT)
            .wait()
            .map_err(Error::zenoh("send the pull query"))?;
        // The first answer is sent on the proxy's output, to the input that asked
        // (this runs inside the proxy's answer to it); any other reply is dropped,
        // so that one request gets one answer, and the proxy's thread goes on at once.
        match replies.recv().map(|reply| reply.into_result()) {
            Ok(Ok(sample)) => {
                (output.deliver)(sample.payload(), Via::Pull);
                Ok(())
            }
            Ok(Err(error)) => Err(Error::ErrorReply {
                node: self.on.clone(),
                reason: error
                    .payload()
                    .try_to_string()
                    .unwrap_or_default()
                    .into_owned(),
            }
            .into()),
            Err(_) => Err(PlaceError::PullUnanswered {
                node: self.on.clone(),
                waited: crate::DEFAULT_PULL_TIMEOUT,
            }),
        }
    }
    /// [`RemoteEnd::view`].
    fn view_here(&mut self) -> Result<Option<Monitor>, PlaceError> {
        if let Some(lost) = lock(&self.shared.lost).clone() {
            return Err(PlaceError::Lost(lost));
        }
        self.judge_silence();
        if let Some(gone) = self.gone.clone() {
            return Err(PlaceError::Silent(gone));
        }
        let losses = self.network_losses() - self.losses_before;
        let more_lost = losses != self.reported_losses;
        if !self.shared.changed.swap(false, Ordering::AcqRel) && !more_lost {
            return Ok(None);
        }
        let Some(mut view) = lock(&self.shared.view)
            .as_ref()
            .map(|view| view.view.clone())
        else {
            return Ok(None);
        };
        self.reported_losses = losses;
        // Counted here, for this generation: the proxy adds what grew since it last
        // looked.
        view.port_overflows.retain(|(port, _)| port != NETWORK);
        view.port_overflows.push((NETWORK.to_owned(), losses));
        Ok(Some(view))
    }
}

impl RemoteEnd for End {
    fn instantiate(&mut self, waker: Option<Waker>) -> Result<(), NetworkError> {
        Ok(self.build(waker)?)
    }

    fn needs_instance(&self) -> bool {
        !self.built || lock(&self.shared.lost).is_some() || self.gone.is_some() || self.dead()
    }

    fn poll_every(&self) -> Option<Duration> {
        Some(self.refresh())
    }

    fn command(&mut self, command: &Command) -> Result<(), NetworkError> {
        Ok(self.command_here(command)?)
    }

    fn pump(&mut self) {
        for pump in &mut self.pumps {
            pump();
        }
        self.ask_times();
    }

    fn pull(&mut self, output: usize) -> Result<(), NetworkError> {
        Ok(self.pull_here(output)?)
    }

    fn view(&mut self) -> Result<Option<Monitor>, NetworkError> {
        Ok(self.view_here()?)
    }

    fn release(&mut self) {
        if (self.built || self.maybe_built) && lock(&self.shared.lost).is_none() && !self.dead() {
            let dead = Command::SetState(coolbot::Controllable::Dead);
            if let Err(error) = self.send(&dead) {
                tracing::warn!(instance = %self.name, node = %self.on, "not released: {}", Chain(&error));
            }
        }
        self.subscribers.clear();
        self.acks.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use coolbot::{InputKind, InputSpec, State};

    /// The inputs of the instance the tests' views stand for.
    static INPUTS: &[InputSpec] = &[InputSpec {
        name: "scan",
        kind: InputKind::Tick,
        packet: "event",
        pull: false,
    }];

    fn mirrored() -> Mirrored {
        Mirrored::new(crate::top::model::tests::monitor("wanderer", 0), INPUTS)
    }

    fn event(json: &str) -> MonitorEvent {
        serde_json::from_str(json).unwrap()
    }

    #[test]
    fn overflow_events_under_made_up_port_names_do_not_grow_the_mirrored_view() {
        let mut view = mirrored();
        // What a peer that may put on the instance's monitoring key sends: an
        // `Overflow` event that decodes, under a port name of its choosing.
        for n in 0..10_000 {
            let json = format!(r#"{{"Overflow":{{"port":"made-up-{n}","lost":1,"total":1}}}}"#);
            assert!(!view.event(event(&json), INPUTS), "made-up-{n} kept");
        }
        // The instance has no such port: nothing of them is kept (each `view_here`
        // clones this list, and the runtime's `overlay` walks it once per entry of
        // `applied`, which grows alike).
        assert!(view.view.port_overflows.is_empty());
        // Its own port is mirrored.
        assert!(view.event(
            event(r#"{"Overflow":{"port":"scan","lost":2,"total":2}}"#),
            INPUTS
        ));
        assert_eq!(view.view.port_overflows, vec![("scan".to_owned(), 2)]);
        assert_eq!(view.view.overflows, 2);
    }

    #[test]
    fn a_snapshot_makes_good_a_state_change_whose_event_was_lost() {
        let mut view = mirrored();
        assert_eq!(view.view.state, State::Running);
        // The instance fails; its `State` and `Error` events are lost on the way.
        // The next snapshot shows it.
        let mut snapshot = view.view.clone();
        snapshot.state = State::RunningError;
        snapshot.error = Some("the lidar is gone".to_owned());
        snapshot.user_state = None;
        snapshot.result = coolbot::TaskResult::Fail("no scan".to_owned());
        let asked = view.events;
        assert!(view.reconcile(snapshot, asked, INPUTS));
        assert_eq!(view.view.state, State::RunningError);
        assert_eq!(view.view.error.as_deref(), Some("the lidar is gone"));
        assert_eq!(view.view.user_state, None);
        assert_eq!(
            view.view.result,
            coolbot::TaskResult::Fail("no scan".to_owned())
        );
    }

    #[test]
    fn a_snapshot_does_not_undo_what_an_event_heard_after_the_question_set() {
        let mut view = mirrored();
        let asked = view.events;
        // Asked while running; the instance then fails, and its event comes before
        // the answer, which shows it running still.
        let stale = view.view.clone();
        assert!(view.event(
            event(r#"{"State":{"from":"Running","to":"RunningError"}}"#),
            INPUTS
        ));
        assert!(view.event(
            event(r#"{"Overflow":{"port":"scan","lost":3,"total":3}}"#),
            INPUTS
        ));
        assert!(view.reconcile(stale.clone(), asked, INPUTS));
        assert_eq!(view.view.state, State::RunningError);
        assert_eq!(view.view.port_overflows, vec![("scan".to_owned(), 3)]);
        // Asked after the event: the answer is taken.
        let asked = view.events;
        let mut fresh = stale;
        fresh.state = State::Ready;
        assert!(view.reconcile(fresh.clone(), asked, INPUTS));
        assert_eq!(view.view.state, State::Ready);
        // A command's own snapshot: an answer to a question asked before it changes
        // none of what events set.
        let before = view.events;
        fresh.state = State::Running;
        view.replace(fresh.clone(), INPUTS);
        fresh.state = State::RunningError;
        assert!(view.reconcile(fresh, before, INPUTS));
        assert_eq!(view.view.state, State::Running);
    }

    #[test]
    fn json_over_its_limit_is_refused_undecoded() {
        let limit = crate::limits::Limit {
            max: 16,
            ..crate::limits::EVENT
        };
        let event = serde_json::to_vec(&MonitorEvent::Quality(1)).unwrap();
        assert!(event.len() <= 16);
        let decoded: MonitorEvent =
            decode_json(&zenoh::bytes::ZBytes::from(event), limit, "an event").unwrap();
        assert_eq!(decoded, MonitorEvent::Quality(1));
        let long = serde_json::to_vec(&MonitorEvent::Error(Some("x".repeat(100)))).unwrap();
        let why = decode_json::<MonitorEvent>(&zenoh::bytes::ZBytes::from(long), limit, "an event")
            .unwrap_err();
        assert!(why.contains("over the limit EVENT = 16 bytes"), "{why}");
    }

    #[test]
    fn a_snapshot_showing_ports_the_instance_does_not_have_is_counted_and_left_out() {
        let mut view = mirrored();
        let mut snapshot = view.view.clone();
        snapshot.port_overflows = vec![("scan".to_owned(), 1), ("made-up".to_owned(), 5)];
        let asked = view.events;
        assert!(!view.reconcile(snapshot, asked, INPUTS));
        assert_eq!(view.view.port_overflows, vec![("scan".to_owned(), 1)]);
        assert_eq!(view.view.overflows, 1);
    }
}

#[cfg(test)]
mod network_tests {
    use super::*;
    use crate::agent::Agent;
    use crate::testing::{free_port, idle_registry, idle_spec};
    use coolbot::{Controllable, State};

    /// The proxy's view, once it has one (new since it last looked), asking for the
    /// remote snapshot (`pump`) when `pump`, until `done` holds of it or 20 s pass.
    fn view_until(end: &mut End, pump: bool, done: impl Fn(&Monitor) -> bool) -> Option<Monitor> {
        let deadline = Instant::now() + Duration::from_secs(20);
        let mut last = None;
        while Instant::now() < deadline {
            if pump {
                end.pump();
            }
            if let Some(view) = end.view_here().unwrap() {
                if done(&view) {
                    return Some(view);
                }
                last = Some(view);
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        panic!("the view never came to what was waited for; last: {last:?}");
    }

    #[test]
    fn a_proxy_learns_a_state_change_whose_event_it_missed_from_the_next_snapshot() {
        let port = free_port();
        let station = crate::testing::node("far-st", Some(port), None);
        let spec = idle_spec();
        let _agent = Agent::start(Arc::clone(&station), idle_registry(spec)).unwrap();
        let robot = crate::testing::node("far-rb", None, Some(port));
        let placer =
            Placer::new(Arc::clone(&robot), idle_registry(spec)).timeout(Duration::from_secs(10));
        let placement = Placement {
            node: "far-st".to_owned(),
            compound: "c".to_owned(),
            name: "idle".to_owned(),
            spec,
            timing: spec.timing,
            adaptation: coolbot::AdaptConfig::default(),
            configuration: None,
            variables: Vec::new(),
        };
        let (_ports, mut end) = placer.far_end(&placement).unwrap().unwrap();
        // The two nodes may not have met yet on a loaded machine (no token seen, or
        // the agent's queryable not yet declared to the robot): asked again until
        // they have.
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            match end.build(None) {
                Ok(()) => break,
                Err(PlaceError::NotThere { .. } | PlaceError::Unanswered { .. })
                    if Instant::now() < deadline =>
                {
                    std::thread::sleep(Duration::from_millis(50));
                }
                Err(error) => panic!("{error}"),
            }
        }
        view_until(&mut end, false, |view| view.state == State::Ready);

        // The instance runs (a command from anywhere); its event comes.
        crate::testing::set_state(&robot, "far-st", &end.name, Controllable::Running);
        view_until(&mut end, false, |view| view.state == State::Running);
        // As if that event had been lost on the way (Zenoh drops events for a
        // subscriber that falls behind): the view still shows the state before it.
        lock(&end.shared.view).as_mut().unwrap().view.state = State::Ready;
        end.shared.changed.store(true, Ordering::Release);
        assert_eq!(end.view_here().unwrap().unwrap().state, State::Ready);
        // The next snapshot the proxy asks for shows it.
        view_until(&mut end, true, |view| view.state == State::Running);
        end.release();
    }
}
