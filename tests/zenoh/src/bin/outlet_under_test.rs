//! The producer process of `tests/accounting.rs`: node `accounting-producer`,
//! connected to the endpoint given, streams poses on the key given through an outlet,
//! as fast as the outlet takes them (at most LIMIT when given), and prints on stdout
//! what the outlet hands to Zenoh (`coolbot_zenoh::LEDGER_TARGET` at trace level:
//! `<key> sent <epoch> <number>`, written to its tally first). It prints `ready` once
//! the outlet runs, and runs until it is killed.

use coolbot::crossbeam_channel::{self, Sender};
use coolbot::port::DataOut;
use coolbot::{InputKind, System};
use coolbot_zenoh::Node;
use coolbot_zenoh_tests::generated::pose_source;
use coolbot_zenoh_tests::generated::types::Pose;
use tracing_subscriber::EnvFilter;

/// The producer's behaviour: hands its output over when it starts.
struct Hand(Sender<DataOut<Pose>>);

impl pose_source::Behavior for Hand {
    fn start(&mut self, cx: &mut pose_source::Cx<'_>) -> coolbot::SectionResult {
        let _ = self.0.send(cx.outputs.out.clone());
        Ok(())
    }
}

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
    let mut system = System::new();
    let kind = InputKind::Ufifo {
        initial: 64,
        max: Some(1 << 20),
    };
    system
        .add(
            node.outlet::<Pose>("outlet", &key, kind)
                .build()
                .expect("the outlet"),
        )
        .expect("added");
    let (hand, handed) = crossbeam_channel::bounded(1);
    system
        .add(pose_source::component("producer", Hand(hand)))
        .expect("added");
    system
        .connect("producer.out", "outlet.input")
        .expect("connected");
    system.run_all().expect("runs");
    let out = handed.recv().expect("the producer's output");
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
