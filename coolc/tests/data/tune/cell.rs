//! Filled-in `Cell`: no supervisor sections.

use crate::generated::cell::*;

/// No state of its own.
#[derive(Debug, Default)]
pub struct CellSupervisor {}

impl Supervisor for CellSupervisor {}

/// The instances run this crate's parts.
#[derive(Debug, Default)]
pub struct CellParts {}

impl Parts for CellParts {
    fn supervisor(&mut self) -> impl Supervisor {
        CellSupervisor::default()
    }

    fn thawed(&mut self) -> impl crate::generated::frozen::Behavior {
        crate::frozen::Frozen::default()
    }

    fn slow(&mut self) -> impl crate::generated::slow::Behavior {
        crate::slow::Slow::default()
    }
}
