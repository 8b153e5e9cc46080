//! Filled-in `Sink`: counts the packets that arrive.

use crate::generated::sink::*;

/// No state of its own.
#[derive(Debug, Default)]
pub struct Sink {}

impl Behavior for Sink {
    fn counting_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        for packet in cx.inputs.input.drain() {
            cx.vars.received += 1;
            cx.vars.last = packet.n;
        }
        Ok(())
    }
}
