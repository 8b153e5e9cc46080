//! Recording and replay of port traffic, like a rosbag for CoolBOT systems.
//!
//! A [`Recorder`] taps data outputs of a running [`System`](crate::System) by path (`"base.motion.pose"`:
//! a component of the system, instances of compounds through their names, then the
//! port) and monitoring ports of chosen components, and writes what it sees to a file
//! from its own thread. A tap is one more consumer of the output, never a connection:
//! the producer hands it a clone of each packet and goes on (the tap's queue is bounded
//! and a full queue never blocks the producer: the packet is counted as lost, and the
//! loss is written into the recording, sent on [`Recording::losses`] and logged). A
//! monitoring port is followed through the recorder's own counted
//! [`Subscription`](crate::Subscription), bounded by
//! [`OBSERVER_CAPACITY`](crate::OBSERVER_CAPACITY): events dropped for it when the
//! recorder falls behind are lost the same way, counted, written and reported.
//!
//! The file is [MCAP](https://mcap.dev) (profile empty, library `coolbot`, chunked, no
//! compression), so Foxglove and the MCAP tools open it. Every message is JSON
//! (`message_encoding` `json`) with a JSON Schema (`jsonschema`):
//!
//! - a metadata record `coolbot.header` first, before any channel: key `header`, a
//!   JSON [`Header`] (`version` [`FORMAT_VERSION`], `start_unix_ns`, `capacity`, the
//!   tapped `ports` with their Rust `type` and `kind`, the monitored components);
//! - one channel per tapped output, its topic the output's path, its schema the packet
//!   type's ([`crate::schema`]: traced from the type's serde `Deserialize`, or given to
//!   [`Recorder::tap_with_schema`]) in the part of JSON Schema the Foxglove viewers read
//!   ([`crate::schema::for_viewers`]; a given schema also whole in the metadata
//!   `coolbot.schema.given`), its metadata `coolbot.kind` (`data`, `poster`,
//!   `tick`), `coolbot.type` (the Rust type), `coolbot.schema` (how the schema was
//!   obtained) and `coolbot.wrapped` (`value` when a packet that is not a JSON object is
//!   written as `{"value": packet}`, since plotting tools address fields of objects;
//!   empty otherwise). A message is one packet; its `sequence` is the packet's number
//!   on that output since the recording started (from 0, modulo 2^32); its `log_time`
//!   and `publish_time` are when the producer sent it, in nanoseconds since the Unix
//!   epoch (`start_unix_ns` plus the recording clock's time since the start); a tick is
//!   `{"value": null}`, stamped when the recorder's thread saw it;
//! - one channel per monitored component, topic `<path>/events` (metadata
//!   `coolbot.monitor`: the path), one [`MonitorEvent`] per message, stamped when the
//!   recorder's thread received it;
//! - one channel `coolbot/losses` with one [`LossRecord`] per loss noticed (`port`: the
//!   output's path, or the component's path for monitoring events; `lost` now,
//!   `total` so far, `reason`);
//! - a metadata record `coolbot.end` last, key `summary`: a JSON [`Summary`] giving for
//!   each port how many packets were `sent`, `recorded` and `lost` (always `sent ==
//!   recorded + lost`), and for each monitored component how many events it published
//!   to the recorder (`sent`), were recorded (`events`) and were dropped (`lost`), with
//!   `sent == events + lost`. The MCAP statistics record counts the messages per
//!   channel as well.
//!
//! Messages of one port are in `sequence` order when one thread sends on it (an
//! output sent on from several threads at once may have neighbours swapped), and a
//! number missing from the sequence is a loss (a loss message says so). Messages of different channels are in `log_time` order within
//! each batch the thread writes, not across batches: a reader that needs one global
//! order sorts.
//!
//! A [`Reader`] iterates a recording as [`Record`]s (for offline analysis:
//! [`PacketRecord::decode`] gives the typed packet back), and a [`Player`] replays
//! recorded ports into inputs of a running system, at the original pace or as fast as
//! possible.
//!
//! `data` and `poster` outputs are tapped with [`Recorder::tap`] (every post is a
//! packet) and tick outputs with [`Recorder::tap_ticks`] (one message per event);
//! `last`, `fifo` and `ufifo` inputs are fed with [`Player::route`] and tick inputs
//! with [`Player::route_ticks`]. Poster inputs are not fed (they read a producer's
//! post). Packets a producer sends while it answers a pull request go to the requester
//! only, so no tap sees them.

