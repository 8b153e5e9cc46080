//! Recording and replay of port traffic, like a rosbag for CoolBOT systems.
//!
//! A [`Recorder`] taps data outputs of a running [`System`] by path (`"base.motion.pose"`:
//! a component of the system, instances of compounds through their names, then the
//! port) and monitoring ports of chosen components, and writes what it sees to a file
//! from its own thread. A tap is one more consumer of the output, never a connection:
//! the producer hands it a clone of each packet and goes on (the tap's queue is bounded
//! and a full queue never blocks the producer: the packet is counted as lost, and the
//! loss is written into the recording, sent on [`Recording::losses`] and logged). A
//! monitoring port is followed through the recorder's own counted
//! [`Subscription`], bounded by
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
//!   [`Recorder::tap_with_schema`]), its metadata `coolbot.kind` (`data`, `poster`,
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

use std::any::TypeId;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufReader, BufWriter, Read};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use crossbeam_channel::{Receiver, Sender};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::clock::Clock;
use crate::handle::Handle;
use crate::monitor::{MonitorEvent, Subscription};
use crate::port::{
    DataOut, Deliver, ErasedInput, ErasedOutput, InKind, OutKind, Packet, Parcel, TickIn, TickOut,
};
use crate::schema::Schema;
use crate::system::System;
use crate::wake::Doorbell;

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
    /// The packet, as serde serialized it.
    pub value: serde_json::Value,
}

impl PacketRecord {
    /// The packet as a `T`.
    pub fn decode<T: DeserializeOwned>(&self) -> Result<T, ReadError> {
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

// ---------------------------------------------------------------------------------
// Recording.

/// Sets up a recording: which outputs to tap and which monitoring ports to follow.
/// Nothing is attached to the system until [`Recorder::start`].
///
/// ```
/// # use coolbot::record::Recorder;
/// # fn demo(system: &coolbot::System) -> Result<(), coolbot::record::RecordError> {
/// let mut recorder = Recorder::new();
/// recorder.tap::<f64>(system, "base.motion.speed")?;
/// recorder.monitor(system, "base.motion")?;
/// let recording = recorder.start("run.mcap")?;
/// // ... the system runs ...
/// let summary = recording.finish()?;
/// assert!(summary.ports.iter().all(|p| p.sent == p.recorded + p.lost));
/// # Ok(())
/// # }
/// ```
pub struct Recorder {
    capacity: usize,
    clock: Clock,
    taps: Vec<Box<dyn PendingTap>>,
    monitors: Vec<(String, Handle)>,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let taps: Vec<&str> = self.taps.iter().map(|t| t.path()).collect();
        let monitors: Vec<&str> = self.monitors.iter().map(|(p, _)| p.as_str()).collect();
        f.debug_struct("Recorder")
            .field("capacity", &self.capacity)
            .field("taps", &taps)
            .field("monitors", &monitors)
            .finish()
    }
}

impl Default for Recorder {
    fn default() -> Self {
        Recorder::new()
    }
}

impl Recorder {
    /// A recorder with nothing to record yet and [`DEFAULT_TAP_CAPACITY`].
    pub fn new() -> Recorder {
        Recorder {
            capacity: DEFAULT_TAP_CAPACITY,
            clock: Clock::real(),
            taps: Vec::new(),
            monitors: Vec::new(),
        }
    }

    /// How many packets each tap's queue holds (at least 1) while the recorder's thread
    /// catches up; a packet sent to a full queue is lost, counted and reported.
    pub fn capacity(mut self, packets: usize) -> Recorder {
        self.capacity = packets.max(1);
        self
    }

    /// Stamp the messages with `clock` (`crate::clock`; the real clock by default):
    /// the same virtual clock as the system's makes a recording's times those its
    /// components saw.
    pub fn clock(mut self, clock: Clock) -> Recorder {
        self.clock = clock;
        self
    }

    /// Record the data output at `path` (`component.port`, the component through
    /// nested compounds: `"base.motion.pose"`), whose packets are `T`. The channel's
    /// JSON Schema is traced from `T`'s `Deserialize` ([`crate::schema::of`]).
    pub fn tap<T: Packet + Serialize + DeserializeOwned>(
        &mut self,
        system: &System,
        path: &str,
    ) -> Result<&mut Recorder, RecordError> {
        self.tap_as::<T>(system, path, crate::schema::of::<T>)
    }

    /// [`Recorder::tap`] with the channel's JSON Schema given (for a type whose
    /// `Deserialize` cannot be traced, see [`crate::schema`]).
    pub fn tap_with_schema<T: Packet + Serialize>(
        &mut self,
        system: &System,
        path: &str,
        schema: serde_json::Value,
    ) -> Result<&mut Recorder, RecordError> {
        self.tap_as::<T>(system, path, move || Schema::given(schema))
    }

    fn tap_as<T: Packet + Serialize>(
        &mut self,
        system: &System,
        path: &str,
        schema: impl FnOnce() -> Schema,
    ) -> Result<&mut Recorder, RecordError> {
        if self.taps.iter().any(|t| t.path() == path) {
            return Err(RecordError::Duplicate(path.to_owned()));
        }
        let output = find_output(system, path)?;
        if !matches!(output.kind, OutKind::Data | OutKind::Poster) {
            return Err(RecordError::UnsupportedKind {
                path: path.to_owned(),
                kind: output.kind.name(),
                supported: "tap takes data and poster outputs (tick outputs: tap_ticks)",
            });
        }
        if output.type_id != TypeId::of::<T>() {
            return Err(RecordError::TypeMismatch {
                path: path.to_owned(),
                actual: output.type_name.to_owned(),
                requested: std::any::type_name::<T>().to_owned(),
            });
        }
        self.taps.push(Box::new(Pending::<T> {
            path: path.to_owned(),
            kind: output.kind.name(),
            output,
            schema: schema(),
            marker: std::marker::PhantomData,
        }));
        Ok(self)
    }

    /// Record the events of the tick output at `path`: one packet record per event,
    /// with a `null` value (ticks carry no data). An event's `t` is when the
    /// recorder's thread saw it (woken by the event), not when it was emitted; ticks
    /// are counted, never lost.
    pub fn tap_ticks(&mut self, system: &System, path: &str) -> Result<&mut Recorder, RecordError> {
        if self.taps.iter().any(|t| t.path() == path) {
            return Err(RecordError::Duplicate(path.to_owned()));
        }
        let output = find_output(system, path)?;
        if output.kind != OutKind::Tick {
            return Err(RecordError::UnsupportedKind {
                path: path.to_owned(),
                kind: output.kind.name(),
                supported: "tap_ticks takes tick outputs (data outputs: tap)",
            });
        }
        self.taps.push(Box::new(PendingTicks {
            path: path.to_owned(),
            output,
        }));
        Ok(self)
    }

