//! `--node NAME`: the robot on the network (the `network` feature). A Zenoh node
//! (`coolbot_zenoh::Node`) exposes every component of the robot, at every level
//! (`robot`, `robot.base`, `robot.base.motion`, ...), on its monitoring and control
//! keys, so that `coolctl` in another terminal (or on another machine) lists,
//! watches and commands them (`docs/distribution.md`), and echoes the odometry and
//! the scans (`coolctl echo robot/robot.base.scan`, `docs/tools.md`). Nothing of Zenoh runs without the flag: the components
//! and their ports are the same either way, the node only observes them (one thread
//! forwarding monitoring events, one applying remote commands).

use crate::robot::Robot;

/// Where the node is on the network.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NodeOptions {
    /// The node's name (one key chunk: letters, digits, `_`, `-`, `.`).
    pub name: String,
    /// Zenoh endpoints to listen on (e.g. `tcp/0.0.0.0:7447`).
    pub listen: Vec<String>,
    /// Zenoh endpoints to connect to.
    pub connect: Vec<String>,
    /// Find peers by multicast scouting (what `coolctl` does by default).
    pub multicast: bool,
}

impl NodeOptions {
    /// A node called `name` that finds its peers by multicast scouting.
    pub fn named(name: impl Into<String>) -> NodeOptions {
        NodeOptions {
            name: name.into(),
            listen: Vec::new(),
            connect: Vec::new(),
            multicast: true,
        }
    }
}

/// The robot on the network: its components stay exposed while this lives.
pub struct Exposed {
    name: String,
    #[cfg(feature = "network")]
    _node: coolbot_zenoh::Node,
}

impl Exposed {
    /// The node's name.
    pub fn name(&self) -> &str {
        &self.name
    }
}

/// Opens the node and exposes every component of `robot` on it. The robot stays
/// exposed while the returned value lives.
#[cfg(feature = "network")]
pub fn expose(robot: &Robot, options: &NodeOptions) -> Result<Exposed, String> {
    let config = coolbot_zenoh::peer_config(&options.listen, &options.connect, options.multicast)
        .map_err(|e| format!("node `{}`: {e}", options.name))?;
    let node = coolbot_zenoh::Node::open(&options.name, config)
        .map_err(|e| format!("node `{}` cannot open: {e}", options.name))?;
    node.expose_system(robot.system())
        .map_err(|e| format!("node `{}` cannot expose the robot: {e}", options.name))?;
    // `coolctl echo` on the odometry and the scans (the ports `--record` records).
    use crate::generated::types::{Pose2D, RangeScan};
    let echo = |result: Result<(), coolbot_zenoh::Error>, port: &str| {
        result.map_err(|e| format!("node `{}` cannot echo `{port}`: {e}", options.name))
    };
    let [pose, scan] = crate::RECORDED_PORTS;
    echo(node.echo::<Pose2D>(robot.system(), pose), pose)?;
    echo(node.echo::<RangeScan>(robot.system(), scan), scan)?;
    Ok(Exposed {
        name: options.name.clone(),
        _node: node,
    })
}

/// Without the `network` feature there is no Zenoh in the build: `--node` says how
/// to get it.
#[cfg(not(feature = "network"))]
pub fn expose(_robot: &Robot, options: &NodeOptions) -> Result<Exposed, String> {
    Err(format!(
        "node `{}`: this build has no network support; build the example with \
         `--features network` (cargo run --release -p mobile-base --features network -- --node {})",
        options.name, options.name
    ))
}
