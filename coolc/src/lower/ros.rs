//! The ROS 2 message types of a checked model to the IR: one struct per type, in one
//! module per package inside the types module's `ros` module (`docs/ros2.md`, "ROS 2
//! message types in Rust").
//!
//! A field keeps its `.msg` name (keyword-escaped) and order, which CDR depends on;
//! `bool`, the integers and the floats are Rust's, `byte` and `char` are `u8`, strings
//! `String`, `T[N]` `[T; N]`, `T[<=N]` and `T[]` `Vec<T>`, a message type the struct of
//! its package's module. Bounded strings and sequences decode through
//! `coolbot::ros::{BoundedString, Bounded}`, arrays longer than 32 through
//! `serde_with`'s `[Same; N]`, unbounded byte sequences through its `Bytes` (one
//! slice). A message without fields gets the one field rosidl gives it, so that its
//! CDR is ROS 2's. `Default` gives each field its `.msg` default, else its type's.

use crate::checked::Checked;
use crate::checked::model::RosMessage;
use crate::ir;
use crate::ros::msg::{Base, Cardinality, Constant, Field, FieldType, Value};
use crate::{ident, ros};

use super::{SERDE_WITH, default_code};

/// The path of the runtime's ROS module as generated code sees it.
const COOLBOT_ROS: &str = "::coolbot::ros::";

/// The name of the field rosidl gives a message without fields.
const PLACEHOLDER: &str = "structure_needs_at_least_one_member";

/// The packages of every ROS 2 message type of the model, by package; their types
/// by name.
pub(super) fn packages(checked: &Checked) -> Vec<ir::RosPackage> {
    let mut packages: Vec<ir::RosPackage> = Vec::new();
    for ros in checked.ros_messages() {
        let module = ident::escape(ros.message.name.package());
        let message = message(ros);
        match packages.last_mut() {
            Some(package) if package.module == module => package.messages.push(message),
            _ => packages.push(ir::RosPackage {
                package: ros.message.name.package().to_owned(),
                module,
                messages: vec![message],
            }),
        }
    }
    packages
}

/// The path of a ROS type's struct from inside any package module.
fn struct_path(name: &ros::TypeName) -> String {
    format!(
        "super::{}::{}",
        ident::escape(name.package()),
        ident::escape(name.name())
    )
}

fn message(ros: &RosMessage) -> ir::RosMessage {
    let message = &ros.message;
    let mut fields: Vec<ir::Field> = message.fields.iter().map(field).collect();
    // When every default is the one the field's type gives, the struct derives
    // `Default` (as clippy asks) rather than spell the same values out.
    let derivable = message.fields.iter().all(|field| {
        field
            .default
            .as_ref()
            .is_none_or(|(value, _)| is_type_default(value, field.ty.cardinality))
    });
    if derivable {
        for (ir, field) in fields.iter_mut().zip(&message.fields) {
            ir.default = type_default(&field.ty);
        }
    }
    if fields.is_empty() {
        fields.push(ir::Field {
            doc: vec![
                "The field rosidl gives a message without fields: ROS 2 sends it.".to_owned(),
            ],
            name: PLACEHOLDER.to_owned(),
            cool_name: PLACEHOLDER.to_owned(),
            ty: "u8".to_owned(),
            default: ir::Code::atom("0"),
            serde_with: None,
        });
    }
    ir::RosMessage {
        packet: ir::Packet {
            doc: vec![format!("The ROS 2 message type `{}`.", message.name)],
            name: ident::escape(message.name.name()),
            fields,
            has_default: true,
        },
        constants: message.constants.iter().map(constant).collect(),
        name: ident::string_literal(&message.name.to_string()),
        dds_name: ident::string_literal(&message.name.dds_name()),
        hash: ident::string_literal(&ros.hash.to_string()),
        definition: ident::string_literal(&ros.definition),
    }
}

