//! The way from the echoed outputs to the WebSocket. A node publishes its echoed
//! packets a batch per echo tick ([`crate::echo`]); Zenoh's callback only queues each
//! batch as it came (its payload shared, not copied) and wakes the feed's task, on
//! the WebSocket server's own runtime, if it waits. The task splits every batch
//! waiting and logs each packet on the channels of its output that clients subscribe
//! ([`Routes`]), made their messages, then sleeps a [`FEED_TICK`] before it waits
//! again: the batches that come meanwhile wake nothing. So the server's thread wakes
//! at most once a tick while packets come, and not at all while none does; the
//! messages of a tick reach the client tasks on that thread, and each keeps the time
//! its packet was sent. **Invariant:** nothing is lost silently: a batch that finds
//! the queue full or does not decode, and a packet that does not fit its channel, are
//! dropped, counted ([`super::Counts`]) and warned about (rate-limited); so is a
//! packet of a served output that never came (a number missing) or that its node
//! could not echo (its place in the batch says so).

use std::collections::HashMap;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use crossbeam_channel::{Receiver, Sender, TrySendError};
use foxglove::{ChannelId, RawChannel};
use tokio::sync::Notify;
use zenoh::bytes::ZBytes;

use super::Counts;
use super::wellknown::Transform;
use crate::echo::EchoedRaw;

/// The feed takes what waits at most once in this time, so that the WebSocket
/// server's thread wakes at most 20 times a second while packets come (each message
/// keeps the time its packet was sent).
pub const FEED_TICK: Duration = Duration::from_millis(50);

/// How many batches of echoed packets wait for the feed before the newest are
/// dropped (a batch: a node's packets of one echo tick).
pub const FEED_CAPACITY: usize = 256;

/// Where an echoed output's packets go: a channel, and what makes them its messages.
pub(super) struct Route {
    pub(super) channel: Arc<RawChannel>,
    pub(super) transform: Transform,
}

/// The routes of the outputs whose channels clients subscribe, by node and output
/// (`<path>.<port>`).
#[derive(Default)]
pub(super) struct Routes(Mutex<Table>);

/// Routes by node, then by output.
type Table = HashMap<String, HashMap<String, Served>>;

/// An output whose channels clients subscribe.
#[derive(Default)]
struct Served {
    routes: Vec<Arc<Route>>,
    /// The number its next packet should have (none before the first came).
    next: Option<u64>,
}

impl Routes {
    fn lock(&self) -> std::sync::MutexGuard<'_, Table> {
        self.0.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Log the packets of `output` on `node` on `route`'s channel too.
    pub(super) fn add(&self, node: &str, output: &str, route: Arc<Route>) {
        self.lock()
            .entry(node.to_owned())
            .or_default()
            .entry(output.to_owned())
            .or_default()
            .routes
            .push(route);
    }

    /// Stop logging the packets of `output` on `node` on `channel`; whether `node`
    /// has no route left.
    pub(super) fn remove(&self, node: &str, output: &str, channel: ChannelId) -> bool {
        let mut routes = self.lock();
        let Some(outputs) = routes.get_mut(node) else {
            return true;
        };
        if let Some(served) = outputs.get_mut(output) {
            served.routes.retain(|route| route.channel.id() != channel);
            if served.routes.is_empty() {
                outputs.remove(output);
            }
        }
        let none = outputs.is_empty();
        if none {
            routes.remove(node);
        }
        none
    }

    /// Forget every route of `node`.
    pub(super) fn forget(&self, node: &str) {
        self.lock().remove(node);
    }
}

/// A batch waiting, with the node that published it and how many of that node's
/// batches the inlet had dropped when it was queued.
type Waiting = (Arc<str>, ZBytes, u64);

/// The queue's end that Zenoh's callbacks hold.
#[derive(Clone)]
pub(super) struct Inlet {
    sender: Sender<Waiting>,
    counts: Arc<Counts>,
    wake: Arc<Notify>,
    drops: Arc<Drops>,
}

