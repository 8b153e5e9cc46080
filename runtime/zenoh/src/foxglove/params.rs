//! Parameters and services of `coolctl foxglove`: a component's controllable
//! variables as Foxglove parameters, and services that suspend, run and restart a
//! component. Every change is a command on the component's control key, as
//! `coolctl set` sends it: the component's own checks (types, `coolbot::ranges`) and
//! the node's access rules decide, and a refusal reaches the client as an error
//! status with the component's reason.

use std::time::Duration;

use coolbot::{Command, Controllable, Monitor, Value};
use foxglove::Schema;
use foxglove::websocket::service::{Request, Service, ServiceSchema};
use foxglove::websocket::{Parameter, ParameterType, ParameterValue};
use serde::{Deserialize, Serialize};
use serde_json::json;

use crate::ctl::{Ctl, CtlError};
use crate::info::ComponentInfo;
use crate::node::ControlReply;

/// The default controllable variables served as parameters beside a component's
/// own: `period` and `max_response` in seconds, `priority`, `quality`.
pub const DEFAULT_PARAMETERS: [&str; 4] = ["period", "max_response", "priority", "quality"];

/// A parameter's name: `<node>/<path>/<variable>`.
pub fn parameter_name(address: &str, variable: &str) -> String {
    format!("{address}/{variable}")
}

/// Split a parameter's name into the component's address and the variable.
pub fn split_name(name: &str) -> Option<(&str, &str)> {
    let (address, variable) = name.rsplit_once('/')?;
    address.contains('/').then_some((address, variable))
}

/// The controllable variables of a component: the defaults, then its own.
pub(super) fn controllables(info: &ComponentInfo) -> Vec<String> {
    DEFAULT_PARAMETERS
        .iter()
        .map(|name| (*name).to_owned())
        .chain(
            info.variables
                .iter()
                .filter(|v| v.kind == "controllable")
                .map(|v| v.name.clone()),
        )
        .collect()
}

/// The value of `variable` in `monitor` as a parameter.
pub(super) fn parameter(name: String, variable: &str, monitor: &Monitor) -> Parameter {
    let seconds = |d: Option<Duration>| match d {
        Some(d) => Parameter::float64(name.clone(), d.as_secs_f64()),
        None => Parameter::empty(name.clone()),
    };
    match variable {
        "period" => seconds(monitor.period),
        "max_response" => seconds(monitor.max_response),
        "priority" => Parameter::integer(name, i64::from(monitor.priority)),
        "quality" => Parameter::integer(name, monitor.quality as i64),
        _ => match monitor.variables.iter().find(|(v, _)| v == variable) {
            Some((_, value)) => of_value(name, value),
            None => Parameter::empty(name),
        },
    }
}

/// A variable's value as a parameter, typed: booleans, integers, floats (marked
/// `float64`), strings, and structured values as Foxglove's arrays and dictionaries.
fn of_value(name: String, value: &Value) -> Parameter {
    match value {
        Value::Bool(b) => Parameter::bool(name, *b),
        Value::Int(i) => Parameter::integer(name, *i),
        Value::UInt(u) => match i64::try_from(*u) {
            Ok(i) => Parameter::integer(name, i),
            Err(_) => Parameter::float64(name, *u as f64),
        },
        Value::Float(f) => Parameter::float64(name, *f),
        Value::Str(s) | Value::Enum(s) => Parameter::string(name, s.clone()),
        Value::Duration(d) => Parameter::float64(name, d.as_secs_f64()),
        other => match serde_json::from_value::<ParameterValue>(other.to_json()) {
            Ok(value) => Parameter {
                name,
                r#type: None,
                value: Some(value),
            },
            Err(_) => Parameter::empty(name),
        },
    }
}

/// A parameter's value as `coolctl set` reads a typed value: booleans, integers
/// (unsigned when not negative), floats, strings, the rest as JSON.
fn to_value(value: &ParameterValue, declared: Option<&ParameterType>) -> Value {
    match value {
        ParameterValue::Bool(b) => Value::Bool(*b),
        ParameterValue::Integer(i) if declared == Some(&ParameterType::Float64) => {
            Value::Float(*i as f64)
        }
        ParameterValue::Integer(i) => match u64::try_from(*i) {
            Ok(u) => Value::UInt(u),
            Err(_) => Value::Int(*i),
        },
        ParameterValue::Float64(f) => Value::Float(*f),
        ParameterValue::String(s) => Value::Str(s.clone()),
        other => Value::Json(serde_json::to_value(other).unwrap_or_default()),
    }
}

/// Why a parameter is not set.
#[derive(Debug, thiserror::Error)]
pub enum SetError {
    /// Not a parameter of this server.
    #[error("`{0}` is not a parameter (write <node>/<path>/<variable>)")]
    Unknown(String),
    /// A value the variable cannot take before anything is sent.
    #[error("`{name}`: {why}")]
    Value {
        /// The parameter.
        name: String,
        /// Why.
        why: String,
    },
    /// The component refused the command.
    #[error("`{name}`: rejected: {reason}")]
    Rejected {
        /// The parameter.
        name: String,
        /// The component's reason.
        reason: String,
    },
    /// The command did not reach the component, or was refused by the access rules.
    #[error("`{name}`")]
    Ctl {
        /// The parameter.
        name: String,
        /// What failed.
        #[source]
        source: Box<CtlError>,
    },
}

