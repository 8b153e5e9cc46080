//! The parts of compound `MobileBase`: its supervisor's sections and which
//! behaviour each instance runs.
//!
//! `coolc` wrote this file once and never overwrites it: new supervisor sections get
//! stubs at the end of the `impl Supervisor` block, new instances new methods at the
//! end of the `impl Parts` block. Build the compound with the generated module's
//! `component` function from a `MobileBaseParts` and add it to a
//! `coolbot::System` (or to another compound).

use crate::generated::mobile_base::*;

/// What `MobileBase`'s supervisor keeps between sections.
#[derive(Debug, Default)]
pub struct MobileBaseSupervisor {}

impl Supervisor for MobileBaseSupervisor {}

/// The behaviours `MobileBase`'s instances run: by default this crate's own.
#[derive(Debug, Default)]
pub struct MobileBaseParts {}

impl Parts for MobileBaseParts {
    fn supervisor(&mut self) -> impl Supervisor {
        // The supervisor: its sections are the `impl Supervisor` above.
        MobileBaseSupervisor::default()
    }

    fn motion(&mut self) -> impl crate::generated::motion_controller::Behavior {
        // Instance `motion`: the behavior it runs.
        crate::motion_controller::MotionController::default()
    }

    fn ranges(&mut self) -> impl crate::generated::range_server::Behavior {
        // Instance `ranges`: the behavior it runs.
        crate::range_server::RangeServer::default()
    }

    fn sim_ranges(&mut self) -> impl crate::generated::sim_range_server::Behavior {
        // Instance `sim_ranges`: the behavior it runs.
        crate::sim_range_server::SimRangeServer::default()
    }
}
