//! Remote monitoring and control, and `coolctl`'s text output, against a node started
//! here: a system with a compound `robot` (holding a compound `base` with `motion` and
//! `ranges`, and a `planner`) and an atomic `logger`.

use std::time::Duration;

use coolbot::crossbeam_channel::{self, Sender};
use coolbot::port::{DataOut, FifoIn};
use coolbot::{Command, Controllable, SectionResult, State, System};
use coolbot_zenoh::ctl::{Ctl, CtlError};
use coolbot_zenoh::{ControlReply, Node};
use coolbot_zenoh_tests::generated::{doubler, numbers, results};
use coolbot_zenoh_tests::support::{self, PATIENCE, pair, robot, wait_until};
use zenoh::Wait;

const COMPONENTS: usize = 6;

/// A `coolctl` on `station`'s session, once it sees all of the robot's components.
fn ctl(station: &Node) -> Ctl {
    let ctl = Ctl::new(station.session().clone(), Duration::from_secs(5));
    assert!(
        wait_until(PATIENCE, || ctl
            .components(Some("robot"))
            .is_ok_and(|listed| listed.len() == COMPONENTS)),
        "the station does not see the robot's components"
    );
    ctl
}

fn text(f: impl FnOnce(&mut Vec<u8>) -> Result<(), CtlError>) -> String {
    let mut out = Vec::new();
    f(&mut out).unwrap();
    String::from_utf8(out).unwrap()
}

#[test]
fn coolctl_lists_nodes_and_every_component_with_its_state() {
    let (node, station) = pair("robot", "station");
    let system = robot(&node);
    let ctl = ctl(&station);
    insta::assert_snapshot!("nodes", text(|out| ctl.nodes(out)));
    insta::assert_snapshot!("list", text(|out| ctl.list(Some("robot"), out)));
    // A suspended instance deep inside shows as such.
    let motion = system
        .handle("robot")
        .unwrap()
        .instance("base.motion")
        .unwrap();
    motion
        .command(Command::SetState(Controllable::Suspended))
        .unwrap();
    let listed = ctl.components(None).unwrap();
    let row = listed
        .iter()
        .find(|listed| listed.path == "robot.base.motion")
        .expect("motion listed");
    assert_eq!(row.monitor.state, State::Suspended);
    assert_eq!(row.node, "robot");
}

#[test]
fn coolctl_set_answers_as_the_control_port_does() {
    let (node, station) = pair("robot", "station");
    let system = robot(&node);
    let ctl = ctl(&station);
    let mut transcript = String::new();
    for args in [
        &["state", "suspended"][..],
        &["state", "running"],
        &["max_speed=0.5"],
        &["odometry=1"],
        &["no_such_variable=1"],
        &["period=0ms"],
        &["quality=3"],
        &["priority=0"],
    ] {
        let args: Vec<String> = args.iter().map(|a| (*a).to_owned()).collect();
        let answer = text(|out| {
            ctl.set("robot/robot.base.motion", &args, out)
                .map(|_accepted| ())
        });
        transcript.push_str(&format!(
            "$ coolctl set robot/robot.base.motion {}\n{answer}",
            args.join(" ")
        ));
    }
    insta::assert_snapshot!("set", transcript);
    let motion = system
        .handle("robot")
        .unwrap()
        .instance("base.motion")
        .unwrap();
    let monitor = motion.snapshot();
    assert_eq!(monitor.state, State::Running);
    assert_eq!(
        monitor.variables[1],
        ("max_speed".to_owned(), coolbot::Value::Float(0.5))
    );
    // A component nobody exposes does not answer, and the error says the node has
    // no such component, naming those it has.
    let quick = Ctl::new(station.session().clone(), Duration::from_millis(300));
    match quick.command("robot/robot.nothing", &Command::SetPriority(0)) {
        Err(CtlError::UnknownComponent { node, path, known }) => {
            assert_eq!((node.as_str(), path.as_str()), ("robot", "robot.nothing"));
            assert!(known.contains("robot.base.motion"), "{known}");
        }
        other => panic!("expected no such component, got {other:?}"),
    }
}

