//! Cross-cutting tests of the repository as a whole: the documentation against the
//! compiler (`tests/docs.rs`). The fixture suites in `tests/data` are walked by
//! `coolc`'s own tests.