/// How many batches of each node the inlet dropped (over size, or the queue full:
/// counted there), and how many of those the feed has seen behind a batch it took:
/// the numbers such a batch held are not counted missing again at the next one. Per
/// subscription to a node's batches: the name its callback hands over
/// ([`Inlet::push`]) is made anew for each subscription, and the counts are kept by
/// that name's identity, so that a batch of an earlier subscription (the node went
/// and came back while it was queued, or a callback still running as its subscriber
/// went) neither reads nor moves those of the current one.
#[derive(Default)]
struct Drops(Mutex<HashMap<usize, Counted>>);

/// The counts of one subscription to a node's batches, kept under the address of the
/// name its callback hands over: the entry keeps that name alive, so no other name
/// can take its address while it is there.
struct Counted {
    name: Arc<str>,
    dropped: u64,
    seen: u64,
}

/// The key of `node`'s subscription: its name's address (its identity).
fn subscription(node: &Arc<str>) -> usize {
    Arc::as_ptr(node).cast::<u8>().addr()
}

impl Drops {
    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<usize, Counted>> {
        self.0.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// How many of `node`'s batches were dropped so far.
    fn dropped(&self, node: &Arc<str>) -> u64 {
        self.lock()
            .get(&subscription(node))
            .map_or(0, |counted| counted.dropped)
    }

    /// One more of `node`'s batches dropped.
    fn drop_one(&self, node: &Arc<str>) {
        self.lock()
            .entry(subscription(node))
            .or_insert_with(|| Counted {
                name: Arc::clone(node),
                dropped: 0,
                seen: 0,
            })
            .dropped += 1;
    }

    /// Whether a batch of `node` queued after `dropped` drops follows one the feed
    /// has not seen yet (and it is seen now).
    fn after_unseen(&self, node: &Arc<str>, dropped: u64) -> bool {
        let mut drops = self.lock();
        let Some(counted) = drops.get_mut(&subscription(node)) else {
            return false;
        };
        let unseen = dropped > counted.seen;
        counted.seen = counted.seen.max(dropped);
        unseen
    }

    /// Forget every subscription to `node`'s batches (its token went, or its last
    /// route was removed).
    fn forget(&self, node: &str) {
        self.lock().retain(|_, counted| &*counted.name != node);
    }
}

impl Inlet {
    /// Forget what was dropped of `node`'s batches (its token went, or its last route
    /// was removed), so that nodes that come and go leave nothing behind.
    pub(super) fn forget(&self, node: &str) {
        self.drops.forget(node);
    }

    /// Queue `payload`, a batch of echoed packets from `node`, and wake the feed;
    /// count it dropped if the queue is full, or if it is over
    /// [`crate::limits::ECHO_BATCH`] (never queued: what waits is within it).
    pub(super) fn push(&self, node: &Arc<str>, payload: ZBytes) {
        if let Err(exceeded) = crate::limits::ECHO_BATCH
            .check(|| "a batch of echoed packets".to_owned(), payload.len())
        {
            self.counts.undecoded.fetch_add(1, Ordering::Relaxed);
            self.drops.drop_one(node);
            coolbot::limited!(&**node, |held| tracing::warn!(
                "a batch of echoed packets from {node} is not decoded (dropped): {exceeded}{held}"
            ));
            return;
        }
        let dropped = self.drops.dropped(node);
        match self.sender.try_send((Arc::clone(node), payload, dropped)) {
            Ok(()) => self.wake.notify_one(),
            Err(TrySendError::Full(_)) => {
                self.counts.overflowed.fetch_add(1, Ordering::Relaxed);
                self.drops.drop_one(node);
                coolbot::limited!("foxglove:feed", |held| tracing::warn!(
                    "the server falls behind: a batch of echoed packets from {node} is dropped{held}"
                ));
            }
            Err(TrySendError::Disconnected(_)) => {}
        }
    }
}

/// The queue, the routes, and the task that takes from the queue; dropping it ends
/// the task.
pub(super) struct Feed {
    inlet: Inlet,
    routes: Arc<Routes>,
    task: tokio::task::JoinHandle<()>,
}

impl Feed {
    /// Start the feed's task on `runtime` (the WebSocket server's), counting in
    /// `counts`.
    pub(super) fn start(runtime: &tokio::runtime::Handle, counts: Arc<Counts>) -> Feed {
        let (inlet, waiting) = queue(FEED_CAPACITY, counts);
        let routes = Arc::new(Routes::default());
        let (counts, wake, taken, drops) = (
            Arc::clone(&inlet.counts),
            Arc::clone(&inlet.wake),
            Arc::clone(&routes),
            Arc::clone(&inlet.drops),
        );
        let task = runtime.spawn(async move {
            loop {
                // Asleep while nothing comes. A batch queued since the last wait left
                // a permit: it is taken at once.
                wake.notified().await;
                log_waiting(&waiting, &taken, &counts, &drops);
                // At most one wake a tick: the batches that come meanwhile find no
                // waiter, wake nothing and leave a permit.
                tokio::time::sleep(FEED_TICK).await;
            }
        });
        Feed {
            inlet,
            routes,
            task,
        }
    }

