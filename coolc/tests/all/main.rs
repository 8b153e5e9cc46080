//! coolc's integration tests, one module a former test file, in one binary (one link
//! instead of one per file). The snapshot tests (`insta`, whose snapshot names and
//! folder follow their file) stay files of their own in `tests/`.

mod common;

mod builder;
mod cli;
mod emit_mutations;
mod generated_crate;
mod grammar;
mod no_panic;
mod recompile;
mod regenerate;
mod ros_crate;
mod ros_msg;
mod ros_rosbags;
mod rustfmt_clean;
mod supervisor_control;
mod valid_descriptions;
