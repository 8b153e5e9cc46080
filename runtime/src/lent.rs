//! [`Bytes`]: a packet's bytes that a receiver can read where they arrived, and
//! [`lend`], which lends a message's memory to its decoding.
//!
//! A `Vec<u8>` in a packet is the receiver's own copy: a bridge decodes each message
//! into new memory. A [`Bytes`] field decodes without a copy when the message's memory
//! is lent while it is decoded ([`lend`]): the field then shares that memory (for a
//! bridge between two processes on one host, the sender's buffer of shared memory) and
//! keeps it alive as long as a clone of the packet lives. Anywhere else (no lender, or
//! bytes outside the lent memory: JSON, a value, a recording) it decodes into memory
//! of its own, as a `Vec<u8>` would.
//!
//! Serialized, it is the same as a `Vec<u8>` written as one slice (`serialize_bytes`:
//! postcard and CDR a length and the bytes, JSON an array of numbers), so a `[u8]`
//! field and a `Bytes` field are the same message.

use std::cell::RefCell;
use std::fmt;
use std::ops::Deref;

use serde::de::{self, Visitor};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// Bytes that a clone shares rather than copies; decoded in place from lent memory
/// (module docs). Reads as a `[u8]`; compares by its bytes.
#[derive(Clone, Default)]
pub struct Bytes {
    data: ::bytes::Bytes,
    /// Decoded in place from lent memory.
    lent: bool,
}

impl Bytes {
    /// Empty bytes.
    pub const fn new() -> Bytes {
        Bytes {
            data: ::bytes::Bytes::new(),
            lent: false,
        }
    }

    /// Whether these bytes were decoded in place, in memory lent to their decoding
    /// ([`lend`]), rather than copied into memory of their own.
    pub fn is_lent(&self) -> bool {
        self.lent
    }

    /// The bytes as a vector of their own (a copy).
    pub fn to_vec(&self) -> Vec<u8> {
        self.data.to_vec()
    }
}

impl PartialEq for Bytes {
    fn eq(&self, other: &Bytes) -> bool {
        self.data == other.data
    }
}

impl Eq for Bytes {}

impl std::hash::Hash for Bytes {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        self.data.hash(state);
    }
}

impl Deref for Bytes {
    type Target = [u8];

    fn deref(&self) -> &[u8] {
        &self.data
    }
}

impl AsRef<[u8]> for Bytes {
    fn as_ref(&self) -> &[u8] {
        &self.data
    }
}

impl From<Vec<u8>> for Bytes {
    fn from(bytes: Vec<u8>) -> Bytes {
        Bytes {
            data: bytes.into(),
            lent: false,
        }
    }
}

impl From<&'static [u8]> for Bytes {
    fn from(bytes: &'static [u8]) -> Bytes {
        Bytes {
            data: ::bytes::Bytes::from_static(bytes),
            lent: false,
        }
    }
}

impl fmt::Debug for Bytes {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Bytes({} bytes)", self.data.len())
    }
}

thread_local! {
    /// The memory lent on this thread, innermost last.
    static LENT: RefCell<Vec<::bytes::Bytes>> = const { RefCell::new(Vec::new()) };
}

/// Whether `part` lies within `whole`'s memory.
fn contains(whole: &::bytes::Bytes, part: &[u8]) -> bool {
    let (start, end) = (
        whole.as_ptr() as usize,
        whole.as_ptr() as usize + whole.len(),
    );
    let (from, to) = (part.as_ptr() as usize, part.as_ptr() as usize + part.len());
    !part.is_empty() && start <= from && to <= end
}

/// Calls `read` with `owner`'s bytes, lent: a [`Bytes`] decoded from them meanwhile
/// on this thread shares `owner` (kept alive by it) instead of copying.
pub fn lend<O, R>(owner: O, read: impl FnOnce(&[u8]) -> R) -> R
where
    O: AsRef<[u8]> + Send + 'static,
{
    let whole = ::bytes::Bytes::from_owner(owner);
    LENT.with(|lent| lent.borrow_mut().push(whole.clone()));
    // Taken off again even if `read` panics.
    struct Return;
    impl Drop for Return {
        fn drop(&mut self) {
            LENT.with(|lent| {
                lent.borrow_mut().pop();
            });
        }
    }
    let _return = Return;
    read(&whole)
}

/// The lent memory holding `part`, sliced to it, if any.
fn lent_slice(part: &[u8]) -> Option<::bytes::Bytes> {
    LENT.with(|lent| {
        lent.borrow()
            .iter()
            .rev()
            .find(|whole| contains(whole, part))
            .map(|whole| whole.slice_ref(part))
    })
}

impl Serialize for Bytes {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_bytes(&self.data)
    }
}

impl<'de> Deserialize<'de> for Bytes {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Bytes, D::Error> {
        deserializer.deserialize_bytes(BytesVisitor)
    }
}

struct BytesVisitor;

