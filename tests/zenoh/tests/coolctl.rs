//! The `coolctl` binary as an operator runs it, against a node started here: `list`,
//! `set`, `get`, `configure`, `degrade` and `echo`, and every command failing within
//! its timeout, with a clear message and a non-zero exit, on a node, component or port
//! that does not exist, an endpoint where nothing answers, a zero timeout, a file too
//! large to be a security file, and `top` without a terminal; and `top --once
//! --json`.

use std::process::{Command, Output};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use coolbot_zenoh::Node;
use coolbot_zenoh_tests::generated::types::Reading;
use coolbot_zenoh_tests::support::{self, PATIENCE, Sourced, node, wait_until};
use zenoh::Wait;

/// The `coolctl` binary, built in this package from its source (`Cargo.toml`).
const COOLCTL: &str = env!("CARGO_BIN_EXE_coolctl-under-test");

/// Node `robot` with `tuner` and `source` (its output `out` echoed, `idle` not),
/// running; and the endpoint to reach it.
fn robot() -> Sourced {
    support::sourced("robot")
}

/// `coolctl ARGS` reaching `endpoint` only.
fn coolctl(endpoint: &str, args: &[&str]) -> Output {
    Command::new(COOLCTL)
        .args(["--connect", endpoint, "--no-multicast", "--timeout", "2s"])
        .args(args)
        .output()
        .expect("coolctl runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// `coolctl get robot/tuner` once it sees the node (its session needs a moment to
/// connect the first time).
fn get_tuner(endpoint: &str) -> String {
    let mut last = None;
    assert!(
        wait_until(PATIENCE, || {
            let out = coolctl(endpoint, &["get", "robot/tuner"]);
            let ok = out.status.success();
            last = Some(out);
            ok
        }),
        "coolctl get never succeeded: {last:?}"
    );
    text(&last.unwrap().stdout)
}

#[test]
fn get_shows_every_variable_with_kind_type_and_value_and_configure_changes_them() {
    let robot = robot();
    let before = get_tuner(&robot.endpoint);
    insta::assert_snapshot!("get_tuner", before);

    // A configuration, typed: a float and a string; the others keep their values.
    let out = coolctl(
        &robot.endpoint,
        &[
            "configure",
            "robot/tuner",
            "gain=2.25",
            "label=\"tuned up\"",
        ],
    );
    assert_eq!(text(&out.stdout), "accepted\n", "{}", text(&out.stderr));
    assert!(out.status.success());
    // The observables follow at the next period.
    let mut after = String::new();
    assert!(
        wait_until(PATIENCE, || {
            after = get_tuner(&robot.endpoint);
            after.contains("gain      observable    f64     2.25")
        }),
        "{after}"
    );
    assert!(
        after.contains("label     observable    String  \"tuned up\""),
        "{after}"
    );

    // Refused by the component: the answer is printed, the exit status is 1.
    for (fields, reason) in [
        (&["gain=fast"][..], "invalid type"),
        (&["gian=2"], "unknown field `gian`"),
    ] {
        let mut args = vec!["configure", "robot/tuner"];
        args.extend_from_slice(fields);
        let out = coolctl(&robot.endpoint, &args);
        let stdout = text(&out.stdout);
        assert!(stdout.starts_with("rejected: "), "{stdout}");
        assert!(stdout.contains(reason), "{stdout}");
        assert_eq!(out.status.code(), Some(1), "{stdout}");
    }
    // Malformed on the command line: usage, exit 2, nothing sent.
    let out = coolctl(&robot.endpoint, &["configure", "robot/tuner", "gain"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("`gain` is not FIELD=VALUE"));

    // `degrade`: a component without adaptation refuses, with the reason.
    let out = coolctl(&robot.endpoint, &["degrade", "robot/tuner", "1"]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stdout));
    assert!(
        text(&out.stdout).starts_with("rejected: "),
        "{}",
        text(&out.stdout)
    );
    drop(robot.node);
    robot.system.shutdown();
}

#[test]
fn echo_prints_packets_as_json_lines_and_counts_what_it_skips() {
    let robot = robot();
    get_tuner(&robot.endpoint);
    // The producer sends as fast as it can meanwhile: never slowed by the echo.
    let stop = Arc::new(AtomicBool::new(false));
    let producer = {
        let stop = Arc::clone(&stop);
        let out = robot.out.clone();
        std::thread::spawn(move || {
            let mut n = 0;
            while !stop.load(Ordering::Relaxed) {
                out.send(Reading {
                    n,
                    label: "r".to_owned(),
                });
                n += 1;
                std::thread::sleep(Duration::from_micros(200));
            }
            n
        })
    };
    let out = coolctl(
        &robot.endpoint,
        &["echo", "robot/source.out", "--count", "5"],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let lines: Vec<Reading> = text(&out.stdout)
        .lines()
        .map(|line| serde_json::from_str(line).expect("a JSON packet per line"))
        .collect();
    assert_eq!(lines.len(), 5, "{}", text(&out.stdout));
    assert!(lines.windows(2).all(|w| w[0].n < w[1].n), "{lines:?}");
    assert!(
        text(&out.stderr).contains("coolctl echo robot/source.out: "),
        "{}",
        text(&out.stderr)
    );

    // At 5 lines a second for a second and a half: a handful printed, the rest
    // received and counted as skipped.
    let out = coolctl(
        &robot.endpoint,
        &["echo", "robot/source.out", "--hz", "5", "--for", "1500ms"],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let printed = text(&out.stdout).lines().count();
    assert!((1..=8).contains(&printed), "{printed} lines");
    let summary = text(&out.stderr);
    let skipped: u64 = summary
        .split(", ")
        .find_map(|part| part.strip_suffix(" skipped (--hz)"))
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no skipped count in {summary}"));
    assert!(skipped > 0, "{summary}");

    // A node's batch holds the packets of every output someone asks for: `echo` prints
    // its own output's only. Batches naming another output come all along.
    let others = {
        let stop = Arc::clone(&stop);
        let session = robot.node.session().clone();
        std::thread::spawn(move || {
            let other = r#"[{"output":"source.idle","seq":0,"dropped":0,"sent":1,"packet":{"n":7,"label":"not asked for"}}]"#;
            while !stop.load(Ordering::Relaxed) {
                session.put("coolbot/robot/o", other).wait().unwrap();
                std::thread::sleep(Duration::from_millis(2));
            }
        })
    };
    let out = coolctl(
        &robot.endpoint,
        &["echo", "robot/source.out", "--for", "1s"],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let lines: Vec<Reading> = text(&out.stdout)
        .lines()
        .map(|line| serde_json::from_str(line).expect("a JSON packet per line"))
        .collect();
    assert!(!lines.is_empty());
    assert!(lines.iter().all(|line| line.label == "r"), "{lines:?}");
    stop.store(true, Ordering::Relaxed);
    others.join().unwrap();
    let sent = producer.join().unwrap();
    assert!(sent > 0);
    drop(robot.node);
    robot.system.shutdown();
}

#[test]
fn every_command_fails_fast_and_clearly_on_what_does_not_exist() {
    let robot = robot();
    get_tuner(&robot.endpoint);
    let cases: &[(&[&str], &str)] = &[
        (
            &["get", "nobody/tuner"],
            "no node `nobody` is alive (nodes alive: robot)",
        ),
        (
            &["get", "robot/tunr"],
            "node `robot` has no component `tunr` (its components: source, tuner)",
        ),
        (
            &["watch", "robot/tunr", "--count", "1"],
            "node `robot` has no component `tunr`",
        ),
        (
            &["set", "robot/tunr", "state", "suspended"],
            "node `robot` has no component `tunr`",
        ),
        (
            &["configure", "robot/tunr", "gain=1"],
            "node `robot` has no component `tunr`",
        ),
        (
            &["degrade", "nobody/tuner", "1"],
            "no node `nobody` is alive",
        ),
        (
            &["list", "nobody"],
            "no node `nobody` is alive (nodes alive: robot)",
        ),
        (
            &["echo", "robot/tunr.out", "--count", "1"],
            "node `robot` has no component `tunr`",
        ),
        (
            &["echo", "robot/source.nope", "--count", "1"],
            "`robot/source` has no output `nope` (its outputs: out, idle)",
        ),
        (
            &["echo", "robot/source.idle", "--count", "1"],
            "node `robot` does not echo `source.idle` (it echoes out of `source`",
        ),
    ];
    for (args, message) in cases {
        let started = Instant::now();
        let out = coolctl(&robot.endpoint, args);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
        assert!(stderr.contains(message), "{args:?}: {stderr}");
        assert!(out.stdout.is_empty(), "{args:?}: {}", text(&out.stdout));
        // Bounded: the session, the timeout of a query or two, never a wait forever.
        assert!(
            started.elapsed() < PATIENCE,
            "{args:?} took {:?}",
            started.elapsed()
        );
    }
    // Usage errors: exit 2.
    for args in [
        &["echo", "robot/source", "--count", "1"][..],
        &["get", "robot"],
    ] {
        let out = coolctl(&robot.endpoint, args);
        assert_eq!(
            out.status.code(),
            Some(2),
            "{args:?}: {}",
            text(&out.stderr)
        );
    }
    drop(robot.node);
    robot.system.shutdown();
}

/// What `coolctl list robot` prints through the library on `station`'s session, once
/// it sees the six components of `support::robot`.
fn library_list(station: &Node) -> String {
    let ctl = coolbot_zenoh::ctl::Ctl::new(station.session().clone(), Duration::from_secs(5));
    assert!(
        wait_until(PATIENCE, || ctl
            .components(Some("robot"))
            .is_ok_and(|listed| listed.len() == 6)),
        "the station does not see the robot's components"
    );
    let mut out = Vec::new();
    ctl.list(Some("robot"), &mut out).unwrap();
    String::from_utf8(out).unwrap()
}

/// The robot of `support::robot` (nested compounds), listed by the binary as by the
/// library; its answers and exit codes (from `tests/zenoh/tests/remote.rs`, whose
/// other tests run on generated components: this one needs the binary, which only
/// this package's tests can run).
#[test]
fn the_coolctl_binary_prints_what_the_library_prints() {
    let (robot_node, endpoint) = node("robot", &[]);
    let _system = support::robot(&robot_node);
    let (station, _) = node("station", std::slice::from_ref(&endpoint));
    let expected = library_list(&station);
    let run = |args: &[&str]| {
        let output = Command::new(COOLCTL)
            .args(["--connect", &endpoint, "--no-multicast", "--timeout", "5s"])
            .args(args)
            .output()
            .expect("coolctl runs");
        (
            output.status.code(),
            String::from_utf8_lossy(&output.stdout).into_owned(),
            String::from_utf8_lossy(&output.stderr).into_owned(),
        )
    };
    let (code, stdout, stderr) = run(&["list", "robot"]);
    assert_eq!(code, Some(0), "{stderr}");
    assert_eq!(stdout, expected);
    let (code, stdout, _) = run(&["set", "robot/robot.planner", "nothing=1"]);
    assert_eq!(code, Some(1));
    assert!(
        stdout.starts_with("rejected: no variable `nothing` (") && stdout.contains("`configure`"),
        "{stdout}"
    );
    let (code, _, stderr) = run(&["set", "robot", "state", "running"]);
    assert_eq!(code, Some(2));
    assert!(stderr.contains("not a component address"), "{stderr}");
}

/// `coolctl top --once --json` from the real binary, against `support::robot` (from
/// `tests/zenoh/tests/top.rs`, whose other tests run on generated components: this one
/// needs the binary, which only this package's tests can run).
#[test]
fn coolctl_top_once_json_prints_every_node_and_component() {
    let (robot_node, endpoint) = node("json-robot", &[]);
    let system = support::robot(&robot_node);
    let output = Command::new(COOLCTL)
        .args([
            "--connect",
            &endpoint,
            "--no-multicast",
            "top",
            "--once",
            "--json",
            "--refresh",
            "200ms",
        ])
        .output()
        .expect("coolctl runs");
    assert!(output.status.success(), "{output:?}");
    let json: serde_json::Value = serde_json::from_slice(&output.stdout).expect("JSON");
    assert_eq!(json["nodes"], serde_json::json!(["json-robot"]));
    assert_eq!(json["lost"], serde_json::json!([]));
    let paths: Vec<&str> = json["components"]
        .as_array()
        .expect("components")
        .iter()
        .map(|c| c["path"].as_str().expect("a path"))
        .collect();
    assert_eq!(
        paths,
        [
            "logger",
            "robot",
            "robot.base",
            "robot.base.motion",
            "robot.base.ranges",
            "robot.planner"
        ]
    );
    assert_eq!(json["components"][1]["monitor"]["state"], "Running");
    assert!(system.shutdown().clean());
}

/// `coolctl ARGS` (global options included), killed if it has not ended within
/// `PATIENCE`: the test fails then, rather than waiting forever.
fn coolctl_bounded(args: &[&str]) -> Output {
    let mut child = Command::new(COOLCTL)
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("coolctl runs");
    let deadline = Instant::now() + PATIENCE;
    while child.try_wait().expect("coolctl's status").is_none() {
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("coolctl {args:?} did not end within {PATIENCE:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().expect("coolctl's output")
}

/// An endpoint on loopback where nothing listens.
fn nowhere() -> String {
    format!("tcp/127.0.0.1:{}", support::free_port())
}

#[test]
fn what_finds_nothing_says_why_and_exits_1() {
    let endpoint = nowhere();
    for (args, message) in [
        (
            &["nodes"][..],
            "no node is alive (none answered within 2s; this session reached no Zenoh peer",
        ),
        (
            &["list"],
            "no node is alive (none answered within 2s; this session reached no Zenoh peer",
        ),
        (&["list", "robot"], "no node is alive"),
        (&["top", "--once", "--refresh", "100ms"], "no node is alive"),
        (
            &["top", "--once", "--json", "--refresh", "100ms"],
            "no node is alive",
        ),
    ] {
        let out = coolctl(&endpoint, args);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
        assert!(
            stderr.starts_with("coolctl: ") && stderr.contains(message),
            "{args:?}: {stderr}"
        );
        assert!(out.stdout.is_empty(), "{args:?}: {}", text(&out.stdout));
    }
    // A node alive with no component (an agent's station before anything is placed).
    let (_bare, endpoint) = node("bare", &[]);
    let mut out = coolctl(&endpoint, &["list", "bare"]);
    assert!(
        wait_until(PATIENCE, || {
            out = coolctl(&endpoint, &["list", "bare"]);
            text(&out.stderr).contains("is alive")
        }),
        "{}",
        text(&out.stderr)
    );
    assert_eq!(out.status.code(), Some(1));
    assert!(
        text(&out.stderr)
            .contains("node `bare` is alive, but no component of it answered within 2s"),
        "{}",
        text(&out.stderr)
    );
    // No time to answer in: refused as usage.
    let out = coolctl_bounded(&[
        "--connect",
        &endpoint,
        "--no-multicast",
        "--timeout",
        "0s",
        "list",
    ]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    assert!(
        text(&out.stderr).contains("nothing answers in no time"),
        "{}",
        text(&out.stderr)
    );
}

#[test]
fn files_given_are_read_up_to_a_size_limit() {
    let endpoint = nowhere();
    // Endless: refused at the limit, not read forever.
    let out = coolctl_bounded(&[
        "--connect",
        &endpoint,
        "--no-multicast",
        "--config",
        "/dev/zero",
        "nodes",
    ]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    assert!(
        text(&out.stderr).contains("/dev/zero: larger than 1024 KiB"),
        "{}",
        text(&out.stderr)
    );
}

#[test]
fn top_without_a_terminal_says_so_and_exits_2() {
    // Its standard output is a pipe here.
    let out = coolctl_bounded(&["--connect", &nowhere(), "--no-multicast", "top"]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("`coolctl top` needs a terminal (its standard output is not one)")
            && stderr.contains("--once"),
        "{stderr}"
    );
}