use std::path::PathBuf;
use std::time::Duration;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::monitor::MonitorEvent;

/// The version of the recording format written in every header.
pub const FORMAT_VERSION: u32 = 2;

/// The topic of the channel that holds the losses.
pub const LOSSES_TOPIC: &str = "coolbot/losses";

/// The suffix of a monitored component's channel topic (`base.motion/events`).
pub const EVENTS_SUFFIX: &str = "/events";

/// The name of the metadata record that opens a recording.
const HEADER_METADATA: &str = "coolbot.header";

/// The name of the metadata record that closes a recording that ended cleanly.
const END_METADATA: &str = "coolbot.end";

/// How many packets each tap's queue holds by default, waiting for the recorder's
/// thread (see [`Recorder::capacity`]).
pub const DEFAULT_TAP_CAPACITY: usize = 4096;

/// How often the recorder's thread flushes the file while packets keep coming.
const FLUSH_INTERVAL: Duration = Duration::from_millis(100);

/// Why a tap, a monitor, a route or a recording could not be set up, or failed.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// A rosbag2 recording ([`RecordFormat::Ros2`]) given a port whose packets are not
    /// a ROS 2 message type, or tapped without saying it is one.
    #[error(
        "`{path}` carries `{carries}`, not a ROS 2 message type: a rosbag2 recording takes only ports tapped with `tap_ros` (record the others in a recording of the coolbot format)"
    )]
    NotRosType {
        /// The port.
        path: String,
        /// What it carries (its Rust type, or `tick events`).
        carries: String,
    },
    /// A rosbag2 recording ([`RecordFormat::Ros2`]) asked to record monitoring events,
    /// which are not a ROS 2 message type.
    #[error(
        "the monitoring port of `{component}` is not a ROS 2 topic: a rosbag2 recording holds no monitoring events (record them in a recording of the coolbot format)"
    )]
    MonitorNotRos {
        /// The component.
        component: String,
    },
    /// A ROS 2 topic name that ROS 2 does not accept.
    #[error("`{topic}` is not a ROS 2 topic name: {reason}")]
    BadTopic {
        /// The name.
        topic: String,
        /// Which rule it breaks.
        reason: &'static str,
    },
    /// Two ports recorded on one ROS 2 topic.
    #[error("`{path}` and `{other}` would both be recorded on topic `{topic}`")]
    SameTopic {
        /// The topic.
        topic: String,
        /// The port tapped last.
        path: String,
        /// The port tapped first.
        other: String,
    },
    /// Not `component.port`.
    #[error("`{path}` is not a `component.port` path")]
    BadPath {
        /// The path.
        path: String,
    },
    /// No component at the path.
    #[error("`{path}`: no component `{component}` in the system")]
    UnknownComponent {
        /// The path.
        path: String,
        /// The component part of the path.
        component: String,
    },
    /// The component has no such port.
    #[error("`{path}`: component `{component}` has no {direction} port `{port}` (it has: {known})")]
    UnknownPort {
        /// The path.
        path: String,
        /// The component part.
        component: String,
        /// `input` or `output`.
        direction: &'static str,
        /// The port name.
        port: String,
        /// The ports it has, comma-separated.
        known: String,
    },
    /// The port carries another packet type than the one asked for.
    #[error("`{path}` carries `{actual}`, not `{requested}`")]
    TypeMismatch {
        /// The path.
        path: String,
        /// The port's packet type.
        actual: String,
        /// The type given to `tap` or `route`.
        requested: String,
    },
    /// A port kind that cannot be tapped or fed.
    #[error("`{path}` is a {kind} port: {supported}")]
    UnsupportedKind {
        /// The path.
        path: String,
        /// Its kind.
        kind: &'static str,
        /// What is supported.
        supported: &'static str,
    },
    /// The same path given twice.
    #[error("`{0}` is already recorded or routed")]
    Duplicate(String),
    /// A route for a port the recording does not have.
    #[error("the recording has no port `{port}` (it has: {known})")]
    NotRecorded {
        /// The port asked for.
        port: String,
        /// The recorded ports, comma-separated.
        known: String,
    },
    /// Writing the recording failed.
    #[error("cannot write the recording {path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// The MCAP writer failed.
    #[error("cannot write the recording {path}")]
    Mcap {
        /// The file.
        path: PathBuf,
        /// What failed.
        #[source]
        source: mcap::McapError,
    },
    /// The recorder's thread could not be spawned.
    #[error("cannot spawn the recorder's thread")]
    Spawn(#[source] std::io::Error),
    /// The recorder's thread panicked (a bug).
    #[error("the recorder's thread panicked: {0}")]
    Panicked(String),
}

