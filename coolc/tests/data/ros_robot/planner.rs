//! Filled-in `Planner`: counts the ranges it receives and keeps the last one's
//! nearest range and stamp.

use crate::generated::planner::*;

/// No state of its own.
#[derive(Debug, Default)]
pub struct Planner {}

impl Behavior for Planner {
    fn planning_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        for ranges in cx.inputs.ranges.drain() {
            cx.vars.received += 1;
            cx.vars.nearest = ranges.nearest;
            cx.vars.stamp = ranges.stamp;
        }
        Ok(())
    }
}