    /// Record the monitoring events of the component at `path` (`"base"`,
    /// `"base.motion"`).
    pub fn monitor(&mut self, system: &System, path: &str) -> Result<&mut Recorder, RecordError> {
        if self.monitors.iter().any(|(p, _)| p == path) {
            return Err(RecordError::Duplicate(path.to_owned()));
        }
        let handle = system
            .handle_at(path)
            .ok_or_else(|| RecordError::UnknownComponent {
                path: path.to_owned(),
                component: path.to_owned(),
            })?;
        self.monitors.push((path.to_owned(), handle));
        Ok(self)
    }

    /// Attach the taps and start recording into the MCAP file at `path` (created or
    /// truncated).
    pub fn start(self, path: impl AsRef<Path>) -> Result<Recording, RecordError> {
        let path = path.as_ref().to_path_buf();
        let file = File::create(&path).map_err(|source| RecordError::Io {
            path: path.clone(),
            source,
        })?;
        let mcap_error = |source| RecordError::Mcap {
            path: path.clone(),
            source,
        };
        let mut mcap = mcap::WriteOptions::new()
            .compression(None)
            .profile("")
            .library(concat!("coolbot-", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::new(file))
            .map_err(mcap_error)?;
        let start = Start::on(self.clock.clone());
        let start_unix_ns = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, nanos);
        let mut pending = self.taps;
        let header = Header {
            version: FORMAT_VERSION,
            start_unix_ns,
            capacity: self.capacity,
            ports: pending
                .iter()
                .map(|tap| PortInfo {
                    path: tap.path().to_owned(),
                    type_name: tap.type_name().to_owned(),
                    kind: tap.kind().to_owned(),
                })
                .collect(),
            monitors: self.monitors.iter().map(|(p, _)| p.clone()).collect(),
        };
        // (A header of strings and numbers always serializes.)
        let header_text = serde_json::to_string(&header).unwrap_or_default();
        mcap.write_metadata(&mcap::records::Metadata {
            name: HEADER_METADATA.to_owned(),
            metadata: BTreeMap::from([("header".to_owned(), header_text)]),
        })
        .map_err(mcap_error)?;

        // One channel per tapped output, per monitored component, and for the losses.
        let mut channels = Vec::new();
        for tap in &mut pending {
            let schema = tap.schema();
            let mut metadata = BTreeMap::new();
            metadata.insert("coolbot.kind".to_owned(), tap.kind().to_owned());
            metadata.insert("coolbot.type".to_owned(), tap.type_name().to_owned());
            let out = add_channel(&mut mcap, tap.type_name(), tap.path(), &schema, metadata)
                .map_err(mcap_error)?;
            channels.push(out);
        }
        let mut monitor_channels = Vec::new();
        let event_schema = crate::schema::of::<MonitorEvent>();
        for (path, _) in &self.monitors {
            let metadata = BTreeMap::from([("coolbot.monitor".to_owned(), path.clone())]);
            let out = add_channel(
                &mut mcap,
                "coolbot::MonitorEvent",
                &format!("{path}{EVENTS_SUFFIX}"),
                &event_schema,
                metadata,
            )
            .map_err(mcap_error)?;
            monitor_channels.push(out);
        }
        let losses_channel = add_channel(
            &mut mcap,
            "coolbot::record::LossRecord",
            LOSSES_TOPIC,
            &crate::schema::of::<LossRecord>(),
            BTreeMap::new(),
        )
        .map_err(mcap_error)?;
        mcap.flush().map_err(mcap_error)?;

        let bell = Doorbell::new();
        let mut taps = Vec::new();
        let mut counters = Vec::new();
        for (pending, channel) in pending.into_iter().zip(channels) {
            let tap = pending.attach(self.capacity, start.clone(), Arc::clone(&bell), channel);
            counters.push(tap.counters());
            taps.push(tap);
        }
        let waker = crate::wake::Waker {
            bell: Arc::clone(&bell),
        };
        let monitors = self
            .monitors
            .into_iter()
            .zip(monitor_channels)
            .map(|((path, handle), channel)| Followed {
                events: handle.subscribe_waking(waker.clone()),
                handle,
                path,
                channel,
                recorded: 0,
                reported: 0,
                detached: false,
            })
            .collect();
        let (loss_sender, losses) = crossbeam_channel::bounded(LOSS_EVENTS);
        let stop = Arc::new(AtomicBool::new(false));
        let thread = Writer {
            path: path.clone(),
            mcap,
            start,
            start_unix_ns,
            taps,
            monitors,
            losses_channel,
            losses_written: 0,
            bell: Arc::clone(&bell),
            stop: Arc::clone(&stop),
            losses: loss_sender,
        };
        let (done_sender, done) = crossbeam_channel::bounded(1);
        let join = crate::thread::spawn("recorder", move || {
            let _ = done_sender.send(thread.run());
        })
        .map_err(RecordError::Spawn)?;
        Ok(Recording {
            path,
            stop,
            bell,
            join: Some(join),
            done,
            counters,
            losses,
        })
    }
}

/// The start of a recording on its clock.
#[derive(Clone)]
struct Start {
    clock: Clock,
    at: Instant,
}

impl Start {
    fn on(clock: Clock) -> Start {
        Start {
            at: clock.now(),
            clock,
        }
    }

