//! What `coolctl` does, as a library (the binary parses arguments and prints; tests
//! call these on a session of their own): list nodes and components, watch a
//! component's monitoring events, send it commands.

use std::io::Write;
use std::time::{Duration, Instant};

use coolbot::{Command, Controllable, Monitor, MonitorEvent, Value};
use zenoh::Wait;
use zenoh::query::{ConsolidationMode, QueryTarget};

use crate::echo::EchoedRaw;
use crate::info::ComponentInfo;
use crate::limits::{self, Limit};
use crate::{ControlReply, keys};

/// `sample`'s payload as a JSON `T` ([`decode_payload`]).
fn decode<T: serde::de::DeserializeOwned>(
    sample: &zenoh::sample::Sample,
    limit: Limit,
    what: &str,
) -> Result<T, CtlError> {
    decode_payload(sample.key_expr().as_str(), sample.payload(), limit, what)
}

/// `payload` (sent on `key`) as a JSON `T`, decoded only when it is within `limit`
/// (`what`, for the refusal): its length is checked before its bytes are copied.
fn decode_payload<T: serde::de::DeserializeOwned>(
    key: &str,
    payload: &zenoh::bytes::ZBytes,
    limit: Limit,
    what: &str,
) -> Result<T, CtlError> {
    limit
        .check(|| what.to_owned(), payload.len())
        .map_err(|source| CtlError::TooLarge {
            key: key.to_owned(),
            source,
        })?;
    serde_json::from_slice(&payload.to_bytes()).map_err(|source| CtlError::Decode {
        key: key.to_owned(),
        source,
    })
}

