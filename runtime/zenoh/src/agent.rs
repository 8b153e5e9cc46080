//! Remote instantiation, the first step (`docs/distribution.md`, "Remote instances"):
//! an [`Agent`] on a node builds components from a [`Registry`] of factories when
//! another node asks ([`instantiate`]), bridges the ports the request names, runs them
//! and exposes them like any other component of the node.

use std::collections::BTreeMap;
use std::marker::PhantomData;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::Duration;

use coolbot::port::ErasedInput;
use coolbot::{
    AdaptConfig, Command, Component, Controllable, Handle, InputKind, OutputKind, OverflowPolicy,
    Packet, PortSet, State, System, TimingSpec, Value,
};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use zenoh::Wait;

use crate::{ControlReply, Error, Node, keys};

/// How long the agent waits for a new component to leave `starting`.
const START_TIMEOUT: Duration = Duration::from_secs(10);

/// The remote input an instance's output is bridged to (an outlet of this kind).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RemoteInput {
    /// A tick input.
    Tick,
    /// A poster input.
    Poster,
    /// A last input.
    Last,
    /// A fifo input of `capacity` packets, rejecting packets when full.
    Fifo {
        /// Its capacity.
        capacity: usize,
    },
    /// A ufifo input starting at `initial` packets.
    Ufifo {
        /// Its initial size (and growth step).
        initial: usize,
        /// Its cap, if any.
        max: Option<usize>,
    },
}

impl RemoteInput {
    fn kind(self) -> InputKind {
        match self {
            RemoteInput::Tick => InputKind::Tick,
            RemoteInput::Poster => InputKind::Poster,
            RemoteInput::Last => InputKind::Last,
            RemoteInput::Fifo { capacity } => InputKind::Fifo {
                capacity,
                policy: OverflowPolicy::Reject,
            },
            RemoteInput::Ufifo { initial, max } => InputKind::Ufifo { initial, max },
        }
    }
}

/// One port of the new instance to bridge.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Wire {
    /// Feed the instance's input `port` from bridge key `key` (an inlet).
    Input {
        /// The instance's input port.
        port: String,
        /// The bridge key.
        key: String,
    },
    /// Publish the instance's output `port` on bridge key `key`, for a remote input
    /// of kind `to` (an outlet).
    Output {
        /// The instance's output port.
        port: String,
        /// The bridge key.
        key: String,
        /// The remote input's kind.
        to: RemoteInput,
    },
}

/// What [`instantiate`] asks an agent for.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Instantiate {
    /// The component type, as registered.
    pub type_name: String,
    /// The instance's name on the agent's node (no `.`).
    pub name: String,
    /// The ports to bridge.
    pub wires: Vec<Wire>,
    /// A configuration to apply before the instance runs (`Command::Configure`).
    #[serde(default)]
    pub configuration: Option<Value>,
    /// Controllable variables to set before the instance runs (`Command::Set`), in
    /// order: an instance's overrides.
    #[serde(default)]
    pub variables: Vec<(String, Value)>,
    /// The instance's timing (an instance's `timing` override), if not the type's.
    #[serde(default)]
    pub timing: Option<RemoteTiming>,
    /// Bring the instance to `running` (the default); `false` leaves it `ready`, for
    /// the node that asked to run it (a proxy, [`crate::place`]).
    #[serde(default = "yes")]
    pub run: bool,
    /// The node that asks, if the instance is to live only as long as that node: when
    /// its liveliness token goes (the node stopped, died or cannot be reached), the
    /// agent sends the instance and its bridges to `dead` (a proxy's instance: its
    /// node builds it again, under a new name, when it needs it).
    #[serde(default)]
    pub owner: Option<String>,
}

fn yes() -> bool {
    true
}

/// The timing block and adaptation settings that travel with an instantiation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RemoteTiming {
    /// The nominal period.
    pub period: Option<Duration>,
    /// The longest period degradation may stretch to.
    pub max_period: Option<Duration>,
    /// The longest a response may take.
    pub max_response: Option<Duration>,
    /// The priority.
    pub priority: i32,
    /// The quality levels, best first (empty: the type's).
    #[serde(default)]
    pub qualities: Vec<String>,
    /// The adaptation settings (None: the type's defaults).
    #[serde(default)]
    pub adaptation: Option<AdaptConfig>,
}