    /// Nanoseconds since the start.
    fn since(&self) -> u64 {
        nanos(self.clock.now().saturating_duration_since(self.at))
    }
}

/// A channel of the recording: its id, and whether its messages are wrapped.
#[derive(Debug, Clone, Copy)]
struct Channel {
    id: u16,
    wrapped: bool,
}

/// Add a JSON channel on `topic` with `schema` (wrapped when its values are not
/// objects), named after the Rust type `type_name`.
fn add_channel(
    mcap: &mut McapWriter,
    type_name: &str,
    topic: &str,
    schema: &Schema,
    mut metadata: BTreeMap<String, String>,
) -> Result<Channel, mcap::McapError> {
    let wrapped = !schema.is_object();
    let data = if wrapped {
        schema.wrapped()
    } else {
        schema.schema.clone()
    };
    // (A JSON value always serializes.)
    let bytes = serde_json::to_vec(&data).unwrap_or_default();
    let schema_id = mcap.add_schema(type_name, "jsonschema", &bytes)?;
    metadata.insert("coolbot.schema".to_owned(), schema.derived.clone());
    metadata.insert(
        "coolbot.wrapped".to_owned(),
        if wrapped { "value" } else { "" }.to_owned(),
    );
    let id = mcap.add_channel(schema_id, topic, "json", &metadata)?;
    Ok(Channel { id, wrapped })
}

/// The MCAP writer of a recording.
type McapWriter = mcap::Writer<BufWriter<File>>;

/// How many loss notices [`Recording::losses`] holds; beyond that they are dropped
/// (the losses themselves stay in the recording and in [`Recording::stats`]).
pub const LOSS_EVENTS: usize = 1024;

/// A loss noticed by the recorder's thread, as sent on [`Recording::losses`].
pub type Loss = LossRecord;

/// A recording in progress. [`Recording::finish`] detaches the taps, writes what is
/// still queued and the `end` record, and returns the counts; dropping it does the
/// same and ignores errors.
pub struct Recording {
    path: PathBuf,
    stop: Arc<AtomicBool>,
    bell: Arc<Doorbell>,
    join: Option<std::thread::JoinHandle<()>>,
    done: Receiver<Result<Summary, RecordError>>,
    counters: Vec<Arc<Counters>>,
    losses: Receiver<Loss>,
}

impl std::fmt::Debug for Recording {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Recording({})", self.path.display())
    }
}

impl Recording {
    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Every loss the recorder notices, as it notices it (also written into the
    /// recording and logged with `tracing`).
    pub fn losses(&self) -> &Receiver<Loss> {
        &self.losses
    }

    /// The counts so far, per tapped output (`recorded` lags behind `sent` while
    /// packets wait in the tap's queue).
    pub fn stats(&self) -> Vec<PortSummary> {
        self.counters.iter().map(|c| c.summary()).collect()
    }

    /// Stop recording: detach every tap and monitor, write what they still hold and the
    /// `end` record, flush, and return the counts (in which `sent == recorded + lost`
    /// for every port, and `sent == events + lost` for every monitored component).
    pub fn finish(mut self) -> Result<Summary, RecordError> {
        self.stop_and_join()
    }

    fn stop_and_join(&mut self) -> Result<Summary, RecordError> {
        self.stop.store(true, Ordering::Release);
        self.bell.ring_strong();
        let Some(join) = self.join.take() else {
            return Ok(Summary::default());
        };
        if let Err(message) = crate::thread::join(join) {
            return Err(RecordError::Panicked(message));
        }
        self.done
            .try_recv()
            .unwrap_or_else(|_| Err(RecordError::Panicked("no result".to_owned())))
    }
}

impl Drop for Recording {
    fn drop(&mut self) {
        if self.join.is_some() {
            let _ = self.stop_and_join();
        }
    }
}

/// A tap waiting for [`Recorder::start`].
trait PendingTap: Send {
    fn path(&self) -> &str;
    fn type_name(&self) -> &'static str;
    /// `data`, `poster` or `tick`.
    fn kind(&self) -> &'static str;
    /// The JSON Schema of its messages.
    fn schema(&self) -> Schema;
    fn attach(
        self: Box<Self>,
        capacity: usize,
        start: Start,
        bell: Arc<Doorbell>,
        channel: Channel,
    ) -> Box<dyn Tap>;
}

struct Pending<T> {
    path: String,
    /// `data` or `poster`.
    kind: &'static str,
    output: ErasedOutput,
    schema: Schema,
    marker: std::marker::PhantomData<fn() -> T>,
}

impl<T: Packet + Serialize> PendingTap for Pending<T> {
    fn path(&self) -> &str {
        &self.path
    }

    fn type_name(&self) -> &'static str {
        self.output.type_name
    }

    fn kind(&self) -> &'static str {
        self.kind
    }

    fn schema(&self) -> Schema {
        self.schema.clone()
    }

    fn attach(
        self: Box<Self>,
        capacity: usize,
        start: Start,
        bell: Arc<Doorbell>,
        channel: Channel,
    ) -> Box<dyn Tap> {
        let (sender, receiver) = crossbeam_channel::bounded(capacity);
        let counters = Arc::new(Counters {
            port: self.path.clone(),
            ..Counters::default()
        });
        let sink = Arc::new(TapSink {
            sender,
            start,
            counters: Arc::clone(&counters),
            bell,
        });
        // The kind and type were checked by `Recorder::tap`.
        let id = crate::port::tap_data::<T>(&self.output, sink);
        Box::new(Attached {
            path: self.path,
            output: self.output,
            channel,
            id,
            receiver,
            counters,
            reported: (0, 0),
        })
    }
}

/// A tick tap waiting for [`Recorder::start`].
struct PendingTicks {
    path: String,
    output: ErasedOutput,
}

impl PendingTap for PendingTicks {
    fn path(&self) -> &str {
        &self.path
    }

    fn type_name(&self) -> &'static str {
        "event"
    }

    fn kind(&self) -> &'static str {
        "tick"
    }

    fn schema(&self) -> Schema {
        Schema::given(serde_json::json!({
            "$schema": crate::schema::DIALECT,
            "title": "tick",
            "type": "null",
        }))
    }

    fn attach(
        self: Box<Self>,
        _capacity: usize,
        start: Start,
        bell: Arc<Doorbell>,
        channel: Channel,
    ) -> Box<dyn Tap> {
        // A tick input of the tap's own, owned by no component: each event counts at
        // it and rings the recorder's thread.
        let events = TickIn::new();
        let input = crate::port::InputPort::erased(&events);
        let _ = input.core.owner.set(crate::port::Owner {
            bell,
            shared: std::sync::Weak::new(),
            port_name: "recorder",
            label: None,
        });
        let linked = self.output.link(&input);
        let counters = Arc::new(Counters {
            port: self.path.clone(),
            ..Counters::default()
        });
        Box::new(TickTap {
            path: self.path,
            channel,
            output: self.output,
            input,
            events,
            linked,
            counters,
            start,
        })
    }
}

/// The recorder thread's side of a tick tap.
struct TickTap {
    path: String,
    channel: Channel,
    output: ErasedOutput,
    input: ErasedInput,
    events: TickIn,
    linked: bool,
    counters: Arc<Counters>,
    start: Start,
}

