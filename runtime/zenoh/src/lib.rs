//! `coolbot-zenoh`: CoolBOT components distributed over a network, on Zenoh.
//!
//! The paper's components "can be distributed along a computer network", and CoolBOT
//! "hides any aspects related to communications". This crate keeps the core runtime
//! (`coolbot`) free of network code and adds, on a Zenoh session:
//!
//! - **Port bridges** ([`Node::outlet`], [`Node::inlet`]): an *outlet* is a component
//!   that stands, in the producer's [`coolbot::System`], for a remote input (its one
//!   input has that remote input's kind), and publishes what arrives at it on a key
//!   expression; an *inlet* stands, in the consumer's system, for the remote output
//!   (its one output has that output's kind) and sends what arrives on the key. Both
//!   are connected with [`coolbot::System::connect`], so every local rule (kinds,
//!   cardinality, pull, packet types) holds at both ends. Packets are encoded with
//!   postcard; poster values are served to late-joining readers by a queryable; pull
//!   requests are queries and answers are replies.
//! - **Remote monitoring and control** ([`Node::expose`]): every component of a system,
//!   nested instances included, as `coolbot/<node>/<path>/m` (monitoring events as they
//!   happen, and the current snapshot on query, in JSON) and `coolbot/<node>/<path>/c`
//!   (a queryable taking a [`coolbot::Command`] and answering [`ControlReply`]), and a
//!   liveliness token `coolbot/<node>` per node.
//! - **Echoed outputs** ([`Node::echo`]): the packets of chosen outputs as JSON, for
//!   `coolctl echo`; and each component's static shape on query ([`info`]).
//! - **`coolctl`**, the command-line tool over those keys ([`ctl`]), its live view
//!   `coolctl top` ([`top`]), and `coolctl foxglove`, the components as a Foxglove
//!   WebSocket server (`foxglove`, with the feature of that name, on by default).
//! - **Remote instantiation** ([`agent`]): an agent builds registered component
//!   types on request from another node, bridges their ports, runs and exposes them.
//! - **Remote instances from the description** ([`place`]): a [`Placer`] installed
//!   in a process puts its compounds' `instance x: T on "node";` on that node, each
//!   behind a proxy (`coolbot::remote`).
//! - **A process on the network** ([`network`]): the `--node NAME` options of a
//!   program, and the node, agent and placer they open.
//! - **Same host** ([`Node::shared_memory`]): a large message of a bridge is written
//!   once into shared memory, which a node on the same host reads in place.
//! - **Limits** ([`limits`]): on the names, keys, sizes and counts that come from
//!   the network, checked before anything is allocated or declared for them.
//! - **ROS 2 topics** ([`ros2`]): a ROS 2 node on the rmw_zenoh wire, its publishers
//!   and subscriptions components connected to ports of ROS types (`docs/ros2.md`).
//! - **Security** ([`security`]): TLS with mutual authentication and access rules
//!   from a file, mapped onto Zenoh's access control; without one, a node stays on
//!   loopback.
//!
//! `docs/distribution.md` describes the model, the keys, the encoding and what
//! happens when the network fails.
#![deny(missing_docs)]

pub mod agent;
mod backlog;
mod bridge;
mod codec;
mod config;
pub mod ctl;
mod delivery;
pub mod echo;
#[cfg(feature = "foxglove")]
pub mod foxglove;
pub mod info;
pub mod keys;
mod lanes;
mod ledger;
pub mod limits;
mod locks;
mod loopback;
mod nearby;
pub mod network;
mod node;
pub mod place;
mod reply;
pub mod ros2;
pub mod security;
mod serve;
mod shm;
mod tally;
#[cfg(test)]
mod testing;
pub mod top;

pub use crate::bridge::{DEFAULT_MAX_PAYLOAD, DEFAULT_PULL_TIMEOUT, InletBuilder, OutletBuilder};
pub use crate::config::{peer_config, secure_config};
pub use crate::ledger::{LEDGER_TARGET, OUTLET_LEDGER_TARGET};
pub use crate::loopback::free_loopback_port;
pub use crate::node::{ControlReply, Node};
pub use crate::place::Placer;
pub use crate::security::Security;
pub use crate::shm::{SHARED_THRESHOLD, SharedMemoryCounts};

/// Re-exported so users need not depend on it themselves (configurations, sessions).
pub use zenoh;

