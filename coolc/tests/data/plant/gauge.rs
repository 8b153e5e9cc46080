//! Filled-in `Gauge`: counts, and changes its variables as it counts.

use crate::generated::gauge::*;
use crate::generated::types::{Count, Mode};

/// No state of its own.
#[derive(Debug, Default)]
pub struct Gauge {}

impl Gauge {
    fn count(cx: &mut Cx<'_>) {
        cx.vars.level += 1;
        cx.vars.ratio = cx.vars.level as f32 / 10.0;
        cx.vars.on = cx.vars.level > 2;
        cx.vars.stamp = cx.rt.now();
        cx.vars.uptime = cx.rt.in_state_for();
        if cx.vars.level == 5 {
            cx.vars.mode = Mode::Backup;
            cx.vars.maybe = Some(5);
        }
        if cx.vars.level == 60 {
            cx.vars.last = Some(Count { n: 60 });
        }
        if cx.vars.level == 30 {
            cx.rt
                .set_result(coolbot::TaskResult::Success("counted".to_owned()));
        }
    }
}

impl Behavior for Gauge {
    fn warming_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        Self::count(cx);
        Ok(())
    }

    fn ready_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        Self::count(cx);
        Ok(())
    }
}
