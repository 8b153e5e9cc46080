//! Remote instantiation, the first step (`docs/distribution.md`, "Remote instances"):
//! an [`Agent`] on a node builds components from a [`Registry`] of factories when
//! another node asks ([`instantiate`]), bridges the ports the request names, runs them
//! and exposes them like any other component of the node.

use crate::locks::lock;
use std::collections::{BTreeMap, HashMap, HashSet};
use std::marker::PhantomData;
use std::panic::AssertUnwindSafe;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use coolbot::port::ErasedInput;
use coolbot::{
    AdaptConfig, Command, Component, Controllable, Handle, InputKind, OutputKind, OverflowPolicy,
    Packet, PortSet, State, System, TimingSpec, Value,
};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use zenoh::Wait;

use coolbot::Chain;
use coolbot::ranges::{EXCERPT_CHARS, REASON_CHARS, excerpt};

use crate::{ControlReply, Error, Node, keys, limits};

/// How a refusal of an agent whose queue is full begins: the request may be asked
/// again (a proxy's first start does, within its wait).
pub(crate) const BUSY: &str = "the agent has too many requests waiting";

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
    /// node builds it again, under a new name, when it needs it). A request whose
    /// owner is lost by the time the agent serves it is refused.
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

/// Whether `list` and `requested` name the same quality levels in the same order.
fn same_levels(list: &[&str], requested: &[String]) -> bool {
    list.len() == requested.len() && list.iter().zip(requested).all(|(a, b)| *a == b)
}

/// A refusal's text: `error` with its sources ([`Chain`]), as the agent sends it.
fn text<E: std::error::Error>(error: E) -> String {
    Chain(&error).to_string()
}

/// Check quality levels from a request: at most [`limits::LEVELS`] names of letters,
/// digits and `_`, each at most [`limits::LEVEL_NAME`] bytes.
fn check_levels(requested: &[String]) -> Result<(), String> {
    limits::LEVELS
        .check(|| "the quality levels".to_owned(), requested.len())
        .map_err(text)?;
    for (index, level) in requested.iter().enumerate() {
        limits::LEVEL_NAME
            .check(|| format!("quality level {index}"), level.len())
            .map_err(text)?;
        if level.is_empty() || !level.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return Err(format!(
                "quality level {index} is not a name of letters, digits and `_`"
            ));
        }
    }
    Ok(())
}

/// Quality levels from a request as the runtime holds them: each distinct list is
/// leaked once.
fn levels(requested: &[String]) -> Result<&'static [&'static str], String> {
    check_levels(requested)?;
    static KNOWN: Mutex<Vec<&'static [&'static str]>> = Mutex::new(Vec::new());
    let mut known = lock(&KNOWN);
    if let Some(list) = known.iter().find(|list| same_levels(list, requested)) {
        return Ok(list);
    }
    // One list more than it keeps.
    limits::LEVEL_LISTS
        .check(
            || "the distinct lists of quality levels this agent would keep".to_owned(),
            known.len() + 1,
        )
        .map_err(text)?;
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
    /// The size of one packet of this type in memory (what a queue slot holds).
    fn packet_size(&self) -> usize;
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
        node: &Node,
        ports: PortSet,
        kind: OutputKind,
        losses: ErasedInput,
        key: &str,
    ) -> (
        PortSet,
        crate::delivery::DeliverFn,
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
    fn packet_size(&self) -> usize {
        size_of::<T>()
    }

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
        let (_, mut outlet, _) = builder.parts(false)?;
        let ports = outlet.add_input(ports);
        Ok((ports, Box::new(move || outlet.pump())))
    }

    fn proxy_output(
        &self,
        node: &Node,
        ports: PortSet,
        kind: OutputKind,
        losses: ErasedInput,
        key: &str,
    ) -> (
        PortSet,
        crate::delivery::DeliverFn,
        Arc<crate::ledger::InletLedger>,
    ) {
        crate::bridge::proxy_output::<T>(node, ports, kind, losses, key)
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

/// How many instantiation requests wait for the agent's thread at most; one more is
/// refused at once.
pub const AGENT_QUEUE: usize = 16;

/// How many losses of nodes (their liveliness tokens withdrawn) wait for the agent's
/// thread at most; one more is dropped and counted ([`AgentStatus::losses_dropped`]),
/// and the thread then asks which owners still live.
pub const GONE_QUEUE: usize = 256;

/// How long the agent asks the network whether the owner of a request lives, before
/// building it, when its watcher has not heard of the owner's token.
const OWNERS_LOOKUP: Duration = Duration::from_secs(1);

/// How many requests wait, off the agent's thread, for the network to say whether
/// their owners live (owners the agent's watcher has not heard of); one more is
/// refused at once as busy (it may be asked again). One lookup runs per owner, for
/// every request of that owner waiting.
pub const OWNER_WAITING: usize = AGENT_QUEUE;

/// The shortest time between two of the agent's re-checks of its owners (after a
/// dropped loss): however many requests come, one runs within this time (and the
/// serving of the request at hand) of the loss being dropped.
const OWNERS_RECHECK: Duration = Duration::from_millis(100);

/// How many dead instances wait for the agent's reaper at most; the next dead ones
/// stay with the agent (their names taken, counted among its instances) until there
/// is room.
const REAPER_QUEUE: usize = 64;

/// What an agent has done ([`Agent::status`]).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct AgentStatus {
    /// Requests built.
    pub built: u64,
    /// Requests refused (over a limit, failing a check, failing while built,
    /// panicking, or finding the agent busy or stopped).
    pub refused: u64,
    /// Requests whose serving panicked (a bug, in a factory or in the agent): each was
    /// refused with the panic's message, what it had built went to `dead`, and the
    /// agent served on.
    pub panics: u64,
    /// Why the agent's thread ended, if it did: every request is then refused with
    /// this reason.
    pub stopped: Option<String>,
    /// Losses of nodes dropped before the agent's thread took them (more than
    /// [`GONE_QUEUE`] waited): after each, the thread asked which owners live.
    pub losses_dropped: u64,
    /// Lookups of owners the agent had not heard of (their liveliness tokens not yet
    /// come, or gone): it asked the network whether the owner lives, up to a second,
    /// off its thread (the requests of that owner wait for the answer, the others are
    /// served meanwhile), once for every request of that owner waiting. An owner
    /// whose token it has heard costs none.
    pub owners_asked: u64,
}

/// The refusal of a request that finds the agent stopped.
fn stopped_reason(why: &str) -> String {
    format!("the agent has stopped: {why}")
}

/// Hand `query` to the agent's thread, or refuse it at once, truthfully: the agent
/// has stopped (its status says why), or too many requests wait. Under the status's
/// lock, so that a request is either queued before the end of the thread drains the
/// queue ([`Inbox`]) or finds the agent stopped. A refusal is sent from the node's
/// replier (`crate::reply`): a querier that does not read it holds that thread, not
/// Zenoh's.
fn admit(
    status: &Mutex<AgentStatus>,
    requests: &crossbeam_channel::Sender<zenoh::query::Query>,
    replier: &crate::reply::Replier,
    query: zenoh::query::Query,
) {
    let refusal = {
        let mut status = lock(status);
        let refusal = match &status.stopped {
            Some(why) => Err((query, stopped_reason(why))),
            None => match requests.try_send(query) {
                Ok(()) => Ok(()),
                Err(crossbeam_channel::TrySendError::Full(query)) => {
                    Err((query, format!("{BUSY} ({AGENT_QUEUE}); ask again later")))
                }
                Err(crossbeam_channel::TrySendError::Disconnected(query)) => {
                    Err((query, stopped_reason("its thread has ended")))
                }
            },
        };
        if refusal.is_err() {
            status.refused += 1;
        }
        refusal
    };
    if let Err((query, reason)) = refusal {
        replier.send("an instantiation refusal", move || {
            if let Err(error) = reply(&query, &ControlReply::Rejected { reason }) {
                coolbot::limited!("refusal", |held| tracing::warn!(
                    "instantiation refusal not sent: {}{held}",
                    Chain(&*error)
                ));
            }
        });
    }
}

/// The agent thread's end of the request queue. When the thread ends (the agent is
/// dropped, or a panic escaped), the status says why, and
/// every request still waiting is refused with that reason: none is left unanswered,
/// and none after it is told to wait.
struct Inbox {
    received: crossbeam_channel::Receiver<zenoh::query::Query>,
    status: Arc<Mutex<AgentStatus>>,
    /// Why the thread ends, when it ends on purpose.
    ending: Option<String>,
    /// The requests waiting for the network to say whether their owners live.
    asking: Asking,
}

impl Drop for Inbox {
    fn drop(&mut self) {
        let why = self.ending.take().unwrap_or_else(|| {
            if std::thread::panicking() {
                tracing::error!("the agent's thread ended with a panic: it builds nothing more");
                "its thread ended with a panic (the node's log has it)".to_owned()
            } else {
                "its thread has ended".to_owned()
            }
        });
        let parked = std::mem::take(&mut self.asking.owners);
        let waiting: Vec<zenoh::query::Query> = {
            let mut status = lock(&self.status);
            status.stopped.get_or_insert(why.clone());
            let waiting: Vec<_> = parked
                .into_values()
                .flat_map(|lookup| lookup.queries)
                .chain(self.received.try_iter())
                .collect();
            status.refused += waiting.len() as u64;
            waiting
        };
        for query in waiting {
            let reason = stopped_reason(&why);
            if let Err(error) = reply(&query, &ControlReply::Rejected { reason }) {
                coolbot::limited!("refusal", |held| tracing::warn!(
                    "instantiation refusal not sent: {}{held}",
                    Chain(&*error)
                ));
            }
        }
    }
}

/// What the network said of an owner the agent asked for ([`look_up`]): the lookup's
/// number, the owner, and whether its liveliness token is there.
type Verdict = (u64, String, bool);

/// The network's answer for a request's owner, if it came: the owner, and whether it
/// lives.
type Known<'a> = Option<(&'a str, bool)>;

/// The requests whose owners the agent asks the network for (owners its watcher has
/// not heard of), by owner: they wait off the agent's thread, which serves the others
/// meanwhile. At most [`OWNER_WAITING`] wait, with one lookup per owner.
#[derive(Default)]
struct Asking {
    owners: HashMap<String, Lookup>,
    /// The number of the next lookup.
    next: u64,
}

/// The requests of one owner waiting for the network's answer.
struct Lookup {
    /// Its number: an answer to an earlier lookup of the owner is ignored.
    number: u64,
    queries: Vec<zenoh::query::Query>,
}

