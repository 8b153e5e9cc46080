//! Filled-in `Unit`: no supervisor sections.

use crate::generated::unit::*;

/// No state of its own.
#[derive(Debug, Default)]
pub struct UnitSupervisor {}

impl Supervisor for UnitSupervisor {}

/// The sensor runs this crate's `Sensor`.
#[derive(Debug, Default)]
pub struct UnitParts {}

impl Parts for UnitParts {
    fn supervisor(&mut self) -> impl Supervisor {
        UnitSupervisor::default()
    }

    fn sensor(&mut self) -> impl crate::generated::sensor::Behavior {
        crate::sensor::Sensor::default()
    }
}
