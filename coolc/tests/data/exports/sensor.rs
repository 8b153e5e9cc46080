//! Filled-in `Sensor`: counts its periods, posts the count, emits a beat, and answers
//! pulls with the count.

use crate::generated::sensor::*;
use crate::generated::types::Reading;

/// No state of its own.
#[derive(Debug, Default)]
pub struct Sensor {}

impl Behavior for Sensor {
    fn sensing_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.vars.count += 1;
        cx.outputs.status.post(Reading { n: cx.vars.count });
        cx.outputs.beat.emit();
        Ok(())
    }

    fn answer_latest(&mut self, cx: &mut Cx<'_>) -> Result<Reading, coolbot::Fault> {
        Ok(Reading { n: cx.vars.count })
    }
}
