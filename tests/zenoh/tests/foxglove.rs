//! `coolctl foxglove` against a client that is not ours: `@foxglove/ws-protocol`'s
//! `FoxgloveClient` (npm) in Node, every message checked against its channel's JSON
//! Schema by Ajv (`tests/foxglove/client.cjs`). The real `coolctl` binary serves a
//! real node: the client receives the advertisements, subscribes, decodes the echoed
//! packets, the monitoring and the supervision log; a channel nobody watches has no
//! Zenoh subscriber behind it.
//!
//! The client's packages are in `$COOLBOT_FOXGLOVE_CLIENT` (a `node_modules`
//! directory), else `target/foxglove-client/node_modules`; `.ci/run` installs them.
//! Without them these tests fail under CI (`CI` set) and say they are skipped
//! elsewhere, with the command that installs them.

use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use coolbot::crossbeam_channel::{self, Receiver, Sender};
use coolbot::port::DataOut;
use coolbot::{SectionResult, System};
use coolbot_zenoh::Node;
use coolbot_zenoh_tests::generated::types::Reading;
use coolbot_zenoh_tests::generated::{source, tuner};
use coolbot_zenoh_tests::support::{self, PATIENCE, node, wait_until};
use serde_json::{Value, json};
use zenoh::Wait;

const COOLCTL: &str = env!("CARGO_BIN_EXE_coolctl-under-test");

/// How to install the client's packages.
const SETUP: &str = "npm install --prefix target/foxglove-client @foxglove/ws-protocol@0.8.0 \
ws@8.18.3 ajv@8.17.1 (from the repository root), or set COOLBOT_FOXGLOVE_CLIENT to a \
node_modules directory holding them";

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The client's `node_modules`, or None (the test is skipped, said on stderr) when
/// it is not installed outside CI; a panic under CI.
fn client_modules() -> Option<PathBuf> {
    let modules = std::env::var_os("COOLBOT_FOXGLOVE_CLIENT")
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("target/foxglove-client/node_modules"));
    if modules.join("@foxglove/ws-protocol").is_dir() {
        return Some(modules);
    }
    let missing = format!(
        "the Foxglove client is not installed at {}: {SETUP}",
        modules.display()
    );
    if std::env::var_os("CI").is_some() {
        panic!("{missing}");
    }
    eprintln!("skipped: {missing}");
    None
}

/// `Source`'s behaviour: it hands its output `out` to the test when it starts.
struct HandOut(Sender<DataOut<Reading>>);

impl source::Behavior for HandOut {
    fn start(&mut self, cx: &mut source::Cx<'_>) -> SectionResult {
        let _ = self.0.send(cx.outputs.out.clone());
        Ok(())
    }
}

/// `Tuner`'s behaviour: its observables follow its configuration.
struct Tuning;

impl tuner::Behavior for Tuning {
    fn tuning_periodic(&mut self, cx: &mut tuner::Cx<'_>) -> SectionResult {
        cx.vars.gain = cx.config.gain;
        Ok(())
    }
}

/// A node `fox` with `source` (its `out` echoed, `idle` not), `tuner`, and the
/// network tests' robot (compounds), running; a thread sending readings on `out`
/// until dropped.
struct Fox {
    node: Node,
    endpoint: String,
    _system: System,
    _robot: System,
    sending: Arc<AtomicBool>,
}

impl Drop for Fox {
    fn drop(&mut self) {
        self.sending.store(false, Ordering::Release);
    }
}

fn fox() -> Fox {
    let (node, endpoint) = node("fox", &[]);
    let (hand, out) = crossbeam_channel::bounded(1);
    let mut system = System::new();
    system
        .add(source::component("source", HandOut(hand)))
        .unwrap();
    system.add(tuner::component("tuner", Tuning)).unwrap();
    system.run_all().unwrap();
    node.expose_system(&system).unwrap();
    node.echo::<Reading>(&system, "source.out").unwrap();
    let robot = support::robot(&node);
    let out = out.recv_timeout(PATIENCE).expect("the source started");
    let sending = Arc::new(AtomicBool::new(true));
    let running = Arc::clone(&sending);
    std::thread::spawn(move || {
        let mut n = 0;
        while running.load(Ordering::Acquire) {
            out.send(Reading {
                n,
                label: format!("reading {n}"),
            });
            n += 1;
            std::thread::sleep(Duration::from_millis(10));
        }
    });
    Fox {
        node,
        endpoint,
        _system: system,
        _robot: robot,
        sending,
    }
}

/// A child process whose stdout lines are read on a thread.
struct Process {
    child: Child,
    stdin: Option<ChildStdin>,
    lines: Receiver<String>,
}

