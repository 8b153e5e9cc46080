//! Replaying a recording into a running system: [`Player`].

use std::any::TypeId;
use std::collections::BTreeMap;
use std::path::Path;
use std::time::{Duration, Instant};

use serde::de::DeserializeOwned;

use super::paths::{find_input, known};
use super::{Header, PacketRecord, ReadError, Reader, Record, RecordError};
use crate::port::{DataOut, ErasedInput, ErasedOutput, InKind, Packet, TickOut};
use crate::system::System;

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
    pub(super) reader: Reader,
    pub(super) routes: BTreeMap<String, Box<dyn Route>>,
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

    pub(super) fn check_route(&self, recorded: &str) -> Result<(), RecordError> {
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
pub(super) trait Route: Send {
    fn send(&self, packet: &PacketRecord) -> Result<(), ReadError>;
}

pub(super) struct Routed<T: Packet> {
    pub(super) out: DataOut<T>,
    pub(super) erased: ErasedOutput,
    pub(super) target: ErasedInput,
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

pub(super) struct RoutedTicks {
    pub(super) out: TickOut,
    pub(super) erased: ErasedOutput,
    pub(super) target: ErasedInput,
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