/// Why a `coolctl` command failed.
#[derive(Debug, thiserror::Error)]
pub enum CtlError {
    /// Zenoh refused an operation.
    #[error("zenoh: cannot {action}")]
    Zenoh {
        /// What was being done.
        action: &'static str,
        /// Zenoh's error.
        #[source]
        source: zenoh::Error,
    },
    /// The network layer refused something (a name, the security file).
    #[error(transparent)]
    Network(#[from] crate::Error),
    /// `coolctl foxglove` cannot serve. (The source is a `foxglove::FoxgloveError`,
    /// boxed whole: the operator's commands do not depend on the server built on them.)
    #[cfg(feature = "foxglove")]
    #[error("coolctl foxglove")]
    Foxglove(#[source] Box<dyn std::error::Error + Send + Sync>),
    /// A target that is not `<node>/<path>`.
    #[error("`{0}` is not a component address: write <node>/<path>, e.g. robot/base.motion")]
    BadTarget(String),
    /// An argument that cannot be understood.
    #[error("{0}")]
    BadArgument(String),
    /// Nothing answered.
    #[error(
        "no component answered at `{target}` within {waited:?} (is the node running and reachable, and do its access rules let this node do that?)"
    )]
    NoAnswer {
        /// The target.
        target: String,
        /// How long it waited.
        waited: Duration,
    },
    /// Nothing answered a command, and the access rules of the security file this
    /// `coolctl` was given do not grant it.
    #[error(
        "no component answered at `{target}` within {waited:?}: the access rules of this security file do not let `{who}` command `{target}` (a node that enforces them drops the command unanswered)"
    )]
    Refused {
        /// The target.
        target: String,
        /// How long it waited.
        waited: Duration,
        /// This `coolctl`'s name in the rules (its certificate's common name).
        who: String,
    },
    /// No node at all answered.
    #[error("no node is alive (none answered within {waited:?}{})", if *.connected {
        ""
    } else {
        "; this session reached no Zenoh peer: is a node listening at a --connect \
         endpoint, and can this machine reach it?"
    })]
    NoNode {
        /// How long it waited.
        waited: Duration,
        /// Whether the session was connected to any Zenoh peer or router.
        connected: bool,
    },
    /// Nodes are alive, but none of the nodes asked for answered with a component.
    #[error("{}", no_components(node.as_deref(), alive, *waited))]
    NoComponents {
        /// The node asked for, if one was.
        node: Option<String>,
        /// The nodes alive, comma-separated.
        alive: String,
        /// How long it waited.
        waited: Duration,
    },
    /// `coolctl top` without a terminal to draw on.
    #[error(
        "`coolctl top` needs a terminal ({why}): `coolctl top --once` prints one screen as \
         text, `--once --json` one snapshot as JSON"
    )]
    NoTerminal {
        /// Why there is none.
        why: &'static str,
        /// The terminal library's error, if it said one.
        #[source]
        source: Option<std::io::Error>,
    },
    /// No node of that name is alive.
    #[error("no node `{node}` is alive (nodes alive: {alive})")]
    UnknownNode {
        /// The node asked for.
        node: String,
        /// The nodes alive, comma-separated (`none`).
        alive: String,
    },
    /// The node is alive but has no such component.
    #[error("node `{node}` has no component `{path}` (its components: {known})")]
    UnknownComponent {
        /// The node.
        node: String,
        /// The path asked for.
        path: String,
        /// Its components, comma-separated (`none`).
        known: String,
    },
    /// The component has no such output, or its node does not echo it.
    #[error("{0}")]
    UnknownPort(String),
    /// An answer, or a sample, over its limit (`crate::limits`): not decoded.
    #[error("`{key}` sent more than coolctl decodes")]
    TooLarge {
        /// The key that sent it.
        key: String,
        /// The limit and the size.
        #[source]
        source: limits::Exceeded,
    },
    /// An answer that is not what a node sends.
    #[error("`{key}` answered something that does not decode")]
    Decode {
        /// The key that answered.
        key: String,
        /// What failed.
        #[source]
        source: serde_json::Error,
    },
    /// A query answered with an error (its text).
    #[error("`{key}` answered with an error: {reason}")]
    ErrorReply {
        /// The key that answered.
        key: String,
        /// The error's text.
        reason: String,
    },
    /// A command that does not encode (JSON).
    #[error("the command does not encode")]
    Encode(#[source] serde_json::Error),
    /// Writing the output failed.
    #[error(transparent)]
    Io(#[from] std::io::Error),
}

/// [`CtlError::NoComponents`]'s message.
fn no_components(node: Option<&str>, alive: &str, waited: Duration) -> String {
    let why = "a node that only runs an agent has none until something is placed on it";
    match node {
        Some(node) => {
            format!(
                "node `{node}` is alive, but no component of it answered within {waited:?} ({why})"
            )
        }
        None => format!("no component answered within {waited:?} (nodes alive: {alive}; {why})"),
    }
}

impl CtlError {
    /// A closure turning Zenoh's error into [`CtlError::Zenoh`] for `action`, for
    /// `map_err`.
    pub fn zenoh(action: &'static str) -> impl FnOnce(zenoh::Error) -> CtlError {
        move |source| CtlError::Zenoh { action, source }
    }
}

/// A parsed `<node>/<path>` address.
fn target(address: &str) -> Result<(&str, &str), CtlError> {
    let (node, path) = address
        .split_once('/')
        .ok_or_else(|| CtlError::BadTarget(address.to_owned()))?;
    if keys::check_name(node).is_err() || keys::check_name(path).is_err() {
        return Err(CtlError::BadTarget(address.to_owned()));
    }
    Ok((node, path))
}

/// Parse a duration written `500us`, `20ms`, `2s` or `1min`.
pub fn parse_duration(text: &str) -> Result<Duration, CtlError> {
    let bad = || {
        CtlError::BadArgument(format!(
            "`{text}` is not a duration (write e.g. 500us, 20ms, 2s, 1min)"
        ))
    };
    let split = text
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .ok_or_else(bad)?;
    let (number, unit) = text.split_at(split);
    let number: f64 = number.parse().map_err(|_| bad())?;
    let seconds = match unit {
        "ns" => number / 1e9,
        "us" => number / 1e6,
        "ms" => number / 1e3,
        "s" => number,
        "min" => number * 60.0,
        _ => return Err(bad()),
    };
    Duration::try_from_secs_f64(seconds).map_err(|_| bad())
}

/// A variable's value as written on the command line: `true`/`false`, an integer
/// (signed if it starts with `-`), a float, a JSON string, list or object, else the
/// text itself as a string.
pub fn parse_value(text: &str) -> Value {
    match text {
        "true" => return Value::Bool(true),
        "false" => return Value::Bool(false),
        _ => {}
    }
    if let Ok(unsigned) = text.parse::<u64>() {
        return Value::UInt(unsigned);
    }
    if let Ok(signed) = text.parse::<i64>() {
        return Value::Int(signed);
    }
    if let Ok(float) = text.parse::<f64>() {
        return Value::Float(float);
    }
    match serde_json::from_str::<serde_json::Value>(text) {
        Ok(serde_json::Value::String(string)) => Value::Str(string),
        Ok(json @ (serde_json::Value::Array(_) | serde_json::Value::Object(_))) => {
            Value::Json(json)
        }
        _ => Value::Str(text.to_owned()),
    }
}

/// The command `coolctl set` sends for `args`: `state <ready|running|suspended|dead>`,
/// or `<name>=<value>` where `period`, `max_response` (durations), `priority` and
/// `quality` (integers) are the default controllable variables and any other name is
/// a controllable variable of the component.
pub fn parse_command(args: &[String]) -> Result<Command, CtlError> {
    match args {
        [word, state] if word == "state" => {
            let state = match state.as_str() {
                "ready" => Controllable::Ready,
                "running" => Controllable::Running,
                "suspended" => Controllable::Suspended,
                "dead" => Controllable::Dead,
                other => {
                    return Err(CtlError::BadArgument(format!(
                        "`{other}` is not a controllable state (ready, running, suspended, dead)"
                    )));
                }
            };
            Ok(Command::SetState(state))
        }
        [assignment] => {
            let (name, value) = assignment.split_once('=').ok_or_else(|| {
                CtlError::BadArgument(format!(
                    "`{assignment}`: write `state <state>` or `<variable>=<value>`"
                ))
            })?;
            let integer =
                |what: &str| CtlError::BadArgument(format!("{name} takes {what}, not `{value}`"));
            match name {
                "period" => Ok(Command::SetPeriod(parse_duration(value)?)),
                "max_response" => Ok(Command::SetMaxResponse(parse_duration(value)?)),
                "priority" => Ok(Command::SetPriority(
                    value.parse().map_err(|_| integer("an integer"))?,
                )),
                "quality" => {
                    Ok(Command::SetQuality(value.parse().map_err(|_| {
                        integer("a quality level index (0 = best)")
                    })?))
                }
                "" => Err(CtlError::BadArgument(format!(
                    "`{assignment}`: the variable has no name"
                ))),
                _ => Ok(Command::Set(name.to_owned(), parse_value(value))),
            }
        }
        _ => Err(CtlError::BadArgument(
            "write `state <state>` or `<variable>=<value>`".to_owned(),
        )),
    }
}

/// The command `coolctl configure` sends for `fields` (`FIELD=VALUE` each, values
/// typed as [`parse_value`] reads them): `Configure` with a JSON object of those
/// fields.
pub fn parse_configuration(fields: &[String]) -> Result<Command, CtlError> {
    if fields.is_empty() {
        return Err(CtlError::BadArgument(
            "give at least one FIELD=VALUE".to_owned(),
        ));
    }
    let mut object = serde_json::Map::new();
    for field in fields {
        let (name, value) = field
            .split_once('=')
            .filter(|(name, _)| !name.is_empty())
            .ok_or_else(|| CtlError::BadArgument(format!("`{field}` is not FIELD=VALUE")))?;
        if object
            .insert(name.to_owned(), parse_value(value).to_json())
            .is_some()
        {
            return Err(CtlError::BadArgument(format!("field `{name}` given twice")));
        }
    }
    Ok(Command::Configure(Value::Json(serde_json::Value::Object(
        object,
    ))))
}

/// Rows as columns two spaces apart, each as wide as its widest cell.
fn write_table<const N: usize>(rows: &[[String; N]], out: &mut dyn Write) -> Result<(), CtlError> {
    let mut widths = [0usize; N];
    for row in rows {
        for (width, cell) in widths.iter_mut().zip(row) {
            *width = (*width).max(cell.chars().count());
        }
    }
    for row in rows {
        let mut line = String::new();
        for (column, (cell, width)) in row.iter().zip(widths).enumerate() {
            if column + 1 == row.len() {
                line.push_str(cell);
            } else {
                line.push_str(&format!("{cell:<width$}  "));
            }
        }
        writeln!(out, "{}", line.trim_end())?;
    }
    Ok(())
}

/// One line describing a monitoring event.
pub fn describe(event: &MonitorEvent) -> String {
    match event {
        MonitorEvent::State { from, to } => format!("state {from} -> {to}"),
        MonitorEvent::UserState(Some(state)) => format!("user state {state}"),
        MonitorEvent::UserState(None) => "user state -".to_owned(),
        MonitorEvent::Result(result) => format!("result {result:?}"),
        MonitorEvent::Error(Some(error)) => format!("error {error}"),
        MonitorEvent::Error(None) => "error cleared".to_owned(),
        MonitorEvent::Variable { name, value } => format!("{name} = {value}"),
        MonitorEvent::Overflow { port, lost, total } => {
            format!("overflow at {port}: {lost} lost ({total} in all)")
        }
        MonitorEvent::MissedDeadline { missed, total } => {
            format!("missed {missed} deadline(s) ({total} in all)")
        }
        MonitorEvent::Overrun { took, total } => format!("overrun: ran {took:?} ({total} in all)"),
        MonitorEvent::LateResponse { took, bound, total } => {
            format!("late response: {took:?}, max_response {bound:?} ({total} in all)")
        }
        MonitorEvent::Period(Some(period)) => format!("period {period:?}"),
        MonitorEvent::Period(None) => "period -".to_owned(),
        MonitorEvent::MaxResponse(Some(bound)) => format!("max_response {bound:?}"),
        MonitorEvent::MaxResponse(None) => "max_response -".to_owned(),
        MonitorEvent::Priority(priority) => format!("priority {priority}"),
        MonitorEvent::Quality(level) => format!("quality {level}"),
        MonitorEvent::Configured => "configured".to_owned(),
        MonitorEvent::Supervision(step) => format!("supervision: {step}"),
        MonitorEvent::OsPriority(priority) => format!("os priority {priority:?}"),
        MonitorEvent::Pressure(pressure) => format!("pressure {pressure:?}"),
        MonitorEvent::Adaptation(step) => format!("adaptation: {step}"),
    }
}

/// `none`, or the names joined with `, `.
fn listing(names: &[String]) -> String {
    if names.is_empty() {
        "none".to_owned()
    } else {
        names.join(", ")
    }
}

/// What `coolctl echo` saw.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct EchoSummary {
    /// Packets received.
    pub received: u64,
    /// Packets printed.
    pub printed: u64,
    /// Packets received but not printed because of `--hz`.
    pub skipped: u64,
    /// Packets the port sent after the first one received that never arrived
    /// (dropped by the node's echo queue or by the network), and those the node
    /// could not echo.
    pub lost: u64,
    /// Of those lost, the packets the node could not echo (too large for a batch
    /// alone, or not serializable): the batch said so in their place.
    pub unechoed: u64,
    /// What the node said it dropped in all (its echo queue was full), at the last
    /// packet received.
    pub node_dropped: u64,
}