fn field(field: &Field) -> ir::Field {
    let mut doc = vec![format!("`{} {}`", field.ty, field.name)];
    if let Some(bound) = bound_doc(&field.ty) {
        doc.push(String::new());
        doc.push(bound);
    }
    ir::Field {
        doc,
        name: ident::snake(&field.name),
        cool_name: field.name.clone(),
        ty: field_ty(&field.ty),
        default: match &field.default {
            Some((value, _)) => value_rust(value, &field.ty),
            None => type_default(&field.ty),
        },
        serde_with: adapter(&field.ty).map(|adapter| format!("{SERDE_WITH}As::<{adapter}>")),
    }
}

/// The Rust expression of the default value of a field's type (`Default` for arrays
/// stops at 32 elements).
fn type_default(ty: &FieldType) -> ir::Code {
    match ty.cardinality {
        Cardinality::Array(size) if size > 32 => super::array_from_fn(default_code()),
        _ => default_code(),
    }
}

/// What a field's doc says of its bounds.
fn bound_doc(ty: &FieldType) -> Option<String> {
    let string = match ty.base {
        Base::String(Some(bound)) | Base::WString(Some(bound)) => Some(bound),
        _ => None,
    };
    let sequence = match ty.cardinality {
        Cardinality::Bounded(bound) => Some(bound),
        _ => None,
    };
    let text = match (sequence, string) {
        (Some(count), Some(chars)) => {
            format!("At most {count} elements of at most {chars} characters each")
        }
        (Some(count), None) => format!("At most {count} elements"),
        (None, Some(chars)) if ty.cardinality == Cardinality::Single => {
            format!("At most {chars} characters")
        }
        (None, Some(chars)) => format!("Elements of at most {chars} characters"),
        (None, None) => return None,
    };
    Some(format!("{text}: a longer value is refused when decoded."))
}

/// The Rust type of a base type.
fn base_ty(base: &Base) -> String {
    match base {
        Base::Bool => "bool",
        Base::Byte | Base::Char | Base::Uint8 => "u8",
        Base::Int8 => "i8",
        Base::Int16 => "i16",
        Base::Uint16 => "u16",
        Base::Int32 => "i32",
        Base::Uint32 => "u32",
        Base::Int64 => "i64",
        Base::Uint64 => "u64",
        Base::Float32 => "f32",
        Base::Float64 => "f64",
        Base::String(_) | Base::WString(_) => "::std::string::String",
        Base::Nested(name) => return struct_path(name),
    }
    .to_owned()
}

/// The Rust type of a field.
fn field_ty(ty: &FieldType) -> String {
    let base = base_ty(&ty.base);
    match ty.cardinality {
        Cardinality::Single => base,
        Cardinality::Array(size) => format!("[{base}; {size}]"),
        Cardinality::Bounded(_) | Cardinality::Unbounded => format!("::std::vec::Vec<{base}>"),
    }
}

/// The `serde_with` adapter of a field, when it needs one: a bound to check, an array
/// longer than serde's own impls go (32), or a sequence of bytes (one slice).
fn adapter(ty: &FieldType) -> Option<String> {
    let element = match ty.base {
        Base::String(Some(bound)) | Base::WString(Some(bound)) => {
            Some(format!("{COOLBOT_ROS}BoundedString<{bound}>"))
        }
        _ => None,
    };
    let same = || format!("{SERDE_WITH}Same");
    match ty.cardinality {
        Cardinality::Single => element,
        Cardinality::Array(size) if element.is_some() || size > 32 => {
            Some(format!("[{}; {size}]", element.unwrap_or_else(same)))
        }
        Cardinality::Array(_) => None,
        Cardinality::Bounded(bound) => Some(match element {
            Some(element) => format!("{COOLBOT_ROS}Bounded<{bound}, {element}>"),
            None => format!("{COOLBOT_ROS}Bounded<{bound}>"),
        }),
        // A sequence of bytes (an image's `data`) as one slice, not byte by byte: CDR
        // writes both alike (a length, then the bytes).
        Cardinality::Unbounded if matches!(ty.base, Base::Byte | Base::Char | Base::Uint8) => {
            Some(format!("{SERDE_WITH}Bytes"))
        }
        Cardinality::Unbounded => element.map(|element| format!("::std::vec::Vec<{element}>")),
    }
}

