//! The base's supervisor alone, in its generated harness
//! (`generated::mobile_base::Harness`): the description's rules and this crate's
//! supervisor sections (`robot::BaseSupervisor`) on a virtual clock, with no thread;
//! the motion controller and the range servers are stand-ins whose states and
//! variables the test sets, and whose commands from the supervisor it reads back.

use std::sync::Arc;
use std::time::Duration;

use coolbot::{Command, Controllable, State, Value};
use mobile_base::generated::mobile_base as base;
use mobile_base::generated::mobile_base::{Harness, UserState};
use mobile_base::generated::{motion_controller, range_server, sim_range_server};
use mobile_base::motion_controller::MotionController;
use mobile_base::range_server::RangeServer;
use mobile_base::robot::{BaseSupervisor, DEGRADED_MAX_SPEED};
use mobile_base::sim_range_server::SimRangeServer;
use mobile_base::world::{Platform, World};

/// The base's parts, as the robot's, around a platform nothing drives (the
/// instances are stand-ins: their behaviours are built, never run).
struct Parts(Arc<Platform>);

impl base::Parts for Parts {
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

fn harness() -> Harness {
    let platform = Platform::new(World::example(), World::example_start(), None);
    Harness::running(Parts(Arc::new(platform))).expect("the base's supervisor runs")
}

fn set_max_speed(speed: f64) -> (String, Command) {
    (
        "motion".to_owned(),
        Command::Set("max_speed".to_owned(), Value::from(speed)),
    )
}

/// The `max_speed` the motion controller's stand-in holds.
fn motion_max_speed(h: &mut Harness) -> Option<Value> {
    h.instances()
        .motion()
        .monitor()
        .unwrap()
        .variables
        .into_iter()
        .find(|(name, _)| name == "max_speed")
        .map(|(_, value)| value)
}

/// The motion controller's task fails (`motion.result == fail`).
fn fail_motion_task(h: &mut Harness) {
    h.instances()
        .motion()
        .set_result(coolbot::TaskResult::Fail("wheels".to_owned()))
        .unwrap();
}

#[test]
fn the_base_degrades_when_its_range_server_fails_and_recovers_when_it_streams() {
    let mut h = harness();
    assert_eq!(h.user_state(), Some(UserState::Operating));
    // The compound ran its instances; the substitute stands by.
    assert_eq!(
        h.instances().motion().monitor().unwrap().state,
        State::Running
    );
    assert_eq!(
        h.instances().ranges().monitor().unwrap().state,
        State::Running
    );
    assert_eq!(
        h.instances().sim_ranges().monitor().unwrap().state,
        State::Ready
    );
    h.instances().motion().set_max_speed(0.5).unwrap();
    assert!(h.take_commands().is_empty());

    // The range server fails: `degraded`, whose entry lowers the motion controller's
    // speed limit and counts the fault.
    h.instances()
        .ranges()
        .set_state(State::RunningError)
        .unwrap();
    assert_eq!(h.user_state(), Some(UserState::Degraded));
    assert_eq!(h.take_commands(), [set_max_speed(DEGRADED_MAX_SPEED)]);
    assert_eq!(h.variable("faults"), Some(Value::from(1_u32)));
    // The stand-in took the command as the motion controller would.
    assert_eq!(
        motion_max_speed(&mut h),
        Some(Value::from(DEGRADED_MAX_SPEED))
    );

    // Periodic sections run on the virtual clock and command nothing.
    h.advance(Duration::from_secs(1)).unwrap();
    assert_eq!(h.user_state(), Some(UserState::Degraded));
    assert!(h.take_commands().is_empty());

    // Running again, but not streaming yet: the rule reads both.
    h.instances().ranges().set_state(State::Running).unwrap();
    assert_eq!(h.user_state(), Some(UserState::Degraded));
    h.instances()
        .ranges()
        .set_user_state(Some(range_server::UserState::Streaming.name()))
        .unwrap();
    assert_eq!(h.user_state(), Some(UserState::Operating));
    // The exit section put back the limit it found.
    assert_eq!(h.take_commands(), [set_max_speed(0.5)]);
}

#[test]
fn hold_stops_the_base_and_suspends_the_motion_controller() {
    let mut h = harness();
    h.inner().set("hold", Value::from(true)).unwrap();
    assert_eq!(h.user_state(), Some(UserState::Stopped));
    assert_eq!(
        h.take_commands(),
        [(
            "motion".to_owned(),
            Command::SetState(Controllable::Suspended)
        )]
    );
    assert_eq!(
        h.instances().motion().monitor().unwrap().state,
        State::Suspended
    );
    // Released: `operating` runs it again.
    h.inner().set("hold", Value::from(false)).unwrap();
    assert_eq!(h.user_state(), Some(UserState::Operating));
    assert_eq!(
        h.take_commands(),
        [(
            "motion".to_owned(),
            Command::SetState(Controllable::Running)
        )]
    );
    // A failed motion task stops it too (`motion.result == fail`).
    fail_motion_task(&mut h);
    assert_eq!(h.user_state(), Some(UserState::Stopped));
}

#[test]
fn a_motion_controller_failing_while_degraded_is_left_to_its_restart_policy() {
    let mut h = harness();
    h.instances()
        .ranges()
        .set_state(State::RunningError)
        .unwrap();
    assert_eq!(h.user_state(), Some(UserState::Degraded));
    h.take_commands();
    // The motion controller fails while the substitute stands in: `on error motion:
    // restart` brings it back, and the supervisor stays where it is, commanding
    // nothing (a stuck controller would refuse every command).
    h.instances()
        .motion()
        .set_state(State::RunningError)
        .unwrap();
    assert_eq!(h.user_state(), Some(UserState::Degraded));
    assert!(h.take_commands().is_empty());
    h.instances().motion().set_state(State::Running).unwrap();
    h.advance(Duration::from_secs(1)).unwrap();
    assert_eq!(h.user_state(), Some(UserState::Degraded));
    assert!(h.take_commands().is_empty());
    // A failed motion task still stops the base.
    fail_motion_task(&mut h);
    assert_eq!(h.user_state(), Some(UserState::Stopped));
}

#[test]
fn a_command_the_motion_controller_cannot_take_yet_is_given_again_until_it_is() {
    let mut h = harness();
    h.instances().motion().set_max_speed(0.5).unwrap();
    // The motion controller is stuck in a section past its `max_response` (its
    // restart policy will bring it back) when the range server fails: `degraded`'s
    // entry cannot lower its limit, and does not fail for that.
    h.inner()
        .refuse_next("motion", coolbot::Refused::Stuck)
        .unwrap();
    h.instances()
        .ranges()
        .set_state(State::RunningError)
        .unwrap();
    assert_eq!(h.user_state(), Some(UserState::Degraded));
    assert_eq!(h.take_commands(), [set_max_speed(DEGRADED_MAX_SPEED)]);
    assert_eq!(h.inner().state(), State::Running);
    assert_eq!(motion_max_speed(&mut h), Some(Value::from(0.5)));
    // Still refused at the next periodic section, taken at the one after.
    h.inner()
        .refuse_next("motion", coolbot::Refused::Stuck)
        .unwrap();
    h.advance(Duration::from_millis(100)).unwrap();
    assert_eq!(h.take_commands(), [set_max_speed(DEGRADED_MAX_SPEED)]);
    h.advance(Duration::from_millis(100)).unwrap();
    assert_eq!(h.take_commands(), [set_max_speed(DEGRADED_MAX_SPEED)]);
    h.advance(Duration::from_millis(100)).unwrap();
    assert!(h.take_commands().is_empty());
    // Any other refusal still fails the supervisor's section.
    h.inner()
        .refuse_next("motion", coolbot::Refused::QueueFull)
        .unwrap();
    h.instances().ranges().set_state(State::Running).unwrap();
    h.instances()
        .ranges()
        .set_user_state(Some(range_server::UserState::Streaming.name()))
        .unwrap();
    assert_eq!(h.inner().state(), State::RunningError);
}
