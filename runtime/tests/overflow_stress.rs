//! A producer much faster than its consumer: 10^6 packets, and every one is accounted
//! for (received + counted overflow = sent), for each overflow policy and for ufifo.

mod support;

use std::sync::atomic::Ordering;

use coolbot::port::FifoIn;
use coolbot::{Controllable, OverflowPolicy};
use support::{Rig, Script, eventually, worker};

const SENT: u64 = 1_000_000;

fn flood(policy: OverflowPolicy, sent: u64) {
    let data = FifoIn::new(64, policy);
    let rig = Rig::start(Rig::unstarted_with(
        Script::new(),
        &worker::SPEC,
        data,
        None,
    ));
    rig.command(Controllable::Running).expect("running");
    rig.wait_user("idle");
    // The worker drains its fifo on entering `busy` and then every 5 ms: far slower
    // than this loop.
    for packet in 0..sent {
        rig.feeder.data.send(packet);
    }
    let accounted = || rig.script.received.load(Ordering::SeqCst) + rig.inputs.data.overflows();
    eventually(|| accounted() == sent, "every packet received or counted");
    let monitor = rig.handle.snapshot();
    assert_eq!(monitor.overflows, rig.inputs.data.overflows());
    assert!(rig.inputs.data.overflows() > 0, "the consumer was slower");
    assert_eq!(accounted(), sent);
}

#[test]
fn reject_accounts_for_every_packet() {
    flood(OverflowPolicy::Reject, SENT);
}

#[test]
fn drop_oldest_accounts_for_every_packet() {
    flood(OverflowPolicy::DropOldest, SENT);
}

#[test]
fn block_accounts_for_every_packet() {
    // A blocked producer waits for the 5 ms consumer, so fewer packets keep this short.
    let data = FifoIn::with_block_timeout(
        64,
        OverflowPolicy::Block,
        std::time::Duration::from_millis(1),
    );
    let rig = Rig::start(Rig::unstarted_with(
        Script::new(),
        &worker::SPEC,
        data,
        None,
    ));
    rig.command(Controllable::Running).expect("running");
    rig.wait_user("idle");
    let sent = 10_000;
    for packet in 0..sent {
        rig.feeder.data.send(packet);
    }
    let accounted = || rig.script.received.load(Ordering::SeqCst) + rig.inputs.data.overflows();
    eventually(|| accounted() == sent, "every packet received or counted");
    assert_eq!(rig.handle.snapshot().overflows, rig.inputs.data.overflows());
}
