//! Runs the generated `Station`: a watcher reads the `Unit` compound's exported poster
//! output, counts the beats of its exported tick output and pulls its exported `pull`
//! output, as it would read a `Sensor` directly. Every check is on monitor snapshots.

use std::time::Duration;

use coolbot::{Monitor, State, System};
use exports::generated::{station, unit};
use exports::station::StationParts;

const WAIT: Duration = Duration::from_secs(20);

fn count(monitor: &Monitor, name: &str) -> u64 {
    monitor
        .variables
        .iter()
        .find(|(n, _)| n == name)
        .and_then(|(_, v)| u64::try_from(v).ok())
        .unwrap_or(0)
}

#[test]
fn a_watcher_reads_a_compound_as_it_reads_an_atomic_sensor() {
    // The unit's interface: the sensor's ports under the unit's names, with their
    // kinds and pull model.
    let outputs: Vec<(&str, coolbot::OutputKind, bool)> = unit::SPEC
        .outputs
        .iter()
        .map(|o| (o.name, o.kind, o.pull))
        .collect();
    assert_eq!(
        outputs,
        [
            ("status", coolbot::OutputKind::Poster, false),
            ("beat", coolbot::OutputKind::Tick, false),
            ("latest", coolbot::OutputKind::Data, true),
        ]
    );
    let mut system = System::new();
    let station = system
        .add(station::component("station", StationParts::default()).unwrap())
        .unwrap();
    system.run_all().unwrap();
    let watcher = station.instance("watcher").unwrap();
    // Posts, beats and pull answers all cross the unit's boundary.
    let monitor = watcher
        .wait_for(
            |m| count(m, "posted") >= 5 && count(m, "beats") >= 5 && count(m, "pulled") >= 5,
            WAIT,
        )
        .unwrap();
    assert_eq!(monitor.state, State::Running);
    assert_eq!(station.snapshot().state, State::Running);
    assert_eq!(monitor.overflows, 0);
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}
