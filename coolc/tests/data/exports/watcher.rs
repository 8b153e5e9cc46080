//! Filled-in `Watcher`: reads the post, counts the beats, pulls the latest reading.

use crate::generated::watcher::*;

/// No state of its own.
#[derive(Debug, Default)]
pub struct Watcher {}

impl Behavior for Watcher {
    fn watching_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        if let Some(reading) = cx.inputs.status.read() {
            cx.vars.posted = reading.n;
        }
        cx.vars.beats += cx.inputs.beat.take();
        if let Some(reading) = cx.inputs.latest.take_new() {
            cx.vars.pulled = reading.n;
        }
        // The answer arrives before a later period reads it (a request while one
        // waits is queued at the producer, and refused beyond its capacity).
        let _ = cx.inputs.latest.request();
        Ok(())
    }
}
