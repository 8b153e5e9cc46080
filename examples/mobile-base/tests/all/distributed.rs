//! The robot distributed over two processes, as its description says
//! (`instance wanderer: Wanderer on "station";`, `docs/distribution.md`): a station
//! node (`--node station --serve`) runs the wanderer the robot's compound places on
//! it; `kill -9` of the station is a fault of the wanderer's proxy, its local
//! substitute `fallback` drives the base meanwhile, and when the station is back the
//! recovery queue builds the wanderer there again and the fallback stands down.
#![cfg(feature = "network")]

use std::sync::mpsc;
use std::time::{Duration, Instant};

use rustix::process::{Pid, Signal, kill_process};

use crate::support::{free_port, spawn, wait_line};

#[test]
fn the_wanderer_runs_on_the_station_and_the_fallback_drives_while_the_station_is_lost() {
    let port = free_port();
    let listen = format!("tcp/127.0.0.1:{port}");
    let station_args = [
        "--node",
        "station",
        "--serve",
        "--listen",
        &listen,
        "--no-multicast",
        "--lease",
        "1s",
    ];
    let (sender, lines) = mpsc::channel();
    let (mut station, _) = spawn("station", &station_args, "warn,coolbot_zenoh=info", &sender);
    let mut seen = Vec::new();
    let serving = |l: &str| l.starts_with("station: node `station` on the network");
    wait_line(&lines, &mut seen, "of the station serving", serving);
    let (robot, robot_out) = spawn(
        "robot",
        &[
            "--node",
            "robot",
            "--connect",
            &listen,
            "--no-multicast",
            "--lease",
            "1s",
            "--duration",
            "120s",
            "--output",
            "lines",
        ],
        "warn,coolbot_zenoh=info",
        &sender,
    );
    let built = |l: &str| {
        l.starts_with("station")
            && l.contains("built for another node")
            && l.contains(&format!(
                "{}robot-wanderer",
                coolbot_zenoh::keys::namespace("robot")
            ))
    };
    let robot_says =
        |text: &'static str| move |l: &str| l.starts_with("robot: ") && l.contains(text);
    let status = |a: &'static str, b: &'static str| {
        move |l: &str| l.starts_with("robot: [") && l.contains(a) && l.contains(b)
    };

    // The station built the wanderer for the robot; the robot's status lines show it
    // running (its proxy mirrors the remote user state) with the fallback standing by.
    wait_line(
        &lines,
        &mut seen,
        "of the station building the wanderer",
        built,
    );
    wait_line(
        &lines,
        &mut seen,
        "with the remote wanderer running",
        status(" wanderer=running/", " fallback=ready"),
    );

    // kill -9 the station: the proxy's node is lost, the fallback takes over.
    station.kill().expect("SIGKILL");
    let _ = station.wait();
    wait_line(
        &lines,
        &mut seen,
        "saying the station is lost",
        robot_says("robot: wanderer failed: node `station` is lost"),
    );
    wait_line(
        &lines,
        &mut seen,
        "substituting the fallback",
        robot_says("robot: wanderer substituted by fallback"),
    );
    wait_line(
        &lines,
        &mut seen,
        "with the fallback driving",
        status(" fallback=running/", " wanderer="),
    );

    // The station is back: the wanderer is built there again and takes over.
    let (mut station, _) = spawn("station", &station_args, "warn,coolbot_zenoh=info", &sender);
    wait_line(
        &lines,
        &mut seen,
        "of the new station building the wanderer",
        built,
    );
    wait_line(
        &lines,
        &mut seen,
        "saying the wanderer recovered",
        robot_says("robot: wanderer recovered"),
    );
    wait_line(
        &lines,
        &mut seen,
        "with the wanderer back and the fallback ready",
        status(" wanderer=running/", " fallback=ready"),
    );

    // SIGTERM: a clean shutdown, which releases the remote wanderer too.
    kill_process(Pid::from_child(&robot), Signal::TERM).expect("SIGTERM");
    let mut robot = robot;
    let status = robot.wait().expect("the robot exits");
    let out = robot_out.join().expect("stdout");
    assert!(status.success(), "{out}");
    assert!(out.contains("substitutions 1, recoveries 1"), "{out}");
    assert!(
        out.contains("clean: every component dead, every thread joined"),
        "{out}"
    );
    // A robot that dies without releasing its wanderer: the station sees it lost and
    // sends what it built for it to `dead`.
    let (mut robot, _) = spawn(
        "robot",
        &[
            "--node",
            "robot",
            "--connect",
            &listen,
            "--no-multicast",
            "--lease",
            "1s",
            "--duration",
            "120s",
            "--output",
            "lines",
        ],
        "warn,coolbot_zenoh=info",
        &sender,
    );
    wait_line(
        &lines,
        &mut seen,
        "of the station building a wanderer again",
        built,
    );
    robot.kill().expect("SIGKILL");
    let _ = robot.wait();
    wait_line(
        &lines,
        &mut seen,
        "of the station stopping the dead robot's instances",
        |l| l.starts_with("station") && l.contains("is lost: they go to dead"),
    );
    station.kill().expect("SIGKILL");
    let _ = station.wait();
}

