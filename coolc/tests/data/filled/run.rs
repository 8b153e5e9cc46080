//! Runs the generated `MobileBase` compound on the runtime, built by its generated
//! `component` (instances with their overrides, the connections, one of them
//! through the `PathToTwist` converter, the mapped variables) with the behaviours the
//! user file's `MobileBaseParts` gives.

use std::time::Duration;

use coolbot::{System, Value};
use fleet::converters::Convert;
use fleet::generated::mobile_base::{self, Parts};
use fleet::mobile_base::MobileBaseParts;

const WAIT: Duration = Duration::from_secs(20);

fn variable(monitor: &coolbot::Monitor, name: &str) -> Option<Value> {
    monitor
        .variables
        .iter()
        .find(|(n, _)| n == name)
        .map(|(_, v)| v.clone())
}

#[test]
fn mobile_base_instances_run_and_talk() {
    let mut system = System::new();
    // The compound as the description builds it; `instance motion: MotionController
    // { max_speed = 0.5; }` sets the configuration field and the controllable
    // variable of that name.
    let builder = mobile_base::builder::<Convert>("base", MobileBaseParts::default()).unwrap();
    let motion = builder.instance_handle("motion").unwrap();
    let ranges = builder.instance_handle("ranges").unwrap();
    let base = system.add(builder.build().unwrap()).unwrap();
    // Outside the compound: a planner of its own and a follower pulling from it.
    system
        .add(fleet::generated::planner::component(
            "planner",
            MobileBaseParts::default().planner(),
        ))
        .unwrap();
    let follower = system
        .add(fleet::generated::follower::component(
            "follower",
            fleet::follower::Follower::default(),
        ))
        .unwrap();
    system.connect("planner.path", "follower.path").unwrap();
    system.run_all().unwrap();
    base.wait_state(coolbot::State::Running, WAIT).unwrap();

    // The range server leaves `calibrating` through its `may` choice and streams.
    let monitor = ranges
        .wait_for(
            |m| {
                m.user_state.as_deref() == Some("streaming")
                    && matches!(variable(m, "scans"), Some(Value::UInt(n)) if n >= 3)
            },
            WAIT,
        )
        .unwrap();
    assert_eq!(monitor.state, coolbot::State::Running);

    // A section raised `sensor_timeout`: the handler ran, the plan retried the
    // section, and the component goes on running.
    let monitor = ranges
        .wait_for(
            |m| {
                matches!(variable(m, "timeouts"), Some(Value::UInt(1)))
                    && matches!(variable(m, "scans"), Some(Value::UInt(n)) if n >= 6)
            },
            WAIT,
        )
        .unwrap();
    assert_eq!(monitor.state, coolbot::State::Running);

    // The follower's pulls are answered by the planner's `answer_path`.
    follower
        .wait_for(
            |m| matches!(variable(m, "waypoints"), Some(Value::UInt(2))),
            WAIT,
        )
        .unwrap();
    // A partial configuration through the control port changes only what it names.
    follower
        .command(coolbot::Command::Configure(Value::Record(vec![(
            "scale".to_owned(),
            Value::UInt(3),
        )])))
        .unwrap();
    follower
        .wait_for(
            |m| matches!(variable(m, "waypoints"), Some(Value::UInt(6))),
            WAIT,
        )
        .unwrap();
    // A field the configuration does not have is rejected, not ignored.
    let refused = follower.command(coolbot::Command::Configure(Value::Record(vec![(
        "scal".to_owned(),
        Value::UInt(3),
    )])));
    assert!(
        refused
            .as_ref()
            .is_err_and(|rejected| rejected.to_string().contains("unknown field `scal`")),
        "{refused:?}"
    );

    // Inside the compound the planner's path reaches the motion controller through the converter: it
    // moves (`on command -> moving`) and integrates the command into its odometry.
    let monitor = motion
        .wait_for(
            |m| {
                variable(m, "odometry")
                    .and_then(|v| v.to_serde::<fleet::generated::types::Pose2D>().ok())
                    .is_some_and(|pose| pose.x > 0.0)
            },
            WAIT,
        )
        .unwrap();
    let pose: fleet::generated::types::Pose2D =
        variable(&monitor, "odometry").unwrap().to_serde().unwrap();
    // `instance motion: MotionController { max_speed = 0.5; }` overrides the
    // controllable variable (default 0.8), which clamps the 1 m/s command.
    assert_eq!(pose.x, 0.5, "the command is clamped to max_speed");
    assert!(matches!(variable(&monitor, "max_speed"), Some(Value::Float(s)) if s == 0.5));

    // With no further command, the watchdog (`after 500ms without command`) brings it
    // back to `idle`.
    motion
        .wait_for(|m| m.user_state.as_deref() == Some("idle"), WAIT)
        .unwrap();

    // The compound's mapped controllable variable is set through its control port
    // and lands on the instance's.
    base.command(coolbot::Command::Set(
        "max_speed".to_owned(),
        Value::Float(0.3),
    ))
    .unwrap();
    motion
        .wait_for(
            |m| matches!(variable(m, "max_speed"), Some(Value::Float(s)) if s == 0.3),
            WAIT,
        )
        .unwrap();
    base.wait_for(
        |m| matches!(variable(m, "max_speed"), Some(Value::Float(s)) if s == 0.3),
        WAIT,
    )
    .unwrap();

    let report = system.shutdown();
    assert!(
        report.components.iter().all(|c| c.thread_panic.is_none()),
        "{report:?}"
    );
}

