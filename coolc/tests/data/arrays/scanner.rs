//! Filled-in `Scanner`: beam `i` of every scan reads `gains[i] * count`.

use crate::generated::scanner::*;
use crate::generated::types::LaserScan;

/// No state of its own: the count is the component's variable.
#[derive(Debug, Default)]
pub struct Scanner {}

impl Behavior for Scanner {
    fn scanning_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.vars.count += 1;
        let count = cx.vars.count as f32;
        let mut scan = LaserScan::default();
        for (range, gain) in scan.ranges.iter_mut().zip(cx.config.gains) {
            *range = gain * count;
        }
        scan.history.push(scan.ranges);
        cx.vars.last = scan.ranges;
        cx.vars.frame.scan = scan.clone();
        cx.outputs.scan.send(scan);
        Ok(())
    }
}
