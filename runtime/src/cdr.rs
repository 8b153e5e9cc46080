//! CDR, the encoding of ROS 2 messages: any serde type to bytes and back, as
//! ROS 2 puts them on the wire (XCDR1, little endian, after the 4-byte encapsulation
//! header `00 01 00 00`).
//!
//! A struct is its fields in order; a fixed array (`[T; N]`, a serde tuple) its
//! elements without a length; a sequence (`Vec<T>`) a `u32` count and its elements; a
//! string a `u32` length counting a NUL terminator, its UTF-8 bytes and the NUL. Each
//! primitive is aligned to its size, counted from the end of the header. The encoding
//! of each value is `cdr-encoding`'s; this module adds the header and strict decoding.
//!
//! Decoding is strict: the header must say CDR little endian (`00 01`; its two option
//! bytes are not read), every string must end with its NUL and be UTF-8, every `bool`
//! is 0 or 1, and the bytes after the message are at most its padding to a multiple
//! of 4 (which some writers add); anything else is a [`CdrError`].
//!
//! ```
//! #[derive(Debug, PartialEq, serde::Serialize, serde::Deserialize)]
//! struct Time {
//!     sec: i32,
//!     nanosec: u32,
//! }
//! let bytes = coolbot::cdr::to_vec(&Time { sec: 1, nanosec: 2 }).unwrap();
//! assert_eq!(bytes, [0, 1, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0]);
//! assert_eq!(coolbot::cdr::from_slice::<Time>(&bytes).unwrap(), Time { sec: 1, nanosec: 2 });
//! ```

use std::fmt;

use byteorder::LittleEndian;
use cdr_encoding::CdrDeserializer;
use serde::de::{
    self, DeserializeSeed, Deserializer, EnumAccess, MapAccess, SeqAccess, VariantAccess, Visitor,
};
use serde::{Deserialize, Serialize};

