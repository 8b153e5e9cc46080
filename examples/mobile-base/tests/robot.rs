//! The robot, headless: the same system the `mobile-base` binary runs, for a few
//! seconds, with assertions on what it did.
//!
//! On a virtual clock (`coolbot::VirtualClock`): the robot's system, the simulated
//! platform (its uptime, faults and processor shortage) and the run read that clock
//! only, and the tests (or the run itself, `mobile_base::VirtualTime`) advance it a
//! step at a time, so that what the robot does depends on no real time and not on the
//! machine's load. Only the network test keeps the real clock: it waits for no timer.

use std::sync::Arc;
use std::time::Duration;

use coolbot::{Clock, Handle, Monitor, State, Step, VirtualClock};
use mobile_base::world::{Platform, SensorFault, World};
use mobile_base::{Display, Options, Summary, VirtualTime};

/// How far the tests advance the virtual clock at a time: half the smallest period of
/// the robot's components (20 ms: the motion controller's, `teleop`'s).
const STEP: Duration = Duration::from_millis(10);

/// A run of the robot on a virtual clock (the options' own, or a new one advanced
/// [`STEP`] a turn).
fn run(options: Options) -> Summary {
    let virtual_time = options.virtual_time.clone().unwrap_or(VirtualTime {
        step: STEP,
        ..VirtualTime::new()
    });
    run_on(Options {
        virtual_time: Some(virtual_time),
        ..options
    })
}

/// A run of the robot as `options` say (on the real clock without `virtual_time`).
fn run_on(options: Options) -> Summary {
    let summary = mobile_base::run(&Options {
        display: Display::Quiet,
        ..options
    })
    .expect("the robot builds and starts");
    eprintln!("{summary}");
    summary
}

/// A simulated platform on a new virtual clock, with an optional sensor fault: the
/// robot started on it runs on that clock, which the test advances
/// (`Platform::advance`).
fn platform(fault: Option<SensorFault>) -> Arc<Platform> {
    let clock = VirtualClock::new();
    let platform = Platform::new(World::example(), World::example_start(), fault)
        .with_clock(Clock::virtual_clock(&clock));
    Arc::new(platform)
}

/// One [`STEP`] of the platform's virtual clock.
fn step(platform: &Platform) {
    platform.advance(STEP).expect("the robot settles");
}

/// The robot started on `platform` with noiseless sensors (seed 1).
fn quiet_robot(platform: &Arc<Platform>) -> mobile_base::robot::Robot {
    let setup = mobile_base::robot::Setup {
        noise: Some(0.0),
        seed: 1,
        ..mobile_base::robot::Setup::default()
    };
    mobile_base::robot::Robot::start(platform, &setup).expect("the robot starts")
}

/// The distance the motion controller has driven (its `distance`), from its monitor.
fn driven(m: &Monitor) -> f64 {
    m.variables
        .iter()
        .find(|(name, _)| name == "distance")
        .and_then(|(_, value)| value.to_json().as_f64())
        .unwrap_or(0.0)
}

/// Waits (at most 3 s of the platform's clock) until the motion controller has driven
/// 5 cm past `from` (m).
fn drives_on(robot: &mobile_base::robot::Robot, platform: &Platform, from: f64) {
    wait_member(
        robot,
        platform,
        mobile_base::robot::MOTION,
        |m| driven(m) > from + 0.05,
        Duration::from_secs(3),
    )
    .expect("moving again");
}

/// Advances the platform's clock [`STEP`] by step until `pred` holds for the monitor
/// of `handle` (read from its own monitoring port after each step), for at most
/// `limit` of virtual time, and returns that monitor.
fn step_until(
    platform: &Platform,
    handle: &Handle,
    pred: impl Fn(&Monitor) -> bool,
    limit: Duration,
) -> Option<Monitor> {
    let until = platform.uptime() + limit;
    loop {
        let monitor = handle.snapshot();
        if pred(&monitor) {
            return Some(monitor);
        }
        if platform.uptime() >= until {
            return None;
        }
        step(platform);
    }
}

/// Advances the platform's clock by `by`, [`STEP`] by step.
fn advance(platform: &Platform, by: Duration) {
    let until = platform.uptime() + by;
    while platform.uptime() < until {
        step(platform);
    }
}

