//! Filled-in `Rig`: its entry section sets the scanner's limits.

use crate::generated::rig::*;

/// Keeps nothing.
#[derive(Debug, Default)]
pub struct RigSupervisor {}

impl Supervisor for RigSupervisor {
    fn limiting_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.instances.scanner().set_limits([5; 64])?;
        Ok(())
    }
}

/// The crate's scanner.
#[derive(Debug, Default)]
pub struct RigParts {}

impl Parts for RigParts {
    fn supervisor(&mut self) -> impl Supervisor {
        RigSupervisor::default()
    }

    fn scanner(&mut self) -> impl crate::generated::scanner::Behavior {
        crate::scanner::Scanner::default()
    }
}
