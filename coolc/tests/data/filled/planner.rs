//! Filled-in `Planner`: sends one two-pose path when it starts planning.

use crate::generated::planner::*;
use crate::generated::types::{Path, Pose2D};

/// No state.
#[derive(Debug, Default)]
pub struct Planner {}

impl Behavior for Planner {
    fn planning_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let path = self.answer_path(cx)?;
        cx.outputs.path.send(path);
        Ok(())
    }

    fn answer_path(&mut self, cx: &mut Cx<'_>) -> Result<Path, coolbot::Fault> {
        let _ = cx;
        let start = Pose2D::default();
        let goal = Pose2D {
            x: 2.0,
            y: 0.0,
            theta: 0.0,
        };
        Ok(Path {
            poses: vec![start, goal],
        })
    }
}
