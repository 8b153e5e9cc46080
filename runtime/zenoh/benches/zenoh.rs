//! One-way latency over the network: ping-pong between two components on two nodes
//! through Zenoh bridges (an outlet and an inlet each way, fifo connections), against
//! raw Zenoh pub/sub ping-pong between two bare threads on the same two sessions. One
//! process, two sessions connected over loopback TCP (explicit endpoints, multicast
//! scouting off). One-way latency is half a round trip; every round trip is a sample.
//!
//! `cargo bench -p coolbot-zenoh --bench zenoh` (add `-- --quick` for a smoke run).

#[path = "../../benches/common/mod.rs"]
#[macro_use]
mod common;
mod setup;

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use coolbot::{InputKind, OutputKind, OverflowPolicy, System};
use coolbot_zenoh::Node;
use zenoh::Wait;

use common::{Figure, Goal, Mode, Samples, Table};
use setup::pingpong::{Pace, Pinger, pong, since, stamp};

/// Round trips discarded at the start of every round.
const WARMUP: usize = 100;
/// Rounds of project and baseline, alternated.
const ROUNDS: usize = 10;

/// The project: ping on node a, pong on node b, bridged both ways.
struct Project {
    pinger: Pinger,
    systems: (System, System),
}

fn project(a: &Node, b: &Node, per_round: usize) -> Project {
    let bridge = InputKind::Fifo {
        capacity: 16,
        policy: OverflowPolicy::Block,
    };
    let mut near = System::new();
    let pinger = Pinger::add::<u64>(&mut near, "", Pace::Burst, per_round, WARMUP);
    near.add(
        a.outlet::<u64>("to_pong", "bench/ping", bridge)
            .build()
            .expect("outlet"),
    )
    .expect("outlet");
    near.add(
        a.inlet::<u64>("from_pong", "bench/pong", OutputKind::Data)
            .build()
            .expect("inlet"),
    )
    .expect("inlet");
    near.connect("ping.output", "to_pong.input")
        .expect("connect");
    near.connect("from_pong.output", "ping.input")
        .expect("connect");

    let mut far = System::new();
    far.add(pong::<u64>("pong")).expect("pong");
    far.add(
        b.inlet::<u64>("from_ping", "bench/ping", OutputKind::Data)
            .build()
            .expect("inlet"),
    )
    .expect("inlet");
    far.add(
        b.outlet::<u64>("to_ping", "bench/pong", bridge)
            .build()
            .expect("outlet"),
    )
    .expect("outlet");
    far.connect("from_ping.output", "pong.input")
        .expect("connect");
    far.connect("pong.output", "to_ping.input")
        .expect("connect");
    far.run_all().expect("run far");
    near.run_all().expect("run near");
    setup::wait_subscribed(a.session(), "bench/ping");
    setup::wait_subscribed(b.session(), "bench/pong");
    Project {
        pinger,
        systems: (near, far),
    }
}

/// The baseline: raw Zenoh on the same two sessions, an echo thread on b.
struct Baseline {
    to_echo: zenoh::pubsub::Publisher<'static>,
    back: zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
    stop: Arc<AtomicBool>,
    echo: Option<std::thread::JoinHandle<()>>,
}

impl Drop for Baseline {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(echo) = self.echo.take() {
            let _ = echo.join();
        }
    }
}

fn baseline(a: &Node, b: &Node) -> Baseline {
    let echo_in = b
        .session()
        .declare_subscriber("bench/raw/ping")
        .wait()
        .expect("subscriber");
    let echo_out = b
        .session()
        .declare_publisher("bench/raw/pong")
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .wait()
        .expect("publisher");
    let back = a
        .session()
        .declare_subscriber("bench/raw/pong")
        .wait()
        .expect("subscriber");
    let to_echo = a
        .session()
        .declare_publisher("bench/raw/ping")
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .wait()
        .expect("publisher");
    let stop = Arc::new(AtomicBool::new(false));
    let stopped = Arc::clone(&stop);
    let echo = std::thread::spawn(move || {
        while !stopped.load(Ordering::Acquire) {
            if let Ok(Some(sample)) = echo_in.recv_timeout(Duration::from_millis(100)) {
                echo_out.put(sample.payload().clone()).wait().expect("echo");
            }
        }
    });
    setup::wait_subscribed(a.session(), "bench/raw/ping");
    setup::wait_subscribed(b.session(), "bench/raw/pong");
    Baseline {
        to_echo,
        back,
        stop,
        echo: Some(echo),
    }
}

fn baseline_round(baseline: &Baseline, per_round: usize) -> Vec<Duration> {
    let mut samples = Vec::with_capacity(per_round + WARMUP);
    for _ in 0..per_round + WARMUP {
        let bytes = postcard::to_allocvec(&stamp()).expect("encode");
        baseline.to_echo.put(bytes).wait().expect("put");
        let sample = baseline.back.recv().expect("echo alive");
        let sent: u64 = postcard::from_bytes(&sample.payload().to_bytes()).expect("decode");
        samples.push(since(sent) / 2);
    }
    samples.split_off(WARMUP)
}

fn main() {
    let mode = Mode::from_env();
    let per_round = mode.scale(10_000, 1_000) / ROUNDS;
    let mut table = Table::new(
        "One-way latency over Zenoh, ping-pong (half round trip): components through bridges vs raw pub/sub",
        mode,
    );
    // Declared first, removed last (after the outlets).
    let state = setup::state_directory();
    let (a, b) = setup::nodes(state.path());
    let project = project(&a, &b, per_round);
    let baseline = baseline(&a, &b);
    let (project_samples, baseline_samples) = common::alternate(
        ROUNDS,
        || project.pinger.round("bridge ping-pong"),
        || baseline_round(&baseline, per_round),
    );
    let (near, far) = project.systems;
    let outlet_losses = near.handle("to_pong").map_or(0, |h| h.snapshot().overflows)
        + far.handle("to_ping").map_or(0, |h| h.snapshot().overflows);
    let (project_samples, baseline_samples) = (
        Samples::new(project_samples),
        Samples::new(baseline_samples),
    );
    table.row(
        "bridge p50",
        Figure::Time(project_samples.p50()),
        Figure::Time(baseline_samples.p50()),
        // The goal: a remote connection within 1.2x of raw Zenoh pub/sub.
        Goal::AtMost(1.2),
    );
    table.row(
        "bridge p99",
        Figure::Time(project_samples.p99()),
        Figure::Time(baseline_samples.p99()),
        Goal::None,
    );
    table.note(&format!(
        "{} samples per side; max project {:?}, baseline {:?}; packets lost at the outlets: {outlet_losses}",
        project_samples.len(),
        project_samples.max(),
        baseline_samples.max()
    ));
    table.print();
    assert!(near.shutdown().clean(), "unclean shutdown");
    assert!(far.shutdown().clean(), "unclean shutdown");
    drop(baseline);
}
