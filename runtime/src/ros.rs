//! ROS 2 message types in Rust: what every type coolc generates for an `import ros`
//! implements ([`RosType`]: its names and type hash, for a topic or a bag to use
//! without coolc at run time), and the serde adapters of its bounded fields
//! ([`Bounded`], [`BoundedString`]), which refuse a value over its bound when it is
//! decoded (`docs/ros2.md`).
//!
//! ```
//! #[derive(Debug, PartialEq, serde::Serialize, serde::Deserialize)]
//! struct Tags {
//!     #[serde(with = "coolbot::serde_with::As::<coolbot::ros::Bounded<2>>")]
//!     ids: Vec<u8>,
//!     #[serde(with = "coolbot::serde_with::As::<coolbot::ros::BoundedString<4>>")]
//!     label: String,
//! }
//! let fits = Tags { ids: vec![1, 2], label: "four".into() };
//! let bytes = coolbot::cdr::to_vec(&fits).unwrap();
//! assert_eq!(coolbot::cdr::from_slice::<Tags>(&bytes).unwrap(), fits);
//!
//! // Encoding does not check the bounds; decoding does.
//! let over = Tags { ids: vec![1, 2, 3], label: "four".into() };
//! let bytes = coolbot::cdr::to_vec(&over).unwrap();
//! assert!(coolbot::cdr::from_slice::<Tags>(&bytes).is_err());
//! ```

use std::fmt;
use std::marker::PhantomData;

use serde::de::{self, Deserialize, Deserializer, SeqAccess, Visitor};
use serde::{Serialize, Serializer};
use serde_with::de::DeserializeAsWrap;
use serde_with::ser::SerializeAsWrap;
use serde_with::{DeserializeAs, Same, SerializeAs};

/// A ROS 2 message type: its names and its type hash, as coolc computed them from its
/// `.msg` file.
pub trait RosType {
    /// The type's name: `sensor_msgs/msg/LaserScan`.
    const NAME: &'static str;
    /// Its DDS type name, which rmw implementations put on the wire:
    /// `sensor_msgs::msg::dds_::LaserScan_`.
    const DDS_NAME: &'static str;
    /// Its RIHS01 type hash (REP-2016): `RIHS01_` and 64 lowercase hex digits.
    const TYPE_HASH: &'static str;
    /// Its full message definition as a rosbag2 bag holds it (the schema of encoding
    /// `ros2msg`): its `.msg` text, then for each type it references, directly or
    /// not, a line of 80 `=`, a line `MSG: pkg/Type` and that type's `.msg` text.
    const MESSAGE_DEFINITION: &'static str;
}

/// The serde adapter of a bounded sequence (`.msg` `T[<=N]`, a `Vec<T>`): at most `N`
/// elements, each through the adapter `A`. Decoding a longer sequence is an error;
/// encoding writes what it is given.
pub struct Bounded<const N: usize, A = Same>(PhantomData<A>);

impl<T, A: SerializeAs<T>, const N: usize> SerializeAs<Vec<T>> for Bounded<N, A> {
    fn serialize_as<S: Serializer>(source: &Vec<T>, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_seq(source.iter().map(SerializeAsWrap::<T, A>::new))
    }
}

impl<'de, T, A: DeserializeAs<'de, T>, const N: usize> DeserializeAs<'de, Vec<T>>
    for Bounded<N, A>
{
    fn deserialize_as<D: Deserializer<'de>>(deserializer: D) -> Result<Vec<T>, D::Error> {
        deserializer.deserialize_seq(BoundedVisitor::<T, A, N>(PhantomData))
    }
}

struct BoundedVisitor<T, A, const N: usize>(PhantomData<(T, A)>);

impl<'de, T, A: DeserializeAs<'de, T>, const N: usize> Visitor<'de> for BoundedVisitor<T, A, N> {
    type Value = Vec<T>;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "a sequence of at most {N} elements")
    }

    fn visit_seq<S: SeqAccess<'de>>(self, mut seq: S) -> Result<Vec<T>, S::Error> {
        if let Some(len) = seq.size_hint().filter(|len| *len > N) {
            return Err(de::Error::invalid_length(len, &self));
        }
        // Room for what the input announces, within the bound and within a cautious
        // amount of memory: the announcement is the sender's.
        let cautious = (1 << 20) / size_of::<T>().max(1);
        let mut items = Vec::with_capacity(seq.size_hint().unwrap_or(0).min(N).min(cautious));
        while let Some(item) = seq.next_element::<DeserializeAsWrap<T, A>>()? {
            if items.len() == N {
                return Err(de::Error::custom(format_args!(
                    "more than {N} elements, expected a sequence of at most {N} elements"
                )));
            }
            items.push(item.into_inner());
        }
        Ok(items)
    }
}

/// The serde adapter of a bounded string (`.msg` `string<=N`, a `String`): at most `N`
/// bytes, as ROS 2 bounds a `string` (a `char` is a byte). Decoding a longer string is
/// an error; encoding writes what it is given.
pub struct BoundedString<const N: usize>;

