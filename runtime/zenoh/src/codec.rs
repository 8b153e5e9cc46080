//! Postcard on the wire (`docs/distribution.md`, "Serialization"): what a bridge or a
//! ledger sends, and the one strict way to read it back.
//!
//! A payload from the network is decoded only when it is no longer than the bound of
//! what it should be, and it decodes only when the value takes every byte of it: a
//! packet followed by anything else, or the bytes of another type that happen to
//! begin with a valid value, are refused with the reason.

use serde::Serialize;
use serde::de::DeserializeOwned;

/// Why a payload was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub(crate) enum Undecodable {
    /// Longer than the most its port takes: not decoded at all.
    #[error("{len} bytes, more than the {max} a message of this port takes")]
    TooLong {
        /// The payload's length.
        len: usize,
        /// The bound.
        max: usize,
    },
    /// The bytes are not a value of the type.
    #[error("does not decode as {type_name}")]
    Invalid {
        /// The type expected.
        type_name: &'static str,
        /// What postcard found.
        #[source]
        source: postcard::Error,
    },
    /// A value of the type, followed by bytes that are not part of it.
    #[error("{extra} byte(s) after a {type_name}")]
    Trailing {
        /// The type expected.
        type_name: &'static str,
        /// How many bytes were left over.
        extra: usize,
    },
}

/// `value` as postcard bytes.
pub(crate) fn encode<P: Serialize + ?Sized>(value: &P) -> Result<Vec<u8>, postcard::Error> {
    postcard::to_allocvec(value)
}

/// The value of type `T` that is exactly `bytes`, at most `max` of them.
pub(crate) fn decode<T: DeserializeOwned>(bytes: &[u8], max: usize) -> Result<T, Undecodable> {
    if bytes.len() > max {
        return Err(Undecodable::TooLong {
            len: bytes.len(),
            max,
        });
    }
    let type_name = std::any::type_name::<T>();
    let (value, rest) = postcard::take_from_bytes::<T>(bytes)
        .map_err(|source| Undecodable::Invalid { type_name, source })?;
    if !rest.is_empty() {
        return Err(Undecodable::Trailing {
            type_name,
            extra: rest.len(),
        });
    }
    Ok(value)
}

/// [`decode`] of a payload as Zenoh holds it: its length is checked before its
/// bytes are made contiguous (copied, when Zenoh holds them in fragments).
pub(crate) fn decode_payload<T: DeserializeOwned>(
    payload: &zenoh::bytes::ZBytes,
    max: usize,
) -> Result<T, Undecodable> {
    if payload.len() > max {
        return Err(Undecodable::TooLong {
            len: payload.len(),
            max,
        });
    }
    decode(&payload.to_bytes(), max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_value_decodes_from_exactly_its_bytes() {
        let bytes = encode(&(7u64, 1u64, 2.5f64)).unwrap();
        assert_eq!(
            decode::<(u64, u64, f64)>(&bytes, 64),
            Ok((7u64, 1u64, 2.5f64))
        );
    }

    #[test]
    fn trailing_bytes_are_refused() {
        let mut bytes = encode(&(7u64, 1u64, 2.5f64)).unwrap();
        bytes.extend([0, 0, 0]);
        assert!(matches!(
            decode::<(u64, u64, f64)>(&bytes, 64),
            Err(Undecodable::Trailing { extra: 3, .. })
        ));
        // Three floats read as two: the third is left over.
        let three = encode(&(1.0f64, 2.0f64, 3.0f64)).unwrap();
        assert!(matches!(
            decode::<(f64, f64)>(&three, 64),
            Err(Undecodable::Trailing { extra: 8, .. })
        ));
    }

    #[test]
    fn a_payload_over_the_bound_is_not_decoded() {
        let bytes = encode(&vec![0u8; 100]).unwrap();
        assert_eq!(
            decode::<Vec<u8>>(&bytes, 100),
            Err(Undecodable::TooLong { len: 101, max: 100 })
        );
        assert_eq!(decode::<Vec<u8>>(&bytes, 101), Ok(vec![0u8; 100]));
    }

    #[test]
    fn a_payload_in_fragments_is_measured_before_it_is_read() {
        let bytes = encode(&vec![0u8; 100]).unwrap();
        let mut writer = zenoh::bytes::ZBytes::writer();
        for part in bytes.chunks(10) {
            writer.append(zenoh::bytes::ZBytes::from(part.to_vec()));
        }
        let payload = writer.finish();
        assert_eq!(
            decode_payload::<Vec<u8>>(&payload, 100),
            Err(Undecodable::TooLong { len: 101, max: 100 })
        );
        assert_eq!(decode_payload::<Vec<u8>>(&payload, 101), Ok(vec![0u8; 100]));
    }

    #[test]
    fn bytes_that_are_not_a_value_are_refused_with_the_type() {
        let error = decode::<(u64, u64, f64)>(&[1], 64).unwrap_err();
        assert!(matches!(error, Undecodable::Invalid { .. }), "{error:?}");
        assert!(error.to_string().contains("(u64, u64, f64)"), "{error}");
    }
}