impl Asking {
    /// Have `query`, whose owner `owner` the watcher has not heard of, wait for the
    /// network's answer, asking for the owner with `start` (given the lookup's
    /// number) if no lookup of it runs. The query back with the reason to refuse it
    /// with, if [`OWNER_WAITING`] wait already or the lookup could not start.
    fn park(
        &mut self,
        owner: String,
        query: zenoh::query::Query,
        start: impl FnOnce(u64) -> Result<(), String>,
    ) -> Result<(), Vec<(zenoh::query::Query, String)>> {
        let waiting: usize = self
            .owners
            .values()
            .map(|lookup| lookup.queries.len())
            .sum();
        if waiting >= OWNER_WAITING {
            return Err(vec![(
                query,
                format!(
                    "{BUSY} ({OWNER_WAITING} for the network to say whether their owners \
                     live); ask again later"
                ),
            )]);
        }
        if let Some(lookup) = self.owners.get_mut(&owner) {
            lookup.queries.push(query);
            return Ok(());
        }
        let number = self.next;
        self.next += 1;
        self.owners.insert(
            owner.clone(),
            Lookup {
                number,
                queries: vec![query],
            },
        );
        self.start(&owner, number, start)
    }

    /// Start the lookup of `owner` numbered `number`; if it cannot start, its
    /// requests back with the reason.
    fn start(
        &mut self,
        owner: &str,
        number: u64,
        start: impl FnOnce(u64) -> Result<(), String>,
    ) -> Result<(), Vec<(zenoh::query::Query, String)>> {
        let Err(reason) = start(number) else {
            return Ok(());
        };
        let queries = self
            .owners
            .remove(owner)
            .map(|lookup| lookup.queries)
            .unwrap_or_default();
        Err(queries
            .into_iter()
            .map(|query| (query, reason.clone()))
            .collect())
    }

    /// The network's answer `verdict` came: the owner, whether it lives and the
    /// requests that waited for it; nothing if it answers an earlier lookup (or one
    /// whose owner's loss was handled meanwhile: its requests were refused then).
    fn answered(
        &mut self,
        (number, owner, found): Verdict,
    ) -> Option<(String, bool, Vec<zenoh::query::Query>)> {
        if self.owners.get(&owner)?.number != number {
            return None;
        }
        let lookup = self.owners.remove(&owner)?;
        Some((owner, found, lookup.queries))
    }

    /// A loss was dropped (it may have been the loss of any owner asked for): every
    /// owner is asked for again (`start`, per owner and number). The requests whose
    /// lookup could not start, with the reason.
    fn ask_again(
        &mut self,
        mut start: impl FnMut(&str, u64) -> Result<(), String>,
    ) -> Vec<(zenoh::query::Query, String)> {
        let owners: Vec<String> = self.owners.keys().cloned().collect();
        let mut refused = Vec::new();
        for owner in owners {
            let number = self.next;
            self.next += 1;
            if let Some(lookup) = self.owners.get_mut(&owner) {
                lookup.number = number;
            }
            if let Err(queries) = self.start(&owner, number, |number| start(&owner, number)) {
                refused.extend(queries);
            }
        }
        refused
    }
}

/// A lookup under way: when Zenoh drops it (the query ended, every answer in or
/// [`OWNERS_LOOKUP`] passed), it sends the verdict to the agent's thread.
struct Finding {
    number: u64,
    owner: String,
    found: AtomicBool,
    verdicts: crossbeam_channel::Sender<Verdict>,
}

impl Drop for Finding {
    fn drop(&mut self) {
        let verdict = (
            self.number,
            std::mem::take(&mut self.owner),
            self.found.load(Ordering::Acquire),
        );
        // A test holding the lookup holds it on a thread of its own (never Zenoh's).
        #[cfg(test)]
        if tests::is_held("lookup", &verdict.1) {
            let verdicts = self.verdicts.clone();
            std::thread::spawn(move || {
                tests::held("lookup", &verdict.1);
                let _ = verdicts.send(verdict);
            });
            return;
        }
        // Unbounded, never full: a lookup runs per owner waiting, and one more per
        // owner lost while it ran (each ends within its timeout).
        let _ = self.verdicts.send(verdict);
    }
}

/// Ask the network whether node `owner` lives (its liveliness token is there), off
/// the agent's thread: the verdict, numbered `number`, comes on `verdicts` when the
/// query ends, within [`OWNERS_LOOKUP`].
fn look_up(
    session: &zenoh::Session,
    owner: &str,
    number: u64,
    verdicts: &crossbeam_channel::Sender<Verdict>,
) -> Result<(), String> {
    let finding = Finding {
        number,
        owner: owner.to_owned(),
        found: AtomicBool::new(false),
        verdicts: verdicts.clone(),
    };
    let token = keys::node_token(owner);
    let expected = token.clone();
    session
        .liveliness()
        .get(&token)
        .callback(move |reply| {
            if let Ok(sample) = reply.result()
                && sample.key_expr().as_str() == expected
            {
                finding.found.store(true, Ordering::Release);
            }
        })
        .timeout(OWNERS_LOOKUP)
        .wait()
        .map_err(|error| {
            format!(
                "the agent could not ask whether the owner `{}` lives: {}",
                excerpt(owner, EXCERPT_CHARS),
                Chain(&*error)
            )
        })
}

/// Builds components on request, on its own thread, each request's in a [`System`] of
/// its own, in the namespace of the node that asks ([`instantiate`]). An instance
/// found `dead` is released, on a thread of the agent's own (so that a system slow
/// to shut down holds no request up): its system shut down (its bridges with it),
/// its keys withdrawn, then its names free again. Dropping the agent stops answering
/// and releases every instance it runs (every component it built is joined).
///
/// A request over a limit ([`crate::limits`]) or outside the control port's ranges
/// (`coolbot::ranges`) is refused before anything is built. A panic while serving a
/// request (a bug) refuses that request with the panic's message, sends what it had
/// built to `dead`, is logged (`tracing` error) and counted
/// ([`AgentStatus::panics`]), and the agent serves on.
pub struct Agent {
    stop: Arc<AtomicBool>,
    status: Arc<Mutex<AgentStatus>>,
    queryable: Option<zenoh::query::Queryable<()>>,
    _watcher: zenoh::pubsub::Subscriber<()>,
    thread: Option<JoinHandle<()>>,
    #[cfg(test)]
    probe: Probe,
}

/// What a test sees of the agent's queues: how many requests and losses wait.
#[cfg(test)]
struct Probe {
    requests: crossbeam_channel::Receiver<zenoh::query::Query>,
    losses: crossbeam_channel::Receiver<String>,
}

impl std::fmt::Debug for Agent {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Agent")
    }
}

impl Agent {
    /// Answer instantiation requests on `coolbot/<node>/@agent/<type>/<requester>` with
    /// the types of `registry`, running at most [`limits::INSTANCES`] instances at
    /// once.
    pub fn start(node: Arc<Node>, registry: impl Into<Arc<Registry>>) -> Result<Agent, Error> {
        Agent::start_with_cap(node, registry, limits::INSTANCES.max)
    }

    /// [`Agent::start`], running at most `instances` instances at once (a node that
    /// knows how many it is to run; the refusal beyond them names
    /// [`limits::INSTANCES`] with this value).
    pub fn start_with_cap(
        node: Arc<Node>,
        registry: impl Into<Arc<Registry>>,
        instances: usize,
    ) -> Result<Agent, Error> {
        let cap = limits::Limit {
            max: instances,
            ..limits::INSTANCES
        };
        let registry: Arc<Registry> = registry.into();
        let (requests, received) = crossbeam_channel::bounded::<zenoh::query::Query>(AGENT_QUEUE);
        let status = Arc::new(Mutex::new(AgentStatus::default()));
        let admitting = Arc::clone(&status);
        let replier = node.replier();
        let queryable = node
            .session()
            .declare_queryable(keys::agent(node.name(), "*", "*"))
            .callback(move |query| admit(&admitting, &requests, &replier, query))
            .wait()
            .map_err(Error::zenoh("declare the agent's queryable"))?;
        // The nodes that go away (their tokens `coolbot/<node>`): their instances here
        // go with them.
        let (gone, lost) = crossbeam_channel::bounded::<String>(GONE_QUEUE);
        // Set when a loss was dropped (more than `GONE_QUEUE` waited): the thread then
        // asks which owners still live.
        let resync = Arc::new(AtomicBool::new(false));
        let (dropping, resyncing) = (Arc::clone(&status), Arc::clone(&resync));
        // The nodes whose tokens live, as the watcher hears them come and go (those
        // there already among them): whether a request's owner lives, and which
        // owners do after a dropped loss, without asking the network. A token goes
        // from it before its loss is sent, so an owner found in it is either alive or
        // its loss is still to come to the agent's thread.
        let alive: Arc<Mutex<HashSet<String>>> = Arc::default();
        let living = Arc::clone(&alive);
        let watcher = node
            .session()
            .liveliness()
            .declare_subscriber(format!("{}/*", keys::ROOT))
            .history(true)
            .callback(move |sample| {
                let Some(name) = sample.key_expr().as_str().rsplit('/').next() else {
                    return;
                };
                if sample.kind() == zenoh::sample::SampleKind::Delete {
                    lock(&living).remove(name);
                    node_gone(name, &gone, &dropping, &resyncing);
                } else {
                    lock(&living).insert(name.to_owned());
                }
            })
            .wait()
            .map_err(Error::zenoh("watch the nodes' liveliness"))?;
        let stop = Arc::new(AtomicBool::new(false));
        let stopped = Arc::clone(&stop);
        let serving = Arc::clone(&status);
        let reaper = Reaper::start(node.name())?;
        #[cfg(test)]
        let probe = Probe {
            requests: received.clone(),
            losses: lost.clone(),
        };
        // The network's answers about owners the watcher has not heard of.
        let (verdicts, answers) = crossbeam_channel::unbounded::<Verdict>();
        let thread = std::thread::Builder::new()
            .name(format!("cool-net:{}:agent", node.name()))
            .spawn(move || {
                let mut inbox = Inbox {
                    received,
                    status: Arc::clone(&serving),
                    ending: None,
                    asking: Asking::default(),
                };
                let server = Server {
                    node: &node,
                    registry: &registry,
                    status: &serving,
                    alive: &alive,
                    reaper: &reaper,
                    cap,
                    verdicts: &verdicts,
                };
                // Every request built here, until its instance is found dead (or its
                // owner lost) and handed to the reaper.
                let mut hosted: Vec<Hosted> = Vec::new();
                let mut rechecked = Instant::now();
                // The losses that came first are handled first (those queued now: a
                // stream of new ones holds no request up).
                let losses_first = |hosted: &mut Vec<Hosted>, asking: &mut Asking| {
                    let mut refused = Vec::new();
                    for name in lost.try_iter().take(lost.len()) {
                        refused.extend(owner_lost(hosted, asking, |owner| owner == name));
                    }
                    server.refuse(refused);
                };
                loop {
                    crossbeam_channel::select! {
                        recv(inbox.received) -> query => {
                            let Ok(query) = query else { break };
                            losses_first(&mut hosted, &mut inbox.asking);
                            server.serve(query, None, &mut hosted, &mut inbox.asking);
                        }
                        recv(answers) -> verdict => {
                            let Ok(verdict) = verdict else { break };
                            losses_first(&mut hosted, &mut inbox.asking);
                            if let Some((owner, lives, queries)) = inbox.asking.answered(verdict) {
                                for query in queries {
                                    let known = Some((owner.as_str(), lives));
                                    server.serve(query, known, &mut hosted, &mut inbox.asking);
                                }
                            }
                        }
                        recv(lost) -> name => {
                            let Ok(name) = name else { break };
                            let refused =
                                owner_lost(&mut hosted, &mut inbox.asking, |owner| owner == name);
                            server.refuse(refused);
                            reap(&mut hosted, &reaper);
                        }
                        default(Duration::from_millis(100)) => {
                            if stopped.load(Ordering::Acquire) {
                                inbox.ending = Some("the agent was shut down".to_owned());
                                break;
                            }
                            reap(&mut hosted, &reaper);
                        }
                    }
                    // Whatever comes, a dropped loss has the owners re-checked soon.
                    if rechecked.elapsed() >= OWNERS_RECHECK && resync.swap(false, Ordering::AcqRel)
                    {
                        owners_lost(&mut hosted, &alive);
                        let refused = inbox
                            .asking
                            .ask_again(|owner, number| server.look_up(owner, number));
                        server.refuse(refused);
                        reap(&mut hosted, &reaper);
                        rechecked = Instant::now();
                    }
                }
                // Every instance goes, each joined by the reaper before the thread
                // ends.
                for built in hosted {
                    reaper.hand_over(built);
                }
                drop(reaper);
            })
            .map_err(Error::spawn("agent"))?;
        Ok(Agent {
            stop,
            status,
            queryable: Some(queryable),
            _watcher: watcher,
            thread: Some(thread),
            #[cfg(test)]
            probe,
        })
    }

