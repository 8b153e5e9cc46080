//! An inlet's backlog: the packets whose delivery would wait, sent on a thread of the
//! inlet's own (`docs/distribution.md`, "Each connection kind across the network").
//!
//! An inlet delivers on Zenoh's receiving thread, which its whole session shares:
//! every other bridge, the control port, the acknowledgments. A consumer's fifo whose
//! policy is `block` makes its producer wait for room (up to its block timeout, then
//! the packet is rejected and counted there); on the receiving thread that wait would
//! hold up everything else the session receives. So a packet goes to the port at once
//! only when nothing waits before it and the send would not wait
//! ([`DataOut::would_wait`]); otherwise it joins the backlog, whose thread sends the
//! packets in order and does the waiting. The backlog holds at most
//! [`BACKLOG_PACKETS`] packets and [`BACKLOG_BYTES`] bytes (as they came on the wire);
//! a packet beyond is refused, and the inlet counts it lost. The thread starts with
//! the first packet that has to wait.

use crate::locks::lock;
use std::collections::VecDeque;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::thread::JoinHandle;

use coolbot::Packet;
use coolbot::port::DataOut;

/// The most packets a backlog holds.
pub(crate) const BACKLOG_PACKETS: usize = 256;

/// The most bytes a backlog holds, counted as the packets came on the wire.
pub(crate) const BACKLOG_BYTES: usize = 64 << 20;

/// Where a backlog sends: a data output ([`DataOut`]), or a test's stand-in.
pub(crate) trait Port<T>: Send + Sync + 'static {
    /// Whether [`Port::send`] now would wait for room.
    fn would_wait(&self) -> bool;
    /// Send `packet`, waiting as long as the consumer makes the sender wait.
    fn send(&self, packet: T);
}

impl<T: Packet> Port<T> for DataOut<T> {
    fn would_wait(&self) -> bool {
        DataOut::would_wait(self)
    }

    fn send(&self, packet: T) {
        DataOut::send(self, packet);
    }
}

/// Counts `count` packets lost, with the reason.
pub(crate) type LostFn = Arc<dyn Fn(u64, String) + Send + Sync>;

/// Why the backlog did not take a packet (the caller counts it lost).
#[derive(Debug, thiserror::Error)]
pub(crate) enum Refused {
    /// The backlog is full.
    #[error(
        "the consumer's `block` fifo is full and the inlet's backlog holds {packets} packets ({bytes} bytes): at most {BACKLOG_PACKETS} packets and {BACKLOG_BYTES} bytes"
    )]
    Full { packets: usize, bytes: usize },
    /// The backlog's thread could not be started.
    #[error("the consumer's `block` fifo is full and the inlet's backlog thread could not start")]
    Thread(#[source] std::io::Error),
}

/// The packets of one inlet waiting for room, and the thread that sends them.
pub(crate) struct Backlog<T, P = DataOut<T>> {
    shared: Arc<Shared<T, P>>,
    thread: Mutex<Option<JoinHandle<()>>>,
    /// The thread's name.
    name: String,
}

struct Shared<T, P> {
    port: P,
    state: Mutex<State<T>>,
    ready: Condvar,
    lost: LostFn,
}

struct State<T> {
    /// Each packet with its size on the wire, oldest first.
    queue: VecDeque<(T, usize)>,
    bytes: usize,
    /// The thread took a packet off the queue and sends it.
    sending: bool,
    /// The backlog was dropped: what is left is counted lost.
    closed: bool,
}

impl<T: Packet, P: Port<T>> Backlog<T, P> {
    /// The backlog in front of `port`, for the bridge key `key`; `lost` counts what a
    /// dropped backlog still held.
    pub(crate) fn new(port: P, key: &str, lost: LostFn) -> Backlog<T, P> {
        Backlog {
            shared: Arc::new(Shared {
                port,
                state: Mutex::new(State {
                    queue: VecDeque::new(),
                    bytes: 0,
                    sending: false,
                    closed: false,
                }),
                ready: Condvar::new(),
                lost,
            }),
            thread: Mutex::new(None),
            name: format!("cool-net:backlog:{key}"),
        }
    }

