//! `SimRangeServer`: the simulated backup of `RangeServer`, with the same interface.
//! It computes what the sensors would read from the map at the odometry pose (its
//! `pose` input), so it keeps working while the sensor board is down. The mobile base
//! substitutes it for a failed `RangeServer`.

use std::sync::Arc;

use crate::generated::sim_range_server::*;
use crate::generated::types::RangeScan;
use crate::sensing::{self, Odometry, Overrides};
use crate::world::Platform;

/// The simulated range server's code.
#[derive(Debug)]
pub struct SimRangeServer {
    platform: Arc<Platform>,
    overrides: Overrides,
    odometry: Odometry,
    last: Option<RangeScan>,
}

impl SimRangeServer {
    /// A server computing ranges in `platform`'s map, with the run's `overrides` (only
    /// `frequency` applies: it reads no sensors).
    pub fn new(platform: Arc<Platform>, overrides: Overrides) -> SimRangeServer {
        SimRangeServer {
            platform,
            overrides,
            odometry: Odometry::default(),
            last: None,
        }
    }

    /// The poses dropped from `pose` for a value that is not finite (`crate::finite`).
    pub fn rejected(&self) -> u64 {
        self.odometry.rejected()
    }

    /// Computes one scan from the map at the odometry pose and publishes it (nothing
    /// before a pose came).
    fn read(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        if let Some(period) = sensing::period_for(cx.vars.frequency)
            && cx.rt.period() != Some(period)
        {
            cx.rt.set_period(period);
        }
        let Some(pose) = self.odometry.pose(&cx.inputs.pose, cx.rt.component_name()) else {
            return Ok(());
        };
        let readings = self.platform.world().sense(
            pose,
            f64::from(cx.config.ir_max_range),
            f64::from(cx.config.us_max_range),
        );
        let scan = sensing::scan(cx.rt.now(), &readings);
        cx.vars.scans += 1;
        cx.vars.nearest = sensing::nearest(&scan);
        cx.outputs.scan.send(scan.clone());
        self.last = Some(scan);
        Ok(())
    }
}

impl Behavior for SimRangeServer {
    fn start(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        if let Some(frequency) = self.overrides.frequency {
            cx.vars.frequency = frequency;
        }
        Ok(())
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
}
