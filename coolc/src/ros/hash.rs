//! The RIHS01 type hash (REP-2016): the SHA-256 of a [`TypeDescription`] written as
//! JSON, printed `RIHS01_` and 64 lowercase hex digits.
//!
//! The JSON is exactly what rosidl hashes (`rosidl_generator_type_description`):
//! `{"type_description": ..., "referenced_type_descriptions": [...]}`, keys in the
//! model's order, `", "` between items and `": "` after keys (Python's `json.dumps`
//! with `indent=None`), every character outside ASCII escaped as `\uXXXX`, and no
//! default values.

use std::fmt;
use std::io;

use serde::Serialize;
use sha2::{Digest, Sha256};

use super::description::TypeDescription;

/// A RIHS01 hash: SHA-256 over the hashed JSON of a type description.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct TypeHash([u8; 32]);

impl TypeHash {
    /// The hash of a type description.
    pub fn of(description: &TypeDescription) -> TypeHash {
        TypeHash(Sha256::digest(hashed_json(description).as_bytes()).into())
    }
}

/// `RIHS01_` and the digest in lowercase hex: how ROS 2 prints and sends it.
impl fmt::Display for TypeHash {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("RIHS01_")?;
        for byte in self.0 {
            write!(f, "{byte:02x}")?;
        }
        Ok(())
    }
}

/// The JSON text that is hashed.
pub fn hashed_json(description: &TypeDescription) -> String {
    let mut out = Vec::new();
    let mut serializer = serde_json::Serializer::with_formatter(&mut out, PythonFormatter);
    description
        .serialize(&mut serializer)
        .expect("a type description is plain data, and a Vec accepts every write");
    String::from_utf8(out).expect("the formatter writes ASCII only")
}

/// Python's `json.dumps(..., indent=None, ensure_ascii=True)`: `", "` and `": "`
/// separators, non-ASCII characters as `\uXXXX` (surrogate pairs above U+FFFF).
struct PythonFormatter;

impl serde_json::ser::Formatter for PythonFormatter {
    fn begin_array_value<W: ?Sized + io::Write>(
        &mut self,
        writer: &mut W,
        first: bool,
    ) -> io::Result<()> {
        if first {
            Ok(())
        } else {
            writer.write_all(b", ")
        }
    }

    fn begin_object_key<W: ?Sized + io::Write>(
        &mut self,
        writer: &mut W,
        first: bool,
    ) -> io::Result<()> {
        if first {
            Ok(())
        } else {
            writer.write_all(b", ")
        }
    }

    fn begin_object_value<W: ?Sized + io::Write>(&mut self, writer: &mut W) -> io::Result<()> {
        writer.write_all(b": ")
    }

    fn write_string_fragment<W: ?Sized + io::Write>(
        &mut self,
        writer: &mut W,
        fragment: &str,
    ) -> io::Result<()> {
        for c in fragment.chars() {
            if c.is_ascii() {
                writer.write_all(&[c as u8])?;
            } else {
                let mut units = [0u16; 2];
                for unit in c.encode_utf16(&mut units) {
                    write!(writer, "\\u{unit:04x}")?;
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::super::description::IndividualTypeDescription;
    use super::super::description::{FieldDescription, FieldTypeDescription};
    use super::*;

    fn one_field(type_name: &str, field: &str) -> TypeDescription {
        TypeDescription {
            type_description: IndividualTypeDescription {
                type_name: type_name.into(),
                fields: vec![FieldDescription {
                    name: field.into(),
                    field_type: FieldTypeDescription {
                        type_id: 17,
                        capacity: 0,
                        string_capacity: 0,
                        nested_type_name: String::new(),
                    },
                }],
            },
            referenced_type_descriptions: vec![],
        }
    }

    /// std_msgs/msg/String's hash as ROS 2 publishes it (on the rmw_zenoh wire of
    /// every `chatter` demo): `string data`.
    #[test]
    fn std_msgs_string_hashes_as_in_ros() {
        let description = one_field("std_msgs/msg/String", "data");
        assert_eq!(
            hashed_json(&description),
            r#"{"type_description": {"type_name": "std_msgs/msg/String", "fields": [{"name": "data", "type": {"type_id": 17, "capacity": 0, "string_capacity": 0, "nested_type_name": ""}}]}, "referenced_type_descriptions": []}"#
        );
        assert_eq!(
            TypeHash::of(&description).to_string(),
            "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
        );
    }

    #[test]
    fn non_ascii_is_escaped_as_python_does() {
        let json = hashed_json(&one_field("a/msg/B", "é😀"));
        assert!(json.contains(r#""name": "\u00e9\ud83d\ude00""#), "{json}");
    }
}