    /// What the agent has done so far: requests built, refused and panicked, and why
    /// its thread ended if it did.
    pub fn status(&self) -> AgentStatus {
        lock(&self.status).clone()
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

/// Send `answer` to `query` (a failure is logged, rate-limited).
fn answer(query: &zenoh::query::Query, answer: &ControlReply) {
    if let Err(error) = reply(query, answer) {
        coolbot::limited!("answer", |held| tracing::warn!(
            "instantiation answer not sent: {}{held}",
            Chain(&*error)
        ));
    }
}

/// What the agent's thread serves requests with.
struct Server<'a> {
    node: &'a Node,
    registry: &'a Registry,
    status: &'a Mutex<AgentStatus>,
    alive: &'a Mutex<HashSet<String>>,
    reaper: &'a Reaper,
    cap: limits::Limit,
    verdicts: &'a crossbeam_channel::Sender<Verdict>,
}

impl Server<'_> {
    /// Serve `query` ([`serve_one`]) and answer it, or, if its owner is one the
    /// watcher has not heard of (and not `known`: the network's answer for an owner),
    /// have it wait in `asking` for the network to say whether the owner lives.
    fn serve(
        &self,
        query: zenoh::query::Query,
        known: Known<'_>,
        hosted: &mut Vec<Hosted>,
        asking: &mut Asking,
    ) {
        let outcome = serve_one(
            self.node,
            self.registry,
            &query,
            (self.status, self.alive, known),
            (hosted, self.reaper, self.cap),
        );
        match outcome {
            Answer::Reply(reply) => answer(&query, &reply),
            Answer::Unheard(owner) => {
                if let Err(refused) =
                    asking.park(owner.clone(), query, |number| self.look_up(&owner, number))
                {
                    self.refuse(refused);
                }
            }
        }
    }

    /// Ask the network whether `owner` lives ([`look_up`]), counted.
    fn look_up(&self, owner: &str, number: u64) -> Result<(), String> {
        lock(self.status).owners_asked += 1;
        look_up(self.node.session(), owner, number, self.verdicts)
    }

    /// Refuse each of `refused` with its reason, counted.
    fn refuse(&self, refused: Vec<(zenoh::query::Query, String)>) {
        if refused.is_empty() {
            return;
        }
        lock(self.status).refused += refused.len() as u64;
        for (query, reason) in refused {
            answer(&query, &ControlReply::Rejected { reason });
        }
    }
}

/// What serving a request comes to: its answer, or the owner the watcher has not
/// heard of (the request waits for the network's answer).
enum Answer {
    Reply(ControlReply),
    Unheard(String),
}

/// Why a request is not built: refused with a reason, or its owner is one the
/// watcher has not heard of (to ask the network for, off the agent's thread).
enum Refusal {
    Reason(String),
    Unheard(String),
}

impl From<String> for Refusal {
    fn from(reason: String) -> Refusal {
        Refusal::Reason(reason)
    }
}

impl From<&str> for Refusal {
    fn from(reason: &str) -> Refusal {
        Refusal::Reason(reason.to_owned())
    }
}

/// Serve one request ([`serve`]) under `catch_unwind`, count it in `status`, and keep
/// what an accepted one built in `hosted`; what a refused or panicking one had built
/// is handed to the reaper, which shuts its system down (its names are free again
/// once it has). The names and queue memory of the instances the reaper still
/// releases count as taken. A request whose owner the watcher has not heard of (in
/// `alive`), and that `known` (the network's answer for an owner) does not say lives
/// or is lost, is not served: its owner is to be asked for.
fn serve_one(
    node: &Node,
    registry: &Registry,
    query: &zenoh::query::Query,
    (status, alive, known): (&Mutex<AgentStatus>, &Mutex<HashSet<String>>, Known<'_>),
    (hosted, reaper, cap): (&mut Vec<Hosted>, &Reaper, limits::Limit),
) -> Answer {
    reap(hosted, reaper);
    let mut building = None;
    let outcome = std::panic::catch_unwind(AssertUnwindSafe(|| {
        cap.check(
            || "the instances this agent runs with this one".to_owned(),
            hosted.len() + 1,
        )
        .map_err(text)?;
        let taken = |name: &str| {
            hosted
                .iter()
                .any(|built| built.names.iter().any(|taken| taken == name))
                || reaper.holds(name)
        };
        let held = hosted
            .iter()
            .map(|built| built.queue_bytes)
            .fold(reaper.queue_bytes(), usize::saturating_add);
        let lives = |owner: &str| owner_lives((alive, known), owner);
        serve(node, registry, query, (&taken, held), &lives, &mut building)
    }));
    // What a refused or panicking request had built: its system is shut down on the
    // reaper's thread (up to `coolbot::SHUTDOWN_TIMEOUT`), its names taken until then.
    if let Some(Building {
        names,
        queue_bytes,
        system,
    }) = building
    {
        hosted.push(Hosted {
            names,
            queue_bytes,
            owner: None,
            handles: Vec::new(),
            system,
            exposure: None,
            fate: Fate::Refused,
        });
        reap(hosted, reaper);
    }
    let reply = match outcome {
        Ok(Ok(built)) => {
            lock(status).built += 1;
            hosted.push(built);
            ControlReply::Accepted
        }
        Ok(Err(Refusal::Unheard(owner))) => return Answer::Unheard(owner),
        Ok(Err(Refusal::Reason(reason))) => {
            lock(status).refused += 1;
            ControlReply::Rejected { reason }
        }
        Err(payload) => {
            let message = coolbot::panic_message(payload.as_ref());
            let panics = {
                let mut status = lock(status);
                status.refused += 1;
                status.panics += 1;
                status.panics
            };
            tracing::error!(
                panics,
                "an instantiation request panicked: {}; what it had built goes to dead, \
                 and the agent serves on",
                excerpt(&message, REASON_CHARS)
            );
            ControlReply::Rejected {
                reason: format!(
                    "the agent failed while building this request (a panic: {}); what it \
                     had built went to dead",
                    excerpt(&message, REASON_CHARS)
                ),
            }
        }
    };
    Answer::Reply(reply)
}

/// Wait until `handle` has left `starting` for `ready`.
fn started(handle: &Handle) -> Result<(), String> {
    let monitor = handle
        .wait_for(|m| m.state != State::Starting, START_TIMEOUT)
        .map_err(text)?;
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
        .map_err(text)
}

/// Check the names, keys, counts, queue sizes and timing of `request` against the
/// limits and the control port's ranges, before anything is looked up or built.
fn check_request(request: &Instantiate) -> Result<(), String> {
    let over = text::<limits::Exceeded>;
    let name = |what: &str, value: &str| {
        limits::NAME
            .check(|| what.to_owned(), value.len())
            .map_err(over)
    };
    name("the type name", &request.type_name)?;
    name("the instance name", &request.name)?;
    if let Some(owner) = &request.owner {
        name("the owner's name", owner)?;
        keys::check_name(owner).map_err(text)?;
    }
    limits::WIRES
        .check(|| "the wires".to_owned(), request.wires.len())
        .map_err(over)?;
    for (index, wire) in request.wires.iter().enumerate() {
        let (port, key) = match wire {
            Wire::Input { port, key } | Wire::Output { port, key, .. } => (port, key),
        };
        name(&format!("the port name of wire {index}"), port)?;
        keys::check_bridge_key(key).map_err(text)?;
        let queue = |what: &str, packets: usize| {
            limits::QUEUE
                .check(|| format!("the {what} of wire {index}"), packets)
                .map_err(over)
        };
        match wire {
            Wire::Output {
                to: RemoteInput::Fifo { capacity },
                ..
            } => queue("fifo capacity", *capacity)?,
            Wire::Output {
                to: RemoteInput::Ufifo { initial, max },
                ..
            } => {
                queue("ufifo initial size", *initial)?;
                if let Some(max) = max {
                    queue("ufifo cap", *max)?;
                }
            }
            Wire::Input { .. } | Wire::Output { .. } => {}
        }
    }
    limits::VARIABLES
        .check(|| "the variables".to_owned(), request.variables.len())
        .map_err(over)?;
    for (index, (variable, _)) in request.variables.iter().enumerate() {
        name(&format!("the name of variable {index}"), variable)?;
    }
    if let Some(timing) = &request.timing {
        let timing_range = |what: &str, checked: Result<(), coolbot::Refused>| {
            checked.map_err(|refused| format!("the timing's {what}: {}", Chain(&refused)))
        };
        if let Some(period) = timing.period {
            timing_range("period", coolbot::ranges::period(period))?;
        }
        if let Some(max_period) = timing.max_period {
            timing_range("max_period", coolbot::ranges::period(max_period))?;
        }
        if let Some(max_response) = timing.max_response {
            timing_range("max_response", coolbot::ranges::max_response(max_response))?;
        }
        // The description's own priority: within the range, and applied as a local
        // instance's is (a real-time one the OS refuses is published, not refused
        // here: the real-time opt-in is for commands).
        let (min, max) = (coolbot::ranges::MIN_PRIORITY, coolbot::ranges::MAX_PRIORITY);
        if !(min..=max).contains(&timing.priority) {
            timing_range(
                "priority",
                Err(coolbot::Refused::PriorityOutOfRange {
                    priority: timing.priority,
                    min,
                    max,
                }),
            )?;
        }
        check_levels(&timing.qualities)?;
    }
    Ok(())
}

/// A request's system while it is built, with the names and queue memory it takes:
/// handed to the reaper if the request is refused or panics.
struct Building {
    names: Vec<String>,
    queue_bytes: usize,
    system: System,
}

/// What becomes of something the agent built.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Fate {
    /// It serves, until found `dead`.
    Serving,
    /// Its owner is lost: the reaper sends it to `dead`, then releases it.
    OwnerLost,
    /// What a refused or panicking request had built: the reaper releases it.
    Refused,
}

