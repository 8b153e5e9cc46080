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
//! A packet's bytes made with `coolbot::Bytes::loan` come from the same pool (the
//! node is the process's lender, [`PoolLender`]) and are not copied at all: the
//! outlet encodes the rest of the message on the heap and sends the loaned buffer as
//! one part of it ([`Arena::encode`]), which Zenoh moves as a descriptor to a node on
//! this host and as bytes to any other; the inlet decodes the parts in place, the
//! loaned buffer shared by the packet's `Bytes` (`coolbot::lent::lend_whole`). A
//! buffer written once is sent so by every outlet of the output: fifo connections to
//! several processes write no copy each.
//!
//! The pool is bounded (Zenoh's `transport/shared_memory/transport_optimization/
//! pool_size`, 16 MiB by default). When it is full, because consumers still hold
//! earlier messages, the outlet does not wait for them: it encodes the message on the
//! heap, and it goes by the link as to another host, counted as copied
//! ([`SharedMemoryCounts::copied`]); nothing is lost.

use std::any::Any;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock, PoisonError};
use std::time::{Duration, Instant};

use coolbot::lent::{Lender, Lent, Loan};
use serde::Serialize;
use zenoh::Wait;
use zenoh::bytes::ZBytes;
use zenoh::internal::buffers::{ZBuf, ZSlice};
use zenoh::shm::{
    Defragment, GarbageCollect, PosixShmProviderBackend, ShmProvider, ShmProviderState, ZShm,
    ZShmMut,
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
    /// another node, received in shared memory (from a node on this host): whole, or
    /// with a part in it (a loaned buffer).
    pub received: u64,
    /// Buffers of its pool lent by `coolbot::Bytes::loan` (the node is the process's
    /// lender while it is open).
    pub loaned: u64,
    /// Messages its outlets sent with a loaned buffer as it was, not copied (also
    /// counted in `shared`).
    pub in_place: u64,
    /// Messages its queue outlets wrote into a ring of a consumer on this host
    /// (`docs/distribution.md`, "Same host: a ring"), not on the link.
    pub ring_written: u64,
    /// Messages its inlets took from rings their outlets wrote.
    pub ring_taken: u64,
}

/// How long the first large message of a node waits for its session's pool to be made.
const POOL_WAIT: Duration = Duration::from_secs(5);

/// A node's counts, and its session's pool, shared by its bridges.
#[derive(Debug, Default)]
pub(crate) struct Counters {
    shared: AtomicU64,
    copied: AtomicU64,
    received: AtomicU64,
    loaned: AtomicU64,
    in_place: AtomicU64,
    ring_written: AtomicU64,
    ring_taken: AtomicU64,
    /// The session's pool, asked of the session once for the whole node.
    pool: OnceLock<Option<Arc<ShmProvider<PosixShmProviderBackend>>>>,
}

impl Counters {
    pub(crate) fn counts(&self) -> SharedMemoryCounts {
        SharedMemoryCounts {
            shared: self.shared.load(Ordering::Relaxed),
            copied: self.copied.load(Ordering::Relaxed),
            received: self.received.load(Ordering::Relaxed),
            loaned: self.loaned.load(Ordering::Relaxed),
            in_place: self.in_place.load(Ordering::Relaxed),
            ring_written: self.ring_written.load(Ordering::Relaxed),
            ring_taken: self.ring_taken.load(Ordering::Relaxed),
        }
    }

    /// An outlet wrote a message into a ring.
    pub(crate) fn ring_written(&self) {
        self.ring_written.fetch_add(1, Ordering::Relaxed);
    }

    /// An inlet took `count` messages from a ring.
    pub(crate) fn ring_taken(&self, count: usize) {
        self.ring_taken.fetch_add(count as u64, Ordering::Relaxed);
    }

