//! A queue of messages from one process to another on this host, in shared memory:
//! the reading process makes a [`Ring`] and hands its [`RingAddress`] to the writing
//! process, which opens it ([`RingWriter::open`]) and writes length-prefixed
//! messages into it. One writer and one reader; neither waits on the other (a full
//! ring refuses a message, an empty one has nothing to take), and each asks the
//! other to be woken through whatever bell the two agreed on ([`RemoteBell`]): the
//! writer rings the reader after it writes, and the reader tells its caller when the
//! writer asked to be rung because it found the ring full
//! ([`RingWriter::ask_to_be_rung`], [`Taken::writer_waits`]).
//!
//! Neither side trusts the other's words: the reader checks every length and
//! position the writer left before it copies a message out (a ring that breaks the
//! layout is [`RingError::Malformed`], and is then closed), and the writer checks the
//! reader's position. The memory is a sealed memfd of the reader's process: when
//! both have unmapped it (or ended) it is gone, whoever ended first.
//!
//! [`RemoteBell`]: crate::RemoteBell

use std::sync::atomic::{AtomicU64, Ordering};

use crate::mapping::Mapping;

/// Header words; messages start at word [`DATA`].
const MAGIC_AT: usize = 0;
const NONCE_AT: usize = 1;
const CAPACITY_AT: usize = 2;
/// The writer's position (bytes written since the start), alone on a cache line.
const HEAD_AT: usize = 8;
/// The reader's position, alone on a cache line.
const TAIL_AT: usize = 16;
/// 1 while the writer waits to be rung.
const WAITING_AT: usize = 24;
/// 1 once the reader dropped the ring.
const CLOSED_AT: usize = 25;
const DATA: usize = 32;

/// Names the layout (and its version).
const MAGIC: u64 = 0xC001_B070_0000_0001;

/// A message's first word when the rest of the ring to its end is unused: the
/// message is at the start.
const SKIP: u64 = u64::MAX;

/// The smallest and largest rings.
const MIN_CAPACITY: usize = 4096;
const MAX_CAPACITY: usize = 1 << 30;

/// Where a writer in another process on this host finds a [`Ring`]: the reader's
/// process, its descriptor of the ring's memory, the nonce in the ring's header, and
/// the ring's size. Plain numbers, to pass in any message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct RingAddress {
    /// The reading process.
    pub pid: u32,
    /// Its descriptor of the ring (`/proc/<pid>/fd/<fd>`).
    pub fd: i32,
    /// The nonce in the ring's header.
    pub nonce: u64,
    /// The bytes messages take in it.
    pub capacity: u64,
}

/// Why a ring was not taken from.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RingError {
    /// The writer broke the layout (a length or a position out of bounds): the
    /// messages not yet taken are dropped, and the ring is closed.
    #[error("the ring's writer broke its layout ({0}); its messages are dropped")]
    Malformed(&'static str),
}

/// What [`Ring::take`] took.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Taken {
    /// Messages handed to the caller.
    pub messages: usize,
    /// The writer found the ring full and asked to be rung: ring it.
    pub writer_waits: bool,
}

/// Why a [`RingWriter`] did not write a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum WriteError {
    /// No room now: ask to be rung ([`RingWriter::ask_to_be_rung`]) and try again.
    #[error("the ring is full")]
    Full,
    /// Longer than [`RingWriter::max_message`].
    #[error("the message is longer than the ring takes")]
    TooLong,
    /// The reader closed the ring, or left it in a state no reader leaves.
    #[error("the ring's reader is gone")]
    Gone,
}

fn words_for(len: usize) -> usize {
    1 + len.div_ceil(8)
}

/// The reading end, in the process that made it. Closed when dropped: the writer
/// sees it ([`RingWriter::is_gone`]).
pub struct Ring {
    shared: Mapping,
    nonce: u64,
    capacity: usize,
    /// Where a message is copied out before it is handed on.
    scratch: Vec<u8>,
}

impl std::fmt::Debug for Ring {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Ring")
            .field("capacity", &self.capacity)
            .finish_non_exhaustive()
    }
}

