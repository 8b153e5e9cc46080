//! Cross-cutting tests of the repository as a whole, in one test binary
//! (`tests/main.rs`): the documentation against the compiler (`tests/docs.rs`) and the
//! generated binaries run as processes (`tests/starter_node.rs`). The fixture suites in
//! `tests/data` are walked by `coolc`'s own tests.
