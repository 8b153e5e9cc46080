//! Filled-in `MotionController`: integrates the commands it receives into its
//! odometry.

use crate::generated::motion_controller::*;

/// Commands executed so far.
#[derive(Debug, Default)]
pub struct MotionController {
    executed: u32,
}

impl Behavior for MotionController {
    fn idle_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let _ = cx;
        Ok(())
    }

    fn moving_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        while let Some(twist) = cx.inputs.command.recv() {
            let speed = twist.linear.min(cx.vars.max_speed);
            cx.vars.odometry.x += speed;
            cx.vars.odometry.theta += twist.angular;
            self.executed += 1;
        }
        cx.vars.last_command = Some(cx.rt.now());
        Ok(())
    }

    fn moving_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.vars.battery -= 0.001;
        cx.outputs.pose.send(cx.vars.odometry.clone());
        Ok(())
    }

    fn moving_exit(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let _ = cx;
        Ok(())
    }

    fn moving_choose(&mut self, cx: &mut Cx<'_>) -> Option<MovingMay> {
        (cx.vars.battery < 1.0).then_some(MovingMay::Stopped)
    }

    fn stopped_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let _ = cx;
        Ok(())
    }

    fn on_link_lost(&mut self, cx: &mut Cx<'_>, message: &str) {
        let _ = (cx, message);
    }

    fn on_stalled(&mut self, cx: &mut Cx<'_>, message: &str) {
        let _ = (cx, message);
    }

    fn on_overheated(&mut self, cx: &mut Cx<'_>, message: &str) {
        let _ = (cx, message);
    }
}
