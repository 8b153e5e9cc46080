//! Filled-in `Gate`.

use crate::generated::gate::*;

/// No state of its own.
#[derive(Debug, Default)]
pub struct GateSupervisor {}

impl Supervisor for GateSupervisor {
    fn open_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let _ = cx;
        Ok(())
    }

    fn quiet_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let _ = cx;
        Ok(())
    }
}

/// The worker runs this crate's `Worker`.
#[derive(Debug, Default)]
pub struct GateParts {}

impl Parts for GateParts {
    fn supervisor(&mut self) -> impl Supervisor {
        GateSupervisor::default()
    }

    fn w(&mut self) -> impl crate::generated::worker::Behavior {
        crate::worker::Worker::default()
    }
}
