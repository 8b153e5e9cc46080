//! What `RangeServer` and `SimRangeServer` share: turning readings into a scan and
//! deciding when the platform is too close to an obstacle.

use std::time::Duration;

use coolbot::Time;
use coolbot::port::LastIn;

use crate::finite::{Kept, Rejected};
use crate::generated::types::{Pose2D, RangeScan};
use crate::world::{IR_BEAMS, Pose, Readings};

/// Settings of a run that replace the descriptions' for both range servers (the
/// command line's `--noise`, `--seed` and `--scan-rate`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Overrides {
    /// Range noise (m, standard deviation) instead of the configuration's `noise`.
    pub noise: Option<f64>,
    /// Noise seed instead of the configuration's `seed`.
    pub seed: Option<u64>,
    /// Scan frequency (Hz): the controllable `frequency` each start begins with.
    pub frequency: Option<f64>,
}

/// Where a range server reads the world: the newest pose of its `pose` input (the
/// motion controller's odometry, which in this simulation is the true pose). A pose
/// with a value that is not finite is dropped and counted (`crate::finite`), and the
/// one before it stays.
#[derive(Debug, Default)]
pub struct Odometry {
    newest: Kept<Pose2D>,
    rejected: Rejected,
}

impl Odometry {
    /// The newest finite pose of `input` (of `component`), `None` before one came.
    pub fn pose(&mut self, input: &LastIn<Pose2D>, component: &str) -> Option<Pose> {
        self.newest
            .latest(input, &mut self.rejected, component, "pose")
            .map(|pose| Pose {
                x: pose.x,
                y: pose.y,
                theta: pose.theta,
            })
    }

    /// The poses dropped for a value that is not finite.
    pub fn rejected(&self) -> u64 {
        self.rejected.count()
    }
}

/// Infrared beams that watch the way ahead (within about 65 degrees of straight on).
const FRONT_IR: std::ops::RangeInclusive<usize> = 1..=IR_BEAMS - 2;

/// Builds the scan packet from `readings`, stamped `stamp`.
pub fn scan(stamp: Time, readings: &Readings) -> RangeScan {
    RangeScan {
        stamp,
        ir: readings.ir.map(|r| r as f32),
        us: readings.us.map(|r| r as f32),
        bumpers: readings.bumpers,
    }
}

/// The nearest range of a scan, every beam together (m).
pub fn nearest(scan: &RangeScan) -> f32 {
    scan.ir
        .iter()
        .chain(scan.us.iter())
        .copied()
        .fold(f32::INFINITY, f32::min)
}

/// The nearest range ahead: the front infrared beams and the front ultrasonic beam.
pub fn front(scan: &RangeScan) -> f32 {
    scan.ir[FRONT_IR].iter().copied().fold(scan.us[0], f32::min)
}

/// Whether the platform is too close: something ahead nearer than `distance`, or a
/// bumper pressed.
pub fn too_close(scan: &RangeScan, distance: f32) -> bool {
    front(scan) < distance || scan.bumpers.iter().any(|b| *b)
}

/// Whether an alarm can end: the way ahead is clear by a margin (hysteresis, so the
/// alarm does not flicker on noise) and no bumper is pressed.
pub fn clear_again(scan: &RangeScan, distance: f32) -> bool {
    front(scan) > distance * 1.4 + 0.05 && !scan.bumpers.iter().any(|b| *b)
}

/// The period for a scan frequency in Hz, when it is a sensible one (0.5 to 200 Hz).
pub fn period_for(frequency: f64) -> Option<Duration> {
    (0.5..=200.0)
        .contains(&frequency)
        .then(|| Duration::from_secs_f64(1.0 / frequency))
}

/// The highest scan rate the range server serves (Hz): it reads its sensors once a
/// period, and its description's shortest period is 50 ms.
pub const MAX_SCAN_RATE: f64 = 20.0;

/// Whether a scan read now is published, `since` the last publication (`None`: none
/// yet), at most `frequency` times a second, by a server that reads every `period`:
/// due when the next read would come later than the publication interval (half a
/// period of tolerance, so 20 Hz at a 50 ms period publishes every scan, and 10 Hz
/// every other one). An unusable frequency publishes every scan.
pub fn publish_due(since: Option<Duration>, frequency: f64, period: Option<Duration>) -> bool {
    let (Some(since), Some(interval)) = (since, period_for(frequency)) else {
        return true;
    };
    since + period.unwrap_or_default() / 2 >= interval
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scan_with(front_ir: f64, bumpers: [bool; 4]) -> RangeScan {
        let mut readings = Readings {
            ir: [0.8; IR_BEAMS],
            us: [3.0; 8],
            bumpers,
        };
        readings.ir[3] = front_ir;
        scan(Time::from_nanos(1), &readings)
    }

    #[test]
    fn an_obstacle_ahead_or_a_bumper_is_too_close() {
        assert!(too_close(&scan_with(0.1, [false; 4]), 0.25));
        assert!(!too_close(&scan_with(0.5, [false; 4]), 0.25));
        assert!(too_close(
            &scan_with(0.5, [false, false, true, false]),
            0.25
        ));
    }

    #[test]
    fn the_alarm_ends_only_past_the_margin() {
        assert!(!clear_again(&scan_with(0.3, [false; 4]), 0.25));
        assert!(clear_again(&scan_with(0.6, [false; 4]), 0.25));
        assert_eq!(nearest(&scan_with(0.3, [false; 4])), 0.3);
    }

    #[test]
    fn scans_are_published_at_most_at_the_frequency() {
        let ms = Duration::from_millis;
        // The first scan, and every scan at 20 Hz with a 50 ms period.
        assert!(publish_due(None, 10.0, Some(ms(50))));
        assert!(publish_due(Some(ms(50)), 20.0, Some(ms(50))));
        // 10 Hz at a 50 ms period: every other scan.
        assert!(!publish_due(Some(ms(50)), 10.0, Some(ms(50))));
        assert!(publish_due(Some(ms(100)), 10.0, Some(ms(50))));
        // A degraded period longer than the interval: every scan.
        assert!(publish_due(Some(ms(100)), 20.0, Some(ms(100))));
        // A nonsense frequency does not stop the scans.
        assert!(publish_due(Some(ms(1)), 0.0, Some(ms(50))));
    }

    #[test]
    fn frequencies_map_to_periods_within_bounds() {
        assert_eq!(period_for(20.0), Some(Duration::from_millis(50)));
        assert_eq!(period_for(0.0), None);
        assert_eq!(period_for(1000.0), None);
    }
}
