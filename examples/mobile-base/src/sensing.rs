//! What `RangeServer` and `SimRangeServer` share: turning readings into a scan and
//! deciding when the platform is too close to an obstacle.

use coolbot::Time;

use crate::generated::types::RangeScan;
use crate::world::{IR_BEAMS, Readings};

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
pub fn period_for(frequency: f64) -> Option<std::time::Duration> {
    (0.5..=200.0)
        .contains(&frequency)
        .then(|| std::time::Duration::from_secs_f64(1.0 / frequency))
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
    fn frequencies_map_to_periods_within_bounds() {
        assert_eq!(period_for(20.0), Some(std::time::Duration::from_millis(50)));
        assert_eq!(period_for(0.0), None);
        assert_eq!(period_for(1000.0), None);
    }
}
