//! Remote instances from the description (`coolbot_zenoh::place`): a compound's
//! instance declared on another node runs there behind a proxy, and every connection
//! kind crosses the network through the proxy's ports, both ways: tick, last, fifo,
//! ufifo and poster inputs; tick, data and poster outputs (a poster's value reaches a
//! reader that joins late); and pull, both ways in one request.

use std::sync::Arc;
use std::time::Duration;

use coolbot::crossbeam_channel::{self, Receiver, Sender};
use coolbot::port::{DataOut, FifoIn, LastIn, PosterIn, PosterOut, TickIn, TickOut, UfifoIn};
use coolbot::{MonitorEvent, SectionResult, State, System};
use coolbot_zenoh::Placer;
use coolbot_zenoh::agent::{Agent, Registry};
use coolbot_zenoh_tests::generated::{
    asker, cell, cell_sink, cell_source, counter, doubling, every_kind_relay, flaky, ignore_cell,
    nest_cell, pair_relay, pair_sink, pair_source, pull_cell, pull_doubler, remote_lead_pair,
    remote_pair, restart_cell, tuned, tuned_cell,
};
use coolbot_zenoh_tests::support::{NodeProcess, PATIENCE, pair, wait_until};
use zenoh::Wait;

/// The ports of a relay, as its behaviour hands them over when it starts.
#[derive(Clone)]
struct RelayPorts {
    ti: TickIn,
    li: LastIn<u64>,
    fi: FifoIn<u64>,
    ui: UfifoIn<u64>,
    pi: PosterIn<u64>,
    to: TickOut,
    out: DataOut<u64>,
    po: PosterOut<u64>,
}

/// A relay's behaviour: hands its ports to the test when it starts.
struct HandRelay(Sender<RelayPorts>);

impl every_kind_relay::Behavior for HandRelay {
    fn start(&mut self, cx: &mut every_kind_relay::Cx<'_>) -> SectionResult {
        let (i, o) = (&cx.inputs, &cx.outputs);
        let _ = self.0.send(RelayPorts {
            ti: i.ti.clone(),
            li: i.li.clone(),
            fi: i.fi.clone(),
            ui: i.ui.clone(),
            pi: i.pi.clone(),
            to: o.to.clone(),
            out: o.out.clone(),
            po: o.po.clone(),
        });
        Ok(())
    }
}

/// The local source's outputs, handed over when it starts.
struct SourcePorts {
    t: TickOut,
    d: DataOut<u64>,
    p: PosterOut<u64>,
}

struct HandSource(Sender<SourcePorts>);

impl cell_source::Behavior for HandSource {
    fn start(&mut self, cx: &mut cell_source::Cx<'_>) -> SectionResult {
        let o = &cx.outputs;
        let _ = self.0.send(SourcePorts {
            t: o.t.clone(),
            d: o.d.clone(),
            p: o.p.clone(),
        });
        Ok(())
    }
}

/// The local sink's inputs, handed over when it starts.
struct SinkPorts {
    ti: TickIn,
    fi: FifoIn<u64>,
    li: LastIn<u64>,
    pi: PosterIn<u64>,
}

struct HandSink(Sender<SinkPorts>);

impl cell_sink::Behavior for HandSink {
    fn start(&mut self, cx: &mut cell_sink::Cx<'_>) -> SectionResult {
        let i = &cx.inputs;
        let _ = self.0.send(SinkPorts {
            ti: i.ti.clone(),
            fi: i.fi.clone(),
            li: i.li.clone(),
            pi: i.pi.clone(),
        });
        Ok(())
    }
}

/// The behaviour of every supervisor here: nothing.
struct Quiet;

impl cell::Supervisor for Quiet {}
impl pull_cell::Supervisor for Quiet {}
impl nest_cell::Supervisor for Quiet {}
impl doubling::Supervisor for Quiet {}
impl tuned_cell::Supervisor for Quiet {}
impl restart_cell::Supervisor for Quiet {}
impl ignore_cell::Supervisor for Quiet {}
impl remote_pair::Supervisor for Quiet {}
impl remote_lead_pair::Supervisor for Quiet {}

/// `Cell`'s parts: the source and sink hand their ports to the test; the local
/// relay (which the placer leaves unused: the station's runs) hands them to nobody.
struct CellParts {
    source: Sender<SourcePorts>,
    sink: Sender<SinkPorts>,
}

impl cell::Parts for CellParts {
    fn supervisor(&mut self) -> impl cell::Supervisor {
        Quiet
    }
    fn source(&mut self) -> impl cell_source::Behavior {
        HandSource(self.source.clone())
    }
    fn relay(&mut self) -> impl every_kind_relay::Behavior {
        HandRelay(crossbeam_channel::bounded(1).0)
    }
    fn sink(&mut self) -> impl cell_sink::Behavior {
        HandSink(self.sink.clone())
    }
}

