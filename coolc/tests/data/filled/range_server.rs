//! Filled-in `RangeServer` for the compile-and-run test: calibrates once, then
//! streams simulated scans.

use crate::generated::range_server::*;
use crate::generated::types::RangeScan;

/// Counts calibration rounds.
#[derive(Debug, Default)]
pub struct RangeServer {
    calibrated: bool,
}

impl RangeServer {
    /// Whether `calibrating`'s entry has run.
    pub fn calibrated_once(&self) -> bool {
        self.calibrated
    }
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
        if cx.vars.scans == 4 && cx.vars.timeouts == 0 {
            // Once: the continuity plan (`retry 2 every 50ms`) runs this section again.
            cx.vars.scans -= 1;
            return Err(Exception::SensorTimeout.raise("no reading at scan 4"));
        }
        let scan = RangeScan {
            stamp: cx.rt.now(),
            ranges: [cx.config.emergency_distance * 10.0; 16],
            bumpers: [false; 8],
        };
        cx.outputs.scan.send(scan);
        Ok(())
    }

    fn on_sensor_timeout(&mut self, cx: &mut Cx<'_>, message: &str) {
        assert_eq!(message, "no reading at scan 4");
        cx.vars.timeouts += 1;
    }
}
