//! Filled-in `Recorder`: keeps the ranges of the last scan it received.

use crate::generated::recorder::*;

/// No state of its own.
#[derive(Debug, Default)]
pub struct Recorder {}

impl Behavior for Recorder {
    fn recording_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        for scan in cx.inputs.scan.drain() {
            cx.vars.received += 1;
            cx.vars.ranges = scan.ranges;
        }
        Ok(())
    }
}