impl<'de> Visitor<'de> for BytesVisitor {
    type Value = Bytes;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("bytes")
    }

    fn visit_borrowed_bytes<E: de::Error>(self, bytes: &'de [u8]) -> Result<Bytes, E> {
        Ok(match lent_slice(bytes) {
            Some(data) => Bytes { data, lent: true },
            None => Bytes::from(bytes.to_vec()),
        })
    }

    fn visit_bytes<E: de::Error>(self, bytes: &[u8]) -> Result<Bytes, E> {
        Ok(Bytes::from(bytes.to_vec()))
    }

    fn visit_byte_buf<E: de::Error>(self, bytes: Vec<u8>) -> Result<Bytes, E> {
        Ok(Bytes::from(bytes))
    }

    /// A string, as its UTF-8 bytes (as a `[u8]` field reads one).
    fn visit_str<E: de::Error>(self, text: &str) -> Result<Bytes, E> {
        Ok(Bytes::from(text.as_bytes().to_vec()))
    }

    fn visit_string<E: de::Error>(self, text: String) -> Result<Bytes, E> {
        Ok(Bytes::from(text.into_bytes()))
    }

    fn visit_seq<A: de::SeqAccess<'de>>(self, mut seq: A) -> Result<Bytes, A::Error> {
        let mut bytes = Vec::with_capacity(seq.size_hint().unwrap_or(0).min(1 << 16));
        while let Some(byte) = seq.next_element::<u8>()? {
            bytes.push(byte);
        }
        Ok(Bytes::from(bytes))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Frame {
        number: u64,
        pixels: Bytes,
    }

    fn encoded() -> Vec<u8> {
        let frame = Frame {
            number: 7,
            pixels: Bytes::from(vec![1, 2, 3, 250]),
        };
        let bytes = postcard::to_allocvec(&frame).unwrap();
        // The same message as a `Vec<u8>` written as one slice.
        assert_eq!(
            bytes,
            postcard::to_allocvec(&(7u64, serde_bytes_like(&[1, 2, 3, 250]))).unwrap()
        );
        bytes
    }

    /// `bytes` serialized as one slice.
    fn serde_bytes_like(bytes: &[u8]) -> impl Serialize + '_ {
        struct Slice<'a>(&'a [u8]);
        impl Serialize for Slice<'_> {
            fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
                serializer.serialize_bytes(self.0)
            }
        }
        Slice(bytes)
    }

    #[test]
    fn bytes_decoded_from_lent_memory_share_it_and_keep_it_alive() {
        let message = encoded();
        let start = message.as_ptr() as usize;
        let end = start + message.len();
        let frame: Frame = lend(message, |bytes| postcard::from_bytes(bytes).unwrap());
        assert_eq!(&*frame.pixels, &[1, 2, 3, 250]);
        assert!(frame.pixels.is_lent());
        // In the lent message's memory (the message is gone from here: the frame keeps
        // it alive).
        let at = frame.pixels.as_ptr() as usize;
        assert!(start <= at && at + 4 <= end);
        let clone = frame.pixels.clone();
        drop(frame);
        assert_eq!(&*clone, &[1, 2, 3, 250]);
    }

    #[test]
    fn bytes_decoded_without_a_lender_or_outside_it_are_copied() {
        let message = encoded();
        let frame: Frame = postcard::from_bytes(&message).unwrap();
        assert!(!frame.pixels.is_lent());
        // Lent memory other than the message's: copied.
        let frame: Frame = lend(vec![0u8; 64], |_| postcard::from_bytes(&message).unwrap());
        assert!(!frame.pixels.is_lent());
        assert_eq!(frame.pixels, Bytes::from(vec![1, 2, 3, 250]));
        // After the lending, nothing is lent any more.
        let frame: Frame = postcard::from_bytes(&message).unwrap();
        assert!(!frame.pixels.is_lent());
    }

    #[test]
    fn bytes_read_json_arrays_and_strings_and_write_arrays() {
        let frame: Frame = serde_json::from_str(r#"{"number":1,"pixels":[4,5]}"#).unwrap();
        assert_eq!(&*frame.pixels, &[4, 5]);
        assert_eq!(
            serde_json::to_string(&frame).unwrap(),
            r#"{"number":1,"pixels":[4,5]}"#
        );
        // Through a JSON value too (as `coolbot::Value` reads packets), and a string
        // as its UTF-8 bytes, as a `[u8]` field reads one.
        let value = serde_json::json!({"number": 2, "pixels": [6, 7]});
        let frame: Frame = serde_json::from_value(value).unwrap();
        assert_eq!(&*frame.pixels, &[6, 7]);
        let value = serde_json::json!({"number": 3, "pixels": "ab"});
        let frame: Frame = serde_json::from_value(value).unwrap();
        assert_eq!(&*frame.pixels, b"ab");
        let frame: Frame = serde_json::from_str(r#"{"number":3,"pixels":"ab"}"#).unwrap();
        assert_eq!(&*frame.pixels, b"ab");
    }
}
