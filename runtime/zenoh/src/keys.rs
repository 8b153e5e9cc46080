//! The key expressions this crate uses (`docs/distribution.md`, "Key expressions").
//!
//! - `coolbot/<node>`: the liveliness token of a node.
//! - `coolbot/<node>/<path>/m`: a component's monitoring port: its events as they
//!   happen (JSON `coolbot::MonitorEvent`), and its snapshot on query (JSON
//!   `coolbot::Monitor`). `<path>` is the component's dotted path (`robot.base.motion`).
//! - `coolbot/<node>/<path>/c`: a component's control port: a query whose payload is a
//!   JSON `coolbot::Command`, answered with a JSON [`crate::ControlReply`].
//! - `coolbot/<node>/<path>/s`: a component's static shape on query (JSON
//!   [`crate::info::ComponentInfo`]: variables with kinds and types, ports, the
//!   outputs echoed).
//! - `coolbot/<node>/<path>/o/<port>`: an echoed output, subscribed to ask for its
//!   packets (`coolctl echo`); the node taps the output while a subscriber matches.
//! - `coolbot/<node>/o`: the packets of the node's echoed outputs, one sample per echo
//!   tick (a JSON array of [`crate::echo::Echoed`]).
//! - `coolbot/<node>/@agent/<type>/<requester>`: the agent of a node (remote
//!   instantiation): a query from node `<requester>` whose payload is a JSON
//!   [`crate::agent::Instantiate`] for a component of type `<type>`, answered with a
//!   JSON [`crate::ControlReply`]. The type is in the key so that access rules can
//!   grant instantiation per type, the requester so that they grant each node only
//!   its own name: the agent builds only in the requester's namespace
//!   ([`namespace`], [`link_namespace`]).
//! - A bridge's own key `K` (chosen by the application): packets on `K`, the current
//!   poster value on query of `K`, pull requests as queries on `K/@pull`, and the
//!   liveliness tokens that check the connection rules, `K/@out/<kind>/<node>/<name>`
//!   (outlets) and `K/@in/<node>/<name>/<process>` (inlets; the process is drawn
//!   once per process, `crate::ledger::process`), and the inlets' acknowledgments as
//!   queries on
//!   `K/@ack/<node>/<name>` (`crate::ledger`); the queryable on which an inlet makes
//!   a ring for an outlet of its host, `K/@ring/<node>/<name>` (`crate::nearby`).

use crate::{Error, limits};

/// The root of every key this crate declares for nodes.
pub const ROOT: &str = "coolbot";

/// The liveliness token of node `node`.
pub fn node_token(node: &str) -> String {
    format!("{ROOT}/{node}")
}

/// The prefix of every bridge key of a remote placement (`<node>/<root>/...` follow):
/// a placement's bridges keep no tally (`crate::tally`), their keys being new at every
/// placement.
pub(crate) const LINKS: &str = "coolbot-link/";

/// The monitoring key of the component at `path` on `node`.
pub fn monitor(node: &str, path: &str) -> String {
    format!("{ROOT}/{node}/{path}/m")
}

/// The control key of the component at `path` on `node`.
pub fn control(node: &str, path: &str) -> String {
    format!("{ROOT}/{node}/{path}/c")
}

/// The info key of the component at `path` on `node`.
pub fn info(node: &str, path: &str) -> String {
    format!("{ROOT}/{node}/{path}/s")
}

/// The key whose subscribers ask `node` for output `port` of the component at `path`
/// (the node taps it while one matches).
pub fn echo(node: &str, path: &str, port: &str) -> String {
    format!("{ROOT}/{node}/{path}/o/{port}")
}

/// The key on which `node` publishes the packets of its echoed outputs, a batch per
/// echo tick.
pub fn echoes(node: &str) -> String {
    format!("{ROOT}/{node}/o")
}

/// The key on which node `node`'s agent takes the requests of node `requester` to
/// build a `type_name` (`*`: every type, every requester: the key the agent answers
/// on).
pub fn agent(node: &str, type_name: &str, requester: &str) -> String {
    format!("{ROOT}/{node}/@agent/{type_name}/{requester}")
}

/// Split an agent's key back into `(type, requester)`.
pub fn parse_agent(key: &str) -> Option<(&str, &str)> {
    let rest = key.strip_prefix(ROOT)?.strip_prefix('/')?;
    let (_node, rest) = rest.split_once('/')?;
    let rest = rest.strip_prefix("@agent/")?;
    let (type_name, requester) = rest.split_once('/')?;
    (!requester.contains('/')).then_some((type_name, requester))
}

/// How the names an agent builds for node `requester` begin: the instance's, and so
/// its bridges' (`<name>-<port>`). No node's namespace begins another's (`robot`'s
/// does not begin `robot-2`'s): the requester's name, `_` doubled and `.` written
/// `_d` (an instance's name holds no `.`), after its length: `5-robot-`,
/// `11-robot_dlocal-`.
pub fn namespace(requester: &str) -> String {
    let mut encoded = String::with_capacity(requester.len() + 4);
    for c in requester.chars() {
        match c {
            '_' => encoded.push_str("__"),
            '.' => encoded.push_str("_d"),
            c => encoded.push(c),
        }
    }
    format!("{}-{encoded}-", encoded.len())
}

/// How the bridge keys under `coolbot-link/` that an agent on `node` bridges for node
/// `requester` begin: a placement's keys, `coolbot-link/<node>/<root>/...`, its root
/// in the requester's [`namespace`] (`crate::place`).
pub fn link_namespace(node: &str, requester: &str) -> String {
    format!("{LINKS}{node}/{}", namespace(requester))
}