/// A registry of `EveryKindRelay`, whose instances hand their ports to `built`.
fn registry(built: Sender<RelayPorts>) -> Registry {
    let mut registry = Registry::new();
    every_kind_relay::register(&mut registry, move |name| {
        every_kind_relay::component(name, HandRelay(built.clone()))
    });
    registry
}

/// A station running an agent and a robot whose placer this thread uses, on a
/// loopback network of their own; dropped in the reverse order of their making.
struct Placed {
    _placer: coolbot::remote::Installed,
    _agent: Agent,
    _robot: Arc<coolbot_zenoh::Node>,
    station: Arc<coolbot_zenoh::Node>,
}

/// [`Placed`] nodes named `station` and `robot`, both with `registry`'s types.
fn placed(station: &str, robot: &str, registry: fn() -> Registry) -> Placed {
    let (station, robot) = pair(station, robot);
    let (station, robot) = (Arc::new(station), Arc::new(robot));
    Placed {
        _agent: Agent::start(Arc::clone(&station), registry()).expect("agent"),
        _placer: Placer::new(Arc::clone(&robot), registry()).install(),
        _robot: robot,
        station,
    }
}

/// What a channel's sender handed over, once it has.
fn handed<T>(ports: &Receiver<T>, what: &str) -> T {
    ports
        .recv_timeout(PATIENCE)
        .unwrap_or_else(|_| panic!("{what} did not start"))
}

