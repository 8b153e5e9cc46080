//! A process on the network: the `--node NAME` options any CoolBOT program takes (the
//! starter `main` that `coolc` writes, the example robot), and what they open.
//!
//! [`NodeOptions::take_args`] takes `--node NAME`, `--listen ENDPOINT`,
//! `--connect ENDPOINT`, `--multicast` / `--no-multicast`, `--lease DURATION`,
//! `--silence DURATION`,
//! `--config FILE` (the security file, [`crate::Security`]), `--insecure` and
//! `--serve` out of a program's arguments and leaves the rest to the program. [`Network::open`] then opens
//! the node (`coolctl` sees it), starts its agent (other nodes may build the
//! registered component types here: an `on "node"` instance of one of their
//! compounds) and installs its placer on the calling thread (the compounds this
//! thread builds put their `on "node"` instances on their nodes). Open it before
//! building the components, on the thread that builds them; [`Network::expose_system`]
//! then puts every component of the system on the node.

use std::sync::Arc;
use std::time::Duration;

use crate::Error;
use crate::agent::{Agent, Registry};
use crate::node::Node;

/// The default session lease: a peer that stops answering is lost after it, and an
/// instance on a lost node is a fault of its proxy (`docs/distribution.md`).
pub const DEFAULT_LEASE: Duration = Duration::from_secs(2);

/// What the options [`NodeOptions::take_args`] takes mean, for a program's `--help`.
pub const USAGE: &str = "\
network options (a build with the `network` feature):
  --node NAME          run as the Zenoh node NAME: coolctl lists, watches and commands
                       every component; `on \"NAME\"` instances of other nodes run here
  --serve              with --node: run no components of this program, only what other
                       nodes place on this one, until stopped
  --listen ENDPOINT    with --node: listen on ENDPOINT (e.g. tcp/127.0.0.1:7447, or
                       quic/0.0.0.0:7447 with --config); repeatable
  --connect ENDPOINT   with --node: connect to ENDPOINT; repeatable
  --config FILE        with --node: the security file (TLS certificates, access rules);
                       without one the node stays on loopback
  --insecure           with --node: allow plaintext off loopback and multicast scouting
  --multicast          with --node: find peers by multicast scouting (the default with
                       TLS; needs TLS or --insecure)
  --no-multicast       with --node: do not (the default without TLS)
  --lease DURATION     with --node: the session lease, after which a silent peer is
                       lost (default 2s)
  --silence DURATION   with --node: how long an instance this node placed on another
                       may leave its monitoring unanswered before its proxy fails
                       (default 3s)";

/// Where a node is on the network, and what it does there.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NodeOptions {
    /// The node's name (one key chunk: letters, digits, `_`, `-`, `.`).
    pub name: String,
    /// Zenoh endpoints to listen on (e.g. `tcp/0.0.0.0:7447`).
    pub listen: Vec<String>,
    /// Zenoh endpoints to connect to.
    pub connect: Vec<String>,
    /// Find peers by multicast scouting: `None` for the default, on with TLS and off
    /// without (multicast reaches the whole network).
    pub multicast: Option<bool>,
    /// The security file (`--config`): TLS and access rules ([`crate::Security`]).
    pub security: Option<std::path::PathBuf>,
    /// Allow plaintext off loopback and multicast scouting without TLS (`--insecure`).
    pub insecure: bool,
    /// The Zenoh session lease: a peer that stops answering is lost after it.
    pub lease: Duration,
    /// How long an instance placed on another node may leave its monitoring port
    /// unanswered before its proxy fails ([`crate::Placer::silence`]).
    pub silence: Duration,
    /// Run only what other nodes place on this one (`--serve`).
    pub serve: bool,
}

