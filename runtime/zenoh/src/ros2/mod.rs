//! ROS 2 topics on the rmw_zenoh wire (`docs/ros2.md`, "Topics on the rmw_zenoh
//! wire"): a [`Participant`] is a ROS 2 node on a Zenoh session, as rmw_zenoh makes
//! one, and its publishers and subscriptions are components, like the bridges'
//! outlets and inlets: [`Participant::publish`] connects an output of a ROS type to a
//! publisher, [`Participant::subscribe`] a subscription to an input, with
//! [`coolbot::System::connect`]'s rules (a port of another type is a typed error).
//!
//! A publisher's messages are the packets as CDR (`coolbot::cdr`) with rmw_zenoh's
//! attachment, on the key `<domain>/<topic>/<dds type>/<type hash>`; the node and
//! each endpoint have rmw_zenoh's liveliness tokens, so ROS 2 tools see them. A
//! received message that does not decode (its size over the bound, an attachment
//! that is not rmw_zenoh's, CDR that is not the type) is dropped and counted at the
//! subscription's `network` input: an `overflows` count and a
//! `MonitorEvent::Overflow` on its monitoring port, and a `tracing` warning.

pub mod wire;

use crate::locks::lock;
use std::marker::PhantomData;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{SystemTime, UNIX_EPOCH};

use coolbot::InputPort;
use coolbot::port::{DataOut, ErasedInput, FifoIn, TickIn};
use coolbot::ros::RosType;
use coolbot::{
    Automaton, Chain, Component, Context, Fault, InputKind, InputSpec, OutputKind, OutputSpec,
    OverflowPolicy, Packet, PortSet, Section, Spec, System,
};
use serde::Serialize;
use serde::de::DeserializeOwned;
use zenoh::Wait;
use zenoh::bytes::ZBytes;

use self::wire::{Attachment, EntityKind, NodeInfo, TopicInfo};
pub use self::wire::{BadName, History, Qos, Reliability};
use crate::limits;

/// Where rmw_zenoh's sessions find their router unless told otherwise.
pub const DEFAULT_ROUTER: &str = "tcp/127.0.0.1:7447";

/// How many packets wait at a publisher's input before the newest is refused
/// (counted) unless [`PublisherBuilder::capacity`] says otherwise.
pub const DEFAULT_CAPACITY: usize = 64;

/// What can go wrong making a participant or a topic.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RosError {
    /// A node name, namespace or topic name that ROS 2 does not allow.
    #[error(transparent)]
    Name(#[from] BadName),
    /// Zenoh refused an operation.
    #[error("zenoh: cannot {action}")]
    Zenoh {
        /// What was being done.
        action: &'static str,
        /// Zenoh's error.
        #[source]
        source: zenoh::Error,
    },
    /// The router endpoint cannot be used (see [`router_config`]).
    #[error("the router endpoint")]
    Router(#[source] Box<crate::Error>),
    /// The topic's component could not be added to the system.
    #[error("cannot add `{name}` to the system")]
    Add {
        /// The component's name.
        name: String,
        /// The system's refusal.
        #[source]
        source: coolbot::Error,
    },
    /// The port cannot be connected to the topic (not a port of the topic's type, not
    /// of a kind that connects, no such port).
    #[error("cannot connect `{port}` to the ROS 2 topic `{topic}`")]
    Connect {
        /// The port (`instance.port`).
        port: String,
        /// The topic.
        topic: String,
        /// The system's refusal.
        #[source]
        source: Box<coolbot::ConnectError>,
    },
}

fn zenoh_error(action: &'static str) -> impl FnOnce(zenoh::Error) -> RosError {
    move |source| RosError::Zenoh { action, source }
}

/// A Zenoh configuration as rmw_zenoh's default session: client mode, connected to the
/// router at `endpoint` ([`DEFAULT_ROUTER`] by default), no scouting. Like a node's
/// own configuration (`crate::peer_config`), a `tcp/` endpoint off loopback is refused
/// without a security file that allows it.
pub fn router_config(endpoint: &str) -> Result<zenoh::Config, RosError> {
    let connect = [endpoint.to_owned()];
    crate::Security::none()
        .check(&[], &connect, false)
        .map_err(|error| RosError::Router(Box::new(error)))?;
    let mut config = zenoh::Config::default();
    let set = |config: &mut zenoh::Config, key: &str, value: &str, action| {
        config.insert_json5(key, value).map_err(zenoh_error(action))
    };
    set(&mut config, "mode", "\"client\"", "set the mode")?;
    let endpoints = serde_json::to_string(&connect).expect("a list of strings serializes");
    set(
        &mut config,
        "connect/endpoints",
        &endpoints,
        "set the connect endpoints",
    )?;
    set(
        &mut config,
        "scouting/multicast/enabled",
        "false",
        "set multicast scouting",
    )?;
    Ok(config)
}

/// A Zenoh session as rmw_zenoh's default one ([`router_config`]): a client of the
/// router at `endpoint`, for [`Participant::open`].
pub fn open_router(endpoint: &str) -> Result<zenoh::Session, RosError> {
    let config = router_config(endpoint)?;
    zenoh::open(config)
        .wait()
        .map_err(zenoh_error("open a session to the ROS 2 router"))
}

/// A participant's identity on the ROS 2 graph.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RosOptions {
    /// The ROS domain id (`ROS_DOMAIN_ID`); 0 by default.
    pub domain: u32,
    /// The node's namespace; `/` by default.
    pub namespace: String,
    /// The node's name; `coolbot` by default.
    pub node: String,
}

