//! A producer much faster than its consumer: 10^6 packets, and every one is accounted
//! for (received + counted overflow = sent), for each overflow policy and for ufifo.
//! The worker's fifo of 64 is declared with each policy (`cool/overflow_stress.cool`);
//! its overflow count is read by the worker's behaviour, which the monitor must match.

use std::sync::atomic::Ordering;

use coolbot::{Component, Controllable, System};
use coolbot_runtime_tests::generated::{os_block_worker, os_drop_oldest_worker, os_reject_worker};
use coolbot_runtime_tests::support::{Rig, Script, Scripted, WORKER, eventually};

const SENT: u64 = 1_000_000;

/// A started rig around `component`, made for `script`, in `running`.
fn running(script: std::sync::Arc<Script>, component: Component) -> Rig {
    let rig = Rig::start(Rig::with(System::new(), script, component));
    rig.command(Controllable::Running).expect("running");
    rig.wait_user("idle");
    rig
}

/// Packets received plus overflows counted, as the worker's behaviour saw them.
fn accounted(rig: &Rig) -> u64 {
    rig.script.received.load(Ordering::SeqCst) + rig.script.data_overflows.load(Ordering::SeqCst)
}

fn flood(script: std::sync::Arc<Script>, component: Component, sent: u64) {
    let rig = running(script, component);
    // The worker drains its fifo on entering `busy` and then every 5 ms: far slower
    // than this loop.
    for packet in 0..sent {
        rig.feeder().data.send(packet);
    }
    eventually(
        || accounted(&rig) == sent,
        "every packet received or counted",
    );
    let monitor = rig.handle.snapshot();
    let overflows = rig.script.data_overflows.load(Ordering::SeqCst);
    assert_eq!(monitor.overflows, overflows);
    assert!(overflows > 0, "the consumer was slower");
    assert_eq!(accounted(&rig), sent);
}

#[test]
fn reject_accounts_for_every_packet() {
    let script = Script::new();
    let component = os_reject_worker::component(WORKER, Scripted::new(&script));
    flood(script, component, SENT);
}

#[test]
fn drop_oldest_accounts_for_every_packet() {
    let script = Script::new();
    let component = os_drop_oldest_worker::component(WORKER, Scripted::new(&script));
    flood(script, component, SENT);
}

#[test]
fn block_accounts_for_every_packet() {
    // A blocked producer waits for the 5 ms consumer (up to the 100 ms a `block` fifo
    // waits), so fewer packets keep this short.
    let script = Script::new();
    let component = os_block_worker::component(WORKER, Scripted::new(&script));
    let rig = running(script, component);
    let sent = 10_000;
    for packet in 0..sent {
        rig.feeder().data.send(packet);
    }
    eventually(
        || accounted(&rig) == sent,
        "every packet received or counted",
    );
    assert_eq!(
        rig.handle.snapshot().overflows,
        rig.script.data_overflows.load(Ordering::SeqCst)
    );
}
