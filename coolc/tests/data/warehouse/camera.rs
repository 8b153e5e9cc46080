//! Filled-in `Camera`: numbered frames.

use crate::generated::camera::*;
use crate::generated::types::Frame;

/// Counts frames.
#[derive(Debug, Default)]
pub struct Camera {
    seq: u64,
}

impl Behavior for Camera {
    fn streaming_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        self.seq += 1;
        cx.outputs.frames.send(Frame {
            seq: self.seq,
            pixels: [(self.seq % 256) as u8; 48],
        });
        Ok(())
    }
}