impl Default for RosOptions {
    fn default() -> RosOptions {
        RosOptions {
            domain: 0,
            namespace: "/".to_owned(),
            node: "coolbot".to_owned(),
        }
    }
}

/// Which way a topic goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// Published: packets of an output go out.
    Out,
    /// Subscribed: messages come in to an input.
    In,
}

/// What went through one topic of a participant.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicCount {
    /// The fully qualified topic name.
    pub topic: String,
    /// Its message type (`sensor_msgs/msg/LaserScan`).
    pub type_name: &'static str,
    /// Published or subscribed.
    pub direction: Direction,
    /// Messages published (handed to Zenoh) or received and delivered.
    pub messages: u64,
    /// Packets not published (they did not encode, or Zenoh refused them), or
    /// messages received that did not decode.
    pub lost: u64,
}

#[derive(Debug)]
struct Counts {
    topic: String,
    type_name: &'static str,
    direction: Direction,
    messages: AtomicU64,
    lost: AtomicU64,
}

impl Counts {
    fn snapshot(&self) -> TopicCount {
        TopicCount {
            topic: self.topic.clone(),
            type_name: self.type_name,
            direction: self.direction,
            messages: self.messages.load(Ordering::Acquire),
            lost: self.lost.load(Ordering::Acquire),
        }
    }
}

/// A ROS 2 node on a Zenoh session: its liveliness token is declared while it lives,
/// and its topics are components ([`Participant::publisher`],
/// [`Participant::subscriber`]). Cheap to clone.
#[derive(Clone)]
pub struct Participant {
    inner: Arc<Inner>,
}

struct Inner {
    session: zenoh::Session,
    node: NodeInfo,
    /// The next entity id (the node's is 0).
    next_id: AtomicU64,
    topics: Mutex<Vec<Arc<Counts>>>,
    _token: zenoh::liveliness::LivelinessToken,
}

impl std::fmt::Debug for Participant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Participant")
            .field("node", &self.inner.node)
            .finish_non_exhaustive()
    }
}

impl Participant {
    /// A ROS 2 node named by `options` on `session` (a session of its own from
    /// [`router_config`], as rmw_zenoh has, or a `crate::Node`'s, when it reaches the
    /// router): declares its liveliness token.
    pub fn open(session: &zenoh::Session, options: &RosOptions) -> Result<Participant, RosError> {
        wire::check_node_name(&options.node)?;
        wire::check_namespace(&options.namespace)?;
        let node = NodeInfo {
            domain: options.domain,
            zid: session.zid().to_string(),
            nid: 0,
            enclave: "/".to_owned(),
            namespace: options.namespace.clone(),
            name: options.node.clone(),
        };
        let token = session
            .liveliness()
            .declare_token(node.token())
            .wait()
            .map_err(zenoh_error("declare the ROS 2 node's liveliness token"))?;
        Ok(Participant {
            inner: Arc::new(Inner {
                session: session.clone(),
                node,
                next_id: AtomicU64::new(1),
                topics: Mutex::new(Vec::new()),
                _token: token,
            }),
        })
    }

    /// The node's liveliness token.
    pub fn token(&self) -> String {
        self.inner.node.token()
    }