fn constant(constant: &Constant) -> ir::RosConstant {
    let ty = match constant.ty {
        Base::String(_) | Base::WString(_) => "&str".to_owned(),
        ref base => base_ty(base),
    };
    ir::RosConstant {
        doc: vec![format!(
            "`{} {}={}`",
            constant.ty,
            constant.name,
            written(&constant.value)
        )],
        name: ident::escape(&constant.name),
        ty,
        value: scalar_rust(&constant.value, &constant.ty, false),
    }
}

/// Whether a field's default value is the one its Rust type's `Default` gives: zero
/// (not `-0.0`), `false`, an empty string or sequence, an array of those.
fn is_type_default(value: &Value, cardinality: Cardinality) -> bool {
    match (value, cardinality) {
        (Value::Array(items), Cardinality::Array(_)) => items
            .iter()
            .all(|item| is_type_default(item, Cardinality::Single)),
        (Value::Array(items), _) => items.is_empty(),
        (Value::Bool(value), _) => !value,
        (Value::Int(value), _) => *value == 0,
        (Value::Float(value), _) => *value == 0.0 && value.is_sign_positive(),
        (Value::String(text), _) => text.is_empty(),
    }
}

/// A constant's value as a doc comment shows it.
fn written(value: &Value) -> String {
    match value {
        Value::Bool(value) => value.to_string(),
        Value::Int(value) => value.to_string(),
        Value::Float(value) => value.to_string(),
        Value::String(text) => format!("{text:?}"),
        Value::Array(items) => {
            let items: Vec<String> = items.iter().map(written).collect();
            format!("[{}]", items.join(", "))
        }
    }
}

/// The Rust expression of a field's default value.
fn value_rust(value: &Value, ty: &FieldType) -> ir::Code {
    match (value, ty.cardinality) {
        (Value::Array(items), cardinality) => {
            let items: Vec<ir::Code> = items
                .iter()
                .map(|item| scalar_code(item, &ty.base))
                .collect();
            match cardinality {
                Cardinality::Array(_) => ir::Code::List("[".to_owned(), items),
                _ => ir::Code::List("::std::vec![".to_owned(), items),
            }
        }
        (value, _) => scalar_code(value, &ty.base),
    }
}

/// [`scalar_rust`] of an owned value (a string is a `String`).
fn scalar_code(value: &Value, base: &Base) -> ir::Code {
    match value {
        Value::String(text) => {
            ir::Code::call("::std::string::String::from", vec![ir::Code::string(text)])
        }
        Value::Array(_) => default_code(),
        value => ir::Code::atom(scalar_rust(value, base, true)),
    }
}

/// The Rust expression of one value of a base type: a string is a `String` when
/// `owned`, else a literal.
fn scalar_rust(value: &Value, base: &Base, owned: bool) -> String {
    match value {
        Value::Bool(value) => value.to_string(),
        Value::Int(value) => value.to_string(),
        Value::Float(value) => float_rust(*value, base == &Base::Float32),
        Value::String(text) if owned => {
            format!(
                "::std::string::String::from({})",
                ident::string_literal(text)
            )
        }
        Value::String(text) => ident::string_literal(text),
        // An array inside an array does not exist: `.msg` has none.
        Value::Array(_) => default_code().to_string(),
    }
}

