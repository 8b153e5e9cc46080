//! The same-host path of a queue bridge (`docs/distribution.md`, "Same host: a
//! ring"): when a fifo or ufifo outlet and its inlet are in two processes of one
//! host (or one process), the outlet writes its numbered messages into a
//! [`coolbot::ring::Ring`] the inlet made, and rings the consumer's doorbell
//! ([`coolbot::RemoteBell`]); the consumer's own thread takes them (a
//! [`coolbot::Source`]) and hands each to the inlet's delivery, as if it had come on
//! the key: the same numbering, ledger, losses and backlog. No TCP, no Zenoh thread,
//! and, for a fifo, no wake-up of the outlet's thread: a packet the outlet's input
//! takes on the producer's thread ([`coolbot::port::Intake`]) is in the consumer's
//! input after one futex wake.
//!
//! **How the path is found.** The outlet asks `K/@ring/**` (a query carrying its host's
//! boot id, its epoch, the number it has sent, and its own doorbell); an inlet on the
//! same host makes a ring, adds the source to its consumer's bell and answers with
//! both addresses. The answer comes on a Zenoh thread and is adopted by whichever of
//! the outlet's paths sends next; until then, and whenever the ring is not usable,
//! messages go on the key as before.
//!
//! **Order.** Messages sent on the key after the question may still be on their way
//! when the first goes into the ring: the consumer takes a ring message only once the
//! key's message before it is in the consumer's input (or a second has passed: a
//! link that broke lost it, the ledger counts it, and a key message that still comes
//! after is dropped by the inlet's `Delivered`). A message longer than a quarter of
//! the ring sends the stream back to the key for good, once the consumer has taken
//! everything in the ring. When the ring is full, the outlet leaves the packets at its
//! input (whose overflow policy applies, as for a slow consumer in one process) and
//! asks the consumer to ring it when it has taken.
//!
//! **Ends.** A consumer whose inlet closed its ring is seen by the outlet at its next
//! write, one whose process ended within 20 ms of writing (or when the ring is
//! full): the stream goes back to the key (the messages left in the ring are lost,
//! and counted as a gone inlet's are: `crate::ledger`), and the outlet asks again
//! later. A producer that ends leaves the consumer its ring, replaced when that
//! outlet asks again, and bounded in number per inlet.
//!
//! `outlet` is the producer's side (asking, writing, falling back to the key),
//! `inlet` the consumer's (the rings, their gates, the answers), `wire` what they
//! say to each other.

mod inlet;
mod outlet;
mod wire;

pub(crate) use inlet::{InletParts, InletRings, NewestFn};
pub(crate) use outlet::{Held, Inline, Link, Nearby, Parts, Queue, SameHost};