impl std::fmt::Display for EchoSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} received, {} printed, {} skipped (--hz), {} lost (",
            self.received, self.printed, self.skipped, self.lost
        )?;
        if self.unechoed > 0 {
            write!(
                f,
                "{} not echoed by the node, too large or not serializable; ",
                self.unechoed
            )?;
        }
        write!(
            f,
            "the node's echo queue dropped {} in all)",
            self.node_dropped
        )
    }
}

impl EchoSummary {
    /// Count `echoed`, the next element of a batch for the output read (`output`),
    /// against `next_seq`, the number expected next: what is missing before it is
    /// lost, and so is a packet the node could not echo (its place says why: warned
    /// about, rate-limited). Whether it is a packet received.
    fn take(&mut self, output: &str, echoed: &EchoedRaw<'_>, next_seq: &mut Option<u64>) -> bool {
        self.node_dropped = echoed.dropped;
        if let Some(expected) = *next_seq {
            self.lost += echoed.seq.saturating_sub(expected);
        }
        *next_seq = Some(echoed.seq.saturating_add(1));
        if let Some(why) = &echoed.unsent {
            self.lost += 1;
            self.unechoed += 1;
            coolbot::limited!(output, |held| tracing::warn!(
                "packet {} of {output} was not echoed by its node (lost): {}{held}",
                echoed.seq,
                coolbot::ranges::excerpt(why, coolbot::ranges::REASON_CHARS)
            ));
            return false;
        }
        self.received += 1;
        true
    }
}

/// One component in `coolctl list`.
#[derive(Debug, Clone)]
pub struct Listed {
    /// The node.
    pub node: String,
    /// The component's path on the node.
    pub path: String,
    /// Its snapshot.
    pub monitor: Monitor,
}

