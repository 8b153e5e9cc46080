//! A node's security file (`docs/distribution.md`, "Security"): TLS with mutual
//! authentication, and access rules mapped onto Zenoh's own access control over this
//! crate's key layout ([`crate::keys`]).
//!
//! ```toml
//! allow_plaintext = false        # optional: tcp/ endpoints off loopback
//! nodes = ["robot", "station"]   # optional: more nodes heard under their own names
//!
//! [tls]                          # paths relative to this file
//! ca = "ca.pem"                  # the authority that signs every node's certificate
//! certificate = "robot.pem"      # this node's certificate; its common name is its
//! key = "robot.key"              #   identity in the rules below
//! verify_name = true             # optional: a listener's certificate names its host
//!
//! [[allow]]                      # with no [[allow]], every node of the CA may do all
//! nodes = ["workstation"]        # certificate common names
//! command = ["robot/*"]          # NODE/PATH: control ports `c` (coolctl set, ...)
//! instantiate = ["robot/Arm"]    # NODE or NODE/TYPE: the agent's Instantiate requests
//! publish = ["robot/cmd_vel"]    # bridge keys the nodes may send packets on
//! ```
//!
//! With `[[allow]]` rules, Zenoh's access control is on and denies by default, on
//! what a node receives from each peer, by the common name of the peer's certificate.
//! Every peer may still subscribe, watch liveliness, and query monitoring, info and
//! the bridges named in some `publish` rule (poster values and pull requests). A node
//! is heard (puts, queryables and their replies, liveliness tokens) only under its own
//! name: `coolbot/<name>/**` and its agent, the inlet tokens that carry its name, and
//! on the bridge keys a `publish` rule grants it (packets, a poster's value, pull
//! answers, outlet tokens). The names are those the file gives as nodes ([`Security`]'s
//! `nodes`, a rule's `nodes`, the NODE of `command` and `instantiate`). Only the rules
//! grant commands and instantiation.

use std::collections::BTreeSet;
use std::net::IpAddr;
use std::path::{Path, PathBuf};
use std::sync::Once;

use serde::Deserialize;
use serde_json::{Value, json};

use coolbot::Chain;

use crate::{Error, keys};

/// A node's security: TLS identity, access rules, and whether plaintext may leave
/// loopback. The default (no file) is plaintext on loopback only.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Security {
    tls: Option<Tls>,
    allow_plaintext: bool,
    /// The top-level `nodes`: heard under their own names though no rule names them.
    nodes: Vec<String>,
    rules: Vec<Rule>,
}

/// The TLS part of a security file, paths resolved.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Tls {
    ca: PathBuf,
    certificate: PathBuf,
    key: PathBuf,
    verify_name: bool,
}

/// The file as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    #[serde(default)]
    allow_plaintext: bool,
    #[serde(default)]
    nodes: Vec<String>,
    tls: Option<TlsFile>,
    #[serde(default)]
    allow: Vec<Rule>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct TlsFile {
    ca: PathBuf,
    certificate: PathBuf,
    key: PathBuf,
    #[serde(default = "yes")]
    verify_name: bool,
}

fn yes() -> bool {
    true
}

/// One `[[allow]]` rule: what the nodes it names may do.
#[derive(Debug, Clone, Deserialize, PartialEq, Eq)]
#[serde(deny_unknown_fields)]
struct Rule {
    nodes: Vec<String>,
    #[serde(default)]
    command: Vec<String>,
    #[serde(default)]
    instantiate: Vec<String>,
    #[serde(default)]
    publish: Vec<String>,
}

/// Every message kind Zenoh's access control knows.
const ALL_MESSAGES: [&str; 9] = [
    "put",
    "delete",
    "declare_subscriber",
    "declare_queryable",
    "query",
    "reply",
    "liveliness_token",
    "declare_liveliness_subscriber",
    "liveliness_query",
];

/// Key expressions that cover every key this crate uses: `**` does not match the
/// verbatim `@` chunks, so those are named.
const EVERY_KEY: [&str; 7] = [
    "**",
    "coolbot/*/@agent/*/*",
    "**/@pull",
    "**/@ring/**",
    "**/@out/**",
    "**/@in/**",
    "**/@ack/**",
];

/// Why a security file, or a certificate it names, cannot be used, or what it does not
/// allow ([`Error::Security`]).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SecurityError {
    /// A file (the security file, a certificate) cannot be read.
    #[error("{}: cannot read", .path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// A file larger than [`MAX_FILE_SIZE`].
    #[error("{}: {}", .path.display(), TOO_LARGE)]
    TooLarge {
        /// The file.
        path: PathBuf,
    },
    /// The security file is not UTF-8 text.
    #[error("{}: not UTF-8 text", .path.display())]
    NotText {
        /// The file.
        path: PathBuf,
        /// Where it is not.
        #[source]
        source: std::string::FromUtf8Error,
    },
    /// The security file is not TOML of its format (a syntax error, an unknown field).
    #[error("{}", .path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// The TOML error.
        #[source]
        source: toml::de::Error,
    },
    /// A certificate that is not a PEM X.509 certificate with a common name.
    #[error("{}: {what}", .path.display())]
    Certificate {
        /// The certificate's file.
        path: PathBuf,
        /// What it is not.
        what: &'static str,
        /// The parser's error, if one.
        #[source]
        source: Option<Box<dyn std::error::Error + Send + Sync>>,
    },
    /// The certificate is another node's.
    #[error(
        "{}: the certificate is node `{common_name}`'s: a node opens under its \
         certificate's common name, not `{name}`",
        .path.display()
    )]
    OtherNode {
        /// The certificate's file.
        path: PathBuf,
        /// Its common name.
        common_name: String,
        /// The node's name.
        name: String,
    },
    /// The security file's content is refused (its rules, its names, a `[tls]` file
    /// missing): why.
    #[error("{}: {reason}", .path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// An endpoint, or multicast scouting, that the security does not allow, or an
    /// endpoint that is not one: why.
    #[error("{0}")]
    Endpoint(String),
    /// A TLS or access-control setting that Zenoh's configuration refused.
    #[error("{key}")]
    Config {
        /// The setting's key.
        key: String,
        /// Zenoh's error.
        #[source]
        source: zenoh::Error,
    },
}

