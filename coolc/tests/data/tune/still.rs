//! Filled-in `Still`: no supervisor sections.

use crate::generated::still::*;

/// No state of its own.
#[derive(Debug, Default)]
pub struct StillSupervisor {}

impl Supervisor for StillSupervisor {}

/// The instance runs this crate's `Slow`.
#[derive(Debug, Default)]
pub struct StillParts {}

impl Parts for StillParts {
    fn supervisor(&mut self) -> impl Supervisor {
        StillSupervisor::default()
    }

    fn slow(&mut self) -> impl crate::generated::slow::Behavior {
        crate::slow::Slow::default()
    }
}
