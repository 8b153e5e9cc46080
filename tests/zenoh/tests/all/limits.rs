//! The limits on what comes from the network (`docs/distribution.md`, "Limits"),
//! against a real agent on loopback: each limit refuses a request over it with a
//! reason naming the limit and its value, and the station builds a valid request
//! afterwards; the hostile sizes that used to abort the station or kill its agent
//! (capacities of 2^33, 2^61 and `usize::MAX`, names and keys of 100,000 characters)
//! are refused the same way; a panic while building refuses that request and the
//! agent serves on; a command on a control key is held to its size and the control
//! port's ranges.

use std::sync::Arc;
use std::time::Duration;

use coolbot::{Chain, SectionResult, Value};
use coolbot_zenoh::agent::{
    Agent, Instantiate, Registry, RemoteInput, RemoteTiming, Wire, instantiate,
};
use coolbot_zenoh::limits::{self, Limit};
use coolbot_zenoh::{ControlReply, Error, Node};
use coolbot_zenoh_tests::generated::{doubler, frame_relay};
use coolbot_zenoh_tests::support::{PATIENCE, pair, robot, wait_until};
use zenoh::Wait;

struct Doubling;

impl doubler::Behavior for Doubling {
    fn doubling_entry(&mut self, cx: &mut doubler::Cx<'_>) -> SectionResult {
        for number in cx.inputs.input.drain() {
            cx.outputs.output.send(number * cx.vars.factor);
        }
        Ok(())
    }
}

struct Relaying;

impl frame_relay::Behavior for Relaying {}

/// A robot asking a station whose agent builds `Doubler`, `FrameRelay` and `Bomb` (a
/// factory with a bug: it panics).
struct Station {
    robot: Node,
    agent: Agent,
    _station: Arc<Node>,
}

impl Station {
    fn start() -> Station {
        Station::start_with_cap(limits::INSTANCES.max)
    }

    /// A station whose agent runs at most `instances` instances at once.
    fn start_with_cap(instances: usize) -> Station {
        let (robot, station) = pair("robot", "station");
        let station = Arc::new(station);
        let mut registry = Registry::new();
        doubler::register(&mut registry, |name| doubler::component(name, Doubling));
        frame_relay::register(&mut registry, |name| frame_relay::component(name, Relaying));
        registry.register("Bomb", |name| panic!("a factory bug building `{name}`"));
        let agent =
            Agent::start_with_cap(Arc::clone(&station), registry, instances).expect("the agent");
        let station = Station {
            robot,
            agent,
            _station: station,
        };
        // The agent's queryable reaches the robot's session after a while.
        assert!(
            wait_until(PATIENCE, || match station.ask(&valid("first")) {
                Ok(()) => true,
                Err(Error::NoAgent { .. }) => false,
                Err(error) => panic!("the first request was refused: {}", Chain(&error)),
            }),
            "the agent never answered"
        );
        station
    }

    fn ask(&self, request: &Instantiate) -> Result<(), Error> {
        instantiate(&self.robot, "station", request, PATIENCE)
    }

    /// The agent's reason for refusing `request`.
    fn refusal(&self, request: &Instantiate) -> String {
        match self.ask(request) {
            Err(Error::Refused { reason, .. }) => reason,
            other => panic!("expected a refusal, got {other:?}"),
        }
    }

    /// The agent's answer to `payload` sent as is on the key of type `type_name`.
    fn raw(&self, type_name: &str, payload: Vec<u8>) -> ControlReply {
        let replies = self
            .robot
            .session()
            .get(coolbot_zenoh::keys::agent("station", type_name, "robot"))
            .payload(payload)
            .timeout(PATIENCE)
            .wait()
            .expect("the query is sent");
        let reply = replies.recv().expect("the agent answers");
        let sample = reply.result().expect("an answer, not an error");
        serde_json::from_slice(&sample.payload().to_bytes()).expect("a ControlReply")
    }

    /// The station still builds: a valid request named `name` is built.
    fn still_builds(&self, name: &str) {
        self.ask(&valid(name))
            .unwrap_or_else(|error| panic!("the station no longer builds `{name}`: {error}"));
    }
}

/// A valid request: a `Doubler` named `name`, no wire.
/// A request for a Doubler named `robot-<name>` (the robot asks: its names begin
/// with `robot-`).
fn valid(name: &str) -> Instantiate {
    Instantiate {
        type_name: "Doubler".to_owned(),
        name: format!("{}{name}", coolbot_zenoh::keys::namespace("robot")),
        wires: Vec::new(),
        configuration: None,
        variables: Vec::new(),
        timing: None,
        run: true,
        owner: None,
    }
}