/// `coolctl` on a session.
#[derive(Debug, Clone)]
pub struct Ctl {
    session: zenoh::Session,
    timeout: Duration,
    /// The security file's rules and this session's name in them.
    rules: Option<(crate::Security, String)>,
}

impl Ctl {
    /// On `session`, waiting at most `timeout` for answers.
    pub fn new(session: zenoh::Session, timeout: Duration) -> Ctl {
        Ctl {
            session,
            timeout,
            rules: None,
        }
    }

    /// Explain, with the access rules of `security` (the file the session was opened
    /// with), a command nothing answered: when they do not let this session's
    /// certificate command the target, the error says so ([`CtlError::Refused`])
    /// rather than only that nothing answered. The target node enforces its own file;
    /// this reads the same rules, as nodes that share one file do.
    pub fn with_security(mut self, security: &crate::Security) -> Result<Ctl, CtlError> {
        let who = security.identity()?;
        self.rules = who
            .filter(|_| security.has_rules())
            .map(|who| (security.clone(), who));
        Ok(self)
    }

    /// The names of the nodes alive, sorted.
    pub fn node_names(&self) -> Result<Vec<String>, CtlError> {
        let tokens = crate::node::liveliness_keys(
            &self.session,
            &format!("{}/*", keys::ROOT),
            self.timeout,
        )?;
        Ok(tokens
            .iter()
            .filter_map(|key| key.strip_prefix(keys::ROOT)?.strip_prefix('/'))
            .map(str::to_owned)
            .collect())
    }

    /// `coolctl nodes`: one node name per line; [`CtlError::NoNode`] when none is
    /// alive.
    pub fn nodes(&self, out: &mut dyn Write) -> Result<(), CtlError> {
        let names = self.node_names()?;
        if names.is_empty() {
            return Err(self.no_node());
        }
        for name in names {
            writeln!(out, "{name}")?;
        }
        Ok(())
    }

    /// No node answered: how long it waited, and whether this session reached any
    /// Zenoh peer at all (an endpoint that cannot be reached, or nothing listening).
    pub(crate) fn no_node(&self) -> CtlError {
        let info = self.session.info();
        let connected =
            info.peers_zid().wait().next().is_some() || info.routers_zid().wait().next().is_some();
        CtlError::NoNode {
            waited: self.timeout,
            connected,
        }
    }

    /// Why nothing was listed for `node` (or for every node): no node alive, that node
    /// not alive, or no component answered.
    fn nothing_listed(&self, node: Option<&str>) -> CtlError {
        let alive = match self.node_names() {
            Ok(alive) => alive,
            Err(error) => return error,
        };
        if alive.is_empty() {
            return self.no_node();
        }
        if let Some(node) = node
            && !alive.iter().any(|name| name == node)
        {
            return CtlError::UnknownNode {
                node: node.to_owned(),
                alive: listing(&alive),
            };
        }
        CtlError::NoComponents {
            node: node.map(str::to_owned),
            alive: listing(&alive),
            waited: self.timeout,
        }
    }

    /// Subscribe to nodes coming and going (their liveliness tokens).
    pub fn node_watcher(&self) -> Result<NodeWatcher, CtlError> {
        let subscriber = self
            .session
            .liveliness()
            .declare_subscriber(format!("{}/*", keys::ROOT))
            .wait()
            .map_err(CtlError::zenoh("watch the nodes' liveliness"))?;
        Ok(NodeWatcher { subscriber })
    }

    /// `coolctl nodes --watch`: the nodes alive now, then `+ <node>` when one comes
    /// and `- <node>` when one goes, until `count` changes were printed or `duration`
    /// passed (each when given).
    pub fn watch_nodes(
        &self,
        count: Option<usize>,
        duration: Option<Duration>,
        out: &mut dyn Write,
    ) -> Result<(), CtlError> {
        let watcher = self.node_watcher()?;
        self.nodes(out)?;
        out.flush()?;
        let deadline = duration.map(|d| Instant::now() + d);
        let mut printed = 0;
        while count.is_none_or(|count| printed < count) {
            let wait = match deadline {
                Some(deadline) => match deadline.checked_duration_since(Instant::now()) {
                    Some(left) => left,
                    None => break,
                },
                None => Duration::from_secs(3600),
            };
            if let Some(line) = watcher.next(wait)? {
                writeln!(out, "{line}")?;
                out.flush()?;
                printed += 1;
            }
        }
        Ok(())
    }

    /// The components of `node` (or of every node), with their snapshots, sorted by
    /// node and path.
    pub fn components(&self, node: Option<&str>) -> Result<Vec<Listed>, CtlError> {
        if let Some(node) = node {
            keys::check_name(node)?;
        }
        let pattern = keys::monitor(node.unwrap_or("*"), "*");
        let replies = self
            .session
            .get(pattern)
            .target(QueryTarget::All)
            .consolidation(ConsolidationMode::None)
            .timeout(self.timeout)
            .wait()
            .map_err(CtlError::zenoh("ask for the components' snapshots"))?;
        let mut listed = Vec::new();
        while let Ok(reply) = replies.recv() {
            let Ok(sample) = reply.result() else {
                continue;
            };
            let key = sample.key_expr().as_str();
            let Some((node, path)) = keys::parse_component(key) else {
                continue;
            };
            // One node's bad answer hides no other component: it is left out, and
            // said so.
            let monitor: Monitor = match decode(sample, limits::SNAPSHOT, "a snapshot") {
                Ok(monitor) => monitor,
                Err(error) => {
                    tracing::warn!("{key}: left out of the listing: {error}");
                    continue;
                }
            };
            listed.push(Listed {
                node: node.to_owned(),
                path: path.to_owned(),
                monitor,
            });
        }
        listed.sort_by(|a, b| (&a.node, &a.path).cmp(&(&b.node, &b.path)));
        listed.dedup_by(|a, b| a.node == b.node && a.path == b.path);
        Ok(listed)
    }