    /// An inlet or a proxy's output received `payload`: refused when it is longer
    /// than `max` bytes, before anything is copied (Zenoh may hold it in fragments);
    /// else handed to `deliver` as its parts, in order (one part but for a message
    /// sent with a loaned buffer, or one Zenoh holds in fragments). A payload in
    /// shared memory is lent to its decoding ([`coolbot::lend`]): a
    /// [`coolbot::Bytes`] decoded from it shares the buffer (no copy) and keeps it
    /// from the pool while it lives; of a payload in several parts, those in shared
    /// memory are lent whole ([`coolbot::lent::lend_whole`]): a `Bytes` that is one
    /// of them (a loaned buffer) shares it. Counted when it is in shared memory, or a
    /// part of it is.
    pub(crate) fn received(
        &self,
        payload: &ZBytes,
        max: usize,
        deliver: impl FnOnce(&[&[u8]]),
    ) -> Result<(), crate::codec::Undecodable> {
        if payload.len() > max {
            return Err(crate::codec::Undecodable::TooLong {
                len: payload.len(),
                max,
            });
        }
        if let Some(buffer) = payload.as_shm() {
            self.received.fetch_add(1, Ordering::Relaxed);
            coolbot::lend(buffer.to_owned(), |bytes| deliver(&[bytes]));
            return Ok(());
        }
        if payload.slices().nth(1).is_none() {
            deliver(&[&payload.to_bytes()]);
            return Ok(());
        }
        let parts: Vec<ZSlice> = ZBuf::from(payload.clone()).zslices().cloned().collect();
        // Each part its own owner (holding a part holds nothing else of the message);
        // only parts in shared memory may be shared.
        let parts: Vec<(ZSlice, bool)> = parts
            .into_iter()
            .map(|part| {
                let shared = ZBytes::from(ZBuf::from(part.clone())).as_shm().is_some();
                (part, shared)
            })
            .collect();
        if parts.iter().any(|&(_, shared)| shared) {
            self.received.fetch_add(1, Ordering::Relaxed);
        }
        coolbot::lent::lend_whole(parts, deliver);
        Ok(())
    }