/// How a refusal names `limit` and its value.
fn names(limit: Limit) -> String {
    format!(
        "over the limit {} = {} {}",
        limit.name, limit.max, limit.unit
    )
}

/// A doubler whose output is bridged for a remote input `to`.
fn output_to(to: RemoteInput) -> Instantiate {
    Instantiate {
        wires: vec![Wire::Output {
            port: "output".to_owned(),
            key: "test/limits/out".to_owned(),
            to,
        }],
        ..valid("queued")
    }
}

/// A timing for a `Doubler` (aperiodic) with `change` applied.
fn timing(change: impl FnOnce(&mut RemoteTiming)) -> Instantiate {
    let mut timing = RemoteTiming {
        period: None,
        max_period: None,
        max_response: None,
        priority: 0,
        qualities: Vec::new(),
        adaptation: None,
    };
    change(&mut timing);
    Instantiate {
        timing: Some(timing),
        ..valid("timed")
    }
}

#[test]
fn each_limit_refuses_a_request_over_it_by_name_and_value_and_the_station_builds_on() {
    coolbot::ranges::allow_realtime_priorities(false);
    let station = Station::start();
    let over = |limit: Limit| "x".repeat(limit.max + 1);
    let wire = |port: &str, key: &str| Wire::Input {
        port: port.to_owned(),
        key: key.to_owned(),
    };
    let limit_cases: Vec<(Limit, Instantiate)> = vec![
        (limits::NAME, valid(&over(limits::NAME))),
        (
            limits::NAME,
            Instantiate {
                type_name: over(limits::NAME),
                ..valid("typed")
            },
        ),
        (
            limits::NAME,
            Instantiate {
                owner: Some(over(limits::NAME)),
                ..valid("owned")
            },
        ),
        (
            limits::NAME,
            Instantiate {
                wires: vec![wire(&over(limits::NAME), "test/limits/in")],
                ..valid("ported")
            },
        ),
        (
            limits::NAME,
            Instantiate {
                variables: vec![(over(limits::NAME), Value::UInt(3))],
                ..valid("set")
            },
        ),
        (
            limits::KEY,
            Instantiate {
                wires: vec![wire("input", &format!("test/{}", over(limits::KEY)))],
                ..valid("keyed")
            },
        ),
        (
            limits::WIRES,
            Instantiate {
                wires: (0..=limits::WIRES.max)
                    .map(|n| wire("input", &format!("test/limits/{n}")))
                    .collect(),
                ..valid("wired")
            },
        ),
        (
            limits::VARIABLES,
            Instantiate {
                variables: vec![("factor".to_owned(), Value::UInt(3)); limits::VARIABLES.max + 1],
                ..valid("varied")
            },
        ),
        (
            limits::QUEUE,
            output_to(RemoteInput::Fifo {
                capacity: limits::QUEUE.max + 1,
            }),
        ),
        (
            limits::QUEUE,
            output_to(RemoteInput::Ufifo {
                initial: limits::QUEUE.max + 1,
                max: None,
            }),
        ),
        (
            limits::QUEUE,
            output_to(RemoteInput::Ufifo {
                initial: 1,
                max: Some(limits::QUEUE.max + 1),
            }),
        ),
        // 16 KiB frames: 8192 of them hold 128 MiB from the start.
        (
            limits::QUEUE_BYTES,
            Instantiate {
                type_name: "FrameRelay".to_owned(),
                wires: vec![Wire::Output {
                    port: "output".to_owned(),
                    key: "test/limits/frames".to_owned(),
                    to: RemoteInput::Fifo { capacity: 8192 },
                }],
                ..valid("frames")
            },
        ),
        (
            limits::REQUEST,
            Instantiate {
                configuration: Some(Value::Str("c".repeat(limits::REQUEST.max))),
                ..valid("configured")
            },
        ),
        (
            limits::LEVELS,
            timing(|timing| timing.qualities = vec!["q".to_owned(); limits::LEVELS.max + 1]),
        ),
        (
            limits::LEVEL_NAME,
            timing(|timing| timing.qualities = vec!["best".to_owned(), over(limits::LEVEL_NAME)]),
        ),
    ];
    let range_cases: Vec<(&str, Instantiate)> = vec![
        (
            "the timing's period: period 50µs out of range: from 100µs to 3600s",
            timing(|timing| timing.period = Some(Duration::from_micros(50))),
        ),
        (
            "the timing's max_period: period 7200s out of range",
            timing(|timing| {
                timing.period = Some(Duration::from_millis(10));
                timing.max_period = Some(Duration::from_secs(7200));
            }),
        ),
        (
            "the timing's max_response: a max_response must be positive",
            timing(|timing| timing.max_response = Some(Duration::ZERO)),
        ),
        (
            "the timing's priority: priority 2147483647 out of range: from -39 to 99",
            timing(|timing| timing.priority = i32::MAX),
        ),
    ];
    let expected = limit_cases
        .into_iter()
        .map(|(limit, request)| (names(limit), request))
        .chain(
            range_cases
                .into_iter()
                .map(|(reason, request)| (reason.to_owned(), request)),
        );
    let mut refused = 0;
    for (n, (reason, request)) in expected.enumerate() {
        let refusal = station.refusal(&request);
        assert!(
            refusal.contains(&reason),
            "case {n}: `{reason}` not in `{refusal}`"
        );
        assert!(refusal.len() < 400, "case {n}: a long refusal: {refusal}");
        refused += 1;
        station.still_builds(&format!("after-{n}"));
    }
    let status = station.agent.status();
    assert_eq!(
        (status.refused, status.panics, status.stopped),
        (refused, 0, None)
    );
    assert_eq!(status.built, refused + 1);
    // A description's own real-time priority is the description's: built (the thread
    // takes it if the OS lets it), whatever the process allows its commands.
    station
        .ask(&Instantiate {
            name: format!(
                "{}realtime-by-description",
                coolbot_zenoh::keys::namespace("robot")
            ),
            ..timing(|timing| timing.priority = 5)
        })
        .expect("a description's priority is built");
    // At the limits, a queue is taken: 4096 frames are 64 MiB.
    station
        .ask(&Instantiate {
            type_name: "FrameRelay".to_owned(),
            wires: vec![Wire::Output {
                port: "output".to_owned(),
                key: "test/limits/frames".to_owned(),
                to: RemoteInput::Fifo { capacity: 4096 },
            }],
            ..valid("frames-at-the-limit")
        })
        .expect("a queue of 64 MiB");
    station
        .ask(&Instantiate {
            name: format!(
                "{}queued-at-the-limit",
                coolbot_zenoh::keys::namespace("robot")
            ),
            ..output_to(RemoteInput::Ufifo {
                initial: limits::QUEUE.max,
                max: Some(limits::QUEUE.max),
            })
        })
        .expect("a ufifo of QUEUE packets");
}

