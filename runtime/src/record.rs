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
//! The file is JSON lines (one JSON object per line, each with a `kind`):
//!
//! - first a `header`: `version` ([`FORMAT_VERSION`]), `start_unix_ns` (wall-clock
//!   start), `capacity` (each tap's queue), `ports` (each tapped output's `path`, Rust
//!   `type` and `kind`: `data`, `poster` or `tick`) and `monitors` (the paths of the
//!   components whose monitoring events are recorded);
//! - then, in the order the recorder's thread wrote them, `packet` records (`t`: time
//!   since the start in ns, taken on the producer's thread when it sent; `port`; `seq`:
//!   the packet's number on that port, from 0; `value`: the packet, serialized with
//!   serde), `lost` records (`t`, `port`, `lost` now, `total` so far, `reason`; for
//!   monitoring events dropped for the recorder, `port` is the component's path), and
//!   `event` records (`t`, `component`, `event`: a [`MonitorEvent`]);
//! - last an `end` record: for each port how many packets were `sent`, `recorded` and
//!   `lost` (always `sent == recorded + lost`), and for each monitored component how
//!   many events it published to the recorder (`sent`), were recorded (`events`) and
//!   were dropped (`lost`), with `sent == events + lost`.
//!
//! Packet records of one port are in `seq` order, and a gap in `seq` is a loss (a `lost`
//! record says so). Records of different ports are sorted by `t` within each batch the
//! thread writes, not across batches: a reader that needs one global order sorts.
//!
//! A [`Reader`] iterates a recording (for offline analysis: [`PacketRecord::decode`]
//! gives the typed packet back), and a [`Player`] replays recorded ports into inputs of
//! a running system, at the original pace or as fast as possible.
//!
//! `data` and `poster` outputs are tapped with [`Recorder::tap`] (every post is a
//! packet record) and tick outputs with [`Recorder::tap_ticks`] (one packet record per
//! event, value `null`, stamped when the recorder's thread sees it); `last`, `fifo`
//! and `ufifo` inputs are fed with [`Player::route`] and tick inputs with
//! [`Player::route_ticks`]. Poster inputs are not fed (they read a producer's post). Packets a producer sends while it answers a pull request go to the
//! requester only, so no tap sees them.

use std::any::TypeId;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use crossbeam_channel::{Receiver, Sender};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::monitor::{Handle, MonitorEvent, Subscription};
use crate::port::{
    DataOut, Deliver, Doorbell, ErasedInput, ErasedOutput, InKind, OutKind, Packet, Parcel, TickIn,
    TickOut,
};
use crate::system::System;

/// The version of the recording format written in every header.
pub const FORMAT_VERSION: u32 = 1;

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
    #[error("cannot write the recording {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// The recorder's thread could not be spawned.
    #[error("cannot spawn the recorder's thread: {0}")]
    Spawn(std::io::Error),
    /// The recorder's thread panicked (a bug).
    #[error("the recorder's thread panicked: {0}")]
    Panicked(String),
}

/// Why a recording could not be read or replayed.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// A line is not a record.
    #[error("{path}:{line}: not a recording record: {source}")]
    Json {
        /// The file.
        path: PathBuf,
        /// The line number (from 1).
        line: usize,
        /// What is wrong.
        source: serde_json::Error,
    },
    /// The file does not start with a header.
    #[error("{path}: not a recording (the first line is not a `header` record)")]
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
    #[error("packet {seq} of `{port}` does not decode: {source}")]
    Decode {
        /// The port.
        port: String,
        /// The packet's sequence number.
        seq: u64,
        /// What is wrong.
        source: serde_json::Error,
    },
}

// ---------------------------------------------------------------------------------
// The records.

/// The first line of a recording.
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

/// The last line of a recording that ended cleanly (also what
/// [`Recording::finish`] returns).
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

/// One line of a recording after the header.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Record {
    /// The header (only as the first line).
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

