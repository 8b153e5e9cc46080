//! Setting up a recording ([`Recorder`]) and the recording under way ([`Recording`]):
//! the file opened, its header and channels written, the taps attached and the
//! recorder's thread started.

use std::any::TypeId;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{SystemTime, UNIX_EPOCH};

use crossbeam_channel::Receiver;
use serde::Serialize;
use serde::de::DeserializeOwned;

use super::channel::{Channel, McapWriter, Start, nanos};
use super::paths::find_output;
use super::rosbag2::{OFFERED_QOS_PROFILES, RecordFormat, RosTopic, check_topic, topic_of};
use super::tap::{Counters, Pending, PendingTap, PendingTicks};
use super::writer::{Bag, Followed, Writer};
use super::{
    DEFAULT_TAP_CAPACITY, EVENTS_SUFFIX, FORMAT_VERSION, HEADER_METADATA, Header, LOSS_EVENTS,
    LOSSES_TOPIC, Loss, LossRecord, PortInfo, PortSummary, RecordError, Summary,
};
use crate::clock::Clock;
use crate::handle::Handle;
use crate::monitor::MonitorEvent;
use crate::port::{OutKind, Packet};
use crate::ros::RosType;
use crate::schema::Schema;
use crate::system::System;
use crate::wake::Doorbell;

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
    pub(super) capacity: usize,
    pub(super) clock: Clock,
    pub(super) taps: Vec<Box<dyn PendingTap>>,
    pub(super) monitors: Vec<(String, Handle)>,
    pub(super) format: RecordFormat,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let taps: Vec<&str> = self.taps.iter().map(|t| t.path()).collect();
        let monitors: Vec<&str> = self.monitors.iter().map(|(p, _)| p.as_str()).collect();
        f.debug_struct("Recorder")
            .field("capacity", &self.capacity)
            .field("format", &self.format)
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
            format: RecordFormat::Coolbot,
        }
    }

    /// Write the recording in `format` ([`RecordFormat::Coolbot`] by default). A
    /// [`RecordFormat::Ros2`] recording takes only ports tapped with
    /// [`Recorder::tap_ros`] or [`Recorder::tap_ros_on`]: [`Recorder::start`] refuses
    /// any other tap, and any monitor, naming it.
    pub fn format(mut self, format: RecordFormat) -> Recorder {
        self.format = format;
        self
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
        self.tap_as::<T>(system, path, crate::schema::of::<T>, None)
    }

    /// [`Recorder::tap`] with the channel's JSON Schema given (for a type whose
    /// `Deserialize` cannot be traced, see [`crate::schema`]). The channel's schema is
    /// its part the Foxglove viewers read ([`crate::schema::for_viewers`]: no `$ref`,
    /// no `allOf`, no union of several types); the metadata `coolbot.schema.given`
    /// holds it whole.
    pub fn tap_with_schema<T: Packet + Serialize>(
        &mut self,
        system: &System,
        path: &str,
        schema: serde_json::Value,
    ) -> Result<&mut Recorder, RecordError> {
        self.tap_as::<T>(system, path, move || Schema::given(schema), None)
    }

    /// Record the data output at `path`, whose packets are the ROS 2 message type
    /// `T`, on the ROS 2 topic its path names (`robot.base.scan` on
    /// `/robot/base/scan`). In a [`RecordFormat::Ros2`] recording its messages are CDR
    /// on that topic; in a [`RecordFormat::Coolbot`] one it is recorded as
    /// [`Recorder::tap`] records it.
    pub fn tap_ros<T: Packet + Serialize + DeserializeOwned + RosType>(
        &mut self,
        system: &System,
        path: &str,
    ) -> Result<&mut Recorder, RecordError> {
        self.tap_ros_on::<T>(system, path, &topic_of(path))
    }

    /// [`Recorder::tap_ros`] on the ROS 2 topic `topic` (`/scan`: a fully qualified
    /// name, as ROS 2 accepts it).
    pub fn tap_ros_on<T: Packet + Serialize + DeserializeOwned + RosType>(
        &mut self,
        system: &System,
        path: &str,
        topic: &str,
    ) -> Result<&mut Recorder, RecordError> {
        check_topic(topic)?;
        if let Some(other) = self
            .taps
            .iter()
            .find(|t| t.ros().is_some_and(|ros| ros.topic == topic))
        {
            return Err(RecordError::SameTopic {
                topic: topic.to_owned(),
                path: path.to_owned(),
                other: other.path().to_owned(),
            });
        }
        let ros = RosTopic {
            topic: topic.to_owned(),
            type_name: T::NAME,
            hash: T::TYPE_HASH,
            definition: T::MESSAGE_DEFINITION,
        };
        self.tap_as::<T>(system, path, crate::schema::of::<T>, Some(ros))
    }

    pub(super) fn tap_as<T: Packet + Serialize>(
        &mut self,
        system: &System,
        path: &str,
        schema: impl FnOnce() -> Schema,
        ros: Option<RosTopic>,
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
            ros,
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

    /// Attach the taps and start recording at `path`: into the MCAP file at `path`
    /// (created or truncated) in the [`RecordFormat::Coolbot`] format; into the
    /// rosbag2 bag directory `path` (created: it must not exist) in the
    /// [`RecordFormat::Ros2`] format, which then holds `<name>_0.mcap` (`<name>` the
    /// directory's name) and, once the recording finishes, `metadata.yaml`.
    pub fn start(self, path: impl AsRef<Path>) -> Result<Recording, RecordError> {
        let path = path.as_ref().to_path_buf();
        let ros2 = self.format == RecordFormat::Ros2;
        if ros2 {
            if let Some(tap) = self.taps.iter().find(|tap| tap.ros().is_none()) {
                return Err(RecordError::NotRosType {
                    path: tap.path().to_owned(),
                    carries: if tap.kind() == "tick" {
                        "tick events".to_owned()
                    } else {
                        tap.type_name().to_owned()
                    },
                });
            }
            if let Some((component, _)) = self.monitors.first() {
                return Err(RecordError::MonitorNotRos {
                    component: component.clone(),
                });
            }
        }
        let (file_path, bag) = if ros2 {
            std::fs::create_dir(&path).map_err(|source| RecordError::Io {
                path: path.clone(),
                source,
            })?;
            let name = path
                .file_name()
                .map_or_else(|| "bag".into(), |name| name.to_string_lossy().into_owned());
            let file = format!("{name}_0.mcap");
            (path.join(&file), Some(file))
        } else {
            (path.clone(), None)
        };
        let file = File::create(&file_path).map_err(|source| RecordError::Io {
            path: file_path.clone(),
            source,
        })?;
        let mcap_error = |source| RecordError::Mcap {
            path: file_path.clone(),
            source,
        };
        let mut mcap = mcap::WriteOptions::new()
            .compression(None)
            .profile(if ros2 { "ros2" } else { "" })
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

        // One channel per tapped output, per monitored component, and for the losses
        // (in a rosbag2 recording, one per tapped output: its topic).
        let mut channels = Vec::new();
        let mut schemas = BTreeMap::new();
        let mut topics = Vec::new();
        for tap in &mut pending {
            if let (Some(ros), true) = (tap.ros(), ros2) {
                let channel = add_ros_channel(&mut mcap, &mut schemas, ros, tap.as_ref())
                    .map_err(mcap_error)?;
                topics.push((ros.clone(), channel.id));
                channels.push(channel);
                continue;
            }
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
        let losses_channel = if ros2 {
            None
        } else {
            Some(
                add_channel(
                    &mut mcap,
                    "coolbot::record::LossRecord",
                    LOSSES_TOPIC,
                    &crate::schema::of::<LossRecord>(),
                    BTreeMap::new(),
                )
                .map_err(mcap_error)?,
            )
        };
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
        let bag = bag.map(|file| Bag {
            dir: path.clone(),
            file,
            topics,
            counts: BTreeMap::new(),
            span: None,
        });
        let thread = Writer {
            path: file_path,
            bag,
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

/// Add a JSON channel on `topic` with `schema` (wrapped when its values are not
/// objects), named after the Rust type `type_name`.
pub(super) fn add_channel(
    mcap: &mut McapWriter,
    type_name: &str,
    topic: &str,
    schema: &Schema,
    mut metadata: BTreeMap<String, String>,
) -> Result<Channel, mcap::McapError> {
    let wrapped = !schema.is_object();
    // In the part of JSON Schema the Foxglove and Lichtblick viewers read: they refuse
    // a channel for one property outside it. A schema given by the caller is kept
    // whole in the channel's metadata.
    let data = schema.for_viewers();
    if schema.derived == "given" {
        metadata.insert("coolbot.schema.given".to_owned(), schema.schema.to_string());
    }
    // (A JSON value always serializes.)
    let bytes = serde_json::to_vec(&data).unwrap_or_default();
    let schema_id = mcap.add_schema(type_name, "jsonschema", &bytes)?;
    metadata.insert("coolbot.schema".to_owned(), schema.derived.clone());
    metadata.insert(
        "coolbot.wrapped".to_owned(),
        if wrapped { "value" } else { "" }.to_owned(),
    );
    let id = mcap.add_channel(schema_id, topic, "json", &metadata)?;
    Ok(Channel {
        id,
        wrapped,
        cdr: false,
    })
}

/// Add a rosbag2 channel for `ros` (and its type's schema, once per type): message
/// encoding `cdr`, rosbag2's metadata (`offered_qos_profiles`, `topic_type_hash`) and
/// the recorded port (`coolbot.port`, `coolbot.kind`, `coolbot.type`).
fn add_ros_channel(
    mcap: &mut McapWriter,
    schemas: &mut BTreeMap<&'static str, u16>,
    ros: &RosTopic,
    tap: &dyn PendingTap,
) -> Result<Channel, mcap::McapError> {
    let schema_id = match schemas.get(ros.type_name) {
        Some(id) => *id,
        None => {
            let id = mcap.add_schema(ros.type_name, "ros2msg", ros.definition.as_bytes())?;
            schemas.insert(ros.type_name, id);
            id
        }
    };
    let metadata = BTreeMap::from([
        (
            "offered_qos_profiles".to_owned(),
            OFFERED_QOS_PROFILES.to_owned(),
        ),
        ("topic_type_hash".to_owned(), ros.hash.to_owned()),
        ("coolbot.port".to_owned(), tap.path().to_owned()),
        ("coolbot.kind".to_owned(), tap.kind().to_owned()),
        ("coolbot.type".to_owned(), tap.type_name().to_owned()),
    ]);
    let id = mcap.add_channel(schema_id, &ros.topic, "cdr", &metadata)?;
    Ok(Channel {
        id,
        wrapped: false,
        cdr: true,
    })
}

/// A recording in progress. [`Recording::finish`] detaches the taps, writes what is
/// still queued and the `end` record, and returns the counts; dropping it does the
/// same and ignores errors.
pub struct Recording {
    pub(super) path: PathBuf,
    pub(super) stop: Arc<AtomicBool>,
    pub(super) bell: Arc<Doorbell>,
    pub(super) join: Option<std::thread::JoinHandle<()>>,
    pub(super) done: Receiver<Result<Summary, RecordError>>,
    pub(super) counters: Vec<Arc<Counters>>,
    pub(super) losses: Receiver<Loss>,
}

impl std::fmt::Debug for Recording {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Recording({})", self.path.display())
    }
}

impl Recording {
    /// The file being written (the bag directory of a rosbag2 recording).
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

    pub(super) fn stop_and_join(&mut self) -> Result<Summary, RecordError> {
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