    /// `coolctl list [node]`: a table of every component with its state, user state,
    /// quality, missed deadlines, overruns and overflows. Nothing listed is an error
    /// that says why: no node alive, `node` not alive ([`CtlError::UnknownNode`]), or
    /// no component answered ([`CtlError::NoComponents`]).
    pub fn list(&self, node: Option<&str>, out: &mut dyn Write) -> Result<(), CtlError> {
        let listed = self.components(node)?;
        if listed.is_empty() {
            return Err(self.nothing_listed(node));
        }
        let mut rows = vec![[
            "NODE".to_owned(),
            "COMPONENT".to_owned(),
            "STATE".to_owned(),
            "USER STATE".to_owned(),
            "QUALITY".to_owned(),
            "MISSED".to_owned(),
            "OVERRUNS".to_owned(),
            "OVERFLOWS".to_owned(),
        ]];
        for listed in listed {
            let monitor = &listed.monitor;
            rows.push([
                listed.node,
                listed.path,
                monitor.state.to_string(),
                monitor.user_state.clone().unwrap_or_else(|| "-".to_owned()),
                monitor.quality.to_string(),
                monitor.missed_deadlines.to_string(),
                monitor.overruns.to_string(),
                monitor.overflows.to_string(),
            ]);
        }
        write_table(&rows, out)
    }

    /// Subscribe to the monitoring events of `<node>/<path>`.
    pub fn watcher(&self, address: &str) -> Result<Watcher, CtlError> {
        let (node, path) = target(address)?;
        let subscriber = self
            .session
            .declare_subscriber(keys::monitor(node, path))
            .wait()
            .map_err(CtlError::zenoh("subscribe to the monitoring events"))?;
        Ok(Watcher {
            address: address.to_owned(),
            subscriber,
        })
    }

    /// `coolctl watch`: print `<node>/<path> <event>` for each event, until `count`
    /// events were printed or `duration` passed (each when given).
    pub fn watch(
        &self,
        address: &str,
        count: Option<usize>,
        duration: Option<Duration>,
        out: &mut dyn Write,
    ) -> Result<(), CtlError> {
        let watcher = self.watcher(address)?;
        // A wrong node or path fails now, not after waiting forever in silence.
        self.snapshot(address)?;
        let deadline = duration.map(|d| Instant::now() + d);
        let mut printed = 0;
        while count.is_none_or(|count| printed < count) {
            let wait = match deadline {
                Some(deadline) => match deadline.checked_duration_since(Instant::now()) {
                    Some(left) => left,
                    None => break,
                },
                None => Duration::from_secs(3600),
            };
            if let Some(line) = watcher.next(wait)? {
                writeln!(out, "{line}")?;
                out.flush()?;
                printed += 1;
            }
        }
        Ok(())
    }

    /// Send `command` to `<node>/<path>` and return the component's answer.
    pub fn command(&self, address: &str, command: &Command) -> Result<ControlReply, CtlError> {
        let (node, path) = target(address)?;
        let key = keys::control(node, path);
        let json = serde_json::to_vec(command).map_err(CtlError::Encode)?;
        let replies = self
            .session
            .get(key.clone())
            .payload(json)
            .timeout(self.timeout)
            .wait()
            .map_err(CtlError::zenoh("send the command"))?;
        match replies.recv() {
            Ok(reply) => match reply.result() {
                Ok(sample) => decode(sample, limits::REPLY, "the control port's answer"),
                Err(error) => Err(CtlError::ErrorReply {
                    key,
                    reason: error
                        .payload()
                        .try_to_string()
                        .unwrap_or_default()
                        .into_owned(),
                }),
            },
            Err(_) => Err(match self.missing(node, path, address) {
                CtlError::NoAnswer { target, waited } => match &self.rules {
                    Some((rules, who)) if rules.grants_command(who, node, path) == Some(false) => {
                        CtlError::Refused {
                            target,
                            waited,
                            who: who.clone(),
                        }
                    }
                    _ => CtlError::NoAnswer { target, waited },
                },
                other => other,
            }),
        }
    }

    /// Why nothing answered at `<node>/<path>`: the node is not alive, it has no such
    /// component, or (both there) it did not answer in time.
    fn missing(&self, node: &str, path: &str, address: &str) -> CtlError {
        let no_answer = || CtlError::NoAnswer {
            target: address.to_owned(),
            waited: self.timeout,
        };
        let Ok(alive) = self.node_names() else {
            return no_answer();
        };
        if !alive.iter().any(|name| name == node) {
            return CtlError::UnknownNode {
                node: node.to_owned(),
                alive: listing(&alive),
            };
        }
        match self.components(Some(node)) {
            Ok(listed) if !listed.iter().any(|listed| listed.path == path) => {
                let known: Vec<String> = listed.into_iter().map(|listed| listed.path).collect();
                CtlError::UnknownComponent {
                    node: node.to_owned(),
                    path: path.to_owned(),
                    known: listing(&known),
                }
            }
            _ => no_answer(),
        }
    }

    /// The one JSON answer to a query on `key` (for `<node>/<path>`), decoded.
    fn query<T: serde::de::DeserializeOwned>(
        &self,
        key: String,
        (node, path, address): (&str, &str, &str),
        (limit, what): (Limit, &str),
    ) -> Result<T, CtlError> {
        let replies = self
            .session
            .get(key.clone())
            .timeout(self.timeout)
            .wait()
            .map_err(CtlError::zenoh("query the component"))?;
        while let Ok(reply) = replies.recv() {
            let Ok(sample) = reply.result() else {
                continue;
            };
            return decode(sample, limit, what);
        }
        Err(self.missing(node, path, address))
    }

