//! The converters between the robot's packets and the ROS 2 messages of its topics
//! (`examples/components/ros_topics.cool`): `/scan`, `/odom` and `/cmd_vel`.

use std::f64::consts::FRAC_PI_4;
use std::time::{SystemTime, UNIX_EPOCH};

use crate::generated::types::ros::builtin_interfaces::Time;
use crate::generated::types::ros::geometry_msgs::{Point, Pose, PoseWithCovariance, Quaternion};
use crate::generated::types::ros::std_msgs::Header;
use crate::generated::types::{LaserScan, Odometry, Pose2D, RangeScan, RosTwist, Twist};
use crate::world::{ROBOT_RADIUS, US_BEAMS};

/// The frame of the platform's centre.
pub const BASE_FRAME: &str = "base_link";
/// The frame the odometry integrates in.
pub const ODOM_FRAME: &str = "odom";
/// The ultrasonic sensors' maximum range from the rim (m): the range servers'
/// `us_max_range` by default.
pub const US_MAX_RANGE: f32 = 3.0;

/// Implements the generated `Converters` trait.
#[derive(Debug, Default)]
pub struct Convert;

/// The wall clock as a ROS 2 time.
fn now() -> Time {
    let since = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap_or_default();
    Time {
        sec: i32::try_from(since.as_secs()).unwrap_or(i32::MAX),
        nanosec: since.subsec_nanos(),
    }
}

fn header(frame: &str) -> Header {
    Header {
        stamp: now(),
        frame_id: frame.to_owned(),
    }
}

impl crate::generated::types::Converters for Convert {
    /// The ultrasonic ring, counter-clockwise from straight ahead every 45 degrees,
    /// ranges from the centre: from the robot's radius to the maximum range plus it.
    fn scan_to_laser(from: &RangeScan) -> LaserScan {
        let radius = ROBOT_RADIUS as f32;
        LaserScan {
            header: header(BASE_FRAME),
            angle_min: 0.0,
            angle_max: (FRAC_PI_4 * (US_BEAMS - 1) as f64) as f32,
            angle_increment: FRAC_PI_4 as f32,
            range_min: radius,
            range_max: US_MAX_RANGE + radius,
            ranges: from.us.iter().map(|range| range + radius).collect(),
            ..LaserScan::default()
        }
    }

    fn pose_to_odometry(from: &Pose2D) -> Odometry {
        let half = from.theta / 2.0;
        Odometry {
            header: header(ODOM_FRAME),
            child_frame_id: BASE_FRAME.to_owned(),
            pose: PoseWithCovariance {
                pose: Pose {
                    position: Point {
                        x: from.x,
                        y: from.y,
                        z: 0.0,
                    },
                    orientation: Quaternion {
                        x: 0.0,
                        y: 0.0,
                        z: half.sin(),
                        w: half.cos(),
                    },
                },
                ..PoseWithCovariance::default()
            },
            ..Odometry::default()
        }
    }

    /// Forward speed and turn rate; the other components are ignored (a
    /// differential drive has no others).
    fn twist_from_ros(from: &RosTwist) -> Twist {
        Twist {
            linear: from.linear.x,
            angular: from.angular.z,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::generated::types::Converters;
    use crate::generated::types::ros::geometry_msgs::Vector3;

    #[test]
    fn a_scan_is_the_ultrasonic_ring_from_the_centre() {
        let scan = RangeScan {
            stamp: coolbot::Time::default(),
            ir: [0.5; 8],
            us: [0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 1.0],
            bumpers: [false; 4],
        };
        let laser = Convert::scan_to_laser(&scan);
        assert_eq!(laser.header.frame_id, "base_link");
        assert!(laser.header.stamp.sec > 0);
        assert_eq!(laser.ranges.len(), 8);
        assert!((laser.ranges[2] - 1.18).abs() < 1e-6);
        assert!(
            laser
                .ranges
                .iter()
                .all(|r| (laser.range_min..=laser.range_max).contains(r))
        );
        let last = laser.angle_min + 7.0 * laser.angle_increment;
        assert!((last - laser.angle_max).abs() < 1e-6);
    }

    #[test]
    fn a_pose_is_odometry_with_its_heading_as_a_quaternion() {
        let odom = Convert::pose_to_odometry(&Pose2D {
            x: 1.0,
            y: 2.0,
            theta: std::f64::consts::FRAC_PI_2,
        });
        assert_eq!(
            (odom.header.frame_id.as_str(), odom.child_frame_id.as_str()),
            ("odom", "base_link")
        );
        let q = &odom.pose.pose.orientation;
        assert_eq!(odom.pose.pose.position.x, 1.0);
        assert!((q.z - 0.5f64.sqrt()).abs() < 1e-12 && (q.w - 0.5f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn a_ros_twist_keeps_forward_speed_and_turn_rate() {
        let twist = Convert::twist_from_ros(&RosTwist {
            linear: Vector3 {
                x: 0.2,
                y: 9.0,
                z: 9.0,
            },
            angular: Vector3 {
                x: 9.0,
                y: 9.0,
                z: -0.5,
            },
        });
        assert_eq!(
            twist,
            Twist {
                linear: 0.2,
                angular: -0.5
            }
        );
    }
}
