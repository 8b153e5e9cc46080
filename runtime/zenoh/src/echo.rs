//! Echoed outputs (`coolctl echo`): a node taps an output it was asked to echo
//! ([`crate::Node::echo`], a `coolbot::tap::Tap`) and publishes each packet as JSON on
//! `coolbot/<node>/<path>/o/<port>`, from a thread of its own. **Invariant:** the
//! producer is never slowed: the tap drops a packet its queue has no room for
//! (counted), and publishing drops rather than waits when the network is congested;
//! every message carries the packet's sequence number and the node's drop count, so
//! a subscriber counts every packet it did not get.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use coolbot::port::Packet;
use coolbot::tap::Tap;
use serde::{Deserialize, Serialize};
use zenoh::Wait;

use crate::Error;

/// How many packets wait in an echo's tap before the newest are dropped.
pub const ECHO_CAPACITY: usize = 256;

/// How often the echo thread looks whether it is to stop.
const STOP_POLL: Duration = Duration::from_millis(100);

/// One echoed packet on the network.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Echoed {
    /// The packet's number among those the output sent since the echo began (0 first);
    /// a gap is packets this subscriber did not get.
    pub seq: u64,
    /// Packets the node dropped so far because its echo queue was full.
    pub dropped: u64,
    /// The packet, as serde writes it in JSON.
    pub packet: serde_json::Value,
}

/// A running echo: its thread ends (joined) when this is dropped.
pub(crate) struct Echo {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Drop for Echo {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

impl Echo {
    /// Publish every packet of `tap` on `key`, until dropped.
    pub(crate) fn start<T: Packet + Serialize>(
        session: &zenoh::Session,
        key: String,
        tap: Tap<T>,
    ) -> Result<Echo, Error> {
        let publisher = session
            .declare_publisher(key.clone())
            .congestion_control(zenoh::qos::CongestionControl::Drop)
            .wait()
            .map_err(Error::zenoh("declare the echo publisher"))?;
        let stop = Arc::new(AtomicBool::new(false));
        let stopped = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name(format!("cool-net:echo:{key}"))
            .spawn(move || {
                while !stopped.load(Ordering::Acquire) {
                    let Ok((seq, packet)) = tap.receiver().recv_timeout(STOP_POLL) else {
                        continue;
                    };
                    let message = match serde_json::to_value(&packet) {
                        Ok(packet) => Echoed {
                            seq,
                            dropped: tap.dropped(),
                            packet,
                        },
                        Err(error) => {
                            coolbot::limited!(&key, |held| tracing::warn!(%key, "packet {seq} does not serialize: {error}{held}"));
                            continue;
                        }
                    };
                    match serde_json::to_vec(&message) {
                        Ok(json) => {
                            if let Err(error) = publisher.put(json).wait() {
                                coolbot::limited!(&key, |held| tracing::warn!(%key, "echo not published: {}{held}", coolbot::Chain(&*error)));
                            }
                        }
                        Err(error) => coolbot::limited!(&key, |held| tracing::warn!(%key, "echo does not encode: {error}{held}")),
                    }
                }
            })
            .map_err(Error::spawn("echo"))?;
        Ok(Echo {
            stop,
            thread: Some(thread),
        })
    }
}