    /// A publisher of `topic` (relative to the namespace unless it starts with `/`):
    /// a component named `name` whose input `input` takes the packets to publish.
    pub fn publisher<T>(&self, name: &str, topic: &str) -> PublisherBuilder<'_, T> {
        PublisherBuilder {
            participant: self,
            name: name.to_owned(),
            topic: topic.to_owned(),
            qos: Qos::default(),
            capacity: DEFAULT_CAPACITY,
            packet: PhantomData,
        }
    }

    /// A subscription to `topic`: a component named `name` whose output `output` sends
    /// each message received.
    pub fn subscriber<T>(&self, name: &str, topic: &str) -> SubscriberBuilder<'_, T> {
        SubscriberBuilder {
            participant: self,
            name: name.to_owned(),
            topic: topic.to_owned(),
            qos: Qos::default(),
            max_payload: limits::ROS_PAYLOAD.max,
            packet: PhantomData,
        }
    }

    /// Publish what the output `output` (`instance.port`) of `system` sends on
    /// `topic`, with the default QoS: adds a publisher named after the topic
    /// (`ros2_pub_<topic>`, its slashes as `_`; `_2`, `_3`, ... after it when that
    /// name is taken) and connects the output to it. Works before and while the
    /// system runs.
    pub fn publish<T>(&self, system: &mut System, topic: &str, output: &str) -> Result<(), RosError>
    where
        T: RosType + Packet + Serialize,
    {
        let name = component_name(system, "pub", topic);
        let component = self.publisher::<T>(&name, topic).build()?;
        add(system, component, &name)?;
        system
            .connect(output, &format!("{name}.input"))
            .map_err(|source| RosError::Connect {
                port: output.to_owned(),
                topic: topic.to_owned(),
                source: Box::new(source),
            })
    }

    /// Deliver what arrives on `topic` at the input `input` (`instance.port`) of
    /// `system`, with the default QoS: adds a subscription named after the topic
    /// (`ros2_sub_<topic>`, named as [`Participant::publish`] names its publisher)
    /// and connects it to the input.
    pub fn subscribe<T>(
        &self,
        system: &mut System,
        topic: &str,
        input: &str,
    ) -> Result<(), RosError>
    where
        T: RosType + Packet + DeserializeOwned,
    {
        let name = component_name(system, "sub", topic);
        let component = self.subscriber::<T>(&name, topic).build()?;
        add(system, component, &name)?;
        system
            .connect(&format!("{name}.output"), input)
            .map_err(|source| RosError::Connect {
                port: input.to_owned(),
                topic: topic.to_owned(),
                source: Box::new(source),
            })
    }

    /// Publish on `topic` what the output `output` sends, each packet converted to
    /// the topic's type by `convert` (a `.cool` converter, on the producer's thread):
    /// [`Participant::publish`] for an output of the program's own packets.
    pub fn publish_via<A, T>(
        &self,
        system: &mut System,
        topic: &str,
        output: &str,
        convert: impl Fn(&A) -> T + Send + Sync + 'static,
    ) -> Result<(), RosError>
    where
        A: Packet,
        T: RosType + Packet + Serialize,
    {
        let name = component_name(system, "pub", topic);
        let component = self.publisher::<T>(&name, topic).build()?;
        add(system, component, &name)?;
        system
            .connect_via(output, &format!("{name}.input"), convert)
            .map_err(|source| RosError::Connect {
                port: output.to_owned(),
                topic: topic.to_owned(),
                source: Box::new(source),
            })
    }

    /// Deliver what arrives on `topic` at the input `input`, each message converted
    /// by `convert` (on the subscription's side): [`Participant::subscribe`] for an
    /// input of the program's own packets.
    pub fn subscribe_via<T, B>(
        &self,
        system: &mut System,
        topic: &str,
        input: &str,
        convert: impl Fn(&T) -> B + Send + Sync + 'static,
    ) -> Result<(), RosError>
    where
        T: RosType + Packet + DeserializeOwned,
        B: Packet,
    {
        let name = component_name(system, "sub", topic);
        let component = self.subscriber::<T>(&name, topic).build()?;
        add(system, component, &name)?;
        system
            .connect_via(&format!("{name}.output"), input, convert)
            .map_err(|source| RosError::Connect {
                port: input.to_owned(),
                topic: topic.to_owned(),
                source: Box::new(source),
            })
    }

    /// What went through each topic so far, in the order they were made.
    pub fn counts(&self) -> Vec<TopicCount> {
        lock(&self.inner.topics)
            .iter()
            .map(|counts| counts.snapshot())
            .collect()
    }

    /// The topic's name, data key, token and counters for a new endpoint.
    fn endpoint<T: RosType>(
        &self,
        topic: &str,
        kind: EntityKind,
        qos: Qos,
    ) -> Result<Endpoint, RosError> {
        let node = &self.inner.node;
        let name = wire::qualify(&node.namespace, topic)?;
        let info = TopicInfo {
            domain: node.domain,
            name: name.clone(),
            dds_type: T::DDS_NAME.to_owned(),
            type_hash: T::TYPE_HASH.to_owned(),
            qos,
        };
        let id = self.inner.next_id.fetch_add(1, Ordering::AcqRel);
        let token_key = node.endpoint_token(id, kind, &info);
        let token = self
            .inner
            .session
            .liveliness()
            .declare_token(token_key.clone())
            .wait()
            .map_err(zenoh_error("declare the ROS 2 endpoint's liveliness token"))?;
        let counts = Arc::new(Counts {
            topic: name,
            type_name: T::NAME,
            direction: match kind {
                EntityKind::Subscription => Direction::In,
                _ => Direction::Out,
            },
            messages: AtomicU64::new(0),
            lost: AtomicU64::new(0),
        });
        lock(&self.inner.topics).push(Arc::clone(&counts));
        Ok(Endpoint {
            key: info.key(),
            gid: wire::gid(&token_key),
            token,
            counts,
        })
    }
}

