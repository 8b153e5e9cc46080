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
    assert_eq!(
        (summary.faults, summary.failed_restarts),
        (0, 0),
        "{summary}"
    );
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
    assert_eq!(summary.faults, 1, "{summary}");
    assert!(
        summary.failed_restarts >= 1,
        "the board was still down: {summary}"
    );
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
    // The range server's driver panics on purpose; keep its message out of the log.
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if std::thread::current().name() != Some("cool:ranges") {
            default_hook(info);
        }
    }));
    let summary = run(Options {
        duration: Duration::from_millis(6500),
        fault_after: Some(Duration::from_millis(200)),
        outage: Duration::from_secs(60),
        fault_kind: mobile_base::world::FaultKind::Panic,
        ..Options::default()
    });
    assert_safe(&summary);
    assert_eq!(summary.substitutions, 1, "{summary}");
    assert_eq!(summary.recoveries, 0, "{summary}");
    assert_eq!(summary.retired, 1, "{summary}");
    assert_eq!(summary.faults, 1, "{summary}");
    // Restarted every 500 ms for 5 s, and the board never came back.
    assert!(summary.failed_restarts >= 5, "{summary}");
    let before: std::collections::HashMap<_, _> =
        summary.states_before_shutdown.iter().cloned().collect();
    assert_eq!(before["ranges"], State::Dead, "{summary}");
    assert_eq!(before["sim_ranges"], State::Running, "{summary}");
    assert_eq!(summary.supervisor, "degraded");
    assert_clean_shutdown(&summary);
}

#[test]
fn a_stop_request_ends_the_run_early_and_cleanly() {
    let options = Options {
        duration: Duration::from_secs(30),
        max_speed: Some(0.3),
        scan_rate: Some(10.0),
        ..Options::default()
    };
    let stop = options.stop.clone();
    let stopper = std::thread::spawn(move || {
        std::thread::sleep(Duration::from_millis(1500));
        stop.store(true, std::sync::atomic::Ordering::Relaxed);
    });
    let summary = run(options);
    stopper.join().unwrap();
    assert!(summary.interrupted);
    assert!(summary.elapsed < Duration::from_secs(10), "{summary}");
    // At 10 Hz, about 15 scans in 1.5 s (not the 30 of the default 20 Hz).
    assert!((5..=22).contains(&summary.scans.0), "{summary}");
    assert_clean_shutdown(&summary);
}

#[test]
fn a_pause_trips_the_platform_watchdog_and_the_retry_plan_recovers() {
    use coolbot::{Command, Controllable};
    use mobile_base::robot::{self, MOTION, Setup};
    use mobile_base::world::{Platform, World};
    use std::sync::Arc;

    let platform = Arc::new(Platform::new(
        World::example(),
        World::example_start(),
        None,
    ));
    let setup = Setup {
        noise: 0.0,
        seed: 1,
        goal: None,
        max_speed: None,
        scan_rate: None,
    };
    let system = robot::wire_robot(&platform, &setup).expect("the robot starts");
    let motion = system.handle(MOTION).unwrap();
    let moving = |m: &coolbot::Monitor| {
        m.variables.iter().any(|(name, value)| {
            name == "speed" && value.to_json()["linear"].as_f64().is_some_and(|v| v > 0.05)
        })
    };
    motion
        .wait_for(moving, Duration::from_secs(3))
        .expect("the base gets going");
    // Freeze the controller mid-motion for longer than the platform's watchdog.
    motion
        .command(Command::SetState(Controllable::Suspended))
        .unwrap();
    std::thread::sleep(Duration::from_millis(400));
    motion
        .command(Command::SetState(Controllable::Running))
        .unwrap();
    let trips = |m: &coolbot::Monitor| {
        m.variables
            .iter()
            .find(|(name, _)| name == "watchdog_trips")
            .and_then(|(_, value)| value.to_json().as_u64())
            .unwrap_or(0)
    };
    let after = motion
        .wait_for(|m| trips(m) >= 1, Duration::from_secs(2))
        .expect("the watchdog exception was raised");
    // The plan (`retry 3 every 20ms`) recovered: still running, no error, moving on.
    assert_eq!(after.state, State::Running);
    assert_eq!(after.error, None);
    let distance = platform.truth().distance;
    motion
        .wait_for(moving, Duration::from_secs(3))
        .expect("moving again");
    assert!(platform.truth().distance > distance);
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}