/// A float literal of `f32` or `f64`: the shortest text that reads back as the same
/// value of that type (a `float32` written `0.1` is the `f32` nearest 0.1).
fn float_rust(value: f64, single: bool) -> String {
    let ty = if single { "f32" } else { "f64" };
    if value.is_nan() {
        format!("{ty}::NAN")
    } else if value.is_infinite() {
        let sign = if value < 0.0 { "NEG_" } else { "" };
        format!("{ty}::{sign}INFINITY")
    } else if single {
        format!("{:?}", value as f32)
    } else {
        format!("{value:?}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ty(base: Base, cardinality: Cardinality) -> FieldType {
        FieldType { base, cardinality }
    }

    #[test]
    fn every_field_type_maps_to_its_rust_type_and_adapter() {
        let point = Base::Nested(ros::TypeName::parse("geometry_msgs/msg/Point").unwrap());
        let cases = [
            (ty(Base::Bool, Cardinality::Single), "bool", None),
            (ty(Base::Char, Cardinality::Single), "u8", None),
            (
                ty(Base::Byte, Cardinality::Unbounded),
                "::std::vec::Vec<u8>",
                Some("::coolbot::serde_with::Bytes"),
            ),
            (ty(Base::Float64, Cardinality::Array(9)), "[f64; 9]", None),
            (
                ty(Base::Float64, Cardinality::Array(36)),
                "[f64; 36]",
                Some("[::coolbot::serde_with::Same; 36]"),
            ),
            (
                ty(Base::Int32, Cardinality::Bounded(5)),
                "::std::vec::Vec<i32>",
                Some("::coolbot::ros::Bounded<5>"),
            ),
            (
                ty(Base::String(Some(4)), Cardinality::Single),
                "::std::string::String",
                Some("::coolbot::ros::BoundedString<4>"),
            ),
            (
                ty(Base::String(Some(4)), Cardinality::Bounded(3)),
                "::std::vec::Vec<::std::string::String>",
                Some("::coolbot::ros::Bounded<3, ::coolbot::ros::BoundedString<4>>"),
            ),
            (
                ty(Base::WString(Some(4)), Cardinality::Array(2)),
                "[::std::string::String; 2]",
                Some("[::coolbot::ros::BoundedString<4>; 2]"),
            ),
            (
                ty(Base::String(Some(4)), Cardinality::Unbounded),
                "::std::vec::Vec<::std::string::String>",
                Some("::std::vec::Vec<::coolbot::ros::BoundedString<4>>"),
            ),
            (
                ty(Base::WString(None), Cardinality::Single),
                "::std::string::String",
                None,
            ),
            (
                ty(point, Cardinality::Unbounded),
                "::std::vec::Vec<super::geometry_msgs::Point>",
                None,
            ),
        ];
        for (ty, rust, serde) in cases {
            assert_eq!(field_ty(&ty), rust, "{ty}");
            assert_eq!(adapter(&ty).as_deref(), serde, "{ty}");
        }
    }

    #[test]
    fn a_default_equal_to_the_types_is_left_to_its_default() {
        let single = Cardinality::Single;
        assert!(is_type_default(&Value::Int(0), single));
        assert!(is_type_default(&Value::Float(0.0), single));
        assert!(!is_type_default(&Value::Float(-0.0), single));
        assert!(is_type_default(&Value::String(String::new()), single));
        let zeros = Value::Array(vec![Value::Int(0), Value::Int(0)]);
        assert!(is_type_default(&zeros, Cardinality::Array(2)));
        assert!(!is_type_default(&zeros, Cardinality::Unbounded));
        assert!(is_type_default(
            &Value::Array(vec![]),
            Cardinality::Bounded(3)
        ));
        assert!(!is_type_default(&Value::Bool(true), single));
    }

    #[test]
    fn floats_read_back_as_the_same_value_of_their_type() {
        assert_eq!(float_rust(0.1, true), "0.1");
        assert_eq!(float_rust(1.0, false), "1.0");
        assert_eq!(float_rust(1e300, false), "1e300");
        assert_eq!(float_rust(f64::NEG_INFINITY, true), "f32::NEG_INFINITY");
        assert_eq!(float_rust(f64::NAN, false), "f64::NAN");
        // The f32 nearest the value: 16777217 is no f32.
        assert_eq!(float_rust(16_777_217.0, true), "16777216.0");
    }
}