impl From<TimingSpec> for RemoteTiming {
    fn from(timing: TimingSpec) -> RemoteTiming {
        RemoteTiming {
            period: timing.period,
            max_period: timing.max_period,
            max_response: timing.max_response,
            priority: timing.priority,
            qualities: timing
                .qualities
                .iter()
                .map(|&level| level.to_owned())
                .collect(),
            adaptation: None,
        }
    }
}

/// The most quality levels a request may give, and the longest name of one.
const MAX_LEVELS: usize = 64;
const MAX_LEVEL_NAME: usize = 64;

/// The most distinct lists of quality levels an agent keeps (each is kept for the
/// process's life: the runtime holds levels as `&'static str`).
const MAX_LEVEL_LISTS: usize = 256;

/// Whether `list` and `requested` name the same quality levels in the same order.
fn same_levels(list: &[&str], requested: &[String]) -> bool {
    list.len() == requested.len() && list.iter().zip(requested).all(|(a, b)| *a == b)
}

/// Quality levels from a request as the runtime holds them: each distinct list is
/// leaked once.
fn levels(requested: &[String]) -> Result<&'static [&'static str], String> {
    let valid = |level: &String| {
        !level.is_empty()
            && level.len() <= MAX_LEVEL_NAME
            && level.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
    };
    if requested.len() > MAX_LEVELS || !requested.iter().all(valid) {
        return Err(format!(
            "quality levels must be at most {MAX_LEVELS} names of letters, digits and `_`"
        ));
    }
    static KNOWN: Mutex<Vec<&'static [&'static str]>> = Mutex::new(Vec::new());
    let mut known = KNOWN.lock().unwrap_or_else(PoisonError::into_inner);
    if let Some(list) = known.iter().find(|list| same_levels(list, requested)) {
        return Ok(list);
    }
    if known.len() >= MAX_LEVEL_LISTS {
        return Err(format!(
            "this agent keeps at most {MAX_LEVEL_LISTS} distinct lists of quality levels"
        ));
    }
    let list: Vec<&'static str> = requested
        .iter()
        .map(|level| &*Box::leak(level.clone().into_boxed_str()))
        .collect();
    let list: &'static [&'static str] = Box::leak(list.into_boxed_slice());
    known.push(list);
    Ok(list)
}

/// What pumps a proxy's input to the network.
pub(crate) type Pump = Box<dyn FnMut() + Send>;

/// Makes the bridges of one port type.
pub(crate) trait PortBridge: Send + Sync {
    /// A proxy's input of `kind` (added to `ports`), published on `key`; a `pull`
    /// input serves the remote instance's pull requests on `key/@pull` instead,
    /// waiting at most `pull` for the producer.
    fn proxy_input(
        &self,
        node: &Node,
        key: &str,
        kind: InputKind,
        pull: Option<Duration>,
        ports: PortSet,
    ) -> Result<(PortSet, Pump), Error>;
    /// A proxy's output of `kind` (added to `ports`), what delivers a message of
    /// `key` on it, and its ledger (which the proxy serves acknowledgments from).
    fn proxy_output(
        &self,
        ports: PortSet,
        kind: OutputKind,
        losses: ErasedInput,
        key: &str,
    ) -> (
        PortSet,
        crate::bridge::DeliverFn,
        Arc<crate::ledger::InletLedger>,
    );
    /// An inlet of `kind` on `key` (a pull inlet when `pull`, its requests waiting
    /// at most that long).
    fn inlet(
        &self,
        node: &Node,
        name: &str,
        key: &str,
        kind: OutputKind,
        pull: Option<Duration>,
    ) -> Result<Component, Error>;
    /// An outlet of `kind` on `key` (serving pull requests when `pull`).
    fn outlet(
        &self,
        node: &Node,
        name: &str,
        key: &str,
        kind: InputKind,
        pull: Option<Duration>,
    ) -> Result<Component, Error>;
}

struct Typed<T>(PhantomData<fn() -> T>);

impl<T: Packet + Serialize + DeserializeOwned> PortBridge for Typed<T> {
    fn proxy_input(
        &self,
        node: &Node,
        key: &str,
        kind: InputKind,
        pull: Option<Duration>,
        ports: PortSet,
    ) -> Result<(PortSet, Pump), Error> {
        let mut builder = node.outlet::<T>("proxy", key, kind);
        if let Some(timeout) = pull {
            builder = builder.pull(timeout);
        }
        let (_, mut outlet, _) = builder.parts()?;
        let ports = outlet.add_input(ports);
        Ok((ports, Box::new(move || outlet.pump())))
    }