fn assert_clean_shutdown(summary: &Summary) {
    assert!(summary.clean_shutdown, "{summary}");
    let names: Vec<&str> = summary
        .final_states
        .iter()
        .map(|(n, _)| n.as_str())
        .collect();
    assert_eq!(names, ["robot", "base", "wanderer"]);
    for (name, state) in &summary.final_states {
        assert_eq!(*state, State::Dead, "{name}");
    }
    // Every behaviour, at every level, was dropped: every component thread ended.
    assert!(summary.released, "{summary}");
}

/// The steps the base's supervisor published about `instance`, in order.
fn steps_of<'a>(summary: &'a Summary, instance: &str) -> Vec<&'a Step> {
    summary
        .supervision
        .iter()
        .filter(|s| s.compound == "base" && s.step.instance == instance)
        .map(|s| &s.step.step)
        .collect()
}

fn assert_safe(summary: &Summary) {
    assert!(summary.distance > 0.2, "the robot hardly moved: {summary}");
    // Odometry is integrated by the motion controller from the same steps, and read
    // from its own monitoring port after its last section ran. The check is exact
    // whatever period the motion controller ran at: its description's `period
    // 20ms..40ms` turns adaptation on, and on a loaded machine its supervisor may
    // stretch the period (or stretch it to keep the base homogeneous when the range
    // server is degraded), but each step integrates the time that really elapsed
    // (capped at 0.1 s) and the platform executes that very step. So the example keeps
    // adaptation on for the motion controller, as the description says.
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
    assert!(summary.supervision.is_empty(), "{summary}");
    assert_eq!(summary.supervisor, "operating");
    assert_eq!(summary.user_states, ["operating"]);
    assert_eq!(summary.base_faults, 0);
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
    // Each step, in order, on the base's monitoring port. Retries made while the
    // sensor is still out are steps too (`RetryFailed`), between the substitution and
    // the retry that succeeds; how many depends on where the retry period falls.
    let steps = steps_of(&summary, "ranges");
    let substituted = steps
        .iter()
        .position(|s| matches!(s, Step::Substituted { .. }))
        .unwrap_or_default();
    let retried = steps
        .iter()
        .position(|s| **s == Step::Retried)
        .unwrap_or_default();
    assert!(
        steps
            .iter()
            .enumerate()
            .filter(|(_, s)| ***s == Step::RetryFailed)
            .all(|(i, _)| substituted < i && i < retried),
        "{summary}"
    );
    let steps: Vec<_> = steps
        .into_iter()
        .filter(|s| **s != Step::RetryFailed)
        .collect();
    assert_eq!(
        steps,
        [
            &Step::Failed,
            &Step::Enqueued,
            &Step::Substituted {
                by: "sim_ranges".to_owned()
            },
            &Step::Retried,
            &Step::Recovered,
        ],
        "{summary}"
    );
    assert_eq!(
        (summary.faults(), summary.recoveries(), summary.retired()),
        (1, 1, 0)
    );
    assert!(
        summary.scans.1 > 0,
        "the substitute published nothing: {summary}"
    );
    // Back to normal: the real server runs again, the substitute is on standby.
    let before: std::collections::HashMap<_, _> =
        summary.states_before_shutdown.iter().cloned().collect();
    assert_eq!(before["ranges"], State::Running, "{summary}");
    assert_eq!(before["sim_ranges"], State::Ready, "{summary}");
    assert_eq!(summary.supervisor, "operating");
    assert_eq!(summary.base_faults, 1, "{summary}");
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
    let steps = steps_of(&summary, "ranges");
    assert_eq!(
        steps.first(),
        Some(&&Step::Failed),
        "the panic is the first fault: {summary}"
    );
    assert!(
        steps.contains(&&Step::Substituted {
            by: "sim_ranges".to_owned()
        }),
        "{summary}"
    );
    // Restarted every 500 ms for 5 s, the board never came back: retired, never
    // recovered, and the substitute stays.
    assert_eq!(steps.last(), Some(&&Step::Retired), "{summary}");
    assert_eq!((summary.recoveries(), summary.retired()), (0, 1));
    let before: std::collections::HashMap<_, _> =
        summary.states_before_shutdown.iter().cloned().collect();
    assert_eq!(before["ranges"], State::Dead, "{summary}");
    assert_eq!(before["sim_ranges"], State::Running, "{summary}");
    assert_eq!(summary.supervisor, "degraded");
    assert_eq!(summary.user_states, ["operating", "degraded"]);
    assert_clean_shutdown(&summary);
}