#[test]
fn every_connection_kind_crosses_the_network_through_a_proxy_both_ways() {
    let (station, robot) = pair("station", "robot");
    let station = Arc::new(station);
    let robot = Arc::new(robot);
    let (built, remote_ports) = crossbeam_channel::bounded(1);
    let _agent = Agent::start(Arc::clone(&station), registry(built)).expect("agent");
    let _placer = Placer::new(
        Arc::clone(&robot),
        registry(crossbeam_channel::bounded(1).0),
    )
    .install();

    // Local producers and consumers around the remote relay (`cool/placement.cool`).
    let (source, sources) = crossbeam_channel::bounded(1);
    let (sink, sinks) = crossbeam_channel::bounded(1);
    let compound =
        cell::component("cell", CellParts { source, sink }).expect("the compound builds");
    let mut system = System::new();
    let cell = system.add(compound).expect("added");
    system.run_all().expect("runs");
    let proxy = cell.instance("relay").expect("the relay's proxy");
    proxy
        .wait_for(|m| m.state == State::Running, PATIENCE)
        .expect("the proxy runs");
    let remote = handed(&remote_ports, "the relay the agent built on the station");
    let SourcePorts {
        t: src_t,
        d: src_d,
        p: src_p,
    } = handed(&sources, "the source");
    let SinkPorts {
        ti: dst_ti,
        fi: dst_fi,
        li: dst_li,
        pi: dst_pi,
    } = handed(&sinks, "the sink");

    // Out: local producers to the remote relay's inputs, every kind. The poster is
    // posted first, before anything else: its value reaches the relay however late.
    src_p.post(42);
    for _ in 0..3 {
        src_t.emit();
    }
    for n in 1..=5 {
        src_d.send(n);
    }
    let (mut ticks, mut fifo, mut ufifo) = (0, Vec::new(), Vec::new());
    let arrived = wait_until(PATIENCE, || {
        ticks += remote.ti.take();
        fifo.extend(remote.fi.drain());
        ufifo.extend(remote.ui.drain());
        ticks == 3
            && fifo == [1, 2, 3, 4, 5]
            && ufifo == [1, 2, 3, 4, 5]
            && remote.li.latest() == Some(5)
            && remote.pi.read() == Some(42)
    });
    assert!(
        arrived,
        "on the station: ticks {ticks}, fifo {fifo:?}, ufifo {ufifo:?}, last {:?}, poster {:?}",
        remote.li.latest(),
        remote.pi.read()
    );

    // Back: the remote relay's outputs to the local consumers, every kind.
    remote.po.post(99);
    remote.to.emit();
    remote.to.emit();
    for n in [7, 8, 9] {
        remote.out.send(n);
    }
    let (mut ticks, mut fifo) = (0, Vec::new());
    let arrived = wait_until(PATIENCE, || {
        ticks += dst_ti.take();
        fifo.extend(dst_fi.drain());
        ticks == 2 && fifo == [7, 8, 9] && dst_li.latest() == Some(9) && dst_pi.read() == Some(99)
    });
    assert!(
        arrived,
        "here: ticks {ticks}, fifo {fifo:?}, last {:?}, poster {:?}",
        dst_li.latest(),
        dst_pi.read()
    );
    // Nothing was lost on the way: no overflow at the proxy's inputs.
    assert_eq!(proxy.snapshot().overflows, 0);
    // The remote instance's timing shows on the proxy's monitor: a period given to the
    // proxy goes to the remote instance (the proxy's runner sets nothing of its own),
    // and the period its monitor then shows comes back on the proxy's.
    assert_eq!(proxy.snapshot().period, None);
    proxy
        .command(coolbot::Command::SetPeriod(Duration::from_millis(25)))
        .expect("the period is forwarded");
    assert!(
        wait_until(PATIENCE, || proxy.snapshot().period
            == Some(Duration::from_millis(25))),
        "{:?}",
        proxy.snapshot()
    );

    // Losses show on the proxy's monitor, with their events. What the remote fifo
    // (16, reject) drops: 20 packets while the station reads none.
    let events = proxy.subscribe();
    for n in 100..120 {
        src_d.send(n);
    }
    assert!(
        wait_until(PATIENCE, || proxy
            .snapshot()
            .port_overflows
            .contains(&("fi".to_owned(), 4))),
        "{:?}",
        proxy.snapshot()
    );
    // Bytes that are no packet, put on the key of the proxy's output `out` (from the
    // station, as a faulty producer would): dropped, and counted at `network`.
    let heard = robot
        .session()
        .declare_subscriber("coolbot-link/station/*/out/out")
        .wait()
        .expect("subscribe");
    remote.out.send(10);
    let key = heard
        .recv_timeout(PATIENCE)
        .expect("a packet on the output's key")
        .expect("in time")
        .key_expr()
        .to_string();
    station
        .session()
        .put(key, vec![0xff_u8; 3])
        .wait()
        .expect("put");
    assert!(
        wait_until(PATIENCE, || proxy
            .snapshot()
            .port_overflows
            .contains(&("@network".to_owned(), 1))),
        "{:?}",
        proxy.snapshot()
    );
    let snapshot = proxy.snapshot();
    assert_eq!(snapshot.overflows, 5, "{snapshot:?}");
    let mut announced = Vec::new();
    while let Ok(event) = events.try_recv() {
        if let MonitorEvent::Overflow { port, lost, total } = event {
            announced.push((port, lost, total));
        }
    }
    // Every loss was announced: at `fi` (the proxy's own queue or the remote one,
    // whichever filled first), then on the network.
    let at = |port: &str| -> (u64, Option<u64>) {
        let mut events = announced.iter().filter(|(p, _, _)| p == port);
        (
            events.clone().map(|(_, lost, _)| lost).sum(),
            events.next_back().map(|(_, _, total)| *total),
        )
    };
    assert_eq!(at("fi"), (4, Some(4)), "{announced:?}");
    assert_eq!(at("@network"), (1, Some(1)), "{announced:?}");
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

/// `PullDoubler`'s behaviour: answers a pull of `y` by pulling `x` and sending twice
/// the value.
struct Twice;

impl pull_doubler::Behavior for Twice {
    fn answer_y(&mut self, cx: &mut pull_doubler::Cx<'_>) -> Result<u64, coolbot::Fault> {
        let value = cx
            .inputs
            .x
            .pull(Duration::from_secs(5))
            .map_err(|error| coolbot::Fault::message(format!("no answer at `x`: {error}")))?;
        Ok(value * 2)
    }
}

fn doubler_registry() -> Registry {
    let mut registry = Registry::new();
    pull_doubler::register(&mut registry, |name| pull_doubler::component(name, Twice));
    registry
}

/// `Counter`'s behaviour: answers each pull with the next number.
struct Counting(u64);

impl counter::Behavior for Counting {
    fn answer_n(&mut self, _cx: &mut counter::Cx<'_>) -> Result<u64, coolbot::Fault> {
        self.0 += 1;
        Ok(self.0 - 1)
    }
}

/// `Asker`'s behaviour: hands its pull input to the test when it starts.
struct HandAsker(Sender<LastIn<u64>>);

impl asker::Behavior for HandAsker {
    fn start(&mut self, cx: &mut asker::Cx<'_>) -> SectionResult {
        let _ = self.0.send(cx.inputs.asked.clone());
        Ok(())
    }
}

/// The parts of `PullCell` and `NestCell`: a producer `source` whose pull output `n`
/// answers each pull with the next number from `first`, and a consumer `sink` whose
/// pull input `asked` it hands to the test.
struct PullParts {
    first: u64,
    asked: Sender<LastIn<u64>>,
}

/// `PullParts` from `first`, and where the sink's input arrives.
fn pull_ends(first: u64) -> (PullParts, Receiver<LastIn<u64>>) {
    let (asked, input) = crossbeam_channel::bounded(1);
    (PullParts { first, asked }, input)
}

impl pull_cell::Parts for PullParts {
    fn supervisor(&mut self) -> impl pull_cell::Supervisor {
        Quiet
    }
    fn source(&mut self) -> impl counter::Behavior {
        Counting(self.first)
    }
    fn doubler(&mut self) -> impl pull_doubler::Behavior {
        Twice
    }
    fn sink(&mut self) -> impl asker::Behavior {
        HandAsker(self.asked.clone())
    }
}

impl nest_cell::Parts for PullParts {
    fn supervisor(&mut self) -> impl nest_cell::Supervisor {
        Quiet
    }
    fn source(&mut self) -> impl counter::Behavior {
        Counting(self.first)
    }
    fn twice(&mut self) -> impl doubling::Parts {
        DoublingParts
    }
    fn sink(&mut self) -> impl asker::Behavior {
        HandAsker(self.asked.clone())
    }
}

/// Pull through a proxy, both ways in one request: a consumer here pulls the remote
/// `Doubler`'s pull output; to answer, the `Doubler` on the station pulls its pull
/// input, which the proxy serves by pulling from the producer here.
#[test]
fn a_pull_crosses_the_network_through_a_proxy_both_ways() {
    let placed = placed("pull-station", "pull-robot", doubler_registry);
    let station = &placed.station;

    // The producer answers each pull with the next number: 21, 22, ...
    let (parts, asked) = pull_ends(21);
    let compound = pull_cell::component("cell", parts).expect("the compound builds");
    let mut system = System::new();
    let cell = system.add(compound).unwrap();
    system.run_all().unwrap();
    cell.wait_for(|m| m.state == State::Running, PATIENCE)
        .unwrap_or_else(|timeout| panic!("{timeout}"));
    let asked = handed(&asked, "the sink");
    for expected in [42, 44, 46] {
        assert_eq!(asked.pull(PATIENCE), Ok(expected));
    }
    // It was the station's instance that answered.
    let ctl = coolbot_zenoh::ctl::Ctl::new(station.session().clone(), PATIENCE);
    let built = ctl
        .components(Some("pull-station"))
        .expect("the station lists");
    assert!(
        built.iter().any(|l| l.path.starts_with(&format!(
            "{}cell-doubler-",
            coolbot_zenoh::keys::namespace("pull-robot")
        ))),
        "{:?}",
        built.iter().map(|l| &l.path).collect::<Vec<_>>()
    );
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

/// `Doubling`'s parts: a `PullDoubler` that doubles.
struct DoublingParts;

impl doubling::Parts for DoublingParts {
    fn supervisor(&mut self) -> impl doubling::Supervisor {
        Quiet
    }
    fn doubler(&mut self) -> impl pull_doubler::Behavior {
        Twice
    }
}

fn doubling_registry() -> Registry {
    let mut registry = doubler_registry();
    doubling::register(&mut registry, |name| {
        doubling::component(name, DoublingParts)
    });
    registry
}

/// A compound on another node: the station builds the whole `Doubling` (its
/// supervisor and its `Doubler`), the proxy here stands for it with its exported
/// ports, mirrors its supervisor's state, and a pull crosses it both ways.
#[test]
fn a_compound_runs_on_another_node_behind_a_proxy() {
    let placed = placed("nest-station", "nest-robot", doubling_registry);
    let station = &placed.station;

    let (parts, asked) = pull_ends(5);
    let compound = nest_cell::component("cell", parts).expect("the compound builds");
    let mut system = System::new();
    let cell = system.add(compound).unwrap();
    system.run_all().unwrap();
    let twice = cell.instance("twice").expect("the proxy");
    twice
        .wait_for(|m| m.user_state.as_deref() == Some("doubling"), PATIENCE)
        .unwrap_or_else(|timeout| panic!("the remote supervisor's state: {timeout}"));
    let asked = handed(&asked, "the sink");
    for expected in [10, 12, 14] {
        assert_eq!(asked.pull(PATIENCE), Ok(expected));
    }
    // The station built the compound, with its own instance.
    let ctl = coolbot_zenoh::ctl::Ctl::new(station.session().clone(), PATIENCE);
    let built: Vec<String> = ctl
        .components(Some("nest-station"))
        .expect("the station lists")
        .into_iter()
        .map(|l| l.path)
        .collect();
    assert!(
        built.iter().any(|path| path.starts_with(&format!(
            "{}cell-twice-",
            coolbot_zenoh::keys::namespace("nest-robot")
        )) && path.ends_with(".doubler")),
        "{built:?}"
    );
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

/// `Tuned`'s behaviour: nothing each period.
struct Idle;

impl tuned::Behavior for Idle {
    fn going_periodic(&mut self, _cx: &mut tuned::Cx<'_>) -> SectionResult {
        Ok(())
    }
}

/// `TunedCell`'s parts.
struct TunedParts;

impl tuned_cell::Parts for TunedParts {
    fn supervisor(&mut self) -> impl tuned_cell::Supervisor {
        Quiet
    }
    fn tuned(&mut self) -> impl tuned::Behavior {
        Idle
    }
}

fn tuned_registry() -> Registry {
    let mut registry = Registry::new();
    tuned::register(&mut registry, |name| tuned::component(name, Idle));
    registry
}

/// An instance's own quality levels and adaptation settings travel with it: the
/// station builds the `Tuned` with three levels (its type has two) and adaptation
/// off (its type's period interval would turn it on), at its own period.
#[test]
fn a_remote_instance_keeps_its_own_quality_levels_and_adaptation() {
    let placed = placed("tuned-station", "tuned-robot", tuned_registry);
    let station = &placed.station;

    let compound = tuned_cell::component("cell", TunedParts).expect("the compound builds");
    let mut system = System::new();
    let cell = system.add(compound).unwrap();
    system.run_all().unwrap();
    let tuned = cell.instance("tuned").expect("the proxy");
    tuned
        .wait_for(|m| m.state == State::Running, PATIENCE)
        .unwrap_or_else(|timeout| panic!("{timeout}"));
    // The station's instance, as the station publishes it.
    let ctl = coolbot_zenoh::ctl::Ctl::new(station.session().clone(), PATIENCE);
    let remote = || {
        ctl.components(Some("tuned-station"))
            .expect("the station lists")
            .into_iter()
            .find(|l| {
                l.path.starts_with(&format!(
                    "{}cell-tuned-",
                    coolbot_zenoh::keys::namespace("tuned-robot")
                ))
            })
            .expect("the station built the instance")
    };
    let built = remote();
    assert_eq!(built.monitor.period, Some(Duration::from_millis(20)));
    assert!(
        !built.monitor.adaptation.enabled,
        "the instance's `adaptation {{ off; }}`"
    );
    // Its third level exists on the station: the command goes through the proxy.
    tuned
        .command(coolbot::Command::SetQuality(2))
        .expect("the station's instance has three levels");
    assert!(
        wait_until(PATIENCE, || remote().monitor.quality == 2),
        "the station's instance at its third level"
    );
    // Its response bound and priority, set through the proxy, show on the proxy's
    // monitoring port as the station's instance publishes them (rules read them).
    tuned
        .command(coolbot::Command::SetMaxResponse(Duration::from_millis(25)))
        .unwrap();
    tuned.command(coolbot::Command::SetPriority(-1)).unwrap();
    tuned
        .wait_for(
            |m| m.max_response == Some(Duration::from_millis(25)) && m.priority == -1,
            PATIENCE,
        )
        .unwrap_or_else(|timeout| panic!("the proxy mirrors them: {timeout}"));
    let built = remote();
    assert_eq!(built.monitor.max_response, Some(Duration::from_millis(25)));
    assert_eq!(built.monitor.priority, -1);
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

/// `Flaky`'s behaviour: the first period after `fail` is set fails (and clears it).
struct Flakiness;

impl flaky::Behavior for Flakiness {
    fn going_periodic(&mut self, cx: &mut flaky::Cx<'_>) -> SectionResult {
        if cx.vars.fail {
            cx.vars.fail = false;
            return Err(coolbot::Fault::message("told to fail"));
        }
        cx.vars.periods += 1;
        Ok(())
    }
}

struct RestartParts;

impl restart_cell::Parts for RestartParts {
    fn supervisor(&mut self) -> impl restart_cell::Supervisor {
        Quiet
    }
    fn flaky(&mut self) -> impl flaky::Behavior {
        Flakiness
    }
}

fn flaky_registry() -> Registry {
    let mut registry = Registry::new();
    flaky::register(&mut registry, |name| flaky::component(name, Flakiness));
    registry
}

/// `on error flaky: restart;` for an instance on another node: the remote instance
/// fails (a command through the proxy tells it to), the proxy goes to
/// `running_error`, and the compound's restart commands it back to `running` in
/// place, on its node, as it would a local instance.
#[test]
fn a_remote_instance_that_fails_is_restarted_on_its_node() {
    let placed = placed("restart-station", "restart-robot", flaky_registry);
    let station = &placed.station;

    let compound = restart_cell::component("cell", RestartParts).expect("the compound builds");
    let mut system = System::new();
    let cell = system.add(compound).unwrap();
    system.run_all().unwrap();
    let flaky = cell.instance("flaky").expect("the proxy");
    let periods = |m: &coolbot::Monitor| {
        m.variables
            .iter()
            .find(|(name, _)| name == "periods")
            .map_or(0, |(_, value)| match value {
                coolbot::Value::UInt(n) => *n,
                _ => 0,
            })
    };
    flaky
        .wait_for(|m| m.state == State::Running && periods(m) > 0, PATIENCE)
        .unwrap_or_else(|timeout| panic!("the remote instance runs: {timeout}"));
    let ctl = coolbot_zenoh::ctl::Ctl::new(station.session().clone(), PATIENCE);
    let built = || -> Vec<(String, State)> {
        ctl.components(Some("restart-station"))
            .expect("the station lists")
            .into_iter()
            .filter(|l| {
                l.path.starts_with(&format!(
                    "{}cell-flaky-",
                    coolbot_zenoh::keys::namespace("restart-robot")
                ))
            })
            .map(|l| (l.path, l.monitor.state))
            .collect()
    };
    let first = built();
    assert_eq!(first.len(), 1, "{first:?}");

    let before = periods(&flaky.snapshot());
    flaky
        .command(coolbot::Command::Set(
            "fail".to_owned(),
            coolbot::Value::Bool(true),
        ))
        .expect("the proxy forwards the command");
    let restarted = cell
        .wait_for(
            |m| {
                m.supervision
                    .iter()
                    .any(|step| step.instance == "flaky" && step.step == coolbot::Step::Restarted)
            },
            PATIENCE,
        )
        .unwrap_or_else(|timeout| panic!("the compound restarts the instance: {timeout}"));
    assert_eq!(restarted.state, State::Running);
    assert!(
        restarted
            .supervision
            .iter()
            .any(|step| step.instance == "flaky"
                && step.step == coolbot::Step::Failed
                && step.detail.contains("told to fail")),
        "the remote fault, with its reason: {:?}",
        restarted.supervision
    );
    // Running again, in place: the same instance on the station counts on.
    flaky
        .wait_for(
            |m| m.state == State::Running && periods(m) > before + 5,
            PATIENCE,
        )
        .unwrap_or_else(|timeout| panic!("the instance runs again: {timeout}"));
    let again = built();
    assert_eq!(again.len(), 1, "{again:?}");
    assert_eq!(again[0].0, first[0].0, "restarted in place");
    assert_eq!(cell.state(), State::Running);
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

impl ignore_cell::Parts for RestartParts {
    fn supervisor(&mut self) -> impl ignore_cell::Supervisor {
        Quiet
    }
    fn flaky(&mut self) -> impl flaky::Behavior {
        Flakiness
    }
}

/// `on error flaky: ignore;` for an instance on another node: the remote instance
/// fails, its proxy shows `running_error` with the remote reason, and the compound
/// records the step and runs on without touching it.
#[test]
fn a_remote_instance_whose_failure_is_ignored_stays_failed_and_the_compound_runs_on() {
    let _placed = placed("ignore-station", "ignore-robot", flaky_registry);

    let compound = ignore_cell::component("cell", RestartParts).expect("the compound builds");
    let mut system = System::new();
    let cell = system.add(compound).unwrap();
    system.run_all().unwrap();
    let flaky = cell.instance("flaky").expect("the proxy");
    flaky
        .wait_for(|m| m.state == State::Running, PATIENCE)
        .unwrap_or_else(|timeout| panic!("{timeout}"));
    flaky
        .command(coolbot::Command::Set(
            "fail".to_owned(),
            coolbot::Value::Bool(true),
        ))
        .expect("the proxy forwards the command");
    let ignored = cell
        .wait_for(
            |m| {
                m.supervision
                    .iter()
                    .any(|step| step.instance == "flaky" && step.step == coolbot::Step::Ignored)
            },
            PATIENCE,
        )
        .unwrap_or_else(|timeout| panic!("the compound ignores the failure: {timeout}"));
    assert_eq!(ignored.state, State::Running);
    let failed = flaky.snapshot();
    assert_eq!(failed.state, State::RunningError);
    assert!(
        failed
            .error
            .as_deref()
            .unwrap_or("")
            .contains("told to fail"),
        "{:?}",
        failed.error
    );
    assert!(
        !cell
            .snapshot()
            .supervision
            .iter()
            .any(|step| step.instance == "flaky" && step.step == coolbot::Step::Restarted),
        "ignored, not restarted"
    );
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

/// `PairRelay`'s behaviour: passes on what arrived; fails while `fail` is set.
struct Relaying;

impl pair_relay::Behavior for Relaying {
    fn relaying_entry(&mut self, cx: &mut pair_relay::Cx<'_>) -> SectionResult {
        if cx.vars.fail {
            return Err(coolbot::Fault::message("told to fail"));
        }
        for value in cx.inputs.input.drain() {
            cx.outputs.output.send(value);
        }
        Ok(())
    }
}

struct HandPairSource(Sender<DataOut<u64>>);

impl pair_source::Behavior for HandPairSource {
    fn start(&mut self, cx: &mut pair_source::Cx<'_>) -> SectionResult {
        let _ = self.0.send(cx.outputs.out.clone());
        Ok(())
    }
}

struct HandPairSink(Sender<UfifoIn<u64>>);

impl pair_sink::Behavior for HandPairSink {
    fn start(&mut self, cx: &mut pair_sink::Cx<'_>) -> SectionResult {
        let _ = self.0.send(cx.inputs.inbox.clone());
        Ok(())
    }
}

struct PairParts {
    source: Sender<DataOut<u64>>,
    sink: Sender<UfifoIn<u64>>,
}

impl remote_pair::Parts for PairParts {
    fn supervisor(&mut self) -> impl remote_pair::Supervisor {
        Quiet
    }
    fn source(&mut self) -> impl pair_source::Behavior {
        HandPairSource(self.source.clone())
    }
    fn a(&mut self) -> impl pair_relay::Behavior {
        Relaying
    }
    fn b(&mut self) -> impl pair_relay::Behavior {
        Relaying
    }
    fn sink(&mut self) -> impl pair_sink::Behavior {
        HandPairSink(self.sink.clone())
    }
}

impl remote_lead_pair::Parts for PairParts {
    fn supervisor(&mut self) -> impl remote_lead_pair::Supervisor {
        Quiet
    }
    fn source(&mut self) -> impl pair_source::Behavior {
        HandPairSource(self.source.clone())
    }
    fn a(&mut self) -> impl pair_relay::Behavior {
        Relaying
    }
    fn b(&mut self) -> impl pair_relay::Behavior {
        Relaying
    }
    fn sink(&mut self) -> impl pair_sink::Behavior {
        HandPairSink(self.sink.clone())
    }
}

fn relay_registry() -> Registry {
    let mut registry = Registry::new();
    pair_relay::register(&mut registry, |name| pair_relay::component(name, Relaying));
    registry
}

/// A redundant group with one member on another node: both members get every
/// packet (the remote one through its proxy), the sink reads one stream; when the
/// leader fails, the other member continues it with no packet missing or doubled.
/// `station` is the node the compound places `b` on; `failing`, the leader.
fn one_stream_across_a_failover(
    station: &str,
    build: impl FnOnce(PairParts) -> coolbot::Component,
    failing: &str,
) {
    let _placed = placed(station, &format!("{station}-robot"), relay_registry);

    let (source, sources) = crossbeam_channel::unbounded();
    let (sink, sinks) = crossbeam_channel::unbounded();
    let mut system = System::new();
    let pair = system.add(build(PairParts { source, sink })).unwrap();
    system.run_all().unwrap();
    let out = handed(&sources, "the source");
    let inbox = handed(&sinks, "the sink");
    let (a, b) = (
        pair.instance("a").expect("a"),
        pair.instance("b").expect("the proxy"),
    );
    for member in [&a, &b] {
        member
            .wait_for(|m| m.state == State::Running, PATIENCE)
            .unwrap_or_else(|timeout| panic!("{timeout}"));
    }
    let mut seen = Vec::new();
    let read_until = |count: usize, seen: &mut Vec<u64>| {
        wait_until(PATIENCE, || {
            seen.extend(inbox.drain());
            seen.len() >= count
        })
    };
    for n in 1..=50 {
        out.send(n);
    }
    assert!(read_until(50, &mut seen), "the first 50: {seen:?}");
    // The leader fails at its next packet: the other member leads on.
    let (leader, other) = if failing == "a" { (&a, &b) } else { (&b, &a) };
    leader
        .command(coolbot::Command::Set(
            "fail".to_owned(),
            coolbot::Value::Bool(true),
        ))
        .unwrap();
    for n in 51..=100 {
        out.send(n);
    }
    leader
        .wait_for(|m| m.state == State::RunningError, PATIENCE)
        .unwrap_or_else(|timeout| panic!("{timeout}"));
    assert!(read_until(100, &mut seen), "all 100: {seen:?}");
    // It was the leader: the other member took its place.
    let took_over = |m: &coolbot::Monitor| {
        m.supervision.iter().any(|step| {
            step.instance == failing
                && matches!(&step.step, coolbot::Step::Substituted { by } if by != failing)
        })
    };
    pair.wait_for(took_over, PATIENCE)
        .unwrap_or_else(|timeout| panic!("the other member leads: {timeout}"));
    assert_eq!(pair.state(), State::Running);
    assert_eq!(other.state(), State::Running);
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
    // Stopped: anything that came after the hundredth is in the sink's queue now.
    seen.extend(inbox.drain());
    assert_eq!(
        seen,
        (1..=100).collect::<Vec<u64>>(),
        "one stream, none missing or doubled"
    );
}

#[test]
fn a_redundant_group_keeps_one_stream_when_its_local_leader_fails_and_the_remote_member_leads_on() {
    one_stream_across_a_failover(
        "pair-station",
        |parts| remote_pair::component("pair", parts).expect("the compound builds"),
        "a",
    );
}

#[test]
fn a_redundant_group_keeps_one_stream_when_its_remote_leader_fails_and_the_local_member_leads_on() {
    one_stream_across_a_failover(
        "lead-station",
        |parts| remote_lead_pair::component("pair", parts).expect("the compound builds"),
        "b",
    );
}

/// Start the station process `name` (`station-under-test`), connected to
/// `endpoint`; it has printed `ready` and `robot` sees its node.
fn station_process(name: &str, endpoint: &str, robot: &coolbot_zenoh::Node) -> NodeProcess {
    NodeProcess::start(
        env!("CARGO_BIN_EXE_station-under-test"),
        &[name, endpoint],
        name,
        robot,
    )
}

/// Every connection kind, and pull both ways, between three OS processes: this one
/// (the robot: the compounds, their sources and sinks, the proxies) and two station
/// processes (`station-under-test`) whose agents build the relay and the doubler.
/// The relay there forwards each input to the output of its kind, so what the source
/// here sends comes back to the sink here through the station.
#[test]
fn every_connection_kind_crosses_between_os_processes() {
    let (robot, endpoint) = coolbot_zenoh_tests::support::node("robot", &[]);
    let robot = Arc::new(robot);
    let _station = station_process("station", &endpoint, &robot);
    let _pull_station = station_process("pull-station", &endpoint, &robot);
    let mut types = registry(crossbeam_channel::bounded(1).0);
    pull_doubler::register(&mut types, |name| pull_doubler::component(name, Twice));
    let _placer = Placer::new(Arc::clone(&robot), types).install();

    let (source, sources) = crossbeam_channel::bounded(1);
    let (sink, sinks) = crossbeam_channel::bounded(1);
    let (parts, asked) = pull_ends(21);
    let mut system = System::new();
    let cell = system
        .add(cell::component("cell", CellParts { source, sink }).expect("builds"))
        .expect("added");
    let pull = system
        .add(pull_cell::component("pull", parts).expect("builds"))
        .expect("added");
    system.run_all().expect("runs");
    for (compound, instance) in [(&cell, "relay"), (&pull, "doubler")] {
        compound
            .instance(instance)
            .expect("a proxy")
            .wait_for(|m| m.state == State::Running, PATIENCE)
            .unwrap_or_else(|timeout| panic!("{instance}: {timeout}"));
    }
    let SourcePorts { t, d, p } = handed(&sources, "the source");
    let SinkPorts { ti, fi, li, pi } = handed(&sinks, "the sink");

    // Out to the station's relay and back: a poster, ticks, and data into a last, a
    // fifo and a ufifo input, which come back tagged by the input they went through.
    p.post(42);
    for _ in 0..3 {
        t.emit();
    }
    for n in 1..=5 {
        d.send(n);
    }
    let (mut ticks, mut through) = (0, [Vec::new(), Vec::new(), Vec::new()]);
    let arrived = wait_until(PATIENCE, || {
        ticks += ti.take();
        for value in fi.drain() {
            through[(value % 10 - 1) as usize].push(value / 10);
        }
        ticks == 3
            && through[0].last() == Some(&5)
            && through[1] == [1, 2, 3, 4, 5]
            && through[2] == [1, 2, 3, 4, 5]
            && li.latest().is_some()
            && pi.read() == Some(42)
    });
    assert!(
        arrived,
        "back here: ticks {ticks}, through last/fifo/ufifo {through:?}, last {:?}, poster {:?}",
        li.latest(),
        pi.read()
    );
    // Pull, both ways in one request: the sink pulls the doubler on `pull-station`,
    // which pulls the counter here.
    let asked = handed(&asked, "the asker");
    for expected in [42, 44, 46] {
        assert_eq!(asked.pull(PATIENCE), Ok(expected));
    }
    assert_eq!(cell.instance("relay").unwrap().snapshot().overflows, 0);
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}
