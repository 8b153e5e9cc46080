//! Type descriptions (REP-2016): a message type and every type it references, as the
//! `type_description_interfaces` messages describe them and as the RIHS01 hash
//! ([`super::hash`]) reads them.
//!
//! A field's type is a type id (a base id plus 48 for a fixed array, 96 for a bounded
//! sequence, 144 for an unbounded one), a capacity (the array's size or the sequence's
//! bound, else 0), a string capacity (the bound of a bounded string, else 0) and the
//! name of a nested type (else empty). A `.msg` `char` is described as `uint8` and a
//! `byte` as a byte, as rosidl converts them. A message with no field is described
//! with the one field rosidl gives it, `uint8 structure_needs_at_least_one_member`.
//!
//! Default values are not part of this model: the hash leaves them out.
//!
//! **Invariant:** the structs' fields are declared in the order of the hashed JSON's
//! keys (`serde` writes them in that order).

use std::collections::BTreeMap;

use serde::Serialize;

use super::msg::{Base, Cardinality, FieldType, Message};
use super::names::TypeName;

/// A type and every type it references, directly or not, sorted by name.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct TypeDescription {
    /// The type itself.
    pub type_description: IndividualTypeDescription,
    /// Every other type reachable through its fields, by `type_name`.
    pub referenced_type_descriptions: Vec<IndividualTypeDescription>,
}

/// One type alone: its name and fields.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct IndividualTypeDescription {
    /// `pkg/msg/Type`.
    pub type_name: String,
    /// Its fields, in order.
    pub fields: Vec<FieldDescription>,
}

/// One field.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct FieldDescription {
    /// Its name.
    pub name: String,
    /// Its type.
    #[serde(rename = "type")]
    pub field_type: FieldTypeDescription,
}

/// A field's type.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct FieldTypeDescription {
    /// The type id (`type_description_interfaces/msg/FieldType`).
    pub type_id: u8,
    /// An array's size or a bounded sequence's bound; 0 otherwise.
    pub capacity: u64,
    /// A bounded string's bound; 0 otherwise.
    pub string_capacity: u64,
    /// A nested type's `pkg/msg/Type`; empty otherwise.
    pub nested_type_name: String,
}

/// The type ids of `type_description_interfaces/msg/FieldType` that `.msg` files use.
pub mod type_id {
    /// A nested message type.
    pub const NESTED_TYPE: u8 = 1;
    /// `int8`.
    pub(crate) const INT8: u8 = 2;
    /// `uint8` (and `.msg` `char`).
    pub const UINT8: u8 = 3;
    /// `int16`.
    pub(crate) const INT16: u8 = 4;
    /// `uint16`.
    pub(crate) const UINT16: u8 = 5;
    /// `int32`.
    pub(crate) const INT32: u8 = 6;
    /// `uint32`.
    pub(crate) const UINT32: u8 = 7;
    /// `int64`.
    pub(crate) const INT64: u8 = 8;
    /// `uint64`.
    pub(crate) const UINT64: u8 = 9;
    /// `float32`.
    pub(crate) const FLOAT: u8 = 10;
    /// `float64`.
    pub(crate) const DOUBLE: u8 = 11;
    /// `bool`.
    pub const BOOLEAN: u8 = 15;
    /// `byte`.
    pub const BYTE: u8 = 16;
    /// `string`.
    pub(crate) const STRING: u8 = 17;
    /// `wstring`.
    pub const WSTRING: u8 = 18;
    /// `string<=N`.
    pub const BOUNDED_STRING: u8 = 21;
    /// `wstring<=N`.
    pub const BOUNDED_WSTRING: u8 = 22;
    /// Added to a base id for a fixed array (`T[N]`).
    pub(crate) const ARRAY: u8 = 48;
    /// Added to a base id for a bounded sequence (`T[<=N]`).
    pub(crate) const BOUNDED_SEQUENCE: u8 = 96;
    /// Added to a base id for an unbounded sequence (`T[]`).
    pub(crate) const UNBOUNDED_SEQUENCE: u8 = 144;
}

