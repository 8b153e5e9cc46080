//! The producer process of `tests/accounting.rs`: node `accounting-producer`,
//! connected to the endpoint given, streams poses on the key given through an outlet,
//! as fast as the outlet takes them (at most LIMIT when given), and prints on stdout
//! what the outlet hands to Zenoh (`coolbot_zenoh::LEDGER_TARGET` at trace level:
//! `<key> sent <epoch> <number>`, written to its tally first). It prints `ready` once
//! the outlet runs, and runs until it is killed.

use coolbot::InputKind;
use coolbot::crossbeam_channel;
use coolbot_zenoh::Node;
use coolbot_zenoh_tests::generated::pose_source;
use coolbot_zenoh_tests::generated::types::Pose;
use coolbot_zenoh_tests::support::{Hand, outlet_fed};
use tracing_subscriber::EnvFilter;

fn main() {
    let mut args = std::env::args().skip(1);
    let (Some(endpoint), Some(key)) = (args.next(), args.next()) else {
        eprintln!("usage: outlet-under-test ENDPOINT KEY [LIMIT]");
        std::process::exit(2);
    };
    let limit = args
        .next()
        .map_or(u64::MAX, |limit| limit.parse().expect("a count"));
    // Stdout is line-buffered: each line is one write, kept by the pipe whenever the
    // process is killed.
    tracing_subscriber::fmt()
        .with_env_filter(EnvFilter::new(format!(
            "{}=trace",
            coolbot_zenoh::LEDGER_TARGET
        )))
        .with_writer(std::io::stdout)
        .with_ansi(false)
        .without_time()
        .init();
    let config = coolbot_zenoh::peer_config(&[], &[endpoint], false).expect("a configuration");
    let node = Node::open("accounting-producer", config).expect("the node opens");
    let kind = InputKind::Ufifo {
        initial: 64,
        max: Some(1 << 20),
    };
    let (hand, handed) = crossbeam_channel::bounded(1);
    let producer = pose_source::component("producer", Hand(hand));
    let (_system, out) = outlet_fed(&node, &key, kind, producer, &handed);
    println!("ready");
    for seq in 1..=limit {
        out.send(Pose { x: seq as f64, seq });
        // Let the outlet's thread keep up (the queue grows otherwise, unbounded).
        if seq % 64 == 0 {
            std::thread::sleep(std::time::Duration::from_micros(500));
        }
    }
    loop {
        std::thread::park();
    }
}
