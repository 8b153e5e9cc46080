//! A compound's exported ports behave as an atomic component's: for every port kind
//! (tick, fifo, ufifo, last and poster inputs; tick, data and poster outputs), pushed
//! and pulled, the same scenario runs once against an atomic component's port and
//! once against a compound exporting that port of the same component, and must see
//! the same packets. Then the same through a substitution and through a redundant
//! group's failover: the exported ports follow the stand-in, pulls included.
//!
//! Only the pulled tick ports are here, on hand-made components: the language does
//! not let a tick output be `pull` (`coolc::check::connect_kind`), so no generated
//! component has one (and none can feed a pulled tick input), though the runtime
//! answers a pull of a tick output with an event. Every other kind is in
//! `tests/runtime/tests/exports.rs`, on generated components.

mod support;

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use coolbot::port::{DataOut, FifoIn, LastIn, PosterIn, PosterOut, TickIn, TickOut, UfifoIn};
use coolbot::{
    Component, CompoundBuilder, Fault, InputKind, OutputKind, OverflowPolicy, Policy, Step, System,
};
use support::shell::{Idle, ShellBuilder, input, output};
use support::{WAIT, eventually};

/// The input kinds, as the port under test or as the outside consumer of an output.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[expect(
    dead_code,
    reason = "the scenario handles every kind; only the pulled tick ones run here"
)]
enum In {
    Fifo,
    Ufifo,
    Last,
    Poster,
    Tick,
}

/// The output kinds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Out {
    Data,
    Poster,
    Tick,
}

/// One input handle of packets `u64` (or events).
#[derive(Clone)]
enum Input {
    Fifo(FifoIn<u64>),
    Ufifo(UfifoIn<u64>),
    Last(LastIn<u64>),
    Poster(PosterIn<u64>),
    Tick(TickIn),
}

impl Input {
    fn new(kind: In) -> Input {
        match kind {
            In::Fifo => Input::Fifo(FifoIn::new(8, OverflowPolicy::Reject)),
            In::Ufifo => Input::Ufifo(UfifoIn::new(2, None)),
            In::Last => Input::Last(LastIn::new()),
            In::Poster => Input::Poster(PosterIn::new()),
            In::Tick => Input::Tick(TickIn::new()),
        }
    }

    fn kind(&self) -> InputKind {
        match self {
            Input::Fifo(_) => InputKind::Fifo {
                capacity: 8,
                policy: OverflowPolicy::Reject,
            },
            Input::Ufifo(_) => InputKind::Ufifo {
                initial: 2,
                max: None,
            },
            Input::Last(_) => InputKind::Last,
            Input::Poster(_) => InputKind::Poster,
            Input::Tick(_) => InputKind::Tick,
        }
    }

    fn register(&self, shell: ShellBuilder, name: &'static str, pull: bool) -> ShellBuilder {
        let spec = input(name, self.kind(), pull);
        match self {
            Input::Fifo(port) => shell.input(spec, port),
            Input::Ufifo(port) => shell.input(spec, port),
            Input::Last(port) => shell.input(spec, port),
            Input::Poster(port) => shell.input(spec, port),
            Input::Tick(port) => shell.input(spec, port),
        }
    }

    /// What `pull` returns: the packet, or the events taken.
    fn pull(&self) -> u64 {
        match self {
            Input::Fifo(port) => port.pull(WAIT),
            Input::Ufifo(port) => port.pull(WAIT),
            Input::Last(port) => port.pull(WAIT),
            Input::Poster(port) => port.pull(WAIT),
            Input::Tick(port) => port.pull(WAIT),
        }
        .expect("the pull is answered")
    }

    /// Forget what arrived so far.
    fn clear(&self) {
        match self {
            Input::Fifo(port) => port.drain().for_each(drop),
            Input::Ufifo(port) => port.drain().for_each(drop),
            Input::Last(port) => _ = port.take_new(),
            Input::Poster(port) => _ = port.take_new(),
            Input::Tick(port) => _ = port.take(),
        }
    }

