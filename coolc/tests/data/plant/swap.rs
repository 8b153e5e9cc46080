//! Filled-in `Swap` supervisor: nothing to do on entering `swapped`.

use crate::generated::swap::*;

/// No state of its own.
#[derive(Debug, Default)]
pub struct SwapSupervisor {}

impl Supervisor for SwapSupervisor {
    fn swapped_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let _ = cx;
        Ok(())
    }
}

/// Both workers run this crate's `Worker`.
#[derive(Debug, Default)]
pub struct SwapParts {}

impl Parts for SwapParts {
    fn supervisor(&mut self) -> impl Supervisor {
        SwapSupervisor::default()
    }

    fn main(&mut self) -> impl crate::generated::worker::Behavior {
        crate::worker::Worker::default()
    }

    fn stand(&mut self) -> impl crate::generated::worker::Behavior {
        crate::worker::Worker::default()
    }
}
