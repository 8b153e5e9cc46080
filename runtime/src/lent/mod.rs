//! [`Bytes`]: a packet's bytes that a receiver can read where they arrived, and
//! [`lend`], which lends a message's memory to its decoding; [`Bytes::loan`], a
//! buffer a sender fills where its message will travel.
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
//!
//! On the sending side, [`Bytes::loan`] gives a buffer ([`BytesMut`]) to fill where
//! the message will travel: from the process's [`Lender`] when one is set (a node
//! with shared memory sets one: its pool), else from the heap. Frozen into a `Bytes`
//! and sent, a loaned buffer is not copied by an encoder that knows its lender
//! ([`encoding_loans`], [`loan_at`]): a bridge to another process on the host sends
//! it as the buffer it already is.

mod lend;
mod loan;

pub use lend::{lend, lend_whole};
pub use loan::{Lender, Lent, Loan, encoding_loans, lender, loan_at, push_lender, withdraw_lender};

use lend::lent_slice;

use std::fmt;
use std::ops::{Deref, DerefMut};
use std::sync::Arc;

use serde::de::{self, Visitor};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// Bytes that a clone shares rather than copies; decoded in place from lent memory
/// (module docs). Reads as a `[u8]`; compares by its bytes.
#[derive(Clone, Default)]
pub struct Bytes {
    data: ::bytes::Bytes,
    /// Decoded in place from lent memory.
    lent: bool,
    /// The loaned buffer these bytes are, whole ([`Bytes::loan`]).
    loaned: Option<Arc<dyn Lent>>,
}

impl Bytes {
    /// Empty bytes.
    pub const fn new() -> Bytes {
        Bytes {
            data: ::bytes::Bytes::new(),
            lent: false,
            loaned: None,
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
            loaned: None,
        }
    }
}

impl From<&'static [u8]> for Bytes {
    fn from(bytes: &'static [u8]) -> Bytes {
        Bytes {
            data: ::bytes::Bytes::from_static(bytes),
            lent: false,
            loaned: None,
        }
    }
}

impl fmt::Debug for Bytes {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Bytes({} bytes)", self.data.len())
    }
}

impl Bytes {
    /// A buffer of `len` bytes to fill and then [`BytesMut::freeze`]: from the
    /// process's [`Lender`] when one is set and has room (a node with shared memory:
    /// a buffer of its pool, which a bridge to another process on this host sends as
    /// it is, without a copy), else from the heap. Its bytes are zero when it comes
    /// from the heap, and unspecified when it comes from a lender: write every one.
    pub fn loan(len: usize) -> BytesMut {
        match lender().and_then(|lender| lender.loan(len)) {
            Some(loan) if loan.as_slice().len() == len => BytesMut(Buffer::Loan(loan)),
            _ => BytesMut(Buffer::Heap(vec![0; len])),
        }
    }

    /// Whether these bytes are a buffer loaned by the process's [`Lender`]
    /// ([`Bytes::loan`]).
    pub fn is_loaned(&self) -> bool {
        self.loaned.is_some()
    }
}

impl From<BytesMut> for Bytes {
    fn from(bytes: BytesMut) -> Bytes {
        bytes.freeze()
    }
}

/// A buffer to fill, made by [`Bytes::loan`]; reads and writes as a `[u8]` of its
/// length, and becomes a [`Bytes`] with [`BytesMut::freeze`] (no copy).
pub struct BytesMut(Buffer);

enum Buffer {
    Heap(Vec<u8>),
    Loan(Box<dyn Loan>),
}

impl BytesMut {
    /// The bytes, read-only and shareable from now on (no copy).
    pub fn freeze(self) -> Bytes {
        match self.0 {
            Buffer::Heap(bytes) => Bytes::from(bytes),
            Buffer::Loan(loan) => {
                let lent = loan.freeze();
                Bytes {
                    data: ::bytes::Bytes::from_owner(Frozen(Arc::clone(&lent))),
                    lent: false,
                    loaned: Some(lent),
                }
            }
        }
    }

    /// Whether the buffer came from the process's [`Lender`] rather than the heap.
    pub fn is_loaned(&self) -> bool {
        matches!(self.0, Buffer::Loan(_))
    }
}

impl Deref for BytesMut {
    type Target = [u8];

