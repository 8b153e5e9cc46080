//! `RangeServer` (paper Figure 4, right): reads the platform's ir/us/bumper suite at a
//! set frequency, publishes time-stamped scans and raises the emergency tick when the
//! platform gets too close to an obstacle.

use std::sync::Arc;

use crate::generated::range_server::*;
use crate::generated::types::RangeScan;
use crate::sensing::{self, Overrides};
use crate::world::{FaultKind, Platform, Rng};

/// The range server's code: the driver of the platform's sensor suite.
#[derive(Debug)]
pub struct RangeServer {
    platform: Arc<Platform>,
    overrides: Overrides,
    rng: Option<Rng>,
    last: Option<RangeScan>,
}

impl RangeServer {
    /// A server reading `platform`'s sensors, with the run's `overrides`.
    pub fn new(platform: Arc<Platform>, overrides: Overrides) -> RangeServer {
        RangeServer {
            platform,
            overrides,
            rng: None,
            last: None,
        }
    }

    /// Reads the sensors once and publishes the scan.
    fn read(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        if let Some(period) = sensing::period_for(cx.vars.frequency)
            && cx.rt.period() != Some(period)
        {
            cx.rt.set_period(period);
        }
        let config = cx.config;
        let seed = self.overrides.seed.unwrap_or(config.seed);
        let rng = self.rng.get_or_insert_with(|| Rng::new(seed));
        let readings = self.platform.read_sensors(
            f64::from(config.ir_max_range),
            f64::from(config.us_max_range),
            self.overrides.noise.unwrap_or(config.noise),
            rng,
        );
        let Some(readings) = readings else {
            if self
                .platform
                .fault()
                .is_some_and(|f| f.kind == FaultKind::Panic)
            {
                panic!("sensor driver crashed: the ir/us board reset");
            }
            return Err(Exception::SensorTimeout.raise("no answer from the ir/us board"));
        };
        let scan = sensing::scan(cx.rt.now(), &readings);
        cx.vars.scans += 1;
        cx.vars.nearest = sensing::nearest(&scan);
        cx.outputs.scan.send(scan.clone());
        self.last = Some(scan);
        Ok(())
    }
}

impl Behavior for RangeServer {
    fn start(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        if let Some(frequency) = self.overrides.frequency {
            cx.vars.frequency = frequency;
        }
        // Opening the sensor board fails while it does not answer.
        if self.platform.sensors_answering() {
            Ok(())
        } else {
            Err(coolbot::Fault::message("the ir/us board does not answer"))
        }
    }

    fn streaming_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let _ = cx;
        Ok(())
    }

    fn streaming_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        self.read(cx)
    }

    fn streaming_choose(&mut self, cx: &mut Cx<'_>) -> Option<StreamingMay> {
        let distance = cx.vars.emergency_distance;
        let danger = self
            .last
            .as_ref()
            .is_some_and(|s| sensing::too_close(s, distance));
        danger.then_some(StreamingMay::Alarm)
    }

    fn alarm_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.vars.emergencies += 1;
        cx.outputs.emergency.emit();
        Ok(())
    }

    fn alarm_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        self.read(cx)
    }

    fn alarm_choose(&mut self, cx: &mut Cx<'_>) -> Option<AlarmMay> {
        let distance = cx.vars.emergency_distance;
        let clear = self
            .last
            .as_ref()
            .is_some_and(|s| sensing::clear_again(s, distance));
        clear.then_some(AlarmMay::Streaming)
    }

    fn on_sensor_timeout(&mut self, cx: &mut Cx<'_>, message: &str) {
        // The plan retries the read; nothing to clean up.
        let _ = (cx, message);
    }
}