impl Tap for TickTap {
    fn counters(&self) -> Arc<Counters> {
        Arc::clone(&self.counters)
    }

    fn drain(&mut self, lines: &mut Vec<Line>) {
        let count = self.events.take();
        let t = self.start.since();
        for _ in 0..count {
            let seq = self.counters.sent.fetch_add(1, Ordering::AcqRel);
            // A unit value always serializes.
            match message_bytes(&(), self.channel.wrapped) {
                Ok(data) => {
                    lines.push(Line {
                        t,
                        channel: self.channel.id,
                        seq,
                        data,
                    });
                    self.counters.recorded.fetch_add(1, Ordering::AcqRel);
                }
                Err(_) => {
                    self.counters.unserializable.fetch_add(1, Ordering::AcqRel);
                }
            }
        }
    }

    fn detach(&mut self) {
        if std::mem::take(&mut self.linked) {
            self.output.unlink(&self.input);
        }
    }

    fn unreported(&mut self) -> Vec<(u64, u64, &'static str)> {
        Vec::new()
    }

    fn path(&self) -> &str {
        &self.path
    }
}

impl Drop for TickTap {
    fn drop(&mut self) {
        self.detach();
    }
}

/// A tap's counts, shared by the producer side (`sent`, `full`) and the recorder's
/// thread (`recorded`, `unserializable`).
#[derive(Default)]
struct Counters {
    port: String,
    sent: AtomicU64,
    full: AtomicU64,
    recorded: AtomicU64,
    unserializable: AtomicU64,
}

impl Counters {
    fn lost(&self) -> u64 {
        self.full.load(Ordering::Acquire) + self.unserializable.load(Ordering::Acquire)
    }

    fn summary(&self) -> PortSummary {
        // `recorded` and the losses first: `sent` is bumped before either, so the
        // snapshot never shows more recorded and lost than sent.
        let recorded = self.recorded.load(Ordering::Acquire);
        let lost = self.lost();
        PortSummary {
            port: self.port.clone(),
            sent: self.sent.load(Ordering::Acquire).max(recorded + lost),
            recorded,
            lost,
        }
    }
}

/// The producer's side of a tap: one more sink of the output.
struct TapSink<T> {
    sender: Sender<(u64, u64, T)>,
    start: Start,
    counters: Arc<Counters>,
    bell: Arc<Doorbell>,
}

impl<T: Packet> Deliver<T> for TapSink<T> {
    fn deliver(&self, packet: Parcel<T>) {
        // (A packet shared with the output's other sinks is copied here, on the
        // producer's thread, as it was before packets were shared.)
        let packet = packet.into_owned();
        let seq = self.counters.sent.fetch_add(1, Ordering::AcqRel);
        let t = self.start.since();
        if self.sender.try_send((t, seq, packet)).is_err() {
            self.counters.full.fetch_add(1, Ordering::AcqRel);
        }
        self.bell.ring_strong();
    }
}

fn nanos(duration: Duration) -> u64 {
    u64::try_from(duration.as_nanos()).unwrap_or(u64::MAX)
}

/// The `reason` of a loss record: the producer found the tap's queue full.
pub const QUEUE_FULL: &str = "queue full";

/// The `reason` of a loss record: serde could not serialize the packet.
pub const NOT_SERIALIZABLE: &str = "not serializable";

/// The recorder thread's side of a tap.
trait Tap: Send {
    fn counters(&self) -> Arc<Counters>;
    /// Serialize every queued packet into `lines`.
    fn drain(&mut self, lines: &mut Vec<Line>);
    /// Stop receiving: after this returns, nothing more is queued.
    fn detach(&mut self);
    /// The losses not reported yet: `(new, total, reason)`, one per reason.
    fn unreported(&mut self) -> Vec<(u64, u64, &'static str)>;
    fn path(&self) -> &str;
}

struct Attached<T: Packet> {
    path: String,
    output: ErasedOutput,
    channel: Channel,
    id: Option<usize>,
    receiver: Receiver<(u64, u64, T)>,
    counters: Arc<Counters>,
    /// Losses already reported: queue full, not serializable.
    reported: (u64, u64),
}

/// One serialized message with its time, for sorting a batch.
struct Line {
    t: u64,
    channel: u16,
    seq: u64,
    data: Vec<u8>,
}

impl<T: Packet + Serialize> Tap for Attached<T> {
    fn counters(&self) -> Arc<Counters> {
        Arc::clone(&self.counters)
    }

    fn drain(&mut self, lines: &mut Vec<Line>) {
        for (t, seq, value) in self.receiver.try_iter() {
            match message_bytes(&value, self.channel.wrapped) {
                Ok(data) => {
                    lines.push(Line {
                        t,
                        channel: self.channel.id,
                        seq,
                        data,
                    });
                    self.counters.recorded.fetch_add(1, Ordering::AcqRel);
                }
                Err(error) => {
                    crate::limited!(
                        &self.path,
                        |held| tracing::warn!(port = %self.path, seq, "cannot serialize a packet: {error}{held}")
                    );
                    self.counters.unserializable.fetch_add(1, Ordering::AcqRel);
                }
            }
        }
    }

    fn detach(&mut self) {
        if let Some(id) = self.id.take() {
            // Senders deliver under the sinks' read lock: once the write that removes
            // the tap returns, no delivery to it is in flight.
            crate::port::unforward(&self.output, id);
        }
    }

    fn unreported(&mut self) -> Vec<(u64, u64, &'static str)> {
        let full = self.counters.full.load(Ordering::Acquire);
        let unserializable = self.counters.unserializable.load(Ordering::Acquire);
        let mut found = Vec::new();
        if full > self.reported.0 {
            found.push((full - self.reported.0, full, QUEUE_FULL));
        }
        if unserializable > self.reported.1 {
            found.push((
                unserializable - self.reported.1,
                unserializable,
                NOT_SERIALIZABLE,
            ));
        }
        self.reported = (full, unserializable);
        found
    }

