//! Serving requests in lanes: those of one lane (a node's component) one at a time
//! and in the order they came, those of different lanes side by side, on a few
//! threads. A node's control commands go through it, so that a component that takes
//! its whole command timeout delays only the commands sent to it.
//!
//! A lane with requests waits in a ready queue until a thread is free; a thread
//! serves one request of the lane it took, then puts the lane back at the end of
//! the queue if it has more, so a lane flooded with requests takes no more than its
//! turn. At most [`THREADS`] requests are served at once: the first thread starts with
//! the lanes, the others when a request finds every running thread busy. Dropping
//! [`Lanes`] serves what is queued, then joins the threads.

use crate::locks::lock;
use std::collections::{HashMap, VecDeque};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::thread::JoinHandle;

use crate::Error;

/// The most requests served at once (the most lanes held by slow requests before a
/// request of another lane waits).
pub(crate) const THREADS: usize = 4;

/// Why a request was not queued.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Refused {
    /// Its lane holds its bound of requests.
    LaneFull,
    /// The lanes together hold their bound.
    Full,
    /// The lanes are stopping.
    Stopped,
}

/// Lanes of requests of type `T`, served by `serve`; stopped when dropped.
pub(crate) struct Lanes<T: Send + 'static> {
    shared: Arc<Shared<T>>,
}

/// What queues requests on [`Lanes`] (cloned into the callbacks that receive them).
pub(crate) struct Sender<T: Send + 'static> {
    shared: Arc<Shared<T>>,
}

impl<T: Send + 'static> Clone for Sender<T> {
    fn clone(&self) -> Self {
        Sender {
            shared: Arc::clone(&self.shared),
        }
    }
}

struct Shared<T> {
    state: Mutex<State<T>>,
    /// Signalled when a lane becomes ready or the lanes stop.
    ready: Condvar,
    serve: Box<dyn Fn(T) + Send + Sync>,
    /// The threads' name.
    name: String,
    /// Bound of one lane's queue, and of all of them together.
    per_lane: usize,
    total: usize,
}

struct State<T> {
    /// The requests of each lane not yet being served (a lane with none is removed).
    queues: HashMap<Arc<str>, VecDeque<T>>,
    /// Lanes with requests and no thread serving them, in the order they became so.
    ready: VecDeque<Arc<str>>,
    /// Lanes a thread is serving a request of.
    serving: Vec<Arc<str>>,
    /// Requests queued, all lanes together.
    queued: usize,
    /// Threads running, and those of them waiting for a ready lane.
    threads: Vec<JoinHandle<()>>,
    idle: usize,
    stopping: bool,
}

impl<T: Send + 'static> Lanes<T> {
    /// Lanes whose threads are named `name`, serving each request with `serve`,
    /// holding at most `per_lane` requests in a lane and `total` in all; the first
    /// thread is started now (`what` names it in a spawn error).
    pub(crate) fn start(
        name: String,
        what: &'static str,
        per_lane: usize,
        total: usize,
        serve: impl Fn(T) + Send + Sync + 'static,
    ) -> Result<Lanes<T>, Error> {
        let shared = Arc::new(Shared {
            state: Mutex::new(State {
                queues: HashMap::new(),
                ready: VecDeque::new(),
                serving: Vec::new(),
                queued: 0,
                threads: Vec::new(),
                idle: 0,
                stopping: false,
            }),
            ready: Condvar::new(),
            serve: Box::new(serve),
            name,
            per_lane: per_lane.max(1),
            total: total.max(1),
        });
        let first = spawn(&shared).map_err(Error::spawn(what))?;
        lock(&shared.state).threads.push(first);
        Ok(Lanes { shared })
    }

    /// What queues requests on these lanes.
    pub(crate) fn sender(&self) -> Sender<T> {
        Sender {
            shared: Arc::clone(&self.shared),
        }
    }
}

impl<T: Send + 'static> Sender<T> {
    /// Queue `request` on `lane`, or hand it back with why not.
    pub(crate) fn try_send(&self, lane: &Arc<str>, request: T) -> Result<(), (Refused, T)> {
        let shared = &self.shared;
        let mut state = lock(&shared.state);
        if state.stopping {
            return Err((Refused::Stopped, request));
        }
        if state.queued >= shared.total {
            return Err((Refused::Full, request));
        }
        let queue = state.queues.entry(Arc::clone(lane)).or_default();
        if queue.len() >= shared.per_lane {
            return Err((Refused::LaneFull, request));
        }
        let first = queue.is_empty();
        queue.push_back(request);
        state.queued += 1;
        // A lane already ready, or being served, is taken up again by its thread.
        if first && !state.serving.contains(lane) {
            state.ready.push_back(Arc::clone(lane));
            // A thread more unless a waiting one is there for each ready lane (a
            // thread told to wake counts as waiting until it takes one).
            if state.ready.len() > state.idle && state.threads.len() < THREADS {
                match spawn(shared) {
                    Ok(thread) => state.threads.push(thread),
                    // The running threads serve it when one is free.
                    Err(error) => coolbot::limited!(&shared.name, |held| tracing::warn!(
                        "no thread more for `{}`: {error}{held}",
                        shared.name
                    )),
                }
            }
            shared.ready.notify_one();
        }
        Ok(())
    }
}