    /// The snapshot of `<node>/<path>`'s monitoring port; a clear error, within the
    /// timeout, when the node or the component does not exist.
    pub fn snapshot(&self, address: &str) -> Result<Monitor, CtlError> {
        let (node, path) = target(address)?;
        self.query(
            keys::monitor(node, path),
            (node, path, address),
            (limits::SNAPSHOT, "a snapshot"),
        )
    }

    /// The static shape of `<node>/<path>` (types of its variables, its ports, the
    /// outputs its node echoes).
    pub fn info(&self, address: &str) -> Result<ComponentInfo, CtlError> {
        let (node, path) = target(address)?;
        self.query(
            keys::info(node, path),
            (node, path, address),
            (limits::INFO, "a component's shape"),
        )
    }

    /// `coolctl get <node>/<path>`: the component's type and states, its default
    /// variables, then every user variable with its kind, type and value.
    pub fn get(&self, address: &str, out: &mut dyn Write) -> Result<(), CtlError> {
        let info = self.info(address)?;
        let monitor = self.snapshot(address)?;
        let user = monitor
            .user_state
            .as_deref()
            .map(|user| format!(" ({user})"))
            .unwrap_or_default();
        writeln!(out, "{address}: {} {}{user}", info.type_name, monitor.state)?;
        let quality = match info.qualities.get(monitor.quality) {
            Some(name) => format!("{} ({name})", monitor.quality),
            None => monitor.quality.to_string(),
        };
        let duration = |d: Option<Duration>| d.map_or_else(|| "-".to_owned(), |d| format!("{d:?}"));
        writeln!(
            out,
            "period {}, quality {quality}, level {}/{}, max_response {}, priority {}",
            duration(monitor.period),
            monitor.adaptation.level,
            monitor.adaptation.max_level,
            duration(monitor.max_response),
            monitor.priority,
        )?;
        if let Some(error) = &monitor.error {
            writeln!(out, "error {error}")?;
        }
        let mut rows = vec![[
            "VARIABLE".to_owned(),
            "KIND".to_owned(),
            "TYPE".to_owned(),
            "VALUE".to_owned(),
        ]];
        for (name, value) in &monitor.variables {
            let declared = info.variables.iter().find(|v| &v.name == name);
            rows.push([
                name.clone(),
                declared.map_or_else(|| "-".to_owned(), |v| v.kind.clone()),
                declared.map_or_else(|| "-".to_owned(), |v| v.ty.clone()),
                serde_json::to_string(&value.to_json()).unwrap_or_else(|_| value.to_string()),
            ]);
        }
        write_table(&rows, out)
    }

    /// Send `command` and print `accepted` or `rejected: <reason>`; whether it was
    /// accepted.
    fn answer(
        &self,
        address: &str,
        command: &Command,
        out: &mut dyn Write,
    ) -> Result<bool, CtlError> {
        match self.command(address, command)? {
            ControlReply::Accepted => {
                writeln!(out, "accepted")?;
                Ok(true)
            }
            ControlReply::Rejected { reason } => {
                writeln!(out, "rejected: {reason}")?;
                Ok(false)
            }
        }
    }

    /// `coolctl configure <node>/<path> FIELD=VALUE...`: one `Configure` command with
    /// the fields given (the others keep their values), each value typed as
    /// [`parse_value`] reads it; prints the component's answer.
    pub fn configure(
        &self,
        address: &str,
        fields: &[String],
        out: &mut dyn Write,
    ) -> Result<bool, CtlError> {
        let command = parse_configuration(fields)?;
        self.answer(address, &command, out)
    }

    /// `coolctl degrade <node>/<path> LEVEL`: set the adaptation level (an atomic
    /// component's place on its ladder; a compound's cap); prints the answer.
    pub fn degrade(
        &self,
        address: &str,
        level: u32,
        out: &mut dyn Write,
    ) -> Result<bool, CtlError> {
        self.answer(address, &Command::SetDegradation(level), out)
    }

