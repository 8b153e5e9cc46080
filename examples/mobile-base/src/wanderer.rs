//! `Wanderer`: the behaviour that drives the base. It cruises with slow random heading
//! changes (or steers to a goal when `seek` is set), and turns on the spot away from
//! obstacles that get closer than its clearance.

use crate::finite::{Kept, Rejected};
use crate::generated::types::{Pose2D, RangeScan, Twist};
use crate::generated::wanderer::*;
use crate::sensing;
use crate::world::{Rng, wrap_angle};

/// How close to the goal counts as reached (m).
const GOAL_RADIUS: f64 = 0.3;
/// The way ahead is clear again when it is this open (m), below the infrared limit.
const CLEAR_AHEAD: f32 = 0.7;

/// The wanderer's code.
#[derive(Debug)]
pub struct Wanderer {
    rng: Option<Rng>,
    /// The current random turn rate while wandering (rad/s).
    drift: f64,
    /// Periods until the drift changes.
    drift_left: u32,
    /// Which way the current avoidance turns (+1 left, -1 right).
    turn: f64,
    /// The way ahead is blocked: the choice goes to `avoiding`.
    blocked: bool,
    /// The newest finite packets of `scan` and `pose`.
    scan: Kept<RangeScan>,
    pose: Kept<Pose2D>,
    rejected: Rejected,
}

impl Default for Wanderer {
    fn default() -> Self {
        Wanderer {
            rng: None,
            drift: 0.0,
            drift_left: 0,
            turn: 1.0,
            blocked: false,
            scan: Kept::default(),
            pose: Kept::default(),
            rejected: Rejected::default(),
        }
    }
}

impl Wanderer {
    /// The packets dropped from the inputs for a value that is not finite
    /// (`crate::finite`).
    pub fn rejected(&self) -> u64 {
        self.rejected.count()
    }

    /// The newest finite scan.
    fn scan(&mut self, cx: &Cx<'_>) -> Option<RangeScan> {
        let name = cx.rt.component_name();
        self.scan
            .latest(&cx.inputs.scan, &mut self.rejected, name, "scan")
    }

    /// The newest finite pose.
    fn pose(&mut self, cx: &Cx<'_>) -> Option<Pose2D> {
        let name = cx.rt.component_name();
        self.pose
            .latest(&cx.inputs.pose, &mut self.rejected, name, "pose")
    }
}

/// Mean of the ultrasonic ranges on one side (beams at 45 and 90 degrees).
fn side(scan: &RangeScan, left: bool) -> f32 {
    if left {
        (scan.us[1] + scan.us[2]) / 2.0
    } else {
        (scan.us[7] + scan.us[6]) / 2.0
    }
}

impl Behavior for Wanderer {
    fn wandering_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let _ = cx;
        self.blocked = false;
        Ok(())
    }

    fn wandering_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let Some(scan) = self.scan(cx) else {
            // No scan yet: do not drive blind.
            cx.outputs.command.send(Twist {
                linear: 0.0,
                angular: 0.0,
            });
            return Ok(());
        };
        let front = sensing::front(&scan);
        if front < cx.config.clearance {
            self.blocked = true;
            cx.outputs.command.send(Twist {
                linear: 0.0,
                angular: 0.0,
            });
            return Ok(());
        }
        let pose = if cx.vars.seek { self.pose(cx) } else { None };
        let seed = cx.config.seed;
        let rng = self.rng.get_or_insert_with(|| Rng::new(seed));
        let mut angular = if cx.vars.seek {
            match pose {
                Some(pose) => {
                    let (dx, dy) = (cx.config.goal_x - pose.x, cx.config.goal_y - pose.y);
                    if dx.hypot(dy) < GOAL_RADIUS {
                        cx.vars.goals_reached += 1;
                        cx.vars.seek = false;
                    }
                    (2.0 * wrap_angle(dy.atan2(dx) - pose.theta)).clamp(-1.5, 1.5)
                }
                None => 0.0,
            }
        } else {
            if self.drift_left == 0 {
                self.drift = (rng.uniform() - 0.5) * 1.2;
                self.drift_left = 10 + (rng.uniform() * 30.0) as u32;
            }
            self.drift_left -= 1;
            self.drift
        };
        // Keep away from walls on the sides: steer towards the more open side.
        let (left, right) = (side(&scan, true), side(&scan, false));
        if left.min(right) < 2.0 * cx.config.clearance {
            angular += 0.8 * f64::from((left - right).clamp(-1.0, 1.0));
        }
        // Slow down as the way ahead closes in.
        let room = f64::from(front / (3.0 * cx.config.clearance)).min(1.0);
        let linear = cx.config.cruise_speed * (0.4 + 0.6 * room);
        cx.outputs.command.send(Twist { linear, angular });
        Ok(())
    }

    fn wandering_choose(&mut self, cx: &mut Cx<'_>) -> Option<WanderingMay> {
        let _ = cx;
        self.blocked.then_some(WanderingMay::Avoiding)
    }

    fn avoiding_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.vars.avoidances += 1;
        // Turn towards the more open side.
        if let Some(scan) = self.scan(cx) {
            self.turn = if side(&scan, true) >= side(&scan, false) {
                1.0
            } else {
                -1.0
            };
        }
        Ok(())
    }

    fn avoiding_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.outputs.command.send(Twist {
            linear: 0.0,
            angular: self.turn * cx.config.turn_speed,
        });
        Ok(())
    }

    fn avoiding_choose(&mut self, cx: &mut Cx<'_>) -> Option<AvoidingMay> {
        let clear = self
            .scan(cx)
            .is_some_and(|scan| sensing::front(&scan) > CLEAR_AHEAD.min(1.8 * cx.config.clearance));
        clear.then_some(AvoidingMay::Wandering)
    }
}
