//! A bounded queue of messages from any thread to one, closed by one end: a
//! component's control queue (the commands its handles post, closed when its thread
//! ends) and the answers to one command (closed when the component is done with it).
//!
//! One small allocation that grows with what is queued and shrinks when it is taken,
//! where a channel allocates its whole capacity and its own bookkeeping up front: a
//! thousand idle components cost a thousand empty queues. Whoever waits
//! ([`Mailbox::take_until`], [`Mailbox::wait_closed`]) wakes on a post and on the close.

use std::collections::VecDeque;
use std::ops::Deref;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::time::Instant;

/// Why a post did not go in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum PostError {
    /// The queue holds its capacity already.
    Full,
    /// The mailbox is closed.
    Closed,
}

/// A bounded queue of messages, closed by its [`Closer`].
pub(crate) struct Mailbox<M> {
    letters: Mutex<Letters<M>>,
    /// Signalled on a post while someone waits, and on the close.
    changed: Condvar,
    /// How many messages are queued: read without the lock.
    len: AtomicUsize,
    capacity: usize,
}

struct Letters<M> {
    queue: VecDeque<M>,
    closed: bool,
    /// Threads waiting on `changed`.
    waiters: usize,
}

impl<M> Mailbox<M> {
    /// An open, empty mailbox that holds at most `capacity` messages.
    pub(crate) fn new(capacity: usize) -> Arc<Mailbox<M>> {
        Arc::new(Mailbox {
            letters: Mutex::new(Letters {
                queue: VecDeque::new(),
                closed: false,
                waiters: 0,
            }),
            changed: Condvar::new(),
            len: AtomicUsize::new(0),
            capacity,
        })
    }

    fn lock(&self) -> MutexGuard<'_, Letters<M>> {
        self.letters.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Queue `message`, or give it back with why not.
    pub(crate) fn post(&self, message: M) -> Result<(), (PostError, M)> {
        let mut letters = self.lock();
        if letters.closed {
            return Err((PostError::Closed, message));
        }
        if letters.queue.len() >= self.capacity {
            return Err((PostError::Full, message));
        }
        letters.queue.push_back(message);
        self.len.store(letters.queue.len(), Ordering::Release);
        if letters.waiters > 0 {
            self.changed.notify_all();
        }
        Ok(())
    }

    /// The oldest message queued, if any.
    pub(crate) fn take(&self) -> Option<M> {
        if self.is_empty() {
            return None;
        }
        Self::pop(&mut self.lock(), &self.len)
    }

    fn pop(letters: &mut Letters<M>, len: &AtomicUsize) -> Option<M> {
        let message = letters.queue.pop_front();
        len.store(letters.queue.len(), Ordering::Release);
        if letters.queue.is_empty() {
            // An idle queue holds no buffer.
            letters.queue = VecDeque::new();
        }
        message
    }

    /// The oldest message, waiting for one until `deadline`; `None` if none came by
    /// then or the mailbox is closed and empty.
    pub(crate) fn take_until(&self, deadline: Instant) -> Option<M> {
        let mut letters = self.lock();
        loop {
            if !letters.queue.is_empty() {
                return Self::pop(&mut letters, &self.len);
            }
            let now = Instant::now();
            if letters.closed || now >= deadline {
                return None;
            }
            letters = self.wait(letters, deadline - now);
        }
    }

    fn wait<'a>(
        &self,
        mut letters: MutexGuard<'a, Letters<M>>,
        timeout: std::time::Duration,
    ) -> MutexGuard<'a, Letters<M>> {
        letters.waiters += 1;
        let mut letters = self
            .changed
            .wait_timeout(letters, timeout)
            .unwrap_or_else(PoisonError::into_inner)
            .0;
        letters.waiters -= 1;
        letters
    }

    /// Keep only the messages `keep` keeps; how many were dropped (after the lock is
    /// released: a message's own drop may take other locks).
    pub(crate) fn retain(&self, mut keep: impl FnMut(&M) -> bool) -> usize {
        let dropped: Vec<M> = {
            let mut letters = self.lock();
            let queue = std::mem::take(&mut letters.queue);
            let mut dropped = Vec::new();
            for message in queue {
                if keep(&message) {
                    letters.queue.push_back(message);
                } else {
                    dropped.push(message);
                }
            }
            self.len.store(letters.queue.len(), Ordering::Release);
            dropped
        };
        dropped.len()
    }

    /// Whether the mailbox is closed (its other end is gone).
    pub(crate) fn is_closed(&self) -> bool {
        self.lock().closed
    }

    /// Whether nothing is queued (one load, no lock).
    pub(crate) fn is_empty(&self) -> bool {
        self.len.load(Ordering::Acquire) == 0
    }

    /// Close the mailbox: refuse later posts, drop what is queued if `discard`
    /// (outside the lock), wake every waiter.
    fn close(&self, discard: bool) {
        let queued = {
            let mut letters = self.lock();
            letters.closed = true;
            if discard {
                self.len.store(0, Ordering::Release);
                std::mem::take(&mut letters.queue)
            } else {
                VecDeque::new()
            }
        };
        self.changed.notify_all();
        drop(queued);
    }

    /// Wait until the mailbox is closed or `deadline` passes; whether it is closed.
    pub(crate) fn wait_closed(&self, deadline: Instant) -> bool {
        let mut letters = self.lock();
        while !letters.closed {
            let now = Instant::now();
            if now >= deadline {
                return false;
            }
            letters = self.wait(letters, deadline - now);
        }
        true
    }
}

