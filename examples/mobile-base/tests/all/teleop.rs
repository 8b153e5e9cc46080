//! Teleoperation: the `Teleop` switch alone in its generated harness, and the robot's
//! supervisor alone in its own (`generated::robot::Harness`), both on a virtual clock
//! with no thread. The switch passes the wanderer's commands until outside commands
//! arrive and the supervisor sets `follow`; the supervisor follows the switch's user
//! state and says so in its own.

use std::sync::Arc;
use std::time::Duration;

use coolbot::{Command, Value};
use mobile_base::generated::robot::UserState as RobotState;
use mobile_base::generated::teleop::{self, UserState};
use mobile_base::generated::types::Twist;
use mobile_base::generated::{
    mapper, mobile_base as base, motion_controller, range_server, robot, sim_range_server, wanderer,
};
use mobile_base::mapper::Mapper;
use mobile_base::motion_controller::MotionController;
use mobile_base::range_server::RangeServer;
use mobile_base::robot::{BaseSupervisor, RobotSupervisor};
use mobile_base::sim_range_server::SimRangeServer;
use mobile_base::teleop::Teleop;
use mobile_base::wanderer::Wanderer;
use mobile_base::world::{Platform, World};

fn twist(linear: f64, angular: f64) -> Twist {
    Twist { linear, angular }
}

const PERIOD: Duration = Duration::from_millis(20);

#[test]
fn outside_commands_drive_the_base_while_they_arrive_and_the_supervisor_lets_them() {
    let mut h = teleop::Harness::running(Teleop::default()).unwrap();
    assert_eq!(h.user_state(), Some(UserState::Quiet));
    // Quiet: the wanderer's commands go through, in order.
    h.push_wander(twist(0.3, 0.1)).unwrap();
    h.push_wander(twist(0.3, 0.2)).unwrap();
    h.advance(PERIOD).unwrap();
    assert_eq!(
        h.sent_command().unwrap(),
        [twist(0.3, 0.1), twist(0.3, 0.2)]
    );

    // An outside command: `commanded`, but without `follow` the wanderer still drives.
    h.push_remote(twist(-0.1, 0.5)).unwrap();
    h.advance(PERIOD).unwrap();
    assert_eq!(h.user_state(), Some(UserState::Commanded));
    assert_eq!(h.vars().received, 1);
    h.push_wander(twist(0.3, 0.0)).unwrap();
    h.advance(PERIOD).unwrap();
    assert_eq!(h.sent_command().unwrap(), [twist(0.3, 0.0)]);

    // The supervisor lets it: the newest outside command every period, the wanderer's
    // dropped.
    h.set_follow(true).unwrap();
    h.push_wander(twist(0.3, 0.0)).unwrap();
    h.push_remote(twist(0.2, -0.4)).unwrap();
    h.advance(PERIOD).unwrap();
    h.advance(PERIOD).unwrap();
    assert_eq!(
        h.sent_command().unwrap(),
        [twist(0.2, -0.4), twist(0.2, -0.4)]
    );

    // Outside commands stop: after 500 ms the switch is quiet again.
    h.advance(Duration::from_millis(400)).unwrap();
    assert_eq!(h.user_state(), Some(UserState::Commanded));
    let sent = h.sent_command().unwrap();
    assert!(
        !sent.is_empty() && sent.iter().all(|t| *t == twist(0.2, -0.4)),
        "{sent:?}"
    );
    // Period by period until quiet: the command goes each period, and not in the
    // period that goes quiet (it is as old as the timeout then).
    let mut periods = 0;
    loop {
        h.advance(PERIOD).unwrap();
        let sent = h.sent_command().unwrap();
        if h.user_state() == Some(UserState::Quiet) {
            assert!(sent.is_empty(), "a stale command was sent: {sent:?}");
            break;
        }
        assert_eq!(sent, [twist(0.2, -0.4)]);
        periods += 1;
        assert!(periods < 10, "never quiet");
    }
    // Quiet with `follow` still set (until the supervisor moves): nothing stale is sent.
    h.push_wander(twist(0.3, 0.0)).unwrap();
    h.advance(PERIOD).unwrap();
    assert!(h.sent_command().unwrap().is_empty());
    h.set_follow(false).unwrap();
    h.push_wander(twist(0.3, 0.0)).unwrap();
    h.advance(PERIOD).unwrap();
    assert_eq!(h.sent_command().unwrap(), [twist(0.3, 0.0)]);
}