impl Process {
    fn start(command: &mut Command) -> Process {
        let mut child = command
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .expect("the process starts");
        let stdout = child.stdout.take().expect("piped stdout");
        let (sender, lines) = crossbeam_channel::unbounded();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                let _ = sender.send(line);
            }
        });
        let stdin = child.stdin.take();
        Process {
            child,
            stdin,
            lines,
        }
    }

    fn line(&self) -> String {
        self.lines
            .recv_timeout(PATIENCE)
            .expect("a line from the process")
    }
}

impl Drop for Process {
    fn drop(&mut self) {
        drop(self.stdin.take());
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `coolctl foxglove` serving `fox` on a free port, with the echoed outputs `ports`
/// select; its URL.
fn serve(fox: &Fox, ports: &[&str]) -> (Process, String) {
    let mut command = Command::new(COOLCTL);
    command.args([
        "--connect",
        &fox.endpoint,
        "--no-multicast",
        "--timeout",
        "2s",
        "foxglove",
        "--bind",
        "127.0.0.1:0",
        "--refresh",
        "100ms",
    ]);
    for port in ports {
        command.args(["--port", port]);
    }
    let server = Process::start(&mut command);
    let line = server.line();
    let url = line
        .strip_prefix("serving ")
        .unwrap_or_else(|| panic!("coolctl foxglove said `{line}`"))
        .to_owned();
    (server, url)
}

/// The Node client on `url`, its lines as JSON.
struct Client {
    process: Process,
}

impl Client {
    fn start(modules: &Path, url: &str) -> Client {
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/foxglove/client.cjs");
        let process = Process::start(
            Command::new("node")
                .arg(script)
                .arg(url)
                .env("NODE_PATH", modules),
        );
        Client { process }
    }

    /// The next line of `kind` for which `accept` holds, skipping others.
    fn next_where(&self, kind: &str, mut accept: impl FnMut(&Value) -> bool) -> Value {
        let deadline = Instant::now() + PATIENCE;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let line = self
                .process
                .lines
                .recv_timeout(left)
                .unwrap_or_else(|_| panic!("no `{kind}` line from the client"));
            let value: Value = serde_json::from_str(&line)
                .unwrap_or_else(|error| panic!("the client printed `{line}`: {error}"));
            if value["kind"] == "error" {
                panic!("the client: {value}");
            }
            if value["kind"] == kind && accept(&value) {
                return value;
            }
        }
    }

    fn order(&mut self, order: Value) {
        let stdin = self.process.stdin.as_mut().expect("stdin open");
        writeln!(stdin, "{order}").expect("the client reads its orders");
    }

    /// The advertisements until every topic of `expected` was advertised, by topic.
    fn advertised(&self, expected: &[&str]) -> std::collections::BTreeMap<String, Value> {
        let mut seen = std::collections::BTreeMap::new();
        while !expected.iter().all(|topic| seen.contains_key(*topic)) {
            let channel = self.next_where("advertise", |_| true);
            seen.insert(channel["topic"].as_str().unwrap().to_owned(), channel);
        }
        seen
    }

    /// The next `count` messages of `topic`, each checked valid against its schema.
    fn messages(&self, topic: &str, count: usize) -> Vec<Value> {
        (0..count)
            .map(|_| {
                let message = self.next_where("message", |m| m["topic"] == topic);
                assert_eq!(
                    message["valid"], true,
                    "a message of {topic} does not validate: {message}"
                );
                message["data"].clone()
            })
            .collect()
    }
}

/// Whether some subscriber (of another session) is on `key`, as a publisher of the
/// node's session sees it.
fn has_subscriber(node: &Node, key: &str) -> bool {
    let probe = node
        .session()
        .declare_publisher(key.to_owned())
        .wait()
        .expect("a probe publisher");
    // The probe's matching status settles once the session has told it what it knows.
    std::thread::sleep(Duration::from_millis(200));
    probe
        .matching_status()
        .wait()
        .is_ok_and(|status| status.matching())
}

#[test]
fn a_foxglove_client_sees_channels_subscribes_and_decodes_them() {
    let Some(modules) = client_modules() else {
        return;
    };
    let fox = fox();
    let (_server, url) = serve(&fox, &["fox/source.*"]);
    let client = Client::start(&modules, &url);
    let info = client.next_where("serverInfo", |_| true);
    assert_eq!(info["name"], "coolctl foxglove", "{info}");

    let channels = client.advertised(&[
        "/fox/source.out",
        "/fox/source/monitor",
        "/fox/tuner/monitor",
        "/fox/robot.base.motion/monitor",
        "/coolbot/log",
    ]);
    let out = &channels["/fox/source.out"];
    assert_eq!(out["encoding"], "json", "{out}");
    assert_eq!(out["schemaEncoding"], "jsonschema", "{out}");
    assert_eq!(out["schemaName"], "Reading", "{out}");
    assert_eq!(out["schemaError"], Value::Null, "{out}");
    assert_eq!(channels["/coolbot/log"]["schemaName"], "foxglove.Log");
    assert_eq!(
        channels["/fox/tuner/monitor"]["schemaName"],
        "coolbot.Monitoring"
    );
    // `idle` is not echoed: no channel.
    assert!(!channels.contains_key("/fox/source.idle"), "{channels:?}");

    let mut client = client;
    client.order(json!({ "do": "subscribe", "topic": "/fox/source.out", "count": 3 }));
    let readings = client.messages("/fox/source.out", 3);
    for reading in &readings {
        let n = reading["n"].as_u64().expect("n is a number");
        assert_eq!(reading["label"], format!("reading {n}"), "{reading}");
    }

    client.order(json!({ "do": "subscribe", "topic": "/fox/tuner/monitor", "count": 2 }));
    let monitoring = client.messages("/fox/tuner/monitor", 2);
    assert_eq!(monitoring[1]["state"], "running", "{}", monitoring[1]);
    assert_eq!(monitoring[1]["state_code"], 2);
    assert_eq!(monitoring[1]["period"], 0.005);
    assert_eq!(monitoring[1]["nominal_period"], 0.005);
    assert!(
        monitoring[1]["cpu_share"].is_number(),
        "the second reading has a CPU share: {}",
        monitoring[1]
    );
}

#[test]
fn a_channel_nobody_watches_has_no_zenoh_subscriber() {
    let Some(modules) = client_modules() else {
        return;
    };
    let fox = fox();
    let (_server, url) = serve(&fox, &["fox/*"]);
    let mut client = Client::start(&modules, &url);
    client.advertised(&["/fox/source.out"]);
    let key = coolbot_zenoh::keys::echo("fox", "source", "out");
    assert!(
        !has_subscriber(&fox.node, &key),
        "advertised but not subscribed: no subscriber on {key}"
    );
    client.order(json!({ "do": "subscribe", "topic": "/fox/source.out", "count": 1 }));
    client.messages("/fox/source.out", 1);
    assert!(has_subscriber(&fox.node, &key), "subscribed: {key} is");
    client.order(json!({ "do": "unsubscribe", "topic": "/fox/source.out" }));
    assert!(
        wait_until(PATIENCE, || !has_subscriber(&fox.node, &key)),
        "unsubscribed: {key} is not any more"
    );
}

#[test]
fn supervision_and_adaptation_steps_reach_the_log() {
    let Some(modules) = client_modules() else {
        return;
    };
    let fox = fox();
    let (_server, url) = serve(&fox, &[]);
    let mut client = Client::start(&modules, &url);
    client.advertised(&["/coolbot/log", "/fox/robot/monitor"]);
    client.order(json!({ "do": "subscribe", "topic": "/coolbot/log" }));
    client.next_where("subscribed", |_| true);
    let key = coolbot_zenoh::keys::monitor("fox", "robot.base");
    assert!(wait_until(PATIENCE, || has_subscriber(&fox.node, &key)));
    // Events as a node publishes them on a compound's monitoring key: a step of each
    // kind, an event that is neither (not logged), and bytes that do not decode
    // (dropped, counted by the server).
    let publish = |event: &[u8]| {
        fox.node
            .session()
            .put(key.clone(), event.to_vec())
            .wait()
            .expect("published");
    };
    let json = |event: &coolbot::MonitorEvent| serde_json::to_vec(event).unwrap();
    publish(b"not an event");
    publish(&json(&coolbot::MonitorEvent::Quality(1)));
    publish(&json(&coolbot::MonitorEvent::Supervision(
        coolbot::Supervision {
            instance: "motion".to_owned(),
            step: coolbot::Step::Failed,
            detail: "wheel jammed".to_owned(),
        },
    )));
    publish(&json(&coolbot::MonitorEvent::Adaptation(
        coolbot::Adaptation {
            component: "motion".to_owned(),
            action: coolbot::adapt::AdaptAction::Degraded,
            from: 0,
            to: 1,
            period: Some(Duration::from_millis(20)),
            quality: None,
            detail: "deadlines missed".to_owned(),
        },
    )));
    let logs = client.messages("/coolbot/log", 2);
    assert_eq!(logs[0]["name"], "fox/robot.base", "{}", logs[0]);
    assert_eq!(logs[0]["level"], 3, "a failure is a warning: {}", logs[0]);
    let failed = logs[0]["message"].as_str().unwrap();
    assert!(
        failed.starts_with("supervision: motion failed") && failed.contains("wheel jammed"),
        "{failed}"
    );
    assert_eq!(
        logs[1]["level"], 2,
        "an adaptation step is information: {}",
        logs[1]
    );
    let degraded = logs[1]["message"].as_str().unwrap();
    assert!(
        degraded.starts_with("adaptation: motion Degraded 0 -> 1"),
        "{degraded}"
    );
}