/// `ros2_<kind>_<topic>`, the topic's slashes as `_`; when `system` has a component
/// of that name already (`/a/b` and `/a_b` make the same name, and a topic may have
/// two publishers), the first of `_2`, `_3`, ... after it that is free.
fn component_name(system: &System, kind: &str, topic: &str) -> String {
    let name = format!(
        "ros2_{kind}_{}",
        topic.trim_start_matches('/').replace('/', "_")
    );
    if system.handle(&name).is_none() {
        return name;
    }
    (2..)
        .map(|n| format!("{name}_{n}"))
        .find(|candidate| system.handle(candidate).is_none())
        .unwrap_or(name)
}

fn add(system: &mut System, component: Component, name: &str) -> Result<(), RosError> {
    system
        .add(component)
        .map(drop)
        .map_err(|source| RosError::Add {
            name: name.to_owned(),
            source,
        })
}

struct Endpoint {
    key: String,
    gid: [u8; wire::GID_LEN],
    token: zenoh::liveliness::LivelinessToken,
    counts: Arc<Counts>,
}

// ---------------------------------------------------------------------------------
// Publishers.

/// Builds a publisher ([`Participant::publisher`]).
#[must_use = "call build() to get the component"]
pub struct PublisherBuilder<'p, T> {
    participant: &'p Participant,
    name: String,
    topic: String,
    qos: Qos,
    capacity: usize,
    packet: PhantomData<fn() -> T>,
}

impl<T> PublisherBuilder<'_, T> {
    /// The QoS its token announces ([`Qos`]); its Zenoh publisher drops a message on
    /// a congested link unless the QoS is reliable and keeps all, as rmw_zenoh's.
    pub fn qos(mut self, qos: Qos) -> Self {
        self.qos = qos;
        self
    }

    /// How many packets wait at its input (a fifo that refuses the newest when full,
    /// counted; [`DEFAULT_CAPACITY`] unless set; at least 1).
    pub fn capacity(mut self, capacity: usize) -> Self {
        self.capacity = capacity.max(1);
        self
    }
}

impl<T: RosType + Packet + Serialize> PublisherBuilder<'_, T> {
    /// Declare the publisher and its liveliness token, and return the component (add
    /// it to the producer's system and connect the producer's output to
    /// `<name>.input`).
    pub fn build(self) -> Result<Component, RosError> {
        let PublisherBuilder {
            participant,
            name,
            topic,
            qos,
            capacity,
            packet: _,
        } = self;
        let endpoint = participant.endpoint::<T>(&topic, EntityKind::Publisher, qos)?;
        // As rmw_zenoh: a message is dropped rather than waited for on a congested
        // link, unless the QoS is reliable and keeps everything.
        let congestion = match (qos.reliability, qos.history) {
            (Reliability::Reliable, History::KeepAll) => zenoh::qos::CongestionControl::Block,
            _ => zenoh::qos::CongestionControl::Drop,
        };
        let publisher = participant
            .inner
            .session
            .declare_publisher(endpoint.key.clone())
            .congestion_control(congestion)
            .wait()
            .map_err(zenoh_error("declare the ROS 2 publisher"))?;
        let kind = InputKind::Fifo {
            capacity,
            policy: OverflowPolicy::Reject,
        };
        let spec = crate::bridge::leak_spec(
            "RosPublisher",
            "Publishes what arrives at `input` on a ROS 2 topic (rmw_zenoh's wire).",
            vec![InputSpec {
                name: "input",
                kind,
                packet: std::any::type_name::<T>(),
                pull: false,
            }],
            None,
            true,
        );
        let input = FifoIn::<T>::new(capacity, OverflowPolicy::Reject);
        let ports = PortSet::new().input(&input);
        let losses = input.erased();
        let automaton = RosPublisher {
            spec,
            input,
            losses,
            publisher,
            gid: endpoint.gid,
            sequence: 0,
            key: endpoint.key,
            counts: endpoint.counts,
            _token: endpoint.token,
        };
        Ok(Component::new(name, Box::new(automaton), ports))
    }
}