/// Why a recording could not be read or replayed.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The file could not be read.
    #[error("cannot read {path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// The file is not MCAP, or is damaged.
    #[error("{path}: not a readable MCAP file")]
    Mcap {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        #[source]
        source: mcap::McapError,
    },
    /// A message or metadata record of the recording is not what this runtime writes.
    #[error("{path}: record {record}: {what}")]
    Json {
        /// The file.
        path: PathBuf,
        /// The record's number in the file (from 1).
        record: usize,
        /// What it was meant to be.
        what: &'static str,
        /// What is wrong.
        #[source]
        source: serde_json::Error,
    },
    /// A message on a channel the file never declared.
    #[error("{path}: record {record}: a message on channel {channel}, which is not declared")]
    UnknownChannel {
        /// The file.
        path: PathBuf,
        /// The record's number in the file (from 1).
        record: usize,
        /// The channel id.
        channel: u16,
    },
    /// The file does not start with a header.
    #[error(
        "{path}: not a CoolBOT recording (no `coolbot.header` metadata before the first channel)"
    )]
    NoHeader {
        /// The file.
        path: PathBuf,
    },
    /// A format version this runtime cannot read.
    #[error(
        "{path}: recording format version {found}, this runtime reads version {FORMAT_VERSION}"
    )]
    Version {
        /// The file.
        path: PathBuf,
        /// The version found.
        found: u32,
    },
    /// A packet's CDR bytes (a rosbag2 recording's message) do not decode into the
    /// type asked for.
    #[error("packet {seq} of `{port}` does not decode")]
    DecodeCdr {
        /// The port (or topic).
        port: String,
        /// The packet's sequence number.
        seq: u64,
        /// What is wrong.
        #[source]
        source: crate::cdr::CdrError,
    },
    /// A rosbag2 bag directory that does not hold exactly one MCAP file.
    #[error("{path}: a rosbag2 bag directory with {found} MCAP files; one is read")]
    BagFiles {
        /// The directory.
        path: PathBuf,
        /// How many `.mcap` files it holds.
        found: usize,
    },
    /// A packet's value does not decode into the type asked for.
    #[error("packet {seq} of `{port}` does not decode")]
    Decode {
        /// The port.
        port: String,
        /// The packet's sequence number.
        seq: u64,
        /// What is wrong.
        #[source]
        source: serde_json::Error,
    },
}

mod channel;
mod paths;
mod player;
mod reader;
mod recorder;
mod rosbag2;
mod tap;
mod writer;

pub use player::{Pace, Played, Player};
pub use reader::Reader;
pub use recorder::{Recorder, Recording};
pub use rosbag2::{OFFERED_QOS_PROFILES, RecordFormat, UnknownFormat};

/// The `reason` of a loss record: the producer found the tap's queue full.
pub const QUEUE_FULL: &str = "queue full";

/// The `reason` of a loss record: serde could not serialize the packet.
pub const NOT_SERIALIZABLE: &str = "not serializable";

/// How many loss notices [`Recording::losses`] holds; beyond that they are dropped
/// (the losses themselves stay in the recording and in [`Recording::stats`]).
pub const LOSS_EVENTS: usize = 1024;

/// A loss noticed by the recorder's thread, as sent on [`Recording::losses`].
pub type Loss = LossRecord;

// ---------------------------------------------------------------------------------
// The records.

/// What a recording holds, written first (the `coolbot.header` metadata record).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// [`FORMAT_VERSION`] when written.
    pub version: u32,
    /// When the recording started: nanoseconds since the Unix epoch (wall clock).
    pub start_unix_ns: u64,
    /// Each tap's queue capacity, in packets.
    pub capacity: usize,
    /// The tapped outputs, in the order they were tapped.
    pub ports: Vec<PortInfo>,
    /// The components whose monitoring events are recorded.
    pub monitors: Vec<String>,
}

/// One tapped output in the [`Header`].
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PortInfo {
    /// Its path (`"base.motion.pose"`).
    pub path: String,
    /// The Rust packet type (`std::any::type_name`).
    #[serde(rename = "type")]
    pub type_name: String,
    /// The output kind (`data`, `poster` or `tick`).
    pub kind: String,
}