    /// Send `packet` (`size` bytes on the wire) on the port: on this thread when no
    /// packet waits before it and the send would not wait, else after those before it
    /// on the backlog's thread.
    pub(crate) fn send(&self, packet: T, size: usize) -> Result<(), Refused> {
        let mut state = lock(&self.shared.state);
        if state.queue.is_empty() && !state.sending && !self.shared.port.would_wait() {
            // Under the lock: the backlog's thread starts no send meanwhile.
            self.shared.send(packet);
            return Ok(());
        }
        if state.queue.len() >= BACKLOG_PACKETS || state.bytes + size > BACKLOG_BYTES {
            return Err(Refused::Full {
                packets: state.queue.len(),
                bytes: state.bytes,
            });
        }
        self.start()?;
        state.queue.push_back((packet, size));
        state.bytes += size;
        drop(state);
        self.shared.ready.notify_one();
        Ok(())
    }

    /// Send `packet` on the port now, on this thread, whatever waits in the backlog
    /// (the answer to a pull request, which goes to the requesting input alone while
    /// this thread answers it).
    pub(crate) fn send_now(&self, packet: T) {
        self.shared.send(packet);
    }

    /// The thread, started if it is not yet.
    fn start(&self) -> Result<(), Refused> {
        let mut thread = lock(&self.thread);
        if thread.is_none() {
            let shared = Arc::clone(&self.shared);
            *thread = Some(
                std::thread::Builder::new()
                    .name(self.name.clone())
                    .spawn(move || shared.run())
                    .map_err(Refused::Thread)?,
            );
        }
        Ok(())
    }
}

impl<T: Packet, P: Port<T>> Shared<T, P> {
    /// Send `packet` on the port. A converter on a connection is user code: its
    /// panic costs that packet (counted lost, though consumers served before the
    /// panic have it), not the thread, which may be Zenoh's receiving thread.
    fn send(&self, packet: T) {
        if let Err(panic) = catch_unwind(AssertUnwindSafe(|| self.port.send(packet))) {
            (self.lost)(
                1,
                format!(
                    "sending it on panicked: {}",
                    coolbot::panic_message(panic.as_ref())
                ),
            );
        }
    }

    /// Send the queued packets in order, each waiting as long as its fifo makes it;
    /// once closed, count what is left lost and end.
    fn run(&self) {
        let mut state = lock(&self.state);
        loop {
            while state.queue.is_empty() && !state.closed {
                state = self
                    .ready
                    .wait(state)
                    .unwrap_or_else(PoisonError::into_inner);
            }
            if state.closed {
                let left = state.queue.len() as u64;
                state.queue.clear();
                state.bytes = 0;
                drop(state);
                if left > 0 {
                    (self.lost)(
                        left,
                        "the inlet closed with packets in its backlog".to_owned(),
                    );
                }
                return;
            }
            let Some((packet, size)) = state.queue.pop_front() else {
                continue;
            };
            state.bytes -= size;
            state.sending = true;
            drop(state);
            self.send(packet);
            state = lock(&self.state);
            state.sending = false;
        }
    }
}

