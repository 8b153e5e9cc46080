//! Filled-in `Frozen`: a section longer than the nominal period.

use crate::generated::frozen::*;

/// No state of its own.
#[derive(Debug, Default)]
pub struct Frozen {}

impl Behavior for Frozen {
    fn working_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.vars.runs += 1;
        std::thread::sleep(std::time::Duration::from_millis(12));
        Ok(())
    }
}
