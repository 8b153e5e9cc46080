//! The runtime's integration tests, one module a former test file, in one binary
//! (one link of the dependency graph instead of one per file). A test that needs its
//! process to itself (a panic hook, the process's CPU time or nice value, a pinned
//! core) stays a file of its own in `tests/`.

mod adapt;
mod adapt_hierarchy;
mod adapt_policy;
mod automaton_table;
mod command_sequences;
mod compound;
mod compound_clock;
mod compound_rules;
mod connections;
mod exports;
mod faults;
mod groups;
mod harness;
mod overflow_stress;
mod passive;
mod plans;
mod pull;
mod ranges;
mod record;
mod redundancy;
mod response;
mod rosbag2_interop;
mod spend;
mod stack;
mod supervisor_commands;
mod timing_override;
mod user_automaton;
mod values_and_specs;
