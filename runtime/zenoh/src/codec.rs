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

/// [`decode`] of a message in `parts`, in order (as [`crate::shm`] hands a payload
/// on): each part read where it is when a value's bytes lie within one part (a
/// loaned buffer is one whole part); the parts joined into one copy only when a
/// value's bytes lie across two parts. Bytes that are not a value are read once.
pub(crate) fn decode_parts<T: DeserializeOwned>(
    parts: &[&[u8]],
    max: usize,
) -> Result<T, Undecodable> {
    if let [whole] = parts {
        return decode(whole, max);
    }
    let len: usize = parts.iter().map(|part| part.len()).sum();
    if len > max {
        return Err(Undecodable::TooLong { len, max });
    }
    let mut reader = postcard::Deserializer::from_flavor(Segments {
        parts,
        at: 0,
        across: false,
    });
    let read = T::deserialize(&mut reader);
    let type_name = std::any::type_name::<T>();
    // (The parts' finalize cannot fail.)
    let rest = reader
        .finalize()
        .map_err(|source| Undecodable::Invalid { type_name, source })?;
    // A run of bytes across two parts (fragments of a message) was not read in
    // place: read the whole from one copy (whatever a type's own `Deserialize` made
    // of the failed read).
    if rest.across {
        return decode(&parts.concat(), max);
    }
    match read {
        Ok(value) => match rest.parts.iter().map(|part| part.len()).sum() {
            0 => Ok(value),
            extra => Err(Undecodable::Trailing { type_name, extra }),
        },
        Err(source) => Err(Undecodable::Invalid { type_name, source }),
    }
}

/// A message's parts as postcard reads them: what is left of each part, in order.
struct Segments<'de> {
    parts: &'de [&'de [u8]],
    /// How far into the first part the reading is.
    at: usize,
    /// Whether a run of bytes was asked for that begins in one part and ends in a
    /// later one (read from one copy of the parts instead).
    across: bool,
}

impl<'de> Segments<'de> {
    /// The rest of the current part, past the parts read to their end.
    fn current(&mut self) -> &'de [u8] {
        while let Some((first, rest)) = self.parts.split_first() {
            if self.at < first.len() {
                return &first[self.at..];
            }
            self.parts = rest;
            self.at = 0;
        }
        &[]
    }
}

/// What is left: the parts not read, the first from where the reading stopped.
struct Rest<'de> {
    parts: Vec<&'de [u8]>,
    /// [`Segments::across`].
    across: bool,
}