/// A packet seen on a tapped output.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PacketRecord {
    /// When the producer sent it: nanoseconds since the recording started.
    pub t: u64,
    /// The output's path.
    pub port: String,
    /// Its number among the packets sent on this output since the recording started.
    pub seq: u64,
    /// The packet, as serde serialized it (`null` for a message of a rosbag2
    /// recording: see `cdr`).
    pub value: serde_json::Value,
    /// The message's CDR bytes, with their encapsulation header, for a message of a
    /// rosbag2 recording (message encoding `cdr`); `None` otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cdr: Option<Vec<u8>>,
}

impl PacketRecord {
    /// The packet as a `T`: from its JSON value, or from its CDR bytes
    /// ([`crate::cdr::from_slice`]) for a message of a rosbag2 recording.
    pub fn decode<T: DeserializeOwned>(&self) -> Result<T, ReadError> {
        if let Some(bytes) = &self.cdr {
            return crate::cdr::from_slice(bytes).map_err(|source| ReadError::DecodeCdr {
                port: self.port.clone(),
                seq: self.seq,
                source,
            });
        }
        T::deserialize(&self.value).map_err(|source| ReadError::Decode {
            port: self.port.clone(),
            seq: self.seq,
            source,
        })
    }
}

/// Packets sent on a tapped output that are not in the recording.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct LossRecord {
    /// When the recorder noticed: nanoseconds since the recording started.
    pub t: u64,
    /// The output's path.
    pub port: String,
    /// How many were lost since the last loss record of this port.
    pub lost: u64,
    /// How many were lost on this port for this reason in all.
    pub total: u64,
    /// Why: [`QUEUE_FULL`] or [`NOT_SERIALIZABLE`].
    pub reason: String,
}

/// A monitoring event of a recorded component.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EventRecord {
    /// When the recorder's thread received it: nanoseconds since the start.
    pub t: u64,
    /// The component's path.
    pub component: String,
    /// The event.
    pub event: MonitorEvent,
}

/// The counts of a recording that ended cleanly (the `coolbot.end` metadata record,
/// last in the file; also what [`Recording::finish`] returns).
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Summary {
    /// When the recording ended: nanoseconds since it started.
    pub t: u64,
    /// Each tapped output, in header order.
    pub ports: Vec<PortSummary>,
    /// Each recorded monitoring port, in header order.
    pub monitors: Vec<MonitorSummary>,
}

/// The counts of one tapped output.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct PortSummary {
    /// The output's path.
    pub port: String,
    /// Packets the producer sent while tapped.
    pub sent: u64,
    /// Packets in the recording.
    pub recorded: u64,
    /// Packets lost (queue full or not serializable): `sent - recorded`.
    pub lost: u64,
}

/// The counts of one recorded monitoring port: `sent == events + lost`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct MonitorSummary {
    /// The component's path.
    pub component: String,
    /// Events the component published to the recorder while it was recording.
    #[serde(default)]
    pub sent: u64,
    /// Events in the recording.
    pub events: u64,
    /// Events dropped for the recorder because it fell behind (its subscription held
    /// [`OBSERVER_CAPACITY`](crate::OBSERVER_CAPACITY) events): `sent - events`, each
    /// written as a `lost` record with the component's path as `port`.
    #[serde(default)]
    pub lost: u64,
}

/// One record of a recording, as a [`Reader`] yields it after the header.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Record {
    /// The header (a [`Reader`] gives it as [`Reader::header`], never as a record).
    Header(Header),
    /// A packet.
    Packet(PacketRecord),
    /// A loss.
    Lost(LossRecord),
    /// A monitoring event.
    Event(EventRecord),
    /// The end.
    End(Summary),
}

/// A packet that is not a JSON object, as a recording holds it (`coolbot.wrapped`).
#[derive(Serialize)]
struct Wrapped<'a, T> {
    value: &'a T,
}

/// `value` as the JSON bytes of a message (wrapped in `{"value": ...}` if `wrapped`).
fn message_bytes<T: Serialize>(value: &T, wrapped: bool) -> serde_json::Result<Vec<u8>> {
    if wrapped {
        serde_json::to_vec(&Wrapped { value })
    } else {
        serde_json::to_vec(value)
    }
}
