//! The CoolBOT paper's mobile robot, simulated.
#![deny(missing_docs)]

/// The code `coolc` generated from `examples/components/*.cool` (in `OUT_DIR`).
#[allow(missing_docs)]
pub mod generated {
    include!(concat!(env!("OUT_DIR"), "/cool.rs"));
}