impl<'de> postcard::de_flavors::Flavor<'de> for Segments<'de> {
    type Remainder = Rest<'de>;
    type Source = &'de [u8];

    fn pop(&mut self) -> postcard::Result<u8> {
        let byte = *self
            .current()
            .first()
            .ok_or(postcard::Error::DeserializeUnexpectedEnd)?;
        self.at += 1;
        Ok(byte)
    }

    fn try_take_n(&mut self, count: usize) -> postcard::Result<&'de [u8]> {
        let current = self.current();
        if count == 0 {
            return Ok(&[]);
        }
        let Some(taken) = current.get(..count) else {
            let later: usize = self.parts.iter().skip(1).map(|part| part.len()).sum();
            self.across |= current.len() + later >= count;
            return Err(postcard::Error::DeserializeUnexpectedEnd);
        };
        self.at += count;
        Ok(taken)
    }

    fn finalize(mut self) -> postcard::Result<Rest<'de>> {
        let first = self.current();
        let mut parts = vec![first];
        parts.extend(self.parts.iter().skip(1).copied());
        Ok(Rest {
            parts,
            across: self.across,
        })
    }
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

    #[test]
    fn a_message_in_parts_decodes_each_part_in_place_or_from_one_copy() {
        #[derive(Debug, PartialEq, serde::Serialize, serde::Deserialize)]
        struct Image {
            number: u64,
            scale: f64,
            pixels: coolbot::Bytes,
            tag: String,
        }
        let image = Image {
            number: 300,
            scale: 0.5,
            pixels: coolbot::Bytes::from(vec![9u8; 64]),
            tag: "rgb".to_owned(),
        };
        let bytes = encode(&image).unwrap();
        // The pixels' bytes are one part: varint 300 (2 bytes), 8 of the scale, the
        // length (1 byte), then 64 pixels, then the tag.
        let (head, rest) = bytes.split_at(11);
        let (pixels, tail) = rest.split_at(64);
        let at = pixels.as_ptr() as usize;
        let parts = vec![
            (head.to_vec(), true),
            (pixels.to_vec(), true),
            (tail.to_vec(), true),
            (Vec::new(), true),
        ];
        let pixels_at = parts[1].0.as_ptr() as usize;
        let (decoded, shared) =
            coolbot::lent::lend_whole(parts, |parts| decode_parts::<Image>(parts, 1024).unwrap());
        assert_eq!(decoded, image);
        assert!(decoded.pixels.is_lent(), "read in its part");
        assert_eq!(decoded.pixels.as_ptr() as usize, pixels_at);
        assert_ne!(at, pixels_at);
        assert_eq!(shared, 1);
        // Cut inside the scale and inside the pixels (fragments): read from one copy.
        for cut in [5, 40] {
            let (first, second) = bytes.split_at(cut);
            let decoded = decode_parts::<Image>(&[first, second], 1024).unwrap();
            assert_eq!(decoded, image, "cut at {cut}");
        }
        // Bounds, leftovers and bytes of another type are refused as from one slice.
        let (first, second) = bytes.split_at(11);
        assert_eq!(
            decode_parts::<Image>(&[first, second], 40),
            Err(Undecodable::TooLong {
                len: bytes.len(),
                max: 40
            })
        );
        let extra = [1u8, 2];
        assert!(matches!(
            decode_parts::<Image>(&[first, second, &extra], 1024),
            Err(Undecodable::Trailing { extra: 2, .. })
        ));
        assert!(matches!(
            decode_parts::<Image>(&[&bytes[..3], &bytes[3..20]], 1024),
            Err(Undecodable::Invalid { .. })
        ));
    }

    #[test]
    fn bytes_in_parts_that_are_not_a_value_are_read_once_and_refused_as_from_one_slice() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        static READS: AtomicUsize = AtomicUsize::new(0);
        /// A `u16` that counts its reads.
        #[derive(Debug, PartialEq)]
        struct Counted(u16);
        impl<'de> serde::Deserialize<'de> for Counted {
            fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
                READS.fetch_add(1, Ordering::Relaxed);
                u16::deserialize(d).map(Counted)
            }
        }
        // A varint that never ends (every byte has its high bit): not a `u16`.
        let bad: [&[u8]; 2] = [&[0xff, 0xff], &[0xff, 0xff]];
        let error = decode_parts::<Counted>(&bad, 64).unwrap_err();
        assert_eq!(READS.load(Ordering::Relaxed), 1, "read once");
        assert_eq!(
            error,
            decode::<Counted>(&bad.concat(), 64).unwrap_err(),
            "the error one slice gives"
        );
        // A value followed by bytes in the next part: refused at once, as leftovers.
        READS.store(0, Ordering::Relaxed);
        assert_eq!(
            decode_parts::<Counted>(&[&[5], &[1, 2]], 64),
            Err(Undecodable::Trailing {
                type_name: std::any::type_name::<Counted>(),
                extra: 2
            })
        );
        assert_eq!(READS.load(Ordering::Relaxed), 1, "read once");
        // A value in two parts whose bytes need no run across them reads in place.
        READS.store(0, Ordering::Relaxed);
        let two: [&[u8]; 2] = [&[0x81], &[0x01]];
        assert_eq!(decode_parts::<Counted>(&two, 64), Ok(Counted(129)));
        assert_eq!(READS.load(Ordering::Relaxed), 1, "read once");
    }
}