impl Ring {
    /// A ring of `capacity` bytes of messages (rounded up to a power of two, at least
    /// 4 KiB): an error where no shared memory can be made (not Linux).
    pub fn new(capacity: usize) -> std::io::Result<Ring> {
        let capacity = capacity
            .clamp(MIN_CAPACITY, MAX_CAPACITY)
            .next_power_of_two();
        let shared = Mapping::create("coolbot-ring", DATA * 8 + capacity)?;
        let nonce = crate::mapping::nonce();
        let words = shared.u64s();
        words[NONCE_AT].store(nonce, Ordering::Relaxed);
        words[CAPACITY_AT].store(capacity as u64, Ordering::Relaxed);
        words[MAGIC_AT].store(MAGIC, Ordering::SeqCst);
        Ok(Ring {
            shared,
            nonce,
            capacity,
            scratch: Vec::new(),
        })
    }

    /// Where a writer in another process finds it.
    pub fn address(&self) -> Option<RingAddress> {
        Some(RingAddress {
            pid: std::process::id(),
            fd: self.shared.fd()?,
            nonce: self.nonce,
            capacity: self.capacity as u64,
        })
    }

    fn words(&self) -> &[AtomicU64] {
        self.shared.u64s()
    }

    /// Whether the writer never wrote into it.
    pub fn is_unused(&self) -> bool {
        self.words()[HEAD_AT].load(Ordering::Acquire) == 0
    }

    /// Whether a message waits to be taken.
    pub fn has_messages(&self) -> bool {
        let words = self.words();
        words[HEAD_AT].load(Ordering::Acquire) != words[TAIL_AT].load(Ordering::Relaxed)
    }

    /// Hand each waiting message to `each`, oldest first, and make its room the
    /// writer's again; a message `each` declines (false) is left, with those after
    /// it, for the next take. A message is copied out of the shared memory before
    /// `each` sees it (the writer cannot change it under the caller).
    pub fn take(&mut self, mut each: impl FnMut(&[u8]) -> bool) -> Result<Taken, RingError> {
        let capacity = self.capacity as u64;
        let mut scratch = std::mem::take(&mut self.scratch);
        let words = self.shared.u64s();
        let mut taken = Taken::default();
        let mut tail = words[TAIL_AT].load(Ordering::Relaxed);
        let head = words[HEAD_AT].load(Ordering::Acquire);
        let result = loop {
            if head.wrapping_sub(tail) > capacity {
                break Err(RingError::Malformed("its position is out of the ring"));
            }
            if tail == head {
                break Ok(());
            }
            let offset = (tail % capacity) as usize;
            let first = words[DATA + offset / 8].load(Ordering::Relaxed);
            let to_end = capacity - offset as u64;
            if first == SKIP {
                tail = tail.wrapping_add(to_end);
                continue;
            }
            let len = first as usize;
            if len > self.capacity / 4 || (words_for(len) * 8) as u64 > to_end {
                break Err(RingError::Malformed(
                    "a message's length is out of the ring",
                ));
            }
            if (words_for(len) * 8) as u64 > head.wrapping_sub(tail) {
                break Err(RingError::Malformed(
                    "a message runs past its writer's position",
                ));
            }
            scratch.clear();
            let start = DATA + offset / 8 + 1;
            for word in &words[start..start + len.div_ceil(8)] {
                scratch.extend_from_slice(&word.load(Ordering::Relaxed).to_le_bytes());
            }
            scratch.truncate(len);
            if !each(&scratch) {
                break Ok(());
            }
            tail = tail.wrapping_add((words_for(len) * 8) as u64);
            words[TAIL_AT].store(tail, Ordering::Release);
            taken.messages += 1;
        };
        self.scratch = scratch;
        match result {
            Ok(()) => {
                words[TAIL_AT].store(tail, Ordering::SeqCst);
                // After the position is stored: a writer that asked before it looked
                // at the position (`ask_to_be_rung`) is seen here, or saw the room.
                taken.writer_waits = words[WAITING_AT].swap(0, Ordering::SeqCst) == 1;
                Ok(taken)
            }
            Err(error) => {
                words[TAIL_AT].store(words[HEAD_AT].load(Ordering::Acquire), Ordering::SeqCst);
                words[CLOSED_AT].store(1, Ordering::SeqCst);
                Err(error)
            }
        }
    }
}

impl Ring {
    /// Close it: the writer sees it ([`RingWriter::is_closed`]) and writes no more.
    pub fn close(&self) {
        self.words()[CLOSED_AT].store(1, Ordering::SeqCst);
    }
}

impl Drop for Ring {
    fn drop(&mut self) {
        self.close();
    }
}

/// The writing end, in another process on the host (or the same one).
pub struct RingWriter {
    shared: Mapping,
    capacity: usize,
    reader: u32,
}