/// The encapsulation header of CDR little endian: representation `00 01`, options `00 00`.
pub const HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// Why bytes are not a CDR message of the type asked for, or a value cannot be encoded.
#[derive(Debug, thiserror::Error)]
pub enum CdrError {
    /// Fewer bytes than the encapsulation header.
    #[error("{len} bytes are too few for a CDR message (its header alone is 4)")]
    Truncated {
        /// How many bytes there were.
        len: usize,
    },
    /// The header names another representation than CDR little endian.
    #[error(
        "the encapsulation header starts {:02x} {:02x}, not 00 01 (CDR little endian)",
        .found[0],
        .found[1]
    )]
    Encapsulation {
        /// The header's first two bytes.
        found: [u8; 2],
    },
    /// Bytes follow the message beyond its padding to a multiple of 4.
    #[error("{trailing} bytes follow a message of {used} bytes, more than its padding to 4")]
    Trailing {
        /// The message's length after the header.
        used: usize,
        /// How many bytes follow it.
        trailing: usize,
    },
    /// The bytes after the header are not a message of the type.
    #[error("the bytes are not a CDR message of this type")]
    Decode(#[source] cdr_encoding::Error),
    /// The value cannot be encoded (a serde sequence of unknown length, or a custom
    /// `Serialize` that failed).
    #[error("the value cannot be encoded as CDR")]
    Encode(#[source] cdr_encoding::Error),
}

/// Encodes `value`: the header, then its CDR bytes (no padding after them).
pub fn to_vec<T: Serialize>(value: &T) -> Result<Vec<u8>, CdrError> {
    let mut bytes = Vec::with_capacity(64);
    bytes.extend_from_slice(&HEADER);
    cdr_encoding::to_writer::<T, LittleEndian, _>(&mut bytes, value).map_err(CdrError::Encode)?;
    Ok(bytes)
}

/// Decodes a message of type `T`, strictly (see the module's documentation).
pub fn from_slice<'de, T: Deserialize<'de>>(bytes: &'de [u8]) -> Result<T, CdrError> {
    let Some((header, body)) = bytes.split_first_chunk::<4>() else {
        return Err(CdrError::Truncated { len: bytes.len() });
    };
    if header[..2] != HEADER[..2] {
        return Err(CdrError::Encapsulation {
            found: [header[0], header[1]],
        });
    }
    let mut deserializer = CdrDeserializer::<LittleEndian>::new(body);
    let value = T::deserialize(Strict(&mut deserializer)).map_err(CdrError::Decode)?;
    let used = deserializer.bytes_consumed();
    let trailing = body.len() - used;
    if used + trailing > used.next_multiple_of(4) {
        return Err(CdrError::Trailing { used, trailing });
    }
    Ok(value)
}

// `cdr-encoding` reads a string whose last byte is not NUL by dropping that byte (it
// only logs it). `Strict` wraps its deserializer so that strings are read as their
// bytes instead (the same layout: a u32 length, then that many bytes) and checked
// here; everything else goes to it unchanged, through wrappers that keep nested
// values strict too.

/// A deserializer whose strings must end with NUL.
struct Strict<D>(D);

/// A visitor, or an access to a sequence, map or enum, whose nested values are read
/// through [`Strict`].
struct Nested<T>(T);

/// A string's visitor, given the string's bytes with their NUL.
struct Terminated<V>(V);

macro_rules! forward_deserialize {
    ($($method:ident)*) => {$(
        fn $method<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, D::Error> {
            self.0.$method(Nested(visitor))
        }
    )*};
}

impl<'de, D: Deserializer<'de>> Deserializer<'de> for Strict<D> {
    type Error = D::Error;

    forward_deserialize! {
        deserialize_any deserialize_bool deserialize_i8 deserialize_i16 deserialize_i32
        deserialize_i64 deserialize_i128 deserialize_u8 deserialize_u16 deserialize_u32
        deserialize_u64 deserialize_u128 deserialize_f32 deserialize_f64 deserialize_char
        deserialize_bytes deserialize_byte_buf deserialize_option deserialize_unit
        deserialize_seq deserialize_map deserialize_identifier deserialize_ignored_any
    }

    fn deserialize_str<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, D::Error> {
        self.0.deserialize_bytes(Terminated(visitor))
    }

    fn deserialize_string<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, D::Error> {
        self.0.deserialize_bytes(Terminated(visitor))
    }

    fn deserialize_unit_struct<V: Visitor<'de>>(
        self,
        name: &'static str,
        visitor: V,
    ) -> Result<V::Value, D::Error> {
        self.0.deserialize_unit_struct(name, Nested(visitor))
    }

    fn deserialize_newtype_struct<V: Visitor<'de>>(
        self,
        name: &'static str,
        visitor: V,
    ) -> Result<V::Value, D::Error> {
        self.0.deserialize_newtype_struct(name, Nested(visitor))
    }

    fn deserialize_tuple<V: Visitor<'de>>(
        self,
        len: usize,
        visitor: V,
    ) -> Result<V::Value, D::Error> {
        self.0.deserialize_tuple(len, Nested(visitor))
    }

    fn deserialize_tuple_struct<V: Visitor<'de>>(
        self,
        name: &'static str,
        len: usize,
        visitor: V,
    ) -> Result<V::Value, D::Error> {
        self.0.deserialize_tuple_struct(name, len, Nested(visitor))
    }

    fn deserialize_struct<V: Visitor<'de>>(
        self,
        name: &'static str,
        fields: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, D::Error> {
        self.0.deserialize_struct(name, fields, Nested(visitor))
    }

    fn deserialize_enum<V: Visitor<'de>>(
        self,
        name: &'static str,
        variants: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, D::Error> {
        self.0.deserialize_enum(name, variants, Nested(visitor))
    }

    fn is_human_readable(&self) -> bool {
        self.0.is_human_readable()
    }
}

macro_rules! forward_visit {
    ($($method:ident: $ty:ty)*) => {$(
        fn $method<E: de::Error>(self, value: $ty) -> Result<V::Value, E> {
            self.0.$method(value)
        }
    )*};
}

