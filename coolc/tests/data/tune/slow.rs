//! Filled-in `Slow`: a section longer than the nominal period.

use crate::generated::slow::*;

/// No state of its own.
#[derive(Debug, Default)]
pub struct Slow {}

impl Behavior for Slow {
    fn working_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.vars.runs += 1;
        std::thread::sleep(std::time::Duration::from_millis(12));
        Ok(())
    }
}
