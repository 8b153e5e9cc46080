//! Filled-in `Navigation`: `holding` suspends the base (the robot stands still),
//! `driving` runs it again.

use crate::generated::navigation::*;

/// Keeps nothing.
#[derive(Debug, Default)]
pub struct NavigationSupervisor {}

impl Supervisor for NavigationSupervisor {
    fn driving_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.instances.base().run()?;
        Ok(())
    }

    fn holding_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.instances.base().suspend()?;
        Ok(())
    }
}

/// The crate's lidars and base.
#[derive(Debug, Default)]
pub struct NavigationParts {}

impl Parts for NavigationParts {
    fn supervisor(&mut self) -> impl Supervisor {
        NavigationSupervisor::default()
    }

    fn lidar(&mut self) -> impl crate::generated::lidar::Behavior {
        crate::lidar::Lidar::default()
    }

    fn spare(&mut self) -> impl crate::generated::lidar::Behavior {
        crate::lidar::Lidar::default()
    }

    fn base(&mut self) -> impl crate::generated::base::Parts {
        crate::base::BaseParts::default()
    }
}
