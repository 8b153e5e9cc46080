//! The API fragments of the docs, each in a function of its own (compiled, never
//! run), written by the build script from the table `places::FRAGMENTS`, after the
//! declarations every fragment function sees.
// The fragments are statements of the docs as written: what they leave unused, the
// full paths they spell out and their style are not this crate's to lint.
#![allow(unused, unused_qualifications, clippy::all)]

use std::time::Duration;

use coolbot::{CompoundBuilder, Policy, State, System};
use coolbot_zenoh::Node;

use crate::Fragment;
use crate::generated::types::{LaserScan, Map, Odometry, Path, Pose2D, RangeScan, Twist};
use crate::generated::{
    mapper, mobile_base, motion_controller, planner, range_server, robot, sim_range_server,
};
use crate::motion_controller::MotionController as MyMotion;
use crate::planner::Planner as MyPlanner;
use crate::range_server::RangeServer as MyRanges;
use crate::robot::RobotParts;
use crate::sim_range_server::SimRangeServer as MySim;

/// A hand-written supervisor of `MobileBase`'s shape.
#[derive(Default)]
struct MobileBaseSupervisor;

impl coolbot::Supervisor for MobileBaseSupervisor {
    fn spec(&self) -> &'static coolbot::Spec {
        &mobile_base::SPEC
    }
}

/// A converter for `connect_via`.
fn path_to_twist(path: &Path) -> Twist {
    Twist {
        linear: path.poses.len() as f64,
        angular: 0.0,
    }
}

include!(concat!(env!("OUT_DIR"), "/fragments.rs"));