    fn proxy_output(
        &self,
        ports: PortSet,
        kind: OutputKind,
        losses: ErasedInput,
        key: &str,
    ) -> (
        PortSet,
        crate::bridge::DeliverFn,
        Arc<crate::ledger::InletLedger>,
    ) {
        crate::bridge::proxy_output::<T>(ports, kind, losses, key)
    }

    fn inlet(
        &self,
        node: &Node,
        name: &str,
        key: &str,
        kind: OutputKind,
        pull: Option<Duration>,
    ) -> Result<Component, Error> {
        match pull {
            Some(timeout) => node.inlet::<T>(name, key, kind).pull(timeout).build(),
            None => node.inlet::<T>(name, key, kind).build(),
        }
    }

    fn outlet(
        &self,
        node: &Node,
        name: &str,
        key: &str,
        kind: InputKind,
        pull: Option<Duration>,
    ) -> Result<Component, Error> {
        match pull {
            Some(timeout) => node.outlet::<T>(name, key, kind).pull(timeout).build(),
            None => node.outlet::<T>(name, key, kind).build(),
        }
    }
}

type Make = coolbot::remote::MakeCompound;

/// How to build one component type, and the packet type of each port that may be
/// bridged.
pub struct Factory {
    make: Make,
    pub(crate) ports: BTreeMap<String, Box<dyn PortBridge>>,
}

impl Factory {
    /// Port `port` (input or output) carries `T` (`()` for a tick port).
    pub fn port<T: Packet + Serialize + DeserializeOwned>(&mut self, port: &str) -> &mut Factory {
        self.ports
            .insert(port.to_owned(), Box::new(Typed::<T>(PhantomData)));
        self
    }
}

/// The component types an agent can build, by type name.
#[derive(Default)]
pub struct Registry {
    pub(crate) types: BTreeMap<String, Factory>,
}

impl std::fmt::Debug for Registry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.types.keys()).finish()
    }
}

impl Registry {
    /// An empty registry.
    pub fn new() -> Registry {
        Registry::default()
    }

    /// Register type `type_name`, built by `make(instance_name)`; declare its
    /// bridgeable ports on the returned factory.
    pub fn register(
        &mut self,
        type_name: &str,
        make: impl Fn(&str) -> Component + Send + Sync + 'static,
    ) -> &mut Factory {
        self.types.insert(
            type_name.to_owned(),
            Factory {
                make: Box::new(move |name| Ok(make(name))),
                ports: BTreeMap::new(),
            },
        );
        self.types.get_mut(type_name).expect("just inserted")
    }
}

/// What generated crates register (`<component>::register`, one call per type):
/// the factory and the packet type of every port.
impl coolbot::remote::Registrar for Registry {
    fn component(
        &mut self,
        type_name: &'static str,
        make: Box<dyn Fn(&str) -> Component + Send + Sync>,
    ) {
        let ports = self
            .types
            .remove(type_name)
            .map(|factory| factory.ports)
            .unwrap_or_default();
        self.types.insert(
            type_name.to_owned(),
            Factory {
                make: Box::new(move |name| Ok(make(name))),
                ports,
            },
        );
    }

    fn compound(&mut self, type_name: &'static str, make: coolbot::remote::MakeCompound) {
        let ports = self
            .types
            .remove(type_name)
            .map(|factory| factory.ports)
            .unwrap_or_default();
        self.types
            .insert(type_name.to_owned(), Factory { make, ports });
    }

    fn port<T: Packet + Serialize + DeserializeOwned>(
        &mut self,
        type_name: &'static str,
        port: &'static str,
    ) {
        if let Some(factory) = self.types.get_mut(type_name) {
            factory.port::<T>(port);
        }
    }
}

/// Builds components on request, on its own thread, in its own [`System`]. Dropping
/// it stops answering and shuts that system down (every component it built is joined).
pub struct Agent {
    stop: Arc<AtomicBool>,
    queryable: Option<zenoh::query::Queryable<()>>,
    _watcher: zenoh::pubsub::Subscriber<()>,
    thread: Option<JoinHandle<()>>,
}

impl std::fmt::Debug for Agent {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Agent")
    }
}

