//! Filled-in `Lidar`: a sweep per period, 72 beams, every other beam in `sparse`.

use crate::generated::lidar::*;
use crate::generated::types::LaserScan;

/// Counts sweeps.
#[derive(Debug, Default)]
pub struct Lidar {
    seq: u64,
}

impl Behavior for Lidar {
    fn sweeping_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        self.seq += 1;
        let mut ranges = [4.0_f32; 72];
        if cx.rt.quality() > 0 {
            for beam in ranges.iter_mut().skip(1).step_by(2) {
                *beam = f32::NAN;
            }
        }
        cx.outputs.scan.send(LaserScan {
            stamp: cx.rt.now(),
            ranges,
            seq: self.seq,
        });
        cx.vars.sweeps = self.seq;
        Ok(())
    }
}
