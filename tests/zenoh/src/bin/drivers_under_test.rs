//! The drivers process of `tests/all/isolation.rs`, as the starter `main` coolc writes
//! runs one: `drivers-under-test --node drivers --serve --connect ENDPOINT` (the
//! options of `coolbot_zenoh::network::NodeOptions`) opens the node, whose agent
//! builds a `NativeDriver` (`cool/isolation.cool`) or a `Camera` (`cool/camera.cool`,
//! for `benches/camera.rs`) when another node places one here.
//! It prints `ready` once the node is open, and serves until it is killed, its input
//! closes, or the driver it runs crashes it.

use std::process::ExitCode;

use coolbot_zenoh::network::{Network, NodeOptions};
use coolbot_zenoh_tests::isolation::registry;

fn main() -> ExitCode {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let options = match NodeOptions::take_args(&mut args) {
        Ok(Some(options)) if options.serve && args.is_empty() => options,
        Ok(_) => {
            eprintln!("usage: drivers-under-test --node NAME --serve [network options]");
            return ExitCode::from(2);
        }
        Err(error) => {
            eprintln!("drivers-under-test: {error}");
            return ExitCode::from(2);
        }
    };
    let _network = match Network::open(&options, registry()) {
        Ok(network) => network,
        Err(error) => {
            eprintln!(
                "node `{}` cannot open: {}",
                options.name,
                coolbot::Chain(&error)
            );
            return ExitCode::FAILURE;
        }
    };
    println!("ready");
    // Until the test closes stdin, or kills this process.
    let _ = std::io::Read::read_to_end(&mut std::io::stdin(), &mut Vec::new());
    ExitCode::SUCCESS
}
