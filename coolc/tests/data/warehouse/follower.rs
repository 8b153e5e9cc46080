//! Filled-in `Follower`: the farther the front beam, the faster, up to `speed`.

use crate::generated::follower::*;
use crate::generated::types::Twist;

/// Keeps nothing.
#[derive(Debug, Default)]
pub struct Follower {}

impl Behavior for Follower {
    fn following_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let Some(scan) = cx.inputs.scan.latest() else {
            return Ok(());
        };
        let front = f64::from(scan.ranges[0]);
        cx.outputs.cmd.send(Twist {
            linear: (front / 4.0).min(1.0) * cx.vars.speed,
            angular: 0.0,
        });
        Ok(())
    }
}
