//! A compound's exported ports behave as an atomic component's: for every port kind
//! (tick, fifo, ufifo, last and poster inputs; tick, data and poster outputs), pushed
//! and pulled, the same scenario runs once against an atomic component's port and
//! once against a compound exporting that port of the same component, and must see
//! the same packets. Then the same through a substitution and through a redundant
//! group's failover: the exported ports follow the stand-in, pulls included.
//!
//! The components and compounds are `cool/exports.cool`'s (one component per port
//! kind, one compound exporting its port); their behaviours hand their ports to the
//! test when they start. A stand-in is added to a compound with the runtime's
//! `CompoundBuilder` (its `substitute`, `redundant`, `on_error` and `recovery`), as
//! the scenario varies it; a tick output cannot be `pull` in the language, so the two
//! pulled tick cases stay in `runtime/tests/exports_tick_pull.rs`.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use coolbot::crossbeam_channel::{self, Receiver, Sender};
use coolbot::port::{DataOut, FifoIn, LastIn, PosterIn, PosterOut, TickIn, TickOut, UfifoIn};
use coolbot::{Component, CompoundBuilder, Fault, Policy, SectionResult, Step, System};
use coolbot_runtime_tests::generated as g;
use coolbot_runtime_tests::support::compound::CompoundRig;
use coolbot_runtime_tests::support::{WAIT, eventually};

/// The input kinds, as the port under test or as the outside consumer of an output.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
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

#[derive(Clone)]
enum PortHandle {
    In(Input),
    Out(Output),
}

/// The behaviour of `w` and its stand-in `s` (an `Exp<Kind>` component): hands its
/// port under test to the test when it starts, fails answering a pull of `trip`, and
/// answers a pull of its port with the next count of `answers`.
struct Member {
    hand: Sender<PortHandle>,
    answers: Arc<AtomicU64>,
}

impl Member {
    fn hand(&self, port: PortHandle) -> SectionResult {
        // A restarted member starts again: the test kept the first hand-over.
        let _ = self.hand.try_send(port);
        Ok(())
    }

    fn answer(&self) -> Result<u64, Fault> {
        Ok(self.answers.fetch_add(1, Ordering::SeqCst) + 1)
    }
}

/// `Member` for component module `$m`, whose port `$dir` is handed as `$variant`;
/// with `pull`, it answers pulls of its (output) port.
macro_rules! member {
    ($m:ident, $dir:ident, $handle:ident, $wrap:ident :: $variant:ident $(, $pull:ident)?) => {
        impl g::$m::Behavior for Member {
            fn start(&mut self, cx: &mut g::$m::Cx<'_>) -> SectionResult {
                self.hand(PortHandle::$handle($wrap::$variant(cx.$dir.port.clone())))
            }
            fn answer_trip(&mut self, _cx: &mut g::$m::Cx<'_>) -> Result<u64, Fault> {
                Err(Fault::message("tripped"))
            }
            $(
                fn $pull(&mut self, _cx: &mut g::$m::Cx<'_>) -> Result<u64, Fault> {
                    self.answer()
                }
            )?
        }
    };
}

member!(exp_fifo, inputs, In, Input::Fifo);
member!(exp_fifo_pull, inputs, In, Input::Fifo);
member!(exp_ufifo, inputs, In, Input::Ufifo);
member!(exp_ufifo_pull, inputs, In, Input::Ufifo);
member!(exp_last, inputs, In, Input::Last);
member!(exp_last_pull, inputs, In, Input::Last);
member!(exp_poster, inputs, In, Input::Poster);
member!(exp_poster_pull, inputs, In, Input::Poster);
member!(exp_tick, inputs, In, Input::Tick);
member!(exp_data_out, outputs, Out, Output::Data);
member!(exp_data_out_pull, outputs, Out, Output::Data, answer_port);
member!(exp_poster_out, outputs, Out, Output::Poster);
member!(
    exp_poster_out_pull,
    outputs,
    Out,
    Output::Poster,
    answer_port
);
member!(exp_tick_out, outputs, Out, Output::Tick);