impl std::fmt::Debug for RingWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RingWriter")
            .field("capacity", &self.capacity)
            .field("reader", &self.reader)
            .finish_non_exhaustive()
    }
}

impl RingWriter {
    /// Map the ring `address` names and check that it is that one (its nonce and
    /// size): an error if the process is gone, is another one, or does not let this
    /// one map its memory, or not on Linux.
    pub fn open(address: &RingAddress) -> std::io::Result<RingWriter> {
        let capacity = usize::try_from(address.capacity).unwrap_or(usize::MAX);
        if !(MIN_CAPACITY..=MAX_CAPACITY).contains(&capacity) || !capacity.is_power_of_two() {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!("no ring has {capacity} bytes"),
            ));
        }
        let shared = Mapping::open(address.pid, address.fd, DATA * 8 + capacity)?;
        let words = shared.u64s();
        if words[MAGIC_AT].load(Ordering::SeqCst) != MAGIC
            || words[NONCE_AT].load(Ordering::Relaxed) != address.nonce
            || words[CAPACITY_AT].load(Ordering::Relaxed) != address.capacity
        {
            return Err(std::io::Error::new(
                std::io::ErrorKind::NotFound,
                "the shared memory is not the ring it was said to be (another process)",
            ));
        }
        Ok(RingWriter {
            shared,
            capacity,
            reader: address.pid,
        })
    }

    /// The longest message it takes: a quarter of the ring.
    pub fn max_message(&self) -> usize {
        self.capacity / 4
    }

    /// Write `message` (then ring the reader).
    pub fn write(&mut self, message: &[u8]) -> Result<(), WriteError> {
        if message.len() > self.max_message() {
            return Err(WriteError::TooLong);
        }
        let capacity = self.capacity as u64;
        let words = self.shared.u64s();
        if self.is_closed() {
            return Err(WriteError::Gone);
        }
        let mut head = words[HEAD_AT].load(Ordering::Relaxed);
        let tail = words[TAIL_AT].load(Ordering::Acquire);
        let used = head.wrapping_sub(tail);
        if used > capacity {
            return Err(WriteError::Gone);
        }
        let need = (words_for(message.len()) * 8) as u64;
        let offset = head % capacity;
        let to_end = capacity - offset;
        let total = if to_end < need { to_end + need } else { need };
        if capacity - used < total {
            return Err(WriteError::Full);
        }
        if to_end < need {
            words[DATA + (offset / 8) as usize].store(SKIP, Ordering::Relaxed);
            head = head.wrapping_add(to_end);
        }
        let start = DATA + ((head % capacity) / 8) as usize;
        words[start].store(message.len() as u64, Ordering::Relaxed);
        for (word, chunk) in words[start + 1..].iter().zip(message.chunks(8)) {
            let mut bytes = [0u8; 8];
            bytes[..chunk.len()].copy_from_slice(chunk);
            word.store(u64::from_le_bytes(bytes), Ordering::Relaxed);
        }
        words[HEAD_AT].store(head.wrapping_add(need), Ordering::SeqCst);
        Ok(())
    }

    /// Whether the reader took every message written.
    pub fn is_empty(&self) -> bool {
        let words = self.shared.u64s();
        words[HEAD_AT].load(Ordering::Relaxed) == words[TAIL_AT].load(Ordering::SeqCst)
    }

    /// Ask the reader to say, after it next takes, that this writer waits
    /// ([`Taken::writer_waits`]). Look at the ring again after asking (room may have
    /// been made in between, by a take that did not see the request).
    pub fn ask_to_be_rung(&self) {
        self.shared.u64s()[WAITING_AT].store(1, Ordering::SeqCst);
        // The request before any later look at the reader's position (a store then
        // a load: only a full fence orders them).
        std::sync::atomic::fence(Ordering::SeqCst);
    }

    /// Whether the reader closed the ring (a look at one word).
    pub fn is_closed(&self) -> bool {
        self.shared.u64s()[CLOSED_AT].load(Ordering::Acquire) != 0
    }

    /// Whether the reader closed the ring or its process ended (a system call).
    pub fn is_gone(&self) -> bool {
        if self.is_closed() {
            return true;
        }
        process_ended(self.reader)
    }
}

