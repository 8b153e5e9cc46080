//! `MotionController` (paper Figure 4, left): executes motion commands on the
//! simulated differential-drive platform every period.

use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::finite::{Kept, Rejected};
use crate::generated::motion_controller::*;
use crate::generated::types::{DriveMode, Pose2D, RangeScan, Twist};
use crate::sensing;
use crate::world::Platform;

/// The longest step integrated at once (s): a late period does not teleport the robot.
const MAX_STEP: f64 = 0.1;
/// The platform's set-point watchdog: without a new set-point for this long, it stops
/// the wheels.
const WATCHDOG: Duration = Duration::from_millis(250);

/// The motion controller's code: it owns the platform's drive.
#[derive(Debug)]
pub struct MotionController {
    platform: Arc<Platform>,
    last_step: Option<Instant>,
    /// The newest finite scan of `obstacles`.
    obstacles: Kept<RangeScan>,
    rejected: Rejected,
}

impl MotionController {
    /// A controller driving `platform`.
    pub fn new(platform: Arc<Platform>) -> MotionController {
        MotionController {
            platform,
            last_step: None,
            obstacles: Kept::default(),
            rejected: Rejected::default(),
        }
    }

    /// The packets dropped from the inputs for a value that is not finite
    /// (`crate::finite`).
    pub fn rejected(&self) -> u64 {
        self.rejected.count()
    }

    /// The next command of `command`, if one came and its values are finite (one that
    /// is not is dropped: the target stays).
    fn command(&mut self, cx: &mut Cx<'_>) -> Option<Twist> {
        let command = cx.inputs.command.recv();
        self.rejected
            .check(command, cx.rt.component_name(), "command")
    }

    /// One integration step towards `target` under the speed, acceleration and turn
    /// limits; publishes the odometry.
    fn step(&mut self, cx: &mut Cx<'_>, target: Twist) -> coolbot::SectionResult {
        // The run's clock (a virtual one in tests), as the runtime's periods are.
        let now = self.platform.now();
        let gap = self
            .last_step
            .map_or(Duration::ZERO, |last| now.duration_since(last));
        self.last_step = Some(now);
        if gap > WATCHDOG && cx.vars.speed != still() {
            // The wheels were stopped by the platform; the plan retries this section.
            cx.vars.speed = still();
            return Err(
                Exception::Watchdog.raise(format!("no set-point for {} ms", gap.as_millis()))
            );
        }
        let dt = gap.as_secs_f64().min(MAX_STEP);

        let near = self
            .obstacles
            .latest(
                &cx.inputs.obstacles,
                &mut self.rejected,
                cx.rt.component_name(),
                "obstacles",
            )
            .map(|scan| sensing::front(&scan));
        let cautious = near.is_some_and(|d| f64::from(d) < cx.config.cautious_distance);
        if cx.vars.mode != DriveMode::Halted {
            cx.vars.mode = if cautious {
                DriveMode::Cautious
            } else {
                DriveMode::Normal
            };
        }
        let mut limit = cx.vars.max_speed.max(0.0);
        if cautious {
            limit *= cx.config.cautious_factor;
        }
        let wanted = target.linear.clamp(-limit, limit);
        let accel = cx.config.max_accel * dt;
        let linear = cx.vars.speed.linear + (wanted - cx.vars.speed.linear).clamp(-accel, accel);
        let angular = target
            .angular
            .clamp(-cx.config.max_turn_rate, cx.config.max_turn_rate);

        // A bus that hangs once (`Platform::hiccup`) holds the section up.
        cx.rt.spend(self.platform.bus_delay());
        let drive = self.platform.drive(linear, angular, dt);
        cx.vars.distance += drive.moved;
        cx.vars.odometry = Pose2D {
            x: drive.pose.x,
            y: drive.pose.y,
            theta: drive.pose.theta,
        };
        cx.outputs.pose.send(cx.vars.odometry.clone());
        if drive.blocked {
            cx.vars.speed = Twist {
                linear: 0.0,
                angular: 0.0,
            };
            return Err(Exception::WheelStall.raise(format!(
                "blocked at ({:.2}, {:.2}) while commanded {linear:.2} m/s",
                drive.pose.x, drive.pose.y
            )));
        }
        cx.vars.speed = Twist { linear, angular };
        Ok(())
    }
}

fn still() -> Twist {
    Twist {
        linear: 0.0,
        angular: 0.0,
    }
}

impl Behavior for MotionController {
    fn start(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let pose = self.platform.truth().pose;
        cx.vars.odometry = Pose2D {
            x: pose.x,
            y: pose.y,
            theta: pose.theta,
        };
        self.last_step = None;
        Ok(())
    }

    fn idle_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.vars.target = still();
        if cx.vars.mode == DriveMode::Halted {
            cx.vars.mode = DriveMode::Normal;
        }
        Ok(())
    }

    fn idle_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        // Standing still (braking if still rolling); the odometry is still published.
        self.step(cx, still())
    }

    fn moving_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        // Emergencies signalled before moving are stale. The command that woke the
        // controller is the first target.
        cx.inputs.halt.take();
        if let Some(command) = self.command(cx) {
            cx.vars.target = command;
        }
        Ok(())
    }

    fn moving_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        // One command per period, in order; without a new one the last one holds.
        if let Some(command) = self.command(cx) {
            cx.vars.target = command;
        }
        let target = cx.vars.target.clone();
        self.step(cx, target)
    }

    fn moving_exit(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.vars.target = still();
        Ok(())
    }

    fn moving_choose(&mut self, cx: &mut Cx<'_>) -> Option<MovingMay> {
        // Told to stand still and standing still: back to idle.
        let resting = cx.vars.target == still() && cx.vars.speed.linear.abs() < 1e-3;
        resting.then_some(MovingMay::Idle)
    }

    fn stopped_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        // Emergency brake: the platform stops at once.
        cx.vars.halts += 1;
        cx.vars.mode = DriveMode::Halted;
        cx.vars.target = still();
        cx.vars.speed = still();
        cx.inputs.halt.take();
        Ok(())
    }

    fn stopped_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        // Commands that arrive while stopped are discarded, not queued for later.
        cx.inputs.command.drain().for_each(drop);
        cx.inputs.halt.take();
        self.step(cx, still())
    }

    fn on_wheel_stall(&mut self, cx: &mut Cx<'_>, message: &str) {
        // The plan (`goto stopped`) stops the platform; remember why.
        let _ = message;
        cx.vars.mode = DriveMode::Halted;
    }

    fn on_watchdog(&mut self, cx: &mut Cx<'_>, message: &str) {
        // The wheels stopped: the retry starts again from standstill.
        let _ = message;
        cx.vars.watchdog_trips += 1;
        cx.vars.speed = still();
    }
}