/// The behaviour of the outside component `o` (an `ExpFeed<Kind>` or
/// `ExpRead<Kind>`): hands its end and its `trip` input to the test when it starts,
/// and answers a pull of its (output) end with the next count of `answers`.
struct Outer {
    hand: Sender<(PortHandle, LastIn<u64>)>,
    answers: Arc<AtomicU64>,
}

macro_rules! outer {
    ($m:ident, $dir:ident, $handle:ident, $wrap:ident :: $variant:ident $(, $pull:ident)?) => {
        impl g::$m::Behavior for Outer {
            fn start(&mut self, cx: &mut g::$m::Cx<'_>) -> SectionResult {
                let end = PortHandle::$handle($wrap::$variant(cx.$dir.end.clone()));
                let _ = self.hand.try_send((end, cx.inputs.trip.clone()));
                Ok(())
            }
            $(
                fn $pull(&mut self, _cx: &mut g::$m::Cx<'_>) -> Result<u64, Fault> {
                    Ok(self.answers.fetch_add(1, Ordering::SeqCst) + 1)
                }
            )?
        }
    };
}

outer!(exp_feed_data, outputs, Out, Output::Data);
outer!(exp_feed_data_pull, outputs, Out, Output::Data, answer_end);
outer!(exp_feed_poster, outputs, Out, Output::Poster);
outer!(
    exp_feed_poster_pull,
    outputs,
    Out,
    Output::Poster,
    answer_end
);
outer!(exp_feed_tick, outputs, Out, Output::Tick);
outer!(exp_read_fifo, inputs, In, Input::Fifo);
outer!(exp_read_fifo_pull, inputs, In, Input::Fifo);
outer!(exp_read_poster, inputs, In, Input::Poster);
outer!(exp_read_poster_pull, inputs, In, Input::Poster);
outer!(exp_read_tick, inputs, In, Input::Tick);

/// The compounds have no supervisor block: their supervisor has nothing to do.
struct NoSections;

/// The parts of a compound around `w`: its behaviour.
struct KParts(Option<Member>);

macro_rules! compound {
    ($k:ident, $m:ident) => {
        impl g::$k::Supervisor for NoSections {}
        impl g::$k::Parts for KParts {
            fn supervisor(&mut self) -> impl g::$k::Supervisor {
                NoSections
            }
            fn w(&mut self) -> impl g::$m::Behavior {
                self.0.take().expect("w is built once")
            }
        }
    };
}

compound!(exp_k_fifo, exp_fifo);
compound!(exp_k_fifo_pull, exp_fifo_pull);
compound!(exp_k_ufifo, exp_ufifo);
compound!(exp_k_ufifo_pull, exp_ufifo_pull);
compound!(exp_k_last, exp_last);
compound!(exp_k_last_pull, exp_last_pull);
compound!(exp_k_poster, exp_poster);
compound!(exp_k_poster_pull, exp_poster_pull);
compound!(exp_k_tick, exp_tick);
compound!(exp_k_data_out, exp_data_out);
compound!(exp_k_data_out_pull, exp_data_out_pull);
compound!(exp_k_poster_out, exp_poster_out);
compound!(exp_k_poster_out_pull, exp_poster_out_pull);
compound!(exp_k_tick_out, exp_tick_out);
compound!(exp_bare_poster, exp_poster_out);
compound!(exp_bare_tick, exp_tick);

/// The `Exp<Kind>` component named `name` with the port under test (pulled or not),
/// following `member`.
fn member(name: &str, port: Port, pull: bool, member: Member) -> Component {
    match (port, pull) {
        (Port::In(In::Fifo), false) => g::exp_fifo::component(name, member),
        (Port::In(In::Fifo), true) => g::exp_fifo_pull::component(name, member),
        (Port::In(In::Ufifo), false) => g::exp_ufifo::component(name, member),
        (Port::In(In::Ufifo), true) => g::exp_ufifo_pull::component(name, member),
        (Port::In(In::Last), false) => g::exp_last::component(name, member),
        (Port::In(In::Last), true) => g::exp_last_pull::component(name, member),
        (Port::In(In::Poster), false) => g::exp_poster::component(name, member),
        (Port::In(In::Poster), true) => g::exp_poster_pull::component(name, member),
        (Port::In(In::Tick), false) => g::exp_tick::component(name, member),
        (Port::Out(Out::Data), false) => g::exp_data_out::component(name, member),
        (Port::Out(Out::Data), true) => g::exp_data_out_pull::component(name, member),
        (Port::Out(Out::Poster), false) => g::exp_poster_out::component(name, member),
        (Port::Out(Out::Poster), true) => g::exp_poster_out_pull::component(name, member),
        (Port::Out(Out::Tick), false) => g::exp_tick_out::component(name, member),
        (port, true) => panic!("{port:?} cannot be pulled in the language"),
    }
}

