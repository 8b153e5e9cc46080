//! Same host: large messages in shared memory (`docs/distribution.md`, "Same host:
//! shared memory").
//!
//! Zenoh finds out, link by link when two sessions connect, whether the other end can
//! map this host's shared memory (both have it enabled, and a probe segment one side
//! writes is read by the other). On such a link a buffer of shared memory travels as
//! a descriptor of a few bytes; on any other link Zenoh sends the buffer's bytes, as it
//! sends any payload. So an outlet writes each numbered message of at least
//! [`SHARED_THRESHOLD`] bytes straight into a buffer of its session's shared-memory
//! pool (postcard encodes into the buffer: the one copy of the payload on the
//! producer's side), and an inlet on the same host decodes it in place, then drops
//! it, which frees the buffer; a `coolbot::Bytes` in the packet is not copied but
//! shares the buffer, lent to the decoding (`coolbot::lend`), and keeps it from the
//! pool while the packet lives.
//!
//! The pool is bounded (Zenoh's `transport/shared_memory/transport_optimization/
//! pool_size`, 16 MiB by default). When it is full, because consumers still hold
//! earlier messages, the outlet does not wait for them: it encodes the message on the
//! heap, and it goes by the link as to another host, counted as copied
//! ([`SharedMemoryCounts::copied`]); nothing is lost.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

use serde::Serialize;
use zenoh::Wait;
use zenoh::bytes::ZBytes;
use zenoh::shm::{
    Defragment, GarbageCollect, PosixShmProviderBackend, ShmProvider, ShmProviderState,
};

/// The smallest message an outlet writes into shared memory: below it, a message
/// costs less to copy through the link than a buffer costs to allocate and free.
pub const SHARED_THRESHOLD: usize = 4096;

/// What a node's bridges did with shared memory ([`crate::Node::shared_memory`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SharedMemoryCounts {
    /// Messages its outlets wrote into shared memory.
    pub shared: u64,
    /// Messages of at least [`SHARED_THRESHOLD`] bytes its outlets encoded on the heap
    /// instead, because the pool was full (or shared memory is off): sent over the link
    /// all the same, not lost.
    pub copied: u64,
    /// Messages its inlets, and the outputs of the proxies of its instances placed on
    /// another node, received in shared memory (from a node on this host).
    pub received: u64,
}

/// How long the first large message of a node waits for its session's pool to be made.
const POOL_WAIT: Duration = Duration::from_secs(5);

/// A node's counts, and its session's pool, shared by its bridges.
#[derive(Debug, Default)]
pub(crate) struct Counters {
    shared: AtomicU64,
    copied: AtomicU64,
    received: AtomicU64,
    /// The session's pool, asked of the session once for the whole node.
    pool: OnceLock<Option<Arc<ShmProvider<PosixShmProviderBackend>>>>,
}

impl Counters {
    pub(crate) fn counts(&self) -> SharedMemoryCounts {
        SharedMemoryCounts {
            shared: self.shared.load(Ordering::Relaxed),
            copied: self.copied.load(Ordering::Relaxed),
            received: self.received.load(Ordering::Relaxed),
        }
    }

    /// An inlet or a proxy's output received `payload`: refused when it is longer
    /// than `max` bytes, before anything is copied (Zenoh may hold it in fragments);
    /// else counted when it is in shared memory, and handed to `deliver`. A payload
    /// in shared memory is lent to its decoding ([`coolbot::lend`]): a
    /// [`coolbot::Bytes`] decoded from it shares the buffer (no copy) and keeps it
    /// from the pool while it lives.
    pub(crate) fn received(
        &self,
        payload: &ZBytes,
        max: usize,
        deliver: impl FnOnce(&[u8]),
    ) -> Result<(), crate::codec::Undecodable> {
        if payload.len() > max {
            return Err(crate::codec::Undecodable::TooLong {
                len: payload.len(),
                max,
            });
        }
        match payload.as_shm() {
            Some(buffer) => {
                self.received.fetch_add(1, Ordering::Relaxed);
                coolbot::lend(buffer.to_owned(), deliver);
            }
            None => deliver(&payload.to_bytes()),
        }
        Ok(())
    }

    /// `session`'s pool (Zenoh makes it on first use, and the node's first large
    /// message waits for it, at most [`POOL_WAIT`]): None when shared memory is off or
    /// the pool could not be made (memory that cannot be locked, `ulimit -l`).
    ///
    /// The node asks once, and asks by polling: Zenoh 1.10 hands the pool it is making
    /// to one blocking waiter only, and leaves its own state waiting for good, so that
    /// any later asker (another outlet of the node, Zenoh's own transport) would be
    /// told there is none.
    fn pool(&self, session: &zenoh::Session) -> Option<&Arc<ShmProvider<PosixShmProviderBackend>>> {
        self.pool
            .get_or_init(|| {
                let deadline = Instant::now() + POOL_WAIT;
                loop {
                    match session.get_shm_provider() {
                        ShmProviderState::Ready(pool) => return Some(pool),
                        ShmProviderState::Initializing(_) if Instant::now() < deadline => {
                            std::thread::sleep(Duration::from_millis(1));
                        }
                        ShmProviderState::Initializing(_) => {
                            tracing::warn!(
                                "no shared-memory pool after {POOL_WAIT:?}: large messages go over the link"
                            );
                            return None;
                        }
                        ShmProviderState::Disabled | ShmProviderState::Error => return None,
                    }
                }
            })
            .as_ref()
    }
}

/// An outlet's way into its session's shared memory (the node's pool).
pub(crate) struct Arena {
    session: zenoh::Session,
    counters: Arc<Counters>,
}

impl Arena {
    pub(crate) fn new(session: &zenoh::Session, counters: Arc<Counters>) -> Arena {
        Arena {
            session: session.clone(),
            counters,
        }
    }

    /// `value` encoded as a message: in shared memory when it is at least
    /// [`SHARED_THRESHOLD`] bytes and the pool has room, else on the heap.
    pub(crate) fn encode<P: Serialize + ?Sized>(
        &self,
        value: &P,
    ) -> Result<ZBytes, postcard::Error> {
        let size = postcard::serialize_with_flavor(value, postcard::ser_flavors::Size::default())?;
        if size < SHARED_THRESHOLD {
            return Ok(crate::codec::encode(value)?.into());
        }
        let buffer = self.counters.pool(&self.session).and_then(|provider| {
            // Never waits: a full pool is collected and defragmented once, then the
            // message goes on the heap.
            provider
                .alloc(size)
                .with_policy::<Defragment<GarbageCollect>>()
                .wait()
                .ok()
        });
        match buffer {
            Some(mut buffer) => {
                postcard::to_slice(value, &mut buffer)?;
                self.counters.shared.fetch_add(1, Ordering::Relaxed);
                Ok(buffer.into())
            }
            None => {
                self.counters.copied.fetch_add(1, Ordering::Relaxed);
                Ok(crate::codec::encode(value)?.into())
            }
        }
    }
}

/// Remove the shared-memory segments of this host that no process maps any more (left
/// by a process that was killed, or crashed, before it could remove its own).
pub(crate) fn reclaim() {
    zenoh::shm::cleanup_orphaned_shm_segments();
}