#[test]
fn a_stop_request_ends_the_run_early_and_cleanly() {
    let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
    // The request comes 1.5 s into the run (as SIGINT would set the flag).
    let request = Arc::clone(&stop);
    let summary = run(Options {
        duration: Duration::from_secs(30),
        max_speed: Some(0.3),
        scan_rate: Some(10.0),
        stop,
        virtual_time: Some(VirtualTime {
            step: STEP,
            after_step: Some(Arc::new(move |at| {
                if at >= Duration::from_millis(1500) {
                    request.store(true, std::sync::atomic::Ordering::Relaxed);
                }
            })),
            ..VirtualTime::new()
        }),
        ..Options::default()
    });
    assert!(summary.interrupted);
    assert!(summary.elapsed < Duration::from_secs(10), "{summary}");
    // At 10 Hz, about 15 scans in 1.5 s (not the 30 of the default 20 Hz).
    assert!((5..=22).contains(&summary.scans.0), "{summary}");
    assert_clean_shutdown(&summary);
}

/// Advances the platform's clock (at most `limit`) until `pred` holds for the monitor
/// of the base's instance `name` (read from its own monitoring port), and returns that
/// monitor.
fn wait_member(
    robot: &mobile_base::robot::Robot,
    platform: &Platform,
    name: &str,
    pred: impl Fn(&Monitor) -> bool,
    limit: Duration,
) -> Option<Monitor> {
    let handle = robot.instance(&format!("base.{name}"))?;
    step_until(platform, &handle, pred, limit)
}

#[test]
fn a_pause_trips_the_platform_watchdog_and_the_retry_plan_recovers() {
    use coolbot::{Command, Controllable};
    use mobile_base::robot::MOTION;

    let platform = platform(None);
    let robot = quiet_robot(&platform);
    let moving = |m: &Monitor| {
        m.state == State::Running
            && m.variables.iter().any(|(name, value)| {
                name == "speed" && value.to_json()["linear"].as_f64().is_some_and(|v| v > 0.05)
            })
    };
    wait_member(&robot, &platform, MOTION, moving, Duration::from_secs(3))
        .expect("the base gets going");
    // Freeze the whole robot mid-motion (the compounds pass `suspended` down to every
    // instance) for longer than the platform's set-point watchdog.
    robot
        .robot
        .command(Command::SetState(Controllable::Suspended))
        .unwrap();
    advance(&platform, Duration::from_millis(400));
    robot
        .robot
        .command(Command::SetState(Controllable::Running))
        .unwrap();
    let trips = |m: &Monitor| {
        m.variables
            .iter()
            .find(|(name, _)| name == "watchdog_trips")
            .and_then(|(_, value)| value.to_json().as_u64())
            .unwrap_or(0)
    };
    let after = wait_member(
        &robot,
        &platform,
        MOTION,
        |m| trips(m) >= 1,
        Duration::from_secs(2),
    )
    .expect("the watchdog exception was raised");
    // The plan (`retry 3 every 20ms`) recovered: still running, no error, moving on.
    assert_eq!(after.state, State::Running);
    assert_eq!(after.error, None);
    // Moving on: the odometry gets past where the platform was just now.
    drives_on(&robot, &platform, platform.truth().distance);
    // Nothing failed: the base's supervisor took no step.
    assert!(robot.base.snapshot().supervision.is_empty());
    let report = robot.shutdown();
    assert!(report.clean(), "{report:?}");
}