impl Agent {
    /// Answer instantiation requests on `coolbot/<node>/@agent/<type>` with the types
    /// of `registry`.
    pub fn start(node: Arc<Node>, registry: impl Into<Arc<Registry>>) -> Result<Agent, Error> {
        let registry: Arc<Registry> = registry.into();
        let (requests, received) = crossbeam_channel::bounded::<zenoh::query::Query>(16);
        let queryable = node
            .session()
            .declare_queryable(keys::agent(node.name(), "*"))
            .callback(move |query| {
                if let Err(error) = requests.try_send(query) {
                    let query = error.into_inner();
                    let _ = reply(
                        &query,
                        &ControlReply::Rejected {
                            reason: "the agent has too many requests waiting".to_owned(),
                        },
                    );
                }
            })
            .wait()
            .map_err(Error::zenoh)?;
        // The nodes that go away (their tokens `coolbot/<node>`): their instances here
        // go with them.
        let (gone, lost) = crossbeam_channel::unbounded::<String>();
        let watcher = node
            .session()
            .liveliness()
            .declare_subscriber(format!("{}/*", keys::ROOT))
            .callback(move |sample| {
                if sample.kind() == zenoh::sample::SampleKind::Delete
                    && let Some(name) = sample.key_expr().as_str().rsplit('/').next()
                {
                    let _ = gone.send(name.to_owned());
                }
            })
            .wait()
            .map_err(Error::zenoh)?;
        let stop = Arc::new(AtomicBool::new(false));
        let stopped = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name(format!("cool-net:{}:agent", node.name()))
            .spawn(move || {
                let mut system = System::new();
                if let Err(error) = system.start() {
                    tracing::error!("the agent's system does not start: {error}");
                    return;
                }
                // What each owner node had built here.
                let mut owned: BTreeMap<String, Vec<Handle>> = BTreeMap::new();
                loop {
                    crossbeam_channel::select! {
                        recv(received) -> query => {
                            let Ok(query) = query else { break };
                            let answer = match serve(&node, &registry, &mut system, &query) {
                                Ok((owner, handles)) => {
                                    if let Some(owner) = owner {
                                        owned.entry(owner).or_default().extend(handles);
                                    }
                                    ControlReply::Accepted
                                }
                                Err(reason) => ControlReply::Rejected { reason },
                            };
                            if let Err(error) = reply(&query, &answer) {
                                tracing::warn!("instantiation answer not sent: {error}");
                            }
                        }
                        recv(lost) -> name => {
                            let Ok(name) = name else { break };
                            if let Some(handles) = owned.remove(&name) {
                                tracing::info!(
                                    owner = %name,
                                    "the node that asked for {} instance(s) here is lost: they go to dead",
                                    handles.len()
                                );
                                for handle in handles.iter().rev() {
                                    let _ = handle.command(Command::SetState(Controllable::Dead));
                                }
                            }
                        }
                        default(Duration::from_millis(100)) => {
                            if stopped.load(Ordering::Acquire) {
                                break;
                            }
                        }
                    }
                }
                let report = system.shutdown();
                if !report.clean() {
                    tracing::warn!("the agent's system did not shut down cleanly: {report:?}");
                }
            })
            .map_err(|error| Error::Zenoh(format!("cannot spawn the agent thread: {error}")))?;
        Ok(Agent {
            stop,
            queryable: Some(queryable),
            _watcher: watcher,
            thread: Some(thread),
        })
    }
}