    /// `session`'s pool if it is made, without waiting (asking once for it, which
    /// starts Zenoh making it): None while it is being made, and when shared memory
    /// is off or the pool could not be made.
    fn pool_now(
        &self,
        session: &zenoh::Session,
    ) -> Option<&Arc<ShmProvider<PosixShmProviderBackend>>> {
        if let Some(pool) = self.pool.get() {
            return pool.as_ref();
        }
        match session.get_shm_provider() {
            ShmProviderState::Ready(pool) => {
                let _ = self.pool.set(Some(pool));
                self.pool.get().and_then(Option::as_ref)
            }
            _ => None,
        }
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

/// A node's pool as the process's lender (`coolbot::Bytes::loan`): while the node is
/// open, a loan is a buffer of its pool, when shared memory is on and the pool has
/// room.
pub(crate) struct PoolLender {
    /// The node's session; None once the node is dropped (the lender does not keep
    /// the session open).
    session: Mutex<Option<zenoh::Session>>,
    counters: Arc<Counters>,
}

impl PoolLender {
    /// The lender of `session`'s pool (Zenoh makes it on first use: at the first
    /// large message or loan, so that a node that sends none locks no memory for it).
    pub(crate) fn new(session: &zenoh::Session, counters: Arc<Counters>) -> PoolLender {
        PoolLender {
            session: Mutex::new(Some(session.clone())),
            counters,
        }
    }

    /// The node is dropped: no more loans from its pool.
    pub(crate) fn close(&self) {
        self.session
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .take();
    }
}

impl Lender for PoolLender {
    /// A loan smaller than [`SHARED_THRESHOLD`] is made on the heap: its message would
    /// be copied through the link anyway. Never waits: while the pool is being made
    /// (the first loan asks for it), and when it is full after a collection and a
    /// defragmentation, the loan is made on the heap.
    fn loan(&self, len: usize) -> Option<Box<dyn Loan>> {
        if len < SHARED_THRESHOLD {
            return None;
        }
        let session = self
            .session
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()?;
        let pool = self.counters.pool_now(&session)?;
        let buffer = pool
            .alloc(len)
            .with_policy::<Defragment<GarbageCollect>>()
            .wait()
            .ok()
            .filter(|buffer| buffer.len() == len)?;
        self.counters.loaned.fetch_add(1, Ordering::Relaxed);
        Some(Box::new(PoolLoan(buffer)))
    }
}

/// A buffer of a node's pool, lent to be written.
struct PoolLoan(ZShmMut);

impl Loan for PoolLoan {
    fn as_slice(&self) -> &[u8] {
        &self.0
    }

    fn as_mut_slice(&mut self) -> &mut [u8] {
        &mut self.0
    }

    fn freeze(self: Box<Self>) -> Arc<dyn Lent> {
        Arc::new(PoolLent(ZShm::from(self.0)))
    }
}

/// A buffer of a node's pool, written: what an outlet sends as it is.
struct PoolLent(ZShm);

impl AsRef<[u8]> for PoolLent {
    fn as_ref(&self) -> &[u8] {
        &self.0
    }
}

impl Lent for PoolLent {}

/// The buffer of a pool that `bytes` is, when an encoder meets a loaned `Bytes`
/// (`coolbot::lent::loan_at`) lent by a node's pool ([`PoolLender`]).
fn pool_buffer(bytes: &[u8]) -> Option<ZShm> {
    let lent = coolbot::lent::loan_at(bytes)?;
    let lent: &dyn Any = &*lent;
    lent.downcast_ref::<PoolLent>().map(|lent| lent.0.clone())
}

/// A message as its parts: bytes copied, and buffers of a pool sent as they are.
#[derive(Default)]
struct Parts {
    copied: Vec<u8>,
    writer: Option<zenoh::bytes::ZBytesWriter>,
}

impl postcard::ser_flavors::Flavor for Parts {
    type Output = Option<ZBytes>;

    fn try_push(&mut self, byte: u8) -> postcard::Result<()> {
        self.copied.push(byte);
        Ok(())
    }

    fn try_extend(&mut self, bytes: &[u8]) -> postcard::Result<()> {
        match pool_buffer(bytes) {
            Some(buffer) => {
                let writer = self.writer.get_or_insert_with(ZBytes::writer);
                writer.append(ZBytes::from(std::mem::take(&mut self.copied)));
                writer.append(ZBytes::from(buffer));
            }
            None => self.copied.extend_from_slice(bytes),
        }
        Ok(())
    }

    /// The message in parts, or None when it had no buffer of a pool (its bytes are
    /// to be encoded as one).
    fn finalize(self) -> postcard::Result<Option<ZBytes>> {
        Ok(self.writer.map(|mut writer| {
            if !self.copied.is_empty() {
                writer.append(ZBytes::from(self.copied));
            }
            writer.finish()
        }))
    }
}

/// A message's size, and whether it holds a buffer of a pool (`coolbot::Bytes::loan`)
/// as its encoder would find it.
#[derive(Default)]
struct Measure {
    size: usize,
    loaned: bool,
}

impl postcard::ser_flavors::Flavor for Measure {
    type Output = (usize, bool);

    fn try_push(&mut self, _byte: u8) -> postcard::Result<()> {
        self.size += 1;
        Ok(())
    }

    fn try_extend(&mut self, bytes: &[u8]) -> postcard::Result<()> {
        self.size += bytes.len();
        if !self.loaned && bytes.len() >= SHARED_THRESHOLD {
            self.loaned = pool_buffer(bytes).is_some();
        }
        Ok(())
    }

    fn finalize(self) -> postcard::Result<(usize, bool)> {
        Ok((self.size, self.loaned))
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

    /// `value` encoded as a message: the bytes a loaned buffer holds (a
    /// `coolbot::Bytes` made by `Bytes::loan` from a node's pool) sent as that
    /// buffer, the rest copied on the heap; else in shared memory when it is at least
    /// [`SHARED_THRESHOLD`] bytes and the pool has room, else on the heap.
    pub(crate) fn encode<P: Serialize + ?Sized>(
        &self,
        value: &P,
    ) -> Result<ZBytes, postcard::Error> {
        let (size, loaned) = coolbot::lent::encoding_loans(|| {
            postcard::serialize_with_flavor(value, Measure::default())
        })?;
        if size < SHARED_THRESHOLD {
            return Ok(crate::codec::encode(value)?.into());
        }
        if loaned {
            let parts = coolbot::lent::encoding_loans(|| {
                postcard::serialize_with_flavor(value, Parts::default())
            })?;
            if let Some(parts) = parts {
                self.counters.shared.fetch_add(1, Ordering::Relaxed);
                self.counters.in_place.fetch_add(1, Ordering::Relaxed);
                return Ok(parts);
            }
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

/// Whether `config` gives its session a pool of shared memory: shared memory on, and
/// its transport optimization (which makes the pool) on, as by Zenoh's default.
pub(crate) fn enabled(config: &zenoh::Config) -> bool {
    let on = |key: &str| {
        config
            .get_json(key)
            .map_or(true, |json| json.trim() != "false")
    };
    on("transport/shared_memory/enabled")
        && on("transport/shared_memory/transport_optimization/enabled")
}

/// Remove the shared-memory segments of this host that no process maps any more (left
/// by a process that was killed, or crashed, before it could remove its own).
///
/// Zenoh makes a segment in three steps: it creates the file (empty), takes a shared
/// lock on it, then gives it its size; every process that maps it holds a shared lock
/// too. A segment on which an exclusive lock is free is therefore either orphaned, or
/// one that another process has just created and not locked yet. Zenoh's own sweep
/// (`zenoh::shm::cleanup_orphaned_shm_segments`) tells the two apart by nothing and
/// removes both: a node opening while another process makes a segment could remove
/// it under that process, whose consumers then could never map it (each of its
/// messages lost, or shared memory off on a link). This sweep removes only a segment
/// that has its size, so was locked before: one whose creator was killed between
/// creating and sizing it stays (empty, it holds no memory).
#[cfg(target_os = "linux")]
pub(crate) fn reclaim() {
    sweep(std::path::Path::new("/dev/shm"));
}

/// [`reclaim`] in `directory`.
#[cfg(target_os = "linux")]
fn sweep(directory: &std::path::Path) {
    let Ok(entries) = std::fs::read_dir(directory) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        let zenohs = path
            .extension()
            .is_some_and(|extension| extension == "zenoh")
            && path
                .file_stem()
                .and_then(|stem| stem.to_str())
                .is_some_and(|stem| stem.parse::<u64>().is_ok());
        // A file, not a link to one (the directory is anyone's to write in).
        let file = entry.file_type().is_ok_and(|kind| kind.is_file());
        if !zenohs || !file {
            continue;
        }
        // Its size read and its lock tried through one descriptor, so both are of
        // the same file. (A segment of another user's does not open: it stays.)
        let Ok(file) = std::fs::File::open(&path) else {
            continue;
        };
        let sized = file.metadata().is_ok_and(|metadata| metadata.len() > 0);
        if sized && file.try_lock().is_ok() {
            // Held while it is removed: no process maps it, and none can start to.
            let _ = std::fs::remove_file(&path);
        }
    }
}

/// Elsewhere a killed process's segments stay (`docs/distribution.md`, "Limits").
#[cfg(not(target_os = "linux"))]
pub(crate) fn reclaim() {}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use std::fs::File;
    use std::path::{Path, PathBuf};

    /// A segment file of `size` bytes in `directory`.
    fn segment(directory: &Path, id: u64, size: u64) -> (PathBuf, File) {
        let path = directory.join(format!("{id}.zenoh"));
        let file = File::options()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&path)
            .expect("the segment is made");
        file.set_len(size).expect("sized");
        (path, file)
    }

    #[test]
    fn a_sweep_removes_a_sized_segment_nobody_locks_and_leaves_one_being_made() {
        // A directory of its own, where no other sweep on this host looks.
        let directory = std::env::temp_dir().join(format!("coolbot-sweep-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&directory);
        std::fs::create_dir_all(&directory).expect("the directory");
        // Left by a killed process: sized, its descriptor closed, so no lock.
        let (orphan, file) = segment(&directory, 1, 4096);
        drop(file);
        // Mapped by a live process: it holds a shared lock.
        let (mapped, held) = segment(&directory, 2, 4096);
        held.lock_shared().expect("a shared lock");
        // Being made: created, not locked nor sized yet.
        let (made, making) = segment(&directory, 3, 0);
        // Not a segment's name: never touched.
        let (other, _) = segment(&directory, 4, 4096);
        let other_name = directory.join("other.zenoh");
        std::fs::rename(&other, &other_name).expect("renamed");
        super::sweep(&directory);
        let left = [&orphan, &mapped, &made, &other_name].map(|path| path.exists());
        drop((held, making));
        let _ = std::fs::remove_dir_all(&directory);
        assert_eq!(
            left,
            [false, true, true, true],
            "the orphan removed; the segment in use, the one being made and the other file left"
        );
    }
}