#[test]
fn a_motion_controller_past_its_max_response_is_restarted_until_its_budget_is_spent() {
    use mobile_base::robot::MOTION;

    let platform = platform(None);
    let robot = quiet_robot(&platform);
    wait_member(
        &robot,
        &platform,
        MOTION,
        |m| m.state == State::Running && driven(m) > 0.05,
        Duration::from_secs(3),
    )
    .expect("the base gets going");
    // The platform's bus hangs once for 30 ms, three times the motion controller's
    // `max_response` (10 ms): the section overruns and the controller fails.
    platform.hiccup(Duration::from_millis(30));
    let overran = wait_member(
        &robot,
        &platform,
        MOTION,
        |m| m.overruns == 1 && m.state == State::Running,
        Duration::from_secs(2),
    )
    .expect("the motion controller overran and runs again");
    assert_eq!(overran.error, None, "{overran:?}");
    // `on error motion: restart`: the base restarted it in place, and nothing
    // propagated: the base and the robot run on.
    let steps: Vec<(String, Step)> = robot
        .base
        .snapshot()
        .supervision
        .into_iter()
        .map(|s| (s.instance, s.step))
        .collect();
    assert_eq!(
        steps,
        [
            (MOTION.to_owned(), Step::Failed),
            (MOTION.to_owned(), Step::Restarted)
        ]
    );
    assert_eq!(robot.base.state(), State::Running);
    assert_eq!(robot.robot.state(), State::Running);
    let above = robot.robot.snapshot().supervision;
    assert!(!above.iter().any(|s| s.instance == "base"), "{above:?}");
    // It starts again in `idle` and drives on.
    drives_on(&robot, &platform, driven(&overran));

    // Two more hangs within 10 s: restarted each time (`limit 3 in 10s`).
    for overruns in 2..=3 {
        platform.hiccup(Duration::from_millis(30));
        wait_member(
            &robot,
            &platform,
            MOTION,
            |m| m.overruns == overruns && m.state == State::Running,
            Duration::from_secs(2),
        )
        .expect("restarted again");
    }
    assert_eq!(robot.base.state(), State::Running);
    // The fourth is beyond the budget: it propagates, and the base fails.
    platform.hiccup(Duration::from_millis(30));
    step_until(
        &platform,
        &robot.base,
        |m| m.state == State::RunningError,
        Duration::from_secs(2),
    )
    .expect("the fourth failure propagates");
    let steps: Vec<Step> = robot
        .base
        .snapshot()
        .supervision
        .into_iter()
        .filter(|s| s.instance == MOTION)
        .map(|s| s.step)
        .collect();
    let mut expected: Vec<Step> = (0..3)
        .flat_map(|_| [Step::Failed, Step::Restarted])
        .collect();
    expected.extend([Step::Failed, Step::Propagated]);
    assert_eq!(steps, expected);
    let report = robot.shutdown();
    assert!(report.clean(), "{report:?}");
}

#[test]
fn a_hold_stops_the_platform_and_its_release_drives_on() {
    use coolbot::{Command, MonitorEvent, Value};
    use mobile_base::robot::{MOTION, Robot, Setup};

    let platform = platform(None);
    let robot = Robot::start(&platform, &Setup::default()).expect("the robot starts");
    let motion = robot.instance("base.motion").expect("base.motion");
    wait_member(
        &robot,
        &platform,
        MOTION,
        |m| driven(m) > 0.05,
        Duration::from_secs(5),
    )
    .expect("the base gets going");
    let motion_events = motion.subscribe();

    // The operator holds the base: its supervisor goes to `stopped`, whose entry
    // section suspends the motion controller, so the platform stands still.
    robot
        .base
        .command(Command::Set("hold".to_owned(), Value::Bool(true)))
        .unwrap();
    step_until(
        &platform,
        &robot.base,
        |m| m.user_state.as_deref() == Some("stopped"),
        Duration::from_secs(5),
    )
    .expect("the base stops");
    step_until(
        &platform,
        &motion,
        |m| m.state == State::Suspended,
        Duration::from_secs(5),
    )
    .expect("the motion controller is suspended");
    let commanded = |command: &str| {
        let command = command.to_owned();
        move |m: &Monitor| {
            m.supervision.iter().any(|s| {
                s.instance == MOTION
                    && s.step
                        == Step::Commanded {
                            command: command.clone(),
                        }
            })
        }
    };
    step_until(
        &platform,
        &robot.base,
        commanded("suspend"),
        Duration::from_secs(5),
    )
    .expect("the command is a step on the base's monitoring port");
    // Suspended, the motion controller runs no section: the platform does not move
    // (the ground truth is what it drove; a suspended controller drives nothing),
    // however long it is held.
    let held_at = platform.truth().distance;
    advance(&platform, Duration::from_secs(1));
    assert_eq!(platform.truth().distance, held_at);
    assert_eq!(motion.state(), State::Suspended);

    // Released: `operating` resumes it and the platform drives on.
    robot
        .base
        .command(Command::Set("hold".to_owned(), Value::Bool(false)))
        .unwrap();
    step_until(
        &platform,
        &robot.base,
        commanded("run"),
        Duration::from_secs(5),
    )
    .expect("`operating` resumes the motion controller");
    wait_member(
        &robot,
        &platform,
        MOTION,
        |m| driven(m) > held_at + 0.05,
        Duration::from_secs(5),
    )
    .expect("moving again");
    // While held, the motion controller's state went to `suspended` and came back
    // only through the supervisor's command.
    let states: Vec<State> = motion_events
        .try_iter()
        .filter_map(|event| match event {
            MonitorEvent::State { to, .. } => Some(to),
            _ => None,
        })
        .collect();
    assert_eq!(states, [State::Suspended, State::Running]);
    let report = robot.shutdown();
    assert!(report.clean(), "{report:?}");
}

