//! Filled-in `Logger`: counts the scans it receives and keeps the last one.

use crate::generated::logger::*;

/// No state of its own.
#[derive(Debug, Default)]
pub struct Logger {}

impl Behavior for Logger {
    fn logging_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        for scan in cx.inputs.scans.drain() {
            cx.vars.logged += 1;
            cx.vars.frame = scan.header.frame_id.clone();
            cx.vars.beams = scan.ranges.len() as u64;
            cx.vars.last = scan;
        }
        Ok(())
    }
}
