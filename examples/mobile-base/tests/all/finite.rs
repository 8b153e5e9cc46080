//! Values that are not finite from the inputs, in each component's generated harness
//! (a virtual clock, no thread): the motion controller, the wanderer and the mapper
//! drop the packet, count it and go on as if it never came (`mobile_base::finite`).

use std::sync::Arc;
use std::time::Duration;

use mobile_base::generated::types::{DriveMode, Pose2D, RangeScan, Twist};
use mobile_base::generated::{mapper, motion_controller, wanderer};
use mobile_base::mapper::Mapper;
use mobile_base::motion_controller::MotionController;
use mobile_base::wanderer::Wanderer;
use mobile_base::world::{Platform, World};

fn platform() -> Arc<Platform> {
    Arc::new(Platform::new(
        World::example(),
        World::example_start(),
        None,
    ))
}

fn twist(linear: f64, angular: f64) -> Twist {
    Twist { linear, angular }
}

/// A scan with every range `range` (m).
fn scan(range: f32) -> RangeScan {
    RangeScan {
        stamp: coolbot::Time::default(),
        ir: [range; 8],
        us: [range; 8],
        bumpers: [false; 4],
    }
}

fn finite_pose(pose: &Pose2D) -> bool {
    pose.x.is_finite() && pose.y.is_finite() && pose.theta.is_finite()
}

#[test]
fn the_motion_controller_drops_commands_and_scans_that_are_not_finite() {
    const PERIOD: Duration = Duration::from_millis(20);
    let platform = platform();
    let mut motion =
        motion_controller::Harness::running(MotionController::new(Arc::clone(&platform)))
            .expect("it starts");
    // A NaN command wakes the controller, and is dropped: it stands still, and no
    // collision is reported.
    motion.push_command(twist(f64::NAN, 0.0)).unwrap();
    motion.advance(PERIOD * 5).unwrap();
    assert_eq!(
        (motion.vars().halts, motion.vars().mode),
        (0, DriveMode::Normal)
    );
    assert_eq!(platform.truth().contacts, 0);
    assert!(finite_pose(&motion.vars().odometry));
    assert_eq!(motion.vars().speed, twist(0.0, 0.0));
    assert_eq!(motion.vars().target, twist(0.0, 0.0));
    assert_eq!(
        motion.user_state(),
        Some(motion_controller::UserState::Idle)
    );
    assert_eq!(motion.state(), coolbot::State::Running);
    assert_eq!(motion.behavior().rejected(), 1);

    // A finite command is executed; an infinite one after it is dropped, and the
    // target holds.
    motion.push_command(twist(0.3, 0.5)).unwrap();
    motion.advance(PERIOD).unwrap();
    assert_eq!(
        motion.user_state(),
        Some(motion_controller::UserState::Moving)
    );
    motion.push_command(twist(f64::INFINITY, 0.0)).unwrap();
    motion.advance(PERIOD).unwrap();
    assert_eq!(motion.vars().target, twist(0.3, 0.5));
    assert_eq!(motion.behavior().rejected(), 2);

    // Obstacles close by make it cautious; a scan of NaN ranges after them is
    // dropped, and the close scan still counts.
    motion.push_obstacles(scan(0.2)).unwrap();
    motion.advance(PERIOD).unwrap();
    assert_eq!(motion.vars().mode, DriveMode::Cautious);
    motion.push_obstacles(scan(f32::NAN)).unwrap();
    motion.advance(PERIOD * 3).unwrap();
    assert_eq!(motion.vars().mode, DriveMode::Cautious);
    assert_eq!(motion.behavior().rejected(), 3);
    assert!(motion.sent_pose().unwrap().iter().all(finite_pose));
    assert_eq!(platform.truth().contacts, 0);
    let truth = platform.truth().pose;
    assert!(truth.x.is_finite() && truth.y.is_finite() && truth.theta.is_finite());
}

#[test]
fn the_wanderer_does_not_drive_on_a_scan_or_steer_on_a_pose_that_is_not_finite() {
    const PERIOD: Duration = Duration::from_millis(50);
    let mut wanderer = wanderer::Harness::running(Wanderer::default()).expect("it starts");
    // A scan of NaN ranges is no scan: the wanderer does not drive blind.
    wanderer.push_scan(scan(f32::NAN)).unwrap();
    wanderer.advance(PERIOD).unwrap();
    assert_eq!(wanderer.sent_command().unwrap(), [twist(0.0, 0.0)]);
    assert_eq!(wanderer.behavior().rejected(), 1);

    // An open room: it cruises; a NaN scan after that is dropped, and it cruises on
    // the open one.
    let mut open = scan(3.0);
    open.ir = [0.8; 8];
    wanderer.push_scan(open).unwrap();
    wanderer.advance(PERIOD).unwrap();
    wanderer.push_scan(scan(f32::NAN)).unwrap();
    wanderer.advance(PERIOD).unwrap();
    let commands = wanderer.sent_command().unwrap();
    assert_eq!(commands.len(), 2);
    assert!(commands.iter().all(|c| c.linear > 0.0), "{commands:?}");
    assert_eq!(wanderer.behavior().rejected(), 2);
    assert_eq!(wanderer.user_state(), Some(wanderer::UserState::Wandering));

    // Seeking the goal from a pose that is not finite: the pose is dropped, and the
    // command it would have steered stays finite.
    wanderer.set_seek(true).unwrap();
    wanderer
        .push_pose(Pose2D {
            x: f64::NAN,
            y: 1.0,
            theta: 0.0,
        })
        .unwrap();
    wanderer.advance(PERIOD * 2).unwrap();
    let commands = wanderer.sent_command().unwrap();
    assert_eq!(commands.len(), 2);
    assert!(
        commands
            .iter()
            .all(|c| c.linear.is_finite() && c.angular.is_finite()),
        "{commands:?}"
    );
    assert_eq!(wanderer.behavior().rejected(), 3);
}

#[test]
fn the_mapper_drops_a_pose_that_is_not_finite() {
    let mut mapper = mapper::Harness::running(Mapper::new(platform())).expect("it starts");
    mapper
        .push_pose(Pose2D {
            x: 1.0,
            y: f64::NEG_INFINITY,
            theta: 0.0,
        })
        .unwrap();
    mapper.settle().unwrap();
    assert_eq!((mapper.vars().poses, mapper.vars().cells), (0, 0));
    assert_eq!(mapper.behavior().rejected(), 1);
    mapper
        .push_pose(Pose2D {
            x: 1.0,
            y: 2.0,
            theta: 0.0,
        })
        .unwrap();
    mapper.settle().unwrap();
    assert_eq!((mapper.vars().poses, mapper.vars().cells), (1, 1));
    assert_eq!(mapper.behavior().rejected(), 1);
}