#[test]
fn an_outside_command_that_is_not_finite_is_refused_and_starts_nothing() {
    let mut h = teleop::Harness::running(Teleop::default()).unwrap();
    for bad in [f64::NAN, f64::INFINITY] {
        h.push_remote(twist(bad, 0.0)).unwrap();
        h.advance(PERIOD).unwrap();
    }
    assert_eq!(h.user_state(), Some(UserState::Quiet));
    assert_eq!((h.vars().received, h.vars().refused), (0, 2));

    h.set_follow(true).unwrap();
    h.push_remote(twist(0.2, 0.0)).unwrap();
    h.advance(PERIOD).unwrap();
    assert_eq!(h.user_state(), Some(UserState::Commanded));
    h.sent_command().unwrap();
    // While commanded, a bad one is refused and the last good one stays.
    h.push_remote(twist(0.0, f64::NEG_INFINITY)).unwrap();
    h.advance(PERIOD).unwrap();
    assert_eq!(h.sent_command().unwrap(), [twist(0.2, 0.0)]);
    assert_eq!((h.vars().received, h.vars().refused), (1, 3));
}

/// The robot's parts around a platform nothing drives (the instances are stand-ins:
/// their behaviours are built, never run).
struct RobotParts(Arc<Platform>);
struct BaseParts(Arc<Platform>);

impl base::Parts for BaseParts {
    fn supervisor(&mut self) -> impl base::Supervisor {
        BaseSupervisor::default()
    }
    fn motion(&mut self) -> impl motion_controller::Behavior {
        MotionController::new(Arc::clone(&self.0))
    }
    fn ranges(&mut self) -> impl range_server::Behavior {
        RangeServer::new(Arc::clone(&self.0), Default::default())
    }
    fn sim_ranges(&mut self) -> impl sim_range_server::Behavior {
        SimRangeServer::new(Arc::clone(&self.0), Default::default())
    }
}

impl robot::Parts for RobotParts {
    fn supervisor(&mut self) -> impl robot::Supervisor {
        RobotSupervisor
    }
    fn base(&mut self) -> impl base::Parts {
        BaseParts(Arc::clone(&self.0))
    }
    fn wanderer(&mut self) -> impl wanderer::Behavior {
        Wanderer::default()
    }
    fn fallback(&mut self) -> impl wanderer::Behavior {
        Wanderer::default()
    }
    fn mapper(&mut self) -> impl mapper::Behavior {
        Mapper::new(Arc::clone(&self.0))
    }
    fn teleop(&mut self) -> impl teleop::Behavior {
        Teleop::default()
    }
}

fn follow(on: bool) -> (String, Command) {
    (
        "teleop".to_owned(),
        Command::Set("follow".to_owned(), Value::from(on)),
    )
}

#[test]
fn the_robots_supervisor_hands_the_base_to_outside_commands_and_back() {
    let platform = Platform::new(World::example(), World::example_start(), None);
    let mut h = robot::Harness::running(RobotParts(Arc::new(platform))).unwrap();
    assert_eq!(h.user_state(), Some(RobotState::Autonomous));
    h.take_commands();

    h.instances()
        .teleop()
        .set_user_state(Some(UserState::Commanded.name()))
        .unwrap();
    assert_eq!(h.user_state(), Some(RobotState::Teleoperated));
    assert_eq!(h.take_commands(), [follow(true)]);

    h.instances()
        .teleop()
        .set_user_state(Some(UserState::Quiet.name()))
        .unwrap();
    assert_eq!(h.user_state(), Some(RobotState::Autonomous));
    assert_eq!(h.take_commands(), [follow(false)]);
}
