//! Answers to queries, sent from a thread of the node's rather than from the Zenoh
//! callback that received the query: an answer waits while the link to the querier
//! is full (a query's reply takes the query's congestion control, blocking, up to
//! Zenoh's `wait_before_close`, 5 s), and a Zenoh callback runs on one of the few
//! threads that receive everything the node hears. A querier that stops reading its
//! answers then holds the node's replier, not what the node hears; the answers
//! beyond [`REPLY_QUEUE`] waiting are dropped (the querier's query ends unanswered)
//! and counted ([`Replier::dropped`]). Each answer is made on the replier's thread
//! where it can be, so that one waiting is small.

use crossbeam_channel::{Sender, TrySendError};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use crate::Error;
use crate::serve::Server;

/// The most answers a node's replier holds waiting; one more is dropped. Many: a
/// dropped answer's query is dropped where it was received, and Zenoh then tells
/// the querier that no answer comes (its `ResponseFinal`), which waits as an answer
/// would for a querier that does not read; so the queue is to outlast a querier's
/// link until Zenoh closes it (`wait_before_close`) however fast it asks. An answer
/// waiting holds its query and what it is made from (a handle, a key), not its
/// bytes: a few hundred bytes each.
pub const REPLY_QUEUE: usize = 65_536;

/// One answer to send: it replies to its query when called.
type Answer = Box<dyn FnOnce() + Send>;

/// Where a Zenoh callback hands the answer to its query (cloned into each callback).
#[derive(Clone)]
pub(crate) struct Replier {
    queue: Sender<Answer>,
    dropped: Arc<AtomicU64>,
}

impl Replier {
    /// Send `answer` from the replier's thread; dropped (and counted) if
    /// [`REPLY_QUEUE`] answers wait already, or the thread has stopped. `what` names
    /// it in the warning.
    pub(crate) fn send(&self, what: &str, answer: impl FnOnce() + Send + 'static) {
        match self.queue.try_send(Box::new(answer)) {
            Ok(()) => {}
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
                let total = self.dropped.fetch_add(1, Ordering::AcqRel) + 1;
                coolbot::limited!(what, |held| tracing::warn!(
                    total,
                    "{what} not sent: the node's answers wait for a querier that does not \
                     read them{held}"
                ));
            }
        }
    }

    /// How many answers were dropped.
    pub(crate) fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Acquire)
    }
}

/// A node's replier thread: stopped and joined when dropped (what still waits is
/// dropped, its queries ending unanswered).
pub(crate) struct Replies {
    replier: Replier,
    /// The replier's thread, stopped when dropped.
    _server: Server,
}

impl Replies {
    /// Start the thread of node `node`, whose queue holds `capacity` answers.
    pub(crate) fn start(node: &str, capacity: usize) -> Result<Replies, Error> {
        let (queue, answers) = crossbeam_channel::bounded::<Answer>(capacity);
        // A stop leaves the answers still waiting: their queries end unanswered.
        let server = Server::start(
            format!("cool-net:{node}:r"),
            "replier",
            answers,
            |answer: Answer| answer(),
        )?;
        Ok(Replies {
            replier: Replier {
                queue,
                dropped: Arc::default(),
            },
            _server: server,
        })
    }

    /// Where the node's callbacks hand their answers.
    pub(crate) fn replier(&self) -> &Replier {
        &self.replier
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;
    use std::time::Instant;

    #[test]
    fn answers_beyond_the_queue_are_dropped_and_counted_while_one_is_held() {
        let replies = Replies::start("test", 2).unwrap();
        let replier = replies.replier().clone();
        // The first answer is held (a querier that does not read it).
        let (held, release) = crossbeam_channel::bounded::<()>(0);
        let (taken, started) = crossbeam_channel::bounded::<()>(1);
        replier.send("held", move || {
            taken.send(()).unwrap();
            let _ = release.recv();
        });
        started
            .recv_timeout(Duration::from_secs(10))
            .expect("the replier took the first answer");
        // Two wait; the next ones are dropped at once, counted.
        let sent = Arc::new(AtomicU64::new(0));
        for _ in 0..5 {
            let sent = Arc::clone(&sent);
            replier.send("queued", move || {
                sent.fetch_add(1, Ordering::AcqRel);
            });
        }
        assert_eq!(replier.dropped(), 3);
        // Released, the two waiting are sent.
        held.send(()).unwrap();
        let deadline = Instant::now() + Duration::from_secs(10);
        while sent.load(Ordering::Acquire) < 2 && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(5));
        }
        assert_eq!(sent.load(Ordering::Acquire), 2);
        assert_eq!(replier.dropped(), 3);
    }
}
