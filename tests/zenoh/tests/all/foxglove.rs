//! `coolctl foxglove` against a client that is not ours: `@foxglove/ws-protocol`'s
//! `FoxgloveClient` (npm) in Node, every message checked against its channel's JSON
//! Schema by Ajv (`tests/foxglove/client.cjs`). The real `coolctl` binary serves a
//! real node: the client receives the advertisements, subscribes, decodes the echoed
//! packets, the monitoring and the supervision log; a channel nobody watches has no
//! Zenoh subscriber behind it; a node killed (`robot-under-test`, its own process)
//! has its channels unadvertised until it comes back.
//!
//! The client's packages are in `$COOLBOT_FOXGLOVE_CLIENT` (a `node_modules`
//! directory), else `target/foxglove-client/node_modules`; `.ci/run` installs them.
//! Without them these tests fail under CI (`CI` set) and say they are skipped
//! elsewhere, with the command that installs them.

use std::collections::{BTreeMap, BTreeSet};
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
use coolbot_zenoh_tests::generated::rover;
use coolbot_zenoh_tests::generated::types::{Reading, RoverPose, RoverScan};
use coolbot_zenoh_tests::support::{self, Authority, PATIENCE, Sourced, node, wait_until};
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

/// A node `fox` with `source` (its `out` echoed, `idle` not), `tuner`, and the
/// network tests' robot (compounds), running; a thread sending readings on `out`
/// until dropped.
struct Fox {
    node: Node,
    endpoint: String,
    system: System,
    _robot: System,
    sending: Arc<AtomicBool>,
}

impl Drop for Fox {
    fn drop(&mut self) {
        self.sending.store(false, Ordering::Release);
    }
}

fn fox() -> Fox {
    let Sourced {
        node,
        endpoint,
        system,
        out,
    } = support::sourced("fox");
    let robot = support::robot(&node);
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
        system,
        _robot: robot,
        sending,
    }
}

/// A child process whose stdout and stderr lines are read on threads (its stderr
/// lines are printed here too).
struct Process {
    child: Child,
    stdin: Option<ChildStdin>,
    lines: Receiver<String>,
    errors: Receiver<String>,
}

impl Process {
    fn start(command: &mut Command) -> Process {
        let mut child = command
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("the process starts");
        let stdout = child.stdout.take().expect("piped stdout");
        let stderr = child.stderr.take().expect("piped stderr");
        let (sender, lines) = crossbeam_channel::unbounded();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                let _ = sender.send(line);
            }
        });
        let (sender, errors) = crossbeam_channel::unbounded();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                eprintln!("{line}");
                let _ = sender.send(line);
            }
        });
        let stdin = child.stdin.take();
        Process {
            child,
            stdin,
            lines,
            errors,
        }
    }

    /// Waits for a stderr line that contains `text`.
    fn error_line(&self, text: &str) -> String {
        let deadline = Instant::now() + PATIENCE;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.errors.recv_timeout(left) {
                Ok(line) if line.contains(text) => return line,
                Ok(_) => {}
                Err(error) => panic!("no line with `{text}` on stderr ({error})"),
            }
        }
    }

    fn line(&self) -> String {
        self.lines
            .recv_timeout(PATIENCE)
            .expect("a line from the process")
    }

    /// Kill the process (`kill -9`, before its input closes) and reap it.
    fn kill(mut self) {
        self.child.kill().expect("the process is killed");
        self.child.wait().expect("the process is reaped");
    }
}

