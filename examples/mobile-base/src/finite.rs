//! Floats from inputs are checked before they are used: a packet with a value that is
//! not finite (NaN or infinite) is dropped, counted, and said in a warning (the first
//! one, then at every tenfold count: 10, 100, ...), and the section goes on without
//! it. Unchecked, a NaN goes through `clamp` and `min` and fails every comparison:
//! one `Twist { linear: NaN, .. }` would drive the platform's pose to NaN, and the
//! platform would report a collision that never happened.

use std::fmt::Debug;

use coolbot::Packet;
use coolbot::port::LastIn;

use crate::generated::types::{Pose2D, RangeScan, Twist};

/// A packet whose values can all be checked.
pub trait Finite {
    /// Whether every float in it is finite.
    fn is_finite(&self) -> bool;
}

impl Finite for Twist {
    fn is_finite(&self) -> bool {
        self.linear.is_finite() && self.angular.is_finite()
    }
}

impl Finite for Pose2D {
    fn is_finite(&self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.theta.is_finite()
    }
}

impl Finite for RangeScan {
    fn is_finite(&self) -> bool {
        self.ir
            .iter()
            .chain(&self.us)
            .all(|range| range.is_finite())
    }
}

/// The packets a component dropped for a value that is not finite.
#[derive(Debug, Default)]
pub struct Rejected {
    count: u64,
}

impl Rejected {
    /// How many were dropped.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// `packet` if its values are all finite; else `None`: the packet is dropped,
    /// counted, and said (`component`'s input `input`) if the count is 1, 10, 100, ...
    pub fn check<T: Finite + Debug>(
        &mut self,
        packet: Option<T>,
        component: &str,
        input: &str,
    ) -> Option<T> {
        let packet = packet?;
        if packet.is_finite() {
            return Some(packet);
        }
        self.count += 1;
        if self.count == 10u64.pow(self.count.ilog10()) {
            tracing::warn!(
                component,
                input,
                "dropped a packet with a value that is not finite: {packet:?} ({} so far)",
                self.count
            );
        }
        None
    }
}

/// What a section reads of a `last` input: the newest packet whose values are all
/// finite (a packet that is not is dropped, and the one before it stays).
#[derive(Debug)]
pub struct Kept<T> {
    newest: Option<T>,
}

impl<T> Default for Kept<T> {
    fn default() -> Self {
        Kept { newest: None }
    }
}

impl<T: Finite + Packet + Debug> Kept<T> {
    /// The newest finite packet of `input` (named `name`, of `component`), checking
    /// the one that arrived since the last call, if any, with `rejected`.
    pub fn latest(
        &mut self,
        input: &LastIn<T>,
        rejected: &mut Rejected,
        component: &str,
        name: &str,
    ) -> Option<T> {
        if let Some(packet) = rejected.check(input.take_new(), component, name) {
            self.newest = Some(packet);
        }
        self.newest.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_packet_with_a_value_that_is_not_finite_is_dropped_and_counted() {
        let mut rejected = Rejected::default();
        let good = Twist {
            linear: 0.2,
            angular: -1.0,
        };
        assert_eq!(rejected.check(Some(good.clone()), "m", "c"), Some(good));
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let twist = Twist {
                linear: 0.0,
                angular: bad,
            };
            assert_eq!(rejected.check(Some(twist), "m", "c"), None);
        }
        assert_eq!(rejected.check(None::<Twist>, "m", "c"), None);
        assert_eq!(rejected.count(), 3);
        let mut scan = RangeScan {
            stamp: coolbot::Time::default(),
            ir: [1.0; 8],
            us: [2.0; 8],
            bumpers: [false; 4],
        };
        assert!(scan.is_finite());
        scan.us[7] = f32::NAN;
        assert!(!scan.is_finite());
        let pose = Pose2D {
            x: 0.0,
            y: f64::INFINITY,
            theta: 0.0,
        };
        assert!(!pose.is_finite());
    }
}
