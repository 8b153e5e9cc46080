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
    /// Find peers by multicast scouting: `None` for the default (on with TLS, off
    /// without).
    pub multicast: Option<bool>,
    /// The security file: TLS certificates and access rules.
    pub security: Option<std::path::PathBuf>,
    /// Allow plaintext off loopback and multicast scouting without TLS.
    pub insecure: bool,
    /// The Zenoh session lease: a peer that stops answering is lost after it (and an
    /// instance on it is a fault of its proxy).
    pub lease: std::time::Duration,
    /// How long an instance placed on another node may leave its monitoring port
    /// unanswered before its proxy fails.
    pub silence: std::time::Duration,
}

impl NodeOptions {
    /// A node called `name`, without a security file: on loopback only.
    pub fn named(name: impl Into<String>) -> NodeOptions {
        NodeOptions {
            name: name.into(),
            listen: Vec::new(),
            connect: Vec::new(),
            multicast: None,
            security: None,
            insecure: false,
            // coolbot-zenoh's defaults (a build without the network has no such crate).
            lease: std::time::Duration::from_secs(2),
            silence: std::time::Duration::from_secs(3),
        }
    }
}

/// The process on the network: its node, the placer that puts the robot's
/// `on "node"` instances on their nodes (the wanderer `on "station"`, the range
/// server `on "drivers"` with `--drivers`), and the agent
/// that builds such instances here when another node asks
/// (`coolbot_zenoh::network::Network`). Open it before the robot is built, on the
/// thread that builds it (the placer is installed on that thread); the robot's
/// components are exposed by [`Network::expose`].
pub struct Network {
    name: String,
    #[cfg(feature = "network")]
    network: coolbot_zenoh::network::Network,
}

impl Network {
    /// The node's name.
    pub fn name(&self) -> &str {
        &self.name
    }
}

/// What a range server built in this process for another node reads: the process's
/// own simulated sensor board (the room, and the injected fault and processor
/// shortage of its command line), at the pose of the range server's `pose` input.
#[derive(Clone, Debug)]
pub struct Board {
    /// The board: a platform of this process, which no motion controller drives.
    pub platform: std::sync::Arc<crate::world::Platform>,
    /// The run's `--noise`, `--seed` and `--scan-rate`.
    pub overrides: crate::sensing::Overrides,
}

impl Board {
    /// A board in the example room, with no fault, no shortage and no overrides.
    pub fn example() -> Board {
        use crate::world::{Platform, World};
        Board {
            platform: std::sync::Arc::new(Platform::new(
                World::example(),
                World::example_start(),
                None,
            )),
            overrides: crate::sensing::Overrides::default(),
        }
    }
}

/// The component types this process can run for another node, and whose ports it
/// can bridge: the instances the robot's descriptions place, the wanderer
/// (`on "station"`) and the range server (`on "drivers"`, on `board`).
#[cfg(feature = "network")]
fn registry(board: &Board) -> coolbot_zenoh::agent::Registry {
    use crate::generated::{range_server, wanderer};
    let mut registry = coolbot_zenoh::agent::Registry::new();
    wanderer::register(&mut registry, |name| {
        wanderer::component(name, crate::wanderer::Wanderer::default())
    });
    let board = board.clone();
    range_server::register(&mut registry, move |name| {
        let server = crate::range_server::RangeServer::new(
            std::sync::Arc::clone(&board.platform),
            board.overrides,
        );
        range_server::component(name, server)
    });
    registry
}

/// Opens the node, installs its placer and starts its agent; a range server built
/// here for another node reads `board`.
#[cfg(feature = "network")]
pub fn open(options: &NodeOptions, board: &Board) -> Result<Network, String> {
    let zenoh_options = coolbot_zenoh::network::NodeOptions {
        listen: options.listen.clone(),
        connect: options.connect.clone(),
        multicast: options.multicast,
        security: options.security.clone(),
        insecure: options.insecure,
        lease: options.lease,
        silence: options.silence,
        ..coolbot_zenoh::network::NodeOptions::named(options.name.clone())
    };
    let network =
        coolbot_zenoh::network::Network::open(&zenoh_options, registry(board)).map_err(|e| {
            format!(
                "node `{}` cannot open: {}",
                options.name,
                coolbot::Chain(&e)
            )
        })?;
    Ok(Network {
        name: options.name.clone(),
        network,
    })
}

#[cfg(feature = "network")]
impl Network {
    /// Exposes every component of `robot` on the node, and echoes the odometry and
    /// the scans.
    pub fn expose(&self, robot: &Robot) -> Result<(), String> {
        let node = self.network.node();
        node.expose_system(robot.system()).map_err(|e| {
            format!(
                "node `{}` cannot expose the robot: {}",
                self.name,
                coolbot::Chain(&e)
            )
        })?;
        // `coolctl echo` on the odometry and the scans (the ports `--record` records).
        use crate::generated::types::{Pose2D, RangeScan};
        let echo = |result: Result<(), coolbot_zenoh::Error>, port: &str| {
            result.map_err(|e| {
                format!(
                    "node `{}` cannot echo `{port}`: {}",
                    self.name,
                    coolbot::Chain(&e)
                )
            })
        };
        let [pose, scan] = crate::RECORDED_PORTS;
        echo(node.echo::<Pose2D>(robot.system(), pose), pose)?;
        echo(node.echo::<RangeScan>(robot.system(), scan), scan)?;
        Ok(())
    }
}

/// A loopback port for a node that others on this host are told of
/// (`coolbot_zenoh::free_loopback_port`).
#[cfg(feature = "network")]
pub fn loopback_port() -> u16 {
    coolbot_zenoh::free_loopback_port()
}

/// Without the `network` feature no node opens (see [`open`]): any port serves.
#[cfg(not(feature = "network"))]
pub fn loopback_port() -> u16 {
    0
}

/// Without the `network` feature there is no Zenoh in the build: `--node` says how
/// to get it.
#[cfg(not(feature = "network"))]
pub fn open(options: &NodeOptions, _board: &Board) -> Result<Network, String> {
    Err(format!(
        "node `{}`: this build has no network support; build the example with \
         `--features network` (cargo run --release -p mobile-base --features network -- --node {})",
        options.name, options.name
    ))
}

#[cfg(not(feature = "network"))]
impl Network {
    /// Never reached: [`open`] fails without the feature.
    pub fn expose(&self, _robot: &Robot) -> Result<(), String> {
        Ok(())
    }
}
