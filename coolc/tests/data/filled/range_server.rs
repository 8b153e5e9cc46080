//! Filled-in `RangeServer` for the compile-and-run test: calibrates once, then
//! streams simulated scans.

use crate::generated::range_server::*;
use crate::generated::types::RangeScan;

/// Counts calibration rounds.
#[derive(Debug, Default)]
pub struct RangeServer {
    calibrated: bool,
}

impl Behavior for RangeServer {
    fn calibrating_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let _ = cx;
        self.calibrated = true;
        Ok(())
    }

    fn calibrating_choose(&mut self, cx: &mut Cx<'_>) -> Option<CalibratingMay> {
        let _ = cx;
        self.calibrated.then_some(CalibratingMay::Streaming)
    }

    fn streaming_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.vars.scans += 1;
        let scan = RangeScan {
            stamp: cx.rt.now(),
            ranges: [cx.config.emergency_distance * 10.0; 16],
            bumpers: [false; 8],
        };
        cx.outputs.scan.send(scan);
        Ok(())
    }

    fn on_sensor_timeout(&mut self, cx: &mut Cx<'_>, message: &str) {
        let _ = (cx, message);
    }
}
