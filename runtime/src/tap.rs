//! Taps: a copy of every packet a data or poster output sends, into a bounded queue
//! an observer reads (`coolctl echo` through `coolbot-zenoh`, a live display). A tap
//! is one more sink of the output, as the recorder's are ([`crate::record`]), not a
//! connection. Each packet is stamped with the wall-clock time it was sent, read on
//! the producer's thread as it sends. **Invariant:** a tap never blocks its producer:
//! a packet that finds the queue full is dropped for the tap only, and counted
//! ([`Tap::dropped`]).

use std::any::TypeId;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use crossbeam_channel::{Receiver, Sender};

use crate::handle::Handle;
use crate::port::{Deliver, ErasedOutput, OutKind, Packet, Parcel};
use crate::value::Time;

/// Why [`Tap::attach`] failed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TapError {
    /// The component has no output of that name.
    #[error("`{component}` has no output `{port}` (its outputs: {known})")]
    UnknownPort {
        /// The component.
        component: String,
        /// The port asked for.
        port: String,
        /// The outputs it has.
        known: String,
    },
    /// A tick output (it carries no packets).
    #[error("`{component}.{port}` is a tick output: it carries no packets to tap")]
    Tick {
        /// The component.
        component: String,
        /// The port.
        port: String,
    },
    /// The output's packets are of another type.
    #[error("`{component}.{port}` sends {actual}, not {requested}")]
    TypeMismatch {
        /// The component.
        component: String,
        /// The port.
        port: String,
        /// Its packet type.
        actual: &'static str,
        /// The type asked for.
        requested: &'static str,
    },
}

/// What a tap counted.
#[derive(Debug, Default)]
struct Counts {
    sent: AtomicU64,
    dropped: AtomicU64,
}

struct Sink<T> {
    sender: Sender<(u64, Time, T)>,
    counts: Arc<Counts>,
}

impl<T: Packet> Deliver<T> for Sink<T> {
    fn deliver(&self, packet: Parcel<T>) {
        let seq = self.counts.sent.fetch_add(1, Ordering::AcqRel);
        if self
            .sender
            .try_send((seq, Time::now(), packet.into_owned()))
            .is_err()
        {
            self.counts.dropped.fetch_add(1, Ordering::AcqRel);
        }
    }
}

/// A copy of every packet an output sends from now on, up to `capacity` waiting.
/// Dropping it removes it from the output.
pub struct Tap<T> {
    output: ErasedOutput,
    id: usize,
    receiver: Receiver<(u64, Time, T)>,
    counts: Arc<Counts>,
}

impl<T> std::fmt::Debug for Tap<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Tap({:?})", self.output)
    }
}

impl<T: Packet> Tap<T> {
    /// Tap output `port` of the component behind `handle`, whose packets are `T`;
    /// at most `capacity` (at least 1) packets wait in the tap's queue.
    pub fn attach(handle: &Handle, port: &str, capacity: usize) -> Result<Tap<T>, TapError> {
        let Some(output) = handle
            .outputs
            .iter()
            .find(|(name, _)| *name == port)
            .map(|(_, output)| output.clone())
        else {
            let known: Vec<&str> = handle.outputs.iter().map(|(name, _)| *name).collect();
            return Err(TapError::UnknownPort {
                component: handle.name().to_owned(),
                port: port.to_owned(),
                known: if known.is_empty() {
                    "none".to_owned()
                } else {
                    known.join(", ")
                },
            });
        };
        if output.kind == OutKind::Tick {
            return Err(TapError::Tick {
                component: handle.name().to_owned(),
                port: port.to_owned(),
            });
        }
        let mismatch = || TapError::TypeMismatch {
            component: handle.name().to_owned(),
            port: port.to_owned(),
            actual: output.type_name,
            requested: std::any::type_name::<T>(),
        };
        if output.type_id != TypeId::of::<T>() {
            return Err(mismatch());
        }
        let (sender, receiver) = crossbeam_channel::bounded(capacity.max(1));
        let counts = Arc::new(Counts::default());
        let sink = Arc::new(Sink {
            sender,
            counts: Arc::clone(&counts),
        });
        let id = crate::port::tap_data::<T>(&output, sink).ok_or_else(mismatch)?;
        Ok(Tap {
            output,
            id,
            receiver,
            counts,
        })
    }

    /// The queue of tapped packets, each with its sequence number (0 for the first
    /// packet sent after the tap was attached: a gap is packets dropped for the tap)
    /// and when the output sent it.
    pub fn receiver(&self) -> &Receiver<(u64, Time, T)> {
        &self.receiver
    }

    /// Packets the output sent since the tap was attached.
    pub fn sent(&self) -> u64 {
        self.counts.sent.load(Ordering::Acquire)
    }

    /// Of those, the packets dropped for the tap because its queue was full.
    pub fn dropped(&self) -> u64 {
        self.counts.dropped.load(Ordering::Acquire)
    }
}

impl<T> Drop for Tap<T> {
    fn drop(&mut self) {
        crate::port::unforward(&self.output, self.id);
    }
}
