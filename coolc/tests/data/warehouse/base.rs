//! Filled-in `Base`: no supervisor sections.

use crate::generated::base::*;

/// Keeps nothing.
#[derive(Debug, Default)]
pub struct BaseSupervisor {}

impl Supervisor for BaseSupervisor {}

/// The crate's follower and drive.
#[derive(Debug, Default)]
pub struct BaseParts {}

impl Parts for BaseParts {
    fn supervisor(&mut self) -> impl Supervisor {
        BaseSupervisor::default()
    }

    fn follower(&mut self) -> impl crate::generated::follower::Behavior {
        crate::follower::Follower::default()
    }

    fn drive(&mut self) -> impl crate::generated::drive::Behavior {
        crate::drive::Drive::default()
    }
}