/// The builder of `ExpK<Kind>` named `k`: `w` (following `w`) with its port under
/// test exported as `x`, and its `trip`.
fn exported(port: Port, pull: bool, w: Member) -> CompoundBuilder {
    let parts = KParts(Some(w));
    match (port, pull) {
        (Port::In(In::Fifo), false) => g::exp_k_fifo::builder("k", parts),
        (Port::In(In::Fifo), true) => g::exp_k_fifo_pull::builder("k", parts),
        (Port::In(In::Ufifo), false) => g::exp_k_ufifo::builder("k", parts),
        (Port::In(In::Ufifo), true) => g::exp_k_ufifo_pull::builder("k", parts),
        (Port::In(In::Last), false) => g::exp_k_last::builder("k", parts),
        (Port::In(In::Last), true) => g::exp_k_last_pull::builder("k", parts),
        (Port::In(In::Poster), false) => g::exp_k_poster::builder("k", parts),
        (Port::In(In::Poster), true) => g::exp_k_poster_pull::builder("k", parts),
        (Port::In(In::Tick), false) => g::exp_k_tick::builder("k", parts),
        (Port::Out(Out::Data), false) => g::exp_k_data_out::builder("k", parts),
        (Port::Out(Out::Data), true) => g::exp_k_data_out_pull::builder("k", parts),
        (Port::Out(Out::Poster), false) => g::exp_k_poster_out::builder("k", parts),
        (Port::Out(Out::Poster), true) => g::exp_k_poster_out_pull::builder("k", parts),
        (Port::Out(Out::Tick), false) => g::exp_k_tick_out::builder("k", parts),
        (port, true) => panic!("{port:?} cannot be pulled in the language"),
    }
    .expect("the compound's builder")
}

