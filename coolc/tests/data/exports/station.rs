//! Filled-in `Station`: no supervisor sections.

use crate::generated::station::*;

/// No state of its own.
#[derive(Debug, Default)]
pub struct StationSupervisor {}

impl Supervisor for StationSupervisor {}

/// The unit and the watcher run this crate's parts.
#[derive(Debug, Default)]
pub struct StationParts {}

impl Parts for StationParts {
    fn supervisor(&mut self) -> impl Supervisor {
        StationSupervisor::default()
    }

    fn unit(&mut self) -> impl crate::generated::unit::Parts {
        crate::unit::UnitParts::default()
    }

    fn watcher(&mut self) -> impl crate::generated::watcher::Behavior {
        crate::watcher::Watcher::default()
    }
}
