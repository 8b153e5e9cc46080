//! `--ros2`: the robot as a ROS 2 node on the rmw_zenoh wire (`coolbot_zenoh::ros2`),
//! with its own Zenoh session on the ROS 2 router: `/scan` and `/odom` go out from
//! the relay (`crate::topics`), `/cmd_vel` comes in to the robot's input `teleop`
//! through the converter `TwistFromRos`.

use coolbot::System;
use coolbot_zenoh::ros2::{self, Direction, Participant, RosOptions};
use coolbot_zenoh::zenoh::Wait;

use crate::TopicCount;
use crate::converters::Convert;
use crate::generated::types::{Converters, LaserScan, Odometry};
use crate::robot::ROBOT;
use crate::topics::{CMD_VEL, ODOM, ODOM_PORT, SCAN, SCAN_PORT};

/// Where and as whom the robot joins ROS 2.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RosSetup {
    /// The Zenoh router's endpoint (`ros2::DEFAULT_ROUTER`, rmw_zenoh's).
    pub router: String,
    /// The ROS domain id.
    pub domain: u32,
    /// The node's namespace (`/` by default); relative topics are in it.
    pub namespace: String,
    /// The node's name.
    pub node: String,
}

impl Default for RosSetup {
    fn default() -> RosSetup {
        RosSetup {
            router: ros2::DEFAULT_ROUTER.to_owned(),
            domain: 0,
            namespace: "/".to_owned(),
            node: "mobile_base".to_owned(),
        }
    }
}

/// The robot's ROS 2 node while it runs.
pub struct RosNode {
    participant: Participant,
    session: zenoh::Session,
}

impl std::fmt::Debug for RosNode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RosNode").finish_non_exhaustive()
    }
}

fn text(error: impl std::error::Error) -> String {
    coolbot::Chain(&error).to_string()
}

/// Joins ROS 2 as `setup` says: publishes the relay's `/scan` and `/odom` (the relay
/// must be on `system`) and delivers `/cmd_vel` to the robot's `teleop`. The topics
/// are relative names: in the node's namespace.
pub fn join(system: &mut System, setup: &RosSetup) -> Result<RosNode, String> {
    let session = ros2::open_router(&setup.router).map_err(text)?;
    let options = RosOptions {
        domain: setup.domain,
        namespace: setup.namespace.clone(),
        node: setup.node.clone(),
    };
    let participant = Participant::open(&session, &options).map_err(text)?;
    let relative = |topic: &str| topic.trim_start_matches('/').to_owned();
    participant
        .publish::<LaserScan>(system, &relative(SCAN), SCAN_PORT)
        .map_err(text)?;
    participant
        .publish::<Odometry>(system, &relative(ODOM), ODOM_PORT)
        .map_err(text)?;
    participant
        .subscribe_via(
            system,
            &relative(CMD_VEL),
            &format!("{ROBOT}.teleop"),
            Convert::twist_from_ros,
        )
        .map_err(text)?;
    // The publishers and the subscription run with the robot.
    system.run_all().map_err(text)?;
    Ok(RosNode {
        participant,
        session,
    })
}

impl RosNode {
    /// The ROS 2 subscription component's output of `/cmd_vel` (its messages as
    /// ROS 2 sends them), for a rosbag2 recording.
    pub fn cmd_vel_port(&self) -> String {
        format!(
            "ros2_sub_{}.output",
            CMD_VEL.trim_start_matches('/').replace('/', "_")
        )
    }

    /// What went through each topic so far.
    pub fn counts(&self) -> Vec<TopicCount> {
        self.participant
            .counts()
            .into_iter()
            .map(|count| TopicCount {
                topic: count.topic,
                type_name: count.type_name.to_owned(),
                outgoing: count.direction == Direction::Out,
                messages: count.messages,
                lost: count.lost,
            })
            .collect()
    }

    /// Leaves ROS 2: the session closes (its liveliness tokens go with it).
    pub fn close(self) {
        drop(self.participant);
        let _ = self.session.close().wait();
    }
}
