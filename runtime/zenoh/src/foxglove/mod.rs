//! `coolctl foxglove`: the components of the nodes on the network as a Foxglove
//! WebSocket server (`docs/foxglove.md`), on the Foxglove SDK's server (the
//! `foxglove` crate, this crate's `foxglove` feature).
//!
//! Channels, all JSON with a JSON Schema:
//! - `/<node>/<path>.<port>`: the packets of an echoed output that a `--port`
//!   pattern selects ([`crate::Node::echo`]), with the schema the node traced for its
//!   packet type (as a recording does, [`coolbot::schema`]);
//! - `/<node>/<path>/monitor`: a component's monitoring, one [`channels::Monitoring`]
//!   per refresh;
//! - `/coolbot/log`: every supervision and adaptation step of every component, as
//!   `foxglove.Log`;
//! - `/<node>/<path>.<port>/pose`, `.../tf`, `.../laser_scan`: an echoed output a
//!   mapping file names, as `foxglove.PoseInFrame`, `foxglove.FrameTransform` and
//!   `foxglove.LaserScan` ([`wellknown`]).
//!
//! Parameters `<node>/<path>/<variable>`: every component's controllable variables
//! (`period`, `max_response`, `priority`, `quality` and its own); services `suspend`,
//! `run`, `restart` with a request `{"component": "<node>/<path>"}` ([`params`]).
//!
//! Echoed packets reach their channels through the feed (`feed.rs`): Zenoh's callback
//! queues each node's batches, a task on the WebSocket server's one thread splits
//! them and logs each packet on the channels of its output.
//!
//! **Invariant:** a channel nobody subscribes costs nothing: no Zenoh subscriber is
//! declared and no snapshot asked for it until a client subscribes, and both end when
//! the last one unsubscribes.
//!
//! A node's channels live as long as its liveliness token: when the token goes, they
//! are unadvertised; when it comes back, they are advertised again (new ids).

mod channels;
mod feed;
mod matching;
pub mod params;
pub mod wellknown;

use std::collections::{BTreeMap, HashMap};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, RecvTimeoutError, Sender};
use foxglove::websocket::{
    AnyClient, ChannelView, Client, GetParametersResponder, Parameter, ParameterHandler,
    ServerListener, SetParametersResponder,
};
use foxglove::{ChannelId, Context, RawChannel, WebSocketServer, WebSocketServerHandle};
use zenoh::Wait;

use crate::ctl::Ctl;
use crate::keys;

pub use channels::{LOG_TOPIC, Monitoring};
pub use feed::{FEED_CAPACITY, FEED_TICK};
pub use matching::matches;

/// The address `coolctl foxglove` serves on unless told otherwise.
pub const DEFAULT_BIND: &str = "127.0.0.1:8765";