#[test]
fn hostile_sizes_are_refused_and_the_station_and_its_agent_live_on() {
    let station = Station::start();
    let huge = "h".repeat(100_000);
    let cases: Vec<(Limit, Instantiate)> = vec![
        (
            limits::QUEUE,
            output_to(RemoteInput::Fifo { capacity: 1 << 33 }),
        ),
        (
            limits::QUEUE,
            output_to(RemoteInput::Fifo {
                capacity: usize::MAX,
            }),
        ),
        (
            limits::QUEUE,
            output_to(RemoteInput::Fifo { capacity: 1 << 61 }),
        ),
        (
            limits::QUEUE,
            output_to(RemoteInput::Ufifo {
                initial: 1 << 61,
                max: None,
            }),
        ),
        (
            limits::QUEUE,
            output_to(RemoteInput::Ufifo {
                initial: 64,
                max: Some(usize::MAX),
            }),
        ),
        (limits::NAME, valid(&huge)),
        (
            limits::NAME,
            Instantiate {
                owner: Some(huge.clone()),
                ..valid("owned")
            },
        ),
        (
            limits::NAME,
            Instantiate {
                variables: vec![(huge.clone(), Value::UInt(1))],
                ..valid("set")
            },
        ),
        (
            limits::KEY,
            Instantiate {
                wires: vec![Wire::Input {
                    port: "input".to_owned(),
                    key: format!("test/{huge}"),
                }],
                ..valid("keyed")
            },
        ),
        (
            limits::KEY,
            Instantiate {
                wires: vec![Wire::Output {
                    port: "output".to_owned(),
                    key: huge.clone(),
                    to: RemoteInput::Fifo { capacity: 1 << 33 },
                }],
                ..valid("keyed-out")
            },
        ),
    ];
    for (n, (limit, request)) in cases.into_iter().enumerate() {
        let refusal = station.refusal(&request);
        assert!(
            refusal.contains(&names(limit)),
            "case {n}: `{}` not in `{refusal}`",
            names(limit)
        );
        assert!(refusal.len() < 400, "case {n}: a long refusal: {refusal}");
        station.still_builds(&format!("after-{n}"));
    }
    // A type name of 100,000 characters: the asking side refuses to make a key of
    // it, and the agent refuses it in a request on another type's key.
    let refused = station
        .ask(&Instantiate {
            type_name: huge.clone(),
            ..valid("typed")
        })
        .expect_err("a type name of 100,000 characters");
    let refusal = Chain(&refused).to_string();
    assert!(matches!(refused, Error::InvalidName { .. }), "{refusal}");
    assert!(refusal.contains(&names(limits::PATH)), "{refusal}");
    assert!(refusal.len() < 400, "{refusal}");
    let payload = serde_json::to_vec(&Instantiate {
        type_name: huge.clone(),
        ..valid("typed")
    })
    .unwrap();
    match station.raw("Doubler", payload) {
        ControlReply::Rejected { reason } => {
            assert!(reason.contains(&names(limits::NAME)), "{reason}");
            assert!(reason.len() < 400, "{reason}");
        }
        ControlReply::Accepted => panic!("a type name of 100,000 characters was accepted"),
    }
    // Bytes that are no request, and a request of 2 MiB.
    match station.raw("Doubler", vec![0xff; 64]) {
        ControlReply::Rejected { reason } => assert!(reason.starts_with("malformed request")),
        ControlReply::Accepted => panic!("garbage was accepted"),
    }
    match station.raw("Doubler", vec![b' '; 2 << 20]) {
        ControlReply::Rejected { reason } => {
            assert!(reason.contains(&names(limits::REQUEST)), "{reason}");
        }
        ControlReply::Accepted => panic!("a request of 2 MiB was accepted"),
    }
    station.still_builds("last");
    let status = station.agent.status();
    assert_eq!((status.panics, status.stopped), (0, None));
}