    /// The end to queue on.
    pub(super) fn inlet(&self) -> Inlet {
        self.inlet.clone()
    }

    /// The routes the feed logs on.
    pub(super) fn routes(&self) -> Arc<Routes> {
        Arc::clone(&self.routes)
    }
}

impl Drop for Feed {
    fn drop(&mut self) {
        self.task.abort();
    }
}

/// A queue of `capacity` batches: its inlet, and the end [`log_waiting`] takes from.
fn queue(capacity: usize, counts: Arc<Counts>) -> (Inlet, Receiver<Waiting>) {
    let (sender, receiver) = crossbeam_channel::bounded(capacity);
    let wake = Arc::new(Notify::new());
    (
        Inlet {
            sender,
            counts,
            wake,
            drops: Arc::new(Drops::default()),
        },
        receiver,
    )
}

/// Log every packet of every batch waiting on the channels of its output. A batch
/// dropped whole is counted once where it is dropped: the numbers it held are not
/// counted missing again at the node's next batch.
fn log_waiting(waiting: &Receiver<Waiting>, routes: &Routes, counts: &Counts, drops: &Drops) {
    for (node, payload, dropped) in waiting.try_iter() {
        let after_drop = drops.after_unseen(&node, dropped);
        // (Within `ECHO_BATCH`: checked when queued.)
        let payload = payload.to_bytes();
        let decoded = serde_json::from_slice::<Vec<EchoedRaw<'_>>>(&payload);
        let mut routes = routes.lock();
        if after_drop || decoded.is_err() {
            forget_numbers(routes.get_mut(&*node));
        }
        let batch = match decoded {
            Ok(batch) => batch,
            Err(error) => {
                counts.undecoded.fetch_add(1, Ordering::Relaxed);
                coolbot::limited!(&*node, |held| tracing::warn!(
                    "a batch of echoed packets from {node} does not decode (dropped): {error}{held}"
                ));
                continue;
            }
        };
        let Some(outputs) = routes.get_mut(&*node) else {
            continue;
        };
        for echoed in &batch {
            let Some(served) = outputs.get_mut(&*echoed.output) else {
                continue;
            };
            if !counted(&node, echoed, served, counts) {
                continue;
            }
            for route in &served.routes {
                if let Err(error) = message(route, echoed.packet, echoed.sent) {
                    counts.undecoded.fetch_add(1, Ordering::Relaxed);
                    let topic = route.channel.topic();
                    coolbot::limited!(topic, |held| tracing::warn!(
                        "an echoed packet for {topic} does not fit (dropped): {error}{held}"
                    ));
                }
            }
        }
    }
}

/// The next numbers of `outputs` (a node's) unknown: a batch of the node was dropped
/// whole, and counted so.
fn forget_numbers(outputs: Option<&mut HashMap<String, Served>>) {
    for served in outputs.into_iter().flat_map(HashMap::values_mut) {
        served.next = None;
    }
}

/// Count what is lost of `served`, an output of `node`, up to `echoed`, its next
/// element in a batch (the numbers missing before it, and it if its node could not
/// echo it), warning about it (rate-limited); whether it is a packet to log.
fn counted(node: &str, echoed: &EchoedRaw<'_>, served: &mut Served, counts: &Counts) -> bool {
    let output = &*echoed.output;
    if let Some(expected) = served.next {
        let missing = echoed.seq.saturating_sub(expected);
        if missing > 0 {
            counts.missing.fetch_add(missing, Ordering::Relaxed);
            coolbot::limited!(output, |held| tracing::warn!(
                "{missing} echoed packet(s) of {node}/{output} never came (dropped by the \
                 node's echo queue or on the way){held}"
            ));
        }
    }
    served.next = Some(echoed.seq.saturating_add(1));
    let Some(why) = &echoed.unsent else {
        return true;
    };
    counts.unechoed.fetch_add(1, Ordering::Relaxed);
    coolbot::limited!(output, |held| tracing::warn!(
        "packet {} of {node}/{output} was not echoed by its node (lost): {}{held}",
        echoed.seq,
        coolbot::ranges::excerpt(why, coolbot::ranges::REASON_CHARS)
    ));
    false
}

/// Log the echoed packet `packet`, sent at `sent`, on `route`'s channel, at the time
/// it was sent.
fn message(
    route: &Route,
    packet: &serde_json::value::RawValue,
    sent: coolbot::Time,
) -> Result<(), String> {
    let Some(message) = route.transform.message(packet, sent)? else {
        return Ok(());
    };
    route.channel.log_with_meta(
        &message,
        foxglove::PartialMetadata {
            log_time: Some(sent.as_nanos()),
        },
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use foxglove::{Context, Metadata, Sink, SinkId};

    use super::*;
    use crate::foxglove::wellknown::PoseMap;

    /// Keeps what is logged on every channel: (topic, message, log time).
    struct Kept {
        id: SinkId,
        logged: Mutex<Vec<(String, String, u64)>>,
    }

    impl Sink for Kept {
        fn id(&self) -> SinkId {
            self.id
        }

        fn log(
            &self,
            channel: &RawChannel,
            msg: &[u8],
            metadata: &Metadata,
        ) -> Result<(), foxglove::FoxgloveError> {
            self.logged.lock().unwrap().push((
                channel.topic().to_owned(),
                String::from_utf8_lossy(msg).into_owned(),
                metadata.log_time,
            ));
            Ok(())
        }
    }

    fn route(context: &Arc<Context>, topic: &str, transform: Transform) -> Arc<Route> {
        let channel = context
            .channel_builder(topic)
            .message_encoding("json")
            .build_raw()
            .expect("a channel");
        Arc::new(Route { channel, transform })
    }

    /// When the packets of the tests were sent, plus their sequence numbers.
    const SENT: u64 = 7_000_000_000;

    /// A batch of `(output, seq, packet)`.
    fn batch(packets: &[(&str, u64, &str)]) -> ZBytes {
        let frames: Vec<String> = packets
            .iter()
            .map(|(output, seq, packet)| {
                format!(
                    r#"{{"output":"{output}","seq":{seq},"dropped":0,"sent":{},"packet":{packet}}}"#,
                    SENT + seq
                )
            })
            .collect();
        ZBytes::from(format!("[{}]", frames.join(",")))
    }

    /// Each packet of a batch goes to the routes of its output, in order, as the node
    /// wrote it, logged at the time it was sent; an output nobody routes is passed
    /// over, as are the batches of a node with no route. Batches beyond the queue's capacity are dropped and counted; a
    /// batch that does not decode, and a packet that does not fit its channel, are
    /// counted too.
    #[test]
    fn batches_are_split_on_their_routes_and_what_is_lost_is_counted() {
        let counts = Arc::new(Counts::default());
        let (inlet, waiting) = queue(4, Arc::clone(&counts));
        let context = Context::new();
        let kept = Arc::new(Kept {
            id: SinkId::next(),
            logged: Mutex::new(Vec::new()),
        });
        context.add_sink(kept.clone());
        let routes = Routes::default();
        let pose: PoseMap = serde_json::from_value(serde_json::json!({
            "port": "*", "x": "x", "y": "y", "yaw": "theta",
            "frame": "odom", "child": "base_link",
        }))
        .unwrap();
        routes.add(
            "n",
            "a.out",
            route(&context, "/n/a.out", Transform::Raw { wrap: false }),
        );
        routes.add(
            "n",
            "a.out",
            route(&context, "/n/a.out/pose", Transform::Pose(pose)),
        );
        routes.add(
            "n",
            "b.out",
            route(&context, "/n/b.out", Transform::Raw { wrap: true }),
        );
        let (node, other): (Arc<str>, Arc<str>) = (Arc::from("n"), Arc::from("m"));
        inlet.push(
            &node,
            batch(&[
                ("a.out", 0, r#"{"x":1,"y":2,"theta":0}"#),
                ("b.out", 0, "7"),
                ("c.out", 0, "8"),
                ("a.out", 1, r#"{"x":3}"#),
            ]),
        );
        inlet.push(&node, ZBytes::from("not JSON"));
        inlet.push(&other, batch(&[("a.out", 0, "{}")]));
        inlet.push(&node, batch(&[("b.out", 1, "9")]));
        for _ in 0..2 {
            inlet.push(&node, batch(&[("b.out", 2, "10")]));
        }
        assert_eq!(counts.overflowed.load(Ordering::Relaxed), 2);
        log_waiting(&waiting, &routes, &counts, &inlet.drops);
        assert!(waiting.is_empty());
        let logged = kept.logged.lock().unwrap().clone();
        let topics: Vec<&str> = logged.iter().map(|(topic, ..)| topic.as_str()).collect();
        let times: Vec<u64> = logged.iter().map(|(.., time)| time - SENT).collect();
        assert_eq!(
            topics,
            [
                "/n/a.out",
                "/n/a.out/pose",
                "/n/b.out",
                "/n/a.out",
                "/n/b.out"
            ]
        );
        assert_eq!(times, [0, 0, 0, 1, 1]);
        assert_eq!(logged[0].1, r#"{"x":1,"y":2,"theta":0}"#);
        assert_eq!(logged[2].1, r#"{"value":7}"#);
        assert_eq!(logged[3].1, r#"{"x":3}"#);
        assert_eq!(logged[4].1, r#"{"value":9}"#);
        // The batch that does not decode, and the pose without `y`.
        assert_eq!(counts.undecoded.load(Ordering::Relaxed), 2);
    }

    /// A batch the feed drops whole (its queue full, or not decoded) is counted once,
    /// where it is dropped: the numbers it held are not counted missing again at the
    /// node's next batch; a gap after that is.
    #[test]
    fn a_batch_dropped_by_the_feed_is_not_counted_missing_too() {
        let counts = Arc::new(Counts::default());
        let (inlet, waiting) = queue(1, Arc::clone(&counts));
        let context = Context::new();
        let routes = Routes::default();
        routes.add(
            "n",
            "a.out",
            route(&context, "/n/a.out", Transform::Raw { wrap: true }),
        );
        let node: Arc<str> = Arc::from("n");
        inlet.push(&node, batch(&[("a.out", 0, "1")]));
        inlet.push(&node, batch(&[("a.out", 1, "2"), ("a.out", 2, "3")]));
        assert_eq!(counts.overflowed.load(Ordering::Relaxed), 1);
        log_waiting(&waiting, &routes, &counts, &inlet.drops);
        inlet.push(&node, batch(&[("a.out", 3, "4")]));
        log_waiting(&waiting, &routes, &counts, &inlet.drops);
        assert_eq!(counts.missing.load(Ordering::Relaxed), 0);
        inlet.push(&node, ZBytes::from("not JSON"));
        log_waiting(&waiting, &routes, &counts, &inlet.drops);
        inlet.push(&node, batch(&[("a.out", 6, "5")]));
        log_waiting(&waiting, &routes, &counts, &inlet.drops);
        assert_eq!(counts.undecoded.load(Ordering::Relaxed), 1);
        assert_eq!(counts.missing.load(Ordering::Relaxed), 0);
        // A gap with nothing dropped between: counted.
        inlet.push(&node, batch(&[("a.out", 9, "6")]));
        log_waiting(&waiting, &routes, &counts, &inlet.drops);
        assert_eq!(counts.missing.load(Ordering::Relaxed), 2);
        // The node goes: nothing of it is kept.
        assert_eq!(inlet.drops.lock().len(), 1);
        inlet.forget(&node);
        assert!(inlet.drops.lock().is_empty());
    }

    /// A node that goes and comes back under its name while a batch of its earlier
    /// life still waits, and a callback of the earlier subscription drops one more
    /// after the new one began: neither reads nor moves the drops of the new
    /// subscription, whose dropped batches are counted once.
    #[test]
    fn a_batch_of_a_nodes_earlier_life_does_not_hide_a_drop_of_the_next() {
        let counts = Arc::new(Counts::default());
        let (inlet, waiting) = queue(2, Arc::clone(&counts));
        let context = Context::new();
        let routes = Routes::default();
        let earlier: Arc<str> = Arc::from("n");
        inlet.push(
            &earlier,
            ZBytes::from("x".repeat(crate::limits::ECHO_BATCH.max + 1)),
        );
        inlet.push(&earlier, batch(&[("a.out", 7, "1")]));
        assert_eq!(counts.undecoded.load(Ordering::Relaxed), 1);
        // The node goes (its batch still queued) and comes back: a new subscription.
        inlet.forget("n");
        routes.add(
            "n",
            "a.out",
            route(&context, "/n/a.out", Transform::Raw { wrap: true }),
        );
        let later: Arc<str> = Arc::from("n");
        inlet.push(&later, batch(&[("a.out", 0, "1")]));
        // The queue is full: the next batch (numbers 1 and 2) is dropped, counted.
        inlet.push(&later, batch(&[("a.out", 1, "2"), ("a.out", 2, "3")]));
        assert_eq!(counts.overflowed.load(Ordering::Relaxed), 1);
        // A callback of the earlier subscription, still running, drops one more.
        inlet.push(
            &earlier,
            ZBytes::from("x".repeat(crate::limits::ECHO_BATCH.max + 1)),
        );
        assert_eq!(counts.undecoded.load(Ordering::Relaxed), 2);
        log_waiting(&waiting, &routes, &counts, &inlet.drops);
        inlet.push(&later, batch(&[("a.out", 3, "4")]));
        log_waiting(&waiting, &routes, &counts, &inlet.drops);
        assert_eq!(
            counts.missing.load(Ordering::Relaxed),
            0,
            "the dropped batch is counted once, where it was dropped"
        );
    }

    /// The packets of a served output that never came (numbers missing) are counted,
    /// and so is one its node could not echo (its place in the batch says so), the
    /// last one too; neither is logged.
    #[test]
    fn packets_missing_or_not_echoed_are_counted() {
        let counts = Arc::new(Counts::default());
        let (inlet, waiting) = queue(4, Arc::clone(&counts));
        let context = Context::new();
        let kept = Arc::new(Kept {
            id: SinkId::next(),
            logged: Mutex::new(Vec::new()),
        });
        context.add_sink(kept.clone());
        let routes = Routes::default();
        routes.add(
            "n",
            "a.out",
            route(&context, "/n/a.out", Transform::Raw { wrap: true }),
        );
        let node: Arc<str> = Arc::from("n");
        inlet.push(&node, batch(&[("a.out", 3, "1"), ("a.out", 6, "2")]));
        let unsent = format!(
            r#"[{{"output":"a.out","seq":7,"dropped":0,"sent":{SENT},"packet":null,"unsent":"too large"}}]"#
        );
        inlet.push(&node, ZBytes::from(unsent));
        log_waiting(&waiting, &routes, &counts, &inlet.drops);
        let logged: Vec<String> = kept
            .logged
            .lock()
            .unwrap()
            .iter()
            .map(|(_, message, _)| message.clone())
            .collect();
        assert_eq!(logged, [r#"{"value":1}"#, r#"{"value":2}"#]);
        assert_eq!(counts.missing.load(Ordering::Relaxed), 2);
        assert_eq!(counts.unechoed.load(Ordering::Relaxed), 1);
    }

    /// A batch over `ECHO_BATCH` is dropped and counted as it comes: it never waits
    /// in the queue.
    #[test]
    fn a_batch_over_its_bound_is_dropped_before_it_is_queued() {
        let counts = Arc::new(Counts::default());
        let (inlet, waiting) = queue(4, Arc::clone(&counts));
        let node: Arc<str> = Arc::from("n");
        let over = vec![b' '; crate::limits::ECHO_BATCH.max + 1];
        inlet.push(&node, ZBytes::from(over));
        assert_eq!(counts.undecoded.load(Ordering::Relaxed), 1);
        assert!(waiting.is_empty(), "a batch over the bound waits");
        inlet.push(&node, batch(&[("a.out", 0, "1")]));
        assert_eq!(waiting.len(), 1);
    }

    /// The feed sleeps until a batch comes and logs it at once; then it takes what
    /// waits at most once a tick: a batch that comes within the tick waits for its
    /// end.
    #[test]
    fn the_feed_takes_a_batch_at_once_then_at_most_once_a_tick() {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_time()
            .start_paused(true)
            .build()
            .unwrap();
        let context = Context::new();
        let kept = Arc::new(Kept {
            id: SinkId::next(),
            logged: Mutex::new(Vec::new()),
        });
        context.add_sink(kept.clone());
        let feed = Feed::start(runtime.handle(), Arc::new(Counts::default()));
        let route = route(&context, "/n/a.out", Transform::Raw { wrap: false });
        feed.routes().add("n", "a.out", route);
        let node: Arc<str> = Arc::from("n");
        let logged = || kept.logged.lock().unwrap().len();
        // Runs what is ready on the runtime, the clock standing still.
        let settle = || {
            runtime.block_on(async {
                for _ in 0..10 {
                    tokio::task::yield_now().await;
                }
            })
        };
        settle();
        feed.inlet().push(&node, batch(&[("a.out", 0, "1")]));
        settle();
        assert_eq!(logged(), 1, "at once");
        feed.inlet().push(&node, batch(&[("a.out", 1, "2")]));
        settle();
        assert_eq!(logged(), 1, "within the tick");
        runtime.block_on(tokio::time::advance(FEED_TICK - Duration::from_millis(1)));
        settle();
        assert_eq!(logged(), 1, "still within the tick");
        runtime.block_on(tokio::time::advance(Duration::from_millis(1)));
        settle();
        assert_eq!(logged(), 2, "at the tick's end");
    }

    /// A node's last route gone, it has none; another output's keep it.
    #[test]
    fn a_node_has_routes_until_its_last_is_removed() {
        let context = Context::new();
        let routes = Routes::default();
        let (a, b) = (
            route(&context, "/n/a.out", Transform::Raw { wrap: false }),
            route(&context, "/n/b.out", Transform::Raw { wrap: false }),
        );
        let (a_id, b_id) = (a.channel.id(), b.channel.id());
        routes.add("n", "a.out", a);
        routes.add("n", "b.out", b);
        assert!(!routes.remove("n", "a.out", a_id));
        assert!(routes.remove("n", "b.out", b_id));
        assert!(routes.remove("n", "b.out", b_id), "none left, still");
    }
}