    /// `coolctl echo <node>/<path>.<port>`: every packet the port sends, one JSON line
    /// each; with `hz`, at most that many lines a second (the others are counted as
    /// skipped, the producer is never slowed); until `count` lines were printed or
    /// `duration` passed (each when given).
    pub fn echo(
        &self,
        address: &str,
        hz: Option<f64>,
        count: Option<u64>,
        duration: Option<Duration>,
        out: &mut dyn Write,
    ) -> Result<EchoSummary, CtlError> {
        let (node, full) = target(address)?;
        let (path, port) = full.rsplit_once('.').ok_or_else(|| {
            CtlError::BadArgument(format!(
                "`{address}` names no port: write <node>/<path>.<port>, e.g. robot/robot.base.scan"
            ))
        })?;
        let interval = match hz {
            Some(hz) if hz.is_finite() && hz > 0.0 => Some(Duration::from_secs_f64(1.0 / hz)),
            Some(hz) => {
                return Err(CtlError::BadArgument(format!(
                    "--hz {hz}: the rate is a positive number of lines a second"
                )));
            }
            None => None,
        };
        // The node's batches first, so that none holding this output's first packets
        // is missed; then the output's key, which has the node tap it.
        let batches = self
            .session
            .declare_subscriber(keys::echoes(node))
            .wait()
            .map_err(CtlError::zenoh("subscribe to the echoed outputs"))?;
        let _asking = self
            .session
            .declare_subscriber(keys::echo(node, path, port))
            .callback(|_| {})
            .wait()
            .map_err(CtlError::zenoh("subscribe to the echoed output"))?;
        let component = format!("{node}/{path}");
        let info = self.info(&component)?;
        if !info.outputs.iter().any(|output| output.name == port) {
            let outputs: Vec<String> = info.outputs.iter().map(|o| o.name.clone()).collect();
            return Err(CtlError::UnknownPort(format!(
                "`{component}` has no output `{port}` (its outputs: {})",
                listing(&outputs)
            )));
        }
        if !info.echoed.iter().any(|echoed| echoed == port) {
            return Err(CtlError::UnknownPort(format!(
                "node `{node}` does not echo `{full}` (it echoes {} of `{path}`; a program \
                 chooses the outputs it echoes with Node::echo)",
                listing(&info.echoed)
            )));
        }
        let deadline = duration.map(|d| Instant::now() + d);
        let mut summary = EchoSummary::default();
        let mut next_seq = None;
        let mut next_print = Instant::now();
        'batches: while count.is_none_or(|count| summary.printed < count) {
            let wait = match deadline {
                Some(deadline) => match deadline.checked_duration_since(Instant::now()) {
                    Some(left) => left,
                    None => break,
                },
                None => Duration::from_secs(3600),
            };
            let Some(sample) = batches
                .recv_timeout(wait)
                .map_err(CtlError::zenoh("receive echoed packets"))?
            else {
                continue;
            };
            // (Decoded borrowing from the bytes: the length is checked first.)
            limits::ECHO_BATCH
                .check(
                    || "a batch of echoed packets".to_owned(),
                    sample.payload().len(),
                )
                .map_err(|source| CtlError::TooLarge {
                    key: sample.key_expr().as_str().to_owned(),
                    source,
                })?;
            let payload = sample.payload().to_bytes();
            let batch: Vec<EchoedRaw<'_>> =
                serde_json::from_slice(&payload).map_err(|source| CtlError::Decode {
                    key: sample.key_expr().as_str().to_owned(),
                    source,
                })?;
            for echoed in batch.iter().filter(|echoed| echoed.output == full) {
                if count.is_some_and(|count| summary.printed >= count) {
                    break 'batches;
                }
                if !summary.take(full, echoed, &mut next_seq) {
                    continue;
                }
                let now = Instant::now();
                if now < next_print {
                    summary.skipped += 1;
                    continue;
                }
                if let Some(interval) = interval {
                    next_print = now + interval;
                }
                writeln!(out, "{}", echoed.packet.get())?;
                out.flush()?;
                summary.printed += 1;
            }
        }
        Ok(summary)
    }

    /// `coolctl set <node>/<path> ...`: print `accepted` or `rejected: <reason>`;
    /// returns whether it was accepted.
    pub fn set(
        &self,
        address: &str,
        args: &[String],
        out: &mut dyn Write,
    ) -> Result<bool, CtlError> {
        let command = parse_command(args)?;
        self.answer(address, &command, out)
    }
}

/// Nodes coming and going, as lines (`coolctl nodes --watch`).
pub struct NodeWatcher {
    subscriber:
        zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
}

impl std::fmt::Debug for NodeWatcher {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("NodeWatcher")
    }
}

impl NodeWatcher {
    /// The next change, `+ <node>` (it came) or `- <node>` (it went), waiting at
    /// most `timeout`.
    pub fn next(&self, timeout: Duration) -> Result<Option<String>, CtlError> {
        loop {
            let Some(sample) = self
                .subscriber
                .recv_timeout(timeout)
                .map_err(CtlError::zenoh("receive a node's liveliness change"))?
            else {
                return Ok(None);
            };
            let Some(node) = sample
                .key_expr()
                .as_str()
                .strip_prefix(keys::ROOT)
                .and_then(|rest| rest.strip_prefix('/'))
            else {
                continue;
            };
            let sign = match sample.kind() {
                zenoh::sample::SampleKind::Put => '+',
                zenoh::sample::SampleKind::Delete => '-',
            };
            return Ok(Some(format!("{sign} {node}")));
        }
    }
}

/// The monitoring events of one component, as lines (`coolctl watch`).
pub struct Watcher {
    address: String,
    subscriber:
        zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
}

impl std::fmt::Debug for Watcher {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Watcher({})", self.address)
    }
}

impl Watcher {
    /// The next event as `<node>/<path> <event>`, waiting at most `timeout`.
    pub fn next(&self, timeout: Duration) -> Result<Option<String>, CtlError> {
        let Some(sample) = self
            .subscriber
            .recv_timeout(timeout)
            .map_err(CtlError::zenoh("receive a monitoring event"))?
        else {
            return Ok(None);
        };
        let event: MonitorEvent = decode(&sample, limits::EVENT, "a monitoring event")?;
        Ok(Some(format!("{} {}", self.address, describe(&event))))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What `coolctl echo` counts of an output's elements in the node's batches:
    /// numbers missing are lost, and so is a packet the node could not echo (its
    /// place says why), the last one too; it is not a packet received.
    #[test]
    fn an_echo_counts_a_packet_the_node_could_not_echo_lost() {
        let batch = br#"[
            {"output":"a.out","seq":0,"dropped":0,"sent":1,"packet":1},
            {"output":"a.out","seq":2,"dropped":1,"sent":2,"packet":3},
            {"output":"a.out","seq":3,"dropped":1,"sent":3,"packet":null,"unsent":"too large"}
        ]"#;
        let batch: Vec<EchoedRaw<'_>> = serde_json::from_slice(batch).unwrap();
        let mut summary = EchoSummary::default();
        let mut next_seq = None;
        let received: Vec<bool> = batch
            .iter()
            .map(|echoed| summary.take("a.out", echoed, &mut next_seq))
            .collect();
        assert_eq!(received, [true, true, false]);
        assert_eq!(
            summary,
            EchoSummary {
                received: 2,
                lost: 2,
                unechoed: 1,
                node_dropped: 1,
                ..EchoSummary::default()
            }
        );
        assert_eq!(
            summary.to_string(),
            "2 received, 0 printed, 0 skipped (--hz), 2 lost (1 not echoed by the node, too \
             large or not serializable; the node's echo queue dropped 1 in all)"
        );
    }