/// The description of `name`: `None` when `name` or a type it references is not
/// given by `get`.
pub(crate) fn describe<'m>(
    name: &TypeName,
    get: impl Fn(&TypeName) -> Option<&'m Message>,
) -> Option<TypeDescription> {
    let top = get(name)?;
    let mut referenced: BTreeMap<String, IndividualTypeDescription> = BTreeMap::new();
    let mut pending: Vec<&TypeName> = nested(top).collect();
    while let Some(next) = pending.pop() {
        let key = next.to_string();
        if next == name || referenced.contains_key(&key) {
            continue;
        }
        let message = get(next)?;
        pending.extend(nested(message));
        referenced.insert(key, individual(message));
    }
    Some(TypeDescription {
        type_description: individual(top),
        referenced_type_descriptions: referenced.into_values().collect(),
    })
}

/// The nested types a message's fields name.
fn nested(message: &Message) -> impl Iterator<Item = &TypeName> {
    message
        .fields
        .iter()
        .filter_map(|field| match &field.ty.base {
            Base::Nested(name) => Some(name),
            _ => None,
        })
}

/// One type's own description.
pub(crate) fn individual(message: &Message) -> IndividualTypeDescription {
    let mut fields: Vec<FieldDescription> = message
        .fields
        .iter()
        .map(|field| FieldDescription {
            name: field.name.clone(),
            field_type: field_type(&field.ty),
        })
        .collect();
    if fields.is_empty() {
        fields.push(FieldDescription {
            name: "structure_needs_at_least_one_member".into(),
            field_type: FieldTypeDescription {
                type_id: type_id::UINT8,
                capacity: 0,
                string_capacity: 0,
                nested_type_name: String::new(),
            },
        });
    }
    IndividualTypeDescription {
        type_name: message.name.to_string(),
        fields,
    }
}

/// A field type's description.
pub(crate) fn field_type(ty: &FieldType) -> FieldTypeDescription {
    let (base_id, string_capacity, nested_type_name) = match &ty.base {
        Base::Bool => (type_id::BOOLEAN, 0, String::new()),
        Base::Byte => (type_id::BYTE, 0, String::new()),
        Base::Char | Base::Uint8 => (type_id::UINT8, 0, String::new()),
        Base::Int8 => (type_id::INT8, 0, String::new()),
        Base::Int16 => (type_id::INT16, 0, String::new()),
        Base::Uint16 => (type_id::UINT16, 0, String::new()),
        Base::Int32 => (type_id::INT32, 0, String::new()),
        Base::Uint32 => (type_id::UINT32, 0, String::new()),
        Base::Int64 => (type_id::INT64, 0, String::new()),
        Base::Uint64 => (type_id::UINT64, 0, String::new()),
        Base::Float32 => (type_id::FLOAT, 0, String::new()),
        Base::Float64 => (type_id::DOUBLE, 0, String::new()),
        Base::String(None) => (type_id::STRING, 0, String::new()),
        Base::String(Some(bound)) => (type_id::BOUNDED_STRING, *bound, String::new()),
        Base::WString(None) => (type_id::WSTRING, 0, String::new()),
        Base::WString(Some(bound)) => (type_id::BOUNDED_WSTRING, *bound, String::new()),
        Base::Nested(name) => (type_id::NESTED_TYPE, 0, name.to_string()),
    };
    let (offset, capacity) = match ty.cardinality {
        Cardinality::Single => (0, 0),
        Cardinality::Array(size) => (type_id::ARRAY, size),
        Cardinality::Bounded(bound) => (type_id::BOUNDED_SEQUENCE, bound),
        Cardinality::Unbounded => (type_id::UNBOUNDED_SEQUENCE, 0),
    };
    FieldTypeDescription {
        type_id: base_id + offset,
        capacity,
        string_capacity,
        nested_type_name,
    }
}
