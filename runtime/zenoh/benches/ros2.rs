//! One-way latency of a ROS 2 topic hop (`coolbot_zenoh::ros2`: a publisher and a
//! subscription, CDR and rmw_zenoh's attachment) against a hop through our own Zenoh
//! bridge (an outlet and an inlet, postcard), on the same link: ping-pong between two
//! components on two nodes, one hop each way, both measured in one run. One process,
//! two sessions connected over loopback TCP (explicit endpoints, multicast scouting
//! off). One-way latency is half a round trip; every round trip is a sample.
//!
//! `cargo bench -p coolbot-zenoh --bench ros2` (add `-- --quick` for a smoke run).

#[path = "../../benches/common/mod.rs"]
#[macro_use]
mod common;
mod setup;

use coolbot::ros::RosType;
use coolbot::{Component, InputKind, OutputKind, OverflowPolicy, System};
use coolbot_zenoh::Node;
use coolbot_zenoh::ros2::{Participant, RosOptions};
use serde::{Deserialize, Serialize};

use common::{Figure, Goal, Mode, Samples, Table};
use setup::pingpong::{Pace, Pinger, Stamped, pong};
use setup::{nodes, state_directory, wait_subscribed};

/// Round trips discarded at the start of every round.
const WARMUP: usize = 100;
/// Rounds of each side, alternated.
const ROUNDS: usize = 10;

/// The packet both hops carry: a stamp, as a ROS 2 message type of one `uint64`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Stamp {
    nanos: u64,
}

impl RosType for Stamp {
    const NAME: &'static str = "coolbot_bench/msg/Stamp";
    const DDS_NAME: &'static str = "coolbot_bench::msg::dds_::Stamp_";
    const TYPE_HASH: &'static str =
        "RIHS01_0000000000000000000000000000000000000000000000000000000000000000";
    const MESSAGE_DEFINITION: &'static str = "uint64 nanos\n";
}

impl Stamped for Stamp {
    fn at(nanos: u64) -> Stamp {
        Stamp { nanos }
    }
    fn nanos(&self) -> u64 {
        self.nanos
    }
}

/// One side: ping on node a, pong on node b, one hop each way.
struct Side {
    pinger: Pinger,
    systems: (System, System),
}

/// The systems of a side, ping's (with its kicker) and pong's, before their hops.
fn side(per_round: usize) -> (System, System, Pinger) {
    let mut near = System::new();
    let pinger = Pinger::add::<Stamp>(&mut near, "", Pace::Burst, per_round, WARMUP);
    let mut far = System::new();
    far.add(pong::<Stamp>("pong")).expect("pong");
    (near, far, pinger)
}

/// The ROS 2 side: a participant on each node's session, `/ping` and `/pong` topics.
fn ros_side(a: &Node, b: &Node, per_round: usize) -> Side {
    let (mut near, mut far, pinger) = side(per_round);
    let options = |node: &str| RosOptions {
        domain: 42,
        node: node.to_owned(),
        ..RosOptions::default()
    };
    let ros_a = Participant::open(a.session(), &options("near")).expect("participant");
    let ros_b = Participant::open(b.session(), &options("far")).expect("participant");
    ros_a
        .publish::<Stamp>(&mut near, "/ping", "ping.output")
        .expect("publish");
    ros_a
        .subscribe::<Stamp>(&mut near, "/pong", "ping.input")
        .expect("subscribe");
    ros_b
        .subscribe::<Stamp>(&mut far, "/ping", "pong.input")
        .expect("subscribe");
    ros_b
        .publish::<Stamp>(&mut far, "/pong", "pong.output")
        .expect("publish");
    far.run_all().expect("run far");
    near.run_all().expect("run near");
    let key = |topic: &str| format!("42/{topic}/{}/{}", Stamp::DDS_NAME, Stamp::TYPE_HASH);
    wait_subscribed(a.session(), &key("ping"));
    wait_subscribed(b.session(), &key("pong"));
    Side {
        pinger,
        systems: (near, far),
    }
}

/// The bridge side: outlets and inlets on `bench/ping` and `bench/pong`.
fn bridge_side(a: &Node, b: &Node, per_round: usize) -> Side {
    let bridge = InputKind::Fifo {
        capacity: 64,
        policy: OverflowPolicy::Reject,
    };
    let (mut near, mut far, pinger) = side(per_round);
    let built = |component: Result<Component, coolbot_zenoh::Error>| component.expect("bridge");
    near.add(built(
        a.outlet::<Stamp>("to_pong", "bench/ping", bridge).build(),
    ))
    .expect("outlet");
    near.add(built(
        a.inlet::<Stamp>("from_pong", "bench/pong", OutputKind::Data)
            .build(),
    ))
    .expect("inlet");
    near.connect("ping.output", "to_pong.input")
        .expect("connect");
    near.connect("from_pong.output", "ping.input")
        .expect("connect");
    far.add(built(
        b.inlet::<Stamp>("from_ping", "bench/ping", OutputKind::Data)
            .build(),
    ))
    .expect("inlet");
    far.add(built(
        b.outlet::<Stamp>("to_ping", "bench/pong", bridge).build(),
    ))
    .expect("outlet");
    far.connect("from_ping.output", "pong.input")
        .expect("connect");
    far.connect("pong.output", "to_ping.input")
        .expect("connect");
    far.run_all().expect("run far");
    near.run_all().expect("run near");
    wait_subscribed(a.session(), "bench/ping");
    wait_subscribed(b.session(), "bench/pong");
    Side {
        pinger,
        systems: (near, far),
    }
}

fn main() {
    let mode = Mode::from_env();
    let per_round = mode.scale(10_000, 1_000) / ROUNDS;
    let mut table = Table::new(
        "One-way latency of a ROS 2 topic hop vs a CoolBOT bridge hop on the same link (ping-pong, half round trip)",
        mode,
    );
    // Declared first, removed last (after the outlets).
    let state = state_directory();
    let (a, b) = nodes(state.path());
    let ros = ros_side(&a, &b, per_round);
    let bridge = bridge_side(&a, &b, per_round);
    let (ros_samples, bridge_samples) = common::alternate(
        ROUNDS,
        || ros.pinger.round("ROS 2 ping-pong"),
        || bridge.pinger.round("bridge ping-pong"),
    );
    let (ros_samples, bridge_samples) = (Samples::new(ros_samples), Samples::new(bridge_samples));
    table.row(
        "ROS 2 hop p50",
        Figure::Time(ros_samples.p50()),
        Figure::Time(bridge_samples.p50()),
        // The goal: a ROS 2 topic within 1.2x of the project's own bridge.
        Goal::AtMost(1.2),
    );
    table.row(
        "ROS 2 hop p99",
        Figure::Time(ros_samples.p99()),
        Figure::Time(bridge_samples.p99()),
        Goal::None,
    );
    table.note(&format!(
        "{} samples per side; max ROS 2 {:?}, bridge {:?}",
        ros_samples.len(),
        ros_samples.max(),
        bridge_samples.max()
    ));
    table.print();
    for side in [ros, bridge] {
        let (near, far) = side.systems;
        assert!(near.shutdown().clean(), "unclean shutdown");
        assert!(far.shutdown().clean(), "unclean shutdown");
    }
}