#[test]
fn an_instance_inside_a_compound_is_not_sent_to_dead_from_the_network() {
    let (node, station) = pair("robot", "station");
    let system = robot(&node);
    let ctl = ctl(&station);
    let dead = Command::SetState(Controllable::Dead);
    // Its compound would not see it as a fault: refused, and it runs on.
    match ctl.command("robot/robot.base.motion", &dead).unwrap() {
        ControlReply::Rejected { reason } => assert_eq!(
            reason,
            "`motion` is an instance of `robot.base`: it goes to dead with its compound, \
             not alone (send dead to `robot.base`)"
        ),
        ControlReply::Accepted => panic!("motion accepted dead"),
    }
    let robot = system.handle("robot").unwrap();
    let motion = robot.instance("base.motion").unwrap();
    assert_eq!(motion.snapshot().state, State::Running);
    // Other commands still reach it; a component of its own goes to dead.
    assert_eq!(
        ctl.command(
            "robot/robot.base.motion",
            &Command::SetState(Controllable::Suspended)
        )
        .unwrap(),
        ControlReply::Accepted
    );
    assert_eq!(
        ctl.command("robot/logger", &dead).unwrap(),
        ControlReply::Accepted
    );
    let logger = system.handle("logger").unwrap();
    logger
        .wait_for(|m| m.state == State::Dead, PATIENCE)
        .expect("the logger goes to dead");
}

#[test]
fn a_malformed_command_is_rejected_with_the_reason() {
    let (node, station) = pair("robot", "station");
    let _system = robot(&node);
    let _ctl = ctl(&station);
    let replies = station
        .session()
        .get("coolbot/robot/logger/c")
        .payload("{\"SetState\": \"Sleeping\"}")
        .timeout(PATIENCE)
        .wait()
        .unwrap();
    let reply = replies.recv().expect("an answer");
    let answer: ControlReply =
        serde_json::from_slice(&reply.result().unwrap().payload().to_bytes()).unwrap();
    match answer {
        ControlReply::Rejected { reason } => {
            assert!(reason.starts_with("malformed command"), "{reason}")
        }
        ControlReply::Accepted => panic!("a malformed command was accepted"),
    }
}

#[test]
fn coolctl_watch_prints_monitoring_events_as_they_happen() {
    let (node, station) = pair("robot", "station");
    let _system = robot(&node);
    let ctl = ctl(&station);
    let target = "robot/robot.base.motion";
    let watcher = ctl.watcher(target).unwrap();
    // The subscription reaches the robot's node after a while: change a variable until
    // the watcher sees an event.
    let mut probe = 0u32;
    assert!(wait_until(PATIENCE, || {
        probe += 1;
        let reply = ctl
            .command(
                target,
                &Command::Set("max_speed".into(), coolbot::Value::Float(f64::from(probe))),
            )
            .unwrap();
        assert_eq!(reply, ControlReply::Accepted);
        watcher.next(Duration::from_millis(200)).unwrap().is_some()
    }));
    for command in [
        Command::Set("max_speed".into(), coolbot::Value::Float(0.25)),
        Command::SetState(Controllable::Suspended),
        Command::SetState(Controllable::Running),
    ] {
        assert_eq!(
            ctl.command(target, &command).unwrap(),
            ControlReply::Accepted
        );
    }
    // Events of one component arrive in order: keep what follows the first 0.25.
    let mut lines = Vec::new();
    while !lines
        .last()
        .is_some_and(|l: &String| l.ends_with("suspended -> running"))
    {
        let line = watcher
            .next(PATIENCE)
            .unwrap()
            .expect("the events of the commands");
        if !lines.is_empty() || line.ends_with("max_speed = 0.25") {
            lines.push(line);
        }
    }
    insta::assert_snapshot!("watch", lines.join("\n"));
}

#[test]
fn coolctl_sees_nodes_come_and_go() {
    let (robot, endpoint) = support::node("robot", &[]);
    let (station, _) = support::node("station", std::slice::from_ref(&endpoint));
    let ctl = Ctl::new(station.session().clone(), Duration::from_secs(5));
    assert!(wait_until(PATIENCE, || ctl
        .node_names()
        .is_ok_and(|names| names == ["robot", "station"])));
    let watcher = ctl.node_watcher().unwrap();
    let next = |expected: &str| loop {
        let line = watcher
            .next(PATIENCE)
            .unwrap()
            .unwrap_or_else(|| panic!("no `{expected}` within {PATIENCE:?}"));
        // Tokens already alive may be announced when the subscription starts.
        if line == expected {
            break;
        }
        assert!(
            line.starts_with('+'),
            "unexpected `{line}` before `{expected}`"
        );
    };
    let (arm, _) = support::node("arm", std::slice::from_ref(&endpoint));
    next("+ arm");
    drop(arm);
    next("- arm");
    assert_eq!(ctl.node_names().unwrap(), ["robot", "station"]);
    drop(robot);
}

