//! How a bridge key's messages reach what delivers them: the one signature shared by
//! inlets, proxies' outputs and rings (`crate::bridge`, `crate::place`,
//! `crate::nearby`).

use std::sync::Arc;

use zenoh::bytes::ZBytes;

/// What delivers one message of a bridge key, and how it came: it takes the payload
/// as Zenoh holds it, and checks its length before copying or decoding it.
pub(crate) type DeliverFn = Arc<dyn Fn(&ZBytes, Via) + Send + Sync>;

/// What decodes and delivers one message this process already holds, its parts in
/// order: what a [`DeliverFn`] calls once it has taken Zenoh's payload apart, and what
/// a ring's messages go to directly (no payload made for them). It checks the length
/// against its bound before decoding.
pub(crate) type DecodeFn = Arc<dyn Fn(&[&[u8]], Via) + Send + Sync>;

/// How a message reached an inlet: on the key's stream or a ring (numbered, counted
/// by the ledger), or as the answer to a query (the current value of a `last` or poster
/// outlet, or a pull), which the ledger does not count.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Via {
    /// The key's numbered stream.
    Stream,
    /// A ring of the same messages, from an outlet of this host (`crate::nearby`).
    Ring,
    /// The last messages of a ring handed over to a new consumer, taken after it
    /// closed: the outlet may have sent newer ones on the key meanwhile.
    HandedOver,
    /// The current value of a `last` or poster outlet, on Zenoh's receiving thread.
    Answer,
    /// The answer to a pull request, on the inlet's (or proxy's) own thread while it
    /// answers the request: sent to the requesting input alone, at once.
    Pull,
}

impl Via {
    /// Whether the message is one of the stream's numbered messages, which the
    /// ledger counts (the key's, or a ring's).
    pub(crate) fn counted(self) -> bool {
        matches!(self, Via::Stream | Via::Ring | Via::HandedOver)
    }
}
