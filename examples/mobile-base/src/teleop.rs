//! `Teleop`: passes the wanderer's commands to the base, or the newest outside
//! command (a ROS 2 `/cmd_vel`) while the robot's supervisor sets `follow` and outside
//! commands keep arriving (its user state `commanded`, left when no finite one came
//! for the configuration's `timeout`, on the component's clock). An outside command
//! with a value that is not finite is refused and counted (`refused`,
//! `crate::finite`): it neither starts nor prolongs teleoperation.

use crate::finite::Rejected;
use crate::generated::teleop::*;
use crate::generated::types::Twist;

/// The teleoperation switch's code.
#[derive(Debug, Default)]
pub struct Teleop {
    /// The newest finite outside command in this state, if any.
    newest: Option<Twist>,
    /// When the newest finite outside command came.
    since: Option<coolbot::Time>,
    rejected: Rejected,
}

impl Teleop {
    /// Takes the outside commands that arrived: keeps the newest finite one, counts
    /// them (`received`, `refused`).
    fn take_remote(&mut self, cx: &mut Cx<'_>) {
        while let Some(command) = cx.inputs.remote.recv() {
            match self
                .rejected
                .check(Some(command), cx.rt.component_name(), "remote")
            {
                Some(command) => {
                    cx.vars.received += 1;
                    self.newest = Some(command);
                    self.since = Some(cx.rt.now());
                }
                None => cx.vars.refused = self.rejected.count(),
            }
        }
    }

    /// The wanderer's commands: to the base unless outside commands drive it.
    fn pass_wanderer(cx: &mut Cx<'_>, drop: bool) {
        for command in cx.inputs.wander.drain() {
            if !drop {
                cx.outputs.command.send(command);
            }
        }
    }
}

impl Behavior for Teleop {
    fn quiet_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        self.take_remote(cx);
        Self::pass_wanderer(cx, cx.vars.follow);
        Ok(())
    }

    fn quiet_choose(&mut self, cx: &mut Cx<'_>) -> Option<QuietMay> {
        let _ = cx;
        self.newest.is_some().then_some(QuietMay::Commanded)
    }

    fn commanded_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        self.take_remote(cx);
        let follow = cx.vars.follow;
        Self::pass_wanderer(cx, follow);
        // A command as old as the timeout is not sent: `choose`, which runs after
        // this section, goes quiet in this very period.
        if follow
            && !stale(self.since, cx)
            && let Some(command) = &self.newest
        {
            cx.outputs.command.send(command.clone());
        }
        Ok(())
    }

    fn commanded_choose(&mut self, cx: &mut Cx<'_>) -> Option<CommandedMay> {
        if !stale(self.since, cx) {
            return None;
        }
        // Stale from here on: `quiet` starts with none.
        self.newest = None;
        self.since = None;
        Some(CommandedMay::Quiet)
    }
}

/// Whether the newest command, received at `since`, is as old as the timeout.
fn stale(since: Option<coolbot::Time>, cx: &Cx<'_>) -> bool {
    let now = cx.rt.now().0;
    let since = since.map_or(0, |since| since.0);
    let timeout = u64::try_from(cx.config.timeout.as_nanos()).unwrap_or(u64::MAX);
    now.saturating_sub(since) >= timeout
}
