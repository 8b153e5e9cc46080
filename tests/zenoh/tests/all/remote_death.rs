//! A remote instance that dies while its node lives is a fault of its proxy, whatever
//! its cause: an operator sends it to `dead`, its node's agent stops (and takes what
//! it built with it), or its monitoring port falls silent. Each time the compound's
//! policy acts (here: its local substitute takes over) and the recovery queue builds a
//! new generation of the instance on its node once one can be built.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use coolbot::{Command, Controllable, Handle, Monitor, SectionResult, State, Step, System};
use coolbot_zenoh::agent::{Agent, Registry};
use coolbot_zenoh::ctl::Ctl;
use coolbot_zenoh::{ControlReply, Node, Placer};
use coolbot_zenoh_tests::dying::{self, Counting, Parts, counted, registry, started_cell};
use coolbot_zenoh_tests::generated::{dying_cell, finisher, finishing_cell, flaky};
use coolbot_zenoh_tests::support::{PATIENCE, pair, wait_until};
use zenoh::Wait;

fn periods(monitor: &Monitor) -> u64 {
    counted(monitor, "periods")
}

/// The cell's steps about `flaky` so far.
fn steps(cell: &Handle) -> Vec<(Step, String)> {
    dying::steps(cell, "flaky")
}

/// Wait until the cell has taken `step` about `flaky`; its detail.
fn wait_step(cell: &Handle, step: fn(&Step) -> bool, what: &str) -> String {
    dying::wait_step(cell, "flaky", step, what)
}

/// The `flaky` instances built on the station by the robot, `(path, state)`.
fn built(ctl: &Ctl) -> Vec<(String, State)> {
    ctl.components(Some("dying-station"))
        .expect("the station lists")
        .into_iter()
        .filter(|l| {
            l.path.starts_with(&format!(
                "{}cell-flaky-",
                coolbot_zenoh::keys::namespace("dying-robot")
            ))
        })
        .map(|l| (l.path, l.monitor.state))
        .collect()
}

/// The cell, built and running on this thread's placer, with its remote instance
/// counting.
fn running_cell(system: &mut System) -> Handle {
    let cell = started_cell(system);
    cell.instance("flaky")
        .expect("the proxy")
        .wait_for(|m| m.state == State::Running && periods(m) > 0, PATIENCE)
        .unwrap_or_else(|timeout| panic!("the remote instance runs: {timeout}"));
    cell
}

/// The spare stands in, the recovery queue builds the instance again on its node (a
/// new generation, its path not `first`), and the proxy counts on.
fn substituted_then_recovered(cell: &Handle, ctl: &Ctl, first: &str) {
    wait_step(
        cell,
        |s| matches!(s, Step::Substituted { .. }),
        "the spare stands in",
    );
    cell.instance("spare")
        .unwrap()
        .wait_for(|m| m.state == State::Running, PATIENCE)
        .unwrap_or_else(|timeout| panic!("the spare runs: {timeout}"));
    wait_step(
        cell,
        |s| *s == Step::Recovered,
        "the instance is built again",
    );
    let proxy = cell.instance("flaky").unwrap();
    let before = periods(&proxy.snapshot());
    proxy
        .wait_for(
            |m| m.state == State::Running && periods(m) > before + 3,
            PATIENCE,
        )
        .unwrap_or_else(|timeout| panic!("the new generation counts: {timeout}"));
    let now = built(ctl);
    assert!(
        now.iter()
            .any(|(path, state)| path != first && *state == State::Running),
        "a new generation runs on the station: {now:?}"
    );
}