fn invalid(path: &Path, reason: impl std::fmt::Display) -> SecurityError {
    SecurityError::Invalid {
        path: path.to_owned(),
        reason: reason.to_string(),
    }
}

/// The largest file read as a security file, or as a certificate or key it names
/// (they are a few kilobytes): a wrong path (`/dev/zero`, a disk image) is refused
/// after this many bytes instead of read to the end.
pub const MAX_FILE_SIZE: u64 = 1 << 20;

/// The file at `path`, read whole if it holds at most [`MAX_FILE_SIZE`] bytes.
pub(crate) fn read_bounded(path: &Path) -> Result<Vec<u8>, SecurityError> {
    use std::io::Read;
    let read = |source| SecurityError::Read {
        path: path.to_owned(),
        source,
    };
    let file = std::fs::File::open(path).map_err(read)?;
    let mut bytes = Vec::new();
    file.take(MAX_FILE_SIZE + 1)
        .read_to_end(&mut bytes)
        .map_err(read)?;
    if bytes.len() as u64 > MAX_FILE_SIZE {
        return Err(SecurityError::TooLarge {
            path: path.to_owned(),
        });
    }
    Ok(bytes)
}

/// Why a file is refused for its size (1024 KiB: [`MAX_FILE_SIZE`]).
const TOO_LARGE: &str =
    "larger than 1024 KiB, the limit of a security, certificate or key file: is it the right file?";
const _: () = assert!(MAX_FILE_SIZE == 1024 * 1024, "TOO_LARGE says 1024 KiB");

impl Security {
    /// No TLS and no rules: plaintext, on loopback only unless
    /// [`Security::allow_plaintext`].
    pub fn none() -> Security {
        Security::default()
    }

    /// Read the security file at `path` (TOML; its format is in the module
    /// documentation and in `docs/distribution.md`). Paths inside are relative to the
    /// file's directory; the certificate files must exist.
    pub fn load(path: &Path) -> Result<Security, Error> {
        let bytes = read_bounded(path)?;
        let text = String::from_utf8(bytes).map_err(|source| SecurityError::NotText {
            path: path.to_owned(),
            source,
        })?;
        Security::parse(&text, path)
    }

    /// [`Security::load`] on `text`, as if read from `path`.
    pub fn parse(text: &str, path: &Path) -> Result<Security, Error> {
        let file: File = toml::from_str(text).map_err(|source| SecurityError::Format {
            path: path.to_owned(),
            source,
        })?;
        let base = path.parent().unwrap_or(Path::new("."));
        let tls = match file.tls {
            None => None,
            Some(tls) => {
                // (Zenoh reads them whole when the session opens: their size is
                // checked here.)
                let resolve = |file: PathBuf, what: &str| {
                    let full = base.join(file);
                    match full.metadata() {
                        Ok(meta) if meta.is_file() && meta.len() <= MAX_FILE_SIZE => Ok(full),
                        Ok(meta) if meta.is_file() => Err(invalid(
                            path,
                            format!("[tls] {what}: {}: {TOO_LARGE}", full.display()),
                        )),
                        _ => Err(invalid(
                            path,
                            format!("[tls] {what}: no file {}", full.display()),
                        )),
                    }
                };
                Some(Tls {
                    ca: resolve(tls.ca, "ca")?,
                    certificate: resolve(tls.certificate, "certificate")?,
                    key: resolve(tls.key, "key")?,
                    verify_name: tls.verify_name,
                })
            }
        };
        for (index, rule) in file.allow.iter().enumerate() {
            rule.check()
                .map_err(|reason| invalid(path, format!("[[allow]] #{}: {reason}", index + 1)))?;
        }
        for node in &file.nodes {
            keys::check_name(node)
                .map_err(|error| invalid(path, format!("nodes: `{node}`: {error}")))?;
        }
        if !file.nodes.is_empty() && file.allow.is_empty() {
            return Err(invalid(
                path,
                "`nodes` says who is heard under their own names when access rules are \
                 on: without [[allow]] rules every node of the CA may do all",
            )
            .into());
        }
        if !file.allow.is_empty() && tls.is_none() {
            return Err(invalid(
                path,
                "[[allow]] rules name nodes by their certificate: they need [tls]",
            )
            .into());
        }
        Ok(Security {
            tls,
            allow_plaintext: file.allow_plaintext,
            nodes: file.nodes,
            rules: file.allow,
        })
    }

    /// Also let plaintext endpoints leave loopback, and multicast scouting run
    /// without TLS, when `allow` (`--insecure`); `false` keeps what the file says.
    pub fn allow_plaintext(mut self, allow: bool) -> Security {
        self.allow_plaintext |= allow;
        self
    }

    /// Whether the node speaks TLS.
    pub fn has_tls(&self) -> bool {
        self.tls.is_some()
    }

    /// Whether access rules are enforced.
    pub fn has_rules(&self) -> bool {
        !self.rules.is_empty()
    }

    /// The common name of this node's certificate, its name in every node's rules
    /// (`None` without `[tls]`).
    pub fn identity(&self) -> Result<Option<String>, Error> {
        self.tls
            .as_ref()
            .map(|tls| common_name(&tls.certificate))
            .transpose()
            .map_err(Error::from)
    }

    /// Whether these rules let the node whose certificate names `who` command the
    /// component at `path` on `node`, as the same rules enforced by that node would
    /// decide (the same key expressions); `None` without rules (no access control).
    pub fn grants_command(&self, who: &str, node: &str, path: &str) -> Option<bool> {
        if self.rules.is_empty() {
            return None;
        }
        let key = zenoh::key_expr::KeyExpr::try_from(keys::control(node, path)).ok()?;
        Some(
            self.rules
                .iter()
                .filter(|rule| rule.nodes.iter().any(|n| n == who))
                .flat_map(|rule| &rule.command)
                .filter_map(|pattern| component_pattern(pattern).ok())
                .filter_map(|(node, chunk)| {
                    zenoh::key_expr::KeyExpr::try_from(keys::control(node, &chunk)).ok()
                })
                .any(|pattern| pattern.includes(&key)),
        )
    }