/// Split a monitoring or control key back into `(node, path)`.
pub fn parse_component(key: &str) -> Option<(&str, &str)> {
    let rest = key.strip_prefix(ROOT)?.strip_prefix('/')?;
    let (node, rest) = rest.split_once('/')?;
    let (path, port) = rest.rsplit_once('/')?;
    (matches!(port, "m" | "c") && !path.contains('/')).then_some((node, path))
}

/// Check a node or component name: one key chunk, of letters, digits, `_`, `-` and
/// `.` (dotted paths), not starting with `.`, at most [`limits::PATH`] bytes long.
pub fn check_name(name: &str) -> Result<(), Error> {
    if let Err(exceeded) = limits::PATH.check(|| "the name".to_owned(), name.len()) {
        return Err(Error::InvalidName {
            name: name.to_owned(),
            reason: exceeded.to_string(),
        });
    }
    let reason = if name.is_empty() {
        Some("a name cannot be empty")
    } else if name.starts_with('.') || name.ends_with('.') || name.contains("..") {
        Some("a dotted path has no empty segment")
    } else if !name
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'))
    {
        Some("only letters, digits, `_`, `-` and `.` are allowed")
    } else {
        None
    };
    match reason {
        Some(reason) => Err(Error::InvalidName {
            name: name.to_owned(),
            reason: reason.to_owned(),
        }),
        None => Ok(()),
    }
}

/// Check a bridge key: a key expression without wildcards (one connection is one key)
/// and without `@` chunks of its own (they are the bridge's), at most [`limits::KEY`]
/// bytes long.
pub fn check_bridge_key(key: &str) -> Result<(), Error> {
    let invalid = |reason: &str| Error::InvalidName {
        name: key.to_owned(),
        reason: reason.to_owned(),
    };
    if let Err(exceeded) = limits::KEY.check(|| "the key".to_owned(), key.len()) {
        return Err(invalid(&exceeded.to_string()));
    }
    if let Err(error) = zenoh::key_expr::KeyExpr::try_from(key) {
        return Err(invalid(&format!("not a key expression: {error}")));
    }
    if key.split('/').any(|chunk| chunk.contains(['*', '$'])) {
        return Err(invalid("a bridge key names one connection: no wildcards"));
    }
    if key.split('/').any(|chunk| chunk.starts_with('@')) {
        return Err(invalid("`@` chunks are reserved for the bridge's own keys"));
    }
    if key.split('/').next() == Some(ROOT) {
        return Err(invalid(
            "the keys under `coolbot/` are the nodes' own (monitoring, control, agents)",
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn component_keys_round_trip() {
        let key = monitor("robot", "base.motion");
        assert_eq!(key, "coolbot/robot/base.motion/m");
        assert_eq!(parse_component(&key), Some(("robot", "base.motion")));
        assert_eq!(parse_component(&control("n", "x")), Some(("n", "x")));
        assert_eq!(parse_component("coolbot/robot"), None);
        assert_eq!(parse_component("coolbot/robot/a/b/m"), None);
        assert_eq!(parse_component("other/robot/a/m"), None);
        let key = agent("station", "Wanderer", "robot");
        assert_eq!(key, "coolbot/station/@agent/Wanderer/robot");
        assert_eq!(parse_agent(&key), Some(("Wanderer", "robot")));
        assert_eq!(parse_agent("coolbot/station/@agent/Wanderer"), None);
        assert_eq!(parse_agent("coolbot/station/@agent/W/r/x"), None);
        assert_eq!(
            link_namespace("station", "robot"),
            "coolbot-link/station/5-robot-"
        );
    }

    #[test]
    fn no_nodes_namespace_begins_anothers() {
        let nodes = [
            "robot",
            "robot-2",
            "robot-",
            "robot_2",
            "robot.2",
            "robot_d2",
            "r",
            "5-robot",
            "robot.local",
            "robot_dlocal",
            "a_",
            "a__",
            "a.",
        ];
        for a in nodes {
            let space = namespace(a);
            assert!(check_name(&format!("{space}x")).is_ok(), "{space}");
            assert!(!space.contains('.'), "{space}");
            for b in nodes {
                if a != b {
                    assert!(!namespace(b).starts_with(&space), "{a} / {b}");
                }
            }
        }
    }

    #[test]
    fn names_are_checked() {
        for good in ["robot", "base.motion", "node-1", "a_b"] {
            assert!(check_name(good).is_ok(), "{good}");
        }
        for bad in ["", ".a", "a.", "a..b", "a/b", "a*", "@x", "é"] {
            assert!(check_name(bad).is_err(), "{bad}");
        }
        assert!(check_name(&"a".repeat(limits::PATH.max)).is_ok());
        let long = "a".repeat(100_000);
        let error = check_name(&long).unwrap_err().to_string();
        assert!(error.contains("over the limit PATH = 512 bytes"), "{error}");
        assert!(error.len() < 300, "the name is not echoed whole: {error}");
    }

    #[test]
    fn bridge_keys_are_checked() {
        assert!(check_bridge_key("robot/pose").is_ok());
        for bad in [
            "robot/*",
            "robot/**",
            "a/@x",
            "",
            "a//b",
            "/a",
            "coolbot/robot/x/c",
        ] {
            assert!(check_bridge_key(bad).is_err(), "{bad}");
        }
        assert!(check_bridge_key(&"k".repeat(limits::KEY.max)).is_ok());
        let error = check_bridge_key(&"k".repeat(100_000))
            .unwrap_err()
            .to_string();
        assert!(error.contains("over the limit KEY = 512 bytes"), "{error}");
    }
}