/// The command that sets `variable` to `value`, as `coolctl set` sends it.
pub(super) fn command(
    name: &str,
    variable: &str,
    value: &ParameterValue,
    declared: Option<&ParameterType>,
) -> Result<Command, SetError> {
    let bad = |why: &str| SetError::Value {
        name: name.to_owned(),
        why: why.to_owned(),
    };
    let seconds = |value: &ParameterValue| {
        let seconds = match value {
            ParameterValue::Float64(f) => *f,
            ParameterValue::Integer(i) => *i as f64,
            _ => return Err(bad("takes a number of seconds")),
        };
        Duration::try_from_secs_f64(seconds)
            .map_err(|_| bad("takes a number of seconds, not negative, finite"))
    };
    let integer = |value: &ParameterValue| match value {
        ParameterValue::Integer(i) => Ok(*i),
        _ => Err(bad("takes an integer")),
    };
    Ok(match variable {
        "period" => Command::SetPeriod(seconds(value)?),
        "max_response" => Command::SetMaxResponse(seconds(value)?),
        "priority" => Command::SetPriority(
            i32::try_from(integer(value)?).map_err(|_| bad("takes a 32-bit integer"))?,
        ),
        "quality" => Command::SetQuality(
            usize::try_from(integer(value)?)
                .map_err(|_| bad("takes a quality level index (0 = best)"))?,
        ),
        _ => Command::Set(variable.to_owned(), to_value(value, declared)),
    })
}

/// Send `command` for parameter `name` to the component at `address`.
pub(super) fn apply(
    ctl: &Ctl,
    name: &str,
    address: &str,
    command: &Command,
) -> Result<(), SetError> {
    match ctl.command(address, command) {
        Ok(ControlReply::Accepted) => Ok(()),
        Ok(ControlReply::Rejected { reason }) => Err(SetError::Rejected {
            name: name.to_owned(),
            reason,
        }),
        Err(source) => Err(SetError::Ctl {
            name: name.to_owned(),
            source: Box::new(source),
        }),
    }
}

/// The request of the `suspend`, `run` and `restart` services.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ComponentRequest {
    /// The component, `<node>/<path>`.
    pub component: String,
}

/// The names of the services, and the states they bring a component to.
pub const SERVICES: [&str; 3] = ["suspend", "run", "restart"];

/// Why a service call failed.
#[derive(Debug, thiserror::Error)]
pub enum CallError {
    /// The request is not a [`ComponentRequest`] in JSON.
    #[error("the request is not {{\"component\": \"<node>/<path>\"}}")]
    Request(#[source] serde_json::Error),
    /// The component refused.
    #[error("{component}: rejected: {reason}")]
    Rejected {
        /// The component.
        component: String,
        /// Its reason.
        reason: String,
    },
    /// The command did not reach the component, or was refused by the access rules.
    #[error("{component}")]
    Ctl {
        /// The component.
        component: String,
        /// What failed.
        #[source]
        source: Box<CtlError>,
    },
}

fn call(ctl: &Ctl, service: &str, request: &Request) -> Result<Vec<u8>, CallError> {
    let ComponentRequest { component } =
        serde_json::from_slice(request.payload()).map_err(CallError::Request)?;
    let states: &[Controllable] = match service {
        "suspend" => &[Controllable::Suspended],
        "run" => &[Controllable::Running],
        _ => &[Controllable::Ready, Controllable::Running],
    };
    for state in states {
        match ctl.command(&component, &Command::SetState(*state)) {
            Ok(ControlReply::Accepted) => {}
            Ok(ControlReply::Rejected { reason }) => {
                return Err(CallError::Rejected { component, reason });
            }
            Err(source) => {
                return Err(CallError::Ctl {
                    component,
                    source: Box::new(source),
                });
            }
        }
    }
    Ok(json!({ "accepted": true }).to_string().into_bytes())
}

/// The `suspend`, `run` and `restart` services, each commanding through `ctl` on a
/// blocking thread of the server's.
pub(super) fn services(ctl: &Ctl) -> Vec<Service> {
    let request = json!({
        "$schema": coolbot::schema::DIALECT,
        "type": "object",
        "properties": { "component": { "type": "string" } },
        "required": ["component"],
    });
    let response = json!({
        "$schema": coolbot::schema::DIALECT,
        "type": "object",
        "properties": { "accepted": { "type": "boolean" } },
        "required": ["accepted"],
    });
    SERVICES
        .iter()
        .map(|name| {
            let schema = ServiceSchema::new(format!("coolbot.{name}"))
                .with_request(
                    "json",
                    Schema::new(
                        "coolbot.ComponentRequest",
                        "jsonschema",
                        request.to_string().into_bytes(),
                    ),
                )
                .with_response(
                    "json",
                    Schema::new(
                        "coolbot.CommandResponse",
                        "jsonschema",
                        response.to_string().into_bytes(),
                    ),
                );
            let ctl = ctl.clone();
            let service = *name;
            Service::builder(service, schema).blocking_handler_fn(move |request: Request| {
                call(&ctl, service, &request).map_err(|error| coolbot::Chain(&error).to_string())
            })
        })
        .collect()
}