    /// Check the endpoints and scouting against this security: `tls/` and `quic/`
    /// endpoints need TLS (a `tls/` one is warned about); `tcp/` endpoints off loopback and multicast scouting need TLS or plaintext
    /// allowed.
    pub(crate) fn check(
        &self,
        listen: &[String],
        connect: &[String],
        multicast: bool,
    ) -> Result<(), Error> {
        let open = self.tls.is_some() || self.allow_plaintext;
        for endpoint in listen.iter().chain(connect) {
            let (protocol, loopback) = parse_endpoint(endpoint)?;
            let secure = matches!(protocol, "tls" | "quic");
            if secure && self.tls.is_none() {
                return Err(SecurityError::Endpoint(format!(
                    "`{endpoint}` is a TLS endpoint but the node has no certificate: \
                     give it a security file with [tls] (--config FILE)"
                ))
                .into());
            }
            if protocol == "tls" {
                static SAID: Once = Once::new();
                SAID.call_once(|| {
                    tracing::warn!(
                        "`{endpoint}`: Zenoh's tls/ link reads and writes one TLS session \
                         at once; under two-way traffic it closes and the node looks lost \
                         to its peers: use quic/ endpoints, with the same security file \
                         (docs/distribution.md, \"Which secure link\")"
                    );
                });
            }
            if !secure && !loopback && !self.allow_plaintext {
                return Err(SecurityError::Endpoint(format!(
                    "`{endpoint}` is not on loopback and not TLS: a node opens to a \
                     network with quic/ (or tls/) endpoints and a security file (--config FILE), \
                     or in plaintext only when told to (--insecure, allow_plaintext = true)"
                ))
                .into());
            }
        }
        if multicast && !open {
            return Err(SecurityError::Endpoint(
                "multicast scouting finds peers on the whole network: without TLS name \
                 loopback peers instead (--no-multicast --connect tcp/127.0.0.1:PORT), \
                 or use a security file with [tls] (--config FILE), or allow plaintext \
                 (--insecure)"
                    .to_owned(),
            )
            .into());
        }
        if !open {
            static SAID: Once = Once::new();
            SAID.call_once(|| {
                tracing::info!(
                    "no security file: plaintext on loopback only (docs/distribution.md, \"Security\")"
                );
            });
        } else if self.tls.is_none() {
            tracing::warn!(
                "plaintext allowed off loopback: any host that reaches this node may command it"
            );
        }
        Ok(())
    }

    /// Write the TLS and access-control settings into a Zenoh configuration.
    pub(crate) fn apply(&self, config: &mut zenoh::Config) -> Result<(), Error> {
        let set = |config: &mut zenoh::Config, key: &str, value: Value| {
            config
                .insert_json5(key, &value.to_string())
                .map_err(|source| SecurityError::Config {
                    key: key.to_owned(),
                    source,
                })
        };
        if let Some(tls) = &self.tls {
            let text = |path: &Path| json!(path.display().to_string());
            let prefix = "transport/link/tls";
            set(
                config,
                &format!("{prefix}/root_ca_certificate"),
                text(&tls.ca),
            )?;
            for side in ["listen", "connect"] {
                set(
                    config,
                    &format!("{prefix}/{side}_certificate"),
                    text(&tls.certificate),
                )?;
                set(
                    config,
                    &format!("{prefix}/{side}_private_key"),
                    text(&tls.key),
                )?;
            }
            set(config, &format!("{prefix}/enable_mtls"), json!(true))?;
            set(
                config,
                &format!("{prefix}/verify_name_on_connect"),
                json!(tls.verify_name),
            )?;
        }
        if !self.rules.is_empty() {
            set(config, "access_control", self.access_control())?;
        }
        Ok(())
    }

    /// The names heard under their own keys: the top-level `nodes`, every rule's
    /// `nodes`, and the NODE of every `command` and `instantiate` but `*`; a common
    /// name that cannot be a node's (`keys::check_name`: a space, a `*`) names no keys.
    fn node_names(&self) -> BTreeSet<&str> {
        let targets = self.rules.iter().flat_map(|rule| {
            rule.command
                .iter()
                .filter_map(|pattern| pattern.split_once('/').map(|(node, _)| node))
                .chain(rule.instantiate.iter().map(|pattern| {
                    pattern
                        .split_once('/')
                        .map_or(pattern.as_str(), |(node, _)| node)
                }))
        });
        self.nodes
            .iter()
            .chain(self.rules.iter().flat_map(|rule| &rule.nodes))
            .map(String::as_str)
            .chain(targets)
            .filter(|node| keys::check_name(node).is_ok())
            .collect()
    }