    /// Wait until `last` (the last of `count` packets or events sent) is seen; return
    /// what was seen: every packet of a queue, the latest of a last or poster input,
    /// the events of a tick input.
    fn observe(&self, count: u64, last: u64) -> Vec<u64> {
        let seen = std::sync::Mutex::new(Vec::new());
        eventually(
            || {
                let mut seen = seen.lock().unwrap();
                match self {
                    Input::Fifo(port) => seen.extend(port.drain()),
                    Input::Ufifo(port) => seen.extend(port.drain()),
                    Input::Last(port) => seen.extend(port.take_new()),
                    Input::Poster(port) => seen.extend(port.take_new()),
                    Input::Tick(port) => {
                        let events = port.take() + seen.pop().unwrap_or(0);
                        seen.push(events);
                    }
                }
                match self {
                    Input::Tick(_) => seen.last() == Some(&count),
                    _ => seen.last() == Some(&last),
                }
            },
            "the packets sent",
        );
        let mut seen = seen.into_inner().unwrap();
        if !matches!(self, Input::Fifo(_) | Input::Ufifo(_) | Input::Tick(_)) {
            // A last or poster input keeps the latest: what was seen before it
            // depends on timing, the latest does not.
            seen.drain(..seen.len() - 1);
        }
        seen
    }
}

/// One output handle of packets `u64` (or events).
#[derive(Clone)]
enum Output {
    Data(DataOut<u64>),
    Poster(PosterOut<u64>),
    Tick(TickOut),
}

impl Output {
    fn new(kind: Out) -> Output {
        match kind {
            Out::Data => Output::Data(DataOut::new()),
            Out::Poster => Output::Poster(PosterOut::new()),
            Out::Tick => Output::Tick(TickOut::new()),
        }
    }

    fn kind(&self) -> OutputKind {
        match self {
            Output::Data(_) => OutputKind::Data,
            Output::Poster(_) => OutputKind::Poster,
            Output::Tick(_) => OutputKind::Tick,
        }
    }

    fn register(&self, shell: ShellBuilder, name: &'static str, pull: bool) -> ShellBuilder {
        let spec = output(name, self.kind(), pull);
        match self {
            Output::Data(port) => shell.output(spec, port),
            Output::Poster(port) => shell.output(spec, port),
            Output::Tick(port) => shell.output(spec, port),
        }
    }

    fn produce(&self, n: u64) {
        match self {
            Output::Data(port) => port.send(n),
            Output::Poster(port) => port.post(n),
            Output::Tick(port) => port.emit(),
        }
    }
}

/// The output kind that feeds an input kind.
fn producer_of(kind: In) -> Out {
    match kind {
        In::Fifo | In::Ufifo | In::Last => Out::Data,
        In::Poster => Out::Poster,
        In::Tick => Out::Tick,
    }
}

/// The input kind that reads an output kind.
fn consumer_of(kind: Out) -> In {
    match kind {
        Out::Data => In::Fifo,
        Out::Poster => In::Poster,
        Out::Tick => In::Tick,
    }
}

/// The port under test: an input or an output of the component `w`.
#[derive(Debug, Clone, Copy)]
enum Port {
    In(In),
    Out(Out),
}

/// Where `w` is: added to the system itself, or inside compound `k`, which exports its
/// port `port` as `x`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Topology {
    Atomic,
    Exported,
}

/// What `w` and its stand-in look like: the port under test (`port`), a pull output
/// `trip` whose answer fails the component (to inject a fault), and the counter its
/// pull answers count with.
struct Member {
    component: Component,
    port: PortHandle,
}

#[derive(Clone)]
enum PortHandle {
    In(Input),
    Out(Output),
}

