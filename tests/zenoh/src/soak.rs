//! What the accounting soaks (`tests/accounting.rs`) stream: poses, small and many, or
//! chunks of 4 MiB at 30 Hz, which two processes on one host pass through shared memory. The
//! soak's processes (`inlet-under-test`, `outlet-under-test`) take `chunks` as an
//! argument to stream chunks.

use coolbot::crossbeam_channel::Sender;
use coolbot::port::{DataOut, UfifoIn};
use coolbot::{Component, InputKind, OverflowPolicy, Packet};

use crate::generated::types::{Chunk, Pose};
use crate::generated::{chunk_queue, growing_queue, pose_source, shm_source};
use crate::support::Hand;

/// The size of a chunk: large, as a camera's image is.
pub const CHUNK: usize = 4 << 20;

/// A packet a soak streams, numbered from 1.
pub trait Streamed: Packet + serde::Serialize + serde::de::DeserializeOwned {
    /// The argument that makes a soak process stream this packet.
    const ARG: &'static str;
    /// Packets a producer sends between two pauses, and the pause (so that the
    /// outlet's thread keeps up).
    const BURST: u64;
    const PAUSE: std::time::Duration;
    /// How an outlet takes them: poses in a growing queue; chunks in a queue of four
    /// that drops the oldest (counted at the outlet) while a put waits on a killed
    /// consumer, rather than holding gigabytes.
    const OUTLET: InputKind;
    /// Packet number `seq`.
    fn numbered(seq: u64) -> Self;
    /// Its number.
    fn seq(&self) -> u64;
    /// Whether it is what [`Streamed::numbered`] made of its number.
    fn intact(&self) -> bool;
    /// A component named `name` whose output `out` of this packet is handed over
    /// through `hand` when it starts.
    fn source(name: &str, hand: Sender<DataOut<Self>>) -> Component;
    /// A component named `name` whose growing queue `input` of this packet is handed
    /// over through `hand` when it starts.
    fn queue(name: &str, hand: Sender<UfifoIn<Self>>) -> Component;
}

impl Streamed for Pose {
    const ARG: &'static str = "poses";
    const BURST: u64 = 64;
    const PAUSE: std::time::Duration = std::time::Duration::from_micros(500);
    const OUTLET: InputKind = InputKind::Ufifo {
        initial: 64,
        max: Some(1 << 20),
    };

    fn numbered(seq: u64) -> Pose {
        Pose { x: seq as f64, seq }
    }

    fn seq(&self) -> u64 {
        self.seq
    }

    fn intact(&self) -> bool {
        self.x == self.seq as f64
    }

    fn source(name: &str, hand: Sender<DataOut<Pose>>) -> Component {
        pose_source::component(name, Hand(hand))
    }

    fn queue(name: &str, hand: Sender<UfifoIn<Pose>>) -> Component {
        growing_queue::component(name, Hand(hand))
    }
}

impl Streamed for Chunk {
    const ARG: &'static str = "chunks";
    const BURST: u64 = 1;
    /// 30 a second, as a camera's images.
    const PAUSE: std::time::Duration = std::time::Duration::from_millis(33);
    const OUTLET: InputKind = InputKind::Fifo {
        capacity: 4,
        policy: OverflowPolicy::DropOldest,
    };

    fn numbered(seq: u64) -> Chunk {
        Chunk {
            number: seq,
            bytes: vec![seq as u8; CHUNK],
        }
    }

    fn seq(&self) -> u64 {
        self.number
    }

    fn intact(&self) -> bool {
        self.bytes.len() == CHUNK && self.bytes.iter().all(|&b| b == self.number as u8)
    }

    fn source(name: &str, hand: Sender<DataOut<Chunk>>) -> Component {
        shm_source::component(name, Hand(hand))
    }

    fn queue(name: &str, hand: Sender<UfifoIn<Chunk>>) -> Component {
        chunk_queue::component(name, Hand(hand))
    }
}