    fn path(&self) -> &str {
        &self.path
    }
}

impl<T: Packet> Drop for Attached<T> {
    fn drop(&mut self) {
        // A tap is never left on an output, even if the recorder's thread panicked.
        if let Some(id) = self.id.take() {
            crate::port::unforward(&self.output, id);
        }
    }
}

/// A followed monitoring port.
struct Followed {
    path: String,
    handle: Handle,
    channel: Channel,
    /// The recorder's own subscription: it counts what was published to it and what
    /// was dropped for it (its channel full: the recorder's thread fell behind).
    events: Subscription,
    recorded: u64,
    /// Drops already written as `lost` records.
    reported: u64,
    /// Whether the subscription was ended (`detach`): its counts are final.
    detached: bool,
}

impl Followed {
    /// End the subscription: nothing is published to it from now on (what it holds
    /// stays, for the last drain).
    fn detach(&mut self, bell: &Arc<Doorbell>) {
        if !std::mem::replace(&mut self.detached, true) {
            self.handle.shared.unsubscribe(&self.events);
            self.handle.shared.forget_waker(bell);
        }
    }
}

/// The recorder's thread.
struct Writer {
    path: PathBuf,
    mcap: McapWriter,
    start: Start,
    /// `log_time` of the start.
    start_unix_ns: u64,
    taps: Vec<Box<dyn Tap>>,
    monitors: Vec<Followed>,
    losses_channel: Channel,
    /// Loss messages written so far (their sequence numbers).
    losses_written: u64,
    bell: Arc<Doorbell>,
    stop: Arc<AtomicBool>,
    losses: Sender<Loss>,
}

impl Writer {
    fn run(mut self) -> Result<Summary, RecordError> {
        self.bell.attach();
        let mut last_flush = Instant::now();
        let result = loop {
            self.bell.clear();
            let stopping = self.stop.load(Ordering::Acquire);
            if stopping {
                for tap in &mut self.taps {
                    tap.detach();
                }
                for followed in &mut self.monitors {
                    followed.detach(&self.bell);
                }
            }
            match self.turn() {
                Ok(()) => {}
                Err(source) => break Err(source),
            }
            if stopping {
                break self.end();
            }
            if last_flush.elapsed() >= FLUSH_INTERVAL {
                // Ends the chunk under way: a reader of the file sees it whole.
                if let Err(source) = self.mcap.flush() {
                    break Err(source);
                }
                last_flush = Instant::now();
            }
            self.bell
                .park_until(Some(crate::time::later(Instant::now(), FLUSH_INTERVAL)));
        };
        for tap in &mut self.taps {
            tap.detach();
        }
        result.map_err(|source| RecordError::Mcap {
            path: self.path.clone(),
            source,
        })
    }

    /// Write one message.
    fn write(&mut self, channel: u16, seq: u64, t: u64, data: &[u8]) -> mcap::McapResult<()> {
        let time = self.start_unix_ns.saturating_add(t);
        self.mcap.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: channel,
                // The sequence modulo 2^32 (a reader unwraps it, see `Reader`).
                sequence: seq as u32,
                log_time: time,
                publish_time: time,
            },
            data,
        )
    }

    /// Write what the taps and monitors hold now, then the losses noticed.
    fn turn(&mut self) -> mcap::McapResult<()> {
        let mut lines = Vec::new();
        for tap in &mut self.taps {
            tap.drain(&mut lines);
        }
        for followed in &mut self.monitors {
            for event in followed.events.try_iter() {
                let t = self.start.since();
                let data = message_bytes(&event, followed.channel.wrapped)
                    .map_err(|error| mcap::McapError::Io(error.into()))?;
                lines.push(Line {
                    t,
                    channel: followed.channel.id,
                    seq: followed.recorded,
                    data,
                });
                followed.recorded += 1;
            }
        }
        lines.sort_by_key(|line| line.t);
        for line in &lines {
            self.write(line.channel, line.seq, line.t, &line.data)?;
        }
        let mut losses = Vec::new();
        for tap in &mut self.taps {
            for (lost, total, reason) in tap.unreported() {
                losses.push(LossRecord {
                    t: self.start.since(),
                    port: tap.path().to_owned(),
                    lost,
                    total,
                    reason: reason.to_owned(),
                });
            }
        }
        // Events dropped for the recorder's subscription since the last turn: a loss
        // after this turn's events (a drop means the recorder's channel held
        // `OBSERVER_CAPACITY` older events).
        for followed in &mut self.monitors {
            let total = followed.events.dropped();
            if total > followed.reported {
                losses.push(LossRecord {
                    t: self.start.since(),
                    port: followed.path.clone(),
                    lost: total - followed.reported,
                    total,
                    reason: QUEUE_FULL.to_owned(),
                });
                followed.reported = total;
            }
        }
        for loss in losses {
            crate::limited!(&loss.port, |held| tracing::warn!(
                port = %loss.port,
                lost = loss.lost,
                total = loss.total,
                "recorder: {} lost{held}",
                if self.monitors.iter().any(|m| m.path == loss.port) {
                    "monitoring events"
                } else {
                    "packets"
                }
            ));
            let data = message_bytes(&loss, self.losses_channel.wrapped)
                .map_err(|error| mcap::McapError::Io(error.into()))?;
            self.write(self.losses_channel.id, self.losses_written, loss.t, &data)?;
            self.losses_written += 1;
            let _ = self.losses.try_send(loss);
        }
        Ok(())
    }

    fn end(&mut self) -> mcap::McapResult<Summary> {
        let summary = Summary {
            t: self.start.since(),
            ports: self.taps.iter().map(|t| t.counters().summary()).collect(),
            monitors: self
                .monitors
                .iter()
                .map(|m| MonitorSummary {
                    component: m.path.clone(),
                    // (The subscription ended before the last drain: these are final,
                    // and every event published to it was either recorded or dropped.)
                    sent: m.events.published(),
                    events: m.recorded,
                    lost: m.events.dropped(),
                })
                .collect(),
        };
        // (Strings and numbers always serialize.)
        let text = serde_json::to_string(&summary).unwrap_or_default();
        self.mcap.write_metadata(&mcap::records::Metadata {
            name: END_METADATA.to_owned(),
            metadata: BTreeMap::from([("summary".to_owned(), text)]),
        })?;
        self.mcap.finish()?;
        Ok(summary)
    }
}

impl Drop for Writer {
    fn drop(&mut self) {
        // Also when the thread could not be spawned: the taps detach as they drop.
        for followed in &mut self.monitors {
            followed.detach(&self.bell);
        }
    }
}

