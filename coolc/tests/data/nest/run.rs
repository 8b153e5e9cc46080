//! Runs the generated `Fleet` (`nest.cool`): compounds whose innermost level connects
//! through a converter, nested three levels deep, built by the generated
//! `component::<Convert>` of the outermost one.

use std::time::Duration;

use coolbot::{Monitor, State, System, Value};
use nest::converters::Convert;
use nest::fleet::FleetParts;
use nest::generated::fleet;

const WAIT: Duration = Duration::from_secs(20);

fn variable(monitor: &Monitor, name: &str) -> Option<Value> {
    monitor
        .variables
        .iter()
        .find(|(n, _)| n == name)
        .map(|(_, v)| v.clone())
}

fn float(monitor: &Monitor, name: &str) -> f64 {
    variable(monitor, name)
        .and_then(|v| f64::try_from(&v).ok())
        .unwrap_or(0.0)
}

#[test]
fn converters_reach_compounds_nested_three_deep() {
    let component = fleet::component::<Convert>("fleet", FleetParts::default()).unwrap();
    let mut system = System::new();
    let fleet = system.add(component).unwrap();
    system.run_all().unwrap();

    // Each base's follower sends `linear = 1 + n, angular = 0.5`; the converter
    // makes `left = linear - angular`, and the drive multiplies it by the gain the
    // robot's override set (2): `left = 2n + 1`, an odd whole number.
    let monitor = fleet
        .wait_for(
            |m| {
                variable(m, "two_received").and_then(|v| u64::try_from(&v).ok()) >= Some(3)
                    && float(m, "one_left") >= 3.0
            },
            WAIT,
        )
        .unwrap();
    assert_eq!(monitor.state, State::Running);
    let left = float(&monitor, "one_left");
    assert_eq!(left.fract(), 0.0, "left = {left}");
    assert_eq!(left as u64 % 2, 1, "left = {left}");

    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}
