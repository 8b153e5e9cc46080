//! Remote instances from the description (`coolbot_zenoh::place`): a compound's
//! instance declared on another node runs there behind a proxy, and every connection
//! kind crosses the network through the proxy's ports, both ways: tick, last, fifo,
//! ufifo and poster inputs; tick, data and poster outputs (a poster's value reaches a
//! reader that joins late); and pull, both ways in one request.

mod support;

use std::sync::{Arc, Mutex};

use coolbot::port::{DataOut, FifoIn, LastIn, PosterIn, PosterOut, TickIn, TickOut, UfifoIn};
use coolbot::{
    CompoundBuilder, InputKind, InputSpec, MonitorEvent, OutputKind, OutputSpec, OverflowPolicy,
    PortSet, State, System,
};
use coolbot_zenoh::Placer;
use coolbot_zenoh::agent::{Agent, Registry};
use zenoh::Wait;

use support::{PATIENCE, Shell, pair, spec, supervisor, wait_until};

fn input(name: &'static str, kind: InputKind) -> InputSpec {
    InputSpec {
        name,
        kind,
        packet: "u64",
        pull: false,
    }
}

fn output(name: &'static str, kind: OutputKind) -> OutputSpec {
    OutputSpec {
        name,
        kind,
        packet: "u64",
        pull: false,
    }
}

const FIFO: InputKind = InputKind::Fifo {
    capacity: 16,
    policy: OverflowPolicy::Reject,
};
const UFIFO: InputKind = InputKind::Ufifo {
    initial: 4,
    max: None,
};

/// The ports of the instance built on the station, for the test to drive.
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

/// `Relay`: one input of each kind and one output of each kind.
fn relay(name: &str, built: &Mutex<Option<RelayPorts>>) -> coolbot::Component {
    let shape = spec(
        "Relay",
        vec![
            input("ti", InputKind::Tick),
            input("li", InputKind::Last),
            input("fi", FIFO),
            input("ui", UFIFO),
            input("pi", InputKind::Poster),
        ],
        vec![
            output("to", OutputKind::Tick),
            output("out", OutputKind::Data),
            output("po", OutputKind::Poster),
        ],
        vec![],
    );
    let ports = RelayPorts {
        ti: TickIn::new(),
        li: LastIn::new(),
        fi: FifoIn::new(16, OverflowPolicy::Reject),
        ui: UfifoIn::new(4, None),
        pi: PosterIn::new(),
        to: TickOut::new(),
        out: DataOut::new(),
        po: PosterOut::new(),
    };
    let set = PortSet::new()
        .input(&ports.ti)
        .input(&ports.li)
        .input(&ports.fi)
        .input(&ports.ui)
        .input(&ports.pi)
        .output(&ports.to)
        .output(&ports.out)
        .output(&ports.po);
    *built.lock().unwrap() = Some(ports);
    Shell::component(name, shape, set)
}

fn registry(built: &Arc<Mutex<Option<RelayPorts>>>) -> Registry {
    let mut registry = Registry::new();
    let built = Arc::clone(built);
    registry
        .register("Relay", move |name| relay(name, &built))
        .port::<()>("ti")
        .port::<u64>("li")
        .port::<u64>("fi")
        .port::<u64>("ui")
        .port::<u64>("pi")
        .port::<()>("to")
        .port::<u64>("out")
        .port::<u64>("po");
    registry
}