/// Build a component named `name` with the port under test (pulled or not).
fn member(name: &str, port: Port, pull: bool, answers: Arc<AtomicU64>) -> Member {
    let trip = DataOut::<u64>::new();
    let handle = match port {
        Port::In(kind) => PortHandle::In(Input::new(kind)),
        Port::Out(kind) => PortHandle::Out(Output::new(kind)),
    };
    let shell = ShellBuilder::new(name);
    let shell = match &handle {
        PortHandle::In(input) => input.register(shell, "port", pull),
        PortHandle::Out(output) => output.register(shell, "port", pull),
    };
    let answer_with = handle.clone();
    // `trip` comes after the port under test if that is an output.
    let trip_index = match port {
        Port::In(_) => 0,
        Port::Out(_) => 1,
    };
    let shell = shell
        .output(output("trip", OutputKind::Data, true), &trip)
        .answer(move |index| {
            if index == trip_index {
                return Err(Fault::message("tripped"));
            }
            let n = answers.fetch_add(1, Ordering::SeqCst) + 1;
            match &answer_with {
                PortHandle::Out(output) => output.produce(n),
                PortHandle::In(_) => return Err(Fault::message("an input does not answer")),
            }
            Ok(())
        });
    Member {
        component: shell.build(),
        port: handle,
    }
}

/// The system of one scenario: `w` (or `k` around `w`, with substitute `s` if
/// `substitute`) and the outside component `o` that feeds or reads the port.
struct Rig {
    system: System,
    /// The port under test at `w`, and at `s`.
    inner: PortHandle,
    standby: Option<PortHandle>,
    /// The outside end: a producer's output or a consumer's input.
    outer: PortHandle,
    /// `o`'s pull answers count from here.
    outer_answers: Arc<AtomicU64>,
    /// `w`'s (and `s`'s) pull answers.
    answers: Arc<AtomicU64>,
    /// The outside pull consumer of `trip` (to fail `w`).
    trip: LastIn<u64>,
}

/// Who stands by for `w` inside the compound.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Standby {
    None,
    /// `s` substitutes `w`.
    Substitute,
    /// `s` substitutes `w`, and `w` recovers soon after (it takes its place back).
    SubstituteThenRecover,
    /// `w` and `s` are a redundant group (`w` leads).
    Redundant,
}

fn rig(port: Port, pull: bool, topology: Topology, standby_by: Standby) -> Rig {
    let answers = Arc::new(AtomicU64::new(0));
    let w = member("w", port, pull, Arc::clone(&answers));
    let inner = w.port.clone();
    let outer_answers = Arc::new(AtomicU64::new(0));
    let outer = match port {
        Port::In(kind) => PortHandle::Out(Output::new(producer_of(kind))),
        Port::Out(kind) => PortHandle::In(Input::new(consumer_of(kind))),
    };
    let o = ShellBuilder::new("o");
    let o = match &outer {
        PortHandle::Out(output) => {
            let answer_with = output.clone();
            let counter = Arc::clone(&outer_answers);
            output.register(o, "end", pull).answer(move |_| {
                answer_with.produce(counter.fetch_add(1, Ordering::SeqCst) + 1);
                Ok(())
            })
        }
        PortHandle::In(input) => input.register(o, "end", pull),
    };
    let trip = LastIn::<u64>::new();
    let o = o.input(input("trip", InputKind::Last, true), &trip);
    let mut system = System::new();
    system.add(o.build()).expect("add o");
    let mut standby = None;
    let address = match topology {
        Topology::Atomic => {
            system.add(w.component).expect("add w");
            system.connect("w.trip", "o.trip").expect("trip");
            "w.port"
        }
        Topology::Exported => {
            let mut builder = CompoundBuilder::new("k", Idle).instance(w.component);
            if standby_by != Standby::None {
                let s = member("s", port, pull, Arc::clone(&answers));
                standby = Some(s.port.clone());
                let retry = match standby_by {
                    Standby::SubstituteThenRecover => std::time::Duration::from_millis(20),
                    _ => WAIT,
                };
                builder = builder.instance(s.component).recovery(retry, WAIT * 6);
                builder = match standby_by {
                    Standby::Redundant => builder.redundant(&["w", "s"]),
                    _ => builder
                        .substitute("s", "w")
                        .on_error("w", Policy::Substitute),
                };
            }
            builder = match port {
                Port::In(In::Tick) => builder.export_tick_input("x", "w.port"),
                Port::In(_) => builder.export_input::<u64>("x", "w.port"),
                Port::Out(Out::Tick) => builder.export_tick_output("x", "w.port"),
                Port::Out(_) => builder.export_output::<u64>("x", "w.port"),
            };
            let k = builder
                .export_output::<u64>("trip", "w.trip")
                .build()
                .expect("build k");
            system.add(k).expect("add k");
            system.connect("k.trip", "o.trip").expect("trip");
            "k.x"
        }
    };
    match port {
        Port::In(_) => system.connect("o.end", address),
        Port::Out(_) => system.connect(address, "o.end"),
    }
    .expect("connect the port under test");
    system.run_all().expect("run");
    Rig {
        system,
        inner,
        standby,
        outer,
        outer_answers,
        answers,
        trip,
    }
}

