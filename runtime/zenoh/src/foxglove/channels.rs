//! The channels `coolctl foxglove` serves: their topics, schemas and messages.

use std::sync::Arc;
use std::time::{Duration, SystemTime};

use coolbot::{Monitor, MonitorEvent, State, Step};
use foxglove::{Context, FoxgloveError, RawChannel, Schema};
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

/// The topic of the supervision and adaptation steps (`foxglove.Log`).
pub const LOG_TOPIC: &str = "/coolbot/log";

/// The schema name of a monitoring channel's messages.
pub const MONITORING_SCHEMA: &str = "coolbot.Monitoring";

fn channel(
    context: &Arc<Context>,
    topic: &str,
    schema_name: &str,
    schema: &Value,
) -> Result<Arc<RawChannel>, FoxgloveError> {
    context
        .channel_builder(topic)
        .message_encoding("json")
        .schema(Schema::new(
            schema_name,
            "jsonschema",
            schema.to_string().into_bytes(),
        ))
        .build_raw()
}

/// The channel of the echoed output `name` (`node/path.port`), whose packets are
/// `packet` (the type's name) of JSON Schema `schema`.
pub(super) fn port(
    context: &Arc<Context>,
    name: &str,
    packet: &str,
    schema: &Value,
) -> Result<Arc<RawChannel>, FoxgloveError> {
    channel(context, &format!("/{name}"), packet, schema)
}

/// The monitoring channel of the component at `address` (`node/path`).
pub(super) fn monitor(
    context: &Arc<Context>,
    address: &str,
) -> Result<Arc<RawChannel>, FoxgloveError> {
    channel(
        context,
        &format!("/{address}/monitor"),
        MONITORING_SCHEMA,
        &Monitoring::schema(),
    )
}

/// The channel of the supervision and adaptation steps.
pub(super) fn log(context: &Arc<Context>) -> Result<Arc<RawChannel>, FoxgloveError> {
    channel(context, LOG_TOPIC, "foxglove.Log", &log_schema())
}

/// A time as Foxglove's JSON messages write it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Stamp {
    /// Whole seconds since the Unix epoch.
    pub sec: u64,
    /// Nanoseconds within the second.
    pub nsec: u32,
}

impl Stamp {
    /// `time` since the Unix epoch (zero before it).
    pub fn of(time: SystemTime) -> Stamp {
        let since = time
            .duration_since(SystemTime::UNIX_EPOCH)
            .unwrap_or_default();
        Stamp {
            sec: since.as_secs(),
            nsec: since.subsec_nanos(),
        }
    }
}

fn stamp_schema() -> Value {
    json!({
        "type": "object",
        "properties": {
            "sec": { "type": "integer", "minimum": 0 },
            "nsec": { "type": "integer", "minimum": 0, "maximum": 999_999_999 },
        },
        "required": ["sec", "nsec"],
    })
}

/// One reading of a component's monitoring, as a plot reads it: numbers, and the
/// states as names and as codes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Monitoring {
    /// When it was read.
    pub timestamp: Stamp,
    /// The default automaton's state (`running`).
    pub state: String,
    /// The state's place in the paper's order (starting 0, ready 1, running 2,
    /// suspended 3, dead 4, starting_error 5, running_error 6, end 7).
    pub state_code: u8,
    /// The user automaton's state (empty when it has none).
    pub user_state: String,
    /// The period in effect, in seconds (null: aperiodic).
    pub period: Option<f64>,
    /// The period the component was built with, in seconds.
    pub nominal_period: Option<f64>,
    /// The quality level (0 = best).
    pub quality: u64,
    /// The adaptation level.
    pub level: u32,
    /// Its thread's CPU time over wall time since the previous reading (null at
    /// the first).
    pub cpu_share: Option<f64>,
    /// Periodic deadlines missed in all.
    pub missed_deadlines: u64,
    /// User calls longer than `max_response` in all.
    pub overruns: u64,
    /// Packets lost at its inputs in all.
    pub overflows: u64,
    /// Monitoring events dropped for slow observers in all.
    pub dropped_events: u64,
    /// Its variables (observable and controllable) by name, as JSON (a plot reads
    /// `variables.speed.linear`).
    pub variables: serde_json::Map<String, Value>,
}