#[test]
fn a_panic_while_building_refuses_that_request_and_the_agent_serves_on() {
    let station = Station::start();
    for n in 1..=2 {
        let refusal = station.refusal(&Instantiate {
            type_name: "Bomb".to_owned(),
            ..valid(&format!("bomb{n}"))
        });
        assert!(
            refusal.contains(&format!(
                "a panic: a factory bug building `{}bomb{n}`",
                coolbot_zenoh::keys::namespace("robot")
            )),
            "{refusal}"
        );
        station.still_builds(&format!("after-bomb{n}"));
        let status = station.agent.status();
        assert_eq!((status.panics, status.stopped.as_deref()), (n, None));
    }
}

#[test]
fn an_answer_over_its_limit_from_another_nodes_agent_is_refused_undecoded() {
    let (robot, impostor) = pair("robot", "impostor");
    // An agent answering 100,000 bytes.
    let _queryable = impostor
        .session()
        .declare_queryable(coolbot_zenoh::keys::agent("impostor", "*", "*"))
        .callback(|query| {
            let reason = "r".repeat(100_000);
            let json = serde_json::to_vec(&ControlReply::Rejected { reason }).unwrap();
            let _ = query.reply(query.key_expr().clone(), json).wait();
        })
        .wait()
        .unwrap();
    let mut reason = String::new();
    assert!(wait_until(PATIENCE, || {
        match instantiate(&robot, "impostor", &valid("x"), Duration::from_secs(5)) {
            Err(Error::NoAgent { .. }) => false,
            Err(error @ Error::TooLarge { .. }) => {
                reason = Chain(&error).to_string();
                true
            }
            other => panic!("expected a refusal, got {other:?}"),
        }
    }));
    assert!(reason.contains(&names(limits::REPLY)), "{reason}");
}

/// The control port's answer to `payload` on `robot/<path>`'s control key.
fn command(station: &Node, path: &str, payload: Vec<u8>) -> ControlReply {
    let replies = station
        .session()
        .get(format!("coolbot/robot/{path}/c"))
        .payload(payload)
        .timeout(PATIENCE)
        .wait()
        .expect("the query is sent");
    let reply = replies.recv().expect("the component answers");
    serde_json::from_slice(&reply.result().expect("an answer").payload().to_bytes())
        .expect("a ControlReply")
}

