//! Filled-in `Pair`: no supervisor sections.

use crate::generated::pair::*;

/// No state of its own.
#[derive(Debug, Default)]
pub struct PairSupervisor {}

impl Supervisor for PairSupervisor {}

/// Both members run this crate's `Worker`.
#[derive(Debug, Default)]
pub struct PairParts {}

impl Parts for PairParts {
    fn supervisor(&mut self) -> impl Supervisor {
        PairSupervisor::default()
    }

    fn a(&mut self) -> impl crate::generated::worker::Behavior {
        crate::worker::Worker::default()
    }

    fn b(&mut self) -> impl crate::generated::worker::Behavior {
        crate::worker::Worker::default()
    }
}