/// The end that closes a mailbox when it is dropped, and reaches it meanwhile: the
/// thread that takes from it ([`Closer::taker`]: what is still queued is dropped, as
/// nobody will take it), or the one sender of a mailbox of answers
/// ([`Closer::sender`]: what it posted stays to be taken).
pub(crate) struct Closer<M> {
    mailbox: Arc<Mailbox<M>>,
    discard: bool,
}

impl<M> Closer<M> {
    /// The closing end of the thread that takes from `mailbox`.
    pub(crate) fn taker(mailbox: Arc<Mailbox<M>>) -> Closer<M> {
        Closer {
            mailbox,
            discard: true,
        }
    }

    /// The closing end of the one sender to `mailbox`.
    pub(crate) fn sender(mailbox: Arc<Mailbox<M>>) -> Closer<M> {
        Closer {
            mailbox,
            discard: false,
        }
    }
}

impl<M> Closer<M> {
    /// The mailbox this end closes, to post to from elsewhere while this end lives.
    pub(crate) fn mailbox(&self) -> Arc<Mailbox<M>> {
        Arc::clone(&self.mailbox)
    }
}

impl<M> Deref for Closer<M> {
    type Target = Mailbox<M>;

    fn deref(&self) -> &Mailbox<M> {
        &self.mailbox
    }
}

impl<M> Drop for Closer<M> {
    fn drop(&mut self) {
        self.mailbox.close(self.discard);
    }
}

/// A mailbox for the answers to one request, with the end that sends them: the
/// mailbox closes when the sender is dropped, and what it sent stays to be taken.
pub(crate) fn answers<M>(capacity: usize) -> (Closer<M>, Arc<Mailbox<M>>) {
    let mailbox = Mailbox::new(capacity);
    (Closer::sender(Arc::clone(&mailbox)), mailbox)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn far() -> Instant {
        Instant::now() + Duration::from_secs(60)
    }

    #[test]
    fn posts_come_out_in_order_up_to_the_capacity() {
        let mailbox = Mailbox::new(2);
        assert!(mailbox.is_empty());
        assert_eq!(mailbox.post(1), Ok(()));
        assert_eq!(mailbox.post(2), Ok(()));
        assert_eq!(mailbox.post(3), Err((PostError::Full, 3)));
        assert!(!mailbox.is_empty());
        assert_eq!(mailbox.take(), Some(1));
        assert_eq!(mailbox.post(4), Ok(()));
        assert_eq!(mailbox.take(), Some(2));
        assert_eq!(mailbox.take(), Some(4));
        assert_eq!(mailbox.take(), None);
        assert!(mailbox.is_empty());
    }

    #[test]
    fn the_takers_end_drops_what_is_queued_refuses_posts_and_wakes_a_waiter() {
        let mailbox = Mailbox::new(4);
        let dropped = Arc::new(());
        mailbox.post(Arc::clone(&dropped)).unwrap();
        let waiter = {
            let mailbox = Arc::clone(&mailbox);
            std::thread::spawn(move || mailbox.wait_closed(far()))
        };
        assert!(!mailbox.wait_closed(Instant::now()));
        drop(Closer::taker(Arc::clone(&mailbox)));
        assert!(waiter.join().unwrap());
        assert_eq!(
            Arc::strong_count(&dropped),
            1,
            "the queued message is dropped"
        );
        assert!(mailbox.is_empty());
        assert_eq!(mailbox.take(), None);
        assert!(matches!(
            mailbox.post(Arc::new(())),
            Err((PostError::Closed, _))
        ));
        assert!(mailbox.wait_closed(Instant::now()));
    }

    #[test]
    fn answers_wake_their_waiter_and_stay_after_the_sender_is_dropped() {
        let (sender, answers) = answers::<u8>(2);
        let waiter = {
            let answers = Arc::clone(&answers);
            std::thread::spawn(move || answers.take_until(far()))
        };
        sender.post(1).unwrap();
        assert_eq!(waiter.join().unwrap(), Some(1));
        sender.post(2).unwrap();
        drop(sender);
        assert_eq!(answers.take_until(far()), Some(2), "kept after the close");
        assert_eq!(answers.take_until(far()), None, "closed and empty");
        assert_eq!(answers.take_until(Instant::now()), None);
    }
}
