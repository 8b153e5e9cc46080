//! Filled-in `Cell` supervisor: records each switch to the backup in its variables.

use crate::generated::cell::*;
use crate::generated::types::Mode;

/// No state of its own: the supervisor's variables are in `cx.vars`.
#[derive(Debug, Default)]
pub struct CellSupervisor {}

impl Supervisor for CellSupervisor {
    fn normal_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.vars.entered += 1;
        cx.vars.mode = Mode::Normal;
        Ok(())
    }

    fn backup_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.vars.switches += 1;
        cx.vars.mode = Mode::Backup;
        Ok(())
    }
}

/// Both workers run this crate's `Worker`.
#[derive(Debug, Default)]
pub struct CellParts {}

impl Parts for CellParts {
    fn supervisor(&mut self) -> impl Supervisor {
        CellSupervisor::default()
    }

    fn primary(&mut self) -> impl crate::generated::worker::Behavior {
        crate::worker::Worker::default()
    }

    fn backup(&mut self) -> impl crate::generated::worker::Behavior {
        crate::worker::Worker::default()
    }
}