/// `Doubler`'s behaviour (`cool/remote.cool`): multiplies each number arriving at
/// `input` by its controllable `factor` (2 unless set) onto `output`.
struct Doubling;

impl doubler::Behavior for Doubling {
    fn doubling_entry(&mut self, cx: &mut doubler::Cx<'_>) -> SectionResult {
        for number in cx.inputs.input.drain() {
            cx.outputs.output.send(number * cx.vars.factor);
        }
        Ok(())
    }
}

/// `Numbers`' behaviour: hands its output to the test when it starts.
struct HandNumbers(Sender<DataOut<u64>>);

impl numbers::Behavior for HandNumbers {
    fn start(&mut self, cx: &mut numbers::Cx<'_>) -> SectionResult {
        let _ = self.0.send(cx.outputs.out.clone());
        Ok(())
    }
}

/// `Results`' behaviour: hands its input to the test when it starts.
struct HandResults(Sender<FifoIn<u64>>);

impl results::Behavior for HandResults {
    fn start(&mut self, cx: &mut results::Cx<'_>) -> SectionResult {
        let _ = self.0.send(cx.inputs.input.clone());
        Ok(())
    }
}

/// A `Numbers` named `source` and a `Results` named `sink` in `system`, and (once
/// the system has started) their ports.
fn ends(
    system: &mut System,
) -> (
    crossbeam_channel::Receiver<DataOut<u64>>,
    crossbeam_channel::Receiver<FifoIn<u64>>,
) {
    let (out, source) = crossbeam_channel::bounded(1);
    let (input, sink) = crossbeam_channel::bounded(1);
    system
        .add(numbers::component("source", HandNumbers(out)))
        .unwrap();
    system
        .add(results::component("sink", HandResults(input)))
        .unwrap();
    (source, sink)
}

