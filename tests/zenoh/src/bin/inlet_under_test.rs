//! The consumer process of `tests/accounting.rs`: node `sink`, connected to the
//! endpoint given, reads poses (or chunks: `chunks`) on the key given through an inlet,
//! and prints on stdout
//! what the inlet's ledger records (`coolbot_zenoh::LEDGER_TARGET` at trace level),
//! one line each as it happens: every numbered message received, and every
//! acknowledgment answered. The inlet feeds a queue this process empties (a consumer
//! on the host of a queue outlet: the outlet writes into its ring, `docs/distribution.md`).
//! It prints `ready` once the inlet runs, and runs until it is killed or its standard
//! input closes.

use coolbot::{OutputKind, System};
use coolbot_zenoh::Node;
use coolbot_zenoh_tests::generated::types::{Chunk, Pose};
use coolbot_zenoh_tests::soak::Streamed;
use tracing_subscriber::EnvFilter;

fn main() {
    coolbot_zenoh_tests::support::exit_when_stdin_closes();
    let mut args = std::env::args().skip(1);
    let (Some(endpoint), Some(key), what) = (args.next(), args.next(), args.next()) else {
        eprintln!("usage: inlet-under-test ENDPOINT KEY [poses|chunks]");
        std::process::exit(2);
    };
    match what.as_deref() {
        None | Some(Pose::ARG) => consume::<Pose>(endpoint, &key),
        Some(Chunk::ARG) => consume::<Chunk>(endpoint, &key),
        Some(other) => {
            eprintln!("inlet-under-test: no stream `{other}`");
            std::process::exit(2);
        }
    }
}

fn consume<P: Streamed>(endpoint: String, key: &str) {
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
    let node = Node::open("sink", config).expect("node `sink` opens");
    let mut system = System::new();
    system
        .add(
            node.inlet::<P>("inlet", key, OutputKind::Data)
                .build()
                .expect("the inlet"),
        )
        .expect("added");
    let (hand, handed) = coolbot::crossbeam_channel::bounded(1);
    system.add(P::queue("queue", hand)).expect("added");
    system
        .connect("inlet.output", "queue.input")
        .expect("connected");
    system.run_all().expect("runs");
    let queue = handed
        .recv_timeout(coolbot_zenoh_tests::support::PATIENCE)
        .expect("the queue's input");
    println!("ready");
    loop {
        while queue.recv().is_some() {}
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
}