/// Arguments [`NodeOptions::take_args`] could not take.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum OptionsError {
    /// A flag that takes a value came last.
    #[error("`{0}` needs a value")]
    MissingValue(&'static str),
    /// A network flag without `--node`.
    #[error("`{0}` needs `--node NAME`")]
    NeedsNode(&'static str),
    /// `--lease` with something that is not a duration.
    #[error("`--lease {0}`: not a duration (e.g. 2s, 500ms)")]
    Lease(String),
    /// `--silence` with something that is not a duration.
    #[error("`--silence {0}`: not a duration (e.g. 3s, 500ms)")]
    Silence(String),
    /// `--node` twice.
    #[error("`--node` is given twice")]
    TwoNodes,
    /// A flag that takes no value was given one (`--serve=yes`).
    #[error("`{0}` takes no value")]
    UnexpectedValue(&'static str),
}

impl NodeOptions {
    /// A node called `name` with no security file (on loopback only), the default
    /// lease, running the program's components.
    pub fn named(name: impl Into<String>) -> NodeOptions {
        NodeOptions {
            name: name.into(),
            listen: Vec::new(),
            connect: Vec::new(),
            multicast: None,
            security: None,
            insecure: false,
            lease: DEFAULT_LEASE,
            silence: crate::place::DEFAULT_SILENCE,
            serve: false,
        }
    }

    /// Takes the network options ([`USAGE`]) out of `args` (a program's arguments,
    /// without its name), leaving the others in order. `None` when there is no
    /// `--node`; an error when a network option comes without it, or lacks its value.
    /// `--flag=value` is accepted as well as `--flag value`.
    pub fn take_args(args: &mut Vec<String>) -> Result<Option<NodeOptions>, OptionsError> {
        let mut name = None;
        let mut options = NodeOptions::named("");
        let mut without_node = None;
        let mut rest = Vec::new();
        let mut iter = std::mem::take(args).into_iter().peekable();
        while let Some(arg) = iter.next() {
            let (flag, inline) = match arg.split_once('=') {
                Some((flag, value)) if flag.starts_with("--") => (flag, Some(value.to_owned())),
                _ => (arg.as_str(), None),
            };
            let flag: &'static str = match flag {
                "--node" => "--node",
                "--listen" => "--listen",
                "--connect" => "--connect",
                "--lease" => "--lease",
                "--silence" => "--silence",
                "--config" => "--config",
                "--insecure" => "--insecure",
                "--multicast" => "--multicast",
                "--no-multicast" => "--no-multicast",
                "--serve" => "--serve",
                _ => {
                    rest.push(arg);
                    continue;
                }
            };
            // A value is the flag's own (`--flag=value`) or the next argument, never
            // another flag, and never empty.
            let mut value = || {
                let value = match inline.clone() {
                    Some(value) => value,
                    None => iter
                        .next_if(|next| !next.starts_with("--"))
                        .ok_or(OptionsError::MissingValue(flag))?,
                };
                if value.is_empty() {
                    return Err(OptionsError::MissingValue(flag));
                }
                Ok(value)
            };
            if inline.is_some()
                && matches!(
                    flag,
                    "--insecure" | "--multicast" | "--no-multicast" | "--serve"
                )
            {
                return Err(OptionsError::UnexpectedValue(flag));
            }
            match flag {
                "--node" => {
                    if name.replace(value()?).is_some() {
                        return Err(OptionsError::TwoNodes);
                    }
                    continue;
                }
                "--listen" => options.listen.push(value()?),
                "--connect" => options.connect.push(value()?),
                "--lease" => {
                    let text = value()?;
                    options.lease = crate::ctl::parse_duration(&text)
                        .map_err(|_| OptionsError::Lease(text.clone()))?;
                }
                "--silence" => {
                    let text = value()?;
                    options.silence = crate::ctl::parse_duration(&text)
                        .map_err(|_| OptionsError::Silence(text.clone()))?;
                }
                "--config" => options.security = Some(value()?.into()),
                "--insecure" => options.insecure = true,
                "--multicast" => options.multicast = Some(true),
                "--no-multicast" => options.multicast = Some(false),
                _ => options.serve = true,
            }
            without_node.get_or_insert(flag);
        }
        *args = rest;
        match (name, without_node) {
            (Some(name), _) => Ok(Some(NodeOptions { name, ..options })),
            (None, Some(flag)) => Err(OptionsError::NeedsNode(flag)),
            (None, None) => Ok(None),
        }
    }

    /// The node's Zenoh configuration: peer mode, the endpoints, scouting, lease, and
    /// the security file's TLS and access rules (endpoints off loopback, and
    /// multicast scouting, need TLS or `--insecure`: an error says so).
    pub fn config(&self) -> Result<zenoh::Config, Error> {
        let security = match &self.security {
            Some(path) => crate::Security::load(path)?,
            None => crate::Security::none(),
        }
        .allow_plaintext(self.insecure);
        let multicast = self.multicast.unwrap_or(security.has_tls());
        let mut config = crate::secure_config(&self.listen, &self.connect, multicast, &security)?;
        config
            .insert_json5(
                "transport/link/tx/lease",
                &self.lease.as_millis().to_string(),
            )
            .map_err(Error::zenoh("set the lease"))?;
        Ok(config)
    }
}

/// A process on the network: its node, its agent and its placer ([`Network::open`]).
/// Not `Send`: the placer is installed on the thread that opened it, and uninstalled
/// when it is dropped there.
pub struct Network {
    node: Arc<Node>,
    _agent: Agent,
    _placer: coolbot::remote::Installed,
}

impl Network {
    /// Opens the node `options` name, starts its agent, which builds the component
    /// types of `registry` when another node asks, and installs a placer on this
    /// thread, which puts the `on "node"` instances of the compounds built here on
    /// their nodes (and bridges their ports with the types of `registry`).
    pub fn open(
        options: &NodeOptions,
        registry: impl Into<Arc<Registry>>,
    ) -> Result<Network, Error> {
        let node = Arc::new(Node::open(&options.name, options.config()?)?);
        let registry = registry.into();
        let agent = Agent::start(Arc::clone(&node), Arc::clone(&registry))?;
        let placer = crate::Placer::new(Arc::clone(&node), registry)
            .silence(options.silence)
            .install();
        Ok(Network {
            node,
            _agent: agent,
            _placer: placer,
        })
    }

    /// The node's name.
    pub fn name(&self) -> &str {
        self.node.name()
    }

    /// The node, to expose more on it ([`Node::echo`], bridges).
    pub fn node(&self) -> &Arc<Node> {
        &self.node
    }

    /// Exposes every component of `system`, at every level, on the node.
    pub fn expose_system(&self, system: &coolbot::System) -> Result<(), Error> {
        self.node.expose_system(system)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(text: &str) -> Vec<String> {
        text.split_whitespace().map(str::to_owned).collect()
    }

    #[test]
    fn network_options_are_taken_and_the_rest_is_left() {
        let mut given = args(
            "30 --node robot --listen tcp/127.0.0.1:7447 -v --lease=500ms --no-multicast --connect tcp/10.0.0.2:7447 --config=sec.toml --insecure --silence 10s",
        );
        let options = NodeOptions::take_args(&mut given).unwrap().unwrap();
        assert_eq!(given, args("30 -v"));
        assert_eq!(
            options,
            NodeOptions {
                name: "robot".into(),
                listen: args("tcp/127.0.0.1:7447"),
                connect: args("tcp/10.0.0.2:7447"),
                multicast: Some(false),
                security: Some("sec.toml".into()),
                insecure: true,
                lease: Duration::from_millis(500),
                silence: Duration::from_secs(10),
                serve: false,
            }
        );
        let mut given = args("--serve --node=station");
        let options = NodeOptions::take_args(&mut given).unwrap().unwrap();
        assert!(given.is_empty());
        assert_eq!(
            options,
            NodeOptions {
                serve: true,
                ..NodeOptions::named("station")
            }
        );
    }

    #[test]
    fn without_a_security_file_multicast_and_plaintext_off_loopback_are_refused() {
        let mut options = NodeOptions::named("robot");
        // The default: no multicast without TLS, loopback endpoints.
        options.listen = args("tcp/127.0.0.1:0");
        assert!(options.config().is_ok());
        options.multicast = Some(true);
        let error = coolbot::Chain(&options.config().unwrap_err()).to_string();
        assert!(error.contains("multicast scouting"), "{error}");
        options.multicast = None;
        options.listen = args("tcp/0.0.0.0:7447");
        let error = coolbot::Chain(&options.config().unwrap_err()).to_string();
        assert!(error.contains("not on loopback"), "{error}");
        options.insecure = true;
        assert!(options.config().is_ok());
    }

    #[test]
    fn without_node_nothing_is_taken_and_network_flags_are_errors() {
        let mut given = args("forever --verbose");
        assert_eq!(NodeOptions::take_args(&mut given), Ok(None));
        assert_eq!(given, args("forever --verbose"));
        assert_eq!(
            NodeOptions::take_args(&mut args("--serve")),
            Err(OptionsError::NeedsNode("--serve"))
        );
        assert_eq!(
            NodeOptions::take_args(&mut args("--node")),
            Err(OptionsError::MissingValue("--node"))
        );
        assert_eq!(
            NodeOptions::take_args(&mut args("--node a --lease soon")),
            Err(OptionsError::Lease("soon".into()))
        );
        assert_eq!(
            NodeOptions::take_args(&mut args("--node a --silence=never")),
            Err(OptionsError::Silence("never".into()))
        );
        assert_eq!(
            NodeOptions::take_args(&mut args("--node a --node b")),
            Err(OptionsError::TwoNodes)
        );
        // A flag is not another flag's value; a value is not empty; a switch has none.
        assert_eq!(
            NodeOptions::take_args(&mut args("--listen --node left")),
            Err(OptionsError::MissingValue("--listen"))
        );
        assert_eq!(
            NodeOptions::take_args(&mut args("--node=")),
            Err(OptionsError::MissingValue("--node"))
        );
        assert_eq!(
            NodeOptions::take_args(&mut args("--node a --insecure=yes")),
            Err(OptionsError::UnexpectedValue("--insecure"))
        );
    }
}