impl<const N: usize> SerializeAs<String> for BoundedString<N> {
    fn serialize_as<S: Serializer>(source: &String, serializer: S) -> Result<S::Ok, S::Error> {
        source.serialize(serializer)
    }
}

impl<'de, const N: usize> DeserializeAs<'de, String> for BoundedString<N> {
    fn deserialize_as<D: Deserializer<'de>>(deserializer: D) -> Result<String, D::Error> {
        let text = String::deserialize(deserializer)?;
        if text.len() > N {
            return Err(de::Error::invalid_length(
                text.len(),
                &format!("a string of at most {N} bytes").as_str(),
            ));
        }
        Ok(text)
    }
}

#[cfg(test)]
mod tests {
    use serde::{Deserialize, Serialize};
    use serde_with::As;

    use super::*;
    use crate::cdr::{self, CdrError};

    #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
    struct Bounds {
        #[serde(with = "As::<Bounded<3>>")]
        few: Vec<i32>,
        #[serde(with = "As::<BoundedString<4>>")]
        label: String,
        #[serde(with = "As::<Bounded<2, BoundedString<3>>>")]
        tags: Vec<String>,
        #[serde(with = "As::<[BoundedString<2>; 2]>")]
        pair: [String; 2],
    }

    fn fits() -> Bounds {
        Bounds {
            few: vec![1, 2, 3],
            label: "ça!".into(),
            tags: vec!["abc".into(), String::new()],
            pair: ["ab".into(), "c".into()],
        }
    }

    /// The reason a decode failed, with its sources.
    fn reason(error: &CdrError) -> String {
        let mut text = error.to_string();
        let mut source = std::error::Error::source(error);
        while let Some(next) = source {
            text.push_str(&format!(": {next}"));
            source = next.source();
        }
        text
    }

    #[test]
    fn values_within_their_bounds_round_trip_as_plain_fields_would() {
        #[derive(Serialize)]
        struct Plain {
            few: Vec<i32>,
            label: String,
            tags: Vec<String>,
            pair: [String; 2],
        }
        let value = fits();
        let bytes = cdr::to_vec(&value).unwrap();
        let plain = Plain {
            few: value.few.clone(),
            label: value.label.clone(),
            tags: value.tags.clone(),
            pair: value.pair.clone(),
        };
        assert_eq!(bytes, cdr::to_vec(&plain).unwrap());
        assert_eq!(cdr::from_slice::<Bounds>(&bytes).unwrap(), value);
        let json = serde_json::to_string(&value).unwrap();
        assert_eq!(serde_json::from_str::<Bounds>(&json).unwrap(), value);
    }

    #[test]
    fn a_value_over_its_bound_is_refused_when_decoded() {
        type Change = fn(&mut Bounds);
        let cases: [(Change, &str); 4] = [
            (
                |b| b.few.push(4),
                "expected a sequence of at most 3 elements",
            ),
            (
                |b| b.label.push('x'),
                "invalid length 5, expected a string of at most 4 bytes",
            ),
            (
                |b| b.tags[1] = "abcd".into(),
                "invalid length 4, expected a string of at most 3 bytes",
            ),
            (
                |b| b.pair[0] = "abc".into(),
                "invalid length 3, expected a string of at most 2 bytes",
            ),
        ];
        for (change, expected) in cases {
            let mut value = fits();
            change(&mut value);
            let bytes = cdr::to_vec(&value).unwrap();
            let error = cdr::from_slice::<Bounds>(&bytes).unwrap_err();
            assert!(reason(&error).contains(expected), "{}", reason(&error));
            let json = serde_json::to_string(&value).unwrap();
            let error = serde_json::from_str::<Bounds>(&json).unwrap_err();
            assert!(error.to_string().contains(expected), "{error}");
        }
    }

    #[test]
    fn a_type_with_bounds_has_the_schema_of_its_plain_fields() {
        // What a recording of a port carrying it writes (`crate::record`).
        let schema = crate::schema::of::<Bounds>();
        assert_eq!(schema.derived, "traced");
        let properties = &schema.schema["properties"];
        assert_eq!(properties["few"]["type"], "array");
        assert_eq!(properties["label"]["type"], "string");
        assert_eq!(properties["tags"]["items"]["type"], "string");
        assert_eq!(properties["pair"]["type"], "array");
    }

    #[test]
    fn a_sequence_of_unknown_length_is_cut_at_its_bound() {
        struct Stream;
        impl<'de> Deserializer<'de> for Stream {
            type Error = de::value::Error;
            fn deserialize_any<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, Self::Error> {
                visitor.visit_seq(de::value::SeqDeserializer::new(
                    (0..).take(5).filter(|_| true),
                ))
            }
            serde::forward_to_deserialize_any! {
                bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string
                bytes byte_buf option unit unit_struct newtype_struct seq tuple
                tuple_struct map struct enum identifier ignored_any
            }
        }
        let error =
            <Bounded<3> as DeserializeAs<'_, Vec<i32>>>::deserialize_as(Stream).unwrap_err();
        assert_eq!(
            error.to_string(),
            "more than 3 elements, expected a sequence of at most 3 elements"
        );
    }
}