/// Run the scenario for `port` at `at` (the component behind the port now): push
/// three packets and see them arrive; with `pull`, also pull three. Returns what was
/// seen, in order.
fn scenario(rig: &Rig, at: &PortHandle, pull: bool, base: u64) -> Vec<u64> {
    scenario_with(rig, at, None, pull, base)
}

/// [`scenario`], where `twin` (a redundant member beside `at`, if given) sends what
/// `at` sends, as members on the same inputs do.
fn scenario_with(
    rig: &Rig,
    at: &PortHandle,
    twin: Option<&PortHandle>,
    pull: bool,
    base: u64,
) -> Vec<u64> {
    let mut seen = Vec::new();
    let (producer, consumer, answers) = match (at, &rig.outer) {
        (PortHandle::In(input), PortHandle::Out(output)) => (output, input, &rig.outer_answers),
        (PortHandle::Out(output), PortHandle::In(input)) => (output, input, &rig.answers),
        _ => unreachable!("an input faces an output"),
    };
    for n in base + 1..=base + 3 {
        if let Some(PortHandle::Out(twin)) = twin {
            twin.produce(n);
        }
        producer.produce(n);
    }
    seen.extend(consumer.observe(3, base + 3));
    if pull {
        let before = answers.load(Ordering::SeqCst);
        for _ in 0..3 {
            seen.push(consumer.pull());
        }
        // Each pull was answered once, by the producer behind the port.
        assert_eq!(answers.load(Ordering::SeqCst), before + 3);
    }
    seen
}

/// The pulled tick ports (a pulled tick output, and a pulled tick input fed by one).
const CASES: &[(Port, bool)] = &[(Port::In(In::Tick), true), (Port::Out(Out::Tick), true)];

/// What the scenario sees at a port of `kind`: three pushed packets (a queue keeps
/// them all, a last or poster input the latest, a tick input counts three events),
/// then, pulled, the answers 1, 2 and 3 (one event each for ticks).
fn expected(port: Port, pull: bool) -> Vec<u64> {
    let consumer = match port {
        Port::In(kind) => kind,
        Port::Out(kind) => consumer_of(kind),
    };
    let mut seen = match consumer {
        In::Fifo | In::Ufifo => vec![1, 2, 3],
        In::Last | In::Poster => vec![3],
        In::Tick => vec![3],
    };
    if pull {
        seen.extend(match consumer {
            In::Tick => [1, 1, 1],
            _ => [1, 2, 3],
        });
    }
    seen
}