fn seconds(duration: Option<Duration>) -> Option<f64> {
    duration.map(|d| d.as_secs_f64())
}

impl Monitoring {
    /// The reading of `monitor`, read at `at`, with the CPU share measured.
    pub fn of(monitor: &Monitor, cpu_share: Option<f64>, at: SystemTime) -> Monitoring {
        Monitoring {
            timestamp: Stamp::of(at),
            state: monitor.state.to_string(),
            state_code: State::ALL
                .iter()
                .position(|state| *state == monitor.state)
                .map_or(u8::MAX, |at| at as u8),
            user_state: monitor.user_state.clone().unwrap_or_default(),
            period: seconds(monitor.period),
            nominal_period: seconds(monitor.nominal_period),
            quality: monitor.quality as u64,
            level: monitor.adaptation.level,
            cpu_share,
            missed_deadlines: monitor.missed_deadlines,
            overruns: monitor.overruns,
            overflows: monitor.overflows,
            dropped_events: monitor.dropped_events,
            variables: monitor
                .variables
                .iter()
                .map(|(name, value)| (name.clone(), value.to_json()))
                .collect(),
        }
    }

    /// Its JSON Schema.
    pub fn schema() -> Value {
        let count = json!({ "type": "integer", "minimum": 0 });
        // In the part of JSON Schema the viewers read (`coolbot::schema::for_viewers`).
        let seconds = json!({ "type": "number", "nullable": true });
        json!({
            "$schema": coolbot::schema::DIALECT,
            "title": MONITORING_SCHEMA,
            "type": "object",
            "properties": {
                "timestamp": stamp_schema(),
                "state": { "type": "string" },
                "state_code": { "type": "integer", "minimum": 0, "maximum": 7 },
                "user_state": { "type": "string" },
                "period": seconds,
                "nominal_period": seconds,
                "quality": count,
                "level": count,
                "cpu_share": { "type": "number", "nullable": true, "minimum": 0 },
                "missed_deadlines": count,
                "overruns": count,
                "overflows": count,
                "dropped_events": count,
                "variables": { "type": "object", "properties": {} },
            },
            "required": [
                "timestamp", "state", "state_code", "user_state", "period", "nominal_period",
                "quality", "level", "cpu_share", "missed_deadlines", "overruns", "overflows",
                "dropped_events", "variables",
            ],
            "additionalProperties": false,
        })
    }
}

/// `foxglove.Log`'s levels.
const INFO: u8 = 2;
const WARNING: u8 = 3;

/// The JSON Schema of `foxglove.Log` (Foxglove's own, in JSON).
pub fn log_schema() -> Value {
    let levels: Vec<Value> = ["UNKNOWN", "DEBUG", "INFO", "WARNING", "ERROR", "FATAL"]
        .iter()
        .enumerate()
        .map(|(code, name)| json!({ "title": name, "const": code }))
        .collect();
    json!({
        "$schema": coolbot::schema::DIALECT,
        "title": "foxglove.Log",
        "type": "object",
        "properties": {
            "timestamp": stamp_schema(),
            "level": { "title": "foxglove.LogLevel", "oneOf": levels },
            "message": { "type": "string" },
            "name": { "type": "string" },
            "file": { "type": "string" },
            "line": { "type": "integer", "minimum": 0 },
        },
        "required": ["timestamp", "level", "message", "name", "file", "line"],
    })
}

/// The `foxglove.Log` message of a supervision or adaptation step of the component
/// at `node`/`path`; None for other events.
pub(super) fn log_entry(node: &str, path: &str, event: &MonitorEvent) -> Option<Value> {
    let (level, message) = match event {
        MonitorEvent::Supervision(step) => {
            let level = match step.step {
                Step::Failed
                | Step::Propagated
                | Step::RetryFailed
                | Step::Retired
                | Step::CommandRefused { .. }
                | Step::OutOfStep => WARNING,
                _ => INFO,
            };
            (level, format!("supervision: {step}"))
        }
        MonitorEvent::Adaptation(step) => (INFO, format!("adaptation: {step}")),
        _ => return None,
    };
    Some(json!({
        "timestamp": Stamp::of(SystemTime::now()),
        "level": level,
        "message": message,
        "name": format!("{node}/{path}"),
        "file": "",
        "line": 0,
    }))
}