impl<'de, V: Visitor<'de>> Visitor<'de> for Nested<V> {
    type Value = V::Value;

    fn expecting(&self, formatter: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.0.expecting(formatter)
    }

    forward_visit! {
        visit_bool: bool visit_i8: i8 visit_i16: i16 visit_i32: i32 visit_i64: i64
        visit_i128: i128 visit_u8: u8 visit_u16: u16 visit_u32: u32 visit_u64: u64
        visit_u128: u128 visit_f32: f32 visit_f64: f64 visit_char: char
        visit_str: &str visit_borrowed_str: &'de str visit_string: String
        visit_bytes: &[u8] visit_borrowed_bytes: &'de [u8] visit_byte_buf: Vec<u8>
    }

    fn visit_none<E: de::Error>(self) -> Result<V::Value, E> {
        self.0.visit_none()
    }

    fn visit_unit<E: de::Error>(self) -> Result<V::Value, E> {
        self.0.visit_unit()
    }

    fn visit_some<D: Deserializer<'de>>(self, deserializer: D) -> Result<V::Value, D::Error> {
        self.0.visit_some(Strict(deserializer))
    }

    fn visit_newtype_struct<D: Deserializer<'de>>(
        self,
        deserializer: D,
    ) -> Result<V::Value, D::Error> {
        self.0.visit_newtype_struct(Strict(deserializer))
    }

    fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<V::Value, A::Error> {
        self.0.visit_seq(Nested(seq))
    }

    fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<V::Value, A::Error> {
        self.0.visit_map(Nested(map))
    }

    fn visit_enum<A: EnumAccess<'de>>(self, data: A) -> Result<V::Value, A::Error> {
        self.0.visit_enum(Nested(data))
    }
}

/// A seed whose value is read through [`Strict`].
struct Seed<S>(S);

impl<'de, S: DeserializeSeed<'de>> DeserializeSeed<'de> for Seed<S> {
    type Value = S::Value;

    fn deserialize<D: Deserializer<'de>>(self, deserializer: D) -> Result<S::Value, D::Error> {
        self.0.deserialize(Strict(deserializer))
    }
}

impl<'de, A: SeqAccess<'de>> SeqAccess<'de> for Nested<A> {
    type Error = A::Error;

    fn next_element_seed<T: DeserializeSeed<'de>>(
        &mut self,
        seed: T,
    ) -> Result<Option<T::Value>, A::Error> {
        self.0.next_element_seed(Seed(seed))
    }

    fn size_hint(&self) -> Option<usize> {
        self.0.size_hint()
    }
}

impl<'de, A: MapAccess<'de>> MapAccess<'de> for Nested<A> {
    type Error = A::Error;

    fn next_key_seed<K: DeserializeSeed<'de>>(
        &mut self,
        seed: K,
    ) -> Result<Option<K::Value>, A::Error> {
        self.0.next_key_seed(Seed(seed))
    }

    fn next_value_seed<T: DeserializeSeed<'de>>(&mut self, seed: T) -> Result<T::Value, A::Error> {
        self.0.next_value_seed(Seed(seed))
    }

    fn size_hint(&self) -> Option<usize> {
        self.0.size_hint()
    }
}

impl<'de, A: EnumAccess<'de>> EnumAccess<'de> for Nested<A> {
    type Error = A::Error;
    type Variant = Nested<A::Variant>;

    fn variant_seed<T: DeserializeSeed<'de>>(
        self,
        seed: T,
    ) -> Result<(T::Value, Self::Variant), A::Error> {
        let (value, variant) = self.0.variant_seed(Seed(seed))?;
        Ok((value, Nested(variant)))
    }
}

impl<'de, A: VariantAccess<'de>> VariantAccess<'de> for Nested<A> {
    type Error = A::Error;

    fn unit_variant(self) -> Result<(), A::Error> {
        self.0.unit_variant()
    }

    fn newtype_variant_seed<T: DeserializeSeed<'de>>(self, seed: T) -> Result<T::Value, A::Error> {
        self.0.newtype_variant_seed(Seed(seed))
    }

    fn tuple_variant<V: Visitor<'de>>(self, len: usize, visitor: V) -> Result<V::Value, A::Error> {
        self.0.tuple_variant(len, Nested(visitor))
    }

    fn struct_variant<V: Visitor<'de>>(
        self,
        fields: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, A::Error> {
        self.0.struct_variant(fields, Nested(visitor))
    }
}

