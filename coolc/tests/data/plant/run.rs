//! Runs the generated `Plant` hierarchy (source, the `Cell` compound, sink) on the
//! runtime: packets cross the cell's exported ports, a fault injected into the
//! cell's primary worker is handled inside the cell (its backup substitutes it and
//! the cell's supervisor rule moves its state), and the plant's rule sees the nested
//! supervisor's state. Every check is on monitor snapshots.

use std::time::Duration;

use coolbot::{Command, Monitor, State, System, Value};
use plant::generated::types::Mode;
use plant::generated::{cell, plant as plant_module};
use plant::plant::PlantParts;

const WAIT: Duration = Duration::from_secs(20);

fn variable(monitor: &Monitor, name: &str) -> Option<Value> {
    monitor
        .variables
        .iter()
        .find(|(n, _)| n == name)
        .map(|(_, v)| v.clone())
}

fn count(monitor: &Monitor, name: &str) -> u64 {
    variable(monitor, name)
        .and_then(|v| u64::try_from(&v).ok())
        .unwrap_or(0)
}

#[test]
fn a_failed_leaf_is_substituted_and_the_supervisors_follow() {
    assert_eq!(cell::SUBSTITUTES, &[("backup", "primary")]);
    let component = plant_module::component("plant", PlantParts::default()).unwrap();
    // The compound's interface: its mapped variables, then its own.
    let names: Vec<&str> = component.spec().variables.iter().map(|v| v.name).collect();
    assert_eq!(
        names,
        ["received", "switches", "cell_mode", "fail", "alarms"]
    );
    let mut system = System::new();
    let plant = system.add(component).unwrap();
    system.run_all().unwrap();

    // Packets flow source -> cell (exported input) -> primary -> cell (exported
    // output) -> sink.
    let monitor = plant.wait_for(|m| count(m, "received") >= 5, WAIT).unwrap();
    assert_eq!(monitor.state, State::Running);
    assert_eq!(monitor.user_state.as_deref(), Some("watching"));
    assert_eq!(count(&monitor, "alarms"), 0);

    // The fault, set through the plant's control port down to the primary worker.
    plant
        .command(Command::Set("fail".to_owned(), Value::Bool(true)))
        .unwrap();

    // The cell's backup takes over and its rule moves it to `backup`; the plant's
    // rule sees that and moves it to `alarmed`, whose entry section counts it.
    let monitor = plant
        .wait_for(
            |m| m.user_state.as_deref() == Some("alarmed") && count(m, "alarms") == 1,
            WAIT,
        )
        .unwrap();
    assert_eq!(monitor.state, State::Running, "the fault did not propagate");
    assert_eq!(count(&monitor, "switches"), 1);
    let received = count(&monitor, "received");

    // Packets keep arriving (through the backup, then the recovered primary).
    plant
        .wait_for(|m| count(m, "received") >= received + 10, WAIT)
        .unwrap();

    // The primary recovers from the queue: the cell's rule takes it back to
    // `normal`, whose entry section sets its mode back.
    let monitor = plant
        .wait_for(
            |m| {
                variable(m, "cell_mode").and_then(|v| v.to_serde::<Mode>().ok())
                    == Some(Mode::Normal)
                    && count(m, "switches") == 1
            },
            WAIT,
        )
        .unwrap();
    assert_eq!(monitor.user_state.as_deref(), Some("alarmed"));
    assert_eq!(monitor.state, State::Running);

    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}