#[test]
fn the_base_supervisor_goes_degraded_and_back_to_operating_on_its_monitoring_port() {
    use coolbot::MonitorEvent;
    use mobile_base::robot::{Robot, Setup};
    use mobile_base::world::FaultKind;

    let platform = platform(Some(SensorFault {
        after: Duration::from_millis(600),
        outage: Duration::from_millis(600),
        kind: FaultKind::Raise,
    }));
    let robot = Robot::start(&platform, &Setup::default()).expect("the robot starts");
    let events = robot.base.subscribe();
    // The state it is in now, then every change the base's monitoring port publishes.
    let mut states: Vec<String> = robot.base.snapshot().user_state.into_iter().collect();
    let mut modes: Vec<String> = Vec::new();
    while states.len() < 3 && platform.uptime() < Duration::from_secs(8) {
        step(&platform);
        for event in events.try_iter() {
            match event {
                MonitorEvent::UserState(Some(state)) if states.last() != Some(&state) => {
                    states.push(state);
                }
                MonitorEvent::Variable { name, value } if name == "mode" => {
                    modes.push(mobile_base::status::value(&value));
                }
                _ => {}
            }
        }
    }
    assert_eq!(states, ["operating", "degraded", "operating"]);
    // The supervisor's entry sections set `mode` and counted the fault.
    assert!(modes.starts_with(&["Degraded".to_owned()]), "{modes:?}");
    let var = |monitor: &Monitor, name: &str| {
        monitor
            .variables
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| mobile_base::status::value(v))
    };
    // `operating`'s entry section runs just after the state change is published.
    let monitor = step_until(
        &platform,
        &robot.base,
        |m| var(m, "mode").as_deref() == Some("Normal"),
        Duration::from_secs(1),
    )
    .expect("`operating`'s entry section sets `mode` back to Normal");
    assert_eq!(var(&monitor, "faults").as_deref(), Some("1"));
    // While the substitute stood in, `degraded` drove the motion controller at the
    // cautious speed, and its exit put the limit back.
    let commands: Vec<String> = monitor
        .supervision
        .iter()
        .filter_map(|s| match &s.step {
            Step::Commanded { command } if s.instance == "motion" => Some(command.clone()),
            _ => None,
        })
        .collect();
    assert_eq!(commands, ["set max_speed = 0.25", "set max_speed = 0.5"]);
    let report = robot.shutdown();
    assert!(report.clean(), "{report:?}");
}