struct RosPublisher<T> {
    spec: &'static Spec,
    input: FifoIn<T>,
    losses: ErasedInput,
    publisher: zenoh::pubsub::Publisher<'static>,
    gid: [u8; wire::GID_LEN],
    /// The last sequence number used (rmw_zenoh's first message is 1).
    sequence: i64,
    key: String,
    counts: Arc<Counts>,
    _token: zenoh::liveliness::LivelinessToken,
}

impl<T: Packet + Serialize> RosPublisher<T> {
    fn lost(&self, reason: &str) {
        self.losses.count_loss(1);
        self.counts.lost.fetch_add(1, Ordering::AcqRel);
        coolbot::limited!(&self.key, |held| tracing::warn!(
            key = %self.key,
            "ROS 2 publisher lost a packet: {reason}{held}"
        ));
    }

    fn publish(&mut self, packet: &T) {
        let bytes = match coolbot::cdr::to_vec(packet) {
            Ok(bytes) => bytes,
            Err(error) => return self.lost(&format!("does not encode: {}", Chain(&error))),
        };
        let timestamp = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX));
        let attachment = Attachment {
            sequence: self.sequence + 1,
            timestamp,
            gid: self.gid,
        };
        match self
            .publisher
            .put(bytes)
            .attachment(attachment.encode().to_vec())
            .wait()
        {
            Ok(()) => {
                self.sequence += 1;
                self.counts.messages.fetch_add(1, Ordering::AcqRel);
            }
            Err(error) => self.lost(&format!("zenoh refused it: {}", Chain(&*error))),
        }
    }
}

impl<T: Packet + Serialize> Automaton for RosPublisher<T> {
    fn spec(&self) -> &'static Spec {
        self.spec
    }

    fn section(&mut self, _state: usize, section: Section, _cx: &mut Context) -> Result<(), Fault> {
        if section == Section::Entry {
            let packets: Vec<T> = self.input.drain().collect();
            for packet in &packets {
                self.publish(packet);
            }
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------
// Subscriptions.

/// Builds a subscription ([`Participant::subscriber`]).
#[must_use = "call build() to get the component"]
pub struct SubscriberBuilder<'p, T> {
    participant: &'p Participant,
    name: String,
    topic: String,
    qos: Qos,
    max_payload: usize,
    packet: PhantomData<fn() -> T>,
}

impl<T> SubscriberBuilder<'_, T> {
    /// The QoS its token announces ([`Qos`]).
    pub fn qos(mut self, qos: Qos) -> Self {
        self.qos = qos;
        self
    }

    /// The longest message it decodes, in bytes (`limits::ROS_PAYLOAD` unless
    /// set): a longer one is counted lost at `network`, undecoded.
    pub fn max_payload(mut self, bytes: usize) -> Self {
        self.max_payload = bytes;
        self
    }
}

type Deliver = Arc<dyn Fn(&ZBytes, Option<&ZBytes>) + Send + Sync>;

