//! Runs the generated `tune` crate: the `adaptation` blocks of the description take
//! effect at run time. `Slow` (tuned: window 2, 1 violation, hold 1) degrades its
//! period under violations; `Frozen` (`off`) misses the same deadlines and keeps its
//! nominal period; in `Cell`, the instances' blocks replace their components'; in
//! `Still` (`off`), nothing degrades the late `Slow`.
//! Every check polls monitor snapshots with a deadline.

use std::time::Duration;

use coolbot::{Monitor, Pressure, System};
use tune::cell::CellParts;
use tune::frozen::Frozen;
use tune::generated::{cell, frozen, slow, still};
use tune::slow::Slow;
use tune::still::StillParts;

const WAIT: Duration = Duration::from_secs(30);
const NOMINAL: Option<Duration> = Some(Duration::from_millis(5));

fn degraded(monitor: &Monitor) -> bool {
    monitor.adaptation.level >= 1 && monitor.period > NOMINAL
}

#[test]
fn off_means_no_degradation_and_tuning_sets_the_detector() {
    let mut system = System::new();
    let slow = system
        .add(slow::component("slow", Slow::default()))
        .unwrap();
    let frozen = system
        .add(frozen::component("frozen", Frozen::default()))
        .unwrap();
    system.run_all().unwrap();
    let monitor = slow.wait_for(degraded, WAIT).expect("slow degrades");
    assert!(monitor.adaptation.enabled);
    // The detector settles for hold + window + 1 periods: 1 + 2 + 1.
    assert_eq!(monitor.adaptation.settle_periods, 4);
    let monitor = frozen
        .wait_for(|m| m.missed_deadlines >= 10, WAIT)
        .expect("frozen misses deadlines");
    assert!(!monitor.adaptation.enabled);
    assert_eq!(monitor.adaptation.level, 0);
    assert_eq!(monitor.period, NOMINAL);
    assert!(monitor.adaptation.history.is_empty());
    system.shutdown();
}

#[test]
fn instance_blocks_replace_their_components_tuning() {
    let mut system = System::new();
    let cell = system
        .add(cell::component("cell", CellParts::default()).unwrap())
        .unwrap();
    system.run_all().unwrap();
    // `thawed` is a `Frozen` turned back on: hold 7 + the default window 4 + 1.
    let thawed = cell.instance("thawed").unwrap();
    let monitor = thawed
        .wait_for(|m| m.adaptation.settle_periods == 12, WAIT)
        .expect("thawed's detector is tuned");
    assert!(monitor.adaptation.enabled);
    // `slow` keeps `Slow`'s window 2 with its own hold 5: 5 + 2 + 1.
    let slow = cell.instance("slow").unwrap();
    let monitor = slow
        .wait_for(|m| m.adaptation.settle_periods == 8, WAIT)
        .expect("slow's detector is tuned");
    assert!(monitor.adaptation.enabled);
    system.shutdown();
}

#[test]
fn a_compound_turned_off_degrades_none_of_its_instances() {
    let mut system = System::new();
    let still = system
        .add(still::component("still", StillParts::default()).unwrap())
        .unwrap();
    system.run_all().unwrap();
    let slow = still.instance("slow").unwrap();
    // The instance detects its violations and publishes them ...
    let monitor = slow
        .wait_for(
            |m| m.adaptation.pressure == Pressure::Violation && m.missed_deadlines >= 10,
            WAIT,
        )
        .expect("slow reports a time violation");
    // ... and its supervisor, turned off, leaves it at its nominal period.
    assert_eq!(monitor.adaptation.level, 0);
    assert_eq!(monitor.period, NOMINAL);
    assert!(!still.snapshot().adaptation.enabled);
    system.shutdown();
}
