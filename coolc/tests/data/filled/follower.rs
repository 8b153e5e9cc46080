//! Filled-in `Follower`: pulls the planner's path every period.

use std::time::Duration;

use crate::generated::follower::*;

/// No state.
#[derive(Debug, Default)]
pub struct Follower {}

impl Behavior for Follower {
    fn following_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        // Pull model: ask the producer, which answers with `answer_path`.
        if let Ok(path) = cx.inputs.path.pull(Duration::from_secs(5)) {
            let poses = u32::try_from(path.poses.len()).unwrap_or(u32::MAX);
            cx.vars.waypoints = poses * cx.config.scale;
        }
        Ok(())
    }
}
