//! A compound's exported ports behave as an atomic component's
//! (`runtime/tests/support/exports.rs`, the scenario this file shares with the
//! runtime's own test of the pulled tick ports), for every port kind a generated
//! component can have: tick, fifo, ufifo, last and poster inputs; tick, data and
//! poster outputs; pushed and pulled.
//!
//! The components and compounds are `cool/exports.cool`'s (one component per port
//! kind, one compound exporting its port); their behaviours hand their ports to the
//! test when they start. A stand-in is added to a compound with the runtime's
//! `CompoundBuilder` (its `substitute`, `redundant`, `on_error` and `recovery`), as
//! the scenario varies it; a tick output cannot be `pull` in the language, so the two
//! pulled tick cases are in `runtime/tests/exports_tick_pull.rs`.

#[path = "../../../../runtime/tests/support/exports.rs"]
mod scenario;

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use coolbot::crossbeam_channel::{self, Receiver, Sender};
use coolbot::port::LastIn;
use coolbot::{Component, CompoundBuilder, Fault, SectionResult, Step, System};
use coolbot_runtime_tests::generated as g;
use coolbot_runtime_tests::support::compound::CompoundRig;
use coolbot_runtime_tests::support::{WAIT, eventually};
use scenario::{
    In, Input, Out, Output, Port, PortHandle, Rig, Standby, Topology, connect_and_run, consumer_of,
    exported_behaves_as_atomic, follows_the_stand_in, producer_of, stand_by,
};

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
                builder = stand_by(builder, standby_by, member("s", port, pull, s));
            }
            let mut system = System::new();
            system
                .add(builder.build().expect("build k"))
                .expect("add k");
            system
        }
    };
    system.add(o).expect("add o");
    connect_and_run(&mut system, port, topology);
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

scenario::exported_port_tests!(CASES, rig);
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
