//! Filled-in `Restarter`: no supervisor sections.

use crate::generated::restarter::*;

/// No state of its own.
#[derive(Debug, Default)]
pub struct RestarterSupervisor {}

impl Supervisor for RestarterSupervisor {}

/// Its worker is this crate's `Worker`.
#[derive(Debug, Default)]
pub struct RestarterParts {}

impl Parts for RestarterParts {
    fn supervisor(&mut self) -> impl Supervisor {
        RestarterSupervisor::default()
    }

    fn w(&mut self) -> impl crate::generated::worker::Behavior {
        crate::worker::Worker::default()
    }
}