/// The output at `path`.
fn find_output(system: &System, path: &str) -> Result<ErasedOutput, RecordError> {
    let (handle, component, port) = find_component(system, path)?;
    handle
        .outputs
        .iter()
        .find(|(name, _)| *name == port)
        .map(|(_, output)| output.clone())
        .ok_or_else(|| RecordError::UnknownPort {
            path: path.to_owned(),
            component: component.to_owned(),
            direction: "output",
            port: port.to_owned(),
            known: known(handle.outputs.iter().map(|(name, _)| *name)),
        })
}

/// The input at `path`.
fn find_input(system: &System, path: &str) -> Result<ErasedInput, RecordError> {
    let (handle, component, port) = find_component(system, path)?;
    let inputs = &handle.inputs;
    inputs
        .iter()
        .find(|(name, _)| *name == port)
        .map(|(_, input)| input.clone())
        .ok_or_else(|| RecordError::UnknownPort {
            path: path.to_owned(),
            component: component.to_owned(),
            direction: "input",
            port: port.to_owned(),
            known: known(inputs.iter().map(|(name, _)| *name)),
        })
}

fn find_component<'p>(
    system: &System,
    path: &'p str,
) -> Result<(Handle, &'p str, &'p str), RecordError> {
    let Some((component, port)) = path.rsplit_once('.') else {
        return Err(RecordError::BadPath {
            path: path.to_owned(),
        });
    };
    if component.is_empty() || port.is_empty() {
        return Err(RecordError::BadPath {
            path: path.to_owned(),
        });
    }
    let handle = system
        .handle_at(component)
        .ok_or_else(|| RecordError::UnknownComponent {
            path: path.to_owned(),
            component: component.to_owned(),
        })?;
    Ok((handle, component, port))
}

fn known<'a>(names: impl Iterator<Item = &'a str>) -> String {
    let names: Vec<&str> = names.collect();
    if names.is_empty() {
        "none".to_owned()
    } else {
        names.join(", ")
    }
}

// ---------------------------------------------------------------------------------
// Reading.

/// Reads a recording: the [`Header`] at once, then the records as an iterator (packets,
/// losses and events in file order, then the [`Summary`] as [`Record::End`] if the
/// recording ended cleanly).
///
/// It streams the file (one record in memory at a time). A recording whose process
/// died before [`Recording::finish`] holds every chunk flushed until then; the
/// reader yields them, then an error for the cut-off end.
pub struct Reader {
    path: PathBuf,
    header: Header,
    input: Box<dyn Read + Send>,
    mcap: mcap::sans_io::LinearReader,
    channels: BTreeMap<u16, Topic>,
    /// Records read so far (for error messages).
    record: usize,
    /// The data section ended (or an error was yielded).
    done: bool,
}

/// What a channel of a recording carries.
#[derive(Debug)]
enum Topic {
    /// A tapped output, and the last sequence number read on it (to unwrap the
    /// 32-bit MCAP sequence).
    Port {
        path: String,
        wrapped: bool,
        last: Option<u64>,
    },
    /// A monitored component's events.
    Events { component: String, wrapped: bool },
    /// The losses.
    Losses { wrapped: bool },
    /// A channel this runtime does not write (ignored).
    Other,
}

/// An MCAP record, owned, as far as a [`Reader`] cares.
enum Raw {
    Metadata(mcap::records::Metadata),
    Channel(mcap::records::Channel),
    Message(mcap::records::MessageHeader, Vec<u8>),
    DataEnd,
    Other,
}

impl std::fmt::Debug for Reader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Reader({})", self.path.display())
    }
}

impl Reader {
    /// Open the recording at `path` and read its header.
    pub fn open(path: impl AsRef<Path>) -> Result<Reader, ReadError> {
        let path = path.as_ref().to_path_buf();
        let file = File::open(&path).map_err(|source| ReadError::Io {
            path: path.clone(),
            source,
        })?;
        Reader::new(path, Box::new(BufReader::new(file)))
    }

    /// Read a recording from `input` (`path` names it in errors).
    pub fn new(path: PathBuf, input: Box<dyn Read + Send>) -> Result<Reader, ReadError> {
        let mut reader = Reader {
            path,
            header: Header {
                version: FORMAT_VERSION,
                start_unix_ns: 0,
                capacity: 0,
                ports: Vec::new(),
                monitors: Vec::new(),
            },
            input,
            mcap: mcap::sans_io::LinearReader::new(),
            channels: BTreeMap::new(),
            record: 0,
            done: false,
        };
        // The header metadata comes before any channel.
        loop {
            let raw = match reader.next_raw() {
                Some(Ok(raw)) => raw,
                Some(Err(error)) => return Err(error),
                None => return Err(reader.no_header()),
            };
            match raw {
                Raw::Metadata(metadata) if metadata.name == HEADER_METADATA => {
                    let text = metadata.metadata.get("header").cloned().unwrap_or_default();
                    let value: serde_json::Value = serde_json::from_str(&text)
                        .map_err(|source| reader.json("header", source))?;
                    let version = value.get("version").and_then(serde_json::Value::as_u64);
                    if let Some(found) = version.filter(|v| *v != u64::from(FORMAT_VERSION)) {
                        return Err(ReadError::Version {
                            path: reader.path,
                            found: u32::try_from(found).unwrap_or(u32::MAX),
                        });
                    }
                    reader.header = serde_json::from_value(value)
                        .map_err(|source| reader.json("header", source))?;
                    return Ok(reader);
                }
                Raw::Channel(_) | Raw::Message(..) | Raw::DataEnd => {
                    return Err(reader.no_header());
                }
                Raw::Metadata(_) | Raw::Other => {}
            }
        }
    }

    fn no_header(&self) -> ReadError {
        ReadError::NoHeader {
            path: self.path.clone(),
        }
    }

    fn json(&self, what: &'static str, source: serde_json::Error) -> ReadError {
        ReadError::Json {
            path: self.path.clone(),
            record: self.record,
            what,
            source,
        }
    }

    /// The header.
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// The packets of `port` decoded as `T`, in file order, skipping other records.
    pub fn packets<T: DeserializeOwned>(
        self,
        port: &str,
    ) -> impl Iterator<Item = Result<(PacketRecord, T), ReadError>> {
        let port = port.to_owned();
        self.filter_map(move |record| match record {
            Ok(Record::Packet(packet)) if packet.port == port => {
                Some(packet.decode::<T>().map(|value| (packet, value)))
            }
            Ok(_) => None,
            Err(error) => Some(Err(error)),
        })
    }

