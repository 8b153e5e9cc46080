//! The robot process of `tests/all/foxglove.rs`: node NAME, connected to the endpoint
//! given, runs the network tests' robot (`support::robot`). It prints `ready` once the
//! robot runs, and runs until it is killed or its input closes.

use coolbot_zenoh::Node;
use coolbot_zenoh_tests::support;

fn main() {
    let mut args = std::env::args().skip(1);
    let (Some(name), Some(endpoint)) = (args.next(), args.next()) else {
        eprintln!("usage: robot-under-test NAME ENDPOINT");
        std::process::exit(2);
    };
    let config = coolbot_zenoh::peer_config(&[], &[endpoint], false).expect("a configuration");
    let node = Node::open(&name, config)
        .expect("the node opens")
        .with_state_directory(None);
    let _robot = support::robot(&node);
    println!("ready");
    // Until the test closes stdin (or kills this process).
    let _ = std::io::Read::read_to_end(&mut std::io::stdin(), &mut Vec::new());
}
