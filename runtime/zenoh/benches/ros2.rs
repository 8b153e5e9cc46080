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

use std::sync::OnceLock;
use std::time::{Duration, Instant};

use coolbot::port::{DataOut, FifoIn, TickIn, TickOut};
use coolbot::ros::RosType;
use coolbot::{Component, InputKind, OutputKind, OverflowPolicy, PortSet, Section, System};
use coolbot_zenoh::Node;
use coolbot_zenoh::ros2::{Participant, RosOptions};
use crossbeam_channel::{Receiver, Sender, bounded};
use serde::{Deserialize, Serialize};

use common::{Figure, Glue, Goal, Mode, Samples, Table};
use setup::{nodes, state_directory, wait_subscribed};

/// Round trips discarded at the start of every round.
const WARMUP: usize = 100;
/// Rounds of each side, alternated.
const ROUNDS: usize = 10;

const QUEUE: InputKind = InputKind::Fifo {
    capacity: 4,
    policy: OverflowPolicy::Reject,
};

one_state_spec! {
    static PING_SPEC = "Ping",
    inputs: [("input", QUEUE), ("kick", InputKind::Tick)],
    outputs: [("output", OutputKind::Data)],
    on: [0, 1],
    periodic: None,
}

one_state_spec! {
    static PONG_SPEC = "Pong",
    inputs: [("input", QUEUE)],
    outputs: [("output", OutputKind::Data)],
    on: [0],
    periodic: None,
}

one_state_spec! {
    static KICK_SPEC = "Kick",
    inputs: [],
    outputs: [("kick", OutputKind::Tick)],
    on: [],
    periodic: None,
}

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

/// A packet that carries a stamp.
trait Stamped: coolbot::Packet + Serialize + serde::de::DeserializeOwned + RosType {
    fn at(nanos: u64) -> Self;
    fn nanos(&self) -> u64;
}

impl Stamped for Stamp {
    fn at(nanos: u64) -> Stamp {
        Stamp { nanos }
    }
    fn nanos(&self) -> u64 {
        self.nanos
    }
}

/// Stamps are nanoseconds since one instant of this process (both ends are in it).
fn stamp() -> u64 {
    static BASE: OnceLock<Instant> = OnceLock::new();
    BASE.get_or_init(Instant::now).elapsed().as_nanos() as u64
}

fn since(stamp_ns: u64) -> Duration {
    Duration::from_nanos(stamp().saturating_sub(stamp_ns))
}

/// The pinging side: on a kick, runs `per_round + WARMUP` round trips and sends the
/// samples (warm-up dropped) on `done`.
fn ping<P: Stamped>(per_round: usize, done: Sender<Vec<Duration>>) -> Component {
    let input = FifoIn::<P>::new(4, OverflowPolicy::Reject);
    let kick = TickIn::new();
    let output = DataOut::<P>::new();
    let ports = PortSet::new().input(&input).input(&kick).output(&output);
    let mut samples = Vec::with_capacity(per_round + WARMUP);
    let mut remaining = 0usize;
    let mut in_flight = false;
    let body = Box::new(move |section: Section, _: &mut coolbot::Context| {
        if section != Section::Entry {
            return Ok(());
        }
        if kick.take() > 0 {
            remaining = per_round + WARMUP;
            samples.clear();
        }
        if let Some(sent) = input.recv() {
            samples.push(since(sent.nanos()) / 2);
            in_flight = false;
        }
        if !in_flight {
            if remaining > 0 {
                remaining -= 1;
                in_flight = true;
                output.send(P::at(stamp()));
            } else if samples.len() == per_round + WARMUP {
                let _ = done.send(samples.split_off(WARMUP));
                samples.clear();
            }
        }
        Ok(())
    });
    Component::new("ping", Glue::boxed(&PING_SPEC, body), ports)
}

/// The echo side: sends back every stamp it takes.
fn pong<P: Stamped>() -> Component {
    let input = FifoIn::<P>::new(4, OverflowPolicy::Reject);
    let output = DataOut::<P>::new();
    let ports = PortSet::new().input(&input).output(&output);
    let body = Box::new(move |section: Section, _: &mut coolbot::Context| {
        if section == Section::Entry {
            while let Some(stamp) = input.recv() {
                output.send(stamp);
            }
        }
        Ok(())
    });
    Component::new("pong", Glue::boxed(&PONG_SPEC, body), ports)
}

/// One side: ping on node a, pong on node b, one hop each way.
struct Side {
    kick: TickOut,
    samples: Receiver<Vec<Duration>>,
    systems: (System, System),
}

/// The systems of a side, ping's (with its kicker) and pong's, before their hops.
fn side(per_round: usize) -> (System, System, TickOut, Receiver<Vec<Duration>>) {
    let (done, samples) = bounded(1);
    let kick = TickOut::new();
    let mut near = System::new();
    near.add(ping::<Stamp>(per_round, done)).expect("ping");
    near.add(Component::new(
        "kicker",
        Glue::boxed(&KICK_SPEC, Box::new(|_, _| Ok(()))),
        PortSet::new().output(&kick),
    ))
    .expect("kicker");
    near.connect("kicker.kick", "ping.kick").expect("connect");
    let mut far = System::new();
    far.add(pong::<Stamp>()).expect("pong");
    (near, far, kick, samples)
}

/// The ROS 2 side: a participant on each node's session, `/ping` and `/pong` topics.
fn ros_side(a: &Node, b: &Node, per_round: usize) -> Side {
    let (mut near, mut far, kick, samples) = side(per_round);
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
        kick,
        samples,
        systems: (near, far),
    }
}

/// The bridge side: outlets and inlets on `bench/ping` and `bench/pong`.
fn bridge_side(a: &Node, b: &Node, per_round: usize) -> Side {
    let bridge = InputKind::Fifo {
        capacity: 64,
        policy: OverflowPolicy::Reject,
    };
    let (mut near, mut far, kick, samples) = side(per_round);
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
        kick,
        samples,
        systems: (near, far),
    }
}

fn round(side: &Side, what: &str) -> Vec<Duration> {
    side.kick.emit();
    common::expect(&side.samples, Duration::from_secs(120), what)
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
        || round(&ros, "ROS 2 ping-pong"),
        || round(&bridge, "bridge ping-pong"),
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