    /// The next MCAP record of the data section, chunks unpacked.
    fn next_raw(&mut self) -> Option<Result<Raw, ReadError>> {
        loop {
            let event = match self.mcap.next_event()? {
                Ok(event) => event,
                Err(source) => {
                    return Some(Err(ReadError::Mcap {
                        path: self.path.clone(),
                        source,
                    }));
                }
            };
            match event {
                mcap::sans_io::LinearReadEvent::ReadRequest(wanted) => {
                    let buffer = self.mcap.insert(wanted);
                    let read = match self.input.read(buffer) {
                        Ok(read) => read,
                        Err(error) if error.kind() == std::io::ErrorKind::Interrupted => 0,
                        Err(source) => {
                            return Some(Err(ReadError::Io {
                                path: self.path.clone(),
                                source,
                            }));
                        }
                    };
                    self.mcap.notify_read(read);
                }
                mcap::sans_io::LinearReadEvent::Record { data, opcode } => {
                    self.record += 1;
                    let raw = match mcap::parse_record(opcode, data) {
                        Ok(mcap::records::Record::Metadata(metadata)) => Raw::Metadata(metadata),
                        Ok(mcap::records::Record::Channel(channel)) => Raw::Channel(channel),
                        Ok(mcap::records::Record::Message { header, data }) => {
                            Raw::Message(header, data.into_owned())
                        }
                        Ok(mcap::records::Record::DataEnd(_)) => Raw::DataEnd,
                        Ok(_) => Raw::Other,
                        Err(source) => {
                            return Some(Err(ReadError::Mcap {
                                path: self.path.clone(),
                                source,
                            }));
                        }
                    };
                    return Some(Ok(raw));
                }
            }
        }
    }

    /// Learn what a channel carries.
    fn declare(&mut self, channel: mcap::records::Channel) {
        let wrapped = channel
            .metadata
            .get("coolbot.wrapped")
            .is_some_and(|w| w == "value");
        let topic = if channel.topic == LOSSES_TOPIC {
            Topic::Losses { wrapped }
        } else if let Some(component) = channel.metadata.get("coolbot.monitor") {
            Topic::Events {
                component: component.clone(),
                wrapped,
            }
        } else if channel.metadata.contains_key("coolbot.kind") {
            Topic::Port {
                path: channel.topic,
                wrapped,
                last: None,
            }
        } else {
            Topic::Other
        };
        self.channels.insert(channel.id, topic);
    }

    /// A message as a record; `None` for a channel this runtime does not write.
    fn message(
        &mut self,
        header: mcap::records::MessageHeader,
        data: &[u8],
    ) -> Result<Option<Record>, ReadError> {
        let t = header.log_time.saturating_sub(self.header.start_unix_ns);
        let record = self.record;
        let Some(topic) = self.channels.get_mut(&header.channel_id) else {
            return Err(ReadError::UnknownChannel {
                path: self.path.clone(),
                record,
                channel: header.channel_id,
            });
        };
        let parse = |wrapped: bool| -> Result<serde_json::Value, serde_json::Error> {
            let value: serde_json::Value = serde_json::from_slice(data)?;
            Ok(if wrapped {
                value
                    .get("value")
                    .cloned()
                    .unwrap_or(serde_json::Value::Null)
            } else {
                value
            })
        };
        match topic {
            Topic::Port {
                path,
                wrapped,
                last,
            } => {
                // The MCAP sequence is the packet's number modulo 2^32: the number is
                // the one nearest the last one read (packets sent from several threads
                // at once may be written slightly out of order, so a smaller number is
                // not always a wrap).
                let low = u64::from(header.sequence);
                let seq = match *last {
                    None => low,
                    Some(previous) => {
                        let candidate = (previous & !0xffff_ffff) | low;
                        [
                            candidate.checked_sub(1 << 32),
                            Some(candidate),
                            candidate.checked_add(1 << 32),
                        ]
                        .into_iter()
                        .flatten()
                        .min_by_key(|seq| seq.abs_diff(previous))
                        .unwrap_or(candidate)
                    }
                };
                *last = Some(seq);
                let port = path.clone();
                let value = parse(*wrapped).map_err(|source| self.json("a packet", source))?;
                Ok(Some(Record::Packet(PacketRecord {
                    t,
                    port,
                    seq,
                    value,
                })))
            }
            Topic::Events { component, wrapped } => {
                let component = component.clone();
                let value = parse(*wrapped).map_err(|source| self.json("an event", source))?;
                let event = serde_json::from_value(value)
                    .map_err(|source| self.json("a monitoring event", source))?;
                Ok(Some(Record::Event(EventRecord {
                    t,
                    component,
                    event,
                })))
            }
            Topic::Losses { wrapped } => {
                let value = parse(*wrapped).map_err(|source| self.json("a loss", source))?;
                let loss =
                    serde_json::from_value(value).map_err(|source| self.json("a loss", source))?;
                Ok(Some(Record::Lost(loss)))
            }
            Topic::Other => Ok(None),
        }
    }
}

impl Iterator for Reader {
    type Item = Result<Record, ReadError>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.done {
            let raw = match self.next_raw() {
                None => {
                    self.done = true;
                    return None;
                }
                Some(Err(error)) => {
                    self.done = true;
                    return Some(Err(error));
                }
                Some(Ok(raw)) => raw,
            };
            match raw {
                Raw::Channel(channel) => self.declare(channel),
                Raw::Message(header, data) => match self.message(header, &data) {
                    Ok(Some(record)) => return Some(Ok(record)),
                    Ok(None) => {}
                    Err(error) => return Some(Err(error)),
                },
                Raw::Metadata(metadata) if metadata.name == END_METADATA => {
                    let text = metadata
                        .metadata
                        .get("summary")
                        .cloned()
                        .unwrap_or_default();
                    return Some(
                        serde_json::from_str(&text)
                            .map(Record::End)
                            .map_err(|source| self.json("the summary", source)),
                    );
                }
                // The summary section repeats the channels: nothing more to read.
                Raw::DataEnd => self.done = true,
                Raw::Metadata(_) | Raw::Other => {}
            }
        }
        None
    }
}

// ---------------------------------------------------------------------------------
// Replay.

/// How fast a [`Player`] replays.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pace {
    /// Each packet at its recorded time after the start of the replay.
    Original,
    /// Each packet as soon as the previous one was sent.
    AsFastAsPossible,
}

