//! The taps: the producer's side of each (a sink of the output, or a tick input of
//! the recorder's own) and the recorder thread's side, with the counts they share.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use crossbeam_channel::{Receiver, Sender};
use serde::Serialize;

use super::channel::{Channel, Start};
use super::rosbag2::RosTopic;
use super::{NOT_SERIALIZABLE, PortSummary, QUEUE_FULL, message_bytes};
use crate::port::{Deliver, ErasedInput, ErasedOutput, Packet, Parcel, TickIn};
use crate::schema::Schema;
use crate::wake::Doorbell;

/// A tap waiting for [`Recorder::start`].
pub(super) trait PendingTap: Send {
    fn path(&self) -> &str;
    fn type_name(&self) -> &'static str;
    /// `data`, `poster` or `tick`.
    fn kind(&self) -> &'static str;
    /// The JSON Schema of its messages.
    fn schema(&self) -> Schema;
    /// Its topic and type, for a port of a ROS 2 message type tapped as one.
    fn ros(&self) -> Option<&RosTopic>;
    fn attach(
        self: Box<Self>,
        capacity: usize,
        start: Start,
        bell: Arc<Doorbell>,
        channel: Channel,
    ) -> Box<dyn Tap>;
}

pub(super) struct Pending<T> {
    pub(super) path: String,
    /// `data` or `poster`.
    pub(super) kind: &'static str,
    pub(super) output: ErasedOutput,
    pub(super) schema: Schema,
    pub(super) ros: Option<RosTopic>,
    pub(super) marker: std::marker::PhantomData<fn() -> T>,
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

    fn ros(&self) -> Option<&RosTopic> {
        self.ros.as_ref()
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
pub(super) struct PendingTicks {
    pub(super) path: String,
    pub(super) output: ErasedOutput,
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

    fn ros(&self) -> Option<&RosTopic> {
        None
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
pub(super) struct TickTap {
    pub(super) path: String,
    pub(super) channel: Channel,
    pub(super) output: ErasedOutput,
    pub(super) input: ErasedInput,
    pub(super) events: TickIn,
    pub(super) linked: bool,
    pub(super) counters: Arc<Counters>,
    pub(super) start: Start,
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
pub(super) struct Counters {
    pub(super) port: String,
    pub(super) sent: AtomicU64,
    pub(super) full: AtomicU64,
    pub(super) recorded: AtomicU64,
    pub(super) unserializable: AtomicU64,
}

impl Counters {
    pub(super) fn lost(&self) -> u64 {
        self.full.load(Ordering::Acquire) + self.unserializable.load(Ordering::Acquire)
    }

    pub(super) fn summary(&self) -> PortSummary {
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
pub(super) struct TapSink<T> {
    pub(super) sender: Sender<(u64, u64, T)>,
    pub(super) start: Start,
    pub(super) counters: Arc<Counters>,
    pub(super) bell: Arc<Doorbell>,
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

/// The recorder thread's side of a tap.
pub(super) trait Tap: Send {
    fn counters(&self) -> Arc<Counters>;
    /// Serialize every queued packet into `lines`.
    fn drain(&mut self, lines: &mut Vec<Line>);
    /// Stop receiving: after this returns, nothing more is queued.
    fn detach(&mut self);
    /// The losses not reported yet: `(new, total, reason)`, one per reason.
    fn unreported(&mut self) -> Vec<(u64, u64, &'static str)>;
    fn path(&self) -> &str;
}

pub(super) struct Attached<T: Packet> {
    pub(super) path: String,
    pub(super) output: ErasedOutput,
    pub(super) channel: Channel,
    pub(super) id: Option<usize>,
    pub(super) receiver: Receiver<(u64, u64, T)>,
    pub(super) counters: Arc<Counters>,
    /// Losses already reported: queue full, not serializable.
    pub(super) reported: (u64, u64),
}

/// One serialized message with its time, for sorting a batch.
pub(super) struct Line {
    pub(super) t: u64,
    pub(super) channel: u16,
    pub(super) seq: u64,
    pub(super) data: Vec<u8>,
}

impl<T: Packet + Serialize> Tap for Attached<T> {
    fn counters(&self) -> Arc<Counters> {
        Arc::clone(&self.counters)
    }

    fn drain(&mut self, lines: &mut Vec<Line>) {
        for (t, seq, value) in self.receiver.try_iter() {
            let bytes = if self.channel.cdr {
                crate::cdr::to_vec(&value)
                    .map_err(|error| Box::new(error) as Box<dyn std::error::Error>)
            } else {
                message_bytes(&value, self.channel.wrapped).map_err(|error| error.into())
            };
            match bytes {
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
            // A change of the sinks waits for the deliveries in flight (`port::Sinks`):
            // once the one that removes the tap returns, none is on its way to it.
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
