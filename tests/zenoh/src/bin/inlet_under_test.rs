//! The consumer process of `tests/accounting.rs`: node `sink`, connected to the
//! endpoint given, reads poses (or chunks: `chunks`) on the key given through an inlet,
//! and prints on stdout
//! what the inlet's ledger records (`coolbot_zenoh::LEDGER_TARGET` at trace level),
//! one line each as it happens: every numbered message received, and every
//! acknowledgment answered. It prints `ready` once the inlet runs, and runs until it
//! is killed or its standard input closes.

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
    system.run_all().expect("runs");
    println!("ready");
    loop {
        std::thread::park();
    }
}