/// In one process, two Zenoh sessions: the station's agent, and the robot with the
/// placer installed (`mobile_base::node::open`). Commands given to the wanderer's
/// proxy reach the instance on the station (read back on the station's own keys), and
/// the proxy mirrors what the instance publishes.
#[test]
fn commands_to_the_proxy_reach_the_remote_wanderer_and_its_variables_come_back() {
    use std::sync::Arc;

    use coolbot::{Command, Controllable, State, Value};
    use coolbot_zenoh::agent::{Agent, Registry};
    use coolbot_zenoh::ctl::{Ctl, CtlError};
    use coolbot_zenoh::zenoh::{self, Wait};
    use mobile_base::generated::wanderer;
    use mobile_base::node::NodeOptions;
    use mobile_base::robot::{Robot, Setup};
    use mobile_base::world::{Platform, World};

    let port = free_port();
    let listen = format!("tcp/127.0.0.1:{port}");
    let config = coolbot_zenoh::peer_config(std::slice::from_ref(&listen), &[], false)
        .expect("a configuration");
    let station = Arc::new(coolbot_zenoh::Node::open("station", config).expect("the station"));
    let mut registry = Registry::new();
    wanderer::register(&mut registry, |name| {
        wanderer::component(name, mobile_base::wanderer::Wanderer::default())
    });
    let _agent = Agent::start(Arc::clone(&station), registry).expect("the agent");
    let network = mobile_base::node::open(
        &NodeOptions {
            connect: vec![listen.clone()],
            multicast: Some(false),
            ..NodeOptions::named("robot")
        },
        &mobile_base::node::Board::example(),
    )
    .expect("the robot's node");

    let platform = Arc::new(Platform::new(
        World::example(),
        World::example_start(),
        None,
    ));
    let robot = Robot::start(&platform, &Setup::default()).expect("the robot starts");
    let proxy = &robot.wanderer;
    let session = zenoh::open(
        coolbot_zenoh::peer_config(&[], std::slice::from_ref(&listen), false).expect("config"),
    )
    .wait()
    .expect("a session");
    let ctl = Ctl::new(session, Duration::from_secs(2));
    let deadline = Duration::from_secs(20);
    // The instance's name on the station: `5-robot-robot-wanderer-<epoch>-<generation>`.
    let until = Instant::now() + deadline;
    let remote = loop {
        let listed = ctl.components(Some("station")).unwrap_or_default();
        if let Some(found) = listed.iter().find(|c| {
            c.path.starts_with(&format!(
                "{}robot-wanderer-",
                coolbot_zenoh::keys::namespace("robot")
            )) && c.path.ends_with("-1")
        }) {
            break format!("station/{}", found.path);
        }
        assert!(
            Instant::now() < until,
            "no wanderer on the station: {listed:?}"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    let remote = remote.as_str();
    // Polls the remote wanderer's snapshot (its monitor, or why the station has
    // none) until `done` holds of it, or panics with the last one.
    let remote_until = |what: &str, done: &dyn Fn(&Result<coolbot::Monitor, CtlError>) -> bool| {
        let until = Instant::now() + deadline;
        loop {
            let snapshot = ctl.snapshot(remote);
            if done(&snapshot) {
                return;
            }
            assert!(
                Instant::now() <= until,
                "the remote wanderer {remote} is not {what}: {snapshot:?}"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    };
    let remote_is = |what: &str, holds: &dyn Fn(&coolbot::Monitor) -> bool| {
        remote_until(what, &|snapshot| snapshot.as_ref().is_ok_and(holds));
    };
    let variable = |monitor: &coolbot::Monitor, name: &str| {
        monitor
            .variables
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, value)| value.clone())
    };

    // The instance runs on the station, and the proxy mirrors its user state.
    remote_is("running", &|m| m.state == State::Running);
    let mirrored = proxy
        .wait_for(
            |m| m.user_state.is_some() && m.state == State::Running,
            deadline,
        )
        .expect("the proxy runs");
    assert!(
        ["wandering", "avoiding", "seeking"]
            .contains(&mirrored.user_state.as_deref().unwrap_or("")),
        "{mirrored:?}"
    );

    // A controllable variable: set through the proxy, set on the station, and the
    // value the station publishes comes back to the proxy's monitoring port.
    proxy
        .command(Command::Set("seek".to_owned(), Value::Bool(true)))
        .expect("seek is set");
    remote_is("seeking", &|m| {
        variable(m, "seek") == Some(Value::Bool(true))
    });
    proxy
        .wait_for(|m| variable(m, "seek") == Some(Value::Bool(true)), deadline)
        .expect("the proxy mirrors seek");
    // A bad value is refused by the remote instance, with its reason.
    let refused = proxy
        .command(Command::Set(
            "seek".to_owned(),
            Value::Str("yes".to_owned()),
        ))
        .expect_err("a text is no bool");
    assert!(refused.reason.contains("seek"), "{refused}");

    // The period, and the default automaton: suspend and run.
    proxy
        .command(Command::SetPeriod(Duration::from_millis(120)))
        .expect("the period is set");
    remote_is("at 120 ms", &|m| {
        m.period == Some(Duration::from_millis(120))
    });
    proxy
        .command(Command::SetState(Controllable::Suspended))
        .expect("suspended");
    remote_is("suspended", &|m| m.state == State::Suspended);
    proxy
        .command(Command::SetState(Controllable::Running))
        .expect("running again");
    remote_is("running again", &|m| m.state == State::Running);

    // Shutting the robot down releases the remote instance: it goes `dead`, and the
    // station's agent, finding it dead, withdraws its keys. The test may come after
    // either.
    let report = robot.shutdown();
    assert!(report.clean(), "{report:?}");
    remote_until("released", &|snapshot| match snapshot {
        Ok(monitor) => monitor.state == State::Dead,
        Err(error) => matches!(error, CtlError::UnknownComponent { .. }),
    });
    drop(network);
}