impl Drop for Agent {
    fn drop(&mut self) {
        drop(self.queryable.take());
        self.stop.store(true, Ordering::Release);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

fn reply(query: &zenoh::query::Query, answer: &ControlReply) -> zenoh::Result<()> {
    let json = serde_json::to_vec(answer).expect("a ControlReply serializes");
    query.reply(query.key_expr().clone(), json).wait()
}

/// Wait until `handle` has left `starting` for `ready`.
fn started(handle: &Handle) -> Result<(), String> {
    let monitor = handle
        .wait_for(|m| m.state != State::Starting, START_TIMEOUT)
        .map_err(|error| error.to_string())?;
    if monitor.state != State::Ready {
        return Err(format!(
            "`{}` did not start: {}",
            monitor.name,
            monitor.error.unwrap_or_else(|| monitor.state.to_string())
        ));
    }
    Ok(())
}

/// Bring `handle` from `starting` to `running`.
fn run(handle: &Handle) -> Result<(), String> {
    started(handle)?;
    handle
        .command(Command::SetState(Controllable::Running))
        .map_err(|rejected| rejected.to_string())
}

/// One instantiation request: build, bridge, run, expose. Its owner, and what was
/// built (the instance first, then its bridges).
fn serve(
    node: &Node,
    registry: &Registry,
    system: &mut System,
    query: &zenoh::query::Query,
) -> Result<(Option<String>, Vec<Handle>), String> {
    let request: Instantiate = query
        .payload()
        .ok_or("no request: the query carries no payload")
        .and_then(|payload| {
            serde_json::from_slice(&payload.to_bytes()).map_err(|_| "malformed request")
        })
        .map_err(str::to_owned)?;
    // Access rules grant instantiation by the key's type: the request must be for it.
    let asked = query
        .key_expr()
        .as_str()
        .rsplit('/')
        .next()
        .unwrap_or_default();
    if asked != request.type_name {
        return Err(format!(
            "the request builds a `{}` but came on the key of type `{asked}`",
            request.type_name
        ));
    }
    let factory = registry.types.get(&request.type_name).ok_or_else(|| {
        format!(
            "no component type `{}` here (registered: {:?})",
            request.type_name, registry
        )
    })?;
    keys::check_name(&request.name).map_err(|error| error.to_string())?;
    if request.name.contains('.') || system.handle(&request.name).is_some() {
        return Err(format!(
            "`{}` is not a free instance name here",
            request.name
        ));
    }
    let mut component = (factory.make)(&request.name)?;
    let spec = component.spec();
    if let Some(timing) = &request.timing {
        let own = component.timing();
        let qualities =
            if timing.qualities.is_empty() || same_levels(own.qualities, &timing.qualities) {
                own.qualities
            } else {
                levels(&timing.qualities)?
            };
        component = component.with_timing(TimingSpec {
            period: timing.period,
            max_period: timing.max_period,
            max_response: timing.max_response,
            priority: timing.priority,
            qualities,
        });
        if let Some(adaptation) = timing.adaptation {
            component = component.with_adaptation(adaptation);
        }
    }
    // Check every wire before building anything.
    for wire in &request.wires {
        let (port, key, output) = match wire {
            Wire::Input { port, key } => (port, key, false),
            Wire::Output { port, key, .. } => (port, key, true),
        };
        // Not under `coolbot/`: a requester must not make this node publish, or
        // answer, on another component's monitoring or control keys.
        keys::check_bridge_key(key).map_err(|error| error.to_string())?;
        let declared = if output {
            spec.output_index(port).is_some()
        } else {
            spec.input_index(port).is_some()
        };
        if !declared {
            return Err(format!(
                "`{}` has no {} port `{port}`",
                spec.type_name,
                if output { "output" } else { "input" }
            ));
        }
        if !factory.ports.contains_key(port) {
            return Err(format!(
                "port `{port}` of `{}` was not registered as bridgeable",
                spec.type_name
            ));
        }
    }
    let name = request.name.clone();
    let mut handles = vec![system.add(component).map_err(|e| e.to_string())?];
    let mut made = || -> Result<(), String> {
        for wire in &request.wires {
            match wire {
                Wire::Input { port, key } => {
                    let index = spec.input_index(port).expect("checked");
                    let kind = match spec.inputs[index].kind {
                        InputKind::Tick => OutputKind::Tick,
                        InputKind::Poster => OutputKind::Poster,
                        InputKind::Last | InputKind::Fifo { .. } | InputKind::Ufifo { .. } => {
                            OutputKind::Data
                        }
                    };
                    let bridge = format!("{name}-{port}");
                    // A pull input pulls through the inlet: each request a query.
                    let pull = spec.inputs[index]
                        .pull
                        .then_some(crate::DEFAULT_PULL_TIMEOUT);
                    let inlet = factory.ports[port]
                        .inlet(node, &bridge, key, kind, pull)
                        .map_err(|e| e.to_string())?;
                    handles.push(system.add(inlet).map_err(|e| e.to_string())?);
                    system
                        .connect(&format!("{bridge}.output"), &format!("{name}.{port}"))
                        .map_err(|e| e.to_string())?;
                }
                Wire::Output { port, key, to } => {
                    let bridge = format!("{name}-{port}");
                    // A pull output is pulled through the outlet: it serves queries.
                    let index = spec.output_index(port).expect("checked");
                    let pull = spec.outputs[index]
                        .pull
                        .then_some(crate::DEFAULT_PULL_TIMEOUT);
                    let outlet = factory.ports[port]
                        .outlet(node, &bridge, key, to.kind(), pull)
                        .map_err(|e| e.to_string())?;
                    handles.push(system.add(outlet).map_err(|e| e.to_string())?);
                    system
                        .connect(&format!("{name}.{port}"), &format!("{bridge}.input"))
                        .map_err(|e| e.to_string())?;
                }
            }
        }
        // The overrides, through the instance's control port, before it runs.
        started(&handles[0])?;
        let overrides = request
            .configuration
            .iter()
            .map(|configuration| Command::Configure(configuration.clone()))
            .chain(
                request
                    .variables
                    .iter()
                    .map(|(variable, value)| Command::Set(variable.clone(), value.clone())),
            );
        for command in overrides {
            handles[0]
                .command(command)
                .map_err(|rejected| rejected.to_string())?;
        }
        // Bridges first, so that the instance's first packets find them running.
        for handle in handles.iter().skip(1).rev() {
            run(handle)?;
        }
        if request.run {
            run(&handles[0])?;
        }
        for handle in &handles {
            node.expose(handle).map_err(|e| e.to_string())?;
        }
        Ok(())
    };
    let outcome = made().map(|()| (request.owner.clone(), handles.clone()));
    if outcome.is_ok() {
        tracing::info!(
            instance = %name,
            type_name = %request.type_name,
            "built for another node{}",
            if request.run { "" } else { " (left ready)" }
        );
    }
    if outcome.is_err() {
        // What was built goes away (its names stay taken in this system).
        for handle in &handles {
            let _ = handle.command(Command::SetState(Controllable::Dead));
        }
    }
    outcome
}

/// Ask the agent of node `on` to build `request`, waiting at most `timeout`.
pub fn instantiate(
    node: &Node,
    on: &str,
    request: &Instantiate,
    timeout: Duration,
) -> Result<(), Error> {
    keys::check_name(&request.type_name).map_err(|error| Error::Remote {
        node: on.to_owned(),
        reason: format!("the type name is not a key chunk: {error}"),
    })?;
    let json = serde_json::to_vec(request).map_err(Error::zenoh)?;
    let asked = std::time::Instant::now();
    let replies = node
        .session()
        .get(keys::agent(on, &request.type_name))
        .payload(json)
        .timeout(timeout)
        .wait()
        .map_err(Error::zenoh)?;
    let Ok(reply) = replies.recv() else {
        return Err(Error::Remote {
            node: on.to_owned(),
            reason: format!(
                "no agent answered (after {:.1?}, of at most {timeout:.1?}; does the node run an \
                 agent, and do its access rules let this node instantiate `{}` there?)",
                asked.elapsed(),
                request.type_name
            ),
        });
    };
    let answer = reply
        .result()
        .map_err(|error| {
            Error::Zenoh(
                error
                    .payload()
                    .try_to_string()
                    .unwrap_or_default()
                    .into_owned(),
            )
        })
        .and_then(|sample| {
            serde_json::from_slice::<ControlReply>(&sample.payload().to_bytes())
                .map_err(Error::zenoh)
        })?;
    match answer {
        ControlReply::Accepted => Ok(()),
        ControlReply::Rejected { reason } => Err(Error::Remote {
            node: on.to_owned(),
            reason,
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(list: &[&str]) -> Vec<String> {
        list.iter().map(|&name| name.to_owned()).collect()
    }

    #[test]
    fn quality_levels_from_a_request_are_checked_and_kept_once() {
        let first = levels(&names(&["best", "good", "poor"])).unwrap();
        assert_eq!(first, ["best", "good", "poor"]);
        let again = levels(&names(&["best", "good", "poor"])).unwrap();
        assert!(std::ptr::eq(first, again), "one copy per distinct list");
        assert!(levels(&names(&["best", "no spaces"])).is_err());
        assert!(levels(&names(&[""])).is_err());
        assert!(levels(&names(&["x"; MAX_LEVELS + 1])).is_err());
        assert!(levels(&["y".repeat(MAX_LEVEL_NAME + 1)]).is_err());
    }
}