/// What one accepted request built, in a system of its own: the instance, its
/// bridges and their exposure on the node (or what a refused request had built of
/// them). Released once the instance is `dead` or its owner lost
/// ([`Hosted::release`], by the agent's [`Reaper`]): its threads joined, its keys
/// withdrawn, its names free.
struct Hosted {
    /// The names it takes on the node: the instance's, then its bridges'.
    names: Vec<String>,
    /// What its queues hold from the start, in bytes (the request's wires together).
    queue_bytes: usize,
    /// The node whose life it shares, if any ([`Instantiate::owner`]).
    owner: Option<String>,
    /// The instance first, then its bridges (none for a refused request's).
    handles: Vec<Handle>,
    system: System,
    exposure: Option<crate::node::Exposure>,
    fate: Fate,
}

impl Hosted {
    /// Whether it is to be released: the instance is `dead` (sent there by a
    /// command, or by its own end), its owner is lost, or its request was refused.
    fn dead(&self) -> bool {
        match self.fate {
            Fate::Serving => self
                .handles
                .first()
                .is_some_and(|instance| instance.state() == State::Dead),
            Fate::OwnerLost | Fate::Refused => true,
        }
    }

    /// Send the instance and its bridges to `dead` (its owner is lost), waiting for
    /// each: on the reaper's thread.
    fn kill(&self) {
        #[cfg(test)]
        tests::held("kill", &self.names[0]);
        for handle in self.handles.iter().rev() {
            let _ = handle.command(Command::SetState(Controllable::Dead));
        }
    }

    /// Send it to `dead` if its owner is lost; shut its system down (the bridges go
    /// to `dead` with it, every thread is joined), then withdraw its exposure (its
    /// monitoring thread publishes the events still waiting, the instance's `dead`
    /// among them, and ends).
    fn release(self) {
        #[cfg(test)]
        tests::held_release(&self.names[0]);
        if self.fate == Fate::OwnerLost {
            self.kill();
        }
        let Hosted {
            names,
            system,
            exposure,
            ..
        } = self;
        let report = system.shutdown();
        if !report.clean() {
            tracing::warn!(
                instance = %names[0],
                "a dead instance's system did not shut down cleanly: {report:?}"
            );
        }
        drop(exposure);
        tracing::debug!(instance = %names[0], "released: its names are free again");
    }
}

/// Hand what `hosted` holds of dead instances to `reaper`, as many as it has room
/// for (the others wait for the next call).
fn reap(hosted: &mut Vec<Hosted>, reaper: &Reaper) {
    let mut index = 0;
    while index < hosted.len() {
        if hosted[index].dead() && reaper.has_room() {
            reaper.hand_over(hosted.swap_remove(index));
        } else {
            index += 1;
        }
    }
}

/// What the reaper releases and has not released yet: the names it takes and the
/// queue memory it holds (as taken as a hosted instance's).
#[derive(Default)]
struct Releasing {
    names: HashSet<String>,
    queue_bytes: usize,
}

/// The agent's reaper: a thread of its own releases the dead instances the agent
/// hands it ([`Hosted::release`]), so that a system slow to shut down (a stuck
/// bridge, up to `coolbot::SHUTDOWN_TIMEOUT`) holds no request up. An instance's
/// names stay taken until its exposure is withdrawn. Dropping it releases what it
/// was handed and joins its thread.
struct Reaper {
    sender: Option<crossbeam_channel::Sender<Hosted>>,
    releasing: Arc<Mutex<Releasing>>,
    thread: Option<JoinHandle<()>>,
}

impl Reaper {
    fn start(node: &str) -> Result<Reaper, Error> {
        let (sender, received) = crossbeam_channel::bounded::<Hosted>(REAPER_QUEUE);
        let releasing = Arc::new(Mutex::new(Releasing::default()));
        let freed = Arc::clone(&releasing);
        let thread = std::thread::Builder::new()
            .name(format!("cool-net:{node}:reap"))
            .spawn(move || {
                for built in received {
                    release(built, &freed);
                }
            })
            .map_err(Error::spawn("agent's reaper"))?;
        Ok(Reaper {
            sender: Some(sender),
            releasing,
            thread: Some(thread),
        })
    }

    /// Whether it takes one more dead instance now.
    fn has_room(&self) -> bool {
        self.sender.as_ref().is_some_and(|sender| !sender.is_full())
    }

    /// Release `built` on the reaper's thread; its names and memory count as
    /// releasing until it is released. Waits for room if there is none (the agent's
    /// thread hands over only after [`Reaper::has_room`], but at its end).
    fn hand_over(&self, built: Hosted) {
        let (names, queue_bytes) = (built.names.clone(), built.queue_bytes);
        {
            let mut releasing = lock(&self.releasing);
            releasing.names.extend(names);
            releasing.queue_bytes = releasing.queue_bytes.saturating_add(queue_bytes);
        }
        let sent = match &self.sender {
            Some(sender) => sender.send(built).map_err(|unsent| unsent.0),
            None => Err(built),
        };
        if let Err(built) = sent {
            // The reaper's thread has ended (a panic): released here.
            release(built, &self.releasing);
        }
    }

    /// Whether an instance it still releases takes `name`.
    fn holds(&self, name: &str) -> bool {
        lock(&self.releasing).names.contains(name)
    }

    /// The queue memory of the instances it still releases, in bytes.
    fn queue_bytes(&self) -> usize {
        lock(&self.releasing).queue_bytes
    }
}

/// Release `built`, then free its names and memory in `releasing`. A panic while
/// releasing it is caught and logged: what it held is dropped by then (its system,
/// its exposure withdrawn), so its names are freed all the same, and the reaper goes
/// on (else its names, and those of every instance waiting for it, would stay taken
/// and their memory held).
fn release(built: Hosted, releasing: &Mutex<Releasing>) {
    let (names, queue_bytes) = (built.names.clone(), built.queue_bytes);
    if let Err(payload) = std::panic::catch_unwind(AssertUnwindSafe(|| built.release())) {
        tracing::error!(
            instance = %names[0],
            "the release of a dead instance panicked: {}; its names are free again",
            excerpt(&coolbot::panic_message(payload.as_ref()), REASON_CHARS)
        );
    }
    let mut releasing = lock(releasing);
    for name in &names {
        releasing.names.remove(name);
    }
    releasing.queue_bytes = releasing.queue_bytes.saturating_sub(queue_bytes);
}

