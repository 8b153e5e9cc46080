//! Filled-in `Drive`: integrates its speed every period.

use crate::generated::drive::*;

/// Nothing of its own: the distance is an observable variable.
#[derive(Debug, Default)]
pub struct Drive {}

impl Behavior for Drive {
    fn start(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.vars.accel_used = cx.config.accel;
        Ok(())
    }

    fn driving_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        // The bus write a real platform makes each period: at least a millisecond of
        // section time, so the supervisor's rule over the drive's elapsed time
        // (`motion.elapsed_time > 10ms`) is reached after about ten periods however
        // fast the machine is.
        std::thread::sleep(std::time::Duration::from_millis(1));
        cx.vars.accel_used = cx.config.accel;
        cx.vars.travelled += cx.vars.speed * 0.005;
        Ok(())
    }
}