    fn deref(&self) -> &[u8] {
        match &self.0 {
            Buffer::Heap(bytes) => bytes,
            Buffer::Loan(loan) => loan.as_slice(),
        }
    }
}

impl DerefMut for BytesMut {
    fn deref_mut(&mut self) -> &mut [u8] {
        match &mut self.0 {
            Buffer::Heap(bytes) => bytes,
            Buffer::Loan(loan) => loan.as_mut_slice(),
        }
    }
}

impl fmt::Debug for BytesMut {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "BytesMut({} bytes{})",
            self.len(),
            if self.is_loaned() { ", loaned" } else { "" }
        )
    }
}

/// A frozen loan as the owner of a `bytes::Bytes`.
struct Frozen(Arc<dyn Lent>);

impl AsRef<[u8]> for Frozen {
    fn as_ref(&self) -> &[u8] {
        (*self.0).as_ref()
    }
}

impl Serialize for Bytes {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        if let Some(loan) = &self.loaned {
            loan::serialized(loan);
        }
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
            Some(data) => Bytes {
                data,
                lent: true,
                loaned: None,
            },
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

    /// A frame of number 7 and 4 pixels, encoded.
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

    #[test]
    fn parts_lent_whole_share_only_bytes_that_are_a_whole_part() {
        // The message `encoded()` in three parts: the number and the length, the
        // pixels, nothing.
        let message = encoded();
        let parts = vec![
            (message[..2].to_vec(), true),
            (message[2..].to_vec(), true),
            (Vec::new(), true),
        ];
        let pixels_at = parts[1].0.as_ptr() as usize;
        let (frame, shared) = lend_whole(parts, |parts| {
            assert_eq!(parts.len(), 3);
            let mut joined = Vec::new();
            for part in parts {
                joined.extend_from_slice(part);
            }
            // Decoded from the parts as a segmented reader would hand them out: the
            // pixels are borrowed from the second part.
            let pixels = Bytes::deserialize(BorrowedBytes(parts[1])).unwrap();
            assert!(pixels.is_lent());
            assert_eq!(pixels.as_ptr() as usize, pixels_at);
            // Bytes within a part but not all of it are copied.
            let within = Bytes::deserialize(BorrowedBytes(&parts[1][1..])).unwrap();
            assert!(!within.is_lent());
            let frame: Frame = postcard::from_bytes(&joined).unwrap();
            Frame { pixels, ..frame }
        });
        assert_eq!(&*frame.pixels, &[1, 2, 3, 250]);
        assert!(frame.pixels.is_lent());
        assert_eq!(shared, 1, "the pixels' part");
        // Shared no longer once the pixels are gone; a part that may not be shared is
        // copied.
        drop(frame);
        let message = encoded();
        let parts = vec![
            (message[..2].to_vec(), true),
            (message[2..].to_vec(), false),
        ];
        let (copied, shared) = lend_whole(parts, |parts| {
            let pixels = Bytes::deserialize(BorrowedBytes(parts[1])).unwrap();
            assert!(!pixels.is_lent());
            pixels
        });
        assert_eq!((&*copied, shared), (&message[2..], 0));
        let parts = vec![(message.clone(), true)];
        let ((), shared) = lend_whole(parts, |parts| {
            let whole = Bytes::deserialize(BorrowedBytes(parts[0])).unwrap();
            assert!(whole.is_lent());
        });
        assert_eq!(shared, 0, "what was decoded is gone");
        // Nothing stays lent after.
        let again = Bytes::deserialize(BorrowedBytes(&[9, 9])).unwrap();
        assert!(!again.is_lent());
    }