impl Drop for Reaper {
    fn drop(&mut self) {
        drop(self.sender.take());
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// Node `name` is gone: tell the agent's thread through `gone`, or, with
/// [`GONE_QUEUE`] waiting, drop it, count it in `status`, log it and have the thread
/// ask which owners live (`resync`).
fn node_gone(
    name: &str,
    gone: &crossbeam_channel::Sender<String>,
    status: &Mutex<AgentStatus>,
    resync: &AtomicBool,
) {
    if gone.try_send(name.to_owned()).is_ok() {
        return;
    }
    let dropped = {
        let mut status = lock(status);
        status.losses_dropped += 1;
        status.losses_dropped
    };
    resync.store(true, Ordering::Release);
    coolbot::limited!("agent-losses", |held| tracing::warn!(
        dropped,
        "the loss of node `{}` was dropped ({GONE_QUEUE} waited for the agent): it asks \
         which owners still live instead{held}",
        excerpt(name, EXCERPT_CHARS)
    ));
}

/// Have the reaper send to `dead` what was built for the owners `lost` says are lost
/// (marked here, handed over by the next [`reap`]: the agent's thread waits for no
/// instance). The requests of those owners that wait in `asking` back, with the
/// reason to refuse them: they build nothing (nothing would send their instances to
/// `dead`); the owner's next request, from a node of the same name started again,
/// is asked for afresh.
#[must_use]
fn owner_lost(
    hosted: &mut [Hosted],
    asking: &mut Asking,
    lost: impl Fn(&str) -> bool,
) -> Vec<(zenoh::query::Query, String)> {
    let gone: Vec<String> = asking
        .owners
        .keys()
        .filter(|owner| lost(owner))
        .cloned()
        .collect();
    let mut refused = Vec::new();
    for owner in gone {
        if let Some(lookup) = asking.owners.remove(&owner) {
            let reason = lost_reason(&owner);
            refused.extend(
                lookup
                    .queries
                    .into_iter()
                    .map(|query| (query, reason.clone())),
            );
        }
    }
    let mut count = 0;
    let mut name = String::new();
    // What is `dead` already (an owner that stops cleanly sends its instances there
    // before it leaves) is released as any dead instance is: the owner left, and
    // nothing of its is lost here.
    for built in hosted.iter_mut() {
        if built.fate == Fate::Serving
            && !built.dead()
            && let Some(owner) = &built.owner
            && lost(owner)
        {
            built.fate = Fate::OwnerLost;
            count += 1;
            name.clone_from(owner);
        }
    }
    if count > 0 {
        tracing::info!(
            owner = %name,
            "the node that asked for {count} instance(s) here is lost: they go to dead"
        );
    }
    refused
}

/// Why a request of `owner`, a node lost, builds nothing.
fn lost_reason(owner: &str) -> String {
    format!(
        "the owner `{}` is lost (its liveliness token is gone): nothing is built for it",
        excerpt(owner, EXCERPT_CHARS)
    )
}

/// After a node's loss was dropped: send to `dead` what was built for owners whose
/// tokens the watcher no longer holds in `alive` (every loss goes from it, dropped
/// or not).
fn owners_lost(hosted: &mut [Hosted], alive: &Mutex<HashSet<String>>) {
    // Taken under the lock, marked without it: the watcher's callback, on Zenoh's
    // thread, is not to wait for the agent's.
    let lost: HashSet<String> = {
        let alive = lock(alive);
        hosted
            .iter()
            .filter_map(|built| built.owner.as_deref())
            .filter(|owner| !alive.contains(*owner))
            .map(str::to_owned)
            .collect()
    };
    // (The requests waiting for the network's answer are asked for again: none is
    // in this empty `Asking`.)
    let none = owner_lost(hosted, &mut Asking::default(), |owner| lost.contains(owner));
    debug_assert!(none.is_empty());
}

/// Check that node `owner` lives: the watcher holds its token in `alive`, or, if it
/// has not heard of it (its token not yet come, or gone), the network said so
/// (`known`: an owner and whether its token was there, asked for off the agent's
/// thread; else [`Refusal::Unheard`], to ask). Its loss may have been handled while
/// its request waited: nothing would send that request's instance to `dead`.
fn owner_lives(
    (alive, known): (&Mutex<HashSet<String>>, Known<'_>),
    owner: &str,
) -> Result<(), Refusal> {
    if lock(alive).contains(owner) {
        return Ok(());
    }
    match known {
        Some((asked, true)) if asked == owner => Ok(()),
        Some((asked, false)) if asked == owner => Err(Refusal::Reason(lost_reason(owner))),
        _ => Err(Refusal::Unheard(owner.to_owned())),
    }
}

/// Check that `request`, from node `requester`, builds in the requester's own
/// namespace on node `here`: its instance's name ([`keys::namespace`]), its wires'
/// keys under `coolbot-link/` (a placement's: [`keys::link_namespace`]) and its owner.
/// So a node that may instantiate cannot have this node publish on, or read from,
/// another node's placement keys, nor take another node's instance names.
fn check_namespace(request: &Instantiate, here: &str, requester: &str) -> Result<(), String> {
    let own = keys::namespace(requester);
    if !request.name.starts_with(&own) || request.name.len() == own.len() {
        return Err(format!(
            "the instance name `{}` is not in the namespace of node `{}`, which asks: \
             its names begin with `{own}`",
            excerpt(&request.name, EXCERPT_CHARS),
            excerpt(requester, EXCERPT_CHARS)
        ));
    }
    let links = keys::link_namespace(here, requester);
    for (index, wire) in request.wires.iter().enumerate() {
        let (Wire::Input { key, .. } | Wire::Output { key, .. }) = wire;
        if key.starts_with(keys::LINKS) && !key.starts_with(&links) {
            return Err(format!(
                "the key of wire {index}, `{}`, is a placement's key outside the namespace \
                 of node `{}`, which asks: its placement keys here begin with `{links}`",
                excerpt(key, EXCERPT_CHARS),
                excerpt(requester, EXCERPT_CHARS)
            ));
        }
    }
    if let Some(owner) = &request.owner
        && owner != requester
    {
        return Err(format!(
            "the owner `{}` is not node `{}`, which asks: an instance shares the life of \
             the node that asked for it",
            excerpt(owner, EXCERPT_CHARS),
            excerpt(requester, EXCERPT_CHARS)
        ));
    }
    Ok(())
}

/// Whether a request's owner lives ([`owner_lives`]): an error says why not.
type Lives<'a> = dyn Fn(&str) -> Result<(), Refusal> + 'a;

/// One instantiation request: build, bridge, run, expose, in a system of its own,
/// left in `building` while it is built (for the reaper, if the request fails or
/// panics). `taken`: the names hosted instances hold; `held`: the queue memory they
/// hold, in bytes; `lives`: whether a request's owner lives ([`owner_lives`]).
fn serve(
    node: &Node,
    registry: &Registry,
    query: &zenoh::query::Query,
    (taken, held): (&dyn Fn(&str) -> bool, usize),
    lives: &Lives<'_>,
    building: &mut Option<Building>,
) -> Result<Hosted, Refusal> {
    let payload = query
        .payload()
        .ok_or("no request: the query carries no payload")?;
    limits::REQUEST
        .check(|| "the request".to_owned(), payload.len())
        .map_err(text)?;
    let request: Instantiate = serde_json::from_slice(&payload.to_bytes()).map_err(|error| {
        format!(
            "malformed request: {}",
            excerpt(&error.to_string(), REASON_CHARS)
        )
    })?;
    check_request(&request)?;
    // Access rules grant instantiation by the key's type and to each node under its
    // own name (the key's last chunk): the request must be for that type, and build
    // in that node's namespace.
    let Some((asked, requester)) = keys::parse_agent(query.key_expr().as_str()) else {
        return Err(Refusal::Reason(format!(
            "`{}` is not an agent's key",
            excerpt(query.key_expr().as_str(), EXCERPT_CHARS)
        )));
    };
    if asked != request.type_name {
        return Err(Refusal::Reason(format!(
            "the request builds a `{}` but came on the key of type `{}`",
            request.type_name,
            excerpt(asked, EXCERPT_CHARS)
        )));
    }
    keys::check_name(requester).map_err(text)?;
    check_namespace(&request, node.name(), requester)?;
    let factory = registry.types.get(&request.type_name).ok_or_else(|| {
        format!(
            "no component type `{}` here (registered: {:?})",
            request.type_name, registry
        )
    })?;
    keys::check_name(&request.name).map_err(text)?;
    let name = request.name.clone();
    let mut names = vec![name.clone()];
    for wire in &request.wires {
        let (Wire::Input { port, .. } | Wire::Output { port, .. }) = wire;
        names.push(format!("{name}-{port}"));
    }
    if request.name.contains('.') || names.iter().any(|name| taken(name)) {
        return Err(Refusal::Reason(format!(
            "`{}` is not a free instance name here",
            request.name
        )));
    }
    let mut component = (factory.make)(&request.name).map_err(text)?;
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
    let mut total = 0usize;
    for (index, wire) in request.wires.iter().enumerate() {
        let (port, output) = match wire {
            Wire::Input { port, .. } => (port, false),
            Wire::Output { port, .. } => (port, true),
        };
        let declared = if output {
            spec.output_index(port).is_some()
        } else {
            spec.input_index(port).is_some()
        };
        if !declared {
            return Err(Refusal::Reason(format!(
                "`{}` has no {} port `{port}`",
                spec.type_name,
                if output { "output" } else { "input" }
            )));
        }
        let Some(bridge) = factory.ports.get(port) else {
            return Err(Refusal::Reason(format!(
                "port `{port}` of `{}` was not registered as bridgeable",
                spec.type_name
            )));
        };
        // What the outlet's queue holds from the start.
        let held = match wire {
            Wire::Output {
                to: RemoteInput::Fifo { capacity },
                ..
            } => *capacity,
            Wire::Output {
                to: RemoteInput::Ufifo { initial, .. },
                ..
            } => *initial,
            Wire::Input { .. } | Wire::Output { .. } => 0,
        };
        let size = bridge.packet_size().max(1);
        let bytes = held.saturating_mul(size);
        limits::QUEUE_BYTES
            .check(
                || format!("the queue of wire {index} ({held} packets of {size} bytes)"),
                bytes,
            )
            .map_err(text)?;
        total = total.saturating_add(bytes);
    }
    limits::REQUEST_QUEUE_BYTES
        .check(
            || "the queues of every wire of the request, together".to_owned(),
            total,
        )
        .map_err(text)?;
    limits::HOSTED_QUEUE_BYTES
        .check(
            || {
                format!(
                    "the queues of every instance this agent runs, with this request's \
                     ({held} bytes held, {total} asked for)"
                )
            },
            held.saturating_add(total),
        )
        .map_err(text)?;
    // A request served after its owner's loss was handled builds nothing for it.
    if let Some(owner) = &request.owner {
        lives(owner)?;
    }
    // Handed to the reaper (shut down, its names free) if anything below fails or
    // panics.
    let system = &mut building
        .insert(Building {
            names: names.clone(),
            queue_bytes: total,
            system: System::new(),
        })
        .system;
    system.start().map_err(text)?;
    let mut built = vec![system.add(component).map_err(text)?];
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
                    .map_err(text)?;
                built.push(system.add(inlet).map_err(text)?);
                system
                    .connect(&format!("{bridge}.output"), &format!("{name}.{port}"))
                    .map_err(text)?;
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
                    .map_err(text)?;
                built.push(system.add(outlet).map_err(text)?);
                system
                    .connect(&format!("{name}.{port}"), &format!("{bridge}.input"))
                    .map_err(text)?;
            }
        }
    }
    // The overrides, through the instance's control port, before it runs.
    started(&built[0])?;
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
        built[0].command(command).map_err(text)?;
    }
    // Bridges first, so that the instance's first packets find them running.
    for handle in built.iter().skip(1).rev() {
        run(handle)?;
    }
    if request.run {
        run(&built[0])?;
    }
    let exposure = node.exposure(&built).map_err(text)?;
    tracing::info!(
        instance = %name,
        type_name = %request.type_name,
        requester = %requester,
        "built for another node{}",
        if request.run { "" } else { " (left ready)" }
    );
    let Some(Building { system, .. }) = building.take() else {
        unreachable!("a request is built in its system");
    };
    Ok(Hosted {
        names,
        queue_bytes: total,
        owner: request.owner.clone(),
        handles: built,
        system,
        exposure: Some(exposure),
        fate: Fate::Serving,
    })
}

/// Ask the agent of node `on` to build `request`, waiting at most `timeout`. An agent
/// that has too many requests waiting answers [`Error::Busy`]; no answer within
/// `timeout` is [`Error::NoAgent`]. The request is `node`'s: the agent builds it in
/// `node`'s namespace only (its instance's name begins with `<node>-`, its keys
/// under `coolbot-link/` with `coolbot-link/<on>/<node>-`, its owner is `node` if any).
pub fn instantiate(
    node: &Node,
    on: &str,
    request: &Instantiate,
    timeout: Duration,
) -> Result<(), Error> {
    ask(node, on, node.name(), request, timeout)
}

