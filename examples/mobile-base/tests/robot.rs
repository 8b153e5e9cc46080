//! The robot, headless: the same system the `mobile-base` binary runs, for a few
//! seconds, with assertions on what it did.

use std::time::Duration;

use coolbot::State;
use mobile_base::{Display, Options, Summary};

fn run(options: Options) -> Summary {
    let summary = mobile_base::run(&Options {
        display: Display::Quiet,
        ..options
    })
    .expect("the robot builds and starts");
    eprintln!("{summary}");
    summary
}

fn assert_clean_shutdown(summary: &Summary) {
    assert!(summary.clean_shutdown, "{summary}");
    assert_eq!(summary.final_states.len(), 4);
    for (name, state, joined) in &summary.final_states {
        assert_eq!(*state, State::Dead, "{name}");
        assert!(joined, "{name}'s thread was not joined");
    }
}

fn assert_safe(summary: &Summary) {
    assert!(summary.distance > 0.2, "the robot hardly moved: {summary}");
    // Odometry is integrated by the motion controller from the same steps.
    assert!(
        (summary.distance - summary.odometry_distance).abs() < 1e-6,
        "{summary}"
    );
    // Never inside an obstacle, and never even touching one.
    assert!(summary.min_clearance > 0.0, "{summary}");
    assert_eq!(
        summary.contacts, 0,
        "the robot touched an obstacle: {summary}"
    );
    // The emergency stop fired, or the robot never came within its distance of an
    // obstacle ahead (less a margin: range noise, and 50 ms between scans).
    assert!(
        summary.emergencies > 0 || summary.min_front_clearance > summary.emergency_distance - 0.05,
        "the robot came within {:.3} m of an obstacle ahead without an emergency: {summary}",
        summary.min_front_clearance
    );
}

#[test]
fn the_robot_wanders_without_touching_anything_and_stops_cleanly() {
    let summary = run(Options {
        duration: Duration::from_secs(4),
        ..Options::default()
    });
    assert_safe(&summary);
    assert!(summary.emergency_distance > 0.0);
    assert!(summary.scans.0 > 0, "the range server published nothing");
    assert_eq!(
        summary.scans.1, 0,
        "the standby substitute ran without a fault"
    );
    assert_eq!(summary.faults, 0, "{summary}");
    assert_eq!(summary.supervisor, "operating");
    assert!(!summary.interrupted);
    assert_clean_shutdown(&summary);
}

#[test]
fn a_failed_range_server_is_substituted_then_recovered() {
    let summary = run(Options {
        duration: Duration::from_secs(4),
        fault_after: Some(Duration::from_millis(1000)),
        outage: Duration::from_millis(800),
        ..Options::default()
    });
    assert_safe(&summary);
    assert_eq!(summary.substitutions, 1, "{summary}");
    assert!(
        summary.scans.1 > 0,
        "the substitute published nothing: {summary}"
    );
    assert_eq!(summary.recoveries, 1, "{summary}");
    assert_eq!(summary.retired, 0);
    assert!(summary.faults >= 1);
    // Back to normal: the real server runs again, the substitute is on standby.
    let before: std::collections::HashMap<_, _> =
        summary.states_before_shutdown.iter().cloned().collect();
    assert_eq!(before["ranges"], State::Running, "{summary}");
    assert_eq!(before["sim_ranges"], State::Ready, "{summary}");
    assert_eq!(summary.supervisor, "operating");
    assert_clean_shutdown(&summary);
}

#[test]
fn a_range_server_that_does_not_recover_is_retired_and_the_substitute_stays() {
    let summary = run(Options {
        duration: Duration::from_secs(6),
        fault_after: Some(Duration::from_millis(300)),
        outage: Duration::from_secs(60),
        fault_kind: mobile_base::world::FaultKind::Panic,
        ..Options::default()
    });
    assert_safe(&summary);
    assert_eq!(summary.substitutions, 1, "{summary}");
    assert_eq!(summary.recoveries, 0, "{summary}");
    assert_eq!(summary.retired, 1, "{summary}");
    let before: std::collections::HashMap<_, _> =
        summary.states_before_shutdown.iter().cloned().collect();
    assert_eq!(before["ranges"], State::Dead, "{summary}");
    assert_eq!(before["sim_ranges"], State::Running, "{summary}");
    assert_eq!(summary.supervisor, "degraded");
    assert_clean_shutdown(&summary);
}
