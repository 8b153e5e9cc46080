//! Replay of an MCAP recording ([`crate::record`]) into one component's [`Harness`]:
//! recorded channels mapped to the component's inputs, each packet pushed at its
//! recorded time on the harness's virtual clock.
//!
//! ```no_run
//! # use coolbot::harness::{Harness, replay::Replay};
//! # fn demo(harness: &mut Harness) -> Result<(), Box<dyn std::error::Error>> {
//! let mut replay = Replay::open("run.mcap")?;
//! replay.route::<f64>("robot.base.motion.speed", harness, "speed")?;
//! let replayed = replay.play(harness)?;
//! assert_eq!(replayed.skipped, 0);
//! # Ok(())
//! # }
//! ```
//!
//! [`Replay::play`] reads the routed packets, orders them by recorded time (a
//! recording is in time order within each batch its recorder wrote, not across
//! batches), and for each advances the harness to the packet's time (relative to the
//! first routed packet, which is delivered at the harness's time when `play` starts),
//! pushes it, and settles. So the component sees the recorded traffic with its
//! recorded spacing, its timers firing in between as they are due, and no real time
//! passes. After the last packet the harness stays at that packet's time; a test
//! advances it further if it wants the component's timers to run on.

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Duration;

use serde::de::DeserializeOwned;

use super::{Harness, HarnessError};
use crate::port::{InKind, Packet};
use crate::record::{PacketRecord, ReadError, Reader, Record};

/// What went wrong setting up or playing a [`Replay`].
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The recording does not have the port.
    #[error("the recording has no port `{port}` (recorded: {known})")]
    NotRecorded {
        /// The port asked for.
        port: String,
        /// The recorded ports.
        known: String,
    },
    /// The recorded port is routed already.
    #[error("recorded port `{0}` is routed twice")]
    Duplicate(String),
    /// The input cannot take the route (name, kind, type), or the harness failed.
    #[error("harness")]
    Harness(#[from] HarnessError),
    /// The recording cannot be read, or a packet does not decode into its route's
    /// type.
    #[error("reading the recording")]
    Read(#[from] ReadError),
}

/// What a replay delivered.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Replayed {
    /// Packets pushed, per recorded port routed.
    pub sent: BTreeMap<String, u64>,
    /// Packet records of ports without a route.
    pub skipped: u64,
    /// Packets the recording says its routed ports lost (loss records): the
    /// component never saw them.
    pub lost: u64,
    /// The recorded time of the first and last packet pushed (since the recording
    /// started).
    pub span: Option<(Duration, Duration)>,
}

/// How one route delivers a recorded packet to the harness.
type Deliver = Box<dyn Fn(&mut Harness, &PacketRecord) -> Result<(), ReplayError>>;

/// Recorded ports mapped to inputs of one component's harness (see the module's
/// documentation).
pub struct Replay {
    reader: Reader,
    routes: BTreeMap<String, Deliver>,
}

impl std::fmt::Debug for Replay {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Replay")
            .field("reader", &self.reader)
            .field("routes", &self.routes.keys().collect::<Vec<_>>())
            .finish()
    }
}

impl Replay {
    /// A replay of `reader`'s recording, with no routes yet.
    pub fn new(reader: Reader) -> Replay {
        Replay {
            reader,
            routes: BTreeMap::new(),
        }
    }

    /// A replay of the recording at `path`.
    pub fn open(path: impl AsRef<Path>) -> Result<Replay, ReplayError> {
        Ok(Replay::new(Reader::open(path)?))
    }

    /// The recording's header.
    pub fn header(&self) -> &crate::record::Header {
        self.reader.header()
    }

    fn check(&self, recorded: &str) -> Result<(), ReplayError> {
        let ports = &self.reader.header().ports;
        if !ports.iter().any(|p| p.path == recorded) {
            let known: Vec<&str> = ports.iter().map(|p| p.path.as_str()).collect();
            return Err(ReplayError::NotRecorded {
                port: recorded.to_owned(),
                known: if known.is_empty() {
                    "none".to_owned()
                } else {
                    known.join(", ")
                },
            });
        }
        if self.routes.contains_key(recorded) {
            return Err(ReplayError::Duplicate(recorded.to_owned()));
        }
        Ok(())
    }

    /// Replay recorded port `recorded` (a path in the header) into input `input` of
    /// `harness`'s component, whose packets are `T` (any input but a tick input:
    /// data inputs get each packet sent, poster inputs posted).
    pub fn route<T: Packet + DeserializeOwned>(
        &mut self,
        recorded: &str,
        harness: &Harness,
        input: &str,
    ) -> Result<&mut Replay, ReplayError> {
        self.check(recorded)?;
        harness.checked_feed::<T>(input)?;
        let port = input.to_owned();
        self.routes.insert(
            recorded.to_owned(),
            Box::new(move |harness, packet| {
                harness.push::<T>(&port, packet.decode::<T>()?)?;
                Ok(())
            }),
        );
        Ok(self)
    }

    /// Replay recorded tick port `recorded` into tick input `input`: one event per
    /// recorded event.
    pub fn route_ticks(
        &mut self,
        recorded: &str,
        harness: &Harness,
        input: &str,
    ) -> Result<&mut Replay, ReplayError> {
        self.check(recorded)?;
        let feed = harness.feed(input)?;
        if feed.input.kind != InKind::Tick {
            return Err(HarnessError::WrongKind {
                port: input.to_owned(),
                kind: feed.input.kind.name(),
                wanted: "route_ticks feeds tick inputs (data inputs: route)",
            }
            .into());
        }
        let port = input.to_owned();
        self.routes.insert(
            recorded.to_owned(),
            Box::new(move |harness, _| {
                harness.tick(&port)?;
                Ok(())
            }),
        );
        Ok(self)
    }

    /// Play the routed packets into `harness` on its virtual clock (see the module's
    /// documentation). A packet that does not decode into its route's type stops the
    /// replay with [`ReadError::Decode`].
    pub fn play(mut self, harness: &mut Harness) -> Result<Replayed, ReplayError> {
        let mut replayed = Replayed::default();
        for name in self.routes.keys() {
            replayed.sent.insert(name.clone(), 0);
        }
        let mut packets = Vec::new();
        for record in self.reader.by_ref() {
            match record? {
                Record::Packet(packet) if self.routes.contains_key(&packet.port) => {
                    packets.push(packet);
                }
                Record::Packet(_) => replayed.skipped += 1,
                Record::Lost(loss) if self.routes.contains_key(&loss.port) => {
                    replayed.lost += loss.lost;
                }
                Record::Header(_) | Record::Lost(_) | Record::Event(_) | Record::End(_) => {}
            }
        }
        // Stable: packets of one port keep their order.
        packets.sort_by_key(|packet| packet.t);
        let Some(first) = packets.first().map(|packet| packet.t) else {
            return Ok(replayed);
        };
        let start = harness.elapsed();
        for packet in &packets {
            let due = start + Duration::from_nanos(packet.t - first);
            let now = harness.elapsed();
            harness.advance(due.saturating_sub(now))?;
            if let Some(deliver) = self.routes.get(&packet.port) {
                deliver(harness, packet)?;
            }
            harness.settle()?;
            *replayed.sent.entry(packet.port.clone()).or_default() += 1;
        }
        let last = packets.last().map_or(first, |packet| packet.t);
        replayed.span = Some((Duration::from_nanos(first), Duration::from_nanos(last)));
        Ok(replayed)
    }
}
