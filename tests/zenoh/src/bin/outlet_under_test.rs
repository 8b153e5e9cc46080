//! The producer process of `tests/accounting.rs`: node `accounting-producer`,
//! connected to the endpoint given, streams poses (or chunks of 4 MiB: `chunks`) on the
//! key given through an outlet, as fast as the outlet takes them (at most LIMIT when
//! given), and prints on stdout
//! what the outlet hands to Zenoh (`coolbot_zenoh::LEDGER_TARGET` at trace level:
//! `<key> sent <epoch> <number>`, written to its tally first). It prints `ready` once
//! the outlet runs, and runs until it is killed or its standard input closes.

use coolbot::crossbeam_channel;
use coolbot_zenoh::Node;
use coolbot_zenoh_tests::generated::types::{Chunk, Pose};
use coolbot_zenoh_tests::soak::Streamed;
use coolbot_zenoh_tests::support::outlet_fed;
use tracing_subscriber::EnvFilter;

fn main() {
    coolbot_zenoh_tests::support::exit_when_stdin_closes();
    let mut args = std::env::args().skip(1);
    let (Some(endpoint), Some(key), Some(what)) = (args.next(), args.next(), args.next()) else {
        eprintln!("usage: outlet-under-test ENDPOINT KEY poses|chunks [LIMIT]");
        std::process::exit(2);
    };
    let limit = args
        .next()
        .map_or(u64::MAX, |limit| limit.parse().expect("a count"));
    match what.as_str() {
        Pose::ARG => produce::<Pose>(endpoint, &key, limit),
        Chunk::ARG => produce::<Chunk>(endpoint, &key, limit),
        other => {
            eprintln!("outlet-under-test: no stream `{other}`");
            std::process::exit(2);
        }
    }
}

fn produce<P: Streamed>(endpoint: String, key: &str, limit: u64) {
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
    let (hand, handed) = crossbeam_channel::bounded(1);
    let producer = P::source("producer", hand);
    let (_system, out) = outlet_fed(&node, key, P::OUTLET, producer, &handed);
    println!("ready");
    for seq in 1..=limit {
        out.send(P::numbered(seq));
        // Let the outlet's thread keep up (a queue of poses grows otherwise).
        if seq % P::BURST == 0 {
            std::thread::sleep(P::PAUSE);
        }
    }
    loop {
        std::thread::park();
    }
}
