//! Filled-in `Drive`: integrates the wheel speeds it is given.

use crate::generated::drive::*;

/// Keeps nothing.
#[derive(Debug, Default)]
pub struct Drive {}

impl Behavior for Drive {
    fn driving_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let step = cx.rt.period().unwrap_or_default().as_secs_f64();
        for wheels in cx.inputs.wheels.drain() {
            cx.vars.travelled += (wheels.left + wheels.right) / 2.0 * step;
        }
        Ok(())
    }
}
