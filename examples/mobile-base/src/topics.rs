//! The robot's ROS 2 messages (`examples/components/ros_topics.cool`): the relay
//! `RosTopics`, added beside the robot when the run speaks ROS 2 (`--ros2`, or a
//! rosbag2 recording): the base's scans and odometry converted to
//! `sensor_msgs/msg/LaserScan` and `nav_msgs/msg/Odometry` on its outputs `ros.scan`
//! and `ros.odom`, and the topics they go on.

use coolbot::System;

use crate::converters::Convert;
use crate::generated::ros_topics::{self, Behavior, Cx};
use crate::generated::types::Converters;
use crate::robot::ROBOT;

/// The relay's name on the robot's system.
pub const RELAY: &str = "ros";
/// The topic of the scans (`ros.scan`).
pub const SCAN: &str = "/scan";
/// The topic of the odometry (`ros.odom`).
pub const ODOM: &str = "/odom";
/// The topic of the velocity commands (to the robot's input `teleop`).
pub const CMD_VEL: &str = "/cmd_vel";
/// The relay's output of the scans.
pub const SCAN_PORT: &str = "ros.scan";
/// The relay's output of the odometry.
pub const ODOM_PORT: &str = "ros.odom";

/// The relay's code: passes on what arrives.
#[derive(Debug, Default)]
pub struct Relay;

impl Behavior for Relay {
    fn relaying_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        for scan in cx.inputs.scan_in.drain() {
            cx.outputs.scan.send(scan);
        }
        for odom in cx.inputs.odom_in.drain() {
            cx.outputs.odom.send(odom);
        }
        Ok(())
    }
}

/// Adds the relay to `system`, fed by the robot's outputs `scan` and `pose` through
/// the converters, and sets it running.
pub fn add_relay(system: &mut System) -> Result<(), String> {
    let component = ros_topics::component(RELAY, Relay);
    system.add(component).map_err(text)?;
    system
        .connect_via(
            &format!("{ROBOT}.scan"),
            &format!("{RELAY}.scan_in"),
            Convert::scan_to_laser,
        )
        .map_err(text)?;
    system
        .connect_via(
            &format!("{ROBOT}.pose"),
            &format!("{RELAY}.odom_in"),
            Convert::pose_to_odometry,
        )
        .map_err(text)?;
    // Added to a started system, it starts at once; it runs with the robot.
    system.run_all().map_err(text)?;
    Ok(())
}

fn text(error: impl std::error::Error) -> String {
    coolbot::Chain(&error).to_string()
}
