//! The range servers read the world at the pose of their `pose` input (the motion
//! controller's odometry), not at the platform's own: so a range server in another
//! process (`--drivers`), whose platform no motion controller drives, sees the robot
//! move. Each server alone in its generated harness (a virtual clock, no thread), on
//! a platform that stays at its start.

use std::f64::consts::FRAC_PI_2;
use std::sync::Arc;
use std::time::Duration;

use mobile_base::generated::types::{Pose2D, RangeScan};
use mobile_base::generated::{range_server, sim_range_server};
use mobile_base::range_server::RangeServer;
use mobile_base::sensing::{self, Overrides};
use mobile_base::sim_range_server::SimRangeServer;
use mobile_base::world::{Platform, Pose, World};

const PERIOD: Duration = Duration::from_millis(50);

fn platform() -> Arc<Platform> {
    Arc::new(Platform::new(
        World::example(),
        World::example_start(),
        None,
    ))
}

/// Below the pillar at (1.2, 3.0), facing it; and in the room's right half, facing
/// the right wall. Neither is where the platform is.
const NEAR_PILLAR: Pose2D = Pose2D {
    x: 1.2,
    y: 2.2,
    theta: FRAC_PI_2,
};
const RIGHT_HALF: Pose2D = Pose2D {
    x: 5.0,
    y: 2.0,
    theta: 0.0,
};

/// What the sensors of a robot at `pose` read, noise-free, as a scan's ranges.
fn seen_from(pose: &Pose2D) -> ([f32; 8], [f32; 8], [bool; 4]) {
    let pose = Pose {
        x: pose.x,
        y: pose.y,
        theta: pose.theta,
    };
    let scan = sensing::scan(
        coolbot::Time::default(),
        &World::example().sense(pose, 0.8, 3.0),
    );
    (scan.ir, scan.us, scan.bumpers)
}

fn ranges(scan: &RangeScan) -> ([f32; 8], [f32; 8], [bool; 4]) {
    (scan.ir, scan.us, scan.bumpers)
}

#[test]
fn the_range_server_reads_nothing_before_a_pose_then_the_world_at_each_pose() {
    let noise_free = Overrides {
        noise: Some(0.0),
        ..Overrides::default()
    };
    let mut server = range_server::Harness::running(RangeServer::new(platform(), noise_free))
        .expect("it starts");
    // Every scan read is published: the server throttles its publications by the
    // real clock, which does not move with the harness's.
    server.set_frequency(200.0).expect("the frequency");
    server.advance(PERIOD * 4).expect("four periods");
    assert!(
        server.sent_scan().expect("scans").is_empty(),
        "no scan before a pose came"
    );
    assert_eq!(server.state(), coolbot::State::Running);

    server.push_pose(NEAR_PILLAR).expect("a pose");
    server.advance(PERIOD).expect("a period");
    let scans = server.sent_scan().expect("scans");
    assert!(!scans.is_empty(), "a scan once the pose came");
    for scan in &scans {
        assert_eq!(ranges(scan), seen_from(&NEAR_PILLAR));
    }
    assert_ne!(seen_from(&NEAR_PILLAR), seen_from(&RIGHT_HALF));

    server.push_pose(RIGHT_HALF).expect("a pose");
    server.advance(PERIOD).expect("a period");
    let scans = server.sent_scan().expect("scans");
    assert!(!scans.is_empty());
    for scan in &scans {
        assert_eq!(ranges(scan), seen_from(&RIGHT_HALF));
    }

    // A pose that is not finite is dropped and counted: the one before stays.
    server
        .push_pose(Pose2D {
            x: f64::NAN,
            ..RIGHT_HALF
        })
        .expect("a pose");
    server.advance(PERIOD).expect("a period");
    let scans = server.sent_scan().expect("scans");
    assert!(!scans.is_empty());
    for scan in &scans {
        assert_eq!(ranges(scan), seen_from(&RIGHT_HALF));
    }
    assert_eq!(server.behavior().rejected(), 1);
}

#[test]
fn the_simulated_range_server_computes_the_scan_at_the_odometry_pose() {
    let mut server =
        sim_range_server::Harness::running(SimRangeServer::new(platform(), Overrides::default()))
            .expect("it starts");
    server.advance(PERIOD * 4).expect("four periods");
    assert!(
        server.sent_scan().expect("scans").is_empty(),
        "no scan before a pose came"
    );
    for pose in [NEAR_PILLAR, RIGHT_HALF] {
        server.push_pose(pose.clone()).expect("a pose");
        server.advance(PERIOD).expect("a period");
        let scans = server.sent_scan().expect("scans");
        assert!(!scans.is_empty(), "a scan at {pose:?}");
        for scan in &scans {
            assert_eq!(ranges(scan), seen_from(&pose));
        }
    }
    server
        .push_pose(Pose2D {
            theta: f64::INFINITY,
            ..NEAR_PILLAR
        })
        .expect("a pose");
    server.advance(PERIOD).expect("a period");
    for scan in &server.sent_scan().expect("scans") {
        assert_eq!(ranges(scan), seen_from(&RIGHT_HALF));
    }
    assert_eq!(server.behavior().rejected(), 1);
}
