//! Runs the generated atomic components on the runtime, wired as `MobileBase`
//! declares (by hand on a `coolbot::System`: the runtime's compound builder does not
//! convert packets yet, and one connection goes through a converter), with the
//! behaviours the user file's `MobileBaseParts` gives.

use std::time::Duration;

use coolbot::{System, Value};
use fleet::converters::Convert;
use fleet::generated::mobile_base::{self, Parts};
use fleet::generated::types::Converters;
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
    let mut parts = MobileBaseParts::default();
    // `instance motion: MotionController { max_speed = 0.5; }` sets the configuration
    // field and the controllable variable of that name.
    let config = fleet::generated::motion_controller::Config {
        max_speed: 0.5,
        ..Default::default()
    };
    let vars = fleet::generated::motion_controller::Vars {
        max_speed: 0.5,
        ..Default::default()
    };
    system
        .add(fleet::generated::motion_controller::component_with(
            "motion",
            parts.motion(),
            config,
            vars,
        ))
        .unwrap();
    system
        .add(fleet::generated::range_server::component(
            "ranges",
            parts.ranges(),
        ))
        .unwrap();
    system
        .add(fleet::generated::planner::component(
            "planner",
            parts.planner(),
        ))
        .unwrap();
    for (from, to) in mobile_base::CONNECTIONS {
        if *from == "planner.path" {
            system
                .connect_via(from, to, <Convert as Converters>::path_to_twist)
                .unwrap();
        } else {
            system.connect(from, to).unwrap();
        }
    }
    // An instance outside the compound, pulling from the planner.
    let follower = system
        .add(fleet::generated::follower::component(
            "follower",
            fleet::follower::Follower::default(),
        ))
        .unwrap();
    system.connect("planner.path", "follower.path").unwrap();
    let motion = system.handle("motion").unwrap();
    let ranges = system.handle("ranges").unwrap();
    system.run_all().unwrap();

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

    // The planner's path reaches the motion controller through the converter: it
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

    // The controllable variable is set through the control port.
    motion
        .command(coolbot::Command::Set(
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

    let report = system.shutdown();
    assert!(
        report.components.iter().all(|c| c.thread_panic.is_none()),
        "{report:?}"
    );
}
