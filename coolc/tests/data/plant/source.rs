//! Filled-in `Source`: sends an increasing count every period.

use crate::generated::source::*;
use crate::generated::types::Count;

/// No state of its own: the count is the component's `local ticks`.
#[derive(Debug, Default)]
pub struct Source {}

impl Behavior for Source {
    fn sending_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.vars.ticks += 1;
        cx.vars.sent = cx.vars.ticks;
        cx.outputs.out.send(Count { n: cx.vars.sent });
        Ok(())
    }
}