#[test]
fn an_agent_builds_a_registered_component_on_request_and_bridges_its_ports() {
    use coolbot::{InputKind, OutputKind, OverflowPolicy};
    use coolbot_zenoh::Error;
    use coolbot_zenoh::agent::{Agent, Instantiate, Registry, RemoteInput, Wire, instantiate};

    let (robot, workstation) = pair("robot", "workstation");
    let workstation = std::sync::Arc::new(workstation);
    let mut registry = Registry::new();
    doubler::register(&mut registry, |name| doubler::component(name, Doubling));
    let _agent = Agent::start(std::sync::Arc::clone(&workstation), registry).unwrap();

    // The robot: numbers out to the remote doubler, doubled numbers back into a fifo.
    let queue = InputKind::Fifo {
        capacity: 64,
        policy: OverflowPolicy::Reject,
    };
    let mut system = System::new();
    let (numbers, doubled) = ends(&mut system);
    system
        .add(
            robot
                .outlet::<u64>("to_doubler", "test/agent/in", queue)
                .build()
                .unwrap(),
        )
        .unwrap();
    system
        .add(
            robot
                .inlet::<u64>("from_doubler", "test/agent/out", OutputKind::Data)
                .build()
                .unwrap(),
        )
        .unwrap();
    system.connect("source.out", "to_doubler.input").unwrap();
    system.connect("from_doubler.output", "sink.input").unwrap();
    system.run_all().unwrap();
    let numbers = numbers.recv_timeout(PATIENCE).expect("the source started");
    let doubled = doubled.recv_timeout(PATIENCE).expect("the sink started");

    let request = Instantiate {
        type_name: "Doubler".to_owned(),
        name: format!("{}doubler", coolbot_zenoh::keys::namespace("robot")),
        wires: vec![
            Wire::Input {
                port: "input".to_owned(),
                key: "test/agent/in".to_owned(),
            },
            Wire::Output {
                port: "output".to_owned(),
                key: "test/agent/out".to_owned(),
                to: RemoteInput::Fifo { capacity: 64 },
            },
        ],
        timing: None,
        run: true,
        owner: None,
        configuration: None,
        variables: Vec::new(),
    };
    // The agent's queryable reaches the robot's session after a while.
    assert!(wait_until(PATIENCE, || {
        match instantiate(&robot, "workstation", &request, Duration::from_secs(5)) {
            Ok(()) => true,
            Err(Error::NoAgent { .. }) => false,
            Err(error) => panic!("instantiation refused: {}", coolbot::Chain(&error)),
        }
    }));
    support::wait_subscribed(&robot, "test/agent/in");
    support::wait_subscribed(&workstation, "test/agent/out");
    for number in 1..=3 {
        numbers.send(number);
    }
    let received: Vec<u64> = (0..3)
        .map(|_| doubled.recv_timeout(PATIENCE).expect("a doubled number"))
        .collect();
    assert_eq!(received, [2, 4, 6]);

    // The remote instance and its bridges are exposed on the workstation's node.
    let ctl = Ctl::new(robot.session().clone(), Duration::from_secs(5));
    let mut rows = Vec::new();
    assert!(wait_until(PATIENCE, || {
        rows = ctl
            .components(Some("workstation"))
            .unwrap()
            .into_iter()
            .map(|listed| (listed.path, listed.monitor.state))
            .collect();
        rows.len() == 3
    }));
    assert_eq!(
        rows,
        [
            (
                format!("{}doubler", coolbot_zenoh::keys::namespace("robot")),
                State::Running
            ),
            (
                format!("{}doubler-input", coolbot_zenoh::keys::namespace("robot")),
                State::Running
            ),
            (
                format!("{}doubler-output", coolbot_zenoh::keys::namespace("robot")),
                State::Running
            ),
        ]
    );

    // Refusals say why.
    let refused =
        |request: &Instantiate| match instantiate(&robot, "workstation", request, PATIENCE) {
            Err(Error::Refused { reason, .. }) => reason,
            other => panic!("expected a refusal, got {other:?}"),
        };
    assert!(refused(&request).contains("not a free instance name"));
    let unknown = Instantiate {
        type_name: "Tripler".to_owned(),
        ..request.clone()
    };
    assert!(refused(&unknown).contains("no component type `Tripler`"));
    let bad_port = Instantiate {
        name: format!("{}other", coolbot_zenoh::keys::namespace("robot")),
        wires: vec![Wire::Input {
            port: "nothing".to_owned(),
            key: "test/agent/x".to_owned(),
        }],
        ..request.clone()
    };
    assert!(refused(&bad_port).contains("has no input port `nothing`"));

    // An instance's overrides are applied before it runs; a refused one fails the
    // request with the control port's reason.
    let mut second = System::new();
    let (tripled, doubled_back) = ends(&mut second);
    second
        .add(
            robot
                .outlet::<u64>("to", "test/agent/in3", queue)
                .build()
                .unwrap(),
        )
        .unwrap();
    second
        .add(
            robot
                .inlet::<u64>("from", "test/agent/out3", OutputKind::Data)
                .build()
                .unwrap(),
        )
        .unwrap();
    second.connect("source.out", "to.input").unwrap();
    second.connect("from.output", "sink.input").unwrap();
    second.run_all().unwrap();
    let tripled = tripled.recv_timeout(PATIENCE).expect("the source started");
    let doubled_back = doubled_back
        .recv_timeout(PATIENCE)
        .expect("the sink started");
    let tripler = Instantiate {
        name: format!("{}tripler", coolbot_zenoh::keys::namespace("robot")),
        wires: vec![
            Wire::Input {
                port: "input".to_owned(),
                key: "test/agent/in3".to_owned(),
            },
            Wire::Output {
                port: "output".to_owned(),
                key: "test/agent/out3".to_owned(),
                to: RemoteInput::Fifo { capacity: 64 },
            },
        ],
        variables: vec![("factor".to_owned(), coolbot::Value::UInt(3))],
        ..request.clone()
    };
    instantiate(&robot, "workstation", &tripler, PATIENCE).expect("a tripler");
    support::wait_subscribed(&robot, "test/agent/in3");
    support::wait_subscribed(&workstation, "test/agent/out3");
    tripled.send(5);
    assert_eq!(doubled_back.recv_timeout(PATIENCE), Some(15));
    let bad_override = Instantiate {
        name: format!("{}broken", coolbot_zenoh::keys::namespace("robot")),
        wires: Vec::new(),
        variables: vec![("speed".to_owned(), coolbot::Value::UInt(3))],
        ..request.clone()
    };
    assert!(refused(&bad_override).contains("no variable `speed`"));
}
