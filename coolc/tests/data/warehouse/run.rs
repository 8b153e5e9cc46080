//! Runs the warehouse robot, written from `docs/language.md` alone: three levels of
//! compounds (Warehouse > Navigation > Base), a converter inside the nested Base, a
//! camera whose frames feed two redundant detectors through their own queues, a
//! pan-tilt unit whose poster the robot exports to a console outside it, a lidar with
//! a spare, and a supervisor that stops the base by suspending it. Every check polls
//! monitor snapshots with a deadline.

use std::time::Duration;

use coolbot::{Command, Monitor, State, Step, System, Value};
use warehouse::converters::Convert;
use warehouse::generated;

const WAIT: Duration = Duration::from_secs(20);

fn number(monitor: &Monitor, name: &str) -> f64 {
    monitor
        .variables
        .iter()
        .find(|(n, _)| n == name)
        .and_then(|(_, v)| f64::try_from(v).ok())
        .unwrap_or(f64::NAN)
}

#[test]
fn the_warehouse_robot_runs_as_described() {
    let robot = generated::warehouse::component::<Convert>(
        "warehouse",
        warehouse::warehouse::WarehouseParts::default(),
    )
    .unwrap();
    let mut system = System::new();
    let robot = system.add(robot).unwrap();
    let console = system
        .add(generated::console::component(
            "console",
            warehouse::console::Console::default(),
        ))
        .unwrap();
    // The robot's exported poster connects as an atomic component's would.
    system
        .connect("warehouse.position", "console.position")
        .unwrap();
    system.run_all().unwrap();

    // Both redundant detectors see the camera's frames, each through its own queue.
    for detector in ["perception.det_a", "perception.det_b"] {
        let handle = robot.instance(detector).unwrap();
        handle
            .wait_for(|m| number(m, "seen") >= 20.0, WAIT)
            .unwrap();
    }
    // The follower drives the wheels through the converter inside the nested base.
    robot
        .wait_for(|m| number(m, "travelled") > 0.05, WAIT)
        .unwrap();
    // The console reads the pan-tilt unit's posts through the robot's export.
    robot
        .command(Command::Set("pan".to_owned(), Value::Float(1.0)))
        .unwrap();
    console
        .wait_for(|m| (number(m, "pan") - 1.0).abs() < 1e-9, WAIT)
        .unwrap();

    // `hold`: the navigation supervisor suspends the base; the robot stands still.
    robot
        .command(Command::Set("hold".to_owned(), Value::Bool(true)))
        .unwrap();
    let base = robot.instance("navigation.base").unwrap();
    base.wait_state(State::Suspended, WAIT).unwrap();
    // Suspending the base suspended its instances: the drive integrates nothing more.
    let drive = robot.instance("navigation.base.drive").unwrap();
    let stopped_at = number(
        &drive.wait_state(State::Suspended, WAIT).unwrap(),
        "travelled",
    );
    let lidar = robot.instance("navigation.lidar").unwrap();
    let sweeps = number(&lidar.snapshot(), "sweeps");
    lidar
        .wait_for(|m| number(m, "sweeps") >= sweeps + 10.0, WAIT)
        .unwrap();
    assert_eq!(number(&drive.snapshot(), "travelled"), stopped_at);
    // The robot's mapped `travelled` reads the same value: the suspended base keeps
    // observing its drive, so the value goes up three compounds.
    robot
        .wait_for(|m| number(m, "travelled") == stopped_at, WAIT)
        .unwrap();
    let navigation = robot.instance("navigation").unwrap();
    assert!(
        navigation
            .snapshot()
            .supervision
            .iter()
            .any(|s| s.instance == "base"
                && matches!(&s.step, Step::Commanded { command } if command.contains("suspend"))),
        "{:?}",
        navigation.snapshot().supervision
    );

    // Released, it drives on.
    robot
        .command(Command::Set("hold".to_owned(), Value::Bool(false)))
        .unwrap();
    base.wait_state(State::Running, WAIT).unwrap();
    robot
        .wait_for(|m| number(m, "travelled") > stopped_at + 0.05, WAIT)
        .unwrap();

    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}
