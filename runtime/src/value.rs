//! Values that cross the default ports ([`Value`]) and wall-clock stamps ([`Time`]).

use std::fmt;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};

/// A wall-clock stamp: nanoseconds since the UNIX epoch.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default, Serialize, Deserialize,
)]
#[serde(transparent)]
pub struct Time(pub u64);

impl Time {
    /// The current wall-clock time.
    pub fn now() -> Time {
        let since = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .unwrap_or(Duration::ZERO);
        Time(u64::try_from(since.as_nanos()).unwrap_or(u64::MAX))
    }

    /// The stamp `nanos` nanoseconds after the epoch.
    pub const fn from_nanos(nanos: u64) -> Time {
        Time(nanos)
    }

    /// Nanoseconds since the epoch.
    pub const fn as_nanos(self) -> u64 {
        self.0
    }

    /// The time elapsed from `earlier` to `self` (zero if `earlier` is later).
    pub fn duration_since(self, earlier: Time) -> Duration {
        Duration::from_nanos(self.0.saturating_sub(earlier.0))
    }
}

/// A dynamically typed value: configurations, controllable and observable variables.
///
/// Generated code converts user packets and enums with serde (as [`Value::Json`]);
/// primitives convert with `From` and `TryFrom<&Value>`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub enum Value {
    /// No value.
    #[default]
    Unit,
    /// A boolean.
    Bool(bool),
    /// A signed integer.
    Int(i64),
    /// An unsigned integer.
    UInt(u64),
    /// A float.
    Float(f64),
    /// A string.
    Str(String),
    /// A wall-clock stamp.
    Time(Time),
    /// A duration.
    Duration(Duration),
    /// An enum variant's name.
    Enum(String),
    /// A list.
    List(Vec<Value>),
    /// Named fields, in order.
    Record(Vec<(String, Value)>),
    /// Anything serde can represent.
    Json(serde_json::Value),
}

impl Value {
    /// A short name of the value's variant, for error messages.
    pub fn kind_name(&self) -> &'static str {
        match self {
            Value::Unit => "unit",
            Value::Bool(_) => "bool",
            Value::Int(_) => "int",
            Value::UInt(_) => "uint",
            Value::Float(_) => "float",
            Value::Str(_) => "string",
            Value::Time(_) => "time",
            Value::Duration(_) => "duration",
            Value::Enum(_) => "enum",
            Value::List(_) => "list",
            Value::Record(_) => "record",
            Value::Json(_) => "json",
        }
    }

    /// The field `name` of a record (or of a JSON object, converted).
    pub fn field(&self, name: &str) -> Option<Value> {
        match self {
            Value::Record(fields) => fields
                .iter()
                .find(|(field, _)| field == name)
                .map(|(_, v)| v.clone()),
            Value::Json(serde_json::Value::Object(map)) => map.get(name).cloned().map(Value::Json),
            _ => None,
        }
    }

    /// The value as JSON (records become objects, durations seconds as floats).
    pub fn to_json(&self) -> serde_json::Value {
        use serde_json::Value as J;
        match self {
            Value::Unit => J::Null,
            Value::Bool(b) => J::Bool(*b),
            Value::Int(i) => J::from(*i),
            Value::UInt(u) => J::from(*u),
            Value::Float(f) => J::from(*f),
            Value::Str(s) | Value::Enum(s) => J::String(s.clone()),
            Value::Time(t) => J::from(t.0),
            Value::Duration(d) => J::from(d.as_secs_f64()),
            Value::List(items) => J::Array(items.iter().map(Value::to_json).collect()),
            Value::Record(fields) => J::Object(
                fields
                    .iter()
                    .map(|(k, v)| (k.clone(), v.to_json()))
                    .collect(),
            ),
            Value::Json(j) => j.clone(),
        }
    }

    /// Convert a serializable user value (packet, enum, struct) into a [`Value::Json`].
    pub fn from_serde<T: Serialize>(value: &T) -> Result<Value, ConvertError> {
        serde_json::to_value(value)
            .map(Value::Json)
            .map_err(ConvertError::Serialize)
    }

    /// Convert into a deserializable user type, through JSON.
    pub fn to_serde<T: serde::de::DeserializeOwned>(&self) -> Result<T, ConvertError> {
        serde_json::from_value(self.to_json()).map_err(ConvertError::Deserialize)
    }
}

/// A user value that does not convert to or from a [`Value`] ([`Value::from_serde`],
/// [`Value::to_serde`]); the source is serde's reason.
#[derive(Debug, thiserror::Error)]
pub enum ConvertError {
    /// The user value has no JSON form (a map whose keys are not strings, a
    /// serializer's own error).
    #[error("the value cannot be written as JSON")]
    Serialize(#[source] serde_json::Error),
    /// The value is not one of the type asked for.
    #[error("the value does not match its type")]
    Deserialize(#[source] serde_json::Error),
}

impl fmt::Display for Value {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Value::Str(s) => write!(f, "{s:?}"),
            Value::Duration(d) => write!(f, "{d:?}"),
            other => write!(f, "{}", other.to_json()),
        }
    }
}