/// [`instantiate`] as node `requester` (what the access rules let only `requester`
/// send; a test's forgery on plaintext).
fn ask(
    node: &Node,
    on: &str,
    requester: &str,
    request: &Instantiate,
    timeout: Duration,
) -> Result<(), Error> {
    keys::check_name(&request.type_name)?;
    let json = serde_json::to_vec(request).map_err(|source| Error::Json {
        what: "the instantiation request".to_owned(),
        decoding: false,
        source,
    })?;
    let asked = Instant::now();
    let replies = node
        .session()
        .get(keys::agent(on, &request.type_name, requester))
        .payload(json)
        .timeout(timeout)
        .wait()
        .map_err(Error::zenoh("send the instantiation request"))?;
    let Ok(reply) = replies.recv() else {
        return Err(Error::NoAgent {
            node: on.to_owned(),
            type_name: request.type_name.clone(),
            waited: asked.elapsed(),
            timeout,
        });
    };
    let answer = reply
        .result()
        .map_err(|error| Error::ErrorReply {
            node: on.to_owned(),
            reason: excerpt(
                &error.payload().try_to_string().unwrap_or_default(),
                REASON_CHARS,
            )
            .into_owned(),
        })
        .and_then(|sample| {
            let payload = sample.payload();
            limits::REPLY
                .check(|| "the agent's answer".to_owned(), payload.len())
                .map_err(|source| Error::TooLarge {
                    node: on.to_owned(),
                    source,
                })?;
            serde_json::from_slice::<ControlReply>(&payload.to_bytes()).map_err(|source| {
                Error::Json {
                    what: format!("node `{on}`'s answer"),
                    decoding: true,
                    source,
                }
            })
        })?;
    match answer {
        ControlReply::Accepted => Ok(()),
        // The agent's own words for a full queue ([`admit`]): the one refusal that
        // may be asked again.
        ControlReply::Rejected { reason } if reason.starts_with(BUSY) => Err(Error::Busy {
            node: on.to_owned(),
            reason,
        }),
        ControlReply::Rejected { reason } => Err(Error::Refused {
            node: on.to_owned(),
            reason,
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeSet;

    /// The reason of the refusal `replies` bring, if any.
    fn refusal(
        replies: zenoh::handlers::FifoChannelHandler<zenoh::query::Reply>,
    ) -> Option<String> {
        let reply = replies.recv().ok()?;
        let sample = reply.result().ok()?;
        match serde_json::from_slice(&sample.payload().to_bytes()).ok()? {
            ControlReply::Rejected { reason } => Some(reason),
            ControlReply::Accepted => None,
        }
    }

    #[test]
    fn a_request_is_answered_truthfully_when_too_many_wait_and_when_the_agent_has_stopped() {
        let session = zenoh::open(crate::peer_config(&[], &[], false).unwrap())
            .wait()
            .unwrap();
        let status = Arc::new(Mutex::new(AgentStatus::default()));
        let (requests, received) = crossbeam_channel::bounded(AGENT_QUEUE);
        let admitting = Arc::clone(&status);
        let replies = crate::reply::Replies::start("test", crate::reply::REPLY_QUEUE).unwrap();
        let replier = replies.replier().clone();
        let _queryable = session
            .declare_queryable("test/agent/admit")
            .callback(move |query| admit(&admitting, &requests, &replier, query))
            .wait()
            .unwrap();
        let ask = || {
            session
                .get("test/agent/admit")
                .payload("{}")
                .timeout(Duration::from_secs(30))
                .wait()
                .unwrap()
        };
        // As many as may wait, unserved.
        let waiting: Vec<_> = (0..AGENT_QUEUE).map(|_| ask()).collect();
        let deadline = Instant::now() + Duration::from_secs(30);
        while received.len() < AGENT_QUEUE {
            assert!(Instant::now() < deadline, "the requests wait");
            std::thread::sleep(Duration::from_millis(5));
        }
        assert_eq!(
            refusal(ask()).as_deref(),
            Some("the agent has too many requests waiting (16); ask again later")
        );
        // The thread ends: those waiting are answered with why, and every later one.
        drop(Inbox {
            received,
            status: Arc::clone(&status),
            ending: Some("a test ended it".to_owned()),
            asking: Asking::default(),
        });
        for replies in waiting {
            assert_eq!(
                refusal(replies).as_deref(),
                Some("the agent has stopped: a test ended it")
            );
        }
        assert_eq!(
            refusal(ask()).as_deref(),
            Some("the agent has stopped: a test ended it")
        );
        let status = lock(&status).clone();
        assert_eq!(status.stopped.as_deref(), Some("a test ended it"));
        assert_eq!(status.refused, AGENT_QUEUE as u64 + 2);

        // A thread that ends with a panic says so.
        let status = Arc::new(Mutex::new(AgentStatus::default()));
        let (_requests, received) = crossbeam_channel::bounded(1);
        let inbox = Inbox {
            received,
            status: Arc::clone(&status),
            ending: None,
            asking: Asking::default(),
        };
        let ended = std::thread::spawn(move || {
            let _inbox = inbox;
            panic!("a bug outside any request");
        })
        .join();
        assert!(ended.is_err());
        assert_eq!(
            lock(&status).stopped.as_deref(),
            Some("its thread ended with a panic (the node's log has it)")
        );
    }

    use crate::testing::{
        Idle, asking, built, eventually, free_port, idle, idle_registry, idle_spec, set_state,
    };

    /// A request for a `type_name` named `name`: no wires, no overrides, run, no
    /// owner (the rest given with `..request(...)`).
    fn request(type_name: &str, name: &str) -> Instantiate {
        Instantiate {
            type_name: type_name.to_owned(),
            name: name.to_owned(),
            wires: Vec::new(),
            configuration: None,
            variables: Vec::new(),
            timing: None,
            run: true,
            owner: None,
        }
    }

    /// `name` in the namespace of node `node`.
    fn own(node: &str, name: &str) -> String {
        format!("{}{name}", keys::namespace(node))
    }

    /// The threads of this process whose name is `name`.
    fn threads_named(name: &str) -> usize {
        std::fs::read_dir("/proc/self/task")
            .unwrap()
            .flatten()
            .filter(|task| {
                std::fs::read_to_string(task.path().join("comm"))
                    .is_ok_and(|comm| comm.trim_end() == name)
            })
            .count()
    }

    #[test]
    fn instances_sent_to_dead_leave_nothing_of_their_exposure_behind() {
        let node = crate::testing::node("leak", None, None);
        let agent =
            Agent::start_with_cap(Arc::clone(&node), idle_registry(idle_spec()), 4).unwrap();
        assert_eq!(
            threads_named("cool-net:leak:m"),
            0,
            "no node of this name but this test's"
        );
        const ROUNDS: usize = 12;
        for round in 0..ROUNDS {
            let name = own("leak", &format!("idle-{round}"));
            instantiate(
                &node,
                "leak",
                &request("Idle", &name),
                Duration::from_secs(10),
            )
            .unwrap();
            // What any peer may send to a component of the node: `dead`.
            set_state(&node, "leak", &name, Controllable::Dead);
        }
        // The cap (4 at once) never refused: every instance built went to dead.
        assert_eq!(agent.status().built, ROUNDS as u64);
        // Each dead instance is released: its monitoring thread, queryables and
        // publisher go, and its name is free again.
        assert!(
            eventually(|| threads_named("cool-net:leak:m") == 0),
            "{} monitoring threads left by {ROUNDS} dead instances",
            threads_named("cool-net:leak:m")
        );
        instantiate(
            &node,
            "leak",
            &request("Idle", &own("leak", "idle-0")),
            Duration::from_secs(10),
        )
        .expect("the name of a released instance is free again");
        // (A thread takes its name once it runs.)
        assert!(eventually(|| threads_named("cool-net:leak:m") == 1));
        assert_eq!(agent.status().refused, 0);
    }

    #[test]
    fn refused_requests_do_not_take_the_names_a_proxy_builds_its_next_generations_under() {
        let node = crate::testing::node("claim", None, None);
        let agent =
            Agent::start_with_cap(Arc::clone(&node), idle_registry(idle_spec()), 1).unwrap();
        // A proxy's root is observable (its first generation is exposed on the node);
        // its next generations are `<root>-2`, `<root>-3`, ... Asked for with an
        // override the type refuses, each request is refused after the component was
        // added: its name is free again.
        let root = format!("{}robot-wanderer-0badf00d", keys::namespace("claim"));
        for generation in 2..=20 {
            let error = instantiate(
                &node,
                "claim",
                &Instantiate {
                    variables: vec![("nope".to_owned(), Value::Int(1))],
                    ..request("Idle", &format!("{root}-{generation}"))
                },
                Duration::from_secs(10),
            )
            .unwrap_err();
            assert!(matches!(error, Error::Refused { .. }), "{error}");
        }
        assert_eq!(agent.status().refused, 19);
        // Another node may not ask for them at all: they are not in its namespace.
        let error = ask(
            &node,
            "claim",
            "robot",
            &request("Idle", &format!("{root}-3")),
            Duration::from_secs(10),
        )
        .unwrap_err();
        assert!(
            error
                .to_string()
                .contains("is not in the namespace of node `robot`"),
            "{error}"
        );
        // The proxy's next generation, after its instance was lost (once the reaper
        // has shut the refused request's system down):
        built(&node, "claim", &request("Idle", &format!("{root}-2")));
    }

    #[test]
    fn an_agent_does_not_publish_on_the_keys_of_another_nodes_placement() {
        let node = crate::testing::node("depu", None, None);
        let spec = crate::bridge::leak_spec(
            "Src",
            "Has one data output.",
            Vec::new(),
            Some(coolbot::OutputSpec {
                name: "out",
                kind: OutputKind::Data,
                packet: std::any::type_name::<u64>(),
                pull: false,
            }),
            false,
        );
        let mut registry = Registry::new();
        registry
            .register("Src", move |name| {
                let out = coolbot::port::DataOut::<u64>::new();
                Component::new(name, Box::new(Idle(spec)), PortSet::new().output(&out))
            })
            .port::<u64>("out");
        let agent = Agent::start(Arc::clone(&node), registry).unwrap();
        // Node `robot2` lives (its token), as the owner of what it asks for must.
        let _robot2 = node
            .session()
            .liveliness()
            .declare_token(keys::node_token("robot2"))
            .wait()
            .unwrap();
        let request = |name: &str, key: &str| Instantiate {
            wires: vec![Wire::Output {
                port: "out".into(),
                key: key.into(),
                to: RemoteInput::Ufifo {
                    initial: 64,
                    max: Some(65_536),
                },
            }],
            owner: Some("robot2".into()),
            ..request("Src", name)
        };
        // Node `robot1` placed an instance here: its proxy hears the instance's
        // output on this key (`place::Placer`), from this node, whose `publish` rule
        // covers `coolbot-link/depu/**`.
        let victim = format!(
            "coolbot-link/depu/{}robot-wanderer-5f54b428/out/out",
            keys::namespace("robot1")
        );
        // Another node that may instantiate here (any type) asks, under its own name
        // (the access rules let it ask under no other), for an instance whose output
        // is published on that key.
        let asked = ask(
            &node,
            "depu",
            "robot2",
            &request(&format!("{}anything-1", keys::namespace("robot2")), &victim),
            Duration::from_secs(10),
        );
        let Err(Error::Refused { reason, .. }) = asked else {
            panic!("the agent built an outlet on another placement's key {victim}: {asked:?}");
        };
        assert!(
            reason.contains("outside the namespace of node `robot2`"),
            "{reason}"
        );
        // Nor under its own name, as another node's (the owner is the requester).
        let own = |rest: &str| own("robot2", rest);
        let mut forged = request(
            &own("anything-2"),
            &format!("coolbot-link/depu/{}", own("x/out/out")),
        );
        forged.owner = Some("robot1".into());
        let asked = ask(&node, "depu", "robot2", &forged, Duration::from_secs(10));
        assert!(
            matches!(&asked, Err(Error::Refused { reason, .. }) if reason.contains("the owner `robot1`")),
            "{asked:?}"
        );
        // Its own placement's keys, it may.
        ask(
            &node,
            "depu",
            "robot2",
            &request(
                &own("anything-3"),
                &format!("coolbot-link/depu/{}", own("x/out/out")),
            ),
            Duration::from_secs(10),
        )
        .expect("a placement in the requester's own namespace");
        assert_eq!(agent.status().refused, 2);
    }

    #[test]
    fn losses_beyond_the_queue_are_dropped_counted_and_make_the_agent_ask_who_lives() {
        let (gone, lost) = crossbeam_channel::bounded(GONE_QUEUE);
        let status = Mutex::new(AgentStatus::default());
        let resync = AtomicBool::new(false);
        for n in 0..GONE_QUEUE {
            node_gone(&format!("n{n}"), &gone, &status, &resync);
        }
        assert_eq!(lock(&status).losses_dropped, 0);
        assert!(!resync.load(Ordering::Acquire));
        node_gone("one-more", &gone, &status, &resync);
        node_gone("two-more", &gone, &status, &resync);
        assert_eq!(lock(&status).losses_dropped, 2);
        assert!(resync.load(Ordering::Acquire));
        assert_eq!(lost.len(), GONE_QUEUE);
    }

    /// A packet of 128 KiB.
    type Chunk = [[[u64; 32]; 32]; 16];

    /// A packet of 1 KiB.
    type Kib = [[u64; 32]; 4];

    /// A registry of one type, `Big`, with one data output `out` of packets `T`.
    fn big_registry<T: Packet + Serialize + DeserializeOwned>() -> Registry {
        let spec = crate::bridge::leak_spec(
            "Big",
            "Has one data output of big packets.",
            Vec::new(),
            Some(coolbot::OutputSpec {
                name: "out",
                kind: OutputKind::Data,
                packet: std::any::type_name::<T>(),
                pull: false,
            }),
            false,
        );
        let mut registry = Registry::new();
        registry
            .register("Big", move |name| {
                let out = coolbot::port::DataOut::<T>::new();
                Component::new(name, Box::new(Idle(spec)), PortSet::new().output(&out))
            })
            .port::<T>("out");
        registry
    }

    #[test]
    fn a_request_may_not_ask_for_more_queue_memory_than_its_limit_in_all() {
        let node = crate::testing::node("qmem", None, None);
        let _agent = Agent::start(Arc::clone(&node), big_registry::<Chunk>()).unwrap();
        // Each wire's queue within `QUEUE_BYTES` (64 MiB: 512 packets of 128 KiB),
        // three of them over `REQUEST_QUEUE_BYTES` together.
        let wire = |n: usize| Wire::Output {
            port: "out".into(),
            key: format!("qmem/{n}"),
            to: RemoteInput::Fifo { capacity: 512 },
        };
        let request = Instantiate {
            wires: (0..3).map(wire).collect(),
            ..request("Big", &own("qmem", "big"))
        };
        let refused = instantiate(&node, "qmem", &request, Duration::from_secs(10));
        let Err(Error::Refused { reason, .. }) = refused else {
            panic!("{refused:?}");
        };
        assert!(
            reason.contains("the queues of every wire of the request, together: 201326592 bytes, over the limit REQUEST_QUEUE_BYTES = 134217728 bytes"),
            "{reason}"
        );
    }

    #[test]
    fn an_agent_may_not_hold_more_queue_memory_than_its_limit_in_all() {
        let node = crate::testing::node("amem", None, None);
        let _agent = Agent::start(Arc::clone(&node), big_registry::<Kib>()).unwrap();
        // Each request within `REQUEST_QUEUE_BYTES` (64 MiB: 65536 packets of 1 KiB),
        // eight of them `HOSTED_QUEUE_BYTES` together.
        let big = |n: usize, packets: usize| Instantiate {
            wires: vec![Wire::Output {
                port: "out".into(),
                key: format!("amem/{n}"),
                to: RemoteInput::Fifo { capacity: packets },
            }],
            ..request("Big", &own("amem", &format!("big-{n}")))
        };
        let timeout = Duration::from_secs(10);
        for n in 0..8 {
            instantiate(&node, "amem", &big(n, 65_536), timeout).unwrap();
        }
        let refused = instantiate(&node, "amem", &big(8, 1), timeout);
        let Err(Error::Refused { reason, .. }) = refused else {
            panic!("{refused:?}");
        };
        assert!(
            reason.contains(
                "the queues of every instance this agent runs, with this request's \
                 (536870912 bytes held, 1024 asked for): 536871936 bytes, over the limit \
                 HOSTED_QUEUE_BYTES = 536870912 bytes"
            ),
            "{reason}"
        );
        // An instance gone, its memory is free again.
        set_state(&node, "amem", &own("amem", "big-0"), Controllable::Dead);
        built(&node, "amem", &big(8, 1));
    }

    /// What the test holds of an agent's work on an instance ([`hold`]).
    struct Held {
        /// Told when the release begins.
        begun: crossbeam_channel::Receiver<()>,
        /// Dropped to let the release go on.
        _go: crossbeam_channel::Sender<()>,
    }

    /// The points held (`<point> <instance or owner>`): what tells that the agent
    /// reached them and what lets it go on.
    type Holds = BTreeMap<
        String,
        (
            crossbeam_channel::Sender<()>,
            crossbeam_channel::Receiver<()>,
        ),
    >;

    static HOLDS: Mutex<Holds> = Mutex::new(BTreeMap::new());

    /// The instances whose release panics ([`held_release`]).
    static PANICKING: Mutex<BTreeSet<String>> = Mutex::new(BTreeSet::new());

    /// Hold the agent at `point` for `name` until the returned [`Held`] is dropped
    /// (or a deadline passes): `release` (an instance's, or what a refused request
    /// built: [`Hosted::release`]), `kill` (an instance sent to `dead` for its lost
    /// owner: [`Hosted::kill`]), `lookup` (the network's answer about an owner:
    /// [`Finding`]).
    fn hold(point: &str, name: &str) -> Held {
        let (begins, begun) = crossbeam_channel::bounded(1);
        let (go, wait) = crossbeam_channel::bounded(0);
        lock(&HOLDS).insert(format!("{point} {name}"), (begins, wait));
        Held { begun, _go: go }
    }

    /// Whether a test holds the agent at `point` for `name` ([`hold`]).
    pub(super) fn is_held(point: &str, name: &str) -> bool {
        lock(&HOLDS).contains_key(&format!("{point} {name}"))
    }

    /// The agent reaches `point` for `name`: a test holding it there ([`hold`])
    /// holds it here.
    pub(super) fn held(point: &str, name: &str) {
        let held = lock(&HOLDS).remove(&format!("{point} {name}"));
        if let Some((begins, wait)) = held {
            let _ = begins.send(());
            let _ = wait.recv_timeout(Duration::from_secs(60));
        }
    }

    /// The release of instance `name` begins ([`Hosted::release`]): it panics if the
    /// test asks, or is held ([`hold`]).
    pub(super) fn held_release(name: &str) {
        assert!(
            !lock(&PANICKING).contains(name),
            "the release of `{name}` panics, as the test asks"
        );
        held("release", name);
    }

    /// An instance whose release is slow (its system slow to shut down) holds no
    /// request up, and its names stay taken until it is released.
    #[test]
    fn a_slow_release_holds_no_request_up_and_keeps_its_names_taken() {
        let node = crate::testing::node("slow", None, None);
        let agent = Agent::start(Arc::clone(&node), idle_registry(idle_spec())).unwrap();
        let timeout = Duration::from_secs(10);
        let name = own("slow", "held");
        let held = hold("release", &name);
        instantiate(&node, "slow", &request("Idle", &name), timeout).unwrap();
        set_state(&node, "slow", &name, Controllable::Dead);
        // The agent finds it dead (at the latest when it serves the next request).
        instantiate(&node, "slow", &request("Idle", &own("slow", "a")), timeout).unwrap();
        held.begun
            .recv_timeout(Duration::from_secs(60))
            .expect("the release begins");
        // While its release is held, requests are served.
        instantiate(&node, "slow", &request("Idle", &own("slow", "b")), timeout)
            .expect("a request served while a release is under way");
        let taken = instantiate(&node, "slow", &request("Idle", &name), timeout);
        assert!(
            matches!(&taken, Err(Error::Refused { reason, .. }) if reason.contains("is not a free instance name")),
            "{taken:?}"
        );
        drop(held);
        built(&node, "slow", &request("Idle", &name));
        assert_eq!(agent.status().built, 4);
    }

    /// A release that panics frees the instance's names all the same (its exposure
    /// is withdrawn as the panic unwinds), and the reaper goes on releasing.
    #[test]
    fn a_release_that_panics_frees_the_names_and_the_reaper_goes_on() {
        let node = crate::testing::node("rp", None, None);
        let agent = Agent::start(Arc::clone(&node), idle_registry(idle_spec())).unwrap();
        let timeout = Duration::from_secs(10);
        let name = own("rp", "boom");
        lock(&PANICKING).insert(name.clone());
        instantiate(&node, "rp", &request("Idle", &name), timeout).unwrap();
        set_state(&node, "rp", &name, Controllable::Dead);
        assert!(
            eventually(|| threads_named("cool-net:rp:m") == 0),
            "the exposure of the instance whose release panicked is withdrawn"
        );
        lock(&PANICKING).remove(&name);
        // (Else the name of an instance whose release panicked stays taken.)
        built(&node, "rp", &request("Idle", &name));
        assert_eq!(threads_named("cool-net:rp:rea"), 1, "the reaper has ended");
        // It releases the next.
        set_state(&node, "rp", &name, Controllable::Dead);
        built(&node, "rp", &request("Idle", &name));
        assert_eq!(agent.status().built, 3);
    }

    /// A registry of `Idle` and `Gate`, an `Idle` whose factory waits until the test
    /// opens the gate (or a deadline passes), holding the agent's thread: the
    /// registry, what tells that the factory waits, and what opens the gate (sent to,
    /// or dropped).
    fn gated_registry() -> (
        Registry,
        crossbeam_channel::Receiver<()>,
        crossbeam_channel::Sender<()>,
    ) {
        let spec = idle_spec();
        let mut registry = idle_registry(spec);
        let (waits, waiting) = crossbeam_channel::unbounded();
        let (open, opened) = crossbeam_channel::bounded::<()>(1);
        registry.register("Gate", move |name| {
            let _ = waits.send(());
            let _ = opened.recv_timeout(Duration::from_secs(60));
            idle(name, spec)
        });
        (registry, waiting, open)
    }

    /// Hold the agent of `node` in a `Gate`'s factory, asked by `node` on another
    /// thread: its handle, to join once the gate is open.
    fn hold_agent(
        node: &Arc<Node>,
        waiting: &crossbeam_channel::Receiver<()>,
    ) -> JoinHandle<Result<(), Error>> {
        let asking = Arc::clone(node);
        let gate = std::thread::spawn(move || {
            let on = asking.name().to_owned();
            let gate = request("Gate", &own(&on, "gate"));
            instantiate(&asking, &on, &gate, Duration::from_secs(60))
        });
        waiting
            .recv_timeout(Duration::from_secs(60))
            .expect("the agent builds the gate");
        gate
    }

    /// Until node `node` reaches the agent of node `on` (a refused request answered).
    fn meet(node: &Node, on: &str) {
        let nothing = request("Nothing", &own(node.name(), "nothing"));
        assert!(eventually(|| matches!(
            instantiate(node, on, &nothing, Duration::from_secs(10)),
            Err(Error::Refused { .. })
        )));
    }

    /// A request whose owner's loss the agent handled while it waited is refused:
    /// nothing would ever send its instance to dead.
    #[test]
    fn a_request_whose_owner_was_lost_while_it_waited_builds_nothing() {
        let port = free_port();
        let node = crate::testing::node("ol", Some(port), None);
        let (registry, waiting, open) = gated_registry();
        let agent = Agent::start(Arc::clone(&node), registry).unwrap();
        let owner = crate::testing::node("ol-x", None, Some(port));
        meet(&owner, "ol");
        let gate = hold_agent(&node, &waiting);
        // The owner asks, its request waits, then it is lost.
        let owned = Instantiate {
            owner: Some("ol-x".to_owned()),
            ..request("Idle", &own("ol-x", "idle"))
        };
        let replies = asking(&owner, "ol", "ol-x", &owned);
        assert!(eventually(|| agent.probe.requests.len() == 1));
        drop(replies);
        drop(owner);
        assert!(eventually(|| agent.probe.losses.len() == 1));
        let refused = agent.status().refused;
        open.send(()).unwrap();
        gate.join().unwrap().unwrap();
        assert!(eventually(|| agent.status().refused == refused + 1));
        assert_eq!(agent.status().built, 1, "the gate only");
        // (A thread takes its name once it runs.)
        assert!(
            eventually(|| threads_named("cool-net:ol:m") == 1),
            "the gate's exposure only: {}",
            threads_named("cool-net:ol:m")
        );
    }

    /// A request whose owner the agent has heard live is built without asking the
    /// network (a round trip on the agent's thread, as long as the slowest peer takes
    /// to answer, up to a second): a flood of owned requests costs no more than
    /// unowned ones. One whose owner it has not heard of is asked for.
    #[test]
    fn an_owner_heard_live_is_not_asked_for() {
        let port = free_port();
        let node = crate::testing::node("oh", Some(port), None);
        let agent = Agent::start(Arc::clone(&node), idle_registry(idle_spec())).unwrap();
        let owner = crate::testing::node("oh-x", None, Some(port));
        meet(&owner, "oh");
        let before = agent.status();
        for n in 0..3 {
            let owned = Instantiate {
                owner: Some("oh-x".to_owned()),
                ..request("Idle", &own("oh-x", &format!("idle-{n}")))
            };
            instantiate(&owner, "oh", &owned, Duration::from_secs(10)).unwrap();
        }
        let status = agent.status();
        assert_eq!(status.built, before.built + 3);
        assert_eq!(status.owners_asked, before.owners_asked, "{status:?}");
        // A token the agent has not heard of (a node that declares none): asked for,
        // and refused.
        let forged = Instantiate {
            owner: Some("oh-y".to_owned()),
            ..request("Idle", &own("oh-y", "idle"))
        };
        let refused = ask(&node, "oh", "oh-y", &forged, Duration::from_secs(10));
        assert!(
            matches!(&refused, Err(Error::Refused { reason, .. }) if reason.contains("is lost")),
            "{refused:?}"
        );
        assert_eq!(agent.status().owners_asked, before.owners_asked + 1);
    }

    /// A request whose owner the agent has not heard of (a peer that declares no
    /// token) waits off the agent's thread while the network is asked whether the
    /// owner lives, once for every request of that owner waiting: the other requests
    /// are served meanwhile.
    #[test]
    fn an_unheard_owner_is_asked_for_off_the_agents_thread() {
        let node = crate::testing::node("ua", None, None);
        let agent = Agent::start(Arc::clone(&node), idle_registry(idle_spec())).unwrap();
        let held = hold("lookup", "ua-y");
        let forged = |name: &str| Instantiate {
            owner: Some("ua-y".to_owned()),
            ..request("Idle", &own("ua-y", name))
        };
        let first = asking(&node, "ua", "ua-y", &forged("idle-1"));
        held.begun
            .recv_timeout(Duration::from_secs(60))
            .expect("the owner is asked for");
        let second = asking(&node, "ua", "ua-y", &forged("idle-2"));
        instantiate(
            &node,
            "ua",
            &request("Idle", &own("ua", "a")),
            Duration::from_secs(10),
        )
        .expect("a request served while an owner is asked for");
        assert_eq!(
            agent.status().owners_asked,
            1,
            "one lookup for the owner's requests"
        );
        drop(held);
        for replies in [first, second] {
            let reason = refusal(replies);
            assert!(
                reason.as_deref().is_some_and(|reason| reason
                    .contains("the owner `ua-y` is lost (its liveliness token is gone)")),
                "{reason:?}"
            );
        }
        let status = agent.status();
        assert_eq!(
            (status.built, status.refused, status.owners_asked),
            (1, 2, 1),
            "{status:?}"
        );
    }

    /// When an owner is lost, its instances are sent to dead on the reaper's thread
    /// (each command waits for the instance): the agent serves requests meanwhile.
    #[test]
    fn a_lost_owners_instances_go_to_dead_off_the_agents_thread() {
        let port = free_port();
        let node = crate::testing::node("ok", Some(port), None);
        let agent = Agent::start(Arc::clone(&node), idle_registry(idle_spec())).unwrap();
        let owner = crate::testing::node("ok-x", None, Some(port));
        meet(&owner, "ok");
        let name = own("ok-x", "idle");
        let held = hold("kill", &name);
        let owned = Instantiate {
            owner: Some("ok-x".to_owned()),
            ..request("Idle", &name)
        };
        instantiate(&owner, "ok", &owned, Duration::from_secs(10)).unwrap();
        drop(owner);
        held.begun
            .recv_timeout(Duration::from_secs(60))
            .expect("the lost owner's instance is sent to dead");
        instantiate(
            &node,
            "ok",
            &request("Idle", &own("ok", "a")),
            Duration::from_secs(10),
        )
        .expect("a request served while a lost owner's instance goes to dead");
        drop(held);
        assert!(
            eventually(|| threads_named("cool-net:ok:m") == 1),
            "the lost owner's instance is released: {} exposures",
            threads_named("cool-net:ok:m")
        );
        assert_eq!(agent.status().built, 2);
    }

    /// What a refused request had built is shut down on the reaper's thread: the
    /// refusal is answered, and other requests are served, meanwhile; its names stay
    /// taken until its system is shut down.
    #[test]
    fn a_refused_requests_system_is_shut_down_off_the_agents_thread() {
        let node = crate::testing::node("rs", None, None);
        let agent = Agent::start(Arc::clone(&node), idle_registry(idle_spec())).unwrap();
        let timeout = Duration::from_secs(10);
        let name = own("rs", "refused");
        let held = hold("release", &name);
        // Refused by the instance's control port, after it was added to its system.
        let refused = instantiate(
            &node,
            "rs",
            &Instantiate {
                variables: vec![("nope".to_owned(), Value::Int(1))],
                ..request("Idle", &name)
            },
            timeout,
        );
        assert!(
            matches!(&refused, Err(Error::Refused { reason, .. }) if reason.contains("nope")),
            "{refused:?}"
        );
        held.begun
            .recv_timeout(Duration::from_secs(60))
            .expect("the refused request's system is shut down");
        instantiate(&node, "rs", &request("Idle", &own("rs", "a")), timeout)
            .expect("a request served while a refused request's system is shut down");
        let taken = instantiate(&node, "rs", &request("Idle", &name), timeout);
        assert!(
            matches!(&taken, Err(Error::Refused { reason, .. }) if reason.contains("is not a free instance name")),
            "{taken:?}"
        );
        drop(held);
        built(&node, "rs", &request("Idle", &name));
        assert_eq!(agent.status().built, 2);
    }

    /// After a dropped loss, the owners are asked for even while requests keep the
    /// agent busy: an instance whose owner's loss was dropped goes to dead.
    #[test]
    fn a_dropped_loss_has_the_owners_asked_for_however_many_requests_come() {
        let port = free_port();
        let node = crate::testing::node("rc", Some(port), None);
        let (registry, waiting, open) = gated_registry();
        let agent = Agent::start(Arc::clone(&node), registry).unwrap();
        let owner = crate::testing::node("rc-x", None, Some(port));
        meet(&owner, "rc");
        let owned = Instantiate {
            owner: Some("rc-x".to_owned()),
            ..request("Idle", &own("rc-x", "idle"))
        };
        instantiate(&owner, "rc", &owned, Duration::from_secs(10)).unwrap();
        let gate = hold_agent(&node, &waiting);
        // More losses than wait for the agent's thread (nodes that are no owner),
        // then the owner's: it is dropped.
        let tokens: Vec<_> = (0..=GONE_QUEUE)
            .map(|n| {
                owner
                    .session()
                    .liveliness()
                    .declare_token(keys::node_token(&format!("rc-t{n}")))
                    .wait()
                    .unwrap()
            })
            .collect();
        let pattern = keys::node_token("rc-t$*");
        assert!(eventually(|| {
            crate::node::liveliness_keys(node.session(), &pattern, Duration::from_secs(1))
                .is_ok_and(|alive| alive.len() == GONE_QUEUE + 1)
        }));
        drop(tokens);
        assert!(eventually(|| agent.probe.losses.len() == GONE_QUEUE));
        drop(owner);
        assert!(eventually(|| agent.status().losses_dropped == 2));
        // Requests, one after the other, keep the agent busy.
        let streaming = Arc::new(AtomicBool::new(true));
        let stream = {
            let (node, streaming) = (Arc::clone(&node), Arc::clone(&streaming));
            std::thread::spawn(move || {
                let nothing = request("Nothing", &own("rc", "nothing"));
                while streaming.load(Ordering::Acquire) {
                    let _ = instantiate(&node, "rc", &nothing, Duration::from_secs(10));
                }
            })
        };
        open.send(()).unwrap();
        gate.join().unwrap().unwrap();
        let released = eventually(|| threads_named("cool-net:rc:m") == 1);
        streaming.store(false, Ordering::Release);
        stream.join().unwrap();
        assert!(
            released,
            "the instance of the lost owner still runs: {} exposures",
            threads_named("cool-net:rc:m")
        );
    }

    /// A node whose name is another's followed by `-` (`robot`, `robot-2`) takes
    /// nothing of the other's namespace: neither its proxy's next generation nor any
    /// name the other may build.
    #[test]
    fn a_node_named_as_a_prefix_of_another_takes_none_of_its_names() {
        let node = crate::testing::node("pfx", None, None);
        let _agent =
            Agent::start_with_cap(Arc::clone(&node), idle_registry(idle_spec()), 8).unwrap();
        // Node `robot-2`'s proxy root is observable on the network; its next generation:
        let victim = format!("{}robot-wanderer-5f54b428-2", keys::namespace("robot-2"));
        let squat = ask(
            &node,
            "pfx",
            "robot",
            &request("Idle", &victim),
            Duration::from_secs(10),
        );
        assert!(
            squat.is_err(),
            "node `robot` took a name in the namespace of node `robot-2`"
        );
        let own = ask(
            &node,
            "pfx",
            "robot-2",
            &request("Idle", &victim),
            Duration::from_secs(10),
        );
        assert!(own.is_ok(), "robot-2 refused its own name: {own:?}");
    }

    /// A node whose name holds a `.` has instances built like any other: its
    /// namespace holds no `.`.
    #[test]
    fn a_node_with_a_dot_in_its_name_has_instances_built() {
        let node = crate::testing::node("dot", None, None);
        let _agent =
            Agent::start_with_cap(Arc::clone(&node), idle_registry(idle_spec()), 8).unwrap();
        assert!(keys::check_name("robot.local").is_ok());
        let asked = ask(
            &node,
            "dot",
            "robot.local",
            &request("Idle", &own("robot.local", "planner")),
            Duration::from_secs(10),
        );
        assert!(asked.is_ok(), "{asked:?}");
    }

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
        assert!(levels(&names(&["x"; limits::LEVELS.max + 1])).is_err());
        assert!(levels(&["y".repeat(limits::LEVEL_NAME.max + 1)]).is_err());
    }
}