impl Drop for Process {
    fn drop(&mut self) {
        drop(self.stdin.take());
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `coolctl GLOBAL foxglove --bind 127.0.0.1:0 ARGS`, multicast scouting off: the
/// server, and the URL it serves on.
fn coolctl_foxglove(global: &[&str], args: &[&str]) -> (Process, String) {
    let server = Process::start(
        Command::new(COOLCTL)
            .args(global)
            .args(["--no-multicast", "foxglove", "--bind", "127.0.0.1:0"])
            .args(args),
    );
    let line = server.line();
    let url = line
        .strip_prefix("serving ")
        .unwrap_or_else(|| panic!("coolctl foxglove said `{line}`"))
        .to_owned();
    (server, url)
}

/// `coolctl foxglove` serving `fox` on a free port, with the echoed outputs `ports`
/// select; its URL.
fn serve(fox: &Fox, ports: &[&str]) -> (Process, String) {
    let mut args = vec!["--refresh", "100ms"];
    for port in ports {
        args.extend(["--port", port]);
    }
    coolctl_foxglove(&["--connect", &fox.endpoint, "--timeout", "2s"], &args)
}

/// The Node client on `url`, its lines as JSON.
struct Client {
    process: Process,
    /// Lines read while looking for others.
    aside: std::cell::RefCell<std::collections::VecDeque<Value>>,
    /// The number of the last request sent.
    requests: u32,
}

impl Client {
    fn start(modules: &Path, url: &str) -> Client {
        Client::start_with(modules, url, &[])
    }

    /// [`Client::start`] with `env` in the client's environment.
    fn start_with(modules: &Path, url: &str, env: &[(&str, &Path)]) -> Client {
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/foxglove/client.cjs");
        let process = Process::start(
            Command::new("node")
                .arg(script)
                .arg(url)
                .env("NODE_PATH", modules)
                .envs(env.iter().copied()),
        );
        Client {
            process,
            aside: Default::default(),
            requests: 0,
        }
    }

    /// The first line of `kind` for which `accept` holds, among those set aside and
    /// then as they come; the others are set aside for later calls.
    fn next_where(&self, kind: &str, mut accept: impl FnMut(&Value) -> bool) -> Value {
        let matches = |value: &Value, accept: &mut dyn FnMut(&Value) -> bool| {
            value["kind"] == kind && accept(value)
        };
        {
            let mut aside = self.aside.borrow_mut();
            if let Some(at) = aside.iter().position(|v| matches(v, &mut accept)) {
                return aside.remove(at).expect("a line set aside");
            }
        }
        let deadline = Instant::now() + PATIENCE;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let line = self.process.lines.recv_timeout(left).unwrap_or_else(|_| {
                panic!(
                    "no `{kind}` line from the client; set aside: {:?}",
                    self.aside.borrow()
                )
            });
            let value: Value = serde_json::from_str(&line)
                .unwrap_or_else(|error| panic!("the client printed `{line}`: {error}"));
            if value["kind"] == "error" {
                panic!("the client: {value}");
            }
            if matches(&value, &mut accept) {
                return value;
            }
            self.aside.borrow_mut().push_back(value);
        }
    }

    /// The first line of `kind` for which `accept` holds among those set aside, taken.
    fn aside_where(&self, kind: &str, accept: impl Fn(&Value) -> bool) -> Option<Value> {
        let mut aside = self.aside.borrow_mut();
        let at = aside
            .iter()
            .position(|value| value["kind"] == kind && accept(value))?;
        aside.remove(at)
    }

    /// Set parameter `name` to `value` (typed `float64` when `float`): the value
    /// the server answers the parameter has then, and the error status it sent
    /// before its answer (a refusal), if any.
    fn set_parameter(&mut self, name: &str, value: Value, float: bool) -> Set {
        self.requests += 1;
        let id = format!("set-{}", self.requests);
        let mut parameter = json!({ "name": name, "value": value });
        if float {
            parameter["type"] = json!("float64");
        }
        self.order(json!({ "do": "setParameters", "id": id, "parameters": [parameter] }));
        let answer = parameter_values(self, &id);
        // The server sends a refusal before its answer, on the same ordered stream.
        let refused = self.aside_where("status", |_| true).map(|status| {
            assert_eq!(status["level"], 2, "a refusal is an error: {status}");
            status["message"].as_str().expect("a message").to_owned()
        });
        Set {
            value: answer.get(name).cloned().unwrap_or(Value::Null),
            refused,
        }
    }

    fn order(&mut self, order: Value) {
        let stdin = self.process.stdin.as_mut().expect("stdin open");
        writeln!(stdin, "{order}").expect("the client reads its orders");
    }

    /// The advertisements until every topic of `expected` was advertised, by topic.
    fn advertised(&self, expected: &[&str]) -> BTreeMap<String, Value> {
        let mut seen = BTreeMap::new();
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

/// What setting a parameter got ([`Client::set_parameter`]).
#[derive(Debug)]
struct Set {
    /// The parameter's value in the server's answer.
    value: Value,
    /// The error status the server sent, when it refused.
    refused: Option<String>,
}

impl Set {
    /// The value, the set taken (no refusal).
    fn taken(self) -> Value {
        assert_eq!(self.refused, None, "the set was refused");
        self.value
    }

    /// The refusal's message (the set was refused), and the value then.
    fn refusal(self) -> (String, Value) {
        let message = self
            .refused
            .unwrap_or_else(|| panic!("the set was taken, not refused: {:?}", self.value));
        (message, self.value)
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
    // The viewers read every schema (one property they cannot read loses the channel).
    for channel in channels.values() {
        assert_eq!(channel["viewerError"], Value::Null, "{channel}");
        assert_eq!(channel["schemaError"], Value::Null, "{channel}");
    }

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
    // The output's key, which has the node tap it, and the node's batches.
    let keys = [
        coolbot_zenoh::keys::echo("fox", "source", "out"),
        coolbot_zenoh::keys::echoes("fox"),
    ];
    for key in &keys {
        assert!(
            !has_subscriber(&fox.node, key),
            "advertised but not subscribed: no subscriber on {key}"
        );
    }
    client.order(json!({ "do": "subscribe", "topic": "/fox/source.out", "count": 1 }));
    client.messages("/fox/source.out", 1);
    for key in &keys {
        assert!(has_subscriber(&fox.node, key), "subscribed: {key} is");
    }
    client.order(json!({ "do": "unsubscribe", "topic": "/fox/source.out" }));
    for key in &keys {
        assert!(
            wait_until(PATIENCE, || !has_subscriber(&fox.node, key)),
            "unsubscribed: {key} is not any more"
        );
    }
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

/// The next `parameterValues` answer to request `id`, as `name -> value`.
fn parameter_values(client: &Client, id: &str) -> BTreeMap<String, Value> {
    let values = client.next_where("parameterValues", |v| v["id"] == id);
    values["parameters"]
        .as_array()
        .expect("parameters")
        .iter()
        .map(|p| {
            (
                p["name"].as_str().expect("a name").to_owned(),
                p["value"].clone(),
            )
        })
        .collect()
}

#[test]
fn parameters_show_and_set_controllable_variables_with_the_components_checks() {
    let Some(modules) = client_modules() else {
        return;
    };
    let fox = fox();
    let tuner = fox.system.handle("tuner").expect("the tuner");
    let (_server, url) = serve(&fox, &[]);
    let mut client = Client::start(&modules, &url);
    let info = client.next_where("serverInfo", |_| true);
    let capabilities = info["capabilities"].to_string();
    assert!(
        capabilities.contains("\"parameters\"") && capabilities.contains("\"services\""),
        "{info}"
    );
    client.advertised(&["/fox/tuner/monitor", "/fox/robot.base.motion/monitor"]);

    client.order(json!({ "do": "getParameters", "names": [], "id": "all" }));
    let all = parameter_values(&client, "all");
    assert_eq!(all["fox/tuner/limit"], 3, "{all:?}");
    assert_eq!(all["fox/tuner/period"], 0.005, "{all:?}");
    assert_eq!(all["fox/tuner/quality"], 0, "{all:?}");
    assert_eq!(all["fox/robot.base.motion/max_speed"], 0.0, "{all:?}");
    // Observables are not parameters.
    assert!(!all.contains_key("fox/tuner/gain"), "{all:?}");

    // Set: the component's variable changes.
    let set = client.set_parameter("fox/tuner/limit", json!(7), false);
    assert_eq!(set.taken(), 7);
    let limit = || {
        tuner
            .snapshot()
            .variables
            .iter()
            .find(|(name, _)| name == "limit")
            .map(|(_, value)| value.to_json())
    };
    assert_eq!(limit(), Some(json!(7)));

    // The component's own checks refuse a value its type cannot hold; the client is
    // told, and the value stays.
    let (message, value) = client
        .set_parameter("fox/tuner/limit", json!(-1), false)
        .refusal();
    assert!(
        message.contains("fox/tuner/limit") && message.contains("rejected"),
        "{message}"
    );
    assert_eq!(value, 7);
    assert_eq!(limit(), Some(json!(7)));

    // The control port's ranges refuse a zero period, as for `coolctl set`.
    let (message, value) = client
        .set_parameter("fox/tuner/period", json!(0.0), true)
        .refusal();
    assert!(
        message.contains("fox/tuner/period") && message.contains("rejected"),
        "{message}"
    );
    assert_eq!(value, 0.005);
    assert_eq!(tuner.snapshot().period, Some(Duration::from_millis(5)));

    // A float period in range is taken.
    let set = client.set_parameter("fox/tuner/period", json!(0.01), true);
    assert_eq!(set.taken(), 0.01);
    assert_eq!(tuner.snapshot().period, Some(Duration::from_millis(10)));

    // A name that is no parameter.
    let (message, value) = client
        .set_parameter("fox/tuner/gain", json!(2.0), false)
        .refusal();
    assert!(
        message.contains("`fox/tuner/gain` is not a parameter"),
        "{message}"
    );
    assert_eq!(value, Value::Null, "no value for what is no parameter");
}

#[test]
fn services_suspend_run_and_restart_a_component() {
    let Some(modules) = client_modules() else {
        return;
    };
    let fox = fox();
    let tuner = fox.system.handle("tuner").expect("the tuner");
    let (_server, url) = serve(&fox, &[]);
    let mut client = Client::start(&modules, &url);
    let services = client.next_where("services", |_| true);
    for name in ["suspend", "run", "restart"] {
        assert!(
            services["services"]
                .as_array()
                .unwrap()
                .iter()
                .any(|s| s["name"] == name),
            "{services}"
        );
    }
    let call = |client: &mut Client, service: &str, component: &str, id: u32| {
        client.order(json!({ "do": "call", "service": service, "callId": id,
            "request": { "component": component } }));
    };
    call(&mut client, "suspend", "fox/tuner", 1);
    let answer = client.next_where("serviceCallResponse", |a| a["callId"] == 1);
    assert_eq!(answer["data"], "{\"accepted\":true}", "{answer}");
    assert_eq!(tuner.snapshot().state, coolbot::State::Suspended);

    call(&mut client, "run", "fox/tuner", 2);
    client.next_where("serviceCallResponse", |a| a["callId"] == 2);
    assert_eq!(tuner.snapshot().state, coolbot::State::Running);

    // Restart: ready, then running (the component's `start` hook is not run again,
    // its user automaton restarts from its initial state).
    let events = tuner.subscribe();
    call(&mut client, "restart", "fox/tuner", 3);
    client.next_where("serviceCallResponse", |a| a["callId"] == 3);
    let states: Vec<coolbot::State> = events
        .try_iter()
        .filter_map(|event| match event {
            coolbot::MonitorEvent::State { to, .. } => Some(to),
            _ => None,
        })
        .collect();
    assert_eq!(
        states,
        [coolbot::State::Ready, coolbot::State::Running],
        "restarted"
    );

    // A component that does not exist: a failure that says so.
    call(&mut client, "suspend", "fox/nobody", 4);
    let failure = client.next_where("serviceCallFailure", |f| f["callId"] == 4);
    assert!(
        failure["message"].as_str().unwrap().contains("nobody"),
        "{failure}"
    );
}

/// The operator `ops` may command the robot's base and what is inside it, nothing
/// else.
const RULES: &str = "[[allow]]\nnodes = [\"ops\"]\ncommand = [\"robot/robot.base.*\"]\n";

#[test]
fn the_nodes_access_rules_hold_for_parameters_and_services() {
    let Some(modules) = client_modules() else {
        return;
    };
    let dir = tempfile::tempdir().expect("a temporary directory");
    let dir = dir.path();
    let authority = Authority::new(dir, "fleet");
    let robot_file = authority.node(dir, "robot", "robot", RULES);
    let ops_file = authority.node(dir, "ops", "ops", RULES);
    let endpoint = format!("quic/127.0.0.1:{}", support::free_port());
    let security = coolbot_zenoh::Security::load(&robot_file).expect("the security file");
    let config =
        coolbot_zenoh::secure_config(std::slice::from_ref(&endpoint), &[], false, &security)
            .expect("a TLS configuration");
    let node = Node::open("robot", config)
        .expect("the robot's node opens")
        .with_state_directory(None);
    let system = support::robot(&node);

    let ops_file = ops_file.to_str().expect("a UTF-8 path");
    let (_server, url) = coolctl_foxglove(
        &[
            "--config",
            ops_file,
            "--connect",
            &endpoint,
            "--timeout",
            "2s",
        ],
        &["--refresh", "100ms"],
    );
    let mut client = Client::start(&modules, &url);
    client.advertised(&["/robot/logger/monitor", "/robot/robot.base.motion/monitor"]);

    // Allowed: the base's motion.
    let set = client.set_parameter("robot/robot.base.motion/max_speed", json!(0.5), true);
    assert_eq!(set.taken(), 0.5);
    let motion = system.handle_at("robot.base.motion").expect("motion");
    assert!(
        motion
            .snapshot()
            .variables
            .iter()
            .any(|(name, value)| name == "max_speed" && value.to_json() == json!(0.5))
    );

    // Outside the rules: the logger, neither by a parameter nor by a service.
    let (message, _) = client
        .set_parameter("robot/logger/priority", json!(3), false)
        .refusal();
    assert!(
        message.contains("do not let `ops` command `robot/logger`"),
        "{message}"
    );
    let logger = system.handle("logger").expect("the logger");
    assert_ne!(logger.snapshot().priority, 3);
    client.order(json!({ "do": "call", "service": "suspend", "callId": 1,
        "request": { "component": "robot/logger" } }));
    let failure = client.next_where("serviceCallFailure", |f| f["callId"] == 1);
    assert!(
        failure["message"]
            .as_str()
            .unwrap()
            .contains("do not let `ops` command `robot/logger`"),
        "{failure}"
    );
    assert_eq!(logger.snapshot().state, coolbot::State::Running);
}

/// `Rover`'s behaviour: it hands its outputs to the test when it starts.
struct HandRover(Sender<(DataOut<RoverPose>, DataOut<RoverScan>)>);

impl rover::Behavior for HandRover {
    fn start(&mut self, cx: &mut rover::Cx<'_>) -> SectionResult {
        let _ = self
            .0
            .send((cx.outputs.pose.clone(), cx.outputs.scan.clone()));
        Ok(())
    }
}

/// The mapping of the rover's outputs, in a file of `dir`.
const MAP: &str = r#"
[[pose]]
port = "rover/rover.pose"
x = "x"
y = "y"
yaw = "theta"
frame = "odom"
child = "base_link"

[[laser_scan]]
port = "rover/rover.scan"
ranges = "us"
start_angle = 0.0
step = 1.5707963267948966
range_offset = 0.5
frame = "base_link"
"#;

#[test]
fn mapped_outputs_are_foxglove_poses_transforms_paths_and_laser_scans() {
    let Some(modules) = client_modules() else {
        return;
    };
    let rover = Rover::start();
    let (_server, url, _dir) = rover.serve(MAP);
    let mut client = Client::start(&modules, &url);
    let channels = client.advertised(&[
        "/rover/rover.pose/pose",
        "/rover/rover.pose/tf",
        "/rover/rover.pose/path",
        "/rover/rover.scan/laser_scan",
    ]);
    for channel in channels.values() {
        assert_eq!(channel["viewerError"], Value::Null, "{channel}");
    }
    assert_eq!(
        channels["/rover/rover.pose/pose"]["schemaName"],
        "foxglove.PoseInFrame"
    );
    assert_eq!(
        channels["/rover/rover.pose/tf"]["schemaName"],
        "foxglove.FrameTransform"
    );
    assert_eq!(
        channels["/rover/rover.scan/laser_scan"]["schemaName"],
        "foxglove.LaserScan"
    );
    assert_eq!(
        channels["/rover/rover.pose/path"]["schemaName"],
        "foxglove.PosesInFrame"
    );
    // No --port: the packets themselves are not served.
    assert!(!channels.contains_key("/rover/rover.pose"), "{channels:?}");

    for topic in [
        "/rover/rover.pose/pose",
        "/rover/rover.pose/tf",
        "/rover/rover.pose/path",
        "/rover/rover.scan/laser_scan",
    ] {
        client.order(json!({ "do": "subscribe", "topic": topic, "count": 1 }));
    }
    let pose = client.messages("/rover/rover.pose/pose", 1).remove(0);
    assert_eq!(pose["frame_id"], "odom");
    // (JavaScript prints whole numbers without a point.)
    assert_eq!(pose["pose"]["position"], json!({ "x": 1, "y": 2, "z": 0 }));
    let z = pose["pose"]["orientation"]["z"].as_f64().unwrap();
    assert!((z - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-9, "{pose}");
    let tf = client.messages("/rover/rover.pose/tf", 1).remove(0);
    assert_eq!(tf["parent_frame_id"], "odom");
    assert_eq!(tf["child_frame_id"], "base_link");
    // The rover stands still: its path is the one pose it kept.
    let path = client.messages("/rover/rover.pose/path", 1).remove(0);
    assert_eq!(path["frame_id"], "odom");
    assert_eq!(
        path["poses"],
        json!([{ "position": { "x": 1, "y": 2, "z": 0 }, "orientation": pose["pose"]["orientation"] }]),
        "{path}"
    );
    let laser = client.messages("/rover/rover.scan/laser_scan", 1).remove(0);
    assert_eq!(laser["ranges"], json!([1.5, 2.5, 3.5, 4.5]));
    assert_eq!(laser["end_angle"], 3.0 * std::f64::consts::FRAC_PI_2);

    // A controllable variable's declared range holds for its parameter.
    let gain = || {
        rover
            .system
            .handle("rover")
            .expect("the rover")
            .snapshot()
            .variables
            .iter()
            .find(|(name, _)| name == "gain")
            .map(|(_, value)| value.to_json())
    };
    let (message, value) = client
        .set_parameter("rover/rover/gain", json!(2.0), true)
        .refusal();
    assert!(
        message.contains("`rover/rover/gain`: rejected"),
        "{message}"
    );
    assert_eq!(value, 0.5);
    assert_eq!(gain(), Some(json!(0.5)));
    let set = client.set_parameter("rover/rover/gain", json!(0.25), true);
    assert_eq!(set.taken(), 0.25);
    assert_eq!(gain(), Some(json!(0.25)));
}

/// A node `rover` whose rover sends its pose and scan every 10 ms, echoed, until
/// dropped.
struct Rover {
    /// Kept open while the rover runs.
    _node: Node,
    endpoint: String,
    system: System,
    sending: Arc<AtomicBool>,
    sender: Option<std::thread::JoinHandle<()>>,
}

impl Rover {
    fn start() -> Rover {
        let (node, endpoint) = node("rover", &[]);
        let (hand, outputs) = crossbeam_channel::bounded(1);
        let mut system = System::new();
        system
            .add(rover::component("rover", HandRover(hand)))
            .unwrap();
        system.run_all().unwrap();
        node.expose_system(&system).unwrap();
        node.echo::<RoverPose>(&system, "rover.pose").unwrap();
        node.echo::<RoverScan>(&system, "rover.scan").unwrap();
        let (pose, scan) = outputs.recv_timeout(PATIENCE).expect("the rover started");
        let sending = Arc::new(AtomicBool::new(true));
        let running = Arc::clone(&sending);
        let sender = std::thread::spawn(move || {
            while running.load(Ordering::Acquire) {
                pose.send(RoverPose {
                    x: 1.0,
                    y: 2.0,
                    theta: std::f64::consts::FRAC_PI_2,
                });
                scan.send(RoverScan {
                    us: [1.0, 2.0, 3.0, 4.0],
                });
                std::thread::sleep(Duration::from_millis(10));
            }
        });
        Rover {
            _node: node,
            endpoint,
            system,
            sending,
            sender: Some(sender),
        }
    }

    /// `coolctl foxglove` on this node with the mapping `map`: the server, its URL
    /// and the directory of the mapping's file.
    fn serve(&self, map: &str) -> (Process, String, tempfile::TempDir) {
        let dir = tempfile::tempdir().expect("a temporary directory");
        let file = dir.path().join("map.toml");
        std::fs::write(&file, map).expect("write the mapping");
        let (server, url) = coolctl_foxglove(
            &["--connect", &self.endpoint],
            &["--map", file.to_str().expect("a UTF-8 path")],
        );
        (server, url, dir)
    }
}

impl Drop for Rover {
    fn drop(&mut self) {
        self.sending.store(false, Ordering::Release);
        if let Some(sender) = self.sender.take() {
            let _ = sender.join();
        }
    }
}

/// A mapping that names a field the packets do not have: each packet it does not
/// fit is dropped and `coolctl` says so on stderr.
#[test]
fn a_packet_a_mapping_does_not_fit_is_warned_about() {
    let Some(modules) = client_modules() else {
        return;
    };
    let rover = Rover::start();
    let (server, url, _dir) = rover.serve(&MAP.replace("ranges = \"us\"", "ranges = \"uz\""));
    let mut client = Client::start(&modules, &url);
    client.advertised(&["/rover/rover.scan/laser_scan"]);
    client.order(json!({ "do": "subscribe", "topic": "/rover/rover.scan/laser_scan", "count": 1 }));
    let line = server.error_line("an echoed packet for /rover/rover.scan/laser_scan does not fit");
    assert!(line.contains("WARN") && line.contains("uz"), "{line}");
}

/// Node `name` in a process of its own (`robot-under-test`), running the network
/// tests' robot, connected to `endpoint`.
fn robot_process(name: &str, endpoint: &str) -> Process {
    let process =
        Process::start(Command::new(env!("CARGO_BIN_EXE_robot-under-test")).args([name, endpoint]));
    assert_eq!(process.line(), "ready");
    process
}

/// Channels of node `far`, its own process, that the test follows.
const FAR: [&str; 2] = ["/far/logger/monitor", "/far/robot.base.motion/monitor"];

#[test]
fn a_node_killed_has_its_channels_unadvertised_until_it_comes_back() {
    let Some(modules) = client_modules() else {
        return;
    };
    let fox = fox();
    // `far` connects to coolctl, which listens, so that a new `far` finds it again.
    let listen = format!("tcp/127.0.0.1:{}", support::free_port());
    let (_server, url) = coolctl_foxglove(
        &[
            "--connect",
            &fox.endpoint,
            "--listen",
            &listen,
            "--timeout",
            "2s",
        ],
        &["--refresh", "100ms"],
    );
    let far = robot_process("far", &listen);
    let mut client = Client::start(&modules, &url);
    let channels = client.advertised(&[FAR[0], FAR[1], "/fox/tuner/monitor"]);
    let id = |channel: &Value| channel["id"].as_u64().expect("a channel id");
    let before: BTreeSet<u64> = FAR.iter().map(|topic| id(&channels[*topic])).collect();
    let fox_tuner = id(&channels["/fox/tuner/monitor"]);

    // Killed: its token goes, its channels are unadvertised; fox's stay.
    far.kill();
    let mut gone = BTreeSet::new();
    while !before.is_subset(&gone) {
        let unadvertised = client.next_where("unadvertise", |_| true);
        let ids = unadvertised["ids"].as_array().expect("ids");
        gone.extend(ids.iter().map(|id| id.as_u64().expect("an id")));
    }
    assert!(!gone.contains(&fox_tuner), "fox's channels stay: {gone:?}");

    // Back: advertised again, under new ids, and served.
    let _far = robot_process("far", &listen);
    let mut again = BTreeMap::new();
    while again.len() < FAR.len() {
        let channel = client.next_where("advertise", |channel| {
            FAR.iter().any(|topic| channel["topic"] == *topic) && !before.contains(&id(channel))
        });
        again.insert(
            channel["topic"].as_str().expect("a topic").to_owned(),
            id(&channel),
        );
    }
    client.order(json!({ "do": "subscribe", "topic": FAR[0], "count": 1 }));
    let monitoring = client.messages(FAR[0], 1);
    assert_eq!(monitoring[0]["state"], "running", "{}", monitoring[0]);
}

/// Off loopback, the server needs the security file or `--insecure`, as a node's
/// endpoints do; the refusal comes before anything listens.
/// With a certificate and its key, the server speaks `wss://` only: a client that
/// trusts the certificate's authority is served; one that speaks plain `ws://` to the
/// same port is not.
#[test]
fn with_a_certificate_the_server_speaks_wss_only() {
    let Some(modules) = client_modules() else {
        return;
    };
    let fox = fox();
    let dir = tempfile::tempdir().expect("a temporary directory");
    let dir = dir.path();
    let authority = Authority::new(dir, "viewers");
    // `server.pem` and `server.key`, for localhost and 127.0.0.1.
    authority.node(dir, "server", "server", "");
    let (certificate, key) = (dir.join("server.pem"), dir.join("server.key"));
    let (_server, url) = coolctl_foxglove(
        &["--connect", &fox.endpoint, "--timeout", "2s"],
        &[
            "--refresh",
            "100ms",
            "--port",
            "fox/*",
            "--tls-certificate",
            certificate.to_str().unwrap(),
            "--tls-key",
            key.to_str().unwrap(),
        ],
    );
    let port = url
        .strip_prefix("wss://127.0.0.1:")
        .unwrap_or_else(|| panic!("not a wss URL: {url}"));
    let ca = dir.join("viewers-ca.pem");
    let mut client = Client::start_with(&modules, &url, &[("NODE_EXTRA_CA_CERTS", &ca)]);
    client.advertised(&["/fox/source.out"]);
    client.order(json!({ "do": "subscribe", "topic": "/fox/source.out", "count": 1 }));
    client.messages("/fox/source.out", 1);

    let plain = Client::start(&modules, &format!("ws://127.0.0.1:{port}"));
    let deadline = Instant::now() + PATIENCE;
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        let line = plain
            .process
            .lines
            .recv_timeout(left)
            .expect("the plain client opens or fails");
        let value: Value = serde_json::from_str(&line).expect("a JSON line");
        assert_ne!(value["kind"], "open", "plain ws:// was served");
        if value["kind"] == "error" || value["kind"] == "close" {
            break;
        }
    }
}

#[test]
fn a_tls_certificate_that_cannot_be_read_is_refused() {
    let out = Command::new(COOLCTL)
        .args(["--no-multicast", "foxglove", "--bind", "127.0.0.1:0"])
        .args(["--tls-certificate", "/nonexistent/server.pem"])
        .args(["--tls-key", "/nonexistent/server.key"])
        .output()
        .expect("coolctl runs");
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    let error = String::from_utf8_lossy(&out.stderr);
    assert!(
        error.contains(
            "the WebSocket's TLS certificate or key: /nonexistent/server.pem: cannot read"
        ),
        "{error}"
    );
}

#[test]
fn serving_off_loopback_is_refused_without_the_security_file() {
    let out = Command::new(COOLCTL)
        .args(["--no-multicast", "foxglove", "--bind", "192.0.2.1:8765"])
        .output()
        .expect("coolctl runs");
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    let error = String::from_utf8_lossy(&out.stderr);
    assert!(
        error.contains("coolctl foxglove: `192.0.2.1:8765` is not on loopback")
            && error.contains("give the security file (--config) or --insecure"),
        "{error}"
    );
}