#[test]
fn a_recorded_run_holds_every_odometry_and_scan_packet_or_counts_it_lost() {
    use coolbot::record::{Reader, Record};
    use mobile_base::generated::types::{Pose2D, RangeScan};

    let dir = std::env::temp_dir().join(format!("mobile-base-record-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join("run.mcap");
    let summary = run(Options {
        duration: Duration::from_secs(2),
        record: Some(path.clone()),
        ..Options::default()
    });
    assert_clean_shutdown(&summary);
    let recorded = summary.recorded.as_ref().expect("a recording summary");
    let ports: Vec<&str> = recorded.ports.iter().map(|p| p.port.as_str()).collect();
    assert_eq!(ports, mobile_base::RECORDED_PORTS);
    for port in &recorded.ports {
        assert!(port.sent > 0, "nothing sent on {}", port.port);
        assert_eq!(port.sent, port.recorded + port.lost, "{}", port.port);
    }

    let reader = Reader::open(&path).expect("the recording opens");
    let poses: Vec<Pose2D> = reader
        .packets::<Pose2D>(mobile_base::RECORDED_PORTS[0])
        .map(|item| item.expect("a pose").1)
        .collect();
    assert_eq!(poses.len() as u64, recorded.ports[0].recorded);
    let moved = poses
        .windows(2)
        .any(|pair| pair[0].x != pair[1].x || pair[0].y != pair[1].y);
    assert!(moved, "the recorded odometry shows the robot moving");
    let scans: Vec<RangeScan> = Reader::open(&path)
        .expect("opens")
        .packets::<RangeScan>(mobile_base::RECORDED_PORTS[1])
        .map(|item| item.expect("a scan").1)
        .collect();
    assert_eq!(scans.len() as u64, recorded.ports[1].recorded);
    let last = Reader::open(&path)
        .expect("opens")
        .last()
        .expect("a record")
        .expect("readable");
    assert!(
        matches!(last, Record::End(_)),
        "the file ends with its summary"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_processor_shortage_degrades_the_range_server_and_it_is_promoted_back_after() {
    use coolbot::MonitorEvent;
    use coolbot::adapt::{AdaptAction, Adaptation};
    use mobile_base::robot::{RANGES, Robot, Setup};

    let platform = platform(None);
    let robot = Robot::start(&platform, &Setup::default()).expect("the robot starts");
    let ranges = robot.instance("base.ranges").expect("base.ranges");
    let events = ranges.subscribe();
    let base_events = robot.base.subscribe();
    let mut own: Vec<Adaptation> = Vec::new();
    let mut decisions: Vec<Adaptation> = Vec::new();
    // Advances the clock (at most `limit`) until `pred` holds on the range server's
    // monitoring port, keeping the adaptation steps the range server and the base
    // published meanwhile. During the shortage a scan takes its time on the virtual
    // clock (`Platform::spend`: the section waits while the clock moves on), and the
    // idle probe says the processor has none to spare (`VirtualClock::set_idle`): the
    // machine's real load plays no part.
    let mut wait = |what: &str, pred: &dyn Fn(&Monitor) -> bool, limit: Duration| {
        let until = platform.uptime() + limit;
        loop {
            for event in events.try_iter() {
                if let MonitorEvent::Adaptation(step) = event {
                    own.push(step);
                }
            }
            for event in base_events.try_iter() {
                if let MonitorEvent::Adaptation(step) = event
                    && step.component == RANGES
                {
                    decisions.push(step);
                }
            }
            let monitor = ranges.snapshot();
            if pred(&monitor) {
                return monitor;
            }
            assert!(
                platform.uptime() < until,
                "{what}: not within {limit:?}; the range server: period {:?}, quality {}, {:?}",
                monitor.period,
                monitor.quality,
                monitor.adaptation
            );
            step(&platform);
        }
    };
    let scans = |m: &Monitor| {
        m.variables
            .iter()
            .find(|(name, _)| name == "scans")
            .and_then(|(_, value)| value.to_json().as_u64())
            .unwrap_or(0)
    };
    let nominal = |m: &Monitor| {
        m.adaptation.level == 0 && m.quality == 0 && m.period == Some(Duration::from_millis(50))
    };

    // The description gives the range server degraded modes: adaptation is on, at
    // nominal (50 ms, full scans) to begin with.
    let start = wait(
        "nominal at first",
        &|m| scans(m) > 0,
        Duration::from_secs(10),
    );
    assert!(start.adaptation.enabled, "{:?}", start.adaptation);
    assert_eq!(start.adaptation.max_level, 4, "3 period steps, then `half`");
    assert!(nominal(&start), "{:?}", start.adaptation);

    // The processor gets short: a full scan now takes longer than even the longest
    // period; the runtime stretches the period, then lowers the quality to `half`,
    // which fits.
    platform.set_overloaded(true);
    let degraded = wait(
        "degraded to half scans",
        &|m| m.quality == 1,
        Duration::from_secs(90),
    );
    assert_eq!(degraded.adaptation.level, 4, "{:?}", degraded.adaptation);
    assert_eq!(degraded.period, Some(Duration::from_millis(100)));
    let during = scans(&degraded);
    wait(
        "scans flow while degraded",
        &|m| scans(m) >= during + 3,
        Duration::from_secs(30),
    );

    // The shortage is over: spare time, promotions back to nominal.
    platform.set_overloaded(false);
    let back = wait("back to nominal", &nominal, Duration::from_secs(120));
    let after = scans(&back);
    wait(
        "scans flow after",
        &|m| scans(m) >= after + 3,
        Duration::from_secs(30),
    );
    assert_eq!(back.state, State::Running);
    assert_eq!(back.error, None);

    // The range server's own steps: degraded one level at a time up to `half`, then
    // promoted one level at a time back to nominal (the steps it applied, period and
    // quality included).
    let levels: Vec<(AdaptAction, u32)> = own.iter().map(|s| (s.action, s.to)).collect();
    let top = own
        .iter()
        .position(|s| s.to == 4)
        .unwrap_or_else(|| panic!("never at level 4: {levels:?}"));
    for pair in own[..=top].windows(2) {
        assert!(pair[1].to >= pair[0].to, "{levels:?}");
    }
    assert_eq!(
        own[top].quality,
        Some(1),
        "level 4 is the half scan: {levels:?}"
    );
    assert!(
        own[top..]
            .iter()
            .any(|s| s.action == AdaptAction::Promoted && s.to == 0),
        "{levels:?}"
    );
    // The base's supervisor decided them (the range server is its instance).
    assert!(
        decisions.iter().any(|s| s.action == AdaptAction::Degraded),
        "{decisions:?}"
    );
    assert!(
        decisions.iter().any(|s| s.action == AdaptAction::Promoted),
        "{decisions:?}"
    );
    let report = robot.shutdown();
    assert!(report.clean(), "{report:?}");
}

#[cfg(feature = "network")]
#[test]
fn with_a_node_every_component_answers_coolctl_on_the_network() {
    use coolbot::{Command, Value};
    use coolbot_zenoh::ctl::Ctl;
    use coolbot_zenoh::{ControlReply, Node, peer_config};
    use mobile_base::node::NodeOptions;
    use std::time::Instant;

    // The robot's node listens on a free loopback port; multicast scouting is off so
    // that parallel runs on the machine do not meet.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|listener| listener.local_addr())
        .map(|address| address.port())
        .expect("a free loopback port");
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let name = format!("mobile-base-test-{}", std::process::id());
    // The station the robot's description places the wanderer on (`on "station"`),
    // here in the test's process: a node with an agent that can build a wanderer.
    let station_port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|listener| listener.local_addr())
        .map(|address| address.port())
        .expect("a free loopback port");
    let station_endpoint = format!("tcp/127.0.0.1:{station_port}");
    let station = Arc::new(
        Node::open(
            "station",
            peer_config(std::slice::from_ref(&station_endpoint), &[], false).expect("config"),
        )
        .expect("the station opens"),
    );
    let mut registry = coolbot_zenoh::agent::Registry::new();
    mobile_base::generated::wanderer::register(&mut registry, |name| {
        mobile_base::generated::wanderer::component(
            name,
            mobile_base::wanderer::Wanderer::default(),
        )
    });
    let _agent = coolbot_zenoh::agent::Agent::start(station, registry).expect("the agent");
    let options = Options {
        duration: Duration::from_secs(120),
        node: Some(NodeOptions {
            listen: vec![endpoint.clone()],
            connect: vec![station_endpoint],
            multicast: Some(false),
            ..NodeOptions::named(name.clone())
        }),
        ..Options::default()
    };
    let stop = options.stop.clone();
    // On the real clock: the network and the station keep real time; nothing here
    // waits for a timer, the test polls with a deadline.
    let runner = std::thread::spawn(move || run_on(options));

    // What `coolctl --connect <endpoint> --no-multicast list <name>` does.
    let probe = Node::open(
        &format!("probe-{}", std::process::id()),
        peer_config(&[], &[endpoint], false).expect("config"),
    )
    .expect("the probe opens");
    let ctl = Ctl::new(probe.session().clone(), Duration::from_secs(2));
    let expected = [
        "robot",
        "robot.base",
        "robot.base.motion",
        "robot.base.ranges",
        "robot.base.sim_ranges",
        "robot.fallback",
        "robot.mapper",
        "robot.teleop",
        "robot.wanderer",
    ];
    let deadline = Instant::now() + Duration::from_secs(60);
    let listed = loop {
        let listed = ctl.components(Some(&name)).unwrap_or_default();
        let paths: Vec<&str> = listed.iter().map(|l| l.path.as_str()).collect();
        if paths == expected {
            break listed;
        }
        assert!(
            Instant::now() < deadline && !runner.is_finished(),
            "the node did not list every component: {paths:?}"
        );
        std::thread::sleep(Duration::from_millis(200));
    };
    for component in &listed {
        let state = component.monitor.state;
        // The substitutes wait on standby; every other component runs (the wanderer's
        // proxy mirrors the wanderer on the station).
        let wanted =
            if component.path.ends_with("sim_ranges") || component.path.ends_with("fallback") {
                State::Ready
            } else {
                State::Running
            };
        assert_eq!(state, wanted, "{}", component.path);
    }
    // The control port answers over the network as it does locally.
    let reply = ctl
        .command(
            &format!("{name}/robot.base"),
            &Command::Set("max_speed".to_owned(), Value::Float(0.3)),
        )
        .expect("the base answers");
    assert_eq!(reply, ControlReply::Accepted);
    // Outside the range the motion controller declares: refused, with the range.
    let reply = ctl
        .command(
            &format!("{name}/robot.base"),
            &Command::Set("max_speed".to_owned(), Value::Float(100.0)),
        )
        .expect("the base answers");
    assert!(
        matches!(&reply, ControlReply::Rejected { reason }
            if reason.contains("100.0 is outside its range 0.0..=1.0")),
        "{reply:?}"
    );
    let reply = ctl
        .command(
            &format!("{name}/robot.base"),
            &Command::Set("faults".to_owned(), Value::UInt(0)),
        )
        .expect("the base answers");
    assert!(
        matches!(reply, ControlReply::Rejected { .. }),
        "`faults` is observable: {reply:?}"
    );

    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let summary = runner.join().expect("the run ends");
    assert_eq!(summary.node, Some((name, expected.len())));
    assert_clean_shutdown(&summary);
}

#[test]
fn the_mappers_responses_grow_late_under_a_processor_shortage_its_quality_drops_and_comes_back() {
    use mobile_base::robot::{Robot, Setup};

    let platform = platform(None);
    let robot = Robot::start(&platform, &Setup::default()).expect("the robot starts");
    // Advances the clock (at most `limit`) until `pred` holds on the mapper's
    // monitoring port. During the shortage a pose takes its time on the virtual clock
    // (`Platform::spend`: the section waits while the clock moves on, and the poses
    // that come meanwhile queue), whatever the machine's real load.
    let wait = |what: &str, pred: &dyn Fn(&Monitor) -> bool, limit: Duration| {
        let until = platform.uptime() + limit;
        loop {
            let monitor = robot.mapper.snapshot();
            if pred(&monitor) {
                return monitor;
            }
            assert!(
                platform.uptime() < until,
                "{what}: not within {limit:?}; the mapper: quality {}, {:?}, {:?}",
                monitor.quality,
                monitor.response,
                monitor.adaptation
            );
            step(&platform);
        }
    };

    // The description bounds the mapper's responses (aperiodic: no period) and gives
    // it two quality levels: adaptation is on, at `full`, and responses are timed.
    let start = wait(
        "poses mapped at first",
        &|m| m.response.count >= 10,
        Duration::from_secs(10),
    );
    assert!(start.adaptation.enabled, "{:?}", start.adaptation);
    assert_eq!(start.max_response, Some(Duration::from_millis(150)));
    assert_eq!(start.period, None);

    // The processor gets short: a pose at `full` takes longer than poses take to
    // arrive, they queue, responses pass `max_response`, and the quality drops.
    platform.set_overloaded(true);
    let degraded = wait(
        "late responses and the coarse quality",
        &|m| m.response.late >= 1 && m.quality == 1,
        Duration::from_secs(90),
    );
    assert!(
        degraded.response.worst > Duration::from_millis(150),
        "{:?}",
        degraded.response
    );

    // The shortage is over: responses are short again and the quality comes back.
    platform.set_overloaded(false);
    let back = wait(
        "back to the full quality",
        &|m| m.quality == 0 && m.adaptation.level == 0,
        Duration::from_secs(120),
    );
    let count = back.response.count;
    let after = wait(
        "poses mapped after",
        &|m| m.response.count >= count + 10,
        Duration::from_secs(30),
    );
    assert_eq!(after.state, State::Running);
    assert!(
        after.response.p50 < Duration::from_millis(150),
        "{:?}",
        after.response
    );
    assert!(robot.shutdown().clean());
}

#[test]
fn the_range_server_runs_first_on_the_control_thread_though_it_reads_the_odometry() {
    use mobile_base::robot::{Robot, Setup};

    // `motion.pose -> ranges.pose` closes a cycle with `ranges.scan -> motion.obstacles`;
    // both are `last` inputs, and the group sets aside the one into its first member.
    let platform = platform(None);
    let robot = Robot::start(&platform, &Setup::default()).expect("the robot starts");
    for member in ["base.ranges", "base.motion"] {
        let group = robot
            .instance(member)
            .expect("an instance")
            .snapshot()
            .group
            .expect("a member of a group");
        assert_eq!(
            (group.name.as_str(), group.members.as_slice()),
            (
                "control",
                ["ranges".to_owned(), "motion".to_owned()].as_slice()
            ),
            "{member}"
        );
    }
    let report = robot.shutdown();
    assert!(report.clean(), "{report:?}");
}