/// What can go wrong in this crate. Each error says what failed and keeps its cause
/// as its [`source`](std::error::Error::source) (Zenoh's own error, an OS error, a
/// decoding error): print it with its chain, [`coolbot::Chain`].
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// Zenoh refused an operation (opening a session, declaring, querying).
    #[error("zenoh: cannot {action}")]
    Zenoh {
        /// What was being done (`open the session`, `declare the agent's queryable`).
        action: &'static str,
        /// Zenoh's error.
        #[source]
        source: zenoh::Error,
    },
    /// A thread of the node's own could not be started.
    #[error("cannot spawn the {thread} thread")]
    Spawn {
        /// Which thread (`control`, `monitor`, `agent`, ...).
        thread: &'static str,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// A node, component or key name that cannot be used (its message quotes the
    /// name's first `coolbot::ranges::EXCERPT_CHARS` characters).
    #[error(
        "invalid name `{}`: {reason}",
        coolbot::ranges::excerpt(.name, coolbot::ranges::EXCERPT_CHARS)
    )]
    InvalidName {
        /// The name.
        name: String,
        /// Why.
        reason: String,
    },
    /// A node with this name is already alive on the network.
    #[error("a node named `{0}` is already alive on the network")]
    NodeNameTaken(String),
    /// A bridge would break a connection rule across the network.
    #[error("cannot bridge `{key}`: {rule}")]
    Cardinality {
        /// The bridge's key expression.
        key: String,
        /// The rule and how it is broken.
        rule: String,
    },
    /// A security file that cannot be used, or endpoints it does not allow.
    #[error("security")]
    Security(#[from] security::SecurityError),
    /// Another node's agent refused a request (an instantiation), with its reason as
    /// it sent it.
    #[error("node `{node}`: {reason}")]
    Refused {
        /// The node asked.
        node: String,
        /// Why, in the agent's words.
        reason: String,
    },
    /// Another node's agent has too many requests waiting: the request may be asked
    /// again later.
    #[error("node `{node}`: {reason}")]
    Busy {
        /// The node asked.
        node: String,
        /// The agent's words.
        reason: String,
    },
    /// No agent answered a request within its wait.
    #[error(
        "node `{node}`: no agent answered (after {waited:.1?}, of at most {timeout:.1?}; does \
         the node run an agent, and do its access rules let this node instantiate \
         `{type_name}` there?)"
    )]
    NoAgent {
        /// The node asked.
        node: String,
        /// The component type asked for.
        type_name: String,
        /// How long it waited.
        waited: std::time::Duration,
        /// How long it would have waited at most.
        timeout: std::time::Duration,
    },
    /// Another node answered a query with an error (its text).
    #[error("node `{node}` answered with an error: {reason}")]
    ErrorReply {
        /// The node asked.
        node: String,
        /// The error's text, its first `coolbot::ranges::REASON_CHARS` characters.
        reason: String,
    },
    /// Another node's answer is over a limit ([`limits`]): not decoded.
    #[error("node `{node}`: the answer is refused")]
    TooLarge {
        /// The node asked.
        node: String,
        /// The limit it is over.
        #[source]
        source: limits::Exceeded,
    },
    /// A message to or from another node that does not encode or decode (JSON).
    #[error("{what} does not {}code", if *.decoding { "de" } else { "en" })]
    Json {
        /// What it is (`the request`, `node `station`'s answer`).
        what: String,
        /// Whether it was being decoded (else encoded).
        decoding: bool,
        /// The JSON error.
        #[source]
        source: serde_json::Error,
    },
}

impl Error {
    /// A closure turning Zenoh's error into [`Error::Zenoh`] for `action`, for
    /// `map_err`.
    pub(crate) fn zenoh(action: &'static str) -> impl FnOnce(zenoh::Error) -> Error {
        move |source| Error::Zenoh { action, source }
    }

    /// A closure turning an OS error into [`Error::Spawn`] for `thread`, for `map_err`.
    pub(crate) fn spawn(thread: &'static str) -> impl FnOnce(std::io::Error) -> Error {
        move |source| Error::Spawn { thread, source }
    }
}

#[cfg(test)]
mod tests {
    use std::error::Error as _;

    use coolbot::Chain;

    use super::{Error, Node};

    /// A node that cannot listen where it is told: Zenoh's own error is the source of
    /// [`Error::Zenoh`], which says what was being done, and the chain shows both once.
    #[test]
    fn zenohs_error_is_kept_as_the_source() {
        let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let endpoint = format!("tcp/{}", taken.local_addr().unwrap());
        let config = crate::peer_config(&[endpoint], &[], false).unwrap();
        let error = Node::open("taken", config).unwrap_err();
        let Error::Zenoh { action, source } = &error else {
            panic!("{error:?}");
        };
        assert_eq!(*action, "open the session");
        assert_eq!(error.to_string(), "zenoh: cannot open the session");
        let zenoh = error.source().expect("zenoh's error").to_string();
        assert_eq!(zenoh, source.to_string());
        let chain = Chain(&error).to_string();
        assert!(
            chain.starts_with("zenoh: cannot open the session: ") && chain.contains(&zenoh),
            "{chain}"
        );
        assert_eq!(chain.matches(&zenoh).count(), 1, "{chain}");
    }
}