// ---------------------------------------------------------------------------------
// The generated harnesses (`<module>::Harness`): one component alone, on a virtual
// clock, with no thread.

#[test]
fn a_range_server_alone_in_its_harness_streams_and_retries_on_the_virtual_clock() {
    use fleet::generated::range_server::{Harness, UserState};
    let mut h = Harness::running(fleet::range_server::RangeServer::default()).unwrap();
    // `calibrating`'s entry, then its `may` choice.
    assert_eq!(h.user_state(), Some(UserState::Streaming));
    assert!(h.behavior().calibrated_once());
    h.advance(Duration::from_millis(199)).unwrap();
    assert_eq!(h.sent_scan().unwrap().len(), 3);
    // The fourth periodic section (at 200ms) raises `sensor_timeout` once; its plan
    // (`retry 2 every 50ms`) runs the section again 50ms later, a timer of the harness
    // clock.
    h.advance(Duration::from_millis(1)).unwrap();
    assert_eq!(h.sent_scan().unwrap().len(), 0);
    assert_eq!(h.inner().next_due(), Some(Duration::from_millis(50)));
    h.advance(Duration::from_millis(50)).unwrap();
    let scans = h.sent_scan().unwrap();
    assert_eq!(scans.len(), 1);
    assert_eq!(scans[0].ranges, [h.config().emergency_distance * 10.0; 16]);
    assert_eq!((h.vars().scans, h.vars().timeouts), (4, 1));
    assert_eq!(h.inner().elapsed(), Duration::from_millis(250));
    assert_eq!(h.state(), coolbot::State::Running);
    assert_eq!(h.ticks_emergency().unwrap(), 0);
}

#[test]
fn a_planner_answers_a_pull_and_a_follower_gets_its_answer_in_their_harnesses() {
    use fleet::generated::types::{Path, Pose2D};
    use fleet::generated::{follower, planner};
    let mut planner = planner::Harness::running(MobileBaseParts::default().planner()).unwrap();
    // The entry section sends one path; a pull asks for another.
    assert_eq!(planner.sent_path().unwrap().len(), 1);
    planner.push_goal(Pose2D::default()).unwrap();
    planner.pull_path().unwrap();
    let answered = planner.sent_path().unwrap();
    assert_eq!(answered.len(), 1);
    assert_eq!(answered[0].poses.len(), 2);

    let config = follower::Config {
        scale: 2,
        ..follower::Config::default()
    };
    let mut follower = follower::Harness::with(
        fleet::follower::Follower::default(),
        config,
        follower::Vars::default(),
    )
    .unwrap();
    follower.run().unwrap();
    follower
        .answer_path(Path {
            poses: vec![Pose2D::default(); 3],
        })
        .unwrap();
    follower.advance(Duration::from_millis(50)).unwrap();
    assert_eq!(follower.vars().waypoints, 6);
    assert_eq!(follower.error(), None);
}