#[test]
fn a_remote_instance_sent_to_dead_by_an_operator_is_substituted_and_built_again() {
    let (station, robot) = pair("dying-station", "dying-robot");
    let (station, robot) = (Arc::new(station), Arc::new(robot));
    let _agent = Agent::start(Arc::clone(&station), registry()).expect("agent");
    let _placer = Placer::new(Arc::clone(&robot), registry()).install();
    let mut system = System::new();
    let cell = running_cell(&mut system);
    let ctl = Ctl::new(station.session().clone(), PATIENCE);
    let first = built(&ctl);
    assert_eq!(first.len(), 1, "{first:?}");
    let first = first[0].0.clone();

    // What `coolctl set dying-station/<instance> state dead` sends.
    let answer = ctl
        .command(
            &format!("dying-station/{first}"),
            &Command::SetState(Controllable::Dead),
        )
        .expect("the station answers");
    assert_eq!(answer, ControlReply::Accepted);

    let detail = wait_step(&cell, |s| *s == Step::Failed, "the proxy fails");
    assert!(
        detail.contains("dead") && detail.contains("dying-station"),
        "the reason names the state and the node: {detail}"
    );
    substituted_then_recovered(&cell, &ctl, &first);
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

#[test]
fn a_remote_instance_whose_agent_stops_is_substituted_and_built_again_when_an_agent_returns() {
    let (station, robot) = pair("dying-station", "dying-robot");
    let (station, robot) = (Arc::new(station), Arc::new(robot));
    let agent = Agent::start(Arc::clone(&station), registry()).expect("agent");
    let _placer = Placer::new(Arc::clone(&robot), registry()).install();
    let mut system = System::new();
    let cell = running_cell(&mut system);
    let ctl = Ctl::new(station.session().clone(), PATIENCE);
    let first = built(&ctl)[0].0.clone();

    // The agent stops (its node lives on): what it built goes with it.
    drop(agent);
    let detail = wait_step(&cell, |s| *s == Step::Failed, "the proxy fails");
    assert!(detail.contains("dead"), "{detail}");
    wait_step(
        &cell,
        |s| matches!(s, Step::Substituted { .. }),
        "the spare stands in",
    );
    // No agent: the recovery queue's retries fail, and say why.
    wait_step(&cell, |s| *s == Step::RetryFailed, "a retry fails");
    assert_eq!(
        cell.instance("flaky").unwrap().state(),
        State::StartingError
    );

    let _agent = Agent::start(Arc::clone(&station), registry()).expect("a new agent");
    substituted_then_recovered(&cell, &ctl, &first);
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

/// A station that builds nothing: its agent accepts every request, its control ports
/// accept every command, and its monitoring ports answer with a running `Flaky`'s
/// snapshot while `answering` holds (counted in `answered`), and not at all
/// otherwise. A broken peer.
struct Mute {
    answering: Arc<AtomicBool>,
    answered: Arc<AtomicU64>,
    _queryables: Vec<zenoh::query::Queryable<()>>,
}

/// Answer `query` with `Accepted`, as an agent and a control port do.
fn accept(query: &zenoh::query::Query) {
    let json = serde_json::to_vec(&ControlReply::Accepted).unwrap();
    let _ = query.reply(query.key_expr().clone(), json).wait();
}

/// A running `Flaky`'s snapshot, as its monitoring port answers it.
fn running_snapshot() -> Vec<u8> {
    let mut harness =
        coolbot::harness::Harness::running(flaky::component("mute", Counting)).unwrap();
    harness.advance(Duration::from_millis(20)).unwrap();
    serde_json::to_vec(&harness.monitor()).unwrap()
}

/// The control and monitoring queryables of every instance on the dying station: its
/// control port accepts every command, its monitoring port answers a running
/// `Flaky`'s snapshot whenever `answer` says so.
fn station_ports(
    session: &zenoh::Session,
    answer: impl Fn() -> bool + Send + Sync + 'static,
) -> [zenoh::query::Queryable<()>; 2] {
    let snapshot = running_snapshot();
    let control = session
        .declare_queryable("coolbot/dying-station/*/c")
        .callback(|query| accept(&query))
        .wait()
        .unwrap();
    let monitor = session
        .declare_queryable("coolbot/dying-station/*/m")
        .callback(move |query| {
            if answer() {
                let _ = query
                    .reply(query.key_expr().clone(), snapshot.clone())
                    .wait();
            }
        })
        .wait()
        .unwrap();
    [control, monitor]
}

fn mute_station(node: &Node) -> Mute {
    let answering = Arc::new(AtomicBool::new(true));
    let answered = Arc::new(AtomicU64::new(0));
    let (answers, count) = (Arc::clone(&answering), Arc::clone(&answered));
    let queryables = station_ports(node.session(), move || {
        let answering = answers.load(Ordering::Acquire);
        if answering {
            count.fetch_add(1, Ordering::AcqRel);
        }
        answering
    });
    let agent = node
        .session()
        .declare_queryable(coolbot_zenoh::keys::agent("dying-station", "*", "*"))
        .callback(|query| accept(&query))
        .wait()
        .unwrap();
    Mute {
        answering,
        answered,
        _queryables: [agent].into_iter().chain(queryables).collect(),
    }
}

/// A station whose instance's ports are declared `late` after its agent answered
/// (its agent accepts every request, then declares the control and monitoring
/// queryables of what it was asked to build): the order in which a robot may learn
/// of them, since Zenoh orders a declaration and a later answer on one link no more
/// than that. The queryables live as long as what this returns.
fn late_station(node: &Node, late: Duration) -> Arc<Mutex<Vec<zenoh::query::Queryable<()>>>> {
    let declared = Arc::new(Mutex::new(Vec::new()));
    let keep = Arc::clone(&declared);
    let session = node.session().clone();
    let agent = node
        .session()
        .declare_queryable(coolbot_zenoh::keys::agent("dying-station", "*", "*"))
        .callback(move |query| {
            accept(&query);
            let (session, keep) = (session.clone(), Arc::clone(&keep));
            std::thread::spawn(move || {
                std::thread::sleep(late);
                let ports = station_ports(&session, || true);
                keep.lock().unwrap().extend(ports);
            });
        })
        .wait()
        .unwrap();
    declared.lock().unwrap().push(agent);
    declared
}

/// An instance whose node answered its request before this node knew its ports is
/// started once they are known: its first snapshot is asked again while nothing here
/// can route the question, not taken for a node that does not answer.
#[test]
fn an_instance_whose_ports_are_known_after_its_agent_answered_starts() {
    let (station, robot) = pair("dying-station", "dying-robot");
    let robot = Arc::new(robot);
    let _late = late_station(&station, Duration::from_millis(300));
    let _placer = Placer::new(Arc::clone(&robot), registry()).install();
    let mut system = System::new();
    let cell = started_cell(&mut system);
    let proxy = cell.instance("flaky").expect("the proxy");
    proxy
        .wait_for(|m| m.state == State::Running, PATIENCE)
        .unwrap_or_else(|timeout| panic!("the proxy runs: {timeout}"));
    assert_eq!(steps(&cell), Vec::new(), "no fault on the way");
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

#[test]
fn a_remote_instance_whose_monitoring_port_falls_silent_is_substituted() {
    let (station, robot) = pair("dying-station", "dying-robot");
    let robot = Arc::new(robot);
    let mute = mute_station(&station);
    let silence = Duration::from_millis(600);
    let _placer = Placer::new(Arc::clone(&robot), registry())
        .silence(silence)
        .install();
    let mut system = System::new();
    let cell = started_cell(&mut system);
    let proxy = cell.instance("flaky").expect("the proxy");
    proxy
        .wait_for(|m| m.state == State::Running, PATIENCE)
        .unwrap_or_else(|timeout| panic!("the proxy runs: {timeout}"));

    // Heard for several bounds (the proxy asks every third of one): no fault while
    // the station answers.
    let quiet = steps(&cell);
    let asked = mute.answered.load(Ordering::Acquire);
    assert!(
        wait_until(PATIENCE, || mute.answered.load(Ordering::Acquire)
            >= asked + 9),
        "the proxy asks for the snapshot"
    );
    assert_eq!(proxy.state(), State::Running, "{:?}", steps(&cell));
    assert_eq!(steps(&cell), quiet);

    mute.answering.store(false, Ordering::Release);
    let detail = wait_step(&cell, |s| *s == Step::Failed, "the proxy fails");
    assert!(
        detail.contains("has not answered") && detail.contains("dying-station"),
        "{detail}"
    );
    wait_step(
        &cell,
        |s| matches!(s, Step::Substituted { .. }),
        "the spare stands in",
    );
    // While silent, the station cannot be built on: the retries fail.
    wait_step(&cell, |s| *s == Step::RetryFailed, "a retry fails");

    mute.answering.store(true, Ordering::Release);
    wait_step(&cell, |s| *s == Step::Recovered, "built again");
    proxy
        .wait_for(|m| m.state == State::Running, PATIENCE)
        .unwrap_or_else(|timeout| panic!("the proxy runs again: {timeout}"));
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

/// `Finisher`'s behaviour: ends its task once told to.
struct Finishing;

impl finisher::Behavior for Finishing {
    fn going_periodic(&mut self, cx: &mut finisher::Cx<'_>) -> SectionResult {
        if cx.vars.finish {
            cx.rt.end();
        }
        Ok(())
    }
}

struct FinishingParts;

/// `FinishingCell`'s supervisor: nothing of its own.
struct Still;

impl finishing_cell::Supervisor for Still {}

impl finishing_cell::Parts for FinishingParts {
    fn supervisor(&mut self) -> impl finishing_cell::Supervisor {
        Still
    }
    fn finisher(&mut self) -> impl finisher::Behavior {
        Finishing
    }
}

/// A remote instance that finishes its task (`end`) is no fault: its proxy ends too.
#[test]
fn a_remote_instance_that_ends_its_task_ends_its_proxy() {
    let (station, robot) = pair("dying-station", "dying-robot");
    let (station, robot) = (Arc::new(station), Arc::new(robot));
    let mut registry = Registry::new();
    finisher::register(&mut registry, |name| finisher::component(name, Finishing));
    let _agent = Agent::start(Arc::clone(&station), registry).expect("agent");
    let mut registry = Registry::new();
    finisher::register(&mut registry, |name| finisher::component(name, Finishing));
    let _placer = Placer::new(Arc::clone(&robot), registry).install();
    let mut system = System::new();
    let cell = system
        .add(finishing_cell::component("cell", FinishingParts).expect("the compound builds"))
        .unwrap();
    system.run_all().unwrap();
    let proxy = cell.instance("finisher").expect("the proxy");
    proxy
        .wait_for(|m| m.state == State::Running, PATIENCE)
        .unwrap_or_else(|timeout| panic!("the proxy runs: {timeout}"));
    proxy
        .command(Command::Set(
            "finish".to_owned(),
            coolbot::Value::Bool(true),
        ))
        .expect("the proxy forwards the command");
    proxy
        .wait_for(|m| m.state == State::End, PATIENCE)
        .unwrap_or_else(|timeout| panic!("the proxy ends: {timeout}"));
    let ctl = Ctl::new(station.session().clone(), PATIENCE);
    let remote: Vec<State> = ctl
        .components(Some("dying-station"))
        .expect("the station lists")
        .into_iter()
        .filter(|l| {
            l.path.starts_with(&format!(
                "{}cell-finisher-",
                coolbot_zenoh::keys::namespace("dying-robot")
            ))
        })
        .map(|l| l.monitor.state)
        .collect();
    assert_eq!(remote, vec![State::End]);
    assert!(
        !cell
            .snapshot()
            .supervision
            .iter()
            .any(|step| step.step == Step::Failed),
        "no fault: {:?}",
        cell.snapshot().supervision
    );
    assert_eq!(cell.state(), State::Running);
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

/// Names too long for the other node's agent are refused when the compound is built,
/// naming the limit, not at start on the other node.
#[test]
fn a_placement_whose_names_the_agent_would_refuse_fails_when_built() {
    let (station, robot) = pair("dying-station", "dying-robot");
    let (station, robot) = (Arc::new(station), Arc::new(robot));
    let _agent = Agent::start(Arc::clone(&station), registry()).expect("agent");
    let _placer = Placer::new(Arc::clone(&robot), registry()).install();
    let long = "c".repeat(100);
    let error = match dying_cell::component(&long, Parts) {
        Ok(_) => panic!("a compound named with 100 characters is placed"),
        Err(error) => coolbot::Chain(&error).to_string(),
    };
    assert!(error.contains("NAME") && error.contains("128"), "{error}");
    // A name that fits is placed as usual.
    assert!(dying_cell::component("cell", Parts).is_ok());
}

/// On plaintext any peer may declare a node's liveliness token. A forged
/// `coolbot/dying-station` token outlives the station, whose session ends without a
/// word (as when its process is killed): the node's token says it lives on, but its
/// proxy hears nothing from the instance it stands for, fails on that silence, and the
/// spare stands in. A node's death does not rest on a token a peer can fake.
#[test]
fn a_forged_token_does_not_hide_a_station_killed_without_a_word() {
    use coolbot_zenoh_tests::support::node;
    let (robot, robot_endpoint) = node("dying-robot", &[]);
    let (station, _) = node("dying-station", std::slice::from_ref(&robot_endpoint));
    let (robot, station) = (Arc::new(robot), Arc::new(station));
    let sees_station = |robot: &Node| {
        wait_until(PATIENCE, || {
            Ctl::new(robot.session().clone(), Duration::from_millis(500))
                .node_names()
                .is_ok_and(|names| names.iter().any(|n| n == "dying-station"))
        })
    };
    assert!(sees_station(&robot), "the robot sees the station");
    let _agent = Agent::start(Arc::clone(&station), registry()).expect("agent");
    let _placer = Placer::new(Arc::clone(&robot), registry())
        .silence(Duration::from_millis(600))
        .install();
    let mut system = System::new();
    let cell = running_cell(&mut system);

    // A peer of the robot's, not the station, declares the station's token.
    let forger_config =
        coolbot_zenoh::peer_config(&[], std::slice::from_ref(&robot_endpoint), false)
            .expect("config");
    let forger = zenoh::open(forger_config)
        .wait()
        .expect("the forger's session");
    let _forged = forger
        .liveliness()
        .declare_token("coolbot/dying-station")
        .wait()
        .expect("a forged token");
    // Declared after it on the same link, so the robot has the forged token once it
    // sees this one (else the station could end before the forged token arrives, and
    // the robot would see the node's token go).
    let _after = forger
        .liveliness()
        .declare_token("test/dying/forged")
        .wait()
        .expect("a second token");
    assert!(
        wait_until(PATIENCE, || robot
            .session()
            .liveliness()
            .get("test/dying/forged")
            .timeout(Duration::from_millis(500))
            .wait()
            .is_ok_and(|replies| replies.recv().is_ok())),
        "the robot sees the forger's tokens"
    );

    // The station's session ends without a word (its agent never says goodbye).
    station
        .session()
        .close()
        .wait()
        .expect("the station's session closes");
    let detail = wait_step(&cell, |s| *s == Step::Failed, "the proxy fails");
    assert!(
        detail.contains("has not answered") && detail.contains("dying-station"),
        "the proxy fails on its silence: {detail}"
    );
    wait_step(
        &cell,
        |s| matches!(s, Step::Substituted { .. }),
        "the spare stands in",
    );
    // And all the while the station's token, forged, was there to be seen.
    assert!(
        sees_station(&robot),
        "the forged token stands for the station"
    );
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

/// A robot started before its station's agent serves: the remote instance cannot
/// start (no agent answers within the placer's timeout), a fault the instance's
/// policy handles as it would a later one. The spare stands in from the start, the
/// compound runs, and the recovery queue builds the instance on the station once an
/// agent is there.
#[test]
fn a_remote_instance_whose_node_does_not_serve_at_start_is_substituted_then_built() {
    let (station, robot) = pair("dying-station", "dying-robot");
    let (station, robot) = (Arc::new(station), Arc::new(robot));
    let _placer = Placer::new(Arc::clone(&robot), registry())
        .timeout(Duration::from_secs(1))
        .install();
    let mut system = System::new();
    let cell = started_cell(&mut system);
    let detail = wait_step(&cell, |s| *s == Step::Failed, "the proxy cannot start");
    assert!(detail.contains("dying-station"), "{detail}");
    wait_step(
        &cell,
        |s| matches!(s, Step::Substituted { .. }),
        "the spare stands in from the start",
    );
    cell.wait_for(|m| m.state == State::Running, PATIENCE)
        .unwrap_or_else(|timeout| panic!("the compound runs: {timeout}"));

    let _agent = Agent::start(Arc::clone(&station), registry()).expect("agent");
    let ctl = Ctl::new(station.session().clone(), PATIENCE);
    substituted_then_recovered(&cell, &ctl, "");
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}
