//! The setup the network benchmarks share: free loopback endpoints, a state directory
//! for the outlets' tallies, nodes on explicit endpoints, the wait for a subscriber,
//! and the latency benchmarks' ping-pong (`pingpong`).

#![allow(
    dead_code,
    reason = "each bench binary includes this module and uses a different part of it"
)]

use std::path::Path;
use std::time::{Duration, Instant};

use coolbot_zenoh::Node;
use zenoh::Wait;

pub mod pingpong;

/// A free loopback TCP endpoint.
pub fn endpoint() -> String {
    format!("tcp/127.0.0.1:{}", coolbot_zenoh::free_loopback_port())
}

/// A state directory for the outlets' tallies, not the user's: in memory
/// (`/dev/shm`) as the default one is, else in the temporary directory; removed when
/// dropped.
pub fn state_directory() -> tempfile::TempDir {
    let mut builder = tempfile::Builder::new();
    builder.prefix("coolbot-bench-");
    builder
        .tempdir_in("/dev/shm")
        .or_else(|_| builder.tempdir())
        .expect("a state directory")
}

/// A peer configuration listening on `listen` and connecting to `connect`, with
/// shared memory on or off.
pub fn config(listen: &str, connect: &[String], shared_memory: bool) -> zenoh::Config {
    let mut config =
        coolbot_zenoh::peer_config(&[listen.to_owned()], connect, false).expect("config");
    config
        .insert_json5(
            "transport/shared_memory/enabled",
            if shared_memory { "true" } else { "false" },
        )
        .expect("shared memory setting");
    config
}

/// A node named `name` on `config`, its outlets' tallies in `state`.
pub fn node(name: &str, config: zenoh::Config, state: &Path) -> Node {
    Node::open(name, config)
        .expect(name)
        .with_state_directory(Some(state.to_path_buf()))
}

/// Two nodes, `b` connected to `a`, on loopback, their outlets' tallies in `state`.
pub fn nodes(state: &Path) -> (Node, Node) {
    let a_endpoint = endpoint();
    let a = node("bench-a", config(&a_endpoint, &[], true), state);
    let b = node("bench-b", config(&endpoint(), &[a_endpoint], true), state);
    (a, b)
}

/// Wait until `session` knows a subscriber on `key`.
pub fn wait_subscribed(session: &zenoh::Session, key: &str) {
    let publisher = session
        .declare_publisher(key.to_owned())
        .wait()
        .expect("probe publisher");
    let deadline = Instant::now() + Duration::from_secs(30);
    while !publisher
        .matching_status()
        .wait()
        .is_ok_and(|status| status.matching())
    {
        assert!(Instant::now() < deadline, "no subscriber on `{key}`");
        std::thread::sleep(Duration::from_millis(5));
    }
}
