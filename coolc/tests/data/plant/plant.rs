//! Filled-in `Plant` supervisor: counts the alarms.

use crate::generated::plant::*;

/// No state of its own.
#[derive(Debug, Default)]
pub struct PlantSupervisor {}

impl Supervisor for PlantSupervisor {
    fn alarmed_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.vars.alarms += 1;
        Ok(())
    }
}

/// The plant's instances run this crate's code.
#[derive(Debug, Default)]
pub struct PlantParts {}

impl Parts for PlantParts {
    fn supervisor(&mut self) -> impl Supervisor {
        PlantSupervisor::default()
    }

    fn source(&mut self) -> impl crate::generated::source::Behavior {
        crate::source::Source::default()
    }

    fn cell(&mut self) -> impl crate::generated::cell::Parts {
        crate::cell::CellParts::default()
    }

    fn sink(&mut self) -> impl crate::generated::sink::Behavior {
        crate::sink::Sink::default()
    }
}
