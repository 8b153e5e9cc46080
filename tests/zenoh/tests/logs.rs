//! What the network layer logs when a peer or a fault repeats itself: a flood of
//! packets that do not decode gives one line (the rest are counted, at the inlet's
//! `network` port, and in the next line let through); a node that is lost gives one
//! line when it goes and one when it is back, while each retry of the recovery queue
//! fails at once, without asking the lost node, and is published as a step; a node
//! that never comes fails the first start with a reason that names it.
//!
//! The lines are captured by a `tracing` subscriber of this test binary's own.

use std::io::Write;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use coolbot::{MonitorEvent, OutputKind, State, Step, System};
use coolbot_zenoh::agent::{Agent, Instantiate, instantiate};
use coolbot_zenoh::{Error, Placer};
use coolbot_zenoh_tests::dying::{registry, started_cell};
use coolbot_zenoh_tests::generated::latest;
use coolbot_zenoh_tests::support::{PATIENCE, node, pair, wait_subscribed, wait_until};
use zenoh::Wait;

/// Every line logged in this process, from any thread.
static LINES: Mutex<Vec<u8>> = Mutex::new(Vec::new());

struct Capture;

impl Write for Capture {
    fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        LINES.lock().unwrap().extend_from_slice(bytes);
        Ok(bytes.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// The tests of this file one at a time: they read one process-wide capture, and the
/// same call sites' rate limits.
static SERIAL: Mutex<()> = Mutex::new(());

/// Capture every line at `info` and above (once per process); the test holds the
/// returned guard for its whole run.
fn capture() -> std::sync::MutexGuard<'static, ()> {
    let serial = SERIAL
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let _ = tracing_subscriber::fmt()
        .with_writer(|| Capture)
        .with_ansi(false)
        .without_time()
        .with_max_level(tracing_subscriber::filter::LevelFilter::INFO)
        .try_init();
    serial
}

/// The lines captured so far that contain every one of `parts`.
fn lines_with(parts: &[&str]) -> Vec<String> {
    String::from_utf8_lossy(&LINES.lock().unwrap())
        .lines()
        .filter(|line| parts.iter().all(|part| line.contains(part)))
        .map(str::to_owned)
        .collect()
}

struct Nothing;

impl latest::Behavior for Nothing {}

#[test]
fn a_flood_of_packets_that_do_not_decode_is_counted_whole_and_logged_once() {
    let _serial = capture();
    let (a, b) = pair("flood-a", "flood-b");
    let key = "test/flood";
    let mut consumer = System::new();
    consumer
        .add(
            b.inlet::<coolbot_zenoh_tests::generated::types::Pose>("inlet", key, OutputKind::Data)
                .build()
                .unwrap(),
        )
        .unwrap();
    consumer.add(latest::component("sink", Nothing)).unwrap();
    consumer.connect("inlet.output", "sink.input").unwrap();
    consumer.run_all().unwrap();
    let inlet = consumer.handle("inlet").unwrap();
    wait_subscribed(&a, key);
    const FLOOD: u64 = 1000;
    let flooded = std::time::Instant::now();
    for _ in 0..FLOOD {
        // Not a postcard `Pose`: too short.
        a.session().put(key, vec![1u8]).wait().unwrap();
    }
    let monitor = inlet
        .wait_for(|m| m.overflows == FLOOD, PATIENCE)
        .expect("every undecodable packet counted");
    assert_eq!(
        monitor.port_overflows,
        vec![("network".to_owned(), FLOOD), ("resets".to_owned(), 0)]
    );
    // One line, then at most one every 10 s (`coolbot::log::EVERY`), however many.
    let logged = lines_with(&["inlet lost a packet", key]);
    let windows = 1 + usize::try_from(flooded.elapsed().as_secs() / 10).unwrap();
    assert!(
        !logged.is_empty() && logged.len() <= windows,
        "{} lines in {windows} window(s): {logged:#?}",
        logged.len()
    );
    assert!(consumer.shutdown().clean());
}

#[test]
fn a_node_lost_is_logged_once_when_it_goes_and_once_when_it_is_back() {
    let _serial = capture();
    // The robot listens; the station connects to it, so that a new station can.
    let (robot, endpoint) = node("lossy-robot", &[]);
    let robot = Arc::new(robot);
    let station = |what: &str| {
        let (station, _) = node("dying-station", std::slice::from_ref(&endpoint));
        let station = Arc::new(station);
        let agent = Agent::start(Arc::clone(&station), registry()).expect("agent");
        assert!(
            wait_until(PATIENCE, || {
                coolbot_zenoh::ctl::Ctl::new(robot.session().clone(), Duration::from_millis(500))
                    .node_names()
                    .is_ok_and(|names| names.iter().any(|n| n == "dying-station"))
            }),
            "the robot sees the {what} station"
        );
        (station, agent)
    };
    let (first, agent) = station("first");
    let _placer = Placer::new(Arc::clone(&robot), registry()).install();
    let mut system = System::new();
    let cell = started_cell(&mut system);
    cell.instance("flaky")
        .unwrap()
        .wait_for(|m| m.state == State::Running, PATIENCE)
        .unwrap_or_else(|timeout| panic!("the remote instance runs: {timeout}"));

    // The station goes, and stays away while the recovery queue retries (every
    // 200 ms): each retry fails at once with the node's loss, and is published.
    let events = cell.subscribe();
    drop(agent);
    drop(first);
    let lost = "node `dying-station` is lost (since ";
    const RETRIES: usize = 8;
    let proxy = cell.instance("flaky").unwrap();
    assert!(
        wait_until(PATIENCE, || proxy
            .snapshot()
            .error
            .is_some_and(|error| error.contains(lost))),
        "the proxy fails on the loss: {:?}",
        proxy.snapshot().error
    );
    // Retries are posted one at a time, and each one's step is published when its
    // answer is taken: those that asked the node before its loss was known are in the
    // queue now. Every later one is refused without asking, and counted.
    let _before_the_loss_was_known = events.try_iter().count();
    let mut retries = 0;
    assert!(
        wait_until(PATIENCE, || {
            retries += events
                .try_iter()
                .filter(|event| {
                    matches!(event, MonitorEvent::Supervision(s)
                        if s.instance == "flaky" && s.step == Step::RetryFailed)
                })
                .count();
            retries >= RETRIES
        }),
        "{retries} retries failed"
    );
    // Each failed at once, on the loss: none asked the lost node.
    let error = proxy.snapshot().error.unwrap_or_default();
    assert!(
        error.starts_with("start failed: on node `dying-station`: ") && error.contains(lost),
        "{error}"
    );
    // One line for the loss, whatever the retries.
    let loss_lines = lines_with(&["WARN", lost, "no instantiation is sent to it"]);
    assert_eq!(loss_lines.len(), 1, "{loss_lines:#?}");
    // The steps are logged as their text: the failure at `info`, the failed retries,
    // routine, at `debug` only (not captured here).
    let failed = lines_with(&["INFO", "compound=cell", "flaky failed"]);
    assert!(!failed.is_empty(), "no step line for the failure");
    let mut retried = lines_with(&["retry failed"]);
    retried.extend(lines_with(&["RetryFailed"]));
    assert!(retried.is_empty(), "{retried:#?}");
    // The proxy's own errors: logged when they change, at most every 10 s, not once
    // a retry (the same error each time).
    let proxy_lines = lines_with(&["WARN", "coolbot::runner", "flaky"]);
    assert!(
        proxy_lines.len() <= 3,
        "{} retries, {} lines: {proxy_lines:#?}",
        RETRIES,
        proxy_lines.len()
    );

    // The station comes back: one line, with the count of what was refused meanwhile;
    // the instance is built there again.
    let (_second, _agent) = station("second");
    cell.wait_for(
        |m| {
            m.supervision
                .iter()
                .any(|s| s.instance == "flaky" && s.step == Step::Recovered)
        },
        PATIENCE,
    )
    .unwrap_or_else(|timeout| panic!("the instance recovers: {timeout}"));
    let back = lines_with(&["WARN", "node `dying-station` is back after "]);
    assert_eq!(back.len(), 1, "{back:#?}");
    let refused: usize = back[0]
        .split(" lost (")
        .nth(1)
        .and_then(|rest| rest.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("a count in {}", back[0]));
    assert!(refused >= RETRIES, "{}", back[0]);
    assert_eq!(
        lines_with(&["WARN", lost, "no instantiation is sent to it"]).len(),
        1,
        "still one line for the loss"
    );
    assert!(system.shutdown().clean());
}

#[test]
fn a_node_that_never_comes_fails_the_proxys_first_start_naming_it() {
    let _serial = capture();
    let (robot, _) = node("lonely-robot", &[]);
    let robot = Arc::new(robot);

    // Asked directly, the agent's absence says how long it was waited for.
    let request = Instantiate {
        type_name: "Flaky".to_owned(),
        name: "nobody".to_owned(),
        wires: Vec::new(),
        configuration: None,
        variables: Vec::new(),
        timing: None,
        run: false,
        owner: None,
    };
    match instantiate(&robot, "dying-station", &request, Duration::from_secs(5)) {
        Err(error @ Error::NoAgent { .. }) => {
            assert!(
                matches!(&error, Error::NoAgent { node, .. } if node == "dying-station"),
                "{error:?}"
            );
            let reason = error.to_string();
            assert!(
                reason.starts_with("node `dying-station`: no agent answered (after ")
                    && reason.contains(", of at most 5.0s;"),
                "{reason}"
            );
        }
        other => panic!("{other:?}"),
    }

    let _placer = Placer::new(Arc::clone(&robot), registry()).install();
    let mut system = System::new();
    // The proxy cannot start: its fault (the spare stands in) says why.
    let cell = started_cell(&mut system);
    let error = coolbot_zenoh_tests::dying::wait_step(
        &cell,
        "flaky",
        |step| *step == Step::Failed,
        "the proxy's start fails",
    );
    assert!(
        error.contains("node `dying-station` is not there: no liveliness token of it was seen")
            && error.contains("reachable from node `lonely-robot`"),
        "{error}"
    );
    assert!(!error.contains("did not reach the condition"), "{error}");
    assert_eq!(cell.state(), State::Running, "on the spare");
    let _ = system.shutdown();
}