#[test]
fn a_command_on_a_control_key_is_held_to_its_size_and_ranges_and_quoted_short() {
    let (node, station) = pair("robot", "station");
    let system = robot(&node);
    // The logger answers once its control key has reached the station.
    let json = |command: &coolbot::Command| serde_json::to_vec(command).unwrap();
    assert!(wait_until(PATIENCE, || {
        let replies = station
            .session()
            .get("coolbot/robot/logger/c")
            .payload(json(&coolbot::Command::SetQuality(0)))
            .timeout(Duration::from_millis(500))
            .wait()
            .unwrap();
        replies.recv().is_ok()
    }));
    let rejected = |reply: ControlReply| match reply {
        ControlReply::Rejected { reason } => reason,
        ControlReply::Accepted => panic!("accepted"),
    };
    // Over the size limit: refused undecoded.
    let big = json(&coolbot::Command::Configure(Value::Str(
        "c".repeat(limits::COMMAND.max),
    )));
    let reason = rejected(command(&station, "logger", big));
    assert!(reason.contains(&names(limits::COMMAND)), "{reason}");
    // Out of the control port's ranges.
    let reason = rejected(command(
        &station,
        "robot.base.motion",
        json(&coolbot::Command::SetMaxResponse(Duration::ZERO)),
    ));
    assert_eq!(reason, "a max_response must be positive");
    let reason = rejected(command(
        &station,
        "logger",
        json(&coolbot::Command::SetPriority(i32::MAX)),
    ));
    assert_eq!(reason, "priority 2147483647 out of range: from -39 to 99");
    // What it refuses is quoted short: a variant of 100,000 characters, a variable
    // name of 100,000 characters.
    let huge = "v".repeat(100_000);
    let reason = rejected(command(
        &station,
        "logger",
        format!("{{\"SetState\": \"{huge}\"}}").into_bytes(),
    ));
    assert!(
        reason.starts_with("malformed command: unknown variant"),
        "{reason}"
    );
    assert!(reason.len() < 400, "{} bytes", reason.len());
    let reason = rejected(command(
        &station,
        "logger",
        json(&coolbot::Command::Set(huge.clone(), Value::Unit)),
    ));
    assert!(reason.contains("... (100000 bytes in all)` ("), "{reason}");
    assert!(reason.len() < 200, "{} bytes", reason.len());
    // The robot runs on.
    let motion = system.handle_at("robot.base.motion").unwrap();
    assert_eq!(
        motion.snapshot().max_response,
        motion.spec().timing.max_response
    );
    assert_eq!(motion.state(), coolbot::State::Running);
}

#[test]
fn the_documentation_lists_every_limit_with_its_value() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/distribution.md");
    let doc = std::fs::read_to_string(path).expect("docs/distribution.md is readable");
    for limit in limits::ALL {
        let row = format!("| `{}` | {} {} |", limit.name, limit.max, limit.unit);
        assert!(doc.contains(&row), "docs/distribution.md lacks `{row}`");
    }
}

#[test]
fn an_agent_runs_at_most_its_cap_of_instances_and_builds_again_when_one_is_dead() {
    // The same check as at the default cap (`INSTANCES`), with fewer instances to build.
    let cap = 4;
    let station = Station::start_with_cap(cap);
    let limit = Limit {
        max: cap,
        ..limits::INSTANCES
    };
    // `first` runs already: fill the agent up to its cap.
    for index in 1..cap {
        station.still_builds(&format!("many{index}"));
    }
    let reason = station.refusal(&valid("one-too-many"));
    assert!(reason.contains(&names(limit)), "{reason}");
    assert!(
        reason.contains("the instances this agent runs with this one: 5 instances"),
        "{reason}"
    );
    // One goes to dead: there is room for one more, and only one.
    let ctl = coolbot_zenoh::ctl::Ctl::new(station.robot.session().clone(), PATIENCE);
    let reply = ctl
        .command(
            &format!("station/{}many1", coolbot_zenoh::keys::namespace("robot")),
            &coolbot::Command::SetState(coolbot::Controllable::Dead),
        )
        .expect("the station answers");
    assert_eq!(reply, ControlReply::Accepted);
    // (It is dead once its thread has taken the command: ask until then.)
    assert!(
        wait_until(PATIENCE, || station.ask(&valid("one-more")).is_ok()),
        "no room after an instance went to dead"
    );
    let reason = station.refusal(&valid("one-too-many"));
    assert!(reason.contains(&names(limit)), "{reason}");
    assert_eq!(station.agent.status().panics, 0);
}
