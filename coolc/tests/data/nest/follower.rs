//! Filled-in `Follower`: sends `linear = 1 + n`, `angular = 0.5`.

use crate::generated::follower::*;
use crate::generated::types::Twist;

/// No state of its own.
#[derive(Debug, Default)]
pub struct Follower {}

impl Behavior for Follower {
    fn following_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.vars.sent += 1;
        cx.outputs.cmd.send(Twist {
            linear: 1.0 + cx.vars.sent as f64,
            angular: 0.5,
        });
        Ok(())
    }
}
