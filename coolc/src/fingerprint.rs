//! Stable fingerprints: 64-bit FNV-1a, computed here so that the value depends only
//! on the bytes hashed (not on the Rust release or the platform, as `std`'s
//! `DefaultHasher` may).
//!
//! Two uses: the hash of a compile's inputs printed in every generated file's header
//! ([`inputs`]), which says which descriptions and which coolc a generated file
//! comes from, and the fingerprints of the format cache (`merge`).

use crate::source::SourceFile;

/// 64-bit FNV-1a, fed in pieces.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Fnv1a(u64);

impl Default for Fnv1a {
    fn default() -> Self {
        Fnv1a(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv1a {
    /// Adds `bytes`.
    pub(crate) fn write(&mut self, bytes: &[u8]) {
        for byte in bytes {
            self.0 ^= u64::from(*byte);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }

    /// The hash of everything written so far.
    pub(crate) fn finish(self) -> u64 {
        self.0
    }
}

/// The 64-bit FNV-1a hash of `bytes`.
pub(crate) fn fnv1a(bytes: &[u8]) -> u64 {
    let mut hash = Fnv1a::default();
    hash.write(bytes);
    hash.finish()
}

/// The fingerprint of a compile's inputs, as the generated-file header prints it
/// (`fnv1a64:` and 16 hex digits): coolc's version, then every loaded description in
/// load order (roots, then imports), each as its length and its bytes. Paths are not
/// part of it: moving the files changes nothing generated from them.
pub fn inputs(files: &[SourceFile]) -> String {
    inputs_of(files.iter().map(|f| f.text.as_bytes()))
}

/// [`inputs`] over the texts themselves.
pub(crate) fn inputs_of<'a>(texts: impl IntoIterator<Item = &'a [u8]>) -> String {
    let mut hash = Fnv1a::default();
    hash.write(b"coolc ");
    hash.write(env!("CARGO_PKG_VERSION").as_bytes());
    hash.write(&[0]);
    for text in texts {
        hash.write(&(text.len() as u64).to_le_bytes());
        hash.write(text);
    }
    format!("fnv1a64:{:016x}", hash.finish())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fnv1a_matches_the_reference_values() {
        // The published FNV-1a 64 test vectors.
        assert_eq!(fnv1a(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv1a(b"a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(fnv1a(b"foobar"), 0x8594_4171_f739_67e8);
    }

    #[test]
    fn inputs_depend_on_every_byte_and_on_the_split() {
        let one = inputs_of([&b"atomic A {}"[..]]);
        assert!(one.starts_with("fnv1a64:") && one.len() == 8 + 16, "{one}");
        assert_eq!(one, inputs_of([&b"atomic A {}"[..]]));
        assert_ne!(one, inputs_of([&b"atomic B {}"[..]]));
        assert_ne!(inputs_of([&b"ab"[..], b"c"]), inputs_of([&b"a"[..], b"bc"]));
    }
}