impl<T, P> Drop for Backlog<T, P> {
    /// Close the backlog: the thread ends its send in progress (at most its fifo's
    /// block timeout), counts what is left lost, and is joined.
    fn drop(&mut self) {
        lock(&self.shared.state).closed = true;
        self.shared.ready.notify_all();
        if let Some(thread) = lock(&self.thread).take() {
            let _ = thread.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::{AtomicU64, Ordering};
    use std::time::Duration;

    use coolbot::crossbeam_channel::{Receiver, Sender, bounded};

    use super::*;

    /// A consumer's fifo of `capacity` whose sender waits up to `wait` for room, then
    /// counts the packet rejected.
    struct Fifo {
        sender: Sender<u64>,
        wait: Duration,
        rejected: AtomicU64,
    }

    impl Port<u64> for Arc<Fifo> {
        fn would_wait(&self) -> bool {
            self.sender.is_full()
        }

        fn send(&self, packet: u64) {
            if self.sender.send_timeout(packet, self.wait).is_err() {
                self.rejected.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    fn fifo(capacity: usize, wait: Duration) -> (Arc<Fifo>, Receiver<u64>) {
        let (sender, receiver) = bounded(capacity);
        let fifo = Fifo {
            sender,
            wait,
            rejected: AtomicU64::new(0),
        };
        (Arc::new(fifo), receiver)
    }

    fn counting() -> (LostFn, Arc<AtomicU64>) {
        let count = Arc::new(AtomicU64::new(0));
        let counted = Arc::clone(&count);
        let lost: LostFn = Arc::new(move |n, _why| {
            counted.fetch_add(n, Ordering::Relaxed);
        });
        (lost, count)
    }

    #[test]
    fn a_send_that_would_not_wait_is_made_at_once_without_a_thread() {
        let (port, queue) = fifo(4, Duration::from_secs(60));
        let (lost, _) = counting();
        let backlog = Backlog::new(Arc::clone(&port), "test/direct", lost);
        for packet in 0..4 {
            backlog.send(packet, 8).unwrap();
        }
        assert!(lock(&backlog.thread).is_none(), "no thread started");
        assert_eq!(queue.try_iter().collect::<Vec<_>>(), vec![0, 1, 2, 3]);
    }

    #[test]
    fn packets_that_would_wait_keep_their_order_behind_the_waiting_one() {
        let (port, queue) = fifo(1, Duration::from_secs(60));
        let (lost, count) = counting();
        let backlog = Backlog::new(Arc::clone(&port), "test/order", lost);
        backlog.send(0, 8).unwrap();
        // The fifo is full: these wait in the backlog, in order, and this thread
        // does not.
        for packet in 1..6 {
            backlog.send(packet, 8).unwrap();
        }
        let mut received = Vec::new();
        while received.len() < 6 {
            received.push(
                queue
                    .recv_timeout(Duration::from_secs(60))
                    .expect("the backlog goes on as the fifo empties"),
            );
        }
        assert_eq!(received, vec![0, 1, 2, 3, 4, 5]);
        drop(backlog);
        assert_eq!(count.load(Ordering::Relaxed), 0);
        assert_eq!(port.rejected.load(Ordering::Relaxed), 0);
    }

    #[test]
    fn a_full_backlog_refuses_a_packet_and_says_so() {
        let (port, queue) = fifo(1, Duration::from_secs(60));
        let (lost, _) = counting();
        let backlog = Backlog::new(Arc::clone(&port), "test/full", lost);
        backlog.send(0, 8).unwrap();
        // Of no size: the thread may take it and wait with it, or not yet.
        backlog.send(1, 0).unwrap();
        backlog.send(2, BACKLOG_BYTES).unwrap();
        let refused = backlog.send(3, 1).unwrap_err();
        assert!(
            matches!(refused, Refused::Full { bytes, .. } if bytes == BACKLOG_BYTES),
            "{refused:?}"
        );
        assert!(refused.to_string().contains("backlog"), "{refused}");
        // Reading the fifo lets the rest through.
        let received: Vec<u64> = (0..3)
            .map(|_| queue.recv_timeout(Duration::from_secs(60)).unwrap())
            .collect();
        assert_eq!(received, vec![0, 1, 2]);
    }

    /// A fifo behind a converter that panics on packet 2.
    struct Panicky(Arc<Fifo>);

    impl Port<u64> for Panicky {
        fn would_wait(&self) -> bool {
            self.0.would_wait()
        }

        fn send(&self, packet: u64) {
            assert_ne!(packet, 2, "the converter fails on 2");
            self.0.send(packet);
        }
    }

    #[test]
    fn a_panic_sending_a_packet_on_costs_that_packet_not_the_backlog() {
        let (port, queue) = fifo(1, Duration::from_secs(60));
        let (lost, count) = counting();
        let backlog = Backlog::new(Panicky(Arc::clone(&port)), "test/panic", lost);
        for packet in 0..5 {
            backlog.send(packet, 8).unwrap();
        }
        let received: Vec<u64> = (0..4)
            .map(|_| queue.recv_timeout(Duration::from_secs(60)).unwrap())
            .collect();
        assert_eq!(received, vec![0, 1, 3, 4]);
        assert_eq!(count.load(Ordering::Relaxed), 1, "the packet counted lost");
        // On the thread that sends at once (Zenoh's) too.
        backlog.send(2, 8).unwrap();
        assert_eq!(count.load(Ordering::Relaxed), 2, "that one counted too");
    }

    #[test]
    fn a_dropped_backlog_counts_what_it_still_held() {
        let (port, queue) = fifo(1, Duration::from_millis(20));
        let (lost, count) = counting();
        let backlog = Backlog::new(Arc::clone(&port), "test/closed", lost);
        backlog.send(0, 8).unwrap();
        for packet in 1..4 {
            backlog.send(packet, 8).unwrap();
        }
        // The packet being sent is rejected after its wait; the others are lost.
        drop(backlog);
        assert_eq!(
            count.load(Ordering::Relaxed) + port.rejected.load(Ordering::Relaxed),
            3
        );
        assert_eq!(queue.try_iter().collect::<Vec<_>>(), vec![0]);
    }
}