/// The outside component `o` that feeds (`ExpFeed<Kind>`) or reads (`ExpRead<Kind>`)
/// the port under test of kind `port`.
fn outside(port: Port, pull: bool, outer: Outer) -> Component {
    match (port, pull) {
        (Port::In(kind), false) => match producer_of(kind) {
            Out::Data => g::exp_feed_data::component("o", outer),
            Out::Poster => g::exp_feed_poster::component("o", outer),
            Out::Tick => g::exp_feed_tick::component("o", outer),
        },
        (Port::In(kind), true) => match producer_of(kind) {
            Out::Data => g::exp_feed_data_pull::component("o", outer),
            Out::Poster => g::exp_feed_poster_pull::component("o", outer),
            Out::Tick => panic!("a tick output cannot be pulled in the language"),
        },
        (Port::Out(kind), false) => match consumer_of(kind) {
            In::Poster => g::exp_read_poster::component("o", outer),
            In::Tick => g::exp_read_tick::component("o", outer),
            _ => g::exp_read_fifo::component("o", outer),
        },
        (Port::Out(kind), true) => match consumer_of(kind) {
            In::Poster => g::exp_read_poster_pull::component("o", outer),
            In::Tick => g::exp_read_tick::component("o", outer),
            _ => g::exp_read_fifo_pull::component("o", outer),
        },
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

/// What a started component handed over.
fn handed<T>(from: &Receiver<T>, who: &str) -> T {
    from.recv_timeout(WAIT)
        .unwrap_or_else(|_| panic!("{who} started and handed its ports over"))
}

fn rig(port: Port, pull: bool, topology: Topology, standby_by: Standby) -> Rig {
    let answers = Arc::new(AtomicU64::new(0));
    let (hand_w, from_w) = crossbeam_channel::bounded(1);
    let w = Member {
        hand: hand_w,
        answers: Arc::clone(&answers),
    };
    let outer_answers = Arc::new(AtomicU64::new(0));
    let (hand_o, from_o) = crossbeam_channel::bounded(1);
    let o = outside(
        port,
        pull,
        Outer {
            hand: hand_o,
            answers: Arc::clone(&outer_answers),
        },
    );
    let mut from_s = None;
    let mut system = match topology {
        Topology::Atomic => {
            let mut system = System::new();
            system.add(member("w", port, pull, w)).expect("add w");
            system
        }
        Topology::Exported => {
            let mut builder = exported(port, pull, w);
            if standby_by != Standby::None {
                let (hand_s, from) = crossbeam_channel::bounded(1);
                from_s = Some(from);
                let s = Member {
                    hand: hand_s,
                    answers: Arc::clone(&answers),
                };
                let retry = match standby_by {
                    Standby::SubstituteThenRecover => std::time::Duration::from_millis(20),
                    _ => WAIT,
                };
                builder = builder
                    .instance(member("s", port, pull, s))
                    .recovery(retry, WAIT * 6);
                builder = match standby_by {
                    Standby::Redundant => builder.redundant(&["w", "s"]),
                    _ => builder
                        .substitute("s", "w")
                        .on_error("w", Policy::Substitute),
                };
            }
            let mut system = System::new();
            system
                .add(builder.build().expect("build k"))
                .expect("add k");
            system
        }
    };
    system.add(o).expect("add o");
    let (port_under_test, trip) = match topology {
        Topology::Atomic => ("w.port", "w.trip"),
        Topology::Exported => ("k.x", "k.trip"),
    };
    system.connect(trip, "o.trip").expect("trip");
    match port {
        Port::In(_) => system.connect("o.end", port_under_test),
        Port::Out(_) => system.connect(port_under_test, "o.end"),
    }
    .expect("connect the port under test");
    system.run_all().expect("run");
    let inner = handed(&from_w, "w");
    let standby = from_s.map(|from| handed(&from, "s"));
    let (outer, trip) = handed(&from_o, "o");
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

/// Every port kind a component can have, pushed and pulled (but a tick output, which
/// the language does not let answer pulls: `runtime/tests/exports_tick_pull.rs`).
const CASES: &[(Port, bool)] = &[
    (Port::In(In::Fifo), false),
    (Port::In(In::Fifo), true),
    (Port::In(In::Ufifo), false),
    (Port::In(In::Ufifo), true),
    (Port::In(In::Last), false),
    (Port::In(In::Last), true),
    (Port::In(In::Poster), false),
    (Port::In(In::Poster), true),
    (Port::In(In::Tick), false),
    (Port::Out(Out::Data), false),
    (Port::Out(Out::Data), true),
    (Port::Out(Out::Poster), false),
    (Port::Out(Out::Poster), true),
    (Port::Out(Out::Tick), false),
];

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

#[test]
fn exporting_a_port_of_the_wrong_kind_or_type_is_refused() {
    let member = || {
        let (hand, _) = crossbeam_channel::bounded(1);
        Some(Member {
            hand,
            answers: Arc::new(AtomicU64::new(0)),
        })
    };
    // `w.port` is a poster output of u64 (`ExpBarePoster`'s `w`, not exported).
    let error = g::exp_bare_poster::builder("k", KParts(member()))
        .expect("builder")
        .export_output::<String>("x", "w.port")
        .build()
        .expect_err("a poster of u64 exported as String");
    assert!(
        error.to_string().contains("cannot export `w.port`"),
        "{error}"
    );
    let error = g::exp_bare_poster::builder("k", KParts(member()))
        .expect("builder")
        .export_tick_output("x", "w.port")
        .build()
        .expect_err("a poster exported as a tick output");
    assert!(error.to_string().contains("not a tick output"), "{error}");
    // `w.port` is a tick input (`ExpBareTick`'s `w`).
    let error = g::exp_bare_tick::builder("k", KParts(member()))
        .expect("builder")
        .export_input::<u64>("x", "w.port")
        .build()
        .expect_err("a tick input exported as a data input");
    assert!(
        error
            .to_string()
            .contains("fifo, ufifo, last, poster input"),
        "{error}"
    );
}

/// `ExpWaiting`'s `w` and `s`: answering a pull of `trip` holds the thread until the
/// test opens the gate, then fails; a pull of `port` is answered with 7, and who
/// answered is written down.
struct Gated {
    name: &'static str,
    gate: Arc<std::sync::atomic::AtomicBool>,
    busy: Arc<std::sync::atomic::AtomicBool>,
    answered_by: Arc<std::sync::Mutex<Vec<&'static str>>>,
}

impl g::exp_data_out_pull::Behavior for Gated {
    fn answer_trip(&mut self, _cx: &mut g::exp_data_out_pull::Cx<'_>) -> Result<u64, Fault> {
        self.busy.store(true, Ordering::SeqCst);
        while self.gate.load(Ordering::SeqCst) {
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        Err(Fault::message("tripped"))
    }
    fn answer_port(&mut self, _cx: &mut g::exp_data_out_pull::Cx<'_>) -> Result<u64, Fault> {
        self.answered_by.lock().unwrap().push(self.name);
        Ok(7)
    }
}

struct WaitingParts {
    gated: Box<dyn Fn(&'static str) -> Gated>,
}

impl g::exp_waiting::Supervisor for NoSections {}

impl g::exp_waiting::Parts for WaitingParts {
    fn supervisor(&mut self) -> impl g::exp_waiting::Supervisor {
        NoSections
    }
    fn w(&mut self) -> impl g::exp_data_out_pull::Behavior {
        (self.gated)("w")
    }
    fn s(&mut self) -> impl g::exp_data_out_pull::Behavior {
        (self.gated)("s")
    }
}

#[test]
fn a_pull_waiting_at_a_failed_instance_is_answered_by_its_substitute() {
    // `w` is busy answering a pull of `trip` (which fails it) when `o` pulls the
    // exported `x`: that request waits at `w.port`. `w` fails, `s` takes its place,
    // and the waiting request goes with the connection: `s` answers it.
    let gate = Arc::new(std::sync::atomic::AtomicBool::new(true));
    let busy = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let answered_by = Arc::new(std::sync::Mutex::new(Vec::<&'static str>::new()));
    let gated = {
        let (gate, busy, answered_by) = (
            Arc::clone(&gate),
            Arc::clone(&busy),
            Arc::clone(&answered_by),
        );
        move |name| Gated {
            name,
            gate: Arc::clone(&gate),
            busy: Arc::clone(&busy),
            answered_by: Arc::clone(&answered_by),
        }
    };
    let mut rig = CompoundRig::new(g::exp_waiting::component(
        "k",
        WaitingParts {
            gated: Box::new(gated),
        },
    ));
    let (hand, from_o) = crossbeam_channel::bounded(1);
    rig.add(g::exp_read_fifo_pull::component(
        "o",
        Outer {
            hand,
            answers: Arc::new(AtomicU64::new(0)),
        },
    ));
    rig.connect("k.x", "o.end");
    rig.connect("k.trip", "o.trip");
    rig.run();
    let (PortHandle::In(Input::Fifo(end)), trip) = handed(&from_o, "o") else {
        panic!("o reads a fifo");
    };
    trip.request().expect("request trip");
    eventually(|| busy.load(Ordering::SeqCst), "w is busy answering trip");
    end.request().expect("request x: it waits at w.port");
    gate.store(false, Ordering::SeqCst);
    assert_eq!(
        end.recv_timeout(WAIT),
        Some(7),
        "the request waiting at w is answered by its substitute"
    );
    assert_eq!(*answered_by.lock().unwrap(), ["s"]);
    rig.wait_steps("w", 1, |step| {
        *step == Step::Substituted { by: "s".to_owned() }
    });
    assert!(rig.shutdown().clean());
}