impl<V> Terminated<V> {
    /// The text of a string's bytes: they end with one NUL, and are UTF-8 before it.
    fn text<E: de::Error>(bytes: &[u8]) -> Result<&str, E> {
        let Some((0, text)) = bytes.split_last() else {
            return Err(E::custom(format_args!(
                "a string of {} bytes does not end with its NUL terminator",
                bytes.len()
            )));
        };
        std::str::from_utf8(text)
            .map_err(|error| E::custom(format_args!("a string is not UTF-8: {error}")))
    }
}

impl<'de, V: Visitor<'de>> Visitor<'de> for Terminated<V> {
    type Value = V::Value;

    fn expecting(&self, formatter: &mut fmt::Formatter<'_>) -> fmt::Result {
        formatter.write_str("a string's bytes and its NUL terminator")
    }

    fn visit_borrowed_bytes<E: de::Error>(self, bytes: &'de [u8]) -> Result<V::Value, E> {
        self.0.visit_borrowed_str(Self::text(bytes)?)
    }

    fn visit_bytes<E: de::Error>(self, bytes: &[u8]) -> Result<V::Value, E> {
        self.0.visit_str(Self::text(bytes)?)
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Mixed {
        flag: bool,
        wide: f64,
        name: String,
        small: u8,
        values: Vec<i16>,
        fixed: [u32; 2],
        nested: Vec<Named>,
    }

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Named {
        id: u8,
        label: String,
    }

    fn mixed() -> Mixed {
        Mixed {
            flag: true,
            wide: 0.5,
            name: "ab".into(),
            small: 7,
            values: vec![-1, 2],
            fixed: [3, 4],
            nested: vec![Named {
                id: 9,
                label: String::new(),
            }],
        }
    }

    #[rustfmt::skip]
    const MIXED: &[u8] = &[
        0, 1, 0, 0,                           // header
        1, 0, 0, 0, 0, 0, 0, 0,               // flag, padding to 8
        0, 0, 0, 0, 0, 0, 0xe0, 0x3f,         // wide = 0.5
        3, 0, 0, 0, b'a', b'b', 0,            // name: length 3 with the NUL
        7,                                    // small
        2, 0, 0, 0, 0xff, 0xff, 2, 0,         // values: count, -1, 2
        3, 0, 0, 0, 4, 0, 0, 0,               // fixed: no count
        1, 0, 0, 0, 9, 0, 0, 0, 1, 0, 0, 0, 0, // nested: count, id, padding, label ""
    ];

    #[test]
    fn values_are_laid_out_as_cdr_with_alignment_from_the_header() {
        assert_eq!(to_vec(&mixed()).unwrap(), MIXED);
        assert_eq!(from_slice::<Mixed>(MIXED).unwrap(), mixed());
    }

    #[test]
    fn padding_to_four_may_follow_a_message_and_nothing_more() {
        let mut bytes = MIXED.to_vec();
        assert_eq!((bytes.len() - 4) % 4, 1);
        bytes.extend([0, 0, 0]);
        assert_eq!(from_slice::<Mixed>(&bytes).unwrap(), mixed());
        bytes.push(0);
        assert!(matches!(
            from_slice::<Mixed>(&bytes),
            Err(CdrError::Trailing {
                used: 53,
                trailing: 4
            })
        ));
        let time = to_vec(&(1i32, 2u32)).unwrap();
        let mut padded = time.clone();
        padded.push(0);
        assert!(matches!(
            from_slice::<(i32, u32)>(&padded),
            Err(CdrError::Trailing {
                used: 8,
                trailing: 1
            })
        ));
    }

    #[test]
    fn a_bad_or_short_header_is_refused() {
        let mut bytes = MIXED.to_vec();
        bytes[1] = 0;
        assert!(matches!(
            from_slice::<Mixed>(&bytes),
            Err(CdrError::Encapsulation { found: [0, 0] })
        ));
        assert!(matches!(
            from_slice::<Mixed>(&MIXED[..3]),
            Err(CdrError::Truncated { len: 3 })
        ));
        let mut options = MIXED.to_vec();
        options[3] = 3;
        assert_eq!(from_slice::<Mixed>(&options).unwrap(), mixed());
    }

    fn decode_error<T: for<'de> Deserialize<'de> + fmt::Debug>(bytes: &[u8]) -> String {
        match from_slice::<T>(bytes) {
            Err(CdrError::Decode(source)) => source.to_string(),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn strings_must_end_with_nul_and_be_utf8() {
        // "ab" with a length of 2 and no NUL.
        let unterminated = [0, 1, 0, 0, 2, 0, 0, 0, b'a', b'b'];
        assert_eq!(
            decode_error::<String>(&unterminated),
            "a string of 2 bytes does not end with its NUL terminator"
        );
        let empty = [0, 1, 0, 0, 0, 0, 0, 0];
        assert_eq!(
            decode_error::<String>(&empty),
            "a string of 0 bytes does not end with its NUL terminator"
        );
        let latin1 = [0, 1, 0, 0, 2, 0, 0, 0, 0xe9, 0];
        assert!(decode_error::<String>(&latin1).starts_with("a string is not UTF-8"));
        // Nested: a string inside a sequence of structs.
        let mut nested = MIXED.to_vec();
        *nested.last_mut().unwrap() = b'x';
        assert!(decode_error::<Mixed>(&nested).contains("NUL terminator"));
        assert_eq!(from_slice::<String>(&to_vec(&"é").unwrap()).unwrap(), "é");
    }

    #[test]
    fn a_truncated_message_or_a_bad_bool_is_refused() {
        assert_eq!(
            decode_error::<Mixed>(&MIXED[..MIXED.len() - 1]),
            "unexpected end of input"
        );
        let mut bad_bool = MIXED.to_vec();
        bad_bool[4] = 2;
        assert!(decode_error::<Mixed>(&bad_bool).contains("Boolean"));
    }

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    enum Shape {
        Empty,
        Circle(f32),
        Rect { w: u16, h: u16 },
        Pair(u8, String),
    }

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Meters(f64);

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Every {
        shapes: Vec<Shape>,
        maybe: Option<String>,
        none: Option<u8>,
        map: BTreeMap<String, String>,
        unit: (),
        meters: Meters,
        tuple: (u8, String),
        character: char,
    }

    #[test]
    fn every_serde_shape_round_trips_with_strings_checked_inside_it() {
        let every = Every {
            shapes: vec![
                Shape::Empty,
                Shape::Circle(1.5),
                Shape::Rect { w: 2, h: 3 },
                Shape::Pair(4, "four".into()),
            ],
            maybe: Some("yes".into()),
            none: None,
            map: [("k".to_owned(), "v".to_owned())].into(),
            unit: (),
            meters: Meters(2.5),
            tuple: (5, "five".into()),
            character: 'λ',
        };
        let bytes = to_vec(&every).unwrap();
        assert_eq!(from_slice::<Every>(&bytes).unwrap(), every);
        // Every string of it (in an enum, an option, a map and a tuple) is checked:
        // each one with its NUL changed to `x` is refused.
        for text in ["four", "yes", "k", "v", "five"] {
            let mut needle = text.as_bytes().to_vec();
            needle.push(0);
            let at = bytes
                .windows(needle.len())
                .position(|w| w == needle)
                .unwrap();
            let mut broken = bytes.clone();
            broken[at + text.len()] = b'x';
            assert!(
                decode_error::<Every>(&broken).contains("NUL terminator"),
                "{text}"
            );
        }
    }

    #[test]
    fn a_sequence_of_unknown_length_cannot_be_encoded() {
        struct Unsized;
        impl Serialize for Unsized {
            fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
                serializer.collect_seq((0..3u8).filter(|_| true))
            }
        }
        assert!(matches!(to_vec(&Unsized), Err(CdrError::Encode(_))));
    }
}