#[test]
fn every_connection_kind_crosses_the_network_through_a_proxy_both_ways() {
    let (station, robot) = pair("station", "robot");
    let station = Arc::new(station);
    let robot = Arc::new(robot);
    let remote_ports = Arc::new(Mutex::new(None));
    let _agent = Agent::start(Arc::clone(&station), registry(&remote_ports)).expect("agent");
    let _placer = Placer::new(Arc::clone(&robot), registry(&Arc::new(Mutex::new(None)))).install();

    // Local producers and consumers around the remote relay.
    let src_t = TickOut::new();
    let src_d = DataOut::<u64>::new();
    let src_p = PosterOut::<u64>::new();
    let source = Shell::component(
        "source",
        spec(
            "Source",
            vec![],
            vec![
                output("t", OutputKind::Tick),
                output("d", OutputKind::Data),
                output("p", OutputKind::Poster),
            ],
            vec![],
        ),
        PortSet::new().output(&src_t).output(&src_d).output(&src_p),
    );
    let dst_ti = TickIn::new();
    let dst_fi = FifoIn::<u64>::new(16, OverflowPolicy::Reject);
    let dst_li = LastIn::<u64>::new();
    let dst_pi = PosterIn::<u64>::new();
    let sink = Shell::component(
        "sink",
        spec(
            "Sink",
            vec![
                input("ti", InputKind::Tick),
                input("fi", FIFO),
                input("li", InputKind::Last),
                input("pi", InputKind::Poster),
            ],
            vec![],
            vec![],
        ),
        PortSet::new()
            .input(&dst_ti)
            .input(&dst_fi)
            .input(&dst_li)
            .input(&dst_pi),
    );
    let local_relay = relay("relay", &Mutex::new(None));
    let compound = CompoundBuilder::new("cell", supervisor("working"))
        .instance(source)
        .instance_on("station", local_relay)
        .instance(sink)
        .connect("source.t", "relay.ti")
        .connect("source.d", "relay.li")
        .connect("source.d", "relay.fi")
        .connect("source.d", "relay.ui")
        .connect("source.p", "relay.pi")
        .connect("relay.to", "sink.ti")
        .connect("relay.out", "sink.fi")
        .connect("relay.out", "sink.li")
        .connect("relay.po", "sink.pi")
        .build()
        .expect("the compound builds");
    let mut system = System::new();
    let cell = system.add(compound).expect("added");
    system.run_all().expect("runs");
    let proxy = cell.instance("relay").expect("the relay's proxy");
    proxy
        .wait_for(|m| m.state == State::Running, PATIENCE)
        .expect("the proxy runs");
    let remote = remote_ports
        .lock()
        .unwrap()
        .clone()
        .expect("the agent built the relay on the station");

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
        .command(coolbot::Command::SetPeriod(
            std::time::Duration::from_millis(25),
        ))
        .expect("the period is forwarded");
    assert!(
        wait_until(PATIENCE, || proxy.snapshot().period
            == Some(std::time::Duration::from_millis(25))),
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
            .contains(&("network".to_owned(), 1))),
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
    assert_eq!(at("network"), (1, Some(1)), "{announced:?}");
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

fn pulled_input(name: &'static str, kind: InputKind) -> InputSpec {
    InputSpec {
        pull: true,
        ..input(name, kind)
    }
}

fn pulled_output(name: &'static str) -> OutputSpec {
    OutputSpec {
        pull: true,
        ..output(name, OutputKind::Data)
    }
}

/// `Doubler`: a pull output `y` whose answer pulls its pull input `x` and sends twice
/// the value.
fn doubler(name: &str) -> coolbot::Component {
    let shape = spec(
        "Doubler",
        vec![pulled_input("x", InputKind::Last)],
        vec![pulled_output("y")],
        vec![],
    );
    let x = LastIn::<u64>::new();
    let y = DataOut::<u64>::new();
    let ports = PortSet::new().input(&x).output(&y);
    let (x, answer_y) = (x.clone(), y.clone());
    Shell::with_answer(
        name,
        shape,
        ports,
        Some(Box::new(move |_| {
            if let Ok(value) = x.pull(std::time::Duration::from_secs(5)) {
                answer_y.send(value * 2);
            }
        })),
    )
}

fn doubler_registry() -> Registry {
    let mut registry = Registry::new();
    registry
        .register("Doubler", doubler)
        .port::<u64>("x")
        .port::<u64>("y");
    registry
}

/// A producer `source` whose pull output `n` answers each pull with the next number
/// from `first`, and a consumer `sink` with a pull input `asked` (returned, to pull).
fn pull_ends(first: u64) -> (coolbot::Component, coolbot::Component, LastIn<u64>) {
    let numbers = DataOut::<u64>::new();
    let next = std::sync::atomic::AtomicU64::new(first);
    let answer = numbers.clone();
    let source = Shell::with_answer(
        "source",
        spec("Source", vec![], vec![pulled_output("n")], vec![]),
        PortSet::new().output(&numbers),
        Some(Box::new(move |_| {
            answer.send(next.fetch_add(1, std::sync::atomic::Ordering::SeqCst));
        })),
    );
    let asked = LastIn::<u64>::new();
    let sink = Shell::component(
        "sink",
        spec(
            "Sink",
            vec![pulled_input("asked", InputKind::Last)],
            vec![],
            vec![],
        ),
        PortSet::new().input(&asked),
    );
    (source, sink, asked)
}

/// Pull through a proxy, both ways in one request: a consumer here pulls the remote
/// `Doubler`'s pull output; to answer, the `Doubler` on the station pulls its pull
/// input, which the proxy serves by pulling from the producer here.
#[test]
fn a_pull_crosses_the_network_through_a_proxy_both_ways() {
    let (station, robot) = pair("pull-station", "pull-robot");
    let station = Arc::new(station);
    let robot = Arc::new(robot);
    let _agent = Agent::start(Arc::clone(&station), doubler_registry()).expect("agent");
    let _placer = Placer::new(Arc::clone(&robot), doubler_registry()).install();

    // The producer answers each pull with the next number: 21, 22, ...
    let (source, sink, asked) = pull_ends(21);
    let compound = CompoundBuilder::new("cell", supervisor("working"))
        .instance(source)
        .instance_on("pull-station", doubler("doubler"))
        .instance(sink)
        .connect("source.n", "doubler.x")
        .connect("doubler.y", "sink.asked")
        .build()
        .expect("the compound builds");
    let mut system = System::new();
    let cell = system.add(compound).unwrap();
    system.run_all().unwrap();
    cell.wait_for(|m| m.state == State::Running, PATIENCE)
        .unwrap_or_else(|timeout| panic!("{timeout}"));
    for expected in [42, 44, 46] {
        assert_eq!(asked.pull(PATIENCE), Ok(expected));
    }
    // It was the station's instance that answered.
    let ctl = coolbot_zenoh::ctl::Ctl::new(station.session().clone(), PATIENCE);
    let built = ctl
        .components(Some("pull-station"))
        .expect("the station lists");
    assert!(
        built
            .iter()
            .any(|l| l.path.starts_with("pull-robot-cell-doubler-")),
        "{:?}",
        built.iter().map(|l| &l.path).collect::<Vec<_>>()
    );
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

/// `Doubling`: a compound around a `Doubler`, exporting its pull input and output.
fn doubling(name: &str) -> Result<coolbot::Component, String> {
    CompoundBuilder::new(name, support::supervisor_of("Doubling", "doubling"))
        .instance(doubler("doubler"))
        .export_input::<u64>("x", "doubler.x")
        .export_output::<u64>("y", "doubler.y")
        .build()
        .map_err(|error| error.to_string())
}

fn doubling_registry() -> Registry {
    use coolbot::remote::Registrar;
    let mut registry = doubler_registry();
    registry.compound("Doubling", Box::new(doubling));
    registry.port::<u64>("Doubling", "x");
    registry.port::<u64>("Doubling", "y");
    registry
}

/// A compound on another node: the station builds the whole `Doubling` (its
/// supervisor and its `Doubler`), the proxy here stands for it with its exported
/// ports, mirrors its supervisor's state, and a pull crosses it both ways.
#[test]
fn a_compound_runs_on_another_node_behind_a_proxy() {
    let (station, robot) = pair("nest-station", "nest-robot");
    let station = Arc::new(station);
    let robot = Arc::new(robot);
    let _agent = Agent::start(Arc::clone(&station), doubling_registry()).expect("agent");
    let _placer = Placer::new(Arc::clone(&robot), doubling_registry()).install();

    let (source, sink, asked) = pull_ends(5);
    let local = doubling("twice").expect("the compound builds here too");
    let compound = CompoundBuilder::new("cell", supervisor("working"))
        .instance(source)
        .instance_on("nest-station", local)
        .instance(sink)
        .connect("source.n", "twice.x")
        .connect("twice.y", "sink.asked")
        .build()
        .expect("the compound builds");
    let mut system = System::new();
    let cell = system.add(compound).unwrap();
    system.run_all().unwrap();
    let twice = cell.instance("twice").expect("the proxy");
    twice
        .wait_for(|m| m.user_state.as_deref() == Some("doubling"), PATIENCE)
        .unwrap_or_else(|timeout| panic!("the remote supervisor's state: {timeout}"));
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
        built
            .iter()
            .any(|path| path.starts_with("nest-robot-cell-twice-") && path.ends_with(".doubler")),
        "{built:?}"
    );
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}