/// Whether the process `pid` of this host has ended (a system call: a signal 0; a
/// process of another user counts as running). Never on other platforms than Linux.
pub fn process_ended(pid: u32) -> bool {
    #[cfg(target_os = "linux")]
    {
        let pid = i32::try_from(pid)
            .ok()
            .and_then(rustix::process::Pid::from_raw);
        pid.is_none_or(|pid| {
            matches!(
                rustix::process::test_kill_process(pid),
                Err(rustix::io::Errno::SRCH)
            )
        })
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = pid;
        false
    }
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;

    fn pair(capacity: usize) -> (Ring, RingWriter) {
        let ring = Ring::new(capacity).expect("a ring");
        let writer = RingWriter::open(&ring.address().expect("an address")).expect("opened");
        (ring, writer)
    }

    fn take_all(ring: &mut Ring) -> Vec<Vec<u8>> {
        let mut out = Vec::new();
        ring.take(|m| {
            out.push(m.to_vec());
            true
        })
        .expect("taken");
        out
    }

    #[test]
    fn messages_come_out_in_order_and_whole_across_the_wrap() {
        let (mut ring, mut writer) = pair(4096);
        let mut expected = Vec::new();
        let mut got = Vec::new();
        // Lengths that are not multiples of 8, written and taken in turns, so the
        // positions wrap many times at every alignment.
        for round in 0..2000usize {
            let len = (round * 37) % 700;
            let message: Vec<u8> = (0..len).map(|i| (i + round) as u8).collect();
            while writer.write(&message) == Err(WriteError::Full) {
                got.extend(take_all(&mut ring));
            }
            expected.push(message);
        }
        got.extend(take_all(&mut ring));
        assert_eq!(got, expected);
        assert!(writer.is_empty());
    }

    #[test]
    fn a_declined_message_is_left_with_those_after_it() {
        let (mut ring, mut writer) = pair(4096);
        for message in [b"a", b"b", b"c"] {
            writer.write(message).expect("written");
        }
        let mut got = Vec::new();
        let taken = ring
            .take(|m| {
                if m == b"b" && got.len() == 1 {
                    return false;
                }
                got.push(m.to_vec());
                true
            })
            .expect("taken");
        assert_eq!(taken.messages, 1);
        assert!(ring.has_messages());
        got.extend(take_all(&mut ring));
        assert_eq!(got, vec![b"a".to_vec(), b"b".to_vec(), b"c".to_vec()]);
    }

    #[test]
    fn a_full_ring_refuses_and_the_reader_says_the_writer_waits() {
        let (mut ring, mut writer) = pair(4096);
        let message = [7u8; 1000];
        let mut written = 0;
        while writer.write(&message).is_ok() {
            written += 1;
        }
        assert_eq!(writer.write(&message), Err(WriteError::Full));
        assert_eq!(written, 4, "4096 bytes take four messages of 1008");
        writer.ask_to_be_rung();
        let taken = ring.take(|_| true).expect("taken");
        assert_eq!(taken.messages, 4);
        assert!(taken.writer_waits);
        // Asked once, said once.
        assert!(!ring.take(|_| true).expect("taken").writer_waits);
        assert_eq!(writer.write(&message), Ok(()));
        assert_eq!(writer.write(&[0; 1025]), Err(WriteError::TooLong));
    }

    #[test]
    fn a_writer_that_breaks_the_layout_closes_the_ring_and_loses_nothing_else() {
        let (mut ring, mut writer) = pair(4096);
        writer.write(b"good").expect("written");
        // A length beyond a quarter of the ring, as a hostile writer might leave.
        let words = writer.shared.u64s();
        let head = words[HEAD_AT].load(Ordering::Relaxed);
        words[DATA + (head as usize % 4096) / 8].store(5000, Ordering::Relaxed);
        words[HEAD_AT].store(head + 16, Ordering::SeqCst);
        let mut got = Vec::new();
        let error = ring.take(|m| {
            got.push(m.to_vec());
            true
        });
        assert_eq!(got, vec![b"good".to_vec()]);
        assert!(matches!(error, Err(RingError::Malformed(_))));
        assert!(writer.is_gone());
        assert_eq!(writer.write(b"more"), Err(WriteError::Gone));
        // A position the reader cannot have.
        let (mut ring, writer) = pair(4096);
        writer.shared.u64s()[HEAD_AT].store(1 << 40, Ordering::SeqCst);
        assert!(ring.take(|_| true).is_err());
    }

    #[test]
    fn a_dropped_ring_is_gone_for_its_writer_and_another_nonce_is_refused() {
        let (ring, writer) = pair(4096);
        let mut address = ring.address().expect("an address");
        assert!(!writer.is_gone());
        address.nonce ^= 1;
        assert!(RingWriter::open(&address).is_err());
        drop(ring);
        assert!(writer.is_gone());
    }
}