    /// A deserializer that hands out one borrowed slice of bytes.
    struct BorrowedBytes<'de>(&'de [u8]);

    impl<'de> Deserializer<'de> for BorrowedBytes<'de> {
        type Error = de::value::Error;
        fn deserialize_any<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, Self::Error> {
            visitor.visit_borrowed_bytes(self.0)
        }
        serde::forward_to_deserialize_any! {
            bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string
            bytes byte_buf option unit unit_struct newtype_struct seq tuple
            tuple_struct map struct enum identifier ignored_any
        }
    }

    /// A lender of heap buffers that it can recognize, as a pool's would be.
    struct Marked(Vec<u8>);

    impl Loan for Marked {
        fn as_slice(&self) -> &[u8] {
            &self.0
        }
        fn as_mut_slice(&mut self) -> &mut [u8] {
            &mut self.0
        }
        fn freeze(self: Box<Self>) -> Arc<dyn Lent> {
            Arc::new(*self)
        }
    }

    impl AsRef<[u8]> for Marked {
        fn as_ref(&self) -> &[u8] {
            &self.0
        }
    }

    impl Lent for Marked {}

    struct Lends {
        /// Loans of at most this many bytes.
        room: usize,
    }

    impl Lender for Lends {
        fn loan(&self, len: usize) -> Option<Box<dyn Loan>> {
            (len <= self.room).then(|| Box::new(Marked(vec![0xAA; len])) as Box<dyn Loan>)
        }
    }

    /// A postcard writer that keeps each loaned buffer it is handed as a part of its
    /// own (by reference), as a transport's encoder does.
    #[derive(Default)]
    struct Parts {
        copied: Vec<u8>,
        parts: Vec<Result<Vec<u8>, Arc<dyn Lent>>>,
    }

    impl postcard::ser_flavors::Flavor for Parts {
        type Output = Vec<Result<Vec<u8>, Arc<dyn Lent>>>;
        fn try_push(&mut self, byte: u8) -> postcard::Result<()> {
            self.copied.push(byte);
            Ok(())
        }
        fn try_extend(&mut self, bytes: &[u8]) -> postcard::Result<()> {
            match loan_at(bytes) {
                Some(loan) => {
                    self.parts.push(Ok(std::mem::take(&mut self.copied)));
                    self.parts.push(Err(loan));
                }
                None => self.copied.extend_from_slice(bytes),
            }
            Ok(())
        }
        fn finalize(mut self) -> postcard::Result<Self::Output> {
            self.parts.push(Ok(self.copied));
            Ok(self.parts)
        }
    }

    #[test]
    fn a_loan_comes_from_the_lender_when_one_has_room_and_is_found_by_its_encoder() {
        // A lender that lends nothing: the heap, zeroed, and nothing to find.
        let none: Arc<dyn Lender> = Arc::new(Lends { room: 0 });
        push_lender(Arc::clone(&none));
        let mut heap = Bytes::loan(5);
        assert!(!heap.is_loaned());
        assert_eq!(&*heap, &[0; 5]);
        heap.copy_from_slice(b"hello");
        let heap = heap.freeze();
        assert!(!heap.is_loaned());
        assert_eq!(&*heap, b"hello");

        let lends: Arc<dyn Lender> = Arc::new(Lends { room: 64 });
        push_lender(Arc::clone(&lends));
        let mut loaned = Bytes::loan(4);
        assert!(loaned.is_loaned());
        loaned.copy_from_slice(&[1, 2, 3, 250]);
        let pixels = loaned.freeze();
        assert!(pixels.is_loaned() && !pixels.is_lent());
        // Too large for the lender: the heap.
        assert!(!Bytes::loan(65).is_loaned());

        let frame = Frame { number: 7, pixels };
        // Outside an encoding that looks for loans, nothing is noted.
        assert!(loan_at(&frame.pixels).is_none());
        let parts =
            encoding_loans(|| postcard::serialize_with_flavor(&frame, Parts::default()).unwrap());
        // The number and the length copied, the pixels handed on as their buffer.
        assert_eq!(parts.len(), 3, "{}", parts.len());
        assert_eq!(parts[0].as_ref().ok(), Some(&vec![7, 4]));
        let loan = parts[1].as_ref().expect_err("the loaned buffer");
        assert_eq!((**loan).as_ref(), &[1, 2, 3, 250]);
        assert!(std::ptr::eq(
            (**loan).as_ref().as_ptr(),
            frame.pixels.as_ptr()
        ));
        assert_eq!(parts[2].as_ref().ok(), Some(&vec![]));
        // Once the encoding is over, its loans are forgotten.
        assert!(loan_at(&frame.pixels).is_none());
        // The same message as the bytes copied.
        let whole = postcard::to_allocvec(&frame).unwrap();
        assert_eq!(whole, encoded());
        // Withdrawn, the lender before lends again; then none.
        withdraw_lender(&*lends);
        assert!(!Bytes::loan(4).is_loaned());
        push_lender(Arc::clone(&lends));
        withdraw_lender(&*none);
        assert!(Bytes::loan(4).is_loaned(), "the one left lends");
        withdraw_lender(&*lends);
        assert!(lender().is_none());
    }
}