/// A packet record as the recorder writes it, without building a JSON value first.
#[derive(Serialize)]
#[serde(tag = "kind", rename = "packet")]
struct PacketLine<'a, T> {
    t: u64,
    port: &'a str,
    seq: u64,
    value: &'a T,
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
/// let recording = recorder.start("run.jsonl")?;
/// // ... the system runs ...
/// let summary = recording.finish()?;
/// assert!(summary.ports.iter().all(|p| p.sent == p.recorded + p.lost));
/// # Ok(())
/// # }
/// ```
pub struct Recorder {
    capacity: usize,
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

    /// Record the data output at `path` (`component.port`, the component through
    /// nested compounds: `"base.motion.pose"`), whose packets are `T`.
    pub fn tap<T: Packet + Serialize>(
        &mut self,
        system: &System,
        path: &str,
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

    /// Attach the taps and start recording into the file at `path` (created or
    /// truncated).
    pub fn start(self, path: impl AsRef<Path>) -> Result<Recording, RecordError> {
        let path = path.as_ref().to_path_buf();
        let file = File::create(&path).map_err(|source| RecordError::Io {
            path: path.clone(),
            source,
        })?;
        self.start_writer(path, Box::new(BufWriter::new(file)))
    }

    fn start_writer(
        self,
        path: PathBuf,
        mut writer: Box<dyn Write + Send>,
    ) -> Result<Recording, RecordError> {
        let io = |source| RecordError::Io {
            path: path.clone(),
            source,
        };
        let start = Instant::now();
        let start_unix_ns = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, nanos);
        let header = Record::Header(Header {
            version: FORMAT_VERSION,
            start_unix_ns,
            capacity: self.capacity,
            ports: self
                .taps
                .iter()
                .map(|tap| PortInfo {
                    path: tap.path().to_owned(),
                    type_name: tap.type_name().to_owned(),
                    kind: tap.kind().to_owned(),
                })
                .collect(),
            monitors: self.monitors.iter().map(|(p, _)| p.clone()).collect(),
        });
        serde_json::to_writer(&mut writer, &header).map_err(|e| io(e.into()))?;
        writer.write_all(b"\n").map_err(io)?;
        writer.flush().map_err(io)?;

        let bell = Doorbell::new();
        let mut taps = Vec::new();
        let mut counters = Vec::new();
        for pending in self.taps {
            let tap = pending.attach(self.capacity, start, Arc::clone(&bell));
            counters.push(tap.counters());
            taps.push(tap);
        }
        let waker = crate::automaton::Waker {
            bell: Arc::clone(&bell),
        };
        let monitors = self
            .monitors
            .into_iter()
            .map(|(path, handle)| Followed {
                events: handle.subscribe_waking(waker.clone()),
                handle,
                path,
                recorded: 0,
                reported: 0,
                detached: false,
            })
            .collect();
        let (loss_sender, losses) = crossbeam_channel::bounded(LOSS_EVENTS);
        let stop = Arc::new(AtomicBool::new(false));
        let thread = Writer {
            path: path.clone(),
            writer,
            start,
            taps,
            monitors,
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
    /// `data` or `tick`.
    fn kind(&self) -> &'static str;
    fn attach(
        self: Box<Self>,
        capacity: usize,
        start: Instant,
        bell: Arc<Doorbell>,
    ) -> Box<dyn Tap>;
}

struct Pending<T> {
    path: String,
    /// `data` or `poster`.
    kind: &'static str,
    output: ErasedOutput,
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

    fn attach(
        self: Box<Self>,
        capacity: usize,
        start: Instant,
        bell: Arc<Doorbell>,
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

    fn attach(
        self: Box<Self>,
        _capacity: usize,
        start: Instant,
        bell: Arc<Doorbell>,
    ) -> Box<dyn Tap> {
        // A tick input of the tap's own, owned by no component: each event counts at
        // it and rings the recorder's thread.
        let events = TickIn::new();
        let input = crate::port::InputPort::erased(&events);
        let _ = input.core.owner.set(crate::port::Owner {
            bell,
            shared: std::sync::Weak::new(),
            port_name: "recorder",
        });
        let linked = self.output.link(&input);
        let counters = Arc::new(Counters {
            port: self.path.clone(),
            ..Counters::default()
        });
        Box::new(TickTap {
            path: self.path,
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
    output: ErasedOutput,
    input: ErasedInput,
    events: TickIn,
    linked: bool,
    counters: Arc<Counters>,
    start: Instant,
}

impl Tap for TickTap {
    fn counters(&self) -> Arc<Counters> {
        Arc::clone(&self.counters)
    }

    fn drain(&mut self, lines: &mut Vec<Line>) {
        let count = self.events.take();
        let t = nanos(self.start.elapsed());
        for _ in 0..count {
            let seq = self.counters.sent.fetch_add(1, Ordering::AcqRel);
            let line = PacketLine {
                t,
                port: &self.path,
                seq,
                value: &(),
            };
            // A unit value always serializes.
            if let Ok(text) = serde_json::to_vec(&line) {
                lines.push(Line { t, text });
                self.counters.recorded.fetch_add(1, Ordering::AcqRel);
            } else {
                self.counters.unserializable.fetch_add(1, Ordering::AcqRel);
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
    start: Instant,
    counters: Arc<Counters>,
    bell: Arc<Doorbell>,
}

impl<T: Packet> Deliver<T> for TapSink<T> {
    fn deliver(&self, packet: Parcel<T>) {
        // (A packet shared with the output's other sinks is copied here, on the
        // producer's thread, as it was before packets were shared.)
        let packet = packet.into_owned();
        let seq = self.counters.sent.fetch_add(1, Ordering::AcqRel);
        let t = nanos(self.start.elapsed());
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
    id: Option<usize>,
    receiver: Receiver<(u64, u64, T)>,
    counters: Arc<Counters>,
    /// Losses already reported: queue full, not serializable.
    reported: (u64, u64),
}

/// One serialized line with its time, for sorting a batch.
struct Line {
    t: u64,
    text: Vec<u8>,
}

impl<T: Packet + Serialize> Tap for Attached<T> {
    fn counters(&self) -> Arc<Counters> {
        Arc::clone(&self.counters)
    }

    fn drain(&mut self, lines: &mut Vec<Line>) {
        for (t, seq, value) in self.receiver.try_iter() {
            let line = PacketLine {
                t,
                port: &self.path,
                seq,
                value: &value,
            };
            match serde_json::to_vec(&line) {
                Ok(text) => {
                    lines.push(Line { t, text });
                    self.counters.recorded.fetch_add(1, Ordering::AcqRel);
                }
                Err(error) => {
                    tracing::warn!(port = %self.path, seq, "cannot serialize a packet: {error}");
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
    writer: Box<dyn Write + Send>,
    start: Instant,
    taps: Vec<Box<dyn Tap>>,
    monitors: Vec<Followed>,
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
                if let Err(source) = self.writer.flush() {
                    break Err(source);
                }
                last_flush = Instant::now();
            }
            self.bell
                .park_until(Some(crate::thread::later(Instant::now(), FLUSH_INTERVAL)));
        };
        for tap in &mut self.taps {
            tap.detach();
        }
        result.map_err(|source| RecordError::Io {
            path: self.path.clone(),
            source,
        })
    }

    /// Write what the taps and monitors hold now, then the losses noticed.
    fn turn(&mut self) -> std::io::Result<()> {
        let mut lines = Vec::new();
        for tap in &mut self.taps {
            tap.drain(&mut lines);
        }
        for followed in &mut self.monitors {
            for event in followed.events.try_iter() {
                let record = Record::Event(EventRecord {
                    t: nanos(self.start.elapsed()),
                    component: followed.path.clone(),
                    event,
                });
                let text = serde_json::to_vec(&record)?;
                lines.push(Line {
                    t: nanos(self.start.elapsed()),
                    text,
                });
                followed.recorded += 1;
            }
        }
        lines.sort_by_key(|line| line.t);
        for line in &lines {
            self.writer.write_all(&line.text)?;
            self.writer.write_all(b"\n")?;
        }
        let mut losses = Vec::new();
        for tap in &mut self.taps {
            for (lost, total, reason) in tap.unreported() {
                losses.push(LossRecord {
                    t: nanos(self.start.elapsed()),
                    port: tap.path().to_owned(),
                    lost,
                    total,
                    reason: reason.to_owned(),
                });
            }
        }
        // Events dropped for the recorder's subscription since the last turn: a `lost`
        // record after this turn's events (a drop means the recorder's channel held
        // `OBSERVER_CAPACITY` older events).
        for followed in &mut self.monitors {
            let total = followed.events.dropped();
            if total > followed.reported {
                losses.push(LossRecord {
                    t: nanos(self.start.elapsed()),
                    port: followed.path.clone(),
                    lost: total - followed.reported,
                    total,
                    reason: QUEUE_FULL.to_owned(),
                });
                followed.reported = total;
            }
        }
        for loss in losses {
            tracing::warn!(
                port = %loss.port,
                lost = loss.lost,
                total = loss.total,
                "recorder: {} lost",
                if self.monitors.iter().any(|m| m.path == loss.port) {
                    "monitoring events"
                } else {
                    "packets"
                }
            );
            serde_json::to_writer(&mut self.writer, &Record::Lost(loss.clone()))?;
            self.writer.write_all(b"\n")?;
            let _ = self.losses.try_send(loss);
        }
        Ok(())
    }

    fn end(&mut self) -> std::io::Result<Summary> {
        let summary = Summary {
            t: nanos(self.start.elapsed()),
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
        serde_json::to_writer(&mut self.writer, &Record::End(summary.clone()))?;
        self.writer.write_all(b"\n")?;
        self.writer.flush()?;
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
    let inputs = &handle.shared.inputs;
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

/// Reads a recording: the [`Header`] at once, then the records as an iterator.
pub struct Reader {
    path: PathBuf,
    header: Header,
    lines: std::io::Lines<Box<dyn BufRead + Send>>,
    line: usize,
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
    pub fn new(path: PathBuf, input: Box<dyn BufRead + Send>) -> Result<Reader, ReadError> {
        let mut lines = input.lines();
        let first = match lines.next() {
            Some(Ok(line)) => line,
            Some(Err(source)) => return Err(ReadError::Io { path, source }),
            None => return Err(ReadError::NoHeader { path }),
        };
        let header = match serde_json::from_str::<Record>(&first) {
            Ok(Record::Header(header)) => header,
            Ok(_) => return Err(ReadError::NoHeader { path }),
            Err(source) => {
                // A header of another version may not parse as this version's header.
                let version = serde_json::from_str::<serde_json::Value>(&first)
                    .ok()
                    .filter(|v| v.get("kind").and_then(|k| k.as_str()) == Some("header"))
                    .and_then(|v| v.get("version").and_then(serde_json::Value::as_u64));
                return Err(match version {
                    Some(found) if found != u64::from(FORMAT_VERSION) => ReadError::Version {
                        path,
                        found: u32::try_from(found).unwrap_or(u32::MAX),
                    },
                    _ => ReadError::Json {
                        path,
                        line: 1,
                        source,
                    },
                });
            }
        };
        if header.version != FORMAT_VERSION {
            return Err(ReadError::Version {
                path,
                found: header.version,
            });
        }
        Ok(Reader {
            path,
            header,
            lines,
            line: 1,
        })
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
}

impl Iterator for Reader {
    type Item = Result<Record, ReadError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            let line = self.lines.next()?;
            self.line += 1;
            let line = match line {
                Ok(line) => line,
                Err(source) => {
                    return Some(Err(ReadError::Io {
                        path: self.path.clone(),
                        source,
                    }));
                }
            };
            if line.trim().is_empty() {
                continue;
            }
            return Some(
                serde_json::from_str::<Record>(&line).map_err(|source| ReadError::Json {
                    path: self.path.clone(),
                    line: self.line,
                    source,
                }),
            );
        }
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