/// A value of the wrong kind for the requested conversion.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("expected {expected}, got {got}")]
pub struct ValueError {
    /// What was expected.
    pub expected: &'static str,
    /// What the value was.
    pub got: &'static str,
}

macro_rules! int_conversions {
    ($($ty:ty => $variant:ident as $wide:ty),* $(,)?) => {$(
        impl From<$ty> for Value {
            fn from(value: $ty) -> Value {
                Value::$variant(<$wide>::from(value))
            }
        }
        impl TryFrom<&Value> for $ty {
            type Error = ValueError;
            fn try_from(value: &Value) -> Result<$ty, ValueError> {
                let error = ValueError { expected: stringify!($ty), got: value.kind_name() };
                match value {
                    Value::Int(i) => <$ty>::try_from(*i).map_err(|_| error),
                    Value::UInt(u) => <$ty>::try_from(*u).map_err(|_| error),
                    Value::Json(j) => j
                        .as_i64()
                        .and_then(|i| <$ty>::try_from(i).ok())
                        .or_else(|| j.as_u64().and_then(|u| <$ty>::try_from(u).ok()))
                        .ok_or(error),
                    _ => Err(error),
                }
            }
        }
    )*};
}

int_conversions!(
    i8 => Int as i64, i16 => Int as i64, i32 => Int as i64, i64 => Int as i64,
    u8 => UInt as u64, u16 => UInt as u64, u32 => UInt as u64, u64 => UInt as u64,
);

impl From<f64> for Value {
    fn from(value: f64) -> Value {
        Value::Float(value)
    }
}

impl From<f32> for Value {
    fn from(value: f32) -> Value {
        Value::Float(f64::from(value))
    }
}

impl TryFrom<&Value> for f64 {
    type Error = ValueError;
    fn try_from(value: &Value) -> Result<f64, ValueError> {
        match value {
            Value::Float(f) => Ok(*f),
            // Integers are accepted where a float is expected; precision loss above 2^53
            // is the documented behaviour of this conversion.
            Value::Int(i) => Ok(*i as f64),
            Value::UInt(u) => Ok(*u as f64),
            Value::Json(j) => j.as_f64().ok_or(ValueError {
                expected: "f64",
                got: "json",
            }),
            other => Err(ValueError {
                expected: "f64",
                got: other.kind_name(),
            }),
        }
    }
}

impl TryFrom<&Value> for f32 {
    type Error = ValueError;
    fn try_from(value: &Value) -> Result<f32, ValueError> {
        // Narrowing to f32 is what the caller asked for.
        f64::try_from(value).map(|f| f as f32)
    }
}

impl From<bool> for Value {
    fn from(value: bool) -> Value {
        Value::Bool(value)
    }
}

impl TryFrom<&Value> for bool {
    type Error = ValueError;
    fn try_from(value: &Value) -> Result<bool, ValueError> {
        match value {
            Value::Bool(b) => Ok(*b),
            Value::Json(serde_json::Value::Bool(b)) => Ok(*b),
            other => Err(ValueError {
                expected: "bool",
                got: other.kind_name(),
            }),
        }
    }
}

impl From<String> for Value {
    fn from(value: String) -> Value {
        Value::Str(value)
    }
}

impl From<&str> for Value {
    fn from(value: &str) -> Value {
        Value::Str(value.to_owned())
    }
}

impl TryFrom<&Value> for String {
    type Error = ValueError;
    fn try_from(value: &Value) -> Result<String, ValueError> {
        match value {
            Value::Str(s) | Value::Enum(s) => Ok(s.clone()),
            Value::Json(serde_json::Value::String(s)) => Ok(s.clone()),
            other => Err(ValueError {
                expected: "String",
                got: other.kind_name(),
            }),
        }
    }
}

impl From<Duration> for Value {
    fn from(value: Duration) -> Value {
        Value::Duration(value)
    }
}

impl TryFrom<&Value> for Duration {
    type Error = ValueError;
    fn try_from(value: &Value) -> Result<Duration, ValueError> {
        match value {
            Value::Duration(d) => Ok(*d),
            other => Err(ValueError {
                expected: "Duration",
                got: other.kind_name(),
            }),
        }
    }
}

impl From<Time> for Value {
    fn from(value: Time) -> Value {
        Value::Time(value)
    }
}

impl TryFrom<&Value> for Time {
    type Error = ValueError;
    fn try_from(value: &Value) -> Result<Time, ValueError> {
        match value {
            Value::Time(t) => Ok(*t),
            Value::UInt(u) => Ok(Time(*u)),
            other => Err(ValueError {
                expected: "Time",
                got: other.kind_name(),
            }),
        }
    }
}

impl From<serde_json::Value> for Value {
    fn from(value: serde_json::Value) -> Value {
        Value::Json(value)
    }
}

impl<T: Into<Value>> From<Option<T>> for Value {
    fn from(value: Option<T>) -> Value {
        value.map_or(Value::Unit, Into::into)
    }
}

impl<T: Into<Value>> From<Vec<T>> for Value {
    fn from(value: Vec<T>) -> Value {
        Value::List(value.into_iter().map(Into::into).collect())
    }
}
