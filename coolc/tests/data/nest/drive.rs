//! Filled-in `Drive`: keeps the left wheel speed it receives, times its gain.

use crate::generated::drive::*;

/// No state of its own.
#[derive(Debug, Default)]
pub struct Drive {}

impl Behavior for Drive {
    fn driving_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        for wheels in cx.inputs.wheels.drain() {
            cx.vars.received += 1;
            cx.vars.left = wheels.left * cx.vars.gain;
        }
        Ok(())
    }
}
