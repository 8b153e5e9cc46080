//! Filled-in `Base` supervisor: it commands its drive.

use std::time::Duration;

use crate::generated::base::*;
use crate::generated::drive::Config;

/// The supervisor keeps nothing between sections.
#[derive(Debug, Default)]
pub struct BaseSupervisor {}

impl Supervisor for BaseSupervisor {
    fn operating_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        // Whatever state the drive was left in, it runs again.
        cx.instances.motion().run()?;
        Ok(())
    }

    fn stopped_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.instances.motion().suspend()?;
        Ok(())
    }

    fn degraded_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let mut motion = cx.instances.motion();
        motion.set_speed(0.25)?;
        motion.set_quality(MotionQuality::Eco)?;
        motion.configure(Config { accel: 0.5 })?;
        // Refused (a zero period), with the reason: counted, not fatal.
        if let Err(error) = motion.set_period(Duration::ZERO) {
            assert_eq!(error.reason, coolbot::Refused::ZeroPeriod);
            cx.vars.refusals += 1;
        }
        Ok(())
    }

    fn checking_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let _ = cx;
        Ok(())
    }

    fn checking_choose(&mut self, cx: &mut Cx<'_>) -> Option<CheckingMay> {
        let _ = cx;
        Some(CheckingMay::Judged)
    }

    fn judged_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.rt
            .set_result(coolbot::TaskResult::Fail("the check failed".to_owned()));
        Ok(())
    }

    fn timed_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        let _ = cx;
        Ok(())
    }
}

/// The drive runs this crate's `Drive`.
#[derive(Debug, Default)]
pub struct BaseParts {}

impl Parts for BaseParts {
    fn supervisor(&mut self) -> impl Supervisor {
        BaseSupervisor::default()
    }

    fn motion(&mut self) -> impl crate::generated::drive::Behavior {
        crate::drive::Drive::default()
    }
}
