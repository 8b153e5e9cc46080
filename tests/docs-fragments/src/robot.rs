//! The parts of compound `Robot`: its supervisor's sections and which
//! behaviour each instance runs.
//!
//! `coolc` wrote this file once and never overwrites it: new supervisor sections get
//! stubs at the end of the `impl Supervisor` block, new instances new methods at the
//! end of the `impl Parts` block. Build the compound with the generated module's
//! `component` function from a `RobotParts` and add it to a
//! `coolbot::System` (or to another compound).

use crate::generated::robot::*;

/// What `Robot`'s supervisor keeps between sections.
#[derive(Debug, Default)]
pub struct RobotSupervisor {}

impl Supervisor for RobotSupervisor {}

/// The behaviours `Robot`'s instances run: by default this crate's own.
#[derive(Debug, Default)]
pub struct RobotParts {}

impl Parts for RobotParts {
    fn supervisor(&mut self) -> impl Supervisor {
        // The supervisor: its sections are the `impl Supervisor` above.
        RobotSupervisor::default()
    }

    fn base(&mut self) -> impl crate::generated::mobile_base::Parts {
        // Instance `base`: the parts it runs.
        crate::mobile_base::MobileBaseParts::default()
    }

    fn mapper(&mut self) -> impl crate::generated::mapper::Behavior {
        // Instance `mapper`: the behavior it runs.
        crate::mapper::Mapper::default()
    }
}