/// What can go wrong in `coolctl foxglove`.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum FoxgloveError {
    /// An address off loopback without a security file or `--insecure`.
    #[error(
        "`{0}` is not on loopback: serving the nodes' components there lets any host that \
         reaches it watch and command them; give the security file (--config) or \
         --insecure"
    )]
    OffLoopback(SocketAddr),
    /// The Foxglove server refused to start or to make a channel.
    #[error("the Foxglove server cannot {action}")]
    Server {
        /// What was being done.
        action: &'static str,
        /// The SDK's error.
        #[source]
        source: foxglove::FoxgloveError,
    },
    /// The mapping file cannot be used.
    #[error("the mapping file")]
    Map(#[from] wellknown::MapError),
    /// The nodes' liveliness tokens cannot be watched.
    #[error("cannot watch the nodes' liveliness tokens")]
    Liveliness(#[source] zenoh::Error),
    /// The server's thread could not be started.
    #[error("cannot spawn the foxglove thread")]
    Spawn(#[source] std::io::Error),
    /// The WebSocket's TLS certificate or key cannot be read.
    #[error("the WebSocket's TLS certificate or key")]
    Tls(#[source] crate::security::SecurityError),
}

/// The certificate and key the WebSocket serves `wss://` with.
#[derive(Debug, Clone)]
pub struct TlsFiles {
    /// The server's certificate (PEM, X.509; the first one in the file is sent).
    pub certificate: PathBuf,
    /// Its private key (PEM, PKCS#8).
    pub key: PathBuf,
}

/// How `coolctl foxglove` serves.
#[derive(Debug, Clone)]
pub struct Options {
    /// Where the WebSocket server listens (port 0: any free port).
    pub bind: SocketAddr,
    /// Patterns of the echoed outputs to serve, `NODE/PATH.PORT` with `*` for any
    /// characters (e.g. `robot/robot.base.*`); none: none.
    pub ports: Vec<String>,
    /// The outputs to show as Foxglove's well-known messages.
    pub mappings: wellknown::Mappings,
    /// How often the nodes are asked for new components, and a watched component's
    /// monitoring is read.
    pub refresh: Duration,
    /// Whether the security file was given (a bind off loopback needs it or
    /// `insecure`).
    pub secured: bool,
    /// Serve off loopback without a security file.
    pub insecure: bool,
    /// Speak `wss://` with this certificate and key (none: plain `ws://`).
    pub tls: Option<TlsFiles>,
}

impl Options {
    /// The URL scheme clients use: `wss` with TLS, else `ws`.
    pub fn scheme(&self) -> &'static str {
        if self.tls.is_some() { "wss" } else { "ws" }
    }

    /// Refuse an address off loopback without a security file or `insecure`.
    pub fn check(&self) -> Result<(), FoxgloveError> {
        if self.bind.ip().is_loopback() || self.secured || self.insecure {
            Ok(())
        } else {
            Err(FoxgloveError::OffLoopback(self.bind))
        }
    }
}

/// What a client asked, for the server's thread.
enum Order {
    Subscribe(ChannelId),
    Unsubscribe(ChannelId),
    Get {
        names: Vec<String>,
        responder: GetParametersResponder,
    },
    Set {
        client: AnyClient,
        parameters: Vec<Parameter>,
        responder: SetParametersResponder,
    },
    WatchParameters(Vec<String>),
    UnwatchParameters(Vec<String>),
    /// A node's liveliness token came (`true`) or went (`false`).
    Node {
        name: String,
        alive: bool,
    },
    Stop,
}

/// Tells the server's thread what the clients subscribe to (the SDK calls it from
/// its own tasks, which must not wait: the orders are queued).
struct Listener {
    orders: Sender<Order>,
}

impl ServerListener for Listener {
    fn on_subscribe(&self, _client: Client, channel: ChannelView<'_>) {
        let _ = self.orders.send(Order::Subscribe(channel.id()));
    }

    fn on_unsubscribe(&self, _client: Client, channel: ChannelView<'_>) {
        let _ = self.orders.send(Order::Unsubscribe(channel.id()));
    }

    fn on_parameters_subscribe(&self, names: Vec<String>) {
        let _ = self.orders.send(Order::WatchParameters(names));
    }

    fn on_parameters_unsubscribe(&self, names: Vec<String>) {
        let _ = self.orders.send(Order::UnwatchParameters(names));
    }
}

/// Takes the clients' parameter requests to the server's thread (they ask the nodes,
/// which waits).
struct Parameters {
    orders: Sender<Order>,
}

impl ParameterHandler for Parameters {
    fn get(
        &self,
        _client: AnyClient,
        names: Vec<String>,
        _request_id: Option<String>,
        responder: GetParametersResponder,
    ) {
        let _ = self.orders.send(Order::Get { names, responder });
    }

    fn set(
        &self,
        client: AnyClient,
        parameters: Vec<Parameter>,
        _request_id: Option<String>,
        responder: SetParametersResponder,
    ) {
        let _ = self.orders.send(Order::Set {
            client,
            parameters,
            responder,
        });
    }
}

/// A running `coolctl foxglove`: the server, and the thread that follows the nodes.
/// Dropping it stops both.
pub struct Server {
    /// The WebSocket server's runtime: one worker thread.
    runtime: Option<tokio::runtime::Runtime>,
    handle: Option<Arc<WebSocketServerHandle>>,
    orders: Sender<Order>,
    thread: Option<JoinHandle<()>>,
    stop: Arc<std::sync::atomic::AtomicBool>,
    counts: Arc<Counts>,
    /// The task that logs the echoed packets on their channels.
    feed: Option<feed::Feed>,
}

impl std::fmt::Debug for Server {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Server").finish_non_exhaustive()
    }
}

/// What the server has dropped.
#[derive(Debug, Default)]
pub struct Counts {
    /// Batches of echoed packets, echoed packets and monitoring events that did not
    /// decode, or did not fit their channel (dropped, warned).
    pub undecoded: AtomicU64,
    /// Batches of echoed packets (a node's packets of one echo tick) that found the
    /// server's queue full ([`FEED_CAPACITY`] waiting: the server falls behind;
    /// dropped, warned).
    pub overflowed: AtomicU64,
    /// Echoed packets of served outputs that never came: numbers missing between
    /// two that did (dropped by the node's echo queue, or on the way; warned).
    pub missing: AtomicU64,
    /// Echoed packets of served outputs that their node could not echo (too large
    /// for a batch alone, or not serializable: the batch says so in their place;
    /// warned).
    pub unechoed: AtomicU64,
}

impl Server {
    /// Start serving the nodes `ctl` reaches on `options.bind`.
    pub fn start(
        ctl: Ctl,
        session: zenoh::Session,
        options: Options,
    ) -> Result<Server, FoxgloveError> {
        options.check()?;
        let context = Context::new();
        let (orders, received) = crossbeam_channel::unbounded();
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .thread_name("cool-net:ws")
            .enable_all()
            .build()
            .map_err(FoxgloveError::Spawn)?;
        let mut server = WebSocketServer::new();
        if let Some(tls) = &options.tls {
            let read = |path| crate::security::read_bounded(path).map_err(FoxgloveError::Tls);
            server = server.tls(foxglove::websocket::TlsIdentity {
                cert: read(&tls.certificate)?,
                key: read(&tls.key)?,
            });
        }
        let handle = server
            .tokio_runtime(runtime.handle())
            .name("coolctl foxglove")
            .bind(options.bind.ip().to_string(), options.bind.port())
            .context(&context)
            .listener(Arc::new(Listener {
                orders: orders.clone(),
            }))
            .parameter_handler(Arc::new(Parameters {
                orders: orders.clone(),
            }))
            .services(params::services(&ctl))
            .start_blocking()
            .map_err(|source| FoxgloveError::Server {
                action: "start",
                source,
            })?;
        let handle = Arc::new(handle);
        let nodes = watch_nodes(&session, orders.clone())?;
        let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let counts = Arc::new(Counts::default());
        let feed = feed::Feed::start(runtime.handle(), Arc::clone(&counts));
        let mut follower = Follower {
            inlet: feed.inlet(),
            routes: feed.routes(),
            batches: HashMap::new(),
            ctl,
            session,
            context,
            patterns: options.ports,
            mappings: options.mappings,
            refresh: options.refresh,
            channels: HashMap::new(),
            known: BTreeMap::new(),
            counts: Arc::clone(&counts),
            server: Arc::clone(&handle),
            watched: BTreeMap::new(),
            _nodes: nodes,
        };
        follower.discover();
        let stopped = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name("cool-net:foxglove".to_owned())
            .spawn(move || follower.run(&received, &stopped))
            .map_err(FoxgloveError::Spawn)?;
        Ok(Server {
            runtime: Some(runtime),
            handle: Some(handle),
            orders,
            thread: Some(thread),
            stop,
            counts,
            feed: Some(feed),
        })
    }

    /// The port the server listens on.
    pub fn port(&self) -> u16 {
        self.handle.as_ref().map_or(0, |handle| handle.port())
    }

    /// What the server dropped so far.
    pub fn counts(&self) -> &Counts {
        &self.counts
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        // Wakes the thread at once.
        let _ = self.orders.send(Order::Stop);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
        drop(self.feed.take());
        if let Some(handle) = self.handle.take().and_then(Arc::into_inner) {
            drop(handle.stop());
        }
        drop(self.runtime.take());
    }
}

/// What a channel stands for.
enum Source {
    /// An echoed output, `output` (`<path>.<port>`) asked for on its echo key, each
    /// packet made a message by `transform`.
    Port {
        key: String,
        output: String,
        transform: wellknown::Transform,
    },
    /// A component's monitoring, read each refresh.
    Monitor { address: String },
    /// Every supervision and adaptation step.
    Log,
}

/// One channel: what it stands for, its subscribers, and what runs while it has any.
struct Served {
    channel: Arc<RawChannel>,
    source: Source,
    subscribers: usize,
    /// The node the channel's component is on (none: the log).
    node: Option<String>,
    /// The Zenoh subscriber of the log, or the one that asks a node for a port's
    /// packets, while subscribed.
    subscriber: Option<zenoh::pubsub::Subscriber<()>>,
    /// A monitored component's last CPU time and when it was read.
    cpu: Option<(Duration, Instant)>,
}

/// The server's thread: finds the components, serves the subscribed channels.
struct Follower {
    ctl: Ctl,
    session: zenoh::Session,
    context: Arc<Context>,
    patterns: Vec<String>,
    mappings: wellknown::Mappings,
    refresh: Duration,
    channels: HashMap<ChannelId, Served>,
    /// The components already served, `node/path`, with their controllable
    /// variables.
    known: BTreeMap<String, Vec<String>>,
    counts: Arc<Counts>,
    /// Where the echoed packets queue for the feed's thread.
    inlet: feed::Inlet,
    /// The channels the feed logs each output's packets on.
    routes: Arc<feed::Routes>,
    /// The subscriber of each node's batches of echoed packets, while a client
    /// subscribes one of its outputs' channels.
    batches: HashMap<String, zenoh::pubsub::Subscriber<()>>,
    server: Arc<WebSocketServerHandle>,
    /// The parameters clients subscribed to, with the value last sent.
    watched: BTreeMap<String, Option<Parameter>>,
    /// The nodes' liveliness tokens, coming and going, as [`Order::Node`].
    _nodes: zenoh::pubsub::Subscriber<()>,
}

/// Send an [`Order::Node`] on `orders` each time a node's liveliness token comes or
/// goes.
fn watch_nodes(
    session: &zenoh::Session,
    orders: Sender<Order>,
) -> Result<zenoh::pubsub::Subscriber<()>, FoxgloveError> {
    session
        .liveliness()
        .declare_subscriber(keys::node_token("*"))
        .callback(move |sample| {
            let Some(name) = sample
                .key_expr()
                .as_str()
                .strip_prefix(keys::ROOT)
                .and_then(|rest| rest.strip_prefix('/'))
            else {
                return;
            };
            let alive = sample.kind() == zenoh::sample::SampleKind::Put;
            let _ = orders.send(Order::Node {
                name: name.to_owned(),
                alive,
            });
        })
        .wait()
        .map_err(FoxgloveError::Liveliness)
}

impl Follower {
    fn run(&mut self, orders: &Receiver<Order>, stop: &std::sync::atomic::AtomicBool) {
        let mut next = Instant::now() + self.refresh;
        while !stop.load(Ordering::Acquire) {
            match orders.recv_timeout(next.saturating_duration_since(Instant::now())) {
                Ok(Order::Subscribe(id)) => self.subscribe(id),
                Ok(Order::Unsubscribe(id)) => self.unsubscribe(id),
                Ok(Order::Get { names, responder }) => {
                    let parameters = self.parameters(&names);
                    responder.respond(parameters);
                }
                Ok(Order::Set {
                    client,
                    parameters,
                    responder,
                }) => {
                    let current = self.set(&client, parameters);
                    responder.respond(current);
                    self.publish_watched();
                }
                Ok(Order::WatchParameters(names)) => {
                    for name in names {
                        self.watched.insert(name, None);
                    }
                    self.publish_watched();
                }
                Ok(Order::UnwatchParameters(names)) => {
                    for name in names {
                        self.watched.remove(&name);
                    }
                }
                Ok(Order::Node { name, alive: false }) => self.forget(&name),
                Ok(Order::Node { alive: true, .. }) => self.discover(),
                Err(RecvTimeoutError::Timeout) => {
                    self.discover();
                    self.poll_monitors();
                    self.publish_watched();
                    next = Instant::now() + self.refresh;
                }
                Ok(Order::Stop) | Err(RecvTimeoutError::Disconnected) => break,
            }
        }
    }

    fn add(
        &mut self,
        channel: Result<Arc<RawChannel>, foxglove::FoxgloveError>,
        source: Source,
        node: Option<&str>,
    ) {
        match channel {
            Ok(channel) => {
                self.channels.insert(
                    channel.id(),
                    Served {
                        channel,
                        source,
                        node: node.map(str::to_owned),
                        subscribers: 0,
                        subscriber: None,
                        cpu: None,
                    },
                );
            }
            Err(error) => coolbot::limited!("foxglove:channel", |held| tracing::warn!(
                "a channel is not served: {}{held}",
                coolbot::Chain(&error)
            )),
        }
    }

    /// Serve the components not served yet: their monitoring, and the echoed outputs
    /// the patterns select; and the log, once.
    fn discover(&mut self) {
        if self
            .channels
            .values()
            .all(|served| !matches!(served.source, Source::Log))
        {
            let log = channels::log(&self.context);
            self.add(log, Source::Log, None);
        }
        let listed = match self.ctl.components(None) {
            Ok(listed) => listed,
            Err(error) => {
                coolbot::limited!("foxglove:discover", |held| tracing::warn!(
                    "cannot list the components: {}{held}",
                    coolbot::Chain(&error)
                ));
                return;
            }
        };
        for listed in listed {
            let address = format!("{}/{}", listed.node, listed.path);
            if self.known.contains_key(&address) {
                continue;
            }
            let info = match self.ctl.info(&address) {
                Ok(info) => info,
                Err(error) => {
                    coolbot::limited!(&address, |held| tracing::warn!(
                        "no shape for {address}: {}{held}",
                        coolbot::Chain(&error)
                    ));
                    continue;
                }
            };
            self.known
                .insert(address.clone(), params::controllables(&info));
            let monitor = channels::monitor(&self.context, &address);
            self.add(
                monitor,
                Source::Monitor {
                    address: address.clone(),
                },
                Some(&listed.node),
            );
            for port in &info.echoed {
                let name = format!("{address}.{port}");
                let key = keys::echo(&listed.node, &listed.path, port);
                let schema = coolbot::schema::Schema::given(
                    info.schemas
                        .get(port)
                        .cloned()
                        .unwrap_or_else(|| serde_json::json!({})),
                );
                let mut transforms = Vec::new();
                if self.patterns.iter().any(|pattern| matches(pattern, &name)) {
                    transforms.push(wellknown::Transform::Raw {
                        wrap: !schema.is_object(),
                    });
                }
                for map in self
                    .mappings
                    .pose
                    .iter()
                    .filter(|m| matches(&m.port, &name))
                {
                    transforms.push(wellknown::Transform::Pose(map.clone()));
                    transforms.push(wellknown::Transform::Tf(map.clone()));
                    transforms.push(wellknown::Transform::Path(
                        map.clone(),
                        wellknown::Trail::default(),
                    ));
                }
                for map in self
                    .mappings
                    .laser_scan
                    .iter()
                    .filter(|m| matches(&m.port, &name))
                {
                    transforms.push(wellknown::Transform::Scan(map.clone()));
                }
                for transform in transforms {
                    let topic = format!("{name}{}", transform.suffix());
                    let channel = match transform.schema() {
                        Some((schema_name, schema)) => {
                            channels::port(&self.context, &topic, schema_name, &schema)
                        }
                        None => {
                            let packet = info
                                .outputs
                                .iter()
                                .find(|output| &output.name == port)
                                .map_or("packet", |output| output.packet.as_str());
                            let body = schema.for_viewers();
                            channels::port(&self.context, &topic, packet, &body)
                        }
                    };
                    self.add(
                        channel,
                        Source::Port {
                            key: key.clone(),
                            output: format!("{}.{port}", listed.path),
                            transform,
                        },
                        Some(&listed.node),
                    );
                }
            }
        }
    }

    /// Unadvertise the channels of node `name` (its token went), and forget its
    /// components, so that the next discovery after it comes back serves them again.
    fn forget(&mut self, name: &str) {
        self.channels.retain(|_, served| {
            if served.node.as_deref() == Some(name) {
                served.channel.close();
                false
            } else {
                true
            }
        });
        let prefix = format!("{name}/");
        self.known
            .retain(|address, _| !address.starts_with(&prefix));
        self.routes.forget(name);
        self.batches.remove(name);
        self.inlet.forget(name);
    }

    fn subscribe(&mut self, id: ChannelId) {
        let Some(served) = self.channels.get_mut(&id) else {
            return;
        };
        served.subscribers += 1;
        if let Source::Port { transform, .. } = &served.source {
            if served.subscribers == 1 {
                // A packet that went through its route as the last client left may
                // have kept a pose since.
                transform.unwatched();
            }
            transform.subscribed();
        }
        if served.subscribers > 1 {
            return;
        }
        let channel = Arc::clone(&served.channel);
        let counts = Arc::clone(&self.counts);
        let declared = match &served.source {
            Source::Port {
                key,
                output,
                transform,
            } => {
                let node = served.node.clone().unwrap_or_default();
                self.routes.add(
                    &node,
                    output,
                    Arc::new(feed::Route {
                        channel: Arc::clone(&channel),
                        transform: transform.clone(),
                    }),
                );
                // The node's batches first, so that none holding the output's first
                // packets is missed; then the output's key, which has the node tap it.
                if !self.batches.contains_key(&node) {
                    let inlet = self.inlet.clone();
                    let from: Arc<str> = Arc::from(node.as_str());
                    match self
                        .session
                        .declare_subscriber(keys::echoes(&node))
                        .callback(move |sample| inlet.push(&from, sample.payload().clone()))
                        .wait()
                    {
                        Ok(subscriber) => {
                            self.batches.insert(node, subscriber);
                        }
                        Err(error) => coolbot::limited!("foxglove:subscribe", |held| {
                            tracing::warn!(
                                "cannot subscribe to the echoes of {node}: {}{held}",
                                coolbot::Chain(&*error)
                            )
                        }),
                    }
                }
                Some(
                    self.session
                        .declare_subscriber(key.clone())
                        .callback(|_| {})
                        .wait(),
                )
            }
            Source::Log => Some(
                self.session
                    .declare_subscriber(keys::monitor("*", "*"))
                    .callback(move |sample| {
                        let key = sample.key_expr().as_str();
                        let Some((node, path)) = keys::parse_component(key) else {
                            return;
                        };
                        let event = crate::limits::EVENT
                            .check(|| "a monitoring event".to_owned(), sample.payload().len())
                            .map_err(|exceeded| exceeded.to_string())
                            .and_then(|()| {
                                serde_json::from_slice::<coolbot::MonitorEvent>(
                                    &sample.payload().to_bytes(),
                                )
                                .map_err(|error| error.to_string())
                            });
                        match event {
                            Ok(event) => {
                                if let Some(log) = channels::log_entry(node, path, &event) {
                                    channel.log(log.to_string().as_bytes());
                                }
                            }
                            Err(error) => {
                                counts.undecoded.fetch_add(1, Ordering::Relaxed);
                                coolbot::limited!(key, |held| tracing::warn!(
                                    "a monitoring event on {key} does not decode (dropped): {error}{held}"
                                ));
                            }
                        }
                    })
                    .wait(),
            ),
            Source::Monitor { .. } => None,
        };
        match declared {
            Some(Ok(subscriber)) => served.subscriber = Some(subscriber),
            Some(Err(error)) => coolbot::limited!("foxglove:subscribe", |held| tracing::warn!(
                "cannot subscribe for {}: {}{held}",
                served.channel.topic(),
                coolbot::Chain(&*error)
            )),
            None => {}
        }
        if matches!(served.source, Source::Monitor { .. }) {
            self.poll_monitors();
        }
    }

    fn unsubscribe(&mut self, id: ChannelId) {
        let Some(served) = self.channels.get_mut(&id) else {
            return;
        };
        served.subscribers = served.subscribers.saturating_sub(1);
        if served.subscribers == 0 {
            served.subscriber = None;
            served.cpu = None;
            if let Source::Port { transform, .. } = &served.source {
                transform.unwatched();
            }
            if let (Source::Port { output, .. }, Some(node)) = (&served.source, &served.node)
                && self.routes.remove(node, output, id)
            {
                self.batches.remove(node);
                self.inlet.forget(node);
            }
        }
    }

    /// The parameters named (all when none is), with their values now.
    fn parameters(&self, names: &[String]) -> Vec<Parameter> {
        let snapshots: BTreeMap<String, coolbot::Monitor> = match self.ctl.components(None) {
            Ok(listed) => listed
                .into_iter()
                .map(|listed| (format!("{}/{}", listed.node, listed.path), listed.monitor))
                .collect(),
            Err(error) => {
                coolbot::limited!("foxglove:parameters", |held| tracing::warn!(
                    "cannot read the parameters: {}{held}",
                    coolbot::Chain(&error)
                ));
                return Vec::new();
            }
        };
        let mut parameters = Vec::new();
        for (address, variables) in &self.known {
            let Some(monitor) = snapshots.get(address) else {
                continue;
            };
            for variable in variables {
                let name = params::parameter_name(address, variable);
                if names.is_empty() || names.contains(&name) {
                    parameters.push(params::parameter(name, variable, monitor));
                }
            }
        }
        parameters
    }

    /// Set each parameter through its component's control key; tell `client` each
    /// refusal; the values of the parameters named, now.
    fn set(&self, client: &AnyClient, parameters: Vec<Parameter>) -> Vec<Parameter> {
        let mut names = Vec::new();
        for parameter in parameters {
            let outcome = (|| {
                let unknown = || params::SetError::Unknown(parameter.name.clone());
                let (address, variable) =
                    params::split_name(&parameter.name).ok_or_else(unknown)?;
                if !self
                    .known
                    .get(address)
                    .is_some_and(|variables| variables.iter().any(|v| v == variable))
                {
                    return Err(unknown());
                }
                let value = parameter
                    .value
                    .as_ref()
                    .ok_or_else(|| params::SetError::Value {
                        name: parameter.name.clone(),
                        why: "no value given".to_owned(),
                    })?;
                let command =
                    params::command(&parameter.name, variable, value, parameter.r#type.as_ref())?;
                params::apply(&self.ctl, &parameter.name, address, &command)
            })();
            if let Err(error) = outcome {
                client.send_error(coolbot::Chain(&error).to_string());
            }
            names.push(parameter.name);
        }
        self.parameters(&names)
    }

    /// Send the watched parameters whose values changed.
    fn publish_watched(&mut self) {
        if self.watched.is_empty() {
            return;
        }
        let names: Vec<String> = self.watched.keys().cloned().collect();
        let mut changed = Vec::new();
        for parameter in self.parameters(&names) {
            let last = self.watched.get_mut(&parameter.name);
            if let Some(last) = last
                && last.as_ref() != Some(&parameter)
            {
                *last = Some(parameter.clone());
                changed.push(parameter);
            }
        }
        if !changed.is_empty() {
            self.server.publish_parameter_values(changed);
        }
    }

    /// Read the monitoring of every subscribed monitor channel's component.
    fn poll_monitors(&mut self) {
        let now = std::time::SystemTime::now();
        for served in self.channels.values_mut() {
            let Source::Monitor { address } = &served.source else {
                continue;
            };
            if served.subscribers == 0 {
                continue;
            }
            let monitor = match self.ctl.snapshot(address) {
                Ok(monitor) => monitor,
                Err(error) => {
                    coolbot::limited!(address, |held| tracing::warn!(
                        "no monitoring from {address}: {}{held}",
                        coolbot::Chain(&error)
                    ));
                    continue;
                }
            };
            let read = Instant::now();
            let cpu_share = served.cpu.and_then(|(cpu, at)| {
                let wall = read.duration_since(at);
                (!wall.is_zero()).then(|| {
                    monitor.cpu_time.saturating_sub(cpu).as_secs_f64() / wall.as_secs_f64()
                })
            });
            served.cpu = Some((monitor.cpu_time, read));
            let message = Monitoring::of(&monitor, cpu_share, now);
            match serde_json::to_vec(&message) {
                Ok(json) => served.channel.log(&json),
                Err(error) => tracing::warn!("monitoring does not encode: {error}"),
            }
        }
    }
}