impl<T: Send + 'static> Drop for Lanes<T> {
    fn drop(&mut self) {
        let threads = {
            let mut state = lock(&self.shared.state);
            state.stopping = true;
            self.shared.ready.notify_all();
            std::mem::take(&mut state.threads)
        };
        for thread in threads {
            let _ = thread.join();
        }
    }
}

fn spawn<T: Send + 'static>(shared: &Arc<Shared<T>>) -> std::io::Result<JoinHandle<()>> {
    let shared = Arc::clone(shared);
    std::thread::Builder::new()
        .name(shared.name.clone())
        .spawn(move || serve_lanes(&shared))
}

/// One thread: take a ready lane, serve one of its requests, put the lane back if it
/// has more; wait when none is ready; end when the lanes stop and none is.
fn serve_lanes<T>(shared: &Shared<T>) {
    let mut state = lock(&shared.state);
    loop {
        let Some(lane) = state.ready.pop_front() else {
            if state.stopping {
                return;
            }
            state.idle += 1;
            state = shared
                .ready
                .wait(state)
                .unwrap_or_else(PoisonError::into_inner);
            state.idle -= 1;
            continue;
        };
        let Some(request) = state.queues.get_mut(&lane).and_then(VecDeque::pop_front) else {
            state.queues.remove(&lane);
            continue;
        };
        state.queued -= 1;
        state.serving.push(Arc::clone(&lane));
        drop(state);
        // A panic costs its request, not the thread (the lane goes on after it).
        let served =
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| (shared.serve)(request)));
        if let Err(panic) = served {
            tracing::error!(
                "`{}` panicked serving a request of `{lane}`: {}",
                shared.name,
                coolbot::panic_message(&*panic)
            );
        }
        state = lock(&shared.state);
        state.serving.retain(|serving| *serving != lane);
        if state
            .queues
            .get(&lane)
            .is_some_and(|queue| !queue.is_empty())
        {
            state.ready.push_back(lane);
        } else {
            state.queues.remove(&lane);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crossbeam_channel::{Receiver, Sender, bounded, unbounded};
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::time::Duration;

    /// A deadline for what must happen soon on real threads.
    const SOON: Duration = Duration::from_secs(60);

    type Request = (&'static str, u32, Option<Receiver<()>>);

    /// Lanes whose requests report `(lane, number)` when served, each first waiting
    /// for its gate if it has one.
    fn reporting(per_lane: usize, total: usize) -> (Lanes<Request>, Receiver<(&'static str, u32)>) {
        let (served, serves) = unbounded();
        let lanes = Lanes::start(
            "lanes-test".to_owned(),
            "lanes test",
            per_lane,
            total,
            move |(lane, number, gate): Request| {
                if let Some(gate) = gate {
                    let _ = gate.recv_timeout(SOON);
                }
                let _ = served.send((lane, number));
            },
        )
        .unwrap();
        (lanes, serves)
    }

    fn gate() -> (Sender<()>, Receiver<()>) {
        bounded(0)
    }

    #[test]
    fn a_held_lane_holds_up_no_other_lane() {
        let (owner, served) = reporting(16, 64);
        let send = owner.sender();
        let slow: Arc<str> = Arc::from("slow");
        let other: Arc<str> = Arc::from("other");
        let (open, held) = gate();
        send.try_send(&slow, ("slow", 1, Some(held))).ok().unwrap();
        send.try_send(&slow, ("slow", 2, None)).ok().unwrap();
        for number in 1..=3 {
            send.try_send(&other, ("other", number, None)).ok().unwrap();
        }
        let mut got = Vec::new();
        for _ in 0..3 {
            got.push(served.recv_timeout(SOON).unwrap());
        }
        assert_eq!(got, [("other", 1), ("other", 2), ("other", 3)]);
        // The held lane's second request waits behind its first.
        assert!(served.try_recv().is_err());
        drop(open);
        assert_eq!(served.recv_timeout(SOON).unwrap(), ("slow", 1));
        assert_eq!(served.recv_timeout(SOON).unwrap(), ("slow", 2));
    }

    #[test]
    fn the_requests_of_a_lane_are_served_in_order_one_at_a_time() {
        let inside = Arc::new(AtomicUsize::new(0));
        let most = Arc::new(AtomicUsize::new(0));
        let (served, serves) = unbounded();
        let lanes = {
            let (inside, most) = (Arc::clone(&inside), Arc::clone(&most));
            Lanes::start(
                "lanes-test".to_owned(),
                "lanes test",
                1000,
                1000,
                move |(lane, number): (usize, u32)| {
                    if lane == 0 {
                        let now = inside.fetch_add(1, Ordering::SeqCst) + 1;
                        most.fetch_max(now, Ordering::SeqCst);
                        std::thread::yield_now();
                        inside.fetch_sub(1, Ordering::SeqCst);
                    }
                    let _ = served.send((lane, number));
                },
            )
            .unwrap()
        };
        let names: Vec<Arc<str>> = (0..3).map(|lane| Arc::from(format!("{lane}"))).collect();
        for number in 0..200 {
            for (lane, name) in names.iter().enumerate() {
                lanes.sender().try_send(name, (lane, number)).unwrap();
            }
        }
        let mut next = [0u32; 3];
        for _ in 0..600 {
            let (lane, number) = serves.recv_timeout(SOON).unwrap();
            assert_eq!(number, next[lane], "lane {lane} out of order");
            next[lane] += 1;
        }
        assert_eq!(
            most.load(Ordering::SeqCst),
            1,
            "two requests of one lane at once"
        );
    }

    #[test]
    fn the_bounds_refuse_and_say_which() {
        // A lane's bound: its first request held while being served, two queued.
        let (lanes, served) = reporting(2, 10);
        let send = lanes.sender();
        let a: Arc<str> = Arc::from("a");
        let (open, held) = gate();
        send.try_send(&a, ("a", 0, Some(held))).ok().unwrap();
        // Served, so no longer queued.
        assert!(crate::testing::eventually(|| lock(&lanes.shared.state)
            .queued
            == 0));
        send.try_send(&a, ("a", 1, None)).ok().unwrap();
        send.try_send(&a, ("a", 2, None)).ok().unwrap();
        let refused = send.try_send(&a, ("a", 3, None)).err().unwrap();
        assert_eq!((refused.0, refused.1.1), (Refused::LaneFull, 3));
        drop(open);
        let got: Vec<_> = (0..3).map(|_| served.recv_timeout(SOON).unwrap()).collect();
        assert_eq!(got, [("a", 0), ("a", 1), ("a", 2)]);

        // The bound of all lanes: another lane refused too.
        let (lanes, _served) = reporting(10, 2);
        let send = lanes.sender();
        let b: Arc<str> = Arc::from("b");
        let (open, held) = gate();
        send.try_send(&a, ("a", 0, Some(held))).ok().unwrap();
        assert!(crate::testing::eventually(|| lock(&lanes.shared.state)
            .queued
            == 0));
        send.try_send(&a, ("a", 1, None)).ok().unwrap();
        send.try_send(&a, ("a", 2, None)).ok().unwrap();
        let refused = send.try_send(&b, ("b", 1, None)).err().unwrap();
        assert_eq!(refused.0, Refused::Full);
        drop(open);
        drop(lanes);
        // Stopped lanes refuse.
        let refused = send.try_send(&b, ("b", 2, None)).err().unwrap();
        assert_eq!(refused.0, Refused::Stopped);
    }

    #[test]
    fn dropped_lanes_serve_what_is_queued_then_join() {
        let (lanes, served) = reporting(100, 100);
        let (open, held) = gate();
        let lane: Arc<str> = Arc::from("a");
        lanes
            .sender()
            .try_send(&lane, ("a", 0, Some(held)))
            .ok()
            .unwrap();
        for number in 1..10 {
            lanes
                .sender()
                .try_send(&lane, ("a", number, None))
                .ok()
                .unwrap();
        }
        let dropping = std::thread::spawn(move || drop(lanes));
        drop(open);
        dropping.join().unwrap();
        let got: Vec<_> = served.try_iter().map(|(_, number)| number).collect();
        assert_eq!(got, (0..10).collect::<Vec<_>>());
    }

    #[test]
    fn a_panicking_request_costs_only_itself() {
        let (served, serves) = unbounded();
        let lanes = Lanes::start(
            "lanes-test".to_owned(),
            "lanes test",
            10,
            10,
            move |number: u32| {
                assert_ne!(number, 1, "the request that panics");
                let _ = served.send(number);
            },
        )
        .unwrap();
        let lane: Arc<str> = Arc::from("a");
        for number in 0..3 {
            lanes.sender().try_send(&lane, number).unwrap();
        }
        assert_eq!(serves.recv_timeout(SOON).unwrap(), 0);
        assert_eq!(serves.recv_timeout(SOON).unwrap(), 2);
    }
}