/// Replays recorded ports into inputs of a running system. Each route gives the
/// input a second producer for the time of the replay (the player's own output,
/// which is not a component): the input's usual producer stays connected.
pub struct Player {
    reader: Reader,
    routes: BTreeMap<String, Box<dyn Route>>,
}

impl std::fmt::Debug for Player {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Player")
            .field("reader", &self.reader)
            .field("routes", &self.routes.keys().collect::<Vec<_>>())
            .finish()
    }
}

/// What a replay did.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Played {
    /// Packets sent, per recorded port routed.
    pub sent: BTreeMap<String, u64>,
    /// Packet records of ports without a route.
    pub skipped: u64,
    /// Loss records of tapped outputs met (packets the recording does not have).
    pub lost: u64,
    /// Loss records of monitoring ports met (events the recording does not have).
    pub lost_events: u64,
}

impl Player {
    /// A player over `reader`, with no routes yet.
    pub fn new(reader: Reader) -> Player {
        Player {
            reader,
            routes: BTreeMap::new(),
        }
    }

    /// A player over the recording at `path`.
    pub fn open(path: impl AsRef<Path>) -> Result<Player, ReadError> {
        Ok(Player::new(Reader::open(path)?))
    }

    /// The recording's header.
    pub fn header(&self) -> &Header {
        self.reader.header()
    }

    /// Replay the recorded port `recorded` (a path in the header) into the input at
    /// `input` (`component.port`, through nested compounds), whose packets are `T`
    /// (a `last`, `fifo` or `ufifo` input).
    pub fn route<T: Packet + DeserializeOwned>(
        &mut self,
        recorded: &str,
        system: &System,
        input: &str,
    ) -> Result<&mut Player, RecordError> {
        self.check_route(recorded)?;
        let target = find_input(system, input)?;
        if !matches!(target.kind, InKind::Last | InKind::Fifo | InKind::Ufifo) {
            return Err(RecordError::UnsupportedKind {
                path: input.to_owned(),
                kind: target.kind.name(),
                supported: "only last, fifo and ufifo inputs can be fed",
            });
        }
        if target.type_id != TypeId::of::<T>() {
            return Err(RecordError::TypeMismatch {
                path: input.to_owned(),
                actual: target.type_name.to_owned(),
                requested: std::any::type_name::<T>().to_owned(),
            });
        }
        let out = DataOut::<T>::new();
        let erased = crate::port::OutputPort::erased(&out);
        if !erased.link(&target) {
            return Err(RecordError::TypeMismatch {
                path: input.to_owned(),
                actual: target.type_name.to_owned(),
                requested: std::any::type_name::<T>().to_owned(),
            });
        }
        self.routes.insert(
            recorded.to_owned(),
            Box::new(Routed {
                out,
                erased,
                target,
            }),
        );
        Ok(self)
    }

    /// Replay the recorded tick port `recorded` into the tick input at `input`: one
    /// event per recorded event.
    pub fn route_ticks(
        &mut self,
        recorded: &str,
        system: &System,
        input: &str,
    ) -> Result<&mut Player, RecordError> {
        self.check_route(recorded)?;
        let target = find_input(system, input)?;
        if target.kind != InKind::Tick {
            return Err(RecordError::UnsupportedKind {
                path: input.to_owned(),
                kind: target.kind.name(),
                supported: "route_ticks feeds tick inputs (data inputs: route)",
            });
        }
        let out = TickOut::new();
        let erased = crate::port::OutputPort::erased(&out);
        // Kinds checked: a tick output links to any tick input.
        let _ = erased.link(&target);
        self.routes.insert(
            recorded.to_owned(),
            Box::new(RoutedTicks {
                out,
                erased,
                target,
            }),
        );
        Ok(self)
    }

    fn check_route(&self, recorded: &str) -> Result<(), RecordError> {
        if !self.reader.header.ports.iter().any(|p| p.path == recorded) {
            return Err(RecordError::NotRecorded {
                port: recorded.to_owned(),
                known: known(self.reader.header.ports.iter().map(|p| p.path.as_str())),
            });
        }
        if self.routes.contains_key(recorded) {
            return Err(RecordError::Duplicate(recorded.to_owned()));
        }
        Ok(())
    }

    /// Replay the whole recording on the calling thread at `pace`, then detach the
    /// routes. A packet that does not decode into its route's type stops the replay
    /// with [`ReadError::Decode`].
    pub fn play(mut self, pace: Pace) -> Result<Played, ReadError> {
        let started = Instant::now();
        let mut played = Played::default();
        for name in self.routes.keys() {
            played.sent.insert(name.clone(), 0);
        }
        let monitors = self.reader.header().monitors.clone();
        for record in self.reader.by_ref() {
            match record? {
                Record::Packet(packet) => {
                    let Some(route) = self.routes.get(&packet.port) else {
                        played.skipped += 1;
                        continue;
                    };
                    if pace == Pace::Original {
                        let due = started + Duration::from_nanos(packet.t);
                        let now = Instant::now();
                        if due > now {
                            std::thread::sleep(due - now);
                        }
                    }
                    route.send(&packet)?;
                    *played.sent.entry(packet.port).or_default() += 1;
                }
                Record::Lost(loss) if monitors.contains(&loss.port) => {
                    played.lost_events += loss.lost;
                }
                Record::Lost(loss) => played.lost += loss.lost,
                Record::Header(_) | Record::Event(_) | Record::End(_) => {}
            }
        }
        Ok(played)
    }
}

/// A route of a [`Player`], erased of its packet type.
trait Route: Send {
    fn send(&self, packet: &PacketRecord) -> Result<(), ReadError>;
}

struct Routed<T: Packet> {
    out: DataOut<T>,
    erased: ErasedOutput,
    target: ErasedInput,
}

impl<T: Packet + DeserializeOwned> Route for Routed<T> {
    fn send(&self, packet: &PacketRecord) -> Result<(), ReadError> {
        self.out.send(packet.decode::<T>()?);
        Ok(())
    }
}

impl<T: Packet> Drop for Routed<T> {
    fn drop(&mut self) {
        self.erased.unlink(&self.target);
    }
}

struct RoutedTicks {
    out: TickOut,
    erased: ErasedOutput,
    target: ErasedInput,
}

impl Route for RoutedTicks {
    fn send(&self, _packet: &PacketRecord) -> Result<(), ReadError> {
        self.out.emit();
        Ok(())
    }
}

impl Drop for RoutedTicks {
    fn drop(&mut self) {
        self.erased.unlink(&self.target);
    }
}
