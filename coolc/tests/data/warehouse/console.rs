//! Filled-in `Console`: shows the last posted pan.

use crate::generated::console::*;

/// Keeps nothing.
#[derive(Debug, Default)]
pub struct Console {}

impl Behavior for Console {
    fn showing_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        if let Some(pose) = cx.inputs.position.read() {
            cx.vars.pan = pose.pan;
        }
        Ok(())
    }
}