    /// The `access_control` section: deny by default, on what the node receives.
    /// Every peer ("any") may subscribe, watch liveliness and observe; each node named
    /// in the file may speak under its own name (subject `node-<n>`, by certificate);
    /// each rule's nodes get what the rule grants (subject `rule-<n>`). Zenoh allows
    /// a message when one of the subjects the peer matches allows it.
    fn access_control(&self) -> Value {
        let rule = |id: String, messages: &[&str], flow: &str, keys: Vec<String>| {
            json!({
                "id": id,
                "messages": messages,
                "flows": [flow],
                "permission": "allow",
                "key_exprs": keys,
            })
        };
        let every = || {
            EVERY_KEY
                .iter()
                .map(|k| (*k).to_owned())
                .collect::<Vec<_>>()
        };
        let mut rules = vec![
            rule("send".to_owned(), &ALL_MESSAGES, "egress", every()),
            rule(
                "watch".to_owned(),
                &[
                    "declare_subscriber",
                    "declare_liveliness_subscriber",
                    "liveliness_query",
                ],
                "ingress",
                every(),
            ),
            rule(
                "observe".to_owned(),
                &["query"],
                "ingress",
                vec![keys::monitor("*", "*"), keys::info("*", "*")],
            ),
        ];
        let bridges: Vec<String> = self
            .rules
            .iter()
            .flat_map(|rule| &rule.publish)
            .flat_map(|key| [key.clone(), format!("{key}/@pull")])
            .collect();
        let mut any = vec!["send", "watch", "observe"];
        if !bridges.is_empty() {
            rules.push(rule(
                "read-bridges".to_owned(),
                &["query"],
                "ingress",
                bridges,
            ));
            any.push("read-bridges");
        }
        let mut subjects = vec![json!({ "id": "any" })];
        let mut policies = vec![json!({ "rules": any, "subjects": ["any"] })];
        for (index, node) in self.node_names().into_iter().enumerate() {
            let subject = format!("node-{index}");
            // Its inlets acknowledge, and make rings for outlets of their host, under
            // its name (`crate::ledger`, `crate::nearby`).
            let own = vec![
                format!("{}/{node}/**", keys::ROOT),
                keys::agent(node, "*", "*"),
                format!("**/@ack/{node}/*"),
                format!("**/@ring/{node}/*"),
            ];
            // Its inlets' tokens carry its name (and their process); its outlets'
            // tokens too, on the bridge keys a rule lets it publish on.
            let mut tokens = vec![
                format!("{}/{node}/**", keys::ROOT),
                format!("**/@in/{node}/*/*"),
            ];
            tokens.extend(
                self.rules
                    .iter()
                    .filter(|rule| rule.nodes.iter().any(|n| n == node))
                    .flat_map(|rule| &rule.publish)
                    .map(|key| format!("{key}/@out/*/{node}/*")),
            );
            rules.push(rule(
                format!("{subject}-put"),
                &["put"],
                "ingress",
                vec![format!("{}/{node}/**", keys::ROOT)],
            ));
            rules.push(rule(
                format!("{subject}-answer"),
                &["declare_queryable", "reply"],
                "ingress",
                own,
            ));
            rules.push(rule(
                format!("{subject}-tokens"),
                &["liveliness_token"],
                "ingress",
                tokens,
            ));
            // Its requests to agents, under its own name only (the last chunk of the
            // agent's key): the agent builds in the requester's namespace, so a node
            // that may instantiate cannot have an agent build under another's.
            let instantiate: Vec<String> = self
                .rules
                .iter()
                .filter(|rule| rule.nodes.iter().any(|n| n == node))
                .flat_map(|rule| &rule.instantiate)
                .map(|pattern| {
                    let (target, type_name) = pattern.split_once('/').unwrap_or((pattern, "*"));
                    keys::agent(target, type_name, node)
                })
                .collect();
            let mut granted = vec![
                format!("{subject}-put"),
                format!("{subject}-answer"),
                format!("{subject}-tokens"),
            ];
            if !instantiate.is_empty() {
                rules.push(rule(
                    format!("{subject}-instantiate"),
                    &["query"],
                    "ingress",
                    instantiate,
                ));
                granted.push(format!("{subject}-instantiate"));
            }
            subjects.push(json!({ "id": subject, "cert_common_names": [node] }));
            policies.push(json!({
                "rules": granted,
                "subjects": [subject],
            }));
        }
        for (index, allowed) in self.rules.iter().enumerate() {
            let subject = format!("rule-{index}");
            let mut granted = Vec::new();
            let mut grant = |what: &str, messages: &[&str], keys: Vec<String>| {
                if !keys.is_empty() {
                    let id = format!("{subject}-{what}");
                    rules.push(rule(id.clone(), messages, "ingress", keys));
                    granted.push(id);
                }
            };
            grant(
                "command",
                &["query"],
                allowed
                    .command
                    .iter()
                    .map(|pattern| {
                        let (node, path) = component_pattern(pattern).expect("checked on load");
                        keys::control(node, &path)
                    })
                    .collect(),
            );
            // (`instantiate` is granted per node, above: each its own requester chunk.)
            grant("publish", &["put"], allowed.publish.clone());
            // Its outlets ask the inlets what they had (`crate::ledger`); nobody else
            // may: a question reports ended epochs, which inlets count missing.
            grant(
                "ask",
                &["query"],
                allowed
                    .publish
                    .iter()
                    .flat_map(|key| [format!("{key}/@ack/**"), format!("{key}/@ring/**")])
                    .collect(),
            );
            // The producer on a bridge key answers its poster and pull queries.
            grant(
                "serve",
                &["declare_queryable", "reply"],
                allowed
                    .publish
                    .iter()
                    .flat_map(|key| [key.clone(), format!("{key}/@pull")])
                    .collect(),
            );
            // (A rule of `instantiate` only grants through its nodes' subjects.)
            if !granted.is_empty() {
                subjects.push(json!({ "id": subject, "cert_common_names": allowed.nodes }));
                policies.push(json!({ "rules": granted, "subjects": [subject] }));
            }
        }
        json!({
            "enabled": true,
            "default_permission": "deny",
            "rules": rules,
            "subjects": subjects,
            "policies": policies,
        })
    }
}

impl Rule {
    fn check(&self) -> Result<(), String> {
        if self.nodes.is_empty() || self.nodes.iter().any(|n| n.trim().is_empty()) {
            return Err("`nodes` names one certificate common name or more".to_owned());
        }
        if self.command.is_empty() && self.instantiate.is_empty() && self.publish.is_empty() {
            return Err(
                "the rule grants nothing: give `command`, `instantiate` or `publish`".to_owned(),
            );
        }
        for pattern in &self.command {
            component_pattern(pattern)?;
        }
        for pattern in &self.instantiate {
            instantiate_pattern(pattern)
                .map_err(|reason| format!("instantiate `{pattern}`: {reason}"))?;
        }
        for key in &self.publish {
            publish_pattern(key)?;
        }
        Ok(())
    }
}

