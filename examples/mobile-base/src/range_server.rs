//! `RangeServer` (paper Figure 4, right): reads the platform's ir/us/bumper suite at a
//! set frequency, publishes time-stamped scans and raises the emergency tick when the
//! platform gets too close to an obstacle. Its description gives it degraded
//! operating modes (a period interval and the qualities `full` and `half`): the
//! runtime's adaptation (paper 3.6) picks the period and the quality; the code honours
//! `Context::quality()`.

use std::sync::Arc;
use std::time::Instant;

use crate::generated::range_server::*;
use crate::generated::types::RangeScan;
use crate::sensing::{self, Odometry, Overrides};
use crate::world::{FaultKind, IR_BEAMS, Platform, Rng, US_BEAMS};

/// The range server's code: the driver of the platform's sensor suite.
///
/// The simulated sensor board reads the world at the pose of the `pose` input (the
/// odometry), not at the platform's own: a range server in another process (`--drivers`)
/// has a board of its own, which no motion controller drives. Until a pose comes it
/// reads nothing.
#[derive(Debug)]
pub struct RangeServer {
    platform: Arc<Platform>,
    overrides: Overrides,
    odometry: Odometry,
    rng: Option<Rng>,
    /// The last scan read (published or not).
    last: Option<RangeScan>,
    /// When the last scan was published.
    published: Option<Instant>,
    /// At quality `half`: whether this scan refreshes the odd ultrasonic beams.
    odd: bool,
}

impl RangeServer {
    /// A server reading `platform`'s sensors, with the run's `overrides`.
    pub fn new(platform: Arc<Platform>, overrides: Overrides) -> RangeServer {
        RangeServer {
            platform,
            overrides,
            odometry: Odometry::default(),
            rng: None,
            last: None,
            published: None,
            odd: false,
        }
    }

    /// The poses dropped from `pose` for a value that is not finite (`crate::finite`).
    pub fn rejected(&self) -> u64 {
        self.odometry.rejected()
    }

    /// Reads the sensors once, at the quality the runtime asks for, and publishes the
    /// scan when one is due at the controllable `frequency`.
    ///
    /// Quality `full` (0) refreshes every beam; `half` (1) refreshes every infrared
    /// beam (they watch the way ahead: the emergency stop uses them) and every other
    /// ultrasonic beam, alternately the even and the odd ones, the others keeping
    /// their last reading. The period is the runtime's: the description's 50 ms, or
    /// longer while the server is degraded (it never sets its own period, so that
    /// adaptation alone moves it).
    fn read(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let config = cx.config;
        let seed = self.overrides.seed.unwrap_or(config.seed);
        let rng = self.rng.get_or_insert_with(|| Rng::new(seed));
        let pose = self.odometry.pose(&cx.inputs.pose, cx.rt.component_name());
        let readings = match pose {
            Some(pose) => self.platform.read_sensors(
                pose,
                f64::from(config.ir_max_range),
                f64::from(config.us_max_range),
                self.overrides.noise.unwrap_or(config.noise),
                rng,
            ),
            // No pose yet: nowhere to read the world from (the board answers).
            None if self.platform.sensors_answering() => return Ok(()),
            None => None,
        };
        let Some(mut readings) = readings else {
            if self
                .platform
                .fault()
                .is_some_and(|f| f.kind == FaultKind::Panic)
            {
                panic!("sensor driver crashed: the ir/us board reset");
            }
            return Err(Exception::SensorTimeout.raise("no answer from the ir/us board"));
        };
        let stamp = cx.rt.now();
        let mut beams = IR_BEAMS + US_BEAMS;
        if cx.rt.quality() > 0 {
            self.odd = !self.odd;
            let kept = usize::from(!self.odd);
            if let Some(last) = &self.last {
                for i in (kept..US_BEAMS).step_by(2) {
                    readings.us[i] = f64::from(last.us[i]);
                }
            }
            beams = IR_BEAMS + US_BEAMS / 2;
        }
        // The simulated processor shortage (`--load`): processing the beams takes
        // time, whatever the machine's real load.
        let cost = self.platform.processing_cost(beams);
        cx.rt.spend(cost);
        let scan = sensing::scan(stamp, &readings);
        cx.vars.nearest = sensing::nearest(&scan);
        let now = self.platform.now();
        let since = self.published.map(|at| now.duration_since(at));
        if sensing::publish_due(since, cx.vars.frequency, cx.rt.period()) {
            self.published = Some(now);
            cx.vars.scans += 1;
            cx.outputs.scan.send(scan.clone());
        }
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
