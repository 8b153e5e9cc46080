//! What the recorder's parts share: the recording's start on its clock, its
//! channels, and the MCAP writer.

use std::fs::File;
use std::io::BufWriter;
use std::time::Instant;

use crate::clock::Clock;

/// The start of a recording on its clock.
#[derive(Clone)]
pub(super) struct Start {
    pub(super) clock: Clock,
    pub(super) at: Instant,
}

impl Start {
    pub(super) fn on(clock: Clock) -> Start {
        Start {
            at: clock.now(),
            clock,
        }
    }

    /// Nanoseconds since the start.
    pub(super) fn since(&self) -> u64 {
        nanos(self.clock.now().saturating_duration_since(self.at))
    }
}

/// A channel of the recording: its id, and how its messages are written.
#[derive(Debug, Clone, Copy)]
pub(super) struct Channel {
    pub(super) id: u16,
    /// JSON, wrapped in `{"value": ...}`.
    pub(super) wrapped: bool,
    /// CDR (a rosbag2 recording's channel).
    pub(super) cdr: bool,
}

/// The MCAP writer of a recording.
pub(super) type McapWriter = mcap::Writer<BufWriter<File>>;

pub(super) use crate::time::nanos;