    /// One component's snapshot over `SNAPSHOT` (any node may answer so for its own
    /// components) is left out of the listing: the other nodes' components are listed.
    #[test]
    fn one_bad_snapshot_hides_no_other_component_from_the_listing() {
        use zenoh::Wait;
        let port = crate::testing::free_port();
        let good = crate::testing::node("good", Some(port), None);
        let mut system = coolbot::System::new();
        system
            .add(crate::testing::idle("idle", crate::testing::idle_spec()))
            .unwrap();
        system.start().unwrap();
        good.expose_system(&system).unwrap();
        let evil = zenoh::open(
            crate::peer_config(&[], &[format!("tcp/127.0.0.1:{port}")], false).unwrap(),
        )
        .wait()
        .unwrap();
        let _queryable = evil
            .declare_queryable(keys::monitor("evil", "x"))
            .callback(|query| {
                let huge = vec![b' '; limits::SNAPSHOT.max + 1];
                let _ = query.reply(keys::monitor("evil", "x"), huge).wait();
            })
            .wait()
            .unwrap();
        // Until the bad answer reaches the good node (asked again, up to a minute).
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            let heard = good
                .session()
                .get(keys::monitor("evil", "x"))
                .timeout(Duration::from_secs(2))
                .wait()
                .ok()
                .is_some_and(|replies| replies.recv().is_ok());
            if heard {
                break;
            }
            assert!(Instant::now() < deadline, "the bad node never answered");
        }
        let ctl = Ctl::new(good.session().clone(), Duration::from_secs(2));
        let listed = ctl.components(None).expect("a listing");
        assert!(listed.iter().any(|l| l.path == "idle"), "{listed:?}");
        assert!(!listed.iter().any(|l| l.node == "evil"), "{listed:?}");
    }

    #[test]
    fn answers_over_their_limit_are_refused_undecoded() {
        let limit = Limit {
            max: 16,
            ..limits::REPLY
        };
        let accepted =
            zenoh::bytes::ZBytes::from(serde_json::to_vec(&ControlReply::Accepted).unwrap());
        let reply: ControlReply =
            decode_payload("coolbot/n/c/c", &accepted, limit, "an answer").unwrap();
        assert_eq!(reply, ControlReply::Accepted);
        let long = zenoh::bytes::ZBytes::from(
            serde_json::to_vec(&ControlReply::Rejected {
                reason: "r".repeat(100),
            })
            .unwrap(),
        );
        let error =
            decode_payload::<ControlReply>("coolbot/n/c/c", &long, limit, "an answer").unwrap_err();
        assert!(matches!(error, CtlError::TooLarge { .. }), "{error:?}");
        let said = coolbot::Chain(&error).to_string();
        assert!(
            said.contains("an answer: 126 bytes, over the limit REPLY = 16 bytes"),
            "{said}"
        );
        let bad = zenoh::bytes::ZBytes::from(b"{".to_vec());
        assert!(matches!(
            decode_payload::<ControlReply>("coolbot/n/c/c", &bad, limit, "an answer"),
            Err(CtlError::Decode { .. })
        ));
    }

    fn args(words: &[&str]) -> Vec<String> {
        words.iter().map(|w| (*w).to_owned()).collect()
    }

    #[test]
    fn commands_parse() {
        let cases: &[(&[&str], Command)] = &[
            (
                &["state", "suspended"],
                Command::SetState(Controllable::Suspended),
            ),
            (&["state", "dead"], Command::SetState(Controllable::Dead)),
            (
                &["period=20ms"],
                Command::SetPeriod(Duration::from_millis(20)),
            ),
            (
                &["max_response=1s"],
                Command::SetMaxResponse(Duration::from_secs(1)),
            ),
            (&["priority=-3"], Command::SetPriority(-3)),
            (&["quality=2"], Command::SetQuality(2)),
            (
                &["max_speed=0.5"],
                Command::Set("max_speed".into(), Value::Float(0.5)),
            ),
            (&["limit=7"], Command::Set("limit".into(), Value::UInt(7))),
            (
                &["offset=-7"],
                Command::Set("offset".into(), Value::Int(-7)),
            ),
            (&["on=true"], Command::Set("on".into(), Value::Bool(true))),
            (
                &["mode=Degraded"],
                Command::Set("mode".into(), Value::Str("Degraded".into())),
            ),
            (
                &["name=\"a b\""],
                Command::Set("name".into(), Value::Str("a b".into())),
            ),
        ];
        for (words, expected) in cases {
            assert_eq!(&parse_command(&args(words)).unwrap(), expected, "{words:?}");
        }
    }

    #[test]
    fn bad_commands_say_why() {
        for (words, message) in [
            (&["state", "starting"][..], "not a controllable state"),
            (&["period=fast"], "not a duration"),
            (&["priority=high"], "takes an integer"),
            (&["quality=-1"], "quality level index"),
            (&["=3"], "has no name"),
            (&["speed"], "write `state <state>`"),
            (&[], "write `state <state>`"),
        ] {
            let error = parse_command(&args(words)).unwrap_err().to_string();
            assert!(error.contains(message), "{words:?}: {error}");
        }
    }

    #[test]
    fn targets_are_node_and_path() {
        assert_eq!(
            target("robot/base.motion").unwrap(),
            ("robot", "base.motion")
        );
        for bad in ["robot", "robot/", "/x", "robot/a/b", "robot/*"] {
            assert!(target(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn durations_parse() {
        assert_eq!(parse_duration("250us").unwrap(), Duration::from_micros(250));
        assert_eq!(parse_duration("1.5s").unwrap(), Duration::from_millis(1500));
        assert_eq!(parse_duration("1min").unwrap(), Duration::from_secs(60));
        for bad in ["", "ms", "10", "10h", "-1s"] {
            assert!(parse_duration(bad).is_err(), "{bad}");
        }
    }
}
