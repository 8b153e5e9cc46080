//! Filled-in `Worker`: passes counts on; fails once when `fail` is set.

use crate::generated::types::Count;
use crate::generated::worker::*;

/// No state of its own.
#[derive(Debug, Default)]
pub struct Worker {}

impl Behavior for Worker {
    fn working_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        if cx.vars.fail {
            cx.vars.fail = false;
            return Err(coolbot::Fault::message("injected fault"));
        }
        for packet in cx.inputs.input.drain() {
            cx.outputs.out.send(Count {
                n: packet.n * cx.config.gain * cx.vars.scale,
            });
            cx.vars.passed += 1;
        }
        Ok(())
    }
}