/// A node in a rule: a name, or `*` for every node.
fn node_pattern(node: &str) -> Result<(), String> {
    if node == "*" {
        return Ok(());
    }
    keys::check_name(node).map_err(|error| error.to_string())
}

/// `NODE` or `NODE/TYPE` in an `instantiate` rule: NODE is a name or `*`, TYPE a
/// component type name or `*` (NODE alone: every type).
fn instantiate_pattern(pattern: &str) -> Result<(), String> {
    let (node, type_name) = pattern.split_once('/').unwrap_or((pattern, "*"));
    node_pattern(node)?;
    if type_name != "*" {
        keys::check_name(type_name).map_err(|error| error.to_string())?;
    }
    Ok(())
}

/// `NODE/PATH` in a `command` rule, as the node and the key chunk of the path: NODE
/// is a name or `*`; PATH is a component path, `*` (every component), or `PREFIX.*`
/// (every component inside `PREFIX`).
fn component_pattern(pattern: &str) -> Result<(&str, String), String> {
    let bad = |reason: &str| format!("command `{pattern}`: {reason}");
    let (node, path) = pattern
        .split_once('/')
        .ok_or_else(|| bad("write NODE/PATH (e.g. robot/base.motion, robot/*)"))?;
    node_pattern(node).map_err(|reason| bad(&reason))?;
    let chunk = if path == "*" {
        "*".to_owned()
    } else if let Some(prefix) = path.strip_suffix(".*") {
        keys::check_name(prefix).map_err(|error| bad(&error.to_string()))?;
        format!("{prefix}.$*")
    } else {
        keys::check_name(path).map_err(|error| bad(&error.to_string()))?;
        path.to_owned()
    };
    Ok((node, chunk))
}

/// A bridge key in a `publish` rule: a key expression (wildcards allowed) without `@`
/// chunks.
fn publish_pattern(key: &str) -> Result<(), String> {
    let expr = zenoh::key_expr::KeyExpr::try_from(key)
        .map_err(|error| format!("publish `{key}`: not a key expression: {}", Chain(&*error)))?;
    // The node keys (monitoring, control, shapes, agents) are granted by name and
    // `command`/`instantiate` rules only: a publish rule that reached them (`**`,
    // `coolbot/**`) would let its nodes, and every peer's queries, in there.
    let nodes = zenoh::key_expr::KeyExpr::try_from(format!("{}/**", keys::ROOT))
        .map_err(|error| format!("the node keys: {}", Chain(&*error)))?;
    if expr.intersects(&nodes) || key == keys::ROOT {
        return Err(format!(
            "publish `{key}`: it reaches the node keys under `{}/`, which only `command` and \
             `instantiate` rules open; name the bridge keys (e.g. `coolbot-link/**`)",
            keys::ROOT
        ));
    }
    if key.split('/').any(|chunk| chunk.starts_with('@')) {
        return Err(format!(
            "publish `{key}`: `@` chunks are the bridge's own keys; name the bridge key"
        ));
    }
    Ok(())
}

/// Check that a node called `name` holds, in `config`, a certificate of that common
/// name, if it holds one: the access rules name nodes by their certificates, the keys
/// by their node names, and both must be one name.
pub(crate) fn check_certificate_name(config: &zenoh::Config, name: &str) -> Result<(), Error> {
    let Ok(json) = config.get_json("transport/link/tls/listen_certificate") else {
        return Ok(());
    };
    let Ok(Some(path)) = serde_json::from_str::<Option<PathBuf>>(&json) else {
        return Ok(());
    };
    let common_name = common_name(&path)?;
    if common_name != name {
        return Err(SecurityError::OtherNode {
            path,
            common_name,
            name: name.to_owned(),
        }
        .into());
    }
    Ok(())
}

/// The common name of the PEM certificate at `path`.
fn common_name(path: &Path) -> Result<String, SecurityError> {
    let bad = |what: &'static str, source: Option<Box<dyn std::error::Error + Send + Sync>>| {
        SecurityError::Certificate {
            path: path.to_owned(),
            what,
            source,
        }
    };
    let bytes = read_bounded(path)?;
    let (_, pem) = x509_parser::pem::parse_x509_pem(&bytes)
        .map_err(|error| bad("not a PEM certificate", Some(Box::new(error))))?;
    let certificate = pem
        .parse_x509()
        .map_err(|error| bad("not an X.509 certificate", Some(Box::new(error))))?;
    certificate
        .subject()
        .iter_common_name()
        .next()
        .and_then(|cn| cn.as_str().ok())
        .map(str::to_owned)
        .ok_or_else(|| bad("the certificate has no common name", None))
}

