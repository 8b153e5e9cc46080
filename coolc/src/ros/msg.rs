//! The model of one `.msg` file: its fields and constants, with the spans they were
//! read from (what [`super::parse`] builds).

use std::fmt;

use crate::ast::{FileId, Span};

use super::names::TypeName;

/// One message type, as its `.msg` file defines it.
#[derive(Clone, Debug, PartialEq)]
pub struct Message {
    /// Its name (from where its file was found).
    pub name: TypeName,
    /// Its file in the [`crate::SourceMap`].
    pub file: FileId,
    /// Its constants, in file order.
    pub constants: Vec<Constant>,
    /// Its fields, in file order (the order they are serialized in).
    pub fields: Vec<Field>,
}

/// A field: `float64 x`, `int32[] a [1, 2]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Field {
    /// The field's name.
    pub name: String,
    /// Where the name is.
    pub name_span: Span,
    /// The field's type.
    pub ty: FieldType,
    /// Where the type is.
    pub ty_span: Span,
    /// Its default value and where it is, if it has one.
    pub default: Option<(Value, Span)>,
}

/// A constant: `uint8 FOO=1`, `string NAME="x"`.
#[derive(Clone, Debug, PartialEq)]
pub struct Constant {
    /// The constant's name.
    pub name: String,
    /// Where the name is.
    pub name_span: Span,
    /// Its type: a primitive, never an array, a bounded string or a nested type.
    pub ty: Base,
    /// Where the type is.
    pub ty_span: Span,
    /// Its value.
    pub value: Value,
    /// Where the value is.
    pub value_span: Span,
}

/// A field's type: a base type, alone or in an array or sequence.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FieldType {
    /// The element type.
    pub base: Base,
    /// One value, or how many.
    pub cardinality: Cardinality,
}

/// How many values of the base type a field holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cardinality {
    /// One (`T`).
    Single,
    /// Exactly this many (`T[N]`).
    Array(u64),
    /// At most this many (`T[<=N]`).
    Bounded(u64),
    /// Any number (`T[]`).
    Unbounded,
}

/// A base type: a primitive, a string (bounded or not) or a message type.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Base {
    /// `bool`.
    Bool,
    /// `byte`: an octet.
    Byte,
    /// `char`: an 8-bit unsigned integer (rosidl maps it to `uint8`).
    Char,
    /// `int8`.
    Int8,
    /// `uint8`.
    Uint8,
    /// `int16`.
    Int16,
    /// `uint16`.
    Uint16,
    /// `int32`.
    Int32,
    /// `uint32`.
    Uint32,
    /// `int64`.
    Int64,
    /// `uint64`.
    Uint64,
    /// `float32`.
    Float32,
    /// `float64`.
    Float64,
    /// `string`, or `string<=N` with its bound.
    String(Option<u64>),
    /// `wstring`, or `wstring<=N` with its bound.
    WString(Option<u64>),
    /// A message type.
    Nested(TypeName),
}

impl Base {
    /// The primitive types by their `.msg` keyword (strings unbounded).
    pub(crate) const PRIMITIVES: &'static [(&'static str, Base)] = &[
        ("bool", Base::Bool),
        ("byte", Base::Byte),
        ("char", Base::Char),
        ("int8", Base::Int8),
        ("uint8", Base::Uint8),
        ("int16", Base::Int16),
        ("uint16", Base::Uint16),
        ("int32", Base::Int32),
        ("uint32", Base::Uint32),
        ("int64", Base::Int64),
        ("uint64", Base::Uint64),
        ("float32", Base::Float32),
        ("float64", Base::Float64),
        ("string", Base::String(None)),
        ("wstring", Base::WString(None)),
    ];

    /// The primitive type of a `.msg` keyword.
    pub(crate) fn primitive(keyword: &str) -> Option<Base> {
        Base::PRIMITIVES
            .iter()
            .find(|(name, _)| *name == keyword)
            .map(|(_, base)| base.clone())
    }

    /// The range of an integer type (`byte` and `char` are 0..=255).
    pub(crate) fn integer_range(&self) -> Option<(i128, i128)> {
        let bits = |bits: u32, signed: bool| {
            if signed {
                (-(1i128 << (bits - 1)), (1i128 << (bits - 1)) - 1)
            } else {
                (0, (1i128 << bits) - 1)
            }
        };
        Some(match self {
            Base::Byte | Base::Char | Base::Uint8 => bits(8, false),
            Base::Int8 => bits(8, true),
            Base::Int16 => bits(16, true),
            Base::Uint16 => bits(16, false),
            Base::Int32 => bits(32, true),
            Base::Uint32 => bits(32, false),
            Base::Int64 => bits(64, true),
            Base::Uint64 => bits(64, false),
            _ => return None,
        })
    }
}

/// The `.msg` spelling (`string<=8`, `geometry_msgs/msg/Point`).
impl fmt::Display for Base {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let keyword = match self {
            Base::Bool => "bool",
            Base::Byte => "byte",
            Base::Char => "char",
            Base::Int8 => "int8",
            Base::Uint8 => "uint8",
            Base::Int16 => "int16",
            Base::Uint16 => "uint16",
            Base::Int32 => "int32",
            Base::Uint32 => "uint32",
            Base::Int64 => "int64",
            Base::Uint64 => "uint64",
            Base::Float32 => "float32",
            Base::Float64 => "float64",
            Base::String(None) => "string",
            Base::WString(None) => "wstring",
            Base::String(Some(bound)) => return write!(f, "string<={bound}"),
            Base::WString(Some(bound)) => return write!(f, "wstring<={bound}"),
            Base::Nested(name) => return write!(f, "{name}"),
        };
        f.write_str(keyword)
    }
}

/// The `.msg` spelling (`float64[36]`, `int32[<=4]`).
impl fmt::Display for FieldType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.cardinality {
            Cardinality::Single => write!(f, "{}", self.base),
            Cardinality::Array(size) => write!(f, "{}[{size}]", self.base),
            Cardinality::Bounded(bound) => write!(f, "{}[<={bound}]", self.base),
            Cardinality::Unbounded => write!(f, "{}[]", self.base),
        }
    }
}

/// A constant's value or a field's default value.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// Of `bool`.
    Bool(bool),
    /// Of an integer type, `byte` or `char` (within the type's range).
    Int(i128),
    /// Of `float32` or `float64`.
    Float(f64),
    /// Of a string type (unquoted, escapes resolved).
    String(String),
    /// Of an array or sequence.
    Array(Vec<Value>),
}
