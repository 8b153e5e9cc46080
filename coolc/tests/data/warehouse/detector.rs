//! Filled-in `Detector`: counts the frames that reach its own queue.

use crate::generated::detector::*;

/// Keeps nothing.
#[derive(Debug, Default)]
pub struct Detector {}

impl Behavior for Detector {
    fn looking_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        for frame in cx.inputs.frames.drain() {
            debug_assert_eq!(frame.pixels[0], (frame.seq % 256) as u8);
            cx.vars.seen += 1;
        }
        Ok(())
    }
}
