//! The scenario of the exported-port tests, shared by `exports_tick_pull.rs` here and
//! `tests/runtime/tests/all/exports.rs` (which includes this file by its path): a
//! compound's exported ports behave as an atomic component's. For a port kind, pushed
//! and pulled, the same scenario runs once against an atomic component's port and
//! once against a compound exporting that port of the same component, and must see
//! the same packets; then the same through a substitution and through a redundant
//! group's failover: the exported ports follow the stand-in, pulls included.
//!
//! Each test file makes the components (its [`Rig`]) and names its cases; this module
//! runs them.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use std::time::Duration;

use coolbot::port::{DataOut, FifoIn, LastIn, PosterIn, PosterOut, TickIn, TickOut, UfifoIn};
use coolbot::{Component, CompoundBuilder, Policy, Step, System};

use super::{WAIT, eventually};

/// The input kinds, as the port under test or as the outside consumer of an output.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[allow(
    dead_code,
    reason = "`exports_tick_pull.rs` runs only the pulled tick ports, not every kind"
)]
pub enum In {
    Fifo,
    Ufifo,
    Last,
    Poster,
    Tick,
}

/// The output kinds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Out {
    Data,
    Poster,
    Tick,
}

/// One input handle of packets `u64` (or events).
#[derive(Clone)]
pub enum Input {
    Fifo(FifoIn<u64>),
    Ufifo(UfifoIn<u64>),
    Last(LastIn<u64>),
    Poster(PosterIn<u64>),
    Tick(TickIn),
}

impl Input {
    /// What `pull` returns: the packet, or the events taken.
    pub fn pull(&self) -> u64 {
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
    pub fn clear(&self) {
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
    pub fn observe(&self, count: u64, last: u64) -> Vec<u64> {
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
pub enum Output {
    Data(DataOut<u64>),
    Poster(PosterOut<u64>),
    Tick(TickOut),
}

impl Output {
    pub fn produce(&self, n: u64) {
        match self {
            Output::Data(port) => port.send(n),
            Output::Poster(port) => port.post(n),
            Output::Tick(port) => port.emit(),
        }
    }
}

/// The output kind that feeds an input kind.
pub fn producer_of(kind: In) -> Out {
    match kind {
        In::Fifo | In::Ufifo | In::Last => Out::Data,
        In::Poster => Out::Poster,
        In::Tick => Out::Tick,
    }
}

/// The input kind that reads an output kind.
pub fn consumer_of(kind: Out) -> In {
    match kind {
        Out::Data => In::Fifo,
        Out::Poster => In::Poster,
        Out::Tick => In::Tick,
    }
}

/// The port under test: an input or an output of the component `w`.
#[derive(Debug, Clone, Copy)]
pub enum Port {
    In(In),
    Out(Out),
}

/// Where `w` is: added to the system itself, or inside compound `k`, which exports its
/// port `port` as `x`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Topology {
    Atomic,
    Exported,
}

#[derive(Clone)]
pub enum PortHandle {
    In(Input),
    Out(Output),
}

/// The system of one scenario: `w` (or `k` around `w`, with substitute `s` if
/// `substitute`) and the outside component `o` that feeds or reads the port.
pub struct Rig {
    pub system: System,
    /// The port under test at `w`, and at `s`.
    pub inner: PortHandle,
    pub standby: Option<PortHandle>,
    /// The outside end: a producer's output or a consumer's input.
    pub outer: PortHandle,
    /// `o`'s pull answers count from here.
    pub outer_answers: Arc<AtomicU64>,
    /// `w`'s (and `s`'s) pull answers.
    pub answers: Arc<AtomicU64>,
    /// The outside pull consumer of `trip` (to fail `w`).
    pub trip: LastIn<u64>,
}

/// Who stands by for `w` inside the compound.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Standby {
    None,
    /// `s` substitutes `w`.
    Substitute,
    /// `s` substitutes `w`, and `w` recovers soon after (it takes its place back).
    SubstituteThenRecover,
    /// `w` and `s` are a redundant group (`w` leads).
    Redundant,
}

/// Adds `s`, the stand-in for `w`, to the builder of compound `k` as `standby_by` says:
/// its substitute, its substitute with `w` recovering soon after, or the other member
/// of its redundant group.
pub fn stand_by(builder: CompoundBuilder, standby_by: Standby, s: Component) -> CompoundBuilder {
    let retry = match standby_by {
        Standby::SubstituteThenRecover => Duration::from_millis(20),
        _ => WAIT,
    };
    let builder = builder.instance(s).recovery(retry, WAIT * 6);
    match standby_by {
        Standby::Redundant => builder.redundant(&["w", "s"]),
        _ => builder
            .substitute("s", "w")
            .on_error("w", Policy::Substitute),
    }
}

/// Connects the outside component `o` (added to `system`, beside `w` or `k`) to the
/// port under test (`w.port`, or `k.x`) and to `trip`, and runs the system.
pub fn connect_and_run(system: &mut System, port: Port, topology: Topology) {
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
}

/// Run the scenario for `port` at `at` (the component behind the port now): push
/// three packets and see them arrive; with `pull`, also pull three. Returns what was
/// seen, in order.
pub fn scenario(rig: &Rig, at: &PortHandle, pull: bool, base: u64) -> Vec<u64> {
    scenario_with(rig, at, None, pull, base)
}

/// [`scenario`], where `twin` (a redundant member beside `at`, if given) sends what
/// `at` sends, as members on the same inputs do.
pub fn scenario_with(
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

/// What the scenario sees at a port of `kind`: three pushed packets (a queue keeps
/// them all, a last or poster input the latest, a tick input counts three events),
/// then, pulled, the answers 1, 2 and 3 (one event each for ticks).
pub fn expected(port: Port, pull: bool) -> Vec<u64> {
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

/// The scenario at the atomic port and at the exported one, for each case of `cases`
/// (a port and whether it is pulled); `rig` builds one scenario's system.
pub fn exported_behaves_as_atomic(
    cases: &[(Port, bool)],
    rig: impl Fn(Port, bool, Topology, Standby) -> Rig,
) {
    for &(port, pull) in cases {
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

/// Each port kind, exported from `w`, pushed and pulled before and after `w` fails
/// and `s` (its substitute, or the other member of its redundant group) stands for
/// it (or, once `w` recovered, at `w` again), for each case of `cases`.
pub fn follows_the_stand_in(
    cases: &[(Port, bool)],
    rig: impl Fn(Port, bool, Topology, Standby) -> Rig,
    standby_by: Standby,
) {
    for &(port, pull) in cases {
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

/// The four tests of the scenario over `$cases` (a `&[(Port, bool)]`), each system
/// built by `$rig` (a `fn(Port, bool, Topology, Standby) -> Rig`); where it is used,
/// `exported_behaves_as_atomic`, `follows_the_stand_in` and `Standby` are in scope.
macro_rules! exported_port_tests {
    ($cases:expr, $rig:expr) => {
        #[test]
        fn every_port_kind_exported_behaves_as_the_atomic_port() {
            exported_behaves_as_atomic($cases, $rig);
        }

        #[test]
        fn every_exported_port_kind_follows_the_substitute() {
            follows_the_stand_in($cases, $rig, Standby::Substitute);
        }

        #[test]
        fn every_exported_port_kind_follows_the_original_back_after_its_recovery() {
            follows_the_stand_in($cases, $rig, Standby::SubstituteThenRecover);
        }

        #[test]
        fn every_exported_port_kind_follows_the_redundant_group() {
            follows_the_stand_in($cases, $rig, Standby::Redundant);
        }
    };
}
pub(crate) use exported_port_tests;