impl<T: RosType + Packet + DeserializeOwned> SubscriberBuilder<'_, T> {
    /// Declare the subscription's liveliness token and return the component (add it
    /// to the consumer's system and connect `<name>.output` to the consumer's input).
    /// It subscribes when it starts.
    pub fn build(self) -> Result<Component, RosError> {
        let SubscriberBuilder {
            participant,
            name,
            topic,
            qos,
            max_payload,
            packet: _,
        } = self;
        let endpoint = participant.endpoint::<T>(&topic, EntityKind::Subscription, qos)?;
        let spec = crate::bridge::leak_spec(
            "RosSubscriber",
            "Sends on `output` each message of a ROS 2 topic (rmw_zenoh's wire); messages that do not decode are counted at `network`.",
            vec![InputSpec {
                name: "network",
                kind: InputKind::Tick,
                packet: "event",
                pull: false,
            }],
            Some(OutputSpec {
                name: "output",
                kind: OutputKind::Data,
                packet: std::any::type_name::<T>(),
                pull: false,
            }),
            false,
        );
        let network = TickIn::new();
        let output = DataOut::<T>::new();
        let ports = PortSet::new().input(&network).output(&output);
        let losses = network.erased();
        let counts = Arc::clone(&endpoint.counts);
        let key = endpoint.key.clone();
        let deliver: Deliver = Arc::new(move |payload, attachment| {
            match decode::<T>(payload, attachment, max_payload) {
                Ok(packet) => {
                    counts.messages.fetch_add(1, Ordering::AcqRel);
                    output.send(packet);
                }
                Err(reason) => {
                    losses.count_loss(1);
                    counts.lost.fetch_add(1, Ordering::AcqRel);
                    coolbot::limited!(&key, |held| tracing::warn!(
                        %key,
                        "ROS 2 subscription lost a message: {reason}{held}"
                    ));
                }
            }
        });
        let automaton = RosSubscriber {
            spec,
            session: participant.inner.session.clone(),
            key: endpoint.key,
            deliver,
            subscriber: None,
            _token: endpoint.token,
        };
        Ok(Component::new(name, Box::new(automaton), ports))
    }
}

/// A received message as a packet, or why not.
/// Lengths are checked before anything is copied: a payload or an attachment that
/// Zenoh holds in fragments is made contiguous only once it is known to fit.
fn decode<T: DeserializeOwned>(
    payload: &ZBytes,
    attachment: Option<&ZBytes>,
    max_payload: usize,
) -> Result<T, String> {
    if payload.len() > max_payload {
        return Err(format!(
            "{} bytes, more than the {max_payload} it decodes",
            payload.len()
        ));
    }
    if let Some(attachment) = attachment {
        if attachment.len() != wire::ATTACHMENT_LEN {
            return Err(format!(
                "an attachment of {} bytes, not {}",
                attachment.len(),
                wire::ATTACHMENT_LEN
            ));
        }
        Attachment::decode(&attachment.to_bytes()).map_err(|error| error.to_string())?;
    }
    coolbot::cdr::from_slice::<T>(&payload.to_bytes()).map_err(|error| Chain(&error).to_string())
}

struct RosSubscriber {
    spec: &'static Spec,
    session: zenoh::Session,
    key: String,
    deliver: Deliver,
    subscriber: Option<zenoh::pubsub::Subscriber<()>>,
    _token: zenoh::liveliness::LivelinessToken,
}

impl Automaton for RosSubscriber {
    fn spec(&self) -> &'static Spec {
        self.spec
    }

    fn start(&mut self, _cx: &mut Context) -> Result<(), Fault> {
        if self.subscriber.is_some() {
            return Ok(());
        }
        let deliver = Arc::clone(&self.deliver);
        let subscriber = self
            .session
            .declare_subscriber(self.key.clone())
            .callback(move |sample| {
                deliver(sample.payload(), sample.attachment());
            })
            .wait()
            .map_err(|error| Fault::message(format!("cannot subscribe: {}", Chain(&*error))))?;
        self.subscriber = Some(subscriber);
        Ok(())
    }

    fn stop(&mut self, _cx: &mut Context) {
        self.subscriber = None;
    }
}

#[cfg(test)]
mod tests {
    use super::component_name;
    use crate::testing::{idle, idle_spec};

    #[test]
    fn a_bridges_name_is_the_topics_and_the_next_free_one_when_that_is_taken() {
        let mut system = coolbot::System::new();
        assert_eq!(component_name(&system, "pub", "/a/b"), "ros2_pub_a_b");
        system.add(idle("ros2_pub_a_b", idle_spec())).unwrap();
        // `/a_b` makes the same name: the next free one.
        assert_eq!(component_name(&system, "pub", "/a_b"), "ros2_pub_a_b_2");
        system.add(idle("ros2_pub_a_b_2", idle_spec())).unwrap();
        assert_eq!(component_name(&system, "pub", "a/b"), "ros2_pub_a_b_3");
        assert_eq!(component_name(&system, "sub", "/a/b"), "ros2_sub_a_b");
    }
}