/// An endpoint's protocol, and whether its address is on loopback.
fn parse_endpoint(endpoint: &str) -> Result<(&str, bool), SecurityError> {
    let bad = || {
        SecurityError::Endpoint(format!(
            "`{endpoint}` is not an endpoint (write e.g. tcp/127.0.0.1:7447, quic/robot.local:7447)"
        ))
    };
    let address = endpoint.split(['?', '#']).next().unwrap_or_default();
    let (protocol, address) = address.split_once('/').ok_or_else(bad)?;
    let host = match address.strip_prefix('[') {
        Some(rest) => rest.split_once(']').ok_or_else(bad)?.0,
        None => address.rsplit_once(':').map_or(address, |(host, _)| host),
    };
    let loopback = host.eq_ignore_ascii_case("localhost")
        || host.parse::<IpAddr>().is_ok_and(|ip| ip.is_loopback());
    Ok((protocol, loopback))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn endpoints(security: &Security, listen: &[&str], multicast: bool) -> Result<(), String> {
        let listen: Vec<String> = listen.iter().map(|e| (*e).to_owned()).collect();
        security
            .check(&listen, &[], multicast)
            .map_err(|error| Chain(&error).to_string())
    }

    #[test]
    fn plaintext_stays_on_loopback_unless_allowed() {
        let none = Security::none();
        for good in ["tcp/127.0.0.1:7447", "tcp/[::1]:7447", "tcp/localhost:7447"] {
            assert_eq!(endpoints(&none, &[good], false), Ok(()), "{good}");
        }
        for open in ["tcp/0.0.0.0:7447", "tcp/192.168.1.10:7447", "tcp/[::]:7447"] {
            let error = endpoints(&none, &[open], false).unwrap_err();
            assert!(error.contains("not on loopback"), "{error}");
            let insecure = Security::none().allow_plaintext(true);
            assert_eq!(endpoints(&insecure, &[open], false), Ok(()), "{open}");
        }
        let error = endpoints(&none, &[], true).unwrap_err();
        assert!(error.contains("multicast"), "{error}");
        let error = endpoints(&none, &["tls/127.0.0.1:7447"], false).unwrap_err();
        assert!(error.contains("no certificate"), "{error}");
        assert!(endpoints(&none, &["127.0.0.1"], false).is_err());
    }

    fn parse(text: &str) -> Result<Security, String> {
        Security::parse(text, Path::new("/nowhere/security.toml"))
            .map_err(|error| Chain(&error).to_string())
    }

    #[test]
    fn bad_files_are_clear_errors() {
        let cases = [
            ("colour = 1", "unknown field"),
            (
                "[tls]\nca = \"ca.pem\"\ncertificate = \"a\"\nkey = \"b\"",
                "no file /nowhere/ca.pem",
            ),
            (
                "[[allow]]\nnodes = [\"a\"]\ncommand = [\"robot/*\"]",
                "need [tls]",
            ),
        ];
        for (text, expected) in cases {
            let error = parse(text).unwrap_err();
            assert!(error.contains(expected), "{text}: {error}");
        }
        let rule = |body: &str| Rule::check(&toml::from_str::<Rule>(body).unwrap());
        assert!(rule("nodes = []\ncommand = [\"a/b\"]").is_err());
        assert!(
            rule("nodes = [\"a\"]")
                .unwrap_err()
                .contains("grants nothing")
        );
        assert!(rule("nodes = [\"a\"]\ncommand = [\"robot\"]").is_err());
        assert!(rule("nodes = [\"a\"]\ncommand = [\"robot/a/b\"]").is_err());
        assert!(rule("nodes = [\"a\"]\ninstantiate = [\"a/b/c\"]").is_err());
        assert!(rule("nodes = [\"a\"]\ninstantiate = [\"a/B*\"]").is_err());
        assert_eq!(
            rule("nodes = [\"a\"]\ninstantiate = [\"a/B\", \"*/*\", \"c\"]"),
            Ok(())
        );
        assert!(rule("nodes = [\"a\"]\npublish = [\"k/@pull\"]").is_err());
        assert!(rule("nodes = [\"a\"]\npublish = [\"k//x\"]").is_err());
        // A publish pattern that reaches the node keys would open them to its nodes
        // (put, answer) and to every peer's queries (commands included).
        for reaching in [
            "**",
            "coolbot/**",
            "*/robot/**",
            "coolbot",
            "coolbot/robot/x/c",
        ] {
            let error = rule(&format!("nodes = [\"a\"]\npublish = [\"{reaching}\"]")).unwrap_err();
            assert!(error.contains("node keys"), "{reaching}: {error}");
        }
        assert_eq!(
            rule("nodes = [\"a\"]\npublish = [\"coolbot-link/**\"]"),
            Ok(())
        );
        assert_eq!(
            rule("nodes = [\"a\"]\ncommand = [\"*/base.*\", \"r/*\"]\npublish = [\"k/**\"]"),
            Ok(())
        );
    }

    #[test]
    fn rules_become_zenoh_key_expressions() {
        let security = Security {
            tls: None,
            allow_plaintext: false,
            nodes: vec!["camera".to_owned()],
            rules: vec![Rule {
                nodes: vec!["ops".to_owned()],
                command: vec!["robot/base.*".to_owned(), "*/arm".to_owned()],
                instantiate: vec!["station".to_owned(), "robot/Planner".to_owned()],
                publish: vec!["robot/cmd".to_owned()],
            }],
        };
        let acl = security.access_control();
        let keys_of = |id: &str| {
            acl["rules"]
                .as_array()
                .unwrap()
                .iter()
                .find(|rule| rule["id"] == id)
                .map(|rule| rule["key_exprs"].clone())
        };
        assert_eq!(
            keys_of("rule-0-command"),
            Some(json!(["coolbot/robot/base.$*/c", "coolbot/*/arm/c"]))
        );
        // Each node's own requests only: the requester's chunk is its name.
        assert_eq!(keys_of("rule-0-instantiate"), None);
        assert_eq!(
            keys_of("node-1-instantiate"),
            Some(json!([
                "coolbot/station/@agent/*/ops",
                "coolbot/robot/@agent/Planner/ops"
            ]))
        );
        assert_eq!(keys_of("rule-0-publish"), Some(json!(["robot/cmd"])));
        assert_eq!(
            keys_of("read-bridges"),
            Some(json!(["robot/cmd", "robot/cmd/@pull"]))
        );
        assert_eq!(
            keys_of("rule-0-ask"),
            Some(json!(["robot/cmd/@ack/**", "robot/cmd/@ring/**"]))
        );
        // `**` does not reach the guarded keys: commands and instantiation are granted
        // only by the rules, and the verbatim chunks the crate uses are named.
        let includes = |pattern: &str, key: &str| {
            let pattern = zenoh::key_expr::KeyExpr::try_from(pattern).unwrap();
            pattern.includes(&zenoh::key_expr::KeyExpr::try_from(key).unwrap())
        };
        assert!(!includes("**", "coolbot/station/@agent/Planner/ops"));
        assert!(includes(
            "coolbot/*/@agent/*/*",
            "coolbot/station/@agent/Planner/ops"
        ));
        assert!(!includes(
            "coolbot/station/@agent/*/ops",
            "coolbot/station/@agent/Planner"
        ));
        assert!(!includes(
            "coolbot/station/@agent/*/ops",
            "coolbot/station/@agent/Planner/*"
        ));
        assert!(includes("**/@pull", "a/b/@pull"));
        assert!(includes("**/@out/**", "a/b/@out/poster/n/x"));
        assert!(includes("**/@ack/**", "a/b/@ack/station/inlet"));
        assert!(includes(
            "coolbot/robot/base.$*/c",
            "coolbot/robot/base.motion/c"
        ));
        assert!(!includes("coolbot/robot/base.$*/c", "coolbot/robot/arm/c"));
        // The observe rules do not reach control keys.
        assert!(!includes(
            &keys::monitor("*", "*"),
            &keys::control("robot", "arm")
        ));
        let mut config = zenoh::Config::default();
        Security::apply(&security, &mut config).expect("zenoh takes the section");
    }

    /// Zenoh's decision on an ingress message from a peer whose certificate names
    /// `peer` (`None`: no certificate), over the section's JSON: allowed when a subject
    /// the peer matches has an allow rule for the message on a key expression that
    /// includes `key` (the section has no deny rules).
    fn allowed(acl: &Value, peer: Option<&str>, message: &str, key: &str) -> bool {
        let key = zenoh::key_expr::KeyExpr::try_from(key).unwrap();
        let matches = |subject: &Value| match subject["cert_common_names"].as_array() {
            None => true,
            Some(names) => peer.is_some_and(|peer| names.iter().any(|n| n == peer)),
        };
        let subjects: Vec<&Value> = acl["subjects"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|subject| matches(subject))
            .map(|subject| &subject["id"])
            .collect();
        let rule_ids: Vec<&Value> = acl["policies"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|policy| {
                policy["subjects"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .any(|s| subjects.contains(&s))
            })
            .flat_map(|policy| policy["rules"].as_array().unwrap())
            .collect();
        acl["rules"].as_array().unwrap().iter().any(|rule| {
            rule_ids.contains(&&rule["id"])
                && rule["flows"] == json!(["ingress"])
                && rule["messages"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .any(|m| m == message)
                && rule["key_exprs"].as_array().unwrap().iter().any(|pattern| {
                    zenoh::key_expr::KeyExpr::try_from(pattern.as_str().unwrap())
                        .unwrap()
                        .includes(&key)
                })
        })
    }

    #[test]
    fn a_node_is_heard_only_under_its_own_name() {
        let security = parse_rules(
            "nodes = [\"camera\"]\n\
             [[allow]]\nnodes = [\"station\"]\npublish = [\"link/**\"]\n\
             [[allow]]\nnodes = [\"ops\"]\ncommand = [\"robot/*\"]\ninstantiate = [\"station\", \"robot/Planner\"]\n\
             [[allow]]\nnodes = [\"*\", \"the ops\"]\ncommand = [\"robot/logger\"]\n",
        );
        let acl = security.access_control();
        let cases: &[(Option<&str>, &str, &str, bool)] = &[
            // Its own monitoring events, echoes, queryables, replies, tokens.
            (Some("station"), "put", "coolbot/station/wanderer/m", true),
            (
                Some("station"),
                "put",
                "coolbot/station/wanderer/o/pose",
                true,
            ),
            (
                Some("station"),
                "declare_queryable",
                "coolbot/station/wanderer/c",
                true,
            ),
            (Some("station"), "reply", "coolbot/station/wanderer/s", true),
            (
                Some("station"),
                "declare_queryable",
                "coolbot/station/@agent/*/*",
                true,
            ),
            (
                Some("station"),
                "reply",
                "coolbot/station/@agent/Wanderer/ops",
                true,
            ),
            (Some("station"), "liveliness_token", "coolbot/station", true),
            (Some("camera"), "put", "coolbot/camera/lens/m", true),
            (Some("robot"), "reply", "coolbot/robot/logger/m", true),
            (Some("ops"), "liveliness_token", "coolbot/ops", true),
            // Not under another node's name.
            (Some("station"), "put", "coolbot/robot/logger/m", false),
            (Some("station"), "put", "coolbot/robot/logger/o/out", false),
            (Some("station"), "reply", "coolbot/robot/logger/m", false),
            (
                Some("station"),
                "declare_queryable",
                "coolbot/robot/logger/c",
                false,
            ),
            (
                Some("station"),
                "declare_queryable",
                "coolbot/robot/@agent/*/*",
                false,
            ),
            (
                Some("station"),
                "declare_queryable",
                "coolbot/*/logger/m",
                false,
            ),
            (Some("station"), "liveliness_token", "coolbot/robot", false),
            (Some("ops"), "put", "coolbot/station/wanderer/m", false),
            // A common name that cannot be a node's names no keys.
            (Some("*"), "put", "coolbot/robot/logger/m", false),
            // A name no part of the file gives, or no certificate: not heard.
            (Some("mallory"), "put", "coolbot/mallory/x/m", false),
            (None, "put", "coolbot/robot/logger/m", false),
            (None, "liveliness_token", "coolbot/robot", false),
            // Bridges: packets, answers and outlet tokens where `publish` allows;
            // inlet tokens under one's own name.
            (Some("station"), "put", "link/robot/out/pose", true),
            (Some("station"), "reply", "link/robot/out/pose", true),
            (Some("station"), "reply", "link/robot/out/pose/@pull", true),
            (
                Some("station"),
                "declare_queryable",
                "link/robot/out/pose/@pull",
                true,
            ),
            (
                Some("station"),
                "liveliness_token",
                "link/robot/out/pose/@out/poster/station/w",
                true,
            ),
            (
                Some("station"),
                "liveliness_token",
                "link/robot/out/pose/@out/poster/robot/w",
                false,
            ),
            (Some("station"), "put", "other/pose", false),
            (Some("station"), "reply", "other/pose/@pull", false),
            (Some("ops"), "put", "link/robot/out/pose", false),
            (Some("ops"), "reply", "link/robot/out/pose", false),
            (
                Some("ops"),
                "liveliness_token",
                "link/a/@in/ops/inlet/0123abcd",
                true,
            ),
            (
                Some("ops"),
                "liveliness_token",
                "link/a/@in/station/inlet/0123abcd",
                false,
            ),
            // Its inlets acknowledge under its own name only.
            (Some("ops"), "reply", "link/a/@ack/ops/inlet", true),
            (Some("ops"), "reply", "link/a/@ack/station/inlet", false),
            // Only a node that may publish on a key asks its inlets.
            (
                Some("mallory"),
                "query",
                "link/robot/out/pose/@ack/**",
                false,
            ),
            (
                Some("station"),
                "query",
                "link/robot/out/pose/@ack/**",
                true,
            ),
            // Rings for outlets on the host (`crate::nearby`): asked for by the
            // publishers of the key only, made under the inlet's own name only.
            (
                Some("station"),
                "query",
                "link/robot/out/pose/@ring/**",
                true,
            ),
            (
                Some("mallory"),
                "query",
                "link/robot/out/pose/@ring/**",
                false,
            ),
            (
                Some("ops"),
                "declare_queryable",
                "link/a/@ring/ops/inlet",
                true,
            ),
            (Some("ops"), "reply", "link/a/@ring/ops/inlet", true),
            (
                Some("ops"),
                "declare_queryable",
                "link/a/@ring/station/inlet",
                false,
            ),
            (Some("ops"), "reply", "link/a/@ring/station/inlet", false),
            // Everyone watches and observes; only the rules command and instantiate.
            (None, "declare_subscriber", "coolbot/robot/logger/m", true),
            (None, "liveliness_query", "coolbot/*", true),
            (Some("mallory"), "query", "coolbot/robot/logger/m", true),
            (Some("mallory"), "query", "link/robot/out/pose/@pull", true),
            (Some("station"), "query", "coolbot/robot/logger/c", false),
            (Some("ops"), "query", "coolbot/robot/logger/c", true),
            (
                Some("station"),
                "query",
                "coolbot/station/@agent/Wanderer/station",
                false,
            ),
            (
                Some("ops"),
                "query",
                "coolbot/station/@agent/Wanderer/ops",
                true,
            ),
            (
                Some("ops"),
                "query",
                "coolbot/robot/@agent/Planner/ops",
                true,
            ),
            (
                Some("ops"),
                "query",
                "coolbot/robot/@agent/Mapper/ops",
                false,
            ),
            // Under its own name only: not as another node, nor as any.
            (
                Some("ops"),
                "query",
                "coolbot/station/@agent/Wanderer/station",
                false,
            ),
            (
                Some("ops"),
                "query",
                "coolbot/station/@agent/Wanderer/*",
                false,
            ),
            (
                Some("the ops"),
                "query",
                "coolbot/station/@agent/Wanderer/the ops",
                false,
            ),
        ];
        for &(peer, message, key, expected) in cases {
            assert_eq!(
                allowed(&acl, peer, message, key),
                expected,
                "{peer:?} {message} {key}"
            );
        }
    }

    fn parse_rules(rules: &str) -> Security {
        let file: File = toml::from_str(rules).expect("a security file");
        for rule in &file.allow {
            rule.check().expect("a good rule");
        }
        Security {
            tls: None,
            allow_plaintext: false,
            nodes: file.nodes,
            rules: file.allow,
        }
    }

    #[test]
    fn commands_granted_are_those_the_keys_allow() {
        let security = parse_rules(
            "[[allow]]\nnodes = [\"ops\", \"dev\"]\ncommand = [\"robot/base.*\", \"*/arm\"]\n\
             [[allow]]\nnodes = [\"dev\"]\ncommand = [\"station/*\"]\n",
        );
        let cases = [
            ("ops", "robot", "base.motion", true),
            ("ops", "robot", "base", false),
            ("ops", "robot", "logger", false),
            ("ops", "station", "arm", true),
            ("ops", "station", "wanderer", false),
            ("dev", "station", "wanderer", true),
            ("guest", "robot", "base.motion", false),
        ];
        for (who, node, path, expected) in cases {
            assert_eq!(
                security.grants_command(who, node, path),
                Some(expected),
                "{who} {node}/{path}"
            );
        }
        assert_eq!(Security::none().grants_command("ops", "robot", "x"), None);
    }

    #[test]
    fn files_are_read_up_to_a_size_limit() {
        // An endless file ends at the limit, at once.
        let error = Chain(&Security::load(Path::new("/dev/zero")).unwrap_err()).to_string();
        assert!(
            error.starts_with("security: /dev/zero: larger than 1024 KiB"),
            "{error}"
        );
        let dir = tempfile::tempdir().unwrap();
        let sized = |name: &str, len: u64| {
            let path = dir.path().join(name);
            let file = std::fs::File::create(&path).unwrap();
            file.set_len(len).unwrap();
            path
        };
        assert_eq!(
            read_bounded(&sized("limit", MAX_FILE_SIZE)).unwrap().len() as u64,
            MAX_FILE_SIZE
        );
        assert!(read_bounded(&sized("over", MAX_FILE_SIZE + 1)).is_err());
        // The certificate files a security file names: checked before Zenoh reads them.
        sized("ca.pem", 10);
        sized("robot.pem", MAX_FILE_SIZE + 1);
        sized("robot.key", 10);
        let text = "[tls]\nca = \"ca.pem\"\ncertificate = \"robot.pem\"\nkey = \"robot.key\"\n";
        let file = dir.path().join("security.toml");
        std::fs::write(&file, text).unwrap();
        let error = Chain(&Security::load(&file).unwrap_err()).to_string();
        assert!(
            error.contains("[tls] certificate: ") && error.contains("larger than 1024 KiB"),
            "{error}"
        );
    }

    #[test]
    fn top_level_nodes_are_node_names_and_need_rules() {
        let error = parse("nodes = [\"robot\"]").unwrap_err();
        assert!(error.contains("without [[allow]] rules"), "{error}");
        let error = parse("nodes = [\"*\"]").unwrap_err();
        assert!(error.contains("nodes: `*`"), "{error}");
    }
}