#[test]
fn every_port_kind_exported_behaves_as_the_atomic_port() {
    for &(port, pull) in CASES {
        let mut results = Vec::new();
        for topology in [Topology::Atomic, Topology::Exported] {
            let rig = rig(port, pull, topology, Standby::None);
            results.push(scenario(&rig, &rig.inner, pull, 0));
            let report = rig.system.shutdown();
            assert!(
                report.clean(),
                "{port:?} pull {pull} {topology:?}: {report:?}"
            );
        }
        assert_eq!(
            results[0],
            expected(port, pull),
            "{port:?} pull {pull}: the atomic port"
        );
        assert_eq!(
            results[1], results[0],
            "{port:?} pull {pull}: the exported port sees what the atomic port sees"
        );
    }
}

#[test]
fn every_exported_port_kind_follows_the_substitute() {
    every_kind_follows_the_stand_in(Standby::Substitute);
}

#[test]
fn every_exported_port_kind_follows_the_original_back_after_its_recovery() {
    every_kind_follows_the_stand_in(Standby::SubstituteThenRecover);
}

#[test]
fn every_exported_port_kind_follows_the_redundant_group() {
    every_kind_follows_the_stand_in(Standby::Redundant);
}

/// Each port kind, exported from `w`, pushed and pulled before and after `w` fails
/// and `s` (its substitute, or the other member of its redundant group) stands for
/// it (or, once `w` recovered, at `w` again).
fn every_kind_follows_the_stand_in(standby_by: Standby) {
    for &(port, pull) in CASES {
        let rig = rig(port, pull, Topology::Exported, standby_by);
        let standby = rig.standby.clone().expect("a stand-in");
        // Redundant members send the same packets.
        let twin = (standby_by == Standby::Redundant).then_some(&standby);
        assert_eq!(
            scenario_with(&rig, &rig.inner, twin, pull, 0),
            expected(port, pull),
            "{port:?} pull {pull} {standby_by:?}: before the fault"
        );
        // `w` fails answering `trip`; `s` takes its connections and exported ports.
        let _ = rig.trip.request();
        let k = rig.system.handle("k").expect("k");
        k.wait_for(
            |m| {
                m.supervision
                    .iter()
                    .any(|s| matches!(&s.step, Step::Substituted { by } if by == "s"))
            },
            WAIT,
        )
        .unwrap_or_else(|_| panic!("{port:?} pull {pull} {standby_by:?}: w is substituted"));
        let at = if standby_by == Standby::SubstituteThenRecover {
            k.wait_for(
                |m| {
                    m.supervision
                        .iter()
                        .any(|s| s.instance == "w" && s.step == Step::Recovered)
                },
                WAIT,
            )
            .unwrap_or_else(|_| panic!("{port:?} pull {pull}: w recovers"));
            &rig.inner
        } else {
            &standby
        };
        if let PortHandle::In(input) = &standby {
            // A redundant member got what `w` got: the scenario starts afresh.
            input.clear();
        }
        // Packets 4, 5 and 6 are pushed; pull answers go on counting where they
        // stopped (`w` and `s` share their counter).
        let base = 3;
        let ticks = matches!(port, Port::In(In::Tick) | Port::Out(Out::Tick));
        let mut want: Vec<u64> = expected(port, false)
            .into_iter()
            .map(|n| if ticks { n } else { n + base })
            .collect();
        if pull {
            let answered = match port {
                Port::In(_) => rig.outer_answers.load(Ordering::SeqCst),
                Port::Out(_) => rig.answers.load(Ordering::SeqCst),
            };
            want.extend((answered + 1..=answered + 3).map(|n| if ticks { 1 } else { n }));
        }
        assert_eq!(
            scenario(&rig, at, pull, base),
            want,
            "{port:?} pull {pull} {standby_by:?}: after the fault, at the stand-in"
        );
        let report = rig.system.shutdown();
        assert!(
            report.clean(),
            "{port:?} pull {pull} {standby_by:?}: {report:?}"
        );
    }
}
