//! The repository's cross-cutting tests, in one binary: the documentation against the
//! compiler and the runtime (`docs.rs`), and the crates coolc generates built and run
//! as an operator runs them (`starter_node.rs`).
//!
//! One binary, so that its test threads run both side by side: most of the processes'
//! time is waiting (a node killed, substituted, started again and recovered, fifty
//! times), and the docs' tests build crates meanwhile. libtest starts tests in the
//! order of their names: the processes' module is named to come first, so that the
//! long soak starts at once rather than after the builds.

#[path = "starter_node.rs"]
mod as_processes;
mod docs;
