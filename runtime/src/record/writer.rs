//! The recorder's thread: it drains the taps and the monitoring subscriptions, writes
//! their messages and the losses it notices, and the summary at the end.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use crossbeam_channel::Sender;

use super::channel::{Channel, McapWriter, Start};
use super::rosbag2::{RosTopic, TopicCount, bag_metadata, metadata_yaml};
use super::tap::{Line, Tap};
use super::{
    END_METADATA, FLUSH_INTERVAL, Loss, LossRecord, MonitorSummary, QUEUE_FULL, RecordError,
    Summary, message_bytes,
};
use crate::handle::Handle;
use crate::monitor::Subscription;
use crate::wake::Doorbell;

/// A followed monitoring port.
pub(super) struct Followed {
    pub(super) path: String,
    pub(super) handle: Handle,
    pub(super) channel: Channel,
    /// The recorder's own subscription: it counts what was published to it and what
    /// was dropped for it (its channel full: the recorder's thread fell behind).
    pub(super) events: Subscription,
    pub(super) recorded: u64,
    /// Drops already written as `lost` records.
    pub(super) reported: u64,
    /// Whether the subscription was ended (`detach`): its counts are final.
    pub(super) detached: bool,
}

impl Followed {
    /// End the subscription: nothing is published to it from now on (what it holds
    /// stays, for the last drain).
    pub(super) fn detach(&mut self, bell: &Arc<Doorbell>) {
        if !std::mem::replace(&mut self.detached, true) {
            self.handle.shared.unsubscribe(&self.events);
            self.handle.shared.forget_waker(bell);
        }
    }
}

/// The name of the metadata record that holds one loss in a rosbag2 recording (key
/// `loss`, a JSON [`LossRecord`]): a rosbag2 bag holds CDR messages of ROS 2 types
/// only.
pub(super) const LOSS_METADATA: &str = "coolbot.loss";

/// A rosbag2 recording's bag: its directory, its MCAP file's name, its topics and
/// what was written on each (for `metadata.yaml`).
pub(super) struct Bag {
    pub(super) dir: PathBuf,
    pub(super) file: String,
    /// Each topic and its channel.
    pub(super) topics: Vec<(RosTopic, u16)>,
    /// Messages written per channel.
    pub(super) counts: BTreeMap<u16, u64>,
    /// The first and last message's `log_time`.
    pub(super) span: Option<(u64, u64)>,
}

impl Bag {
    /// The bag's metadata (rosbag2's `BagMetadata`, serialized).
    fn metadata(&self) -> String {
        let topics: Vec<TopicCount<'_>> = self
            .topics
            .iter()
            .map(|(topic, channel)| TopicCount {
                topic,
                messages: self.counts.get(channel).copied().unwrap_or(0),
            })
            .collect();
        // rosbag2 writes an empty bag's start as the largest time.
        let (start, duration) = self
            .span
            .map_or((i64::MAX as u64, 0), |(first, last)| (first, last - first));
        bag_metadata(&self.file, &topics, start, duration)
    }
}

/// The recorder's thread.
pub(super) struct Writer {
    pub(super) path: PathBuf,
    pub(super) mcap: McapWriter,
    pub(super) start: Start,
    /// `log_time` of the start.
    pub(super) start_unix_ns: u64,
    pub(super) taps: Vec<Box<dyn Tap>>,
    pub(super) monitors: Vec<Followed>,
    /// The losses' channel (a rosbag2 recording writes each loss as a metadata record
    /// [`LOSS_METADATA`] instead).
    pub(super) losses_channel: Option<Channel>,
    /// What a rosbag2 recording writes beside its messages.
    pub(super) bag: Option<Bag>,
    /// Loss messages written so far (their sequence numbers).
    pub(super) losses_written: u64,
    pub(super) bell: Arc<Doorbell>,
    pub(super) stop: Arc<AtomicBool>,
    pub(super) losses: Sender<Loss>,
}

impl Writer {
    pub(super) fn run(mut self) -> Result<Summary, RecordError> {
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
        let summary = result.map_err(|source| RecordError::Mcap {
            path: self.path.clone(),
            source,
        })?;
        if let Some(bag) = &self.bag {
            // Last, as rosbag2 does: a bag without it was cut off (`ros2 bag reindex`
            // writes it again from the MCAP file).
            let path = bag.dir.join("metadata.yaml");
            std::fs::write(&path, metadata_yaml(&bag.metadata()))
                .map_err(|source| RecordError::Io { path, source })?;
        }
        Ok(summary)
    }

    /// Write one message.
    pub(super) fn write(
        &mut self,
        channel: u16,
        seq: u64,
        t: u64,
        data: &[u8],
    ) -> mcap::McapResult<()> {
        let time = self.start_unix_ns.saturating_add(t);
        if let Some(bag) = &mut self.bag {
            *bag.counts.entry(channel).or_default() += 1;
            bag.span = Some(bag.span.map_or((time, time), |(first, last)| {
                (first.min(time), last.max(time))
            }));
        }
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
    pub(super) fn turn(&mut self) -> mcap::McapResult<()> {
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
            match self.losses_channel {
                Some(channel) => {
                    let data = message_bytes(&loss, channel.wrapped)
                        .map_err(|error| mcap::McapError::Io(error.into()))?;
                    self.write(channel.id, self.losses_written, loss.t, &data)?;
                }
                None => {
                    // (A loss record of strings and numbers always serializes.)
                    let text = serde_json::to_string(&loss).unwrap_or_default();
                    self.mcap.write_metadata(&mcap::records::Metadata {
                        name: LOSS_METADATA.to_owned(),
                        metadata: BTreeMap::from([("loss".to_owned(), text)]),
                    })?;
                }
            }
            self.losses_written += 1;
            let _ = self.losses.try_send(loss);
        }
        Ok(())
    }

    pub(super) fn end(&mut self) -> mcap::McapResult<Summary> {
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
        if let Some(bag) = &self.bag {
            // The bag's metadata in the file too, as rosbag2 writes it when it closes.
            self.mcap.write_metadata(&mcap::records::Metadata {
                name: "rosbag2".to_owned(),
                metadata: BTreeMap::from([("serialized_metadata".to_owned(), bag.metadata())]),
            })?;
        }
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
