//! The way from the echoed outputs to the WebSocket. Zenoh's callback only queues
//! each echoed packet as it came (its payload shared, not copied); a task on the
//! WebSocket server's own runtime takes what waits every [`FEED_TICK`], makes each
//! packet its channel's message and logs it. The messages of a tick reach the
//! server's client tasks on the thread that runs them, which wakes once per tick
//! rather than once per message; nothing waits on the queue, so Zenoh's thread wakes
//! no thread either. **Invariant:** nothing is lost silently: a packet that finds the
//! queue full, or that does not decode or fit its channel, is dropped, counted
//! ([`super::Counts`]) and warned about (rate-limited).

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use crossbeam_channel::{Receiver, Sender, TrySendError};
use foxglove::RawChannel;
use zenoh::bytes::ZBytes;

use super::Counts;
use super::wellknown::Transform;
use crate::echo::EchoedRaw;

/// How often the feed logs what waits.
pub const FEED_TICK: Duration = Duration::from_millis(10);

/// How many echoed packets wait for the feed before the newest are dropped.
pub const FEED_CAPACITY: usize = 4096;

/// Where an echoed output's packets go: its channel, and what makes them messages.
pub(super) struct Route {
    pub(super) channel: Arc<RawChannel>,
    pub(super) transform: Transform,
}

/// An echoed packet waiting, with its route.
type Waiting = (Arc<Route>, ZBytes);

/// The queue's end that Zenoh's callbacks hold.
#[derive(Clone)]
pub(super) struct Inlet {
    sender: Sender<Waiting>,
    counts: Arc<Counts>,
}

impl Inlet {
    /// Queue `payload`, an echoed packet for `route`; count it dropped if the queue is
    /// full.
    pub(super) fn push(&self, route: &Arc<Route>, payload: ZBytes) {
        if let Err(TrySendError::Full(_)) = self.sender.try_send((Arc::clone(route), payload)) {
            self.counts.overflowed.fetch_add(1, Ordering::Relaxed);
            let topic = route.channel.topic();
            coolbot::limited!("foxglove:feed", |held| tracing::warn!(
                "the server falls behind: a packet for {topic} is dropped{held}"
            ));
        }
    }
}

/// The queue and the task that takes from it; dropping it ends the task.
pub(super) struct Feed {
    inlet: Inlet,
    task: tokio::task::JoinHandle<()>,
}

impl Feed {
    /// Start the feed's task on `runtime` (the WebSocket server's), counting in
    /// `counts`.
    pub(super) fn start(runtime: &tokio::runtime::Handle, counts: Arc<Counts>) -> Feed {
        let (inlet, waiting) = queue(FEED_CAPACITY, counts);
        let counts = Arc::clone(&inlet.counts);
        let task = runtime.spawn(async move {
            let mut ticks = tokio::time::interval(FEED_TICK);
            ticks.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
            loop {
                ticks.tick().await;
                log_waiting(&waiting, &counts);
            }
        });
        Feed { inlet, task }
    }

    /// The end to queue on.
    pub(super) fn inlet(&self) -> Inlet {
        self.inlet.clone()
    }
}

impl Drop for Feed {
    fn drop(&mut self) {
        self.task.abort();
    }
}

/// A queue of `capacity` packets: its inlet, and the end [`log_waiting`] takes from.
fn queue(capacity: usize, counts: Arc<Counts>) -> (Inlet, Receiver<Waiting>) {
    let (sender, receiver) = crossbeam_channel::bounded(capacity);
    (Inlet { sender, counts }, receiver)
}

/// Log every packet waiting on its channel, as its message.
fn log_waiting(waiting: &Receiver<Waiting>, counts: &Counts) {
    for (route, payload) in waiting.try_iter() {
        if let Err(error) = message(&route, &payload) {
            counts.undecoded.fetch_add(1, Ordering::Relaxed);
            let topic = route.channel.topic();
            coolbot::limited!(topic, |held| tracing::warn!(
                "an echoed packet for {topic} does not fit (dropped): {error}{held}"
            ));
        }
    }
}

/// Log the echoed packet `payload` on `route`'s channel.
fn message(route: &Route, payload: &ZBytes) -> Result<(), String> {
    let payload = payload.to_bytes();
    let echoed = serde_json::from_slice::<EchoedRaw<'_>>(&payload).map_err(|e| e.to_string())?;
    let message = route.transform.message(echoed.packet)?;
    route.channel.log(&message);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn route() -> Arc<Route> {
        let context = foxglove::Context::new();
        let channel = context
            .channel_builder("/test")
            .message_encoding("json")
            .build_raw()
            .expect("a channel");
        Arc::new(Route {
            channel,
            transform: Transform::Raw { wrap: false },
        })
    }

    /// Packets beyond the queue's capacity are dropped and counted; those queued are
    /// taken at the next tick, and one that does not decode is counted too.
    #[test]
    fn a_full_queue_drops_and_counts_and_a_packet_that_does_not_decode_is_counted() {
        let counts = Arc::new(Counts::default());
        let (inlet, waiting) = queue(4, Arc::clone(&counts));
        let route = route();
        let good = ZBytes::from(r#"{"seq":0,"dropped":0,"packet":{"x":1}}"#);
        for _ in 0..3 {
            inlet.push(&route, good.clone());
        }
        inlet.push(&route, ZBytes::from("not JSON"));
        for _ in 0..2 {
            inlet.push(&route, good.clone());
        }
        assert_eq!(counts.overflowed.load(Ordering::Relaxed), 2);
        assert_eq!(waiting.len(), 4);
        log_waiting(&waiting, &counts);
        assert!(waiting.is_empty());
        assert_eq!(counts.undecoded.load(Ordering::Relaxed), 1);
        assert_eq!(counts.overflowed.load(Ordering::Relaxed), 2);
    }
}
